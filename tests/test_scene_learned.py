"""The supervised alternative of D8: the forest's JSON export against scikit-learn, the shipped model on a
held-out simulation and on synthetic tracks, and retraining."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from sklearn.ensemble import RandomForestClassifier

from fusiontrack.errors import ConfigError
from fusiontrack.eval.events import agent_tracks, read_agents_csv, read_incidents, score_events
from fusiontrack.scene import (
    LearnedSceneUnderstanding,
    SceneClassifier,
    default_scene_classifier,
    detect_events_learned,
    parse_road_geometry,
    road_geometry_from_world,
)
from fusiontrack.scene.learned import (
    CLASSES,
    FEATURES,
    default_model_path,
    label_samples,
    reversed_tracks,
    train_scene_classifier,
    window_samples,
)
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.types import Track, TrackState

SEED, SECONDS = 7, 100  # the shipped forest was trained on seeds 100-102: this run is held out

ROAD = {
    "roads": [{"name": "main", "centerline": [[-300.0, 0.0], [300.0, 0.0]], "width_m": 7.0}],
    "lanes": [
        {"name": "east", "road": "main", "centerline": [[-300.0, -1.75], [300.0, -1.75]], "width_m": 3.5},
        {"name": "west", "road": "main", "centerline": [[300.0, 1.75], [-300.0, 1.75]], "width_m": 3.5},
    ],
    "zones": [{"name": "east", "kind": "lane", "lane": "east"}, {"name": "west", "kind": "lane", "lane": "west"}],
}


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A held-out simulated road run, in the folder layout train_scene_classifier reuses."""
    work = tmp_path_factory.mktemp("learned")
    scenario = load_scenario("road").with_overrides(seconds=SECONDS, seed=SEED, settings={
        "cameras": [], "lasers": [], "scenario.ground_truth_hz": 10.0})
    simulate(scenario, work / f"road_{SEED}_{SECONDS}")
    return work


def test_forest_export_reproduces_scikit_learn() -> None:
    rng = np.random.default_rng(1)
    X = rng.normal(size=(600, 4))
    y = np.array(CLASSES)[(X[:, 0] > 0) + 2 * (X[:, 1] * X[:, 2] > 0.3)]
    forest = RandomForestClassifier(n_estimators=7, max_depth=6, random_state=0).fit(X, y)
    model = SceneClassifier.from_sklearn(forest, features=("a", "b", "c", "d"))
    Xt = rng.normal(size=(300, 4))
    want = forest.predict_proba(Xt)
    cols = [CLASSES.index(c) for c in forest.classes_]
    np.testing.assert_allclose(model.predict_proba(Xt)[:, cols], want, atol=1e-12)
    back = SceneClassifier.from_dict(json.loads(json.dumps(model.to_dict())), expected_features=None)
    np.testing.assert_allclose(back.predict_proba(Xt)[:, cols], want, atol=2e-3)  # leaf shares kept to 3 decimals
    label, prob = back.predict(Xt)
    clear = np.sort(want, axis=1)[:, -1] - np.sort(want, axis=1)[:, -2] > 0.01
    assert np.all(label[clear] == forest.predict(Xt)[clear])
    assert np.all((prob >= 0) & (prob <= 1))


def test_shipped_model_is_small_json(tmp_path) -> None:
    model = default_scene_classifier()
    assert model.classes == CLASSES
    assert model.features == FEATURES
    assert os.path.getsize(default_model_path()) < 200_000
    assert json.loads(default_model_path().read_text())["format"] == "fusiontrack-forest-1"
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(ConfigError, match="not JSON"):
        SceneClassifier.load(tmp_path / "bad.json")
    data = model.to_dict()
    data["features"] = data["features"][:-1]
    (tmp_path / "old.json").write_text(json.dumps(data))
    with pytest.raises(ConfigError, match="features"):
        SceneClassifier.load(tmp_path / "old.json")
    with pytest.raises(ConfigError, match="not found"):
        SceneClassifier.load(tmp_path / "missing.json")


def test_learned_model_finds_held_out_incidents(work) -> None:
    run = work / f"road_{SEED}_{SECONDS}"
    geo = road_geometry_from_world(run / "ground_truth" / "world.json")
    agents = read_agents_csv(run)
    events = detect_events_learned(agent_tracks(agents), geo)
    scores = score_events(read_incidents(run), events, agents)
    for kind in ("stopped_vehicle", "road_leaving", "jam"):
        s = scores[kind]
        assert s.true >= 1, kind
        assert s.recall >= 0.9, (kind, s)
        assert s.precision >= 0.9, (kind, s)
        assert s.median_latency_s <= 4.0, (kind, s)
    assert scores["wrong_way"].detections == 0
    assert all(0.5 <= e.attributes["confidence"] <= 1.0 for e in events)


def _track(tid: int, t: np.ndarray, x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray) -> Track:
    return Track(tid, tuple(TrackState(round(ti * 1e9), "test", tid, (xi, yi), (a, b), cls="car")
                            for ti, xi, yi, a, b in zip(t, x, y, vx, vy, strict=True)))


def test_learned_model_on_synthetic_tracks() -> None:
    road = parse_road_geometry(ROAD, "test road")
    t = np.arange(0.0, 40.0, 0.1)
    one, zero = np.ones_like(t), np.zeros_like(t)
    v_stop = np.where(t < 14.0, 15.0, np.maximum(15.0 - 2.5 * (t - 14.0), 0.0))
    x_stop = -250.0 + np.concatenate([[0.0], np.cumsum((v_stop[1:] + v_stop[:-1]) / 2 * 0.1)])
    tracks = [
        _track(1, t, x_stop, -1.75 * one, v_stop, zero),  # stops at t = 20 s
        _track(2, t, 200.0 - 14.0 * t, -1.75 * one, -14.0 * one, zero),  # wrong way in the east lane
        # free flow, both directions; the east-bound car runs ahead of the one that stops (starting behind it in
        # the same single lane it would drive through the stopped car at 13.9 m/s at t = 20.5 s)
        _track(3, t, -150.0 + 13.9 * t, -1.75 * one + 0 * t, 13.9 * one, zero),
        _track(4, t, 280.0 - 13.9 * t, 1.75 * one, -13.9 * one, zero),
    ]
    scene = LearnedSceneUnderstanding(road)
    frames: dict[int, list] = {}
    for tr in tracks:
        for s in tr.states:
            frames.setdefault(s.t_ns, []).append(s)
    for t_ns in sorted(frames):
        scene.update(t_ns, frames[t_ns])
    found = {(e.kind, e.track_ids) for e in scene.events}
    assert found == {("stopped_vehicle", (1,)), ("wrong_way", (2,))}
    stop = next(e for e in scene.events if e.kind == "stopped_vehicle")
    assert 19.0 <= stop.t_ns * 1e-9 <= 21.5
    assert np.linalg.norm(stop.position_m - tracks[0].states[-1].position_m) < 1.0


def test_labels_and_retraining(work) -> None:
    run = work / f"road_{SEED}_{SECONDS}"
    geo = road_geometry_from_world(run / "ground_truth" / "world.json")
    agents = read_agents_csv(run)
    incidents = read_incidents(run)
    tracks = agent_tracks(agents)
    ids, t, X = window_samples(tracks, geo)
    y = label_samples(ids, t, incidents, agents)
    assert X.shape == (ids.size, len(FEATURES))
    assert np.isfinite(X).all()
    speed = X[:, FEATURES.index("speed_last")]
    assert np.all(speed[y == "stopped_vehicle"] < 0.6)  # labelled from the simulator's own incident spans
    assert np.all(X[y == "road_leaving", FEATURES.index("edge_last")] < 0.1)
    assert np.all(speed[y == "jam"] < 10 / 3.6 + 0.5)
    assert {"none", "stopped_vehicle", "road_leaving", "jam"} <= set(y)
    rev = reversed_tracks(tracks[:2])
    assert rev[0].states[0].t_ns == tracks[0].states[0].t_ns
    np.testing.assert_allclose(rev[0].states[0].position_m, tracks[0].states[-1].position_m)
    model, report = train_scene_classifier(work, seeds=(SEED,), test_seeds=(), seconds=SECONDS, n_trees=5)
    assert model.classes == CLASSES
    assert report == {"classes": {}}
    pred, _ = model.predict(X)
    for c in ("stopped_vehicle", "road_leaving", "jam"):  # its own training run is learnt
        assert np.mean(pred[y == c] == c) > 0.8, c


def test_a_stop_seen_only_in_the_trackers_extrapolation_raises_no_alarm() -> None:
    """A window whose states a sensor mostly did not confirm shows how the tracker coasts, not what the vehicle
    does: the same stop, confirmed in every frame, alarms; confirmed in one frame of four, it does not."""
    road = parse_road_geometry(ROAD, "test road")
    t = np.arange(0.0, 40.0, 0.1)
    v = np.where(t < 14.0, 15.0, np.maximum(15.0 - 2.5 * (t - 14.0), 0.0))
    x = -250.0 + np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 * 0.1)])

    def events(sensed_every: int, **options) -> list:
        scene = LearnedSceneUnderstanding(road, **options)
        for k, (ti, xi, vi) in enumerate(zip(t, x, v, strict=True)):
            sensors = ("laser_0",) if ti < 14.0 or k % sensed_every == 0 else ()
            scene.update(round(ti * 1e9), [TrackState(round(ti * 1e9), "test", 1, (xi, -1.75), (vi, 0.0),
                                                      cls="car", sensors=sensors)])
        return [e.kind for e in scene.events]

    assert events(1) == ["stopped_vehicle"]
    assert events(4) == []
    assert events(4, min_measured=0.0) == ["stopped_vehicle"]  # the forest alone would alarm
    with pytest.raises(ConfigError, match="min_measured"):
        LearnedSceneUnderstanding(road, min_measured=1.5)
