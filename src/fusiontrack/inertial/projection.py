"""Projective mapping from the dead-reckoned floor position into a video image (seed 002, ALGORITHMS.md C9).

Eq. 9 ``x̃ = P X̃`` with ``X̃ = (X, Y, 1)``: inertial positions are on the floor, so P is a 3x3 homography.
It is trained automatically: while a person is tracked both visually and by dead reckoning, the visual
positions (box centres by default: a plane parallel to the floor at torso height maps by a homography too)
are paired in time with the dead-reckoned trajectory interpolated at the frame stamps
(:func:`align_track_pairs`, reusing C8's :func:`~fusiontrack.inertial.correction.control_pairs`), and P is
fitted by normalised DLT and least squares (X6, :func:`fusiontrack.geometry.fit_homography`) inside a
RANSAC loop with a 10 px threshold that drops visual glitches (:func:`fit_inertial_projection`).

The fit keeps the covariance of its inlier residuals, which is C11's Σ for the visual/inertial consistency
test (:func:`fusiontrack.vision.compressive.consistency`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from fusiontrack.errors import CalibrationError
from fusiontrack.geometry import apply_homography, fit_homography
from fusiontrack.inertial.correction import control_pairs
from fusiontrack.inertial.dead_reckoning import PdrResult

__all__ = [
    "InertialProjection",
    "ProjectionParams",
    "align_track_pairs",
    "fit_inertial_projection",
    "projection_from_pdr",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class ProjectionParams:
    """Parameters of :func:`fit_inertial_projection` (ALGORITHMS.md C9, X6).

    Attributes
    ----------
    ransac_threshold_px : float
        A pair is an inlier when its reprojection error is below this (C9: 10 px). ``inf`` disables RANSAC.
    ransac_iterations : int
        Minimal 4-pair hypotheses drawn (all solved in one batched SVD).
    min_inlier_fraction : float
        Below this share of inliers the fit is refused (CalibrationError).
    recommended_pairs : int
        C9 asks for at least 30 pairs spread over the image; fewer (but >= 4) gives a logged warning.
    refine : bool
        Levenberg–Marquardt on the reprojection error after the DLT (X6).
    """

    ransac_threshold_px: float = 10.0
    ransac_iterations: int = 300
    min_inlier_fraction: float = 0.5
    recommended_pairs: int = 30
    refine: bool = True

    def __post_init__(self) -> None:
        if not self.ransac_threshold_px > 0:
            raise ValueError(f"ransac_threshold_px: expected a value > 0 (inf disables RANSAC), got "
                             f"{self.ransac_threshold_px}")
        for name in ("ransac_iterations", "recommended_pairs"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
        if not 0.0 < self.min_inlier_fraction <= 1.0:
            raise ValueError(f"min_inlier_fraction: expected a value in (0, 1], got {self.min_inlier_fraction}")


@dataclass(frozen=True, slots=True, eq=False)
class InertialProjection:
    """A fitted floor-to-image homography with its residual statistics (C9, C11).

    Attributes
    ----------
    floor2image : (3, 3) float64
        P of Eq. 9, ``P[2, 2] = 1`` where possible.
    residual_cov_px2 : (2, 2) float64
        Sample covariance of the inlier residuals ``x_vis − P X`` (px²): C11's Σ.
    rms_px : float
        RMS reprojection error over the inliers' coordinates (X6's residual).
    inliers : (n,) bool
        Which training pairs the fit kept.
    """

    floor2image: np.ndarray
    residual_cov_px2: np.ndarray
    rms_px: float
    inliers: np.ndarray

    def __post_init__(self) -> None:
        for name, shape in (("floor2image", (3, 3)), ("residual_cov_px2", (2, 2))):
            arr = np.array(getattr(self, name), dtype=np.float64)
            if arr.shape != shape:
                raise ValueError(f"InertialProjection.{name}: expected shape {shape}, got {arr.shape}")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        inl = np.array(self.inliers, dtype=bool)
        inl.setflags(write=False)
        object.__setattr__(self, "inliers", inl)
        object.__setattr__(self, "rms_px", float(self.rms_px))

    @property
    def n_inliers(self) -> int:
        return int(self.inliers.sum())

    def project(self, floor_xy_m: Any) -> np.ndarray:
        """``x' = P·X``: floor positions ``(n, 2)`` or ``(2,)`` m to pixels of the same shape (NaN at infinity)."""
        xy = np.asarray(floor_xy_m, dtype=np.float64)
        if xy.shape == (2,):
            return apply_homography(self.floor2image, xy[None, :])[0]
        return apply_homography(self.floor2image, xy)

    def jacobian(self, floor_xy_m: Any) -> np.ndarray:
        """``∂x'/∂X`` of Eq. 9 at floor positions ``(n, 2)`` (or ``(2,)``) m: ``(n, 2, 2)`` (or ``(2, 2)``) px/m."""
        xy = np.asarray(floor_xy_m, dtype=np.float64)
        pts = np.atleast_2d(xy)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise ValueError(f"floor_xy_m: expected (n, 2) or (2,) floor positions, got shape {xy.shape}")
        P = self.floor2image
        h = np.column_stack([pts, np.ones(len(pts))]) @ P.T  # (n, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = h[:, :2] / h[:, 2:]
            J = (P[None, :2, :2] - x[:, :, None] * P[None, 2:3, :2]) / h[:, 2, None, None]
        return J[0] if xy.ndim == 1 else J

    def image_cov_px2(self, floor_xy_m: Any, floor_cov_m2: Any) -> np.ndarray:
        """C11's Σ at a floor position: the fit's residual covariance plus the floor uncertainty projected
        through the Jacobian, ``Σ = Σ_fit + J C Jᵀ`` [RECON: C11's optional inflation].

        Parameters
        ----------
        floor_xy_m : (2,) float
            Where the dead-reckoned target is, m.
        floor_cov_m2 : (2, 2) float or float
            Covariance of the dead-reckoned position (a scalar is a variance on both axes), m²; it grows with
            the distance walked since the last TPS correction (C8).

        Returns
        -------
        (2, 2) float64, px²
        """
        c = np.asarray(floor_cov_m2, dtype=np.float64)
        c = np.eye(2) * c if c.ndim == 0 else c
        if c.shape != (2, 2) or not np.all(np.isfinite(c)) or np.any(np.linalg.eigvalsh(0.5 * (c + c.T)) < 0):
            raise ValueError(f"floor_cov_m2: expected a variance >= 0 or a (2, 2) covariance, got {floor_cov_m2}")
        J = self.jacobian(np.asarray(floor_xy_m, dtype=np.float64).reshape(2))
        return self.residual_cov_px2 + J @ c @ J.T


def _pairs(floor_xy_m: Any, image_px: Any) -> tuple[np.ndarray, np.ndarray]:
    src = np.asarray(floor_xy_m, dtype=np.float64)
    dst = np.asarray(image_px, dtype=np.float64)
    if src.ndim != 2 or src.shape[1] != 2:
        raise ValueError(f"floor_xy_m: expected an (n, 2) array of floor positions, got shape {src.shape}")
    if dst.shape != src.shape:
        raise ValueError(f"image_px: expected shape {src.shape} (one pixel position per floor position), got "
                         f"{dst.shape}")
    if src.shape[0] < 4:
        raise ValueError(f"floor_xy_m: a homography needs at least 4 pairs, got {src.shape[0]}")
    if not (np.all(np.isfinite(src)) and np.all(np.isfinite(dst))):
        raise ValueError("floor_xy_m, image_px: the pairs contain NaN or infinite values; drop them first")
    return src, dst


def _hartley(pts: np.ndarray) -> np.ndarray:
    c = pts.mean(axis=0)
    d = np.mean(np.linalg.norm(pts - c, axis=1))
    s = np.sqrt(2.0) / d if d > 0 else 1.0
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def _minimal_homographies(src: np.ndarray, dst: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """DLT of every 4-pair sample at once: ``samples (k, 4)`` indices -> ``(k, 3, 3)`` homographies (X6)."""
    Ts, Td = _hartley(src), _hartley(dst)
    xs = src @ Ts[:2, :2].T + Ts[:2, 2]
    xd = dst @ Td[:2, :2].T + Td[:2, 2]
    a, b = xs[samples], xd[samples]  # (k, 4, 2)
    one, zero = np.ones((*samples.shape, 1)), np.zeros((*samples.shape, 3))
    ah = np.concatenate([a, one], axis=2)  # (k, 4, 3)
    rows_u = np.concatenate([ah, zero, -b[..., :1] * ah], axis=2)
    rows_v = np.concatenate([zero, ah, -b[..., 1:] * ah], axis=2)
    A = np.concatenate([rows_u, rows_v], axis=1)  # (k, 8, 9)
    _, _, vt = np.linalg.svd(A)
    H = vt[:, -1, :].reshape(-1, 3, 3)
    return np.linalg.inv(Td) @ H @ Ts


def _residuals(H: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Reprojection errors ``(k, n)`` px of ``(k, 3, 3)`` homographies; inf where a point goes to infinity."""
    h = np.einsum("kij,nj->kni", H, np.column_stack([src, np.ones(len(src))]))
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.linalg.norm(h[..., :2] / h[..., 2:] - dst[None], axis=2)
    return np.where(np.isfinite(err), err, np.inf)


def fit_inertial_projection(floor_xy_m: Any, image_px: Any, params: ProjectionParams | None = None,
                            rng: np.random.Generator | int | None = None) -> InertialProjection:
    """Fit Eq. 9's P from pairs (floor position, image position) by RANSAC + normalised DLT (C9, X6).

    Parameters
    ----------
    floor_xy_m : (n, 2) float
        Dead-reckoned (or TPS-corrected) floor positions, m; n >= 4.
    image_px : (n, 2) float
        The visual positions at the same instants (box centres), px.
    params : ProjectionParams
    rng : numpy.random.Generator | int | None
        Draws the RANSAC samples.

    Returns
    -------
    InertialProjection

    Raises
    ------
    ValueError
        Bad shapes, fewer than 4 pairs, or non-finite values.
    CalibrationError
        Degenerate pairs (e.g. all on one line: a straight walk determines no homography), or too few inliers.
    """
    p = params if params is not None else ProjectionParams()
    src, dst = _pairs(floor_xy_m, image_px)
    n = src.shape[0]
    if n < p.recommended_pairs:
        log.warning("C9 projection: only %d pairs (>= %d spread over the image are recommended)", n,
                    p.recommended_pairs)
    inliers = np.ones(n, dtype=bool)
    if np.isfinite(p.ransac_threshold_px) and n > 4:
        rng = np.random.default_rng(rng)
        samples = np.argsort(rng.random((p.ransac_iterations, n)), axis=1)[:, :4]
        with np.errstate(all="ignore"):
            err = _residuals(_minimal_homographies(src, dst, samples), src, dst)
        ok = err < p.ransac_threshold_px
        count = ok.sum(axis=1)
        # most inliers; ties broken by the smaller sum of inlier errors
        score = count - np.where(ok, err, 0.0).sum(axis=1) / (p.ransac_threshold_px * n + 1.0)
        inliers = ok[int(np.argmax(score))]
        if inliers.sum() < 4:
            raise CalibrationError(f"C9 projection: no 4-pair hypothesis explains the {n} pairs within "
                                   f"{p.ransac_threshold_px} px (are the pairs aligned in time?)")
        for _ in range(2):  # re-fit on the inliers, then re-select them with the better model
            H = fit_homography(src[inliers], dst[inliers], refine=p.refine)
            new = _residuals(H[None], src, dst)[0] < p.ransac_threshold_px
            if new.sum() < 4 or np.array_equal(new, inliers):
                break
            inliers = new
    if inliers.mean() < p.min_inlier_fraction:
        raise CalibrationError(f"C9 projection: only {int(inliers.sum())} of {n} pairs agree within "
                               f"{p.ransac_threshold_px} px (min_inlier_fraction = {p.min_inlier_fraction})")
    H = fit_homography(src[inliers], dst[inliers], refine=p.refine)
    res = apply_homography(H, src[inliers]) - dst[inliers]
    cov = np.cov(res, rowvar=False) if inliers.sum() > 2 else np.eye(2) * np.mean(res**2)
    rms = float(np.sqrt(np.mean(res**2)))
    log.debug("C9 projection: %d/%d inliers, RMS %.2f px", int(inliers.sum()), n, rms)
    return InertialProjection(H, cov, rms, inliers)


def align_track_pairs(visual_t_ns: Any, visual_px: Any, inertial_t_ns: Any, inertial_xy_m: Any, *,
                      min_spacing_px: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pair a visual track with the dead-reckoned trajectory at the same times (C9 "automatically aligned").

    The trajectory is interpolated linearly at each visual stamp (C5: positions between steps are linear);
    frames outside its time span, and frames without a visual position (NaN), are dropped. Optionally frames
    are thinned so consecutive kept image positions are ``min_spacing_px`` apart (a person standing still
    would otherwise dominate the fit).

    Parameters
    ----------
    visual_t_ns : (m,) int
        Frame stamps, non-decreasing, on the same clock as ``inertial_t_ns`` (see :mod:`fusiontrack.io.sync`).
    visual_px : (m, 2) float
        Visual positions (box centres), px; NaN rows where the track is not trusted.
    inertial_t_ns : (n,) int
        Trajectory knots (:meth:`~fusiontrack.inertial.PdrResult.knots`), non-decreasing.
    inertial_xy_m : (n, 2) float
    min_spacing_px : float

    Returns
    -------
    t_ns : (j,) int64
    floor_xy_m : (j, 2) float64
    image_px : (j, 2) float64
    """
    vt = np.asarray(visual_t_ns, dtype=np.int64)
    vp = np.asarray(visual_px, dtype=np.float64)
    if vp.ndim != 2 or vp.shape[1] != 2 or vt.shape != (vp.shape[0],):
        raise ValueError(f"visual_t_ns, visual_px: expected (m,) stamps and (m, 2) positions, got {vt.shape}, "
                         f"{vp.shape}")
    ok = np.all(np.isfinite(vp), axis=1)
    return control_pairs(inertial_t_ns, inertial_xy_m, vt[ok], vp[ok], min_spacing_m=min_spacing_px)


def projection_from_pdr(pdr: PdrResult, visual_t_ns: Any, visual_px: Any, params: ProjectionParams | None = None,
                        rng: np.random.Generator | int | None = None, *,
                        min_spacing_px: float = 0.0) -> InertialProjection:
    """C9 end to end: align a visual track with a :class:`~fusiontrack.inertial.PdrResult` and fit P."""
    kt, kp = pdr.knots()
    if kt.size < 2:
        raise CalibrationError("C9 projection: the dead-reckoned trajectory has fewer than 2 knots (no steps)")
    _, floor, image = align_track_pairs(visual_t_ns, visual_px, kt, kp, min_spacing_px=min_spacing_px)
    return fit_inertial_projection(floor, image, params, rng)
