"""The people pipeline's overlay video: laser points in the camera image, the tracks' boxes, ids and situations,
and the camera's live horizontal bias (issue 6; seeds 000 and 001).

One output frame per image of the camera, the image itself underneath:

* **laser points** — for each laser, the scan nearest in time to the image (within ``max_scan_dt_s``), every
  valid return placed in the world by ``/tf_static`` (``<laser>_calibrated`` preferred, as the pipeline does)
  and projected through the camera *corrected by the bias at that instant* (:func:`bias_at`: the bias
  history's value at or before the image; the calibration as believed before the first update), drawn as
  small dots coloured by distance from the camera (near red, far blue) or by laser. With the right bias the
  leg returns sit on the people's legs; with a yaw error they sit beside them.
* **tracks** — the states nearest in time (within half a scan period), each as its box (its ``box_px`` when
  the state has one in this camera, as the people pipeline's tracks have from :func:`~fusiontrack.fusion.
  camera_boxes`: where the tracker read the camera, through the camera corrected by the bias learnt before it,
  while the laser points show the bias as it was being learnt; else the image box of a person cylinder standing
  at ``position_m``,
  :func:`person_boxes`, or for a track classed ``car`` or ``bicycle`` that of a car- or bicycle-sized cuboid
  along its velocity or, stopped, along its last heading, :func:`vehicle_boxes`; a vehicle track not classed
  yet, ``unknown``, is drawn as a person), its id in :func:`~fusiontrack.vision.overlay.id_colour` (drawn by
  :func:`~fusiontrack.vision.overlay.draw_overlay`: thick while a sensor confirms it, thin and starred while it
  coasts or is merged), and its situation and confirming sensors under the box (``L`` laser, ``C`` camera).
* **text** — top right: the bias (``bias 2.93 deg (settled)``; ``learning`` while it is being learnt, ``live`` for
  a bias learnt over the whole recording, ``not applied`` when the pipeline kept the calibration) and the
  time; bottom left: the events of the last second (merges, splits, identity exchanges).

Frames are produced one at a time from the recording's stream (images wait only until every laser has a scan
at least as late) and written with :func:`~fusiontrack.io.video.write_video`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import deque
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..calibration.bias import BiasHistory
from ..errors import ConfigError, RecordingError
from ..geometry import PinholeCamera, scan_to_points, transform_points
from ..io.recording import LASERSCAN, Recording
from ..io.video import write_video
from ..sim.model import rect_corners
from ..types import Event, Image, LaserScan, ObjectClass, Situation, TrackState
from ..vision.overlay import draw_overlay, id_colour
from ..vision.vehicles import VehicleDetectorParams
from .preview import LASER_COLOURS, _transform_tree

__all__ = [
    "VEHICLE_MOVING_MPS",
    "VEHICLE_SIZE_M",
    "FusedOverlayResult",
    "ProjectedPoints",
    "bias_at",
    "laser_points_world",
    "person_boxes",
    "project_points",
    "render_fused_overlay",
    "vehicle_boxes",
]

log = logging.getLogger(__name__)

PERSON_RADIUS_M = 0.25
"""Radius of the person cylinder drawn for a track without an image box (0.5 m wide)."""
PERSON_HEIGHT_M = 1.75
"""Height of that cylinder."""
VEHICLE_SIZE_M = {str(ObjectClass.CAR): VehicleDetectorParams().car_size_m,
                  str(ObjectClass.BICYCLE): VehicleDetectorParams().bicycle_size_m}
"""Length, width and height of the cuboid drawn for a track of each vehicle class (the camera vehicle pipeline's
size priors, :class:`~fusiontrack.vision.vehicles.VehicleDetectorParams`)."""
VEHICLE_MOVING_MPS = 0.5
"""A vehicle track faster than this is drawn along its velocity; a slower one along its last such heading."""
SITUATION_TEXT = {str(Situation.NONCORRELATED): "free", str(Situation.CORRELATED): "close",
                  str(Situation.MERGED): "merged", str(Situation.APPEARING): "new",
                  str(Situation.DISAPPEARING): "leaving"}
"""Short text of each situation (ALGORITHMS.md B7) under a track's box."""
EVENT_HOLD_S = 1.0
"""An event stays on screen this long after it ends."""

_FONT = cv2.FONT_HERSHEY_SIMPLEX
_RANGE_LUT = cv2.applyColorMap(np.arange(256, dtype=np.uint8)[:, None], cv2.COLORMAP_TURBO)[:, 0, :]  # (256, 3)


# --------------------------------------------------------------------------------------------------
# Geometry (pure, vectorised)
# --------------------------------------------------------------------------------------------------


def bias_at(history: BiasHistory | None, t_ns: Any) -> np.ndarray:
    """The bias in force at times ``t_ns``: the history's value at or before each time, 0 before its first row.

    Parameters
    ----------
    history : BiasHistory or None
        One row per camera frame (:class:`~fusiontrack.calibration.bias.BiasHistory`, times increasing);
        None or empty: the camera as calibrated (0).
    t_ns : int or (n,) int

    Returns
    -------
    float64 array of the shape of ``t_ns``
        Radians.
    """
    t = np.asarray(t_ns, dtype=np.int64)
    if history is None or len(history) == 0:
        return np.zeros(t.shape)
    k = np.searchsorted(history.t_ns, t, side="right") - 1
    return np.where(k >= 0, np.asarray(history.bias_rad, np.float64)[np.maximum(k, 0)], 0.0)


def laser_points_world(scan: LaserScan, laser2world: Any) -> np.ndarray:
    """The valid returns of ``scan`` in the world, at the laser's height: ``(n_valid, 3)`` metres.

    ``laser2world`` is the laser's ``(4, 4)`` pose; NaN and out-of-range beams are dropped.
    """
    T = np.asarray(laser2world, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"laser2world: expected a (4, 4) pose, got shape {T.shape}")
    xy = scan_to_points(scan)
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    return transform_points(T, np.column_stack([xy, np.zeros(len(xy))]))


@dataclass(frozen=True, slots=True, eq=False)
class ProjectedPoints:
    """World points that land in a camera's image.

    Attributes
    ----------
    uv : (m, 2) float64
        Pixels (pixel centres on integers), inside the image.
    range_m : (m,) float64
        Distance of each point from the camera centre.
    index : (m,) int64
        Row of each point in the input.
    """

    uv: np.ndarray
    range_m: np.ndarray
    index: np.ndarray

    def __len__(self) -> int:
        return int(self.index.size)


def project_points(camera: PinholeCamera, points_world: Any, *, bias_rad: float = 0.0) -> ProjectedPoints:
    """Project world points through ``camera`` turned by ``bias_rad`` (its corrected pose, seed 000 A10).

    Parameters
    ----------
    camera : PinholeCamera
        The camera as calibrated.
    points_world : (n, 3) float
        NaN rows are allowed (dropped).
    bias_rad : float
        Horizontal bias: the points go through ``camera.with_yaw_offset(bias_rad)``.

    Returns
    -------
    ProjectedPoints
        The points in front of the camera that fall inside the image.
    """
    pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3) if np.size(points_world) else np.zeros((0, 3))
    if not np.isfinite(bias_rad):
        raise ValueError(f"bias_rad: expected a finite angle, got {bias_rad!r}")
    cam = camera.with_yaw_offset(float(bias_rad)) if bias_rad else camera
    uv = cam.project(pts) if len(pts) else np.zeros((0, 2))
    with np.errstate(invalid="ignore"):
        inside = np.all(np.isfinite(uv), axis=1) & (uv[:, 0] >= -0.5) & (uv[:, 1] >= -0.5) & \
            (uv[:, 0] < cam.width - 0.5) & (uv[:, 1] < cam.height - 0.5)
    idx = np.flatnonzero(inside)
    return ProjectedPoints(uv[idx], np.linalg.norm(pts[idx] - cam.position_m, axis=1), idx.astype(np.int64))


def person_boxes(camera: PinholeCamera, positions_m: Any, *, radius_m: float = PERSON_RADIUS_M,
                 height_m: float = PERSON_HEIGHT_M, n_sides: int = 16) -> np.ndarray:
    """Image boxes of upright person cylinders standing at floor positions.

    The box is the bounding box of the projected top and bottom rims of a vertical cylinder (``n_sides``
    points each).

    Parameters
    ----------
    camera : PinholeCamera
        The camera to draw in (already corrected by its bias).
    positions_m : (n, 2) float
        Floor positions in the world.
    radius_m, height_m : float
        The cylinder.
    n_sides : int

    Returns
    -------
    (n, 4) float64
        ``(u_min, v_min, u_max, v_max)``; NaN rows for a position that is NaN or partly behind the camera.
    """
    pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 2)
    n = len(pos)
    if n == 0:
        return np.zeros((0, 4))
    a = np.linspace(0.0, 2 * np.pi, n_sides, endpoint=False)
    ring = radius_m * np.column_stack([np.cos(a), np.sin(a)])  # (k, 2)
    return _prism_boxes(camera, pos[:, None, :] + ring[None], np.full(n, float(height_m)))


def _prism_boxes(camera: PinholeCamera, outline_m: np.ndarray, height_m: np.ndarray) -> np.ndarray:
    """Image bounding boxes ``(n, 4)`` of upright prisms: floor outlines ``(n, k, 2)`` raised to ``height_m (n,)``;
    NaN rows where a corner is NaN or behind the camera."""
    n, k = outline_m.shape[:2]
    xy = np.concatenate([outline_m, outline_m], axis=1)  # (n, 2k, 2): bottom then top
    z = np.concatenate([np.zeros((n, k)), np.repeat(height_m[:, None], k, axis=1)], axis=1)
    uv = camera.project(np.concatenate([xy, z[..., None]], axis=2).reshape(-1, 3)).reshape(n, 2 * k, 2)
    ok = np.all(np.isfinite(uv), axis=(1, 2))
    out = np.full((n, 4), np.nan)
    out[ok] = np.concatenate([uv[ok].min(axis=1), uv[ok].max(axis=1)], axis=1)
    return out


def vehicle_boxes(camera: PinholeCamera, positions_m: Any, headings_rad: Any, sizes_m: Any) -> np.ndarray:
    """Image boxes of vehicle-sized cuboids standing on the floor.

    The box is the bounding box of the cuboid's 8 projected corners (its footprint,
    :func:`~fusiontrack.sim.model.rect_corners`, at the floor and at its height).

    Parameters
    ----------
    camera : PinholeCamera
        The camera to draw in (already corrected by its bias).
    positions_m : (n, 2) float
        Footprint centres in the world.
    headings_rad : (n,) float
        Direction of each vehicle's length (world yaw).
    sizes_m : (n, 3) float
        Length, width and height.

    Returns
    -------
    (n, 4) float64
        ``(u_min, v_min, u_max, v_max)``; NaN rows for a vehicle with a NaN value or a corner behind the camera
        (a car passing right by the camera is not drawn).
    """
    pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 2)
    yaw = np.asarray(headings_rad, dtype=np.float64).reshape(-1)
    size = np.asarray(sizes_m, dtype=np.float64).reshape(-1, 3)
    n = len(pos)
    if not (len(yaw) == n and len(size) == n):
        raise ValueError(f"headings_rad, sizes_m: expected {n} rows each, got {len(yaw)} and {len(size)}")
    if n == 0:
        return np.zeros((0, 4))
    return _prism_boxes(camera, rect_corners(pos, size[:, 0], size[:, 1], yaw), size[:, 2])


def _vehicle_headings(states: Sequence[TrackState], memory: dict[int, float]) -> np.ndarray:
    """Heading of each vehicle state: its velocity's while it moves (``VEHICLE_MOVING_MPS``), else the last one
    its track had while moving (``memory``: track id -> yaw, updated here), else along the world's x axis."""
    out = np.zeros(len(states))
    for k, s in enumerate(states):
        vx, vy = s.velocity_mps
        if math.hypot(vx, vy) >= VEHICLE_MOVING_MPS:
            memory[s.track_id] = math.atan2(vy, vx)
        out[k] = memory.get(s.track_id, 0.0)
    return out


# --------------------------------------------------------------------------------------------------
# The video
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class FusedOverlayResult:
    """What :func:`render_fused_overlay` wrote.

    Attributes
    ----------
    frames : int
        Frames written (one per camera image read).
    size_px : (width, height)
    image_topic : str
    lasers : tuple of str
        Lasers whose points were drawn.
    frames_with_points, frames_with_tracks : int
        Frames with at least one laser point / one track drawn.
    """

    frames: int
    size_px: tuple[int, int]
    image_topic: str
    lasers: tuple[str, ...]
    frames_with_points: int
    frames_with_tracks: int


@dataclass(frozen=True, slots=True, eq=False)
class _Bias:
    """The bias to draw: its history and how the run ended (from a :class:`~fusiontrack.fusion.CameraBias`)."""

    history: BiasHistory | None
    settled: bool | None = None  # None: unknown (a bare history)
    applied: bool = True

    def at(self, t_ns: int) -> tuple[float, str]:
        h = self.history
        if h is None or len(h) == 0:
            return 0.0, "bias 0.00 deg (as calibrated)"
        if t_ns < int(h.t_ns[0]):
            return 0.0, "bias 0.00 deg (as calibrated)"
        b = float(bias_at(h, t_ns))
        if not self.applied:  # the pipeline fused through the camera as calibrated: draw that
            during = "learning" if t_ns < int(h.t_ns[-1]) else "learnt"
            return 0.0, f"bias 0.00 deg ({during} {np.degrees(b):.2f}, not applied)"
        if t_ns < int(h.t_ns[-1]):  # a BiasRun learns to the end: its value is the live one, not "learning"
            return b, f"bias {np.degrees(b):.2f} deg ({'live' if self.settled is None else 'learning'})"
        state = {None: "final", True: "settled", False: "not settled"}[self.settled]
        return b, f"bias {np.degrees(b):.2f} deg ({state})"


def _bias_source(bias: Any) -> _Bias:
    if bias is None or isinstance(bias, BiasHistory):
        return _Bias(bias)
    history = getattr(bias, "history", None)
    if isinstance(history, BiasHistory):  # a CameraBias (settled / applied known) or a BiasRun (run to the end)
        settled = getattr(bias, "settled", None)
        return _Bias(history, None if settled is None else bool(settled), bool(getattr(bias, "applied", True)))
    raise ConfigError(f"bias_history: expected a BiasHistory, a CameraBias, a BiasRun or None, got "
                      f"{type(bias).__name__}")


class _StateCursor:
    """The track states of the step nearest in time to a frame, if within ``max_dt_ns``."""

    def __init__(self, states: Sequence[TrackState], max_dt_ns: int) -> None:
        self.states = sorted(states, key=lambda s: s.t_ns)
        t = np.array([s.t_ns for s in self.states], np.int64)
        self.times, self.starts = np.unique(t, return_index=True)
        self.ends = np.append(self.starts[1:], len(t))
        self.max_dt_ns = int(max_dt_ns)

    def at(self, t_ns: int) -> list[TrackState]:
        if self.times.size == 0:
            return []
        k = int(np.searchsorted(self.times, t_ns))
        near = [j for j in (k - 1, k) if 0 <= j < self.times.size]
        j = min(near, key=lambda j: abs(int(self.times[j]) - t_ns))
        if abs(int(self.times[j]) - t_ns) > self.max_dt_ns:
            return []
        return self.states[self.starts[j]:self.ends[j]]


class _EventCursor:
    """Events to show at a time: started, and ended no more than ``EVENT_HOLD_S`` ago (``camera_bias`` left out:
    the bias has its own corner)."""

    def __init__(self, events: Sequence[Event]) -> None:
        self.events = [e for e in events if e.kind != "camera_bias"]
        self.t0 = np.array([e.t_ns for e in self.events], np.int64)
        self.t1 = np.array([e.t_ns if e.t_end_ns is None else e.t_end_ns for e in self.events], np.int64) + \
            round(EVENT_HOLD_S * 1e9)

    def at(self, t_ns: int, limit: int = 4) -> list[str]:
        idx = np.flatnonzero((self.t0 <= t_ns) & (t_ns <= self.t1))
        out = []
        for k in idx[np.argsort(-self.t0[idx], kind="stable")][:limit]:
            e = self.events[k]
            ids = "+".join(str(i) for i in e.track_ids)
            extra = " exchanged" if e.kind == "identity" and e.attributes.get("exchanged") else ""
            out.append(f"{e.kind} {ids}{extra}".strip())
        return out


def _setup(rec: Recording, camera: str, image_topic: str | None, world_frame: str, lasers: Sequence[str] | None,
           camera_model: PinholeCamera | None, laser_poses: Mapping[str, Any] | None,
           ) -> tuple[str, PinholeCamera, dict[str, str], dict[str, np.ndarray]]:
    """The camera's image topic and model, and the lasers' scan topics and poses."""
    from ..vision.people import camera_from_recording

    topics = rec.topic_types()
    where = ", ".join(str(p) for p in rec.paths)
    image = rec.image_topic(camera=camera, topic=image_topic, option="image_topic")
    if camera_model is None:
        camera_model = camera_from_recording(rec, camera, camera, world_frame=world_frame)
        if camera_model is None:
            raise RecordingError(f"{where}: camera {camera!r} needs a CameraInfo and a pose in /tf_static "
                                 f"({camera}_calibrated or {camera} relative to {world_frame!r}); or pass "
                                 "camera_model")
    scan_topics = {rec.sensor_of(t): t for t, msgtype in topics.items() if msgtype == LASERSCAN}
    wanted = sorted(scan_topics) if lasers is None else [str(name) for name in lasers]
    missing = [name for name in wanted if name not in scan_topics]
    if missing:
        raise RecordingError(f"{where}: laser(s) {missing} not found; lasers: {sorted(scan_topics)}")
    given = dict(laser_poses or {})
    tf_topics = [t for t in ("/tf_static", "/tf") if t in topics]
    tree = _transform_tree(list(rec.messages(tf_topics))) if tf_topics and any(n not in given for n in wanted) \
        else None
    poses: dict[str, np.ndarray] = {}
    for name in wanted:
        if name in given:
            poses[name] = np.asarray(given[name], np.float64)
            continue
        frame = next((f for f in (f"{name}_calibrated", name) if tree is not None and f in tree.frames
                      and world_frame in tree.frames and tree.has_path(f, world_frame)), None)
        if frame is None and tree is not None:  # no sensor metadata (a recording made by other tools): its frame
            fid = next((m.frame_id for m in rec.messages([scan_topics[name]])), "")
            frame = next((f for f in (f"{fid}_calibrated", fid) if f and f in tree.frames
                          and world_frame in tree.frames and tree.has_path(f, world_frame)), None)
        if frame is None:
            log.warning("%s: no transform from laser %r to %r: its points are not drawn", where, name, world_frame)
            continue
        poses[name] = tree.get(frame, world_frame)
    return str(image), camera_model, {n: scan_topics[n] for n in poses}, poses


def _frames_with_scans(rec: Recording, image_topic: str, scan_topics: Mapping[str, str],
                       poses: Mapping[str, np.ndarray], time_source: str, corrections: Mapping[str, int],
                       max_scan_dt_ns: int) -> Iterator[tuple[Image, np.ndarray, np.ndarray]]:
    """Each image (time on the common clock) with the world points ``(n, 3)`` and laser index ``(n,)`` of the scan
    of each laser nearest to it within ``max_scan_dt_ns``. An image is held back until every laser has a scan at
    least as late, or the stream is ``max_scan_dt_ns`` past it (a laser that stopped)."""
    names = list(scan_topics)
    recent: dict[str, deque[tuple[int, np.ndarray]]] = {n: deque(maxlen=32) for n in names}
    last = dict.fromkeys(names, -(2**62))
    newest = -(2**62)
    pending: deque[Image] = deque()

    def emit(img: Image) -> tuple[Image, np.ndarray, np.ndarray]:
        pts, lab = [], []
        for k, name in enumerate(names):
            if not recent[name]:
                continue
            dt = np.abs(np.array([t for t, _ in recent[name]], np.int64) - img.t_ns)
            j = int(np.argmin(dt))
            if dt[j] <= max_scan_dt_ns:
                pts.append(recent[name][j][1])
                lab.append(np.full(len(recent[name][j][1]), k, np.int64))
        if not pts:
            return img, np.zeros((0, 3)), np.zeros(0, np.int64)
        return img, np.concatenate(pts), np.concatenate(lab)

    cam_sensor = rec.sensor_of(image_topic)
    for msg in rec.messages([image_topic, *scan_topics.values()], time_source=time_source):  # type: ignore[arg-type]
        t = msg.t_ns + int(corrections.get(msg.sensor, 0))
        if isinstance(msg, LaserScan):
            recent[msg.sensor].append((t, laser_points_world(msg, poses[msg.sensor])))
            last[msg.sensor] = max(last[msg.sensor], t)
        elif isinstance(msg, Image) and msg.sensor == cam_sensor and msg.encoding != "mono16":
            pending.append(msg if t == msg.t_ns else dataclasses.replace(msg, t_ns=t))
        else:
            continue
        newest = max(newest, t)
        ready = min(last.values(), default=2**62)
        while pending and (pending[0].t_ns <= ready or newest - pending[0].t_ns > max_scan_dt_ns):
            yield emit(pending.popleft())
    while pending:
        yield emit(pending.popleft())


def _draw_points(img: np.ndarray, uv: np.ndarray, colours: np.ndarray, radius_px: int) -> None:
    """Points ``uv (m, 2)`` as squares of side ``2 radius_px + 1`` in ``colours (m, 3)``, in place (later points
    drawn over earlier ones)."""
    if len(uv) == 0:
        return
    h, w = img.shape[:2]
    off = np.arange(-radius_px, radius_px + 1)
    du, dv = (a.ravel() for a in np.meshgrid(off, off))
    c = np.rint(uv).astype(np.int64)
    uu = np.clip(c[:, 0, None] + du[None], 0, w - 1).ravel()
    vv = np.clip(c[:, 1, None] + dv[None], 0, h - 1).ravel()
    img[vv, uu] = np.repeat(colours, du.size, axis=0)


def _text(img: np.ndarray, text: str, org: tuple[int, int], scale: float,
          colour: tuple[int, int, int] = (255, 255, 255), align_right: bool = False) -> int:
    """Text on a black band with its top-left (or top-right) corner at ``org``; returns the band's height."""
    (tw, th), base = cv2.getTextSize(text, _FONT, scale, 1)
    x = org[0] - tw - 8 if align_right else org[0]
    y = org[1]
    cv2.rectangle(img, (x, y), (x + tw + 8, y + th + base + 6), (0, 0, 0), -1)
    cv2.putText(img, text, (x + 4, y + th + 3), _FONT, scale, colour, 1, cv2.LINE_AA)
    return th + base + 6


def _compose(image: Image, index: int, t0_ns: int, camera: PinholeCamera, bias: _Bias, points: np.ndarray,
             laser_index: np.ndarray, states: list[TrackState], events: list[str], camera_name: str,
             colour_by: str, range_span_m: tuple[float, float],
             headings: dict[int, float]) -> tuple[np.ndarray, bool, bool]:
    bias_rad, bias_text = bias.at(image.t_ns)
    cam = camera.with_yaw_offset(bias_rad) if bias_rad else camera
    frame = np.ascontiguousarray(image.bgr()).copy()
    if frame.shape[:2] != (cam.height, cam.width):  # a damaged image: shown at the calibrated size (or black)
        log.warning("image at %d ns is %dx%d, its CameraInfo says %dx%d: resized", image.t_ns, frame.shape[1],
                    frame.shape[0], cam.width, cam.height)
        frame = cv2.resize(frame, (cam.width, cam.height)) if frame.size else np.zeros((cam.height, cam.width, 3),
                                                                                        np.uint8)
    proj = project_points(cam, points)
    if len(proj):
        if colour_by == "laser":
            lut = np.array(LASER_COLOURS, np.uint8)
            colours = lut[laser_index[proj.index] % len(lut)]
        else:
            lo, hi = range_span_m
            level = np.clip((proj.range_m - lo) / (hi - lo), 0.0, 1.0)
            colours = _RANGE_LUT[np.rint(255 * (1.0 - level)).astype(np.int64)]  # near red, far blue
        order = np.argsort(-proj.range_m, kind="stable")  # far first: near points drawn over them
        _draw_points(frame, proj.uv[order], colours[order], 1)
    # track boxes: their own in this camera, else a person cylinder (a vehicle's cuboid) through the corrected
    # camera
    boxes = np.full((len(states), 4), np.nan)
    people, vehicles = [], []
    for k, s in enumerate(states):
        if s.box_px is not None and s.camera == camera_name:
            boxes[k] = s.box_px
        else:
            (vehicles if s.cls in VEHICLE_SIZE_M else people).append(k)
    if people:
        boxes[people] = person_boxes(cam, np.array([states[k].position_m for k in people]))
    if vehicles:
        boxes[vehicles] = vehicle_boxes(cam, np.array([states[k].position_m for k in vehicles]),
                                        _vehicle_headings([states[k] for k in vehicles], headings),
                                        np.array([VEHICLE_SIZE_M[states[k].cls] for k in vehicles]))
    hi_uv = np.array([cam.width - 1.0, cam.height - 1.0])
    with np.errstate(invalid="ignore"):
        clipped = np.concatenate([np.clip(boxes[:, :2], 0.0, hi_uv), np.clip(boxes[:, 2:], 0.0, hi_uv)], axis=1)
        shown = np.all(np.isfinite(boxes), axis=1) & np.all(clipped[:, 2:] > clipped[:, :2], axis=1)
    drawn = [dataclasses.replace(s, box_px=clipped[k]) for k, s in enumerate(states) if shown[k]]
    out = draw_overlay(frame, drawn, frame=index + 1)
    scale = max(out.shape[0] / 480.0, 0.6)
    for s in drawn:
        u0, _, _, v1 = s.box_px
        kinds = "+".join(dict.fromkeys("C" if x == camera_name else "L" for x in s.sensors)) or "-"
        label = f"{SITUATION_TEXT.get(s.situation, s.situation)} {kinds}"
        (_, th), base = cv2.getTextSize(label, _FONT, 0.4 * scale, 1)
        _text(out, label, (int(u0), int(min(v1 + 1, out.shape[0] - th - base - 6))), 0.4 * scale,
              id_colour(s.track_id))
    y = _text(out, bias_text, (out.shape[1], 0), 0.5 * scale, align_right=True)
    _text(out, f"{(image.t_ns - t0_ns) / 1e9:6.2f} s", (out.shape[1], y), 0.45 * scale, align_right=True)
    y = out.shape[0]
    for line in reversed(events):
        (_, th), base = cv2.getTextSize(line, _FONT, 0.45 * scale, 1)
        y -= th + base + 6
        _text(out, line, (0, y), 0.45 * scale, (120, 255, 255))
    return out, bool(len(proj)), bool(drawn)


def render_fused_overlay(
    recording: Path | str | Sequence[Path | str], out_path: Path | str, states: Sequence[TrackState] = (), *,
    camera: str = "camera_0", image_topic: str | None = None, bias_history: Any = None,
    events: Sequence[Event] = (), time_source: str = "header",
    world_frame: str = "world", lasers: Sequence[str] | None = None, max_frames: int | None = None,
    fps: float | None = None, clock_corrections_ns: Mapping[str, int] | None = None,
    camera_model: PinholeCamera | None = None, laser_poses: Mapping[str, Any] | None = None,
    colour_by: str = "range", range_span_m: tuple[float, float] = (2.0, 25.0), max_scan_dt_s: float = 0.1,
    max_state_dt_s: float | None = None,
) -> FusedOverlayResult:
    """Write the people pipeline's overlay video of one camera (see the module docstring).

    Parameters
    ----------
    recording : path or paths
        With the camera's images, its ``CameraInfo``, laser scans and ``/tf_static``.
    out_path : path
        ``.mp4`` (or ``.avi``); its folder must exist.
    states : sequence of TrackState
        Tracks in the world frame (:func:`~fusiontrack.fusion.track_fused`'s), times on the common clock.
    camera : str
        Sensor name of the camera (its ``CameraInfo`` and pose).
    image_topic : str, optional
        The image topic to draw on (default: the camera's first colour one, raw preferred; pass the one the
        pipeline fused, e.g. its ``camera_topic``).
    bias_history : BiasHistory, CameraBias, BiasRun or None
        The camera's horizontal bias over time (``FusionStats.bias``, its ``history``, or
        :func:`~fusiontrack.calibration.bias_run.bias_from_recording`'s result); None: as calibrated. Each frame
        is drawn through the camera corrected by the bias learnt up to it (the live bias; the pipeline itself
        fuses every frame through the final one); a CameraBias that was not applied draws 0 throughout, as the
        pipeline fused.
    events : sequence of Event
        Shown for a second after they end.
    time_source : {"header", "log"}
    world_frame : str
    lasers : sequence of str, optional
        Lasers to draw (default: all; ``()``: none).
    max_frames : int, optional
        Stop after this many frames.
    fps : float, optional
        Frame rate of the video (default: the camera's).
    clock_corrections_ns : mapping of sensor -> int, optional
        Added to each sensor's stamps, as for ``track_fused``.
    camera_model : PinholeCamera, optional
        The camera as calibrated (default: that of a CameraBias or BiasRun given as ``bias_history``, else the
        recording's, ``<camera>_calibrated`` preferred).
    laser_poses : mapping of laser -> (4, 4), optional
        ``laser2world`` overriding ``/tf_static``.
    colour_by : {"range", "laser"}
        Point colours: distance from the camera over ``range_span_m`` (near red, far blue), or one per laser.
    range_span_m : (near, far)
    max_scan_dt_s : float
        A laser's scan nearest to an image is drawn if this close in time.
    max_state_dt_s : float, optional
        The tracker step nearest to an image is drawn if this close (default: half the lasers' scan period).

    Returns
    -------
    FusedOverlayResult

    Raises
    ------
    RecordingError
        The recording has no image topic of ``camera`` (the message names the cameras and topics present), no
        calibration for it, or no image; an unknown laser.
    ConfigError
        A bad option value.
    """
    if colour_by not in ("range", "laser"):
        raise ConfigError(f"colour_by: expected 'range' or 'laser', got {colour_by!r}")
    lo, hi = (float(v) for v in range_span_m)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
        raise ConfigError(f"range_span_m: expected (near, far) with 0 <= near < far, got {range_span_m!r}")
    if max_frames is not None and (isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 1):
        raise ConfigError(f"max_frames: expected an integer >= 1 or None, got {max_frames!r}")
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ConfigError(f"fps: expected a positive frame rate, got {fps!r}")
    for name, v in (("max_scan_dt_s", max_scan_dt_s), ("max_state_dt_s", max_state_dt_s)):
        if v is not None and not (np.isfinite(v) and v >= 0):
            raise ConfigError(f"{name}: expected a finite time >= 0, got {v!r}")
    if time_source not in ("header", "log"):
        raise ConfigError(f"time_source: expected 'header' or 'log', got {time_source!r}")
    bias = _bias_source(bias_history)
    if camera_model is None and bias_history is not None and isinstance(getattr(bias_history, "camera", None),
                                                                        PinholeCamera):
        camera_model = bias_history.camera
    paths = [recording] if isinstance(recording, Path | str) else list(recording)
    corrections = {str(k): int(v) for k, v in (clock_corrections_ns or {}).items()}
    with Recording(paths) as rec:
        image_topic, cam, scan_topics, poses = _setup(rec, camera, image_topic, world_frame, lasers, camera_model,
                                                      laser_poses)
        topics = rec.topics()
        info = topics[image_topic]
        if info.count == 0:
            raise RecordingError(f"{', '.join(map(str, paths))}: {image_topic} has no image")
        if max_state_dt_s is None:
            rates = [topics[t].rate_hz for t in scan_topics.values() if topics[t].rate_hz > 0]
            max_state_dt_s = 0.5 / max(rates) if rates else 0.05
        if fps is None:
            fps = info.rate_hz if info.rate_hz > 0 else 10.0
        cursor = _StateCursor(states, round(max_state_dt_s * 1e9))
        event_cursor = _EventCursor(events)
        counts = {"points": 0, "tracks": 0}

        def frames() -> Iterator[np.ndarray]:
            t0: int | None = None
            headings: dict[int, float] = {}  # vehicle track id -> its last heading while moving
            stream = _frames_with_scans(rec, image_topic, scan_topics, poses, time_source, corrections,
                                        round(max_scan_dt_s * 1e9))
            for index, (image, points, laser_index) in enumerate(stream):
                if max_frames is not None and index >= max_frames:
                    return
                t0 = image.t_ns if t0 is None else t0
                out, has_points, has_tracks = _compose(image, index, t0, cam, bias, points, laser_index,
                                                       cursor.at(image.t_ns), event_cursor.at(image.t_ns), camera,
                                                       colour_by, (lo, hi), headings)
                counts["points"] += has_points
                counts["tracks"] += has_tracks
                yield out

        try:
            n = write_video(out_path, frames(), fps=min(max(float(fps), 1.0), 60.0))
        except ConfigError as err:
            if "no frames" in str(err):
                raise RecordingError(f"{', '.join(map(str, paths))}: no readable image on {image_topic}") from err
            raise
    log.info("%s: %d frames of %s (%d with laser points, %d with tracks)", out_path, n, image_topic,
             counts["points"], counts["tracks"])
    return FusedOverlayResult(n, (cam.width, cam.height), image_topic, tuple(poses), counts["points"],
                              counts["tracks"])
