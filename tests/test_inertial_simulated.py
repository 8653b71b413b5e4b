"""PDR on simulated phone walks with known heel strikes, step lengths and path (ALGORITHMS.md C1–C5).

The walks are made here from known step durations, step lengths and turn rates and fed to the
project's phone IMU simulator (``fusiontrack.sim.imu.simulate_imu``), whose vertical step pattern
peaks at the heel strikes (``heel_strike_times``). So every number checked below is known before
the inertial code runs: the strikes, the length of each step, the distance, the final heading.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.errors import ConfigError, RecordingError
from fusiontrack.inertial import (
    StepLengthModel,
    detect_steps,
    fit_step_model,
    load_imu,
    pdr_from_file,
    run_pdr,
    step_model_from_files,
    write_pdr,
)
from fusiontrack.io.writer import write_recording
from fusiontrack.sim.imu import heel_strike_times, simulate_imu
from fusiontrack.sim.model import ImuSpec, Timing
from fusiontrack.types import ImuSample

FS_HZ = 100.0


@dataclass(frozen=True)
class Walk:
    t_ns: np.ndarray
    position_m: np.ndarray
    heading_rad: np.ndarray
    phase_rad: np.ndarray
    speed_mps: np.ndarray
    velocity_mps: np.ndarray
    step_s: np.ndarray  # nominal step duration at each sample
    walking: np.ndarray  # 0..1: standing, ramping, walking at full pace

    @property
    def strikes_ns(self) -> np.ndarray:
        return heel_strike_times(self.t_ns, self.phase_rad)[0]

    @property
    def path_length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.position_m, axis=0), axis=1).sum())


def make_walk(segments: list[tuple[float, float, float, float]], *, still_s: float = 12.0, end_still_s: float = 2.0,
              ramp_s: float = 0.6) -> Walk:
    """A walker standing ``still_s``, then walking ``segments`` of (duration s, step duration s, step
    length m, turn rate rad/s), then standing. Starting and stopping are smoothed over ``ramp_s``; the
    gait phase advances by π per step (ALGORITHMS.md B8), so every step has exactly its length."""
    rows = [(still_s, *segments[0][1:3], 0.0, 0.0)]
    rows += [(d, sd, sl, w, 1.0) for d, sd, sl, w in segments]
    rows += [(end_still_s, *segments[-1][1:3], 0.0, 0.0)]
    cols = [np.concatenate([np.full(round(r[0] * FS_HZ), r[i]) for r in rows]) for i in range(1, 5)]
    step_s, step_m, turn, on = cols
    k = round(ramp_s * FS_HZ)
    kernel = np.hanning(2 * k + 1)
    on = np.convolve(np.pad(on, k, mode="edge"), kernel / kernel.sum(), "valid")
    on[: round(still_s * FS_HZ)] = 0.0
    dt = 1.0 / FS_HZ
    t_ns = np.round(np.arange(on.size) * dt * 1e9).astype(np.int64)
    speed = on * step_m / step_s
    # start half-way between two strikes (φ = π/2), where the step pattern is at its lowest
    phase = np.pi / 2 + np.concatenate([[0.0], np.cumsum(on * np.pi / step_s)[:-1] * dt])
    heading = np.concatenate([[0.0], np.cumsum(turn * on)[:-1] * dt])
    vel = speed[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    pos = np.concatenate([[[0.0, 0.0]], np.cumsum(vel, axis=0)[:-1] * dt])
    return Walk(t_ns, pos, heading, phase, speed, vel, step_s, on)


def phone(walk: Walk, rng: int, **spec_kw) -> tuple[np.ndarray, np.ndarray]:
    spec = ImuSpec(name="phone", carrier_id=1, timing=Timing(rate_hz=FS_HZ), **spec_kw)
    return simulate_imu(spec, walk.t_ns, walk.position_m, walk.heading_rad, walk.phase_rad, walk.speed_mps, rng,
                        velocity_mps=walk.velocity_mps)


POCKET = (0.0, np.deg2rad(80.0), 0.3)  # ALGORITHMS.md C1: a phone pitched 80° in a trouser pocket
CARRYING = {"hand": (0.1, -0.3, 0.0), "pocket": POCKET, "bag": (np.deg2rad(150.0), 0.4, 2.0)}


# ---- C2: steps at the heel strikes ---------------------------------------------------------------


@pytest.mark.parametrize("carry", sorted(CARRYING))
def test_steps_match_heel_strikes_in_any_carrying_position(carry: str) -> None:
    walk = make_walk([(30.0, 0.55, 0.7, 0.0), (9.0, 0.5, 0.65, np.deg2rad(10.0)), (20.0, 0.6, 0.75, 0.0)])
    accel, _ = phone(walk, 3, mount_rpy_rad=CARRYING[carry])
    steps = detect_steps(walk.t_ns, accel)
    strikes = walk.strikes_ns
    assert len(steps) == strikes.size
    gap_s = np.abs(steps.t_ns - strikes) * 1e-9
    assert np.max(gap_s) < 0.03  # within three samples, also in the ramps
    assert np.median(gap_s) < 0.005
    # durations at full pace are the walk's step durations (0.55, 0.5, 0.6 s)
    i = np.searchsorted(walk.t_ns, steps.t_ns)
    i_prev = np.searchsorted(walk.t_ns, steps.t_ns - np.round(steps.duration_s * 1e9).astype(np.int64))
    steady = (walk.walking[i] > 0.999) & (walk.walking[i_prev] > 0.999) & (walk.step_s[i] == walk.step_s[i_prev])
    assert steady.sum() > 80
    np.testing.assert_allclose(steps.duration_s[steady], walk.step_s[i[steady]], atol=0.015)
    assert steps.new_walk.sum() == 1


def test_standing_between_walks_restarts_the_duration_chain() -> None:
    first = make_walk([(15.0, 0.55, 0.7, 0.0)], still_s=3.0, end_still_s=5.0)
    second = make_walk([(15.0, 0.6, 0.7, 0.0)], still_s=0.5, end_still_s=1.0)
    offset_ns = int(first.t_ns[-1]) + 10_000_000
    t_ns = np.concatenate([first.t_ns, offset_ns + second.t_ns])
    accel = np.vstack([phone(first, 1)[0], phone(second, 2)[0]])
    strikes = np.concatenate([first.strikes_ns, offset_ns + second.strikes_ns])
    steps = detect_steps(t_ns, accel, first_duration_s=0.5)
    assert len(steps) == strikes.size
    assert np.max(np.abs(steps.t_ns - strikes)) * 1e-9 < 0.03
    # standing 5.5 s > C2's Δt_max = 1.5 s: two walks, each starting with the given first duration
    np.testing.assert_array_equal(np.flatnonzero(steps.new_walk), [0, first.strikes_ns.size])
    np.testing.assert_allclose(steps.duration_s[steps.new_walk], 0.5)
    assert np.max(steps.duration_s) < 1.5


# ---- C3: the step model from walks of known length -----------------------------------------------


def test_known_length_walks_recover_the_step_model() -> None:
    a, b = 0.9, 0.2  # ALGORITHMS.md C3 placeholder line, used as the truth here
    durations, lengths = [], []
    for i, step_s in enumerate((0.45, 0.55, 0.7)):  # the seed: "walk with different step lengths"
        walk = make_walk([(40.0, step_s, a * step_s + b, 0.0)], still_s=3.0)
        accel, _ = phone(walk, 10 + i)
        steps = detect_steps(walk.t_ns, accel)
        durations.append(steps.duration_s)
        lengths.append(np.linalg.norm(walk.position_m[-1] - walk.position_m[0]))  # a measured straight corridor
    model = fit_step_model(durations, total_length_m=lengths, subject="sim")
    assert model.slope_mps == pytest.approx(a, abs=0.05)
    assert model.intercept_m == pytest.approx(b, abs=0.03)
    assert model.typical_duration_s == pytest.approx(0.55, abs=0.01)
    # one walk only fixes the scale; the length at that walk's pace is still right
    single = fit_step_model(durations[1], total_length_m=lengths[1])
    assert single.length(0.55) == pytest.approx(a * 0.55 + b, rel=0.02)


def test_step_model_from_walk_files(tmp_path: Path) -> None:
    a, b = 0.8, 0.25
    paths, lengths = [], []
    for i, step_s in enumerate((0.5, 0.65)):
        walk = make_walk([(30.0, step_s, a * step_s + b, 0.0)], still_s=2.0)
        accel, _ = phone(walk, 20 + i, mount_rpy_rad=CARRYING["hand"])
        path = tmp_path / f"walk{i}.csv"
        np.savetxt(path, np.column_stack([walk.t_ns, accel]), delimiter=",", header="t_ns,ax,ay,az", comments="",
                   fmt=["%d"] + ["%.9g"] * 3)
        paths.append(path)
        lengths.append(float(np.linalg.norm(walk.position_m[-1] - walk.position_m[0])))
    model = step_model_from_files(paths, lengths, subject="carol")
    assert model.slope_mps == pytest.approx(a, abs=0.05)
    assert model.intercept_m == pytest.approx(b, abs=0.03)
    assert model.subject == "carol"
    with pytest.raises(ConfigError, match="total_length_m"):
        step_model_from_files(paths, lengths[:1])


# ---- C1 -> C5 end to end -------------------------------------------------------------------------


def test_run_pdr_recovers_the_path_of_a_turning_walk() -> None:
    step_s, step_m = 0.55, 0.695
    walk = make_walk([(20.0, step_s, step_m, 0.0), (9.0, step_s, step_m, np.deg2rad(10.0)),
                      (20.0, step_s, step_m, 0.0)])
    # biased gyro (0.5, -0.3, 0.4) deg/s. (Seed 7 draws a -3.9 sigma mean of the x-gyro noise over the
    # still period, which the heading tolerance below, ~3 sigma of that noise over 60 s, does not cover.)
    accel, gyro = phone(walk, 8, mount_rpy_rad=POCKET)
    model = StepLengthModel(0.0, step_m, typical_duration_s=step_s, n_train=1)
    result = run_pdr(walk.t_ns, accel, gyro, step_model=model)
    assert result.has_gyro
    assert result.n_steps == walk.strikes_ns.size
    assert result.calibration.still_ns is not None  # the 12 s standing start was found
    # 11.5 s still at 100 Hz, gyro noise 0.17 deg/s per sample: the mean is good to ~0.005 deg/s (1 sigma)
    np.testing.assert_allclose(np.rad2deg(result.calibration.gyro_bias_radps), (0.5, -0.3, 0.4), atol=0.03)
    # the walk turns 90° (10°/s for 9 s, smoothed in and out)
    assert np.rad2deg(result.heading_rad[-1]) == pytest.approx(np.rad2deg(walk.heading_rad[-1]), abs=1.0)
    assert result.distance_m == pytest.approx(result.n_steps * step_m)
    assert result.distance_m == pytest.approx(walk.path_length_m, abs=step_m)  # up to one partial step
    end_error = np.linalg.norm(result.position_m[-1] - walk.position_m[-1])
    assert end_error < 0.02 * walk.path_length_m
    # between steps the trajectory follows the truth too
    t_mid = walk.t_ns[(walk.t_ns > result.step_t_ns[0]) & (walk.t_ns < result.step_t_ns[-1])]
    true_mid = walk.position_m[np.searchsorted(walk.t_ns, t_mid)]
    assert np.max(np.linalg.norm(result.position_at(t_mid) - true_mid, axis=1)) < 1.0


def test_uncorrected_gyro_bias_turns_the_path() -> None:
    # the same walk without a still period: no bias estimate, and the heading drifts by bias x time
    walk = make_walk([(60.0, 0.55, 0.7, 0.0)], still_s=0.5)
    accel, gyro = phone(walk, 8, mount_rpy_rad=(0.0, 0.0, 0.0), gyro_bias_radps=(0.0, 0.0, np.deg2rad(0.5)))
    drifting = run_pdr(walk.t_ns, accel, gyro, still=None)
    known = run_pdr(walk.t_ns, accel, gyro - np.array([0.0, 0.0, np.deg2rad(0.5)]), still=None)
    t_end = (drifting.step_t_ns[-1] - walk.t_ns[0]) * 1e-9
    assert np.rad2deg(drifting.heading_rad[-1]) == pytest.approx(0.5 * t_end, rel=0.05)
    assert abs(np.rad2deg(known.heading_rad[-1])) < 0.5


# ---- files: CSV and recording in, CSVs out -------------------------------------------------------


def _walk_and_phone() -> tuple[Walk, np.ndarray, np.ndarray]:
    walk = make_walk([(20.0, 0.55, 0.7, 0.0), (5.0, 0.55, 0.7, np.deg2rad(18.0))], still_s=11.0)
    accel, gyro = phone(walk, 5, mount_rpy_rad=POCKET)
    return walk, accel, gyro


def test_pdr_from_csv_and_from_recording_agree(tmp_path: Path) -> None:
    walk, accel, gyro = _walk_and_phone()
    csv_path = tmp_path / "walk.csv"
    table = np.column_stack([walk.t_ns, accel, gyro])
    np.savetxt(csv_path, table, delimiter=",", header="t_ns,ax,ay,az,gx,gy,gz", comments="",
               fmt=["%d"] + ["%.9g"] * 6)
    samples = [ImuSample(int(t), "phone", "phone", a, g) for t, a, g in zip(walk.t_ns, accel, gyro, strict=True)]
    bag = tmp_path / "walk_bag"
    write_recording(bag, samples)
    model_path = StepLengthModel(0.0, 0.7, typical_duration_s=0.55, n_train=1).save(tmp_path / "model.json")
    from_csv = pdr_from_file(csv_path, model_path)
    from_bag = pdr_from_file(bag, model_path)
    assert from_csv.n_steps == from_bag.n_steps == walk.strikes_ns.size
    # the CSV holds 9 significant digits, the bag float64: the same steps to the nanosecond or so
    np.testing.assert_allclose(from_bag.step_t_ns, from_csv.step_t_ns, rtol=0, atol=2)
    np.testing.assert_allclose(from_bag.position_m, from_csv.position_m, atol=1e-5)
    assert np.linalg.norm(from_csv.position_m[-1] - walk.position_m[-1]) < 0.02 * walk.path_length_m
    assert from_bag.source == str(bag)
    stream = load_imu(bag)
    assert stream.sensor == "phone"
    assert stream.t_ns.size == walk.t_ns.size


def test_a_recording_with_nan_imu_messages_loses_only_them(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Three messages of a recorded phone carry NaN (a glitch) and one a NaN gyroscope: they are dropped with a
    warning, and dead reckoning still finds every heel strike of the simulated walk (one NaN refused the whole
    recording before)."""
    walk, accel, gyro = _walk_and_phone()
    accel, gyro = accel.copy(), gyro.copy()
    accel[[400, 900, 1400], 1] = np.nan
    gyro[1800, 2] = np.nan
    samples = [ImuSample(int(t), "phone", "phone", a, g) for t, a, g in zip(walk.t_ns, accel, gyro, strict=True)]
    write_recording(tmp_path / "walk_bag", samples)
    with caplog.at_level("WARNING"):
        stream = load_imu(tmp_path / "walk_bag")
        result = pdr_from_file(tmp_path / "walk_bag")
    assert stream.t_ns.size == walk.t_ns.size - 4
    assert np.isfinite(stream.accel_mps2).all()
    assert np.isfinite(stream.gyro_radps).all()
    assert "non-finite acceleration" in caplog.text
    assert "non-finite gyroscope" in caplog.text
    assert result.n_steps == walk.strikes_ns.size


def test_a_phone_with_a_nan_message_keeps_its_dead_reckoning_in_the_wearable_pipeline() -> None:
    """The wearable pipeline dead-reckons each phone (fusion/wearable_data.py): a NaN message gave the phone no
    trajectory at all; now it costs that sample, and the steps are the walk's heel strikes."""
    from fusiontrack.fusion.wearable_data import dead_reckon_phone

    walk, accel, gyro = _walk_and_phone()
    accel = accel.copy()
    accel[700, 2] = np.nan
    track = dead_reckon_phone("phone_a", walk.t_ns, accel, gyro)
    assert track.ok, track.error
    assert track.pdr.n_steps == walk.strikes_ns.size


def test_write_pdr_round_trip(tmp_path: Path) -> None:
    walk, accel, gyro = _walk_and_phone()
    result = run_pdr(walk.t_ns, accel, gyro)
    paths = write_pdr(result, tmp_path / "out")
    steps = np.loadtxt(paths["steps"], delimiter=",", skiprows=1)
    assert steps.shape == (result.n_steps, 8)
    np.testing.assert_array_equal(steps[:, 0], np.arange(1, result.n_steps + 1))
    np.testing.assert_array_equal(steps[:, 1].astype(np.int64), result.step_t_ns)  # ns survive float64 here
    np.testing.assert_allclose(steps[:, 3], result.step_length_m, atol=1e-4)
    np.testing.assert_allclose(steps[:, 5:7], result.position_m, atol=1e-4)
    traj = np.loadtxt(paths["trajectory"], delimiter=",", skiprows=1)
    _, pos = result.knots()
    np.testing.assert_allclose(traj[:, 1:], pos, atol=1e-4)
    assert traj.shape[0] == result.n_steps + int(result.new_walk.sum())
    np.testing.assert_allclose(traj[0, 1:], result.start_m)


def test_pdr_from_file_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="not found"):
        pdr_from_file(tmp_path / "missing.csv")
    short = tmp_path / "short.csv"
    short.write_text("t_s,ax,ay,az\n0.0,0,0,9.8\n0.01,0,0,9.8\n0.02,0,0,9.8\n")
    with pytest.raises(RecordingError, match=r"short\.csv.*too short"):
        pdr_from_file(short)
    bad_model = tmp_path / "model.json"
    bad_model.write_text('{"slope_mps": "fast"}')
    walk, accel, _ = _walk_and_phone()
    good = tmp_path / "walk.csv"
    np.savetxt(good, np.column_stack([walk.t_ns, accel]), delimiter=",", header="t_ns,ax,ay,az", comments="",
               fmt=["%d"] + ["%.9g"] * 3)
    with pytest.raises(ConfigError, match="step_model"):
        pdr_from_file(good, bad_model)
    with pytest.raises(ConfigError, match="step_model"):
        pdr_from_file(good, tmp_path / "no_model.json")


# ---- the simulator's own recording: ``fusiontrack simulate corridor`` without its cameras ---------


@pytest.mark.slow
def test_pdr_on_the_simulated_corridor_recording(tmp_path: Path) -> None:
    # seed 002's setting (corridor.toml): a phone pitched 80° in a pocket, 12 s standing, then a
    # figure-eight; cameras dropped and the walk cut to 80 s to keep the test short
    import csv
    import tomllib
    from importlib import resources

    from fusiontrack.sim.scenario import parse_scenario
    from fusiontrack.sim.simulator import simulate

    text = (resources.files("fusiontrack.sim") / "scenarios" / "corridor.toml").read_text(encoding="utf-8")
    config = tomllib.loads(text)
    config.pop("cameras", None)
    config["scenario"]["duration_s"] = 80
    out = tmp_path / "corridor"
    simulate(parse_scenario(config, "corridor.toml"), out)
    with open(out / "ground_truth" / "steps.csv", newline="") as f:
        strikes = np.array([int(r["t_ns"]) for r in csv.DictReader(f) if r["id"] == "0"])
    with open(out / "ground_truth" / "agents.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["id"] == "0"]
    t_true = np.array([int(r["t_ns"]) for r in rows])
    xy_true = np.array([[float(r["x"]), float(r["y"])] for r in rows])
    result = pdr_from_file(out, start_m=xy_true[0], heading0_rad=float(rows[0]["heading"]))
    assert abs(result.n_steps - strikes.size) <= 1
    gap_s = np.min(np.abs(result.step_t_ns[:, None] - strikes[None, :]), axis=1) * 1e-9
    assert np.median(gap_s) < 0.005
    # the default step model (not fitted to this walker) and the integrated gyro: within 5 % of the path
    path_m = float(np.linalg.norm(np.diff(xy_true, axis=0), axis=1).sum())
    truth_at_steps = np.stack([np.interp(result.step_t_ns, t_true, xy_true[:, i]) for i in range(2)], axis=1)
    err = np.linalg.norm(result.position_m - truth_at_steps, axis=1)
    assert err.max() < 0.05 * path_m
    assert result.distance_m == pytest.approx(path_m, rel=0.05)
