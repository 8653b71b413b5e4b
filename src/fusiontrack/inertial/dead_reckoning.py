"""Pedestrian dead reckoning: floor positions from steps and heading (seed 002 Eq. 2; ALGORITHMS.md C5).

``x_t = x_{t−1} + L_t cos θ_t``, ``y_t = y_{t−1} + L_t sin θ_t`` with ``L_t`` from the step model (C3)
and ``θ_t = θ_0 + ψ_t`` the heading of step ``t`` from the integrated yaw (C4), taken as the mean yaw
over the step (C5 allows the value at the step time or the mean over the step; the mean averages
out the trunk's sway). :func:`run_pdr` chains C1 -> C2 -> C3 -> C4 -> C5 on one IMU stream.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from .attitude import integrate_attitude
from .preprocess import ImuCalibration, calibrate_imu, check_imu, level_imu
from .step_length import DEFAULT_STEP_MODEL, StepLengthModel
from .steps import StepDetectorParams, Steps, detect_steps

__all__ = ["PdrResult", "dead_reckon", "run_pdr", "step_headings"]

log = logging.getLogger(__name__)

HEADING_MODES = ("mean", "at_step")


def dead_reckon(step_length_m: Any, heading_rad: Any, start_m: Any = (0.0, 0.0)) -> np.ndarray:
    """Positions after each step, seed 002 Eq. 2 (ALGORITHMS.md C5), vectorised.

    Parameters
    ----------
    step_length_m : (k,) float
        ``L_t``, m.
    heading_rad : (k,) float
        ``θ_t``, rad, in the floor frame (counter-clockwise from +x).
    start_m : (2,) float
        Position before the first step.

    Returns
    -------
    position_m : (k, 2) float64
        Position at the end of each step.
    """
    L = np.asarray(step_length_m, dtype=np.float64)
    th = np.asarray(heading_rad, dtype=np.float64)
    start = np.asarray(start_m, dtype=np.float64)
    if L.ndim != 1 or th.shape != L.shape:
        raise ValueError(f"step_length_m, heading_rad: expected two (k,) arrays, got {L.shape} and {th.shape}")
    if start.shape != (2,) or not np.all(np.isfinite(start)):
        raise ValueError(f"start_m: expected two finite coordinates, got {start_m!r}")
    if not (np.all(np.isfinite(L)) and np.all(np.isfinite(th))):
        raise ValueError("step_length_m, heading_rad: expected finite values")
    return start + np.cumsum(L[:, None] * np.stack([np.cos(th), np.sin(th)], axis=1), axis=0)


def step_headings(step_t_ns: Any, duration_s: Any, t_ns: Any, yaw_rad: Any, mode: str = "mean") -> np.ndarray:
    """Yaw of each step: the mean over ``[t_k − Δt_k, t_k]`` or the value at ``t_k`` (ALGORITHMS.md C5).

    Parameters
    ----------
    step_t_ns : (k,) int
        Step times.
    duration_s : (k,) float
        Step durations, s.
    t_ns : (n,) int
        Times of the yaw samples, non-decreasing.
    yaw_rad : (n,) float
        Unwrapped yaw.
    mode : {"mean", "at_step"}

    Returns
    -------
    (k,) float64
    """
    if mode not in HEADING_MODES:
        raise ValueError(f"mode: expected one of {HEADING_MODES}, got {mode!r}")
    ts = (np.asarray(t_ns, dtype=np.int64) - int(np.asarray(t_ns)[0])) * 1e-9
    yaw = np.asarray(yaw_rad, dtype=np.float64)
    tk = (np.asarray(step_t_ns, dtype=np.int64) - int(np.asarray(t_ns)[0])) * 1e-9
    at_step = np.interp(tk, ts, yaw)
    if mode == "at_step" or tk.size == 0:
        return at_step
    # mean over the step = difference of the running integral of yaw / duration
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (yaw[1:] + yaw[:-1]) * np.diff(ts))])
    t0 = tk - np.asarray(duration_s, dtype=np.float64)
    span = np.interp(tk, ts, integral) - np.interp(t0, ts, integral)
    # before the first sample the yaw is taken as constant: np.interp clamps the integral, so add that part
    span += np.clip(ts[0] - t0, 0.0, None) * yaw[0]
    width = tk - t0
    return np.where(width > 0, span / np.where(width > 0, width, 1.0), at_step)


@dataclass(frozen=True, slots=True, eq=False)
class PdrResult:
    """The output of :func:`run_pdr`.

    Attributes
    ----------
    step_t_ns : (k,) int64
        Step times, ns (the IMU's clock).
    step_duration_s : (k,) float64
    step_length_m : (k,) float64
    heading_rad : (k,) float64
        Heading of each step in the floor frame, unwrapped.
    position_m : (k, 2) float64
        Position at the end of each step.
    new_walk : (k,) bool
        The step starts a walk (after standing).
    start_m : (2,) float64
        Position before the first step.
    heading0_rad : float
        Floor heading of the phone's initial yaw.
    yaw_t_ns : (n,) int64
        Times of the integrated yaw.
    yaw_rad : (n,) float64
        Integrated yaw of the levelled phone, relative to its first sample (zeros without a gyro).
    has_gyro : bool
        ``False``: no gyroscope, the headings are all ``heading0_rad``.
    calibration : ImuCalibration
    step_model : StepLengthModel
    source : str
        Where the samples came from (a path, or ``"arrays"``).
    """

    step_t_ns: np.ndarray
    step_duration_s: np.ndarray
    step_length_m: np.ndarray
    heading_rad: np.ndarray
    position_m: np.ndarray
    new_walk: np.ndarray
    start_m: np.ndarray
    heading0_rad: float
    yaw_t_ns: np.ndarray
    yaw_rad: np.ndarray
    has_gyro: bool
    calibration: ImuCalibration
    step_model: StepLengthModel
    source: str = "arrays"

    @property
    def n_steps(self) -> int:
        return int(self.step_t_ns.size)

    @property
    def distance_m(self) -> float:
        """Distance walked, m (sum of the step lengths)."""
        return float(self.step_length_m.sum())

    def knots(self) -> tuple[np.ndarray, np.ndarray]:
        """The piecewise-linear trajectory: ``t_ns (m,) int64`` and ``position_m (m, 2)``.

        A walk starts at the previous position ``Δt`` before its first step (the start position for
        the first walk); positions between knots are linear (ALGORITHMS.md C5).
        """
        if self.n_steps == 0:
            return np.zeros(0, np.int64), np.zeros((0, 2))
        prev = np.vstack([self.start_m, self.position_m[:-1]])
        begin = self.step_t_ns - np.round(self.step_duration_s * 1e9).astype(np.int64)
        floor = np.concatenate([[np.iinfo(np.int64).min], self.step_t_ns[:-1]])
        begin = np.maximum(begin, floor)
        w = np.flatnonzero(self.new_walk)
        t = np.concatenate([begin[w], self.step_t_ns])
        pos = np.vstack([prev[w], self.position_m])
        order = np.argsort(np.concatenate([w * 2, np.arange(self.n_steps) * 2 + 1]), kind="stable")
        return t[order], pos[order]

    def position_at(self, t_ns: Any) -> np.ndarray:
        """Positions at times ``t_ns`` (m,) -> (m, 2), linear between knots, constant outside."""
        kt, kp = self.knots()
        q = np.asarray(t_ns, dtype=np.int64)
        if kt.size == 0:
            return np.broadcast_to(self.start_m, (*q.shape, 2)).copy()
        x = (q - kt[0]) * 1e-9
        kx = (kt - kt[0]) * 1e-9
        return np.stack([np.interp(x, kx, kp[:, 0]), np.interp(x, kx, kp[:, 1])], axis=-1)


def run_pdr(t_ns: Any, accel_mps2: Any, gyro_radps: Any = None, *, step_model: StepLengthModel | None = None,
            step_params: StepDetectorParams | None = None, still: tuple[int, int] | str | None = "auto",
            start_m: Any = (0.0, 0.0), heading0_rad: float = 0.0, heading_mode: str = "mean",
            tilt_time_constant_s: float = 1.0) -> PdrResult:
    """Pedestrian dead reckoning on one phone IMU stream (ALGORITHMS.md C1 -> C5).

    Parameters
    ----------
    t_ns : (n,) int
        Sample times, integer ns, non-decreasing.
    accel_mps2 : (n, 3) float
        Specific force, phone frame, m/s^2.
    gyro_radps : (n, 3) float, optional
        Angular rate, phone frame, rad/s; ``None`` or all ``NaN`` (accelerometer-only phones): the
        steps and the distance are still computed, the heading stays ``heading0_rad`` (logged).
    step_model : StepLengthModel, optional
        The walker's C3 model; :data:`~fusiontrack.inertial.step_length.DEFAULT_STEP_MODEL` if omitted.
    step_params : StepDetectorParams, optional
        C2 detector settings.
    still : "auto", (start_ns, end_ns) or None
        Still period for the gyro bias and the levelling (C1), see :func:`calibrate_imu`.
    start_m : (2,) float
        Start position in the floor frame, m (C5: from a known start pose or the first fix).
    heading0_rad : float
        Floor heading of the phone's yaw at the first sample (C1: yaw is unobservable at rest).
    heading_mode : {"mean", "at_step"}
        See :func:`step_headings`.
    tilt_time_constant_s : float
        Complementary filter of :func:`integrate_attitude`.

    Returns
    -------
    PdrResult

    Raises
    ------
    ValueError
        NaN samples, time going backwards, a stream too short for the step filter, bad parameters.
    """
    model = step_model if step_model is not None else DEFAULT_STEP_MODEL
    if not isinstance(model, StepLengthModel):
        raise ValueError(f"step_model: expected a StepLengthModel, got {type(step_model).__name__}")
    params = step_params or StepDetectorParams()
    if not np.isfinite(heading0_rad):
        raise ValueError(f"heading0_rad: expected a finite angle, got {heading0_rad!r}")
    if heading_mode not in HEADING_MODES:
        raise ValueError(f"heading_mode: expected one of {HEADING_MODES}, got {heading_mode!r}")
    t, accel, gyro = check_imu(t_ns, accel_mps2, gyro_radps, min_duration_s=params.min_duration_s)
    calibration = calibrate_imu(t, accel, gyro, still=still)
    steps: Steps = detect_steps(t, accel, params,
                                first_duration_s=model.typical_duration_s if model.n_train else None)
    if gyro is None:
        log.warning("no gyroscope in the IMU stream: headings are held at heading0_rad = %.3f rad", heading0_rad)
        yaw = np.zeros(t.size)
    else:
        accel_level, gyro_level = level_imu(accel, gyro, calibration)
        yaw = integrate_attitude(t, gyro_level, accel_mps2=accel_level, tilt_time_constant_s=tilt_time_constant_s)[:, 2]
    heading = heading0_rad + step_headings(steps.t_ns, steps.duration_s, t, yaw, heading_mode)
    lengths = model.length(steps.duration_s)
    start = np.asarray(start_m, dtype=np.float64)
    positions = dead_reckon(lengths, heading, start)
    return PdrResult(steps.t_ns, steps.duration_s, lengths, heading, positions, steps.new_walk, start,
                     float(heading0_rad), t, yaw, gyro is not None, calibration, model)
