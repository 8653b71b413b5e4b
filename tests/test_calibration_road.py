"""Global road calibration (ALGORITHMS.md D1): known answers X6/X7, the D1 cross-sensor check, covariance
propagation against Monte Carlo, JSON round trip, clear errors on bad CSVs, and the simulated road recording."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.calibration.road import (
    CameraCalibration,
    ControlPoints,
    LaserCalibration,
    RoadCalibration,
    calibrate_road,
    format_residual_table,
    ground_homography,
    read_control_points,
    residual_table,
    road_calibration_from_recording,
)
from fusiontrack.errors import CalibrationError, ConfigError, RecordingError
from fusiontrack.geometry import PinholeCamera, TransformTree, matrix_to_quat, scan_to_points
from fusiontrack.io.recording import Recording
from fusiontrack.io.writer import RecordingWriter
from fusiontrack.types import CameraInfo, LaserScan, Transform

DIST = (-0.2, 0.05, 0.001, -0.001, 0.0)
# A camera on a 9 m pole beside the road, with barrel distortion; a laser at (15, -4) turned by 30 deg.
CAMERA = PinholeCamera.looking_at((0.0, -8.0, 9.0), (20.0, 0.0, 0.0), fx=1000, fy=1000, width=1280, height=720,
                                  dist=DIST)
LASER_YAW = math.radians(30.0)
LASER_R = np.array([[math.cos(LASER_YAW), -math.sin(LASER_YAW)], [math.sin(LASER_YAW), math.cos(LASER_YAW)]])
LASER_T = np.array([15.0, -4.0])


def floor(xy: np.ndarray) -> np.ndarray:
    return np.column_stack([xy, np.zeros(len(xy))])


def road_to_laser(xy: np.ndarray) -> np.ndarray:
    return (xy - LASER_T) @ LASER_R


def survey() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A surveyed grid of road markers inside the image (D1: >= 8, spread out) and 5 laser reflectors."""
    gx, gy = np.meshgrid([6, 9, 12, 16, 20, 25, 30, 36], [-7, -3.5, 0, 3.5, 7])
    xy = np.column_stack([gx.ravel(), gy.ravel()]).astype(float)
    uv = CAMERA.project(floor(xy))
    inside = np.all((uv > 0) & (uv < (CAMERA.width, CAMERA.height)), axis=1)
    laser_xy = np.array([[10.0, -6.0], [22.0, -6.0], [10.0, 6.0], [22.0, 6.0], [16.0, 0.0]])
    return xy[inside], uv[inside], laser_xy


def control_points(sigma_px: float, sigma_m: float, rng: np.random.Generator) -> ControlPoints:
    cam_xy, cam_uv, laser_xy = survey()
    n, m = len(cam_xy), len(laser_xy)
    return ControlPoints(("camera_0",) * n + ("laser_0",) * m, ("camera",) * n + ("laser",) * m,
                         np.vstack([cam_uv + rng.normal(0, sigma_px, cam_uv.shape),
                                    road_to_laser(laser_xy) + rng.normal(0, sigma_m, laser_xy.shape)]),
                         np.vstack([cam_xy, laser_xy]))


def write_csv(path: Path, rows: list[str], header: str = "sensor,kind,a,b,x,y") -> Path:
    path.write_text("\n".join([header, *rows]) + "\n", encoding="utf-8")
    return path


# ---- Camera models and known answers ---------------------------------------------------------------------------


def test_homography_from_a_camera_model_agrees_with_ray_casting():
    cam = RoadCalibration.from_models({"camera_0": CAMERA}).camera("camera_0")
    assert cam.has_distortion
    np.testing.assert_array_equal(cam.image2road, ground_homography(CAMERA))
    rng = np.random.default_rng(0)
    uv = np.column_stack([rng.uniform(0, 1280, 300), rng.uniform(150, 720, 300)])
    truth = CAMERA.backproject_to_floor(uv)
    ok = np.isfinite(truth[:, 0])
    assert ok.sum() > 250
    np.testing.assert_allclose(cam.image_to_road(uv)[ok], truth[ok, :2], atol=1e-6)
    xy = truth[ok, :2]
    np.testing.assert_allclose(cam.road_to_image(xy), CAMERA.project(floor(xy)), atol=1e-6)
    # above the horizon (the camera looks down 23 deg, fy = 1000: the horizon is near v = -60 px) and behind
    # the camera there is no road point / no pixel
    assert np.all(np.isnan(cam.image_to_road([[640.0, -200.0], [np.nan, 100.0]])))
    assert np.all(np.isnan(cam.road_to_image([[-30.0, -20.0]])))


def test_noise_free_control_points_give_the_exact_homography():
    # X6: noise-free recovery to < 1e-6 (px, and here m); with the lens model the distortion is removed first
    pts = control_points(0.0, 0.0, np.random.default_rng(0))
    calib = calibrate_road(pts, lenses={"camera_0": CAMERA})
    cam = calib.camera("camera_0")
    H = ground_homography(CAMERA)
    np.testing.assert_allclose(cam.image2road / np.linalg.norm(cam.image2road), H / np.linalg.norm(H), atol=1e-9)
    rows = {r["sensor"]: r for r in residual_table(calib)}
    assert rows["camera_0"]["rms_px"] < 1e-6
    assert rows["camera_0"]["max_m"] < 1e-6
    assert rows["laser_0"]["max_m"] < 1e-9
    uv = CAMERA.project(floor(np.array([[7.0, 5.0], [33.0, -6.0], [18.0, 0.5]])))
    np.testing.assert_allclose(calib.image_to_road("camera_0", uv), [[7.0, 5.0], [33.0, -6.0], [18.0, 0.5]],
                               atol=1e-6)


def test_without_the_lens_model_the_distortion_shows_in_the_residual():
    pts = control_points(0.0, 0.0, np.random.default_rng(0))
    with_lens = calibrate_road(pts, lenses={"camera_0": CameraInfo(0, "camera_0", "camera_0", 1280, 720,
                                                                   CAMERA.K, CAMERA.dist)})
    without = calibrate_road(pts)
    assert with_lens.camera("camera_0").residual.rms_px < 1e-6
    assert without.camera("camera_0").residual.rms_px > 1.0  # k1 = -0.2 bends the grid by pixels


def test_laser_rigid_transform_is_recovered_exactly():
    # X7: rotate by 30 deg and translate by (2, -1); noise-free recovery is exact
    a = np.random.default_rng(1).uniform(-5, 5, (6, 2))
    R = np.array([[math.cos(math.pi / 6), -math.sin(math.pi / 6)], [math.sin(math.pi / 6), math.cos(math.pi / 6)]])
    b = a @ R.T + (2.0, -1.0)
    calib = calibrate_road(ControlPoints(("laser_0",) * 6, ("laser",) * 6, a, b))
    laser = calib.laser("laser_0")
    np.testing.assert_allclose(laser.R, R, atol=1e-12)
    np.testing.assert_allclose(laser.t, (2.0, -1.0), atol=1e-12)
    assert laser.yaw_rad == pytest.approx(math.pi / 6, abs=1e-12)
    np.testing.assert_allclose(calib.road_to_laser("laser_0", calib.laser_to_road("laser_0", a)), a, atol=1e-12)
    np.testing.assert_allclose(laser.laser2road @ np.array([*a[0], 1.0]), [*b[0], 1.0], atol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_a_point_seen_by_camera_and_laser_maps_to_one_road_point(seed):
    # D1: control-point noise 1 px and 2 cm; a point seen by both sensors maps to the same road point within 0.1 m
    calib = calibrate_road(control_points(1.0, 0.02, np.random.default_rng(seed)), lenses={"camera_0": CAMERA})
    tx, ty = np.meshgrid(np.linspace(10, 25, 31), np.linspace(-6, 6, 25))
    xy = np.column_stack([tx.ravel(), ty.ravel()])  # the area both sensors cover
    from_camera = calib.image_to_road("camera_0", CAMERA.project(floor(xy)))
    from_laser = calib.laser_to_road("laser_0", road_to_laser(xy))
    assert np.max(np.linalg.norm(from_camera - from_laser, axis=1)) < 0.1
    # per-point residuals estimate the noise: E[rms²] = 2 σ² (1 - p / 2n), p = 8 (homography) or 3 (rigid)
    rows = {r["sensor"]: r for r in residual_table(calib)}
    n_cam, n_laser = rows["camera_0"]["n"], rows["laser_0"]["n"]
    assert n_cam == len(survey()[0])
    assert n_laser == 5
    assert 0.6 < rows["camera_0"]["rms_px"] / math.sqrt(2 * (1 - 8 / (2 * n_cam))) < 1.4
    assert 0.3 < rows["laser_0"]["rms_m"] / (0.02 * math.sqrt(2 * (1 - 3 / (2 * n_laser)))) < 1.8


def test_pixel_covariance_propagation_matches_monte_carlo():
    calib = calibrate_road(control_points(0.0, 0.0, np.random.default_rng(0)), lenses={"camera_0": CAMERA})
    near, far = CAMERA.project(floor(np.array([[8.0, -4.0], [35.0, 5.0]])))
    uv = np.array([near, far])
    cov = calib.road_covariance("camera_0", uv, sigma_px=2.0)
    rng = np.random.default_rng(7)
    for i in range(2):
        samples = calib.image_to_road("camera_0", uv[i] + rng.normal(0, 2.0, (20000, 2)))
        mc = np.cov(samples.T)
        np.testing.assert_allclose(cov[i], mc, rtol=0.1, atol=0.05 * np.max(np.abs(mc)))
    assert np.trace(cov[1]) > 10 * np.trace(cov[0])  # grows with distance
    full = calib.road_covariance("camera_0", uv, cov_px2=np.diag([4.0, 4.0]))
    np.testing.assert_allclose(full, cov, rtol=1e-12)
    assert np.all(np.isnan(calib.road_covariance("camera_0", [[640.0, -300.0]])))


def test_json_round_trip_is_exact(tmp_path):
    calib = calibrate_road(control_points(1.0, 0.02, np.random.default_rng(3)), lenses={"camera_0": CAMERA})
    plain = calibrate_road(control_points(1.0, 0.02, np.random.default_rng(4)))  # no lens: K null
    calib = calib.merged(RoadCalibration({"camera_1": CameraCalibration("camera_1", *[
        plain.camera("camera_0").image2road, plain.camera("camera_0").road2image])}, {}, "plain"))
    back = RoadCalibration.load(calib.save(tmp_path / "road.json"))
    assert back.sensors == calib.sensors == ("camera_0", "camera_1", "laser_0")
    for name, cam in calib.cameras.items():
        other = back.camera(name)
        for attr in ("image2road", "road2image", "dist"):
            assert np.array_equal(getattr(cam, attr), getattr(other, attr))
        assert (cam.K is None and other.K is None) or np.array_equal(cam.K, other.K)
        assert cam.residual == other.residual or (cam.residual is None and other.residual is None)
    assert back.laser("laser_0").residual == calib.laser("laser_0").residual
    assert np.array_equal(back.laser("laser_0").R, calib.laser("laser_0").R)
    uv = CAMERA.project(floor(np.array([[12.0, 1.0], [30.0, -5.0]])))
    assert np.array_equal(back.image_to_road("camera_0", uv), calib.image_to_road("camera_0", uv))
    assert json.loads((tmp_path / "road.json").read_text())["cameras"]["camera_1"]["residual"] is None
    # a file that is not a calibration, or whose inverse was edited, is a clear error
    (tmp_path / "bad.json").write_text('{"format": "something else"}')
    with pytest.raises(ConfigError, match=r"bad\.json"):
        RoadCalibration.load(tmp_path / "bad.json")
    data = calib.to_dict()
    data["cameras"]["camera_0"]["road2image"][0][0] += 1.0
    with pytest.raises(ConfigError, match=r"camera_0.*inverse"):
        RoadCalibration.from_dict(data, "edited.json")


# ---- Control-point files -----------------------------------------------------------------------------------------


def test_csv_control_points_round_trip(tmp_path):
    pts = control_points(0.5, 0.01, np.random.default_rng(5))
    rows = [f"{s},{k},{a!r},{b!r},{x!r},{y!r}" for s, k, (a, b), (x, y)
            in zip(pts.sensors, pts.kinds, pts.sensor_xy.tolist(), pts.road_xy.tolist(), strict=True)]
    path = write_csv(tmp_path / "cp.csv", ["# surveyed 2024-05-01", "", *rows])
    read = read_control_points(path)
    assert read.sensors == pts.sensors
    assert read.kinds == pts.kinds
    assert np.array_equal(read.sensor_xy, pts.sensor_xy)
    assert np.array_equal(read.road_xy, pts.road_xy)
    assert read.lines[0] == 4  # header on line 1, a comment and a blank line
    a = calibrate_road(path, lenses={"camera_0": CAMERA})
    b = calibrate_road(pts, lenses={"camera_0": CAMERA})
    assert np.array_equal(a.camera("camera_0").image2road, b.camera("camera_0").image2road)
    text = format_residual_table(residual_table(a))
    assert "camera_0" in text
    assert "laser_0" in text


BAD_CSVS = {
    "missing column": ("sensor,kind,a,b,x\ncam,camera,1,2,3", ConfigError, r"line 1.*missing column\(s\) y"),
    "not a number": ("sensor,kind,a,b,x,y\ncam,camera,1,2,3,4\ncam,camera,1,two,3,4", ConfigError,
                     r"line 3 \(sensor 'cam'\).*'b' is not a number"),
    "too few fields": ("sensor,kind,a,b,x,y\ncam,camera,1,2,3", ConfigError, "line 2: expected 6"),
    "unknown kind": ("sensor,kind,a,b,x,y\nradar_0,radar,1,2,3,4", ConfigError, r"line 2 \(sensor 'radar_0'\).*kind"),
    "nan": ("sensor,kind,a,b,x,y\ncam,camera,nan,2,3,4", ConfigError, "line 2.*not finite"),
    "empty": ("# nothing\n", ConfigError, "empty"),
    "three camera points": ("sensor,kind,a,b,x,y\ncam,camera,0,0,0,0\ncam,camera,100,0,1,0\ncam,camera,0,100,0,1",
                            CalibrationError, r"lines 2, 3, 4: camera 'cam' has 3 control point\(s\); at least 4"),
    "one laser point": ("sensor,kind,a,b,x,y\nlas,laser,1,2,3,4", CalibrationError,
                        r"line.* 2: laser 'las' has 1 control point\(s\); at least 2"),
    "collinear camera points": ("sensor,kind,a,b,x,y\n" + "\n".join(f"cam,camera,{10 * i},{5 * i},{i},{i * i}"
                                                                     for i in range(6)),
                                CalibrationError, "lines 2, 3, 4, 5, 6, 7: the 6 control pixels of camera 'cam' "
                                "are collinear"),
    "coincident laser points": ("sensor,kind,a,b,x,y\nlas,laser,1,2,3,4\nlas,laser,1,2,5,4", CalibrationError,
                                "laser 'las'.*coincide"),
    "camera and laser": ("sensor,kind,a,b,x,y\ns,laser,1,2,3,4\ns,camera,1,2,3,4\ns,laser,2,2,4,4",
                         ConfigError, "sensor 's' is listed both as camera and as laser"),
}


@pytest.mark.parametrize("case", list(BAD_CSVS))
def test_bad_control_point_files_are_clear_errors(tmp_path, case):
    text, error, pattern = BAD_CSVS[case]
    path = tmp_path / "points.csv"
    path.write_text(text + "\n", encoding="utf-8")
    with pytest.raises(error, match=pattern) as info:
        calibrate_road(path)
    assert str(path) in str(info.value)


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        read_control_points(tmp_path / "nope.csv")


def test_a_mislabelled_point_gives_a_warning(caplog):
    pts = control_points(0.5, 0.01, np.random.default_rng(6))
    road = pts.road_xy.copy()
    road[3] += (3.0, 0.0)  # the surveyor swapped two markers
    with caplog.at_level(logging.WARNING, logger="fusiontrack.calibration.road"):
        calibrate_road(ControlPoints(pts.sensors, pts.kinds, pts.sensor_xy, road, source="survey.csv"),
                       lenses={"camera_0": CAMERA})
    assert any("survey.csv" in r.message and "camera_0" in r.message and "large residual" in r.message
               for r in caplog.records)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="fusiontrack.calibration.road"):
        calibrate_road(pts, lenses={"camera_0": CAMERA})
    assert not caplog.records


# ---- Recordings ----------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def road_recording(tmp_path_factory) -> Path:
    """10 s of the simulated `road`: 2 cameras, 2 lasers, ground truth."""
    from fusiontrack.sim.scenario import load_scenario
    from fusiontrack.sim.simulator import simulate

    path = tmp_path_factory.mktemp("road_calibration") / "road10"
    simulate(load_scenario("road").with_overrides(seconds=10, seed=0), path)
    return path


@pytest.fixture(scope="module")
def road_calibration(road_recording) -> RoadCalibration:
    return road_calibration_from_recording(road_recording)


def _tree(rec: Recording) -> TransformTree:
    tree = TransformTree()
    for tf in rec.messages(["/tf_static"]):
        tree.add_record(tf)
    return tree


def test_road_recording_cameras_map_true_positions_back(road_calibration, road_recording):
    # The simulator's truth: agents' road positions projected with the TRUE camera pose (tf "camera_c"); the
    # calibration is built from the believed pose ("camera_c_calibrated") and CameraInfo.
    calib = road_calibration
    assert set(calib.cameras) == {"camera_0", "camera_1"}
    assert set(calib.lasers) == {"laser_0", "laser_1"}
    assert calib.camera("camera_0").residual is None
    with Recording(road_recording) as rec:
        tree = _tree(rec)
        for name in calib.cameras:
            # the road scenario has no yaw bias: believed == true pose
            np.testing.assert_allclose(tree.get(f"{name}_calibrated", "world"), tree.get(name, "world"), atol=1e-9)
            info = next(m for m in rec.messages([f"/{name}/camera_info"]))
            true_cam = PinholeCamera.from_camera_info(info, tree.get("world", name))
            truth = np.vstack([m.positions_m[m.attributes["visibility"] > 0.5]
                               for m in rec.messages([f"/ground_truth/{name}"])])
            assert len(truth) > 100
            uv = true_cam.project(floor(truth))
            np.testing.assert_allclose(calib.image_to_road(name, uv), truth, atol=1e-6)
            np.testing.assert_allclose(calib.road_to_image(name, truth), uv, atol=1e-6)
            cov = calib.road_covariance(name, uv)
            assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_road_recording_lasers_put_the_wall_and_pillars_in_place(road_calibration, road_recording):
    # world.json: a wall along y = 12 for |x| <= 30 and pillars of radius 0.12 m. The first scans (no vehicle
    # yet) mapped with the tf-derived transform must land on them.
    world = json.loads((road_recording / "ground_truth" / "world.json").read_text())
    pillars = np.array(world["pillars"])
    (((x0, y0), (x1, _)),) = world["walls"]
    with Recording(road_recording) as rec:
        for laser in ("laser_0", "laser_1"):
            scan = next(iter(rec.messages([f"/{laser}/scan"])))
            pts = road_calibration.laser_to_road(laser, scan_to_points(scan))
            pts = pts[np.isfinite(pts[:, 0])]
            to_pillar = np.min(np.abs(np.linalg.norm(pts[:, None] - pillars[None, :, :2], axis=2)
                                      - pillars[None, :, 2]), axis=1)
            on_wall = (pts[:, 0] >= x0 - 0.1) & (pts[:, 0] <= x1 + 0.1)
            to_wall = np.where(on_wall, np.abs(pts[:, 1] - y0), np.inf)
            dist = np.minimum(to_pillar, to_wall)
            assert len(pts) >= 4
            assert np.median(dist) < 0.05
            assert np.mean(dist < 0.15) > 0.95


@pytest.fixture(scope="module")
def biased_recording(tmp_path_factory) -> tuple[Path, PinholeCamera, PinholeCamera]:
    """A tiny recording: a distorted camera whose believed pose is 2 deg off in yaw and 0.3 m off in x; a laser
    with only its true pose in tf; a second camera with no pose at all."""
    true_cam = PinholeCamera.looking_at((0.0, -8.0, 9.0), (20.0, 0.0, 0.0), fx=1000, fy=1000, width=1280,
                                        height=720, dist=DIST)
    believed = true_cam.with_yaw_offset(math.radians(2.0))
    c2w = believed.cam2world
    c2w[0, 3] += 0.3
    believed = PinholeCamera(true_cam.K, true_cam.dist, np.linalg.inv(c2w), 1280, 720)
    t0 = 1_700_000_000_000_000_000
    laser2world = np.eye(4)
    laser2world[:3, :3] = np.array([[LASER_R[0, 0], LASER_R[0, 1], 0], [LASER_R[1, 0], LASER_R[1, 1], 0], [0, 0, 1]])
    laser2world[:3, 3] = (*LASER_T, 0.5)

    def tf(child: str, T: np.ndarray) -> Transform:
        return Transform(t0, "/tf_static", "world", child, T[:3, 3], matrix_to_quat(T[:3, :3]), True)

    path = tmp_path_factory.mktemp("road_calib") / "biased"
    with RecordingWriter(path) as w:
        w.write(tf("camera_0", true_cam.cam2world))
        w.write(tf("camera_0_calibrated", believed.cam2world))
        w.write(tf("laser_0", laser2world))
        w.write(CameraInfo(t0, "camera_0", "camera_0", 1280, 720, true_cam.K, true_cam.dist))
        w.write(CameraInfo(t0, "camera_9", "camera_9", 640, 480, [[500, 0, 320], [0, 500, 240], [0, 0, 1]]))
        w.write(LaserScan(t0, "laser_0", "laser_0", -math.pi / 2, math.pi / 180, 0.1, 30.0,
                          np.full(181, 10.0, np.float32)))
    return path, true_cam, believed


def test_recording_calibration_uses_the_believed_pose_and_removes_distortion(biased_recording, caplog):
    path, true_cam, believed = biased_recording
    with caplog.at_level(logging.WARNING, logger="fusiontrack.calibration.road"):
        calib = road_calibration_from_recording(path)
    assert "camera_9" not in calib.cameras
    assert any("camera_9" in r.message for r in caplog.records)
    cam = calib.camera("camera_0")
    assert cam.has_distortion
    xy = np.column_stack([np.linspace(8, 30, 20), np.linspace(-6, 6, 20)])
    uv = true_cam.project(floor(xy))  # what the camera sees
    # mapped with the believed camera: exactly the believed camera's ray casting, not the truth
    np.testing.assert_allclose(cam.image_to_road(uv), believed.backproject_to_floor(uv)[:, :2], atol=1e-6)
    assert np.min(np.linalg.norm(cam.image_to_road(uv) - xy, axis=1)) > 0.25
    # with the true poses it recovers the truth, and the laser transform comes from the laser's own frame
    true_calib = road_calibration_from_recording(path, use_calibrated=False, cameras=["camera_0"])
    np.testing.assert_allclose(true_calib.image_to_road("camera_0", uv), xy, atol=1e-6)
    np.testing.assert_allclose(calib.laser_to_road("laser_0", road_to_laser(xy)), xy, atol=1e-9)
    with pytest.raises(RecordingError, match="camera_9"):
        road_calibration_from_recording(path, cameras=["camera_9"])
    with pytest.raises(RecordingError, match="laser_7"):
        road_calibration_from_recording(path, lasers=["laser_7"])


def _survey(road_recording: Path, path: Path, rng: np.random.Generator, shift_m: float = 0.0
            ) -> tuple[Path, dict[str, PinholeCamera], dict[str, np.ndarray]]:
    """A site survey of the simulated road: markers on the road seen by each camera (pixels from the TRUE pose and
    lens, 1 px noise) and reflectors seen by each laser (in its true frame, 2 cm noise); road coordinates written
    ``shift_m`` further along x than they are (a survey in another frame)."""
    rows = []
    with Recording(road_recording) as rec:
        tree = _tree(rec)
        cams = {}
        for name in ("camera_0", "camera_1"):
            info = next(m for m in rec.messages([f"/{name}/camera_info"]))
            cams[name] = PinholeCamera.from_camera_info(info, tree.get("world", name))
        lasers = {name: tree.get(name, "world") for name in ("laser_0", "laser_1")}
    gx, gy = np.meshgrid(np.arange(-40.0, 41.0, 5.0), [-5.0, -1.75, 1.75, 5.0])
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    for name, cam in cams.items():
        uv = cam.project(floor(grid))
        inside = np.all(np.isfinite(uv), axis=1) & np.all((uv > 5) & (uv < (cam.width - 5, cam.height - 5)), axis=1)
        uv = uv[inside] + rng.normal(0, 1.0, (int(inside.sum()), 2))
        rows += [f"{name},camera,{u:.3f},{v:.3f},{x + shift_m},{y}"
                 for (u, v), (x, y) in zip(uv, grid[inside], strict=True)]
    for name, T in lasers.items():
        R, t = T[:2, :2], T[:2, 3]
        xy = np.array([[-8.0, -6.5], [8.0, -6.5], [0.0, 6.5], [-4.0, 12.0], [4.0, 12.0]]) + t * [1, 0]
        local = (xy - t) @ R + rng.normal(0, 0.02, xy.shape)
        rows += [f"{name},laser,{a:.4f},{b:.4f},{x + shift_m},{y}" for (a, b), (x, y) in zip(local, xy, strict=True)]
    return write_csv(path, rows), cams, lasers


def test_calibrate_road_command_recovers_the_road_recordings_true_poses(road_recording, tmp_path):
    # The calibration written by the command must put the cameras' and lasers' views of the road where the truth is.
    from typer.testing import CliRunner

    from fusiontrack.cli import app

    points, cams, lasers = _survey(road_recording, tmp_path / "survey.csv", np.random.default_rng(3))
    gx, gy = np.meshgrid(np.arange(-40.0, 41.0, 5.0), [-5.0, -1.75, 1.75, 5.0])
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    out = tmp_path / "road_calibration.json"
    result = CliRunner().invoke(app, ["calibrate-road", str(points), "-o", str(out), "--lenses",
                                      str(road_recording)])
    assert result.exit_code == 0, result.output
    assert "camera_0" in result.output
    assert "laser_1" in result.output
    assert "rms px" in result.output
    assert "lenses from" in result.output  # (the lenses used, named)
    assert "camera_0, camera_1" in " ".join(result.output.split())
    calib = RoadCalibration.load(out)
    assert set(calib.cameras) == set(cams)
    assert set(calib.lasers) == set(lasers)
    for name, cam in cams.items():
        assert calib.camera(name).residual.rms_px < 2.0
        near = grid[np.abs(grid[:, 0] - cam.cam2world[0, 3]) < 30]  # the road within 30 m of the pole
        uv = cam.project(floor(near))
        ok = np.all(np.isfinite(uv), axis=1)
        err = np.linalg.norm(calib.image_to_road(name, uv[ok]) - near[ok], axis=1)
        assert np.median(err) < 0.1
        assert err.max() < 0.5
    for name, T in lasers.items():
        fitted = calib.laser(name)
        np.testing.assert_allclose(fitted.t, T[:2, 3], atol=0.05)
        assert abs(math.degrees(fitted.yaw_rad - math.atan2(T[1, 0], T[0, 0]))) < 0.5


def test_lenses_of_other_cameras_are_warned_of_not_ignored(road_recording, tmp_path, shared_data, caplog):
    """--lenses with a recording whose CameraInfo names none of the survey's cameras (an RGB-D bag's) gave the
    same calibration as without it, without a word."""
    from typer.testing import CliRunner

    from fusiontrack.cli import app

    points, _, _ = _survey(road_recording, tmp_path / "survey.csv", np.random.default_rng(3))
    other = shared_data / "rgbd/tue_rgbd_people/2019-05-03-12-41-38.bag"
    with caplog.at_level("WARNING", logger="fusiontrack"):
        result = CliRunner().invoke(app, ["calibrate-road", str(points), "-o", str(tmp_path / "c.json"),
                                          "--lenses", str(other)])
    assert result.exit_code == 0, result.output
    (msg,) = [r.getMessage() for r in caplog.records if "--lenses" in r.getMessage()]
    assert "no CameraInfo of camera_0, camera_1" in msg
    assert "their pixels are used as they are" in msg


def test_the_traffic_pipeline_poses_its_sensors_by_the_road_calibration(road_recording, tmp_path):
    # Tracked through a surveyed calibration the vehicles are where the simulator put them, as through the
    # recording's own tf; a survey written 4 m off along the road moves every track 4 m (so every sensor is
    # posed by the calibration), and the tracks are then 4 m from the truth.
    from fusiontrack.eval.vehicles import evaluate_vehicles
    from fusiontrack.fusion.traffic import track_traffic
    from fusiontrack.types import GroundTruth

    with Recording(road_recording) as rec:
        gt = [g for g in rec.messages(["/ground_truth"]) if isinstance(g, GroundTruth)]
    area = [(-45, -9), (45, -9), (45, 9), (-45, 9)]
    rng = np.random.default_rng(5)
    runs = {}
    for label, shift in (("tf", None), ("survey", 0.0), ("shifted", 4.0)):
        calib = None if shift is None else calibrate_road(_survey(road_recording, tmp_path / f"{label}.csv", rng,
                                                                  shift)[0])
        res = track_traffic(road_recording, variants=("fusion_pf",), calibration=calib)
        runs[label] = res.states["fusion_pf"]
    scores = {k: evaluate_vehicles(gt, v, area=area, rate_hz=15) for k, v in runs.items()}
    assert scores["tf"].mota > 0.5
    assert scores["survey"].mota > scores["tf"].mota - 0.1
    assert scores["shifted"].mota < 0.2
    moved = {}
    for s in runs["shifted"]:
        near = [o for o in runs["survey"] if o.t_ns == s.t_ns]
        if near:
            d = np.array([o.position_m for o in near]) - s.position_m
            moved[s.t_ns, s.track_id] = d[np.argmin(np.linalg.norm(d - [-4.0, 0.0], axis=1))]
    shift = np.median(np.array(list(moved.values())), axis=0)
    np.testing.assert_allclose(shift, [-4.0, 0.0], atol=0.3)


def test_a_calibration_naming_a_sensor_the_recording_lacks_is_a_clear_error(road_recording):
    from fusiontrack.fusion.traffic import track_traffic

    calib = RoadCalibration(lasers={"laser_7": LaserCalibration("laser_7", np.eye(2), np.zeros(2))},
                            source="site.json")
    with pytest.raises(ConfigError, match=r"site\.json.*laser_7.*laser_0"):
        track_traffic(road_recording, variants=("fusion_pf",), calibration=calib)


def test_calibrate_road_command_names_a_bad_file(tmp_path):
    from typer.testing import CliRunner

    from fusiontrack.cli import app

    bad = write_csv(tmp_path / "bad.csv", ["camera_0,camera,10,20,1,2", "camera_0,camera,30,40,3,4"])
    result = CliRunner().invoke(app, ["calibrate-road", str(bad), "-o", str(tmp_path / "c.json")])
    assert result.exit_code != 0
    message = str(result.exception) + result.output
    assert "bad.csv" in message
    assert "camera_0" in message
    assert "at least 4" in message
    assert not (tmp_path / "c.json").exists()


def test_a_surveyed_camera_needs_no_camera_info(tmp_path):
    # A real site: a camera publishing images only, posed by the survey's homography; a laser without a pose in
    # tf and not in the survey still gets one (the identity, with a warning); a camera with images but neither
    # CameraInfo nor survey is left out.
    from fusiontrack.fusion.traffic_sensors import traffic_branches
    from fusiontrack.types import Image

    t0 = 1_700_000_000_000_000_000
    path = tmp_path / "site"
    with RecordingWriter(path) as w:
        for cam in ("camera_0", "camera_5"):
            w.write(Image(t0, cam, cam, np.zeros((48, 64, 3), np.uint8), "bgr8"))
        w.write(LaserScan(t0, "laser_0", "laser_0", -math.pi / 2, math.pi / 180, 0.1, 30.0,
                          np.full(181, 10.0, np.float32)))
    calib = calibrate_road(control_points(1.0, 0.02, np.random.default_rng(0)))
    calib = RoadCalibration({"camera_0": calib.camera("camera_0")}, {}, "survey.json")
    with Recording(path) as rec:
        laser, laser_topics, cams = traffic_branches(rec, np.array([[-50.0, 0.0, 50.0, 0.0, 7.0]]),
                                                     calibration=calib)
    assert list(cams) == ["camera_0"]
    topic, det = cams["camera_0"]
    assert topic == "/camera_0/image"
    np.testing.assert_allclose(det.H_img2road / det.H_img2road[2, 2], calib.camera("camera_0").image2road /
                               calib.camera("camera_0").image2road[2, 2])
    assert laser is not None
    assert laser_topics == ["/laser_0/scan"]
