"""Write-then-read round trips of rosbag2 recordings: identical message by message."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from fusiontrack.io.recording import Recording
from fusiontrack.io.writer import RecordingWriter, default_topic, write_recording
from fusiontrack.types import (
    CameraInfo,
    DepthImage,
    GroundTruth,
    Image,
    ImuSample,
    LaserScan,
    Odometry,
    Transform,
    records_equal,
)


def sample_records(rng: np.random.Generator, t0: int = 1_700_000_000_000_000_000) -> list:
    """One of every record type, with awkward values: NaN/inf ranges, NaN depth, missing gyro."""
    ranges = (rng.random(541) * 10).astype(np.float32)
    ranges[[3, 50]] = np.nan
    ranges[7] = np.inf
    ranges[9] = 0.0
    depth = np.where(rng.random((48, 64)) > 0.3, rng.random((48, 64)) * 4, np.nan)
    q = np.array([0.0, 0.0, np.sin(0.3), np.cos(0.3)])
    return [
        LaserScan(t0 + 10, "laser_front", "laser_front", -2.35619, 0.00872665, 0.02, 30.0, ranges,
                  intensities=rng.random(541) * 100, time_increment_s=1e-4, scan_time_s=0.025),
        LaserScan(t0 + 20, "laser_rear", "laser_rear", -1.5, 0.01, 0.02, 5.6, ranges[:300]),
        Image(t0 + 30, "cam0", "cam0_optical", rng.integers(0, 256, (48, 64, 3), dtype=np.uint8), "bgr8"),
        Image(t0 + 31, "cam0", "cam0_optical", rng.integers(0, 256, (48, 64, 3), dtype=np.uint8), "rgb8"),
        Image(t0 + 32, "cam1", "cam1_optical", rng.integers(0, 256, (48, 64), dtype=np.uint8), "mono8"),
        Image(t0 + 33, "cam1_labels", "cam1_optical", rng.integers(0, 65536, (48, 64), dtype=np.uint16), "mono16"),
        DepthImage(t0 + 40, "rgbd0", "rgbd0_optical", depth),
        ImuSample(t0 + 50, "phone_alice", "phone", [0.1, 0.2, 9.8], [0.01, 0.02, 0.03]),
        ImuSample(t0 + 51, "phone_alice", "phone", [0.1, 0.2, 9.8], orientation_xyzw=q),
        CameraInfo(t0 + 60, "cam0", "cam0_optical", 64, 48, [[50, 0, 32], [0, 50, 24], [0, 0, 1]],
                   [0.1, 0.01, 0.001, -0.001, 0.0]),
        Odometry(t0 + 70, "robot", "odom", "base_link", [1, 2, 3], q, [1, 0, 0], [0, 0, 0.1]),
        Transform(t0 + 80, "/tf_static", "world", "laser_front", [1, 2, 0.2], q, True),
        Transform(t0 + 81, "/tf", "world", "base_link", [1, 2, 0], [0, 0, 0, 1], False),
        GroundTruth(t0 + 90, "ground_truth", "world", [1, 2, 3], rng.random((3, 2)), rng.random((3, 2)),
                    ("person", "bicycle", "car"),
                    {"height_m": np.array([1.7, 1.6, 1.4]), "situation": np.array([0, 1, 2], np.int8),
                     "box_px": rng.random((3, 4))}),
        GroundTruth(t0 + 91, "ground_truth", "world", np.zeros(0, np.int64), np.zeros((0, 2))),
    ]


def diff(a, b) -> list[str]:
    return [f.name for f in dataclasses.fields(a)
            if not records_equal(dataclasses.replace(a, **{f.name: getattr(b, f.name)}), a)]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_round_trip_is_identical_message_by_message(tmp_path, storage):
    records = sample_records(np.random.default_rng(1))
    path = tmp_path / "rec"
    assert write_recording(path, records, storage=storage) == len(records)
    with Recording(path) as rec:
        back = list(rec.messages())
        types = rec.topic_types()  # from the connections alone, before any counting pass
        topics = rec.topics()
    assert types == {t: i.msgtype for t, i in topics.items()}
    assert types["/laser_front/scan"] == "sensor_msgs/msg/LaserScan"
    assert len(back) == len(records)
    expected_counts: dict[str, int] = {}
    for r in records:
        topic = default_topic(r)
        expected_counts[topic] = expected_counts.get(topic, 0) + 1
    assert {t: i.count for t, i in topics.items()} == expected_counts
    assert topics["/laser_front/scan"].sensor == "laser_front"
    for a, b in zip(records, back, strict=True):
        assert records_equal(a, b), f"{type(a).__name__} differs in {diff(a, b)}"


def test_png_images_round_trip_losslessly(tmp_path):
    rng = np.random.default_rng(2)
    depth_mm = rng.integers(300, 4500, (40, 50)).astype(np.float32)
    depth_mm[rng.random((40, 50)) < 0.2] = np.nan
    records = [
        Image(100, "cam0", "cam0", rng.integers(0, 256, (40, 50, 3), dtype=np.uint8), "bgr8"),
        Image(101, "cam0", "cam0", rng.integers(0, 256, (40, 50, 3), dtype=np.uint8), "rgb8"),
        Image(102, "cam0", "cam0", rng.integers(0, 256, (40, 50), dtype=np.uint8), "mono8"),
        Image(104, "labels", "cam0", rng.integers(0, 65536, (40, 50), dtype=np.uint16), "mono16"),
        DepthImage(103, "rgbd", "rgbd", depth_mm / 1000.0),
    ]
    write_recording(tmp_path / "png", records, image_format="png")
    with Recording(tmp_path / "png") as rec:
        types = {t.msgtype for t in rec.topics().values()}
        back = list(rec.messages())
    assert types == {"sensor_msgs/msg/CompressedImage"}
    back_by_t = {r.t_ns: r for r in back}
    for a in records[:4]:
        assert records_equal(a, back_by_t[a.t_ns])
    # compressedDepth holds millimetres: equal to float32 rounding of mm / 1000
    depth_in, depth_out = records[4].depth_m, back_by_t[103].depth_m
    np.testing.assert_allclose(depth_out, depth_in, rtol=0, atol=1e-6)
    assert np.array_equal(np.isnan(depth_out), np.isnan(depth_in))


def test_writer_refuses_to_overwrite(tmp_path):
    from fusiontrack.errors import RecordingError

    (tmp_path / "exists").mkdir()
    with pytest.raises(RecordingError, match="exists"):
        RecordingWriter(tmp_path / "exists")


def test_log_time_differs_from_header_time(tmp_path):
    """A record written with a late log time is read back with its header stamp, or its log time."""
    scan = sample_records(np.random.default_rng(3))[0]
    with RecordingWriter(tmp_path / "r") as w:
        w.write(scan, log_t_ns=scan.t_ns + 5_000_000)
    with Recording(tmp_path / "r") as rec:
        (by_header,) = rec.messages()
        (by_log,) = rec.messages(time_source="log")
    assert by_header.t_ns == scan.t_ns
    assert by_log.t_ns == scan.t_ns + 5_000_000


def test_log_time_restamps_every_transform_of_a_tf_message(tmp_path):
    """A TFMessage carries one header per transform: with ``time_source="log"`` each transform read from it takes
    the message's log time, as every other record does (else a /tf pose and the scan it belongs to, logged
    together, would be looked up at different times)."""
    tf = next(r for r in sample_records(np.random.default_rng(4)) if isinstance(r, Transform) and not r.static)
    with RecordingWriter(tmp_path / "r") as w:
        w.write(tf, log_t_ns=tf.t_ns + 7_000_000)
    with Recording(tmp_path / "r") as rec:
        (by_header,) = rec.messages()
        (by_log,) = rec.messages(time_source="log")
    assert by_header.t_ns == tf.t_ns
    assert by_log.t_ns == tf.t_ns + 7_000_000
    assert records_equal(dataclasses.replace(by_log, t_ns=tf.t_ns), tf)


@pytest.mark.parametrize("kind", ["scan", "imu"])  # the laser's fast reader and the generic one
def test_zero_header_stamps_take_the_log_time_and_say_so(tmp_path, caplog, kind):
    recs = sample_records(np.random.default_rng(4))
    record = recs[0] if kind == "scan" else recs[7]
    t0 = record.t_ns
    with RecordingWriter(tmp_path / "r") as w:
        for k in range(4):  # two stamped, then two a driver left unstamped
            stamped = k < 2
            w.write(dataclasses.replace(record, t_ns=t0 + k if stamped else 0), log_t_ns=t0 + 1000 + k)
    with caplog.at_level("WARNING", logger="fusiontrack"), Recording(tmp_path / "r") as rec:
        got = [m.t_ns for m in rec.messages()]
    assert got == [t0, t0 + 1, t0 + 1002, t0 + 1003]
    (msg,) = [r.getMessage() for r in caplog.records if "header stamps of 0" in r.getMessage()]
    assert f"{default_topic(record)}: 2 of 4 messages" in msg
    assert "two clocks" in msg


def test_a_topic_never_stamped_takes_the_log_time_without_a_warning(tmp_path, caplog):
    scan = sample_records(np.random.default_rng(5))[0]
    with RecordingWriter(tmp_path / "r") as w:
        for k in range(3):
            w.write(dataclasses.replace(scan, t_ns=0), log_t_ns=scan.t_ns + k)
    with caplog.at_level("INFO", logger="fusiontrack"), Recording(tmp_path / "r") as rec:
        assert [m.t_ns for m in rec.messages()] == [scan.t_ns, scan.t_ns + 1, scan.t_ns + 2]
    said = [r for r in caplog.records if "header stamps of 0" in r.getMessage()]
    assert [r.levelname for r in said] == ["INFO"]
    assert "3 of 3 messages" in said[0].getMessage()


def test_a_folders_one_mcap_file_given_alone_is_read_with_the_folders_sensor_map(tmp_path):
    """``road/road.mcap`` (the README's ``site.mcap``) is read as its folder ``road``: the sensor map is in the
    folder's metadata.yaml. Read without it, each topic was its own sensor: a camera's images lost their
    CameraInfo, and the traffic and wearable pipelines dropped every camera without a word."""
    recs = sample_records(np.random.default_rng(6))
    image = next(r for r in recs if isinstance(r, Image))
    with RecordingWriter(tmp_path / "site") as w:
        w.write(image, topic="/front/image")
    (mcap,) = (tmp_path / "site").glob("*.mcap")
    for given in (tmp_path / "site", mcap):
        with Recording(given) as rec:
            assert rec.sensor_of("/front/image") == image.sensor
            assert rec.paths == [tmp_path / "site"]
    # a loose MCAP file (no folder metadata listing it) is read as itself
    loose = tmp_path / "loose.mcap"
    loose.write_bytes(mcap.read_bytes())
    with Recording(loose) as rec:
        assert rec.paths == [loose]
        assert rec.sensor_of("/front/image") == "/front/image"


@pytest.mark.parametrize("name", ["out.mcap", "out.db3", "out.bag"])
def test_a_recording_named_like_a_file_is_refused(tmp_path, name):
    """A rosbag2 recording is a folder: -o out.mcap made a folder out.mcap holding out.mcap.mcap."""
    from fusiontrack.errors import RecordingError

    with pytest.raises(RecordingError, match=r"written as a rosbag2 folder .* name the folder, e.g. .*out$"):
        RecordingWriter(tmp_path / name)
    assert not (tmp_path / name).exists()


def test_a_topic_never_stamped_beside_topics_on_another_clock_is_warned_of(tmp_path, caplog):
    """leg_tracker's training bags: the scans carry 2014 header stamps, logged in 2015, and the cluster positions
    carry none, so they took the 2015 log times: converted, a 380-day recording whose labels paired with no scan."""
    recs = sample_records(np.random.default_rng(5))
    scan, imu = recs[0], recs[7]
    day = 86_400 * 10**9
    with RecordingWriter(tmp_path / "r") as w:
        for k in range(3):
            w.write(dataclasses.replace(scan, t_ns=scan.t_ns + k), log_t_ns=scan.t_ns + 380 * day + k)
            w.write(dataclasses.replace(imu, t_ns=0), log_t_ns=scan.t_ns + 380 * day + k)
    with caplog.at_level("WARNING", logger="fusiontrack"), Recording(tmp_path / "r") as rec:
        list(rec.messages())
    (msg,) = [r.getMessage() for r in caplog.records if "two clocks" in r.getMessage()]
    assert f"{default_topic(imu)}: never stamped" in msg
    assert f"the header times of {default_topic(scan)} are up to 380.0 days from their log times" in msg
    assert "--time log" in msg
    caplog.clear()
    with caplog.at_level("WARNING", logger="fusiontrack"), Recording(tmp_path / "r") as rec:
        list(rec.messages(time_source="log"))  # one clock: nothing to say
    assert not [r for r in caplog.records if "two clocks" in r.getMessage()]


def _lasers_and_camera(rec: Recording) -> tuple[list[str], str]:
    """A simulated recording's laser topics and its camera's image topic."""
    lasers = [t for t, i in rec.topic_types().items() if i == "sensor_msgs/msg/LaserScan"]
    image = rec.image_topic()
    assert lasers
    assert image
    return lasers, image


@pytest.mark.parametrize("order", ["scans first", "images first", "alternate"])
def test_one_pass_for_scans_and_raw_images_reads_what_two_passes_read(simulated, order):
    """``messages_and_raw``: one pass over a simulated recording (lasers and a camera sharing the file's chunks)
    gives its two readers what two passes give, however the two readers take turns: the converted scans of
    :meth:`Recording.messages`, and every image's raw record in log-time order."""
    path = simulated("crowd", seconds=1.5, seed=1)
    with Recording(path) as rec:
        lasers, image = _lasers_and_camera(rec)
        want_scans = list(rec.messages(lasers))
        want_raw = [(c.topic, t, bytes(d)) for c, t, d in rec._raw(rec.select([image]))]
        assert len(want_raw) >= 10
        assert len(want_scans) >= 20
        scans, raw = rec.messages_and_raw(lasers, [image], keep_ns=10**12)
        got_scans: list = []
        got_raw: list = []
        if order == "scans first":
            got_scans, got_raw = list(scans), list(raw)
        elif order == "images first":
            got_raw, got_scans = list(raw), list(scans)
        else:
            for item in raw:
                got_raw.append(item)
                got_scans.extend(itertools.islice(scans, 3))
            got_scans.extend(scans)
    assert [(c.topic, t, bytes(d)) for c, t, d in got_raw] == want_raw
    assert len(got_scans) == len(want_scans)
    assert all(records_equal(a, b) for a, b in zip(got_scans, want_scans, strict=True))


def test_raw_records_nobody_takes_are_kept_only_for_keep_ns(simulated):
    """While only the scans are read, the images read with them wait for the raw reader no longer than ``keep_ns``
    behind the newest image: what the raw reader gets after the last scan is the recording's last images, those
    within ``keep_ns`` of its last one (memory stays bounded however long nobody asks for an image)."""
    path = simulated("crowd", seconds=1.5, seed=1)
    keep_ns = 300_000_000
    with Recording(path) as rec:
        lasers, image = _lasers_and_camera(rec)
        want = [t for _, t, _ in rec._raw(rec.select([image]))]
        scans, raw = rec.messages_and_raw(lasers, [image], keep_ns=keep_ns)
        assert sum(1 for _ in scans) > 0
        got = [t for _, t, _ in raw]
    assert got == [t for t in want if want[-1] - t <= keep_ns]
    assert 1 < len(got) < len(want)


def test_the_raw_reader_pauses_rather_than_read_far_ahead_of_the_scans(simulated):
    """A raw reader that runs ahead (images taken while nobody takes the scans, as when a camera stops sending and
    its reader looks for the next image) must not read on and queue the rest of the recording's scans: once the
    scans it has read for the other reader span more than ``keep_ns``, it yields None; when scans are taken it
    goes on, and every image still comes through, in order."""
    path = simulated("crowd", seconds=1.5, seed=1)
    keep_ns = 200_000_000
    with Recording(path) as rec:
        lasers, image = _lasers_and_camera(rec)
        want = [t for _, t, _ in rec._raw(rec.select([image]))]
        scan_times = [m.t_ns for m in rec.messages(lasers, time_source="log")]
        scans, raw = rec.messages_and_raw(lasers, [image], time_source="log", keep_ns=keep_ns)
        got: list[int] = []
        taken = 0
        pauses = 0
        for item in raw:
            if item is None:  # paused: the scans read ahead span more than keep_ns
                pauses += 1
                assert got
                assert got[-1] - scan_times[taken] > keep_ns - 100_000_000  # (images come every 67 ms)
                for _ in range(10):
                    if next(scans, None) is not None:
                        taken += 1
                continue
            got.append(item[1])
    assert got == want
    assert pauses >= 3
