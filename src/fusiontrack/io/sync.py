"""Time alignment: one clock, one order.

* :func:`merge` merges streams that are each in time order (``heapq.merge``).
* :class:`Synchronizer` puts a stream on a common clock (a per-sensor offset added to ``t_ns``) and
  back into time order: a message that arrives late by at most ``window_ns`` is put back in its
  place; one later than that is dropped and counted, and one warning with the counts is logged
  when the stream ends (never one per message). A message stamped far *ahead* of the stream (a
  corrupt stamp, a clock that jumped) is held until the next messages show whether the whole
  stream jumped (a recording paused) or only it did (dropped, counted): one bad stamp must not
  push the clock forward and make every later message "late".
* :func:`estimate_clock_offset` and :func:`align_nearest` are seed 001's client/server clock
  correction and frame alignment (ALGORITHMS.md B1).
"""

from __future__ import annotations

import copy
import heapq
import itertools
import logging
from collections import Counter
from collections.abc import Iterable, Iterator, Mapping
from typing import Any, TypeVar

import numpy as np

from ..errors import ConfigError

log = logging.getLogger(__name__)

R = TypeVar("R")


def with_time(record: R, t_ns: int) -> R:
    """A copy of a frozen record with another ``t_ns`` (arrays are shared, not copied: they are read-only)."""
    out = copy.copy(record)
    object.__setattr__(out, "t_ns", int(t_ns))
    return out


def merge(*streams: Iterable[R]) -> Iterator[R]:
    """Merge streams that are each ordered by ``t_ns`` into one ordered stream (stable across inputs)."""
    return heapq.merge(*streams, key=lambda r: r.t_ns)  # type: ignore[attr-defined]


class Synchronizer:
    """Correct clocks and restore time order in a stream of records.

    Parameters
    ----------
    window_ns : int
        How late (in corrected time, relative to the newest message seen) a message may arrive and
        still be put back in order. Messages are held back for this long, so it is also the latency
        the synchroniser adds. Default 200 ms.
    clock_corrections_ns : mapping sensor -> ns
        Added to the ``t_ns`` of that sensor's messages (``t_common = t_sensor + correction``); a sensor
        whose clock runs ``d`` ahead needs ``-d`` (the pipeline file's ``clock_offset_ms`` is ``d``;
        :func:`estimate_clock_offset` returns the correction itself).

    leap_ns : int
        A message stamped more than ``max(leap_ns, window_ns)`` after the newest one so far is a *leap*. It is
        held back, and let through with the others held once ``leap_confirm`` leaps agree: the whole stream
        jumped (a paused recording, a restarted clock). They agree when each is at most ``leap_ns`` before the
        first and no farther after the one before it than the first was from the old clock (a stream slower
        than ``leap_ns`` goes on at its own pace; a pause goes on at the stream's rate; unrelated bad stamps do
        not), and, in a stream of several sensors, when they come from two of them. Meanwhile messages at the
        old clock go on as usual (a sensor logged a little late still sends a few); ``leap_confirm`` of them, or
        a leap that disagrees, show the held ones to be bad stamps: they are dropped (counted in
        :attr:`dropped_ahead`). The first ``2 * leap_confirm - 1`` messages of the stream are judged against
        their median time, so that a bad stamp on the very first message cannot set the clock: one more than
        ``leap_ns`` plus 5 median deviations after it is a bad stamp if ``leap_confirm`` of the others come after
        it, and otherwise a leap, held after them (a stream that jumps within its first messages, as recordings of
        three messages each read as one). Default 10 s.
    leap_confirm : int
        Leaps that confirm a jump (default 3: one or two bad stamps are dropped). Leaps still held when
        the stream ends harm nothing after them: they are let through if they agree with each other and are
        more than one, or the stream has one sensor; a lone one in a stream of several is dropped.

    Iterate :meth:`__call__` over a stream; :attr:`dropped`, :attr:`dropped_ahead` and :attr:`reordered` count
    what happened.
    """

    def __init__(self, window_ns: int = 200_000_000, clock_corrections_ns: Mapping[str, int] | None = None, *,
                 leap_ns: int = 10_000_000_000, leap_confirm: int = 3) -> None:
        if isinstance(window_ns, bool) or not isinstance(window_ns, int | np.integer) or window_ns < 0:
            raise ConfigError(f"sync window_ns: expected a non-negative integer of nanoseconds, got {window_ns!r}")
        if isinstance(leap_ns, bool) or not isinstance(leap_ns, int | np.integer) or leap_ns <= 0:
            raise ConfigError(f"sync leap_ns: expected a positive integer of nanoseconds, got {leap_ns!r}")
        if isinstance(leap_confirm, bool) or not isinstance(leap_confirm, int | np.integer) or leap_confirm < 1:
            raise ConfigError(f"sync leap_confirm: expected an integer >= 1, got {leap_confirm!r}")
        offsets = dict(clock_corrections_ns or {})
        for sensor, value in offsets.items():
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise ConfigError(f"clock offset of sensor {sensor!r}: expected integer nanoseconds, got {value!r}")
        self.window_ns = int(window_ns)
        self.clock_corrections_ns = {k: int(v) for k, v in offsets.items()}
        self.leap_ns = max(int(leap_ns), self.window_ns)
        self.leap_confirm = int(leap_confirm)
        self.dropped: Counter[str] = Counter()
        """Messages dropped because they came later than ``window_ns``, per sensor."""
        self.dropped_ahead: Counter[str] = Counter()
        """Messages dropped because they were stamped far ahead of the stream (a leap the messages after it did not
        confirm), per sensor."""
        self.reordered = 0

    def __call__(self, stream: Iterable[Any]) -> Iterator[Any]:
        heap: list[tuple[int, int, Any]] = []
        counter = itertools.count()
        newest = None  # newest corrected time seen so far
        last_out = None  # time of the last message let out
        leaps: list[tuple[int, Any]] = []  # messages far ahead of ``newest``, held until confirmed or refuted
        sensors: set[str] = set()
        leap = self.leap_ns

        def corrected(records: Iterable[Any]) -> Iterator[tuple[int, Any]]:
            for record in records:
                offset = self.clock_corrections_ns.get(record.sensor, 0)
                t = record.t_ns + offset
                yield t, (with_time(record, t) if offset else record)

        old_clock = 0  # messages at the old clock since the first leap held

        def refute() -> None:
            nonlocal old_clock
            for _, bad in leaps:
                self.dropped_ahead[bad.sensor] += 1
            leaps.clear()
            old_clock = 0

        rest = corrected(stream)
        first = list(itertools.islice(rest, 2 * self.leap_confirm - 1))  # judged against their median time
        if first:
            times = np.array([t for t, _ in first], np.float64)
            median = float(np.median(times))
            limit = median + leap + 5.0 * float(np.median(np.abs(times - median)))  # (a slow stream spreads them)
            # one far after the others is a bad stamp when the old clock went on after it (leap_confirm messages
            # or more, as for a leap below); else it is held as a leap after the others, for the messages that
            # follow to confirm (recordings of a few messages each, read as one: the second starts a jump) or refute
            late = [k for k, m in enumerate(first) if m[0] > limit]
            ahead = []
            for k in late:
                if sum(m[0] <= limit for m in first[k + 1:]) >= self.leap_confirm:
                    self.dropped_ahead[first[k][1].sensor] += 1
                else:
                    ahead.append(first[k])
            first = [m for m in first if m[0] <= limit] + ahead
        for t, record in itertools.chain(first, rest):
            sensors.add(record.sensor)
            if newest is not None and t > newest + leap:
                # a leap that does not go on from the held ones at their pace disagrees: they were bad stamps
                if leaps and not (leaps[0][0] - leap <= t <= leaps[-1][0] + max(leap, leaps[0][0] - newest)):
                    refute()
                leaps.append((t, record))
                if len(leaps) < self.leap_confirm or (
                        len(sensors) > 1 and len({r.sensor for _, r in leaps}) < 2
                        and len(leaps) < 4 * self.leap_confirm):  # (other sensors may have died at the jump)
                    continue
                accepted = sorted(leaps, key=lambda m: m[0])  # the stream jumped: let them all through
                leaps.clear()
                old_clock = 0
            else:
                if leaps:  # the old clock goes on: after leap_confirm such messages the held ones were bad stamps
                    old_clock += 1
                    if old_clock >= self.leap_confirm:
                        refute()
                accepted = [(t, record)]
            for t, record in accepted:
                if last_out is not None and t < last_out:
                    self.dropped[record.sensor] += 1
                    continue
                if newest is not None and t < newest:
                    self.reordered += 1
                newest = t if newest is None else max(newest, t)
                heapq.heappush(heap, (t, next(counter), record))
                while heap and heap[0][0] <= newest - self.window_ns:
                    last_out, _, out = heapq.heappop(heap)
                    yield out
        if leaps and (len(sensors) == 1 or len(leaps) > 1):  # (the held ones agree with each other)
            for t, record in leaps:  # nothing comes after them: let through
                heapq.heappush(heap, (t, next(counter), record))
            leaps.clear()
        refute()
        while heap:
            last_out, _, out = heapq.heappop(heap)
            yield out
        if self.dropped:
            log.warning(
                "dropped %d message(s) that arrived more than %.0f ms out of order: %s",
                sum(self.dropped.values()), self.window_ns / 1e6,
                ", ".join(f"{s}: {n}" for s, n in sorted(self.dropped.items())),
            )
        if self.dropped_ahead:
            log.warning(
                "dropped %d message(s) stamped more than %.0f ms ahead of the others (bad stamps, or a clock "
                "offset to set in the pipeline file): %s",
                sum(self.dropped_ahead.values()), self.leap_ns / 1e6,
                ", ".join(f"{s}: {n}" for s, n in sorted(self.dropped_ahead.items())),
            )


def synchronize(
    stream: Iterable[Any], window_ns: int = 200_000_000, clock_corrections_ns: Mapping[str, int] | None = None
) -> Iterator[Any]:
    """Shorthand for ``Synchronizer(window_ns, clock_corrections_ns)(stream)``."""
    return Synchronizer(window_ns, clock_corrections_ns)(stream)


def estimate_clock_offset(t1: np.ndarray, t2: np.ndarray, t3: np.ndarray, t4: np.ndarray) -> tuple[int, int]:
    """Client clock offset from request/reply exchanges, keeping the one with the least delay (B1, NTP).

    Parameters
    ----------
    t1, t4 : (n,) int
        Client send and receive times (client clock, ns).
    t2, t3 : (n,) int
        Server receive and reply times (server clock, ns).

    Returns
    -------
    offset_ns, delay_ns : int
        ``t_server = t_client + offset_ns`` (so ``offset_ns`` is the client's clock *correction* for
        :class:`Synchronizer`); ``delay_ns`` is the round trip of the exchange used.
    """
    t1, t2, t3, t4 = (np.asarray(a, np.int64) for a in (t1, t2, t3, t4))
    if not (t1.shape == t2.shape == t3.shape == t4.shape) or t1.ndim != 1 or t1.size == 0:
        raise ValueError("estimate_clock_offset: t1..t4 must be 1-D arrays of one non-zero length")
    delay = (t4 - t1) - (t3 - t2)
    best = int(np.argmin(delay))
    offset = ((t2[best] - t1[best]) + (t3[best] - t4[best])) // 2
    return int(offset), int(delay[best])


def align_nearest(frame_t_ns: np.ndarray, sample_t_ns: np.ndarray, max_dt_ns: int) -> np.ndarray:
    """For each frame time, the index of the nearest sample within ``max_dt_ns``, else -1 (B1).

    Parameters
    ----------
    frame_t_ns : (n_frames,) int
    sample_t_ns : (n_samples,) int, sorted ascending
    max_dt_ns : int

    Returns
    -------
    (n_frames,) int64 indices into ``sample_t_ns``; -1 where the sensor is missing for that frame.
    """
    frames = np.asarray(frame_t_ns, np.int64)
    samples = np.asarray(sample_t_ns, np.int64)
    if samples.size == 0:
        return np.full(frames.shape, -1, np.int64)
    if np.any(np.diff(samples) < 0):
        raise ValueError("align_nearest: sample_t_ns must be sorted ascending")
    right = np.searchsorted(samples, frames).clip(0, samples.size - 1)
    left = (right - 1).clip(0, samples.size - 1)
    pick = np.where(np.abs(samples[left] - frames) <= np.abs(samples[right] - frames), left, right)
    return np.where(np.abs(samples[pick] - frames) <= max_dt_ns, pick, -1).astype(np.int64)
