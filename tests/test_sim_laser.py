"""The simulated laser against analytic geometry: chords of circles, walls at r = d / cos θ, occlusion,
mounting invariance, visibility of boxes by height, the L-shape of a car, REP 117 and the noise model."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.geometry import pose2d_to_matrix, scan_to_world, transform_points
from fusiontrack.sim.laser import BICYCLE_LASER_WIDTH_M, LaserSim, cast_rays
from fusiontrack.sim.model import (
    KIND_BICYCLE,
    KIND_CAR,
    KIND_PERSON,
    LEG_RADIUS_M,
    AgentSnapshot,
    LaserSpec,
    StaticWorld,
    Timing,
)

R = LEG_RADIUS_M


def make_spec(x: float = 0.0, y: float = 0.0, yaw: float = 0.0, **kw: float) -> LaserSpec:
    kw.setdefault("range_noise_m", 0.0)
    return LaserSpec("laser_test", x, y, yaw, Timing(25.0), **kw)


def snapshot(people: Sequence[tuple[int, tuple[float, float], tuple[float, float]]] = (),
             vehicles: Sequence[tuple[int, int, tuple[float, float], float, float, float]] = ()) -> AgentSnapshot:
    """people: (id, left foot, right foot); vehicles: (id, kind, centre, heading, length, width)."""
    n = len(people) + len(vehicles)
    ids = [p[0] for p in people] + [v[0] for v in vehicles]
    kinds = [KIND_PERSON] * len(people) + [v[1] for v in vehicles]
    feet = [[p[1], p[2]] for p in people] + [[[np.nan] * 2] * 2 for _ in vehicles]
    pos = [np.mean([p[1], p[2]], axis=0) for p in people] + [v[2] for v in vehicles]
    heading = [0.0] * len(people) + [v[3] for v in vehicles]
    size = [[0.3, 0.5, 1.7]] * len(people) + [[v[4], v[5], 1.5] for v in vehicles]
    z = np.zeros
    return AgentSnapshot(0, np.array(ids, np.int64), np.array(kinds, np.int8), np.array(pos, float).reshape(n, 2),
                         z((n, 2)), np.array(heading, float), np.array(feet, float).reshape(n, 2, 2),
                         np.array(size, float).reshape(n, 3), z((n, 3), np.uint8), z((n, 3), np.uint8),
                         z(n, np.int8), -np.ones(n, np.int64), z(n))


def beam_angles(spec: LaserSpec) -> np.ndarray:
    return spec.angle_min_rad + np.arange(spec.n_beams) * spec.angle_increment_rad


def circle_truth(theta: np.ndarray, cx: float, cy: float, r: float) -> np.ndarray:
    """Textbook ray-circle distance from the origin: d·c - sqrt(r² - (d × c)²), inf on a miss."""
    along = cx * np.cos(theta) + cy * np.sin(theta)
    perp = cx * np.sin(theta) - cy * np.cos(theta)
    with np.errstate(invalid="ignore"):
        t = along - np.sqrt(r * r - perp * perp)
    return np.where((np.abs(perp) <= r) & (along > 0), t, np.inf)


def wall_truth(theta: np.ndarray, x_wall: float, half_length: float) -> np.ndarray:
    """Distance to the wall x = x_wall, |y| <= half_length: x_wall / cos θ where the beam meets it."""
    with np.errstate(divide="ignore"):
        r = x_wall / np.cos(theta)
    return np.where((np.cos(theta) > 0) & (np.abs(x_wall * np.tan(theta)) <= half_length), r, np.inf)


WALL_X5 = StaticWorld(walls=np.array([[[5.0, -20.0], [5.0, 20.0]]]))


def test_leg_gives_the_chord_formula():
    spec = make_spec()
    sim = LaserSim(spec, StaticWorld())
    ranges = sim.ranges(snapshot([(7, (3.0, 0.0), (np.nan, np.nan))]), rng=0)
    truth = circle_truth(beam_angles(spec), 3.0, 0.0, R)
    i0 = int(np.argmin(np.abs(beam_angles(spec))))
    assert ranges[i0] == pytest.approx(3.0 - R, abs=1e-6)  # the beam along x reads 2.94
    assert np.array_equal(np.isinf(ranges), np.isinf(truth))
    assert np.isfinite(truth).sum() == 7  # ±1.146° half-angle at 3 m, 0.375° steps
    np.testing.assert_allclose(ranges[np.isfinite(truth)], truth[np.isfinite(truth)], rtol=0, atol=1e-6)


def test_wall_reads_d_over_cos():
    spec = make_spec()
    ranges = LaserSim(spec, WALL_X5).ranges(AgentSnapshot.empty(0), rng=0)
    truth = wall_truth(beam_angles(spec), 5.0, 20.0)
    assert np.array_equal(np.isinf(ranges), np.isinf(truth))
    np.testing.assert_allclose(ranges[np.isfinite(truth)], truth[np.isfinite(truth)], rtol=1e-6)
    assert np.isfinite(truth).sum() > 300  # |θ| < atan(4) = 76°


def test_nearer_object_occludes_farther():
    spec = make_spec()
    sim = LaserSim(spec, WALL_X5)
    theta = beam_angles(spec)
    legs = snapshot([(3, (3.0, 0.0), (3.0, 1.0))])
    ranges, hit_ids = sim.cast(legs)
    wall = wall_truth(theta, 5.0, 20.0)
    leg = np.minimum(circle_truth(theta, 3.0, 0.0, R), circle_truth(theta, 3.0, 1.0, R))
    on_leg = np.isfinite(leg)
    assert on_leg.sum() >= 10
    np.testing.assert_allclose(ranges[on_leg], leg[on_leg], atol=1e-9)
    np.testing.assert_allclose(ranges[~on_leg & np.isfinite(wall)], wall[~on_leg & np.isfinite(wall)], rtol=1e-12)
    assert np.all(hit_ids[on_leg] == 3)
    assert np.all(hit_ids[~on_leg] == -1)
    # a leg behind another leg (both dynamic) is hidden: the nearer one is read
    both, ids = sim.cast(snapshot([(1, (2.0, 0.0), (np.nan, np.nan)), (2, (4.0, 0.0), (np.nan, np.nan))]))
    i0 = int(np.argmin(np.abs(theta)))
    assert both[i0] == pytest.approx(2.0 - R)
    assert ids[i0] == 1


def test_cast_rays_matches_the_simulator():
    spec = make_spec()
    sim = LaserSim(spec, WALL_X5)
    circles = np.array([[3.0, 0.0, R], [3.0, 1.0, R]])
    r, index = cast_rays((0.0, 0.0), sim.directions_world, WALL_X5.walls, circles)
    ranges, _ = sim.cast(snapshot([(3, (3.0, 0.0), (3.0, 1.0))]))
    np.testing.assert_array_equal(r, ranges)
    assert set(np.unique(index)) == {-1, 0, 1, 2}


def surface_distance(points: np.ndarray, segments: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """Distance of each point (n, 2) to the nearest segment or circle outline."""
    p0, e = segments[:, 0], segments[:, 1] - segments[:, 0]
    u = np.clip(np.einsum("nsk,sk->ns", points[:, None] - p0, e) / np.einsum("sk,sk->s", e, e), 0, 1)
    d_seg = np.linalg.norm(points[:, None] - (p0 + u[..., None] * e), axis=-1).min(axis=1)
    d_circ = np.abs(np.linalg.norm(points[:, None] - circles[:, :2], axis=-1) - circles[:, 2]).min(axis=1)
    return np.minimum(d_seg, d_circ)


ROOM = StaticWorld(walls=np.array([[[-6, -6], [6, -6]], [[6, -6], [6, 6]], [[6, 6], [-6, 6]], [[-6, 6], [-6, -6]]],
                                  float),
                   pillars=np.array([[2.0, 2.5, 0.3]]),
                   boxes=np.array([[-3.0, 3.0, 1.0, 0.6, 0.3, 1.2]]))


def test_mounted_laser_points_lie_on_the_surfaces():
    spec = make_spec(1.0, -2.0, 0.7, range_noise_m=0.005)
    sim = LaserSim(spec, ROOM)
    scene = snapshot([(1, (3.0, 0.0), (3.2, 0.3))], [(2, KIND_CAR, (-1.5, 1.0), 0.4, 3.0, 1.6)])
    scan = sim.scan(123, scene, rng=np.random.default_rng(5))
    pts = scan_to_world(scan, pose2d_to_matrix(spec.x_m, spec.y_m, spec.yaw_rad))
    valid = np.isfinite(pts).all(axis=1)
    assert valid.sum() > 600  # a closed room: nearly every beam returns
    np.testing.assert_allclose(sim.points_world(scan.ranges_m)[valid], pts[valid], atol=1e-5)
    segments, _, circles, _ = sim.dynamic_geometry(scene)
    segments = np.concatenate([ROOM.laser_segments(spec.height_m), segments])
    circles = np.concatenate([ROOM.pillars, circles])
    d = surface_distance(pts[valid], segments, circles)
    assert np.max(d) < 6 * spec.range_noise_m
    assert np.std(d) > 0.3 * spec.range_noise_m  # the noise is really there


def test_ranges_are_invariant_under_moving_the_whole_scene():
    """A laser at pose P in a scene reads what a laser at the origin reads in the scene moved by P⁻¹."""
    pose = pose2d_to_matrix(1.0, -2.0, 0.7)
    inv = np.linalg.inv(pose)
    feet = np.array([[3.0, 0.0], [3.2, 0.3]])
    car_c, car_yaw = np.array([-1.5, 1.0]), 0.4
    sim = LaserSim(make_spec(1.0, -2.0, 0.7), ROOM)
    ranges, ids = sim.cast(snapshot([(1, tuple(feet[0]), tuple(feet[1]))],
                                    [(2, KIND_CAR, tuple(car_c), car_yaw, 3.0, 1.6)]))
    moved_world = StaticWorld(
        walls=transform_points(inv, ROOM.walls.reshape(-1, 2)).reshape(-1, 2, 2),
        pillars=np.column_stack([transform_points(inv, ROOM.pillars[:, :2]), ROOM.pillars[:, 2]]),
        boxes=np.column_stack([transform_points(inv, ROOM.boxes[:, :2]), ROOM.boxes[:, 2:4],
                               ROOM.boxes[:, 4] - 0.7, ROOM.boxes[:, 5]]))
    mf = transform_points(inv, feet)
    moved = LaserSim(make_spec(), moved_world).cast(
        snapshot([(1, tuple(mf[0]), tuple(mf[1]))],
                 [(2, KIND_CAR, tuple(transform_points(inv, car_c[None])[0]), car_yaw - 0.7, 3.0, 1.6)]))
    np.testing.assert_allclose(moved[0], ranges, rtol=1e-9)
    np.testing.assert_array_equal(moved[1], ids)
    assert {1, 2} <= set(ids.tolist())


@pytest.mark.parametrize(("box_height", "visible"), [(0.45, False), (0.9, True)])
def test_boxes_lower_than_the_scan_plane_are_invisible(box_height: float, visible: bool):
    world = StaticWorld(boxes=np.array([[4.0, 0.0, 0.5, 1.0, 0.0, box_height]]))
    spec = make_spec(height_m=0.6)
    ranges = LaserSim(spec, world).ranges(AgentSnapshot.empty(0), rng=0)
    i0 = int(np.argmin(np.abs(beam_angles(spec))))
    if visible:
        assert ranges[i0] == pytest.approx(3.75)  # front face at x = 4 - 0.5 / 2
        assert np.isfinite(ranges).sum() == np.sum(np.abs(np.tan(beam_angles(spec))) * 3.75 <= 0.5)
    else:
        assert np.all(np.isinf(ranges))


def test_walls_and_pillars_lower_than_the_scan_plane_are_invisible():
    world = StaticWorld(walls=WALL_X5.walls, pillars=np.array([[3.0, 0.0, 0.2]]), wall_height_m=1.0,
                        pillar_height_m=1.0)
    assert np.all(np.isinf(LaserSim(make_spec(height_m=1.5), world).ranges(AgentSnapshot.empty(0), rng=0)))
    assert np.isfinite(LaserSim(make_spec(height_m=0.5), world).ranges(AgentSnapshot.empty(0), rng=0)).sum() > 300


def car_frame(points: np.ndarray, centre: tuple[float, float], yaw: float) -> np.ndarray:
    return transform_points(np.linalg.inv(pose2d_to_matrix(*centre, yaw)), points)


def test_car_gives_an_l_shape_on_its_near_sides():
    centre, yaw, length, width = (6.0, 3.0), -0.3, 4.5, 1.8
    sim = LaserSim(make_spec(), StaticWorld())
    ranges, ids = sim.cast(snapshot([], [(9, KIND_CAR, centre, yaw, length, width)]))
    pts = sim.points_world(ranges)
    assert np.array_equal(ids == 9, np.isfinite(ranges))
    local = car_frame(pts[ids == 9], centre, yaw)
    on_rear = np.isclose(local[:, 0], -length / 2, atol=1e-9)  # the laser sees the rear and the right side
    on_right = np.isclose(local[:, 1], -width / 2, atol=1e-9)
    assert np.all(on_rear | on_right)
    assert on_rear.sum() >= 5
    assert on_right.sum() >= 5
    assert np.all(np.abs(local) <= [length / 2 + 1e-9, width / 2 + 1e-9])
    # the corner of the L: the rear-right corner lies between the two arms
    corner = np.array([-length / 2, -width / 2])
    assert np.min(np.linalg.norm(local - corner, axis=1)) < 0.1


def test_bicycle_is_a_thin_line():
    centre, yaw = (4.0, -1.0), 1.2
    sim = LaserSim(make_spec(), StaticWorld())
    ranges, ids = sim.cast(snapshot([], [(4, KIND_BICYCLE, centre, yaw, 1.8, 0.6)]))
    local = car_frame(sim.points_world(ranges)[ids == 4], centre, yaw)
    assert len(local) >= 5
    assert np.all(np.abs(local[:, 1]) <= BICYCLE_LASER_WIDTH_M / 2 + 1e-9)
    assert np.all(np.abs(local[:, 0]) <= 0.9 + 1e-9)


def test_out_of_range_reads_inf_and_is_invalid():
    spec = make_spec(range_max_m=4.0, range_noise_m=0.01)
    sim = LaserSim(spec, WALL_X5)
    scan = sim.scan(10, snapshot([(1, (3.0, 0.0), (np.nan, np.nan))]), rng=1)
    r = scan.ranges_m
    assert r.dtype == np.float32
    finite = np.isfinite(r)
    assert 1 <= finite.sum() <= 9  # only the leg is within 4 m
    assert np.all(np.isposinf(r[~finite]))
    valid = scan.valid_ranges_m()
    assert np.all(np.isnan(valid[~finite]))
    assert np.all(np.isfinite(valid[finite]))
    assert np.all(np.isnan(sim.points_world(r)[~finite]))


def test_scan_record_fields():
    spec = make_spec(range_noise_m=0.01)
    scan = LaserSim(spec, WALL_X5).scan(1_000, AgentSnapshot.empty(1_000), rng=0, stamp_ns=1_250)
    assert (scan.t_ns, scan.sensor, scan.frame_id) == (1_250, spec.name, spec.name)
    assert scan.n_beams == spec.n_beams
    assert scan.scan_time_s == pytest.approx(1 / 25)
    assert scan.time_increment_s == 0.0
    assert scan.angle_min_rad == pytest.approx(spec.angle_min_rad)
    assert scan.angle_increment_rad == pytest.approx(spec.angle_increment_rad)
    assert (scan.range_min_m, scan.range_max_m) == pytest.approx((spec.range_min_m, spec.range_max_m))
    assert LaserSim(spec, WALL_X5).scan(1_000, AgentSnapshot.empty(1_000), rng=0).t_ns == 1_000


def test_noise_has_the_specified_std():
    spec = make_spec(range_noise_m=0.02)
    sim = LaserSim(spec, WALL_X5)
    truth = wall_truth(beam_angles(spec), 5.0, 20.0)
    hit = np.isfinite(truth)
    rng = np.random.default_rng(42)
    err = np.concatenate([sim.ranges(AgentSnapshot.empty(0), rng)[hit] - truth[hit] for _ in range(30)])
    assert err.size > 9000
    assert np.std(err) == pytest.approx(0.02, rel=0.03)  # std of a sample std ~ 1/sqrt(2n) ≈ 0.7 %
    assert abs(np.mean(err)) < 4 * 0.02 / np.sqrt(err.size)


def test_same_seed_same_ranges():
    sim = LaserSim(make_spec(range_noise_m=0.01), ROOM)
    scene = snapshot([(1, (3.0, 0.0), (3.2, 0.3))])
    a = sim.ranges(scene, rng=np.random.default_rng(7))
    b = sim.ranges(scene, rng=np.random.default_rng(7))
    c = sim.ranges(scene, rng=np.random.default_rng(8))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_people_without_feet_and_low_vehicles_are_skipped():
    sim = LaserSim(make_spec(height_m=0.2), StaticWorld())
    scene = snapshot([(1, (np.nan, np.nan), (np.nan, np.nan))])
    assert np.all(np.isinf(sim.cast(scene)[0]))
    car = snapshot([], [(2, KIND_CAR, (4.0, 0.0), 0.0, 4.0, 1.8)])
    assert np.isfinite(sim.cast(car)[0]).sum() > 10
    low = dataclasses.replace(car, size_m=np.array([[4.0, 1.8, 0.1]]))  # lower than the scan plane
    assert np.all(np.isinf(sim.cast(low)[0]))


@pytest.mark.parametrize(("field", "value"), [("range_max_m", 0.01), ("range_noise_m", -1.0), ("n_beams", 0),
                                              ("angle_increment_rad", 0.0), ("x_m", np.nan)])
def test_bad_spec_is_a_config_error(field: str, value: float):
    kw = {"range_min_m": 0.05, "range_max_m": 30.0, "range_noise_m": 0.01, "n_beams": 720,
          "angle_increment_rad": 0.0065}
    kw[field] = value
    x = kw.pop("x_m", 0.0)
    with pytest.raises(ConfigError, match=field):
        LaserSim(LaserSpec("bad", x, 0.0, 0.0, Timing(25.0), **kw), StaticWorld())
