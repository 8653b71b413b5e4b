"""Global calibration of N cameras and M lasers into one metric road frame (ALGORITHMS.md D1).

seed 003 (P003): "off-line calibration to define a global coordinate system … calibration matrices". The road
frame is the simulator's world frame: metric ``(X, Y)`` on the road plane, ``Z`` up.

* Camera ``c``: a ground-plane homography ``H_c`` (``image2road``, 3 x 3) from *ideal* (undistorted) pixels to
  road metres, and its inverse ``road2image``. Lens distortion, when the camera's model is known (``K`` and
  OpenCV coefficients), is removed from pixels before ``H_c`` and put back after ``road2image``; without a lens
  model the pixels are used as measured. ``H_c`` is scaled so that the third homogeneous coordinate of
  ``H_c (u, v, 1)`` is positive (``1 / depth``) for pixels below the horizon: pixels above it map to NaN, and
  road points behind the camera project to NaN.
* Laser ``l``: a rigid 2-D transform ``(R_l, t_l)``, ``p_road = R_l p_laser + t_l``.

Two sources: surveyed control points (:func:`read_control_points`, :func:`calibrate_road`: normalised DLT X6
fitted road -> image and refined by Levenberg–Marquardt on the pixel error, and Kabsch X7), or a recording's
believed calibration (:func:`road_calibration_from_recording`: ``CameraInfo`` + the ``<sensor>_calibrated``
poses of ``/tf_static``). :meth:`RoadCalibration.road_covariance` propagates pixel noise through ``H_c`` (D5's
``Σ_c``, it grows with distance). A calibration saves to JSON and loads back exactly.
"""

from __future__ import annotations

import csv
import json
import logging
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from fusiontrack.errors import CalibrationError, ConfigError, RecordingError
from fusiontrack.geometry import PinholeCamera, TransformTree, fit_homography, fit_rigid_2d
from fusiontrack.io.recording import Recording
from fusiontrack.types import CameraInfo

__all__ = [
    "CONTROL_POINT_COLUMNS",
    "CameraCalibration",
    "ControlPoints",
    "LaserCalibration",
    "RoadCalibration",
    "SensorResidual",
    "calibrate_road",
    "format_residual_table",
    "ground_homography",
    "read_control_points",
    "residual_table",
    "road_calibration_from_recording",
]

log = logging.getLogger(__name__)

CONTROL_POINT_COLUMNS = ("sensor", "kind", "a", "b", "x", "y")
"""Header of a road control-point CSV: ``kind`` ``camera`` -> ``a, b`` = pixel ``(u, v)``; ``laser`` -> ``a, b`` =
``(x, y)`` in the laser frame (m); ``x, y`` = the surveyed road coordinates (m)."""

KINDS = ("camera", "laser")
MIN_POINTS = {"camera": 4, "laser": 2}
RECOMMENDED_CAMERA_POINTS = 8  # ALGORITHMS.md D1: ">= 8 recommended, spread out"
COLLINEAR_RATIO = 1e-3
"""Point sets whose second singular value (centred) is below this fraction of the first are collinear."""

JSON_FORMAT = "fusiontrack.road_calibration"
JSON_VERSION = 1


# ---- Records ---------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SensorResidual:
    """Fit residuals of one sensor at its control points (per-point Euclidean distances).

    Attributes
    ----------
    n : int
        Number of control points.
    rms_m, max_m : float
        RMS and maximum road-plane distance between the mapped sensor point and the surveyed point (m).
    rms_px, max_px : float
        Cameras: RMS and maximum pixel distance between the surveyed point projected into the image and the
        measured pixel; NaN for lasers.
    """

    n: int
    rms_m: float
    max_m: float
    rms_px: float = math.nan
    max_px: float = math.nan

    @classmethod
    def from_errors(cls, err_m: np.ndarray, err_px: np.ndarray | None = None) -> SensorResidual:
        """From per-point distances ``(n,)`` m (and px)."""
        def rms(e: np.ndarray) -> float:
            return float(np.sqrt(np.mean(e**2)))
        px = (math.nan, math.nan) if err_px is None else (rms(err_px), float(np.max(err_px)))
        return cls(int(err_m.size), rms(err_m), float(np.max(err_m)), *px)


def _matrix(value: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    arr = np.array(value, dtype=np.float64)
    if arr.shape != shape or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{what}: expected a finite array of shape {shape}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


def _lens(K: np.ndarray | None, dist: np.ndarray, width: int, height: int) -> PinholeCamera | None:
    """A camera at the origin carrying only the lens (K, distortion), or None when there is no distortion."""
    if K is None or not np.any(dist != 0):
        return None
    return PinholeCamera(K, dist, np.eye(4), max(width, 1), max(height, 1))


@dataclass(frozen=True, slots=True, eq=False)
class CameraCalibration:
    """A camera's ground-plane homography (ALGORITHMS.md D1).

    Attributes
    ----------
    name : str
    image2road : (3, 3) float64
        ``H_c``: ideal pixels -> road metres; positive third coordinate below the horizon.
    road2image : (3, 3) float64
        Its inverse, road metres -> ideal pixels.
    K : (3, 3) float64 or None
        Intrinsics of the lens model; None when pixels are used as measured.
    dist : (k,) float64
        OpenCV distortion coefficients (empty: none).
    width, height : int
        Image size in pixels (0 when unknown).
    residual : SensorResidual or None
        Residuals at the control points; None when not calibrated from points.
    """

    name: str
    image2road: np.ndarray
    road2image: np.ndarray
    K: np.ndarray | None = None
    dist: np.ndarray = field(default_factory=lambda: np.zeros(0))
    width: int = 0
    height: int = 0
    residual: SensorResidual | None = None
    _lens: PinholeCamera | None = field(init=False, repr=False, default=None)

    def __post_init__(self) -> None:
        what = f"camera {self.name!r}"
        object.__setattr__(self, "image2road", _matrix(self.image2road, (3, 3), f"{what} image2road"))
        object.__setattr__(self, "road2image", _matrix(self.road2image, (3, 3), f"{what} road2image"))
        if self.K is not None:
            object.__setattr__(self, "K", _matrix(self.K, (3, 3), f"{what} K"))
        dist = np.array(self.dist, dtype=np.float64).ravel()
        dist.setflags(write=False)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        if abs(np.linalg.det(self.image2road)) < 1e-300:
            raise CalibrationError(f"{what}: the homography image2road is singular")
        try:
            object.__setattr__(self, "_lens", _lens(self.K, dist, self.width, self.height))
        except ConfigError as err:
            raise ConfigError(f"{what}: {err}") from err

    @property
    def has_distortion(self) -> bool:
        """Whether pixels are undistorted before the homography."""
        return self._lens is not None

    def undistort(self, uv: Any) -> np.ndarray:
        """Measured pixels ``(n, 2)`` -> ideal pixels ``(n, 2)`` (a copy when there is no distortion)."""
        uv = np.array(uv, dtype=np.float64).reshape(-1, 2)
        return uv if self._lens is None else self._lens.undistort_pixels(uv)

    def distort(self, uv_ideal: Any) -> np.ndarray:
        """Ideal pixels ``(n, 2)`` -> measured (distorted) pixels ``(n, 2)``."""
        uv = np.array(uv_ideal, dtype=np.float64).reshape(-1, 2)
        if self._lens is None:
            return uv
        K = self._lens.K
        xy = (uv - K[:2, 2]) / np.diag(K)[:2]
        return self._lens.project(np.column_stack([xy, np.ones(len(xy))]))

    def image_to_road(self, uv: Any) -> np.ndarray:
        """Pixels ``(n, 2)`` -> road points ``(n, 2)`` m; NaN above the horizon or for NaN pixels."""
        h = np.column_stack([self.undistort(uv), np.ones(len(np.reshape(uv, (-1, 2))))]) @ self.image2road.T
        with np.errstate(divide="ignore", invalid="ignore"):
            out = h[:, :2] / h[:, 2:]
        out[~(h[:, 2] > 0)] = np.nan
        return out

    def road_to_image(self, xy: Any) -> np.ndarray:
        """Road points ``(n, 2)`` m -> pixels ``(n, 2)`` (distorted, as measured); NaN behind the camera."""
        xy = np.array(xy, dtype=np.float64).reshape(-1, 2)
        h = np.column_stack([xy, np.ones(len(xy))]) @ self.road2image.T
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = h[:, :2] / h[:, 2:]
        uv[~(h[:, 2] > 0)] = np.nan
        return self.distort(uv)

    def jacobian(self, uv: Any) -> np.ndarray:
        """``d(road) / d(pixel)`` at pixels ``(n, 2)``: ``(n, 2, 2)`` m/px; NaN above the horizon.

        The homography part is analytic, ``J = (H[:2, :2] - p H[2, :2]) / w``; the undistortion part (when the
        lens has distortion) is a central difference of 0.01 px.
        """
        uv = np.array(uv, dtype=np.float64).reshape(-1, 2)
        ideal = self.undistort(uv)
        H = self.image2road
        h = np.column_stack([ideal, np.ones(len(ideal))]) @ H.T
        with np.errstate(divide="ignore", invalid="ignore"):
            p = h[:, :2] / h[:, 2:]
            J = (H[None, :2, :2] - p[:, :, None] * H[None, None, 2, :2]) / h[:, 2, None, None]
        J[~(h[:, 2] > 0)] = np.nan
        if self._lens is not None:
            step = 1e-2
            offsets = np.array([[step, 0.0], [-step, 0.0], [0.0, step], [0.0, -step]])
            shifted = self.undistort((uv[None, :, :] + offsets[:, None, :]).reshape(-1, 2)).reshape(4, -1, 2)
            D = np.stack([shifted[0] - shifted[1], shifted[2] - shifted[3]], axis=-1) / (2 * step)  # (n, 2, 2)
            J = J @ D
        return J


@dataclass(frozen=True, slots=True, eq=False)
class LaserCalibration:
    """A laser's rigid 2-D pose in the road frame, ``p_road = R p_laser + t`` (ALGORITHMS.md D1, X7).

    Attributes
    ----------
    name : str
    R : (2, 2) float64
        Orthogonal; ``det R = +1`` from control points (a reflection only for an upside-down scanner read
        from tf).
    t : (2,) float64
        The laser's position on the road (m).
    residual : SensorResidual or None
    """

    name: str
    R: np.ndarray
    t: np.ndarray
    residual: SensorResidual | None = None

    def __post_init__(self) -> None:
        what = f"laser {self.name!r}"
        R = _matrix(self.R, (2, 2), f"{what} R")
        if not np.allclose(R @ R.T, np.eye(2), atol=1e-6):
            raise ConfigError(f"{what} R: expected an orthogonal (2, 2) rotation, got {R.tolist()}")
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "t", _matrix(self.t, (2,), f"{what} t"))

    @property
    def yaw_rad(self) -> float:
        """Heading of the laser's x axis in the road frame."""
        return float(math.atan2(self.R[1, 0], self.R[0, 0]))

    @property
    def laser2road(self) -> np.ndarray:
        """``(3, 3)`` homogeneous 2-D transform."""
        T = np.eye(3)
        T[:2, :2], T[:2, 2] = self.R, self.t
        return T

    def laser_to_road(self, pts: Any) -> np.ndarray:
        """Laser-frame points ``(n, 2)`` m -> road points ``(n, 2)``; NaN rows stay NaN."""
        return np.asarray(pts, dtype=np.float64).reshape(-1, 2) @ self.R.T + self.t

    def road_to_laser(self, xy: Any) -> np.ndarray:
        """Road points ``(n, 2)`` -> laser-frame points ``(n, 2)`` (e.g. the road polygon for D4's ROI)."""
        return (np.asarray(xy, dtype=np.float64).reshape(-1, 2) - self.t) @ self.R


@dataclass(frozen=True, slots=True, eq=False)
class RoadCalibration:
    """Every sensor's calibration into the road frame (ALGORITHMS.md D1).

    Attributes
    ----------
    cameras : mapping of name -> CameraCalibration
    lasers : mapping of name -> LaserCalibration
    source : str
        Where it came from (control-point file, recording), for messages.
    """

    cameras: Mapping[str, CameraCalibration] = field(default_factory=dict)
    lasers: Mapping[str, LaserCalibration] = field(default_factory=dict)
    source: str = ""

    def __post_init__(self) -> None:
        both = set(self.cameras) & set(self.lasers)
        if both:
            raise ConfigError(f"road calibration {self.source}: sensor(s) {sorted(both)} are both camera and laser")
        for kind, items in (("cameras", self.cameras), ("lasers", self.lasers)):
            for name, item in items.items():
                if item.name != name:
                    raise ConfigError(f"road calibration: {kind}[{name!r}] holds the calibration of {item.name!r}")
            object.__setattr__(self, kind, MappingProxyType(dict(items)))

    @property
    def sensors(self) -> tuple[str, ...]:
        """Camera names, then laser names."""
        return (*self.cameras, *self.lasers)

    def camera(self, name: str) -> CameraCalibration:
        """One camera's calibration; ConfigError naming the known cameras otherwise."""
        try:
            return self.cameras[name]
        except KeyError:
            raise ConfigError(f"road calibration {self.source}: no camera {name!r}; cameras: "
                              f"{list(self.cameras)}") from None

    def laser(self, name: str) -> LaserCalibration:
        """One laser's calibration; ConfigError naming the known lasers otherwise."""
        try:
            return self.lasers[name]
        except KeyError:
            raise ConfigError(f"road calibration {self.source}: no laser {name!r}; lasers: "
                              f"{list(self.lasers)}") from None

    def image_to_road(self, camera: str, uv: Any) -> np.ndarray:
        """Pixels ``(n, 2)`` of ``camera`` -> road points ``(n, 2)`` m (NaN above the horizon)."""
        return self.camera(camera).image_to_road(uv)

    def road_to_image(self, camera: str, xy: Any) -> np.ndarray:
        """Road points ``(n, 2)`` m -> pixels ``(n, 2)`` of ``camera`` (NaN behind it)."""
        return self.camera(camera).road_to_image(xy)

    def laser_to_road(self, laser: str, pts: Any) -> np.ndarray:
        """Points ``(n, 2)`` in ``laser``'s frame -> road points ``(n, 2)``."""
        return self.laser(laser).laser_to_road(pts)

    def road_to_laser(self, laser: str, xy: Any) -> np.ndarray:
        """Road points ``(n, 2)`` -> points ``(n, 2)`` in ``laser``'s frame."""
        return self.laser(laser).road_to_laser(xy)

    def to_road(self, sensor: str, pts: Any) -> np.ndarray:
        """A camera's pixels or a laser's points ``(n, 2)`` -> road points ``(n, 2)``."""
        if sensor in self.cameras:
            return self.cameras[sensor].image_to_road(pts)
        if sensor in self.lasers:
            return self.lasers[sensor].laser_to_road(pts)
        raise ConfigError(f"road calibration {self.source}: no sensor {sensor!r}; sensors: {list(self.sensors)}")

    def road_covariance(self, camera: str, uv: Any, sigma_px: float = 2.0, cov_px2: Any = None) -> np.ndarray:
        """Road-plane covariance ``(n, 2, 2)`` m² of the pixels ``uv`` (n, 2): ``J Σ_px Jᵀ`` (ALGORITHMS.md D5).

        Parameters
        ----------
        camera : str
        uv : (n, 2) float
            Measured pixels (e.g. box bottom centres).
        sigma_px : float
            Isotropic pixel noise (px), used when ``cov_px2`` is None; D5's default is 2 px.
        cov_px2 : (2, 2) or (n, 2, 2) float, optional
            Pixel covariance (px²).

        Returns
        -------
        (n, 2, 2) float64
            NaN for pixels above the horizon; grows with the distance from the camera.
        """
        J = self.camera(camera).jacobian(uv)
        if cov_px2 is None:
            if not (np.isfinite(sigma_px) and sigma_px >= 0):
                raise ConfigError(f"road_covariance: sigma_px must be a finite value >= 0, got {sigma_px}")
            return float(sigma_px) ** 2 * (J @ J.transpose(0, 2, 1))
        S = np.asarray(cov_px2, dtype=np.float64)
        if S.shape not in ((2, 2), (len(J), 2, 2)):
            raise ConfigError(f"road_covariance: cov_px2 must be (2, 2) or ({len(J)}, 2, 2), got {S.shape}")
        return J @ S @ J.transpose(0, 2, 1)

    @classmethod
    def from_models(cls, cameras: Mapping[str, PinholeCamera] | None = None,
                    lasers: Mapping[str, Any] | None = None, source: str = "camera and laser models"
                    ) -> RoadCalibration:
        """From posed camera models (``H_c`` = :func:`ground_homography`, lens kept) and laser poses
        (``laser2road``, (4, 4) 3-D or (3, 3) 2-D, scan plane level)."""
        return cls({n: _camera_from_model(n, c) for n, c in (cameras or {}).items()},
                   {n: _laser_from_pose(n, T) for n, T in (lasers or {}).items()}, source)

    def merged(self, other: RoadCalibration) -> RoadCalibration:
        """This calibration with ``other``'s sensors added or replacing (e.g. control points over tf)."""
        cams = {k: v for k, v in self.cameras.items() if k not in other.lasers} | dict(other.cameras)
        lasers = {k: v for k, v in self.lasers.items() if k not in other.cameras} | dict(other.lasers)
        return RoadCalibration(cams, lasers, f"{self.source} + {other.source}")

    # ---- JSON --------------------------------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (floats kept exactly; NaN as null)."""
        return {
            "format": JSON_FORMAT, "version": JSON_VERSION, "frame": "road", "source": self.source,
            "cameras": {n: {"image2road": c.image2road.tolist(), "road2image": c.road2image.tolist(),
                            "K": None if c.K is None else c.K.tolist(), "dist": c.dist.tolist(),
                            "width": c.width, "height": c.height, "residual": _residual_to_json(c.residual)}
                        for n, c in self.cameras.items()},
            "lasers": {n: {"R": las.R.tolist(), "t": las.t.tolist(), "yaw_rad": las.yaw_rad,
                           "residual": _residual_to_json(las.residual)} for n, las in self.lasers.items()},
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "road calibration") -> RoadCalibration:
        """Inverse of :meth:`to_dict`; ConfigError naming ``where`` and the key on bad content."""
        if not isinstance(data, Mapping) or data.get("format") != JSON_FORMAT:
            raise ConfigError(f"{where}: not a road calibration (expected \"format\": \"{JSON_FORMAT}\")")
        if data.get("version") != JSON_VERSION:
            raise ConfigError(f"{where}: unsupported version {data.get('version')!r} (expected {JSON_VERSION})")
        cameras, lasers = {}, {}
        try:
            for name, c in dict(data.get("cameras") or {}).items():
                key = f"{where}: cameras.{name}"
                cam = CameraCalibration(name, _json_array(c, "image2road", key), _json_array(c, "road2image", key),
                                        None if c.get("K") is None else _json_array(c, "K", key),
                                        _json_array(c, "dist", key), int(c.get("width", 0)),
                                        int(c.get("height", 0)), _residual_from_json(c.get("residual"), key))
                prod = cam.image2road @ cam.road2image
                if not np.allclose(prod / prod[2, 2], np.eye(3), atol=1e-6):
                    raise ConfigError(f"{key}: road2image is not the inverse of image2road")
                cameras[name] = cam
            for name, item in dict(data.get("lasers") or {}).items():
                key = f"{where}: lasers.{name}"
                lasers[name] = LaserCalibration(name, _json_array(item, "R", key), _json_array(item, "t", key),
                                                _residual_from_json(item.get("residual"), key))
        except (TypeError, ValueError, AttributeError) as err:
            raise ConfigError(f"{where}: malformed calibration: {err}") from err
        return cls(cameras, lasers, str(data.get("source", "")))

    def save(self, path: str | Path) -> Path:
        """Write the calibration as JSON; returns the path."""
        path = Path(path)
        try:
            path.write_text(json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n", encoding="utf-8")
        except OSError as err:
            raise ConfigError(f"{path}: cannot write the road calibration ({err.strerror or err})") from err
        return path

    @classmethod
    def load(cls, path: str | Path) -> RoadCalibration:
        """Read a calibration written by :meth:`save`."""
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError as err:
            raise ConfigError(f"{path}: no such file (expected a road calibration JSON)") from err
        except (OSError, UnicodeDecodeError) as err:
            raise ConfigError(f"{path}: cannot be read ({err})") from err
        except json.JSONDecodeError as err:
            raise ConfigError(f"{path}, line {err.lineno}: not valid JSON ({err.msg})") from err
        return cls.from_dict(data, str(path))


def _residual_to_json(r: SensorResidual | None) -> dict[str, Any] | None:
    if r is None:
        return None
    return {"n": r.n, **{k: (None if math.isnan(v) else v) for k, v in
                         (("rms_m", r.rms_m), ("max_m", r.max_m), ("rms_px", r.rms_px), ("max_px", r.max_px))}}


def _residual_from_json(d: Any, where: str) -> SensorResidual | None:
    if d is None:
        return None
    if not isinstance(d, Mapping):
        raise ConfigError(f"{where}.residual: expected an object or null, got {d!r}")
    vals = {k: math.nan if d.get(k) is None else float(d[k]) for k in ("rms_m", "max_m", "rms_px", "max_px")}
    return SensorResidual(int(d.get("n", 0)), **vals)


def _json_array(d: Any, key: str, where: str) -> np.ndarray:
    if not isinstance(d, Mapping) or key not in d:
        raise ConfigError(f"{where}: missing key {key!r}")
    try:
        return np.array(d[key], dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"{where}.{key}: expected numbers, got {d[key]!r}") from err


# ---- Homographies from camera models ---------------------------------------------------------------------------


def ground_homography(camera: PinholeCamera) -> np.ndarray:
    """``image2road`` ``(3, 3)`` of a posed camera: ideal pixels -> world floor ``Z = 0``.

    ``road2image = K [r1 r2 t]`` (the columns of ``world2cam`` for ``X``, ``Y`` and the translation); its
    inverse has third coordinate ``1 / depth > 0`` in front of the camera. Scaled by a positive factor to
    ``|H[2, 2]| = 1`` where that is possible (``H[2, 2]`` is 0 when the world origin is on the horizon); the
    sign is kept, as it tells the visible road from the sky.
    """
    M = camera.K @ camera.world2cam[:3][:, [0, 1, 3]]
    if abs(np.linalg.det(M)) < 1e-12 * np.linalg.norm(M) ** 3:
        raise CalibrationError("ground_homography: the camera centre is on the road plane (degenerate view)")
    return _positive_scale(np.linalg.inv(M))


def _positive_scale(H: np.ndarray) -> np.ndarray:
    s = abs(H[2, 2]) if abs(H[2, 2]) > 1e-9 * np.linalg.norm(H) else np.linalg.norm(H)
    return H / s


def _camera_from_model(name: str, camera: PinholeCamera, residual: SensorResidual | None = None
                       ) -> CameraCalibration:
    H = ground_homography(camera)
    return CameraCalibration(name, H, np.linalg.inv(H), camera.K, camera.dist, camera.width, camera.height,
                             residual)


def _laser_from_pose(name: str, laser2road: Any) -> LaserCalibration:
    """From a ``(4, 4)`` 3-D pose (or ``(3, 3)`` 2-D pose) of a laser whose scan plane is level."""
    T = np.asarray(laser2road, dtype=np.float64)
    if T.shape == (4, 4):
        tilt_deg = math.degrees(math.acos(min(1.0, abs(T[2, 2]))))
        if tilt_deg > 5.0:
            log.warning("laser %r: the scan plane is tilted by %.1f deg from the road; the 2-D transform "
                        "ignores it", name, tilt_deg)
    elif T.shape != (3, 3):
        raise ConfigError(f"laser {name!r}: expected a (4, 4) or (3, 3) pose, got {T.shape}")
    u, _, vt = np.linalg.svd(T[:2, :2])  # nearest orthogonal matrix (polar decomposition)
    return LaserCalibration(name, u @ vt, T[:2, -1])


# ---- Control points ----------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class ControlPoints:
    """Surveyed control points of several sensors (one row each).

    Attributes
    ----------
    sensors, kinds : tuple of str, length n
        Sensor name and ``"camera"`` or ``"laser"``.
    sensor_xy : (n, 2) float64
        Pixel ``(u, v)`` (cameras) or laser-frame ``(x, y)`` m (lasers).
    road_xy : (n, 2) float64
        Surveyed road coordinates (m).
    lines : (n,) int64
        1-based line of each row in ``source`` (row number for points built in memory).
    source : str
        The file, for messages.
    """

    sensors: tuple[str, ...]
    kinds: tuple[str, ...]
    sensor_xy: np.ndarray
    road_xy: np.ndarray
    lines: np.ndarray | None = None
    source: str = "<control points>"

    def __post_init__(self) -> None:
        sensors, kinds = tuple(map(str, self.sensors)), tuple(str(k).strip().lower() for k in self.kinds)
        n = len(sensors)
        a = np.array(self.sensor_xy, dtype=np.float64).reshape(-1, 2) if n else np.zeros((0, 2))
        b = np.array(self.road_xy, dtype=np.float64).reshape(-1, 2) if n else np.zeros((0, 2))
        lines = np.arange(1, n + 1) if self.lines is None else np.asarray(self.lines, dtype=np.int64).ravel()
        if not len(kinds) == len(a) == len(b) == len(lines) == n:
            raise ConfigError(f"{self.source}: control points of unequal lengths: {n} sensors, {len(kinds)} kinds, "
                              f"{len(a)} sensor points, {len(b)} road points, {len(lines)} lines")
        for i in range(n):
            if kinds[i] not in KINDS:
                raise ConfigError(f"{self.source}, line {lines[i]} (sensor {sensors[i]!r}): kind must be 'camera' "
                                  f"or 'laser', got {kinds[i]!r}")
        bad = ~np.all(np.isfinite(np.hstack([a, b])), axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise ConfigError(f"{self.source}, line {lines[i]} (sensor {sensors[i]!r}): non-finite value")
        for name, arr in (("sensor_xy", a), ("road_xy", b), ("lines", lines)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "sensors", sensors)
        object.__setattr__(self, "kinds", kinds)

    def __len__(self) -> int:
        return len(self.sensors)

    def groups(self) -> dict[str, np.ndarray]:
        """Row indices of each sensor, in order of first appearance."""
        names = np.array(self.sensors, dtype=object)
        return {s: np.flatnonzero(names == s) for s in dict.fromkeys(self.sensors)}


def read_control_points(path: str | Path) -> ControlPoints:
    """Road control points from a CSV file with the header ``sensor,kind,a,b,x,y`` (any order, extra columns
    ignored; blank lines and lines starting with ``#`` skipped).

    Raises
    ------
    ConfigError
        Missing file, missing column, wrong number of fields, unknown kind, a value that is not a finite number
        (the file, line and sensor are named).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError as err:
        raise ConfigError(f"{path}: no such file (expected road control points {','.join(CONTROL_POINT_COLUMNS)})"
                          ) from err
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path}: cannot be read as text ({err})") from err
    rows = [(i, r) for i, r in enumerate(csv.reader(text.splitlines()), start=1)
            if r and any(f.strip() for f in r) and not r[0].lstrip().startswith("#")]
    if not rows:
        raise ConfigError(f"{path}: empty (expected the header {','.join(CONTROL_POINT_COLUMNS)} and points)")
    header_line, header = rows[0]
    names = [h.strip().lower() for h in header]
    missing = [c for c in CONTROL_POINT_COLUMNS if c not in names]
    if missing:
        raise ConfigError(f"{path}, line {header_line}: missing column(s) {', '.join(missing)} in the header "
                          f"{','.join(h.strip() for h in header)!r}; expected {','.join(CONTROL_POINT_COLUMNS)}")
    col = {c: names.index(c) for c in CONTROL_POINT_COLUMNS}
    if len(rows) == 1:
        raise ConfigError(f"{path}: no control points after the header")
    sensors, kinds, values, lines = [], [], [], []
    for lineno, r in rows[1:]:
        if len(r) != len(header):
            raise ConfigError(f"{path}, line {lineno}: expected {len(header)} comma-separated fields, got {len(r)}")
        sensor = r[col["sensor"]].strip()
        if not sensor:
            raise ConfigError(f"{path}, line {lineno}: empty sensor name")
        vals = []
        for c in ("a", "b", "x", "y"):
            try:
                v = float(r[col[c]])
            except ValueError:
                raise ConfigError(f"{path}, line {lineno} (sensor {sensor!r}): column {c!r} is not a number: "
                                  f"{r[col[c]].strip()[:40]!r}") from None
            if not math.isfinite(v):
                raise ConfigError(f"{path}, line {lineno} (sensor {sensor!r}): column {c!r} is not finite: {v}")
            vals.append(v)
        sensors.append(sensor)
        kinds.append(r[col["kind"]])
        values.append(vals)
        lines.append(lineno)
    v = np.array(values)
    return ControlPoints(tuple(sensors), tuple(kinds), v[:, :2], v[:, 2:], np.array(lines), str(path))


def _spread_ratio(pts: np.ndarray) -> float:
    s = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
    return float(s[1] / s[0]) if s[0] > 0 else 0.0


def _fit_camera(name: str, uv: np.ndarray, xy: np.ndarray, where: str, lens: PinholeCamera | CameraInfo | None,
                refine: bool) -> CameraCalibration:
    K, dist, width, height = None, np.zeros(0), 0, 0
    if lens is not None:
        K, dist = np.asarray(lens.K, np.float64), np.asarray(getattr(lens, "dist", getattr(lens, "D", ())))
        width, height = int(lens.width), int(lens.height)
    probe = CameraCalibration(name, np.eye(3), np.eye(3), K, dist, width, height)
    ideal = probe.undistort(uv)
    for what, pts, unit in (("pixels", ideal, "px"), ("road points", xy, "m")):
        if _spread_ratio(pts) < COLLINEAR_RATIO:
            raise CalibrationError(f"{where}: the {len(pts)} control {what} of camera {name!r} are collinear "
                                   f"(or coincide); a homography needs points spread over the road ({unit})")
    try:  # road -> image, so that the refinement minimises the error where the noise is: in pixels
        G = fit_homography(xy, ideal, refine=refine and len(uv) > MIN_POINTS["camera"])
    except CalibrationError as err:
        raise CalibrationError(f"{where}: camera {name!r}: {err}") from err
    H = np.linalg.inv(G)
    w = np.column_stack([ideal, np.ones(len(ideal))]) @ H[2]
    H = _positive_scale(H * (1.0 if np.sum(np.sign(w)) >= 0 else -1.0))
    if np.any(np.column_stack([ideal, np.ones(len(ideal))]) @ H[2] <= 0):
        raise CalibrationError(f"{where}: camera {name!r}: the fitted horizon cuts through the control points "
                               "(a point is mislabelled or the points do not lie on one plane)")
    cam = CameraCalibration(name, H, np.linalg.inv(H), K, dist, width, height)
    err_m = np.linalg.norm(cam.image_to_road(uv) - xy, axis=1)
    err_px = np.linalg.norm(cam.road_to_image(xy) - uv, axis=1)
    return CameraCalibration(name, H, cam.road2image, K, dist, width, height,
                             SensorResidual.from_errors(err_m, err_px))


def _fit_laser(name: str, pts: np.ndarray, xy: np.ndarray, where: str) -> LaserCalibration:
    try:
        R, t = fit_rigid_2d(pts, xy)
    except CalibrationError as err:
        raise CalibrationError(f"{where}: laser {name!r}: {err}") from err
    err_m = np.linalg.norm(pts @ R.T + t - xy, axis=1)
    return LaserCalibration(name, R, t, SensorResidual.from_errors(err_m))


def calibrate_road(points: ControlPoints | str | Path, *,
                   lenses: Mapping[str, PinholeCamera | CameraInfo] | None = None, refine: bool = True,
                   warn_rms_m: float = 0.25, warn_rms_px: float = 3.0) -> RoadCalibration:
    """Every sensor's road calibration from control points (ALGORITHMS.md D1).

    Cameras: normalised DLT homography (X6) road -> (undistorted) pixels, refined by Levenberg–Marquardt when
    there are more than 4 points, then inverted: the fit minimises the error in pixels, where the noise is (a
    pixel at 40 m is tens of centimetres of road, so a fit in road metres would be dominated by far points).
    Lasers: Kabsch (X7).

    Parameters
    ----------
    points : ControlPoints or path
        Control points, or a CSV file for :func:`read_control_points`.
    lenses : mapping of camera name -> PinholeCamera or CameraInfo, optional
        Lens models (``K`` and distortion; the pose is not used): the pixels of these cameras are undistorted
        before the fit and :meth:`CameraCalibration.image_to_road` undistorts likewise. Other cameras use the
        pixels as measured.
    refine : bool
        Levenberg–Marquardt refinement of the DLT.
    warn_rms_m, warn_rms_px : float
        A warning is logged when a sensor's RMS residual exceeds these (m for every sensor, px for cameras).

    Raises
    ------
    ConfigError
        Bad file (see :func:`read_control_points`), or one sensor listed both as camera and as laser.
    CalibrationError
        Fewer than 4 camera / 2 laser points, collinear camera points or coincident laser points (the file,
        lines and sensor are named).
    """
    if not isinstance(points, ControlPoints):
        points = read_control_points(points)
    if not len(points):
        raise CalibrationError(f"{points.source}: no control points")
    lenses = dict(lenses or {})
    cameras: dict[str, CameraCalibration] = {}
    lasers: dict[str, LaserCalibration] = {}
    for name, idx in points.groups().items():
        lines = points.lines[idx]
        kinds = {points.kinds[i] for i in idx}
        where = f"{points.source}, lines {_lines_text(lines)}"
        if len(kinds) > 1:
            raise ConfigError(f"{where}: sensor {name!r} is listed both as camera and as laser")
        kind = kinds.pop()
        need = MIN_POINTS[kind]
        if len(idx) < need:
            raise CalibrationError(f"{where}: {kind} {name!r} has {len(idx)} control point(s); at least {need} "
                                   "are needed")
        a, xy = points.sensor_xy[idx], points.road_xy[idx]
        fitted: CameraCalibration | LaserCalibration
        if kind == "camera":
            fitted = cameras[name] = _fit_camera(name, a, xy, where, lenses.get(name), refine)
        else:
            fitted = lasers[name] = _fit_laser(name, a, xy, where)
        if fitted.residual is not None:
            _log_residual(points.source, kind, name, fitted.residual, warn_rms_m, warn_rms_px)
    return RoadCalibration(cameras, lasers, f"control points {points.source}")


def _lines_text(lines: np.ndarray) -> str:
    shown = ", ".join(str(int(v)) for v in lines[:12])
    return shown + (f", … ({len(lines)} in all)" if len(lines) > 12 else "")


def _log_residual(source: str, kind: str, name: str, res: SensorResidual, warn_m: float, warn_px: float) -> None:
    px = f", {res.rms_px:.2f} px RMS (max {res.max_px:.2f} px)" if kind == "camera" else ""
    text = f"{source}: {kind} {name!r}: {res.n} points, residual {res.rms_m:.3f} m RMS (max {res.max_m:.3f} m){px}"
    if res.rms_m > warn_m or (kind == "camera" and res.rms_px > warn_px):
        log.warning("%s: large residual, check the control points (a mislabelled point, a point off the road "
                    "plane)", text)
    elif kind == "camera" and res.n == MIN_POINTS["camera"]:
        log.warning("%s: 4 points fit exactly, so the residual cannot reveal an error; %d or more spread-out "
                    "points are recommended", text, RECOMMENDED_CAMERA_POINTS)
    else:
        log.info("%s", text)


# ---- From a recording's believed calibration ---------------------------------------------------------------------


def _first_messages(rec: Recording, msgtype: str) -> dict[str, str]:
    return {rec.sensor_of(t): t for t, m in rec.topic_types().items() if m == msgtype}


def _pose_frame(tree: TransformTree, candidates: Iterable[str], world_frame: str) -> str | None:
    return next((f for f in candidates if f and tree.has_path(f, world_frame)), None)


def road_calibration_from_recording(rec: Recording | str | Path, *, world_frame: str = "world",
                                    cameras: Iterable[str] | None = None, lasers: Iterable[str] | None = None,
                                    use_calibrated: bool = True) -> RoadCalibration:
    """The road calibration a recording believes: ``CameraInfo`` + camera poses and laser poses from tf.

    Each sensor's pose is that of ``<sensor>_calibrated`` (what the user believes; the simulator writes the true
    pose as ``<sensor>``) when ``use_calibrated`` and present, else of ``<sensor>``, else of the message's
    ``frame_id``. Camera distortion in ``CameraInfo`` is kept: pixels are undistorted before ``H_c``.

    Parameters
    ----------
    rec : Recording or path
    world_frame : str
        The road frame's name in tf.
    cameras, lasers : iterable of str, optional
        Sensors to include; default every camera with a ``CameraInfo`` and every ``LaserScan`` sensor (those
        without a pose are skipped with a warning; a sensor asked for by name must have one).

    Raises
    ------
    RecordingError
        A sensor asked for has no CameraInfo / scans or no transform to ``world_frame``.
    """
    if not isinstance(rec, Recording):
        with Recording(rec) as opened:
            return road_calibration_from_recording(opened, world_frame=world_frame, cameras=cameras,
                                                   lasers=lasers, use_calibrated=use_calibrated)
    path = rec.paths[0]
    tree = rec.transform_tree()
    infos, scans = _first_messages(rec, "sensor_msgs/msg/CameraInfo"), _first_messages(rec, "sensor_msgs/msg/LaserScan")
    strict_cams, strict_lasers = cameras is not None, lasers is not None
    cam_names = list(infos) if cameras is None else list(cameras)
    laser_names = list(scans) if lasers is None else list(lasers)
    for kind, wanted, have in (("camera", cam_names, infos), ("laser", laser_names, scans)):
        missing = [n for n in wanted if n not in have]
        if missing:
            what = "CameraInfo" if kind == "camera" else "LaserScan"
            raise RecordingError(f"{path}: no {what} topic of {kind}(s) {missing}; {kind}s: {sorted(have)}")

    def frames(name: str) -> list[str]:
        return ([f"{name}_calibrated"] if use_calibrated else []) + [name]

    out_cams: dict[str, CameraCalibration] = {}
    for name in cam_names:
        info = next((m for m in rec.messages([infos[name]]) if isinstance(m, CameraInfo)), None)
        frame = None if info is None else _pose_frame(tree, [*frames(name), info.frame_id], world_frame)
        if info is None or frame is None:
            msg = f"{path}: camera {name!r} has no CameraInfo or no transform to {world_frame!r} in tf"
            if strict_cams:
                raise RecordingError(msg)
            log.warning("%s: skipped", msg)
            continue
        out_cams[name] = _camera_from_model(name, PinholeCamera.from_camera_info(info, tree.get(world_frame, frame)))
        log.info("%s: camera %r: homography from CameraInfo and the pose of %r%s", path, name, frame,
                 " (distortion removed before H_c)" if out_cams[name].has_distortion else "")
    out_lasers: dict[str, LaserCalibration] = {}
    for name in laser_names:
        frame = _pose_frame(tree, frames(name), world_frame)
        if frame is None:
            scan = next(iter(rec.messages([scans[name]])), None)
            frame = None if scan is None else _pose_frame(tree, [scan.frame_id], world_frame)
        if frame is None:
            msg = f"{path}: laser {name!r} has no transform to {world_frame!r} in tf"
            if strict_lasers:
                raise RecordingError(msg)
            log.warning("%s: skipped", msg)
            continue
        out_lasers[name] = _laser_from_pose(name, tree.get(frame, world_frame))
    return RoadCalibration(out_cams, out_lasers, f"recording {path}")


# ---- Residual table ----------------------------------------------------------------------------------------------


def residual_table(calib: RoadCalibration) -> list[dict[str, Any]]:
    """One row per sensor: ``sensor, kind, n, rms_m, max_m, rms_px, max_px`` (n = 0 and NaN when the sensor was
    not calibrated from control points; px NaN for lasers)."""
    rows = []
    for kind, items in (("camera", calib.cameras), ("laser", calib.lasers)):
        for name, item in items.items():
            r = item.residual or SensorResidual(0, math.nan, math.nan)
            rows.append({"sensor": name, "kind": kind, "n": r.n, "rms_m": r.rms_m, "max_m": r.max_m,
                         "rms_px": r.rms_px, "max_px": r.max_px})
    return rows


def format_residual_table(rows: list[dict[str, Any]]) -> str:
    """The rows of :func:`residual_table` as aligned text (``-`` for NaN)."""
    head = ("sensor", "kind", "n", "rms_m", "max_m", "rms_px", "max_px")

    def cell(v: Any) -> str:
        if isinstance(v, float):
            return "-" if math.isnan(v) else f"{v:.3f}"
        return str(v)
    table = [head, *[tuple(cell(r[k]) for k in head) for r in rows]]
    widths = [max(len(t[i]) for t in table) for i in range(len(head))]
    lines = ("  ".join(c.rjust(w) if i >= 2 else c.ljust(w) for i, (c, w) in enumerate(zip(t, widths, strict=True)))
             for t in table)
    return "\n".join(lines)
