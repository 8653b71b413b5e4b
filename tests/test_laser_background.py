"""Per-beam laser background (ALGORITHMS.md A7, B3): known answers, robustness of the mode, bad data."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from fusiontrack.laser.background import BeamBackground, clean_ranges, histogram_mode

RNG_SEED = 20240604


def _learn(bg: BeamBackground, scans: np.ndarray) -> np.ndarray:
    """Feed ``(n_scans, n_beams)`` ranges; return the ``(n_scans, n_beams)`` foreground masks."""
    return np.array([bg.update(s) for s in scans])


# ---- A7 known answers ------------------------------------------------------------------------------


@pytest.mark.parametrize("init", ["mode", "median"])
def test_static_scene_converges_within_1cm(init: str) -> None:
    """A7 test: a static scene converges to within 1 cm of the true range (σ = 1 cm noise)."""
    rng = np.random.default_rng(RNG_SEED)
    true = rng.uniform(0.5, 8.0, 360)
    bg = BeamBackground(360, n_init=50, init=init)
    fg = _learn(bg, true + rng.normal(0.0, 0.01, (300, 360)))
    assert not fg[:50].any()  # nothing is foreground while learning
    assert fg[50:].mean() < 1e-4  # a 20σ threshold: essentially never
    assert np.max(np.abs(bg.background_m - true)) < 0.01


def test_background_follows_a_small_shift_at_rate_beta() -> None:
    """A7: readings within tau update at beta, so a 10 cm shift decays as (1 - beta)^n."""
    bg = BeamBackground(10, beta=0.05, n_init=5)
    _learn(bg, np.full((5, 10), 4.0))
    n = math.ceil(math.log(0.01 / 0.1) / math.log(1 - 0.05))  # 45 frames to get within 1 cm
    fg = _learn(bg, np.full((n, 10), 4.1))
    assert not fg.any()
    assert np.all(np.abs(bg.background_m - 4.1) <= 0.01 + 1e-12)
    assert np.all(np.abs(bg.background_m - 4.1) > 0.0095)  # and not much faster: it is the beta rate


def test_person_in_front_of_wall_stays_foreground_about_540_frames() -> None:
    """A7 test: person at 3 m before a wall at 6 m is foreground for ln(tau/3)/ln(1-alpha) ≈ 540 frames."""
    alpha, tau = 0.005, 0.20
    bg = BeamBackground(4, alpha=alpha, tau_fg_m=tau, n_init=50)
    _learn(bg, np.full((50, 4), 6.0))
    fg = _learn(bg, np.full((700, 4), 3.0))
    n_fg = int(fg[:, 0].sum())
    assert np.all(fg.sum(axis=0) == n_fg)
    assert not fg[n_fg:].any()  # once absorbed it stays background
    expected = math.log(tau / 3.0) / math.log(1.0 - alpha)
    assert expected == pytest.approx(540.25, abs=0.01)
    assert abs(n_fg - expected) <= 2


def test_reading_beyond_the_background_is_never_foreground_and_is_learnt_fast() -> None:
    """A person standing in the beam during initialisation leaves: the wall behind is not a person."""
    bg = BeamBackground(3, n_init=20)
    _learn(bg, np.full((20, 3), 2.0))  # learnt the person at 2 m
    fg = _learn(bg, np.full((100, 3), 5.0))  # the wall at 5 m reappears
    assert not fg.any()
    # gamma = beta by default: after 100 frames the gap is 3 m * 0.95**100 = 1.8 cm.
    assert bg.background_m == pytest.approx(np.full(3, 5.0 - 3.0 * 0.95**100))
    # A7's literal symmetric rule (gamma = alpha) moves far more slowly.
    slow = BeamBackground(3, n_init=20, gamma=0.005)
    _learn(slow, np.full((20, 3), 2.0))
    _learn(slow, np.full((100, 3), 5.0))
    assert slow.background_m == pytest.approx(np.full(3, 5.0 - 3.0 * 0.995**100))


# ---- B3: the histogram mode -----------------------------------------------------------------------


def _occluded_scans(rng: np.random.Generator, true: np.ndarray, n_scans: int, fraction: float,
                    noise_m: float = 0.0) -> np.ndarray:
    """Static ranges with ``fraction`` of the beams of every scan occluded by walkers nearer than the wall."""
    scans = np.tile(true, (n_scans, 1)) + rng.normal(0.0, noise_m, (n_scans, true.size)) * (noise_m > 0)
    occluded = rng.random(scans.shape) < fraction
    walkers = rng.uniform(0.3, 1.0, scans.shape) * (true - 0.2)
    return np.where(occluded, walkers, scans)


def test_mode_recovers_static_range_with_20_percent_occlusion() -> None:
    """B3 test: 500 scans, 20 % of beams occluded by walkers -> the exact static range for >= 99 % of beams."""
    rng = np.random.default_rng(RNG_SEED)
    true = rng.uniform(1.0, 10.0, 720).astype(np.float32).astype(np.float64)  # ranges are float32
    bg = BeamBackground(720, n_init=500, init="mode")
    _learn(bg, _occluded_scans(rng, true, 500, 0.20))
    exact = np.abs(bg.background_m - true) < 1e-9
    assert exact.mean() >= 0.99
    # With 1 cm noise: within 5 mm (the median of the readings in the mode window).
    bg_noisy = BeamBackground(720, n_init=500, init="mode")
    _learn(bg_noisy, _occluded_scans(rng, true, 500, 0.20, noise_m=0.01))
    assert (np.abs(bg_noisy.background_m - true) < 0.005).mean() >= 0.99


def test_mode_survives_majority_occlusion_where_median_fails() -> None:
    """Why the mode: beams occluded in 60 % of the initial scans by moving walkers still recover the wall."""
    rng = np.random.default_rng(RNG_SEED + 1)
    true = rng.uniform(3.0, 8.0, 200).astype(np.float32).astype(np.float64)
    scans = _occluded_scans(rng, true, 100, 0.60)
    mode = BeamBackground(200, n_init=100, init="mode")
    median = BeamBackground(200, n_init=100, init="median")
    _learn(mode, scans)
    _learn(median, scans)
    assert (np.abs(mode.background_m - true) < 1e-9).mean() >= 0.95
    assert (np.abs(median.background_m - true) < 0.05).mean() < 0.2


def test_histogram_mode_straddling_a_bin_edge_beats_a_single_bin_passer_by() -> None:
    """A wall whose noise straddles a bin edge keeps its votes (3-bin window), refined below the bin width."""
    wall = np.array([2.0] * 4 + [2.049, 2.051] * 8)[:, None]  # 20 readings split over bins 40 and 41
    passer = np.full((9, 1), 1.22)  # 9 readings in one bin: more than either half of the wall
    stack = np.vstack([wall, passer])
    b = histogram_mode(stack, 0.05)
    assert b[0] == pytest.approx(2.049, abs=0.002)


def test_beam_without_return_gets_range_max_and_later_returns_are_foreground() -> None:
    """A7 edge case: no return during initialisation -> background = r_max."""
    bg = BeamBackground(3, n_init=10, range_max_m=8.0)
    scans = np.tile([np.nan, 4.0, np.inf], (10, 1))
    scans[3, 0] = 2.0  # one passer-by in 10 scans does not become the background
    _learn(bg, scans)
    assert bg.background_m == pytest.approx([8.0, 4.0, 8.0])
    assert bg.update(np.array([3.0, 4.0, 7.9])).tolist() == [True, False, False]


def test_infinite_range_max_adopts_the_first_return() -> None:
    bg = BeamBackground(2, n_init=3)
    _learn(bg, np.tile([np.nan, 4.0], (3, 1)))
    assert np.isnan(bg.background_m[0])
    assert bg.update(np.array([5.0, 4.0])).tolist() == [False, False]
    assert bg.background_m[0] == 5.0
    assert bg.update(np.array([2.0, 4.0])).tolist() == [True, False]


# ---- bad data ---------------------------------------------------------------------------------------


def test_invalid_readings_are_never_foreground_and_never_learnt() -> None:
    bg = BeamBackground(6, n_init=5, range_min_m=0.05, range_max_m=20.0)
    _learn(bg, np.full((5, 6), 5.0))
    before = bg.background_m.copy()
    bad = np.array([np.nan, np.inf, -np.inf, 0.0, -1.0, 25.0])
    for _ in range(50):
        fg = bg.update(bad)
        assert not fg.any()
    np.testing.assert_array_equal(bg.background_m, before)
    assert np.isnan(clean_ranges(bad, 0.05, 20.0)).all()


def test_bad_readings_during_initialisation_are_ignored() -> None:
    rng = np.random.default_rng(RNG_SEED)
    scans = np.full((50, 100), 6.0)
    corrupt = rng.random(scans.shape) < 0.3
    scans[corrupt] = rng.choice([np.nan, np.inf, 0.0], corrupt.sum())
    bg = BeamBackground(100, n_init=50)
    _learn(bg, scans)
    np.testing.assert_allclose(bg.background_m, 6.0)


def test_beam_count_change_resets_with_warning(caplog: pytest.LogCaptureFixture) -> None:
    bg = BeamBackground(10, n_init=5)
    _learn(bg, np.full((5, 10), 3.0))
    assert bg.initialised
    with caplog.at_level(logging.WARNING, logger="fusiontrack.laser.background"):
        fg = bg.update(np.full(12, 1.0))
    assert "beam count changed from 10 to 12" in caplog.text
    assert fg.shape == (12,)
    assert not fg.any()
    assert bg.n_beams == 12
    assert not bg.initialised
    assert bg.resets == 1
    _learn(bg, np.full((4, 12), 3.0))
    assert bg.initialised
    assert bg.update(np.r_[np.full(11, 3.0), 1.0]).tolist() == [False] * 11 + [True]
    assert bg.update(np.zeros(0)).shape == (0,)  # an empty scan does not crash either


def test_new_geometry_takes_the_background_of_the_nearest_old_beams() -> None:
    """Known answer: a room whose range is a known function of the beam angle. At a new geometry each beam's
    background is the old one at the nearest angle (within half a beam); beams outside the old field of view have
    none until they see something; back at the old geometry its background resumes unchanged."""
    wall = lambda a: 3.0 + np.cos(a)  # noqa: E731 - the room's range at angle a
    a720 = -2.0 + 0.005 * np.arange(720)
    bg = BeamBackground(720, n_init=5)
    assert bg.set_geometry(720, -2.0, 0.005) == "same"
    _learn(bg, np.tile(wall(a720), (5, 1)))
    assert bg.set_geometry(500, -1.0, 0.007) == "resampled"  # 500 beams from -1.0 to 2.493 rad
    a500 = -1.0 + 0.007 * np.arange(500)
    inside = a500 <= a720[-1] + 0.0035
    assert bg.initialised
    assert bg.n_beams == 500
    np.testing.assert_allclose(bg.background_m[inside], wall(a500[inside]), atol=0.0035)  # |d wall/da| <= 1
    assert np.isnan(bg.background_m[~inside]).all()
    fg = bg.update(np.r_[wall(a500[:10]) - 1.0, wall(a500[10:])])  # someone 1 m in front of the first 10
    assert fg.tolist() == [True] * 10 + [False] * 490
    assert bg.set_geometry(720, -2.0, 0.005) == "resumed"
    np.testing.assert_allclose(bg.background_m, wall(a720), atol=1e-6)
    assert bg.set_geometry(500, -1.0, 0.007) == "resumed"
    assert bg.resets == 0


def test_new_geometry_before_initialisation_learns_from_scratch() -> None:
    bg = BeamBackground(10, n_init=5)
    _learn(bg, np.full((3, 10), 3.0))
    assert bg.set_geometry(12, 0.0, 0.1) == "new"
    assert not bg.initialised
    assert bg.resets == 1
    _learn(bg, np.full((5, 12), 3.0))
    assert bg.update(np.r_[np.full(11, 3.0), 1.0]).tolist() == [False] * 11 + [True]


def test_a_geometry_met_before_anything_was_learnt_is_carried_over_once_something_is() -> None:
    """Every 7th scan has only the first 100 beams, from the first scan on: the 100-beam model starts empty, and
    must take the 720-beam background as soon as that one is learnt, not learn alone for 50 of its own scans."""
    a, b = (720, -2.0, 0.005), (100, -2.0, 0.005)
    bg = BeamBackground(720, n_init=50)
    ranges = 5.0 + 0.5 * np.sin(np.arange(720) / 30.0)
    first_b_after = None
    for k in range(120):
        g = b if k % 7 == 0 else a
        bg.set_geometry(*g)
        bg.update(ranges[: g[0]])
        if g == b and first_b_after is None and k > 60:
            first_b_after = k
            assert bg.initialised
            np.testing.assert_allclose(bg.background_m, ranges[:100], atol=1e-6)
    assert first_b_after is not None


def test_geometries_kept_are_bounded() -> None:
    bg = BeamBackground(10, n_init=1)
    bg.set_geometry(10, 0.0, 0.1)
    _learn(bg, np.full((1, 10), 3.0))
    for n in range(11, 11 + 2 * BeamBackground.max_geometries):
        assert bg.set_geometry(n, 0.0, 0.1) == "resampled"
    assert len(bg._saved) == BeamBackground.max_geometries - 1
    assert bg.set_geometry(10, 0.0, 0.1) == "resampled"  # forgotten, carried over again


def test_nothing_is_foreground_before_initialisation() -> None:
    bg = BeamBackground(5, n_init=10)
    for i in range(9):
        assert not bg.update(np.full(5, 1.0 + i)).any()
        assert not bg.initialised
        assert not bg.foreground(np.full(5, 0.5)).any()
    bg.update(np.full(5, 10.0))
    assert bg.initialised


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"alpha": 1.5}, "alpha"), ({"beta": -0.1}, "beta"), ({"gamma": 2.0}, "gamma"),
    ({"tau_fg_m": -0.2}, "tau_fg_m"), ({"tau_fg_m": np.nan}, "tau_fg_m"), ({"n_init": 0}, "n_init"),
    ({"n_init": 2.5}, "n_init"), ({"init": "mean"}, "init"), ({"bin_m": 0.0}, "bin_m"),
    ({"range_min_m": 5.0, "range_max_m": 1.0}, "range_min_m"), ({"n_beams": 0}, "n_beams"),
])
def test_parameters_are_validated_by_name(kwargs: dict, name: str) -> None:
    args = {"n_beams": 10, **kwargs}
    with pytest.raises(ValueError, match=name):
        BeamBackground(**args)
