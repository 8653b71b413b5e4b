"""The camera path end to end: the real PETS 2009 S2.L1 video (against the MOT15 public detections) and a
simulated `crossing` (against the simulator's per-pixel labels and boxes)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fusiontrack.io.recording import Recording
from fusiontrack.io.video import VideoReader
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.vision import BlobTracker, ForegroundModel, blob_histograms, extract_blobs


def _inside(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """``(n_points,)`` bool: the point lies in at least one box ``(u_min, v_min, u_max, v_max)``."""
    if len(boxes) == 0:
        return np.zeros(len(points), bool)
    p = points[:, None, :]
    return ((boxes[None, :, :2] <= p) & (p <= boxes[None, :, 2:])).all(axis=2).any(axis=1)


@pytest.fixture(scope="module")
def pets(shared_data: Path) -> dict:
    folder = shared_data / "video" / "pets09_s2l1"
    det = np.loadtxt(folder / "PETS09-S2L1_det_MOT15.txt", delimiter=",")
    model, tracker = ForegroundModel(), BlobTracker()
    coverage, stray, n_blobs, n_dets, n_objects, duplicates = [], [], [], [], [], 0
    for i, image in enumerate(VideoReader(folder / "vtest_pets09_s2l1_480x360.avi")):
        fg = model.apply(image)
        blobs = extract_blobs(fg.mask)
        objects = tracker.step(blobs, blob_histograms(image.bgr(), blobs), image.t_ns)
        ids = [o.object_id for o in objects]
        duplicates += len(ids) - len(set(ids))
        if i < 100:  # MOG2's start-up and A2's warm-up
            continue
        d = det[det[:, 0] == i + 1]
        boxes = d[:, 2:6] * 0.625  # MOT15 boxes are in the original 768x576 pixels
        boxes[:, 2:] += boxes[:, :2]
        for u0, v0, u1, v1 in np.clip(np.round(boxes).astype(int), 0, [480, 360, 480, 360]):
            coverage.append(fg.mask[v0:v1, u0:u1].mean() if u1 > u0 and v1 > v0 else 0.0)
        stray += list(~_inside(blobs.centroids_px, boxes))
        n_blobs.append(len(blobs))
        n_dets.append(len(d))
        n_objects.append(len(objects))
    return {"coverage": np.array(coverage), "stray": np.array(stray), "blobs": np.array(n_blobs),
            "dets": np.array(n_dets), "objects": np.array(n_objects), "duplicates": duplicates,
            "illumination": model.n_illumination_events}


def test_pets_people_are_foreground(pets):
    # an independent detector's boxes (MOT15 public DPM detections) contain our object pixels
    assert len(pets["coverage"]) > 3000
    assert (pets["coverage"] >= 0.2).mean() >= 0.95
    assert pets["illumination"] == 0


def test_pets_blobs_are_people(pets):
    assert pets["stray"].mean() <= 0.10  # blob centroids outside every detection box
    ratio = pets["blobs"].mean() / pets["dets"].mean()
    assert 0.7 <= ratio <= 1.1  # fewer blobs than people where people walk in groups


def test_pets_tracker_runs_and_reports_each_object_once(pets):
    assert pets["duplicates"] == 0
    assert 0.6 <= pets["objects"].mean() / pets["dets"].mean() <= 1.3


@pytest.fixture(scope="module")
def crossing(tmp_path_factory: pytest.TempPathFactory) -> dict:
    out = tmp_path_factory.mktemp("vision") / "crossing"
    simulate(load_scenario("crossing").with_overrides(seconds=6, seed=0), out)
    with Recording(out) as rec:
        images = list(rec.messages(["/camera_0/image"]))
        labels = list(rec.messages(["/camera_0/labels"]))
        truth = list(rec.messages(["/ground_truth/camera_0"]))
    model = ForegroundModel()
    tp = fp = fn = hit = visible = 0
    for k, (image, label, gt) in enumerate(zip(images, labels, truth, strict=True)):
        fg = model.apply(image)
        blobs = extract_blobs(fg.mask)
        if k < 15:
            continue
        person = label.pixels > 0
        tp += int(np.count_nonzero(fg.mask & person))
        fp += int(np.count_nonzero(fg.mask & ~person))
        fn += int(np.count_nonzero(~fg.mask & person))
        boxes = gt.attributes["box_px"][gt.attributes["visibility"] > 0.5]
        visible += len(boxes)
        centres = np.column_stack([(boxes[:, 0] + boxes[:, 2]) / 2, (boxes[:, 1] + boxes[:, 3]) / 2])
        hit += int(_inside(centres, blobs.boxes_px).sum())
    return {"precision": tp / (tp + fp), "recall": tp / (tp + fn), "box_recall": hit / visible}


def test_simulated_foreground_against_labels(crossing):
    assert crossing["precision"] >= 0.95  # shadows (never labelled as the agent) are removed by A3
    assert crossing["recall"] >= 0.65  # A3 also takes grey clothes on a grey floor for shadow
    assert crossing["box_recall"] >= 0.9  # the centre of each visible person's true box lies in a blob
