"""Constant-velocity Kalman filter as pure functions, vectorised over targets (ALGORITHMS.md X5).

State ``[x, y, ẋ, ẏ]`` per target: ``x (n, 4)``, ``P (n, 4, 4)``. ``F``, ``Q``, ``H`` and ``R`` are either
shared ``(k, k)`` matrices or per-target stacks ``(n, k, k)``. Used by the merged targets of B17, the
bicycle/car model of B18 and the baseline tracker (CV Kalman + Hungarian).
"""

from __future__ import annotations

import numpy as np

__all__ = ["H_POSITION", "cv_matrices", "innovation", "predict", "update"]

H_POSITION = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])  # X5: H = [I 0]
H_POSITION.setflags(write=False)


def cv_matrices(dt_s: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Transition and process noise of the 2-D constant-velocity model (X5).

    ``F = [[I, Δt I], [0, I]]``, ``Q = q [[Δt³/3 I, Δt²/2 I], [Δt²/2 I, Δt I]]`` (white-noise acceleration).

    Parameters
    ----------
    dt_s : float
        Time step, s.
    q : float
        Acceleration noise intensity: 1 m²/s³ for vehicles, 25 px²/s³ for image blobs (X5).

    Returns
    -------
    F, Q : (4, 4) float64
    """
    if not dt_s >= 0.0:
        raise ValueError(f"dt_s: expected a time step >= 0 s, got {dt_s}")
    if not q >= 0.0:
        raise ValueError(f"q: expected >= 0, got {q}")
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt_s
    Q = np.zeros((4, 4))
    Q[0, 0] = Q[1, 1] = q * dt_s**3 / 3.0
    Q[0, 2] = Q[1, 3] = Q[2, 0] = Q[3, 1] = q * dt_s**2 / 2.0
    Q[2, 2] = Q[3, 3] = q * dt_s
    return F, Q


def _apply(M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``M x`` per target for a shared ``(m, k)`` or per-target ``(n, m, k)`` matrix."""
    return x @ M.T if M.ndim == 2 else np.einsum("nij,nj->ni", M, x)


def _batch(x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xs = np.asarray(x, dtype=np.float64)
    Ps = np.asarray(P, dtype=np.float64)
    if xs.ndim != 2 or Ps.shape != (*xs.shape, xs.shape[1]):
        raise ValueError(f"x (n, k) and P (n, k, k) disagree: {xs.shape} vs {Ps.shape}")
    return xs, Ps


def predict(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kalman prediction ``x ← F x``, ``P ← F P Fᵀ + Q`` for every target.

    Parameters
    ----------
    x : (n, k) float
    P : (n, k, k) float
    F, Q : (k, k) or (n, k, k) float

    Returns
    -------
    x, P : (n, k), (n, k, k) float64
    """
    xs, Ps = _batch(x, P)
    Fm = np.asarray(F, dtype=np.float64)
    x_new = _apply(Fm, xs)
    P_new = Fm @ Ps @ np.swapaxes(Fm, -1, -2) + np.asarray(Q, dtype=np.float64)
    return x_new, 0.5 * (P_new + np.swapaxes(P_new, -1, -2))


def innovation(x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray = H_POSITION,
               R: np.ndarray | float = 0.05**2) -> tuple[np.ndarray, np.ndarray]:
    """Innovation ``y = z - H x`` and its covariance ``S = H P Hᵀ + R`` (for gating: ``yᵀ S⁻¹ y``).

    Parameters
    ----------
    x : (n, k); P : (n, k, k); z : (n, m) float
    H : (m, k) or (n, m, k) float
    R : float (times I), (m, m) or (n, m, m) float

    Returns
    -------
    y : (n, m) float64
    S : (n, m, m) float64
    """
    xs, Ps = _batch(x, P)
    Hm = np.asarray(H, dtype=np.float64)
    zs = np.asarray(z, dtype=np.float64)
    m = Hm.shape[-2]
    if zs.shape != (xs.shape[0], m):
        raise ValueError(f"z: expected shape ({xs.shape[0]}, {m}), got {zs.shape}")
    Rm = np.asarray(R, dtype=np.float64)
    if Rm.ndim == 0:
        Rm = Rm * np.eye(m)
    y = zs - _apply(Hm, xs)
    S = Hm @ Ps @ np.swapaxes(Hm, -1, -2) + Rm
    return y, S


def update(x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray = H_POSITION,
           R: np.ndarray | float = 0.05**2) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with a measurement per target (Joseph form, so ``P`` stays symmetric positive definite).

    A target whose ``z`` row contains ``NaN`` (no measurement this frame) keeps its prediction.

    Parameters
    ----------
    x : (n, k) float
    P : (n, k, k) float
    z : (n, m) float
        Measurements, e.g. detection centres (m).
    H : (m, k) or (n, m, k) float
        Default ``[I 0]`` (X5).
    R : float (times I), (m, m) or (n, m, m) float
        Measurement covariance; default ``0.05² m²·I`` (X5, laser).

    Returns
    -------
    x, P : (n, k), (n, k, k) float64
    """
    xs, Ps = _batch(x, P)
    zs = np.asarray(z, dtype=np.float64)
    missing = np.isnan(zs).any(axis=-1) if zs.ndim == 2 else np.zeros(xs.shape[0], bool)
    any_missing = missing.any()
    if any_missing:
        zs = np.where(missing[:, None], 0.0, zs)
    # innovation(xs, Ps, zs, H, R), inlined: the same products, without checking and converting twice
    Hm = np.asarray(H, dtype=np.float64)
    m = Hm.shape[-2]
    if zs.shape != (xs.shape[0], m):
        raise ValueError(f"z: expected shape ({xs.shape[0]}, {m}), got {zs.shape}")
    Rm = np.asarray(R, dtype=np.float64)
    if Rm.ndim == 0:
        Rm = Rm * _eye(m)
    Ht = Hm.swapaxes(-1, -2)
    y = zs - _apply(Hm, xs)
    S = Hm @ Ps @ Ht + Rm
    PHt = Ps @ Ht  # (n, k, m)
    K = np.linalg.solve(S, PHt.swapaxes(-1, -2)).swapaxes(-1, -2)  # P Hᵀ S⁻¹, S symmetric
    x_new = xs + np.einsum("nij,nj->ni", K, y)
    IKH = _eye(xs.shape[1]) - K @ Hm
    P_new = IKH @ Ps @ IKH.swapaxes(-1, -2) + K @ Rm @ K.swapaxes(-1, -2)
    P_new = 0.5 * (P_new + P_new.swapaxes(-1, -2))
    if any_missing:
        x_new[missing] = xs[missing]
        P_new[missing] = Ps[missing]
    return x_new, P_new


_EYES: dict[int, np.ndarray] = {}


def _eye(n: int) -> np.ndarray:
    """``np.eye(n)``, read-only and cached."""
    e = _EYES.get(n)
    if e is None:
        e = _EYES[n] = np.eye(n)
        e.setflags(write=False)
    return e
