"""The data model: immutable records with integer-nanosecond time and the name of their sensor.

Every message, detection, track state, ground-truth frame and event carries ``t_ns`` (nanoseconds,
the recording's clock) and ``sensor`` (a key into the pipeline's sensor set, e.g. ``"laser_front"``;
for messages read from a bag it defaults to the topic name). Arrays are converted once on
construction to the documented dtype and made read-only, so a record can be shared between
components without copying and without anyone changing it behind another's back.

Conventions (ALGORITHMS.md 0.2): metres, seconds, radians; image origin top-left, ``u`` right,
``v`` down; a box is ``(u_min, v_min, u_max, v_max)`` in pixels; the world floor frame has ``Z`` up.
"""

from __future__ import annotations

import dataclasses
import enum
import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

__all__ = [
    "CameraInfo",
    "DepthImage",
    "Detection",
    "Event",
    "GroundTruth",
    "Image",
    "ImuSample",
    "LaserScan",
    "Message",
    "ObjectClass",
    "Odometry",
    "Situation",
    "Track",
    "TrackState",
    "Transform",
    "records_equal",
]


class ObjectClass(enum.StrEnum):
    """What a target is (seed 001 B18, seed 003 D5)."""

    PERSON = "person"
    BICYCLE = "bicycle"
    CAR = "car"
    GROUP = "group"
    UNKNOWN = "unknown"


class Situation(enum.StrEnum):
    """The tracking situation of a target in the current frame (seed 001, ALGORITHMS.md B7)."""

    NONCORRELATED = "noncorrelated"
    CORRELATED = "correlated"
    MERGED = "merged"
    APPEARING = "appearing"
    DISAPPEARING = "disappearing"


def _frozen_array(value: Any, dtype: Any, shape: tuple[int | None, ...] | None, name: str) -> np.ndarray:
    """Convert to a read-only array of ``dtype``; check the shape (``None`` = any length on that axis)."""
    arr = np.array(value, dtype=dtype, copy=True)
    if shape is not None and (arr.ndim != len(shape) or (shape != (None,) and any(
            s is not None and s != n for s, n in zip(shape, arr.shape, strict=True)))):
        want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected an array of shape {want}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


def _optional_array(value: Any, dtype: Any, shape: tuple[int | None, ...] | None, name: str) -> np.ndarray | None:
    return None if value is None else _frozen_array(value, dtype, shape, name)


_EMPTY: Mapping[str, Any] = MappingProxyType({})


def _set(obj: object, name: str, value: Any) -> None:
    object.__setattr__(obj, name, value)


def _rebuild_record(cls: type, values: tuple[tuple[bool, Any], ...]) -> Any:
    """Unpickle a record of :func:`_reduce_record`: its read-only mappings and arrays read-only again."""
    obj = object.__new__(cls)
    for f, (proxy, v) in zip(dataclasses.fields(cls), values, strict=True):
        for a in (v.values() if proxy else (v,)):
            if isinstance(a, np.ndarray):
                a.setflags(write=False)
        _set(obj, f.name, MappingProxyType(v) if proxy else v)
    return obj


def _reduce_record(self: Any) -> tuple[Any, ...]:
    """Pickle support for the records holding read-only mappings (``MappingProxyType`` cannot be pickled): the
    fields as they are, without the constructor's checks (they passed them), e.g. a camera worker's detections."""
    values = tuple((isinstance(v, MappingProxyType), dict(v) if isinstance(v, MappingProxyType) else v)
                   for v in (getattr(self, f.name) for f in dataclasses.fields(self)))
    return _rebuild_record, (type(self), values)


def _check_time(t_ns: Any, name: str = "t_ns") -> int:
    if isinstance(t_ns, bool) or not isinstance(t_ns, int | np.integer):
        raise TypeError(f"{name}: expected an integer number of nanoseconds, got {type(t_ns).__name__}")
    return int(t_ns)


# --------------------------------------------------------------------------------------------------
# Sensor messages
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class LaserScan:
    """One sweep of a planar laser range finder (sensor_msgs/LaserScan).

    ``ranges_m`` is kept exactly as measured (float32, as in ROS); readings that are not valid
    (``NaN``, ``inf``, ``<= range_min_m`` or ``>= range_max_m``) become ``NaN`` in
    :meth:`valid_ranges_m` and in :func:`fusiontrack.geometry.scan_to_points`.

    Attributes
    ----------
    ranges_m : (n_beams,) float32
        Range of beam ``i`` at angle ``angle_min_rad + i * angle_increment_rad`` (counter-clockwise
        from the sensor x-axis).
    intensities : (n_beams,) float32 or (0,)
        Return intensities; empty when the sensor gives none.
    angle_max_rad : float
        As recorded (ROS ``angle_max``); some drivers report the end of the field of view rather than
        the last beam's angle, so beam angles are always ``angle_min_rad + i * angle_increment_rad``.
    """

    t_ns: int
    sensor: str
    frame_id: str
    angle_min_rad: float
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    ranges_m: np.ndarray
    intensities: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    time_increment_s: float = 0.0
    scan_time_s: float = 0.0
    angle_max_rad: float | None = None

    _FLOAT32_FIELDS = ("angle_min_rad", "angle_increment_rad", "range_min_m", "range_max_m",
                       "time_increment_s", "scan_time_s", "angle_max_rad")

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        ranges = _frozen_array(self.ranges_m, np.float32, (None,), "LaserScan.ranges_m")
        intensities = _frozen_array(self.intensities, np.float32, (None,), "LaserScan.intensities")
        if intensities.size not in (0, ranges.size):
            raise ValueError(f"LaserScan.intensities: expected 0 or {ranges.size} values, got {intensities.size}")
        _set(self, "ranges_m", ranges)
        _set(self, "intensities", intensities)
        if self.angle_max_rad is None:  # ROS: angle of the last beam
            _set(self, "angle_max_rad", self.angle_min_rad + (ranges.size - 1) * self.angle_increment_rad)
        # sensor_msgs/LaserScan stores these as float32: hold exactly what a recording can hold
        # (one array conversion for all seven: this runs once per scan on the read path).
        with np.errstate(over="ignore"):  # a corrupted header beyond float32's range reads as inf, as ROS would hold it
            values = np.array([getattr(self, name) for name in self._FLOAT32_FIELDS], np.float32).tolist()
        for name, value in zip(self._FLOAT32_FIELDS, values, strict=True):
            _set(self, name, value)

    @property
    def n_beams(self) -> int:
        return int(self.ranges_m.size)

    def angles_rad(self) -> np.ndarray:
        """Beam angles, ``(n_beams,) float64``; NaN for every beam of a header whose angles are not finite (a
        corrupted message)."""
        if not (math.isfinite(self.angle_min_rad) and math.isfinite(self.angle_increment_rad)):
            return np.full(self.n_beams, np.nan)
        return self.angle_min_rad + np.arange(self.n_beams) * self.angle_increment_rad

    def valid_ranges_m(self) -> np.ndarray:
        """Ranges as float64 with every invalid reading replaced by ``NaN``, ``(n_beams,)``; all of them when the
        header's angles are not finite (a corrupted message: no beam has a direction)."""
        r = self.ranges_m.astype(np.float64)
        if not (math.isfinite(self.angle_min_rad) and math.isfinite(self.angle_increment_rad)):
            return np.full_like(r, np.nan)
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(r) | (r <= self.range_min_m) | (r >= self.range_max_m)
        r[bad] = np.nan
        return r


@dataclass(frozen=True, slots=True, eq=False)
class Image:
    """A colour or grey image (sensor_msgs/Image or CompressedImage after decoding).

    Attributes
    ----------
    pixels : (H, W, 3) uint8 for ``rgb8``/``bgr8``, (H, W) uint8 for ``mono8``, (H, W) uint16 for ``mono16``
    encoding : str
        ``"bgr8"`` (OpenCV's order, what decoders and the simulator produce), ``"rgb8"``, ``"mono8"``, or
        ``"mono16"`` (16-bit intensities or labels: the simulator's per-pixel agent labels). A 16-bit
        *depth* image is ``16UC1`` in ROS and becomes a :class:`DepthImage`.
    """

    t_ns: int
    sensor: str
    frame_id: str
    pixels: np.ndarray
    encoding: str = "bgr8"

    _SHAPES = MappingProxyType({"bgr8": 3, "rgb8": 3, "mono8": 2, "mono16": 2})

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        if self.encoding not in self._SHAPES:
            raise ValueError(f"Image.encoding: expected one of {sorted(self._SHAPES)}, got {self.encoding!r}")
        shape: tuple[int | None, ...] = (None, None, 3) if self._SHAPES[self.encoding] == 3 else (None, None)
        dtype = np.uint16 if self.encoding == "mono16" else np.uint8
        _set(self, "pixels", _frozen_array(self.pixels, dtype, shape, f"Image.pixels ({self.encoding})"))

    @staticmethod
    def trusted(t_ns: int, sensor: str, frame_id: str, pixels: np.ndarray, encoding: str = "bgr8") -> Image:
        """An image from pixels a reader already holds in the documented form, without checks or a copy (the
        recording reader's hot path; ``Image(...)`` is the checked constructor).

        The caller guarantees: ``t_ns`` an int, ``encoding`` one of the four, ``pixels`` of its dtype and shape
        (native byte order). The array is made read-only here, not copied: it may be a view of the message's
        bytes."""
        im = object.__new__(Image)
        pixels.setflags(write=False)
        _set(im, "t_ns", t_ns)
        _set(im, "sensor", sensor)
        _set(im, "frame_id", frame_id)
        _set(im, "pixels", pixels)
        _set(im, "encoding", encoding)
        return im

    @property
    def height(self) -> int:
        return int(self.pixels.shape[0])

    @property
    def width(self) -> int:
        return int(self.pixels.shape[1])

    def bgr(self) -> np.ndarray:
        """The pixels as ``(H, W, 3) uint8`` in OpenCV's BGR order (a view when already BGR)."""
        if self.encoding == "bgr8":
            return self.pixels
        if self.encoding == "rgb8":
            return self.pixels[:, :, ::-1]
        grey = self.pixels if self.encoding == "mono8" else (self.pixels >> 8).astype(np.uint8)
        return np.repeat(grey[:, :, None], 3, axis=2)


@dataclass(frozen=True, slots=True, eq=False)
class DepthImage:
    """Metric depth registered to a camera (sensor_msgs/Image ``32FC1`` metres or ``16UC1`` millimetres).

    Attributes
    ----------
    depth_m : (H, W) float32
        Distance along the optical axis in metres; ``NaN`` where the sensor has no reading
        (``0`` in a ``16UC1`` image).
    """

    t_ns: int
    sensor: str
    frame_id: str
    depth_m: np.ndarray

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        _set(self, "depth_m", _frozen_array(self.depth_m, np.float32, (None, None), "DepthImage.depth_m"))

    @property
    def height(self) -> int:
        return int(self.depth_m.shape[0])

    @property
    def width(self) -> int:
        return int(self.depth_m.shape[1])


@dataclass(frozen=True, slots=True, eq=False)
class ImuSample:
    """One inertial sample (sensor_msgs/Imu), in the IMU's own body frame.

    Attributes
    ----------
    accel_mps2 : (3,) float64
        Specific force in m/s^2 (gravity included, as a phone reports it).
    gyro_radps : (3,) float64
        Angular rate in rad/s; ``NaN`` when the device has no gyroscope (e.g. accelerometer CSV).
    orientation_xyzw : (4,) float64 or None
        Orientation quaternion when the device provides one.
    """

    t_ns: int
    sensor: str
    frame_id: str
    accel_mps2: np.ndarray
    gyro_radps: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    orientation_xyzw: np.ndarray | None = None

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        _set(self, "accel_mps2", _frozen_array(self.accel_mps2, np.float64, (3,), "ImuSample.accel_mps2"))
        _set(self, "gyro_radps", _frozen_array(self.gyro_radps, np.float64, (3,), "ImuSample.gyro_radps"))
        _set(self, "orientation_xyzw",
             _optional_array(self.orientation_xyzw, np.float64, (4,), "ImuSample.orientation_xyzw"))


@dataclass(frozen=True, slots=True, eq=False)
class CameraInfo:
    """Intrinsic calibration of a camera (sensor_msgs/CameraInfo).

    Attributes
    ----------
    K : (3, 3) float64
        Camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels.
    D : (n,) float64
        Distortion coefficients in OpenCV order ``(k1, k2, p1, p2[, k3, ...])`` for ``plumb_bob``.
    R : (3, 3) float64
        Rectification rotation (identity for a monocular camera).
    P : (3, 4) float64
        Projection matrix of the rectified image.
    """

    t_ns: int
    sensor: str
    frame_id: str
    width: int
    height: int
    K: np.ndarray
    D: np.ndarray = field(default_factory=lambda: np.zeros(5))
    distortion_model: str = "plumb_bob"
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    P: np.ndarray | None = None

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        _set(self, "width", int(self.width))
        _set(self, "height", int(self.height))
        _set(self, "K", _frozen_array(self.K, np.float64, (3, 3), "CameraInfo.K"))
        _set(self, "D", _frozen_array(self.D, np.float64, (None,), "CameraInfo.D"))
        _set(self, "R", _frozen_array(self.R, np.float64, (3, 3), "CameraInfo.R"))
        P = np.hstack([self.K, np.zeros((3, 1))]) if self.P is None else self.P
        _set(self, "P", _frozen_array(P, np.float64, (3, 4), "CameraInfo.P"))


@dataclass(frozen=True, slots=True, eq=False)
class Odometry:
    """A pose and twist estimate (nav_msgs/Odometry).

    Attributes
    ----------
    position_m : (3,) float64
        Position of ``child_frame_id`` in ``frame_id``.
    orientation_xyzw : (4,) float64
    linear_velocity_mps, angular_velocity_radps : (3,) float64
        Twist expressed in ``child_frame_id`` (as in ROS).
    """

    t_ns: int
    sensor: str
    frame_id: str
    child_frame_id: str
    position_m: np.ndarray
    orientation_xyzw: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    linear_velocity_mps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    angular_velocity_radps: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        _set(self, "position_m", _frozen_array(self.position_m, np.float64, (3,), "Odometry.position_m"))
        _set(self, "orientation_xyzw",
             _frozen_array(self.orientation_xyzw, np.float64, (4,), "Odometry.orientation_xyzw"))
        _set(self, "linear_velocity_mps",
             _frozen_array(self.linear_velocity_mps, np.float64, (3,), "Odometry.linear_velocity_mps"))
        _set(self, "angular_velocity_radps",
             _frozen_array(self.angular_velocity_radps, np.float64, (3,), "Odometry.angular_velocity_radps"))


@dataclass(frozen=True, slots=True, eq=False)
class Transform:
    """One stamped transform from tf / tf_static: the pose of ``child_frame`` in ``parent_frame``.

    A point ``p_child`` maps to ``p_parent = R(rotation_xyzw) @ p_child + translation_m``, i.e. this is
    ``child2parent`` in fusiontrack's A2B naming.
    """

    t_ns: int
    sensor: str
    parent_frame: str
    child_frame: str
    translation_m: np.ndarray
    rotation_xyzw: np.ndarray
    static: bool = False

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        _set(self, "translation_m", _frozen_array(self.translation_m, np.float64, (3,), "Transform.translation_m"))
        _set(self, "rotation_xyzw", _frozen_array(self.rotation_xyzw, np.float64, (4,), "Transform.rotation_xyzw"))
        _set(self, "static", bool(self.static))


# --------------------------------------------------------------------------------------------------
# Ground truth, detections, tracks, events
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class GroundTruth:
    """The true state of every annotated object at one instant (simulator output or hand annotation).

    Attributes
    ----------
    ids : (n,) int64
        Object identities, stable over the recording.
    positions_m : (n, 2) float64
        Floor-plane position in ``frame_id`` (``"world"`` for the simulator; the laser frame for
        annotations made in a laser's frame).
    velocities_mps : (n, 2) float64
        ``NaN`` where unknown.
    classes : tuple[str, ...] of length n
        :class:`ObjectClass` values.
    attributes : mapping of name -> (n, ...) array
        Further per-object truth (height, situation label, box in a camera, ...).
    """

    t_ns: int
    sensor: str
    frame_id: str
    ids: np.ndarray
    positions_m: np.ndarray
    velocities_mps: np.ndarray | None = None
    classes: tuple[str, ...] = ()
    attributes: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        ids = _frozen_array(self.ids, np.int64, (None,), "GroundTruth.ids")
        n = ids.size
        _set(self, "ids", ids)
        _set(self, "positions_m", _frozen_array(self.positions_m, np.float64, (n, 2), "GroundTruth.positions_m"))
        vel = np.full((n, 2), np.nan) if self.velocities_mps is None else self.velocities_mps
        _set(self, "velocities_mps", _frozen_array(vel, np.float64, (n, 2), "GroundTruth.velocities_mps"))
        classes = tuple(str(ObjectClass(c)) for c in self.classes) if self.classes else ("person",) * n
        if len(classes) != n:
            raise ValueError(f"GroundTruth.classes: expected {n} classes, got {len(classes)}")
        _set(self, "classes", classes)
        attrs = {}
        for key, val in self.attributes.items():
            arr = _frozen_array(val, None, None, f"GroundTruth.attributes[{key!r}]")
            if arr.ndim == 0 or arr.shape[0] != n:
                raise ValueError(f"GroundTruth.attributes[{key!r}]: expected a first axis of length {n}")
            attrs[key] = arr
        _set(self, "attributes", MappingProxyType(attrs))

    def __len__(self) -> int:
        return int(self.ids.size)

    __reduce__ = _reduce_record


@dataclass(frozen=True, slots=True, eq=False)
class Detection:
    """What one sensor measured of one object at one instant, before association.

    A detection is either on the floor (``position_m`` with ``covariance_m2``, world frame) or in an
    image (``box_px``), or both. ``features`` carries sensor-specific extras under documented keys:
    ``"feet_m"`` (2, 2) two-feet points, ``"points_m"`` (k, 2) laser points of the segment,
    ``"appearance"`` (d,) descriptor. Trackers read only the common fields, so one tracker fuses
    any sensor (the Stone Soup habit).
    """

    t_ns: int
    sensor: str
    position_m: np.ndarray | None = None
    covariance_m2: np.ndarray | None = None
    box_px: np.ndarray | None = None
    score: float = 1.0
    cls: str = ObjectClass.UNKNOWN
    class_probs: Mapping[str, float] = field(default_factory=dict)
    features: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        if self.position_m is None and self.box_px is None:
            raise ValueError("Detection: needs position_m (floor) or box_px (image), got neither")
        _set(self, "position_m", _optional_array(self.position_m, np.float64, (2,), "Detection.position_m"))
        cov = self.covariance_m2
        if cov is None and self.position_m is not None:
            cov = np.eye(2) * 0.05**2
        _set(self, "covariance_m2", _optional_array(cov, np.float64, (2, 2), "Detection.covariance_m2"))
        _set(self, "box_px", _optional_array(self.box_px, np.float64, (4,), "Detection.box_px"))
        _set(self, "score", float(self.score))
        _set(self, "cls", str(ObjectClass(self.cls)))
        _set(self, "class_probs", MappingProxyType({str(ObjectClass(k)): float(v)
                                                     for k, v in self.class_probs.items()}))
        _set(self, "features", MappingProxyType({k: _frozen_array(v, None, None, f"Detection.features[{k!r}]")
                                                  for k, v in self.features.items()}))

    __reduce__ = _reduce_record

    @staticmethod
    def trusted(t_ns: int, sensor: str, position_m: np.ndarray | None = None, covariance_m2: np.ndarray | None = None,
                box_px: np.ndarray | None = None, score: float = 1.0, cls: str = ObjectClass.UNKNOWN,
                class_probs: Mapping[str, float] | None = None, features: Mapping[str, np.ndarray] | None = None
                ) -> Detection:
        """A detection from values a pipeline component already holds in the documented form, without checks or
        copies (the hot path of the branches and the fusion; ``Detection(...)`` is the checked constructor).

        The caller guarantees: ``t_ns`` an int; ``position_m`` a float64 ``(2,)`` array and ``covariance_m2`` a
        float64 ``(2, 2)`` one (or both ``None`` with a ``box_px``), ``box_px`` float64 ``(4,)`` or ``None``; ``cls`` an
        :class:`ObjectClass` value; ``class_probs`` keys :class:`ObjectClass` values; ``features`` numpy arrays.
        The arrays are not copied but made read-only here: the caller must not keep writing to them (or to the
        arrays they are views of). A mapping already read-only (``MappingProxyType``) is shared as it is: pass
        only another record's ``features`` that way (their arrays are read-only already).
        """
        d = object.__new__(Detection)
        for a in (position_m, covariance_m2, box_px):
            if a is not None:
                a.setflags(write=False)
        if features is None:
            features = _EMPTY
        elif not isinstance(features, MappingProxyType):
            for v in features.values():
                v.setflags(write=False)
            features = MappingProxyType(features)
        if class_probs is None:
            class_probs = _EMPTY
        elif not isinstance(class_probs, MappingProxyType):
            class_probs = MappingProxyType(class_probs)
        _set(d, "t_ns", t_ns)
        _set(d, "sensor", sensor)
        _set(d, "position_m", position_m)
        _set(d, "covariance_m2", covariance_m2)
        _set(d, "box_px", box_px)
        _set(d, "score", float(score))
        _set(d, "cls", str(cls))
        _set(d, "class_probs", class_probs)
        _set(d, "features", features)
        return d

    def moved(self, position_m: np.ndarray) -> Detection:
        """This detection with another ``position_m`` (a float64 ``(2,)`` array the caller hands over, made
        read-only), everything else shared; no checks (see :meth:`trusted`)."""
        d = object.__new__(Detection)
        for name in Detection.__slots__:
            _set(d, name, getattr(self, name))
        position_m.setflags(write=False)
        _set(d, "position_m", position_m)
        return d


@dataclass(frozen=True, slots=True, eq=False)
class TrackState:
    """The estimate of one track at one instant.

    Attributes
    ----------
    position_m, velocity_mps : (2,) float64
        Floor-plane state in the world frame.
    covariance : (4, 4) float64 or None
        Covariance of ``(x, y, vx, vy)``.
    box_px : (4,) float64 or None
        Image box in ``camera`` when the track is (also) tracked in an image.
    sensors : tuple[str, ...]
        The sensors whose measurements confirmed this step (empty while coasting): of a laser track, the
        scanners that saw the person (e.g. ``("laser_0", "laser_1")``), then the camera if its image was used.
    """

    t_ns: int
    sensor: str
    track_id: int
    position_m: np.ndarray
    velocity_mps: np.ndarray = field(default_factory=lambda: np.zeros(2))
    covariance: np.ndarray | None = None
    cls: str = ObjectClass.PERSON
    situation: str = Situation.NONCORRELATED
    sensors: tuple[str, ...] = ()
    score: float = 1.0
    box_px: np.ndarray | None = None
    camera: str = ""

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        _set(self, "track_id", int(self.track_id))
        _set(self, "position_m", _frozen_array(self.position_m, np.float64, (2,), "TrackState.position_m"))
        _set(self, "velocity_mps", _frozen_array(self.velocity_mps, np.float64, (2,), "TrackState.velocity_mps"))
        _set(self, "covariance", _optional_array(self.covariance, np.float64, (4, 4), "TrackState.covariance"))
        _set(self, "cls", str(ObjectClass(self.cls)))
        _set(self, "situation", str(Situation(self.situation)))
        _set(self, "sensors", tuple(str(s) for s in self.sensors))
        _set(self, "score", float(self.score))
        _set(self, "box_px", _optional_array(self.box_px, np.float64, (4,), "TrackState.box_px"))

    @staticmethod
    def trusted(t_ns: int, sensor: str, track_id: int, position_m: np.ndarray, velocity_mps: np.ndarray,
                covariance: np.ndarray | None = None, cls: str = ObjectClass.PERSON,
                situation: str = Situation.NONCORRELATED, sensors: tuple[str, ...] = (), score: float = 1.0,
                box_px: np.ndarray | None = None, camera: str = "") -> TrackState:
        """A state from values a tracker already holds in the documented form, without checks or copies (its hot
        path; ``TrackState(...)`` is the checked constructor).

        The caller guarantees: ``t_ns`` and ``track_id`` ints; float64 arrays of shapes ``(2,)``, ``(2,)``,
        ``(4, 4)`` (or ``None``) and ``(4,)`` (or ``None``); ``cls``/``situation`` :class:`ObjectClass` /
        :class:`Situation` values; ``sensors`` a tuple of str. The arrays are made read-only, not copied: the
        caller must not keep writing to them (or to the arrays they are views of).
        """
        st = object.__new__(TrackState)
        for a in (position_m, velocity_mps, covariance, box_px):
            if a is not None:
                a.setflags(write=False)
        for name, value in (("t_ns", t_ns), ("sensor", sensor), ("track_id", track_id), ("position_m", position_m),
                            ("velocity_mps", velocity_mps), ("covariance", covariance), ("cls", str(cls)),
                            ("situation", str(situation)), ("sensors", sensors), ("score", float(score)),
                            ("box_px", box_px), ("camera", camera)):
            _set(st, name, value)
        return st


@dataclass(frozen=True, slots=True, eq=False)
class Track:
    """The history of one track: its id (owned by the tracker instance) and its states in time order."""

    track_id: int
    states: tuple[TrackState, ...]

    def __post_init__(self) -> None:
        states = tuple(self.states)
        if any(s.track_id != self.track_id for s in states):
            raise ValueError(f"Track {self.track_id}: every state must carry track_id {self.track_id}")
        if any(b.t_ns < a.t_ns for a, b in itertools.pairwise(states)):
            raise ValueError(f"Track {self.track_id}: states must be in time order")
        _set(self, "states", states)

    @property
    def t_start_ns(self) -> int:
        return self.states[0].t_ns

    @property
    def t_end_ns(self) -> int:
        return self.states[-1].t_ns

    def positions_m(self) -> np.ndarray:
        """All positions, ``(n_states, 2)``."""
        return np.array([s.position_m for s in self.states]).reshape(-1, 2)

    def times_ns(self) -> np.ndarray:
        return np.array([s.t_ns for s in self.states], dtype=np.int64)


@dataclass(frozen=True, slots=True, eq=False)
class Event:
    """Something that happened in the scene (seed 003 D8; meetings, splits, zone entries, failures).

    ``t_ns`` is the start; ``t_end_ns`` is ``None`` while the event is still going on.
    """

    t_ns: int
    sensor: str
    kind: str
    t_end_ns: int | None = None
    position_m: np.ndarray | None = None
    track_ids: tuple[int, ...] = ()
    attributes: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _set(self, "t_ns", _check_time(self.t_ns))
        if self.t_end_ns is not None:
            _set(self, "t_end_ns", _check_time(self.t_end_ns, "t_end_ns"))
            if self.t_end_ns < self.t_ns:
                raise ValueError(f"Event {self.kind!r}: t_end_ns {self.t_end_ns} is before t_ns {self.t_ns}")
        _set(self, "position_m", _optional_array(self.position_m, np.float64, (2,), "Event.position_m"))
        _set(self, "track_ids", tuple(int(i) for i in self.track_ids))
        _set(self, "attributes", MappingProxyType(dict(self.attributes)))

    __reduce__ = _reduce_record


Message = LaserScan | Image | DepthImage | ImuSample | CameraInfo | Odometry | Transform | GroundTruth
"""Anything a recording yields after conversion."""


def _values_equal(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)):
            return False
        if a.shape != b.shape:
            return False
        if a.dtype.kind == "f" or b.dtype.kind == "f":
            return bool(np.array_equal(a, b, equal_nan=True))
        return bool(np.array_equal(a, b))
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        return a.keys() == b.keys() and all(_values_equal(a[k], b[k]) for k in a)
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_values_equal(x, y) for x, y in zip(a, b, strict=True))
    if dataclasses.is_dataclass(a) and dataclasses.is_dataclass(b):
        return records_equal(a, b)
    return bool(a == b)


def records_equal(a: Any, b: Any) -> bool:
    """Field-by-field equality of two records, arrays compared exactly (``NaN`` equal to ``NaN``).

    The records hold numpy arrays, so the dataclass ``==`` is switched off (it would be ambiguous);
    use this where exact equality is meant, e.g. in round-trip tests.
    """
    if type(a) is not type(b):
        return False
    return all(_values_equal(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
