"""Foreground of one static camera: MoG (A1) + stopped-object mask (A2) + shadow/highlight removal (A3).

Seed 000's blob extraction (ALGORITHMS.md A0, A1-A3), built on OpenCV's MOG2:

``M_mog`` = MOG2's foreground (no shadow detection of its own); ``M = M_mog ∪ M_aug`` with the
augmented mask of :class:`~fusiontrack.vision.stopped.AugmentedMask`, minus the pixels A2 knows to be
uncovered background (ghosts); the pixels of ``M`` are then labelled object / shadow / highlight
against the background colour (A3, :func:`~fusiontrack.vision.shadows.shadow_highlight_labels`). Only
object pixels form :attr:`ForegroundResult.mask`, the input of blob extraction (A4).

A1's parameters mapped onto MOG2 (:class:`ForegroundParams`): ``K = 5`` mixtures, ``α = 1/history =
0.005`` (after a start-up in which MOG2 learns at ``1/(2n)``), ``T = 0.7`` (MOG2's ``backgroundRatio``;
its own default is 0.9), ``λ_m = 2.5``: MOG2 compares the squared colour distance with
``varThreshold × σ²`` for one isotropic ``σ²``, so A1's ``Σ_c (x_c − μ_c)² < λ_m² Σ_c σ²`` is
``varThreshold = 3 λ_m² = 18.75``. MOG2 learns each pixel's variance between ``var_min`` and ``var_max``
(its defaults 4 and 75 grey levels²) instead of A1's fixed floor ``σ_min = 15``, which belongs to
OpenCV's older, coarser MOG. A long-static background has weight 1 in MOG2 (0.952 in A1's model), a new
component starts at weight ``α`` and every weight loses ``α c_T`` (``c_T = 0.05``) per frame, so the
conventional mask absorbs a stopped object after ~73 frames instead of A1's 62 (the tests derive the
number from MOG2's weight recursion and measure 72). The first frame is the model, hence all background.

Illumination (A1 edge case): when more than ``illumination_fraction`` (60 %) of the frame is MoG
foreground, MOG2 learns at ``illumination_boost × α`` (10α) for ``illumination_frames`` (30) frames;
``M_mog`` is clean again about 8 frames after the jump. Two additions [RECON] keep the object mask clean
and people in it meanwhile:

* A2's remembered colours are multiplied by the measured global gain (median brightness distortion of
  the MoG foreground against them), so A2 keeps working through the jump: a person in the scene still
  triggers a stop where MoG, relearning at 10α, absorbs them within ~8 frames.
* While relearning, the frame's global gain is the median brightness distortion (A3's ``a``) of the
  foreground against MOG2's background, and a pixel whose colour is the background's times that gain
  (``|a/gain − 1| <= 0.15`` and ``CD <= 0.15``) is background. A jump of 0.35× (lights off) to 1.8×
  leaves the object mask clean from the frame it happens; people stay foreground where they differ from
  the background by more than the gain. (A3 alone already absorbs gains inside its shadow band
  0.40-0.95 and highlight band 1.05-1.60.) A gain that saturates much of the frame (2.5×) is not
  normalised: the object mask is dirty until MOG2 has relearned, and A2 may keep ~3 % of the frame.

Bad input: a frame of the wrong type or shape raises ``ValueError``; an all-black frame (mean below
``black_level``, a camera dropout) does not touch the model and gives an empty, ``valid=False`` result
(logged once as a warning).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from ..types import Image
from .shadows import PixelLabel, ShadowParams, brightness_chromaticity, shadow_highlight_labels
from .stopped import AugmentedMask, AugmentedMaskParams

__all__ = ["ForegroundModel", "ForegroundParams", "ForegroundResult", "PixelLabel"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class ForegroundParams:
    """Every parameter of :class:`ForegroundModel` (ALGORITHMS.md A1 defaults, mapped onto MOG2).

    Attributes
    ----------
    history : int
        MOG2 history; the learning rate is ``α = 1/history`` (A1: 200, α = 0.005).
    n_mixtures : int
        Gaussians per pixel, K (A1: 5; 3 is a little faster).
    background_ratio : float
        A1's ``T`` (0.7).
    lambda_m : float
        Match threshold in standard deviations (2.5); MOG2's ``varThreshold = 3 λ_m²``.
    var_threshold_gen : float
        MOG2's threshold for updating a component rather than creating one (its default 9).
    var_init, var_min, var_max : float
        MOG2's initial, smallest and largest variance in grey levels² (its defaults 15, 4, 75).
    illumination_fraction : float
        A MoG foreground fraction above this is an illumination change (A1: 0.6).
    illumination_boost : float
        Learning-rate factor while relearning after it (A1: 10).
    illumination_frames : int
        Frames of fast relearning (A1: 30).
    illumination_tolerance : float
        While relearning, a foreground pixel whose colour is the background's times the frame's global gain
        (median brightness distortion of the foreground) to within this relative tolerance, and whose
        chromaticity distortion is below it, is background: the jump is normalised away at once [RECON].
        0 = off (needs A3).
    black_level : float
        A frame whose mean grey level is below this is a dropout and is skipped (3).
    stopped_warmup : int
        A2 starts no stop during the first this many frames (100) [RECON]: whatever the first frame shows
        is background to A1 and A2 alike, so a person in it who walks away uncovers a stable new colour,
        which A2 would keep as a "stopped object" for good; meanwhile MOG2, learning at ``1/(2n)``, and
        A2's memory (which follows MOG2's background) relearn the uncovered scene.
    stopped : AugmentedMaskParams or None
        A2's parameters; ``None`` switches the augmented mask off (plain MoG).
    shadows : ShadowParams or None
        A3's thresholds; ``None`` switches shadow/highlight removal off.
    background_every : int
        MOG2's background image (A3's ``E``) is recomputed every this many frames (4: it changes at rate α,
        and it costs as much as half a MOG2 update), and at every frame while relearning.
    """

    history: int = 200
    n_mixtures: int = 5
    background_ratio: float = 0.7
    lambda_m: float = 2.5
    var_threshold_gen: float = 9.0
    var_init: float = 15.0
    var_min: float = 4.0
    var_max: float = 75.0
    illumination_fraction: float = 0.6
    illumination_boost: float = 10.0
    illumination_frames: int = 30
    illumination_tolerance: float = 0.15
    black_level: float = 3.0
    stopped_warmup: int = 100
    stopped: AugmentedMaskParams | None = field(default_factory=AugmentedMaskParams)
    shadows: ShadowParams | None = field(default_factory=ShadowParams)
    background_every: int = 4

    def __post_init__(self) -> None:
        def integer(name: str, lo: int) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ValueError(f"ForegroundParams.{name}: expected an integer >= {lo}, got {v!r}")

        integer("history", 1)
        integer("illumination_frames", 0)
        integer("background_every", 1)
        integer("stopped_warmup", 0)
        if not (isinstance(self.n_mixtures, int) and 1 <= self.n_mixtures <= 8):
            raise ValueError(f"ForegroundParams.n_mixtures: expected an integer in 1..8, got {self.n_mixtures!r}")
        if not 0 < self.background_ratio <= 1:
            raise ValueError(f"ForegroundParams.background_ratio: expected a value in (0, 1], got "
                             f"{self.background_ratio!r}")
        for name in ("lambda_m", "var_threshold_gen", "var_init", "var_min", "var_max", "illumination_boost"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"ForegroundParams.{name}: expected a finite value > 0, got {v!r}")
        if not self.var_min <= self.var_init <= self.var_max:
            raise ValueError(f"ForegroundParams.var_min, var_init, var_max: expected var_min <= var_init <= var_max, "
                             f"got {self.var_min!r}, {self.var_init!r}, {self.var_max!r}")
        if not 0 < self.illumination_fraction <= 1:
            raise ValueError(f"ForegroundParams.illumination_fraction: expected a value in (0, 1], got "
                             f"{self.illumination_fraction!r}")
        if not 0 <= self.illumination_tolerance < 1:
            raise ValueError(f"ForegroundParams.illumination_tolerance: expected a value in [0, 1), got "
                             f"{self.illumination_tolerance!r}")
        if not (np.isfinite(self.black_level) and 0 <= self.black_level < 255):
            raise ValueError(f"ForegroundParams.black_level: expected a value in [0, 255), got {self.black_level!r}")

    @property
    def alpha(self) -> float:
        """A1's learning rate ``1/history``."""
        return 1.0 / self.history


@dataclass(frozen=True, slots=True, eq=False)
class ForegroundResult:
    """The foreground of one frame (arrays read-only).

    Attributes
    ----------
    labels : (H, W) uint8
        :class:`PixelLabel` per pixel: background, foreground (object), shadow or highlight.
    mask : (H, W) bool
        Object pixels, ``labels == FOREGROUND``: the input of blob extraction (A4).
    mog_mask : (H, W) bool
        The conventional MoG mask ``M_mog`` (A1).
    augmented_mask : (H, W) bool
        Seed 000's stopped-object mask ``M_aug`` (A2); all False when A2 is off.
    foreground_fraction : float
        Fraction of the frame in ``M_mog`` (what the illumination test looks at).
    relearning : bool
        MoG learns fast after an illumination change in this frame.
    valid : bool
        False for a skipped (black) frame; every mask is then empty.
    """

    labels: np.ndarray
    mask: np.ndarray
    mog_mask: np.ndarray
    augmented_mask: np.ndarray
    foreground_fraction: float
    relearning: bool = False
    valid: bool = True

    def __post_init__(self) -> None:
        for name in ("labels", "mask", "mog_mask", "augmented_mask"):
            getattr(self, name).setflags(write=False)


def _as_bgr(frame: Any) -> np.ndarray:
    """Validate one frame at the edge: ``(H, W, 3)`` or ``(H, W)`` uint8 array, or an :class:`Image`."""
    if isinstance(frame, Image):
        if frame.encoding == "mono16":
            raise ValueError(f"frame: expected a colour or mono8 image, got encoding {frame.encoding!r} "
                             "(16-bit label or intensity image)")
        frame = frame.bgr()
    if not isinstance(frame, np.ndarray):
        raise ValueError(f"frame: expected a numpy array or an Image, got {type(frame).__name__}")
    if frame.dtype != np.uint8:
        raise ValueError(f"frame: expected uint8 grey levels, got dtype {frame.dtype}")
    if frame.ndim == 2:
        frame = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    elif frame.ndim != 3 or frame.shape[2] != 3:
        raise ValueError(f"frame: expected an (H, W, 3) BGR or (H, W) grey image, got shape {frame.shape}")
    if frame.shape[0] == 0 or frame.shape[1] == 0:
        raise ValueError(f"frame: empty image of shape {frame.shape}")
    return np.ascontiguousarray(frame)


class ForegroundModel:
    """Per-pixel background model of one static camera; :meth:`apply` once per frame, in time order.

    Parameters
    ----------
    params : ForegroundParams, optional
        A1-A3 parameters (defaults from ALGORITHMS.md).

    Examples
    --------
    >>> model = ForegroundModel()
    >>> for image in VideoReader("video.avi"):          # doctest: +SKIP
    ...     fg = model.apply(image)
    ...     blobs = extract_blobs(fg.mask)
    """

    def __init__(self, params: ForegroundParams | None = None) -> None:
        p = ForegroundParams() if params is None else params
        if not isinstance(p, ForegroundParams):
            raise ValueError(f"params: expected ForegroundParams or None, got {type(p).__name__}")
        self.params = p
        mog = cv2.createBackgroundSubtractorMOG2(history=p.history, varThreshold=3.0 * p.lambda_m**2,
                                                 detectShadows=False)
        mog.setNMixtures(p.n_mixtures)
        mog.setBackgroundRatio(p.background_ratio)
        mog.setVarThresholdGen(p.var_threshold_gen)
        mog.setVarInit(p.var_init)
        mog.setVarMin(p.var_min)
        mog.setVarMax(p.var_max)
        self._mog = mog
        self._shape: tuple[int, int] | None = None
        self._aug: AugmentedMask | None = None
        self._background: np.ndarray | None = None
        self._background_frame = 0  # the frame count when it was taken
        self._n_frames = 0  # frames the model has learned from (black frames excluded)
        self._boost_left = 0
        self._warned_black = False
        self.n_skipped = 0
        self.n_illumination_events = 0

    # -- state --------------------------------------------------------------------------------------

    @property
    def n_frames(self) -> int:
        """Frames learned from so far (skipped black frames excluded)."""
        return self._n_frames

    @property
    def shape(self) -> tuple[int, int] | None:
        """``(H, W)`` fixed by the first valid frame, ``None`` before it."""
        return self._shape

    @property
    def mog(self) -> cv2.BackgroundSubtractorMOG2:
        """The underlying OpenCV MOG2 (e.g. to time it alone)."""
        return self._mog

    @property
    def augmented(self) -> AugmentedMask | None:
        """A2's state (``None`` before the first frame or when A2 is off)."""
        return self._aug

    def background_image(self) -> np.ndarray:
        """MOG2's background image ``(H, W, 3)`` uint8 (the mean of its background components)."""
        if self._shape is None:
            raise ValueError("background_image: no frame has been applied yet")
        return self._mog.getBackgroundImage()

    def recent_background_image(self) -> np.ndarray:
        """MOG2's background image as A3 last used it: refreshed every ``background_every`` frames and in every
        frame while relearning (read-only; one refresh serves A3 and any caller that can use the same age)."""
        if self._shape is None:
            raise ValueError("recent_background_image: no frame has been applied yet")
        if self._background is None or self._boost_left > 0 or self._n_frames - self._background_frame >= \
                self.params.background_every:
            self._refresh_background()
        return self._background

    def _refresh_background(self) -> None:
        self._background = self._mog.getBackgroundImage()
        self._background.setflags(write=False)
        self._background_frame = self._n_frames

    # -- per frame ----------------------------------------------------------------------------------

    def apply(self, frame: np.ndarray | Image) -> ForegroundResult:
        """Update the model with one frame and return its foreground.

        Parameters
        ----------
        frame : (H, W, 3) uint8 BGR, (H, W) uint8 grey, or :class:`~fusiontrack.types.Image`
            Every frame must have the size of the first.

        Returns
        -------
        ForegroundResult

        Raises
        ------
        ValueError
            ``frame`` is not a uint8 image, is empty, or changes size.
        """
        p = self.params
        bgr = _as_bgr(frame)
        shape = (int(bgr.shape[0]), int(bgr.shape[1]))
        if self._shape is not None and shape != self._shape:
            raise ValueError(f"frame: size {shape[1]}x{shape[0]} differs from the first frame's "
                             f"{self._shape[1]}x{self._shape[0]}")
        if max(cv2.mean(bgr)[:3]) < p.black_level:
            return self._skip(shape, bgr)
        first = self._shape is None
        self._shape = shape

        relearning = self._boost_left > 0
        rate = -1.0  # MOG2's own schedule: 1/min(2n, history)
        if relearning:  # A1 edge case: α <- 10 α while the scene is relearned
            auto = 1.0 / min(2 * (self._n_frames + 1), p.history)
            rate = min(1.0, max(auto, p.illumination_boost * p.alpha))
            self._boost_left -= 1
        raw = self._mog.apply(bgr, learningRate=rate)
        self._n_frames += 1
        if first:  # A1: the first frame initialises the model, so it is all background
            raw[:] = 0
        mog_mask = raw > 127
        n_pix = shape[0] * shape[1]
        fraction = cv2.countNonZero(raw) / n_pix
        if not first and fraction > p.illumination_fraction and p.illumination_frames:
            if self._boost_left == 0:
                self.n_illumination_events += 1
                log.info("frame %d: %.0f %% of the frame is foreground; relearning at %g alpha for %d frames "
                         "(illumination change)", self._n_frames, 100 * fraction, p.illumination_boost,
                         p.illumination_frames)
            self._boost_left = p.illumination_frames
            relearning = True

        if p.stopped is not None:
            if self._aug is None:
                self._aug = AugmentedMask(bgr, p.stopped)
            elif fraction > p.illumination_fraction and p.illumination_frames:
                gain = self._global_gain(bgr, mog_mask)
                if abs(gain - 1.0) > 0.02:
                    self._aug.rescale(gain)
            aug = self._aug.update(bgr, mog_mask, relearning=relearning,
                                   suppress_triggers=self._n_frames <= p.stopped_warmup)
            union = (mog_mask | aug) & ~self._aug.ghost
        else:
            aug = np.zeros(shape, bool)
            union = mog_mask

        labels = union.view(np.uint8).copy()  # FOREGROUND = 1 where in M, BACKGROUND = 0 elsewhere
        if p.shadows is not None:
            idx = np.flatnonzero(union)
            if idx.size:
                if relearning or self._background is None or (self._n_frames - 1) % p.background_every == 0:
                    self._refresh_background()
                x = np.take(bgr.reshape(-1, 3), idx, axis=0)
                e = np.take(self._background.reshape(-1, 3), idx, axis=0).astype(np.float32)
                if self._aug is not None:  # under a stopped object MOG2 has learned the object: use A2's memory
                    st = self._aug.stopped.reshape(-1)[idx]
                    e[st] = self._aug.reference_background.reshape(-1, 3)[idx[st]]
                lab = shadow_highlight_labels(x, e, p.shadows)
                if relearning and p.illumination_tolerance > 0:
                    lab[self._explained_by_gain(x, e)] = PixelLabel.BACKGROUND
                labels.reshape(-1)[idx] = lab
        mask = labels == PixelLabel.FOREGROUND
        return ForegroundResult(labels, mask, mog_mask, aug, fraction, relearning)

    def _global_gain(self, bgr: np.ndarray, mog_mask: np.ndarray) -> float:
        """Median brightness distortion (A3's ``a``) of the MoG foreground against A2's remembered background.

        Called only when most of the frame is foreground, so the median is the illumination change; every
        7th foreground pixel is enough for a median.
        """
        idx = np.flatnonzero(mog_mask)[::7]
        if idx.size == 0 or self._aug is None:
            return 1.0
        x = np.take(bgr.reshape(-1, 3), idx, axis=0)
        ref = np.take(self._aug.reference_background.reshape(-1, 3), idx, axis=0)
        a, _ = brightness_chromaticity(x, ref)
        return float(np.median(a)) if np.median(a) > 0 else 1.0

    def _explained_by_gain(self, x: np.ndarray, e: np.ndarray) -> np.ndarray:
        """Pixels whose change from the background is the frame's global gain (normalisation while relearning).

        The gain is the median brightness distortion ``a`` (A3) of the foreground pixels; a pixel is explained
        when ``|a / gain − 1|`` and its chromaticity distortion ``CD`` are both within ``illumination_tolerance``
        (looser than A3's ``τ_CD = 0.10``: sensor noise weighs more in a darkened frame).
        """
        a, cd = brightness_chromaticity(x, e)
        gain = float(np.median(a))
        tol = np.float32(self.params.illumination_tolerance)
        if gain <= 0:
            return np.zeros(a.shape, bool)
        return (cd <= tol) & (np.abs(a / np.float32(gain) - 1) <= tol)

    def _skip(self, shape: tuple[int, int], bgr: np.ndarray) -> ForegroundResult:
        self.n_skipped += 1
        msg = "black frame (mean grey level %.1f < %g) skipped: the background model is left unchanged"
        if not self._warned_black:
            log.warning(msg, max(cv2.mean(bgr)[:3]), self.params.black_level)
            self._warned_black = True
        else:
            log.debug(msg, max(cv2.mean(bgr)[:3]), self.params.black_level)
        empty = np.zeros(shape, bool)
        return ForegroundResult(np.zeros(shape, np.uint8), empty, empty, empty, 0.0, self._boost_left > 0, False)
