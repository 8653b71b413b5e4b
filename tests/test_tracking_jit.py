"""The numba kernels of the PF hot path (tracking/_jit.py) against the numpy code they replace."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.tracking import _jit, pf, walking
from fusiontrack.tracking.likelihood import laser_log_likelihood_cols

pytestmark = pytest.mark.skipif(not _jit.ENABLED, reason="numba not available / FUSIONTRACK_NUMBA=0")


@pytest.fixture
def numpy_path(monkeypatch):
    def run(f, *a, **k):
        monkeypatch.setattr(_jit, "ENABLED", False)
        try:
            return f(*a, **k)
        finally:
            monkeypatch.setattr(_jit, "ENABLED", True)
    return run


def _cols(n_t=4, n_p=100, seed=0):
    rng = np.random.default_rng(seed)
    x = walking.init_walking(rng.normal(size=(n_t, 2, 2)), n_p, rng, feet_sigma_m=0.05, period_sigma_s=0.1,
                             stride_sigma_m=0.2)
    return np.ascontiguousarray(np.moveaxis(x, -1, 0))


@pytest.mark.parametrize("standing", [[0, 0, 0, 0], [1, 0, 1, 0], [1, 1, 1, 1]])
def test_predict_people_matches_numpy_and_rng_stream(numpy_path, standing):
    cols = _cols()
    st = np.array(standing, bool)
    r1, r2 = np.random.default_rng(5), np.random.default_rng(5)
    nz, snz = walking.WalkingNoise(dt_ref_s=0.04), walking.StandingNoise(dt_ref_s=0.04)
    a = walking.predict_people_cols(cols, st, 0.05, r1, nz, snz)
    b = numpy_path(walking.predict_people_cols, cols, st, 0.05, r2, nz, snz)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-7)  # float32 sin/cos differ by an ulp (6e-8) at times
    assert r1.random() == r2.random()  # the same number of draws


def test_predict_without_noise(numpy_path):
    cols = _cols()
    st = np.zeros(4, bool)
    nz = walking.WalkingNoise.zero()
    a = walking.predict_people_cols(cols, st, 0.04, np.random.default_rng(1), nz)
    b = numpy_path(walking.predict_people_cols, cols, st, 0.04, np.random.default_rng(1), nz)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-7)


def test_likelihood_matches_numpy(numpy_path):
    cols = _cols(6)
    rng = np.random.default_rng(2)
    feet = cols[0:4, :, 0].T.reshape(6, 2, 2) + rng.normal(0, 0.1, (6, 2, 2))
    feet[2, 1] = feet[2, 0]  # both predicted feet nearest one barycentre
    sd = np.hypot(*(feet[:, 0] - feet[:, 1]).T)
    one = np.array([0, 0, 0, 1, 0, 1], bool)
    missing = np.array([0, 0, 0, 0, 1, 0], bool)
    for lateral in (0.0, 0.2):
        a = laser_log_likelihood_cols(cols, feet, sd, one, 0.1, 0.12, lateral_m=lateral, missing=missing)
        b = numpy_path(laser_log_likelihood_cols, cols, feet, sd, one, 0.1, 0.12, lateral_m=lateral, missing=missing)
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-12)  # float32 cos φ: an ulp apart at times
        assert np.all(a[4] == 0)


def test_reweight_and_resample_match_numpy(numpy_path):
    cols = _cols(5)
    rng = np.random.default_rng(3)
    w = rng.random((5, 100))
    w /= w.sum(axis=1, keepdims=True)
    ll = -rng.random((5, 100)) * 50
    a, da = pf.reweight(w, ll)
    b, db = numpy_path(pf.reweight, w, ll)
    np.testing.assert_allclose(a, b, rtol=1e-13)
    sel = np.array([1, 0, 1, 1, 0], bool)
    xa, wa = pf.resample_where_cols(cols, b, sel, np.random.default_rng(9))
    xb, wb = numpy_path(pf.resample_where_cols, cols, b, sel, np.random.default_rng(9))
    assert np.array_equal(xa, xb)
    assert np.array_equal(wa, wb)
    # all -inf row: the general path
    ll[1] = -np.inf
    a, da = pf.reweight(w, ll)
    b, db = numpy_path(pf.reweight, w, ll)
    assert np.array_equal(a, b)
    assert np.array_equal(da, db)
    assert da[1]


