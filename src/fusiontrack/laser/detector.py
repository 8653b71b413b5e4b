"""Laser people detection from several scanners: background, foreground points in the world, two-feet segments.

Per scan (:meth:`LaserPeopleDetector.update`), for the scanner that made it:

1. the scanner's :class:`~fusiontrack.laser.background.BeamBackground` (ALGORITHMS.md A7 + B3) marks the
   foreground beams;
2. with ``min_cluster_points`` above 1 (the default keeps every beam: a far leg is one beam), the foreground
   beams are clustered in beam order (A8, :func:`~fusiontrack.laser.clustering.cluster_scan`) to drop clusters
   of fewer beams;
3. the surviving points are moved into the world frame with the scanner's ``laser2world`` (B2);
4. **rigid objects**: the surviving beams are also clustered in beam order with A8 joined across grazing sides
   (:func:`~fusiontrack.laser.clustering.segment_scan`; up to two beams without a return inside are bridged); a
   cluster in one piece (no gap wider than ``rigid_max_gap`` of its length) whose first and last points are at
   least ``rigid_min_m`` (1 m) apart, or ``rigid_keep_m`` (0.6 m) next to the scanner's rigid points of its
   previous scan, is the side of a bicycle or a car, not a person (a person's beam-order clusters are legs, a few
   centimetres to half a metre across), and its points are marked rigid.

Per frame (:meth:`LaserPeopleDetector.detect`): the latest foreground points of every scanner are pooled. The rigid
clusters of all scanners within ``rigid_join_m`` of each other, and the beam-order clusters that come within that
distance of them, form one rigid object each: a :class:`~fusiontrack.types.Detection` with feature ``"rigid"``
(B18's bicycles and cars, tracked with constant velocity). The other points are segmented by mean-shift (B4) and
split into feet (B5), and each segment becomes one detection. Without step 4 a car was cut into 0.4 m pieces, each
tracked as a walker.

Timing assumptions
------------------
* A scan's time is its ``t_ns`` (the header stamp: the start of the sweep). Points are not motion
  compensated, neither within a sweep (≤ 0.1 s at 10 Hz: a walker moves ≤ 0.15 m) nor between scanners.
* :meth:`detect` pools, per scanner, the latest accepted scan whose ``t_ns`` lies within ``max_age_s`` of
  the requested time (either side). A scanner that went silent simply stops contributing once its last
  scan is older than that; call ``detect`` once per tracking cycle, e.g. with the newest scan's time.
* Scans must arrive in time order per scanner: a scan older than that scanner's latest accepted one is
  dropped (counted in :attr:`LaserPeopleDetector.dropped_scans`, as are scans whose beam angles are not
  finite); scanners are independent of each other.
* The background needs ``n_init`` scans per scanner (5 s at 10 Hz by default) before anything is
  foreground, and again after a change of beam count or beam angles (logged warning). A recording can be
  read ahead: :meth:`LaserPeopleDetector.prime` learns the backgrounds from its first scans before the
  tracking pass, so that its first scans have foregrounds too.
"""

from __future__ import annotations

import dataclasses
import inspect
import logging
import math
import numbers
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from fusiontrack.errors import ConfigError
from fusiontrack.laser.background import (
    BeamBackground,
    InitMethod,
    all_initialised,
    keep_primed_backgrounds,
    learn_short_backgrounds,
    switch_geometry,
)
from fusiontrack.laser.clustering import Segments, cluster_scan, mean_shift_segments, segment_scan
from fusiontrack.types import Detection, LaserScan

__all__ = ["LaserPeopleDetector", "check_detector_params", "detector_for_recording", "planar_pose"]

log = logging.getLogger(__name__)


def planar_pose(laser2world: Any, name: str = "laser2world") -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``(2, 2)`` and translation ``(2,)`` on the floor from a ``(3, 3)`` 2-D pose or ``(4, 4)`` transform.

    A ``(4, 4)`` transform maps scan points (``z = 0`` in the laser frame) to ``(x, y)`` as
    :func:`fusiontrack.geometry.transform_points` does; a tilted scanner is thereby projected, not corrected.
    """
    T = np.asarray(laser2world, dtype=np.float64)
    if T.shape not in ((3, 3), (4, 4)) or not np.all(np.isfinite(T)):
        raise ValueError(f"{name}: expected a finite (3, 3) 2-D pose or (4, 4) transform, got shape {T.shape}")
    d = T.shape[0] - 1
    R = T[:d, :d]
    if not (np.allclose(R @ R.T, np.eye(d), atol=1e-6) and np.allclose(T[d], np.eye(d + 1)[d])):
        raise ValueError(f"{name}: not a rigid transform (rotation not orthonormal or last row not 0..0 1)")
    R2, t2 = T[:2, :2].copy(), T[:2, d].copy()
    R2.setflags(write=False)
    t2.setflags(write=False)
    return R2, t2


class _Scanner:
    """Mutable per-scanner state (the detector's, not shared)."""

    __slots__ = ("background", "cluster", "points_m", "primed_ns", "rigid", "rotation", "t_ns", "translation")

    def __init__(self, rotation: np.ndarray, translation: np.ndarray) -> None:
        self.rotation = rotation
        self.translation = translation
        self.background: BeamBackground | None = None
        self.t_ns: int | None = None
        self.points_m = np.zeros((0, 2))
        self.rigid = np.zeros(0, np.int64)  # rigid cluster of each point in this scan, -1 for none
        self.cluster = np.zeros(0, np.int64)  # beam-order cluster of each point, -1 for one alone
        self.primed_ns: int | None = None  # scans up to this time taught the background already (prime)


class LaserPeopleDetector:
    """Two-feet segment detections from one or several 2-D laser scanners (seed 001; ALGORITHMS.md A7, A8, B2–B5).

    Parameters
    ----------
    scanners : mapping of sensor name -> laser2world
        The ``sensor`` of each scanner's :class:`~fusiontrack.types.LaserScan` and its pose in the world:
        a ``(3, 3)`` 2-D pose or a ``(4, 4)`` rigid transform.
    alpha, beta, gamma, tau_fg_m, n_init, init, bin_m :
        Background model of every scanner, see :class:`~fusiontrack.laser.background.BeamBackground`
        (defaults A7 with B3's mode initialisation).
    c0_m : float
        A8 breakpoint constant for clustering the foreground beams (0.20 m).
    min_cluster_points : int
        Foreground beam-order clusters smaller than this are dropped before the mean-shift (A8's ``n_min``);
        the default 1 keeps all, and the mean-shift's ``min_segment_points`` decides. A8's ``n_min = 2`` [RECON]
        drops every leg that only one beam hits: beyond about 9 m for a 0.375-degree scanner (legs 6 cm
        across), beyond 4.6 m for a 0.75-degree one, so people far away or behind others vanished. Paired runs
        (simulated crowd and groups, 30 s, seeds 0-5): MOTA 0.863 -> 0.912 and 0.904 -> 0.938, ID switches
        34 -> 10 and 15 -> 7; the same crowd with every second beam dropped: MOTA 0.31 -> 0.75; the outdoor
        leg_tracker bag: 0.922 -> 0.921.
    bandwidth_m, merge_m, min_segment_points :
        Mean-shift (B4): ``h`` = 0.40 m, modes closer than ``merge_m`` (default ``h / 2``) merge, segments
        need ``min_segment_points`` (3).
    pair_feet_m, foot_radius_m :
        Foot pairing after the mean-shift (see :func:`~fusiontrack.laser.clustering.mean_shift_segments`):
        two mutually nearest segments whose union splits into two feet (every point within ``foot_radius_m``
        = 0.15 m of its foot's barycentre) at most ``pair_feet_m`` = 0.8 m apart become one segment, so a
        walker at a long stride is one detection, not two. ``pair_feet_m=None`` gives pure B4.
    d_one_foot_m : float
        B5: feet closer than this (0.12 m) make a one-foot segment.
    min_sigma_m : float
        The detection covariance is ``min_sigma_m**2 I`` plus the sample covariance of the segment's points.
    rigid_min_m : float or None
        A beam-order cluster (A8 with ``c0_m``, joined across sides seen at down to ``rigid_grazing_deg`` = 10
        degrees) whose first and last points are at least this far apart (1.0 m) and that is one piece (below) is
        rigid: part of a bicycle or a car, kept whole instead of mean-shifted. ``None`` or ``inf`` (in a pipeline
        file): none is (pure B4). A person's beam-order clusters are legs, at most about half a metre across.
    rigid_grazing_deg : float
        See ``rigid_min_m``.
    rigid_max_gap : float
        One piece: no gap between consecutive points wider than this fraction (0.3) of the first-to-last distance.
        Two legs of different people at nearly the same bearing, half a metre apart in depth, pass the grazing
        joins, and a vehicle's side does not have such a gap. Measured on simulated recordings (30 s crowd seeds
        0-11 and groups 0-3; 60 s road seed 7 with half bicycles; one count per scanner and scan): clusters of
        people at least 1 m long went from 53 to 2, the cars' points in such clusters from 704 000 to 682 000,
        the bicycles' from 22 700 to 22 100. Without it the rigid objects cost paired 30 s crowd runs (laser only,
        seeds 0-11) MOTA 0.923 -> 0.916 and ID switches 33 -> 40; with it those runs are the same as with no rigid
        objects at all, and of 12 groups runs one differs (3 ID switches instead of 2).
    rigid_keep_m : float
        Hysteresis: a cluster in one piece at least this long (0.6 m) that comes within ``rigid_join_m`` of the
        scanner's rigid points of its previous scan stays rigid. An object seen at about ``rigid_min_m`` (a bicycle
        end-on, clutter seen from a moving robot) otherwise flickers between a rigid object and walker-sized
        pieces, and each piece starts a walking track. On the outdoor leg_tracker bag (a robot following a person)
        MOTA was 0.81 without it against 0.90 with no rigid objects at all.
    rigid_join_m : float
        Rigid clusters closer than this (0.5 m; from any scanner) are one object, and a point closer than this to
        a rigid cluster is part of it, with the rest of its beam-order cluster.
    max_age_s : float
        How far a scanner's latest scan may be from the time passed to :meth:`detect` (0.2 s).
    sensor : str
        ``sensor`` of the detections (``"laser"``).
    """

    def __init__(self, scanners: Mapping[str, Any], *, alpha: float = 0.005, beta: float = 0.05,
                 gamma: float | None = None, tau_fg_m: float = 0.20, n_init: int = 50, init: InitMethod = "mode",
                 bin_m: float = 0.05, c0_m: float = 0.20, min_cluster_points: int = 1, bandwidth_m: float = 0.40,
                 merge_m: float | None = None, min_segment_points: int = 3, pair_feet_m: float | None = 0.8,
                 foot_radius_m: float = 0.15, d_one_foot_m: float = 0.12,
                 min_sigma_m: float = 0.05, rigid_min_m: float | None = 1.0, rigid_grazing_deg: float = 10.0,
                 rigid_keep_m: float = 0.6, rigid_max_gap: float = 0.3, rigid_join_m: float = 0.5,
                 max_age_s: float = 0.2,
                 sensor: str = "laser") -> None:
        if not isinstance(scanners, Mapping) or not scanners:
            raise ValueError("scanners: expected a non-empty mapping of sensor name -> laser2world")
        self._scanners = {str(name): _Scanner(*planar_pose(T, f"scanners[{name!r}]"))
                          for name, T in scanners.items()}
        self._bg_args = {"alpha": alpha, "beta": beta, "tau_fg_m": tau_fg_m, "n_init": n_init, "init": init,
                         "bin_m": bin_m, "gamma": gamma}
        for name, v in (("min_cluster_points", min_cluster_points), ("min_segment_points", min_segment_points)):
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
        BeamBackground(1, **self._bg_args)  # validate the background parameters now, not at the first scan
        # Validate the clustering parameters once, on empty input.
        cluster_scan(np.zeros(0), 0.0, 0.01, c0_m=c0_m, n_min=min_cluster_points)
        mean_shift_segments(np.zeros((0, 2)), bandwidth_m, n_min=min_segment_points, merge_m=merge_m,
                            pair_feet_m=pair_feet_m, foot_radius_m=foot_radius_m, d_one_foot_m=d_one_foot_m)
        self.c0_m = float(c0_m)
        self.min_cluster_points = int(min_cluster_points)
        self.bandwidth_m = float(bandwidth_m)
        self.merge_m = merge_m
        self.min_segment_points = int(min_segment_points)
        self.pair_feet_m = pair_feet_m
        self.foot_radius_m = float(foot_radius_m)
        self.d_one_foot_m = float(d_one_foot_m)
        self.min_sigma_m = float(min_sigma_m)
        if not (math.isfinite(self.min_sigma_m) and self.min_sigma_m >= 0):
            raise ValueError(f"min_sigma_m: expected a finite value >= 0 m, got {min_sigma_m}")
        if rigid_min_m is not None and not (isinstance(rigid_min_m, numbers.Real) and not isinstance(rigid_min_m, bool)
                                            and rigid_min_m > 0):
            raise ValueError(f"rigid_min_m: expected a length > 0 m (inf: none), or None, got {rigid_min_m!r}")
        if not (math.isfinite(rigid_join_m) and rigid_join_m >= 0):
            raise ValueError(f"rigid_join_m: expected a finite value >= 0 m, got {rigid_join_m}")
        if not 0.0 < float(rigid_grazing_deg) < 90.0:
            raise ValueError(f"rigid_grazing_deg: expected an angle in (0, 90) degrees, got {rigid_grazing_deg}")
        self.rigid_min_m = None if rigid_min_m is None or math.isinf(rigid_min_m) else float(rigid_min_m)
        self.rigid_grazing_deg = float(rigid_grazing_deg)
        if not (math.isfinite(rigid_keep_m) and rigid_keep_m > 0):
            raise ValueError(f"rigid_keep_m: expected a finite length > 0 m, got {rigid_keep_m}")
        self.rigid_keep_m = float(rigid_keep_m)
        if not (math.isfinite(rigid_max_gap) and 0 < rigid_max_gap <= 1):
            raise ValueError(f"rigid_max_gap: expected a fraction in (0, 1], got {rigid_max_gap}")
        self.rigid_max_gap = float(rigid_max_gap)
        self.rigid_join_m = float(rigid_join_m)
        self.max_age_s = float(max_age_s)
        if not (self.max_age_s >= 0 and math.isfinite(self.max_age_s)):
            raise ValueError(f"max_age_s: expected a finite value >= 0 s, got {max_age_s}")
        self._max_age_ns = round(self.max_age_s * 1e9)
        self.sensor = str(sensor)
        self._names_of_set: dict[tuple[bool, ...], np.ndarray] = {}  # scanners' flags -> names (_scanner_sets)
        self.dropped_scans: dict[str, int] = dict.fromkeys(self._scanners, 0)
        """Scans dropped per scanner: out of order, or without usable beam angles."""
        self._warned: set[str] = set()
        self._geometries_warned: set[tuple[str, tuple[int, float, float]]] = set()

    # ---------------------------------------------------------------------------------------------
    @property
    def scanners(self) -> tuple[str, ...]:
        return tuple(self._scanners)

    def background(self, sensor: str) -> BeamBackground | None:
        """The background model of one scanner (``None`` before its first scan)."""
        return self._state(sensor).background

    def prime(self, scans: Iterable[LaserScan], max_scans: int | None = None) -> dict[str, int]:
        """Learn every scanner's background from the start of a recording before tracking it.

        Online, nothing is foreground until a scanner has sent ``n_init`` scans (2 s at 25 Hz): people present
        from the start go undetected meanwhile. A recording can be read ahead: this takes ``scans`` (the same
        time-ordered stream the tracking pass will read, from its start) until every scanner's background is
        initialised, then forgets the scans' times and points but keeps the backgrounds. The tracking pass
        then classifies the scans the priming read against the background learnt from them, *without
        learning from them again*, and learns from every later scan as usual: from the first scan after the
        priming on, each background is the one online learning would have reached (the same numbers), and
        only the first scans' foregrounds differ (they exist).

        Parameters
        ----------
        scans : iterable of LaserScan
            The recording's scans from its start, in time order (as :meth:`update` takes them).
        max_scans : int, optional
            Stop after this many scans even if some scanner is not initialised (a silent scanner must not make
            the priming read the whole recording). Default ``4 * n_init * number of scanners``.

        Returns
        -------
        dict sensor -> int
            Scans each scanner's priming took. A scanner whose background is not initialised at the end is reset
            to nothing learnt, so that the tracking pass learns it online from its first scan, as without
            priming; but when the priming read the whole recording (a recording shorter than ``n_init`` scans of
            a scanner), its background is learnt from the scans it sent, if there are at least
            ``PRIME_MIN_SCANS`` (10; a warning says so): online it would never have been learnt.
        """
        n_init = int(self._bg_args["n_init"])
        limit = 4 * n_init * len(self._scanners) if max_scans is None else int(max_scans)
        used = dict.fromkeys(self._scanners, 0)
        for i, scan in enumerate(scans):
            if i >= limit:
                break
            self.update(scan)
            if scan.sensor in used:
                used[scan.sensor] += 1
            if all_initialised(self._scanners.values()):
                break
        else:  # the whole recording was read: a scanner short of n_init scans sent all it will
            learn_short_backgrounds(self._scanners, used)
        keep_primed_backgrounds(self._scanners.values())
        for st in self._scanners.values():
            st.points_m = np.zeros((0, 2))
            st.rigid = st.cluster = np.zeros(0, np.int64)
        self.dropped_scans = dict.fromkeys(self._scanners, 0)  # the tracking pass meets (and counts) them again
        return used

    def _state(self, sensor: str) -> _Scanner:
        try:
            return self._scanners[sensor]
        except KeyError:
            raise ConfigError(f"laser scan from sensor {sensor!r}, but the detector knows only "
                              f"{sorted(self._scanners)}; name every scanner in 'scanners'") from None

    def update(self, scan: LaserScan) -> None:
        """Take one scan: update its scanner's background and keep its foreground points (world frame).

        Raises
        ------
        ConfigError
            ``scan.sensor`` is not one of the configured scanners.
        """
        st = self._state(scan.sensor)
        if st.t_ns is not None and scan.t_ns < st.t_ns:
            self.dropped_scans[scan.sensor] += 1
            log.debug("laser %s: dropped a scan at %d ns, older than the last one (%d ns)", scan.sensor,
                      scan.t_ns, st.t_ns)
            return
        if not (math.isfinite(scan.angle_min_rad) and math.isfinite(scan.angle_increment_rad)
                and scan.angle_increment_rad != 0):
            self.dropped_scans[scan.sensor] += 1
            if scan.sensor not in self._warned:
                self._warned.add(scan.sensor)
                log.warning("laser %s: dropping scans without usable beam angles (angle_min %s, increment %s)",
                            scan.sensor, scan.angle_min_rad, scan.angle_increment_rad)
            return
        if st.background is None:
            # Odd limits in a scan header must not stop the detector: fall back to (0, inf).
            r_min = scan.range_min_m if math.isfinite(scan.range_min_m) and scan.range_min_m > 0 else 0.0
            r_max = scan.range_max_m if scan.range_max_m > r_min else math.inf
            st.background = BeamBackground(max(scan.n_beams, 1), **self._bg_args, range_min_m=r_min,
                                           range_max_m=r_max)
        switch_geometry(st.background, scan, self._geometries_warned)
        last_ns, st.t_ns = st.t_ns, scan.t_ns
        r = scan.valid_ranges_m()
        if st.primed_ns is not None and scan.t_ns <= st.primed_ns:  # already learnt from: classify only
            fg = st.background.foreground(r) if r.size else np.zeros(0, bool)
        else:
            st.primed_ns = None
            fg = st.background.update(r) if r.size else np.zeros(0, bool)
        if not fg.any():
            st.points_m = np.zeros((0, 2))
            st.rigid = st.cluster = np.zeros(0, np.int64)
            return
        if self.min_cluster_points > 1:
            clusters = cluster_scan(np.where(fg, r, np.nan), scan.angle_min_rad, scan.angle_increment_rad,
                                    c0_m=self.c0_m, n_min=self.min_cluster_points)
            keep = np.flatnonzero(clusters.labels >= 0)
        else:  # clusters of one beam kept: A8 drops nothing but invalid beams (its cost was 0.3 ms a scan)
            keep = np.flatnonzero(fg & np.isfinite(r) & (r > 0))
        a = scan.angle_min_rad + keep * scan.angle_increment_rad
        local = np.column_stack([r[keep] * np.cos(a), r[keep] * np.sin(a)])
        # the previous scan's rigid points, for the hysteresis: only if that scan is recent
        recent = last_ns is not None and scan.t_ns - last_ns <= self._max_age_ns
        prev = st.points_m[st.rigid >= 0] if recent and st.rigid.size else None
        world = local @ st.rotation.T + st.translation
        rigid, cluster = self._rigid_clusters(r, keep, local, world, scan, prev)
        st.points_m, st.rigid, st.cluster = world, rigid, cluster

    def _rigid_clusters(self, r: np.ndarray, keep: np.ndarray, local: np.ndarray, world: np.ndarray,
                        scan: LaserScan, prev: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Rigid cluster of each kept beam (``keep``: beam indices; ``local``, ``world``: their points in the
        sensor and world frames), ``-1`` for none, and its beam-order cluster (``-1`` for a beam alone); ``prev``:
        the rigid points of the scanner's previous scan, world frame, or None."""
        out = np.full(keep.size, -1, np.int64)
        if self.rigid_min_m is None or keep.size < 2:
            return out, out
        on = np.full(r.size, np.nan)
        on[keep] = r[keep]
        # A beam without a return (glass, dark paint) must not cut a side in two: up to _BRIDGE_BEAMS invalid
        # beams between two kept ones are filled by interpolation (for the clustering only; they are no points)
        # where the side runs on smoothly: the range on each side of the hole, extrapolated from the beam before,
        # lands within _BRIDGE_M of the other (legs of two people have a step in range there).
        invalid = np.flatnonzero(~np.isfinite(r) | (r <= 0))
        if invalid.size:
            kept = np.zeros(r.size + 3, bool)  # (past the end, and index -1 and -2: never kept)
            kept[keep] = True
            # only holes with a kept beam within two on each side (most invalid beams see nothing at all)
            invalid = invalid[(kept[invalid - 1] | kept[invalid - 2]) & (kept[invalid + 1] | kept[invalid + 2])]
        if invalid.size:
            pos = np.searchsorted(keep, invalid)
            before, after = keep[np.maximum(pos - 1, 0)], keep[np.minimum(pos, keep.size - 1)]
            valid_before = np.cumsum(np.isfinite(r) & (r > 0))  # valid beams up to each index
            fill = ((pos > 0) & (pos < keep.size) & (after - before <= _BRIDGE_BEAMS + 1)
                    & (valid_before[np.maximum(after - 1, 0)] == valid_before[before])
                    & kept[before - 1] & (before > 0) & kept[after + 1])
            if fill.any():
                i, b, a = invalid[fill], before[fill], after[fill]
                rb, ra, rb1, ra1 = r[b], r[a], r[b - 1], r[np.minimum(a + 1, r.size - 1)]
                smooth = ((np.abs(rb + (rb - rb1) * (a - b) - ra) <= _BRIDGE_M)
                          & (np.abs(ra + (ra - ra1) * (a - b) - rb) <= _BRIDGE_M))
                i, b, a = i[smooth], b[smooth], a[smooth]
                on[i] = r[b] + (r[a] - r[b]) * (i - b) / (a - b)
        labels = segment_scan(on, scan.angle_min_rad, scan.angle_increment_rad, c0_m=self.c0_m, n_min=2,
                              grazing_deg=self.rigid_grazing_deg)[0][keep]
        # clusters are beam-order runs: the first and last kept point of each
        runs = np.flatnonzero(labels >= 0)
        if runs.size == 0:
            return out, labels
        lab = labels[runs]
        new_cluster = np.r_[True, lab[1:] != lab[:-1]]
        first = runs[new_cluster]
        last = runs[np.r_[lab[1:] != lab[:-1], True]]
        chord = np.hypot(*(local[last] - local[first]).T)
        # one piece: no gap between consecutive points wider than rigid_max_gap of the chord
        gap = np.zeros(runs.size)  # gap[i]: from point i to point i + 1 of the same cluster, else 0
        d = np.diff(local[runs], axis=0)
        gap[:-1] = np.where(new_cluster[1:], 0.0, np.hypot(d[:, 0], d[:, 1]))
        piece = np.maximum.reduceat(gap, np.flatnonzero(new_cluster)) < self.rigid_max_gap * chord
        long = piece & (chord >= self.rigid_min_m)
        kept = np.flatnonzero(piece & ~long & (chord >= min(self.rigid_keep_m, self.rigid_min_m)))
        if kept.size and prev is not None and len(prev):
            # hysteresis: near the rigid points of the scanner's previous scan (world frame)
            d, _ = cKDTree(prev).query(world[runs], distance_upper_bound=self.rigid_join_m)
            near = np.zeros(int(lab.max()) + 1, bool)
            near[lab[np.isfinite(d)]] = True
            long[kept] = near[labels[first[kept]]]
        if not long.any():
            return out, labels
        new = np.full(int(lab.max()) + 1, -1, np.int64)
        new[labels[first[long]]] = np.arange(int(long.sum()))
        out[runs] = new[lab]
        return out, labels

    # ---------------------------------------------------------------------------------------------
    def foreground_points(self, t_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """The pooled foreground points of every scanner with a scan within ``max_age_s`` of ``t_ns``.

        Returns
        -------
        points_m : (n, 2) float64
            World frame, metres, grouped by scanner in configuration order.
        scanner : (n,) int64
            Index into :attr:`scanners` of the scanner each point came from.
        """
        points, owner, _, _ = self._pooled(t_ns)
        return points, owner

    def _pooled(self, t_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`foreground_points` and each point's rigid cluster and beam-order cluster, each numbered across
        scanners (-1: none)."""
        parts, owner, rigid, cluster = [], [], [], []
        n_rigid = n_cluster = 0
        for i, st in enumerate(self._scanners.values()):
            if st.t_ns is not None and abs(int(t_ns) - st.t_ns) <= self._max_age_ns and len(st.points_m):
                parts.append(st.points_m)
                owner.append(np.full(len(st.points_m), i, dtype=np.int64))
                rigid.append(np.where(st.rigid >= 0, st.rigid + n_rigid, -1))
                cluster.append(np.where(st.cluster >= 0, st.cluster + n_cluster, -1))
                n_rigid += int(st.rigid.max()) + 1 if st.rigid.size else 0
                n_cluster += int(st.cluster.max()) + 1 if st.cluster.size else 0
        if not parts:
            return np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
        return np.concatenate(parts), np.concatenate(owner), np.concatenate(rigid), np.concatenate(cluster)

    def rigid_objects(self, points_m: np.ndarray, rigid: np.ndarray,
                      cluster: np.ndarray | None = None) -> tuple[np.ndarray, int]:
        """The rigid objects of pooled points: rigid clusters (``rigid``, per point, -1 for none) closer than
        ``rigid_join_m`` are one (measured between points thinned to one per 0.1 m cell), and a point closer than
        that to one joins it, with the rest of its beam-order cluster (``cluster``, per point, -1 for a point
        alone). Returns each point's object (-1 for none; objects numbered from 0) and their number."""
        on = np.flatnonzero(rigid >= 0)
        out = np.full(len(points_m), -1, np.int64)
        if on.size == 0:
            return out, 0
        lab = np.unique(rigid[on], return_inverse=True)[1].reshape(-1)
        k = int(lab.max()) + 1
        comp = np.arange(k)
        if k > 1 and self.rigid_join_m > 0:
            # one point per cluster and 0.1 m cell: a car's side near a scanner has hundreds of points
            cell = np.floor(points_m[on] / _JOIN_CELL_M).astype(np.int64)
            _, pick = np.unique(np.column_stack([lab, cell]), axis=0, return_index=True)
            pairs = cKDTree(points_m[on[pick]]).query_pairs(self.rigid_join_m, output_type="ndarray")
            a, b = lab[pick[pairs[:, 0]]], lab[pick[pairs[:, 1]]]
            other = a != b
            if other.any():
                graph = coo_matrix((np.ones(int(other.sum())), (a[other], b[other])), shape=(k, k))
                k, comp = connected_components(graph, directed=False)
        out[on] = comp[lab]
        loose = np.flatnonzero(rigid < 0)
        if loose.size and self.rigid_join_m > 0:
            d, i = cKDTree(points_m[on]).query(points_m[loose], distance_upper_bound=self.rigid_join_m)
            near = np.isfinite(d)
            out[loose[near]] = comp[lab[i[near]]]
            if cluster is not None and near.any():
                # the rest of each touched beam-order cluster comes along (not half a piece of a car)
                whole = cluster[loose[near]]
                touched = whole >= 0
                if touched.any():
                    of = np.full(int(cluster.max()) + 2, -1, np.int64)  # (its last entry, for cluster -1, stays -1)
                    of[whole[touched]] = out[loose[near]][touched]
                    rest = loose[~near]
                    out[rest] = of[cluster[rest]]
        return out, k

    def objects(self, t_ns: int) -> tuple[np.ndarray, Segments, np.ndarray, int]:
        """Everything :meth:`detect` finds at ``t_ns``, as arrays: the pooled points ``(n, 2)`` (those of
        :meth:`foreground_points`), the two-feet :class:`Segments` of the points that are not part of a rigid
        object (``labels`` and ``foot`` over all ``n`` points, ``-1`` on the rigid objects'), and each point's
        rigid object (``-1`` for none) with their number."""
        points, _, seg, obj, k = self._objects(t_ns)
        return points, seg, obj, k

    def _objects(self, t_ns: int) -> tuple[np.ndarray, np.ndarray, Segments, np.ndarray, int]:
        """:meth:`objects` with each point's scanner (index into :attr:`scanners`) after the points."""
        points, owner, rigid, cluster = self._pooled(t_ns)
        obj, k = self.rigid_objects(points, rigid, cluster)
        if k == 0:
            return points, owner, self.segment(points), obj, 0
        free = np.flatnonzero(obj < 0)
        seg = self.segment(points[free])
        labels = np.full(len(points), -1, np.int64)
        labels[free] = seg.labels
        foot = np.full(len(points), -1, seg.foot.dtype)
        foot[free] = seg.foot
        return points, owner, dataclasses.replace(seg, labels=labels, foot=foot), obj, k

    def _scanner_sets(self, groups: np.ndarray, owner: np.ndarray, n: int) -> list[np.ndarray]:
        """For each of ``n`` groups (``groups`` per point, ``-1`` for none), the names of the scanners whose points
        it holds, sorted (one read-only array per distinct set, shared)."""
        on = groups >= 0
        k = len(self._scanners)
        # which scanners each group has points of: (n, k)
        has = np.bincount(groups[on] * k + owner[on], minlength=n * k).reshape(n, k) > 0
        names, out = self._names_of_set, []
        for key in map(tuple, has.tolist()):
            a = names.get(key)
            if a is None:
                a = names[key] = np.array(sorted(s for s, yes in zip(self._scanners, key, strict=True) if yes), str)
                a.flags.writeable = False
            out.append(a)
        return out

    def segments(self, t_ns: int) -> tuple[np.ndarray, Segments]:
        """The two-feet part of :meth:`objects`: the pooled points ``(n, 2)`` and their :class:`Segments` (the
        points of rigid objects in no segment)."""
        points, seg, _, _ = self.objects(t_ns)
        return points, seg

    def segment(self, points_m: np.ndarray) -> Segments:
        """The two-feet segments (B4, B5) of pooled foreground points ``(n, 2)``, with this detector's
        parameters (:meth:`segments` of :meth:`foreground_points`)."""
        return mean_shift_segments(points_m, self.bandwidth_m, n_min=self.min_segment_points, merge_m=self.merge_m,
                                   pair_feet_m=self.pair_feet_m, foot_radius_m=self.foot_radius_m,
                                   d_one_foot_m=self.d_one_foot_m)

    def detect(self, t_ns: int) -> list[Detection]:
        """Two-feet segments at ``t_ns`` as detections (world frame), one per segment.

        Each detection has ``position_m`` = the segment centre (mean point), ``covariance_m2`` =
        ``min_sigma_m**2 I`` + the points' sample covariance, ``sensor`` = :attr:`sensor`, ``cls`` unknown
        (the classifier decides), and features ``"feet_m"`` (2, 2), ``"points_m"`` (k, 2),
        ``"inter_feet_m"`` () float, ``"one_foot"`` () bool, ``"mode_m"`` (2,) the mean-shift mode, ``"rigid"``
        () bool, ``"scanners"`` (s,) str the names of the scanners whose points it holds, sorted (what
        ``TrackState.sensors`` names when it confirms a track). The rigid objects (bicycles, cars: ``"rigid"``
        true) come after the two-feet segments; their position is the centre of the smallest rectangle around
        their points (``cv2.minAreaRect``), their covariance ``min_sigma_m**2 I`` + the points' second moments
        about it, and their feet and mode are the centre (no feet).
        """
        t_ns = int(t_ns)
        points, owner, seg, obj, n_obj = self._objects(t_ns)
        k = len(seg)
        out = []
        eye = self.min_sigma_m**2 * np.eye(2)
        if k:
            on = np.flatnonzero(seg.labels >= 0)
            order = on[np.argsort(seg.labels[on], kind="stable")]
            groups = np.split(points[order], np.cumsum(seg.n_points)[:-1])
            scanners = self._scanner_sets(seg.labels, owner, k)
            cov = seg.covariances_m2 + eye
            no = np.asarray(False)
            out = [Detection(t_ns, self.sensor, position_m=seg.centres_m[j], covariance_m2=cov[j],
                             features={"feet_m": seg.feet_m[j], "points_m": groups[j],
                                       "inter_feet_m": np.asarray(seg.inter_feet_m[j]),
                                       "one_foot": np.asarray(seg.one_foot[j]), "mode_m": seg.modes_m[j],
                                       "rigid": no, "scanners": scanners[j]})
                   for j in range(k)]
        if n_obj:
            on = np.flatnonzero(obj >= 0)
            order = on[np.argsort(obj[on], kind="stable")]
            groups = np.split(points[order], np.cumsum(np.bincount(obj[on], minlength=n_obj))[:-1])
            scanners = self._scanner_sets(obj, owner, n_obj)
            yes, zero, one = np.asarray(True), np.asarray(0.0), np.asarray(True)
            for g, sc in zip(groups, scanners, strict=True):
                # the centre of the smallest rectangle around the points: the vehicle's centre when its sides are
                # seen all round, not pulled towards the nearer scanner's denser points as the mean is
                m = g.mean(axis=0)  # (about the mean: float32 world coordinates far from the origin are coarse)
                c = m + np.asarray(cv2.minAreaRect((g - m).astype(np.float32))[0]) if len(g) >= 3 else m
                d = g - c
                out.append(Detection(t_ns, self.sensor, position_m=c, covariance_m2=d.T @ d / len(g) + eye,
                                     features={"feet_m": np.stack([c, c]), "points_m": g, "inter_feet_m": zero,
                                               "one_foot": one, "mode_m": c, "rigid": yes, "scanners": sc}))
        return out


_BRIDGE_BEAMS = 2  # invalid beams bridged inside a rigid object's side
_BRIDGE_M = 0.1  # where the ranges on each side of them run on smoothly to within this
_JOIN_CELL_M = 0.1  # rigid points are thinned to one per cell of this size to find the clusters that join

_BACKGROUND_ARGS = ("alpha", "beta", "gamma", "tau_fg_m", "n_init", "init", "bin_m")


def check_detector_params(params: Mapping[str, Any] | None, source: str = "laser") -> dict[str, Any]:
    """The keyword arguments of :class:`LaserPeopleDetector` in ``params`` (a pipeline file's ``[laser]`` table),
    checked: an unknown key or a bad value raises :class:`~fusiontrack.errors.ConfigError` naming ``source``, the
    key and (for an unknown key) the known ones.

    Returns
    -------
    dict
        A copy of ``params`` (empty for ``None``).
    """
    out = dict(params or {})
    signature = inspect.signature(LaserPeopleDetector).parameters
    known = [k for k in signature if k != "scanners"]
    unknown = sorted(set(out) - set(known))
    if unknown:
        raise ConfigError(f"{source}: unknown laser detector parameter(s) {', '.join(map(str, unknown))}; known: "
                          f"{', '.join(sorted(known))}")
    for key, value in out.items():  # numbers given as text: named here (the converters' messages name no key)
        default = signature[key].default
        numeric = key in ("gamma", "merge_m", "pair_feet_m", "rigid_min_m") or (
            isinstance(default, int | float) and not isinstance(default, bool))
        if numeric and isinstance(value, str | bool):
            raise ConfigError(f"{source}: {key}: expected a number, got {value!r}")
    try:
        LaserPeopleDetector({"check": np.eye(3)}, **out)
    except (ValueError, TypeError) as err:
        raise ConfigError(f"{source}: {err}") from None
    return out


def first_scans(rec: Any, lasers: Sequence[str], time_source: str = "header") -> dict[str, Any]:
    """sensor -> the first :class:`~fusiontrack.types.LaserScan` of each of the laser topics of an open recording
    (their frame ids and geometries); a topic without scans has no entry."""
    first: dict[str, Any] = {}
    if lasers:
        for scan in rec.messages(list(lasers), time_source=time_source):
            first.setdefault(scan.sensor, scan)
            if len(first) == len(lasers):
                break
    return first


def recorded_laser_poses(rec: Any, first: Mapping[str, Any], world_frame: str = "world") -> dict[str, np.ndarray]:
    """sensor -> laser2world ``(4, 4)`` of the scanners in ``first`` (:func:`first_scans`) from the recording's
    ``/tf_static``: the pose of the scan's frame, or else of the sensor's name, in ``world_frame``; a scanner without
    one has no entry. How :func:`detector_for_recording` poses a scanner its caller did not."""
    tree = rec.transform_tree(["/tf_static"])
    poses = {}
    for sensor, scan in first.items():
        frame = next((f for f in (scan.frame_id, sensor) if f and tree.has_path(f, world_frame)), None)
        if frame is not None:
            poses[sensor] = tree.get(frame, world_frame)
    return poses


def detector_for_recording(rec: Any, lasers: list[str], *, time_source: str = "header", world_frame: str = "world",
                           background: str = "learn", detector_params: Mapping[str, Any] | None = None,
                           laser_poses: Mapping[str, Any] | None = None,
                           ) -> tuple[LaserPeopleDetector, dict[str, np.ndarray]]:
    """A :class:`LaserPeopleDetector` for the laser topics of an open recording.

    Each scanner is posed by ``laser_poses`` when it names it (the user's word, e.g. a pipeline file's
    ``[sensors.<name>] pose``), else by ``/tf_static`` (its frame, or else its sensor name, to ``world_frame``;
    the identity when there is no such transform, i.e. the laser frame is the world).

    Parameters
    ----------
    rec : Recording
        Open recording.
    lasers : list of str
        Laser topics.
    time_source, world_frame :
        As in :func:`~fusiontrack.tracking.track_recording`.
    background : ``"learn"`` or ``"none"``
        ``"none"``: a scanner on a moving platform; every return is foreground (the background is set to "no
        return" and never learns, ``alpha = gamma = 0`` unless ``detector_params`` say otherwise).
    detector_params : mapping, optional
        Keyword arguments of the detector.
    laser_poses : mapping of sensor or topic -> laser2world, optional
        ``(3, 3)`` 2-D poses or ``(4, 4)`` transforms that override ``/tf_static``.

    Returns
    -------
    detector, poses : the detector and each sensor's laser2world.
    """
    from fusiontrack.geometry import make_transform

    if background not in ("learn", "none"):
        raise ConfigError(f"background: expected 'learn' or 'none', got {background!r}")
    dparams = check_detector_params(detector_params)
    first = first_scans(rec, lasers, time_source)
    recorded = recorded_laser_poses(rec, first, world_frame)
    given = dict(laser_poses or {})
    given.update({rec.sensor_of(t): given[t] for t in lasers if t in given})  # given by topic
    unused = sorted(k for k in laser_poses or {} if k not in first and k not in lasers)
    if unused:
        log.warning("%s: poses given for %s, which %s no laser tracked here (tracked: %s)", rec.paths[0],
                    ", ".join(unused), "is" if len(unused) == 1 else "are", ", ".join(lasers))
    poses: dict[str, np.ndarray] = {}
    unposed = []
    for sensor in first:
        pose = given.get(sensor)
        if pose is not None:
            try:
                R2, t2 = planar_pose(pose, f"laser_poses[{sensor!r}]")
            except ValueError as err:
                raise ConfigError(str(err)) from err
            if np.shape(pose) == (3, 3):  # a 2-D pose: the same transform in 3-D, on the floor
                R = np.eye(3)
                R[:2, :2] = R2
                pose = make_transform(R, [t2[0], t2[1], 0.0])
        if pose is None:
            pose = recorded.get(sensor)
        if pose is None:
            unposed.append(sensor)
        poses[sensor] = np.eye(4) if pose is None else np.asarray(pose, np.float64)
    if not poses:
        raise ConfigError(f"{rec.paths[0]}: the laser topics {', '.join(lasers)} hold no scans")
    if len(poses) > 1 and unposed:
        log.warning("%s: no /tf_static transform from %s to %r, so %s at the world origin: the %d scanners' "
                    "detections will not line up (record /tf_static, or give each scanner's pose in a pipeline "
                    "file: [sensors.<name>] kind = \"laser\", topic, pose = {x, y, yaw_deg})", rec.paths[0],
                    ", ".join(unposed), world_frame,
                    "they are taken" if len(unposed) > 1 else "it is taken", len(poses))
    if background == "none":
        dparams = {**UNLEARNT_BACKGROUND, **dparams}
    try:
        detector = LaserPeopleDetector(poses, **dparams)
    except ValueError as err:  # a bad pose given in laser_poses
        raise ConfigError(str(err)) from err
    if background == "none":
        for scan in first.values():
            learn_no_return(detector, scan, dparams)
    return detector, poses


UNLEARNT_BACKGROUND = {"alpha": 0.0, "gamma": 0.0}
"""Detector parameters of a scanner on a moving platform (``background = "none"``): backgrounds that never learn
(with :func:`learn_no_return` first)."""


def learn_no_return(detector: LaserPeopleDetector, scan: LaserScan, dparams: Mapping[str, Any]) -> None:
    """Make ``scan``'s scanner's background "no return" on every beam (its ``n_init`` scans holding nothing,
    just before ``scan``), so that every return is foreground: a scanner on a moving platform."""
    bg = BeamBackground(1, **{k: v for k, v in dparams.items() if k in _BACKGROUND_ARGS})
    blank = np.full(scan.n_beams, np.nan, np.float32)
    for i in range(bg.n_init):
        detector.update(LaserScan(scan.t_ns - (bg.n_init - i) * 1_000_000, scan.sensor, scan.frame_id,
                                  scan.angle_min_rad, scan.angle_increment_rad, scan.range_min_m,
                                  scan.range_max_m, blank))
