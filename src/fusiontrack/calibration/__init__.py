"""Calibration: camera extrinsics from control points (ALGORITHMS.md B11, X6) and seed 000's adaptive horizontal
bias between a camera and lasers (A0, A6–A12).

* :mod:`~fusiontrack.calibration.extrinsics` — :func:`solve_pnp` (OpenCV PnP, RANSAC, LM refinement, residuals
  and pose covariance); camera poses to and from the pipeline file's convention.
* :mod:`~fusiontrack.calibration.pipeline_file` — :func:`write_pose_to_pipeline`: a sensor's pose rewritten in
  place, the rest of the file kept.
* :mod:`~fusiontrack.calibration.regions` (A6), :mod:`~fusiontrack.calibration.clusters` (A8 on the A7
  foreground), :mod:`~fusiontrack.calibration.selection` (A9, A10) — pure functions of the adaptive bias.
* :mod:`~fusiontrack.calibration.bias` — :class:`HorizontalBiasEstimator`: laser backgrounds, the bias, its
  history and the corrected camera.
* :mod:`~fusiontrack.calibration.bias_run` — the estimator over a recording (camera path A1–A5 included).
* :mod:`~fusiontrack.calibration.calibrate` — what ``fusiontrack calibrate`` does.
"""

from fusiontrack.calibration.bias import BiasHistory, BiasParams, BiasStep, HorizontalBiasEstimator
from fusiontrack.calibration.bias_run import (
    BiasInputs,
    BiasRun,
    FrameObjects,
    bias_from_recording,
    object_centroids,
    open_bias_inputs,
    write_bias_history,
)
from fusiontrack.calibration.calibrate import (
    CalibrationReport,
    calibrate_from_points,
    calibrate_from_recording,
    camera_info_from_recording,
    read_control_points,
)
from fusiontrack.calibration.clusters import ForegroundClusters, foreground_clusters
from fusiontrack.calibration.extrinsics import (
    PnPResult,
    cam2world_from_camera_pose,
    camera_pose_from_cam2world,
    pose_covariance,
    reprojection_residuals,
    solve_pnp,
)
from fusiontrack.calibration.pipeline_file import format_pose, update_pipeline_pose, write_pose_to_pipeline
from fusiontrack.calibration.regions import (
    CandidateRegions,
    candidate_regions,
    pixel_azimuths,
    points_in_regions,
    regions_overlap,
)
from fusiontrack.calibration.selection import bias_update, discriminant, select_clusters

__all__ = [
    "BiasHistory",
    "BiasInputs",
    "BiasParams",
    "BiasRun",
    "BiasStep",
    "CalibrationReport",
    "CandidateRegions",
    "ForegroundClusters",
    "FrameObjects",
    "HorizontalBiasEstimator",
    "PnPResult",
    "bias_from_recording",
    "bias_update",
    "calibrate_from_points",
    "calibrate_from_recording",
    "cam2world_from_camera_pose",
    "camera_info_from_recording",
    "camera_pose_from_cam2world",
    "candidate_regions",
    "discriminant",
    "foreground_clusters",
    "format_pose",
    "object_centroids",
    "open_bias_inputs",
    "pixel_azimuths",
    "points_in_regions",
    "pose_covariance",
    "read_control_points",
    "regions_overlap",
    "reprojection_residuals",
    "select_clusters",
    "solve_pnp",
    "update_pipeline_pose",
    "write_bias_history",
    "write_pose_to_pipeline",
]
