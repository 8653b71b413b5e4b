"""Camera extrinsics from control points (ALGORITHMS.md B11, X6) and writing poses into the pipeline file."""

from __future__ import annotations

import math
import tomllib

import cv2
import numpy as np
import pytest
from scipy.stats import chi2

from fusiontrack.calibration import (
    calibrate_from_points,
    cam2world_from_camera_pose,
    camera_pose_from_cam2world,
    pose_covariance,
    read_control_points,
    solve_pnp,
    update_pipeline_pose,
    write_pose_to_pipeline,
)
from fusiontrack.config import Pose, load_config
from fusiontrack.errors import CalibrationError, ConfigError, RecordingError
from fusiontrack.geometry import PinholeCamera, make_transform, rpy_to_matrix

K = np.array([[420.0, 0.0, 322.0], [0.0, 418.0, 241.0], [0.0, 0.0, 1.0]])
DIST = np.array([-0.12, 0.03, 0.001, -0.0005, 0.0])
LASER2WORLD = make_transform(rpy_to_matrix(0.0, 0.0, math.radians(37.0)), [-9.6, -7.1, 0.2])


def box_corners(centre_xy: tuple[float, float], size: tuple[float, float, float], yaw_rad: float,
                z0: float = -0.2) -> np.ndarray:
    """The 8 corners (8, 3) of a box standing on the floor (laser frame: the floor is 0.2 m below the laser)."""
    (cx, cy), (lx, ly, h) = centre_xy, size
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    xy = np.array([[sx * lx / 2, sy * ly / 2] for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]) @ \
        np.array([[c, s], [-s, c]]) + [cx, cy]
    return np.vstack([np.column_stack([xy, np.full(4, z)]) for z in (z0, z0 + h)])


@pytest.fixture
def scene() -> dict:
    """Two boxes seen by a laser and by an elevated camera (seed 001's "control points in a box")."""
    cam = PinholeCamera.from_pose([0.0, -7.4, 7.0], math.radians(88.0), math.radians(40.0), math.radians(1.5),
                                  fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], width=640, height=480, dist=DIST)
    pts = np.vstack([box_corners((9.0, 3.0), (0.6, 0.4, 0.8), 0.3), box_corners((8.0, 8.0), (1.0, 0.5, 1.2), -0.5),
                     box_corners((12.0, 6.0), (0.5, 0.5, 0.5), 1.0)])
    world2cam = cam.world2cam
    laser2cam = world2cam @ LASER2WORLD
    return {"camera": cam, "points": pts, "laser2cam": laser2cam,
            "pixels": cam.project(pts @ LASER2WORLD[:3, :3].T + LASER2WORLD[:3, 3])}


def pose_error(T_est: np.ndarray, T_true: np.ndarray) -> np.ndarray:
    """``(rvec, tvec)`` of ``T_est`` minus that of ``T_true`` (6,), the parametrisation of the covariance."""
    r_est, r_true = cv2.Rodrigues(T_est[:3, :3])[0].ravel(), cv2.Rodrigues(T_true[:3, :3])[0].ravel()
    return np.r_[r_est - r_true, T_est[:3, 3] - T_true[:3, 3]]


def test_pixels_all_in_image(scene):
    uv = scene["pixels"]
    assert np.all(np.isfinite(uv))
    assert np.all((uv > 0) & (uv < [640, 480]))


def test_noise_free_points_give_the_exact_pose(scene):
    res = solve_pnp(scene["points"], scene["pixels"], K, DIST)
    assert res.rms_px < 1e-6
    np.testing.assert_allclose(res.ref2cam, scene["laser2cam"], atol=1e-6)  # micrometres
    np.testing.assert_allclose(res.cam2world(LASER2WORLD), scene["camera"].cam2world, atol=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_noisy_points_recover_the_pose_within_the_noise(scene, seed):
    # Pixel noise σ = 0.5 px. Tolerance derived from it: the first-order pose covariance σ² (JᵀJ)⁻¹ at the
    # true pose; the 6-D error must lie inside its 99.9 % ellipsoid (chi-square, 6 dof).
    sigma = 0.5
    rng = np.random.default_rng(seed)
    pix = scene["pixels"] + rng.normal(0.0, sigma, scene["pixels"].shape)
    res = solve_pnp(scene["points"], pix, K, DIST)
    cov = pose_covariance(scene["laser2cam"], scene["points"], scene["pixels"], K, DIST, sigma_px=sigma)
    e = pose_error(res.ref2cam, scene["laser2cam"])
    assert e @ np.linalg.solve(cov, e) <= chi2.ppf(0.999, 6)
    # the residual RMS estimates σ (2n - 6 degrees of freedom out of 2n coordinates)
    n = len(pix)
    assert 0.6 * sigma < res.rms_px / math.sqrt((2 * n - 6) / (2 * n)) < 1.4 * sigma
    # and the reported covariance (estimated from the residuals) agrees with the true one within a factor 2
    assert np.all(res.position_std_m > 0)
    ratio = np.diag(res.covariance) / np.diag(cov)
    assert np.all((ratio > 0.25) & (ratio < 4.0))
    # in metres and degrees, for the reader: centimetres and a fraction of a degree
    assert np.linalg.norm(res.cam2world(LASER2WORLD)[:3, 3] - scene["camera"].position_m) < 0.1


def test_ransac_rejects_a_misclicked_corner(scene):
    rng = np.random.default_rng(3)
    pix = scene["pixels"] + rng.normal(0.0, 0.3, scene["pixels"].shape)
    pix[5] += (40.0, -25.0)
    plain = solve_pnp(scene["points"], pix, K, DIST)
    robust = solve_pnp(scene["points"], pix, K, DIST, ransac=True, ransac_threshold_px=3.0)
    assert not robust.inliers[5]
    assert robust.inliers.sum() == len(pix) - 1
    assert robust.rms_px < 0.5 < plain.rms_px
    assert np.hypot(*robust.residuals_px[5]) > 30  # the outlier's residual is still reported
    err = np.linalg.norm(robust.cam2world(LASER2WORLD)[:3, 3] - scene["camera"].position_m)
    assert err < np.linalg.norm(plain.cam2world(LASER2WORLD)[:3, 3] - scene["camera"].position_m)


def test_bad_control_points_are_clear_errors(scene):
    pts, pix = scene["points"], scene["pixels"]
    with pytest.raises(CalibrationError, match="at least 4"):
        solve_pnp(pts[:3], pix[:3], K)
    line = np.column_stack([np.arange(6.0), np.zeros(6), np.zeros(6)])
    with pytest.raises(CalibrationError, match="collinear"):
        solve_pnp(line, pix[:6], K)
    # pixels on one line are the images of points in one plane through the camera's centre: the corners of boxes
    # (not in one plane) cannot look so, whatever the pose (OpenCV fitted such a mis-typed file exactly, 223 m away)
    cam = scene["camera"]
    typed = np.column_stack([pix[:8, 0], np.full(8, 240.0)])  # the v column typed as the same value
    with pytest.raises(CalibrationError, match=r"pixels of the 8 control points lie on one line .* not in one plane"):
        solve_pnp(pts[:8], typed, K, DIST)
    # points that are in one plane through the camera's centre (markers at the camera's height, here in the plane of
    # the image's x axis and the optical axis) do look so: they are solved, and the pose is the camera's
    c, (a, b) = cam.position_m, cam.cam2world[:3, [0, 2]].T
    in_plane = c + np.array([[1.0, 8.0], [-2.0, 10.0], [3.0, 12.0], [0.5, 9.0], [-1.0, 14.0]]) @ np.array([a, b])
    in_laser = (in_plane - LASER2WORLD[:3, 3]) @ LASER2WORLD[:3, :3]
    fit = solve_pnp(in_laser, cam.project(in_plane), K, DIST)
    np.testing.assert_allclose(fit.cam2world(LASER2WORLD)[:3, 3], c, atol=1e-3)
    bad = pix.copy()
    bad[0, 0] = np.nan
    with pytest.raises(CalibrationError, match="NaN"):
        solve_pnp(pts, bad, K)
    with pytest.raises(CalibrationError, match="RANSAC needs at least 6"):
        solve_pnp(pts[:5], pix[:5], K, ransac=True)
    with pytest.raises(ValueError, match="points_m, pixels_px"):
        solve_pnp(pts, pix[:-1], K)
    with pytest.raises(ValueError, match="points_m: expected an array of shape"):
        solve_pnp(pts[:, :2], pix, K)
    with pytest.raises(ValueError, match="K: expected a camera matrix"):
        solve_pnp(pts, pix, np.eye(3) * 0)
    with pytest.raises(ValueError, match="method"):
        solve_pnp(pts, pix, K, method="p3p")  # type: ignore[arg-type]


@pytest.mark.parametrize(("yaw", "pitch", "roll"), [(90.0, 42.0, 0.0), (-135.0, 10.0, 2.0), (3.0, -5.0, -1.0)])
def test_camera_pose_round_trip_matches_pinhole_from_pose(yaw, pitch, roll):
    cam = PinholeCamera.from_pose([1.0, -2.0, 3.0], math.radians(yaw), math.radians(pitch), math.radians(roll),
                                  fx=400, fy=400, width=640, height=480)
    pose = camera_pose_from_cam2world(cam.cam2world)
    assert (pose.yaw_deg, pose.pitch_deg, pose.roll_deg) == pytest.approx((yaw, pitch, roll), abs=1e-9)
    np.testing.assert_allclose(cam2world_from_camera_pose(pose), cam.cam2world, atol=1e-12)


PIPELINE = """# my hall
[pipeline]
name = "people-laser"   # keep me

[sensors.laser_0]
kind = "laser"
topic = "/laser_0/scan"
pose = { x = -9.6, y = -7.1, z = 0.2, yaw_deg = 37.0 }

[sensors.camera_0]
kind = "camera"
topic = "/camera_0/image"
pose = { x = 0.0, y = -7.0, z = 7.0, pitch_deg = 40.0, yaw_deg = 90.0 }  # by hand
clock_offset_ms = 3.0

[tracking]
gate = 4.0
"""


def test_update_pipeline_pose_rewrites_only_the_pose():
    pose = Pose(x=0.01, y=-7.4, z=7.0, roll_deg=1.5, pitch_deg=40.0, yaw_deg=88.0)
    text = update_pipeline_pose(PIPELINE, "camera_0", pose, comment="PnP, rms 0.4 px")
    old, new = PIPELINE.splitlines(), text.splitlines()
    changed = [i for i, (a, b) in enumerate(zip(old, new, strict=True)) if a != b]
    assert len(old) == len(new)
    assert changed == [old.index(next(ln for ln in old if ln.startswith("pose = { x = 0.0")))]
    assert new[changed[0]].endswith("# PnP, rms 0.4 px")
    cfg = tomllib.loads(text)
    assert cfg["sensors"]["camera_0"]["pose"] == pytest.approx(pose.model_dump())
    assert cfg["sensors"]["camera_0"]["clock_offset_ms"] == 3.0
    assert cfg["tracking"] == {"gate": 4.0}


def test_update_pipeline_pose_other_forms():
    pose = Pose(x=1.0, y=2.0, z=3.0, yaw_deg=-45.5)
    sub = PIPELINE.replace("pose = { x = 0.0, y = -7.0, z = 7.0, pitch_deg = 40.0, yaw_deg = 90.0 }  # by hand\n", "")
    sub += "\n[sensors.camera_0.pose]\nx = 0.0\nyaw_deg = 90.0\n"
    dotted = PIPELINE.replace("pose = { x = 0.0, y = -7.0, z = 7.0, pitch_deg = 40.0, yaw_deg = 90.0 }  # by hand",
                              "pose.x = 0.0\npose.yaw_deg = 90.0")
    missing = PIPELINE.replace("pose = { x = 0.0, y = -7.0, z = 7.0, pitch_deg = 40.0, yaw_deg = 90.0 }  # by hand\n",
                               "")
    for text in (sub, dotted, missing):
        out = update_pipeline_pose(text, "camera_0", pose)
        assert tomllib.loads(out)["sensors"]["camera_0"]["pose"] == pytest.approx(pose.model_dump())
        assert tomllib.loads(out)["tracking"] == {"gate": 4.0}
    added = update_pipeline_pose(PIPELINE, "camera 1", pose, kind="camera", topic="/camera_1/image")
    assert tomllib.loads(added)["sensors"]["camera 1"]["topic"] == "/camera_1/image"
    assert added.startswith(PIPELINE)


def test_update_pipeline_pose_bad_input():
    pose = Pose()
    with pytest.raises(ConfigError, match="kind and topic"):
        update_pipeline_pose(PIPELINE, "camera_9", pose)
    with pytest.raises(ConfigError, match="not valid TOML"):
        update_pipeline_pose("[sensors.camera_0\n", "camera_0", pose)
    with pytest.raises(ConfigError, match=r"sensors\.camera_0\.kind"):
        update_pipeline_pose(PIPELINE.replace('kind = "camera"', 'kind = "kamera"'), "camera_0", pose)
    with pytest.raises(ValueError, match="finite"):  # the model refuses it (pydantic's ValidationError) ...
        Pose(x=math.inf)
    with pytest.raises(ConfigError, match="finite"):  # ... and so does the writer, given one built unchecked
        update_pipeline_pose(PIPELINE, "camera_0", Pose.model_construct(x=math.inf))
    with pytest.raises(ConfigError, match="inline"):
        update_pipeline_pose('[sensors]\ncam = { kind = "camera", topic = "/c" }\n', "cam", pose)


def test_calibrate_from_points_writes_the_pose(scene, tmp_path):
    pipeline = tmp_path / "pipeline.toml"
    pipeline.write_text(PIPELINE, encoding="utf-8")
    rng = np.random.default_rng(7)
    pix = scene["pixels"] + rng.normal(0.0, 0.5, scene["pixels"].shape)
    csv = tmp_path / "points.csv"
    rows = "\n".join(",".join(f"{v:.6f}" for v in row) for row in np.hstack([scene["points"], pix]))
    csv.write_text("# box corners, laser_0 frame\nx_m,y_m,z_m,u_px,v_px\n" + rows + "\n", encoding="utf-8")
    report = calibrate_from_points(pipeline, "camera_0", csv, reference="laser_0", intrinsics=(K, DIST))
    cfg = load_config(pipeline)
    true = camera_pose_from_cam2world(scene["camera"].cam2world)
    got = cfg.sensors["camera_0"].pose
    assert report.written == pipeline
    assert got.model_dump() == pytest.approx(report.pose.model_dump(), abs=1e-6)  # written with 6 decimals
    assert abs(got.yaw_deg - true.yaw_deg) < 0.3
    assert abs(got.pitch_deg - true.pitch_deg) < 0.3
    assert np.hypot(got.x - true.x, got.y - true.y) < 0.1
    assert "# my hall" in pipeline.read_text(encoding="utf-8")
    assert report.previous.yaw_deg == 90.0
    # the read-only variant leaves the file alone
    before = pipeline.read_text(encoding="utf-8")
    calibrate_from_points(pipeline, "camera_0", csv, reference="laser_0", intrinsics=(K, DIST), write=False)
    assert pipeline.read_text(encoding="utf-8") == before


def test_calibration_edges_name_the_problem(scene, tmp_path):
    pipeline = tmp_path / "pipeline.toml"
    pipeline.write_text(PIPELINE, encoding="utf-8")
    csv = tmp_path / "points.csv"
    csv.write_text("x,y,z,u,v\n1,2,3,4,5\n", encoding="utf-8")
    with pytest.raises(RecordingError, match="expected the header x_m, y_m, z_m, u_px, v_px"):
        read_control_points(csv)
    csv.write_text("x_m,y_m,z_m,u_px,v_px\n1,2,3,4,5\n1,2,x,4,5\n", encoding="utf-8")
    with pytest.raises(RecordingError, match="line 3"):
        read_control_points(csv)
    with pytest.raises(ConfigError, match="no sensor 'camera_7'"):
        calibrate_from_points(pipeline, "camera_7", csv, intrinsics=(K, DIST))
    with pytest.raises(ConfigError, match="is a laser, not a camera"):
        calibrate_from_points(pipeline, "laser_0", csv, intrinsics=(K, DIST))
    with pytest.raises(ConfigError, match="reference 'laser_9'"):
        calibrate_from_points(pipeline, "camera_0", csv, reference="laser_9", intrinsics=(K, DIST))
    unposed = tmp_path / "unposed.toml"  # a reference laser without a pose would sit at the origin unsaid
    unposed.write_text(PIPELINE.replace("pose = { x = -9.6, y = -7.1, z = 0.2, yaw_deg = 37.0 }\n", ""),
                       encoding="utf-8")
    with pytest.raises(ConfigError, match="reference 'laser_0' has no pose in the pipeline file"):
        calibrate_from_points(unposed, "camera_0", csv, reference="laser_0", intrinsics=(K, DIST))
    with pytest.raises(ConfigError, match="pipeline file not found"):
        write_pose_to_pipeline(tmp_path / "none.toml", "camera_0", Pose())
    new = write_pose_to_pipeline(tmp_path / "new.toml", "camera_0", Pose(z=3.0), kind="camera", topic="/c",
                                 create=True)
    assert new.sensors["camera_0"].pose.z == 3.0


def test_a_reference_laser_without_a_pose_is_posed_by_the_recording(scene, tmp_path):
    """The README's `calibrate --points --reference laser_0 --recording`: a laser the pipeline file gives no pose keeps
    its recording's (/tf_static, as tracking poses it). Here the recording poses laser_0 where the pipeline file of the
    other tests does, so the camera comes out where it truly is; without the recording's pose it is an error."""
    from fusiontrack.geometry import matrix_to_quat
    from fusiontrack.io.writer import RecordingWriter
    from fusiontrack.types import CameraInfo, LaserScan, Transform

    pipeline = tmp_path / "pipeline.toml"
    pipeline.write_text(PIPELINE.replace("pose = { x = -9.6, y = -7.1, z = 0.2, yaw_deg = 37.0 }\n", ""),
                        encoding="utf-8")
    csv = tmp_path / "points.csv"
    rows = "\n".join(",".join(f"{v:.6f}" for v in row) for row in np.hstack([scene["points"], scene["pixels"]]))
    csv.write_text("x_m,y_m,z_m,u_px,v_px\n" + rows + "\n", encoding="utf-8")
    for posed in (True, False):
        rec = tmp_path / f"rec_{posed}"
        with RecordingWriter(rec) as w:
            w.write(CameraInfo(10**9, "camera_0", "camera_0", 640, 480, K, DIST), topic="/camera_0/camera_info")
            if posed:
                w.write(Transform(10**9, "/tf_static", "world", "laser_0_frame", LASER2WORLD[:3, 3],
                                  matrix_to_quat(LASER2WORLD[:3, :3]), True))
            w.write(LaserScan(10**9, "laser_0", "laser_0_frame", -1.5, 0.01, 0.1, 30.0, np.full(301, 5.0)),
                    topic="/laser_0/scan")
        if not posed:
            with pytest.raises(ConfigError, match=r"reference 'laser_0' has no pose in the pipeline file, nor in"):
                calibrate_from_points(pipeline, "camera_0", csv, reference="laser_0", recording=rec, write=False)
            continue
        report = calibrate_from_points(pipeline, "camera_0", csv, reference="laser_0", recording=rec)
        np.testing.assert_allclose(report.cam2world, scene["camera"].cam2world, atol=1e-5)
        assert "posed by" in pipeline.read_text(encoding="utf-8")  # the written comment says where it came from


def test_rewriting_a_pose_keeps_the_files_permissions_and_a_link(tmp_path):
    """The pose is written atomically through a temporary file: the file keeps its mode (it became 0600) and a
    pipeline file that is a symlink stays one, its target rewritten (the link was replaced by a copy)."""
    import os
    import stat

    target = tmp_path / "shared" / "hall.toml"
    target.parent.mkdir()
    target.write_text(PIPELINE, encoding="utf-8")
    os.chmod(target, 0o640)
    link = tmp_path / "hall.toml"
    link.symlink_to(target)
    write_pose_to_pipeline(link, "camera_0", Pose(z=4.5))
    assert link.is_symlink()
    assert link.resolve() == target.resolve()
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    assert load_config(target).sensors["camera_0"].pose.z == 4.5
    assert sorted(p.name for p in target.parent.iterdir()) == ["hall.toml"]  # no temporary file left


def test_calibrate_command_line(scene, tmp_path):
    """`fusiontrack calibrate CAMERA -c PIPELINE --points CSV --intrinsics ...` rewrites the camera's pose."""
    import subprocess
    import sys

    pipeline = tmp_path / "pipeline.toml"
    pipeline.write_text(PIPELINE, encoding="utf-8")
    csv = tmp_path / "points.csv"
    rows = "\n".join(",".join(f"{v:.6f}" for v in row) for row in np.hstack([scene["points"], scene["pixels"]]))
    csv.write_text("x_m,y_m,z_m,u_px,v_px\n" + rows + "\n", encoding="utf-8")
    intr = ",".join(f"{v:.9g}" for v in [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *np.ravel(DIST)])
    cmd = [sys.executable, "-m", "fusiontrack", "calibrate", "camera_0", "-c", str(pipeline), "--points", str(csv),
           "--reference", "laser_0", "--intrinsics", intr]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "written to" in out.stdout
    true = camera_pose_from_cam2world(scene["camera"].cam2world)
    got = load_config(pipeline).sensors["camera_0"].pose
    assert abs(got.yaw_deg - true.yaw_deg) < 0.01
    bad = subprocess.run(cmd[:7], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2
    assert "exactly one of --points CSV or --adaptive RECORDING" in bad.stderr
    clicked = scene["pixels"].copy()
    clicked[5] += (40.0, -25.0)  # one mis-clicked corner: RANSAC rejects it, and the command says which
    rows = "\n".join(",".join(f"{v:.6f}" for v in row) for row in np.hstack([scene["points"], clicked]))
    csv.write_text("x_m,y_m,z_m,u_px,v_px\n" + rows + "\n", encoding="utf-8")
    out = subprocess.run([*cmd, "--ransac", "--dry-run"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert f"PnP on {len(clicked) - 1} of {len(clicked)} points" in out.stdout
    assert "point 6 rejected as an outlier: 47" in out.stdout  # its residual: the 47 px it was moved by


@pytest.mark.parametrize("fx", [0.0, float("nan")])
def test_a_recordings_camera_info_without_intrinsics_is_named(scene, tmp_path, fx):
    """A CameraInfo of an uncalibrated camera (K all zeros) or a damaged one (NaN): a RecordingError naming the
    recording and the camera, not OpenCV's check of the matrix."""
    from fusiontrack.io.writer import RecordingWriter
    from fusiontrack.types import CameraInfo

    pipeline = tmp_path / "pipeline.toml"
    pipeline.write_text(PIPELINE, encoding="utf-8")
    csv = tmp_path / "points.csv"
    rows = "\n".join(",".join(f"{v:.6f}" for v in row) for row in np.hstack([scene["points"], scene["pixels"]]))
    csv.write_text("x_m,y_m,z_m,u_px,v_px\n" + rows + "\n", encoding="utf-8")
    with RecordingWriter(tmp_path / "rec") as w:
        w.write(CameraInfo(10**9, "camera_0", "camera_0", 640, 480, np.where(K != 0, fx, 0.0)))
    with pytest.raises(RecordingError, match=r"rec: the CameraInfo of camera 'camera_0' holds no usable intrinsics"):
        calibrate_from_points(pipeline, "camera_0", csv, reference="laser_0", recording=tmp_path / "rec", write=False)


def test_a_ros_named_camera_info_is_found_beside_the_image_topic(scene, tmp_path):
    """A pipeline file naming the camera by its ROS image topic (no info_topic) and a recording of another tool:
    its CameraInfo sits beside the image topic, as ROS names them. It was looked up by the pipeline file's sensor
    name only ("no CameraInfo of camera 'head'")."""
    from fusiontrack.io.writer import RecordingWriter
    from fusiontrack.types import CameraInfo

    pipeline = tmp_path / "pipeline.toml"
    pipeline.write_text(PIPELINE + '\n[sensors.head]\nkind = "camera"\ntopic = "/hero/rgb/image_raw"\n',
                        encoding="utf-8")
    csv = tmp_path / "points.csv"
    rows = "\n".join(",".join(f"{v:.6f}" for v in row) for row in np.hstack([scene["points"], scene["pixels"]]))
    csv.write_text("x_m,y_m,z_m,u_px,v_px\n" + rows + "\n", encoding="utf-8")
    info = "/hero/rgb/camera_info"
    with RecordingWriter(tmp_path / "rec") as w:  # (sensor = topic: as a foreign recording reads)
        w.write(CameraInfo(10**9, info, info, 640, 480, K, DIST), topic=info)
    result = calibrate_from_points(pipeline, "head", csv, reference="laser_0", recording=tmp_path / "rec",
                                   write=False)
    true = camera_pose_from_cam2world(scene["camera"].cam2world)
    assert abs(result.pose.yaw_deg - true.yaw_deg) < 0.01
