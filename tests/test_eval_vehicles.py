"""Vehicle scoring (eval/vehicles.py): the truth is scored at every instant of the tracker's clock."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.eval.vehicles import evaluate_vehicles, identity_kept, truth_at
from fusiontrack.types import GroundTruth, TrackState

T0 = 1_700_000_000 * 10**9


def _gt(n=100, rate=25.0):
    return [GroundTruth(T0 + round(k * 1e9 / rate), "gt", "world", [7], [[10.0 * k / rate, 0.0]], classes=("car",))
            for k in range(n)]


def _states(t_end_s, rate=15.0, offset_ns=3_000_000):
    out = []
    for k in range(int(t_end_s * rate) + 1):
        t = T0 + offset_ns + round(k * 1e9 / rate)
        out.append(TrackState(t, "trk", 1, np.array([10.0 * (t - T0) / 1e9, 0.3]), cls="car"))
    return out


def test_a_track_that_is_lost_half_way_misses_the_second_half():
    gt = _gt(100)  # 4 s of one car
    whole = evaluate_vehicles(gt, _states(3.96), rate_hz=15)
    half = evaluate_vehicles(gt, _states(2.0), rate_hz=15)
    assert whole.mota == pytest.approx(1.0)
    assert whole.fn == 0
    assert half.fn >= 25  # ~2 s x 15 Hz of truth with no track: missed, not skipped
    assert half.mota == pytest.approx(0.5, abs=0.05)


def test_area_limits_truth_and_tracks_and_classes_are_vehicles():
    gt = _gt(100)
    inside = truth_at(gt, [g.t_ns for g in gt], area=[(-1, -5), (19.8, -5), (19.8, 5), (-1, 5)])
    assert sum(len(g) for g in inside) == sum(1 for g in gt if g.positions_m[0, 0] < 19.8)
    people = [GroundTruth(g.t_ns, "gt", "world", [1], g.positions_m, classes=("person",)) for g in gt]
    assert sum(len(g) for g in truth_at(people, [g.t_ns for g in gt])) == 0


def test_identity_kept_through_a_gap():
    st = _states(4.0)
    before, after = T0 + int(1e9), T0 + int(3e9)
    assert identity_kept(st, [10.0, 0.0], before, [30.0, 0.0], after) is True
    swapped = [TrackState(s.t_ns, s.sensor, 2 if s.t_ns > T0 + 2e9 else 1, s.position_m) for s in st]
    assert identity_kept(swapped, [10.0, 0.0], before, [30.0, 0.0], after) is False
    assert identity_kept(st, [99.0, 0.0], before, [30.0, 0.0], after) is None
