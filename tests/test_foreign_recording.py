"""A recording made by other tools has none of fusiontrack's sensor metadata: each topic is its own sensor, and
only the ROS names tie an image topic to its ``camera_info`` and a scan to its frame in ``/tf_static``. The fused
pipeline must still find its camera (it used to track with the lasers only: "no CameraInfo")."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from fusiontrack.fusion import track_fused
from fusiontrack.io.recording import Recording
from fusiontrack.io.writer import RecordingWriter
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.types import CameraInfo, Image

YAW_ERROR_DEG = 3.0


def _without_metadata(src: Path, dst: Path) -> None:
    """Copy a rosbag2 recording message by message, leaving out fusiontrack's custom data (the sensor map)."""
    with AnyReader([src]) as reader:
        writer = Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=reader.typestore)
                 for c in reader.connections}
        for c, t, raw in reader.messages():
            writer.write(conns[c.id], t, raw)
        writer.close()


def test_camera_info_beside_the_image_topic_by_ros_names(tmp_path: Path) -> None:
    pixels = np.zeros((4, 6, 3), np.uint8)
    info = CameraInfo(0, "x", "cam", 4, 6, np.array([[5.0, 0, 3], [0, 5.0, 2], [0, 0, 1]]))
    with RecordingWriter(tmp_path / "r") as w:  # every record its own sensor, named by its topic
        for topic, kind in (("/front/image_raw", "image"), ("/front/camera_info", "info"),
                            ("/back/image_raw/compressed", "image"), ("/back/camera_info", "info"),
                            ("/camera_info", "info")):
            record = Image(0, topic, "cam", pixels, "bgr8") if kind == "image" else \
                CameraInfo(0, topic, info.frame_id, info.height, info.width, info.K)
            w.write(record, topic=topic, image_format="png" if topic.endswith("compressed") else None)
    with Recording(tmp_path / "r") as rec:
        assert rec.sensor_of("/front/image_raw") == "/front/image_raw"  # no sensor metadata
        assert rec.camera_info_topics("/front/image_raw") == ["/front/camera_info", "/camera_info"]
        assert rec.camera_info_topics("/back/image_raw/compressed") == ["/back/camera_info", "/camera_info"]


@pytest.fixture(scope="module")
def foreign_crowd(simulated, tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The 9 s ``crowd`` whose camera is turned 3 degrees (as test_bias_priming's), without its sensor metadata."""
    settings = {"cameras.0.yaw_bias_deg": YAW_ERROR_DEG}
    scenario = load_scenario("crowd").with_overrides(seconds=9, seed=0, settings=settings)
    path: Path = simulated("crowd", seconds=9, seed=0, settings=settings)
    out = tmp_path_factory.mktemp("foreign") / "crowd"
    _without_metadata(path, out)
    # clock corrections are per sensor; here the sensors are the topics
    corrections = {f"/{c.name}/scan": -round(c.clock_offset_ms * 1e6) for c in scenario.config.lasers}
    corrections["/camera_0/image"] = -round(scenario.config.cameras[0].clock_offset_ms * 1e6)
    return {"path": out, "corrections": corrections}


def test_the_fused_pipeline_finds_its_camera_without_sensor_metadata(foreign_crowd: dict) -> None:
    with Recording(foreign_crowd["path"]) as rec:
        assert rec.sensor_of("/camera_0/image") == "/camera_0/image"
        assert rec.camera_info_topics("/camera_0/image") == ["/camera_0/camera_info"]
    states, _, stats = track_fused(foreign_crowd["path"], clock_corrections_ns=foreign_crowd["corrections"],
                                   tracker_params={"lateral_m": 0.2}, rng=0)
    assert stats.camera == "/camera_0/image"
    assert stats.bias is not None
    assert abs(math.degrees(stats.bias.bias_rad) - YAW_ERROR_DEG) < 0.3  # the simulator's truth
    assert states


def _images(path: Path, topics: dict[str, str]) -> Path:
    """A recording of one image per topic (``kind``: "raw", "png" compressed, or "info") with no sensor metadata."""
    pixels = np.zeros((4, 6, 3), np.uint8)
    K = np.array([[5.0, 0, 3], [0, 5.0, 2], [0, 0, 1]])
    with RecordingWriter(path) as w:
        for topic, kind in topics.items():
            record = CameraInfo(0, topic, "cam", 4, 6, K) if kind == "info" else Image(0, topic, "cam", pixels, "bgr8")
            w.write(record, topic=topic, image_format="png" if kind == "png" else None)
    return path


def test_one_camera_published_raw_and_compressed_is_one_camera(tmp_path: Path) -> None:
    """image_transport publishes ``/ns/image_raw/compressed`` beside ``/ns/image_raw``: one camera, read raw. The
    people pipelines refused such a recording ("several image topics") unless told --camera-topic."""
    path = _images(tmp_path / "r", {"/cam/image_raw": "raw", "/cam/image_raw/compressed": "png",
                                    "/cam/camera_info": "info", "/cam/depth/image_raw": "raw",
                                    "/cam/depth_registered/image": "raw"})
    with Recording(path) as rec:
        assert rec.image_topics() == ["/cam/image_raw"]  # (not its compressed variant, not the depth images)
        assert rec.image_topic() == "/cam/image_raw"
        assert rec.image_topic(camera="/cam/camera_info") == "/cam/image_raw"
        assert rec.image_topic(camera="/cam/image_raw/compressed") == "/cam/image_raw/compressed"
    only = _images(tmp_path / "c", {"/cam/image_raw/compressed": "png", "/cam/camera_info": "info"})
    with Recording(only) as rec:
        assert rec.image_topic() == "/cam/image_raw/compressed"


def test_image_topic_errors_name_the_option_and_the_choices(tmp_path: Path, caplog) -> None:
    from fusiontrack.errors import ConfigError, TopicError

    path = _images(tmp_path / "r", {"/left/image_raw": "raw", "/left/image_raw/compressed": "png",
                                    "/right/image_raw": "raw", "/right/camera_info": "info"})
    with Recording(path) as rec:
        with pytest.raises(ConfigError, match=r"several cameras' image topics \(/left/image_raw, /right/image_raw\); "
                                              r"choose one with camera_topic \(--camera-topic\)"):
            rec.image_topic()
        assert rec.image_topic(required=False, camera="/right/camera_info") == "/right/image_raw"
        with pytest.raises(TopicError, match=r"camera_topic \(--camera-topic\) '/right/camera_info': a "
                                             r"sensor_msgs/msg/CameraInfo topic, not an image; image topics: "
                                             r"/left/image_raw, /right/image_raw"):
            rec.image_topic(topic="/right/camera_info")
        with pytest.raises(TopicError, match="image_topic '/middle/image_raw': no such topic"):
            rec.image_topic(topic="/middle/image_raw", option="image_topic")
        with pytest.raises(TopicError, match="no image topic of camera '/middle/camera_info'"):
            rec.image_topic(camera="/middle/camera_info")
    depth = _images(tmp_path / "d", {"/cam/image_raw": "raw", "/cam/depth/image_raw": "raw"})
    with Recording(depth) as rec, caplog.at_level(logging.WARNING, logger="fusiontrack.io.recording"):
        assert rec.image_topic(topic="/cam/depth/image_raw") == "/cam/depth/image_raw"  # the user's word, but said:
    assert "'/cam/depth/image_raw' is named as a label or depth image topic, not colour images (colour image " \
           "topics: /cam/image_raw)" in caplog.text
    empty = _images(tmp_path / "e", {"/cam/camera_info": "info"})
    with Recording(empty) as rec:
        assert rec.image_topic(required=False) is None
        with pytest.raises(TopicError, match="no image topic"):
            rec.image_topic()


def test_the_people_pipelines_read_the_raw_images_beside_their_compressed_copy(foreign_crowd: dict,
                                                                              tmp_path: Path) -> None:
    """The 9 s foreign ``crowd`` with its images also on ``/camera_0/image/compressed``: the fused and the camera
    pipelines both track through the raw topic, as without the copy."""
    from fusiontrack.vision.people import track_camera

    both = tmp_path / "both"
    with AnyReader([foreign_crowd["path"]]) as reader:
        writer = Writer(both, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=reader.typestore)
                 for c in reader.connections}
        image = next(c for c in reader.connections if c.topic == "/camera_0/image")
        copy = writer.add_connection("/camera_0/image/compressed", "sensor_msgs/msg/CompressedImage",
                                     typestore=reader.typestore)
        for c, t, raw in reader.messages():
            writer.write(conns[c.id], t, raw)
            if c.id == image.id:
                msg = reader.deserialize(raw, c.msgtype)
                ok, png = cv2.imencode(".png", np.asarray(msg.data, np.uint8).reshape(msg.height, msg.width, -1))
                assert ok
                comp = reader.typestore.types["sensor_msgs/msg/CompressedImage"](
                    header=msg.header, format="bgr8; png compressed bgr8", data=png.ravel())
                writer.write(copy, t, reader.typestore.serialize_cdr(comp, "sensor_msgs/msg/CompressedImage"))
        writer.close()
    _, _, stats = track_fused(both, clock_corrections_ns=foreign_crowd["corrections"],
                              tracker_params={"lateral_m": 0.2}, rng=0, adaptive_bias=False)
    assert stats.camera == "/camera_0/image"
    assert stats.frames_used > 0
    _, _, cam_stats = track_camera(both, max_frames=10)
    assert cam_stats.sensor == "/camera_0/image"  # (a foreign recording's sensors are its topics)
    assert cam_stats.n_frames == 10


def test_the_traffic_pipeline_counts_one_camera_not_its_streams(tmp_path: Path, caplog) -> None:
    """A camera known by /ns/camera_info, with its images raw and compressed and its depth images beside them: the
    traffic branches warned that '/ns/depth/image_raw', '/ns/image_raw' and '/ns/image_raw/compressed' were cameras
    with images but no CameraInfo."""
    from fusiontrack.fusion.traffic_sensors import traffic_branches

    path = _images(tmp_path / "r", {"/ns/image_raw": "raw", "/ns/image_raw/compressed": "png",
                                    "/ns/camera_info": "info", "/ns/depth/image_raw": "raw",
                                    "/other/image_raw": "raw"})
    from fusiontrack.errors import RecordingError

    with caplog.at_level("WARNING", logger="fusiontrack"), Recording(path) as rec, \
            pytest.raises(RecordingError, match="'/ns/camera_info' has no CameraInfo or no pose"):  # (no /tf_static)
        traffic_branches(rec, np.array([[0.0, 0.0, 10.0, 0.0, 7.0]]))
    (msg,) = [r.getMessage() for r in caplog.records if "have images but no CameraInfo" in r.getMessage()]
    assert "['/other/image_raw']" in msg  # the one camera without a CameraInfo, and only it


def test_a_camera_whose_namespace_says_depth_is_still_a_colour_camera(tmp_path: Path) -> None:
    """Depth images are told by their own name or their depth namespace, not by the camera's name (a first version
    of the shared lookup dropped /depth_cam/image and /stereo_depth_camera/rgb/image_raw as depth)."""
    path = _images(tmp_path / "r", {"/stereo_depth_camera/rgb/image_raw": "raw",
                                    "/stereo_depth_camera/rgb/camera_info": "info",
                                    "/stereo_depth_camera/depth/image_raw": "raw",
                                    "/stereo_depth_camera/depth/image_raw/compressed": "png",
                                    "/stereo_depth_camera/aligned_depth_to_color/image_raw": "raw",
                                    "/depth_cam/image": "raw", "/depth_cam/labels": "raw", "/depth_cam/depth": "raw"})
    with Recording(path) as rec:
        assert rec.image_topics() == ["/depth_cam/image", "/stereo_depth_camera/rgb/image_raw"]
        assert rec.image_topic(camera="/stereo_depth_camera/rgb/camera_info") == "/stereo_depth_camera/rgb/image_raw"
