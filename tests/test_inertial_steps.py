"""Step detection (ALGORITHMS.md C2) on signals whose steps are known by construction."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import find_peaks

from fusiontrack.inertial import StepDetectorParams, detect_steps, step_signal
from fusiontrack.sim.imu import G_MPS2

FS_HZ = 50.0  # seed 002's phone rate


def _accel_from_vertical(a_v: np.ndarray) -> np.ndarray:
    return np.stack([np.zeros_like(a_v), np.zeros_like(a_v), a_v], axis=1)


def _t_ns(n: int, fs: float = FS_HZ) -> np.ndarray:
    return np.round(np.arange(n) / fs * 1e9).astype(np.int64)


def test_c2_sine_gives_108_steps() -> None:
    # ALGORITHMS.md C2 test: a_v = g + 2.5 sin(2π·1.8 t) + N(0, 0.3²) for 60 s -> 108 ± 1 steps
    rng = np.random.default_rng(0)
    t_s = np.arange(round(60 * FS_HZ)) / FS_HZ
    a_v = G_MPS2 + 2.5 * np.sin(2 * np.pi * 1.8 * t_s) + rng.normal(0.0, 0.3, t_s.size)
    steps = detect_steps(_t_ns(t_s.size), _accel_from_vertical(a_v))
    assert abs(len(steps) - 108) <= 1
    # the maxima of the sine are at t = (1/4 + k) / 1.8 s
    maxima = (0.25 + np.arange(108)) / 1.8
    gap = np.min(np.abs(steps.t_ns[:, None] * 1e-9 - maxima[None, :]), axis=1)
    assert np.max(gap) < 0.03
    np.testing.assert_allclose(steps.duration_s[1:], 1 / 1.8, atol=0.02)


def test_c2_standing_noise_gives_no_step() -> None:
    rng = np.random.default_rng(1)
    n = round(10 * FS_HZ)
    accel = np.array([0.3, -0.2, G_MPS2]) + rng.normal(0.0, 0.3, (n, 3))  # ALGORITHMS.md C2 test
    assert len(detect_steps(_t_ns(n), accel)) == 0


@pytest.mark.parametrize("orientation", ["flat", "upside_down", "on_edge", "tilted"])
def test_count_does_not_depend_on_phone_orientation(orientation: str) -> None:
    rng = np.random.default_rng(2)
    t_s = np.arange(round(30 * FS_HZ)) / FS_HZ
    f = np.stack([np.zeros_like(t_s), np.zeros_like(t_s), G_MPS2 + 2.0 * np.sin(2 * np.pi * 1.7 * t_s)], axis=1)
    R = {"flat": np.eye(3), "upside_down": np.diag([1.0, -1.0, -1.0]),
         "on_edge": np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),
         "tilted": np.array([[0.8, 0.0, 0.6], [0.0, 1.0, 0.0], [-0.6, 0.0, 0.8]])}[orientation]
    accel = f @ R + rng.normal(0.0, 0.1, f.shape)  # phone-frame readings v_phone = R.T v_body
    assert abs(len(detect_steps(_t_ns(t_s.size), accel)) - 51) <= 1  # 1.7 Hz for 30 s


def test_valley_rule_merges_a_double_humped_step() -> None:
    # every 1.2 s, two humps 0.35 s apart (> Δt_min, so the minimum step time alone keeps both) with
    # no dip between them, then a deep trough: one step per 1.2 s, 17 in 20 s
    t_s = np.arange(round(20 * FS_HZ)) / FS_HZ
    ph = np.mod(t_s, 1.2)
    bump = lambda x, s: np.exp(-0.5 * (x / s) ** 2)  # noqa: E731
    a_v = 2.2 * bump(ph - 0.1, 0.07) + 2.2 * bump(ph - 0.45, 0.07) - 2.5 * bump(ph - 0.85, 0.12)
    accel = _accel_from_vertical(a_v - a_v.mean() + G_MPS2)
    _, dyn, threshold = step_signal(_t_ns(t_s.size), accel)
    raw, _ = find_peaks(dyn, height=threshold, distance=round(0.3 * FS_HZ))
    assert raw.size == 34  # both humps pass height and distance
    steps = detect_steps(_t_ns(t_s.size), accel)
    assert len(steps) == 17
    assert np.min(np.diff(steps.t_ns)) * 1e-9 > 0.8


def test_adaptive_threshold_counts_gentle_steps_the_fixed_one_misses() -> None:
    # a hand-held phone bounces little: peaks of 0.8 m/s^2 (below C2's fixed τ_peak = 1.0)
    t_s = np.arange(round(30 * FS_HZ)) / FS_HZ
    a_v = G_MPS2 + 0.8 * np.sin(2 * np.pi * 1.8 * t_s)
    accel = _accel_from_vertical(a_v)
    fixed = StepDetectorParams(tau_peak_min_mps2=1.0, adaptive_gain=0.0)
    assert len(detect_steps(_t_ns(t_s.size), accel, fixed)) == 0
    assert abs(len(detect_steps(_t_ns(t_s.size), accel)) - 54) <= 1
    _, _, threshold = step_signal(_t_ns(t_s.size), accel)
    assert np.all(threshold >= 0.4)
    assert np.all(threshold <= 1.0)


def test_magnitude_signal_counts_too() -> None:
    rng = np.random.default_rng(3)
    t_s = np.arange(round(30 * FS_HZ)) / FS_HZ
    a_v = G_MPS2 + 2.5 * np.sin(2 * np.pi * 1.8 * t_s) + rng.normal(0.0, 0.2, t_s.size)
    steps = detect_steps(_t_ns(t_s.size), _accel_from_vertical(a_v), StepDetectorParams(signal="magnitude"))
    assert abs(len(steps) - 54) <= 1


def test_irregular_sampling_and_rate() -> None:
    # jittered stamps at 405 Hz (the Pixel traces): same steps as at a regular 50 Hz
    rng = np.random.default_rng(4)
    fs = 405.0
    t_s = np.sort(np.arange(round(30 * fs)) / fs + rng.uniform(-3e-4, 3e-4, round(30 * fs)))
    a_v = G_MPS2 + 2.5 * np.sin(2 * np.pi * 1.8 * t_s)
    steps = detect_steps(np.round(t_s * 1e9).astype(np.int64), _accel_from_vertical(a_v))
    maxima = (0.25 + np.arange(54)) / 1.8
    assert len(steps) == 54
    np.testing.assert_allclose(steps.t_ns * 1e-9, maxima, atol=0.01)


def test_parameter_validation() -> None:
    with pytest.raises(ValueError, match="signal"):
        StepDetectorParams(signal="z")
    with pytest.raises(ValueError, match="max_step_s"):
        StepDetectorParams(min_step_s=0.5, max_step_s=0.4)
    with pytest.raises(ValueError, match="tau_peak_min_mps2"):
        StepDetectorParams(tau_peak_min_mps2=2.0)
    with pytest.raises(ValueError, match="cutoff_hz"):
        StepDetectorParams(cutoff_hz=-1.0)
    t = _t_ns(500)
    with pytest.raises(ValueError, match="first_duration_s"):
        detect_steps(t, _accel_from_vertical(np.full(500, G_MPS2)), first_duration_s=0.0)
    # 10 Hz is too slow for a 3 Hz step filter
    with pytest.raises(ValueError, match="sampling rate"):
        detect_steps(_t_ns(100, fs=10.0), _accel_from_vertical(np.full(100, G_MPS2)))
