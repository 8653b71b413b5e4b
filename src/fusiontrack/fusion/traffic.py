"""The ``traffic`` pipeline (seed 003, ALGORITHMS.md D0–D8): lasers and cameras on a road, fused into vehicle
models, tracked by the mode particle filter, read by scene understanding.

One pass over the recording, every sensor in log order:

1. each laser scan goes through the laser branch (``laser/vehicles.py``: background, road ROI, clustering, box
   fitting, per-laser tracks), every ``camera_every``-th image of a camera (default every 2nd) through the camera
   branch (``vision/vehicles.py``: MoG + shadows, road ROI, blobs, ground position through the ground homography,
   per-camera tracks); both give :class:`~fusiontrack.types.Detection` in the road frame;
2. at a fixed rate (``rate_hz``, default 15 Hz, the cameras' rate) the latest frame of every sensor is moved to
   the fusion instant (D2) and fused into object models (D5, ``fusion/objects.py``);
3. the objects feed the trackers of the requested *variants*: ``fusion_pf`` (D6 mode particle filter, the
   pipeline's output), and for comparison ``fusion`` (the same objects, a constant-velocity Kalman tracker),
   ``laser`` and ``camera`` (objects from one sensor kind only, Kalman);
4. the ``fusion_pf`` states go through scene understanding (D7/D8 rules, ``scene/``) online.

``message_filter`` lets a benchmark inject faults (occlusions, blackouts) into the stream without touching the
recording. Bad sensor data degrades: a branch that raises on a message logs it and the run goes on.
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, RecordingError
from ..io.recording import Recording
from ..io.sync import synchronize
from ..tracking.baseline import CVKalmanTracker
from ..tracking.vehicle_pf import FusedObject, VehicleModeTracker, VehiclePfParams
from ..types import Detection, Event, Image, LaserScan, TrackState
from ..vision.cvthreads import opencv_threads
from .objects import DetectionBuffer, ObjectFusionParams, fuse_objects, sensor_kind
from .traffic_workers import CameraJob, CameraWorkers, default_workers

log = logging.getLogger(__name__)

__all__ = ["VARIANTS", "TrafficParams", "TrafficResult", "roads_of", "track_traffic"]

VARIANTS = {
    "camera": "cameras only: camera objects, constant-velocity Kalman",
    "laser": "lasers only: laser objects, constant-velocity Kalman",
    "fusion": "D5 fused objects, constant-velocity Kalman",
    "fusion_pf": "D5 fused objects, D6 mode particle filter (the pipeline's output)",
}


def _every_nth_scan(messages: Iterable[Any], every: int) -> Iterator[LaserScan]:
    """Each laser's 1st, (every+1)-th, ... scan: those the laser branch is given (``TrafficParams.laser_every``)."""
    seen: dict[str, int] = {}
    for msg in messages:
        if isinstance(msg, LaserScan):
            seen[msg.sensor] = seen.get(msg.sensor, -1) + 1
            if seen[msg.sensor] % every == 0:
                yield msg


@dataclass(frozen=True, slots=True)
class TrafficParams:
    """Pipeline settings; the component parameters are passed to the component that owns them.

    ``camera_every`` = k gives each camera's branch only every k-th frame (1: all); the others are dropped
    before any processing (the branch's tracker steps over the gap, fusion uses the latest frame, at most
    ``k / 15`` s old at 15 Hz; the fusion's buffer keeps a frame for up to ``k + 1.25`` of its sensor's periods,
    measured from the stream, when that is longer than ``fusion.max_age_s``, so a 10 Hz camera, ``k = 3`` or a
    dropped frame do not make its detections vanish between two frames). Default 2 [RECON]: the cameras cost half,
    and on ``benchmarks/traffic.py`` (3 seeds x 60 s) fusion + PF went from MOTA 0.712 / IDF1 0.819 / 15 IDSW
    (every frame) to 0.783 / 0.832 / 16.
    ``laser_every`` likewise for each laser's scans (its background then learns from those scans only). Default 2
    [RECON]: 25 Hz scans at 12.5 Hz, still close to the 15 Hz fusion rate; the laser branch costs half, and on
    ``benchmarks/traffic.py`` (3 seeds x 60 s, ``camera_every = 2``) fusion + PF went from MOTA 0.783 / IDF1 0.832 /
    16 IDSW (every scan) to 0.778 / 0.851 / 9, the injected occlusions kept as before (3/4), the incidents as
    before or better (stopped vehicle 3/3, onset latency 0.73 -> 0.80 s; road leaving 2/3 -> 3/3). On 16 s clips
    (seeds 0-2) MOTA 0.905 / 0.976 / 0.935 -> 0.877 / 0.956 / 0.939, seed 0 with two id switches (none).

    The branches count in the frames (scans) they are given, so with ``camera_every = k`` every per-frame constant
    of the camera branch spans k times as long: its tracker's ``n_confirm`` (3 frames: 0.4 s instead of 0.2 s at
    k = 2, 15 Hz), the foreground model's MOG2 rate α = 0.002 per frame (``history = 500``: 67 s instead of 33 s),
    its ``illumination_frames`` (30: 4 s of fast relearning) and stopped-object timings, and the road memory's
    update every 4th frame; likewise ``laser_every`` for the laser branch's background and tracker. The time-based
    ones (``max_coast_s``, the Kalman noise per second) are unchanged. Tune them in ``camera``/``laser`` when
    changing k.

    The pipeline runs OpenCV single-threaded (``cv2.setNumThreads(1)``, restored after the run): its images are
    small, and OpenCV's worker threads cost more CPU than they save (0.7-0.8 ms of CPU per camera frame of
    9-10 ms, measured frame by frame on the simulated road, the same detections).

    ``workers`` camera branches run in worker processes beside the main one (``fusion/traffic_workers.py``): the
    camera branch is two thirds of the work, and the tracks are those of the serial run, bit for bit. Default
    (``None``): one per camera within the cores this process may use, minus one for the main process (one worker
    for both cameras on 2 cores); 0 runs everything in this process.

    ``prime_lasers``: the laser branch learns its backgrounds from the recording's first scans read ahead
    (:meth:`~fusiontrack.laser.vehicles.LaserVehicleDetector.prime`, every ``laser_every``-th scan as the branch
    gets them, as recorded: ``message_filter`` acts on the tracking pass), so vehicles on the road from the start
    are detected from the first scan instead of after ``n_init`` scans (4 s at ``laser_every = 2``). Off by default
    (online learning only, as a live sensor would) [RECON]: on ``benchmarks/traffic.py`` (3 seeds x 60 s, paired)
    it gave fusion + PF MOTA 0.783 -> 0.787, FN 1725 -> 1659, but ID switches 8 -> 11 and road leaving 3/3 -> 2/3
    (stopped vehicles 3/3 both): a shift in the first seconds moves the rest of the run, and three seeds cannot
    tell whether it pays.
    """

    rate_hz: float = 15.0
    fusion: ObjectFusionParams = field(default_factory=ObjectFusionParams)
    tracker: VehiclePfParams = field(default_factory=VehiclePfParams)
    kalman: Mapping[str, Any] = field(default_factory=lambda: {"q": 2.0, "r_m": 0.3, "gate_m": 2.5,
                                                               "n_confirm": 3, "n_miss": 30})
    laser: Mapping[str, Any] = field(default_factory=dict)
    camera: Mapping[str, Any] = field(default_factory=dict)
    roi_margin_m: float = 5.0
    camera_every: int = 2
    laser_every: int = 2
    workers: int | None = None
    prime_lasers: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.rate_hz) and 0.5 <= self.rate_hz <= 100):
            raise ConfigError(f"traffic.rate_hz: expected a rate in [0.5, 100] Hz, got {self.rate_hz!r}")
        for name in ("camera_every", "laser_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"traffic.{name}: expected an integer >= 1, got {v!r}")
        if not isinstance(self.prime_lasers, bool):
            raise ConfigError(f"traffic.prime_lasers: expected true or false, got {self.prime_lasers!r}")
        w = self.workers
        if w is not None and (isinstance(w, bool) or not isinstance(w, int) or w < 0):
            raise ConfigError(f"traffic.workers: expected an integer >= 0 (0: no worker processes) or none for "
                              f"one per camera within the cores, got {w!r}")

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], source: str = "[traffic]") -> TrafficParams:
        """From a pipeline file's ``[traffic]`` table: ``rate_hz``, and sub-tables ``fusion``, ``tracker``,
        ``kalman``, ``laser``, ``camera``."""
        from .objects import as_params

        names = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - names)
        if unknown:
            raise ConfigError(f"{source}: unknown key(s) {unknown}; expected some of {sorted(names)}")
        # every key but the two sub-tables read into their own types goes through as it is (a key left out of a
        # list here was accepted and then silently ignored: prime_lasers was)
        kw: dict[str, Any] = {k: v for k, v in values.items() if k not in ("fusion", "tracker")}
        if "fusion" in values:
            kw["fusion"] = as_params(dict(values["fusion"]), f"{source}.fusion")
        if "tracker" in values:
            kw["tracker"] = VehiclePfParams.from_mapping(dict(values["tracker"]), f"{source}.tracker")
        try:
            return cls(**kw)
        except ConfigError as err:
            raise ConfigError(f"{source}: {err}") from None


@dataclass
class TrafficResult:
    """What :func:`track_traffic` measured. ``states[variant]`` are the track states of each variant.

    ``timings_s`` is the wall-clock time spent per part, ``cpu_s`` the CPU time of the process (every thread) per
    part: on a shared machine the wall clock also counts the time other processes held the cores. The parts are
    ``read`` (reading and decoding the recording's messages, the skipped frames and scans included), the branches
    (``laser_branch``, ``camera_branch``), ``dispatch`` (with camera workers: sending frames, waiting for and
    taking in their results), the trackers of the variants and ``scene``; with ``workers`` > 0 the camera branch's
    times are the workers' own. ``elapsed_s`` is the whole run by the wall clock and ``total_cpu_s`` its CPU time,
    the main process and the workers together. ``fused_ticks`` counts, per sensor, the fusion instants at which a
    frame of it was recent enough to take part.
    """

    states: dict[str, list[TrackState]]
    tracker_events: list[Event]
    scene_events: list[Event]
    sensors: dict[str, str]
    n_ticks: int = 0
    duration_s: float = 0.0
    timings_s: dict[str, float] = field(default_factory=dict)
    detections: dict[str, int] = field(default_factory=dict)
    errors: dict[str, int] = field(default_factory=dict)
    t0_ns: int = 0
    cpu_s: dict[str, float] = field(default_factory=dict)
    fused_ticks: dict[str, int] = field(default_factory=dict)
    elapsed_s: float = 0.0
    total_cpu_s: float = 0.0
    workers: int = 0

    def real_time_factor(self) -> float:
        """Recording seconds per second of the run, by the wall clock from opening the recording to the last
        track (everything a user waits for, with the camera workers running beside the main process)."""
        return self.duration_s / self.elapsed_s if self.elapsed_s > 0 else math.inf

    def cpu_real_time_factor(self) -> float:
        """Recording seconds per second of CPU, the main process (every thread) and the camera workers together:
        the cost, whatever the cores."""
        return self.duration_s / self.total_cpu_s if self.total_cpu_s > 0 else math.inf

    def speed_x_real_time(self, parts: Sequence[str] = ("read", "laser_branch", "camera_branch", "dispatch",
                                                        "fusion_pf", "scene"), cpu: bool = False) -> float:
        """Recording seconds per processing second of the named parts (by default what a user of ``fusion_pf``
        waits for in a serial run: reading the recording, the branches, the particle filter and scene
        understanding); by the wall clock, or by CPU time (``cpu``). With camera workers the parts overlap (the
        workers' camera branch runs while the main process works or waits in ``dispatch``): the wall-clock sum is
        then no real time factor; :meth:`real_time_factor` is."""
        spent = sum((self.cpu_s if cpu else self.timings_s).get(p, 0.0) for p in parts)
        return self.duration_s / spent if spent > 0 else math.inf


def roads_of(source: Any) -> np.ndarray:
    """Roads as ``(n, 5)`` rows ``(x0, y0, x1, y1, width)`` from a world.json path/mapping, a :class:`RoadGeometry`
    (each road polygon by its minimum-area rectangle) or an array."""
    from ..scene.road import RoadGeometry

    if isinstance(source, RoadGeometry):
        import cv2

        rows = []
        for road in source.roads:
            (cx, cy), (w, h), ang = cv2.minAreaRect(road.polygon.astype(np.float32))
            a = math.radians(ang)
            length, width = (w, h) if w >= h else (h, w)
            if w < h:
                a += math.pi / 2
            d = np.array([math.cos(a), math.sin(a)]) * length / 2
            rows.append([cx - d[0], cy - d[1], cx + d[0], cy + d[1], width])
        return np.array(rows, np.float64)
    if isinstance(source, str | Path):
        path = Path(source)
        try:
            source = json.loads(path.read_text())
        except (OSError, ValueError) as err:
            raise ConfigError(f"{path}: cannot read the roads ({err})") from err
    if isinstance(source, Mapping):
        if "roads" not in source:
            raise ConfigError(f"roads: no 'roads' entry (keys: {sorted(source)})")
        source = source["roads"]
    arr = np.asarray(source, np.float64).reshape(-1, 5)
    if not arr.shape[0]:
        raise ConfigError("roads: the scene has no road")
    return arr


def _world_json(path: Path) -> Path | None:
    for cand in (path / "ground_truth" / "world.json", path.parent / "ground_truth" / "world.json"):
        if cand.is_file():
            return cand
    return None


def _roi_polygon(roads: np.ndarray, margin_m: float) -> np.ndarray:
    """The convex hull of every road rectangle widened by ``margin_m`` (the area where modes may live)."""
    from scipy.spatial import ConvexHull

    a, b, w = roads[:, 0:2], roads[:, 2:4], roads[:, 4]
    d = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    n = np.column_stack([-d[:, 1], d[:, 0]]) * (w[:, None] / 2 + margin_m)
    a, b = a - d * margin_m, b + d * margin_m
    pts = np.concatenate([a - n, b - n, b + n, a + n])
    return pts[ConvexHull(pts).vertices]


def _as_detection(o: FusedObject, t_ns: int, sensor: str) -> Detection:
    return Detection.trusted(t_ns, sensor, np.array(o.position_m, np.float64), o.covariance_m2 + np.eye(2) * 1e-4,
                             cls=o.cls, score=o.confidence)


class _KalmanVariant:
    """A constant-velocity Kalman tracker on fused objects of some sensors (the comparison variants)."""

    def __init__(self, name: str, kinds: tuple[str, ...], kalman: Mapping[str, Any], frame_s: float) -> None:
        self.name, self.kinds = name, kinds
        self.tracker = CVKalmanTracker(frame_s=frame_s, sensor=name, **dict(kalman))
        self.cls: dict[int, str] = {}

    def step(self, t_ns: int, objects: list[FusedObject]) -> list[TrackState]:
        states = self.tracker.step(t_ns, [_as_detection(o, t_ns, self.name) for o in objects])
        return states


def _select(per_sensor: Mapping[str, list[Detection]], kinds: tuple[str, ...]) -> dict[str, list[Detection]]:
    return {s: d for s, d in per_sensor.items() if d and sensor_kind(d[0]) in kinds}


def track_traffic(path: str | Path, *, roads: Any = None, geometry: Any = None, rules: Any = None,
                  params: TrafficParams | None = None, variants: Iterable[str] = ("fusion_pf",),
                  time_source: str = "header", message_filter: Callable[[Any], Any] | None = None,
                  progress: Callable[[float], None] | None = None, start_ns: int | None = None,
                  stop_ns: int | None = None, calibration: Any = None, scene_engine: str = "rules") -> TrafficResult:
    """Run the traffic pipeline over a recording (module docstring).

    Parameters
    ----------
    path : recording folder or file
    roads : (n, 5) rows, world.json path, or None
        The road(s) the branches watch; default: the ``geometry``'s roads, else the simulator's
        ``ground_truth/world.json`` beside the recording.
    geometry : RoadGeometry or path of a road TOML, optional
        Lanes and zones for scene understanding; default: built from world.json.
    rules : SceneRules or path of a rules TOML, optional
        D8 rules (default: the shipped ones). Scene understanding needs a geometry.
    params : TrafficParams
    variants : names of :data:`VARIANTS`
    message_filter : callable(message) -> message or None, optional
        Applied to every sensor message before its branch (``None`` drops it): fault injection.
    scene_engine : ``"rules"`` or ``"learned"``
        Scene understanding by the D8 rules (``rules``; default: alarms after their hold times, 10 s for a stopped
        vehicle, 30 s for a jam) or by the learned behaviour model (D8's supervised alternative,
        :class:`~fusiontrack.scene.learned.LearnedSceneUnderstanding`: alarms within about 2 s; takes no rules).
    calibration : RoadCalibration or path of its JSON, optional
        Poses the lasers and cameras it names (``fusiontrack calibrate-road``, D1) instead of the recording's
        ``/tf_static`` and ``CameraInfo`` (:func:`~fusiontrack.fusion.traffic_sensors.traffic_branches`).
    """
    from ..scene import SceneUnderstanding, default_rules, load_road_geometry, load_rules, road_geometry_from_world
    from ..scene.road import RoadGeometry
    from ..vision.vehicles import VehicleDetectorParams
    from .traffic_sensors import traffic_branches

    p = params or TrafficParams()
    if isinstance(calibration, str | Path):
        from ..calibration.road import RoadCalibration

        calibration = RoadCalibration.load(calibration)
    variants = tuple(variants)
    bad = [v for v in variants if v not in VARIANTS]
    if bad or not variants:
        raise ConfigError(f"variants: expected some of {sorted(VARIANTS)}, got {list(variants)}")
    path = Path(path)
    world = _world_json(path)
    if isinstance(geometry, str | Path):
        geometry = load_road_geometry(geometry)
    if geometry is None and world is not None:
        geometry = road_geometry_from_world(world)
    if roads is None:
        if isinstance(geometry, RoadGeometry):
            roads = roads_of(geometry)
        elif world is not None:
            roads = roads_of(world)
        else:
            raise ConfigError(f"{path}: no road geometry: give the roads (a road TOML with --geometry) — the "
                              "recording has no ground_truth/world.json beside it")
    roads = roads_of(roads)
    if isinstance(rules, str | Path):
        rules = load_rules(rules)
    if scene_engine not in ("rules", "learned"):
        raise ConfigError(f"scene_engine: expected 'rules' or 'learned', got {scene_engine!r}")
    if scene_engine == "learned" and rules is not None:
        raise ConfigError("rules: the learned scene model takes no rules file (scene_engine='learned')")
    if geometry is None:
        scene = None
    elif scene_engine == "learned":
        from ..scene.learned import LearnedSceneUnderstanding

        scene = LearnedSceneUnderstanding(geometry, sensor="fusion_pf")
    else:
        scene = SceneUnderstanding(geometry, rules or default_rules(), sensor="fusion_pf")
    frame_s = 1.0 / p.rate_hz
    pf = VehicleModeTracker(p.tracker, roi_m=_roi_polygon(roads, p.roi_margin_m), sensor="fusion_pf") \
        if "fusion_pf" in variants else None
    kinds = {"camera": ("camera",), "laser": ("laser",), "fusion": ("laser", "camera")}
    kal = {v: _KalmanVariant(v, kinds[v], p.kalman, frame_s) for v in variants if v != "fusion_pf"}
    states: dict[str, list[TrackState]] = {v: [] for v in variants}
    tracker_events: list[Event] = []
    scene_events: list[Event] = []
    timings = dict.fromkeys(("read", "laser_branch", "camera_branch", "dispatch", *variants, "scene"), 0.0)
    cpu = dict.fromkeys(timings, 0.0)
    clock: dict[str, tuple[float, float]] = {}

    def start(part: str) -> None:
        clock[part] = (time.perf_counter(), time.process_time())

    def stop(part: str) -> None:
        wall0, cpu0 = clock.pop(part)
        timings[part] += time.perf_counter() - wall0
        cpu[part] += time.process_time() - cpu0

    counts: dict[str, int] = {}
    errors: dict[str, int] = {}
    buffer = DetectionBuffer(max(p.fusion.max_age_s, frame_s))
    wall_start, cpu_start = time.perf_counter(), time.process_time()
    worker_cpu, n_workers = 0.0, 0
    with Recording(path) as rec, opencv_threads(1):
        unknown = sorted(set(p.camera) - {f.name for f in fields(VehicleDetectorParams)})
        if unknown:
            raise ConfigError(f"traffic.camera: unknown key(s) {unknown}; expected some of "
                              f"{sorted(f.name for f in fields(VehicleDetectorParams))}")
        cam_params = VehicleDetectorParams(**dict(p.camera)) if p.camera else None
        laser, laser_topics, cams = traffic_branches(rec, roads, laser_params=p.laser, camera_params=cam_params,
                                                     time_source=time_source, calibration=calibration)
        if laser is None and not cams:
            raise RecordingError(f"{path}: neither LaserScan nor camera topics: nothing to track")
        cam_by_sensor = {d.camera_name: d for _, d in cams.values()}
        topics = [*laser_topics, *(t for t, _ in cams.values())]
        sensors = {**dict.fromkeys(laser.scanners if laser else (), "laser"), **dict.fromkeys(cam_by_sensor,
                                                                                               "camera")}
        t_first, t_last = rec.start_ns, rec.end_ns
        span = max(t_last - t_first, 1)
        next_tick: int | None = None
        first_t: int | None = None
        n_ticks = 0
        last_t = None
        seen: dict[str, int] = {}

        fused: dict[str, int] = {}
        first_frame: dict[str, int] = {}

        def tick(t_ns: int) -> None:
            per_sensor = buffer.at(t_ns)
            for s in per_sensor:
                fused[s] = fused.get(s, 0) + 1
            for v, k in kal.items():
                start(v)
                objs = fuse_objects(_select(per_sensor, k.kinds), p.fusion)
                states[v].extend(k.step(t_ns, objs))
                stop(v)
            if pf is not None:
                start("fusion_pf")
                objs = fuse_objects(per_sensor, p.fusion)
                out = pf.step(t_ns, objs)
                tracker_events.extend(pf.events)
                states["fusion_pf"].extend(out)
                stop("fusion_pf")
                if scene is not None:
                    start("scene")
                    scene.update(t_ns, out)
                    stop("scene")

        # Every effect on the fusion's state (a tick, a sensor's period, a branch's detections) is an event run in
        # recording order. Serially each runs at once; with camera workers a frame's detections come back later,
        # and the events after it wait in `pending` until they are back, so the run is the serial one.
        n_workers = p.workers if p.workers is not None else default_workers(len(cam_by_sensor))
        pool = CameraWorkers(cam_by_sensor, n_workers) if n_workers > 0 and cam_by_sensor else None
        n_workers = pool.n_workers if pool is not None else 0
        pending: deque[tuple[Any, ...]] = deque()

        def run(ev: tuple[Any, ...]) -> None:
            nonlocal n_ticks
            kind = ev[0]
            if kind == "tick":
                tick(ev[1])
                n_ticks += 1
                return
            if kind == "note":
                buffer.note(ev[1], ev[2])
                return
            if kind == "error":  # bad data in one message: skipped (counted and logged in recording order)
                errors[ev[1]] = errors.get(ev[1], 0) + 1
                log.warning("%s at %d ns: message skipped (%s)", ev[1], ev[2], ev[3])
                return
            _, sensor, t_ns, every, dets = ev
            if isinstance(dets, CameraJob):
                job = dets
                cpu["camera_branch"] += job.cpu_s
                timings["camera_branch"] += job.wall_s
                if job.error is not None:
                    run(("error", sensor, t_ns, job.error))
                    return
                dets = job.detections
            counts[sensor] = counts.get(sensor, 0) + len(dets)
            buffer.put(sensor, t_ns, dets, every=every)
            first_frame.setdefault(sensor, n_ticks)
            if progress is not None:
                progress(min(1.0, (t_ns - t_first) / span))

        def emit(*ev: Any) -> None:
            if pending or (ev[0] == "put" and isinstance(ev[4], CameraJob) and not ev[4].done):
                pending.append(ev)
            else:
                run(ev)

        def flush(block: bool) -> None:
            if pool is not None and pending:
                start("dispatch")
                pool.poll()
                stop("dispatch")
            while pending:
                head = pending[0]
                if head[0] == "put" and isinstance(head[4], CameraJob) and not head[4].done:
                    if not block:
                        return
                    start("dispatch")
                    pool.wait(head[4])  # type: ignore[union-attr]
                    stop("dispatch")
                run(pending.popleft())

        if laser is not None and p.prime_lasers:
            laser.prime(_every_nth_scan(rec.messages(laser_topics, time_source=time_source, start_ns=start_ns,
                                                     stop_ns=stop_ns), p.laser_every))
        try:
            # in time order, a message stamped far ahead (a bad stamp) dropped and counted, as the people pipelines
            # read theirs: used as it came, one scan 100 s ahead made every later scan and frame look late (all
            # skipped: 0.71 -> 0.09 MOTA on a 20 s road)
            stream = iter(synchronize(rec.messages(topics, time_source=time_source, start_ns=start_ns,
                                                   stop_ns=stop_ns)))
            while True:
                start("read")  # reading and decoding, the frames and scans a branch skips included
                try:
                    msg = next(stream)
                except StopIteration:
                    break
                finally:
                    stop("read")
                if message_filter is not None:
                    msg = message_filter(msg)
                    if msg is None:
                        continue
                t = msg.t_ns
                if next_tick is None:
                    next_tick = first_t = t
                while t >= next_tick:
                    emit("tick", next_tick)
                    next_tick += round(frame_s * 1e9)
                last_t = t
                part = ""
                try:
                    if isinstance(msg, LaserScan) and laser is not None:
                        seen[msg.sensor] = seen.get(msg.sensor, -1) + 1
                        emit("note", msg.sensor, t)  # its period, skipped scans included
                        every = p.laser_every
                        if seen[msg.sensor] % p.laser_every:
                            continue
                        part = "laser_branch"
                        start(part)
                        dets: Any = laser(msg)
                    elif isinstance(msg, Image) and msg.sensor in cam_by_sensor and msg.encoding != "mono16":
                        seen[msg.sensor] = seen.get(msg.sensor, -1) + 1
                        emit("note", msg.sensor, t)
                        every = p.camera_every
                        if seen[msg.sensor] % p.camera_every:
                            continue
                        if pool is not None:
                            part = "dispatch"
                            start(part)
                            dets = pool.submit(msg.sensor, msg)
                        else:
                            part = "camera_branch"
                            start(part)
                            dets = cam_by_sensor[msg.sensor](msg)
                    else:
                        continue
                    stop(part)
                except (ValueError, FloatingPointError) as err:  # bad data in one message: skip it, keep going
                    if part in clock:
                        stop(part)
                    emit("error", msg.sensor, t, err)
                    continue
                emit("put", msg.sensor, t, every, dets)
                flush(block=False)
            flush(block=True)
        finally:
            if pool is not None:
                pool.close()
                worker_cpu = max(pool.total_cpu_s, pool.cpu_s)  # the whole workers (their frames if unknown)
        if scene is not None:
            scene_events = scene.events  # ended ones with their end, open ones with t_end_ns None
        for s, k in first_frame.items():
            due = n_ticks - k  # the fusion instants after the sensor's first frame
            if due >= 10 and fused.get(s, 0) < 0.9 * due:
                log.warning("%s: its detections took part in %d of the %d fusion instants after its first frame "
                            "(its frames were older than %.3f s at the others: gaps or an outage)", s,
                            fused.get(s, 0), due, buffer.age_limit_s(s))
    duration = (last_t - first_t) / 1e9 if last_t is not None and first_t is not None else 0.0
    return TrafficResult(states, tracker_events, scene_events, sensors, n_ticks, duration, timings, counts, errors,
                         first_t or 0, cpu, fused, elapsed_s=time.perf_counter() - wall_start,
                         total_cpu_s=time.process_time() - cpu_start + worker_cpu, workers=n_workers)
