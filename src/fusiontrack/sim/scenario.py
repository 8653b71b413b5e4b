"""Scenario files: a readable TOML description of a simulated recording.

A scenario names a setting (the static world and its parameters), who is in it (a plan generator
and its parameters), the sensors with their poses, rates, noise and failures, and the duration and
seed. The built-in scenarios are such files, shipped in ``fusiontrack/sim/scenarios/``; a user can
copy one, edit it and pass its path wherever a scenario name is accepted.

Example (abridged from ``crossing.toml``)::

    [scenario]
    description = "2-4 people cross a hall, their paths meeting in the middle"
    duration_s = 20
    seed = 0

    [world]
    setting = "room"
    width_m = 16.0

    [agents]
    plan = "crossing"
    n_people = 3

    [[lasers]]
    name = "laser_0"
    x_m = -7.5
    y_m = -5.5
    yaw_deg = 45
    rate_hz = 25

    [[cameras]]
    name = "camera_0"
    position_m = [0.0, -9.0, 6.0]
    yaw_deg = 90
    pitch_deg = 35
    rate_hz = 15
    yaw_bias_deg = 3.0

Angles are degrees in the file and radians inside. Unknown keys are errors.
"""

from __future__ import annotations

import inspect
import math
import tomllib
from collections.abc import Callable, Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, validate_call

from ..config import parse_error_message
from ..errors import ConfigError
from .model import CameraSpec, ImuSpec, LaserSpec, Timing


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


SENSOR_NAME = r"^[A-Za-z][A-Za-z0-9_]*$"
"""A sensor's name makes its topics (``/<name>/scan``) and file names: a ROS name token (letters, digits, _)."""


class TimingConfig(_Model):
    rate_hz: float = Field(gt=0)
    # a day either way: ROS stamps hold int32 seconds (the year 2038), and a sensor clock days off is a typo
    clock_offset_ms: float = Field(0.0, ge=-86_400_000.0, le=86_400_000.0)
    jitter_ms: float = Field(0.0, ge=0)
    latency_ms: float = Field(2.0, ge=0)
    drop_probability: float = Field(0.0, ge=0, le=1)
    outages_s: list[tuple[float, float]] = Field(default_factory=list)

    @field_validator("outages_s")
    @classmethod
    def _ordered(cls, v: list[tuple[float, float]]) -> list[tuple[float, float]]:
        for a, b in v:
            if b <= a:
                raise ValueError(f"outage ({a}, {b}) must end after it starts")
        return v

    def timing(self) -> Timing:
        return Timing(self.rate_hz, self.clock_offset_ms / 1e3, self.jitter_ms / 1e3, self.drop_probability,
                      tuple((float(a), float(b)) for a, b in self.outages_s))


class LaserConfig(TimingConfig):
    name: str = Field(pattern=SENSOR_NAME)
    x_m: float
    y_m: float
    yaw_deg: float = 0.0
    height_m: float = Field(0.2, gt=0)
    fov_deg: float = Field(270.0, gt=0, le=360)
    n_beams: int = Field(720, ge=2)
    range_min_m: float = Field(0.05, ge=0)
    range_max_m: float = Field(30.0, gt=0)
    range_noise_m: float = Field(0.01, ge=0)

    def spec(self) -> LaserSpec:
        fov = math.radians(self.fov_deg)
        return LaserSpec(self.name, self.x_m, self.y_m, math.radians(self.yaw_deg), self.timing(), self.height_m,
                         -fov / 2, fov / (self.n_beams - 1) if self.fov_deg < 360 else fov / self.n_beams,
                         self.n_beams, self.range_min_m, self.range_max_m, self.range_noise_m)


class CameraConfig(TimingConfig):
    name: str = Field(pattern=SENSOR_NAME)
    position_m: tuple[float, float, float]
    yaw_deg: float
    pitch_deg: float = Field(ge=-89, le=89)
    roll_deg: float = 0.0
    width: int = Field(640, ge=16)
    height: int = Field(480, ge=16)
    fx: float = Field(500.0, gt=0)
    fy: float = Field(500.0, gt=0)
    cx: float | None = None
    cy: float | None = None
    dist: list[float] = Field(default_factory=list)
    yaw_bias_deg: float = 0.0
    noise_sigma: float = Field(2.0, ge=0)
    illumination: list[tuple[float, float]] = Field(default_factory=list)
    shadows: bool = True
    labels: bool = False
    depth: bool = False
    depth_range_m: tuple[float, float] = (0.5, 4.5)
    depth_noise_m: float = Field(0.01, ge=0)

    def spec(self) -> CameraSpec:
        return CameraSpec(
            self.name, self.position_m, math.radians(self.yaw_deg), math.radians(self.pitch_deg), self.timing(),
            self.width, self.height, self.fx, self.fy, self.cx, self.cy, tuple(self.dist),
            math.radians(self.roll_deg), math.radians(self.yaw_bias_deg), self.noise_sigma,
            tuple((float(t), float(g)) for t, g in self.illumination), self.shadows, self.labels, self.depth,
            self.depth_range_m, self.depth_noise_m)


class PhoneConfig(TimingConfig):
    name: str = Field(pattern=SENSOR_NAME)
    rate_hz: float = Field(100.0, gt=0)
    mount_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_bias_mps2: tuple[float, float, float] = (0.05, -0.03, 0.04)
    gyro_bias_dps: tuple[float, float, float] = (0.5, -0.3, 0.4)
    accel_noise_mps2: float = Field(0.05, ge=0)
    gyro_noise_dps: float = Field(0.17, ge=0)
    step_accel_mps2: float = Field(2.5, ge=0)

    def spec(self, carrier_id: int) -> ImuSpec:
        return ImuSpec(self.name, carrier_id, self.timing(), tuple(math.radians(a) for a in self.mount_rpy_deg),
                       self.accel_bias_mps2, tuple(math.radians(g) for g in self.gyro_bias_dps),
                       self.accel_noise_mps2, math.radians(self.gyro_noise_dps), self.step_accel_mps2)


class Header(_Model):
    description: str = ""
    duration_s: float = Field(30.0, gt=0, allow_inf_nan=False)
    seed: int = Field(0, ge=0)
    step_hz: float = Field(100.0, gt=0, description="internal rate of the agents' motion")
    ground_truth_hz: float = Field(25.0, gt=0)


class ScenarioConfig(_Model):
    scenario: Header = Header()
    world: dict[str, Any] = Field(default_factory=lambda: {"setting": "room"})
    agents: dict[str, Any] = Field(default_factory=lambda: {"plan": "crossing"})
    lasers: list[LaserConfig] = Field(default_factory=list)
    cameras: list[CameraConfig] = Field(default_factory=list)
    phones: list[PhoneConfig] = Field(default_factory=list)

    @field_validator("lasers", "cameras", "phones")
    @classmethod
    def _unique(cls, v: list[Any]) -> list[Any]:
        names = [s.name for s in v]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"sensor names must be unique, repeated: {', '.join(dupes)}")
        return v


class Scenario:
    """A validated scenario: its name, where it came from, and its configuration."""

    def __init__(self, name: str, config: ScenarioConfig, source: str) -> None:
        self.name = name
        self.config = config
        self.source = source
        sensors = [s.name for group in (config.lasers, config.cameras, config.phones) for s in group]
        dupes = sorted({n for n in sensors if sensors.count(n) > 1})
        if dupes:
            raise ConfigError(f"{source}: sensor names must be unique across lasers, cameras and phones: "
                              f"{', '.join(dupes)}")

    @property
    def description(self) -> str:
        return self.config.scenario.description

    def with_overrides(self, *, seconds: float | None = None, seed: int | None = None,
                       settings: Mapping[str, Any] | None = None) -> Scenario:
        """A copy with the duration, seed or any dotted key (``agents.mean_present``) replaced."""
        data = self.config.model_dump()
        given = {"scenario.duration_s": ("seconds", seconds), "scenario.seed": ("seed", seed)}
        for key, (option, value) in given.items():
            if value is not None and key in (settings or {}):  # (the setting won without a word)
                raise ConfigError(f"{self.source}: {key} is set twice, by {option} (--{option}) and by a setting "
                                  f"(--set): give it once")
        if seconds is not None:
            data["scenario"]["duration_s"] = seconds
        if seed is not None:
            data["scenario"]["seed"] = seed
        for key, value in (settings or {}).items():
            _set_dotted(data, key, value, self.source)
        return Scenario(self.name, parse_scenario(data, f"{self.source} (with overrides)").config,
                        self.source)


def _set_dotted(data: dict[str, Any], key: str, value: Any, source: str) -> None:
    parts = key.split(".")
    node: Any = data
    for i, part in enumerate(parts[:-1]):
        if isinstance(node, list):
            try:
                node = node[int(part)]
                continue
            except (ValueError, IndexError) as err:
                raise ConfigError(f"{source}: no entry {'.'.join(parts[:i + 1])!r} to set") from err
        if part not in node or not isinstance(node[part], dict | list):
            raise ConfigError(f"{source}: no section {'.'.join(parts[:i + 1])!r} to set {key!r} in")
        node = node[part]
    if isinstance(node, list):
        raise ConfigError(f"{source}: {key!r} names a list entry, not a value")
    node[parts[-1]] = value


def parse_scenario(data: Mapping[str, Any], source: str, name: str = "") -> Scenario:
    try:
        config = ScenarioConfig.model_validate(data)
    except ValidationError as err:
        raise ConfigError(parse_error_message(err, source, ScenarioConfig)) from err
    return Scenario(name or Path(source).stem, config, source)


def builtin_names() -> list[str]:
    """Names of the scenarios shipped with fusiontrack."""
    folder = resources.files(__package__) / "scenarios"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A built-in scenario by name (``crowd``) or a scenario file by path.

    Raises
    ------
    ConfigError
        Unknown name (the built-in names are listed), unreadable file, bad TOML, a bad value (the
        field is named), or no sensor at all (no ``[[lasers]]``, ``[[cameras]]`` or ``[[phones]]``: its
        recording would hold nothing but ground truth). A ground-truth-only scenario can still be made on
        purpose from a loaded one, e.g. ``with_overrides(settings={"lasers": [], "cameras": []})``.
    """
    text = str(name_or_path)
    path = Path(text)
    if text in builtin_names():
        resource = resources.files(__package__) / "scenarios" / f"{text}.toml"
        source, content = f"built-in scenario {text!r}", resource.read_text(encoding="utf-8")
    elif path.suffix == ".toml" or path.exists():
        try:
            content = path.read_text(encoding="utf-8")
        except OSError as err:
            raise ConfigError(f"scenario file {path}: {err.strerror or err}") from err
        source = str(path)
    else:
        raise ConfigError(f"unknown scenario {text!r}: expected one of {', '.join(builtin_names())} "
                          "or the path of a scenario .toml file")
    try:
        data = tomllib.loads(content)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{source}: not valid TOML: {err}") from err
    scenario = parse_scenario(data, source, name=path.stem if source == str(path) else text)
    cfg = scenario.config
    if not (cfg.lasers or cfg.cameras or cfg.phones):
        raise ConfigError(f"{source}: no sensors: the scenario has no [[lasers]], [[cameras]] or [[phones]] "
                          "table, so its recording would hold only ground truth; add at least one (the built-in "
                          "scenarios, listed by `fusiontrack scenarios`, show how)")
    return scenario


def call_with_params(fn: Callable[..., Any], params: Mapping[str, Any], section: str, source: str,
                     **fixed: Any) -> Any:
    """Call a world builder or plan generator with a scenario section's keys as keyword arguments.

    A key the function does not take, or a value it rejects, is a ConfigError naming the section.
    """
    accepted = inspect.signature(fn).parameters
    unknown = sorted(k for k in params if k not in accepted or k in fixed)
    if unknown:
        options = sorted(k for k in accepted if k not in fixed and k not in ("rng", "world"))
        raise ConfigError(f"{source}: {section} has unknown key(s) {', '.join(unknown)} for "
                          f"{fn.__name__}; it takes {', '.join(options)}")
    # The function's annotations are the schema of its section: pydantic checks (and coerces) the values.
    checked = validate_call(fn, config=ConfigDict(arbitrary_types_allowed=True))
    try:
        return checked(**fixed, **params)
    except ValidationError as err:
        problems = "; ".join(f"{section}.{'.'.join(str(p) for p in e['loc'])}: {e['msg']} (got {e.get('input')!r})"
                             for e in err.errors())
        raise ConfigError(f"{source}: {problems}") from err
    except (TypeError, ValueError, IndexError, ConfigError) as err:
        raise ConfigError(f"{source}: {section}: {err}") from err
