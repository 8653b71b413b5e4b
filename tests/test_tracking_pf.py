"""SIR particle-filter core (ALGORITHMS.md X1): known answers and invariants."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.tracking import pf


@pytest.mark.parametrize("u0", [0.0, 0.01, 0.1, 0.125, 0.2, 0.24, 0.25 - 1e-12])
def test_systematic_resample_x1_counts(u0: float) -> None:
    # X1: weights [0.5, 0.25, 0.25] with N = 4 give counts {2, 1, 1} for every u0 in [0, 1/4)
    idx = pf.systematic_resample(np.array([0.5, 0.25, 0.25]), u0=u0, n=4)
    assert np.bincount(idx, minlength=3).tolist() == [2, 1, 1]


def test_systematic_resample_strict_inequality_at_u0_zero() -> None:
    # u = 0, 1/4, 2/4, 3/4 against C = 0.25, 0.5, 0.75, 1: "first index with C > u" (strict) gives
    # one draw each; a non-strict "C >= u" would give particle 0 twice (u = 0 and u = 0.25).
    idx = pf.systematic_resample(np.full(4, 0.25), u0=0.0)
    assert idx.tolist() == [0, 1, 2, 3]
    # zero-weight particles are never drawn, even with u0 = 0 on their cumulative boundary
    idx = pf.systematic_resample(np.array([0.0, 0.5, 0.0, 0.5]), u0=0.0)
    assert idx.tolist() == [1, 1, 3, 3]


def test_systematic_resample_vectorised_rows_and_rng() -> None:
    rng = np.random.default_rng(1)
    w = np.tile([0.5, 0.25, 0.25], (50, 1))
    idx = pf.systematic_resample(w, rng, n=4)
    assert idx.shape == (50, 4)
    counts = np.stack([np.bincount(row, minlength=3) for row in idx])
    assert (counts == [2, 1, 1]).all()


def test_systematic_resample_counts_are_floor_or_ceil() -> None:
    # invariant of systematic resampling: particle i is drawn floor(N w_i) or ceil(N w_i) times
    rng = np.random.default_rng(2)
    w = rng.random((20, 37)) ** 3
    w /= w.sum(axis=1, keepdims=True)
    idx = pf.systematic_resample(w, rng)
    assert idx.shape == w.shape
    assert (np.diff(idx, axis=1) >= 0).all()  # sorted ancestors
    counts = np.stack([np.bincount(row, minlength=37) for row in idx])
    nw = 37 * w
    assert ((counts >= np.floor(nw) - 1e-9) & (counts <= np.ceil(nw) + 1e-9)).all()


def test_systematic_resample_rejects_bad_u0() -> None:
    with pytest.raises(ValueError, match="u0"):
        pf.systematic_resample(np.full(4, 0.25), u0=0.25)


def test_effective_sample_size() -> None:
    n = 100
    w = np.zeros((3, n))
    w[0] = 1.0 / n
    w[1, 7] = 1.0
    w[2, :2] = 0.5
    np.testing.assert_allclose(pf.effective_sample_size(w), [n, 1.0, 2.0])


def test_normalise_log_weights_log_domain_and_degenerate() -> None:
    log_w = np.array([
        [-1000.0, -1001.0, -np.inf],  # would underflow to 0 / 0 in the linear domain
        [-np.inf, -np.inf, -np.inf],  # nothing explains the measurement: uniform + flag
        [0.0, np.nan, 0.0],  # NaN has no support
    ])
    w, degenerate = pf.normalise_log_weights(log_w)
    np.testing.assert_allclose(w[0], [1 / (1 + np.exp(-1)), np.exp(-1) / (1 + np.exp(-1)), 0.0])
    np.testing.assert_allclose(w[1], 1 / 3)
    np.testing.assert_allclose(w[2], [0.5, 0.0, 0.5])
    assert degenerate.tolist() == [False, True, False]


def test_reweight_keeps_weights_when_log_likelihood_is_zero() -> None:
    w = np.array([[0.1, 0.2, 0.7]])
    w2, deg = pf.reweight(w, np.zeros((1, 3)))
    np.testing.assert_allclose(w2, w)
    assert not deg.any()


def test_resample_where_only_touches_selected_rows() -> None:
    rng = np.random.default_rng(3)
    x = rng.normal(size=(3, 5, 2))
    w = np.array([[1, 0, 0, 0, 0], [0.2] * 5, [0, 0, 0, 0, 1]], dtype=float)
    x2, w2 = pf.resample_where(x, w, np.array([True, False, True]), rng)
    np.testing.assert_array_equal(x2[0], np.repeat(x[0, :1], 5, axis=0))
    np.testing.assert_array_equal(x2[1], x[1])
    np.testing.assert_array_equal(x2[2], np.repeat(x[2, 4:], 5, axis=0))
    np.testing.assert_allclose(w2, [[0.2] * 5] * 3)
    # all rows: the same as gathering each row by its systematic indices
    x3, _ = pf.resample_where(x, w, True, u0=0.1)
    idx = pf.systematic_resample(w, u0=0.1)
    np.testing.assert_array_equal(x3, np.take_along_axis(x, idx[:, :, None], axis=1))


def test_weighted_mean_cov_and_circular_columns() -> None:
    rng = np.random.default_rng(4)
    x = rng.normal(size=(2, 400, 3))
    w = rng.random((2, 400))
    w /= w.sum(axis=1, keepdims=True)
    mean = pf.weighted_mean(x, w)
    cov = pf.weighted_cov(x, w)
    for t in range(2):
        np.testing.assert_allclose(mean[t], np.average(x[t], axis=0, weights=w[t]))
        np.testing.assert_allclose(cov[t], np.cov(x[t].T, aweights=w[t], bias=True))
    # angles either side of ±π average to π, not to 0
    ang = np.array([[[np.pi - 0.1], [-np.pi + 0.1]]])
    m = pf.weighted_mean(ang, np.array([[0.5, 0.5]]), circular=[0])
    assert abs(abs(m[0, 0]) - np.pi) < 1e-12
    c = pf.weighted_cov(ang, np.array([[0.5, 0.5]]), circular=[0])
    np.testing.assert_allclose(c[0, 0, 0], 0.01)


def test_max_weight_cluster_mean_picks_the_heaviest_mode() -> None:
    rng = np.random.default_rng(5)
    a = rng.normal([0.0, 0.0], 0.05, size=(300, 2))
    b = rng.normal([3.0, 0.0], 0.05, size=(300, 2))
    x = np.concatenate([a, b])[None]
    w = np.concatenate([np.full(300, 1.0), np.full(300, 1.2)])[None]
    w /= w.sum()
    mean, inside = pf.max_weight_cluster_mean(x, w, radius=0.5)
    np.testing.assert_allclose(mean[0], b.mean(axis=0), atol=1e-12)
    assert inside[0, 300:].all()
    assert not inside[0, :300].any()
    # the plain weighted mean lies between the modes
    assert 1.0 < pf.weighted_mean(x, w)[0, 0] < 2.0


def test_pf_matches_kalman_posterior_1d() -> None:
    # X1: a 1-D constant-position target with Gaussian likelihood matches the Kalman posterior mean
    # within 2 % for N = 2000 (here: 4 independent filters at once, 15 measurements, small process noise)
    rng = np.random.default_rng(6)
    n_t, n_p, steps = 4, 2000, 15
    x_true, m0, p0, r, q = 5.0, 4.0, 1.0, 0.5**2, 0.02**2
    z = x_true + np.sqrt(r) * rng.standard_normal((steps, n_t))
    particles = m0 + np.sqrt(p0) * rng.standard_normal((n_t, n_p, 1))
    w = pf.uniform_weights(n_t, n_p)
    m, p = np.full(n_t, m0), np.full(n_t, p0)
    for k in range(steps):
        particles = particles + np.sqrt(q) * rng.standard_normal(particles.shape)
        p = p + q
        log_lik = -((particles[..., 0] - z[k][:, None]) ** 2) / (2 * r)
        w, deg = pf.reweight(w, log_lik)
        assert not deg.any()
        gain = p / (p + r)
        m, p = m + gain * (z[k] - m), (1 - gain) * p
        est = pf.weighted_mean(particles, w)[:, 0]
        np.testing.assert_allclose(est, m, rtol=0.02)
        particles, w = pf.resample_where(particles, w, pf.effective_sample_size(w) < n_p / 2, rng)
    # the spread matches too (looser: a second moment from 2000 samples)
    np.testing.assert_allclose(pf.weighted_cov(particles, w)[:, 0, 0], p, rtol=0.25)


@pytest.mark.parametrize("mask", [[True, True, True], [False, True, False], [False, False, False]])
def test_resample_where_cols_is_resample_where_in_the_column_layout(mask: list[bool]) -> None:
    """The laser tracker's column layout (d, n_t, n_p) resamples exactly as the row layout (n_t, n_p, d): the same
    draws from the same generator state, the same ancestors, the same weights."""
    rng = np.random.default_rng(7)
    x = rng.normal(size=(3, 50, 8))
    w = rng.random((3, 50))
    w /= w.sum(axis=1, keepdims=True)
    sel = np.array(mask)
    x_rows, w_rows = pf.resample_where(x, w, sel, np.random.default_rng(1))
    cols, w_cols = pf.resample_where_cols(np.ascontiguousarray(np.moveaxis(x, -1, 0)), w, sel, np.random.default_rng(1))
    assert np.array_equal(np.moveaxis(cols, 0, -1), x_rows)
    assert np.array_equal(w_cols, w_rows)
    # unselected targets keep their particles and weights as they were
    assert np.array_equal(x_rows[~sel], x[~sel])
    assert np.array_equal(w_rows[~sel], w[~sel])
