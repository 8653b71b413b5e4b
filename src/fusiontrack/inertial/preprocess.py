"""IMU preprocessing: input checks, uniform resampling, still-period calibration and levelling.

Seed 002 (``002_5ddfad3fcb8d60bb.txt``, section 4): "the test subject stood steadily in the same
position for over 10 seconds, and the inherent noise in the sensor measurements was estimated".
ALGORITHMS.md C1 turns that into: gyro bias = mean gyro over the still period, noise = its std, and a
mounting rotation ``R_mount`` (phone frame -> level frame, z up, yaw fixed to 0) from the mean
accelerometer vector. Real traces often have no still period (the Oxford step counter traces start
walking within a second), so :func:`calibrate_imu` falls back to the gravity direction of the whole
trace and a zero gyro bias, and says so in the log.

For step detection the phone may be carried any way (hand, pocket, bag) and may turn in the pocket,
so :func:`vertical_acceleration` projects every sample on the *low-passed* gravity direction at that
instant (ALGORITHMS.md C2, "the projection on the low-passed gravity direction") instead of relying
on one fixed ``R_mount``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.signal import butter, sosfiltfilt

__all__ = [
    "G_MPS2",
    "ImuCalibration",
    "calibrate_imu",
    "check_imu",
    "detect_still_period",
    "gravity_to_level",
    "gyro_glitches",
    "level_imu",
    "resample_uniform",
    "vertical_acceleration",
]

log = logging.getLogger(__name__)

G_MPS2 = 9.81
"""Nominal gravity, m/s^2 (ALGORITHMS.md C1 / C2)."""


# ---- validation at the edge ----------------------------------------------------------------------


def check_imu(t_ns: Any, accel_mps2: Any, gyro_radps: Any = None, *,
              min_duration_s: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Validate an IMU stream once, at the edge; returns clean arrays.

    Parameters
    ----------
    t_ns : (n,) int
        Sample times in integer nanoseconds, non-decreasing (repeated stamps are allowed: phones
        produce them).
    accel_mps2 : (n, 3) float
        Specific force in the phone frame, m/s^2, every value finite.
    gyro_radps : (n, 3) float, optional
        Angular rate, rad/s. ``None`` or all ``NaN`` means "no gyroscope" (returned as ``None``);
        a gyro that is ``NaN`` only in places is an error.
    min_duration_s : float
        The stream must span at least this long.

    Returns
    -------
    t_ns : (n,) int64
    accel_mps2 : (n, 3) float64
    gyro_radps : (n, 3) float64 or None

    Raises
    ------
    ValueError
        Naming the parameter and the first bad sample.
    """
    t = np.asarray(t_ns)
    if t.ndim != 1 or not np.issubdtype(t.dtype, np.integer):
        raise ValueError(f"t_ns: expected a (n,) array of integer nanoseconds, got {t.dtype} {t.shape}")
    t = t.astype(np.int64)
    if t.size < 2:
        raise ValueError(f"t_ns: expected at least 2 samples, got {t.size}")
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise ValueError(f"t_ns: time goes backwards at sample {i} ({int(t[i])} ns after {int(t[i - 1])} ns); "
                         "expected non-decreasing times")
    duration_s = (int(t[-1]) - int(t[0])) * 1e-9
    if duration_s <= 0.0 or duration_s < min_duration_s:
        raise ValueError(f"t_ns: the stream spans {duration_s:.3f} s, too short (need at least "
                         f"{max(min_duration_s, 1e-9):.3g} s)")
    accel = np.asarray(accel_mps2, dtype=np.float64)
    if accel.shape != (t.size, 3):
        raise ValueError(f"accel_mps2: expected shape ({t.size}, 3) to match t_ns, got {accel.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(accel), axis=1))
    if bad.size:
        raise ValueError(f"accel_mps2: sample {int(bad[0])} is not finite ({accel[bad[0]].tolist()}); "
                         f"{bad.size} bad sample(s) in all")
    gyro = None
    if gyro_radps is not None:
        gyro = np.asarray(gyro_radps, dtype=np.float64)
        if gyro.shape != (t.size, 3):
            raise ValueError(f"gyro_radps: expected shape ({t.size}, 3) to match t_ns, got {gyro.shape}")
        finite = np.isfinite(gyro)
        if not finite.any():
            gyro = None
        elif not finite.all():
            bad = np.flatnonzero(~np.all(finite, axis=1))
            raise ValueError(f"gyro_radps: sample {int(bad[0])} is not finite ({gyro[bad[0]].tolist()}); expected "
                             "all finite, or all NaN for a device without a gyroscope")
    return t, accel, gyro


def gyro_glitches(gyro_radps: np.ndarray) -> np.ndarray | None:
    """The one rule for a gyroscope that is non-finite in places (the CSV reader and the recordings' IMU streams):
    the rows to drop, ``(n,)`` bool, when they are at most half (a few glitches cost their samples), or ``None``
    when the gyroscope is missing from most rows and is better not used at all (the attitude then comes from the
    accelerometer alone, rather than most steps being lost). All finite, or all non-finite: no row to drop."""
    bad = ~np.isfinite(gyro_radps).all(axis=1)
    n_bad = int(np.count_nonzero(bad))
    if n_bad == 0 or n_bad == bad.size:
        return np.zeros(bad.size, dtype=bool)
    return bad if n_bad <= bad.size // 2 else None


# ---- uniform sampling ----------------------------------------------------------------------------


def resample_uniform(t_ns: np.ndarray, x: np.ndarray, rate_hz: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of samples onto a uniform time grid (filters assume one).

    Samples with the same stamp are averaged first. Gaps are bridged linearly.

    Parameters
    ----------
    t_ns : (n,) int64
        Non-decreasing sample times (checked by :func:`check_imu`).
    x : (n, d) float
        Values.
    rate_hz : float, optional
        Grid rate; by default the median sampling rate of ``t_ns``.

    Returns
    -------
    grid_ns : (m,) int64
        ``t_ns[0] + k / rate_hz``, up to ``t_ns[-1]``.
    x_grid : (m, d) float64
    """
    x = np.asarray(x, dtype=np.float64)
    t_u, inverse, counts = np.unique(t_ns, return_inverse=True, return_counts=True)
    if t_u.size < 2:
        raise ValueError("t_ns: need at least two distinct sample times")
    if t_u.size != t_ns.size:
        sums = np.zeros((t_u.size, x.shape[1]))
        np.add.at(sums, inverse, x)
        x = sums / counts[:, None]
    if rate_hz is None:
        rate_hz = 1e9 / float(np.median(np.diff(t_u)))
    if not np.isfinite(rate_hz) or rate_hz <= 0:
        raise ValueError(f"rate_hz: expected a finite rate > 0, got {rate_hz!r}")
    rel = (t_u - t_u[0]).astype(np.float64)
    step_ns = 1e9 / rate_hz
    grid_rel = np.arange(int(np.floor(rel[-1] / step_ns)) + 1) * step_ns
    x_grid = np.stack([np.interp(grid_rel, rel, x[:, j]) for j in range(x.shape[1])], axis=1)
    return t_u[0] + np.round(grid_rel).astype(np.int64), x_grid


def _sample_rate_hz(grid_ns: np.ndarray) -> float:
    return 1e9 / float(grid_ns[1] - grid_ns[0]) if grid_ns.size > 1 else float("nan")


def _lowpass(x: np.ndarray, cutoff_hz: float, rate_hz: float, order: int) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0 (``sosfiltfilt``); the input must be long enough."""
    if not 0 < cutoff_hz < rate_hz / 2:
        raise ValueError(f"cutoff_hz: expected 0 < cutoff < {rate_hz / 2:g} Hz (Nyquist), got {cutoff_hz!r}")
    sos = butter(order, cutoff_hz / (rate_hz / 2), output="sos")
    padlen = 3 * (2 * sos.shape[0] + 1)  # sosfiltfilt's default
    if x.shape[0] <= padlen:
        raise ValueError(f"t_ns: {x.shape[0]} samples on the {rate_hz:.4g} Hz grid are too few to filter "
                         f"(need more than {padlen})")
    return sosfiltfilt(sos, x, axis=0)


# ---- gravity and the vertical axis ---------------------------------------------------------------


def gravity_to_level(gravity_phone: Any) -> np.ndarray:
    """``R_mount`` (3, 3): the smallest rotation taking the gravity reaction direction to +z.

    ALGORITHMS.md C1: "rotate so that ḡ maps to (0, 0, |g|); yaw about z is unobservable, so fix it"
    -- here fixed by taking the minimal rotation (no twist about the vertical), which is defined for
    every orientation, including the near-vertical phone in a pocket where roll/pitch angles are not.

    Parameters
    ----------
    gravity_phone : (3,) float
        Mean accelerometer reading at rest (specific force, pointing up), in the phone frame.

    Returns
    -------
    (3, 3) float64
        ``v_level = R_mount @ v_phone``.
    """
    g = np.asarray(gravity_phone, dtype=np.float64).reshape(-1)
    norm = float(np.linalg.norm(g)) if g.shape == (3,) and np.all(np.isfinite(g)) else 0.0
    if norm < 1e-6:
        raise ValueError(f"gravity_phone: expected a finite non-zero 3-vector, got {gravity_phone!r}")
    u = g / norm
    z = np.array([0.0, 0.0, 1.0])
    c = float(u @ z)
    if c < -1.0 + 1e-12:  # upside down: half a turn about x
        return np.diag([1.0, -1.0, -1.0])
    v = np.cross(u, z)
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)  # Rodrigues for unit vectors u -> z


def vertical_acceleration(t_ns: np.ndarray, accel_mps2: np.ndarray, *, gravity_cutoff_hz: float = 0.5,
                          rate_hz: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Acceleration along the local gravity direction, on a uniform grid (ALGORITHMS.md C2 signal).

    The gravity direction is the zero-phase low-passed accelerometer (2nd-order Butterworth at
    ``gravity_cutoff_hz``), so the projection follows a phone that turns slowly in a hand or a bag.

    Parameters
    ----------
    t_ns : (n,) int64
        Non-decreasing sample times.
    accel_mps2 : (n, 3) float
        Specific force in the phone frame.
    gravity_cutoff_hz : float
        Cut-off of the gravity estimate, Hz (well below the step rate of ~2 Hz).
    rate_hz : float, optional
        Grid rate; by default the median sampling rate.

    Returns
    -------
    grid_ns : (m,) int64
        Uniform grid times.
    a_v_mps2 : (m,) float64
        Specific force along the up direction (about ``g`` at rest).
    g_mps2 : (m,) float64
        Magnitude of the low-passed gravity estimate (subtract it for the dynamic part).
    """
    grid_ns, a = resample_uniform(t_ns, accel_mps2, rate_hz)
    fs = _sample_rate_hz(grid_ns)
    g = _lowpass(a, gravity_cutoff_hz, fs, order=2)
    g_norm = np.linalg.norm(g, axis=1)
    up = g / np.maximum(g_norm, 1e-9)[:, None]
    return grid_ns, np.einsum("ij,ij->i", a, up), g_norm


# ---- still period and calibration ----------------------------------------------------------------


def _moving_std(x: np.ndarray, w: int) -> np.ndarray:
    """Std over a centred window of ``w`` samples (shrinking at the ends); ``x`` (n,) or (n, d) -> (n,)."""
    x = x.reshape(x.shape[0], -1)
    c1 = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    c2 = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x * x, axis=0)])
    n = x.shape[0]
    lo = np.clip(np.arange(n) - w // 2, 0, n)
    hi = np.clip(np.arange(n) + (w - w // 2), 0, n)
    cnt = (hi - lo)[:, None]
    mean = (c1[hi] - c1[lo]) / cnt
    var = np.maximum((c2[hi] - c2[lo]) / cnt - mean**2, 0.0)
    return np.sqrt(var.sum(axis=1))


def detect_still_period(t_ns: Any, accel_mps2: Any, gyro_radps: Any = None, *, window_s: float = 0.5,
                        accel_std_max_mps2: float = 0.25, gyro_std_max_radps: float = 0.05,
                        min_duration_s: float = 1.0) -> tuple[int, int] | None:
    """The still period at the start of a stream, as a sample slice ``(i0, i1)``, or ``None``.

    A sample is still when, over a centred window of ``window_s``, the accelerometer (all axes
    together) varies by less than ``accel_std_max_mps2`` and the gyro by less than
    ``gyro_std_max_radps`` (a std, so an unknown constant bias does not matter). The still period is
    the first run of still samples that starts within the first two seconds and lasts at least
    ``min_duration_s``. ALGORITHMS.md C1 asks for >= 10 s; a shorter period is used but logged.

    Returns
    -------
    (i0, i1) or None
        Sample indices, ``accel_mps2[i0:i1]`` is still.
    """
    t, accel, gyro = check_imu(t_ns, accel_mps2, gyro_radps)
    for name, value in (("window_s", window_s), ("accel_std_max_mps2", accel_std_max_mps2),
                        ("gyro_std_max_radps", gyro_std_max_radps), ("min_duration_s", min_duration_s)):
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"{name}: expected a finite value > 0, got {value!r}")
    dt_ns = float(np.median(np.diff(t))) or 1.0
    w = max(3, round(window_s * 1e9 / dt_ns))
    still = _moving_std(accel, w) < accel_std_max_mps2
    if gyro is not None:
        still &= _moving_std(gyro, w) < gyro_std_max_radps
    if not still.any():
        return None
    i0 = int(np.argmax(still))
    if (int(t[i0]) - int(t[0])) * 1e-9 > 2.0:
        return None
    moving = np.flatnonzero(~still[i0:])
    i1 = i0 + int(moving[0]) if moving.size else t.size
    # the window straddles the start of walking: back off half a window
    i1 = max(i0 + 1, i1 - w // 2) if i1 < t.size else i1
    if (int(t[i1 - 1]) - int(t[i0])) * 1e-9 < min_duration_s:
        return None
    return i0, i1


@dataclass(frozen=True, slots=True, eq=False)
class ImuCalibration:
    """What a still period tells about a phone IMU (ALGORITHMS.md C1).

    Attributes
    ----------
    gravity_phone_mps2 : (3,) float64
        Mean accelerometer at rest, phone frame (accelerometer bias is not separable from gravity
        with one orientation, so it is inside this vector).
    R_mount : (3, 3) float64
        Phone frame -> level frame (z up, yaw 0): :func:`gravity_to_level` of ``gravity_phone_mps2``.
    gyro_bias_radps : (3,) float64
        Mean gyro over the still period; zeros when there is no still period or no gyro.
    gyro_noise_radps : (3,) float64
        Per-axis std of the gyro over the still period; ``NaN`` when unknown.
    accel_noise_mps2 : (3,) float64
        Per-axis std of the accelerometer over the still period; ``NaN`` when unknown.
    still_ns : (2,) int64 or None
        ``(start, end)`` of the still period used; ``None`` when there was none (then gravity is the
        mean accelerometer over the whole stream and the gyro bias is zero).
    """

    gravity_phone_mps2: np.ndarray
    R_mount: np.ndarray
    gyro_bias_radps: np.ndarray
    gyro_noise_radps: np.ndarray
    accel_noise_mps2: np.ndarray
    still_ns: tuple[int, int] | None

    @property
    def g_mps2(self) -> float:
        """Measured gravity magnitude, m/s^2."""
        return float(np.linalg.norm(self.gravity_phone_mps2))


def calibrate_imu(t_ns: Any, accel_mps2: Any, gyro_radps: Any = None, *,
                  still: tuple[int, int] | str | None = "auto", min_still_s: float = 10.0) -> ImuCalibration:
    """Gyro bias, noise and mounting rotation from a still period (ALGORITHMS.md C1).

    Parameters
    ----------
    t_ns : (n,) int
        Sample times, ns, non-decreasing.
    accel_mps2 : (n, 3) float
        Specific force, phone frame, m/s^2.
    gyro_radps : (n, 3) float, optional
        Angular rate, phone frame, rad/s (``None`` / all ``NaN``: no gyroscope).
    still : "auto", (start_ns, end_ns) or None
        ``"auto"``: :func:`detect_still_period`; a pair: the still period's times; ``None``: no still
        period (gravity from the whole stream, zero gyro bias).
    min_still_s : float
        ALGORITHMS.md C1's minimum still time (10 s); a shorter still period is still used, with a
        warning, because some bias estimate beats none.

    Returns
    -------
    ImuCalibration
    """
    t, accel, gyro = check_imu(t_ns, accel_mps2, gyro_radps)
    nan3 = np.full(3, np.nan)
    if isinstance(still, str):
        if still != "auto":
            raise ValueError(f"still: expected 'auto', (start_ns, end_ns) or None, got {still!r}")
        sl = detect_still_period(t, accel, gyro)
    elif still is None:
        sl = None
    else:
        try:
            start_ns, end_ns = (int(v) for v in still)
        except (TypeError, ValueError) as err:
            raise ValueError(f"still: expected 'auto', (start_ns, end_ns) or None, got {still!r}") from err
        i0, i1 = int(np.searchsorted(t, start_ns, "left")), int(np.searchsorted(t, end_ns, "right"))
        if i1 - i0 < 2:
            raise ValueError(f"still: ({start_ns}, {end_ns}) holds {max(i1 - i0, 0)} samples; expected at least 2 "
                             f"within the stream [{int(t[0])}, {int(t[-1])}] ns")
        sl = (i0, i1)
    if sl is None:
        # no still period: the mean over whole strides is still gravity (the step pattern has zero mean)
        log.warning("no still period at the start of the IMU stream: gravity from the whole stream, gyro bias "
                    "not estimated (it needs the phone kept still for >= %.0f s at the start)", min_still_s)
        gravity = accel.mean(axis=0)
        return ImuCalibration(gravity, gravity_to_level(gravity), np.zeros(3), nan3, nan3, None)
    i0, i1 = sl
    seconds = (int(t[i1 - 1]) - int(t[i0])) * 1e-9
    if seconds < min_still_s:
        log.warning("still period of only %.1f s (a reliable estimate needs the phone kept still for >= %.0f s): "
                    "gravity, gyro bias and noise are rough", seconds, min_still_s)
    gravity = accel[i0:i1].mean(axis=0)
    accel_noise = accel[i0:i1].std(axis=0)
    if gyro is None:
        bias, gyro_noise = np.zeros(3), nan3
    else:
        bias, gyro_noise = gyro[i0:i1].mean(axis=0), gyro[i0:i1].std(axis=0)
    return ImuCalibration(gravity, gravity_to_level(gravity), bias, gyro_noise, accel_noise,
                          (int(t[i0]), int(t[i1 - 1])))


def level_imu(accel_mps2: Any, gyro_radps: Any, calibration: ImuCalibration) -> tuple[np.ndarray, np.ndarray | None]:
    """Rotate samples into the level frame and remove the gyro bias (ALGORITHMS.md C1, "all later
    samples are rotated by ``R_mount``").

    Parameters
    ----------
    accel_mps2 : (n, 3) float
    gyro_radps : (n, 3) float or None
    calibration : ImuCalibration

    Returns
    -------
    accel_level : (n, 3) float64
        ``R_mount @ a``; about ``(0, 0, g)`` at rest.
    gyro_level : (n, 3) float64 or None
        ``R_mount @ (ω - bias)``.
    """
    R = calibration.R_mount
    accel = np.asarray(accel_mps2, dtype=np.float64) @ R.T
    if gyro_radps is None:
        return accel, None
    return accel, (np.asarray(gyro_radps, dtype=np.float64) - calibration.gyro_bias_radps) @ R.T
