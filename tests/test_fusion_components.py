"""The score maps' grouping of correlated targets (``_components``) labels groups as scipy's connected components
do: the same groups, numbered in the order of their first member (the maps are computed, and draw their patches,
in that order)."""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import connected_components

from fusiontrack.fusion.tracker import _components


def test_groups_and_their_numbering_are_scipys():
    rng = np.random.default_rng(0)
    for _ in range(500):
        n = int(rng.integers(0, 12))
        pts = rng.uniform(0, 4, (n, 2))
        if n and rng.random() < 0.2:
            pts[rng.integers(n)] = np.nan  # linked to nobody
        close = np.linalg.norm(pts[:, None] - pts[None], axis=2) < 1.0
        expected = connected_components(close, directed=False)[1] if n >= 2 else np.arange(n)
        np.testing.assert_array_equal(_components(pts, 1.0), expected)


def test_a_chain_is_one_group():
    pts = np.array([[0.0, 0.0], [5.0, 0.0], [0.9, 0.0], [1.8, 0.0], [2.7, 0.0], [5.5, 0.0]])
    np.testing.assert_array_equal(_components(pts, 1.0), [0, 1, 0, 0, 0, 1])
