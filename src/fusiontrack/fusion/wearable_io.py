"""Writing the results of the ``wearable`` pipeline (:class:`~fusiontrack.fusion.wearable.WearableResult`)
to a folder."""

from __future__ import annotations

import csv
from collections import Counter
from pathlib import Path

import numpy as np

from ..errors import RecordingError
from ..io.tracks import format_time_s, write_jsonl, write_tracks_csv
from ..types import TrackState
from .wearable import WearableResult

__all__ = ["BOX_COLUMNS", "TRAJECTORY_COLUMNS", "write_wearable"]


TRAJECTORY_COLUMNS = ("phone", "track_id", "t", "t_ns", "x_m", "y_m", "frame", "corrected", "reporting")
BOX_COLUMNS = ("phone", "track_id", "camera", "segment", "t", "t_ns", "u_min", "v_min", "u_max", "v_max", "ct_u_min",
               "ct_v_min", "ct_u_max", "ct_v_max", "proj_u", "proj_v", "sim", "status")


def _f(v: float, digits: int = 3) -> str:
    return f"{v:.{digits}f}" if np.isfinite(v) else ""


def write_wearable(result: WearableResult, out_dir: str | Path) -> dict[str, Path]:
    """Write a :class:`WearableResult` into ``out_dir``.

    Files: ``trajectories.csv`` (:data:`TRAJECTORY_COLUMNS`: every person's trajectory, ``frame`` world or phone,
    ``corrected`` and ``reporting`` 0/1), ``tracks.csv`` (world-frame people as tracks, :mod:`fusiontrack.io.tracks`),
    ``boxes.csv`` (:data:`BOX_COLUMNS`; plus ``base_*`` columns when the visual-only baseline ran),
    ``events.jsonl`` (every :class:`~fusiontrack.types.Event`), ``people.csv`` (one row per person).

    Raises
    ------
    RecordingError
        The folder cannot be written.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        paths = {k: out / f for k, f in (("trajectories", "trajectories.csv"), ("tracks", "tracks.csv"),
                                          ("boxes", "boxes.csv"), ("events", "events.jsonl"),
                                          ("people", "people.csv"))}
        with paths["trajectories"].open("w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(TRAJECTORY_COLUMNS)
            for pr in result.people.values():
                for i in range(pr.t_ns.size):
                    w.writerow([pr.phone, pr.track_id, format_time_s(int(pr.t_ns[i])), int(pr.t_ns[i]),
                                _f(pr.xy_m[i, 0], 4), _f(pr.xy_m[i, 1], 4), pr.frame, int(pr.corrected[i]),
                                int(pr.reporting[i])])
        states = []
        for pr in result.people.values():
            if pr.frame != "world" or pr.t_ns.size < 2:
                continue
            vel = np.gradient(pr.xy_m, pr.t_ns * 1e-9, axis=0)
            states += [TrackState(int(t), "wearable", pr.track_id, xy, v,
                                  sensors=(pr.phone,) + (("rgbd",) if c else ()))
                       for t, xy, v, c in zip(pr.t_ns, pr.xy_m, vel, pr.corrected, strict=True)]
        states.sort(key=lambda s: (s.t_ns, s.track_id))
        write_tracks_csv(paths["tracks"], states)
        baseline = any(v.baseline_box_px is not None for pr in result.people.values() for v in pr.boxes.values())
        with paths["boxes"].open("w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(BOX_COLUMNS + (("base_u_min", "base_v_min", "base_u_max", "base_v_max") if baseline else ()))
            for pr in result.people.values():
                for cam, v in sorted(pr.boxes.items()):
                    for i in range(v.t_ns.size):
                        row = [pr.phone, pr.track_id, cam, int(v.segment[i]), format_time_s(int(v.t_ns[i])),
                               int(v.t_ns[i]), *(_f(x, 1) for x in v.box_px[i]), *(_f(x, 1) for x in v.ct_box_px[i]),
                               *(_f(x, 1) for x in v.projected_px[i]), _f(v.sim[i], 4), v.status[i]]
                        if baseline:
                            row += [_f(x, 1) for x in (v.baseline_box_px[i] if v.baseline_box_px is not None
                                                       else np.full(4, np.nan))]
                        w.writerow(row)
        write_jsonl(paths["events"], result.events)
        with paths["people"].open("w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(["phone", "track_id", "status", "frame", "steps", "distance_m", "rgbd_tracklets", "fixes",
                        "corrected_from_t", "cameras", "visual_failures", "visual_recoveries", "error"])
            for pr in result.people.values():
                kinds = Counter(e.kind for e in pr.events)
                first = pr.correction.control_t_ns
                w.writerow([pr.phone, pr.track_id, pr.status, pr.frame, pr.step_count, _f(pr.distance_m, 2),
                            len(pr.tracklets), int(pr.correction.fix_t_ns.size),
                            format_time_s(int(first[0])) if first.size else "", "|".join(sorted(pr.boxes)),
                            kinds["visual_failure"], kinds["visual_recovery"], pr.error])
    except OSError as err:
        raise RecordingError(f"{out}: cannot write the wearable output ({err.strerror or err})") from err
    return paths
