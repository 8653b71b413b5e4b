"""Shadow and highlight removal against a background colour (seed 000, ALGORITHMS.md A3).

Horprasert et al. 1999, simplified (A3): for a pixel colour ``x`` and its background colour ``E``
(RGB or BGR, the order does not matter), the *brightness distortion* is ``a = x·E / (E·E + ε)`` and the
relative *chromaticity distortion* is ``CD = ||x − aE|| / (a||E|| + ε)``. A pixel whose colour is the
background's scaled down (``τ_s1 ≤ a < τ_s2``, small ``CD``) is a shadow; scaled up
(``τ_h1 < a ≤ τ_h2``) a highlight; anything else is the object. A uniform global brightness change
inside those bands is therefore labelled shadow/highlight at once, which is half of how
:class:`~fusiontrack.vision.foreground.ForegroundModel` survives an illumination jump.

Everything here is a pure function over a batch of pixels ``(..., 3)``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["PixelLabel", "ShadowParams", "brightness_chromaticity", "shadow_highlight_labels"]

_EPS = 1e-6  # A3's ε


class PixelLabel(enum.IntEnum):
    """What a pixel of a foreground label image is (seed 000, Figure 2: object, shadow, highlight)."""

    BACKGROUND = 0
    FOREGROUND = 1  # "object": the only label that goes on to blob extraction (A4)
    SHADOW = 2
    HIGHLIGHT = 3


@dataclass(frozen=True, slots=True)
class ShadowParams:
    """Thresholds of A3 [RECON defaults].

    Attributes
    ----------
    tau_cd : float
        Largest relative chromaticity distortion of a shadow or highlight (0.10).
    shadow_min, shadow_max : float
        Shadow band of the brightness distortion, ``shadow_min <= a < shadow_max`` (0.40, 0.95).
    highlight_min, highlight_max : float
        Highlight band, ``highlight_min < a <= highlight_max`` (1.05, 1.60).
    dark_norm : float
        Background colours with ``||E||`` below this (grey levels) are never shadow (A3 edge case: 20).
    saturated : int
        A pixel with any channel at or above this is never a highlight (A3 edge case: 255).
    """

    tau_cd: float = 0.10
    shadow_min: float = 0.40
    shadow_max: float = 0.95
    highlight_min: float = 1.05
    highlight_max: float = 1.60
    dark_norm: float = 20.0
    saturated: int = 255

    def __post_init__(self) -> None:
        if not (np.isfinite(self.tau_cd) and self.tau_cd >= 0):
            raise ValueError(f"ShadowParams.tau_cd: expected a finite value >= 0, got {self.tau_cd!r}")
        if not 0 <= self.shadow_min < self.shadow_max <= 1:
            raise ValueError("ShadowParams.shadow_min, shadow_max: expected 0 <= shadow_min < shadow_max <= 1, "
                             f"got {self.shadow_min!r}, {self.shadow_max!r}")
        if not 1 <= self.highlight_min < self.highlight_max:
            raise ValueError("ShadowParams.highlight_min, highlight_max: expected 1 <= highlight_min < "
                             f"highlight_max, got {self.highlight_min!r}, {self.highlight_max!r}")
        if not (np.isfinite(self.dark_norm) and self.dark_norm >= 0):
            raise ValueError(f"ShadowParams.dark_norm: expected a finite value >= 0, got {self.dark_norm!r}")
        if not 0 < self.saturated <= 255:
            raise ValueError(f"ShadowParams.saturated: expected 1..255, got {self.saturated!r}")


def _pixels(value: Any, name: str) -> np.ndarray:
    a = np.asarray(value)
    if a.ndim < 1 or a.shape[-1] != 3:
        raise ValueError(f"{name}: expected colours of shape (..., 3), got {a.shape}")
    return a


def brightness_chromaticity(pixels: Any, background: Any) -> tuple[np.ndarray, np.ndarray]:
    """Brightness distortion ``a`` and relative chromaticity distortion ``CD`` of A3.

    Parameters
    ----------
    pixels : (..., 3) array
        Colours ``x`` of the current frame (grey levels, any channel order).
    background : (..., 3) array
        Background colours ``E`` (the same channel order), broadcastable against ``pixels``.

    Returns
    -------
    a : (...) float32
        ``x·E / (E·E + ε)``: 1 for the background colour itself, 0.6 for a 40 % darker shadow.
    cd : (...) float32
        ``||x − aE|| / (a||E|| + ε)``, the colour change that brightness cannot explain, relative to
        the brightness.
    """
    a, cd, _ = _distortions(_pixels(pixels, "pixels"), _pixels(background, "background"))
    return a, cd


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-pixel dot product over the last axis (3); per channel, several times faster than einsum."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _distortions(pixels: np.ndarray, background: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``a``, ``CD`` and ``||E||`` (all float32)."""
    x = pixels.astype(np.float32, copy=False)
    e = background.astype(np.float32, copy=False)
    xe, ee, xx = _dot(x, e), _dot(e, e), _dot(x, x)
    a = xe / (ee + np.float32(_EPS))
    # ||x − aE||² = x·x − 2a x·E + a² E·E = x·x − a x·E (with a = x·E / E·E): no (..., 3) temporary needed
    resid = np.sqrt(np.maximum(xx - a * xe, 0.0))
    e_norm = np.sqrt(ee)
    cd = resid / (a * e_norm + np.float32(_EPS))
    return a, cd, e_norm


def shadow_highlight_labels(pixels: Any, background: Any, params: ShadowParams | None = None) -> np.ndarray:
    """Label foreground pixels as object, shadow or highlight against their background (A3).

    Parameters
    ----------
    pixels : (..., 3) uint8 or float
        Colours of the pixels in the foreground mask.
    background : (..., 3) uint8 or float
        Background colour ``E`` of the same pixels (e.g. the MoG background image).
    params : ShadowParams, optional
        Thresholds (A3 defaults).

    Returns
    -------
    (...) uint8
        :class:`PixelLabel` values ``FOREGROUND`` (object), ``SHADOW`` or ``HIGHLIGHT``.

    Examples
    --------
    With ``E = (120, 120, 120)`` (A3's known answers): ``0.6 E`` is a shadow, ``1.3 E`` a highlight,
    ``(170, 70, 120)`` an object (``CD ≈ 0.34``) and ``0.3 E`` an object (too dark for a shadow).
    """
    p = ShadowParams() if params is None else params
    x = _pixels(pixels, "pixels")
    e = _pixels(background, "background")
    a, cd, e_norm = _distortions(x, e)
    flat = cd <= p.tau_cd
    shadow = flat & (a >= p.shadow_min) & (a < p.shadow_max) & (e_norm >= p.dark_norm)
    saturated = (x[..., 0] >= p.saturated) | (x[..., 1] >= p.saturated) | (x[..., 2] >= p.saturated)
    highlight = flat & (a > p.highlight_min) & (a <= p.highlight_max) & ~saturated
    labels = np.full(a.shape, PixelLabel.FOREGROUND, np.uint8)
    labels[shadow] = PixelLabel.SHADOW
    labels[highlight] = PixelLabel.HIGHLIGHT
    return labels
