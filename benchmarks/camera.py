"""Camera path speed and accuracy: foreground (MOG2 + A2 augmented mask + A3 shadows) + A4 blobs per frame.

Frames per second on the real PETS 2009 S2.L1 video (native 480x360, and resized to 640x480), on synthetic
640x480 frames, and on a simulated `crossing` (640x480), with OpenCV's MOG2 alone (same parameters) as a
reference row measured in the same process. Each timing is the best of ``--repeats`` passes (median per frame
within a pass) so that other processes on the machine inflate it as little as possible. On the simulation,
foreground precision/recall against the simulator's per-pixel labels, and box-level recall of the people.

    .venv/bin/python benchmarks/camera.py [--repeats 3] [--threads N] [--seconds 10] [--frames 400]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table

from fusiontrack.io.recording import Recording
from fusiontrack.io.video import VideoReader
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.vision import (
    BlobTracker,
    ForegroundModel,
    ForegroundParams,
    PixelLabel,
    blob_histograms,
    extract_blobs,
)

PETS = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "video" / "pets09_s2l1" / \
    "vtest_pets09_s2l1_480x360.avi"
WARMUP = 50  # frames not timed (MOG2's start-up learning rate, first allocations)


def time_frames(make: Callable[[], Callable[[np.ndarray], object]], frames: Sequence[np.ndarray],
                repeats: int) -> float:
    """Best-of-``repeats`` median seconds per frame of ``step`` (a fresh one from ``make`` per pass)."""
    best = np.inf
    for _ in range(repeats):
        step = make()
        t = []
        for f in frames:
            t0 = time.perf_counter()
            step(f)
            t.append(time.perf_counter() - t0)
        best = min(best, float(np.median(t[WARMUP:])))
    return best


def mog2_alone(p: ForegroundParams) -> Callable[[np.ndarray], object]:
    mog = cv2.createBackgroundSubtractorMOG2(history=p.history, varThreshold=3.0 * p.lambda_m**2,
                                             detectShadows=False)
    mog.setNMixtures(p.n_mixtures)
    mog.setBackgroundRatio(p.background_ratio)
    return mog.apply


def pipeline(p: ForegroundParams) -> Callable[[np.ndarray], object]:
    model = ForegroundModel(p)

    def step(frame: np.ndarray) -> object:
        return extract_blobs(model.apply(frame).mask)

    return step


def pipeline_tracked(p: ForegroundParams) -> Callable[[np.ndarray], object]:
    """Foreground + blobs + HSV histograms + the A5 blob tracker."""
    model, tracker = ForegroundModel(p), BlobTracker()

    def step(frame: np.ndarray) -> object:
        blobs = extract_blobs(model.apply(frame).mask)
        return tracker.step(blobs, blob_histograms(frame, blobs))

    return step


def synthetic(n: int, width: int = 640, height: int = 480, seed: int = 0) -> list[np.ndarray]:
    """Textured background, six uniform 40x100 px walkers at 3 px/frame, σ = 3 noise."""
    rng = np.random.default_rng(seed)
    bg = cv2.GaussianBlur(rng.uniform(0, 1, (height, width, 3)).astype(np.float32), (0, 0), 3)
    bg = 130 + (bg - bg.mean()) / bg.std() * 25
    noise = rng.normal(0, 3, (8, height, width, 3)).astype(np.float32)
    frames = []
    for i in range(n):
        f = bg.copy()
        for k in range(6):
            u0, v0 = (i * 3 + k * 100) % (width - 40), 50 + k * 60
            f[v0:v0 + 100, u0:u0 + 40] = (40 + 30 * k, 60, 200 - 20 * k)
        frames.append(np.clip(f + noise[i % 8], 0, 255).astype(np.uint8))
    return frames


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of boxes ``a`` (n, 4) and ``b`` (m, 4), ``(n, m)``."""
    lo = np.maximum(a[:, None, :2], b[None, :, :2])
    hi = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(hi - lo, 0, None), axis=2)
    area = lambda x: np.prod(x[:, 2:] - x[:, :2], axis=1)  # noqa: E731
    return inter / (area(a)[:, None] + area(b)[None, :] - inter + 1e-9)


def simulated_accuracy(seconds: float) -> tuple[list[np.ndarray], dict[str, float]]:
    """Simulate `crossing`, run the camera path, compare with the per-pixel labels and the people's boxes."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "crossing"
        simulate(load_scenario("crossing").with_overrides(seconds=seconds, seed=0), out)
        with Recording(out) as rec:
            images = list(rec.messages(["/camera_0/image"]))
            labels = list(rec.messages(["/camera_0/labels"]))
            truth = list(rec.messages(["/ground_truth/camera_0"]))
    model = ForegroundModel()
    tp = fp = fn = tp_mog = fp_mog = 0
    shadow_in_person = person = 0
    n_vis = n_hit = 0
    n_blobs, n_people = [], []
    for k, (im, lab, gt) in enumerate(zip(images, labels, truth, strict=True)):
        r = model.apply(im)
        blobs = extract_blobs(r.mask)
        if k < 15:  # the first second: MOG2's start-up
            continue
        person_px = lab.pixels > 0
        tp += int(np.count_nonzero(r.mask & person_px))
        fp += int(np.count_nonzero(r.mask & ~person_px))
        fn += int(np.count_nonzero(~r.mask & person_px))
        tp_mog += int(np.count_nonzero(r.mog_mask & person_px))
        fp_mog += int(np.count_nonzero(r.mog_mask & ~person_px))
        person += int(np.count_nonzero(person_px))
        shadow_in_person += int(np.count_nonzero((r.labels >= PixelLabel.SHADOW) & person_px))
        visible = gt.attributes["visibility"] > 0.5
        boxes = gt.attributes["box_px"][visible]
        n_vis += len(boxes)
        n_people.append(len(boxes))
        n_blobs.append(len(blobs))
        if len(boxes) and len(blobs):
            n_hit += int(np.count_nonzero(box_iou(boxes, blobs.boxes_px).max(axis=1) >= 0.3))
    stats = {
        "pixel precision": tp / max(tp + fp, 1), "pixel recall": tp / max(tp + fn, 1),
        "pixel precision (MoG only)": tp_mog / max(tp_mog + fp_mog, 1), "pixel recall (MoG only)": tp_mog / person,
        "person pixels labelled shadow/highlight": shadow_in_person / person,
        "box recall (IoU >= 0.3, visibility > 0.5)": n_hit / max(n_vis, 1),
        "blobs per frame": float(np.mean(n_blobs)), "visible people per frame": float(np.mean(n_people)),
    }
    return [im.bgr() for im in images], stats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=None, help="cv2.setNumThreads (default: OpenCV's)")
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated crossing (s)")
    parser.add_argument("--frames", type=int, default=400, help="frames per real/synthetic sequence")
    args = parser.parse_args()
    if args.threads is not None:
        cv2.setNumThreads(args.threads)
    console = Console(width=120)
    load = os.getloadavg()
    pets = [im.bgr().copy() for _, im in zip(range(args.frames), VideoReader(PETS), strict=False)]
    sim_frames, acc = simulated_accuracy(args.seconds)
    sequences = {
        "PETS S2.L1, native 480x360": pets,
        "PETS S2.L1, resized to 640x480": [cv2.resize(f, (640, 480), interpolation=cv2.INTER_LINEAR) for f in pets],
        "synthetic 640x480 (6 walkers)": synthetic(args.frames),
        "simulated crossing 640x480": sim_frames,
    }
    variants = {"K=5 (A1 default)": ForegroundParams(), "K=3": ForegroundParams(n_mixtures=3)}
    table = Table(title=f"camera path per frame, best of {args.repeats} (cv2 threads {cv2.getNumThreads()}, "
                        f"load average {load[0]:.1f} on {os.cpu_count()} cores)", header_style="bold")
    for col in ("sequence", "variant", "MOG2 alone ms", "fg + A2 + A3 + blobs ms", "fps", "MOG2 fps", "ratio"):
        table.add_column(col, justify="left" if col in ("sequence", "variant") else "right")
    for name, frames in sequences.items():
        for vname, p in variants.items():
            t_mog = time_frames(lambda p=p: mog2_alone(p), frames, args.repeats)
            t_all = time_frames(lambda p=p: pipeline(p), frames, args.repeats)
            table.add_row(name, vname, f"{t_mog * 1e3:.2f}", f"{t_all * 1e3:.2f}", f"{1 / t_all:.0f}",
                          f"{1 / t_mog:.0f}", f"{t_all / t_mog:.2f}")
    t_trk = time_frames(lambda: pipeline_tracked(ForegroundParams()), pets, args.repeats)
    t_fg = time_frames(lambda: pipeline(ForegroundParams()), pets, args.repeats)
    table.add_row("PETS S2.L1, native 480x360", "K=5 + histograms + A5 tracker", "", f"{t_trk * 1e3:.2f}",
                  f"{1 / t_trk:.0f}", "", f"{t_trk / t_fg:.2f} (vs fg + blobs)")
    console.print(table)
    acc_table = Table(title=f"simulated crossing ({args.seconds:g} s, 15 Hz, 640x480) vs the simulator's labels",
                      header_style="bold")
    acc_table.add_column("measure")
    acc_table.add_column("value", justify="right")
    for k, v in acc.items():
        acc_table.add_row(k, f"{v:.3f}")
    console.print(acc_table)


if __name__ == "__main__":
    main()
