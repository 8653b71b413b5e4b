"""Identity decisions of the fused tracker where tracks overlap in time: a re-identified track's states all take the
lost identity, and no identity is worn by two states at once (the invariants a track file and the CLEAR metrics
rely on)."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from fusiontrack.fusion import FusionTracker, relabel_states
from fusiontrack.fusion.tracker import _Claim
from fusiontrack.types import TrackState

LOST, NEW = 3, 7


def _states(tid: int, times: range, x0: float) -> list[TrackState]:
    return [TrackState(t, "laser", tid, np.array([x0 + 0.01 * t, 0.0])) for t in times]


def _reidentify(seen_ns: int, lost_times: range, new_times: range, decided_ns: int) -> list[TrackState]:
    """Lost track LOST (detected until ``seen_ns``, states at ``lost_times``: coasted after ``seen_ns``) and new
    track NEW (states at ``new_times``) re-identified at ``decided_ns``: all states with the decision applied."""
    trk = FusionTracker(None, None)
    trk._lost[LOST] = (seen_ns, lost_times[-1], np.zeros(2))
    trk._span[LOST] = [lost_times[0], lost_times[-1]]
    trk._span[NEW] = [new_times[0], new_times[-1]]
    trk._claims[NEW] = _Claim(new_times[0], [LOST], {LOST: 0.9}, {LOST: 1}, 3)
    at_decision = [s for s in _states(NEW, new_times, 10.0) if s.t_ns == decided_ns]
    out = trk._give_back(decided_ns, NEW, LOST, at_decision)
    assert [s.track_id for s in out] == [LOST]
    assert trk.stats.reids == 1
    earlier = [s for s in _states(NEW, new_times, 10.0) if s.t_ns < decided_ns]  # (the tracker returned them)
    return relabel_states([*_states(LOST, lost_times, 0.0), *earlier, *out], trk.relabels)


@pytest.mark.parametrize("new_from", [12, 15, 16])
def test_reborn_track_takes_the_lost_identity_over_the_coasted_states(new_from: int) -> None:
    # detected until 10, coasted to 15; the new track born after the last detection (overlapping the coasting or
    # not): every state of the new track is the lost person's, the coasted guesses give way
    states = _reidentify(10, range(0, 16), range(new_from, 21), 20)
    assert not [k for k, n in Counter((s.t_ns, s.track_id) for s in states).items() if n > 1]
    reborn = [s for s in states if s.position_m[0] >= 10.0]
    assert {s.track_id for s in reborn} == {LOST}
    detected = [s for s in states if s.position_m[0] < 10.0 and s.t_ns <= 10]
    assert {s.track_id for s in detected} == {LOST}


def test_new_track_born_before_the_last_detection_keeps_its_id_where_the_lost_one_was_detected() -> None:
    # two people at once up to 10: the new track's states there cannot be the lost track's person
    states = _reidentify(10, range(0, 16), range(8, 21), 20)
    assert not [k for k, n in Counter((s.t_ns, s.track_id) for s in states).items() if n > 1]
    ids = {s.t_ns: s.track_id for s in states if s.position_m[0] >= 10.0}
    assert all(ids[t] == NEW for t in (8, 9, 10))
    assert all(ids[t] == LOST for t in range(11, 21))
    assert {s.track_id for s in states if s.position_m[0] < 10.0 and s.t_ns <= 10} == {LOST}
