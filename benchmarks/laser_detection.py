"""Laser detection speed: background + A8 + mean-shift + feet per frame on a simulated `crowd`
(2 scanners x 720 beams at 25 Hz, ~10 people), the same without the rigid objects (vehicles kept whole; none
in a crowd, so this is their cost), and our mean-shift against scikit-learn's MeanShift on the same points, in
this process.

    .venv/bin/python benchmarks/laser_detection.py [--seconds 20]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table
from sklearn.cluster import MeanShift

from fusiontrack.geometry import TransformTree
from fusiontrack.io.recording import Recording
from fusiontrack.laser.clustering import mean_shift_segments
from fusiontrack.laser.detector import LaserPeopleDetector
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rec_path = Path(tmp) / "crowd"
        simulate(load_scenario("crowd").with_overrides(seconds=args.seconds, settings={"cameras": []}), rec_path)
        with Recording(rec_path) as rec:
            tree = TransformTree()
            for tf in rec.messages(["/tf_static"]):
                tree.add_record(tf)
            scans = list(rec.messages(["/laser_0/scan", "/laser_1/scan"], time_source="log"))
    poses = {s: tree.get(s, "world") for s in ("laser_0", "laser_1")}
    detector = LaserPeopleDetector(poses)
    plain = LaserPeopleDetector(poses, rigid_min_m=None)
    frame_times, plain_times, n_dets, clouds = [], [], [], []
    for scan in scans:
        t0 = time.perf_counter()
        plain.update(scan)
        plain.detect(scan.t_ns)
        t1 = time.perf_counter()
        detector.update(scan)
        dets = detector.detect(scan.t_ns)
        frame_times.append(time.perf_counter() - t1)
        plain_times.append(t1 - t0)
        n_dets.append(len(dets))
        if dets and len(clouds) < 50 and scan.sensor == "laser_1":
            clouds.append(detector.foreground_points(scan.t_ns)[0])
    learned = np.array(frame_times[100:]) * 1e3  # after both backgrounds are initialised
    learned_plain = np.array(plain_times[100:]) * 1e3
    ours, theirs = [], []
    for pts in clouds:
        t0 = time.perf_counter()
        mean_shift_segments(pts)
        ours.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        MeanShift(bandwidth=0.4).fit(pts)
        theirs.append(time.perf_counter() - t0)
    table = Table(title=f"laser detection on {args.seconds:g} s of simulated crowd ({len(scans)} scans)",
                  header_style="bold")
    for col in ("what", "median ms", "p95 ms"):
        table.add_column(col, justify="left" if col == "what" else "right")
    table.add_row("update + detect per scan (2 scanners pooled)", f"{np.median(learned):.3f}",
                  f"{np.percentile(learned, 95):.3f}")
    table.add_row("  the same without rigid objects (rigid_min_m None)", f"{np.median(learned_plain):.3f}",
                  f"{np.percentile(learned_plain, 95):.3f}")
    table.add_row("mean-shift + feet (fusiontrack)", f"{np.median(ours) * 1e3:.3f}",
                  f"{np.percentile(ours, 95) * 1e3:.3f}")
    table.add_row("sklearn MeanShift(bandwidth=0.4)", f"{np.median(theirs) * 1e3:.3f}",
                  f"{np.percentile(theirs, 95) * 1e3:.3f}")
    console = Console(width=100)
    console.print(table)
    console.print(f"speed-up over scikit-learn: {np.median(theirs) / np.median(ours):.0f}x; "
                  f"detections per scan after learning: {np.mean(n_dets[100:]):.1f}")


if __name__ == "__main__":
    main()
