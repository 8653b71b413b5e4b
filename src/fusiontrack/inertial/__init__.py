"""Inertial pedestrian dead reckoning from a phone IMU (seed 002; ALGORITHMS.md C1–C5, C8).

* :mod:`~fusiontrack.inertial.preprocess` — input checks, uniform resampling, still-period gyro bias
  and noise, gravity direction and levelling (C1), vertical acceleration for any carrying position.
* :mod:`~fusiontrack.inertial.steps` — step detection: low-pass, peaks with a minimum step time and
  an adaptive threshold, valley check (C2).
* :mod:`~fusiontrack.inertial.step_length` — per-person straight-line step length from step duration,
  fitted from per-step lengths or walks of known length; JSON round trip (C3).
* :mod:`~fusiontrack.inertial.attitude` — Euler-rate matrix (erratum E1) and attitude / yaw
  integration with the gyro bias (C4).
* :mod:`~fusiontrack.inertial.dead_reckoning` — positions from step lengths and headings (C5) and
  :func:`run_pdr`, the C1 -> C5 chain on one stream.
* :mod:`~fusiontrack.inertial.correction` — thin-plate-spline drift correction from control pairs,
  affine fallback, causal application (C8).
* :mod:`~fusiontrack.inertial.pdr_io` — :func:`pdr_from_file`, :func:`write_pdr` and
  :func:`step_model_from_files` for the CLI.
"""

from fusiontrack.inertial.attitude import accel_tilt, euler_rate_matrix, integrate_attitude, integrate_yaw
from fusiontrack.inertial.correction import Correction, control_pairs, correct_trajectory, fit_correction
from fusiontrack.inertial.dead_reckoning import PdrResult, dead_reckon, run_pdr, step_headings
from fusiontrack.inertial.pdr_io import ImuStream, load_imu, pdr_from_file, step_model_from_files, write_pdr
from fusiontrack.inertial.preprocess import (
    ImuCalibration,
    calibrate_imu,
    check_imu,
    detect_still_period,
    gravity_to_level,
    level_imu,
    resample_uniform,
    vertical_acceleration,
)
from fusiontrack.inertial.projection import InertialProjection, fit_inertial_projection, projection_from_pdr
from fusiontrack.inertial.step_length import DEFAULT_STEP_MODEL, StepLengthModel, fit_step_model, load_step_model
from fusiontrack.inertial.steps import StepDetectorParams, Steps, detect_steps, step_signal

__all__ = [
    "DEFAULT_STEP_MODEL",
    "Correction",
    "ImuCalibration",
    "ImuStream",
    "InertialProjection",
    "PdrResult",
    "StepDetectorParams",
    "StepLengthModel",
    "Steps",
    "accel_tilt",
    "calibrate_imu",
    "check_imu",
    "control_pairs",
    "correct_trajectory",
    "dead_reckon",
    "detect_steps",
    "detect_still_period",
    "euler_rate_matrix",
    "fit_correction",
    "fit_inertial_projection",
    "fit_step_model",
    "gravity_to_level",
    "integrate_attitude",
    "integrate_yaw",
    "level_imu",
    "load_imu",
    "load_step_model",
    "pdr_from_file",
    "projection_from_pdr",
    "resample_uniform",
    "run_pdr",
    "step_headings",
    "step_model_from_files",
    "step_signal",
    "vertical_acceleration",
    "write_pdr",
]
