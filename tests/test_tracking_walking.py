"""Two-feet walking model and constant velocity (ALGORITHMS.md B8, B18, X5): kinematic known answers."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.tracking import walking as wk
from fusiontrack.tracking.kalman import cv_matrices

DT = 0.04  # 25 Hz
PERIOD, STRIDE = 1.2, 1.4  # T / Δt = 30 steps


def consistent_state(psi: np.ndarray, phi: np.ndarray, period: float = PERIOD, stride: float = STRIDE,
                     centre: tuple[float, float] = (1.0, -2.0), lateral_m: float = 0.0) -> np.ndarray:
    """Particles whose feet separation matches their phase: (p^L - p^R)·u = -(S/π) cos φ."""
    psi, phi = np.broadcast_arrays(np.asarray(psi, float), np.asarray(phi, float))
    u = np.stack([np.cos(psi), np.sin(psi)], axis=-1)
    nrm = np.stack([-u[..., 1], u[..., 0]], axis=-1)
    half = (-(stride / np.pi) * np.cos(phi) / 2)[..., None] * u + (lateral_m / 2) * nrm
    x = np.empty((*psi.shape, 8))
    x[..., wk.LEFT] = np.asarray(centre) + half
    x[..., wk.RIGHT] = np.asarray(centre) - half
    x[..., wk.PSI], x[..., wk.PHI] = psi, phi
    x[..., wk.PERIOD], x[..., wk.STRIDE] = period, stride
    return x


def propagate(x: np.ndarray, n_steps: int, dt: float = DT) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    out = [x]
    for _ in range(n_steps):
        out.append(wk.predict_walking(out[-1], dt, rng, noise=wk.WalkingNoise.zero()))
    return out


def grid_state() -> np.ndarray:
    psi = np.linspace(-np.pi, np.pi, 7, endpoint=False)[:, None] + 0.3
    phi = np.linspace(0, 2 * np.pi, 9, endpoint=False)[None, :] + 0.1
    return consistent_state(psi, phi)  # (7 targets, 9 particles, 8)


def test_one_period_advances_each_foot_by_the_stride() -> None:
    # B8: noise-free propagation for one period T = 1.2 s at Δt = 40 ms: each foot advances S along u (0.5 %)
    x0 = grid_state()
    x1 = propagate(x0, round(PERIOD / DT))[-1]
    u = np.stack([np.cos(x0[..., wk.PSI]), np.sin(x0[..., wk.PSI])], axis=-1)
    for foot in (wk.LEFT, wk.RIGHT):
        disp = x1[..., foot] - x0[..., foot]
        np.testing.assert_allclose(np.linalg.norm(disp - STRIDE * u, axis=-1), 0.0, atol=0.005 * STRIDE)
    # the phase has come round: back where it started (mod 2π)
    np.testing.assert_allclose(np.cos(x1[..., wk.PHI] - x0[..., wk.PHI]), 1.0, atol=1e-12)


def test_signed_separation_follows_cosine_pattern() -> None:
    # B8: (p^L - p^R)·u = -(S/π) cos φ, so D_pred = κ S |cos φ| with κ = 1/π, all along the way
    # (within 0.5 % of S: the residual of the O(Δt²) Taylor step, which cancels over each period)
    states = propagate(grid_state(), 90)
    for x in states:
        d = wk.signed_separation(x)
        np.testing.assert_allclose(d, -(STRIDE / np.pi) * np.cos(x[..., wk.PHI]), atol=0.005 * STRIDE)
        np.testing.assert_allclose(np.abs(d), wk.predicted_feet_distance(x[..., wk.PHI], x[..., wk.STRIDE]),
                                   atol=0.005 * STRIDE)


def test_mean_speed_over_ten_periods() -> None:
    # B8: mean speed over 10 periods = S/T ± 1 %, for each foot and the body
    n = 10 * round(PERIOD / DT)
    x0 = grid_state()
    x1 = propagate(x0, n)[-1]
    for pos in (lambda s: s[..., wk.LEFT], lambda s: s[..., wk.RIGHT], wk.body_position):
        speed = np.linalg.norm(pos(x1) - pos(x0), axis=-1) / (n * DT)
        np.testing.assert_allclose(speed, STRIDE / PERIOD, rtol=0.01)


def test_velocities_accelerations_and_standing_foot() -> None:
    x = consistent_state(0.0, np.array([-np.pi / 2, 0.0, np.pi / 2]))
    v_l, v_r = wk.foot_velocities(x)
    # at φ = -π/2 the left foot stands (speed 0) and the right one swings at 2S/T
    np.testing.assert_allclose(v_l[0], [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(v_r[0], [2 * STRIDE / PERIOD, 0.0])
    np.testing.assert_allclose(v_l + v_r, np.tile([2 * STRIDE / PERIOD, 0.0], (3, 1)))
    a_l, a_r = wk.foot_accelerations(x)
    a_max = 2 * np.pi * STRIDE / PERIOD**2  # A = 2πS/T²
    np.testing.assert_allclose(a_l[1], [a_max, 0.0])
    np.testing.assert_allclose(a_l + a_r, 0.0, atol=1e-12)


def test_noise_statistics_and_clips() -> None:
    rng = np.random.default_rng(7)
    x = consistent_state(np.zeros((20, 500)), np.zeros((20, 500)))
    x1 = wk.predict_walking(x, DT, rng)  # B8 default noise
    dphi = x1[..., wk.PHI] - 2 * np.pi * DT / PERIOD
    assert abs(dphi.mean()) < 0.005
    assert abs(dphi.std() - 0.1) < 0.005
    assert abs(x1[..., wk.PSI].std() - np.deg2rad(3)) < 0.003
    assert abs(x1[..., wk.STRIDE].std() - 0.03) < 0.002
    # T and S stay inside B8's ranges however hard they are pushed
    big = wk.WalkingNoise(period_s=5.0, stride_m=5.0)
    x2 = wk.predict_walking(x, DT, rng, noise=big)
    assert x2[..., wk.PERIOD].min() >= 0.8
    assert x2[..., wk.PERIOD].max() <= 1.6
    assert x2[..., wk.STRIDE].min() >= 0.4
    assert x2[..., wk.STRIDE].max() <= 2.0
    assert (np.abs(x2[..., wk.PSI]) <= np.pi).all()
    assert (np.abs(x2[..., wk.PHI]) <= np.pi).all()
    # the input is never modified
    np.testing.assert_array_equal(x, consistent_state(np.zeros((20, 500)), np.zeros((20, 500))))


def test_noise_scales_with_dt_when_asked() -> None:
    rng = np.random.default_rng(8)
    x = consistent_state(np.zeros((10, 1000)), np.zeros((10, 1000)))
    nz = wk.WalkingNoise(dt_ref_s=DT)
    x1 = wk.predict_walking(x, 4 * DT, rng, noise=nz)
    assert abs(x1[..., wk.PSI].std() - 2 * np.deg2rad(3)) < 0.003


def test_predicted_feet_distance_with_lateral_offset() -> None:
    np.testing.assert_allclose(wk.predicted_feet_distance(0.0, 1.4), 1.4 / np.pi)
    np.testing.assert_allclose(wk.predicted_feet_distance(np.pi / 2, 1.4, lateral_m=0.2), 0.2)
    np.testing.assert_allclose(wk.predicted_feet_distance(0.0, 1.4, kappa=0.5, lateral_m=0.2), np.hypot(0.7, 0.2))


def test_init_walking() -> None:
    rng = np.random.default_rng(9)
    feet = np.array([[[0.0, 0.0], [0.3, 0.0]], [[5.0, 5.0], [5.0, 5.2]]])
    heading = wk.heading_from_displacement(np.array([[0.0, 0.0], [5, 5]]), np.array([[0.5, 0.5], [5.05, 5]]))
    assert np.isclose(heading[0], np.pi / 4)
    assert np.isnan(heading[1])
    x = wk.init_walking(feet, 200, rng, heading)
    assert x.shape == (2, 200, 8)
    np.testing.assert_array_equal(x[:, :, 0:4], np.repeat(feet.reshape(2, 1, 4), 200, axis=1))
    np.testing.assert_allclose(x[0, :, wk.PSI], np.pi / 4)
    assert x[1, :, wk.PSI].std() > 1.0  # uniform heading
    assert x[..., wk.PERIOD].tolist() == np.full((2, 200), 1.1).tolist()
    assert x[..., wk.STRIDE].tolist() == np.full((2, 200), 1.4).tolist()
    assert (np.abs(x[..., wk.PHI]) <= np.pi).all()
    assert x[..., wk.PHI].std() > 1.5


def test_standing_switch_and_random_walk() -> None:
    count, still = np.zeros(2, np.int64), np.zeros(2, bool)
    for _ in range(9):
        count, still = wk.update_standing(np.array([0.05, 0.5]), count, still)
    assert not still.any()
    count, still = wk.update_standing(np.array([0.05, 0.5]), count, still)  # the 10th slow frame
    assert still.tolist() == [True, False]
    count, still = wk.update_standing(np.array([0.15, 0.5]), count, still)  # hysteresis: still standing
    assert still.tolist() == [True, False]
    count, still = wk.update_standing(np.array([0.3, 0.5]), count, still)
    assert still.tolist() == [False, False]
    assert count.tolist() == [0, 0]

    rng = np.random.default_rng(10)
    x = consistent_state(np.zeros((2, 2000)), np.zeros((2, 2000)))
    x1 = wk.predict_people(x, np.array([True, False]), DT, rng)
    body = wk.body_position(x1) - wk.body_position(x)
    assert abs(body[0].mean(axis=0)).max() < 0.003  # standing: no drift
    assert abs(body[1, :, 0].mean() - STRIDE / PERIOD * DT) < 0.003  # walking: moves along u
    np.testing.assert_array_equal(x1[0, :, wk.STRIDE], STRIDE)


def test_predict_cv_mean_and_x5_noise_covariance() -> None:
    rng = np.random.default_rng(11)
    x = np.zeros((2, 40000, 4))
    x[..., 2:4] = [3.0, -1.0]
    dt = 0.1
    x1 = wk.predict_cv(x, dt, np.array([0.5, 1.0]), rng)
    np.testing.assert_allclose(x1[..., 0:2].mean(axis=1), [[0.3, -0.1]] * 2, atol=2e-3)
    for t, q in enumerate([0.5, 1.0]):
        _, Q = cv_matrices(dt, q)
        np.testing.assert_allclose(np.cov(x1[t].T), Q, atol=0.03 * Q.max())
    x2 = wk.predict_cv(x[:, :3], dt, 0.0, rng)  # q = 0: exact
    np.testing.assert_allclose(x2[..., 0:2], np.tile([0.3, -0.1], (2, 3, 1)))


def test_rng_must_be_a_generator() -> None:
    with pytest.raises(TypeError, match="rng"):
        wk.predict_walking(grid_state(), DT, 0)  # type: ignore[arg-type]
