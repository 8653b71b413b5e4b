"""Scoring vehicle tracks (seed 003): ground truth restricted to vehicles in the monitored area, sampled at the
tracker's instants, and identity kept through occlusions.

A traffic tracker reports at its own rate (the pipeline's ``rate_hz``), the simulator's truth comes at
``ground_truth_hz``; :func:`truth_at` picks, for every tracker instant, the nearest truth frame, so each scored frame
has track states within half a tracker period. Vehicles are matched within ``threshold_m`` (2 m: half a car's
length; a footprint-centre error of a partly seen car can reach 1 m).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from matplotlib.path import Path as _MplPath

from ..types import GroundTruth, TrackState
from .mot import Metrics, evaluate_floor
from .mot import truth_at as _frames_at

__all__ = ["VEHICLE_CLASSES", "evaluate_vehicles", "identity_kept", "truth_at"]

VEHICLE_CLASSES = ("car", "bicycle")
_ANY_DISTANCE_NS = 2**62  # the nearest frame, however far


def _inside(area: Any, xy: np.ndarray) -> np.ndarray:
    if area is None:
        return np.ones(xy.shape[0], bool)
    return _MplPath(np.asarray(area, np.float64).reshape(-1, 2)).contains_points(xy.reshape(-1, 2))


def _edge_distance(area: Any, xy: np.ndarray) -> np.ndarray:
    """Distance of each point to the polygon's boundary, ``(n,)``."""
    a = np.asarray(area, np.float64).reshape(-1, 2)
    b = np.roll(a, -1, axis=0)
    d = b - a
    t = np.clip(np.einsum("nek,ek->ne", xy[:, None] - a[None], d) / np.maximum((d * d).sum(1), 1e-12), 0, 1)
    return np.linalg.norm(xy[:, None] - (a[None] + t[..., None] * d[None]), axis=2).min(axis=1)


def truth_at(frames: Sequence[GroundTruth], times_ns: Iterable[int], *, area: Any = None,
             classes: Sequence[str] = VEHICLE_CLASSES) -> list[GroundTruth]:
    """For each distinct instant, the nearest truth frame (:func:`fusiontrack.eval.truth_at`, however far), keeping
    the objects of ``classes`` inside ``area``."""
    if not frames:
        return []
    out = []
    for g in _frames_at(frames, times_ns, tolerance_ns=_ANY_DISTANCE_NS):
        keep = np.isin(np.array(g.classes), list(classes)) & _inside(area, g.positions_m)
        out.append(GroundTruth(g.t_ns, g.sensor, g.frame_id, g.ids[keep], g.positions_m[keep],
                               g.velocities_mps[keep], tuple(np.array(g.classes)[keep]),
                               {a: v[keep] for a, v in g.attributes.items()}))
    return out


def evaluate_vehicles(frames: Sequence[GroundTruth], states: Sequence[TrackState], *, area: Any = None,
                      threshold_m: float = 2.0, margin_m: float = 2.0, rate_hz: float | None = None) -> Metrics:
    """CLEAR MOT / identity / HOTA of vehicle tracks inside ``area`` (tracks within ``margin_m`` of it kept).

    Truth frames are those nearest the tracker's instants (:func:`truth_at`) — every instant of its clock over
    the truth's span, reported or not; the time tolerance is half the tracker period (from ``rate_hz``, else from
    the states' own instants).
    """
    frames = sorted(frames, key=lambda g: g.t_ns)
    times = np.unique(np.array([s.t_ns for s in states], np.int64))
    own = float(np.median(np.diff(times))) if times.size > 1 else 1e8
    period = 1e9 / rate_hz if rate_hz else own
    if frames:
        # every instant of the tracker's clock over the truth's span, not only those with states: instants where
        # the tracker reported nothing still have vehicles to miss (FN)
        phase = int(times[0]) if times.size else frames[0].t_ns
        n0 = int(np.ceil((frames[0].t_ns - phase) / period))
        n1 = int(np.floor((frames[-1].t_ns - phase) / period))
        grid = phase + np.round(np.arange(n0, n1 + 1) * period).astype(np.int64)
        times = np.union1d(grid, times)
    gt = truth_at(frames, times, area=area)
    if area is not None and states:
        xy = np.array([s.position_m for s in states])
        keep = _inside(area, xy) | (_edge_distance(area, xy) <= margin_m)
        states = [s for s, k in zip(states, keep, strict=True) if k]
    return evaluate_floor(gt, states, threshold_m=threshold_m, classes=None,
                          time_tolerance_ns=int(period / 2) + 1, name="vehicles")


def identity_kept(states: Sequence[TrackState], truth_xy_before: np.ndarray, t_before_ns: int,
                  truth_xy_after: np.ndarray, t_after_ns: int, *, threshold_m: float = 2.0,
                  tolerance_ns: int = 70_000_000) -> bool | None:
    """Whether the track nearest a vehicle before an occlusion is the one nearest it after.

    ``None`` when no track is within ``threshold_m`` of the vehicle before (nothing to keep); ``False`` when none
    is after, or another one is.
    """
    def nearest(t_ns: int, xy: np.ndarray) -> int | None:
        cand = [s for s in states if abs(s.t_ns - t_ns) <= tolerance_ns]
        if not cand:
            return None
        d = np.array([np.linalg.norm(s.position_m - xy) for s in cand])
        i = int(np.argmin(d))
        return cand[i].track_id if d[i] <= threshold_m else None

    before = nearest(t_before_ns, np.asarray(truth_xy_before, np.float64))
    if before is None:
        return None
    return nearest(t_after_ns, np.asarray(truth_xy_after, np.float64)) == before
