"""Scene understanding by rules: the switching control module (D7) and behaviour selection (D8).

ALGORITHMS.md D7 / D8 (seed 003):

* **Switching control** (:class:`SwitchingControl`): per track, the entity type (``group`` when the track is of
  class ``group``, longer than 18 m, or a camera blob holding >= 2 laser objects; ``vehicle`` when its class is
  a vehicle class) and its properties, computed from a short history: speed, velocity and heading as medians
  over 0.5 s, acceleration, lateral speed towards the road edge, signed distance to the road edge (now and
  predicted 1 s ahead), lane, cosine between the motion and the lane direction, zones, dwell time, time on the
  road, and whether a sensor confirmed the state (``measured``: false while the tracker coasts). Per lane zone,
  the group properties: count, mean speed and density of the vehicles in a sliding window.
* **Rules** (:class:`SceneRules`, a TOML file, ``scene/data/default_rules.toml`` by default): per application a
  logical expression over the selected properties (spatial and logical constraints), a hold time or frame
  count (temporal constraint) and a clearing condition (hysteresis). Defaults are D8's: stopped vehicle, road
  leaving with its early warning (kind ``road_leaving_warning``), jam, and wrong-way driving. Road leaving and its
  warning count only measured states: a coasting track's position is the tracker's extrapolation, and on the
  traffic pipeline's tracks every road-leaving false alarm came from a mode coasting off the road after a
  camera-only object placed beyond the edge or a wrong association.
* **Events**: :class:`SceneUnderstanding` is online (``update(t_ns, track_states) -> list[Event]``: start
  events with ``t_end_ns = None`` and end events); :func:`detect_events` runs it over whole tracks.

Event times: an event's ``t_ns`` is when its condition began to hold continuously, ``position_m`` where it was
then; ``attributes["alarm_t_ns"]`` is when the hold was complete and the alarm raised (``t_ns + hold_s`` for
a time hold), ``t_end_ns`` when the clearing condition began to hold (the end event is raised
``clear_hold_s`` later, ``attributes["cleared_t_ns"]``). Other attributes: ``rule``, ``lane``, ``zone``,
``confidence`` (the tracks' mean score), ``alarm_position_m`` and the rule's selected ``properties`` at the alarm.
"""

from __future__ import annotations

import ast
import functools
import logging
import math
import tomllib
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from ..config import parse_error_message
from ..errors import ConfigError
from ..io.tracks import flatten_states
from ..types import Event, Track, TrackState
from .road import ZONE_KINDS, RoadGeometry

__all__ = [
    "VEHICLE_PROPERTIES",
    "ZONE_PROPERTIES",
    "Expression",
    "Frame",
    "RuleSpec",
    "SceneRules",
    "SceneUnderstanding",
    "SwitchingControl",
    "default_rules",
    "detect_events",
    "load_rules",
    "parse_rules",
]

VEHICLE_PROPERTIES: Mapping[str, str] = {
    "speed": "m/s, median of |v| over speed_median_s",
    "heading": "rad, direction of the median velocity",
    "acceleration": "m/s^2, change of the median speed over the median window",
    "lateral_speed": "m/s towards the nearest road edge (median velocity . the edge's outward normal)",
    "edge_distance": "m to the road edge: + on the road, - off it, NaN beyond an open end of the road",
    "predicted_edge_distance": "edge_distance of position + median velocity * prediction_s",
    "on_road": "bool, on a carriageway",
    "time_on_road": "s spent on a carriageway since the track began",
    "in_lane": "bool, inside a lane",
    "lane_cos": "cosine between the median velocity and the lane direction (NaN off lanes or below 0.1 m/s)",
    "lane_offset": "m left of the lane centre line",
    "dwell": "s since the track last entered or left a zone",
    "track_age": "s since the track's first state",
    "score": "the track's score",
    "measured": "bool, a sensor confirmed this state (TrackState.sensors not empty; a track that never names its "
                "sensors counts as measured): false while the tracker coasts on its prediction",
    "length": "m, the entity's length when given (NaN otherwise)",
    "is_vehicle": "bool, entity type vehicle",
    "is_group": "bool, entity type group of vehicles",
}
ZONE_PROPERTIES: Mapping[str, str] = {
    "count": "vehicles in the selected window of window_m",
    "mean_speed": "m/s, their mean (median-smoothed) speed",
    "density": "vehicles per km",
}
_FUNCTIONS = ("in_zone", "in_zone_kind", "abs")
log = logging.getLogger(__name__)
_MIN_MOVING_MPS = 0.1


# --------------------------------------------------------------------------------------------------
# Logical expressions over properties (D7 constraints)
# --------------------------------------------------------------------------------------------------

_CMP: dict[type, Callable[[Any, Any], Any]] = {
    ast.Lt: np.less, ast.LtE: np.less_equal, ast.Gt: np.greater, ast.GtE: np.greater_equal,
    ast.Eq: np.equal, ast.NotEq: np.not_equal,
}
_BIN: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide,
}


class Expression:
    """A rule condition such as ``"speed <= v_stop and not in_zone_kind('parking')"``, checked once, evaluated
    vectorised over entities.

    Allowed: ``and``, ``or``, ``not``, comparisons (chains too), ``+ - * /``, unary minus, numbers,
    ``True``/``False``, the given names, and the calls ``in_zone('name')``, ``in_zone_kind('kind')``, ``abs(x)``.
    A comparison with ``NaN`` is false.

    Parameters
    ----------
    text : str
    names : iterable of str — the names the expression may use
    where : str — where it comes from, for error messages (``"rules.toml: rules.jam.when"``)
    zone_calls : bool — whether ``in_zone``/``in_zone_kind`` are allowed

    Raises
    ------
    ConfigError
        Not an expression, a construct not allowed, an unknown name or zone kind.
    """

    def __init__(self, text: str, names: Iterable[str], where: str, *, zone_calls: bool = True) -> None:
        self.text, self.where = text, where
        known = set(names)
        try:
            self._tree = ast.parse(text.strip(), mode="eval").body
        except SyntaxError as err:
            raise ConfigError(f"{where}: not an expression: {text!r} ({err.msg})") from err
        self.names: set[str] = set()
        self.zones: set[str] = set()
        self._check(self._tree, known, zone_calls)
        self._fn = self._compile(self._tree)
        # only arithmetic can warn (a comparison or abs of NaN does not)
        self._arith = any(isinstance(node, ast.BinOp) for node in ast.walk(self._tree))

    def _fail(self, what: str) -> ConfigError:
        return ConfigError(f"{self.where}: {what} in {self.text!r}")

    def _check(self, node: ast.AST, known: set[str], zone_calls: bool) -> None:
        if isinstance(node, ast.BoolOp | ast.Compare | ast.BinOp | ast.UnaryOp):
            if isinstance(node, ast.BinOp) and type(node.op) not in _BIN:
                raise self._fail(f"operator {type(node.op).__name__} is not allowed")
            if isinstance(node, ast.UnaryOp) and not isinstance(node.op, ast.Not | ast.USub | ast.UAdd):
                raise self._fail(f"operator {type(node.op).__name__} is not allowed")
            if isinstance(node, ast.Compare) and any(type(op) not in _CMP for op in node.ops):
                raise self._fail("only <, <=, >, >=, ==, != compare")
            for child in ast.iter_child_nodes(node):
                if not isinstance(child, ast.boolop | ast.cmpop | ast.operator | ast.unaryop):
                    self._check(child, known, zone_calls)
        elif isinstance(node, ast.Name):
            if node.id not in known:
                raise self._fail(f"unknown name {node.id!r} (known: {', '.join(sorted(known))})")
            self.names.add(node.id)
        elif isinstance(node, ast.Constant):
            if isinstance(node.value, str) or not isinstance(node.value, int | float | bool):
                raise self._fail(f"constant {node.value!r} is not allowed (numbers and True/False only)")
        elif isinstance(node, ast.Call):
            fn = node.func.id if isinstance(node.func, ast.Name) else ""
            if fn not in _FUNCTIONS or node.keywords or len(node.args) != 1:
                raise self._fail(f"calls allowed: {', '.join(f + '(x)' for f in _FUNCTIONS)}")
            arg = node.args[0]
            if fn == "abs":
                self._check(arg, known, zone_calls)
                return
            if not zone_calls:
                raise self._fail(f"{fn}() applies to tracks, not to lane zones")
            if not (isinstance(arg, ast.Constant) and isinstance(arg.value, str)):
                raise self._fail(f"{fn}() takes a quoted name")
            if fn == "in_zone_kind" and arg.value not in ZONE_KINDS:
                raise self._fail(f"zone kind {arg.value!r} (expected one of {list(ZONE_KINDS)})")
            if fn == "in_zone":
                self.zones.add(arg.value)
        else:
            raise self._fail(f"{type(node).__name__} is not allowed")

    def __call__(self, env: Mapping[str, Any], n: int, zone: Callable[[str, str], np.ndarray] | None = None
                 ) -> np.ndarray:
        """The condition for ``n`` entities, ``(n,) bool``; ``env`` maps names to ``(n,)`` arrays or numbers;
        ``zone(fn, arg)`` answers ``in_zone``/``in_zone_kind``."""
        if self._arith:
            with np.errstate(invalid="ignore", divide="ignore"):
                out = self._fn(env, zone)
        else:
            out = self._fn(env, zone)
        return np.broadcast_to(np.asarray(out, dtype=bool), (n,)).copy()

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        del state["_fn"]  # closures do not pickle: compiled again when loaded
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._fn = self._compile(self._tree)

    def _compile(self, node: ast.AST) -> Callable[[Mapping[str, Any], Any], Any]:
        """The checked tree as nested closures ``f(env, zone)`` (evaluated once per frame and rule: no tree walk
        then). ``and``/``or`` evaluate every operand (element-wise, no short cut); comparisons chain with
        ``and``."""
        if isinstance(node, ast.BoolOp):
            parts = [self._compile(v) for v in node.values]
            op = np.logical_and if isinstance(node.op, ast.And) else np.logical_or

            def bool_op(env: Mapping[str, Any], zone: Any) -> Any:
                vals = [np.asarray(f(env, zone), dtype=bool) for f in parts]
                return functools.reduce(op, vals)

            return bool_op
        if isinstance(node, ast.UnaryOp):
            inner = self._compile(node.operand)
            if isinstance(node.op, ast.Not):
                return lambda env, zone: np.logical_not(np.asarray(inner(env, zone), dtype=bool))
            if isinstance(node.op, ast.USub):
                return lambda env, zone: np.negative(inner(env, zone))
            return inner
        if isinstance(node, ast.Compare):
            first = self._compile(node.left)
            chain = [(_CMP[type(op)], self._compile(comp)) for op, comp in zip(node.ops, node.comparators,
                                                                               strict=True)]

            def compare(env: Mapping[str, Any], zone: Any) -> Any:
                left, result = first(env, zone), True
                for cmp, f in chain:
                    right = f(env, zone)
                    result = np.logical_and(result, cmp(left, right))
                    left = right
                return result

            return compare
        if isinstance(node, ast.BinOp):
            fn, lhs, rhs = _BIN[type(node.op)], self._compile(node.left), self._compile(node.right)
            return lambda env, zone: fn(lhs(env, zone), rhs(env, zone))
        if isinstance(node, ast.Name):
            name = node.id
            return lambda env, zone: env[name]
        if isinstance(node, ast.Constant):
            value = node.value
            return lambda env, zone: value
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):  # _check let nothing else in
            raise self._fail(f"{type(node).__name__} is not allowed")
        if node.func.id == "abs":
            arg = self._compile(node.args[0])
            return lambda env, zone: np.abs(arg(env, zone))
        fn_name, zone_arg, where = node.func.id, node.args[0].value, self.where  # type: ignore[attr-defined]

        def zone_call(env: Mapping[str, Any], zone: Any) -> Any:
            if zone is None:
                raise ConfigError(f"{where}: {fn_name}() needs zones")
            return zone(fn_name, zone_arg)

        return zone_call


# --------------------------------------------------------------------------------------------------
# Configuration
# --------------------------------------------------------------------------------------------------


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SmoothingSpec(_Model):
    speed_median_s: float = Field(0.5, gt=0)
    prediction_s: float = Field(1.0, ge=0)
    track_timeout_s: float = Field(2.0, gt=0)
    velocity: Literal["track", "positions"] = "track"


class EntitySpec(_Model):
    vehicle_classes: list[str] = ["car", "bicycle", "unknown"]
    group_min_length_m: float = Field(18.0, gt=0)
    group_min_laser_objects: int = Field(2, ge=1)


class RuleSpec(_Model):
    """One application: entity, condition, temporal constraints, clearing (see ``default_rules.toml``)."""

    kind: str = ""
    enabled: bool = True
    entity: Literal["vehicle", "group", "any", "lane_zone"] = "vehicle"
    when: str = Field(min_length=1)
    hold_s: float = Field(0.0, ge=0)
    hold_frames: int = Field(1, ge=1)
    clear: str = ""
    clear_hold_s: float = Field(0.0, ge=0)
    clear_hold_frames: int = Field(1, ge=1)
    params: dict[str, float] = {}
    window_m: float = Field(50.0, gt=0)
    min_count: int = Field(5, ge=1)
    zones: list[str] = []

    @model_validator(mode="after")
    def _zone_only(self) -> RuleSpec:
        extra = {"window_m", "min_count", "zones"} & self.model_fields_set
        if self.entity != "lane_zone" and extra:
            raise ValueError(f"{sorted(extra)} apply to entity = 'lane_zone' only")
        bad = [k for k, v in self.params.items() if not math.isfinite(v)]
        if bad:
            raise ValueError(f"params {bad} must be finite numbers")
        return self


class RulesFile(_Model):
    smoothing: SmoothingSpec = SmoothingSpec()
    entity: EntitySpec = EntitySpec()
    rules: dict[str, RuleSpec] = Field(min_length=1)


@dataclass(frozen=True, slots=True, eq=False)
class CompiledRule:
    name: str
    kind: str
    spec: RuleSpec
    when: Expression
    clear: Expression | None
    env: Mapping[str, float]

    @property
    def selected(self) -> tuple[str, ...]:
        """The properties this application uses (D7 property selection)."""
        used = self.when.names | (self.clear.names if self.clear else set())
        props = ZONE_PROPERTIES if self.spec.entity == "lane_zone" else VEHICLE_PROPERTIES
        return tuple(p for p in props if p in used)


@dataclass(frozen=True, slots=True, eq=False)
class SceneRules:
    """Validated rules: smoothing, entity typing and the compiled applications (in file order)."""

    smoothing: SmoothingSpec
    entity: EntitySpec
    rules: tuple[CompiledRule, ...]
    source: str = "<rules>"

    @property
    def kinds(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(r.kind for r in self.rules))

    @property
    def selected_properties(self) -> dict[str, tuple[str, ...]]:
        """D7 property selection: per application (rule name), the properties its constraints use."""
        return {r.name: r.selected for r in self.rules}


def parse_rules(data: Mapping[str, Any], source: str = "<rules>") -> SceneRules:
    """Validate a rules mapping (as loaded from TOML) and compile its expressions.

    Raises
    ------
    ConfigError
        Naming ``source`` and the key (``rules.jam.hold_s``, ``rules.stopped_vehicle.when``) with the problem.
    """
    try:
        cfg = RulesFile.model_validate(dict(data))
    except ValidationError as err:
        raise ConfigError(parse_error_message(err, source, RulesFile)) from err
    compiled = []
    for name, spec in cfg.rules.items():
        if not spec.enabled:
            continue
        zone_rule = spec.entity == "lane_zone"
        props = set(ZONE_PROPERTIES if zone_rule else VEHICLE_PROPERTIES)
        clash = sorted(props & set(spec.params))
        if clash:
            raise ConfigError(f"{source}: rules.{name}.params: {clash} are property names")
        env = dict(spec.params)
        if zone_rule:
            env.update(min_count=float(spec.min_count), window_m=spec.window_m)
        names = props | set(env)
        when = Expression(spec.when, names, f"{source}: rules.{name}.when", zone_calls=not zone_rule)
        clear = Expression(spec.clear, names, f"{source}: rules.{name}.clear", zone_calls=not zone_rule) \
            if spec.clear.strip() else None
        compiled.append(CompiledRule(name, spec.kind or name, spec, when, clear, env))
    if not compiled:
        raise ConfigError(f"{source}: every rule is disabled")
    return SceneRules(cfg.smoothing, cfg.entity, tuple(compiled), source)


def load_rules(path: str | Path | None = None) -> SceneRules:
    """Read a rules TOML file; ``None`` gives the shipped defaults (:func:`default_rules`)."""
    if path is None:
        return default_rules()
    from ..io.datafile import read_toml

    return parse_rules(read_toml(path, "rules"), str(path))


def default_rules_text() -> str:
    """The text of the shipped ``default_rules.toml`` (a starting point for a ``--rules`` file)."""
    return (resources.files("fusiontrack.scene") / "data" / "default_rules.toml").read_text(encoding="utf-8")


@functools.cache
def default_rules() -> SceneRules:
    """D8's rules with their default thresholds (``scene/data/default_rules.toml``)."""
    return parse_rules(tomllib.loads(default_rules_text()), "default_rules.toml")


# --------------------------------------------------------------------------------------------------
# D7: the switching control module
# --------------------------------------------------------------------------------------------------

_EMPTY_NS = np.iinfo(np.int64).min


@dataclass(frozen=True, slots=True, eq=False)
class Frame:
    """What :meth:`SwitchingControl.observe` saw at one instant.

    Attributes
    ----------
    t_ns : int
    slots : (n,) int64 — the tracks updated now (rows of the per-slot arrays)
    track_ids : (n,) int64
    positions_m : (n, 2)
    props : dict name -> (n,) array of :data:`VEHICLE_PROPERTIES`
    zone_mask : (n, n_zones) bool
    lane : (n,) int64 — lane index, -1 off lanes
    velocity_mps : (n, 2) — median velocity
    """

    t_ns: int
    slots: np.ndarray
    track_ids: np.ndarray
    positions_m: np.ndarray
    props: Mapping[str, np.ndarray]
    zone_mask: np.ndarray
    lane: np.ndarray
    velocity_mps: np.ndarray

    def __len__(self) -> int:
        return int(self.slots.size)


class SwitchingControl:
    """D7: entity types and properties of tracks (with their short history) and of lane-zone groups.

    Tracks live in slots; each slot keeps a ring of recent samples for the median smoothing. The latest
    properties of every live track are kept per slot (:attr:`latest`), so lane-zone groups count every
    live track, also those not updated in the current frame.

    Parameters
    ----------
    geometry : RoadGeometry
    rules : SceneRules — its smoothing and entity sections are used
    """

    def __init__(self, geometry: RoadGeometry, rules: SceneRules) -> None:
        self.geometry, self.rules = geometry, rules
        sm = rules.smoothing
        self._window_ns = round(sm.speed_median_s * 1e9)
        self._timeout_ns = round(sm.track_timeout_s * 1e9)
        self._vehicle_classes = frozenset(rules.entity.vehicle_classes)
        self._zone_axes: dict[int, tuple[int, np.ndarray | None]] = {}  # zone -> (its lane, else its main axis)
        self._slot_of: dict[int, int] = {}
        self._n_slots, self._k = 0, 16
        self._alloc(32)
        self._last_t_ns: int | None = None

    # ------------------------------------------------------------------ storage
    def _alloc(self, n: int) -> None:
        """Grow the per-slot arrays to ``n`` slots (keeping what is there)."""
        old = self._n_slots
        z = len(self.geometry.zones)

        def grow(arr: np.ndarray | None, fill: Any, shape: tuple[int, ...] = ()) -> np.ndarray:
            new = np.full((n, *shape), fill, dtype=np.asarray(fill).dtype if arr is None else arr.dtype)
            if arr is not None:
                new[:old] = arr[:old]
            return new

        g = self.__dict__.get
        self._h_t = grow(g("_h_t"), _EMPTY_NS, (self._k,))
        self._h_v = grow(g("_h_v"), np.nan, (4, self._k))  # speed, vx, vy, smoothed speed
        self._count = grow(g("_count"), np.int64(0))
        self.alive = grow(g("alive"), False)
        self.track_id = grow(g("track_id"), np.int64(-1))
        self.first_t_ns = grow(g("first_t_ns"), np.int64(0))
        self.last_t_ns = grow(g("last_t_ns"), np.int64(0))
        self.last_pos = grow(g("last_pos"), np.nan, (2,))
        self.time_on_road_s = grow(g("time_on_road_s"), 0.0)
        self.dwell_start_ns = grow(g("dwell_start_ns"), np.int64(0))
        self.last_zones = grow(g("last_zones"), False, (z,))
        self.latest_pos = grow(g("latest_pos"), np.nan, (2,))
        self.latest_speed = grow(g("latest_speed"), np.nan)
        self.latest_vehicle = grow(g("latest_vehicle"), False)
        self.latest_score = grow(g("latest_score"), np.nan)
        self.latest_zones = grow(g("latest_zones"), False, (z,))
        self.latest_lane = grow(g("latest_lane"), np.int64(-1))
        self.latest_s = grow(g("latest_s"), np.nan)
        self.names_sensors = grow(g("names_sensors"), False)
        self._n_slots = n

    def _grow_history(self) -> None:
        """Double the ring length, samples put in time order first."""
        k = self._k
        order = (self._count[:, None] + np.arange(k)[None, :]) % k  # oldest first for full rings
        full = self._count >= k
        order[~full] = np.arange(k)
        rows = np.arange(self._n_slots)[:, None]
        new_t = np.full((self._n_slots, 2 * k), _EMPTY_NS, dtype=np.int64)
        new_t[:, :k] = self._h_t[rows, order]
        new_v = np.full((self._n_slots, 4, 2 * k), np.nan)
        new_v[:, :, :k] = np.take_along_axis(self._h_v, order[:, None, :], axis=2)
        self._h_t, self._h_v = new_t, new_v
        self._count = np.minimum(self._count, k)
        self._k = 2 * k

    def _slots_for(self, ids: np.ndarray, t_ns: int) -> np.ndarray:
        slots = np.empty(ids.size, np.int64)
        for j, tid in enumerate(ids.tolist()):
            s = self._slot_of.get(tid)
            if s is None:
                free = np.flatnonzero(~self.alive)
                if not free.size:
                    self._alloc(2 * self._n_slots)
                    free = np.flatnonzero(~self.alive)
                s = int(free[0])
                self._reset_slot(s, tid, t_ns)
            slots[j] = s
        return slots

    def _reset_slot(self, s: int, tid: int, t_ns: int) -> None:
        self._slot_of[tid] = s
        self.alive[s], self.track_id[s] = True, tid
        self._h_t[s], self._h_v[s] = _EMPTY_NS, np.nan
        self._count[s] = 0
        self.first_t_ns[s] = self.last_t_ns[s] = self.dwell_start_ns[s] = t_ns
        self.last_pos[s] = np.nan
        self.time_on_road_s[s] = 0.0
        self.last_zones[s] = False
        self.latest_pos[s], self.latest_speed[s], self.latest_score[s] = np.nan, np.nan, np.nan
        self.latest_vehicle[s], self.latest_zones[s] = False, False
        self.latest_lane[s], self.latest_s[s] = -1, np.nan
        self.names_sensors[s] = False

    def expire(self, t_ns: int) -> list[tuple[int, int, int]]:
        """Free the tracks unseen for longer than ``track_timeout_s``: ``[(slot, track_id, last_t_ns)]``."""
        gone = np.flatnonzero(self.alive & (t_ns - self.last_t_ns > self._timeout_ns))
        out = [(int(s), int(self.track_id[s]), int(self.last_t_ns[s])) for s in gone]
        for s, tid, _ in out:
            self.alive[s] = False
            del self._slot_of[tid]
        return out

    def live_slots(self) -> np.ndarray:
        return np.flatnonzero(self.alive)

    @property
    def n_slots(self) -> int:
        """Rows of the per-slot arrays (grows as tracks arrive)."""
        return self._n_slots

    # ------------------------------------------------------------------ entity type
    def entity_types(self, classes: Sequence[str], lengths_m: np.ndarray, laser_counts: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
        """D7 entity types: ``(is_vehicle, is_group)``, ``(n,) bool`` each."""
        cls = list(classes)
        with np.errstate(invalid="ignore"):
            group = np.array([c == "group" for c in cls], bool) | (lengths_m > self.rules.entity.group_min_length_m) \
                | (laser_counts >= self.rules.entity.group_min_laser_objects)
        vehicle = np.array([c in self._vehicle_classes for c in cls], bool) & ~group
        return vehicle, group

    # ------------------------------------------------------------------ one frame
    def observe(self, t_ns: int, states: Sequence[TrackState], lengths_m: Mapping[int, float] | None = None,
                laser_counts: Mapping[int, int] | None = None) -> Frame:
        """Take the track states of one instant and compute their properties.

        States with a non-finite position are skipped; when a track id appears twice, the last state counts.
        """
        if self._last_t_ns is not None and t_ns < self._last_t_ns:
            raise ConfigError(f"t_ns: frames must come in time order ({t_ns} after {self._last_t_ns})")
        self._last_t_ns = t_ns
        states = list(states)
        finite = np.isfinite(np.array([s.position_m for s in states], dtype=np.float64).reshape(-1, 2)).all(axis=1)
        by_id = {s.track_id: s for s, ok in zip(states, finite.tolist(), strict=True) if ok}
        sts = list(by_id.values())
        n = len(sts)
        ids = np.fromiter(by_id, dtype=np.int64, count=n)
        pos = np.array([s.position_m for s in sts], dtype=np.float64).reshape(n, 2)
        vel_given = np.array([s.velocity_mps for s in sts], dtype=np.float64).reshape(n, 2)
        score = np.array([s.score for s in sts], dtype=np.float64)
        sensed = np.array([bool(s.sensors) for s in sts], dtype=bool)
        slots = self._slots_for(ids, t_ns)
        names = self.names_sensors[slots] | sensed
        self.names_sensors[slots] = names
        measured = sensed | ~names
        sm = self.rules.smoothing
        # raw velocity: the track's own, else the position difference since its previous state
        dt_s = (t_ns - self.last_t_ns[slots]) * 1e-9
        diff_vel = np.where((dt_s > 0)[:, None], (pos - self.last_pos[slots]) / np.maximum(dt_s, 1e-9)[:, None],
                            np.nan)
        if sm.velocity == "positions":
            vel = diff_vel
        else:
            vel = np.where(np.isfinite(vel_given).all(axis=1)[:, None], vel_given, diff_vel)
        # ring buffer of samples; grow it while the median window does not fit
        while True:
            count = self._count[slots]
            w = count % self._k
            if not ((count >= self._k) & (self._h_t[slots, w] > t_ns - self._window_ns)).any():
                break
            self._grow_history()
        self._h_t[slots, w] = t_ns
        vx, vy = vel[:, 0], vel[:, 1]
        self._h_v[slots, 0, w], self._h_v[slots, 1, w], self._h_v[slots, 2, w] = np.hypot(vx, vy), vx, vy
        count += 1
        self._count[slots] = count
        h_t = self._h_t[slots]  # (n, k)
        in_window = h_t > t_ns - self._window_ns
        med = _row_nanmedian(np.where(in_window[:, None, :], self._h_v[slots, 0:3], np.nan))  # (n, 3)
        speed = med[:, 0]
        v_med = med[:, 1:3]
        self._h_v[slots, 3, w] = speed
        # acceleration: change of the median speed since the oldest sample in the window
        smooth = self._h_v[slots, 3]
        t_hist = np.where(in_window & np.isfinite(smooth), h_t, np.iinfo(np.int64).max)
        oldest = t_hist.argmin(axis=1)
        rows = np.arange(n)
        span_s = (t_ns - h_t[rows, oldest]) * 1e-9
        accel = np.where(span_s > 0, (speed - smooth[rows, oldest]) / np.maximum(span_s, 1e-9), 0.0)
        # geometry
        geo = self.geometry
        lane = geo.lane_index(pos)
        lane_s, lane_off, lane_dir = geo.lane_coordinates(pos, lane)
        both, outward = geo.edge_distance(np.vstack([pos, pos + np.nan_to_num(v_med) * sm.prediction_s]))
        edge, pred, outward = both[:n], both[n:], outward[:n]
        on_road = geo.inside_road(pos)
        zones = geo.zone_mask(pos)
        moving = np.hypot(v_med[:, 0], v_med[:, 1])
        unit = v_med / np.maximum(moving, 1e-12)[:, None]
        lane_cos = np.where(moving > _MIN_MOVING_MPS, np.einsum("nk,nk->n", unit, lane_dir), np.nan)
        lateral = np.einsum("nk,nk->n", v_med, outward)
        # time accumulators (a track's first state contributes no time)
        seen = count > 1
        step_s = np.where(seen, dt_s, 0.0)
        self.time_on_road_s[slots] += np.where(on_road, step_s, 0.0)
        changed = np.any(zones != self.last_zones[slots], axis=1) & seen
        self.dwell_start_ns[slots[changed]] = t_ns
        self.last_zones[slots] = zones
        self.last_t_ns[slots], self.last_pos[slots] = t_ns, pos
        id_list = ids.tolist()
        lengths = np.full(n, np.nan) if lengths_m is None else \
            np.array([float(lengths_m.get(i, np.nan)) for i in id_list], dtype=np.float64).reshape(n)
        lasers = np.zeros(n, np.int64) if laser_counts is None else \
            np.array([int(laser_counts.get(i, 0)) for i in id_list], dtype=np.int64).reshape(n)
        is_vehicle, is_group = self.entity_types([s.cls for s in sts], lengths, lasers)
        props = {
            "speed": speed, "heading": np.arctan2(v_med[:, 1], v_med[:, 0]), "acceleration": accel,
            "lateral_speed": lateral, "edge_distance": edge, "predicted_edge_distance": pred, "on_road": on_road,
            "time_on_road": self.time_on_road_s[slots].copy(), "in_lane": lane >= 0, "lane_cos": lane_cos,
            "lane_offset": lane_off, "dwell": (t_ns - self.dwell_start_ns[slots]) * 1e-9,
            "track_age": (t_ns - self.first_t_ns[slots]) * 1e-9, "score": score, "measured": measured,
            "length": lengths,
            "is_vehicle": is_vehicle, "is_group": is_group,
        }
        self.latest_pos[slots], self.latest_speed[slots] = pos, speed
        self.latest_vehicle[slots], self.latest_score[slots], self.latest_zones[slots] = is_vehicle, score, zones
        self.latest_lane[slots], self.latest_s[slots] = lane, lane_s
        return Frame(int(t_ns), slots, ids, pos, props, zones, lane, v_med)

    # ------------------------------------------------------------------ lane-zone groups
    def _zone_axis(self, zone: int) -> tuple[int, np.ndarray | None]:
        """The lane a zone lies along (:meth:`RoadGeometry.lane_of_zone`), and without one the principal axis of
        its polygon; looked up once per zone (the geometry does not change)."""
        got = self._zone_axes.get(zone)
        if got is None:
            lane, axis = self.geometry.lane_of_zone(zone), None
            if lane < 0:
                poly = self.geometry.zones[zone].polygon
                axis = np.linalg.svd(poly - poly.mean(axis=0))[2][0]
            got = self._zone_axes[zone] = (lane, axis)
        return got

    def zone_groups(self, zones: np.ndarray, window_m: float, min_count: int) -> dict[str, Any]:
        """D7 scene-level groups: per lane zone, the vehicles of the window of ``window_m`` (along the zone's
        lane) with ``>= min_count`` vehicles and the lowest mean speed; when no window has that many, the
        fullest window (the slowest among equals).

        Returns
        -------
        dict with ``count`` (z,) int, ``mean_speed`` (z,) m/s (NaN when empty), ``density`` (z,) veh/km,
        ``position_m`` (z, 2) the members' centroid, ``members`` list of (k,) int64 track ids, ``score`` (z,).
        """
        live = self.live_slots()
        vehicle_slots = live[self.latest_vehicle[live] & np.isfinite(self.latest_speed[live])]
        nz = len(zones)
        count = np.zeros(nz, np.int64)
        mean_speed, score = np.full(nz, np.nan), np.full(nz, np.nan)
        centre = np.full((nz, 2), np.nan)
        members: list[np.ndarray] = []
        for j, z in enumerate(np.asarray(zones, np.int64).tolist()):
            inside = vehicle_slots[self.latest_zones[vehicle_slots, z]]
            if not inside.size:
                members.append(np.zeros(0, np.int64))
                continue
            lane, axis = self._zone_axis(z)
            pos = self.latest_pos[inside]
            if lane >= 0:
                s = self.latest_s[inside]
                other = self.latest_lane[inside] != lane
                if other.any():
                    s[other] = self.geometry.lanes[lane].coordinates(pos[other])[0]
            else:  # along the zone polygon's principal axis
                s = pos @ axis
            order = s.argsort(kind="stable")
            s, sl = s[order], inside[order]
            v = self.latest_speed[sl]
            i, k = _best_window(s, v, window_m, min_count)
            sel = sl[i:k]
            count[j] = k - i
            mean_speed[j] = float(v[i:k].mean())
            centre[j] = self.latest_pos[sel].mean(axis=0)
            sc = self.latest_score[sel]
            if np.isfinite(sc).any():  # np.nanmean's sum and count
                known = ~np.isnan(sc)
                score[j] = float(np.where(known, sc, 0.0).sum() / known.sum())
            members.append(self.track_id[sel].copy())
        return {"count": count, "mean_speed": mean_speed, "density": count / (window_m / 1000.0),
                "position_m": centre, "members": members, "score": score}


def _row_nanmedian(a: np.ndarray) -> np.ndarray:
    """Median over the last axis ignoring NaN (``NaN`` for an all-NaN row); a sort, much cheaper than
    :func:`numpy.nanmedian` on many short rows."""
    a = np.sort(a, axis=-1)  # NaN sort last
    cnt = (~np.isnan(a)).sum(axis=-1)
    rows = a.reshape(-1, a.shape[-1])
    r = np.arange(rows.shape[0])
    lo = np.maximum((cnt - 1) // 2, 0).reshape(-1)
    hi = np.maximum(cnt // 2, 0).reshape(-1)
    med = (0.5 * (rows[r, lo] + rows[r, hi])).reshape(cnt.shape)
    return np.where(cnt > 0, med, np.nan)


@functools.lru_cache(maxsize=256)
def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.triu_indices(n)


def _best_window(s: np.ndarray, v: np.ndarray, window_m: float, min_count: int) -> tuple[int, int]:
    """Among runs ``[i, k)`` of sorted positions ``s`` spanning at most ``window_m``: the one with
    ``>= min_count`` members and the lowest mean of ``v``, else the longest (lowest mean among equals)."""
    i, k = _pairs(s.size)  # pairs i <= j, run [i, j]
    ok = s[k] - s[i] <= window_m
    i, k = i[ok], k[ok] + 1
    csum = np.empty(v.size + 1)
    csum[0] = 0.0
    np.cumsum(v, out=csum[1:])
    size = k - i
    mean = np.round((csum[k] - csum[i]) / size, 6)  # equal speeds tie exactly: the larger window wins
    big = size >= min_count
    if big.any():
        cand = np.flatnonzero(big)
        best = cand[np.lexsort((-size[cand], mean[cand]))[0]]
    else:
        best = np.lexsort((mean, -size))[0]
    return int(i[best]), int(k[best])


# --------------------------------------------------------------------------------------------------
# Temporal constraints
# --------------------------------------------------------------------------------------------------


class Latch:
    """Temporal constraints of one application over many entities (D7): an event starts once the condition
    has held for ``hold_ns`` and ``hold_frames``; it ends once the clearing condition has held for
    ``clear_ns`` and ``clear_frames``. Entities are rows (track slots, zones); gaps in a row's frames do not
    break a run.
    """

    def __init__(self, hold_ns: int, hold_frames: int, clear_ns: int, clear_frames: int, n: int = 0) -> None:
        self.hold_ns, self.hold_frames, self.clear_ns, self.clear_frames = hold_ns, hold_frames, clear_ns, clear_frames
        self._n = 0
        self.resize(n)

    def resize(self, n: int) -> None:
        if n <= self._n:
            return
        old = self._n

        def grow(name: str, fill: Any, shape: tuple[int, ...] = ()) -> None:
            new = np.full((n, *shape), fill)
            if old:
                new[:old] = getattr(self, name)
            setattr(self, name, new)

        grow("active", False)
        grow("running", False)
        grow("run_start_ns", np.int64(0))
        grow("run_frames", np.int64(0))
        grow("run_pos", np.nan, (2,))
        grow("clearing", False)
        grow("clear_start_ns", np.int64(0))
        grow("clear_frames_n", np.int64(0))
        grow("event", np.int64(-1))
        self._n = n

    def reset(self, rows: np.ndarray | Sequence[int]) -> None:
        rows = np.asarray(rows, np.int64)
        self.active[rows] = self.running[rows] = self.clearing[rows] = False
        self.event[rows] = -1

    def step(self, rows: np.ndarray, t_ns: int, cond: np.ndarray, clear: np.ndarray,
             positions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Advance the rows seen at ``t_ns``; returns the rows whose event starts now and those whose ends now
        (read :attr:`run_start_ns` / :attr:`clear_start_ns` of those rows for the start and end times)."""
        rows = np.asarray(rows, np.int64)
        active = self.active[rows]
        if not cond.any() and not active.any():  # the common case: nothing going on
            self.running[rows] = False
            return rows[:0], rows[:0]
        c = cond & ~active
        new = c & ~self.running[rows]
        self.run_start_ns[rows[new]] = t_ns
        self.run_frames[rows[new]] = 0
        if positions is not None:
            self.run_pos[rows[new]] = positions[new]
        self.running[rows[c]] = True
        self.run_frames[rows[c]] += 1
        self.running[rows[~active & ~cond]] = False
        ready = c & (t_ns - self.run_start_ns[rows] >= self.hold_ns) & (self.run_frames[rows] >= self.hold_frames)
        cl = clear & active
        newc = cl & ~self.clearing[rows]
        self.clear_start_ns[rows[newc]] = t_ns
        self.clear_frames_n[rows[newc]] = 0
        self.clearing[rows[cl]] = True
        self.clear_frames_n[rows[cl]] += 1
        self.clearing[rows[active & ~clear]] = False
        done = cl & (t_ns - self.clear_start_ns[rows] >= self.clear_ns) & \
            (self.clear_frames_n[rows] >= self.clear_frames)
        started, ended = rows[ready], rows[done]
        self.active[started], self.running[started] = True, False
        self.active[ended], self.clearing[ended], self.running[ended] = False, False, False
        return started, ended


# --------------------------------------------------------------------------------------------------
# D8: behaviour selection by rules, online and in batch
# --------------------------------------------------------------------------------------------------


def _number(x: Any) -> Any:
    if isinstance(x, np.bool_ | bool):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    return float(x)


class EventLog:
    """The events of a run: latest version of each, by id (used by the rule and learned engines)."""

    def __init__(self, sensor: str) -> None:
        self.sensor = sensor
        self._events: list[Event] = []
        self._ids: list[set[int]] = []

    def open(self, kind: str, t_ns: int, position: np.ndarray, track_ids: Iterable[int],
             attributes: Mapping[str, Any]) -> tuple[int, Event]:
        ids = {int(i) for i in track_ids}
        pos = None if not np.isfinite(position).all() else position
        ev = Event(int(t_ns), self.sensor, kind, None, pos, tuple(sorted(ids)), attributes)
        self._events.append(ev)
        self._ids.append(ids)
        return len(self._events) - 1, ev

    def add_ids(self, event: int, track_ids: Iterable[int]) -> None:
        self._ids[event].update(int(i) for i in track_ids)

    def close(self, event: int, t_end_ns: int, cleared_t_ns: int) -> Event:
        ev = self._events[event]
        attrs = {**ev.attributes, "cleared_t_ns": int(cleared_t_ns)}
        out = Event(ev.t_ns, ev.sensor, ev.kind, max(int(t_end_ns), ev.t_ns), ev.position_m,
                    tuple(sorted(self._ids[event])), attrs)
        self._events[event] = out
        return out

    def reopen(self, event: int) -> Event:
        """An ended event goes on again (``t_end_ns = None``, its ``cleared_t_ns`` dropped)."""
        ev = self._events[event]
        attrs = {k: v for k, v in ev.attributes.items() if k != "cleared_t_ns"}
        out = Event(ev.t_ns, ev.sensor, ev.kind, None, ev.position_m, tuple(sorted(self._ids[event])), attrs)
        self._events[event] = out
        return out

    def kind(self, event: int) -> str:
        return self._events[event].kind

    def current(self, event: int) -> Event:
        ev = self._events[event]
        ids = tuple(sorted(self._ids[event]))
        if ev.t_end_ns is None and ids != ev.track_ids:
            ev = Event(ev.t_ns, ev.sensor, ev.kind, None, ev.position_m, ids, ev.attributes)
            self._events[event] = ev
        return ev

    @property
    def events(self) -> list[Event]:
        return [self.current(i) for i in range(len(self._events))]

    @property
    def open_events(self) -> list[Event]:
        return [e for e in self.events if e.t_end_ns is None]


class SceneUnderstanding:
    """Online incident detection by rules (ALGORITHMS.md D8): feed track states frame by frame.

    Parameters
    ----------
    geometry : RoadGeometry
    rules : SceneRules, optional — :func:`default_rules` when None
    sensor : str — the ``sensor`` of the events

    Raises
    ------
    ConfigError
        A rule names a zone the geometry does not have, or a lane-zone rule finds no lane zones.
    """

    def __init__(self, geometry: RoadGeometry, rules: SceneRules | None = None, sensor: str = "scene") -> None:
        self.geometry = geometry
        self.rules = rules if rules is not None else default_rules()
        self.control = SwitchingControl(geometry, self.rules)
        self.log = EventLog(sensor)
        self._latches: list[Latch] = []
        self._zones: list[np.ndarray] = []
        names = set(geometry.zone_names)
        for r in self.rules.rules:
            unknown = sorted(set().union(r.when.zones, r.clear.zones if r.clear else set()) - names)
            if unknown:
                raise ConfigError(f"{self.rules.source}: rules.{r.name}: in_zone({unknown[0]!r}) names no zone of "
                                  f"{geometry.source} (zones: {sorted(names)})")
            spec = r.spec
            zones = np.zeros(0, np.int64)
            if spec.entity == "lane_zone":
                zones = _lane_zones(geometry, spec.zones, f"{self.rules.source}: rules.{r.name}.zones")
            self._zones.append(zones)
            self._latches.append(Latch(round(spec.hold_s * 1e9), spec.hold_frames, round(spec.clear_hold_s * 1e9),
                                       spec.clear_hold_frames, max(len(zones), 1)))

    @property
    def events(self) -> list[Event]:
        """Every event so far: ended ones with ``t_end_ns``, open ones with ``None``."""
        return self.log.events

    @property
    def open_events(self) -> list[Event]:
        return self.log.open_events

    def update(self, t_ns: int, track_states: Iterable[TrackState], *, lengths_m: Mapping[int, float] | None = None,
               laser_counts: Mapping[int, int] | None = None) -> list[Event]:
        """Process the track states of one instant; returns the events that start or end now.

        Parameters
        ----------
        t_ns : int — the frame time (non-decreasing from call to call)
        track_states : iterable of TrackState — the tracks seen now (states with NaN positions are skipped)
        lengths_m : mapping track id -> length (m), optional — for the D7 group test (> 18 m)
        laser_counts : mapping track id -> number of laser objects in its camera blob, optional (>= 2: group)
        """
        out: list[Event] = []
        for slot, _tid, last_ns in self.control.expire(int(t_ns)):
            out += self._end_track(slot, last_ns)
        frame = self.control.observe(int(t_ns), list(track_states), lengths_m, laser_counts)
        for rule, latch, zones in zip(self.rules.rules, self._latches, self._zones, strict=True):
            if rule.spec.entity == "lane_zone":
                if zones.size:
                    out += self._zone_rule(rule, latch, zones, frame.t_ns)
            elif len(frame):
                out += self._track_rule(rule, latch, frame)
        return out

    # ------------------------------------------------------------------ tracks
    def _env(self, rule: CompiledRule, frame: Frame) -> dict[str, Any]:
        return {**frame.props, **rule.env}

    def _zone_fn(self, frame: Frame) -> Callable[[str, str], np.ndarray]:
        geo = self.geometry

        def zone(fn: str, arg: str) -> np.ndarray:
            if fn == "in_zone":
                return frame.zone_mask[:, geo.zone_names.index(arg)]
            idx = geo.zone_indices(arg)
            return frame.zone_mask[:, idx].any(axis=1) if idx.size else np.zeros(len(frame), bool)

        return zone

    def _track_rule(self, rule: CompiledRule, latch: Latch, frame: Frame) -> list[Event]:
        latch.resize(self.control.n_slots)
        n = len(frame)
        env, zone = self._env(rule, frame), self._zone_fn(frame)
        entity = rule.spec.entity
        who = frame.props["is_vehicle"] if entity == "vehicle" else \
            frame.props["is_group"] if entity == "group" else np.ones(n, bool)
        cond = rule.when(env, n, zone) & who
        clear = rule.clear(env, n, zone) if rule.clear is not None else ~cond
        started, ended = latch.step(frame.slots, frame.t_ns, cond, clear, frame.positions_m)
        out = []
        row_of = {int(s): j for j, s in enumerate(frame.slots)} if started.size else {}
        for s in ended.tolist():
            out.append(self.log.close(int(latch.event[s]), int(latch.clear_start_ns[s]), frame.t_ns))
            latch.event[s] = -1
        for s in started.tolist():
            j = row_of[s]
            lane = int(frame.lane[j])
            zones = [self.geometry.zone_names[z] for z in np.flatnonzero(frame.zone_mask[j])]
            attrs = {"rule": rule.name, "alarm_t_ns": frame.t_ns,
                     "alarm_position_m": tuple(float(x) for x in frame.positions_m[j]),
                     "lane": self.geometry.lane_names[lane] if lane >= 0 else "", "zone": "|".join(zones),
                     "confidence": float(frame.props["score"][j]),
                     "properties": {p: _number(frame.props[p][j]) for p in rule.selected}}
            eid, ev = self.log.open(rule.kind, int(latch.run_start_ns[s]), latch.run_pos[s], [frame.track_ids[j]],
                                    attrs)
            latch.event[s] = eid
            out.append(ev)
        return out

    def _end_track(self, slot: int, last_ns: int) -> list[Event]:
        """A track has gone: its open events end at its last state; its rows are freed."""
        out = []
        for rule, latch in zip(self.rules.rules, self._latches, strict=True):
            if rule.spec.entity == "lane_zone" or slot >= latch._n:
                continue
            if latch.active[slot] and latch.event[slot] >= 0:
                out.append(self.log.close(int(latch.event[slot]), last_ns, last_ns))
            latch.reset([slot])
        return out

    # ------------------------------------------------------------------ lane zones
    def _zone_rule(self, rule: CompiledRule, latch: Latch, zones: np.ndarray, t_ns: int) -> list[Event]:
        spec = rule.spec
        g = self.control.zone_groups(zones, spec.window_m, spec.min_count)
        nz = len(zones)
        env = {"count": g["count"].astype(np.float64), "mean_speed": g["mean_speed"], "density": g["density"],
               **rule.env}
        cond = rule.when(env, nz)
        clear = rule.clear(env, nz) if rule.clear is not None else ~cond
        rows = np.arange(nz)
        # while an event is open, every vehicle of its group joins its track ids
        for r in np.flatnonzero(latch.active[:nz]).tolist():
            if cond[r] or not clear[r]:
                self.log.add_ids(int(latch.event[r]), g["members"][r].tolist())
        started, ended = latch.step(rows, t_ns, cond, clear, g["position_m"])
        out = []
        for r in ended.tolist():
            out.append(self.log.close(int(latch.event[r]), int(latch.clear_start_ns[r]), t_ns))
            latch.event[r] = -1
        for r in started.tolist():
            zone = self.geometry.zones[int(zones[r])]
            attrs = {"rule": rule.name, "alarm_t_ns": int(t_ns),
                     "alarm_position_m": tuple(float(x) for x in g["position_m"][r]),
                     "lane": zone.lane or "", "zone": zone.name,
                     "confidence": float(g["score"][r]) if np.isfinite(g["score"][r]) else 1.0,
                     "properties": {"count": int(g["count"][r]), "mean_speed": float(g["mean_speed"][r]),
                                    "density": float(g["density"][r])}}
            eid, ev = self.log.open(rule.kind, int(latch.run_start_ns[r]), latch.run_pos[r],
                                    g["members"][r].tolist(), attrs)
            latch.event[r] = eid
            out.append(ev)
        return out


def _lane_zones(geometry: RoadGeometry, names: Sequence[str], where: str) -> np.ndarray:
    """Indices of the lane zones a lane-zone rule watches (all of kind ``lane`` when ``names`` is empty)."""
    if names:
        missing = sorted(set(names) - set(geometry.zone_names))
        if missing:
            raise ConfigError(f"{where}: no zone named {missing[0]!r} in {geometry.source}")
        return np.array([geometry.zone_names.index(n) for n in names], np.int64)
    zones = geometry.zone_indices("lane")
    if not zones.size:
        log.warning("%s: %s has no zone of kind 'lane': no jams will be detected (add [[zones]] with kind = "
                    "\"lane\")", where, geometry.source)
    return zones


def frames_of(tracks: Iterable[TrackState | Track]) -> list[tuple[int, list[TrackState]]]:
    """Track states grouped into frames by time stamp, in time order: ``[(t_ns, states)]``."""
    states = flatten_states(tracks)
    if not states:
        return []
    t = np.array([s.t_ns for s in states], dtype=np.int64)
    order = np.argsort(t, kind="stable")
    t_sorted = t[order]
    cuts = np.flatnonzero(np.diff(t_sorted)) + 1
    return [(int(t[g[0]]), [states[i] for i in g]) for g in np.split(order, cuts)]


def detect_events(tracks: Iterable[TrackState | Track], geometry: RoadGeometry, rules: SceneRules | None = None, *,
                  lengths_m: Mapping[int, float] | None = None, laser_counts: Mapping[int, int] | None = None,
                  sensor: str = "scene") -> list[Event]:
    """Run :class:`SceneUnderstanding` over whole tracks (states grouped into frames by time stamp).

    Returns
    -------
    list of Event
        In the order they started; events still going on at the end have ``t_end_ns = None``.
    """
    scene = SceneUnderstanding(geometry, rules, sensor)
    for t_ns, states in frames_of(tracks):
        scene.update(t_ns, states, lengths_m=lengths_m, laser_counts=laser_counts)
    return sorted(scene.events, key=lambda e: (e.t_ns, e.kind))
