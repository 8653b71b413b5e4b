"""Attitude and yaw from the gyroscope (seed 002 Eq. 1; ALGORITHMS.md C4, erratum E1).

Seed 002, section 2.1.3: ``Ψ_{k+1} = Ψ_k + E_b2n,k · (ω̃_b,k − ω̂_b,k^bias) · Δt`` with Ψ = (roll,
pitch, yaw). The paper prints the (3,3) entry of ``E_b2n`` as ``cos θ · cos φ``; the Euler-rate matrix
of the ZYX convention has ``cos(roll) / cos(pitch)`` there (ALGORITHMS.md E1), which is what
:func:`euler_rate_matrix` returns. Roll and pitch drift is pulled towards the accelerometer tilt by a
complementary filter (C4, RECON); yaw is not corrected (no magnetometer) and is kept unwrapped.

:func:`integrate_attitude` is sequential by nature (each step's matrix depends on the previous roll
and pitch), so it is a tight loop on Python floats. When roll and pitch are known at every sample
(e.g. the phone was levelled by :func:`~fusiontrack.inertial.preprocess.level_imu`, or they come from
the accelerometer tilt), :func:`integrate_yaw` integrates the yaw row of Eq. 1 in one vectorised pass.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["accel_tilt", "euler_rate_matrix", "integrate_attitude", "integrate_yaw"]

_QUAT_SWITCH_RAD = math.radians(80.0)


def euler_rate_matrix(roll_rad: Any, pitch_rad: Any) -> np.ndarray:
    """``E_b2n``: body angular rate -> (roll, pitch, yaw) rates, ZYX Euler angles (ALGORITHMS.md C4).

    Uses the corrected (3,3) entry ``cos(roll)/cos(pitch)`` (ALGORITHMS.md E1; the seed prints
    ``cos θ·cos φ``).

    Parameters
    ----------
    roll_rad, pitch_rad : float or (...,) float
        Broadcast together.

    Returns
    -------
    (..., 3, 3) float64
    """
    r = np.asarray(roll_rad, dtype=np.float64)
    p = np.asarray(pitch_rad, dtype=np.float64)
    r, p = np.broadcast_arrays(r, p)
    sr, cr, tp, cp = np.sin(r), np.cos(r), np.tan(p), np.cos(p)
    zero, one = np.zeros_like(r), np.ones_like(r)
    return np.stack([
        np.stack([one, sr * tp, cr * tp], axis=-1),
        np.stack([zero, cr, -sr], axis=-1),
        np.stack([zero, sr / cp, cr / cp], axis=-1),
    ], axis=-2)


def accel_tilt(accel_mps2: Any) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch from the gravity reaction (ALGORITHMS.md C4 complementary filter).

    ``roll = atan2(a_y, a_z)``, ``pitch = atan2(−a_x, sqrt(a_y² + a_z²))``.

    Parameters
    ----------
    accel_mps2 : (n, 3) float

    Returns
    -------
    roll_rad, pitch_rad : (n,) float64
    """
    a = np.asarray(accel_mps2, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"accel_mps2: expected shape (n, 3), got {a.shape}")
    return np.arctan2(a[:, 1], a[:, 2]), np.arctan2(-a[:, 0], np.hypot(a[:, 1], a[:, 2]))


def _dt_s(t_ns: Any, n: int) -> np.ndarray:
    t = np.asarray(t_ns)
    if t.ndim != 1 or t.size != n or not np.issubdtype(t.dtype, np.integer):
        raise ValueError(f"t_ns: expected ({n},) integer nanoseconds, got {t.dtype} {t.shape}")
    dt = np.diff(t.astype(np.int64)) * 1e-9
    if np.any(dt < 0):
        raise ValueError(f"t_ns: time goes backwards at sample {int(np.flatnonzero(dt < 0)[0]) + 1}")
    return dt


def _rates(gyro_radps: Any, gyro_bias_radps: Any) -> np.ndarray:
    w = np.asarray(gyro_radps, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != 3 or w.shape[0] < 1:
        raise ValueError(f"gyro_radps: expected shape (n, 3), got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError(f"gyro_radps: sample {int(np.flatnonzero(~np.isfinite(w).all(1))[0])} is not finite")
    b = np.zeros(3) if gyro_bias_radps is None else np.asarray(gyro_bias_radps, dtype=np.float64)
    if b.shape != (3,) or not np.all(np.isfinite(b)):
        raise ValueError(f"gyro_bias_radps: expected three finite values, got {gyro_bias_radps!r}")
    return w - b


def integrate_yaw(t_ns: Any, gyro_radps: Any, roll_rad: Any, pitch_rad: Any, *, gyro_bias_radps: Any = None,
                  yaw0_rad: float = 0.0) -> np.ndarray:
    """Yaw from the third row of Eq. 1 when roll and pitch are known at every sample (vectorised).

    ``ψ_{k+1} = ψ_k + [0, sin r/cos p, cos r/cos p]·(ω_k − b)·Δt_k`` (forward Euler, as Eq. 1).

    Parameters
    ----------
    t_ns : (n,) int
        Sample times, ns, non-decreasing.
    gyro_radps : (n, 3) float
        Body angular rate, rad/s.
    roll_rad, pitch_rad : (n,) float or float
        Attitude at each sample.
    gyro_bias_radps : (3,) float, optional
        Subtracted from every sample (ALGORITHMS.md C1).
    yaw0_rad : float
        Yaw at the first sample.

    Returns
    -------
    yaw_rad : (n,) float64
        Unwrapped.
    """
    w = _rates(gyro_radps, gyro_bias_radps)
    dt = _dt_s(t_ns, w.shape[0])
    r = np.broadcast_to(np.asarray(roll_rad, dtype=np.float64), (w.shape[0],))
    p = np.broadcast_to(np.asarray(pitch_rad, dtype=np.float64), (w.shape[0],))
    rate = (np.sin(r) * w[:, 1] + np.cos(r) * w[:, 2]) / np.cos(p)
    return yaw0_rad + np.concatenate([[0.0], np.cumsum(rate[:-1] * dt)])


def integrate_attitude(t_ns: Any, gyro_radps: Any, *, gyro_bias_radps: Any = None,
                       rpy0_rad: Any = (0.0, 0.0, 0.0), accel_mps2: Any = None,
                       tilt_time_constant_s: float = 1.0) -> np.ndarray:
    """Roll, pitch and yaw by seed 002 Eq. 1 with the corrected ``E_b2n`` (ALGORITHMS.md C4).

    ``Ψ_{k+1} = Ψ_k + E_b2n(Ψ_k) · (ω_k − b) · Δt_k``. With ``accel_mps2`` given, roll and pitch are
    then pulled towards the accelerometer tilt, ``r ← r + α·wrap(r_acc − r)`` with
    ``α = Δt / tilt_time_constant_s`` (C4: 0.02 per sample at 50 Hz is a 1 s time constant). While
    ``|pitch| > 80°`` a step is taken on the rotation itself (no Euler singularity) and converted back.

    Parameters
    ----------
    t_ns : (n,) int
        Sample times, ns, non-decreasing.
    gyro_radps : (n, 3) float
        Body angular rate, rad/s.
    gyro_bias_radps : (3,) float, optional
        ALGORITHMS.md C1's bias, subtracted from every sample.
    rpy0_rad : (3,) float
        Initial roll, pitch, yaw.
    accel_mps2 : (n, 3) float, optional
        Specific force in the same body frame, for the tilt correction.
    tilt_time_constant_s : float
        Time constant of the complementary filter, s.

    Returns
    -------
    rpy_rad : (n, 3) float64
        Roll and pitch wrapped to (−π, π], yaw unwrapped (continuous).
    """
    w = _rates(gyro_radps, gyro_bias_radps)
    n = w.shape[0]
    dt = _dt_s(t_ns, n)
    rpy0 = np.asarray(rpy0_rad, dtype=np.float64)
    if rpy0.shape != (3,) or not np.all(np.isfinite(rpy0)):
        raise ValueError(f"rpy0_rad: expected three finite angles, got {rpy0_rad!r}")
    if not np.isfinite(tilt_time_constant_s) or tilt_time_constant_s <= 0:
        raise ValueError(f"tilt_time_constant_s: expected a finite value > 0, got {tilt_time_constant_s!r}")
    if accel_mps2 is not None:
        a = np.asarray(accel_mps2, dtype=np.float64)
        if a.shape != (n, 3) or not np.all(np.isfinite(a)):
            raise ValueError(f"accel_mps2: expected finite values of shape ({n}, 3), got {a.shape}")
        roll_acc, pitch_acc = (x.tolist() for x in accel_tilt(a))
        alpha = np.minimum(dt / tilt_time_constant_s, 1.0).tolist()
    wx, wy, wz = (w[:, j].tolist() for j in range(3))
    dts = dt.tolist()
    out = np.empty((n, 3))
    r, p, y = (float(v) for v in rpy0)
    out[0] = r, p, y
    sin, cos, tan, pi = math.sin, math.cos, math.tan, math.pi
    rows = [None] * n
    for k in range(n - 1):
        h = dts[k]
        if abs(p) < _QUAT_SWITCH_RAD:
            sr, cr, tp, cp = sin(r), cos(r), tan(p), cos(p)
            r, p, y = (r + (wx[k] + sr * tp * wy[k] + cr * tp * wz[k]) * h,
                       p + (cr * wy[k] - sr * wz[k]) * h,
                       y + (sr * wy[k] + cr * wz[k]) / cp * h)
        else:  # ALGORITHMS.md C4 edge case: integrate on the rotation near the singularity
            R = Rotation.from_euler("ZYX", [y, p, r]) * Rotation.from_rotvec([wx[k] * h, wy[k] * h, wz[k] * h])
            y2, p, r = R.as_euler("ZYX")
            y += (y2 - y + pi) % (2 * pi) - pi
        if accel_mps2 is not None:
            r += alpha[k] * ((roll_acc[k + 1] - r + pi) % (2 * pi) - pi)
            p += alpha[k] * ((pitch_acc[k + 1] - p + pi) % (2 * pi) - pi)
        r = (r + pi) % (2 * pi) - pi
        rows[k + 1] = (r, p, y)
    if n > 1:
        out[1:] = rows[1:]
    return out
