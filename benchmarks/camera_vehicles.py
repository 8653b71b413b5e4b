"""The camera branch of the traffic pipeline (ALGORITHMS.md D3) against the simulator's truth.

For each camera of a simulated ``road`` recording (640x480 at 15 Hz, poles 9 m high looking along the road):

* detection recall and precision in the image: detections against the simulator's vehicle boxes
  (``/ground_truth/<camera>``) by Hungarian matching on IoU >= 0.5; vehicles less than half visible (occluded,
  or mostly outside the image) are neither missed when undetected nor false positives when detected;
* ground-position error of the matched detections against the true footprint centre, median and p95 by
  distance band from the camera, with and without the footprint-centre correction (without it the position is
  D3's plain bottom-centre under ``H_c``), and the fraction inside the 95 % ellipse of the reported covariance;
* the camera tracker: CLEAR MOT IDSW, MOTA and IDF1 (TrackEval, IoU >= 0.5, the less-than-half-visible vehicles
  as distractors) of the detections' ``track_id``;
* detection recall and precision on the road: footprint centres within D5's 2 m association gate of a true
  one (Hungarian on the distance), what the fusion needs of a detection;
* class accuracy (car / bicycle) of the matched detections, and frames per second (foreground + blobs +
  features + tracking, decode excluded);
* the image recall / precision per 10 s (the built-in scenario has a jam from ~45 s to ~100 s and camera_0's
  light drops at 70 s).

    .venv/bin/python benchmarks/camera_vehicles.py [--recording /tmp/road30] [--seconds 60 --seed 0]

Without ``--recording`` a ``road`` scenario of ``--seconds`` is simulated into a temporary folder (the
illumination drop of camera_0 is at 70 s in the built-in scenario; ``--drop-s`` moves it into a short run).
"""

from __future__ import annotations

import argparse
import itertools
import json
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from fusiontrack.eval import evaluate_boxes
from fusiontrack.io.recording import Recording
from fusiontrack.io.tracks import MotBoxes
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.tracking.association import hungarian
from fusiontrack.types import GroundTruth
from fusiontrack.vision import box_iou, camera_truth_boxes
from fusiontrack.vision.vehicles import VehicleDetectorParams, camera_homography, vehicle_detections_for_recording

BANDS_M = (0.0, 20.0, 40.0, 60.0, 80.0, np.inf)
MIN_VISIBILITY = 0.5
CHI2_95 = 5.991
GATE_M = 2.0


@dataclass
class CameraScore:
    """Matches of one camera's detections against the truth."""

    tp: int = 0
    fp: int = 0
    fn: int = 0
    g_tp: int = 0
    g_fp: int = 0
    g_fn: int = 0
    bins: dict[int, list[int]] = field(default_factory=dict)  # 10-s bin -> [tp, fp, fn] in the image
    err_m: list[float] = field(default_factory=list)
    err_raw_m: list[float] = field(default_factory=list)
    range_m: list[float] = field(default_factory=list)
    nees: list[float] = field(default_factory=list)
    cls_ok: list[bool] = field(default_factory=list)
    rows: list[list[float]] = field(default_factory=list)  # MOT rows: frame, id, l, t, w, h
    truth: list[GroundTruth] = field(default_factory=list)
    seconds: float = 0.0
    frames: int = 0
    processed: int = 0
    size: tuple[int, int] = (640, 480)

    @property
    def recall(self) -> float:
        return self.tp / max(self.tp + self.fn, 1)

    @property
    def precision(self) -> float:
        return self.tp / max(self.tp + self.fp, 1)

    @property
    def ground_recall(self) -> float:
        return self.g_tp / max(self.g_tp + self.g_fn, 1)

    @property
    def ground_precision(self) -> float:
        return self.g_tp / max(self.g_tp + self.g_fp, 1)


def read_roads(recording: Path) -> np.ndarray:
    """The roads ``(n, 5)`` of a simulated recording's ``ground_truth/world.json``."""
    with open(recording / "ground_truth" / "world.json") as f:
        return np.asarray(json.load(f)["roads"], np.float64).reshape(-1, 5)


def evaluate(recording: Path, params: VehicleDetectorParams | None = None, cameras: list[str] | None = None,
             start_s: float = 0.0) -> dict[str, CameraScore]:
    """Run the detector over the recording's cameras and score every frame after ``start_s``."""
    roads = read_roads(recording)
    with Recording(recording) as rec:
        names = cameras or sorted({rec.sensor_of(t) for t, i in rec.topics().items()
                                   if i.msgtype == "sensor_msgs/msg/CameraInfo"})
        truth: dict[str, dict[int, GroundTruth]] = {}
        sizes: dict[str, tuple[int, int]] = {}
        for name in names:
            truth[name] = {g.t_ns: g for g in rec.messages([f"/ground_truth/{name}"]) if isinstance(g, GroundTruth)}
            _, _, _, scores_size = camera_homography(rec, name)
            sizes[name] = scores_size
        scores = {name: CameraScore(size=sizes[name]) for name in names}
        frame_no = dict.fromkeys(names, 0)
        t0 = rec.start_ns
        timing: dict[str, float] = dict.fromkeys(names, 0.0)

        def timed(frame, seconds):
            timing[frame.sensor] += seconds

        for frame in vehicle_detections_for_recording(rec, roads, names, params, on_frame=timed):
            s = scores[frame.sensor]
            frame_no[frame.sensor] += 1
            s.processed += 1
            g = truth[frame.sensor].get(frame.t_ns)
            if g is None or (frame.t_ns - t0) * 1e-9 < start_s:
                continue
            s.frames += 1
            s.truth.append(g)
            before = (s.tp, s.fp, s.fn)
            _score_frame(s, frame.detections, g, s.frames, _camera_foot(rec, frame.sensor))
            b = s.bins.setdefault(int((frame.t_ns - t0) * 1e-9 // 10) * 10, [0, 0, 0])
            for i, (new, old) in enumerate(zip((s.tp, s.fp, s.fn), before, strict=True)):
                b[i] += new - old
        for name in names:
            scores[name].seconds = timing[name]
    return scores


_FEET: dict[str, np.ndarray] = {}


def _camera_foot(rec: Recording, name: str) -> np.ndarray:
    """The camera's position on the road plane (for distance bands)."""
    if name not in _FEET:
        from fusiontrack.vision import camera_from_recording

        _FEET[name] = camera_from_recording(rec, name, name).position_m[:2]
    return _FEET[name]


def _score_frame(s: CameraScore, detections, g: GroundTruth, frame: int, foot: np.ndarray) -> None:
    w, h = s.size
    tb = np.clip(np.asarray(g.attributes["box_px"], np.float64), 0, [w, h, w, h]).reshape(-1, 4)
    vis = np.asarray(g.attributes["visibility"], np.float64)
    present = np.all(np.isfinite(tb), axis=1) & (tb[:, 2] - tb[:, 0] >= 1) & (tb[:, 3] - tb[:, 1] >= 1)
    visible = present & (vis >= MIN_VISIBILITY)
    db = np.array([d.box_px for d in detections]).reshape(-1, 4)
    iou = box_iou(db, np.where(present[:, None], tb, 0.0))
    cost = np.where(iou >= 0.5, 1.0 - iou, np.inf)
    pairs, free_d, _ = hungarian(cost)
    matched_truth = np.zeros(len(tb), bool)
    for di, ti in pairs:
        matched_truth[ti] = True
        if not visible[ti]:
            continue  # a detection of a vehicle less than half visible: neither hit nor false positive
        s.tp += 1
        d = detections[di]
        true_xy = g.positions_m[ti]
        e = d.position_m - true_xy
        s.err_m.append(float(np.linalg.norm(e)))
        s.err_raw_m.append(float(np.linalg.norm(d.features["ground_point_m"] - true_xy)))
        s.range_m.append(float(np.linalg.norm(true_xy - foot)))
        s.nees.append(float(e @ np.linalg.solve(d.covariance_m2, e)))
        s.cls_ok.append(d.cls == g.classes[ti])
    for di in free_d:  # unmatched detections overlapping a barely visible vehicle are not counted
        if not np.any((iou[di] > 0.3) & present & ~visible):
            s.fp += 1
    s.fn += int(np.sum(visible & ~matched_truth))
    # on the road: footprint centres within D5's 2 m gate (what the fusion associates)
    pos = np.array([d.position_m for d in detections]).reshape(-1, 2)
    dist = np.linalg.norm(pos[:, None] - g.positions_m[None], axis=2)
    gpairs, gfree, _ = hungarian(np.where(dist <= GATE_M, dist, np.inf))
    gmatched = np.zeros(len(tb), bool)
    gmatched[gpairs[:, 1]] = True
    s.g_tp += int(np.sum(gmatched & visible))
    s.g_fn += int(np.sum(visible & ~gmatched))
    s.g_fp += len(gfree)
    for d in detections:
        b = d.box_px
        s.rows.append([frame, int(d.features["track_id"][0]), b[0], b[1], b[2] - b[0], b[3] - b[1]])


def mot_metrics(s: CameraScore):
    """TrackEval CLEAR/Identity of the detections' track ids (vehicles < half visible are distractors)."""
    w, h = s.size
    gt = camera_truth_boxes(s.truth, w, h, min_visibility=MIN_VISIBILITY)
    a = np.array(s.rows, np.float64).reshape(-1, 6)
    res = MotBoxes(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a[:, 2:6], np.ones(len(a)),
                   np.zeros((len(a), 0)))
    return evaluate_boxes(gt, res, preprocess=True, n_frames=s.frames)


def bin_table(scores: dict[str, CameraScore]) -> Table:
    t = Table(title="image recall / precision over time (10 s bins)")
    t.add_column("from (s)", justify="right")
    for name in scores:
        t.add_column(name, justify="right")
    for b in sorted({b for s in scores.values() for b in s.bins}):
        cells = []
        for s in scores.values():
            tp, fp, fn = s.bins.get(b, [0, 0, 0])
            cells.append(f"{tp / max(tp + fn, 1):.0%} / {tp / max(tp + fp, 1):.0%} ({tp + fn})")
        t.add_row(str(b), *cells)
    return t


def band_table(scores: dict[str, CameraScore], title: str) -> Table:
    t = Table(title=title)
    for c in ("camera", "range band (m)", "n", "median (m)", "p95 (m)", "median raw (m)", "p95 raw (m)",
              "in 95 % ellipse"):
        t.add_column(c, justify="right")
    for name, s in scores.items():
        r, e, er, nees = (np.asarray(v) for v in (s.range_m, s.err_m, s.err_raw_m, s.nees))
        for lo, hi in itertools.pairwise(BANDS_M):
            m = (r >= lo) & (r < hi)
            if not m.any():
                continue
            t.add_row(name, f"{lo:.0f}-{hi:.0f}" if np.isfinite(hi) else f">= {lo:.0f}", str(int(m.sum())),
                      f"{np.median(e[m]):.2f}", f"{np.percentile(e[m], 95):.2f}", f"{np.median(er[m]):.2f}",
                      f"{np.percentile(er[m], 95):.2f}", f"{np.mean(nees[m] <= CHI2_95):.0%}")
    return t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--recording", type=Path, help="a simulated road recording (default: simulate one)")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--drop-s", type=float, default=None, help="move camera_0's illumination drop to this time")
    ap.add_argument("--start-s", type=float, default=3.0, help="score frames after this time (MoG start-up)")
    ap.add_argument("--no-correction", action="store_true", help="plain bottom-centre ground points")
    ap.add_argument("--keep", type=Path, help="simulate into this folder (kept) instead of a temporary one")
    args = ap.parse_args()
    console = Console(width=170)
    params = VehicleDetectorParams(correct_footprint=not args.no_correction)
    with tempfile.TemporaryDirectory() as tmp:
        recording = args.recording
        if recording is None:
            settings: dict = {"lasers": []}
            if args.drop_s is not None:
                settings["cameras.0.illumination"] = [[args.drop_s, 0.55]]
            recording = args.keep or Path(tmp) / "road"
            tic = time.perf_counter()
            simulate(load_scenario("road").with_overrides(seconds=args.seconds, seed=args.seed, settings=settings),
                     recording)
            console.print(f"simulated {args.seconds:g} s of 'road' (seed {args.seed}) in "
                          f"{time.perf_counter() - tic:.0f} s")
        scores = evaluate(recording, params, start_s=args.start_s)
    t = Table(title=f"D3 camera branch on {recording.name if args.recording else 'road'} (IoU >= 0.5; "
                    f"frames after {args.start_s:g} s)")
    for c in ("camera", "frames", "recall", "precision", "road recall", "road precision", "median err (m)",
              "p95 err (m)", "class acc.", "IDSW", "MOTA", "IDF1", "fps"):
        t.add_column(c, justify="right")
    for name, s in scores.items():
        m = mot_metrics(s)
        e = np.asarray(s.err_m)
        t.add_row(name, str(s.frames), f"{s.recall:.1%}", f"{s.precision:.1%}", f"{s.ground_recall:.1%}",
                  f"{s.ground_precision:.1%}",
                  f"{np.median(e):.2f}" if e.size else "-", f"{np.percentile(e, 95):.2f}" if e.size else "-",
                  f"{np.mean(s.cls_ok):.1%}" if s.cls_ok else "-", str(m.id_switches), f"{m.mota:.1%}",
                  f"{m.idf1:.1%}", f"{s.processed / max(s.seconds, 1e-9):.0f}")
    console.print(t)
    console.print(bin_table(scores))
    console.print(band_table(scores, "ground error against the true footprint centre by distance from the camera "
                                     "(raw = D3's plain bottom-centre)"))


if __name__ == "__main__":
    main()
