"""LaserPeopleDetector: simulated two-scanner rooms with known people, bad sensor data, the leg_tracker demo bag."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.geometry import make_transform, pose2d_to_matrix, rpy_to_matrix
from fusiontrack.io.recording import Recording
from fusiontrack.laser import LaserPeopleDetector
from fusiontrack.sim.laser import cast_rays
from fusiontrack.types import Detection, LaserScan

RNG_SEED = 11
W_M, H_M = 12.0, 10.0
WALLS = np.array([[[0, 0], [W_M, 0]], [[W_M, 0], [W_M, H_M]], [[W_M, H_M], [0, H_M]], [[0, H_M], [0, 0]]], float)
POSES = {"laser_a": (0.3, 0.3, np.pi / 4), "laser_b": (W_M - 0.3, H_M - 0.3, -3 * np.pi / 4)}
N_BEAMS = 720
ANGLE_MIN = -np.deg2rad(135.0)
INC = np.deg2rad(270.0) / N_BEAMS
LEG_RADIUS_M = 0.06
PERIOD_NS = 100_000_000  # 10 Hz


def _scan(name: str, t_ns: int, legs: np.ndarray | None, rng: np.random.Generator, noise_m: float = 0.01,
          n_beams: int = N_BEAMS, sides: np.ndarray | None = None) -> LaserScan:
    """A 270° scan of the room (and of the leg circles ``legs`` (n, 2) and the segments ``sides`` (m, 2, 2))
    from scanner ``name``."""
    x, y, yaw = POSES[name]
    inc = np.deg2rad(270.0) / n_beams
    ang = yaw + ANGLE_MIN + np.arange(n_beams) * inc
    circles = np.zeros((0, 3)) if legs is None else np.column_stack([legs, np.full(len(legs), LEG_RADIUS_M)])
    walls = WALLS if sides is None else np.concatenate([WALLS, sides])
    r, _ = cast_rays([x, y], np.column_stack([np.cos(ang), np.sin(ang)]), walls, circles)
    r = r + rng.normal(0.0, noise_m, n_beams)
    return LaserScan(t_ns, name, name, ANGLE_MIN, inc, 0.05, 30.0, r.astype(np.float32))


def _people(rng: np.random.Generator, n: int, min_gap_m: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` people at least ``min_gap_m`` apart: centres (n, 2) and legs (n, 2, 2), feet 0.15-0.40 m apart."""
    centres = np.zeros((0, 2))
    while len(centres) < n:
        c = rng.uniform([2.0, 2.0], [W_M - 2.0, H_M - 2.0])
        if len(centres) == 0 or np.min(np.linalg.norm(centres - c, axis=1)) >= min_gap_m:
            centres = np.vstack([centres, c])
    heading = rng.uniform(-np.pi, np.pi, n)
    half = rng.uniform(0.15, 0.40, n)[:, None] / 2
    off = np.column_stack([np.cos(heading), np.sin(heading)]) * half
    return centres, np.stack([centres + off, centres - off], axis=1)


def _detector(**kwargs: object) -> LaserPeopleDetector:
    return LaserPeopleDetector({k: pose2d_to_matrix(*v) for k, v in POSES.items()}, **kwargs)


def _learn_empty_room(det: LaserPeopleDetector, rng: np.random.Generator, n: int = 50) -> int:
    for i in range(n):
        for name in POSES:
            det.update(_scan(name, i * PERIOD_NS, None, rng))
    return n * PERIOD_NS


def _match(dets: list[Detection], centres: np.ndarray) -> np.ndarray:
    """Distance from every person to the nearest detection, (n,)."""
    pos = np.array([d.position_m for d in dets]).reshape(-1, 2)
    if len(pos) == 0:
        return np.full(len(centres), np.inf)
    return np.linalg.norm(centres[:, None, :] - pos[None, :, :], axis=2).min(axis=1)


# ---- simulated scenes with known people -----------------------------------------------------------------------


def test_ten_people_two_scanners_are_detected_once_each() -> None:
    rng = np.random.default_rng(RNG_SEED)
    det = _detector()
    t = _learn_empty_room(det, rng)
    centres, legs = _people(rng, 10)
    for name in POSES:
        det.update(_scan(name, t, legs.reshape(-1, 2), rng))
    dets = det.detect(t)
    assert len(dets) == 10
    # The scanners see the near side of each leg: the centre is biased by < a leg radius.
    assert _match(dets, centres).max() < 0.08
    for d in dets:
        assert d.sensor == "laser"
        assert d.t_ns == t
        assert d.features["feet_m"].shape == (2, 2)
        assert d.features["points_m"].ndim == 2
        assert d.features["points_m"].shape[1] == 2
        assert d.features["inter_feet_m"].shape == ()
        assert d.features["one_foot"].dtype == bool
        np.testing.assert_allclose(d.position_m, d.features["points_m"].mean(axis=0))
        assert np.all(np.linalg.eigvalsh(d.covariance_m2) >= 0.05**2 - 1e-12)
    # Feet: a foot barycentre lies on the visible arc of its leg, within a leg radius of the leg's centre.
    true_sd = np.linalg.norm(legs[:, 0] - legs[:, 1], axis=1)
    pos = np.array([d.position_m for d in dets])
    nearest = np.argmin(np.linalg.norm(pos[:, None] - centres[None], axis=2), axis=1)
    two = [j for j, d in enumerate(dets) if not d.features["one_foot"]]
    assert len(two) >= 8
    sd = np.array([float(dets[j].features["inter_feet_m"]) for j in two])
    np.testing.assert_allclose(sd, true_sd[nearest[two]], atol=2 * LEG_RADIUS_M)
    assert np.median(np.abs(sd - true_sd[nearest[two]])) < 0.05


def test_a_person_seen_by_both_scanners_is_one_detection() -> None:
    rng = np.random.default_rng(RNG_SEED)
    det = _detector()
    t = _learn_empty_room(det, rng)
    legs = np.array([[6.0, 4.85], [6.0, 5.15]])
    for name in POSES:
        det.update(_scan(name, t, legs, rng))
    _points, owner = det.foreground_points(t)
    assert set(owner.tolist()) == {0, 1}  # both scanners contribute
    dets = det.detect(t)
    assert len(dets) == 1
    assert np.linalg.norm(dets[0].position_m - [6.0, 5.0]) < 0.05
    assert float(dets[0].features["inter_feet_m"]) == pytest.approx(0.3, abs=0.05)


def test_4x4_poses_give_the_same_detections_as_2d_poses() -> None:
    rng = np.random.default_rng(RNG_SEED)
    poses4 = {k: make_transform(rpy_to_matrix(0.0, 0.0, yaw), [x, y, 0.25]) for k, (x, y, yaw) in POSES.items()}
    det2, det4 = _detector(), LaserPeopleDetector(poses4)
    _centres, legs = _people(rng, 4)
    scans = [_scan(n, i * PERIOD_NS, None if i < 50 else legs.reshape(-1, 2), rng) for i in range(51) for n in POSES]
    for s in scans:
        det2.update(s)
        det4.update(s)
    a, b = det2.detect(50 * PERIOD_NS), det4.detect(50 * PERIOD_NS)
    assert len(a) == len(b) == 4
    np.testing.assert_allclose([d.position_m for d in a], [d.position_m for d in b], atol=1e-9)


@pytest.mark.parametrize("stride_feet_m", [0.2, 0.35, 0.5, 0.6, 0.7])
def test_a_walker_at_any_stride_is_one_detection(stride_feet_m: float) -> None:
    """Feet up to 0.7 m apart: one detection per walker (foot pairing), centred between the feet."""
    rng = np.random.default_rng(RNG_SEED)
    det = _detector()
    t = _learn_empty_room(det, rng)
    for heading in np.linspace(0.0, np.pi, 6, endpoint=False):
        t += PERIOD_NS
        centre = rng.uniform([3.0, 3.0], [9.0, 7.0])
        off = 0.5 * stride_feet_m * np.array([np.cos(heading), np.sin(heading)])
        for name in POSES:
            det.update(_scan(name, t, np.array([centre + off, centre - off]), rng))
        dets = det.detect(t)
        assert len(dets) == 1
        # Both feet seen: within a few cm; one foot hidden behind the other for both scanners: within
        # half the feet distance plus a leg radius.
        assert _match(dets, centre[None])[0] < 0.5 * stride_feet_m + LEG_RADIUS_M


def test_people_standing_still_are_absorbed_only_slowly() -> None:
    """A7 through the detector: a person standing still is still detected 30 s (300 scans) later."""
    rng = np.random.default_rng(RNG_SEED)
    det = _detector()
    t = _learn_empty_room(det, rng)
    centres, legs = _people(rng, 3)
    for i in range(300):
        for name in POSES:
            det.update(_scan(name, t + i * PERIOD_NS, legs.reshape(-1, 2), rng))
    assert _match(det.detect(t + 299 * PERIOD_NS), centres).max() < 0.1


def test_nothing_is_detected_while_learning_or_in_an_empty_room() -> None:
    rng = np.random.default_rng(RNG_SEED)
    det = _detector()
    _, legs = _people(rng, 5)
    for i in range(50):  # people present while learning: nothing is foreground yet
        for name in POSES:
            det.update(_scan(name, i * PERIOD_NS, legs.reshape(-1, 2), rng))
        assert det.detect(i * PERIOD_NS) == []
    t = 50 * PERIOD_NS
    false_alarms = 0
    for i in range(50):
        for name in POSES:
            det.update(_scan(name, t + i * PERIOD_NS, None, rng))
        false_alarms += len(det.detect(t + i * PERIOD_NS))
    assert false_alarms == 0


def _walkers(rng: np.random.Generator, n_scans: int) -> tuple[list[LaserScan], np.ndarray]:
    """Scans of both scanners (10 Hz) with 4 people walking at 1 m/s from the first scan on (none stands still
    long enough to look like background), and their centres per scan ``(n_scans, 4, 2)``."""
    start = np.array([[3.0, 3.0], [9.0, 3.0], [3.0, 7.0], [9.0, 7.0]])
    velocity = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-1.0, 0.0]])
    foot = np.array([0.12, 0.0])
    scans, centres = [], []
    for i in range(n_scans):
        c = start + velocity * i * PERIOD_NS * 1e-9
        legs = np.stack([c + foot, c - foot], axis=1).reshape(-1, 2)
        centres.append(c)
        scans.extend(_scan(name, i * PERIOD_NS, legs, rng) for name in POSES)
    return scans, np.array(centres)


def test_priming_detects_people_from_the_first_scan_and_then_matches_online_learning() -> None:
    """A recording read ahead: the people walking from the first scan are found in it; from the first scan
    after the priming on, the backgrounds and detections are those of online learning, number for number."""
    rng = np.random.default_rng(RNG_SEED)
    n_init = 15
    scans, centres = _walkers(rng, 30)
    online, primed = _detector(n_init=n_init), _detector(n_init=n_init)
    used = primed.prime(iter(scans))
    assert used == dict.fromkeys(POSES, n_init)
    for i in range(30):
        t = i * PERIOD_NS
        for scan in scans[2 * i:2 * i + 2]:
            online.update(scan)
            primed.update(scan)
        a, b = online.detect(t), primed.detect(t)
        if i < n_init:
            assert a == []  # online: still learning
            # primed: all four from the first scan (a leg hidden: half the feet distance + a leg radius)
            assert _match(b, centres[i]).max() < 0.12 + 2 * LEG_RADIUS_M
        else:
            for name in POSES:
                np.testing.assert_array_equal(online.background(name).background_m,
                                              primed.background(name).background_m)
            assert len(a) == len(b)
            for da, db in zip(a, b, strict=True):
                np.testing.assert_array_equal(da.position_m, db.position_m)
    assert primed.dropped_scans == dict.fromkeys(POSES, 0)


def test_priming_a_scanner_with_too_few_scans_leaves_it_to_learn_online() -> None:
    """A scanner that sent fewer than n_init scans before the limit is not half primed: it learns from its first
    scan in the tracking pass exactly as online, while the other scanner is primed."""
    rng = np.random.default_rng(RNG_SEED)
    scans = [s for s in _walkers(rng, 30)[0] if s.sensor == "laser_a" or s.t_ns < 5 * PERIOD_NS]
    primed, online = _detector(n_init=10), _detector(n_init=10)
    used = primed.prime(iter(scans), max_scans=25)
    assert used == {"laser_a": 20, "laser_b": 5}
    assert primed.background("laser_b") is None
    assert primed.background("laser_a").initialised
    for scan in scans:
        online.update(scan)
        primed.update(scan)
    np.testing.assert_array_equal(online.background("laser_b").background_m,
                                  primed.background("laser_b").background_m)
    np.testing.assert_array_equal(online.background("laser_a").background_m,
                                  primed.background("laser_a").background_m)


def _box(centre: tuple[float, float], length_m: float, width_m: float, heading_rad: float) -> np.ndarray:
    """The four sides (4, 2, 2) of a ``length_m`` x ``width_m`` rectangle (a car seen from above)."""
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    half = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * [length_m / 2, width_m / 2]
    corners = np.asarray(centre) + half @ np.array([[c, s], [-s, c]])
    return np.stack([corners, np.roll(corners, -1, axis=0)], axis=1)


def _line(centre: tuple[float, float], length_m: float, heading_rad: float) -> np.ndarray:
    """A ``length_m`` segment (1, 2, 2): a bicycle seen from the side (B18's simulated bicycle is a 1.7 m line)."""
    d = np.array([np.cos(heading_rad), np.sin(heading_rad)]) * length_m / 2
    return np.array([[np.asarray(centre) - d, np.asarray(centre) + d]])


def _vehicles_and_people(rigid_min_m: float | None = 1.0) -> tuple[list[Detection], np.ndarray]:
    rng = np.random.default_rng(RNG_SEED)
    det = _detector(rigid_min_m=rigid_min_m)
    t = _learn_empty_room(det, rng)
    # two people side by side (centres 0.45 m apart) and one alone; a bicycle; a car both scanners see
    centres = np.array([[3.0, 4.0], [3.0, 4.45], [9.0, 8.0]])
    legs = np.concatenate([centres + np.array([0.12, 0.0]), centres - np.array([0.12, 0.0])])
    sides = np.concatenate([_line((4.0, 8.0), 1.7, 0.3), _box((8.0, 3.5), 4.5, 1.8, 0.2)])
    for name in POSES:
        det.update(_scan(name, t, legs, rng, sides=sides))
    return det.detect(t), centres


def test_a_bicycle_and_a_car_are_one_rigid_detection_each_and_people_stay_segments() -> None:
    dets, centres = _vehicles_and_people()
    rigid = [d for d in dets if bool(d.features["rigid"])]
    people = [d for d in dets if not bool(d.features["rigid"])]
    assert len(rigid) == 2
    pos = np.array([d.position_m for d in rigid])
    # the bicycle's side; the car's four sides (two from each scanner, joined at the corners): centroid = centre
    assert np.linalg.norm(pos - [4.0, 8.0], axis=1).min() < 0.1
    assert np.linalg.norm(pos - [8.0, 3.5], axis=1).min() < 0.3
    car = rigid[int(np.argmin(np.linalg.norm(pos - [8.0, 3.5], axis=1)))]
    extent = np.ptp(car.features["points_m"] @ np.array([np.cos(0.2), np.sin(0.2)]))
    assert extent > 4.0  # whole, not the side one scanner sees
    # every person is still a two-feet segment, and nothing of the vehicles leaked into those
    assert len(people) == len(centres)
    assert _match(people, centres).max() < 0.25


def test_without_rigid_objects_a_car_is_cut_into_walker_sized_pieces() -> None:
    dets, centres = _vehicles_and_people(rigid_min_m=None)
    assert not any(bool(d.features["rigid"]) for d in dets)
    near_car = [d for d in dets if np.linalg.norm(d.position_m - [8.0, 3.5]) < 3.0]
    assert len(near_car) >= 3  # the failure the rigid objects fix: one car, several "people"
    assert _match(dets, centres).max() < 0.25


def test_a_rigid_object_seen_shorter_stays_rigid_and_a_short_new_one_is_not() -> None:
    def rigid_after(lengths: list[float], step_ns: int = PERIOD_NS) -> bool:
        rng = np.random.default_rng(RNG_SEED)
        det = _detector()
        t = _learn_empty_room(det, rng)
        for k, length in enumerate(lengths):
            for name in POSES:
                # the line lies across both scanners' views (heading 2.3 rad)
                det.update(_scan(name, t + k * step_ns, None, rng, sides=_line((6.0, 5.0), length, 2.3)))
            dets = det.detect(t + k * step_ns)
        return any(bool(d.features["rigid"]) for d in dets)

    assert rigid_after([1.2])
    assert not rigid_after([0.8])  # below rigid_min_m (1 m): walker-sized
    assert rigid_after([1.2, 0.8])  # hysteresis: above rigid_keep_m (0.6 m) next to last scan's rigid points
    assert not rigid_after([1.2, 0.4])
    assert not rigid_after([1.2, 0.8], step_ns=3 * PERIOD_NS)  # the scanners were silent longer than max_age_s


def test_legs_strung_together_in_depth_are_not_a_rigid_object() -> None:
    # Legs of people one behind the other, 15-16 m away, at adjacent bearings: each half a metre deeper than the
    # last, within the grazing joins' reach there (0.59 m), so the beam-order cluster is 1 m long. A vehicle's side
    # seen at the same place is one piece; the legs have gaps of half the cluster's length.
    inc = np.deg2rad(0.375)

    def objects(fg: np.ndarray, **kwargs: float) -> list[tuple[bool, int]]:
        det = LaserPeopleDetector({"s": np.eye(3)}, **kwargs)
        bg = np.full(480, 25.0)
        for k in range(60):
            det.update(LaserScan(k * PERIOD_NS, "s", "s", -np.pi / 2, inc, 0.05, 40.0, bg.astype(np.float32)))
        r = bg.copy()
        r[200:200 + fg.size] = fg
        det.update(LaserScan(60 * PERIOD_NS, "s", "s", -np.pi / 2, inc, 0.05, 40.0, r.astype(np.float32)))
        return [(bool(d.features["rigid"]), len(d.features["points_m"])) for d in det.detect(60 * PERIOD_NS)]

    legs = np.repeat([15.0, 15.5, 16.0], 4)
    assert objects(legs) == [(False, 4)] * 3
    assert objects(legs, rigid_max_gap=1.0) == [(True, 12)]  # what the gap test prevents
    side = np.linspace(15.0, 16.2, 40)
    assert objects(side) == [(True, 40)]
    # beams without a return inside the side (glass, dark paint: NaN, inf, 0) do not cut it
    holes = side.copy()
    holes[[8, 20, 21, 30]] = [np.nan, np.inf, 0.0, np.nan]
    assert objects(holes) == [(True, 36)]
    # a piece beside the side, a step of 0.2 m in range away (a mirror, a corner): not bridged, but it touches the
    # side, so all of it goes with the side, not only its points within rigid_join_m
    piece = np.r_[side[:30], np.nan, np.linspace(16.1, 16.3, 8)]
    assert objects(piece) == [(True, 38)]


def test_a_rigid_objects_centre_is_exact_far_from_the_origin() -> None:
    # A georeferenced world (UTM-like coordinates): the centre must not be computed in float32 world metres.
    inc = np.deg2rad(0.375)
    origin = np.array([5.0e5, 5.4e6])
    det = LaserPeopleDetector({"s": pose2d_to_matrix(*origin, 0.0)})
    for k in range(60):
        det.update(LaserScan(k * PERIOD_NS, "s", "s", -np.pi / 2, inc, 0.05, 40.0, np.full(480, 25.0, np.float32)))
    # a flat wall-like side 5 m ahead, across beams 220-259 (x = 5 m in the scanner frame)
    r = np.full(480, 25.0)
    beams = np.arange(220, 260)
    r[beams] = 5.0 / np.cos(-np.pi / 2 + beams * inc)
    det.update(LaserScan(60 * PERIOD_NS, "s", "s", -np.pi / 2, inc, 0.05, 40.0, r.astype(np.float32)))
    (d,) = det.detect(60 * PERIOD_NS)
    assert bool(d.features["rigid"])
    y = 5.0 * np.tan(-np.pi / 2 + beams[[0, -1]] * inc)
    assert np.hypot(*(d.position_m - (origin + np.array([5.0, y.mean()])))) < 0.01


def test_rigid_object_parameters_are_checked() -> None:
    from fusiontrack.laser.detector import check_detector_params

    assert check_detector_params({"rigid_min_m": float("inf")}) == {"rigid_min_m": float("inf")}
    assert _detector(rigid_min_m=float("inf")).rigid_min_m is None  # a pipeline file's "off"
    for key, value in (("rigid_min_m", 0.0), ("rigid_min_m", "1"), ("rigid_keep_m", -1.0), ("rigid_join_m", np.nan),
                       ("rigid_grazing_deg", 95.0)):
        with pytest.raises(ConfigError, match=key):
            check_detector_params({key: value}, "pipeline.toml [laser]")


# ---- bad sensor data --------------------------------------------------------------------------------------


def test_nan_inf_and_zero_ranges_do_not_stop_detection() -> None:
    rng = np.random.default_rng(RNG_SEED)
    det = _detector()
    t = _learn_empty_room(det, rng)
    centres, legs = _people(rng, 6)
    for name in POSES:
        s = _scan(name, t, legs.reshape(-1, 2), rng)
        r = s.ranges_m.copy()
        bad = rng.random(r.size) < 0.1
        r[bad] = rng.choice(np.array([np.nan, np.inf, -np.inf, 0.0], np.float32), bad.sum())
        det.update(LaserScan(s.t_ns, name, name, s.angle_min_rad, s.angle_increment_rad, 0.05, 30.0, r))
    dets = det.detect(t)
    assert len(dets) == 6
    err = _match(dets, centres)
    # Worst case a foot lost all its points: the centre is then off by half the feet distance (<= 0.2 m)
    # plus a leg radius.
    assert err.max() < 0.2 + LEG_RADIUS_M
    assert np.median(err) < 0.05
    # A scan of nothing but invalid readings: no foreground from it, no crash.
    for name in POSES:
        det.update(LaserScan(t + PERIOD_NS, name, name, ANGLE_MIN, INC, 0.05, 30.0, np.full(N_BEAMS, np.nan)))
    assert det.detect(t + PERIOD_NS) == []
    assert det.background("laser_a").initialised


def test_beam_count_change_keeps_the_scanner_detecting(caplog: pytest.LogCaptureFixture) -> None:
    """A scanner that switches to 540 beams over the same field of view, then alternates between 540 and 720 (a
    reconfigured driver, a corrupt header), keeps finding the people at once: its background carries over to the
    new beams and each geometry's background is kept. Relearning at each change left it blind for good."""
    rng = np.random.default_rng(RNG_SEED)
    det = _detector()
    t = _learn_empty_room(det, rng)
    centres, legs = _people(rng, 3)
    with caplog.at_level(logging.WARNING, logger="fusiontrack.laser"):
        for i in range(12):
            ti = t + i * PERIOD_NS
            det.update(_scan("laser_a", ti, legs.reshape(-1, 2), rng, n_beams=540 if i % 2 == 0 else N_BEAMS))
            det.update(_scan("laser_b", ti, legs.reshape(-1, 2), rng))
            _, owner = det.foreground_points(ti)
            assert set(owner.tolist()) == {0, 1}, i
            assert _match(det.detect(ti), centres).max() < 0.15, i
    assert caplog.text.count("laser_a: scan geometry changed") == 1  # once, not at every switch
    assert "carried over" in caplog.text
    assert det.background("laser_a").resets == 0


def test_priming_through_geometry_changes_gives_the_online_backgrounds() -> None:
    """``prime`` promises the numbers online learning reaches: also when a scanner changes its beam count during
    the priming (laser_a goes through 6 geometries, laser_b starts late so the priming runs on past them)."""
    rng = np.random.default_rng(0)
    beams = [N_BEAMS - 20 * g for g in range(6)]
    scans = []
    for i in range(60):
        scans.append(_scan("laser_a", i * PERIOD_NS, None, rng, n_beams=N_BEAMS if i < 12 else beams[i % 6]))
        if i >= 20:
            scans.append(_scan("laser_b", i * PERIOD_NS, None, rng))
    online, primed = _detector(n_init=10), _detector(n_init=10)
    primed.prime(iter(scans))
    for scan in scans:
        online.update(scan)
        primed.update(scan)
    for name in POSES:
        a, b = online.background(name), primed.background(name)
        assert a.geometry == b.geometry
        np.testing.assert_array_equal(a.background_m, b.background_m)


def test_silent_scanner_stops_contributing_after_max_age() -> None:
    rng = np.random.default_rng(RNG_SEED)
    det = _detector(max_age_s=0.2)
    t = _learn_empty_room(det, rng)
    centres, legs = _people(rng, 4)
    for name in POSES:
        det.update(_scan(name, t, legs.reshape(-1, 2), rng))
    assert set(det.foreground_points(t)[1].tolist()) == {0, 1}
    for i in range(1, 6):  # laser_b goes silent
        det.update(_scan("laser_a", t + i * PERIOD_NS, legs.reshape(-1, 2), rng))
        owners = set(det.foreground_points(t + i * PERIOD_NS)[1].tolist())
        assert owners == ({0, 1} if i <= 2 else {0})
        assert _match(det.detect(t + i * PERIOD_NS), centres).max() < 0.15
    assert det.detect(t + 100 * PERIOD_NS) == []  # everybody silent: nothing


def test_out_of_order_scans_are_dropped() -> None:
    rng = np.random.default_rng(RNG_SEED)
    det = _detector()
    t = _learn_empty_room(det, rng)
    _centres, legs = _people(rng, 4)
    for name in POSES:
        det.update(_scan(name, t, legs.reshape(-1, 2), rng))
    before = [d.position_m for d in det.detect(t)]
    det.update(_scan("laser_a", t - 5 * PERIOD_NS, None, rng))  # late, stale scan of the empty room
    assert det.dropped_scans == {"laser_a": 1, "laser_b": 0}
    np.testing.assert_array_equal([d.position_m for d in det.detect(t)], before)


def test_scans_without_usable_angles_are_dropped(caplog: pytest.LogCaptureFixture) -> None:
    rng = np.random.default_rng(RNG_SEED)
    det = _detector()
    t = _learn_empty_room(det, rng)
    with caplog.at_level(logging.WARNING, logger="fusiontrack.laser"):
        for inc in (0.0, np.nan):
            det.update(LaserScan(t, "laser_a", "laser_a", ANGLE_MIN, inc, 0.05, 30.0, np.ones(N_BEAMS)))
    assert det.dropped_scans["laser_a"] == 2
    assert caplog.text.count("without usable beam angles") == 1
    assert det.background("laser_a").initialised  # the model is untouched


def test_unknown_sensor_and_bad_configuration_are_reported_by_name() -> None:
    det = _detector()
    with pytest.raises(ConfigError, match="'laser_c'"):
        det.update(LaserScan(0, "laser_c", "x", 0.0, 0.01, 0.05, 30.0, np.ones(10)))
    with pytest.raises(ValueError, match="scanners"):
        LaserPeopleDetector({})
    with pytest.raises(ValueError, match=r"scanners\['bad'\]"):
        LaserPeopleDetector({"bad": np.eye(2)})
    with pytest.raises(ValueError, match=r"scanners\['skew'\]"):
        LaserPeopleDetector({"skew": np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])})
    for kwargs, name in [({"alpha": 2.0}, "alpha"), ({"bandwidth_m": 0.0}, "bandwidth_m"),
                         ({"c0_m": -1.0}, "c0_m"), ({"max_age_s": -1.0}, "max_age_s"),
                         ({"min_sigma_m": np.nan}, "min_sigma_m"),
                         ({"min_segment_points": 0}, "min_segment_points"),
                         ({"min_cluster_points": 1.5}, "min_cluster_points"), ({"n_init": 0}, "n_init")]:
        with pytest.raises(ValueError, match=name):
            _detector(**kwargs)


def test_a_pipeline_files_laser_table_is_checked_by_key() -> None:
    """``check_detector_params`` (the CLI's [laser] table): an unknown key is named with every known one, a bad value
    with its key, also when TOML gave text for a number; good values pass through."""
    from fusiontrack.laser.detector import check_detector_params

    with pytest.raises(ConfigError, match=r"^p.toml: \[laser\]: unknown .* min_segmnt_points; known: .*min_segment"):
        check_detector_params({"min_segmnt_points": 10}, "p.toml: [laser]")
    for kwargs, name in [({"min_segment_points": -5}, "min_segment_points"), ({"alpha": "x"}, "alpha"),
                         ({"pair_feet_m": "far"}, "pair_feet_m"), ({"max_age_s": True}, "max_age_s"),
                         ({"init": "mean"}, "init"), ({"c0_m": -1.0}, "c0_m")]:
        with pytest.raises(ConfigError, match=rf"^laser: {name}: "):
            check_detector_params(kwargs)
    good = {"min_segment_points": 10, "alpha": 0.01, "init": "median", "pair_feet_m": None}
    assert check_detector_params(good) == good
    assert check_detector_params(None) == {}


def test_scanners_without_poses_are_named(shared_data: Path, caplog: pytest.LogCaptureFixture) -> None:
    """leg_tracker's negative_2.bag has three scanners and no /tf_static: each is taken at the world origin, where
    their detections cannot line up, and the user is told which."""
    from fusiontrack.laser.detector import detector_for_recording

    with Recording(shared_data / "laser/leg_tracker_demo/training/negative_2.bag") as rec, \
            caplog.at_level(logging.WARNING, logger="fusiontrack.laser.detector"):
        _, poses = detector_for_recording(rec, ["/left_scan", "/rear_scan", "/right_scan"])
    assert all(np.array_equal(T, np.eye(4)) for T in poses.values())
    assert "no /tf_static transform from" in caplog.text
    assert all(name in caplog.text for name in poses)


def test_ten_people_standing_are_found_in_every_frame() -> None:
    """2 scanners x 720 beams, 10 people standing: every frame of 20 has exactly 10 detections (the speed of
    this case is measured by benchmarks/laser_detection.py, not here)."""
    rng = np.random.default_rng(RNG_SEED)
    det = _detector()
    t = _learn_empty_room(det, rng)
    centres, legs = _people(rng, 10)
    for i in range(20):
        for name in POSES:
            det.update(_scan(name, t + i * PERIOD_NS, legs.reshape(-1, 2), rng))
        dets = det.detect(t + i * PERIOD_NS)
        assert len(dets) == 10
        assert _match(dets, centres).max() < 0.1


# ---- real data: the leg_tracker demo bag ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def demo_scans(shared_data: Path) -> list[LaserScan]:
    path = shared_data / "laser" / "leg_tracker_demo" / "demo_stationary_simple_environment.bag"
    with Recording(path) as rec:
        return list(rec.messages(["/scan"]))


def test_real_demo_bag_three_people_walking_past(demo_scans: list[LaserScan]) -> None:
    """leg_tracker demo: 1265 scans (10 Hz, 512 beams, stationary scanner); no labels, but a bird's-eye plot
    of the detections shows three people walking back and forth (two of them stand still at the end).

    Measured after the 50 learning scans, with the default foot pairing: a detection in 99.6 % of scans;
    exactly 3 in 76 % (counts 0: 5 scans, 1: 23, 2: 250, 3: 928, 4: 9); the scans with fewer are people
    occluding each other. Pure B4 (``pair_feet_m=None``) splits walkers at long strides: more than 3
    detections in 28 % of scans (4: 289, 5: 47, 6: 12, 7: 1).
    """
    assert len(demo_scans) == 1265
    counts = {}
    for pair in (0.8, None):
        det = LaserPeopleDetector({"/scan": np.eye(3)}, pair_feet_m=pair)
        n = []
        for scan in demo_scans:
            det.update(scan)
            dets = det.detect(scan.t_ns)
            n.append(len(dets))
            for d in dets:
                assert np.all(np.isfinite(d.position_m))
                assert 0.0 < np.linalg.norm(d.position_m) < scan.range_max_m
        assert det.dropped_scans == {"/scan": 0}
        counts[pair] = np.array(n)
    assert not counts[0.8][:50].any()  # learning
    after = counts[0.8][50:]
    assert (after > 0).mean() >= 0.95
    assert (after == 3).mean() >= 0.7
    assert (after > 3).mean() <= 0.02
    assert (counts[None][50:] > 3).mean() >= 0.2


def test_one_beam_clusters_are_kept_by_default_and_invalid_beams_never_are():
    """A8 with ``min_cluster_points`` 1 (the default) keeps every valid foreground beam, a lone one too; NaN, inf and
    zero readings never make points; with 2 the lone beam goes and the 3-beam leg stays (seed 000's A8)."""
    rng = np.random.default_rng(RNG_SEED)
    t = _learn_empty_room(det1 := _detector(), rng)
    rng = np.random.default_rng(RNG_SEED)
    _learn_empty_room(det2 := _detector(min_cluster_points=2), rng)
    scan = _scan("laser_a", t, None, rng)
    r = scan.ranges_m.astype(np.float64)
    r[300:303] = 3.0  # a leg three beams wide, far in front of the wall
    r[400] = 4.0  # a leg one beam hits
    r[[200, 201, 202]] = [np.nan, np.inf, 0.0]  # readings that are no points
    scan = LaserScan(t, "laser_a", "laser_a", scan.angle_min_rad, scan.angle_increment_rad, 0.05, 30.0,
                     r.astype(np.float32))
    for det in (det1, det2):
        det.update(scan)
    x, y, yaw = POSES["laser_a"]
    ang = yaw + ANGLE_MIN + np.array([300, 301, 302, 400]) * INC
    expected = np.column_stack([x + r[[300, 301, 302, 400]] * np.cos(ang), y + r[[300, 301, 302, 400]] * np.sin(ang)])
    p1, _ = det1.foreground_points(t)
    p2, _ = det2.foreground_points(t)
    np.testing.assert_allclose(np.sort(p1, axis=0), np.sort(expected, axis=0), atol=1e-6)
    np.testing.assert_allclose(np.sort(p2, axis=0), np.sort(expected[:3], axis=0), atol=1e-6)
