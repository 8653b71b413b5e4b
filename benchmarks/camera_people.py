"""The vision-only people tracker (``--pipeline people-camera``) on simulated and real camera data.

Simulated ``crossing``, ``groups`` and ``crowd`` (seeds 0-2, 640x480 at 15 Hz): CLEAR MOT and identity metrics in
image space (TrackEval, IoU >= 0.5, MOT16-style: people less than half visible are distractors) against the
simulator's per-camera boxes, foreground pixel precision/recall against its per-pixel labels (after the first
second, MoG's start-up), floor-position error of the matched states, and frames per second (decode + foreground
+ blobs + tracking). Two reference rows per scenario, from the same foreground: A5's blob tracker alone (each
object's box, completed to the feet like ours; group members left out, which scores better than reporting them
with the group's box), and our tracker without the completion of short boxes (what an uncalibrated camera gets).
Real PETS 2009 S2.L1 (795 frames, 480x360): both detection modes (own foreground blobs; the MOT15 public
detections), tracks, tracks per frame and fps.

    .venv/bin/python benchmarks/camera_people.py [--seeds 0 1 2] [--seconds crossing=20 groups=30 crowd=30]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from fusiontrack.eval import Metrics, combine_metrics, evaluate_boxes
from fusiontrack.io.recording import Recording
from fusiontrack.io.tracks import MotBoxes
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.tracking.association import hungarian
from fusiontrack.types import Image, TrackState
from fusiontrack.vision import (
    BlobTracker,
    FrameResult,
    blob_histograms,
    box_iou,
    camera_from_recording,
    camera_truth_boxes,
    complete_person_boxes,
    track_camera,
)

PETS = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "video" / "pets09_s2l1"
SCENARIOS = {"crossing": 20.0, "groups": 30.0, "crowd": 30.0}
WARMUP = 15  # frames (1 s at 15 Hz) of MoG start-up left out of the pixel counts


def mot_rows(rows: list[list[float]]) -> MotBoxes:
    a = np.array(rows, np.float64).reshape(-1, 6)
    return MotBoxes(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a[:, 2:6], np.ones(len(a)),
                    np.zeros((len(a), 0)))


def state_rows(states: list[TrackState], frame_of: dict[int, int]) -> list[list[float]]:
    return [[frame_of[s.t_ns], s.track_id, s.box_px[0], s.box_px[1], s.box_px[2] - s.box_px[0],
             s.box_px[3] - s.box_px[1]] for s in states if s.box_px is not None]


class SceneProbe:
    """``on_frame`` of :func:`track_camera`: pixel counts against the labels, and A5 on the same blobs."""

    def __init__(self, labels: Iterator[Image], camera) -> None:
        self.labels, self.camera = labels, camera
        self.tp = self.fp = self.fn = 0
        self.a5 = BlobTracker()
        self.a5_rows: list[list[float]] = []

    def __call__(self, r: FrameResult) -> None:
        lab = next(self.labels)
        if lab.t_ns != r.image.t_ns:
            raise RuntimeError(f"labels at {lab.t_ns} ns do not belong to the image at {r.image.t_ns} ns")
        if r.foreground is None or r.blobs is None:
            return
        if r.index >= WARMUP:
            person, fg = lab.pixels > 0, r.foreground.mask
            self.tp += int(np.count_nonzero(fg & person))
            self.fp += int(np.count_nonzero(fg & ~person))
            self.fn += int(np.count_nonzero(~fg & person))
        objects = self.a5.step(r.blobs, blob_histograms(r.image.bgr(), r.blobs), r.image.t_ns)
        solo = [o for o in objects if not o.in_group]
        if solo:
            boxes = complete_person_boxes(self.camera, np.array([o.box_px for o in solo]))
            for o, b in zip(solo, boxes, strict=True):
                self.a5_rows.append([r.index + 1, o.object_id, b[0], b[1], b[2] - b[0], b[3] - b[1]])


def floor_errors(states: list[TrackState], truth: list, frame_of: dict[int, int]) -> np.ndarray:
    """Distance (m) from each state matched in the image (IoU >= 0.5, visibility >= 0.9) to the true position."""
    by_frame: dict[int, list[TrackState]] = {}
    for s in states:
        by_frame.setdefault(frame_of[s.t_ns], []).append(s)
    out = []
    for k, g in enumerate(truth, start=1):
        ss = by_frame.get(k, [])
        vis = np.asarray(g.attributes["visibility"]) >= 0.9
        if not ss or not vis.any():
            continue
        pairs, _, _ = hungarian(1 - box_iou(g.attributes["box_px"][vis], np.array([s.box_px for s in ss])), gate=0.5)
        out += [float(np.linalg.norm(ss[c].position_m - g.positions_m[vis][r])) for r, c in pairs]
    return np.array(out)


def run_scenario(name: str, seconds: float, seed: int, tmp: Path) -> dict:
    out = tmp / f"{name}_{seed}"
    t0 = time.perf_counter()
    simulate(load_scenario(name).with_overrides(seconds=seconds, seed=seed), out)
    sim_s = time.perf_counter() - t0
    with Recording(out) as rec:
        truth = list(rec.messages(["/ground_truth/camera_0"]))
        camera = camera_from_recording(rec, "camera_0", "camera_0")
    with Recording(out) as rec:
        probe = SceneProbe(iter(rec.messages(["/camera_0/labels"])), camera)
        states, _, stats = track_camera(out, camera_topic="/camera_0/image", on_frame=probe)
    plain, _, _ = track_camera(out, camera_topic="/camera_0/image", complete_height_m=None)
    frame_of = stats.frame_of()
    gt = camera_truth_boxes(truth, stats.width, stats.height, frames=[frame_of[g.t_ns] for g in truth])
    n = stats.n_frames

    def score(rows: list[list[float]]) -> Metrics:
        return evaluate_boxes(gt, mot_rows(rows), preprocess=True, n_frames=n, name=f"{name} seed {seed}")

    err = floor_errors(states, truth, frame_of)
    return {
        "ours": score(state_rows(states, frame_of)), "a5": score(probe.a5_rows),
        "plain": score(state_rows(plain, frame_of)), "precision": probe.tp / max(probe.tp + probe.fp, 1),
        "recall": probe.tp / max(probe.tp + probe.fn, 1), "tp": probe.tp, "fp": probe.fp, "fn": probe.fn,
        "fps": stats.fps, "frames": n, "tracks": stats.n_tracks, "sim_s": sim_s,
        "floor_median_m": float(np.median(err)) if err.size else float("nan"), "floor_errors": err,
    }


def pets_runs() -> dict[str, dict]:
    video = PETS / "vtest_pets09_s2l1_480x360.avi"
    runs = {"own foreground blobs": {}, "MOT15 public detections": {
        "detections": PETS / "PETS09-S2L1_det_MOT15.txt", "detection_scale": 0.625}}
    out = {}
    for name, kw in runs.items():
        states, events, stats = track_camera(video, **kw)
        per_frame = np.bincount([stats.frame_of()[s.t_ns] for s in states], minlength=stats.n_frames + 1)[1:]
        _, lives = np.unique([s.track_id for s in states], return_counts=True)
        out[name] = {"frames": stats.n_frames, "tracks": stats.n_tracks, "per_frame": float(per_frame.mean()),
                     "det_per_frame": stats.n_detections / stats.n_frames, "median_life": float(np.median(lives)),
                     "merges": sum(e.kind == "image_merge" for e in events), "fps": stats.fps,
                     "seconds": stats.seconds}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--seconds", nargs="*", default=[], help="NAME=SECONDS overrides, e.g. crowd=20")
    args = parser.parse_args()
    seconds = dict(SCENARIOS)
    for item in args.seconds:
        key, _, value = item.partition("=")
        if key not in seconds:
            parser.error(f"--seconds: unknown scenario {key!r}")
        seconds[key] = float(value)
    console = Console(width=150)
    t_start = time.perf_counter()
    results: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, secs in seconds.items():
            results[name] = [run_scenario(name, secs, seed, Path(tmp)) for seed in args.seeds]
    pets = pets_runs()

    table = Table(title="people-camera on simulated cameras (640x480, 15 Hz): image space, IoU >= 0.5; "
                        "foreground pixels vs the rendered labels", header_style="bold")
    for col in ("scenario", "seed", "s", "MOTA", "IDF1", "IDSW", "FP", "FN", "GT ids", "tracks", "fg precision",
                "fg recall", "floor median m", "fps"):
        table.add_column(col, justify="left" if col == "scenario" else "right")
    for name, runs in results.items():
        for seed, r in zip(args.seeds, runs, strict=True):
            m = r["ours"]
            table.add_row(name, str(seed), f"{seconds[name]:g}", f"{100 * m.mota:.1f}", f"{100 * m.idf1:.1f}",
                          str(m.id_switches), str(m.fp), str(m.fn), str(m.num_gt_ids), str(r["tracks"]),
                          f"{r['precision']:.3f}", f"{r['recall']:.3f}", f"{r['floor_median_m']:.2f}",
                          f"{r['fps']:.0f}")
        m = combine_metrics([r["ours"] for r in runs])
        tp, fp, fn = (sum(r[k] for r in runs) for k in ("tp", "fp", "fn"))
        err = np.concatenate([r["floor_errors"] for r in runs])
        fps = sum(r["frames"] for r in runs) / sum(r["frames"] / r["fps"] for r in runs)
        table.add_row(f"[bold]{name} (all seeds)", "", "", f"[bold]{100 * m.mota:.1f}", f"[bold]{100 * m.idf1:.1f}",
                      str(m.id_switches), str(m.fp), str(m.fn), str(m.num_gt_ids),
                      str(sum(r["tracks"] for r in runs)), f"{tp / max(tp + fp, 1):.3f}", f"{tp / max(tp + fn, 1):.3f}",
                      f"{np.median(err):.2f}", f"{fps:.0f}", end_section=True)
    console.print(table)

    ref = Table(title="the same frames, all seeds combined: our tracker vs references", header_style="bold")
    for col in ("scenario", "tracker", "MOTA", "IDF1", "IDSW", "FP", "FN"):
        ref.add_column(col, justify="left" if col in ("scenario", "tracker") else "right")
    for name, runs in results.items():
        for key, label in (("ours", "CameraPeopleTracker on blobs (default)"),
                           ("plain", "  same, short boxes not completed (no camera)"),
                           ("a5", "  A5 BlobTracker objects, alone, completed")):
            m = combine_metrics([r[key] for r in runs])
            ref.add_row(name if key == "ours" else "", label, f"{100 * m.mota:.1f}", f"{100 * m.idf1:.1f}",
                        str(m.id_switches), str(m.fp), str(m.fn), end_section=key == "a5")
    console.print(ref)

    pt = Table(title="PETS 2009 S2.L1 (795 frames, 480x360; no ground truth here)", header_style="bold")
    for col in ("detections", "frames", "tracks", "tracks/frame", "detections/frame", "median track frames",
                "image merges", "fps", "decode / fg / track s"):
        pt.add_column(col, justify="left" if col == "detections" else "right")
    for name, r in pets.items():
        s = r["seconds"]
        pt.add_row(name, str(r["frames"]), str(r["tracks"]), f"{r['per_frame']:.2f}", f"{r['det_per_frame']:.2f}",
                   f"{r['median_life']:.0f}", str(r["merges"]), f"{r['fps']:.0f}",
                   f"{s['decode']:.2f} / {s['foreground']:.2f} / {s['track']:.2f}")
    console.print(pt)
    sims = sum(r["sim_s"] for runs in results.values() for r in runs)
    console.print(f"total {time.perf_counter() - t_start:.0f} s (simulation {sims:.0f} s); "
                  f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
