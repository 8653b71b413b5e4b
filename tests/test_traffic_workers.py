"""The traffic pipeline's camera branches in worker processes: the serial run's tracks bit for bit, bad frames
skipped as serially, and a worker's failure raised (never a hang)."""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
from dataclasses import replace

import numpy as np
import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.fusion.traffic import TrafficParams, track_traffic
from fusiontrack.fusion.traffic_workers import CameraWorkers, available, default_workers
from fusiontrack.io.recording import Recording
from fusiontrack.types import Image, records_equal

pytestmark = pytest.mark.skipif(not available(), reason="worker processes need the 'fork' start method")


@pytest.fixture(scope="module")
def road(simulated):
    out = simulated("road", seconds=8.0, seed=1)
    with Recording(out) as rec:
        t_bad = rec.start_ns + int(4e9)
    return out, t_bad


def _same(a, b) -> bool:
    return len(a) == len(b) and all(records_equal(x, y) for x, y in zip(a, b, strict=True))


def test_camera_workers_give_the_serial_run_bit_for_bit(road):
    path, t_bad = road
    state = {"done": False}

    def one_bad_frame(msg):  # a frame of the wrong size: camera_0's branch rejects it (ValueError), once
        if isinstance(msg, Image) and msg.sensor == "camera_0" and msg.t_ns >= t_bad and not state["done"]:
            state["done"] = True
            return replace(msg, pixels=np.ascontiguousarray(msg.pixels[:-8]))
        return msg

    runs = {}
    for n in (0, 1, 2):
        state["done"] = False
        runs[n] = track_traffic(path, params=TrafficParams(workers=n), variants=("camera", "fusion_pf"),
                                message_filter=one_bad_frame)
    serial = runs[0]
    assert serial.workers == 0
    assert serial.errors == {"camera_0": 1}
    assert len(serial.states["fusion_pf"]) > 100
    for n in (1, 2):
        par = runs[n]
        assert par.workers == n
        for v in serial.states:
            assert _same(serial.states[v], par.states[v]), (n, v)
        assert _same(serial.scene_events, par.scene_events)
        assert _same(serial.tracker_events, par.tracker_events)
        assert par.detections == serial.detections
        assert par.errors == serial.errors
        assert par.fused_ticks == serial.fused_ticks
        assert par.n_ticks == serial.n_ticks
        # the camera branch's CPU is the workers' own, counted in the run's total with the main process's
        assert 0 < par.cpu_s["camera_branch"] <= par.total_cpu_s
        assert par.cpu_s["dispatch"] > 0
    assert not mp.active_children(), "the workers are stopped after the run"


def _raise_type_error(image):
    raise TypeError(f"a bug in the branch ({image})")


def _die(image):
    os._exit(3)


def _exit(image):
    sys.exit(3)


def _echo(image):
    return [image]


class _Unpicklable(Exception):
    def __init__(self, what, lock):  # two arguments: pickling rebuilds it with one, and fails
        super().__init__(what)
        self.lock = lock


def _raise_unpicklable(image):
    raise _Unpicklable("a bug with a lock", object())


@pytest.mark.parametrize(("branch", "raised", "message"), [
    (_raise_type_error, TypeError, "a bug in the branch"),
    (_raise_unpicklable, RuntimeError, "_Unpicklable: a bug with a lock"),
    (_die, RuntimeError, "ended unexpectedly"),
    (_exit, RuntimeError, "SystemExit: 3")])  # not raised here as itself: it would end this process quietly
def test_a_bug_in_a_worker_or_its_death_is_raised_in_the_main_process_not_waited_for(branch, raised, message):
    with CameraWorkers({"cam": branch}, 1) as pool:
        job = pool.submit("cam", 1)
        with pytest.raises(raised, match=message) as info:
            pool.wait(job)
    if branch is _raise_type_error:  # the worker's exception, of its own type, its traceback chained as the cause
        assert "_raise_type_error" in str(info.value.__cause__)
        assert any("camera worker 0" in note for note in info.value.__notes__)
    assert not mp.active_children()


def test_results_come_back_in_order_per_camera_with_bounded_frames_in_flight():
    with CameraWorkers({"a": _echo, "b": _echo}, 2, max_in_flight=2) as pool:
        jobs = [pool.submit("a" if i % 3 else "b", i) for i in range(20)]  # waits whenever 2 are out
        for job in jobs:
            pool.wait(job)
        assert [j.detections[0] for j in jobs] == list(range(20))
        assert {j.worker for j in jobs if j.sensor == "a"} != {j.worker for j in jobs if j.sensor == "b"}


def test_bad_worker_settings_are_named():
    with pytest.raises(ValueError, match="detectors"):
        CameraWorkers({}, 1)
    for bad in (0, True, 1.5):
        with pytest.raises(ValueError, match="n_workers"):
            CameraWorkers({"cam": _echo}, bad)
        with pytest.raises(ConfigError, match=r"traffic\.workers"):
            TrafficParams(workers=bad if bad != 0 else -1)
    assert TrafficParams.from_mapping({"workers": 0}).workers == 0
    assert default_workers(0) == 0
    cores = len(os.sched_getaffinity(0))
    for n in (1, 2, 5):  # never more workers than cameras, and a core is left to the main process
        assert 0 <= default_workers(n) <= min(n, max(cores - 1, 0))
        assert (default_workers(n) > 0) == (cores >= 2)


def test_a_frame_that_cannot_be_sent_fails_at_once_and_the_workers_go_on():
    import threading

    with CameraWorkers({"cam": _echo}, 1) as pool:
        with pytest.raises(TypeError, match="pickle"):
            pool.submit("cam", threading.Lock())
        job = pool.submit("cam", 7)
        pool.wait(job)
        assert job.detections == [7]
    assert pool.total_cpu_s > 0  # the worker's own CPU time, reported at its exit


def _state(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return "gone"


def _start_workers_and_die(conn):
    pool = CameraWorkers({"cam": _echo}, 1)
    conn.send(pool._procs[0].pid)
    os._exit(0)  # killed without a chance to stop its workers


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="needs /proc")
def test_workers_leave_when_the_main_process_is_killed():
    import time

    ctx = mp.get_context("fork")
    a, b = ctx.Pipe(duplex=False)
    parent = ctx.Process(target=_start_workers_and_die, args=(b,))
    parent.start()
    worker = a.recv()
    parent.join(timeout=10)
    deadline = time.monotonic() + 10
    while _state(worker) not in ("gone", "Z") and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _state(worker) in ("gone", "Z"), "an orphaned worker must not wait for ever"
