"""Labelled windows of laser segments for the object classifier (ALGORITHMS.md B18), from recordings.

Three sources, each turned into rows of :func:`~fusiontrack.laser.features.window_features` (one row per
window of ``W`` consecutive observations of one object) and a class label:

* :func:`simulated_windows` — a simulator recording: the foreground points of the people-tracking detector,
  labelled by the ground truth (a person's points lie near its feet, a vehicle's inside its footprint);
  people, bicycles and cars; and the detector's two-feet segments that hold people, with a neighbour's foot
  or a second person at times, as a tracker sees them.
* :func:`leg_windows` — leg_tracker's positive training bag: scans with the leg positions its authors
  labelled; the points near a person's legs are the person.

Observations of one object are chained over frames (by ground-truth id, or by the nearest centroid for the
real bag), and windows of ``W`` of them, advancing by ``stride``, become samples.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fusiontrack.laser.clustering import Segments
from fusiontrack.laser.features import GEOMETRIC_FEATURES, segment_features, window_features
from fusiontrack.types import ObjectClass

__all__ = ["Windows", "label_points", "leg_windows", "simulated_windows", "windows_from_observations"]

log = logging.getLogger(__name__)

PERSON_RADIUS_M = 0.30
"""A simulated person's points: within this of one of its feet."""
VEHICLE_MARGIN_M = 0.30
"""A simulated vehicle's points: inside its footprint grown by this."""


@dataclass(frozen=True, slots=True)
class Windows:
    """Classifier samples: ``X`` (m, len(WINDOW_FEATURES)) and their classes ``y`` (m,) str."""

    X: np.ndarray
    y: np.ndarray

    def __len__(self) -> int:
        return int(self.y.size)

    @staticmethod
    def concat(parts: Iterable[Windows]) -> Windows:
        parts = [p for p in parts if len(p)]
        if not parts:
            from fusiontrack.laser.features import WINDOW_FEATURES

            return Windows(np.zeros((0, len(WINDOW_FEATURES))), np.zeros(0, dtype=object))
        return Windows(np.concatenate([p.X for p in parts]), np.concatenate([p.y for p in parts]))


def windows_from_observations(obs: Sequence[tuple[Any, int, str, np.ndarray, np.ndarray]], *, window: int = 10,
                              stride: int = 5, max_gap_s: float = 0.5) -> Windows:
    """Windows of ``window`` consecutive observations of each object.

    Parameters
    ----------
    obs : sequence of (key, t_ns, class, geometric (F,), centre (2,))
        One row per object per frame; ``key`` identifies the object.
    window, stride : int
        Window length (B18 ``W_c = 10``) and how far the next window starts.
    max_gap_s : float
        A longer gap between two observations of an object starts a new chain.
    """
    by_key: dict[Any, list[tuple[int, str, np.ndarray, np.ndarray]]] = {}
    for key, t_ns, cls, geo, centre in obs:
        by_key.setdefault(key, []).append((int(t_ns), cls, geo, centre))
    geos, cents, times, labels = [], [], [], []
    gap_ns = max_gap_s * 1e9
    for rows in by_key.values():
        rows.sort(key=lambda r: r[0])
        t = np.array([r[0] for r in rows], dtype=np.int64)
        cut = np.flatnonzero(np.diff(t) > gap_ns) + 1
        for a, b in zip(np.r_[0, cut], np.r_[cut, len(rows)], strict=True):
            for s in range(a, b - window + 1, stride):
                chunk = rows[s:s + window]
                geos.append(np.stack([r[2] for r in chunk]))
                cents.append(np.stack([r[3] for r in chunk]))
                times.append((t[s:s + window] - t[s]) * 1e-9)
                labels.append(chunk[-1][1])
    if not geos:
        return Windows.concat([])
    X = window_features(np.stack(geos), np.stack(cents), np.stack(times))
    return Windows(X, np.array(labels, dtype=object))


def _frames(path: str | Path, *, background: str = "learn", time_source: str = "header",
            detector_params: dict[str, Any] | None = None,
            ) -> Iterator[tuple[int, np.ndarray, Callable[[], Segments]]]:
    """(t_ns, pooled foreground points (n, 2) in the world, their segments) per scan time, from the tracker's
    detector. The segments: a function giving the detector's two-feet segments of all those points (B4,
    :class:`~fusiontrack.laser.clustering.Segments`; the mean-shift runs only when it is called). The tracker's
    detector first takes out its rigid objects (vehicles' sides); the people's segments kept for training hold
    no vehicle's points, so this does not change them."""
    from fusiontrack.io.recording import LASERSCAN, Recording
    from fusiontrack.io.sync import synchronize
    from fusiontrack.laser.detector import detector_for_recording

    with Recording(path) as rec:
        lasers = [t for t, msgtype in rec.topic_types().items() if msgtype == LASERSCAN]
        detector, _ = detector_for_recording(rec, lasers, time_source=time_source, background=background,
                                             detector_params=detector_params)

        def frame(t_ns: int) -> tuple[int, np.ndarray, Callable[[], Segments]]:
            points = detector.foreground_points(t_ns)[0]
            return t_ns, points, lambda: detector.segment(points)

        pending: int | None = None
        for scan in synchronize(rec.messages(lasers, time_source=time_source)):
            if pending is not None and scan.t_ns != pending:
                yield frame(pending)
            detector.update(scan)
            pending = scan.t_ns
        if pending is not None:
            yield frame(pending)


def simulated_windows(path: str | Path, *, window: int = 10, stride: int = 5, segments: bool = True,
                      purity: float = 0.8, link_m: float = 0.5) -> Windows:
    """Samples of people, bicycles and cars from a simulator recording (its ``/ground_truth`` labels them).

    An observation is all the foreground points of one object (:func:`label_points`): a whole car, a person's
    two feet; chained over frames by the object's id. With ``segments``, also every two-feet segment of the
    detector (B4) at least ``purity`` of whose points are people's, as a person (chained over frames by the
    nearest centroid within ``link_m``): what a track of the people pipeline classifies
    (:class:`~fusiontrack.tracking.classify.TrackClassifier`), with the points of whoever walks close by. A
    segment that holds a person and a foot of a neighbour, or two people side by side whose second has no
    track, is half a metre wide or more: trained on people's own points alone, the classifier called such
    windows ``car``, and tracks of people walking in pairs left the person class for seconds. Vehicles'
    segments are not added: the tracker's detector keeps a vehicle's side whole (a rigid object, which the
    whole-object samples stand for) instead of cutting it into two-feet segments.
    """
    from fusiontrack.io.recording import Recording

    with Recording(path) as rec:
        gts = list(rec.messages(["/ground_truth"]))
    if not gts:
        raise ValueError(f"{path}: no /ground_truth topic: not a simulator recording")
    gt_t = np.array([g.t_ns for g in gts], dtype=np.int64)
    obs: list[tuple[Any, int, str, np.ndarray, np.ndarray]] = []
    people: list[tuple[int, np.ndarray, np.ndarray]] = []  # per frame: shape rows, centroids of people's segments
    for t_ns, pts, segmenter in _frames(path):
        if len(pts) < 3:
            continue
        i = int(np.clip(np.searchsorted(gt_t, t_ns), 1, len(gts) - 1))
        g = gts[i if abs(gt_t[i] - t_ns) < abs(gt_t[i - 1] - t_ns) else i - 1]
        labels = label_points(pts, g)
        n_obj = len(g.ids)
        feats = segment_features(pts, labels, n_obj)
        for j in np.flatnonzero(feats[:, 0] >= 3):
            centre = pts[labels == j].mean(axis=0)
            obs.append((int(g.ids[j]), t_ns, g.classes[j], feats[j], centre))
        is_person = np.asarray(g.classes) == ObjectClass.PERSON
        if segments and is_person.any():
            owned = labels >= 0
            persons = owned & is_person[np.where(owned, labels, 0)]
            people.append((t_ns, *_people_segments(pts, segmenter(), owned, persons, purity)))
    obs.extend(_link(people, ObjectClass.PERSON.value, link_m, f"{path}:segments"))
    return windows_from_observations(obs, window=window, stride=stride)


def _people_segments(points_m: np.ndarray, segs: Segments, owned: np.ndarray, persons: np.ndarray,
                     purity: float) -> tuple[np.ndarray, np.ndarray]:
    """Shape rows and centres of the segments ``segs`` of ``points_m`` (3 points or more) at least ``purity`` of
    whose points are people's (``persons``), the others all belonging to some object (``owned``) or to none."""
    k = len(segs)
    if k == 0:
        return np.zeros((0, len(GEOMETRIC_FEATURES))), np.zeros((0, 2))
    seg = segs.labels
    on = seg >= 0
    n = segs.n_points
    of_people = np.bincount(seg[on], weights=persons[on], minlength=k)
    of_others = np.bincount(seg[on], weights=owned[on] & ~persons[on], minlength=k)
    keep = np.flatnonzero((n >= 3) & (of_people >= purity * n) & (of_others == 0))
    return segment_features(points_m, seg, k)[keep], segs.centres_m[keep]


def label_points(points_m: np.ndarray, gt: Any) -> np.ndarray:
    """The ground-truth object each point belongs to (index into ``gt.ids``), -1 for none.

    A person's points are those within :data:`PERSON_RADIUS_M` of one of its feet (attribute ``feet_m``, or
    its position); a vehicle's, those inside its footprint (``size_m`` length x width, ``heading_rad``)
    grown by :data:`VEHICLE_MARGIN_M`. A point claimed by several objects is given to none.
    """
    n = len(gt.ids)
    labels = np.full(len(points_m), -1, dtype=np.int64)
    if n == 0 or len(points_m) == 0:
        return labels
    classes = np.array(gt.classes)
    person = classes == ObjectClass.PERSON
    claim = np.zeros((len(points_m), n), bool)
    if person.any():
        feet = np.asarray(gt.attributes.get("feet_m", np.repeat(gt.positions_m[:, None, :], 2, axis=1)))
        d = np.linalg.norm(points_m[:, None, None, :] - feet[None, person], axis=3).min(axis=2)
        claim[:, person] = d < PERSON_RADIUS_M
    if (~person).any():
        heading = np.asarray(gt.attributes["heading_rad"])[~person]
        size = np.asarray(gt.attributes["size_m"])[~person]
        rel = points_m[:, None, :] - gt.positions_m[None, ~person]
        c, s = np.cos(heading), np.sin(heading)
        u = rel[..., 0] * c + rel[..., 1] * s
        v = -rel[..., 0] * s + rel[..., 1] * c
        claim[:, ~person] = ((np.abs(u) <= size[:, 0] / 2 + VEHICLE_MARGIN_M)
                             & (np.abs(v) <= size[:, 1] / 2 + VEHICLE_MARGIN_M))
    one = claim.sum(axis=1) == 1
    labels[one] = np.argmax(claim[one], axis=1)
    return labels


def _scan_points(scan: Any, max_range_m: float = np.inf) -> np.ndarray:
    r = scan.valid_ranges_m()
    a = scan.angles_rad()
    ok = np.isfinite(r) & (r > 0) & (r <= max_range_m)
    return np.column_stack([r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])])


def _chain(frames: Sequence[tuple[int, np.ndarray, list[np.ndarray]]], cls: str, link_m: float,
           source: str) -> list[tuple[Any, int, str, np.ndarray, np.ndarray]]:
    """Observations from per-frame (t_ns, points, [index arrays of each object]), chained by nearest centroid
    (:func:`_link`)."""
    rows = []
    for t_ns, pts, groups in frames:
        if not groups:
            rows.append((t_ns, np.zeros((0, len(GEOMETRIC_FEATURES))), np.zeros((0, 2))))
            continue
        labels = np.full(len(pts), -1, dtype=np.int64)
        for j, idx in enumerate(groups):
            labels[idx] = j
        rows.append((t_ns, segment_features(pts, labels, len(groups)),
                     np.stack([pts[idx].mean(axis=0) for idx in groups])))
    return _link(rows, cls, link_m, source)


def _link(frames: Sequence[tuple[int, np.ndarray, np.ndarray]], cls: str, link_m: float,
          source: str) -> list[tuple[Any, int, str, np.ndarray, np.ndarray]]:
    """Observations from per-frame (t_ns, shape rows (k, F), centroids (k, 2)), chained over frames by nearest
    centroid within ``link_m``: one to one, the closest pairs first (two segments of a frame never continue the
    same chain); a frame without segments ends every chain."""
    obs: list[tuple[Any, int, str, np.ndarray, np.ndarray]] = []
    prev_c = np.zeros((0, 2))
    prev_k: list[int] = []
    next_key = 0
    for t_ns, feats, cents in frames:
        keys = [-1] * len(cents)
        if len(prev_c) and len(cents):
            d = np.linalg.norm(cents[:, None] - prev_c[None], axis=2)
            taken = np.zeros(len(prev_c), bool)
            for a, b in zip(*np.unravel_index(np.argsort(d, axis=None, kind="stable"), d.shape), strict=True):
                if d[a, b] > link_m:
                    break
                if keys[a] < 0 and not taken[b]:
                    keys[a], taken[b] = prev_k[b], True
        for j, key in enumerate(keys):
            if key < 0:
                keys[j], next_key = next_key, next_key + 1
            obs.append(((source, keys[j]), t_ns, cls, feats[j], cents[j]))
        prev_c, prev_k = cents, keys
    return obs


def leg_windows(path: str | Path, *, window: int = 10, stride: int = 2, leg_radius_m: float = 0.20,
                pair_m: float = 0.7) -> Windows:
    """People from leg_tracker's positive training bag (``/training_scan`` + ``/leg_cluster_positions``).

    The k-th scan goes with the k-th leg-position message (the bag stores them as pairs). Legs closer than
    ``pair_m`` are one person; the person's points are the scan points within ``leg_radius_m`` of a leg.
    """
    from fusiontrack.io.recording import Recording

    with Recording(path) as rec:
        scans = list(rec.messages(["/training_scan"]))
        legs = list(rec.messages(["/leg_cluster_positions"]))
    if not scans or len(scans) != len(legs):
        raise ValueError(f"{path}: expected as many /training_scan as /leg_cluster_positions messages, "
                         f"got {len(scans)} and {len(legs)}")
    from scipy.sparse.csgraph import connected_components

    frames = []
    for scan, leg in zip(scans, legs, strict=True):
        pts = _scan_points(scan)
        lp = np.asarray(leg.positions_m)
        if len(lp) == 0 or len(pts) == 0:
            frames.append((scan.t_ns, pts, []))
            continue
        _, comp = connected_components(np.linalg.norm(lp[:, None] - lp[None], axis=2) < pair_m, directed=False)
        d = np.linalg.norm(pts[:, None] - lp[None], axis=2)
        near = d.min(axis=1) < leg_radius_m
        owner = comp[np.argmin(d, axis=1)]
        groups = [np.flatnonzero(near & (owner == c)) for c in np.unique(comp)]
        frames.append((scan.t_ns, pts, [g for g in groups if g.size >= 3]))
    return windows_from_observations(_chain(frames, ObjectClass.PERSON, 0.6, str(path)), window=window,
                                     stride=stride)
