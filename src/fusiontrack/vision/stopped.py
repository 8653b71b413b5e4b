"""Seed 000's stopped-object "augmented mask" on top of any MoG foreground mask (ALGORITHMS.md A2).

The paper's four steps (seed 000, 3.1): sort the Gaussians by weight; pixels *moving from the first
Gaussian component to the second* belong to a stopped object and go into the augmented mask; the
augmented mask is added to the MoG mask; pixels leave it *when the stopped object starts to move*.

OpenCV's MOG2 does not expose its per-pixel components, so A2's per-pixel state keeps the **colour**
of a component where A2 keeps its id (a component is its mean colour to within ``λ_m σ``):

* ``ref`` — the colour of the background the pixel showed the last time MoG called it background
  while nothing was stopped on it (A2 step 5's ``ref_bg_id``); it follows slow change at rate
  ``ref_rate`` and is frozen while the pixel is foreground or stopped;
* ``cand``/``cnt`` — a MoG-foreground pixel that does not match ``ref`` but keeps matching one new
  colour is what "moved from the first to the second component and stays there" means (a new
  component starts at rank 2 by weight, A1 step 4); after ``n_stop`` consecutive frames the colour
  becomes ``stop`` (step 1, the trigger); a count that has started goes on even if MoG absorbs the
  colour meanwhile (it does within ~8 frames while relearning after an illumination change);
* ``stop``/``miss`` — the pixel stays in the augmented mask while it keeps matching ``stop``, even
  after MoG absorbs the object (step 2); it is released when it matches ``ref`` again or misses
  ``stop`` for ``n_release`` frames (step 3), or after ``t_max`` frames if set (step 4);
* ``ghost`` — a pixel released because it shows ``ref`` again is background, even while MoG (which has
  by then learned the object and, after ~600 frames, forgotten the background) still calls it
  foreground; the flag holds until MoG agrees or the pixel shows something else. This is what keeps
  the uncovered background from leaving a ghost (A2 test: <= 1 % three frames after the object leaves).

Camera shake or a global illumination change makes a large part of the frame trigger at once: if more
than ``max_trigger_fraction`` of the pixels would trigger in one frame the triggers are suppressed
(A2 edge case) and their new colour becomes their remembered background (the scene changed). The
caller can also suppress triggers (``suppress_triggers``) or, after it measured a global illumination
change, rescale the remembered colours (:meth:`AugmentedMask.rescale`).

Limitation: a colour cannot tell an object that arrives and stops from a background that reappears
when something that was part of the learned scene leaves (a car parked since the first frame drives
off): both are a stable new colour on a pixel, and A2 keeps the uncovered street as a "stopped object"
until ``t_max`` (off by default). :class:`~fusiontrack.vision.foreground.ForegroundModel` avoids the
common case, people in the very first frame, by starting no stop during a warm-up.

Work is done only on the *active* pixels (MoG foreground, stopped, counting or ghost), gathered once per
frame; the background pixels cost one masked ``cv2.accumulateWeighted``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["AugmentedMask", "AugmentedMaskParams"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class AugmentedMaskParams:
    """Parameters of the stopped-object mask (ALGORITHMS.md A2 [RECON]).

    Attributes
    ----------
    n_stop : int
        Consecutive frames on one new colour before a pixel counts as stopped (5).
    n_release : int
        Consecutive frames off the stopped colour before it is released (2).
    t_max : int or None
        Release after this many stopped frames (a parked object becomes scene); ``None`` = never (A2 step 4).
    lambda_m : float
        Match test ``Σ_c (x_c − μ_c)² < λ_m² Σ_c σ²`` as in A1 (2.5).
    match_sigma : float
        The ``σ`` of that test in grey levels. A1's ``σ_min = 15`` is the floor of OpenCV's coarse MOG;
        MOG2 learns variances of 2-9 grey levels, and 6 keeps dark clothes on grey floors apart [RECON].
    ref_rate : float
        Rate at which the remembered background colour follows the frame where MoG sees background.
    ref_check_every : int
        Every this many frames the remembered colour of MoG-background pixels that no longer match it
        jumps to the frame (A2 step 5: ``ref_bg_id`` becomes the matched component); 0 = never.
    max_trigger_fraction : float
        More triggers than this fraction of the frame in one frame are suppressed (A2 edge case: 0.30).
    max_trigger_fraction_relearning : float
        The same while the caller relearns after an illumination change (0.10): a gain the camera clips
        leaves whole regions off the rescaled memory, and they must not become "stopped" [RECON].
    """

    n_stop: int = 5
    n_release: int = 2
    t_max: int | None = None
    lambda_m: float = 2.5
    match_sigma: float = 6.0
    ref_rate: float = 0.05
    ref_check_every: int = 10
    max_trigger_fraction: float = 0.30
    max_trigger_fraction_relearning: float = 0.10

    def __post_init__(self) -> None:
        for name in ("n_stop", "n_release"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 250:
                raise ValueError(f"AugmentedMaskParams.{name}: expected an integer in 1..250, got {v!r}")
        if self.t_max is not None and (not isinstance(self.t_max, int) or self.t_max < 1):
            raise ValueError(f"AugmentedMaskParams.t_max: expected None or an integer >= 1, got {self.t_max!r}")
        for name in ("lambda_m", "match_sigma"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"AugmentedMaskParams.{name}: expected a finite value > 0, got {v!r}")
        if not 0 < self.ref_rate <= 1:
            raise ValueError(f"AugmentedMaskParams.ref_rate: expected 0 < ref_rate <= 1, got {self.ref_rate!r}")
        if not isinstance(self.ref_check_every, int) or self.ref_check_every < 0:
            raise ValueError("AugmentedMaskParams.ref_check_every: expected an integer >= 0, got "
                             f"{self.ref_check_every!r}")
        for name in ("max_trigger_fraction", "max_trigger_fraction_relearning"):
            v = getattr(self, name)
            if not 0 < v <= 1:
                raise ValueError(f"AugmentedMaskParams.{name}: expected a value in (0, 1], got {v!r}")

    @property
    def match_threshold2(self) -> float:
        """``λ_m² Σ_c σ²`` for three channels (squared grey levels)."""
        return float(self.lambda_m**2 * 3 * self.match_sigma**2)


_ROW = np.dtype((np.void, 12))  # one float32 colour as a single element: row gathers ~3x faster than [idx]
_PIXEL = np.dtype((np.void, 3))  # one uint8 BGR pixel as a single element
_INV_COUNT = (1.0 / np.clip(np.arange(9), 1, 8)).astype(np.float32)  # a running mean's rate 1/min(count, 8)


def _rows(colours: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``colours[idx]`` for a C-contiguous ``(n, 3)`` float32 array, as a new ``(len(idx), 3)`` array."""
    return colours.view(_ROW).reshape(-1)[idx].view(np.float32).reshape(-1, 3)


def _put_rows(colours: np.ndarray, idx: np.ndarray, values: np.ndarray) -> None:
    """``colours[idx] = values`` for C-contiguous ``(n, 3)`` float32 arrays."""
    colours.view(_ROW).reshape(-1)[idx] = np.ascontiguousarray(values, np.float32).view(_ROW).reshape(-1)


def _sqdist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``Σ_c (a_c − b_c)²`` of ``(n, 3)`` colours, ``(n,)`` float32."""
    d = a - b
    d *= d
    return d[:, 0] + d[:, 1] + d[:, 2]


class AugmentedMask:
    """Per-pixel stopped-object state of one camera (A2); ``update`` once per frame after the MoG.

    Parameters
    ----------
    first_frame : (H, W, 3) uint8
        The frame that initialises the remembered background (as A1's first frame does the MoG).
    params : AugmentedMaskParams, optional
    """

    def __init__(self, first_frame: np.ndarray, params: AugmentedMaskParams | None = None) -> None:
        self.params = AugmentedMaskParams() if params is None else params
        if first_frame.ndim != 3 or first_frame.shape[2] != 3 or first_frame.dtype != np.uint8:
            raise ValueError(f"first_frame: expected an (H, W, 3) uint8 image, got {first_frame.shape} "
                             f"{first_frame.dtype}")
        self.shape = (int(first_frame.shape[0]), int(first_frame.shape[1]))
        n = self.shape[0] * self.shape[1]
        self._ref = first_frame.astype(np.float32)  # (H, W, 3), updated in place by cv2
        self._cand = np.zeros((n, 3), np.float32)
        self._stop_col = np.zeros((n, 3), np.float32)
        self._cnt = np.zeros(n, np.int32)
        self._miss = np.zeros(n, np.int32)
        self._age = np.zeros(n, np.int32)
        self._stop = np.zeros(n, bool)
        self._ghost = np.zeros(n, bool)
        self._busy = np.zeros(n, bool)  # stopped, ghost or counting: kept so no full-frame int compare is needed
        self._frame = 0
        self.suppressed_frames = 0  # frames in which triggers were suppressed (diagnostics)

    # -- state views ------------------------------------------------------------------------------

    @property
    def stopped(self) -> np.ndarray:
        """Pixels in the augmented mask ``M_aug``, ``(H, W)`` bool (a read-only view)."""
        v = self._stop.reshape(self.shape).view()
        v.setflags(write=False)
        return v

    @property
    def ghost(self) -> np.ndarray:
        """Pixels known to show the remembered background although MoG still calls them foreground."""
        v = self._ghost.reshape(self.shape).view()
        v.setflags(write=False)
        return v

    @property
    def reference_background(self) -> np.ndarray:
        """The remembered background colour, ``(H, W, 3)`` float32 grey levels (a read-only view).

        Under a stopped object this is the background *before* it stopped, unlike MoG's background image.
        """
        v = self._ref.view()
        v.setflags(write=False)
        return v

    def rescale(self, gain: float) -> None:
        """Multiply the remembered colours by a global illumination gain (the caller measured it), restart counts.

        After a global jump the background then still matches ``ref``, and a person who was in the scene
        still differs from it: A2 keeps working through the jump while MoG relearns.
        """
        if not (np.isfinite(gain) and gain > 0):
            raise ValueError(f"gain: expected a finite value > 0, got {gain!r}")
        g = np.float32(gain)
        for colours in (self._ref, self._stop_col):  # the camera clips at 255 as the gain does
            colours *= g
            np.minimum(colours, np.float32(255), out=colours)
        self._cnt[:] = 0
        np.logical_or(self._stop, self._ghost, out=self._busy)

    # -- update -----------------------------------------------------------------------------------

    def update(self, frame: np.ndarray, mog_foreground: np.ndarray, relearning: bool = False,
               suppress_triggers: bool = False) -> np.ndarray:
        """Advance one frame and return ``M_aug``.

        Parameters
        ----------
        frame : (H, W, 3) uint8
        mog_foreground : (H, W) bool
            The conventional MoG mask ``M_mog`` of this frame.
        relearning : bool
            The caller relearns after an illumination change: the stricter trigger guard applies.
        suppress_triggers : bool
            No pixel may start a stop in this frame; counting restarts.

        Returns
        -------
        (H, W) bool
            ``M_aug`` (a fresh array).
        """
        p = self.params
        if frame.shape[:2] != self.shape or mog_foreground.shape != self.shape:
            raise ValueError(f"frame, mog_foreground: expected size {self.shape}, got {frame.shape[:2]} and "
                             f"{mog_foreground.shape}")
        if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
            raise ValueError(f"frame: expected an (H, W, 3) uint8 image, got {frame.shape} {frame.dtype}")
        frame = np.ascontiguousarray(frame)  # the pixel gather below views each BGR pixel as one element
        self._frame += 1
        thr2 = np.float32(p.match_threshold2)
        fg_all = mog_foreground.reshape(-1)
        active = fg_all | self._busy  # busy = stopped | ghost | counting
        idx = np.flatnonzero(active)
        if idx.size:
            x = frame.reshape(-1, 3).view(_PIXEL).reshape(-1)[idx].view(np.uint8).reshape(-1, 3).astype(np.float32)
            fg = fg_all[idx]
            match_ref = _sqdist(x, _rows(self._ref.reshape(-1, 3), idx)) < thr2
            cnt_all = self._cnt[idx]

            # steps 2-4: keep or release the stopped pixels (s = positions in idx of stopped pixels)
            st = self._stop[idx]
            s = np.flatnonzero(st)
            release = np.zeros(idx.size, bool)
            if s.size:
                gs = idx[s]
                xs = x[s]
                stop_col = _rows(self._stop_col, gs)
                match_stop = _sqdist(xs, stop_col) < thr2
                miss_s = np.where(match_stop, 0, self._miss[gs] + 1)
                age_s = self._age[gs] + 1
                release_s = match_ref[s] | (miss_s >= p.n_release)
                if p.t_max is not None:
                    release_s |= age_s >= p.t_max
                # the stopped colour follows slow change (lighting); products with 0/1, not boolean indexing
                follow = (match_stop & ~release_s).astype(np.float32) * np.float32(p.ref_rate)
                stop_col += follow[:, None] * (xs - stop_col)
                release[s] = release_s
                still = st & ~release
            else:
                still = st

            # ghost: released onto the remembered background, while MoG has not relearned it
            ghost = (self._ghost[idx] | release) & match_ref & fg

            # step 1: count frames on one new colour (c = positions in idx of counting pixels), trigger at n_stop.
            # A count starts on MoG foreground only, but goes on if MoG absorbs the colour before n_stop (after an
            # illumination change MoG relearns at 10 α and absorbs whatever sits on a pixel for ~8 frames)
            counting = ~(still | match_ref | ghost) & (fg | (cnt_all > 0))
            c = np.flatnonzero(counting)
            gc = idx[c]
            cnt_c = cnt_all[c]
            cand = _rows(self._cand, gc)
            xc = x[c]
            same = (cnt_c > 0) & (_sqdist(xc, cand) < thr2)
            cnt_c = np.where(same, cnt_c + 1, fg[c].view(np.int8)).astype(np.int32, copy=False)
            # a fresh candidate takes the colour (rate 1); a repeated one is a running mean, then smoothing
            rate = np.where(same, _INV_COUNT[np.minimum(cnt_c, 8)], np.float32(1))
            cand += rate[:, None] * (xc - cand)
            trig = cnt_c >= p.n_stop
            n_trig = int(np.count_nonzero(trig))
            guard = p.max_trigger_fraction_relearning if relearning else p.max_trigger_fraction
            if n_trig and (suppress_triggers or n_trig > guard * active.size):
                if not suppress_triggers:  # the scene itself changed there: its new colour is the background
                    log.debug("frame %d: %d stop triggers (%.0f %% of the frame) suppressed as camera shake or "
                              "an illumination change", self._frame, n_trig, 100.0 * n_trig / active.size)
                    _put_rows(self._ref.reshape(-1, 3), gc[trig], cand[trig])
                self.suppressed_frames += 1
                cnt_c[trig] = 0
                trig[:] = False
                n_trig = 0
            cnt_c[trig] = 0

            # write back: counters of every active pixel restart unless counting or stopped
            cnt_new = np.zeros(idx.size, np.int32)
            cnt_new[c] = cnt_c
            self._cnt[idx] = cnt_new
            _put_rows(self._cand, gc, cand)
            self._ghost[idx] = ghost
            stop_new = still.copy()
            if s.size:
                self._miss[gs] = np.where(release_s, 0, miss_s)
                self._age[gs] = np.where(release_s, 0, age_s)
                _put_rows(self._stop_col, gs, stop_col)
            if n_trig:
                gt = gc[trig]
                stop_new[c[trig]] = True
                self._miss[gt] = 0
                self._age[gt] = 0
                _put_rows(self._stop_col, gt, cand[trig])
            self._stop[idx] = stop_new
            self._busy[idx] = stop_new | ghost | (cnt_new > 0)

        # step 5: the remembered background follows the frame where MoG sees background and nothing stopped
        # (ghost pixels are MoG foreground, so this is: neither MoG foreground nor busy)
        bg = ~(fg_all | self._busy).reshape(self.shape)
        bg_u8 = bg.view(np.uint8)
        if p.ref_check_every and self._frame % p.ref_check_every == 0:
            # L1 colour distance; for an equal offset in all three channels L1 > sqrt(3 thr2) <=> L2² > thr2
            l1 = cv2.transform(cv2.absdiff(frame, cv2.convertScaleAbs(self._ref)), np.ones((1, 3), np.float32))
            far = bg & (l1 > np.sqrt(3.0 * thr2))
            if far.any():  # MoG has adopted another colour here: so does ref (A2 step 5)
                self._ref[far] = frame[far]
        cv2.accumulateWeighted(frame, self._ref, p.ref_rate, bg_u8)
        return self._stop.reshape(self.shape).copy()
