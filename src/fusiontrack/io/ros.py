"""Conversion between ROS messages (as ``rosbags`` deserialises them) and fusiontrack records.

Both directions live here so that a write-then-read round trip is exact by construction: every
``to_ros`` function has a matching ``from_ros`` that inverts it field by field.

Standard types handled: sensor_msgs LaserScan, Image (rgb8, bgr8, mono8, mono16, 16UC1, 32FC1),
CompressedImage (jpeg/png, and ``compressedDepth`` PNG), Imu, CameraInfo; nav_msgs Odometry;
tf2_msgs TFMessage (tf and tf_static). Annotation types: ``leg_tracker/msg/Person`` (the hand
annotations of the leg_tracker benchmarks), geometry_msgs PoseArray (leg_tracker's training labels),
and fusiontrack's own ``fusiontrack_msgs/msg/GroundTruth`` (what the simulator writes).
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable, Iterator, Mapping
from typing import Any

import cv2
import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype
from rosbags.typesys.store import Typestore

from ..errors import MessageTypeError
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

# Custom message definitions (ROS .msg syntax). Registered in every typestore fusiontrack builds,
# and embedded in the recordings it writes, so other tools (Foxglove, ros2 bag) can read them too.
FUSIONTRACK_TYPES: dict[str, str] = {
    "fusiontrack_msgs/msg/Attribute": (
        "# One named per-object array, stored as raw bytes with its numpy dtype and shape\n"
        "string name\nstring dtype\nuint32[] shape\nuint8[] data\n"
    ),
    "fusiontrack_msgs/msg/GroundTruth": (
        "# The true state of every object at one instant (written by the fusiontrack simulator)\n"
        "std_msgs/Header header\n"
        "int64[] ids\n"
        "float64[] positions_m\n"
        "float64[] velocities_mps\n"
        "string[] classes\n"
        "fusiontrack_msgs/Attribute[] attributes\n"
    ),
}

# leg_tracker's annotation type; it is embedded in the benchmark bags, and registered here for
# recordings whose storage carries no definitions (README of ../shared/data/laser/leg_tracker_outdoor).
LEG_TRACKER_TYPES: dict[str, str] = {
    "leg_tracker/msg/Person": "geometry_msgs/Pose pose\nuint32 id\n",
}

NS = 1_000_000_000


def parse_definitions(definitions: Mapping[str, str]) -> dict[str, Any]:
    """Parse ``{msgtype: definition}`` strings (ROS .msg syntax) into rosbags field definitions.

    Raises
    ------
    MessageTypeError
        When a definition cannot be parsed; the message names the type.
    """
    fields: dict[str, Any] = {}
    for name, text in definitions.items():
        try:
            fields.update(get_types_from_msg(text, name))
        except Exception as err:  # rosbags raises several parser errors
            raise MessageTypeError(f"cannot parse the definition of message type {name!r}: {err}") from err
    return fields


def _referenced_types(node: Any) -> Iterator[str]:
    """Names of the message types a rosbags field description refers to (through arrays too)."""
    kind, detail = node
    if kind == Nodetype.NAME:
        yield detail
    elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        yield from _referenced_types(detail[0])


def build_typestore(custom_types: Mapping[str, str] | None = None, store: Stores = Stores.ROS2_JAZZY) -> Typestore:
    """A typestore with the standard ROS 2 types, fusiontrack's own types and ``custom_types``.

    Raises
    ------
    MessageTypeError
        A custom definition does not parse, or refers to a type that neither it nor the store defines.
    """
    typestore = get_typestore(store)
    fields = parse_definitions({**FUSIONTRACK_TYPES, **LEG_TRACKER_TYPES, **(custom_types or {})})
    known = set(typestore.fielddefs) | set(fields)
    for name, (_, members) in fields.items():
        for field_name, node in members:
            unknown = [t for t in _referenced_types(node) if t not in known]
            if unknown:
                raise MessageTypeError(
                    f"message type {name!r}: field {field_name!r} refers to unknown type {unknown[0]!r}")
    typestore.register(fields)
    return typestore


# --------------------------------------------------------------------------------------------------
# ROS -> fusiontrack
# --------------------------------------------------------------------------------------------------


def stamp_to_ns(stamp: Any) -> int:
    return int(stamp.sec) * NS + int(stamp.nanosec)


def _field(msg: Any, name: str) -> Any:
    """ROS 1 CameraInfo spells ``K``/``D``/``R``/``P`` in capitals, ROS 2 in lower case."""
    value = getattr(msg, name, None)
    return getattr(msg, name.upper()) if value is None else value


def _image_array(msg: Any, dtype: np.dtype, channels: int, topic: str) -> np.ndarray:
    """The pixel array of a sensor_msgs/Image, honouring ``step`` (row padding) and endianness."""
    dtype = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")
    row_bytes = msg.width * channels * dtype.itemsize
    data = np.asarray(msg.data, dtype=np.uint8)
    if msg.width == 0 or msg.height == 0:  # no pixels: as unusable as a truncated image
        raise MessageTypeError(f"{topic}: image of {msg.width}x{msg.height} {msg.encoding} holds no pixels")
    if msg.step < row_bytes or data.size < msg.step * msg.height:
        raise MessageTypeError(
            f"{topic}: image of {msg.width}x{msg.height} {msg.encoding} needs {row_bytes} bytes per row and "
            f"{msg.step * msg.height} in all, got step {msg.step} and {data.size} bytes"
        )
    rows = data[: msg.step * msg.height].reshape(msg.height, msg.step)[:, :row_bytes]
    arr = np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("="))
    return arr.reshape(msg.height, msg.width, channels) if channels > 1 else arr.reshape(msg.height, msg.width)


def image_from_ros(msg: Any, t_ns: int, sensor: str, topic: str) -> Image | DepthImage:
    enc = msg.encoding.lower()
    frame = msg.header.frame_id
    if enc in ("rgb8", "bgr8"):
        return Image(t_ns, sensor, frame, _image_array(msg, np.uint8, 3, topic), enc)
    if enc in ("mono8", "8uc1"):
        return Image(t_ns, sensor, frame, _image_array(msg, np.uint8, 1, topic), "mono8")
    if enc == "mono16":  # 16-bit intensities (or labels); 16UC1 is REP 118's depth encoding
        return Image(t_ns, sensor, frame, _image_array(msg, np.uint16, 1, topic), "mono16")
    if enc in ("32fc1",):
        depth = _image_array(msg, np.float32, 1, topic)
        return DepthImage(t_ns, sensor, frame, depth)
    if enc == "16uc1":
        mm = _image_array(msg, np.uint16, 1, topic)
        depth = mm.astype(np.float32) / 1000.0
        depth[mm == 0] = np.nan
        return DepthImage(t_ns, sensor, frame, depth)
    raise MessageTypeError(
        f"{topic}: image encoding {msg.encoding!r} is not supported "
        "(expected rgb8, bgr8, mono8, mono16, 16UC1 or 32FC1)"
    )


def compressed_from_ros(msg: Any, t_ns: int, sensor: str, topic: str) -> Image | DepthImage:
    data = np.asarray(msg.data, dtype=np.uint8)
    fmt = msg.format.lower()
    if "compresseddepth" in fmt and fmt.startswith("32fc1"):
        # 32-bit compressedDepth holds quantised inverse depth with parameters in its header
        raise MessageTypeError(f"{topic}: 32FC1 compressedDepth (quantised inverse depth) is not supported; "
                               "record the depth as 16UC1 compressedDepth or as a raw image")
    if "compresseddepth" in fmt:
        # image_transport's compressedDepth: a 12-byte config header, then a 16-bit PNG in millimetres.
        mm = cv2.imdecode(data[12:], cv2.IMREAD_UNCHANGED)
        if mm is None or mm.dtype != np.uint16:
            raise MessageTypeError(f"{topic}: cannot decode a compressedDepth image ({msg.format!r})")
        depth = mm.astype(np.float32) / 1000.0
        depth[mm == 0] = np.nan
        return DepthImage(t_ns, sensor, msg.header.frame_id, depth)
    pixels = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if pixels is None:
        raise MessageTypeError(f"{topic}: cannot decode a compressed image (format {msg.format!r}, {data.size} bytes)")
    if pixels.ndim == 2:
        return Image(t_ns, sensor, msg.header.frame_id, pixels, "mono16" if pixels.dtype == np.uint16 else "mono8")
    if pixels.shape[2] == 4:
        pixels = cv2.cvtColor(pixels, cv2.COLOR_BGRA2BGR)
    if fmt.startswith("rgb8"):  # image_transport's "rgb8; jpeg compressed bgr8": the source was RGB
        return Image(t_ns, sensor, msg.header.frame_id, pixels[:, :, ::-1], "rgb8")
    return Image(t_ns, sensor, msg.header.frame_id, pixels, "bgr8")


def laserscan_from_ros(msg: Any, t_ns: int, sensor: str, topic: str) -> LaserScan:
    return LaserScan(
        t_ns, sensor, msg.header.frame_id,
        angle_min_rad=msg.angle_min, angle_increment_rad=msg.angle_increment,
        range_min_m=msg.range_min, range_max_m=msg.range_max,
        ranges_m=np.asarray(msg.ranges, np.float32), intensities=np.asarray(msg.intensities, np.float32),
        time_increment_s=msg.time_increment, scan_time_s=msg.scan_time, angle_max_rad=msg.angle_max,
    )


def _xyz(v: Any) -> list[float]:
    return [v.x, v.y, v.z]


def _xyzw(q: Any) -> list[float]:
    return [q.x, q.y, q.z, q.w]


def imu_from_ros(msg: Any, t_ns: int, sensor: str, topic: str) -> ImuSample:
    # REP 145: covariance[0] == -1 means "this field is not provided".
    gyro = _xyz(msg.angular_velocity) if msg.angular_velocity_covariance[0] != -1 else [np.nan] * 3
    quat = _xyzw(msg.orientation) if msg.orientation_covariance[0] != -1 else None
    return ImuSample(t_ns, sensor, msg.header.frame_id, _xyz(msg.linear_acceleration), gyro, quat)


def camera_info_from_ros(msg: Any, t_ns: int, sensor: str, topic: str) -> CameraInfo:
    K = np.asarray(_field(msg, "k"), np.float64).reshape(3, 3)
    R = np.asarray(_field(msg, "r"), np.float64).reshape(3, 3)
    P = np.asarray(_field(msg, "p"), np.float64).reshape(3, 4)
    return CameraInfo(t_ns, sensor, msg.header.frame_id, msg.width, msg.height, K,
                      np.asarray(_field(msg, "d"), np.float64), msg.distortion_model, R, P)


def odometry_from_ros(msg: Any, t_ns: int, sensor: str, topic: str) -> Odometry:
    return Odometry(t_ns, sensor, msg.header.frame_id, msg.child_frame_id,
                    _xyz(msg.pose.pose.position), _xyzw(msg.pose.pose.orientation),
                    _xyz(msg.twist.twist.linear), _xyz(msg.twist.twist.angular))


def tf_from_ros(msg: Any, t_ns: int, sensor: str, topic: str) -> list[Transform]:
    static = topic.rstrip("/").endswith("tf_static")
    return [
        Transform(stamp_to_ns(tr.header.stamp) or t_ns, sensor, tr.header.frame_id, tr.child_frame_id,
                  _xyz(tr.transform.translation), _xyzw(tr.transform.rotation), static)
        for tr in msg.transforms
    ]


def person_from_ros(msg: Any, t_ns: int, sensor: str, topic: str) -> GroundTruth:
    """leg_tracker's Person annotation: one position (laser frame) and an id, no header."""
    p = msg.pose.position
    return GroundTruth(t_ns, sensor, "", [msg.id], [[p.x, p.y]], classes=("person",))


def pose_array_from_ros(msg: Any, t_ns: int, sensor: str, topic: str) -> GroundTruth:
    """A PoseArray of labelled positions (leg_tracker's training leg clusters): no identities (id -1)."""
    xy = np.array([[p.position.x, p.position.y] for p in msg.poses], np.float64).reshape(-1, 2)
    n = len(xy)
    return GroundTruth(t_ns, sensor, msg.header.frame_id, np.full(n, -1), xy, classes=("unknown",) * n)


def ground_truth_from_ros(msg: Any, t_ns: int, sensor: str, topic: str) -> GroundTruth:
    n = len(msg.ids)
    attrs = {
        a.name: np.frombuffer(np.asarray(a.data, np.uint8).tobytes(), dtype=np.dtype(a.dtype)).reshape(
            tuple(int(s) for s in a.shape))
        for a in msg.attributes
    }
    return GroundTruth(t_ns, sensor, msg.header.frame_id, np.asarray(msg.ids, np.int64),
                       np.asarray(msg.positions_m, np.float64).reshape(n, 2),
                       np.asarray(msg.velocities_mps, np.float64).reshape(n, 2),
                       tuple(msg.classes), attrs)


Converter = Callable[[Any, int, str, str], Message | list[Transform]]

FROM_ROS: dict[str, Converter] = {
    "sensor_msgs/msg/LaserScan": laserscan_from_ros,
    "sensor_msgs/msg/Image": image_from_ros,
    "sensor_msgs/msg/CompressedImage": compressed_from_ros,
    "sensor_msgs/msg/Imu": imu_from_ros,
    "sensor_msgs/msg/CameraInfo": camera_info_from_ros,
    "nav_msgs/msg/Odometry": odometry_from_ros,
    "tf2_msgs/msg/TFMessage": tf_from_ros,
    "leg_tracker/msg/Person": person_from_ros,
    "geometry_msgs/msg/PoseArray": pose_array_from_ros,
    "fusiontrack_msgs/msg/GroundTruth": ground_truth_from_ros,
}
"""Message types fusiontrack converts into its records, by ROS 2 type name."""

HEADERLESS = frozenset({"leg_tracker/msg/Person", "tf2_msgs/msg/TFMessage"})
"""Types without a header stamp: their time is the recording's log time."""


# --------------------------------------------------------------------------------------------------
# fusiontrack -> ROS (for writing recordings)
# --------------------------------------------------------------------------------------------------


class RosEncoder:
    """Builds ROS 2 message objects of a typestore from fusiontrack records.

    ``image_format`` chooses how colour and depth images are stored: ``"raw"`` (sensor_msgs/Image)
    or ``"png"`` (sensor_msgs/CompressedImage; lossless, so round trips stay exact).
    """

    def __init__(self, typestore: Typestore, image_format: str = "raw") -> None:
        if image_format not in ("raw", "png"):
            raise ValueError(f"image_format: expected 'raw' or 'png', got {image_format!r}")
        self.ts = typestore
        self.t = typestore.types
        self.image_format = image_format

    def header(self, t_ns: int, frame_id: str) -> Any:
        stamp = self.t["builtin_interfaces/msg/Time"](sec=t_ns // NS, nanosec=t_ns % NS)
        return self.t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def _vec3(self, v: np.ndarray) -> Any:
        return self.t["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def _quat(self, q: np.ndarray) -> Any:
        return self.t["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    def msgtype(self, record: Message) -> str:
        """The ROS type a record is written as."""
        if isinstance(record, Image | DepthImage):
            return "sensor_msgs/msg/CompressedImage" if self.image_format == "png" else "sensor_msgs/msg/Image"
        return {
            LaserScan: "sensor_msgs/msg/LaserScan",
            ImuSample: "sensor_msgs/msg/Imu",
            CameraInfo: "sensor_msgs/msg/CameraInfo",
            Odometry: "nav_msgs/msg/Odometry",
            Transform: "tf2_msgs/msg/TFMessage",
            GroundTruth: "fusiontrack_msgs/msg/GroundTruth",
        }[type(record)]

    def encode(self, record: Message) -> Any:
        method: Callable[[Any], Any] = getattr(self, "_" + type(record).__name__.lower())
        return method(record)

    def _laserscan(self, s: LaserScan) -> Any:
        return self.t["sensor_msgs/msg/LaserScan"](
            header=self.header(s.t_ns, s.frame_id), angle_min=s.angle_min_rad,
            angle_max=s.angle_max_rad, angle_increment=s.angle_increment_rad,
            time_increment=s.time_increment_s, scan_time=s.scan_time_s,
            range_min=s.range_min_m, range_max=s.range_max_m,
            ranges=np.asarray(s.ranges_m, np.float32), intensities=np.asarray(s.intensities, np.float32))

    def _compressed(self, t_ns: int, frame_id: str, fmt: str, buf: np.ndarray) -> Any:
        return self.t["sensor_msgs/msg/CompressedImage"](
            header=self.header(t_ns, frame_id), format=fmt, data=np.asarray(buf, np.uint8).ravel())

    def _raw_image(self, t_ns: int, frame_id: str, arr: np.ndarray, encoding: str) -> Any:
        h, w = arr.shape[:2]
        arr = np.ascontiguousarray(arr)
        return self.t["sensor_msgs/msg/Image"](
            header=self.header(t_ns, frame_id), height=h, width=w, encoding=encoding,
            is_bigendian=0, step=arr.nbytes // max(h, 1), data=arr.view(np.uint8).ravel())

    def _image(self, im: Image) -> Any:
        if self.image_format == "png":
            ok, buf = cv2.imencode(".png", np.ascontiguousarray(im.bgr()) if im.encoding == "rgb8" else im.pixels)
            if not ok:
                raise MessageTypeError(f"{im.sensor}: PNG encoding of a {im.width}x{im.height} image failed")
            return self._compressed(im.t_ns, im.frame_id, f"{im.encoding}; png compressed bgr8", buf)
        return self._raw_image(im.t_ns, im.frame_id, im.pixels, im.encoding)

    def _depthimage(self, d: DepthImage) -> Any:
        if self.image_format == "png":
            # compressedDepth stores millimetres: lossless only for depth on a 1 mm grid.
            mm = np.nan_to_num(np.round(d.depth_m * 1000.0), nan=0.0).clip(0, 65535).astype(np.uint16)
            ok, buf = cv2.imencode(".png", mm)
            if not ok:
                raise MessageTypeError(f"{d.sensor}: PNG encoding of a depth image failed")
            return self._compressed(d.t_ns, d.frame_id, "16UC1; compressedDepth png",
                                    np.concatenate([np.zeros(12, np.uint8), buf.ravel()]))
        return self._raw_image(d.t_ns, d.frame_id, d.depth_m, "32FC1")

    def _imusample(self, m: ImuSample) -> Any:
        no_cov = np.zeros(9)
        missing = np.array([-1.0] + [0.0] * 8)
        has_gyro = bool(np.all(np.isfinite(m.gyro_radps)))
        quat = m.orientation_xyzw if m.orientation_xyzw is not None else np.array([0.0, 0.0, 0.0, 1.0])
        return self.t["sensor_msgs/msg/Imu"](
            header=self.header(m.t_ns, m.frame_id), orientation=self._quat(quat),
            orientation_covariance=no_cov if m.orientation_xyzw is not None else missing,
            angular_velocity=self._vec3(m.gyro_radps if has_gyro else np.zeros(3)),
            angular_velocity_covariance=no_cov if has_gyro else missing,
            linear_acceleration=self._vec3(m.accel_mps2), linear_acceleration_covariance=no_cov)

    def _camerainfo(self, c: CameraInfo) -> Any:
        roi = self.t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return self.t["sensor_msgs/msg/CameraInfo"](
            header=self.header(c.t_ns, c.frame_id), height=c.height, width=c.width,
            distortion_model=c.distortion_model, d=np.asarray(c.D, np.float64),
            k=np.asarray(c.K, np.float64).ravel(), r=np.asarray(c.R, np.float64).ravel(),
            p=np.asarray(c.P, np.float64).ravel(), binning_x=0, binning_y=0, roi=roi)

    def _odometry(self, o: Odometry) -> Any:
        t = self.t
        point = t["geometry_msgs/msg/Point"](x=float(o.position_m[0]), y=float(o.position_m[1]),
                                             z=float(o.position_m[2]))
        pose = t["geometry_msgs/msg/PoseWithCovariance"](
            pose=t["geometry_msgs/msg/Pose"](position=point, orientation=self._quat(o.orientation_xyzw)),
            covariance=np.zeros(36))
        twist = t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](linear=self._vec3(o.linear_velocity_mps),
                                               angular=self._vec3(o.angular_velocity_radps)),
            covariance=np.zeros(36))
        return t["nav_msgs/msg/Odometry"](header=self.header(o.t_ns, o.frame_id), child_frame_id=o.child_frame_id,
                                          pose=pose, twist=twist)

    def _transform(self, tr: Transform) -> Any:
        t = self.t
        stamped = t["geometry_msgs/msg/TransformStamped"](
            header=self.header(tr.t_ns, tr.parent_frame), child_frame_id=tr.child_frame,
            transform=t["geometry_msgs/msg/Transform"](translation=self._vec3(tr.translation_m),
                                                       rotation=self._quat(tr.rotation_xyzw)))
        return t["tf2_msgs/msg/TFMessage"](transforms=[stamped])

    def _groundtruth(self, g: GroundTruth) -> Any:
        attr_type = self.t["fusiontrack_msgs/msg/Attribute"]
        attrs = []
        for name, arr in g.attributes.items():
            arr = np.ascontiguousarray(arr)
            if arr.dtype.kind not in "biuf":
                raise MessageTypeError(f"ground truth attribute {name!r}: only numeric arrays can be written, "
                                       f"got dtype {arr.dtype}")
            attrs.append(attr_type(name=name, dtype=arr.dtype.str, shape=np.array(arr.shape, np.uint32),
                                   data=np.frombuffer(arr.tobytes(), np.uint8).copy()))
        return self.t["fusiontrack_msgs/msg/GroundTruth"](
            header=self.header(g.t_ns, g.frame_id), ids=np.asarray(g.ids, np.int64),
            positions_m=np.asarray(g.positions_m, np.float64).ravel(),
            velocities_mps=np.asarray(g.velocities_mps, np.float64).ravel(),
            classes=list(g.classes), attributes=attrs)


def sensor_map_to_json(sensors: Mapping[str, str]) -> str:
    return json.dumps(dict(sorted(sensors.items())))


# --------------------------------------------------------------------------------------------------
# Fast path: LaserScan straight from the wire bytes
# --------------------------------------------------------------------------------------------------
# Scans are most of a laser recording and their layout is fixed, so they are decoded with struct and
# np.frombuffer instead of rosbags' generic deserialiser (about twice as fast overall, see
# benchmarks/read_throughput.py). The decoder checks that it consumed the buffer exactly; anything
# unexpected returns None and the caller falls back to the generic path.

_SCAN_FLOATS = {"<": struct.Struct("<7f"), ">": struct.Struct(">7f")}


def _scan_from_parts(
    buf: bytes, pos: int, order: str, t_ns: int, frame_id: str, sensor: str, align: bool
) -> LaserScan | None:
    floats = _SCAN_FLOATS[order]
    if align:
        pos += -pos % 4
    a_min, a_max, a_inc, t_inc, scan_t, r_min, r_max = floats.unpack_from(buf, pos)
    pos += floats.size
    arrays = []
    for _ in range(2):
        if align:
            pos += -pos % 4
        (n,) = struct.unpack_from(order + "I", buf, pos)
        pos += 4
        if pos + 4 * n > len(buf):
            return None
        arrays.append(np.frombuffer(buf, np.dtype(order + "f4"), n, pos))
        pos += 4 * n
    if len(buf) - pos >= 4 or (not align and pos != len(buf)):  # CDR may pad the end to 4 bytes
        return None
    return LaserScan(t_ns, sensor, frame_id, a_min, a_inc, r_min, r_max, arrays[0], arrays[1], t_inc, scan_t, a_max)


def laserscan_from_ros1_bytes(buf: bytes, sensor: str) -> LaserScan | None:
    """Decode a ROS 1 sensor_msgs/LaserScan (little-endian, no alignment) or return None."""
    try:
        _seq, sec, nsec, n_frame = struct.unpack_from("<IIII", buf, 0)
        frame_id = bytes(buf[16:16 + n_frame]).decode()
        return _scan_from_parts(buf, 16 + n_frame, "<", sec * NS + nsec, frame_id, sensor, align=False)
    except (struct.error, UnicodeDecodeError, ValueError):
        return None


_IMAGE_WIRE = {"rgb8": (np.uint8, 3, "rgb8"), "bgr8": (np.uint8, 3, "bgr8"), "mono8": (np.uint8, 1, "mono8"),
               "8uc1": (np.uint8, 1, "mono8"), "mono16": (np.uint16, 1, "mono16")}


def image_from_cdr_bytes(buf: bytes, sensor: str) -> Image | None:
    """Decode a ROS 2 (CDR) sensor_msgs/msg/Image of a colour, grey or 16-bit encoding, its pixels a view of
    ``buf`` (no copy when the rows are not padded and the byte order is the machine's), or return None (other
    encodings, depth, a buffer it does not understand: the caller takes the general path)."""
    try:
        order = "<" if buf[1] == 1 else ">"
        body = memoryview(buf)[4:]  # CDR aligns relative to the end of the 4-byte encapsulation header
        sec, nsec, n_frame = struct.unpack_from(order + "iII", body, 0)
        pos = 12 + n_frame
        frame_id = bytes(body[12:pos]).rstrip(b"\x00").decode()
        pos += -pos % 4
        height, width, n_enc = struct.unpack_from(order + "III", body, pos)
        pos += 12
        spec = _IMAGE_WIRE.get(bytes(body[pos:pos + n_enc]).rstrip(b"\x00").decode().lower())
        pos += n_enc
        big = body[pos]
        pos += 1
        pos += -pos % 4
        step, n_data = struct.unpack_from(order + "II", body, pos)
        pos += 8
        if spec is None or height == 0 or width == 0:
            return None
        dtype, channels, encoding = spec
        wire = np.dtype(dtype).newbyteorder(">" if big else "<")
        row = width * channels * wire.itemsize
        if step < row or n_data < step * height or pos + n_data > len(body):
            return None
        rows = np.frombuffer(buf, np.uint8, step * height, 4 + pos).reshape(height, step)
        if step != row:
            rows = np.ascontiguousarray(rows[:, :row])
        pixels = rows.view(wire)
        if not wire.isnative:
            pixels = pixels.astype(wire.newbyteorder("="))
        shape = (height, width, channels) if channels > 1 else (height, width)
        return Image.trusted(sec * NS + nsec, sensor, frame_id, pixels.reshape(shape), encoding)
    except (struct.error, UnicodeDecodeError, ValueError, IndexError):
        return None


def laserscan_from_cdr_bytes(buf: bytes, sensor: str) -> LaserScan | None:
    """Decode a ROS 2 (CDR) sensor_msgs/msg/LaserScan or return None."""
    try:
        order = "<" if buf[1] == 1 else ">"
        body = memoryview(buf)[4:]  # CDR aligns relative to the end of the 4-byte encapsulation header
        sec, nsec, n_frame = struct.unpack_from(order + "iII", body, 0)
        frame_id = bytes(body[12:12 + n_frame]).rstrip(b"\x00").decode()
        return _scan_from_parts(bytes(body), 12 + n_frame, order, sec * NS + nsec, frame_id, sensor, align=True)
    except (struct.error, UnicodeDecodeError, ValueError, IndexError):
        return None
