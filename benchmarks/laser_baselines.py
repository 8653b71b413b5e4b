"""Laser people tracking baselines (issue 4): Stone Soup's GNN + Kalman tracker against our constant-velocity
Kalman + Hungarian baseline and our walking-model particle-filter tracker, on the same laser detections.

For each simulated scenario (``crowd``, ``groups``) and seed the recording is simulated once and our laser
detector (:class:`fusiontrack.laser.LaserPeopleDetector`, built and fed exactly as
:func:`fusiontrack.tracking.tracker.track_recording` builds and feeds it) runs once; its detections are cached
per scan time and the very same :class:`~fusiontrack.types.Detection` objects are given to

- ``CV Kalman``: :class:`fusiontrack.tracking.baseline.CVKalmanTracker` with its defaults;
- ``PF (ours)``: :class:`fusiontrack.tracking.tracker.LaserPeopleTracker` (``lateral_m`` 0.2, as in
  ``laser_people.py``), and the same with its particle-filter step in numpy (``PF (ours), numpy step``: the
  reference code the numba kernels of ``tracking/_jit.py`` replace; the runs differ in the particles' draws, so
  identities may differ too);
- ``Stone Soup``: ``MultiTargetTracker`` built as the Stone Soup tutorials build a GNN + Kalman tracker
  (``ConstantVelocity`` x 2, ``LinearGaussian`` on (x, y), ``KalmanPredictor``, ``KalmanUpdater``,
  ``DistanceHypothesiser`` with ``Mahalanobis``, ``GNNWith2DAssignment``, ``MultiMeasurementInitiator``,
  ``UpdateTimeStepsDeleter``), fed by a detector that yields ``(time, set of Detection)``. Its noise,
  confirmation and deletion copy the CV Kalman's defaults (:func:`stone_soup_tracker`). Its gate is a
  Mahalanobis distance (``--ss-gate``, default 8: the best of 3-20 on crowd seeds 0-1 and groups seed 0,
  30 s; the tutorials' 3 is far too tight for the jitter of leg-segment centres, MOTA 0.3-0.4).
  ``--ss-measure euclidean`` (default gate 0.8 m) gates as our CV Kalman does, which leaves the two trackers
  differing only in initiation and checks the adapter: their MOTA then agree within ~0.01.

Every tracker's output is scored identically (:func:`fusiontrack.eval.evaluate_floor`, match 0.5 m). Only the
tracker step is timed (``time.perf_counter`` per scan; the first tenth of the scans, while the backgrounds are
learnt and no track exists, is left out, as in ``laser_people.py``). For Stone Soup the step is one
``next(tracker)``: building its ``Detection`` objects from ours and turning its tracks into
:class:`~fusiontrack.types.TrackState` records are done outside the clock, which favours Stone Soup. The ratio
column is Stone Soup's median time per scan over the tracker's.

Stone Soup is an optional extra, installed only for this benchmark: ``pip install -e '.[stonesoup]'``.
The default run takes about 3 minutes on 2 cores, most of it in Stone Soup (~20 s per crowd seed) and in the
simulator.

    .venv/bin/python benchmarks/laser_baselines.py [--seeds 0 1 2] [--crowd-seconds 60] [--groups-seconds 40]
        [--ss-measure mahalanobis|euclidean] [--ss-gate 8]
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import math
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from fusiontrack.eval import evaluate_floor
from fusiontrack.io.recording import LASERSCAN, Recording
from fusiontrack.io.sync import synchronize
from fusiontrack.laser.detector import detector_for_recording
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import Simulation, simulate
from fusiontrack.tracking import _jit
from fusiontrack.tracking.baseline import CVKalmanTracker
from fusiontrack.tracking.tracker import LaserPeopleTracker
from fusiontrack.types import Detection, GroundTruth, TrackState

SIM_PF = {"lateral_m": 0.2}  # the simulator's feet are 0.2 m apart side by side
MATCH_M = 0.5
TRACKERS = ("kalman", "pf", "pf_numpy", "stonesoup")
LABELS = {"kalman": "CV Kalman (ours)", "pf": "PF (ours)", "pf_numpy": "PF (ours), numpy step",
          "stonesoup": "Stone Soup GNN"}
EPOCH = datetime.datetime(1970, 1, 1)
Frames = list[tuple[int, list[Detection]]]


def _require_stonesoup() -> str:
    try:
        import stonesoup
    except ImportError as err:
        raise SystemExit("laser_baselines.py needs Stone Soup, an optional extra of fusiontrack: "
                         "pip install -e '.[stonesoup]'") from err
    return str(getattr(stonesoup, "__version__", "?"))


def _ms(values: Sequence[float]) -> tuple[float, float]:
    skip = len(values) // 10  # once the backgrounds are learnt and tracks exist
    a = np.asarray(values[skip:] or values) * 1e3
    return float(np.median(a)), float(np.percentile(a, 95))


def detect_recording(path: Path, clock_corrections_ns: dict[str, int]) -> Frames:
    """Our laser detections of a recording, per scan time: ``track_recording``'s detector loop.

    The same detector (posed by ``/tf_static`` to ``world``, default parameters, learnt backgrounds), the same
    synchronised stream and the same rule (detect once the next scan has another time stamp) as
    :func:`fusiontrack.tracking.tracker.track_recording` with ``area_m`` given, ``time_source="header"``.
    """
    with Recording(path) as rec:
        lasers = [t for t, i in rec.topics().items() if i.msgtype == LASERSCAN]
        detector, _ = detector_for_recording(rec, lasers)
        frames: Frames = []
        pending_t: int | None = None
        for scan in synchronize(rec.messages(lasers), clock_corrections_ns=clock_corrections_ns):
            if pending_t is not None and scan.t_ns != pending_t:
                frames.append((pending_t, detector.detect(pending_t)))
            detector.update(scan)
            pending_t = scan.t_ns
        if pending_t is not None:
            frames.append((pending_t, detector.detect(pending_t)))
    return frames


@contextlib.contextmanager
def numpy_step() -> Iterator[None]:
    """The laser tracker's particle-filter step in numpy (its reference code), not by the numba kernels."""
    was = _jit.ENABLED
    _jit.ENABLED = False
    try:
        yield
    finally:
        _jit.ENABLED = was


def replay(step: Callable[[int, list[Detection]], list[TrackState]], frames: Frames
           ) -> tuple[list[TrackState], list[float]]:
    """Step a tracker through the cached detections; the states and the seconds of each step."""
    states: list[TrackState] = []
    seconds: list[float] = []
    for t_ns, dets in frames:
        t0 = time.perf_counter()
        out = step(t_ns, dets)
        seconds.append(time.perf_counter() - t0)
        states.extend(out)
    return states, seconds


def stone_soup_tracker(detector: Any, step_s: float, *, gate: float, measure: str = "mahalanobis") -> Any:
    """Stone Soup's GNN + Kalman multi-target tracker as its tutorials build it, tuned like our CV Kalman.

    Our baseline's defaults, in Stone Soup's terms (state order ``(x, vx, y, vy)``): ``q`` = 2 m²/s³ per axis;
    ``R = 0.05² I``; initial velocity σ 0.5 m/s; a candidate confirmed once seen for
    ``(n_confirm - 1) · frame_s`` = 80 ms (``min_points`` updates at ``step_s`` per scan) and dropped after a
    gap of 0.25 s; a track ended after ``n_miss · frame_s`` = 1 s without a detection. ``UpdateTimeStepsDeleter``
    counts tracker steps, so the times are turned into steps of ``step_s`` (the mean scan interval).

    Parameters
    ----------
    detector : iterable of (datetime, set of stonesoup Detection)
    step_s : float
        Mean time between scans, s.
    gate : float
        Distance of a missed detection (no pair farther than it).
    measure : ``"mahalanobis"`` or ``"euclidean"``
        Distance between the predicted measurement and a detection (Euclidean: metres in (x, y)).
    """
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.deleter.time import UpdateTimeStepsDeleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Euclidean, Mahalanobis
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.tracker.simple import MultiTargetTracker
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import KalmanUpdater

    base = CVKalmanTracker()
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(base.q), ConstantVelocity(base.q)])
    predictor = KalmanPredictor(transition)
    updater = KalmanUpdater(_measurement_model(base.r_m))
    dist = Mahalanobis() if measure == "mahalanobis" else Euclidean(mapping=(0, 1))  # measurement space (x, y)
    hypothesiser = DistanceHypothesiser(predictor, updater, measure=dist, missed_distance=gate)
    associator = GNNWith2DAssignment(hypothesiser)
    confirm_s = (base.n_confirm - 1) * base.frame_s
    initiator = MultiMeasurementInitiator(
        prior_state=GaussianState(np.zeros((4, 1)), np.diag([0.0, 0.5**2, 0.0, 0.5**2])),
        measurement_model=updater.measurement_model, deleter=UpdateTimeStepsDeleter(max(1, round(0.25 / step_s))),
        data_associator=associator, updater=updater, min_points=1 + max(1, round(confirm_s / step_s)))
    deleter = UpdateTimeStepsDeleter(max(1, round(base.n_miss * base.frame_s / step_s)))
    return MultiTargetTracker(initiator=initiator, deleter=deleter, detector=detector,
                              data_associator=associator, updater=updater)


def _measurement_model(r_m: float) -> Any:
    from stonesoup.models.measurement.linear import LinearGaussian

    return LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.eye(2) * r_m**2)


def run_stone_soup(frames: Frames, gate: float, measure: str = "mahalanobis"
                   ) -> tuple[list[TrackState], list[float], dict[str, Any]]:
    """Stone Soup on the cached detections: its states as TrackState records, seconds per step, notes."""
    from stonesoup.types.detection import Detection as SSDetection
    from stonesoup.types.update import Update

    model = _measurement_model(CVKalmanTracker().r_m)
    stamps = [EPOCH + datetime.timedelta(microseconds=t_ns // 1000) for t_ns, _ in frames]
    ss_frames = [(ts, {SSDetection(d.position_m.reshape(2, 1), timestamp=ts, measurement_model=model)
                       for d in dets})
                 for ts, (_, dets) in zip(stamps, frames, strict=True)]
    step_s = (frames[-1][0] - frames[0][0]) / 1e9 / (len(frames) - 1) if len(frames) > 1 else 0.04
    tracker = stone_soup_tracker(iter(ss_frames), step_s, gate=gate, measure=measure)
    it = iter(tracker)
    ids: dict[str, int] = {}  # Stone Soup's track ids are uuid strings; ours are the tracker's own integers
    states: list[TrackState] = []
    seconds: list[float] = []
    order = [0, 2, 1, 3]  # (x, vx, y, vy) -> (x, y, vx, vy)
    for (t_ns, _), ts in zip(frames, stamps, strict=True):
        t0 = time.perf_counter()
        _, tracks = next(it)
        seconds.append(time.perf_counter() - t0)
        for track in tracks:
            s = track.state
            x = np.asarray(s.state_vector, float).ravel()[order]
            tid = ids.setdefault(track.id, len(ids) + 1)
            measured = isinstance(s, Update) and s.timestamp == ts
            states.append(TrackState(t_ns, "stonesoup", tid, x[0:2], x[2:4],
                                     covariance=np.asarray(s.covar, float)[np.ix_(order, order)],
                                     sensors=("laser",) if measured else ()))
    notes = {"tracks": len(ids), "step_s": step_s, "distinct_stamps": len(set(stamps)) == len(stamps)}
    return states, seconds, notes


def run_case(name: str, seconds: float, seed: int, tmp: Path, ss: dict[str, Any], console: Console
             ) -> dict[str, Any]:
    t_start = time.perf_counter()
    scenario = load_scenario(name).with_overrides(seconds=seconds, seed=seed, settings={"cameras": []})
    path = tmp / f"{name}_{seed}_{int(seconds)}"
    sim = simulate(scenario, path)
    bounds = Simulation(scenario).world.bounds_m
    corrections = {c.name: -round(c.clock_offset_ms * 1e6) for c in scenario.config.lasers}
    with Recording(path) as rec:
        gt: list[GroundTruth] = list(rec.messages(["/ground_truth"]))
    t_sim = time.perf_counter()
    frames = detect_recording(path, corrections)
    t_det = time.perf_counter()
    out: dict[str, Any] = {"mean_present": sim.mean_present, "scans": len(frames),
                           "detections": sum(len(d) for _, d in frames),
                           "empty": sum(not d for _, d in frames)}
    runs: dict[str, tuple[list[TrackState], list[float]]] = {
        "kalman": replay(CVKalmanTracker(area_m=bounds).step, frames),
        "pf": replay(LaserPeopleTracker(SIM_PF, area_m=bounds, rng=0).step, frames),
    }
    with numpy_step():  # the same tracker with its particle-filter step in numpy, not compiled (tracking/_jit.py)
        runs["pf_numpy"] = replay(LaserPeopleTracker(SIM_PF, area_m=bounds, rng=0).step, frames)
    ss_states, ss_seconds, out["ss_notes"] = run_stone_soup(frames, **ss)
    runs["stonesoup"] = (ss_states, ss_seconds)
    for trk, (states, secs) in runs.items():
        out[trk] = {"m": evaluate_floor(gt, states, MATCH_M), "ms": _ms(secs), "total_s": float(np.sum(secs))}
    console.log(f"{name} seed {seed}: simulate {t_sim - t_start:.0f} s, detect {t_det - t_sim:.0f} s, track "
                + ", ".join(f"{trk} {out[trk]['total_s']:.1f} s" for trk in TRACKERS)
                + f"; {len(frames)} scans, {out['detections']} detections, {out['empty']} empty scans")
    return out


def _ratio(ss_ms: float, ms: float) -> str:
    return f"{ss_ms / ms:.1f}x" if ms > 0 else "-"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--crowd-seconds", type=float, default=60.0)
    parser.add_argument("--groups-seconds", type=float, default=40.0)
    parser.add_argument("--ss-measure", choices=("mahalanobis", "euclidean"), default="mahalanobis",
                        help="Stone Soup's association distance")
    parser.add_argument("--ss-gate", type=float, default=None,
                        help="Stone Soup's gate (missed_distance): default 8 (Mahalanobis) or 0.8 m (Euclidean)")
    args = parser.parse_args()
    gate = args.ss_gate if args.ss_gate is not None else (8.0 if args.ss_measure == "mahalanobis" else 0.8)
    if not (math.isfinite(gate) and gate > 0):
        parser.error(f"--ss-gate: expected a finite value > 0, got {gate}")
    ss = {"gate": gate, "measure": args.ss_measure}
    version = _require_stonesoup()
    console = Console(width=200)
    t_start = time.perf_counter()
    verdicts: dict[str, list[bool]] = {"kalman": [], "pf": []}
    with tempfile.TemporaryDirectory() as tmp_name:
        for name, secs in (("crowd", args.crowd_seconds), ("groups", args.groups_seconds)):
            results = {seed: run_case(name, secs, seed, Path(tmp_name), ss, console) for seed in args.seeds}
            people = np.mean([r["mean_present"] for r in results.values()])
            table = Table(title=f"{name}: {secs:g} s, mean {people:.1f} people present, 2 scanners x 25 Hz, the same "
                                f"cached detections for every tracker; match {MATCH_M:g} m; Stone Soup {version}, "
                                f"{args.ss_measure} gate {gate:g}", header_style="bold")
            for col in ("seed", "tracker", "MOTA", "IDF1", "HOTA", "IDSW", "FP", "FN", "ms/scan med", "ms/scan p95",
                        "Stone Soup / this"):
                table.add_column(col, justify="left" if col == "tracker" else "right")
            for seed, r in results.items():
                for trk in TRACKERS:
                    m, (med, p95) = r[trk]["m"], r[trk]["ms"]
                    table.add_row(str(seed), LABELS[trk], f"{m.mota:.3f}", f"{m.idf1:.3f}", f"{m.hota:.3f}",
                                  str(m.id_switches), str(m.fp), str(m.fn), f"{med:.3f}", f"{p95:.3f}",
                                  _ratio(r["stonesoup"]["ms"][0], med))
            agg = {trk: [r[trk] for r in results.values()] for trk in TRACKERS}
            mean_mota = {trk: float(np.mean([x["m"].mota for x in rs])) for trk, rs in agg.items()}
            mean_med = {trk: float(np.mean([x["ms"][0] for x in rs])) for trk, rs in agg.items()}
            for trk, rs in agg.items():
                table.add_row("mean", LABELS[trk], f"{mean_mota[trk]:.3f}",
                              f"{np.mean([x['m'].idf1 for x in rs]):.3f}", f"{np.mean([x['m'].hota for x in rs]):.3f}",
                              str(sum(x["m"].id_switches for x in rs)), str(sum(x["m"].fp for x in rs)),
                              str(sum(x["m"].fn for x in rs)), f"{mean_med[trk]:.3f}",
                              f"{np.mean([x['ms'][1] for x in rs]):.3f}", _ratio(mean_med["stonesoup"], mean_med[trk]),
                              style="bold")
            console.print(table)
            notes = [r["ss_notes"] for r in results.values()]
            console.print(f"  Stone Soup: {sum(n['tracks'] for n in notes)} confirmed tracks over the seeds, mean step "
                          f"{np.median([n['step_s'] for n in notes]) * 1e3:.1f} ms, scan stamps distinct at 1 µs: "
                          f"{all(n['distinct_stamps'] for n in notes)}")
            for trk in ("kalman", "pf"):
                ratio = mean_med["stonesoup"] / mean_med[trk]
                ok = ratio >= 10.0 and mean_mota[trk] >= mean_mota["stonesoup"]
                verdicts[trk].append(ok)
                console.print(f"  {LABELS[trk]}: {ratio:.1f}x faster than Stone Soup (median ms/scan), MOTA "
                              f"{mean_mota[trk]:.3f} vs {mean_mota['stonesoup']:.3f}: {'PASS' if ok else 'FAIL'}")
            console.print(f"  PF step compiled (numba) vs numpy: {mean_med['pf_numpy'] / mean_med['pf']:.2f}x faster "
                          f"(median ms/scan {mean_med['pf']:.3f} vs {mean_med['pf_numpy']:.3f})"
                          + ("" if _jit.ENABLED else " [numba off: both numpy]"))
    for trk in ("kalman", "pf"):
        ok = all(verdicts[trk])
        console.print(f"[bold]verdict: {LABELS[trk]} is {'' if ok else 'NOT '}>= 10x faster than Stone Soup at >= "
                      f"MOTA in every scenario (means over seeds {args.seeds})[/bold]")
    console.print(f"total {time.perf_counter() - t_start:.0f} s")


if __name__ == "__main__":
    main()
