"""Seed 000's adaptive horizontal bias (ALGORITHMS.md A6, A9, A10, A12) on hand-built scans and boxes.

The hand-built scene is the paper's: a level camera and a laser on one vertical axis, a wall 8 m ahead and
people as two legs (circles of 6 cm radius) standing across the line of sight; the real camera is turned
``B_TRUE`` from its calibration. Boxes are the people's true image boxes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiontrack.calibration import (
    BiasParams,
    HorizontalBiasEstimator,
    bias_update,
    candidate_regions,
    discriminant,
    foreground_clusters,
    points_in_regions,
    select_clusters,
)
from fusiontrack.calibration.bias_run import bias_settled
from fusiontrack.geometry import PinholeCamera, make_transform
from fusiontrack.types import LaserScan

W, H = 320, 240
FX = (W / 2) / math.tan(math.radians(30.0))  # A6 test: W = 320 px, Φ = 60 degrees
B_TRUE = math.radians(3.0)
DTHETA = math.radians(0.5)
N_BEAMS = 361  # -90 .. +90 degrees
LEG_R = 0.06


def level_camera(yaw_rad: float = 0.0) -> PinholeCamera:
    return PinholeCamera.from_pose([0.0, 0.0, 1.0], yaw_rad, 0.0, fx=FX, fy=FX, width=W, height=H)


CALIBRATED = level_camera()
TRUE = CALIBRATED.with_yaw_offset(B_TRUE)
LASER2WORLD = {"laser": make_transform(np.eye(3), [0.0, 0.0, 0.2])}


def beam_angles() -> np.ndarray:
    return -math.pi / 2 + np.arange(N_BEAMS) * DTHETA


def person_at(beam: int, range_m: float) -> np.ndarray:
    """A person centred exactly on a beam (so their scan is symmetric about it), world (2,)."""
    a = beam_angles()[beam]
    return range_m * np.array([math.cos(a), math.sin(a)])


def scan_of(people: list[np.ndarray], t_ns: int, feet_apart_m: float = 0.24) -> LaserScan:
    """Ranges of a wall at x = 8 m and each person's two legs, side by side across the line of sight."""
    a = beam_angles()
    d = np.column_stack([np.cos(a), np.sin(a)])
    with np.errstate(divide="ignore"):
        r = np.where(np.cos(a) > 1e-9, 8.0 / np.cos(a), np.inf)
    for p in people:
        u = p / np.linalg.norm(p)
        for c in (p + feet_apart_m / 2 * np.array([-u[1], u[0]]), p - feet_apart_m / 2 * np.array([-u[1], u[0]])):
            along = d @ c
            perp2 = c @ c - along**2
            with np.errstate(invalid="ignore"):
                hit = along - np.sqrt(LEG_R**2 - perp2)
            r = np.where((perp2 <= LEG_R**2) & (hit > 0), np.minimum(r, hit), r)
    r = np.where(r < 30.0, r, np.inf).astype(np.float32)
    return LaserScan(t_ns, "laser", "laser", -math.pi / 2, DTHETA, 0.05, 30.0, r)


def boxes_of(people: list[np.ndarray], camera: PinholeCamera = TRUE) -> np.ndarray:
    return camera.person_box(np.array(people), 1.7, 0.3)


def estimator(rho: float, **kw: object) -> HorizontalBiasEstimator:
    est = HorizontalBiasEstimator(CALIBRATED, LASER2WORLD, BiasParams(rho=rho, bg_n_init=5, **kw))
    for k in range(5):  # the A7 background: the empty room
        est.observe_scan(scan_of([], k * 40_000_000))
    return est


def run(est: HorizontalBiasEstimator, people: list[np.ndarray], n: int, *, box_noise_px: float = 0.0,
        rng: np.random.Generator | None = None) -> np.ndarray:
    """``n`` frames of the same people; the bias after each, degrees."""
    return np.degrees(_biases_and_targets(est, people, n, box_noise_px, rng)[0])


# ---- A6 ------------------------------------------------------------------------------------------------


def test_candidate_region_numbers_of_a6():
    reg = candidate_regions([[150.0, 100.0, 170.0, 200.0]], CALIBRATED, 0.0, math.radians(1.0))
    assert math.degrees(reg.centre_rad[0]) == pytest.approx(0.0, abs=1e-9)  # θ_fwd
    assert math.degrees(reg.half_width_rad[0]) == pytest.approx(3.07, abs=0.005)  # atan(10 / 277.1) + 1°
    # a bias of 3 degrees shifts the region by exactly 6 beams of 0.5 degrees
    a = beam_angles()
    dist = np.full(N_BEAMS, 5.0)
    base = points_in_regions(a, dist, reg)[0]
    shifted = points_in_regions(a, dist, candidate_regions([[150.0, 100.0, 170.0, 200.0]], CALIBRATED, B_TRUE))[0]
    assert base.sum() == shifted.sum() > 0
    assert np.flatnonzero(shifted)[0] - np.flatnonzero(base)[0] == 6


def test_region_azimuth_is_exact_for_a_pitched_camera():
    # All pixels of a vertical line share one azimuth: the region centre of an upright person seen from
    # 7 m up is the person's own azimuth (the bias is the camera's yaw error whatever its pitch).
    cam = PinholeCamera.from_pose([0.0, -7.4, 7.0], math.radians(90), math.radians(42), fx=420, fy=420, width=640,
                                  height=480)
    feet = np.array([[-3.0, 2.0], [4.0, 5.0]])
    reg = candidate_regions(cam.person_box(feet, 1.7, 0.3), cam)
    want = np.arctan2(feet[:, 1] + 7.4, feet[:, 0])
    np.testing.assert_allclose(reg.centre_rad, want, atol=1e-9)
    # the box's bottom-centre is not quite under the (leaning) feet: the distance is good to 1 %
    np.testing.assert_allclose(reg.distance_m, np.hypot(feet[:, 0], feet[:, 1] + 7.4), rtol=0.01)
    turned = candidate_regions(cam.with_yaw_offset(0.05).person_box(feet, 1.7, 0.3), cam, bias_rad=0.05)
    np.testing.assert_allclose(turned.centre_rad, want, atol=1e-9)


# ---- A8 on the foreground --------------------------------------------------------------------------------


def test_wall_between_the_legs_does_not_split_the_walker():
    scan = scan_of([person_at(200, 5.0)], 0)
    r = scan.valid_ranges_m()
    fg = r < 7.5  # the legs; the wall (8 m) is background, also between the legs
    assert np.any(~fg[np.flatnonzero(fg)[0]:np.flatnonzero(fg)[-1]])  # some beams pass between the legs
    one = foreground_clusters(r, scan.angle_min_rad, DTHETA, fg)
    assert len(one) == 1
    assert one.width_m[0] > 0.2
    # on the person's axis: the two feet's mean, moved (pi / 4) r_leg away from the laser
    np.testing.assert_allclose(one.centre_m[0], person_at(200, 5.0), atol=0.01)
    as_published = foreground_clusters(r, scan.angle_min_rad, DTHETA, np.isfinite(r), c0_m=0.2, skip_gaps=False)
    legs = np.unique(as_published.labels[fg])
    assert legs.size == 2  # A8 on the whole scan: one cluster per leg
    with pytest.raises(ValueError, match="foreground"):
        foreground_clusters(r, scan.angle_min_rad, DTHETA, fg[:-1])


# ---- A9 ------------------------------------------------------------------------------------------------


def test_discriminant_picks_the_person_not_the_wall():
    g = discriminant([[40, 8]], [[0.01, 2.0]], [[0.0, 0.01]], [0.02])
    assert select_clusters(g, [[False, True]]).tolist() == [1]


def test_discriminant_prefers_the_person_nearer_the_centre():
    g = discriminant([[8, 8]], [[2.0, 2.0]], [[0.01, 0.03]], [0.03])
    assert g[0, 0] > g[0, 1]
    assert select_clusters(g, [[True, True]], clarity=1.0).tolist() == [0]


def test_overlapping_regions_get_distinct_clusters():
    # A9's overlap test: two regions both see persons 0 and 1; region 0 prefers person 0 and region 1 would too
    # (its own person is farther from its centre), but person 0 goes to region 0 (higher g), so region 1
    # takes its next best: person 1.
    n = [[10, 6], [10, 10]]
    D = [[2.0, 2.0], [2.0, 2.0]]
    delta = [[0.00, 0.06], [0.02, 0.03]]
    g = discriminant(n, D, delta, [0.03, 0.03])
    assert np.argmax(g[1]) == 0  # both regions' best is person 0
    assert select_clusters(g, np.ones((2, 2), bool)).tolist() == [0, 1]


def test_no_clear_winner_means_no_cluster():
    g = discriminant([[8, 8]], [[2.0, 2.0]], [[0.02, 0.02]], [0.03])
    assert select_clusters(g, [[True, True]]).tolist() == [-1]
    assert select_clusters(discriminant([[8]], [[0.05]], [[0.0]], [0.03]), [[False]]).tolist() == [-1]


@pytest.mark.parametrize("gate", [None, 1.0])
def test_estimator_resolves_overlapping_regions_of_two_people(gate):
    # People at 10 degrees 5 m away and 16 degrees 7 m away: their candidate regions overlap (in azimuth; with
    # gate=None the distance does not separate them), and at the start (bias 0, 3 degrees off) the second
    # person's region holds half of the first person's legs.
    people = [person_at(200, 5.0), person_at(212, 7.0)]
    est = estimator(0.5, range_gate_m=gate)
    steps = []
    for k in range(15):
        t = (10 + k) * 40_000_000
        est.observe_scan(scan_of(people, t))
        steps.append(est.update(t, boxes_of(people)))
    assert all(s.overlapping.all() for s in steps)
    for s in steps:
        np.testing.assert_allclose(s.position_m, np.array(people), atol=0.02)  # each got its own legs
    assert math.degrees(est.bias_rad) == pytest.approx(3.0, abs=0.01)


def test_estimator_skips_a_frame_without_a_clear_winner():
    # Two people at 6 and 14 degrees, 5 m away, inside one box centred (as calibrated) near 10 degrees: the two
    # clusters score the same, so the frame gives no update.
    people = [person_at(192, 5.0), person_at(208, 5.0)]
    b = boxes_of(people, CALIBRATED)
    box = np.r_[b[:, :2].min(axis=0), b[:, 2:].max(axis=0)][None]
    est = estimator(0.1, range_gate_m=None)
    est.observe_scan(scan_of(people, 400_000_000))
    step = est.update(400_000_000, box)
    assert math.degrees(candidate_regions(box, CALIBRATED).centre_rad[0]) == pytest.approx(10.0, abs=0.1)
    assert step.n_used == 0
    assert step.bias_rad == 0.0


# ---- A10 -----------------------------------------------------------------------------------------------


def test_bias_update_is_exponential_smoothing():
    b = 0.0
    for n in range(1, 41):
        b, _, ok = bias_update(b, [3.0 - b], [1.0], 0.1)
        assert ok
        assert 3.0 - b == pytest.approx(3.0 * 0.9**n)
    assert bias_update(0.0, [], [], 0.5)[2] is False
    assert bias_update(0.0, [1.0, 3.0], [3.0, 1.0], 1.0)[0] == pytest.approx(1.5)  # g-weighted mean
    assert bias_update(0.0, [0.2], [1.0], 0.5, max_residual_rad=0.1)[2] is False  # outlier guard


@pytest.mark.parametrize(("rho", "frames", "tol_deg"), [(0.1, 40, 0.05), (0.5, 10, 0.01)])
def test_noise_free_bias_settles_at_the_papers_speed(rho, frames, tol_deg):
    # A10 tests 1-2 (paper: ~40 frames at LR 0.1, < 10 at LR 0.5); analytically 3° (1 - ρ)^n.
    bias = run(estimator(rho), [person_at(200, 5.0)], frames)
    assert abs(bias[-1] - 3.0) <= tol_deg
    # float32 ranges: the residual is exact to ~1e-5 degrees
    np.testing.assert_allclose(3.0 - bias, 3.0 * (1 - rho) ** np.arange(1, frames + 1), atol=1e-4)


def test_noisy_bias_error_after_convergence():
    # A10 test 3: σ_e = 0.3 degrees of blob jitter, ρ = 0.1, frames 100-600: mean |b - 3°| <= 0.085 degrees
    # (the paper's average error; theory 0.8 · 0.229 σ_e = 0.055 degrees).
    rng = np.random.default_rng(0)
    sigma_px = FX * math.tan(math.radians(0.3))
    bias = run(estimator(0.1), [person_at(200, 5.0)], 600, box_noise_px=sigma_px, rng=rng)
    err = np.abs(bias[100:] - 3.0)
    assert err.mean() <= 0.085
    assert abs(bias[100:].mean() - 3.0) <= 0.05


def _biases_and_targets(est: HorizontalBiasEstimator, people: list[np.ndarray], n: int, box_noise_px: float = 0.0,
                        rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Bias after each of ``n`` frames and each frame's target ``b + ē`` (A10; NaN when no person was used),
    radians."""
    bias, target = [], []
    for k in range(n):
        t = (10 + k) * 40_000_000
        est.observe_scan(scan_of(people, t))
        boxes = boxes_of(people)
        if box_noise_px:
            boxes = boxes + rng.normal(0.0, box_noise_px, (len(people), 1)) * [1, 0, 1, 0]
        before = est.bias_rad
        step = est.update(t, boxes)
        bias.append(step.bias_rad)
        target.append(before + step.mean_residual_rad if step.n_used else np.nan)
    return np.array(bias), np.array(target)


def test_stop_rule_stops_once_the_bias_has_caught_up_with_its_targets():
    # Noise-free A10 at rho 0.1 from 0 towards 3 degrees: every target is 3 degrees, so the target test of
    # bias_settled first holds when 3 (0.9)^n <= 0.1, n = 33; the span of the last 20 values,
    # 3 (0.9)^(n-19) (1 - 0.9^19), first falls to 0.1 degree at n = 50.
    tol = math.radians(0.1)
    bias, target = _biases_and_targets(estimator(0.1), [person_at(200, 5.0)], 60)
    assert np.isfinite(target).all()  # every frame's person was used
    np.testing.assert_allclose(target, B_TRUE, atol=math.radians(1e-3))
    first = next(n for n in range(1, 61) if bias_settled(bias[:n], target[:n], 20, tol))
    assert first == math.ceil(math.log(0.1 / 3.0) / math.log(0.9)) == 33
    assert abs(math.degrees(bias[first - 1]) - 3.0) <= 0.1
    span_first = next(n for n in range(20, 61) if np.ptp(bias[n - 20:n]) <= tol)
    assert span_first == 50
    assert not bias_settled(bias[:19], target[:19], 20, tol)  # fewer updates than the window
    assert bias_settled(bias[:1], target[:1], 1, tol)  # one update spans nothing


def test_stop_rule_on_noisy_boxes_stops_within_the_tolerance_of_the_true_bias():
    # 0.3 degrees of blob jitter (A10 test 3): wherever the rule first holds, the bias is within the
    # tolerance of the true 3 degrees; with 1.5 degrees of jitter the targets' standard error alone exceeds
    # the tolerance, and a bias that happens to sit on their mean is not settled.
    tol = math.radians(0.1)
    for seed in range(5):
        rng = np.random.default_rng(seed)
        bias, target = _biases_and_targets(estimator(0.1), [person_at(200, 5.0)], 120,
                                           FX * math.tan(math.radians(0.3)), rng)
        assert np.isfinite(target).all()
        first = next(n for n in range(20, 121) if bias_settled(bias[:n], target[:n], 20, tol))
        assert abs(bias[first - 1] - B_TRUE) <= tol
    rng = np.random.default_rng(0)
    noisy = B_TRUE + rng.normal(0.0, math.radians(1.5), 20)
    wander = np.full(20, noisy.mean())
    wander[0] -= 1.5 * tol  # still moving: the span test does not hold
    assert not bias_settled(wander, noisy, 20, tol)
    assert bias_settled(wander, np.full(20, noisy.mean()), 20, tol)  # the same bias, targets in agreement


def test_warm_start_bias_is_the_mean_of_its_first_targets_then_a10():
    # BiasParams.warm_start: the n-th update at max(rho, 1/n). Noise-free, the first update lands on the true
    # bias; with jitter, the bias after n <= 1/rho updates is the mean of their targets b + ē, and later
    # updates are A10's at rho.
    bias = run(estimator(0.1, warm_start=True), [person_at(200, 5.0)], 5)
    np.testing.assert_allclose(bias, 3.0, atol=1e-4)
    rng = np.random.default_rng(3)
    bias, target = _biases_and_targets(estimator(0.1, warm_start=True), [person_at(200, 5.0)], 30,
                                       FX * math.tan(math.radians(0.3)), rng)
    assert np.isfinite(target).all()
    np.testing.assert_allclose(bias[:10], np.cumsum(target[:10]) / np.arange(1, 11), atol=1e-12)
    np.testing.assert_allclose(bias[10:], bias[9:-1] + 0.1 * (target[10:] - bias[9:-1]), atol=1e-12)


def test_warm_start_counts_only_the_updates_made():
    # a frame that makes no update (its box 20 degrees off: no valid cluster in its region, or a residual beyond
    # A10's h_theta) moves nothing, and the next update is still the second: its rate 1/2, the bias the mean of
    # the two targets
    est = estimator(0.1, warm_start=True, gate_sigmas=0.0)
    people = [person_at(200, 5.0)]
    first = run(est, people, 1)[-1]
    t = 11 * 40_000_000
    est.observe_scan(scan_of(people, t))
    far = boxes_of(people, CALIBRATED.with_yaw_offset(math.radians(20.0)))
    step = est.update(t, far)
    assert step.n_used == 0
    assert est.bias_rad == pytest.approx(math.radians(first))
    t = 12 * 40_000_000
    est.observe_scan(scan_of(people, t))
    jitter = FX * math.tan(math.radians(0.3)) * np.array([1.0, 0.0, 1.0, 0.0])  # a box 0.3 degree off
    before = est.bias_rad
    step = est.update(t, boxes_of(people) + jitter)
    assert step.n_used == 1
    target = before + step.mean_residual_rad
    assert abs(target - before) > math.radians(0.1)
    assert est.bias_rad == pytest.approx((before + target) / 2, abs=1e-12)  # rate 1/2, not 1/3


def test_warm_start_after_20_updates_is_nearer_the_true_bias_than_a10_after_40():
    # 0.3 degrees of blob jitter: A10 alone after 40 updates still lags 3 (0.9)^40 = 0.044 degree behind; the
    # warm start's mean of 20 targets has no lag, only its noise (0.3 / sqrt(20) = 0.067 degree sigma, 0.054
    # mean absolute). Over 20 runs the warm start at 20 updates is the nearer, and unbiased.
    sigma_px = FX * math.tan(math.radians(0.3))
    warm, fixed = [], []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        warm.append(run(estimator(0.1, warm_start=True), [person_at(200, 5.0)], 20, box_noise_px=sigma_px,
                        rng=rng)[-1])
        rng = np.random.default_rng(seed)
        fixed.append(run(estimator(0.1), [person_at(200, 5.0)], 40, box_noise_px=sigma_px, rng=rng)[-1])
    warm_err, fixed_err = np.abs(np.array(warm) - 3.0), np.abs(np.array(fixed) - 3.0)
    assert warm_err.mean() < fixed_err.mean()
    assert warm_err.mean() <= 0.085  # the paper's average error after convergence
    assert abs(np.mean(warm) - 3.0) <= 3 * 0.067 / math.sqrt(20)  # no lag: its mean within 3 standard errors
    assert np.mean(fixed) < 3.0 - 0.02  # A10 alone: still behind


@pytest.mark.parametrize(("kw", "name"), [({"window": 0}, "window"), ({"tol_rad": 0.0}, "tol_rad"),
                                          ({"target_rad": [0.0]}, "target_rad")])
def test_stop_rule_bad_arguments_name_the_argument(kw, name):
    args = {"bias_rad": [0.0, 0.0], "target_rad": [0.0, 0.0], "window": 2, "tol_rad": 0.01, **kw}
    with pytest.raises(ValueError, match=name):
        bias_settled(**args)


def test_capture_beyond_the_region_needs_widening():
    # A10 test 4: 8 degrees off with a ~4 degree region: nothing is found until A6's margin widens.
    far = HorizontalBiasEstimator(CALIBRATED, LASER2WORLD, BiasParams(rho=0.5, bg_n_init=5, widen_after=0))
    wide = HorizontalBiasEstimator(CALIBRATED, LASER2WORLD, BiasParams(rho=0.5, bg_n_init=5, widen_after=5))
    people = [person_at(200, 5.0)]
    cam8 = CALIBRATED.with_yaw_offset(math.radians(8.0))
    for est in (far, wide):
        for k in range(5):
            est.observe_scan(scan_of([], k * 40_000_000))
        for k in range(60):
            t = (10 + k) * 40_000_000
            est.observe_scan(scan_of(people, t))
            est.update(t, boxes_of(people, cam8))
    assert far.bias_rad == 0.0
    assert math.degrees(wide.bias_rad) == pytest.approx(8.0, abs=0.05)
    assert math.degrees(wide.history.margin_rad[-1]) == pytest.approx(1.0)  # back to A6's margin once locked on


def test_history_and_corrected_camera():
    est = estimator(0.5)
    run(est, [person_at(200, 5.0)], 12)
    h = est.history
    assert len(h) == 12
    assert np.all(np.diff(h.t_ns) > 0)
    assert np.all(h.n_used == 1)
    np.testing.assert_allclose(est.corrected_camera.cam2world, TRUE.cam2world, atol=1e-4)


# ---- bad input -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(("kw", "name"), [({"rho": 0.0}, "rho"), ({"rho": 1.5}, "rho"),
                                          ({"margin_rad": -0.1}, "margin_rad"), ({"n_min": 0}, "n_min"),
                                          ({"range_gate_m": -1.0}, "range_gate_m"), ({"clarity": 0.5}, "clarity"),
                                          ({"centre": "middle"}, "centre"), ({"gate_sigmas": -1.0}, "gate_sigmas"),
                                          ({"bg_beta": 2.0}, "bg_beta"), ({"warm_start": "yes"}, "warm_start")])
def test_bad_parameters_name_the_parameter(kw, name):
    with pytest.raises(ValueError, match=rf"BiasParams\.{name}"):
        BiasParams(**kw)


def test_bad_arrays_are_clear_errors():
    with pytest.raises(ValueError, match="boxes_px"):
        candidate_regions([[10.0, 0.0, 5.0, 20.0]], CALIBRATED)
    with pytest.raises(ValueError, match="boxes_px"):
        candidate_regions([1.0, 2.0, 3.0], CALIBRATED)
    with pytest.raises(ValueError, match="bg_diff_m, delta_rad"):
        discriminant([[1, 2]], [[1.0]], [[0.0, 0.0]], [0.1])
    with pytest.raises(ValueError, match="sigma_rad"):
        discriminant([[1]], [[1.0]], [[0.0]], [0.0])
    with pytest.raises(ValueError, match="rho"):
        bias_update(0.0, [1.0], [1.0], 0.0)
    with pytest.raises(ValueError, match="lasers"):
        HorizontalBiasEstimator(CALIBRATED, {})
    est = estimator(0.1)
    with pytest.raises(ValueError, match=r"scan\.sensor"):
        est.observe_scan(LaserScan(0, "other", "other", 0.0, DTHETA, 0.05, 30.0, np.ones(10, np.float32)))
    with pytest.raises(ValueError, match="object_ids, usable"):
        est.update(0, boxes_of([person_at(200, 5.0)]), object_ids=[1, 2])
    # no boxes, or no scan near the frame's time: a frame without an update, not an error
    assert est.update(10**12, np.zeros((0, 4))).n_used == 0
    assert est.update(10**12, boxes_of([person_at(200, 5.0)])).n_used == 0
