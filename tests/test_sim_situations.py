"""Seed 001's tracking situations labelled from ground truth (sim/situations.py; ALGORITHMS.md B6, B7).

Every expected label and event below is written by hand from the scripted geometry.
"""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.sim.model import KIND_PERSON, AgentSnapshot
from fusiontrack.sim.situations import (
    bridge_correlated,
    drop_undone_splits,
    label_situations,
    situation_counts,
    situation_events,
)
from fusiontrack.types import GroundTruth, Situation

BOUNDS = (-10.0, -10.0, 10.0, 10.0)
DT_NS = 100_000_000  # 10 Hz frames
N, C, M, A, D = (Situation.NONCORRELATED, Situation.CORRELATED, Situation.MERGED, Situation.APPEARING,
                 Situation.DISAPPEARING)


def _snap(k: int, ids, pos) -> AgentSnapshot:
    n = len(ids)
    return AgentSnapshot(
        t_ns=k * DT_NS, ids=np.asarray(ids, np.int64), kinds=np.full(n, KIND_PERSON, np.int8),
        position_m=np.asarray(pos, float).reshape(n, 2), velocity_mps=np.zeros((n, 2)), heading_rad=np.zeros(n),
        feet_m=np.zeros((n, 2, 2)), size_m=np.tile([0.3, 0.5, 1.7], (n, 1)), upper_bgr=np.zeros((n, 3), np.uint8),
        lower_bgr=np.zeros((n, 3), np.uint8), pattern=np.zeros(n, np.int8), group_ids=np.full(n, -1, np.int64),
        gait_phase_rad=np.zeros(n),
    )


def _pair(separation_m: float, n_frames: int = 5) -> list[AgentSnapshot]:
    return [_snap(k, [1, 2], [[0.0, 0.0], [separation_m, 0.0]]) for k in range(n_frames)]


@pytest.mark.parametrize(("separation_m", "expected"), [(3.0, N), (0.7, C), (0.3, M)])
def test_two_people(separation_m: float, expected: Situation) -> None:
    labels = label_situations(_pair(separation_m), BOUNDS)
    assert len(labels) == 5
    for lab in labels:
        assert lab.shape == (2,)
        assert list(lab) == [expected, expected]


def test_merged_sets_are_transitive_and_correlated_excludes_merged() -> None:
    # 1-2 and 2-3 are 0.4 m apart (1-3: 0.8 m): one merged set of three; 4 is 0.7 m from 3: correlated
    frames = [_snap(k, [1, 2, 3, 4], [[0, 0], [0.4, 0], [0.8, 0], [1.5, 0]]) for k in range(3)]
    for lab in label_situations(frames, BOUNDS):
        assert list(lab) == [M, M, M, C]


def test_person_entering_at_the_boundary_is_appearing_for_one_second() -> None:
    # person 5 steps in at x = -10 (on the boundary) at frame 5 and walks +x at 1 m/s; 1 stands far away
    frames = []
    for k in range(40):
        ids, pos = [1], [[0.0, 5.0]]
        if k >= 5:
            ids.append(5)
            pos.append([-10.0 + 0.1 * (k - 5), 0.0])
        frames.append(_snap(k, ids, pos))
    labels = label_situations(frames, BOUNDS)
    for k, lab in enumerate(labels):
        assert lab[0] == N
        if k >= 5:
            # present for less than 1 s: frames 5..14 (t - t_enter = 0 .. 0.9 s)
            assert lab[1] == (A if k < 15 else N), k
    events = situation_events(frames, BOUNDS)
    assert [(e.kind, e.track_ids, e.t_ns, e.t_end_ns) for e in events] == [("appear", (5,), 5 * DT_NS, 14 * DT_NS)]


def test_person_inside_at_the_start_is_not_appearing() -> None:
    labels = label_situations([_snap(k, [1], [[0.0, 0.0]]) for k in range(15)], BOUNDS)
    assert all(lab[0] == N for lab in labels)
    assert situation_events([_snap(k, [1], [[0.0, 0.0]]) for k in range(15)], BOUNDS) == []


def test_person_leaving_is_disappearing() -> None:
    # person 5 walks +x at 1 m/s from x = 7 and is last seen at frame 29 at x = 9.9; the sequence goes on
    frames = []
    for k in range(40):
        ids, pos = [1], [[0.0, 5.0]]
        if k < 30:
            ids.append(5)
            pos.append([7.0 + 0.1 * k, 0.0])
        frames.append(_snap(k, ids, pos))
    labels = label_situations(frames, BOUNDS)
    for k in range(30):
        # leaves within 1 s (frames 20..29) and within 0.5 m of x = 10 (x >= 9.5: frames 25..29)
        assert labels[k][1] == (D if k >= 25 else N), k
    events = situation_events(frames, BOUNDS)
    assert [(e.kind, e.track_ids, e.t_ns, e.t_end_ns) for e in events] == [
        ("disappear", (5,), 25 * DT_NS, 29 * DT_NS)]
    # still there at the end of the sequence: not disappearing, however close to the edge
    labels = label_situations(frames[:30], BOUNDS)
    assert all(lab[1] == N for lab in labels)


def test_interaction_takes_precedence_over_the_edge() -> None:
    # two people step in together at the boundary 0.7 m apart: correlated, not appearing
    frames = [_snap(k, [1, 2], [[-10.0 + 0.1 * k, 0.0], [-10.0 + 0.1 * k, 0.7]]) for k in range(5)]
    for lab in label_situations(frames, BOUNDS):
        assert list(lab) == [C, C]
    counts = situation_counts(situation_events(frames, BOUNDS))
    assert counts["appear"] == 2  # the events count the entries even so
    assert counts["correlated"] == 2


def _approach_merge_split() -> list[AgentSnapshot]:
    """1 and 2 walk +x side by side; their separation 0.31 + 0.5 |t - 5 s| closes to 0.31 m and reopens.

    Separation < 0.6 m (merged) for |t - 5| < 0.58 s: frames 45..55; < 0.8 m (correlated) for
    |t - 5| < 0.98 s: frames 41..44 and 56..59. Person 3 walks far away throughout.
    """
    frames = []
    for k in range(101):
        t = k * 0.1
        d = 0.31 + 0.5 * abs(t - 5.0)
        frames.append(_snap(k, [3, 1, 2], [[t - 5, 6.0], [t - 5, d / 2], [t - 5, -d / 2]]))
    return frames


def test_approach_merge_split_labels() -> None:
    labels = label_situations(_approach_merge_split(), BOUNDS)
    for k, lab in enumerate(labels):
        want = M if 45 <= k <= 55 else C if 41 <= k <= 59 else N
        assert list(lab) == [N, want, want], k


def test_approach_merge_split_events() -> None:
    events = situation_events(_approach_merge_split(), BOUNDS, sensor="gt")
    merges = [e for e in events if e.kind == "merge"]
    splits = [e for e in events if e.kind == "split"]
    assert len(merges) == 1
    assert len(splits) == 1
    assert merges[0].track_ids == (1, 2)
    assert merges[0].t_ns == 45 * DT_NS
    assert merges[0].attributes["parts"] == ((1,), (2,))
    assert splits[0].track_ids == (1, 2)
    assert splits[0].t_ns == 56 * DT_NS
    assert splits[0].attributes["parts"] == ((1,), (2,))
    assert all(e.sensor == "gt" for e in events)
    corr = [(e.track_ids, e.t_ns, e.t_end_ns, e.attributes["partners"]) for e in events if e.kind == "correlated"]
    assert sorted(corr) == [((1,), 41 * DT_NS, 44 * DT_NS, (2,)), ((1,), 56 * DT_NS, 59 * DT_NS, (2,)),
                            ((2,), 41 * DT_NS, 44 * DT_NS, (1,)), ((2,), 56 * DT_NS, 59 * DT_NS, (1,))]
    assert situation_counts(events) == {"merge": 1, "split": 1, "correlated": 4, "appear": 0, "disappear": 0}
    assert [e.t_ns for e in events] == sorted(e.t_ns for e in events)


def test_third_person_joining_a_merged_pair_is_a_merge() -> None:
    frames = []
    for k in range(10):
        x3 = 3.0 - 0.4 * k if k < 6 else 0.6  # 0.7 m from 2 at frame 5 (correlated), 0.3 m from frame 6 on
        frames.append(_snap(k, [1, 2, 3], [[0.0, 0.0], [0.3, 0.0], [x3, 0.0]]))
    events = [e for e in situation_events(frames, BOUNDS) if e.kind in ("merge", "split")]
    # 1-2 merged from the first frame (no event); 3 joins at frame 6 (0.3 m from 2)
    assert [(e.kind, e.track_ids, e.t_ns) for e in events] == [("merge", (1, 2, 3), 6 * DT_NS)]
    assert events[0].attributes["parts"] == ((1, 2), (3,))


def test_ground_truth_records_are_accepted() -> None:
    frames = [GroundTruth(t_ns=k * DT_NS, sensor="gt", frame_id="world", ids=[1, 2],
                          positions_m=[[0.0, 0.0], [0.7, 0.0]]) for k in range(3)]
    assert all(list(lab) == [C, C] for lab in label_situations(frames, BOUNDS))


def test_bad_input_names_the_parameter() -> None:
    with pytest.raises(ValueError, match="bounds_m"):
        label_situations(_pair(1.0), (0, 0, -1, 1))
    with pytest.raises(ValueError, match="d_merged"):
        label_situations(_pair(1.0), BOUNDS, d_merged=0.9)
    with pytest.raises(ValueError, match="increasing"):
        label_situations(_pair(1.0)[::-1], BOUNDS)
    assert label_situations([], BOUNDS) == []


def _flicker() -> list[AgentSnapshot]:
    """1 and 2 side by side: 1.0 m apart (frames 0-4), 0.5 m (merged, 5-14), 0.65 m (correlated, 15-16),
    0.5 m again (17-26), then 1.0 m (27-34): by the centre distance, merge 5, split 15, merge 17, split 27."""
    sep = [1.0] * 5 + [0.5] * 10 + [0.65] * 2 + [0.5] * 10 + [1.0] * 8
    return [_snap(k, [1, 2], [[0.0, 0.0], [d, 0.0]]) for k, d in enumerate(sep)]


def test_split_hold_drops_a_split_undone_by_a_re_merge() -> None:
    def merges_splits(events):
        return [(e.kind, e.t_ns) for e in events if e.kind in ("merge", "split")]

    raw = merges_splits(situation_events(_flicker(), BOUNDS))
    assert raw == [("merge", 5 * DT_NS), ("split", 15 * DT_NS), ("merge", 17 * DT_NS), ("split", 27 * DT_NS)]
    # 0.2 s apart (10 Hz frames): a hold of 0.3 s drops the split at 15 and the merge at 17, 0.1 s keeps them
    held = situation_events(_flicker(), BOUNDS, split_hold_s=0.3)
    assert merges_splits(held) == [("merge", 5 * DT_NS), ("split", 27 * DT_NS)]
    assert merges_splits(situation_events(_flicker(), BOUNDS, split_hold_s=0.1)) == raw
    # the same rule on any event list (e.g. a tracker's): same result
    assert merges_splits(drop_undone_splits(situation_events(_flicker(), BOUNDS), 0.3)) == merges_splits(held)
    with pytest.raises(ValueError, match="hold_s"):
        drop_undone_splits([], -1.0)


def test_correlated_gap_bridging_and_minimum_length() -> None:
    # 1 and 2: correlated (0.7 m) frames 0-3, apart (2 m) 4-5, correlated 6-9, apart 10-20, correlated 21
    sep = [0.7] * 4 + [2.0] * 2 + [0.7] * 4 + [2.0] * 11 + [0.7]
    frames = [_snap(k, [1, 2], [[0.0, 0.0], [d, 0.0]]) for k, d in enumerate(sep)]

    def runs(**kw):
        return sorted((e.t_ns // DT_NS, e.t_end_ns // DT_NS) for e in situation_events(frames, BOUNDS, **kw)
                      if e.kind == "correlated" and e.track_ids == (1,))

    assert runs() == [(0, 3), (6, 9), (21, 21)]
    assert runs(correlated_gap_s=0.3) == [(0, 9), (21, 21)]  # the 0.3 s gap (last 3 -> next 6) is bridged
    assert runs(correlated_gap_s=0.25) == [(0, 3), (6, 9), (21, 21)]
    assert runs(correlated_gap_s=0.3, min_correlated_s=0.1) == [(0, 9)]


def test_a_merge_ends_a_correlated_run_even_within_the_gap() -> None:
    # correlated 0-2, merged 3, correlated 4-6: two runs whatever the gap allowance (the tracker closes at a merge)
    sep = [0.7] * 3 + [0.4] + [0.7] * 3
    frames = [_snap(k, [1, 2], [[0.0, 0.0], [d, 0.0]]) for k, d in enumerate(sep)]
    corr = sorted((e.t_ns // DT_NS, e.t_end_ns // DT_NS) for e in situation_events(frames, BOUNDS, correlated_gap_s=1.0)
                  if e.kind == "correlated" and e.track_ids == (1,))
    assert corr == [(0, 2), (4, 6)]


@pytest.mark.parametrize("gap_s", [0.25, 0.3, 1.0])
def test_bridge_correlated_on_any_event_list_is_the_truths_gap_rule(gap_s: float) -> None:
    """The tracker's events are bridged after the fact (benchmark 'persistence' row): the same runs as
    situation_events' own correlated_gap_s, also across a merge (which a bridge never crosses)."""
    def corr(events):
        return sorted((e.track_ids, e.t_ns // DT_NS, e.t_end_ns // DT_NS) for e in events if e.kind == "correlated")

    sep = [0.7] * 4 + [2.0] * 2 + [0.7] * 4 + [2.0] * 11 + [0.7] + [0.4] + [0.7] * 3
    frames = [_snap(k, [1, 2], [[0.0, 0.0], [d, 0.0]]) for k, d in enumerate(sep)]
    bridged = bridge_correlated(situation_events(frames, BOUNDS), gap_s)
    assert corr(bridged) == corr(situation_events(frames, BOUNDS, correlated_gap_s=gap_s))
    assert [e.kind for e in bridged if e.kind != "correlated"] == ["merge", "split"]
    with pytest.raises(ValueError, match="gap_s"):
        bridge_correlated([], -1.0)
