"""``fusiontrack track --pipeline traffic``: run the traffic pipeline and write its evidence.

Writes into the output folder:

* ``tracks.csv``, ``tracks.jsonl`` — the fused particle-filter tracks (states, then the tracker's events);
* ``events.jsonl`` — scene understanding's incidents (D8: stopped vehicle, road leaving and its early warning,
  jam, wrong way), each with onset ``t_ns``, ``t_end_ns`` (``None`` if still open), place and tracks;
* ``summary.json`` — sensors, detections per sensor, the fusion instants each sensor took part in, time spent per
  part (reading and decoding the recording included) and the speed against real time it gives, and, when the
  recording has ground truth (a simulation), the metrics of every variant and the incident scores;
* ``report.html`` — the same as tables, the events on a timeline (against the true incidents when known) and the
  bird's-eye video ``tracks.mp4`` (``video=True``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io.datafile import json_text
from ..io.recording import Recording
from ..io.tracks import write_jsonl, write_tracks_csv
from ..types import GroundTruth
from .traffic import VARIANTS, TrafficParams, TrafficResult, track_traffic

log = logging.getLogger(__name__)

__all__ = ["evaluate_traffic", "run_traffic"]


def _truth(path: Path) -> list[GroundTruth]:
    with Recording(path) as rec:
        if "/ground_truth" not in rec.topic_types():
            return []
        return [g for g in rec.messages(["/ground_truth"]) if isinstance(g, GroundTruth)]


def evaluate_traffic(result: TrafficResult, path: str | Path, *, area: Any = None, threshold_m: float = 2.0,
                     rate_hz: float | None = None) -> dict[str, Any]:
    """Metrics of every variant against the recording's ``/ground_truth`` and incident scores (when it has them).

    ``area`` (a polygon) limits the scored vehicles and tracks; ``None`` scores the whole scene (the CLI passes the
    roads with a 3 m verge: vehicles no sensor can see near the road's far ends then count as missed).
    """
    from ..eval.events import read_agents_csv, read_incidents, score_events
    from ..eval.vehicles import evaluate_vehicles

    path = Path(path)
    frames = _truth(path)
    out: dict[str, Any] = {}
    if frames:
        out["metrics"] = {}
        for v, states in result.states.items():
            m = evaluate_vehicles(frames, states, area=area, threshold_m=threshold_m, rate_hz=rate_hz)
            out["metrics"][v] = {"MOTA": m.mota, "IDF1": m.idf1, "HOTA": m.hota, "IDSW": m.id_switches,
                                 "FP": m.fp, "FN": m.fn, "MOTP_m": (1 - m.motp) * 2 * threshold_m,
                                 "gt_objects": m.num_gt_ids, "tracks": m.num_tracker_ids}
    inc = path / "ground_truth" / "incidents.jsonl"
    if inc.is_file():
        agents = read_agents_csv(path)
        scores = score_events(read_incidents(path), result.scene_events, agents,
                              kind_map={"road_leaving_warning": "road_leaving_warning"})
        out["incidents"] = {k: {"true": s.true, "detections": s.detections, "hits": s.true_positives,
                                "false_alarms": s.false_alarms,
                                "onset_latency_s": float(np.median(s.onset_latency_s)) if s.onset_latency_s else None,
                                "alarm_latency_s": float(np.median(s.alarm_latency_s)) if s.alarm_latency_s else None}
                            for k, s in scores.items()}
    return out


def run_traffic(recording: str | Path, output: str | Path, *, geometry: Any = None, rules: Any = None,
                params: TrafficParams | None = None, compare: bool = False, video: bool = True,
                time_source: str = "header", progress: Callable[[float], None] | None = None,
                variants: Sequence[str] | None = None, calibration: Any = None,
                scene_engine: str = "rules") -> dict[str, Any]:
    """Track, write the outputs (module docstring) and return the summary.

    ``compare`` also runs the camera-only, laser-only and fusion-without-particle-filter variants (scored when
    the recording has ground truth). ``calibration`` (a :class:`~fusiontrack.calibration.road.RoadCalibration`
    or its JSON file, from ``fusiontrack calibrate-road``) poses the sensors it names instead of the
    recording's ``/tf_static``; its residuals go into the summary and the report. ``scene_engine``: ``"rules"``
    (D8) or ``"learned"`` (:func:`~fusiontrack.fusion.traffic.track_traffic`).
    """
    if isinstance(calibration, str | Path):
        from ..calibration.road import RoadCalibration

        calibration = RoadCalibration.load(calibration)
    recording, output = Path(recording), Path(output)
    p = params or TrafficParams()
    if variants is None:
        variants = tuple(VARIANTS) if compare else ("fusion_pf",)
    result = track_traffic(recording, geometry=geometry, rules=rules, params=p, variants=variants,
                           time_source=time_source, progress=progress, calibration=calibration,
                           scene_engine=scene_engine)
    output.mkdir(parents=True, exist_ok=True)
    states = result.states["fusion_pf"] if "fusion_pf" in result.states else next(iter(result.states.values()))
    write_tracks_csv(output / "tracks.csv", states)
    write_jsonl(output / "tracks.jsonl", [*states, *result.tracker_events])
    write_jsonl(output / "events.jsonl", result.scene_events)
    summary: dict[str, Any] = {
        "recording": str(recording), "sensors": result.sensors, "duration_s": result.duration_s,
        "fusion_instants": result.n_ticks, "fusion_instants_per_sensor": result.fused_ticks,
        "detections_per_sensor": result.detections,
        "messages_skipped": result.errors, "time_s": result.timings_s, "cpu_s": result.cpu_s,
        "x_real_time": result.real_time_factor(), "x_real_time_cpu": result.cpu_real_time_factor(),
        "workers": result.workers,
        "tracks": len({s.track_id for s in states}), "scene_engine": scene_engine,
        "events": _count_kinds(result.scene_events),
    }
    if calibration is not None:
        from ..calibration.road import residual_table

        rows = [{k: None if isinstance(v, float) and math.isnan(v) else v for k, v in r.items()}  # JSON null
                for r in residual_table(calibration)]
        summary["calibration"] = {"source": calibration.source, "residuals": rows}
    # scored on the roads watched: the --geometry's (it was ignored here: a recording whose simulated world has no
    # road then failed after tracking, "roads: the scene has no road"), else the simulated world's, else everywhere
    area = None
    world = recording / "ground_truth" / "world.json"
    source = geometry if geometry is not None else world if world.is_file() else None
    if source is not None:
        from ..errors import ConfigError
        from ..scene import load_road_geometry
        from .traffic import _roi_polygon, roads_of

        try:
            area = _roi_polygon(roads_of(load_road_geometry(source) if isinstance(source, str | Path)
                                         and source != world else source), 3.0)
        except ConfigError as err:  # a world without roads (a people scene): scored everywhere
            log.info("%s: traffic scored over the whole area (%s)", recording, err)
    summary.update(evaluate_traffic(result, recording, area=area, rate_hz=p.rate_hz))
    if video:
        from ..viz.preview import render_preview

        drawn = render_preview([recording], output / "tracks.mp4", tracks=states)
        summary["video"] = {"path": "tracks.mp4", "frames": drawn.frames}
    (output / "summary.json").write_text(json_text(summary, default=_json_default))
    _report(output / "report.html", recording, result, summary)
    return summary


def _count_kinds(events: Sequence[Any]) -> dict[str, int]:
    out: dict[str, int] = {}
    for e in events:
        out[e.kind] = out.get(e.kind, 0) + 1
    return out


def _json_default(x: Any) -> Any:
    if isinstance(x, np.integer | np.floating):
        return x.item()
    return str(x)


def _report(path: Path, recording: Path, result: TrafficResult, summary: dict[str, Any]) -> None:
    from ..eval.events import read_incidents
    from ..viz.report import Report, events_timeline

    r = Report(f"fusiontrack traffic — {recording.name}")
    r.text(None, f"{result.duration_s:.1f} s of recording, sensors: "
                 f"{', '.join(f'{s} ({k})' for s, k in result.sensors.items())}; "
                 f"{summary['tracks']} tracks; processed at {summary['x_real_time']:.1f}x real time.")
    if "metrics" in summary:
        r.table("Tracking against ground truth (vehicles, match within 2 m)",
                [{"variant": v, "what": VARIANTS[v], **m} for v, m in summary["metrics"].items()])
    if "incidents" in summary:
        r.table("Incidents against the simulator's labels",
                [{"kind": k, **v} for k, v in summary["incidents"].items()],
                note="onset latency: event start minus incident start; alarm latency: when the rule fired "
                     "(after its hold time) minus incident start.")
    if "calibration" in summary:
        r.table("Sensor calibration (residuals at the control points)", summary["calibration"]["residuals"],
                note=f"from {summary['calibration']['source']}; sensors it does not name are posed by the "
                     "recording's /tf_static.")
    spent = result.timings_s
    r.table("Time spent", [{"part": k, "seconds": v, "CPU seconds": result.cpu_s.get(k, math.nan),
                            "ms per recording second": 1e3 * v / result.duration_s if result.duration_s else math.nan}
                           for k, v in spent.items()])
    truth = read_incidents(recording) if (recording / "ground_truth" / "incidents.jsonl").is_file() else []
    if result.scene_events or truth:
        r.figure("Events", events_timeline(result.scene_events, truth, t0_ns=result.t0_ns,
                                           t_end_ns=result.t0_ns + int(result.duration_s * 1e9)))
    t0 = result.t0_ns
    r.table("Events", [{"kind": e.kind, "start_s": (e.t_ns - t0) / 1e9,
                        "end_s": (e.t_end_ns - t0) / 1e9 if e.t_end_ns else "open",
                        "tracks": " ".join(map(str, e.track_ids))} for e in result.scene_events] or
            [{"kind": "none"}])
    if "video" in summary:
        r.video("Bird's-eye view (lasers, tracks)", summary["video"]["path"])
    r.write(path)
