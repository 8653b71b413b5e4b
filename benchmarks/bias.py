"""Seed 000's experiment in simulation: the camera turned 3 degrees from its calibration (ALGORITHMS.md A10, A12).

For each seed: simulate ``--scenario`` (default ``crowd``: ~10 people in a 20 x 15 m hall, two lasers in opposite
corners, a camera 7 m up) with ``cameras.0.yaw_bias_deg = 3``; run the camera path (MoG foreground, blobs,
blob tracker: A1-A5) on the images and the adaptive bias (A6-A10) on the scans; measure the bias against the
injected 3 degrees (the simulator renders from the true pose and writes the pose turned by -3 degrees as the
calibration, ``fusiontrack.sim.camera``). Variants, all on the same boxes and scans:

* rho = 0.1 and rho = 0.5 (the paper's two learning rates), fusiontrack's defaults;
* rho = 0.1 fed only with people whose candidate region overlaps another person's (the paper's Fig. 7 case);
* rho = 0.1 with A6-A10 as published (beam-order A8 clustering, point centroids, no distance gate, no residual
  gate, no box checks, box centres).

Definitions (counted in *updates*: camera frames in which at least one person was matched and used):

* settled: the first update from which |b - 3| <= 10 % of 3 degrees for 30 updates in a row; noise-free
  smoothing needs 22 updates at rho = 0.1 and 4 at rho = 0.5 (3 (1 - rho)^n <= 0.3);
* 95 %: the first update with |b - 3| <= 5 % (noise-free: 29 and 5);
* after convergence: camera frames from 100 frames (6.7 s) after the first update to the end: the converged
  bias error |mean(b) - 3| (the paper's Table 1 quantity, 0.085 degrees averaged over 5 runs) and the mean
  |b - 3| over those frames (ALGORITHMS.md A10 test 3's quantity);
* overlapping regions: of the people matched while their region overlapped another's, the share whose
  chosen cluster is that same person's legs (within 0.5 m of their true position and nearer to it than to
  anybody else); the person behind a box is found from the simulator's boxes (IoU >= 0.5).

Writes ``out/bias/bias_convergence.png`` and ``out/bias/history_seed<S>_rho<R>.csv``.

    .venv/bin/python benchmarks/bias.py [--seeds 21 22 23 24 25] [--seconds 30] [--scenario crowd] [--out out/bias]
"""

from __future__ import annotations

import argparse
import logging
import math
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from rich.console import Console
from rich.table import Table

from fusiontrack.calibration import (
    BiasParams,
    BiasStep,
    FrameObjects,
    HorizontalBiasEstimator,
    candidate_regions,
    regions_overlap,
    write_bias_history,
)
from fusiontrack.calibration.bias_run import open_bias_inputs
from fusiontrack.io.recording import Recording
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.types import GroundTruth, LaserScan
from fusiontrack.vision import box_iou

BIAS_DEG = 3.0
SETTLE_TOL = 0.10
HOLD = 30
POST_FRAMES = 100
PUBLISHED = {"c0_m": 0.20, "foreground_only": False, "centre": "centroid", "leg_radius_m": 0.0, "min_width_m": 0.0,
             "range_gate_m": None, "gate_sigmas": 0.0, "min_aspect": 0.0}
VARIANTS = {"rho 0.1": {"rho": 0.1}, "rho 0.5": {"rho": 0.5}, "rho 0.1, overlapping only": {"rho": 0.1},
            "rho 0.1, A6-A10 as published": {"rho": 0.1, **PUBLISHED}}


@dataclass
class Run:
    steps: list[BiasStep] = field(default_factory=list)


def updates_to(bias_deg: np.ndarray, n_used: np.ndarray, tol_deg: float, hold: int) -> int:
    """1-based update from which |b - 3| <= tol for ``hold`` updates in a row (NaN when never)."""
    upd = bias_deg[n_used > 0]
    ok = np.abs(upd - BIAS_DEG) <= tol_deg
    if ok.size < hold:
        return math.nan
    run = np.convolve(ok, np.ones(hold, int), "valid") == hold
    return int(np.argmax(run)) + 1 if run.any() else math.nan


def feed(est: HorizontalBiasEstimator, item: FrameObjects, overlapping_only: bool, box_centres: bool) -> BiasStep:
    usable = item.usable
    if overlapping_only and len(item.boxes_px):
        reg = candidate_regions(item.boxes_px, est.camera, est.bias_rad, est.params.margin_rad, centres_px=None)
        usable = usable & regions_overlap(reg).any(axis=1)
    return est.update(item.t_ns, item.boxes_px, item.object_ids, usable, None if box_centres else item.centres_px)


def truth(path: Path, camera: str) -> tuple[list[GroundTruth], list[GroundTruth]]:
    with Recording(path) as rec:
        agents = list(rec.messages(["/ground_truth"]))
        boxes = list(rec.messages([f"/ground_truth/{camera}"]))
    return agents, boxes


def position_at(agents: list[GroundTruth], t_ns: int) -> dict[int, np.ndarray]:
    """True positions of everybody at ``t_ns``, interpolated between the 25 Hz truth frames."""
    ts = np.array([g.t_ns for g in agents])
    i = int(np.clip(np.searchsorted(ts, t_ns), 1, len(agents) - 1))
    g0, g1 = agents[i - 1], agents[i]
    w = (t_ns - g0.t_ns) / (g1.t_ns - g0.t_ns)
    p0 = dict(zip(g0.ids.tolist(), g0.positions_m, strict=True))
    return {a: (1 - w) * p0[a] + w * p for a, p in zip(g1.ids.tolist(), g1.positions_m, strict=True) if a in p0}


def overlap_check(steps: list[BiasStep], agents: list[GroundTruth], cam_truth: list[GroundTruth]) -> dict[str, int]:
    """Matched objects with / without overlapping regions, and how many got their own person's legs."""
    out = {"overlap": 0, "overlap_ok": 0, "alone": 0, "alone_ok": 0}
    ts = np.array([g.t_ns for g in cam_truth])
    for s in steps:
        sel = np.flatnonzero(np.isfinite(s.residual_rad))
        if sel.size == 0:
            continue
        gt = cam_truth[int(np.argmin(np.abs(ts - s.t_ns)))]
        vis = gt.attributes["visibility"] > 0.3
        gboxes, gids = gt.attributes["box_px"][vis], gt.ids[vis]
        if len(gboxes) == 0:
            continue
        pos = position_at(agents, s.t_ns)
        iou = box_iou(s.boxes_px[sel], gboxes)
        for k, j in enumerate(sel):
            m = int(np.argmax(iou[k]))
            if iou[k, m] < 0.5 or int(gids[m]) not in pos:
                continue
            key = "overlap" if s.overlapping[j] else "alone"
            ids = list(pos)
            d = np.hypot(*(np.array([pos[a] for a in ids]) - s.position_m[j]).T)
            own = ids.index(int(gids[m]))
            out[key] += 1
            out[key + "_ok"] += int(d[own] <= 0.5 and int(np.argmin(d)) == own)
    return out


def one_seed(scenario_name: str, seconds: float, seed: int, out: Path) -> tuple[dict[str, Run], dict[str, int], float]:
    scenario = load_scenario(scenario_name).with_overrides(seconds=seconds, seed=seed,
                                                           settings={"cameras.0.yaw_bias_deg": BIAS_DEG})
    cfg = scenario.config
    camera = cfg.cameras[0].name
    offsets = {c.name: c.clock_offset_ms for c in [*cfg.lasers, *cfg.cameras]}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rec"
        simulate(scenario, path)
        inputs = open_bias_inputs(path, camera, clock_offsets_ms=offsets)
        ests = {name: inputs.estimator(BiasParams(**kw)) for name, kw in VARIANTS.items()}
        runs = {name: Run() for name in VARIANTS}
        t0 = time.perf_counter()
        n_frames = 0
        for item in inputs:
            if isinstance(item, LaserScan):
                for est in ests.values():
                    est.observe_scan(item)
                continue
            n_frames += 1
            for name, est in ests.items():
                runs[name].steps.append(feed(est, item, "overlapping" in name, "published" in name))
        seconds_per_frame = (time.perf_counter() - t0) / max(n_frames, 1)
        agents, cam_truth = truth(path, camera)
    for name, est in ests.items():
        if name in ("rho 0.1", "rho 0.5"):
            write_bias_history(out / f"history_seed{seed}_{name.replace(' ', '')}.csv", est.history)
    return runs, overlap_check(runs["rho 0.1"].steps, agents, cam_truth), seconds_per_frame


def metrics(run: Run) -> dict[str, float]:
    bias = np.degrees([s.bias_rad for s in run.steps])
    n_used = np.array([s.n_used for s in run.steps])
    if not n_used.any():
        return {"updates": 0, "first": math.nan, "settle": math.nan, "settle_frames": math.nan, "p95": math.nan,
                "conv_err": math.nan, "mean_abs": math.nan, "std": math.nan}
    first = int(np.flatnonzero(n_used)[0])
    settle = updates_to(bias, n_used, SETTLE_TOL * BIAS_DEG, HOLD)
    upd_frames = np.flatnonzero(n_used)
    settle_frames = math.nan if math.isnan(settle) else int(upd_frames[settle - 1] - first + 1)
    post = bias[first + POST_FRAMES:]
    return {"updates": int((n_used > 0).sum()), "frames": len(bias), "first": first, "settle": settle,
            "settle_frames": settle_frames, "p95": updates_to(bias, n_used, 0.05 * BIAS_DEG, 1),
            "conv_err": abs(float(post.mean()) - BIAS_DEG), "mean_abs": float(np.mean(np.abs(post - BIAS_DEG))),
            "std": float(post.std())}


def plot(all_runs: dict[int, dict[str, Run]], path: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8))
    colours = {"rho 0.1": "tab:blue", "rho 0.5": "tab:orange"}
    n = np.arange(0, 81)
    for name, c in colours.items():
        rho = VARIANTS[name]["rho"]
        for seed, runs in all_runs.items():
            steps = runs[name].steps
            b = np.degrees([s.bias_rad for s in steps])
            used = np.array([s.n_used for s in steps]) > 0
            upd = np.r_[0.0, b[used]]
            axes[0].plot(np.arange(upd.size)[:81], upd[:81], color=c, lw=0.8, alpha=0.6)
            t = np.array([s.t_ns for s in steps])
            axes[1].plot((t - t[0]) / 1e9, b, color=c, lw=0.7, alpha=0.6,
                         label=f"{name} ({len(all_runs)} seeds)" if seed == min(all_runs) else None)
        axes[0].plot(n, BIAS_DEG * (1 - (1 - rho) ** n), color=c, lw=2, ls="--", label=f"{name}: 3 (1 - (1 - rho)^n)")
    for ax in axes:
        ax.axhline(BIAS_DEG, color="k", lw=0.8)
        ax.axhspan(BIAS_DEG * (1 - SETTLE_TOL), BIAS_DEG * (1 + SETTLE_TOL), color="0.85", zorder=0)
        ax.set_ylabel("bias (degrees)")
        ax.grid(alpha=0.3)
    axes[0].set_xlabel("updates (camera frames with a matched person)")
    axes[0].set_title("convergence: simulation (thin) and exponential smoothing (dashed)")
    axes[1].set_xlabel("time (s)")
    axes[1].set_title(f"whole runs ({len(all_runs)} seeds); grey: within 10 % of 3 degrees")
    axes[0].legend(loc="lower right", fontsize=8)
    axes[1].legend(loc="lower right", fontsize=8)
    axes[1].set_ylim(-0.2, 3.8)
    fig.suptitle("seed 000: camera turned 3 degrees from its calibration, adaptive horizontal bias")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[21, 22, 23, 24, 25])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--scenario", default="crowd")
    parser.add_argument("--out", type=Path, default=Path("out/bias"))
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    args.out.mkdir(parents=True, exist_ok=True)
    console = Console(width=150)
    all_runs: dict[int, dict[str, Run]] = {}
    overlap = {"overlap": 0, "overlap_ok": 0, "alone": 0, "alone_ok": 0}
    t0 = time.perf_counter()
    per_frame = []
    for seed in args.seeds:
        runs, ov, spf = one_seed(args.scenario, args.seconds, seed, args.out)
        all_runs[seed] = runs
        per_frame.append(spf)
        for k, v in ov.items():
            overlap[k] += v
        console.print(f"seed {seed}: " + ", ".join(f"{name} {math.degrees(runs[name].steps[-1].bias_rad):.3f}°"
                                                    for name in VARIANTS))
    table = Table(title=f"seed 000 in simulation: '{args.scenario}', {args.seconds:g} s, camera turned 3°, "
                        f"seeds {args.seeds} (mean over runs; per-run values in brackets)")
    for col in ("variant", "updates / frames", "updates to settle (10 %)", "frames to settle", "updates to 95 %",
                "converged error |mean b - 3°|", "mean |b - 3°|", "std b"):
        table.add_column(col, justify="right" if col != "variant" else "left")
    for name in VARIANTS:
        ms = [metrics(all_runs[s][name]) for s in args.seeds]

        def col(key: str, fmt: str, ms: list[dict[str, float]] = ms) -> str:
            vals = np.array([m[key] for m in ms], float)
            never = int(np.isnan(vals).sum())
            mean = f"{np.nanmean(vals):{fmt}}" if never < vals.size else "never"
            note = f" ({never} never)" if never else ""
            return mean + note + " [" + " ".join("never" if np.isnan(v) else f"{v:{fmt}}" for v in vals) + "]"

        table.add_row(name, f"{np.mean([m['updates'] for m in ms]):.0f} / {np.mean([m['frames'] for m in ms]):.0f}",
                      col("settle", ".0f"), col("settle_frames", ".0f"), col("p95", ".0f"), col("conv_err", ".3f"),
                      col("mean_abs", ".3f"), col("std", ".3f"))
    console.print(table)
    console.print("paper (Table 1, Fig. 6): error after convergence ≈ 0.085° (5 runs); saturation ≈ 40 frames at "
                  "rho 0.1, < 10 at rho 0.5.\nNoise-free exponential smoothing: 22 / 4 updates to settle, 29 / 5 to "
                  "95 %.")
    ot = Table(title="overlapping candidate regions (rho 0.1 run): is the chosen cluster the person's own legs?")
    for col in ("regions", "matched people", "own legs", "share"):
        ot.add_column(col, justify="right" if col != "regions" else "left")
    for key, label in (("overlap", "overlapping another person's"), ("alone", "not overlapping")):
        n, ok = overlap[key], overlap[key + "_ok"]
        ot.add_row(label, str(n), str(ok), f"{ok / n:.1%}" if n else "-")
    console.print(ot)
    png = args.out / "bias_convergence.png"
    plot(all_runs, png)
    console.print(f"plot: {png}; histories: {args.out}/history_seed*_rho*.csv")
    console.print(f"{np.mean(per_frame) * 1e3:.1f} ms per camera frame (camera path + 4 estimators); total "
                  f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
