"""Per-beam range background of one laser scanner, and the foreground beams it reveals.

seed 000 Eq. 9 (ALGORITHMS.md A7): a selective exponential update with a slow rate ``alpha`` for beams
that see something in front of the background and a faster rate ``beta`` for beams that agree with it,
so a person standing still is absorbed only after ``ln(tau / d) / ln(1 - alpha)`` frames (≈ 540 frames
for a person 3 m in front of the background at ``alpha = 0.005``).

seed 001 (ALGORITHMS.md B3): the background is the *mode* of the range histogram (5 cm bins), which is
robust to passers-by. :class:`BeamBackground` combines both — the most robust combination we found:

* **initialisation** (default ``init="mode"``): over the first ``n_init`` scans, per beam, the mode of
  the range histogram, refined to the median of the readings within ±1.5 bins of it (so the static
  range is recovered to the sensor noise, not to the bin width). The histogram is smoothed over three
  adjacent bins so that a static surface whose noise straddles a bin edge is not out-voted by a
  passer-by who happens to fall into one bin. Invalid readings (no return) vote for "no background"
  (``range_max_m``): a beam that mostly sees nothing keeps every later return as foreground instead of
  learning a passer-by. ``init="median"`` is A7's literal rule (nan-median of the valid readings);
  it breaks once a beam is occluded in more than half of the initial scans, the mode does not.
* **update** (A7): after initialisation, ``B <- (1 - rate) B + rate r`` per valid beam, with
  ``rate = alpha`` for a foreground reading (nearer than ``B - tau_fg_m``), ``beta`` for a reading
  within ``tau_fg_m`` of ``B`` and ``gamma`` (default ``beta``) for a reading *beyond* ``B + tau_fg_m``.
  A reading beyond the background proves that whatever made the old background has gone (the beam
  passed through it), so following it at the background rate is safe; ``gamma = alpha`` gives A7's
  literal symmetric rule. Invalid readings (NaN, inf, 0, out of range) never update ``B``.

A beam is foreground when its reading is valid and nearer than ``B - tau_fg_m``; readings farther than
the background are never people. Before initialisation nothing is foreground (see :meth:`update`).
"""

from __future__ import annotations

import logging
import math
import warnings
from typing import Any, Literal

import numpy as np

__all__ = ["BeamBackground", "all_initialised", "clean_ranges", "histogram_mode", "keep_primed_backgrounds",
           "learn_short_backgrounds", "switch_geometry"]

log = logging.getLogger(__name__)

InitMethod = Literal["mode", "median"]
Geometry = tuple[int, float, float]
"""A scan's (beams, angle of the first beam, increment), radians."""


def clean_ranges(ranges_m: Any, range_min_m: float = 0.0, range_max_m: float = math.inf) -> np.ndarray:
    """Ranges as float64 with every invalid reading as ``NaN``.

    Parameters
    ----------
    ranges_m : (n_beams,) float
        Raw readings in metres.
    range_min_m, range_max_m : float
        A reading is valid when finite and ``range_min_m < r < range_max_m`` (so ``0`` is never valid).

    Returns
    -------
    (n_beams,) float64
    """
    r = np.array(ranges_m, dtype=np.float64, copy=True).reshape(-1)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(r) | (r <= max(range_min_m, 0.0)) | (r >= range_max_m)
    r[bad] = np.nan
    return r


def histogram_mode(ranges_m: np.ndarray, bin_m: float = 0.05, no_return_m: float = np.nan) -> np.ndarray:
    """Per-beam mode of the range histogram over a stack of scans (ALGORITHMS.md B3), refined.

    Parameters
    ----------
    ranges_m : (n_scans, n_beams) float
        Readings with invalid ones as ``NaN``.
    bin_m : float
        Histogram bin width, metres.
    no_return_m : float
        Value for a beam whose invalid readings outnumber the best 3-bin window of valid ones (and for a
        beam without any valid reading).

    Returns
    -------
    (n_beams,) float64
        The median of the readings within ±1.5 bins of the centre of the mode window.
    """
    r = np.asarray(ranges_m, dtype=np.float64)
    if r.ndim != 2:
        raise ValueError(f"ranges_m: expected an array of shape (n_scans, n_beams), got {r.shape}")
    if not bin_m > 0:
        raise ValueError(f"bin_m: expected a positive bin width in metres, got {bin_m}")
    n_scans, n_beams = r.shape
    valid = np.isfinite(r)
    out = np.full(n_beams, no_return_m, dtype=np.float64)
    if n_beams == 0 or not valid.any():
        return out
    # A sparse histogram (unique keys), so one absurd reading cannot allocate a huge dense one.
    beam = np.broadcast_to(np.arange(n_beams, dtype=np.int64), r.shape)[valid]
    b = np.floor(np.minimum(r[valid], 1e9) / bin_m).astype(np.int64)  # clip: no int64 overflow
    stride = int(b.max()) + 3  # >= 1 empty bin between beams: the 3-bin window never joins two beams
    keys, counts = np.unique(beam * stride + b, return_counts=True)
    window = counts.copy()
    for shift in (-1, 1):  # add the counts of the two neighbouring bins
        j = np.searchsorted(keys, keys + shift)
        j = np.minimum(j, keys.size - 1)
        window += np.where(keys[j] == keys + shift, counts[j], 0)
    key_beam = keys // stride
    order = np.lexsort((-keys, -window, key_beam))  # per beam the best window first; ties: the farthest
    kb = key_beam[order]
    first = order[np.concatenate([[True], kb[1:] != kb[:-1]])]
    best_beam, votes = key_beam[first], window[first]
    centre_m = np.full(n_beams, np.nan)
    centre_m[best_beam] = (keys[first] % stride + 0.5) * bin_m
    n_votes = np.zeros(n_beams, dtype=np.int64)
    n_votes[best_beam] = votes
    with np.errstate(invalid="ignore"):
        near = np.abs(r - centre_m[None, :]) <= 1.5 * bin_m
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: beams without a return
        refined = np.nanmedian(np.where(near, r, np.nan), axis=0)
    has_bg = (n_votes > 0) & (n_votes >= n_scans - valid.sum(axis=0))
    out[has_bg] = refined[has_bg]
    return out


def _rate(value: float, name: str) -> float:
    value = float(value)
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"{name}: expected a learning rate in [0, 1], got {value}")
    return value


class BeamBackground:
    """Range background of one scanner, one value per beam (ALGORITHMS.md A7 with B3's mode initialisation).

    Parameters
    ----------
    n_beams : int
        Beams per scan (>= 1). A scan of another length resets the model (logged warning), unless
        :meth:`set_geometry` announced it (then what was learnt is kept or carried over).
    alpha : float
        Learning rate for foreground readings (A7: 0.005, so people are not absorbed quickly).
    beta : float
        Learning rate for readings within ``tau_fg_m`` of the background (A7: 0.05).
    tau_fg_m : float
        A reading nearer than ``background - tau_fg_m`` is foreground (A7: 0.20 m; B3 uses 0.15 m).
    n_init : int
        Scans collected before the background is initialised (A7: 50; B3: 500).
    init : {"mode", "median"}
        Initialisation over the first ``n_init`` scans: the refined 5 cm histogram mode (B3, default) or
        A7's median.
    bin_m : float
        Histogram bin width of the mode, metres (B3: 0.05).
    gamma : float or None
        Learning rate for readings beyond ``background + tau_fg_m``; ``None`` means ``beta``.
    range_min_m, range_max_m : float
        Valid readings satisfy ``range_min_m < r < range_max_m``; ``range_max_m`` is also the background
        of a beam that has no return (A7's edge case). With ``range_max_m = inf`` such a beam adopts its
        first valid reading after initialisation as its background.

    Attributes
    ----------
    max_geometries : int
        Scan geometries whose backgrounds are kept (:meth:`set_geometry`), 8. (A scanner that goes through more
        loses the oldest; a detector's priming then no longer gives exactly the numbers online learning would.)
    background_m : (n_beams,) float64
        Current background (``NaN`` before initialisation, for a beam that never had a return when
        ``range_max_m`` is infinite, and for the beams of a new geometry outside the old one's field of view,
        until their first valid reading). Read-only view, of the current geometry's model.
    """

    def __init__(self, n_beams: int, alpha: float = 0.005, beta: float = 0.05, tau_fg_m: float = 0.20,
                 n_init: int = 50, *, init: InitMethod = "mode", bin_m: float = 0.05, gamma: float | None = None,
                 range_min_m: float = 0.0, range_max_m: float = math.inf) -> None:
        self.alpha = _rate(alpha, "alpha")
        self.beta = _rate(beta, "beta")
        self.gamma = self.beta if gamma is None else _rate(gamma, "gamma")
        self.tau_fg_m = float(tau_fg_m)
        if not (math.isfinite(self.tau_fg_m) and self.tau_fg_m >= 0):
            raise ValueError(f"tau_fg_m: expected a finite threshold >= 0 m, got {tau_fg_m}")
        if isinstance(n_init, bool) or not isinstance(n_init, int | np.integer) or n_init < 1:
            raise ValueError(f"n_init: expected an integer number of scans >= 1, got {n_init!r}")
        self.n_init = int(n_init)
        if init not in ("mode", "median"):
            raise ValueError(f"init: expected 'mode' or 'median', got {init!r}")
        self.init: InitMethod = init
        self.bin_m = float(bin_m)
        if not (math.isfinite(self.bin_m) and self.bin_m > 0):
            raise ValueError(f"bin_m: expected a positive bin width in metres, got {bin_m}")
        self.range_min_m = float(range_min_m)
        self.range_max_m = float(range_max_m)
        if not (math.isfinite(self.range_min_m) and 0 <= self.range_min_m < self.range_max_m):
            raise ValueError(f"range_min_m, range_max_m: expected 0 <= range_min_m < range_max_m, "
                             f"got {range_min_m}, {range_max_m}")
        self.resets = 0
        """How many times the model started learning from nothing again: a scan of another beam count given to
        :meth:`update`, or a new geometry met before anything was learnt (:meth:`set_geometry`)."""
        self.geometry: Geometry | None = None
        """The scan geometry the model is for, once :meth:`set_geometry` named it."""
        self._saved: dict[Geometry, tuple[int, np.ndarray, int, np.ndarray]] = {}
        self.reset(n_beams)

    # ---------------------------------------------------------------------------------------------
    def set_geometry(self, n_beams: int, angle_min_rad: float, angle_increment_rad: float) -> str:
        """Take scans of this geometry from now on, keeping what was learnt for the others.

        A scanner may change its beam count or field of view mid-recording (a driver restart, a reconfigured
        scanner, a corrupt header), or alternate between two. Relearning from scratch at each change would blind
        the scanner for ``n_init`` scans every time, and for good when it alternates. Instead the model keeps one
        background per geometry (the ``max_geometries`` most recent):

        * back to a geometry seen before: its background resumes where it was left (``"resumed"``);
        * a new geometry while the current background is initialised: each new beam takes the background of the
          old beam nearest in angle, if one lies within half a beam (the larger of the two increments); beams
          outside the old field of view have none and adopt their first valid reading (``"resampled"``);
        * otherwise a new, empty model that learns from its next ``n_init`` scans (``"new"``).

        Parameters
        ----------
        n_beams : int
            Beams per scan (>= 1).
        angle_min_rad, angle_increment_rad : float
            Angle of the first beam and between beams (finite, increment non-zero).

        Returns
        -------
        {"same", "resumed", "resampled", "new"}
        """
        new: Geometry = (int(n_beams), float(angle_min_rad), float(angle_increment_rad))
        old = self.geometry
        if new == old:
            return "same"
        if isinstance(n_beams, bool) or not isinstance(n_beams, int | np.integer) or n_beams < 1:
            raise ValueError(f"n_beams: expected an integer >= 1, got {n_beams!r}")
        if not (math.isfinite(angle_min_rad) and math.isfinite(angle_increment_rad) and angle_increment_rad != 0):
            raise ValueError(f"beam angles: expected finite angle_min and a finite non-zero increment, got "
                             f"{angle_min_rad}, {angle_increment_rad}")
        if old is None and self._n_beams == new[0] and not self._saved:  # naming the geometry it was built for
            self.geometry = new
            return "same"
        if old is not None:
            self._saved[old] = (self._n_beams, self._buffer, self._n_seen, self._bg)
        self.geometry = new
        if new in self._saved:
            left = (self._bg, self.initialised)
            self._n_beams, self._buffer, self._n_seen, self._bg = self._saved.pop(new)
            if self.initialised or not left[1]:
                return "resumed"
            # first met before the one left was initialised: carried over from it now rather than learnt alone
            self._resample(old, new, left[0])
            return "resampled"
        while len(self._saved) > self.max_geometries - 1:
            self._saved.pop(next(iter(self._saved)))  # the oldest
        if old is not None and self.initialised:
            self._resample(old, new, self._bg)
            return "resampled"
        self.resets += 1
        self.reset(new[0])
        return "new"

    def _resample(self, old: Geometry, new: Geometry, bg: np.ndarray) -> None:
        """Become the initialised model of geometry ``new`` whose beams take ``bg`` (of geometry ``old``) at the
        nearest angle within half a beam, NaN (adopt the first valid reading) outside."""
        a_old = old[1] + old[2] * np.arange(old[0])
        a_new = new[1] + new[2] * np.arange(new[0])
        j = np.rint((a_new - old[1]) / old[2]).astype(np.int64)
        inside = (j >= 0) & (j < old[0])
        j = j.clip(0, old[0] - 1)
        inside &= np.abs(a_old[j] - a_new) <= 0.5 * max(abs(old[2]), abs(new[2])) + 1e-12
        self._n_beams = new[0]
        self._buffer = np.empty((0, new[0]), dtype=np.float32)
        self._n_seen = self.n_init
        self._bg = np.where(inside, bg[j], np.nan)

    def reset(self, n_beams: int) -> None:
        """Forget everything and start learning again for scans of ``n_beams`` beams."""
        if isinstance(n_beams, bool) or not isinstance(n_beams, int | np.integer) or n_beams < 1:
            raise ValueError(f"n_beams: expected an integer >= 1, got {n_beams!r}")
        self._n_beams = int(n_beams)
        self._buffer = np.full((self.n_init, self._n_beams), np.nan, dtype=np.float32)
        self._n_seen = 0
        self._bg = np.full(self._n_beams, np.nan)

    @property
    def n_beams(self) -> int:
        return self._n_beams

    @property
    def initialised(self) -> bool:
        """Whether the background is learnt: ``n_init`` scans seen since construction or the last reset, or carried
        over from another geometry (:meth:`set_geometry`), or learnt early from fewer (:meth:`initialise_now`)."""
        return self._n_seen >= self.n_init

    @property
    def background_m(self) -> np.ndarray:
        view = self._bg.view()
        view.setflags(write=False)
        return view

    # ---------------------------------------------------------------------------------------------
    def update(self, ranges_m: Any) -> np.ndarray:
        """Classify one scan against the background, then learn from it.

        Parameters
        ----------
        ranges_m : (n_beams,) float
            Readings in metres; ``NaN``, ``inf``, values ``<= range_min_m`` (including 0) or
            ``>= range_max_m`` are invalid: never foreground and never learnt from.

        Returns
        -------
        (n_beams,) bool
            Foreground: valid and nearer than ``background - tau_fg_m``. All ``False`` until the model is
            initialised (the first ``n_init`` scans, and again after a reset): an unlearnt scene would
            make every wall a person. A scan with a different beam count resets the model (warning) and
            is the first scan of the new initialisation.
        """
        r = clean_ranges(ranges_m, self.range_min_m, self.range_max_m)
        if r.size != self._n_beams:
            log.warning("laser background: beam count changed from %d to %d; relearning the background "
                        "from scratch (%d scans)", self._n_beams, r.size, self.n_init)
            self.resets += 1
            self.reset(max(r.size, 1))
            self.geometry = None
            self._saved.clear()
            if r.size == 0:
                return np.zeros(0, dtype=bool)
        if not self.initialised:
            self._buffer[self._n_seen] = r
            self._n_seen += 1
            if self.initialised:
                self._initialise()
            return np.zeros(self._n_beams, dtype=bool)
        return self._step(r)

    def foreground(self, ranges_m: Any) -> np.ndarray:
        """The foreground mask of :meth:`update` without learning from the scan, ``(n_beams,) bool``."""
        r = clean_ranges(ranges_m, self.range_min_m, self.range_max_m)
        if r.size != self._n_beams or not self.initialised:
            return np.zeros(r.size, dtype=bool)
        with np.errstate(invalid="ignore"):
            return r < self._bg - self.tau_fg_m

    # ---------------------------------------------------------------------------------------------
    def initialise_now(self, min_scans: int = 1) -> int:
        """Learn the background now from the scans seen so far (of the current geometry) when there are fewer than
        ``n_init`` but at least ``min_scans`` (a recording that ends sooner: its scans are all there is). Returns
        the number of scans it was learnt from (0: not learnt now)."""
        n = self._n_seen
        if self.initialised or n < max(int(min_scans), 1):
            return 0
        self._initialise()
        self._n_seen = self.n_init
        return n

    def _initialise(self) -> None:
        no_return = self.range_max_m if math.isfinite(self.range_max_m) else np.nan
        buf = self._buffer[:self._n_seen].astype(np.float64)
        if self.init == "mode":
            self._bg = histogram_mode(buf, self.bin_m, no_return)
        else:
            valid = np.isfinite(buf)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                med = np.nanmedian(buf, axis=0)
            self._bg = np.where(valid.any(axis=0), med, no_return)
        self._buffer = np.empty((0, self._n_beams), dtype=np.float32)  # no longer needed

    def _step(self, r: np.ndarray) -> np.ndarray:
        bg = self._bg
        valid = ~np.isnan(r)
        with np.errstate(invalid="ignore"):
            d = r - bg  # NaN where either is unknown
            fg = d < -self.tau_fg_m
            far = d > self.tau_fg_m
        rate = np.where(fg, self.alpha, np.where(far, self.gamma, self.beta))
        learn = valid & ~np.isnan(bg)
        bg[learn] += rate[learn] * d[learn]
        adopt = valid & np.isnan(bg)  # beam without a background yet (only with range_max_m = inf)
        bg[adopt] = r[adopt]
        return fg

    max_geometries = 8


def switch_geometry(background: BeamBackground, scan: Any, warned: set[tuple[str, Geometry]]) -> str:
    """Point a scanner's background at the geometry of ``scan`` (a :class:`~fusiontrack.types.LaserScan`), as
    :meth:`BeamBackground.set_geometry` does; a scan without beams changes nothing. Each geometry met after the
    first is logged once per scanner (``warned`` holds what was logged); returns what happened."""
    if scan.n_beams < 1:
        return "same"
    old = background.geometry
    kind = background.set_geometry(scan.n_beams, scan.angle_min_rad, scan.angle_increment_rad)
    key = (scan.sensor, background.geometry)
    if kind in ("resampled", "new") and old is not None and key not in warned:
        warned.add(key)
        how = ("its background carried over from the nearest beams" if kind == "resampled"
               else f"learning its background for it ({background.n_init} scans)")
        log.warning("laser %s: scan geometry changed from %s to %s (beams, angle_min, increment); %s",
                    scan.sensor, old, background.geometry, how)
    return kind


def all_initialised(states: Any) -> bool:
    """Whether every scanner state (objects with a ``background``) has an initialised background: a priming pass
    can stop."""
    return all(st.background is not None and st.background.initialised for st in states)


PRIME_MIN_SCANS = 10  # a scanner that sent fewer than n_init scans in a whole recording: learnt from these if so many


def learn_short_backgrounds(scanners: Any, used: Any) -> None:
    """End of a priming pass that read the whole recording: a scanner whose background is not initialised sent
    fewer than ``n_init`` scans in all. Online, nothing of it would ever be foreground (its people would go
    undetected, silently); its background is learnt from the scans it sent instead, if at least
    ``PRIME_MIN_SCANS`` (:meth:`BeamBackground.initialise_now`), with a warning. ``scanners``: sensor -> state
    (``background``); ``used``: sensor -> scans the pass read."""
    for name, st in scanners.items():
        bg = st.background
        n = 0 if bg is None else bg.initialise_now(PRIME_MIN_SCANS)
        if n:
            log.warning("laser %s: the recording holds %d of its scans, fewer than the %d its background is learnt "
                        "from (n_init): learnt from the %d it has (of its last beam geometry)", name,
                        used.get(name, n), bg.n_init, n)


def keep_primed_backgrounds(states: Any) -> None:
    """End a priming pass over scanner states (``background``, ``primed_ns``, ``t_ns``): an initialised
    background is kept and marked learnt up to its last scan (``primed_ns``: the tracking pass classifies scans up
    to then without learning from them again); one not initialised is dropped, to be learnt online from the first
    scan. The scan times are forgotten either way."""
    for st in states:
        if st.background is not None and st.background.initialised:
            st.primed_ns = st.t_ns
        else:
            st.background, st.primed_ns = None, None
        st.t_ns = None
