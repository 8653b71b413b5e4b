"""Simulated agents: two-feet gait (ALGORITHMS.md B8), social-force walking, groups, crowds, road incidents (D8)."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.sim import plans, worlds
from fusiontrack.sim.agents import Population
from fusiontrack.sim.model import KIND_CAR, Appearance, PedestrianPlan, StaticWorld
from fusiontrack.types import records_equal

LOOK = Appearance((0, 0, 200), (200, 0, 0))
OPEN = StaticWorld(bounds_m=np.array([-30.0, -30.0, 30.0, 30.0]))


def walker(agent_id: int, route: list, speed: float = 1.2, stride: float = 1.3, waits: list | None = None,
           t_start: float = 0.0, **kw) -> PedestrianPlan:
    route = np.array(route, np.float64)
    return PedestrianPlan(agent_id=agent_id, t_start_s=t_start, waypoints_m=route, speed_mps=speed,
                          waits_s=np.zeros(len(route)) if waits is None else np.array(waits, np.float64),
                          height_m=1.75, appearance=LOOK, stride_m=stride, period_s=stride / speed, **kw)


def track(pop: Population, t_end_s: float, rate_hz: float = 25.0) -> list:
    return [pop.snapshot(round(k / rate_hz * 1e9)) for k in range(int(t_end_s * rate_hz) + 1)]


def positions_of(snaps: list, agent_id: int) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and positions (n, 2) of one agent over the snapshots where it is present."""
    rows = [(s.t_ns * 1e-9, s.position_m[s.ids == agent_id][0]) for s in snaps if np.any(s.ids == agent_id)]
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows]).reshape(-1, 2)


# ------------------------------------------------------------------ B8 two-feet kinematics


@pytest.fixture(scope="module")
def straight_walk() -> tuple[Population, list]:
    pop = Population(OPEN, [walker(7, [[-15.0, 0.0], [15.0, 0.0]], speed=1.2, stride=1.3)], rng=3)
    return pop, track(pop, 20.0)


def test_feet_separation_follows_the_b8_cosine(straight_walk: tuple[Population, list]) -> None:
    _, snaps = straight_walk
    feet = np.array([s.feet_m[0] for s in snaps[25:]])
    phase = np.array([s.gait_phase_rad[0] for s in snaps[25:]])
    u = np.array([[np.cos(s.heading_rad[0]), np.sin(s.heading_rad[0])] for s in snaps[25:]])
    separation = np.einsum("nk,nk->n", feet[:, 0] - feet[:, 1], u)
    np.testing.assert_allclose(separation, -(1.3 / np.pi) * np.cos(phase), atol=1e-9)
    lateral = np.einsum("nk,nk->n", feet[:, 0] - feet[:, 1], u[:, ::-1] * [-1.0, 1.0])
    np.testing.assert_allclose(lateral, 0.2, atol=1e-9)  # left foot on the left, 2 x 0.1 m apart
    np.testing.assert_allclose(feet.mean(axis=1), [s.position_m[0] for s in snaps[25:]], atol=1e-12)


def test_foot_speeds_follow_b8(straight_walk: tuple[Population, list]) -> None:
    _, snaps = straight_walk
    dt = 1 / 25
    feet = np.array([s.feet_m[0] for s in snaps[25:300]])
    phase = np.unwrap([s.gait_phase_rad[0] for s in snaps[25:300]])
    body_speed = np.linalg.norm(np.diff([s.position_m[0] for s in snaps[25:300]], axis=0), axis=1) / dt
    np.testing.assert_allclose(body_speed, 1.2, rtol=1e-6)  # free walking at the preferred speed
    left_speed = np.diff(feet[:, 0, 0]) / dt  # walking along +x
    mid = (phase[1:] + phase[:-1]) / 2
    # B8: v_L = (S/T)(1 + sin φ), v_R = (S/T)(1 - sin φ), S/T = the walking speed
    np.testing.assert_allclose(left_speed, 1.2 * (1 + np.sin(mid)), atol=0.02)
    np.testing.assert_allclose(np.diff(feet[:, 1, 0]) / dt, 1.2 * (1 - np.sin(mid)), atol=0.02)
    assert abs(np.mean(left_speed) - 1.2) < 0.02 * 1.2 + 1.3 / np.pi / (len(left_speed) * dt)


def test_heel_strikes_every_half_stride_alternating(straight_walk: tuple[Population, list]) -> None:
    pop, snaps = straight_walk
    events = pop.drain_step_events()
    assert pop.drain_step_events() == []
    _, xy = positions_of(snaps, 7)
    walked = np.linalg.norm(xy[-1] - xy[0])
    assert abs(len(events) - 2 * walked / 1.3) <= 1.5
    assert {e.agent_id for e in events} == {7}
    feet = np.array([e.foot for e in events])
    assert np.all(feet[1:] != feet[:-1])
    x = np.array([e.position_m[0] for e in events])
    np.testing.assert_allclose(np.diff(x), 1.3 / 2, atol=1e-6)
    np.testing.assert_allclose([e.position_m[1] for e in events], np.where(feet == 0, 0.1, -0.1), atol=1e-9)
    # the striking foot is the one ahead, S/(2π) in front of the body (d = ±S/π at φ = π or 0)
    for e in events[5:10]:
        s = min(snaps, key=lambda s: abs(s.t_ns - e.t_ns))
        ahead = s.feet_m[0, e.foot, 0] - s.position_m[0, 0]
        assert ahead == pytest.approx(1.3 / (2 * np.pi), abs=0.05)


def test_standing_person_has_feet_together_and_no_steps() -> None:
    pop = Population(OPEN, [walker(1, [[0.0, 0.0], [5.0, 0.0]], waits=[3.0, 0.0], leave_at_end=False)], rng=0)
    snaps = track(pop, 10.0)
    still = [s for s in snaps if s.t_ns < 2.9e9]
    assert all(np.allclose(np.linalg.norm(s.velocity_mps[0]), 0) for s in still)
    assert all(np.allclose(s.feet_m[0, 0] - s.feet_m[0, 1], [0.0, 0.2]) for s in still)  # heading +x, feet abreast
    events = pop.drain_step_events()
    assert events
    assert min(e.t_ns for e in events) > 3e9
    assert len({s.gait_phase_rad[0] for s in still}) == 1
    last = snaps[-1]
    np.testing.assert_allclose(last.position_m[0], [5.0, 0.0], atol=0.3)  # stays at its last waypoint


# ------------------------------------------------------------------ social force


def test_walker_goes_round_a_pillar_and_a_bench_to_its_goal() -> None:
    room = worlds.room(16, 12, rng=0, n_pillars=0)
    world = StaticWorld(walls=room.walls, pillars=np.array([[-2.0, 0.05, 0.35]]),
                        boxes=np.array([[3.0, -0.05, 1.6, 0.45, np.pi / 2, 0.45]]), bounds_m=room.bounds_m)
    pop = Population(world, [walker(1, [[-8.0, 0.0], [8.0, 0.0]], speed=1.4)], rng=0)
    snaps = track(pop, 25.0)
    times, xy = positions_of(snaps, 1)
    assert worlds.clearance(world, xy).min() > 0.15
    assert times[-1] < 20.0
    assert xy[-1, 0] > 7.0


def test_head_on_walkers_avoid_each_other_and_arrive() -> None:
    pop = Population(OPEN, [walker(1, [[-8.0, 0.0], [8.0, 0.0]]), walker(2, [[8.0, 0.0], [-8.0, 0.0]], speed=1.3)],
                     rng=0)
    snaps = track(pop, 25.0)
    both = [s for s in snaps if len(s) == 2]
    gaps = [np.linalg.norm(s.position_m[0] - s.position_m[1]) for s in both]
    assert min(gaps) > 0.4
    assert len(snaps[-1]) == 0  # both reached their goals (and left)
    t1, xy1 = positions_of(snaps, 1)
    assert xy1[-1, 0] > 7.4
    assert t1[-1] < 18.0


def test_group_walks_together_then_splits() -> None:
    world = worlds.room(rng=5)
    group_plans, _ = plans.groups_plans(world, n_groups=1, rng=5, n_singles=0)
    pop = Population(world, group_plans, rng=5)
    snaps = track(pop, 40.0, rate_hz=10.0)
    ids = [p.agent_id for p in group_plans]
    together, apart_after = [], []
    for s in snaps:
        mine = np.isin(s.ids, ids)
        grouped = mine & (s.group_ids >= 0)
        if grouped.sum() >= 2:
            pts = s.position_m[grouped]
            together.append(np.max(np.linalg.norm(pts[:, None] - pts[None], axis=-1)))
        elif together and mine.sum() >= 2:
            pts = s.position_m[mine]
            apart_after.append(np.min(np.linalg.norm(pts[:, None] - pts[None], axis=-1)[np.triu_indices(len(pts), 1)]))
    assert len(together) >= 30  # walked together for 3 s or more
    assert max(together[5:]) < 1.2 * (len(ids) - 1)  # side by side (3 abreast: < 2.4 m end to end)
    assert apart_after
    assert apart_after[-1] > 2.0
    assert len(snaps[-1]) == 0


def test_crowd_count_and_interactions_over_two_minutes() -> None:
    world = worlds.room(rng=11)
    crowd, vehicles = plans.crowd_plans(world, mean_present=10, duration_s=120, rng=11)
    assert vehicles == []
    assert len({p.agent_id for p in crowd}) == len(crowd)
    assert any(p.t_start_s == 0 for p in crowd)
    assert any(p.t_start_s > 60 for p in crowd)
    assert sum(p.group_id >= 0 for p in crowd) >= 2
    assert any(np.any(p.waits_s > 0) for p in crowd)
    pop = Population(world, crowd, rng=11)
    present, pairs = [], []
    for s in track(pop, 120.0, rate_hz=5.0):
        p = s.position_m[s.persons]
        present.append(len(p))
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)[np.triu_indices(len(p), 1)]
        pairs.append(int((d < 1.5).sum()))
    assert abs(np.mean(present) / 10 - 1) < 0.3
    assert np.mean(pairs) >= 1.0
    assert np.mean(present[:50]) > 5  # people are inside from the first frame


def test_lookalikes_dress_alike_and_others_differ() -> None:
    crowd, _ = plans.crowd_plans(worlds.room(rng=2), mean_present=8, duration_s=30, rng=2, lookalike_pairs=1)
    looks = np.array([p.appearance.upper_bgr + p.appearance.lower_bgr for p in crowd], np.int64)
    diff = np.abs(looks[:, None] - looks[None]).max(axis=-1)
    close = np.argwhere(np.triu(diff <= 8, 1))
    assert len(close) >= 1
    assert all(crowd[i].appearance.pattern == crowd[j].appearance.pattern for i, j in close)
    heights = np.array([p.height_m for p in crowd])
    assert heights.min() >= 1.55
    assert heights.max() <= 1.95
    speeds = np.array([p.speed_mps for p in crowd])
    assert speeds.min() >= 0.8
    assert speeds.max() <= 1.6
    np.testing.assert_allclose([p.stride_m / p.period_s for p in crowd], speeds)


def test_same_seed_same_motion() -> None:
    world = worlds.room(rng=4)
    runs = []
    for _ in range(2):
        crowd, _ = plans.crowd_plans(world, mean_present=6, duration_s=10, rng=4)
        pop = Population(world, crowd, rng=4)
        runs.append((track(pop, 10.0, rate_hz=7.0), pop.drain_step_events()))
    assert len(runs[0][1]) > 50
    assert all(records_equal(a, b) for a, b in zip(runs[0][0], runs[1][0], strict=True))
    assert runs[0][1] == runs[1][1]


def test_recording_clock_offset() -> None:
    t0 = 1_700_000_000 * 1_000_000_000
    pops = [Population(OPEN, [walker(1, [[0.0, 0.0], [9.0, 0.0]])], rng=0, t0_ns=t0_ns) for t0_ns in (0, t0)]
    a, b = pops[0].snapshot(3_210_000_000), pops[1].snapshot(t0 + 3_210_000_000)
    assert b.t_ns == t0 + 3_210_000_000
    np.testing.assert_array_equal(a.feet_m, b.feet_m)
    assert [e.t_ns + t0 for e in pops[0].step_events] == [e.t_ns for e in pops[1].step_events]


def test_snapshot_asked_too_far_back_is_refused() -> None:
    pop = Population(OPEN, [walker(1, [[0.0, 0.0], [5.0, 0.0]])], rng=0)
    pop.snapshot(2_000_000_000)
    with pytest.raises(ConfigError, match="t_ns"):
        pop.snapshot(1_000_000_000)


def test_corridor_subject_stands_still_then_walks_the_loop() -> None:
    world = worlds.corridor_loop(rng=1)
    walkers, _ = plans.corridor_plans(world, duration_s=200, rng=1, phone="phone_a", n_passers=0)
    assert walkers[0].phone == "phone_a"
    assert not walkers[0].leave_at_end
    pop = Population(world, walkers, rng=1)
    times, xy = positions_of(track(pop, 45.0, rate_hz=10.0), walkers[0].agent_id)
    still = times < 11.9
    assert np.ptp(xy[still], axis=0).max() == 0.0
    assert min(e.t_ns for e in pop.drain_step_events()) > 12e9
    speed = np.linalg.norm(np.diff(xy[times > 15], axis=0), axis=1).sum() / (times[-1] - 15)
    assert 1.1 < speed < 1.4
    assert worlds.clearance(world, xy).min() > 0.3  # round the corners without touching a wall


# ------------------------------------------------------------------ road and incidents (D8)


@pytest.fixture(scope="module")
def road_run() -> tuple:
    world = worlds.road(rng=2)
    walkers, vehicles = plans.road_plans(world, duration_s=100, rng=2)
    assert walkers == []
    pop = Population(world, (), vehicles, rng=2)
    return world, vehicles, pop, track(pop, 100.0, rate_hz=10.0)


def _speeds(snaps: list, agent_id: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows = [(s.t_ns * 1e-9, *s.position_m[s.ids == agent_id][0], np.linalg.norm(s.velocity_mps[s.ids == agent_id][0]))
            for s in snaps if np.any(s.ids == agent_id)]
    a = np.array(rows)
    return a[:, 0], a[:, 1:3], a[:, 3]


def test_stopped_vehicle_incident_matches_its_motion(road_run: tuple) -> None:
    _, vehicles, pop, snaps = road_run
    (stopper,) = [v for v in vehicles if v.incident == "stop"]
    (inc,) = [i for i in pop.incidents if i.kind == "stopped_vehicle"]
    assert inc.agent_ids == (stopper.agent_id,)
    t, _, v = _speeds(snaps, stopper.agent_id)
    t0, t1 = inc.t_start_ns * 1e-9, inc.t_end_ns * 1e-9
    first_still = t[np.flatnonzero((v < 0.01) & (t > stopper.incident_t_s))[0]]
    assert first_still - 0.1 - 1e-9 <= t0 <= first_still
    assert np.all(v[(t >= t0) & (t <= t1)] < 0.5)
    assert t1 - t0 == pytest.approx(stopper.incident_duration_s, abs=0.05)
    assert v[t < stopper.incident_t_s].min() > 5.0
    assert v[t > t1 + 3].max() > 3.0


def test_road_leaving_vehicle_ends_off_the_road(road_run: tuple) -> None:
    world, vehicles, pop, snaps = road_run
    (leaver,) = [v for v in vehicles if v.incident == "leave"]
    (inc,) = [i for i in pop.incidents if i.kind == "road_leaving"]
    t, xy, v = _speeds(snaps, leaver.agent_id)
    half_width = world.roads[0, 4] / 2
    outside = np.abs(xy[:, 1]) - half_width  # the road runs along y = 0
    assert outside[-1] > 0.5
    assert v[-1] == 0.0
    crossed = t[np.flatnonzero(outside > 0)[0]]
    assert crossed - 0.1 - 1e-9 <= inc.t_start_ns * 1e-9 <= crossed
    assert np.all(outside[t < inc.t_start_ns * 1e-9 - 1e-6] <= 0)
    assert worlds.clearance(world, xy[-1:])[0] > 1.0  # parked clear of the poles


def test_slow_vehicle_builds_a_jam(road_run: tuple) -> None:
    _, vehicles, pop, snaps = road_run
    (slow,) = [v for v in vehicles if v.incident == "slow"]
    (inc,) = [i for i in pop.incidents if i.kind == "jam"]
    assert slow.agent_id in inc.agent_ids
    assert len(inc.agent_ids) >= 6
    lanes = {v.agent_id: v.lane for v in vehicles}
    queue = []
    for s in snaps:
        k = np.flatnonzero(s.ids == slow.agent_id)
        if not k.size:
            queue.append(0)
            continue
        behind = np.array([lanes[int(i)] == slow.lane for i in s.ids]) & (s.position_m[:, 0] < s.position_m[k[0], 0]) \
            & (s.position_m[:, 0] > s.position_m[k[0], 0] - 50) & (np.linalg.norm(s.velocity_mps, axis=1) < 10 / 3.6)
        queue.append(int(behind.sum()))
    t = np.array([s.t_ns * 1e-9 for s in snaps])
    queue = np.array(queue)
    assert queue.max() >= 5
    during = (t >= inc.t_start_ns * 1e-9 + 0.1) & (t <= inc.t_end_ns * 1e-9 - 0.1)
    assert np.all(queue[during] >= 5)
    assert during.sum() > 100
    assert inc.t_end_ns < 100e9  # and it clears once the slow car speeds up


def _overlap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Separating-axis test of convex quadrilaterals, ``(p, 4, 2)`` x 2 -> ``(p,)`` bool."""
    hit = np.ones(a.shape[0], bool)
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=1) - poly
        for e in range(4):
            axis = edges[:, e, ::-1] * [-1.0, 1.0]
            pa, pb = np.einsum("pkd,pd->pk", a, axis), np.einsum("pkd,pd->pk", b, axis)
            hit &= ~((pa.max(1) < pb.min(1)) | (pb.max(1) < pa.min(1)))
    return hit


def test_vehicles_never_overlap_and_keep_their_shapes(road_run: tuple) -> None:
    _, vehicles, _, snaps = road_run
    seen = set()
    for s in snaps:
        if len(s) < 2:
            continue
        i, j = np.triu_indices(len(s), 1)
        fp = s.footprints()
        assert not np.any(_overlap(fp[i], fp[j])), f"overlap at t = {s.t_ns * 1e-9:.1f} s"
        assert np.all(np.isnan(s.feet_m))
        assert np.all(s.gait_phase_rad == 0)
        seen.update(s.kinds.tolist())
    assert KIND_CAR in seen
    assert len(seen) == 2
    bikes = [v for v in vehicles if v.width_m < 1.0]
    assert bikes
    assert all(v.lane in (0, -1) for v in bikes)


def test_bad_plans_are_refused() -> None:
    with pytest.raises(ConfigError, match="agent_id"):
        Population(OPEN, [walker(1, [[0, 0], [1, 0]]), walker(1, [[0, 0], [2, 0]])])
    with pytest.raises(ConfigError, match="n_people"):
        plans.crossing_plans(worlds.room(rng=0), n_people=5)
