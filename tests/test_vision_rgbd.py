"""RGB-D building blocks against known answers: X4 Bhattacharyya, X3 integral histograms, C6 depth shape and
likelihood on a synthetic person in front of a wall, C7 back-projection through a known camera, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.geometry import PinholeCamera
from fusiontrack.types import CameraInfo
from fusiontrack.vision.rgbd import (
    RgbdDetectorParams,
    RgbdParticleFilter,
    RgbdPfParams,
    bhattacharyya,
    bin_integrals,
    box_histograms,
    depth_overlap,
    depth_shapes,
    detect_people_rgbd,
    hsv_bins,
    reference_depth,
    remove_floor,
    target_position,
)

K = np.array([[525.0, 0.0, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])  # C7's default Kinect intrinsics


# ---- X4 -----------------------------------------------------------------------------------------


def test_bhattacharyya_known_answers():
    rng = np.random.default_rng(0)
    p = rng.random(110)
    p /= p.sum()
    assert bhattacharyya(p, p) == pytest.approx(1.0)  # X4: BC(p, p) = 1
    a = np.r_[0.5, 0.5, 0.0, 0.0]
    b = np.r_[0.0, 0.0, 0.3, 0.7]
    assert bhattacharyya(a, b) == 0.0  # disjoint supports
    # textbook value: BC of (1/2, 1/2) and (1, 0) is sqrt(1/2)
    assert bhattacharyya([0.5, 0.5], [1.0, 0.0]) == pytest.approx(np.sqrt(0.5))
    # broadcast over a batch of particles
    batch = np.stack([p, np.roll(p, 1), np.full(110, 1 / 110)])
    out = bhattacharyya(batch, p)
    assert out.shape == (3,)
    assert out[0] == pytest.approx(1.0)
    assert np.all(out <= 1.0)


# ---- C6 histograms via X3 -----------------------------------------------------------------------


def test_integral_histograms_equal_direct_histograms():
    rng = np.random.default_rng(1)
    bgr = rng.integers(0, 256, (60, 80, 3), dtype=np.uint8)
    bgr[:20, :30] = (20, 20, 200)  # a saturated red patch and a grey one
    bgr[30:, 50:] = 128
    bins = hsv_bins(bgr)
    assert bins.shape == (60, 80)
    assert bins.max() < 110
    roi = (5, 3, 77, 58)
    integ = bin_integrals(bins, 110, roi)
    boxes = np.array([[5, 3, 40, 30], [10, 10, 77, 58], [20, 15, 21, 16], [0, 0, 90, 70]])
    got = box_histograms(integ, boxes, roi[:2])
    for box, hist in zip(boxes, got, strict=True):
        u0, v0, u1, v1 = np.clip(box, [roi[0], roi[1]] * 2, [roi[2], roi[3]] * 2)  # clipped to the region
        want = np.bincount(bins[v0:v1, u0:u1].ravel(), minlength=110).astype(float)
        np.testing.assert_allclose(hist, want / want.sum(), atol=1e-12)


def test_perez_binning_puts_greys_in_value_bins():
    img = np.zeros((2, 3, 3), np.uint8)
    img[0, 0] = (0, 0, 255)  # pure red: hue 0, full saturation
    img[0, 1] = (255, 0, 0)  # pure blue: hue 120 of 180 -> bin 6
    img[0, 2] = (200, 200, 200)  # grey: V-only bin 7 (200 * 10 // 256)
    img[1, :] = (10, 10, 10)  # dark: V-only bin 0
    bins = hsv_bins(img)
    assert bins[0, 0] == 0 * 10 + 9
    assert bins[0, 1] == 6 * 10 + 9
    assert bins[0, 2] == 100 + 7
    assert np.all(bins[1] == 100)


# ---- C6 depth shape and likelihood on a synthetic scene -----------------------------------------


def _scene(person_u: int = 300, person_depth_m: float = 2.5, wall_depth_m: float = 4.0, seed: int = 0):
    """A 640x480 RGB-D frame: a textured wall at 4 m and a person (head + body + legs) at 2.5 m."""
    rng = np.random.default_rng(seed)
    bgr = np.clip(rng.normal(150, 25, (480, 640, 3)), 0, 255).astype(np.uint8)
    bgr[..., 0] = np.clip(bgr[..., 0].astype(int) - 40, 0, 255)  # a yellowish wall
    depth = np.full((480, 640), wall_depth_m, np.float32) + rng.normal(0, 0.01, (480, 640)).astype(np.float32)
    mask = np.zeros((480, 640), bool)
    u = person_u
    mask[120:160, u - 18:u + 18] = True  # head
    mask[160:300, u - 45:u + 45] = True  # torso
    mask[300:440, u - 40:u - 5] = True  # legs
    mask[300:440, u + 5:u + 40] = True
    shirt = np.zeros((480, 640, 3), np.uint8)
    shirt[..., :] = (40, 40, 180)  # red shirt
    shirt[300:, :] = (120, 60, 20)  # blue trousers
    shirt[120:160, :] = (90, 140, 200)  # skin
    bgr[mask] = shirt[mask]
    depth[mask] = person_depth_m
    box = np.array([u - 48, 115, u + 48, 445], float)
    return bgr, depth, box


def test_identical_patch_scores_one():
    bgr, depth, box = _scene()
    pf = RgbdParticleFilter(bgr, depth, box, rng=0)
    bc, sd = pf.similarity(bgr, depth, box[None, :])
    assert bc[0] == pytest.approx(1.0)
    assert sd[0] == pytest.approx(1.0)
    # the paper's variant (mean depth, template-normalised overlap) on a box filled by the torso
    torso = np.array([255, 160, 345, 300], float)
    pf_paper = RgbdParticleFilter(bgr, depth, torso, RgbdPfParams(overlap="template", reference="mean"), rng=0)
    bc, sd = pf_paper.similarity(bgr, depth, torso[None, :])
    assert bc[0] * sd[0] == pytest.approx(1.0)
    # erratum E7: over the whole box the mean depth (wall pixels included) is far from the person's 2.5 m, and
    # Eq. 3 then selects nothing; the median of the central half does not have this problem
    assert abs(reference_depth(depth, box, "mean") - 2.5) > 0.3
    assert reference_depth(depth, box, "median") == pytest.approx(2.5, abs=0.01)


@pytest.mark.parametrize("overlap", ["union", "template"])
def test_person_against_wall_centred_vs_shifted(overlap):
    # ALGORITHMS.md C6 test: centred particle >= 0.8, a particle shifted by a full box width <= 0.3
    bgr, depth, box = _scene(seed=0)
    pf = RgbdParticleFilter(bgr, depth, box, RgbdPfParams(overlap=overlap), rng=0)
    bgr2, depth2, box2 = _scene(person_u=310, seed=1)  # next frame: moved 10 px, new sensor noise
    width = box2[2] - box2[0]
    shift = np.array([width, 0.0, width, 0.0])
    boxes = np.stack([box2, box2 + shift, box2 - shift])
    bc, sd = pf.similarity(bgr2, depth2, boxes)
    p = bc * sd
    assert p[0] >= 0.8
    assert np.all(p[1:] <= 0.3)


def test_depth_shape_and_overlap_known_answers():
    depth = np.full((40, 40), 4.0, np.float32)
    depth[10:30, 10:20] = 2.0
    depth[0, 0] = np.nan
    shapes = depth_shapes(depth, np.array([[10, 10, 20, 30], [0, 0, 40, 40], [-20, -20, 0, 0]], float), 2.0, 0.3,
                          size=(10, 20))
    assert shapes.shape == (3, 20, 10)
    assert shapes[0].all()  # the box is the silhouette
    # nearest-neighbour samples at the cell centres: columns 2, 6, ..., 38 (3 of 10 in [10, 20)) and rows
    # 1, 3, ..., 39 (10 of 20 in [10, 30))
    assert shapes[1].mean() == pytest.approx(3 / 10 * 10 / 20)
    assert not shapes[2].any()  # entirely outside the image
    tmpl = shapes[0].astype(np.float32)
    ov_t = depth_overlap(shapes, tmpl, "template")
    ov_u = depth_overlap(shapes, tmpl, "union")
    np.testing.assert_allclose(ov_t[[0, 2]], [1.0, 0.0])
    np.testing.assert_allclose(ov_u[[0, 2]], [1.0, 0.0])
    # a box inside the silhouette: full template overlap, but Jaccard sees the missing foreground
    half = np.zeros_like(tmpl)
    half[:10] = 1
    assert depth_overlap(tmpl[None], half, "template")[0] == pytest.approx(1.0)
    assert depth_overlap(tmpl[None], half, "union")[0] == pytest.approx(0.5)
    assert reference_depth(depth, [10, 10, 20, 30]) == pytest.approx(2.0)
    assert reference_depth(depth, [0, 0, 40, 40], mode="mean") == pytest.approx((200 * 2.0 + 1399 * 4.0) / 1599)


def test_pf_follows_the_synthetic_person():
    bgr, depth, box = _scene(person_u=200, seed=0)
    pf = RgbdParticleFilter(bgr, depth, box, rng=3)
    errors = []
    for k in range(1, 31):  # 6 px per frame to the right, and 2 cm per frame further away
        u = 200 + 6 * k
        bgr, depth, _ = _scene(person_u=u, person_depth_m=2.5 + 0.02 * k, seed=k)
        est = pf.step(bgr, depth)
        errors.append(abs(est.centre_px[0] - u))
        assert not est.lost
    assert np.mean(errors) < 4.0  # the PF's σ_u is 8 px: the mean must stay well inside one σ
    assert pf.template.depth_m == pytest.approx(2.5 + 0.02 * 30, abs=0.05)  # D̄ follows the target


# ---- C7 -----------------------------------------------------------------------------------------


def test_target_position_back_projects_through_a_known_camera():
    # a camera 1.5 m up looking along world +x; a flat target 3 m ahead, 0.5 m to the left of the axis
    cam = PinholeCamera.from_pose([0.0, 0.0, 1.5], 0.0, 0.0, fx=525.0, fy=525.0, width=640, height=480, cx=319.5,
                                  cy=239.5)
    target_world = np.array([3.0, 0.5, 1.2])
    u, v = cam.project(target_world[None])[0]
    depth = np.full((480, 640), np.nan, np.float32)
    depth[int(v) - 30:int(v) + 31, int(u) - 20:int(u) + 21] = 3.0  # a 41x61 px patch around the target pixel
    box = [u - 60, v - 80, u + 60, v + 80]
    info = CameraInfo(0, "kinect", "kinect", 640, 480, K, np.zeros(5))
    fix = target_position(depth, box, info, cam.cam2world)
    assert fix.valid
    assert fix.n_pixels == 41 * 61
    assert fix.depth_m == pytest.approx(3.0)
    centre = np.array([int(u), int(v)], float)
    np.testing.assert_allclose(fix.centroid_px, centre, atol=1e-9)
    want = cam.cam2world[:3, :3] @ np.array([(centre[0] - 319.5) * 3 / 525, (centre[1] - 239.5) * 3 / 525, 3.0]) \
        + cam.position_m
    np.testing.assert_allclose(fix.position_world_m, want, atol=1e-9)
    np.testing.assert_allclose(fix.position_world_m, target_world, atol=0.01)  # pixel rounding only
    det = fix.detection(5, "kinect", box)
    np.testing.assert_allclose(det.position_m, fix.position_world_m[:2])
    # out of the C7 range: not valid
    far = target_position(depth * 2, box, K)
    assert far.depth_m == pytest.approx(6.0)
    assert not far.valid
    # no foreground at all
    empty = target_position(np.full((480, 640), np.nan, np.float32), box, K)
    assert not empty.valid
    assert empty.n_pixels == 0
    assert np.all(np.isnan(empty.position_cam_m))


def test_remove_floor_and_detector_on_a_rendered_floor():
    # floor seen by a camera 1.4 m up, pitched 15° down; a 1.75 m person-sized box 3 m ahead
    cam = PinholeCamera.from_pose([0.0, 0.0, 1.4], 0.0, np.deg2rad(15), fx=262.5, fy=262.5, width=320, height=240)
    uv = np.stack(np.meshgrid(np.arange(320.0), np.arange(240.0)), -1).reshape(-1, 2)
    floor = cam.backproject_to_floor(uv)
    depth = (floor - cam.position_m) @ cam.cam2world[:3, 2]  # depth along the optical axis
    depth = np.where(depth < 6.0, depth, np.nan).reshape(240, 320).astype(np.float32)
    # the person: a box 0.5 m wide and 1.75 m tall at x = 3 m, rendered as its front face at 2.9 m
    corners = np.array([[2.9, 0.25, 0.0], [2.9, -0.25, 1.75]])
    (u0, v1), (u1, v0) = cam.project(corners)
    z_face = float((np.array([2.9, 0.0, 1.0]) - cam.position_m) @ cam.cam2world[:3, 2])
    depth[int(v0):int(v1), int(u0):int(u1)] = z_face
    info = CameraInfo(0, "kinect", "kinect", 320, 240, cam.K, np.zeros(5))
    no_floor = remove_floor(depth, info, cam.cam2world)
    assert np.isnan(no_floor[230, 10])
    assert np.isfinite(depth[230, 10])
    assert np.isfinite(no_floor[int((v0 + v1) / 2), int((u0 + u1) / 2)])  # person kept
    for pose in (cam.cam2world, None):  # with the pose, and with a RANSAC floor
        det = detect_people_rgbd(depth, info, pose, rng=0)
        assert len(det) == 1
        assert det.height_m[0] == pytest.approx(1.75, abs=0.1)
        assert det.width_m[0] == pytest.approx(0.5, abs=0.1)
        np.testing.assert_allclose(det.position_cam_m[0, 2], z_face, atol=0.05)
        if pose is None:
            # the plane found: the camera is 1.4 m above it, and it is tilted by the camera's 15° pitch
            assert det.floor_plane is not None
            assert det.floor_plane[3] == pytest.approx(1.4, abs=0.05)
            assert np.degrees(np.arccos(-det.floor_plane[1])) == pytest.approx(15.0, abs=1.0)
        else:
            np.testing.assert_allclose(det.position_world_m[0, :2], [2.9, 0.0], atol=0.1)


# ---- bad input ----------------------------------------------------------------------------------


def test_bad_input_names_the_parameter():
    bgr, depth, box = _scene()
    with pytest.raises(ValueError, match="n_particles"):
        RgbdPfParams(n_particles=0)
    with pytest.raises(ValueError, match="eps_m"):
        RgbdPfParams(eps_m=-0.3)
    with pytest.raises(ValueError, match="overlap"):
        RgbdPfParams(overlap="mean")
    with pytest.raises(ValueError, match="scale_range"):
        RgbdPfParams(scale_range=(2.0, 1.0))
    with pytest.raises(ValueError, match="cell_m"):
        RgbdDetectorParams(cell_m=0.0)
    with pytest.raises(ValueError, match="box_px"):
        RgbdParticleFilter(bgr, depth, [10, 10, 5, 5])
    with pytest.raises(ValueError, match=r"box_px.*no valid depth"):
        RgbdParticleFilter(bgr, np.full_like(depth, np.nan), box)
    with pytest.raises(ValueError, match="depth_m"):
        RgbdParticleFilter(bgr, depth[:100], box)
    with pytest.raises(ValueError, match="bgr"):
        RgbdParticleFilter(bgr[..., 0], depth, box)
    pf = RgbdParticleFilter(bgr, depth, box, rng=0)
    with pytest.raises(ValueError, match="depth_m"):
        pf.step(bgr[:240, :320], depth[:240, :320])
    with pytest.raises(ValueError, match="p, q"):
        bhattacharyya([0.5, 0.5], [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="camera"):
        target_position(depth, box, np.eye(2))
    with pytest.raises(ValueError, match="box_px"):
        target_position(depth, [0, 0, 0, 0], K)
    with pytest.raises(ValueError, match="cam2world"):
        detect_people_rgbd(depth, K, np.eye(3))
    with pytest.raises(ValueError, match="roi"):
        bin_integrals(hsv_bins(bgr), 110, (0, 0, 1000, 10))
