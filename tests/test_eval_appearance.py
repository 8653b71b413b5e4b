"""Seed 001's classifiers on a real video (fusiontrack.eval.appearance): PETS 2009 S2.L1 with MOTChallenge's public
detections, identities from unambiguous box continuity (no annotated identities needed); and that continuity's
tracklets on hand-built boxes whose story is known."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from fusiontrack.eval.appearance import NeighbourEvidence, iou_tracklets, neighbour_evidence
from fusiontrack.io.tracks import MotBoxes, read_mot
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
    """PETS09 S2.L1 (480 x 360, people about 23 x 51 px): over 795 frames, test then train as the fused tracker
    learns. Each classifier scores its own person above a neighbour far more often than chance (1 in 2), and the
    identity checks, had they been asked, would have exchanged hardly any of the pairs they decided on (none was
    ever exchanged: the identities are the tracklets')."""
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
    assert decided >= 20
    assert v["exchange"] <= 0.05 * decided
    assert np.all(np.abs(ne.evidence) <= 2.0)


def test_tracklets_start_afresh_after_an_empty_frame_a_weak_link_or_a_split():
    a = _walk(0.0, 4.0, 6)
    # frames 1-2 linked; nothing in frame 3; frame 4 a new tracklet; frame 5 moved 15 px (IoU 0.14 < 0.3): new again
    frame = np.array([1, 2, 4, 5])
    boxes = np.array([a[1], a[2], a[4], a[4] + [15.0, 0, 15.0, 0]])
    assert iou_tracklets(frame, boxes).tolist() == [0, 0, 1, 2]
    assert iou_tracklets(frame, boxes, min_iou=0.1).tolist() == [0, 0, 1, 1]
    # one box followed by two overlapping it alike (a group coming apart): neither continues it
    two = np.array([a[0], a[0] + [-3.0, 0, -3.0, 0], a[0] + [3.0, 0, 3.0, 0]])
    assert iou_tracklets(np.array([1, 2, 2]), two).tolist() == [0, 1, 2]
    # two boxes coming together into one (a group forming): it continues neither
    assert iou_tracklets(np.array([1, 1, 2]), two[[1, 2, 0]]).tolist() == [0, 1, 2]
    assert iou_tracklets(np.zeros(0), np.zeros((0, 4))).size == 0
    with pytest.raises(ValueError, match=r"whole frame numbers, got 1\.5"):
        iou_tracklets(np.array([1.0, 1.5]), np.zeros((2, 4)))
    with pytest.raises(ValueError, match="expected numbers"):
        iou_tracklets(np.array(["a"]), np.zeros((1, 4)))


def test_tracklets_on_annotated_boxes_seldom_hold_two_people(shared_data):
    """On MOTChallenge ground truth (the identities annotated by hand), tracklets built from the boxes alone: none
    holds two people on TUD-Campus and TUD-Stadtmitte, and at most 1 % do on MOT17-05 and MOT17-11, where small
    people walk one behind the other faster than half a box per frame."""
    ref = shared_data / "mot_reference"
    for path, most in ((ref / "motmetrics_tud/TUD-Campus/gt.txt", 0.0),
                       (ref / "motmetrics_tud/TUD-Stadtmitte/gt.txt", 0.0),
                       (ref / "trackeval_mot17/gt/mot_challenge/MOT17-train/MOT17-05-FRCNN/gt/gt.txt", 0.01),
                       (ref / "trackeval_mot17/gt/mot_challenge/MOT17-train/MOT17-11-FRCNN/gt/gt.txt", 0.01)):
        gt = read_mot(path)
        keep = (gt.conf > 0) & (gt.extra[:, 0] == 1) if "MOT17" in str(path) else np.ones(len(gt), bool)  # people
        ids = iou_tracklets(gt.frame[keep], gt.boxes_xyxy[keep])
        person = gt.id[keep]
        two = sum(np.unique(person[ids == t]).size > 1 for t in np.unique(ids))
        assert two <= most * np.unique(ids).size, path.parent.name
        assert np.unique(ids).size >= np.unique(person).size  # (paths are cut, never fewer pieces than people)


def test_verdicts_pair_the_two_classifiers_and_decide_at_the_first_sure_frame():
    # pair (1, 2): both classifiers score frames 3, 6, 9; pair (1, 3): one classifier, evidence turning negative;
    # pair (2, 3) scored on 2 frames only (no verdict); rows shuffled
    rows = [(3, 1, 2, 0.2), (3, 2, 1, 0.6), (6, 1, 2, 0.9), (6, 2, 1, 0.9), (9, 1, 2, -1.0), (9, 2, 1, -1.0),
            (3, 3, 1, -0.5), (6, 3, 1, -0.5), (9, 3, 1, -0.9), (12, 3, 1, -0.9),
            (3, 2, 3, 1.0), (6, 2, 3, 1.0)]
    order = np.random.default_rng(1).permutation(len(rows))
    f, t, o, e = (np.array([rows[k][j] for k in order]) for j in range(4))
    ne = NeighbourEvidence(e.astype(float), f.astype(np.int64), t.astype(np.int64), o.astype(np.int64))
    # per frame: (1, 2) 0.4, 0.9, -1.0 (running 0.4, 0.65, 0.1); (1, 3) -0.5, -0.5, -0.9, -0.9 (running -0.5, -0.5,
    # -0.633, -0.7); (2, 3) 1.0, 1.0
    assert ne.verdicts(n=2, margin=0.6) == {"keep": 2, "exchange": 1, "undecided": 0}
    # n = 3: (1, 2) is at 0.1 by its 3rd frame, (2, 3) has no 3rd frame (no verdict)
    assert ne.verdicts(n=3, margin=0.6) == {"keep": 0, "exchange": 1, "undecided": 1}
    assert ne.verdicts(n=1, margin=0.95) == {"keep": 1, "exchange": 0, "undecided": 2}
    assert ne.right_sign() == pytest.approx(0.5)
    with pytest.raises(ValueError, match="n:"):
        ne.verdicts(n=0)


@pytest.mark.parametrize(("per_frame", "verdict"), [([-0.5, 1.5, 1.5], "keep"),  # wrong at first, sure at the 3rd
                                                    ([1.0, 1.0, 1.0, -5.0, -5.0], "keep"),  # decided before it turns
                                                    ([-1.0, 1.0, 0.0], "undecided")])  # (mean 0, margin 0)
def test_a_verdict_is_taken_at_the_first_sure_frame_from_the_nth_on(per_frame, verdict):
    k = len(per_frame)
    ne = NeighbourEvidence(np.array(per_frame, float), np.arange(k, dtype=np.int64), np.ones(k, np.int64),
                           np.full(k, 2, np.int64))
    margin = 0.0 if verdict == "undecided" else 0.6
    assert ne.verdicts(n=3, margin=margin) == {"keep": 0, "exchange": 0, "undecided": 0, verdict: 1}


def test_empty_boxes_are_left_out_and_counted():
    # two people side by side over 8 frames of a grey image; one detection of frame 3 is an empty box
    boxes = [[10.0, 10.0, 30.0, 60.0], [40.0, 10.0, 60.0, 60.0]]
    rows = [(f, b) for f in range(1, 9) for b in boxes] + [(3, [70.0, 10.0, 70.0, 60.0])]
    det = MotBoxes(np.array([f for f, _ in rows], np.int64), np.full(len(rows), -1, np.int64),
                   np.array([[b[0], b[1], b[2] - b[0], b[3] - b[1]] for _, b in rows]), np.ones(len(rows)),
                   np.zeros((len(rows), 0)))
    img = np.full((80, 100, 3), 128, np.uint8)
    ne = neighbour_evidence(((f, img) for f in range(1, 9)), det)
    assert (ne.frames, ne.detections, ne.dropped, ne.tracklets) == (8, 17, 1, 2)
