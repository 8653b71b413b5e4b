"""`fusiontrack eval` on image boxes: people-camera output against a simulated camera's truth boxes (IoU >= 0.5)."""

from __future__ import annotations

import importlib.util
import json
import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fusiontrack.cli import app
from fusiontrack.eval import evaluate_boxes
from fusiontrack.eval.mot import evaluate_camera_boxes
from fusiontrack.io.recording import Recording
from fusiontrack.io.tracks import write_jsonl, write_mot
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.types import GroundTruth, TrackState
from fusiontrack.vision import camera_truth_boxes, track_camera

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "camera_people.py"
runner = CliRunner()


@pytest.fixture(scope="module")
def rec(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("image_boxes") / "crossing"
    simulate(load_scenario("crossing").with_overrides(seconds=10, seed=1), out)
    return out


@pytest.fixture(scope="module")
def truth(rec) -> tuple[list[GroundTruth], int, int]:
    with Recording(rec) as r:
        frames = list(r.messages(["/ground_truth/camera_0"]))
        info = next(iter(r.messages(["/camera_0/camera_info"])))
    return frames, info.width, info.height


def truth_states(frames: list[GroundTruth], width: int, height: int, shift: float = 0.0) -> list[TrackState]:
    """One state per agent per image with its truth box (clipped to the image), moved right by ``shift`` widths."""
    out = []
    for g in frames:
        box = np.clip(np.asarray(g.attributes["box_px"], float), 0, [width, height, width, height])
        for i, b in zip(g.ids, box, strict=True):
            w = b[2] - b[0]
            if not np.all(np.isfinite(b)) or w < 1 or b[3] - b[1] < 1:
                continue
            out.append(TrackState(g.t_ns, "camera_0", int(i) + 100, np.full(2, np.nan),
                                  box_px=b + shift * np.array([w, 0, w, 0]), camera="camera_0"))
    return out


def visible_people(frames: list[GroundTruth], width: int, height: int) -> int:
    """(image, agent) pairs that count: at least half visible, a box of at least 1 px inside the image."""
    n = 0
    for g in frames:
        box = np.clip(np.asarray(g.attributes["box_px"], float), 0, [width, height, width, height])
        ok = np.all(np.isfinite(box), axis=1) & (box[:, 2] - box[:, 0] >= 1) & (box[:, 3] - box[:, 1] >= 1)
        n += int(np.count_nonzero(ok & (np.asarray(g.attributes["visibility"]) >= 0.5)))
    return n


def write_output(folder: Path, states: list[TrackState], frames: list[GroundTruth]) -> Path:
    """What `track --pipeline people-camera` writes (the files eval reads)."""
    folder.mkdir(parents=True, exist_ok=True)
    write_jsonl(folder / "tracks.jsonl", states)
    write_mot(folder / "tracks_mot.txt", states, frame_of={g.t_ns: k + 1 for k, g in enumerate(frames)})
    return folder


def cli_eval(*args: str) -> dict:
    out = Path(args[0]).parent / f"{Path(args[0]).name}_metrics.json"
    result = runner.invoke(app, ["eval", *args, "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "MOTA" in result.output
    return json.loads(out.read_text())


def test_perfect_boxes_score_one(truth, rec, tmp_path):
    frames, w, h = truth
    states = truth_states(frames, w, h)
    n = visible_people(frames, w, h)
    assert n > 50
    m = evaluate_camera_boxes(frames, states, w, h)
    assert (m.mota, m.idf1, m.num_gt_dets, m.fn, m.fp, m.id_switches) == (1.0, 1.0, n, 0, 0, 0)
    folder = write_output(tmp_path / "perfect", states, frames)
    out = cli_eval(str(folder), str(rec))  # auto-detected: a people-camera folder of camera_0
    assert out["camera"] == "camera_0"
    assert (out["metrics"]["mota"], out["metrics"]["idf1"], out["metrics"]["num_gt_dets"]) == (1.0, 1.0, n)
    out = cli_eval(str(folder / "tracks_mot.txt"), str(rec), "--camera", "camera_0")  # frame-numbered rows
    assert (out["metrics"]["mota"], out["metrics"]["idf1"]) == (1.0, 1.0)


def test_shifted_boxes_are_misses_and_false_positives(truth):
    frames, w, h = truth
    n = visible_people(frames, w, h)
    m = evaluate_camera_boxes(frames, truth_states(frames, w, h, shift=0.6), w, h)  # own IoU 0.25
    assert m.mota <= 0.0
    far = truth_states(frames, w, h, shift=50.0)  # nowhere near anyone
    m = evaluate_camera_boxes(frames, far, w, h)
    assert (m.tp, m.fn, m.fp, m.idf1) == (0, n, len(far), 0.0)
    assert m.mota == pytest.approx(1 - (n + len(far)) / n)


def test_cli_eval_matches_the_benchmark_on_a_real_people_camera_run(rec, tmp_path):
    out_dir = tmp_path / "tracked"
    result = runner.invoke(app, ["track", str(rec), "--pipeline", "people-camera", "--camera-topic",
                                 "/camera_0/image", "--no-video", "-o", str(out_dir)])
    assert result.exit_code == 0, result.output
    auto = cli_eval(str(out_dir), str(rec))
    named = cli_eval(str(out_dir / "tracks_mot.txt"), str(rec), "--camera", "camera_0")
    # benchmarks/camera_people.py's scoring of the same tracker on the same recording
    spec = importlib.util.spec_from_file_location("camera_people_bench", BENCH)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    with Recording(rec) as r:
        gt_frames = list(r.messages(["/ground_truth/camera_0"]))
    states, _, stats = track_camera(rec, camera_topic="/camera_0/image")
    frame_of = stats.frame_of()
    gt = camera_truth_boxes(gt_frames, stats.width, stats.height, frames=[frame_of[g.t_ns] for g in gt_frames])
    ref = evaluate_boxes(gt, bench.mot_rows(bench.state_rows(states, frame_of)), preprocess=True,
                         n_frames=stats.n_frames)
    assert min(ref.num_gt_dets, ref.tp) > 0
    for out in (auto, named):
        got = out["metrics"]
        assert (got["mota"], got["idf1"], got["tp"], got["fp"], got["fn"], got["id_switches"]) == \
            (ref.mota, ref.idf1, ref.tp, ref.fp, ref.fn, ref.id_switches)


def test_bad_inputs(truth, rec, tmp_path):
    frames, w, h = truth
    result = runner.invoke(app, ["eval", str(tmp_path / "none.csv"), str(rec), "--camera", "camera_0"])
    assert result.exit_code != 0
    folder = write_output(tmp_path / "x", truth_states(frames[:5], w, h), frames[:5])
    result = runner.invoke(app, ["eval", str(folder), str(rec), "--camera", "camera_9"])
    assert result.exit_code != 0
    assert "camera_9" in str(result.exception) + result.output
    with pytest.raises(Exception, match="ground-truth record"):
        evaluate_camera_boxes([], [], w, h)
    empty = evaluate_camera_boxes(frames, [], w, h)  # no tracks: all misses, no crash
    assert (empty.tp, empty.fn) == (0, visible_people(frames, w, h))


def test_only_the_named_cameras_states_are_scored(truth, rec, tmp_path):
    """Boxes of another camera (here: nowhere near anyone in camera_0's image) are not camera_0's false positives;
    states with an empty camera field count as the named camera."""
    frames, w, h = truth
    n = visible_people(frames, w, h)
    own = truth_states(frames, w, h)
    other = [replace(s, camera="camera_1", sensor="camera_1", track_id=s.track_id + 1000)
             for s in truth_states(frames, w, h, shift=50.0)]
    unnamed = [replace(s, camera="") for s in own]
    for states in (own + other, unnamed + other):
        m = evaluate_camera_boxes(frames, states, w, h, camera="camera_0")
        assert (m.mota, m.idf1, m.num_gt_dets, m.fp) == (1.0, 1.0, n, 0)
    folder = write_output(tmp_path / "two_cameras", own + other, frames)
    out = cli_eval(str(folder / "tracks.jsonl"), str(rec), "--camera", "camera_0")
    assert (out["metrics"]["mota"], out["metrics"]["fp"]) == (1.0, 0)


def test_one_state_per_track_and_frame_the_nearest_in_time(truth):
    """A track with two states near one image (a tracker faster than the camera) is scored by the nearer one:
    the truth box at the image's time wins over a wrong box 20 ms later, in either order."""
    frames, w, h = truth
    n = visible_people(frames, w, h)
    own = truth_states(frames, w, h)
    late = [replace(s, t_ns=s.t_ns + 20_000_000, box_px=s.box_px + 300.0) for s in own]
    for states in (own + late, late + own):
        m = evaluate_camera_boxes(frames, states, w, h, camera="camera_0")
        assert (m.mota, m.idf1, m.num_gt_dets, m.fp) == (1.0, 1.0, n, 0)


def test_states_far_from_every_image_are_warned_about(truth, caplog):
    """States outside the time tolerance are not scored; more than 5 % of them is a warning naming the count."""
    frames, w, h = truth
    own = truth_states(frames, w, h)
    after_end = [replace(s, t_ns=s.t_ns + 60_000_000_000) for s in own]  # a minute after the last image
    few, many = after_end[: len(own) // 100], after_end[: len(own) // 5]
    with caplog.at_level(logging.DEBUG, logger="fusiontrack.eval.mot"):
        m = evaluate_camera_boxes(frames, own + few, w, h)
    assert (m.mota, m.fp) == (1.0, 0)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="fusiontrack.eval.mot"):
        m = evaluate_camera_boxes(frames, own + many, w, h)
    assert (m.mota, m.fp) == (1.0, 0)
    assert any(f"{len(many)} of {len(own) + len(many)} states" in r.getMessage() for r in caplog.records)


def test_no_image_boxes_score_as_misses_with_a_warning_naming_the_file(truth, rec, tmp_path, caplog):
    """An empty tracks.jsonl scored against a camera's truth boxes: every box missed, and a warning says why."""
    frames, w, h = truth
    (tmp_path / "none").mkdir()
    (tmp_path / "none" / "tracks.jsonl").write_text("")
    with caplog.at_level(logging.WARNING, logger="fusiontrack"):
        out = cli_eval(str(tmp_path / "none"), str(rec), "--camera", "camera_0")
    assert (out["metrics"]["tp"], out["metrics"]["fn"]) == (0, visible_people(frames, w, h))
    assert any(f"no track states with image boxes in {tmp_path / 'none' / 'tracks.jsonl'}" in r.getMessage()
               for r in caplog.records)

def test_mot_rows_without_camera_take_it_from_the_tracks_beside_them(truth, rec, tmp_path):
    frames, w, h = truth
    folder = write_output(tmp_path / "mot", truth_states(frames, w, h), frames)
    out = cli_eval(str(folder / "tracks_mot.txt"), str(rec))  # camera_0, from tracks.jsonl
    assert out["camera"] == "camera_0"
    assert (out["metrics"]["mota"], out["metrics"]["idf1"]) == (1.0, 1.0)
    (folder / "tracks.jsonl").unlink()
    result = runner.invoke(app, ["eval", str(folder / "tracks_mot.txt"), str(rec)])
    assert result.exit_code != 0
    message = str(result.exception) + result.output
    assert "--camera" in message
    assert "is a folder" not in message
