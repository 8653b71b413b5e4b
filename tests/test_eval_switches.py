"""Causes of identity switches (fusiontrack.eval.switches) on hand-built runs whose story is known, and their
count against TrackEval's CLEAR ID switches."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.eval import evaluate_floor, frame_matches
from fusiontrack.eval.switches import SWITCH_CAUSES, id_switch_causes, switch_cause_counts
from fusiontrack.types import GroundTruth, TrackState

T0_NS, DT_NS = 1_000_000_000, 100_000_000  # 10 Hz
N = 100  # frames


def _people(n: int) -> np.ndarray:
    """``n`` people 4 m apart walking in parallel at 1 m/s, (N, n, 2)."""
    t = np.arange(N) * 0.1
    return np.stack([np.column_stack([t, np.full(N, 4.0 * j)]) for j in range(n)], axis=1)


def _truth(xy: np.ndarray) -> list[GroundTruth]:
    return [GroundTruth(t_ns=T0_NS + k * DT_NS, sensor="sim", frame_id="world", ids=np.arange(1, xy.shape[1] + 1),
                        positions_m=xy[k]) for k in range(N)]


def _state(k: int, tid: int, xy) -> TrackState:
    return TrackState(t_ns=T0_NS + k * DT_NS, sensor="tracker", track_id=tid, position_m=np.asarray(xy, float))


def test_each_story_gets_its_cause():
    xy = _people(4)
    far = np.array([50.0, 50.0])
    st = []
    for k in range(N):
        # people 1 and 2: tracks 1 and 2 exchange them at frame 50
        st += [_state(k, 1 if k < 50 else 2, xy[k, 0]), _state(k, 2 if k < 50 else 1, xy[k, 1])]
        # person 3: track 3 ends at frame 40; track 4 starts at frame 45
        if k < 40:
            st.append(_state(k, 3, xy[k, 2]))
        if k >= 45:
            st.append(_state(k, 4, xy[k, 2]))
        # person 4: track 5 drifts off it at frame 60 and goes on (onto nobody); track 6 starts there at frame 58
        # and track 6's person is taken at frame 80 by track 7, alive since the start far from everybody
        st.append(_state(k, 5, xy[k, 3] if k < 60 else far + np.array([k, 0.0])))
        if 58 <= k < 80:
            st.append(_state(k, 6, xy[k, 3] + np.array([0.1, 0.0])))
        st.append(_state(k, 7, far - np.array([k, 0.0]) if k < 80 else xy[k, 3]))
    gt = _truth(xy)
    switches = id_switch_causes(frame_matches(gt, st, 0.5), st)
    got = sorted((s.gt_id, s.from_track, s.to_track, s.cause) for s in switches)
    assert got == [(1, 1, 2, "exchange"), (2, 2, 1, "exchange"), (3, 3, 4, "reborn"), (4, 5, 6, "new_track"),
                   (4, 6, 7, "takeover")]
    assert [s.t_ns for s in switches] == sorted(s.t_ns for s in switches)
    by_person = {s.gt_id: s for s in switches}
    assert by_person[3].last_ns == T0_NS + 39 * DT_NS  # matched track 3 last at frame 39
    assert by_person[3].t_ns == T0_NS + 45 * DT_NS
    assert len(switches) == evaluate_floor(gt, st, 0.5).id_switches
    assert switch_cause_counts(switches) == {"exchange": 2, "reborn": 1, "shared": 0, "new_track": 1, "takeover": 1}


def _side_by_side() -> np.ndarray:
    """Two people walking side by side 0.6 m apart (people 1 and 2), (N, 2, 2)."""
    t = np.arange(N) * 0.1
    return np.stack([np.column_stack([t, np.zeros(N)]), np.column_stack([t, np.full(N, 0.6)])], axis=1)


def _causes(xy: np.ndarray, st: list[TrackState], **kw) -> list[tuple[int, int, int, str]]:
    gt = _truth(xy)
    return [(s.gt_id, s.from_track, s.to_track, s.cause) for s in id_switch_causes(frame_matches(gt, st, 0.5), st,
                                                                                    **kw)]


@pytest.mark.parametrize("own_track", [False, True])
def test_a_track_shared_by_two_walkers_side_by_side(own_track):
    """Track 1 follows two people walking side by side as one, 0.25 m from person 1 and 0.35 m from person 2 (person
    1 is its match); at frame 50 it settles on person 2 and a new track 2 is born on person 1. Person 1 had the only
    track there was: ``shared``. With a track of its own on person 2 until frame 44 (``own_track``), track 1 drifted
    off person 1 onto somebody tracked: ``new_track``."""
    xy = _side_by_side()
    gt = _truth(xy)
    st = []
    for k in range(N):
        st.append(_state(k, 1, xy[k, 0] + [0.0, 0.25] if k < 50 else xy[k, 1]))
        if k >= 50:
            st.append(_state(k, 2, xy[k, 0]))
        if own_track and k < 45:
            st.append(_state(k, 3, xy[k, 1] + [0.0, 0.1]))
    got = _causes(xy, st, truth=gt)
    assert [w[:3] for w in got] == [(1, 1, 2)] + ([(2, 3, 1)] if own_track else [])
    assert got[0][3] == ("new_track" if own_track else "shared")
    # without the truth, the two walking together is not known: person 2 was never matched to track 1 before
    assert _causes(xy, st)[0][3] == "new_track"
    if own_track:  # track 3's last state is 0.6 s before the switch: looking back only 0.4 s, person 2 had no track
        assert _causes(xy, st, truth=gt, shared_s=0.4)[0][3] == "shared"
        assert _causes(xy, st, truth=gt, shared_s=0.4, shared_m=0.5)[0][3] == "new_track"  # (0.6 m apart)


def test_without_the_truth_a_shared_track_is_known_by_its_matches():
    # as above, but track 1 wavers: on person 1, and every 7th frame on person 2, before settling there at frame 50
    xy = _side_by_side()
    st = []
    for k in range(N):
        off = 0.55 if k % 7 == 3 else 0.05
        st.append(_state(k, 1, xy[k, 0] + [0.0, off] if k < 50 else xy[k, 1]))
        if k >= 50:
            st.append(_state(k, 2, xy[k, 0]))
    switches = _causes(xy, st)
    assert (1, 1, 2, "shared") in switches


def test_a_track_that_drifts_far_or_onto_a_newcomer_is_no_shared_track():
    """Person 1's track 1 leaves it at frame 50 for a person nobody tracked, and a new track 2 takes person 1. Far
    away (4 m), or a person coming into view only then, or settling on the other person only 1.5 s after the switch:
    ``new_track``, not ``shared``."""
    t = np.arange(N) * 0.1
    base = np.column_stack([t, np.zeros(N)])
    for story in ("far", "newcomer", "late"):
        other = np.column_stack([t, np.full(N, 4.0 if story == "far" else 0.6)])
        xy = np.stack([base, other], axis=1)
        gt = _truth(xy)
        if story == "newcomer":  # person 2 is in the truth from frame 50 only
            gt = [g if k >= 50 else GroundTruth(t_ns=g.t_ns, sensor="sim", frame_id="world", ids=g.ids[:1],
                                                 positions_m=g.positions_m[:1]) for k, g in enumerate(gt)]
        st = []
        for k in range(N):
            if story == "late":  # off onto nobody for 1.5 s, then onto person 2
                st.append(_state(k, 1, xy[k, 0] if k < 50 else np.array([50.0, 50.0]) if k < 65 else xy[k, 1]))
            else:
                st.append(_state(k, 1, xy[k, 0] if k < 50 else xy[k, 1]))
            if k >= 50:
                st.append(_state(k, 2, xy[k, 0]))
        switches = id_switch_causes(frame_matches(gt, st, 0.5), st, truth=gt)
        assert [(s.gt_id, s.from_track, s.to_track, s.cause) for s in switches] == [(1, 1, 2, "new_track")], story


def test_shared_looks_for_the_other_person_near_the_switch_only():
    """Track 1 covers persons 1 and 2 walking side by side (matched to person 1), follows person 2 alone from frame
    30 to 35 while person 1 goes unmatched, then drifts off onto nobody; the new track 2 takes person 1 at frame 50.
    Track 1 was with person 2 1.5 to 2 s before the switch: shared with ``shared_s`` 2.5, not with 1 (the truth
    given in any order)."""
    xy = _side_by_side()
    gt = _truth(xy)
    st = []
    for k in range(N):
        st.append(_state(k, 1, xy[k, 0] + [0.0, 0.25] if k < 30 else xy[k, 1] if k < 36 else [50.0, 50.0 + k]))
        if k >= 50:
            st.append(_state(k, 2, xy[k, 0]))
    shuffled = [gt[k] for k in np.random.default_rng(2).permutation(len(gt))]
    assert _causes(xy, st, truth=shuffled, shared_s=2.5) == [(1, 1, 2, "shared")]
    assert _causes(xy, st, truth=shuffled, shared_s=1.0) == [(1, 1, 2, "new_track")]


def test_an_exchange_needs_both_directions_within_the_window():
    # track 1 takes person 2 at frame 30 (3 s); track 2, off on nobody meanwhile, takes person 1 at frame 80 (8 s)
    xy = _people(2)
    far = np.array([50.0, 50.0])
    st = []
    for k in range(N):
        st.append(_state(k, 1, xy[k, 0] if k < 30 else xy[k, 1]))
        st.append(_state(k, 2, xy[k, 1] if k < 30 else far if k < 80 else xy[k, 0]))
    m = frame_matches(_truth(xy), st, 0.5)
    assert [(s.gt_id, s.cause) for s in id_switch_causes(m, st)] == [(2, "takeover"), (1, "takeover")]
    assert [s.cause for s in id_switch_causes(m, st, exchange_s=5.0)] == ["exchange", "exchange"]


def test_a_person_taken_and_given_back_is_no_exchange():
    # track 2, alive far off from the start, takes person 1 for 3 frames; track 1 takes it back: one person, no
    # exchange between two (review: both switches were labelled exchange)
    xy = _people(1)
    far = np.array([50.0, 50.0])
    st = []
    for k in range(N):
        st.append(_state(k, 1, xy[k, 0] if not 40 <= k < 43 else far))
        st.append(_state(k, 2, xy[k, 0] if 40 <= k < 43 else far + np.array([k, 0.0])))
    switches = id_switch_causes(frame_matches(_truth(xy), st, 0.5), st)
    assert [(s.from_track, s.to_track, s.cause) for s in switches] == [(1, 2, "takeover"), (2, 1, "takeover")]


@pytest.mark.parametrize("seed", range(5))
def test_the_causes_add_up_to_trackeval_id_switches(seed):
    """Random relabelings of a crowd's tracks (exchanges, new ids, ids reused, dropped frames): however the
    switches arise, one label each, and as many as TrackEval's CLEAR counts."""
    rng = np.random.default_rng(seed)
    xy = _people(6) + rng.normal(0, 0.05, (N, 6, 2))
    ids = np.tile(np.arange(6), (N, 1))
    next_id = 6
    for k in rng.choice(np.arange(5, N), 8, replace=False):
        kind = rng.integers(3)
        a, b = rng.choice(6, 2, replace=False)
        if kind == 0:  # exchange from frame k on
            ids[k:, [a, b]] = ids[k:, [b, a]]
        elif kind == 1:  # a new track from frame k on
            ids[k:, a] = next_id
            next_id += 1
        else:  # an id that ended reused from frame k on
            ids[k:, a] = rng.integers(next_id)
    drop = rng.random((N, 6)) < 0.1
    st = [_state(k, int(ids[k, j]), xy[k, j]) for k in range(N) for j in range(6) if not drop[k, j]]
    # an id may now be on two people at once in a frame: keep the first, as a tracker's ids are unique
    seen, unique = set(), []
    for s in st:
        if (s.t_ns, s.track_id) not in seen:
            seen.add((s.t_ns, s.track_id))
            unique.append(s)
    gt = _truth(xy)
    switches = id_switch_causes(frame_matches(gt, unique, 0.5), unique)
    assert len(switches) == evaluate_floor(gt, unique, 0.5).id_switches
    assert {s.cause for s in switches} <= set(SWITCH_CAUSES)


def test_bad_windows_are_refused():
    with pytest.raises(ValueError, match="new_s"):
        id_switch_causes(frame_matches(_truth(_people(1)), [], 0.5), [], new_s=-1.0)
    with pytest.raises(ValueError, match="shared_s"):
        id_switch_causes(frame_matches(_truth(_people(1)), [], 0.5), [], shared_s=float("nan"))
    with pytest.raises(ValueError, match="shared_m"):
        id_switch_causes(frame_matches(_truth(_people(1)), [], 0.5), [], shared_m=-1.0)
