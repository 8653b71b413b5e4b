"""Inputs of the ``wearable`` pipeline (seed 002): phones, cameras and RGB-D detections read from a recording.

One pass over a recording (:func:`read_inputs`) gathers

* every phone IMU stream (``sensor_msgs/Imu`` topics; the phone's sensor name is the person's identity),
  dead-reckoned by :func:`fusiontrack.inertial.run_pdr` (ALGORITHMS.md C1-C5) into a :class:`PhoneTrack`:
  the trajectory on a uniform grid, the distance walked along it, and where the phone was silent (gaps, or
  the end of its stream when it stops reporting);
* every camera's intrinsics (first ``CameraInfo``) and pose (``/tf_static``: the believed calibration
  ``world -> <camera>_calibrated`` when the recording has one, else ``world -> <camera>``);
* people found in every depth frame (:func:`fusiontrack.vision.rgbd.detect_people_rgbd`) and placed on the
  floor (C7: cluster centroid at its median depth, accepted at 0.8-4.0 m from the camera).

Images are not read here: the visual pass (:mod:`fusiontrack.fusion.wearable_visual`) streams them.
"""

from __future__ import annotations

import logging
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..geometry import TransformTree
from ..inertial import PdrResult, run_pdr
from ..inertial.pdr_io import drop_unusable_imu, imu_time_order
from ..inertial.step_length import StepLengthModel
from ..io.recording import Recording
from ..types import CameraInfo, DepthImage, ImuSample, Transform
from ..vision.rgbd import detect_people_rgbd

__all__ = ["CameraModel", "Detections", "Inputs", "PhoneTrack", "dead_reckon_phone", "read_inputs"]

log = logging.getLogger(__name__)

IMU_MSGTYPE = "sensor_msgs/msg/Imu"
GRID_HZ = 50.0  # trajectory grid of a phone: 2.6 cm apart at 1.3 m/s, interpolated linearly in between


@dataclass(frozen=True, slots=True, eq=False)
class CameraModel:
    """A calibrated camera of the recording.

    Attributes
    ----------
    name : str
    info : CameraInfo
    cam2world : (4, 4) float64
        Pose of the optical frame in the world.
    has_depth : bool
        The recording has a ``/<name>/depth`` topic (an RGB-D camera).
    has_image : bool
    pose_frame : str
        The tf frame the pose came from (``<name>_calibrated`` when present).
    """

    name: str
    info: CameraInfo
    cam2world: np.ndarray
    has_depth: bool
    has_image: bool
    pose_frame: str


@dataclass(frozen=True, slots=True, eq=False)
class Detections:
    """People found in the depth frames, time-ordered.

    Attributes
    ----------
    t_ns : (n,) int64
    camera : (n,) int64
        Index into the camera names of :class:`Inputs`.
    xy_m : (n, 2) float64
        C7 floor position in the world.
    box_px : (n, 4) float64
    depth_m : (n,) float64
    """

    t_ns: np.ndarray
    camera: np.ndarray
    xy_m: np.ndarray
    box_px: np.ndarray
    depth_m: np.ndarray

    def __len__(self) -> int:
        return int(self.t_ns.size)


@dataclass(frozen=True, slots=True, eq=False)
class PhoneTrack:
    """One phone's dead reckoning on a uniform grid (ALGORITHMS.md C5: linear between steps).

    Attributes
    ----------
    name : str
        The phone's sensor name: the identity of the person carrying it.
    t_ns : (m,) int64
        Grid over the phone's samples (``GRID_HZ``); empty when the stream is unusable.
    xy_m : (m, 2) float64
        Dead-reckoned position in the phone's own frame (start ``start_m``, heading ``heading0_rad``).
    path_m : (m,) float64
        Distance walked since the first sample (along the dead-reckoned path).
    reporting : (m,) bool
        Samples around the grid time (not in a gap longer than ``gap_s``).
    gaps_ns : (k, 2) int64
        Silent intervals ``(last sample before, first sample after)``; the stream's end is not a gap.
    pdr : PdrResult or None
    error : str
        Why there is no dead reckoning (empty when there is).
    n_samples : int
    """

    name: str
    t_ns: np.ndarray
    xy_m: np.ndarray
    path_m: np.ndarray
    reporting: np.ndarray
    gaps_ns: np.ndarray
    pdr: PdrResult | None
    error: str
    n_samples: int

    @property
    def ok(self) -> bool:
        return self.pdr is not None and self.t_ns.size > 1

    @property
    def span_ns(self) -> tuple[int, int]:
        return (int(self.t_ns[0]), int(self.t_ns[-1])) if self.t_ns.size else (0, -1)

    def _interp(self, t_ns: Any, values: np.ndarray) -> np.ndarray:
        q = (np.asarray(t_ns, dtype=np.int64) - self.t_ns[0]) * 1e-9
        x = (self.t_ns - self.t_ns[0]) * 1e-9
        return np.interp(q, x, values)

    def position_at(self, t_ns: Any) -> np.ndarray:
        """Dead-reckoned positions ``(n, 2)`` at times ``(n,)``; NaN outside the phone's span."""
        t = np.atleast_1d(np.asarray(t_ns, dtype=np.int64))
        out = np.full((t.size, 2), np.nan)
        if not self.ok:
            return out
        inside = (t >= self.t_ns[0]) & (t <= self.t_ns[-1])
        out[inside] = np.column_stack([self._interp(t[inside], self.xy_m[:, k]) for k in range(2)])
        return out

    def path_at(self, t_ns: Any) -> np.ndarray:
        """Distance walked ``(n,)`` m at times ``(n,)``, clamped to the span."""
        t = np.atleast_1d(np.asarray(t_ns, dtype=np.int64))
        return self._interp(t, self.path_m) if self.ok else np.full(t.size, np.nan)

    def silent_s(self, t0_ns: Any, t1_ns: Any) -> np.ndarray:
        """Seconds of gaps between times ``t0_ns`` and ``t1_ns`` (broadcast, either order): walking the phone missed."""
        a, b = np.asarray(t0_ns, dtype=np.int64), np.asarray(t1_ns, dtype=np.int64)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        out = np.zeros(np.broadcast(lo, hi).shape)
        for g0, g1 in self.gaps_ns:
            out += np.clip(np.minimum(g1, hi) - np.maximum(g0, lo), 0, None) * 1e-9
        return out

    def reporting_at(self, t_ns: Any, gap_s: float = 0.25) -> np.ndarray:
        """Whether the phone has samples around each time ``(n,)`` (inside its span, not in a gap)."""
        t = np.atleast_1d(np.asarray(t_ns, dtype=np.int64))
        if not self.ok:
            return np.zeros(t.size, bool)
        out = (t >= self.t_ns[0] - round(gap_s * 1e9)) & (t <= self.t_ns[-1] + round(gap_s * 1e9))
        for a, b in self.gaps_ns:
            out &= ~((t > a) & (t < b))
        return out


@dataclass(frozen=True, slots=True, eq=False)
class Inputs:
    """Everything :func:`read_inputs` gathers from a recording."""

    path: Path
    cameras: dict[str, CameraModel]
    camera_names: tuple[str, ...]
    detections: Detections
    phones: dict[str, PhoneTrack]
    start_ns: int
    end_ns: int
    depth_frames: dict[str, int]
    empty_depth_frames: dict[str, int]


def dead_reckon_phone(name: str, t_ns: np.ndarray, accel: np.ndarray, gyro: np.ndarray, *,
                      step_model: StepLengthModel | None = None, start_m: Any = (0.0, 0.0),
                      heading0_rad: float = 0.0, gap_s: float = 0.25) -> PhoneTrack:
    """Run C1-C5 on one phone's samples and put the trajectory on a uniform grid.

    Samples are put in time order (:func:`~fusiontrack.inertial.pdr_io.imu_time_order`: given in log order, a message
    stamped ahead of or behind its neighbours is dropped with a warning); repeated stamps are kept (the resampler
    averages them). Gaps longer than
    ``gap_s`` are recorded: the preprocessing bridges them linearly, so no step is counted in a gap and the
    heading carries on with the interpolated gyro. Messages with a non-finite acceleration (or gyroscope) are
    dropped first (:func:`~fusiontrack.inertial.pdr_io.drop_unusable_imu`). An unusable stream (fewer than 2
    samples, too short for the step filter) gives a track without dead reckoning and the reason in ``error``.
    """
    t = np.asarray(t_ns, dtype=np.int64)
    order = imu_time_order(f"phone {name}", t)  # (a message stamped ahead or back costs itself, with a warning)
    t, accel, gyro = t[order], np.asarray(accel, np.float64)[order], np.asarray(gyro, np.float64)[order]
    if t.size:  # a NaN message costs itself, not the phone's dead reckoning
        t, accel, gyro = drop_unusable_imu(f"phone {name}", t, accel, gyro)
    empty = np.zeros(0, np.int64)
    if t.size:
        jumps = np.flatnonzero(np.diff(t) > round(gap_s * 1e9))
        gaps = np.column_stack([t[jumps], t[jumps + 1]]).astype(np.int64) if jumps.size else np.zeros((0, 2), np.int64)
    else:
        gaps = np.zeros((0, 2), np.int64)

    def failed(reason: str) -> PhoneTrack:
        log.warning("phone %s: no dead reckoning (%s)", name, reason)
        return PhoneTrack(name, empty, np.zeros((0, 2)), np.zeros(0), np.zeros(0, bool), gaps, None, reason, t.size)

    if t.size < 2:
        return failed(f"{t.size} IMU sample(s)")
    try:
        pdr = run_pdr(t, accel, gyro, step_model=step_model, start_m=start_m, heading0_rad=heading0_rad)
    except ValueError as err:
        return failed(str(err))
    grid = np.arange(int(t[0]), int(t[-1]) + 1, round(1e9 / GRID_HZ), dtype=np.int64)
    xy = pdr.position_at(grid)
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    path = np.concatenate([[0.0], np.cumsum(seg)])
    track = PhoneTrack(name, grid, xy, path, np.ones(grid.size, bool), gaps, pdr, "", t.size)
    reporting = track.reporting_at(grid, gap_s)
    return PhoneTrack(name, grid, xy, path, reporting, gaps, pdr, "", t.size)


def _pose(tree: TransformTree, camera: str) -> tuple[np.ndarray, str] | None:
    for frame in (f"{camera}_calibrated", camera):
        if tree.has_path(frame, "world"):
            return tree.get(frame, "world"), frame
    return None


def read_inputs(path: str | Path, *, phones: tuple[str, ...] | None = None,
                step_model: StepLengthModel | None = None, start_poses: dict[str, Any] | None = None,
                depth_range_m: tuple[float, float] = (0.8, 4.0), gap_s: float = 0.25,
                rng: np.random.Generator | int | None = None) -> Inputs:
    """Read phones, cameras and RGB-D detections from a recording (one pass; images are not decoded).

    Parameters
    ----------
    path : str or Path
        A recording readable by :class:`fusiontrack.io.Recording`.
    phones : tuple of str, optional
        The phones (IMU sensor names) to track; default every IMU topic.
    step_model : StepLengthModel, optional
        C3 model for every phone (the default model when omitted).
    start_poses : mapping phone -> (x_m, y_m, heading_rad), optional
        Known start poses (C5); the others start at the origin of their own frame.
    depth_range_m : (float, float)
        C7's accepted depth of an RGB-D fix.
    gap_s : float
        A phone silent longer than this has a gap.
    rng : numpy Generator, int or None
        For the RGB-D detector's floor RANSAC (unused with calibrated cameras).

    Raises
    ------
    ConfigError
        A requested phone is not in the recording.
    """
    path = Path(path)
    start_poses = dict(start_poses or {})
    rng = np.random.default_rng(rng)
    with Recording(path) as rec:
        topics = rec.topic_types()
        imu_topics = {rec.sensor_of(t): t for t, msgtype in topics.items() if msgtype == IMU_MSGTYPE}
        wanted = tuple(sorted(imu_topics)) if phones is None else tuple(phones)
        missing = [p for p in wanted if p not in imu_topics]
        if missing:
            raise ConfigError(f"phones: {missing} not in {path} (its IMU sensors: {sorted(imu_topics)})")
        unknown = sorted(set(start_poses) - set(wanted))
        if unknown:
            raise ConfigError(f"start_poses: {unknown} are not tracked phones ({list(wanted)})")
        depth_topics = {t.split("/")[1] for t in topics if t.endswith("/depth") and t.count("/") == 2}
        image_topics = {t.split("/")[1] for t in topics if t.endswith("/image") and t.count("/") == 2}
        cam_names = tuple(sorted(depth_topics | image_topics))
        info_topics = [f"/{c}/camera_info" for c in cam_names if f"/{c}/camera_info" in topics]
        tree = TransformTree()
        infos: dict[str, CameraInfo] = {}
        imu: dict[str, list[ImuSample]] = defaultdict(list)
        cam_index = {c: i for i, c in enumerate(cam_names)}
        rows: list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray]] = []
        frames: dict[str, int] = defaultdict(int)
        empty: dict[str, int] = defaultdict(int)
        poses: dict[str, tuple[np.ndarray, str] | None] = {}
        read = (["/tf_static"] if "/tf_static" in topics else []) + info_topics + \
            [imu_topics[p] for p in wanted] + [f"/{c}/depth" for c in sorted(depth_topics)]
        for m in rec.messages(read):
            if isinstance(m, Transform):
                try:
                    tree.add_record(m)
                except ConfigError as err:  # a transform that cannot be used (NaN): left out, with a warning
                    log.warning("%s %s: %s", rec.paths[0], m.sensor, err)
                    continue
                poses.clear()
            elif isinstance(m, CameraInfo):
                infos.setdefault(m.sensor, m)
            elif isinstance(m, ImuSample):
                imu[m.sensor].append(m)
            elif isinstance(m, DepthImage):
                cam = m.sensor if m.sensor in cam_index else next((c for c in cam_names if m.frame_id == c), None)
                if cam is None or cam not in infos:
                    continue
                if cam not in poses:
                    poses[cam] = _pose(tree, cam)
                if poses[cam] is None:
                    continue
                frames[cam] += 1
                d = m.depth_m
                if not np.any(np.isfinite(d) & (d > 0)):
                    empty[cam] += 1
                    continue
                try:
                    det = detect_people_rgbd(d, infos[cam], poses[cam][0], rng=rng)
                except ValueError as err:  # a malformed frame inside a recording degrades, never stops
                    empty[cam] += 1
                    log.debug("%s: depth frame at %d skipped (%s)", cam, m.t_ns, err)
                    continue
                ok = (det.depth_m >= depth_range_m[0]) & (det.depth_m <= depth_range_m[1])
                ok &= np.all(np.isfinite(det.position_world_m[:, :2]), axis=1)
                for i in np.flatnonzero(ok):
                    rows.append((m.t_ns, cam_index[cam], det.position_world_m[i, :2], det.boxes_px[i],
                                 det.depth_m[i]))
        start_ns, end_ns = rec.start_ns, rec.end_ns
    for cam, n in empty.items():
        if n:
            log.warning("%s: %d of %d depth frame(s) without any valid pixel", cam, n, frames[cam])
    cameras = {}
    for c in cam_names:
        pose = _pose(tree, c)
        if c not in infos or pose is None:
            log.warning("camera %s: no %s; not used", c, "CameraInfo" if c not in infos else "pose in /tf_static")
            continue
        cameras[c] = CameraModel(c, infos[c], pose[0], c in depth_topics, c in image_topics, pose[1])
    rows.sort(key=lambda r: r[0])
    det = Detections(np.array([r[0] for r in rows], np.int64), np.array([r[1] for r in rows], np.int64),
                     np.array([r[2] for r in rows], np.float64).reshape(-1, 2),
                     np.array([r[3] for r in rows], np.float64).reshape(-1, 4),
                     np.array([r[4] for r in rows], np.float64))
    tracks = {}
    for p in wanted:
        samples = imu.get(p, [])
        x, y, heading = ((*tuple(start_poses[p]), 0.0))[:3] if p in start_poses else (0.0, 0.0, 0.0)
        tracks[p] = dead_reckon_phone(
            p, np.array([s.t_ns for s in samples], np.int64),
            np.array([s.accel_mps2 for s in samples], np.float64).reshape(-1, 3),
            np.array([s.gyro_radps for s in samples], np.float64).reshape(-1, 3),
            step_model=step_model, start_m=(x, y), heading0_rad=float(heading), gap_s=gap_s)
    return Inputs(path, cameras, cam_names, det, tracks, start_ns, end_ns, dict(frames), dict(empty))
