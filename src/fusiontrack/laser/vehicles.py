"""Vehicles from roadside 2-D lasers: background, road ROI, clusters, oriented boxes, per-laser tracks (seed 003).

The laser branch of seed 003's traffic monitoring (ALGORITHMS.md D4), per scanner and per scan:

1. **background** — :class:`~fusiontrack.laser.background.BeamBackground` (A7, initialised by B3's histogram
   mode); a beam is moving when it reads more than ``tau_fg_m`` = 0.3 m nearer than its background. A beam
   without a return counts as free up to ``range_max`` for the background, so passing vehicles cannot drag a
   "no return" background down (the background never learns from invalid readings); ``alpha`` = 0.002, D3's
   traffic rate, so a stopped car stays foreground for a minute or more;
2. **ROI** — moving beams whose road-frame point lies outside the road polygons grown by ``margin_m`` (3 m,
   so a vehicle leaving the road is still seen) are dropped (:class:`RoadROI`);
3. **segmentation** — A8 range-adaptive breakpoint clustering in beam order with ``C0 = 0.5 m``
   (:func:`~fusiontrack.laser.clustering.cluster_scan`), with adjacent clusters joined across a side seen at
   a grazing angle (:func:`segment_scan`); clusters of fewer than ``min_points`` points go;
4. **modelling** — :func:`fit_boxes`: an oriented rectangle per cluster by an L-shape search over the
   orientations ``0, 1, ..., 89°`` (refined on a 0.05° grid around the best), minimising the squared distance
   of every point to the nearer of the two box sides that face the sensor, vectorised over angles x points
   (all clusters at once). :func:`box_heading` picks the length axis (a side longer than ``long_side_m`` is a
   length; otherwise the track's velocity, its last heading or the road direction decides) and
   :func:`classify_extents` the class from the seen extents. :func:`complete_boxes` fills the dimensions the
   laser cannot see from the class prior (:data:`DEFAULT_PRIORS`: car 4.5 x 1.8 m) — or, once a track has
   seen its vehicle's side whole, from that size — and moves the centre *away from the sensor*, so the seen
   sides stay where they were measured; an end of the cluster hidden by a nearer object is not trusted as
   the vehicle's end;
5. **tracking** — a constant-velocity Kalman filter per track (X5, ``q`` = 1 m²/s³, ``R`` = the detection's
   covariance) with Hungarian association on centre distance, gate 2 m (X2). Each detection carries its
   track's id and, once the track's velocity is known to 0.5 m/s, its velocity; the track also votes on the
   class (a car seen end-on looks like a fragment for a while, a bicycle never looks like a car), keeps the
   direction of travel (velocity, or the displacement over each metre travelled) that signs the heading, and
   joins a cluster split off its vehicle by an occluder back to it.

Output: one :class:`~fusiontrack.types.Detection` per kept cluster in the ROAD frame, with ``position_m`` = the
estimated footprint centre, an honest ``covariance_m2`` (range noise, fit residual, beam spacing and the spread
of the prior dimension when a side is unseen), ``cls``, ``class_probs`` (the track's votes), ``score`` and the
features ``"box"`` (cx, cy, length, width, heading), ``"track_id"`` (1,) int64, ``"velocity_mps"`` (2,) (when
known), ``"points_m"`` (k, 2), ``"extent_m"`` (2,) the seen extent along (length, width), ``"from_prior"`` (2,)
bool (that dimension came from the prior).

Heading: the angle of the length axis, signed by the direction of travel; before that is known it is only
defined modulo π and reported in (-π/2, π/2].

Limits: no motion compensation within a sweep; a vehicle standing still is absorbed by the background after
``ln(tau_fg_m / d) / ln(1 - alpha)`` scans (≈ 47 s at 25 Hz for a car 3 m in front of a wall, ≈ 75 s 14 m in
front of open space); two vehicles touching in the scan are one cluster.
"""

from __future__ import annotations

import functools
import json
import logging
import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fusiontrack.errors import ConfigError
from fusiontrack.laser.background import (
    BeamBackground,
    InitMethod,
    all_initialised,
    keep_primed_backgrounds,
    learn_short_backgrounds,
    switch_geometry,
)
from fusiontrack.laser.clustering import breakpoint_c1, segment_scan
from fusiontrack.laser.detector import planar_pose
from fusiontrack.tracking import kalman
from fusiontrack.tracking.association import hungarian
from fusiontrack.tracking.situations import boundary_distance
from fusiontrack.types import Detection, LaserScan

__all__ = [
    "DEFAULT_PRIORS",
    "BoxFit",
    "ClassPrior",
    "CompletedBoxes",
    "LaserVehicleDetector",
    "RoadROI",
    "box_heading",
    "bridge_dropouts",
    "classify_extents",
    "complete_boxes",
    "fit_boxes",
    "laser_poses_for_recording",
    "road_roi",
    "segment_scan",
    "vehicle_detections_for_recording",
    "vehicle_detector_for_recording",
]

log = logging.getLogger(__name__)

_HALF_PI = 0.5 * math.pi


# --------------------------------------------------------------------------------------------------
# Class priors and classification by size
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ClassPrior:
    """Size prior of one class (ALGORITHMS.md D4: "unseen dimensions default to the class prior").

    Attributes
    ----------
    length_m, width_m : float
        Footprint of the class (reported in the detection's ``"box"`` when a side is unseen).
    profile_length_m, profile_width_m : float
        What the scan plane cuts of it: a car is its footprint; a bicycle shows only its wheels and frame
        (a line on its centre axis; the handlebar is above the scan plane), so its centre is ~4 cm behind
        the seen line, not half its 0.6 m width.
    sigma_length_m, sigma_width_m : float
        Spread of the class's dimensions; half of it is the centre's uncertainty along an unseen dimension.
    """

    length_m: float
    width_m: float
    profile_length_m: float
    profile_width_m: float
    sigma_length_m: float
    sigma_width_m: float

    def __post_init__(self) -> None:
        for name in self.__slots__:
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"ClassPrior.{name}: expected a finite value >= 0 m, got {v}")


DEFAULT_PRIORS: Mapping[str, ClassPrior] = {
    "car": ClassPrior(4.5, 1.8, 4.5, 1.8, 0.25, 0.08),
    "bicycle": ClassPrior(1.8, 0.6, 1.8, 0.08, 0.15, 0.03),
    "person": ClassPrior(0.5, 0.5, 0.3, 0.3, 0.1, 0.1),
    "unknown": ClassPrior(4.5, 1.8, 4.5, 1.8, 1.5, 0.6),
}
"""Class priors (D4: car 4.5 x 1.8 m, bicycle ~1.8 x 0.6 m); the car sigmas cover the simulator's car sizes
(length 4.2–4.9 m, width 1.7–1.9 m). ``"unknown"`` (a small fragment on a road: most often a far car's corner,
sometimes a bicycle end-on) takes the car's profile with sigmas that span a bicycle too."""

_CLASSES = ("unknown", "person", "bicycle", "car")  # by rank: a track takes the highest class seen often enough


def _class_index(extent_m: Any, people: bool = False) -> np.ndarray:
    """:func:`classify_extents` as indices into ``("unknown", "person", "bicycle", "car")``, ``(k,) int64``."""
    e = np.asarray(extent_m, dtype=np.float64).reshape(-1, 2)
    e_len, e_wid = e[:, 0], e[:, 1]
    if people:
        car = (e_len >= CAR_LENGTH_M) | (e_wid >= CAR_WIDTH_M) | ((e_len >= BICYCLE_LENGTH_M) & (e_wid >= PERSON_M))
        bicycle = ~car & (e_len >= BICYCLE_LENGTH_M)
        return np.where(car, 3, np.where(bicycle, 2, 1)).astype(np.int64)
    car = (e_len >= CAR_LENGTH_M) | (e_wid >= THIN_M)
    bicycle = ~car & ((e_len >= BICYCLE_LENGTH_M) | ((e_len >= LINE_M) & (e_wid < BICYCLE_WIDTH_M)))
    return np.where(car, 3, np.where(bicycle, 2, 0)).astype(np.int64)


CAR_LENGTH_M = 2.6
"""A seen side at least this long along the heading is a car's (bicycles are <= 2 m)."""
CAR_WIDTH_M = 1.0
"""With people: a face at least this wide across the heading is a car's."""
BICYCLE_LENGTH_M = 0.9
"""A thin line at least this long along the heading is a bicycle (or a car's partly seen side)."""
THIN_M = 0.25
"""Without people: a face at least this wide across the heading is a car's; a bicycle shows its wheels and frame,
< 0.1 m across, at the scan height."""
BICYCLE_WIDTH_M = 0.1
"""Without people: a straight line (narrower than this) at least ``LINE_M`` long along the heading is a bicycle."""
LINE_M = 0.3
PERSON_M = 0.5
"""With people: an L at least this wide across the heading (and ``BICYCLE_LENGTH_M`` along it) is a car's."""


def classify_extents(extent_m: Any, *, people: bool = False) -> np.ndarray:
    """Class of each cluster from the extent it shows along its (length, width) axes.

    Without people (a road): a car shows a side >= 2.6 m along the heading or a face >= 0.25 m across it (a
    bicycle's wheels and frame are < 0.1 m across); a bicycle a line >= 0.9 m along the heading, or a straight
    one (< 0.1 m across) >= 0.3 m long; anything smaller is ``"unknown"`` (a car's corner far away, or a bicycle
    seen end-on). With people: a car shows a
    side >= 2.6 m, a face >= 1 m across, or an L (>= 0.9 m along and >= 0.5 m across); a bicycle a line >= 0.9 m
    along; anything smaller is a person.

    Parameters
    ----------
    extent_m : (k, 2) float
        Seen extent along the length and the width axis (see :func:`box_heading`), metres.
    people : bool
        Whether people are expected in the scene.

    Returns
    -------
    (k,) str array of ``"car"``, ``"bicycle"``, ``"person"``, ``"unknown"``
    """
    return np.array(_CLASSES)[_class_index(extent_m, people)]


# --------------------------------------------------------------------------------------------------
# Segmentation: A8, with the breakpoint widened at grazing incidence
# --------------------------------------------------------------------------------------------------


# --------------------------------------------------------------------------------------------------
# Box fitting (L-shape search), vectorised over clusters and angles
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class BoxFit:
    """Oriented rectangles fitted to ``k`` point clusters (:func:`fit_boxes`).

    The box of cluster ``j`` has the axes ``a0 = (cos θ, sin θ)`` and ``a1 = (-sin θ, cos θ)``, ``θ =
    angle_rad[j]`` in ``[0, π/2)``; it spans ``lo_m[j, i] <= p · a_i <= hi_m[j, i]`` (the extreme projections
    of its points). Empty clusters are all ``NaN``.

    Attributes
    ----------
    angle_rad : (k,) float64
    lo_m, hi_m : (k, 2) float64
    rms_m : (k,) float64
        Root mean square distance of the points to their nearer fitted side.
    n_points : (k,) int64
    """

    angle_rad: np.ndarray
    lo_m: np.ndarray
    hi_m: np.ndarray
    rms_m: np.ndarray
    n_points: np.ndarray

    def __len__(self) -> int:
        return int(self.angle_rad.size)

    @property
    def axes(self) -> np.ndarray:
        """Unit axes ``(k, 2, 2)``: ``axes[j, i]`` is ``a_i`` of box ``j``."""
        c, s = np.cos(self.angle_rad), np.sin(self.angle_rad)
        return np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], axis=1)

    @property
    def extent_m(self) -> np.ndarray:
        """Side lengths along ``a0`` and ``a1``, ``(k, 2)``."""
        return self.hi_m - self.lo_m

    @property
    def centre_m(self) -> np.ndarray:
        """Centre of the rectangle spanned by the points (no prior), ``(k, 2)``."""
        return np.einsum("kij,ki->kj", self.axes, 0.5 * (self.lo_m + self.hi_m))


@dataclass(frozen=True, slots=True, eq=False)
class _Clusters:
    """The points of ``k`` clusters ready for :func:`_fit`: sorted by cluster and centred on their cluster's mean
    (well-conditioned projections). Built once per labelling and shared by the search and every refit."""

    k: int
    counts: np.ndarray  # (k,) int64 points per cluster
    present: np.ndarray  # (kp,) the clusters with points
    sizes: np.ndarray  # (kp,) int64 their point counts
    cnt: np.ndarray  # (kp,) float64 the same
    starts: np.ndarray  # (kp,) first point of each present cluster
    mean: np.ndarray  # (kp, 2)
    qx: np.ndarray  # (n,) points minus their cluster's mean, contiguous x and y
    qy: np.ndarray
    srel: np.ndarray | None  # (kp, 2) sensor minus cluster mean, or None
    ordered: bool  # the points were given sorted by cluster, none dropped (``starts`` index them as given)


def bridge_dropouts(moving: np.ndarray, invalid: np.ndarray, angle_increment_rad: float, c0_m: float,
                    max_gap: int = 3) -> np.ndarray:
    """Fill, in place, the gaps of at most ``max_gap`` beams between two foreground beams of ``moving`` (ranges, NaN
    elsewhere) where the scan gave no reading (``invalid``: a dropout on a dark or shiny body, NaN, 0, beyond range)
    and the two are within A8's breakpoint of each other across the gap (``C0 + C1 min(r) (gap + 1)``): the gap's
    beams get ranges interpolated between them, so one vehicle stays one cluster [RECON: A8 ends a cluster at an
    invalid beam; on a 20 s road 0.5 % of beams invalid made 251 false laser tracks, 2 % made 1435, fused MOTA 0.71
    -> 0.16; with it 36 and 0.71 (clean: 0.72). On ``benchmarks/traffic.py``'s clean roads (3 x 60 s) laser-only
    gains (MOTA 0.670 -> 0.672, 324 -> 293 false positives) and fusion + PF loses a little (0.783 -> 0.775, IDF1
    0.861 -> 0.849, ID switches 8 -> 10; most likely vehicles close together joined across the "no return" beams
    between them, not traced). A threshold of the gap's chord alone (1.5x, + 0.1 m) kept the 2 % case at 0.59.]
    A gap showing the background (a beam with a reading) is never filled. Returns the filled beams."""
    fg = np.flatnonzero(np.isfinite(moving))
    if fg.size < 2:
        return np.zeros(0, np.int64)
    a, b = fg[:-1], fg[1:]
    gap = b - a - 1
    n_invalid = np.cumsum(np.r_[0, invalid.astype(np.int64)])
    ok = (gap >= 1) & (gap <= max_gap) & (n_invalid[b] - n_invalid[a + 1] == gap)
    if not ok.any():
        return np.zeros(0, np.int64)
    a, b, gap = a[ok], b[ok], gap[ok]
    ra, rb = moving[a], moving[b]
    d2 = ra * ra + rb * rb - 2.0 * ra * rb * np.cos((gap + 1) * angle_increment_rad)
    th = c0_m + breakpoint_c1(angle_increment_rad) * np.minimum(ra, rb) * (gap + 1)
    near = d2 <= th * th
    a, gap, ra, rb = a[near], gap[near], ra[near], rb[near]
    if not a.size:
        return np.zeros(0, np.int64)
    pair = np.repeat(np.arange(a.size), gap)  # the gap's beams, pair by pair
    step = np.arange(pair.size) - np.repeat(np.cumsum(gap) - gap, gap) + 1  # 1 .. gap within each pair
    beams = a[pair] + step
    moving[beams] = ra[pair] + (rb[pair] - ra[pair]) * step / (gap[pair] + 1)
    return beams


def _clusters(p: np.ndarray, lab: np.ndarray, k: int, sensor: np.ndarray | None) -> _Clusters:
    """:class:`_Clusters` of checked points ``(n, 2)`` float64 and labels ``(n,)`` int64 (``< k``)."""
    ok = (lab >= 0) & np.isfinite(p).all(axis=1)
    ordered = bool(ok.all())
    if not ordered:
        p, lab = p[ok], lab[ok]
    if lab.size > 1 and (lab[1:] < lab[:-1]).any():
        order = lab.argsort(kind="stable")
        p, lab = p[order], lab[order]
        ordered = False
    counts = np.bincount(lab, minlength=k)
    present = np.flatnonzero(counts)
    cp = counts[present] if present.size != k else counts
    starts = cp.cumsum() - cp
    cnt = cp.astype(np.float64)
    px, py = p[:, 0], p[:, 1]
    if present.size:
        mx, my = np.add.reduceat(px, starts) / cnt, np.add.reduceat(py, starts) / cnt
    else:
        mx = my = np.zeros(0)
    mean = np.empty((present.size, 2))
    mean[:, 0], mean[:, 1] = mx, my
    return _Clusters(k, counts.astype(np.int64), present, cp, cnt, starts, mean, px - mx.repeat(cp), py - my.repeat(cp),
                     None if sensor is None else sensor - mean, ordered)


@functools.lru_cache(maxsize=16)
def _grid(n_ang: int, step_rad: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The search angles ``(A,)``, their cosines and sines as ``(A, 1)`` columns (the same for every cluster)
    and the refinement offsets ``(41, 1)``; read-only."""
    ang = np.arange(n_ang) * step_rad
    out = (ang, np.cos(ang)[:, None], np.sin(ang)[:, None], np.linspace(-step_rad, step_rad, 41)[:, None])
    for a in out:
        a.setflags(write=False)
    return out


def _side_cost(cl: _Clusters, c: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """L-shape cost of every candidate angle of every cluster.

    Parameters
    ----------
    cl : the clusters; c, s : (A, kp) cosines and sines of the candidate angles per cluster, or (A, 1) when every
    cluster has the same candidates (then each point takes the nearer of all four sides when ``cl.srel`` is None).

    Returns
    -------
    cost : (A, kp) sum of squared distances to the nearer fitted side; lo, hi : (2A, kp) the extreme projections
    on ``a0`` (rows ``0 .. A - 1``) and on ``a1`` (rows ``A .. 2A - 1``).
    """
    sizes, starts = cl.sizes, cl.starts
    n_a = c.shape[0]
    cp, sp = (c, s) if c.shape[1] == 1 else (c.repeat(sizes, axis=1), s.repeat(sizes, axis=1))
    uv = np.empty((2 * n_a, cl.qx.size))  # the projections on a0 (U) over those on a1 (V), (2A, n)
    u, v = uv[:n_a], uv[n_a:]
    np.multiply(cp, cl.qx, out=u)
    u += sp * cl.qy
    np.multiply(cp, cl.qy, out=v)
    v -= sp * cl.qx
    lo, hi = np.minimum.reduceat(uv, starts, axis=1), np.maximum.reduceat(uv, starts, axis=1)
    if cl.srel is None:
        d = np.minimum(uv - lo.repeat(sizes, axis=1), hi.repeat(sizes, axis=1) - uv)
    else:  # the sides the sensor can see: the end of each axis nearer to it
        sx, sy = cl.srel[:, 0], cl.srel[:, 1]
        sens = np.concatenate([c * sx + s * sy, c * sy - s * sx])  # the sensor's projections, (2A, kp)
        d = np.subtract(uv, np.where(np.abs(sens - lo) <= np.abs(sens - hi), lo, hi).repeat(sizes, axis=1), out=uv)
    d *= d
    cost = np.add.reduceat(np.minimum(d[:n_a], d[n_a:]), starts, axis=1)
    return cost, lo, hi


def _fit(cl: _Clusters, n_ang: int, step_rad: float, refine: bool, fixed: np.ndarray | None = None) -> BoxFit:
    """:func:`fit_boxes` of prepared clusters; ``fixed`` (kp,): a known orientation per present cluster, ``NaN``
    where it is to be searched (None: search all)."""
    k, present = cl.k, cl.present
    kp = present.size
    if kp == 0:
        nan2 = np.full((k, 2), np.nan)
        return BoxFit(np.full(k, np.nan), nan2, nan2.copy(), np.full(k, np.nan), cl.counts)
    search = np.ones(kp, bool) if fixed is None else ~np.isfinite(fixed)
    theta = np.full(kp, np.nan) if fixed is None else np.mod(fixed, _HALF_PI)
    done = None  # the cost and extents at theta, when the search already has them
    if search.any():
        ang, cg, sg, offsets = _grid(n_ang, step_rad)
        cost = _side_cost(cl, cg, sg)[0]
        best = ang[cost.argmin(axis=0)]
        if refine:
            fine = best[None, :] + offsets
            cost, lo_a, hi_a = _side_cost(cl, np.cos(fine), np.sin(fine))
            i, cols = cost.argmin(axis=0), np.arange(kp)
            best = fine[i, cols]
            if fixed is None:
                done = cost[i, cols][None, :], lo_a[[i, i + offsets.size], cols], hi_a[[i, i + offsets.size], cols]
        theta = np.mod(best, _HALF_PI)  # a rectangle repeats every 90°
        if fixed is not None:
            theta = np.where(search, theta, np.mod(fixed, _HALF_PI))
        if done is not None and not ((theta == best).all() and not np.signbit(theta).any()):
            done = None  # an angle wrapped around: evaluate it there
    c, s = np.cos(theta), np.sin(theta)
    cost, lo_a, hi_a = done if done is not None else _side_cost(cl, c[None, :], s[None, :])
    mx, my = cl.mean[:, 0], cl.mean[:, 1]
    shift = np.array([c * mx + s * my, c * my - s * mx])
    lo_p, hi_p = (lo_a + shift).T, (hi_a + shift).T
    rms_p = np.sqrt(cost[0] / cl.cnt)
    if kp == k:
        return BoxFit(theta, lo_p, hi_p, rms_p, cl.counts)
    angle, rms = np.full(k, np.nan), np.full(k, np.nan)
    lo, hi = np.full((k, 2), np.nan), np.full((k, 2), np.nan)
    angle[present], lo[present], hi[present], rms[present] = theta, lo_p, hi_p, rms_p
    return BoxFit(angle, lo, hi, rms, cl.counts)


def _step_grid(step_deg: float) -> tuple[int, float]:
    """Number of search angles in 90° and the step in radians; ``ValueError`` unless the step divides 90°."""
    step = float(step_deg)
    n_ang = round(90.0 / step) if math.isfinite(step) and step > 0 else 0
    if not (0 < step <= 45.0 and abs(n_ang * step - 90.0) < 1e-6):
        raise ValueError(f"step_deg: expected a step in (0, 45] degrees that divides 90, got {step_deg}")
    return n_ang, math.radians(step)


def fit_boxes(points_m: Any, labels: Any, sensor_m: Any = None, *, n_clusters: int | None = None,
              step_deg: float = 1.0, refine: bool = True, angle_rad: Any = None) -> BoxFit:
    """Oriented rectangle of every cluster by an L-shape search over orientations (ALGORITHMS.md D4).

    For every candidate orientation ``θ = 0, step, ..., 90° - step`` (a rectangle repeats every 90°) the
    points are projected on the box axes, the box spans their extreme projections, and the cost is the sum
    of squared distances of the points to the nearer of the two sides facing ``sensor_m`` (the sides a laser
    can see: an L, or one side); without a sensor, to the nearest of all four sides. The best orientation is
    refined on a grid of ``step / 20`` within ±``step``. Vectorised over angles x points: one pass for all
    clusters.

    Parameters
    ----------
    points_m : (n, 2) float
        Points of all clusters, metres; rows with a non-finite coordinate are ignored.
    labels : (n,) int
        Cluster of each point, ``0 .. n_clusters - 1``; negative labels are ignored.
    sensor_m : (2,) float, optional
        Sensor position in the points' frame.
    n_clusters : int, optional
        Number of clusters ``k`` (default ``max(labels) + 1``).
    step_deg : float
        Orientation step, degrees (1°); must divide 90°.
    refine : bool
        Refine the best orientation on the finer grid.
    angle_rad : (k,) float, optional
        A known orientation per cluster (e.g. a tracked heading, for a cluster too small to show its own);
        ``NaN`` where it is to be searched.

    Returns
    -------
    BoxFit
    """
    p = np.asarray(points_m, dtype=np.float64)
    if p.size == 0:
        p = p.reshape(0, 2)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points_m: expected an array of shape (n, 2), got {p.shape}")
    lab = np.asarray(labels).reshape(-1)
    if lab.size != p.shape[0]:
        raise ValueError(f"labels: expected {p.shape[0]} labels (one per point), got {lab.size}")
    if lab.size and not np.issubdtype(lab.dtype, np.integer):
        raise ValueError(f"labels: expected integers, got dtype {lab.dtype}")
    lab = lab.astype(np.int64)
    n_ang, step_rad = _step_grid(step_deg)
    k = int(lab.max()) + 1 if n_clusters is None and lab.size else int(n_clusters or 0)
    if lab.size and lab.max() >= k:
        raise ValueError(f"labels: label {int(lab.max())} out of range for n_clusters = {k}")
    sensor = None
    if sensor_m is not None:
        sensor = np.asarray(sensor_m, dtype=np.float64).reshape(-1)
        if sensor.shape != (2,) or not np.all(np.isfinite(sensor)):
            raise ValueError(f"sensor_m: expected a finite (2,) position, got {sensor_m!r}")
    cl = _clusters(p, lab, k, sensor)
    fixed = None if angle_rad is None else np.broadcast_to(np.asarray(angle_rad, dtype=np.float64),
                                                            (k,))[cl.present]
    return _fit(cl, n_ang, step_rad, refine, fixed)


# --------------------------------------------------------------------------------------------------
# Heading and completion with the class prior
# --------------------------------------------------------------------------------------------------


def box_heading(fit: BoxFit, hint_rad: Any = None, signed: Any = False, *,
                long_side_m: float = 2.4) -> tuple[np.ndarray, np.ndarray]:
    """Heading of each fitted box: which axis is the length, and (when known) which way along it.

    The length axis is the axis of a seen side longer than ``long_side_m`` (no vehicle is that wide). When
    both seen sides are shorter (one short face, or a partly occluded vehicle), the axis nearer to
    ``hint_rad`` — the track's velocity, its last heading, or the road direction — and, without a hint, the
    longer seen side.

    Parameters
    ----------
    fit : BoxFit
    hint_rad : (k,) float, optional
        Direction hint per box, ``NaN`` for none.
    signed : (k,) bool or bool
        Whether the hint's sign is meaningful (a velocity or a tracked heading; a road axis is not).
    long_side_m : float

    Returns
    -------
    heading_rad : (k,) float64
        In ``(-π, π]`` where ``signed`` (pointing along the hint), else in ``(-π/2, π/2]``.
    length_axis : (k,) int64
        ``0`` or ``1``: the fit's axis (``a0`` or ``a1``) that is the length.
    """
    k = len(fit)
    e = fit.extent_m
    longer = (e[:, 1] > e[:, 0]).astype(np.int64)
    hint = np.full(k, np.nan) if hint_rad is None else np.broadcast_to(
        np.asarray(hint_rad, dtype=np.float64), (k,))
    sign_ok = np.broadcast_to(np.asarray(signed, dtype=bool), (k,)) & np.isfinite(hint)
    rel = hint - fit.angle_rad
    hint_axis = (np.abs(np.sin(rel)) > np.abs(np.cos(rel))).astype(np.int64)
    with np.errstate(invalid="ignore"):
        clear = np.fmax(e[:, 0], e[:, 1]) > long_side_m
    axis = np.where(clear | ~np.isfinite(hint), longer, hint_axis)
    heading = fit.angle_rad + axis * _HALF_PI
    with np.errstate(invalid="ignore"):
        flip = np.where(sign_ok, np.cos(heading - hint) < 0, heading > _HALF_PI)
    heading = heading - np.where(flip, math.pi, 0.0)
    heading = np.where(heading <= -math.pi, heading + 2 * math.pi, heading)
    return heading, axis


@dataclass(frozen=True, slots=True, eq=False)
class CompletedBoxes:
    """Vehicle boxes completed with the class prior (:func:`complete_boxes`); ``k`` boxes.

    Attributes
    ----------
    centre_m : (k, 2) float64
        Footprint centre (of the scan-plane profile).
    size_m : (k, 2) float64
        Profile size along (length, width): the seen extent, or the prior where that is larger.
    extent_m : (k, 2) float64
        Seen extent along (length, width).
    from_prior : (k, 2) bool
        Where the size came from the prior (the side was unseen or partly seen).
    covariance_m2 : (k, 2, 2) float64
        Covariance of the centre.
    """

    centre_m: np.ndarray
    size_m: np.ndarray
    extent_m: np.ndarray
    from_prior: np.ndarray
    covariance_m2: np.ndarray


def complete_boxes(fit: BoxFit, sensor_m: Any, length_axis: Any, profile_m: Any, *, dims_sigma_m: Any = 0.0,
                   sigma_m: Any = 0.05, quant_m: Any = 0.0, edge_points_m: Any = None,
                   edge_occluded: Any = None, angle_increment_rad: float = 0.0) -> CompletedBoxes:
    """Fill the dimensions a laser does not see from a prior, keeping the seen sides where they were measured.

    Per box axis: the size is ``max(seen extent, prior)``; when it grows, the box grows *away from the
    sensor* — from the seen side nearer the sensor (an L's corner, or the one visible face) — so the centre
    moves away from the sensor. Occlusion can overrule this: when the cluster's first or last point (in beam
    order) has a nearer return beside it, the end of the axis at that point is not the vehicle's end but an
    occluder's edge; if the other end is not occluded, the box grows from that other end instead. When the
    sensor lies within the extent along an axis (it sees one long side) and occlusion does not tell, or when
    both ends are occluded, the box grows equally both ways (and the covariance says so).

    Parameters
    ----------
    fit : BoxFit
    sensor_m : (2,) float
        Sensor position in the fit's frame.
    length_axis : (k,) int
        Which fit axis is the length (:func:`box_heading`).
    profile_m : (2,) or (k, 2) float
        Prior scan-plane profile (length, width) per box (:attr:`ClassPrior.profile_length_m`, ...).
    dims_sigma_m : float, (2,) or (k, 2) float
        Standard deviation of the prior dimensions (length, width).
    sigma_m : float or (k,) float
        Standard deviation of a seen side's position (range noise and fit; X5: 0.05 m for the laser).
    quant_m : float or (k,) float
        Beam spacing at the cluster (range x angle increment): a side's end lies up to one spacing beyond
        its last point (variance ``quant_m² / 12``).
    edge_points_m : (k, 2, 2) float, optional
        The first and the last point of each cluster in beam order.
    edge_occluded : (k, 2) bool, optional
        Whether the beam beside that point reads nearer (or is outside the field of view).
    angle_increment_rad : float
        Beam spacing, for how far beyond a free edge point the vehicle may go unseen.

    Returns
    -------
    CompletedBoxes
    """
    k = len(fit)
    sensor = np.asarray(sensor_m, dtype=np.float64).reshape(-1)
    if sensor.shape != (2,) or not np.all(np.isfinite(sensor)):
        raise ValueError(f"sensor_m: expected a finite (2,) position, got {sensor_m!r}")
    ep = occ = None
    if edge_points_m is not None and edge_occluded is not None:
        ep = np.broadcast_to(np.asarray(edge_points_m, dtype=np.float64), (k, 2, 2))
        occ = np.broadcast_to(np.asarray(edge_occluded, dtype=bool), (k, 2))
    return _complete(_box_frame(fit.angle_rad, fit.lo_m, fit.hi_m, sensor, ep, occ, angle_increment_rad),
                     np.broadcast_to(np.asarray(length_axis, dtype=np.int64), (k,)),
                     np.broadcast_to(np.asarray(profile_m, dtype=np.float64), (k, 2)),
                     np.broadcast_to(np.asarray(dims_sigma_m, dtype=np.float64), (k, 2)),
                     np.broadcast_to(np.asarray(sigma_m, dtype=np.float64), (k,)),
                     np.broadcast_to(np.asarray(quant_m, dtype=np.float64), (k,)))


def _unsigned_heading(angle: np.ndarray, e: np.ndarray, hint: np.ndarray,
                      long_side_m: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`box_heading` without a signed hint, of angles ``(k,)``, extents ``(k, 2)`` and hints ``(k,)``."""
    longer = e[:, 1] > e[:, 0]
    rel = hint - angle
    hint_axis = np.abs(np.sin(rel)) > np.abs(np.cos(rel))
    with np.errstate(invalid="ignore"):
        clear = np.fmax(e[:, 0], e[:, 1]) > long_side_m
    axis = np.where(clear | ~np.isfinite(hint), longer, hint_axis).astype(np.int64)
    heading = angle + axis * _HALF_PI
    with np.errstate(invalid="ignore"):
        heading = heading - np.where(heading > _HALF_PI, math.pi, 0.0)  # in (-π/2, π/2]: no wrap at -π needed
    return heading, axis


def _axes(angle: np.ndarray) -> np.ndarray:
    """Unit axes ``(k, 2, 2)`` of boxes at ``angle`` (:attr:`BoxFit.axes`)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([c, s, -s, c]).T.reshape(-1, 2, 2)


@dataclass(frozen=True, slots=True, eq=False)
class _BoxFrame:
    """What :func:`complete_boxes` takes of the fitted boxes, the sensor and the cluster ends, whatever the prior
    (``(k, 2)`` arrays per fit axis; the occlusion ones ``None`` without edge points)."""

    lo: np.ndarray
    hi: np.ndarray
    axes: np.ndarray  # (k, 2, 2)
    e: np.ndarray  # seen extent
    from_lo: np.ndarray  # the end facing the sensor: grow from lo ...
    from_hi: np.ndarray  # ... or from hi
    hidden_lo: np.ndarray | None  # only the lo end is hidden by an occluder
    hidden_hi: np.ndarray | None
    gap_lo: np.ndarray | None  # how far the vehicle may go on unseen beyond a free lo end
    gap_hi: np.ndarray | None


def _box_frame(angle: np.ndarray, lo: np.ndarray, hi: np.ndarray, sensor: np.ndarray, ep: np.ndarray | None,
               occ: np.ndarray | None, inc: float) -> _BoxFrame:
    """:class:`_BoxFrame` of checked arrays: ``angle`` (k,), ``lo``/``hi`` (k, 2), ``sensor`` (2,), ``ep``
    (k, 2, 2) and ``occ`` (k, 2) or None (see :func:`complete_boxes`)."""
    axes = _axes(angle)
    e = hi - lo
    s = np.einsum("kij,j->ki", axes, sensor)
    below, above = s <= lo, s >= hi
    if ep is None or occ is None or not occ.any():  # no end hidden: nothing for the occlusion rule to do
        return _BoxFrame(lo, hi, axes, e, below, above & ~below, None, None, None, None)
    proj = np.einsum("kia,kja->kij", axes, ep)  # (k, axis, edge point)
    # Along the surface, the next beam passes up to ``gap`` beyond a free edge point: r Δθ / sin(incidence).
    ray = ep - sensor
    rng = np.hypot(ray[..., 0], ray[..., 1])
    # |ray x a_i| = |ray . (the other axis)|: the other axis is ±axes[:, ::-1]
    sin_inc = np.abs(np.einsum("kja,kia->kij", ray, axes[:, ::-1])) / np.maximum(rng[:, None, :], 1e-9)
    gap = rng[:, None, :] * abs(float(inc)) / np.maximum(sin_inc, _SIN_3_DEG)
    # Each edge point ends the seen side it lies on: the side along axis i is the one at the sensor-facing
    # end of the other axis; the point tells about axis i only.
    side = np.where(np.abs(s - lo) <= np.abs(s - hi), lo, hi)  # sensor-facing end of each axis (k, 2)
    off = np.abs(proj - side[:, :, None])  # (k, axis, point): distance to the side across that axis
    tol = 0.1  # a point within tol of both sides (a corner) ends both
    along = (off[:, ::-1] <= np.fmax(off, tol)) & (e > 2 * tol)[:, :, None]
    at_lo = along & (proj - lo[:, :, None] <= tol)
    at_hi = along & (hi[:, :, None] - proj <= tol)
    hidden, free = occ[:, None, :], ~occ[:, None, :]
    occ_lo, occ_hi = (at_lo & hidden).any(axis=2), (at_hi & hidden).any(axis=2)
    return _BoxFrame(lo, hi, axes, e, below, above & ~below, occ_lo & ~occ_hi, occ_hi & ~occ_lo,
                     np.where(at_lo & free, gap, 0.0).max(axis=2), np.where(at_hi & free, gap, 0.0).max(axis=2))


def _complete(fr: _BoxFrame, ax: np.ndarray, prof: np.ndarray, dsig: np.ndarray, sig: np.ndarray,
              quant: np.ndarray, centre_only: bool = False) -> CompletedBoxes | np.ndarray:
    """:func:`complete_boxes` of a :class:`_BoxFrame` and checked arrays: ``ax`` (k,) int, ``prof``/``dsig``
    (k, 2), ``sig``/``quant`` (k,); only the centres ``(k, 2)`` when ``centre_only``."""
    lo, hi, e, axes = fr.lo, fr.hi, fr.e, fr.axes
    swap = (ax == 1)[:, None]
    prof_f = np.where(swap, prof[:, ::-1], prof)  # along the fit's axes (a0, a1)
    size = np.fmax(e, prof_f)
    grow = size - e
    from_lo, from_hi = fr.from_lo, fr.from_hi  # default: grow from the end that faces the sensor
    new_lo = np.where(from_lo, lo, np.where(from_hi, hi - size, lo - 0.5 * grow))
    if fr.hidden_lo is not None:
        # One end hidden by an occluder, the other a free end: trust the free end when the vehicle can end at
        # most ``gap`` beyond it, less than the size still missing (else the occluded end is the better guess).
        use_hi = fr.hidden_lo & (fr.gap_hi < grow)
        use_lo = fr.hidden_hi & (fr.gap_lo < grow)
        new_lo = np.where(use_hi, hi + np.minimum(0.5 * fr.gap_hi, grow) - size,
                          np.where(use_lo, lo - np.minimum(0.5 * fr.gap_lo, grow), new_lo))
        from_lo, from_hi = from_lo | use_lo, from_hi | use_hi
    centre = np.einsum("kij,ki->kj", axes, new_lo + 0.5 * size)
    if centre_only:
        return centre
    dsig_f = np.where(swap, dsig[:, ::-1], dsig)
    from_prior = grow > 1e-9
    ambiguous = from_prior & ~from_lo & ~from_hi
    var = (sig[:, None] ** 2 + quant[:, None] ** 2 / 12.0 + np.where(from_prior, (0.5 * dsig_f) ** 2, 0.0)
           + np.where(ambiguous, (0.5 * grow) ** 2 / 3.0, 0.0))
    cov = np.einsum("kia,ki,kib->kab", axes, var, axes)
    return CompletedBoxes(centre, np.where(swap, size[:, ::-1], size), np.where(swap, e[:, ::-1], e),
                          np.where(swap, from_prior[:, ::-1], from_prior), cov)


_SIN_3_DEG = math.sin(math.radians(3.0))
_STEP_OUT = np.array([-1, 1])  # the beams before a cluster's first point and after its last
_STEP_OUT.setflags(write=False)


# --------------------------------------------------------------------------------------------------
# Road region of interest
# --------------------------------------------------------------------------------------------------


class RoadROI:
    """The road polygons in the road frame, grown by a margin; membership and road direction of points.

    Parameters
    ----------
    polygons : sequence of (m >= 3, 2) float
        Road polygons (vertices in order), road frame.
    margin_m : float
        A point within ``margin_m`` outside a polygon is still in the ROI (3 m: a vehicle leaving the road).
    directions_rad : sequence of float, optional
        Driving axis of each polygon; default its principal axis (the major axis of its vertices).
    """

    def __init__(self, polygons: Sequence[Any], margin_m: float = 3.0,
                 directions_rad: Sequence[float] | None = None) -> None:
        polys = []
        for i, poly in enumerate(polygons):
            a = np.asarray(poly, dtype=np.float64)
            if a.ndim != 2 or a.shape[1] != 2 or a.shape[0] < 3 or not np.all(np.isfinite(a)):
                raise ConfigError(f"road polygon {i}: expected finite vertices of shape (m >= 3, 2), got "
                                  f"{a.shape}")
            polys.append(a)
        if not polys:
            raise ConfigError("roads: expected at least one road polygon")
        self.margin_m = float(margin_m)
        if not (math.isfinite(self.margin_m) and self.margin_m >= 0):
            raise ConfigError(f"margin_m: expected a finite margin >= 0 m, got {margin_m}")
        self.polygons = tuple(polys)
        if directions_rad is None:
            dirs = []
            for a in polys:
                d = a - a.mean(axis=0)
                _, _, vt = np.linalg.svd(d, full_matrices=False)
                dirs.append(math.atan2(vt[0, 1], vt[0, 0]))
            directions_rad = dirs
        self.directions_rad = np.asarray(directions_rad, dtype=np.float64).reshape(-1)
        if self.directions_rad.size != len(polys) or not np.all(np.isfinite(self.directions_rad)):
            raise ConfigError(f"directions_rad: expected {len(polys)} finite angles, got {directions_rad!r}")
        self._rects = _rectangles(polys)

    @classmethod
    def from_roads(cls, roads: Any, margin_m: float = 3.0) -> RoadROI:
        """From straight roads ``(x0, y0, x1, y1, width_m)`` (the simulator's ``world.json`` ``"roads"``)."""
        r = np.asarray(roads, dtype=np.float64)
        if r.ndim == 1 and r.size == 5:
            r = r[None]
        if r.ndim != 2 or r.shape[1] != 5 or r.shape[0] == 0 or not np.all(np.isfinite(r)):
            raise ConfigError(f"roads: expected rows (x0, y0, x1, y1, width_m), got shape {r.shape}")
        d = r[:, 2:4] - r[:, 0:2]
        length = np.hypot(d[:, 0], d[:, 1])
        if np.any(length <= 0) or np.any(r[:, 4] <= 0):
            raise ConfigError("roads: every road needs two distinct end points and a positive width")
        t = d / length[:, None]
        n = np.column_stack([-t[:, 1], t[:, 0]]) * (0.5 * r[:, 4:5])
        polys = [np.array([a - m, b - m, b + m, a + m]) for a, b, m in zip(r[:, 0:2], r[:, 2:4], n, strict=True)]
        return cls(polys, margin_m, np.arctan2(t[:, 1], t[:, 0]))

    def contains(self, points_m: Any) -> np.ndarray:
        """Whether each point is inside a road polygon or within ``margin_m`` of one, ``(n,) bool``."""
        return self._signed(points_m).max(axis=0) > -self.margin_m

    def direction_at(self, points_m: Any) -> np.ndarray:
        """Driving axis (radians, modulo π) of the road nearest to each point, ``(n,)``."""
        if len(self.polygons) == 1:  # the only road is the nearest
            return np.full(np.asarray(points_m).reshape(-1, 2).shape[0], self.directions_rad[0])
        return self.directions_rad[np.argmax(self._signed(points_m), axis=0)]

    def _signed(self, points_m: Any) -> np.ndarray:
        """Signed distance ``(polygons, n)`` of each point to each polygon's boundary, positive inside: the
        rectangles (every road of :meth:`from_roads`) all at once in their own frames, other polygons by
        :func:`~fusiontrack.tracking.situations.boundary_distance`."""
        p = np.asarray(points_m, dtype=np.float64).reshape(-1, 2)
        if p.shape[0] == 0:
            return np.zeros((len(self.polygons), 0))
        if self._rects is not None:
            centre, axes, half = self._rects
            local = np.abs(np.einsum("rij,rnj->rni", axes, p[None] - centre[:, None]))  # (r, n, 2)
            gap = local - half[:, None]
            out = np.hypot(np.maximum(gap[..., 0], 0.0), np.maximum(gap[..., 1], 0.0))
            inner = gap.max(axis=2)
            with np.errstate(invalid="ignore"):
                return np.where(inner < 0, -inner, -out)
        return np.stack([boundary_distance(p, a) for a in self.polygons])


def _rectangles(polygons: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Centres ``(r, 2)``, unit axes ``(r, 2, 2)`` (rows) and half extents ``(r, 2)`` when every polygon is a
    rectangle (four vertices, right angles, opposite sides equal), else ``None``."""
    centres, axes, halves = [], [], []
    for a in polygons:
        if a.shape[0] != 4:
            return None
        e = np.roll(a, -1, axis=0) - a
        length = np.hypot(e[:, 0], e[:, 1])
        scale = max(float(length.max()), 1e-12)
        if (length.min() <= 1e-9 * scale or abs(float(e[0] @ e[1])) > 1e-9 * scale**2
                or np.abs(e[0] + e[2]).max() > 1e-9 * scale or np.abs(e[1] + e[3]).max() > 1e-9 * scale):
            return None
        centres.append(a.mean(axis=0))
        axes.append(e[:2] / length[:2, None])
        halves.append(length[:2] / 2)
    return np.array(centres), np.array(axes), np.array(halves)


def road_roi(roads: Any, margin_m: float = 3.0) -> RoadROI | None:
    """A :class:`RoadROI` from any of the ways roads are given.

    Parameters
    ----------
    roads : None, RoadROI, (n, 5) rows ``(x0, y0, x1, y1, width_m)``, sequence of (m, 2) polygons, a mapping with
        a ``"roads"`` entry (the simulator's ``world.json``), or the path of such a JSON file.
        ``None``: no ROI (every moving cluster is kept, no road direction).
    margin_m : float
    """
    if roads is None or isinstance(roads, RoadROI):
        return roads
    if isinstance(roads, str | Path):
        path = Path(roads)
        try:
            roads = json.loads(path.read_text())
        except (OSError, ValueError) as err:
            raise ConfigError(f"{path}: cannot read the roads ({err})") from err
        if not isinstance(roads, Mapping):
            raise ConfigError(f"{path}: expected a JSON object with a 'roads' entry")
    if isinstance(roads, Mapping):
        if "roads" not in roads:
            raise ConfigError(f"roads: the mapping has no 'roads' entry (keys: {sorted(roads)})")
        return RoadROI.from_roads(roads["roads"], margin_m)
    try:
        arr = np.asarray(roads, dtype=np.float64)
    except (TypeError, ValueError):
        arr = None  # ragged: polygons of different vertex counts
    if arr is not None and arr.ndim == 2 and arr.shape[1] == 5:
        return RoadROI.from_roads(arr, margin_m)
    if arr is not None and arr.ndim == 1 and arr.size == 5:
        return RoadROI.from_roads(arr, margin_m)
    if arr is not None and arr.ndim == 2 and arr.shape[1] == 2:
        return RoadROI([arr], margin_m)
    return RoadROI(list(roads), margin_m)


# --------------------------------------------------------------------------------------------------
# The detector: per-laser background, segmentation, boxes and tracks
# --------------------------------------------------------------------------------------------------


class _Laser:
    """Mutable per-scanner state: background, tracks (the detector's, not shared)."""

    __slots__ = (
        "P",
        "background",
        "dims",
        "heading",
        "hits",
        "ids",
        "last_ns",
        "origin",
        "primed_ns",
        "rotation",
        "t_ns",
        "translation",
        "votes",
        "x",
    )

    def __init__(self, rotation: np.ndarray, translation: np.ndarray) -> None:
        self.rotation = rotation
        self.translation = translation
        self.background: BeamBackground | None = None
        self.t_ns: int | None = None
        self.primed_ns: int | None = None  # scans up to this time taught the background already (prime)
        self.x = np.zeros((0, 4))
        self.P = np.zeros((0, 4, 4))
        self.ids = np.zeros(0, np.int64)
        self.last_ns = np.zeros(0, np.int64)
        self.hits = np.zeros(0, np.int64)
        self.votes = np.zeros((0, len(_CLASSES)), np.int64)
        self.heading = np.zeros(0)  # last signed heading, NaN until the direction of travel is known
        self.dims = np.zeros((0, 2))  # largest plausible (length, width) seen, NaN until seen
        self.origin = np.zeros((0, 2))  # where the direction of travel was last measured

    def keep(self, mask: np.ndarray) -> None:
        if mask.all():
            return
        for name in ("x", "P", "ids", "last_ns", "hits", "votes", "heading", "dims", "origin"):
            setattr(self, name, getattr(self, name)[mask])


def _positive(value: float, name: str, allow_zero: bool = False) -> float:
    v = float(value)
    if not (math.isfinite(v) and (v >= 0 if allow_zero else v > 0)):
        raise ConfigError(f"{name}: expected a finite value {'>=' if allow_zero else '>'} 0, got {value!r}")
    return v


def _count(value: int, name: str, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        raise ConfigError(f"{name}: expected an integer >= {low}, got {value!r}")
    return int(value)


class LaserVehicleDetector:
    """Vehicle detections with per-laser tracks from roadside 2-D lasers (seed 003; ALGORITHMS.md D4).

    Call it with each scan (any of its scanners, time-ordered per scanner); it returns that scan's detections
    in the road frame (module docstring for the steps and the features).

    Parameters
    ----------
    scanners : mapping of sensor name -> laser2road
        ``scan.sensor`` of each scanner and its pose in the road frame: a ``(3, 3)`` 2-D pose or a ``(4, 4)``
        rigid transform.
    roads : see :func:`road_roi`
        The road polygons (road frame), or ``None`` for no ROI.
    margin_m : float
        ROI margin around the roads (3 m).
    alpha : float
        Background learning rate of a moving beam: 0.002, D3's traffic rate (A7's 0.005 is for people), so a
        stopped car ~14 m in front of open space stays foreground for ~75 s at 25 Hz.
    beta, gamma, n_init, init, bin_m :
        Background model (:class:`~fusiontrack.laser.background.BeamBackground`; A7 defaults). A beam without
        a return counts as free up to ``range_max`` for the background (see ``_free_as_far``).
    tau_fg_m : float
        A beam is moving when ``|r - B| > tau_fg_m`` nearer than the background (D4: 0.3 m).
    c0_m : float
        A8 breakpoint constant (D4: 0.5 m for vehicles).
    grazing_deg : float or None
        Adjacent clusters are joined across a sparse side seen down to this incidence angle (10°,
        :func:`segment_scan`); ``None``: A8 alone.
    min_points : int
        Clusters with fewer points are dropped (3).
    step_deg : float
        Orientation step of the box search (1°).
    min_fit_extent_m : float
        A cluster whose fitted box is smaller than this both ways (a few points of a far or occluded vehicle)
        takes its orientation from the track (or the road) instead of its own fit (1 m).
    long_side_m : float
        A seen side longer than this is a vehicle's length side (2.4 m).
    max_rms_m : float
        A track learns its vehicle's size (the largest seen, which then replaces the class prior) only from
        clusters whose points lie within this RMS distance of the fitted sides (0.1 m): a bicycle or a
        pedestrian joined to a car's cluster is not part of the car.
    priors : mapping of class -> ClassPrior
        Needs ``"car"``, ``"bicycle"``, ``"person"`` and ``"unknown"`` (default :data:`DEFAULT_PRIORS`).
    sigma_m : float
        Standard deviation of a seen side (0.05 m, X5's laser ``R``).
    q : float
        Kalman acceleration noise intensity, m²/s³ (X5 vehicles: 1).
    gate_m : float
        Largest track-to-detection centre distance of a pair (D4: 2 m).
    merge_m : float
        Of two tracks closer than this (1 m: two vehicles never are), the one with fewer updates is deleted; a
        cluster left unpaired whose box centre is this close to a track that another cluster was paired with is
        a piece of that vehicle (split by an occluder) and is joined to that cluster.
    max_coast_s : float
        A track without a detection for longer is deleted (3 s: occlusion by vehicles in a nearer lane).
    min_hits_velocity : int, max_velocity_sigma_mps : float
        A track reports ``"velocity_mps"`` once it has at least ``min_hits_velocity`` updates (3) and its
        velocity's standard deviation is at most ``max_velocity_sigma_mps`` (0.5 m/s). Its velocity orients
        the boxes when its direction is known to 3°.
    heading_speed_mps : float
        Tracks slower than this (or than 3 sigma of their velocity) keep their last direction of travel instead
        of the velocity's (0.5 m/s).
    sign_travel_m : float
        Every time a track has travelled this far (1 m), its direction of travel is set from the displacement.
    class_votes : int
        A track is of the highest class (car > bicycle > person > unknown) it was seen as at least this often (2).
    people : bool
        Whether small clusters are people (:func:`classify_extents`); by default (a road) they are ``"unknown"``
        fragments completed with the ``"unknown"`` prior.
    """

    def __init__(self, scanners: Mapping[str, Any], roads: Any = None, *, margin_m: float = 3.0,
                 alpha: float = 0.002, beta: float = 0.05, gamma: float | None = None, tau_fg_m: float = 0.3,
                 n_init: int = 50, init: InitMethod = "mode", bin_m: float = 0.05, c0_m: float = 0.5,
                 grazing_deg: float | None = 10.0, min_points: int = 3, step_deg: float = 1.0,
                 min_fit_extent_m: float = 1.0, long_side_m: float = 2.4, max_rms_m: float = 0.1,
                 priors: Mapping[str, ClassPrior] = DEFAULT_PRIORS, sigma_m: float = 0.05, q: float = 1.0,
                 gate_m: float = 2.0, merge_m: float = 1.0, max_coast_s: float = 3.0, min_hits_velocity: int = 3,
                 max_velocity_sigma_mps: float = 0.5, heading_speed_mps: float = 0.5, sign_travel_m: float = 1.0,
                 class_votes: int = 2, people: bool = False) -> None:
        if not isinstance(scanners, Mapping) or not scanners:
            raise ConfigError("scanners: expected a non-empty mapping of sensor name -> laser2road")
        try:
            self._lasers = {str(n): _Laser(*planar_pose(T, f"scanners[{n!r}]")) for n, T in scanners.items()}
        except ValueError as err:
            raise ConfigError(str(err)) from err
        self.roi = road_roi(roads, margin_m)
        self._bg_args = {"alpha": alpha, "beta": beta, "gamma": gamma, "tau_fg_m": tau_fg_m, "n_init": n_init,
                         "init": init, "bin_m": bin_m}
        try:
            BeamBackground(1, **self._bg_args)  # validate now, not at the first scan
            segment_scan(np.zeros(0), 0.0, 0.01, c0_m=c0_m, n_min=min_points, grazing_deg=grazing_deg)
            fit_boxes(np.zeros((0, 2)), np.zeros(0, np.int64), step_deg=step_deg)
        except ValueError as err:
            raise ConfigError(f"LaserVehicleDetector: {err}") from err
        self.c0_m = float(c0_m)
        self.grazing_deg = grazing_deg
        self.min_points = _count(min_points, "min_points")
        self.step_deg = float(step_deg)
        self._n_ang, self._step_rad = _step_grid(step_deg)
        self.min_fit_extent_m = _positive(min_fit_extent_m, "min_fit_extent_m", allow_zero=True)
        self.long_side_m = _positive(long_side_m, "long_side_m")
        self.max_rms_m = _positive(max_rms_m, "max_rms_m")
        missing = [c for c in _CLASSES if c not in priors]
        if missing:
            raise ConfigError(f"priors: missing the class(es) {missing}; expected {list(_CLASSES)}")
        self.priors = {c: priors[c] for c in _CLASSES}
        self._profile = np.array([[p.profile_length_m, p.profile_width_m] for p in self.priors.values()])
        self._dims = np.array([[p.length_m, p.width_m] for p in self.priors.values()])
        self._dsig = np.array([[p.sigma_length_m, p.sigma_width_m] for p in self.priors.values()])
        self._footprint_extra = self._dims - self._profile  # footprint minus scan-plane profile, per class
        self._max_extent = self._profile + 3.0 * self._dsig  # the largest plausible seen extent, per class
        self.sigma_m = _positive(sigma_m, "sigma_m")
        self.q = _positive(q, "q")
        self.gate_m = _positive(gate_m, "gate_m")
        self.merge_m = _positive(merge_m, "merge_m", allow_zero=True)
        self.max_coast_s = _positive(max_coast_s, "max_coast_s", allow_zero=True)
        self.min_hits_velocity = _count(min_hits_velocity, "min_hits_velocity")
        self.max_velocity_sigma_mps = _positive(max_velocity_sigma_mps, "max_velocity_sigma_mps")
        self.heading_speed_mps = _positive(heading_speed_mps, "heading_speed_mps", allow_zero=True)
        self.sign_travel_m = _positive(sign_travel_m, "sign_travel_m")
        self.class_votes = _count(class_votes, "class_votes")
        self.people = bool(people)
        self._next_id = 1  # track ids are unique over all of this detector's lasers
        self._cv: tuple[int, np.ndarray, np.ndarray] | tuple[None, None, None] = (None, None, None)
        self.dropped_scans: dict[str, int] = dict.fromkeys(self._lasers, 0)
        """Scans dropped per scanner: out of time order, or without usable beam angles."""
        self._warned: set[str] = set()
        self._geometries_warned: set[tuple[str, tuple[int, float, float]]] = set()

    # ---------------------------------------------------------------------------------------------
    @property
    def scanners(self) -> tuple[str, ...]:
        return tuple(self._lasers)

    def background(self, sensor: str) -> BeamBackground | None:
        """The background model of one scanner (``None`` before its first scan)."""
        return self._state(sensor).background

    def track_ids(self, sensor: str) -> np.ndarray:
        """Ids of the live tracks of one scanner, ``(n,) int64``."""
        return self._state(sensor).ids.copy()

    def _state(self, sensor: str) -> _Laser:
        try:
            return self._lasers[sensor]
        except KeyError:
            raise ConfigError(f"laser scan from sensor {sensor!r}, but the detector knows only "
                              f"{sorted(self._lasers)}; name every scanner in 'scanners'") from None

    # ---------------------------------------------------------------------------------------------
    def prime(self, scans: Iterable[LaserScan], max_scans: int | None = None) -> dict[str, int]:
        """Learn every laser's background from the start of a recording before tracking it (as
        :meth:`fusiontrack.laser.LaserPeopleDetector.prime` does for people).

        Online, nothing is detected until a laser has sent ``n_init`` scans: vehicles on the road from the start go
        unseen meanwhile. This takes ``scans`` (the stream the tracking pass will give :meth:`__call__`, from its
        start) until every laser's background is initialised and keeps only the backgrounds: the tracking pass then
        classifies those first scans against them *without learning from them again*, and learns from every later
        scan as usual (from then on each background is the one online learning would have reached).

        Parameters
        ----------
        scans : iterable of LaserScan
        max_scans : int, optional
            Stop after this many scans even if some laser is not initialised (default ``4 * n_init`` per laser);
            such a laser is left to learn online from its first scan.

        Returns
        -------
        dict sensor -> int
            Scans each laser's priming took.
        """
        n_init = int(self._bg_args["n_init"])
        limit = 4 * n_init * len(self._lasers) if max_scans is None else int(max_scans)
        used = dict.fromkeys(self._lasers, 0)
        for i, scan in enumerate(scans):
            if i >= limit:
                break
            st = self._state(scan.sensor)
            if not self._usable(st, scan):
                continue
            self._background_of(st, scan)
            st.t_ns = scan.t_ns
            if scan.valid_ranges_m().size:
                st.background.update(self._free_as_far(scan, st.background.range_max_m))
            used[scan.sensor] += 1
            if all_initialised(self._lasers.values()):
                break
        else:  # the whole recording was read: a laser short of n_init scans sent all it will
            learn_short_backgrounds(self._lasers, used)
        keep_primed_backgrounds(self._lasers.values())
        self.dropped_scans = dict.fromkeys(self._lasers, 0)  # the tracking pass meets (and counts) them again
        return used

    def _usable(self, st: _Laser, scan: LaserScan) -> bool:
        """False (counted, and logged) for a scan older than the laser's last one or without usable beam angles."""
        if st.t_ns is not None and scan.t_ns < st.t_ns:
            self.dropped_scans[scan.sensor] += 1
            log.debug("laser %s: dropped a scan at %d ns, older than the last one (%d ns)", scan.sensor,
                      scan.t_ns, st.t_ns)
            return False
        if not (math.isfinite(scan.angle_min_rad) and math.isfinite(scan.angle_increment_rad)
                and scan.angle_increment_rad != 0):
            self.dropped_scans[scan.sensor] += 1
            if scan.sensor not in self._warned:
                self._warned.add(scan.sensor)
                log.warning("laser %s: dropping scans without usable beam angles (angle_min %s, increment %s)",
                            scan.sensor, scan.angle_min_rad, scan.angle_increment_rad)
            return False
        return True

    def _background_of(self, st: _Laser, scan: LaserScan) -> None:
        """The laser's background, made at its first scan and switched with the scan geometry (kept per geometry)."""
        if st.background is None:
            r_min = scan.range_min_m if math.isfinite(scan.range_min_m) and scan.range_min_m > 0 else 0.0
            r_max = scan.range_max_m if scan.range_max_m > r_min else math.inf
            st.background = BeamBackground(max(scan.n_beams, 1), **self._bg_args, range_min_m=r_min,
                                           range_max_m=r_max)
        switch_geometry(st.background, scan, self._geometries_warned)

    def __call__(self, scan: LaserScan) -> list[Detection]:
        """Process one scan; the detections of its vehicles (road frame), ``[]`` while the background learns.

        Raises
        ------
        ConfigError
            ``scan.sensor`` is not one of the configured scanners.
        """
        st = self._state(scan.sensor)
        if not self._usable(st, scan):
            return []
        self._background_of(st, scan)
        self._predict(st, scan.t_ns)
        r = scan.valid_ranges_m()
        free = self._free_as_far(scan, st.background.range_max_m) if r.size else None
        if free is None:
            fg = np.zeros(0, bool)
        elif st.primed_ns is not None and scan.t_ns <= st.primed_ns:  # already learnt from: classify only
            fg = st.background.foreground(free)
        else:
            st.primed_ns = None
            fg = st.background.update(free)
        beams = np.flatnonzero(fg)
        if beams.size and self.roi is not None:
            beams = beams[self.roi.contains(self._to_road(st, scan, beams, r))]
        if beams.size < self.min_points:
            self._prune(st, scan.t_ns)
            return []
        moving = np.full(r.size, np.nan)
        moving[beams] = r[beams]
        filled = bridge_dropouts(moving, np.isnan(r), scan.angle_increment_rad, self.c0_m)
        if filled.size:  # the filled beams are points of their vehicle from here on
            r = r.copy()
            r[filled] = moving[filled]
        beam_labels, n_points, mean_range = segment_scan(moving, scan.angle_min_rad, scan.angle_increment_rad,
                                                         c0_m=self.c0_m, n_min=self.min_points,
                                                         grazing_deg=self.grazing_deg)
        on = np.flatnonzero(beam_labels >= 0)
        if on.size == 0:
            self._prune(st, scan.t_ns)
            return []
        points = self._to_road(st, scan, on, r)
        labels = beam_labels[on]
        k = n_points.size
        inc = scan.angle_increment_rad
        cl = _clusters(points, labels, k, st.translation)
        fit = _fit(cl, self._n_ang, self._step_rad, True)
        quant = mean_range * abs(inc)
        edges = self._edges(on, labels, k, points, r, cl)
        # First pass (road direction only) to associate; second pass with the tracks' headings.
        road_dir = self._road_direction(fit)
        if st.ids.size:
            centres, first = self._boxes(st, cl, fit, road_dir, None, None, quant, edges, inc)
            pairs = self._associate(st, centres)
            join = self._fragments(st, pairs, centres)
        else:  # nothing to associate with
            first, pairs, join = None, np.zeros((0, 2), np.int64), None
        if join is not None:  # pieces of one vehicle split by an occluder: one cluster, fitted again
            labels = join[labels]
            k = int(join.max()) + 1
            pairs[:, 1] = join[pairs[:, 1]]
            n_points = np.bincount(labels, minlength=k)
            quant = np.bincount(labels, weights=r[on], minlength=k) / n_points * abs(inc)
            cl = _clusters(points, labels, k, st.translation)
            fit = _fit(cl, self._n_ang, self._step_rad, True)
            edges = self._edges(on, labels, k, points, r, cl)
            road_dir = self._road_direction(fit)
            first = None
        hint, sign_dir = road_dir.copy(), np.full(k, np.nan)
        track_of = np.full(k, -1, np.int64)
        if pairs.size:
            ti, di = pairs[:, 0], pairs[:, 1]
            track_of[di] = ti
            hint[di], sign_dir[di] = self._track_hints(st, ti, road_dir[di])
        boxes, heading, cls, frame_cls = self._boxes(st, cl, fit, hint, sign_dir, track_of, quant, edges, inc, first)
        signed = np.isfinite(sign_dir)
        ids, vel, probs = self._update(st, scan.t_ns, track_of, boxes, heading, signed, cls, frame_cls, fit.rms_m)
        return self._detections(scan, labels, n_points, points, cl, boxes, heading, cls, ids, vel, probs)

    # ---------------------------------------------------------------------------------------------
    @staticmethod
    def _free_as_far(scan: LaserScan, range_max_m: float) -> np.ndarray:
        """The ranges for the background: "no return" (``+inf`` or ``>= range_max``, REP 117) as a reading just
        short of ``range_max_m`` — the beam is free that far — so that vehicles passing in front of open space
        cannot drag a beam's "no return" background down (``BeamBackground`` never learns from invalid readings);
        ``NaN`` (an error) stays invalid."""
        r = scan.ranges_m.astype(np.float64)
        if math.isfinite(range_max_m):
            with np.errstate(invalid="ignore"):
                r[(r == np.inf) | (np.isfinite(r) & (r >= range_max_m))] = range_max_m * (1.0 - 1e-6)
        return r

    @staticmethod
    def _to_road(st: _Laser, scan: LaserScan, beams: np.ndarray, r: np.ndarray) -> np.ndarray:
        a = scan.angle_min_rad + beams * scan.angle_increment_rad
        rb = r[beams]
        local = np.empty((beams.size, 2))
        local[:, 0], local[:, 1] = rb * np.cos(a), rb * np.sin(a)
        return local @ st.rotation.T + st.translation

    def _track_hints(self, st: _Laser, rows: np.ndarray, road_dir: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Orientation and direction hints of the boxes of tracked clusters.

        Orientation (for the length axis, and the whole box of a small cluster): the velocity's direction when
        it is known to within ``3°`` (``σ_v / speed``), else the track's last heading, else the road's.
        Direction (the heading's sign): the velocity's when the speed exceeds ``heading_speed_mps`` and three
        standard deviations, else the track's last heading (``NaN``: unknown).
        """
        v = st.x[rows, 2:4]
        speed = np.hypot(v[:, 0], v[:, 1])
        sigma_v = self._velocity_sigma(st, rows)
        aged = st.hits[rows] >= self.min_hits_velocity
        vel_dir = np.arctan2(v[:, 1], v[:, 0])
        moving = aged & (speed >= self.heading_speed_mps) & (speed >= 3.0 * sigma_v)
        precise = aged & (sigma_v <= math.radians(3.0) * speed)
        last = st.heading[rows]
        hint = np.where(precise, vel_dir, np.where(np.isfinite(last), last, road_dir))
        return hint, np.where(moving, vel_dir, last)

    def _fragments(self, st: _Laser, pairs: np.ndarray, centres: np.ndarray) -> np.ndarray | None:
        """Clusters to join: an unpaired cluster whose box centre is within ``merge_m`` of a track that another
        cluster was paired with is a piece of that vehicle (an occluder split it). Returns the new label of
        every cluster (``0 .. k' - 1``), or ``None`` when nothing joins."""
        k = centres.shape[0]
        if pairs.shape[0] == 0 or pairs.shape[0] == k:
            return None
        free = np.setdiff1d(np.arange(k), pairs[:, 1])
        d = np.linalg.norm(centres[free, None, :] - st.x[pairs[:, 0], None, 0:2].reshape(1, -1, 2), axis=2)
        near = np.argmin(d, axis=1)
        ok = d[np.arange(free.size), near] <= self.merge_m
        if not ok.any():
            return None
        target = np.arange(k)
        target[free[ok]] = pairs[near[ok], 1]
        return np.unique(target, return_inverse=True)[1].astype(np.int64)

    def _edges(self, on: np.ndarray, labels: np.ndarray, k: int, points: np.ndarray, r: np.ndarray,
               cl: _Clusters) -> tuple[np.ndarray, np.ndarray]:
        """First and last point of each cluster in beam order ``(k, 2, 2)`` and whether the beam beyond each is
        nearer by more than ``c0_m`` or outside the field of view (an occluder's edge, not the vehicle's),
        ``(k, 2)``. ``on`` (the beams of ``points``) is ascending; ``cl`` the clusters of ``points``."""
        if cl.ordered and cl.present.size == k:  # beam-order runs: cluster j is points starts[j] .. + sizes[j]
            first = cl.starts
            last = first + cl.sizes - 1
        else:
            idx = np.arange(labels.size)
            first = np.full(k, labels.size, np.int64)
            last = np.full(k, -1, np.int64)
            np.minimum.at(first, labels, idx)
            np.maximum.at(last, labels, idx)
        ends = np.array([first, last]).T  # (k, 2) points
        b = on[ends]  # beam indices
        nb = b + _STEP_OUT
        outside = (nb < 0) | (nb >= r.size)
        r_nb = r[np.minimum(np.maximum(nb, 0), r.size - 1)]
        with np.errstate(invalid="ignore"):
            nearer = r_nb < r[b] - self.c0_m  # NaN (no return, error): not an occluder
        return points[ends], outside | nearer

    def _road_direction(self, fit: BoxFit) -> np.ndarray:
        """The road's driving axis at each box's centre (``NaN`` without an ROI), ``(k,)``."""
        if self.roi is None:
            return np.full(len(fit), np.nan)
        return self.roi.direction_at(np.einsum("kij,ki->kj", _axes(fit.angle_rad), 0.5 * (fit.lo_m + fit.hi_m)))

    def _boxes(self, st: _Laser, cl: _Clusters, fit: BoxFit, hint: np.ndarray, sign_dir: np.ndarray | None,
               track_of: np.ndarray | None, quant: np.ndarray, edges: tuple[np.ndarray, np.ndarray], inc: float,
               first: tuple[BoxFit, _BoxFrame, np.ndarray | None] | None = None) -> Any:
        """Heading, class and completed box of every cluster.

        A cluster smaller than ``min_fit_extent_m`` cannot show its orientation: its box takes the hint's.
        Returns the boxes, headings, the class (the track's, with this frame's vote, where ``track_of`` names a
        track) and the class this frame alone shows, as indices into ``_CLASSES``. Without ``track_of`` (the
        first pass, before association; ``sign_dir`` unused) the boxes' centres ``(k, 2)`` and ``(fit, frame, refit
        angles)``, which the second pass (``first``) reuses where its fit is the same.
        """
        e = fit.hi_m - fit.lo_m
        small = (np.fmax(e[:, 0], e[:, 1]) < self.min_fit_extent_m) & np.isfinite(hint)
        if small.any():
            fixed = np.where(small, hint, fit.angle_rad)[cl.present]
            if first is not None and first[2] is not None and np.array_equal(first[2], fixed):
                fit = first[0]  # the first pass refitted them at the same angles
            else:
                fit = _fit(cl, self._n_ang, self._step_rad, True, fixed)
            e = fit.hi_m - fit.lo_m
        else:
            fixed = None
        if first is not None and (first[0] is fit or np.array_equal(first[0].angle_rad, fit.angle_rad)):
            frame = first[1]  # the same boxes as in the first pass
        else:
            frame = _box_frame(fit.angle_rad, fit.lo_m, fit.hi_m, st.translation, edges[0], edges[1], inc)
        heading, axis = _unsigned_heading(fit.angle_rad, e, hint, self.long_side_m)
        frame_cls = _class_index(np.where((axis == 1)[:, None], e[:, ::-1], e), self.people)
        if track_of is None:
            return _complete(frame, axis, self._profile[frame_cls], None, None, None, centre_only=True), (fit, frame,
                                                                                                          fixed)
        with np.errstate(invalid="ignore"):
            flip = np.cos(heading - sign_dir) < 0  # NaN (no direction known): False
        heading = np.where(flip, np.where(heading <= 0, heading + math.pi, heading - math.pi), heading)
        cls = frame_cls.copy()
        has = track_of >= 0
        votes = st.votes[track_of[has]].copy()
        votes[np.arange(votes.shape[0]), frame_cls[has]] += 1
        cls[has] = self._track_class(votes, frame_cls[has])
        profile, dsig = self._profile[cls], self._dsig[cls]
        # A side the track has seen whole (close to the class's size) replaces the class prior.
        dims = st.dims[track_of[has]]
        with np.errstate(invalid="ignore"):
            use = ((dims >= profile[has] - 3.0 * dsig[has]) & (dims <= profile[has] + 4.0 * dsig[has]))
        profile[has] = np.where(use, dims, profile[has])
        dsig[has] = np.where(use, np.minimum(dsig[has], 2.0 * self.sigma_m), dsig[has])
        # points off the fitted sides (a poor rectangle: clutter or a neighbour joined) make the centre less sure
        rms = fit.rms_m
        sigma = np.hypot(self.sigma_m, rms if np.isfinite(rms).all() else np.nan_to_num(rms))
        boxes = _complete(frame, axis, profile, dsig, sigma, quant)
        return boxes, heading, cls, frame_cls

    def _track_class(self, votes: np.ndarray, frame_cls: np.ndarray) -> np.ndarray:
        """Highest class with at least ``class_votes`` votes; the frame's class if none has enough."""
        enough = votes >= self.class_votes
        best = len(_CLASSES) - 1 - enough[:, ::-1].argmax(axis=1)
        return np.where(enough.any(axis=1), best, frame_cls)

    @staticmethod
    def _velocity_sigma(st: _Laser, rows: np.ndarray) -> np.ndarray:
        """Largest standard deviation of the tracks' velocity, m/s, ``(n,)``."""
        return np.sqrt(np.linalg.eigvalsh(st.P[rows, 2:4, 2:4])[:, -1])

    def _velocity_known(self, st: _Laser, rows: np.ndarray) -> np.ndarray:
        return (st.hits[rows] >= self.min_hits_velocity) & (self._velocity_sigma(st, rows)
                                                             <= self.max_velocity_sigma_mps)

    def _predict(self, st: _Laser, t_ns: int) -> None:
        if st.t_ns is not None and st.ids.size and t_ns > st.t_ns:
            dt_ns = t_ns - st.t_ns
            if self._cv[0] != dt_ns:  # scans mostly come at one period
                F, Q = kalman.cv_matrices(dt_ns / 1e9, self.q)
                F.setflags(write=False)
                Q.setflags(write=False)
                self._cv = (dt_ns, F, Q)
            st.x, st.P = kalman.predict(st.x, st.P, self._cv[1], self._cv[2])
        st.t_ns = t_ns

    def _associate(self, st: _Laser, centres: np.ndarray) -> np.ndarray:
        if st.ids.size == 0 or centres.shape[0] == 0:
            return np.zeros((0, 2), np.int64)
        d = st.x[:, None, 0:2] - centres[None, :, :]
        cost = np.sqrt((d * d).sum(axis=2))  # np.linalg.norm's sum of squares
        allowed = cost <= self.gate_m  # NaN: not allowed
        if (allowed.sum(axis=0) <= 1).all() and (allowed.sum(axis=1) <= 1).all():
            # No track and no cluster has a rival within the gate: the optimal assignment is every gated pair
            # (what the Hungarian solver returns then, sorted by track).
            return np.argwhere(allowed).astype(np.int64)
        pairs, _, _ = hungarian(cost, gate=self.gate_m)
        return pairs

    def _prune(self, st: _Laser, t_ns: int) -> None:
        if st.ids.size:
            st.keep((t_ns - st.last_ns) <= round(self.max_coast_s * 1e9))

    def _update(self, st: _Laser, t_ns: int, track_of: np.ndarray, boxes: CompletedBoxes, heading: np.ndarray,
                signed: np.ndarray, cls: np.ndarray, frame_cls: np.ndarray, rms: np.ndarray,
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Kalman update of the paired tracks (``R`` = the detection's covariance), a new track for every other
        cluster, then the deletion of stale tracks.

        Returns each cluster's track id ``(k,)``, track velocity ``(k, 2)`` (``NaN`` before
        ``min_hits_velocity`` updates) and the track's class vote fractions ``(k, 3)``.
        """
        has = track_of >= 0
        ti, di = track_of[has], np.flatnonzero(has)
        # A track's size is the largest it was seen at (a partial view only ever shows less), from clusters that
        # are rectangles (a neighbour joined to the cluster leaves points off the box's sides) and not larger
        # than the class allows.
        plausible = (boxes.extent_m <= self._max_extent[cls]) & (
            rms <= self.max_rms_m)[:, None]
        if ti.size:
            x, P = kalman.update(st.x[ti], st.P[ti], boxes.centre_m[di], R=boxes.covariance_m2[di])
            st.x, st.P = st.x.copy(), st.P.copy()  # the tracks without a detection keep their prediction
            st.x[ti], st.P[ti] = x, P
            st.last_ns[ti] = t_ns
            st.hits[ti] += 1
            st.votes[ti, frame_cls[di]] += 1
            # The direction of travel: the velocity's when sure, and, over every ``sign_travel_m`` travelled, the
            # displacement's (robust to a few bad centres, which can fool a slow track's velocity).
            h = heading[di]
            disp = st.x[ti, 0:2] - st.origin[ti]
            travelled = np.hypot(disp[:, 0], disp[:, 1]) >= self.sign_travel_m
            back = travelled & (np.cos(h - np.arctan2(disp[:, 1], disp[:, 0])) < 0)
            h = np.where(back, np.where(h <= 0, h + math.pi, h - math.pi), h)
            st.heading[ti] = np.where(signed[di] | travelled, h, st.heading[ti])
            st.origin[ti] = np.where(travelled[:, None], st.x[ti, 0:2], st.origin[ti])
            st.dims[ti] = np.where(plausible[di], np.fmax(st.dims[ti], boxes.extent_m[di]), st.dims[ti])
        new = np.flatnonzero(~has)
        track_of = track_of.copy()
        if new.size:
            m = new.size
            x0 = np.zeros((m, 4))
            x0[:, 0:2] = boxes.centre_m[new]
            P0 = np.zeros((m, 4, 4))
            P0[:, 0:2, 0:2] = boxes.covariance_m2[new]
            P0[:, 2, 2] = P0[:, 3, 3] = 10.0**2  # unknown velocity: up to ~36 km/h at 1 sigma
            votes = np.zeros((m, len(_CLASSES)), np.int64)
            votes[np.arange(m), frame_cls[new]] = 1
            track_of[new] = np.arange(st.ids.size, st.ids.size + m)
            st.x = np.concatenate([st.x, x0])
            st.P = np.concatenate([st.P, P0])
            st.ids = np.concatenate([st.ids, np.arange(self._next_id, self._next_id + m, dtype=np.int64)])
            st.last_ns = np.concatenate([st.last_ns, np.full(m, t_ns, np.int64)])
            st.hits = np.concatenate([st.hits, np.ones(m, np.int64)])
            st.votes = np.concatenate([st.votes, votes])
            st.heading = np.concatenate([st.heading, np.full(m, np.nan)])
            st.dims = np.concatenate([st.dims, np.where(plausible[new], boxes.extent_m[new], np.nan)])
            st.origin = np.concatenate([st.origin, boxes.centre_m[new]])
            self._next_id += m
        ids = st.ids[track_of]
        vel = np.where(self._velocity_known(st, track_of)[:, None], st.x[track_of, 2:4], np.nan)
        v = st.votes[track_of].astype(np.float64)
        probs = v / np.maximum(v.sum(axis=1, keepdims=True), 1.0)
        self._prune(st, t_ns)
        if st.ids.size > 1:  # two tracks on one vehicle (born from a split cluster): keep the stronger
            d = st.x[:, None, 0:2] - st.x[None, :, 0:2]
            close = np.sqrt((d * d).sum(axis=2)) < self.merge_m  # np.linalg.norm's sum of squares
            np.fill_diagonal(close, False)
            h = st.hits
            weaker = (h[:, None] < h[None, :]) | ((h[:, None] == h[None, :]) & (st.ids[:, None] > st.ids[None, :]))
            st.keep(~(close & weaker).any(axis=1))
        return ids, vel, probs

    def _detections(self, scan: LaserScan, labels: np.ndarray, n_points: np.ndarray, points: np.ndarray,
                    cl: _Clusters, boxes: CompletedBoxes, heading: np.ndarray, cls: np.ndarray, ids: np.ndarray,
                    vel: np.ndarray, probs: np.ndarray) -> list[Detection]:
        by_cluster = points if cl.ordered else points[np.argsort(labels, kind="stable")]
        ends = n_points.cumsum().tolist()
        groups = [by_cluster[a:b] for a, b in zip([0, *ends[:-1]], ends, strict=True)]
        size_out = boxes.size_m + self._footprint_extra[cls]  # footprint: a bicycle is 0.6 m wide
        score = 1.0 - np.exp(-n_points / 8.0)
        # The detections own their arrays (Detection.trusted takes them as they are, without copies): the boxes,
        # velocities and ids are float64 / int64 arrays made for this scan that nothing else keeps.
        centre, cov = boxes.centre_m, boxes.covariance_m2
        box = np.empty((centre.shape[0], 5))
        box[:, 0:2], box[:, 2:4], box[:, 4] = centre, size_out, heading
        extent, from_prior = boxes.extent_m, boxes.from_prior
        track_ids = ids.reshape(-1, 1)
        prob_rows, scores, classes = probs.tolist(), score.tolist(), cls.tolist()
        known = np.isfinite(vel[:, 0]).tolist()
        out = []
        for j in range(n_points.size):
            feats: dict[str, np.ndarray] = {
                "box": box[j],
                "track_id": track_ids[j],
                "points_m": groups[j],
                "extent_m": extent[j],
                "from_prior": from_prior[j],
            }
            if known[j]:
                feats["velocity_mps"] = vel[j]
            out.append(Detection.trusted(scan.t_ns, scan.sensor, centre[j], cov[j], None, scores[j],
                                         _CLASSES[classes[j]], dict(zip(_CLASSES, prob_rows[j], strict=True)), feats))
        return out


# --------------------------------------------------------------------------------------------------
# Recordings
# --------------------------------------------------------------------------------------------------


def laser_poses_for_recording(rec: Any, lasers: Sequence[str], *, world_frame: str = "world",
                              calibrated_suffix: str | None = "_calibrated",
                              time_source: str = "header") -> dict[str, np.ndarray]:
    """Each laser's ``(4, 4)`` laser2road pose from the recording's ``/tf_static``.

    For each laser topic the first scan gives its frame id; the pose is that of ``<frame><calibrated_suffix>``
    (the calibration the system believes, as the simulator writes it) when the tree has it, else of
    ``<frame>``, else of the sensor name; the identity (with a warning) when none reaches ``world_frame``.

    Returns
    -------
    dict of sensor name -> (4, 4) float64
    """
    tree = rec.transform_tree(["/tf_static"])
    first: dict[str, LaserScan] = {}
    for scan in rec.messages(list(lasers), time_source=time_source):
        if isinstance(scan, LaserScan):
            first.setdefault(scan.sensor, scan)
            if len(first) == len(lasers):
                break
    poses: dict[str, np.ndarray] = {}
    for sensor, scan in first.items():
        names = [f for f in (scan.frame_id, sensor) if f]
        if calibrated_suffix:
            names = [f + calibrated_suffix for f in names] + names
        frame = next((f for f in names if tree.has_path(f, world_frame)), None)
        if frame is None:
            log.warning("laser %s: no transform from %s to %r in /tf_static; using the identity", sensor,
                        names, world_frame)
            poses[sensor] = np.eye(4)
        else:
            poses[sensor] = tree.get(frame, world_frame)
    if not poses:
        raise ConfigError(f"{rec.paths[0]}: the laser topics {list(lasers)} hold no scans")
    return poses


def _laser_topics(rec: Any, lasers: Sequence[str] | None) -> list[str]:
    topics = rec.topic_types()
    if lasers is None:
        found = [t for t, msgtype in topics.items() if msgtype == "sensor_msgs/msg/LaserScan"]
        if not found:
            raise ConfigError(f"{rec.paths[0]}: no LaserScan topic (topics: {sorted(topics)})")
        return found
    missing = [t for t in lasers if t not in topics]
    if missing:
        raise ConfigError(f"{rec.paths[0]}: laser topic(s) {missing} not in the recording (topics: "
                          f"{sorted(topics)})")
    return list(lasers)


def vehicle_detector_for_recording(rec: Any, roads: Any, *, lasers: Sequence[str] | None = None,
                                   world_frame: str = "world", calibrated_suffix: str | None = "_calibrated",
                                   time_source: str = "header", **params: Any,
                                   ) -> tuple[LaserVehicleDetector, list[str]]:
    """A :class:`LaserVehicleDetector` for the laser topics of an open recording, posed by its ``/tf_static``.

    Parameters
    ----------
    rec : Recording
    roads : see :func:`road_roi`
    lasers : list of str, optional
        Laser topics (default: every ``sensor_msgs/msg/LaserScan`` topic).
    world_frame, calibrated_suffix, time_source :
        See :func:`laser_poses_for_recording`.
    **params :
        Keyword arguments of :class:`LaserVehicleDetector`.

    Returns
    -------
    detector, laser topics
    """
    topics = _laser_topics(rec, lasers)
    poses = laser_poses_for_recording(rec, topics, world_frame=world_frame, calibrated_suffix=calibrated_suffix,
                                      time_source=time_source)
    return LaserVehicleDetector(poses, roads, **params), topics


def vehicle_detections_for_recording(rec: Any, roads: Any, *, lasers: Sequence[str] | None = None,
                                     world_frame: str = "world", calibrated_suffix: str | None = "_calibrated",
                                     time_source: str = "header", start_ns: int | None = None,
                                     stop_ns: int | None = None, **params: Any,
                                     ) -> Iterator[tuple[int, str, list[Detection]]]:
    """``(t_ns, sensor, detections)`` for every scan of every laser of a recording, in time order.

    Parameters
    ----------
    rec : Recording, or a path to open
    roads : see :func:`road_roi` (e.g. the simulator's ``ground_truth/world.json``)
    lasers, world_frame, calibrated_suffix, time_source, **params :
        See :func:`vehicle_detector_for_recording`.
    start_ns, stop_ns : int, optional
        Time window of the scans (log time).
    """
    if isinstance(rec, str | Path):
        from fusiontrack.io.recording import Recording

        with Recording(rec) as opened:
            yield from vehicle_detections_for_recording(
                opened, roads, lasers=lasers, world_frame=world_frame, calibrated_suffix=calibrated_suffix,
                time_source=time_source, start_ns=start_ns, stop_ns=stop_ns, **params)
        return
    detector, topics = vehicle_detector_for_recording(rec, roads, lasers=lasers, world_frame=world_frame,
                                                      calibrated_suffix=calibrated_suffix,
                                                      time_source=time_source, **params)
    for scan in rec.messages(topics, start_ns=start_ns, stop_ns=stop_ns, time_source=time_source):
        if isinstance(scan, LaserScan):
            yield scan.t_ns, scan.sensor, detector(scan)
