"""Measurement-level situation truth: the detector's segments and the agent each beam hit (sim/situations.py
``segment_*``, eval/situations.py ``segment_frames``; seed 001 B6, B7).

The hand-built cases give every segment's returns per agent directly; each expected label and event is written
by hand from B6/B7's rules (module docstring of :mod:`fusiontrack.sim.situations`). The simulated case checks
the per-beam attribution against the simulator's true feet.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from fusiontrack.errors import RecordingError
from fusiontrack.eval.situations import segment_frames
from fusiontrack.io.recording import Recording
from fusiontrack.sim.laser import LaserSim
from fusiontrack.sim.model import KIND_PERSON, AgentSnapshot, LaserSpec, StaticWorld, Timing
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.sim.situations import (
    HIDDEN,
    SegmentFrame,
    load_laser_hits,
    segment_situation_events,
    segment_situations,
)
from fusiontrack.tracking.association import association_states, gate_distances
from fusiontrack.tracking.situations import classify_situations
from fusiontrack.types import Situation

BOUNDS = (-10.0, -10.0, 10.0, 10.0)
DT_NS = 20_000_000  # 50 Hz, the tracker's step with two 25 Hz scanners
N, C, M = Situation.NONCORRELATED, Situation.CORRELATED, Situation.MERGED


def _frame(k: int, ids, pos, centres, returns) -> SegmentFrame:
    return SegmentFrame(k * DT_NS, np.asarray(ids), np.asarray(pos, float), np.asarray(centres, float),
                        np.asarray(returns))


def _labels(frame: SegmentFrame) -> list[str]:
    return list(segment_situations([frame], BOUNDS).labels[0])


def test_own_segments_far_apart_are_noncorrelated() -> None:
    f = _frame(0, [1, 2], [[0, 0], [3, 0]], [[0, 0], [3, 0]], [[8, 0], [0, 8]])
    assert _labels(f) == [N, N]


def test_one_segment_holding_both_is_a_merge() -> None:
    # B7 rule 1: neither has a segment of its own, both are in segment 0
    f = _frame(0, [1, 2], [[0, 0], [0.5, 0]], [[0.25, 0]], [[6, 5]])
    assert _labels(f) == [M, M]
    a = segment_situations([f], BOUNDS)
    assert a.merged_set[0].tolist() == [0, 0]


def test_shared_segment_with_someone_who_has_their_own_is_correlated() -> None:
    # 1's right leg is alone (segment 0); its left leg and all of 2 are segment 1: 1 finds two detections
    f = _frame(0, [1, 2], [[0, 0], [0.6, 0]], [[-0.1, 0], [0.5, 0]], [[4, 0], [4, 7]])
    assert _labels(f) == [C, C]


@pytest.mark.parametrize(("third_x_m", "expected"), [(1.0, [C, C, C]), (3.0, [M, M, N])])
def test_a_shared_segment_merges_only_when_every_gate_holding_it_holds_nothing_else(third_x_m, expected) -> None:
    # 1 and 2 share segment 0; 3 walks alone at x = third_x_m. At 1.0 m, 3's segment is 0.5 m from 2 (inside
    # 2's gate of radius 2h = 0.8 m: c_2 = 2) and segment 0 is 0.75 m from 3 (c_3 = 2): B7 rule 1 needs r_j = 2 AND
    # c_k = 1 for every target that found j, so nobody merges; all three interact (correlated). At 3 m: a merge.
    f = _frame(0, [1, 2, 3], [[0, 0], [0.5, 0], [third_x_m, 0]], [[0.25, 0], [third_x_m, 0]], [[6, 5, 0], [0, 0, 8]])
    assert _labels(f) == expected
    old = list(segment_situations([f], BOUNDS, gate_merges=False).labels[0])
    assert old == [M, M, C if third_x_m < 2 else N]  # membership alone, before: merged whatever the gate held


@pytest.mark.parametrize(("gap_m", "expected"), [(0.6, C), (1.5, N)])
def test_gate_of_radius_2h_about_the_true_centre(gap_m: float, expected: Situation) -> None:
    f = _frame(0, [1, 2], [[0, 0], [gap_m, 0]], [[0, 0], [gap_m, 0]], [[8, 0], [0, 8]])
    assert _labels(f) == [expected, expected]


@pytest.mark.parametrize(("x2_m", "expected"), [(0.85, [C, C]), (1.0, [N, N])])
def test_a_segment_found_by_a_neighbour_with_two_detections_is_correlated(x2_m: float, expected) -> None:
    # 1 at 0 with its segment at 0.1; 2 at x2 with its segment 0.05 m further out. At 0.85 m: 1's segment is
    # 0.75 m from 2 (inside 2's gate: c_2 = 2, correlated) while 2's segment is 0.9 m from 1 (outside: c_1 = 1).
    # 1's one detection is found by 2 as well (r = 2): B7 rule 4 needs r = 1, rule 1 needs every finder to have
    # c = 1, so 1 interacts too (rule 3's completion). At 1.0 m nobody's gate holds the other's segment.
    centres = [[0.1, 0.0], [x2_m + 0.05, 0.0]]
    f = _frame(0, [1, 2], [[0.0, 0.0], [x2_m, 0.0]], centres, [[8, 0], [0, 8]])
    assert _labels(f) == expected
    # the tracker's own B6 gate and B7 rules on the same geometry (predicted centres = the true ones) agree
    D = gate_distances(np.array([[0.0, 0.0], [x2_m, 0.0]]), np.array(centres), 0.4)
    c, r, found = association_states(D, 4.0)
    frame = classify_situations(c, r, found, np.zeros(2, bool), np.zeros(2, bool), np.zeros(2, bool), D)
    assert frame.situations() == expected


@pytest.mark.parametrize("occlusion_merges", [True, False])
def test_an_agent_never_seen_has_no_target_and_makes_nobody_correlated(occlusion_merges: bool) -> None:
    # 2 stands between 1 and 3 (0.5 m from each) but has never been seen: it has no target, so no gate finds 1's
    # and 3's segments a second time (case (c) counts targets, seen or alive, whatever occlusion_merges)
    f = _frame(0, [1, 2, 3], [[0, 0], [0, 0.5], [0, 1.0]], [[0, 0], [0, 1.0]], [[8, 0, 0], [0, 0, 8]])
    labels = segment_situations([f], BOUNDS, occlusion_merges=occlusion_merges)
    assert list(labels.labels[0]) == [N, HIDDEN, N]
    assert labels.partners[0][0].tolist() == []  # 2 is nobody's partner
    assert labels.partners[0][2].tolist() == []


def test_own_legs_in_two_segments_or_clutter_in_the_gate_are_not_correlated() -> None:
    # 1's legs fell into two segments; a clutter segment (nobody's returns) lies in 2's gate
    f = _frame(0, [1, 2], [[0, 0], [5, 0]], [[-0.2, 0], [0.2, 0], [5, 0], [5.3, 0]],
               [[4, 0], [4, 0], [0, 8], [0, 0]])
    assert _labels(f) == [N, N]


def test_too_few_returns_is_hidden_not_merged() -> None:
    # 2 has 2 returns in 1's segment (< min_returns = 3): hidden; 1 keeps a segment of its own
    f = _frame(0, [1, 2], [[0, 0], [0.4, 0]], [[0, 0]], [[9, 2]])
    assert _labels(f) == [N, HIDDEN]
    assert segment_situations([f], BOUNDS).seen[0].tolist() == [True, False]


def _pair_sequence(together: list[bool], seen2: list[bool] | None = None) -> list[SegmentFrame]:
    """Two people 0.5 m apart; per frame one shared segment (together) or one each; 2 hidden where not seen2."""
    frames = []
    for k, tog in enumerate(together):
        visible = True if seen2 is None else seen2[k]
        if tog and visible:
            frames.append(_frame(k, [1, 2], [[0, 0], [0.5, 0]], [[0.25, 0]], [[6, 6]]))
        else:
            frames.append(_frame(k, [1, 2], [[0, 0], [0.5, 0]], [[0, 0], [0.5, 0]],
                                 [[6, 0], [0, 6 if visible else 0]]))
    return frames


def test_merge_and_split_are_dated_by_the_first_frame_of_the_new_state() -> None:
    together = [False] * 25 + [True] * 25 + [False] * 25  # 0.5 s each at 50 Hz
    events = segment_situation_events(_pair_sequence(together), BOUNDS)
    ms = [(e.kind, e.t_ns, e.track_ids) for e in events if e.kind in ("merge", "split")]
    assert ms == [("merge", 25 * DT_NS, (1, 2)), ("split", 50 * DT_NS, (1, 2))]


def test_a_state_shorter_than_min_state_s_is_no_merge() -> None:
    together = [False] * 25 + [True] * 3 + [False] * 25  # 60 ms as one segment: a blip
    events = segment_situation_events(_pair_sequence(together), BOUNDS)
    assert not [e for e in events if e.kind in ("merge", "split")]
    # ... but counts when nothing is asked to persist
    events = segment_situation_events(_pair_sequence(together), BOUNDS, min_state_s=0.0)
    assert [e.kind for e in events if e.kind in ("merge", "split")] == ["merge", "split"]


def test_hidden_while_merged_is_no_split() -> None:
    together = [False] * 25 + [True] * 50
    seen2 = [True] * 40 + [False] * 15 + [True] * 20  # 2 hidden 0.3 s inside the merged episode
    events = segment_situation_events(_pair_sequence(together, seen2), BOUNDS)
    assert [e.kind for e in events if e.kind in ("merge", "split")] == ["merge"]


def test_pair_seen_again_after_max_gap_starts_afresh() -> None:
    # together (one segment) 0.5 s, then nobody returns anything for 1.5 s (> max_gap_s = 1 s: both targets find
    # nothing in their gates and are gone), then both are seen apart: new targets, no split
    frames = _pair_sequence([True] * 25 + [False] * 100)
    frames[25:100] = [_frame(k, [1, 2], [[0, 0], [0.5, 0]], np.zeros((0, 2)), np.zeros((0, 2))) for k in range(25, 100)]
    for occlusion in (True, False):
        events = segment_situation_events(frames, BOUNDS, occlusion_merges=occlusion)
        assert not [e for e in events if e.kind in ("merge", "split")]


def test_hidden_beside_a_friend_for_longer_than_max_gap_is_still_merged() -> None:
    # 1 and 2 one segment for 0.5 s; then 2 has no returns for 1.5 s but stands 0.5 m from 1's own segment (its
    # target finds that segment, c = 1, and so does 1's: B7 rule 1, one merged target that never misses a
    # detection); seen apart again: one split. Without occlusion merges the hidden frames are skipped and the pair
    # is seen again after more than max_gap_s: it starts afresh.
    together = [True] * 25 + [False] * 100
    seen2 = [True] * 25 + [False] * 75 + [True] * 25
    frames = _pair_sequence(together, seen2)
    events = [(e.kind, e.t_ns, e.track_ids) for e in segment_situation_events(frames, BOUNDS)
              if e.kind in ("merge", "split")]
    assert events == [("split", 100 * DT_NS, (1, 2))]
    assert not [e for e in segment_situation_events(frames, BOUNDS, occlusion_merges=False)
                if e.kind in ("merge", "split")]


def _walk_behind(y_m: float, third: bool = False) -> list[SegmentFrame]:
    """1 stands at the origin (a segment of its own); 2 walks along y = y_m from x = -1 to 1 m at 1 m/s and has
    no returns while |x| < 0.3 m (frames 36-64: hidden behind 1); with ``third``, 3 stands at (0, 1) with its own
    segment (1 m from 1: outside 1's gate, and 1 outside 3's)."""
    frames = []
    for k in range(101):
        x = -1.0 + 0.02 * k
        ids, pos = [1, 2], [[0.0, 0.0], [x, y_m]]
        centres, returns = [[0.0, 0.0]], [[8, 0]]
        if abs(k - 50) >= 15:
            centres.append([x, y_m])
            returns.append([0, 8])
        if third:
            ids.append(3)
            pos.append([0.0, 1.0])
            centres.append([0.0, 1.0])
            returns = [[*r, 0] for r in returns] + [[0, 0, 8]]
        frames.append(_frame(k, ids, pos, centres, returns))
    return frames


def _hidden_frames(frames: list[SegmentFrame]) -> list[int]:
    return [k for k, f in enumerate(frames) if not (f.returns[:, 1] > 0).any()]


def test_walking_behind_someone_is_a_merge_and_a_split() -> None:
    # 2 passes 0.4 m behind 1 and is hidden for 0.58 s: its target's gate (0.8 m) holds 1's segment alone (c = 1)
    # and 1's gate holds nothing else: B7 rule 1 merges them (seed 001: complete occlusion is a merge/split)
    frames = _walk_behind(0.4)
    hidden = _hidden_frames(frames)
    assert hidden == list(range(36, 65))
    events = [(e.kind, e.t_ns, e.track_ids) for e in segment_situation_events(frames, BOUNDS)
              if e.kind in ("merge", "split")]
    assert events == [("merge", hidden[0] * DT_NS, (1, 2)), ("split", (hidden[-1] + 1) * DT_NS, (1, 2))]
    labels = segment_situations(frames, BOUNDS).labels
    assert all(list(labels[k]) == [M, M] for k in hidden)
    # the option off: hidden agents are ignored, no merge
    assert not [e for e in segment_situation_events(frames, BOUNDS, occlusion_merges=False)
                if e.kind in ("merge", "split")]
    off = segment_situations(frames, BOUNDS, occlusion_merges=False).labels
    assert all(list(off[k]) == [N, HIDDEN] for k in hidden)


def test_hidden_out_of_reach_of_every_segment_is_no_merge() -> None:
    # 2 passes 0.9 m behind 1: 1's segment lies outside its gate (radius 0.8 m), c = 0: nothing to merge with
    frames = _walk_behind(0.9)
    hidden = _hidden_frames(frames)
    assert len(hidden) == 29
    assert not [e for e in segment_situation_events(frames, BOUNDS) if e.kind in ("merge", "split")]
    labels = segment_situations(frames, BOUNDS).labels
    assert all(list(labels[k]) == [N, HIDDEN] for k in hidden)


def test_hidden_between_two_people_is_no_merge() -> None:
    # 3 stands at (0, 1): while 2 is hidden behind 1 (at most 0.66 m from 3) its gate holds 1's and 3's segments
    # (c = 2: B7 rule 3, not rule 1), so no merge, although 1's and 3's gates hold their own segments alone (without
    # 3 the same walk is a merge: test above). The hidden person's target would be correlated in a B7 tracker; the
    # truth leaves it hidden (it has no returns of its own to label). 1's and 3's segments are each found by that
    # target too (r = 2), which found two (c = 2): neither rule 1 nor rule 4 holds, so they interact (rule 3's
    # completion), as a B7 tracker labels them.
    frames = _walk_behind(0.4, third=True)
    hidden = _hidden_frames(frames)
    assert not [e for e in segment_situation_events(frames, BOUNDS) if e.kind in ("merge", "split")]
    labels = segment_situations(frames, BOUNDS).labels
    assert all(list(labels[k]) == [C, HIDDEN, C] for k in hidden)


@pytest.mark.parametrize(("away_frames", "split"), [(75, False), (25, True)])
def test_a_target_gone_for_longer_than_max_gap_makes_no_split(away_frames: int, split: bool) -> None:
    # 2 is seen 1.5 m from 1 (apart) for 0.5 s, hidden 0.5 m from 1's segment for 0.2 s (merged by occlusion),
    # then hidden 3 m away, out of every gate (c = 0), for away_frames, then seen there. After 1.5 s
    # (> max_gap_s = 1 s) its target is gone (B7 N_miss): it is a new target, the stale pair makes no split;
    # after 0.5 s the target was still coasting: the merged pair splits.
    frames = []
    n_frames = 25 + 10 + away_frames + 25
    for k in range(n_frames):
        phase = 0 if k < 25 else 1 if k < 35 else 2 if k < 35 + away_frames else 3
        p2 = [[1.5, 0.0], [0.5, 0.0], [3.0, 0.0], [3.0, 0.0]][phase]
        centres, returns = [[0.0, 0.0]], [[8, 0]]
        if phase in (0, 3):
            centres.append(p2)
            returns.append([0, 8])
        frames.append(_frame(k, [1, 2], [[0.0, 0.0], p2], centres, returns))
    events = [(e.kind, e.t_ns, e.track_ids) for e in segment_situation_events(frames, BOUNDS)
              if e.kind in ("merge", "split")]
    expected = [("merge", 25 * DT_NS, (1, 2))]
    if split:
        expected.append(("split", (35 + away_frames) * DT_NS, (1, 2)))
    assert events == expected


def test_entering_together_is_an_appear_not_a_merge() -> None:
    # two newcomers first seen in one segment at the edge (x = -9.8), 30 frames; 3 stands far inside from the start
    frames = [_frame(k, [1, 2, 3], [[-9.8 + 0.02 * k, 0], [-9.8 + 0.02 * k, 0.5], [5, 5]],
                     [[-9.8 + 0.02 * k, 0.25], [5, 5]], [[6, 6, 0], [0, 0, 8]]) for k in range(30)]
    events = segment_situation_events(frames, BOUNDS)
    assert [(e.kind, e.track_ids, e.t_ns) for e in events] == [("appear", (1, 2), 0)]
    labels = segment_situations(frames, BOUNDS).labels
    assert list(labels[0]) == [M, M, N]  # interaction before the edge label


def test_appear_and_disappear_only_on_the_edge_and_only_when_leaving() -> None:
    frames = []
    for k in range(100):
        ids, pos, cen, ret = [1, 2], [[9.8, 0], [0, 0]], [], []
        if k < 80:  # 1 is seen on the edge until frame 79, then leaves the area (not listed from frame 85)
            cen.append([9.8, 0.0])
            ret.append([7, 0])
        if k >= 10:  # 2 is first seen inside at frame 10 (hidden before): no appear
            cen.append([0.0, 0.0])
            ret.append([0, 7])
        if k >= 85:
            ids, pos = [2], [[0, 0]]
            ret = [r[1:] for r in ret]
        frames.append(_frame(k, ids, pos, np.reshape(cen, (-1, 2)), np.reshape(ret, (len(cen), len(ids)))))
    events = segment_situation_events(frames, BOUNDS)
    assert [(e.kind, e.track_ids, e.t_ns) for e in events] == [("appear", (1,), 0),
                                                                ("disappear", (1,), 79 * DT_NS)]
    assert events[0].t_end_ns == 0  # seen from its first frame on: confirmable at once
    labels = segment_situations(frames, BOUNDS).labels
    assert [labels[0][0], labels[79][0]] == [Situation.APPEARING, Situation.DISAPPEARING]
    assert [labels[5][1], labels[20][1]] == [HIDDEN, N]


def test_correlated_runs_shorter_than_min_state_s_make_no_event() -> None:
    frames = []
    for k in range(60):
        near = 20 <= k < 22 or 30 <= k < 45  # 2 is within 1's gate for 40 ms, then for 0.3 s
        x2 = 0.6 if near else 3.0
        frames.append(_frame(k, [1, 2], [[0, 0], [x2, 0]], [[0, 0], [x2, 0]], [[8, 0], [0, 8]]))
    events = [e for e in segment_situation_events(frames, BOUNDS) if e.kind == "correlated"]
    assert [(e.track_ids, e.t_ns, e.t_end_ns) for e in events] == [((1,), 30 * DT_NS, 44 * DT_NS),
                                                                   ((2,), 30 * DT_NS, 44 * DT_NS)]


def test_appear_is_dated_by_the_first_glimpse_and_needs_a_lasting_sighting() -> None:
    # 1 is glimpsed on the edge for 2 frames (40 ms), hidden 5 frames, then seen from frame 7 on;
    # 2 is glimpsed on the edge once and never again: no appear
    frames = []
    for k in range(40):
        seen1 = k < 2 or k >= 7
        cen, ret = ([[-9.8, 0.0]], [[7, 0]]) if seen1 else (np.zeros((0, 2)), np.zeros((0, 2)))
        if k == 3:
            cen, ret = [[9.8, 3.0]], [[0, 7]]
        frames.append(_frame(k, [1, 2], [[-9.8, 0], [9.8, 3]], cen, ret))
    events = segment_situation_events(frames, BOUNDS)
    assert [(e.kind, e.track_ids, e.t_ns, e.t_end_ns) for e in events] == [("appear", (1,), 0, 7 * DT_NS)]


def test_hidden_frames_neither_end_nor_extend_a_correlated_run() -> None:
    # 1 and 2 are 0.6 m apart (each in the other's gate) for 40 frames; 2 is hidden in frames 15-22
    frames = []
    for k in range(40):
        if 15 <= k < 23:
            frames.append(_frame(k, [1, 2], [[0, 0], [0.6, 0]], [[0, 0]], [[8, 0]]))
        else:
            frames.append(_frame(k, [1, 2], [[0, 0], [0.6, 0]], [[0, 0], [0.6, 0]], [[8, 0], [0, 8]]))
    events = [e for e in segment_situation_events(frames, BOUNDS, occlusion_merges=False) if e.kind == "correlated"]
    # 2: one run over its hidden frames; 1 is seen alone in frames 15-22 (0.16 s >= min_state_s: its run ends)
    assert [(e.track_ids, e.t_ns, e.t_end_ns) for e in events] == [((1,), 0, 14 * DT_NS), ((2,), 0, 39 * DT_NS),
                                                                   ((1,), 23 * DT_NS, 39 * DT_NS)]
    # with occlusion merges, 2's target finds 1's segment alone in frames 15-22 (0.6 m < gate 0.8 m) and 1's finds
    # nothing else: merged (B7 rule 1) for 0.16 s, which ends both correlated runs; a split at frame 23
    events = segment_situation_events(frames, BOUNDS)
    assert [(e.kind, e.track_ids, e.t_ns, e.t_end_ns) for e in events] == [
        ("correlated", (1,), 0, 14 * DT_NS), ("correlated", (2,), 0, 14 * DT_NS),
        ("merge", (1, 2), 15 * DT_NS, 15 * DT_NS), ("split", (1, 2), 23 * DT_NS, 23 * DT_NS),
        ("correlated", (1,), 23 * DT_NS, 39 * DT_NS), ("correlated", (2,), 23 * DT_NS, 39 * DT_NS)]


def test_bad_input() -> None:
    f = _frame(0, [1], [[0, 0]], [[0, 0]], [[5]])
    with pytest.raises(ValueError, match="min_returns"):
        segment_situations([f], BOUNDS, min_returns=0)
    with pytest.raises(ValueError, match="bounds_m"):
        segment_situations([f], (0, 0, -1, 1))
    with pytest.raises(ValueError, match="increasing"):
        segment_situations([f, f], BOUNDS)
    with pytest.raises(ValueError, match="positions_m"):
        SegmentFrame(0, np.array([1, 2]), np.zeros((1, 2)), np.zeros((0, 2)), np.zeros((0, 2)))
    with pytest.raises(TypeError, match="SegmentFrame"):
        segment_situations([object()], BOUNDS)  # type: ignore[list-item]
    assert segment_situation_events([], BOUNDS) == []
    empty = _frame(0, [], np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 0)))
    assert segment_situations([empty], BOUNDS).labels[0].size == 0


def test_scan_and_hits_match_scan_and_cast() -> None:
    sim = LaserSim(LaserSpec("laser_test", 0.0, 0.0, 0.0, Timing(25.0)),
                   StaticWorld(walls=np.array([[[5.0, -20.0], [5.0, 20.0]]])))
    z = np.zeros
    snap = AgentSnapshot(0, np.array([7]), np.array([KIND_PERSON], np.int8), np.array([[3.0, 0.0]]), z((1, 2)),
                         z(1), np.array([[[3.0, -0.1], [3.0, 0.1]]]), np.array([[0.3, 0.5, 1.7]]),
                         z((1, 3), np.uint8), z((1, 3), np.uint8), z(1, np.int8), -np.ones(1, np.int64), z(1))
    scan, hits = sim.scan_and_hits(5, snap, rng=3)
    np.testing.assert_array_equal(scan.ranges_m, sim.scan(5, snap, rng=3).ranges_m)  # the same noise draws
    np.testing.assert_array_equal(hits, sim.cast(snap)[1])
    assert set(hits.tolist()) == {-1, 7}
    # the legs are 3 m away, the wall 5 m: the beams that hit agent 7 read about 3 m
    assert np.all(np.abs(scan.ranges_m[hits == 7] - 3.0) < 0.15)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("truth") / "crowd"
    scenario = load_scenario("crowd").with_overrides(seconds=5, seed=4, settings={"cameras": []})
    simulate(scenario, out)
    corrections = {c.name: -round(c.clock_offset_ms * 1e6) for c in scenario.config.lasers}
    return out, corrections


def test_simulator_writes_per_beam_truth_matching_the_scans(simulated) -> None:
    out, _ = simulated
    hits = load_laser_hits(out)
    with Recording(out) as rec:
        for name, h in hits.items():
            scans = list(rec.messages([f"/{name}/scan"]))
            assert [s.t_ns for s in scans] == h["stamp_ns"].tolist()
            assert h["hit_ids"].shape == (len(scans), scans[0].n_beams)
            # a beam that hit an agent has a finite return; one that saw nothing of anybody reads the background
            r = np.stack([s.ranges_m for s in scans])
            assert np.isfinite(r[h["hit_ids"] >= 0]).all()


def test_segment_points_belong_to_the_feet_of_the_agent_they_are_attributed_to(simulated) -> None:
    out, corrections = simulated
    frames = segment_frames(out, clock_corrections_ns=corrections)
    with Recording(out) as rec:
        gt = list(rec.messages(["/ground_truth"]))
    assert len(frames) >= 240  # one per scan time: 2 scanners x 25 Hz x 5 s (minus any coincident stamps)
    attributed = 0
    for f in frames[::10]:
        g = gt[int(np.argmin([abs(x.t_ns - f.t_ns) for x in gt]))]
        assert f.ids.tolist() == list(g.ids)
        np.testing.assert_allclose(f.positions_m, g.positions_m)
        attributed += int(f.returns.sum())
        for j, i in zip(*np.nonzero(f.returns >= 3), strict=True):
            # a segment holding >= 3 returns of agent i lies near i's true centre (two feet within ~0.8 m)
            assert np.linalg.norm(f.centres_m[j] - f.positions_m[i]) < 1.0
    assert attributed > 0
    labels = segment_situations(frames, _bounds(out)).labels
    assert any((lab == Situation.NONCORRELATED).any() for lab in labels)


def _bounds(out) -> tuple[float, ...]:
    import json

    return tuple(json.loads((out / "ground_truth" / "world.json").read_text())["bounds_m"])


def test_old_recording_without_per_beam_truth_raises_a_clear_error(simulated, tmp_path) -> None:
    out, corrections = simulated
    old = tmp_path / "old"
    shutil.copytree(out, old)
    for f in (old / "ground_truth").glob("laser_hits_*.npz"):
        f.unlink()
    with pytest.raises(RecordingError, match="laser_hits"):
        segment_frames(old, clock_corrections_ns=corrections)
