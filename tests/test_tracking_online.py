"""OnlineLaserTracker: people tracked from scans fed one at a time, as from a live scanner. It must give what
track_recording gives on the same scans (a live run and a recorded one are the same code), stream each step's
states one scan late, and survive scans that arrive out of order."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.eval import evaluate_floor
from fusiontrack.io.recording import LASERSCAN, Recording
from fusiontrack.io.sync import synchronize
from fusiontrack.laser.detector import detector_for_recording
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import Simulation
from fusiontrack.tracking import OnlineLaserTracker, track_recording

PARAMS = {"lateral_m": 0.2}


@pytest.fixture(scope="module")
def crowd(simulated):
    """The 20 s crowd of test_tracking_tracker.py: recording, area, clock corrections, truth, scans in time order,
    and the scanners' poses (from its /tf_static, as a user would give them)."""
    scenario = load_scenario("crowd").with_overrides(seconds=20, seed=1, settings={"cameras": []})
    path: Path = simulated("crowd", seconds=20, seed=1, settings={"cameras": []})
    corrections = {c.name: -round(c.clock_offset_ms * 1e6) for c in scenario.config.lasers}
    with Recording(path) as rec:
        gt = list(rec.messages(["/ground_truth"]))
        lasers = [t for t, i in rec.topics().items() if i.msgtype == LASERSCAN]
        _, poses = detector_for_recording(rec, lasers)
        scans = list(synchronize(rec.messages(lasers), clock_corrections_ns=corrections))
    return path, Simulation(scenario).world.bounds_m, corrections, gt, scans, poses


def _run(online: OnlineLaserTracker, scans) -> tuple[list, list]:
    states, events = [], []
    for scan in scans:
        new = online.feed(scan)
        assert all(s.t_ns < scan.t_ns for s in new)  # a step's states come once a later scan has arrived
        states.extend(new)
        events.extend(online.take_events())
    states.extend(online.close())
    events.extend(online.take_events())
    return states, events


def _key(states, events):
    return ([(s.t_ns, s.track_id, tuple(s.position_m), s.situation, s.cls) for s in states],
            [(e.t_ns, e.kind, e.track_ids) for e in events])


@pytest.fixture(scope="module")
def in_order(crowd) -> tuple[list, list]:
    """The crowd's scans fed in time order."""
    _, bounds, _, _, scans, poses = crowd
    return _run(OnlineLaserTracker(poses, params=PARAMS, area_m=bounds), scans)


def test_fed_scan_by_scan_it_tracks_as_track_recording_does(crowd, in_order):
    path, bounds, corrections, gt, _, _ = crowd
    states, events = in_order
    ref = track_recording(path, params=PARAMS, area_m=bounds, clock_corrections_ns=corrections, background="learn")
    assert _key(states, events) == _key(*ref)
    assert len({s.track_id for s in states}) >= 8  # a crowd, tracked
    # and it tracks: the truth after the 2 s (50 scans) in which each scanner learns its background
    t_from = gt[0].t_ns + 3_000_000_000
    m = evaluate_floor([g for g in gt if g.t_ns >= t_from], [s for s in states if s.t_ns >= t_from], 0.5)
    assert m.mota > 0.75, m.mota


def test_scans_arriving_out_of_order_are_used_and_tracking_holds(crowd, in_order):
    _, bounds, _, gt, scans, poses = crowd
    # network jitter: a third of the scans arrive after the next one (of the other scanner, or its own)
    rng = np.random.default_rng(4)
    jittered = list(scans)
    for i in range(0, len(jittered) - 1, 2):
        if rng.random() < 1 / 3:
            jittered[i], jittered[i + 1] = jittered[i + 1], jittered[i]
    online = OnlineLaserTracker(poses, params=PARAMS, area_m=bounds)
    states, _ = _run(online, jittered)
    assert online.late_scans >= 100
    ts = [s.t_ns for s in states]
    assert ts == sorted(ts)  # steps never go back in time
    t_from = gt[0].t_ns + 3_000_000_000
    late = evaluate_floor([g for g in gt if g.t_ns >= t_from], [s for s in states if s.t_ns >= t_from], 0.5)
    ref = evaluate_floor([g for g in gt if g.t_ns >= t_from], [s for s in in_order[0] if s.t_ns >= t_from], 0.5)
    assert late.mota >= ref.mota - 0.03, (late.mota, ref.mota)


def test_kalman_and_unlearnt_backgrounds_as_track_recording(shared_data):
    # leg_tracker's three scanners on a moving robot: no background to learn ("none"), no /tf_static (the
    # laser frame is the world); the CV Kalman baseline, the auto area
    bag = shared_data / "laser/leg_tracker_demo/training/negative_2.bag"
    with Recording(bag) as rec:
        lasers = [t for t, i in rec.topics().items() if i.msgtype == LASERSCAN]
        scans = list(itertools.islice(synchronize(rec.messages(lasers)), 60))
        poses = {s.sensor: np.eye(4) for s in scans}
    online = OnlineLaserTracker(poses, tracker="kalman", background="none")
    states, events = _run(online, scans)
    assert len(states) > 0
    # the same 60 scans through track_recording's loop, with its detector for the recording
    from fusiontrack.tracking.online import make_tracker
    from fusiontrack.tracking.tracker import run_tracker

    with Recording(bag) as rec:
        detector, poses_rec = detector_for_recording(rec, lasers, background="none")
    assert set(poses_rec) == set(poses)
    ref = run_tracker(make_tracker("kalman", None, "auto", 0), detector, poses_rec, iter(scans), total=len(scans),
                      auto_area=True)
    assert _key(states, events) == _key(*ref)


def test_bad_scanners_and_scans_are_named(crowd):
    *_, scans, poses = crowd
    with pytest.raises(ConfigError, match="scanners: expected a non-empty mapping"):
        OnlineLaserTracker({})
    with pytest.raises(ConfigError, match=r"scanners\['front'\]: expected a finite \(3, 3\) 2-D pose or \(4, 4\)"):
        OnlineLaserTracker({"front": np.eye(2)})
    with pytest.raises(ConfigError, match="background: expected 'learn' or 'none'"):
        OnlineLaserTracker(poses, background="prime")
    with pytest.raises(ConfigError, match="tracker: expected 'pf' or 'kalman'"):
        OnlineLaserTracker(poses, tracker="ukf")
    with pytest.raises(ConfigError, match="min_segmnt_points"):
        OnlineLaserTracker(poses, detector_params={"min_segmnt_points": 3})
    first = next(iter(poses))
    online = OnlineLaserTracker({first: poses[first]})
    own = [s for s in scans if s.sensor == first]
    other = next(s for s in scans if s.sensor != first and s.t_ns > own[120].t_ns)
    got = [st for s in own[:120] for st in online.feed(s)]
    with pytest.raises(ConfigError, match=other.sensor):
        online.feed(other)
    # nothing lost with the error: the pending step comes with the next scan
    got += online.feed(own[120])
    assert {st.t_ns for st in got} <= {s.t_ns for s in own[:120]}
    assert max(st.t_ns for st in got) == own[119].t_ns
    online.close()
    with pytest.raises(ConfigError, match="closed"):
        online.feed(scans[0])
