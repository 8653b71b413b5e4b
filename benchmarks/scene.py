"""Incident detection (ALGORITHMS.md D8, D9): rules and the learned forest against the simulator's incidents.

Simulates the built-in ``road`` scenario (no sensors: only the agents are needed) for ``--seconds`` with each of
``--seeds``, takes the agents as perfect tracks (and, with ``--noise``, the same tracks with Gaussian position and
velocity noise, like a tracker's output), runs the D8 rules and the learned forest, and prints per kind the true
incidents, detections, true positives, false alarms, precision, recall and latencies pooled over the seeds
(matching rule: ``fusiontrack.eval.events``). The early warning of road leaving is scored as its own row against
the road-leaving incidents. Targets (perfect tracks): precision and recall >= 0.9 per kind, median onset latency
<= 2 s.

    .venv/bin/python benchmarks/scene.py [--seeds 0 1 2] [--seconds 120] [--noise 0.2 0.2]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console

from fusiontrack.eval.events import EventScore, agent_tracks, event_table, read_agents_csv, read_incidents, score_events
from fusiontrack.scene import detect_events, detect_events_learned, road_geometry_from_world
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.types import Track, TrackState

KINDS = ("stopped_vehicle", "road_leaving", "jam", "wrong_way")


def noisy(tracks: list[Track], sigma_m: float, sigma_mps: float, rng: np.random.Generator) -> list[Track]:
    """The tracks with i.i.d. Gaussian noise on every position (``sigma_m``) and velocity component (``sigma_mps``)."""
    out = []
    for tr in tracks:
        n = len(tr.states)
        dp, dv = rng.normal(0, sigma_m, (n, 2)), rng.normal(0, sigma_mps, (n, 2))
        out.append(Track(tr.track_id, tuple(
            TrackState(s.t_ns, s.sensor, s.track_id, s.position_m + a, s.velocity_mps + b, cls=s.cls,
                       sensors=s.sensors) for s, a, b in zip(tr.states, dp, dv, strict=True))))
    return out


def pool(total: dict[str, EventScore], scores: dict[str, EventScore]) -> None:
    for kind, s in scores.items():
        total[kind] = total[kind] + s if kind in total else s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--seconds", type=float, default=120.0)
    parser.add_argument("--noise", type=float, nargs=2, default=[0.2, 0.2], metavar=("SIGMA_M", "SIGMA_MPS"),
                        help="position and velocity noise of the noisy-tracks variant (0 0: skip it)")
    args = parser.parse_args()
    console = Console(width=150)
    variants = ["perfect"] + (["noisy"] if any(args.noise) else [])
    methods = {"rules": detect_events, "learned": detect_events_learned}
    totals = {(v, m): {} for v in variants for m in methods}
    warnings: dict[str, dict[str, EventScore]] = {v: {} for v in variants}
    cpu = {m: 0.0 for m in methods}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            run = Path(tmp) / f"road_{seed}"
            scenario = load_scenario("road").with_overrides(seconds=args.seconds, seed=seed,
                                                            settings={"cameras": [], "lasers": []})
            simulate(scenario, run)
            geometry = road_geometry_from_world(run / "ground_truth" / "world.json")
            agents = read_agents_csv(run)
            incidents = read_incidents(run)
            perfect = agent_tracks(agents)
            inputs = {"perfect": perfect}
            if "noisy" in variants:
                inputs["noisy"] = noisy(perfect, args.noise[0], args.noise[1], np.random.default_rng(seed))
            for variant, tracks in inputs.items():
                for name, detect in methods.items():
                    t0 = time.process_time()
                    events = detect(tracks, geometry)
                    cpu[name] += time.process_time() - t0
                    pool(totals[variant, name], score_events(incidents, events, agents, kinds=KINDS))
                    if name == "rules":
                        pool(warnings[variant], score_events(
                            incidents, events, agents, kinds=("road_leaving",),
                            kind_map={"road_leaving_warning": "road_leaving", "road_leaving": "-"}))
            console.print(f"seed {seed}: {len(perfect)} vehicles, incidents "
                          + ", ".join(f"{e.kind} {e.t_ns * 1e-9 - 1.7e9:.1f} s" for e in incidents))
    for variant in variants:
        for name in methods:
            scores = dict(totals[variant, name])
            if name == "rules":
                scores["road_leaving (early warning)"] = warnings[variant]["road_leaving"]
            what = "ground-truth tracks" if variant == "perfect" else \
                f"noisy tracks (sigma {args.noise[0]:g} m, {args.noise[1]:g} m/s)"
            console.print(event_table(scores, title=f"{name} on {what}, seeds {args.seeds}, {args.seconds:g} s each"))
    n_runs = len(args.seeds) * len(variants)
    for name, seconds in cpu.items():
        console.print(f"{name}: {seconds / n_runs:.2f} s CPU per {args.seconds:g} s run "
                      f"({args.seconds * n_runs / max(seconds, 1e-9):.0f}x real time)")
    ok = all(s.precision >= 0.9 and s.recall >= 0.9 and s.median_latency_s <= 2.0
             for k, s in totals["perfect", "rules"].items() if s.true)
    console.print(f"rules on ground-truth tracks: precision, recall >= 0.9 and median onset latency <= 2 s per kind: "
                  f"{'yes' if ok else 'NO'}")


if __name__ == "__main__":
    main()
