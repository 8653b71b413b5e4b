"""The traffic pipeline's camera branches in worker processes (``TrafficParams.workers``).

A camera frame costs the camera branch about 9 ms (MoG, A2, A3, blobs, ground positions, its tracker), two thirds
of the pipeline's work on the simulated road; the lasers, fusion, the particle filter and scene understanding
share the rest. On a machine with several cores the camera branches run beside them in worker processes:

* each camera's detector lives in exactly one worker, which is forked after the detectors are built (nothing of
  them is pickled, and their state stays in the worker);
* the main process sends each frame to its camera's worker as soon as it has read it, and reads on;
* the results come back per worker in the order the frames were sent: a frame's detections, or the error that
  made the branch skip it, with the worker's CPU and wall time for it;
* a bug in a worker is raised in the main process as the worker's own exception (a :class:`RuntimeError` if it
  cannot be pickled), with the worker's traceback as its cause; a worker that dies is reported, not waited for.

:func:`~fusiontrack.fusion.traffic.track_traffic` keeps every effect on the fusion's state in recording order (it
queues them until the frames before them are back), so the tracks are those of the serial run, bit for bit.

Only the ``fork`` start method is used (the detectors hold OpenCV objects that cannot be pickled); where it is
not available (Windows, macOS defaults aside) :func:`available` says so and the pipeline runs serially.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing as mp
import os
import pickle
import queue
import signal
import time
import traceback
from collections import deque
from collections.abc import Callable, Mapping
from multiprocessing.connection import Connection, wait
from multiprocessing.reduction import ForkingPickler
from typing import Any

log = logging.getLogger(__name__)

__all__ = ["CameraJob", "CameraWorkers", "available", "default_workers"]


def available() -> bool:
    """Whether worker processes can be used here (the ``fork`` start method)."""
    return "fork" in mp.get_all_start_methods()


def default_workers(n_cameras: int) -> int:
    """Worker processes for ``n_cameras`` camera branches: one per camera, at most one fewer than the cores this
    process may use (the main process reads the recording, runs the lasers, fusion, the particle filter and the
    scene rules); 0 (serial) on one core, without cameras, or without ``fork``."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    if n_cameras <= 0 or cores < 2 or not available() or mp.current_process().daemon:
        return 0  # (a daemonic process, e.g. a multiprocessing pool's worker, may not start processes)
    return max(1, min(n_cameras, cores - 1))


class CameraJob:
    """One frame sent to a worker: ``done`` once its result is back (``detections``, or ``error`` when the branch
    skipped the frame for bad data), with the worker's ``cpu_s`` and ``wall_s`` for it."""

    __slots__ = ("cpu_s", "detections", "done", "error", "sensor", "wall_s", "worker")

    def __init__(self, sensor: str, worker: int) -> None:
        self.sensor = sensor
        self.worker = worker
        self.done = False
        self.detections: list[Any] = []
        self.error: str | None = None
        self.cpu_s = 0.0
        self.wall_s = 0.0


def _detach_from_parent() -> None:
    """In a fresh worker: log to the process's own stderr (a handler of the parent, e.g. a live progress display's
    console, may have been forked with its lock held by a thread that does not exist here) and leave Ctrl-C to the
    main process, which stops the workers."""
    import sys

    root = logging.getLogger()
    level = root.level
    for h in list(root.handlers):
        root.removeHandler(h)
    handler = logging.StreamHandler(sys.__stderr__)
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s (camera worker): %(message)s"))
    root.addHandler(handler)
    root.setLevel(level)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


class _RemoteTraceback(Exception):
    """The traceback of an exception raised in a camera worker, chained as the cause of its copy in the main
    process (as :mod:`concurrent.futures` does)."""

    def __str__(self) -> str:
        return str(self.args[0])


def _picklable(exc: BaseException) -> bytes | None:
    """``exc`` pickled, if it survives the round trip (a custom exception may not); None otherwise."""
    try:
        data = pickle.dumps(exc)
        pickle.loads(data)
    except Exception:
        return None
    return data


def _serve(jobs: Any, results: Connection, detectors: Mapping[str, Callable[[Any], list[Any]]],
           parent: int) -> None:
    """A worker's loop: frames in (pickled by the main process), detections out, in order, until ``None``; at the
    end its whole CPU time. Leaves when the main process is gone (killed: nothing else would end the wait)."""
    _detach_from_parent()
    while True:
        try:
            item = jobs.get(timeout=1.0)
        except queue.Empty:
            if os.getppid() != parent:
                return
            continue
        if item is None:
            results.send(("exit", None, None, time.process_time(), 0.0))
            break
        c0, w0 = time.process_time(), time.perf_counter()
        try:
            sensor, image = pickle.loads(item)
            try:
                out: tuple[Any, ...] = ("ok", detectors[sensor](image), None)
            except (ValueError, FloatingPointError) as err:  # bad data in one frame: the serial run skips it too
                out = ("ok", [], f"{type(err).__name__}: {err}")
            results.send((*out, time.process_time() - c0, time.perf_counter() - w0))
        except BaseException as exc:  # a bug (or a result that cannot be sent): the main process raises it
            results.send(("crash", traceback.format_exc(), _picklable(exc), 0.0, 0.0))
            break
    results.close()


class CameraWorkers:
    """Camera branches in ``n_workers`` forked processes (module docstring).

    Parameters
    ----------
    detectors : mapping sensor -> callable(Image) -> list of Detection
        The camera branches, built; each goes to one worker (round robin in sensor order).
    n_workers : int
        At least 1; more than the cameras are not used.
    max_in_flight : int
        Frames a worker may have queued before :meth:`submit` waits for its oldest (bounds the memory).

    Raises
    ------
    ValueError
        No detectors, ``n_workers < 1``, or no ``fork`` start method here.
    """

    def __init__(self, detectors: Mapping[str, Callable[[Any], list[Any]]], n_workers: int,
                 max_in_flight: int = 8) -> None:
        if not detectors:
            raise ValueError("detectors: expected at least one camera branch, got none")
        if isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 1:
            raise ValueError(f"n_workers: expected an integer >= 1, got {n_workers!r}")
        if not available():
            raise ValueError("worker processes need the 'fork' start method, which this platform does not have")
        ctx = mp.get_context("fork")
        names = sorted(detectors)
        n = min(n_workers, len(names))
        self._worker_of = {s: i % n for i, s in enumerate(names)}
        self._max = max(1, int(max_in_flight))
        self._jobs: list[Any] = []
        self._conns: list[Connection] = []
        self._procs: list[Any] = []
        self._pending: list[deque[CameraJob]] = []
        self.cpu_s = 0.0  # the workers' CPU time, summed over the frames
        self.total_cpu_s = 0.0  # the workers' whole CPU time (unpickling, sending, start-up), known after close()
        try:
            for i in range(n):
                mine = {s: detectors[s] for s in names if self._worker_of[s] == i}
                jobs = ctx.Queue()
                parent, child = ctx.Pipe(duplex=False)
                proc = ctx.Process(target=_serve, args=(jobs, child, mine, os.getpid()),
                                   name=f"fusiontrack-camera-{i}", daemon=True)
                proc.start()
                child.close()
                self._jobs.append(jobs)
                self._conns.append(parent)
                self._procs.append(proc)
                self._pending.append(deque())
        except BaseException:
            self.close()
            raise

    @property
    def n_workers(self) -> int:
        return len(self._procs)

    def submit(self, sensor: str, image: Any) -> CameraJob:
        """Send a frame to its camera's worker; waits first while that worker has ``max_in_flight`` frames."""
        i = self._worker_of[sensor]
        while len(self._pending[i]) >= self._max:
            self._receive(i)
        # pickled here, not in the queue's feeder thread: a frame that cannot be sent fails now (not by a worker
        # waiting for ever), the pixels are taken as they are now, and the cost is counted where it is paid
        data = bytes(ForkingPickler.dumps((sensor, image)))
        job = CameraJob(sensor, i)
        self._pending[i].append(job)
        self._jobs[i].put(data)
        return job

    def poll(self) -> None:
        """Take in every result that is already back, without waiting."""
        for i, conn in enumerate(self._conns):
            while self._pending[i] and conn.poll():
                self._receive(i)

    def wait(self, job: CameraJob) -> None:
        """Wait until ``job`` is done (and every frame sent before it to the same worker)."""
        while not job.done:
            self._receive(job.worker)

    def _receive(self, i: int) -> None:
        conn = self._conns[i]
        wait([conn, self._procs[i].sentinel])
        try:
            status, payload, error, cpu, wall = conn.recv()
        except EOFError:
            raise RuntimeError(f"camera worker {i} ({self._procs[i].name}) ended unexpectedly (exit code "
                               f"{self._procs[i].exitcode})") from None
        if status == "crash":
            remote = _RemoteTraceback(f"camera worker {i} failed:\n{payload}")
            exc = pickle.loads(error) if error is not None else None
            # The worker's own exception, of its own type, with the worker's traceback as its cause; not a
            # SystemExit / KeyboardInterrupt (they would end this process quietly) nor the bad-data types the
            # caller skips (a crash must not pass for one bad frame).
            if isinstance(exc, Exception) and not isinstance(exc, (ValueError, FloatingPointError)):
                exc.add_note(f"raised in camera worker {i} ({self._procs[i].name})")
                raise exc from remote
            raise RuntimeError(f"camera worker {i} ({self._procs[i].name}) failed:\n{payload}") from remote
        job = self._pending[i].popleft()
        job.detections, job.error, job.cpu_s, job.wall_s, job.done = payload, error, cpu, wall, True
        self.cpu_s += cpu

    def close(self) -> None:
        """Stop the workers: results still on their way are read and dropped; a worker that does not stop within
        10 s is terminated."""
        for jobs, proc in zip(self._jobs, self._procs, strict=False):
            if proc.is_alive():
                with contextlib.suppress(OSError, ValueError):
                    jobs.put(None)
        deadline = time.monotonic() + 10.0
        for conn, proc in zip(self._conns, self._procs, strict=False):
            while time.monotonic() < deadline:  # results still on their way, then the worker's CPU at its exit
                try:  # (a worker blocked on sending a result must be able to finish)
                    if conn.poll(0.05):
                        msg = conn.recv()
                        if msg[0] == "exit":
                            self.total_cpu_s += msg[3]
                            break
                    elif not proc.is_alive() and not conn.poll(0):
                        break
                except (EOFError, OSError):
                    break
            proc.join(timeout=1)
            if proc.is_alive():
                log.warning("%s did not stop; terminated", proc.name)
                proc.terminate()
            proc.join(timeout=5)
        for jobs in self._jobs:
            jobs.cancel_join_thread()  # nothing left to deliver to a stopped worker
            jobs.close()
        for conn in self._conns:
            conn.close()
        self._procs, self._jobs, self._conns, self._pending = [], [], [], []

    def __enter__(self) -> CameraWorkers:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
