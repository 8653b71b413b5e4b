"""Situation-detection accuracy (eval/situations.py; seed 001 Table II) on hand-built event lists.

Every expected count is worked out by hand from the listed times, ids and positions.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiontrack.eval import (
    EvaluationError,
    FrameMatches,
    evaluate_floor,
    frame_matches,
    match_events,
    situation_accuracy,
    situation_agreement,
    situation_table,
)
from fusiontrack.eval.situations import AGREEMENT_LABELS
from fusiontrack.sim.situations import EVENT_KINDS, HIDDEN, SITUATION_DTYPE, SegmentAnalysis, situation_events
from fusiontrack.types import Event, GroundTruth, TrackState

S = 1_000_000_000  # ns per second
T0 = 1_700_000_000 * S


def ev(kind: str, t_s: float, ids=(), t_end_s: float | None = None, pos=None, sensor: str = "tracker") -> Event:
    t_end = None if t_end_s is None else T0 + round(t_end_s * S)
    return Event(t_ns=T0 + round(t_s * S), sensor=sensor, kind=kind, t_end_ns=t_end, position_m=pos,
                 track_ids=tuple(ids))


TRUE = [  # ground-truth ids 1..5
    ev("appear", 5.0, (4,), 6.0, pos=(0.2, 3.0), sensor="ground_truth"),
    ev("merge", 10.0, (1, 2), 10.0, pos=(2.0, 2.0), sensor="ground_truth"),
    ev("split", 15.0, (1, 2), 15.0, pos=(4.0, 2.0), sensor="ground_truth"),
    ev("correlated", 20.0, (3,), 25.0, pos=(6.0, 6.0), sensor="ground_truth"),
    ev("disappear", 30.0, (5,), 31.0, pos=(9.8, 1.0), sensor="ground_truth"),
]
ID_MAP = {11: 1, 12: 2, 13: 3, 14: 4, 15: 5}  # tracker id -> ground-truth id


def _perfect() -> list[Event]:
    """What a good tracker reports: its own ids, times a little late, positions a little off."""
    return [
        ev("appear", 5.4, (14,), pos=(0.5, 3.1)),
        ev("merge", 10.3, (11, 12), 10.3, pos=(2.2, 2.0)),
        ev("split", 14.8, (12, 11), 14.8, pos=(4.1, 2.2)),
        ev("correlated", 20.5, (13,), 24.0, pos=(6.3, 6.0)),
        ev("disappear", 31.4, (15,), pos=(9.9, 1.0)),
    ]


def test_everything_detected_with_id_map() -> None:
    scores = situation_accuracy(TRUE, _perfect(), id_map=ID_MAP)
    assert list(scores) == list(EVENT_KINDS)
    for kind, s in scores.items():
        assert (s.true, s.detected, s.false_alarms, s.detections) == (1, 1, 0, 1), kind
        assert (s.recall, s.precision) == (1.0, 1.0)


def test_everything_detected_by_time_and_position_without_id_map() -> None:
    scores = situation_accuracy(TRUE, _perfect())
    assert [s.detected for s in scores.values()] == [1] * 5


def test_time_outside_tolerance_is_a_miss_and_a_false_alarm() -> None:
    late = [ev("merge", 11.5, (11, 12), 11.5)]  # 1.5 s after the true merge
    s = situation_accuracy(TRUE, late, id_map=ID_MAP)["merge"]
    assert (s.true, s.detected, s.false_alarms) == (1, 0, 1)
    assert (s.recall, s.precision) == (0.0, 0.0)
    s = situation_accuracy(TRUE, late, id_map=ID_MAP, time_tolerance_ns=2 * S)["merge"]
    assert (s.detected, s.false_alarms) == (1, 0)


def test_wrong_identities_do_not_match() -> None:
    wrong = [ev("merge", 10.0, (13, 14), 10.0)]  # maps to gt 3 and 4, the true merge is 1 and 2
    s = situation_accuracy(TRUE, wrong, id_map=ID_MAP)["merge"]
    assert (s.detected, s.false_alarms) == (0, 1)
    partly = [ev("merge", 10.0, (11, 99), 10.0)]  # one identity shared is enough; 99 is unmapped
    assert situation_accuracy(TRUE, partly, id_map=ID_MAP)["merge"].detected == 1
    unmapped = [ev("merge", 10.0, (98, 99), 10.0)]
    assert situation_accuracy(TRUE, unmapped, id_map=ID_MAP)["merge"].false_alarms == 1


def test_position_decides_without_id_map_only_when_both_have_one() -> None:
    far = [ev("appear", 5.0, (14,), pos=(8.0, 3.0))]  # 7.8 m from where the true person entered
    assert situation_accuracy(TRUE, far)["appear"].detected == 0
    assert situation_accuracy(TRUE, far, position_tolerance_m=10.0)["appear"].detected == 1
    assert situation_accuracy(TRUE, far, id_map=ID_MAP)["appear"].detected == 1  # ids decide, not position
    no_pos = [ev("appear", 5.0, (77,))]
    assert situation_accuracy(TRUE, no_pos)["appear"].detected == 1  # time only


def test_each_true_event_is_detected_at_most_once() -> None:
    twice = [ev("split", 15.0, (11, 12), 15.0), ev("split", 15.2, (11, 12), 15.2)]
    s = situation_accuracy(TRUE, twice, id_map=ID_MAP)["split"]
    assert (s.true, s.detected, s.false_alarms, s.detections) == (1, 1, 1, 2)
    assert s.precision == 0.5


def test_matching_maximises_the_number_of_matches() -> None:
    """True at 0 s and 1 s, detections at 0.9 s and 1.9 s: pairing 0.9 with the nearer 1 s (greedy)
    would leave 1.9 s unmatched; the one-to-one optimum matches both (0 - 0.9, 1 - 1.9)."""
    true = [ev("merge", 0.0, (1, 2), 0.0), ev("merge", 1.0, (1, 2), 1.0)]
    det = [ev("merge", 0.9, (1, 2), 0.9), ev("merge", 1.9, (1, 2), 1.9)]
    assert match_events(true, det) == [(0, 0), (1, 1)]
    assert situation_accuracy(true, det)["merge"].detected == 2
    assert match_events(true, det[::-1]) == [(0, 1), (1, 0)]  # indices follow the input order


def test_kinds_never_match_each_other() -> None:
    det = [ev("split", 10.0, (11, 12), 10.0)]  # at the time of the true merge
    scores = situation_accuracy(TRUE, det, id_map=ID_MAP)
    assert (scores["merge"].detected, scores["split"].detected, scores["split"].false_alarms) == (0, 0, 1)


def test_time_spans() -> None:
    """A detection inside a true episode matches; the gap between spans is what the tolerance bounds."""
    inside = [ev("correlated", 23.0, (13,), 23.5)]  # inside the true 20-25 s episode
    assert situation_accuracy(TRUE, inside, id_map=ID_MAP)["correlated"].detected == 1
    after = [ev("correlated", 26.5, (13,), 27.0)]  # starts 1.5 s after the episode ended
    assert situation_accuracy(TRUE, after, id_map=ID_MAP)["correlated"].detected == 0
    ongoing = [ev("correlated", 18.0, (13,))]  # t_end None: still going on, so it spans the episode
    assert situation_accuracy(TRUE, ongoing, id_map=ID_MAP)["correlated"].detected == 1
    gone = [ev("disappear", 31.9, (15,), 31.9)]  # 0.9 s after the true exit at 31 s
    assert situation_accuracy(TRUE, gone, id_map=ID_MAP)["disappear"].detected == 1


def test_empty_kinds_and_ignored_kinds() -> None:
    scores = situation_accuracy([], [ev("meeting", 1.0), ev("merge", 2.0, (1, 2), 2.0)])
    assert "meeting" not in scores
    assert (scores["merge"].true, scores["merge"].false_alarms) == (0, 1)
    assert math.isnan(scores["merge"].recall)
    assert math.isnan(scores["split"].precision)
    only = situation_accuracy(TRUE, _perfect(), kinds=("merge",), id_map=ID_MAP)
    assert list(only) == ["merge"]


def test_order_of_events_changes_nothing() -> None:
    rng = np.random.default_rng(3)
    det = [*_perfect(), ev("merge", 10.1, (11, 12), 10.1), ev("appear", 40.0, (16,))]
    ref = {k: s.to_dict() for k, s in situation_accuracy(TRUE, det, id_map=ID_MAP).items()}
    for _ in range(5):
        t = [TRUE[i] for i in rng.permutation(len(TRUE))]
        d = [det[i] for i in rng.permutation(len(det))]
        assert {k: s.to_dict() for k, s in situation_accuracy(t, d, id_map=ID_MAP).items()} == ref


def test_bad_options_raise() -> None:
    with pytest.raises(EvaluationError, match="time_tolerance_ns"):
        situation_accuracy(TRUE, [], time_tolerance_ns=-1)
    with pytest.raises(EvaluationError, match="position_tolerance_m"):
        situation_accuracy(TRUE, [], position_tolerance_m=float("nan"))


def test_with_simulator_labels_and_the_mot_id_map() -> None:
    """Two people meet and part in a 10 m room; the true events come from sim.situations, the tracker's
    ids from evaluate_floor's identity map."""
    dt = S // 10
    frames, states = [], []
    for k in range(60):  # 6 s: they approach, walk together (0.4 m apart) from ~2 s to ~4 s, and part
        gap = float(np.clip(abs(k - 30) * 0.12, 0.4, 3.0))
        xy = np.array([[5.0, 5.0 - gap / 2], [5.0, 5.0 + gap / 2]])
        frames.append(GroundTruth(t_ns=T0 + k * dt, sensor="sim", frame_id="world", ids=[1, 2], positions_m=xy))
        states += [TrackState(t_ns=T0 + k * dt, sensor="tracker", track_id=tid, position_m=p + 0.05)
                   for tid, p in zip((101, 102), xy, strict=True)]
    true = situation_events(frames, (0.0, 0.0, 10.0, 10.0))
    kinds = [e.kind for e in true]
    assert (kinds.count("merge"), kinds.count("split")) == (1, 1)
    m = evaluate_floor(frames, states)
    assert dict(m.id_map) == {101: 1, 102: 2}
    merge_t = next(e.t_ns for e in true if e.kind == "merge")
    split_t = next(e.t_ns for e in true if e.kind == "split")
    detected = [Event(t_ns=merge_t + 2 * dt, sensor="tracker", kind="merge", t_end_ns=merge_t + 2 * dt,
                      track_ids=(101, 102)),
                Event(t_ns=split_t + 3 * dt, sensor="tracker", kind="split", t_end_ns=split_t + 3 * dt,
                      track_ids=(101, 102)),
                Event(t_ns=T0, sensor="tracker", kind="split", t_end_ns=T0, track_ids=(101, 102))]  # false alarm
    scores = situation_accuracy(true, detected, id_map=m.id_map)
    assert (scores["merge"].true, scores["merge"].detected, scores["merge"].false_alarms) == (1, 1, 0)
    assert (scores["split"].true, scores["split"].detected, scores["split"].false_alarms) == (1, 1, 1)


def test_frame_matches_name_who_a_track_followed_at_the_time_of_the_event() -> None:
    """Track 10 follows person 1 for 2 s, then (an identity error) person 2 for 4 s; track 20 the other way round.
    The whole-run identity map (IDF1's) gives track 10 to person 2, so track 10's correlated episode in the first
    2 s cannot match person 1's: a miss and a false alarm for what is an identity error. CLEAR's frame-by-frame
    matches name person 1 then, and the episode is detected."""
    dt = S // 10
    frames, states = [], []
    for k in range(60):
        xy = np.array([[float(k) * 0.1, 2.0], [float(k) * 0.1, 2.6]])  # side by side, 0.6 m apart
        frames.append(GroundTruth(t_ns=T0 + k * dt, sensor="sim", frame_id="world", ids=[1, 2], positions_m=xy))
        ids = (10, 20) if k < 20 else (20, 10)
        states += [TrackState(t_ns=T0 + k * dt, sensor="tracker", track_id=tid, position_m=p)
                   for tid, p in zip(ids, xy, strict=True)]
    m = evaluate_floor(frames, states)
    assert dict(m.id_map) == {10: 2, 20: 1}
    fm = frame_matches(frames, states)
    assert fm.n_matches == m.tp == 120
    with pytest.raises(EvaluationError, match="threshold_m"):
        frame_matches(frames, states, threshold_m=0.0)
    assert (fm.gt_id(10, T0 + 5 * dt), fm.gt_id(10, T0 + 40 * dt), fm.gt_id(99, T0)) == (1, 2, None)
    # before the track's first state (an appear event dated by the first sighting): the nearest match, if near
    assert fm.gt_id(10, T0 - 3 * dt) is None
    assert fm.gt_id(10, T0 - 3 * dt, within_ns=5 * dt) == 1
    assert fm.gt_id(20, T0 + 80 * dt, within_ns=30 * dt) == 1  # after its last state: its last person
    true = [ev("correlated", 0.5, (1,), 1.5, sensor="ground_truth")]
    detected = [ev("correlated", 0.6, (10,), 1.4)]
    whole = situation_accuracy(true, detected, id_map=m.id_map)["correlated"]
    assert (whole.detected, whole.false_alarms) == (0, 1)
    local = situation_accuracy(true, detected, id_map=fm)["correlated"]
    assert (local.detected, local.false_alarms) == (1, 0)
    # a detection of the other person at that time still does not match
    other = situation_accuracy(true, [ev("correlated", 0.6, (20,), 1.4)], id_map=fm)["correlated"]
    assert (other.detected, other.false_alarms) == (0, 1)


@pytest.mark.parametrize("seed", range(4))
def test_frame_matches_are_trackevals_clear_matches(seed: int) -> None:
    """Random crowds with noisy, swapping and missing tracks: as many matches as TrackEval's CLEAR TP, and the
    ID switches counted from them by CLEAR's rule equal its IDSW."""
    rng = np.random.default_rng(seed)
    n_t, n = 50, 5
    xy = np.cumsum(rng.normal(0, 0.15, (n_t, n, 2)), axis=0) + rng.uniform(0, 2, (1, n, 2))
    frames, states = [], []
    for k in range(n_t):
        frames.append(GroundTruth(t_ns=T0 + k * S // 10, sensor="sim", frame_id="world", ids=np.arange(n),
                                  positions_m=xy[k]))
        ids = rng.permutation(n) + 100 if rng.random() < 0.05 else np.arange(n) + 100
        states += [TrackState(t_ns=T0 + k * S // 10, sensor="tracker", track_id=int(tid),
                              position_m=xy[k, j] + rng.normal(0, 0.25, 2))
                   for j, tid in enumerate(ids) if rng.random() > 0.1]
    m = evaluate_floor(frames, states)
    fm = frame_matches(frames, states)
    assert fm.n_matches == m.tp
    last: dict[int, int] = {}
    idsw = 0
    for frame in fm.matches:
        idsw += sum(1 for tid, g in frame.items() if g in last and last[g] != tid)
        last.update({g: tid for tid, g in frame.items()})
    assert idsw == m.id_switches
    assert m.id_switches > 0


def test_situation_table() -> None:
    from rich.console import Console

    console = Console(width=120, record=True)
    console.print(situation_table(situation_accuracy(TRUE, _perfect()[:2], id_map=ID_MAP)))
    text = console.export_text()
    assert all(cell in text for cell in ("merge", "disappear", "100.0", "0.0", "false alarms"))


# ---- frame-level agreement ------------------------------------------------------------------------------------


def _analysis(t_ns: list[int], labels: list[list[str]], seen: list[list[bool]],
              merged: list[list[int]]) -> SegmentAnalysis:
    n = len(t_ns)
    ids = [np.array([1, 2], np.int64)] * n
    return SegmentAnalysis(np.array(t_ns, np.int64), ids, [np.zeros((2, 2))] * n,
                           [np.array(x, SITUATION_DTYPE) for x in labels], [np.array(x, bool) for x in seen],
                           [np.array(x, np.int64) for x in merged], [[np.zeros(0, np.int64)] * 2] * n,
                           [np.zeros((2, 2))] * n, [np.zeros(2, np.int64)] * n)


def _state(t_ns: int, tid: int, situation: str) -> TrackState:
    return TrackState(t_ns=t_ns, sensor="laser", track_id=tid, position_m=np.zeros(2), situation=situation)


def test_situation_agreement_counts_each_seen_person_frame_once() -> None:
    """Persons 1 and 2 over four frames 40 ms apart, written out by hand:
    frame 0 (before t_from): left out;
    frame 1: both correlated, track 10 follows 1 (says correlated), track 20 follows 2 (says merged);
    frame 2: both merged, 1 hidden but merged by occlusion; track 10 follows 1 (merged), nobody follows 2;
    frame 3: 1 noncorrelated and followed by 10 ('appearing' counts as noncorrelated); 2 hidden, not merged: left
    out. States are 10 ms off the frames: the nearest is used."""
    ms = 1_000_000
    t = [0, 40 * ms, 80 * ms, 120 * ms]
    analysis = _analysis(t, [["correlated", "correlated"], ["correlated", "correlated"], ["merged", "merged"],
                             ["noncorrelated", HIDDEN]],
                         [[True, True], [True, True], [False, True], [True, False]],
                         [[-1, -1], [-1, -1], [0, 0], [-1, -1]])
    matches = FrameMatches.from_frames(np.array(t), [{10: 1, 20: 2}, {10: 1, 20: 2}, {10: 1}, {10: 1}])
    states = [_state(0, 10, "merged"), _state(0, 20, "merged"),
              _state(50 * ms, 10, "correlated"), _state(30 * ms, 20, "merged"),
              _state(90 * ms, 10, "merged"), _state(130 * ms, 10, "appearing")]
    a = situation_agreement(analysis, states, matches, t_from_ns=10 * ms)
    want = np.zeros((3, 4), np.int64)
    want[1, 1] = want[1, 2] = 1  # frame 1
    want[2, 2] = want[2, 3] = 1  # frame 2
    want[0, 0] = 1  # frame 3
    np.testing.assert_array_equal(a.counts, want)
    assert AGREEMENT_LABELS == ("noncorrelated", "correlated", "merged")
    assert a.share("correlated") == 0.5
    assert a.share("merged", "no track") == 0.5
    assert a.share("noncorrelated") == 1
    assert math.isnan(situation_agreement(analysis, [], matches, t_from_ns=200 * ms).share("merged"))
    # a state too far from the frame counts as no track: track 10 only at t = 0 ... frame 1 is 40 ms away
    b = situation_agreement(analysis, states[:2], matches, t_from_ns=10 * ms, max_dt_ns=20 * ms)
    assert b.counts[:, 3].sum() == b.counts.sum() == 5
    # a truth label the comparison does not know is an error, not a silent skip
    bad = _analysis(t, [["correlated", "walking"]] * 4, [[True, True]] * 4, [[-1, -1]] * 4)
    with pytest.raises(EvaluationError, match="unknown situation 'walking'"):
        situation_agreement(bad, states, matches)
