"""Feature-level fusion of vehicle detections into object models in the road frame (ALGORITHMS.md D2, D5).

Input: per sensor, the latest list of :class:`~fusiontrack.types.Detection` from its branch (laser: oriented
boxes, ``laser/vehicles.py``; camera: blobs on the road plane, ``vision/vehicles.py``), in the road frame.

* **D2 synchronisation** (:class:`DetectionBuffer`): each sensor's latest frame is used at a fusion instant ``t``
  if it is at most ``max_age_s`` old — or, for a sensor whose frames come farther apart (a 10 Hz camera, or a
  branch given every k-th frame), at most ``(k + 1.25)`` of its frame periods (measured from its stream) [RECON],
  so its detections take part at every instant between two of its frames, one dropped frame included; its
  positions are
  moved to ``t`` with the branch track's velocity, ``x(t) = x(t_s) + v·(t − t_s)``.
* **D5 association** (:func:`fuse_objects`): sensors are folded in one by one, lasers first (the most precise
  positions), each by a Hungarian assignment against the objects built so far, cost ``‖p_o − p_d‖`` plus a
  size-compatibility penalty, gated at ``gate_m`` (2 m) — or, for the imprecise (a far camera's position is
  metres uncertain along the view), within ``gate_chi2`` (99 %) of the summed covariances — at most one
  detection of a sensor per object. Without the second gate a far camera blob 3 m from the laser box of the
  same car became a second object (a duplicate track).
* **D5 object model**: position = the information-weighted mean of the members' positions
  (``(Σ Σ_i⁻¹)⁻¹ Σ Σ_i⁻¹ x_i``, each branch's covariance: a laser box centre ~5 cm plus its partial-view
  uncertainty, a camera point the 2 px image noise through the homography, growing with distance); velocity from
  the laser tracks if any, else the camera tracks; dimensions from the laser box with the longest seen side;
  colour = the mean camera histogram; class from length (< 2.5 m bicycle, < 18 m car, else a group of vehicles)
  when a laser measured it, else the branches' vote; confidence = min(1, Σ per-sensor confidence) with 0.6 per
  laser and 0.4 per camera (D5: 1.0 both, 0.6 laser only, 0.4 camera only; more sensors agreeing, more
  confidence); the template check (length 1–18 m, width 0.3–2.6 m; bicycles included, D5's 2 m floor would
  drop them) marks objects that fit no vehicle as ``unknown``.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..tracking.association import hungarian
from ..tracking.vehicle_pf import FusedObject
from ..types import Detection, ObjectClass

log = logging.getLogger(__name__)

__all__ = ["DetectionBuffer", "ObjectFusionParams", "fuse_objects", "sensor_kind"]


@dataclass(frozen=True, slots=True)
class ObjectFusionParams:
    """D5 defaults. ``size_penalty`` is the cost (m) per metre of length disagreement."""

    gate_m: float = 2.0
    gate_chi2: float = 9.21
    size_penalty: float = 0.25
    confidence_laser: float = 0.6
    confidence_camera: float = 0.4
    bicycle_max_length_m: float = 2.5
    group_min_length_m: float = 18.0
    length_range_m: tuple[float, float] = (1.0, 18.0)
    width_range_m: tuple[float, float] = (0.3, 2.6)
    max_age_s: float = 0.15

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            vals = v if isinstance(v, tuple) else (v,)
            if not all(isinstance(x, int | float) and math.isfinite(x) and x >= 0 for x in vals):
                raise ConfigError(f"ObjectFusionParams.{f.name}: expected finite values >= 0, got {v!r}")
        if self.gate_m <= 0 or self.max_age_s <= 0:
            raise ConfigError("ObjectFusionParams: gate_m and max_age_s must be > 0")


def sensor_kind(det: Detection) -> str:
    """``"laser"`` for a detection with laser points or no image box, ``"camera"`` for one with an image box."""
    return "camera" if det.box_px is not None else "laser"


def _length(det: Detection) -> float:
    box = det.features.get("box")
    if box is not None and box.size >= 3 and np.isfinite(box[2]):
        return float(box[2])
    g = det.features.get("ground_length_m")
    return float(g.ravel()[0]) if g is not None and g.size else math.nan


_EPS = np.eye(2) * 1e-6


class _Clusters:
    """The objects being built: members, and the running information sums of the information-weighted mean.

    Each member's information ``(Σ_i + 10⁻⁶ I)⁻¹`` and information vector are computed once, in one batched call per
    sensor; a cluster's sums grow in member order, so its position is the same as summing over its members."""

    __slots__ = ("info", "length", "members", "vec")

    def __init__(self) -> None:
        self.members: list[list[Detection]] = []
        self.info = np.zeros((0, 2, 2))
        self.vec = np.zeros((0, 2))
        self.length = np.zeros(0)

    def __len__(self) -> int:
        return len(self.members)

    def positions(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions ``(m, 2)`` and covariances ``(m, 2, 2)`` of every cluster."""
        cov = np.linalg.inv(self.info)
        return np.matmul(cov, self.vec[:, :, None])[:, :, 0], cov

    def add(self, rows: np.ndarray, dets: Sequence[Detection], which: np.ndarray, info: np.ndarray, vec: np.ndarray,
            length: np.ndarray) -> None:
        """Detections ``which`` join the clusters ``rows``."""
        for a, b in zip(rows.tolist(), which.tolist(), strict=True):
            self.members[a].append(dets[b])
        self.info[rows] += info[which]
        self.vec[rows] += vec[which]
        self.length[rows] = np.fmax(self.length[rows], length[which])

    def extend(self, dets: Sequence[Detection], which: np.ndarray, info: np.ndarray, vec: np.ndarray,
               length: np.ndarray) -> None:
        """Detections ``which`` start clusters of their own."""
        self.members.extend([dets[b]] for b in which.tolist())
        self.info = np.concatenate([self.info, info[which]])
        self.vec = np.concatenate([self.vec, vec[which]])
        self.length = np.concatenate([self.length, length[which]])


def fuse_objects(per_sensor: dict[str, Sequence[Detection]], params: ObjectFusionParams | None = None
                 ) -> list[FusedObject]:
    """D5: fuse every sensor's detections of one instant into object models (module docstring).

    ``per_sensor`` maps a sensor name to its detections (already synchronised, road frame). The result is in
    a deterministic order (lasers' objects first, by sensor name).
    """
    p = params or ObjectFusionParams()
    order = sorted(per_sensor, key=lambda s: (0 if any(sensor_kind(d) == "laser" for d in per_sensor[s]) else 1, s))
    clusters = _Clusters()
    for s in order:
        dets = [d for d in per_sensor[s] if d.position_m is not None and np.isfinite(d.position_m).all()]
        if not dets:
            continue
        dpos = np.array([d.position_m for d in dets])
        dcov = np.array([d.covariance_m2 for d in dets])
        dinfo = np.linalg.inv(dcov + _EPS)
        dvec = np.matmul(dinfo, dpos[:, :, None])[:, :, 0]
        dlen = np.array([_length(d) if sensor_kind(d) == "laser" else math.nan for d in dets])
        if not len(clusters):
            clusters.extend(dets, np.arange(len(dets)), dinfo, dvec, dlen)
            continue
        cpos, ccov = clusters.positions()
        diff = cpos[:, None] - dpos[None]
        cost = np.linalg.norm(diff, axis=2)
        S = ccov[:, None] + dcov[None]
        m2 = np.einsum("cdi,cdij,cdj->cd", diff, np.linalg.inv(S), diff)
        near = (cost <= p.gate_m) | (m2 <= p.gate_chi2)
        dl = np.abs(clusters.length[:, None] - np.array([_length(d) for d in dets])[None])
        cost_gated = np.where(near, np.sqrt(m2) + p.size_penalty * np.nan_to_num(dl, nan=0.0), np.inf)
        pairs, _, free = hungarian(cost_gated, gate=np.inf)
        if len(pairs):
            clusters.add(pairs[:, 0], dets, pairs[:, 1], dinfo, dvec, dlen)
        clusters.extend(dets, np.asarray(free, np.intp).reshape(-1), dinfo, dvec, dlen)
    if not len(clusters):
        return []
    pos, cov = clusters.positions()
    return [_object(m, pos[i], cov[i], p) for i, m in enumerate(clusters.members)]


def _mean(arrays: list[np.ndarray]) -> np.ndarray:
    """``np.mean(arrays, axis=0)``, without its overhead for one or two arrays (the common cases)."""
    if len(arrays) == 1:
        return arrays[0] / 1.0
    if len(arrays) == 2:
        return (arrays[0] + arrays[1]) / 2.0
    return np.mean(arrays, axis=0)


def _object(members: list[Detection], pos: np.ndarray, cov: np.ndarray, p: ObjectFusionParams) -> FusedObject:
    lasers = [d for d in members if d.box_px is None]
    cams = [d for d in members if d.box_px is not None]
    vel = None
    for group in (lasers, cams):
        vs = [v for v in (d.features.get("velocity_mps") for d in group) if v is not None and np.isfinite(v).all()]
        if vs:
            vel = _mean(vs)
            break
    hists = [d.features["hist_hsv"] for d in cams if "hist_hsv" in d.features]
    hist = None
    if hists:
        h = _mean(hists)
        hist = h / max(float(h.sum()), 1e-12)
    boxes = [b for b in (d.features.get("box") for d in lasers) if b is not None and np.isfinite(b).all()]
    box = max(boxes, key=lambda b: b[2]) if boxes else None
    if box is not None:
        length, width = float(box[2]), float(box[3])
        cls = (ObjectClass.BICYCLE if length < p.bicycle_max_length_m else
               ObjectClass.CAR if length < p.group_min_length_m else ObjectClass.GROUP)
        fits = (p.length_range_m[0] <= length and p.width_range_m[0] <= width <= p.width_range_m[1]
                and (cls == ObjectClass.GROUP or length <= p.length_range_m[1]))
        if not fits:
            cls = ObjectClass.UNKNOWN
        dims = np.array([length, width, float(box[4])])
    else:
        votes = [d.cls for d in members if d.cls != ObjectClass.UNKNOWN]
        # the most votes; a tie goes to the first member's (a set's order would follow PYTHONHASHSEED: one run
        # called a car what the next called a bicycle)
        cls = Counter(votes).most_common(1)[0][0] if votes else ObjectClass.UNKNOWN
        dims = None
    conf = min(1.0, p.confidence_laser * len(lasers) + p.confidence_camera * len(cams))
    box_px = {d.sensor: d.box_px for d in cams}
    return FusedObject(pos, cov, vel, hist, str(cls), conf, tuple(sorted(d.sensor for d in members)), dims,
                       box_px or None)


class DetectionBuffer:
    """D2: the latest detections of each sensor, moved to a common instant with their track velocities.

    Parameters
    ----------
    max_age_s : float
        A frame older than this is not used (0.15 s) ...
    margin_periods : float or None
        ... unless the sensor's frames come farther apart: its limit is then ``k + margin_periods`` times its frame
        period (1.25: one dropped frame and the timing jitter), ``k`` its branch's ``every`` (:meth:`put`) and the
        period the median of its last ``n_intervals`` intervals between the frames it sent (:meth:`note`), at most
        ``max_age_cap_s``. ``None`` keeps ``max_age_s`` for every sensor.
    max_age_cap_s : float
        Largest per-sensor limit (1.0 s): a sensor that has gone quiet is not stretched further.
    n_intervals : int
        Intervals the median is taken over (9: an outage does not move it).

    Attributes
    ----------
    max_age_ns : int
        ``max_age_s`` in ns.
    """

    def __init__(self, max_age_s: float = 0.15, *, margin_periods: float | None = 1.25, max_age_cap_s: float = 1.0,
                 n_intervals: int = 9) -> None:
        if not (math.isfinite(max_age_s) and max_age_s > 0):
            raise ConfigError(f"DetectionBuffer max_age_s: expected a finite value > 0, got {max_age_s!r}")
        if margin_periods is not None and not (math.isfinite(margin_periods) and margin_periods >= 0):
            raise ConfigError(f"DetectionBuffer margin_periods: expected a finite value >= 0 or None, got "
                              f"{margin_periods!r}")
        if not (math.isfinite(max_age_cap_s) and max_age_cap_s > 0):
            raise ConfigError(f"DetectionBuffer max_age_cap_s: expected a finite value > 0, got {max_age_cap_s!r}")
        if isinstance(n_intervals, bool) or not isinstance(n_intervals, int) or n_intervals < 1:
            raise ConfigError(f"DetectionBuffer n_intervals: expected an integer >= 1, got {n_intervals!r}")
        self.max_age_ns = int(max_age_s * 1e9)
        self._margin = margin_periods
        self._cap_ns = max(self.max_age_ns, int(max_age_cap_s * 1e9))
        self._n_intervals = n_intervals
        self._latest: dict[str, tuple[int, list[Detection]]] = {}
        self._last_seen: dict[str, int] = {}
        self._intervals: dict[str, list[int]] = {}
        self._every: dict[str, int] = {}
        self._limit_ns: dict[str, int] = {}

    def age_limit_s(self, sensor: str) -> float:
        """The oldest a frame of ``sensor`` may be to be used (s): ``max_age_s``, or more for a sparse sensor."""
        return self._limit_ns.get(sensor, self.max_age_ns) / 1e9

    def note(self, sensor: str, t_ns: int) -> None:
        """A frame of ``sensor`` arrived at ``t_ns``, whether its branch processes it or not: measures the
        sensor's frame period (:meth:`put` notes the frames it stores)."""
        last = self._last_seen.get(sensor)
        if last is not None and t_ns <= last:
            return
        self._last_seen[sensor] = int(t_ns)
        if last is None or self._margin is None:
            return
        iv = self._intervals.setdefault(sensor, [])
        iv.append(int(t_ns) - last)
        del iv[:-self._n_intervals]
        self._update_limit(sensor)

    def _update_limit(self, sensor: str) -> None:
        iv = self._intervals.get(sensor)
        if not iv or self._margin is None:
            return
        period = float(np.median(iv))
        k = self._every.get(sensor, 1)
        limit = min(self._cap_ns, max(self.max_age_ns, int((k + self._margin) * period)))
        if limit > self.max_age_ns and self._limit_ns.get(sensor, self.max_age_ns) == self.max_age_ns:
            log.info("%s: a frame every %.3f s, every %d used: its detections are fused for up to %.3f s after "
                     "their frame (max_age_s %.3f s)", sensor, period / 1e9, k, limit / 1e9, self.max_age_ns / 1e9)
        self._limit_ns[sensor] = limit

    def put(self, sensor: str, t_ns: int, detections: Sequence[Detection], *, every: int = 1) -> None:
        """Store a sensor's frame (an older frame than the one held is ignored: out-of-order messages).

        ``every`` = k: its branch is given every k-th frame of the sensor, so the stored frames are k periods apart.
        """
        if every != self._every.get(sensor, 1):
            self._every[sensor] = int(every)
            self._update_limit(sensor)
        self.note(sensor, t_ns)
        held = self._latest.get(sensor)
        if held is None or t_ns >= held[0]:
            self._latest[sensor] = (int(t_ns), list(detections))

    def at(self, t_ns: int) -> dict[str, list[Detection]]:
        """Every sensor's detections whose frame is within the sensor's age limit of ``t_ns``
        (:meth:`age_limit_s`), moved to ``t_ns``."""
        out: dict[str, list[Detection]] = {}
        for s, (ts, dets) in self._latest.items():
            if abs(t_ns - ts) > self._limit_ns.get(s, self.max_age_ns):
                continue
            dt = (t_ns - ts) / 1e9
            out[s] = [_moved(d, dt) for d in dets] if dt else dets
        return out


def _moved(d: Detection, dt: float) -> Detection:
    v = d.features.get("velocity_mps")
    if v is None or not np.isfinite(v).all():
        return d
    return d.moved(d.position_m + v * dt)


def as_params(values: dict[str, Any], source: str = "traffic.fusion") -> ObjectFusionParams:
    """Build :class:`ObjectFusionParams` from a config mapping, naming unknown keys."""
    names = {f.name for f in fields(ObjectFusionParams)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise ConfigError(f"{source}: unknown parameter(s) {unknown}; expected some of {sorted(names)}")
    vals = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return ObjectFusionParams(**vals)
