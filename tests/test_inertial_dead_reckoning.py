"""Dead reckoning from step lengths and headings (seed 002 Eq. 2, ALGORITHMS.md C5)."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.inertial import dead_reckon, run_pdr, step_headings


def test_c5_square_returns_to_the_origin() -> None:
    # ALGORITHMS.md C5 test: four 1 m steps at 0°, 90°, 180°, 270° return to the start
    pos = dead_reckon(np.ones(4), np.deg2rad([0.0, 90.0, 180.0, 270.0]), start_m=(2.0, -1.0))
    np.testing.assert_allclose(pos, [[3.0, -1.0], [3.0, 0.0], [2.0, 0.0], [2.0, -1.0]], atol=1e-12)


def test_c5_yaw_bias_drift_is_v_b_t_squared_over_2() -> None:
    # ALGORITHMS.md C5: 1.3 m/s with a residual yaw bias of 0.037 deg/s -> lateral error v·b·t²/2 ≈ 17 m at 200 s
    step_s, v = 0.5, 1.3
    t = np.arange(1, 401) * step_s
    b = np.deg2rad(0.037)
    pos = dead_reckon(np.full(t.size, v * step_s), b * t)
    assert pos[-1, 1] == pytest.approx(v * b * 200.0**2 / 2, rel=0.01)
    assert pos[-1, 1] == pytest.approx(16.8, abs=0.2)


def test_step_headings_mean_over_the_step_and_at_the_step() -> None:
    t = np.arange(0, 1001, dtype=np.int64) * 10_000_000  # 10 s at 100 Hz
    yaw = 0.1 * t * 1e-9  # 0.1 rad/s
    steps = np.array([2_000_000_000, 5_000_000_000], dtype=np.int64)
    dur = np.array([0.5, 1.0])
    np.testing.assert_allclose(step_headings(steps, dur, t, yaw, "at_step"), [0.2, 0.5])
    np.testing.assert_allclose(step_headings(steps, dur, t, yaw), [0.1 * 1.75, 0.1 * 4.5])
    # a sway of ±0.2 rad at the step frequency averages out over the step
    sway = yaw + 0.2 * np.sin(2 * np.pi * t * 1e-9 / 0.5)
    np.testing.assert_allclose(step_headings(steps, np.full(2, 0.5), t, sway), [0.175, 0.475], atol=1e-3)
    with pytest.raises(ValueError, match="mode"):
        step_headings(steps, dur, t, yaw, "median")


def test_run_pdr_trajectory_knots_and_interpolation() -> None:
    # a pure step signal (no gyro): steps every 0.5 s along heading0, with the default model
    fs = 100.0
    t_s = np.arange(round(20 * fs)) / fs
    a_v = 9.81 + 2.5 * np.sin(2 * np.pi * 2.0 * t_s)
    accel = np.stack([np.zeros_like(a_v), np.zeros_like(a_v), a_v], axis=1)
    t_ns = np.round(t_s * 1e9).astype(np.int64)
    res = run_pdr(t_ns, accel, None, heading0_rad=np.pi / 2, start_m=(1.0, 1.0))
    assert not res.has_gyro
    assert res.n_steps == 40
    # default C3 line at Δt = 0.5 s (the filter's edge effects move the first peaks by a few ms)
    np.testing.assert_allclose(res.step_length_m, 0.9 * 0.5 + 0.2, atol=0.005)
    np.testing.assert_allclose(res.position_m[:, 0], 1.0, atol=1e-12)
    np.testing.assert_allclose(res.position_m[:, 1], 1.0 + np.cumsum(res.step_length_m))
    assert res.distance_m == pytest.approx(40 * 0.65, abs=0.02)
    t_knots, p_knots = res.knots()
    assert t_knots.size == res.n_steps + 1
    np.testing.assert_allclose(p_knots[0], (1.0, 1.0))
    mid = (res.step_t_ns[3] + res.step_t_ns[4]) // 2
    np.testing.assert_allclose(res.position_at([mid])[0], (res.position_m[3] + res.position_m[4]) / 2, atol=1e-6)
    np.testing.assert_allclose(res.position_at([t_knots[0] - 1, 10**12]), [[1.0, 1.0], res.position_m[-1]])


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="step_length_m, heading_rad"):
        dead_reckon(np.ones(3), np.zeros(2))
    with pytest.raises(ValueError, match="start_m"):
        dead_reckon(np.ones(3), np.zeros(3), start_m=(0.0,))
    t = np.arange(500, dtype=np.int64) * 10_000_000
    accel = np.tile([0.0, 0.0, 9.81], (500, 1))
    with pytest.raises(ValueError, match="step_model"):
        run_pdr(t, accel, step_model="model.json")
    with pytest.raises(ValueError, match="heading_mode"):
        run_pdr(t, accel, heading_mode="max")
