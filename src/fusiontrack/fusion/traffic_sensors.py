"""The traffic pipeline's per-sensor branches for a recording, posed by the recording or by a road calibration.

Each laser gets its pose (laser2road) and each camera its ground homography either from the recording itself
(``/tf_static`` and ``CameraInfo``: the calibration the recording believes, :mod:`fusiontrack.laser.vehicles`,
:mod:`fusiontrack.vision.vehicles`) or, for the sensors a :class:`~fusiontrack.calibration.road.RoadCalibration`
names (``fusiontrack calibrate-road``: surveyed control points, seed 003 D1), from that calibration.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

from ..calibration.road import RoadCalibration
from ..errors import ConfigError, RecordingError
from ..laser.vehicles import LaserVehicleDetector, laser_poses_for_recording
from ..vision.vehicles import CameraVehicleDetector, VehicleDetectorParams, vehicle_detectors_for_recording
from ..vision.vehicles import _camera_names as camera_names

log = logging.getLogger(__name__)

__all__ = ["traffic_branches"]

_LASER = "sensor_msgs/msg/LaserScan"


def traffic_branches(rec: Any, roads: Any, *, laser_params: Mapping[str, Any] | None = None,
                     camera_params: VehicleDetectorParams | None = None, time_source: str = "header",
                     calibration: RoadCalibration | None = None,
                     ) -> tuple[LaserVehicleDetector | None, list[str], dict[str, tuple[str, CameraVehicleDetector]]]:
    """The laser branch (all lasers in one detector) and one camera branch per camera of an open recording.

    Parameters
    ----------
    rec : Recording
    roads : (n, 5) float
        ``(x0, y0, x1, y1, width)`` in the road frame.
    laser_params : mapping, optional
        Keyword arguments of :class:`~fusiontrack.laser.vehicles.LaserVehicleDetector`, and optionally ``lasers``
        (the laser topics to use), ``world_frame`` and ``calibrated_suffix`` (of
        :func:`~fusiontrack.laser.vehicles.laser_poses_for_recording`).
    camera_params : VehicleDetectorParams, optional
    time_source : str
    calibration : RoadCalibration, optional
        Poses the lasers and cameras it names (the others: the recording's ``/tf_static`` and ``CameraInfo``).

    Returns
    -------
    laser detector (None without LaserScan topics), its laser topics, and camera name -> (image topic, detector)

    Raises
    ------
    ConfigError
        The calibration names a sensor the recording does not have (or has as the other kind).
    """
    topics = rec.topic_types()
    lparams = dict(laser_params or {})
    chosen, pose_args = lparams.pop("lasers", None), {k: lparams.pop(k) for k in ("world_frame", "calibrated_suffix")
                                                     if k in lparams}
    if chosen is not None:
        missing = [t for t in chosen if t not in topics]
        if missing:
            raise ConfigError(f"{rec.paths[0]}: laser topic(s) {missing} not in the recording (topics: "
                              f"{sorted(topics)})")
    laser_topics = {rec.sensor_of(t): t for t, i in topics.items()
                    if i == _LASER and (chosen is None or t in chosen)}
    with_info = camera_names(rec)  # cameras the recording can pose itself (CameraInfo + tf)
    # cameras with colour images but none of those (Recording.image_topics: not labels or depth, one per image_transport
    # stream; another tool's /ns/image_raw is the camera /ns/camera_info's)
    owned = {rec.image_topic(camera=c, required=False) for c in with_info}
    with_images = sorted({rec.sensor_of(t) for t in rec.image_topics() if t not in owned} - set(with_info))
    cameras = sorted(set(with_info) | set(with_images))
    calib = calibration or RoadCalibration()
    for kind, named, have in (("laser", calib.lasers, laser_topics), ("camera", calib.cameras, cameras)):
        unknown = sorted(set(named) - set(have))
        if unknown:
            chosen_note = " chosen by [traffic.laser] lasers" if kind == "laser" and chosen is not None else ""
            raise ConfigError(f"road calibration ({calib.source}): {kind}(s) {unknown} are not among the "
                              f"{kind}s{chosen_note} of {rec.paths[0]} (its lasers: {sorted(laser_topics)}, "
                              f"cameras: {cameras})")

    laser = None
    if laser_topics:
        from_tf = [t for n, t in laser_topics.items() if n not in calib.lasers]
        poses: dict[str, Any] = (laser_poses_for_recording(rec, from_tf, time_source=time_source, **pose_args)
                                 if from_tf else {})
        poses.update({n: calib.laser(n).laser2road for n in laser_topics if n in calib.lasers})
        laser = LaserVehicleDetector(poses, roads, **lparams)
    cams: dict[str, tuple[str, CameraVehicleDetector]] = {}
    unposed = [c for c in cameras if c not in calib.cameras and c not in with_info]
    if unposed:
        log.warning("%s: camera(s) %s have images but no CameraInfo and no road calibration: not used",
                    rec.paths[0], unposed)
    from_info = [c for c in with_info if c not in calib.cameras]
    if from_info:
        try:
            cams.update(vehicle_detectors_for_recording(rec, roads, cameras=from_info, params=camera_params))
        except RecordingError as err:
            if "no camera with a CameraInfo" not in str(err):
                raise
    for name in cameras:
        if name in calib.cameras:
            c = calib.camera(name)
            cams[name] = (rec.image_topic(camera=name), CameraVehicleDetector(name, c.image2road, roads, camera_params,
                                                                        K=c.K, dist=c.dist))
    if calibration is not None:
        log.info("sensors posed by %s: %s; by the recording: %s", calib.source,
                 sorted({*calib.lasers, *calib.cameras}),
                 sorted((set(laser_topics) - set(calib.lasers)) | (set(cameras) - set(calib.cameras))))
    return laser, list(laser_topics.values()), {n: cams[n] for n in sorted(cams)}
