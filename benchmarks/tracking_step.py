"""One particle-filter step of the laser people tracker (B8 predict + B9 likelihood + X1 resampling)
for 5-80 targets of 100 particles, and the association + situation switch (B6, B7), timed in this
process. Issue 4's budget is 2 ms per scan for the whole tracker with 10 people; growth with the
number of targets should be close to linear.

    .venv/bin/python benchmarks/tracking_step.py
"""

from __future__ import annotations

import timeit

import numpy as np
from rich.console import Console
from rich.table import Table

from fusiontrack.tracking import association as asc
from fusiontrack.tracking import likelihood as lk
from fusiontrack.tracking import pf
from fusiontrack.tracking import situations as sit
from fusiontrack.tracking import walking as wk


def measure(n_targets: int, n_particles: int = 100) -> tuple[float, float]:
    rng = np.random.default_rng(0)
    feet = rng.uniform(0, 20, size=(n_targets, 2, 2))
    state = wk.init_walking(feet, n_particles, rng)
    weights = pf.uniform_weights(n_targets, n_particles)
    obs = feet + 0.05
    inter_feet = np.linalg.norm(obs[:, 0] - obs[:, 1], axis=1)
    one_foot = np.zeros(n_targets, bool)
    dets = obs.mean(axis=1)

    def step() -> None:
        x = wk.predict_walking(state, 0.04, rng)
        w, _ = pf.reweight(weights, lk.laser_log_likelihood(x, obs, inter_feet, one_foot))
        pf.resample_where(x, w, True, rng)

    def associate() -> None:
        D = asc.gate_distances(dets, dets, 0.4)
        c, r, found = asc.association_states(D)
        none = np.zeros(n_targets, bool)
        sit.classify_situations(c, r, found, none, none, none, D)

    def best(fn, number: int = 100) -> float:
        return min(timeit.repeat(fn, number=number, repeat=7)) / number

    return best(step), best(associate)


def main() -> None:
    table = Table(title="tracking step, 100 particles per target (best of 7 x 100)", header_style="bold")
    for col in ("targets", "PF step ms", "association + situations ms", "PF ms per target"):
        table.add_column(col, justify="right")
    for n in (5, 10, 20, 40, 80):
        pf_s, assoc_s = measure(n)
        table.add_row(str(n), f"{pf_s * 1e3:.3f}", f"{assoc_s * 1e3:.3f}", f"{pf_s * 1e3 / n:.4f}")
    Console(width=100).print(table)


if __name__ == "__main__":
    main()
