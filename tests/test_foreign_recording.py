"""A recording made by other tools has none of fusiontrack's sensor metadata: each topic is its own sensor, and
only the ROS names tie an image topic to its ``camera_info`` and a scan to its frame in ``/tf_static``. The fused
pipeline must still find its camera (it used to track with the lasers only: "no CameraInfo")."""

from __future__ import annotations

import math
from pathlib import Path

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
