"""C9: the projective matrix from the dead-reckoned floor position to the image (ALGORITHMS.md C9, X6).

The known answer is a real camera: a pinhole looking down at the floor maps the plane of a walker's torso
(0.9 m above the floor) into the image by a homography, the columns ``(0, 1, 3)`` of ``P = K [R | t]`` with
``0.9 P[:, 2]`` added to the last.
"""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.errors import CalibrationError
from fusiontrack.geometry import PinholeCamera, apply_homography
from fusiontrack.inertial.dead_reckoning import PdrResult
from fusiontrack.inertial.projection import (
    InertialProjection,
    ProjectionParams,
    align_track_pairs,
    fit_inertial_projection,
    projection_from_pdr,
)

CAM = PinholeCamera.from_pose([0.0, -1.0, 4.0], np.deg2rad(80), np.deg2rad(35), fx=800, fy=800, width=1280,
                              height=720)
P = CAM.projection_matrix()
H_TRUE = P[:, [0, 1, 3]].copy()
H_TRUE[:, 2] += 0.9 * P[:, 2]  # (X, Y, 0.9, 1) -> (X, Y, 1)
H_TRUE /= H_TRUE[2, 2]


def _floor_points(rng: np.random.Generator, n: int) -> np.ndarray:
    """Floor positions in the camera's view, m."""
    pts = rng.uniform([-3.0, 3.0], [3.0, 12.0], (4 * n, 2))
    uv = apply_homography(H_TRUE, pts)
    ok = (uv[:, 0] > 20) & (uv[:, 0] < 1260) & (uv[:, 1] > 20) & (uv[:, 1] < 700)
    assert ok.sum() >= n
    return pts[ok][:n]


def test_camera_homography_is_the_known_answer():
    rng = np.random.default_rng(0)
    X = _floor_points(rng, 20)
    np.testing.assert_allclose(apply_homography(H_TRUE, X), CAM.project(np.column_stack([X, np.full(20, 0.9)])),
                               atol=1e-9)


def test_noise_free_recovery_is_exact():
    rng = np.random.default_rng(1)
    X = _floor_points(rng, 12)
    fit = fit_inertial_projection(X, apply_homography(H_TRUE, X), rng=0)
    assert fit.inliers.all()
    assert fit.rms_px < 1e-6
    np.testing.assert_allclose(fit.floor2image, H_TRUE, rtol=1e-7, atol=1e-9)


def test_noisy_pairs_held_out_error():
    # C9 test: 40 pairs with σ = 2 px image noise; reprojection RMSE on held-out points < 3 px
    rng = np.random.default_rng(2)
    X = _floor_points(rng, 140)
    x = apply_homography(H_TRUE, X)
    noisy = x + rng.normal(0, 2.0, x.shape)
    fit = fit_inertial_projection(X[:40], noisy[:40], rng=0)
    held_out = np.sqrt(np.mean(np.sum((fit.project(X[40:]) - x[40:]) ** 2, axis=1)))  # vs the true positions
    assert held_out < 3.0
    # Σ of C11 is the residual covariance: about σ² = 4 px² per axis (fewer dof than points: a bit less)
    assert np.trace(fit.residual_cov_px2) / 2 == pytest.approx(4.0, rel=0.5)
    assert fit.rms_px == pytest.approx(2.0, rel=0.35)


def test_ransac_drops_visual_glitches():
    rng = np.random.default_rng(3)
    X = _floor_points(rng, 60)
    x = apply_homography(H_TRUE, X) + rng.normal(0, 1.5, (60, 2))
    bad = rng.choice(60, 12, replace=False)  # 20 % of the visual positions jumped onto something else
    x[bad] += rng.uniform(40, 150, (12, 2)) * rng.choice([-1, 1], (12, 2))
    fit = fit_inertial_projection(X, x, rng=0)
    assert not fit.inliers[bad].any()
    assert fit.n_inliers == 48
    assert np.sqrt(np.mean((fit.project(X) - apply_homography(H_TRUE, X)) ** 2)) < 2.0
    plain = fit_inertial_projection(X, x, ProjectionParams(ransac_threshold_px=np.inf, min_inlier_fraction=0.1))
    assert np.sqrt(np.mean((plain.project(X) - apply_homography(H_TRUE, X)) ** 2)) > 5.0  # least squares alone


def test_jacobian_and_image_covariance():
    fit = InertialProjection(H_TRUE, np.eye(2) * 4.0, 2.0, np.ones(4, bool))
    X = np.array([[0.5, 6.0], [-1.0, 9.0]])
    J = fit.jacobian(X)
    h = 1e-6
    for i in range(2):
        num = (fit.project(X + h * np.eye(2)[i]) - fit.project(X - h * np.eye(2)[i])) / (2 * h)
        np.testing.assert_allclose(J[:, :, i], num, rtol=1e-6)
    cov = fit.image_cov_px2(X[0], 0.1**2)
    np.testing.assert_allclose(cov, np.eye(2) * 4 + 0.01 * J[0] @ J[0].T)
    np.testing.assert_allclose(fit.image_cov_px2(X[0], 0.0), np.eye(2) * 4)
    with pytest.raises(ValueError, match="floor_cov_m2"):
        fit.image_cov_px2(X[0], -1.0)


def _pdr(step_t_ns: np.ndarray, positions: np.ndarray) -> PdrResult:
    n = len(step_t_ns)
    return PdrResult(step_t_ns=step_t_ns, step_duration_s=np.full(n, 0.5), step_length_m=np.full(n, 0.6),
                     heading_rad=np.zeros(n), position_m=positions, new_walk=np.r_[True, np.zeros(n - 1, bool)],
                     start_m=positions[0] - [0.0, 0.0], heading0_rad=0.0, yaw_t_ns=step_t_ns, yaw_rad=np.zeros(n),
                     has_gyro=True, calibration=None, step_model=None)


def test_pairs_are_aligned_in_time_and_fitted_from_a_pdr_track():
    # a walk on a circle, one step every 0.5 s; video at 15 Hz sees the torso; the trajectory is linear between
    # steps, so visual stamps between steps pair with interpolated positions
    t_step = (np.arange(1, 41) * 0.5 * 1e9).astype(np.int64)
    ang = np.arange(1, 41) * 0.5 * 2 * np.pi / 20.0
    pos = np.column_stack([np.cos(ang), 7.0 + np.sin(ang)]) * [2.0, 1.0]
    pdr = _pdr(t_step, pos)
    kt, kp = pdr.knots()
    t_vis = (np.arange(0, 20.5, 1 / 15) * 1e9).astype(np.int64)
    truth_floor = pdr.position_at(t_vis)
    vis = apply_homography(H_TRUE, truth_floor)
    vis[5] = np.nan  # a frame without a trusted visual position
    t, floor, _image = align_track_pairs(t_vis, vis, kt, kp)
    inside = (t_vis >= kt[0]) & (t_vis <= kt[-1]) & np.all(np.isfinite(vis), axis=1)
    np.testing.assert_array_equal(t, t_vis[inside])
    np.testing.assert_allclose(floor, truth_floor[inside], atol=1e-9)
    fit = projection_from_pdr(pdr, t_vis, vis, rng=0)
    assert fit.rms_px < 1e-6
    np.testing.assert_allclose(fit.floor2image, H_TRUE, rtol=1e-6, atol=1e-8)


def test_bad_input():
    rng = np.random.default_rng(4)
    X = _floor_points(rng, 10)
    x = apply_homography(H_TRUE, X)
    with pytest.raises(ValueError, match="floor_xy_m"):
        fit_inertial_projection(X[:3], x[:3])
    with pytest.raises(ValueError, match="image_px"):
        fit_inertial_projection(X, x[:9])
    with pytest.raises(ValueError, match="NaN"):
        fit_inertial_projection(np.vstack([X, [[np.nan, 1.0]]]), np.vstack([x, [[1.0, 1.0]]]))
    with pytest.raises(ValueError, match="ransac_threshold_px"):
        ProjectionParams(ransac_threshold_px=0.0)
    with pytest.raises(ValueError, match="ransac_iterations"):
        ProjectionParams(ransac_iterations=0)
    with pytest.raises(ValueError, match="visual_t_ns"):
        align_track_pairs(np.arange(3), np.zeros((4, 2)), np.arange(5), np.zeros((5, 2)))
    # a straight walk (collinear floor positions) determines no homography
    line = np.column_stack([np.linspace(-2, 2, 30), np.full(30, 6.0)])
    with pytest.raises(CalibrationError):
        fit_inertial_projection(line, apply_homography(H_TRUE, line), rng=0)
