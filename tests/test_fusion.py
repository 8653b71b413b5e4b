"""Seed 001's tracking-learning loop (ALGORITHMS.md B15-B17) on simulated laser + camera recordings.

One group of two differently dressed people (``groups`` with one group and no single walkers, 20 s, seed 2)
meet, walk side by side as one laser segment and split. Truth is the simulator's: its floor positions say who
is where, its situation events say when the two merge and split.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.eval import evaluate_floor
from fusiontrack.fusion import FusionParams, FusionTracker, LazyFrames, track_fused
from fusiontrack.geometry import PinholeCamera
from fusiontrack.io.recording import Recording
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import Simulation, simulate
from fusiontrack.sim.situations import situation_events
from fusiontrack.tracking.tracker import track_recording
from fusiontrack.types import Detection

SIM_PF = {"lateral_m": 0.2}  # the simulator's feet are 0.2 m apart side by side


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> dict:
    scenario = load_scenario("groups").with_overrides(seconds=20, seed=2,
                                                      settings={"agents.n_groups": 1, "agents.n_singles": 0})
    path: Path = tmp_path_factory.mktemp("fusion") / "pair"
    simulate(scenario, path)
    bounds = Simulation(scenario).world.bounds_m
    with Recording(path) as rec:
        gt = list(rec.messages(["/ground_truth"]))
    kw = {"area_m": bounds, "clock_corrections_ns": {c.name: -round(c.clock_offset_ms * 1e6)
                                                      for c in scenario.config.lasers}}
    return {"path": path, "gt": gt, "truth": situation_events(gt, bounds), "kw": kw}


def _track_at(states, gt, agent: int, t_ns: int) -> int | None:
    """The track nearest (within 0.5 m) to the agent at the truth instant nearest to ``t_ns``."""
    g = min(gt, key=lambda g: abs(g.t_ns - t_ns))
    xy = g.positions_m[np.flatnonzero(g.ids == agent)[0]]
    st_t = min({s.t_ns for s in states}, key=lambda t: abs(t - g.t_ns))
    near = [(float(np.hypot(*(s.position_m - xy))), s.track_id) for s in states if s.t_ns == st_t]
    d, tid = min(near)
    return tid if d <= 0.5 else None


def test_merge_and_split_of_two_differently_dressed_people_keeps_both_identities(pair):
    merges = [e for e in pair["truth"] if e.kind == "merge"]
    splits = [e for e in pair["truth"] if e.kind == "split"]
    assert merges
    assert splits
    assert set(merges[0].track_ids) == set(splits[0].track_ids)
    states, events, stats = track_fused(pair["path"], tracker_params=SIM_PF, **pair["kw"])
    agents = sorted(merges[0].track_ids)
    before = [_track_at(states, pair["gt"], a, merges[0].t_ns - 300_000_000) for a in agents]
    assert None not in before
    assert len(set(before)) == 2
    for split in splits:  # every true split: each person is followed by the same track as before the first merge
        after = [_track_at(states, pair["gt"], a, split.t_ns + 1_000_000_000) for a in agents]
        assert after == before, (split.t_ns, before, after)
    # the classifiers did the work: they had learnt both people before the merge and named the pieces
    assert stats.splits_by_appearance >= 1
    decided = [e for e in events if e.kind == "split" and e.attributes.get("identity") == "appearance"]
    assert decided
    assert all(set(e.track_ids) == set(before) for e in decided)
    m = evaluate_floor(pair["gt"], states, 0.5)
    assert m.id_switches == 0
    assert any(s.sensors == ("laser", "camera_0") for s in states)  # the camera confirmed some steps


class _Blackout:
    """Frames with no image between ``t0_ns`` and ``t1_ns`` (a camera blackout); records the times asked for."""

    def __init__(self, frames: LazyFrames, t0_ns: int, t1_ns: int) -> None:
        self.frames, self.t0_ns, self.t1_ns = frames, t0_ns, t1_ns
        self.read: list[int] = []

    def nearest_time(self, t_ns: int) -> int | None:
        t = self.frames.nearest_time(t_ns)
        return None if t is None or self.t0_ns <= t_ns <= self.t1_ns else t

    def at(self, t_ns: int):
        if self.nearest_time(t_ns) is None:
            return None
        self.read.append(t_ns)
        return self.frames.at(t_ns)


def test_camera_blackout_leaves_laser_tracking_intact_and_learning_resumes(pair):
    gt = pair["gt"]
    t_merge = min(e.t_ns for e in pair["truth"] if e.kind == "merge")
    t0, t1 = t_merge - 2_500_000_000, t_merge + 500_000_000  # no camera while the two approach and meet
    wrappers: list[_Blackout] = []

    def blackout(frames: LazyFrames) -> _Blackout:
        wrappers.append(_Blackout(frames, t0, t1))
        return wrappers[-1]

    states, _, stats = track_fused(pair["path"], tracker_params=SIM_PF, frames_wrapper=blackout, **pair["kw"])
    laser, _ = track_recording(pair["path"], params=SIM_PF, **pair["kw"])
    read = np.array(wrappers[0].read)
    assert not ((read >= t0) & (read <= t1)).any()  # no image was read during the blackout
    # laser tracking intact: during the blackout the fused tracker is the laser tracker
    window = [g for g in gt if t0 <= g.t_ns <= t1]
    fused_w = evaluate_floor(window, [s for s in states if t0 <= s.t_ns <= t1], 0.5)
    laser_w = evaluate_floor(window, [s for s in laser if t0 <= s.t_ns <= t1], 0.5)
    assert fused_w.mota >= laser_w.mota - 0.02
    assert fused_w.id_switches <= laser_w.id_switches
    assert fused_w.mota > 0.8
    in_window = [s for s in states if t0 <= s.t_ns <= t1]
    assert in_window
    assert all("camera_0" not in s.sensors for s in in_window)
    assert any("laser" in s.sensors for s in in_window)
    # learning resumes after it: the camera confirms steps again, and classifiers are updated
    assert any("camera_0" in s.sensors for s in states if s.t_ns > t1)
    assert (read > t1).any()
    assert stats.train_updates >= 1


def test_fusion_tracker_without_interaction_never_reads_the_camera():
    """Two people 5 m apart: nobody needs the camera, so no image is read (seed 001's cost argument)."""

    class Frames:
        def __init__(self) -> None:
            self.read = 0

        def nearest_time(self, t_ns: int) -> int | None:
            return t_ns

        def at(self, t_ns: int):
            self.read += 1
            return None

    cam = PinholeCamera.looking_at([0.0, -8.0, 5.0], [0.0, 0.0, 0.0], fx=400, fy=400, width=640, height=480)
    frames = Frames()
    trk = FusionTracker(cam, frames, FusionParams(), {"n_confirm": 2, "n_confirm_interior": 2}, rng=0)
    for k in range(50):  # standing still, feet 0.2 m apart
        t = 1_000_000_000 + k * 40_000_000
        dets = []
        for x in (-2.5, 2.5):
            feet = np.array([[x, -0.1], [x, 0.1]])
            dets.append(Detection(t, "laser", position_m=feet.mean(axis=0), features={
                "feet_m": feet, "inter_feet_m": np.asarray(0.2), "one_foot": np.asarray(False)}))
        states = trk.step(t, dets)
    assert len(states) == 2
    assert all(s.sensors == ("laser",) for s in states)
    assert frames.read == 0
    assert len(trk.bank) == 0


def test_relabel_states_swaps_only_inside_each_window_in_decision_order():
    from fusiontrack.fusion.tracker import Relabel, relabel_states
    from fusiontrack.types import TrackState

    states = [TrackState(t, "laser", tid, np.array([float(tid), 0.0]), np.zeros(2))
              for t in range(10) for tid in (1, 2, 3)]
    # 1 and 2 exchanged over [3, 6); then (named after that exchange) 2 and 3 over [5, 8)
    out = relabel_states(states, [Relabel(3, 6, 1, 2), Relabel(5, 8, 2, 3)])
    who = {(s.t_ns, int(s.position_m[0])): s.track_id for s in out}  # position = the raw track's id
    for t in range(10):
        step1 = {1: 2, 2: 1, 3: 3} if 3 <= t < 6 else {1: 1, 2: 2, 3: 3}
        step2 = {1: 1, 2: 3, 3: 2} if 5 <= t < 8 else {1: 1, 2: 2, 3: 3}
        for raw in (1, 2, 3):
            assert who[(t, raw)] == step2[step1[raw]], (t, raw)
    assert relabel_states(states, []) == states
    assert all(a is b for a, b in zip(out, states, strict=True) if a.track_id == b.track_id)


def test_assignment_gap_is_the_margin_of_the_best_assignment():
    from fusiontrack.fusion.tracker import _assignment_gap

    s = np.array([[0.8, -0.2], [0.1, 0.5]])
    assert _assignment_gap(s) == pytest.approx((0.8 + 0.5) - (-0.2 + 0.1))
    # three members, two pieces: 6 assignments; best (0 -> m2, 1 -> m0) = 1.6, second (0 -> m2, 1 -> m1) = 1.3
    s3 = np.array([[0.0, 0.1, 0.9], [0.7, 0.4, -0.5]])
    assert _assignment_gap(s3) == pytest.approx(1.6 - 1.3)
    assert _assignment_gap(np.array([[0.3]])) == np.inf


def test_identity_check_undoes_an_exchange_the_laser_made_at_a_split(pair, monkeypatch):
    """The laser tracker is made to exchange the two people's ids right after their first split (a wrong
    motion decision); the camera's identity check must exchange them back, and the output (relabelled back
    to the split) must follow each person with the same track before the merge and after every split."""
    from fusiontrack.tracking.tracker import LaserPeopleTracker

    orig = LaserPeopleTracker.step
    injected: list[int] = []

    def step(self, t_ns, detections):
        states = orig(self, t_ns, detections)
        split = [e for e in self.events if e.kind == "split" and len(e.track_ids) == 2]
        if split and not injected:
            a, b = split[0].track_ids
            ia, ib = np.flatnonzero(self._id == a), np.flatnonzero(self._id == b)
            if ia.size and ib.size:
                self._id[ia[0]], self._id[ib[0]] = b, a
                injected.append(t_ns)
                swap = {a: b, b: a}
                states = [dataclasses.replace(s, track_id=swap.get(s.track_id, s.track_id)) for s in states]
        return states

    monkeypatch.setattr(LaserPeopleTracker, "step", step)
    params = FusionParams(split_identity=False)
    states, events, stats = track_fused(pair["path"], params=params, tracker_params=SIM_PF, **pair["kw"])
    assert injected
    assert stats.exchanges >= 1
    exchanged = [e for e in events if e.kind == "identity"]
    assert exchanged
    assert exchanged[0].attributes["from_ns"] <= exchanged[0].t_ns
    merges = [e for e in pair["truth"] if e.kind == "merge"]
    agents = sorted(merges[0].track_ids)
    before = [_track_at(states, pair["gt"], a, merges[0].t_ns - 300_000_000) for a in agents]
    assert None not in before
    assert len(set(before)) == 2
    for split in (e for e in pair["truth"] if e.kind == "split"):
        after = [_track_at(states, pair["gt"], a, split.t_ns + 1_000_000_000) for a in agents]
        assert after == before, (split.t_ns, before, after)
