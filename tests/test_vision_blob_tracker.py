"""A5 blob tracker: ALGORITHMS.md's three synthetic-mask tests and hand-built event sequences."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from fusiontrack.geometry import PinholeCamera
from fusiontrack.vision import BlobParams, Blobs, blob_histograms, extract_blobs
from fusiontrack.vision.blob_tracker import (
    BlobTracker,
    BlobTrackerParams,
    NodeLabel,
    box_gaps,
    fit_person_area,
)

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


# -- A5 §3-4 size prior: A_p(v_bottom), n̂ = area / A_p, groups of unknown member count ----------------------


def sized_frame(people: list[tuple[float, float, int, tuple[int, int, int]]]) -> np.ndarray:
    """Black frame with a filled box per person ``(u_min, v_bottom, width, colour)``, height ``v_bottom // 2``.

    A single person (width ``PW``) then has the box-area law ``A_p(v) = PW * (v // 2) ≈ 10 v`` px².
    """
    f = np.zeros((H, W, 3), np.uint8)
    for u, vb, w, colour in people:
        u0, vb = round(u), round(vb)
        f[vb - vb // 2:vb, u0:u0 + w] = colour
    return f


LEARN = [sized_frame([(20, 100 + 2 * k, PW, GREEN)]) for k in range(62)]  # a walker coming nearer: rows 100..222


def run_on(tracker: BlobTracker, frames: list[np.ndarray], start: int = 0):
    outputs = []
    for k, f in enumerate(frames, start=start):
        blobs = extract_blobs(f.any(axis=2))
        outputs.append(tracker.step(blobs, blob_histograms(f, blobs), t_ns=k * 100_000_000))
    return outputs


SIZE_RULE = BlobTrackerParams(group_n_hat=1.7)  # A5 §4's value (off by default)


@pytest.fixture(scope="module")
def learnt() -> BlobTracker:
    tracker = BlobTracker(SIZE_RULE)
    run_on(tracker, LEARN)
    return tracker


def test_fit_person_area_recovers_a_linear_law_robustly():
    rng = np.random.default_rng(3)
    v = rng.uniform(80, 230, 400)
    a = 12.0 * v - 300.0 + rng.normal(0, 20, v.size)
    bad = rng.random(v.size) < 0.2  # a fifth of the "single" samples are two people or a person and shadow
    a[bad] *= 2.0
    law = fit_person_area(v, a)
    assert law is not None
    assert abs(law.slope - 12.0) < 0.4
    assert abs(law.intercept + 300.0) < 60
    np.testing.assert_allclose(law(np.array([100.0, 200.0])), [900.0, 2100.0], rtol=0.03)
    assert np.isnan(law(np.array([10.0, 400.0]))).all()  # far outside the rows seen: unknown
    assert fit_person_area(v[:20], a[:20]) is None  # too few
    assert fit_person_area(np.full(100, 150.0) + rng.normal(0, 3, 100), np.full(100, 1500.0)) is None  # one row
    nan_v = v.copy()
    nan_v[::2] = np.nan
    assert fit_person_area(nan_v, a) is not None  # NaN samples are ignored


def test_tracker_learns_the_area_law_of_single_walkers(learnt):
    law = learnt.area_law
    assert law is not None
    assert abs(law.slope - PW / 2) < 0.3  # the rendering's law: A = PW * (v // 2)
    v = np.array([120.0, 160.0, 200.0])
    np.testing.assert_allclose(learnt.expected_area(v), PW * (v // 2), rtol=0.03)
    np.testing.assert_allclose(learnt.n_hat(np.array([[0, 80, 40, 160]])), [2.0], rtol=0.03)
    # before enough samples spread over rows: no prior, no size rule
    fresh = BlobTracker()
    run_on(fresh, LEARN[:30])
    assert fresh.area_law is None
    assert np.isnan(fresh.expected_area(np.array([150.0]))).all()


def test_blob_twice_a_person_entering_is_a_group_of_unknown_count(learnt):
    tracker = copy.deepcopy(learnt)
    frames = [sized_frame([(120, 160, 2 * PW, RED), (240, 160, PW, BLUE)]) for _ in range(8)]
    out = run_on(tracker, frames, start=len(LEARN))[-1]
    by_u = sorted(out, key=lambda o: o.box_px[0])
    wide, single = by_u[-2], by_u[-1]
    np.testing.assert_allclose(wide.box_px, [120, 80, 160, 160])
    assert (wide.in_group, wide.count_known, wide.group_size) == (True, False, 2)
    assert wide.group_id >= 0
    assert (single.in_group, single.count_known, single.group_size) == (False, True, 1)
    labels = tracker.node_labels()
    assert labels[wide.group_id][0] == str(NodeLabel.GROUP)
    # without the rule (the default) the same blob is one object
    off = BlobTracker()
    run_on(off, LEARN)
    out = run_on(off, frames, start=len(LEARN))[-1]
    assert not any(o.in_group for o in out)


def test_group_entering_as_one_blob_and_diverging_gives_two_objects(learnt):
    tracker = copy.deepcopy(learnt)
    frames = []
    for k in range(45):  # side by side (one blob) for 15 frames, then apart 2 px/frame each way
        d = max(0, k - 15) * 2
        frames.append(sized_frame([(150 - d, 160, PW, RED), (150 + PW + d, 160, PW, BLUE)]))
    outputs = run_on(tracker, frames, start=len(LEARN))
    during = outputs[10]
    (group,) = [o for o in during if o.box_px[0] > 100]
    assert (group.in_group, group.count_known, group.group_size) == (True, False, 2)
    last = [o for o in outputs[-1] if o.box_px[0] > 60]
    assert len(last) == 2
    assert all(not o.in_group and o.count_known and o.group_size == 1 for o in last)
    assert len({o.object_id for o in last} | {group.object_id}) == 3  # two new ids; the group's id is gone
    np.testing.assert_allclose(sorted(o.box_px[0] for o in last), [150 - 58, 150 + PW + 58], atol=1)


def test_split_child_still_twice_a_person_stays_a_group(learnt):
    tracker = copy.deepcopy(learnt)
    frames = []
    for k in range(45):  # three abreast; the left one walks off, the other two stay together
        d = max(0, k - 15) * 3
        frames.append(sized_frame([(120 - d, 160, PW, GREEN), (120 + PW, 160, PW, RED),
                                   (120 + 2 * PW, 160, PW, BLUE)]))
    outputs = run_on(tracker, frames, start=len(LEARN))
    (trio,) = [o for o in outputs[10] if o.box_px[0] > 100]
    assert (trio.in_group, trio.count_known, trio.group_size) == (True, False, 3)
    last = sorted((o for o in outputs[-1] if o.box_px[2] > 45), key=lambda o: o.box_px[0])
    assert len(last) == 2
    alone, pair = last
    assert (alone.in_group, alone.count_known, alone.group_size) == (False, True, 1)
    assert (pair.in_group, pair.count_known, pair.group_size) == (True, False, 2)
    np.testing.assert_allclose(pair.box_px, [120 + PW, 80, 120 + 3 * PW, 160])


def test_camera_gives_an_a_priori_person_area():
    cam = PinholeCamera.from_pose([0.0, 0.0, 3.0], 0.0, np.radians(20), fx=300, fy=300, width=W, height=H)
    tracker = BlobTracker(SIZE_RULE, camera=cam)
    feet = np.array([[4.0, 0.0], [6.0, 0.0], [9.0, 0.0]])  # in front of the camera, on its central column
    box = cam.person_box(feet, 1.72, 0.40)
    area = (box[:, 2] - box[:, 0]) * (box[:, 3] - box[:, 1])
    np.testing.assert_allclose(tracker.expected_area(box[:, 3]), area, rtol=0.02)
    assert np.isnan(tracker.expected_area(np.array([10.0]))).all()  # above the horizon: no floor there
    # a blob twice that wide appearing at once is a group, before anything was learnt
    b = box[1]
    wide = np.array([[b[0] - (b[2] - b[0]) / 2, b[1], b[2] + (b[2] - b[0]) / 2, b[3]]])
    blobs = Blobs(wide, (wide[:, :2] + wide[:, 2:]) / 2, np.array([1000]), np.array([1], np.int32),
                  np.zeros((H, W), np.int32))
    for k in range(4):
        out = tracker.step(blobs, t_ns=k * 100_000_000)
    assert len(out) == 1
    assert (out[0].in_group, out[0].count_known, out[0].group_size) == (True, False, 2)


def test_size_rule_params_checked():
    with pytest.raises(ValueError, match="group_n_hat"):
        BlobTrackerParams(group_n_hat=-1.0)
    with pytest.raises(ValueError, match="person_height_m"):
        BlobTrackerParams(person_height_m=0.0)
    with pytest.raises(ValueError, match="differ"):
        fit_person_area(np.ones(3), np.ones(4))


def test_components_match_scipys_connected_components_and_their_order():
    """The tracker's own connected components (union-find) label every vertex as scipy does, components numbered
    by their lowest vertex: the order in which the tracker handles association events, hence its ids."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from fusiontrack.vision.blob_tracker import _components

    rng = np.random.default_rng(0)
    for n in (1, 2, 5, 12, 30):
        for density in (0.0, 0.05, 0.15, 0.5):
            adj = rng.random((n, n)) < density
            _, ref = connected_components(coo_matrix(adj.astype(np.float64)), directed=False)
            np.testing.assert_array_equal(_components(adj), ref)
    assert _components(np.zeros((0, 0), bool)).shape == (0,)
