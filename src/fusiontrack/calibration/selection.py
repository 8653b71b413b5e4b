"""Cluster selection and the bias update of seed 000 (ALGORITHMS.md A9, Eqs. 3–8; A10, Eq. 10): pure functions."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fusiontrack.geometry import wrap_angle

__all__ = ["bias_update", "discriminant", "select_clusters"]


def discriminant(n_points: Any, bg_diff_m: Any, delta_rad: Any, sigma_rad: Any) -> np.ndarray:
    """``g = P_V · P_B · P_C`` of every cluster in every region (ALGORITHMS.md A9, Eqs. 3–8).

    ``P_V = n_k / Σ_j n_j`` (volume, Eq. 4), ``P_B = D_k / Σ_j D_j`` (difference from the laser background,
    Eqs. 5–6), ``P_C = exp(-δ_k² / 2σ²) / Σ_j exp(-δ_j² / 2σ²)`` (closeness to the centre, Eqs. 7–8), sums over
    the clusters of the region (those with ``n > 0``). A sum of 0 gives the uniform distribution (A 0.2).

    Parameters
    ----------
    n_points : (n_regions, k) int
        Beams of cluster ``k`` inside the region; 0 = the cluster is not in the region.
    bg_diff_m : (n_regions, k) float
        ``D_k``, mean ``|B(i) - r(i)|`` over those beams, metres (NaN counts as 0).
    delta_rad : (n_regions, k) float
        ``δ_k = |θ̄_k - θ_c|``.
    sigma_rad : (n_regions,) float
        ``σ_θ`` (A9: ``h_θ / 2``), > 0.

    Returns
    -------
    (n_regions, k) float64
        ``g``, 0 outside the region; each row with a cluster sums to at most 1.
    """
    n = np.asarray(n_points, dtype=np.float64)
    if n.ndim != 2:
        raise ValueError(f"n_points: expected an array of shape (n_regions, k), got {n.shape}")
    D = np.nan_to_num(np.asarray(bg_diff_m, dtype=np.float64), nan=0.0)
    delta = np.asarray(delta_rad, dtype=np.float64)
    sigma = np.asarray(sigma_rad, dtype=np.float64).reshape(-1)
    if D.shape != n.shape or delta.shape != n.shape:
        raise ValueError(f"bg_diff_m, delta_rad: expected shape {n.shape}, got {D.shape}, {delta.shape}")
    if sigma.shape != (n.shape[0],) or not np.all(sigma > 0):
        raise ValueError(f"sigma_rad: expected {n.shape[0]} positive values, got {sigma}")
    member = n > 0

    def normalise(x: np.ndarray) -> np.ndarray:
        x = np.where(member, x, 0.0)
        s = x.sum(axis=1, keepdims=True)
        uniform = member / np.maximum(member.sum(axis=1, keepdims=True), 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(s > 0, x / s, uniform)

    p_v = normalise(n)
    p_b = normalise(np.maximum(D, 0.0))
    z = np.where(member, np.nan_to_num(delta, nan=np.inf) / sigma[:, None], np.inf)
    z0 = np.min(z, axis=1, keepdims=True)
    p_c = normalise(np.exp(-0.5 * (z**2 - np.where(np.isfinite(z0), z0, 0.0) ** 2)))  # shifted: no underflow
    return p_v * p_b * p_c


def select_clusters(g: Any, valid: Any, clarity: float = 2.0) -> np.ndarray:
    """One cluster per region, each cluster to at most one region (ALGORITHMS.md A9, overlapping regions).

    Pairs are taken greedily in descending ``g``; a region whose best clusters were taken by regions with a
    higher score takes its next-best. A region gets no cluster when its best free cluster is not ``valid``
    (background-like) or not a clear winner: ``g`` below ``clarity`` times that of its next free cluster.

    Parameters
    ----------
    g : (n_regions, k) float
        Scores from :func:`discriminant` (0 = not in the region).
    valid : (n_regions, k) bool
        Clusters that may be chosen (A9: ``D_k >= τ_fg``).
    clarity : float
        Required ratio of the winner to the runner-up, >= 1 (1 = plain argmax).

    Returns
    -------
    (n_regions,) int64
        Chosen cluster per region, -1 for none.
    """
    g = np.asarray(g, dtype=np.float64)
    valid = np.asarray(valid, dtype=bool)
    if g.ndim != 2 or valid.shape != g.shape:
        raise ValueError(f"g, valid: expected two arrays of one shape (n_regions, k), got {g.shape}, {valid.shape}")
    if not (math.isfinite(clarity) and clarity >= 1):
        raise ValueError(f"clarity: expected a ratio >= 1, got {clarity}")
    n_reg, k = g.shape
    choice = np.full(n_reg, -1, dtype=np.int64)
    done = np.zeros(n_reg, dtype=bool)
    taken = np.zeros(k, dtype=bool)
    score = np.where(g > 0, g, 0.0)
    rows, cols = np.nonzero(score > 0)
    for i in np.argsort(-score[rows, cols], kind="stable"):  # a loop over (object, cluster) pairs, not beams
        r, c = rows[i], cols[i]
        if done[r] or taken[c]:
            continue
        done[r] = True  # the region's best free cluster: chosen or the region is skipped this frame
        others = np.where(taken, 0.0, score[r])
        others[c] = 0.0
        if valid[r, c] and score[r, c] >= clarity * others.max(initial=0.0):
            choice[r] = c
            taken[c] = True
    return choice


def bias_update(bias_rad: float, residuals_rad: Any, weights: Any, rho: float,
                max_residual_rad: float = math.inf) -> tuple[float, float, bool]:
    """One step of the bias (ALGORITHMS.md A10, Eq. 10): ``b <- b + ρ ē``, ``ē = Σ g_k e_k / Σ g_k``.

    Equivalent to ``b <- (1 - ρ) b + ρ b*`` with ``b*`` the paper's target bias.

    Parameters
    ----------
    bias_rad : float
    residuals_rad : (m,) float
        ``e_k = θ̄_k* - θ_c,k`` of the objects with a valid cluster (``θ_c`` including the current bias).
    weights : (m,) float
        ``g_k`` (>= 0).
    rho : float
        Learning rate in (0, 1] (paper: 0.1 or 0.5).
    max_residual_rad : float
        Outlier guard: no update when ``|ē|`` exceeds it (A10: ``h_θ``).

    Returns
    -------
    bias_rad : float
        Updated (or unchanged) bias, wrapped to ``(-pi, pi]``.
    mean_residual_rad : float
        ``ē`` (NaN without residuals).
    updated : bool
    """
    if not 0 < rho <= 1:
        raise ValueError(f"rho: expected a learning rate in (0, 1], got {rho}")
    e = np.asarray(residuals_rad, dtype=np.float64).reshape(-1)
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    if e.shape != w.shape:
        raise ValueError(f"weights: expected {e.size} weights (one per residual), got {w.size}")
    ok = np.isfinite(e) & np.isfinite(w) & (w > 0)
    if not ok.any():
        return float(bias_rad), math.nan, False
    e_bar = float(np.sum(w[ok] * e[ok]) / np.sum(w[ok]))
    if abs(e_bar) > max_residual_rad:
        return float(bias_rad), e_bar, False
    return float(wrap_angle(bias_rad + rho * e_bar)), e_bar, True
