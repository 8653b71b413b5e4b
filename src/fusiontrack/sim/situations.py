"""Seed 001's tracking situations labelled from ground truth (ALGORITHMS.md B6, B7, B15, B19).

Two truths, both compared with the tracker's situation switches (seed 001 Table II: true counts of
correlated, merge/split and appear/disappear situations):

* **centre-distance truth** (:func:`label_situations`, :func:`situation_events`): from the true body centres
  alone (below);
* **measurement truth** (:func:`segment_situations`, :func:`segment_situation_events`): from what the scanners
  returned — which agent each beam hit (the simulator's ``laser_hits_<laser>.npz``) and the two-feet segments
  the detector made of those returns (see "Measurement truth" at the end of this docstring).

Centre-distance truth
---------------------
Every agent listed in a frame gets one :class:`~fusiontrack.types.Situation` per frame, from the true
body centres (``AgentSnapshot.position_m``) alone, so the labels say what a laser tracker built as in
B4-B7 *should* see.

Definitions (distances between body centres; ``h = 0.40 m`` is B4's mean-shift bandwidth):

``merged`` — another agent within ``d_merged = 0.6 m``.
    Legs lie ~0.1 m either side of the walking line, so two people side by side closer than 0.6 m
    put all four legs inside one flat-kernel window of radius ``h`` centred between them
    (``d / 2 + 0.1 < h``): B4 returns one segment, which both targets find (B7 step 1: ``r_j = 2``
    with ``c_k = 1``), i.e. they merge. (Walking in step, the fore-aft spread of the feet makes the
    strict bound ~0.47 m; mean-shift's modes fuse before every point shares one window, so 0.6 m
    is the better single number. Friends walking together keep ~0.5 m: they are merged.) Merged sets are the
    connected components of the "within ``d_merged``" graph (A-B and B-C close makes {A, B, C} one
    set, as one segment would swallow all three).
``correlated`` — not merged and another agent within ``d_correlated = 0.8 m = 2h``.
    B6's gate is a circle of radius 2h about the predicted centre: the other person's segment falls
    inside it, the target finds two detections (``c_k = 2``) and B7 step 3 hands it to B16.
``appearing`` — entered less than ``appear_window_s = 1 s`` ago, and was within ``edge_m = 0.5 m``
    of the area boundary when it entered (B7 step 6: a detection on the edge with nobody to claim it;
    ``d_edge = 0.5 m``; 1 s = B7's ``N_miss`` at 25 Hz). "Entered" = the first frame in which the
    agent is listed; an agent in the very first frame counts as entering then (a tracker starting
    with the recording also meets it as a new detection).
``disappearing`` — will leave (its last listed frame is before the last frame of the sequence) within
    ``appear_window_s``, and is within ``edge_m`` of the boundary now (B7 step 5).
``noncorrelated`` — none of the above (B7 step 4: one detection, found by nobody else).

Precedence: ``merged > correlated > appearing > disappearing > noncorrelated``. Interaction wins over
the edge labels because the tracker's association (B7 steps 1-3) is decided before its appear /
disappear rules, and an interaction is the harder case to score; appearing is put before
disappearing for the rare agent that crosses a corner in under a second.

The boundary is the rectangle ``bounds_m = (x_min, y_min, x_max, y_max)``
(:attr:`~fusiontrack.sim.model.StaticWorld.bounds_m`); the distance to it is
``min(x - x_min, x_max - x, y - y_min, y_max - y)`` (negative outside, which counts as on the edge).
Every listed agent takes part (the simulator can pass people only). An agent that leaves and comes
back with the same id is treated as present from its first to its last frame.

:func:`situation_events` turns the labels into seed 001's events (:class:`~fusiontrack.types.Event`):
``merge``, ``split``, ``correlated`` (one per agent and episode), ``appear`` and ``disappear``; see there.

Measurement truth
-----------------
Seed 001 defines the situations by the association of targets and measurements (B6, B7): a merge is two
targets whose only detection is one segment, a correlated target has more than one detection in its gate, an
appearing detection on the edge belongs to no target. Its Table II truth was "obtained in a semi-automatic way
(system detection labeling)", i.e. from what the laser detections showed. Here the same rules are applied to
the *true* owners of the detector's segments. Per frame (one per tracker step: every scan time) a
:class:`SegmentFrame` holds the detector's segments (the same :class:`~fusiontrack.laser.LaserPeopleDetector`
the tracker uses, on the same scans) and, per segment and agent, how many of its points are returns of beams
that hit that agent (noise-free cast of the simulator: exact attribution, no distance rule). Then:

* agent ``a`` is a *member* of segment ``j`` when ``j`` holds at least ``min_returns = 3`` of its returns
  (B4's ``n_min``: as many as a segment of its own needs); ``a`` is *seen* when it is a member of a segment,
  *hidden* otherwise (occluded, out of reach, or not yet separated from the background), and has a segment of
  its *own* when some segment has it as the only member;
* ``merged`` — seen, no segment of its own, and sharing a segment with another such agent, when no agent whose
  gate (below) holds that segment's centre has a second segment with members in its gate. Merged sets are the
  connected components of "share such a segment" among those agents (B7 rule 1: ``r_j = 2`` and every target
  finding ``j`` has ``c = 1``; B6 counts in ``c`` every detection in the target's gate, so a pair sharing a
  segment next to a third person's segment, within ``2h``, interacts — correlated — and does not merge;
  ``gate_merges=False`` drops this condition: membership alone, as before);
* ``merged`` by occlusion — B7 rule 1 is about *targets*, and a person occluded by a neighbour has no returns of
  its own but still has a target, whose gate holds the occluder's segment (seed 001: "the targets may occlude each
  other completely ... we deal with it as a merge/split condition"). The targets are the seen agents and the
  hidden ones whose target lives: seen before, and a detection in the gate (``c >= 1``: seen, or a segment with
  members within ``gate_m`` of the true centre) less than ``max_gap_s = 1 s`` ago (B7's ``N_miss``: frames with
  ``c = 0``; a member of a merged target is not missing while the merged target finds its segment). A hidden
  target whose gate holds exactly one segment with members (``c = 1``), when no target whose gate holds that
  segment finds a second one (the ``gate_merges`` condition, over targets), is merged with that segment's members
  (merged sets are the connected components of both kinds of link: an occluder with a segment of its own merges
  with the person behind it; one hidden behind a merged pair joins it). With ``occlusion_merges=True`` (the
  default) only targets' gates count in the ``c = 1`` condition of both rules (a listed agent never seen, or gone
  longer than ``max_gap_s``, has no target); ``occlusion_merges=False`` gives the truth before: hidden agents are
  never merged, and every listed agent's gate counts. A hidden target with ``c = 2`` (between two people) is not
  merged and keeps the hidden label: B7 rule 3 would make its target correlated, but the correlated truth below
  labels what agents' own returns show, and it has none;
* ``correlated`` — seen, not merged, and either (a) a member of a segment shared with someone (the other has a
  segment of its own: its target finds two detections, ``c = 2``, B7 rule 3 and its completion in
  :mod:`fusiontrack.tracking.situations`), or (b) B6's gate about its true centre (circle of radius
  ``gate_m = 2h = 0.8 m``) holds the centres of at least two segments that have members, at least one of
  which holds another agent (``c_k = 2`` because of another person, not because its own two legs fell into
  two segments), or (c) a member of a segment that the gate of another target with ``c = 2`` holds: that
  segment has ``r = 2``, so B7 rule 4 (``r_j = 1``) does not hold for the agent's target, nor rule 1 (every
  target finding it has ``c = 1``): the same completion of rule 3 as the tracker's (before, (c) was missing, and
  an agent whose neighbour's gate held its segment, but not the other way round, was noncorrelated while its
  neighbour was correlated). Like the tracker's ``c``, the other target's count is of segments: a person hidden
  behind an agent whose legs fell into two segments has ``c = 2`` and makes the agent correlated (with one leg
  segment they merge). Targets are the seen or alive agents whatever ``occlusion_merges``. A known difference
  remains: a hidden member of a merged pair is gated at its own true position, while the tracker gates its
  merged target by its members' estimated positions and labels a member ``merged`` where the truth may say
  correlated. Segments of no agent (clutter, background errors) are left out of the gate count;
* ``appearing`` — within ``appear_window_s = 1 s`` after an *appear* event of the agent (below);
  ``disappearing`` — within ``appear_window_s`` before a *disappear* event; ``noncorrelated`` otherwise;
  precedence as in the centre-distance truth. Hidden agents get the empty label ``""`` (``merged`` when merged by
  occlusion). These per-frame labels are raw (what each scan shows); the events below ask states to persist.

Events (the same kinds and :class:`~fusiontrack.types.Event` layout as :func:`situation_events`):

``merge`` / ``split``
    Per pair of agents, the frames in which both are *present* (seen, or hidden and merged by occlusion), each
    "together" (in one merged set) or "apart".
    The pair's state changes when the other state holds in every such frame for ``min_state_s = 0.1 s``
    (B7's ``N_confirm = 3`` frames at 25 Hz: a detection must persist that long to count; two friends side
    by side are one segment in one scan and two in the next, and a one-scan blip is no situation a labeller
    would mark); the change apart -> together is a pair merge, together -> apart a pair split, dated by the
    first frame of the new state. Frames in which both are present more than ``max_gap_s = 1 s`` apart (B7's
    ``N_miss``: a target hidden longer is gone), or a target of either started anew since the pair's last such
    frame (its agent was seen again after its target was gone: hidden with no detection in its gate for more than
    ``max_gap_s``), start the pair afresh, as does its first such frame: the first state that holds is taken as it
    is, without an event. So a person hidden behind another (in its gate) for any time makes one merge and, when
    it shows up apart, one split; one that then walked on hidden out of everybody's gate for over ``max_gap_s``
    comes back as a new target, and its stale pair makes no split. A merge event is a merged set of the frame that
    confirms a pair merge (``track_ids`` = the set); a split event is the merged set the pair was last
    confirmed in (``track_ids`` = that set). An agent hidden while beside a friend and seen again still beside
    it makes no event; seen first inside a shared segment (entering together) makes no merge (seed 001: "when a
    nonmerged target splits, we do not consider this to be a merge/split condition").
``correlated``
    Per agent, over the frames in which it is present, its state (correlated, merged, or neither) changes with
    the same ``min_state_s`` hysteresis and ``max_gap_s`` reset as a pair's; one event per run of the correlated
    state, from its first frame to its last correlated frame (``attributes["partners"]`` = the agents it
    interacted with). Hidden frames not merged by occlusion (up to ``max_gap_s``) neither end nor extend a run.
``appear``
    B7 rule 6, per segment: the first frame in which the agent is seen, when that segment's centre lies within
    ``edge_m = 0.5 m`` of the area's boundary; ``t_end_ns`` = the start of its first sighting that lasts
    ``min_state_s`` (consecutive frames in which it is seen: B7 confirms a new detection after ``N_confirm``
    frames, and a person glimpsed in a doorway is confirmable only once in full view). An agent never seen that
    long makes no appear event. Agents first seen in the same segment make one event
    (``track_ids`` = those agents): one detection, one new target. First seen in the interior (in view from
    the start, or hidden while entering) is no appear event.
``disappear``
    B7 rule 5 (which, unlike rule 6, waits for nothing): the last frame in which the agent is seen, when it then
    leaves (it is not listed in the last frame of the sequence) and the centre of its segment then lies within
    ``edge_m`` of the boundary; ``t_ns = t_end_ns`` = that frame.

The optional persistence rules of :func:`situation_events` (``split_hold_s``, ``correlated_gap_s``,
``min_correlated_s``) apply on top, as there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.distance import pdist, squareform

from ..types import Event, Situation

__all__ = [
    "EVENT_APPEAR",
    "EVENT_CORRELATED",
    "EVENT_DISAPPEAR",
    "EVENT_KINDS",
    "EVENT_MERGE",
    "EVENT_SPLIT",
    "HIDDEN",
    "SITUATION_DTYPE",
    "TRUTH_PERSISTENCE",
    "SegmentAnalysis",
    "SegmentFrame",
    "bridge_correlated",
    "drop_undone_splits",
    "label_situations",
    "load_laser_hits",
    "segment_situation_events",
    "segment_situations",
    "situation_counts",
    "situation_events",
]

SITUATION_DTYPE = np.dtype("<U16")
"""dtype of the label arrays (the :class:`~fusiontrack.types.Situation` string values)."""

EVENT_MERGE, EVENT_SPLIT, EVENT_CORRELATED, EVENT_APPEAR, EVENT_DISAPPEAR = (
    "merge", "split", "correlated", "appear", "disappear")
EVENT_KINDS = (EVENT_MERGE, EVENT_SPLIT, EVENT_CORRELATED, EVENT_APPEAR, EVENT_DISAPPEAR)

TRUTH_PERSISTENCE = {"split_hold_s": 0.5, "correlated_gap_s": 0.4}
"""The persistence rules benchmarks/laser_people.py applies to both sides in its second situation table: to the
truth here, and to the tracker's events with :func:`drop_undone_splits` and :func:`bridge_correlated` (groups walk
~0.5-0.6 m apart, at ``d_merged``, and both their one/two-segment look and their centre distance cross it back and
forth)."""


@dataclass(frozen=True, slots=True, eq=False)
class _Analysis:
    """Per-frame results shared by :func:`label_situations` and :func:`situation_events`."""

    t_ns: np.ndarray  # (T,) int64
    ids: list[np.ndarray]  # per frame (n_k,) int64
    positions: list[np.ndarray]  # per frame (n_k, 2)
    labels: list[np.ndarray]  # per frame (n_k,) SITUATION_DTYPE
    merged_set: list[np.ndarray]  # per frame (n_k,) int64: merged-set index, -1 = not merged
    partners: list[list[np.ndarray]]  # per frame, per agent: ids within d_correlated (merged or not)
    disappear_raw: list[np.ndarray]  # per frame (n_k,) bool: the disappearing condition before precedence
    entry: dict[int, tuple[int, np.ndarray, bool]]  # id -> (t_ns, position, on the edge)
    exit: dict[int, tuple[int, np.ndarray, bool]]  # id -> (t_ns, position, leaves on the edge before the end)


def label_situations(frames: Sequence[Any], bounds_m: Any, *, d_correlated: float = 0.8, d_merged: float = 0.6,
                     edge_m: float = 0.5, appear_window_s: float = 1.0) -> list[np.ndarray]:
    """Seed 001's tracking situation of every agent in every frame (see the module docstring).

    Parameters
    ----------
    frames : sequence of AgentSnapshot (or GroundTruth, or any record with ``t_ns``, ``ids`` and
        ``position_m`` / ``positions_m``)
        The whole sequence, in strictly increasing time (disappearing looks ahead ``appear_window_s``).
    bounds_m : (4,) float
        ``(x_min, y_min, x_max, y_max)`` of the monitored area, m.
    d_correlated : float
        Centre distance below which two agents are correlated, m (B6 gate radius 2h).
    d_merged : float
        Centre distance below which two agents are merged, m (< ``d_correlated``).
    edge_m : float
        Width of the edge band of the area, m (B7 ``d_edge``).
    appear_window_s : float
        How long after entering (before leaving) an agent is appearing (disappearing), s.

    Returns
    -------
    list of (n_k,) arrays of dtype :data:`SITUATION_DTYPE`
        One per frame, in the frame's agent order; values are :class:`~fusiontrack.types.Situation`
        strings (``labels == Situation.MERGED`` works).
    """
    return _analyse(frames, bounds_m, d_correlated, d_merged, edge_m, appear_window_s).labels


def situation_events(frames: Sequence[Any], bounds_m: Any, *, d_correlated: float = 0.8, d_merged: float = 0.6,
                     edge_m: float = 0.5, appear_window_s: float = 1.0, sensor: str = "ground_truth",
                     split_hold_s: float = 0.0, correlated_gap_s: float = 0.0,
                     min_correlated_s: float = 0.0) -> list[Event]:
    """Seed 001's situation events (Table II's true counts) from the ground truth, in time order.

    Same parameters as :func:`label_situations`, plus ``sensor`` (written into each event) and three
    optional persistence rules, all off (0) by default. They are the rules the laser tracker applies to
    its own events (:class:`~fusiontrack.tracking.tracker.TrackerParams` fields of the same names), so that
    truth and detections count the same thing when two people walk at the ``d_merged`` spacing and the
    centre distance crosses it back and forth (:data:`TRUTH_PERSISTENCE` holds the benchmark's values):

    ``split_hold_s``
        A split followed, within this time, by a merge of exactly the same people is no split: both
        events are dropped (the people never were apart long enough to be two segments for a while).
    ``correlated_gap_s``
        Gaps up to this long in an agent's run of correlated frames are bridged (one episode), unless the
        agent is merged in the gap (a merge ends the run).
    ``min_correlated_s``
        Correlated episodes (after bridging) shorter than this (last frame - first frame) make no event.

    Events (``t_ns`` = the frame where it happens; ``track_ids`` sorted agent ids):

    ``merge``
        At frame k a merged set contains two agents, both listed at frame k-1, that were not in one
        merged set at k-1 (two people meet, or a third joins a merged pair). ``track_ids`` = the
        set at k; ``attributes["parts"]`` = how its members present at k-1 were grouped then.
        Agents merged in the first frame, or that enter already merged, make no merge event.
    ``split``
        At frame k two agents of one merged set of frame k-1, both still listed, are no longer in
        one merged set. ``track_ids`` = the set at k-1; ``attributes["parts"]`` = the grouping at k.
        Merge and split are instants (``t_end_ns == t_ns``); a member leaving the area is no split.
    ``correlated``
        One per agent and maximal run of consecutive frames labelled correlated (while listed):
        ``t_ns`` .. ``t_end_ns`` = its first and last frame; ``track_ids = (agent,)``;
        ``attributes["partners"]`` = the agents within ``d_correlated`` during the run.
    ``appear``
        An agent whose entry was on the edge (the appearing condition, whether or not precedence
        let a frame be *labelled* appearing): ``t_ns`` = its first frame, ``t_end_ns`` = its last
        frame within ``appear_window_s``, ``position_m`` = where it entered.
    ``disappear``
        An agent that leaves before the end of the sequence from within ``edge_m`` of the edge:
        ``t_ns`` = the first frame of the disappearing condition, ``t_end_ns`` = its last frame.

    Returns
    -------
    list of Event
        Sorted by ``(t_ns, kind order of EVENT_KINDS, track_ids)``.
    """
    a = _analyse(frames, bounds_m, d_correlated, d_merged, edge_m, appear_window_s)
    events: list[Event] = []
    pos_of = [dict(zip(ids.tolist(), pos, strict=True)) for ids, pos in zip(a.ids, a.positions, strict=True)]

    # merge / split from the merged sets of consecutive frames
    for k in range(1, a.t_ns.size):
        t = int(a.t_ns[k])
        prev = dict(zip(a.ids[k - 1].tolist(), a.merged_set[k - 1].tolist(), strict=True))
        cur = dict(zip(a.ids[k].tolist(), a.merged_set[k].tolist(), strict=True))
        for kind, here, there, pos_frame in ((EVENT_MERGE, cur, prev, pos_of[k]),
                                             (EVENT_SPLIT, prev, cur, pos_of[k])):
            for s in sorted({v for v in here.values() if v >= 0}):
                members = sorted(i for i, v in here.items() if v == s)
                kept = [i for i in members if i in there]
                if len(kept) < 2:
                    continue
                other = [there[i] for i in kept]
                if other[0] >= 0 and all(o == other[0] for o in other):
                    continue  # still (or already) together
                parts = _parts(kept, other)
                present = [i for i in members if i in pos_frame]
                centre = np.mean([pos_frame[i] for i in present], axis=0) if present else None
                events.append(Event(t_ns=t, sensor=sensor, kind=kind, t_end_ns=t, position_m=centre,
                                    track_ids=tuple(members), attributes={"parts": parts}))
    if split_hold_s > 0:
        events = drop_undone_splits(events, split_hold_s)

    # correlated episodes, per agent
    _correlated_runs(events, a.t_ns, a.ids, a.positions, a.labels, a.partners, sensor, correlated_gap_s,
                     min_correlated_s)

    # appear / disappear
    window_ns = round(appear_window_s * 1e9)
    for agent, (t_in, pos_in, on_edge) in a.entry.items():
        if on_edge:
            within = a.t_ns[(a.t_ns >= t_in) & (a.t_ns - t_in < window_ns)]
            events.append(Event(t_ns=t_in, sensor=sensor, kind=EVENT_APPEAR, t_end_ns=int(within.max()),
                                position_m=pos_in, track_ids=(agent,)))
    for agent, (t_out, pos_out, leaves) in a.exit.items():
        if leaves:
            first = next(int(a.t_ns[k]) for k in range(a.t_ns.size)
                         if np.any(a.disappear_raw[k][a.ids[k] == agent]))
            events.append(Event(t_ns=first, sensor=sensor, kind=EVENT_DISAPPEAR, t_end_ns=t_out,
                                position_m=pos_out, track_ids=(agent,)))

    order = {kind: i for i, kind in enumerate(EVENT_KINDS)}
    events.sort(key=lambda e: (e.t_ns, order[e.kind], e.track_ids))
    return events


def situation_counts(events: Sequence[Event]) -> dict[str, int]:
    """Number of events of each kind of :data:`EVENT_KINDS` (seed 001 Table II's "true" column)."""
    counts = dict.fromkeys(EVENT_KINDS, 0)
    for e in events:
        counts[e.kind] = counts.get(e.kind, 0) + 1
    return counts


# ---- measurement truth ---------------------------------------------------------------------------

HIDDEN = ""
"""Label of an agent that is listed but has no returns in any segment this frame (measurement truth)."""


@dataclass(frozen=True, slots=True, eq=False)
class SegmentFrame:
    """The detector's segments at one tracker step and which agents' returns they hold (measurement truth).

    Attributes
    ----------
    t_ns : int
        Time of the step (the tracker's: the scan time on the common clock).
    ids : (n,) int64
        Agents listed in the area at that time (ground truth).
    positions_m : (n, 2) float64
        Their true body centres.
    centres_m : (m, 2) float64
        Centre (mean point) of each segment the detector made, people's or not.
    returns : (m, n) int64
        Number of points of segment ``j`` that are returns of a beam which hit agent ``i``.
    """

    t_ns: int
    ids: np.ndarray
    positions_m: np.ndarray
    centres_m: np.ndarray
    returns: np.ndarray

    def __post_init__(self) -> None:
        ids = np.asarray(self.ids).astype(np.int64).reshape(-1)
        pos = np.asarray(self.positions_m, np.float64).reshape(-1, 2) if ids.size else np.zeros((0, 2))
        centres = np.asarray(self.centres_m, np.float64)
        centres = centres.reshape(-1, 2) if centres.size else np.zeros((0, 2))
        returns = np.asarray(self.returns).astype(np.int64).reshape(len(centres), ids.size)
        if pos.shape != (ids.size, 2):
            raise ValueError(f"SegmentFrame at {self.t_ns}: positions_m has shape {pos.shape}, expected "
                             f"({ids.size}, 2)")
        if np.unique(ids).size != ids.size:
            raise ValueError(f"SegmentFrame at {self.t_ns}: agent ids must be unique")
        for name, value in (("t_ns", int(self.t_ns)), ("ids", ids), ("positions_m", pos), ("centres_m", centres),
                            ("returns", returns)):
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)


@dataclass(frozen=True, slots=True, eq=False)
class SegmentAnalysis:
    """Per-frame measurement-truth results of :func:`segment_situations`, in the frames' agent order.

    Attributes
    ----------
    t_ns : (T,) int64
    ids : list of (n_k,) int64
    positions : list of (n_k, 2) float64
        True body centres.
    labels : list of (n_k,) :data:`SITUATION_DTYPE`
        :class:`~fusiontrack.types.Situation` values, :data:`HIDDEN` for agents without returns (unless merged by
        occlusion: ``merged``).
    seen : list of (n_k,) bool
    merged_set : list of (n_k,) int64
        Merged-set index within the frame, ``-1`` = not merged (hidden agents merged by occlusion included).
    partners : list of list of (p,) int64
        Per agent, the other agents it interacts with (sharing a segment, members of a gated segment, or targets
        whose gate holds one of its segments).
    segment_centre : list of (n_k, 2) float64
        Centre of the segment holding most of the agent's returns (NaN when hidden).
    target_since : list of (n_k,) int64
        When the agent's current target started (its first sighting, or the first after its target was gone,
        module docstring); ``-1`` before it is first seen.
    """

    t_ns: np.ndarray
    ids: list[np.ndarray]
    positions: list[np.ndarray]
    labels: list[np.ndarray]
    seen: list[np.ndarray]
    merged_set: list[np.ndarray]
    partners: list[list[np.ndarray]]
    segment_centre: list[np.ndarray]
    target_since: list[np.ndarray]


def load_laser_hits(recording: Any) -> dict[str, dict[str, np.ndarray]]:
    """The simulator's per-beam truth of a recording folder: ``{laser: {"t_ns", "stamp_ns", "hit_ids"}}``.

    ``hit_ids`` (n_scans, n_beams) int64 is the agent id each beam hit (``-1``: static world or nothing),
    ``stamp_ns`` the header stamp of the matching ``/<laser>/scan`` message, ``t_ns`` its true time.

    Raises
    ------
    fusiontrack.errors.RecordingError
        The folder has no ``ground_truth/laser_hits_*.npz`` (a recording simulated before the simulator wrote
        it, or not a simulation): it has no measurement truth; simulate it again.
    """
    from pathlib import Path

    from ..errors import RecordingError

    folder = Path(recording)
    if folder.is_file():
        folder = folder.parent
    files = sorted((folder / "ground_truth").glob("laser_hits_*.npz"))
    if not files:
        raise RecordingError(f"{folder}: no ground_truth/laser_hits_<laser>.npz, so no measurement-level situation "
                             f"truth (the recording was made before the simulator wrote it, or is not a "
                             f"simulation); simulate it again")
    out = {}
    for f in files:
        with np.load(f) as z:
            hits = z["hit_ids"].astype(np.int64)
            t_ns, stamp_ns = z["t_ns"].astype(np.int64), z["stamp_ns"].astype(np.int64)
        if hits.ndim != 2 or hits.shape[0] != t_ns.size or stamp_ns.size != t_ns.size:
            raise RecordingError(f"{f}: inconsistent arrays (hit_ids {hits.shape}, t_ns {t_ns.shape}, "
                                 f"stamp_ns {stamp_ns.shape})")
        out[f.stem.removeprefix("laser_hits_")] = {"t_ns": t_ns, "stamp_ns": stamp_ns, "hit_ids": hits}
    return out


def segment_situations(frames: Sequence[SegmentFrame], bounds_m: Any, *, min_returns: int = 3,
                       gate_m: float = 0.8, edge_m: float = 0.5, appear_window_s: float = 1.0,
                       min_state_s: float = 0.1, gate_merges: bool = True, occlusion_merges: bool = True,
                       max_gap_s: float = 1.0) -> SegmentAnalysis:
    """Seed 001's situation of every listed agent in every frame, from the measurement truth.

    Parameters
    ----------
    frames : sequence of SegmentFrame
        In strictly increasing time.
    bounds_m : (4,) float
        ``(x_min, y_min, x_max, y_max)`` of the monitored area, m.
    min_returns : int
        Returns of an agent a segment must hold for the agent to be a member of it.
    gate_m : float
        B6 gate radius about the true centre, m (``2h``).
    edge_m : float
        Width of the edge band, m (B7 ``d_edge``).
    appear_window_s : float
        How long after an appear event (before a disappear event) an agent is appearing (disappearing), s.
    min_state_s : float
        Shortest sighting (consecutive frames in which the agent is seen) that confirms an appear, s.
    gate_merges : bool
        B7 rule 1's ``c = 1`` for every target whose gate holds the shared segment (module docstring); False:
        sharing a segment is enough.
    occlusion_merges : bool
        A hidden agent whose target's gate holds one segment (B7 rule 1 for targets) merges with its members
        (module docstring); False: hidden agents are never merged (the truth before).
    max_gap_s : float
        How long a target lives without a detection in its gate (B7 ``N_miss``), s.

    Returns
    -------
    SegmentAnalysis
    """
    return _segment_analysis(frames, bounds_m, min_returns, gate_m, edge_m, appear_window_s, min_state_s,
                             gate_merges, occlusion_merges, max_gap_s)[0]


def segment_situation_events(frames: Sequence[SegmentFrame], bounds_m: Any, *, min_returns: int = 3,
                             gate_m: float = 0.8, edge_m: float = 0.5, appear_window_s: float = 1.0,
                             max_gap_s: float = 1.0, min_state_s: float = 0.1, sensor: str = "ground_truth",
                             split_hold_s: float = 0.0, correlated_gap_s: float = 0.0,
                             min_correlated_s: float = 0.0, gate_merges: bool = True,
                             occlusion_merges: bool = True) -> list[Event]:
    """Seed 001's situation events from the measurement truth (module docstring, "Measurement truth").

    Parameters are those of :func:`segment_situations`, plus ``max_gap_s`` (longest time between two frames in
    which a pair, or an agent, is present — seen, or merged by occlusion — for a change of state to count, and how
    long a target lives without a detection in its gate, s), ``min_state_s`` (how long a pair's "together" or an
    agent's correlated / merged / neither state must hold, in every frame it is present, before it counts),
    ``sensor`` and the persistence rules ``split_hold_s``, ``correlated_gap_s``, ``min_correlated_s``
    of :func:`situation_events`, and ``gate_merges``, ``occlusion_merges`` (:func:`segment_situations`; its
    ``max_gap_s`` is this one).

    Returns
    -------
    list of Event
        Sorted by ``(t_ns, kind order of EVENT_KINDS, track_ids)``.
    """
    if not max_gap_s > 0:
        raise ValueError(f"max_gap_s: expected a value > 0, got {max_gap_s!r}")
    if not min_state_s >= 0:
        raise ValueError(f"min_state_s: expected a value >= 0, got {min_state_s!r}")
    a, appear, disappear = _segment_analysis(frames, bounds_m, min_returns, gate_m, edge_m, appear_window_s,
                                             min_state_s, gate_merges, occlusion_merges, max_gap_s)
    gap_ns = round(max_gap_s * 1e9)
    events: list[Event] = []
    hold_ns = round(min_state_s * 1e9)
    # per pair: [confirmed state (None = not yet), its merged set, candidate state, candidate start, last seen]
    pairs: dict[tuple[int, int], list[Any]] = {}
    last_set: dict[int, frozenset[int] | None] = {}
    for k in range(a.t_ns.size):
        t = int(a.t_ns[k])
        seen = a.seen[k] | (a.merged_set[k] >= 0)  # seen, or hidden and merged by occlusion
        ids = a.ids[k][seen].tolist()
        sets = a.merged_set[k][seen].tolist()
        pos = dict(zip(ids, a.positions[k][seen], strict=True))
        groups: dict[int, frozenset[int]] = {
            s: frozenset(i for i, q in zip(ids, sets, strict=True) if q == s) for s in set(sets) if s >= 0}
        set_of = {i: groups.get(q) for i, q in zip(ids, sets, strict=True)}
        since = dict(zip(ids, a.target_since[k][seen].tolist(), strict=True))
        merged_now: dict[frozenset[int], int] = {}  # merged set -> start of the change
        split_prev: dict[frozenset[int], int] = {}
        order = sorted(ids)
        for x in range(len(order)):
            for y in range(x + 1, len(order)):
                i, j = order[x], order[y]
                together = set_of[i] is not None and set_of[i] is set_of[j]
                st = pairs.get((i, j))
                if st is None or t - st[4] > gap_ns or max(since[i], since[j]) > st[4]:  # first, or a target new
                    st = pairs[(i, j)] = [None, None, None, t, t]
                st[4] = t
                if together == st[0]:
                    st[2] = None
                    if together:
                        st[1] = set_of[i]
                    continue
                if st[2] != together:
                    st[2], st[3] = together, t
                if t - st[3] < hold_ns:
                    continue
                if st[0] is not None:
                    if together:
                        merged_now[set_of[i]] = min(merged_now.get(set_of[i], t), st[3])
                    else:
                        split_prev[st[1]] = min(split_prev.get(st[1], t), st[3])
                st[0], st[1], st[2] = together, set_of[i] if together else None, None
        for members, t0 in sorted(merged_now.items(), key=lambda item: sorted(item[0])):
            parts = _parts(sorted(members), [_set_key(last_set.get(i), i) for i in sorted(members)])
            events.append(Event(t_ns=t0, sensor=sensor, kind=EVENT_MERGE, t_end_ns=t0,
                                position_m=np.mean([pos[i] for i in members], axis=0),
                                track_ids=tuple(sorted(members)), attributes={"parts": parts}))
        for members, t0 in sorted(split_prev.items(), key=lambda item: sorted(item[0])):
            here = [i for i in sorted(members) if i in set_of]
            parts = _parts(here, [_set_key(set_of[i], i) for i in here])
            events.append(Event(t_ns=t0, sensor=sensor, kind=EVENT_SPLIT, t_end_ns=t0,
                                position_m=np.mean([pos[i] for i in here], axis=0) if here else None,
                                track_ids=tuple(sorted(members)), attributes={"parts": parts}))
        last_set.update(set_of)
    if split_hold_s > 0:
        events = drop_undone_splits(events, split_hold_s)
    _held_correlated_runs(events, a, sensor, hold_ns, gap_ns, round(correlated_gap_s * 1e9),
                          round(min_correlated_s * 1e9))
    for t_ns, t_end_ns, members, centre in appear:
        events.append(Event(t_ns=t_ns, sensor=sensor, kind=EVENT_APPEAR, t_end_ns=t_end_ns, position_m=centre,
                            track_ids=members))
    for t_ns, agent, centre in disappear:
        events.append(Event(t_ns=t_ns, sensor=sensor, kind=EVENT_DISAPPEAR, t_end_ns=t_ns, position_m=centre,
                            track_ids=(agent,)))
    order_of = {kind: i for i, kind in enumerate(EVENT_KINDS)}
    events.sort(key=lambda e: (e.t_ns, order_of[e.kind], e.track_ids))
    return events


def _held_correlated_runs(events: list[Event], a: SegmentAnalysis, sensor: str, hold_ns: int, gap_ns: int,
                          bridge_ns: int, min_ns: int) -> None:
    """Correlated events of the measurement truth: per agent, over the frames it is seen, its state (correlated,
    merged or neither) changes when the new state holds for ``hold_ns``; a run of the correlated state is one
    event, from its first frame to its last correlated frame. Seen frames more than ``gap_ns`` apart end the
    run; runs at most ``bridge_ns`` apart are joined unless a merge came between; shorter than ``min_ns``: no
    event."""
    series: dict[int, list[tuple[int, str, set[int], np.ndarray]]] = {}
    for k in range(a.t_ns.size):
        for j in np.flatnonzero(a.seen[k] | (a.merged_set[k] >= 0)):
            lab = str(a.labels[k][j])
            state = lab if lab in (Situation.CORRELATED, Situation.MERGED) else "other"
            series.setdefault(int(a.ids[k][j]), []).append(
                (int(a.t_ns[k]), state, set(a.partners[k][j].tolist()), a.positions[k][j]))
    for agent, rows in series.items():
        runs: list[list[Any]] = []  # [start, last correlated frame, partners, position, ended by a merge]
        state, cand, cand_t, last_t = None, None, 0, None
        cur: list[Any] | None = None
        for t, raw, partners, pos in rows:
            if last_t is not None and t - last_t > gap_ns:
                state, cand, cur = None, None, None
            last_t = t
            if raw == state:
                cand = None
            else:
                if cand != raw:
                    cand, cand_t = raw, t
                if t - cand_t >= hold_ns:
                    if cur is not None:
                        cur[4] = raw == Situation.MERGED
                        cur = None
                    state, cand = raw, None
                    if raw == Situation.CORRELATED:
                        cur = [cand_t, t, set(), pos, False]
                        runs.append(cur)
            if cur is not None and raw == Situation.CORRELATED:
                cur[1] = t
                cur[2] |= partners
        joined: list[list[Any]] = []
        for run in runs:
            if joined and not joined[-1][4] and run[0] - joined[-1][1] <= bridge_ns:
                joined[-1][1], joined[-1][4] = run[1], run[4]
                joined[-1][2] |= run[2]
            else:
                joined.append(run)
        for start, last, partners, pos, _ in joined:
            if last - start >= min_ns:
                events.append(_correlated_event(agent, (start, last, partners, pos, 0), sensor))


def _set_key(members: frozenset[int] | None, agent: int) -> int:
    """Group key for :func:`_parts`: the smallest member of a merged set, ``-1`` (alone) otherwise."""
    return min(members) if members else -1


_AppearRows = list[tuple[int, int, tuple[int, ...], np.ndarray]]
_DisappearRows = list[tuple[int, int, np.ndarray]]


def _segment_analysis(frames: Sequence[SegmentFrame], bounds_m: Any, min_returns: int, gate_m: float, edge_m: float,
                      appear_window_s: float, min_state_s: float, gate_merges: bool = True,
                      occlusion_merges: bool = True, max_gap_s: float = 1.0
                      ) -> tuple[SegmentAnalysis, _AppearRows, _DisappearRows]:
    bounds = _check_bounds(bounds_m)
    if isinstance(min_returns, bool) or not isinstance(min_returns, int | np.integer) or min_returns < 1:
        raise ValueError(f"min_returns: expected an integer >= 1, got {min_returns!r}")
    for name, value in (("gate_m", gate_m), ("appear_window_s", appear_window_s), ("max_gap_s", max_gap_s)):
        if not value > 0:
            raise ValueError(f"{name}: expected a value > 0, got {value!r}")
    if not min_state_s >= 0:
        raise ValueError(f"min_state_s: expected a value >= 0, got {min_state_s!r}")
    if not edge_m >= 0:
        raise ValueError(f"edge_m: expected a value >= 0, got {edge_m!r}")
    frames = list(frames)
    for k, f in enumerate(frames):
        if not isinstance(f, SegmentFrame):
            raise TypeError(f"frames[{k}]: expected a SegmentFrame, got {type(f).__name__}")
    t_all = np.array([f.t_ns for f in frames], dtype=np.int64)
    if np.any(np.diff(t_all) <= 0):
        raise ValueError("frames: times must be strictly increasing")
    window_ns = round(appear_window_s * 1e9)

    seen_all, merged_all, partners_all, corr_all, centre_all = [], [], [], [], []
    gap_ns = round(max_gap_s * 1e9)
    alive_t: dict[int, int] = {}  # agent -> last time its target found a detection (c >= 1) since first seen
    since: dict[int, int] = {}  # agent -> when its current target started
    since_all: list[np.ndarray] = []
    for f in frames:
        n = f.ids.size
        member = f.returns >= min_returns  # (m, n)
        n_mem = member.sum(axis=1)
        seen = member.any(axis=0)
        own = (member & (n_mem == 1)[:, None]).any(axis=0)
        shared = n_mem >= 2
        cand = seen & ~own
        set_index = np.full(n, -1, np.int64)
        if len(f.centres_m) and n:
            gated = (np.linalg.norm(f.positions_m[:, None, :] - f.centres_m[None, :, :], axis=2) < gate_m) \
                & (n_mem >= 1)[None, :]  # (n, m)
        else:
            gated = np.zeros((n, len(f.centres_m)), bool)
        alive = np.array([i in alive_t and f.t_ns - alive_t[i] <= gap_ns for i in f.ids.tolist()], bool)
        for i in f.ids[seen & ~alive].tolist():  # a new target: first seen, or seen again after it was gone
            since[i] = f.t_ns
        # the targets: seen now, or alive (B7 N_miss); without occlusion merges every listed agent's gate counts
        live = seen | alive
        target = live if occlusion_merges else np.ones(n, bool)
        gated_t = gated & target[:, None]
        c = gated_t.sum(axis=1)
        busy = (gated_t & (c >= 2)[:, None]).any(axis=0)  # segments some target with c >= 2 finds
        if gate_merges:  # B7 rule 1: every target whose gate holds the segment has c = 1
            shared = shared & ~busy
        link = np.zeros((n, n), bool)
        if cand.sum() >= 2 and shared.any():
            m_c = member[shared][:, cand].astype(np.int64)
            link[np.ix_(cand, cand)] = (m_c.T @ m_c) > 0
        if occlusion_merges:  # a hidden target whose one detection is someone's segment merges with its members
            for h in np.flatnonzero(target & ~seen & (c == 1)):
                j = int(np.argmax(gated_t[h]))
                if not (gate_merges and busy[j]):
                    link[h, member[j]] = link[member[j], h] = True
        np.fill_diagonal(link, False)
        if link.any():
            _, comp = connected_components(csr_matrix(link), directed=False)
            big = np.bincount(comp)[comp] >= 2
            set_index[big] = np.unique(comp[big], return_inverse=True)[1]
        # N_miss counts the frames in which a target finds no detection (c = 0): finding one keeps it alive
        for i in f.ids[seen | ((c >= 1) & target) if occlusion_merges else seen].tolist():
            alive_t[i] = f.t_ns
        since_all.append(np.array([since.get(i, -1) for i in f.ids.tolist()], np.int64))
        merged = set_index >= 0
        in_shared = (member & (n_mem >= 2)[:, None]).any(axis=0)
        if len(f.centres_m) and n:
            holds_other = (n_mem[None, :] - member.T) >= 1  # (n, m)
            by_gate = (gated.sum(axis=1) >= 2) & (gated & holds_other).any(axis=1)
            # (c): a member of a segment its own gate and that of another target with c >= 2 hold (r = 2, rule 3's
            # completion); targets = seen or alive (also with occlusion_merges=False: a never-seen agent has none)
            g_live = gated & live[:, None]
            g2 = g_live & (g_live.sum(axis=1) >= 2)[:, None]  # (n, m)
            others = g2.sum(axis=0)[None, :] - g2  # per agent and segment: the *other* such targets finding it
            by_share = (member.T & g_live & (others >= 1)).any(axis=1)
            # partners: members of the segments in the gate and of the shared segments one is a member of
            touch = gated | (member.T & (n_mem >= 2)[None, :])
            near = (touch.astype(np.int64) @ member.astype(np.int64)) > 0  # (n, n)
            near |= (near & live[:, None]).T  # both sides: a target whose gate holds my segment is a partner
            np.fill_diagonal(near, False)
            best = np.argmax(f.returns, axis=0)
            centre = np.where(seen[:, None], f.centres_m[best], np.nan)
        else:
            by_gate = by_share = np.zeros(n, bool)
            near = np.zeros((n, n), bool)
            centre = np.full((n, 2), np.nan)
        seen_all.append(seen)
        merged_all.append(set_index)
        corr_all.append(seen & ~merged & (in_shared | by_gate | by_share))
        partners_all.append([f.ids[near[j]] for j in range(n)])
        centre_all.append(centre)

    # first frame in which every agent is seen, if it is ever seen for min_state_s in a row (B7 rule 6 confirms a
    # new detection after N_confirm frames), and when that sighting starts; last frame in which it is seen at
    # all (rule 5 needs no confirmation)
    seen_frames: dict[int, list[int]] = {}
    for k, f in enumerate(frames):
        for i in f.ids[seen_all[k]].tolist():
            seen_frames.setdefault(i, []).append(k)
    first: dict[int, int] = {}
    confirmed: dict[int, int] = {}
    last: dict[int, int] = {}
    hold_ns = round(min_state_s * 1e9)
    for i, ks in seen_frames.items():
        ks_a = np.asarray(ks)
        breaks = np.flatnonzero(np.diff(ks_a) != 1)
        starts, ends = np.r_[ks_a[0], ks_a[breaks + 1]], np.r_[ks_a[breaks], ks_a[-1]]
        lasting = (t_all[ends] - t_all[starts]) >= hold_ns
        if lasting.any():
            first[i], confirmed[i] = int(ks_a[0]), int(t_all[starts[lasting][0]])
        last[i] = int(ks_a[-1])
    listed_at_end = set(frames[-1].ids.tolist()) if frames else set()
    appear_events: list[tuple[int, tuple[int, ...], np.ndarray]] = []
    appear_t: dict[int, int] = {}
    by_frame: dict[int, list[int]] = {}
    for i, k in first.items():
        by_frame.setdefault(k, []).append(i)
    for k, newcomers in sorted(by_frame.items()):
        f = frames[k]
        col = {i: j for j, i in enumerate(f.ids.tolist())}
        groups: dict[tuple[float, float], list[int]] = {}
        for i in newcomers:
            groups.setdefault(tuple(centre_all[k][col[i]]), []).append(i)
        for c, members in sorted(groups.items()):
            centre = np.array(c)
            if _edge_distance(centre[None], bounds)[0] <= edge_m:
                appear_events.append((int(t_all[k]), max(confirmed[i] for i in members), tuple(sorted(members)),
                                      centre))
                appear_t.update(dict.fromkeys(members, int(t_all[k])))
    disappear_events: list[tuple[int, int, np.ndarray]] = []
    disappear_t: dict[int, int] = {}
    for i, k in last.items():
        if i in listed_at_end:
            continue
        centre = centre_all[k][int(np.flatnonzero(frames[k].ids == i)[0])]
        if _edge_distance(centre[None], bounds)[0] <= edge_m:
            disappear_events.append((int(t_all[k]), i, centre))
            disappear_t[i] = int(t_all[k])

    labels = []
    for k, f in enumerate(frames):
        t = int(t_all[k])
        ids = f.ids.tolist()
        appear = np.array([i in appear_t and 0 <= t - appear_t[i] < window_ns for i in ids], bool)
        disappear = np.array([i in disappear_t and 0 <= disappear_t[i] - t < window_ns for i in ids], bool)
        lab = np.full(len(ids), Situation.NONCORRELATED.value, dtype=SITUATION_DTYPE)
        lab[disappear.reshape(-1)] = Situation.DISAPPEARING.value
        lab[appear.reshape(-1)] = Situation.APPEARING.value
        lab[corr_all[k]] = Situation.CORRELATED.value
        lab[merged_all[k] >= 0] = Situation.MERGED.value
        lab[~seen_all[k] & (merged_all[k] < 0)] = HIDDEN
        labels.append(lab)
    analysis = SegmentAnalysis(t_all, [f.ids for f in frames], [f.positions_m for f in frames], labels, seen_all,
                               merged_all, partners_all, centre_all, since_all)
    return analysis, appear_events, disappear_events


# ---- internals -----------------------------------------------------------------------------------


def _correlated_runs(events: list[Event], t_ns: np.ndarray, ids: list[np.ndarray], positions: list[np.ndarray],
                     labels: list[np.ndarray], partners_of: list[list[np.ndarray]], sensor: str,
                     correlated_gap_s: float, min_correlated_s: float) -> None:
    """Append one ``correlated`` event per agent and run of correlated frames (rules of :func:`situation_events`)."""
    runs: dict[int, tuple[int, int, set[int], np.ndarray, int]] = {}  # id -> (start, last, partners, pos, k)
    gap_ns, min_ns = round(correlated_gap_s * 1e9), round(min_correlated_s * 1e9)
    for k in range(t_ns.size):
        t = int(t_ns[k])
        listed = set(ids[k].tolist())
        for agent in [i for i in runs if i not in listed]:  # not listed (left the area): the run ends
            _close_run(events, agent, runs.pop(agent), sensor, min_ns)
        for j, agent in enumerate(ids[k].tolist()):
            run = runs.get(agent)
            ended = run is not None and run[4] != k - 1 and t - run[1] > gap_ns  # a gap too long to bridge
            if labels[k][j] != Situation.CORRELATED:  # a merge always ends the run (as in the tracker)
                if ended or (run is not None and (gap_ns == 0 or labels[k][j] == Situation.MERGED)):
                    _close_run(events, agent, runs.pop(agent), sensor, min_ns)
                continue
            if ended:
                _close_run(events, agent, runs.pop(agent), sensor, min_ns)
                run = None
            partners = set(partners_of[k][j].tolist())
            runs[agent] = ((t, t, partners, positions[k][j], k) if run is None
                           else (run[0], t, run[2] | partners, run[3], k))
    for agent, run in runs.items():
        _close_run(events, agent, run, sensor, min_ns)


def _close_run(events: list[Event], agent: int, run: tuple[int, int, set[int], np.ndarray, int], sensor: str,
               min_ns: int) -> None:
    if run[1] - run[0] >= min_ns:
        events.append(_correlated_event(agent, run, sensor))


def drop_undone_splits(events: Sequence[Event], hold_s: float) -> list[Event]:
    """Drop each ``split`` that a ``merge`` of exactly the same ``track_ids`` follows within ``hold_s``, and that
    merge (the ``split_hold_s`` rule of :func:`situation_events` and of the laser tracker; any source of events).

    Returns the other events, sorted by time (stable).
    """
    if not hold_s >= 0:
        raise ValueError(f"hold_s: expected a value >= 0, got {hold_s!r}")
    hold_ns = round(hold_s * 1e9)
    events = sorted(events, key=lambda e: e.t_ns)
    dropped: set[int] = set()
    for i, e in enumerate(events):
        if e.kind != EVENT_SPLIT or i in dropped:
            continue
        for q in range(i + 1, len(events)):
            f = events[q]
            if f.t_ns - e.t_ns > hold_ns:
                break
            if q not in dropped and f.kind == EVENT_MERGE and f.track_ids == e.track_ids:
                dropped.update((i, q))
                break
    return [e for i, e in enumerate(events) if i not in dropped]


def bridge_correlated(events: Sequence[Event], gap_s: float) -> list[Event]:
    """Join the ``correlated`` events of the same ``track_ids`` whose time spans are at most ``gap_s`` apart, unless a
    ``merge`` naming one of those ids starts between them (the ``correlated_gap_s`` rule of :func:`situation_events`,
    for any source of events). The joined event keeps the first one's position and unites the partners.

    Returns all events, sorted by time (stable).
    """
    if not gap_s >= 0:
        raise ValueError(f"gap_s: expected a value >= 0, got {gap_s!r}")
    gap_ns = round(gap_s * 1e9)
    events = sorted(events, key=lambda e: e.t_ns)
    merges: dict[int, list[int]] = {}
    for e in events:
        if e.kind == EVENT_MERGE:
            for i in e.track_ids:
                merges.setdefault(i, []).append(e.t_ns)
    out: list[Event] = []
    open_run: dict[tuple[int, ...], int] = {}  # track_ids -> index in out of the last correlated event
    for e in events:
        if e.kind != EVENT_CORRELATED:
            out.append(e)
            continue
        q = open_run.get(e.track_ids)
        if q is not None:
            prev = out[q]
            end = prev.t_end_ns if prev.t_end_ns is not None else prev.t_ns
            merged_between = any(end <= t <= e.t_ns for i in e.track_ids for t in merges.get(i, ()))
            if e.t_ns - end <= gap_ns and not merged_between:
                partners = set(prev.attributes.get("partners", ())) | set(e.attributes.get("partners", ()))
                last = None if e.t_end_ns is None or prev.t_end_ns is None else max(prev.t_end_ns, e.t_end_ns)
                attrs = {**prev.attributes, "partners": tuple(sorted(partners))} if partners else prev.attributes
                out[q] = Event(prev.t_ns, prev.sensor, prev.kind, last, position_m=prev.position_m,
                               track_ids=prev.track_ids, attributes=attrs)
                continue
        open_run[e.track_ids] = len(out)
        out.append(e)
    return sorted(out, key=lambda e: e.t_ns)


def _correlated_event(agent: int, run: tuple[int, int, set[int], np.ndarray, int], sensor: str) -> Event:
    start, last, partners, pos, _ = run
    return Event(t_ns=start, sensor=sensor, kind=EVENT_CORRELATED, t_end_ns=last, position_m=pos,
                 track_ids=(agent,), attributes={"partners": tuple(sorted(partners - {agent}))})


def _parts(ids: list[int], groups: list[int]) -> tuple[tuple[int, ...], ...]:
    """Group ``ids`` by merged-set index (``-1`` = each alone), sorted."""
    out: dict[Any, list[int]] = {}
    for i, g in zip(ids, groups, strict=True):
        out.setdefault(g if g >= 0 else ("alone", i), []).append(i)
    return tuple(sorted(tuple(sorted(p)) for p in out.values()))


def _frame_arrays(frame: Any, k: int) -> tuple[int, np.ndarray, np.ndarray]:
    try:
        t_ns = frame.t_ns
        ids = frame.ids
        pos = frame.position_m if hasattr(frame, "position_m") else frame.positions_m
    except AttributeError as err:
        raise TypeError(f"frames[{k}]: expected a record with t_ns, ids and position_m (or positions_m): {err}") \
            from err
    ids = np.asarray(ids).astype(np.int64).reshape(-1)
    pos = np.asarray(pos, dtype=np.float64)
    if pos.shape != (ids.size, 2):
        raise ValueError(f"frames[{k}]: expected positions of shape ({ids.size}, 2), got {pos.shape}")
    if np.unique(ids).size != ids.size:
        raise ValueError(f"frames[{k}]: agent ids must be unique within a frame")
    return int(t_ns), ids, pos


def _check_bounds(bounds_m: Any) -> np.ndarray:
    bounds = np.asarray(bounds_m, dtype=np.float64).reshape(-1)
    if bounds.shape != (4,) or not np.all(np.isfinite(bounds)) or bounds[2] <= bounds[0] or bounds[3] <= bounds[1]:
        raise ValueError(f"bounds_m: expected (x_min, y_min, x_max, y_max) with x_min < x_max, y_min < y_max, "
                         f"got {bounds_m!r}")
    return bounds


def _edge_distance(points: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Distance of ``(n, 2)`` points to the boundary of the rectangle ``bounds`` (negative outside), ``(n,)``."""
    return np.minimum(np.minimum(points[:, 0] - bounds[0], bounds[2] - points[:, 0]),
                      np.minimum(points[:, 1] - bounds[1], bounds[3] - points[:, 1]))


def _analyse(frames: Sequence[Any], bounds_m: Any, d_correlated: float, d_merged: float, edge_m: float,
             appear_window_s: float) -> _Analysis:
    bounds = _check_bounds(bounds_m)
    if not 0 < d_merged < d_correlated:
        raise ValueError(f"d_merged, d_correlated: expected 0 < d_merged < d_correlated, "
                         f"got {d_merged}, {d_correlated}")
    if not edge_m >= 0:
        raise ValueError(f"edge_m: expected a value >= 0, got {edge_m}")
    if not appear_window_s > 0:
        raise ValueError(f"appear_window_s: expected a value > 0, got {appear_window_s}")

    parsed = [_frame_arrays(f, k) for k, f in enumerate(frames)]
    t_all = np.array([p[0] for p in parsed], dtype=np.int64)
    if np.any(np.diff(t_all) <= 0):
        raise ValueError("frames: times must be strictly increasing")
    ids_list = [p[1] for p in parsed]
    pos_list = [p[2] for p in parsed]
    window_ns = round(appear_window_s * 1e9)

    # entry and exit of every agent, from the flattened (frame, agent) rows
    if parsed:
        row_ids = np.concatenate(ids_list)
        row_t = np.repeat(t_all, [ids.size for ids in ids_list])
        row_pos = np.concatenate(pos_list).reshape(-1, 2)
    else:
        row_ids, row_t, row_pos = np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2))
    uniq, first = np.unique(row_ids, return_index=True)
    last = row_ids.size - 1 - np.unique(row_ids[::-1], return_index=True)[1]
    t_end = int(t_all[-1]) if t_all.size else 0
    first_on_edge = _edge_distance(row_pos[first], bounds) <= edge_m
    last_on_edge = _edge_distance(row_pos[last], bounds) <= edge_m
    leaves = (row_t[last] < t_end) & last_on_edge
    entry = {int(i): (int(row_t[f]), row_pos[f], bool(e)) for i, f, e in zip(uniq, first, first_on_edge, strict=True)}
    exit_ = {int(i): (int(row_t[li]), row_pos[li], bool(lv)) for i, li, lv in zip(uniq, last, leaves, strict=True)}
    t_first, t_last = row_t[first], row_t[last]
    left_before_end = t_last < t_end

    labels, merged_sets, partners_all, disappear_all = [], [], [], []
    for t, ids, pos in zip(t_all.tolist(), ids_list, pos_list, strict=True):
        n = ids.size
        u = np.searchsorted(uniq, ids)  # row of each agent in the per-agent arrays
        dist = squareform(pdist(pos)) if n >= 2 else np.zeros((n, n))
        np.fill_diagonal(dist, np.inf)
        set_index = np.full(n, -1, np.int64)  # merged-set index, numbered over the merged sets only
        if n >= 2:
            _, comp = connected_components(csr_matrix(dist < d_merged), directed=False)
            merged = np.bincount(comp)[comp] >= 2
            if merged.any():
                set_index[merged] = np.unique(comp[merged], return_inverse=True)[1]
        merged = set_index >= 0
        near = dist < d_correlated
        correlated = near.any(axis=1) & ~merged
        appear = (t - t_first[u] < window_ns) & first_on_edge[u]
        disappear = left_before_end[u] & (t_last[u] - t < window_ns) & (_edge_distance(pos, bounds) <= edge_m)
        lab = np.full(n, Situation.NONCORRELATED.value, dtype=SITUATION_DTYPE)
        lab[disappear] = Situation.DISAPPEARING.value
        lab[appear] = Situation.APPEARING.value
        lab[correlated] = Situation.CORRELATED.value
        lab[merged] = Situation.MERGED.value
        labels.append(lab)
        merged_sets.append(set_index)
        partners_all.append([ids[near[j]] for j in range(n)])
        disappear_all.append(disappear)
    return _Analysis(t_all, ids_list, pos_list, labels, merged_sets, partners_all, disappear_all,
                     entry, exit_)
