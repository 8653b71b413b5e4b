"""Frames and transforms, laser beams, the pinhole camera, DLT fits and rigid 2-D registration.

Conventions (ALGORITHMS.md 0.2): metres, radians; frames in names, ``a2b`` maps points expressed in
frame ``a`` into frame ``b``; the world floor has ``Z`` up; the camera optical frame has ``z`` forward,
``x`` right, ``y`` down; pixels have ``u`` right, ``v`` down; a box is ``(u_min, v_min, u_max, v_max)``.
Everything here is vectorised over the point / beam axis; invalid values travel as ``NaN`` rows.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace
from itertools import pairwise
from typing import Any

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from fusiontrack.errors import CalibrationError, ConfigError
from fusiontrack.types import CameraInfo, LaserScan, Transform

__all__ = [
    "PinholeCamera", "TransformTree", "apply_homography", "apply_pose2d", "fit_homography",
    "fit_projection_matrix", "fit_rigid_2d", "invert_transform", "make_transform", "matrix_to_quat",
    "person_box_from_matrix", "pose2d_to_matrix", "project_with_matrix", "quat_to_matrix",
    "ranges_to_points", "reprojection_rms", "rpy_to_matrix", "scan_to_points", "scan_to_world",
    "static_transform", "transform_points", "wrap_angle", "yaw_to_matrix",
]

# Columns are the optical axes (x right, y down, z forward) in a level body frame (x forward, y left, z up).
_OPT2BODY = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _points(value: Any, dim: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"{name}: expected an array of shape (n, {dim}), got {arr.shape}")
    return arr


# ---- Rotations, poses, angles --------------------------------------------------------------------


def wrap_angle(angle_rad: Any) -> np.ndarray:
    """Wrap angles to ``(-pi, pi]`` (ALGORITHMS.md 0.2); any shape, returns float64 of the same shape."""
    return np.pi - np.mod(np.pi - np.asarray(angle_rad, dtype=np.float64), 2.0 * np.pi)


def quat_to_matrix(xyzw: Any) -> np.ndarray:
    """Rotation matrix from a quaternion in ROS order (x, y, z, w): (4,) -> (3, 3), (n, 4) -> (n, 3, 3)."""
    try:
        return Rotation.from_quat(np.asarray(xyzw, dtype=np.float64)).as_matrix()
    except ValueError as err:
        raise ValueError(f"xyzw: not a valid (non-zero, finite) quaternion: {err}") from err


def matrix_to_quat(R: Any) -> np.ndarray:
    """Quaternion ``(x, y, z, w)``, ``w >= 0``, from a rotation: (3, 3) -> (4,), (n, 3, 3) -> (n, 4)."""
    return Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat(canonical=True)


def static_transform(t_ns: int, parent: str, child: str, child2parent: Any) -> Transform:
    """The ``/tf_static`` record of a ``(4, 4)`` ``child2parent`` (the pose of ``child`` in ``parent``)."""
    T = np.asarray(child2parent, dtype=np.float64)
    return Transform(t_ns, "/tf_static", parent, child, T[:3, 3], matrix_to_quat(T[:3, :3]), True)


def rpy_to_matrix(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (ROS REP-103 fixed-axis order), ``(3, 3)``.

    With a body frame x forward, y left, z up, a positive pitch turns the nose down.
    """
    return Rotation.from_euler("xyz", [roll_rad, pitch_rad, yaw_rad]).as_matrix()


def yaw_to_matrix(yaw_rad: Any) -> np.ndarray:
    """Rotation about the vertical axis: scalar -> ``(3, 3)``, ``(n,)`` -> ``(n, 3, 3)``."""
    return Rotation.from_euler("z", yaw_rad).as_matrix()


def make_transform(R: Any, t: Any) -> np.ndarray:
    """Homogeneous transform from rotation and translation: (3, 3), (3,) -> (4, 4); (2, 2), (2,) -> (3, 3)."""
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    d = R.shape[0]
    if R.shape not in ((2, 2), (3, 3)) or t.shape != (d,):
        raise ValueError(f"make_transform: expected R (d, d), t (d,), d = 2 or 3; got {R.shape}, {t.shape}")
    T = np.eye(d + 1)
    T[:d, :d] = R
    T[:d, d] = t
    return T


def invert_transform(T: Any) -> np.ndarray:
    """Inverse of a rigid homogeneous transform, (4, 4) or (3, 3), using ``R.T`` rather than a solve."""
    T = np.asarray(T, dtype=np.float64)
    d = T.shape[0] - 1
    return make_transform(T[:d, :d].T, -T[:d, :d].T @ T[:d, d])


def pose2d_to_matrix(x_m: float, y_m: float, yaw_rad: float) -> np.ndarray:
    """The 2-D pose ``(x, y, yaw)`` as a ``(3, 3)`` homogeneous ``local2parent`` transform."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, x_m], [s, c, y_m], [0.0, 0.0, 1.0]])


def transform_points(T: Any, pts: Any) -> np.ndarray:
    """Map points ``pts`` in frame ``a`` into frame ``b`` with ``T = a2b``; NaN rows stay NaN.

    ``T`` (4, 4) with ``pts`` (n, 3) -> (n, 3); ``T`` (3, 3) 2-D pose with ``pts`` (n, 2) -> (n, 2); ``T``
    (4, 4) with ``pts`` (n, 2) treats them as floor points (``z = 0``) and returns the mapped ``(x, y)``.
    """
    T = np.asarray(T, dtype=np.float64)
    p = np.asarray(pts, dtype=np.float64)
    if p.ndim != 2 or T.shape not in ((3, 3), (4, 4)) or not 2 <= p.shape[1] < T.shape[0]:
        raise ValueError(f"transform_points: cannot apply a {T.shape} transform to points of shape {p.shape}")
    d = p.shape[1]
    return p @ T[:d, :d].T + T[:d, -1]


def apply_pose2d(pose: Any, pts: Any) -> np.ndarray:
    """Apply a ``(3, 3)`` 2-D pose to ``(n, 2)`` points; returns ``(n, 2)``."""
    if np.shape(pose) != (3, 3):
        raise ValueError(f"pose: expected a (3, 3) 2-D pose, got {np.shape(pose)}")
    return transform_points(pose, _points(pts, 2, "pts"))


# ---- Transform tree ------------------------------------------------------------------------------


class TransformTree:
    """Named frames joined by rigid transforms; :meth:`get` chains and inverts along the unique path."""

    def __init__(self) -> None:
        self._edges: dict[str, dict[str, np.ndarray]] = {}  # _edges[u][w] = u2w

    def add(self, parent: str, child: str, child2parent: Any) -> None:
        """Add (or replace) the edge ``child2parent`` ``(4, 4)``; an edge closing a loop is a ConfigError."""
        T = np.array(child2parent, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ConfigError(f"transform {child!r} -> {parent!r}: expected a finite (4, 4) matrix, got {T}")
        if parent == child:
            raise ConfigError(f"transform {child!r} -> {parent!r}: a frame cannot be its own parent")
        if child not in self._edges.get(parent, {}) and self.has_path(parent, child):
            raise ConfigError(f"transform {child!r} -> {parent!r}: the frames are already connected (loop)")
        inv = invert_transform(T)
        T.setflags(write=False)
        inv.setflags(write=False)
        self._edges.setdefault(child, {})[parent] = T
        self._edges.setdefault(parent, {})[child] = inv

    def add_record(self, tf: Transform) -> None:
        """Add a :class:`fusiontrack.types.Transform` (the pose of ``child_frame`` in ``parent_frame``); a
        translation or quaternion that is not finite, or a zero quaternion, is a ConfigError naming the frames
        (as :meth:`add`'s other refusals: callers reading a recording warn and leave the edge out)."""
        q, t = np.asarray(tf.rotation_xyzw), np.asarray(tf.translation_m)
        bad = [f"{name} ({', '.join(f'{v:.4g}' for v in value)}) is {what}" for name, value, what, ok in (
            ("translation", t, "not finite", np.all(np.isfinite(t))),
            ("rotation x, y, z, w", q, "not a finite non-zero quaternion", np.all(np.isfinite(q)) and np.any(q != 0)),
        ) if not ok]
        if bad:
            raise ConfigError(f"transform {tf.child_frame!r} -> {tf.parent_frame!r}: its {' and its '.join(bad)}")
        T = make_transform(quat_to_matrix(q), t)
        self.add(tf.parent_frame, tf.child_frame, T)

    @property
    def frames(self) -> tuple[str, ...]:
        """Every frame name, in the order first added."""
        return tuple(self._edges)

    def _path(self, a: str, b: str) -> list[str] | None:
        previous: dict[str, str] = {a: a}
        queue = deque([a])
        while queue:
            u = queue.popleft()
            if u == b:
                path = [b]
                while path[-1] != a:
                    path.append(previous[path[-1]])
                return path[::-1]
            for w in self._edges[u]:
                if w not in previous:
                    previous[w] = u
                    queue.append(w)
        return None

    def has_path(self, a: str, b: str) -> bool:
        """Whether both frames are known and connected."""
        return a in self._edges and b in self._edges and self._path(a, b) is not None

    def get(self, a: str, b: str) -> np.ndarray:
        """The ``(4, 4)`` transform ``a2b``, mapping points in frame ``a`` into frame ``b``."""
        unknown = [f for f in (a, b) if f not in self._edges]
        if unknown:
            names = ", ".join(map(repr, unknown))
            raise ConfigError(f"unknown frame(s) {names}; known frames: {list(self._edges)}")
        path = self._path(a, b)
        if path is None:
            raise ConfigError(f"no chain of transforms connects frame {a!r} to frame {b!r}")
        T = np.eye(4)
        for u, w in pairwise(path):
            T = self._edges[u][w] @ T
        return T


# ---- Laser beams ---------------------------------------------------------------------------------


def ranges_to_points(ranges_m: Any, angles_rad: Any) -> np.ndarray:
    """Polar readings (n,) to Cartesian points (n, 2), ``(r cos a, r sin a)``; non-finite r -> NaN rows."""
    r = np.asarray(ranges_m, dtype=np.float64)
    r = np.where(np.isfinite(r), r, np.nan)
    a = np.asarray(angles_rad, dtype=np.float64)
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)


def scan_to_points(scan: LaserScan) -> np.ndarray:
    """Beam end points in the sensor frame, ``(n_beams, 2)`` metres; invalid beams are NaN rows."""
    return ranges_to_points(scan.valid_ranges_m(), scan.angles_rad())


def scan_to_world(scan: LaserScan, laser2world: Any) -> np.ndarray:
    """Beam end points in the world floor frame, (n_beams, 2); ``laser2world`` is a 2-D pose or (4, 4)."""
    return transform_points(laser2world, scan_to_points(scan))


# ---- Pinhole camera ------------------------------------------------------------------------------


def _box_from_segment(bottom_uv: np.ndarray, top_uv: np.ndarray, width_ratio: float) -> np.ndarray:
    # seed 001 box geometry; ALGORITHMS.md B11: h_b = |v_b - v_t|, w_b = r_w h_b, centred on the midpoint
    # (filled column by column: the fused tracker projects a few boxes many times a step, where stacking costs
    # more than the arithmetic)
    centre = 0.5 * (bottom_uv + top_uv)
    half_h = 0.5 * np.abs(bottom_uv[:, 1] - top_uv[:, 1])
    half_w = width_ratio * half_h
    out = np.empty((len(centre), 4))
    out[:, 0] = centre[:, 0] - half_w
    out[:, 1] = centre[:, 1] - half_h
    out[:, 2] = centre[:, 0] + half_w
    out[:, 3] = centre[:, 1] + half_h
    return out


def _feet_segments(feet_xy: Any, height_m: Any) -> tuple[np.ndarray, int]:
    """World points ``(2n, 3)``: the feet ``(n, 2)`` on the floor, then the heads ``height_m`` above them."""
    feet = _points(feet_xy, 2, "feet_xy")
    n = feet.shape[0]
    seg = np.empty((2 * n, 3))
    seg[:n, :2] = feet
    seg[n:, :2] = feet
    seg[:n, 2] = 0.0
    seg[n:, 2] = np.broadcast_to(np.asarray(height_m, dtype=np.float64), (n,))
    return seg, n


@dataclass(frozen=True, slots=True, eq=False)
class PinholeCamera:
    """A calibrated camera: intrinsics, OpenCV distortion and its pose.

    Attributes
    ----------
    K : (3, 3) float64
        ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels (no skew, as OpenCV).
    dist : (0,), (4,), (5,) or (8,) float64
        ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])``.
    world2cam : (4, 4) float64
        Maps world points into the optical frame (z forward, x right, y down).
    width, height : int
        Image size in pixels.
    """

    K: np.ndarray
    dist: np.ndarray
    world2cam: np.ndarray
    width: int
    height: int

    def __post_init__(self) -> None:
        K = np.array(self.K, dtype=np.float64)
        dist = np.array(self.dist if self.dist is not None else (), dtype=np.float64).ravel()
        T = np.array(self.world2cam, dtype=np.float64)
        if K.shape != (3, 3) or np.any(K[[0, 1, 2, 2, 2], [1, 0, 0, 1, 2]] != (0, 0, 0, 0, 1)) \
                or min(K[0, 0], K[1, 1]) <= 0:
            raise ConfigError(f"PinholeCamera.K: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {K}")
        if dist.size not in (0, 4, 5, 8) or not np.all(np.isfinite(dist)):
            raise ConfigError(f"PinholeCamera.dist: expected 0, 4, 5 or 8 finite coefficients, got {dist}")
        R = T[:3, :3] if T.shape == (4, 4) else np.zeros((3, 3))
        if T.shape != (4, 4) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0 \
                or not np.allclose(T[3], (0, 0, 0, 1)):
            raise ConfigError(f"PinholeCamera.world2cam: expected a rigid (4, 4) transform, got {T}")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ConfigError(f"PinholeCamera: image size must be positive, got {self.width}x{self.height}")
        for name, arr in (("K", K), ("dist", dist), ("world2cam", T)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    @classmethod
    def from_camera_info(cls, info: CameraInfo, world2cam: Any) -> PinholeCamera:
        """Build from a ROS ``CameraInfo`` (``plumb_bob`` or ``rational_polynomial``) and the camera pose."""
        if info.distortion_model not in ("plumb_bob", "rational_polynomial", "") and np.any(info.D != 0):
            raise ConfigError(f"camera {info.sensor!r}: unsupported distortion {info.distortion_model!r}")
        return cls(info.K, info.D, world2cam, info.width, info.height)

    @classmethod
    def from_pose(cls, position_m: Any, yaw_rad: float, pitch_rad: float, roll_rad: float = 0.0, *, fx: float,
                  fy: float, width: int, height: int, cx: float | None = None, cy: float | None = None,
                  dist: Any = None) -> PinholeCamera:
        """A camera placed by position and heading, e.g. an elevated camera looking down at the floor.

        Parameters
        ----------
        position_m : (3,) float
            Camera centre in the world (m).
        yaw_rad, pitch_rad, roll_rad : float
            Heading of the view from world x, counter-clockwise; tilt below the horizon (positive looks
            down); roll about the view. All zero: looking along world +x, image right = world -y.
        fx, fy, cx, cy : float
            Intrinsics (px); ``cx, cy`` default to the image centre ``(width / 2, height / 2)``.
        width, height : int
            Image size (px).
        dist : (0,), (4,), (5,) or (8,) float, optional
            OpenCV distortion coefficients; none by default.
        """
        cam2world_R = rpy_to_matrix(roll_rad, pitch_rad, yaw_rad) @ _OPT2BODY
        return cls._from_rotation(cam2world_R, position_m, fx, fy, width, height, cx, cy, dist)

    @classmethod
    def looking_at(cls, position_m: Any, target_m: Any, *, fx: float, fy: float, width: int, height: int,
                   cx: float | None = None, cy: float | None = None, dist: Any = None,
                   up: Any = (0.0, 0.0, 1.0)) -> PinholeCamera:
        """A camera at ``position_m`` (3,), optical axis through ``target_m`` (3,), image up along ``up``."""
        c = np.asarray(position_m, dtype=np.float64)
        z = np.asarray(target_m, dtype=np.float64) - c
        x = np.cross(z, np.asarray(up, dtype=np.float64))
        if np.linalg.norm(z) == 0 or np.linalg.norm(x) < 1e-9 * np.linalg.norm(z):
            raise ConfigError("PinholeCamera.looking_at: target equals position, or view parallel to 'up'")
        z, x = z / np.linalg.norm(z), x / np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z])
        return cls._from_rotation(R, c, fx, fy, width, height, cx, cy, dist)

    @classmethod
    def _from_rotation(cls, cam2world_R: np.ndarray, position_m: Any, fx: float, fy: float, width: int,
                       height: int, cx: float | None, cy: float | None, dist: Any) -> PinholeCamera:
        cx = width / 2.0 if cx is None else cx
        cy = height / 2.0 if cy is None else cy
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        world2cam = invert_transform(make_transform(cam2world_R, position_m))
        return cls(K, np.zeros(0) if dist is None else dist, world2cam, width, height)

    @property
    def cam2world(self) -> np.ndarray:
        """``(4, 4)`` pose of the optical frame in the world."""
        return invert_transform(self.world2cam)

    @property
    def position_m(self) -> np.ndarray:
        """Camera centre in the world, ``(3,)``."""
        return self.cam2world[:3, 3]

    def projection_matrix(self) -> np.ndarray:
        """``P = K [R | t]``, ``(3, 4)``, the undistorted projection."""
        return self.K @ self.world2cam[:3]

    def with_yaw_offset(self, delta_rad: float) -> PinholeCamera:
        """The same camera turned by ``delta_rad`` (CCW seen from above) about the world vertical through its
        centre: seed 000's horizontal misalignment (ALGORITHMS.md A10)."""
        cam2world = self.cam2world
        return replace(self, world2cam=invert_transform(
            make_transform(yaw_to_matrix(delta_rad) @ cam2world[:3, :3], cam2world[:3, 3])))

    def _depth(self, points_world: Any) -> tuple[np.ndarray, np.ndarray]:
        p = transform_points(self.world2cam, _points(points_world, 3, "points_world"))
        return p, p[:, 2]

    def in_front(self, points_world: Any) -> np.ndarray:
        """``(n,) bool``: strictly positive depth along the optical axis (NaN points are False)."""
        return self._depth(points_world)[1] > 0

    def project(self, points_world: Any) -> np.ndarray:
        """World points (n, 3) m to distorted pixels (n, 2), as ``cv2.projectPoints``; behind -> NaN."""
        p, z = self._depth(points_world)
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = p[:, 0] / z, p[:, 1] / z
        coeffs = self.dist.tolist()  # Python floats: scalar arithmetic on tiny arrays costs less than with np.pad's
        k1, k2, p1, p2, k3, k4, k5, k6 = coeffs + [0.0] * (8 - len(coeffs))
        if any(coeffs):
            r2 = x * x + y * y
            radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
            x, y = (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                    y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)
        K = self.K
        uv = np.empty((len(x), 2))
        uv[:, 0] = K[0, 0] * x + K[0, 2]
        uv[:, 1] = K[1, 1] * y + K[1, 2]
        uv[~(z > 0)] = np.nan
        return uv

    def undistort_pixels(self, uv: Any, normalized: bool = False) -> np.ndarray:
        """Remove lens distortion from pixels (n, 2): ideal pixels, or normalised ``(x/z, y/z)`` if asked."""
        uv = _points(uv, 2, "uv")
        out = np.full_like(uv, np.nan)
        ok = np.all(np.isfinite(uv), axis=1)
        if ok.any():
            crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
            res = cv2.undistortPoints(uv[ok].reshape(-1, 1, 2), self.K, self.dist, R=None,
                                      P=None if normalized else self.K, criteria=crit)
            out[ok] = res.reshape(-1, 2)
        return out

    def backproject_to_floor(self, uv: Any, floor_z: float = 0.0) -> np.ndarray:
        """Intersect the viewing rays of pixels ``(n, 2)`` with the plane ``Z = floor_z``; ``(n, 3)`` m.

        Rays parallel to the plane or pointing away from it (above the horizon) give NaN rows.
        """
        xy = self.undistort_pixels(uv, normalized=True)
        rays = np.column_stack([xy, np.ones(len(xy))]) @ self.world2cam[:3, :3]  # cam -> world directions
        centre = self.position_m
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (floor_z - centre[2]) / rays[:, 2]
        s[~(np.isfinite(s) & (s > 0))] = np.nan
        return centre + s[:, None] * rays

    def person_box(self, feet_xy: Any, height_m: Any = 1.70, width_ratio: float = 0.40) -> np.ndarray:
        """Image boxes (n, 4) of upright people standing at ``feet_xy`` (n, 2) m, ``height_m`` (n,) or scalar.

        seed 001 / ALGORITHMS.md B11: project the bottom and top of the vertical segment (with distortion);
        NaN rows where either end is behind the camera.
        """
        seg, n = _feet_segments(feet_xy, height_m)
        uv = self.project(seg)
        return _box_from_segment(uv[:n], uv[n:], width_ratio)


# ---- DLT (ALGORITHMS.md X6) and rigid registration (X7) ------------------------------------------


def _homogeneous_apply(M: np.ndarray, pts: np.ndarray) -> np.ndarray:
    h = pts @ M[:, :-1].T + M[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = h[:, :2] / h[:, 2:]
    out[h[:, 2] == 0] = np.nan
    return out


def apply_homography(H: Any, pts: Any) -> np.ndarray:
    """Map ``(n, 2)`` points through a ``(3, 3)`` homography; points sent to infinity are NaN."""
    return _homogeneous_apply(np.asarray(H, dtype=np.float64), _points(pts, 2, "pts"))


def project_with_matrix(P: Any, pts3: Any) -> np.ndarray:
    """Project world points (n, 3) with a (3, 4) camera matrix to pixels (n, 2), without distortion."""
    return _homogeneous_apply(np.asarray(P, dtype=np.float64), _points(pts3, 3, "pts3"))


def person_box_from_matrix(P: Any, feet_xy: Any, height_m: Any = 1.70,
                           width_ratio: float = 0.40) -> np.ndarray:
    """:meth:`PinholeCamera.person_box` with a DLT-calibrated ``(3, 4)`` matrix ``P`` (ALGORITHMS.md B11)."""
    seg, n = _feet_segments(feet_xy, height_m)
    uv = project_with_matrix(P, seg)
    return _box_from_segment(uv[:n], uv[n:], width_ratio)


def reprojection_rms(M: Any, src: Any, dst: Any) -> float:
    """RMS over the ``2n`` pixel coordinates of ``M(src) - dst`` (Hartley & Zisserman's residual error).

    ``M`` is a ``(3, 3)`` homography with ``src (n, 2)`` or a ``(3, 4)`` camera matrix with ``src (n, 3)``;
    isotropic noise of σ px per coordinate gives about σ.
    """
    M = np.asarray(M, dtype=np.float64)
    src = _points(src, M.shape[1] - 1, "src")
    return float(np.sqrt(np.mean((_homogeneous_apply(M, src) - _points(dst, 2, "dst")) ** 2)))


def _hartley(pts: np.ndarray) -> np.ndarray:
    """Similarity ``(d+1, d+1)`` moving the centroid to 0 and the mean distance to sqrt(d)."""
    d = pts.shape[1]
    c = pts.mean(axis=0)
    scale = np.sqrt(d) / np.mean(np.linalg.norm(pts - c, axis=1))
    return make_transform(np.eye(d) * scale, -scale * c)


def _check_spread(pts: np.ndarray, min_rank: int, name: str, what: str) -> None:
    s = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
    if s[0] == 0 or np.sum(s > 1e-9 * s[0]) < min_rank:
        raise CalibrationError(f"{name}: the {len(pts)} points are {what}; the fit is degenerate")


def _dlt(src: np.ndarray, dst: np.ndarray, refine: bool) -> np.ndarray:
    Ts, Td = _hartley(src), _hartley(dst)
    xs = np.column_stack([src, np.ones(len(src))]) @ Ts.T
    xd = (np.column_stack([dst, np.ones(len(dst))]) @ Td.T)[:, :2]
    n, k = xs.shape
    zero = np.zeros_like(xs)
    A = np.vstack([np.hstack([xs, zero, -xd[:, :1] * xs]), np.hstack([zero, xs, -xd[:, 1:] * xs])])
    _, s, vt = np.linalg.svd(A, full_matrices=True)
    if np.sum(s > 1e-10 * s[0]) < 3 * k - 1:
        raise CalibrationError(f"DLT: the {n} correspondences do not determine a unique solution (degenerate "
                               "configuration, e.g. too many points on one line)")
    M = vt[-1].reshape(3, k)
    sm = np.linalg.svd(M, compute_uv=False)
    if sm[2] < 1e-9 * sm[0]:  # e.g. 3 collinear source points mapped to 3 non-collinear ones
        raise CalibrationError(f"DLT: the {n} correspondences are degenerate (the best fit is singular)")
    if refine and 2 * n > 3 * k:  # Levenberg–Marquardt on the (normalised) reprojection error
        def residual(m: np.ndarray) -> np.ndarray:
            return (_homogeneous_apply(m.reshape(3, k), xs[:, :-1]) - xd).ravel()
        M = least_squares(residual, M.ravel() / np.linalg.norm(M), method="lm").x.reshape(3, k)
    return np.linalg.inv(Td) @ M @ Ts


def _validated_pairs(src: Any, dst: Any, d: int, n_min: int, what: str) -> tuple[np.ndarray, np.ndarray]:
    src, dst = _points(src, d, "src"), _points(dst, 2, "dst")
    if len(src) != len(dst):
        raise ValueError(f"{what}: {len(src)} source points but {len(dst)} destination points")
    if len(src) < n_min:
        raise CalibrationError(f"{what}: {len(src)} point pairs given, at least {n_min} are needed")
    if not (np.all(np.isfinite(src)) and np.all(np.isfinite(dst))):
        raise CalibrationError(f"{what}: the point pairs contain NaN or infinite values")
    return src, dst


def fit_homography(src: Any, dst: Any, refine: bool = False) -> np.ndarray:
    """Homography ``H`` (3, 3), ``H[2, 2] = 1`` where possible, with ``dst ~ H src``; ``(n, 2)`` each, n >= 4.

    Normalised DLT (ALGORITHMS.md X6), optionally refined by Levenberg–Marquardt on the reprojection error.
    """
    src, dst = _validated_pairs(src, dst, 2, 4, "fit_homography")
    _check_spread(src, 2, "fit_homography src", "collinear")
    _check_spread(dst, 2, "fit_homography dst", "collinear")
    H = _dlt(src, dst, refine)
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 * np.linalg.norm(H) else H / np.linalg.norm(H)


def fit_projection_matrix(world: Any, pixels: Any, refine: bool = False) -> np.ndarray:
    """Camera matrix ``P`` (3, 4) from world ``(n, 3)`` m and pixels ``(n, 2)``, n >= 6 non-coplanar points.

    Normalised DLT (ALGORITHMS.md X6, B11). ``P`` is scaled so that ``||P[2, :3]|| = 1`` and
    ``det P[:, :3] > 0``, making the third homogeneous coordinate the depth in front of the camera.
    """
    world, pixels = _validated_pairs(world, pixels, 3, 6, "fit_projection_matrix")
    _check_spread(world, 3, "fit_projection_matrix world", "coplanar")
    _check_spread(pixels, 2, "fit_projection_matrix pixels", "collinear")
    P = _dlt(world, pixels, refine)
    P = P / np.linalg.norm(P[2, :3])
    return -P if np.linalg.det(P[:, :3]) < 0 else P


def fit_rigid_2d(a: Any, b: Any) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``R`` (2, 2), ``det R = +1``, and translation ``t`` (2,) minimising ``Σ ||b - (R a + t)||²``.

    Kabsch on ``a, b`` (n, 2), n >= 2 (ALGORITHMS.md X7); seed 001 multi-laser registration (B2).
    """
    a, b = _validated_pairs(a, b, 2, 2, "fit_rigid_2d")
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    if np.allclose(a, ca, rtol=0, atol=1e-12) or np.allclose(b, cb, rtol=0, atol=1e-12):
        raise CalibrationError(f"fit_rigid_2d: all {len(a)} points coincide, so the rotation is undetermined")
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    D = np.diag([1.0, np.sign(np.linalg.det(vt.T @ u.T)) or 1.0])
    R = vt.T @ D @ u.T
    return R, cb - R @ ca
