"""Adaptive horizontal bias between a camera and laser scanners (seed 000; ALGORITHMS.md A0, A6–A10).

For each tracked image blob: the candidate region of the scan (A6), clustering (A8), the cluster chosen by
the discriminant — volume x difference from the laser background x closeness to the region's centre (A9) —
and the bias learned at rate ``rho`` from the angle between the image direction and the chosen cluster
(A10). :class:`HorizontalBiasEstimator` holds the state (laser backgrounds, recent scans, the bias, its
history) and gives the corrected camera that everything downstream should use.

Geometry (:mod:`~fusiontrack.calibration.regions`). Every angle is an azimuth seen from the camera centre, so
A6, written for a camera and a laser on one vertical axis, works for any placement, and the bias is the
camera's yaw error: ``camera.with_yaw_offset(bias)`` is the corrected camera. Several lasers may be used;
A8 runs once per scan, so a cluster is the same object in every region that sees it, which is what A9's rule
for overlapping regions needs, and each region counts only its own beams of a cluster (A9's volume and
background terms).

Departures from the published form, each a parameter of :class:`BiasParams` (all [RECON]): A8 runs on the A7
foreground beams with background beams between them skipped, so the wall seen between a walker's legs does
not cut the walker in two (:mod:`~fusiontrack.calibration.clusters`); a cluster is placed at the mean of its
two feet (B5) moved to the legs' axes, must be at least a hip width wide, and must lie at the distance the
box's feet give (an elevated camera knows it); boxes too wide for one upright person are skipped; residuals
pass an adaptive 3-sigma gate. The image side uses the blob's pixel centroid rather than the box centre when
it is given (:func:`~fusiontrack.calibration.regions.candidate_regions`). With A6-A10 as published, walking
people (legs swinging ±0.3 m about their axis, leaning silhouettes, merged blobs) leave the bias 0.24 degrees
off on average and wandering by ±0.4; with these, 0.01 and ±0.04 (``benchmarks/bias.py``).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fusiontrack.geometry import PinholeCamera, transform_points, wrap_angle
from fusiontrack.laser.background import BeamBackground, learn_short_backgrounds
from fusiontrack.types import LaserScan

from .clusters import foreground_clusters
from .regions import (
    CandidateRegions,
    candidate_regions,
    pixel_azimuths,
    points_in_regions,
    regions_overlap,
    validate_boxes,
)
from .selection import bias_update, discriminant, select_clusters

__all__ = [
    "BiasHistory",
    "BiasParams",
    "BiasStep",
    "CandidateRegions",
    "HorizontalBiasEstimator",
    "bias_update",
    "candidate_regions",
    "discriminant",
    "pixel_azimuths",
    "points_in_regions",
    "regions_overlap",
    "select_clusters",
]

log = logging.getLogger(__name__)

SIGMA_PER_MEAN_ABS = math.sqrt(math.pi / 2)
"""``σ / E|e|`` of a zero-mean normal residual: turns the running mean absolute residual into a sigma."""


@dataclass(frozen=True, slots=True)
class BiasParams:
    """Parameters of the adaptive bias (ALGORITHMS.md A6–A10). Angles in radians, lengths in metres.

    Attributes
    ----------
    rho : float
        A10 learning rate, (0, 1] (0.1; the paper also uses 0.5).
    warm_start : bool
        A10 with a warm start [RECON] (False: A10 as published, whose saturation the paper's Fig. 6 shows).
        The ``n``-th update uses ``rho_n = max(rho, 1 / n)``, so the bias is the mean of its first ``1 / rho``
        targets ``b + ē`` (each a measurement of the whole bias) and is then smoothed at ``rho`` as A10's. A10
        alone starts at the calibrated camera and forgets that start slowly (a 3-degree error at ``rho = 0.1``
        is 0.044 degree off after 40 updates); the mean has no such lag, and after ``n`` updates its noise is
        that of A10's settled bias when ``n = (2 - rho) / rho`` (19 at 0.1), the variance of exponential
        smoothing. As MOG2 learns its background at ``1 / min(n, history)``. (The first update replaces an
        estimator's ``initial_bias_rad``.)
    margin_rad : float
        A6 margin ``m`` (1 degree).
    max_margin_rad : float
        A6 widening cap (10 degrees): after ``widen_after`` frames in a row with objects but no valid cluster
        the margin doubles, up to this; every valid update halves it again, down to ``margin_rad``.
    widen_after : int
        A6 ``N_widen`` (10); 0 = never widen.
    c0_m, n_min : float, int
        A8 clustering of the A7 foreground beams, background beams between them skipped
        (:func:`~fusiontrack.calibration.clusters.foreground_clusters`): ``C0`` 0.30 m (A8: 0.20 m; a little more
        keeps both legs of a walker in one cluster) and at least 2 points [RECON].
    foreground_only : bool
        Cluster the foreground beams, skipping background beams (True) [RECON], or every valid beam in beam
        order, a gap ending a cluster (False: A8 as published; walls are clusters too, left out by A9's
        validity test).
    tau_fg_m : float
        A7 foreground threshold and A9 validity: a chosen cluster must differ from the background by at least
        this on average (0.20 m).
    clarity : float
        A9 clear-winner ratio of :func:`select_clusters` (2.0) [RECON].
    leg_radius_m : float
        The laser sees the near surface of legs; cluster centres are moved ``(pi / 4) leg_radius_m`` away from
        the laser to the legs' axes (0.06 m; 0 = off) [RECON].
    min_width_m : float
        Narrowest cluster (chord from its first to its last point) that may be chosen (0.20 m) [RECON]: one
        leg shows at most ~0.12 m, and a walker with one leg hidden behind the other has a centre up to half a
        stride off their axis; two visible legs are at least a hip width (~0.2 m) apart. 0 = off.
    range_gate_m : float or None
        Distance gate of :func:`points_in_regions` (1.0 m) [RECON]: an elevated camera fixes how far away a
        box's feet are, and that distance does not depend on the yaw bias, so clusters more than this nearer
        or farther are not candidates. None = A6 as published (wedges only).
    gate_sigmas : float
        Residual gate [RECON]: an object's ``|e_k|`` above ``gate_sigmas`` residual sigmas (or above
        ``margin_rad``, whichever is larger) is left out of the update, a wrong cluster rather than noise. The
        sigma is learnt online (running mean of ``|e_k|`` at rate ``scale_rate``; a rejected residual counts as
        the gate, at an eighth of the rate), starting at twice the candidate regions' half-width (nothing in
        the capture range is cut at first). 0 = off (A10 as published).
    scale_rate : float
        Rate of that running mean, (0, 1] (0.1).
    centre : {"feet", "centroid"}
        Where a cluster is: the mean of its two feet (B5's split, each foot weighted equally, so the leg
        nearer the laser, which shows more points, does not pull the centre) or the mean of its points
        (:func:`~fusiontrack.calibration.clusters.foreground_clusters`).
    sigma_fraction : float
        A9 ``σ_θ = sigma_fraction · h_θ`` (0.5).
    max_scan_dt_s : float
        Largest time between an image and the scan used with it (0.05 s).
    border_px : float
        Boxes within this many pixels of the left or right image edge are cut off and skipped (2 px).
    min_aspect : float
        Boxes less than this many times as tall as wide are skipped (1.5) [RECON]: not one whole upright person
        but a group the blob tracker did not split, a person cut by the image's edge or joined by something
        else. In simulation their residuals are 3-5 times larger than those of taller boxes. 0 = off.
    bg_alpha, bg_beta, bg_n_init : float, float, int
        A7 laser background (0.005, 0.05, 50 scans).
    """

    rho: float = 0.1
    warm_start: bool = False
    margin_rad: float = math.radians(1.0)
    max_margin_rad: float = math.radians(10.0)
    widen_after: int = 10
    c0_m: float = 0.30
    n_min: int = 2
    foreground_only: bool = True
    tau_fg_m: float = 0.20
    clarity: float = 2.0
    leg_radius_m: float = 0.06
    min_width_m: float = 0.20
    range_gate_m: float | None = 1.0
    gate_sigmas: float = 3.0
    scale_rate: float = 0.1
    centre: str = "feet"
    sigma_fraction: float = 0.5
    max_scan_dt_s: float = 0.05
    border_px: float = 2.0
    min_aspect: float = 1.5
    bg_alpha: float = 0.005
    bg_beta: float = 0.05
    bg_n_init: int = 50

    def __post_init__(self) -> None:
        if not 0 < self.rho <= 1:
            raise ValueError(f"BiasParams.rho: expected a learning rate in (0, 1], got {self.rho!r}")
        if not isinstance(self.warm_start, bool | np.bool_):
            raise ValueError(f"BiasParams.warm_start: expected True or False, got {self.warm_start!r}")
        if not 0 <= self.margin_rad <= self.max_margin_rad < math.pi / 2:
            raise ValueError("BiasParams.margin_rad, max_margin_rad: expected 0 <= margin_rad <= max_margin_rad "
                             f"< pi/2, got {self.margin_rad!r}, {self.max_margin_rad!r}")
        for name in ("widen_after", "n_min", "bg_n_init"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < (0 if name == "widen_after" else 1):
                raise ValueError(f"BiasParams.{name}: expected an integer >= {0 if name == 'widen_after' else 1}, "
                                 f"got {v!r}")
        for name in ("c0_m", "tau_fg_m", "leg_radius_m", "min_width_m", "border_px", "min_aspect"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"BiasParams.{name}: expected a finite value >= 0, got {v!r}")
        for name in ("sigma_fraction", "max_scan_dt_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"BiasParams.{name}: expected a finite value > 0, got {v!r}")
        if self.range_gate_m is not None and not (math.isfinite(self.range_gate_m) and self.range_gate_m > 0):
            raise ValueError(f"BiasParams.range_gate_m: expected None or a finite distance > 0, got "
                             f"{self.range_gate_m!r}")
        if not (math.isfinite(self.gate_sigmas) and self.gate_sigmas >= 0):
            raise ValueError(f"BiasParams.gate_sigmas: expected a finite value >= 0, got {self.gate_sigmas!r}")
        if not 0 < self.scale_rate <= 1:
            raise ValueError(f"BiasParams.scale_rate: expected a rate in (0, 1], got {self.scale_rate!r}")
        if self.centre not in ("feet", "centroid"):
            raise ValueError(f"BiasParams.centre: expected 'feet' or 'centroid', got {self.centre!r}")
        if not (math.isfinite(self.clarity) and self.clarity >= 1):
            raise ValueError(f"BiasParams.clarity: expected a ratio >= 1, got {self.clarity!r}")
        for name in ("bg_alpha", "bg_beta"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"BiasParams.{name}: expected a learning rate in [0, 1], got {getattr(self, name)!r}")


@dataclass(frozen=True, slots=True, eq=False)
class BiasStep:
    """What one camera frame did to the bias, and the fused objects (A11). ``n`` objects (boxes given).

    Attributes
    ----------
    t_ns : int
    bias_rad : float
        Bias after this frame.
    n_used : int
        Objects whose residual entered the update (0 = no update).
    mean_residual_rad : float
        ``ē`` (NaN when no object had a valid cluster).
    margin_rad : float
        A6 margin used this frame.
    object_ids : (n,) int64
    boxes_px : (n, 4) float64
        The boxes given.
    overlapping : (n,) bool
        The object's candidate region overlaps another used object's region this frame (A9's hard case).
    position_m : (n, 2) float64
        World floor position of the chosen cluster (legs' axis), NaN where none: A11's fused position.
    laser : tuple of str
        Laser whose cluster was chosen per object ("" where none).
    residual_rad : (n,) float64
        ``e_k`` per object (NaN where none).
    score : (n,) float64
        ``g`` of the chosen cluster (0 where none).
    used : (n,) bool
        The residual passed the gate and entered the update.
    """

    t_ns: int
    bias_rad: float
    n_used: int
    mean_residual_rad: float
    margin_rad: float
    object_ids: np.ndarray
    boxes_px: np.ndarray
    overlapping: np.ndarray
    position_m: np.ndarray
    laser: tuple[str, ...]
    residual_rad: np.ndarray
    score: np.ndarray
    used: np.ndarray


@dataclass(frozen=True, slots=True, eq=False)
class BiasHistory:
    """The bias over time, one row per camera frame given to :meth:`HorizontalBiasEstimator.update`.

    Attributes
    ----------
    t_ns : (n,) int64
    bias_rad : (n,) float64
    n_used : (n,) int64
    margin_rad : (n,) float64
    """

    t_ns: np.ndarray
    bias_rad: np.ndarray
    n_used: np.ndarray
    margin_rad: np.ndarray

    def __len__(self) -> int:
        return int(self.t_ns.size)


@dataclass(slots=True, eq=False)
class _Laser:
    laser2world: np.ndarray
    background: BeamBackground | None = None
    scans: deque[tuple[LaserScan, np.ndarray]] = field(default_factory=lambda: deque(maxlen=8))
    primed_ns: int | None = None  # scans up to this time taught the background already (prime)
    primed_bg: np.ndarray | None = None  # the background the priming left (read-only copy)


class HorizontalBiasEstimator:
    """Seed 000's adaptive horizontal bias between one camera and one or more lasers (ALGORITHMS.md A0–A10).

    Feed every scan to :meth:`observe_scan` (it learns the A7 background and keeps the last few scans) and
    every camera frame's object boxes to :meth:`update`; use :attr:`corrected_camera` downstream. Online, no
    beam is foreground, so no update can happen, until each laser has sent ``bg_n_init`` scans (2 s at 25 Hz);
    a recording can be read ahead first with :meth:`prime`.

    Parameters
    ----------
    camera : PinholeCamera
        The camera as calibrated (the pose to correct).
    lasers : mapping of sensor name -> (4, 4) float
        ``laser2world`` of each laser whose scans will be given (the ``sensor`` of the scans).
    params : BiasParams, optional
    initial_bias_rad : float
        Starting bias (0).
    """

    def __init__(self, camera: PinholeCamera, lasers: Mapping[str, Any], params: BiasParams | None = None,
                 initial_bias_rad: float = 0.0) -> None:
        if not isinstance(camera, PinholeCamera):
            raise TypeError(f"camera: expected a PinholeCamera, got {type(camera).__name__}")
        if not lasers:
            raise ValueError("lasers: expected at least one laser (sensor name -> laser2world)")
        self.camera = camera
        self.params = BiasParams() if params is None else params
        self._lasers: dict[str, _Laser] = {}
        for name, T in lasers.items():
            T = np.array(T, dtype=np.float64)
            if T.shape != (4, 4) or not np.all(np.isfinite(T)):
                raise ValueError(f"lasers[{name!r}]: expected a finite (4, 4) laser2world, got shape {T.shape}")
            self._lasers[str(name)] = _Laser(T)
        if not math.isfinite(initial_bias_rad):
            raise ValueError(f"initial_bias_rad: expected a finite angle, got {initial_bias_rad}")
        self._bias = float(initial_bias_rad)
        self._margin = self.params.margin_rad
        self._misses = 0
        self._scale: float | None = None
        self._updates = 0
        self._hist: list[tuple[int, float, int, float]] = []

    # -- state -------------------------------------------------------------------------------------

    @property
    def bias_rad(self) -> float:
        """The current bias ``b``, radians."""
        return self._bias

    @property
    def lasers(self) -> tuple[str, ...]:
        """Sensor names of the lasers, in the order given."""
        return tuple(self._lasers)

    @property
    def corrected_camera(self) -> PinholeCamera:
        """The camera turned by the current bias about the vertical through its centre."""
        return self.camera.with_yaw_offset(self._bias)

    @property
    def history(self) -> BiasHistory:
        """The bias after every :meth:`update` so far."""
        h = self._hist
        return BiasHistory(np.array([r[0] for r in h], np.int64), np.array([r[1] for r in h], np.float64),
                           np.array([r[2] for r in h], np.int64), np.array([r[3] for r in h], np.float64))

    # -- input -------------------------------------------------------------------------------------

    def background(self, sensor: str) -> BeamBackground | None:
        """The A7 background model of one laser (``None`` before its first scan)."""
        laser = self._lasers.get(sensor)
        if laser is None:
            raise ValueError(f"sensor: {sensor!r} is not one of the lasers {sorted(self._lasers)}")
        return laser.background

    def prime(self, scans: Iterable[LaserScan], max_scans: int | None = None) -> dict[str, int]:
        """Learn every laser's background (A7) from the start of a recording before the bias pass reads it.

        Online, no beam is foreground until a laser has sent ``bg_n_init`` scans (2 s at 25 Hz), so the bias
        cannot move during the recording's first seconds. A recording can be read ahead: this takes ``scans``
        (the laser scans of the stream the pass will read, from its start, on the same clock) until every
        laser's background is initialised, then forgets the scans but keeps the backgrounds. The pass then
        classifies the scans the priming read against the background learnt from them, *without learning from
        them again*, and learns from every later scan as usual (as
        :meth:`~fusiontrack.laser.LaserPeopleDetector.prime` does): from the first scan after the priming on,
        each background is the one online learning would have reached (the same numbers); only the first scans
        differ (they have foregrounds, so the first camera frames can update the bias).

        Parameters
        ----------
        scans : iterable of LaserScan
            The recording's scans from its start, in time order (as :meth:`observe_scan` takes them). Call
            before the first :meth:`observe_scan`.
        max_scans : int, optional
            Stop after this many scans even if some laser is not initialised (a silent laser must not make the
            priming read the whole recording). Default ``4 * bg_n_init * number of lasers``.

        Returns
        -------
        dict sensor -> int
            Scans each laser's priming took. A laser whose background is not initialised at the end (too few
            scans) is reset to nothing learnt, so that the pass learns it online from its first scan, as
            without priming; unless the priming read the whole recording: then it is learnt from the scans there
            are (:func:`~fusiontrack.laser.background.learn_short_backgrounds`).
        """
        if isinstance(max_scans, bool) or not (max_scans is None or (isinstance(max_scans, int | np.integer)
                                                                      and max_scans >= 0)):
            raise ValueError(f"max_scans: expected None or an integer >= 0, got {max_scans!r}")
        if any(laser.background is not None for laser in self._lasers.values()):
            raise ValueError("prime: the estimator has already seen scans; prime it before the first observe_scan")
        limit = 4 * self.params.bg_n_init * len(self._lasers) if max_scans is None else int(max_scans)
        used = dict.fromkeys(self._lasers, 0)
        last: dict[str, int] = {}
        for i, scan in enumerate(scans):
            if i >= limit:
                break
            self.observe_scan(scan)
            used[scan.sensor] += 1
            last[scan.sensor] = int(scan.t_ns)
            if all(las.background is not None and las.background.initialised for las in self._lasers.values()):
                break
        else:  # the whole recording was read: a laser short of bg_n_init scans sent all it will
            learn_short_backgrounds(self._lasers, used)
        for name, laser in self._lasers.items():
            laser.scans.clear()
            if laser.background is not None and laser.background.initialised:
                laser.primed_ns = last[name]
                laser.primed_bg = laser.background.background_m.copy()
                laser.primed_bg.setflags(write=False)
            else:
                laser.background, laser.primed_ns, laser.primed_bg = None, None, None
        return used

    def observe_scan(self, scan: LaserScan) -> None:
        """Learn the laser background (A7) from one scan and keep it for the next camera frames.

        A scan :meth:`prime` has learnt from already (at or before the last scan it read from that laser) is
        kept with the primed background and not learnt from again.
        """
        laser = self._lasers.get(scan.sensor)
        if laser is None:
            raise ValueError(f"scan.sensor: {scan.sensor!r} is not one of the lasers {sorted(self._lasers)}")
        if laser.primed_ns is not None:
            if scan.t_ns <= laser.primed_ns:  # read by the priming: classify only
                if laser.primed_bg is not None and laser.primed_bg.size == scan.ranges_m.size:
                    laser.scans.append((scan, laser.primed_bg))  # (else from before a beam-count change: skipped)
                return
            laser.primed_ns, laser.primed_bg = None, None
        p = self.params
        if laser.background is None or laser.background.n_beams != scan.ranges_m.size:
            laser.background = BeamBackground(max(scan.ranges_m.size, 1), p.bg_alpha, p.bg_beta, p.tau_fg_m,
                                              p.bg_n_init, range_min_m=float(scan.range_min_m),
                                              range_max_m=float(scan.range_max_m))
            laser.scans.clear()
        laser.background.update(scan.ranges_m)
        if laser.background.initialised:
            laser.scans.append((scan, laser.background.background_m.copy()))

    def update(self, t_ns: int, boxes_px: Any, object_ids: Any = None, usable: Any = None,
               centres_px: Any = None) -> BiasStep:
        """One camera frame: regions, clusters, discriminant, selection, bias update (A6–A10).

        Parameters
        ----------
        t_ns : int
            Frame time, on the scans' clock.
        boxes_px : (n, 4) float
            The tracked objects' boxes in this frame.
        object_ids : (n,) int, optional
            Their ids (default ``0 .. n-1``).
        usable : (n,) bool, optional
            Objects allowed to update the bias (e.g. not in a group, seen this frame); all by default. Boxes
            cut by the left or right image edge, or too wide for one person (``min_aspect``), are never used.
        centres_px : (n, 2) float, optional
            The point of each object whose direction is compared with its cluster (default: the box centre;
            the blob's pixel centroid is better, see :func:`candidate_regions`).

        Returns
        -------
        BiasStep
        """
        p = self.params
        boxes = np.asarray(boxes_px, dtype=np.float64).reshape(-1, 4) if np.size(boxes_px) else np.zeros((0, 4))
        n = boxes.shape[0]
        ids = np.arange(n, dtype=np.int64) if object_ids is None else np.asarray(object_ids, np.int64).reshape(-1)
        use = np.ones(n, bool) if usable is None else np.asarray(usable, bool).reshape(-1)
        if ids.shape != (n,) or use.shape != (n,):
            raise ValueError(f"object_ids, usable: expected {n} values each (one per box), got {ids.size}, {use.size}")
        if n:
            validate_boxes(boxes)
        use = use & (boxes[:, 0] >= p.border_px) & (boxes[:, 2] <= self.camera.width - p.border_px) \
            & (boxes[:, 3] - boxes[:, 1] >= p.min_aspect * (boxes[:, 2] - boxes[:, 0]))
        position = np.full((n, 2), np.nan)
        residual = np.full(n, np.nan)
        score = np.zeros(n)
        laser_of = [""] * n
        overlapping = np.zeros(n, bool)
        used = np.zeros(n, bool)
        scans = self._scans_near(int(t_ns))
        e_bar, n_used = math.nan, 0
        if use.any() and scans:
            idx = np.flatnonzero(use)
            cen = None if centres_px is None else np.asarray(centres_px, np.float64).reshape(n, 2)[idx]
            regions = candidate_regions(boxes[idx], self.camera, self._bias, self._margin, centres_px=cen)
            overlapping[idx] = regions_overlap(regions).any(axis=1)
            cand = self._candidates(regions, scans)
            if cand is not None:
                g, valid, az, xy, owner = cand
                choice = select_clusters(g, valid, p.clarity)
                ok = choice >= 0
                sel = idx[ok]
                c = choice[ok]
                residual[sel] = wrap_angle(az[c] - regions.centre_rad[ok])
                score[sel] = g[ok, c]
                position[sel] = xy[c]
                for j, cj in zip(sel, c, strict=True):
                    laser_of[j] = owner[cj]
                keep = self._gate(residual[sel], regions.half_width_rad[ok])
                used[sel[keep]] = True
                rho = max(p.rho, 1.0 / (self._updates + 1)) if p.warm_start else p.rho
                bias, e_bar, updated = bias_update(self._bias, residual[used], score[used], rho,
                                                   float(np.mean(regions.half_width_rad[ok])) if ok.any() else 0.0)
                if updated:
                    self._bias = bias
                    self._updates += 1
                    n_used = int(used.sum())
                else:
                    used[:] = False
            self._adapt_margin(n_used > 0)
        self._hist.append((int(t_ns), self._bias, n_used, self._margin))
        return BiasStep(int(t_ns), self._bias, n_used, e_bar, self._margin, ids, boxes, overlapping, position,
                        tuple(laser_of), residual, score, used)

    # -- internals -----------------------------------------------------------------------------------

    def _gate(self, e: np.ndarray, half_width: np.ndarray) -> np.ndarray:
        """Which residuals pass the adaptive gate; learns the residual scale from this frame's residuals."""
        p = self.params
        if e.size == 0 or p.gate_sigmas == 0:
            return np.ones(e.size, bool)
        if self._scale is None:  # before any residual: twice the regions' half-width (the capture range)
            self._scale = 2.0 * float(np.mean(half_width)) / (p.gate_sigmas * SIGMA_PER_MEAN_ABS)
        gate = max(p.gate_sigmas * SIGMA_PER_MEAN_ABS * self._scale, p.margin_rad)
        keep = np.abs(e) <= gate
        # accepted residuals teach the scale at scale_rate; rejected ones (counted at the gate) only at
        # scale_rate / 8, so a run of wrong matches (a group box) barely opens the gate while a real jump of the
        # bias still reopens it within a few dozen frames
        rate = np.where(keep, p.scale_rate, p.scale_rate / 8)
        self._scale += float(np.mean(rate * (np.minimum(np.abs(e), gate) - self._scale)))
        return keep

    def _adapt_margin(self, updated: bool) -> None:
        p = self.params
        if updated:
            self._misses = 0
            self._margin = max(p.margin_rad, self._margin / 2)
            return
        self._misses += 1
        if p.widen_after and self._misses >= p.widen_after:
            self._misses = 0
            new = min(p.max_margin_rad, 2 * max(self._margin, math.radians(0.5)))
            if new > self._margin:
                log.info("bias: no valid cluster for %d frames; candidate margin widened to %.1f deg",
                         p.widen_after, math.degrees(new))
            self._margin = new

    def _scans_near(self, t_ns: int) -> list[tuple[str, LaserScan, np.ndarray]]:
        out = []
        max_dt = self.params.max_scan_dt_s * 1e9
        for name, laser in self._lasers.items():
            if not laser.scans:
                continue
            scan, bg = min(laser.scans, key=lambda s: abs(s[0].t_ns - t_ns))
            if abs(scan.t_ns - t_ns) <= max_dt:
                out.append((name, scan, bg))
        return out

    def _candidates(self, regions: CandidateRegions, scans: Sequence[tuple[str, LaserScan, np.ndarray]]
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]] | None:
        """Per-region statistics of every cluster of every scan: ``g``, validity, cluster azimuth and position."""
        p = self.params
        cam_xy = self.camera.position_m[:2]
        n_reg = len(regions)
        parts_n, parts_d, parts_az, parts_xy, parts_w, owner = [], [], [], [], [], []
        for name, scan, bg in scans:
            T = self._lasers[name].laser2world
            r = scan.valid_ranges_m()
            with np.errstate(invalid="ignore"):
                fg = r < bg - p.tau_fg_m if p.foreground_only else np.isfinite(r)
            cl = foreground_clusters(r, scan.angle_min_rad, scan.angle_increment_rad, fg, c0_m=p.c0_m,
                                     n_min=p.n_min, centre=p.centre, leg_radius_m=p.leg_radius_m,
                                     skip_gaps=p.foreground_only)
            k = len(cl)
            if k == 0:
                continue
            on = np.flatnonzero(cl.labels >= 0)
            a = scan.angle_min_rad + on * scan.angle_increment_rad
            rel = transform_points(T, np.column_stack([r[on] * np.cos(a), r[on] * np.sin(a)])) - cam_xy
            inside = points_in_regions(np.arctan2(rel[:, 1], rel[:, 0]), np.hypot(rel[:, 0], rel[:, 1]), regions,
                                       p.range_gate_m)
            rr, j = np.nonzero(inside)
            beam = on[j]
            flat = rr * k + cl.labels[beam]
            counts = np.bincount(flat, minlength=n_reg * k).reshape(n_reg, k)
            diff = np.bincount(flat, np.abs(bg[beam] - r[beam]), minlength=n_reg * k).reshape(n_reg, k)
            with np.errstate(invalid="ignore", divide="ignore"):
                parts_d.append(diff / counts)
            parts_n.append(counts)
            xy = transform_points(T, cl.centre_m)
            parts_xy.append(xy)
            parts_w.append(cl.width_m)
            parts_az.append(np.arctan2(xy[:, 1] - cam_xy[1], xy[:, 0] - cam_xy[0]))
            owner += [name] * k
        if not owner:
            return None
        n_pts = np.hstack(parts_n)
        D = np.hstack(parts_d)
        az = np.concatenate(parts_az)
        delta = np.abs(wrap_angle(az[None, :] - regions.centre_rad[:, None]))
        g = discriminant(n_pts, D, delta, p.sigma_fraction * regions.half_width_rad)
        valid = (n_pts > 0) & (np.nan_to_num(D) >= p.tau_fg_m) & (np.concatenate(parts_w) >= p.min_width_m)[None, :]
        return g, valid, az, np.vstack(parts_xy), owner

