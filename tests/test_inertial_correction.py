"""Thin-plate-spline drift correction (seed 002 Eqs. 4–8, ALGORITHMS.md C8, C14)."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.inertial import control_pairs, correct_trajectory, dead_reckon, fit_correction


def _affine(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    A = np.array([[1.05, -0.2], [0.15, 0.9]]) + rng.normal(0, 0.05, (2, 2))
    return A, rng.normal(0, 3, 2)


def test_smoothing_zero_interpolates_exactly() -> None:
    rng = np.random.default_rng(0)
    src = rng.uniform(-10, 10, (25, 2))
    dst = src + rng.normal(0, 0.5, src.shape) + 0.02 * src**2  # a non-affine warp
    f = fit_correction(src, dst, smoothing=0.0)
    assert f.kind == "tps"
    np.testing.assert_allclose(f(src), dst, atol=1e-9)
    # with smoothing the fit no longer passes through the points, but stays close
    g = fit_correction(src, dst, smoothing=5.0)
    residual = np.linalg.norm(g(src) - dst, axis=1)
    assert residual.max() > 1e-3
    assert residual.mean() < 1.0


def test_affine_map_is_reproduced_everywhere() -> None:
    # ALGORITHMS.md C8 test: M_2 = A·M_1 + t -> f is that affine map, also far outside the control points
    rng = np.random.default_rng(1)
    A, t = _affine(rng)
    src = rng.uniform(-5, 5, (12, 2))
    f = fit_correction(src, src @ A.T + t)
    query = rng.uniform(-50, 50, (100, 2))
    np.testing.assert_allclose(f(query), query @ A.T + t, atol=1e-9)
    # and for a rotation, its local rotation is the rotation angle
    c, s = np.cos(0.3), np.sin(0.3)
    rot = fit_correction(src, src @ np.array([[c, -s], [s, c]]).T)
    np.testing.assert_allclose(rot.rotation_at(query[:5]), 0.3, atol=1e-6)


def test_collinear_points_fall_back_to_a_rigid_fit() -> None:
    # one straight pass through one camera's view: collinear control points (ALGORITHMS.md C8 edge case)
    rng = np.random.default_rng(2)
    src = np.stack([np.linspace(0, 6, 10), 0.5 * np.linspace(0, 6, 10) + 1.0], axis=1)
    c, s = np.cos(0.1), np.sin(0.1)
    R = np.array([[c, -s], [s, c]])
    dst = src @ R.T + (2.0, -1.0)
    f = fit_correction(src, dst)
    assert f.kind == "rigid"
    query = rng.uniform(-20, 20, (50, 2))
    out = f(query)
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(out, query @ R.T + (2.0, -1.0), atol=1e-9)
    # nearly collinear (1 cm off a 6 m line) is collinear too
    wobbly = src + np.stack([np.zeros(10), 0.01 * (-1.0) ** np.arange(10)], axis=1)
    assert fit_correction(wobbly, dst).kind == "rigid"


def test_few_points_and_duplicates() -> None:
    assert fit_correction(np.zeros((0, 2)), np.zeros((0, 2)))(np.ones((3, 2))).tolist() == np.ones((3, 2)).tolist()
    one = fit_correction([[1.0, 2.0]], [[1.5, 1.0]])
    assert one.kind == "translation"
    np.testing.assert_allclose(one([[0.0, 0.0], [10.0, 10.0]]), [[0.5, -1.0], [10.5, 9.0]])
    two = fit_correction([[0.0, 0.0], [1.0, 0.0]], [[1.0, 1.0], [1.0, 2.0]])
    assert two.kind == "rigid"
    np.testing.assert_allclose(two([[0.5, 0.0]]), [[1.0, 1.5]], atol=1e-12)
    # duplicates (same place, 1 mm apart) would make the spline singular: dropped, and the fit exact
    src = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 5.0], [5.0, 5.0], [5.0005, 5.0]])
    dst = src + np.array([[0.1, 0.0], [0.0, 0.1], [-0.1, 0.0], [0.2, 0.2], [0.2, 0.2]])
    f = fit_correction(src, dst)
    assert f.kind == "tps"
    assert f.src_m.shape[0] == 4
    np.testing.assert_allclose(f(src[:4]), dst[:4], atol=1e-9)


def test_control_pairs_interpolate_and_thin() -> None:
    traj_t = np.array([0, 10, 20], dtype=np.int64) * 1_000_000_000
    traj = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    obs_t = np.array([-5, 5, 5.1, 5.2, 15, 25], dtype=float) * 1e9
    obs = np.array([[9.0, 9.0], [5.0, 1.0], [5.1, 1.0], [5.6, 1.0], [10.0, 5.0], [0.0, 0.0]])
    t, src, dst = control_pairs(traj_t, traj, obs_t.astype(np.int64), obs, min_spacing_m=0.5)
    np.testing.assert_array_equal(t, (np.array([5, 5.2, 15]) * 1e9).astype(np.int64))
    np.testing.assert_allclose(src, [[5.0, 0.0], [5.2, 0.0], [10.0, 5.0]])
    np.testing.assert_allclose(dst, [[5.0, 1.0], [5.6, 1.0], [10.0, 5.0]])


def _figure_eight_walk(seed: int):
    """ALGORITHMS.md C14 recipe: a 70 m x 30 m figure-eight at 1.3 m/s for 200 s, a step every 0.55 s,
    3 % step-length noise, a residual yaw bias from N(0.037, 0.01) deg/s, 8 camera zones of 3.5 m
    radius along the path seeing the walker at 30 Hz with 5 cm noise."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 2 * np.pi, 20001)
    curve = np.stack([35 * np.sin(s), 15 * np.sin(2 * s)], axis=1)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
    n = int(200 / 0.55)
    t_ns = np.arange(n + 1) * 550_000_000
    along = (np.arange(n + 1) * 0.55 * 1.3) % arc[-1]
    truth = np.stack([np.interp(along, arc, curve[:, 0]), np.interp(along, arc, curve[:, 1])], axis=1)
    d = np.diff(truth, axis=0)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0])) + np.deg2rad(rng.normal(0.037, 0.01)) * t_ns[1:] * 1e-9
    lengths = np.linalg.norm(d, axis=1) * (1 + 0.03 * rng.standard_normal(n))
    dr = np.vstack([truth[:1], dead_reckon(lengths, heading, truth[0])])
    zones_along = arc[-1] * (np.arange(8) + 0.5) / 8
    zones = np.stack([np.interp(zones_along, arc, curve[:, 0]), np.interp(zones_along, arc, curve[:, 1])], axis=1)
    obs_t = np.arange(0, t_ns[-1], 1_000_000_000 // 30)
    obs = np.stack([np.interp(obs_t, t_ns, truth[:, 0]), np.interp(obs_t, t_ns, truth[:, 1])], axis=1)
    seen = np.min(np.linalg.norm(obs[:, None] - zones[None], axis=2), axis=1) < 3.5
    obs_noisy = obs[seen] + rng.normal(0, 0.05, (int(seen.sum()), 2))
    return t_ns, truth, dr, obs_t[seen], obs_noisy


def _window_means(t_ns: np.ndarray, err: np.ndarray) -> np.ndarray:
    window = np.minimum(t_ns // 20_000_000_000, 9)
    return np.array([err[window == k].mean() for k in range(10)])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_c14_causal_correction_removes_the_drift(seed: int) -> None:
    t_ns, truth, dr, obs_t, obs = _figure_eight_walk(seed)
    tc, src, dst = control_pairs(t_ns, dr, obs_t, obs)
    assert 100 < tc.size < 200
    before = _window_means(t_ns, np.linalg.norm(dr - truth, axis=1))
    for rotate in ("pass", "none"):
        corrected = correct_trajectory(t_ns, dr, tc, src, dst, rotate=rotate)
        after = _window_means(t_ns, np.linalg.norm(corrected - truth, axis=1))
        # C14 target: "after" <= 2.5 m in every 20 s window; and well below "before" once drift has built up
        assert np.all(after <= 2.5), (rotate, after)
        assert after[3:].mean() < 0.5 * before[3:].mean(), (rotate, before, after)
    # the drift before correction grows (super-linearly in its first minute and a half, C14)
    assert before[4] > 2 * before[2] > 4 * before[0]


def test_causal_correction_uses_only_the_past() -> None:
    t_ns, _, dr, obs_t, obs = _figure_eight_walk(3)
    tc, src, dst = control_pairs(t_ns, dr, obs_t, obs)
    full = correct_trajectory(t_ns, dr, tc, src, dst)
    # positions before the first control point are untouched
    early = t_ns < tc[0]
    np.testing.assert_array_equal(full[early], dr[early])
    # control points after time T change nothing before T
    T = tc[len(tc) // 2]
    keep = tc <= T
    partial = correct_trajectory(t_ns, dr, tc[keep], src[keep], dst[keep])
    before_T = t_ns < T
    np.testing.assert_allclose(partial[before_T], full[before_T], atol=1e-9)
    # non-causal: one fit of every control point re-maps the whole trajectory
    offline = correct_trajectory(t_ns, dr, tc, src, dst, causal=False)
    assert np.linalg.norm(offline[early] - dr[early], axis=1).max() > 0.0


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="src_m, dst_m"):
        fit_correction(np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="src_m: row 1"):
        fit_correction([[0.0, 0.0], [np.nan, 1.0]], [[0.0, 0.0], [1.0, 1.0]])
    with pytest.raises(ValueError, match="smoothing"):
        fit_correction(np.zeros((3, 2)), np.zeros((3, 2)), smoothing=-1.0)
    t = np.arange(3, dtype=np.int64)
    with pytest.raises(ValueError, match="rotate"):
        correct_trajectory(t, np.zeros((3, 2)), t, np.zeros((3, 2)), np.zeros((3, 2)), rotate="jacobian")
    with pytest.raises(ValueError, match="non-decreasing"):
        correct_trajectory(t, np.zeros((3, 2)), t[::-1].copy(), np.zeros((3, 2)), np.zeros((3, 2)))
