"""Scene understanding on tracker-like output (issue 8): tracks that coast off the road, a stopped vehicle lost and
found again under a new id, and the labels of tracked windows, all against the simulator's incidents."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from fusiontrack.eval.events import agent_tracks, read_agents_csv, read_incidents, score_events
from fusiontrack.scene import (
    SceneClassifier,
    default_rules,
    detect_events,
    detect_events_learned,
    parse_rules,
    road_geometry_from_world,
)
from fusiontrack.scene.learned import FEATURES, label_samples, main, match_agents, tracked_samples, window_samples
from fusiontrack.scene.rules import default_rules_text
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.types import Track, TrackState

SEED, SECONDS = 5, 45  # a stopped vehicle at ~10 s, a vehicle leaving the road at ~15 s, a jam from ~32 s


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A simulated road run (agents only) in the layout ``train_scene_classifier`` reuses."""
    work = tmp_path_factory.mktemp("tracked")
    out = work / f"road_{SEED}_{SECONDS}"
    simulate(load_scenario("road").with_overrides(seconds=SECONDS, seed=SEED, settings={
        "cameras": [], "lasers": [], "scenario.ground_truth_hz": 10.0}), out)
    return out


@pytest.fixture(scope="module")
def truth(run):
    gt = run / "ground_truth"
    agents = read_agents_csv(run)
    return road_geometry_from_world(gt / "world.json"), agents, read_incidents(run), agent_tracks(agents)


def coast_off(track: Track, t_from_ns: int, lateral_mps: float, seconds: float = 1.5) -> Track:
    """The track up to ``t_from_ns``, then coasting (no sensor, score 0.5) on its velocity plus ``lateral_mps``
    away from the road's centre line for ``seconds``, then lost: a particle filter's mode after a wrong update."""
    keep = [s for s in track.states if s.t_ns <= t_from_ns]
    last = keep[-1]
    v = last.velocity_mps + np.array([0.0, np.sign(last.position_m[1]) * lateral_mps])
    coast = [TrackState(last.t_ns + k * 100_000_000, "tracker", track.track_id, last.position_m + v * k * 0.1, v,
                        cls=last.cls, sensors=(), score=0.5) for k in range(1, round(seconds * 10) + 1)]
    return Track(track.track_id, (*keep, *coast))


def test_coasting_off_the_road_raises_no_road_leaving(truth) -> None:
    geo, agents, incidents, tracks = truth
    involved = {i for e in incidents for i in e.track_ids}
    free = [tr for tr in tracks if tr.track_id not in involved and tr.states[0].cls == "car"
            and len(tr.states) > 60 and abs(tr.states[0].position_m[1]) > 3.5]  # outer lanes: 2 m from the edge
    assert len(free) >= 3
    faulty = {tr.track_id: coast_off(tr, tr.states[len(tr.states) // 2].t_ns, 4.0) for tr in free[:3]}
    for tr in faulty.values():  # each coasts > 0.5 m off the road for >= 5 frames
        edge = geo.edge_distance(np.array([s.position_m for s in tr.states]))[0]
        assert np.sum(edge < -0.5) >= 5
    corrupted = [faulty.get(tr.track_id, tr) for tr in tracks]
    scores = score_events(incidents, detect_events(corrupted, geo), agents)
    leave = scores["road_leaving"]
    assert (leave.true, leave.true_positives, leave.false_alarms) == (1, 1, 0), leave
    assert leave.median_alarm_latency_s <= 1.0  # N_out = 5 frames at 10 Hz after 0.5 m outside
    # the same rule without the `measured` condition takes the predictions for evidence: false alarms
    text = default_rules_text().replace(" and measured\"", "\"")
    assert text != default_rules_text()
    naive = parse_rules(tomllib.loads(text), "naive.toml")
    naive_scores = score_events(incidents, detect_events(corrupted, geo, naive), agents)
    assert naive_scores["road_leaving"].false_alarms == 3
    assert "measured" in next(r for r in default_rules().rules if r.name == "road_leaving").selected


def test_stopped_vehicle_found_again_is_one_incident(truth) -> None:
    geo, agents, incidents, tracks = truth
    stop = next(e for e in incidents if e.kind == "stopped_vehicle")
    tr = next(t for t in tracks if t.track_id == stop.track_ids[0])
    mid = (stop.t_ns + stop.t_end_ns) // 2
    first = [s for s in tr.states if s.t_ns <= mid - 1_000_000_000]
    again = [TrackState(s.t_ns, s.sensor, 900, s.position_m, s.velocity_mps, cls=s.cls, sensors=s.sensors)
             for s in tr.states if s.t_ns >= mid + 2_000_000_000]  # lost for 3 s, found again as track 900
    split = [t for t in tracks if t.track_id != tr.track_id] + [Track(tr.track_id, tuple(first)),
                                                                 Track(900, tuple(again))]
    events = detect_events_learned(split, geo)
    s = score_events(incidents, events, agents)["stopped_vehicle"]
    assert (s.true, s.true_positives, s.false_alarms) == (1, 1, 0), s
    ev = next(e for e in events if e.kind == "stopped_vehicle")
    assert set(ev.track_ids) == {tr.track_id, 900}
    assert ev.t_end_ns is not None
    assert ev.t_end_ns >= stop.t_end_ns - 3_000_000_000
    # without rejoining the second track is a second alarm of the same incident
    s0 = score_events(incidents, detect_events_learned(split, geo, rejoin_s=0.0), agents)["stopped_vehicle"]
    assert (s0.true_positives, s0.false_alarms) == (1, 1)


def noisy_relabelled(tracks: list[Track], offset: int, sigma_m: float, rng: np.random.Generator) -> list[Track]:
    return [Track(tr.track_id + offset, tuple(
        TrackState(s.t_ns, "tracker", tr.track_id + offset, s.position_m + rng.normal(0, sigma_m, 2), s.velocity_mps,
                   cls=s.cls, sensors=("laser_0",)) for s in tr.states)) for tr in tracks]


def test_tracked_windows_take_the_label_of_the_agent_under_them(run, truth) -> None:
    geo, agents, incidents, tracks = truth
    rng = np.random.default_rng(3)
    noisy = noisy_relabelled(tracks, 500, 0.3, rng)
    ghost = Track(9999, tuple(TrackState(round(t * 1e9) + tracks[0].states[0].t_ns, "tracker", 9999, (0.0, 10.5),
                                         (0.0, 0.0), cls="car", sensors=("camera_0",)) for t in np.arange(0, 8, 0.1)))
    ids, t, _ = window_samples([*noisy, ghost], geo, period_s=0.5)
    agent = match_agents(ids, t, [*noisy, ghost], agents)
    real = ids != 9999
    assert np.mean(agent[real] == ids[real] - 500) > 0.97
    assert np.all(agent[~real] == -1)
    assert (~real).any()
    X, y = tracked_samples([*noisy, ghost], run, reverse_fraction=0.0, period_s=0.5)
    assert X.shape[1] == len(FEATURES)
    # the labels are those of the vehicle truly under each window (its id is the track's minus 500), except where
    # the 3 m match failed; the ghost's windows are "none"
    want = label_samples(np.where(real, ids - 500, -1), t, incidents, agents)
    assert np.mean(y == want) > 0.97
    assert np.all(y[~real] == "none")
    assert {"stopped_vehicle", "road_leaving", "jam"} <= set(y)
    c = FEATURES.index
    assert np.all(X[y == "stopped_vehicle", c("speed_last")] < 0.6)
    assert np.all(X[y == "road_leaving", c("speed_last")] > 0.3)  # leaving, not yet parked on the verge


def test_road_leaving_is_labelled_until_the_vehicle_is_parked(truth) -> None:
    _geo, agents, incidents, _tracks = truth
    leave = next(e for e in incidents if e.kind == "road_leaving")
    a = leave.track_ids[0]
    rows = agents.rows_of(a)
    t = agents.t_ns[rows]
    speed = np.hypot(*agents.velocities_mps[rows].T)
    y = label_samples(np.full(t.size, a), t, incidents, agents)
    after = t >= leave.t_ns
    assert np.all(y[~after] == "none")
    assert np.all(y[after & (speed >= 0.5)] == "road_leaving")
    assert (after & (speed >= 0.5)).sum() >= 10
    assert np.all(y[after & (speed < 0.5)] == "none")
    assert (after & (speed < 0.5)).sum() >= 10
    assert leave.t_end_ns >= t[-1] - 200_000_000  # the incident itself lasts to the end of the run


def test_retraining_command(run, truth, tmp_path) -> None:
    out = tmp_path / "forest.json"
    main([str(run.parent), "--seeds", str(SEED), "--test-seeds", "--tracked-seeds", "--tracked-test-seeds",
          "--seconds", str(SECONDS), "--sample-period", "0.5", "--save", str(out)])
    model = SceneClassifier.load(out)
    assert model.features == FEATURES
    geo, agents, incidents, tracks = truth
    scores = score_events(incidents, detect_events_learned(tracks, geo, model), agents)
    for kind in ("stopped_vehicle", "road_leaving"):  # its own training run is learnt
        assert scores[kind].true_positives == scores[kind].true == 1, (kind, scores[kind])

