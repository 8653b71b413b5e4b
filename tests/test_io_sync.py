"""Time alignment: merging, clock offsets, bounded reordering, B1 clock estimation and frame alignment."""

from __future__ import annotations

import itertools
import logging
import os
import subprocess
import sys

import numpy as np
import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.io.sync import Synchronizer, align_nearest, estimate_clock_offset, merge, synchronize, with_time
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


def _two_lasers(seconds: float, jitter_ns: int, rng: np.random.Generator) -> list[ImuSample]:
    """Two 25 Hz sensors whose messages arrive with up to ``jitter_ns`` of disorder (as two scanners in a bag)."""
    true_t = [(t, s) for t in range(0, round(seconds * 1e9), 40_000_000) for s in ("a", "b")]
    arrival = np.array([t for t, _ in true_t]) + rng.integers(0, jitter_ns, len(true_t))
    return [imu(true_t[i][0] + (1_000_000 if true_t[i][1] == "b" else 0), true_t[i][1])
            for i in np.argsort(arrival, kind="stable")]


@pytest.mark.parametrize("n_bad", [1, 2])
def test_messages_stamped_far_ahead_are_dropped_not_followed(n_bad, caplog):
    """One (or two) messages stamped an hour ahead (a corrupt stamp) used to move the stream's clock forward, so that
    every later message counted as late: the reordering stopped and ~100 scans were dropped. Now only they are."""
    stream = _two_lasers(4.0, 30_000_000, np.random.default_rng(1))
    clean = sorted(r.t_ns for r in stream)
    bad = [with_time(stream[k], stream[k].t_ns + 3_600_000_000_000) for k in (60, 61)[:n_bad]]
    stream[60:60 + n_bad] = bad
    sync = Synchronizer(window_ns=50_000_000)
    with caplog.at_level(logging.WARNING):
        out = list(sync(stream))
    assert [r.t_ns for r in out] == sorted(set(clean) - {r.t_ns - 3_600_000_000_000 for r in bad})
    assert sum(sync.dropped_ahead.values()) == n_bad
    assert sum(sync.dropped.values()) == 0
    assert "ahead of the others" in caplog.text


def test_a_jump_of_the_whole_stream_is_followed():
    """A recording paused for an hour: every sensor jumps at once, nothing is dropped, the order holds."""
    rng = np.random.default_rng(2)
    first, second = _two_lasers(2.0, 30_000_000, rng), _two_lasers(2.0, 30_000_000, rng)
    stream = first + [with_time(r, r.t_ns + 3_600_000_000_000) for r in second]
    sync = Synchronizer(window_ns=50_000_000)
    out = list(sync(stream))
    assert [r.t_ns for r in out] == sorted(r.t_ns for r in stream)
    assert not sync.dropped
    assert not sync.dropped_ahead


def test_a_lone_leap_at_the_end_is_dropped_unless_the_stream_has_one_sensor():
    """Nothing comes after a leap at the very end to confirm or refute it: one sensor's (a slow sensor after a
    pause) goes through; a lone one in a stream of several sensors is a bad stamp."""
    one = [imu(t) for t in range(0, 1_000_000_000, 10_000_000)] + [imu(7_200_000_000_000)]
    sync = Synchronizer()
    assert len(list(sync(one))) == len(one)
    two = [imu(t, "ab"[k % 2]) for k, t in enumerate(range(0, 1_000_000_000, 10_000_000))] + [imu(7_200_000_000_000)]
    sync = Synchronizer()
    assert len(list(sync(two))) == len(two) - 1
    assert sync.dropped_ahead == {"imu": 1}


H_NS = 3_600_000_000_000


def _kept(stream: list[ImuSample], **kwargs: int) -> tuple[list[int], Synchronizer]:
    sync = Synchronizer(window_ns=50_000_000, **kwargs)
    out = [r.t_ns for r in sync(stream)]
    assert out == sorted(out)
    return out, sync


def test_a_bad_stamp_on_the_first_message_does_not_set_the_clock():
    ms = 1_000_000
    good = [0, 40, 30, 80, 70, 120, 110, 160]  # 10 ms of disorder, within the window
    out, sync = _kept([imu(H_NS)] + [imu(t * ms) for t in good])
    assert out == sorted(t * ms for t in good)
    assert sync.dropped_ahead == {"imu": 1}
    assert not sync.dropped


def test_recordings_of_a_few_messages_each_read_as_one_lose_nothing():
    """Five snapshot bags of three messages each (image, depth, camera info; ../shared/data/rgbd/tue_rgbd_people),
    the second 40 s after the first: the jump falls within the first five messages, which are judged against their
    median. Two of the second bag's messages were dropped as bad stamps; the messages after them confirm the jump."""
    ms = 1_000_000
    starts = [0, 40_000, 47_000, 52_000, 56_000]  # ms, as the bags' times 12:41:38 .. 12:42:34
    stream = [imu((t0 + dt) * ms, s) for t0 in starts for dt, s in ((0, "depth"), (300, "info"), (1100, "rgb"))]
    out, sync = _kept(stream)
    assert out == [r.t_ns for r in stream]
    assert not sync.dropped_ahead
    assert not sync.dropped
    # one bad stamp among the first messages, with the old clock going on after it, is still dropped
    bad = [imu(t * ms, "ab"[k % 2]) for k, t in enumerate(range(0, 200, 40))]
    bad[3] = imu(H_NS, "a")
    out, sync = _kept(bad + [imu(t * ms, "ab"[k % 2]) for k, t in enumerate(range(200, 400, 40))])
    assert H_NS not in out
    assert sync.dropped_ahead == {"a": 1}


def test_unrelated_bad_stamps_in_a_row_are_not_a_jump():
    """Three bad stamps in a row (1 h, 5 h, 9 h ahead) disagree with each other: no jump, all three dropped."""
    ms = 1_000_000
    stream = [imu(t * ms, "a") for t in range(0, 400, 40)] + [imu(H_NS, "a"), imu(5 * H_NS, "b"), imu(9 * H_NS, "a")]
    stream += [imu(t * ms, s) for t in range(400, 2000, 40) for s in "ab"]
    out, sync = _kept(stream)
    assert len(out) == len(stream) - 3
    assert sum(sync.dropped_ahead.values()) == 3


def test_one_sensor_an_hour_ahead_is_dropped_not_followed():
    """A sensor whose clock is an hour off (messages in bursts of three) is not the whole stream jumping: its
    messages are dropped, counted (the warning suggests a clock offset), the others all go through."""
    ms = 1_000_000
    stream = [imu(t * ms, "a") for t in range(0, 400, 40)]
    for t in range(400, 2000, 120):
        stream += [imu(H_NS + (t + k) * ms, "cam") for k in range(3)]
        stream += [imu((t + d) * ms, "a") for d in (0, 40, 80)]
    out, sync = _kept(stream)
    assert len(out) == sum(r.sensor == "a" for r in stream)
    assert sync.dropped_ahead == {"cam": sum(r.sensor == "cam" for r in stream)}


def test_a_pause_with_one_sensor_logged_a_little_late_loses_nothing():
    """After a pause, sensor b's last message from before it arrives after a's first from after it (b is logged
    30 ms late): the old clock goes on for a message, which must not refute the jump."""
    ms = 1_000_000
    stream = [imu(0, "a")]
    for t in range(40, 1000, 40):
        stream += [imu(t * ms, "a"), imu((t - 30) * ms, "b")]
    for t in range(1000, 2000, 40):
        stream += [imu(H_NS + t * ms, "a"), imu((t - 30) * ms if t == 1000 else H_NS + (t - 30) * ms, "b")]
    out, sync = _kept(stream)
    assert len(out) == len(stream)
    assert not sync.dropped_ahead


def test_a_slow_stream_is_not_taken_for_leaps():
    """A sensor at 0.05 Hz alone (each message 20 s after the last: more than leap_ns) loses nothing."""
    stream = [imu(k * 20_000_000_000, "gps") for k in range(11)]
    out, sync = _kept(stream)
    assert len(out) == 11
    assert not sync.dropped_ahead


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


def test_the_pipeline_files_sync_window_reaches_track(tmp_path):
    """``[sync] window_ms`` is how late a scan may come: scanner b's scans are logged 350 ms after a's of the same
    time; with the default 200 ms they are dropped (warned), with ``window_ms = 500`` none is."""
    from fusiontrack.io.writer import RecordingWriter

    rng = np.random.default_rng(3)
    with RecordingWriter(tmp_path / "rec") as w:
        for i in range(60):
            for name, lag_ns in (("a", 0), ("b", 350_000_000)):
                r = (3.0 + 0.01 * rng.standard_normal(180)).astype(np.float32)
                t = (i + 1) * 100_000_000
                w.write(LaserScan(t, name, name, -1.5, 3.0 / 180, 0.05, 20.0, r), log_t_ns=t + lag_ns,
                        topic=f"/{name}/scan")
    (tmp_path / "wide.toml").write_text("[sync]\nwindow_ms = 500\n")

    def track(*extra: str) -> str:
        done = subprocess.run([sys.executable, "-m", "fusiontrack", "track", str(tmp_path / "rec"), "-o",
                               str(tmp_path / "out"), "--no-video", *extra], capture_output=True, text=True,
                              timeout=120, env={**os.environ, "COLUMNS": "300"})
        assert done.returncode == 0, done.stderr
        return done.stdout + done.stderr

    assert "arrived more than 200 ms out of order" in track()
    assert "out of order" not in track("-c", str(tmp_path / "wide.toml"))
