"""The people pipeline's overlay video (issue 6): laser points projected through the bias-corrected camera land on
the people, the tracks' boxes, one video frame per camera image.

Truth is the simulator's: a short ``crowd`` whose real camera is turned 3 degrees from its calibration (the
simulator's ``yaw_bias_deg``), its true floor positions (``/ground_truth``) and the true image box of every person
(``/ground_truth/camera_0``, drawn with the real camera pose).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.calibration.bias import BiasHistory
from fusiontrack.errors import ConfigError, RecordingError
from fusiontrack.geometry import TransformTree
from fusiontrack.io.recording import Recording
from fusiontrack.io.video import VideoReader
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.types import CameraInfo, Event, GroundTruth, LaserScan, TrackState
from fusiontrack.vision.people import camera_from_recording
from fusiontrack.viz.fused_overlay import (
    VEHICLE_MOVING_MPS,
    VEHICLE_SIZE_M,
    _vehicle_headings,
    bias_at,
    laser_points_world,
    person_boxes,
    project_points,
    render_fused_overlay,
    vehicle_boxes,
)

YAW_ERROR_DEG = 3.0  # the real camera is turned this much from its calibration; the learnt bias is +3 deg
WIDEN_PX = 1.0  # slack around the true boxes (pixel rounding of the rendered silhouette)


@pytest.fixture(scope="module")
def crowd(simulated) -> dict:
    """5 s of ``crowd`` with few people, camera 3 degrees off its calibration."""
    settings = {"cameras.0.yaw_bias_deg": YAW_ERROR_DEG, "agents.mean_present": 4}
    scenario = load_scenario("crowd").with_overrides(seconds=5, seed=0, settings=settings)
    path: Path = simulated("crowd", seconds=5, seed=0, settings=settings)
    corrections = {c.name: -round(c.clock_offset_ms * 1e6) for c in scenario.config.lasers}
    with Recording(path) as rec:
        gt = [g for g in rec.messages(["/ground_truth"]) if isinstance(g, GroundTruth)]
        boxes = [g for g in rec.messages(["/ground_truth/camera_0"]) if isinstance(g, GroundTruth)]
        scans = [s for s in rec.messages(["/laser_0/scan", "/laser_1/scan"]) if isinstance(s, LaserScan)]
        info = next(m for m in rec.messages(["/camera_0/camera_info"]) if isinstance(m, CameraInfo))
        tree = TransformTree()
        for tf in rec.messages(["/tf_static"]):
            tree.add_record(tf)
        believed = camera_from_recording(rec, "camera_0", "camera_0")  # the calibration the user is given
        n_images = rec.topics()["/camera_0/image"].count
    return {"path": path, "gt": gt, "boxes": boxes, "scans": scans, "info": info, "tree": tree, "camera": believed,
            "n_images": n_images, "corrections": corrections}


def _truth_states(gt: list[GroundTruth]) -> list[TrackState]:
    """The true people as track states (what a perfect tracker would give)."""
    return [TrackState(g.t_ns, "laser", int(i), xy, sensors=("laser",)) for g in gt for i, xy in
            zip(g.ids, g.positions_m, strict=True)]


def _visible_boxes(frame: GroundTruth) -> tuple[np.ndarray, np.ndarray]:
    """Ids and true boxes of the people at least half visible in a camera truth frame."""
    box = np.asarray(frame.attributes["box_px"], float).reshape(-1, 4)
    vis = np.asarray(frame.attributes["visibility"], float)
    ok = np.all(np.isfinite(box), axis=1) & (vis >= 0.5)
    return frame.ids[ok], box[ok]


def _leg_points_per_frame(crowd: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per camera truth frame: the laser returns (world, (n, 3)) within 0.4 m of a visible person, and the true
    boxes of all visible people. Scans: each laser's nearest in time (clock offsets corrected); poses: true."""
    poses = {name: crowd["tree"].get(name, "world") for name in ("laser_0", "laser_1")}
    scans = {name: [s for s in crowd["scans"] if s.sensor == name] for name in poses}
    scan_t = {name: np.array([s.t_ns + crowd["corrections"].get(name, 0) for s in v]) for name, v in scans.items()}
    gt_t = np.array([g.t_ns for g in crowd["gt"]])
    out = []
    for frame in crowd["boxes"]:
        t = int(frame.attributes["t_true_ns"][0]) if len(frame) else frame.t_ns
        ids, boxes = _visible_boxes(frame)
        if not len(ids):
            continue
        g = crowd["gt"][int(np.argmin(np.abs(gt_t - t)))]
        people = g.positions_m[np.isin(g.ids, ids)]
        pts = []
        for name in poses:
            k = int(np.argmin(np.abs(scan_t[name] - t)))
            if abs(scan_t[name][k] - t) <= 25_000_000:
                pts.append(laser_points_world(scans[name][k], poses[name]))
        if not pts:
            continue
        p = np.concatenate(pts)
        near = np.linalg.norm(p[:, None, :2] - people[None], axis=2).min(axis=1) < 0.4
        out.append((p[near], boxes))
    return out


def _share_inside(crowd: dict, legs: list, bias_rad: float) -> tuple[float, int]:
    inside = total = 0
    for pts, boxes in legs:
        proj = project_points(crowd["camera"], pts, bias_rad=bias_rad)
        u, v = proj.uv[:, 0, None], proj.uv[:, 1, None]
        hit = ((u >= boxes[None, :, 0] - WIDEN_PX) & (u <= boxes[None, :, 2] + WIDEN_PX)
               & (v >= boxes[None, :, 1] - WIDEN_PX) & (v <= boxes[None, :, 3] + WIDEN_PX)).any(axis=1)
        inside += int(hit.sum())
        total += len(proj)
    return inside / max(total, 1), total


def test_leg_points_projected_with_the_true_bias_land_on_the_true_boxes(crowd):
    legs = _leg_points_per_frame(crowd)
    assert len(legs) > 40
    right, n_right = _share_inside(crowd, legs, math.radians(YAW_ERROR_DEG))
    wrong, _ = _share_inside(crowd, legs, 0.0)  # the calibration as believed
    assert n_right > 500
    assert right >= 0.95
    assert wrong <= right - 0.25
    # a correction the wrong way round doubles the error: the points miss the people
    assert _share_inside(crowd, legs, -math.radians(YAW_ERROR_DEG))[0] <= 0.2


def test_person_cylinder_boxes_through_the_corrected_camera_cover_the_true_boxes(crowd):
    gt_t = np.array([g.t_ns for g in crowd["gt"]])
    iou = {0.0: [], math.radians(YAW_ERROR_DEG): []}
    for frame in crowd["boxes"][::3]:
        ids, true_box = _visible_boxes(frame)
        t = int(frame.attributes["t_true_ns"][0]) if len(frame) else frame.t_ns
        g = crowd["gt"][int(np.argmin(np.abs(gt_t - t)))]
        pos = np.array([g.positions_m[np.flatnonzero(g.ids == i)[0]] for i in ids]).reshape(-1, 2)
        for bias in iou:
            b = person_boxes(crowd["camera"].with_yaw_offset(bias), pos)
            lo, hi = np.maximum(b[:, :2], true_box[:, :2]), np.minimum(b[:, 2:], true_box[:, 2:])
            inter = np.clip(hi - lo, 0, None).prod(axis=1)
            union = (b[:, 2:] - b[:, :2]).prod(axis=1) + (true_box[:, 2:] - true_box[:, :2]).prod(axis=1) - inter
            iou[bias].extend(inter / union)
    right, wrong = np.median(iou[math.radians(YAW_ERROR_DEG)]), np.median(iou[0.0])
    assert len(iou[0.0]) > 40
    assert right > 0.5
    assert right > wrong + 0.2


def _iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    lo, hi = np.maximum(a[:, :2], b[:, :2]), np.minimum(a[:, 2:], b[:, 2:])
    inter = np.clip(hi - lo, 0, None).prod(axis=1)
    return inter / ((a[:, 2:] - a[:, :2]).prod(axis=1) + (b[:, 2:] - b[:, :2]).prod(axis=1) - inter)


def test_a_vehicle_track_is_drawn_as_its_cuboid_and_covers_the_true_box(simulated):
    """Against the simulator's true image boxes of the cars and bicycles of a road (fully visible, inside the
    image): the cuboid of the true size and heading covers them; so does the one the overlay draws for a track (its
    class's size, along its velocity, or its last heading while it is stopped in the jam); a person's cylinder
    would not."""
    path = simulated("road", seconds=16.0, seed=0)  # the traffic pipeline tests' recording
    with Recording(path) as rec:
        gt = {g.t_ns: g for g in rec.messages(["/ground_truth"]) if isinstance(g, GroundTruth)}
        frames = [f for f in rec.messages(["/ground_truth/camera_0"]) if isinstance(f, GroundTruth)]
        cam = camera_from_recording(rec, "camera_0", "camera_0")
    gt_t = np.array(sorted(gt))
    iou: dict[str, list[float]] = {"truth": [], "track": [], "slow": [], "person": []}
    memory: dict[int, float] = {}
    for f in frames:
        g = gt[gt_t[np.argmin(np.abs(gt_t - int(f.attributes["t_true_ns"][0])))]] if len(f) else None
        box = np.asarray(f.attributes["box_px"], float).reshape(-1, 4)
        vis = np.asarray(f.attributes["visibility"], float)
        for k, agent in enumerate(f.ids):
            j = np.flatnonzero(g.ids == agent) if g is not None else []
            if len(j) != 1 or g.classes[j[0]] == "person":
                continue
            j = j[0]
            state = TrackState(f.t_ns, "laser", int(agent), g.positions_m[j], g.velocities_mps[j], cls=g.classes[j])
            heading = _vehicle_headings([state], memory)  # the track's heading, as the video draws it
            inside = np.isfinite(box[k]).all() and box[k, 0] >= 0 and box[k, 1] >= 0 and box[k, 2] <= cam.width \
                and box[k, 3] <= cam.height
            if vis[k] < 0.95 or not inside:
                continue
            true = vehicle_boxes(cam, g.positions_m[j], [g.attributes["heading_rad"][j]], g.attributes["size_m"][j])
            drawn = vehicle_boxes(cam, g.positions_m[j], heading, VEHICLE_SIZE_M[state.cls])
            iou["truth"].append(_iou(true, box[k:k + 1])[0])
            iou["track"].append(_iou(drawn, box[k:k + 1])[0])
            if np.hypot(*g.velocities_mps[j]) < VEHICLE_MOVING_MPS:
                iou["slow"].append(iou["track"][-1])
            iou["person"].append(_iou(person_boxes(cam, g.positions_m[j][None]), box[k:k + 1])[0])
    assert len(iou["track"]) > 200
    # the jam: vehicles at a standstill, drawn along their last heading (this road runs along x, as a track that
    # never moved would be drawn: the memory itself is tested in test_vehicle_boxes_headings_and_bad_input)
    assert len(iou["slow"]) > 20
    assert np.median(iou["truth"]) > 0.95
    assert np.min(iou["truth"]) > 0.8
    assert np.median(iou["track"]) > 0.85
    assert np.min(iou["track"]) > 0.7
    assert np.median(iou["slow"]) > 0.85
    assert np.median(iou["person"]) < 0.3


def test_vehicle_boxes_headings_and_bad_input(crowd):
    cam = crowd["camera"]
    axis = cam.cam2world[:2, 2] / np.linalg.norm(cam.cam2world[:2, 2])  # the optical axis on the floor
    ahead = cam.cam2world[:2, 3] + 12.0 * axis
    size = (4.5, 1.8, 1.5)
    across = vehicle_boxes(cam, ahead, [math.atan2(axis[0], -axis[1])], size)[0]  # driving across the view
    along = vehicle_boxes(cam, ahead, [math.atan2(axis[1], axis[0])], size)[0]  # driving away
    assert across[2] - across[0] > 1.5 * (along[2] - along[0])
    behind = cam.cam2world[:2, 3] - 12.0 * axis
    assert np.isnan(vehicle_boxes(cam, [behind, [np.nan, 0.0]], [0.0, 0.0], [size, size])).all()
    assert vehicle_boxes(cam, np.zeros((0, 2)), [], np.zeros((0, 3))).shape == (0, 4)
    with pytest.raises(ValueError, match="sizes_m"):
        vehicle_boxes(cam, [ahead, ahead], [0.0, 0.0], [size])
    # headings: the velocity's while moving, the last moving one when stopped, the x axis before it ever moved
    memory: dict[int, float] = {}

    def car(tid: int, v: tuple[float, float]) -> TrackState:
        return TrackState(0, "laser", tid, np.zeros(2), np.array(v), cls="car")

    assert _vehicle_headings([car(1, (0.0, 3.0)), car(2, (0.1, 0.1))], memory) == pytest.approx([math.pi / 2, 0.0])
    assert _vehicle_headings([car(1, (0.0, 0.0)), car(2, (-2.0, 0.0))], memory) == pytest.approx([math.pi / 2, math.pi])


def test_bias_at_is_the_value_at_or_before_and_zero_before_the_first_update():
    h = BiasHistory(np.array([100, 200, 300]), np.array([0.01, 0.02, 0.03]), np.ones(3, np.int64), np.zeros(3))
    np.testing.assert_array_equal(bias_at(h, [0, 99, 100, 150, 200, 299, 300, 10**12]),
                                  [0.0, 0.0, 0.01, 0.01, 0.02, 0.02, 0.03, 0.03])
    assert bias_at(None, 5) == 0.0
    assert float(bias_at(h, 250)) == 0.02


def test_a_bias_the_pipeline_did_not_apply_is_not_drawn():
    # The pipeline fuses through the calibrated camera when it did not apply the learnt bias: the overlay draws
    # that camera (bias 0) while and after learning; an applied one is drawn live, then final.
    from types import SimpleNamespace

    from fusiontrack.viz.fused_overlay import _bias_source

    h = BiasHistory(np.array([100, 200, 300]), np.array([0.01, 0.02, 0.03]), np.ones(3, np.int64), np.zeros(3))
    kept = _bias_source(SimpleNamespace(history=h, settled=False, applied=False))
    assert [kept.at(t)[0] for t in (150, 250, 400)] == [0.0, 0.0, 0.0]
    assert "not applied" in kept.at(400)[1]
    applied = _bias_source(SimpleNamespace(history=h, settled=True, applied=True))
    assert [applied.at(t)[0] for t in (50, 150, 400)] == [0.0, 0.01, 0.03]
    assert "learning" in applied.at(150)[1]
    assert "settled" in applied.at(400)[1]
    whole_run = _bias_source(SimpleNamespace(history=h))  # a BiasRun: learnt to the end, no settled flag
    assert "live" in whole_run.at(250)[1]


def test_projection_drops_nan_and_points_behind_the_camera(crowd):
    cam = crowd["camera"]
    ahead = cam.backproject_to_floor(np.array([[320.0, 400.0]]))[0]
    behind = 2 * cam.position_m - ahead  # mirrored through the camera centre
    proj = project_points(cam, np.array([ahead, [np.nan] * 3, behind]))
    assert proj.index.tolist() == [0]
    np.testing.assert_allclose(proj.uv[0], [320.0, 400.0], atol=1e-6)
    np.testing.assert_allclose(proj.range_m[0], np.linalg.norm(ahead - cam.position_m))
    scan = crowd["scans"][0]
    ranges = np.array(scan.ranges_m, np.float32)
    ranges[::2] = np.nan
    nan_scan = LaserScan(scan.t_ns, scan.sensor, scan.frame_id, scan.angle_min_rad, scan.angle_increment_rad,
                         scan.range_min_m, scan.range_max_m, ranges)
    pts = laser_points_world(nan_scan, crowd["tree"].get(scan.sensor, "world"))
    assert np.isfinite(pts).all()
    assert len(pts) <= ranges.size // 2
    np.testing.assert_allclose(pts[:, 2], crowd["tree"].get(scan.sensor, "world")[2, 3])  # at the laser's height


def test_video_has_one_frame_per_camera_image_at_the_image_size(crowd, tmp_path):
    t0 = crowd["gt"][0].t_ns
    history = BiasHistory(np.array([t0 + 1_000_000_000]), np.array([math.radians(YAW_ERROR_DEG)]),
                          np.ones(1, np.int64), np.zeros(1))
    events = [Event(t0 + 2_000_000_000, "laser", "merge", t0 + 2_500_000_000, track_ids=(1, 3))]
    out = tmp_path / "overlay.mp4"
    result = render_fused_overlay(crowd["path"], out, _truth_states(crowd["gt"]), camera="camera_0",
                                  bias_history=history, events=events,
                                  clock_corrections_ns=crowd["corrections"])
    info = crowd["info"]
    assert result.frames == crowd["n_images"]
    assert result.size_px == (info.width, info.height)
    assert result.lasers == ("laser_0", "laser_1")
    assert result.frames_with_points == result.frames
    assert result.frames_with_tracks >= result.frames - 2  # somebody is always in the hall
    with VideoReader(out) as video:
        assert (video.width, video.height) == (info.width, info.height)
        assert sum(1 for _ in video) == crowd["n_images"]


def test_frames_without_scans_are_just_the_image_and_max_frames_stops(crowd, tmp_path):
    result = render_fused_overlay(crowd["path"], tmp_path / "bare.mp4", lasers=(), max_frames=10)
    assert result.frames == 10
    assert result.lasers == ()
    assert result.frames_with_points == 0
    assert result.frames_with_tracks == 0


def test_a_recording_without_that_camera_names_the_camera_and_the_topics(crowd, tmp_path):
    with pytest.raises(RecordingError, match=r"camera 'camera_9'.*image topics: /camera_0/image \(camera camera_0\)"):
        render_fused_overlay(crowd["path"], tmp_path / "x.mp4", camera="camera_9")
    with pytest.raises(RecordingError, match="image_topic '/camera_0/camera_info'"):
        render_fused_overlay(crowd["path"], tmp_path / "x.mp4", image_topic="/camera_0/camera_info")
    with pytest.raises(RecordingError, match="laser_7"):
        render_fused_overlay(crowd["path"], tmp_path / "x.mp4", lasers=["laser_7"])
    with pytest.raises(ConfigError, match="colour_by"):
        render_fused_overlay(crowd["path"], tmp_path / "x.mp4", colour_by="speed")
    with pytest.raises(ConfigError, match="bias_history"):
        render_fused_overlay(crowd["path"], tmp_path / "x.mp4", bias_history=3.0)
