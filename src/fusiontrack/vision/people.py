"""Vision-only people tracker: boxes in the image, and on the floor through a calibrated camera (issue 5).

:class:`CameraPeopleTracker` tracks image boxes ``(u_min, v_min, u_max, v_max)`` [RECON, SORT-like]:

* **Motion.** Two X5 constant-velocity Kalman filters per track: the box centre ``(u, v, u̇, v̇)`` and the box
  size ``(w, h, ẇ, ḣ)``, predicted to each frame's time.
* **Association.** Hungarian (X2) on ``1 − IoU`` of predicted and detected boxes where ``IoU >= iou_min``;
  a pair without enough overlap can still pair at cost ``1 + d`` when the centre distance ``d``, in units
  of the larger box height, is at most ``centre_gate`` (a small box moving fast at a low frame rate);
  pairs whose heights differ by more than ``size_gate`` times are forbidden (``inf``). With colour
  descriptors (``Detection.features["appearance"]``, normalised HSV histograms) ``colour_weight × (1 − BC)``
  (X4) is added.
* **Groups** (people overlapping in the image, one foreground blob): a detection that contains at least
  ``group_containment`` of the predicted boxes of two or more confirmed tracks, and is at least
  ``group_area_ratio`` times larger than each (a person-sized box over two tracks is one person in front of
  the other, e.g. a detector's box: that goes to the assignment), is a group. It is left out
  of the assignment; each member keeps its own predicted box, pushed inside the group's box (a pseudo-
  measurement of variance ``r_group_px2``), and is reported with situation ``merged``. Members leave the
  group by the ordinary assignment when the blob splits, so identities are kept through a crossing by
  the motion prediction (and colour, when given). After ``max_group_s`` the group is treated as a
  detection like any other.
* **Fragments** (one person in several blobs): detections that lie mostly (``fragment_containment``)
  inside one confirmed track's predicted box, and inside no other's, are joined into their union box.
* **Life cycle.** A new track is tentative; ``n_confirm`` consecutive hits confirm it (it then gets the
  next id of this tracker instance and an ``appear`` event); a tentative track that misses a frame ends;
  a confirmed track ends after ``max_coast_s`` without a detection (``disappear`` event). Detections
  mostly inside a confirmed track's box start no new track (a fragment or a duplicate).

Floor positions: given a :class:`~fusiontrack.geometry.PinholeCamera`, each state's ``position_m`` is
the bottom centre of its box back-projected onto the floor ``Z = 0`` (ALGORITHMS.md 0.2), and
``velocity_mps`` the floor displacement of that point over the box's image velocity; without a
camera both are ``NaN``. With a camera, a foreground box much shorter than a person standing under its
top row (the legs lost in a floor-coloured background by A3) can be completed down to the feet
(:func:`complete_person_boxes`, on by default in :func:`track_camera`).

Detections come from the foreground blobs (:func:`blob_detections`; A1-A4 of seed 000) or from a
MOTChallenge detection file (:func:`mot_detections`). Blobs go to the box tracker directly, not through
A5's :class:`~fusiontrack.vision.BlobTracker`: on the simulated ``crossing``, ``groups`` and ``crowd``
(``benchmarks/camera_people.py``, 3 seeds each) the box tracker scores MOTA 93 / 53 / 51 % and IDF1
97 / 63 / 60 %, A5's objects alone (same foreground, same box completion, group members left out) 70 / 36 / 37 %
and 84 / 52 / 52 %: A5 reports a group's members with the group's box (an IoU miss for each; leaving them out
is a miss too), while here each member keeps its own predicted box. A5's colour-based identity restoration
is kept in spirit by the colour term.

:func:`track_camera` runs the whole path over a video file or a recording's image topic, and can write
an overlay video (:mod:`fusiontrack.vision.overlay`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, RecordingError
from ..geometry import PinholeCamera, invert_transform
from ..io.tracks import MotBoxes, read_mot
from ..tracking import kalman
from ..tracking.association import hungarian
from ..types import CameraInfo, Detection, Event, GroundTruth, Image, Situation, TrackState
from .blobs import BlobParams, Blobs, blob_contours, blob_histograms, box_histograms, extract_blobs
from .cvthreads import opencv_threads
from .foreground import ForegroundModel, ForegroundParams, ForegroundResult

__all__ = [
    "CameraPeopleTracker",
    "CameraRunStats",
    "CameraTrackerParams",
    "FrameResult",
    "blob_detections",
    "box_containment",
    "box_iou",
    "camera_from_recording",
    "camera_truth_boxes",
    "complete_person_boxes",
    "floor_positions",
    "mot_detections",
    "track_camera",
]

log = logging.getLogger(__name__)

_MERGED = str(Situation.MERGED)
_NONCORRELATED = str(Situation.NONCORRELATED)


# --------------------------------------------------------------------------------------------------
# Box maths (pure, vectorised)
# --------------------------------------------------------------------------------------------------


def _boxes(value: Any, name: str) -> np.ndarray:
    b = np.asarray(value, dtype=np.float64)
    if b.size == 0:
        return np.zeros((0, 4))
    if b.ndim != 2 or b.shape[1] != 4:
        raise ValueError(f"{name}: expected an (n, 4) array of boxes, got shape {b.shape}")
    return b


def _areas(b: np.ndarray) -> np.ndarray:
    return np.prod(np.clip(b[:, 2:] - b[:, :2], 0.0, None), axis=1)


def _intersections(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    lo = np.maximum(a[:, None, :2], b[None, :, :2])
    hi = np.minimum(a[:, None, 2:], b[None, :, 2:])
    return np.prod(np.clip(hi - lo, 0.0, None), axis=2)


def box_iou(a: Any, b: Any) -> np.ndarray:
    """Intersection over union of boxes ``a (n, 4)`` and ``b (m, 4)`` ``(u_min, v_min, u_max, v_max)``: ``(n, m)``."""
    a, b = _boxes(a, "a"), _boxes(b, "b")
    inter = _intersections(a, b)
    union = _areas(a)[:, None] + _areas(b)[None, :] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def box_containment(a: Any, b: Any) -> np.ndarray:
    """Fraction of the area of each box ``a[i]`` that lies inside ``b[j]``: ``(n, m)`` in ``[0, 1]``."""
    a, b = _boxes(a, "a"), _boxes(b, "b")
    area = _areas(a)[:, None]
    return np.where(area > 0, _intersections(a, b) / np.where(area > 0, area, 1.0), 0.0)


def _centre_size(boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return (boxes[:, :2] + boxes[:, 2:]) / 2, boxes[:, 2:] - boxes[:, :2]


def _box_from(centre: np.ndarray, size: np.ndarray) -> np.ndarray:
    return np.concatenate([centre - size / 2, centre + size / 2], axis=-1)


def _bc_cost(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``1 − BC`` (X4) between histograms ``p (n, k)`` and ``q (m, k)``: ``(n, m)``."""
    return 1.0 - np.sqrt(p) @ np.sqrt(q).T


# --------------------------------------------------------------------------------------------------
# Floor geometry
# --------------------------------------------------------------------------------------------------


def floor_positions(camera: PinholeCamera | None, boxes_px: Any) -> np.ndarray:
    """Bottom centres ``((u_min + u_max) / 2, v_max)`` of boxes ``(n, 4)`` on the floor ``Z = 0``: ``(n, 2)`` m.

    ``NaN`` rows without a camera, and for a bottom centre at or above the horizon.
    """
    b = _boxes(boxes_px, "boxes_px")
    if camera is None or len(b) == 0:
        return np.full((len(b), 2), np.nan)
    bottom = np.column_stack([(b[:, 0] + b[:, 2]) / 2, b[:, 3]])
    return camera.backproject_to_floor(bottom)[:, :2]


def complete_person_boxes(camera: PinholeCamera, boxes_px: Any, height_m: float = 1.72, min_ratio: float = 0.8
                          ) -> np.ndarray:
    """Extend boxes much shorter than a person standing under their top row down to that person's feet.

    For each box, the ray through its top centre meets the plane ``Z = height_m`` at the head; the feet are
    below it on the floor, projected to row ``v_feet``. A box with ``v_max − v_min < min_ratio (v_feet − v_min)``
    gets ``v_max = min(v_feet, image height)``. Boxes touching the top of the image (the head may be cut off)
    and boxes whose top is above the horizon are left as they are. [RECON] (the simulator's people are
    1.58-1.86 m tall; 0.8 leaves a person up to 20 % shorter than ``height_m`` untouched).

    Parameters
    ----------
    camera : PinholeCamera
    boxes_px : (n, 4) float
    height_m : float
        Assumed height of a person.
    min_ratio : float
        Boxes at least this fraction of the expected height are kept.

    Returns
    -------
    (n, 4) float64
    """
    b = _boxes(boxes_px, "boxes_px").copy()
    if len(b) == 0:
        return b
    top = np.column_stack([(b[:, 0] + b[:, 2]) / 2, b[:, 1]])
    head = camera.backproject_to_floor(top, floor_z=height_m)
    feet = head.copy()
    feet[:, 2] = 0.0
    v_feet = camera.project(feet)[:, 1]
    with np.errstate(invalid="ignore"):
        short = (b[:, 1] > 0.5) & np.isfinite(v_feet) & (v_feet > b[:, 1]) & \
            (b[:, 3] - b[:, 1] < min_ratio * (v_feet - b[:, 1]))
    b[short, 3] = np.minimum(v_feet[short], camera.height)
    return b


def camera_from_recording(rec: Any, image_sensor: str, frame_id: str, *, info_topic: str | None = None,
                          world_frame: str = "world", cam2world: Any = None) -> PinholeCamera | None:
    """The calibrated camera of an image topic: its ``CameraInfo`` and its pose from ``/tf_static``.

    The pose is that of ``<frame_id>_calibrated`` when the transform tree has it (the calibration the
    simulator writes beside the true pose, which the user is not supposed to know), else of ``frame_id``,
    else of ``image_sensor``; ``cam2world`` (``(4, 4)``, the optical frame's pose in ``world_frame``, e.g. a
    pipeline file's, :meth:`fusiontrack.config.PipelineConfig.camera_poses`) overrides it. Returns ``None``
    (floor positions unavailable) when the recording has no CameraInfo for the camera or no pose for it.
    """
    topics = rec.topic_types()
    infos = [info_topic] if info_topic else rec.camera_info_topics(image_sensor)
    info: CameraInfo | None = None
    if infos and infos[0] in topics:
        info = next((m for m in rec.messages(infos[:1]) if isinstance(m, CameraInfo)), None)
    if info is None:
        log.info("%s: no CameraInfo for camera %r: no floor positions", rec.paths[0], image_sensor)
        return None
    if cam2world is not None:
        return PinholeCamera.from_camera_info(info, invert_transform(np.asarray(cam2world, np.float64)))
    tree = rec.transform_tree()
    for frame in (f"{frame_id}_calibrated", frame_id, info.frame_id, image_sensor):
        if frame and tree.has_path(frame, world_frame):
            return PinholeCamera.from_camera_info(info, tree.get(world_frame, frame))
    log.info("%s: no transform from camera %r to %r: no floor positions", rec.paths[0], frame_id, world_frame)
    return None


# --------------------------------------------------------------------------------------------------
# Detection sources
# --------------------------------------------------------------------------------------------------


def blob_detections(blobs: Blobs, t_ns: int, sensor: str, frame_bgr: np.ndarray | None = None,
                    camera: PinholeCamera | None = None, complete_height_m: float | None = 1.72) -> list[Detection]:
    """One :class:`~fusiontrack.types.Detection` per blob: its box (completed to the feet with a camera, see
    :func:`complete_person_boxes`), its floor position, and its HSV histogram under ``"appearance"`` when
    the frame is given."""
    boxes = blobs.boxes_px
    if camera is not None and complete_height_m is not None:
        boxes = complete_person_boxes(camera, boxes, complete_height_m)
    hists = blob_histograms(frame_bgr, blobs) if frame_bgr is not None and len(blobs) else None
    floor = floor_positions(camera, boxes)
    out = []
    for k in range(len(boxes)):
        feats = {} if hists is None else {"appearance": hists[k]}
        pos = floor[k] if np.all(np.isfinite(floor[k])) else None
        out.append(Detection(t_ns, sensor, position_m=pos, box_px=boxes[k], score=1.0, cls="person",
                             features=feats))
    return out


def mot_detections(det: MotBoxes, frame: int, t_ns: int, sensor: str, *, min_score: float = -np.inf,
                   frame_bgr: np.ndarray | None = None, camera: PinholeCamera | None = None) -> list[Detection]:
    """The detections of 1-based ``frame`` of a MOTChallenge file with a score of at least ``min_score``.

    With ``frame_bgr`` each carries the HSV histogram of its box (clipped to the image) under
    ``"appearance"``.
    """
    rows = det.rows_at(frame)
    rows = rows[det.conf[rows] >= min_score]
    boxes = det.boxes_xyxy[rows]
    hists = box_histograms(frame_bgr, boxes) if frame_bgr is not None and len(rows) else None
    floor = floor_positions(camera, boxes)
    out = []
    for k, r in enumerate(rows):
        feats = {} if hists is None else {"appearance": hists[k]}
        pos = floor[k] if np.all(np.isfinite(floor[k])) else None
        out.append(Detection(t_ns, sensor, position_m=pos, box_px=boxes[k], score=float(det.conf[r]), cls="person",
                             features=feats))
    return out


def camera_truth_boxes(truth: Sequence[GroundTruth], width: int, height: int, *, min_visibility: float = 0.5,
                       frames: Sequence[int] | None = None) -> MotBoxes:
    """The simulator's per-camera truth (``/ground_truth/<camera>``) as MOT16-style ground-truth boxes.

    Boxes are clipped to the image; a person whose ``visibility`` is at least ``min_visibility`` is a
    pedestrian (class 1), a less visible one a distractor (class 8: a track on them is neither a hit nor a
    false positive, as MOT16's occluded people), and one entirely outside the image is left out. Evaluate
    with ``evaluate_boxes(..., preprocess=True)``.

    Parameters
    ----------
    truth : sequence of GroundTruth
        One record per image, with attributes ``box_px`` (n, 4) and ``visibility`` (n,).
    width, height : int
        Image size, px.
    min_visibility : float
    frames : sequence of int, optional
        1-based frame number of each record (default ``1 .. len(truth)``).

    Returns
    -------
    MotBoxes
        ``extra`` holds ``(class, visibility)``.
    """
    rows: list[np.ndarray] = []
    for k, g in enumerate(truth):
        if "box_px" not in g.attributes or len(g) == 0:
            continue
        b = np.clip(np.asarray(g.attributes["box_px"], np.float64), 0, [width, height, width, height])
        vis = np.asarray(g.attributes.get("visibility", np.ones(len(g))), np.float64)
        ok = np.all(np.isfinite(b), axis=1) & (b[:, 2] - b[:, 0] >= 1) & (b[:, 3] - b[:, 1] >= 1)
        cls = np.where(vis >= min_visibility, 1.0, 8.0)
        f = (k + 1) if frames is None else frames[k]
        rows.append(np.column_stack([np.full(len(g), f), g.ids, b[:, :2], b[:, 2:] - b[:, :2], np.ones(len(g)),
                                     cls, vis])[ok])
    a = np.concatenate(rows) if rows else np.zeros((0, 9))
    return MotBoxes(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a[:, 2:6], a[:, 6], a[:, 7:9])


# --------------------------------------------------------------------------------------------------
# The tracker
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class CameraTrackerParams:
    """Parameters of :class:`CameraPeopleTracker` [RECON]; pixels and seconds.

    Attributes
    ----------
    iou_min : float
        Smallest IoU of an overlap pair (0.1).
    centre_gate : float
        Largest centre distance of a pair without overlap, in box heights (0.5).
    size_gate : float
        Largest ratio of the heights of a pair (2.0).
    colour_weight : float
        Weight of ``1 − BC`` of colour histograms in the cost (0.5; 0 = off).
    n_confirm : int
        Consecutive hits that confirm a track (3).
    max_coast_s : float
        A confirmed track without a detection for longer ends (1.0 s).
    max_group_s : float
        Longest time a track stays inside a group without a detection of its own (5.0 s).
    group_containment : float
        Fraction of a predicted box inside a detection that makes the track a member of it (0.5).
    group_area_ratio : float
        A group detection is at least this many times larger than each member's predicted box (1.4): a
        person-sized box over two tracks is one person in front of the other, and goes to the assignment.
    fragment_containment : float
        Fraction of a detection inside a track's predicted box that makes it a fragment of that track (0.7).
    join_fragments : bool
        Join fragments (True; off for a person detector's boxes, where a box inside another's is someone
        farther away).
    birth_containment : float
        A detection this much inside a confirmed track's predicted box starts no track (0.5).
    q_centre_px2, q_size_px2 : float
        X5 white-noise acceleration of the centre and of the size, px²/s³ (400, 100).
    r_centre_px2, r_size_px2 : float
        Measurement variances of the centre and of the size, px² (9, 36).
    r_group_px2 : float
        Variance of the pseudo-measurement that keeps a group member inside its group's box (100 px²).
    velocity0_px_s : float
        Prior σ of a new track's velocity (100 px/s).
    frame_dt_s : float
        Time step when ``step`` gets equal times (0.1 s).
    output_coast_frames : int
        A confirmed track that misses its detection is still reported for this many frames (0).
    appearance_rate : float
        Rate at which a track's colour histogram follows its detections while it is alone (0.1).
    """

    iou_min: float = 0.1
    centre_gate: float = 0.5
    size_gate: float = 2.0
    colour_weight: float = 0.5
    n_confirm: int = 3
    max_coast_s: float = 1.0
    max_group_s: float = 5.0
    group_containment: float = 0.5
    group_area_ratio: float = 1.4
    fragment_containment: float = 0.7
    join_fragments: bool = True
    birth_containment: float = 0.5
    q_centre_px2: float = 400.0
    q_size_px2: float = 100.0
    r_centre_px2: float = 9.0
    r_size_px2: float = 36.0
    r_group_px2: float = 100.0
    velocity0_px_s: float = 100.0
    frame_dt_s: float = 0.1
    output_coast_frames: int = 0
    appearance_rate: float = 0.1

    def __post_init__(self) -> None:
        for name in ("n_confirm", "output_coast_frames"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < (1 if name == "n_confirm" else 0):
                raise ConfigError(f"CameraTrackerParams.{name}: expected an integer >= "
                                  f"{1 if name == 'n_confirm' else 0}, got {v!r}")
        for name in ("iou_min", "group_containment", "fragment_containment", "birth_containment",
                     "appearance_rate"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and 0 <= v <= 1):
                raise ConfigError(f"CameraTrackerParams.{name}: expected a value in [0, 1], got {v!r}")
        for name in ("centre_gate", "colour_weight", "max_coast_s", "max_group_s", "q_centre_px2", "q_size_px2",
                     "velocity0_px_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v >= 0):
                raise ConfigError(f"CameraTrackerParams.{name}: expected a finite value >= 0, got {v!r}")
        for name in ("r_centre_px2", "r_size_px2", "r_group_px2", "frame_dt_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v > 0):
                raise ConfigError(f"CameraTrackerParams.{name}: expected a finite value > 0, got {v!r}")
        for name in ("size_gate", "group_area_ratio"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and v >= 1):
                raise ConfigError(f"CameraTrackerParams.{name}: expected a ratio >= 1, got {v!r}")


@dataclass(slots=True, eq=False)
class _Track:
    key: int  # internal, also for tentative tracks
    centre: np.ndarray  # (4,) u, v, u̇, v̇
    P_centre: np.ndarray  # (4, 4)
    size: np.ndarray  # (4,) w, h, ẇ, ḣ
    P_size: np.ndarray
    track_id: int = -1  # -1 while tentative
    hits: int = 1
    missed: int = 0
    coast_s: float = 0.0
    group_s: float = 0.0  # time spent in groups since its last own detection
    grouped: bool = False  # in a group since its last own detection
    group: int = -1  # detection index of its group this frame, -1 when alone
    score: float = 1.0
    appearance: np.ndarray | None = None
    measured: bool = True

    def box(self) -> np.ndarray:
        return _box_from(self.centre[:2], np.maximum(self.size[:2], 1.0))


class CameraPeopleTracker:
    """Box tracker of the people in one camera (see the module docstring); :meth:`step` once per frame.

    Parameters
    ----------
    params : CameraTrackerParams, optional
    camera : PinholeCamera, optional
        Calibrated camera: states get floor positions and velocities (else ``NaN``).
    sensor : str
        ``sensor`` and ``camera`` of the states and events.

    Attributes
    ----------
    events : list of Event
        Events of the last :meth:`step`: ``appear`` (a track is confirmed), ``disappear`` (it ends),
        ``image_merge`` (tracks enter a group blob; ``track_ids`` the members) and ``image_split`` (a member
        is detected on its own again). The image events are occlusions in this camera, not seed 001's
        floor-plane merges.
    """

    def __init__(self, params: CameraTrackerParams | None = None, camera: PinholeCamera | None = None,
                 sensor: str = "camera") -> None:
        p = CameraTrackerParams() if params is None else params
        if not isinstance(p, CameraTrackerParams):
            raise ConfigError(f"params: expected CameraTrackerParams or None, got {type(p).__name__}")
        self.params = p
        self.camera = camera
        self.sensor = sensor
        self._tracks: list[_Track] = []
        self._next_key = 0
        self._next_id = 1
        self._t_ns: int | None = None
        self.events: list[Event] = []

    @property
    def n_confirmed(self) -> int:
        """Track ids handed out so far."""
        return self._next_id - 1

    def step(self, t_ns: int, detections: Sequence[Detection]) -> list[TrackState]:
        """Advance to ``t_ns`` with this frame's detections (their ``box_px``); return the confirmed tracks.

        Raises
        ------
        ValueError
            ``t_ns`` not after the previous frame's, or a detection without ``box_px``.
        """
        p = self.params
        t_ns = int(t_ns)
        if self._t_ns is not None and t_ns <= self._t_ns:
            raise ValueError(f"t_ns: {t_ns} is not after the previous frame's {self._t_ns}")
        dt = p.frame_dt_s if self._t_ns is None else (t_ns - self._t_ns) * 1e-9
        self._t_ns = t_ns
        self.events = []
        if any(d.box_px is None for d in detections):
            raise ValueError("detections: every detection needs box_px")
        boxes = np.array([d.box_px for d in detections], np.float64).reshape(-1, 4)
        scores = np.array([d.score for d in detections], np.float64)
        app = [d.features.get("appearance") for d in detections]
        appearance = np.array(app, np.float64) if app and all(a is not None for a in app) else None

        self._predict(dt)
        tracks = self._tracks
        pred = np.array([t.box() for t in tracks]).reshape(-1, 4)
        confirmed = np.array([t.track_id > 0 for t in tracks], bool)
        boxes, scores, appearance = self._join_fragments(pred, confirmed, boxes, scores, appearance)
        in_group = self._groups(pred, confirmed, boxes, dt)
        free_det = np.ones(len(boxes), bool)
        free_det[list({t.group for t in tracks if t.group >= 0})] = False
        rows = np.flatnonzero(~in_group)
        cols = np.flatnonzero(free_det)
        cost = self._cost(pred[rows], boxes[cols], rows, None if appearance is None else appearance[cols])
        pairs, _, free_cols = hungarian(cost)
        matched = np.zeros(len(tracks), bool)
        if len(pairs):
            ti, dj = rows[pairs[:, 0]], cols[pairs[:, 1]]
            matched[ti] = True
            self._update(ti, boxes[dj], scores[dj], None if appearance is None else appearance[dj])
        self._births(pred, confirmed, boxes[cols[free_cols]], scores[cols[free_cols]],
                     None if appearance is None else appearance[cols[free_cols]])
        self._lifecycle(matched, in_group, dt)
        return self._states(t_ns)

    # -- steps ----------------------------------------------------------------------------------------

    def _predict(self, dt: float) -> None:
        p = self.params
        if not self._tracks:
            return
        F, Qc = kalman.cv_matrices(dt, p.q_centre_px2)
        _, Qs = kalman.cv_matrices(dt, p.q_size_px2)
        xc, Pc = kalman.predict(np.array([t.centre for t in self._tracks]),
                                np.array([t.P_centre for t in self._tracks]), F, Qc)
        xs, Ps = kalman.predict(np.array([t.size for t in self._tracks]),
                                np.array([t.P_size for t in self._tracks]), F, Qs)
        xs[:, :2] = np.maximum(xs[:, :2], 2.0)
        for t, a, b, c, d in zip(self._tracks, xc, Pc, xs, Ps, strict=True):
            t.centre, t.P_centre, t.size, t.P_size = a, b, c, d
            t.group = -1
            t.measured = False

    def _join_fragments(self, pred: np.ndarray, confirmed: np.ndarray, boxes: np.ndarray, scores: np.ndarray,
                        appearance: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Detections mostly inside exactly one confirmed track's predicted box, two or more per track: union."""
        p = self.params
        if not p.join_fragments or not confirmed.any() or len(boxes) < 2:
            return boxes, scores, appearance
        inside = box_containment(boxes, pred[confirmed]) >= p.fragment_containment  # (n_det, n_conf)
        owner = np.where(inside.sum(axis=1) == 1, np.argmax(inside, axis=1), -1)
        keep = np.ones(len(boxes), bool)
        boxes = boxes.copy()
        for k in np.unique(owner[owner >= 0]):
            js = np.flatnonzero(owner == k)
            if len(js) < 2:
                continue
            boxes[js[0]] = np.r_[boxes[js, :2].min(axis=0), boxes[js, 2:].max(axis=0)]
            keep[js[1:]] = False
            if appearance is not None:
                area = _areas(boxes[js])
                appearance = appearance.copy()
                appearance[js[0]] = area @ appearance[js] / max(area.sum(), 1e-9)
        return boxes[keep], scores[keep], None if appearance is None else appearance[keep]

    def _groups(self, pred: np.ndarray, confirmed: np.ndarray, boxes: np.ndarray, dt: float) -> np.ndarray:
        """Mark the members of group detections; coast them inside the group's box. ``(n_tracks,)`` bool."""
        p = self.params
        in_group = np.zeros(len(self._tracks), bool)
        if not confirmed.any() or not len(boxes):
            return in_group
        eligible = confirmed & np.array([t.group_s <= p.max_group_s for t in self._tracks], bool)
        inside = (box_containment(pred, boxes) >= p.group_containment) & eligible[:, None]  # (n_tracks, n_det)
        # a group's box is bigger than each member's: a person-sized box over two tracks is one of them in front
        # of the other (or two people right behind each other), which the assignment gives to one track
        inside &= _areas(boxes)[None, :] >= p.group_area_ratio * _areas(pred)[:, None]
        for j in np.flatnonzero(inside.sum(axis=0) >= 2):
            members = np.flatnonzero(inside[:, j] & ~in_group)
            if len(members) < 2:
                continue
            in_group[members] = True
            group_box = boxes[j]
            new = [self._tracks[i].track_id for i in members if not self._tracks[i].grouped]
            if new:
                self.events.append(Event(int(self._t_ns or 0), self.sensor, "image_merge",
                                         track_ids=tuple(sorted(self._tracks[i].track_id for i in members)),
                                         attributes={"box_px": tuple(float(v) for v in group_box)}))
            for i in members:
                t = self._tracks[i]
                t.group = int(j)
                t.group_s += dt
                size = np.minimum(t.size[:2], group_box[2:] - group_box[:2])
                lo, hi = group_box[:2] + size / 2, group_box[2:] - size / 2
                target = np.clip(t.centre[:2], np.minimum(lo, hi), np.maximum(lo, hi))
                t.size[:2], t.size[2:] = size, 0.0
                if np.any(target != t.centre[:2]):
                    x, P = kalman.update(t.centre[None], t.P_centre[None], target[None], R=p.r_group_px2)
                    t.centre, t.P_centre = x[0], P[0]
        return in_group

    def _cost(self, pred: np.ndarray, boxes: np.ndarray, rows: np.ndarray, appearance: np.ndarray | None
              ) -> np.ndarray:
        """Assignment cost of predicted boxes ``(n, 4)`` and detections ``(m, 4)`` (module docstring)."""
        p = self.params
        iou = box_iou(pred, boxes)
        pc, ps = _centre_size(pred)
        dc, ds = _centre_size(boxes)
        h = np.maximum(ps[:, None, 1], ds[None, :, 1])
        d = np.linalg.norm(pc[:, None] - dc[None], axis=2) / np.maximum(h, 1.0)
        ratio = np.maximum(ps[:, None, 1], 1.0) / np.maximum(ds[None, :, 1], 1.0)
        cost = np.where(iou >= max(p.iou_min, 1e-9), 1.0 - iou, np.where(d <= p.centre_gate, 1.0 + d, np.inf))
        cost[(ratio > p.size_gate) | (ratio < 1.0 / p.size_gate)] = np.inf
        if appearance is not None and p.colour_weight > 0 and len(rows):
            have = [i for i, r in enumerate(rows) if self._tracks[r].appearance is not None]
            if have:
                track_app = np.array([self._tracks[rows[i]].appearance for i in have])
                cost[have] += p.colour_weight * _bc_cost(track_app, appearance)
        return cost

    def _update(self, ti: np.ndarray, boxes: np.ndarray, scores: np.ndarray, appearance: np.ndarray | None) -> None:
        p = self.params
        tracks = [self._tracks[i] for i in ti]
        c, s = _centre_size(boxes)
        xc, Pc = kalman.update(np.array([t.centre for t in tracks]), np.array([t.P_centre for t in tracks]), c,
                               R=p.r_centre_px2)
        xs, Ps = kalman.update(np.array([t.size for t in tracks]), np.array([t.P_size for t in tracks]), s,
                               R=p.r_size_px2)
        for k, t in enumerate(tracks):
            t.centre, t.P_centre, t.size, t.P_size = xc[k], Pc[k], xs[k], Ps[k]
            t.hits += 1
            t.missed = 0
            t.coast_s = 0.0
            t.score = float(scores[k])
            t.measured = True
            if appearance is not None:
                if t.appearance is None:
                    t.appearance = appearance[k]
                else:
                    a = (1 - p.appearance_rate) * t.appearance + p.appearance_rate * appearance[k]
                    t.appearance = a / max(a.sum(), 1e-12)

    def _births(self, pred: np.ndarray, confirmed: np.ndarray, boxes: np.ndarray, scores: np.ndarray,
                appearance: np.ndarray | None) -> None:
        p = self.params
        if not len(boxes):
            return
        born = np.ones(len(boxes), bool)
        if confirmed.any():
            born = box_containment(boxes, pred[confirmed]).max(axis=1) < p.birth_containment
        c, s = _centre_size(boxes)
        v0 = p.velocity0_px_s**2
        for j in np.flatnonzero(born):
            self._tracks.append(_Track(
                self._next_key, np.r_[c[j], 0.0, 0.0], np.diag([p.r_centre_px2, p.r_centre_px2, v0, v0]),
                np.r_[s[j], 0.0, 0.0], np.diag([p.r_size_px2, p.r_size_px2, v0 / 16, v0 / 16]),
                score=float(scores[j]), appearance=None if appearance is None else appearance[j]))
            self._next_key += 1

    def _lifecycle(self, matched: np.ndarray, in_group: np.ndarray, dt: float) -> None:
        p = self.params
        keep: list[_Track] = []
        n_old = len(matched)
        for i, t in enumerate(self._tracks):
            if i >= n_old:  # born this frame
                keep.append(t)
                continue
            if matched[i] and t.grouped:
                self.events.append(Event(int(self._t_ns or 0), self.sensor, "image_split", track_ids=(t.track_id,)))
            t.grouped = bool(in_group[i]) or (t.grouped and not matched[i])
            if matched[i]:
                t.group_s = 0.0
                if t.track_id < 0 and t.hits >= p.n_confirm:
                    t.track_id = self._next_id
                    self._next_id += 1
                    self.events.append(Event(int(self._t_ns or 0), self.sensor, "appear", track_ids=(t.track_id,)))
                keep.append(t)
                continue
            if in_group[i]:
                keep.append(t)
                continue
            t.missed += 1
            t.coast_s += dt
            if t.track_id < 0:
                continue  # a tentative track ends at its first miss
            if t.coast_s > p.max_coast_s:
                self.events.append(Event(int(self._t_ns or 0), self.sensor, "disappear", track_ids=(t.track_id,)))
                continue
            keep.append(t)
        self._tracks = keep

    def _states(self, t_ns: int) -> list[TrackState]:
        p = self.params
        out = [t for t in self._tracks if t.track_id > 0 and (t.measured or t.group >= 0
                                                               or t.missed <= p.output_coast_frames)]
        if not out:
            return []
        boxes = np.array([t.box() for t in out])
        floor = floor_positions(self.camera, boxes)
        vel = np.full_like(floor, np.nan)
        if self.camera is not None:  # the bottom centre moved by the image velocity over 0.1 s
            h = 0.1
            ahead = boxes + h * np.array([np.r_[t.centre[2:], t.centre[2:]] for t in out])
            vel = (floor_positions(self.camera, ahead) - floor) / h
        states = []
        for k, t in enumerate(out):
            states.append(TrackState(
                t_ns, self.sensor, t.track_id, floor[k], vel[k], cls="person",
                situation=_MERGED if t.group >= 0 else _NONCORRELATED,
                sensors=(self.sensor,) if t.measured else (), score=t.score, box_px=boxes[k], camera=self.sensor))
        return states


# --------------------------------------------------------------------------------------------------
# Recording / video level
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class FrameResult:
    """What :func:`track_camera` saw and did in one frame (given to ``on_frame`` and the overlay).

    Attributes
    ----------
    index : int
        0-based frame number.
    image : Image
    detections : list of Detection
    states : list of TrackState
    foreground : ForegroundResult or None
        ``None`` when the foreground is not computed (detection-file mode without an overlay).
    blobs : Blobs or None
    mode : str
        ``"blobs"`` (the detections are the blobs) or ``"detections"`` (from a file).
    """

    index: int
    image: Image
    detections: list[Detection]
    states: list[TrackState]
    foreground: ForegroundResult | None = None
    blobs: Blobs | None = None
    mode: str = "blobs"

    def contours(self) -> list[np.ndarray]:
        """Outer contours of the foreground blobs (empty without a foreground)."""
        return [] if self.blobs is None else blob_contours(self.blobs)


@dataclass(frozen=True, slots=True, eq=False)
class CameraRunStats:
    """Facts about one :func:`track_camera` run.

    Attributes
    ----------
    mode : str
        ``"blobs"`` or ``"detections"``.
    sensor : str
    n_frames : int
    width, height : int
    n_tracks : int
        Track ids handed out.
    n_detections : int
        Detections given to the tracker over the run.
    calibrated : bool
        A camera model gave floor positions.
    frame_times_ns : (n_frames,) int64
        Time of each frame (frame ``k`` of a MOT file is ``frame_times_ns[k - 1]``).
    seconds : dict of str -> float
        Wall time of ``decode``, ``foreground`` (MoG + blobs), ``track`` and ``overlay`` (drawing + encoding).
    """

    mode: str
    sensor: str
    n_frames: int
    width: int
    height: int
    n_tracks: int
    n_detections: int
    calibrated: bool
    frame_times_ns: np.ndarray
    seconds: dict[str, float] = field(default_factory=dict)

    @property
    def fps(self) -> float:
        """Frames per second of decoding, foreground and tracking (without the overlay)."""
        busy = sum(v for k, v in self.seconds.items() if k != "overlay")
        return self.n_frames / busy if busy > 0 else float("nan")

    def frame_of(self) -> dict[int, int]:
        """``t_ns -> 1-based frame`` (for :func:`~fusiontrack.io.tracks.write_mot`)."""
        return {int(t): k + 1 for k, t in enumerate(self.frame_times_ns)}


VIDEO_SUFFIXES = frozenset({".avi", ".mp4", ".mkv", ".mov", ".m4v", ".webm", ".mpg", ".mpeg"})


class _Frames:
    """Time-stamped colour images of a video file or a recording's image topic, with the camera if known."""

    def __init__(self, source: str | Path | Sequence[str | Path], camera_topic: str | None, camera: Any,
                 time_source: str) -> None:
        from ..io.recording import Recording
        from ..io.video import VideoReader

        paths = [Path(source)] if isinstance(source, str | Path) else [Path(s) for s in source]
        if not paths:
            raise RecordingError("source: expected a video file or a recording, got nothing")
        self.paths = paths
        self.camera: PinholeCamera | None = None if isinstance(camera, str) else camera
        self._rec: Any = None
        if len(paths) == 1 and paths[0].suffix.lower() in VIDEO_SUFFIXES:
            self._video = VideoReader(paths[0])
            self.sensor = self._video.sensor
            self.count = self._video.frame_count
            self._fps: float | None = self._video.fps
            self.width, self.height = self._video.width, self._video.height
            if camera == "auto":
                self.camera = None
            return
        self._video = None
        self._rec = Recording(paths)
        try:
            self.topic = self._rec.image_topic(topic=camera_topic)
            self.sensor = self._rec.sensor_of(self.topic)
            # the count from the connections (index or metadata); the rate, which needs the topic's span (a pass over
            # the whole recording, Recording.topics), only if an overlay video asks for it
            self.count = sum(c.msgcount for c in self._rec.connections if c.topic == self.topic)
            self._fps = None
            self._time_source = time_source
            first = next((m for m in self._rec.messages([self.topic], time_source=time_source)
                          if isinstance(m, Image)), None)
            if first is None:
                raise RecordingError(f"{paths[0]}: image topic {self.topic} holds no readable image")
            self.width, self.height = first.width, first.height
            if camera == "auto":
                self.camera = camera_from_recording(self._rec, self.sensor, first.frame_id)
        except BaseException:
            self._rec.close()
            raise

    @property
    def fps(self) -> float:
        """The video's frame rate, or the image topic's mean rate (10 for fewer than two images)."""
        if self._fps is None:
            rate = self._rec.topics()[self.topic].rate_hz
            self._fps = rate if rate > 0 else 10.0
        return self._fps

    def __iter__(self) -> Iterator[Image]:
        if self._video is not None:
            yield from self._video
            return
        last = None
        for m in self._rec.messages([self.topic], time_source=self._time_source):
            if not isinstance(m, Image) or m.encoding == "mono16":
                continue
            if last is not None and m.t_ns <= last:  # a duplicate or out-of-order stamp cannot be a frame
                log.warning("%s: image at %d ns is not after the previous one; skipped", self.topic, m.t_ns)
                continue
            last = m.t_ns
            yield m

    def close(self) -> None:
        if self._video is not None:
            self._video.close()
        if self._rec is not None:
            self._rec.close()


def track_camera(
    source: str | Path | Sequence[str | Path],
    *,
    detections: str | Path | MotBoxes | None = None,
    camera_topic: str | None = None,
    camera: PinholeCamera | str | None = "auto",
    params: CameraTrackerParams | None = None,
    min_score: float = -np.inf,
    detection_scale: float = 1.0,
    foreground: ForegroundParams | None = None,
    blob_params: BlobParams | None = None,
    complete_height_m: float | None = 1.72,
    colour: bool = True,
    overlay: str | Path | None = None,
    max_frames: int | None = None,
    time_source: str = "header",
    on_frame: Callable[[FrameResult], None] | None = None,
    progress: Callable[[float], None] | None = None,
) -> tuple[list[TrackState], list[Event], CameraRunStats]:
    """Track the people in a video file or a recording's camera with :class:`CameraPeopleTracker`.

    Parameters
    ----------
    source : path or paths
        A video file (``.avi``, ``.mp4``, ...; times from its frame rate) or a recording (bag, MCAP, ...).
    detections : path or MotBoxes, optional
        A MOTChallenge detection file (``det.txt``: ``frame,-1,left,top,width,height,conf,...``, frames
        1-based in the order of the images). Without it the detections are the foreground blobs (A1-A4).
    camera_topic : str, optional
        The recording's image topic (default: its only one; labels and depth images are not candidates).
    camera : PinholeCamera, ``"auto"`` or None
        ``"auto"``: from the recording's CameraInfo and ``/tf_static`` (:func:`camera_from_recording`);
        none for a video. Floor positions need one.
    params : CameraTrackerParams, optional
        Default: :class:`CameraTrackerParams`, without fragment joining for a detection file.
    min_score : float
        Detections of the file with a lower confidence are dropped.
    detection_scale : float
        The file's boxes are multiplied by this (0.625 for MOT15's 768x576 PETS boxes on a 480x360 video).
    foreground, blob_params : optional
        Parameters of the foreground model (A1-A3) and of blob extraction (A4).
    complete_height_m : float or None
        With a camera, blob boxes shorter than a person this tall are completed to the feet
        (:func:`complete_person_boxes`); ``None`` = off.
    colour : bool
        Use HSV histograms of the detections in the association cost.
    overlay : path, optional
        Write the overlay video (boxes, ids, foreground contours, frame number) here.
    max_frames : int, optional
        Stop after this many frames.
    time_source : ``"header"`` or ``"log"``
        Image times of a recording.
    on_frame : callable, optional
        Called with each :class:`FrameResult`.
    progress : callable, optional
        Called with the fraction of frames done.

    Returns
    -------
    states : list of TrackState
        Every reported state, in time order (``box_px`` set; ``position_m`` NaN without a camera).
    events : list of Event
    stats : CameraRunStats

    Raises
    ------
    RecordingError
        Missing or unreadable source or detection file, a video without frames, a recording without an image
        topic.
    ConfigError
        Bad parameters, several image topics and none chosen, or detections that do not fit the frames.
    """
    if detection_scale <= 0 or not np.isfinite(detection_scale):
        raise ConfigError(f"detection_scale: expected a positive factor, got {detection_scale!r}")
    if max_frames is not None and max_frames < 1:
        raise ConfigError(f"max_frames: expected >= 1, got {max_frames!r}")
    if time_source not in ("header", "log"):
        raise ConfigError(f"time_source: expected 'header' or 'log', got {time_source!r}")
    if isinstance(camera, str) and camera != "auto":
        raise ConfigError(f"camera: expected a PinholeCamera, 'auto' or None, got {camera!r}")
    det: MotBoxes | None = None
    if detections is not None:
        det = detections if isinstance(detections, MotBoxes) else read_mot(detections)
        if detection_scale != 1.0:
            det = det.scaled(detection_scale)
        if len(det.conf) and np.isfinite(min_score) and not np.any(det.conf >= min_score):
            log.warning("%s: min_score %g is above every detection's score (%.3g to %.3g): no detection is used",
                        detections if isinstance(detections, str | Path) else "detections", min_score,
                        float(np.min(det.conf)), float(np.max(det.conf)))
    frames = _Frames(source, camera_topic, camera, time_source)
    if det is not None and len(det) and frames.count > 0:  # (a file of another sequence, or numbered otherwise)
        inside = float(np.mean(det.frame <= frames.count))
        if inside < 0.5:
            log.warning("%s: %.0f %% of its boxes are in frames 1..%d of %s (its frames %d..%d): another sequence, "
                        "or frames numbered otherwise? The others are never used",
                        detections if isinstance(detections, str | Path) else "detections", 100 * inside,
                        frames.count, frames.paths[0], int(det.frame.min()), int(det.frame.max()))
    try:
        with opencv_threads(1):  # small frames: OpenCV's worker threads cost more CPU than they save
            return _run(frames, det, params, min_score, foreground, blob_params, complete_height_m, colour,
                        overlay, max_frames, on_frame, progress)
    finally:
        frames.close()


def _check_detections(det: MotBoxes, width: int, height: int, source: Path) -> None:
    """Detection boxes whose centres fall well outside the frame are at another resolution: say so."""
    if not len(det):
        return
    c = (det.boxes_xyxy[:, :2] + det.boxes_xyxy[:, 2:]) / 2
    outside = (c[:, 0] > 1.05 * width) | (c[:, 1] > 1.05 * height) | (c[:, 0] < -0.05 * width) | \
        (c[:, 1] < -0.05 * height)
    if outside.mean() > 0.01:
        far = det.boxes_xyxy[:, 2:].max(axis=0)
        raise ConfigError(f"detections: {100 * outside.mean():.0f} % of the boxes lie outside the {width}x{height} "
                          f"frames of {source} (they reach {far[0]:.0f}x{far[1]:.0f} px); scale them to the video "
                          "with detection_scale (--detection-scale), e.g. 0.625 for 768x576 boxes on 480x360")


def _run(frames: _Frames, det: MotBoxes | None, params: CameraTrackerParams | None, min_score: float,
         fg_params: ForegroundParams | None, blob_params: BlobParams | None, complete_height_m: float | None,
         colour: bool, overlay: str | Path | None, max_frames: int | None,
         on_frame: Callable[[FrameResult], None] | None, progress: Callable[[float], None] | None,
         ) -> tuple[list[TrackState], list[Event], CameraRunStats]:
    from ..io.video import write_video
    from .overlay import OverlayRenderer

    if det is not None:
        _check_detections(det, frames.width, frames.height, frames.paths[0])
        if params is None:
            params = CameraTrackerParams(join_fragments=False)
    tracker = CameraPeopleTracker(params, frames.camera, frames.sensor)
    model = ForegroundModel(fg_params) if det is None or overlay is not None else None
    states: list[TrackState] = []
    events: list[Event] = []
    times: list[int] = []
    seconds = {"decode": 0.0, "foreground": 0.0, "track": 0.0, "overlay": 0.0}
    size: list[int] = []
    total = frames.count if max_frames is None else min(frames.count, max_frames)
    n_det = 0

    def results() -> Iterator[FrameResult]:
        nonlocal n_det
        it = iter(frames)
        k = 0
        while max_frames is None or k < max_frames:
            t0 = time.perf_counter()
            image = next(it, None)
            t1 = time.perf_counter()
            seconds["decode"] += t1 - t0
            if image is None:
                break
            if not size:
                size.extend((image.width, image.height))
            bgr = image.bgr()
            fg = blobs = None
            if model is not None:
                fg = model.apply(bgr)
                blobs = extract_blobs(fg.mask, blob_params)
            t2 = time.perf_counter()
            seconds["foreground" if det is None else "overlay"] += t2 - t1  # with a file, only the overlay needs it
            if det is None:
                assert blobs is not None
                dets = blob_detections(blobs, image.t_ns, frames.sensor, bgr if colour else None, frames.camera,
                                       complete_height_m)
            else:
                dets = mot_detections(det, k + 1, image.t_ns, frames.sensor, min_score=min_score,
                                      frame_bgr=bgr if colour else None, camera=frames.camera)
            new = tracker.step(image.t_ns, dets)
            seconds["track"] += time.perf_counter() - t2
            n_det += len(dets)
            states.extend(new)
            events.extend(tracker.events)
            times.append(image.t_ns)
            result = FrameResult(k, image, dets, new, fg, blobs, "blobs" if det is None else "detections")
            if on_frame is not None:
                on_frame(result)
            k += 1
            if progress is not None and (k % 25 == 0):
                progress(min(k / max(total, 1), 1.0))
            yield result

    if overlay is not None:
        renderer = OverlayRenderer()

        def drawn() -> Iterator[np.ndarray]:
            for r in results():
                t0 = time.perf_counter()
                img = renderer.render(r)
                seconds["overlay"] += time.perf_counter() - t0
                yield img

        fps = min(max(frames.fps, 1.0), 60.0)  # (the image topic's rate: a pass over the recording, not timed)
        t0 = time.perf_counter()
        write_video(overlay, drawn(), fps=fps)
        # write_video's own time (encoding) minus what the frames cost to make
        seconds["overlay"] = time.perf_counter() - t0 - sum(v for k, v in seconds.items() if k != "overlay")
    else:
        for _ in results():
            pass
    if not times:
        raise RecordingError(f"{frames.paths[0]}: no frame to track (an empty video or image topic)")
    if progress is not None:
        progress(1.0)
    stats = CameraRunStats("blobs" if det is None else "detections", frames.sensor, len(times), size[0], size[1],
                           tracker.n_confirmed, n_det, frames.camera is not None, np.array(times, np.int64), seconds)
    log.info("%s: %d frames, %d tracks, %.1f fps", frames.paths[0], len(times), tracker.n_confirmed, stats.fps)
    return states, events, stats
