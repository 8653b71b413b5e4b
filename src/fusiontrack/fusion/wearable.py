"""The ``wearable`` pipeline (seed 002): people identified by the phones they carry, tracked across RGB-D and
video cameras by dead reckoning corrected with RGB-D fixes and fused with compressive visual trackers.

:func:`track_wearable` chains

1. per phone, pedestrian dead reckoning from its IMU topic (ALGORITHMS.md C1-C5;
   :mod:`~fusiontrack.fusion.wearable_data`);
2. people found in every depth frame and placed on the floor (C7);
3. which detection is which phone's carrier: detections linked into tracklets, each matched to the phones'
   dead-reckoned paths by shape (similarity registration, X7 with a free step-length scale) and, once a phone
   is placed, by position (:mod:`~fusiontrack.fusion.wearable_assoc`);
4. per phone, the step-length factor learnt from its fixes, alignment with the world and the causal
   thin-plate-spline drift correction (C3, C8; :mod:`~fusiontrack.fusion.wearable_correct`);
5. per (person, camera), compressive tracking checked by the corrected position projected into the image, with
   failure detection and recovery (C9-C12; :mod:`~fusiontrack.fusion.wearable_visual`).

Everything degrades instead of failing: an IMU gap is bridged (no steps inside it; reported as an
``imu_gap`` event), a phone that stops reporting ends its dead reckoning (``phone_silent``) and its visual
trackers lose the inertial check, a depth frame without valid pixels gives no detection, and a person never
seen by an RGB-D camera keeps an uncorrected dead reckoning in the phone's own frame (status
``dead_reckoning_only``, ``never_seen_by_rgbd`` event, ``frame = phone`` in the trajectory).
:func:`run_wearable` does all of it for a recording and writes the results into a folder
(:func:`fusiontrack.fusion.wearable_io.write_wearable`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, RecordingError
from ..inertial.step_length import StepLengthModel, load_step_model
from ..io.datafile import json_text
from ..types import Event
from .wearable_assoc import AssocParams, Tracklet, associate, link_tracklets
from .wearable_correct import Correction, correct_phone
from .wearable_data import Inputs, PhoneTrack, read_inputs
from .wearable_visual import VisualParams, VisualTrack, track_visual

__all__ = ["PersonResult", "WearableParams", "WearableResult", "check_options", "run_wearable", "track_wearable"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class WearableParams:
    """Settings of :func:`track_wearable`.

    Attributes
    ----------
    phones : tuple of str or None
        Phones (IMU sensor names) to track; all when None.
    cameras : tuple of str or None
        Cameras to run visual trackers in; all with images when None.
    start_poses : mapping phone -> (x_m, y_m, heading_rad)
        Known start poses (C5); others are placed by their first owned RGB-D tracklet.
    step_model : StepLengthModel, path of its JSON, or None
        C3 model for every phone (the default model when None).
    depth_range_m : (float, float)
        C7's accepted fix depth.
    gap_s : float
        A phone without samples for longer is silent (gap).
    output_hz : float
        Rate of the written trajectories.
    visual : bool
        Run the visual side (C9-C12).
    assoc : AssocParams
    vision : VisualParams
    seed : int
    """

    phones: tuple[str, ...] | None = None
    cameras: tuple[str, ...] | None = None
    start_poses: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    step_model: StepLengthModel | str | Path | None = None
    depth_range_m: tuple[float, float] = (0.8, 4.0)
    gap_s: float = 0.25
    output_hz: float = 10.0
    visual: bool = True
    assoc: AssocParams = field(default_factory=AssocParams)
    vision: VisualParams = field(default_factory=VisualParams)
    seed: int = 0

    def __post_init__(self) -> None:
        lo, hi = self.depth_range_m
        if not 0 <= lo < hi:
            raise ConfigError(f"depth_range_m: expected (low, high) with 0 <= low < high, got {self.depth_range_m}")
        for name in ("gap_s", "output_hz"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"{name}: expected a finite value > 0, got {value!r}")
        for phone, pose in self.start_poses.items():
            if len(pose) not in (2, 3) or not np.all(np.isfinite(np.asarray(pose, np.float64))):
                raise ConfigError(f"start_poses[{phone!r}]: expected (x_m, y_m[, heading_rad]), got {pose!r}")


@dataclass(frozen=True, slots=True, eq=False)
class PersonResult:
    """One phone carrier.

    Attributes
    ----------
    phone : str
    track_id : int
        Index of the phone among the tracked phones (sorted by name).
    status : str
        ``corrected`` (RGB-D fixes used), ``heading_unknown`` (seen only standing), ``start_pose`` (placed by a
        known start pose, never seen), ``dead_reckoning_only`` (never seen: uncorrected, phone frame) or
        ``no_dead_reckoning`` (unusable IMU stream).
    t_ns : (n,) int64
        Trajectory times (``output_hz``).
    xy_m : (n, 2) float64
        World positions, or the phone's own frame when ``frame == "phone"``.
    corrected : (n,) bool
        A TPS control point has been used at or before this time.
    reporting : (n,) bool
        The phone was reporting.
    frame : str
        ``"world"`` or ``"phone"``.
    step_count : int
    distance_m : float
    correction : Correction
    tracklets : list of Tracklet
        Owned RGB-D tracklets.
    boxes : mapping camera -> VisualTrack
    events : list of Event
    error : str
    """

    phone: str
    track_id: int
    status: str
    t_ns: np.ndarray
    xy_m: np.ndarray
    corrected: np.ndarray
    reporting: np.ndarray
    frame: str
    step_count: int
    distance_m: float
    correction: Correction
    tracklets: list[Tracklet]
    boxes: dict[str, VisualTrack]
    events: list[Event]
    error: str = ""


@dataclass(frozen=True, slots=True, eq=False)
class WearableResult:
    """The output of :func:`track_wearable`."""

    people: dict[str, PersonResult]
    events: list[Event]
    tracklets: list[Tracklet]
    owner: np.ndarray
    margin: np.ndarray
    cameras: dict[str, dict[str, Any]]
    inputs: Inputs
    seconds: dict[str, float]


def _step_model(value: StepLengthModel | str | Path | None) -> StepLengthModel | None:
    if value is None or isinstance(value, StepLengthModel):
        return value
    try:
        return load_step_model(value)
    except (OSError, ValueError) as err:
        raise ConfigError(f"step_model: {err}") from err


def _phone_events(track: PhoneTrack, tid: int, end_ns: int, gap_s: float) -> list[Event]:
    ev = [Event(int(a), track.name, "imu_gap", int(b), track_ids=(tid,), attributes={"phone": track.name,
                                                                                    "seconds": (b - a) * 1e-9})
          for a, b in track.gaps_ns]
    if not track.ok:
        ev.append(Event(int(track.t_ns[0]) if track.t_ns.size else 0, track.name, "no_dead_reckoning",
                        track_ids=(tid,), attributes={"phone": track.name, "reason": track.error}))
    elif end_ns - track.span_ns[1] > 4 * gap_s * 1e9:
        ev.append(Event(track.span_ns[1], track.name, "phone_silent", track_ids=(tid,),
                        attributes={"phone": track.name, "silent_s": (end_ns - track.span_ns[1]) * 1e-9}))
    return ev


def track_wearable(recording: str | Path, params: WearableParams | None = None) -> WearableResult:
    """Track every phone carrier of a recording (see the module docstring).

    Raises
    ------
    RecordingError
        The recording cannot be read or has no phone (IMU topic).
    ConfigError
        Bad parameters, a requested phone or camera that is not in the recording.
    """
    p = params or WearableParams()
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    inputs = read_inputs(recording, phones=p.phones, step_model=_step_model(p.step_model),
                         start_poses=dict(p.start_poses), depth_range_m=p.depth_range_m, gap_s=p.gap_s, rng=p.seed)
    seconds["read_and_pdr"] = time.perf_counter() - t0
    if not inputs.phones:
        raise RecordingError(f"{recording}: no phone IMU topic (sensor_msgs/Imu): nothing to track")
    if p.cameras is not None:
        missing = sorted(set(p.cameras) - set(inputs.cameras))
        if missing:
            raise ConfigError(f"cameras: {missing} not usable in {recording} (calibrated cameras: "
                              f"{sorted(inputs.cameras)})")
    names = sorted(inputs.phones)
    tracks = [inputs.phones[n] for n in names]
    known = {n: n in p.start_poses for n in names}
    t0 = time.perf_counter()
    tracklets = link_tracklets(inputs.detections, p.assoc)
    owner, margin = associate(tracklets, tracks, p.assoc, known, p.gap_s)
    corrections = {n: correct_phone(inputs.phones[n], [t for t, o in zip(tracklets, owner, strict=True) if o == k],
                                    p.assoc, known[n]) for k, n in enumerate(names)}
    seconds["associate_and_correct"] = time.perf_counter() - t0
    visual: dict[tuple[str, str], VisualTrack] = {}
    vis_events: list[Event] = []
    cam_info: dict[str, dict[str, Any]] = {}
    if p.visual:
        t0 = time.perf_counter()
        cams = {c: m for c, m in inputs.cameras.items() if p.cameras is None or c in p.cameras}
        visual, vis_events, cam_info = track_visual(inputs.path, cams, inputs.phones, corrections, p.vision,
                                                    gap_s=p.gap_s, rng=p.seed)
        seconds["visual"] = time.perf_counter() - t0
    people: dict[str, PersonResult] = {}
    all_events: list[Event] = []
    for k, n in enumerate(names):
        tr, corr = inputs.phones[n], corrections[n]
        owned = [t for t, o in zip(tracklets, owner, strict=True) if o == k]
        ev = _phone_events(tr, k, inputs.end_ns, p.gap_s)
        for i in np.flatnonzero(owner == k):
            t = tracklets[i]
            cams = sorted({inputs.camera_names[c] for c in inputs.detections.camera[t.index]})
            ev.append(Event(t.span_ns[0], "|".join(cams), "rgbd_fixes", t.span_ns[1], track_ids=(k,),
                            attributes={"phone": n, "fixes": int(t.t_ns.size), "margin": float(margin[i])}))
        if not tr.ok:
            status = "no_dead_reckoning"
        elif corr.control_t_ns.size and corr.heading_known:
            status = "corrected"
        elif corr.control_t_ns.size:
            status = "heading_unknown"
        elif known[n]:
            status = "start_pose"
        else:
            status = "dead_reckoning_only"
        if tr.ok and not owned:
            ev.append(Event(tr.span_ns[0], n, "never_seen_by_rgbd", track_ids=(k,),
                            attributes={"phone": n, "note": "dead reckoning uncorrected" + (
                                ", in the phone's own frame" if not known[n] else ", from the known start pose")}))
        ev += [e for e in vis_events if e.attributes.get("phone") == n]
        ev.sort(key=lambda e: e.t_ns)
        if tr.ok:
            tt = np.arange(tr.span_ns[0], tr.span_ns[1] + 1, round(1e9 / p.output_hz), dtype=np.int64)
            idx = np.clip(np.searchsorted(corr.t_ns, tt), 0, corr.t_ns.size - 1)
            xy = np.column_stack([np.interp(tt, corr.t_ns, corr.xy_m[:, j]) for j in range(2)])
            corrected, reporting = corr.corrected[idx], tr.reporting_at(tt, p.gap_s)
        else:
            tt, xy, corrected, reporting = np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0, bool), np.zeros(0, bool)
        people[n] = PersonResult(n, k, status, tt, xy, corrected, reporting, "world" if corr.aligned else "phone",
                                 tr.pdr.n_steps if tr.pdr else 0, tr.pdr.distance_m if tr.pdr else 0.0, corr, owned,
                                 {c: v for (ph, c), v in visual.items() if ph == n}, ev, tr.error)
        all_events += ev
    all_events.sort(key=lambda e: e.t_ns)
    return WearableResult(people, all_events, tracklets, owner, margin, cam_info, inputs, seconds)


def check_options(options: Mapping[str, Any], source: str) -> None:
    """Check a pipeline file's ``[wearable]`` table (keys and values as :func:`run_wearable` takes them) before any
    reading; errors name ``source``."""
    try:
        _params_from(options)
    except ConfigError as err:
        raise ConfigError(f"{source}: {str(err).removeprefix('wearable: ')}") from None


def _params_from(options: Mapping[str, Any]) -> WearableParams:
    """WearableParams from flat keyword options: its own fields, and those of AssocParams and VisualParams."""
    own = {f.name for f in dataclasses.fields(WearableParams)}
    sub = {"assoc": {f.name for f in dataclasses.fields(AssocParams)},
           "vision": {f.name for f in dataclasses.fields(VisualParams)}}
    top: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {"assoc": {}, "vision": {}}
    for key, value in options.items():
        if key in own:
            top[key] = tuple(value) if key in ("phones", "cameras") and value is not None else value
        elif key in sub["assoc"]:
            nested["assoc"][key] = value
        elif key in sub["vision"]:
            nested["vision"][key] = value
        else:
            raise ConfigError(f"wearable: unknown option {key!r} (a key of the pipeline file's [wearable] table "
                              f"or a keyword of run_wearable); known: "
                              f"{', '.join(sorted(own | sub['assoc'] | sub['vision']))}")
    try:
        if nested["assoc"]:
            top["assoc"] = dataclasses.replace(top.get("assoc", AssocParams()), **nested["assoc"])
        if nested["vision"]:
            top["vision"] = dataclasses.replace(top.get("vision", VisualParams()), **nested["vision"])
        return WearableParams(**top)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"wearable: {err}") from err


def run_wearable(recording_path: str | Path, out_dir: str | Path, **options: Any) -> dict[str, Any]:
    """Run the wearable pipeline on a recording and write its results (what ``fusiontrack track --pipeline
    wearable`` does).

    Parameters
    ----------
    recording_path : str or Path
    out_dir : str or Path
        Created if needed; receives the files of :func:`~fusiontrack.fusion.wearable_io.write_wearable` and
        ``summary.json``.
    **options
        Any field of :class:`WearableParams`, :class:`~fusiontrack.fusion.wearable_assoc.AssocParams` or
        :class:`~fusiontrack.fusion.wearable_visual.VisualParams` by name (e.g. ``phones=["phone_a"]``,
        ``start_poses={"phone_a": (0, 0, 1.57)}``, ``baseline=True``, ``visual=False``).

    Returns
    -------
    dict
        The summary (also ``summary.json``): per person the status, steps, distance, fixes, when the correction
        started, and per camera the frames tracked, failures and recoveries; per camera the projection used;
        counts of events by kind; the files written; the time spent.
    """
    from .wearable_io import write_wearable

    params = _params_from(options)
    t0 = time.perf_counter()
    result = track_wearable(recording_path, params)
    paths = write_wearable(result, out_dir)
    people = {}
    for n, pr in result.people.items():
        kinds = Counter(e.kind for e in pr.events)
        cams = {}
        for cam, v in pr.boxes.items():
            ck = Counter(e.kind for e in pr.events if e.attributes.get("camera") == cam)
            cams[cam] = {"frames": int(v.t_ns.size), "failures": ck["visual_failure"],
                         "recoveries": ck["visual_recovery"],
                         "no_inertial_frames": int(np.sum(v.status == "no_inertial"))}
        first = pr.correction.control_t_ns
        people[n] = {"track_id": pr.track_id, "status": pr.status, "frame": pr.frame, "steps": pr.step_count,
                     "distance_m": round(pr.distance_m, 3), "rgbd_tracklets": len(pr.tracklets),
                     "fixes": int(pr.correction.fix_t_ns.size), "control_points": int(first.size),
                     "corrected_from_s": (int(first[0]) - result.inputs.start_ns) * 1e-9 if first.size else None,
                     "imu_gaps": kinds["imu_gap"], "phone_silent": bool(kinds["phone_silent"]), "cameras": cams,
                     "error": pr.error}
    summary = {"recording": str(recording_path), "people": people, "cameras": result.cameras,
               "rgbd": {"detections": len(result.inputs.detections), "tracklets": len(result.tracklets),
                        "owned": int(np.sum(result.owner >= 0)), "depth_frames": result.inputs.depth_frames,
                        "empty_depth_frames": result.inputs.empty_depth_frames},
               "events": dict(Counter(e.kind for e in result.events)),
               "files": {k: str(v) for k, v in paths.items()},
               "seconds": {**{k: round(v, 3) for k, v in result.seconds.items()},
                           "total": round(time.perf_counter() - t0, 3)}}
    path = Path(out_dir) / "summary.json"
    try:
        path.write_text(json_text(summary))
    except OSError as err:
        raise RecordingError(f"{path}: cannot write the summary ({err.strerror or err})") from err
    summary["files"]["summary"] = str(path)
    return summary
