"""Phone IMU simulator (sim/imu.py): step pattern, gyro, mounting, biases (ALGORITHMS.md C1, C2, C4)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import butter, filtfilt, find_peaks

from fusiontrack.sim.imu import G_MPS2, PhoneImuSim, heel_strike_times, mount_matrix, simulate_imu
from fusiontrack.sim.model import KIND_PERSON, AgentSnapshot, ImuSpec, Timing
from fusiontrack.types import ImuSample

FS_HZ = 100.0
SPEED = 1.3
STRIDE = 1.4
NO_BIAS = {"accel_bias_mps2": (0.0, 0.0, 0.0), "gyro_bias_radps": (0.0, 0.0, 0.0)}


def _spec(**kw) -> ImuSpec:
    return ImuSpec(name="phone", carrier_id=7, timing=Timing(rate_hz=FS_HZ), **kw)


def _straight_walk(duration_s: float = 60.0, speed: float = SPEED, phase0: float = 0.3):
    t_s = np.arange(round(duration_s * FS_HZ)) / FS_HZ
    t_ns = np.round(t_s * 1e9).astype(np.int64)
    pos = np.stack([speed * t_s, np.zeros_like(t_s)], axis=1)
    heading = np.zeros_like(t_s)
    phase = phase0 + 2 * np.pi * speed * t_s / STRIDE  # 2π per stride walked
    return t_ns, pos, heading, phase, np.full_like(t_s, speed)


def _count_steps(accel_z: np.ndarray) -> tuple[int, np.ndarray]:
    """A plain peak count (ALGORITHMS.md C2): 3 Hz 4th-order low-pass, peaks > g + 1 m/s^2, >= 0.3 s apart."""
    b, a = butter(4, 3.0 / (FS_HZ / 2))
    low = filtfilt(b, a, accel_z)
    peaks, _ = find_peaks(low, height=G_MPS2 + 1.0, distance=int(0.3 * FS_HZ))
    return peaks.size, peaks


def test_peak_count_matches_heel_strikes() -> None:
    t_ns, pos, heading, phase, speed = _straight_walk()
    accel, gyro = simulate_imu(_spec(), t_ns, pos, heading, phase, speed, rng=1)
    assert accel.shape == (t_ns.size, 3)
    assert gyro.shape == (t_ns.size, 3)
    # heel strikes = crossings of φ ≡ 0 (right) and φ ≡ π (left)
    n_strikes = int(np.sum(np.diff(np.floor(phase / np.pi)) > 0))
    assert n_strikes == pytest.approx(60 * SPEED / STRIDE * 2, abs=1)  # ~111 steps in 60 s
    n_peaks, peaks = _count_steps(accel[:, 2])
    assert abs(n_peaks - n_strikes) <= 1
    # and every peak is at a heel strike (zero-phase filter: within two samples)
    strikes_ns, foot = heel_strike_times(t_ns, phase)
    assert strikes_ns.size == n_strikes
    gap_s = np.min(np.abs(t_ns[peaks][:, None] - strikes_ns[None, :]), axis=1) * 1e-9
    assert np.all(gap_s <= 0.02)
    # feet alternate; φ0 = 0.3 rad: the first strike is the left one (φ = π)
    assert foot[0] == 0
    assert np.all(np.diff(foot) != 0)


def test_heel_strike_times_interpolates_crossings() -> None:
    t_ns = np.array([0, 10, 20, 30], dtype=np.int64)
    phase = np.array([-0.5, 0.5, 3.0, 3.5])  # crosses 0 at t = 5, π at t = 20 + 10 * 0.1416 / 0.5
    strikes, foot = heel_strike_times(t_ns, phase)
    np.testing.assert_array_equal(strikes, [5, 23])
    np.testing.assert_array_equal(foot, [1, 0])
    strikes, foot = heel_strike_times(t_ns, np.full(4, 1.0))
    assert strikes.size == 0
    assert foot.size == 0


def test_vertical_bounce_integrates_to_zero_mean() -> None:
    t_ns, pos, heading, phase, speed = _straight_walk()
    spec = _spec(accel_noise_mps2=0.0, **NO_BIAS)
    accel, _ = simulate_imu(spec, t_ns, pos, heading, phase, speed, rng=0)
    # whole strides only: the pattern has zero mean over every half cycle of φ
    n = round(FS_HZ * STRIDE / SPEED * 50)
    a_v = accel[:n, 2] - G_MPS2
    assert abs(a_v.mean()) < 0.01
    v_z = np.cumsum(a_v) / FS_HZ
    # bounded vertical velocity without drift: the body bounces, it does not fly off
    cycle = round(FS_HZ * STRIDE / SPEED)
    assert np.ptp(v_z) < 0.5
    assert v_z[: 10 * cycle].mean() == pytest.approx(v_z[-10 * cycle:].mean(), abs=0.005)
    # a trunk excursion of a few centimetres, as in human walking (~4 cm peak to peak)
    z = np.cumsum(v_z - v_z.mean()) / FS_HZ
    assert 0.02 < np.ptp(z) < 0.06


def test_standing_gives_gravity_only() -> None:
    spec = _spec()
    t_ns, pos, heading, phase, _ = _straight_walk(speed=0.0)
    accel, gyro = simulate_imu(spec, t_ns, pos, heading, phase, np.zeros(t_ns.size), rng=2)
    n = t_ns.size
    tol = 4 * spec.accel_noise_mps2 / np.sqrt(n)
    assert accel[:, 2].mean() == pytest.approx(G_MPS2 + spec.accel_bias_mps2[2], abs=tol)
    np.testing.assert_allclose(accel.std(axis=0), spec.accel_noise_mps2, rtol=0.1)
    np.testing.assert_allclose(gyro.std(axis=0), spec.gyro_noise_radps, rtol=0.1)
    n_peaks, _ = _count_steps(accel[:, 2])
    assert n_peaks == 0


def test_biases_are_the_mean_offset() -> None:
    spec = _spec(accel_bias_mps2=(0.2, -0.1, 0.3), gyro_bias_radps=(0.01, -0.02, 0.005))
    t_ns, pos, heading, phase, _ = _straight_walk(speed=0.0)
    accel, gyro = simulate_imu(spec, t_ns, pos, heading, phase, np.zeros(t_ns.size), rng=3)
    n = t_ns.size
    np.testing.assert_allclose(accel.mean(axis=0) - [0, 0, G_MPS2], spec.accel_bias_mps2,
                               atol=4 * spec.accel_noise_mps2 / np.sqrt(n))
    np.testing.assert_allclose(gyro.mean(axis=0), spec.gyro_bias_radps, atol=4 * spec.gyro_noise_radps / np.sqrt(n))


def test_constant_turn_gives_yaw_rate_and_centripetal_acceleration() -> None:
    spec = _spec()
    rate = np.deg2rad(10.0)
    t_s = np.arange(int(60 * FS_HZ)) / FS_HZ
    t_ns = np.round(t_s * 1e9).astype(np.int64)
    heading = rate * t_s  # exceeds π after 18 s: the unwrapping must hold
    radius = SPEED / rate
    pos = radius * np.stack([np.sin(heading), 1 - np.cos(heading)], axis=1)  # circle to the left
    phase = 2 * np.pi * SPEED * t_s / STRIDE
    accel, gyro = simulate_imu(spec, t_ns, pos, np.angle(np.exp(1j * heading)), phase,
                               np.full(t_s.size, SPEED), rng=4)
    inner = slice(10, -10)
    assert np.rad2deg(gyro[inner, 2].mean() - spec.gyro_bias_radps[2]) == pytest.approx(10.0, abs=0.01)
    np.testing.assert_allclose(gyro[inner, :2].mean(axis=0), spec.gyro_bias_radps[:2], atol=1e-3)
    # centripetal v * ω towards the centre (body +y); the sway averages out over whole gait cycles
    n_cycles = int(60 * SPEED / STRIDE)
    whole = slice(0, round(n_cycles * STRIDE / SPEED * FS_HZ))
    assert accel[whole, 1].mean() - spec.accel_bias_mps2[1] == pytest.approx(SPEED * rate, abs=0.01)
    assert accel[whole, 0].mean() - spec.accel_bias_mps2[0] == pytest.approx(0.0, abs=0.01)


def test_phone_pitched_in_a_pocket() -> None:
    """C1 setting: phone pitched 80° in the pocket; the still-period mean is gravity along the rotated z."""
    pitch = np.deg2rad(80.0)
    spec = _spec(mount_rpy_rad=(0.0, pitch, 0.0), accel_bias_mps2=(0.0, 0.0, 0.0))
    t_ns, pos, heading, phase, _ = _straight_walk(duration_s=20.0, speed=0.0)
    accel, _ = simulate_imu(spec, t_ns, pos, heading, phase, np.zeros(t_ns.size), rng=5)
    g_mean = accel.mean(axis=0)
    assert np.linalg.norm(g_mean) == pytest.approx(G_MPS2, abs=0.01)
    # body z in phone axes: R_mount.T @ e_z; for a pitch θ about y that is (-sin θ, 0, cos θ)
    np.testing.assert_allclose(g_mean / G_MPS2, [-np.sin(pitch), 0.0, np.cos(pitch)], atol=0.002)
    # R_mount maps phone axes into body axes: the mean then points up
    np.testing.assert_allclose(mount_matrix(spec.mount_rpy_rad) @ g_mean, [0, 0, G_MPS2], atol=0.01)


def test_same_seed_is_reproducible() -> None:
    t_ns, pos, heading, phase, speed = _straight_walk(duration_s=5.0)
    a1, g1 = simulate_imu(_spec(), t_ns, pos, heading, phase, speed, rng=11)
    a2, g2 = simulate_imu(_spec(), t_ns, pos, heading, phase, speed, rng=np.random.default_rng(11))
    a3, _ = simulate_imu(_spec(), t_ns, pos, heading, phase, speed, rng=12)
    np.testing.assert_array_equal(a1, a2)
    np.testing.assert_array_equal(g1, g2)
    assert not np.array_equal(a1, a3)


def _snapshot(t_ns: int, ids, pos, vel, heading, phase) -> AgentSnapshot:
    n = len(ids)
    return AgentSnapshot(
        t_ns=t_ns, ids=np.asarray(ids, np.int64), kinds=np.full(n, KIND_PERSON, np.int8),
        position_m=np.asarray(pos, float).reshape(n, 2), velocity_mps=np.asarray(vel, float).reshape(n, 2),
        heading_rad=np.asarray(heading, float), feet_m=np.zeros((n, 2, 2)), size_m=np.tile([0.3, 0.5, 1.7], (n, 1)),
        upper_bgr=np.zeros((n, 3), np.uint8), lower_bgr=np.zeros((n, 3), np.uint8), pattern=np.zeros(n, np.int8),
        group_ids=np.full(n, -1, np.int64), gait_phase_rad=np.asarray(phase, float),
    )


def test_class_matches_the_batch_function() -> None:
    spec = _spec()
    t_ns, pos, heading, phase, speed = _straight_walk(duration_s=5.0)
    vel = np.tile([SPEED, 0.0], (t_ns.size, 1))
    sim = PhoneImuSim(spec)
    rng = np.random.default_rng(21)
    out = []
    for k in range(t_ns.size):
        # another person is listed first: the carrier is found by id
        snap = _snapshot(int(t_ns[k]), [3, 7], [[0.0, 5.0], pos[k]], [[0.0, 0.0], vel[k]], [0.0, heading[k]],
                         [0.0, np.angle(np.exp(1j * phase[k]))])
        sample = sim.sample(int(t_ns[k]), snap, rng, stamp_ns=int(t_ns[k]) + 1000)
        assert isinstance(sample, ImuSample)
        assert sample.sensor == "phone"
        assert sample.frame_id == "phone"
        assert sample.t_ns == t_ns[k] + 1000
        out.append((sample.accel_mps2, sample.gyro_radps))
    accel, gyro = simulate_imu(spec, t_ns, pos, heading, phase, speed, rng=21, velocity_mps=vel)
    # constant velocity: the backward differences of the class equal the batch's; same noise stream
    np.testing.assert_allclose(np.array([a for a, _ in out]), accel, atol=1e-9)
    np.testing.assert_allclose(np.array([g for _, g in out]), gyro, atol=1e-9)


def test_class_differentiates_velocity_and_heading() -> None:
    spec = _spec(accel_noise_mps2=0.0, gyro_noise_radps=0.0, step_accel_mps2=0.0, **NO_BIAS)
    sim = PhoneImuSim(spec)
    # heading crosses ±π between the samples: the yaw rate must still be +0.2 rad/s
    s0 = _snapshot(0, [7], [0.0, 0.0], [1.0, 0.0], [np.pi - 0.001], [0.0])
    s1 = _snapshot(10_000_000, [7], [0.0, 0.0], [1.0, 0.05], [-np.pi + 0.001], [0.0])
    first = sim.sample(0, s0, rng=0)
    assert first is not None
    np.testing.assert_allclose(first.accel_mps2, [0, 0, G_MPS2])
    second = sim.sample(10_000_000, s1, rng=0)
    assert second is not None
    np.testing.assert_allclose(second.gyro_radps, [0, 0, 0.2], atol=1e-9)
    # world acceleration (0, 5) m/s^2 seen by a walker heading ~-x: body y = -5
    np.testing.assert_allclose(second.accel_mps2, [0.0, -5.0, G_MPS2], atol=0.01)


def test_class_returns_none_without_carrier_and_rejects_time_going_back() -> None:
    sim = PhoneImuSim(_spec())
    assert sim.sample(0, AgentSnapshot.empty(0), rng=0) is None
    assert sim.sample(1, _snapshot(1, [3], [0.0, 0.0], [0.0, 0.0], [0.0], [0.0]), rng=0) is None
    snap = _snapshot(2, [7], [0.0, 0.0], [0.0, 0.0], [0.0], [0.0])
    assert sim.sample(2, snap, rng=0) is not None
    with pytest.raises(ValueError, match="t_ns"):
        sim.sample(2, snap, rng=0)


def test_bad_input_names_the_parameter() -> None:
    t_ns, pos, heading, phase, speed = _straight_walk(duration_s=1.0)
    with pytest.raises(ValueError, match="position_m"):
        simulate_imu(_spec(), t_ns, pos[:-1], heading, phase, speed, rng=0)
    with pytest.raises(ValueError, match="t_ns"):
        simulate_imu(_spec(), t_ns[::-1], pos, heading, phase, speed, rng=0)
    with pytest.raises(ValueError, match="accel_noise_mps2"):
        PhoneImuSim(_spec(accel_noise_mps2=-1.0))
