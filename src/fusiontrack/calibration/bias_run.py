"""Run seed 000's adaptive horizontal bias over a recording (ALGORITHMS.md A0 data flow, A10).

Camera frames go through foreground (A1–A3), blobs (A4) and the blob tracker (A5); every laser scan feeds
the A7 background; each frame's tracked objects update :class:`~fusiontrack.calibration.bias.
HorizontalBiasEstimator`. Images are held back until every laser has a scan at least as late, so each frame
is paired with the nearest scan on either side.

The A7 backgrounds need ``bg_n_init`` scans (2 s at 25 Hz) before any beam is foreground, so learnt online no
frame of a recording's first seconds can update the bias. By default (``background="prime"``) they are first
learnt from the recording's first scans, read ahead (:meth:`~fusiontrack.calibration.bias.
HorizontalBiasEstimator.prime`, :meth:`BiasInputs.prime`); ``"learn"`` learns online only, as live.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable, Generator, Iterator, Mapping, Sequence
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np

from fusiontrack.errors import ConfigError, RecordingError
from fusiontrack.geometry import PinholeCamera, TransformTree, invert_transform
from fusiontrack.io.recording import Recording
from fusiontrack.io.sync import with_time
from fusiontrack.types import CameraInfo, GroundTruth, Image, LaserScan
from fusiontrack.vision.blob_tracker import BlobTracker, BlobTrackerParams
from fusiontrack.vision.blobs import BlobParams, Blobs, blob_histograms, extract_blobs
from fusiontrack.vision.foreground import ForegroundModel, ForegroundParams
from fusiontrack.vision.people import camera_from_recording

from .bias import BiasHistory, BiasParams, BiasStep, HorizontalBiasEstimator

__all__ = [
    "VISION_WIDTH_PX",
    "BiasInputs",
    "BiasRun",
    "FrameObjects",
    "bias_from_recording",
    "bias_settled",
    "check_background",
    "object_centroids",
    "open_bias_inputs",
    "shrink_image",
    "vision_factor",
    "write_bias_history",
]

log = logging.getLogger(__name__)

BoxSource = Literal["blobs", "truth"]
Background = Literal["prime", "learn"]
PIXEL_EDGE_OFFSET_PX = 0.5
"""Blob boxes (ALGORITHMS.md A4) are on pixel edges, pixel ``k`` covering ``[k, k + 1)``; in the camera model's
(OpenCV's) coordinates pixel ``k`` is centred on ``k``, so a blob box is moved by -0.5 px before use."""
VISION_WIDTH_PX = 320
"""A reduced width for the bias's vision path (A1–A5), ``vision_width_px`` of :func:`open_bias_inputs`: wider
images are shrunk by the integer factor :func:`vision_factor` (640 x 480 -> 320 x 240, seed 000's own
resolution, the one A4/A5's pixel parameters are set for). The bias needs only each person's horizontal extent
and centroid; at 320 x 240 the foreground, blobs and tracker cost about half as much per frame, and the
residuals of simulated walkers grow a little (median |e| 0.05-0.09 -> 0.05-0.11 degree over six 30 s
``crowd`` runs). The fused pipeline's bias pass uses it (:func:`~fusiontrack.fusion.learn_camera_bias`);
:func:`open_bias_inputs` and :func:`bias_from_recording` work at full resolution unless asked."""


def check_background(background: object) -> Background:
    """``background`` if it is ``"prime"`` or ``"learn"``.

    Raises
    ------
    ConfigError
        Anything else.
    """
    if background not in ("prime", "learn"):
        raise ConfigError(f"background: expected 'prime' or 'learn', got {background!r}")
    return background  # type: ignore[return-value]


@dataclass(frozen=True, slots=True, eq=False)
class BiasRun:
    """The result of :func:`bias_from_recording`.

    Attributes
    ----------
    history : BiasHistory
        The bias after every camera frame.
    steps : tuple of BiasStep
        Every frame's update and fused objects.
    camera : PinholeCamera
        The camera as calibrated in the recording (what the bias corrects).
    corrected_camera : PinholeCamera
        ``camera`` turned by the final bias.
    lasers : tuple of str
        The lasers used.
    """

    history: BiasHistory
    steps: tuple[BiasStep, ...]
    camera: PinholeCamera
    corrected_camera: PinholeCamera
    lasers: tuple[str, ...]

    @property
    def bias_rad(self) -> float:
        """The final bias."""
        return float(self.history.bias_rad[-1]) if len(self.history) else 0.0


def _camera_info(rec: Recording, camera: str) -> CameraInfo | None:
    infos = rec.camera_info_topics(camera)
    return next((m for m in rec.messages(infos[:1]) if isinstance(m, CameraInfo)), None) if infos else None


def _setup(rec: Recording, camera: str, lasers: Sequence[str] | None, world_frame: str, cam2world: Any,
           laser2world: Mapping[str, Any] | None, image_topic: str | None = None,
           ) -> tuple[PinholeCamera, str, dict[str, np.ndarray], dict[str, str]]:
    topics = rec.topic_types()
    image_topic = rec.image_topic(camera=camera, topic=image_topic, option="image_topic")
    if cam2world is None:
        cam = camera_from_recording(rec, camera, camera, world_frame=world_frame)
    else:
        info = _camera_info(rec, camera)
        cam = None if info is None else PinholeCamera.from_camera_info(info, invert_transform(cam2world))
    if cam is None:
        raise RecordingError(f"{rec.paths[0]}: camera {camera!r} needs a CameraInfo and a pose (given, or in "
                             f"/tf_static as {camera}_calibrated or {camera} relative to {world_frame!r})")
    scan_topics = {rec.sensor_of(t): t for t, m in topics.items() if m == "sensor_msgs/msg/LaserScan"}
    wanted = sorted(scan_topics) if lasers is None else list(lasers)
    missing = [name for name in wanted if name not in scan_topics]
    if missing or not wanted:
        raise RecordingError(f"{rec.paths[0]}: laser(s) {missing or wanted} not found; lasers: {sorted(scan_topics)}")
    given = dict(laser2world or {})
    tree = rec.transform_tree() if any(name not in given for name in wanted) else TransformTree()
    poses = {}
    for name in wanted:
        if name in given:
            poses[name] = np.asarray(given[name], np.float64)
            continue
        frame = f"{name}_calibrated" if tree.has_path(f"{name}_calibrated", world_frame) else name
        if not tree.has_path(frame, world_frame):
            raise RecordingError(f"{rec.paths[0]}: no transform from laser {name!r} to {world_frame!r} in /tf_static")
        poses[name] = tree.get(frame, world_frame)
    return cam, image_topic, poses, {name: scan_topics[name] for name in wanted}


@dataclass(frozen=True, slots=True, eq=False)
class FrameObjects:
    """The tracked objects of one camera frame, ready for :meth:`HorizontalBiasEstimator.update`.

    Attributes
    ----------
    t_ns : int
        Frame time on the common clock.
    boxes_px : (n, 4) float64
        Boxes in the camera model's pixel coordinates (pixel centres on integers).
    object_ids : (n,) int64
    usable : (n,) bool
        Alone (not in a group) and seen in this frame.
    centres_px : (n, 2) float64
        Pixel centroid of each object's blobs (NaN: use the box centre).
    """

    t_ns: int
    boxes_px: np.ndarray
    object_ids: np.ndarray
    usable: np.ndarray
    centres_px: np.ndarray

    def update(self, estimator: HorizontalBiasEstimator) -> BiasStep:
        """Feed this frame to ``estimator``."""
        return estimator.update(self.t_ns, self.boxes_px, self.object_ids, self.usable, self.centres_px)


def vision_factor(width_px: int, vision_width_px: int | None) -> int:
    """The integer factor an image ``width_px`` wide is shrunk by for the bias's vision path:
    ``max(1, width_px // vision_width_px)`` (1 when ``vision_width_px`` is None: full resolution)."""
    if vision_width_px is None:
        return 1
    return max(1, int(width_px) // int(vision_width_px))


def shrink_image(image: Image, factor: int) -> Image:
    """``image`` shrunk by an integer ``factor`` (mean of ``factor`` x ``factor`` pixel blocks; a right or bottom
    strip narrower than ``factor`` is dropped); the image itself when ``factor`` is 1.

    Small pixel ``k`` covers full pixels ``factor k .. factor k + factor - 1``, so a box on small pixel edges
    times ``factor`` is on full pixel edges.
    """
    if factor == 1:
        return image
    h, w = image.height // factor * factor, image.width // factor * factor
    if h == 0 or w == 0:
        raise ValueError(f"image: {image.width}x{image.height} px is smaller than the shrink factor {factor}")
    px = cv2.resize(image.pixels[:h, :w], (w // factor, h // factor), interpolation=cv2.INTER_AREA)
    return Image(image.t_ns, image.sensor, image.frame_id, px, image.encoding)


def object_centroids(object_boxes_px: np.ndarray, blobs: Blobs, tol_px: float = 0.5) -> np.ndarray:
    """Area-weighted pixel centroid of the blobs inside each object box (A5 boxes are unions of blob boxes).

    Parameters
    ----------
    object_boxes_px : (n, 4) float
        Object boxes on pixel edges, as the blob tracker gives them.
    blobs : Blobs
        The frame's blobs (A4).
    tol_px : float
        Slack of the "inside" test.

    Returns
    -------
    (n, 2) float64
        ``(u, v)`` with pixel centres on integers; NaN for an object without a blob inside its box.
    """
    ob = np.asarray(object_boxes_px, np.float64).reshape(-1, 4)
    bb = blobs.boxes_px
    inside = np.all(bb[None, :, :2] >= ob[:, None, :2] - tol_px, axis=2) & \
        np.all(bb[None, :, 2:] <= ob[:, None, 2:] + tol_px, axis=2)
    w = inside * blobs.areas_px[None, :].astype(np.float64)
    total = w.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, (w @ blobs.centroids_px) / total, np.nan)


@dataclass(frozen=True, slots=True, eq=False)
class BiasInputs:
    """What the bias needs from a recording: the camera, the laser poses and a time-ordered input stream.

    Iterating yields :class:`~fusiontrack.types.LaserScan` (stamps on the common clock) and
    :class:`FrameObjects`; a frame comes after every laser has a scan at least as late, so the nearest scan on
    either side of it is known. The vision path (A1–A5) runs during the iteration, at full resolution or
    (``vision_width_px``) on images shrunk to about that width (:func:`vision_factor`); iterate once and feed
    several estimators to compare parameters on the same boxes. With ``recording`` (an open
    :class:`~fusiontrack.io.Recording` of ``path``, which the caller closes), the priming and the iteration read
    through it instead of opening the recording again (an open costs rosbags about 0.2 s).
    """

    path: Path
    camera: PinholeCamera
    lasers: dict[str, np.ndarray]
    image_topic: str
    scan_topics: dict[str, str]
    camera_name: str
    boxes: BoxSource
    offsets_ns: dict[str, int]
    foreground: ForegroundParams | None
    blob: BlobParams | None
    tracker: BlobTrackerParams | None
    vision_width_px: int | None = None
    recording: Recording | None = None

    def _open(self) -> AbstractContextManager[Recording]:
        return nullcontext(self.recording) if self.recording is not None else Recording(self.path)

    def estimator(self, params: BiasParams | None = None, *, background: Background = "learn",
                  max_prime_scans: int | None = None) -> HorizontalBiasEstimator:
        """A fresh estimator for this camera and these lasers.

        ``background="prime"`` learns its laser backgrounds first from the recording's first scans
        (:meth:`prime`); ``"learn"`` (default here, so that an estimator fed alongside others by hand behaves as
        a live one) leaves them to be learnt online from the stream.

        Raises
        ------
        ConfigError
            ``background`` is neither.
        """
        est = HorizontalBiasEstimator(self.camera, self.lasers, params)
        if check_background(background) == "prime":
            self.prime(est, max_prime_scans)
        return est

    def scans(self) -> Generator[LaserScan, None, None]:
        """The recording's laser scans alone, in the order and on the clock iterating yields them."""
        with self._open() as rec:
            for msg in rec.messages(list(self.scan_topics.values())):
                if isinstance(msg, LaserScan):
                    t = msg.t_ns - self.offsets_ns.get(msg.sensor, 0)
                    yield msg if t == msg.t_ns else with_time(msg, t)

    def prime(self, est: HorizontalBiasEstimator, max_scans: int | None = None) -> dict[str, int]:
        """Prime ``est``'s laser backgrounds from the recording's first scans
        (:meth:`~fusiontrack.calibration.bias.HorizontalBiasEstimator.prime`); the scans read per laser."""
        scans = self.scans()
        try:
            return est.prime(scans, max_scans)
        finally:
            scans.close()

    def __iter__(self) -> Iterator[LaserScan | FrameObjects]:
        truth_topic = f"/ground_truth/{self.camera_name}"
        with self._open() as rec:
            frame_topic = truth_topic if self.boxes == "truth" else self.image_topic
            if frame_topic not in rec.topic_types():
                raise RecordingError(f"{self.path}: no topic {frame_topic} for boxes={self.boxes!r}")
            fg = ForegroundModel(self.foreground)
            tracker = BlobTracker(self.tracker)
            last_scan = dict.fromkeys(self.scan_topics, -(2**62))
            pending: deque[Image | GroundTruth] = deque()
            cam_offset = self.offsets_ns.get(self.camera_name, 0)

            def frame_time(msg: Image | GroundTruth) -> int:
                return msg.t_ns - cam_offset if isinstance(msg, Image) else msg.t_ns

            def objects(msg: Image | GroundTruth) -> FrameObjects:
                t_ns = frame_time(msg)
                if isinstance(msg, GroundTruth):  # the simulator's boxes in the true image (a reference run)
                    box = np.asarray(msg.attributes.get("box_px", np.zeros((0, 4))), np.float64).reshape(-1, 4)
                    vis = np.asarray(msg.attributes.get("visibility", np.ones(len(box))), np.float64)
                    ok = np.all(np.isfinite(box), axis=1) & (vis > 0.5)
                    ok[ok] &= (box[ok, 2] > box[ok, 0]) & (box[ok, 3] > box[ok, 1])
                    return FrameObjects(t_ns, box[ok], msg.ids[ok], np.ones(int(ok.sum()), bool),
                                        np.full((int(ok.sum()), 2), np.nan))
                f = vision_factor(msg.width, self.vision_width_px)
                small = shrink_image(msg, f)
                bl = extract_blobs(fg.apply(small).mask, self.blob)
                colour = msg.encoding in ("bgr8", "rgb8")
                objs = tracker.step(bl, blob_histograms(small.bgr(), bl) if colour else None, t_ns)
                edge_boxes = np.array([o.box_px for o in objs]).reshape(-1, 4)
                centres = object_centroids(edge_boxes, bl)
                # back to the full image: small pixel k covers full pixels f k .. f k + f - 1 (edges f k .. f k + f)
                return FrameObjects(t_ns, f * edge_boxes - PIXEL_EDGE_OFFSET_PX,
                                    np.array([o.object_id for o in objs], np.int64),
                                    np.array([not o.in_group and o.missed == 0 for o in objs], bool),
                                    f * (centres + PIXEL_EDGE_OFFSET_PX) - PIXEL_EDGE_OFFSET_PX)

            last_frame, skipped = [-(2**62)], [0]

            def in_order(msg: Image | GroundTruth) -> bool:
                # a repeated or out-of-order frame is skipped (the blob tracker's frames must advance): one bad
                # frame must not end the pass
                t = frame_time(msg)
                if t <= last_frame[0]:
                    skipped[0] += 1
                    log.debug("%s: frame at %d ns is not after the previous one (%d ns); skipped", frame_topic, t,
                              last_frame[0])
                    return False
                last_frame[0] = t
                return True

            for msg in rec.messages([frame_topic, *self.scan_topics.values()]):
                if isinstance(msg, LaserScan):
                    t = msg.t_ns - self.offsets_ns.get(msg.sensor, 0)
                    msg = msg if t == msg.t_ns else with_time(msg, t)
                    yield msg
                    last_scan[msg.sensor] = t
                    ready = min(last_scan.values())
                    while pending and frame_time(pending[0]) <= ready:
                        frame = pending.popleft()
                        if in_order(frame):
                            yield objects(frame)
                elif isinstance(msg, Image | GroundTruth):
                    pending.append(msg)
            while pending:
                frame = pending.popleft()
                if in_order(frame):
                    yield objects(frame)
            if skipped[0]:
                log.warning("%s: %d frame(s) not after the previous one skipped", frame_topic, skipped[0])


def open_bias_inputs(path: str | Path, camera: str = "camera_0", lasers: Sequence[str] | None = None, *,
                     boxes: BoxSource = "blobs", clock_offsets_ms: Mapping[str, float] | None = None,
                     world_frame: str = "world", cam2world: Any = None, laser2world: Mapping[str, Any] | None = None,
                     foreground: ForegroundParams | None = None, blob: BlobParams | None = None,
                     tracker: BlobTrackerParams | None = None, image_topic: str | None = None,
                     vision_width_px: int | None = None, recording: Recording | None = None) -> BiasInputs:
    """Read a recording's calibration and prepare its input stream for the bias (see :func:`bias_from_recording`).

    ``cam2world`` (4, 4) and ``laser2world`` (name -> (4, 4)) replace the poses in the recording's ``/tf_static``
    (e.g. those of a pipeline file); ``foreground``, ``blob`` and ``tracker`` are the A1–A5 parameters, at the
    resolution the vision path works at: full resolution (None), or images at least twice ``vision_width_px``
    wide shrunk by :func:`vision_factor` first (e.g. :data:`VISION_WIDTH_PX`; boxes and centroids are given in
    full-image pixels either way). ``image_topic`` is the camera's image topic (``sensor_msgs/Image`` or
    ``CompressedImage``; default: the camera's first one that is not a label or depth image, raw images
    preferred). ``recording``: an open :class:`~fusiontrack.io.Recording` of ``path`` (or of several files, ``path``
    one of them) to read through (setup, priming and iteration; the caller closes it), instead of opening ``path``
    for each.

    Raises
    ------
    RecordingError
        The recording lacks the camera, its calibration, the lasers or their poses.
    """
    if boxes not in ("blobs", "truth"):
        raise ValueError(f"boxes: expected 'blobs' or 'truth', got {boxes!r}")
    if vision_width_px is not None and (isinstance(vision_width_px, bool) or not isinstance(vision_width_px, int)
                                        or vision_width_px < 1):
        raise ValueError(f"vision_width_px: expected None or an integer >= 1, got {vision_width_px!r}")
    offsets = {k: round(float(v) * 1e6) for k, v in (clock_offsets_ms or {}).items()}
    with nullcontext(recording) if recording is not None else Recording(path) as rec:
        cam, image_topic, poses, scan_topics = _setup(rec, camera, lasers, world_frame, cam2world, laser2world,
                                                      image_topic)
    return BiasInputs(Path(path), cam, poses, image_topic, scan_topics, camera, boxes, offsets, foreground, blob,
                      tracker, vision_width_px, recording)


def bias_settled(bias_rad: Sequence[float], target_rad: Sequence[float], window: int, tol_rad: float) -> bool:
    """Whether a bias learnt by A10 has settled over its last ``window`` updates (a stop rule).

    ``bias_rad[i]`` is the bias after update ``i`` and ``target_rad[i]`` that update's target
    ``b* = b + ē`` (A10: ``b <- (1 - rho) b + rho b*``, at a fixed ``rho`` or with the warm start's
    ``max(rho, 1/n)``, ``b`` the bias before it, ``ē`` the update's mean residual: what this frame's people say the
    bias is). Settled when, over the last ``window`` updates, either

    * the biases span at most ``tol_rad``: the bias has stopped moving; or
    * the last bias is within ``tol_rad`` of the targets' mean ``m``, two standard errors of that mean counted
      against it: ``|b - m| + 2 std(b*) / sqrt(window) <= tol_rad``: the bias has caught up with what the
      measurements say while still creeping towards it. (Noise-free, at ``rho = 0.1``, a 3-degree error is
      within 0.1 degree of its end after 33 updates, but its last 20 values span more than 0.1 degree until
      the 50th update: the span test alone waits for that.)

    Parameters
    ----------
    bias_rad, target_rad : sequence of float
        One value per update so far, oldest first (same length).
    window : int
        Updates looked at (>= 1; one update is settled); with fewer, not settled.
    tol_rad : float
        Tolerance (> 0).

    Returns
    -------
    bool
    """
    b = np.asarray(bias_rad, np.float64).reshape(-1)
    t = np.asarray(target_rad, np.float64).reshape(-1)
    if b.shape != t.shape:
        raise ValueError(f"target_rad: expected {b.size} targets (one per bias), got {t.size}")
    if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 1:
        raise ValueError(f"window: expected an integer >= 1, got {window!r}")
    if not (math.isfinite(tol_rad) and tol_rad > 0):
        raise ValueError(f"tol_rad: expected a finite value > 0, got {tol_rad!r}")
    if b.size < window:
        return False
    b, t = b[-window:], t[-window:]
    if not (np.isfinite(b).all() and np.isfinite(t).all()):
        return False
    if np.ptp(b) <= tol_rad:
        return True
    return bool(abs(b[-1] - t.mean()) + 2.0 * t.std(ddof=1) / math.sqrt(window) <= tol_rad)


def bias_from_recording(path: str | Path, camera: str = "camera_0", lasers: Sequence[str] | None = None,
                        params: BiasParams | None = None, *, boxes: BoxSource = "blobs",
                        clock_offsets_ms: Mapping[str, float] | None = None, world_frame: str = "world",
                        cam2world: Any = None, laser2world: Mapping[str, Any] | None = None,
                        progress: Callable[[BiasStep], None] | None = None, image_topic: str | None = None,
                        background: Background = "prime", max_prime_scans: int | None = None) -> BiasRun:
    """Estimate a camera's horizontal bias against the lasers of a recording (seed 000, ALGORITHMS.md A0–A10).

    Parameters
    ----------
    path : str or Path
        A recording with the camera's images (raw or compressed), its ``CameraInfo``, laser scans and
        ``/tf_static`` poses (the camera's believed pose is ``<camera>_calibrated`` when present, as the simulator
        writes it).
    camera : str
        Sensor name of the camera.
    lasers : sequence of str, optional
        Sensor names of the lasers to use (default: all).
    params : BiasParams, optional
    boxes : {"blobs", "truth"}
        Object boxes from the camera path (A1–A5), or from ``/ground_truth/<camera>`` (the simulator's boxes,
        for reference runs that isolate the laser side).
    clock_offsets_ms : mapping of sensor -> float, optional
        How far each sensor's stamps run ahead of the common clock (the pipeline file's ``clock_offset_ms``).
    world_frame : str
    cam2world : (4, 4) float, optional
        The camera's believed pose (default: from the recording).
    laser2world : mapping of laser name -> (4, 4) float, optional
        Laser poses (default: from the recording).
    progress : callable, optional
        Called with every step.
    image_topic : str, optional
        The camera's image topic (default: see :func:`open_bias_inputs`).
    background : {"prime", "learn"}
        ``"prime"`` (default): the laser backgrounds (A7) are first learnt from the recording's first scans, read
        ahead (at most ``max_prime_scans``, default ``4 * bg_n_init`` per laser; a laser with fewer scans by
        then learns online), so the bias can be updated from the first camera frames on
        (:meth:`~fusiontrack.calibration.bias.HorizontalBiasEstimator.prime`). ``"learn"``: online only, as a
        live sensor would: no update during each laser's first ``bg_n_init`` scans.
    max_prime_scans : int, optional

    Returns
    -------
    BiasRun

    Raises
    ------
    RecordingError
        The recording lacks the camera, its calibration, the lasers or their poses.
    ConfigError
        ``background`` is neither ``"prime"`` nor ``"learn"``.
    """
    check_background(background)
    inputs = open_bias_inputs(path, camera, lasers, boxes=boxes, clock_offsets_ms=clock_offsets_ms,
                              world_frame=world_frame, cam2world=cam2world, laser2world=laser2world,
                              image_topic=image_topic)
    est = inputs.estimator(params, background=background, max_prime_scans=max_prime_scans)
    steps = []
    for item in inputs:
        if isinstance(item, LaserScan):
            est.observe_scan(item)
            continue
        step = item.update(est)
        steps.append(step)
        if progress is not None:
            progress(step)
    if not any(s.n_used for s in steps):
        log.warning("%s: the bias was never updated (no object matched a laser cluster)", path)
    return BiasRun(est.history, tuple(steps), est.camera, est.corrected_camera, est.lasers)


def write_bias_history(path: str | Path, history: BiasHistory) -> Path:
    """Write the bias history as CSV: ``t_ns, bias_deg, n_used, margin_deg``, one row per camera frame.

    Raises
    ------
    RecordingError
        The file cannot be written.
    """
    path = Path(path)
    rows = np.column_stack([np.degrees(history.bias_rad), history.n_used, np.degrees(history.margin_rad)])
    lines = ["t_ns,bias_deg,n_used,margin_deg"] + [f"{t},{b:.6f},{int(n)},{m:.4f}"
                                                  for t, (b, n, m) in zip(history.t_ns.tolist(), rows, strict=True)]
    try:
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    except OSError as err:
        raise RecordingError(f"{path}: cannot write the bias history: {err.strerror}") from err
    return path
