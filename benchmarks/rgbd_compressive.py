"""Seed 002's visual side, speed and real-data distances: the RGB-D particle filter (C6), the RGB-D person
detector, compressive tracking (C10) and its multi-template, inertially checked variant (C11/C12).

Per-frame cost (best of ``--repeats`` passes, median per frame within a pass) at 640x480 on synthetic frames, at
the TUe frame size on the real TUe RGB-D snapshots (../shared/data/rgbd/tue_rgbd_people: 640x480 as well, so the
two rows differ by content, not size), and at the simulator's 320x240; then the measured distance of the standing
man in each of the five TUe frames (README: "~2 m").

    .venv/bin/python benchmarks/rgbd_compressive.py [--repeats 3] [--frames 60] [--threads N]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table

from fusiontrack.io.recording import Recording
from fusiontrack.vision.compressive import CompressiveTracker, MultiTemplateTracker
from fusiontrack.vision.rgbd import RgbdParticleFilter, RgbdPfParams, detect_people_rgbd, target_position

TUE = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "rgbd" / "tue_rgbd_people"
TUE_TORSO_PX = {"2019-05-03-12-41-38": (310, 220), "2019-05-03-12-42-18": (370, 220),
                "2019-05-03-12-42-25": (370, 220), "2019-05-03-12-42-30": (350, 220),
                "2019-05-03-12-42-34": (350, 220)}  # a point on the man's torso, marked by hand
WARMUP = 3


def time_frames(make: Callable[[], Callable[[int], object]], n: int, repeats: int) -> float:
    """Best-of-``repeats`` median seconds per call of ``step(k)``, k = 1..n (a fresh ``step`` per pass)."""
    best = np.inf
    for _ in range(repeats):
        step = make()
        t = []
        for k in range(1, n + 1):
            t0 = time.perf_counter()
            step(k)
            t.append(time.perf_counter() - t0)
        best = min(best, float(np.median(t[WARMUP:])))
    return best


def synthetic_person(width: int, height: int, n: int, seed: int = 0) -> tuple[list, list, np.ndarray]:
    """A person-shaped RGB-D target (2.5 m) walking across a textured wall (4 m): frames, depths, first box."""
    rng = np.random.default_rng(seed)
    s = height / 480
    wall = cv2.GaussianBlur(rng.integers(60, 200, (height, width, 3)).astype(np.uint8), (0, 0), 3)
    bgrs, depths = [], []
    for k in range(n + 1):
        u = int(width * 0.2 + k * 5 * s)
        bgr, depth = wall.copy(), np.full((height, width), 4.0, np.float32)
        m = np.zeros((height, width), bool)
        m[int(120 * s):int(160 * s), u - int(18 * s):u + int(18 * s)] = True
        m[int(160 * s):int(440 * s), u - int(45 * s):u + int(45 * s)] = True
        bgr[m] = (40, 40, 180)
        bgr[int(300 * s):][m[int(300 * s):]] = (120, 60, 20)
        depth[m] = 2.5
        bgrs.append(bgr)
        depths.append(depth + rng.normal(0, 0.01, depth.shape).astype(np.float32))
    u0 = int(width * 0.2)
    return bgrs, depths, np.array([u0 - 48 * s, 115 * s, u0 + 48 * s, 445 * s])


def moving_patch(width: int, height: int, n: int, seed: int = 0) -> tuple[list, np.ndarray]:
    """Grey frames with a textured 40x60 patch moving over a smooth background; the first box."""
    rng = np.random.default_rng(seed)
    bg = cv2.GaussianBlur(rng.random((height, width)), (0, 0), 6)
    bg = (40 + 180 * (bg - bg.min()) / np.ptp(bg)).astype(np.uint8)
    patch = cv2.GaussianBlur(rng.random((60, 40)), (0, 0), 1.5)
    patch = (255 * (patch - patch.min()) / np.ptp(patch)).astype(np.uint8)
    frames = []
    for k in range(n + 1):
        u, v = int(width / 2 + 0.3 * width * np.sin(k / 15)), int(height / 2 + 0.2 * height * np.sin(k / 10))
        f = bg.copy()
        f[v - 30:v + 30, u - 20:u + 20] = patch
        frames.append(f)
    u, v = width // 2, height // 2
    return frames, np.array([u - 20, v - 30, u + 20, v + 30], float)


def load_tue() -> dict[str, tuple]:
    out = {}
    for bag in sorted(TUE.glob("*.bag")):
        with Recording(bag) as rec:
            msgs = {type(m).__name__: m for m in rec.messages()}
        out[bag.stem] = (msgs["Image"].bgr(), msgs["DepthImage"].depth_m, msgs["CameraInfo"])
    return out


def the_man(depth: np.ndarray, info: object, torso: tuple[int, int]) -> np.ndarray | None:
    det = detect_people_rgbd(depth, info, rng=0)
    u, v = torso
    hit = (det.boxes_px[:, 0] <= u) & (u < det.boxes_px[:, 2]) & (det.boxes_px[:, 1] <= v) & (v < det.boxes_px[:, 3])
    return det.boxes_px[int(np.flatnonzero(hit)[0])] if hit.any() else None


def pf_row(bgrs: Sequence, depths: Sequence, box: np.ndarray, n_particles: int, n: int, repeats: int) -> float:
    def make() -> Callable[[int], object]:
        pf = RgbdParticleFilter(bgrs[0], depths[0], box, RgbdPfParams(n_particles=n_particles), rng=0)
        return lambda k: pf.step(bgrs[k % len(bgrs)], depths[k % len(depths)])

    return time_frames(make, n, repeats)


def ct_row(greys: Sequence, box: np.ndarray, n: int, repeats: int, multi: bool) -> float:
    def make() -> Callable[[int], object]:
        if multi:
            mt = MultiTemplateTracker(greys[0], box, np.eye(2) * 25.0, rng=0)
            c = 0.5 * (box[:2] + box[2:])
            return lambda k: mt.step(greys[k % len(greys)], c)  # projected position given: C11 + C12 run
        ct = CompressiveTracker(greys[0], box, rng=0)
        return lambda k: ct.step(greys[k % len(greys)])

    return time_frames(make, n, repeats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--frames", type=int, default=60, help="frames timed per pass")
    parser.add_argument("--threads", type=int, default=None, help="cv2.setNumThreads")
    args = parser.parse_args()
    if args.threads is not None:
        cv2.setNumThreads(args.threads)
    console = Console(width=120)
    n, reps = args.frames, args.repeats
    tue = load_tue()
    stems = list(tue)
    tue_bgr = [tue[s][0] for s in stems]
    tue_depth = [tue[s][1] for s in stems]
    tue_grey = [cv2.cvtColor(b, cv2.COLOR_BGR2GRAY) for b in tue_bgr]
    man_box = the_man(tue_depth[0], tue[stems[0]][2], TUE_TORSO_PX[stems[0]])

    table = Table(title=f"per-frame cost, best of {reps} passes x {n} frames (median), cv2 threads "
                        f"{cv2.getNumThreads()}")
    for col in ("component", "input", "frame", "box px", "ms / frame", "fps"):
        table.add_column(col, justify="right" if col in ("ms / frame", "fps") else "left")

    def add(component: str, source: str, size: str, box: np.ndarray, sec: float) -> None:
        w, h = box[2] - box[0], box[3] - box[1]
        table.add_row(component, source, size, f"{w:.0f}x{h:.0f}", f"{sec * 1e3:.2f}", f"{1 / sec:.0f}")

    for width, height in ((640, 480), (320, 240)):
        bgrs, depths, box = synthetic_person(width, height, n)
        for n_p in (100, 200, 500):
            add(f"RGB-D PF (C6), N = {n_p}", "synthetic", f"{width}x{height}", box,
                pf_row(bgrs, depths, box, n_p, n, reps))
    for n_p in (100, 200, 500):
        add(f"RGB-D PF (C6), N = {n_p}", "TUe real", "640x480", man_box,
            pf_row(tue_bgr, tue_depth, man_box, n_p, n, reps))
    for width, height in ((640, 480), (320, 240)):
        greys, box = moving_patch(width, height, n)
        add("CT (C10)", "synthetic", f"{width}x{height}", box, ct_row(greys, box, n, reps, multi=False))
        add("CT + C11/C12", "synthetic", f"{width}x{height}", box, ct_row(greys, box, n, reps, multi=True))
    add("CT (C10)", "TUe real", "640x480", man_box, ct_row(tue_grey, man_box, n, reps, multi=False))
    add("CT + C11/C12", "TUe real", "640x480", man_box, ct_row(tue_grey, man_box, n, reps, multi=True))
    det_sec = time_frames(lambda: (lambda k: detect_people_rgbd(tue_depth[k % 5], tue[stems[0]][2], rng=0)), n, reps)
    table.add_row("RGB-D detector", "TUe real", "640x480", "-", f"{det_sec * 1e3:.2f}", f"{1 / det_sec:.0f}")
    console.print(table)

    dist = Table(title="the standing man in the TUe frames (README: about 2 m): detector + C7")
    for col in ("frame", "box px", "median depth Z m", "range m", "x, y, z (optical) m", "pixels"):
        dist.add_column(col)
    for stem in stems:
        _, depth, info = tue[stem]
        box = the_man(depth, info, TUE_TORSO_PX[stem])
        if box is None:
            dist.add_row(stem, "not found", "-", "-", "-", "-")
            continue
        fix = target_position(depth, box, info)
        dist.add_row(stem, str(box.astype(int).tolist()), f"{fix.depth_m:.3f}", f"{fix.range_m:.3f}",
                     ", ".join(f"{c:+.2f}" for c in fix.position_cam_m), str(fix.n_pixels))
    console.print(dist)


if __name__ == "__main__":
    main()
