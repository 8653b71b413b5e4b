"""Road geometry for scene understanding: carriageways, lanes and zones in the road frame (ALGORITHMS.md D7).

A :class:`RoadGeometry` holds

* **roads**: carriageway polygons. Some polygon edges may be *open*: the ends of the monitored stretch,
  where the road goes on beyond the area (a vehicle driving out through an open edge has not left the road);
* **lanes**: polygons with a direction of travel; a lane given by its centre line (a polyline in the
  direction of travel) and width also has a longitudinal coordinate ``s`` (arc length along the centre line);
* **zones**: named polygons of a kind: ``"lane"`` (a lane zone in which jams are detected),
  ``"parking"`` (stopping allowed), ``"no_stop"`` (stopping forbidden, also off the carriageway),
  ``"shoulder"``.

Point queries are vectorised over points (``(n, 2)`` in, ``(n,)`` out): :meth:`RoadGeometry.lane_index`,
:meth:`~RoadGeometry.lane_direction`, :meth:`~RoadGeometry.lane_coordinates`, :meth:`~RoadGeometry.inside_road`,
:meth:`~RoadGeometry.edge_distance` (signed: positive on the road, negative outside, ``NaN`` beyond an open
end), :meth:`~RoadGeometry.zone_mask`. Point-in-polygon is :class:`matplotlib.path.Path`.

Two sources:

* :func:`load_road_geometry` reads a small TOML file (validated with pydantic; errors name the file and the
  key, e.g. ``lanes.1.width_m``)::

      [[roads]]
      name = "main"
      centerline = [[-60.0, 0.0], [60.0, 0.0]]   # the ends of a centre-line road are open
      width_m = 14.0

      [[lanes]]
      name = "east_0"
      road = "main"
      centerline = [[-60.0, -5.25], [60.0, -5.25]]   # points in the direction of travel
      width_m = 3.5
      # or: polygon = [[x, y], ...] and direction_deg = 0.0

      [[zones]]
      name = "jam_east_0"
      kind = "lane"                 # lane | parking | no_stop | shoulder
      lane = "east_0"               # the lane's polygon (optionally s_range_m = [0.0, 50.0]) ...
      # polygon = [[x, y], ...]     # ... or any polygon

  A road may instead be a ``polygon`` with ``open_edges`` (indices ``i`` of the edges from vertex ``i`` to
  ``i + 1``).
* :func:`road_geometry_from_world` builds the same from the simulator's ``ground_truth/world.json``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from matplotlib.path import Path as MplPath
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from ..config import parse_error_message
from ..errors import ConfigError

__all__ = [
    "ZONE_KINDS",
    "Lane",
    "Road",
    "RoadGeometry",
    "Zone",
    "load_road_geometry",
    "parse_road_geometry",
    "road_geometry_from_world",
]

ZONE_KINDS = ("lane", "parking", "no_stop", "shoulder")


# --------------------------------------------------------------------------------------------------
# Pure geometry on arrays
# --------------------------------------------------------------------------------------------------


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance from points ``(n, 2)`` to segments ``a -> b`` ``(m, 2)``, ``(n, m)``, and the segment parameter
    ``t`` in [0, 1] of the nearest point."""
    d = b - a
    rel = points[:, None, :] - a[None, :, :]
    t = np.clip(np.einsum("nmk,mk->nm", rel, d) / np.maximum(np.einsum("mk,mk->m", d, d), 1e-18), 0.0, 1.0)
    diff = rel - t[..., None] * d[None, :, :]
    return np.hypot(diff[..., 0], diff[..., 1]), t


def _signed_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _offset_polyline(line: np.ndarray, offset: float) -> np.ndarray:
    """The polyline moved ``offset`` to its left (mitred joins), ``(m, 2)``."""
    d = np.diff(line, axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    left = d[:, ::-1] * [-1.0, 1.0]
    normals = np.vstack([left[:1], left[:-1] + left[1:], left[-1:]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    # a mitre keeps the offset lines parallel to both neighbouring segments
    cos_half = np.ones(len(line))
    cos_half[1:-1] = np.einsum("mk,mk->m", normals[1:-1], left[:-1])
    return line + offset * normals / np.maximum(cos_half, 0.2)[:, None]


def _buffer_polyline(line: np.ndarray, width_m: float) -> np.ndarray:
    """Polygon of a strip ``width_m`` wide around a polyline (flat ends): left side, then the right side back."""
    half = width_m / 2
    return np.vstack([_offset_polyline(line, half), _offset_polyline(line, -half)[::-1]])


def _cut_polyline(line: np.ndarray, s0: float, s1: float) -> np.ndarray:
    """The part of a polyline between arc lengths ``s0 < s1`` (clipped to the line)."""
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s0, s1 = max(s0, 0.0), min(s1, float(cum[-1]))
    inner = (cum > s0) & (cum < s1)
    s = np.concatenate([[s0], cum[inner], [s1]])
    return np.column_stack([np.interp(s, cum, line[:, 0]), np.interp(s, cum, line[:, 1])])


@dataclass(frozen=True, slots=True, eq=False)
class _Polygon:
    """A closed polygon with point-in-polygon, boundary distance and outward edge normals."""

    vertices: np.ndarray  # (k, 2)
    path: MplPath = field(init=False)
    a: np.ndarray = field(init=False)  # (k, 2) edge starts
    b: np.ndarray = field(init=False)  # (k, 2) edge ends
    outward: np.ndarray = field(init=False)  # (k, 2) unit outward normals

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, np.float64)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "path", MplPath(np.vstack([v, v[:1]]), closed=True))
        a, b = v, np.roll(v, -1, axis=0)
        d = b - a
        n = d[:, ::-1] * [1.0, -1.0]  # right of each edge: outside for a counter-clockwise polygon
        if _signed_area(v) < 0:
            n = -n
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)
        object.__setattr__(self, "outward", n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-18))

    def contains(self, points: np.ndarray) -> np.ndarray:
        if not len(points):
            return np.zeros(0, bool)
        return self.path.contains_points(points)


# --------------------------------------------------------------------------------------------------
# Records
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class Road:
    """A carriageway polygon ``(k, 2)``; ``open_edges`` are the edges (vertex ``i`` -> ``i + 1``) that are not
    road edges but the ends of the monitored stretch."""

    name: str
    polygon: np.ndarray
    open_edges: tuple[int, ...] = ()
    _poly: _Polygon = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_poly", _Polygon(self.polygon))
        object.__setattr__(self, "polygon", self._poly.vertices)


@dataclass(frozen=True, slots=True, eq=False)
class Lane:
    """A lane: its polygon, direction of travel and (when given by one) its centre line.

    Attributes
    ----------
    polygon : (k, 2)
    centerline : (m, 2) or None — in the direction of travel
    direction : (2,) or None — unit direction of a lane without a centre line
    width_m : float (``NaN`` for a polygon lane)
    """

    name: str
    road: str
    polygon: np.ndarray
    centerline: np.ndarray | None = None
    direction: np.ndarray | None = None
    width_m: float = math.nan
    _poly: _Polygon = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_poly", _Polygon(self.polygon))
        object.__setattr__(self, "polygon", self._poly.vertices)

    def coordinates(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per point: longitudinal ``s`` (m), lateral offset (m, left of travel positive), distance to the
        centre line (m) and the unit direction of travel there ``(n, 2)``."""
        if self.centerline is None:
            u = np.asarray(self.direction, np.float64)
            centre = self.polygon.mean(axis=0)
            rel = points - centre
            lat = rel[:, 0] * -u[1] + rel[:, 1] * u[0]
            return rel @ u, lat, np.abs(lat), np.broadcast_to(u, points.shape).copy()
        a, b = self.centerline[:-1], self.centerline[1:]
        dist, t = _segment_distance(points, a, b)
        k = np.argmin(dist, axis=1)
        rows = np.arange(len(points))
        seg = b - a
        seg_len = np.linalg.norm(seg, axis=1)
        u = seg[k] / seg_len[k, None]
        cum = np.concatenate([[0.0], np.cumsum(seg_len)])
        s = cum[k] + t[rows, k] * seg_len[k]
        rel = points - a[k]
        lat = rel[:, 0] * -u[:, 1] + rel[:, 1] * u[:, 0]
        return s, lat, dist[rows, k], u


@dataclass(frozen=True, slots=True, eq=False)
class Zone:
    """A named polygon of a kind in :data:`ZONE_KINDS`; ``lane`` names the lane a lane zone lies along."""

    name: str
    kind: str
    polygon: np.ndarray
    lane: str = ""
    _poly: _Polygon = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.kind not in ZONE_KINDS:
            raise ConfigError(f"zone {self.name!r}: kind {self.kind!r}, expected one of {list(ZONE_KINDS)}")
        object.__setattr__(self, "_poly", _Polygon(self.polygon))
        object.__setattr__(self, "polygon", self._poly.vertices)


@dataclass(frozen=True, slots=True, eq=False)
class RoadGeometry:
    """Roads, lanes and zones in the road frame, with vectorised point queries."""

    roads: tuple[Road, ...]
    lanes: tuple[Lane, ...] = ()
    zones: tuple[Zone, ...] = ()
    source: str = "<geometry>"

    def __post_init__(self) -> None:
        if not self.roads:
            raise ConfigError(f"{self.source}: the geometry needs at least one road")
        for what, items in (("road", self.roads), ("lane", self.lanes), ("zone", self.zones)):
            names = [x.name for x in items]
            dup = sorted({n for n in names if names.count(n) > 1})
            if dup:
                raise ConfigError(f"{self.source}: {what} names must be unique, {dup} repeated")
        lanes = {ln.name for ln in self.lanes}
        for z in self.zones:
            if z.lane and z.lane not in lanes:
                raise ConfigError(f"{self.source}: zone {z.name!r} names lane {z.lane!r}, which does not exist")

    # ------------------------------------------------------------------ look-ups
    @property
    def lane_names(self) -> tuple[str, ...]:
        return tuple(ln.name for ln in self.lanes)

    @property
    def zone_names(self) -> tuple[str, ...]:
        return tuple(z.name for z in self.zones)

    def zone_indices(self, kind: str) -> np.ndarray:
        """Indices of the zones of one kind, ``(k,) int64``."""
        return np.array([i for i, z in enumerate(self.zones) if z.kind == kind], dtype=np.int64)

    def lane_of_zone(self, zone: int) -> int:
        """Index of the lane a zone lies along (its ``lane``, else the lane containing its centroid), or -1."""
        z = self.zones[zone]
        if z.lane:
            return self.lane_names.index(z.lane)
        return int(self.lane_index(z.polygon.mean(axis=0, keepdims=True))[0])

    # ------------------------------------------------------------------ point queries
    @staticmethod
    def _points(points: Any) -> np.ndarray:
        p = np.asarray(points, np.float64)
        if p.ndim != 2 or p.shape[1] != 2:
            raise ValueError(f"points: expected shape (n, 2), got {p.shape}")
        return p

    def lane_index(self, points: Any) -> np.ndarray:
        """Index into :attr:`lanes` of the lane containing each point, ``(n,) int64``; -1 outside every lane
        (and for ``NaN`` points). Where lanes overlap, the one whose centre is nearest wins."""
        p = self._points(points)
        out = np.full(len(p), -1, np.int64)
        if not self.lanes or not len(p):
            return out
        inside = np.column_stack([lane._poly.contains(p) for lane in self.lanes])  # (n, lanes)
        hits = inside.sum(axis=1)
        out[hits == 1] = np.argmax(inside[hits == 1], axis=1)
        shared = np.flatnonzero(hits > 1)
        if shared.size:  # on a shared lane border or in overlapping lanes: the nearest centre wins
            dist = np.full((shared.size, len(self.lanes)), np.inf)
            for i in np.flatnonzero(inside[shared].any(axis=0)):
                sel = inside[shared, i]
                dist[sel, i] = self.lanes[i].coordinates(p[shared[sel]])[2]
            out[shared] = np.argmin(dist, axis=1)
        return out

    def lane_coordinates(self, points: Any, lanes: Any | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per point, in its lane (``lanes``: indices as from :meth:`lane_index`, computed when None):
        ``s`` (m along the lane), lateral offset (m, left of travel positive) and the unit direction of
        travel ``(n, 2)``; ``NaN`` outside every lane."""
        p = self._points(points)
        idx = self.lane_index(p) if lanes is None else np.asarray(lanes, np.int64)
        s, lat, u = np.full(len(p), np.nan), np.full(len(p), np.nan), np.full((len(p), 2), np.nan)
        for i in np.unique(idx[idx >= 0]):
            sel = idx == i
            s[sel], lat[sel], _, u[sel] = self.lanes[i].coordinates(p[sel])
        return s, lat, u

    def lane_direction(self, points: Any) -> np.ndarray:
        """Unit direction of travel of the lane at each point, ``(n, 2)``; ``NaN`` outside every lane."""
        return self.lane_coordinates(points)[2]

    def inside_road(self, points: Any) -> np.ndarray:
        """Whether each point lies on a carriageway, ``(n,) bool``."""
        p = self._points(points)
        inside = np.zeros(len(p), bool)
        for road in self.roads:
            inside |= road._poly.contains(p)
        return inside

    def edge_distance(self, points: Any) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance to the road edge and the edge's outward unit normal.

        Returns
        -------
        distance_m : (n,) float
            On a road: the distance to its nearest (closed) edge, positive; off every road: minus the distance
            to the nearest road; ``NaN`` when that nearest boundary is an open edge (the point is beyond the
            end of the monitored stretch, not off the road) and for ``NaN`` points.
        outward : (n, 2) float
            Unit vector across the nearest edge towards the outside (``NaN`` where the distance is).

        Notes
        -----
        With several roads the inside distance is the largest over the roads containing the point: exact
        for roads that meet without overlapping.
        """
        p = self._points(points)
        n = len(p)
        inside_d = np.full(n, -np.inf)
        inside_nrm = np.full((n, 2), np.nan)
        out_d = np.full(n, np.inf)
        out_nrm = np.full((n, 2), np.nan)
        out_open = np.zeros(n, bool)
        inside_any = np.zeros(n, bool)
        rows = np.arange(n)
        for road in self.roads:
            poly = road._poly
            dist, t = _segment_distance(p, poly.a, poly.b)
            inside = poly.contains(p)
            inside_any |= inside
            closed = np.ones(len(poly.a), bool)
            closed[list(road.open_edges)] = False
            if closed.any():
                dc = np.where(closed[None, :], dist, np.inf)
                k = np.argmin(dc, axis=1)
                d_in = dc[rows, k]
                better = inside & (d_in > inside_d)
                inside_d[better] = d_in[better]
                inside_nrm[better] = poly.outward[k[better]]
            k = np.argmin(dist - 1e-9 * ~closed[None, :], axis=1)  # a corner shared with an open end: beyond it
            d_out = dist[rows, k]
            closest = poly.a[k] + t[rows, k, None] * (poly.b[k] - poly.a[k])
            better = ~inside & (d_out < out_d)
            out_d[better] = d_out[better]
            out_open[better] = ~closed[k[better]]
            diff = p[better] - closest[better]
            nrm = np.linalg.norm(diff, axis=1, keepdims=True)
            out_nrm[better] = np.where(nrm > 1e-12, diff / np.maximum(nrm, 1e-12), poly.outward[k[better]])
        distance = np.where(inside_any, inside_d, -out_d)
        outward = np.where(inside_any[:, None], inside_nrm, out_nrm)
        unknown = (~inside_any & out_open) | ~np.isfinite(distance) | np.isnan(p).any(axis=1)
        distance[unknown] = np.nan
        outward[unknown] = np.nan
        return distance, outward

    def zone_mask(self, points: Any) -> np.ndarray:
        """Membership of each point in each zone, ``(n, n_zones) bool``."""
        p = self._points(points)
        out = np.zeros((len(p), len(self.zones)), bool)
        for j, zone in enumerate(self.zones):
            out[:, j] = zone._poly.contains(p)
        return out


# --------------------------------------------------------------------------------------------------
# TOML file
# --------------------------------------------------------------------------------------------------

Point = tuple[float, float]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _check_points(pts: list[Point] | None, n_min: int, what: str) -> None:
    if pts is None:
        return
    arr = np.asarray(pts, np.float64)
    if len(arr) < n_min:
        raise ValueError(f"{what}: expected at least {n_min} points, got {len(arr)}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{what}: points must be finite")
    if what == "centerline" and np.any(np.linalg.norm(np.diff(arr, axis=0), axis=1) < 1e-9):
        raise ValueError("centerline: consecutive points must differ")
    if what == "polygon" and abs(_signed_area(arr)) < 1e-9:
        raise ValueError("polygon: the polygon has no area")


class RoadSpec(_Model):
    name: str = Field(min_length=1)
    centerline: list[Point] | None = None
    width_m: float | None = Field(default=None, gt=0)
    polygon: list[Point] | None = None
    open_edges: list[int] = []

    @model_validator(mode="after")
    def _shape(self) -> RoadSpec:
        if (self.polygon is None) == (self.centerline is None):
            raise ValueError("give either polygon or centerline + width_m")
        if self.centerline is not None and self.width_m is None:
            raise ValueError("a centerline road needs width_m")
        if self.polygon is not None and self.width_m is not None:
            raise ValueError("width_m goes with a centerline, not with a polygon")
        if self.centerline is not None and self.open_edges:
            raise ValueError("open_edges goes with a polygon (the ends of a centerline road are open)")
        _check_points(self.centerline, 2, "centerline")
        _check_points(self.polygon, 3, "polygon")
        if self.polygon is not None and any(not 0 <= i < len(self.polygon) for i in self.open_edges):
            raise ValueError(f"open_edges: indices must be in [0, {len(self.polygon) - 1}]")
        return self


class LaneSpec(_Model):
    name: str = Field(min_length=1)
    road: str = ""
    centerline: list[Point] | None = None
    width_m: float | None = Field(default=None, gt=0)
    polygon: list[Point] | None = None
    direction_deg: float | None = None

    @model_validator(mode="after")
    def _shape(self) -> LaneSpec:
        if self.centerline is not None:
            if self.width_m is None and self.polygon is None:
                raise ValueError("a centerline lane needs width_m (or a polygon)")
            if self.direction_deg is not None:
                raise ValueError("direction_deg goes with a polygon lane (a centerline gives the direction)")
        elif self.polygon is None or self.direction_deg is None:
            raise ValueError("give centerline + width_m, or polygon + direction_deg")
        _check_points(self.centerline, 2, "centerline")
        _check_points(self.polygon, 3, "polygon")
        return self


class ZoneSpec(_Model):
    name: str = Field(min_length=1)
    kind: Literal["lane", "parking", "no_stop", "shoulder"]
    polygon: list[Point] | None = None
    lane: str = ""
    s_range_m: tuple[float, float] | None = None

    @model_validator(mode="after")
    def _shape(self) -> ZoneSpec:
        if self.polygon is None and not self.lane:
            raise ValueError("give a polygon or the lane the zone covers")
        if self.s_range_m is not None:
            if self.polygon is not None or not self.lane:
                raise ValueError("s_range_m cuts a lane: give lane and no polygon")
            if not self.s_range_m[0] < self.s_range_m[1]:
                raise ValueError(f"s_range_m: expected [start, end] with start < end, got {list(self.s_range_m)}")
        _check_points(self.polygon, 3, "polygon")
        return self


class GeometryFile(_Model):
    roads: list[RoadSpec] = Field(min_length=1)
    lanes: list[LaneSpec] = []
    zones: list[ZoneSpec] = []


def _lane(spec: LaneSpec) -> Lane:
    line = None if spec.centerline is None else np.asarray(spec.centerline, np.float64)
    if spec.polygon is not None:
        poly = np.asarray(spec.polygon, np.float64)
    else:  # LaneSpec guarantees a centre line and a width here
        poly = _buffer_polyline(np.asarray(spec.centerline, np.float64), float(spec.width_m or 0.0))
    direction = None
    if line is None:
        a = math.radians(float(spec.direction_deg or 0.0))
        direction = np.array([math.cos(a), math.sin(a)])
    return Lane(spec.name, spec.road, poly, line, direction, float(spec.width_m or math.nan))


def _build(cfg: GeometryFile, source: str) -> RoadGeometry:
    roads = []
    for r in cfg.roads:
        if r.polygon is not None:
            roads.append(Road(r.name, np.asarray(r.polygon, np.float64), tuple(r.open_edges)))
        else:
            line = np.asarray(r.centerline, np.float64)
            m = len(line)
            roads.append(Road(r.name, _buffer_polyline(line, float(r.width_m or 0.0)), (m - 1, 2 * m - 1)))
    road_names = {r.name for r in roads}
    lanes = []
    for i, spec in enumerate(cfg.lanes):
        if spec.road and spec.road not in road_names:
            raise ConfigError(f"{source}: lanes.{i}.road: no road named {spec.road!r} (roads: {sorted(road_names)})")
        lanes.append(_lane(spec))
    by_name = {ln.name: ln for ln in lanes}
    zones = []
    for i, spec in enumerate(cfg.zones):
        if spec.lane and spec.lane not in by_name:
            raise ConfigError(f"{source}: zones.{i}.lane: no lane named {spec.lane!r} (lanes: {sorted(by_name)})")
        if spec.polygon is not None:
            poly = np.asarray(spec.polygon, np.float64)
        else:
            lane = by_name[spec.lane]
            if spec.s_range_m is None:
                poly = lane.polygon
            elif lane.centerline is None:
                raise ConfigError(f"{source}: zones.{i}.s_range_m: lane {lane.name!r} has no centerline to cut")
            elif not np.isfinite(lane.width_m):
                raise ConfigError(f"{source}: zones.{i}.s_range_m: lane {lane.name!r} has no width_m to cut with")
            else:
                part = _cut_polyline(lane.centerline, *spec.s_range_m)
                if len(part) < 2 or np.linalg.norm(part[-1] - part[0]) < 1e-6:
                    raise ConfigError(f"{source}: zones.{i}.s_range_m: {list(spec.s_range_m)} lies outside "
                                      f"lane {lane.name!r}")
                poly = _buffer_polyline(part, lane.width_m)
        zones.append(Zone(spec.name, spec.kind, poly, spec.lane))
    return RoadGeometry(tuple(roads), tuple(lanes), tuple(zones), source)


def parse_road_geometry(data: dict[str, Any], source: str = "<geometry>") -> RoadGeometry:
    """Validate a geometry mapping (as loaded from TOML) and build the :class:`RoadGeometry`.

    Raises
    ------
    ConfigError
        Naming ``source`` and each offending key (``lanes.0.width_m``) with what was expected.
    """
    try:
        cfg = GeometryFile.model_validate(data)
    except ValidationError as err:
        raise ConfigError(parse_error_message(err, source, GeometryFile)) from err
    return _build(cfg, source)


def load_road_geometry(path: str | Path) -> RoadGeometry:
    """Read and validate a road geometry TOML file (format in the module docstring)."""
    from ..io.datafile import read_toml

    return parse_road_geometry(read_toml(path, "road geometry"), str(path))


# --------------------------------------------------------------------------------------------------
# The simulator's world.json
# --------------------------------------------------------------------------------------------------


def road_geometry_from_world(world_json_path: str | Path, *, shoulder_m: float = 3.0) -> RoadGeometry:
    """The road geometry of a simulated world (``<out>/ground_truth/world.json``).

    Each road ``(x0, y0, x1, y1, width)`` becomes a carriageway rectangle with open ends and
    ``n = round(width / (2 lane_width_m))`` lanes per direction, as the simulator drives them
    (``sim/agents.py``): lane ``k >= 0`` runs from ``(x0, y0)`` to ``(x1, y1)``, lane ``-1 - k`` the other way,
    lane 0 and -1 being the rightmost lanes of their direction; the centre of lane ``k`` of a direction lies
    ``width/2 - (k + 1/2) lane_width_m`` to the right of the road's centre line. Lanes are named
    ``road<r>_lane<k>``; each lane is also a ``"lane"`` zone of the same name (jam detection), and a
    ``shoulder_m`` wide strip beyond each road edge is a ``"shoulder"`` zone.

    Raises
    ------
    ConfigError
        Missing or unreadable file, or no valid roads in it.
    """
    path = Path(world_json_path)
    try:
        world = json.loads(path.read_text(encoding="utf-8"))
        roads_arr = np.asarray(world["roads"], np.float64).reshape(-1, 5)
        lane_w = float(world["lane_width_m"])
    except FileNotFoundError as err:
        raise ConfigError(f"world file not found: {path}") from err
    except (OSError, json.JSONDecodeError) as err:
        raise ConfigError(f"{path}: cannot read the world file: {err}") from err
    except (KeyError, TypeError, ValueError) as err:
        raise ConfigError(f"{path}: expected 'roads' [[x0, y0, x1, y1, width], ...] and 'lane_width_m' "
                          f"({err})") from err
    if not len(roads_arr):
        raise ConfigError(f"{path}: the world has no roads")
    if not (np.isfinite(roads_arr).all() and lane_w > 0 and (roads_arr[:, 4] > 0).all()):
        raise ConfigError(f"{path}: roads must be finite with width > 0, and lane_width_m > 0")
    roads, lanes, zones = [], [], []
    for r, (x0, y0, x1, y1, width) in enumerate(roads_arr):
        start, end = np.array([x0, y0]), np.array([x1, y1])
        line = np.vstack([start, end])
        if np.linalg.norm(end - start) < 1e-9:
            raise ConfigError(f"{path}: road {r} has zero length")
        name = f"road{r}"
        roads.append(Road(name, _buffer_polyline(line, width), (1, 3)))
        half = width / 2
        n_lanes = max(1, round(width / (2 * lane_w)))
        for k in range(n_lanes):
            right = half - (k + 0.5) * lane_w  # to the right of the direction of travel
            for lane_id, centre in ((k, _offset_polyline(line, -right)),
                                    (-1 - k, _offset_polyline(line[::-1], -right))):
                lane = Lane(f"{name}_lane{lane_id}", name, _buffer_polyline(centre, lane_w), centre, None, lane_w)
                lanes.append(lane)
                zones.append(Zone(lane.name, "lane", lane.polygon, lane.name))
        for side, sign in (("right", -1.0), ("left", 1.0)):
            edge = _offset_polyline(line, sign * half)
            outer = _offset_polyline(line, sign * (half + shoulder_m))
            zones.append(Zone(f"{name}_shoulder_{side}", "shoulder", np.vstack([edge, outer[::-1]])))
    return RoadGeometry(tuple(roads), tuple(lanes), tuple(zones), str(path))

