"""Observation likelihoods of the laser particle filters (ALGORITHMS.md B9, B18).

Seed 001: ``p(z | x) = P_pos · P_walk``, a feet-to-segment similarity times a walking-pattern
similarity, assumed independent (functional forms RECON). Everything is evaluated for all targets and
particles at once; each target is paired with *one* detection (its nearest gated one, B10), passed as
row ``t`` of the observation arrays. A row whose observation holds ``NaN`` (no detection: coasting)
gets log-likelihood 0, i.e. its weights are left as they are.
"""

from __future__ import annotations

import numpy as np

from . import _jit
from .walking import PHI, STATE_DIM, STRIDE, predicted_feet_distance

__all__ = [
    "centroid_likelihood",
    "centroid_log_likelihood",
    "laser_likelihood",
    "laser_log_likelihood",
    "laser_log_likelihood_cols",
]


def _sqdist(px: np.ndarray, py: np.ndarray, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
    dx = px - qx
    dx *= dx
    dy = py - qy
    dy *= dy
    dx += dy
    return dx


def laser_log_likelihood(state: np.ndarray, feet_obs: np.ndarray, inter_feet: np.ndarray, one_foot: np.ndarray,
                         sigma_f: float = 0.10, sigma_w: float = 0.10, *, sigma_f_one: float = 0.15,
                         kappa: float = 1.0 / np.pi, lateral_m: float = 0.0) -> np.ndarray:
    """``log p(z | x) = log P_pos + log P_walk`` for walking particles against their detections (B9).

    Feet-to-segment: each predicted foot goes to its nearest foot barycentre; if both go to the same
    one and the segment has two (``one_foot`` False), the assignment with the smaller total (Euclidean)
    distance is used. ``log P_pos = -(|p^L - f_L*|² + |p^R - f_R*|²) / (2σ_f²)``.
    Walking pattern: ``log P_walk = -(S_d - D_pred(φ, S))² / (2σ_w²)`` with
    ``D_pred = κ S |cos φ|`` (:func:`~fusiontrack.tracking.walking.predicted_feet_distance`).
    For a one-foot segment ``P_walk = 1`` and ``σ_f = sigma_f_one``.

    Parameters
    ----------
    state : (n_t, n_p, 8) float
        Walking particles (columns in :mod:`fusiontrack.tracking.walking`).
    feet_obs : (n_t, 2, 2) float
        The two foot barycentres ``f_1, f_2`` of each target's detection, m (B5). ``NaN`` = no detection.
    inter_feet : (n_t,) float
        Measured inter-feet distance ``S_d = |f_1 - f_2|``, m.
    one_foot : (n_t,) bool
        B5's single-blob flag.
    sigma_f, sigma_w : float
        σ_f and σ_w of B9, m.
    sigma_f_one : float
        σ_f used for one-foot segments, m.
    kappa, lateral_m : float
        See :func:`~fusiontrack.tracking.walking.predicted_feet_distance`.

    Returns
    -------
    log_likelihood : (n_t, n_p) float64
        ``<= 0``; exactly 0 on rows without a detection.
    """
    x = np.asarray(state, dtype=np.float64)
    if x.ndim != 3 or x.shape[-1] != STATE_DIM:
        raise ValueError(f"state: expected shape (n_t, n_p, {STATE_DIM}), got {x.shape}")
    cols = np.ascontiguousarray(x.reshape(-1, STATE_DIM).T).reshape(STATE_DIM, *x.shape[:2])  # (8, n_t, n_p)
    return laser_log_likelihood_cols(cols, feet_obs, inter_feet, one_foot, sigma_f, sigma_w, sigma_f_one=sigma_f_one,
                                     kappa=kappa, lateral_m=lateral_m)


def laser_log_likelihood_cols(cols: np.ndarray, feet_obs: np.ndarray, inter_feet: np.ndarray, one_foot: np.ndarray,
                              sigma_f: float = 0.10, sigma_w: float = 0.10, *, sigma_f_one: float = 0.15,
                              kappa: float = 1.0 / np.pi, lateral_m: float = 0.0,
                              missing: np.ndarray | None = None) -> np.ndarray:
    """:func:`laser_log_likelihood` of particles in the column layout ``(8, n_t, n_p)`` (``cols[c]`` is column
    ``c`` of every particle, as the laser tracker keeps them): the same values, without a transpose per call.

    ``missing (n_t,) bool``, optional: the rows without a detection when the caller knows them, given as finite
    values (e.g. zeros: they are not used, the rows' log-likelihood is 0); default: the rows holding ``NaN``.
    """
    f = np.asarray(feet_obs, dtype=np.float64)
    if cols.ndim != 3 or cols.shape[0] != STATE_DIM:
        raise ValueError(f"cols: expected shape ({STATE_DIM}, n_t, n_p), got {cols.shape}")
    n_t = cols.shape[1]
    if f.shape != (n_t, 2, 2):
        raise ValueError(f"feet_obs: expected shape ({n_t}, 2, 2), got {f.shape}")
    sd = _vector(inter_feet, np.float64, n_t)
    one = _vector(one_foot, bool, n_t)
    if missing is None:
        missing = np.isnan(f).any(axis=(1, 2)) | (np.isnan(sd) & ~one)
        any_missing = np.count_nonzero(missing) > 0
        if any_missing:
            f = np.where(missing[:, None, None], 0.0, f)
            sd = np.where(missing, 0.0, sd)
    else:
        missing = np.asarray(missing, dtype=bool)
        if missing.shape != (n_t,):  # (the kernel would read past its end)
            raise ValueError(f"missing: expected shape ({n_t},), got {missing.shape}")
        any_missing = np.count_nonzero(missing) > 0
    if _jit.ENABLED and cols.dtype == np.float64 and cols.flags.c_contiguous:
        out = np.empty(cols.shape[1:])
        prm = np.array([1.0 / (2.0 * sigma_f**2), 1.0 / (2.0 * sigma_f_one**2), 1.0 / (2.0 * sigma_w**2), kappa,
                        lateral_m])
        _jit.laser_ll(cols, np.ascontiguousarray(f), np.ascontiguousarray(sd), np.ascontiguousarray(one),
                      np.ascontiguousarray(missing, dtype=bool), prm, out)
        return out
    any_one = np.count_nonzero(one) > 0

    # The four squared foot-to-barycentre distances in one pass, each |p - f|² = dx² + dy² as written out:
    # rows (l-f1, l-f2, r-f1, r-f2) x (x, y)
    # (8, n_t, n_p): (lx ly lx ly rx ry rx ry) - (f1x f1y f2x f2y f1x f1y f2x f2y), one broadcast subtraction:
    # feet (l, r) x barycentre (f1, f2) x (x, y)
    n_p = cols.shape[2]
    d = np.subtract(cols[0:4].reshape(2, 1, 2, n_t, n_p), f.reshape(n_t, 4).T.reshape(1, 2, 2, n_t, 1))
    d = d.reshape(8, n_t, n_p)
    d *= d
    d4 = d[0::2] + d[1::2]  # (4, n_t, n_p): dl1, dl2, dr1, dr2
    dl1, dl2, dr1, dr2 = d4
    le = d4[0::2] <= d4[1::2]  # dl1 <= dl2, dr1 <= dr2
    l_to_1 = le[0]
    same = le[0] == le[1]
    straight = dl1 + dr2
    crossed = dl2 + dr1
    # feet on different barycentres: the nearest-foot assignment itself (the smaller of the two
    # pairings); both on the same one of a two-foot segment: the smaller total Euclidean distance
    pick_straight = straight <= crossed
    if np.count_nonzero(same):
        r4 = np.sqrt(d4)
        # sqrt(dl1) + sqrt(dr2) <= sqrt(dl2) + sqrt(dr1)
        pick_straight = np.where(same, r4[0] + r4[3] <= r4[1] + r4[2], pick_straight)
    sq = np.where(pick_straight, straight, crossed)
    if any_one:  # a one-foot segment: both feet go to the nearest (the same) barycentre
        both = np.where(l_to_1, dl1 + dr1, dl2 + dr2)
        sq[one] = both[one]
        sq *= -np.where(one, 1.0 / (2.0 * sigma_f_one**2), 1.0 / (2.0 * sigma_f**2))[:, None]
    else:
        sq *= -(1.0 / (2.0 * sigma_f**2))
    log_l = sq
    d_pred = predicted_feet_distance(cols[PHI], cols[STRIDE], kappa, lateral_m)
    log_walk = np.subtract(sd[:, None], d_pred, out=d_pred)  # (S_d - D_pred)² (-1 / 2σ_w²)
    log_walk *= log_walk
    log_walk *= -1.0 / (2.0 * sigma_w**2)
    if any_one:
        log_walk[one] = 0.0
    log_l += log_walk
    if any_missing:
        log_l[missing] = 0.0
    return log_l


def _vector(value: object, dtype: type, n: int) -> np.ndarray:
    """``value`` as an ``(n,)`` array of ``dtype`` (broadcast from a scalar), without copying an array that is one."""
    if isinstance(value, np.ndarray) and value.dtype == dtype and value.shape == (n,):
        return value
    return np.broadcast_to(np.asarray(value, dtype=dtype), (n,))


def laser_likelihood(state: np.ndarray, feet_obs: np.ndarray, inter_feet: np.ndarray, one_foot: np.ndarray,
                     sigma_f: float = 0.10, sigma_w: float = 0.10, **kwargs: float) -> np.ndarray:
    """``p(z | x) = P_pos · P_walk`` (B9); see :func:`laser_log_likelihood` for the parameters.

    Returns
    -------
    likelihood : (n_t, n_p) float64 in [0, 1]
        May underflow to 0 far from the detection: weight with the log variant.
    """
    return np.exp(laser_log_likelihood(state, feet_obs, inter_feet, one_foot, sigma_f, sigma_w, **kwargs))


def centroid_log_likelihood(positions_m: np.ndarray, centres_m: np.ndarray, sigma_m: float = 0.15) -> np.ndarray:
    """Gaussian log-likelihood of a segment centroid, ``-|x - c|² / (2σ²)`` (B18, bicycles and cars).

    Parameters
    ----------
    positions_m : (n_t, n_p, >=2) float
        Particle states; the first two columns are the position (the CV state works as is).
    centres_m : (n_t, 2) float
        Each target's detection centroid; ``NaN`` row = no detection (log-likelihood 0).
    sigma_m : float

    Returns
    -------
    log_likelihood : (n_t, n_p) float64
    """
    p = np.asarray(positions_m, dtype=np.float64)
    c = np.asarray(centres_m, dtype=np.float64)
    if p.ndim != 3 or p.shape[-1] < 2 or c.shape != (p.shape[0], 2):
        raise ValueError(f"positions_m (n_t, n_p, >=2) and centres_m (n_t, 2) disagree: {p.shape} vs {c.shape}")
    missing = np.isnan(c).any(axis=1)
    c = np.where(missing[:, None], 0.0, c)
    d = p[..., 0:2] - c[:, None, :]
    out = -np.einsum("tpk,tpk->tp", d, d) / (2.0 * sigma_m**2)
    out[missing] = 0.0
    return out


def centroid_likelihood(positions_m: np.ndarray, centres_m: np.ndarray, sigma_m: float = 0.15) -> np.ndarray:
    """``exp`` of :func:`centroid_log_likelihood`, ``(n_t, n_p)``."""
    return np.exp(centroid_log_likelihood(positions_m, centres_m, sigma_m))
