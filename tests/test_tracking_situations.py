"""The situation switch of seed 001 (ALGORITHMS.md B7) on scripted scenes with hand-written truth.

The covered area is the rectangle (0, 0)-(20, 10) m with d_edge = 0.5 m; gating is B6's
(σ = h = 0.4 m, G = 4: a detection is found within 0.8 m of a predicted centre).
"""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.tracking.association import association_states, gate_distances
from fusiontrack.tracking.situations import (
    DetectionLabel as DL,
)
from fusiontrack.tracking.situations import (
    SituationFrame,
    boundary_distance,
    classify_situations,
    on_edge,
)
from fusiontrack.tracking.situations import (
    TargetLabel as TL,
)
from fusiontrack.types import Situation

AREA = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 10.0], [0.0, 10.0]])


def run(targets: list[tuple[float, float]], merged: list[bool], dets: list[tuple[float, float]]) -> SituationFrame:
    t = np.array(targets, dtype=float)
    d = np.array(dets, dtype=float)
    D = gate_distances(t, d, 0.4)
    c, r, found = association_states(D, 4.0)
    return classify_situations(c, r, found, np.array(merged), on_edge(t, AREA), on_edge(d, AREA), D=D)


def test_frame_1_six_detections_four_targets() -> None:
    # T0 walks alone; T1 and T2 (0.6 m apart) share one segment; T3 is at the right edge with nothing.
    # D2 and D5 are new segments on the edge, D3 and D4 new segments inside.
    frame = run(
        targets=[(3.0, 5.0), (8.0, 5.0), (8.6, 5.0), (19.8, 5.0)],
        merged=[False, False, False, False],
        dets=[(3.1, 5.0), (8.3, 5.0), (0.2, 3.0), (12.0, 8.0), (15.0, 5.0), (15.0, 0.3)],
    )
    #                          T0                T1             T2             T3
    assert frame.target_labels.tolist() == [TL.NONCORRELATED, TL.MERGING, TL.MERGING, TL.DISAPPEARING]
    #                       D0          D1         D2              D3                  D4                  D5
    assert frame.det_labels.tolist() == [DL.MATCHED, DL.SHARED, DL.APPEAR_EDGE, DL.APPEAR_INTERIOR,
                                         DL.APPEAR_INTERIOR, DL.APPEAR_EDGE]
    assert {k: v.tolist() for k, v in frame.merge_groups.items()} == {1: [1, 2]}
    assert frame.merge_det.tolist() == [-1, 1, 1, -1]
    assert frame.nearest_det.tolist() == [0, 1, 1, -1]
    assert frame.appear_candidates.tolist() == [2, 3, 4, 5]
    assert frame.splitting.size == 0
    assert frame.split_candidates.size == 0
    assert frame.situations() == [Situation.NONCORRELATED, Situation.MERGED, Situation.MERGED,
                                  Situation.DISAPPEARING]


def test_frame_2_split_correlated_coasting() -> None:
    # M0 (merged, from frame 1) now sees two segments of its own: it splits. T1 and T2 both see D3:
    # each found two detections, so nobody merges -- both are correlated. T3 is occluded inside the area.
    frame = run(
        targets=[(8.3, 5.0), (3.0, 5.0), (4.2, 5.0), (15.0, 5.0)],
        merged=[True, False, False, False],
        dets=[(7.9, 5.0), (8.75, 5.0), (3.2, 5.0), (3.7, 5.2), (4.6, 5.0), (12.0, 9.8)],
    )
    #                          M0             T1             T2             T3
    assert frame.target_labels.tolist() == [TL.SPLITTING, TL.CORRELATED, TL.CORRELATED, TL.COASTING]
    #                       D0          D1          D2          D3         D4          D5
    assert frame.det_labels.tolist() == [DL.MATCHED, DL.MATCHED, DL.MATCHED, DL.SHARED, DL.MATCHED,
                                         DL.APPEAR_EDGE]
    assert frame.splitting.tolist() == [0]
    assert np.flatnonzero(frame.found[0]).tolist() == [0, 1]  # the detections to recover identities on
    assert frame.nearest_det.tolist() == [0, 2, 4, -1]
    assert frame.merge_groups == {}
    assert frame.situations()[3] == Situation.NONCORRELATED  # coasting is not an interaction


def test_frame_3_entered_together_stay_merged_join_and_shared_with_a_correlated() -> None:
    # T0 (never merged) sees two segments of its own: not a split -- it keeps the nearest (D0), D1 may
    # become a new target. M1 stays merged. M2 and T3 share D3 and see nothing else: they merge
    # (a third person joins a merged target). T4 finds D4 and D5; T5 finds only D4, shared with T4,
    # which found two: no merge, both correlated; D5, found by T4 alone and not its nearest, may become a new
    # target too (if no target is assigned it: a person beside a correlated pair).
    frame = run(
        targets=[(5.0, 5.0), (10.0, 5.0), (14.0, 5.0), (14.9, 5.0), (2.0, 2.0), (2.7, 2.0)],
        merged=[False, True, True, False, False, False],
        dets=[(4.8, 5.0), (5.5, 5.0), (10.1, 5.0), (14.45, 5.0), (2.35, 2.0), (1.5, 2.0)],
    )
    assert frame.target_labels.tolist() == [TL.CORRELATED, TL.MERGED, TL.MERGING, TL.MERGING,
                                            TL.CORRELATED, TL.CORRELATED]
    assert frame.det_labels.tolist() == [DL.MATCHED, DL.SPLIT_CANDIDATE, DL.MATCHED, DL.SHARED, DL.SHARED,
                                         DL.SPLIT_CANDIDATE]
    assert frame.split_candidates.tolist() == [1, 5]
    assert {k: v.tolist() for k, v in frame.merge_groups.items()} == {3: [2, 3]}
    assert frame.nearest_det.tolist() == [0, 2, 3, 3, 4, 4]


def test_merged_target_with_two_detections_one_shared_stays_merged() -> None:
    # M0 finds D0 and D1 but D1 is also T1's: not every detection has r = 1, so no split
    frame = run(targets=[(0.0 + 5, 5.0), (5.9, 5.0)], merged=[True, False], dets=[(4.7, 5.0), (5.5, 5.0)])
    assert frame.target_labels.tolist() == [TL.MERGED, TL.CORRELATED]


def test_empty_frames() -> None:
    frame = classify_situations(np.zeros(0), np.zeros(2), np.zeros((0, 2), bool), np.zeros(0, bool),
                                np.zeros(0, bool), np.array([True, False]))
    assert frame.det_labels.tolist() == [DL.APPEAR_EDGE, DL.APPEAR_INTERIOR]
    frame = classify_situations(np.zeros(2), np.zeros(0), np.zeros((2, 0), bool), np.zeros(2, bool),
                                np.array([True, False]), np.zeros(0, bool))
    assert frame.target_labels.tolist() == [TL.DISAPPEARING, TL.COASTING]
    assert frame.nearest_det.tolist() == [-1, -1]


def test_shape_mismatch_is_reported() -> None:
    with pytest.raises(ValueError, match="on_edge_dets"):
        classify_situations(np.ones(1), np.ones(2), np.ones((1, 2), bool), np.zeros(1, bool), np.zeros(1, bool),
                            np.zeros(3, bool))


def test_boundary_distance_rectangle_and_concave_polygon() -> None:
    rng = np.random.default_rng(0)
    p = rng.uniform([-3, -3], [23, 13], size=(500, 2))
    d = boundary_distance(p, AREA)
    inside = (p[:, 0] > 0) & (p[:, 0] < 20) & (p[:, 1] > 0) & (p[:, 1] < 10)
    assert ((d > 0) == inside).all()
    rect = np.minimum.reduce([p[:, 0], 20 - p[:, 0], p[:, 1], 10 - p[:, 1]])  # seed's rectangle rule inside
    np.testing.assert_allclose(d[inside], rect[inside])
    # outside: the Euclidean distance to the rectangle
    dx = np.maximum.reduce([-p[:, 0], p[:, 0] - 20, np.zeros(500)])
    dy = np.maximum.reduce([-p[:, 1], p[:, 1] - 10, np.zeros(500)])
    np.testing.assert_allclose(-d[~inside], np.hypot(dx, dy)[~inside])
    # an L-shaped room: (3, 3) in the notch is 1 m outside, (1, 3) 1 m inside
    ell = np.array([[0, 0], [4, 0], [4, 2], [2, 2], [2, 4], [0, 4]], dtype=float)
    np.testing.assert_allclose(boundary_distance(np.array([[3.0, 3.0], [1.0, 3.0]]), ell), [-1.0, 1.0])
    assert on_edge(np.array([[1.0, 3.0], [1.0, 3.7], [3.0, 3.0]]), ell).tolist() == [False, True, True]
