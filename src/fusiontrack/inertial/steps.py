"""Step (gait) detection from the vertical acceleration of a phone (ALGORITHMS.md C2).

Seed 002, section 2.1.1: "the z-component of the acceleration was found to be periodic and the most
significant one ... a gait could be detected from the variation in the vertical acceleration". The
detector (ALGORITHMS.md C2, RECON) in array form:

1. the vertical specific force ``a_v`` (projection on the low-passed gravity direction, so any way of
   carrying the phone works; or the magnitude ``|a|``), on a uniform grid;
2. a zero-phase 4th-order Butterworth low-pass at 3 Hz, minus the gravity magnitude: ``d(t)``;
3. peaks of ``d`` (:func:`scipy.signal.find_peaks`) at least ``min_step_s`` apart and higher than an
   adaptive threshold ``τ(t) = clip(gain · RMS_window(d), τ_min, τ_peak)`` -- C2's fixed
   ``τ_peak = 1 m/s²`` is the ceiling, the floor stays above standing noise, and a phone that bounces
   little (held in the hand) still has its steps counted;
4. between two kept peaks ``d`` must dip below ``−valley_ratio · τ`` (C2's ``τ_valley = 0.5`` for
   ``τ_peak = 1``); of peaks with no such dip between them only the highest is kept;
5. step duration ``Δt_k = t_k − t_{k−1}``; a gap over ``max_step_s`` (1.5 s) means standing, so the
   duration chain restarts and the step after the gap gets ``first_duration_s``.

Peak times are refined between grid samples by a parabola through the three samples at the peak.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.signal import find_peaks

from .preprocess import _lowpass, _sample_rate_hz, check_imu, resample_uniform, vertical_acceleration

__all__ = ["DEFAULT_FIRST_DURATION_S", "StepDetectorParams", "Steps", "detect_steps", "step_signal"]

log = logging.getLogger(__name__)

DEFAULT_FIRST_DURATION_S = 0.55
"""Duration given to the first step of a walk when nothing better is known (ALGORITHMS.md C14 recipe)."""

SIGNALS = ("vertical", "magnitude")


@dataclass(frozen=True, slots=True)
class StepDetectorParams:
    """Parameters of :func:`detect_steps` (defaults: ALGORITHMS.md C2, RECON).

    Attributes
    ----------
    signal : {"vertical", "magnitude"}
        Projection on the low-passed gravity direction, or the norm of the specific force.
    cutoff_hz, order : float, int
        Butterworth low-pass of the step signal (zero phase).
    gravity_cutoff_hz : float
        Low-pass that estimates gravity (its direction for ``"vertical"``, its magnitude for both).
    tau_peak_mps2 : float
        Ceiling of the adaptive peak threshold: C2's ``τ_peak``.
    tau_peak_min_mps2 : float
        Floor of the adaptive peak threshold (above the noise of a phone at rest).
    adaptive_gain : float
        Threshold = ``adaptive_gain`` x RMS of the dynamic signal over ``adaptive_window_s``, clipped to
        ``[tau_peak_min_mps2, tau_peak_mps2]``. With ``adaptive_gain=0`` the threshold is the floor
        everywhere; C2's literal fixed rule is ``adaptive_gain=0, tau_peak_min_mps2=1.0``.
    adaptive_window_s : float
        Centred window of the RMS.
    valley_ratio : float
        Between two steps the signal must dip below ``−valley_ratio`` x threshold.
    min_step_s, max_step_s : float
        ``Δt_min`` (shortest step) and ``Δt_max`` (longer gaps are standing) of C2.
    min_duration_s : float
        Shortest stream accepted, s.
    """

    signal: str = "vertical"
    cutoff_hz: float = 3.0
    order: int = 4
    gravity_cutoff_hz: float = 0.5
    tau_peak_mps2: float = 1.0
    tau_peak_min_mps2: float = 0.4
    adaptive_gain: float = 0.5
    adaptive_window_s: float = 2.0
    valley_ratio: float = 0.5
    min_step_s: float = 0.30
    max_step_s: float = 1.5
    min_duration_s: float = 2.0

    def __post_init__(self) -> None:
        if self.signal not in SIGNALS:
            raise ValueError(f"signal: expected one of {SIGNALS}, got {self.signal!r}")
        if not isinstance(self.order, int) or not 1 <= self.order <= 8:
            raise ValueError(f"order: expected an integer in [1, 8], got {self.order!r}")
        for name in ("cutoff_hz", "gravity_cutoff_hz", "tau_peak_mps2", "tau_peak_min_mps2", "adaptive_window_s",
                     "min_step_s", "max_step_s", "min_duration_s"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"{name}: expected a finite value > 0, got {value!r}")
        for name in ("adaptive_gain", "valley_ratio"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name}: expected a finite value >= 0, got {value!r}")
        if self.tau_peak_min_mps2 > self.tau_peak_mps2:
            raise ValueError(f"tau_peak_min_mps2: expected <= tau_peak_mps2 ({self.tau_peak_mps2}), "
                             f"got {self.tau_peak_min_mps2}")
        if self.max_step_s <= self.min_step_s:
            raise ValueError(f"max_step_s: expected > min_step_s ({self.min_step_s}), got {self.max_step_s}")
        if self.gravity_cutoff_hz >= self.cutoff_hz:
            raise ValueError(f"gravity_cutoff_hz: expected below cutoff_hz ({self.cutoff_hz}), "
                             f"got {self.gravity_cutoff_hz}")


@dataclass(frozen=True, slots=True, eq=False)
class Steps:
    """Detected steps.

    Attributes
    ----------
    t_ns : (k,) int64
        Step times (peak of the vertical acceleration, ~ heel strike), ns.
    duration_s : (k,) float64
        ``t_k − t_{k−1}``, s; ``first_duration_s`` for the first step of each walk.
    new_walk : (k,) bool
        The step starts a walk (first step, or after a gap longer than ``max_step_s``).
    peak_mps2 : (k,) float64
        Height of the filtered dynamic vertical acceleration at the step, m/s^2.
    """

    t_ns: np.ndarray
    duration_s: np.ndarray
    new_walk: np.ndarray
    peak_mps2: np.ndarray

    def __len__(self) -> int:
        return int(self.t_ns.size)


def step_signal(t_ns: Any, accel_mps2: Any, params: StepDetectorParams | None = None,
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The signal the detector looks at, and its threshold (for plots and benchmarks).

    Parameters
    ----------
    t_ns : (n,) int
        Non-decreasing sample times, ns.
    accel_mps2 : (n, 3) float
        Specific force, phone frame, m/s^2.
    params : StepDetectorParams, optional

    Returns
    -------
    grid_ns : (m,) int64
        Uniform grid at the median sampling rate.
    dyn_mps2 : (m,) float64
        Low-passed vertical (or magnitude) specific force minus gravity.
    threshold_mps2 : (m,) float64
        Adaptive peak threshold.
    """
    p = params or StepDetectorParams()
    t, accel, _ = check_imu(t_ns, accel_mps2, min_duration_s=p.min_duration_s)
    if p.signal == "vertical":
        grid_ns, a, g = vertical_acceleration(t, accel, gravity_cutoff_hz=p.gravity_cutoff_hz)
        fs = _sample_rate_hz(grid_ns)
    else:
        grid_ns, a3 = resample_uniform(t, accel)
        fs = _sample_rate_hz(grid_ns)
        a = np.linalg.norm(a3, axis=1)
        g = _lowpass(a, p.gravity_cutoff_hz, fs, order=2)
    if fs < 4 * p.cutoff_hz:
        raise ValueError(f"t_ns: sampling rate {fs:.3g} Hz is too low for a {p.cutoff_hz:g} Hz step filter "
                         f"(need at least {4 * p.cutoff_hz:g} Hz)")
    dyn = _lowpass(a, p.cutoff_hz, fs, order=p.order) - g
    w = max(1, round(p.adaptive_window_s * fs))
    c = np.concatenate([[0.0], np.cumsum(dyn * dyn)])
    i = np.arange(dyn.size)
    lo, hi = np.clip(i - w // 2, 0, dyn.size), np.clip(i + w - w // 2, 0, dyn.size)
    rms = np.sqrt((c[hi] - c[lo]) / (hi - lo))
    threshold = np.clip(p.adaptive_gain * rms, p.tau_peak_min_mps2, p.tau_peak_mps2)
    return grid_ns, dyn, threshold


def detect_steps(t_ns: Any, accel_mps2: Any, params: StepDetectorParams | None = None, *,
                 first_duration_s: float | None = None) -> Steps:
    """Detect steps in a phone accelerometer stream (ALGORITHMS.md C2).

    Parameters
    ----------
    t_ns : (n,) int
        Sample times, integer ns, non-decreasing; at least ``params.min_duration_s`` long.
    accel_mps2 : (n, 3) float
        Specific force (gravity included), phone frame, m/s^2; any phone orientation.
    params : StepDetectorParams, optional
        Detector settings (ALGORITHMS.md C2 defaults).
    first_duration_s : float, optional
        Duration given to the first step of each walk (C2: the median training duration, e.g.
        :attr:`StepLengthModel.typical_duration_s`); by default the median duration of the other
        steps of this stream, or :data:`DEFAULT_FIRST_DURATION_S` if there are none.

    Returns
    -------
    Steps
        ``t_ns (k,)``, ``duration_s (k,)``, ``new_walk (k,)``, ``peak_mps2 (k,)``.

    Raises
    ------
    ValueError
        Bad or too short input (the parameter is named).
    """
    p = params or StepDetectorParams()
    if first_duration_s is not None and (not np.isfinite(first_duration_s) or first_duration_s <= 0):
        raise ValueError(f"first_duration_s: expected a finite duration > 0, got {first_duration_s!r}")
    grid_ns, dyn, threshold = step_signal(t_ns, accel_mps2, p)
    fs = _sample_rate_hz(grid_ns)
    peaks, _ = find_peaks(dyn, height=threshold, distance=max(1, int(p.min_step_s * fs)))
    if peaks.size > 1:
        # a step needs a dip between it and the previous one; of peaks with no dip between them,
        # keep the highest (groups of peaks split at the deep valleys)
        valley = np.minimum.reduceat(dyn, peaks)[:-1]
        deep = valley < -p.valley_ratio * threshold[peaks[1:]]
        group = np.concatenate([[0], np.cumsum(deep)])
        order = np.lexsort((-dyn[peaks], group))
        first_of_group = np.concatenate([[True], group[order][1:] != group[order][:-1]])
        peaks = np.sort(peaks[order][first_of_group])
    # sub-sample peak time: vertex of the parabola through the three samples at the peak
    inner = (peaks > 0) & (peaks < dyn.size - 1)
    offset = np.zeros(peaks.size)
    y0, y1, y2 = dyn[peaks[inner] - 1], dyn[peaks[inner]], dyn[peaks[inner] + 1]
    den = y0 - 2 * y1 + y2
    offset[inner] = np.where(den < 0, 0.5 * (y0 - y2) / np.where(den < 0, den, -1.0), 0.0)
    step_ns = float(grid_ns[1] - grid_ns[0])
    t_steps = grid_ns[peaks] + np.round(offset * step_ns).astype(np.int64)

    gaps_s = np.diff(t_steps) * 1e-9
    new_walk = np.concatenate([[True], gaps_s > p.max_step_s]) if t_steps.size else np.zeros(0, bool)
    duration = np.concatenate([[np.nan], gaps_s]) if t_steps.size else np.zeros(0)
    if first_duration_s is None:
        inside = duration[~new_walk]
        first_duration_s = float(np.median(inside)) if inside.size else DEFAULT_FIRST_DURATION_S
    duration[new_walk] = first_duration_s
    log.debug("detected %d steps in %d walk(s) over %.1f s", t_steps.size, int(new_walk.sum()),
              (grid_ns[-1] - grid_ns[0]) * 1e-9)
    return Steps(t_steps, duration, new_walk, dyn[peaks])
