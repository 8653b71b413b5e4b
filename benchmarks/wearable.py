"""Seed 002's second and third experiments (P002 Figs. 11-14, ALGORITHMS.md C14) on simulated scenes: visual-only
compressive tracking against the fused tracker of the ``wearable`` pipeline.

Scenes (built-in scenarios, ``--seeds`` each): ``wearable_crossing`` (two phone carriers walk towards each other,
meet, turn and walk back), ``wearable_occlusions`` (four carriers cross a lobby corner to corner through the
middle) and ``wearable_lights`` (two carriers walk laps; the lights go off for 3 s in every camera). Each is
simulated, then :func:`fusiontrack.fusion.track_wearable` runs on the recording: dead reckoning per phone, RGB-D
tracklets matched to the phones, TPS correction, and per (person, video camera) the compressive tracker checked by
the projected inertial position (C9-C12) with, beside it, a plain compressive tracker started from the same box
in the same frame (``VisualParams.baseline``): the visual-only column.

Truth: the carrier of each phone (the simulator's plans), the agents' boxes in every image
(``/ground_truth/<camera>``, ``box_px`` and ``visibility``) and the illumination schedule of the scenario.

* **on target**: share of the tracked frames in which the person's truth box is in the image and the tracker's
  box overlaps it with IoU >= 0.5 (and, looser, the box centre lies inside it);
* **ID switches**: changes of the identity a tracker's box covers (the agent whose truth box it overlaps most,
  at IoU >= 0.5) from one covered frame to the next covered one;
* **injected failures**: per (person, camera) every interval in which the person, in view, is hidden (visible
  fraction < 0.5 for at least 2 frames: another person or the image border in front) or the lights are off. A
  failure is *detected* when the fused tracker reports a failure between its start and 1 s after its end;
  *recovered* when the box is on target (IoU >= 0.5) on 3 consecutive frames within 1 s after its end (the
  recovery time is the first of them minus the end); a looser column asks for the box centre inside the truth
  box instead. An interval after which the track ends within 1 s is not judged. The issue's target: fused
  recovers every injected failure within 1 s.

Also per scene: ownership of the RGB-D tracklets against the truth, the trajectories' mean error before
(dead reckoning moved into the world by the first alignment only) and after the TPS correction, and the dead
reckoning speed in multiples of real time (``run_pdr`` on each phone's samples). Compressive tracking speed at
640x480 is measured by ``benchmarks/rgbd_compressive.py``; here the time per tracker step of the whole visual
side is reported (frames decoded, MOG2, fused and baseline trackers).

    .venv/bin/python benchmarks/wearable.py [--seeds 0 1 2] [--scenes wearable_crossing ...] [--keep DIR]
"""

from __future__ import annotations

import argparse
import csv
import logging
import shutil
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from fusiontrack.fusion.wearable import WearableParams, WearableResult, track_wearable
from fusiontrack.fusion.wearable_visual import VisualParams
from fusiontrack.inertial import load_imu, run_pdr
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import T0_NS, Simulation

SCENES = ("wearable_crossing", "wearable_occlusions", "wearable_lights")
HIDDEN = 0.5  # visible fraction below which a person is hidden (an injected failure)
IOU_OK = 0.5
RECOVER_S = 1.0
RUN_FRAMES = 3  # consecutive on-target frames that make a recovery


def iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise IoU of boxes ``(n, 4)`` and ``(n, 4)`` (or broadcast)."""
    iw = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    ih = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = iw * ih
    union = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1]) + (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(union - inter > 0, inter / (union - inter), 0.0)


@dataclass
class CameraTruth:
    """Truth boxes of one camera: per stamp, ids -> (box, visibility); image size."""

    boxes: dict[int, dict[int, tuple[np.ndarray, float]]]
    width: int
    height: int


def read_camera_truth(folder: Path, camera: str, width: int, height: int) -> CameraTruth:
    boxes: dict[int, dict[int, tuple[np.ndarray, float]]] = defaultdict(dict)
    with open(folder / "ground_truth" / f"camera_{camera}.csv", newline="") as f:
        for r in csv.DictReader(f):
            box = np.array([float(r[k]) for k in ("u_min", "v_min", "u_max", "v_max")])
            boxes[int(r["stamp_ns"])][int(r["id"])] = (box, float(r["visibility"]))
    return CameraTruth(dict(boxes), width, height)


def read_agents(folder: Path) -> dict[int, np.ndarray]:
    """Truth floor tracks: id -> (n, 3) rows ``t_ns, x, y``."""
    rows: dict[int, list] = defaultdict(list)
    with open(folder / "ground_truth" / "agents.csv", newline="") as f:
        for r in csv.DictReader(f):
            rows[int(r["id"])].append((int(r["t_ns"]), float(r["x"]), float(r["y"])))
    return {k: np.array(v, np.float64) for k, v in rows.items()}


@dataclass
class Metrics:
    frames: int = 0
    on_fused: int = 0
    on_base: int = 0
    centre_fused: int = 0
    centre_base: int = 0
    switches_fused: int = 0
    switches_base: int = 0
    episodes: int = 0
    lost_base: int = 0
    lost_fused: int = 0
    detected: int = 0
    recovered_fused: int = 0
    recovered_base: int = 0
    recovered_centre_fused: int = 0  # looser: box centre back inside the truth box
    recovered_centre_base: int = 0
    recovery_s: list = field(default_factory=list)  # fused recovery times
    unrecovered: list = field(default_factory=list)  # descriptions of fused misses


def centre_inside(boxes: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Whether each box's centre lies inside the truth box of the same row, ``(n, 4)`` x2 -> ``(n,)``."""
    c = 0.5 * (boxes[:, :2] + boxes[:, 2:])
    return np.all((c >= truth[:, :2]) & (c <= truth[:, 2:]), axis=1)


def _switches(ids: np.ndarray) -> int:
    covered = ids[ids >= 0]
    return int(np.sum(covered[1:] != covered[:-1]))


def _episodes(hidden: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True (at least 2 frames) as index pairs ``[a, b)``."""
    d = np.diff(np.r_[0, hidden.astype(int), 0])
    return [(a, b) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True) if b - a >= 2]


def _recovery(on: np.ndarray, t_s: np.ndarray, end: int) -> float:
    """Seconds from frame ``end`` until the first of ``RUN_FRAMES`` consecutive on-target frames (inf: never)."""
    run = np.convolve(on[end:].astype(int), np.ones(RUN_FRAMES, int), "valid") >= RUN_FRAMES
    k = np.flatnonzero(run)
    return float(t_s[end + k[0]] - t_s[end]) if k.size else np.inf


def evaluate(result: WearableResult, folder: Path, carriers: dict[str, int],
             lights: dict[str, list[tuple[float, float]]]) -> Metrics:
    """Visual metrics of every (person, camera) track against the truth boxes (see the module docstring)."""
    m = Metrics()
    truths: dict[str, CameraTruth] = {}
    for phone, person in result.people.items():
        agent = carriers[phone]
        for cam, v in person.boxes.items():
            if cam not in truths:
                info = result.inputs.cameras[cam].info
                truths[cam] = read_camera_truth(folder, cam, info.width, info.height)
            truth = truths[cam]
            t_s = (v.t_ns - T0_NS) * 1e-9
            n = v.t_ns.size
            own = np.full((n, 4), np.nan)
            vis = np.zeros(n)
            ids_f, ids_b = np.full(n, -1), np.full(n, -1)
            for i, t in enumerate(v.t_ns):
                frame = truth.boxes.get(int(t), {})
                if agent in frame:
                    own[i], vis[i] = frame[agent]
                if frame:
                    ids = np.array(list(frame))
                    bx = np.array([frame[k][0] for k in ids])
                    for box, out in ((v.box_px[i], ids_f), (v.baseline_box_px[i], ids_b)):
                        ov = iou(box[None, :], bx)
                        if ov.max() >= IOU_OK:
                            out[i] = ids[int(np.argmax(ov))]
            c = 0.5 * (own[:, :2] + own[:, 2:])
            in_view = np.all(np.isfinite(own), axis=1) & (c[:, 0] >= 0) & (c[:, 0] < truth.width) & \
                (c[:, 1] >= 0) & (c[:, 1] < truth.height)
            on_f = in_view & (iou(v.box_px, own) >= IOU_OK)
            on_b = in_view & (iou(v.baseline_box_px, own) >= IOU_OK)

            m.frames += int(in_view.sum())
            m.on_fused += int(on_f.sum())
            m.on_base += int(on_b.sum())
            centre_f, centre_b = in_view & centre_inside(v.box_px, own), in_view & centre_inside(v.baseline_box_px, own)
            m.centre_fused += int(centre_f.sum())
            m.centre_base += int(centre_b.sum())
            m.switches_fused += _switches(ids_f)
            m.switches_base += _switches(ids_b)
            dark = np.zeros(n, bool)
            for t_off, gain in sorted(lights.get(cam, [])):
                dark[t_s >= t_off] = gain < 0.5
            failure = v.status == "failure"
            for a, b in _episodes(in_view & ((vis < HIDDEN) | dark)):
                if b >= n or t_s[-1] - t_s[b] < RECOVER_S:  # the track ends too soon after: not judged
                    continue
                after = (t_s >= t_s[a]) & (t_s <= t_s[b - 1] + RECOVER_S)
                m.episodes += 1
                m.lost_fused += int(np.any(~on_f[after]))
                m.lost_base += int(np.any(~on_b[after]))
                m.detected += int(np.any(failure[after]))
                rf = _recovery(on_f, t_s, b)
                m.recovered_fused += int(rf <= RECOVER_S)
                m.recovered_base += int(_recovery(on_b, t_s, b) <= RECOVER_S)
                m.recovered_centre_fused += int(_recovery(centre_f, t_s, b) <= RECOVER_S)
                m.recovered_centre_base += int(_recovery(centre_b, t_s, b) <= RECOVER_S)
                m.recovery_s.append(rf)
                if rf > RECOVER_S:
                    m.unrecovered.append(f"{phone}/{cam} {t_s[a]:.1f}-{t_s[b - 1]:.1f} s")
    return m


def pdr_speed(folder: Path, phones: list[str]) -> float:
    """Dead reckoning speed in multiples of real time: recorded seconds / compute seconds, over the phones."""
    recorded = compute = 0.0
    for phone in phones:
        s = load_imu(folder, sensor=phone)
        t0 = time.perf_counter()
        run_pdr(s.t_ns, s.accel_mps2, s.gyro_radps)
        compute += time.perf_counter() - t0
        recorded += (s.t_ns[-1] - s.t_ns[0]) * 1e-9
    return recorded / compute


@dataclass
class Run:
    scene: str
    seed: int
    metrics: Metrics
    owned_right: int
    owned_wrong: int
    undecided: int
    err_before: float
    err_after: float
    pdr_x: float
    step_ms: float
    seconds: float


def run_scene(scene: str, seed: int, folder: Path, keep: bool) -> Run:
    started = time.perf_counter()
    scenario = load_scenario(scene).with_overrides(seed=seed)
    sim = Simulation(scenario)
    carriers = {p.phone: p.agent_id for p in sim.pedestrian_plans if p.phone}
    lights = {c.name: [tuple(x) for x in c.illumination] for c in scenario.config.cameras}
    video = tuple(c.name for c in scenario.config.cameras if not c.depth)
    path = folder / f"{scene}_seed{seed}"
    if not path.exists():
        sim.run(path)
    result = track_wearable(path, WearableParams(cameras=video, vision=VisualParams(baseline=True), seed=seed))
    metrics = evaluate(result, path, carriers, lights)
    agents = read_agents(path)
    names = sorted(result.people)
    right = wrong = 0
    for tr, o in zip(result.tracklets, result.owner, strict=True):
        if o < 0:
            continue
        d = {a: np.median(np.hypot(np.interp(tr.t_ns, xs[:, 0], xs[:, 1]) - tr.xy_m[:, 0],
                                   np.interp(tr.t_ns, xs[:, 0], xs[:, 2]) - tr.xy_m[:, 1])) for a, xs in agents.items()}
        right += int(min(d, key=d.get) == carriers[names[o]])
        wrong += int(min(d, key=d.get) != carriers[names[o]])
    before, after = [], []
    for phone, pr in result.people.items():
        c, xs = pr.correction, agents[carriers[phone]]
        if not c.aligned:
            continue
        sel = c.corrected
        ts = c.t_ns[sel]
        truth = np.column_stack([np.interp(ts, xs[:, 0], xs[:, 1]), np.interp(ts, xs[:, 0], xs[:, 2])])
        before.append(np.linalg.norm(c.dr_world_m[sel] - truth, axis=1))
        after.append(np.linalg.norm(c.xy_m[sel] - truth, axis=1))
    steps = sum(v.t_ns.size for pr in result.people.values() for v in pr.boxes.values())
    run = Run(scene, seed, metrics, right, wrong, int(np.sum(result.owner < 0)),
              float(np.mean(np.concatenate(before))) if before else np.nan,
              float(np.mean(np.concatenate(after))) if after else np.nan, pdr_speed(path, names),
              1e3 * result.seconds.get("visual", 0.0) / max(steps, 1), time.perf_counter() - started)
    if not keep:
        shutil.rmtree(path, ignore_errors=True)
    return run


def pct(a: int, b: int) -> str:
    return f"{100 * a / b:.1f} %" if b else "-"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES)
    parser.add_argument("--keep", type=Path, help="simulate into (or reuse recordings in) this folder and keep them")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    folder = args.keep or Path(tempfile.mkdtemp(prefix="wearable_bench_"))
    folder.mkdir(parents=True, exist_ok=True)
    console = Console(width=230)
    runs: list[Run] = []
    try:
        for scene in args.scenes:
            for seed in args.seeds:
                runs.append(run_scene(scene, seed, folder, keep=args.keep is not None))
                r = runs[-1]
                console.print(f"{scene} seed {seed}: {r.seconds:.0f} s; unrecovered (fused): "
                              f"{', '.join(r.metrics.unrecovered) or 'none'}")
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)
    seeds = ", ".join(map(str, args.seeds))
    table = Table(title=f"Visual-only compressive tracking vs fused (C9-C12), video cameras, seeds {seeds}")
    for col in ("scene", "frames", "IoU>=0.5\nvisual-only", "IoU>=0.5\nfused", "centre in box\nvisual-only",
                "centre in box\nfused", "ID switches\nvisual-only", "ID switches\nfused", "injected\nfailures",
                "lost\nvisual-only / fused", "detected\n(fused)", "recovered <= 1 s\nvisual-only",
                "recovered <= 1 s\nfused", "fused recovery s\nmedian / max",
                "recovered <= 1 s\ncentre criterion\nvisual-only / fused"):
        table.add_column(col, justify="right")
    by_scene: dict[str, list[Run]] = defaultdict(list)
    for r in runs:
        by_scene[r.scene].append(r)
    for scene, rs in by_scene.items():
        ms = [r.metrics for r in rs]
        tot = {k: sum(getattr(m, k) for m in ms) for k in Metrics.__dataclass_fields__ if k not in
               ("recovery_s", "unrecovered")}
        rec = np.concatenate([np.asarray(m.recovery_s, float) for m in ms]) if ms else np.zeros(0)
        table.add_row(scene.removeprefix("wearable_"), str(tot["frames"]), pct(tot["on_base"], tot["frames"]),
                      pct(tot["on_fused"], tot["frames"]),
                      pct(tot["centre_base"], tot["frames"]), pct(tot["centre_fused"], tot["frames"]),
                      str(tot["switches_base"]), str(tot["switches_fused"]), str(tot["episodes"]),
                      f"{tot['lost_base']} / {tot['lost_fused']}", str(tot["detected"]),
                      f"{tot['recovered_base']}/{tot['episodes']}", f"{tot['recovered_fused']}/{tot['episodes']}",
                      f"{np.median(rec):.2f} / {np.max(rec):.2f}" if rec.size else "-",
                      f"{tot['recovered_centre_base']}/{tot['episodes']} / "
                      f"{tot['recovered_centre_fused']}/{tot['episodes']}")
    console.print(table)
    per = Table(title="Per run: RGB-D ownership, trajectory error, speed")
    for col in ("scene", "seed", "tracklets owned\nright / wrong", "undecided", "mean error m\nbefore / after TPS",
                "PDR x real time", "visual ms\nper tracker step", "run s"):
        per.add_column(col, justify="right")
    for r in runs:
        per.add_row(r.scene, str(r.seed), f"{r.owned_right} / {r.owned_wrong}", str(r.undecided),
                    f"{r.err_before:.2f} / {r.err_after:.2f}", f"{r.pdr_x:.0f}", f"{r.step_ms:.1f}", f"{r.seconds:.0f}")
    console.print(per)


if __name__ == "__main__":
    main()
