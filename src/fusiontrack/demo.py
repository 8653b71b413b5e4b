"""The people half of ``fusiontrack demo``: one simulated crowd tracked three ways, with the evidence in one report.

:func:`people_comparison` takes a simulated recording whose camera is off its calibration (``crowd``: 3°) and

1. learns the camera's horizontal bias against the lasers (seed 000, ``calibration/bias_run.py``);
2. tracks the people with the lasers only (seed 001's particle filters), with the camera only (blobs, floor
   positions through the *corrected* camera; overlay video) and with both (seed 001's tracking-learning loop,
   again through the corrected camera);
3. scores the three against the ground truth (0.5 m) and writes ``report.html``: the metrics table, the bias
   convergence plot, the time-cost table and the videos.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from .io.recording import Recording
from .types import GroundTruth, TrackState

__all__ = ["people_comparison"]


def _truth(path: Path) -> list[GroundTruth]:
    with Recording(path) as rec:
        return [g for g in rec.messages(["/ground_truth"]) if isinstance(g, GroundTruth)]


def _frames(states: list[TrackState]) -> int:
    return len({s.t_ns for s in states})


def people_comparison(recording: str | Path, output: str | Path, *, camera: str = "camera_0",
                      true_bias_deg: float | None = None, laser_video: str | None = None,
                      laser_states: list[TrackState] | None = None, laser_time_s: float | None = None
                      ) -> dict[str, Any]:
    """Run the comparison (module docstring); returns the summary written into the report.

    ``laser_states`` (with ``laser_time_s``): the laser-only run, when the caller already has it.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from .calibration.bias_run import bias_from_recording
    from .eval import evaluate_floor, truth_at
    from .fusion import camera_boxes, track_fused
    from .tracking.tracker import track_recording
    from .vision.people import track_camera
    from .viz.report import Report

    recording, output = Path(recording), Path(output)
    output.mkdir(parents=True, exist_ok=True)
    truth = _truth(recording)
    times: dict[str, float] = {}

    tic = time.perf_counter()
    bias = bias_from_recording(recording, camera)
    times["bias (seed 000)"] = time.perf_counter() - tic
    corrected = bias.corrected_camera

    runs: dict[str, list[TrackState]] = {}
    if laser_states is None:
        tic = time.perf_counter()
        laser_states, _ = track_recording(recording)
        laser_time_s = time.perf_counter() - tic
    runs["laser only"] = laser_states
    times["laser only"] = laser_time_s if laser_time_s is not None else math.nan
    tic = time.perf_counter()
    runs["camera only"], _, cam_stats = track_camera(recording, camera=corrected,
                                                     overlay=output / "camera_overlay.mp4")
    times["camera only"] = time.perf_counter() - tic
    tic = time.perf_counter()
    runs["fusion"], fevents, fstats = track_fused(recording, camera=corrected, adaptive_bias=False)  # learnt above
    times["fusion"] = time.perf_counter() - tic
    runs["fusion"] = camera_boxes(runs["fusion"], fstats)  # the boxes where fusion read the camera
    from .viz.fused_overlay import render_fused_overlay

    # the laser points through the camera as corrected at each instant: off by the misalignment at first, on the
    # people once the bias has been learnt (the boxes: where fusion read the camera, through the learnt bias)
    render_fused_overlay(recording, output / "fusion_overlay.mp4", runs["fusion"], camera=camera, bias_history=bias,
                         events=fevents)

    # camera-only reports at the camera's rate: scored on the truth frames nearest to its images (truth_at), not
    # on the frames between them, where it has no report and would miss everybody
    at_camera = truth_at(truth, cam_stats.frame_times_ns) if len(cam_stats.frame_times_ns) else truth
    metrics = {k: evaluate_floor(at_camera if k == "camera only" else truth, v, threshold_m=0.5)
               for k, v in runs.items()}
    # IDF1 ceiling: the IDF1 of the same positions with perfect identities (Metrics.idf1_ceiling), so the report
    # shows which part of a pipeline's IDF1 loss is identity errors and which is detection errors
    rows = [{"pipeline": k, "MOTA": m.mota, "IDF1": m.idf1, "IDF1 ceiling": m.idf1_ceiling, "HOTA": m.hota,
             "ID switches": m.id_switches, "FP": m.fp, "FN": m.fn} for k, m in metrics.items()]
    n_scans = max(_frames(runs["laser only"]), 1)
    cost = [{"part": k, "seconds": v, "ms per laser tracking step": 1e3 * v / n_scans} for k, v in times.items()]

    h = bias.history
    t = (h.t_ns - h.t_ns[0]) / 1e9 if len(h) else np.zeros(0)
    fig, ax = plt.subplots(figsize=(8, 3))
    ax.plot(t, np.degrees(h.bias_rad), label="learnt bias")
    if true_bias_deg is not None:
        ax.axhline(true_bias_deg, color="k", ls="--", lw=1, label=f"true misalignment {true_bias_deg:g}°")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("bias (deg)")
    ax.legend()
    ax.grid(alpha=0.3)

    final = math.degrees(bias.bias_rad)
    rep = Report(f"fusiontrack demo — people in a simulated crowd ({recording.name})")
    rep.text(None, f"A camera {true_bias_deg if true_bias_deg is not None else '?'}° off its calibration and two "
                   f"lasers. The bias learnt from the people both sensors see ends at {final:.3f}°; the camera-only "
                   "and fused pipelines use the corrected camera.")
    rep.table("Tracking against ground truth (match within 0.5 m)", rows,
              note="camera only is scored on the ground-truth frames nearest to its camera's images (it reports "
                   "at the camera's rate); the others on every ground-truth frame.")
    rep.figure("Camera bias convergence (seed 000)", fig)
    rep.table("Time cost", cost, note=f"fusion read {fstats.frames_used} camera images of {cam_stats.n_frames}; "
                                      f"time on the camera side {fstats.camera_s:.2f} s.")
    if laser_video:
        rep.video("Bird's-eye view: lasers, truth and laser tracks", laser_video)
    rep.video("Fusion overlay: laser points projected through the camera as the bias corrects it (live bias top "
              "right), fused tracks with their ids, situations and confirming sensors", "fusion_overlay.mp4")
    rep.video("Camera overlay: camera-only tracks, foreground contours", "camera_overlay.mp4")
    rep.write(output / "report.html")
    return {"bias_deg": final, "metrics": {k: m.to_dict() for k, m in metrics.items()}, "time_s": times,
            "camera_frames_read_by_fusion": fstats.frames_used, "camera_frames": cam_stats.n_frames}
