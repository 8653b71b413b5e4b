"""Phone IMU: the accelerometer and gyroscope of a phone carried by a walker (issue 3; ALGORITHMS.md C1, C2, C4).

Model, in the walker's **body frame** (x forward along the heading, y left, z up; the body does not
tilt):

- **Horizontal acceleration** from the change of the walker's world velocity (the agents' motion),
  rotated by ``-heading``: a turn at constant speed shows the centripetal ``v * yaw_rate`` along +y.
- **Yaw rate** ``d(heading)/dt`` of the unwrapped heading, about body z; roll and pitch rates are 0.
- **Vertical step pattern** (ALGORITHMS.md C2: the z component is periodic and the most significant).
  With φ the gait phase of :class:`~fusiontrack.sim.model.AgentSnapshot` (right heel strike at φ ≡ 0,
  left at φ ≡ π, +2π per stride)::

      a_z = A(v) * (cos 2φ + B * cos 4φ),     A(v) = step_accel_mps2 * clip(v / V_REF_MPS, 0, A_SCALE_MAX)

  which peaks at every heel strike (twice per gait cycle), with a sharper peak and a flatter
  mid-stance trough than a pure cosine (as in recorded gait) and no extra local maximum
  (``B = 0.2 < 1/4``). The amplitude grows with the walking speed and is 0 when standing.
- **Lateral sway** at the gait frequency: the body moves over the stance leg (leftmost in mid left
  stance, φ ≈ 3π/2), i.e. a displacement ``-h sin φ`` and an acceleration ``a_y = SWAY * A(v) * sin φ``.

Both gait terms integrate consistently: with the phase advancing at ``dφ/dt = 2π v / S`` and an
amplitude proportional to ``v`` (below the cap), ``A / (dφ/dt)`` is constant, so the vertical velocity
is exactly ``(A / φ')(sin 2φ / 2 + B sin 4φ / 4)`` and the lateral one ``-(SWAY A / φ')cos φ``: bounded
and zero-mean whatever the speed profile (a stop-and-go walk does not make the bounce drift). With
``step_accel_mps2 = 2.5`` at 1.3 m/s and S = 1.4 m the bounce is ±1.8 cm, the sway ±1.5 cm. The gait
terms are not in the agents' positions (they are the trunk's oscillation about the planned path).

The body-frame specific force is ``f_body = a_body + (0, 0, g)`` (gravity reaction, as phones report
it). The phone's **mounting rotation** ``R_mount = rpy_to_matrix(*spec.mount_rpy_rad)`` =
``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (ZYX roll-pitch-yaw, :func:`fusiontrack.geometry.rpy_to_matrix`)
maps phone axes into body axes, ``v_body = R_mount @ v_phone``, so the phone measures::

    v_phone = R_mount.T @ v_body

for the specific force and the angular rate alike (ALGORITHMS.md C1 estimates ``R_mount`` back from
the still-period mean of the accelerometer). Then constant biases (``spec.accel_bias_mps2``,
``spec.gyro_bias_radps``, phone frame) and white Gaussian noise (``spec.accel_noise_mps2``,
``spec.gyro_noise_radps`` per axis and sample) are added.

:func:`simulate_imu` is the vectorised pure function; :class:`PhoneImuSim` keeps the previous state
of the carrier and produces one :class:`~fusiontrack.types.ImuSample` per call from successive
snapshots. Noise is drawn as one ``(6,)`` standard-normal row per sample (accel then gyro), so a
generator gives the same noise sample by sample as in one batch.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..geometry import rpy_to_matrix
from ..types import ImuSample
from .model import AgentSnapshot, ImuSpec

__all__ = [
    "A_SCALE_MAX",
    "G_MPS2",
    "HARMONIC",
    "SWAY",
    "V_REF_MPS",
    "PhoneImuSim",
    "body_imu",
    "heel_strike_times",
    "mount_matrix",
    "simulate_imu",
    "true_imu",
]

G_MPS2 = 9.81
"""Gravity, m/s^2 (the value ALGORITHMS.md C1 / C2 use)."""

V_REF_MPS = 1.3
"""Walking speed at which the vertical step pattern has amplitude ``spec.step_accel_mps2``."""

A_SCALE_MAX = 1.6
"""Cap on ``v / V_REF_MPS`` (a jogging walker does not bounce without bound)."""

HARMONIC = 0.2
"""Relative amplitude ``B`` of the ``cos 4φ`` harmonic of the vertical pattern (< 1/4: one peak per step)."""

SWAY = 0.2
"""Lateral sway acceleration amplitude relative to the vertical step amplitude ``A(v)``."""


def mount_matrix(mount_rpy_rad: Any) -> np.ndarray:
    """``R_mount`` ``(3, 3)``: maps phone axes into body axes (``v_body = R_mount @ v_phone``).

    Parameters
    ----------
    mount_rpy_rad : (3,) float
        ``(roll, pitch, yaw)`` of the phone in the body frame, ZYX: ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
    """
    rpy = np.asarray(mount_rpy_rad, dtype=np.float64).reshape(-1)
    if rpy.shape != (3,) or not np.all(np.isfinite(rpy)):
        raise ValueError(f"mount_rpy_rad: expected three finite angles (roll, pitch, yaw), got {mount_rpy_rad!r}")
    return rpy_to_matrix(float(rpy[0]), float(rpy[1]), float(rpy[2]))


def heel_strike_times(t_ns: Any, gait_phase_rad: Any) -> tuple[np.ndarray, np.ndarray]:
    """Heel strikes of a walker: the instants its (unwrapped) gait phase crosses a multiple of π.

    Right heel strike at φ ≡ 0, left at φ ≡ π (:class:`~fusiontrack.sim.model.AgentSnapshot`); the
    crossing instant is interpolated linearly between samples. A phase that stands still or runs
    backwards gives no strike.

    Parameters
    ----------
    t_ns : (m,) int
        Sample times, strictly increasing.
    gait_phase_rad : (m,) float
        Gait phase (wrapped or not; it is unwrapped here, so samples must be dense enough that the
        phase advances by less than π between two of them).

    Returns
    -------
    strike_t_ns : (k,) int64
        Times of the strikes.
    foot : (k,) int64
        0 = left (φ ≡ π), 1 = right (φ ≡ 0), as in :class:`~fusiontrack.sim.model.StepEvent`.
    """
    t = _times(t_ns, "t_ns")
    phase = np.unwrap(_vector(gait_phase_rad, t.size, "gait_phase_rad"))
    k = np.floor(phase / np.pi).astype(np.int64)
    # the running maximum ignores a phase that steps back, so a strike is never counted twice
    k = np.maximum.accumulate(k)
    n_new = np.diff(k)
    seg = np.repeat(np.arange(n_new.size), n_new)  # interval index of each crossing
    if seg.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    rank = np.arange(seg.size) - (np.cumsum(n_new) - n_new)[seg]  # 0, 1, ... within an interval
    multiple = k[seg] + 1 + rank  # the multiple of π crossed
    p0, p1 = phase[seg], phase[seg + 1]
    frac = np.clip((multiple * np.pi - p0) / np.where(p1 > p0, p1 - p0, 1.0), 0.0, 1.0)
    strike = t[seg] + np.round(frac * (t[seg + 1] - t[seg])).astype(np.int64)
    foot = np.where(multiple % 2 == 0, 1, 0).astype(np.int64)
    return strike, foot


def body_imu(t_ns: Any, position_m: Any, heading_rad: Any, gait_phase_rad: Any, speed_mps: Any,
             step_accel_mps2: float, *, velocity_mps: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Ideal specific force and angular rate in the walker's body frame (x forward, y left, z up).

    Derivatives are :func:`numpy.gradient` over the given samples (central inside, one-sided at the
    ends); a single sample has zero horizontal acceleration and yaw rate.

    Parameters
    ----------
    t_ns : (m,) int
        Strictly increasing sample times.
    position_m : (m, 2) float
        World position of the walker (only used when ``velocity_mps`` is not given).
    heading_rad : (m,) float
        Heading (wrapped or not; unwrapped here).
    gait_phase_rad : (m,) float
        Gait phase φ (right heel strike at 0, left at π).
    speed_mps : (m,) float
        Walking speed that scales the step pattern (0 = standing: no pattern).
    step_accel_mps2 : float
        Step pattern amplitude at :data:`V_REF_MPS`.
    velocity_mps : (m, 2) float, optional
        World velocity; differentiated once for the acceleration (else ``position_m`` twice).

    Returns
    -------
    accel_body : (m, 3) float64
        Specific force, m/s^2 (gravity reaction ``+g`` on z included).
    gyro_body : (m, 3) float64
        Angular rate, rad/s.
    """
    t = _times(t_ns, "t_ns")
    m = t.size
    t_s = (t - t[0]) * 1e-9
    pos = _array(position_m, (m, 2), "position_m")
    heading = np.unwrap(_vector(heading_rad, m, "heading_rad"))
    phase = _vector(gait_phase_rad, m, "gait_phase_rad")
    speed = _vector(speed_mps, m, "speed_mps")
    if not np.isfinite(step_accel_mps2) or step_accel_mps2 < 0:
        raise ValueError(f"step_accel_mps2: expected a finite value >= 0, got {step_accel_mps2!r}")

    if m >= 2:
        vel = np.gradient(pos, t_s, axis=0) if velocity_mps is None else _array(velocity_mps, (m, 2), "velocity_mps")
        acc_world = np.gradient(vel, t_s, axis=0)
        yaw_rate = np.gradient(heading, t_s)
    else:
        acc_world = np.zeros((m, 2))
        yaw_rate = np.zeros(m)
    c, s = np.cos(heading), np.sin(heading)
    ax = c * acc_world[:, 0] + s * acc_world[:, 1]
    ay = -s * acc_world[:, 0] + c * acc_world[:, 1]

    # seed 002's vertical step pattern; ALGORITHMS.md C2 (peaks at heel strikes φ ≡ 0, π)
    amp = step_accel_mps2 * np.clip(np.abs(speed) / V_REF_MPS, 0.0, A_SCALE_MAX)
    az = amp * (np.cos(2 * phase) + HARMONIC * np.cos(4 * phase))
    sway = SWAY * amp * np.sin(phase)

    accel = np.stack([ax, ay + sway, G_MPS2 + az], axis=1)
    gyro = np.stack([np.zeros(m), np.zeros(m), yaw_rate], axis=1)
    return accel, gyro


def true_imu(spec: ImuSpec, t_ns: Any, position_m: Any, heading_rad: Any, gait_phase_rad: Any, speed_mps: Any,
             *, velocity_mps: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Ideal phone readings (no bias, no noise): :func:`body_imu` rotated into the phone frame.

    Same parameters as :func:`simulate_imu` without ``rng``; returns ``accel (m, 3)`` m/s^2 and
    ``gyro (m, 3)`` rad/s in the phone frame, ``v_phone = R_mount.T @ v_body``.
    """
    accel_body, gyro_body = body_imu(t_ns, position_m, heading_rad, gait_phase_rad, speed_mps,
                                     float(spec.step_accel_mps2), velocity_mps=velocity_mps)
    R_mount = mount_matrix(spec.mount_rpy_rad)
    # row vectors: (R.T @ v).T == v.T @ R
    return accel_body @ R_mount, gyro_body @ R_mount


def simulate_imu(spec: ImuSpec, t_ns: Any, position_m: Any, heading_rad: Any, gait_phase_rad: Any, speed_mps: Any,
                 rng: np.random.Generator | int | None, *, velocity_mps: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Phone accelerometer and gyroscope along a walker's trajectory (bias and noise included).

    Parameters
    ----------
    spec : ImuSpec
        Mounting, biases, noises and step amplitude.
    t_ns : (m,) int
        Strictly increasing sample times, ns.
    position_m : (m, 2) float
        World position of the carrier, m.
    heading_rad : (m,) float
        Heading of the carrier (body x axis) in the world, rad.
    gait_phase_rad : (m,) float
        Gait phase φ: right heel strike at φ ≡ 0, left at φ ≡ π, +2π per stride.
    speed_mps : (m,) float
        Walking speed, m/s (scales the step pattern; 0 = standing).
    rng : numpy.random.Generator or int or None
        Noise source, normalised by :func:`numpy.random.default_rng`.
    velocity_mps : (m, 2) float, optional
        World velocity; when given the acceleration is its derivative, else ``position_m``'s second.

    Returns
    -------
    accel : (m, 3) float64
        Specific force in the phone frame, m/s^2 (gravity included).
    gyro : (m, 3) float64
        Angular rate in the phone frame, rad/s.
    """
    accel, gyro = true_imu(spec, t_ns, position_m, heading_rad, gait_phase_rad, speed_mps, velocity_mps=velocity_mps)
    return _add_errors(spec, accel, gyro, np.random.default_rng(rng))


class PhoneImuSim:
    """Phone IMU of the person ``spec.carrier_id``: one :class:`~fusiontrack.types.ImuSample` per call.

    Keeps the carrier's previous time, velocity and heading so that :meth:`sample` differentiates
    them (backward differences); forgets them when the carrier is absent. Call :meth:`sample` at
    every IMU tick in time order (also where the message will then be dropped, so the differences
    and the noise stream do not depend on the drops).
    """

    def __init__(self, spec: ImuSpec) -> None:
        if not isinstance(spec, ImuSpec):
            raise TypeError(f"spec: expected an ImuSpec, got {type(spec).__name__}")
        for name in ("accel_noise_mps2", "gyro_noise_radps", "step_accel_mps2"):
            value = float(getattr(spec, name))
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"ImuSpec.{name}: expected a finite value >= 0, got {value!r}")
        for name in ("accel_bias_mps2", "gyro_bias_radps"):
            value = np.asarray(getattr(spec, name), dtype=np.float64)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise ValueError(f"ImuSpec.{name}: expected three finite values, got {getattr(spec, name)!r}")
        mount_matrix(spec.mount_rpy_rad)  # validates
        self._spec = spec
        self._prev: tuple[int, np.ndarray, np.ndarray, float, float, float] | None = None

    @property
    def spec(self) -> ImuSpec:
        return self._spec

    def reset(self) -> None:
        """Forget the previous state (the next sample has zero horizontal acceleration and yaw rate)."""
        self._prev = None

    def sample(self, t_ns: int, snapshot: AgentSnapshot, rng: np.random.Generator | int | None,
               stamp_ns: int | None = None) -> ImuSample | None:
        """The phone's reading at true time ``t_ns``, or ``None`` when the carrier is not in ``snapshot``.

        Parameters
        ----------
        t_ns : int
            True time of the sample (later than the previous call's).
        snapshot : AgentSnapshot
            The agents at ``t_ns``.
        rng : numpy.random.Generator or int or None
            Noise source; pass the same Generator on every call (an int would repeat the same noise).
        stamp_ns : int, optional
            Header stamp to write (true time + clock offset + jitter); defaults to ``t_ns``.
        """
        t_ns = int(t_ns)
        idx = np.flatnonzero(np.asarray(snapshot.ids) == self._spec.carrier_id)
        if idx.size == 0:
            self._prev = None
            return None
        i = int(idx[0])
        pos = np.asarray(snapshot.position_m[i], dtype=np.float64)
        vel = np.asarray(snapshot.velocity_mps[i], dtype=np.float64)
        heading = float(snapshot.heading_rad[i])
        phase = float(snapshot.gait_phase_rad[i])
        speed = float(np.hypot(vel[0], vel[1]))
        now = (t_ns, pos, vel, heading, phase, speed)
        if self._prev is not None and t_ns <= self._prev[0]:
            raise ValueError(f"t_ns: samples must be in increasing time order, got {t_ns} after {self._prev[0]}")
        rows = [now] if self._prev is None else [self._prev, now]
        accel, gyro = true_imu(
            self._spec,
            np.array([r[0] for r in rows], dtype=np.int64),
            np.array([r[1] for r in rows]),
            np.array([r[3] for r in rows]),
            np.array([r[4] for r in rows]),
            np.array([r[5] for r in rows]),
            velocity_mps=np.array([r[2] for r in rows]),
        )
        self._prev = now
        accel, gyro = _add_errors(self._spec, accel[-1:], gyro[-1:], np.random.default_rng(rng))
        return ImuSample(t_ns=t_ns if stamp_ns is None else int(stamp_ns), sensor=self._spec.name,
                         frame_id=self._spec.name, accel_mps2=accel[0], gyro_radps=gyro[0])


# ---- helpers -------------------------------------------------------------------------------------


def _add_errors(spec: ImuSpec, accel: np.ndarray, gyro: np.ndarray,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    noise = rng.standard_normal((accel.shape[0], 6))
    accel = accel + np.asarray(spec.accel_bias_mps2, np.float64) + float(spec.accel_noise_mps2) * noise[:, :3]
    gyro = gyro + np.asarray(spec.gyro_bias_radps, np.float64) + float(spec.gyro_noise_radps) * noise[:, 3:]
    return accel, gyro


def _times(t_ns: Any, name: str) -> np.ndarray:
    t = np.asarray(t_ns)
    if t.ndim != 1 or t.size == 0 or not np.issubdtype(t.dtype, np.integer):
        raise ValueError(f"{name}: expected a non-empty (m,) array of integer nanoseconds, got {t.dtype} {t.shape}")
    t = t.astype(np.int64)
    if np.any(np.diff(t) <= 0):
        raise ValueError(f"{name}: times must be strictly increasing")
    return t


def _vector(value: Any, m: int, name: str) -> np.ndarray:
    return _array(value, (m,), name)


def _array(value: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected finite values")
    return arr
