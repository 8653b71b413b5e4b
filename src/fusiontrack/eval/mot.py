"""Multi-object tracking metrics (CLEAR MOT, identity, HOTA) computed with TrackEval's metric classes.

The numbers come from ``trackeval.metrics.CLEAR``, ``Identity``, ``HOTA`` and ``Count`` (TrackEval 1.3.0);
this module only builds the per-sequence ``data`` dict those classes read, the way TrackEval's
datasets build it in ``get_preprocessed_seq_data``: per timestep ``gt_ids`` and ``tracker_ids``
(``(n_gt_t,)`` and ``(n_tr_t,)`` int, relabelled to ``0 .. n_ids - 1`` over the sequence) and
``similarity_scores`` (``(n_gt_t, n_tr_t)`` float in ``[0, 1]``), plus the counts
``num_gt_ids``, ``num_tracker_ids``, ``num_gt_dets``, ``num_tracker_dets``, ``num_timesteps``.
Several sequences are combined with each metric's own ``combine_sequences`` (:func:`combine_metrics`):
counts are summed and the ratios recomputed from the sums, HOTA's AssA/LocA weighted by HOTA_TP,
exactly as TrackEval's ``COMBINED_SEQ`` row.

Floor plane (:func:`evaluate_floor`)
    Similarity from the Euclidean distance ``d`` (m) between a ground-truth position and a track
    position, with TrackEval's own point formula (``_BaseDataset._calculate_euclidean_similarity``,
    the MOT15-3D convention) and ``zero_distance = 2 * threshold_m``::

        similarity = max(0, 1 - d / (2 * threshold_m))

    so TrackEval's fixed similarity threshold 0.5 of CLEAR and Identity means exactly
    ``d <= threshold_m`` (a pair farther than ``threshold_m`` by rounding is pushed just below 0.5,
    so the rule is exact at the boundary). Consequences:

    * MOTP (and LocA) is ``1 - mean(d) / (2 * threshold_m)`` over the matches:
      1 for zero distance, 0.5 for matches at the threshold; :attr:`Metrics.motp_m` gives the
      mean matched distance back in metres. A constant 0.3 m offset at the default 0.5 m gives 0.7.
    * HOTA averages over ``alpha = 0.05, 0.10, ..., 0.95``; at ``alpha`` a pair can match when
      ``d <= 2 * threshold_m * (1 - alpha)``, i.e. distance thresholds from ``0.1`` to ``1.9 *
      threshold_m`` (5 cm to 95 cm for 0.5 m). ``alpha = 0.5`` is the CLEAR/Identity threshold,
      as IoU 0.5 is for boxes. A track 0.3 m off everywhere matches for ``alpha <= 0.7`` only, so its
      HOTA is below 1 although MOTA is 1: HOTA scores localisation, MOTA does not.

    Time pairing: every ground-truth frame is one TrackEval timestep. A track state is assigned to
    the ground-truth frame nearest in time, if within ``time_tolerance_ns`` (default half the median
    ground-truth period, so a state belongs to at most one frame); when one track has several states
    in a frame's window, the one nearest in time is used (the earlier on a tie). States farther than
    the tolerance from every frame (between frames, before the first, after the last) are not
    evaluated; ground-truth frames with no state are all misses. Positions are used as stamped (not
    interpolated to the frame time): at 1.5 m/s a 20 ms offset is 3 cm.
    Objects and tracks are kept when their class is in ``classes`` and then matched class-agnostically
    (evaluate once per class for per-class numbers). Ids are sorted within each frame, so the order
    of the input records does not change any result.

Image boxes (:func:`evaluate_boxes`, :func:`evaluate_mot_files`)
    Similarity = IoU of ``(bb_left, bb_top, bb_width, bb_height)`` boxes, computed by TrackEval's
    ``_BaseDataset._calculate_box_ious``; a match needs IoU >= 0.5 (as the MOTChallenge devkit and
    py-motmetrics ``distth=0.5``). Which rows count follows ``MotChallenge2DBox``:

    * ground-truth rows whose 7th column, truncated to an integer, is 0 are dropped (TrackEval's
      ``zero_marked``: "do not consider");
    * with ``preprocess`` (MOT16/17/20 ground truth, whose 8th column is the class): per frame, tracker
      boxes matched (Hungarian on IoU >= 0.5, over ground truth of every class) to a distractor
      (person on vehicle 2, static person 7, distractor 8, reflection 12; add 6 for MOT20) are
      removed, then only pedestrian (class 1) ground truth is kept;
    * without it (MOT15 / 2D MOT 2015 files such as TUD-Campus and TUD-Stadtmitte, whose 8th column
      is the 3D ``x`` = -1, not a class): no class filtering at all; TrackEval does the same for
      ``BENCHMARK='MOT15'`` (or ``DO_PREPROC=False``). This is what reproduces the devkit's and
      py-motmetrics' published TUD values: their ground truth has 1 in column 7 everywhere and the
      tracker's confidence column (-1) is not used; there are no crowd ignore regions in MOTChallenge.

    ``preprocess=None`` picks it from the ground-truth layout: on for 9-column files (MOT16/17/20),
    off otherwise.

Image boxes of one simulated camera (:func:`evaluate_camera_boxes`)
    The simulator's per-camera truth (``/ground_truth/<camera>``: ``box_px`` and ``visibility`` per agent per
    image) becomes MOT16-style ground truth through :func:`fusiontrack.vision.camera_truth_boxes` (boxes
    clipped to the image; a person at least half visible is a pedestrian, a less visible one a distractor),
    each truth record being one frame ``1 .. n``. Agents of other classes (cars on a road) are left out, so
    a track on one is a false positive. Track states (``box_px``) go to the truth frame nearest in time, within
    half the median truth period, as in the floor plane; then :func:`evaluate_boxes` with ``preprocess=True``.
    This is the scoring of ``benchmarks/camera_people.py``.

Compatibility: TrackEval 1.3.0 runs unchanged on numpy 2.x (it no longer uses the removed
``np.float``/``np.int`` aliases), so no shim is installed. Metric configs are built with
``PRINT_CONFIG=False``, so nothing is printed; TrackEval is imported on first use (~0.7 s).
"""

from __future__ import annotations

import configparser
import logging
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..io.tracks import MotBoxes, flatten_states, read_mot
from ..types import GroundTruth, ObjectClass, Track, TrackState
from .errors import EvaluationError

if TYPE_CHECKING:
    from rich.table import Table

__all__ = [
    "MOT16_DISTRACTOR_CLASSES",
    "MOT20_DISTRACTOR_CLASSES",
    "FrameMatches",
    "Metrics",
    "MetricsTable",
    "combine_metrics",
    "evaluate_boxes",
    "evaluate_camera_boxes",
    "evaluate_floor",
    "evaluate_mot_files",
    "floor_similarity",
    "frame_matches",
    "metrics_table",
    "truth_at",
]

logger = logging.getLogger(__name__)

MOT16_DISTRACTOR_CLASSES = (2, 7, 8, 12)
"""MOT16/17 ground-truth classes whose matched tracker boxes are removed (TrackEval MotChallenge2DBox)."""
MOT20_DISTRACTOR_CLASSES = (2, 6, 7, 8, 12)
"""MOT20 adds ``non_mot_vehicle`` (6)."""
_PEDESTRIAN = 1
_EPS = float(np.finfo(float).eps)
_MATCH_SIMILARITY = 0.5  # TrackEval's CLEAR/Identity threshold, also its MOT preprocessing threshold
_BELOW_MATCH = _MATCH_SIMILARITY - 4 * _EPS  # below CLEAR's ``threshold - eps`` and Identity's ``>= threshold``


# --------------------------------------------------------------------------------------------------
# Result record
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Metrics:
    """Tracking metrics of one sequence, or of several combined.

    Fractions are in ``[0, 1]`` (MOTA and MODA can be negative); HOTA and its parts are the means over
    TrackEval's 19 ``alpha`` thresholds (what TrackEval reports as HOTA, DetA, ...). Names follow
    TrackEval: ``recall`` = CLR_Re (MOTChallenge "Rcll"), ``precision`` = CLR_Pr ("Prcn"), ``motp`` =
    mean similarity of the CLEAR matches (IoU for boxes; see the module docstring for distances).

    Attributes
    ----------
    tp, fp, fn : int
        CLEAR matches, false positives and misses (detections, summed over frames).
    id_switches, fragmentations : int
        CLEAR IDSW and Frag.
    mostly_tracked, partially_tracked, mostly_lost : int
        Ground-truth identities tracked for > 80 %, 20-80 %, < 20 % of their frames.
    idtp, idfp, idfn : int
        Identity (IDF1) true positives, false positives, false negatives.
    max_matches : int
        Per timestep, the most ground-truth/track pairs that can be matched one-to-one within the match
        threshold, summed over the timesteps. ``-1`` when not computed.
    num_gt_ids, num_tracker_ids, num_gt_dets, num_tracker_dets, num_frames : int
        What was evaluated (after class filtering and preprocessing).
    distance_scale_m : float or None
        Floor-plane mode: the distance at which similarity reaches 0 (``2 * threshold_m``);
        ``None`` for image boxes.
    id_map : mapping of int -> int
        Tracker id -> ground-truth id of the identity (IDF1) correspondence: one-to-one, maximising
        the number of frames in which the pair is within the match threshold (pairs that never are
        left out). Original ids, not TrackEval's relabelled ones; empty for combined results.
    raw : mapping of str -> mapping
        TrackEval's result dict of each metric class (``"CLEAR"``, ``"Identity"``, ``"HOTA"``,
        ``"Count"``), kept for :func:`combine_metrics` and for fields not copied here.
    """

    hota: float
    deta: float
    assa: float
    loca: float
    detre: float
    detpr: float
    assre: float
    asspr: float
    mota: float
    motp: float
    moda: float
    idf1: float
    idp: float
    idr: float
    recall: float
    precision: float
    tp: int
    fp: int
    fn: int
    id_switches: int
    fragmentations: int
    mostly_tracked: int
    partially_tracked: int
    mostly_lost: int
    idtp: int
    idfp: int
    idfn: int
    num_gt_ids: int
    num_tracker_ids: int
    num_gt_dets: int
    num_tracker_dets: int
    num_frames: int
    max_matches: int = -1
    distance_scale_m: float | None = None
    id_map: Mapping[int, int] = field(default_factory=dict, compare=False)
    raw: Mapping[str, Mapping[str, Any]] = field(default_factory=dict, repr=False, compare=False)

    @property
    def idf1_ceiling(self) -> float:
        """The highest IDF1 any assignment of identities to these detections could reach: ``2 * max_matches /
        (num_gt_dets + num_tracker_dets)``.

        IDF1 is ``2 * IDTP / (num_gt_dets + num_tracker_dets)``, and the IDTP pairs of one timestep are a one-to-one
        matching within the threshold, so ``IDTP <= max_matches``. The ceiling is what the same track positions
        would score if every track kept one identity for good (association perfect); the gap to IDF1 is the
        identity errors' share, the gap to 1 the detection errors' (misses, false tracks, localisation beyond the
        threshold). 1 with nothing to evaluate; NaN when ``max_matches`` was not computed.
        """
        if self.max_matches < 0:
            return float("nan")
        n = self.num_gt_dets + self.num_tracker_dets
        return 2.0 * self.max_matches / n if n else 1.0

    @property
    def motp_m(self) -> float | None:
        """Mean distance of the CLEAR matches in metres (floor plane), ``None`` for boxes or without matches."""
        if self.distance_scale_m is None or self.tp == 0:
            return None
        return self.distance_scale_m * (1.0 - self.motp)

    def to_dict(self) -> dict[str, float | int | None]:
        """The numbers as a flat dict (JSON-ready), plus ``motp_m``; ``id_map`` and ``raw`` are left out."""
        out: dict[str, float | int | None] = {name: getattr(self, name) for name in _NUMBER_FIELDS}
        out["motp_m"] = self.motp_m
        out["idf1_ceiling"] = self.idf1_ceiling
        return out

    @classmethod
    def from_trackeval(cls, raw: Mapping[str, Mapping[str, Any]], *, num_frames: int,
                       distance_scale_m: float | None = None, id_map: Mapping[int, int] | None = None,
                       max_matches: int = -1) -> Metrics:
        """Build from TrackEval result dicts keyed by metric class name (CLEAR, Identity, HOTA, Count)."""
        clear, ident, hota, count = raw["CLEAR"], raw["Identity"], raw["HOTA"], raw["Count"]

        def mean(name: str) -> float:
            return float(np.mean(hota[name]))

        return cls(
            hota=mean("HOTA"), deta=mean("DetA"), assa=mean("AssA"), loca=mean("LocA"),
            detre=mean("DetRe"), detpr=mean("DetPr"), assre=mean("AssRe"), asspr=mean("AssPr"),
            mota=float(clear["MOTA"]), motp=float(clear["MOTP"]), moda=float(clear["MODA"]),
            idf1=float(ident["IDF1"]), idp=float(ident["IDP"]), idr=float(ident["IDR"]),
            recall=float(clear["CLR_Re"]), precision=float(clear["CLR_Pr"]),
            tp=int(clear["CLR_TP"]), fp=int(clear["CLR_FP"]), fn=int(clear["CLR_FN"]),
            id_switches=int(clear["IDSW"]), fragmentations=int(clear["Frag"]),
            mostly_tracked=int(clear["MT"]), partially_tracked=int(clear["PT"]), mostly_lost=int(clear["ML"]),
            idtp=int(ident["IDTP"]), idfp=int(ident["IDFP"]), idfn=int(ident["IDFN"]),
            num_gt_ids=int(count["GT_IDs"]), num_tracker_ids=int(count["IDs"]),
            num_gt_dets=int(count["GT_Dets"]), num_tracker_dets=int(count["Dets"]), num_frames=int(num_frames),
            max_matches=int(max_matches), distance_scale_m=distance_scale_m,
            id_map=MappingProxyType(dict(id_map or {})),
            raw=MappingProxyType({k: MappingProxyType(dict(v)) for k, v in raw.items()}),
        )


_NUMBER_FIELDS = tuple(name for name in Metrics.__dataclass_fields__ if name not in ("id_map", "raw"))


# --------------------------------------------------------------------------------------------------
# TrackEval core
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Sequence:
    """Per-timestep inputs in original ids: ``gt_ids[t]`` (n_gt_t,), ``tracker_ids[t]`` (n_tr_t,),
    ``similarity[t]`` (n_gt_t, n_tr_t)."""

    name: str
    gt_ids: list[np.ndarray]
    tracker_ids: list[np.ndarray]
    similarity: list[np.ndarray]


def _trackeval_metrics(threshold: float) -> list[Any]:
    import trackeval  # heavy (~0.7 s): imported when first needed

    quiet = {"THRESHOLD": float(threshold), "PRINT_CONFIG": False}
    return [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR(dict(quiet)), trackeval.metrics.Identity(dict(quiet)),
            trackeval.metrics.Count()]


def _relabel(ids_per_t: list[np.ndarray], seq: str, what: str) -> tuple[list[np.ndarray], np.ndarray]:
    """Contiguous 0-based ids over the sequence; check each id appears once per timestep."""
    if not ids_per_t:
        return [], np.zeros(0, np.int64)
    lengths = np.array([ids.size for ids in ids_per_t], dtype=np.int64)
    flat = np.concatenate(ids_per_t).astype(np.int64)
    unique, inverse = np.unique(flat, return_inverse=True)
    t_of = np.repeat(np.arange(lengths.size), lengths)
    key = t_of * max(unique.size, 1) + inverse
    keys, counts = np.unique(key, return_counts=True)
    if np.any(counts > 1):
        k = int(keys[np.argmax(counts > 1)])
        t, i = divmod(k, max(unique.size, 1))
        raise EvaluationError(f"{seq}: {what} id {int(unique[i])} appears more than once in timestep {t} "
                              f"(frame {t + 1})")
    return np.split(inverse.astype(np.int64), np.cumsum(lengths)[:-1]), unique


def _identity_map(gt: list[np.ndarray], tr: list[np.ndarray], sim: list[np.ndarray], gt_unique: np.ndarray,
                  tr_unique: np.ndarray, threshold: float) -> dict[int, int]:
    """One-to-one tracker -> gt map (original ids) maximising co-matched frames: Identity's assignment,
    whose cost is ``sum(gt dets) + sum(tracker dets) - 2 * sum(matched frames)``."""
    n_gt, n_tr = gt_unique.size, tr_unique.size
    if n_gt == 0 or n_tr == 0:
        return {}
    pairs = [g[r] * n_tr + t[c] for g, t, s in zip(gt, tr, sim, strict=True)
             for r, c in [np.nonzero(s >= threshold)]]
    flat = np.concatenate(pairs) if pairs else np.zeros(0, np.int64)
    counts = np.bincount(flat, minlength=n_gt * n_tr).reshape(n_gt, n_tr)
    rows, cols = linear_sum_assignment(-counts)
    keep = counts[rows, cols] > 0
    return {int(tr_unique[c]): int(gt_unique[r]) for r, c in zip(rows[keep], cols[keep], strict=True)}


def _max_matches(sim: list[np.ndarray], threshold: float) -> int:
    """Summed over timesteps, the largest one-to-one matching of pairs with similarity >= ``threshold``."""
    total = 0
    for s in sim:
        ok = s >= threshold
        if not ok.any():
            continue
        if (np.count_nonzero(ok, axis=0) <= 1).all() and (np.count_nonzero(ok, axis=1) <= 1).all():
            total += int(np.count_nonzero(ok))  # no contention: every candidate pair is its own match
            continue
        rows, cols = linear_sum_assignment(ok, maximize=True)
        total += int(np.count_nonzero(ok[rows, cols]))
    return total


def _evaluate(seq: _Sequence, threshold: float = _MATCH_SIMILARITY, distance_scale_m: float | None = None) -> Metrics:
    gt, gt_unique = _relabel(seq.gt_ids, seq.name, "ground-truth")
    tr, tr_unique = _relabel(seq.tracker_ids, seq.name, "tracker")
    sim = [np.asarray(s, dtype=np.float64).reshape(g.size, t.size) for g, t, s in zip(gt, tr, seq.similarity,
                                                                                       strict=True)]
    data = {
        "gt_ids": gt, "tracker_ids": tr, "similarity_scores": sim,
        "num_timesteps": len(gt), "num_gt_ids": int(gt_unique.size), "num_tracker_ids": int(tr_unique.size),
        "num_gt_dets": int(sum(g.size for g in gt)), "num_tracker_dets": int(sum(t.size for t in tr)),
        "seq": seq.name,
    }
    # Call the undecorated eval_sequence: TrackEval's timing wrapper prints once any Evaluator has switched
    # its global timing flag on (the Evaluator's default).
    raw = {type(m).__name__: getattr(type(m).eval_sequence, "__wrapped__", type(m).eval_sequence)(m, data)
           for m in _trackeval_metrics(threshold)}
    id_map = _identity_map(gt, tr, sim, gt_unique, tr_unique, threshold)
    return Metrics.from_trackeval(raw, num_frames=len(gt), distance_scale_m=distance_scale_m, id_map=id_map,
                                  max_matches=_max_matches(sim, threshold))


def combine_metrics(results: Iterable[Metrics] | Mapping[str, Metrics]) -> Metrics:
    """Combine several sequences as TrackEval's ``COMBINED_SEQ`` does (each metric's ``combine_sequences``).

    Parameters
    ----------
    results : iterable of Metrics, or mapping name -> Metrics
        Per-sequence results from this module (they carry TrackEval's raw dicts).

    Returns
    -------
    Metrics
        Counts summed; MOTA, IDF1, ... recomputed from the sums; HOTA's AssA and LocA weighted by
        HOTA_TP. ``id_map`` is empty; ``distance_scale_m`` is kept when all agree.
    """
    items = list(results.values()) if isinstance(results, Mapping) else list(results)
    if not items:
        raise EvaluationError("results: expected at least one Metrics to combine")
    if any(not m.raw for m in items):
        raise EvaluationError("results: every Metrics must come from this module's evaluate_* (raw TrackEval dicts)")
    metrics = _trackeval_metrics(_MATCH_SIMILARITY)
    raw = {type(m).__name__: m.combine_sequences({i: dict(r.raw[type(m).__name__]) for i, r in enumerate(items)})
           for m in metrics}
    scales = {m.distance_scale_m for m in items}
    known = all(m.max_matches >= 0 for m in items)
    return Metrics.from_trackeval(raw, num_frames=sum(m.num_frames for m in items),
                                  distance_scale_m=scales.pop() if len(scales) == 1 else None,
                                  max_matches=sum(m.max_matches for m in items) if known else -1)


# --------------------------------------------------------------------------------------------------
# Floor plane
# --------------------------------------------------------------------------------------------------


def floor_similarity(gt_xy_m: np.ndarray, track_xy_m: np.ndarray, threshold_m: float) -> np.ndarray:
    """TrackEval similarity of floor positions: ``max(0, 1 - d / (2 threshold_m))``, < 0.5 iff ``d > threshold_m``.

    Parameters
    ----------
    gt_xy_m : (n, 2) float
    track_xy_m : (m, 2) float
    threshold_m : float
        Match distance, m.

    Returns
    -------
    (n, m) float64
    """
    a = np.asarray(gt_xy_m, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(track_xy_m, dtype=np.float64).reshape(-1, 2)
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    d[~np.isfinite(d)] = np.inf  # a position that is NaN (a camera track without a floor) matches nothing
    sim = np.maximum(0.0, 1.0 - d / (2.0 * threshold_m))  # TrackEval's formula, zero_distance = 2 threshold
    return np.where(d > threshold_m, np.minimum(sim, _BELOW_MATCH), sim)


def _class_filter(classes: Iterable[str] | None) -> frozenset[str] | None:
    if classes is None:
        return None
    if isinstance(classes, str):
        classes = (classes,)
    try:
        return frozenset(str(ObjectClass(c)) for c in classes)
    except ValueError as err:
        raise EvaluationError(f"classes: expected values of {[c.value for c in ObjectClass]}, got "
                              f"{tuple(classes)!r}") from err


def _time_tolerance(gt_t: np.ndarray, time_tolerance_ns: int | None) -> int:
    if time_tolerance_ns is None:
        return int(np.median(np.diff(gt_t))) // 2 if gt_t.size > 1 else 0
    if isinstance(time_tolerance_ns, bool) or not isinstance(time_tolerance_ns, int | np.integer) \
            or time_tolerance_ns < 0:
        raise EvaluationError(f"time_tolerance_ns: expected an integer >= 0 or None, got {time_tolerance_ns!r}")
    return int(time_tolerance_ns)


def _nearest_frame(gt_t: np.ndarray, st_t: np.ndarray, tolerance_ns: int) -> tuple[np.ndarray, np.ndarray,
                                                                                   np.ndarray]:
    """Index of the nearest of the sorted frame times ``gt_t`` for each time ``st_t`` (the earlier on a tie),
    the offset (ns), and whether it is within ``tolerance_ns``."""
    n_t = gt_t.size
    after = np.searchsorted(gt_t, st_t)
    lo, hi = np.clip(after - 1, 0, n_t - 1), np.clip(after, 0, n_t - 1)
    dt_lo, dt_hi = np.abs(st_t - gt_t[lo]), np.abs(gt_t[hi] - st_t)
    frame = np.where(dt_hi < dt_lo, hi, lo)
    dt = np.minimum(dt_lo, dt_hi)
    return frame, dt, dt <= tolerance_ns


def _check_threshold(threshold_m: object) -> float:
    """``threshold_m`` as a float, if a finite distance > 0 m."""
    if not (isinstance(threshold_m, int | float | np.floating) and np.isfinite(threshold_m) and threshold_m > 0):
        raise EvaluationError(f"threshold_m: expected a finite distance > 0 m, got {threshold_m!r}")
    return float(threshold_m)


def _frames_in_order(gt: Sequence[GroundTruth]) -> tuple[list[GroundTruth], np.ndarray]:
    """The frames sorted by time and their times (int64); EvaluationError without frames or with two at one time."""
    frames = sorted(gt, key=lambda f: f.t_ns)
    if not frames:
        raise EvaluationError("gt: expected at least one GroundTruth frame")
    gt_t = np.array([f.t_ns for f in frames], dtype=np.int64)
    if np.any(np.diff(gt_t) == 0):
        t_dup = int(gt_t[1:][np.diff(gt_t) == 0][0])
        raise EvaluationError(f"gt: two GroundTruth frames at t_ns={t_dup}")
    return frames, gt_t


def _floor_sequence(gt: Sequence[GroundTruth], tracks: Iterable[TrackState | Track], threshold_m: float,
                    classes: frozenset[str] | None, time_tolerance_ns: int | None, name: str) -> _Sequence:
    frames, gt_t = _frames_in_order(gt)
    time_tolerance_ns = _time_tolerance(gt_t, time_tolerance_ns)
    n_t = gt_t.size

    # ground truth, per frame, sorted by id
    gt_ids, gt_pos = [], []
    for f in frames:
        keep = np.ones(len(f), bool) if classes is None else np.isin(np.array(f.classes, dtype=object),
                                                                     list(classes))
        order = np.argsort(f.ids[keep], kind="stable")
        gt_ids.append(f.ids[keep][order])
        gt_pos.append(f.positions_m[keep][order])

    # track states -> nearest ground-truth frame within the tolerance, one state per (frame, track)
    states = [s for s in flatten_states(tracks) if classes is None or s.cls in classes]
    st_t = np.array([s.t_ns for s in states], dtype=np.int64)
    st_id = np.array([s.track_id for s in states], dtype=np.int64)
    st_xy = np.array([s.position_m for s in states], dtype=np.float64).reshape(-1, 2)
    if st_t.size:
        pair = np.unique(np.stack([st_t, st_id], axis=1), axis=0, return_counts=True)
        if np.any(pair[1] > 1):
            t_dup, id_dup = pair[0][np.argmax(pair[1] > 1)].tolist()
            raise EvaluationError(f"tracks: two states of track {id_dup} at t_ns={t_dup}")
    _warn_if_slower(gt_t, st_t, name)
    _warn_if_shifted(gt_t, st_t, name)
    frame, dt, inside = _nearest_frame(gt_t, st_t, time_tolerance_ns)
    frame, dt, st_t, st_id, st_xy = frame[inside], dt[inside], st_t[inside], st_id[inside], st_xy[inside]
    order = np.lexsort((st_t, dt, st_id, frame))  # by frame, id, then nearest (earlier on a tie)
    frame, st_id, st_xy = frame[order], st_id[order], st_xy[order]
    first = np.ones(frame.size, bool)
    first[1:] = (frame[1:] != frame[:-1]) | (st_id[1:] != st_id[:-1])
    frame, st_id, st_xy = frame[first], st_id[first], st_xy[first]
    n_dropped = int(inside.size - inside.sum())
    if n_dropped:
        # most states far from every truth frame: the two are on different clocks (header stamps against log times)
        log_at = logging.WARNING if 2 * n_dropped > inside.size else logging.DEBUG
        logger.log(log_at, "%s: %d of %d track states are farther than %.0f ms from every ground-truth frame and are "
                   "not scored%s", name, n_dropped, inside.size, time_tolerance_ns / 1e6,
                   " (does the ground truth cover only part of them, or are the two on different clocks: header "
                   "stamps and log times, fusiontrack eval --time?)" if log_at == logging.WARNING else "")

    bounds = np.searchsorted(frame, np.arange(n_t + 1))
    tr_ids = [st_id[bounds[k]:bounds[k + 1]] for k in range(n_t)]
    sims = [floor_similarity(gt_pos[k], st_xy[bounds[k]:bounds[k + 1]], threshold_m) for k in range(n_t)]
    return _Sequence(name, gt_ids, tr_ids, sims)


def _warn_if_shifted(gt_t: np.ndarray, st_t: np.ndarray, name: str) -> None:
    """Log a warning when the tracks start and end well before (or after) the ground truth, by about as much: the two
    are on different clocks (e.g. tracks on a bag's log times against truth on its header stamps), and every track
    is then compared with where the people were at another time."""
    if gt_t.size < 2 or st_t.size < 2:
        return
    d0, d1 = float(st_t.min() - gt_t[0]), float(st_t.max() - gt_t[-1])
    big = max(1e9, 0.02 * float(gt_t[-1] - gt_t[0]))
    # one shift at both ends (truth that covers only part of the tracks moves one end, or the two by different
    # amounts: no clock problem)
    if d0 * d1 > 0 and min(abs(d0), abs(d1)) > big and abs(d0 - d1) <= 0.25 * max(abs(d0), abs(d1)):
        logger.warning("%s: the tracks start %+.1f s and end %+.1f s from the ground truth's start and end: are they "
                       "on one clock (header stamps or log times: fusiontrack eval --time)?", name, d0 / 1e9, d1 / 1e9)


def _warn_if_slower(gt_t: np.ndarray, st_t: np.ndarray, name: str) -> None:
    """Log a warning when the tracks come at a lower rate than the ground truth (see :func:`truth_at`): at 20 Hz against
    25 Hz truth, one truth frame in five has no report."""
    if gt_t.size < 3 or st_t.size < 3:
        return
    reports = np.unique(st_t[(st_t >= gt_t[0]) & (st_t <= gt_t[-1])])
    if reports.size < 10:
        return
    gt_period, st_period = float(np.median(np.diff(gt_t))), float(np.median(np.diff(reports)))
    if st_period > 1.2 * gt_period:  # (a median: the jitter of a tracker at the truth's rate stays below)
        logger.warning("%s: the tracks come every %.0f ms, the ground truth every %.0f ms: every truth frame between "
                       "two reports counts all its people as missed; to score at the tracker's rate, pass "
                       "truth_at(ground truth, the tracker's frame times) (CLI: fusiontrack eval --at TOPIC)",
                       name, st_period / 1e6, gt_period / 1e6)


def truth_at(gt: Sequence[GroundTruth], times_ns: Iterable[int], tolerance_ns: int | None = None
             ) -> list[GroundTruth]:
    """The ground-truth frames nearest to ``times_ns``, to score a tracker at the rate of the sensor it runs on.

    The frame-based metrics score every ground-truth frame, and a frame without any track state counts all its
    people as missed. A tracker that reports at its sensor's rate (a 15 Hz camera) against truth written at
    another (25 Hz, the lasers') has no state in two frames of five: its recall could not exceed 60 %, whatever
    it tracked. Scored on the truth frames nearest to its sensor's frames instead, each of its reports meets the
    truth of its own instant (within half a truth period; the frames are not restamped or interpolated).

    Parameters
    ----------
    gt : sequence of GroundTruth
        The truth, any order.
    times_ns : iterable of int
        The sensor's frame times (e.g. the image stamps of the camera the tracker read), ns.
    tolerance_ns : int or None
        A time farther than this from every truth frame selects none; ``None`` = half the truth's median period.

    Returns
    -------
    list of GroundTruth
        The selected frames, each once, in time order.

    Raises
    ------
    EvaluationError
        No truth frames, two at one time, or a bad tolerance.
    """
    frames, gt_t = _frames_in_order(gt)
    t = np.fromiter((int(x) for x in times_ns), dtype=np.int64)
    frame, _, inside = _nearest_frame(gt_t, t, _time_tolerance(gt_t, tolerance_ns))
    return [frames[k] for k in np.unique(frame[inside]).tolist()]


def evaluate_floor(gt: Sequence[GroundTruth], tracks: Iterable[TrackState | Track], threshold_m: float = 0.5,
                   classes: Iterable[str] | None = ("person",), time_tolerance_ns: int | None = None,
                   *, name: str = "floor") -> Metrics:
    """Metrics of floor-plane tracks against ground-truth frames (see the module docstring for the mapping).

    Parameters
    ----------
    gt : sequence of GroundTruth
        One frame per instant (any order; times must differ). Each frame is one timestep.
    tracks : iterable of TrackState or Track
        Tracker output in the ground truth's frame (``position_m``), any order.
    threshold_m : float
        Match distance, m: a track matches an object when within ``threshold_m`` (similarity >= 0.5).
    classes : iterable of str or None
        Object classes kept, in the ground truth and in the tracks (``TrackState.cls``); ``None`` = all.
    time_tolerance_ns : int or None
        Largest time offset between a track state and the frame it is scored in; ``None`` = half the
        median ground-truth period (0 for a single frame).
    name : str
        Sequence name used in error messages.

    Returns
    -------
    Metrics
        With ``distance_scale_m = 2 * threshold_m`` and ``id_map`` from track id to ground-truth id.

    Raises
    ------
    EvaluationError
        Bad threshold or tolerance, no frames, two frames at one time, two states of one track at one time.
    """
    seq = _floor_sequence(gt, tracks, _check_threshold(threshold_m), _class_filter(classes), time_tolerance_ns, name)
    return _evaluate(seq, _MATCH_SIMILARITY, distance_scale_m=2.0 * float(threshold_m))


@dataclass(frozen=True, slots=True, eq=False)
class FrameMatches:
    """CLEAR's matches of every ground-truth frame: which track stood for which object, frame by frame.

    The matching of TrackEval's CLEAR (the MOTA matching): per frame, the Hungarian algorithm on the similarity
    with a bonus for the pairs matched in the previous frame, pairs within the match threshold only. Unlike
    :attr:`Metrics.id_map` (one ground-truth id per track for the whole sequence, the IDF1 correspondence), a track
    that follows one person, then another, maps to each in turn.

    Attributes
    ----------
    t_ns : (n_frames,) int64
        The ground-truth frame times, ascending.
    matches : tuple of dict of int -> int
        Per frame, track id -> ground-truth id (original ids).
    by_track : dict of int -> (times (k,) int64, gt ids (k,) int64)
        The same matches per track, in time order.
    """

    t_ns: np.ndarray
    matches: tuple[dict[int, int], ...]
    by_track: dict[int, tuple[np.ndarray, np.ndarray]]

    @classmethod
    def from_frames(cls, t_ns: np.ndarray, matches: Sequence[dict[int, int]]) -> FrameMatches:
        rows: dict[int, list[tuple[int, int]]] = {}
        for t, frame in zip(np.asarray(t_ns).tolist(), matches, strict=True):
            for tid, g in frame.items():
                rows.setdefault(tid, []).append((t, g))
        by_track = {tid: (np.array([r[0] for r in v], np.int64), np.array([r[1] for r in v], np.int64))
                    for tid, v in rows.items()}
        return cls(np.asarray(t_ns, np.int64), tuple(matches), by_track)

    @property
    def n_matches(self) -> int:
        """All matches summed over frames (CLEAR's TP)."""
        return sum(len(m) for m in self.matches)

    def gt_id(self, track_id: int, t_ns: int, t_end_ns: int | None = None, within_ns: int = 0) -> int | None:
        """The object ``track_id`` was matched to nearest in time to ``[t_ns, t_end_ns]`` (the earliest match
        inside it, else the nearest one outside), at most ``within_ns`` away; None without such a match."""
        hit = self.by_track.get(int(track_id))
        if hit is None:
            return None
        times, ids = hit
        end = t_ns if t_end_ns is None else max(t_ns, t_end_ns)
        k = int(np.searchsorted(times, t_ns))  # first match at or after the start
        if k < times.size and times[k] <= end:
            return int(ids[k])
        best, gap = None, within_ns
        if k < times.size and times[k] - end <= gap:
            best, gap = int(ids[k]), int(times[k] - end)
        if k > 0 and t_ns - times[k - 1] <= gap:
            best = int(ids[k - 1])
        return best


def _clear_matches(seq: _Sequence, threshold: float) -> list[dict[int, int]]:
    """Per timestep, CLEAR's matches in original ids (TrackEval's ``CLEAR.eval_sequence`` matching, written out:
    TrackEval keeps the matches to itself)."""
    out: list[dict[int, int]] = []
    prev: dict[int, int] = {}  # gt id -> track id matched in the previous timestep
    for g, t, s in zip(seq.gt_ids, seq.tracker_ids, seq.similarity, strict=True):
        sim = np.asarray(s, dtype=np.float64).reshape(g.size, t.size)
        if not g.size or not t.size:  # (TrackEval skips the timestep: the previous matches stay)
            out.append({})
            continue
        had = np.array([int(gi) in prev for gi in g.tolist()])
        before = np.array([prev.get(int(gi), 0) for gi in g.tolist()], dtype=np.int64)
        cont = had[:, None] & (before[:, None] == t[None, :])
        score = 1000.0 * cont + sim
        score[sim < threshold - _EPS] = 0.0
        rows, cols = linear_sum_assignment(-score)
        ok = score[rows, cols] > _EPS
        frame = {int(t[c]): int(g[r]) for r, c in zip(rows[ok], cols[ok], strict=True)}
        out.append(frame)
        prev = {gi: ti for ti, gi in frame.items()}
    return out


def frame_matches(gt: Sequence[GroundTruth], tracks: Iterable[TrackState | Track], threshold_m: float = 0.5,
                  classes: Iterable[str] | None = ("person",), time_tolerance_ns: int | None = None) -> FrameMatches:
    """CLEAR's frame-by-frame matches of floor-plane tracks to ground truth (parameters as :func:`evaluate_floor`,
    whose MOTA counts these matches: their number is its ``tp``).

    Situation-detection scoring (:func:`fusiontrack.eval.situation_accuracy`) takes it as ``id_map``: a detected
    event then names the people its tracks followed at the time of the event.
    """
    seq = _floor_sequence(gt, tracks, _check_threshold(threshold_m), _class_filter(classes), time_tolerance_ns,
                          "floor")
    t_ns = np.array(sorted(f.t_ns for f in gt), dtype=np.int64)
    return FrameMatches.from_frames(t_ns, _clear_matches(seq, _MATCH_SIMILARITY))


# --------------------------------------------------------------------------------------------------
# Image boxes (MOTChallenge)
# --------------------------------------------------------------------------------------------------


def _box_ious(gt_ltwh: np.ndarray, res_ltwh: np.ndarray) -> np.ndarray:
    """IoU ``(n, m)`` of ``(n, 4)`` and ``(m, 4)`` ltwh boxes, by TrackEval's own function."""
    if gt_ltwh.shape[0] == 0 or res_ltwh.shape[0] == 0:
        return np.zeros((gt_ltwh.shape[0], res_ltwh.shape[0]))
    from trackeval.datasets._base_dataset import _BaseDataset

    return _BaseDataset._calculate_box_ious(gt_ltwh, res_ltwh, box_format="xywh")


def _frame_slices(frame: np.ndarray, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Row order (stable by frame, file order within a frame) and slice bounds of frames 1..n_frames."""
    order = np.argsort(frame, kind="stable")
    return order, np.searchsorted(frame[order], np.arange(1, n_frames + 2))


def _box_sequence(gt: MotBoxes, res: MotBoxes, preprocess: bool, distractor_classes: Sequence[int],
                  n_frames: int, name: str) -> _Sequence:
    # TrackEval reads column 7 of gt with ``astype(int)`` as "zero_marked" (consider flag)
    considered = gt.conf.astype(np.int64) != 0
    gt_class = gt.extra[:, 0].astype(np.int64) if preprocess else np.full(len(gt), _PEDESTRIAN)
    distractors = np.asarray(distractor_classes, dtype=np.int64)
    g_order, g_bounds = _frame_slices(gt.frame, n_frames)
    r_order, r_bounds = _frame_slices(res.frame, n_frames)
    gt_ids, tr_ids, sims = [], [], []
    for k in range(n_frames):
        g = g_order[g_bounds[k]:g_bounds[k + 1]]
        r = r_order[r_bounds[k]:r_bounds[k + 1]]
        iou = _box_ious(gt.boxes_ltwh[g], res.boxes_ltwh[r])
        keep_r = np.ones(r.size, bool)
        if preprocess and g.size and r.size:
            # MotChallenge2DBox step 2: drop tracker boxes matched to a distractor (IoU >= 0.5, any gt class)
            scores = np.where(iou < _MATCH_SIMILARITY - _EPS, 0.0, iou)
            rows, cols = linear_sum_assignment(-scores)
            matched = scores[rows, cols] > _EPS
            rows, cols = rows[matched], cols[matched]
            keep_r[cols[np.isin(gt_class[g][rows], distractors)]] = False
        keep_g = considered[g] & (gt_class[g] == _PEDESTRIAN) if preprocess else considered[g]
        gt_ids.append(gt.id[g][keep_g])
        tr_ids.append(res.id[r][keep_r])
        sims.append(iou[np.ix_(keep_g, keep_r)])
    return _Sequence(name, gt_ids, tr_ids, sims)


def evaluate_boxes(gt: MotBoxes, res: MotBoxes, *, preprocess: bool | None = None, iou_threshold: float = 0.5,
                   n_frames: int | None = None, distractor_classes: Sequence[int] = MOT16_DISTRACTOR_CLASSES,
                   name: str = "boxes", gt_name: str | None = None) -> Metrics:
    """Metrics of image boxes (MOTChallenge rows) with IoU similarity.

    Parameters
    ----------
    gt, res : MotBoxes
        Ground truth and tracker output (:func:`fusiontrack.io.tracks.read_mot`); frames are 1-based.
    preprocess : bool or None
        MOT16/17/20 preprocessing (distractor removal, pedestrians only; see the module docstring);
        ``None`` = on when the ground truth has the 9-column MOT16/17/20 layout.
    iou_threshold : float
        CLEAR and Identity match threshold on IoU (0.5 in every benchmark); HOTA always sweeps alpha
        and preprocessing always uses 0.5, as in TrackEval.
    n_frames : int or None
        Sequence length (``seqLength``); ``None`` = the last frame in either file. Only
        ``FP_per_frame`` and :attr:`Metrics.num_frames` depend on it.
    distractor_classes : sequence of int
        Ground-truth classes whose matched tracker boxes are removed when preprocessing
        (:data:`MOT20_DISTRACTOR_CLASSES` for MOT20).
    name : str
        Sequence name used in error messages.
    gt_name : str, optional
        The ground truth's name in its messages (default ``name``).

    Raises
    ------
    EvaluationError
        A frame outside ``1 .. n_frames``, an id twice in one frame, a bad threshold, ``preprocess``
        asked of ground truth without a class column, or ground truth whose column 7 (the consider flag) drops
        every box.
    """
    if not (isinstance(iou_threshold, int | float | np.floating) and 0 < iou_threshold <= 1):
        raise EvaluationError(f"iou_threshold: expected a value in (0, 1], got {iou_threshold!r}")
    if preprocess is None:
        preprocess = gt.extra.shape[1] == 2  # MOT16/17/20 gt: consider, class, visibility
    if preprocess and gt.extra.shape[1] < 1:
        raise EvaluationError(f"{name}: preprocess needs the ground-truth class column (the 8th), which the "
                              "ground truth lacks")
    last = int(max(gt.frame.max(initial=0), res.frame.max(initial=0)))
    if n_frames is None:
        n_frames = last
    elif not isinstance(n_frames, int | np.integer) or n_frames < last:
        raise EvaluationError(f"n_frames: expected an integer >= {last} (the last frame in the files), "
                              f"got {n_frames!r}")
    first = int(min(gt.frame.min(initial=1), res.frame.min(initial=1)))
    if first < 1:
        raise EvaluationError(f"{name}: frames are 1-based, found frame {first}")
    _check_consider_flags(gt, name if gt_name is None else gt_name)
    seq = _box_sequence(gt, res, bool(preprocess), distractor_classes, int(n_frames), name)
    return _evaluate(seq, float(iou_threshold))


def _check_consider_flags(gt: MotBoxes, name: str) -> None:
    """Column 7 of ground truth is the *consider* flag, read as an integer (as TrackEval does): 0 drops the box.
    Ground truth in which it drops every box scores nothing (an error); one whose flags are fractions, such as a
    detection file's confidences, loses those in (-1, 1) (a warning naming how many)."""
    if not len(gt):
        return
    flag = gt.conf.astype(np.int64)
    if not np.any(flag != 0):
        frac = np.any(gt.conf != np.round(gt.conf))
        raise EvaluationError(f"{name}: column 7 of the ground truth (the consider flag, an integer: 0 = not "
                              f"scored) drops every one of its {len(gt)} boxes"
                              + (" (its values are fractions, like a detection file's confidences: is it one?)"
                                 if frac else ""))
    lost = np.count_nonzero((flag == 0) & (gt.conf != 0))
    if lost:
        logger.warning("%s: %d of the ground truth's %d boxes have a fraction in (-1, 1) in column 7 (the consider "
                       "flag, read as an integer as TrackEval does): they are dropped as 0 (not scored)", name,
                       lost, len(gt))


def evaluate_camera_boxes(truth: Sequence[GroundTruth], tracks: Iterable[TrackState | Track] | MotBoxes,
                          width: float | None, height: float | None, *, classes: Iterable[str] | None = ("person",),
                          min_visibility: float = 0.5, iou_threshold: float = 0.5,
                          time_tolerance_ns: int | None = None, camera: str | None = None, name: str = "camera",
                          warn_dropped_fraction: float = 0.05) -> Metrics:
    """Metrics of image tracks against a simulated camera's truth boxes (see the module docstring).

    Parameters
    ----------
    truth : sequence of GroundTruth
        The camera's truth records (``/ground_truth/<camera>``), one per image, with attributes ``box_px``
        (n, 4) and ``visibility`` (n,). Record ``k`` in time order is frame ``k + 1``.
    tracks : iterable of TrackState or Track, or MotBoxes
        States with ``box_px`` in that camera's image (states without a box are skipped), or MOTChallenge
        rows already numbered by those frames (e.g. ``tracks_mot.txt`` of ``fusiontrack track``). Each state is
        scored in the frame nearest in time; of several states of one track in one frame, the nearest (the
        earlier on a tie) is kept, as in :func:`evaluate_floor`.
    width, height : float or None
        Image size (px); truth boxes are clipped to it (``None``: not clipped).
    classes : iterable of str or None
        Truth classes kept (``None`` = all).
    min_visibility : float
        Less visible people are distractors.
    iou_threshold : float
        CLEAR and Identity match threshold.
    time_tolerance_ns : int or None
        Largest offset between a state and its frame; ``None`` = half the median truth period. States farther
        from every frame are not scored (a warning when more than ``warn_dropped_fraction`` of them).
    camera : str or None
        The truth's camera: only states of it (``TrackState.camera``, an empty field counting as this camera)
        are scored; ``None`` = every state (MOT rows carry no camera).
    name : str
        Sequence name used in error and warning messages.
    warn_dropped_fraction : float
        Share of the states outside the time tolerance above which a warning is logged (0.05).

    Raises
    ------
    EvaluationError
        No truth records, two at one time, two MOT rows of one track in one frame, a bad threshold, or MOT
        rows outside ``1 .. len(truth)``.
    """
    from ..vision.people import camera_truth_boxes  # vision pulls in OpenCV: only when asked

    frames = sorted(truth, key=lambda f: f.t_ns)
    if not frames:
        raise EvaluationError(f"{name}: expected at least one ground-truth record of the camera")
    gt_t = np.array([f.t_ns for f in frames], dtype=np.int64)
    if np.any(np.diff(gt_t) == 0):
        raise EvaluationError(f"{name}: two ground-truth records at t_ns={int(gt_t[1:][np.diff(gt_t) == 0][0])}")
    size = [np.inf if x is None else x for x in (width, height)]
    if not all(isinstance(x, int | float | np.number) and x > 0 for x in size):
        raise EvaluationError(f"{name}: expected a positive image size, got {width!r} x {height!r}")
    gt = camera_truth_boxes(frames, size[0], size[1], min_visibility=min_visibility)  # type: ignore[arg-type]
    keep_cls = _class_filter(classes)
    if keep_cls is not None:
        ids = np.concatenate([f.ids for f in frames]).astype(np.int64)
        cls = np.concatenate([np.array(f.classes if len(f.classes) == len(f) else [""] * len(f), dtype=object)
                              for f in frames]) if ids.size else np.zeros(0, object)
        kept_ids = np.unique(ids[np.isin(cls, list(keep_cls))])
        sel = np.isin(gt.id, kept_ids)
        gt = MotBoxes(gt.frame[sel], gt.id[sel], gt.boxes_ltwh[sel], gt.conf[sel], gt.extra[sel])
    if isinstance(tracks, MotBoxes):
        res = tracks
        if len(res) and (res.frame.min() < 1 or res.frame.max() > len(frames)):
            raise EvaluationError(f"{name}: track rows in frames {int(res.frame.min())}..{int(res.frame.max())}, "
                                  f"expected 1..{len(frames)} (one per ground-truth record)")
    else:
        boxed = [s for s in flatten_states(tracks) if s.box_px is not None]
        states = boxed if camera is None else [s for s in boxed if s.camera in (camera, "")]
        if len(states) < len(boxed):
            others = sorted({s.camera for s in boxed} - {camera, ""})
            logger.info("%s: %d states with boxes of other cameras (%s) are not evaluated", name,
                        len(boxed) - len(states), ", ".join(others))
        tolerance = _time_tolerance(gt_t, time_tolerance_ns)
        st_t = np.array([s.t_ns for s in states], dtype=np.int64)
        st_id = np.array([s.track_id for s in states], dtype=np.int64)
        box = np.array([s.box_px for s in states], dtype=np.float64).reshape(-1, 4)
        frame, dt, inside = _nearest_frame(gt_t, st_t, tolerance)
        n_out = int((~inside).sum())
        if n_out:
            share = n_out / inside.size
            (logger.warning if share > warn_dropped_fraction else logger.debug)(
                "%s: %d of %d states (%.1f %%) are farther than %.3f s from every ground-truth frame and are not "
                "evaluated (tracks of another time base or rate?)", name, n_out, inside.size, 100 * share,
                tolerance / 1e9)
        frame, dt, st_t, st_id, box = frame[inside], dt[inside], st_t[inside], st_id[inside], box[inside]
        order = np.lexsort((st_t, dt, st_id, frame))  # by frame, id, then nearest in time (the earlier on a tie)
        frame, st_id, box = frame[order], st_id[order], box[order]
        first = np.ones(frame.size, bool)
        first[1:] = (frame[1:] != frame[:-1]) | (st_id[1:] != st_id[:-1])
        frame, st_id, box = frame[first], st_id[first], box[first]
        res = MotBoxes(frame.astype(np.int64) + 1, st_id, np.column_stack([box[:, :2], box[:, 2:] - box[:, :2]]),
                       np.ones(frame.size), np.zeros((frame.size, 0)))
    return evaluate_boxes(gt, res, preprocess=True, iou_threshold=iou_threshold, n_frames=len(frames), name=name)


def _seq_length(gt_path: Path) -> tuple[int, Path] | None:
    """``seqLength`` and the ``seqinfo.ini`` it was read from (beside the ``gt/`` folder, else beside the file)."""
    for ini in (gt_path.parent.parent / "seqinfo.ini", gt_path.parent / "seqinfo.ini"):
        if ini.is_file():
            parser = configparser.ConfigParser()
            try:
                parser.read(ini, encoding="utf-8")
                return int(parser["Sequence"]["seqLength"]), ini
            except (configparser.Error, KeyError, ValueError) as err:
                raise EvaluationError(f"{ini}: expected [Sequence] seqLength=<int> ({err})") from err
    return None


def evaluate_mot_files(gt_path: str | Path, res_path: str | Path, *, preprocess: bool | None = None,
                       iou_threshold: float = 0.5, n_frames: int | None = None,
                       distractor_classes: Sequence[int] = MOT16_DISTRACTOR_CLASSES) -> Metrics:
    """Metrics of a MOTChallenge result file against its ground truth (see :func:`evaluate_boxes`).

    ``n_frames=None`` reads ``seqLength`` from ``seqinfo.ini`` beside the ground truth's ``gt/`` folder
    (MOTChallenge layout ``SEQ/gt/gt.txt`` + ``SEQ/seqinfo.ini``) or beside ``gt.txt``, else uses the
    last frame in the files.

    Raises
    ------
    RecordingError
        A file is missing or malformed (file and line named).
    EvaluationError
        As :func:`evaluate_boxes`, or a malformed ``seqinfo.ini``.
    """
    gt_path, res_path = Path(gt_path), Path(res_path)
    gt, res = read_mot(gt_path), read_mot(res_path, allow_empty=True)
    if not len(res):  # (TrackEval scores an empty result too: every truth box missed)
        logger.warning("%s: no boxes: every box of %s counts as missed", res_path, gt_path)
    if len(gt) and len(res):
        inside = np.isin(res.frame, np.unique(gt.frame)).mean()
        if inside < 0.5:  # (scored all the same: every truth box missed, every result box a false positive)
            logger.warning("%s: %.0f %% of its boxes are in frames of %s (its frames %d..%d, the truth's %d..%d): "
                        "another sequence, or frames numbered otherwise?", res_path, 100 * inside, gt_path,
                        res.frame.min(), res.frame.max(), gt.frame.min(), gt.frame.max())
    if n_frames is None and (found := _seq_length(gt_path)) is not None:
        n_frames, ini = found
        for path, boxes in ((res_path, res), (gt_path, gt)):
            if len(boxes) and int(boxes.frame.max()) > n_frames:
                raise EvaluationError(f"{path}: frame {int(boxes.frame.max())} is past the sequence's last, "
                                      f"{n_frames} (seqLength in {ini}): another sequence, or frames numbered "
                                      "otherwise?")
    return evaluate_boxes(gt, res, preprocess=preprocess, iou_threshold=iou_threshold, n_frames=n_frames,
                          distractor_classes=distractor_classes, name=str(res_path), gt_name=str(gt_path))


# --------------------------------------------------------------------------------------------------
# Presentation
# --------------------------------------------------------------------------------------------------

_TABLE_COLUMNS = (  # (header, field, is a fraction shown in percent)
    ("HOTA", "hota", True), ("DetA", "deta", True), ("AssA", "assa", True), ("LocA", "loca", True),
    ("MOTA", "mota", True), ("MOTP", "motp", True), ("IDF1", "idf1", True),
    ("IDF1max", "idf1_ceiling", True),  # IDF1 with perfect identities: the rest of the gap is detection errors
    ("IDP", "idp", True),
    ("IDR", "idr", True), ("Rcll", "recall", True), ("Prcn", "precision", True), ("IDSW", "id_switches", False),
    ("Frag", "fragmentations", False), ("FP", "fp", False), ("FN", "fn", False), ("GT", "num_gt_ids", False),
    ("MT", "mostly_tracked", False), ("PT", "partially_tracked", False), ("ML", "mostly_lost", False),
)


def metrics_table(results: Mapping[str, Metrics], *, title: str | None = None) -> MetricsTable:
    """A rich renderable of ``results``, fractions in percent with one decimal (MOTChallenge style).

    One row per entry of ``results`` and one column per metric when that fits the console; otherwise (the 21
    metric columns need about 190 characters) one row per metric and one column per entry, so that no header or
    number is cut. Floor-plane results (all with a distance scale) get a ``MOTP m`` column (row): the mean matched
    distance. ``IDF1max`` is :attr:`Metrics.idf1_ceiling`.
    """
    return MetricsTable(dict(results), title)


class MetricsTable:
    """The renderable of :func:`metrics_table`: wide (a row per result) when it fits, else transposed.

    ``wide()`` and ``tall()`` give either layout as a :class:`rich.table.Table`.
    """

    def __init__(self, results: Mapping[str, Metrics], title: str | None = None) -> None:
        self.results, self.title = dict(results), title
        self._floor = bool(self.results) and all(m.distance_scale_m is not None for m in self.results.values())

    def _cells(self) -> tuple[list[str], list[list[str]]]:
        """Metric headers, and per result its cells in that order."""
        headers = [h for h, _, _ in _TABLE_COLUMNS] + (["MOTP m"] if self._floor else [])
        rows = []
        for m in self.results.values():
            cells = [f"{100 * getattr(m, f):.1f}" if pct else str(getattr(m, f)) for _, f, pct in _TABLE_COLUMNS]
            if self._floor:
                cells.append("-" if m.motp_m is None else f"{m.motp_m:.3f}")
            rows.append(cells)
        return headers, rows

    def wide(self) -> Table:
        from rich.table import Table

        headers, rows = self._cells()
        table = Table(title=self.title)
        table.add_column("sequence", style="bold")
        for header in headers:
            table.add_column(header, justify="right", no_wrap=True)
        for name, cells in zip(self.results, rows, strict=True):
            table.add_row(str(name), *cells)
        return table

    def tall(self) -> Table:
        from rich.table import Table

        headers, rows = self._cells()
        table = Table(title=self.title)
        table.add_column("metric", style="bold", no_wrap=True)
        for name in self.results:
            table.add_column(str(name), justify="right", overflow="fold")
        for q, header in enumerate(headers):
            table.add_row(header, *(cells[q] for cells in rows))
        return table

    def _layout(self, console: Any, options: Any) -> Table:
        wide = self.wide()
        natural = console.measure(wide, options=options.update(max_width=10_000)).maximum  # unclamped width
        return wide if natural <= options.max_width else self.tall()

    def __rich_console__(self, console: Any, options: Any) -> Any:
        yield self._layout(console, options)

    def __rich_measure__(self, console: Any, options: Any) -> Any:
        return console.measure(self._layout(console, options), options=options)
