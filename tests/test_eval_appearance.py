"""Seed 001's classifiers on a real video (fusiontrack.eval.appearance): PETS 2009 S2.L1 with MOTChallenge's public
detections, identities from unambiguous box continuity (no annotated identities needed); and that continuity's
tracklets on hand-built boxes whose story is known."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from fusiontrack.eval.appearance import iou_tracklets, neighbour_evidence
from fusiontrack.io.tracks import read_mot
from fusiontrack.io.video import VideoReader


def _walk(x0: float, vx: float, n: int, y: float = 50.0) -> np.ndarray:
    """Boxes 20 x 50 px of one person walking ``vx`` px per frame, (n, 4)."""
    x = x0 + vx * np.arange(n)
    return np.column_stack([x, np.full(n, y), x + 20, np.full(n, y + 50)])


def test_tracklets_follow_clear_paths_and_never_join_two_people():
    # two people walk towards each other along one line, meet at frame 10 and pass; a third walks alone, unseen in
    # frame 5 (a missed detection starts a new tracklet)
    n = 21
    a, b, c = _walk(0.0, 4.0, n), _walk(80.0, -4.0, n), _walk(300.0, 2.0, n, y=200.0)
    frame, boxes, who = [], [], []
    for k in range(n):
        for p, bx in enumerate((a, b, c)):
            if p == 2 and k == 5:
                continue
            frame.append(k)
            boxes.append(bx[k])
            who.append(p)
    frame, who = np.array(frame), np.array(who)
    rng = np.random.default_rng(0)
    perm = rng.permutation(len(frame))  # rows in any order
    ids = np.empty(len(frame), np.int64)
    ids[perm] = iou_tracklets(frame[perm], np.array(boxes)[perm])
    # no tracklet holds two people
    for t in np.unique(ids):
        assert np.unique(who[ids == t]).size == 1
    # the lone walker: one tracklet before the missed frame, one after
    assert np.unique(ids[who == 2]).size == 2
    # the two who pass each other: continuous while apart, cut where their boxes overlap
    for p in (0, 1):
        first = ids[(who == p) & (frame < 7)]
        assert np.unique(first).size == 1
        assert np.unique(ids[who == p]).size > 1


def test_bad_tracklet_settings_are_refused():
    with pytest.raises(ValueError, match="min_iou"):
        iou_tracklets(np.zeros(1), np.zeros((1, 4)), min_iou=0.0)
    with pytest.raises(ValueError, match="as many rows"):
        iou_tracklets(np.zeros(2), np.zeros((1, 4)))


def test_the_classifiers_tell_real_pedestrians_from_their_neighbours(shared_data):
    """PETS09 S2.L1 (480 x 360, people about 20 x 45 px): over 795 frames, test then train as the fused tracker
    learns. Each classifier scores its own person above a neighbour far more often than chance (1 in 2), and an
    identity check asked after three images would have exchanged hardly any pair that was never exchanged."""
    folder = shared_data / "video" / "pets09_s2l1"
    det = read_mot(folder / "PETS09-S2L1_det_MOT15.txt").scaled(0.625)  # (768 x 576 -> 480 x 360)

    def frames() -> Iterator[tuple[int, np.ndarray]]:
        with VideoReader(folder / "vtest_pets09_s2l1_480x360.avi", "camera", fps=7.0) as video:
            for k, img in enumerate(video, start=1):  # MOT frames count from 1
                yield k, img.pixels

    ne = neighbour_evidence(frames(), det)
    assert ne.evidence.size > 500  # (people do meet in this video: the classifiers are asked often)
    assert ne.right_sign() > 0.8
    v = ne.verdicts(n=3, margin=0.6)
    decided = v["keep"] + v["exchange"]
    assert decided > 30
    assert v["exchange"] <= 0.05 * decided
    assert np.all(np.abs(ne.evidence) <= 2.0)
