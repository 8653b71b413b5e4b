"""Simulation speed: 60 s of the built-in `crowd` (about 10 people, 2 lasers at 25 Hz with 720 beams,
one 640x480 camera at 15 Hz) must simulate in no more than 60 s (>= 1x real time) with peak memory
under 1 GB. Prints the time spent per part (agents, each sensor, ground truth) and the real-time factor.

    .venv/bin/python benchmarks/simulate.py [--scenario crowd] [--seconds 60] [--seed 0]
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="crowd")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    scenario = load_scenario(args.scenario).with_overrides(seconds=args.seconds, seed=args.seed)
    cfg = scenario.config
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        result = simulate(scenario, Path(tmp) / "rec")
        wall = time.perf_counter() - t0
        size_mb = sum(p.stat().st_size for p in (Path(tmp) / "rec").rglob("*") if p.is_file()) / 1e6
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    console = Console(width=110)
    sensors = {s.name: s for s in [*cfg.lasers, *cfg.cameras, *cfg.phones]}
    table = Table(title=f"simulate {scenario.name}: {args.seconds:g} s simulated, seed {args.seed}",
                  header_style="bold")
    for col in ("part", "what", "messages", "seconds", "ms / message", "share"):
        table.add_column(col, justify="left" if col in ("part", "what") else "right")
    for part, seconds in sorted(result.seconds.items(), key=lambda kv: -kv[1]):
        n = result.messages.get(part, 0)
        s = sensors.get(part)
        if s is None:
            what = "social force + gait" if part == "agents" else "labels, CSV"
        elif hasattr(s, "n_beams"):
            what = f"laser {s.n_beams} beams @ {s.rate_hz:g} Hz"
        elif hasattr(s, "width"):
            what = f"camera {s.width}x{s.height} @ {s.rate_hz:g} Hz" + (" + depth" if s.depth else "")
        else:
            what = f"phone IMU @ {s.rate_hz:g} Hz"
        table.add_row(part, what, str(n) if n else "-", f"{seconds:.2f}",
                      f"{1e3 * seconds / n:.2f}" if n else "-", f"{seconds / wall:.0%}")
    table.add_row("[bold]total", "", str(sum(result.messages.values())), f"[bold]{wall:.2f}", "", "")
    console.print(table)
    console.print(f"real-time factor {args.seconds / wall:.2f}x (>= 1 required); peak memory {peak_mb:.0f} MB "
                  f"(< 1024 required); recording {size_mb:.0f} MB; {result.n_agents} agents, "
                  f"{result.mean_present:.1f} present on average")


if __name__ == "__main__":
    main()
