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




def test_reweight_of_a_weight_of_minus_one_matches_numpy(numpy_path):
    # (the kernel's "no log taken yet" marker was -1.0: such a weight got log 0)
    w = np.array([[-1.0, 0.5, 0.5, 1.0]])
    with np.errstate(invalid="ignore"):  # (log of a negative weight)
        a, _ = pf.reweight(w, np.zeros((1, 4)))
        b, _ = numpy_path(pf.reweight, w, np.zeros((1, 4)))
    np.testing.assert_array_equal(a, b)


def test_the_kernels_clip_gait_as_the_walking_model_does():
    assert (_jit.P_LO, _jit.P_HI) == walking.PERIOD_RANGE_S
    assert (_jit.S_LO, _jit.S_HI) == walking.STRIDE_RANGE_M


def test_a_flag_array_of_the_wrong_length_is_an_error_not_a_read_past_its_end():
    cols = _cols(4)
    with pytest.raises(ValueError, match="standing"):
        walking.predict_people_cols(cols, np.zeros(3, bool), 0.04, np.random.default_rng(0))
    feet = np.zeros((4, 2, 2))
    with pytest.raises(ValueError, match="missing"):
        laser_log_likelihood_cols(cols, feet, np.zeros(4), np.zeros(4, bool), 0.1, 0.12, missing=np.zeros(2, bool))


def _two_walkers_one_stopping(n: int = 150) -> list:
    """Scans of two walkers, the second standing still from step 40 to 90 (the standing switch, the restart)."""
    from test_tracking_tracker import FRAME_NS, _detection, _walk

    rng = np.random.default_rng(0)
    _, feet1 = _walk(n, np.array([2.0, 2.0]), np.zeros(n), 1.2, 1.2)
    _, f2 = _walk(n, np.array([2.0, 6.0]), np.zeros(n), 1.0, 1.1)
    feet2 = f2[[i if i < 40 else (40 if i < 90 else i - 50) for i in range(n)]]
    return [((i + 1) * FRAME_NS, [_detection((i + 1) * FRAME_NS, feet1[i], rng), _detection((i + 1) * FRAME_NS,
                                                                                           feet2[i], rng)])
            for i in range(n)]


def test_the_tracker_update_matches_numpy_step_by_step(monkeypatch):
    """The update kernel (likelihood, reweight, centres, resampling), the velocity / standing kernels and their
    numpy fall-backs, in lockstep: from the same predicted particles, each step's update by the kernels and by the
    numpy code leaves the same tracker state and the same rng state."""
    import copy

    from fusiontrack.tracking.tracker import LaserPeopleTracker, detection_arrays

    fields = ("_x", "_w", "_id", "_seen", "_pos", "_lag", "_vel", "_slow", "_standing", "_reseed_at")
    trk = LaserPeopleTracker(rng=3, standing_speed_mps=0.3, resume_speed_mps=0.5)
    standing_seen = False
    for t_ns, dets in _two_walkers_one_stopping():
        det = detection_arrays(dets)
        dt = 0.0 if trk._t is None else min((t_ns - trk._t) / 1e9, trk.params.max_dt_s)
        trk._t = t_ns
        trk.events = []
        trk._predict(dt)
        twin = copy.deepcopy(trk)
        trk._update(t_ns, dt, det)
        monkeypatch.setattr(_jit, "ENABLED", False)
        twin._update(t_ns, dt, det)
        monkeypatch.setattr(_jit, "ENABLED", True)
        for f in fields:
            a, b = np.asarray(getattr(trk, f)), np.asarray(getattr(twin, f))
            if a.dtype.kind == "f":
                np.testing.assert_allclose(a, b, rtol=0, atol=1e-6, err_msg=f)
            else:
                np.testing.assert_array_equal(a, b, err_msg=f)
        assert trk.rng.random() == twin.rng.random()  # the same draws
        standing_seen |= bool(np.count_nonzero(trk._standing))
    assert standing_seen  # the standing switch (and the restart after it) was exercised
    assert trk._id.size == 2


def test_a_long_gap_gives_no_velocity_rather_than_an_error(numpy_path):
    """After a gap long enough that the velocity filter's gain rounds to 1, the lag is 0: the kernel raised
    ZeroDivisionError where numpy went on (with a NaN velocity). Now both give the same, finite velocity."""
    from fusiontrack.tracking.tracker import LaserPeopleTracker
    from test_tracking_tracker import FRAME_NS, _detection, _walk

    def run() -> np.ndarray:
        rng = np.random.default_rng(0)
        _, feet = _walk(40, np.array([2.0, 2.0]), np.zeros(40), 1.2, 1.2)
        trk = LaserPeopleTracker(rng=3, max_dt_s=30.0)
        for i in range(40):
            t = (i + 1) * FRAME_NS + (15_000_000_000 if i >= 20 else 0)
            trk.step(t, [_detection(t, feet[i], rng)])
        return np.array(trk._vel)

    a, b = run(), numpy_path(run)
    assert np.isfinite(a).all()
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)


_CACHED_KERNEL = '''
import numpy as np
from fusiontrack.tracking._jit import njit

@njit(cache=True)
def halve_sum(x):
    s = 0.0
    for v in x:
        s += 0.5 * v
    return s

print(halve_sum(np.arange(10.0)))
'''


@pytest.mark.skipif(not _jit.ENABLED, reason="numba not installed or disabled")
@pytest.mark.parametrize("damaged", ["nbc", "nbi"])
def test_a_damaged_kernel_cache_is_compiled_again(tmp_path, damaged):
    """A cache file cut short (a full disk, a killed process) gave numba's unpickling traceback at the kernel's first
    call, in every later run. Now it is a cache miss: the kernel compiles, warns once, and rewrites the file."""
    import os
    import subprocess
    import sys

    (tmp_path / "kern.py").write_text(_CACHED_KERNEL)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}  # the cache beside kern.py
    env["PYTHONPATH"] = str(tmp_path)

    def run() -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", "import logging; logging.basicConfig(); import kern"],
                              capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)

    first = run()
    assert first.returncode == 0, first.stderr
    assert first.stdout.strip() == "22.5"
    files = sorted((tmp_path / "__pycache__").glob(f"kern.halve_sum-*.{damaged}"))
    assert files, sorted(p.name for p in (tmp_path / "__pycache__").iterdir())
    for f in files:
        f.write_bytes(f.read_bytes()[:20])
    second = run()
    assert second.returncode == 0, second.stderr
    assert second.stdout.strip() == "22.5"
    assert "cannot be read" in second.stderr
    assert "compiling it again" in second.stderr
    third = run()  # the file was rewritten: read back without a word
    assert third.returncode == 0
    assert third.stdout.strip() == "22.5"
    assert "cannot be" not in third.stderr, third.stderr
