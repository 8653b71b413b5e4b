"""Clusters of a scan's foreground beams for the adaptive bias (seed 000 Eq. 2; ALGORITHMS.md A7, A8, B5).

A8's nearest-neighbour rule, ``||p_i - p_j|| <= C0 + C1 min(r_i, r_j)``, applied to the *foreground* beams of
A7 in beam order, where a background beam between two foreground beams is skipped rather than ending the
cluster: a laser sees the wall between a walker's legs, and plain A8 would cut the walker into two one-leg
clusters, each up to half a stride off the person's axis.

Each cluster is placed on the axis of the legs it shows: the mean of its two feet (B5's split, each foot
weighted equally, so that the leg nearer the laser, which returns more points, does not pull the centre)
moved away from the laser by ``(pi / 4) r_leg``, the mean depth of the visible half of a leg below its axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fusiontrack.laser.clustering import breakpoint_c1, extract_feet

__all__ = ["LEG_SURFACE_FACTOR", "ForegroundClusters", "foreground_clusters"]

LEG_SURFACE_FACTOR = math.pi / 4
"""Mean depth of the visible half of a circle in front of its centre, per unit radius: beams uniform across a
leg of radius ``r`` hit it on average ``(pi / 4) r`` in front of its axis."""


@dataclass(frozen=True, slots=True, eq=False)
class ForegroundClusters:
    """``k`` clusters of one scan's foreground beams, in beam order (sensor frame).

    Attributes
    ----------
    labels : (n_beams,) int64
        Cluster of each beam; -1 for background, invalid beams and dropped (too small) clusters.
    n_points : (k,) int64
    centre_m : (k, 2) float64
        Where the cluster's object stands (see the module docstring), metres.
    width_m : (k,) float64
        Chord from the cluster's first to its last point.
    """

    labels: np.ndarray
    n_points: np.ndarray
    centre_m: np.ndarray
    width_m: np.ndarray

    def __len__(self) -> int:
        return int(self.n_points.size)


def foreground_clusters(ranges_m: Any, angle_min_rad: float, angle_increment_rad: float, foreground: Any, *,
                        c0_m: float = 0.3, n_min: int = 2, centre: str = "feet", leg_radius_m: float = 0.06,
                        skip_gaps: bool = True) -> ForegroundClusters:
    """A8 clustering of the foreground beams, background beams skipped (see the module docstring).

    Parameters
    ----------
    ranges_m : (n_beams,) float
        Readings, metres (NaN / inf / <= 0 invalid).
    angle_min_rad, angle_increment_rad : float
        Beam ``i`` points at ``angle_min_rad + i * angle_increment_rad``.
    foreground : (n_beams,) bool
        A7's foreground beams.
    c0_m : float
        A8's ``C0`` (>= 0).
    n_min : int
        Smallest cluster kept (>= 1).
    centre : {"feet", "centroid"}
        Cluster position: the mean of its two feet (B5) or the mean of its points; either is then moved
        ``LEG_SURFACE_FACTOR * leg_radius_m`` away from the laser.
    leg_radius_m : float
        0 = no correction.
    skip_gaps : bool
        Beams not in ``foreground`` between two that are do not end a cluster (True); False is A8 as published
        (a gap ends the cluster), e.g. with ``foreground`` = every valid beam.

    Returns
    -------
    ForegroundClusters
    """
    r = np.asarray(ranges_m, dtype=np.float64).reshape(-1)
    fg = np.asarray(foreground, dtype=bool).reshape(-1)
    if fg.shape != r.shape:
        raise ValueError(f"foreground: expected {r.size} flags (one per beam), got {fg.size}")
    if not (math.isfinite(c0_m) and c0_m >= 0):
        raise ValueError(f"c0_m: expected a finite distance >= 0, got {c0_m}")
    if isinstance(n_min, bool) or not isinstance(n_min, int | np.integer) or n_min < 1:
        raise ValueError(f"n_min: expected an integer >= 1, got {n_min!r}")
    if centre not in ("feet", "centroid"):
        raise ValueError(f"centre: expected 'feet' or 'centroid', got {centre!r}")
    if not (math.isfinite(angle_increment_rad) and angle_increment_rad != 0 and math.isfinite(angle_min_rad)):
        raise ValueError(f"angle_min_rad, angle_increment_rad: expected finite angles, the increment non-zero, "
                         f"got {angle_min_rad}, {angle_increment_rad}")
    with np.errstate(invalid="ignore"):
        idx = np.flatnonzero(fg & np.isfinite(r) & (r > 0))
    rv = r[idx]
    a = angle_min_rad + idx * float(angle_increment_rad)
    p = np.column_stack([rv * np.cos(a), rv * np.sin(a)])
    th = c0_m + breakpoint_c1(angle_increment_rad) * np.minimum(rv[:-1], rv[1:])
    starts = np.ones(idx.size, dtype=bool)
    starts[1:] = np.hypot(*np.diff(p, axis=0).T) > th
    if not skip_gaps:
        starts[1:] |= np.diff(idx) != 1
    cid = np.cumsum(starts) - 1
    size = np.bincount(cid) if idx.size else np.zeros(0, np.int64)
    keep = size >= n_min
    new_id = np.where(keep, np.cumsum(keep) - 1, -1)
    lab = new_id[cid] if idx.size else np.zeros(0, np.int64)
    labels = np.full(r.size, -1, dtype=np.int64)
    labels[idx] = lab
    k = int(keep.sum())
    on = lab >= 0
    q, lq = p[on], lab[on]
    if k == 0:
        return ForegroundClusters(labels, np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0))
    n_pts = np.bincount(lq, minlength=k)
    first = np.cumsum(n_pts) - n_pts  # clusters are runs of the kept points, in order
    width = np.hypot(*(q[first + n_pts - 1] - q[first]).T)
    if centre == "feet":
        c = extract_feet(q, lq, k, d_one_foot_m=0.0, min_foot_points=1).feet_m.mean(axis=1)
    else:
        c = np.column_stack([np.bincount(lq, q[:, 0], k), np.bincount(lq, q[:, 1], k)]) / n_pts[:, None]
    c = c + (LEG_SURFACE_FACTOR * leg_radius_m) * c / np.maximum(np.hypot(c[:, :1], c[:, 1:]), 1e-9)
    return ForegroundClusters(labels, n_pts.astype(np.int64), c, width)
