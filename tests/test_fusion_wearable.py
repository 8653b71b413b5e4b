"""The ``wearable`` pipeline (seed 002, ALGORITHMS.md C1-C14) end to end on a short simulated scene.

Two people, each with a phone in a trouser pocket, stand still 4 s and then walk laps in a room (the built-in
``wearable_lights`` scenario, shortened): two RGB-D cameras see them at their starts and on the way round, one
320x240 video camera watches the room, and the lights go down to 25 % from 9.5 s to 11 s. Truth: which agent
carries which phone (the simulator's plans), the agents' floor tracks, heel strikes and boxes in the images.
Bad input is made by editing a copy of the recording: IMU samples dropped (a gap, a phone that stops), depth
frames blanked (one camera, then every camera: nobody is ever seen by an RGB-D camera).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.fusion.wearable import WearableParams, run_wearable, track_wearable
from fusiontrack.inertial import run_pdr
from fusiontrack.io.recording import Recording
from fusiontrack.io.tracks import read_jsonl
from fusiontrack.io.writer import RecordingWriter
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import T0_NS, Simulation
from fusiontrack.types import DepthImage, Event, ImuSample

LIGHTS_OFF_S, LIGHTS_ON_S = 9.5, 11.0
SECONDS = 14.0


def _settings() -> dict:
    cameras = []
    for c in load_scenario("wearable_lights").config.model_dump()["cameras"]:
        if c["name"] in ("rgbd_0", "rgbd_1", "video_0"):
            c["illumination"] = [(LIGHTS_OFF_S, 0.25), (LIGHTS_ON_S, 1.0)]
            if c["name"] == "video_0":
                c.update(width=320, height=240, fx=200.0, fy=200.0)
            cameras.append(c)
    return {"agents.still_s": 4.0, "agents.stagger_s": 2.0, "cameras": cameras}


@pytest.fixture(scope="module")
def scene(simulated):
    settings = _settings()
    sim = Simulation(load_scenario("wearable_lights").with_overrides(seconds=SECONDS, seed=1, settings=settings))
    carriers = {p.phone: p.agent_id for p in sim.pedestrian_plans if p.phone}  # the plans, without running it
    recording = simulated("wearable_lights", seconds=SECONDS, seed=1, settings=settings)
    truth: dict[int, list] = {}
    with open(recording / "ground_truth" / "agents.csv", newline="") as f:
        for r in csv.DictReader(f):
            truth.setdefault(int(r["id"]), []).append((int(r["t_ns"]), float(r["x"]), float(r["y"]),
                                                       float(r["heading"])))
    result = track_wearable(recording, WearableParams(cameras=("video_0",)))
    return recording, carriers, {k: np.array(v) for k, v in truth.items()}, result


def _truth_at(track: np.ndarray, t_ns: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(t_ns, track[:, 0], track[:, 1]), np.interp(t_ns, track[:, 0], track[:, 2])])


def _edited_copy(src: Path, dst: Path, *, drop: dict[str, tuple[float, float]] | None = None,
                 blank: dict[str, tuple[float, float]] | None = None, images: tuple[str, ...] = ()) -> Path:
    """Copy the sensors the pipeline reads, dropping IMU samples in ``drop[phone]`` and blanking the depth frames of
    ``blank[camera]`` (``"all"``: every camera), both intervals in seconds."""
    drop, blank = drop or {}, blank or {}

    def inside(t_ns: int, span: tuple[float, float]) -> bool:
        return span[0] <= (t_ns - T0_NS) * 1e-9 < span[1]

    with Recording(src) as rec, RecordingWriter(dst) as out:
        topics = [t for t in rec.topics() if t == "/tf_static" or t.endswith(("/camera_info", "/depth", "/imu"))
                  or t in {f"/{c}/image" for c in images}]
        for m in rec.messages(topics):
            if isinstance(m, ImuSample) and m.sensor in drop and inside(m.t_ns, drop[m.sensor]):
                continue
            span = blank.get(m.sensor, blank.get("all"))
            if isinstance(m, DepthImage) and span is not None and inside(m.t_ns, span):
                m = DepthImage(m.t_ns, m.sensor, m.frame_id, np.full_like(m.depth_m, np.nan))
            out.write(m, log_t_ns=m.t_ns)
    return dst


def test_each_phone_owns_the_detections_of_its_carrier(scene):
    _recording, carriers, truth, result = scene
    names = sorted(result.people)
    assert set(names) == set(carriers)
    owned = 0
    for tr, o in zip(result.tracklets, result.owner, strict=True):
        if o < 0:
            continue
        owned += 1
        dist = {a: np.median(np.linalg.norm(_truth_at(xs, tr.t_ns) - tr.xy_m, axis=1)) for a, xs in truth.items()}
        assert min(dist, key=dist.get) == carriers[names[o]]  # the detections are the phone's carrier's
        assert dist[carriers[names[o]]] < 0.3
    assert owned >= 2
    for pr in result.people.values():
        assert pr.status == "corrected"
        assert pr.frame == "world"
        assert pr.correction.control_t_ns.size >= 3


def test_corrected_trajectories_beat_dead_reckoning(scene):
    recording, carriers, truth, result = scene
    for phone, pr in result.people.items():
        xs = truth[carriers[phone]]
        sel = pr.corrected
        assert sel.mean() > 0.9
        err = np.linalg.norm(pr.xy_m[sel] - _truth_at(xs, pr.t_ns[sel]), axis=1)
        # dead reckoning alone, started from the true start pose (the best a phone can do without fixes)
        with Recording(recording) as rec:
            imu = [m for m in rec.messages([f"/{phone}/imu"])]
        t = np.array([m.t_ns for m in imu], np.int64)
        pdr = run_pdr(t, np.array([m.accel_mps2 for m in imu]), np.array([m.gyro_radps for m in imu]),
                      start_m=xs[0, 1:3], heading0_rad=xs[0, 3])
        err_dr = np.linalg.norm(pdr.position_at(pr.t_ns[sel]) - _truth_at(xs, pr.t_ns[sel]), axis=1)
        assert err.mean() < err_dr.mean()
        assert err.mean() < 0.35
        # step count and distance against the simulator's heel strikes and path
        with open(recording / "ground_truth" / "steps.csv", newline="") as f:
            true_steps = sum(int(r["id"]) == carriers[phone] for r in csv.DictReader(f))
        assert abs(pr.step_count - true_steps) <= 2
        path = np.sum(np.linalg.norm(np.diff(xs[:, 1:3], axis=0), axis=1))
        assert pr.distance_m == pytest.approx(path, rel=0.35)


def test_lights_off_failures_are_detected_and_recovered(scene):
    recording, carriers, _truth, result = scene
    boxes = {}
    with open(recording / "ground_truth" / "camera_video_0.csv", newline="") as f:
        for r in csv.DictReader(f):
            boxes[(int(r["stamp_ns"]), int(r["id"]))] = [float(r[k]) for k in ("u_min", "v_min", "u_max", "v_max")]
    off, on = T0_NS + round(LIGHTS_OFF_S * 1e9), T0_NS + round(LIGHTS_ON_S * 1e9)
    inside, n_fail, n_recovered, tracked = [], 0, 0, 0
    for phone, pr in result.people.items():
        v = pr.boxes.get("video_0")
        if v is None or v.t_ns[0] > off or v.t_ns[-1] < on + 2e9:
            continue
        tracked += 1
        ev = [e for e in pr.events if e.attributes.get("camera") == "video_0"]
        fails = [e for e in ev if e.kind == "visual_failure" and off <= e.t_ns <= on + 1e9]
        n_fail += len(fails)
        n_recovered += sum(bool(e.attributes["recovered"]) for e in fails)
        for e in fails:  # a failure episode ends at a recovery event, or at the end of the track
            assert e.t_end_ns is not None
            assert e.attributes["recovered"] == any(r.kind == "visual_recovery" and r.t_ns == e.t_end_ns for r in ev)
        # the reported box stays on the person: reset onto the projected inertial position while failing
        window = (v.t_ns >= off) & (v.t_ns <= on + 3e9)
        centre = 0.5 * (v.box_px[window, :2] + v.box_px[window, 2:])
        truth_box = np.array([boxes[(int(t), carriers[phone])] for t in v.t_ns[window]])
        inside.append(np.all((centre >= truth_box[:, :2]) & (centre <= truth_box[:, 2:]), axis=1))
        # the criterion: within 1 s of the lights coming back the box overlaps the person's truth box at
        # IoU >= 0.5 on 3 consecutive frames
        back = (v.t_ns >= on) & (v.t_ns <= on + 1e9)
        tb = np.array([boxes.get((int(t), carriers[phone]), [np.nan] * 4) for t in v.t_ns[back]])
        b = v.box_px[back]
        iw = np.clip(np.minimum(b[:, 2], tb[:, 2]) - np.maximum(b[:, 0], tb[:, 0]), 0, None)
        ih = np.clip(np.minimum(b[:, 3], tb[:, 3]) - np.maximum(b[:, 1], tb[:, 1]), 0, None)
        union = np.prod(b[:, 2:] - b[:, :2], axis=1) + np.prod(tb[:, 2:] - tb[:, :2], axis=1) - iw * ih
        on_target = np.nan_to_num(iw * ih / union) >= 0.5
        assert np.any(np.convolve(on_target, np.ones(3), "valid") >= 3), (phone, np.round(iw * ih / union, 2))
    assert tracked >= 1
    assert n_fail >= 1  # the change of lighting is detected ...
    assert n_recovered >= 1  # ... and tracking recovers from it
    assert np.concatenate(inside).mean() > 0.7


def test_bad_input_degrades(scene, tmp_path):
    recording, carriers, truth, _ = scene
    rec = _edited_copy(recording, tmp_path / "bad", drop={"phone_a": (7.0, 9.0), "phone_b": (10.0, 99.0)},
                       blank={"rgbd_0": (10.0, 99.0)}, images=("video_0",))
    summary = run_wearable(rec, tmp_path / "out", cameras=["video_0"])
    a, b = summary["people"]["phone_a"], summary["people"]["phone_b"]
    assert a["imu_gaps"] == 1
    assert not a["phone_silent"]
    assert b["phone_silent"]
    blanked, frames = summary["rgbd"]["empty_depth_frames"]["rgbd_0"], summary["rgbd"]["depth_frames"]["rgbd_0"]
    assert 0.25 * frames < blanked < 0.35 * frames
    assert a["status"] == b["status"] == "corrected"
    events = read_jsonl(tmp_path / "out" / "events.jsonl")
    assert all(isinstance(e, Event) for e in events)
    gap = [e for e in events if e.kind == "imu_gap"]
    assert len(gap) == 1
    assert abs((gap[0].t_ns - T0_NS) * 1e-9 - 7.0) < 0.05
    assert abs(
        (gap[0].t_end_ns - T0_NS) * 1e-9 - 9.0) < 0.05
    silent = [e for e in events if e.kind == "phone_silent"]
    assert len(silent) == 1
    assert abs((silent[0].t_ns - T0_NS) * 1e-9 - 10.0) < 0.05
    with open(tmp_path / "out" / "trajectories.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    ta = np.array([(int(r["t_ns"]) - T0_NS) * 1e-9 for r in rows if r["phone"] == "phone_a"])
    rep_a = np.array([r["reporting"] == "1" for r in rows if r["phone"] == "phone_a"])
    assert not rep_a[(ta > 7.3) & (ta < 8.7)].any()
    assert rep_a[ta < 6.5].all()
    tb = np.array([(int(r["t_ns"]) - T0_NS) * 1e-9 for r in rows if r["phone"] == "phone_b"])
    assert tb.max() < 10.05  # the trajectory ends when the phone stops
    # the visual tracker of phone_b goes on without the inertial check once the phone is silent
    # visual trackers go on without the inertial check while a phone is silent: phone_a during its gap, phone_b
    # from 10 s on; never while it reports
    with open(tmp_path / "out" / "boxes.csv", newline="") as f:
        boxes = [(r["phone"], (int(r["t_ns"]) - T0_NS) * 1e-9, r["status"]) for r in csv.DictReader(f)]
    silent = [s for p, t, s in boxes if (p == "phone_a" and 7.3 < t < 8.7) or (p == "phone_b" and t > 10.3)]
    reporting = [s for p, t, s in boxes
                 if (p == "phone_a" and (t < 6.9 or 9.1 < t < 13.8)) or (p == "phone_b" and t < 9.9)]
    assert silent
    assert all(s == "no_inertial" for s in silent)
    assert reporting
    assert "no_inertial" not in reporting
    # after the IMU gap, the next RGB-D pass (rgbd_1) is still recognised as phone_a's and corrects it again
    xs = truth[carriers["phone_a"]]
    xy = np.array([(float(r["x_m"]), float(r["y_m"])) for r in rows if r["phone"] == "phone_a"])
    t_ns = np.array([int(r["t_ns"]) for r in rows if r["phone"] == "phone_a"])
    err = np.linalg.norm(xy - _truth_at(xs, t_ns), axis=1)
    refix = min((e.t_ns - T0_NS) * 1e-9 for e in events if e.kind == "rgbd_fixes" and e.attributes["phone"] == "phone_a"
                and (e.t_end_ns - T0_NS) * 1e-9 > 9.0)
    assert np.mean(err[ta < 7.0]) < 0.35
    assert np.mean(err[ta > max(refix, 9.0) + 0.5]) < 0.75
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["people"]["phone_a"]["imu_gaps"] == 1


def test_nobody_seen_by_rgbd_keeps_dead_reckoning_and_says_so(scene, tmp_path):
    recording, carriers, truth, _ = scene
    rec = _edited_copy(recording, tmp_path / "blind", blank={"all": (0.0, 99.0)})
    result = track_wearable(rec, WearableParams(visual=False))
    assert len(result.inputs.detections) == 0
    assert sum(result.inputs.empty_depth_frames.values()) == sum(result.inputs.depth_frames.values()) > 0
    for _phone, pr in result.people.items():
        assert pr.status == "dead_reckoning_only"
        assert pr.frame == "phone"
        assert not pr.corrected.any()
        assert pr.step_count > 5
        assert pr.t_ns.size > 100
        assert np.all(np.isfinite(pr.xy_m))
        assert any(e.kind == "never_seen_by_rgbd" for e in pr.events)
        assert not pr.boxes
    # a known start pose places the dead reckoning in the world, still uncorrected
    a = carriers["phone_a"]
    pose = (*truth[a][0, 1:3], truth[a][0, 3])
    placed = track_wearable(rec, WearableParams(visual=False, phones=("phone_a",), start_poses={"phone_a": pose}))
    pr = placed.people["phone_a"]
    assert pr.status == "start_pose"
    assert pr.frame == "world"
    assert not pr.corrected.any()
    assert np.mean(np.linalg.norm(pr.xy_m - _truth_at(truth[a], pr.t_ns), axis=1)) < 1.5


def test_options_are_checked():
    with pytest.raises(ConfigError, match="unknown option 'bogus'"):
        run_wearable("nowhere", "/tmp/never", bogus=1)
    with pytest.raises(ConfigError, match="depth_range_m"):
        WearableParams(depth_range_m=(4.0, 1.0))
    with pytest.raises(ConfigError, match="gate"):
        run_wearable("nowhere", "/tmp/never", gate=-1.0)


def test_cli_track_wearable_writes_each_phone_s_results(scene, tmp_path):
    """`fusiontrack track REC --pipeline wearable` as a user runs it: one row per phone, files written, and the
    step counts agree with the simulator's heel strikes of each carrier (within 2, as the library test)."""
    import json
    import subprocess
    import sys

    recording, carriers, _, _ = scene
    cfg = tmp_path / "w.toml"
    cfg.write_text('[wearable]\ncameras = ["video_0"]\n')
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "fusiontrack", "track", str(recording), "--pipeline", "wearable",
                        "-c", str(cfg), "-o", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["people"]) == set(carriers)
    steps: dict[int, int] = {}
    with open(recording / "ground_truth" / "steps.csv", newline="") as f:
        for row in csv.DictReader(f):
            steps[int(row["id"])] = steps.get(int(row["id"]), 0) + 1
    for phone, agent in carriers.items():
        assert abs(summary["people"][phone]["steps"] - steps[agent]) <= 2
    for name in ("trajectories.csv", "events.jsonl"):
        assert (out / name).stat().st_size > 0
    bad = tmp_path / "bad.toml"
    bad.write_text("[wearable]\nno_such_option = 1\n")
    r = subprocess.run([sys.executable, "-m", "fusiontrack", "track", str(recording), "--pipeline", "wearable",
                        "-c", str(bad), "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert "no_such_option" in r.stderr


def test_person_blob_takes_the_person_not_a_bystander():
    # hand-built boxes: a 200 px tall person predicted at u = 300..340 (0.4 x 1.75 m wide box), feet at row 300
    from fusiontrack.fusion.wearable_visual import VisualParams, _person_blob

    class Camera:
        size = (640, 480)

    p = VisualParams()
    pred = np.array([300.0, 100.0, 340.0, 300.0])
    none = np.zeros((0, 4))
    own = np.array([[305.0, 104.0, 333.0, 299.0]])
    bystander = np.array([[322.0, 102.0, 360.0, 299.0]])  # a person without a phone 21 px (~0.37 m) to the side
    ct_box = np.array([305.0, 100.0, 345.0, 300.0])  # the tracker's box covers both centres
    assert np.array_equal(_person_blob(Camera, own, pred, none, p, near=ct_box), own[0])
    assert _person_blob(Camera, bystander, pred, none, p, near=ct_box) is None
    both = np.vstack([bystander, own])
    assert np.array_equal(_person_blob(Camera, both, pred, none, p, near=ct_box), own[0])
    # two people side by side in one blob (wider than a person can be), or another carrier's predicted box on it
    assert _person_blob(Camera, np.array([[290.0, 104.0, 460.0, 299.0]]), pred, none, p, near=ct_box) is None
    assert _person_blob(Camera, own, pred, np.array([[310.0, 100.0, 350.0, 300.0]]), p, near=ct_box) is None
    # a blob whose feet are not where the person stands (another depth), or the head lost: extended up
    assert _person_blob(Camera, own - np.array([0.0, 60.0, 0.0, 60.0]), pred, none, p, near=ct_box) is None
    short = np.array([[305.0, 170.0, 333.0, 299.0]])
    assert np.allclose(_person_blob(Camera, short, pred, none, p, near=ct_box), [305.0, 99.0, 333.0, 299.0])


def test_an_imu_message_stamped_ahead_or_back_costs_itself(simulated, caplog):
    """In log order, one IMU message stamped 100 s ahead and one 1 s back (bad stamps): sorted as they came, the
    phone's trajectory ran to 103 s of a 10 s recording (or began 1 s early), without a word. As the CSV reader does,
    each costs itself, with a warning; the dead reckoning is the clean one's (the same steps, the same span)."""
    from fusiontrack.fusion.wearable_data import dead_reckon_phone

    path = simulated("wearable_crossing", seconds=16, seed=0)
    with Recording(path) as rec:
        samples = [m for m in rec.messages(["/phone_a/imu"]) if isinstance(m, ImuSample)]
    t = np.array([s.t_ns for s in samples], np.int64)
    accel = np.array([s.accel_mps2 for s in samples])
    gyro = np.array([s.gyro_radps for s in samples])
    clean = dead_reckon_phone("phone_a", t, accel, gyro)
    bad = t.copy()
    bad[900] += 100 * 10**9  # (9 s and 12 s in: the phone's carrier walks)
    bad[1200] -= 10**9
    with caplog.at_level("WARNING"):
        got = dead_reckon_phone("phone_a", bad, accel, gyro)
    assert "phone phone_a: dropped 2 IMU message(s) stamped out of order" in caplog.text
    assert got.n_samples == clean.n_samples - 2
    assert (got.t_ns[0], got.t_ns[-1]) == (clean.t_ns[0], clean.t_ns[-1])
    assert got.pdr.n_steps == clean.pdr.n_steps
    assert clean.pdr.n_steps > 5

