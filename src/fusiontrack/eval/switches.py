"""Why each identity switch happened: exchanges between two tracks, or a person's track lost and replaced.

CLEAR's ID switches (:attr:`fusiontrack.eval.Metrics.id_switches`) count every time a person's matched track
changes; they do not say why. The cure differs with the cause: two people who *exchange* tracks when they meet
need appearance (seed 001's classifiers at a merge or split), a track *lost* and replaced by a new one needs better
continuity (coasting through occlusions, re-identification), a track *shared* by two people walking side by side
needs a detector that sees them as two, and an older track *taking over* a person whose own track drifted off needs
better association. :func:`id_switch_causes` labels each switch of a run's CLEAR matches
(:func:`fusiontrack.eval.frame_matches`), so a benchmark can show which of these a tracker suffers from.

A switch of person ``g`` from track ``a`` to track ``b`` at ``t`` (``g`` matched ``a`` last, ``b`` now) is

* ``exchange`` — another person switched from ``b`` to ``a`` within ``exchange_s`` of ``t``: the two tracks
  exchanged their people (each such pair counts two switches, as CLEAR counts them);
* ``reborn`` — else, ``b`` began within ``new_s`` before ``t`` and ``a`` ended by ``t + ended_s``: the person's
  track was lost and a new one started (re-identification's case);
* ``shared`` — else, ``b`` began within ``new_s`` before ``t`` while ``a`` goes on, and ``a`` is matched, within
  ``shared_s`` of ``t`` (before or after, and after ``g`` left it), to some other person ``o`` who was matched to no
  track but ``a`` over the ``shared_s`` before ``t`` and walked with ``g`` then: with the ground truth, both present
  and at most ``shared_m`` apart throughout; without it, ``o`` matched to ``a`` at least once. ``a`` had been
  following two people as one (two people walking side by side, whom the detector saw as one), and when they
  parted the new track took this one. The person had no track of its own to keep: no appearance at a meeting can
  give one back, better detection (seeing the two as two) can;
* ``new_track`` — else, ``b`` began within ``new_s`` before ``t`` while ``a`` goes on: a new track took the person
  from a track that drifted off (onto somebody else, or onto nothing);
* ``takeover`` — else: an older track, which was following somebody else or nobody, took the person.

The labels cover every switch CLEAR counts, so their counts sum to the run's ``id_switches``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..types import GroundTruth, Track, TrackState
from .mot import FrameMatches

__all__ = ["SWITCH_CAUSES", "IdSwitch", "id_switch_causes", "switch_cause_counts"]

SWITCH_CAUSES = ("exchange", "reborn", "shared", "new_track", "takeover")


@dataclass(frozen=True, slots=True)
class IdSwitch:
    """One CLEAR identity switch: person ``gt_id`` matched ``from_track`` last (at ``last_ns``) and ``to_track``
    at ``t_ns``; ``cause`` is one of :data:`SWITCH_CAUSES` (module docstring)."""

    t_ns: int
    gt_id: int
    from_track: int
    to_track: int
    last_ns: int
    cause: str


def _lifetimes(tracks: Iterable[TrackState | Track]) -> dict[int, tuple[int, int]]:
    span: dict[int, list[int]] = {}
    for tr in tracks:
        if isinstance(tr, Track):
            if tr.states:
                _extend(span, tr.track_id, tr.t_start_ns, tr.t_end_ns)
        else:
            _extend(span, tr.track_id, tr.t_ns, tr.t_ns)
    return {tid: (lo, hi) for tid, (lo, hi) in span.items()}


def _extend(span: dict[int, list[int]], tid: int, lo: int, hi: int) -> None:
    s = span.get(tid)
    if s is None:
        span[tid] = [lo, hi]
    else:
        s[0], s[1] = min(s[0], lo), max(s[1], hi)


def id_switch_causes(matches: FrameMatches, tracks: Iterable[TrackState | Track], *, exchange_s: float = 3.0,
                     new_s: float = 2.0, ended_s: float = 0.5, shared_s: float = 1.0, shared_m: float = 1.0,
                     truth: Sequence[GroundTruth] | None = None) -> list[IdSwitch]:
    """Every CLEAR identity switch of a run, with its cause (module docstring), in time order.

    Parameters
    ----------
    matches : FrameMatches
        The run's CLEAR matches (:func:`fusiontrack.eval.frame_matches` of the same ground truth and tracks).
    tracks : iterable of TrackState or Track
        The tracks those matches were made from: their first and last times.
    exchange_s, new_s, ended_s, shared_s : float
        The windows of the rules, s.
    shared_m : float
        How far apart two people walking together (``shared``) may be, m (with ``truth``).
    truth : sequence of GroundTruth, optional
        The ground truth the matches were made from; without it ``shared`` asks for a match of the other person to
        the shared track instead of the two people's distance.
    """
    for name, v in (("exchange_s", exchange_s), ("new_s", new_s), ("ended_s", ended_s), ("shared_s", shared_s),
                    ("shared_m", shared_m)):
        if not v >= 0:
            raise ValueError(f"{name}: expected a value >= 0, got {v!r}")
    life = _lifetimes(tracks)
    last: dict[int, tuple[int, int]] = {}  # person -> (track, time) of its last match
    raw: list[tuple[int, int, int, int, int]] = []  # (t, person, from, to, last time)
    by_person: dict[int, list[tuple[int, int]]] = {}  # person -> [(time, track)] of its matches
    for t, frame in zip(matches.t_ns.tolist(), matches.matches, strict=True):
        for tid, g in sorted(frame.items(), key=lambda kv: kv[1]):
            prev = last.get(g)
            if prev is not None and prev[0] != tid:
                raw.append((t, g, prev[0], tid, prev[1]))
            last[g] = (tid, t)
            by_person.setdefault(g, []).append((t, tid))
    by_pair: dict[tuple[int, int], list[tuple[int, int]]] = {}  # (from, to) -> [(time, person)]
    for t, g, a, b, _ in raw:
        by_pair.setdefault((a, b), []).append((t, g))
    ex_ns, new_ns, end_ns = round(exchange_s * 1e9), round(new_s * 1e9), round(ended_s * 1e9)
    shared_ns = round(shared_s * 1e9)
    together = None if truth is None else _Together(truth, shared_m)
    out = []
    for t, g, a, b, t_last in raw:
        if any(g2 != g and abs(t2 - t) <= ex_ns for t2, g2 in by_pair.get((b, a), ())):  # (another person: one
            # person taken by another track and given back is two takeovers)
            cause = "exchange"
        elif b in life and life[b][0] >= t - new_ns:
            if a in life and life[a][1] <= t + end_ns:
                cause = "reborn"
            else:
                cause = "shared" if _shared(matches, by_person, t, t_last, g, a, shared_ns, together) else "new_track"
        else:
            cause = "takeover"
        out.append(IdSwitch(t, g, a, b, t_last, cause))
    return out


class _Together:
    """Whether two people were both present and within ``max_m`` of each other at every truth frame of a window."""

    def __init__(self, truth: Sequence[GroundTruth], max_m: float) -> None:
        t = np.array([g.t_ns for g in truth], np.int64)
        order = np.argsort(t, kind="stable")  # (frame_matches takes the truth in any order)
        self.t = t[order]
        self.frames = [truth[k] for k in order]
        self.max_m = max_m

    def __call__(self, g: int, o: int, lo: int, hi: int) -> bool:
        ks = range(int(np.searchsorted(self.t, lo)), int(np.searchsorted(self.t, hi)))  # frames in [lo, hi)
        if not len(ks):
            return False
        for k in ks:
            ids = self.frames[k].ids
            i, j = np.flatnonzero(ids == g), np.flatnonzero(ids == o)
            if not (i.size and j.size):
                return False
            p = self.frames[k].positions_m
            if not np.hypot(*(p[i[0]] - p[j[0]])) <= self.max_m:
                return False
        return True


def _shared(matches: FrameMatches, by_person: Mapping[int, list[tuple[int, int]]], t: int, t_last: int, g: int,
            a: int, window_ns: int, together: _Together | None) -> bool:
    """The ``shared`` rule (module docstring) for person ``g``, who matched track ``a`` last at ``t_last`` and
    another track at ``t``."""
    times, gts = matches.by_track.get(a, (np.empty(0, np.int64), np.empty(0, np.int64)))
    lo = max(t_last, t - window_ns)
    after = gts[int(np.searchsorted(times, lo, side="right")):int(np.searchsorted(times, t + window_ns, side="right"))]
    # the other people ``a`` went on with, in order: the first who walked with ``g`` (a passer-by ``a`` touched on
    # its way does not hide them)
    for o in dict.fromkeys(int(x) for x in after[after != g]):
        before = [tid for tt, tid in by_person.get(o, ()) if t - window_ns <= tt < t]
        if any(tid != a for tid in before):
            continue  # ``o`` had a track of its own
        if together(g, o, t - window_ns, t) if together is not None else bool(before):
            return True
    return False  # ``a`` went on with nobody, or with people who did not share it


def switch_cause_counts(switches: Iterable[IdSwitch] | Iterable[Mapping[str, int]]) -> dict[str, int]:
    """``{cause: count}`` over :data:`SWITCH_CAUSES` (zeros included), of switches or of earlier counts summed."""
    total: Counter[str] = Counter({c: 0 for c in SWITCH_CAUSES})
    for s in switches:
        if isinstance(s, IdSwitch):
            total[s.cause] += 1
        else:
            total.update(s)
    return {c: total[c] for c in SWITCH_CAUSES}
