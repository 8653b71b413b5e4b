"""Run a scenario: move the agents, render every sensor on its own clock, write one recording.

Output (``simulate(scenario, out)``): ``out/`` is an ordinary rosbag2 MCAP recording readable by
:class:`fusiontrack.io.Recording` (and by ROS tools), with

* ``/<laser>/scan`` LaserScan, ``/<camera>/image`` Image, ``/<camera>/camera_info`` CameraInfo
  (the *believed* calibration), ``/<camera>/depth`` DepthImage (RGB-D), ``/<camera>/labels``
  mono16 label images (agent id + 1 per pixel), ``/<phone>/imu`` Imu;
* ``/tf_static``: every sensor's true pose (``world -> <name>``) and its believed calibration
  (``world -> <name>_calibrated``; different for a camera with a yaw bias);
* ``/ground_truth``: every agent at ``ground_truth_hz`` (ids, classes, positions, velocities and
  attributes ``feet_m`` (n, 2, 2), ``heading_rad``, ``size_m`` (n, 3), ``group_id``,
  ``gait_phase_rad``, ``situation`` (codes of :data:`SITUATION_CODES`));
* ``/ground_truth/<camera>``: at each image's stamp, the agents' boxes in that image (``box_px``
  (n, 4)) and ``visibility`` (n,);
* ``/ground_truth/steps``: heel strikes (one GroundTruth per step, attribute ``foot``).

and ``out/ground_truth/`` holds the same truth as CSV (agents, per-camera boxes, steps, incidents,
situation events) plus ``incidents.jsonl``, ``world.json`` (area bounds, walls, pillars, boxes, roads) and
``laser_hits_<laser>.npz`` (per written scan and beam, the id of the agent the beam hit: the measurement-level
truth of :mod:`fusiontrack.sim.situations`).

Sensor messages carry header stamps on the sensor's clock (true time + clock offset + jitter) and
are logged at true time + latency, so clock correction and reordering are exercised exactly as
with real recordings. Ground truth is stamped with true time.
"""

from __future__ import annotations

import csv
import json
import logging
import time
import zlib
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..geometry import make_transform, static_transform, yaw_to_matrix
from ..io.tracks import write_jsonl
from ..io.writer import RecordingWriter
from ..types import Event, GroundTruth, Image, Situation, Transform
from . import plans as plan_generators
from . import worlds
from .agents import Population
from .camera import CameraSim
from .imu import PhoneImuSim
from .laser import LaserSim
from .model import KIND_NAMES, AgentSnapshot, Timing
from .scenario import Scenario, call_with_params
from .situations import label_situations, situation_events

log = logging.getLogger(__name__)

T0_NS = 1_700_000_000 * 1_000_000_000
"""Simulated time 0 on the recording's clock (a fixed epoch, so a seed always gives the same file)."""

SITUATION_CODES = {s: i for i, s in enumerate(Situation)}
"""Ground-truth ``situation`` attribute code of each :class:`fusiontrack.types.Situation`."""

WORLD_BUILDERS: dict[str, Callable[..., Any]] = {"room": worlds.room, "corridor": worlds.corridor_loop,
                                                 "road": worlds.road}
PLAN_GENERATORS: dict[str, Callable[..., Any]] = {
    "crossing": plan_generators.crossing_plans,
    "groups": plan_generators.groups_plans,
    "crowd": plan_generators.crowd_plans,
    "corridor": plan_generators.corridor_plans,
    "road": plan_generators.road_plans,
    "wearable": plan_generators.wearable_plans,
}


def _rng(seed: int, name: str) -> np.random.Generator:
    """An independent stream per named part, stable when other parts are added or removed."""
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32(name.encode())]))


@dataclass(frozen=True, slots=True)
class Capture:
    """One tick of a sensor: true capture time, header stamp, log (arrival) time, and whether it is lost."""

    t_ns: int
    stamp_ns: int
    log_ns: int
    lost: bool = False


def schedule(timing: Timing, duration_s: float, latency_s: float, rng: np.random.Generator) -> list[Capture]:
    """Every tick of a sensor over ``[0, duration_s)`` with its clock's stamps; dropped ticks and ticks in an
    outage are marked ``lost`` (the IMU still integrates through them; nothing is written)."""
    period = 1.0 / timing.rate_hz
    t = rng.uniform(0.0, period) + np.arange(int(np.ceil(duration_s * timing.rate_hz)) + 1) * period
    t = t[t < duration_s]
    lost = rng.random(t.size) < timing.drop_probability
    for a, b in timing.outages_s:
        lost |= (t >= a) & (t < b)
    jitter = rng.normal(0.0, timing.jitter_s, t.size) if timing.jitter_s else 0.0
    t_ns = T0_NS + np.round(t * 1e9).astype(np.int64)
    stamp_ns = T0_NS + np.round((t + timing.clock_offset_s + jitter) * 1e9).astype(np.int64)
    log_ns = t_ns + round(latency_s * 1e9)
    return [Capture(int(a), int(b), int(c), bool(d)) for a, b, c, d in zip(t_ns, stamp_ns, log_ns, lost, strict=True)]


def _laser2world(spec: Any) -> np.ndarray:
    return make_transform(yaw_to_matrix(spec.yaw_rad), [spec.x_m, spec.y_m, spec.height_m])


@dataclass
class SimulationResult:
    """What a run wrote and what it cost."""

    path: Path
    duration_s: float
    messages: dict[str, int] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    n_agents: int = 0
    mean_present: float = 0.0
    step_events: int = 0
    incidents: int = 0
    situation_counts: dict[str, int] = field(default_factory=dict)


class Simulation:
    """A scenario made runnable: world, plans, agents and sensors, all seeded from the scenario's seed."""

    def __init__(self, scenario: Scenario) -> None:
        cfg = scenario.config
        self.scenario = scenario
        self.duration_s = cfg.scenario.duration_s
        seed = cfg.scenario.seed
        src = scenario.source
        world_params = dict(cfg.world)
        setting = world_params.pop("setting", "room")
        if not isinstance(setting, str) or setting not in WORLD_BUILDERS:
            raise ConfigError(f"{src}: world.setting {setting!r} is not one of {', '.join(WORLD_BUILDERS)}")
        self.world = call_with_params(WORLD_BUILDERS[setting], world_params, "world", src,
                                      rng=_rng(seed, "world"))
        agent_params = dict(cfg.agents)
        plan = agent_params.pop("plan", "crossing")
        if not isinstance(plan, str) or plan not in PLAN_GENERATORS:
            raise ConfigError(f"{src}: agents.plan {plan!r} is not one of {', '.join(PLAN_GENERATORS)}")
        peds, vehicles = call_with_params(PLAN_GENERATORS[plan], agent_params, "agents", src, world=self.world,
                                          duration_s=self.duration_s, rng=_rng(seed, "plans"))
        self.pedestrian_plans, self.vehicle_plans = list(peds), list(vehicles)
        self.population = Population(self.world, self.pedestrian_plans, self.vehicle_plans, _rng(seed, "agents"),
                                     dt_s=min(1.0 / cfg.scenario.step_hz, 0.02), t0_ns=T0_NS)
        carriers = {p.phone: p.agent_id for p in self.pedestrian_plans if p.phone}
        self.lasers = [LaserSim(c.spec(), self.world) for c in cfg.lasers]
        self.cameras = [CameraSim(c.spec(), self.world, _rng(seed, "render:" + c.name)) for c in cfg.cameras]
        self.phones = []
        for phone in cfg.phones:
            if phone.name not in carriers:
                raise ConfigError(f"{src}: phone {phone.name!r} is carried by nobody; the agents plan gives "
                                  f"phones {sorted(carriers) or 'to nobody'}")
            self.phones.append(PhoneImuSim(phone.spec(carriers[phone.name])))
        self.latency_s = {c.name: c.latency_ms / 1e3 for group in (cfg.lasers, cfg.cameras, cfg.phones) for c in group}
        self.seed = seed

    def sensor_transforms(self) -> list[Transform]:
        """tf_static: the true pose of every sensor and the calibration the user believes it has."""
        out = []
        for laser in self.lasers:
            T = _laser2world(laser.spec)
            out += [static_transform(T0_NS, "world", laser.spec.name, T),
                    static_transform(T0_NS, "world", laser.spec.name + "_calibrated", T)]
        for cam in self.cameras:
            out += [static_transform(T0_NS, "world", cam.spec.name, cam.true_camera.cam2world),
                    static_transform(T0_NS, "world", cam.spec.name + "_calibrated", cam.calibrated_camera.cam2world)]
        return out

    def run(self, output: str | Path, progress: Callable[[float], None] | None = None) -> SimulationResult:
        """Simulate the whole scenario into a new recording folder ``output``."""
        output = Path(output)
        cfg = self.scenario.config
        gt_timing = Timing(cfg.scenario.ground_truth_hz)
        captures: dict[str, list[Capture]] = {}
        sensors: dict[str, Any] = {}
        for sim in [*self.lasers, *self.cameras, *self.phones]:
            name = sim.spec.name
            captures[name] = schedule(sim.spec.timing, self.duration_s, self.latency_s[name],
                                      _rng(self.seed, "clock:" + name))
            sensors[name] = sim
        gt_times = np.arange(0.0, self.duration_s, 1.0 / gt_timing.rate_hz)
        events: dict[int, list[tuple[str, Capture]]] = defaultdict(list)
        for name, caps in captures.items():
            for cap in caps:
                events[cap.t_ns].append((name, cap))
        gt_ns = [T0_NS + round(t * 1e9) for t in gt_times]
        for t in gt_ns:
            events.setdefault(t, [])
        gt_set = set(gt_ns)
        noise_rng = {name: _rng(self.seed, "noise:" + name) for name in sensors}
        result = SimulationResult(output, self.duration_s)
        seconds: dict[str, float] = defaultdict(float)
        counts: dict[str, int] = defaultdict(int)
        gt_frames: list[AgentSnapshot] = []
        camera_truth: dict[str, list[tuple[int, int, AgentSnapshot, Any]]] = defaultdict(list)
        gt_dir = output / "ground_truth"
        self._laser_hits: dict[str, list[tuple[int, int, np.ndarray]]] = defaultdict(list)
        with RecordingWriter(output) as writer:
            for tf in self.sensor_transforms():
                writer.write(tf)
            for t_ns in sorted(events):
                t_s = (t_ns - T0_NS) / 1e9
                t0 = time.perf_counter()
                self.population.advance(t_s)
                snap = self.population.snapshot(t_ns)
                seconds["agents"] += time.perf_counter() - t0
                if t_ns in gt_set:
                    gt_frames.append(snap)
                for name, cap in events[t_ns]:
                    t0 = time.perf_counter()
                    if self._capture(writer, sensors[name], cap, snap, noise_rng[name], camera_truth):
                        counts[name] += 1
                    seconds[name] += time.perf_counter() - t0
                if progress is not None:
                    progress(t_s)
            t0 = time.perf_counter()
            situations = self._write_truth(writer, gt_frames, camera_truth)
            seconds["ground truth"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        self._write_csv(gt_dir, gt_frames, situations, camera_truth)
        self._write_laser_hits(gt_dir)
        seconds["ground truth"] += time.perf_counter() - t0
        result.messages = dict(counts)
        result.dropped = {name: sum(c.lost for c in caps) for name, caps in captures.items()}
        result.seconds = dict(seconds)
        result.n_agents = len(self.pedestrian_plans) + len(self.vehicle_plans)
        result.mean_present = float(np.mean([len(f) for f in gt_frames])) if gt_frames else 0.0
        result.step_events = len(self.population.step_events)
        result.incidents = len(self.population.incidents)
        result.situation_counts = {s.value: int(sum(int(np.sum(lab == s.value)) for lab in situations))
                                   for s in Situation}
        return result

    # ---------------------------------------------------------------------------------------------
    def _capture(self, writer: RecordingWriter, sim: Any, cap: Capture, snap: AgentSnapshot,
                 rng: np.random.Generator, camera_truth: dict[str, list]) -> bool:
        """Produce one sensor tick; True when a message was written."""
        name = sim.spec.name
        if isinstance(sim, PhoneImuSim):  # integrates every tick, written or not
            sample = sim.sample(cap.t_ns, snap, rng, stamp_ns=cap.stamp_ns)
            if sample is None or cap.lost:
                return False
            writer.write(sample, log_t_ns=cap.log_ns)
            return True
        if cap.lost:
            return False
        if isinstance(sim, LaserSim):
            scan, hit_ids = sim.scan_and_hits(cap.t_ns, snap, rng, stamp_ns=cap.stamp_ns)
            writer.write(scan, log_t_ns=cap.log_ns)
            small = hit_ids.size == 0 or hit_ids.max() <= np.iinfo(np.int16).max  # 2 bytes per beam while it runs
            self._laser_hits[name].append((cap.t_ns, cap.stamp_ns, hit_ids.astype(np.int16 if small else np.int32)))
        elif isinstance(sim, CameraSim):
            out = sim.render((cap.t_ns - T0_NS) / 1e9, snap, rng)
            writer.write(sim.camera_info(cap.stamp_ns), log_t_ns=cap.log_ns)
            writer.write(Image(cap.stamp_ns, name, name, out.bgr, "bgr8"), log_t_ns=cap.log_ns)
            if out.depth_m is not None:
                from ..types import DepthImage

                writer.write(DepthImage(cap.stamp_ns, name, name, out.depth_m), log_t_ns=cap.log_ns)
            if out.labels is not None and sim.spec.labels:
                # labels are mostly zeros: lossless PNG makes them ~50x smaller
                writer.write(Image(cap.stamp_ns, name, name, out.labels, "mono16"), topic=f"/{name}/labels",
                             log_t_ns=cap.log_ns, image_format="png")
            # keep only the small truth (boxes, visibility) for the end of the run, never the images
            camera_truth[name].append((cap.t_ns, cap.stamp_ns, snap, out.boxes_px, out.visibility))
        return True

    def _write_truth(self, writer: RecordingWriter, frames: list[AgentSnapshot],
                     camera_truth: dict[str, list]) -> list[np.ndarray]:
        situations = label_situations(frames, self.world.bounds_m)
        for snap, labels in zip(frames, situations, strict=True):
            writer.write(self._gt_record(snap, "ground_truth", labels))
        for name, items in camera_truth.items():
            for t_ns, stamp_ns, snap, boxes_px, visibility in items:
                rec = GroundTruth(stamp_ns, "ground_truth/" + name, "world", snap.ids, snap.position_m,
                                  snap.velocity_mps, tuple(KIND_NAMES[k] for k in snap.kinds),
                                  {"box_px": boxes_px, "visibility": visibility,
                                   "t_true_ns": np.full(len(snap), t_ns, np.int64)})
                writer.write(rec, topic=f"/ground_truth/{name}", log_t_ns=t_ns)
        for ev in self.population.step_events:
            writer.write(GroundTruth(ev.t_ns, "ground_truth/steps", "world", [ev.agent_id], [ev.position_m],
                                     attributes={"foot": np.array([ev.foot], np.int8)}), topic="/ground_truth/steps")
        return situations

    @staticmethod
    def _gt_record(snap: AgentSnapshot, sensor: str, situations: np.ndarray) -> GroundTruth:
        codes = np.array([SITUATION_CODES[Situation(s)] for s in situations], np.int8)
        return GroundTruth(snap.t_ns, sensor, "world", snap.ids, snap.position_m, snap.velocity_mps,
                           tuple(KIND_NAMES[k] for k in snap.kinds),
                           {"feet_m": snap.feet_m, "heading_rad": snap.heading_rad, "size_m": snap.size_m,
                            "group_id": snap.group_ids, "gait_phase_rad": snap.gait_phase_rad, "situation": codes})

    def _write_laser_hits(self, folder: Path) -> None:
        """``laser_hits_<laser>.npz`` per scanner: which agent each beam of each written scan hit.

        Arrays ``t_ns`` (n,) true scan time, ``stamp_ns`` (n,) header stamp of the ``/<laser>/scan`` message,
        ``hit_ids`` (n, n_beams) agent id of the noise-free cast, ``-1`` = static world or no return (int16, or
        int32 when an id does not fit). Read with :func:`fusiontrack.sim.situations.load_laser_hits`.
        """
        folder.mkdir(parents=True, exist_ok=True)
        for laser in self.lasers:
            rows = self._laser_hits.get(laser.spec.name, [])
            hits = (np.stack([r[2] for r in rows]) if rows else np.zeros((0, laser.n_beams), np.int64))
            dtype = np.int16 if hits.size == 0 or hits.max() <= np.iinfo(np.int16).max else np.int32
            np.savez_compressed(folder / f"laser_hits_{laser.spec.name}.npz",
                                t_ns=np.array([r[0] for r in rows], np.int64),
                                stamp_ns=np.array([r[1] for r in rows], np.int64), hit_ids=hits.astype(dtype))

    def _write_csv(self, folder: Path, frames: list[AgentSnapshot], situations: list[np.ndarray],
                   camera_truth: dict[str, list]) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        w = self.world
        (folder / "world.json").write_text(json.dumps({
            "scenario": self.scenario.name, "seed": self.seed, "duration_s": self.duration_s,
            "bounds_m": w.bounds_m.tolist(), "walls": w.walls.tolist(), "pillars": w.pillars.tolist(),
            "boxes": w.boxes.tolist(), "roads": w.roads.tolist(), "lane_width_m": w.lane_width_m,
            "t0_ns": T0_NS}, indent=1))

        def t(ns: int) -> str:
            return f"{(ns - T0_NS) / 1e9:.6f}"

        with open(folder / "agents.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["t", "t_ns", "id", "class", "x", "y", "vx", "vy", "heading", "left_x", "left_y", "right_x",
                        "right_y", "length", "width", "height", "group", "gait_phase", "situation"])
            for snap, labels in zip(frames, situations, strict=True):
                for i in range(len(snap)):
                    w.writerow([t(snap.t_ns), snap.t_ns, int(snap.ids[i]), KIND_NAMES[snap.kinds[i]],
                                *(f"{v:.4f}" for v in (*snap.position_m[i], *snap.velocity_mps[i], snap.heading_rad[i],
                                                       *snap.feet_m[i].ravel(), *snap.size_m[i])),
                                int(snap.group_ids[i]), f"{snap.gait_phase_rad[i]:.4f}", labels[i]])
        for name, items in camera_truth.items():
            with open(folder / f"camera_{name}.csv", "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["frame", "t", "stamp_ns", "id", "class", "u_min", "v_min", "u_max", "v_max", "visibility"])
                for frame, (t_ns, stamp_ns, snap, boxes_px, visibility) in enumerate(items, start=1):
                    for i in range(len(snap)):
                        w.writerow([frame, t(t_ns), stamp_ns, int(snap.ids[i]), KIND_NAMES[snap.kinds[i]],
                                    *(f"{v:.2f}" for v in boxes_px[i]), f"{visibility[i]:.3f}"])
        with open(folder / "steps.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["t", "t_ns", "id", "foot", "x", "y"])
            for ev in self.population.step_events:
                w.writerow([t(ev.t_ns), ev.t_ns, ev.agent_id, "left" if ev.foot == 0 else "right",
                            f"{ev.position_m[0]:.4f}", f"{ev.position_m[1]:.4f}"])
        incidents = list(self.population.incidents)
        with open(folder / "incidents.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["kind", "t_start", "t_end", "ids"])
            for inc in incidents:
                w.writerow([inc.kind, t(inc.t_start_ns), t(inc.t_end_ns), "|".join(map(str, inc.agent_ids))])
        write_jsonl(folder / "incidents.jsonl",
                    [Event(inc.t_start_ns, "ground_truth", inc.kind, inc.t_end_ns, track_ids=inc.agent_ids)
                     for inc in incidents])
        events = situation_events(frames, self.world.bounds_m)
        with open(folder / "situation_events.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["kind", "t", "t_ns", "ids"])
            for ev in events:
                w.writerow([ev.kind, t(ev.t_ns), ev.t_ns, "|".join(map(str, ev.track_ids))])


def simulate(
    scenario: Scenario, output: str | Path, progress: Callable[[float], None] | None = None
) -> SimulationResult:
    """Build and run ``scenario`` into the new recording folder ``output``."""
    return Simulation(scenario).run(output, progress)
