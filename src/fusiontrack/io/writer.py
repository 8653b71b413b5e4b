"""Writing recordings: rosbag2 (MCAP by default) with standard ROS message types.

The simulator writes its recordings through :class:`RecordingWriter`, so simulated and real data go
through the same readers. Topics follow one layout per sensor name:

=====================  ==================================  ================================
record                 topic                                ROS type
=====================  ==================================  ================================
LaserScan              ``/<sensor>/scan``                  sensor_msgs/msg/LaserScan
Image                  ``/<sensor>/image``                 sensor_msgs/msg/Image (or CompressedImage)
DepthImage             ``/<sensor>/depth``                 sensor_msgs/msg/Image 32FC1
CameraInfo             ``/<sensor>/camera_info``           sensor_msgs/msg/CameraInfo
ImuSample              ``/<sensor>/imu``                   sensor_msgs/msg/Imu
Odometry               ``/<sensor>/odom``                  nav_msgs/msg/Odometry
Transform              ``/tf`` or ``/tf_static``           tf2_msgs/msg/TFMessage
GroundTruth            ``/<sensor>``                       fusiontrack_msgs/msg/GroundTruth
=====================  ==================================  ================================

A record whose ``sensor`` already is a topic (starts with ``/``) is written to that topic, so
messages read from a bag go back where they came from. The topic -> sensor map is stored in the
bag's metadata, so reading it back gives every record its original ``sensor``.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Literal

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys.store import Typestore

from ..errors import RecordingError
from ..types import (
    CameraInfo,
    DepthImage,
    GroundTruth,
    Image,
    ImuSample,
    LaserScan,
    Message,
    Odometry,
    Transform,
)
from .recording import SENSOR_MAP_KEY
from .ros import RosEncoder, build_typestore, sensor_map_to_json

log = logging.getLogger(__name__)

_SUFFIX: dict[type, str] = {
    LaserScan: "scan",
    Image: "image",
    DepthImage: "depth",
    CameraInfo: "camera_info",
    ImuSample: "imu",
    Odometry: "odom",
}


def default_topic(record: Message) -> str:
    """The topic :class:`RecordingWriter` uses for a record (see the module table)."""
    if isinstance(record, Transform):
        return "/tf_static" if record.static else "/tf"
    if record.sensor.startswith("/"):
        return record.sensor
    if isinstance(record, GroundTruth):
        return "/" + record.sensor
    return f"/{record.sensor}/{_SUFFIX[type(record)]}"


class RecordingWriter:
    """Write fusiontrack records into a new rosbag2 recording (a folder with ``metadata.yaml``).

    Parameters
    ----------
    path : folder to create; it must not exist yet.
    storage : ``"mcap"`` (default) or ``"sqlite3"``.
    image_format : ``"raw"`` (sensor_msgs/Image) or ``"png"`` (lossless CompressedImage).
    custom_types : further message definitions to register (ROS .msg syntax).

    Use as a context manager; records may be written in any order (readers sort by log time).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        storage: Literal["mcap", "sqlite3"] = "mcap",
        image_format: Literal["raw", "png"] = "raw",
        custom_types: Mapping[str, str] | None = None,
    ) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise RecordingError(f"{self.path}: already exists; fusiontrack does not overwrite recordings")
        if storage not in ("mcap", "sqlite3"):
            raise RecordingError(f"storage: expected 'mcap' or 'sqlite3', got {storage!r}")
        if self.path.suffix.lower() in (".mcap", ".db3", ".bag"):
            # (rosbags would make a folder x.mcap holding x.mcap.mcap)
            raise RecordingError(f"{self.path}: a recording is written as a rosbag2 folder (its {storage} file and "
                                 f"metadata.yaml inside); name the folder, e.g. {self.path.with_suffix('')}")
        self.typestore: Typestore = build_typestore(custom_types)
        self.encoder = RosEncoder(self.typestore, image_format)
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        self._writer = Writer(self.path, version=9, storage_plugin=plugin)
        self._connections: dict[tuple[str, str], Any] = {}
        self._sensors: dict[str, str] = {}
        self.count = 0
        self._made: Path | None = None  # the folder this writer created (rosbags' open makes it, or fails)
        try:
            self._writer.open()
        except Exception as err:
            raise RecordingError(f"{self.path}: cannot create the recording: {err}") from err
        self._made = self.path

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        if exc_type is None:
            self.close()
            return
        try:  # stopped part way (Ctrl-C, an error): a cut-off recording opens and looks whole
            self.close()
        except Exception:  # (closing must not hide the error that stopped the writing)
            log.debug("error while closing %s", self.path, exc_info=True)
        self.discard()

    def discard(self) -> None:
        """Remove the recording this writer created (an incomplete one), with a warning; nothing else."""
        made, self._made = self._made, None
        if made is not None and made.is_dir():
            import shutil

            shutil.rmtree(made, ignore_errors=True)
            log.warning("stopped: the incomplete recording %s was removed", made)

    def _connection(self, topic: str, msgtype: str) -> Any:
        key = (topic, msgtype)
        if key not in self._connections:
            self._connections[key] = self._writer.add_connection(topic, msgtype, typestore=self.typestore)
        return self._connections[key]

    def write(self, record: Message, topic: str | None = None, log_t_ns: int | None = None,
              image_format: Literal["raw", "png"] | None = None) -> None:
        """Write one record (log time = the record's time unless ``log_t_ns`` is given).

        ``image_format`` overrides the writer's choice for this record (e.g. PNG for label images).
        """
        topic = topic or default_topic(record)
        encoder = self.encoder if image_format in (None, self.encoder.image_format) else \
            RosEncoder(self.typestore, image_format)
        msgtype = encoder.msgtype(record)
        data = self.typestore.serialize_cdr(encoder.encode(record), msgtype)
        self._writer.write(self._connection(topic, msgtype), record.t_ns if log_t_ns is None else log_t_ns, data)
        if not isinstance(record, Transform):
            self._sensors[topic] = record.sensor
        self.count += 1

    def write_all(self, records: Iterable[Message]) -> int:
        n = 0
        for record in records:
            self.write(record)
            n += 1
        return n

    def close(self) -> None:
        if self._writer is None:
            return
        writer, self._writer = self._writer, None
        if self._sensors:
            writer.set_custom_data(SENSOR_MAP_KEY, sensor_map_to_json(self._sensors))
        writer.close()


def write_recording(path: str | Path, records: Iterable[Message], **kwargs: Any) -> int:
    """Write ``records`` into a new rosbag2 recording at ``path``; returns the number written."""
    with RecordingWriter(path, **kwargs) as writer:
        return writer.write_all(records)
