"""What ``fusiontrack calibrate`` does: a camera pose from control points, or from seed 000's adaptive bias,
written into the pipeline file.

* :func:`calibrate_from_points` — control points (a CSV of ``x_m, y_m, z_m, u_px, v_px``, the points in the
  frame of a reference sensor of the pipeline, e.g. a laser, or in the world) and the camera's intrinsics (from
  a recording's ``CameraInfo`` or given) -> PnP (:func:`~fusiontrack.calibration.extrinsics.solve_pnp`) -> the
  camera's pose in the world.
* :func:`calibrate_from_recording` — seed 000's adaptive horizontal bias over a recording (ALGORITHMS.md
  A6–A10) -> the camera's pose turned by the learnt bias.

Both return a :class:`CalibrationReport` and, unless ``write=False``, rewrite the camera's ``pose`` in the
pipeline file, keeping the rest of it (:func:`~fusiontrack.calibration.pipeline_file.write_pose_to_pipeline`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fusiontrack.config import PipelineConfig, Pose, SensorKind, load_config
from fusiontrack.errors import CalibrationError, ConfigError, RecordingError
from fusiontrack.io.csvtable import read_numeric_table
from fusiontrack.io.recording import Recording
from fusiontrack.types import CameraInfo

from .bias import BiasParams
from .bias_run import BiasRun, bias_from_recording
from .extrinsics import PnPResult, cam2world_from_camera_pose, camera_pose_from_cam2world, solve_pnp
from .pipeline_file import write_pose_to_pipeline

__all__ = [
    "CONTROL_POINT_COLUMNS",
    "CalibrationReport",
    "calibrate_from_points",
    "calibrate_from_recording",
    "camera_info_from_recording",
    "read_control_points",
]

log = logging.getLogger(__name__)

CONTROL_POINT_COLUMNS = ("x_m", "y_m", "z_m", "u_px", "v_px")
"""Header of a control-point CSV file: a point in the reference frame (m) and its pixel."""


@dataclass(frozen=True, slots=True, eq=False)
class CalibrationReport:
    """A camera calibration and where it went.

    Attributes
    ----------
    camera : str
    method : str
        ``"points"`` or ``"adaptive-bias"``.
    cam2world : (4, 4) float64
        The new pose of the camera's optical frame.
    pose : Pose
        The same as written in the pipeline file.
    previous : Pose
        The camera's pose in the pipeline file before (``--adaptive`` from a file without one: the pose it
        started from, the recording's).
    pnp : PnPResult or None
        Control-point fit (residuals, inliers, covariance).
    bias : BiasRun or None
        Adaptive-bias run (bias history; the final bias is ``bias.bias_rad``).
    written : Path or None
        The pipeline file, when it was rewritten.
    """

    camera: str
    method: str
    cam2world: np.ndarray
    pose: Pose
    previous: Pose
    pnp: PnPResult | None = None
    bias: BiasRun | None = None
    written: Path | None = None


def read_control_points(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Control points from a CSV file with the header ``x_m, y_m, z_m, u_px, v_px`` (``#`` comments allowed).

    Returns
    -------
    points_m : (n, 3) float64
    pixels_px : (n, 2) float64

    Raises
    ------
    RecordingError
        Missing file, wrong header or columns, a value that is not a number (file and line named).
    """
    table = read_numeric_table(path, n_cols=5, header=True, what="control points x_m, y_m, z_m, u_px, v_px")
    if tuple(table.header or ()) != CONTROL_POINT_COLUMNS:
        raise RecordingError(f"{path}: expected the header {', '.join(CONTROL_POINT_COLUMNS)}, got "
                             f"{', '.join(table.header or [])}")
    return table.values[:, :3].copy(), table.values[:, 3:].copy()


def camera_info_from_recording(path: str | Path, camera: str, info_topic: str = "",
                               image_topic: str = "") -> CameraInfo:
    """The first ``CameraInfo`` of ``camera`` (or on ``info_topic``; else of the sensor ``camera``, else beside its
    ``image_topic`` as ROS names them: :meth:`~fusiontrack.io.recording.Recording.camera_info_topics`) in a
    recording.

    Raises
    ------
    RecordingError
        The recording has none.
    """
    with Recording(path) as rec:
        wanted = [info_topic] if info_topic else (rec.camera_info_topics(camera)
                                                  or (rec.camera_info_topics(image_topic) if image_topic else []))
        info = next((m for m in rec.messages(wanted) if isinstance(m, CameraInfo)), None) if wanted else None
    where = f" on {info_topic}" if info_topic else ""
    if info is None:
        hint = "" if info_topic else " (name its topic with info_topic in the camera's [sensors] table)"
        raise RecordingError(f"{path}: no CameraInfo of camera {camera!r}{where}{hint}")
    K = np.asarray(info.K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        fx, fy = (K[0, 0], K[1, 1]) if K.shape == (3, 3) else (np.nan, np.nan)
        raise RecordingError(f"{path}: the CameraInfo of camera {camera!r}{where} holds no usable intrinsics (fx "
                             f"{fx:g}, fy {fy:g}; an uncalibrated camera?): give the intrinsics (calibrate "
                             "--intrinsics)")
    return info


def _camera_sensor(cfg: PipelineConfig, camera: str, source: str) -> Pose:
    sensor = cfg.sensors.get(camera)
    if sensor is None:
        raise ConfigError(f"{source}: no sensor {camera!r}; sensors: {sorted(cfg.sensors)}")
    if sensor.kind not in (SensorKind.CAMERA, SensorKind.RGBD):
        raise ConfigError(f"{source}: sensor {camera!r} is a {sensor.kind.value}, not a camera")
    return sensor.pose


def _reference2world(cfg: PipelineConfig, reference: str, source: str,
                     recording: str | Path | None = None) -> tuple[np.ndarray, str]:
    """The reference's pose in the world and where it came from: the pipeline file, else (a laser) the recording's
    ``/tf_static`` as the trackers pose it."""
    if reference == "world":
        return np.eye(4), "world"
    sensor = cfg.sensors.get(reference)
    if sensor is None:
        raise ConfigError(f"{source}: reference {reference!r} is neither 'world' nor a sensor; sensors: "
                          f"{sorted(cfg.sensors)}")
    if sensor.has_pose:
        return sensor.pose.matrix(), "the pipeline file"
    # Pose() would silently put it at the origin: a laser without a pose keeps its recording's, as tracking poses it
    if recording is not None and sensor.kind == SensorKind.LASER:
        from fusiontrack.laser.detector import first_scans, recorded_laser_poses

        with Recording(recording) as rec:
            if sensor.topic not in rec.topic_types():
                raise ConfigError(f"{source}: reference {reference!r} has no pose in the pipeline file, and its topic "
                                  f"{sensor.topic} is not in {recording}")
            first = first_scans(rec, [sensor.topic])
            if not first:  # (its frame id, which /tf_static poses, is in its scans)
                raise ConfigError(f"{source}: reference {reference!r} has no pose in the pipeline file, and its topic "
                                  f"{sensor.topic} holds no scan in {recording} to find its frame in /tf_static")
            poses = recorded_laser_poses(rec, first)
        if poses:
            return next(iter(poses.values())), f"{recording}'s /tf_static"
        raise ConfigError(f"{source}: reference {reference!r} has no pose in the pipeline file, nor in {recording}'s "
                          f"/tf_static: give its [sensors.{reference}] a pose, or measure the points in the world "
                          "frame")
    tf_hint = ", or a recording with its /tf_static (--recording)" if sensor.kind == SensorKind.LASER else ""
    raise ConfigError(f"{source}: reference {reference!r} has no pose in the pipeline file: give its "
                      f"[sensors.{reference}] a pose{tf_hint}, or measure the points in the world frame")


def _finish(pipeline: Path, camera: str, method: str, cam2world: np.ndarray, previous: Pose, write: bool,
            comment: str, **extra: Any) -> CalibrationReport:
    pose = camera_pose_from_cam2world(cam2world)
    written = None
    if write:
        write_pose_to_pipeline(pipeline, camera, pose, comment=comment)
        written = pipeline
    return CalibrationReport(camera, method, cam2world, pose, previous, written=written, **extra)


def calibrate_from_points(pipeline: str | Path, camera: str, points: str | Path, *, reference: str = "world",
                          intrinsics: CameraInfo | tuple[Any, Any] | None = None,
                          recording: str | Path | None = None, ransac: bool = False,
                          ransac_threshold_px: float = 5.0, write: bool = True) -> CalibrationReport:
    """A camera's pose from control points (ALGORITHMS.md B11 with OpenCV's PnP), written into the pipeline file.

    Parameters
    ----------
    pipeline : str or Path
        The pipeline file; it must list ``camera`` (and ``reference`` unless it is ``"world"``).
    camera : str
        The camera's sensor name.
    points : str or Path
        Control-point CSV (:func:`read_control_points`), points in the frame of ``reference``.
    reference : str
        ``"world"`` or the sensor (e.g. a laser) in whose frame the points were measured; its pipeline pose
        takes them to the world.
    intrinsics : CameraInfo or (K (3, 3), dist), optional
        The camera's intrinsics; else read from ``recording``.
    recording : str or Path, optional
        A recording with the camera's ``CameraInfo`` (the sensor's ``info_topic`` if set), read when ``intrinsics``
        is not given; and whose ``/tf_static`` poses a ``reference`` laser the pipeline file gives no pose.
    ransac, ransac_threshold_px : bool, float
        Reject mis-clicked points (X6: 5 px).
    write : bool
        Rewrite the pipeline file (False: only report).

    Returns
    -------
    CalibrationReport

    Raises
    ------
    ConfigError, RecordingError, CalibrationError
        Bad pipeline file, sensor names, CSV or recording; too few or degenerate points.
    """
    pipeline = Path(pipeline)
    cfg = load_config(pipeline)
    previous = _camera_sensor(cfg, camera, str(pipeline))
    ref2world, posed_by = _reference2world(cfg, reference, str(pipeline), recording)
    if intrinsics is None:
        if recording is None:
            raise ConfigError("intrinsics: give the camera's intrinsics or a recording with its CameraInfo")
        sensor = cfg.sensors[camera]
        # the camera's CameraInfo: on its info_topic, else beside its image topic as ROS names them (by the pipeline
        # file's sensor name alone, only a fusiontrack recording's sensor map found it)
        intrinsics = camera_info_from_recording(recording, camera, sensor.info_topic, image_topic=sensor.topic)
    K, dist = (intrinsics.K, intrinsics.D) if isinstance(intrinsics, CameraInfo) else intrinsics
    pts, pix = read_control_points(points)
    result = solve_pnp(pts, pix, K, dist, ransac=ransac, ransac_threshold_px=ransac_threshold_px)
    if result.rms_px > ransac_threshold_px:
        log.warning("%s: reprojection RMS %.1f px is large: check the control points", points, result.rms_px)
    cam2world = result.cam2world(ref2world)
    comment = (f"fusiontrack calibrate: {int(result.inliers.sum())}/{len(pts)} control points in {reference}"
               f"{f' (posed by {posed_by})' if posed_by not in ('world', 'the pipeline file') else ''}, "
               f"rms {result.rms_px:.2f} px")
    return _finish(pipeline, camera, "points", cam2world, previous, write, comment, pnp=result)


def calibrate_from_recording(pipeline: str | Path, camera: str, recording: str | Path, *,
                             lasers: Sequence[str] | None = None, params: BiasParams | None = None,
                             poses_from: str = "pipeline", write: bool = True) -> CalibrationReport:
    """A camera's yaw corrected by seed 000's adaptive horizontal bias over a recording (ALGORITHMS.md A6–A10).

    Parameters
    ----------
    pipeline : str or Path
        The pipeline file listing the camera and the lasers (their poses and clock offsets are used).
    camera : str
    recording : str or Path
        A recording with the camera's images and ``CameraInfo`` and the lasers' scans, with people walking.
    lasers : sequence of str, optional
        Lasers to use, by their names in the pipeline file (default: every laser of the pipeline file; each must be
        in the recording, found by its topic).
    params : BiasParams, optional
    poses_from : {"pipeline", "recording"}
        Start from the poses in the pipeline file (a sensor whose table gives no ``pose``: its pose in the
        recording's ``/tf_static``, as the pipelines do), or from the recording's ``/tf_static`` for all.
    write : bool
        Rewrite the camera's pose in the pipeline file.

    Returns
    -------
    CalibrationReport

    Raises
    ------
    ConfigError, RecordingError, CalibrationError
        Bad pipeline file or recording, or the bias could never be updated.
    """
    if poses_from not in ("pipeline", "recording"):
        raise ValueError(f"poses_from: expected 'pipeline' or 'recording', got {poses_from!r}")
    pipeline = Path(pipeline)
    cfg = load_config(pipeline)
    previous = _camera_sensor(cfg, camera, str(pipeline))
    laser_names = [n for n, s in cfg.sensors.items() if s.kind == SensorKind.LASER]
    wanted = list(lasers) if lasers is not None else laser_names or None
    cam2world = laser2world = None
    if poses_from == "pipeline":  # the poses the file gives; the others from /tf_static (not the origin)
        if cfg.sensors[camera].has_pose:
            cam2world = cam2world_from_camera_pose(previous)
        laser2world = {n: cfg.sensors[n].pose.matrix() for n in (wanted or [])
                       if n in cfg.sensors and cfg.sensors[n].has_pose}
    offsets = {n: s.clock_offset_ms for n, s in cfg.sensors.items() if s.clock_offset_ms}
    # the file's sensors are found in the recording by their topics, as the pipelines find them: the names the
    # recording gives those topics may be others (a file naming its scanners front / back)
    from ..io.recording import Recording

    with Recording(recording) as rec:
        name = {n: rec.sensor_of(s.topic) for n, s in cfg.sensors.items()}
        have = set(rec.topic_types())
    for n in [camera, *(wanted or [])]:
        if n in cfg.sensors and cfg.sensors[n].topic not in have:
            raise RecordingError(f"{recording}: {pipeline}'s [sensors.{n}] topic {cfg.sensors[n].topic!r} is not in "
                                 f"the recording; it has: {', '.join(sorted(have))}")
    run = bias_from_recording(recording, name.get(camera, camera), [name.get(n, n) for n in wanted or []] or None,
                              params, clock_offsets_ms={name.get(n, n): v for n, v in offsets.items()},
                              cam2world=cam2world,
                              laser2world=None if laser2world is None else {name.get(n, n): m
                                                                            for n, m in laser2world.items()},
                              image_topic=cfg.sensors[camera].topic)
    if not np.any(run.history.n_used):
        raise CalibrationError(f"{recording}: no camera object was ever matched to a laser cluster; the bias is "
                               "unknown (are people walking in view of both sensors?)")
    comment = (f"fusiontrack calibrate --adaptive: yaw corrected by {math.degrees(run.bias_rad):+.3f} deg over "
               f"{int(np.count_nonzero(run.history.n_used))} frames")
    if not cfg.sensors[camera].has_pose:  # the file had none: the pose it started from, the recording's
        previous = camera_pose_from_cam2world(run.camera.cam2world)
    return _finish(pipeline, camera, "adaptive-bias", run.corrected_camera.cam2world, previous, write, comment,
                   bias=run)
