"""Reading phone accelerometer / IMU samples from CSV files.

Three formats are understood (``format=`` names them; ``"auto"`` detects them):

``"oxford_validation"``
    Oxford Step Counter ``validation/*.csv``: no header, seven columns
    ``timestamp_ns_since_boot, acc_x, acc_y, acc_z, steps_by_app, steps_by_ground_truth, steps_by_hw``
    (acceleration in m/s^2; the three step columns are cumulative counts).
``"oxford_optimisation"``
    Oxford Step Counter ``optimisation/<trace>/``: ``accelerometer.csv`` with no header,
    ``ts_ns, sensor_type, ax, ay, az``, and (optional, next to it) ``stepcounter.csv``,
    ``ts_ns, gt_step_event, hw_step_event``. The two step columns are *toggling* 0/1 levels, not
    impulses: each change of value is one step (the number of changes of ``gt_step_event`` equals the
    ``steps`` column of ``optimisation/stats.csv``; the number of 1s does not). The rows come every
    ~90 ms and the intervals between changes alternate short and long (~0.27 s / ~0.81 s on the
    Pixel traces, ~1.08 s per stride), so the times suit step counts and cadence over a few seconds
    better than the instant of each foot strike. The path may name the trace folder or its
    ``accelerometer.csv``. (The Pixel accelerometer runs at ~405 Hz, not ~100 Hz.)
``"generic"``
    A CSV for users' own phones, with a header row naming the columns (any order, extra columns
    ignored, ``#`` comment lines and blank lines skipped)::

        t_ns,ax,ay,az[,gx,gy,gz]        # t_ns: integer nanoseconds
        t_ms,ax,ay,az[,gx,gy,gz]        # t_ms: milliseconds (float), rounded to the nearest ns
        t_s,ax,ay,az[,gx,gy,gz]         # t_s: seconds (float), rounded to the nearest ns

    ``ax, ay, az`` in m/s^2 (specific force, gravity included, as phones report it); ``gx, gy, gz``
    in rad/s. Without gyro columns the gyro is ``NaN``. Units are checked where they show: accelerations
    whose median magnitude is under 3 m/s^2 (values in g, or gravity removed), a gyroscope whose 99th percentile
    is beyond 35 rad/s (values in deg/s) and ``t_s`` values that are milliseconds are errors that say so.

Auto-detection: a folder, or a file named ``accelerometer.csv``, is ``oxford_optimisation``; otherwise
the first data line decides: a header with letters is ``generic``, seven numbers are
``oxford_validation``, five numbers are ``oxford_optimisation`` (an accelerometer file alone).

Bad sensor data inside a log costs only its samples, each drop a warning naming the file and line: a row cut
short (the phone stopped mid-write) or garbled, a sample with a non-finite time or acceleration, a sample whose
gyroscope is non-finite (or, when that is most of them, the gyroscope altogether), and the fewest rows whose removal
puts the stamps in order (out of order, or one stamped ahead), and a lone first or last sample stamped far from
the rest (:data:`STRAY_GAP_S`). Repeated stamps occur in the Oxford data and are kept.
More than a few bad rows or out-of-order rows (:data:`~fusiontrack.io.csvtable.MAX_BAD_ROW_SHARE` of them, or one:
many rows back in time is a clock reset, two recordings in one file), or no usable row at all mean the file is
not what it should be: :class:`~fusiontrack.errors.RecordingError` naming the file and the first bad line (1-based,
as an editor shows it).
No pandas: parsing is ``np.loadtxt`` with a line-by-line scan only to locate an error.
"""

from __future__ import annotations

import bisect
import decimal
import functools
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError, RecordingError
from ..inertial.preprocess import G_MPS2, gyro_glitches
from ..types import ImuSample
from .csvtable import MAX_BAD_ROW_SHARE, NumericTable, read_numeric_table

__all__ = [
    "IMU_CSV_FORMATS",
    "ImuCsv",
    "detect_imu_csv_format",
    "longest_in_order",
    "read_imu_csv",
    "stray_ends",
]

logger = logging.getLogger(__name__)

IMU_CSV_FORMATS = ("oxford_validation", "oxford_optimisation", "generic")
"""The values ``format=`` accepts besides ``"auto"``."""


def longest_in_order(t_ns: np.ndarray) -> np.ndarray:
    """Mask of a longest non-decreasing subsequence of ``t_ns``: the fewest rows to drop to put the stamps in order
    (one row stamped ahead costs itself, not the rows after it). Patience sorting, O(n log n); run only when some
    stamp goes back."""
    tails: list[int] = []  # the smallest last stamp of an in-order run of each length
    tail_rows: list[int] = []
    prev = [-1] * t_ns.size
    for i, v in enumerate(t_ns.tolist()):
        k = bisect.bisect_right(tails, v)
        if k:
            prev[i] = tail_rows[k - 1]
        if k == len(tails):
            tails.append(v)
            tail_rows.append(i)
        else:
            tails[k], tail_rows[k] = v, i
    keep = np.zeros(t_ns.size, dtype=bool)
    i = tail_rows[-1] if tail_rows else -1
    while i >= 0:
        keep[i] = True
        i = prev[i]
    return keep


def _check_time_order(path: Path, t_ns: np.ndarray, line_numbers: np.ndarray) -> np.ndarray:
    """Rows to keep: all, or, when stamps go back, all but the fewest rows that put them in order, dropped with a
    warning while they are few (:data:`~fusiontrack.io.csvtable.MAX_BAD_ROW_SHARE`, or one). More than that (a clock
    reset: two recordings in one file) is an error naming the first line where time goes back."""
    n_repeat = int(np.count_nonzero(np.diff(t_ns) == 0))
    if n_repeat:
        logger.debug("%s: %d samples repeat the previous time stamp", path, n_repeat)
    back = np.flatnonzero(np.diff(t_ns) < 0)
    if not back.size:
        return np.ones(t_ns.size, dtype=bool)
    keep = longest_in_order(t_ns)
    drop = np.flatnonzero(~keep)
    if drop.size > max(1, int(MAX_BAD_ROW_SHARE * t_ns.size)):
        i = int(back[0]) + 1
        raise RecordingError(
            f"{path}, line {int(line_numbers[i])}: time goes backwards ({int(t_ns[i])} ns after "
            f"{int(t_ns[i - 1])} ns); expected rows in non-decreasing time order ({drop.size} rows out of order: "
            f"a clock reset, two recordings in one file?)"
        )
    shown = ", ".join(str(int(line_numbers[k])) for k in drop[:5]) + (", ..." if drop.size > 5 else "")
    logger.warning("%s: dropped %d sample(s) out of time order (line %s)", path, drop.size, shown)
    return keep


STRAY_GAP_S = 1.0
"""A first or last sample this far (or 100 sampling intervals, if longer) from the rest of the log is dropped."""


def stray_ends(path: Path | str, t_ns: np.ndarray, line_numbers: np.ndarray, keep: np.ndarray,
               unit: str = "line") -> np.ndarray:
    """``keep`` without a first or last sample stamped far from all the others (a clock glitch at the start or end
    of a log: one row stamped ahead as the phone stopped writing, or one far back): in time order, so nothing else
    marks it, and it would stretch the log's span (``info``, trajectories) by the gap. Dropped with a warning; a log
    of fewer than 10 samples is left as it is."""
    rows = np.flatnonzero(keep)
    if rows.size < 10:
        return keep
    t = t_ns[rows]
    dt = np.diff(t)
    pos = dt[dt > 0]
    if not pos.size:
        return keep
    limit = max(STRAY_GAP_S * 1e9, 100.0 * float(np.median(pos)))
    keep = keep.copy()
    for end, gap in ((rows[0], dt[0]), (rows[-1], dt[-1])):
        if gap > limit:
            keep[end] = False
            logger.warning("%s, %s %d: dropped a sample stamped %.3g s from the rest of the log, alone at its %s "
                           "(a clock glitch?)", path, unit, int(line_numbers[end]), gap / 1e9,
                           "start" if end == rows[0] else "end")
    return keep


def _finite_rows(path: Path, x: np.ndarray, line_numbers: np.ndarray, what: str) -> np.ndarray:
    """Rows of ``x (n, k)`` that are all finite; the others (a NaN sample, a sensor that stopped) are dropped
    with a warning."""
    ok = np.isfinite(x).all(axis=1)
    if not ok.any():
        raise RecordingError(f"{path}: no row has a finite {what} (line {int(line_numbers[0])}: {x[0].tolist()})")
    if not ok.all():
        bad = np.flatnonzero(~ok)
        logger.warning("%s: dropped %d sample(s) with a non-finite %s, first at line %d", path, bad.size, what,
                       int(line_numbers[bad[0]]))
    return ok


def _keep(table: NumericTable, keep: np.ndarray) -> NumericTable:
    """The table's rows where ``keep``."""
    if keep.all():
        return table
    return NumericTable(values=table.values[keep], ints={c: v[keep] for c, v in table.ints.items()},
                        line_numbers=table.line_numbers[keep], header=table.header,
                        skipped_lines=table.skipped_lines)


# --------------------------------------------------------------------------------------------------
# The result
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ImuCsv:
    """IMU samples read from a CSV file, as arrays and (built on first use) as records.

    Attributes
    ----------
    path : Path
        The file read (the ``accelerometer.csv`` for the optimisation format).
    format : str
        One of :data:`IMU_CSV_FORMATS`.
    sensor, frame_id : str
        Given to every :class:`~fusiontrack.types.ImuSample`.
    t_ns : (n,) int64
        Sample times in nanoseconds (the file's clock, e.g. time since boot), non-decreasing.
    accel_mps2 : (n, 3) float64
        Specific force in m/s^2 in the phone's frame.
    gyro_radps : (n, 3) float64
        Angular rate in rad/s; ``NaN`` when the file has none.
    steps_gt_cum, steps_app_cum, steps_hw_cum : (n,) int64 or None
        Cumulative step counts at each sample (ground truth, the Oxford app's algorithm, the phone's
        hardware counter); ``oxford_validation`` only.
    step_times_ns : (k,) int64 or None
        Ground-truth step times: where ``steps_gt_cum`` increases (validation, so at the resolution of
        the 10 ms sampling), or where ``gt_step_event`` toggles (optimisation). ``None`` when the
        file holds no ground truth.
    hw_step_times_ns : (k,) int64 or None
        The same for the phone's hardware step counter (optimisation format only).
    """

    path: Path
    format: str
    sensor: str
    frame_id: str
    t_ns: np.ndarray
    accel_mps2: np.ndarray
    gyro_radps: np.ndarray
    steps_gt_cum: np.ndarray | None = None
    steps_app_cum: np.ndarray | None = None
    steps_hw_cum: np.ndarray | None = None
    step_times_ns: np.ndarray | None = None
    hw_step_times_ns: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("t_ns", "accel_mps2", "gyro_radps", "steps_gt_cum", "steps_app_cum", "steps_hw_cum",
                     "step_times_ns", "hw_step_times_ns"):
            arr = getattr(self, name)
            if arr is not None:
                arr.setflags(write=False)

    def __len__(self) -> int:
        return int(self.t_ns.size)

    @functools.cached_property
    def samples(self) -> list[ImuSample]:
        """The samples as records, ``len(self)`` of them (built once, on first access)."""
        return [ImuSample(t, self.sensor, self.frame_id, a, g)
                for t, a, g in zip(self.t_ns.tolist(), self.accel_mps2, self.gyro_radps, strict=True)]

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample, in seconds."""
        return float(self.t_ns[-1] - self.t_ns[0]) * 1e-9 if len(self) else 0.0

    @property
    def rate_hz(self) -> float:
        """Sampling rate from the median sampling interval (robust to gaps and repeated stamps), in Hz."""
        dt = np.diff(self.t_ns)
        dt = dt[dt > 0]
        return float(1e9 / np.median(dt)) if dt.size else float("nan")

    @property
    def n_steps_gt(self) -> int | None:
        """The ground-truth number of steps in the file, or ``None`` when it holds no ground truth."""
        if self.steps_gt_cum is not None:
            return int(self.steps_gt_cum[-1])
        return None if self.step_times_ns is None else int(self.step_times_ns.size)


# --------------------------------------------------------------------------------------------------
# Format readers
# --------------------------------------------------------------------------------------------------

_VALIDATION_COLS = ("timestamp_ns_since_boot, acc_x, acc_y, acc_z, steps_by_app, "
                    "steps_by_ground_truth, steps_by_hw")
_ACCEL_COLS = "ts_ns, sensor_type, ax, ay, az"
_STEP_COLS = "ts_ns, gt_step_event, hw_step_event"


def _increase_times(t_ns: np.ndarray, cum: np.ndarray) -> np.ndarray:
    """Times at which a cumulative count increases, each repeated by the size of the increase."""
    inc = np.diff(cum, prepend=cum[:1])
    return np.repeat(t_ns, np.clip(inc, 0, None))


def _toggle_times(t_ns: np.ndarray, level: np.ndarray) -> np.ndarray:
    """Times at which a 0/1 level changes value (one event per change)."""
    return t_ns[1:][level[1:] != level[:-1]]


def _int_column(path: Path, table: NumericTable, col: int, name: str) -> np.ndarray:
    x = table.values[:, col]
    bad = np.flatnonzero(~np.isfinite(x) | (x != np.round(x)))
    if bad.size:
        i = int(bad[0])
        raise RecordingError(f"{path}, line {int(table.line_numbers[i])}: {name} must be a whole number, "
                             f"got {x[i]!r}")
    return x.astype(np.int64)


def _exact_ints(path: Path, line_numbers: np.ndarray, col: int, name: str) -> np.ndarray:
    """Column ``col`` of the file's lines ``line_numbers`` as exact integers (float64 rounds beyond 2**53 ns, i.e.
    epoch nanoseconds), read from the text of exactly the rows kept (``"170...00.0"`` is a whole number too)."""
    lines = path.read_text(encoding="utf-8-sig").splitlines()
    out = np.empty(line_numbers.size, dtype=np.int64)
    for k, ln in enumerate(line_numbers.tolist()):
        text = lines[ln - 1].split(",")[col].strip()
        try:
            value = decimal.Decimal(text)
            if value != value.to_integral_value():
                raise decimal.InvalidOperation
            out[k] = int(value)
        except (decimal.InvalidOperation, ValueError, OverflowError):
            raise RecordingError(f"{path}, line {ln}: {name} must be a whole number, got {text!r}") from None
    return out


def _read_validation(path: Path, sensor: str, frame_id: str) -> ImuCsv:
    table = read_numeric_table(path, n_cols=7, int_cols=(0,), what=_VALIDATION_COLS, skip_bad_rows=True)
    table = _keep(table, _finite_rows(path, table.values[:, 1:4], table.line_numbers, "acceleration"))
    order = _check_time_order(path, table.ints[0], table.line_numbers)
    table = _keep(table, stray_ends(path, table.ints[0], table.line_numbers, order))
    t_ns = table.ints[0]
    app, gt, hw = (_int_column(path, table, c, name) for c, name in
                   ((4, "steps_by_app"), (5, "steps_by_ground_truth"), (6, "steps_by_hw")))
    return ImuCsv(path, "oxford_validation", sensor, frame_id, t_ns, table.values[:, 1:4].copy(),
                  np.full((t_ns.size, 3), np.nan), steps_gt_cum=gt, steps_app_cum=app, steps_hw_cum=hw,
                  step_times_ns=_increase_times(t_ns, gt))


def _read_optimisation(path: Path, sensor: str, frame_id: str) -> ImuCsv:
    folder = path if path.is_dir() else path.parent
    accel_path = folder / "accelerometer.csv" if path.is_dir() else path
    table = read_numeric_table(accel_path, n_cols=5, int_cols=(0,), what=_ACCEL_COLS, skip_bad_rows=True)
    table = _keep(table, _finite_rows(accel_path, table.values[:, 2:5], table.line_numbers, "acceleration"))
    order = _check_time_order(accel_path, table.ints[0], table.line_numbers)
    table = _keep(table, stray_ends(accel_path, table.ints[0], table.line_numbers, order))
    t_ns = table.ints[0]
    kinds = np.unique(table.values[:, 1])
    if kinds.size > 1:
        logger.warning("%s: several sensor_type values %s; all rows are read as accelerometer",
                       accel_path, kinds.tolist())
    step_path = folder / "stepcounter.csv"
    gt_times = hw_times = None
    if step_path.is_file():
        steps = read_numeric_table(step_path, n_cols=3, int_cols=(0,), what=_STEP_COLS, skip_bad_rows=True)
        steps = _keep(steps, _check_time_order(step_path, steps.ints[0], steps.line_numbers))
        ts = steps.ints[0]
        gt_times = _toggle_times(ts, _int_column(step_path, steps, 1, "gt_step_event"))
        hw_times = _toggle_times(ts, _int_column(step_path, steps, 2, "hw_step_event"))
    else:
        logger.info("%s: no stepcounter.csv next to it; no ground-truth steps", accel_path)
    return ImuCsv(accel_path, "oxford_optimisation", sensor, frame_id, t_ns, table.values[:, 2:5].copy(),
                  np.full((t_ns.size, 3), np.nan), step_times_ns=gt_times, hw_step_times_ns=hw_times)


_GENERIC_DOC = "a header with t_ns, t_ms or t_s, ax, ay, az (m/s^2) and optionally gx, gy, gz (rad/s)"
_PHONE_GYRO_MAX_RADPS = 35.0  # phone gyroscopes saturate at 2000 deg/s (34.9 rad/s)


_MAX_SAMPLE_STEP_S = 1.0
"""A generic IMU CSV whose median sample interval is longer than this has its times in a wrong unit."""


def _read_generic(path: Path, sensor: str, frame_id: str) -> ImuCsv:
    table = read_numeric_table(path, header=True, what=_GENERIC_DOC, skip_bad_rows=True, empty_as_nan=True)
    names = [n.lower() for n in table.header or []]
    missing = [n for n in ("ax", "ay", "az") if n not in names]
    if not {"t_ns", "t_ms", "t_s"} & set(names) or missing:
        raise RecordingError(f"{path}, line {int(table.line_numbers[0]) - 1}: header {table.header} "
                             f"lacks {missing or ['t_ns, t_ms or t_s']} (expected {_GENERIC_DOC})")
    gyro_names = ("gx", "gy", "gz")
    if any(n in names for n in gyro_names) and not all(n in names for n in gyro_names):
        raise RecordingError(f"{path}: header {table.header} has only some of gx, gy, gz "
                             "(expected all three or none)")
    name = next(n for n in ("t_ns", "t_ms", "t_s") if n in names)
    col = names.index(name)
    accel_cols = [names.index(n) for n in ("ax", "ay", "az")]
    table = _keep(table, _finite_rows(path, table.values[:, [col]], table.line_numbers, name))
    table = _keep(table, _finite_rows(path, table.values[:, accel_cols], table.line_numbers, "acceleration"))
    if name == "t_ns":
        t_ns = _int_column(path, table, col, "t_ns")
        if np.abs(table.values[:, col]).max() >= 2.0**53:  # beyond float64's exact integers
            t_ns = _exact_ints(path, table.line_numbers, col, "t_ns")
    else:
        t = table.values[:, col]
        if name == "t_s" and np.abs(t).max() > 1e11:  # past the year 5000 in seconds: milliseconds since 1970
            raise RecordingError(f"{path}: t_s reaches {np.abs(t).max():.6g}, which is milliseconds (or finer), "
                                 f"not seconds: name the column t_ms (or t_ns)")
        t_ns = np.rint(t * (1e6 if name == "t_ms" else 1e9)).astype(np.int64)
    keep = stray_ends(path, t_ns, table.line_numbers, _check_time_order(path, t_ns, table.line_numbers))
    table, t_ns = _keep(table, keep), t_ns[keep]
    step_s = float(np.median(np.diff(t_ns))) / 1e9 if t_ns.size >= 2 else 0.0
    if step_s > _MAX_SAMPLE_STEP_S:  # a phone's IMU samples at 10-500 Hz: a wrong unit, not a slow sensor
        finer = {"t_s": "milliseconds (name the column t_ms)",
                 "t_ms": "microseconds (multiply them by 1000 and name the column t_ns)",
                 "t_ns": "not nanoseconds"}[name]
        raise RecordingError(f"{path}: {name}: the samples are {step_s:.4g} s apart (median), "
                             f"{1 / step_s:.3g} Hz, too slow for an IMU; are the times {finer}?")
    accel = table.values[:, accel_cols]
    norm = np.linalg.norm(accel, axis=1)
    if np.median(norm) < 0.3 * G_MPS2:
        raise RecordingError(f"{path}: the acceleration's median magnitude is {np.median(norm):.3g}, not about "
                             f"9.81: ax, ay, az must be the specific force in m/s^2, gravity included, as phones "
                             f"report it (values in g: multiply by 9.81; gravity-free 'linear acceleration' will "
                             f"not do)")
    gyro = np.full((t_ns.size, 3), np.nan)
    if all(n in names for n in gyro_names):
        gyro = table.values[:, [names.index(n) for n in gyro_names]]
        ok = np.isfinite(gyro).all(axis=1)
        rate = np.abs(gyro[ok])
        top = float(np.percentile(rate, 99)) if rate.size else 0.0  # (a glitch or two is not the unit)
        if top > _PHONE_GYRO_MAX_RADPS:
            raise RecordingError(f"{path}: the gyroscope's 99th percentile is {top:.4g}, beyond a phone "
                                 f"gyroscope's range (2000 deg/s = 34.9 rad/s): gx, gy, gz must be in rad/s "
                                 f"(values in deg/s: multiply by pi/180)")
        bad = gyro_glitches(gyro)
        if bad is None:
            logger.warning("%s: the gyroscope is missing (non-finite) from %d of %d samples; it is not used",
                           path, np.count_nonzero(~ok), ok.size)
            gyro = np.full((t_ns.size, 3), np.nan)
        elif bad.any():
            logger.warning("%s: dropped %d sample(s) with a non-finite gyroscope, first at line %d", path,
                           np.count_nonzero(bad), int(table.line_numbers[np.flatnonzero(bad)[0]]))
            table, t_ns, accel, gyro = _keep(table, ~bad), t_ns[~bad], accel[~bad], gyro[~bad]
    return ImuCsv(path, "generic", sensor, frame_id, t_ns, accel, gyro)


_READERS = {"oxford_validation": _read_validation, "oxford_optimisation": _read_optimisation,
            "generic": _read_generic}


def detect_imu_csv_format(path: str | Path) -> str:
    """Guess the format of an IMU CSV file or Oxford trace folder (see the module docstring).

    Raises
    ------
    RecordingError
        The path does not exist or matches no known format.
    """
    path = Path(path)
    if path.is_dir():
        if (path / "accelerometer.csv").is_file():
            return "oxford_optimisation"
        raise RecordingError(f"{path}: a folder without accelerometer.csv (expected an Oxford optimisation "
                             "trace folder or a CSV file)")
    if path.name == "accelerometer.csv":
        return "oxford_optimisation"
    try:
        with path.open(encoding="utf-8-sig") as f:
            first = next((line for line in f if line.strip() and not line.lstrip().startswith("#")), "")
    except (OSError, UnicodeDecodeError) as err:
        raise RecordingError(f"{path}: cannot be read (expected an IMU CSV file)") from err
    if not first:
        what = "empty file (0 bytes)" if path.stat().st_size == 0 else "no data: only blank or comment lines"
        raise RecordingError(f"{path}: {what}; expected an IMU CSV file: 7 columns ({_VALIDATION_COLS}), "
                             f"5 ({_ACCEL_COLS}) or {_GENERIC_DOC}")
    fields = [x.strip() for x in first.rstrip().removesuffix(",").split(",")]  # (a trailing comma: no column)
    if any(c.isalpha() and x.lower() not in ("nan", "inf", "-inf") for x in fields for c in x[:1]):
        return "generic"
    if len(fields) == 7:
        return "oxford_validation"
    if len(fields) == 5:
        return "oxford_optimisation"
    raise RecordingError(
        f"{path}, first line: {len(fields)} columns without a header; expected 7 ({_VALIDATION_COLS}), "
        f"5 ({_ACCEL_COLS}) or {_GENERIC_DOC}"
    )


def read_imu_csv(
    path: str | Path, *, format: str = "auto", sensor: str = "imu", frame_id: str | None = None
) -> ImuCsv:
    """Read accelerometer (and gyro) samples from a CSV file or an Oxford trace folder.

    Parameters
    ----------
    path : str or Path
        A CSV file, or an Oxford optimisation trace folder.
    format : {"auto", "oxford_validation", "oxford_optimisation", "generic"}
        See the module docstring; ``"auto"`` calls :func:`detect_imu_csv_format`.
    sensor : str
        The ``sensor`` of every sample.
    frame_id : str, optional
        The ``frame_id`` of every sample; defaults to ``sensor``.

    Returns
    -------
    ImuCsv
        Arrays ``t_ns (n,)``, ``accel_mps2 (n, 3)``, ``gyro_radps (n, 3)``, ground-truth steps when the
        format has them, and ``samples`` as :class:`~fusiontrack.types.ImuSample` records.

    Raises
    ------
    RecordingError
        Missing file, unknown format, a bad row (file and line named) or time going backwards.
    ConfigError
        ``format`` is not one of the known names.
    """
    path = Path(path)
    if format != "auto" and format not in _READERS:
        raise ConfigError(f"format: expected 'auto' or one of {list(IMU_CSV_FORMATS)}, got {format!r}")
    if not path.exists():
        raise RecordingError(f"{path}: no such file or folder (expected an IMU CSV file)")
    fmt = detect_imu_csv_format(path) if format == "auto" else format
    result = _READERS[fmt](path, sensor, sensor if frame_id is None else frame_id)
    logger.debug("%s: %d IMU samples (%s) over %.1f s", path, len(result), fmt, result.duration_s)
    return result
