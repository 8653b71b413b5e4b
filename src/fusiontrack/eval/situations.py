"""Situation-detection accuracy: the tracker's situation events against the true ones (seed 001, Table II).

True events come from :func:`fusiontrack.sim.situations.situation_events` (kinds ``merge``, ``split``,
``correlated``, ``appear``, ``disappear``); detected events are the tracker's
:class:`~fusiontrack.types.Event` records of the same kinds. Per kind, detections are matched one-to-one
to true events (:func:`match_events`), and :func:`situation_accuracy` reports the true count, the
true events detected (true positives), the false alarms (detections matched to nothing), recall
and precision.

A detection ``d`` may match a true event ``e`` when all of these hold:

* same ``kind``;
* time: the gap between their time spans ``[t_ns, t_end_ns]`` is at most ``time_tolerance_ns``
  (default 1 s). For instants (merge, split: ``t_end_ns == t_ns``) this is ``|t_d - t_e| <= 1 s``;
  a detection inside a true correlated episode, or a tracker's appear/disappear anywhere in the true
  event's window (``appear``: entry .. entry + 1 s; ``disappear``: up to 1 s before the exit .. exit),
  matches. ``t_end_ns = None`` (still going on) extends to the end of time;
* identities, when ``id_map`` is given: the detection's ids mapped to ground-truth ids share at least one
  with the true event's ``track_ids`` (a detection none of whose ids maps to anything cannot match).
  ``id_map`` is either :func:`~fusiontrack.eval.mot.frame_matches` of the same run (CLEAR's frame-by-frame
  matches: each track maps to the person it followed at the time of the event, its first match within the
  event's span, else its match nearest to it within ``time_tolerance_ns``: a track is not matched yet when
  its person appears, nor any more once the person has gone), or one tracker id -> ground-truth id for the
  whole run (:attr:`fusiontrack.eval.mot.Metrics.id_map`, the IDF1 correspondence; or ``{i: i for i in ...}``
  when the detector reports ground-truth ids). With the whole-run map, an event of a track that followed
  two people in turn can only match events of the person it followed longer: an identity error, which IDF1
  and the ID switches count already, then also counts as a missed situation and a false alarm;
* position, only without ``id_map`` and only when both events have ``position_m``: within
  ``position_tolerance_m`` (default 1 m); otherwise time alone decides.

Among the allowed pairs the matching maximises the number of matches, then minimises the summed
start-time offsets (Hungarian algorithm), so the counts do not depend on the order of the inputs.

:func:`segment_frames` builds the measurement-level truth of a simulated recording
(:class:`fusiontrack.sim.situations.SegmentFrame`, for
:func:`~fusiontrack.sim.situations.segment_situation_events`): it replays the laser detector the tracker uses
over the same scans and attributes every segment point to the agent its beam hit.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..sim.situations import EVENT_KINDS, SegmentFrame, load_laser_hits
from ..types import Event
from .errors import EvaluationError
from .mot import FrameMatches, _nearest_frame

if TYPE_CHECKING:
    from rich.table import Table

__all__ = ["AGREEMENT_LABELS", "SituationAgreement", "SituationScore", "match_events", "segment_frames",
           "situation_accuracy", "situation_agreement", "situation_table"]

_FOREVER = 2**62  # "still going on"; far from int64 overflow when differences are taken


@dataclass(frozen=True, slots=True)
class SituationScore:
    """Detection accuracy of one kind of situation event.

    Attributes
    ----------
    kind : str
    true : int
        Number of true events.
    detected : int
        True events matched by a detection (true positives).
    false_alarms : int
        Detections matched to no true event.
    detections : int
        Number of detections (``detected + false_alarms``).
    """

    kind: str
    true: int
    detected: int
    false_alarms: int
    detections: int

    @property
    def recall(self) -> float:
        """``detected / true``; ``NaN`` when there is no true event."""
        return self.detected / self.true if self.true else float("nan")

    @property
    def precision(self) -> float:
        """``detected / detections``; ``NaN`` when there is no detection."""
        return self.detected / self.detections if self.detections else float("nan")

    def to_dict(self) -> dict[str, str | int | float]:
        return {"kind": self.kind, "true": self.true, "detected": self.detected, "false_alarms": self.false_alarms,
                "detections": self.detections, "recall": self.recall, "precision": self.precision}


def _check_options(time_tolerance_ns: int, position_tolerance_m: float) -> None:
    if isinstance(time_tolerance_ns, bool) or not isinstance(time_tolerance_ns, int | np.integer) \
            or time_tolerance_ns < 0:
        raise EvaluationError(f"time_tolerance_ns: expected an integer >= 0, got {time_tolerance_ns!r}")
    if not position_tolerance_m >= 0:
        raise EvaluationError(f"position_tolerance_m: expected a distance >= 0 m, got {position_tolerance_m!r}")


def _spans(events: Sequence[Event]) -> tuple[np.ndarray, np.ndarray]:
    start = np.array([e.t_ns for e in events], dtype=np.int64)
    end = np.array([_FOREVER if e.t_end_ns is None else e.t_end_ns for e in events], dtype=np.int64)
    return start, end


def _positions(events: Sequence[Event]) -> np.ndarray:
    return np.array([(np.nan, np.nan) if e.position_m is None else e.position_m for e in events],
                    dtype=np.float64).reshape(-1, 2)


def _incidence(id_lists: Sequence[Sequence[int]], universe: np.ndarray) -> np.ndarray:
    """``(n_events, n_ids)`` int: 1 where the event names the id."""
    lengths = np.array([len(ids) for ids in id_lists], dtype=np.int64)
    flat = np.fromiter((i for ids in id_lists for i in ids), dtype=np.int64, count=int(lengths.sum()))
    out = np.zeros((len(id_lists), universe.size), dtype=np.int64)
    out[np.repeat(np.arange(len(id_lists)), lengths), np.searchsorted(universe, flat)] = 1
    return out


def _allowed(true: Sequence[Event], det: Sequence[Event], time_tolerance_ns: int,
             id_map: Mapping[int, int] | FrameMatches | None,
             position_tolerance_m: float) -> tuple[np.ndarray, np.ndarray]:
    """``(n_true, n_det)`` bool of allowed pairs and ``(n_true, n_det)`` start-time offsets in ns (int64)."""
    t_start, t_end = _spans(true)
    d_start, d_end = _spans(det)
    # gap between the spans [t_start, t_end] and [d_start, d_end] (0 when they overlap)
    gap = np.maximum(np.maximum(t_start[:, None] - d_end[None, :], d_start[None, :] - t_end[:, None]), 0)
    ok = gap <= time_tolerance_ns
    offset = np.abs(t_start[:, None] - d_start[None, :])
    if id_map is not None:
        true_ids = [e.track_ids for e in true]
        if isinstance(id_map, FrameMatches):  # the people the tracks followed at the time of the event
            det_ids = [tuple(g for i in e.track_ids
                             if (g := id_map.gt_id(i, e.t_ns, e.t_end_ns, time_tolerance_ns)) is not None)
                       for e in det]
        else:
            det_ids = [tuple(id_map[i] for i in e.track_ids if i in id_map) for e in det]
        universe = np.unique(np.fromiter((i for ids in (*true_ids, *det_ids) for i in ids), dtype=np.int64))
        ok &= (_incidence(true_ids, universe) @ _incidence(det_ids, universe).T) > 0
    else:
        diff = _positions(true)[:, None, :] - _positions(det)[None, :, :]
        ok &= ~(np.linalg.norm(diff, axis=2) > position_tolerance_m)  # NaN (no position) passes
    return ok, offset


def match_events(true_events: Sequence[Event], detected_events: Sequence[Event], *,
                 time_tolerance_ns: int = 1_000_000_000, id_map: Mapping[int, int] | FrameMatches | None = None,
                 position_tolerance_m: float = 1.0) -> list[tuple[int, int]]:
    """One-to-one matches between true and detected events of the same kind (rules in the module docstring).

    Parameters
    ----------
    true_events, detected_events : sequence of Event
    time_tolerance_ns : int
        Largest gap between the two events' time spans, ns.
    id_map : FrameMatches or mapping of int -> int, optional
        Tracker ids -> ground-truth ids (module docstring); when given, matched events must share an identity.
    position_tolerance_m : float
        Largest distance between the events' positions (without ``id_map``, when both have one), m.

    Returns
    -------
    list of (int, int)
        ``(index into true_events, index into detected_events)``, sorted.
    """
    _check_options(time_tolerance_ns, position_tolerance_m)
    true_events, detected_events = list(true_events), list(detected_events)
    pairs: list[tuple[int, int]] = []
    for kind in sorted({e.kind for e in true_events} & {e.kind for e in detected_events}):
        ti = [i for i, e in enumerate(true_events) if e.kind == kind]
        di = [i for i, e in enumerate(detected_events) if e.kind == kind]
        ok, offset = _allowed([true_events[i] for i in ti], [detected_events[i] for i in di], time_tolerance_ns,
                              id_map, position_tolerance_m)
        # Every allowed pair is worth more than any sum of tie-breaks: maximum matches first, then the
        # smallest summed start offsets (each normalised into [0, 1)).
        worth = min(len(ti), len(di)) + 2
        cost = np.where(ok, offset / (offset.max(initial=0) + 1.0) - worth, 0.0)
        rows, cols = linear_sum_assignment(cost)
        keep = ok[rows, cols]
        pairs.extend((ti[r], di[c]) for r, c in zip(rows[keep], cols[keep], strict=True))
    return sorted(pairs)


def situation_accuracy(true_events: Iterable[Event], detected_events: Iterable[Event], *,
                       kinds: Sequence[str] = EVENT_KINDS, time_tolerance_ns: int = 1_000_000_000,
                       id_map: Mapping[int, int] | FrameMatches | None = None,
                       position_tolerance_m: float = 1.0) -> dict[str, SituationScore]:
    """Per kind of situation: true count, detected, false alarms (seed 001 Table II).

    Parameters
    ----------
    true_events : iterable of Event
        From :func:`fusiontrack.sim.situations.situation_events`.
    detected_events : iterable of Event
        The tracker's situation events; kinds not in ``kinds`` are ignored.
    kinds : sequence of str
        The kinds scored (every one gets an entry, also when it has no events).
    time_tolerance_ns, id_map, position_tolerance_m
        As :func:`match_events`.

    Returns
    -------
    dict of str -> SituationScore
        In the order of ``kinds``.
    """
    wanted = tuple(kinds)
    true = [e for e in true_events if e.kind in wanted]
    det = [e for e in detected_events if e.kind in wanted]
    pairs = match_events(true, det, time_tolerance_ns=time_tolerance_ns, id_map=id_map,
                         position_tolerance_m=position_tolerance_m)
    kind_true = np.array([e.kind for e in true], dtype=object)
    kind_det = np.array([e.kind for e in det], dtype=object)
    kind_pair = np.array([true[i].kind for i, _ in pairs], dtype=object)
    scores = {}
    for kind in wanted:
        n_true, n_det, n_hit = (int(np.count_nonzero(k == kind)) for k in (kind_true, kind_det, kind_pair))
        scores[kind] = SituationScore(kind=kind, true=n_true, detected=n_hit, false_alarms=n_det - n_hit,
                                      detections=n_det)
    return scores


def situation_table(scores: Mapping[str, SituationScore], *, title: str | None = None) -> Table:
    """A rich table of :func:`situation_accuracy`'s result: one row per kind, recall and precision in percent."""
    from rich.table import Table

    table = Table(title=title)
    for header in ("situation", "true", "detected", "false alarms", "recall %", "precision %"):
        table.add_column(header, justify="left" if header == "situation" else "right")
    for kind, s in scores.items():
        table.add_row(kind, str(s.true), str(s.detected), str(s.false_alarms),
                      "-" if np.isnan(s.recall) else f"{100 * s.recall:.1f}",
                      "-" if np.isnan(s.precision) else f"{100 * s.precision:.1f}")
    return table


#: The interaction situations :func:`situation_agreement` compares (``appearing`` and ``disappearing`` are about
#: the edge, not about neighbours: they count as ``noncorrelated``).
AGREEMENT_LABELS = ("noncorrelated", "correlated", "merged")
_AGREEMENT_OF = {"noncorrelated": 0, "appearing": 0, "disappearing": 0, "correlated": 1, "merged": 2}


@dataclass(frozen=True, slots=True)
class SituationAgreement:
    """Frame by frame, the truth's situation of each person against the situation of the track that followed them.

    Attributes
    ----------
    counts : (3, 4) int64
        Rows: the truth's label (:data:`AGREEMENT_LABELS`); columns: the track's label, then "no track" (the person
        was seen but no track followed them in that frame).
    """

    counts: np.ndarray

    def share(self, truth: str, tracker: str | None = None) -> float:
        """Of the person-frames the truth labels ``truth``, the share whose track says ``tracker`` (one of
        :data:`AGREEMENT_LABELS` or ``"no track"``; default: ``truth``, the agreement). NaN when the truth never
        says ``truth``."""
        i = AGREEMENT_LABELS.index(truth)
        j = 3 if tracker == "no track" else AGREEMENT_LABELS.index(truth if tracker is None else tracker)
        n = int(self.counts[i].sum())
        return float(self.counts[i, j]) / n if n else float("nan")


def situation_agreement(analysis: Any, states: Iterable[Any], matches: FrameMatches, *,
                        t_from_ns: int | None = None, max_dt_ns: int = 30_000_000) -> SituationAgreement:
    """Per-frame situation agreement: for every person the measurement truth sees (or merges by occlusion) in a
    frame of ``analysis``, its label against the situation of the track that CLEAR's matching (``matches``) gave
    that person at the nearest ground-truth frame, read from that track's state nearest in time.

    Episode counts (:func:`situation_accuracy`) match one detection to one true episode, so a tracker that cuts one
    episode in two shows a false alarm, and one that is a frame late on a short episode a miss; this count has
    neither bias and shows where the time goes instead (e.g. people the truth sees as correlated whose track is
    merged).

    Parameters
    ----------
    analysis : SegmentAnalysis
        :func:`~fusiontrack.sim.situations.segment_situations`'s result.
    states : iterable of TrackState
    matches : FrameMatches
        :func:`~fusiontrack.eval.mot.frame_matches` of the same run.
    t_from_ns : int, optional
        Frames before this time are left out (e.g. a warm-up).
    max_dt_ns : int
        A frame of ``analysis`` uses the ground-truth frame and the track state nearest to it only within this
        time (else the person counts as "no track").

    Returns
    -------
    SituationAgreement
    """
    by_track: dict[int, tuple[list[int], list[int]]] = {}
    for st in states:
        code = _AGREEMENT_OF.get(str(st.situation))
        if code is None:
            raise EvaluationError(f"situation_agreement: unknown situation {st.situation!r} of track {st.track_id}")
        ts, codes = by_track.setdefault(int(st.track_id), ([], []))
        ts.append(int(st.t_ns))
        codes.append(code)
    tracks = {}
    for tid, (ts, codes) in by_track.items():
        t = np.asarray(ts, np.int64)
        order = np.argsort(t, kind="stable")
        tracks[tid] = (t[order], np.asarray(codes, np.int64)[order])
    gt_t = np.asarray(matches.t_ns, np.int64)
    t_all = np.asarray(analysis.t_ns, np.int64)
    if gt_t.size:
        frame, _, near = _nearest_frame(gt_t, t_all, max_dt_ns)
    else:
        frame, near = np.zeros(t_all.size, np.int64), np.zeros(t_all.size, bool)
    counts = np.zeros((3, 4), np.int64)
    for k, t in enumerate(t_all.tolist()):
        if t_from_ns is not None and t < t_from_ns:
            continue
        present = np.asarray(analysis.seen[k], bool) | (np.asarray(analysis.merged_set[k]) >= 0)
        if not present.any():
            continue
        followed = {g: tid for tid, g in matches.matches[int(frame[k])].items()} if near[k] else {}
        for j in np.flatnonzero(present).tolist():
            label = str(analysis.labels[k][j])
            row = _AGREEMENT_OF.get(label)
            if row is None:
                raise EvaluationError(f"situation_agreement: unknown situation {label!r} of person "
                                      f"{int(analysis.ids[k][j])} at {t} ns in the truth")
            col = 3
            tid = followed.get(int(analysis.ids[k][j]))
            if tid is not None and tid in tracks:
                tt, codes = tracks[tid]
                q, _, ok = _nearest_frame(tt, np.array([t], np.int64), max_dt_ns)
                if ok[0]:
                    col = int(codes[q[0]])
            counts[row, col] += 1
    return SituationAgreement(counts)


def segment_frames(path: str | Path, *, clock_corrections_ns: Mapping[str, int] | None = None,
                   detector_params: Mapping[str, Any] | None = None, background: str = "prime") -> list[SegmentFrame]:
    """The measurement-level situation truth of a simulated recording, one frame per tracker step.

    Replays :func:`fusiontrack.tracking.tracker.track_recording`'s detection loop (the same laser topics, clock
    corrections, :func:`~fusiontrack.laser.detector.detector_for_recording` detector and step times: every
    distinct scan time) and, per step, attributes each point of each two-feet segment to its scanner's beam
    (the point's bearing in the scanner frame) and the beam to the agent it hit
    (:func:`fusiontrack.sim.situations.load_laser_hits`, matched to the scan by its header stamp). The true
    agents are those of the ``/ground_truth`` frame nearest in time; returns of agents it does not list are left
    out.

    Parameters
    ----------
    path : str or Path
        Recording folder written by :func:`fusiontrack.sim.simulator.simulate`.
    clock_corrections_ns, detector_params, background :
        As for :func:`~fusiontrack.tracking.tracker.track_recording` (use the same values as the tracked run;
        ``background`` ``"prime"`` or ``"learn"``).

    Returns
    -------
    list of SegmentFrame

    Raises
    ------
    fusiontrack.errors.RecordingError
        The recording has no per-beam truth (simulated before the simulator wrote it), or it does not match
        the scans.
    fusiontrack.errors.EvaluationError
        The recording has no LaserScan topic or no ``/ground_truth``.
    """
    from ..errors import RecordingError
    from ..io.recording import LASERSCAN, Recording
    from ..io.sync import synchronize
    from ..laser.detector import detector_for_recording, planar_pose

    hits = load_laser_hits(path)
    corrections = {k: int(v) for k, v in (clock_corrections_ns or {}).items()}
    frames: list[SegmentFrame] = []
    with Recording(path) as rec:
        lasers = [t for t, msgtype in rec.topic_types().items() if msgtype == LASERSCAN]
        if not lasers:
            raise EvaluationError(f"{path}: no sensor_msgs/LaserScan topic")
        gt = list(rec.messages(["/ground_truth"]))
        if not gt:
            raise EvaluationError(f"{path}: no /ground_truth messages")
        gt_t = np.array([g.t_ns for g in gt], dtype=np.int64)
        detector, poses = detector_for_recording(rec, lasers, detector_params=detector_params)
        if background == "prime":
            detector.prime(synchronize(rec.messages(lasers), clock_corrections_ns=corrections))
        elif background != "learn":
            raise EvaluationError(f"background: expected 'prime' or 'learn', got {background!r}")
        names = detector.scanners
        pose = {name: planar_pose(poses[name]) for name in names}
        rows = {name: dict(zip(h["stamp_ns"].tolist(), range(h["stamp_ns"].size), strict=True))
                for name, h in hits.items()}
        latest: dict[str, tuple[int, np.ndarray, float, float]] = {}  # sensor -> (t_ns, hit ids, angle0, step)

        def step(t_ns: int) -> None:
            g = gt[int(np.argmin(np.abs(gt_t - t_ns)))]
            ids = np.asarray(g.ids, np.int64)
            points, seg = detector.segments(t_ns)
            _, owner = detector.foreground_points(t_ns)
            m = len(seg)
            returns = np.zeros((m, ids.size), np.int64)
            if m and ids.size:
                agent = np.full(len(points), -1, np.int64)
                for s_idx, name in enumerate(names):
                    sel = np.flatnonzero(owner == s_idx)
                    if sel.size == 0 or name not in latest:
                        continue
                    _, hit_ids, angle0, inc = latest[name]
                    rot, trans = pose[name]
                    local = (points[sel] - trans) @ rot
                    bearing = np.arctan2(local[:, 1], local[:, 0])
                    beam = np.rint(np.mod(bearing - angle0, 2 * np.pi) / inc).astype(np.int64)
                    if abs(inc * hit_ids.size - 2 * np.pi) < inc:  # a full circle: the last beam is next to the first
                        beam %= hit_ids.size
                    ok = (beam >= 0) & (beam < hit_ids.size)
                    agent[sel[ok]] = hit_ids[beam[ok]]
                col = np.searchsorted(np.sort(ids), agent)
                order = np.argsort(ids)
                col = order[np.clip(col, 0, ids.size - 1)]
                ok = (seg.labels >= 0) & (agent >= 0) & (ids[col] == agent)
                np.add.at(returns, (seg.labels[ok], col[ok]), 1)
            frames.append(SegmentFrame(t_ns, ids, np.asarray(g.positions_m, np.float64).reshape(-1, 2),
                                       seg.centres_m if m else np.zeros((0, 2)), returns))

        pending: int | None = None
        for scan in synchronize(rec.messages(lasers), clock_corrections_ns=corrections):
            if pending is not None and scan.t_ns != pending:
                step(pending)
            detector.update(scan)
            prev = latest.get(scan.sensor)
            if prev is None or scan.t_ns >= prev[0]:  # the detector keeps the newest scan per scanner
                stamp = scan.t_ns - corrections.get(scan.sensor, 0)
                row = rows.get(scan.sensor, {}).get(stamp)
                if row is None or hits[scan.sensor]["hit_ids"].shape[1] != scan.n_beams:
                    raise RecordingError(f"{path}: the scan of {scan.sensor} stamped {stamp} ns ({scan.n_beams} "
                                         f"beams) has no row in ground_truth/laser_hits_{scan.sensor}.npz: the "
                                         f"per-beam truth does not belong to this recording")
                hit_ids = hits[scan.sensor]["hit_ids"][row]
                latest[scan.sensor] = (scan.t_ns, hit_ids, scan.angle_min_rad, scan.angle_increment_rad)
            pending = scan.t_ns
        if pending is not None:
            step(pending)
    return frames
