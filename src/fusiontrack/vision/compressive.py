"""Compressive tracking with inertial failure detection and a multi-template buffer (seed 002).

* X3 — :func:`integral_image` and :func:`rect_sums`: rectangle sums in O(1) per rectangle.
* C10 — compressive tracking (Zhang, Zhang & Yang, ECCV 2012): a very sparse random measurement of
  multi-rectangle Haar-like features (:func:`make_haar_features`, :func:`haar_features`), a naive Bayes
  classifier with Gaussian class conditionals (:func:`ct_response`, Eq. 10) updated online with learning
  rate λ (:func:`update_gaussians`, Eq. 11, erratum E4/E5), and :class:`CompressiveTracker`, which picks the
  candidate of maximal response within radius γ of the previous box. Every constant follows the authors'
  C++ reference code (ALGORITHMS.md C10, REF-CODE).
* C11 — :func:`consistency`: ``sim(x, x') = exp(−½ (x − x')ᵀ Σ⁻¹ (x − x'))`` between the visual box centre
  and the inertial position projected into the image (:mod:`fusiontrack.inertial.projection`, C9);
  :func:`failure_threshold` gives ``τ_sim = exp(−½ χ²₂(p))``.
* C12 — :class:`MultiTemplateTracker`: updates stop on failure, the box is reset to the projected inertial
  position, and the best stored template (Eq. 14) is restored; while tracking is trusted the buffer keeps the
  templates that match best (Eq. 13).

Boxes are ``(u_min, v_min, u_max, v_max)`` in pixels (ALGORITHMS.md 0.2); the CT box has a fixed integer
size. Frames are grey ``(H, W) uint8`` (a ``(H, W, 3)`` BGR frame is converted). Everything is vectorised over
features x candidates; the only Python loops run over the (at most ``buffer_size``) stored templates.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from scipy.stats import chi2

__all__ = [
    "CompressiveParams",
    "CompressiveTracker",
    "CtResult",
    "CtTemplate",
    "HaarFeatures",
    "MultiTemplateParams",
    "MultiTemplateResult",
    "MultiTemplateTracker",
    "consistency",
    "ct_response",
    "disk_offsets",
    "failure_threshold",
    "haar_features",
    "integral_image",
    "make_haar_features",
    "rect_sums",
    "template_responses",
    "update_gaussians",
]

log = logging.getLogger(__name__)

_EPS = 1e-30  # the reference code's guard in Eq. 10


# ---- X3: integral images -------------------------------------------------------------------------


def integral_image(image: np.ndarray) -> np.ndarray:
    """Integral image ``II(y, x) = Σ_{y'<y, x'<x} I(y', x')`` (ALGORITHMS.md X3).

    Parameters
    ----------
    image : (H, W) or (H, W, C) array
        Any real dtype; a multi-channel image gives one integral image per channel.

    Returns
    -------
    (H + 1, W + 1) or (H + 1, W + 1, C) float64
        Row 0 and column 0 are zero.
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3) or img.shape[0] == 0 or img.shape[1] == 0:
        raise ValueError(f"image: expected a non-empty (H, W) or (H, W, C) array, got shape {img.shape}")
    if img.dtype == np.float64 or (img.ndim == 3 and img.shape[2] > 4):
        out = np.zeros((img.shape[0] + 1, img.shape[1] + 1, *img.shape[2:]))
        np.cumsum(np.cumsum(img, axis=0, dtype=np.float64), axis=1, out=out[1:, 1:])
        return out
    src = img if img.dtype in (np.uint8, np.float32) else img.astype(np.float64)
    return cv2.integral(np.ascontiguousarray(src), sdepth=cv2.CV_64F)


def rect_sums(ii: np.ndarray, x0: Any, y0: Any, x1: Any, y1: Any) -> np.ndarray:
    """Sums over the rectangles ``[x0, x1) × [y0, y1)`` from an integral image (X3), broadcast over the inputs.

    Parameters
    ----------
    ii : (H + 1, W + 1) or (H + 1, W + 1, C) float
        From :func:`integral_image`.
    x0, y0, x1, y1 : int arrays of one broadcast shape ``S``
        Pixel bounds with ``0 <= x0 <= x1 <= W`` and ``0 <= y0 <= y1 <= H`` (not checked: hot path).

    Returns
    -------
    S or S + (C,) float64
    """
    return ii[y1, x1] - ii[y0, x1] - ii[y1, x0] + ii[y0, x0]


# ---- C10: features, classifier, update -----------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class HaarFeatures:
    """A bank of multi-rectangle Haar-like features relative to a box's top-left corner (C10).

    Attributes
    ----------
    rects : (n_features, max_rects, 4) int64
        ``(x, y, w, h)`` of each rectangle inside the ``box_w x box_h`` box, px; padding rows are zeros.
    weights : (n_features, max_rects) float64
        ``±1/sqrt(n_rects)``; 0 on padding rows.
    box_w, box_h : int
        Box size the bank was drawn for, px.
    """

    rects: np.ndarray
    weights: np.ndarray
    box_w: int
    box_h: int

    def __post_init__(self) -> None:
        rects = np.array(self.rects, dtype=np.int64)
        weights = np.array(self.weights, dtype=np.float64)
        if rects.ndim != 3 or rects.shape[2] != 4 or weights.shape != rects.shape[:2]:
            raise ValueError(f"rects (n, k, 4) and weights (n, k) disagree: {rects.shape} vs {weights.shape}")
        for arr in (rects, weights):
            arr.setflags(write=False)
        object.__setattr__(self, "rects", rects)
        object.__setattr__(self, "weights", weights)

    @property
    def n_features(self) -> int:
        return int(self.rects.shape[0])

    @property
    def n_rects(self) -> np.ndarray:
        """Rectangles per feature, ``(n_features,) int``."""
        return np.count_nonzero(self.weights, axis=1)


def make_haar_features(box_w: int, box_h: int, n_features: int = 50, min_rects: int = 2, max_rects: int = 4,
                       rng: np.random.Generator | int | None = None) -> HaarFeatures:
    """Draw the random sparse measurement: ``n_features`` features of 2–3 weighted rectangles (C10, REF-CODE).

    As the reference code: ``n_rects = floor(U(min_rects, max_rects))`` (2 or 3 for the defaults, erratum
    E12), ``x = floor(U(0, w − 3))``, ``y = floor(U(0, h − 3))``, ``width = ceil(U(0, w − x − 2))``,
    ``height = ceil(U(0, h − y − 2))`` (at least 1 px here), weight ``±1/sqrt(n_rects)`` with a fair sign.

    Parameters
    ----------
    box_w, box_h : int
        Size of the tracked box, px (each at least 4).
    n_features : int
        C10: 50.
    min_rects, max_rects : int
        Bounds of ``U`` for the number of rectangles.
    rng : numpy.random.Generator | int | None

    Returns
    -------
    HaarFeatures
    """
    if int(box_w) < 4 or int(box_h) < 4:
        raise ValueError(f"box_w, box_h: the box must be at least 4x4 px, got {box_w}x{box_h}")
    if int(n_features) < 1:
        raise ValueError(f"n_features: expected >= 1, got {n_features}")
    if not 1 <= int(min_rects) < int(max_rects):
        raise ValueError(f"min_rects, max_rects: expected 1 <= min_rects < max_rects, got {min_rects}, {max_rects}")
    rng = np.random.default_rng(rng)
    w, h, n, k = int(box_w), int(box_h), int(n_features), int(max_rects)
    n_rects = np.floor(rng.uniform(min_rects, max_rects, n)).astype(np.int64)
    x = np.floor(rng.uniform(0.0, w - 3, (n, k)))
    y = np.floor(rng.uniform(0.0, h - 3, (n, k)))
    rw = np.maximum(1.0, np.ceil(rng.uniform(0.0, 1.0, (n, k)) * (w - x - 2)))
    rh = np.maximum(1.0, np.ceil(rng.uniform(0.0, 1.0, (n, k)) * (h - y - 2)))
    sign = np.where(rng.random((n, k)) < 0.5, -1.0, 1.0)
    used = np.arange(k)[None, :] < n_rects[:, None]
    rects = np.where(used[..., None], np.stack([x, y, rw, rh], axis=-1), 0).astype(np.int64)
    weights = np.where(used, sign / np.sqrt(n_rects)[:, None], 0.0)
    keep = used.any(axis=0)  # drop all-padding columns (max_rects itself is never drawn)
    return HaarFeatures(rects[:, keep], weights[:, keep], w, h)


def haar_features(ii: np.ndarray, features: HaarFeatures, origins_px: np.ndarray) -> np.ndarray:
    """Feature values ``v_i = Σ_k weight_ik · sum(rect_ik)`` of boxes with top-left corners ``origins_px`` (C10).

    Parameters
    ----------
    ii : (H + 1, W + 1) float
        Integral image of the grey frame (X3).
    features : HaarFeatures
    origins_px : (n, 2) int
        ``(u, v)`` of each box's top-left corner; the box must lie inside the frame.

    Returns
    -------
    (n_features, n) float64
    """
    o = np.asarray(origins_px, dtype=np.int64)
    if o.ndim != 2 or o.shape[1] != 2:
        raise ValueError(f"origins_px: expected an (n, 2) array, got shape {o.shape}")
    # Each feature is a fixed linear combination of integral-image entries at offsets from the box origin:
    # 4 corners x k rectangles. One gather from the flattened integral image serves every candidate.
    stride = ii.shape[1]
    r = features.rects
    x0, y0 = r[:, :, 0], r[:, :, 1]
    x1, y1 = x0 + r[:, :, 2], y0 + r[:, :, 3]
    corners = np.concatenate([y1 * stride + x1, y0 * stride + x1, y1 * stride + x0, y0 * stride + x0], axis=1)
    w = features.weights
    coef = np.concatenate([w, -w, -w, w], axis=1)  # (n_f, 4k)
    flat = np.take(ii.reshape(-1), corners[:, :, None] + (o[:, 1] * stride + o[:, 0])[None, None, :])
    return np.matmul(coef[:, None, :], flat)[:, 0, :]


@dataclass(frozen=True, slots=True, eq=False)
class CtTemplate:
    """The classifier parameters ``Ψ = {μ¹, σ¹, μ⁰, σ⁰}`` of C10/C12, each ``(n_features,) float64``."""

    mu_pos: np.ndarray
    sigma_pos: np.ndarray
    mu_neg: np.ndarray
    sigma_neg: np.ndarray

    def __post_init__(self) -> None:
        n = None
        for name in ("mu_pos", "sigma_pos", "mu_neg", "sigma_neg"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            if arr.ndim != 1 or (n is not None and arr.size != n):
                raise ValueError(f"CtTemplate.{name}: expected shape ({n or 'n'},), got {arr.shape}")
            n = arr.size
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @classmethod
    def prior(cls, n_features: int) -> CtTemplate:
        """The reference code's start: ``μ = 0``, ``σ = 1`` for every feature (C10 initialisation)."""
        return cls(np.zeros(n_features), np.ones(n_features), np.zeros(n_features), np.ones(n_features))

    @property
    def n_features(self) -> int:
        return int(self.mu_pos.size)


def ct_response(values: np.ndarray, template: CtTemplate) -> np.ndarray:
    """Naive Bayes response ``H(v) = Σ_i log p(v_i | y=1) − log p(v_i | y=0)`` (C10, Eq. 10).

    As the reference code: ``p = exp(−(v − μ)² / (2σ² + 1e−30)) / (σ + 1e−30)`` and the logs of ``p + 1e−30``,
    which caps each feature's vote at about ±69.

    Parameters
    ----------
    values : (n_features, n) float
    template : CtTemplate

    Returns
    -------
    (n,) float64
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 2 or v.shape[0] != template.n_features:
        raise ValueError(f"values: expected shape ({template.n_features}, n), got {v.shape}")

    def log_p(mu: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        p = np.exp(-((v - mu[:, None]) ** 2) / (2.0 * sigma[:, None] ** 2 + _EPS)) / (sigma[:, None] + _EPS)
        return np.log(p + _EPS)

    return (log_p(template.mu_pos, template.sigma_pos) - log_p(template.mu_neg, template.sigma_neg)).sum(axis=0)


def update_gaussians(mu: np.ndarray, sigma: np.ndarray, values: np.ndarray,
                     learning_rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Online update of per-feature Gaussians from a batch of samples (C10, Eq. 11).

    ``σ ← sqrt(λσ² + (1−λ)σ_b² + λ(1−λ)(μ − μ_b)²)`` with the *old* μ, then ``μ ← λμ + (1−λ)μ_b``
    (erratum E5), where ``μ_b, σ_b`` are the batch mean and population standard deviation.

    Parameters
    ----------
    mu, sigma : (n_features,) float
    values : (n_features, n_samples) float
        Feature values of the positive (or negative) samples, ``n_samples >= 1``.
    learning_rate : float
        λ in [0, 1] (C10: 0.85; erratum E4).

    Returns
    -------
    mu, sigma : (n_features,) float64
    """
    v = np.asarray(values, dtype=np.float64)
    mu = np.asarray(mu, dtype=np.float64)
    sigma = np.asarray(sigma, dtype=np.float64)
    if v.ndim != 2 or v.shape[0] != mu.size or v.shape[1] < 1 or sigma.shape != mu.shape:
        raise ValueError(f"values: expected shape ({mu.size}, n >= 1) matching mu and sigma, got {v.shape}")
    if not 0.0 <= learning_rate <= 1.0:
        raise ValueError(f"learning_rate: expected a value in [0, 1], got {learning_rate}")
    lam = float(learning_rate)
    mb, sb = v.mean(axis=1), v.std(axis=1)
    new_sigma = np.sqrt(lam * sigma**2 + (1.0 - lam) * sb**2 + lam * (1.0 - lam) * (mu - mb) ** 2)
    return lam * mu + (1.0 - lam) * mb, new_sigma


def disk_offsets(outer_px: float, inner_px: float = 0.0) -> np.ndarray:
    """Integer offsets ``(du, dv)`` with ``inner² <= du² + dv² < outer²`` (C10's sampling rings).

    ``disk_offsets(4)`` has the 45 positives of the paper; ``disk_offsets(25)`` the 1941 detection
    candidates of the reference code. Returns ``(n, 2) int64`` in row-major order.
    """
    if not (np.isfinite(outer_px) and outer_px > 0 and 0 <= inner_px < outer_px):
        raise ValueError(f"outer_px, inner_px: expected 0 <= inner < outer, got {outer_px}, {inner_px}")
    r = int(np.ceil(outer_px))
    dv, du = np.mgrid[-r:r + 1, -r:r + 1]
    d2 = du * du + dv * dv
    ok = (d2 < outer_px**2) & (d2 >= inner_px**2)
    return np.column_stack([du[ok], dv[ok]]).astype(np.int64)


# ---- C10: the tracker ----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class CompressiveParams:
    """Parameters of compressive tracking: the reference C++ code's defaults except ``init`` (ALGORITHMS.md C10).

    Attributes
    ----------
    n_features : int
        Number of Haar-like features (the compressed dimension), 50.
    min_rects, max_rects : int
        ``n_rects = floor(U(min_rects, max_rects))``: 2 or 3 rectangles (erratum E12).
    learning_rate : float
        λ of Eq. 11, 0.85 (erratum E4).
    search_radius_px : float
        γ: detection candidates at every integer offset with distance < γ (25 in C++, 20 in MATLAB/paper).
    positive_radius_px : float
        α_r: positives at distance < α_r (4 px: 45 samples).
    negative_inner_px : float
        ζ = α_r + 4 = 8 px: negatives at distance >= ζ ...
    negative_outer_px : float
        ... and < β = 1.5 γ = 37.5 px.
    max_negatives : int
        Each offset of the negatives' bounding square is kept with probability ``max_negatives / side²``
        (about 75 negatives expected for 100).
    init : {"first_frame", "prior"}
        ``"first_frame"`` (C10's option, the default here): ``μ, σ`` are the first frame's sample statistics.
        ``"prior"`` (the reference code, for parity): the template starts at ``μ = 0, σ = 1`` and the first
        frame's samples are blended in with λ, so for about ten frames ``μ`` is pulled towards 0 and the box
        towards dark candidates; the box then often keeps an offset it learnt in those frames (on 8 synthetic
        100-frame sequences: mean centre error 4.4 px against 1.9 px).
    """

    n_features: int = 50
    min_rects: int = 2
    max_rects: int = 4
    learning_rate: float = 0.85
    search_radius_px: float = 25.0
    positive_radius_px: float = 4.0
    negative_inner_px: float = 8.0
    negative_outer_px: float = 37.5
    max_negatives: int = 100
    init: str = "first_frame"

    def __post_init__(self) -> None:
        if self.init not in ("prior", "first_frame"):
            raise ValueError(f"init: expected 'first_frame' or 'prior', got {self.init!r}")
        for name in ("n_features", "min_rects", "max_rects", "max_negatives"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
        if self.max_rects <= self.min_rects:
            raise ValueError(f"max_rects: expected > min_rects = {self.min_rects}, got {self.max_rects}")
        if not 0.0 <= self.learning_rate <= 1.0:
            raise ValueError(f"learning_rate: expected a value in [0, 1], got {self.learning_rate}")
        for name in ("search_radius_px", "positive_radius_px", "negative_outer_px"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 1:
                raise ValueError(f"{name}: expected a finite value >= 1 px, got {value}")
        if not 0 <= self.negative_inner_px < self.negative_outer_px:
            raise ValueError(f"negative_inner_px: expected 0 <= value < negative_outer_px = "
                             f"{self.negative_outer_px}, got {self.negative_inner_px}")


@dataclass(frozen=True, slots=True, eq=False)
class CtResult:
    """One frame of :class:`CompressiveTracker`.

    Attributes
    ----------
    box_px : (4,) float64
        ``(u_min, v_min, u_max, v_max)``.
    response : float
        ``H(v)`` of the chosen candidate under the template used for detection.
    values : (n_features,) float64
        Its feature vector ``v``.
    n_candidates : int
    """

    box_px: np.ndarray
    response: float
    values: np.ndarray
    n_candidates: int

    @property
    def centre_px(self) -> np.ndarray:
        """``(2,)`` box centre ``(u, v)``."""
        return 0.5 * (self.box_px[:2] + self.box_px[2:])


def _grey(frame: np.ndarray, name: str = "frame") -> np.ndarray:
    f = np.asarray(frame)
    if f.ndim == 3 and f.shape[2] == 3 and f.dtype == np.uint8:
        return cv2.cvtColor(f, cv2.COLOR_BGR2GRAY)
    if f.ndim != 2 or f.dtype != np.uint8:
        raise ValueError(f"{name}: expected a grey (H, W) or BGR (H, W, 3) uint8 image, got {f.shape} {f.dtype}")
    return f


def _integral_u8(grey: np.ndarray) -> np.ndarray:
    """Exact int32 integral image of a uint8 frame (up to 8.4 Mpx): gathers of 4-byte entries are ~3x faster."""
    return cv2.integral(grey, sdepth=cv2.CV_32S)


def _check_box(box_px: Any, width: int, height: int, name: str = "box_px") -> np.ndarray:
    b = np.asarray(box_px, dtype=np.float64)
    if b.shape != (4,) or not np.all(np.isfinite(b)) or b[2] <= b[0] or b[3] <= b[1]:
        raise ValueError(f"{name}: expected (u_min, v_min, u_max, v_max) with u_max > u_min, v_max > v_min, got "
                         f"{box_px}")
    if b[0] < -0.5 or b[1] < -0.5 or b[2] > width + 0.5 or b[3] > height + 0.5:
        raise ValueError(f"{name}: {b.tolist()} is not inside the {width}x{height} frame")
    return b


class CompressiveTracker:
    """Compressive tracking of one fixed-size box in grey frames (ALGORITHMS.md C10).

    Parameters
    ----------
    frame : (H, W) uint8 grey or (H, W, 3) uint8 BGR
        The first frame.
    box_px : (4,) float
        ``(u_min, v_min, u_max, v_max)`` of the target in ``frame``; rounded to whole pixels, and its size is
        kept for the whole track (no scale estimation, as C10).
    params : CompressiveParams
    rng : numpy.random.Generator | int | None
        Draws the feature bank and the negative samples.

    The first template is the first frame's sample statistics (``params.init = "first_frame"``), or, as the
    reference code, ``μ = 0, σ = 1`` blended once with them (``"prior"``).
    """

    def __init__(self, frame: np.ndarray, box_px: Any, params: CompressiveParams | None = None,
                 rng: np.random.Generator | int | None = None) -> None:
        self.params = params if params is not None else CompressiveParams()
        self._rng = np.random.default_rng(rng)
        grey = _grey(frame)
        self.frame_shape = grey.shape
        b = np.round(_check_box(box_px, grey.shape[1], grey.shape[0]))
        self._size = (int(b[2] - b[0]), int(b[3] - b[1]))
        if self._size[0] > grey.shape[1] - 1 or self._size[1] > grey.shape[0] - 1:
            raise ValueError(f"box_px: a {self._size[0]}x{self._size[1]} box does not fit in the frame with room to "
                             f"move ({grey.shape[1]}x{grey.shape[0]})")
        p = self.params
        self.features = make_haar_features(*self._size, p.n_features, p.min_rects, p.max_rects, self._rng)
        self._detect_offsets = disk_offsets(p.search_radius_px)
        self._pos_offsets = disk_offsets(p.positive_radius_px)
        self._neg_offsets = disk_offsets(p.negative_outer_px, p.negative_inner_px)
        self._origin = self._clip_origin(b[:2])
        first = 0.0 if p.init == "first_frame" else None
        self.template = self.updated_template(_integral_u8(grey), CtTemplate.prior(p.n_features), first)

    # ---- geometry --------------------------------------------------------------------------------

    @property
    def box_px(self) -> np.ndarray:
        """Current box ``(u_min, v_min, u_max, v_max)``, ``(4,) float64``."""
        o = self._origin
        return np.array([o[0], o[1], o[0] + self._size[0], o[1] + self._size[1]], dtype=np.float64)

    def _clip_origin(self, origin: Any) -> np.ndarray:
        hi = np.array([self.frame_shape[1] - self._size[0], self.frame_shape[0] - self._size[1]])
        return np.clip(np.round(np.asarray(origin, dtype=np.float64)), 0, hi).astype(np.int64)

    def _inside(self, origins: np.ndarray) -> np.ndarray:
        hi = np.array([self.frame_shape[1] - self._size[0], self.frame_shape[0] - self._size[1]])
        return np.all((origins >= 0) & (origins <= hi), axis=1)

    def _samples(self, offsets: np.ndarray, origin: np.ndarray) -> np.ndarray:
        o = origin + offsets
        return o[self._inside(o)]

    def reset(self, centre_px: Any) -> None:
        """Move the box so that its centre is at ``centre_px`` ``(2,)`` (clipped into the frame); C12 step 3."""
        c = np.asarray(centre_px, dtype=np.float64)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise ValueError(f"centre_px: expected a finite (2,) pixel position, got {centre_px}")
        self._origin = self._clip_origin(c - 0.5 * np.array(self._size))

    # ---- C10 steps -------------------------------------------------------------------------------

    def detect(self, frame: np.ndarray, template: CtTemplate | None = None) -> tuple[CtResult, np.ndarray]:
        """Evaluate every candidate within γ of the current box and move to the best (C10 detection).

        Returns the result and the frame's integral image (for :meth:`updated_template`).
        """
        grey = _grey(frame)
        if grey.shape != self.frame_shape:
            raise ValueError(f"frame: expected size {self.frame_shape}, got {grey.shape}")
        ii = _integral_u8(grey)
        cand = self._samples(self._detect_offsets, self._origin)
        if cand.shape[0] == 0:  # cannot happen once the origin is clipped; kept for safety
            cand = self._origin[None, :]
        v = haar_features(ii, self.features, cand)
        h = ct_response(v, self.template if template is None else template)
        k = int(np.argmax(h))
        self._origin = cand[k]
        return CtResult(self.box_px, float(h[k]), v[:, k].copy(), int(cand.shape[0])), ii

    def values_at_box(self, ii: np.ndarray) -> np.ndarray:
        """Feature vector ``(n_features,)`` of the current box in the frame of integral image ``ii``."""
        return haar_features(ii, self.features, self._origin[None, :])[:, 0]

    def updated_template(self, ii: np.ndarray, template: CtTemplate | None = None,
                         learning_rate: float | None = None) -> CtTemplate:
        """``template`` (default: the current one) updated with positives and negatives around the box (Eq. 11).

        Pure with respect to the tracker, except that it draws the negatives from the tracker's ``rng``.
        ``learning_rate`` overrides λ (0: take the samples' statistics).
        """
        p = self.params
        lam = p.learning_rate if learning_rate is None else learning_rate
        t = self.template if template is None else template
        pos = self._samples(self._pos_offsets, self._origin)
        neg = self._samples(self._neg_offsets, self._origin)
        if neg.shape[0]:
            # C++ sampleRect: each offset of the (clipped) bounding square kept with probability max/side²
            span = np.ptp(neg, axis=0) + 1
            keep = self._rng.random(neg.shape[0]) < p.max_negatives / float(span[0] * span[1])
            neg = neg[keep] if keep.any() else neg[:1]
        mu1, s1 = update_gaussians(t.mu_pos, t.sigma_pos, haar_features(ii, self.features, pos), lam)
        if neg.shape[0] == 0:  # box as large as the frame: no room for background samples
            return CtTemplate(mu1, s1, t.mu_neg, t.sigma_neg)
        mu0, s0 = update_gaussians(t.mu_neg, t.sigma_neg, haar_features(ii, self.features, neg), lam)
        return CtTemplate(mu1, s1, mu0, s0)

    def step(self, frame: np.ndarray) -> CtResult:
        """Plain compressive tracking: detect, then update the template at the new box (C10)."""
        result, ii = self.detect(frame)
        self.template = self.updated_template(ii)
        return result


# ---- C11: consistency ----------------------------------------------------------------------------


def failure_threshold(probability: float = 0.95) -> float:
    """``τ_sim = exp(−½ χ²₂(probability))``: 0.05 for 0.95 (ALGORITHMS.md C11)."""
    if not 0.0 < probability < 1.0:
        raise ValueError(f"probability: expected a value in (0, 1), got {probability}")
    return float(np.exp(-0.5 * chi2.ppf(probability, 2)))


def consistency(x_px: Any, x_proj_px: Any, cov_px2: Any) -> np.ndarray:
    """``sim(x, x') = exp(−½ (x − x')ᵀ Σ⁻¹ (x − x'))`` (C11, Eq. 12), vectorised over points.

    Parameters
    ----------
    x_px : (2,) or (n, 2) float
        Visual positions (box centres), px.
    x_proj_px : (2,) or (n, 2) float
        Inertial positions projected into the image (C9), px.
    cov_px2 : (2, 2) float
        Σ, symmetric positive definite, px².

    Returns
    -------
    () or (n,) float64 in [0, 1]
    """
    cov = np.asarray(cov_px2, dtype=np.float64)
    if cov.shape != (2, 2) or not np.allclose(cov, cov.T) or np.any(np.linalg.eigvalsh(cov) <= 0):
        raise ValueError(f"cov_px2: expected a symmetric positive definite (2, 2) matrix, got {cov.tolist()}")
    d = np.asarray(x_px, dtype=np.float64) - np.asarray(x_proj_px, dtype=np.float64)
    if d.shape[-1] != 2:
        raise ValueError(f"x_px, x_proj_px: expected (..., 2) pixel positions, got {d.shape}")
    m2 = np.einsum("...i,ij,...j->...", d, np.linalg.inv(cov), d)
    return np.exp(-0.5 * m2)


# ---- C12: multi-template recovery ----------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class MultiTemplateParams:
    """Parameters of the C11 failure test and the C12 template buffer (ALGORITHMS.md C11, C12; RECON).

    Attributes
    ----------
    buffer_size : int
        N stored templates, 10.
    tau_sim : float
        Failure when ``sim < tau_sim``; ``exp(−½ χ²₂(0.95)) ≈ 0.05``.
    n_ok : int
        Updates resume after ``n_ok`` consecutive consistent frames following a failure (hysteresis), 3.
    min_sigma_px : float
        Floor on the standard deviations of Σ (a training set with tiny residuals must not make every frame
        a failure), px.
    relearn_after : int
        After this many consecutive failures, learn a fresh template at the reset box (sample statistics of
        the current frame) [RECON; 0 = never, the paper's rule]. Every stored template may predate a lasting
        appearance change (lights switched off): without relearning the box then follows the projected
        inertial position for as long as the change lasts.
    """

    buffer_size: int = 10
    tau_sim: float = field(default_factory=failure_threshold)
    n_ok: int = 3
    min_sigma_px: float = 2.0
    relearn_after: int = 0

    def __post_init__(self) -> None:
        for name in ("buffer_size", "n_ok"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
        if isinstance(self.relearn_after, bool) or not isinstance(self.relearn_after, int | np.integer) \
                or self.relearn_after < 0:
            raise ValueError(f"relearn_after: expected an integer >= 0, got {self.relearn_after!r}")
        if not 0.0 < self.tau_sim < 1.0:
            raise ValueError(f"tau_sim: expected a value in (0, 1), got {self.tau_sim}")
        if not np.isfinite(self.min_sigma_px) or self.min_sigma_px < 0:
            raise ValueError(f"min_sigma_px: expected a finite value >= 0, got {self.min_sigma_px}")


@dataclass(frozen=True, slots=True, eq=False)
class MultiTemplateResult:
    """One frame of :class:`MultiTemplateTracker`.

    Attributes
    ----------
    box_px : (4,) float64
        The output box: the CT box, or after a failure the box reset onto the projected inertial position.
    visual_box_px : (4,) float64
        The CT detection before any reset.
    sim : float
        C11 consistency of the CT box centre with ``projected_px``; NaN without inertial data.
    failure : bool
        ``sim < tau_sim``: the box was reset and the best stored template restored.
    updating : bool
        Whether Ψ was updated this frame.
    restored : int
        Index of the buffer template restored on failure, else -1.
    status : str
        ``"ok"``, ``"failure"``, ``"recovering"`` (consistent, waiting ``n_ok`` frames), ``"no_inertial"``
        (plain CT) or ``"out_of_view"`` (projection outside the frame: suspended).
    response : float
        ``H(v)`` of the CT detection.
    n_templates : int
        Templates in the buffer after this frame.
    """

    box_px: np.ndarray
    visual_box_px: np.ndarray
    sim: float
    failure: bool
    updating: bool
    restored: int
    status: str
    response: float
    n_templates: int

    @property
    def centre_px(self) -> np.ndarray:
        return 0.5 * (self.box_px[:2] + self.box_px[2:])


def template_responses(values: np.ndarray, templates: list[CtTemplate]) -> np.ndarray:
    """``H(v, Ψ_i)`` of one feature vector ``v`` ``(n_f,)`` under each of several templates: ``(n_templates,)``.

    Eq. 10 with the templates as the batch axis; C12 replaces ``argmin_i`` (Eq. 13) and restores ``argmax_i``
    (Eq. 14) of these.
    """
    if not templates:
        raise ValueError("templates: expected at least one template")
    mu1, s1, mu0, s0 = (np.stack([getattr(t, f) for t in templates])
                        for f in ("mu_pos", "sigma_pos", "mu_neg", "sigma_neg"))  # (n_t, n_f) each
    v = np.asarray(values, dtype=np.float64)[None, :]

    def log_p(mu: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        return np.log(np.exp(-((v - mu) ** 2) / (2.0 * sigma**2 + _EPS)) / (sigma + _EPS) + _EPS)

    return (log_p(mu1, s1) - log_p(mu0, s0)).sum(axis=1)


class MultiTemplateTracker:
    """Compressive tracking checked against the projected inertial position, with template recovery (C11, C12).

    Parameters
    ----------
    frame : (H, W) uint8 grey or (H, W, 3) uint8 BGR
        The first frame.
    box_px : (4,) float
        The target's box in ``frame``.
    cov_px2 : (2, 2) float
        Σ of C11: the covariance of the visual-vs-projected residuals (e.g.
        :attr:`fusiontrack.inertial.projection.InertialProjection.residual_cov_px2`), px²; its standard
        deviations are floored at ``min_sigma_px``.
    params : MultiTemplateParams
    ct_params : CompressiveParams
    rng : numpy.random.Generator | int | None

    Per frame (:meth:`step`) with the projected inertial position ``x'`` (C9):

    1. CT detection with the current Ψ gives the box centre ``x`` and features ``v``; ``s = sim(x, x')``.
    2. ``s >= τ``: Ψ is updated (Eq. 11) unless recovering; the buffer takes a copy while it has fewer than N,
       else Ψ replaces ``argmin_i H(v, Ψ_i)`` when ``H(v, Ψ)`` beats it (Eq. 13).
    3. ``s < τ``: failure. The box centre is reset to ``x'`` (size kept), updates stop, and
       ``Ψ ← argmax_i H(v', Ψ_i)`` with ``v'`` the features at the reset box (Eq. 14).
    4. Updates resume after ``n_ok`` consecutive frames with ``s >= τ``.

    Without inertial data the tracker runs as plain CT (status ``"no_inertial"``); the buffer only takes
    templates that the consistency test confirmed.
    """

    def __init__(self, frame: np.ndarray, box_px: Any, cov_px2: Any, params: MultiTemplateParams | None = None,
                 ct_params: CompressiveParams | None = None, rng: np.random.Generator | int | None = None) -> None:
        self.params = params if params is not None else MultiTemplateParams()
        self.cov_px2 = self._floored(cov_px2)
        self.ct = CompressiveTracker(frame, box_px, ct_params, rng)
        self.buffer: list[CtTemplate] = [self.ct.template]
        self.updating = True
        self._ok_run = 0
        self._fail_run = 0
        self.n_failures = 0
        self.n_replacements = 0

    @property
    def box_px(self) -> np.ndarray:
        return self.ct.box_px

    @property
    def template(self) -> CtTemplate:
        return self.ct.template

    def _floored(self, cov_px2: Any) -> np.ndarray:
        """Σ with its eigenvalues floored at ``min_sigma_px²``; checks shape, symmetry and definiteness."""
        cov = np.array(cov_px2, dtype=np.float64)
        if cov.shape != (2, 2) or not np.all(np.isfinite(cov)) or not np.allclose(cov, cov.T):
            raise ValueError(f"cov_px2: expected a finite symmetric (2, 2) matrix, got {np.asarray(cov_px2).tolist()}")
        w, vec = np.linalg.eigh(cov)
        w = np.maximum(w, self.params.min_sigma_px**2)
        if np.any(w <= 0):
            raise ValueError(f"cov_px2: not positive definite ({cov.tolist()}) and min_sigma_px is 0")
        return (vec * w) @ vec.T

    def _store(self, values: np.ndarray) -> None:
        """Eq. 13: fill the buffer, then replace the worst stored template when Ψ matches ``v`` better."""
        t = self.ct.template
        if len(self.buffer) < self.params.buffer_size:
            self.buffer.append(t)
            return
        h_i = template_responses(values, self.buffer)
        h = float(ct_response(values[:, None], t)[0])
        if np.any(h > h_i):
            self.buffer[int(np.argmin(h_i))] = t
            self.n_replacements += 1

    def step(self, frame: np.ndarray, projected_px: Any = None, cov_px2: Any = None) -> MultiTemplateResult:
        """Track one frame.

        Parameters
        ----------
        frame : (H, W) uint8 grey or (H, W, 3) uint8 BGR
        projected_px : (2,) float or None
            ``x' = P·X(t)`` (C9); ``None`` or NaN without inertial data (plain CT, flagged).
        cov_px2 : (2, 2) float, optional
            Σ for this frame (e.g. :meth:`~fusiontrack.inertial.projection.InertialProjection.image_cov_px2`,
            growing with the dead-reckoning uncertainty); default the constructor's.
        """
        cov = self.cov_px2 if cov_px2 is None else self._floored(cov_px2)
        result, ii = self.ct.detect(frame)
        visual_box = result.box_px
        xp = None if projected_px is None else np.asarray(projected_px, dtype=np.float64)
        if xp is not None and xp.shape != (2,):
            raise ValueError(f"projected_px: expected a (2,) pixel position or None, got shape {xp.shape}")
        h_img, w_img = self.ct.frame_shape
        if xp is None or not np.all(np.isfinite(xp)):
            status, s = "no_inertial", float("nan")  # C12 edge case: plain CT, flagged
            if self.updating:
                self.ct.template = self.ct.updated_template(ii)
            return self._result(visual_box, visual_box, s, False, self.updating, -1, status, result.response)
        if not (0 <= xp[0] < w_img and 0 <= xp[1] < h_img):  # the target has left the view: suspend
            return self._result(visual_box, visual_box, float("nan"), False, False, -1, "out_of_view",
                                result.response)
        s = float(consistency(result.centre_px, xp, cov))
        if s >= self.params.tau_sim:
            self._ok_run += 1
            self._fail_run = 0
            if not self.updating and self._ok_run >= self.params.n_ok:
                self.updating = True
                log.debug("compressive tracker: %d consistent frames, updates resume", self._ok_run)
            if not self.updating:
                return self._result(visual_box, visual_box, s, False, False, -1, "recovering", result.response)
            self.ct.template = self.ct.updated_template(ii)
            self._store(result.values)
            return self._result(visual_box, visual_box, s, False, True, -1, "ok", result.response)
        # failure (C12 step 3)
        self._ok_run = 0
        self._fail_run += 1
        self.updating = False
        self.n_failures += 1
        self.ct.reset(xp)
        restored = -1
        if self.params.relearn_after and self._fail_run >= self.params.relearn_after:
            self.ct.template = self.ct.updated_template(ii, learning_rate=0.0)
            self._fail_run = 0
            log.debug("compressive tracker: %d failures in a row, template relearnt at the inertial position",
                      self.params.relearn_after)
        elif self.buffer:
            h_i = template_responses(self.ct.values_at_box(ii), self.buffer)
            restored = int(np.argmax(h_i))
            self.ct.template = self.buffer[restored]
        return self._result(self.ct.box_px, visual_box, s, True, False, restored, "failure", result.response)

    def _result(self, box: np.ndarray, visual: np.ndarray, s: float, failure: bool, updating: bool, restored: int,
                status: str, response: float) -> MultiTemplateResult:
        return MultiTemplateResult(box, visual, s, failure, updating, restored, status, response, len(self.buffer))
