"""Bad input gives a FusiontrackError subclass that names what and where; the CLI prints one line."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from fusiontrack.config import load_config, parse_config
from fusiontrack.errors import ConfigError, FusiontrackError, MessageTypeError, RecordingError, TopicError
from fusiontrack.io.recording import Recording
from fusiontrack.io.writer import RecordingWriter, write_recording
from fusiontrack.sim.scenario import parse_scenario
from fusiontrack.types import LaserScan

DEMO = "laser/leg_tracker_demo/demo_stationary_simple_environment.bag"


def test_missing_file_names_the_path(tmp_path):
    missing = tmp_path / "nowhere.bag"
    with pytest.raises(RecordingError, match=r"nowhere\.bag"):
        Recording(missing)


def test_a_file_that_is_not_a_bag(tmp_path):
    text = tmp_path / "notes.bag"
    text.write_text("this is not a rosbag\n")
    with pytest.raises(RecordingError, match=r"notes\.bag"):
        Recording(text)
    other = tmp_path / "notes.txt"
    other.write_text("hello")
    with pytest.raises(RecordingError, match=r"notes\.txt.*expected a ROS 1 \.bag"):
        Recording(other)


def test_a_recording_given_twice_is_refused(tmp_path):
    """The same recording twice (by the same path, another spelling of it, a rosbag2 folder and its .mcap, or a
    copy) would be merged with itself; two different recordings (the next piece of it) still merge."""
    scans = [LaserScan(i * 100_000_000, "laser", "laser", -1.0, 0.01, 0.02, 5.0, np.ones(21)) for i in range(1, 4)]
    write_recording(tmp_path / "rec", scans)
    write_recording(tmp_path / "other", scans)  # a copy
    write_recording(tmp_path / "next", [LaserScan(s.t_ns + 300_000_000, "laser", "laser", -1.0, 0.01, 0.02, 5.0,
                                                  np.ones(21)) for s in scans])
    (mcap,) = (tmp_path / "rec").glob("*.mcap")
    for twice, message in (([tmp_path / "rec"] * 2, "rec is given twice"),
                           ([tmp_path / "rec", tmp_path / "other" / ".." / "rec"], "other/../rec are one recording"),
                           ([tmp_path / "rec", mcap], f"{mcap.name} are one recording"),
                           ([tmp_path / "rec", tmp_path / "other"], "other hold the same messages")):
        with pytest.raises(RecordingError, match=message):
            Recording(twice)
    with Recording([tmp_path / "rec", tmp_path / "next"]) as rec:
        assert rec.message_count == 6


def test_two_recordings_of_one_topic_over_the_same_time_are_warned_of(tmp_path, caplog):
    """Two scenes given together (two simulations start at the same instant) interleave their scans into one
    stream: tracked as one world. A warning names both; the next piece of a recording gives none."""
    def scans(start_ns: int, r: float) -> list[LaserScan]:
        return [LaserScan(start_ns + i * 100_000_000, "laser", "laser", -1.0, 0.01, 0.02, 5.0, np.full(21, r))
                for i in range(1, 4)]

    write_recording(tmp_path / "a", scans(0, 1.0))
    write_recording(tmp_path / "b", scans(50_000_000, 2.0))  # the same topic, overlapping in time
    write_recording(tmp_path / "c", scans(400_000_000, 3.0))  # after a: its next piece
    with caplog.at_level("WARNING"), Recording([tmp_path / "a", tmp_path / "b"]):
        pass
    assert "both hold /laser/scan over the same time" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING"), Recording([tmp_path / "a", tmp_path / "c"]):
        pass
    assert "both hold" not in caplog.text
    # two machines recording together: different sensors, and both the same transforms (not sensor data): no word
    from fusiontrack.types import Transform

    tf = [Transform(50_000_000 + i * 100_000_000, "tf", "world", "base", np.zeros(3), np.array([0, 0, 0, 1.0]))
          for i in range(1, 4)]
    write_recording(tmp_path / "m1", [*scans(0, 1.0), *tf])
    write_recording(tmp_path / "m2", [LaserScan(s.t_ns, "rear", "rear", -1.0, 0.01, 0.02, 5.0, np.ones(21))
                                      for s in scans(50_000_000, 2.0)] + tf)
    with caplog.at_level("WARNING"), Recording([tmp_path / "m1", tmp_path / "m2"]):
        pass
    assert "both hold" not in caplog.text


@pytest.mark.parametrize("keep", [0.5, 0.01])
def test_truncated_ros1_bag(shared_data, tmp_path, keep):
    src = shared_data / DEMO
    data = src.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(RecordingError, match=r"cut\.bag.*(complete|corrupt|truncated).*"
                       r'run "fusiontrack repair .*cut\.bag -o .*" to recover'), Recording(cut) as rec:
        list(rec.messages())


def test_truncated_mcap(tmp_path):
    scans = [LaserScan(i * 100_000_000, "laser", "laser", -1.0, 0.01, 0.02, 5.0, np.ones(201) * i)
             for i in range(1, 200)]
    write_recording(tmp_path / "rec", scans)
    (mcap,) = (tmp_path / "rec").glob("*.mcap")
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError, match=r"rec.*(complete|corrupt|truncated).*fusiontrack repair .*rec -o"), \
            Recording(tmp_path / "rec") as rec:
        list(rec.messages())


def test_unknown_topic_lists_what_is_there(shared_data):
    with Recording(shared_data / DEMO) as rec, pytest.raises(TopicError, match=r"'/scann'.*it has: /scan"):
        list(rec.messages(["/scann"]))


def test_topic_of_a_type_that_cannot_be_converted(outdoor_bag):
    with Recording(outdoor_bag) as rec:
        with pytest.raises(MessageTypeError, match=r"/visualization_marker \(visualization_msgs/msg/Marker\)"):
            list(rec.messages(["/visualization_marker"]))
        # ... but it can still be read raw.
        _topic, msgtype, _, msg = next(iter(rec.raw_messages(["/visualization_marker"])))
        assert msgtype == "visualization_msgs/msg/Marker"
        assert hasattr(msg, "pose")


def test_unparsable_custom_type_names_the_type(shared_data):
    with pytest.raises(MessageTypeError, match="my_pkg/msg/Broken"):
        Recording(shared_data / DEMO, custom_types={"my_pkg/msg/Broken": "this is not :: a definition"})


def test_custom_type_registered_from_a_definition_string(tmp_path):
    """A type unknown to any store is written and read back through a definition string."""
    definition = "std_msgs/Header header\nfloat64 x_m\nfloat64 y_m\nuint32 id\nstring label\n"
    with RecordingWriter(tmp_path / "c", custom_types={"my_pkg/msg/Marker2D": definition}) as w:
        t = w.typestore.types
        hdr = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=1, nanosec=5), frame_id="w")
        msg = t["my_pkg/msg/Marker2D"](header=hdr, x_m=1.5, y_m=-2.0, id=7, label="door")
        conn = w._writer.add_connection("/marks", "my_pkg/msg/Marker2D", typestore=w.typestore)
        w._writer.write(conn, 1_000_000_005, w.typestore.serialize_cdr(msg, "my_pkg/msg/Marker2D"))
    with Recording(tmp_path / "c", custom_types={"my_pkg/msg/Marker2D": definition}) as rec:
        ((topic, msgtype, t_ns, back),) = list(rec.raw_messages())
    assert (topic, msgtype, t_ns) == ("/marks", "my_pkg/msg/Marker2D", 1_000_000_005)
    assert (back.x_m, back.y_m, back.id, back.label) == (1.5, -2.0, 7, "door")


def test_config_value_of_the_wrong_type(tmp_path):
    cfg = tmp_path / "pipeline.toml"
    cfg.write_text('[sensors.laser_front]\nkind = "laser"\ntopic = "/scan"\npose = { x = "two metres" }\n')
    with pytest.raises(ConfigError, match=r"pipeline\.toml.*sensors\.laser_front\.pose\.x.*'two metres'"):
        load_config(cfg)


def test_config_errors_name_the_field():
    with pytest.raises(ConfigError, match=r"sensors\.cam\.kind.*'camra'"):
        parse_config({"sensors": {"cam": {"kind": "camra", "topic": "/image"}}})
    with pytest.raises(ConfigError, match=r"sync\.window_ms"):
        parse_config({"sync": {"window_ms": -5}})
    with pytest.raises(ConfigError, match=r"sensors\.l\.topc"):  # a typo is not silently ignored
        parse_config({"sensors": {"l": {"kind": "laser", "topc": "/scan"}}})


@pytest.mark.parametrize(("table", "field"), [
    ({"sync": {"window_ms": True}}, r"sync\.window_ms.*True"),  # (was read as 1 ms)
    ({"sync": {"window_ms": "200"}}, r"sync\.window_ms.*'200'"),  # (was read as 200)
    ({"sensors": {"l": {"kind": "laser", "topic": "/s", "clock_offset_ms": "35"}}}, r"sensors\.l\.clock_offset_ms"),
    ({"sensors": {"l": {"kind": "laser", "topic": "/s", "pose": {"yaw_deg": "90"}}}}, r"sensors\.l\.pose\.yaw_deg"),
    ({"sensors": {"l": {"kind": "laser", "topic": "/s", "pose": {"z": False}}}}, r"sensors\.l\.pose\.z"),
    ({"sensors": {"l": {"kind": "laser", "topic": "/s", "frame": "base_laser"}}}, r"sensors\.l\.frame"),  # (unused)
])
def test_config_numbers_are_numbers_and_nothing_is_accepted_unused(table, field):
    """A TOML boolean or string where a number belongs is refused, naming the field (pydantic's lax mode read
    true as 1 and "200" as 200); and a key nothing reads is not accepted."""
    with pytest.raises(ConfigError, match=field):
        parse_config(table)
    ints = parse_config({"sync": {"window_ms": 150}, "sensors": {"l": {"kind": "laser", "topic": "/s",
                                                                      "pose": {"x": 1, "yaw_deg": 45}}}})
    assert (ints.sync.window_ms, ints.sensors["l"].pose.x, ints.sensors["l"].pose.yaw_deg) == (150.0, 1.0, 45.0)


def test_a_sensor_clock_offset_beyond_a_day_is_refused_where_it_is_written():
    # 1e12 ms: the stamps passed int32 seconds and the writer raised struct.error, leaving a half-written recording
    scenario = {"lasers": [{"name": "laser_0", "x_m": 0.0, "y_m": 0.0, "rate_hz": 25.0, "clock_offset_ms": 1e12}]}
    with pytest.raises(ConfigError, match=r"scene\.toml: lasers\.0\.clock_offset_ms: .*86400000"):
        parse_scenario(scenario, "scene.toml")
    # a name makes topics and files: one with a space or a slash gave invalid topics and a file error
    scenario = {"lasers": [{"name": "laser 0/x", "x_m": 0.0, "y_m": 0.0, "rate_hz": 25.0}]}
    with pytest.raises(ConfigError, match=r"scene\.toml: lasers\.0\.name: .*pattern.*'laser 0/x'"):
        parse_scenario(scenario, "scene.toml")


def test_an_unknown_key_is_named_beside_the_known_ones():
    # the right spelling is in the message, at every depth: top-level table, sensor key, pose key
    with pytest.raises(ConfigError, match=r"trackin: unknown table \(known: .*\btracking\b"):
        parse_config({"trackin": {"max_speed": 2.0}})
    with pytest.raises(ConfigError, match=r"sensors\.l\.topc: unknown key \(known: .*\btopic\b"):
        parse_config({"sensors": {"l": {"kind": "laser", "topc": "/scan"}}})
    with pytest.raises(ConfigError, match=r"sensors\.l\.pose\.yaw: unknown key \(known: .*\byaw_deg\b"):
        parse_config({"sensors": {"l": {"kind": "laser", "topic": "/scan", "pose": {"yaw": 3}}}})
    # a sensor's name is what tracks.csv lists, joined by "|", as confirming a step: refused in the file, not at the
    # end of a run when the tracks are written
    for bad in ("front|back", " front", ""):
        with pytest.raises(ConfigError, match=r"pipeline\.toml: sensors: .*sensor name.*'\|'"):
            parse_config({"sensors": {bad: {"kind": "laser", "topic": "/scan"}}}, "pipeline.toml")
    with pytest.raises(ConfigError, match=r"scene\.toml: scenario\.duration: unknown key \(known: .*\bduration_s\b"):
        parse_scenario({"scenario": {"duration": 10}}, "scene.toml")


def test_config_file_problems(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[sensors\nkind = ")
    with pytest.raises(ConfigError, match=r"bad\.toml: not valid TOML"):
        load_config(bad)


def test_a_good_config_is_typed():
    cfg = parse_config({"sync": {"window_ms": 50}, "sensors": {
        "laser_front": {"kind": "laser", "topic": "/scan", "clock_offset_ms": -12.5,
                        "pose": {"x": 1.0, "yaw_deg": 90.0}}}})
    assert cfg.sync.window_ns == 50_000_000
    assert cfg.topics() == {"/scan": "laser_front"}
    assert cfg.clock_corrections_ns() == {"laser_front": 12_500_000}  # a clock 12.5 ms behind: add 12.5 ms
    T = cfg.sensors["laser_front"].pose.matrix()
    np.testing.assert_allclose(T[:3, :3] @ [1, 0, 0] + T[:3, 3], [1.0, 1.0, 0.0], atol=1e-12)


def test_every_error_is_a_fusiontrack_error():
    for cls in (RecordingError, TopicError, MessageTypeError, ConfigError):
        assert issubclass(cls, FusiontrackError)


def _cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fusiontrack", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["info", "nowhere.bag"], "nowhere.bag"),
        (["convert", "{demo}", "-o", "{out}", "-t", "/scann"], "/scann"),
        (["convert", "{demo}", "-o", "{out}", "--config", "{cfg}"], "window_ms"),
        (["convert", "{demo}", "{demo}", "-o", "{out}"], "demo_stationary_simple_environment.bag is given twice"),
        (["info", "{junk}"], "junk.bag"),
        # a pipeline file's [laser] and [tracking] tables: the file, the table and the key, before any reading
        (["track", "{demo}", "-o", "{out}", "-c", "{laser_typo}"], "laser_typo.toml: [laser]: unknown laser "
                                                                   "detector parameter(s) min_segmnt_points; known:"),
        (["track", "{demo}", "-o", "{out}", "-c", "{laser_neg}"], "[laser]: min_segment_points: expected an integer"),
        (["track", "{demo}", "-o", "{out}", "-c", "{laser_text}"], "[laser]: alpha: expected a number, got 'x'"),
        (["track", "{demo}", "-o", "{out}", "-c", "{tracking_typo}"], "tracking_typo.toml: [tracking]: unknown"),
        # every table is checked whatever the pipeline (a typo in one the run does not use was silently ignored),
        # and the errors of the tables read later name the file too
        (["track", "{demo}", "-o", "{out}", "-c", "{fusion_typo}"],
         "fusion_typo.toml: [fusion]: unknown key(s) check_margn"),
        (["track", "{demo}", "-o", "{out}", "-c", "{wearable_typo}", "--pipeline", "wearable"],
         "wearable_typo.toml: [wearable]: unknown option 'phone'"),
        (["track", "{demo}", "-o", "{out}", "-c", "{traffic_workers}", "--pipeline", "traffic"],
         "traffic_workers.toml: [traffic]: traffic.workers: expected an integer >= 0"),
        # a sensor's topic that the recording does not have: the file and the sensor's table
        (["track", "{demo}", "-o", "{out}", "-c", "{topic_missing}"],
         "topic_missing.toml: [sensors.front] topic '/nope' is not in"),
        (["track", "{demo}", "-o", "{out}", "-c", "{topic_missing}", "--pipeline", "traffic"],
         "topic_missing.toml: [sensors.front] topic '/nope' is not in"),
        (["track", "{demo}", "-o", "{out}", "-c", "{tracking_typo}", "--pipeline", "wearable"],
         "tracking_typo.toml: [tracking]: unknown"),
        # ... and by the other commands that read a pipeline file (convert and calibrate ran on, silently)
        (["convert", "{demo}", "-o", "{out}", "-c", "{tracking_typo}"], "tracking_typo.toml: [tracking]: unknown"),
        (["convert", "{demo}", "-o", "{out}", "-c", "{topic_missing}"],
         "topic_missing.toml: [sensors.front] topic '/nope' is not in"),
        (["calibrate", "camera_0", "-c", "{tracking_typo}", "--adaptive", "{demo}", "--dry-run"],
         "tracking_typo.toml: [tracking]: unknown"),
        (["calibrate", "camera_0", "-c", "{fusion_typo}", "--points", "{two_points}", "--dry-run"],
         "fusion_typo.toml: [fusion]: unknown key(s) check_margn"),
        # numbers that are not finite, and a negative seed: the setting named, no traceback
        # (named by the option the user typed, not the field behind it)
        (["simulate", "crowd", "-o", "{out}", "--seconds", "inf"], "--seconds: expected a duration > 0, got inf"),
        (["simulate", "crowd", "-o", "{out}", "--seconds", "0"], "--seconds: expected a duration > 0, got 0"),
        (["simulate", "crowd", "-o", "{out}", "--seconds", "1", "--seed", "-1"],
         "--seed: expected an integer >= 0, got -1"),
        (["track", "{demo}", "-o", "{out}", "--tracker", "bogus"], "--tracker: expected 'pf' or 'kalman'"),
        (["simulate", "crossing", "-o", "{out}", "--seconds", "1", "--set", "scenario.duration_s=2"],
         "scenario.duration_s is set twice, by seconds (--seconds) and by a setting (--set)"),
        (["eval", "{demo}", "{demo}", "--threshold", "0"], "--threshold: expected a distance > 0"),
        (["track", "{demo}", "-o", "{out}", "-c", "{offset_inf}"],
         "offset_inf.toml: sensors.l0.clock_offset_ms: Input should be a finite number"),
        (["track", "{demo}", "-o", "{out}", "-c", "{tracking_pf}", "--tracker", "kalman"],
         "tracking_pf.toml: [tracking] with --tracker kalman: unknown CV Kalman parameter(s) ['cap_merges']"),
        # outputs of the wrong kind, named
        (["track", "{demo}", "-o", "{a_file}"], "is a file"),
        (["eval", "{tracks}", "{demo}", "-o", "{a_dir}"], "is a folder"),
        (["fit-step-model", "walk.csv", "-l", "10", "-o", "{a_dir}"], "is a folder"),
        # a pipeline's options given to another pipeline (traffic and wearable ran on, ignoring them)
        (["track", "{demo}", "-o", "{out}", "--pipeline", "traffic", "--max-frames", "3"],
         "--max-frames: only for --pipeline people-camera (got --pipeline traffic)"),
        (["track", "{demo}", "-o", "{out}", "--pipeline", "wearable", "--detections", "{mot}"],
         "--detections: only for --pipeline people-camera (got --pipeline wearable)"),
        (["track", "{demo}", "-o", "{out}", "--pipeline", "wearable", "--time", "log"],
         "--time: the wearable pipeline reads its sensors by their header stamps only"),
        (["track", "{video}", "-o", "{out}", "--pipeline", "people-camera", "--camera-topic", "/foo"],
         "is a video file (it has no topics)"),
        (["track", "{video}", "-o", "{out}", "--pipeline", "people-camera", "--detection-scale", "0.5"],
         "--detection-scale: scales the boxes of --detections, and none were given"),
        (["track", "{video}", "-o", "{out}", "--pipeline", "people-camera", "--detections", "{mot}", "--min-score",
          "nan"], "--min-score: expected a finite detection score, got nan"),
        # an output that is the command's own input: refused before anything is written (it was overwritten)
        (["events", "{tracks}", "--world", "{a_dir}", "-o", "{tracks}"], "is the input"),
        (["eval", "{tracks}", "{demo}", "-o", "{tracks}"], "is the input"),
        (["calibrate-road", "{two_points}", "-o", "{two_points}"], "is the input"),
        (["events", "{tracks}", "--world", "{a_dir}", "--truth", "{tmp}", "-o", "{tmp}/incidents.jsonl"],
         "is the input"),  # (a run folder's file read by --truth)
        (["eval", "{tmp}", "{mot}", "-o", "{tmp}/tracks_mot.txt"], "is the input"),  # (a people-camera folder's)
        # ... nor into a recording folder it reads: the truth's metadata, storage files and simulator's files
        (["eval", "{tracks}", "{rec}", "-o", "{rec}/metadata.yaml"], "is inside the recording"),
        (["eval", "{tracks}", "{rec}", "-o", "{rec}/ground_truth/world.json"], "is inside the recording"),
        (["eval", "{tracks}", "{rec}/r.mcap", "-o", "{rec}/metrics.json"], "is inside the recording"),  # (its file)
        (["calibrate", "camera_0", "-c", "{hall}", "--adaptive", "{rec}", "--history", "{hall}"],
         "hall.toml: is the input"),  # (the pipeline file it rewrites: it became the history CSV)
        (["calibrate", "camera_0", "-c", "{hall}", "--adaptive", "{rec}", "--history", "{rec}/ground_truth/a.csv"],
         "is inside the recording"),
        (["pdr", "{tmp}/steps.csv", "-o", "{tmp}"], "its steps.csv would overwrite the input"),  # (pdr's own output)
        (["fit-step-model", "walk.csv", "-l", "0", "-o", "{out}.json"], "--length: expected distances walked > 0 m"),
        # a file the pipeline file names is read relative to it (as [traffic] calibration), and named so
        (["track", "{demo}", "-o", "{out}", "--pipeline", "wearable", "-c", "{wearable_model}"],
         "wearable_model.toml: [wearable] step_model: "),
        # calibrate's options of the other way: refused, not ignored
        (["calibrate", "camera_0", "-c", "{hall}", "--points", "{two_points}", "--rho", "0.5", "--history", "h.csv"],
         "--rho, --history: only with --adaptive"),
        (["calibrate", "camera_0", "-c", "{hall}", "--adaptive", "{rec}", "--ransac", "--reference", "laser_0"],
         "--ransac, --reference: only with --points"),
        (["calibrate", "camera_0", "-c", "{hall}", "--points", "{two_points}", "--rho", "0.1"],  # (the default value)
         "--rho: only with --adaptive"),
        (["calibrate", "camera_0", "-c", "{hall}", "--adaptive", "{rec}", "--reference", "world"],
         "--reference: only with --points"),
        # a [tracking] table for the Kalman tracker, wrong: the Kalman's error, not "unknown" particle-filter keys
        (["convert", "{demo}", "-o", "{out}", "-c", "{kalman_bad}"], "kalman_bad.toml: [tracking] with --tracker "
                                                                      "kalman: "),
        (["calibrate", "camera_0", "-c", "{hall}", "--points", "{two_points}", "--intrinsics", "500,500,320,240",
          "--recording", "{rec}"], "2 control points given, at least 4 are needed"),  # (both given: accepted)
        # eval's own options
        (["eval", "{binary}", "{demo}"], "binary.png: not a UTF-8 text file (expected JSON lines"),
        (["eval", "{tracks}", "{demo}", "--time", "lgo"], "--time: expected 'header' or 'log', got 'lgo'"),
        (["eval", "{tracks}", "{demo}", "--topic", "/gt_wrong"], "/gt_wrong"),
        (["eval", "{mot}", "{a_dir}"], "a_dir: a folder that is not a recording"),
        # ground truth that is not there, is not ground truth, or has no identities: what eval reads instead
        (["eval", "{tracks}", "{demo}"], "no ground-truth topic (fusiontrack_msgs/msg/GroundTruth or "
                                         "leg_tracker/msg/Person); give the truth as a CSV file (t or t_ns, id, x, y)"),
        (["eval", "{tracks}", "{demo}", "--topic", "/scan"], "--topic /scan: sensor_msgs/msg/LaserScan is not "
                                                             "ground truth"),
        (["eval", "{tracks}", "{legs}", "--topic", "/leg_cluster_positions"],
         "--topic /leg_cluster_positions: its geometry_msgs/msg/PoseArray positions carry no identities"),
        # calibrate from control points: the file and the flags, not the library's function
        (["calibrate", "camera_0", "-c", "{hall}", "--points", "{two_points}", "--intrinsics", "500,500,320,240",
          "--dry-run"], "two_points.csv: 2 control points given, at least 4 are needed"),
        (["calibrate", "camera_0", "-c", "{hall}", "--points", "{two_points}", "--dry-run"],
         "camera_0: its intrinsics are needed: give --intrinsics"),
        # intrinsics and a learning rate that cannot be used: the option, before any reading
        (["calibrate", "camera_0", "-c", "{hall}", "--points", "{two_points}", "--intrinsics=-500,500,320,240",
          "--dry-run"], "--intrinsics: expected focal lengths fx, fy > 0 (pixels), got fx=-500, fy=500"),
        (["calibrate", "camera_0", "-c", "{hall}", "--points", "{two_points}", "--intrinsics", "500,nan,320,240",
          "--dry-run"], "--intrinsics: expected finite numbers, got '500,nan,320,240'"),
        (["calibrate", "camera_0", "-c", "{hall}", "--adaptive", "{demo}", "--rho", "-1", "--dry-run"],
         "--rho: expected a learning rate in (0, 1], got -1.0"),
        (["calibrate", "camera_0", "-c", "{hall}", "--adaptive", "{demo}", "--rho", "nan", "--dry-run"],
         "--rho: expected a learning rate in (0, 1], got nan"),
    ],
)
def test_cli_prints_one_clear_line_and_exits_nonzero(shared_data, tmp_path, args, expected):
    from fusiontrack.io.tracks import write_tracks_csv
    from fusiontrack.types import TrackState

    cfg = tmp_path / "p.toml"
    cfg.write_text("[sync]\nwindow_ms = 'soon'\n")
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"\x00" * 100)
    tables = {"laser_typo": "[laser]\nmin_segmnt_points = 10\n", "laser_neg": "[laser]\nmin_segment_points = -5\n",
              "laser_text": "[laser]\nalpha = 'x'\n", "tracking_typo": "[tracking]\nnum_particles = 10\n",
              "tracking_pf": "[tracking]\ncap_merges = true\n", "fusion_typo": "[fusion]\ncheck_margn = 0.5\n",
              "wearable_typo": "[wearable]\nphone = 'a'\n", "traffic_workers": "[traffic]\nworkers = -3\n",
              "topic_missing": '[sensors.front]\nkind = "laser"\ntopic = "/nope"\n',
              "offset_inf": '[sensors.l0]\nkind = "laser"\ntopic = "/scan"\nclock_offset_ms = inf\n',
              "kalman_bad": "[tracking]\ngate_m = -1.0\n",
              "wearable_model": '[wearable]\nstep_model = "models/me.json"\n'}
    for name, text in tables.items():
        (tmp_path / f"{name}.toml").write_text(text)
    (tmp_path / "a_file").write_text("")
    (tmp_path / "binary.png").write_bytes(bytes(range(128, 256)) * 8)
    (tmp_path / "a_dir").mkdir()
    (tmp_path / "rec").mkdir()  # a recording folder (what an output must not overwrite in it: checked first)
    (tmp_path / "rec" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (tmp_path / "rec" / "r.mcap").write_bytes(b"")
    (tmp_path / "steps.csv").write_text("t_s,ax,ay,az\n")  # an IMU file where pdr would write its steps.csv
    (tmp_path / "hall.toml").write_text('[sensors.camera_0]\nkind = "camera"\ntopic = "/camera_0/image"\n'
                                        'pose = { x = 0.0, y = 0.0, z = 3.0, yaw_deg = 0.0 }\n')
    (tmp_path / "two_points.csv").write_text("x_m,y_m,z_m,u_px,v_px\n0,0,0,100,400\n1,0,0,200,400\n")
    (tmp_path / "det.txt").write_text("1,1,10,10,20,40,1,-1,-1,-1\n")
    (tmp_path / "incidents.jsonl").write_text("")  # (a run folder's true incidents, and a people-camera folder's
    (tmp_path / "tracks_mot.txt").write_text("1,1,10,10,20,40,1,-1,-1,-1\n")  # image boxes: inputs to keep)
    tracks = tmp_path / "tracks.csv"
    write_tracks_csv(tracks, [TrackState(10**18, "laser", 1, np.zeros(2), np.zeros(2))])
    subst = {"demo": str(shared_data / DEMO), "out": str(tmp_path / "o"), "cfg": str(cfg), "junk": str(junk),
             "legs": str(shared_data / "laser/leg_tracker_demo/training/positive_1_extracted.bag"),
             "a_file": str(tmp_path / "a_file"), "a_dir": str(tmp_path / "a_dir"), "tracks": str(tracks),
             "hall": str(tmp_path / "hall.toml"), "two_points": str(tmp_path / "two_points.csv"),
             "mot": str(tmp_path / "det.txt"), "binary": str(tmp_path / "binary.png"),
             "video": str(shared_data / "video/pets09_s2l1/vtest_pets09_s2l1_480x360.avi"), "tmp": str(tmp_path),
             "rec": str(tmp_path / "rec"),
             **{name: str(tmp_path / f"{name}.toml") for name in tables}}
    result = _cli(*[a.format(**subst) for a in args])
    assert result.returncode == 2
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error:")
    assert expected in lines[0]
    assert "Traceback" not in result.stderr


def test_nan_ranges_and_disordered_messages_do_not_stop_reading(tmp_path):
    """Bad data inside a recording is carried through (NaN ranges) or skipped and counted."""
    rng = np.random.default_rng(5)
    scans = []
    for i in range(50):
        r = rng.random(100).astype(np.float32) * 4
        r[rng.random(100) < 0.3] = np.nan
        scans.append(LaserScan((i + 1) * 100_000_000, "laser", "laser", -1.0, 0.02, 0.02, 5.0, r))
    order = rng.permutation(50)
    with RecordingWriter(tmp_path / "r") as w:
        for k, i in enumerate(order):  # log order scrambled relative to the header stamps
            w.write(scans[i], log_t_ns=k * 100_000_000)
    from fusiontrack.io.sync import Synchronizer

    sync = Synchronizer(window_ns=10**12)  # a window longer than the recording restores everything
    with Recording(tmp_path / "r") as rec:
        out = list(sync(rec.messages()))
    assert [s.t_ns for s in out] == [s.t_ns for s in scans]
    assert np.isnan(out[3].valid_ranges_m()).sum() == np.isnan(scans[3].ranges_m).sum()


def test_a_nan_transform_in_tf_static_is_left_out_with_a_warning(tmp_path, caplog):
    """A /tf_static transform with a NaN quaternion cannot be used: tracking goes on, the transform left out with a
    warning naming its frames; a pose given by the user (a pipeline file's) places the scanner instead."""
    from fusiontrack.geometry import make_transform
    from fusiontrack.laser.detector import detector_for_recording
    from fusiontrack.tracking import track_recording
    from fusiontrack.types import Transform

    with RecordingWriter(tmp_path / "r") as w:
        w.write(Transform(100_000_000, "/tf_static", "world", "laser", [1.0, 2.0, 0.2], [0, 0, 0.3, np.nan], True))
        for i in range(30):
            w.write(LaserScan((i + 1) * 100_000_000, "laser", "laser", -1.0, 0.02, 0.02, 5.0,
                              np.full(100, 3.0, np.float32)))
    with caplog.at_level(logging.WARNING, logger="fusiontrack"):
        track_recording(tmp_path / "r")
    assert any("transform 'laser' -> 'world': its rotation x, y, z, w (0, 0, 0.3, nan) is not a finite" in
               r.getMessage() for r in caplog.records)
    given = make_transform(np.eye(3), [4.0, 5.0, 0.0])
    with Recording(tmp_path / "r") as rec:
        (topic,) = set(rec.topics()) - {"/tf_static"}
        _, poses = detector_for_recording(rec, [topic], laser_poses={"laser": given})
    np.testing.assert_array_equal(poses["laser"], given)


def test_an_image_without_pixels_is_skipped_counted_and_warned_about_once(tmp_path, caplog):
    """0x0 images (width = height = 0, no data) in a recording are unusable frames: each skipped and counted, one
    warning for them all, as for truncated images; the good images between them still come through."""
    from fusiontrack.fusion import LazyFrames
    from fusiontrack.types import Image

    good = np.zeros((4, 6, 3), np.uint8)
    with RecordingWriter(tmp_path / "r") as w:
        ts = w.typestore
        Img, Header, Time = (ts.types[k] for k in ("sensor_msgs/msg/Image", "std_msgs/msg/Header",
                                                   "builtin_interfaces/msg/Time"))
        for i in range(6):
            t = (i + 1) * 100_000_000
            if i % 2:
                w.write(Image(t, "cam", "cam", good + i))
                continue
            empty = Img(Header(Time(sec=0, nanosec=t), "cam"), 0, 0, "bgr8", 0, 0, np.zeros(0, np.uint8))
            w._writer.write(w._connection("/cam/image", "sensor_msgs/msg/Image"), t,
                            ts.serialize_cdr(empty, "sensor_msgs/msg/Image"))
    with caplog.at_level(logging.WARNING, logger="fusiontrack"), Recording(tmp_path / "r") as rec:
        images = list(rec.messages(["/cam/image"]))
        assert [im.pixels[0, 0, 0] for im in images] == [1, 3, 5]
        assert rec.skipped == {"/cam/image": 3}
        frames = LazyFrames(rec, "/cam/image", max_dt_ns=1000)
        got = [frames.at((i + 1) * 100_000_000) for i in range(6)]
        frames.warn_unreadable()
    assert [g is not None for g in got] == [False, True, False, True, False, True]
    warned = [r.getMessage() for r in caplog.records]
    assert len(warned) == 2, warned  # one from each reader
    assert "image of 0x0 bgr8 holds no pixels" in warned[0]
    assert "/cam/image: 3 of the 6 images converted were unreadable and skipped" in warned[1]

def test_cli_version():
    result = _cli("--version")
    assert result.returncode == 0
    assert result.stdout.startswith("fusiontrack ")


def test_cli_help_on_every_command():
    result = _cli("--help")
    assert result.returncode == 0
    expected = ["info", "convert", "repair", "view", "scenarios", "simulate", "demo"]
    commands = [c for c in expected if c in result.stdout]
    assert commands == expected
    for cmd in commands:
        sub = _cli(cmd, "--help")
        assert sub.returncode == 0
        assert "Usage" in sub.stdout




def test_a_recording_without_lasers_points_to_the_camera_pipeline(shared_data):
    """A TU/e RGB-D bag has camera images and no laser: the laser pipeline says so and names the image topics and the
    pipeline that tracks people in them, with the bag's path as plain text."""
    from fusiontrack.tracking.tracker import track_recording

    bag = shared_data / "rgbd/tue_rgbd_people/2019-05-03-12-42-34.bag"
    with pytest.raises(ConfigError, match="no sensor_msgs/LaserScan topic") as err:
        track_recording(bag)
    message = str(err.value)
    assert message.startswith(f"{bag}:")
    assert "/hero/head_rgbd_sensor/rgb/image_raw" in message
    assert "--pipeline people-camera" in message


def test_an_output_that_cannot_be_written_is_one_line_naming_it(tmp_path):
    """The OS refusing an output (a file where a folder is needed, a full disk: /dev/full, a read-only folder when
    not root) ends as one line naming the path and the OS's reason, exit code 2, whichever command writes it."""
    from fusiontrack.io.tracks import write_tracks_csv
    from fusiontrack.types import TrackState

    write_tracks_csv(tmp_path / "tracks.csv", [TrackState(10**9, "laser", 1, np.zeros(2), np.zeros(2))])
    (tmp_path / "gt.csv").write_text("t,id,x,y\n1.0,1,0.0,0.0\n")
    (tmp_path / "a_file").write_text("")
    def eval_to(name: str) -> list[str]:
        return ["eval", str(tmp_path / "tracks.csv"), str(tmp_path / "gt.csv"), "-o", str(tmp_path / name)]

    cases = [(eval_to("a_file/m.json"),  # (refused before the evaluation, naming the option)
              f"--output {tmp_path / 'a_file' / 'm.json'}: {tmp_path / 'a_file'} is a file, not a folder")]
    if Path("/dev/full").exists():  # writes to it fail: no space left on device
        (tmp_path / "full.json").symlink_to("/dev/full")
        cases.append((eval_to("full.json"),
                      f"cannot write {tmp_path / 'full.json'}: [Errno 28] No space left on device"))
        with RecordingWriter(tmp_path / "rec") as w:
            for i in range(60):  # (more than n_init: a shorter recording is said, in a warning line)
                w.write(LaserScan((i + 1) * 100_000_000, "laser", "laser", -1.0, 0.02, 0.02, 5.0,
                                  np.full(100, 3.0, np.float32)))
        (tmp_path / "out").mkdir()
        (tmp_path / "out" / "tracks.csv").symlink_to("/dev/full")
        cases.append((["track", str(tmp_path / "rec"), "-o", str(tmp_path / "out"), "--no-video"],
                      f"cannot write {tmp_path / 'out' / 'tracks.csv'}: [Errno 28] No space left on device"))
    if os.geteuid() != 0:  # root writes into a read-only folder anyway
        (tmp_path / "ro").mkdir(mode=0o500)
        cases.append((eval_to("ro/m.json"), f"{tmp_path / 'ro' / 'm.json'}: [Errno 13]"))
    for args, expected in cases:
        result = _cli(*args)
        assert result.returncode == 2, result.stderr
        lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1, result.stderr
        assert lines[0].startswith("error: ")
        assert expected in lines[0]


def test_a_failed_camera_run_leaves_no_empty_folder(tmp_path):
    """track --pipeline people-camera on a video OpenCV cannot open: one error line, and the output folder it would
    have written into is not left behind empty."""
    video = tmp_path / "empty.avi"
    video.write_bytes(b"")
    result = _cli("track", str(video), "--pipeline", "people-camera", "-o", str(tmp_path / "out"))
    assert result.returncode == 2
    assert "empty.avi" in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "out").exists()


def test_view_makes_its_output_folder_but_not_for_a_bad_suffix(shared_data, tmp_path):
    """view -o new/folder/v.mp4 makes the folders, as track does; -o new/v.gif says what is wrong with the suffix and
    makes no folder for it."""
    demo = str(shared_data / DEMO)
    ok = _cli("view", demo, "-o", str(tmp_path / "new/sub/v.mp4"), "--max-frames", "3")
    assert ok.returncode == 0, ok.stderr
    assert cv2.VideoCapture(str(tmp_path / "new/sub/v.mp4")).get(cv2.CAP_PROP_FRAME_COUNT) == 3
    bad = _cli("view", demo, "-o", str(tmp_path / "other/v.gif"))
    assert bad.returncode == 2
    assert "v.gif: suffix '.gif' is not a video format" in bad.stderr
    assert not (tmp_path / "other").exists()


@pytest.mark.parametrize(("option", "value"), [("--fps", "-5"), ("--fps", "0"), ("--fps", "nan"),
                                               ("--fps", "0.001"), ("--fps", "100000"),  # (the codec was blamed)
                                               ("--max-frames", "-3"), ("--max-frames", "0")])
def test_view_refuses_a_bad_frame_rate_or_frame_count(shared_data, tmp_path, option, value):
    """view --fps -5 wrote a 1 fps video and --max-frames -3 one frame, both saying nothing: now an error naming the
    option, and no video nor folder is made."""
    out = tmp_path / "new" / "v.mp4"
    result = _cli("view", str(shared_data / DEMO), "-o", str(out), option, value)
    assert result.returncode == 2
    assert option in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "new").exists()


def test_a_recording_shorter_than_the_background_learning_still_tracks_its_people(simulated, caplog):
    """A 1.5 s recording holds 38 scans per scanner, fewer than the 50 a background is learnt from (n_init): every
    scanner stayed unlearnt, so nothing was ever foreground and the run gave no track, with exit code 0 and no
    word. Now the backgrounds are learnt from the scans there are, with a warning, and the people are tracked."""
    from fusiontrack.eval import evaluate_floor
    from fusiontrack.sim.scenario import load_scenario
    from fusiontrack.sim.simulator import Simulation
    from fusiontrack.tracking.tracker import track_recording

    path = simulated("crowd", seconds=1.5, seed=1)
    scenario = load_scenario("crowd").with_overrides(seconds=1.5, seed=1)
    corr = {c.name: -round(c.clock_offset_ms * 1e6) for c in scenario.config.lasers}
    with Recording(path) as rec:
        gt = list(rec.messages(["/ground_truth"]))
    with caplog.at_level(logging.WARNING, logger="fusiontrack.laser.background"):
        states, _ = track_recording(path, area_m=Simulation(scenario).world.bounds_m, clock_corrections_ns=corr,
                                    params={"lateral_m": 0.2})
    assert "fewer than the 50 its background is learnt from" in caplog.text
    m = evaluate_floor(gt, states, 0.5)
    people = {i for g in gt for i in g.ids}
    assert len(people) >= 5
    assert m.mota > 0.5  # (0 before: not one track)


def test_lasers_left_out_by_the_pipeline_file_are_named(simulated, tmp_path):
    """A pipeline file listing one of a recording's two scanners (as the README's calibrate workflow writes one, with
    the reference laser) tracks with that one only: said, naming the scanner left out, not silently halved."""
    path = simulated("crowd", seconds=1.5, seed=1)
    one = tmp_path / "one.toml"
    one.write_text('[sensors.laser_0]\nkind = "laser"\ntopic = "/laser_0/scan"\n')
    both = tmp_path / "both.toml"
    both.write_text(one.read_text() + '[sensors.laser_1]\nkind = "laser"\ntopic = "/laser_1/scan"\n')
    said = "lists the laser(s) /laser_0/scan: only they are tracked; the recording's /laser_1/scan is left out"
    result = _cli("track", str(path), "-c", str(one), "--no-video", "-o", str(tmp_path / "a"))
    assert result.returncode == 0, result.stderr
    assert said in " ".join(result.stderr.split())
    result = _cli("track", str(path), "-c", str(both), "--no-video", "-o", str(tmp_path / "b"))
    assert result.returncode == 0, result.stderr
    assert "left out" not in result.stderr


def test_a_broken_world_json_costs_only_the_situation_scores(simulated, tmp_path):
    """A run folder whose ground_truth/world.json is not the simulator's (overwritten by another output): eval
    crashed with a KeyError traceback after printing the metrics; now the metrics are written and the situation
    scores left out with a warning naming the file."""
    import json
    import shutil

    run = tmp_path / "run"
    shutil.copytree(simulated("crowd", seconds=1.5, seed=1), run)
    (run / "ground_truth" / "world.json").write_text('{"mota": 1.0}')
    assert _cli("track", str(run), "--no-video", "-o", str(tmp_path / "t")).returncode == 0
    result = _cli("eval", str(tmp_path / "t"), str(run), "-o", str(tmp_path / "m.json"))
    assert result.returncode == 0, result.stderr
    said = " ".join(result.stderr.split())
    assert "world.json: not the simulator's world description" in said
    assert "situation detection not scored" in said
    assert "Traceback" not in result.stderr
    assert json.loads((tmp_path / "m.json").read_text())["metrics"]["mota"] > 0.3


def test_the_people_pipeline_fuses_the_camera_its_pipeline_file_names(simulated, tmp_path):
    """A road recording has two cameras: a pipeline file naming one of them chooses it (the run asked for
    --camera-topic as if the file said nothing); naming both, the error says to choose one."""
    path = simulated("road", seconds=3, seed=0)
    one = tmp_path / "one.toml"
    one.write_text('[sensors.camera_1]\nkind = "camera"\ntopic = "/camera_1/image"\n')
    result = _cli("track", str(path), "--pipeline", "people", "-c", str(one), "--no-video", "-o", str(tmp_path / "a"))
    assert result.returncode == 0, result.stderr
    assert "camera_1 horizontal bias" in result.stdout
    both = tmp_path / "both.toml"
    both.write_text(one.read_text() + '[sensors.camera_0]\nkind = "camera"\ntopic = "/camera_0/image"\n')
    result = _cli("track", str(path), "--pipeline", "people", "-c", str(both), "--no-video", "-o", str(tmp_path / "b"))
    assert result.returncode == 2
    assert "lists several cameras (/camera_1/image, /camera_0/image)" in " ".join(result.stderr.split())


@pytest.mark.parametrize(("args", "option"), [
    (["track", "{demo}", "--time", "log", "--area", "none", "--no-video", "-o", "{file}/sub"], "--output"),
    (["eval", "{demo}", "{demo}", "-o", "{file}/m.json"], "--output"),
    (["train-classifier", "--work", "{file}", "-o", "{tmp}/m.json"], "--work"),
    (["train-classifier", "--work", "{tmp}/w", "-o", "{file}/x.json"], "--output"),
    (["demo", "-o", "{file}/d"], "--output"),
    (["simulate", "crowd", "--seconds", "2", "-o", "{file}/sim"], "--output"),
    (["convert", "{demo}", "-o", "{file}/mcap"], "--output"),
    (["repair", "{demo}", "-o", "{file}/r.bag"], "--output"),
    (["view", "{demo}", "-o", "{file}/v.mp4"], "--output"),
])
def test_an_output_under_a_file_is_refused_before_any_work(shared_data, tmp_path, args, option):
    """-o notabag.bag/sub used to track (or train, or evaluate) for minutes and fail only when writing, with an
    OS error that did not name the option: now an error at once, naming the option and the file in the way."""
    file = tmp_path / "notabag.bag"
    file.write_text("not a folder", encoding="utf-8")
    argv = [a.format(demo=shared_data / DEMO, file=file, tmp=tmp_path) for a in args]
    result = _cli(*argv)
    assert result.returncode == 2, result.stderr
    assert f"error: {option} " in result.stderr
    assert "is a file" in result.stderr
    assert "Traceback" not in result.stderr


def test_a_recording_stopped_part_way_is_removed_not_left_looking_whole(tmp_path, caplog):
    """convert / simulate stopped by Ctrl-C (or an error) left a recording that opened and looked whole with half
    of the data: the writer now removes the folder it created. What it did not create is never touched: a folder
    that was there (or that another run made first) is refused, and stays as it was."""
    from fusiontrack.errors import RecordingError
    from fusiontrack.io.recording import Recording
    from fusiontrack.io.writer import RecordingWriter

    out = tmp_path / "new"
    scan = LaserScan(10**9, "laser", "laser", -1.0, 0.02, 0.02, 5.0, np.ones(100, np.float32))

    def stopped() -> None:
        with RecordingWriter(out) as w:
            w.write(scan)
            raise KeyboardInterrupt

    with caplog.at_level("WARNING", logger="fusiontrack"), pytest.raises(KeyboardInterrupt):
        stopped()
    assert not out.exists()
    assert any("the incomplete recording" in r.getMessage() for r in caplog.records)
    with RecordingWriter(out) as w:  # finished: kept
        w.write(scan)
    with Recording(out) as rec:
        assert len(list(rec.messages())) == 1
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "data.txt").write_text("precious")

    def refused() -> None:
        with RecordingWriter(theirs) as w:
            w.write(scan)

    with pytest.raises(RecordingError, match="already exists"):
        refused()
    assert (theirs / "data.txt").read_text() == "precious"


def test_a_simulation_stopped_by_sigterm_leaves_nothing(tmp_path):
    """kill (SIGTERM: a scheduler's stop) during simulate left a half-written recording, and the next run refused
    the folder as existing; it now goes through Ctrl-C's clean-up: the incomplete recording is removed, and the run
    exits with SIGTERM's code (it exited with Ctrl-C's, 130: a scheduler could not tell its stop from a user's)."""
    import signal
    import time

    out = tmp_path / "sim"
    proc = subprocess.Popen([sys.executable, "-m", "fusiontrack", "simulate", "crowd", "--seconds", "60", "-o",
                             str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not out.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
    assert out.exists(), "the recording was never started"
    time.sleep(1.0)  # part way through
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM  # the shell's code for a run stopped by SIGTERM (Ctrl-C's: 130)
    assert "incomplete recording" in err
    assert "terminated" in err
    assert not out.exists()


def test_a_scan_header_corrupted_beyond_float32_reads_without_numpy_warnings():
    """Flipped bytes in a scan's header can make its angle increment huge: it is held as float32 (inf), as ROS
    holds it, and no beam has a direction (all invalid), without a bare numpy RuntimeWarning on the way."""
    import warnings

    from fusiontrack.geometry import scan_to_points

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scan = LaserScan(1, "laser", "laser", -1.0, 1e39, 0.02, 5.0, np.ones(21))
        assert scan.angle_increment_rad == np.inf
        assert np.isnan(scan.angles_rad()).all()
        assert np.isnan(scan.valid_ranges_m()).all()
        assert np.isnan(scan_to_points(scan)).all()
        scan = LaserScan(1, "laser", "laser", float("nan"), 0.01, 0.02, 5.0, np.ones(21))
        assert np.isnan(scan.valid_ranges_m()).all()
