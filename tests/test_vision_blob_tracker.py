"""A5 blob tracker: ALGORITHMS.md's three synthetic-mask tests and hand-built event sequences."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.vision import BlobParams, blob_histograms, extract_blobs
from fusiontrack.vision.blob_tracker import BlobTracker, BlobTrackerParams, NodeLabel, box_gaps

H, W = 240, 320
PW, PH = 20, 60  # a person's box, px
RED, BLUE, GREEN = (30, 30, 220), (220, 60, 30), (40, 200, 40)


def frame_of(people: list[tuple[float, float, tuple[int, int, int]]], gap_row: int | None = None) -> np.ndarray:
    """Black frame with a filled ``PW x PH`` box per person ``(u_min, v_min, colour)``; optional 2-px cut."""
    f = np.zeros((H, W, 3), np.uint8)
    for u, v, colour in people:
        u0, v0 = round(u), round(v)
        f[v0:v0 + PH, u0:u0 + PW] = colour
        if gap_row is not None:
            f[v0 + gap_row:v0 + gap_row + 2, u0:u0 + PW] = 0
    return f


def run(frames: list[np.ndarray], blob_params: BlobParams | None = None, params: BlobTrackerParams | None = None,
        colour: bool = True):
    tracker = BlobTracker(params)
    outputs = []
    for k, f in enumerate(frames):
        blobs = extract_blobs(f.any(axis=2), blob_params)
        hists = blob_histograms(f, blobs) if colour else None
        outputs.append(tracker.step(blobs, hists, t_ns=k * 100_000_000))
    return tracker, outputs


def test_fragmented_person_keeps_one_id():
    # A5 test 1: one person with a horizontal 2-px gap = two blobs moving together for 50 frames
    frames = [frame_of([(20 + 2 * k, 90, GREEN)], gap_row=25) for k in range(50)]
    assert len(extract_blobs(frames[0].any(axis=2), BlobParams(close_px=0))) == 2
    tracker, outputs = run(frames, BlobParams(close_px=0))
    ids = {o.object_id for out in outputs for o in out}
    assert len(ids) == 1
    reported = [out for out in outputs if out]
    assert len(reported) >= 50 - tracker.params.n_confirm
    assert all(len(out) == 1 and not out[0].in_group for out in reported)
    last = outputs[-1][0].box_px
    np.testing.assert_allclose(last, [20 + 2 * 49, 90, 20 + 2 * 49 + PW, 90 + PH])  # the union of both pieces
    assert {label for label, _ in tracker.node_labels().values()} == {str(NodeLabel.FRAGMENT)}


def crossing(speed_far: float = 2.0, speed_near: float = 0.8, merged_frames: int = 30):
    """Red walks right, blue walks left; slower while they overlap so they are one blob for ~30 frames."""
    ua, ub = 40.0, 260.0
    frames, pos = [], []
    while ub - ua > -120:
        near = abs(ub - ua) <= PW + 6
        step = speed_near if near else speed_far
        frames.append(frame_of([(ua, 90, RED), (ub, 90, BLUE)]))
        pos.append((ua, ub))
        ua, ub = ua + step, ub - step
    return frames, pos


def test_merge_and_split_restore_both_ids_by_colour():
    # A5 test 2: two differently coloured persons merge for ~30 frames and separate; they crossed
    frames, pos = crossing()
    n_merged = sum(len(extract_blobs(f.any(axis=2))) == 1 for f in frames)
    assert 25 <= n_merged <= 35
    tracker, outputs = run(frames)
    first = outputs[5]
    assert len(first) == 2
    red_id = min(first, key=lambda o: o.box_px[0]).object_id  # red starts on the left
    blue_id = max(first, key=lambda o: o.box_px[0]).object_id
    grouped = [out for out in outputs if out and all(o.in_group for o in out)]
    assert len(grouped) >= 20
    assert {o.object_id for o in grouped[10]} == {red_id, blue_id}
    last = outputs[-1]
    assert len(last) == 2
    assert not any(o.in_group for o in last)
    ua, ub = pos[-1]
    by_id = {o.object_id: o.box_px for o in last}
    assert set(by_id) == {red_id, blue_id}
    np.testing.assert_allclose(by_id[red_id][0], round(ua), atol=1)  # red is now on the right: ids swapped sides
    np.testing.assert_allclose(by_id[blue_id][0], round(ub), atol=1)
    assert by_id[red_id][0] > by_id[blue_id][0]
    # the inference graph: one merge node with both walkers as parents, split into two children
    kinds = [e.kind for e in tracker.events]
    assert kinds.count("merge") == 1
    assert kinds.count("split") == 1
    (merge,) = [e for e in tracker.events if e.kind == "merge"]
    (g,) = merge.after
    assert sorted(tracker.graph()[merge.before[0]]) == [g]
    assert len(tracker.graph()[g]) == 2


def test_persons_entering_merged_get_two_new_ids():
    # A5 test 3: two persons enter already merged, walk together, then separate
    frames = []
    for k in range(60):
        spread = 0.0 if k < 25 else 3.0 * (k - 25)
        frames.append(frame_of([(30 + 2 * k - spread / 2, 90, RED), (30 + PW + 2 * k + spread / 2, 90, BLUE)]))
    _, outputs = run(frames)
    first_ids = {o.object_id for o in outputs[10]}
    assert len(first_ids) == 1  # one blob: one object (an unresolved group)
    last = outputs[-1]
    assert len(last) == 2
    assert len({o.object_id for o in last}) == 2
    assert not {o.object_id for o in last} & first_ids


def test_events_appear_continue_disappear_end():
    p = BlobTrackerParams(n_coast=3, n_confirm=1)
    tracker = BlobTracker(p)
    seq = [[(50, 50, GREEN)]] * 3 + [[]] * 5 + [[(200, 50, GREEN)]]
    outputs = []
    for people in seq:
        f = frame_of(people)
        outputs.append(tracker.step(extract_blobs(f.any(axis=2))))
    kinds = [e.kind for e in tracker.events]
    assert kinds == ["appear", "continue", "continue", "disappear", "end", "appear"]
    assert [len(o) for o in outputs] == [1, 1, 1, 1, 1, 1, 0, 0, 1]
    assert [o[0].missed for o in outputs[3:6]] == [1, 2, 3]  # coasting n_coast frames
    assert outputs[0][0].object_id != outputs[-1][0].object_id


def test_side_by_side_walkers_are_not_merged_while_apart():
    # 30 px apart (> d_frag): two objects from the start
    frames = [frame_of([(20 + 2 * k, 40, RED), (20 + 2 * k, 130, BLUE)]) for k in range(30)]
    tracker, outputs = run(frames)
    assert {e.kind for e in tracker.events} == {"appear", "continue"}
    assert len({o.object_id for out in outputs for o in out}) == 2
    # 10 px apart, the second one seen 5 frames after the first: still two objects
    frames = [frame_of([(20 + 2 * k, 60, RED)] + ([(20 + 2 * k, 130, BLUE)] if k >= 5 else [])) for k in range(30)]
    tracker, outputs = run(frames)
    assert {e.kind for e in tracker.events} == {"appear", "continue"}
    assert len({o.object_id for out in outputs for o in out}) == 2


def test_pieces_born_together_and_coherent_are_one_object():
    # A5 §3: within d_frag and moving together = one object (two people walking in step look the same)
    frames = [frame_of([(20 + 2 * k, 60, RED), (20 + 2 * k, 130, BLUE)]) for k in range(30)]  # 10 px apart
    _, outputs = run(frames)
    assert len({o.object_id for out in outputs for o in out}) == 1


def test_box_gaps():
    a = np.array([[0, 0, 10, 10]])
    b = np.array([[13, 0, 20, 10], [13, 14, 20, 20], [5, 5, 8, 8]])
    np.testing.assert_allclose(box_gaps(a, b), [[3.0, 5.0, 0.0]])


def test_bad_input():
    tracker = BlobTracker()
    blobs = extract_blobs(frame_of([(50, 50, GREEN)]).any(axis=2))
    with pytest.raises(ValueError, match="histograms"):
        tracker.step(blobs, np.ones((3, 4)))
    tracker.step(blobs, t_ns=10)
    with pytest.raises(ValueError, match="t_ns"):
        tracker.step(blobs, t_ns=10)
    with pytest.raises(ValueError, match="window"):
        BlobTrackerParams(window=1)
    with pytest.raises(ValueError, match="tau_ov"):
        BlobTrackerParams(tau_ov=-1.0)
    empty = extract_blobs(np.zeros((H, W), bool))
    assert BlobTracker().step(empty) == []
