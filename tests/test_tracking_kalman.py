"""Constant-velocity Kalman filter (ALGORITHMS.md X5): hand calculation, steady state, vectorisation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are

from fusiontrack.tracking import kalman as kf


def test_cv_matrices_x5_form() -> None:
    F, Q = kf.cv_matrices(0.5, 2.0)
    np.testing.assert_allclose(F, [[1, 0, 0.5, 0], [0, 1, 0, 0.5], [0, 0, 1, 0], [0, 0, 0, 1]])
    a, b, c = 2.0 * 0.125 / 3, 2.0 * 0.25 / 2, 2.0 * 0.5
    np.testing.assert_allclose(Q, [[a, 0, b, 0], [0, a, 0, b], [b, 0, c, 0], [0, b, 0, c]])


def test_predict_update_hand_calculation() -> None:
    # x = (0, 0, 1, 0), P = I, Δt = 1, q = 0 -> x = (1, 0, 1, 0), P = F Fᵀ = [[2, 1], [1, 1]] per axis.
    # z = (2, 0), R = I: S = 3, K = (2/3, 1/3) per axis -> x = (5/3, 0, 4/3, 0),
    # P = [[2/3, 1/3], [1/3, 2/3]] per axis.
    F, Q = kf.cv_matrices(1.0, 0.0)
    x, P = kf.predict(np.array([[0.0, 0.0, 1.0, 0.0]]), np.eye(4)[None], F, Q)
    np.testing.assert_allclose(x, [[1, 0, 1, 0]])
    np.testing.assert_allclose(P[0], [[2, 0, 1, 0], [0, 2, 0, 1], [1, 0, 1, 0], [0, 1, 0, 1]])
    x, P = kf.update(x, P, np.array([[2.0, 0.0]]), kf.H_POSITION, np.eye(2))
    np.testing.assert_allclose(x, [[5 / 3, 0, 4 / 3, 0]])
    third = 1 / 3
    np.testing.assert_allclose(P[0], [[2 * third, 0, third, 0], [0, 2 * third, 0, third],
                                      [third, 0, 2 * third, 0], [0, third, 0, 2 * third]], atol=1e-15)
    y, S = kf.innovation(x, P, np.array([[2.0, 0.0]]), kf.H_POSITION, np.eye(2))
    np.testing.assert_allclose(y, [[1 / 3, 0]])
    np.testing.assert_allclose(S[0], np.eye(2) * (1 + 2 * third))


def test_steady_state_matches_the_riccati_solution() -> None:
    dt, q, r = 0.04, 1.0, 0.05**2
    F, Q = kf.cv_matrices(dt, q)
    H, R = kf.H_POSITION, r * np.eye(2)
    x, P = np.zeros((2, 4)), np.tile(np.eye(4) * 10.0, (2, 1, 1))
    for _ in range(2000):
        x, P = kf.predict(x, P, F, Q)
        P_prior = P
        x, P = kf.update(x, P, np.zeros((2, 2)), H, R)
    P_inf = solve_discrete_are(F.T, H.T, Q, R)  # the prior covariance of the steady-state filter
    np.testing.assert_allclose(P_prior[0], P_inf, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(P_prior[1], P_inf, rtol=1e-6, atol=1e-12)


def test_vectorised_equals_one_by_one_and_missing_measurements() -> None:
    rng = np.random.default_rng(0)
    n = 5
    x = rng.normal(size=(n, 4))
    A = rng.normal(size=(n, 4, 4))
    P = A @ np.swapaxes(A, 1, 2) + np.eye(4)
    F, Q = kf.cv_matrices(0.1, 0.5)
    z = rng.normal(size=(n, 2))
    z[3] = np.nan
    R = np.tile(np.diag([0.1, 0.2]), (n, 1, 1))
    xp, Pp = kf.predict(x, P, F, Q)
    xu, Pu = kf.update(xp, Pp, z, kf.H_POSITION, R)
    for i in range(n):
        xi, Pi = kf.predict(x[i:i + 1], P[i:i + 1], F, Q)
        np.testing.assert_allclose(xi[0], F @ x[i])
        if i == 3:
            np.testing.assert_array_equal(xu[i], xp[i])
            np.testing.assert_array_equal(Pu[i], Pp[i])
            continue
        S = kf.H_POSITION @ Pi[0] @ kf.H_POSITION.T + R[i]
        K = Pi[0] @ kf.H_POSITION.T @ np.linalg.inv(S)
        np.testing.assert_allclose(xu[i], xi[0] + K @ (z[i] - kf.H_POSITION @ xi[0]))
        np.testing.assert_allclose(Pu[i], (np.eye(4) - K @ kf.H_POSITION) @ Pi[0], atol=1e-10)
    # per-target F works as well as a shared one
    xf, _ = kf.predict(x, P, np.tile(F, (n, 1, 1)), Q)
    np.testing.assert_allclose(xf, xp)


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="dt_s"):
        kf.cv_matrices(-1.0, 1.0)
    with pytest.raises(ValueError, match="z"):
        kf.update(np.zeros((2, 4)), np.tile(np.eye(4), (2, 1, 1)), np.zeros((3, 2)))
