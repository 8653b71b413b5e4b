"""Gating, association states and assignment (ALGORITHMS.md B6, B10, X2).

Seed 001 Eq. 3: a normalised squared distance ``D_kj`` between each target's predicted centre and each
detection; detection j is *found* by target k iff ``D_kj < G``. The association states count what was
found: ``c_k`` detections per target and ``r_j`` targets per detection, both capped at 2.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = [
    "FORBIDDEN_COST",
    "association_states",
    "gate_distances",
    "hungarian",
    "mahalanobis_gate_distances",
    "nearest_found",
]

FORBIDDEN_COST = 1e9  # X2: a pair above the gate costs this much and is reported unassigned


def _centres(value: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 2:
        raise ValueError(f"{name}: expected shape (n, 2), got {a.shape}")
    return a


def gate_distances(pred_centres: np.ndarray, det_centres: np.ndarray,
                   sigma: float | np.ndarray = 0.40) -> np.ndarray:
    """``D_kj = (x_j - x̂_k)²/σ_x² + (y_j - ŷ_k)²/σ_y²`` (B6, Eq. 3).

    Parameters
    ----------
    pred_centres : (n_t, 2) float
        Predicted target centres x̂_k (the particle mean after prediction), m.
    det_centres : (n_d, 2) float
        Detection centres c_j, m.
    sigma : float, (n_t,) or (n_t, 2) float
        σ per target (and per axis), m. B6's reconstruction: ``σ_x = σ_y = h = 0.40 m`` with ``G = 4``
        (a circular gate of radius 2h = 0.8 m).

    Returns
    -------
    D : (n_t, n_d) float64
        Dimensionless; ``NaN`` where a centre is ``NaN`` (never found).
    """
    p = _centres(pred_centres, "pred_centres")
    d = _centres(det_centres, "det_centres")
    if isinstance(sigma, float | int) and not isinstance(sigma, bool):
        # one σ for all (the tracker's case): dividing by it is dividing by a (n_t, 2) array full of it
        if sigma <= 0:  # as np.any(s <= 0) below (NaN passes)
            raise ValueError("sigma: expected values > 0")
        diff = (d[None, :, :] - p[:, None, :]) / float(sigma)
        return np.einsum("tdk,tdk->td", diff, diff)
    s = np.asarray(sigma, dtype=np.float64)
    if s.ndim == 0:
        s = np.full((p.shape[0], 2), float(s))
    elif s.shape == (p.shape[0],):
        s = np.repeat(s[:, None], 2, axis=1)
    elif s.shape != (p.shape[0], 2):
        raise ValueError(f"sigma: expected a scalar, ({p.shape[0]},) or ({p.shape[0]}, 2), got {s.shape}")
    if np.any(s <= 0):
        raise ValueError("sigma: expected values > 0")
    diff = (d[None, :, :] - p[:, None, :]) / s[:, None, :]
    return np.einsum("tdk,tdk->td", diff, diff)


def mahalanobis_gate_distances(pred_centres: np.ndarray, det_centres: np.ndarray, cov: np.ndarray,
                               min_var_m2: float = 0.40**2) -> np.ndarray:
    """B6's alternative gate: Mahalanobis distance under each target's particle covariance.

    The covariance is inflated so that every principal variance is at least ``min_var_m2`` (h²);
    use it with ``G = 9.21`` (χ²₂ at 99 %).

    Parameters
    ----------
    pred_centres : (n_t, 2) float
    det_centres : (n_d, 2) float
    cov : (n_t, 2, 2) float
        Position covariance of each target, m² (e.g. :func:`~fusiontrack.tracking.pf.weighted_cov`).
    min_var_m2 : float

    Returns
    -------
    D : (n_t, n_d) float64
    """
    p = _centres(pred_centres, "pred_centres")
    d = _centres(det_centres, "det_centres")
    c = np.asarray(cov, dtype=np.float64)
    if c.shape != (p.shape[0], 2, 2):
        raise ValueError(f"cov: expected shape ({p.shape[0]}, 2, 2), got {c.shape}")
    vals, vecs = np.linalg.eigh(0.5 * (c + np.swapaxes(c, 1, 2)))
    vals = np.maximum(vals, min_var_m2)
    inv = np.einsum("tik,tk,tjk->tij", vecs, 1.0 / vals, vecs)
    diff = d[None, :, :] - p[:, None, :]
    return np.einsum("tdi,tij,tdj->td", diff, inv, diff)


def association_states(D: np.ndarray, G: float = 4.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Association states of seed 001 (B6).

    Parameters
    ----------
    D : (n_t, n_d) float
        Gate distances (:func:`gate_distances`); ``NaN`` is never inside the gate.
    G : float
        Gate threshold: j is found by k iff ``D_kj < G``.

    Returns
    -------
    c : (n_t,) int64 in {0, 1, 2}
        Detections found by each target (2 = more than one).
    r : (n_d,) int64 in {0, 1, 2}
        Targets that found each detection (2 = more than one).
    found : (n_t, n_d) bool
    """
    dist = np.asarray(D, dtype=np.float64)
    if dist.ndim != 2:
        raise ValueError(f"D: expected shape (n_t, n_d), got {dist.shape}")
    found = dist < G
    c = np.add.reduce(found, axis=1, dtype=np.int64)  # (= found.sum, without the method's wrapper)
    np.minimum(c, 2, out=c)
    r = np.add.reduce(found, axis=0, dtype=np.int64)
    np.minimum(r, 2, out=r)
    return c, r, found


def nearest_found(D: np.ndarray, found: np.ndarray) -> np.ndarray:
    """Each target's nearest detection among those it found (B10 nearest-neighbour association).

    Parameters
    ----------
    D : (n_t, n_d) float
    found : (n_t, n_d) bool

    Returns
    -------
    index : (n_t,) int64
        Detection index, ``-1`` for a target that found none.
    """
    dist = np.where(np.asarray(found, dtype=bool), np.asarray(D, dtype=np.float64), np.inf)
    if dist.shape[1] == 0:
        return np.full(dist.shape[0], -1, dtype=np.int64)
    j = np.argmin(dist, axis=1)
    return np.where(np.isfinite(dist[np.arange(dist.shape[0]), j]), j, -1).astype(np.int64)


def hungarian(cost: np.ndarray, gate: float = np.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-cost one-to-one assignment with gating (X2; scipy's ``linear_sum_assignment``).

    A pair whose cost is above ``gate``, or not finite (``inf``/``NaN`` mark forbidden pairs), gets the
    cost ``FORBIDDEN_COST`` (1e9, raised above the largest finite cost when needed) and, if the solver
    still picks it, is reported as unassigned instead.

    Parameters
    ----------
    cost : (n_rows, n_cols) float
        E.g. rows = targets, columns = detections; ``D`` from :func:`gate_distances` or a distance in m.
    gate : float
        Largest allowed cost (inclusive).

    Returns
    -------
    pairs : (k, 2) int64
        ``(row, col)`` assigned pairs, sorted by row.
    unassigned_rows : (n_rows - k,) int64
    unassigned_cols : (n_cols - k,) int64
    """
    cst = np.asarray(cost, dtype=np.float64)
    if cst.ndim != 2:
        raise ValueError(f"cost: expected a 2-D matrix, got shape {cst.shape}")
    n_r, n_c = cst.shape
    allowed = np.isfinite(cst) & (cst <= gate)
    if not allowed.any():
        return np.zeros((0, 2), np.int64), np.arange(n_r, dtype=np.int64), np.arange(n_c, dtype=np.int64)
    big = max(FORBIDDEN_COST, 1e3 * (np.abs(cst[allowed]).max() + 1.0) * max(n_r, n_c))
    rows, cols = linear_sum_assignment(np.where(allowed, cst, big))
    keep = allowed[rows, cols]
    rows, cols = rows[keep], cols[keep]
    free_r, free_c = np.ones(n_r, bool), np.ones(n_c, bool)
    free_r[rows], free_c[cols] = False, False
    return (np.stack([rows, cols], axis=1).astype(np.int64), np.flatnonzero(free_r).astype(np.int64),
            np.flatnonzero(free_c).astype(np.int64))
