"""The simulator end to end: recordings read back through fusiontrack.io, checked against their own truth."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from scipy.signal import butter, filtfilt, find_peaks
from scipy.spatial.transform import Rotation

from fusiontrack.errors import ConfigError
from fusiontrack.geometry import PinholeCamera, TransformTree, scan_to_world
from fusiontrack.io.recording import Recording
from fusiontrack.sim.scenario import builtin_names, load_scenario
from fusiontrack.sim.simulator import T0_NS, simulate
from fusiontrack.types import CameraInfo, GroundTruth, ImuSample, LaserScan


@pytest.fixture(scope="module")
def crossing(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "crossing"
    scenario = load_scenario("crossing").with_overrides(seconds=8, seed=3)
    result = simulate(scenario, out)
    return out, result


def test_every_builtin_scenario_is_valid():
    assert set(builtin_names()) >= {"crossing", "groups", "crowd", "corridor", "road"}
    for name in builtin_names():
        sc = load_scenario(name)
        assert sc.description


def test_recording_reads_back_whole(crossing):
    out, result = crossing
    with Recording(out) as rec:
        topics = rec.topics()
        records = list(rec.messages())
        assert not rec.skipped  # every message converts
        n_messages = rec.message_count
    assert len(records) == n_messages  # one record per message (each tf message holds one transform)
    assert topics["/laser_0/scan"].count == result.messages["laser_0"]
    assert topics["/camera_0/image"].count == result.messages["camera_0"]
    assert topics["/laser_0/scan"].rate_hz == pytest.approx(25, rel=0.02)
    assert topics["/ground_truth"].rate_hz == pytest.approx(25, rel=0.02)


def test_same_seed_same_truth_and_other_seed_differs(tmp_path):
    a = load_scenario("crossing").with_overrides(seconds=3, seed=11)
    simulate(a, tmp_path / "a")
    simulate(a, tmp_path / "b")
    simulate(a.with_overrides(seed=12), tmp_path / "c")
    truth = [(tmp_path / x / "ground_truth" / "agents.csv").read_text() for x in "abc"]
    assert truth[0] == truth[1]
    assert truth[0] != truth[2]
    with Recording(tmp_path / "a") as ra, Recording(tmp_path / "b") as rb:
        scans_a = [m.ranges_m for m in ra.messages(["/laser_0/scan"])]
        scans_b = [m.ranges_m for m in rb.messages(["/laser_0/scan"])]
    assert all(np.array_equal(x, y) for x, y in zip(scans_a, scans_b, strict=True))


def _tree(rec: Recording) -> TransformTree:
    tree = TransformTree()
    for tf in rec.messages(["/tf_static"]):
        tree.add_record(tf)
    return tree


def test_laser_returns_lie_on_the_true_legs(crossing):
    """Scans mapped to the world with the recording's own tf_static land on ground-truth legs."""
    out, _ = crossing
    with Recording(out) as rec:
        tree = _tree(rec)
        truth = list(rec.messages(["/ground_truth"], time_source="log"))
        scans = list(rec.messages(["/laser_0/scan"], time_source="log"))
    by_t = {g.t_ns: g for g in truth}
    hits = 0
    for scan in scans[::5]:
        g = by_t.get(min(by_t, key=lambda t: abs(t - scan.t_ns)))
        if g is None or not len(g) or abs(g.t_ns - scan.t_ns) > 25_000_000:
            continue
        pts = scan_to_world(scan, tree.get(scan.sensor, "world"))
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        feet = g.attributes["feet_m"].reshape(-1, 2)
        d = np.linalg.norm(pts[:, None, :] - feet[None, :, :], axis=2)
        near = d.min(axis=1) < 0.2  # within a leg (6 cm radius) plus motion in 20 ms and noise
        hits += int(near.sum())
        # every point near a person is on a leg surface: radius 6 cm +- noise and motion
        assert np.all(np.abs(d.min(axis=1)[near] - 0.06) < 0.12)
    assert hits > 100


def test_true_camera_pose_reproduces_the_boxes_and_the_calibrated_one_is_3_degrees_off(tmp_path):
    scenario = load_scenario("crowd").with_overrides(seconds=4, seed=5)
    simulate(scenario, tmp_path / "c")
    with Recording(tmp_path / "c") as rec:
        tree = _tree(rec)
        info = next(m for m in rec.messages(["/camera_0/camera_info"]) if isinstance(m, CameraInfo))
        frames = list(rec.messages(["/ground_truth/camera_0"]))
    true_cam = PinholeCamera.from_camera_info(info, tree.get("world", "camera_0"))
    believed = PinholeCamera.from_camera_info(info, tree.get("world", "camera_0_calibrated"))
    # The calibration the user is given is the true pose turned by the scenario's 3 degrees about the
    # world vertical through the camera centre.
    true2world, cal2world = tree.get("camera_0", "world"), tree.get("camera_0_calibrated", "world")
    rotvec = Rotation.from_matrix(cal2world[:3, :3] @ true2world[:3, :3].T).as_rotvec()
    # the real camera is turned +3 deg (counter-clockwise from above) from what the user believes
    np.testing.assert_allclose(rotvec, [0.0, 0.0, -math.radians(3.0)], atol=1e-9)
    np.testing.assert_allclose(cal2world[:3, 3], true2world[:3, 3], atol=1e-9)
    checked = 0
    offsets = []
    for f in frames:
        t_true = int(f.attributes["t_true_ns"][0]) if len(f) else None
        if t_true is None:
            continue
        visible = (f.attributes["visibility"] > 0.9) & (np.array(f.classes) == "person")
        for k in np.flatnonzero(visible):
            box = f.attributes["box_px"][k]
            feet_mid = np.append(f.positions_m[k], 0.0)
            u, v = true_cam.project(feet_mid[None])[0]
            assert box[0] - 3 <= u <= box[2] + 3
            assert box[3] - 15 <= v <= box[3] + 3  # the feet are at the bottom of the box
            offsets.append(believed.project(feet_mid[None])[0][0] - u)
            checked += 1
    assert checked > 20
    # fx * tan(3 deg) ~ 22 px at fx = 420, for points near the image centre (less towards the sides)
    # The believed camera looks 3 deg clockwise of the real one, so scene points appear further left in
    # it: -fx * tan(3 deg) ~ -22 px near the image centre (less towards the sides).
    assert np.median(offsets) == pytest.approx(-420 * math.tan(math.radians(3)), rel=0.25)


def test_phone_steps_match_a_plain_peak_count(tmp_path):
    # no RGB-D cameras: each sensor draws from its own generator, so the phone and the truth are the same without
    # them (checked: identical IMU samples, steps and positions), and rendering them was two thirds of the time
    scenario = load_scenario("corridor").with_overrides(seconds=45, seed=2,
                                                        settings={"agents.n_passers": 0, "cameras": []})
    simulate(scenario, tmp_path / "p")
    with Recording(tmp_path / "p") as rec:
        imu = [m for m in rec.messages(["/phone/imu"]) if isinstance(m, ImuSample)]
        steps = list(rec.messages(["/ground_truth/steps"]))
        truth = list(rec.messages(["/ground_truth"]))
    carrier = next(int(g.ids[0]) for g in truth if len(g))  # the phone carrier appears first
    true_steps = [s for s in steps if int(s.ids[0]) == carrier]
    t = np.array([m.t_ns for m in imu]) / 1e9
    acc = np.array([m.accel_mps2 for m in imu])
    assert np.median(np.diff(t)) == pytest.approx(0.01, rel=0.05)
    # A plain detector: norm of the specific force, 3 Hz low-pass, peaks 1 m/s^2 above gravity.
    b, a = butter(4, 3.0 / 50.0)
    norm = filtfilt(b, a, np.linalg.norm(acc, axis=1))
    peaks, _ = find_peaks(norm, height=9.81 + 1.0, distance=30)
    assert len(true_steps) > 40
    assert abs(len(peaks) - len(true_steps)) <= 2
    # standing still for the first 12 s: no steps then
    assert all(s.t_ns > T0_NS + 11_000_000_000 for s in true_steps)


def test_clock_offset_and_outage_are_in_the_recording(tmp_path):
    scenario = load_scenario("crossing").with_overrides(
        seconds=4, seed=1, settings={"lasers.1.outages_s": [[1.0, 2.0]], "lasers.1.clock_offset_ms": 50.0})
    simulate(scenario, tmp_path / "o")
    with Recording(tmp_path / "o") as rec:
        by_header = [m.t_ns for m in rec.messages(["/laser_1/scan"])]
        by_log = [m.t_ns for m in rec.messages(["/laser_1/scan"], time_source="log")]
    delta = np.array(by_header) - np.array(by_log)
    # stamp = true + 50 ms offset; log = true + 2 ms latency
    assert np.all(delta == 48_000_000)
    t_true = (np.array(by_log) - 2_000_000 - T0_NS) / 1e9
    assert not np.any((t_true >= 1.0) & (t_true < 2.0))
    assert np.sum(t_true < 1.0) >= 24


def test_situations_and_csv_truth(crossing):
    out, _result = crossing
    with open(out / "ground_truth" / "agents.csv") as f:
        rows = list(csv.DictReader(f))
    assert {r["situation"] for r in rows} <= {"noncorrelated", "correlated", "merged", "appearing", "disappearing"}
    assert any(r["situation"] == "appearing" for r in rows)
    with Recording(out) as rec:
        gt = [g for g in rec.messages(["/ground_truth"]) if isinstance(g, GroundTruth)]
    assert sum(len(g) for g in gt) == len(rows)
    # the situation codes in the MCAP agree with the CSV labels
    from fusiontrack.sim.simulator import SITUATION_CODES

    names = {v: k.value for k, v in SITUATION_CODES.items()}
    from_mcap = [names[int(c)] for g in gt for c in g.attributes["situation"]]
    assert from_mcap == [r["situation"] for r in rows]


def test_road_incidents_are_written(tmp_path):
    scenario = load_scenario("road").with_overrides(seconds=100, seed=4, settings={"cameras": []})
    result = simulate(scenario, tmp_path / "r")
    with open(tmp_path / "r" / "ground_truth" / "incidents.csv") as f:
        kinds = {row["kind"] for row in csv.DictReader(f)}
    assert kinds == {"stopped_vehicle", "road_leaving", "jam"}
    assert result.incidents >= 3
    with Recording(tmp_path / "r") as rec:
        scans = [m for m in rec.messages(["/laser_0/scan"]) if isinstance(m, LaserScan)]
    assert np.mean([np.isfinite(s.valid_ranges_m()).sum() for s in scans]) > 10


def test_bad_scenario_values_name_the_field(tmp_path):
    with pytest.raises(ConfigError, match=r"agents.*unknown key.*n_peple"):
        simulate(load_scenario("crossing").with_overrides(seconds=1, settings={"agents.n_peple": 3}),
                 tmp_path / "x")
    with pytest.raises(ConfigError, match=r"lasers\.0\.rate_hz"):
        load_scenario("crossing").with_overrides(settings={"lasers.0.rate_hz": -5})
    with pytest.raises(ConfigError, match="unknown scenario 'crowed'"):
        load_scenario("crowed")
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario]\nduration_s = 'long'\n")
    with pytest.raises(ConfigError, match=r"bad\.toml.*scenario\.duration_s"):
        load_scenario(bad)


def test_the_pipeline_file_undoes_the_scenarios_clock_offset(tmp_path):
    """A sensor clock 12 ms ahead in the scenario is put back on true time by clock_offset_ms = 12."""
    from fusiontrack.config import parse_config
    from fusiontrack.io.sync import synchronize

    simulate(load_scenario("crossing").with_overrides(seconds=2, seed=2), tmp_path / "s")  # laser_1: +12 ms
    cfg = parse_config({"sensors": {"laser_1": {"kind": "laser", "topic": "/laser_1/scan", "clock_offset_ms": 12}}})
    with Recording(tmp_path / "s", sensors=cfg.topics()) as rec:
        corrected = [m.t_ns for m in synchronize(rec.messages(["/laser_1/scan"]), 0, cfg.clock_corrections_ns())]
        logged = [m.t_ns for m in rec.messages(["/laser_1/scan"], time_source="log")]
    true_t = np.array(logged) - 2_000_000  # the scenario's default 2 ms latency
    assert np.array_equal(np.array(corrected), true_t)
