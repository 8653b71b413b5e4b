"""IMU preprocessing (ALGORITHMS.md C1) and the checks at the edge of the inertial package."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fusiontrack.inertial import (
    calibrate_imu,
    check_imu,
    detect_steps,
    detect_still_period,
    gravity_to_level,
    level_imu,
    resample_uniform,
    run_pdr,
    vertical_acceleration,
)
from fusiontrack.sim.imu import G_MPS2, simulate_imu
from fusiontrack.sim.model import ImuSpec, Timing

FS_HZ = 100.0


def _standing_then_walking(mount_rpy_rad, still_s: float = 12.0, walk_s: float = 20.0, rng: int = 0, **spec_kw):
    n_still, n_walk = round(still_s * FS_HZ), round(walk_s * FS_HZ)
    t_s = np.arange(n_still + n_walk) / FS_HZ
    t_ns = np.round(t_s * 1e9).astype(np.int64)
    on = (t_s >= still_s).astype(float)
    speed = 1.3 * on
    phase = np.pi / 2 + np.cumsum(speed) / FS_HZ * 2 * np.pi / 1.4
    pos = np.stack([np.cumsum(speed) / FS_HZ, np.zeros_like(t_s)], axis=1)
    vel = np.stack([speed, np.zeros_like(t_s)], axis=1)
    spec = ImuSpec("phone", 1, Timing(rate_hz=FS_HZ), mount_rpy_rad=mount_rpy_rad, **spec_kw)
    accel, gyro = simulate_imu(spec, t_ns, pos, np.zeros_like(t_s), phase, speed, rng, velocity_mps=vel)
    return t_ns, accel, gyro


def test_c1_pocket_phone_bias_and_levelling() -> None:
    # ALGORITHMS.md C1 test: phone pitched 80° in the pocket, gyro bias (0.5, -0.3, 0.4) deg/s;
    # bias within 0.02 deg/s, rotated gravity (0, 0, 9.81) ± 0.01 (no accelerometer bias: it is not
    # separable from gravity with one orientation)
    bias = np.deg2rad([0.5, -0.3, 0.4])
    t_ns, accel, gyro = _standing_then_walking((0.0, np.deg2rad(80.0), 0.0), gyro_bias_radps=tuple(bias),
                                               accel_bias_mps2=(0.0, 0.0, 0.0))
    cal = calibrate_imu(t_ns, accel, gyro)
    assert cal.still_ns is not None
    assert 10.5 < (cal.still_ns[1] - cal.still_ns[0]) * 1e-9 <= 12.0  # the 12 s standing start, less the edge
    np.testing.assert_allclose(np.rad2deg(cal.gyro_bias_radps), np.rad2deg(bias), atol=0.02)
    np.testing.assert_allclose(cal.R_mount @ cal.gravity_phone_mps2, (0.0, 0.0, G_MPS2), atol=0.01)
    np.testing.assert_allclose(cal.gyro_noise_radps, 0.003, rtol=0.1)  # the simulator's per-sample noise
    np.testing.assert_allclose(cal.accel_noise_mps2, 0.05, rtol=0.1)
    accel_level, gyro_level = level_imu(accel, gyro, cal)
    i_still = slice(0, 1000)
    np.testing.assert_allclose(accel_level[i_still].mean(axis=0), (0.0, 0.0, G_MPS2), atol=0.01)
    np.testing.assert_allclose(gyro_level[i_still].mean(axis=0), 0.0, atol=np.deg2rad(0.02))


def test_given_still_period_and_none() -> None:
    t_ns, accel, gyro = _standing_then_walking((0.2, 0.3, 0.0))
    given = calibrate_imu(t_ns, accel, gyro, still=(int(t_ns[100]), int(t_ns[900])))
    assert given.still_ns == (int(t_ns[100]), int(t_ns[900]))
    np.testing.assert_allclose(given.gyro_bias_radps, (0.0087, -0.0052, 0.0070), atol=np.deg2rad(0.03))
    none = calibrate_imu(t_ns, accel, gyro, still=None)
    assert none.still_ns is None
    np.testing.assert_array_equal(none.gyro_bias_radps, 0.0)
    # walking averages out: gravity from the whole stream is still close to vertical
    up = none.R_mount @ given.gravity_phone_mps2
    assert np.degrees(np.arccos(up[2] / np.linalg.norm(up))) < 2.0
    with pytest.raises(ValueError, match="still"):
        calibrate_imu(t_ns, accel, gyro, still=(0, 1))
    with pytest.raises(ValueError, match="still"):
        calibrate_imu(t_ns, accel, gyro, still="sometimes")


def test_no_still_period_when_walking_from_the_start() -> None:
    t_ns, accel, gyro = _standing_then_walking((0.0, 0.0, 0.0), still_s=0.3)
    assert detect_still_period(t_ns, accel, gyro) is None


@pytest.mark.parametrize("rpy", [(0.0, 0.0, 0.0), (0.3, -1.2, 2.0), (np.pi, 0.0, 0.5), (0.0, np.pi / 2, 0.0),
                                 (3.0, 0.1, -1.0)])
def test_gravity_to_level_is_a_rotation_taking_gravity_up(rpy) -> None:
    R_true = Rotation.from_euler("ZYX", rpy[::-1]).as_matrix()
    g_phone = R_true.T @ np.array([0.0, 0.0, G_MPS2])
    R = gravity_to_level(g_phone)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R @ g_phone, (0.0, 0.0, G_MPS2), atol=1e-9)
    # it differs from the true mounting only by a turn about the vertical (yaw is unobservable)
    D = R @ R_true.T
    np.testing.assert_allclose(D[2], (0.0, 0.0, 1.0), atol=1e-9)


def test_vertical_acceleration_ignores_orientation() -> None:
    # one walk, seen by phones held three ways: the same vertical signal
    signals = []
    for rpy in [(0.0, 0.0, 0.0), (1.2, 0.4, 0.0), (np.deg2rad(170.0), 0.0, 0.0)]:
        t_ns, accel, _ = _standing_then_walking(rpy, still_s=1.0, accel_noise_mps2=0.0, accel_bias_mps2=(0, 0, 0))
        signals.append(vertical_acceleration(t_ns, accel)[1])
    np.testing.assert_allclose(signals[1], signals[0], atol=0.05)
    np.testing.assert_allclose(signals[2], signals[0], atol=0.05)


def test_resample_averages_repeated_stamps_and_bridges_gaps() -> None:
    t = np.array([0, 10, 10, 20, 50], dtype=np.int64) * 1_000_000
    x = np.array([[0.0], [1.0], [3.0], [4.0], [7.0]])
    grid, y = resample_uniform(t, x, rate_hz=100.0)
    np.testing.assert_array_equal(grid, np.arange(6) * 10_000_000)
    np.testing.assert_allclose(y[:, 0], [0.0, 2.0, 4.0, 5.0, 6.0, 7.0])


# ---- bad input: a clear ValueError naming the parameter ------------------------------------------


def _good(n: int = 500):
    t = np.arange(n, dtype=np.int64) * 10_000_000
    accel = np.tile([0.0, 0.0, G_MPS2], (n, 1))
    return t, accel, np.zeros((n, 3))


@pytest.mark.parametrize("fn", [check_imu, detect_steps, run_pdr, calibrate_imu])
def test_nan_sample_is_named(fn) -> None:
    t, accel, gyro = _good()
    accel[123, 1] = np.nan
    with pytest.raises(ValueError, match=r"accel_mps2: sample 123 is not finite"):
        fn(t, accel, gyro) if fn is not detect_steps else fn(t, accel)


@pytest.mark.parametrize("fn", [check_imu, detect_steps, run_pdr])
def test_time_going_backwards_is_named(fn) -> None:
    t, accel, gyro = _good()
    t[200] = t[198]
    with pytest.raises(ValueError, match=r"t_ns: time goes backwards at sample 200"):
        fn(t, accel, gyro) if fn is not detect_steps else fn(t, accel)


def test_repeated_stamps_are_accepted() -> None:
    t, accel, gyro = _good()
    t[200] = t[199]  # Oxford traces have these
    check_imu(t, accel, gyro)
    assert len(detect_steps(t, accel)) == 0


@pytest.mark.parametrize("n", [1, 2, 50, 150])
def test_too_short_input(n: int) -> None:
    t, accel, gyro = _good(n)
    with pytest.raises(ValueError, match=r"t_ns: .*(too short|at least 2 samples)"):
        detect_steps(t, accel)
    with pytest.raises(ValueError, match=r"t_ns: .*(too short|at least 2 samples)"):
        run_pdr(t, accel, gyro)


def test_other_bad_shapes_and_types() -> None:
    t, accel, gyro = _good()
    with pytest.raises(ValueError, match=r"t_ns: expected a .* integer"):
        check_imu(t * 1e-9, accel)
    with pytest.raises(ValueError, match=r"accel_mps2: expected shape \(500, 3\)"):
        check_imu(t, accel[:, :2])
    with pytest.raises(ValueError, match=r"gyro_radps: expected shape"):
        check_imu(t, accel, gyro[:-1])
    partial = gyro.copy()
    partial[7] = np.nan
    with pytest.raises(ValueError, match=r"gyro_radps: sample 7 is not finite"):
        check_imu(t, accel, partial)
    # all-NaN gyro = no gyro (accelerometer-only CSVs)
    assert check_imu(t, accel, np.full_like(gyro, np.nan))[2] is None
    with pytest.raises(ValueError, match="gravity_phone"):
        gravity_to_level([0.0, 0.0, 0.0])
