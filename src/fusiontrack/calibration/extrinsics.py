"""Camera extrinsics from control points seen by a laser (or measured in the world) and by the camera.

seed 001 (ALGORITHMS.md B11): "extrinsic calibration by several control points in a box" — the corners of a
box of known size, their floor coordinates read from the laser (the box's sides are line segments in the
scan) and their heights known, clicked in the image. With the intrinsics known (``CameraInfo``), the pose is a
Perspective-n-Point problem: OpenCV's ``solvePnP`` (SQPnP, globally optimal, n >= 3), optionally inside
RANSAC (``solvePnPRansac``, outliers beyond ``ransac_threshold_px``, X6's 5 px), then Levenberg–Marquardt
refinement of the reprojection error (``solvePnPRefineLM``). Without intrinsics, X6's DLT
(:func:`fusiontrack.geometry.fit_projection_matrix`) gives a full ``3 x 4`` matrix instead.

Frames: the points are in a frame ``ref`` (a laser's frame, or the world); the result is ``ref2cam`` (the
camera's optical frame: x right, y down, z forward) and, given ``ref2world``, the camera's ``cam2world`` and its
pipeline-file pose (:func:`camera_pose_from_cam2world`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Literal

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from fusiontrack.config import Pose
from fusiontrack.errors import CalibrationError
from fusiontrack.geometry import invert_transform, make_transform, rpy_to_matrix
from fusiontrack.types import CameraInfo

__all__ = [
    "OPTICAL2BODY",
    "PnPResult",
    "cam2world_from_camera_pose",
    "camera_pose_from_cam2world",
    "pose_covariance",
    "reprojection_residuals",
    "solve_pnp",
]

log = logging.getLogger(__name__)

OPTICAL2BODY = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Rotation from a camera's optical frame (x right, y down, z forward) to its body frame (x forward, y left,
z up), the convention of :meth:`fusiontrack.geometry.PinholeCamera.from_pose` and of camera poses in the
pipeline file (``yaw_deg`` = heading of the view, ``pitch_deg`` > 0 looks down)."""

Method = Literal["sqpnp", "iterative", "epnp"]
_FLAGS = {"sqpnp": cv2.SOLVEPNP_SQPNP, "iterative": cv2.SOLVEPNP_ITERATIVE, "epnp": cv2.SOLVEPNP_EPNP}


@dataclass(frozen=True, slots=True, eq=False)
class PnPResult:
    """A camera pose from control points.

    Attributes
    ----------
    ref2cam : (4, 4) float64
        Maps points of the control points' frame into the camera's optical frame.
    residuals_px : (n, 2) float64
        Reprojection error ``project(point) - pixel`` of every control point (outliers included).
    inliers : (n,) bool
        Points used in the final refinement (all, without RANSAC).
    rms_px : float
        RMS over the ``2 n_inliers`` pixel coordinates of the inliers (isotropic noise of σ px gives ≈ σ
        times ``sqrt((2n - 6) / 2n)``).
    median_px, max_px : float
        Median and largest inlier reprojection distance.
    covariance : (6, 6) float64
        Covariance of ``(rvec, tvec)`` of ``ref2cam`` (rad, m) from the inlier residuals,
        ``σ̂² (JᵀJ)⁻¹`` with ``σ̂² = SSR / (2n - 6)`` (:func:`pose_covariance`); NaN when ``n <= 3``.
    method : str
    """

    ref2cam: np.ndarray
    residuals_px: np.ndarray
    inliers: np.ndarray
    rms_px: float
    median_px: float
    max_px: float
    covariance: np.ndarray
    method: str

    @property
    def cam2ref(self) -> np.ndarray:
        """``(4, 4)`` pose of the camera's optical frame in the control points' frame."""
        return invert_transform(self.ref2cam)

    def cam2world(self, ref2world: Any) -> np.ndarray:
        """``(4, 4)`` camera pose in the world, given the ``(4, 4)`` pose of the points' frame in the world."""
        T = np.asarray(ref2world, dtype=np.float64)
        if T.shape != (4, 4):
            raise ValueError(f"ref2world: expected a (4, 4) transform, got shape {T.shape}")
        return T @ self.cam2ref

    @property
    def position_std_m(self) -> np.ndarray:
        """1-sigma uncertainty of the camera centre in the points' frame, ``(3,)`` m (from :attr:`covariance`)."""
        return np.sqrt(np.clip(np.diag(_centre_covariance(self.ref2cam, self.covariance)), 0, None))


def _intrinsics(K: Any, dist: Any) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(K, CameraInfo):
        K, dist = K.K, K.D if dist is None else dist
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0 or K[2, 2] != 1:
        raise ValueError(f"K: expected a camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {K}")
    d = np.zeros(0) if dist is None else np.asarray(dist, dtype=np.float64).ravel()
    if d.size not in (0, 4, 5, 8, 12, 14) or not np.all(np.isfinite(d)):
        raise ValueError(f"dist: expected 0, 4, 5, 8, 12 or 14 finite OpenCV distortion coefficients, got {d}")
    return K, d


def _pairs(points_m: Any, pixels_px: Any) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(points_m, dtype=np.float64)
    q = np.asarray(pixels_px, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points_m: expected an array of shape (n, 3), got {p.shape}")
    if q.ndim != 2 or q.shape[1] != 2:
        raise ValueError(f"pixels_px: expected an array of shape (n, 2), got {q.shape}")
    if len(p) != len(q):
        raise ValueError(f"points_m, pixels_px: {len(p)} points but {len(q)} pixels")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        raise CalibrationError("solve_pnp: the control points contain NaN or infinite values")
    if len(p) < 4:
        raise CalibrationError(f"solve_pnp: {len(p)} control points given, at least 4 are needed (6 for RANSAC)")
    s = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    if s[0] == 0 or s[1] < 1e-6 * s[0]:
        raise CalibrationError(f"solve_pnp: the {len(p)} control points are collinear (or coincide); the pose is "
                               "undetermined")
    return p, q


def _check_not_on_a_line(p: np.ndarray, q: np.ndarray, K: np.ndarray, d: np.ndarray) -> None:
    """Pixels that, undistorted, lie on one line (within half a pixel rms) are images of points in one plane through
    the camera's centre. Points that are not in one plane (more than 1 cm rms off their best plane) cannot look so:
    the pixels do not belong to those points (a mis-typed column), though OpenCV would still fit a pose to them
    exactly, metres off. Points in one plane may (the camera at the height of markers on a wall): they are solved."""
    flat = cv2.undistortPoints(q.reshape(-1, 1, 2), K, d, P=K).reshape(-1, 2)
    off_line = np.linalg.svd(flat - flat.mean(axis=0), compute_uv=False)[1] / math.sqrt(len(q))
    off_plane = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)[2] / math.sqrt(len(p))
    if off_line < 0.5 and off_plane > 0.01:
        raise CalibrationError(f"solve_pnp: the pixels of the {len(q)} control points lie on one line (within "
                               f"{off_line:.2g} px rms, distortion removed), but the points are not in one plane "
                               f"({off_plane:.2g} m rms off it): no camera sees them so; check the pixel columns "
                               "and that each point's pixel is its own")


def reprojection_residuals(ref2cam: Any, points_m: Any, pixels_px: Any, K: Any, dist: Any = None) -> np.ndarray:
    """``project(points) - pixels`` through ``K``, ``dist`` and the pose ``ref2cam`` (4, 4); ``(n, 2)`` px."""
    K, d = _intrinsics(K, dist)
    T = np.asarray(ref2cam, dtype=np.float64)
    rvec = cv2.Rodrigues(T[:3, :3])[0]
    proj, _ = cv2.projectPoints(np.asarray(points_m, np.float64).reshape(-1, 1, 3), rvec, T[:3, 3], K, d)
    return proj.reshape(-1, 2) - np.asarray(pixels_px, np.float64).reshape(-1, 2)


def pose_covariance(ref2cam: Any, points_m: Any, pixels_px: Any, K: Any, dist: Any = None,
                    sigma_px: float | None = None) -> np.ndarray:
    """First-order covariance of ``(rvec, tvec)`` (6, 6) of a PnP pose: ``σ² (JᵀJ)⁻¹``.

    ``J`` (2n, 6) is the Jacobian of the projections with respect to the pose (``cv2.projectPoints``). With
    ``sigma_px`` None, ``σ²`` is estimated as ``SSR / (2n - 6)`` from the residuals (NaN when ``n <= 3``).
    """
    K, d = _intrinsics(K, dist)
    p, q = _pairs(points_m, pixels_px)
    T = np.asarray(ref2cam, dtype=np.float64)
    rvec = cv2.Rodrigues(T[:3, :3])[0]
    proj, jac = cv2.projectPoints(p.reshape(-1, 1, 3), rvec, T[:3, 3], K, d)
    J = jac[:, :6]
    if sigma_px is None:
        dof = 2 * len(p) - 6
        sigma2 = float(np.sum((proj.reshape(-1, 2) - q) ** 2) / dof) if dof > 0 else math.nan
    else:
        sigma2 = float(sigma_px) ** 2
    try:
        return sigma2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return np.full((6, 6), np.nan)


def _centre_covariance(ref2cam: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Covariance of the camera centre ``-Rᵀ t`` from that of ``(rvec, tvec)``, by finite differences."""
    rvec = cv2.Rodrigues(ref2cam[:3, :3])[0].ravel()
    t = ref2cam[:3, 3]

    def centre(x: np.ndarray) -> np.ndarray:
        R = cv2.Rodrigues(x[:3])[0]
        return -R.T @ x[3:]

    x0 = np.r_[rvec, t]
    eps = 1e-7
    J = np.column_stack([(centre(x0 + eps * e) - centre(x0 - eps * e)) / (2 * eps) for e in np.eye(6)])
    return J @ cov @ J.T


def solve_pnp(points_m: Any, pixels_px: Any, K: Any, dist: Any = None, *, method: Method = "sqpnp",
              ransac: bool = False, ransac_threshold_px: float = 5.0, refine: bool = True) -> PnPResult:
    """Pose of a camera with known intrinsics from ``n`` control points (OpenCV PnP; ALGORITHMS.md B11, X6).

    Parameters
    ----------
    points_m : (n, 3) float
        Control points in their frame ``ref`` (a laser's frame or the world), metres; n >= 4, not collinear
        (n >= 6 with RANSAC).
    pixels_px : (n, 2) float
        Where they appear in the (distorted) image, pixels.
    K : (3, 3) float or CameraInfo
        Camera matrix (a ``CameraInfo`` also gives ``dist``).
    dist : (0,), (4,), (5,), (8,), ... float, optional
        OpenCV distortion coefficients.
    method : {"sqpnp", "iterative", "epnp"}
        OpenCV solver for the initial pose.
    ransac : bool
        Reject outliers with ``solvePnPRansac`` (a mis-clicked corner).
    ransac_threshold_px : float
        RANSAC inlier threshold (X6: 5 px).
    refine : bool
        Levenberg–Marquardt refinement on the inliers.

    Returns
    -------
    PnPResult

    Raises
    ------
    CalibrationError
        Too few, non-finite, or collinear points; no pose puts the points in front of the camera.
    ValueError
        Malformed arrays, ``K`` or ``dist``.
    """
    if method not in _FLAGS:
        raise ValueError(f"method: expected one of {sorted(_FLAGS)}, got {method!r}")
    if not (math.isfinite(ransac_threshold_px) and ransac_threshold_px > 0):
        raise ValueError(f"ransac_threshold_px: expected a positive threshold, got {ransac_threshold_px}")
    K, d = _intrinsics(K, dist)
    p, q = _pairs(points_m, pixels_px)
    _check_not_on_a_line(p, q, K, d)
    n = len(p)
    obj, img = p.reshape(-1, 1, 3), q.reshape(-1, 1, 2)
    inliers = np.ones(n, dtype=bool)
    try:
        if ransac:
            if n < 6:
                raise CalibrationError(f"solve_pnp: RANSAC needs at least 6 control points, got {n}")
            ok, rvec, tvec, idx = cv2.solvePnPRansac(obj, img, K, d, flags=_FLAGS[method],
                                                     reprojectionError=float(ransac_threshold_px),
                                                     iterationsCount=1000, confidence=0.999)
            if ok and idx is not None:
                inliers[:] = False
                inliers[idx.ravel()] = True
        else:
            ok, rvec, tvec = cv2.solvePnP(obj, img, K, d, flags=_FLAGS[method])
    except cv2.error as err:
        raise CalibrationError(f"solve_pnp: OpenCV could not solve the pose from {n} points: {err.msg}") from err
    if not ok or inliers.sum() < 4:
        raise CalibrationError(f"solve_pnp: no pose found from {n} control points ({int(inliers.sum())} inliers)")
    if refine:
        rvec, tvec = cv2.solvePnPRefineLM(obj[inliers], img[inliers], K, d, rvec, tvec,
                                          (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12))
    T = make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel())
    depth = p @ T[:3, :3].T[:, 2] + T[2, 3]
    if np.any(depth[inliers] <= 0):
        raise CalibrationError("solve_pnp: the solution puts control points behind the camera; check that the "
                               "points and pixels correspond")
    res = reprojection_residuals(T, p, q, K, d)
    dist_px = np.hypot(res[inliers, 0], res[inliers, 1])
    cov = pose_covariance(T, p[inliers], q[inliers], K, d)
    result = PnPResult(T, res, inliers, float(np.sqrt(np.mean(res[inliers] ** 2))), float(np.median(dist_px)),
                       float(dist_px.max()), cov, method + ("+ransac" if ransac else "") + ("+lm" if refine else ""))
    if not inliers.all():
        log.info("solve_pnp: %d of %d control points rejected as outliers (> %.1f px)", n - int(inliers.sum()), n,
                 ransac_threshold_px)
    return result


def camera_pose_from_cam2world(cam2world: Any) -> Pose:
    """The pipeline-file pose (position m, roll/pitch/yaw degrees of the body frame) of a camera's ``cam2world``.

    Inverse of :func:`cam2world_from_camera_pose`; matches :meth:`PinholeCamera.from_pose` (yaw = heading of the
    view counter-clockwise from world x, pitch > 0 looks down, roll about the view).
    """
    T = np.asarray(cam2world, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"cam2world: expected a finite (4, 4) transform, got shape {T.shape}")
    body2world = T[:3, :3] @ OPTICAL2BODY.T
    roll, pitch, yaw = Rotation.from_matrix(body2world).as_euler("xyz", degrees=True)
    x, y, z = T[:3, 3]
    return Pose(x=float(x), y=float(y), z=float(z), roll_deg=float(roll), pitch_deg=float(pitch), yaw_deg=float(yaw))


def cam2world_from_camera_pose(pose: Pose) -> np.ndarray:
    """``cam2world`` (4, 4) of the optical frame of a camera whose pipeline-file pose is ``pose``."""
    R = rpy_to_matrix(math.radians(pose.roll_deg), math.radians(pose.pitch_deg), math.radians(pose.yaw_deg))
    return make_transform(R @ OPTICAL2BODY, [pose.x, pose.y, pose.z])
