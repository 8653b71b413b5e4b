"""Every bag in ../shared/data is read and the facts its README states are checked."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from fusiontrack.geometry import scan_to_points
from fusiontrack.io.recording import Recording
from fusiontrack.types import DepthImage, GroundTruth, Image, LaserScan


def scans_of(rec: Recording, topic: str) -> list[LaserScan]:
    return list(rec.messages([topic]))


def check_scan_geometry(scan: LaserScan, n_beams: int, deg_min: float, deg_max: float, step_deg: float):
    assert scan.n_beams == n_beams
    assert math.degrees(scan.angle_min_rad) == pytest.approx(deg_min, abs=0.1)
    assert math.degrees(scan.angle_max_rad) == pytest.approx(deg_max, abs=step_deg + 0.05)
    last_beam = scan.angles_rad()[-1]
    assert math.degrees(last_beam) == pytest.approx(deg_max, abs=step_deg + 0.05)  # within one beam
    assert math.degrees(scan.angle_increment_rad) == pytest.approx(step_deg, abs=0.001)


def test_leg_tracker_demo_bag(shared_data):
    """README: 126 s, /scan x1265 @10 Hz, 512 beams, -90..+90 deg (0.352 deg), 0.02–5.6 m, frame laser."""
    with Recording(shared_data / "laser/leg_tracker_demo/demo_stationary_simple_environment.bag") as rec:
        info = rec.topics()["/scan"]
        assert info.msgtype == "sensor_msgs/msg/LaserScan"
        assert info.count == 1265
        assert info.rate_hz == pytest.approx(10.0, rel=0.02)
        assert rec.duration_s == pytest.approx(126.0, abs=0.5)
        scans = scans_of(rec, "/scan")
    assert len(scans) == 1265
    first = scans[0]
    check_scan_geometry(first, 512, -90.0, 90.0, 0.352)
    assert (first.range_min_m, first.range_max_m) == (pytest.approx(0.02), pytest.approx(5.6))
    assert {s.frame_id for s in scans} == {"laser"}
    assert {s.sensor for s in scans} == {"/scan"}
    # Header stamps are in time order and 0.1 s apart on average.
    t = np.array([s.t_ns for s in scans])
    assert np.all(np.diff(t) > 0)
    assert np.median(np.diff(t)) / 1e9 == pytest.approx(0.1, rel=0.05)
    # Valid points lie within the stated range; invalid beams become NaN rows.
    pts = scan_to_points(first)
    r = np.hypot(pts[:, 0], pts[:, 1])
    valid = ~np.isnan(r)
    assert valid.sum() > 100
    assert np.all((r[valid] > 0.02) & (r[valid] < 5.6))


def test_leg_tracker_training_bags(shared_data):
    training = shared_data / "laser/leg_tracker_demo/training"
    with Recording(training / "positive_1_extracted.bag") as rec:
        topics = rec.topics()
        assert topics["/training_scan"].count == 197
        assert topics["/leg_cluster_positions"].count == 197
        scans = scans_of(rec, "/training_scan")
        labels = list(rec.messages(["/leg_cluster_positions"]))
    assert {s.n_beams for s in scans} == {768}
    assert {s.frame_id for s in scans} == {"right_laser"}
    assert all(isinstance(g, GroundTruth) for g in labels)
    counts = [len(g) for g in labels]
    assert min(counts) >= 1
    assert max(counts) <= 3

    with Recording(training / "positive_1.bag") as rec:
        info = rec.topics()["right_scan"]
        assert info.count == 400
        assert info.rate_hz == pytest.approx(7.5, rel=0.05)
        scan = next(iter(rec.messages(["right_scan"])))
    assert scan.n_beams == 768
    fov = math.degrees(scan.angle_max_rad - scan.angle_min_rad)
    assert fov == pytest.approx(270.0, abs=1.0)

    with Recording(training / "negative_2.bag") as rec:
        topics = rec.topics()
        assert {t: topics[t].count for t in ("/left_scan", "/rear_scan", "/right_scan")} == {
            "/left_scan": 435, "/rear_scan": 435, "/right_scan": 434}
        assert rec.duration_s == pytest.approx(57.8, abs=0.1)
        for name in ("/left_scan", "/rear_scan", "/right_scan"):
            assert topics[name].rate_hz == pytest.approx(7.5, rel=0.05)
        scans = list(rec.messages())
    assert {s.n_beams for s in scans} == {768}
    assert len(scans) == 1304
    # Three lasers interleave in log order.
    assert {s.sensor for s in scans[:6]} == {"/left_scan", "/rear_scan", "/right_scan"}


@pytest.mark.slow
def test_outdoor_bag_annotations(outdoor_bag, shared_data):
    """README: 720 s; /scan_base2 7170 scans @10 Hz, 245 beams, -34.5..+51.3 deg at 0.352 deg;
    person id 2 annotated on 6179 scans; the Person messages after scan k belong to scan k."""
    with Recording(outdoor_bag) as rec:
        topics = rec.topics()
        assert rec.duration_s == pytest.approx(720.0, abs=1.0)
        assert topics["/scan_base2"].count == 7170
        assert topics["/scan_base2"].rate_hz == pytest.approx(10.0, rel=0.02)
        assert topics["/ground_truth_people_tracks"].msgtype == "leg_tracker/msg/Person"
        assert topics["/ground_truth_people_tracks"].count == 6179
        assert not topics["/visualization_marker"].convertible
        stream = list(rec.messages(["/scan_base2", "/ground_truth_people_tracks"], time_source="log"))
    scans = [m for m in stream if isinstance(m, LaserScan)]
    check_scan_geometry(scans[0], 245, -34.5, 51.3, 0.352)

    # Apply the authors' rule: annotations that follow scan k in the bag belong to scan k.
    annotated: dict[int, GroundTruth] = {}
    k = -1
    for m in stream:
        if isinstance(m, LaserScan):
            k += 1
        else:
            annotated[k] = m
    assert len(annotated) == 6179
    assert {int(g.ids[0]) for g in annotated.values()} == {2}

    # ... and it agrees with the extracted ground_truth.csv, scan index by scan index.
    with open(shared_data / "laser/leg_tracker_outdoor/ground_truth.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 6179
    for row in rows[::97]:
        g = annotated[int(row["scan_index"])]
        assert g.positions_m[0] == pytest.approx([float(row["x"]), float(row["y"])], abs=1e-3)
        scan = scans[int(row["scan_index"])]
        assert scan.t_ns / 1e9 == pytest.approx(float(row["bag_time"]), abs=0.2)
    dist = np.hypot(*np.array([g.positions_m[0] for g in annotated.values()]).T)
    assert dist.min() > 0.6
    assert dist.max() < 2.8


def test_rgbd_bags_read_as_one_recording(shared_data):
    """README: 5 bags x 3 messages; 640x480 pinhole fx=fy~537, cx~320.7, cy~227.7; rgb8 colour;
    32FC1 depth in metres, ~33 % valid, 1.5–9.9 m."""
    bags = sorted((shared_data / "rgbd/tue_rgbd_people").glob("*.bag"))
    assert len(bags) == 5
    with Recording(bags) as rec:
        assert rec.message_count == 15
        records = list(rec.messages(time_source="log"))
        info = rec.topics()
    assert {t.count for t in info.values()} == {5}
    assert len(records) == 15
    infos = [r for r in records if type(r).__name__ == "CameraInfo"]
    images = [r for r in records if isinstance(r, Image)]
    depths = [r for r in records if isinstance(r, DepthImage)]
    assert (len(infos), len(images), len(depths)) == (5, 5, 5)
    for ci in infos:
        assert (ci.width, ci.height) == (640, 480)
        assert ci.K[0, 0] == pytest.approx(537, abs=2)
        assert ci.K[1, 1] == pytest.approx(537, abs=2)
        assert ci.K[0, 2] == pytest.approx(320.7, abs=0.5)
        assert ci.K[1, 2] == pytest.approx(227.7, abs=0.5)
    for im in images:
        assert im.encoding == "rgb8"
        assert im.pixels.shape == (480, 640, 3)
        assert im.pixels.std() > 10  # a real picture, not a blank frame
    for d in depths:
        assert d.depth_m.shape == (480, 640)
        valid = np.isfinite(d.depth_m) & (d.depth_m > 0)
        assert 0.2 < valid.mean() < 0.5
        assert np.nanmin(d.depth_m[valid]) > 1.0
        assert np.nanmax(d.depth_m[valid]) < 10.5
    # Five files, one stream: log times are merged into one ascending order.
    log_t = [r.t_ns for r in records]
    assert log_t == sorted(log_t)


def test_ros1_and_ros2_files_mix_in_one_recording(shared_data, tmp_path):
    from fusiontrack.io.writer import write_recording

    scan = LaserScan(1_556_880_154_500_000_000, "laser", "laser", -1.0, 0.01, 0.02, 5.0, np.ones(201))
    write_recording(tmp_path / "ros2", [scan])
    bag = shared_data / "rgbd/tue_rgbd_people/2019-05-03-12-42-34.bag"
    with Recording([bag, tmp_path / "ros2"]) as rec:
        assert set(rec.topics()) == {"/laser/scan", "/hero/head_rgbd_sensor/rgb/camera_info",
                                     "/hero/head_rgbd_sensor/rgb/image_raw",
                                     "/hero/head_rgbd_sensor/depth_registered/image"}
        out = list(rec.messages(time_source="log"))
    assert len(out) == 4
    assert [r.t_ns for r in out] == sorted(r.t_ns for r in out)
    assert any(isinstance(r, LaserScan) and r.sensor == "laser" for r in out)
