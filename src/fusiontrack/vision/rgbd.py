"""RGB-D person tracking, world positions and detection (seed 002; ALGORITHMS.md C6, C7, X3, X4).

* C6 — :class:`RgbdParticleFilter`: a particle filter over one person's box ``(u, v, scale)`` in the colour
  image. A particle's likelihood is the Bhattacharyya coefficient (X4) between the HSV histogram of its box
  and the template's, times the overlap of the binary depth shape (Eq. 3: pixels within ε of the target's
  depth) with the template's shape. Histograms of every particle come from integral images of the per-bin
  masks (X3, :func:`bin_integrals`, :func:`box_histograms`): four lookups per bin, whatever the box size.
* C7 — :func:`target_position`: the median depth and centroid of the box's depth-foreground pixels,
  back-projected with the intrinsics of a ``CameraInfo`` and moved into the world by the camera pose.
* :func:`detect_people_rgbd` — a depth-only person detector to start the filter: the floor is removed (by
  height when the camera pose is known, else by a RANSAC plane), the depth image is cut at depth jumps into
  connected blobs, and blobs of human height and width are kept.

Conventions (ALGORITHMS.md 0.2): boxes ``(u_min, v_min, u_max, v_max)`` px; depth along the optical axis in
metres, NaN (or 0) where invalid; the optical frame has ``z`` forward, ``x`` right, ``y`` down; ``cam2world``
maps optical-frame points into the world (``Z`` up). Work is vectorised over particles and pixels; the only
Python loops run over histogram bins (110) and over detected blobs.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from fusiontrack.tracking.pf import effective_sample_size, normalise_log_weights, resample_where, standard_normal
from fusiontrack.types import CameraInfo, Detection, ObjectClass

__all__ = [
    "RgbdDetections",
    "RgbdDetectorParams",
    "RgbdEstimate",
    "RgbdFix",
    "RgbdParticleFilter",
    "RgbdPfParams",
    "RgbdTemplate",
    "bhattacharyya",
    "bin_integrals",
    "box_histograms",
    "depth_overlap",
    "depth_shapes",
    "detect_people_rgbd",
    "hsv_bins",
    "reference_depth",
    "remove_floor",
    "target_position",
]

log = logging.getLogger(__name__)


# ---- X4 and the HSV histogram (C6) ---------------------------------------------------------------


def bhattacharyya(p: Any, q: Any) -> np.ndarray:
    """Bhattacharyya coefficient ``BC(p, q) = Σ_b sqrt(p_b q_b)`` of normalised histograms (ALGORITHMS.md X4).

    Used as C6's visual *similarity* (erratum E6: the paper's "distance" is ``sqrt(1 − BC)``).

    Parameters
    ----------
    p, q : (..., n_bins) float
        Non-negative histograms summing to 1 along the last axis; broadcast against each other.

    Returns
    -------
    (...) float64 in [0, 1]: 1 for identical histograms, 0 for disjoint supports.
    """
    a = np.asarray(p, dtype=np.float64)
    b = np.asarray(q, dtype=np.float64)
    if a.shape[-1:] != b.shape[-1:] or a.ndim == 0:
        raise ValueError(f"p, q: expected histograms with the same number of bins, got {a.shape} and {b.shape}")
    if np.any(a < 0) or np.any(b < 0):
        raise ValueError("p, q: histograms must be non-negative")
    return np.clip(np.sqrt(a * b).sum(axis=-1), 0.0, 1.0)


def hsv_bins(bgr: np.ndarray, hue_bins: int = 10, sat_bins: int = 10, value_bins: int = 10, s_min: float = 0.1,
             v_min: float = 0.2) -> np.ndarray:
    """Histogram bin of every pixel, Pérez et al. 2002 binning (C6).

    Pixels with saturation ``>= s_min`` and value ``>= v_min`` fall in one of ``hue_bins x sat_bins`` (H, S)
    bins; the others (greys, dark pixels: their hue is meaningless) in one of ``value_bins`` V-only bins.

    Parameters
    ----------
    bgr : (H, W, 3) uint8
    hue_bins, sat_bins, value_bins : int
    s_min, v_min : float
        Thresholds in [0, 1].

    Returns
    -------
    (H, W) uint8 (or uint16 beyond 255 bins), values in ``[0, hue_bins·sat_bins + value_bins)``.
    """
    img = np.asarray(bgr)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"bgr: expected an (H, W, 3) uint8 image, got {img.shape} {img.dtype}")
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)  # H in [0, 180), S and V in [0, 256)
    h = hsv[..., 0].astype(np.uint16) * hue_bins // 180
    s = hsv[..., 1].astype(np.uint16) * sat_bins // 256
    v = hsv[..., 2].astype(np.uint16) * value_bins // 256
    chroma = (hsv[..., 1] >= s_min * 255.0) & (hsv[..., 2] >= v_min * 255.0)
    out = np.where(chroma, h * sat_bins + s, hue_bins * sat_bins + v)
    return out.astype(np.uint8 if hue_bins * sat_bins + value_bins <= 256 else np.uint16)


def bin_integrals(bins: np.ndarray, n_bins: int, roi: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """Integral images of the per-bin indicator masks (integral histogram; X3) over a region of interest.

    Parameters
    ----------
    bins : (H, W) int
        Bin index of each pixel (:func:`hsv_bins`).
    n_bins : int
    roi : (u0, v0, u1, v1) int, optional
        Pixel bounds ``[u0, u1) x [v0, v1)``; default the whole image.

    Returns
    -------
    (n_bins, h + 1, w + 1) int32
        ``I[b, y, x]`` = number of pixels of bin ``b`` in ``[u0, u0 + x) x [v0, v0 + y)``.
    """
    u0, v0, u1, v1 = (0, 0, bins.shape[1], bins.shape[0]) if roi is None else roi
    if not (0 <= u0 < u1 <= bins.shape[1] and 0 <= v0 < v1 <= bins.shape[0]):
        raise ValueError(f"roi: expected (u0, v0, u1, v1) inside the {bins.shape[1]}x{bins.shape[0]} image, got {roi}")
    sub = np.ascontiguousarray(bins[v0:v1, u0:u1])
    out = np.zeros((n_bins, v1 - v0 + 1, u1 - u0 + 1), np.int32)
    present = np.flatnonzero(np.bincount(sub.ravel(), minlength=n_bins)[:n_bins])
    for b in present:  # one cv2.integral per occupied bin (an empty bin's integral is all zeros)
        cv2.integral((sub == b).view(np.uint8), out[b], sdepth=cv2.CV_32S)
    return out


def box_histograms(integrals: np.ndarray, boxes_px: np.ndarray, roi_origin: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Normalised histograms of many boxes from per-bin integral images: O(bins) per box (C6, X3).

    Parameters
    ----------
    integrals : (n_bins, h + 1, w + 1) int
        From :func:`bin_integrals`.
    boxes_px : (n, 4) int
        ``(u_min, v_min, u_max, v_max)`` in image pixels, exclusive maxima; clipped to the region.
    roi_origin : (u0, v0)
        Image position of the region's top-left pixel.

    Returns
    -------
    (n, n_bins) float64
        Each row sums to 1; a box with no pixel in the region gives a row of zeros.
    """
    b = np.asarray(boxes_px, dtype=np.int64)
    _, hh, ww = integrals.shape
    x0 = np.clip(b[:, 0] - roi_origin[0], 0, ww - 1)
    x1 = np.clip(b[:, 2] - roi_origin[0], 0, ww - 1)
    y0 = np.clip(b[:, 1] - roi_origin[1], 0, hh - 1)
    y1 = np.clip(b[:, 3] - roi_origin[1], 0, hh - 1)
    x1, y1 = np.maximum(x1, x0), np.maximum(y1, y0)
    flat = integrals.reshape(integrals.shape[0], -1)
    counts = (flat[:, y1 * ww + x1] - flat[:, y0 * ww + x1] - flat[:, y1 * ww + x0]
              + flat[:, y0 * ww + x0]).T.astype(np.float64)  # (n, n_bins)
    total = counts.sum(axis=1, keepdims=True)
    return np.divide(counts, total, out=np.zeros_like(counts), where=total > 0)


# ---- Depth shape (C6 Eq. 3) ----------------------------------------------------------------------


def reference_depth(depth_m: np.ndarray, box_px: Any, mode: str = "median") -> float:
    """The target depth ``D̄`` of a box (C6): ``"median"`` of the central 50 % (robust; erratum E7) or ``"mean"``
    of the whole box (the paper). Invalid depth (NaN, 0) is excluded; NaN when the box has none."""
    if mode not in ("median", "mean"):
        raise ValueError(f"mode: expected 'median' or 'mean', got {mode!r}")
    d = np.asarray(depth_m, dtype=np.float32)
    u0, v0, u1, v1 = np.asarray(box_px, dtype=np.float64)
    if mode == "median":  # central half of each side
        du, dv = 0.25 * (u1 - u0), 0.25 * (v1 - v0)
        u0, v0, u1, v1 = u0 + du, v0 + dv, u1 - du, v1 - dv
    H, W = d.shape
    iu0, iv0 = int(np.clip(np.floor(u0), 0, W)), int(np.clip(np.floor(v0), 0, H))
    iu1, iv1 = int(np.clip(np.ceil(u1), 0, W)), int(np.clip(np.ceil(v1), 0, H))
    patch = d[iv0:iv1, iu0:iu1]
    vals = patch[np.isfinite(patch) & (patch > 0)]
    if vals.size == 0:
        return float("nan")
    return float(np.median(vals) if mode == "median" else np.mean(vals))


def depth_shapes(depth_m: np.ndarray, boxes_px: np.ndarray, reference_depth_m: float, eps_m: float,
                 size: tuple[int, int] = (32, 64)) -> np.ndarray:
    """Binary depth shape of each box, resized to ``size``: ``B = |D − D̄| <= ε`` (C6, Eq. 3).

    Nearest-neighbour sampling at the centres of a ``size`` grid laid over each box; samples outside the image
    or on invalid depth are 0.

    Parameters
    ----------
    depth_m : (H, W) float
    boxes_px : (n, 4) float
    reference_depth_m : float
        ``D̄``, m.
    eps_m : float
        ε, m.
    size : (w, h)
        Template grid (C6: e.g. 32 x 64).

    Returns
    -------
    (n, h, w) bool
    """
    d = np.asarray(depth_m, dtype=np.float32)
    H, W = d.shape
    b = np.asarray(boxes_px, dtype=np.float64)
    gw, gh = size
    fu = (np.arange(gw) + 0.5) / gw
    fv = (np.arange(gh) + 0.5) / gh
    u = np.floor(b[:, 0, None] + fu[None, :] * (b[:, 2] - b[:, 0])[:, None]).astype(np.int64)  # (n, gw)
    v = np.floor(b[:, 1, None] + fv[None, :] * (b[:, 3] - b[:, 1])[:, None]).astype(np.int64)  # (n, gh)
    # Eq. 3 only where the samples fall; one spare row/column of zeros takes every sample outside the image
    u_in, v_in = (u >= 0) & (u < W), (v >= 0) & (v < H)
    u0, u1 = (int(u[u_in].min()), int(u[u_in].max()) + 1) if u_in.any() else (0, 0)
    v0, v1 = (int(v[v_in].min()), int(v[v_in].max()) + 1) if v_in.any() else (0, 0)
    fg = np.zeros((v1 - v0 + 1, u1 - u0 + 1), dtype=bool)
    with np.errstate(invalid="ignore"):
        fg[:-1, :-1] = np.abs(d[v0:v1, u0:u1] - np.float32(reference_depth_m)) <= eps_m
    u = np.where(u_in, u - u0, u1 - u0).astype(np.int32)
    rows = (np.where(v_in, v - v0, v1 - v0) * (u1 - u0 + 1)).astype(np.int32)
    return np.take(fg.ravel(), rows[:, :, None] + u[:, None, :])


def depth_overlap(shapes: np.ndarray, template: np.ndarray, mode: str = "template") -> np.ndarray:
    """Similarity of binary depth shapes (C6): shared foreground over the template's foreground.

    Parameters
    ----------
    shapes : (n, h, w) bool or float in [0, 1]
    template : (h, w) float in [0, 1]
        A (possibly averaged, hence soft) template shape; the intersection is ``min``.
    mode : {"template", "union"}
        ``|B ∧ B_T| / |B_T|`` (C6, the paper's wording) or ``|B ∧ B_T| / |B ∨ B_T|`` (Jaccard, which also
        penalises foreground outside the template: a box zoomed into the torso).

    Returns
    -------
    (n,) float64 in [0, 1]; 0 when the template (or union) is empty.
    """
    s = np.asarray(shapes, dtype=np.float32)
    t = np.asarray(template, dtype=np.float32)
    if s.shape[1:] != t.shape:
        raise ValueError(f"shapes (n, h, w) and template (h, w) disagree: {s.shape} vs {t.shape}")
    inter = np.minimum(s, t[None]).reshape(len(s), -1).sum(axis=1, dtype=np.float64)
    if mode == "template":
        denom = np.full(len(s), float(t.sum(dtype=np.float64)))
    elif mode == "union":
        denom = np.maximum(s, t[None]).reshape(len(s), -1).sum(axis=1, dtype=np.float64)
    else:
        raise ValueError(f"mode: expected 'template' or 'union', got {mode!r}")
    return np.divide(inter, denom, out=np.zeros_like(inter), where=denom > 0)


# ---- C7: world position --------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class RgbdFix:
    """The position of a target seen by an RGB-D camera (C7).

    Attributes
    ----------
    position_cam_m : (3,) float64
        Optical frame (x right, y down, z forward), m; NaN when there is no foreground depth.
    position_world_m : (3,) float64
        ``cam2world @ position_cam_m``; the optical frame itself when no pose was given.
    depth_m : float
        Median depth Z of the foreground pixels.
    centroid_px : (2,) float64
        Centroid ``(u_c, v_c)`` of the foreground pixels.
    n_pixels : int
        Foreground pixels (``B = 1``) in the box.
    valid : bool
        ``Z`` inside the accepted range (C7: 0.8–4.0 m) and enough pixels.
    """

    position_cam_m: np.ndarray
    position_world_m: np.ndarray
    depth_m: float
    centroid_px: np.ndarray
    n_pixels: int
    valid: bool

    @property
    def range_m(self) -> float:
        """Straight-line distance from the camera centre, m."""
        return float(np.linalg.norm(self.position_cam_m))

    def detection(self, t_ns: int, sensor: str, box_px: Any = None, sigma_m: float = 0.1) -> Detection:
        """A floor-plane :class:`~fusiontrack.types.Detection` (world ``(x, y)``, isotropic ``sigma_m``)."""
        return Detection(t_ns, sensor, position_m=self.position_world_m[:2], covariance_m2=np.eye(2) * sigma_m**2,
                         box_px=box_px, cls=ObjectClass.PERSON)


def _intrinsics(camera: CameraInfo | Any) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(camera, CameraInfo):
        return np.asarray(camera.K, dtype=np.float64), np.asarray(camera.D, dtype=np.float64)
    K = np.asarray(camera, dtype=np.float64)
    if K.shape != (3, 3) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"camera: expected a CameraInfo or a (3, 3) camera matrix K, got {K.shape}")
    return K, np.zeros(0)


def _cam2world(cam2world: Any) -> np.ndarray:
    if cam2world is None:
        return np.eye(4)
    T = np.asarray(cam2world, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"cam2world: expected a finite (4, 4) transform, got shape {T.shape}")
    return T


def _box_foreground(d: np.ndarray, box: np.ndarray, ref: float, eps_m: float) -> tuple[float, np.ndarray, int]:
    """Median depth, pixel centroid ``(u, v)`` and count of the box's pixels with ``|D − ref| <= ε`` (Eq. 3)."""
    H, W = d.shape
    u0, v0 = int(np.clip(np.floor(box[0]), 0, W)), int(np.clip(np.floor(box[1]), 0, H))
    u1, v1 = int(np.clip(np.ceil(box[2]), 0, W)), int(np.clip(np.ceil(box[3]), 0, H))
    patch = d[v0:v1, u0:u1]
    if not np.isfinite(ref) or patch.size == 0:
        return float("nan"), np.full(2, np.nan), 0
    with np.errstate(invalid="ignore"):
        fg = np.abs(patch - np.float32(ref)) <= eps_m
    n = int(fg.sum())
    if n == 0:
        return float("nan"), np.full(2, np.nan), 0
    vv, uu = np.nonzero(fg)
    return float(np.median(patch[fg])), np.array([uu.mean() + u0, vv.mean() + v0]), n


def target_position(depth_m: np.ndarray, box_px: Any, camera: CameraInfo | Any, cam2world: Any = None, *,
                    reference_depth_m: float | None = None, eps_m: float = 0.30, reference: str = "median",
                    depth_range_m: tuple[float, float] = (0.8, 4.0), min_pixels: int = 20) -> RgbdFix:
    """World position of the person in ``box_px`` from registered depth (ALGORITHMS.md C7).

    The box's foreground ``B = |D − D̄| <= ε`` (Eq. 3) gives the median depth ``Z`` and the centroid
    ``(u_c, v_c)``; the centroid is undistorted with the camera's distortion and back-projected at depth ``Z``:
    ``X_c = (u_c − c_x) Z / f_x``, ``Y_c = (v_c − c_y) Z / f_y``, then ``world = cam2world · (X_c, Y_c, Z)``.

    Parameters
    ----------
    depth_m : (H, W) float
        Depth registered to the colour image, m; NaN or 0 where invalid.
    box_px : (4,) float
    camera : CameraInfo or (3, 3) K
        Intrinsics (C7 default for a Kinect without calibration: ``f = 525``, ``c = (319.5, 239.5)``).
    cam2world : (4, 4) float, optional
        Pose of the optical frame in the world; default: positions stay in the optical frame.
    reference_depth_m : float, optional
        ``D̄`` (e.g. the tracker's target depth); default :func:`reference_depth` of the box.
    eps_m : float
        ε of Eq. 3 (C6: 0.30 m).
    reference : {"median", "mean"}
        How ``D̄`` is taken when not given (erratum E7).
    depth_range_m : (float, float)
        Fixes with ``Z`` outside are marked invalid (C7: 0.8–4.0 m).
    min_pixels : int
        Fewer foreground pixels mark the fix invalid.

    Returns
    -------
    RgbdFix
    """
    d = np.asarray(depth_m, dtype=np.float32)
    if d.ndim != 2:
        raise ValueError(f"depth_m: expected an (H, W) depth image, got shape {d.shape}")
    b = np.asarray(box_px, dtype=np.float64)
    if b.shape != (4,) or not np.all(np.isfinite(b)) or b[2] <= b[0] or b[3] <= b[1]:
        raise ValueError(f"box_px: expected (u_min, v_min, u_max, v_max) with positive size, got {box_px}")
    if not (np.isfinite(eps_m) and eps_m > 0):
        raise ValueError(f"eps_m: expected a finite value > 0, got {eps_m}")
    K, D = _intrinsics(camera)
    T = _cam2world(cam2world)
    ref = reference_depth(d, b, reference) if reference_depth_m is None else float(reference_depth_m)
    z, uv, n = _box_foreground(d, b, ref, eps_m)
    nan3 = np.full(3, np.nan)
    if n == 0:
        return RgbdFix(nan3, nan3.copy(), float("nan"), np.full(2, np.nan), 0, False)
    uv = uv[None, :]
    if D.size and np.any(D != 0):
        xy = cv2.undistortPoints(uv.reshape(1, 1, 2), K, D).reshape(2)
    else:
        xy = np.array([(uv[0, 0] - K[0, 2]) / K[0, 0], (uv[0, 1] - K[1, 2]) / K[1, 1]])
    p_cam = np.array([xy[0] * z, xy[1] * z, z])
    p_world = T[:3, :3] @ p_cam + T[:3, 3]
    valid = bool(depth_range_m[0] <= z <= depth_range_m[1] and n >= min_pixels)
    return RgbdFix(p_cam, p_world, z, uv[0], n, valid)


# ---- C6: the particle filter ---------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RgbdPfParams:
    """Parameters of :class:`RgbdParticleFilter` (ALGORITHMS.md C6; RECON unless noted).

    Attributes
    ----------
    n_particles : int
        N = 200.
    sigma_uv_px : float
        Random-walk standard deviation of the box centre per frame, 8 px.
    sigma_scale : float
        Relative random walk of the box scale per frame, 0.02.
    hue_bins, sat_bins, value_bins : int
        Pérez binning 10 x 10 (H x S) + 10 (V) = 110 bins [REF].
    s_min, v_min : float
        Pixels below either go to the V-only bins [REF].
    eps_m : float
        ε of Eq. 3, 0.30 m.
    reference : {"median", "mean"}
        ``D̄`` of the first box: median of the central 50 % (robust, erratum E7) or the paper's mean.
    shape_size : (int, int)
        ``(w, h)`` of the depth-shape template, 32 x 64.
    overlap : {"union", "template"}
        Depth similarity. Default Jaccard ``|B ∧ B_T| / |B ∨ B_T|`` [RECON]: C6's wording ``|B ∧ B_T| / |B_T|``
        (``"template"``) is 1 for every box inside the silhouette, so nothing holds the scale up and the box
        shrinks onto the torso (on the simulated crossing its height fell by 40 % in 50 frames).
    likelihood_lambda : float
        Particle weight ``exp(−λ (1 − BC · S_D))`` (Pérez's sharpening of a similarity; 20). ``0`` uses the
        product ``BC · S_D`` itself as the likelihood.
    template_rate : float
        ``H_T ← (1 − rate) H_T + rate H_est`` (and the same for the depth shape), 0.1 ...
    template_min_similarity : float
        ... when the estimate's ``BC · S_D`` exceeds 0.6.
    resample_ess_ratio : float
        Systematic resampling when ``ESS < ratio · N`` (X1: 0.5).
    scale_range : (float, float)
        Bounds of the scale relative to the first box.
    depth_range_m : (float, float)
        C7's accepted depths for a fix, 0.8–4.0 m.
    lost_similarity : float
        The estimate is flagged ``lost`` when the best particle's ``BC · S_D`` is below this.
    """

    n_particles: int = 200
    sigma_uv_px: float = 8.0
    sigma_scale: float = 0.02
    hue_bins: int = 10
    sat_bins: int = 10
    value_bins: int = 10
    s_min: float = 0.1
    v_min: float = 0.2
    eps_m: float = 0.30
    reference: str = "median"
    shape_size: tuple[int, int] = (32, 64)
    overlap: str = "union"
    likelihood_lambda: float = 20.0
    template_rate: float = 0.1
    template_min_similarity: float = 0.6
    resample_ess_ratio: float = 0.5
    scale_range: tuple[float, float] = (0.2, 5.0)
    depth_range_m: tuple[float, float] = (0.8, 4.0)
    lost_similarity: float = 0.2

    def __post_init__(self) -> None:
        for name in ("n_particles", "hue_bins", "sat_bins", "value_bins"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
        for name in ("sigma_uv_px", "sigma_scale", "likelihood_lambda"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name}: expected a finite value >= 0, got {value}")
        if not (np.isfinite(self.eps_m) and self.eps_m > 0):
            raise ValueError(f"eps_m: expected a finite value > 0 m, got {self.eps_m}")
        for name in ("s_min", "v_min", "template_rate", "template_min_similarity", "resample_ess_ratio",
                     "lost_similarity"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name}: expected a value in [0, 1], got {value}")
        if self.reference not in ("median", "mean"):
            raise ValueError(f"reference: expected 'median' or 'mean', got {self.reference!r}")
        if self.overlap not in ("template", "union"):
            raise ValueError(f"overlap: expected 'union' or 'template', got {self.overlap!r}")
        if len(self.shape_size) != 2 or min(self.shape_size) < 2:
            raise ValueError(f"shape_size: expected (w, h) with both >= 2, got {self.shape_size}")
        for name in ("scale_range", "depth_range_m"):
            lo, hi = getattr(self, name)
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi):
                raise ValueError(f"{name}: expected (low, high) with 0 < low < high, got {(lo, hi)}")

    @property
    def n_bins(self) -> int:
        return self.hue_bins * self.sat_bins + self.value_bins


@dataclass(frozen=True, slots=True, eq=False)
class RgbdTemplate:
    """The target model of C6.

    Attributes
    ----------
    histogram : (n_bins,) float64
        Normalised HSV histogram ``H_T``.
    shape : (h, w) float32
        Depth-shape template ``B_T`` (binary at start; averaged by the updates).
    depth_m : float
        The target depth ``D̄`` used for Eq. 3.
    """

    histogram: np.ndarray
    shape: np.ndarray
    depth_m: float

    def __post_init__(self) -> None:
        h = np.array(self.histogram, dtype=np.float64)
        s = np.array(self.shape, dtype=np.float32)
        if h.ndim != 1 or s.ndim != 2:
            raise ValueError(f"RgbdTemplate: expected a (n_bins,) histogram and an (h, w) shape, got {h.shape}, "
                             f"{s.shape}")
        for arr in (h, s):
            arr.setflags(write=False)
        object.__setattr__(self, "histogram", h)
        object.__setattr__(self, "shape", s)
        object.__setattr__(self, "depth_m", float(self.depth_m))


@dataclass(frozen=True, slots=True, eq=False)
class RgbdEstimate:
    """One frame of :class:`RgbdParticleFilter`.

    Attributes
    ----------
    box_px : (4,) float64
        Weighted-mean box ``(u_min, v_min, u_max, v_max)``.
    scale : float
        Relative to the first box.
    similarity : float
        ``BC · S_D`` of the estimated box.
    bc, overlap : float
        Its two factors.
    depth_m : float
        Target depth ``D̄`` after this frame.
    ess : float
        Effective sample size before resampling.
    lost : bool
        No particle explains the frame (best ``BC · S_D`` below ``lost_similarity``).
    """

    box_px: np.ndarray
    scale: float
    similarity: float
    bc: float
    overlap: float
    depth_m: float
    ess: float
    lost: bool

    @property
    def centre_px(self) -> np.ndarray:
        return 0.5 * (self.box_px[:2] + self.box_px[2:])


def _check_frame(bgr: np.ndarray, depth_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    img = np.asarray(bgr)
    d = np.asarray(depth_m, dtype=np.float32)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"bgr: expected an (H, W, 3) uint8 colour image, got {img.shape} {img.dtype}")
    if d.shape != img.shape[:2]:
        raise ValueError(f"depth_m: expected a depth image registered to the colour image, shape {img.shape[:2]}, "
                         f"got {d.shape}")
    return img, d


class RgbdParticleFilter:
    """Track one person's box in registered colour + depth frames (ALGORITHMS.md C6, X1).

    Parameters
    ----------
    bgr : (H, W, 3) uint8
        First colour frame.
    depth_m : (H, W) float
        Registered depth, m (NaN or 0 invalid).
    box_px : (4,) float
        The person's box in the first frame (e.g. from :func:`detect_people_rgbd`); its aspect ratio is kept.
    params : RgbdPfParams
    rng : numpy.random.Generator | int | None

    Each :meth:`step` diffuses the particles ``(u_c, v_c, scale)`` by a random walk, weights them by
    ``exp(−λ (1 − BC · S_D))``, takes the weighted mean, updates the target depth ``D̄`` from the estimate's
    foreground (C7's median), updates the template when the estimate is good, and resamples systematically
    (:func:`fusiontrack.tracking.pf.resample_where`) when the effective sample size falls below half.
    With a camera looking down, give it floor-free depth (:func:`remove_floor`): floor pixels next to the feet
    are within ε of the target depth and would join the silhouette.
    """

    def __init__(self, bgr: np.ndarray, depth_m: np.ndarray, box_px: Any, params: RgbdPfParams | None = None,
                 rng: np.random.Generator | int | None = None) -> None:
        self.params = p = params if params is not None else RgbdPfParams()
        self._rng = np.random.default_rng(rng)
        img, d = _check_frame(bgr, depth_m)
        b = np.asarray(box_px, dtype=np.float64)
        H, W = d.shape
        if b.shape != (4,) or not np.all(np.isfinite(b)) or b[2] - b[0] < 2 or b[3] - b[1] < 2:
            raise ValueError(f"box_px: expected (u_min, v_min, u_max, v_max) of at least 2x2 px, got {box_px}")
        if b[2] <= 0 or b[3] <= 0 or b[0] >= W or b[1] >= H:
            raise ValueError(f"box_px: {b.tolist()} does not overlap the {W}x{H} frame")
        self.frame_shape = (H, W)
        self._size = np.array([b[2] - b[0], b[3] - b[1]])
        ref = reference_depth(d, b, p.reference)
        if not np.isfinite(ref):
            raise ValueError(f"box_px: no valid depth inside {b.tolist()}; cannot start the RGB-D filter")
        hist = self._histograms(img, b[None, :])[0]
        shape = depth_shapes(d, b[None, :], ref, p.eps_m, p.shape_size)[0]
        if not shape.any():
            log.warning("RGB-D filter: no pixel of the first box is within %.2f m of its reference depth %.2f m "
                        "(reference=%r); the depth likelihood will be 0 everywhere", p.eps_m, ref, p.reference)
        self.template = RgbdTemplate(hist, shape.astype(np.float32), ref)
        centre = 0.5 * (b[:2] + b[2:])
        self.particles = np.tile(np.array([centre[0], centre[1], 1.0]), (p.n_particles, 1))
        self.weights = np.full(p.n_particles, 1.0 / p.n_particles)
        self.estimate = RgbdEstimate(b.copy(), 1.0, 1.0, 1.0, 1.0, ref, float(p.n_particles), False)

    # ---- model pieces ----------------------------------------------------------------------------

    def boxes(self, states: np.ndarray) -> np.ndarray:
        """Boxes ``(n, 4)`` of states ``(n, 3)`` = ``(u_c, v_c, scale)``."""
        half = 0.5 * states[:, 2:3] * self._size[None, :]
        return np.hstack([states[:, :2] - half, states[:, :2] + half])

    def _histograms(self, img: np.ndarray, boxes: np.ndarray) -> np.ndarray:
        p = self.params
        H, W = img.shape[:2]
        ib = np.round(boxes).astype(np.int64)
        u0, v0 = int(np.clip(ib[:, 0].min(), 0, W - 1)), int(np.clip(ib[:, 1].min(), 0, H - 1))
        u1, v1 = int(np.clip(ib[:, 2].max(), u0 + 1, W)), int(np.clip(ib[:, 3].max(), v0 + 1, H))
        # bin only the region the boxes cover: the integral histogram costs O(bins x region)
        bins = hsv_bins(np.ascontiguousarray(img[v0:v1, u0:u1]), p.hue_bins, p.sat_bins, p.value_bins, p.s_min,
                        p.v_min)
        integ = bin_integrals(bins, p.n_bins)
        return box_histograms(integ, ib, (u0, v0))

    def similarity(self, bgr: np.ndarray, depth_m: np.ndarray, boxes_px: Any) -> tuple[np.ndarray, np.ndarray]:
        """``(BC, S_D)`` of boxes ``(n, 4)`` against the current template: each ``(n,)``; ``p(z|s) = BC · S_D``."""
        img, d = _check_frame(bgr, depth_m)
        boxes = np.atleast_2d(np.asarray(boxes_px, dtype=np.float64))
        p = self.params
        bc = bhattacharyya(self._histograms(img, boxes), self.template.histogram)
        shapes = depth_shapes(d, boxes, self.template.depth_m, p.eps_m, p.shape_size)
        return bc, depth_overlap(shapes, self.template.shape, p.overlap)

    # ---- one frame -------------------------------------------------------------------------------

    def step(self, bgr: np.ndarray, depth_m: np.ndarray) -> RgbdEstimate:
        """Predict, weight, estimate, adapt and resample on one registered frame pair."""
        img, d = _check_frame(bgr, depth_m)
        if d.shape != self.frame_shape:
            raise ValueError(f"depth_m: expected frames of size {self.frame_shape}, got {d.shape}")
        p = self.params
        n = p.n_particles
        noise = standard_normal(self._rng, (n, 3))
        x = self.particles.copy()
        x[:, :2] += p.sigma_uv_px * noise[:, :2]
        x[:, 2] = np.clip(x[:, 2] * np.exp(p.sigma_scale * noise[:, 2]), *p.scale_range)
        H, W = self.frame_shape
        x[:, 0] = np.clip(x[:, 0], 0, W - 1)  # keep the box centre in the image
        x[:, 1] = np.clip(x[:, 1], 0, H - 1)
        bc, sd = self.similarity(img, d, self.boxes(x))
        sim = bc * sd
        log_lik = -p.likelihood_lambda * (1.0 - sim) if p.likelihood_lambda > 0 else np.log(np.maximum(sim, 1e-300))
        with np.errstate(divide="ignore"):
            w, degenerate = normalise_log_weights(np.log(self.weights) + log_lik)
        lost = bool(degenerate) or float(sim.max()) < p.lost_similarity
        ess = float(effective_sample_size(w))
        mean = w @ x
        box = self.boxes(mean[None, :])[0]
        bc_e, sd_e = self.similarity(img, d, box[None, :])
        sim_e = float(bc_e[0] * sd_e[0])
        t = self.template
        depth = t.depth_m
        if not lost:  # follow the target's depth: C7's median over the estimate's foreground
            z, _, n_fg = _box_foreground(d, box, t.depth_m, p.eps_m)
            if n_fg >= 0.05 * (box[2] - box[0]) * (box[3] - box[1]):
                depth = z
        if not lost and sim_e > p.template_min_similarity:
            r = p.template_rate
            hist = (1 - r) * t.histogram + r * self._histograms(img, box[None, :])[0]
            shape = (1 - r) * t.shape + r * depth_shapes(d, box[None, :], depth, p.eps_m, p.shape_size)[0]
            self.template = RgbdTemplate(hist, shape, depth)
        elif depth != t.depth_m:
            self.template = RgbdTemplate(t.histogram, t.shape, depth)
        if ess < p.resample_ess_ratio * n:
            xr, wr = resample_where(x[None], w[None], True, self._rng)
            x, w = xr[0], wr[0]
        self.particles, self.weights = x, w
        self.estimate = RgbdEstimate(box, float(mean[2]), sim_e, float(bc_e[0]), float(sd_e[0]), depth, ess, lost)
        return self.estimate


# ---- Person detector -----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RgbdDetectorParams:
    """Parameters of :func:`detect_people_rgbd` [RECON].

    Attributes
    ----------
    depth_range_m : (float, float)
        Depths used, m.
    stride : int
        Use every ``stride``-th pixel (2: a 640x480 frame gives 76,800 points).
    cell_m : float
        Cell of the floor-plane occupancy grid in which points are clustered.
    min_points : int
        Occupied cells hold at least this many points (sensor noise leaves isolated points).
    min_area_m2 : float
        Smallest frontal area of a cluster (pixel footprints ``(Z s/f_x)(Z s/f_y)`` summed), m².
    height_range_m : (float, float)
        Head height above the floor (floor known), else the vertical extent of the cluster.
    min_visible_height_m : float
        Shortest vertical extent accepted for a cluster cut by the image's top or bottom border.
    width_range_m : (float, float)
        Largest horizontal extent of the cluster on the floor grid (2nd–98th percentile).
    max_bottom_m : float
        With a floor, a person's lowest point (unless cut by the image border) is below this.
    floor_tolerance_m : float
        Points this close to the floor are floor.
    floor_ransac_iterations : int
        Plane hypotheses for the floor when no pose is given.
    floor_max_tilt_deg : float
        The floor's normal is within this angle of the camera's up (−y) axis ...
    min_camera_height_m : float
        ... the plane is at least this far below the camera ...
    floor_min_inliers : float
        ... it holds this share of the sampled points ...
    floor_max_below : float
        ... and at most this share lies more than ``3 x floor_tolerance_m`` under it (a table top has chairs
        and legs under it; a floor has nothing).
    """

    depth_range_m: tuple[float, float] = (0.5, 8.0)
    stride: int = 2
    cell_m: float = 0.06
    min_points: int = 2
    min_area_m2: float = 0.15
    height_range_m: tuple[float, float] = (1.0, 2.2)
    min_visible_height_m: float = 0.8
    width_range_m: tuple[float, float] = (0.15, 1.3)
    max_bottom_m: float = 0.5
    floor_tolerance_m: float = 0.08
    floor_ransac_iterations: int = 200
    floor_max_tilt_deg: float = 30.0
    min_camera_height_m: float = 0.3
    floor_min_inliers: float = 0.05
    floor_max_below: float = 0.005

    def __post_init__(self) -> None:
        for name in ("stride", "min_points", "floor_ransac_iterations"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
        for name in ("depth_range_m", "height_range_m", "width_range_m"):
            lo, hi = getattr(self, name)
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
                raise ValueError(f"{name}: expected (low, high) with 0 <= low < high, got {(lo, hi)}")
        if not (np.isfinite(self.cell_m) and self.cell_m > 0):
            raise ValueError(f"cell_m: expected a finite value > 0 m, got {self.cell_m}")
        for name in ("min_area_m2", "min_visible_height_m", "max_bottom_m", "floor_tolerance_m",
                     "min_camera_height_m"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name}: expected a finite value >= 0, got {value}")
        if not 0 < self.floor_max_tilt_deg < 90:
            raise ValueError(f"floor_max_tilt_deg: expected a value in (0, 90), got {self.floor_max_tilt_deg}")
        if not 0 < self.floor_min_inliers <= 1:
            raise ValueError(f"floor_min_inliers: expected a value in (0, 1], got {self.floor_min_inliers}")
        if not 0 <= self.floor_max_below <= 1:
            raise ValueError(f"floor_max_below: expected a value in [0, 1], got {self.floor_max_below}")


@dataclass(frozen=True, slots=True, eq=False)
class RgbdDetections:
    """People found in one depth frame, nearest first.

    Attributes
    ----------
    boxes_px : (n, 4) float64
        Full-resolution image boxes of the clusters' pixels.
    position_cam_m : (n, 3) float64
        The cluster's pixel centroid at its median depth (C7), optical frame.
    position_world_m : (n, 3) float64
        The same in the world (NaN without a pose).
    depth_m : (n,) float64
        Median depth.
    height_m : (n,) float64
        Top above the floor (floor known), else the vertical extent.
    width_m : (n,) float64
        Largest horizontal extent on the floor grid.
    truncated : (n,) bool
        The cluster touches the image border.
    floor_plane : (4,) float64 or None
        ``(n_x, n_y, n_z, d)`` in the optical frame with ``n · p + d`` the height above the floor, when it was
        found by RANSAC (no pose given); None otherwise.
    """

    boxes_px: np.ndarray
    position_cam_m: np.ndarray
    position_world_m: np.ndarray
    depth_m: np.ndarray
    height_m: np.ndarray
    width_m: np.ndarray
    truncated: np.ndarray
    floor_plane: np.ndarray | None

    def __len__(self) -> int:
        return int(self.depth_m.size)

    def detections(self, t_ns: int, sensor: str, sigma_m: float = 0.1) -> list[Detection]:
        """As floor-plane :class:`~fusiontrack.types.Detection` records (needs the pose: NaN rows are skipped)."""
        return [Detection(t_ns, sensor, position_m=self.position_world_m[i, :2], covariance_m2=np.eye(2) * sigma_m**2,
                          box_px=self.boxes_px[i], cls=ObjectClass.PERSON) for i in range(len(self))
                if np.all(np.isfinite(self.position_world_m[i, :2]))]


def _label_quantiles(labels: np.ndarray, values: np.ndarray, n_labels: int, qs: tuple[float, ...]) -> np.ndarray:
    """Quantiles of ``values`` per label ``0..n_labels-1``, by one sort: ``(len(qs), n_labels)``, NaN if empty."""
    order = np.lexsort((values, labels))
    val = values[order]
    counts = np.bincount(labels, minlength=n_labels)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    out = np.full((len(qs), n_labels), np.nan)
    has = counts > 0
    for i, q in enumerate(qs):  # a handful of quantiles
        idx = starts + np.floor(q * (counts - 1)).astype(np.int64)
        out[i, has] = val[idx[has]]
    return out


def _floor_ransac(pts: np.ndarray, params: RgbdDetectorParams, rng: np.random.Generator) -> np.ndarray | None:
    """Floor plane ``(n, d)``, ``n`` pointing up, from optical-frame points ``(m, 3)``; None if there is none."""
    if len(pts) < 50:
        return None
    sample = pts[rng.choice(len(pts), size=min(len(pts), 4000), replace=False)]
    k = params.floor_ransac_iterations
    tri = sample[rng.integers(0, len(sample), (k, 3))]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-9
    n = np.where(ok[:, None], n / np.where(ok, norm, 1.0)[:, None], 0.0)
    n *= np.where(n[:, 1] > 0, -1.0, 1.0)[:, None]  # up is −y in the optical frame
    d = -np.einsum("ki,ki->k", n, tri[:, 0])
    ok &= (-n[:, 1] >= np.cos(np.deg2rad(params.floor_max_tilt_deg))) & (d >= params.min_camera_height_m)
    if not ok.any():
        return None
    signed = sample @ n[ok].T + d[ok]  # (m, k_ok): heights above each hypothesis
    inliers = (np.abs(signed) < params.floor_tolerance_m).sum(axis=0)
    below = (signed < -3.0 * params.floor_tolerance_m).sum(axis=0)
    inliers = np.where(below <= params.floor_max_below * len(sample), inliers, 0)
    best = int(np.argmax(inliers))
    if inliers[best] < params.floor_min_inliers * len(sample):
        return None
    inl = sample[np.abs(signed[:, best]) < params.floor_tolerance_m]
    c = inl.mean(axis=0)
    _, _, vt = np.linalg.svd(inl - c, full_matrices=False)  # least-squares refit on the inliers
    nn = vt[-1] * (-1.0 if vt[-1][1] > 0 else 1.0)
    return np.concatenate([nn, [-nn @ c]])


def _empty_detections(plane: np.ndarray | None) -> RgbdDetections:
    z2, z1 = np.zeros((0, 3)), np.zeros(0)
    return RgbdDetections(np.zeros((0, 4)), z2, z2.copy(), z1, z1.copy(), z1.copy(), np.zeros(0, bool), plane)


def detect_people_rgbd(depth_m: np.ndarray, camera: CameraInfo | Any, cam2world: Any = None,
                       params: RgbdDetectorParams | None = None,
                       rng: np.random.Generator | int | None = None) -> RgbdDetections:
    """Find standing people in a depth image: floor removal, clustering on the floor plane, human-size clusters.

    The point cloud (every ``stride``-th pixel) loses its floor; the remaining points are binned on a floor-plane
    grid of ``cell_m`` cells, and connected occupied cells form clusters (a person's head, arms and legs fall in
    the cells of their body, however thin the neck looks in the image). Clusters of human height, width and
    frontal area are kept [RECON; the usual RGB-D people-detection pipeline of Munaro et al.].

    Parameters
    ----------
    depth_m : (H, W) float
        Depth along the optical axis, m; NaN or 0 invalid.
    camera : CameraInfo or (3, 3) K
        Intrinsics (distortion is ignored here; :func:`target_position` undistorts).
    cam2world : (4, 4) float, optional
        Camera pose, world ``Z`` up with the floor at ``Z = 0``. Without it the floor is searched by RANSAC (a
        near-horizontal plane below the camera with nothing under it); when there is none (floor out of view),
        the camera is taken as level: clusters on its ``x``–``z`` plane, heights as vertical extents.
    params : RgbdDetectorParams
    rng : numpy.random.Generator | int | None
        RANSAC draws.

    Returns
    -------
    RgbdDetections
        Sorted by depth, nearest first.
    """
    p = params if params is not None else RgbdDetectorParams()
    d_full = np.asarray(depth_m, dtype=np.float32)
    if d_full.ndim != 2 or min(d_full.shape) < 2:
        raise ValueError(f"depth_m: expected an (H, W) depth image, got shape {d_full.shape}")
    K, _ = _intrinsics(camera)
    T = None if cam2world is None else _cam2world(cam2world)
    rng = np.random.default_rng(rng)
    s = p.stride
    d = d_full[::s, ::s]
    h, w = d.shape
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(d) & (d >= p.depth_range_m[0]) & (d <= p.depth_range_m[1])
    rows, cols = np.nonzero(valid)
    z = d[rows, cols].astype(np.float64)
    pts = np.column_stack([(cols * s - cx) / fx * z, (rows * s - cy) / fy * z, z])  # optical frame
    plane = None
    if T is not None:  # world frame: floor Z = 0
        wp = pts @ T[:3, :3].T + T[:3, 3]
        height, ground, have_floor = wp[:, 2], wp[:, :2], True
    else:
        plane = _floor_ransac(pts, p, rng)
        if plane is not None:
            nrm = plane[:3]
            e1 = np.cross(nrm, [0.0, 0.0, 1.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(nrm, e1)
            height, ground, have_floor = pts @ nrm + plane[3], np.column_stack([pts @ e1, pts @ e2]), True
        else:
            height, ground, have_floor = -pts[:, 1], pts[:, [0, 2]], False
    keep = height >= p.floor_tolerance_m if have_floor else np.ones(len(z), bool)
    if have_floor:
        keep &= height <= p.height_range_m[1] + 0.3  # ceiling, lamps
    if not keep.any():
        return _empty_detections(plane)
    rows, cols, z, pts, height, ground = rows[keep], cols[keep], z[keep], pts[keep], height[keep], ground[keep]
    # occupancy grid on the floor plane; clusters = 8-connected occupied cells
    g0 = ground.min(axis=0)
    ij = np.floor((ground - g0) / p.cell_m).astype(np.int64)
    gh, gw = ij.max(axis=0) + 1
    cell = ij[:, 0] * gw + ij[:, 1]
    occupied = (np.bincount(cell, minlength=gh * gw) >= p.min_points).reshape(gh, gw)
    n_lab, grid_labels = cv2.connectedComponents(occupied.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    lab = grid_labels.ravel()[cell] - 1  # -1: point in a sparse cell
    inside = lab >= 0
    nl = n_lab - 1
    if nl == 0 or not inside.any():
        return _empty_detections(plane)
    lab, rows, cols, z, pts, height, ground = (a[inside] for a in (lab, rows, cols, z, pts, height, ground))
    count = np.bincount(lab, minlength=nl)
    area = np.bincount(lab, weights=(z * s / fx) * (z * s / fy), minlength=nl)
    qh = _label_quantiles(lab, height, nl, (0.02, 0.98))
    qa = _label_quantiles(lab, ground[:, 0], nl, (0.02, 0.98))
    qb = _label_quantiles(lab, ground[:, 1], nl, (0.02, 0.98))
    qz = _label_quantiles(lab, z, nl, (0.5,))[0]
    u_min, v_min = np.full(nl, w), np.full(nl, h)
    u_max, v_max = np.full(nl, -1), np.full(nl, -1)
    np.minimum.at(u_min, lab, cols)
    np.minimum.at(v_min, lab, rows)
    np.maximum.at(u_max, lab, cols)
    np.maximum.at(v_max, lab, rows)
    cut_tb = (v_min <= 0) | (v_max >= h - 1)
    cut_lr = (u_min <= 0) | (u_max >= w - 1)
    width = np.maximum(qa[1] - qa[0], qb[1] - qb[0])
    extent = qh[1] - qh[0]
    top = qh[1] if have_floor else extent
    tall = ((top >= p.height_range_m[0]) | (cut_tb & (extent >= p.min_visible_height_m))) & (top <= p.height_range_m[1])
    grounded = (qh[0] <= p.max_bottom_m) | (v_max >= h - 1) if have_floor else np.ones(nl, bool)
    ok = (count > 0) & (area >= p.min_area_m2) & tall & grounded
    ok &= (width >= p.width_range_m[0]) & (width <= p.width_range_m[1])
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return _empty_detections(plane)
    idx = idx[np.argsort(qz[idx])]
    boxes = np.column_stack([u_min[idx] * s, v_min[idx] * s, (u_max[idx] + 1) * s, (v_max[idx] + 1) * s])
    boxes = np.minimum(boxes, [d_full.shape[1], d_full.shape[0]] * 2).astype(np.float64)
    # C7 on each cluster: the centroid of its pixels at its median depth
    cu = np.bincount(lab, weights=cols * s, minlength=nl)[idx] / count[idx]
    cv = np.bincount(lab, weights=rows * s, minlength=nl)[idx] / count[idx]
    zc = qz[idx]
    cam = np.column_stack([(cu - cx) / fx * zc, (cv - cy) / fy * zc, zc])
    world = cam @ T[:3, :3].T + T[:3, 3] if T is not None else np.full_like(cam, np.nan)
    log.debug("RGB-D detector: %d clusters, %d people", nl, idx.size)
    return RgbdDetections(boxes, cam, world, zc, top[idx], width[idx], (cut_tb | cut_lr)[idx], plane)


def remove_floor(depth_m: np.ndarray, camera: CameraInfo | Any, cam2world: Any,
                 tolerance_m: float = 0.08) -> np.ndarray:
    """Depth with the floor's pixels (world ``Z < tolerance_m``) set to NaN, ``(H, W) float32``.

    Eq. 3's depth shape counts every pixel within ε of the target depth, so with a camera looking down the floor
    around a person's feet belongs to the silhouette; feeding :class:`RgbdParticleFilter` floor-free depth keeps
    the shape to the body [RECON].

    Parameters
    ----------
    depth_m : (H, W) float
    camera : CameraInfo or (3, 3) K
    cam2world : (4, 4) float
        Pose of the optical frame; the world floor is ``Z = 0``.
    tolerance_m : float
    """
    d = np.array(depth_m, dtype=np.float32)
    if d.ndim != 2:
        raise ValueError(f"depth_m: expected an (H, W) depth image, got shape {d.shape}")
    if not (np.isfinite(tolerance_m) and tolerance_m >= 0):
        raise ValueError(f"tolerance_m: expected a finite value >= 0, got {tolerance_m}")
    K, _ = _intrinsics(camera)
    T = _cam2world(cam2world)
    H, W = d.shape
    ray_y = (np.arange(H) - K[1, 2]) / K[1, 1]
    ray_x = (np.arange(W) - K[0, 2]) / K[0, 0]
    # world Z of pixel (v, u) at depth z: z * (R[2,0] x + R[2,1] y + R[2,2]) + t_z, separable in u and v
    slope = (T[2, 0] * ray_x[None, :] + T[2, 1] * ray_y[:, None] + T[2, 2]).astype(np.float32)
    with np.errstate(invalid="ignore"):
        floor = d * slope + np.float32(T[2, 3]) < tolerance_m
    d[floor] = np.nan
    return d
