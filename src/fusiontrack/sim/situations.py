"""Seed 001's tracking situations labelled from ground truth (ALGORITHMS.md B6, B7, B15, B19).

Every agent listed in a frame gets one :class:`~fusiontrack.types.Situation` per frame, from the true
body centres (``AgentSnapshot.position_m``) alone, so the labels say what a laser tracker built as in
B4-B7 *should* see; the evaluation compares the tracker's own situation switches against them
(seed 001 Table II: true counts of correlated, merge/split and appear/disappear situations).

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
    "SITUATION_DTYPE",
    "TRUTH_PERSISTENCE",
    "drop_undone_splits",
    "label_situations",
    "situation_counts",
    "situation_events",
]

SITUATION_DTYPE = np.dtype("<U16")
"""dtype of the label arrays (the :class:`~fusiontrack.types.Situation` string values)."""

EVENT_MERGE, EVENT_SPLIT, EVENT_CORRELATED, EVENT_APPEAR, EVENT_DISAPPEAR = (
    "merge", "split", "correlated", "appear", "disappear")
EVENT_KINDS = (EVENT_MERGE, EVENT_SPLIT, EVENT_CORRELATED, EVENT_APPEAR, EVENT_DISAPPEAR)

TRUTH_PERSISTENCE = {"split_hold_s": 0.5, "correlated_gap_s": 0.4}
"""The persistence rules benchmarks/laser_people.py applies to both sides in its second situation table:
``correlated_gap_s`` is the tracker's own default; ``split_hold_s = 0.5 s`` is applied to the truth here and
to the tracker's events with :func:`drop_undone_splits` (groups walk ~0.5-0.6 m apart, at ``d_merged``, and
both their one/two-segment look and their centre distance cross it back and forth)."""


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
    runs: dict[int, tuple[int, int, set[int], np.ndarray, int]] = {}  # id -> (start, last, partners, pos, k)
    gap_ns, min_ns = round(correlated_gap_s * 1e9), round(min_correlated_s * 1e9)
    for k in range(a.t_ns.size):
        t = int(a.t_ns[k])
        listed = set(a.ids[k].tolist())
        for agent in [i for i in runs if i not in listed]:  # not listed (left the area): the run ends
            _close_run(events, agent, runs.pop(agent), sensor, min_ns)
        for j, agent in enumerate(a.ids[k].tolist()):
            run = runs.get(agent)
            ended = run is not None and run[4] != k - 1 and t - run[1] > gap_ns  # a gap too long to bridge
            if a.labels[k][j] != Situation.CORRELATED:  # a merge always ends the run (as in the tracker)
                if ended or (run is not None and (gap_ns == 0 or a.labels[k][j] == Situation.MERGED)):
                    _close_run(events, agent, runs.pop(agent), sensor, min_ns)
                continue
            if ended:
                _close_run(events, agent, runs.pop(agent), sensor, min_ns)
                run = None
            partners = set(a.partners[k][j].tolist())
            runs[agent] = ((t, t, partners, a.positions[k][j], k) if run is None
                           else (run[0], t, run[2] | partners, run[3], k))
    for agent, run in runs.items():
        _close_run(events, agent, run, sensor, min_ns)

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


# ---- internals -----------------------------------------------------------------------------------


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


def _edge_distance(points: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Distance of ``(n, 2)`` points to the boundary of the rectangle ``bounds`` (negative outside), ``(n,)``."""
    return np.minimum(np.minimum(points[:, 0] - bounds[0], bounds[2] - points[:, 0]),
                      np.minimum(points[:, 1] - bounds[1], bounds[3] - points[:, 1]))


def _analyse(frames: Sequence[Any], bounds_m: Any, d_correlated: float, d_merged: float, edge_m: float,
             appear_window_s: float) -> _Analysis:
    bounds = np.asarray(bounds_m, dtype=np.float64).reshape(-1)
    if bounds.shape != (4,) or not np.all(np.isfinite(bounds)) or bounds[2] <= bounds[0] or bounds[3] <= bounds[1]:
        raise ValueError(f"bounds_m: expected (x_min, y_min, x_max, y_max) with x_min < x_max, y_min < y_max, "
                         f"got {bounds_m!r}")
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
