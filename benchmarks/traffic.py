"""Seed 003 on the simulated `road`: camera-only, laser-only, fusion and fusion + particle filter, with injected
occlusions and a camera illumination drop; incidents against the simulator's labels; speed against real time.

Per seed: simulate `road` (``--seconds``, the illumination drop of camera_0 moved to a third of the run), then run
the traffic pipeline once with every variant. Injected occlusions: at ``--occlusions`` instants a moving vehicle
in the monitored stretch vanishes from every sensor for 1.0-1.9 s (camera pixels under its label replaced by the
camera's background plate, laser beams ending on its footprint by the laser's background ranges), so the trackers
see nothing of it; its identity is kept when the track nearest it 0.3 s before the occlusion is the track nearest
it 0.7 s after. Metrics: vehicles within 2 m, truth sampled at the tracker's instants (``eval/vehicles.py``), in
the monitored stretch (``AREA``).

    .venv/bin/python benchmarks/traffic.py [--seeds 0 1 2] [--seconds 60] [--keep DIR] [--camera-every K]
        [--laser-every K] [--processing-scale S] [--prime-lasers]
    .venv/bin/python benchmarks/traffic.py --seeds 0 1 2 --incidents-from DIR

Incidents: the pipeline runs the D8 rules online on the fusion + PF tracks; the learned behaviour model
(``scene/learned.py``, the shipped forest) is then run over the same fusion + PF states through the same interface
as ``fusiontrack events --learned``. Both are scored against the simulator's labelled incidents
(``eval/events.py``): onset latency = event start - incident start, alarm latency = the event's ``alarm_t_ns`` -
incident start. With ``--keep DIR`` the fusion + PF states are kept as ``DIR/tracks_<seed>.jsonl`` (and the
online rule events as ``events_<seed>.jsonl``); ``--incidents-from DIR`` re-scores such a folder (both engines on
the kept tracks, truth from ``DIR/road_<seed>/ground_truth``) without simulating or tracking again.

Speed: the pipeline as a user runs it (fusion + PF with the scene rules, the same faults) twice more, serially
(``workers = 0``) and with its camera workers (``TrafficParams.workers``, default one per camera within the cores
minus one), one after the other; x real time by the wall clock (from opening the recording to the last track) and
by CPU time (all processes). On a shared machine only the CPU time is stable; the wall clock is what a user waits
for on a quiet one.

Targets (issue 8): fusion + PF best on MOTA, every injected occlusion < 2 s kept; incidents P/R >= 0.9, median
latency <= 2 s; >= 5x real time with 2 cameras and 2 lasers.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from fusiontrack.eval.events import read_agents_csv, read_incidents, score_events
from fusiontrack.eval.vehicles import evaluate_vehicles, identity_kept
from fusiontrack.fusion.traffic import VARIANTS, TrafficParams, TrafficResult, track_traffic
from fusiontrack.geometry import scan_to_points, transform_points
from fusiontrack.io.recording import Recording
from fusiontrack.io.tracks import read_jsonl, write_jsonl
from fusiontrack.laser.vehicles import laser_poses_for_recording
from fusiontrack.scene import detect_events, detect_events_learned, road_geometry_from_world
from fusiontrack.sim.model import rect_corners
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.types import Event, GroundTruth, Image, LaserScan, records_equal

console = Console(width=170)
DURATIONS_S = (1.0, 1.5, 1.9, 1.2, 1.7)
AREA = [(-45, -9), (45, -9), (45, 9), (-45, 9)]
"""Scored area: the road between the camera poles (x = +-40 m) plus 5 m, verges included. Beyond it the lasers see
cars by a few grazing returns and the cameras at 80+ m; vehicles there are not scored (nor are tracks)."""


def _plates(rec: Recording, t_end_ns: int) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Per camera the median of frames, per laser the median of ranges, over the start of the run."""
    frames: dict[str, list[np.ndarray]] = {}
    scans: dict[str, list[np.ndarray]] = {}
    for m in rec.messages(stop_ns=t_end_ns):
        if isinstance(m, Image) and m.encoding != "mono16":
            if len(frames.setdefault(m.sensor, [])) < 40 and m.t_ns // 10_000_000 % 7 == 0:
                frames[m.sensor].append(m.pixels)
        elif isinstance(m, LaserScan):
            scans.setdefault(m.sensor, []).append(np.asarray(m.ranges_m, np.float64))
    return ({s: np.median(np.stack(f), axis=0).astype(np.uint8) for s, f in frames.items()},
            {s: np.nanmedian(np.stack(r[::5]), axis=0) for s, r in scans.items()})


def _pick_occlusions(gt: list[GroundTruth], n: int, duration_s: float) -> list[dict[str, Any]]:
    """Moving vehicles inside the monitored stretch, at instants spread over the run."""
    t = np.array([g.t_ns for g in gt])
    out: list[dict[str, Any]] = []
    starts = np.linspace(0.2, 0.85, n) * duration_s
    for k, s in enumerate(starts):
        i = int(np.searchsorted(t, t[0] + s * 1e9))
        d = DURATIONS_S[k % len(DURATIONS_S)]
        j_end = int(np.searchsorted(t, t[i] + (d + 0.7) * 1e9))
        if j_end >= len(gt):
            continue
        g, g_end = gt[i], gt[j_end]
        speed = np.linalg.norm(g.velocities_mps, axis=1)
        end_x = {int(i): abs(x) for i, x in zip(g_end.ids, g_end.positions_m[:, 0], strict=True)}
        ok = [a for a in range(len(g)) if g.classes[a] == "car" and speed[a] > 3 and abs(g.positions_m[a, 0]) < 25
              and end_x.get(int(g.ids[a]), 99.0) < 35 and all(g.ids[a] != o["id"] for o in out)]
        if ok:
            out.append({"id": int(g.ids[ok[0]]), "t0": int(t[i]), "t1": int(t[i] + d * 1e9), "d": d})
    return out


class Occluder:
    """message_filter for the pipeline: hides the chosen vehicles from every sensor during their windows."""

    def __init__(self, rec: Recording, gt: list[GroundTruth], occl: list[dict[str, Any]],
                 plates: tuple[dict[str, np.ndarray], dict[str, np.ndarray]]) -> None:
        self.occl, self.gt = occl, gt
        self.gt_t = np.array([g.t_ns for g in gt])
        self.cam_plate, self.laser_plate = plates
        self.poses = laser_poses_for_recording(rec, [t for t, i in rec.topics().items()
                                                     if i.msgtype == "sensor_msgs/msg/LaserScan"])
        self.labels: dict[tuple[str, int], np.ndarray] = {}
        label_topics = [t for t in rec.topics() if t.endswith("/labels")]
        for o in occl:
            for m in rec.messages(label_topics, start_ns=o["t0"] - int(2e8), stop_ns=o["t1"] + int(2e8)):
                if isinstance(m, Image) and m.encoding == "mono16":
                    self.labels[(m.sensor, m.t_ns)] = m.pixels
        self.hidden = 0
        self.illumination: dict[str, list[tuple[int, float]]] = {}

    def gain(self, sensor: str, t_ns: int) -> float:
        """The camera's illumination gain in force at ``t_ns`` relative to the plate's (taken at gain 1)."""
        g = 1.0
        for t0, value in self.illumination.get(sensor, []):
            if t_ns >= t0:
                g = value
        return g

    def _active(self, t_ns: int) -> list[dict[str, Any]]:
        return [o for o in self.occl if o["t0"] <= t_ns <= o["t1"]]

    def __call__(self, msg: Any) -> Any:
        act = self._active(msg.t_ns)
        if not act:
            return msg
        if isinstance(msg, Image) and msg.sensor in self.cam_plate:
            lab = self.labels.get((msg.sensor, msg.t_ns))
            if lab is None:
                return msg
            mask = np.isin(lab, [o["id"] + 1 for o in act])
            if not mask.any():
                return msg
            data = msg.pixels.copy()
            gain = self.gain(msg.sensor, msg.t_ns)  # the plate was taken before the light changed
            data[mask] = np.clip(self.cam_plate[msg.sensor][mask] * gain, 0, 255).astype(np.uint8)
            self.hidden += 1
            return replace(msg, pixels=data)
        if isinstance(msg, LaserScan) and msg.sensor in self.poses:
            g = self.gt[int(np.argmin(np.abs(self.gt_t - msg.t_ns)))]
            ranges = np.asarray(msg.ranges_m, np.float64).copy()
            pts = transform_points(self.poses[msg.sensor], np.column_stack([scan_to_points(msg),
                                                                             np.zeros(ranges.size)]))[:, :2]
            hit = np.zeros(ranges.size, bool)
            for o in act:
                a = np.flatnonzero(g.ids == o["id"])
                if not a.size:
                    continue
                a = int(a[0])
                size = g.attributes["size_m"][a]
                corners = rect_corners(g.positions_m[a:a + 1], size[0:1] + 0.6, size[1:2] + 0.6,
                                       g.attributes["heading_rad"][a:a + 1])[0]
                from matplotlib.path import Path as MplPath

                hit |= MplPath(corners).contains_points(np.nan_to_num(pts, nan=1e9))
            if not hit.any():
                return msg
            ranges[hit] = self.laser_plate[msg.sensor][hit]
            self.hidden += 1
            return replace(msg, ranges_m=ranges.astype(np.float32))
        return msg


def run_seed(seed: int, seconds: float, folder: Path, params: TrafficParams | None = None,
             keep_tracks: bool = False) -> dict[str, Any]:
    scen = load_scenario("road").with_overrides(seconds=seconds, seed=seed, settings={
        "cameras.0.illumination": [[seconds / 3, 0.55]]})
    rec_dir = folder / f"road_{seed}"
    if rec_dir.exists():
        shutil.rmtree(rec_dir)
    simulate(scen, rec_dir)
    with Recording(rec_dir) as rec:
        gt = [g for g in rec.messages(["/ground_truth"]) if isinstance(g, GroundTruth)]
        plates = _plates(rec, rec.start_ns + int(20e9))
        occl = _pick_occlusions(gt, 5, seconds)
        occluders = [Occluder(rec, gt, occl, plates) for _ in range(3)]  # the variants run, the speed runs
        for o in occluders:
            o.illumination["camera_0"] = [(gt[0].t_ns + int(seconds / 3 * 1e9), 0.55)]
        occluder = occluders[0]
    p = params or TrafficParams()
    res = track_traffic(rec_dir, params=p, variants=tuple(VARIANTS), message_filter=occluder)
    area = AREA
    out: dict[str, Any] = {"seed": seed, "metrics": {}, "kept": {}, "occlusions": occl, "hidden": occluder.hidden}
    for v, states in res.states.items():
        out["metrics"][v] = evaluate_vehicles(gt, states, area=area, rate_hz=p.rate_hz)
        kept = []
        gt_t = np.array([g.t_ns for g in gt])
        for o in occl:
            gb = gt[int(np.argmin(np.abs(gt_t - (o["t0"] - 3e8))))]
            ga = gt[int(np.argmin(np.abs(gt_t - (o["t1"] + 7e8))))]
            xb, xa = gb.positions_m[gb.ids == o["id"]], ga.positions_m[ga.ids == o["id"]]
            kept.append(identity_kept(states, xb[0], gb.t_ns, xa[0], ga.t_ns) if len(xb) and len(xa) else None)
        out["kept"][v] = kept
    agents = read_agents_csv(rec_dir)
    out["incidents"] = score_events(read_incidents(rec_dir), res.scene_events, agents)
    tic = time.process_time()
    learned = detect_events_learned(res.states["fusion_pf"], road_geometry_from_world(
        rec_dir / "ground_truth" / "world.json"))
    out["learned_cpu"] = time.process_time() - tic
    out["incidents_learned"] = score_events(read_incidents(rec_dir), learned, agents)
    if keep_tracks:
        write_jsonl(folder / f"tracks_{seed}.jsonl", res.states["fusion_pf"])
        write_jsonl(folder / f"events_{seed}.jsonl", res.scene_events)
    out["duration"] = res.duration_s
    # speed: the pipeline as a user runs it (fusion + PF and the scene rules only), serially and with the camera
    # workers, one after the other in this process on the same recording and faults
    speed: dict[str, TrafficResult] = {}
    for key, workers, filt in (("serial", 0, occluders[1]), ("workers", p.workers, occluders[2])):
        speed[key] = track_traffic(rec_dir, params=replace(p, workers=workers), variants=("fusion_pf",),
                                   message_filter=filt)
    a, b = speed["serial"], speed["workers"]
    out["speed_same"] = (len(a.states["fusion_pf"]) == len(b.states["fusion_pf"]) and all(
        records_equal(x, y) for x, y in zip(a.states["fusion_pf"], b.states["fusion_pf"], strict=True)))
    out["speed"] = speed
    return out


def incidents_from(folder: Path, seed: int) -> dict[str, Any]:
    """Both engines on the kept fusion + PF states of one seed (``--incidents-from``)."""
    gt = folder / f"road_{seed}" / "ground_truth"
    states = [s for s in read_jsonl(folder / f"tracks_{seed}.jsonl") if not isinstance(s, Event)]
    geo = road_geometry_from_world(gt / "world.json")
    incidents, agents = read_incidents(gt / "incidents.jsonl"), read_agents_csv(gt / "agents.csv")
    tic = time.process_time()
    learned = detect_events_learned(states, geo)
    cpu = time.process_time() - tic
    return {"seed": seed, "incidents": score_events(incidents, detect_events(states, geo), agents),
            "incidents_learned": score_events(incidents, learned, agents), "learned_cpu": cpu,
            "duration": (max(s.t_ns for s in states) - min(s.t_ns for s in states)) * 1e-9}


def incident_table(runs: list[dict[str, Any]], title: str) -> Table:
    """Per engine (D8 rules, learned model) and kind, pooled over the runs."""
    t2 = Table(title=title)
    for c in ("engine", "kind", "true", "detections", "hits", "false alarms", "precision", "recall",
              "onset latency s (median)", "alarm latency s (median)", "alarm latency s (max)"):
        t2.add_column(c, justify="left" if c in ("engine", "kind") else "right")
    for engine, key in (("D8 rules", "incidents"), ("learned", "incidents_learned")):
        for k in runs[0][key]:
            sc = [r[key][k] for r in runs]
            true, det = sum(s.true for s in sc), sum(s.detections for s in sc)
            hit = sum(s.true_positives for s in sc)
            on = [x for s in sc for x in s.onset_latency_s]
            al = [x for s in sc for x in s.alarm_latency_s]
            t2.add_row(engine, k, str(true), str(det), str(hit), str(det - hit), f"{hit / det:.2f}" if det else "–",
                       f"{hit / true:.2f}" if true else "–", f"{np.median(on):.2f}" if on else "–",
                       f"{np.median(al):.2f}" if al else "–", f"{np.max(al):.2f}" if al else "–")
        t2.add_section()
    return t2


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--keep", type=Path, default=None,
                    help="keep the recordings (about 1.6 GB per seed and minute: mind the disk), tracks and events "
                         "in this folder")
    ap.add_argument("--camera-every", type=int, default=None, help="TrafficParams.camera_every (default: its own)")
    ap.add_argument("--laser-every", type=int, default=None, help="TrafficParams.laser_every (default: its own)")
    ap.add_argument("--processing-scale", type=int, default=None,
                    help="the cameras' VehicleDetectorParams.processing_scale (default: its own)")
    ap.add_argument("--prime-lasers", action="store_true",
                    help="TrafficParams.prime_lasers: learn the laser backgrounds from the first scans read ahead")
    ap.add_argument("--workers", type=int, default=None,
                    help="TrafficParams.workers for the speed run with camera workers (default: its own)")
    ap.add_argument("--incidents-from", type=Path, default=None,
                    help="only re-score the incidents of a --keep folder's tracks (rules and learned model)")
    args = ap.parse_args()
    if args.incidents_from is not None:
        kept = [incidents_from(args.incidents_from, s) for s in args.seeds]
        console.print(incident_table(kept, f"incidents on the kept fusion + PF tracks of {args.incidents_from} "
                                           f"(seeds {' '.join(map(str, args.seeds))}), against the simulator's "
                                           "labels, pooled"))
        console.print("learned model CPU time per recording second: " + ", ".join(
            f"seed {r['seed']} {1e3 * r['learned_cpu'] / r['duration']:.0f} ms" for r in kept))
        return
    params = TrafficParams()
    if args.camera_every is not None:
        params = replace(params, camera_every=args.camera_every)
    if args.laser_every is not None:
        params = replace(params, laser_every=args.laser_every)
    if args.processing_scale is not None:
        params = replace(params, camera={**params.camera, "processing_scale": args.processing_scale})
    if args.workers is not None:
        params = replace(params, workers=args.workers)
    if args.prime_lasers:
        params = replace(params, prime_lasers=True)
    tmp = None
    folder = args.keep
    if folder is None:
        tmp = tempfile.TemporaryDirectory(prefix="ft_traffic_")
        folder = Path(tmp.name)
    folder.mkdir(parents=True, exist_ok=True)
    runs = []
    for s in args.seeds:
        console.print(f"seed {s}: simulating {args.seconds:g} s of road and tracking ...")
        runs.append(run_seed(s, args.seconds, folder, params, keep_tracks=args.keep is not None))
        if args.keep is None:
            shutil.rmtree(folder / f"road_{s}", ignore_errors=True)
    t = Table(title=f"road, {len(runs)} seeds x {args.seconds:g} s: vehicles within 2 m; injected occlusions kept")
    for c in ("variant", "MOTA", "IDF1", "HOTA", "IDSW", "FP", "FN", "occlusions kept"):
        t.add_column(c, justify="left" if c == "variant" else "right")
    for v in VARIANTS:
        ms = [r["metrics"][v] for r in runs]
        kept = [k for r in runs for k in r["kept"][v] if k is not None]
        n_occ = sum(len(r["occlusions"]) for r in runs)
        t.add_row(v, *(f"{np.mean([getattr(m, a) for m in ms]):.3f}" for a in ("mota", "idf1", "hota")),
                  *(str(sum(getattr(m, a) for m in ms)) for a in ("id_switches", "fp", "fn")),
                  f"{sum(kept)}/{len(kept)} (of {n_occ})")
    console.print(t)
    console.print(incident_table(runs, "incidents on the fusion + PF tracks (D8 rules online; learned model on the "
                                       "same states) against the simulator's labels, pooled"))
    console.print("learned model CPU time per recording second: " + ", ".join(
        f"seed {r['seed']} {1e3 * r['learned_cpu'] / r['duration']:.0f} ms" for r in runs))
    t3 = Table(title="speed of the traffic pipeline (fusion + PF, scene rules; 2 cameras 640x480 @ 15 Hz, 2 lasers "
                     "361 beams @ 25 Hz): CPU ms per recording second by part (serial run), and x real time")
    parts = ("read", "laser_branch", "camera_branch", "fusion_pf", "scene")
    nw = runs[0]["speed"]["workers"].workers
    for c in ("seed", *parts, "serial: x real time (wall)", "serial: x real time (CPU)",
              f"{nw} camera worker(s): x real time (wall)", "... (CPU, all processes)", "same tracks"):
        t3.add_column(c, justify="right")
    for r in runs:
        ser, par = r["speed"]["serial"], r["speed"]["workers"]
        t3.add_row(str(r["seed"]), *(f"{1e3 * ser.cpu_s[q] / ser.duration_s:.0f}" for q in parts),
                   f"{ser.real_time_factor():.2f}x", f"{ser.cpu_real_time_factor():.2f}x",
                   f"{par.real_time_factor():.2f}x", f"{par.cpu_real_time_factor():.2f}x",
                   "yes" if r["speed_same"] else "NO")
    console.print(t3)
    console.print("x real time = recording seconds per second: by the wall clock from opening the recording to the "
                  "last track (what a user waits for; on a shared machine it also counts other processes), and by "
                  "CPU time (the main process and the camera workers together; whatever the cores). The serial and "
                  "the worker runs follow each other in this process; 'same tracks': their fusion + PF states are "
                  "equal record for record.")
    if tmp is not None:
        tmp.cleanup()


if __name__ == "__main__":
    main()
