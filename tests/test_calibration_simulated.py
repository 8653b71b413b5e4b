"""Seed 000's experiment in simulation, short: the camera turned 3 degrees from its calibration, people walking.

The full experiment (5 runs, plots) is ``benchmarks/bias.py``; here one short run checks the paper's claims
(ALGORITHMS.md A12): the bias settles in about 40 frames at rate 0.1 and in fewer than 10 at rate 0.5, and
``fusiontrack calibrate``'s library function writes the corrected pose into a pipeline file.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiontrack.calibration import calibrate_from_recording, camera_pose_from_cam2world, open_bias_inputs
from fusiontrack.calibration.bias import BiasParams
from fusiontrack.config import load_config
from fusiontrack.errors import RecordingError
from fusiontrack.geometry import PinholeCamera
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import Simulation
from fusiontrack.types import LaserScan

BIAS_DEG = 3.0


@pytest.fixture(scope="module")
def crowd(simulated) -> dict:
    settings = {"cameras.0.yaw_bias_deg": BIAS_DEG}
    scenario = load_scenario("crowd").with_overrides(seconds=14, seed=0, settings=settings)
    out = simulated("crowd", seconds=14, seed=0, settings=settings)  # the recording test_fusion.py's crowd uses
    offsets = {c.name: c.clock_offset_ms for c in [*scenario.config.lasers, *scenario.config.cameras]}
    inputs = open_bias_inputs(out, "camera_0", clock_offsets_ms=offsets)
    estimators = {rho: inputs.estimator(BiasParams(rho=rho)) for rho in (0.1, 0.5)}
    for item in inputs:
        for est in estimators.values():
            if isinstance(item, LaserScan):
                est.observe_scan(item)
            else:
                item.update(est)
    cam = Simulation(scenario).cameras[0]
    return {"path": out, "estimators": estimators, "true": cam.true_camera, "calibrated": cam.calibrated_camera,
            "scenario": scenario}


def updates_to_settle(bias_deg: np.ndarray, n_used: np.ndarray, tol_deg: float, hold: int = 30) -> int:
    """Updates from the first one until |b - 3°| is within ``tol_deg`` and stays there ``hold`` updates."""
    upd = bias_deg[n_used > 0]
    ok = np.abs(upd - BIAS_DEG) <= tol_deg
    run = np.convolve(ok, np.ones(hold, int), "valid") == hold  # run[i]: updates i .. i + hold - 1 all ok
    return int(np.argmax(run)) + 1 if run.any() else len(upd) + 1


@pytest.mark.parametrize(("rho", "max_updates"), [(0.1, 40), (0.5, 10)])
def test_bias_settles_at_the_papers_speed(crowd, rho, max_updates):
    h = crowd["estimators"][rho].history
    bias = np.degrees(h.bias_rad)
    assert (h.n_used > 0).sum() > 80  # people are matched in most frames
    # within 10 % of the 3 degrees (and staying there for 30 updates) after about 40 updates (0.1) / fewer than
    # 10 (0.5): A12. Noise-free smoothing needs 22 and 4.
    assert updates_to_settle(bias, h.n_used, 0.1 * BIAS_DEG) <= max_updates
    first = np.flatnonzero(h.n_used > 0)[0]
    assert abs(bias[first + 60:].mean() - BIAS_DEG) <= 0.1


def test_corrected_camera_is_the_true_camera(crowd):
    est = crowd["estimators"][0.1]
    true: PinholeCamera = crowd["true"]
    fwd_est, fwd_true = est.corrected_camera.cam2world[:3, 2], true.cam2world[:3, 2]
    yaw_err = math.degrees(math.atan2(fwd_est[1], fwd_est[0]) - math.atan2(fwd_true[1], fwd_true[0]))
    assert abs(yaw_err) < 0.15
    before = math.degrees(math.atan2(est.camera.cam2world[1, 2], est.camera.cam2world[0, 2])
                          - math.atan2(fwd_true[1], fwd_true[0]))
    assert before == pytest.approx(-BIAS_DEG, abs=1e-6)


def test_calibrate_from_recording_writes_the_corrected_pose(crowd, tmp_path):
    sc = crowd["scenario"].config
    cam = camera_pose_from_cam2world(crowd["calibrated"].cam2world)
    lines = ["[pipeline]", 'name = "hall"', ""]
    for laser in sc.lasers:
        lines += [f"[sensors.{laser.name}]", 'kind = "laser"', f'topic = "/{laser.name}/scan"',
                  f"pose = {{ x = {laser.x_m}, y = {laser.y_m}, z = {laser.height_m}, yaw_deg = {laser.yaw_deg} }}",
                  f"clock_offset_ms = {laser.clock_offset_ms}", ""]
    lines += ["[sensors.camera_0]", 'kind = "camera"', 'topic = "/camera_0/image"',
              f"pose = {{ x = {cam.x}, y = {cam.y}, z = {cam.z}, pitch_deg = {cam.pitch_deg}, "
              f"yaw_deg = {cam.yaw_deg} }}"]
    pipeline = tmp_path / "pipeline.toml"
    pipeline.write_text("\n".join(lines) + "\n", encoding="utf-8")
    report = calibrate_from_recording(pipeline, "camera_0", crowd["path"], params=BiasParams(rho=0.5))
    got = load_config(pipeline).sensors["camera_0"].pose
    true = camera_pose_from_cam2world(crowd["true"].cam2world)
    assert report.previous.yaw_deg == pytest.approx(true.yaw_deg - BIAS_DEG, abs=1e-6)
    assert got.yaw_deg == pytest.approx(true.yaw_deg, abs=0.2)
    assert got.pitch_deg == pytest.approx(true.pitch_deg, abs=1e-5)
    assert math.degrees(report.bias.bias_rad) == pytest.approx(BIAS_DEG, abs=0.2)
    with pytest.raises(RecordingError, match="laser"):
        calibrate_from_recording(pipeline, "camera_0", crowd["path"], lasers=["laser_9"], write=False)


def _pipeline_without_poses(crowd) -> str:
    sc = crowd["scenario"].config
    lines = ["[pipeline]", 'name = "hall"', ""]
    for laser in sc.lasers:
        lines += [f"[sensors.{laser.name}]", 'kind = "laser"', f'topic = "/{laser.name}/scan"',
                  f"clock_offset_ms = {laser.clock_offset_ms}", ""]
    return "\n".join([*lines, "[sensors.camera_0]", 'kind = "camera"', 'topic = "/camera_0/image"', ""])


def test_calibrate_from_recording_starts_from_the_recordings_poses_when_the_file_gives_none(crowd, tmp_path):
    """A pipeline file listing the sensors without poses: the bias is learnt from the recording's /tf_static
    poses (as the pipelines read them), not from sensors at the world's origin."""
    pipeline = tmp_path / "pipeline.toml"
    pipeline.write_text(_pipeline_without_poses(crowd), encoding="utf-8")
    report = calibrate_from_recording(pipeline, "camera_0", crowd["path"], params=BiasParams(rho=0.5))
    got = load_config(pipeline).sensors["camera_0"].pose
    true = camera_pose_from_cam2world(crowd["true"].cam2world)
    calibrated = camera_pose_from_cam2world(crowd["calibrated"].cam2world)  # the recording's (3 degrees off)
    assert report.previous.model_dump() == pytest.approx(calibrated.model_dump(), abs=1e-6)
    assert got.yaw_deg == pytest.approx(true.yaw_deg, abs=0.2)
    assert (got.x, got.y, got.z, got.pitch_deg) == pytest.approx((true.x, true.y, true.z, true.pitch_deg), abs=1e-5)
    assert math.degrees(report.bias.bias_rad) == pytest.approx(BIAS_DEG, abs=0.2)


def test_calibrate_from_recording_finds_the_files_sensors_by_their_topics(crowd, tmp_path):
    """A pipeline file naming its sensors otherwise than the recording (front / back / front_cam for laser_0 /
    laser_1 / camera_0), with their topics: the same sensors are used, by topic, as the pipelines do (it failed:
    "laser(s) ['front', 'back'] not found"), and the bias is the one learnt under the recording's names."""
    text = _pipeline_without_poses(crowd)
    named = tmp_path / "named.toml"
    named.write_text(text, encoding="utf-8")
    renamed = tmp_path / "renamed.toml"
    renamed.write_text(text.replace("[sensors.laser_0]", "[sensors.front]").replace("[sensors.laser_1]",
                                                                                   "[sensors.back]")
                       .replace("[sensors.camera_0]", "[sensors.front_cam]"), encoding="utf-8")
    assert "laser_0]" not in renamed.read_text()
    a = calibrate_from_recording(named, "camera_0", crowd["path"], params=BiasParams(rho=0.5), write=False)
    b = calibrate_from_recording(renamed, "front_cam", crowd["path"], params=BiasParams(rho=0.5), write=False)
    np.testing.assert_array_equal(b.bias.history.bias_rad, a.bias.history.bias_rad)
    np.testing.assert_array_equal(b.bias.history.n_used, a.bias.history.n_used)
    assert math.degrees(b.bias.bias_rad) == pytest.approx(BIAS_DEG, abs=0.2)
    rear = tmp_path / "rear.toml"  # a sensor of the file the recording lacks: named as the file names it
    rear.write_text(renamed.read_text() + '[sensors.rear]\nkind = "laser"\ntopic = "/rear/scan"\n', encoding="utf-8")
    with pytest.raises(RecordingError, match=r"rear.toml's \[sensors.rear\] topic '/rear/scan' is not in the "
                                             r"recording; it has: .*/laser_0/scan"):
        calibrate_from_recording(rear, "front_cam", crowd["path"], write=False)


def test_the_people_pipeline_poses_its_camera_as_the_pipeline_file_says(crowd, tmp_path):
    """``camera_poses`` (a pipeline file's camera pose, e.g. as ``fusiontrack calibrate`` wrote it) replaces the
    recording's /tf_static pose: the camera moved 100 m aside sees nobody, so no classifier learns; posed as the
    recording has it, the same run learns."""
    from fusiontrack.calibration import cam2world_from_camera_pose
    from fusiontrack.fusion import track_fused

    sc = crowd["scenario"]
    corr = {c.name: -round(c.clock_offset_ms * 1e6) for c in [*sc.config.lasers, *sc.config.cameras]}
    bounds = Simulation(sc).world.bounds_m
    calibrated = camera_pose_from_cam2world(crowd["calibrated"].cam2world)
    away = calibrated.model_copy(update={"x": calibrated.x + 100.0})  # the hall is 90-110 m to its left
    pipeline = tmp_path / "pipeline.toml"
    pipeline.write_text(_pipeline_without_poses(crowd).replace(
        'topic = "/camera_0/image"', f'topic = "/camera_0/image"\npose = {{ x = {away.x}, y = {away.y}, '
        f'z = {away.z}, pitch_deg = {away.pitch_deg}, yaw_deg = {away.yaw_deg} }}'), encoding="utf-8")
    poses = load_config(pipeline).camera_poses()
    assert set(poses) == {"camera_0", "/camera_0/image"}
    np.testing.assert_allclose(poses["camera_0"], cam2world_from_camera_pose(away), atol=1e-9)
    runs = {}
    for name, given in (("away", poses), ("recording", None),
                        ("file, as the recording", {"camera_0": cam2world_from_camera_pose(calibrated)})):
        _, _, stats = track_fused(crowd["path"], adaptive_bias=False, area_m=bounds, clock_corrections_ns=corr,
                                  camera_poses=given)
        runs[name] = stats
    assert runs["away"].camera == "camera_0"  # a usable camera (the one the overlay video draws through) ...
    np.testing.assert_allclose(runs["away"].camera_model.cam2world, cam2world_from_camera_pose(away), atol=1e-9)
    assert runs["away"].train_updates == runs["away"].frames_used == 0  # ... that sees nobody: no image is read
    assert runs["recording"].train_updates > 0
    same, rec = runs["file, as the recording"], runs["recording"]
    assert (same.train_updates, same.frames_used, same.train_frames) == (rec.train_updates, rec.frames_used,
                                                                         rec.train_frames)
