"""Scene understanding by rules (ALGORITHMS.md D7, D8): road geometry, the D8 known answers on synthetic tracks,
entity types and zones, configuration errors, and the rules against a simulation's incidents."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.eval.events import agent_tracks, read_agents_csv, read_incidents, score_events
from fusiontrack.io.tracks import group_tracks, read_jsonl, read_tracks_csv, write_jsonl, write_tracks_csv
from fusiontrack.scene import (
    SceneUnderstanding,
    default_rules,
    detect_events,
    load_road_geometry,
    load_rules,
    parse_road_geometry,
    parse_rules,
    road_geometry_from_world,
)
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import Simulation, simulate
from fusiontrack.types import Track, TrackState, records_equal

RATE_HZ = 25.0
KMH = 1 / 3.6

# A straight two-lane road 600 m long along x: "east" (+x) at y = -1.75, "west" (-x) at y = +1.75.
ROAD = {
    "roads": [{"name": "main", "centerline": [[-300.0, 0.0], [300.0, 0.0]], "width_m": 7.0}],
    "lanes": [
        {"name": "east", "road": "main", "centerline": [[-300.0, -1.75], [300.0, -1.75]], "width_m": 3.5},
        {"name": "west", "road": "main", "centerline": [[300.0, 1.75], [-300.0, 1.75]], "width_m": 3.5},
    ],
    "zones": [
        {"name": "east", "kind": "lane", "lane": "east"},
        {"name": "west", "kind": "lane", "lane": "west"},
        {"name": "bay", "kind": "parking", "polygon": [[100.0, -3.5], [140.0, -3.5], [140.0, -0.5], [100.0, -0.5]]},
        {"name": "verge", "kind": "no_stop", "polygon": [[-100.0, -3.5], [-50.0, -3.5], [-50.0, -9.0],
                                                          [-100.0, -9.0]]},
    ],
}


@pytest.fixture(scope="module")
def road():
    return parse_road_geometry(ROAD, "test road")


def make_track(tid: int, t_s: np.ndarray, xy: np.ndarray, v: np.ndarray, cls: str = "car") -> Track:
    return Track(tid, tuple(TrackState(round(t * 1e9), "test", tid, p, vv, cls=cls)
                            for t, p, vv in zip(t_s, xy, v, strict=True)))


def run_online(road, tracks, **kw):
    """Feed tracks frame by frame; returns [(frame time s, event)] for every event returned by update."""
    scene = SceneUnderstanding(road, kw.pop("rules", None))
    states = sorted((s for tr in tracks for s in tr.states), key=lambda s: s.t_ns)
    times = sorted({s.t_ns for s in states})
    by_t: dict[int, list] = {}
    for s in states:
        by_t.setdefault(s.t_ns, []).append(s)
    out = []
    for t in times:
        out += [(t * 1e-9, ev) for ev in scene.update(t, by_t[t], **kw)]
    return out, scene


def stop_track(tid: int = 1, x0: float = -200.0, y: float = -1.75, cls: str = "car", t_end: float = 45.0,
               drive_on: bool = True, rate_hz: float = RATE_HZ) -> Track:
    """15 m/s along +x, braking at 2.5 m/s^2 to a standstill at t = 20 s, stopped 15 s, then driving on."""
    t = np.arange(0.0, t_end, 1 / rate_hz)
    t_brake, t_stop, t_go, acc = 14.0, 20.0, 35.0, 2.0
    v = np.where(t < t_brake, 15.0, np.maximum(15.0 - 2.5 * (t - t_brake), 0.0))
    if drive_on:
        v = np.where(t > t_go, np.minimum(acc * (t - t_go), 15.0), v)
    x = x0 + np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 / rate_hz)])
    assert abs(v[np.searchsorted(t, t_stop)]) < 1e-9
    return make_track(tid, t, np.column_stack([x, np.full_like(x, y)]), np.column_stack([v, np.zeros_like(v)]),
                      cls)


# ------------------------------------------------------------------------------------------------
# Geometry
# ------------------------------------------------------------------------------------------------


def test_point_queries_on_a_straight_road(road) -> None:
    pts = np.array([[0.0, -1.0], [0.0, 2.0], [0.0, 5.0], [0.0, -4.5], [310.0, 0.0], [310.0, 5.0], [np.nan, 0.0]])
    assert road.inside_road(pts).tolist() == [True, True, False, False, False, False, False]
    d, n = road.edge_distance(pts)
    np.testing.assert_allclose(d[:4], [2.5, 1.5, -1.5, -1.0], atol=1e-12)
    np.testing.assert_allclose(n[:4], [[0, -1], [0, 1], [0, 1], [0, -1]], atol=1e-12)
    assert np.isnan(d[4:]).all()  # beyond the open end of the monitored stretch, and a NaN point
    lanes = road.lane_index(pts)
    assert [road.lane_names[i] if i >= 0 else "" for i in lanes] == ["east", "west", "", "", "", "", ""]
    s, lat, u = road.lane_coordinates(pts[:2])
    np.testing.assert_allclose(s, [300.0, 300.0])  # arc length along each lane's direction of travel
    np.testing.assert_allclose(lat, [0.75, -0.25])  # left of the direction of travel is positive
    np.testing.assert_allclose(u, [[1, 0], [-1, 0]], atol=1e-12)
    zones = road.zone_mask(np.array([[120.0, -2.0], [-70.0, -5.0]]))
    assert [[road.zone_names[j] for j in np.flatnonzero(row)] for row in zones] == [["east", "bay"], ["verge"]]


def test_curved_lane_and_polygon_lane() -> None:
    geo = parse_road_geometry({
        "roads": [{"name": "r", "polygon": [[-5, -5], [105, -5], [105, 105], [95, 105], [95, 5], [-5, 5]],
                   "open_edges": [2, 5]}],
        "lanes": [{"name": "bend", "centerline": [[0, 0], [100, 0], [100, 100]], "width_m": 4.0},
                  {"name": "box", "polygon": [[0, 50], [10, 50], [10, 60], [0, 60]], "direction_deg": 90.0}],
        "zones": [{"name": "first50", "kind": "lane", "lane": "bend", "s_range_m": [0.0, 50.0]}]})
    pts = np.array([[50.0, 1.0], [99.0, 50.0], [5.0, 55.0], [70.0, 1.0]])
    lanes = geo.lane_index(pts)
    assert lanes.tolist() == [0, 0, 1, 0]
    s, lat, u = geo.lane_coordinates(pts)
    np.testing.assert_allclose(s[:2], [50.0, 150.0])
    np.testing.assert_allclose(lat[:2], [1.0, 1.0])
    np.testing.assert_allclose(u[:3], [[1, 0], [0, 1], [0, 1]], atol=1e-12)
    assert geo.zone_mask(pts)[:, 0].tolist() == [False, False, False, False]  # first50 covers s in [0, 50]
    assert geo.zone_mask(np.array([[49.0, 0.0], [51.0, 0.0]]))[:, 0].tolist() == [True, False]
    d, _ = geo.edge_distance(np.array([[50.0, 4.0], [100.0, 110.0], [-10.0, 0.0]]))
    np.testing.assert_allclose(d[0], 1.0)
    assert np.isnan(d[1:]).all()  # beyond the two open ends


def test_world_json_lanes_match_the_simulators_lanes(tmp_path) -> None:
    """Every simulated vehicle drives inside the lane of its plan, in that lane's direction (sim/agents.py)."""
    scenario = load_scenario("road").with_overrides(seconds=30, seed=5, settings={
        "cameras": [], "lasers": [], "scenario.ground_truth_hz": 5.0})
    plans = {p.agent_id: p for p in Simulation(scenario).vehicle_plans}
    simulate(scenario, tmp_path / "run")
    geo = road_geometry_from_world(tmp_path / "run" / "ground_truth" / "world.json")
    agents = read_agents_csv(tmp_path / "run")
    leaving = {p.agent_id for p in plans.values() if p.incident == "leave"}
    sel = np.isin(agents.classes, ["car", "bicycle"]) & ~np.isin(agents.ids, list(leaving)) \
        & (np.abs(agents.positions_m[:, 0]) < 59.0)
    pos, ids, vel = agents.positions_m[sel], agents.ids[sel], agents.velocities_mps[sel]
    lanes = geo.lane_index(pos)
    names = np.array(geo.lane_names, dtype=object)[lanes]
    expected = np.array([f"road0_lane{plans[int(i)].lane}" for i in ids], dtype=object)
    assert sel.sum() > 200
    assert np.all(names == expected)
    moving = np.hypot(*vel.T) > 0.5
    assert np.all(np.einsum("nk,nk->n", geo.lane_direction(pos[moving]), vel[moving]) > 0)
    assert geo.inside_road(pos).all()
    assert {z.kind for z in geo.zones} == {"lane", "shoulder"}


def test_toml_geometry_equals_world_json(tmp_path) -> None:
    """The same road written as TOML and as a simulator world.json answers point queries identically."""
    (tmp_path / "world.json").write_text(json.dumps({"roads": [[-60.0, 0.0, 60.0, 0.0, 14.0]], "lane_width_m": 3.5}))
    lanes = []
    for k, y in ((0, -5.25), (1, -1.75)):
        lanes.append(f'[[lanes]]\nname = "road0_lane{k}"\nroad = "road0"\n'
                     f'centerline = [[-60.0, {y}], [60.0, {y}]]\nwidth_m = 3.5\n')
        lanes.append(f'[[lanes]]\nname = "road0_lane{-1 - k}"\nroad = "road0"\n'
                     f'centerline = [[60.0, {-y}], [-60.0, {-y}]]\nwidth_m = 3.5\n')
    (tmp_path / "road.toml").write_text('[[roads]]\nname = "road0"\ncenterline = [[-60.0, 0.0], [60.0, 0.0]]\n'
                                        'width_m = 14.0\n' + "".join(lanes))
    a = road_geometry_from_world(tmp_path / "world.json")
    b = load_road_geometry(tmp_path / "road.toml")
    pts = np.random.default_rng(0).uniform([-70, -12], [70, 12], (2000, 2))
    name_a = np.array(("", *a.lane_names), dtype=object)[a.lane_index(pts) + 1]
    name_b = np.array(("", *b.lane_names), dtype=object)[b.lane_index(pts) + 1]
    assert np.all(name_a == name_b)
    np.testing.assert_array_equal(a.inside_road(pts), b.inside_road(pts))
    np.testing.assert_allclose(a.edge_distance(pts)[0], b.edge_distance(pts)[0], equal_nan=True)
    np.testing.assert_allclose(a.lane_direction(pts), b.lane_direction(pts), equal_nan=True)


@pytest.mark.parametrize(("change", "where"), [
    (lambda d: d["lanes"][0].pop("width_m"), "lanes.0"),
    (lambda d: d["roads"][0].update(speed=3), "roads.0.speed"),
    (lambda d: d["zones"][2].update(kind="garage"), "zones.2.kind"),
    (lambda d: d["zones"][0].update(lane="north"), "zones.0.lane"),
    (lambda d: d["roads"][0].update(centerline=[[0.0, 0.0]]), "roads.0"),
    (lambda d: d["lanes"][1].update(road="side"), "lanes.1.road"),
    (lambda d: d.update(roads=[]), "roads"),
])
def test_geometry_errors_name_file_and_key(tmp_path, change, where) -> None:
    data = json.loads(json.dumps(ROAD))
    change(data)
    with pytest.raises(ConfigError, match=rf"road\.json.*{where}"):
        parse_road_geometry(data, "road.json")
    bad = tmp_path / "bad.toml"
    bad.write_text("[[roads]]\nname = 'r'\nwidth_m = -1\ncenterline = [[0, 0], [1, 0]]\n")
    with pytest.raises(ConfigError, match=r"bad\.toml.*roads\.0\.width_m"):
        load_road_geometry(bad)
    with pytest.raises(ConfigError, match="not found"):
        load_road_geometry(tmp_path / "missing.toml")


# ------------------------------------------------------------------------------------------------
# D8 known answers (synthetic tracks)
# ------------------------------------------------------------------------------------------------


def test_stopped_vehicle_alarm_at_30_s_and_none_before(road) -> None:
    out, _ = run_online(road, [stop_track()])
    starts = [(t, e) for t, e in out if e.t_end_ns is None]
    assert [e.kind for _, e in starts] == ["stopped_vehicle"]
    t_alarm, ev = starts[0]
    assert 30.0 <= t_alarm <= 30.6
    assert ev.attributes["alarm_t_ns"] * 1e-9 == pytest.approx(t_alarm)
    assert 19.8 <= ev.t_ns * 1e-9 <= 20.6  # the onset: when it (nearly) stopped
    assert ev.track_ids == (1,)
    assert ev.attributes["lane"] == "east"
    # it drives on at t = 35 s: the event ends when its speed exceeds 0.5 m/s, reported 2 s later
    ends = [(t, e) for t, e in out if e.t_end_ns is not None]
    assert len(ends) == 1
    t_end = ends[0][1].t_end_ns * 1e-9
    assert 35.2 <= t_end <= 35.8
    assert ends[0][0] == pytest.approx(t_end + 2.0, abs=0.05)


def test_lateral_drift_raises_road_leaving_within_5_frames(road) -> None:
    t = np.arange(0.0, 8.0, 1 / RATE_HZ)
    vy = np.where(t >= 3.0, -1.5, 0.0)
    y = -1.75 + np.minimum(0.0, -1.5 * (t - 3.0))
    x = -100.0 + 15.0 * t
    out, _ = run_online(road, [make_track(4, t, np.column_stack([x, y]), np.column_stack([np.full_like(t, 15.0),
                                                                                           vy]))])
    crossing = int(np.flatnonzero(y < -3.5 - 0.5)[0])  # the first frame more than 0.5 m outside
    leave = [(ts, e) for ts, e in out if e.kind == "road_leaving" and e.t_end_ns is None]
    assert len(leave) == 1
    alarm_frame = int(np.argmin(np.abs(t - leave[0][0])))
    assert 0 <= alarm_frame - crossing <= 5
    warn = [ts for ts, e in out if e.kind == "road_leaving_warning" and e.t_end_ns is None]
    assert len(warn) == 1
    assert 3.0 < warn[0] < t[np.flatnonzero(y < -3.5)[0]]  # warned before it crossed the edge
    assert {e.kind for _, e in out} == {"road_leaving", "road_leaving_warning"}


def test_queue_at_5_kmh_is_a_jam_from_30_s(road) -> None:
    t = np.arange(0.0, 40.0, 1 / 10.0)
    v = 5 * KMH
    tracks = [make_track(10 + k, t, np.column_stack([-6.0 * k + v * t, np.full_like(t, -1.75)]),
                         np.column_stack([np.full_like(t, v), np.zeros_like(t)])) for k in range(8)]
    out, scene = run_online(road, tracks)
    assert [e.kind for _, e in out] == ["jam"]
    t_alarm, ev = out[0]
    assert t_alarm == pytest.approx(30.0, abs=0.1)
    assert ev.t_ns * 1e-9 == pytest.approx(0.0, abs=0.1)
    assert ev.attributes["zone"] == "east"
    assert set(ev.track_ids) == set(range(10, 18))
    assert ev.attributes["properties"]["count"] == 8
    assert ev.attributes["properties"]["density"] == pytest.approx(160.0)  # 8 vehicles in 50 m
    assert scene.open_events[0].kind == "jam"


def test_free_flow_at_50_kmh_raises_nothing(road) -> None:
    t = np.arange(0.0, 60.0, 1 / 10.0)
    v = 50 * KMH
    tracks = []
    for k in range(6):
        x = -290.0 + 40 * k + v * t  # they drive out of the monitored stretch at x = 300
        tracks.append(make_track(k, t, np.column_stack([x, np.full_like(t, -1.75)]),
                                 np.column_stack([np.full_like(t, v), np.zeros_like(t)])))
        tracks.append(make_track(100 + k, t, np.column_stack([290.0 - 40 * k - v * t, np.full_like(t, 1.75)]),
                                 np.column_stack([np.full_like(t, -v), np.zeros_like(t)]), "bicycle"))
    out, _ = run_online(road, tracks)
    assert out == []


def test_wrong_way_driving(road) -> None:
    t = np.arange(0.0, 10.0, 1 / 10.0)
    one = np.ones_like(t)
    wrong = make_track(1, t, np.column_stack([100.0 - 14.0 * t, -1.75 * one]), np.column_stack([-14.0 * one, 0 * t]))
    reversing = make_track(2, t, np.column_stack([-150.0 - 1.0 * t, -1.75 * one]), np.column_stack([-one, 0 * t]))
    right = make_track(3, t, np.column_stack([150.0 - 14.0 * t, 1.75 * one]), np.column_stack([-14.0 * one, 0 * t]))
    out, _ = run_online(road, [wrong, reversing, right])
    assert [(e.kind, e.track_ids) for _, e in out] == [("wrong_way", (1,))]
    assert out[0][0] == pytest.approx(3.0, abs=0.1)
    assert out[0][1].attributes["lane"] == "east"


# ------------------------------------------------------------------------------------------------
# D7: entity types, zones, temporal bookkeeping
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("cls", "extra", "alarm"), [
    ("car", {"lengths_m": {1: 4.5}}, True),
    ("car", {"lengths_m": {1: 20.0}}, False),  # longer than 18 m: a group of vehicles
    ("unknown", {"laser_counts": {1: 2}}, False),  # a camera blob over two laser objects: a group
    ("group", {}, False),
    ("person", {}, False),
    ("bicycle", {}, True),
])
def test_entity_type_selects_the_stopped_vehicle_rule(road, cls, extra, alarm) -> None:
    out, _ = run_online(road, [stop_track(cls=cls, t_end=31.0, drive_on=False, rate_hz=10.0)], **extra)
    assert [e.kind for _, e in out] == (["stopped_vehicle"] if alarm else [])


def test_parking_and_no_stop_zones(road) -> None:
    # braking at 2.5 m/s^2 from 15 m/s covers 45 m: x0 + 210 + 45 is where it stops
    in_bay = stop_track(x0=120.0 - 255.0, y=-2.0, t_end=31.0, drive_on=False, rate_hz=10.0)
    on_verge_no_stop = stop_track(2, x0=-75.0 - 255.0, y=-5.0, t_end=31.0, drive_on=False, rate_hz=10.0)
    on_verge = stop_track(3, x0=20.0 - 255.0, y=5.5, t_end=31.0, drive_on=False, rate_hz=10.0)
    assert 100 < in_bay.states[-1].position_m[0] < 140
    out, _ = run_online(road, [in_bay, on_verge_no_stop, on_verge])
    assert [(e.kind, e.track_ids, e.attributes["zone"]) for _, e in out] == [("stopped_vehicle", (2,), "verge")]


def test_lost_track_ends_its_event_and_bad_input_degrades(road) -> None:
    tr = stop_track(t_end=32.0, drive_on=False, rate_hz=10.0)
    scene = SceneUnderstanding(road)
    for s in tr.states:
        scene.update(s.t_ns, [s, TrackState(s.t_ns, "test", 9, (np.nan, np.nan))])
    scene.update(tr.t_end_ns + 1_000_000_000, [])
    assert scene.open_events[0].kind == "stopped_vehicle"
    ended = scene.update(tr.t_end_ns + 3_000_000_000, [])  # 2 s timeout
    assert len(ended) == 1
    assert ended[0].t_end_ns == tr.t_end_ns
    assert scene.open_events == []
    with pytest.raises(ConfigError, match="time order"):
        scene.update(0, [])


def test_batch_equals_online_and_events_round_trip(road, tmp_path) -> None:
    tracks = [stop_track(rate_hz=10.0), stop_track(2, x0=-260.0, rate_hz=10.0)]
    online, scene = run_online(road, tracks)
    batch = detect_events(tracks, road)
    assert len(batch) == len(scene.events) == 2
    for a, b in zip(sorted(scene.events, key=lambda e: e.track_ids), sorted(batch, key=lambda e: e.track_ids),
                    strict=True):
        assert records_equal(a, b)
    write_jsonl(tmp_path / "events.jsonl", batch)
    back = read_jsonl(tmp_path / "events.jsonl")
    assert all(records_equal(a, b) for a, b in zip(batch, back, strict=True))
    # a saved tracks.csv read back gives the same events
    write_tracks_csv(tmp_path / "tracks.csv", tracks)
    again = detect_events(group_tracks(read_tracks_csv(tmp_path / "tracks.csv", sensor="test")), road)
    assert [(e.kind, e.t_ns, e.t_end_ns, e.track_ids) for e in again] == \
        [(e.kind, e.t_ns, e.t_end_ns, e.track_ids) for e in batch]
    del online


# ------------------------------------------------------------------------------------------------
# Rules configuration
# ------------------------------------------------------------------------------------------------


def test_default_rules_are_d8(tmp_path) -> None:
    rules = default_rules()
    assert rules.kinds == ("stopped_vehicle", "road_leaving", "road_leaving_warning", "jam", "wrong_way")
    by = {r.name: r for r in rules.rules}
    assert by["stopped_vehicle"].spec.hold_s == 10.0
    assert by["stopped_vehicle"].env["v_stop"] == 0.5
    assert by["road_leaving"].spec.hold_frames == 5
    assert by["road_leaving"].env["d_out"] == 0.5
    assert by["jam"].spec.window_m == 50.0
    assert by["jam"].spec.min_count == 5
    assert by["jam"].spec.hold_s == 30.0
    assert by["jam"].env["v_jam"] == pytest.approx(10 * KMH, abs=1e-4)
    assert by["stopped_vehicle"].selected == ("speed", "on_road")
    assert rules.smoothing.speed_median_s == 0.5
    # a user file: a stricter stopped-vehicle rule only
    f = tmp_path / "rules.toml"
    f.write_text('[rules.stopped_vehicle]\nwhen = "speed <= v and on_road"\nhold_s = 5.0\nparams = { v = 0.5 }\n')
    custom = load_rules(f)
    assert custom.kinds == ("stopped_vehicle",)
    assert load_rules(None) is default_rules()


@pytest.mark.parametrize(("text", "where"), [
    ('[rules.a]\nwhen = "sped < 1"\n', r"rules\.a\.when: unknown name 'sped'"),
    ('[rules.a]\nwhen = "speed < 1"\nhold_s = -1\n', r"rules\.a\.hold_s"),
    ('[rules.a]\nwhen = "speed < 1"\nwindow_m = 40\n', r"rules\.a"),
    ('[rules.a]\nwhen = "speed < "\n', r"rules\.a\.when: not an expression"),
    ('[rules.a]\nwhen = "__import__(1)"\n', r"rules\.a\.when: calls allowed"),
    ('[rules.a]\nwhen = "in_zone_kind(\'garage\')"\n', r"rules\.a\.when: zone kind 'garage'"),
    ('[rules.a]\nentity = "lane_zone"\nwhen = "count > 3 and on_road"\n', r"rules\.a\.when: unknown name 'on_road'"),
    ('[rules.a]\nwhen = "speed < 1"\nparams = { speed = 1.0 }\n', r"rules\.a\.params"),
    ('[rules.a]\nwhen = "speed < 1"\ncolour = "red"\n', r"rules\.a\.colour"),
    ("[smoothing]\nspeed_median_s = 0\n[rules.a]\nwhen = 'speed < 1'\n", r"smoothing\.speed_median_s"),
])
def test_rules_errors_name_file_and_key(tmp_path, text, where) -> None:
    f = tmp_path / "my_rules.toml"
    f.write_text(text)
    with pytest.raises(ConfigError, match=rf"my_rules\.toml.*{where}"):
        load_rules(f)


def test_rule_naming_a_missing_zone_is_refused(road) -> None:
    rules = parse_rules({"rules": {"a": {"when": "in_zone('nowhere') and speed < 1"}}}, "r.toml")
    with pytest.raises(ConfigError, match="nowhere"):
        SceneUnderstanding(road, rules)
    expr_ok = parse_rules({"rules": {"a": {"when": "in_zone('bay') and abs(lane_offset) < 1 and -speed > -1"}}})
    SceneUnderstanding(road, expr_ok)


def test_rules_pickle_and_arithmetic_conditions_do_not_warn(road) -> None:
    import pickle
    import warnings

    rules = parse_rules({"rules": {"a": {"when": "speed / (lane_offset - lane_offset) > 1 or not on_road"}}})
    back = pickle.loads(pickle.dumps(rules))
    env = {"speed": np.array([1.0, 0.0, np.nan]), "lane_offset": np.zeros(3), "on_road": np.array([True, True, False])}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # x / 0 and 0 / 0 are inf and NaN, silently
        for r in (rules, back):
            np.testing.assert_array_equal(r.rules[0].when(env, 3), [True, False, True])
    default = pickle.loads(pickle.dumps(default_rules()))
    assert [r.when.text for r in default.rules] == [r.when.text for r in default_rules().rules]
    n = 4
    env = {p: np.zeros(n) for p in ("speed", "edge_distance", "predicted_edge_distance", "lateral_speed",
                                    "lane_cos", "time_on_road")}
    env.update(on_road=np.ones(n, bool), in_lane=np.ones(n, bool), measured=np.ones(n, bool))
    zone = lambda fn, arg: np.zeros(n, bool)  # noqa: E731
    for a, b in zip(default.rules, default_rules().rules, strict=True):
        if a.spec.entity != "lane_zone":
            np.testing.assert_array_equal(a.when({**env, **a.env}, n, zone), b.when({**env, **b.env}, n, zone))


def test_dense_frames_grow_the_history_and_keep_the_median(road) -> None:
    from fusiontrack.scene.rules import SwitchingControl

    control = SwitchingControl(road, default_rules())
    rate, window = 100.0, 0.5  # 50 samples in the median window, more than the ring holds at first
    vx = 10.0 + np.arange(300) % 7  # m/s, known samples
    for i in range(300):
        t_ns = round(i / rate * 1e9)
        frame = control.observe(t_ns, [TrackState(t_ns, "test", 1, np.array([-100.0 + 0.1 * i, -1.75]),
                                                  np.array([vx[i], 0.0]))])
        recent = vx[max(0, i - round(window * rate) + 1):i + 1]  # the samples newer than 0.5 s
        assert frame.props["speed"][0] == pytest.approx(np.median(recent), abs=1e-12)
        assert frame.velocity_mps[0, 0] == pytest.approx(np.median(recent), abs=1e-12)


def test_geometry_without_lane_zones_skips_jams(caplog) -> None:
    bare = parse_road_geometry({k: v for k, v in ROAD.items() if k != "zones"}, "bare road")
    out, _ = run_online(bare, [stop_track(t_end=31.0, drive_on=False, rate_hz=10.0)])
    assert [e.kind for _, e in out] == ["stopped_vehicle"]
    assert "no zone of kind 'lane'" in caplog.text


# ------------------------------------------------------------------------------------------------
# Against the simulator's incidents
# ------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def road_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("scene") / "road"
    scenario = load_scenario("road").with_overrides(seconds=100, seed=7, settings={
        "cameras": [], "lasers": [], "scenario.ground_truth_hz": 10.0})
    simulate(scenario, out)
    return out


def test_rules_find_the_simulated_incidents(road_run) -> None:
    geo = road_geometry_from_world(road_run / "ground_truth" / "world.json")
    agents = read_agents_csv(road_run)
    incidents = read_incidents(road_run)
    events = detect_events(agent_tracks(agents), geo)
    scores = score_events(incidents, events, agents)
    for kind in ("stopped_vehicle", "road_leaving", "jam"):
        s = scores[kind]
        assert s.true >= 1, kind
        assert s.recall >= 0.9, (kind, s)
        assert s.precision >= 0.9, (kind, s)
        assert s.median_latency_s <= 2.0, (kind, s)
    assert scores["stopped_vehicle"].median_alarm_latency_s == pytest.approx(10.0, abs=1.0)  # D8 T_stop
    assert scores["road_leaving"].median_alarm_latency_s <= 2.0
    assert scores["wrong_way"].detections == 0
    warn = score_events(incidents, events, agents, kinds=("road_leaving",),
                        kind_map={"road_leaving_warning": "road_leaving", "road_leaving": "-"})
    assert warn["road_leaving"].recall == 1.0
    assert warn["road_leaving"].median_latency_s < 0
    assert math.isfinite(scores["jam"].median_alarm_latency_s)
