"""The small baseline of issue 4: constant-velocity Kalman filters with Hungarian assignment on detection centres.

:class:`CVKalmanTracker` has the interface of :class:`~fusiontrack.tracking.tracker.LaserPeopleTracker`
(``step(t_ns, detections) -> list[TrackState]``, :attr:`~CVKalmanTracker.events`, ``finish()``) and none of
its people-specific parts: no feet, no walking model, no situation switch, no merged targets.

Per step: every track is predicted with the X5 constant-velocity model (``q`` m²/s³); tracks and
detection centres are paired by the Hungarian algorithm on Euclidean distance, pairs farther than
``gate_m`` forbidden (X2); paired tracks take a Kalman update (``R = r_m² I``); unpaired detections
become candidates and, seen without a gap for ``(n_confirm - 1) · frame_s`` seconds, tracks; a track
with no detection for ``n_miss · frame_s`` seconds ends. Events: ``appear``/``disappear`` when an area
is given and the birth/death is within ``d_edge_m`` of its boundary, ``born``/``lost`` otherwise.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..types import Detection, Event, ObjectClass, Situation, TrackState
from . import kalman
from .association import hungarian
from .situations import on_edge
from .tracker import CandidateSet, _fast_state, area_polygon

__all__ = ["CVKalmanTracker"]

_NONCORRELATED = str(Situation.NONCORRELATED)


class CVKalmanTracker:
    """Constant-velocity Kalman + Hungarian tracker on detection centres (module docstring).

    Parameters
    ----------
    q : float
        White-noise acceleration intensity, m²/s³ (X5; 2 suits walking people).
    r_m : float
        σ of a detection centre, m.
    gate_m : float
        Largest track-to-detection distance of a pair, m.
    n_confirm, n_miss : int
        Frames (of ``frame_s`` seconds) to confirm a candidate and to end a lost track.
    frame_s : float
    candidate_gate_m, candidate_gap_s : float
        As in :class:`~fusiontrack.tracking.tracker.TrackerParams`.
    area_m : rectangle or polygon, optional
        Only used to name births and deaths (``appear``/``disappear`` on the edge).
    d_edge_m : float
    sensor : str
    cls : str
        The class of the states (``person``; the vehicles of :class:`~fusiontrack.tracking.tracker.
        LaserPeopleTracker`: ``unknown`` until a classifier gives them theirs).
    ids : iterator of int, optional
        Where new track ids come from (default: 1, 2, ...); :class:`~fusiontrack.tracking.tracker.
        LaserPeopleTracker` passes its own, so that its vehicles and people share one id space.
    """

    def __init__(self, *, q: float = 2.0, r_m: float = 0.05, gate_m: float = 0.8, n_confirm: int = 3,
                 n_miss: int = 25, frame_s: float = 0.04, candidate_gate_m: float = 0.5, candidate_gap_s: float = 0.25,
                 area_m: Any = None, d_edge_m: float = 0.5, sensor: str = "laser", cls: str = "person",
                 ids: Iterator[int] | None = None) -> None:
        for name, v in (("q", q), ("r_m", r_m), ("gate_m", gate_m), ("frame_s", frame_s),
                        ("candidate_gate_m", candidate_gate_m), ("candidate_gap_s", candidate_gap_s)):
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"CVKalmanTracker {name}: expected a finite value > 0, got {v!r}")
        for name, v in (("n_confirm", n_confirm), ("n_miss", n_miss)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"CVKalmanTracker {name}: expected an integer >= 1, got {v!r}")
        self.q, self.r_m, self.gate_m = float(q), float(r_m), float(gate_m)
        self.n_confirm, self.n_miss, self.frame_s = n_confirm, n_miss, float(frame_s)
        self.area_m = area_polygon(area_m)
        self.d_edge_m = float(d_edge_m)
        self.sensor = str(sensor)
        self.cls = str(ObjectClass(cls))
        self.events: list[Event] = []
        self.dropped_steps = 0
        self._next_id = itertools.count(1) if ids is None else ids
        self._t: int | None = None
        self._x = np.zeros((0, 4))
        self._P = np.zeros((0, 4, 4))
        self._id = np.zeros(0, np.int64)
        self._seen = np.zeros(0, np.int64)
        self._cand = CandidateSet(candidate_gate_m, candidate_gap_s)

    @property
    def n_tracks(self) -> int:
        """Live tracks (confirmed, not ended)."""
        return int(self._id.size)

    @property
    def idle(self) -> bool:
        """No track and no candidate: a step without detections would change nothing."""
        return self._id.size == 0 and len(self._cand) == 0

    def _edge(self, points: np.ndarray) -> np.ndarray:
        if self.area_m is None or points.shape[0] == 0:
            return np.zeros(points.shape[0], bool)
        return on_edge(points, self.area_m, self.d_edge_m)

    def step(self, t_ns: int, detections: Sequence[Detection]) -> list[TrackState]:
        """Advance to ``t_ns`` with the detections of that instant; one state per confirmed track."""
        t_ns = int(t_ns)
        self.events = []
        if self._t is not None and t_ns <= self._t:
            self.dropped_steps += 1
            return []
        dt = 0.0 if self._t is None else min((t_ns - self._t) / 1e9, 0.5)
        self._t = t_ns
        z = np.array([d.position_m for d in detections], dtype=np.float64).reshape(-1, 2)
        n, k = self._id.size, z.shape[0]
        if n and dt > 0:
            F, Q = kalman.cv_matrices(dt, self.q)
            self._x, self._P = kalman.predict(self._x, self._P, F, Q)
        taken = np.zeros(k, bool)
        meas = np.full((n, 2), np.nan)
        seen, none = (self.sensor,), ()
        # what confirmed each detection: the scanners whose points it holds (a laser detector's "scanners"), else
        # this tracker's sensor
        by = [seen if (sc := d.features.get("scanners")) is None or not sc.size
              else tuple(map(str, sc.reshape(-1).tolist())) for d in detections]
        seen_by = [none] * n
        if n and k:
            cost = np.linalg.norm(self._x[:, None, 0:2] - z[None, :, :], axis=2)
            pairs, _, _ = hungarian(cost, gate=self.gate_m)
            meas[pairs[:, 0]] = z[pairs[:, 1]]
            taken[pairs[:, 1]] = True
            for i, j in pairs.tolist():
                seen_by[i] = by[j]
        updated = ~np.isnan(meas[:, 0])
        if updated.any():
            self._x, self._P = kalman.update(self._x, self._P, meas, R=self.r_m**2)
            self._seen[updated] = t_ns
        frame_ns = self.frame_s * 1e9
        dead = (t_ns - self._seen) > round(self.n_miss * frame_ns)
        states = [_fast_state(t_ns, self.sensor, int(self._id[i]), self._x[i, 0:2], self._x[i, 2:4], _NONCORRELATED,
                              seen_by[i], self._P[i], cls=self.cls)
                  for i in np.flatnonzero(~dead)]
        if dead.any():
            edge = self._edge(self._x[dead, 0:2])
            for i, e in zip(np.flatnonzero(dead), edge, strict=True):
                self.events.append(Event(int(self._seen[i]), self.sensor, "disappear" if e else "lost", t_ns,
                                         position_m=self._x[i, 0:2].copy(), track_ids=(int(self._id[i]),)))
            keep = ~dead
            self._x, self._P, self._id, self._seen = self._x[keep], self._P[keep], self._id[keep], self._seen[keep]
        free = np.flatnonzero(~taken)
        self._cand.update(t_ns, z[free], self._edge(z[free]))
        need = round((self.n_confirm - 1) * frame_ns)
        ready = self._cand.ready(t_ns, need, need)
        if ready.size:
            cd = self._cand
            for c in ready:
                tid = next(self._next_id)
                span = max((t_ns - int(cd.first_t[c])) / 1e9, 1e-3)
                v0 = (cd.pos[c] - cd.first_pos[c]) / span
                x0 = np.concatenate([cd.pos[c], v0])
                r2 = self.r_m**2
                P0 = np.diag([r2, r2, 0.5**2, 0.5**2])
                self._x = np.concatenate([self._x, x0[None]])
                self._P = np.concatenate([self._P, P0[None]])
                self._id = np.append(self._id, tid)
                self._seen = np.append(self._seen, t_ns)
                self.events.append(Event(int(cd.first_t[c]), self.sensor, "appear" if cd.edge[c] else "born", t_ns,
                                         position_m=cd.first_pos[c].copy(), track_ids=(tid,)))
                states.append(TrackState(t_ns, self.sensor, tid, x0[0:2], x0[2:4], covariance=P0, cls=self.cls,
                                         situation=Situation.NONCORRELATED, sensors=by[int(free[cd.det[c]])]))
            self._cand.pop(ready)
        return states

    def finish(self) -> list[Event]:
        """Nothing is left open at the end of a run (interface parity with the PF tracker)."""
        return []
