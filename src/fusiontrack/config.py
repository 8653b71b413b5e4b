"""The pipeline file (TOML): which sensors, on which topics, at which poses, on which clocks.

Validated once at the edge with pydantic; every error names the file and the field
(``sensors.laser_front.pose.yaw_deg``) and what was expected. Typed objects go inward.

Example::

    [pipeline]
    name = "hall"   # a label of the set-up; which pipeline runs is track's --pipeline

    [sync]
    window_ms = 200

    [sensors.laser_front]
    kind = "laser"
    topic = "/scan"
    pose = { x = 0.0, y = 0.0, z = 0.2, yaw_deg = 0.0 }
    clock_offset_ms = 0.0   # how far this sensor's clock runs ahead; subtracted from its stamps

Later components add their own sections (``[laser]``, ``[tracking]``, ...); unknown keys are an
error, so a typo never passes silently.
"""

from __future__ import annotations

import tomllib
from enum import StrEnum
from pathlib import Path
from types import UnionType
from typing import Annotated, Any, Union, get_args, get_origin

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, field_validator

from .errors import ConfigError

Number = Annotated[float, Strict()]
"""A number of the pipeline file: an integer or a float, not ``true`` (read as 1) nor a string (``"200"``)."""


class _Model(BaseModel):
    # a pipeline file's numbers are finite: inf or nan in a pose, a clock offset or a window is a mistake
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class SensorKind(StrEnum):
    LASER = "laser"
    CAMERA = "camera"
    RGBD = "rgbd"
    IMU = "imu"
    GROUND_TRUTH = "ground_truth"


class Pose(_Model):
    """Sensor pose in the world frame: position in metres, orientation in degrees (config only)."""

    x: Number = 0.0
    y: Number = 0.0
    z: Number = 0.0
    roll_deg: Number = 0.0
    pitch_deg: Number = 0.0
    yaw_deg: Number = 0.0

    def matrix(self) -> np.ndarray:
        """``sensor2world`` of the sensor's body frame (x forward, z up) as a 4x4 homogeneous matrix."""
        from .geometry import make_transform, rpy_to_matrix

        R = rpy_to_matrix(np.radians(self.roll_deg), np.radians(self.pitch_deg), np.radians(self.yaw_deg))
        return make_transform(R, [self.x, self.y, self.z])


class SensorConfig(_Model):
    kind: SensorKind
    topic: str = Field(min_length=1)
    pose: Pose = Pose()
    clock_offset_ms: Number = 0.0
    """How far this sensor's clock is ahead of the common clock (its stamps = true time + offset), as in
    the simulator's scenario files; synchronisation subtracts it."""
    info_topic: str = ""
    depth_topic: str = ""

    @property
    def clock_offset_ns(self) -> int:
        return round(self.clock_offset_ms * 1e6)

    @property
    def has_pose(self) -> bool:
        """Whether the pipeline file gives this sensor a ``pose`` (else ``pose`` is the origin, a placeholder: the
        recording's ``/tf_static`` says where the sensor is)."""
        return "pose" in self.model_fields_set


class SyncConfig(_Model):
    window_ms: Number = Field(200.0, ge=0.0)

    @property
    def window_ns(self) -> int:
        return round(self.window_ms * 1e6)


class PipelineHeader(_Model):
    """``[pipeline]``: a label of the set-up and a description (for people; ``track --pipeline`` chooses what
    runs)."""

    name: str = "people-laser"
    description: str = ""


class PipelineConfig(_Model):
    pipeline: PipelineHeader = PipelineHeader()
    sync: SyncConfig = SyncConfig()
    sensors: dict[str, SensorConfig] = Field(default_factory=dict)
    laser: dict[str, Any] = Field(default_factory=dict)
    """Laser detector parameters (keyword arguments of ``LaserPeopleDetector``; checked by it)."""
    tracking: dict[str, Any] = Field(default_factory=dict)
    """Tracker parameters (fields of ``TrackerParams``; checked by it)."""
    fusion: dict[str, Any] = Field(default_factory=dict)
    """The fused people pipeline's options (fields of ``FusionParams``, ``appearance`` a nested table; checked by
    ``FusionParams.from_mapping``)."""
    wearable: dict[str, Any] = Field(default_factory=dict)
    """The wearable pipeline's options (fields of ``WearableParams`` / ``AssocParams`` / ``VisualParams``;
    checked by ``run_wearable``)."""
    traffic: dict[str, Any] = Field(default_factory=dict)
    """The traffic pipeline's settings (``TrafficParams.from_mapping``: rate_hz, fusion, tracker, kalman, laser,
    camera; checked by it)."""

    @field_validator("sensors")
    @classmethod
    def _sensor_names(cls, sensors: dict[str, SensorConfig]) -> dict[str, SensorConfig]:
        # a name is what a track's steps say confirmed them: tracks.csv joins them with "|" and strips its fields
        for name in sensors:
            if not name.strip() or name != name.strip() or "|" in name:
                raise ValueError(f"sensor name {name!r}: expected a name without '|' and without leading or trailing "
                                 "spaces (tracks.csv lists a step's confirming sensors joined by '|')")
        return sensors

    def laser_poses(self) -> dict[str, np.ndarray]:
        """topic -> laser2world ``(4, 4)`` of the lasers whose table gives a ``pose``: they override the
        recording's ``/tf_static`` (the laser pipelines' ``laser_poses``)."""
        return {s.topic: s.pose.matrix() for s in self.sensors.values()
                if s.kind == SensorKind.LASER and s.has_pose}

    def camera_poses(self) -> dict[str, np.ndarray]:
        """cam2world ``(4, 4)`` of the optical frame of the cameras whose table gives a ``pose`` (as ``fusiontrack
        calibrate`` writes it), keyed by their topic and by their name: they override the recording's
        ``/tf_static`` (the people pipeline's ``camera_poses``)."""
        from .calibration.extrinsics import cam2world_from_camera_pose

        out = {}
        for name, s in self.sensors.items():
            if s.kind in (SensorKind.CAMERA, SensorKind.RGBD) and s.has_pose:
                out[s.topic] = out[name] = cam2world_from_camera_pose(s.pose)
        return out

    def topics(self) -> dict[str, str]:
        """topic -> sensor name, for :class:`fusiontrack.io.Recording`'s ``sensors`` argument."""
        out = {}
        for name, s in self.sensors.items():
            for topic in (s.topic, s.info_topic, s.depth_topic):
                if topic:
                    out[topic] = name
        return out

    def clock_corrections_ns(self) -> dict[str, int]:
        """sensor -> what to add to its stamps to put them on the common clock (``-clock_offset``)."""
        return {name: -s.clock_offset_ns for name, s in self.sensors.items() if s.clock_offset_ms}


def _location(loc: tuple[Any, ...]) -> str:
    return ".".join(str(p) for p in loc) or "(top level)"


def _known_keys(model: Any, loc: tuple[Any, ...]) -> list[str] | None:
    """The keys accepted by the table that holds ``loc``'s last part, walking from ``model`` through its fields
    (models, ``dict[str, Model]``, ``list[Model]``, optional ones); None where the walk leaves the models."""
    for part in loc[:-1]:
        if isinstance(model, type) and issubclass(model, BaseModel):
            field = model.model_fields.get(str(part))
            model = field.annotation if field is not None else None
        else:  # a dict's key or a list's index: its values' type
            model = next((a for a in reversed(get_args(model)) if a is not type(None)), None)
        if get_origin(model) in (Union, UnionType):  # X | None
            model = next((a for a in get_args(model) if a is not type(None)), None)
    return sorted(model.model_fields) if isinstance(model, type) and issubclass(model, BaseModel) else None


def parse_error_message(err: ValidationError, source: str, model: type[BaseModel] | None = None) -> str:
    """One line naming ``source`` and every offending field with what was expected and what was given; an
    unknown key or table is named with the ones accepted in its place (a typo shows beside its right spelling)."""
    problems = []
    for e in err.errors():
        given = e.get("input")
        if e["type"] == "extra_forbidden":
            known = _known_keys(model, tuple(e["loc"])) if model is not None else None
            where = "table" if isinstance(given, dict) else "key"
            problems.append(f"{_location(e['loc'])}: unknown {where}"
                            + (f" (known: {', '.join(known)})" if known else ""))
            continue
        shown = "" if isinstance(given, dict) else f" (got {given!r})"
        problems.append(f"{_location(e['loc'])}: {e['msg']}{shown}")
    return f"{source}: " + "; ".join(problems)


def parse_config(data: dict[str, Any], source: str = "<config>") -> PipelineConfig:
    """Validate a pipeline mapping (as loaded from TOML).

    Raises
    ------
    ConfigError
        Naming ``source`` and every offending field with what was expected and what was given.
    """
    try:
        return PipelineConfig.model_validate(data)
    except ValidationError as err:
        raise ConfigError(parse_error_message(err, source, PipelineConfig)) from err


def load_config(path: str | Path) -> PipelineConfig:
    """Read and validate a pipeline TOML file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError as err:
        raise ConfigError(f"pipeline file not found: {path}") from err
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the pipeline file: {err.strerror}") from err
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from err
    return parse_config(data, str(path))
