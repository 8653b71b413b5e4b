"""Laser vehicle branch (ALGORITHMS.md D4) against the simulator's ground truth, per laser.

Runs :func:`fusiontrack.laser.vehicles.vehicle_detections_for_recording` on a simulated ``road`` recording (or
on ``--recording``) with the roads of its ``ground_truth/world.json`` and scores every scan after the background
is learnt against ``/ground_truth`` moved to the scan time (position + velocity x the stamp difference):

- a vehicle is *visible* to a laser when at least 3 of the scan's returns lie on its true footprint (grown by
  0.15 m; "recall >= 10 pts" counts only vehicles with at least 10); it is *seen on two sides* when at least 2
  returns lie on a long side and 2 on an end, away from the corners;
- detections and all vehicles are paired by the Hungarian algorithm on centre distance (gate 2 m); recall =
  paired visible vehicles / visible vehicles, precision = paired detections / detections;
- centre error: footprint centre of the detection to the true centre; heading error: modulo π (axis), and
  the share of detections with a velocity whose heading points the true way;
- id switches: changes of the paired track id along each vehicle's life in one laser;
- partial views: each paired detection's points are completed again (same fit, same heading, no occlusion
  reasoning) once with its class prior and once with the vehicle's *true* length and width. With the true size
  what remains is the fit's error; the difference to the class prior is what the unseen sides cost. The
  detector itself uses the class prior only until its track has seen the vehicle's side whole, then that size.

Timing: the detector's call per scan, after the background is learnt (``time.perf_counter``).

    .venv/bin/python benchmarks/laser_vehicles.py [--seconds 60] [--seed 0] [--recording DIR]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from fusiontrack.io.recording import Recording
from fusiontrack.laser.vehicles import (
    DEFAULT_PRIORS,
    box_heading,
    complete_boxes,
    fit_boxes,
    vehicle_detector_for_recording,
)
from fusiontrack.sim.laser import BICYCLE_LASER_WIDTH_M
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.tracking.association import hungarian
from fusiontrack.types import GroundTruth, LaserScan


def truth_at(gts: list[GroundTruth], gt_t: np.ndarray, t_ns: int) -> dict[str, np.ndarray]:
    """The vehicles of the ground-truth frame nearest ``t_ns``, moved to ``t_ns`` with their velocity."""
    g = gts[int(np.argmin(np.abs(gt_t - t_ns)))]
    vel = np.nan_to_num(g.velocities_mps)
    keep = np.array([c in ("car", "bicycle") for c in g.classes], bool)
    size = g.attributes["size_m"][keep]
    cls = np.array(g.classes)[keep]
    return {"ids": g.ids[keep], "pos": g.positions_m[keep] + vel[keep] * (t_ns - g.t_ns) / 1e9,
            "heading": g.attributes["heading_rad"][keep], "length": size[:, 0],
            "width": np.where(cls == "bicycle", BICYCLE_LASER_WIDTH_M, size[:, 1]), "true_width": size[:, 1],
            "cls": cls, "vel": vel[keep]}


def visibility(points: np.ndarray, truth: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Returns on each vehicle's footprint ``(n,)`` and whether it shows two sides ``(n,) bool``."""
    d = points[:, None, :] - truth["pos"][None]
    c, s = np.cos(truth["heading"]), np.sin(truth["heading"])
    lu, lv = d[..., 0] * c + d[..., 1] * s, d[..., 1] * c - d[..., 0] * s
    hl, hw = truth["length"] / 2, truth["width"] / 2
    on = (np.abs(lu) <= hl + 0.15) & (np.abs(lv) <= hw + 0.15)
    long_side = on & (np.abs(lv) >= hw - 0.1) & (np.abs(lu) < hl - 0.2)
    end = on & (np.abs(lu) >= hl - 0.1) & (np.abs(lv) < hw - 0.2)
    return on.sum(0), (long_side.sum(0) >= 2) & (end.sum(0) >= 2)


def evaluate(rec_path: Path, n_skip_scans: int = 50) -> dict[str, dict[str, Any]]:
    """Per-laser scores of the D4 branch on one recording (module docstring)."""
    world = json.loads((rec_path / "ground_truth" / "world.json").read_text())
    with Recording(rec_path) as rec:
        gts = [m for m in rec.messages(["/ground_truth"]) if isinstance(m, GroundTruth)]
        detector, topics = vehicle_detector_for_recording(rec, world)
        scans = [m for m in rec.messages(topics) if isinstance(m, LaserScan)]
    gt_t = np.array([g.t_ns for g in gts])
    res: dict[str, dict[str, Any]] = defaultdict(lambda: defaultdict(list))
    seen_scans: dict[str, int] = defaultdict(int)
    tracks: dict[tuple[str, int], list[int]] = defaultdict(list)
    for scan in scans:
        t0 = time.perf_counter()
        dets = detector(scan)
        dt_ms = (time.perf_counter() - t0) * 1e3
        seen_scans[scan.sensor] += 1
        if seen_scans[scan.sensor] <= n_skip_scans:
            continue
        r = res[scan.sensor]
        r["ms"].append(dt_ms)
        truth = truth_at(gts, gt_t, scan.t_ns)
        pose = detector._state(scan.sensor)  # the scanner's pose, for the returns in the road frame
        rng_m = scan.valid_ranges_m()
        ok = np.isfinite(rng_m)
        a = scan.angles_rad()[ok]
        pts = np.column_stack([rng_m[ok] * np.cos(a), rng_m[ok] * np.sin(a)]) @ pose.rotation.T + pose.translation
        n_on, two = visibility(pts, truth)
        visible = n_on >= 3
        r["visible"].append(int(visible.sum()))
        r["visible10"].append(int((n_on >= 10).sum()))
        r["dets"].append(len(dets))
        if not dets or len(truth["ids"]) == 0:
            continue
        centres = np.array([d.position_m for d in dets])
        cost = np.linalg.norm(centres[:, None] - truth["pos"][None], axis=2)
        pairs, _, _ = hungarian(cost, gate=2.0)
        r["matched_dets"].append(len(pairs))
        r["matched_visible"].append(int(visible[pairs[:, 1]].sum()))
        r["matched_visible10"].append(int((n_on[pairs[:, 1]] >= 10).sum()))
        for di, gi in pairs:
            d = dets[di]
            err = float(cost[di, gi])
            box = d.features["box"]
            dh = np.angle(np.exp(1j * (box[4] - truth["heading"][gi])))
            r["err"].append(err)
            r["cls"].append(truth["cls"][gi])
            r["cls_ok"].append(d.cls == truth["cls"][gi])
            r["two"].append(bool(two[gi]))
            r["prior"].append(bool(d.features["from_prior"].any()))
            r["dh_axis"].append(abs(np.rad2deg(np.angle(np.exp(2j * dh)) / 2)))
            if "velocity_mps" in d.features:
                r["sign_ok"].append(abs(dh) < np.pi / 2)
            tracks[(scan.sensor, int(truth["ids"][gi]))].append(int(d.features["track_id"][0]))
            # the same points, fit and heading completed with the class prior and with the true size
            p = d.features["points_m"]
            fit = fit_boxes(p, np.zeros(len(p), np.int64), pose.translation)
            _, axis = box_heading(fit, box[4:5], True, long_side_m=detector.long_side_m)
            prior = DEFAULT_PRIORS[d.cls]
            for key, prof in (("err_prior", (prior.profile_length_m, prior.profile_width_m)),
                              ("err_true", (truth["length"][gi], truth["width"][gi]))):
                c = complete_boxes(fit, pose.translation, axis, prof).centre_m[0]
                r[key].append(float(np.linalg.norm(c - truth["pos"][gi])))
    for (sensor, _), ids in tracks.items():
        res[sensor]["switches"].append(int(np.count_nonzero(np.diff(ids))))
        res[sensor]["vehicles"].append(1)
    return res


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--recording", type=Path, default=None, help="a simulated road recording folder")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rec_path = args.recording
        if rec_path is None:
            rec_path = Path(tmp) / "road"
            simulate(load_scenario("road").with_overrides(seconds=args.seconds, seed=args.seed,
                                                          settings={"cameras": []}), rec_path)
        res = evaluate(rec_path)
    console = Console(width=220)
    title = f"laser vehicles (D4) on {rec_path.name if args.recording else f'road {args.seconds:g} s seed {args.seed}'}"
    table = Table(title=title, header_style="bold")
    for col in ("laser", "recall", "recall >= 10 pts", "precision", "median err m", "p95 err m", "2-side cars med",
                "1-side med", "heading med °", "sign ok", "class ok", "id sw / veh", "ms/scan"):
        table.add_column(col, justify="right")
    for sensor in sorted(res):
        r = res[sensor]
        err = np.array(r["err"])
        two = np.array(r["two"], bool)
        car = np.array(r["cls"]) == "car"
        recall = sum(r["matched_visible"]) / max(sum(r["visible"]), 1)
        recall10 = sum(r["matched_visible10"]) / max(sum(r["visible10"]), 1)
        precision = sum(r["matched_dets"]) / max(sum(r["dets"]), 1)
        table.add_row(
            sensor, f"{recall:.3f}", f"{recall10:.3f}", f"{precision:.3f}", f"{np.median(err):.3f}",
            f"{np.percentile(err, 95):.3f}",
            f"{np.median(err[two & car]):.3f}", f"{np.median(err[~two & car]):.3f}",
            f"{np.median(r['dh_axis']):.2f}", f"{np.mean(r['sign_ok']):.3f}",
            f"{np.mean(r['cls_ok']):.3f}", f"{sum(r['switches']) / max(len(r['vehicles']), 1):.2f}",
            f"{np.median(r['ms']):.2f}")
    console.print(table)
    table = Table(title="centre error and partial views (mean, m)", header_style="bold")
    for col in ("laser", "paired", "seen on 1 side", "output", "class prior", "true size", "partial-view share",
                "1-side share of error"):
        table.add_column(col, justify="right")
    for sensor in sorted(res):
        r = res[sensor]
        err, pri, tru = np.array(r["err"]), np.array(r["err_prior"]), np.array(r["err_true"])
        two = np.array(r["two"], bool)
        table.add_row(sensor, str(err.size), f"{np.mean(~two):.0%}", f"{err.mean():.3f}", f"{pri.mean():.3f}",
                      f"{tru.mean():.3f}", f"{1.0 - tru.sum() / max(pri.sum(), 1e-12):.0%}",
                      f"{err[~two].sum() / max(err.sum(), 1e-12):.0%}")
    console.print(table)
    console.print("partial-view share: the part of the class-prior error that the true size removes; "
                  "1-side share: the part of the output's summed error from vehicles seen on one side only.")


if __name__ == "__main__":
    main()
