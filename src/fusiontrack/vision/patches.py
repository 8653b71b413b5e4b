"""Random image patches in a box and their features (seed 001, ALGORITHMS.md B12, B13).

* B12 — :func:`sample_patches`: a "bag of patches" [Lu & Hager 2006] of fixed size ``s × s`` (12 px) at
  uniform random positions inside each target's box, ``N = clip(round(γ w h / s²), 10, 150)`` of them
  (γ = 1.5) where ``w × h`` is the part of the box inside the image; none when less than 30 % of the box
  is visible. A box narrower than a patch (but at least half as wide) gets patches centred on it across
  that direction; a smaller one gets none. :func:`grid_patches` places patches on a
  regular grid instead (dense score maps, B16).
* B13 — :func:`patch_features`: per patch a ``d = 23`` vector: the colour of each cell of a 2×2 grid (12)
  and the Edge Orientation Histogram of Levi & Weiss (2004): K = 4 dominant-orientation features,
  K(K−1)/2 = 6 log-ratios and one left/right mirror-symmetry feature. The colour of a cell is its mean
  R, G, B written as intensity and chromaticity ``(I, r, g)`` by default (``FeatureParams.colour``), a
  lossless change of coordinates of B13's mean R, G, B in which a surface's hue does not change with its
  shading; ``colour="rgb"`` gives B13's literal mean R, G, B in [0, 1].
  :func:`integral_channels` computes the gradients (``cv2.Sobel``) once per image region and the integral
  images (X3) of R, G, B and of the K per-bin gradient magnitudes ``ψ_k``, so any patch costs four
  look-ups per channel and cell, whatever its size.

Conventions (ALGORITHMS.md 0.2): a box is ``(u_min, v_min, u_max, v_max)`` in pixels on pixel *edges*
(pixel ``(x, y)`` covers ``[x, x+1) × [y, y+1)``). A patch is given by the integer pixel of its top-left
corner ``(x, y)`` and covers columns ``x .. x+s−1`` and rows ``y .. y+s−1``; its centre is ``(x + s/2,
y + s/2)``. Gradients are Sobel 3×3 divided by 8, i.e. grey levels per pixel, so that the threshold
``τ_G = 10`` means a change of 10 grey levels (0–255) per pixel [RECON].
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

__all__ = [
    "FeatureParams",
    "IntegralCache",
    "PatchIntegrals",
    "PatchParams",
    "Patches",
    "as_boxes",
    "box_visibility",
    "clip_boxes",
    "extract_features",
    "grid_patches",
    "integral_channels",
    "orientation_energy",
    "patch_centres",
    "patch_counts",
    "patch_eoh",
    "patch_features",
    "patch_fraction",
    "patch_region",
    "sample_patches",
    "validate_image",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------------
# parameters
@dataclass(frozen=True, slots=True)
class PatchParams:
    """Patch sampling, ALGORITHMS.md B12 [RECON values].

    Attributes
    ----------
    size_px : int
        Patch side ``s`` (12 px); even, so the 2×2 grid and the two halves of B13 are exact.
    density : float
        ``γ`` in ``N = round(γ w h / s²)`` (1.5).
    min_count, max_count : int
        Clip of ``N`` (10, 150).
    min_visible : float
        Fraction of the box that must be inside the image for it to be sampled at all (0.3).
    """

    size_px: int = 12
    density: float = 1.5
    min_count: int = 10
    max_count: int = 150
    min_visible: float = 0.3

    def __post_init__(self) -> None:
        s = self.size_px
        if isinstance(s, bool) or not isinstance(s, int) or s < 2 or s % 2 or s > 256:
            raise ValueError(f"PatchParams.size_px: expected an even integer in 2..256 px, got {s!r}")
        if not (np.isfinite(self.density) and self.density > 0):
            raise ValueError(f"PatchParams.density: expected a finite value > 0, got {self.density!r}")
        for name in ("min_count", "max_count"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"PatchParams.{name}: expected an integer >= 1, got {v!r}")
        if self.max_count < self.min_count:
            raise ValueError(f"PatchParams.max_count: expected >= min_count = {self.min_count}, got {self.max_count}")
        if not 0 <= self.min_visible <= 1:
            raise ValueError(f"PatchParams.min_visible: expected a fraction in [0, 1], got {self.min_visible!r}")


@dataclass(frozen=True, slots=True)
class FeatureParams:
    """Patch features, ALGORITHMS.md B13.

    Attributes
    ----------
    n_bins : int
        Orientation bins ``K`` over [0, π) (4, REF Levi & Weiss); bin k is centred at ``kπ/K``.
    grad_threshold : float
        ``τ_G`` in grey levels per pixel (10) [RECON]; weaker gradients count in no bin.
    eps_scale : float
        ``ε = eps_scale · s²`` regularises the ratios (0.01) [RECON].
    colour : str
        The colour of each 2×2 cell: ``"chromaticity"`` (default) ``(I, r, g)`` with ``I = (R+G+B)/3`` in [0, 1]
        and ``r = (R+κ)/(R+G+B+3κ)``, ``g = (G+κ)/(R+G+B+3κ)``; or ``"rgb"``, B13's mean R, G, B in [0, 1].
        Both carry the same information, but a person's clothing keeps its ``r, g`` as the light falling on
        it changes with the viewing angle and the body's orientation, while its R, G, B all scale with the
        shading; axis-aligned CART splits (B14) then learn the clothing, not its lighting [deviation from B13's
        wording, measured in tests/test_vision_appearance_sim.py].
    chroma_eps : float
        ``κ`` in grey levels (0–255, 5): pulls the chromaticity of dark cells, dominated by sensor noise,
        towards neutral grey [RECON].
    """

    n_bins: int = 4
    grad_threshold: float = 10.0
    eps_scale: float = 0.01
    colour: str = "chromaticity"
    chroma_eps: float = 5.0

    def __post_init__(self) -> None:
        k = self.n_bins
        if isinstance(k, bool) or not isinstance(k, int) or not 2 <= k <= 64:
            raise ValueError(f"FeatureParams.n_bins: expected an integer in 2..64, got {k!r}")
        if not (np.isfinite(self.grad_threshold) and self.grad_threshold >= 0):
            raise ValueError(f"FeatureParams.grad_threshold: expected a finite value >= 0, got {self.grad_threshold!r}")
        if not (np.isfinite(self.eps_scale) and self.eps_scale > 0):
            raise ValueError(f"FeatureParams.eps_scale: expected a finite value > 0, got {self.eps_scale!r}")
        if self.colour not in ("chromaticity", "rgb"):
            raise ValueError(f"FeatureParams.colour: expected 'chromaticity' or 'rgb', got {self.colour!r}")
        if not (np.isfinite(self.chroma_eps) and self.chroma_eps > 0):
            raise ValueError(f"FeatureParams.chroma_eps: expected a finite value > 0 grey levels, got "
                             f"{self.chroma_eps!r}")

    @property
    def n_features(self) -> int:
        """``d = 12 + K + K(K−1)/2 + 1`` (23 for K = 4)."""
        k = self.n_bins
        return 12 + k + k * (k - 1) // 2 + 1


# --------------------------------------------------------------------------------------------------
# input checks
def validate_image(image: Any, name: str = "image") -> np.ndarray:
    """Return a colour image as ``(H, W, 3) uint8`` BGR, or raise ``ValueError`` naming ``name``.

    Accepts an array or a :class:`fusiontrack.types.Image` (anything with a ``bgr()`` method).
    """
    if hasattr(image, "bgr") and callable(image.bgr):
        image = image.bgr()
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{name}: expected an (H, W, 3) uint8 BGR array, got {type(image).__name__}")
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"{name}: expected an (H, W, 3) uint8 BGR array, got {image.dtype} {image.shape}")
    if image.shape[0] < 1 or image.shape[1] < 1:
        raise ValueError(f"{name}: the image is empty ({image.shape})")
    return image


def as_boxes(boxes_px: Any, name: str = "boxes_px") -> np.ndarray:
    """``(n, 4) float64`` from one box ``(4,)`` or several ``(n, 4)``; finite with positive width and height."""
    boxes = np.asarray(boxes_px, dtype=np.float64)
    if boxes.ndim == 1:
        boxes = boxes[None, :]
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise ValueError(f"{name}: expected (n, 4) boxes (u_min, v_min, u_max, v_max) px, got shape {boxes.shape}")
    bad = ~np.isfinite(boxes).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name}[{i}]: box is not finite: {boxes[i].tolist()}")
    empty = (boxes[:, 2] <= boxes[:, 0]) | (boxes[:, 3] <= boxes[:, 1])
    if empty.any():
        i = int(np.flatnonzero(empty)[0])
        raise ValueError(f"{name}[{i}]: empty box (expected u_max > u_min and v_max > v_min): {boxes[i].tolist()}")
    return boxes


def _image_hw(image_shape: Any) -> tuple[int, int]:
    shape = tuple(image_shape)
    if len(shape) < 2 or int(shape[0]) < 1 or int(shape[1]) < 1:
        raise ValueError(f"image_shape: expected (H, W[, 3]) with H, W >= 1, got {shape}")
    return int(shape[0]), int(shape[1])


# --------------------------------------------------------------------------------------------------
# B12: patches
@dataclass(frozen=True, slots=True, eq=False)
class Patches:
    """A set of patches of one size.

    Attributes
    ----------
    corners_px : (n, 2) int64
        ``(x, y)`` of each patch's top-left pixel.
    box_index : (n,) int64
        Index of the box each patch was drawn from (0 for a grid).
    size_px : int
        Side ``s``.
    """

    corners_px: np.ndarray
    box_index: np.ndarray
    size_px: int

    def __len__(self) -> int:
        return len(self.corners_px)

    @property
    def centres_px(self) -> np.ndarray:
        """``(n, 2) float64`` patch centres ``(u, v)``."""
        return patch_centres(self.corners_px, self.size_px)

    def subset(self, keep: np.ndarray) -> Patches:
        """The patches selected by a boolean mask or index array."""
        return Patches(self.corners_px[keep], self.box_index[keep], self.size_px)


def patch_centres(corners_px: np.ndarray, size_px: int) -> np.ndarray:
    """Centres ``(n, 2) float64`` of patches with top-left pixels ``corners_px`` ``(n, 2)``."""
    return np.asarray(corners_px, dtype=np.float64).reshape(-1, 2) + size_px / 2.0


def clip_boxes(boxes_px: np.ndarray, image_shape: tuple[int, ...]) -> np.ndarray:
    """Boxes ``(n, 4)`` clipped to the image ``[0, W] × [0, H]``; an off-image box gets zero width or height."""
    h, w = _image_hw(image_shape)
    b = np.asarray(boxes_px, dtype=np.float64).reshape(-1, 4)
    out = np.clip(b, 0.0, [w, h, w, h])
    out[:, 2] = np.maximum(out[:, 2], out[:, 0])
    out[:, 3] = np.maximum(out[:, 3], out[:, 1])
    return out


def box_visibility(boxes_px: np.ndarray, image_shape: tuple[int, ...]) -> np.ndarray:
    """Fraction ``(n,)`` of each box's area inside the image (0 for a non-finite or empty box)."""
    b = np.asarray(boxes_px, dtype=np.float64).reshape(-1, 4)
    finite = np.isfinite(b)
    return _visibility(b, clip_boxes(np.where(finite, b, 0.0), image_shape), finite.all(axis=1))


def _visibility(b: np.ndarray, clipped: np.ndarray, finite: np.ndarray | bool = True) -> np.ndarray:
    """:func:`box_visibility` of boxes ``b`` clipped to the image (``clipped``), ``finite`` the finite rows."""
    area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    inside = (clipped[:, 2] - clipped[:, 0]) * (clipped[:, 3] - clipped[:, 1])
    ok = finite & (area > 0)
    return np.where(ok, inside / np.where(ok, area, 1.0), 0.0)


def _corner_ranges(boxes: np.ndarray, image_shape: tuple[int, ...], s: int) -> np.ndarray:
    """Inclusive integer ranges ``(n, 4)`` ``(x_lo, y_lo, x_hi, y_hi)`` of top-left corners whose patch lies in the
    clipped box.

    A visible box narrower (or shorter) than ``s`` but at least ``s/2`` gets patches centred on it in that
    direction, overhanging it but inside the image (a person seen edge-on) [RECON]; ``hi < lo`` when even that
    is impossible."""
    return _ranges_of_clipped(clip_boxes(boxes, image_shape), image_shape, s)


def _ranges_of_clipped(c: np.ndarray, image_shape: tuple[int, ...], s: int) -> np.ndarray:
    """:func:`_corner_ranges` of boxes already clipped to the image."""
    h, w = _image_hw(image_shape)
    lo = np.ceil(c[:, :2] - 1e-9)
    hi = np.floor(c[:, 2:] + 1e-9) - s
    narrow = (hi < lo) & (c[:, 2:] - c[:, :2] >= s / 2)
    centred = np.clip(np.round((c[:, :2] + c[:, 2:] - s) / 2), 0, np.array([w, h]) - s)
    lo = np.where(narrow, centred, lo)
    hi = np.where(narrow, centred, hi)
    return np.concatenate([lo, hi], axis=1).astype(np.int64)


def patch_counts(boxes_px: np.ndarray, image_shape: tuple[int, ...], params: PatchParams | None = None) -> np.ndarray:
    """Number of patches ``(n,) int64`` B12 draws in each box.

    ``clip(round(γ w h / s²), min_count, max_count)`` with ``w × h`` the visible part of the box; 0 when less
    than ``min_visible`` of the box is inside the image or when its visible part is less than ``s/2`` wide or high.
    """
    p = params or PatchParams()
    boxes = as_boxes(boxes_px)
    c = clip_boxes(boxes, image_shape)
    return _counts(boxes, c, _ranges_of_clipped(c, image_shape, p.size_px), p)


def _counts(boxes: np.ndarray, clipped: np.ndarray, ranges: np.ndarray, p: PatchParams) -> np.ndarray:
    """:func:`patch_counts` of finite boxes given clipped and their corner ranges."""
    area = (clipped[:, 2] - clipped[:, 0]) * (clipped[:, 3] - clipped[:, 1])
    n = np.clip(np.round(p.density * area / p.size_px**2), p.min_count, p.max_count).astype(np.int64)
    fits = (ranges[:, 2] >= ranges[:, 0]) & (ranges[:, 3] >= ranges[:, 1])
    return np.where(fits & (_visibility(boxes, clipped) >= p.min_visible), n, 0)


def sample_patches(
    boxes_px: np.ndarray,
    image_shape: tuple[int, ...],
    params: PatchParams | None = None,
    rng: np.random.Generator | int | None = None,
    counts: np.ndarray | None = None,
) -> Patches:
    """Draw B12's random patches in each box (ALGORITHMS.md B12), vectorised over boxes and patches.

    Parameters
    ----------
    boxes_px : (n_boxes, 4) or (4,) float
        ``(u_min, v_min, u_max, v_max)`` px.
    image_shape : tuple
        ``(H, W[, 3])``.
    params : PatchParams, optional
    rng : numpy.random.Generator or int or None
    counts : (n_boxes,) int, optional
        Patches per box instead of B12's count (still 0 where the box is too little visible).

    Returns
    -------
    Patches
        Patches grouped by box (``box_index`` ascending), each lying wholly inside its box and the image.

    Raises
    ------
    ValueError
        A box that is not finite, is empty, or does not overlap the image at all.
    """
    p = params or PatchParams()
    rng = np.random.default_rng(rng)
    boxes = as_boxes(boxes_px)
    h, w = _image_hw(image_shape)
    c = clip_boxes(boxes, image_shape)  # (as_boxes: finite)
    off = _visibility(boxes, c) <= 0
    if off.any():
        i = int(np.flatnonzero(off)[0])
        raise ValueError(f"boxes_px[{i}]: box {boxes[i].tolist()} lies outside the {w}x{h} image")
    r = _ranges_of_clipped(c, image_shape, p.size_px)
    n = _counts(boxes, c, r, p)
    if counts is not None:
        req = np.broadcast_to(np.asarray(counts, dtype=np.int64), n.shape)
        if (req < 0).any():
            raise ValueError(f"counts: expected non-negative patch counts, got {req.tolist()}")
        n = np.where(n > 0, req, 0)
    idx = np.repeat(np.arange(len(boxes)), n)
    # uniform integer corners = uniform centres in the box shrunk by s/2 (B12)
    lo, span = r[idx, :2], r[idx, 2:] - r[idx, :2] + 1
    corners = lo + np.floor(rng.random((len(idx), 2)) * span).astype(np.int64)
    return Patches(corners, idx.astype(np.int64), p.size_px)


def grid_patches(region_px: np.ndarray, image_shape: tuple[int, ...], size_px: int = 12,
                 stride_px: int = 4) -> Patches:
    """Patches on a regular grid (step ``stride_px``) covering a region, clipped to the image (dense B16 maps).

    Parameters
    ----------
    region_px : (4,) float
        ``(u_min, v_min, u_max, v_max)`` px.

    Returns
    -------
    Patches
        Row-major grid (``box_index`` 0); empty when no patch fits in the visible region.
    """
    if isinstance(stride_px, bool) or not isinstance(stride_px, int | np.integer) or stride_px < 1:
        raise ValueError(f"stride_px: expected an integer >= 1, got {stride_px!r}")
    box = as_boxes(region_px, "region_px")
    r = _corner_ranges(box, image_shape, size_px)[0]
    xs = np.arange(r[0], r[2] + 1, stride_px, dtype=np.int64)
    ys = np.arange(r[1], r[3] + 1, stride_px, dtype=np.int64)
    gx, gy = np.meshgrid(xs, ys)
    corners = np.column_stack([gx.ravel(), gy.ravel()])
    return Patches(corners, np.zeros(len(corners), np.int64), size_px)


# --------------------------------------------------------------------------------------------------
# B13: features through integral images (X3)
@dataclass(frozen=True, slots=True, eq=False)
class PatchIntegrals:
    """Integral images of one image region, ready for O(1) rectangle sums (ALGORITHMS.md X3).

    Attributes
    ----------
    origin_px : (int, int)
        ``(x, y)`` of the region's top-left pixel in the image.
    table : (h+1, w+1, 3+K) float64
        ``II`` of R, G, B (0–255) and of the per-bin gradient magnitudes ``ψ_0 .. ψ_{K−1}``.
    n_bins : int
    """

    origin_px: tuple[int, int]
    table: np.ndarray
    n_bins: int

    @property
    def shape(self) -> tuple[int, int]:
        """``(h, w)`` of the region."""
        return self.table.shape[0] - 1, self.table.shape[1] - 1

    def rect_sums(self, x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray) -> np.ndarray:
        """Channel sums ``(..., 3+K)`` over ``[x0, x1) × [y0, y1)`` (image pixels, broadcast integer arrays)."""
        ox, oy = self.origin_px
        x0, x1, y0, y1 = x0 - ox, x1 - ox, y0 - oy, y1 - oy
        t = self.table
        return t[y1, x1] - t[y0, x1] - t[y1, x0] + t[y0, x0]


def orientation_energy(grey: np.ndarray, params: FeatureParams | None = None) -> np.ndarray:
    """``ψ_k(x, y)`` of B13: the gradient magnitude in its orientation bin, 0 elsewhere and below ``τ_G``.

    Parameters
    ----------
    grey : (h, w) float32
        Grey levels 0–255. Borders are reflected (``cv2.BORDER_REFLECT_101``).

    Returns
    -------
    (h, w, K) float32
        Magnitude in grey levels per pixel (Sobel 3×3 / 8).
    """
    p = params or FeatureParams()
    g = np.asarray(grey, dtype=np.float32)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    out = np.zeros((*g.shape, p.n_bins), np.float32)
    _bin_gradients(gx, gy, p, out.reshape(-1, p.n_bins))
    return out


def _bin_gradients(gx: np.ndarray, gy: np.ndarray, p: FeatureParams, out: np.ndarray) -> None:
    """Write ``ψ_k`` of gradients ``gx, gy (h, w)`` into the bin columns ``out (h w, K)`` (zeros, pixel-major).

    Only the pixels above ``τ_G`` get an orientation (a tenth of them in camera images: ``arctan2`` is most of
    the cost); each is computed as over the whole array, element by element, so the bits are those of binning
    every pixel."""
    mag = np.sqrt(gx * gx + gy * gy)  # NumPy, not cv2.magnitude: the same bits whatever the threading
    strong = np.flatnonzero(mag > p.grad_threshold)  # weaker gradients count in no bin
    # unsigned orientation θ = atan2(Gy, Gx) mod π; bin k centred at kπ/K, width π/K, wrap-around (B13, Levi-Weiss)
    k = p.n_bins
    theta = np.arctan2(gy.reshape(-1)[strong], gx.reshape(-1)[strong])
    b = np.floor(theta * (k / np.pi) + 0.5).astype(np.int64) % k
    out[strong, b] = mag.reshape(-1)[strong]


def integral_channels(image_bgr: np.ndarray, params: FeatureParams | None = None,
                      region_px: tuple[int, int, int, int] | np.ndarray | None = None) -> PatchIntegrals:
    """Sobel gradients, orientation bins and integral images of one region of an image (B13 + X3).

    Parameters
    ----------
    image_bgr : (H, W, 3) uint8
    params : FeatureParams, optional
    region_px : (4,) int, optional
        ``(x0, y0, x1, y1)``, the pixels ``[x0, x1) × [y0, y1)`` to cover (clipped to the image); the whole
        image by default. Gradients are computed with a one-pixel margin, so they equal the whole-image ones.

    Returns
    -------
    PatchIntegrals
    """
    p = params or FeatureParams()
    img = validate_image(image_bgr, "image_bgr")
    h, w = img.shape[:2]
    if region_px is None:
        x0, y0, x1, y1 = 0, 0, w, h
    else:
        x0, y0, x1, y1 = (int(v) for v in np.asarray(region_px).reshape(4))
        x0, x1 = max(x0, 0), min(x1, w)
        y0, y1 = max(y0, 0), min(y1, h)
        if x1 <= x0 or y1 <= y0:
            raise ValueError(f"region_px: {[x0, y0, x1, y1]} does not overlap the {w}x{h} image")
    mx0, my0, mx1, my1 = max(x0 - 1, 0), max(y0 - 1, 0), min(x1 + 1, w), min(y1 + 1, h)
    crop = img[my0:my1, mx0:mx1]
    grey = cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY).astype(np.float32)
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    inner = (slice(y0 - my0, y1 - my0), slice(x0 - mx0, x1 - mx0))
    # R, G, B then ψ (orientation_energy's, of the region's pixels only) in one buffer
    stack = np.zeros((y1 - y0, x1 - x0, 3 + p.n_bins), np.float32)
    stack[..., :3] = crop[inner][..., ::-1]
    flat = stack.reshape(-1, 3 + p.n_bins)
    _bin_gradients(np.ascontiguousarray(gx[inner]), np.ascontiguousarray(gy[inner]), p, flat[:, 3:])
    table = cv2.integral(stack, sdepth=cv2.CV_64F)
    if table.ndim == 2:  # cv2 drops a channel axis of length 1; keep it
        table = table[..., None]
    return PatchIntegrals((x0, y0), table, p.n_bins)


def _check_corners(integrals: PatchIntegrals, corners_px: np.ndarray, s: int) -> np.ndarray:
    c = np.asarray(corners_px)
    if c.ndim != 2 or c.shape[1] != 2 or not np.issubdtype(c.dtype, np.integer):
        raise ValueError(f"corners_px: expected (n, 2) integer top-left pixels, got {c.dtype} {c.shape}")
    if len(c):
        ox, oy = integrals.origin_px
        h, w = integrals.shape
        if c[:, 0].min() < ox or c[:, 1].min() < oy or c[:, 0].max() + s > ox + w or c[:, 1].max() + s > oy + h:
            raise ValueError(f"corners_px: patches of {s} px leave the integral region x {ox}..{ox + w}, "
                             f"y {oy}..{oy + h}")
    return c.astype(np.int64)


def _cell_sums(integrals: PatchIntegrals, corners: np.ndarray, s: int) -> np.ndarray:
    """Channel sums ``(n, 4, 3+K)`` of the 2×2 cells (top-left, top-right, bottom-left, bottom-right)."""
    # the table at the patch's 3 x 3 grid of cell corners (one gather of 9 points instead of 16), then each cell's
    # II(x1, y1) - II(x1, y0) - II(x0, y1) + II(x0, y0) as rect_sums computes it
    half = s // 2
    ox, oy = integrals.origin_px
    t = integrals.table
    w1 = t.shape[1]
    step = np.array([0, half, 2 * half])
    at = ((corners[:, 1:] - oy)[:, :, None] + step[None, :, None]) * w1 + (corners[:, :1] - ox)[:, :, None] + step
    g = t.reshape(-1, t.shape[2])[at]  # (n, 3 rows y, 3 columns x, C)
    cells = g[:, 1:, 1:] - g[:, :-1, 1:] - g[:, 1:, :-1] + g[:, :-1, :-1]  # (n, 2, 2, C): TL, TR / BL, BR
    return cells.reshape(len(corners), 4, t.shape[2])


def patch_eoh(integrals: PatchIntegrals, corners_px: np.ndarray, size_px: int) -> np.ndarray:
    """Edge-orientation energies ``E_k`` ``(n, K)`` of whole patches (B13), four look-ups per bin."""
    c = _check_corners(integrals, corners_px, size_px)
    x0, y0 = c[:, 0], c[:, 1]
    return integrals.rect_sums(x0, y0, x0 + size_px, y0 + size_px)[:, 3:]


@functools.cache
def _pairs(k: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(k, 1)``, once per ``k`` (read-only)."""
    a, b = np.triu_indices(k, 1)
    a.setflags(write=False)
    b.setflags(write=False)
    return a, b


def patch_features(integrals: PatchIntegrals, corners_px: np.ndarray, size_px: int,
                   params: FeatureParams | None = None) -> np.ndarray:
    """B13 feature vectors of patches, vectorised over patches.

    Parameters
    ----------
    integrals : PatchIntegrals
        From :func:`integral_channels` on a region containing every patch.
    corners_px : (n, 2) int
        Top-left pixels.
    size_px : int
        Patch side ``s`` (even).

    Returns
    -------
    (n, d) float64
        ``[colour of cells TL, TR, BL, BR (12: I, r, g each, or R, G, B in [0, 1] with colour="rgb")`` |
        dominant orientations ``(E_k+ε)/(ΣE+Kε)`` (K) | ``log((E_a+ε)/(E_b+ε))`` for ``a < b`` (K(K−1)/2) |
        symmetry (1)]``; d = 23 for K = 4.
    """
    p = params or FeatureParams()
    if p.n_bins != integrals.n_bins:
        raise ValueError(f"params.n_bins: {p.n_bins} differs from the integral images' {integrals.n_bins}")
    if size_px % 2:
        raise ValueError(f"size_px: expected an even patch side, got {size_px}")
    c = _check_corners(integrals, corners_px, size_px)
    k, n = p.n_bins, len(c)
    cells = _cell_sums(integrals, c, size_px)  # (n, 4, 3+K)
    area = (size_px // 2) ** 2
    colour = cells[:, :, :3] / (255.0 * area)  # (n, 4, 3) mean R, G, B in [0, 1]
    if p.colour == "chromaticity":
        kappa = p.chroma_eps / 255.0
        total = colour.sum(axis=2, keepdims=True)
        colour = np.concatenate([total / 3.0, (colour[:, :, :2] + kappa) / (total + 3.0 * kappa)], axis=2)
    colour = colour.reshape(n, 12)
    eoh = cells[:, :, 3:]
    e = eoh.sum(axis=1)  # (n, K) whole patch
    eps = p.eps_scale * size_px**2
    dominant = (e + eps) / (e.sum(axis=1, keepdims=True) + k * eps)
    a, b = _pairs(k)
    ratios = np.log((e[:, a] + eps) / (e[:, b] + eps))
    # left/right symmetry against the mirrored bin k' = (K − k) mod K (θ → π − θ), B13
    left = eoh[:, 0] + eoh[:, 2]
    right = (eoh[:, 1] + eoh[:, 3])[:, (k - np.arange(k)) % k]
    sym = np.abs(left - right).sum(axis=1) / ((left + right).sum(axis=1) + eps)
    return np.concatenate([colour, dominant, ratios, sym[:, None]], axis=1)


def patch_fraction(mask: np.ndarray, patches: Patches) -> np.ndarray:
    """Fraction ``(n,)`` of each patch's pixels that are set in a mask (e.g. a foreground mask), O(1) per patch.

    Parameters
    ----------
    mask : (H, W) bool or uint8
        Non-zero = set.
    patches : Patches
        Lying inside the mask's image.
    """
    m = np.asarray(mask)
    if m.ndim != 2 or not (m.dtype == np.bool_ or np.issubdtype(m.dtype, np.integer)):
        raise ValueError(f"mask: expected an (H, W) bool or integer mask, got {m.dtype} {m.shape}")
    if len(patches) == 0:
        return np.zeros(0)
    s = patches.size_px
    c = patches.corners_px
    h, w = m.shape
    if c.min() < 0 or c[:, 0].max() + s > w or c[:, 1].max() + s > h:
        raise ValueError(f"patches: they leave the {w}x{h} mask")
    ii = cv2.integral((m != 0).astype(np.uint8), sdepth=cv2.CV_32S)
    x0, y0 = c[:, 0], c[:, 1]
    x1, y1 = x0 + s, y0 + s
    return (ii[y1, x1] - ii[y0, x1] - ii[y1, x0] + ii[y0, x0]) / float(s * s)


def patch_region(corners_px: np.ndarray, size_px: int) -> tuple[int, int, int, int] | None:
    """Bounding pixels ``(x0, y0, x1, y1)`` of a set of patches (None when empty)."""
    c = np.asarray(corners_px).reshape(-1, 2)
    if len(c) == 0:
        return None
    x0, y0 = c.min(axis=0)
    x1, y1 = c.max(axis=0) + size_px
    return int(x0), int(y0), int(x1), int(y1)


def extract_features(image_bgr: np.ndarray, patches: Patches, params: FeatureParams | None = None) -> np.ndarray:
    """B13 features ``(n, d)`` of patches of one image, with the integral images built over their bounding region.

    Raises
    ------
    ValueError
        Wrong image type or shape, or patches outside the image.
    """
    p = params or FeatureParams()
    img = validate_image(image_bgr, "image_bgr")
    region = _patch_region_in(img, patches)
    if region is None:
        return np.zeros((0, p.n_features))
    return patch_features(integral_channels(img, p, region), patches.corners_px, patches.size_px, p)


def _patch_region_in(img: np.ndarray, patches: Patches) -> tuple[int, int, int, int] | None:
    """:func:`patch_region`, checked to lie in the image."""
    region = patch_region(patches.corners_px, patches.size_px)
    if region is None:
        return None
    h, w = img.shape[:2]
    if region[0] < 0 or region[1] < 0 or region[2] > w or region[3] > h:
        raise ValueError(f"patches: they span x {region[0]}..{region[2]}, y {region[1]}..{region[3]}, outside the "
                         f"{w}x{h} image")
    return region


def _exact_sums(params: FeatureParams, image_shape: tuple[int, ...]) -> bool:
    """Whether every rectangle sum of :func:`integral_channels`' table is exact in float64, so the same whatever
    region the table covers: R, G, B are integers; ``ψ`` is 0 or a float32 above ``τ_G`` (a multiple of its
    ulp, ``2^(⌊log2 τ_G⌋ − 23)``), at most 181 (Sobel / 8 of 0-255: 127.5 √2) per pixel; the table's sums of
    ``H W`` pixels stay within the 53 bits of float64 when ``log2(181 H W) <= 30 + ⌊log2 τ_G⌋``."""
    tau = params.grad_threshold
    if not tau > 0:
        return False
    h, w = _image_hw(image_shape)
    return math.log2(181.0 * h * w) <= 30 + math.floor(math.log2(tau))


class IntegralCache:
    """:func:`extract_features` for several sets of patches of one image, reusing the integral images of a region
    already built for patches inside it.

    A fused tracker scores one camera image several times in a step (score maps, identity checks, learning): the
    gradients and integral images of a region (:func:`integral_channels`) cost more than the features of its
    patches. The features are the same numbers as :func:`extract_features`' (every rectangle sum of the table is
    exact, whatever region it covers, for ``grad_threshold`` of a few grey levels or more; with a smaller one,
    nothing is reused).

    Parameters
    ----------
    image_bgr : (H, W, 3) uint8
        Kept (by reference: it must not change while the cache is used; :meth:`AppearanceBank.cache_image
        <fusiontrack.vision.appearance.AppearanceBank.cache_image>` caches read-only images only).
    params : FeatureParams, optional
    max_regions : int
        Regions kept (the oldest is dropped).
    """

    def __init__(self, image_bgr: np.ndarray, params: FeatureParams | None = None, max_regions: int = 4) -> None:
        self.image = validate_image(image_bgr, "image_bgr")
        self.params = params or FeatureParams()
        self.max_regions = int(max_regions)
        self._reuse = _exact_sums(self.params, self.image.shape)
        self._tables: list[tuple[tuple[int, int, int, int], PatchIntegrals]] = []
        self.built = 0  # regions whose integral images were built
        self.reused = 0  # feature extractions that reused one

    def features(self, patches: Patches) -> np.ndarray:
        """B13 features ``(n, d)`` of ``patches`` (as :func:`extract_features` on this image)."""
        p = self.params
        region = _patch_region_in(self.image, patches)
        if region is None:
            return np.zeros((0, p.n_features))
        table = None
        if self._reuse:
            x0, y0, x1, y1 = region
            table = next((t for r, t in self._tables if r[0] <= x0 and r[1] <= y0 and x1 <= r[2] and y1 <= r[3]),
                         None)
        if table is None:
            table = integral_channels(self.image, p, region)
            self.built += 1
            if self._reuse and self.max_regions > 0:
                self._tables.append((region, table))
                del self._tables[:-self.max_regions]
        else:
            self.reused += 1
        return patch_features(table, patches.corners_px, patches.size_px, p)
