"""Time alignment: merging, clock offsets, bounded reordering, B1 clock estimation and frame alignment."""

from __future__ import annotations

import itertools
import logging

import numpy as np
import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.io.sync import Synchronizer, align_nearest, estimate_clock_offset, merge, synchronize
from fusiontrack.types import ImuSample, LaserScan


def imu(t_ns: int, sensor: str = "imu") -> ImuSample:
    return ImuSample(t_ns, sensor, "phone", [0.0, 0.0, 9.81])


def test_merge_interleaves_sorted_streams():
    a = [imu(t, "a") for t in (0, 10, 20, 30)]
    b = [imu(t, "b") for t in (5, 10, 25)]
    out = list(merge(a, b))
    assert [r.t_ns for r in out] == [0, 5, 10, 10, 20, 25, 30]
    assert [r.sensor for r in out if r.t_ns == 10] == ["a", "b"]  # stable: first stream first


def test_out_of_order_within_window_is_restored_and_later_is_dropped(caplog):
    rng = np.random.default_rng(0)
    true_t = np.arange(200) * 10_000_000  # 100 Hz
    arrival = true_t + rng.integers(0, 40_000_000, true_t.size)  # up to 40 ms network delay
    order = np.argsort(arrival, kind="stable")
    stream = [imu(int(true_t[i])) for i in order]
    assert [r.t_ns for r in stream] != sorted(r.t_ns for r in stream)  # the input really is shuffled
    sync = Synchronizer(window_ns=50_000_000)
    out = list(sync(stream))
    assert [r.t_ns for r in out] == sorted(true_t.tolist())
    assert sum(sync.dropped.values()) == 0
    assert sync.reordered > 0

    # One message 1 s late: dropped, counted, one warning that carries the count.
    late = [imu(t) for t in range(0, 2_000_000_000, 10_000_000)]
    late.insert(150, imu(500_000_000, "laggard"))
    sync = Synchronizer(window_ns=50_000_000)
    with caplog.at_level(logging.WARNING):
        out = list(sync(late))
    assert sync.dropped == {"laggard": 1}
    assert len(out) == len(late) - 1
    assert all(a.t_ns <= b.t_ns for a, b in itertools.pairwise(out))
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert "laggard: 1" in warnings[0].getMessage()


def test_clock_offsets_put_sensors_on_one_clock():
    scans = [LaserScan(t + 200_000_000, "laser", "laser", 0.0, 0.1, 0.0, 10.0, [1.0])
             for t in range(0, 1_000_000_000, 100_000_000)]
    frames = [imu(t, "camera") for t in range(0, 1_000_000_000, 40_000_000)]
    out = list(synchronize(merge(scans, frames), window_ns=300_000_000,
                           clock_corrections_ns={"laser": -200_000_000}))
    laser_t = [r.t_ns for r in out if r.sensor == "laser"]
    assert laser_t == list(range(0, 1_000_000_000, 100_000_000))
    assert all(a.t_ns <= b.t_ns for a, b in itertools.pairwise(out))
    assert scans[0].t_ns == 200_000_000  # the input record is untouched (records are immutable)


@pytest.mark.parametrize("bad", [-1, 1.5, "100ms", True])
def test_bad_window_is_a_config_error(bad):
    with pytest.raises(ConfigError, match="window_ns"):
        Synchronizer(window_ns=bad)


def test_bad_offset_names_the_sensor():
    with pytest.raises(ConfigError, match="laser_front"):
        Synchronizer(clock_corrections_ns={"laser_front": 0.2})


def test_b1_clock_offset_and_frame_alignment():
    """ALGORITHMS.md B1: +200 ms client offset, symmetric 10 ms delay, +-2 ms jitter."""
    rng = np.random.default_rng(42)
    offset = 200_000_000
    ms = 1_000_000
    n = 8
    t1 = np.cumsum(rng.integers(50, 100, n)) * ms  # client clock
    up = 10 * ms + rng.integers(-2 * ms, 2 * ms, n)
    down = 10 * ms + rng.integers(-2 * ms, 2 * ms, n)
    t2 = t1 + offset + up  # server clock
    t3 = t2 + 1 * ms
    t4 = t3 - offset + down
    est, delay = estimate_clock_offset(t1, t2, t3, t4)
    assert abs(est - offset) <= 2 * ms
    assert delay > 0

    # Camera at 25 Hz on the server clock, lasers at 37.5 Hz stamped on the client clock.
    frames = np.arange(250) * 40 * ms
    laser_client = np.arange(400) * int(1e9 / 37.5) + 3 * ms - offset
    corrected = laser_client + est
    idx = align_nearest(frames, corrected, 20 * ms)
    true_idx = np.abs((laser_client + offset)[None, :] - frames[:, None]).argmin(axis=1)
    assert np.array_equal(idx, true_idx)


def test_align_nearest_marks_missing():
    idx = align_nearest(np.array([0, 100, 200]), np.array([5, 190]), 20)
    assert idx.tolist() == [0, -1, 1]
    assert align_nearest(np.array([1, 2]), np.array([], np.int64), 5).tolist() == [-1, -1]
