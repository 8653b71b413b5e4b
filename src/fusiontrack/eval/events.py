"""Incident-detection accuracy: detected scene events against the simulator's incidents (ALGORITHMS.md D8, D9).

Truth comes from a simulated run's ``<out>/ground_truth/``: ``incidents.jsonl`` (:class:`~fusiontrack.types.Event`
records: ``kind``, ``t_ns`` start, ``t_end_ns``, ``track_ids`` = agent ids; :func:`read_incidents`) and
``agents.csv`` (every agent's position over time; :func:`read_agents_csv`, also usable as perfect tracks with
:func:`agent_tracks`).

Matching rule (:func:`match_incidents`). A detection ``d`` may match an incident ``i`` when all of these hold:

* **kind**: ``d.kind`` equals ``i.kind`` after ``kind_map`` (e.g. ``{"road_leaving_warning": "road_leaving"}``
  scores the early warnings against the road-leaving incidents);
* **time**: their spans ``[t_ns, t_end_ns]`` overlap or lie at most ``time_tolerance_s`` (2 s) apart;
  ``t_end_ns = None`` (still going on) extends to the end of time;
* **place** (``match_by="position"``, the default, since a tracker's ids are not the agents' ids): the
  detection's ``position_m`` (where the event was at its start ``t_ns``) lies within ``radius_m`` of one of
  the incident's agents at that time (agents.csv, nearest sample in time; an agent not present then is
  taken at its nearest time within the incident). Default radius: 10 m for a vehicle's incident, 25 m (half
  the D8 jam zone) for a jam, whose position is the queue's centroid.
  ``match_by="ids"``: the detection's track ids, mapped through ``id_map`` (identity when None: tracks that
  are the ground truth), share an id with the incident's. ``match_by="time"``: no place condition.

Among the allowed pairs the matching is one-to-one, maximises the number of matches, then minimises the summed
start-time offsets (Hungarian algorithm). A second detection of an already matched incident is a false alarm.

Scores per kind (:class:`EventScore`): true incidents, detections, true positives, false alarms, precision,
recall, and the latency of the true positives: **onset latency** ``d.t_ns - i.t_ns`` (when the detector says
the situation began) and **alarm latency** ``d.attributes["alarm_t_ns"] - i.t_ns`` (when it raised the alarm;
the rules hold a condition for D8's ``T_stop``/``T_jam`` first, so that is at least those), median and max.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..errors import RecordingError
from ..io.tracks import read_jsonl
from ..types import Event, Track, TrackState
from .errors import EvaluationError

if TYPE_CHECKING:
    from rich.table import Table

__all__ = [
    "INCIDENT_KINDS",
    "AgentTable",
    "EventScore",
    "agent_tracks",
    "event_table",
    "match_incidents",
    "read_agents_csv",
    "read_incidents",
    "score_events",
]

INCIDENT_KINDS = ("stopped_vehicle", "road_leaving", "jam", "wrong_way")
DEFAULT_RADIUS_M = {"jam": 25.0}
VEHICLE_RADIUS_M = 10.0
_FOREVER = 2**62


# --------------------------------------------------------------------------------------------------
# Ground truth files
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class AgentTable:
    """The simulator's ``agents.csv``: one row per agent and ground-truth instant, sorted by ``(id, t_ns)``.

    Attributes
    ----------
    t_ns, ids : (n,) int64
    classes : (n,) str
    positions_m, velocities_mps : (n, 2) float64
    heading_rad, length_m, width_m : (n,) float64
    """

    t_ns: np.ndarray
    ids: np.ndarray
    classes: np.ndarray
    positions_m: np.ndarray
    velocities_mps: np.ndarray
    heading_rad: np.ndarray
    length_m: np.ndarray
    width_m: np.ndarray

    def __len__(self) -> int:
        return int(self.t_ns.size)

    def rows_of(self, agent_id: int) -> np.ndarray:
        """Row indices of one agent, in time order, ``(k,) int64``."""
        lo, hi = np.searchsorted(self.ids, [agent_id, agent_id + 1])
        return np.arange(lo, hi)

    def positions_at(self, agent_ids: Sequence[int], t_ns: int, window: tuple[int, int] | None = None
                     ) -> np.ndarray:
        """Each agent's position at its sample nearest to ``t_ns`` (within ``window`` = ``(t0, t1)`` when
        given), ``(k, 2)``; ``NaN`` for an agent without samples there."""
        out = np.full((len(agent_ids), 2), np.nan)
        for j, a in enumerate(agent_ids):
            rows = self.rows_of(int(a))
            if window is not None:
                rows = rows[(self.t_ns[rows] >= window[0]) & (self.t_ns[rows] <= window[1])]
            if rows.size:
                out[j] = self.positions_m[rows[np.argmin(np.abs(self.t_ns[rows] - t_ns))]]
        return out


_AGENT_COLUMNS = ("t_ns", "id", "class", "x", "y", "vx", "vy", "heading", "length", "width")


def read_agents_csv(path: str | Path) -> AgentTable:
    """Read a simulated run's ``ground_truth/agents.csv`` (or the run folder holding it).

    Raises
    ------
    RecordingError
        Missing file, missing columns or a bad number (file and line named).
    """
    path = Path(path)
    if path.is_dir():
        path = path / "ground_truth" / "agents.csv" if (path / "ground_truth").is_dir() else path / "agents.csv"
    try:
        with path.open(encoding="utf-8", newline="") as f:
            reader = csv.reader(f)
            header = [h.strip() for h in next(reader, [])]
            missing = [c for c in _AGENT_COLUMNS if c not in header]
            if missing:
                raise RecordingError(f"{path}, line 1: header lacks {missing} (expected the simulator's agents.csv)")
            rows = [r for r in reader if r]
    except FileNotFoundError as err:
        raise RecordingError(f"{path}: no such file (expected the simulator's agents.csv)") from err
    except OSError as err:
        raise RecordingError(f"{path}: cannot be read ({err.strerror or err})") from err
    table = np.array(rows, dtype=object).reshape(len(rows), len(header)) if rows else \
        np.zeros((0, len(header)), dtype=object)
    col = {c: header.index(c) for c in _AGENT_COLUMNS}
    try:
        t_ns = table[:, col["t_ns"]].astype(np.int64)
        ids = table[:, col["id"]].astype(np.int64)
        nums = table[:, [col[c] for c in ("x", "y", "vx", "vy", "heading", "length", "width")]].astype(np.float64)
    except (ValueError, TypeError) as err:
        bad = next((i for i, r in enumerate(rows) if not _row_ok(r, col)), 0)
        raise RecordingError(f"{path}, line {bad + 2}: {err}") from err
    classes = table[:, col["class"]].astype(str)
    order = np.lexsort((t_ns, ids))
    return AgentTable(t_ns[order], ids[order], classes[order], nums[order, 0:2], nums[order, 2:4], nums[order, 4],
                      nums[order, 5], nums[order, 6])


def _row_ok(row: list[str], col: Mapping[str, int]) -> bool:
    try:
        int(row[col["t_ns"]]), int(row[col["id"]])
        [float(row[col[c]]) for c in ("x", "y", "vx", "vy", "heading", "length", "width")]
    except (ValueError, IndexError):
        return False
    return True


def agent_tracks(agents: AgentTable, *, classes: Sequence[str] = ("car", "bicycle"), sensor: str = "ground_truth"
                 ) -> list[Track]:
    """The agents of ``classes`` as perfect tracks (track id = agent id, true velocity, score 1)."""
    keep = np.isin(agents.classes, list(classes))
    out = []
    for a in np.unique(agents.ids[keep]).tolist():
        rows = agents.rows_of(a)
        rows = rows[keep[rows]]
        out.append(Track(a, tuple(
            TrackState(int(t), sensor, a, p, v, cls=str(c), sensors=(sensor,))
            for t, p, v, c in zip(agents.t_ns[rows], agents.positions_m[rows], agents.velocities_mps[rows],
                                  agents.classes[rows], strict=True))))
    return out


def read_incidents(path: str | Path) -> list[Event]:
    """The true incidents of a simulated run (``ground_truth/incidents.jsonl`` or the run folder)."""
    path = Path(path)
    if path.is_dir():
        path = path / "ground_truth" / "incidents.jsonl" if (path / "ground_truth").is_dir() \
            else path / "incidents.jsonl"
    records = read_jsonl(path)
    bad = [type(r).__name__ for r in records if not isinstance(r, Event)]
    if bad:
        raise RecordingError(f"{path}: expected Event records only, found {bad[0]}")
    return [r for r in records if isinstance(r, Event)]


# --------------------------------------------------------------------------------------------------
# Matching and scores
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class EventScore:
    """Detection accuracy of one kind of incident (latencies in seconds, over the true positives)."""

    kind: str
    true: int
    detections: int
    true_positives: int
    false_alarms: int
    onset_latency_s: tuple[float, ...] = ()
    alarm_latency_s: tuple[float, ...] = ()

    @property
    def recall(self) -> float:
        """``true_positives / true``; ``NaN`` without incidents."""
        return self.true_positives / self.true if self.true else float("nan")

    @property
    def precision(self) -> float:
        """``true_positives / detections``; ``NaN`` without detections."""
        return self.true_positives / self.detections if self.detections else float("nan")

    @property
    def median_latency_s(self) -> float:
        """Median onset latency (``NaN`` without true positives)."""
        return float(np.median(self.onset_latency_s)) if self.onset_latency_s else float("nan")

    @property
    def max_latency_s(self) -> float:
        return float(np.max(self.onset_latency_s)) if self.onset_latency_s else float("nan")

    @property
    def median_alarm_latency_s(self) -> float:
        return float(np.median(self.alarm_latency_s)) if self.alarm_latency_s else float("nan")

    @property
    def max_alarm_latency_s(self) -> float:
        return float(np.max(self.alarm_latency_s)) if self.alarm_latency_s else float("nan")

    def __add__(self, other: EventScore) -> EventScore:
        """Pooled over runs (same kind)."""
        if other.kind != self.kind:
            raise EvaluationError(f"cannot pool scores of {self.kind!r} and {other.kind!r}")
        return EventScore(self.kind, self.true + other.true, self.detections + other.detections,
                          self.true_positives + other.true_positives, self.false_alarms + other.false_alarms,
                          self.onset_latency_s + other.onset_latency_s, self.alarm_latency_s + other.alarm_latency_s)

    def to_dict(self) -> dict[str, str | int | float]:
        return {"kind": self.kind, "true": self.true, "detections": self.detections,
                "true_positives": self.true_positives, "false_alarms": self.false_alarms,
                "precision": self.precision, "recall": self.recall, "median_latency_s": self.median_latency_s,
                "max_latency_s": self.max_latency_s, "median_alarm_latency_s": self.median_alarm_latency_s,
                "max_alarm_latency_s": self.max_alarm_latency_s}


def _alarm_ns(ev: Event) -> int:
    a = ev.attributes.get("alarm_t_ns")
    return int(a) if isinstance(a, int | np.integer) else ev.t_ns


def _allowed(true: Sequence[Event], det: Sequence[Event], agents: AgentTable | None, match_by: str,
             tol_ns: int, radius_m: float, id_map: Mapping[int, int] | None) -> np.ndarray:
    t0 = np.array([e.t_ns for e in true], np.int64)
    t1 = np.array([_FOREVER if e.t_end_ns is None else e.t_end_ns for e in true], np.int64)
    d0 = np.array([e.t_ns for e in det], np.int64)
    d1 = np.array([_FOREVER if e.t_end_ns is None else e.t_end_ns for e in det], np.int64)
    gap = np.maximum(np.maximum(t0[:, None] - d1[None, :], d0[None, :] - t1[:, None]), 0)
    ok = gap <= tol_ns
    for i, j in zip(*np.nonzero(ok), strict=True):
        inc, d = true[i], det[j]
        if match_by == "ids":
            mapped = {id_map.get(t, None) if id_map is not None else t for t in d.track_ids}
            ok[i, j] = bool(mapped & set(inc.track_ids))
        elif match_by == "position":
            if d.position_m is None or agents is None:
                ok[i, j] = False
                continue
            window = (inc.t_ns, _FOREVER if inc.t_end_ns is None else inc.t_end_ns)
            at = agents.positions_at(inc.track_ids, d.t_ns)
            missing = np.isnan(at).any(axis=1)
            if missing.any():  # not present at the detection time: nearest time within the incident
                at[missing] = agents.positions_at([inc.track_ids[k] for k in np.flatnonzero(missing)], d.t_ns,
                                                  window)
            dist = np.linalg.norm(at - d.position_m, axis=1)
            ok[i, j] = bool(np.nanmin(dist, initial=np.inf) <= radius_m)
    return ok


def match_incidents(incidents: Sequence[Event], detections: Sequence[Event], agents: AgentTable | None = None, *,
                    kind_map: Mapping[str, str] | None = None, time_tolerance_s: float = 2.0,
                    radius_m: float | Mapping[str, float] | None = None,
                    match_by: Literal["position", "ids", "time"] = "position",
                    id_map: Mapping[int, int] | None = None) -> list[tuple[int, int]]:
    """One-to-one matches of detections to incidents (rule in the module docstring).

    Returns
    -------
    list of (int, int)
        ``(index into incidents, index into detections)``, sorted.

    Raises
    ------
    EvaluationError
        A bad option, or ``match_by="position"`` without ``agents``.
    """
    if match_by not in ("position", "ids", "time"):
        raise EvaluationError(f"match_by: expected 'position', 'ids' or 'time', got {match_by!r}")
    if match_by == "position" and agents is None:
        raise EvaluationError("match_by='position' needs the agents table (read_agents_csv)")
    if not time_tolerance_s >= 0:
        raise EvaluationError(f"time_tolerance_s: expected >= 0 s, got {time_tolerance_s!r}")
    kmap = dict(kind_map or {})
    kinds_det = [kmap.get(d.kind, d.kind) for d in detections]
    pairs: list[tuple[int, int]] = []
    for kind in sorted({e.kind for e in incidents} & set(kinds_det)):
        ti = [i for i, e in enumerate(incidents) if e.kind == kind]
        di = [j for j, k in enumerate(kinds_det) if k == kind]
        if isinstance(radius_m, Mapping):
            radius = float(radius_m.get(kind, DEFAULT_RADIUS_M.get(kind, VEHICLE_RADIUS_M)))
        else:
            radius = float(radius_m) if radius_m is not None else DEFAULT_RADIUS_M.get(kind, VEHICLE_RADIUS_M)
        ok = _allowed([incidents[i] for i in ti], [detections[j] for j in di], agents, match_by,
                      round(time_tolerance_s * 1e9), radius, id_map)
        offset = np.abs(np.array([incidents[i].t_ns for i in ti], np.float64)[:, None]
                        - np.array([detections[j].t_ns for j in di], np.float64)[None, :])
        worth = min(len(ti), len(di)) + 2  # any match is worth more than every tie-break together
        cost = np.where(ok, offset / (offset.max(initial=0) + 1.0) - worth, 0.0)
        rows, cols = linear_sum_assignment(cost)
        keep = ok[rows, cols]
        pairs += [(ti[r], di[c]) for r, c in zip(rows[keep], cols[keep], strict=True)]
    return sorted(pairs)


def score_events(incidents: Iterable[Event], detections: Iterable[Event], agents: AgentTable | None = None, *,
                 kinds: Sequence[str] = INCIDENT_KINDS, kind_map: Mapping[str, str] | None = None,
                 time_tolerance_s: float = 2.0, radius_m: float | Mapping[str, float] | None = None,
                 match_by: Literal["position", "ids", "time"] = "position",
                 id_map: Mapping[int, int] | None = None) -> dict[str, EventScore]:
    """Per kind: true count, detections, true positives, false alarms, and latencies (module docstring).

    Detections whose kind (after ``kind_map``) is not in ``kinds`` are ignored; every kind gets an entry.
    """
    kmap = dict(kind_map or {})
    true = [e for e in incidents if e.kind in kinds]
    det = [d for d in detections if kmap.get(d.kind, d.kind) in kinds]
    pairs = match_incidents(true, det, agents, kind_map=kmap, time_tolerance_s=time_tolerance_s,
                            radius_m=radius_m, match_by=match_by, id_map=id_map)
    out = {}
    for kind in kinds:
        hits = [(i, j) for i, j in pairs if true[i].kind == kind]
        n_true = sum(e.kind == kind for e in true)
        n_det = sum(kmap.get(d.kind, d.kind) == kind for d in det)
        onset = tuple((det[j].t_ns - true[i].t_ns) * 1e-9 for i, j in hits)
        alarm = tuple((_alarm_ns(det[j]) - true[i].t_ns) * 1e-9 for i, j in hits)
        out[kind] = EventScore(kind, n_true, n_det, len(hits), n_det - len(hits), onset, alarm)
    return out


def event_table(scores: Mapping[str, EventScore], *, title: str | None = None) -> Table:
    """A rich table of :func:`score_events`: one row per kind."""
    from rich.table import Table

    def num(x: float, fmt: str) -> str:
        return "-" if np.isnan(x) else format(x, fmt)

    table = Table(title=title)
    for header in ("kind", "true", "detections", "TP", "false alarms", "precision", "recall",
                   "median onset lat. s", "max onset lat. s", "median alarm lat. s", "max alarm lat. s"):
        table.add_column(header, justify="left" if header == "kind" else "right")
    for kind, s in scores.items():
        table.add_row(kind, str(s.true), str(s.detections), str(s.true_positives), str(s.false_alarms),
                      num(s.precision, ".2f"), num(s.recall, ".2f"), num(s.median_latency_s, ".2f"),
                      num(s.max_latency_s, ".2f"), num(s.median_alarm_latency_s, ".2f"),
                      num(s.max_alarm_latency_s, ".2f"))
    return table
