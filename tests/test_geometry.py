"""fusiontrack.geometry: invariants and hand-computed answers (ALGORITHMS.md X6, X7, B2, B11)."""

from __future__ import annotations

import math
import re

import cv2
import numpy as np
import pytest

from fusiontrack import geometry as g
from fusiontrack.errors import CalibrationError, ConfigError
from fusiontrack.types import CameraInfo, LaserScan, Transform

SMALL_DIST = (-0.1, 0.01, 0.001, 0.001)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240607)


def random_quats(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def random_transform(rng: np.random.Generator) -> np.ndarray:
    return g.make_transform(g.quat_to_matrix(random_quats(rng, 1)[0]), rng.uniform(-5, 5, 3))


def elevated_camera(dist=None, yaw_rad: float = 0.0, pitch_deg: float = 60.0, height_m: float = 10.0):
    return g.PinholeCamera.from_pose([1.0, -2.0, height_m], yaw_rad, math.radians(pitch_deg), fx=800.0,
                                     fy=780.0, cx=640.0, cy=470.0, width=1280, height=960, dist=dist)


def visible_floor_points(cam: g.PinholeCamera, rng: np.random.Generator, n: int = 200, margin: float = 20.0):
    """Floor points in front of ``cam`` whose (undistorted) image lies inside the image with a margin."""
    c = cam.position_m
    yaw = math.atan2(cam.cam2world[1, 2], cam.cam2world[0, 2])
    d, lat = rng.uniform(0.5, 25.0, n), rng.uniform(-12.0, 12.0, n)
    pts = np.column_stack([c[0] + d * np.cos(yaw) - lat * np.sin(yaw),
                           c[1] + d * np.sin(yaw) + lat * np.cos(yaw), np.zeros(n)])
    uv = g.project_with_matrix(cam.projection_matrix(), pts)
    inside = (uv[:, 0] > margin) & (uv[:, 0] < cam.width - margin) & (uv[:, 1] > margin) & \
        (uv[:, 1] < cam.height - margin) & cam.in_front(pts)
    assert inside.sum() > 20
    return pts[inside]


# --------------------------------------------------------------------------------------------------
# Rotations, poses, transform tree
# --------------------------------------------------------------------------------------------------


def test_quaternion_matrix_round_trip(rng):
    q = random_quats(rng, 50)
    R = g.quat_to_matrix(q)
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    q_back = g.matrix_to_quat(R)
    np.testing.assert_allclose(np.abs(np.sum(q * q_back, axis=1)), 1.0, atol=1e-12)  # same up to sign
    np.testing.assert_allclose(g.quat_to_matrix(q_back), R, atol=1e-12)
    assert np.all(q_back[:, 3] >= 0)


def test_quaternion_known_answer():
    s = math.sqrt(0.5)
    np.testing.assert_allclose(g.quat_to_matrix([0, 0, s, s]), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(g.yaw_to_matrix(math.pi / 2), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)


def test_rpy_conventions():
    yaw, pitch = 0.7, 0.4
    np.testing.assert_allclose(g.rpy_to_matrix(0, 0, yaw), g.yaw_to_matrix(yaw), atol=1e-15)
    # positive pitch turns the nose (x forward) down
    nose = g.rpy_to_matrix(0, pitch, 0) @ [1, 0, 0]
    np.testing.assert_allclose(nose, [math.cos(pitch), 0, -math.sin(pitch)], atol=1e-15)
    R = g.rpy_to_matrix(0.1, pitch, yaw)
    composed = g.yaw_to_matrix(yaw) @ g.rpy_to_matrix(0, pitch, 0) @ g.rpy_to_matrix(0.1, 0, 0)
    np.testing.assert_allclose(R, composed, atol=1e-15)


def test_wrap_angle(rng):
    np.testing.assert_allclose(g.wrap_angle([0.0, math.pi, -math.pi, 1.5 * math.pi, -2.5 * math.pi, 7.0]),
                               [0.0, math.pi, math.pi, -0.5 * math.pi, -0.5 * math.pi, 7.0 - 2 * math.pi],
                               atol=1e-12)
    a = rng.uniform(-50, 50, 1000)
    w = g.wrap_angle(a)
    assert np.all((w > -math.pi) & (w <= math.pi))
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)


def test_make_and_invert_transform(rng):
    T = random_transform(rng)
    np.testing.assert_allclose(T @ g.invert_transform(T), np.eye(4), atol=1e-12)
    P = g.pose2d_to_matrix(1.0, -2.0, 2.5)
    np.testing.assert_allclose(g.invert_transform(P) @ P, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(g.apply_pose2d(P, [[0.0, 0.0], [1.0, 0.0]]),
                               [[1.0, -2.0], [1.0 + math.cos(2.5), -2.0 + math.sin(2.5)]], atol=1e-12)


def build_tree(rng):
    edges = {("world", "base"): random_transform(rng), ("base", "laser"): random_transform(rng),
             ("laser", "scanner_head"): random_transform(rng), ("world", "camera"): random_transform(rng)}
    tree = g.TransformTree()
    for (parent, child), T in edges.items():
        tree.add(parent, child, T)
    return tree, edges


def test_tree_chains_and_inverts(rng):
    tree, e = build_tree(rng)
    assert set(tree.frames) == {"world", "base", "laser", "scanner_head", "camera"}
    head2camera = tree.get("scanner_head", "camera")
    np.testing.assert_allclose(head2camera @ tree.get("camera", "scanner_head"), np.eye(4), atol=1e-10)
    expected = (g.invert_transform(e["world", "camera"]) @ e["world", "base"] @ e["base", "laser"]
                @ e["laser", "scanner_head"])
    np.testing.assert_allclose(head2camera, expected, atol=1e-10)
    np.testing.assert_allclose(tree.get("laser", "world"), e["world", "base"] @ e["base", "laser"], atol=1e-9)
    np.testing.assert_allclose(tree.get("base", "base"), np.eye(4))
    pts = rng.normal(size=(10, 3))
    in_world = g.transform_points(tree.get("laser", "world"), pts)
    via_world = g.transform_points(tree.get("world", "camera"), in_world)
    np.testing.assert_allclose(g.transform_points(tree.get("laser", "camera"), pts), via_world, atol=1e-10)


def test_tree_errors(rng):
    tree, _ = build_tree(rng)
    with pytest.raises(ConfigError, match="lidar_rear"):
        tree.get("lidar_rear", "world")
    tree.add("map", "odom", np.eye(4))
    assert not tree.has_path("odom", "world")
    assert tree.has_path("scanner_head", "camera")
    with pytest.raises(ConfigError, match=r"'odom'.*'world'"):
        tree.get("odom", "world")
    with pytest.raises(ConfigError, match="loop"):
        tree.add("camera", "laser", np.eye(4))


def test_tree_add_record():
    s = math.sqrt(0.5)
    tf = Transform(t_ns=0, sensor="tf_static", parent_frame="base", child_frame="laser",
                   translation_m=[1.0, 2.0, 0.3], rotation_xyzw=[0, 0, s, s], static=True)
    tree = g.TransformTree()
    tree.add_record(tf)
    out = g.transform_points(tree.get("laser", "base"), [[1.0, 0.0, 0.0]])
    np.testing.assert_allclose(out, [[1.0, 3.0, 0.3]], atol=1e-12)


@pytest.mark.parametrize(("translation", "rotation", "named"), [
    ([1.0, 2.0, 0.3], [0, 0, 0.5, float("nan")], "its rotation x, y, z, w (0, 0, 0.5, nan) is not a finite non-zero"),
    ([1.0, 2.0, 0.3], [0, 0, 0, 0], "its rotation x, y, z, w (0, 0, 0, 0) is not a finite non-zero quaternion"),
    ([float("nan"), 2.0, 0.3], [0, 0, 0, 1], "its translation (nan, 2, 0.3) is not finite"),
])
def test_tree_add_record_refuses_a_transform_that_cannot_be_used(translation, rotation, named):
    """A NaN (or zero) quaternion or a NaN translation, as in a damaged /tf_static: a ConfigError naming the frames
    and what is wrong (as add's other refusals, which callers reading a recording warn about), not scipy's
    ValueError; the edge is not added."""
    tf = Transform(t_ns=0, sensor="/tf_static", parent_frame="world", child_frame="laser",
                   translation_m=translation, rotation_xyzw=rotation, static=True)
    tree = g.TransformTree()
    with pytest.raises(ConfigError, match=re.escape(f"transform 'laser' -> 'world': {named}")):
        tree.add_record(tf)
    assert not tree.has_path("laser", "world")

def test_transform_points_floor_points_with_4x4():
    T = g.make_transform(g.yaw_to_matrix(0.5), [1.0, 2.0, 0.7])
    pts = np.array([[1.0, 0.0], [np.nan, np.nan]])
    out = g.transform_points(T, pts)
    np.testing.assert_allclose(out, g.apply_pose2d(g.pose2d_to_matrix(1.0, 2.0, 0.5), pts), atol=1e-12)
    with pytest.raises(ValueError, match="transform_points"):
        g.transform_points(np.eye(3), np.zeros((2, 3)))


# --------------------------------------------------------------------------------------------------
# Laser
# --------------------------------------------------------------------------------------------------


ONE_DEG = math.radians(1.0)


def make_scan(ranges, angle_min=-math.pi / 3, inc=ONE_DEG, rmin=0.02, rmax=30.0) -> LaserScan:
    return LaserScan(t_ns=0, sensor="laser_front", frame_id="laser_front", angle_min_rad=angle_min,
                     angle_increment_rad=inc, range_min_m=rmin, range_max_m=rmax, ranges_m=ranges)


def test_scan_of_a_wall():
    angles = -math.pi / 3 + np.arange(121) * math.radians(1.0)
    pts = g.scan_to_points(make_scan(2.0 / np.cos(angles)))
    np.testing.assert_allclose(pts[:, 0], 2.0, atol=1e-6)
    np.testing.assert_allclose(pts[:, 1], 2.0 * np.tan(angles), atol=1e-6)


def test_invalid_beams_are_nan_rows():
    pts = g.scan_to_points(make_scan([1.0, 0.0, np.inf, np.nan, 30.0, 45.0, 0.01, 5.0]))
    bad = np.isnan(pts)
    assert np.array_equal(bad[:, 0], bad[:, 1])
    assert bad[:, 0].tolist() == [False, True, True, True, True, True, True, False]
    np.testing.assert_allclose(pts[0], [math.cos(-math.pi / 3), math.sin(-math.pi / 3)], atol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(pts[7]), 5.0, atol=1e-6)


def test_scan_to_world_rotated_translated_laser():
    # beams at 0 and 90 degrees; laser at (1, 2) facing +y
    scan = make_scan([3.0, 1.0, 0.0], angle_min=0.0, inc=math.pi / 2)
    expected = [[1.0, 5.0], [0.0, 2.0], [np.nan, np.nan]]
    np.testing.assert_allclose(g.scan_to_world(scan, g.pose2d_to_matrix(1.0, 2.0, math.pi / 2)), expected,
                               atol=1e-12)
    laser2world = g.make_transform(g.yaw_to_matrix(math.pi / 2), [1.0, 2.0, 0.2])
    np.testing.assert_allclose(g.scan_to_world(scan, laser2world), expected, atol=1e-12)


def test_two_lasers_agree_after_registration():
    """ALGORITHMS.md B2: two lasers see the same 5 poles; after X7 registration they agree < 1 cm."""
    poles = np.array([[2.0, 1.0], [4.0, -1.5], [5.5, 3.0], [3.0, 4.5], [7.0, 0.5]])
    poses = {"laser_a": (0.0, 0.0, 0.3), "laser_b": (8.0, 5.0, -2.6)}
    seen = {}
    for name, (x, y, th) in poses.items():
        local = g.apply_pose2d(g.invert_transform(g.pose2d_to_matrix(x, y, th)), poles)
        ranges, bearings = np.hypot(local[:, 0], local[:, 1]), np.arctan2(local[:, 1], local[:, 0])
        seen[name] = g.ranges_to_points(ranges, bearings)
        # the B2 formula P = (x_l + r cos(th_l + th_i), y_l + r sin(th_l + th_i))
        np.testing.assert_allclose(np.column_stack([x + ranges * np.cos(th + bearings),
                                                    y + ranges * np.sin(th + bearings)]), poles, atol=1e-12)
    R, t = g.fit_rigid_2d(seen["laser_b"], seen["laser_a"])  # laser_b -> laser_a from control points
    a2world = g.pose2d_to_matrix(*poses["laser_a"])
    b2world = a2world @ g.make_transform(R, t)
    world_a = g.apply_pose2d(a2world, seen["laser_a"])
    world_b = g.apply_pose2d(b2world, seen["laser_b"])
    assert np.max(np.linalg.norm(world_a - world_b, axis=1)) < 0.01
    np.testing.assert_allclose(b2world, g.pose2d_to_matrix(*poses["laser_b"]), atol=1e-9)


# --------------------------------------------------------------------------------------------------
# Pinhole camera
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("dist", [None, SMALL_DIST, (*SMALL_DIST, 0.002)])
def test_project_then_backproject_floor(rng, dist):
    cam = elevated_camera(dist, yaw_rad=0.4)
    floor = visible_floor_points(cam, rng)
    back = cam.backproject_to_floor(cam.project(floor))
    assert np.max(np.linalg.norm(back - floor, axis=1)) < 1e-6


RATIONAL_DIST = (*SMALL_DIST, 0.002, 0.01, 1e-3, 5e-4)


@pytest.mark.parametrize("dist", [(), SMALL_DIST, (*SMALL_DIST, 0.002), RATIONAL_DIST])
def test_project_agrees_with_opencv(rng, dist):
    cam = elevated_camera(dist, yaw_rad=-1.1)
    pts = visible_floor_points(cam, rng)
    pts[:, 2] = rng.uniform(0.0, 2.0, len(pts))
    R = cam.world2cam[:3, :3]
    rvec, _ = cv2.Rodrigues(R)
    expected, _ = cv2.projectPoints(pts, rvec, cam.world2cam[:3, 3], cam.K, np.asarray(dist, float))
    np.testing.assert_allclose(cam.project(pts), expected.reshape(-1, 2), atol=1e-8)


def test_points_behind_camera_are_nan(rng):
    cam = elevated_camera(SMALL_DIST, yaw_rad=0.9)
    pts = rng.uniform(-30, 30, (500, 3))
    yaw, pitch = 0.9, math.radians(60)
    forward = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), -math.sin(pitch)])
    depth = (pts - cam.position_m) @ forward
    assert (depth < 0).any()
    assert (depth > 0).any()
    uv = cam.project(pts)
    assert np.array_equal(np.isnan(uv[:, 0]), depth <= 0)
    assert np.array_equal(cam.in_front(pts), depth > 0)
    assert not cam.in_front([[np.nan, 0.0, 0.0]])[0]


def test_undistort_inverts_distortion(rng):
    cam = elevated_camera(SMALL_DIST)
    ideal = elevated_camera(None)
    pts = visible_floor_points(cam, rng)
    np.testing.assert_allclose(cam.undistort_pixels(cam.project(pts)), ideal.project(pts), atol=1e-6)
    assert np.isnan(cam.undistort_pixels([[np.nan, 1.0]])).all()


def test_backproject_above_horizon_is_nan():
    cam = elevated_camera(None, pitch_deg=0.0, height_m=2.0)  # level camera: horizon at v = cy
    out = cam.backproject_to_floor([[640.0, 370.0], [640.0, 470.0], [640.0, 570.0]])
    assert np.isnan(out[:2]).all()
    # 100 px below the horizon: ray drops 100/fy per metre forward -> floor at 2 * 780 / 100 m ahead
    np.testing.assert_allclose(out[2], [1.0 + 2.0 * 780.0 / 100.0, -2.0, 0.0], atol=1e-9)


def test_projection_matrix_matches_undistorted_projection(rng):
    cam = elevated_camera(None, yaw_rad=2.0)
    pts = visible_floor_points(cam, rng)
    pts[:, 2] = rng.uniform(0, 3, len(pts))
    uv = g.project_with_matrix(cam.projection_matrix(), pts)
    np.testing.assert_allclose(uv, cam.project(pts), atol=1e-8)


def test_looking_at_and_from_pose_agree():
    yaw, pitch = 0.8, math.radians(35)
    pos = np.array([3.0, 1.0, 6.0])
    forward = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), -math.sin(pitch)])
    a = g.PinholeCamera.from_pose(pos, yaw, pitch, fx=500, fy=500, width=640, height=480)
    b = g.PinholeCamera.looking_at(pos, pos + 4.0 * forward, fx=500, fy=500, width=640, height=480)
    np.testing.assert_allclose(a.world2cam, b.world2cam, atol=1e-12)
    np.testing.assert_allclose(b.project([pos + 4.0 * forward]), [[320.0, 240.0]], atol=1e-9)
    np.testing.assert_allclose(a.position_m, pos, atol=1e-12)
    with pytest.raises(ConfigError):
        g.PinholeCamera.looking_at(pos, pos - [0, 0, 1], fx=500, fy=500, width=640, height=480)


def test_from_camera_info():
    K = np.array([[500.0, 0, 320], [0, 510.0, 240], [0, 0, 1]])
    info = CameraInfo(t_ns=0, sensor="camera_0", frame_id="camera_0", width=640, height=480, K=K,
                      D=[-0.1, 0.01, 0.001, 0.001, 0.0])
    world2cam = g.PinholeCamera.from_pose([0, 0, 3], 0.2, 0.5, fx=1, fy=1, width=2, height=2).world2cam
    cam = g.PinholeCamera.from_camera_info(info, world2cam)
    np.testing.assert_allclose(cam.K, K)
    assert (cam.width, cam.height) == (640, 480)
    fisheye = CameraInfo(t_ns=0, sensor="camera_1", frame_id="c", width=640, height=480, K=K,
                         D=[0.1, 0.0, 0.0, 0.0], distortion_model="equidistant")
    with pytest.raises(ConfigError, match="camera_1"):
        g.PinholeCamera.from_camera_info(fisheye, world2cam)
    with pytest.raises(ConfigError, match="world2cam"):
        g.PinholeCamera(K, (), np.diag([1.0, 1.0, -1.0, 1.0]), 640, 480)


def test_with_yaw_offset(rng):
    cam = elevated_camera(SMALL_DIST, yaw_rad=0.3)
    delta = math.radians(3.0)
    turned = cam.with_yaw_offset(delta)
    np.testing.assert_allclose(turned.position_m, cam.position_m, atol=1e-12)
    pts = visible_floor_points(cam, rng)
    # rotating the scene with the camera about the vertical through its centre leaves the image unchanged
    c = cam.position_m
    rotated = (pts - c) @ g.yaw_to_matrix(delta).T + c
    np.testing.assert_allclose(turned.project(rotated), cam.project(pts), atol=1e-8)
    # turning the camera left (CCW seen from above) moves the scene right in the image
    ideal, ideal_turned = elevated_camera(None, 0.3), elevated_camera(None, 0.3).with_yaw_offset(delta)
    assert np.all(ideal_turned.project(pts)[:, 0] > ideal.project(pts)[:, 0])


# --------------------------------------------------------------------------------------------------
# Person box (ALGORITHMS.md B11)
# --------------------------------------------------------------------------------------------------


def test_person_box_level_camera_by_hand():
    """Camera 3 m high looking along +y with no tilt: world x is image right, depth is world y."""
    fx, fy, cx, cy, hc = 700.0, 650.0, 320.0, 240.0, 3.0
    cam = g.PinholeCamera.from_pose([0, 0, hc], math.pi / 2, 0.0, fx=fx, fy=fy, cx=cx, cy=cy,
                                    width=640, height=480)
    feet = np.array([[0.5, 8.0], [-1.0, 5.0], [2.0, 12.0]])
    heights = np.array([1.7, 1.5, 1.9])
    X, Y = feet[:, 0], feet[:, 1]
    u = cx + fx * X / Y
    v_bottom, v_top = cy + fy * hc / Y, cy + fy * (hc - heights) / Y
    half_w = 0.5 * 0.4 * fy * heights / Y
    expected = np.column_stack([u - half_w, v_top, u + half_w, v_bottom])
    boxes = cam.person_box(feet, heights, width_ratio=0.4)
    np.testing.assert_allclose(boxes, expected, atol=1e-9)
    bottom_centre = np.column_stack([(boxes[:, 0] + boxes[:, 2]) / 2, boxes[:, 3]])
    np.testing.assert_allclose(cam.backproject_to_floor(bottom_centre)[:, :2], feet, atol=1e-9)


@pytest.mark.parametrize("yaw", [0.0, 1.2])
def test_person_box_tilted_camera_by_hand(yaw):
    """ALGORITHMS.md B11: camera 10 m high, 60° tilt; boxes from the textbook pinhole formula."""
    fx, fy, cx, cy, hc, tilt = 800.0, 780.0, 640.0, 470.0, 10.0, math.radians(60)
    cam = g.PinholeCamera.from_pose([0, 0, hc], yaw, tilt, fx=fx, fy=fy, cx=cx, cy=cy, width=1280, height=960)
    ahead = np.array([4.0, 6.0, 9.0, 5.0])  # metres along the viewing direction
    left = np.array([0.0, 1.5, -2.0, 0.0])  # metres to the left of it
    c, s = math.cos(tilt), math.sin(tilt)

    def pixel(z):  # optical coordinates of (ahead, left, z) relative to the camera's foot point
        xc, yc, zc = -left, -ahead * s + (hc - z) * c, ahead * c + (hc - z) * s
        return cx + fx * xc / zc, cy + fy * yc / zc

    (ub, vb), (ut, vt) = pixel(0.0), pixel(1.7)
    hb = np.abs(vb - vt)
    uc, vc = (ub + ut) / 2, (vb + vt) / 2
    expected = np.column_stack([uc - 0.2 * hb, vc - hb / 2, uc + 0.2 * hb, vc + hb / 2])
    feet = np.column_stack([ahead * math.cos(yaw) - left * math.sin(yaw),
                            ahead * math.sin(yaw) + left * math.cos(yaw)])
    boxes = cam.person_box(feet)
    np.testing.assert_allclose(boxes, expected, atol=1e-9)
    # on the camera's vertical centre plane the box bottom-centre is exactly the feet's image
    on_axis = left == 0
    bottom_centre = np.column_stack([(boxes[:, 0] + boxes[:, 2]) / 2, boxes[:, 3]])[on_axis]
    np.testing.assert_allclose(cam.backproject_to_floor(bottom_centre)[:, :2], feet[on_axis], atol=1e-9)


def test_person_box_behind_camera_is_nan():
    cam = elevated_camera(None)
    boxes = cam.person_box([[-30.0, -2.0], [6.0, -2.0]], [1.7, 1.7])
    assert np.isnan(boxes[0]).all()
    assert np.isfinite(boxes[1]).all()


# --------------------------------------------------------------------------------------------------
# DLT (ALGORITHMS.md X6, B11)
# --------------------------------------------------------------------------------------------------

H_TRUE = np.array([[1.2, 0.1, 30.0], [-0.05, 0.9, 12.0], [2e-4, -1e-4, 1.0]])


def test_homography_noise_free(rng):
    src = rng.uniform(0, 500, (20, 2))
    dst = g.apply_homography(H_TRUE, src)
    H = g.fit_homography(src, dst)
    np.testing.assert_allclose(H, H_TRUE, rtol=1e-8, atol=1e-10)
    test = rng.uniform(0, 500, (100, 2))
    assert np.max(np.abs(g.apply_homography(H, test) - g.apply_homography(H_TRUE, test))) < 1e-6
    H_cv, _ = cv2.findHomography(src, dst, 0)  # OpenCV's own fit is only good to ~1e-5 px here
    np.testing.assert_allclose(g.apply_homography(H, test), g.apply_homography(H_cv, test), atol=1e-3)
    four = g.fit_homography(src[:4], dst[:4], refine=True)
    assert np.max(np.abs(g.apply_homography(four, test) - g.apply_homography(H_TRUE, test))) < 1e-6


def camera_points(cam: g.PinholeCamera, rng: np.random.Generator, n: int) -> np.ndarray:
    pts = visible_floor_points(cam, rng, n=4 * n)[:n].copy()
    pts[:, 2] = rng.uniform(0.0, 3.0, len(pts))
    assert len(pts) == n
    return pts


def test_projection_matrix_noise_free(rng):
    cam = elevated_camera(None, yaw_rad=0.7, pitch_deg=40)
    P_true = cam.projection_matrix()
    world = camera_points(cam, rng, 20)
    P = g.fit_projection_matrix(world, g.project_with_matrix(P_true, world))
    test = camera_points(cam, rng, 50)
    assert np.max(np.abs(g.project_with_matrix(P, test) - cam.project(test))) < 1e-6
    # scaled so the third coordinate is the depth in front of the camera
    depth = np.column_stack([test, np.ones(len(test))]) @ P[2]
    np.testing.assert_allclose(depth, g.transform_points(cam.world2cam, test)[:, 2], rtol=1e-6)


@pytest.mark.parametrize("refine", [False, True])
def test_dlt_with_one_pixel_noise(rng, refine):
    src = rng.uniform(0, 500, (50, 2))
    dst = g.apply_homography(H_TRUE, src) + rng.normal(0, 1.0, (50, 2))
    H = g.fit_homography(src, dst, refine=refine)
    rms_h = g.reprojection_rms(H, src, dst)
    cam = elevated_camera(None, yaw_rad=0.2, pitch_deg=40)
    world = camera_points(cam, rng, 50)
    pix = cam.project(world) + rng.normal(0, 1.0, (50, 2))
    P = g.fit_projection_matrix(world, pix, refine=refine)
    rms_p = g.reprojection_rms(P, world, pix)
    # Hartley & Zisserman: expected residual sigma * sqrt(1 - d / 2n) = 0.96 (H) and 0.94 (P)
    assert 0.6 < rms_h < 1.4
    assert 0.6 < rms_p < 1.4
    if refine:  # LM never does worse than the algebraic solution it starts from
        assert rms_h <= g.reprojection_rms(g.fit_homography(src, dst), src, dst) + 1e-9
        assert rms_p <= g.reprojection_rms(g.fit_projection_matrix(world, pix), world, pix) + 1e-9


def test_b11_box_calibration_reproduces_projections(rng):
    """ALGORITHMS.md B11: camera 10 m high, 60° tilt, P from the 8 corners of a box (two heights)."""
    cam = elevated_camera(None, yaw_rad=0.5)
    c, yaw = cam.position_m, 0.5
    centre = c[:2] + 6.0 * np.array([math.cos(yaw), math.sin(yaw)])
    dx, dy, dz = np.meshgrid([-0.6, 0.6], [-0.4, 0.4], [0.0, 0.8], indexing="ij")
    corners = np.column_stack([centre[0] + dx.ravel(), centre[1] + dy.ravel(), dz.ravel()])
    P = g.fit_projection_matrix(corners, cam.project(corners), refine=True)
    assert np.max(np.abs(g.project_with_matrix(P, corners) - cam.project(corners))) < 1e-6
    test = camera_points(cam, rng, 30)
    assert np.max(np.abs(g.project_with_matrix(P, test) - cam.project(test))) < 1e-6
    feet = test[:, :2]
    np.testing.assert_allclose(g.person_box_from_matrix(P, feet), cam.person_box(feet), atol=1e-6)


def test_dlt_errors(rng):
    pts = rng.uniform(0, 10, (10, 2))
    with pytest.raises(CalibrationError, match=r"3 point pairs given, at least 4"):
        g.fit_homography(pts[:3], pts[:3])
    line = np.column_stack([np.arange(6.0), 2 * np.arange(6.0) + 1])
    with pytest.raises(CalibrationError, match="collinear"):
        g.fit_homography(line, pts[:6])
    three_on_a_line = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [0.0, 1.0]])
    with pytest.raises(CalibrationError, match="degenerate"):  # consistent data: H not unique
        g.fit_homography(three_on_a_line, g.apply_homography(H_TRUE, three_on_a_line))
    with pytest.raises(CalibrationError, match="degenerate"):  # inconsistent data: only a singular fit
        g.fit_homography(three_on_a_line, pts[:4])
    world = rng.uniform(0, 10, (10, 3))
    with pytest.raises(CalibrationError, match=r"5 point pairs given, at least 6"):
        g.fit_projection_matrix(world[:5], pts[:5])
    flat = world.copy()
    flat[:, 2] = 0.0
    with pytest.raises(CalibrationError, match="coplanar"):
        g.fit_projection_matrix(flat, pts)
    bad = pts.copy()
    bad[2, 0] = np.nan
    with pytest.raises(CalibrationError, match="NaN"):
        g.fit_homography(pts, bad)


# --------------------------------------------------------------------------------------------------
# Rigid 2-D registration (ALGORITHMS.md X7)
# --------------------------------------------------------------------------------------------------


def test_rigid_2d_exact_recovery(rng):
    a = rng.uniform(-5, 5, (12, 2))
    th = math.radians(30)
    R_true = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    b = a @ R_true.T + [2.0, -1.0]
    R, t = g.fit_rigid_2d(a, b)
    np.testing.assert_allclose(R, R_true, atol=1e-12)
    np.testing.assert_allclose(t, [2.0, -1.0], atol=1e-12)
    R2, t2 = g.fit_rigid_2d(a[:2], b[:2])  # two points are enough
    np.testing.assert_allclose(R2, R_true, atol=1e-12)
    np.testing.assert_allclose(t2, [2.0, -1.0], atol=1e-12)


def test_rigid_2d_reflection_still_a_rotation(rng):
    a = rng.uniform(-5, 5, (8, 2))
    b = a * [-1.0, 1.0]  # a mirror image: the best orthogonal map would be a reflection
    R, t = g.fit_rigid_2d(a, b)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(R @ R.T, np.eye(2), atol=1e-12)
    assert np.all(np.isfinite(t))


def test_rigid_2d_errors():
    with pytest.raises(CalibrationError, match="1 point pairs given, at least 2"):
        g.fit_rigid_2d([[0.0, 0.0]], [[1.0, 1.0]])
    with pytest.raises(CalibrationError, match="coincide"):
        g.fit_rigid_2d([[1.0, 1.0], [1.0, 1.0]], [[0.0, 0.0], [1.0, 0.0]])
