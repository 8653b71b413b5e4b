"""PDR on files: read an IMU stream from a CSV or a recording, run :func:`run_pdr`, write CSVs.

The layer the ``fusiontrack pdr`` command calls: :func:`pdr_from_file` and :func:`write_pdr`.

Inputs (:func:`load_imu`):

* an IMU CSV or an Oxford trace folder (:func:`fusiontrack.io.imu_csv.read_imu_csv`, format detected);
* a recording (ROS 1 bag, ROS 2 bag folder, ``.mcap``, ``.db3``; e.g. one written by
  ``fusiontrack simulate``): the ``sensor_msgs/msg/Imu`` topic (the first by name when there are
  several and no ``sensor`` is named), samples sorted by their header stamps.

Outputs (:func:`write_pdr`): ``steps.csv`` (one row per step) and ``trajectory.csv`` (the
piecewise-linear trajectory's knots: the start of each walk and the end of every step).
"""

from __future__ import annotations

import csv
import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, RecordingError
from ..types import ImuSample
from .dead_reckoning import PdrResult, run_pdr
from .preprocess import gyro_glitches
from .step_length import StepLengthModel, fit_step_model, load_step_model
from .steps import StepDetectorParams, detect_steps

__all__ = ["STEPS_COLUMNS", "TRAJECTORY_COLUMNS", "ImuStream", "load_imu", "pdr_from_file", "step_model_from_files",
           "write_pdr"]

log = logging.getLogger(__name__)

_CSV_SUFFIXES = (".csv", ".txt")
IMU_MSGTYPE = "sensor_msgs/msg/Imu"
STEPS_COLUMNS = ("step", "t_ns", "duration_s", "length_m", "heading_rad", "x_m", "y_m", "new_walk")
TRAJECTORY_COLUMNS = ("t_ns", "x_m", "y_m")


@dataclass(frozen=True, slots=True, eq=False)
class ImuStream:
    """IMU samples as arrays: ``t_ns (n,) int64``, ``accel_mps2 (n, 3)``, ``gyro_radps (n, 3)`` (NaN: none)."""

    t_ns: np.ndarray
    accel_mps2: np.ndarray
    gyro_radps: np.ndarray
    source: str
    sensor: str


def _is_csv(path: Path) -> bool:
    return path.suffix.lower() in _CSV_SUFFIXES or (path.is_dir() and (path / "accelerometer.csv").is_file())


def load_imu(path: str | Path, *, sensor: str | None = None) -> ImuStream:
    """Read an IMU stream from a CSV, an Oxford trace folder or a recording.

    Parameters
    ----------
    path : str or Path
    sensor : str, optional
        For a recording: the IMU's sensor name or topic (default: the first IMU topic by name).

    Raises
    ------
    RecordingError
        Missing file, unreadable data, or a recording without IMU messages.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: not found (expected an IMU CSV, an Oxford trace folder or a recording)")
    if _is_csv(path):
        from ..io.imu_csv import read_imu_csv

        data = read_imu_csv(path)
        return ImuStream(np.asarray(data.t_ns), np.asarray(data.accel_mps2), np.asarray(data.gyro_radps),
                         str(path), data.sensor)
    from ..io.recording import open_recording

    with open_recording(path) as rec:
        imu_topics = sorted(t for t, msgtype in rec.topic_types().items() if msgtype == IMU_MSGTYPE)
        if sensor is not None:
            chosen = [t for t in imu_topics if t == sensor or rec.sensor_of(t) == sensor]
            if not chosen:
                raise RecordingError(f"{path}: no IMU topic for sensor {sensor!r}; IMU topics: {imu_topics}")
        elif not imu_topics:
            raise RecordingError(f"{path}: no {IMU_MSGTYPE} topic in the recording")
        else:
            chosen = imu_topics[:1]
            if len(imu_topics) > 1:
                log.warning("%s: several IMU topics %s; using %s", path, imu_topics, chosen[0])
        samples = [m for m in rec.messages(chosen) if isinstance(m, ImuSample)]
        name = rec.sensor_of(chosen[0])
    if len(samples) < 2:
        raise RecordingError(f"{path}: {len(samples)} readable IMU message(s) on {chosen[0]}; need at least 2")
    t = np.array([s.t_ns for s in samples], dtype=np.int64)
    order = imu_time_order(f"{path} ({chosen[0]})", t)
    accel = np.stack([s.accel_mps2 for s in samples])[order]
    gyro = np.stack([s.gyro_radps for s in samples])[order]
    t, accel, gyro = drop_unusable_imu(str(path), t[order], accel, gyro)
    if t.size < 2:
        raise RecordingError(f"{path}: {t.size} IMU message(s) with a finite acceleration; need at least 2")
    return ImuStream(t, accel, gyro, str(path), name)


def imu_time_order(where: str, t_ns: np.ndarray) -> np.ndarray:
    """Which of a recording's IMU messages (stamps ``t_ns`` in log order) to use, as indices in time order, by the
    CSV reader's rules (:mod:`fusiontrack.io.imu_csv`): a message whose stamp breaks the order (stamped ahead of or
    behind its neighbours) costs itself, with a warning, while such messages are few (the fewest that put the rest
    in order; at most :data:`~fusiontrack.io.csvtable.MAX_BAD_ROW_SHARE` of them, or one); a stream delivered out of
    order more than that is sorted; then a first or last message stamped far from all the others is dropped. Sorted
    as they came, one message stamped 100 s ahead stretched the phone's trajectory to 100 s."""
    from ..io.csvtable import MAX_BAD_ROW_SHARE
    from ..io.imu_csv import longest_in_order, stray_ends

    t = np.asarray(t_ns, np.int64)
    if t.size and np.any(np.diff(t) < 0):
        keep = longest_in_order(t)
        n_drop = int(np.count_nonzero(~keep))
        if n_drop <= max(1, int(MAX_BAD_ROW_SHARE * t.size)):
            log.warning("%s: dropped %d IMU message(s) stamped out of order (ahead of or behind their neighbours; "
                        "message %s)", where, n_drop, ", ".join(str(int(k) + 1) for k in np.flatnonzero(~keep)[:5]))
            idx = np.flatnonzero(keep)
        else:
            log.info("%s: IMU header stamps out of log order; sorted", where)
            idx = np.argsort(t, kind="stable")
    else:
        idx = np.arange(t.size)
    keep = stray_ends(where, t[idx], idx + 1, np.ones(idx.size, bool), unit="message")
    return idx[keep]


def drop_unusable_imu(where: str, t: np.ndarray, accel: np.ndarray, gyro: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A recording's IMU samples as the CSV reader leaves them (fusiontrack.io.imu_csv): a message with a
    non-finite acceleration is dropped, with a warning naming ``where``; so is one whose gyroscope is non-finite
    while most are not; a gyroscope missing from most messages is not used (all NaN). One NaN message must not
    cost the phone's dead reckoning."""
    ok = np.isfinite(accel).all(axis=1)
    if not ok.all():
        log.warning("%s: dropped %d IMU message(s) with a non-finite acceleration (of %d)", where,
                    np.count_nonzero(~ok), ok.size)
        t, accel, gyro = t[ok], accel[ok], gyro[ok]
    bad = gyro_glitches(gyro)
    if bad is None:
        log.warning("%s: the gyroscope is missing (non-finite) from most of %d IMU messages; it is not used", where,
                    t.size)
        gyro = np.full_like(gyro, np.nan)
    elif bad.any():
        log.warning("%s: dropped %d IMU message(s) with a non-finite gyroscope (of %d)", where, np.count_nonzero(bad),
                    bad.size)
        t, accel, gyro = t[~bad], accel[~bad], gyro[~bad]
    return t, accel, gyro


def pdr_from_file(path: str | Path, step_model: StepLengthModel | str | Path | None = None, *,
                  sensor: str | None = None, **kwargs: Any) -> PdrResult:
    """Run :func:`~fusiontrack.inertial.dead_reckoning.run_pdr` on the IMU stream of a file.

    Parameters
    ----------
    path : str or Path
        An IMU CSV, an Oxford trace folder or a recording (see :func:`load_imu`).
    step_model : StepLengthModel or path to its JSON, optional
        The walker's step-length model; the default model when omitted.
    sensor : str, optional
        IMU sensor or topic of a recording.
    **kwargs
        Passed to :func:`run_pdr` (``step_params``, ``still``, ``start_m``, ``heading0_rad``, ...).

    Returns
    -------
    PdrResult
        With ``source`` set to ``path``.

    Raises
    ------
    RecordingError
        The file cannot be read, or its samples are unusable (NaN, time backwards, too short).
    ConfigError
        The step model file is missing or invalid.
    """
    if isinstance(step_model, str | Path):
        try:
            step_model = load_step_model(step_model)
        except ValueError as err:
            raise ConfigError(f"step_model: {err}") from err
    stream = load_imu(path, sensor=sensor)
    try:
        result = run_pdr(stream.t_ns, stream.accel_mps2, stream.gyro_radps, step_model=step_model, **kwargs)
    except ValueError as err:
        raise RecordingError(f"{path}: {err}") from err
    log.info("%s: %d steps, %.1f m walked", path, result.n_steps, result.distance_m)
    return dataclasses.replace(result, source=str(path))


def step_model_from_files(paths: Sequence[str | Path], total_length_m: Sequence[float], *, subject: str = "default",
                          step_params: StepDetectorParams | None = None) -> StepLengthModel:
    """Fit a walker's step model (ALGORITHMS.md C3) from recorded walks of known length.

    Parameters
    ----------
    paths : sequence of str or Path
        One IMU file per walk (see :func:`load_imu`); walks at different paces fix both slope and
        intercept, one walk only the scale (see :func:`fit_step_model`).
    total_length_m : sequence of float
        The distance of each walk, m.
    subject : str
        Stored in the model.
    step_params : StepDetectorParams, optional

    Raises
    ------
    RecordingError
        A file cannot be read or has unusable samples or no steps.
    ConfigError
        The lengths do not match the files.
    """
    paths = [Path(p) for p in paths]
    lengths = list(total_length_m)
    if len(lengths) != len(paths) or not paths:
        raise ConfigError(f"total_length_m: expected one distance per walk ({len(paths)} file(s)), got {len(lengths)}")
    durations = []
    for path in paths:
        stream = load_imu(path)
        try:
            steps = detect_steps(stream.t_ns, stream.accel_mps2, step_params)
        except ValueError as err:
            raise RecordingError(f"{path}: {err}") from err
        if len(steps) == 0:
            raise RecordingError(f"{path}: no steps detected; is it a walk?")
        durations.append(steps.duration_s)
    try:
        return fit_step_model(durations, total_length_m=lengths, subject=subject)
    except ValueError as err:
        raise ConfigError(str(err)) from err


def write_pdr(result: PdrResult, out_dir: str | Path) -> dict[str, Path]:
    """Write ``steps.csv`` and ``trajectory.csv`` into ``out_dir`` (created if needed).

    ``steps.csv``: ``step, t_ns, duration_s, length_m, heading_rad, x_m, y_m, new_walk`` (one row per
    step; ``x_m, y_m`` at the end of the step). ``trajectory.csv``: ``t_ns, x_m, y_m``, the knots of the
    piecewise-linear trajectory (:meth:`PdrResult.knots`).

    Returns
    -------
    dict
        ``{"steps": path, "trajectory": path}``.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        steps_path, traj_path = out / "steps.csv", out / "trajectory.csv"
        with steps_path.open("w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(STEPS_COLUMNS)
            for i in range(result.n_steps):
                w.writerow([i + 1, int(result.step_t_ns[i]), f"{result.step_duration_s[i]:.4f}",
                            f"{result.step_length_m[i]:.4f}", f"{result.heading_rad[i]:.6f}",
                            f"{result.position_m[i, 0]:.4f}", f"{result.position_m[i, 1]:.4f}",
                            int(result.new_walk[i])])
        t, pos = result.knots()
        with traj_path.open("w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(TRAJECTORY_COLUMNS)
            w.writerows([int(ti), f"{p[0]:.4f}", f"{p[1]:.4f}"] for ti, p in zip(t, pos, strict=True))
    except OSError as err:
        raise RecordingError(f"{out}: cannot write the PDR output ({err.strerror or err})") from err
    return {"steps": steps_path, "trajectory": traj_path}
