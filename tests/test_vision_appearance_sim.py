"""Seed 001's online appearance classifiers on a simulated `crossing` (ALGORITHMS.md B12-B17).

Three differently dressed people cross a hall (10 s, seed 0). The bank learns people 0 and 1 from their true
boxes in frames 40-98 (every other frame, 30 frames) while they are apart (negatives: the other people's boxes,
B15) and is judged on frames 100-124, never trained on, when they meet in the middle of the image, seen from
another angle. Truth is the simulator's: its boxes say who is where and its per-pixel labels say which patches
show the person. Single patches are judged only where at least half their pixels are that person (a patch of
floor seen through a box has no identity). Online learning from a few frames is noisy (one bank's curve can dip
by a few points between checkpoints), so the learning curve is averaged over three banks with different random
streams.

People 0 and 1 are each other's confusers from the first training frame; person 2 walks in only at the 14th
(negatives of both classifiers from then on). The learning curve is therefore read on the pair 0/1 from the
first frame, and on every person once each has been seen: how a classifier ranks a person it was never shown
is luck, not learning.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from sklearn.metrics import roc_auc_score

from fusiontrack.io.recording import Recording
from fusiontrack.vision.appearance import AppearanceBank, assign_identities
from fusiontrack.vision.patches import extract_features, patch_fraction, sample_patches

TRAIN = range(40, 100, 2)
TEST = range(100, 125)
CHECKPOINTS = (1, 5, 15, 20, 30)
PEOPLE = (0, 1)
SEEDS = (0, 1, 2)


def _boxes(gt) -> dict[int, np.ndarray]:
    """Boxes of the people at least half visible in a frame."""
    box, vis = gt.attributes["box_px"], gt.attributes["visibility"]
    return {int(i): box[j] for j, i in enumerate(gt.ids) if vis[j] > 0.5}


@pytest.fixture(scope="module")
def crossing(simulated) -> dict:
    out: Path = simulated("crossing", seconds=10, seed=0)  # the recording test_vision_people.py's crossing uses
    with Recording(out) as rec:
        images = [m.bgr() for m in rec.messages(["/camera_0/image"])]
        labels = [m.pixels for m in rec.messages(["/camera_0/labels"])]
        truth = [_boxes(m) for m in rec.messages(["/ground_truth/camera_0"])]
    # held-out patches, drawn once with their own generator; on_person: >= half the pixels are that person's
    rng = np.random.default_rng(100)
    held_out = []
    for k in TEST:
        for tid, box in truth[k].items():
            p = sample_patches(box, images[k].shape, rng=rng)
            held_out.append((tid, extract_features(images[k], p), patch_fraction(labels[k] == tid + 1, p) >= 0.5))
    # training frames after which every person of the held-out frames has been shown to the bank
    shown = {tid for tid, _, _ in held_out}
    all_seen = next(n for n, k in enumerate(TRAIN, 1) if shown <= set().union(*(truth[j] for j in TRAIN[:n])))
    banks, curves = {}, {}  # curves[seed][n][person][negatives] = metrics after n training frames
    for seed in SEEDS:
        bank = banks[seed] = AppearanceBank(rng=seed)
        curves[seed] = {}
        for n, k in enumerate(TRAIN, 1):
            bank.train(images[k], truth[k], train_ids=[i for i in PEOPLE if i in truth[k]])
            if n in CHECKPOINTS:
                curves[seed][n] = {tid: {"all": _evaluate(bank, tid, held_out),
                                         "pair": _evaluate(bank, tid, [h for h in held_out if h[0] in PEOPLE])}
                                   for tid in PEOPLE}
    return {"images": images, "truth": truth, "banks": banks, "curves": curves, "all_seen": all_seen}


def _mean(crossing: dict, n: int, key: str, negatives: str = "all") -> float:
    """A metric after ``n`` training frames, averaged over the banks and both people; ``negatives``: every other
    person ("all") or only the other one of the pair 0/1 ("pair")."""
    return float(np.mean([crossing["curves"][s][n][tid][negatives][key] for s in SEEDS for tid in PEOPLE]))


def _evaluate(bank: AppearanceBank, tid: int, held_out: list) -> dict[str, float]:
    conf = [bank.confidences(f, [tid])[0] for _, f, _ in held_out]
    own = np.array([t == tid for t, _, _ in held_out])
    patch_own = np.concatenate([np.full(len(c), o) for c, o in zip(conf, own, strict=True)])
    on = np.concatenate([o for _, _, o in held_out])
    c = np.concatenate(conf)
    return {
        "box_auc": roc_auc_score(own, [x.mean() for x in conf]),  # mean confidence of a box's patches (B17)
        "patch_auc": roc_auc_score(patch_own[on], c[on]),  # single patches that show a person
        "margin": c[on & patch_own].mean() - c[on & ~patch_own].mean(),
    }


def test_classifier_separates_differently_dressed_people_on_unseen_frames(crossing):
    for seed in SEEDS:
        for tid in PEOPLE:
            final = crossing["curves"][seed][30][tid]["all"]
            assert final["box_auc"] >= 0.95, (seed, tid, final)  # every bank, every person
            assert final["patch_auc"] >= 0.9, (seed, tid, final)
    assert _mean(crossing, 20, "box_auc") >= 0.95
    assert _mean(crossing, 30, "patch_auc") >= 0.95  # single patches on the person (floor patches excluded)


def test_more_samples_do_not_degrade_the_classifiers(crossing):
    for key in ("box_auc", "patch_auc"):  # the pair, learnt against each other from the first frame
        curve = [_mean(crossing, n, key, "pair") for n in CHECKPOINTS]
        assert all(b >= a - 0.005 for a, b in itertools.pairwise(curve)), (key, curve)
    # misranked pairs of patches (1 - AUC) at least halve from one training frame to thirty
    assert 1 - _mean(crossing, 30, "patch_auc", "pair") <= 0.5 * (1 - _mean(crossing, 1, "patch_auc", "pair"))
    seen = [n for n in CHECKPOINTS if n > crossing["all_seen"]]
    assert len(seen) >= 2  # the last checkpoints come after everyone has been shown
    for key in ("box_auc", "patch_auc", "margin"):  # everyone, once everyone has been shown
        curve = [_mean(crossing, n, key) for n in seen]
        assert all(b >= a - 0.005 for a, b in itertools.pairwise(curve)), (key, curve)
    assert _mean(crossing, 30, "margin") > _mean(crossing, seen[0], "margin")


def test_unknown_boxes_are_given_the_right_identity(crossing):
    images, truth = crossing["images"], crossing["truth"]
    single = []
    for bank in crossing["banks"].values():
        right = joint = 0
        for k in TEST:
            boxes = np.array([truth[k][i] for i in PEOPLE])
            right += sum(bank.identify(images[k], boxes[j], PEOPLE, min_score=-1.0)[0] == PEOPLE[j] for j in range(2))
            joint += assign_identities(bank.box_scores(images[k], boxes, PEOPLE), min_score=-1.0) == [(0, 0), (1, 1)]
        single.append(right / (2 * len(TEST)))
        assert joint >= 0.95 * len(TEST)  # B17's split: Hungarian assignment of both boxes at once
    assert np.mean(single) >= 0.9  # each box on its own: the best mean confidence


def test_score_map_favours_each_targets_own_box(crossing):
    images, truth = crossing["images"], crossing["truth"]
    right = total = 0
    for bank in crossing["banks"].values():
        for k in TEST:
            boxes = np.array([truth[k][i] for i in PEOPLE])
            sm = bank.score_map(images[k], PEOPLE, boxes_px=boxes)  # B16: 300 patches in the interacting region
            centres = (boxes[:, :2] + boxes[:, 2:]) / 2
            like = sm.likelihood(np.stack([centres, centres]))  # (target, candidate centre)
            right += int(like[0, 0] > like[0, 1]) + int(like[1, 1] > like[1, 0])
            total += 2
    assert right >= 0.8 * total
