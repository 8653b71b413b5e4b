"""Seed 001's tracking-learning loop: laser particle filters and per-target camera classifiers, each helping the other.

:class:`FusionTracker` owns a :class:`~fusiontrack.tracking.tracker.LaserPeopleTracker` and an
:class:`~fusiontrack.vision.appearance.AppearanceBank` and, per laser step (ALGORITHMS.md sections in brackets):

1. **tracking** — the laser tracker steps as on its own; two hooks let the camera in only where the laser
   is weak:

   * correlated targets (B7 rule 3): the score map of the classifiers of the targets close to each other
     (one map per group, over their projected boxes dilated by 20 %, B16) weights their particles,
     ``β · log p(z | x)`` with the box centre ``d(x)`` of each particle's feet midpoint (B11); at most once
     per camera frame and target;
   * a merged target that splits (B17): each piece's box is scored by the members' classifiers
     (:meth:`~fusiontrack.vision.appearance.AppearanceBank.box_scores`) and the members are given to the
     pieces by the Hungarian algorithm on ``−score``, when every member has a trained classifier; by motion
     otherwise;
2. **learning** [B15] — a noncorrelated target with another target within ``d_train_m`` (1.5 m) learns from
   the camera image nearest in time: positives from its projected box (B11), negatives from the boxes of
   its ``L`` closest targets (patches centred in another box are dropped); at most once every
   ``train_interval_s``; merged targets' classifiers are frozen.

The camera image is converted only when one of these needs it (:class:`~fusiontrack.fusion.frames.LazyFrames`),
so with no interaction the fused tracker costs what the laser one costs. Each output state names the sensors
that confirmed its step: the laser's, plus the camera's when the image was used for that target.

:func:`track_fused` runs it over a recording (laser scans + one camera).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from ..errors import ConfigError, RecordingError
from ..geometry import PinholeCamera
from ..tracking.tracker import LaserPeopleTracker, TrackerParams, run_tracker
from ..types import Detection, Event, Image, Situation, TrackState
from ..vision.appearance import AppearanceBank, AppearanceParams

__all__ = ["FrameSource", "FusionParams", "FusionStats", "FusionTracker", "track_fused"]

log = logging.getLogger(__name__)

_LEARNING = (str(Situation.NONCORRELATED), str(Situation.APPEARING))


class FrameSource(Protocol):
    """Camera images by time (e.g. :class:`~fusiontrack.fusion.frames.LazyFrames`)."""

    def nearest_time(self, t_ns: int) -> int | None:
        """Time of the image nearest to ``t_ns`` if one is close enough, without reading it."""

    def at(self, t_ns: int) -> Image | None:
        """That image (BGR), or None."""


@dataclass(frozen=True, slots=True)
class FusionParams:
    """Parameters of :class:`FusionTracker` (ALGORITHMS.md values unless marked).

    Attributes
    ----------
    d_train_m : float
        B15: a target learns while another target is closer than this (seed 001: 1.5 m).
    train_interval_s : float
        At most one training frame per target group every this many seconds [RECON: the camera's 15 Hz
        frames are highly correlated; one in three brings as much].
    score_map : bool
        B16 on (score-map observation of correlated targets). Off by default: on the simulated groups it made
        identities worse (``benchmarks/fusion.py``; people side by side have overlapping boxes, and the map pulls
        particles towards the neighbour's look-alike patches).
    score_beta : float
        Exponent of the score-map likelihood (the last annealing level's weight would be 1; the laser
        likelihood is kept, so the camera term is tempered) [RECON].
    group_m : float
        Correlated targets closer than this share one score map [RECON].
    split_identity : bool
        B17 on (classifiers decide identities at splits).
    split_margin : float
        Two-member splits: appearance decides only if the best assignment beats the other one by this much
        summed confidence [RECON; 0.3 measured on simulated groups]; motion otherwise.
    height_m, width_ratio : float
        B11's person box (``H_p``, ``r_w``).
    max_frame_dt_s : float
        An image is used for a laser step only if this close in time.
    appearance : AppearanceParams
        The classifiers (B12-B14).
    """

    d_train_m: float = 1.5
    train_interval_s: float = 0.2
    score_map: bool = False
    score_beta: float = 0.5
    group_m: float = 1.0
    split_identity: bool = True
    split_margin: float = 0.3
    height_m: float = 1.70
    width_ratio: float = 0.40
    max_frame_dt_s: float = 0.05
    appearance: AppearanceParams = field(default_factory=AppearanceParams)

    def __post_init__(self) -> None:
        for name in ("d_train_m", "train_interval_s", "score_beta", "group_m", "split_margin", "height_m",
                     "width_ratio", "max_frame_dt_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v >= 0):
                raise ConfigError(f"FusionParams.{name}: expected a finite value >= 0, got {v!r}")
        if self.height_m <= 0 or self.width_ratio <= 0:
            raise ConfigError("FusionParams.height_m, width_ratio: expected values > 0")


@dataclass(slots=True)
class FusionStats:
    """What the camera was used for during a run."""

    steps: int = 0
    frames_used: int = 0  # distinct camera images read
    train_frames: int = 0  # (step, image) pairs the bank learnt from
    train_updates: int = 0  # classifier ensemble updates
    score_maps: int = 0  # B16 score maps computed
    splits: int = 0  # splits seen
    splits_by_appearance: int = 0
    overrides: int = 0  # splits where appearance gave another assignment than motion
    camera_s: float = 0.0  # time spent on the camera side (reading, learning, scoring)


def _components(points: np.ndarray, radius_m: float) -> np.ndarray:
    """Labels ``(n,)`` of the groups of ``points (n, 2)`` linked by distances below ``radius_m``."""
    from scipy.sparse.csgraph import connected_components

    if points.shape[0] < 2:
        return np.arange(points.shape[0])
    close = np.linalg.norm(points[:, None] - points[None], axis=2) < radius_m
    return connected_components(close, directed=False)[1]


class FusionTracker:
    """Laser people tracker with online per-target appearance classifiers (seed 001; module docstring).

    Parameters
    ----------
    camera : PinholeCamera
        The calibrated camera (world frame, B11).
    frames : FrameSource
        Its images by time.
    params : FusionParams, optional
    tracker_params : TrackerParams or mapping, optional
        Of the laser tracker.
    area_m : optional
        Covered area (see :class:`LaserPeopleTracker`).
    rng : Generator, int or None
        Normalised once; the laser tracker and the bank get independent streams from it.
    camera_name : str
        The camera's sensor name, added to ``TrackState.sensors`` when its image was used.
    """

    def __init__(self, camera: PinholeCamera, frames: FrameSource, params: FusionParams | None = None,
                 tracker_params: TrackerParams | Mapping[str, Any] | None = None, *, area_m: Any = None,
                 rng: np.random.Generator | int | None = None, camera_name: str = "camera") -> None:
        self.params = p = params or FusionParams()
        self.camera = camera
        self.frames = frames
        self.camera_name = camera_name
        r_laser, r_bank = np.random.default_rng(rng).spawn(2)
        self.bank = AppearanceBank(p.appearance, rng=r_bank)
        self.laser = LaserPeopleTracker(tracker_params, area_m=area_m, rng=r_laser,
                                        extra_log_likelihood=self._score_map_ll if p.score_map else None,
                                        split_scores=self._split_scores if p.split_identity else None)
        self.stats = FusionStats()
        self.events: list[Event] = []
        self._used: set[int] = set()  # ids whose step used the camera
        self._scored: dict[int, int] = {}  # id -> time of the image last used for its score map
        self._learnt_t: dict[int, int] = {}  # id -> time of its last training step
        self._frames_seen: set[int] = set()

    @property
    def area_m(self) -> np.ndarray | None:
        return self.laser.area_m

    @area_m.setter
    def area_m(self, value: Any) -> None:
        self.laser.area_m = value

    # ---------------------------------------------------------------------------------------------
    def step(self, t_ns: int, detections: Sequence[Detection]) -> list[TrackState]:
        """One laser step, then learning (B15). Returns the states (``sensors`` with the camera where used)."""
        self._used = set()
        self.stats.steps += 1
        states = self.laser.step(t_ns, detections)
        self.events = list(self.laser.events)
        if states:
            self._learn(int(t_ns), states)
        self._forget(self.events)
        if not self._used:
            return states
        cam = self.camera_name
        return [dataclasses.replace(s, sensors=(*s.sensors, cam)) if s.track_id in self._used else s
                for s in states]

    def finish(self) -> list[Event]:
        """The events still held back by the laser tracker (end of a run)."""
        return self.laser.finish()

    # ---------------------------------------------------------------------------------------------
    def _image(self, t_ns: int) -> Image | None:
        t0 = time.perf_counter()
        img = self.frames.at(t_ns)
        if img is not None and img.t_ns not in self._frames_seen:
            self._frames_seen.add(img.t_ns)
            self.stats.frames_used += 1
        self.stats.camera_s += time.perf_counter() - t0
        return img

    def _boxes(self, positions_m: np.ndarray) -> np.ndarray:
        """B11 person boxes ``(n, 4)`` of floor positions ``(n, 2)``; NaN rows behind the camera."""
        return self.camera.person_box(positions_m, self.params.height_m, self.params.width_ratio)

    def _box_centres(self, positions_m: np.ndarray) -> np.ndarray:
        b = self._boxes(positions_m)
        return 0.5 * (b[:, :2] + b[:, 2:])

    def _forget(self, events: Iterable[Event]) -> None:
        for e in events:
            if e.kind in ("disappear", "lost"):
                self.bank.drop(e.track_ids)
                for tid in e.track_ids:
                    self._scored.pop(tid, None)
                    self._learnt_t.pop(tid, None)
            elif e.kind == "split":
                self.stats.splits += 1
                if e.attributes.get("identity") == "appearance":
                    self.stats.splits_by_appearance += 1
                    self.stats.overrides += bool(e.attributes.get("overrode_motion"))

    # ---------------------------------------------------------------------------------------------
    def _learn(self, t_ns: int, states: list[TrackState]) -> None:
        """B15: noncorrelated targets with another target within ``d_train_m`` learn from this image."""
        p = self.params
        pos = np.array([s.position_m for s in states])
        ids = np.array([s.track_id for s in states])
        if len(states) < 2:
            return
        d = np.linalg.norm(pos[:, None] - pos[None], axis=2)
        np.fill_diagonal(d, np.inf)
        near = d.min(axis=1) < p.d_train_m
        interval = p.train_interval_s * 1e9
        # an untrained target learns from every image, a trained one every ``train_interval_s``
        learners = [k for k, s in enumerate(states)
                    if near[k] and s.situation in _LEARNING and s.sensors
                    and (not self.bank.is_trained(s.track_id)
                         or t_ns - self._learnt_t.get(s.track_id, -(1 << 62)) >= interval)]
        if not learners:
            return
        if self.frames.nearest_time(t_ns) is None:
            return  # no image now (camera blackout, or between frames): the laser goes on alone
        t0 = time.perf_counter()
        img = self._image(t_ns)
        if img is None:
            return
        boxes = self._boxes(pos)
        ok = np.isfinite(boxes).all(axis=1)
        learners = [k for k in learners if ok[k]]
        if not learners:
            self.stats.camera_s += time.perf_counter() - t0
            return
        # the learners, their confusers (within d_train), and whoever's box overlaps theirs (occluders)
        lb = boxes[learners]
        overlap = ((boxes[:, None, :2] < lb[None, :, 2:]) & (lb[None, :, :2] < boxes[:, None, 2:])).all(axis=2)
        involved = ok & ((d[:, learners] < p.d_train_m).any(axis=1) | overlap.any(axis=1))
        involved[learners] = True
        rows = np.flatnonzero(involved)
        boxes_by_id = {int(ids[k]): boxes[k] for k in rows}
        positions = {int(ids[k]): pos[k] for k in rows}
        train_ids = [int(ids[k]) for k in learners]
        # a target's first classifier is fitted at once (B15's cadence would wait 5 frames: often too late, the
        # targets are merged by then)
        first = any(not self.bank.is_trained(tid) for tid in train_ids)
        updated = self.bank.train(img.pixels, boxes_by_id, train_ids=train_ids, positions_m=positions,
                                  force_update=first)
        for tid in train_ids:
            self._learnt_t[tid] = t_ns
        self._used.update(train_ids)
        self.stats.train_frames += 1
        self.stats.train_updates += len(updated)
        self.stats.camera_s += time.perf_counter() - t0

    # ---------------------------------------------------------------------------------------------
    def _score_map_ll(self, t_ns: int, track_ids: np.ndarray, centres_m: np.ndarray) -> np.ndarray | None:
        """B16 hook: ``β · log p(z | x)`` ``(n, n_p)`` of correlated targets' particles from their score maps.

        ``centres_m`` ``(n, n_p, 2)``: the particles' feet midpoints. Targets without a trained classifier,
        or already scored on this image, get 0.
        """
        t_img = self.frames.nearest_time(t_ns)
        if t_img is None:
            return None
        ids = [int(i) for i in track_ids]
        todo = [k for k, tid in enumerate(ids) if self.bank.is_trained(tid) and self._scored.get(tid) != t_img]
        if not todo:
            return None
        t0 = time.perf_counter()
        img = self._image(t_ns)
        if img is None:
            return None
        n, n_p = centres_m.shape[:2]
        mean = centres_m.mean(axis=1)
        boxes = self._boxes(mean)
        ok = np.isfinite(boxes).all(axis=1)
        out = np.zeros((n, n_p))
        groups = _components(mean, self.params.group_m)
        beta = self.params.score_beta
        done = False
        for g in np.unique(groups[todo]):
            members = [k for k in np.flatnonzero(groups == g) if ok[k]]
            scored = [k for k in members if k in todo]
            if not scored:
                continue
            try:
                sm = self.bank.score_map(img.pixels, [ids[k] for k in scored], boxes_px=boxes[members])
            except ValueError:  # the region is off the image
                continue
            self.stats.score_maps += 1
            px = self._box_centres(centres_m[scored].reshape(-1, 2)).reshape(len(scored), n_p, 2)
            finite = np.isfinite(px).all(axis=(1, 2))
            like = sm.likelihood(np.where(np.isfinite(px), px, 0.0))  # (len(scored), n_p)
            ll = np.log(like)
            ll -= ll.max(axis=1, keepdims=True)
            for row, k in enumerate(scored):
                if finite[row]:
                    out[k] = beta * ll[row]
                    self._scored[ids[k]] = t_img
                    self._used.add(ids[k])
                    done = True
        self.stats.camera_s += time.perf_counter() - t0
        return out if done else None

    def _split_scores(self, t_ns: int, member_ids: tuple[int, ...], centres_m: np.ndarray) -> np.ndarray | None:
        """B17 hook: mean confidence ``(n_d, m)`` of each member's classifier over each piece's box, or None
        (motion decides) without an image, an untrained member, an invisible piece or too small a margin."""
        if not all(self.bank.is_trained(tid) for tid in member_ids):
            return None
        if self.frames.nearest_time(t_ns) is None:
            return None
        t0 = time.perf_counter()
        img = self._image(t_ns)
        if img is None:
            return None
        boxes = self._boxes(centres_m)
        scores = None
        if np.isfinite(boxes).all():
            s = self.bank.box_scores(img.pixels, boxes, member_ids)
            if np.isfinite(s).all():
                scores = s
                if s.shape == (2, 2) and abs((s[0, 0] + s[1, 1]) - (s[0, 1] + s[1, 0])) < self.params.split_margin:
                    scores = None
        if scores is not None:
            self._used.update(member_ids)
        self.stats.camera_s += time.perf_counter() - t0
        return scores


# --------------------------------------------------------------------------------------------------
# A whole recording
# --------------------------------------------------------------------------------------------------


def _image_topic(rec: Any, camera_topic: str | None) -> str:
    topics = rec.topics()
    if camera_topic is not None:
        if camera_topic not in topics:
            raise RecordingError(f"{rec.paths[0]}: no topic {camera_topic!r}")
        return camera_topic
    found = [t for t, i in topics.items() if i.msgtype in ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
             and not t.endswith(("/labels", "/depth")) and "depth" not in t.split("/")[-1]]
    if not found:
        raise RecordingError(f"{rec.paths[0]}: no image topic for the people pipeline (laser + camera)")
    if len(found) > 1:
        raise ConfigError(f"{rec.paths[0]}: several image topics ({', '.join(found)}); choose one with camera_topic")
    return found[0]


def track_fused(path: str | Path | Sequence[str | Path], *, params: FusionParams | None = None,
                tracker_params: TrackerParams | Mapping[str, Any] | None = None,
                camera_topic: str | None = None, camera: PinholeCamera | None = None,
                progress: Callable[[float], None] | None = None, topics: Iterable[str] | None = None,
                time_source: str = "header", area_m: Any = "auto",
                clock_corrections_ns: Mapping[str, int] | None = None,
                detector_params: Mapping[str, Any] | None = None, rng: np.random.Generator | int | None = 0,
                world_frame: str = "world", timings: dict[str, list[float]] | None = None,
                classify: bool = True, frames_wrapper: Callable[[Any], FrameSource] | None = None,
                ) -> tuple[list[TrackState], list[Event], FusionStats]:
    """Track the people of a recording with its laser scans and one camera (seed 001's fused pipeline).

    Like :func:`~fusiontrack.tracking.tracker.track_recording` (same detector, synchronisation, area and
    classification), with a :class:`FusionTracker` stepped once per scan time.

    Parameters
    ----------
    path : recording path(s)
    params : FusionParams, optional
    tracker_params : TrackerParams or mapping, optional
    camera_topic : str, optional
        The image topic (default: the recording's only one; labels and depth images are not candidates).
    camera : PinholeCamera, optional
        Default: from the recording's CameraInfo and ``/tf_static`` (``<frame>_calibrated`` preferred,
        :func:`~fusiontrack.vision.people.camera_from_recording`).
    progress, topics, time_source, area_m, clock_corrections_ns, detector_params, rng, world_frame, classify
        As for ``track_recording``; ``clock_corrections_ns`` may also name the camera.
    timings : dict, optional
        Filled with per-step ``"detect_s"`` and ``"track_s"`` (laser tracker + camera side + classification).
    frames_wrapper : callable, optional
        Wraps the camera's :class:`~fusiontrack.fusion.frames.LazyFrames` (e.g. to simulate a blackout).

    Returns
    -------
    states : list of TrackState
    events : list of Event
    stats : FusionStats

    Raises
    ------
    RecordingError
        No laser or image topic, or no calibrated camera.
    """
    from ..io.recording import LASERSCAN, Recording
    from ..io.sync import synchronize
    from ..laser.detector import detector_for_recording
    from ..vision.people import camera_from_recording
    from .frames import LazyFrames

    corrections = dict(clock_corrections_ns or {})
    with Recording(path) as rec, Recording(path) as cam_rec:
        info = rec.topics()
        lasers = [t for t, i in info.items() if i.msgtype == LASERSCAN] if topics is None else list(topics)
        if not lasers:
            raise RecordingError(f"{path}: no sensor_msgs/LaserScan topic to track")
        image_topic = _image_topic(rec, camera_topic)
        cam_sensor = rec.sensor_of(image_topic)
        if camera is None:
            first = next((m for m in rec.messages([image_topic]) if isinstance(m, Image)), None)
            if first is None:
                raise RecordingError(f"{path}: image topic {image_topic} holds no readable image")
            camera = camera_from_recording(rec, cam_sensor, first.frame_id, world_frame=world_frame)
            if camera is None:
                raise RecordingError(f"{path}: no CameraInfo or no /tf_static pose for camera {cam_sensor!r}: the "
                                     "people pipeline needs a calibrated camera (use people-laser without one)")
        p = params or FusionParams()
        frames: Any = LazyFrames(cam_rec, image_topic, round(p.max_frame_dt_s * 1e9), corrections.get(cam_sensor, 0))
        if frames_wrapper is not None:
            frames = frames_wrapper(frames)
        total = sum(info[t].count for t in lasers if t in info)
        detector, poses = detector_for_recording(rec, lasers, time_source=time_source, world_frame=world_frame,
                                                 background="learn", detector_params=detector_params)
        auto_area = isinstance(area_m, str)
        if auto_area and area_m != "auto":
            raise ConfigError(f"area_m: expected 'auto', None, a rectangle or a polygon, got {area_m!r}")
        trk = FusionTracker(camera, frames, p, tracker_params, area_m=None if auto_area else area_m, rng=rng,
                            camera_name=cam_sensor)
        stream = synchronize(rec.messages(lasers, time_source=time_source),
                             clock_corrections_ns={k: v for k, v in corrections.items() if k != cam_sensor})
        states, events = run_tracker(trk, detector, poses, stream, total=total, auto_area=auto_area,
                                     classify=classify, progress=progress, timings=timings)
    return states, events, trk.stats
