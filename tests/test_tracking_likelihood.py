"""Laser observation likelihood (ALGORITHMS.md B9) and the centroid likelihood (B18)."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.tracking import likelihood as lk
from fusiontrack.tracking import walking as wk


def particle(left: tuple[float, float], right: tuple[float, float], psi: float = 0.0, phi: float = 0.0,
             stride: float = 1.4) -> np.ndarray:
    x = np.zeros(8)
    x[wk.LEFT], x[wk.RIGHT] = left, right
    x[wk.PSI], x[wk.PHI], x[wk.PERIOD], x[wk.STRIDE] = psi, phi, 1.1, stride
    return x


def measured_walker(psi: float = 0.4, phi: float = 0.7, stride: float = 1.4) -> tuple[np.ndarray, np.ndarray, float]:
    """A particle and the detection of the same feet: separation -(S/π)cos φ along the heading."""
    u = np.array([np.cos(psi), np.sin(psi)])
    half = -(stride / np.pi) * np.cos(phi) / 2 * u
    c = np.array([2.0, 3.0])
    x = particle(tuple(c + half), tuple(c - half), psi, phi, stride)
    feet = np.stack([c + half, c - half])
    return x, feet, float(np.linalg.norm(feet[0] - feet[1]))


def test_particle_on_the_measured_feet_has_likelihood_one() -> None:
    # B9: exactly on the feet with the correct phase -> 1
    x, feet, sd = measured_walker()
    lik = lk.laser_likelihood(x[None, None], feet[None], np.array([sd]), np.array([False]))
    np.testing.assert_allclose(lik, [[1.0]], rtol=1e-12)
    # which barycentre is called f1 does not matter (nearest-foot assignment)
    lik = lk.laser_likelihood(x[None, None], feet[None, ::-1], np.array([sd]), np.array([False]))
    np.testing.assert_allclose(lik, [[1.0]], rtol=1e-12)


def test_both_feet_shifted_by_10_cm_gives_exp_minus_one() -> None:
    # B9: shifting both feet by 0.1 m -> exp(-(0.01 + 0.01) / (2 · 0.1²)) = exp(-1) ≈ 0.368
    x, feet, sd = measured_walker()
    shifts = np.array([[0.1, 0.0], [0.0, -0.1], [0.06, 0.08]])
    states = np.stack([x] * 3)
    for k, s in enumerate(shifts):
        states[k, wk.LEFT] += s
        states[k, wk.RIGHT] += s
    lik = lk.laser_likelihood(states[None], feet[None], np.array([sd]), np.array([False]))
    np.testing.assert_allclose(lik, np.full((1, 3), np.exp(-1.0)), rtol=1e-12)
    assert abs(lik[0, 0] - 0.368) < 5e-4


def test_walking_pattern_term() -> None:
    # P_walk = exp(-(S_d - κ S |cos φ|)² / (2σ_w²)): measured distance 0.1 m longer than predicted
    x, feet, sd = measured_walker()
    lik = lk.laser_likelihood(x[None, None], feet[None], np.array([sd + 0.1]), np.array([False]))
    np.testing.assert_allclose(lik, [[np.exp(-0.5)]], rtol=1e-6)  # cos φ is taken in float32 (speed)


def test_one_foot_uses_wider_sigma_and_no_walking_term() -> None:
    # B9: one_foot -> P_walk = 1 and σ_f = 0.15 m
    centre = np.array([1.0, 1.0])
    x = particle((1.1, 1.0), (1.0, 0.9), phi=0.0)  # each foot 0.1 m from the blob centre
    feet = np.stack([centre, centre])[None]
    lik = lk.laser_likelihood(x[None, None], feet, np.array([0.0]), np.array([True]))
    np.testing.assert_allclose(lik, [[np.exp(-0.02 / (2 * 0.15**2))]], rtol=1e-12)
    # any measured S_d, any phase: no walking-pattern term
    lik2 = lk.laser_likelihood(x[None, None], feet, np.array([0.9]), np.array([True]))
    np.testing.assert_allclose(lik2, lik)


def test_both_feet_nearest_the_same_barycentre() -> None:
    # B9: both predicted feet nearest f1, two barycentres -> the assignment with the smaller total distance
    f = np.array([[0.0, 0.0], [1.0, 0.0]])
    x = particle((0.1, 0.0), (-0.3, 0.0))  # L: 0.1 / 0.9 m, R: 0.3 / 1.3 m from f1 / f2
    # straight (L->f1, R->f2): 0.1 + 1.3 = 1.4 m; crossed (L->f2, R->f1): 0.9 + 0.3 = 1.2 m -> crossed
    expected = np.exp(-(0.9**2 + 0.3**2) / (2 * 0.1**2))
    got = lk.laser_log_likelihood(x[None, None], f[None], np.array([1.0]), np.array([False]),
                                  kappa=1.0 / 1.4)  # walking term: κ S |cos 0| = 1.0 = S_d -> 0
    np.testing.assert_allclose(got, [[np.log(expected)]], rtol=1e-12)


def test_total_euclidean_distance_decides_not_squares() -> None:
    # both feet nearest f1, and the Euclidean and squared totals disagree: B9 says "total distance"
    f = np.array([[0.0, 0.0], [4.0, 0.0]])
    y = np.sqrt(1.0 - 0.59375**2)
    x = particle((0.59375, y), (0.0, -3.0))  # |L-f1| = 1, |L-f2| = 3.5, |R-f1| = 3, |R-f2| = 5
    # straight (L->f1, R->f2): 1 + 5 = 6 m (squares 26); crossed: 3.5 + 3 = 6.5 m (squares 21.25)
    # -> straight, although its squared total is larger
    got = lk.laser_log_likelihood(x[None, None], f[None], np.array([4.0]), np.array([False]), sigma_f=1.0,
                                  kappa=4.0 / 1.4)  # walking term: κ S |cos 0| = 4 = S_d -> 0
    np.testing.assert_allclose(got, [[-26.0 / 2]], rtol=1e-12)


def test_vectorised_rows_missing_detections_and_log_domain() -> None:
    rng = np.random.default_rng(0)
    x, feet, sd = measured_walker()
    states = np.tile(x, (3, 50, 1))
    states[..., 0:4] += rng.normal(0, 0.05, size=(3, 50, 4))
    obs = np.stack([feet, feet + 50.0, np.full((2, 2), np.nan)])  # near, 50 m away, no detection
    log_l = lk.laser_log_likelihood(states, obs, np.array([sd, sd, np.nan]), np.zeros(3, bool))
    assert log_l.shape == (3, 50)
    assert np.isfinite(log_l).all()
    assert (log_l[0] > -10).all()
    assert (log_l[1] < -1e5).all()
    np.testing.assert_array_equal(log_l[2], 0.0)  # coasting row: weights untouched
    lik = lk.laser_likelihood(states, obs, np.array([sd, sd, np.nan]), np.zeros(3, bool))
    np.testing.assert_array_equal(lik[1], 0.0)
    # each row equals the row computed alone
    for t in range(2):
        alone = lk.laser_log_likelihood(states[t:t + 1], obs[t:t + 1], np.array([sd]), np.array([False]))
        np.testing.assert_allclose(log_l[t], alone[0])


def test_shape_errors_name_the_argument() -> None:
    x, feet, sd = measured_walker()
    with pytest.raises(ValueError, match="feet_obs"):
        lk.laser_log_likelihood(x[None, None], feet, np.array([sd]), np.array([False]))


def test_centroid_likelihood() -> None:
    # B18: Gaussian on the segment centroid, σ = 0.15 m
    p = np.array([[[1.0, 2.0, 0.5, 0.0], [1.15, 2.0, 0.0, 0.0]]])
    lik = lk.centroid_likelihood(p, np.array([[1.0, 2.0]]))
    np.testing.assert_allclose(lik, [[1.0, np.exp(-0.5)]])
    np.testing.assert_array_equal(lk.centroid_log_likelihood(p, np.array([[np.nan, np.nan]])), 0.0)
