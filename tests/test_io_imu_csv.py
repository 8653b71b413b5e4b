"""IMU CSV reading, checked against the facts stated for the Oxford Step Counter data set."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.errors import ConfigError, RecordingError
from fusiontrack.io.csvtable import read_numeric_table
from fusiontrack.io.imu_csv import detect_imu_csv_format, read_imu_csv
from fusiontrack.types import ImuSample

SHARED_DATA = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data").resolve()  # as conftest.py
OXFORD = SHARED_DATA / "imu/oxford_step_counter"
VALIDATION = OXFORD / "validation"
OPTIMISATION = OXFORD / "optimisation"
needs_oxford = pytest.mark.skipif(not OXFORD.is_dir(), reason="Oxford step counter data not available")


def _validation_file(position: str) -> Path:
    (path,) = VALIDATION.glob(f"user1_{position}_*.csv")
    return path


def _stats_row(trace: str) -> dict[str, str]:
    """The row of optimisation/stats.csv for one trace (header: ``#dir, user, ..., duration(s), steps``)."""
    with (OPTIMISATION / "stats.csv").open(newline="") as f:
        rows = [[c.strip() for c in row] for row in csv.reader(f) if row]
    header = [h.lstrip("#").strip() for h in rows[0]]
    (row,) = [r for r in rows[1:] if r[0] == trace]
    return dict(zip(header, row, strict=True))


# -- validation traces (README: six traces, 100 Hz, ~200 s, final ground truth 326-361) ------------


@needs_oxford
def test_validation_final_counts_rate_and_duration() -> None:
    files = sorted(VALIDATION.glob("*.csv"))
    assert len(files) == 6
    finals = []
    for path in files:
        imu = read_imu_csv(path)
        assert imu.format == "oxford_validation"
        finals.append(imu.n_steps_gt)
        assert 326 <= imu.n_steps_gt <= 361
        assert imu.rate_hz == pytest.approx(100.0, rel=0.01)
        assert 180 <= imu.duration_s <= 220
        assert np.all(imu.steps_hw_cum == 0)  # README: the hardware counter is 0 for user 1
        # cumulative counts never decrease; one ground-truth step time per counted step
        assert np.all(np.diff(imu.steps_gt_cum) >= 0)
        assert imu.step_times_ns.size == imu.n_steps_gt
    assert min(finals) == 326


@needs_oxford
@pytest.mark.parametrize(("position", "gt", "app"), [("hand", 326, 311), ("backpocket", 343, 501)])
def test_validation_readme_examples(position: str, gt: int, app: int) -> None:
    imu = read_imu_csv(_validation_file(position), sensor="phone")
    assert imu.steps_gt_cum[-1] == gt
    assert imu.steps_app_cum[-1] == app
    n = len(imu)
    assert imu.t_ns.shape == (n,)
    assert imu.t_ns.dtype == np.int64
    assert imu.accel_mps2.shape == (n, 3)
    assert np.isnan(imu.gyro_radps).all()
    # units are m/s^2, not g: the mean specific force of a walk is gravity plus some jostling
    assert 9.0 < np.linalg.norm(imu.accel_mps2, axis=1).mean() < 13.0


@needs_oxford
def test_validation_samples_are_records() -> None:
    path = _validation_file("hand")
    imu = read_imu_csv(path, sensor="phone", frame_id="phone_imu")
    samples = imu.samples
    assert len(samples) == len(imu)
    assert samples is imu.samples  # built once
    s = samples[1]
    assert isinstance(s, ImuSample)
    assert (s.sensor, s.frame_id) == ("phone", "phone_imu")
    # second line of the file: 1012471532132,0.48243165,2.4528596,4.9643774,0,0,0
    assert s.t_ns == 1012471532132
    np.testing.assert_array_equal(s.accel_mps2, [0.48243165, 2.4528596, 4.9643774])
    assert np.isnan(s.gyro_radps).all()


# -- optimisation traces: step events against stats.csv ---------------------------------------------


@needs_oxford
@pytest.mark.parametrize("trace", ["Pixel_Jamie_Hard_InHand_1", "Pixel_Jamie_Hard_FrontPocket_1"])
def test_optimisation_step_events_match_stats(trace: str) -> None:
    stats = _stats_row(trace)
    imu = read_imu_csv(OPTIMISATION / trace)
    assert imu.format == "oxford_optimisation"
    assert imu.path.name == "accelerometer.csv"
    # each change of the toggling gt_step_event level is one step: their number is stats.csv's count
    assert imu.step_times_ns.size == imu.n_steps_gt == int(stats["steps"])
    assert abs(imu.duration_s - float(stats["duration(s)"])) < 2.0
    assert np.all(np.diff(imu.step_times_ns) > 0)
    assert imu.t_ns[0] <= imu.step_times_ns[0]
    assert imu.step_times_ns[-1] <= imu.t_ns[-1]
    # a walking cadence: 1.5-2.2 steps per second between the first and last step
    span_s = (imu.step_times_ns[-1] - imu.step_times_ns[0]) * 1e-9
    assert 1.5 < (imu.step_times_ns.size - 1) / span_s < 2.2
    # The data README says "~100 Hz" for these traces; the Pixel's accelerometer actually runs at ~405 Hz
    # (66544 and 61406 rows over 164 s and 151 s).
    assert 395 < imu.rate_hz < 415
    assert imu.hw_step_times_ns is not None
    assert imu.steps_gt_cum is None


@needs_oxford
def test_optimisation_accelerometer_file_alone(tmp_path: Path) -> None:
    src = OPTIMISATION / "Pixel_Jamie_Hard_InHand_1" / "accelerometer.csv"
    by_name = read_imu_csv(src)  # the file named accelerometer.csv: steps found next to it
    assert by_name.n_steps_gt == 292
    lonely = tmp_path / "acc_copy.csv"
    lonely.write_text("".join(src.read_text().splitlines(keepends=True)[:1000]))
    assert detect_imu_csv_format(lonely) == "oxford_optimisation"
    imu = read_imu_csv(lonely)
    assert len(imu) == 1000
    assert imu.step_times_ns is None
    assert imu.n_steps_gt is None


# -- generic format --------------------------------------------------------------------------------


def test_generic_t_s_with_gyro(tmp_path: Path) -> None:
    p = tmp_path / "phone.csv"
    p.write_text("# my phone\nt_s,ax,ay,az,gx,gy,gz,temp\n"
                 "0.5,0,0,9.81,0.1,0.2,0.3,20\n"
                 "0.51,0.1,0,9.8,0.1,0.2,0.3,20\n\n"
                 "0.52,0.2,0,9.7,0.1,0.2,0.3,21\n")
    imu = read_imu_csv(p)
    assert imu.format == "generic"
    np.testing.assert_array_equal(imu.t_ns, [500_000_000, 510_000_000, 520_000_000])
    np.testing.assert_array_equal(imu.accel_mps2[:, 2], [9.81, 9.8, 9.7])
    np.testing.assert_array_equal(imu.gyro_radps[0], [0.1, 0.2, 0.3])
    assert imu.samples[0].gyro_radps[1] == 0.2


def test_generic_gyro_glitches_cost_their_samples_and_a_dead_gyro_is_dropped(tmp_path: Path) -> None:
    p = tmp_path / "phone.csv"
    t = np.arange(10) * 0.01

    def write(gyro_nan: list[int]) -> None:
        rows = [f"{x:.2f},0,0,9.81," + ("nan,nan,nan" if k in gyro_nan else "0.1,0.2,0.3") for k, x in enumerate(t)]
        p.write_text("t_s,ax,ay,az,gx,gy,gz\n" + "\n".join(rows) + "\n")

    write([3])  # one glitch: that sample goes, the gyroscope stays
    imu = read_imu_csv(p)
    assert len(imu) == 9
    assert np.isfinite(imu.gyro_radps).all()
    assert 3 * 10_000_000 not in imu.t_ns
    write(list(range(3, 10)))  # the gyroscope died after 3 samples: keep every sample, without the gyroscope
    imu = read_imu_csv(p)
    assert len(imu) == 10
    assert np.isnan(imu.gyro_radps).all()


@pytest.mark.parametrize("missing", ["", " "])
def test_empty_gyro_cells_are_a_missing_gyro_as_nan_is(tmp_path: Path, missing: str) -> None:
    """A spreadsheet leaves a missing value's cell empty (``0,0,9.81,,,``): read as NaN is, so the rules for a gyro
    that is missing in places or from most rows apply (the rows were refused: "expected a number, got ''"; and with
    every gyro cell empty, the trailing-comma rule took one away: "expected 7 values, got 6")."""
    t = np.arange(10) * 0.01
    p, q = tmp_path / "empty.csv", tmp_path / "nan.csv"
    for path, gap in ((p, missing), (q, "nan")):
        for name, dead in (("glitch", [3]), ("died", list(range(3, 10))), ("none", list(range(10)))):
            rows = [f"{x:.2f},0,0,9.81," + (",".join([gap] * 3) if k in dead else "0.1,0.2,0.3")
                    for k, x in enumerate(t)]
            path.with_name(f"{name}_{path.name}").write_text("t_s,ax,ay,az,gx,gy,gz\n" + "\n".join(rows) + "\n")
    for name, n in (("glitch", 9), ("died", 10), ("none", 10)):
        a, b = read_imu_csv(tmp_path / f"{name}_empty.csv"), read_imu_csv(tmp_path / f"{name}_nan.csv")
        assert len(a) == len(b) == n
        np.testing.assert_array_equal(a.t_ns, b.t_ns)
        np.testing.assert_array_equal(a.accel_mps2, b.accel_mps2)
        np.testing.assert_array_equal(a.gyro_radps, b.gyro_radps)


def test_generic_t_ns_exact_and_column_order(tmp_path: Path) -> None:
    t0 = 1_700_000_000_123_456_789  # beyond float64's exact integers
    p = tmp_path / "phone.csv"
    p.write_text("az,ay,ax,t_ns\n" + "".join(f"9.8,{i},0,{t0 + i}\n" for i in range(3)))
    imu = read_imu_csv(p, format="generic")
    np.testing.assert_array_equal(imu.t_ns, t0 + np.arange(3))
    np.testing.assert_array_equal(imu.accel_mps2[:, 1], [0, 1, 2])
    assert np.isnan(imu.gyro_radps).all()
    # a stamp written with ".0" and a NaN stamp among 300 rows: the NaN row goes, every other row keeps its own
    # stamp (the exact re-read had dropped the ".0" row too, shifting every later stamp onto the wrong sample)
    rows = [f"9.8,{i},0,{t0 + 10_000_000 * i}" for i in range(300)]
    rows[100] = f"9.8,100,0,{t0 + 1_000_000_000}.0"
    rows[200] = "9.8,200,0,nan"
    p.write_text("az,ay,ax,t_ns\n" + "\n".join(rows) + "\n")
    imu = read_imu_csv(p, format="generic")
    kept = np.delete(np.arange(300), 200)
    np.testing.assert_array_equal(imu.accel_mps2[:, 1], kept)
    np.testing.assert_array_equal(imu.t_ns, t0 + 10_000_000 * kept)


def test_a_byte_order_mark_and_trailing_commas_are_read_as_spreadsheets_write_them(tmp_path: Path) -> None:
    # a UTF-8 byte-order mark (Windows tools) made the header unreadable; a comma ending every line (some exporters)
    # made every row one value too long
    p = tmp_path / "phone.csv"
    body = "".join(f"{k * 0.01:.2f},0,{k},9.81\n" for k in range(5))
    for text in ("\ufefft_s,ax,ay,az\n" + body, "t_s,ax,ay,az,\n" + body.replace("\n", ",\n"),
                 "t_s,ax,ay,az,\n" + body):
        p.write_text(text, encoding="utf-8")
        imu = read_imu_csv(p)
        np.testing.assert_array_equal(imu.t_ns, np.arange(5) * 10_000_000)
        np.testing.assert_array_equal(imu.accel_mps2[:, 1], np.arange(5))
    p.write_text("".join(f"{1000 + k},0.1,{k},9.8,0,{k},0,\n" for k in range(4)))  # headerless Oxford rows
    assert read_imu_csv(p).n_steps_gt == 3
    p.write_text("t_s\tax\tay\taz\n0.00\t0\t0\t9.81\n")  # said of every row: "expected a number"
    with pytest.raises(RecordingError, match=r"phone\.csv, line 1: tab-separated values; expected comma-separated"):
        read_imu_csv(p, format="generic")


def test_generic_header_errors(tmp_path: Path) -> None:
    p = tmp_path / "phone.csv"
    p.write_text("time,ax,ay,az\n1,0,0,9.8\n")
    with pytest.raises(RecordingError, match=r"phone\.csv, line 1: header .*t_ns, t_ms or t_s"):
        read_imu_csv(p)
    p.write_text("t_s,ax,ay,az,gx\n1,0,0,9.8,0\n")
    with pytest.raises(RecordingError, match="only some of gx, gy, gz"):
        read_imu_csv(p)


def test_generic_units_are_checked_where_they_show(tmp_path: Path) -> None:
    # a phone at rest, turning at 1 rad/s: the specific force is g upwards (9.81 m/s^2)
    p = tmp_path / "phone.csv"
    rows = [(k * 0.01, 0.1, 0.2, 9.81, 0.0, 0.0, 1.0) for k in range(50)]

    def write(header: str, t_scale: float = 1.0, a_scale: float = 1.0, g_scale: float = 1.0) -> Path:
        p.write_text(header + "\n" + "".join(f"{t * t_scale:.6f},{ax * a_scale},{ay * a_scale},{az * a_scale},"
                                             f"{gx * g_scale},{gy * g_scale},{gz * g_scale}\n"
                                             for t, ax, ay, az, gx, gy, gz in rows))
        return p

    ref = read_imu_csv(write("t_s,ax,ay,az,gx,gy,gz"))
    # milliseconds under their own name: the same samples
    ms = read_imu_csv(write("t_ms,ax,ay,az,gx,gy,gz", t_scale=1e3))
    np.testing.assert_array_equal(ms.t_ns, ref.t_ns)
    # milliseconds from the start under t_s (10 "s" apart): the unit named, not the step filter's cut-off later
    with pytest.raises(RecordingError, match=r"t_s: the samples are 10 s apart \(median\), 0\.1 Hz, too slow for an "
                                             r"IMU; are the times milliseconds \(name the column t_ms\)"):
        read_imu_csv(write("t_s,ax,ay,az,gx,gy,gz", t_scale=1e3))
    with pytest.raises(RecordingError, match=r"t_ms: .*microseconds \(multiply them by 1000 and name the column t_ns"):
        read_imu_csv(write("t_ms,ax,ay,az,gx,gy,gz", t_scale=1e6))
    # milliseconds since 1970 under t_s, accelerations in g, a gyroscope in deg/s: each named, with the remedy
    rows = [(1.7e9 + t, *rest) for t, *rest in rows]
    with pytest.raises(RecordingError, match=r"t_s reaches 1\.7e\+12, which is milliseconds .*name the column t_ms"):
        read_imu_csv(write("t_s,ax,ay,az,gx,gy,gz", t_scale=1e3))
    with pytest.raises(RecordingError, match=r"median magnitude is 1, not about 9\.81.*values in g: multiply by"):
        read_imu_csv(write("t_s,ax,ay,az,gx,gy,gz", a_scale=1 / 9.81))
    with pytest.raises(RecordingError, match=r"gyroscope's 99th percentile is 57\.3.*in rad/s \(values in deg/s"):
        read_imu_csv(write("t_s,ax,ay,az,gx,gy,gz", g_scale=180 / np.pi))


# -- errors ----------------------------------------------------------------------------------------


def test_bad_rows_name_file_and_line(tmp_path: Path) -> None:
    # more bad rows than a sensor log's few: the file is not what it should be, and the error names the first
    p = tmp_path / "user9_hand.csv"
    good = "1000,0.1,0.2,9.8,0,0,0\n"
    p.write_text(good * 3 + "1040,0.1,0.2,9.8,0,0\n" + good + "1060,0.1,0.2\n")
    with pytest.raises(RecordingError, match=r"user9_hand\.csv, line 4: expected 7 comma-separated values.*"
                                             r"\(2 of 6 rows are bad\)"):
        read_imu_csv(p)
    p.write_text(good * 2 + "1030,0.1,abc,9.8,0,0,0\n" + "1030,0.1,x,9.8,0,0,0\n")
    with pytest.raises(RecordingError, match=r"user9_hand\.csv, line 3, column 3: expected a number"):
        read_imu_csv(p)
    p.write_text(good + "10x0,0.1,0.2,9.8,0,0,0\n" + "10y0,0.1,0.2,9.8,0,0,0\n")
    with pytest.raises(RecordingError, match=r"line 2, column 1: expected an integer"):
        read_imu_csv(p, format="oxford_validation")
    p.write_text("2000,0.1,0.2,9.8,0,0,0\n1000,0.1,0.2,9.8,0,1,0\n1001,0.1,0.2,9.8,0,1,0\n1002,0.1,0.2,9.8,0,1,0\n"
                 "900,0.1,0.2,9.8,0,1,0\n")
    with pytest.raises(RecordingError, match=r"line 2: time goes backwards.*\(2 rows out of order"):
        read_imu_csv(p)
    p.write_text("2000,0.1,0.2,9.8,0,0.5,0\n")
    with pytest.raises(RecordingError, match=r"line 1: steps_by_ground_truth must be a whole number"):
        read_imu_csv(p)
    p.write_text("1000,nan,0.2,9.8,0,0,0\n")
    with pytest.raises(RecordingError, match=r"no row has a finite acceleration"):
        read_imu_csv(p)


def test_a_clock_reset_is_an_error_not_a_drop(tmp_path: Path) -> None:
    # a second recording appended to the first (its clock starts again): too many rows would have to go
    p = tmp_path / "phone.csv"
    rows = [f"{t:.2f},0,0,9.81" for t in (*np.arange(0, 10, 0.01), *np.arange(0, 4, 0.01))]
    p.write_text("t_s,ax,ay,az\n" + "\n".join(rows) + "\n")
    with pytest.raises(RecordingError, match=r"phone\.csv, line 1002: time goes backwards.*clock reset"):
        read_imu_csv(p)


def test_one_row_stamped_ahead_costs_itself_not_the_rows_after_it(tmp_path: Path) -> None:
    # a glitch 0.3 s ahead: every row of the next 0.3 s is "behind" it, but the row itself is the one out of order
    p = tmp_path / "phone.csv"
    t = np.arange(10_000) * 0.01
    t[5000] += 0.3
    p.write_text("t_s,ax,ay,az\n" + "\n".join(f"{x:.2f},0,0,9.81" for x in t) + "\n")
    imu = read_imu_csv(p)
    assert len(imu) == 9_999
    np.testing.assert_array_equal(imu.t_ns, np.rint(np.delete(t, 5000) * 1e9).astype(np.int64))


@needs_oxford
@pytest.mark.parametrize("end", ["last", "first"])
def test_a_lone_row_stamped_far_from_the_log_at_either_end_is_dropped(tmp_path: Path, end: str,
                                                                      caplog: pytest.LogCaptureFixture) -> None:
    """A real trace whose last row is stamped 50 s ahead (or first row 50 s back): in time order, so nothing else
    caught it, and ``info`` reported a log 50 s longer. The row is dropped with a warning naming its line; the span,
    the rate and the ground-truth step count are the clean trace's."""
    src = _validation_file("frontpocket")
    lines = src.read_text().splitlines()
    clean = read_imu_csv(src)
    k = -1 if end == "last" else 0
    fields = lines[k].split(",")
    fields[0] = str(int(fields[0]) + (50_000_000_000 if end == "last" else -50_000_000_000))
    lines[k] = ",".join(fields)
    p = tmp_path / "user1_frontpocket_stray.csv"
    p.write_text("\n".join(lines) + "\n")
    with caplog.at_level("WARNING"):
        imu = read_imu_csv(p)
    line = len(lines) if end == "last" else 1
    assert f"line {line}: dropped a sample stamped 50 s from the rest of the log, alone at its" in caplog.text
    assert len(imu) == len(clean) - 1
    assert abs(imu.duration_s - clean.duration_s) < 0.05  # one sample interval, not 50 s
    assert imu.n_steps_gt == clean.n_steps_gt


def test_a_pause_inside_a_log_is_kept(tmp_path: Path) -> None:
    # a gap between two long runs of samples is the phone pausing, not a glitch: nothing is dropped
    p = tmp_path / "phone.csv"
    t = np.concatenate([np.arange(500) * 0.01, 60 + np.arange(500) * 0.01])
    p.write_text("t_s,ax,ay,az\n" + "\n".join(f"{x:.2f},0,0,9.81" for x in t) + "\n")
    assert len(read_imu_csv(p)) == 1000


@needs_oxford
def test_a_damaged_real_trace_loses_only_its_bad_rows(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A NaN sample, a garbled row, two rows swapped and a last line cut short (the phone stopped mid-write) in
    a real trace: each bad row is dropped with a warning that names the file and line, and the rest is read
    (before, any one of them refused the whole file)."""
    src = _validation_file("frontpocket")
    lines = src.read_text().splitlines()
    clean = read_imu_csv(src)
    damaged = list(lines)
    fields = damaged[500].split(",")
    fields[2] = "nan"
    damaged[500] = ",".join(fields)  # line 501
    damaged[900] = "garbage,,"  # line 901
    damaged[700], damaged[701] = damaged[701], damaged[700]  # lines 701 and 702 swapped (10 ms apart)
    damaged[-1] = damaged[-1][:15]
    p = tmp_path / "user1_frontpocket_damaged.csv"
    p.write_text("\n".join(damaged))
    with caplog.at_level("WARNING"):
        imu = read_imu_csv(p)
    warned = caplog.text
    for what in ("line 501", f"line 901, {len(lines)}"):
        assert what in warned, what
    assert "out of time order (line 701)" in warned or "out of time order (line 702)" in warned  # one of the two
    assert len(imu) == len(clean) - 4
    kept = np.isin(clean.t_ns, imu.t_ns)
    assert np.count_nonzero(~kept) == 4  # exactly the four damaged rows are gone
    np.testing.assert_array_equal(imu.accel_mps2, clean.accel_mps2[kept])
    assert np.all(np.diff(imu.t_ns) >= 0)
    assert imu.n_steps_gt == clean.n_steps_gt  # the cumulative ground truth survives


def test_missing_empty_and_unknown(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match=r"nope\.csv: no such file"):
        read_imu_csv(tmp_path / "nope.csv")
    empty = tmp_path / "empty.csv"
    empty.write_text("\n")
    with pytest.raises(RecordingError, match=r"empty\.csv: no data rows"):
        read_imu_csv(empty, format="oxford_validation")
    odd = tmp_path / "odd.csv"
    odd.write_text("1,2,3\n")
    with pytest.raises(RecordingError, match=r"odd\.csv, first line: 3 columns without a header"):
        read_imu_csv(odd)
    with pytest.raises(ConfigError, match="format"):
        read_imu_csv(odd, format="android")
    with pytest.raises(RecordingError, match=r"without accelerometer\.csv"):
        read_imu_csv(tmp_path)


def test_a_value_numpy_cannot_parse_is_named_by_its_file_line(tmp_path: Path) -> None:
    # Python's float takes "9_8", numpy's parser does not: the error named numpy's 0-based data row, not the line
    p = tmp_path / "t.csv"
    p.write_text("a,b\n\n1,2\n3,9_8\n")
    with pytest.raises(RecordingError, match=r"t\.csv, line 4, column 2: expected a number"):
        read_numeric_table(p, header=True)


def test_read_numeric_table_keeps_line_numbers(tmp_path: Path) -> None:
    p = tmp_path / "t.csv"
    p.write_text("a,b\n\n# c\n1,2\n3,4\n")
    table = read_numeric_table(p, header=True, int_cols=(0,))
    assert table.header == ["a", "b"]
    np.testing.assert_array_equal(table.line_numbers, [4, 5])
    np.testing.assert_array_equal(table.ints[0], [1, 3])
    assert len(table) == 2
