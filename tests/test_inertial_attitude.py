"""Attitude and yaw integration (seed 002 Eq. 1, ALGORITHMS.md C4 and erratum E1)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fusiontrack.inertial import accel_tilt, calibrate_imu, euler_rate_matrix, integrate_attitude, integrate_yaw

FS_HZ = 50.0


def _t_ns(seconds: float, fs: float = FS_HZ) -> np.ndarray:
    return np.round(np.arange(round(seconds * fs) + 1) / fs * 1e9).astype(np.int64)


def test_rate_matrix_identity_and_erratum() -> None:
    np.testing.assert_allclose(euler_rate_matrix(0.0, 0.0), np.eye(3), atol=1e-15)
    E = euler_rate_matrix(np.deg2rad(30.0), np.deg2rad(20.0))
    # ALGORITHMS.md C4: row 3 = (0, 0.5/0.9397, 0.8660/0.9397); the seed's printed cos·cos is wrong (E1)
    np.testing.assert_allclose(E[2], (0.0, 0.5 / 0.9397, 0.8660 / 0.9397), atol=1e-4)
    assert E[2, 2] != pytest.approx(np.cos(np.deg2rad(30.0)) * np.cos(np.deg2rad(20.0)), abs=1e-3)
    batch = euler_rate_matrix(np.zeros(4), np.linspace(0, 1, 4))
    assert batch.shape == (4, 3, 3)


def test_rate_matrix_matches_the_rotation_kinematics() -> None:
    # the Euler rates E·ω must reproduce a small body rotation: R(Ψ + E ω h) ≈ R(Ψ) exp(ω h)
    rng = np.random.default_rng(0)
    for _ in range(20):
        r, p, y = rng.uniform(-1.2, 1.2, 3)
        w = rng.normal(0.0, 1.0, 3)
        h = 1e-6
        R1 = Rotation.from_euler("ZYX", [y, p, r]) * Rotation.from_rotvec(w * h)
        rates = euler_rate_matrix(r, p) @ w
        r2, p2, y2 = np.array([r, p, y]) + rates * h
        np.testing.assert_allclose(Rotation.from_euler("ZYX", [y2, p2, r2]).as_matrix(), R1.as_matrix(), atol=1e-11)


def test_c4_constant_yaw_rate_gives_90_degrees() -> None:
    # ALGORITHMS.md C4 test: roll = pitch = 0, 10°/s for 9 s -> yaw 90.00 ± 0.01°
    t = _t_ns(9.0)
    gyro = np.tile([0.0, 0.0, np.deg2rad(10.0)], (t.size, 1))
    rpy = integrate_attitude(t, gyro)
    assert np.rad2deg(rpy[-1, 2]) == pytest.approx(90.0, abs=0.01)
    np.testing.assert_allclose(rpy[:, :2], 0.0, atol=1e-12)
    assert np.rad2deg(integrate_yaw(t, gyro, 0.0, 0.0)[-1]) == pytest.approx(90.0, abs=0.01)


def test_c4_bias_removed_by_c1_is_within_0_2_degrees() -> None:
    # ALGORITHMS.md C4 test: the same turn with a gyro bias and noise; bias estimated by C1 from 10 s still
    rng = np.random.default_rng(1)
    bias = np.deg2rad([0.5, -0.3, 0.4])
    t = _t_ns(19.0)
    moving = t >= 10_000_000_000
    # gyro white noise 0.001 rad/s per sample (0.06 deg/s at 50 Hz, a phone-grade MEMS gyro): the 10 s mean
    # leaves ~0.004 deg/s of bias, the 9 s turn ~0.035 deg of error (1 sigma), so 0.2 deg is ~6 sigma
    noise = rng.normal(0, 0.001, (t.size, 3))
    gyro = np.where(moving[:, None], [0.0, 0.0, np.deg2rad(10.0)], 0.0) + bias + noise
    accel = np.tile([0.0, 0.0, 9.81], (t.size, 1)) + rng.normal(0, 0.05, (t.size, 3))
    cal = calibrate_imu(t, accel, gyro, still=(0, 9_980_000_000), min_still_s=9.0)
    yaw = integrate_attitude(t, gyro, gyro_bias_radps=cal.gyro_bias_radps, accel_mps2=accel)[:, 2]
    turned = np.rad2deg(yaw[-1] - yaw[np.argmax(moving)])
    assert turned == pytest.approx(90.0, abs=0.2)
    raw = integrate_attitude(t, gyro)[:, 2]
    assert abs(np.rad2deg(raw[-1] - raw[np.argmax(moving)]) - 90.0) > 0.5  # the bias matters


@pytest.mark.parametrize("rpy0_deg", [(0, 0, 0), (20, -30, 45), (10, 85, 0), (-5, -88, 30)])
def test_constant_body_rate_matches_the_closed_form_rotation(rpy0_deg) -> None:
    # a rigid body turning at a constant body rate ω has R(t) = R0 exp(ω t): integrate and compare,
    # also where the pitch passes 80° and the integration switches to the rotation itself
    fs = 1000.0
    t = _t_ns(3.0, fs)
    w = np.array([0.3, -0.2, 0.5])
    r0, p0, y0 = np.deg2rad(rpy0_deg)
    rpy = integrate_attitude(t, np.tile(w, (t.size, 1)), rpy0_rad=(r0, p0, y0))
    R0 = Rotation.from_euler("ZYX", [y0, p0, r0])
    for k in (t.size // 2, t.size - 1):
        truth = R0 * Rotation.from_rotvec(w * t[k] * 1e-9)
        ours = Rotation.from_euler("ZYX", rpy[k, ::-1])
        assert np.rad2deg((ours.inv() * truth).magnitude()) < 0.1


def test_tilt_correction_pulls_roll_and_pitch_to_gravity() -> None:
    # start 10° off in roll with a still phone: the complementary filter (τ = 1 s) converges
    t = _t_ns(8.0)
    accel = np.tile([0.0, 0.0, 9.81], (t.size, 1))
    rpy = integrate_attitude(t, np.zeros((t.size, 3)), rpy0_rad=(np.deg2rad(10.0), 0.0, 0.0), accel_mps2=accel)
    assert abs(np.rad2deg(rpy[-1, 0])) < 10.0 * np.exp(-7.0)
    roll, pitch = accel_tilt(np.array([[0.0, 9.81 * np.sin(0.3), 9.81 * np.cos(0.3)]]))
    assert roll[0] == pytest.approx(0.3)
    assert pitch[0] == pytest.approx(0.0)


def test_bad_input() -> None:
    t = _t_ns(1.0)
    with pytest.raises(ValueError, match="gyro_radps"):
        integrate_attitude(t, np.zeros((t.size, 2)))
    gyro = np.zeros((t.size, 3))
    gyro[5, 0] = np.nan
    with pytest.raises(ValueError, match="gyro_radps: sample 5"):
        integrate_attitude(t, gyro)
    with pytest.raises(ValueError, match="t_ns"):
        integrate_attitude(t[::-1].copy(), np.zeros((t.size, 3)))
    with pytest.raises(ValueError, match="gyro_bias_radps"):
        integrate_attitude(t, np.zeros((t.size, 3)), gyro_bias_radps=(1.0, 2.0))
    with pytest.raises(ValueError, match="rpy0_rad"):
        integrate_attitude(t, np.zeros((t.size, 3)), rpy0_rad=(0.0, np.nan, 0.0))
