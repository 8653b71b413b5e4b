"""Scanner poses given by the user (a pipeline file's ``[sensors.<name>] pose``) place the scanners of a recording
that has no /tf_static, as the recording's own /tf_static would."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.eval import evaluate_floor
from fusiontrack.io.recording import LASERSCAN, Recording
from fusiontrack.io.tracks import read_jsonl
from fusiontrack.io.writer import RecordingWriter
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import Simulation
from fusiontrack.tracking import track_recording
from fusiontrack.types import TrackState

SECONDS = 8.0


@pytest.fixture(scope="module")
def crowd(simulated, tmp_path_factory):
    """The first 8 s of the 20 s crowd, written twice: with its /tf_static and without it."""
    scenario = load_scenario("crowd").with_overrides(seconds=20, seed=1, settings={"cameras": []})
    path = simulated("crowd", seconds=20, seed=1, settings={"cameras": []})
    out = tmp_path_factory.mktemp("poses")
    with Recording(path) as rec:
        lasers = [t for t, i in rec.topics().items() if i.msgtype == LASERSCAN]
        t_end = min(i.t_start_ns for i in rec.topics().values()) + round(SECONDS * 1e9)
        for name, topics in (("with_tf", [*lasers, "/ground_truth", "/tf_static"]),
                             ("without_tf", [*lasers, "/ground_truth"])):
            with RecordingWriter(out / name) as writer:
                writer.write_all(m for m in rec.messages(topics) if m.t_ns <= t_end)
        gt = [g for g in rec.messages(["/ground_truth"]) if g.t_ns <= t_end]
    bounds = Simulation(scenario).world.bounds_m
    corrections = {c.name: -round(c.clock_offset_ms * 1e6) for c in scenario.config.lasers}
    return out, scenario, lasers, bounds, corrections, gt


def _toml(scenario, lasers) -> str:
    lines = []
    for laser in scenario.config.lasers:
        topic = next(t for t in lasers if t.startswith(f"/{laser.name}/"))
        lines += [f"[sensors.{laser.name}]", 'kind = "laser"', f'topic = "{topic}"',
                  f"pose = {{ x = {laser.x_m}, y = {laser.y_m}, z = {laser.height_m}, yaw_deg = {laser.yaw_deg} }}",
                  ""]
    return "\n".join(lines)


def test_pipeline_file_poses_place_scanners_as_tf_static_does(crowd, tmp_path):
    out, scenario, lasers, bounds, corrections, gt = crowd
    ref, _ = track_recording(out / "with_tf", params={"lateral_m": 0.2}, area_m=bounds,
                             clock_corrections_ns=corrections)
    assert evaluate_floor(gt, ref, 0.5).mota > 0.6  # the recording's own poses track the crowd
    # the command line, the scanners posed by the pipeline file (the scenario's poses, as a user would measure them)
    (tmp_path / "p.toml").write_text(_toml(scenario, lasers) + "[tracking]\nlateral_m = 0.2\n")
    area = ",".join(str(v) for v in np.asarray(bounds).ravel()[[0, 1, 2, 3]])
    clock = {laser.name: laser.clock_offset_ms for laser in scenario.config.lasers}
    text = (tmp_path / "p.toml").read_text()
    for name, ms in clock.items():  # the scanners' clock offsets too, as the simulator's truth gives them
        text = text.replace(f"[sensors.{name}]\n", f"[sensors.{name}]\nclock_offset_ms = {ms}\n")
    (tmp_path / "p.toml").write_text(text)
    result = subprocess.run([sys.executable, "-m", "fusiontrack", "track", str(out / "without_tf"), "-c",
                             str(tmp_path / "p.toml"), "--area", area, "--no-video", "-o", str(tmp_path / "t")],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert "world origin" not in result.stderr  # posed: no warning
    states = [r for r in read_jsonl(tmp_path / "t" / "tracks.jsonl") if isinstance(r, TrackState)]
    assert len(states) == len(ref)
    np.testing.assert_allclose([s.position_m for s in states], [s.position_m for s in ref], atol=1e-6)
    # without poses both scanners sit at the origin: a different (and wrong) picture
    bare, _ = track_recording(out / "without_tf", params={"lateral_m": 0.2}, area_m=bounds,
                              clock_corrections_ns=corrections)
    assert evaluate_floor(gt, bare, 0.5).mota < 0.3


def test_bad_given_poses_are_named(crowd):
    out, *_ = crowd
    with Recording(out / "without_tf") as rec:
        topic = next(t for t, i in rec.topics().items() if i.msgtype == LASERSCAN)
        sensor = rec.sensor_of(topic)  # the scanner's name in the recording
    with pytest.raises(ConfigError, match=rf"laser_poses\['{sensor}'\]: expected a finite \(3, 3\)"):
        track_recording(out / "without_tf", laser_poses={topic: np.eye(2)})


def test_convert_writes_the_pipeline_file_poses_as_tf_static(crowd, tmp_path):
    """A recording converted with a pipeline file carries its poses: tracked without the file, it gives the tracks
    of the recording's own /tf_static."""
    out, scenario, lasers, bounds, corrections, _gt = crowd
    (tmp_path / "p.toml").write_text(_toml(scenario, lasers))
    result = subprocess.run([sys.executable, "-m", "fusiontrack", "convert", str(out / "without_tf"), "-c",
                             str(tmp_path / "p.toml"), "-o", str(tmp_path / "posed")],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    with Recording(out / "with_tf") as rec:
        truth = {tf.child_frame: tf for tf in rec.messages(["/tf_static"])}
    with Recording(tmp_path / "posed") as rec:
        written = list(rec.messages(["/tf_static"]))
        frames = {s.frame_id for s in rec.messages(lasers)}
    assert sorted(tf.child_frame for tf in written) == sorted(frames)  # one per scanner, the frame its scans name
    for tf in written:
        assert tf.parent_frame == truth[tf.child_frame].parent_frame == "world"
        np.testing.assert_allclose(tf.translation_m[:2], truth[tf.child_frame].translation_m[:2], atol=1e-9)
    ref, _ = track_recording(out / "with_tf", params={"lateral_m": 0.2}, area_m=bounds,
                             clock_corrections_ns=corrections)
    posed, _ = track_recording(tmp_path / "posed", params={"lateral_m": 0.2}, area_m=bounds,
                               clock_corrections_ns=corrections)
    assert len(posed) == len(ref)
    np.testing.assert_allclose([s.position_m for s in posed], [s.position_m for s in ref], atol=1e-6)


def test_convert_puts_the_pipeline_file_pose_in_place_of_the_recording_s_own(crowd, tmp_path):
    out, scenario, lasers, *_ = crowd
    laser = scenario.config.lasers[0]
    first, *others = _toml(scenario, lasers).split("[sensors.")[1:]
    assert first.startswith(f"{laser.name}]")
    moved = first.replace(f"x = {laser.x_m},", f"x = {laser.x_m + 1.0},")
    (tmp_path / "p.toml").write_text("".join("[sensors." + part for part in (moved, *others)))
    result = subprocess.run([sys.executable, "-m", "fusiontrack", "convert", str(out / "with_tf"), "-c",
                             str(tmp_path / "p.toml"), "-o", str(tmp_path / "moved")],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    with Recording(out / "with_tf") as rec:
        before = list(rec.messages(["/tf_static"]))
        frame = next(s.frame_id for s in rec.messages([lasers[0]]))
    with Recording(tmp_path / "moved") as rec:
        after = list(rec.messages(["/tf_static"]))
    assert [tf.child_frame for tf in after].count(frame) == 1
    (moved,) = [tf for tf in after if tf.child_frame == frame]
    (own,) = [tf for tf in before if tf.child_frame == frame]
    np.testing.assert_allclose(moved.translation_m[:2], own.translation_m[:2] + np.array([1.0, 0.0]), atol=1e-9)
    # every other transform (the second scanner, the cameras' frames) is kept as it was
    assert sorted(tf.child_frame for tf in after if tf.child_frame != frame) == \
        sorted(tf.child_frame for tf in before if tf.child_frame != frame)
