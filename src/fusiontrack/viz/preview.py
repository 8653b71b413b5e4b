"""A preview video of any recording: laser points and ground truth from above, beside the camera image.

Works on simulated recordings (lasers, cameras, ``/ground_truth``, sensor poses in ``tf_static``)
and on real ones (laser only, annotations in the laser frame, no poses: the laser frame is drawn).
One output frame per camera image when there is a camera, else one per laser scan.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..errors import ConfigError, RecordingError
from ..geometry import TransformTree, scan_to_points, transform_points
from ..io.recording import Recording
from ..io.video import check_video_output, write_video
from ..types import GroundTruth, Image, LaserScan, ObjectClass, TrackState, Transform
from .birdseye import BirdseyeView

log = logging.getLogger(__name__)

LASER_COLOURS = [(80, 220, 255), (255, 160, 60), (120, 255, 120), (200, 120, 255)]
TRUTH_COLOUR = (60, 60, 255)


def id_colour(i: int) -> tuple[int, int, int]:
    """A stable, distinct colour per identity (golden-angle hue steps)."""
    hue = int((i * 137.508) % 180)
    bgr = cv2.cvtColor(np.uint8([[[hue, 200, 255]]]), cv2.COLOR_HSV2BGR)[0, 0]
    return int(bgr[0]), int(bgr[1]), int(bgr[2])


@dataclass(frozen=True, slots=True)
class PreviewResult:
    frames: int
    lasers: tuple[str, ...]
    cameras: tuple[str, ...]
    truth: bool
    size_px: tuple[int, int]


def _transform_tree(transforms: Sequence[Transform]) -> TransformTree:
    tree = TransformTree()
    for tf in transforms:
        try:
            tree.add_record(tf)
        except ConfigError:  # a repeated or loop-closing edge: the first one wins
            continue
    return tree


def _to_world(tree: TransformTree, frame: str, points: np.ndarray) -> np.ndarray:
    if frame and "world" in tree.frames and frame in tree.frames and tree.has_path(frame, "world"):
        return transform_points(tree.get(frame, "world"), points)
    return points


def render_preview(
    recording: Sequence[Path] | Path, output: Path, *, max_frames: int | None = None, fps: float | None = None,
    height_px: int = 480, progress: Callable[[int, int], None] | None = None,
    tracks: Sequence[TrackState] | None = None, laser_poses: Mapping[str, Any] | None = None,
) -> PreviewResult:
    """Write a preview video of ``recording`` to ``output`` (``.mp4``, ``.avi``, ``.mkv`` or ``.webm``).

    ``tracks`` (world frame, or the laser frame for a recording without poses) are drawn as filled
    squares with their id and a short trail, on top of the ground truth's open circles. ``laser_poses`` (laser
    sensor or topic -> (4, 4) laser2world) place those scanners instead of ``/tf_static``, as the tracker did.
    """
    check_video_output(output)  # a folder, an unknown suffix or a missing folder: say so before reading anything
    if max_frames is not None and (isinstance(max_frames, bool) or not max_frames >= 1):
        raise ConfigError(f"max_frames: expected a number of frames >= 1, got {max_frames!r}")
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise ConfigError(f"fps: expected a positive frame rate, got {fps!r}")
    paths = [recording] if isinstance(recording, Path | str) else list(recording)
    with Recording(paths) as rec:
        topics = rec.topics()
        laser_topics = [t for t, i in topics.items() if i.msgtype == "sensor_msgs/msg/LaserScan"]
        image_topics = rec.image_topics()
        truth_topics = [t for t, i in topics.items()
                        if i.msgtype in ("fusiontrack_msgs/msg/GroundTruth", "leg_tracker/msg/Person")
                        and t.count("/") <= 1]
        tf_topics = [t for t in topics if t in ("/tf_static", "/tf")]
        if not laser_topics and not image_topics:
            raise RecordingError(f"{', '.join(map(str, paths))}: nothing to preview (no LaserScan or Image topic)")
        tree = _transform_tree(list(rec.messages(tf_topics))) if tf_topics else TransformTree()
        given = {rec.sensor_of(k): np.asarray(v, np.float64) for k, v in (laser_poses or {}).items()}

        def scan_world(scan: LaserScan) -> np.ndarray:
            pose = given.get(scan.sensor)
            pts = scan_to_points(scan)
            return transform_points(pose, pts) if pose is not None else _to_world(tree, scan.frame_id, pts)
        # First pass over the light topics: the extent of the bird's-eye window.
        sample: list[np.ndarray] = []
        for i, msg in enumerate(rec.messages(laser_topics + truth_topics, time_source="log")):
            if isinstance(msg, LaserScan) and i % 5 == 0:
                sample.append(scan_world(msg)[::3])
            elif isinstance(msg, GroundTruth) and len(msg):
                sample.append(_to_world(tree, msg.frame_id, msg.positions_m))
            if i > 20000:
                break
        view = BirdseyeView.fit(np.concatenate(sample) if sample else np.zeros((1, 2)), margin_m=0.5,
                                height_px=height_px)
        background = view.background()
        primary = image_topics[0] if image_topics else laser_topics[0]
        total = topics[primary].count if max_frames is None else min(topics[primary].count, max_frames)
        stream = rec.messages(laser_topics + image_topics + truth_topics, time_source="log")
        if fps is None:  # the recording's rate, within what players show (1-60 frames per second)
            span = topics[primary].duration_s
            fps = (topics[primary].count - 1) / span if span > 0 and topics[primary].count > 1 else 10.0
            fps = min(max(fps, 1.0), 60.0)
        frames = _frames(stream, primary, laser_topics, tree, view, background, height_px, total, progress,
                         {t: rec.sensor_of(t) for t in topics}, _TrackCursor(tracks or []), scan_world)
        n = write_video(output, frames, fps=fps)
    if n == 0:
        raise RecordingError(f"{', '.join(map(str, paths))}: no frame of {primary} to draw")
    return PreviewResult(n, tuple(laser_topics), tuple(image_topics), bool(truth_topics),
                         (view.size_px[0], view.size_px[1]))


class _TrackCursor:
    """The track states to draw at a time: each track's latest state at or before it, with a trail."""

    def __init__(self, states: Sequence[TrackState], trail_s: float = 2.0) -> None:
        self.states = sorted(states, key=lambda s: s.t_ns)
        self.times = np.array([s.t_ns for s in self.states], np.int64)
        self.trail_ns = int(trail_s * 1e9)

    def at(self, t_ns: int) -> list[list[TrackState]]:
        if not self.states:
            return []
        hi = int(np.searchsorted(self.times, t_ns, side="right"))
        lo = int(np.searchsorted(self.times, t_ns - self.trail_ns, side="left"))
        by_id: dict[int, list[TrackState]] = {}
        for s in self.states[lo:hi]:
            by_id.setdefault(s.track_id, []).append(s)
        step = 2 * int(np.median(np.diff(self.times[self.times > 0]))) if len(self.times) > 1 else 0
        return [trail for trail in by_id.values() if t_ns - trail[-1].t_ns <= max(step, 100_000_000)]


def _frames(stream: Iterator, primary: str, laser_topics: list[str], tree: TransformTree, view: BirdseyeView,
            background: np.ndarray, height_px: int, total: int, progress: Callable[[int, int], None] | None,
            sensor_of: dict[str, str], tracks: _TrackCursor,
            scan_world: Callable[[LaserScan], np.ndarray]) -> Iterator[np.ndarray]:
    primary_sensor = sensor_of[primary]
    laser_sensors = [sensor_of[t] for t in laser_topics]
    scans: dict[str, np.ndarray] = {}
    truth: GroundTruth | None = None
    image: Image | None = None
    t_first: int | None = None
    n = 0
    for msg in stream:
        t_first = msg.t_ns if t_first is None else t_first
        if isinstance(msg, LaserScan):
            scans[msg.sensor] = scan_world(msg)
        elif isinstance(msg, GroundTruth):
            truth = msg
        elif isinstance(msg, Image) and msg.encoding != "mono16":
            image = msg
        if msg.sensor != primary_sensor or not isinstance(msg, LaserScan | Image) or \
                (isinstance(msg, Image) and msg.encoding == "mono16"):
            continue
        yield _compose(view, background, scans, laser_sensors, truth, tree, image, height_px,
                       (msg.t_ns - t_first) / 1e9, tracks.at(msg.t_ns))
        n += 1
        if progress is not None:
            progress(n, total)
        if n >= total:
            return


_UNNAMED = (str(ObjectClass.PERSON), str(ObjectClass.UNKNOWN))


def _compose(view: BirdseyeView, background: np.ndarray, scans: dict[str, np.ndarray], lasers: list[str],
             truth: GroundTruth | None, tree: TransformTree, image: Image | None, height_px: int,
             t_s: float, trails: list[list[TrackState]] | None = None) -> np.ndarray:
    img = background.copy()
    for i, name in enumerate(lasers):
        if name in scans:
            view.draw_points(img, scans[name], LASER_COLOURS[i % len(LASER_COLOURS)], radius_px=1)
    if truth is not None and len(truth):
        pos = _to_world(tree, truth.frame_id, truth.positions_m)
        uv = view.to_pixels(pos)
        radius = max(int(0.3 * view.px_per_m), 3)
        feet = truth.attributes.get("feet_m")
        for k in range(len(truth)):
            colour = id_colour(int(truth.ids[k]))
            cv2.circle(img, (int(uv[k, 0]), int(uv[k, 1])), radius, colour, 1, cv2.LINE_AA)
            cv2.putText(img, str(int(truth.ids[k])), (int(uv[k, 0]) + radius, int(uv[k, 1]) - radius),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1, cv2.LINE_AA)
            if feet is not None and np.all(np.isfinite(feet[k])):
                for f in view.to_pixels(_to_world(tree, truth.frame_id, np.asarray(feet[k]).reshape(2, 2))):
                    cv2.circle(img, (int(f[0]), int(f[1])), 2, colour, -1)
    for trail in trails or []:
        colour = id_colour(trail[-1].track_id + 7)
        uv = view.to_pixels(np.array([s.position_m for s in trail]))
        cv2.polylines(img, [uv.astype(np.int32).reshape(-1, 1, 2)], False, colour, 1, cv2.LINE_AA)
        u, v = int(uv[-1, 0]), int(uv[-1, 1])
        cv2.rectangle(img, (u - 4, v - 4), (u + 4, v + 4), colour, -1)
        last = trail[-1]
        kind = "" if last.cls in _UNNAMED else f" {last.cls}"  # people are the rule; vehicles are named
        cv2.putText(img, f"T{last.track_id}{kind}", (u + 6, v + 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1,
                    cv2.LINE_AA)
    view.label(img, f"{t_s:7.2f} s")
    if image is None:
        return img
    cam = image.bgr()
    scale = img.shape[0] / cam.shape[0]
    cam = cv2.resize(np.ascontiguousarray(cam), (round(cam.shape[1] * scale) // 2 * 2, img.shape[0]))
    return np.hstack([img, cam])
