"""Gating, association states and Hungarian assignment (ALGORITHMS.md B6, B10, X2)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from fusiontrack.tracking import association as asc


def test_b6_table() -> None:
    # B6: targets (0,0), (3,0); detections (0.1,0), (0.5,0.2), (3,0.1); h = 0.4, G = 4 -> c = [2,1], r = [1,1,1]
    targets = np.array([[0.0, 0.0], [3.0, 0.0]])
    dets = np.array([[0.1, 0.0], [0.5, 0.2], [3.0, 0.1]])
    D = asc.gate_distances(targets, dets, 0.4)
    np.testing.assert_allclose(D[0], [0.01 / 0.16, 0.29 / 0.16, 9.01 / 0.16])
    c, r, found = asc.association_states(D, G=4.0)
    assert c.tolist() == [2, 1]
    assert r.tolist() == [1, 1, 1]
    assert found.tolist() == [[True, True, False], [False, False, True]]
    # target 1 correlated (c = 2), target 2 noncorrelated (c = 1, its detection r = 1)
    assert asc.nearest_found(D, found).tolist() == [0, 2]


def test_gate_is_a_circle_of_radius_2h_and_states_cap_at_two() -> None:
    h = 0.4
    targets = np.zeros((3, 2))  # three targets on top of each other
    dets = np.array([[0.79, 0.0], [0.0, 0.81], [0.3, 0.3], [-0.5, 0.0]])
    c, r, found = asc.association_states(asc.gate_distances(targets, dets, h))
    assert found[0].tolist() == [True, False, True, True]
    assert c.tolist() == [2, 2, 2]  # three found: "more than one"
    assert r.tolist() == [2, 0, 2, 2]


def test_per_target_and_per_axis_sigma() -> None:
    targets = np.array([[0.0, 0.0], [0.0, 0.0]])
    dets = np.array([[1.0, 1.0]])
    D = asc.gate_distances(targets, dets, np.array([[1.0, 2.0], [0.5, 0.5]]))
    np.testing.assert_allclose(D[:, 0], [1.0 + 0.25, 8.0])
    np.testing.assert_allclose(asc.gate_distances(targets, dets, np.array([1.0, 0.5])), [[2.0], [8.0]])
    with pytest.raises(ValueError, match="sigma"):
        asc.gate_distances(targets, dets, np.ones(3))


def test_mahalanobis_gate_inflates_to_h_squared() -> None:
    rng = np.random.default_rng(0)
    targets = rng.normal(size=(4, 2))
    dets = rng.normal(size=(5, 2))
    tiny = np.tile(np.eye(2) * 1e-4, (4, 1, 1))  # smaller than h²: inflated to h² I
    np.testing.assert_allclose(asc.mahalanobis_gate_distances(targets, dets, tiny, 0.16),
                               asc.gate_distances(targets, dets, 0.4))
    big = np.tile(np.diag([1.0, 4.0]), (4, 1, 1))
    np.testing.assert_allclose(asc.mahalanobis_gate_distances(targets, dets, big, 0.16),
                               asc.gate_distances(targets, dets, np.tile([1.0, 2.0], (4, 1))))


def test_nan_centres_are_never_found() -> None:
    D = asc.gate_distances(np.array([[np.nan, 0.0], [0.0, 0.0]]), np.array([[0.1, 0.0]]))
    c, r, _ = asc.association_states(D)
    assert c.tolist() == [0, 1]
    assert r.tolist() == [1]


def test_hungarian_forbidden_pair() -> None:
    # row 1 may only take column 0 (column 1 forbidden), so row 0 must take column 1 despite its cost
    cost = np.array([[1.0, 2.0], [1.0, np.inf]])
    pairs, un_r, un_c = asc.hungarian(cost)
    assert pairs.tolist() == [[0, 1], [1, 0]]
    assert un_r.size == 0
    assert un_c.size == 0
    # X2: a pair above the gate is forbidden and, if it is all that is left, reported unassigned
    pairs, un_r, un_c = asc.hungarian(np.array([[0.5, 9.0], [9.0, 9.0]]), gate=4.0)
    assert pairs.tolist() == [[0, 0]]
    assert un_r.tolist() == [1]
    assert un_c.tolist() == [1]


def test_hungarian_rectangular_and_empty() -> None:
    pairs, un_r, un_c = asc.hungarian(np.array([[5.0, 1.0, 3.0]]))
    assert pairs.tolist() == [[0, 1]]
    assert un_r.size == 0
    assert un_c.tolist() == [0, 2]
    pairs, un_r, un_c = asc.hungarian(np.zeros((0, 3)))
    assert pairs.shape == (0, 2)
    assert un_c.tolist() == [0, 1, 2]
    pairs, un_r, un_c = asc.hungarian(np.full((2, 2), np.inf))
    assert pairs.shape == (0, 2)
    assert un_r.tolist() == [0, 1]


def test_hungarian_matches_brute_force_with_gate() -> None:
    rng = np.random.default_rng(1)
    for _ in range(30):
        n_r, n_c = (int(v) for v in rng.integers(1, 5, size=2))
        cost = rng.random((n_r, n_c)) * 10
        gate = 6.0
        pairs, _, _ = asc.hungarian(cost, gate)
        got = (len(pairs), cost[pairs[:, 0], pairs[:, 1]].sum() if len(pairs) else 0.0)
        # brute force: maximise the number of allowed pairs, then minimise their total cost
        best = (0, 0.0)
        for perm in itertools.permutations(range(max(n_r, n_c)), n_r):
            chosen = [(i, j) for i, j in enumerate(perm) if j < n_c and cost[i, j] <= gate]
            cand = (len(chosen), sum(cost[i, j] for i, j in chosen))
            if cand[0] > best[0] or (cand[0] == best[0] and cand[1] < best[1]):
                best = cand
        assert got[0] == best[0]
        assert got[1] == pytest.approx(best[1])
