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
