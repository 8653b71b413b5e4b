"""Segment and window features (ALGORITHMS.md B18) against shapes with known geometry."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.laser.features import GEOMETRIC_FEATURES, WINDOW_FEATURES, segment_features, window_features

G = {name: i for i, name in enumerate(GEOMETRIC_FEATURES)}
W = {name: i for i, name in enumerate(WINDOW_FEATURES)}


def arc(centre, radius, a0, a1, n):
    a = np.linspace(a0, a1, n)
    return np.column_stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)])


def test_shapes_with_known_geometry():
    circle = arc((3.0, 1.0), 0.3, np.pi / 2, 3 * np.pi / 2, 25)  # half circle facing a scanner at the origin
    line = np.column_stack([np.linspace(0.0, 1.7, 35), np.full(35, 2.0)])
    ell = np.vstack([np.column_stack([np.linspace(0, 4.5, 46), np.zeros(46)]),
                     np.column_stack([np.full(18, 4.5), np.linspace(0.1, 1.8, 18)])])
    pts = np.vstack([circle, line, ell])
    labels = np.repeat([0, 1, 2], [len(circle), len(line), len(ell)])
    f = segment_features(pts, labels)
    assert f.shape == (3, len(GEOMETRIC_FEATURES))
    np.testing.assert_array_equal(f[:, G["n_points"]], [25, 35, 64])
    # The half circle: radius exact, circle residual 0, width the diameter, thickness the radius.
    assert f[0, G["radius_m"]] == pytest.approx(0.3, abs=1e-9)
    assert f[0, G["circularity_m"]] == pytest.approx(0.0, abs=1e-9)
    assert f[0, G["width_m"]] == pytest.approx(0.6, abs=1e-3)
    assert f[0, G["thickness_m"]] == pytest.approx(0.3, abs=0.01)
    assert f[0, G["boundary_length_m"]] == pytest.approx(np.pi * 0.3, rel=0.01)
    assert f[0, G["mean_curvature_rad"]] == pytest.approx(np.pi / 24, rel=1e-6)  # 24 equal turns over pi
    # The straight line: no thickness, no line residual, no turning, length = width = boundary.
    assert f[1, G["width_m"]] == pytest.approx(1.7)
    assert f[1, G["thickness_m"]] == pytest.approx(0.0, abs=1e-9)
    assert f[1, G["linearity_m"]] == pytest.approx(0.0, abs=1e-9)
    assert f[1, G["boundary_length_m"]] == pytest.approx(1.7)
    assert f[1, G["mean_curvature_rad"]] == pytest.approx(0.0, abs=1e-9)
    assert f[1, G["std_m"]] == pytest.approx(1.7 / np.sqrt(12), rel=0.05)  # uniform on a segment
    # The L: one right-angle turn among 63 steps, long axis ~ the 4.5 m side.
    assert f[2, G["width_m"]] == pytest.approx(4.5, rel=0.1)
    assert f[2, G["linearity_m"]] > 0.2
    assert f[2, G["mean_curvature_rad"]] == pytest.approx((np.pi / 2) / 62, rel=0.05)


def test_subclusters_count_the_gaps():
    leg1 = arc((2.0, -0.15), 0.06, np.pi / 2, 3 * np.pi / 2, 8)
    leg2 = arc((2.0, 0.15), 0.06, np.pi / 2, 3 * np.pi / 2, 8)
    f = segment_features(np.vstack([leg1, leg2]), np.zeros(16, int))
    assert f[0, G["n_subclusters"]] == 2


def test_order_free_features_do_not_depend_on_point_order():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(40, 2))
    labels = rng.integers(0, 4, 40)
    perm = rng.permutation(40)
    a, b = segment_features(pts, labels), segment_features(pts[perm], labels[perm])
    order_free = [G[n] for n in ("n_points", "std_m", "mad_median_m", "width_m", "thickness_m", "linearity_m",
                                 "circularity_m", "radius_m")]
    np.testing.assert_allclose(a[:, order_free], b[:, order_free], atol=1e-9)


def test_empty_segments_and_bad_labels():
    f = segment_features(np.zeros((0, 2)), np.zeros(0, int), 3)
    assert f.shape == (3, len(GEOMETRIC_FEATURES))
    assert not f.any()
    with pytest.raises(ValueError, match="labels"):
        segment_features(np.zeros((3, 2)), np.zeros(2, int))


def _windows(centres, widths=None, axis=0.0, dt=0.1):
    m, w = centres.shape[:2]
    g = np.zeros((m, w, len(GEOMETRIC_FEATURES)))
    g[..., G["width_m"]] = 0.4 if widths is None else widths
    g[..., G["axis_rad"]] = axis
    return window_features(g, centres, np.arange(w) * dt)


def test_window_speed_heading_alignment():
    t = np.arange(10) * 0.1
    straight = np.column_stack([1.5 * t, np.zeros(10)])  # 1.5 m/s along x
    still = np.zeros((10, 2))
    # A turn of 90 degrees between the halves: first along x, then along y.
    turn = np.vstack([np.column_stack([np.linspace(0, 0.5, 5), np.zeros(5)]),
                      np.column_stack([np.full(5, 0.5), [*np.linspace(0.125, 0.5, 4).tolist(), 0.6]])])
    out = _windows(np.stack([straight, still, turn]), axis=0.0)
    assert out[0, W["speed_mps"]] == pytest.approx(1.5)
    assert out[0, W["speed_std_mps"]] == pytest.approx(0.0, abs=1e-6)
    assert out[0, W["heading_rate_radps"]] == pytest.approx(0.0, abs=1e-9)
    assert out[0, W["motion_alignment"]] == pytest.approx(1.0)  # moves along its long axis (a bicycle)
    assert out[1, W["speed_mps"]] == 0.0
    assert out[1, W["motion_alignment"]] == 0.5
    assert out[2, W["heading_rate_radps"]] > 1.0
    across = _windows(straight[None], axis=np.pi / 2)  # a car seen end-on moves across its visible side
    assert across[0, W["motion_alignment"]] == pytest.approx(0.0, abs=1e-9)


def test_gait_periodicity_finds_a_walking_rhythm():
    t = np.arange(10) * 0.1
    c = np.zeros((2, 10, 2))
    widths = np.stack([0.35 + 0.15 * np.cos(2 * np.pi * 1.25 * t),  # feet open and close at 1.25 Hz
                       np.full(10, 0.35)])
    out = _windows(c, widths=widths)
    assert out[0, W["gait_periodicity"]] > 0.5
    assert out[1, W["gait_periodicity"]] == 0.0
    assert out[0, W["width_std_m"]] == pytest.approx(np.std(widths[0]))


def test_invalid_frames_are_ignored():
    t = np.arange(10) * 0.1
    c = np.column_stack([t, np.zeros(10)])[None].copy()
    valid = np.ones((1, 10), bool)
    c[0, 4] = [50.0, 50.0]  # a wrong association in frame 4, flagged invalid
    valid[0, 4] = False
    g = np.zeros((1, 10, len(GEOMETRIC_FEATURES)))
    out = window_features(g, c, t, valid)
    assert out[0, W["speed_mps"]] == pytest.approx(1.0)
