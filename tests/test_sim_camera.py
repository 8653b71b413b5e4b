"""The camera simulator (issue 3): geometry of the rendered people against the pinhole model, occlusion, labels,
illumination, RGB-D depth, the calibration bias, determinism and lens distortion."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fusiontrack.sim.camera import SHADOW_GAIN, CameraSim
from fusiontrack.sim.model import KIND_BICYCLE, KIND_CAR, KIND_PERSON, AgentSnapshot, CameraSpec, StaticWorld, Timing

FX = 250.0


def _spec(**kw: object) -> CameraSpec:
    base = dict(name="cam", position_m=(0.0, 0.0, 3.0), yaw_rad=0.0, pitch_rad=np.deg2rad(20.0),
                timing=Timing(15.0), width=320, height=240, fx=FX, fy=FX, noise_sigma=0.0, labels=True)
    base.update(kw)
    return CameraSpec(**base)  # type: ignore[arg-type]


def _snapshot(agents: list[dict]) -> AgentSnapshot:
    """People stand with their feet 0.18 m apart (``stride`` moves the left foot forward, the right back)."""
    n = len(agents)
    pos = np.array([a["pos"] for a in agents], float).reshape(n, 2)
    yaw = np.array([a.get("heading", 0.0) for a in agents], float)
    kinds = np.array([a.get("kind", KIND_PERSON) for a in agents], np.int8)
    fwd = np.column_stack([np.cos(yaw), np.sin(yaw)])
    lft = np.column_stack([-np.sin(yaw), np.cos(yaw)])
    stride = np.array([a.get("stride", 0.0) for a in agents])[:, None]
    feet = np.stack([pos + 0.09 * lft + stride * fwd, pos - 0.09 * lft - stride * fwd], axis=1)
    feet[kinds != KIND_PERSON] = np.nan
    default_size = {KIND_PERSON: (0.3, 0.5, 1.75), KIND_CAR: (4.3, 1.8, 1.5), KIND_BICYCLE: (1.8, 0.6, 1.75)}
    size = np.array([a.get("size", default_size[a.get("kind", KIND_PERSON)]) for a in agents], float).reshape(n, 3)
    return AgentSnapshot(
        0, np.array([a["id"] for a in agents], np.int64), kinds, pos, np.zeros((n, 2)), yaw, feet, size,
        np.array([a.get("upper", (40, 40, 200)) for a in agents], np.uint8).reshape(n, 3),
        np.array([a.get("lower", (120, 60, 30)) for a in agents], np.uint8).reshape(n, 3),
        np.array([a.get("pattern", 0) for a in agents], np.int8), np.full(n, -1, np.int64), np.zeros(n))


def _label_box(labels: np.ndarray, agent_id: int) -> np.ndarray:
    ys, xs = np.nonzero(labels == agent_id + 1)
    return np.array([xs.min(), ys.min(), xs.max(), ys.max()], float)


@pytest.fixture(scope="module")
def empty_world() -> StaticWorld:
    return StaticWorld(floor_seed=1)


def test_feet_project_to_the_bottom_of_the_rendered_person(empty_world: StaticWorld) -> None:
    cam = CameraSim(_spec(), empty_world, 0)
    snap = _snapshot([dict(id=7, pos=(6.0, 0.8), heading=0.4), dict(id=8, pos=(7.5, -1.0), heading=2.0, stride=0.3)])
    out = cam.render(0.0, snap, 0)
    feet_uv = cam.true_camera.project(np.column_stack([snap.position_m, np.zeros(2)]))
    for k, aid in enumerate(snap.ids):
        box = out.boxes_px[k]
        assert box[0] <= feet_uv[k, 0] <= box[2]
        assert box[1] <= feet_uv[k, 1] <= box[3] + 0.5
        ys, xs = np.nonzero(out.labels == aid + 1)
        assert np.min(np.hypot(xs - feet_uv[k, 0], ys - feet_uv[k, 1])) < 4.0  # a foot right there
    # standing person: the feet midpoint is at the bottom of the box and of the label region, and the
    # rendered height agrees with the B11 box of a 1.75 m person
    assert abs(out.boxes_px[0, 3] - feet_uv[0, 1]) < 2.5
    assert abs(_label_box(out.labels, 7)[3] - feet_uv[0, 1]) < 3.0
    b11 = cam.true_camera.person_box(snap.position_m[:1], 1.75)[0]
    assert abs(out.boxes_px[0, 1] - b11[1]) < 3.0
    assert abs(out.boxes_px[0, 3] - b11[3]) < 3.0
    assert out.visibility == pytest.approx([1.0, 1.0], abs=0.01)


@pytest.mark.parametrize("far_first", [True, False])
def test_nearer_person_occludes_farther(empty_world: StaticWorld, far_first: bool) -> None:
    cam = CameraSim(_spec(), empty_world, 0)
    near, far = dict(id=1, pos=(5.0, 0.0), upper=(0, 200, 0)), dict(id=2, pos=(7.0, 0.1), upper=(200, 0, 0))
    snap = _snapshot([far, near] if far_first else [near, far])
    both = cam.render(0.0, snap, 0)
    near_alone = cam.render(0.0, _snapshot([near]), 0).labels == 2
    far_alone = cam.render(0.0, _snapshot([far]), 0).labels == 3
    overlap = near_alone & far_alone
    assert overlap.sum() > 50
    assert np.all(both.labels[near_alone] == 2)  # the nearer person wins wherever it is
    assert np.all(both.labels[far_alone & ~near_alone] == 3)
    vis = dict(zip(snap.ids.tolist(), both.visibility, strict=True))
    assert vis[1] == pytest.approx(1.0, abs=0.01)
    assert vis[2] == pytest.approx(1.0 - overlap.sum() / far_alone.sum(), abs=0.02)
    assert vis[2] < 0.9


def test_pillar_and_bench_occlude(empty_world: StaticWorld) -> None:
    person = _snapshot([dict(id=0, pos=(8.0, 0.0))])
    free = CameraSim(_spec(), empty_world, 0).render(0.0, person, 0)
    pillar = CameraSim(_spec(), StaticWorld(pillars=np.array([[5.0, 0.15, 0.2]])), 0).render(0.0, person, 0)
    bench = CameraSim(_spec(position_m=(0.0, 0.0, 1.2), pitch_rad=np.deg2rad(5.0)),
                      StaticWorld(boxes=np.array([[6.5, 0.0, 0.6, 2.0, 0.0, 0.6]])), 0)
    legs_hidden = bench.render(0.0, person, 0)
    assert free.visibility[0] == pytest.approx(1.0, abs=0.01)
    assert pillar.visibility[0] < 0.8
    assert pillar.visibility[0] == pytest.approx((pillar.labels == 1).sum()
                                                                               / (free.labels == 1).sum(), abs=0.02)
    assert 0.2 < legs_hidden.visibility[0] < 0.85
    box = legs_hidden.boxes_px[0]  # the head and shoulders show, the feet do not
    rows = np.nonzero((legs_hidden.labels == 1).any(axis=1))[0]
    assert rows.min() < box[1] + 5
    assert rows.max() < box[3] - 10


def test_label_pixels_lie_inside_the_boxes() -> None:
    rng = np.random.default_rng(3)
    agents = [dict(id=10 + i, pos=(rng.uniform(4, 12), rng.uniform(-3, 3)), heading=rng.uniform(-3, 3),
                   stride=rng.uniform(-0.3, 0.3), pattern=i % 4, upper=rng.integers(0, 255, 3)) for i in range(10)]
    agents += [dict(id=3, kind=KIND_CAR, pos=(9.0, -2.0), heading=0.3),
               dict(id=4, kind=KIND_BICYCLE, pos=(6.0, 2.0), heading=1.2)]
    world = StaticWorld(pillars=np.array([[6.0, 0.5, 0.25]]), floor_seed=4)
    for dist in ((), (-0.25, 0.07, 0.001, -0.001, 0.0)):
        out = CameraSim(_spec(dist=dist), world, 0).render(0.0, _snapshot(agents), 0)
        for k, aid in enumerate(a["id"] for a in agents):
            ys, xs = np.nonzero(out.labels == aid + 1)
            if xs.size == 0:
                assert out.visibility[k] < 0.01
                continue
            box = out.boxes_px[k]
            assert xs.min() >= box[0] - 1.5, (aid, dist)
            assert xs.max() <= box[2] + 1.5, (aid, dist)
            assert ys.min() >= box[1] - 1.5, (aid, dist)
            assert ys.max() <= box[3] + 1.5, (aid, dist)
            assert out.visibility[k] > 0


def test_illumination_gain_scales_brightness(empty_world: StaticWorld) -> None:
    cam = CameraSim(_spec(noise_sigma=2.0, illumination=((1.0, 0.35), (5.0, 1.0))), empty_world, 0)
    snap = _snapshot([dict(id=0, pos=(6.0, 0.0))])
    lit, dark, back_on = (cam.render(t, snap, 5).bgr.astype(float) for t in (0.5, 2.0, 6.0))
    assert [cam.gain(t) for t in (0.0, 1.0, 4.9, 5.0)] == [1.0, 0.35, 0.35, 1.0]
    assert dark.mean() / lit.mean() == pytest.approx(0.35, abs=0.01)
    assert back_on.mean() / lit.mean() == pytest.approx(1.0, abs=0.005)


def test_noise_has_the_specified_sigma(empty_world: StaticWorld) -> None:
    snap = _snapshot([dict(id=0, pos=(6.0, 0.0))])
    clean = CameraSim(_spec(noise_sigma=0.0), empty_world, 0).render(0.0, snap, 1).bgr.astype(float)
    noisy = CameraSim(_spec(noise_sigma=3.0), empty_world, 0).render(0.0, snap, 1).bgr.astype(float)
    ok = (clean > 20) & (clean < 235)
    assert np.std((noisy - clean)[ok]) == pytest.approx(3.0, rel=0.05)
    assert abs(np.mean((noisy - clean)[ok])) < 0.05


def test_shadow_darkens_the_floor_like_a_shadow(empty_world: StaticWorld) -> None:
    """ALGORITHMS.md A3: a cast shadow keeps the floor's chromaticity and scales its brightness into 0.4-0.95."""
    cam = CameraSim(_spec(), empty_world, 0)
    out = cam.render(0.0, _snapshot([dict(id=0, pos=(6.0, 0.0))]), 0)
    bg = cam.background_bgr.astype(float)
    ratio = out.bgr.astype(float).sum(2) / bg.sum(2)
    shadow = (out.labels == 0) & (ratio < 0.9)
    assert shadow.sum() > 100
    assert ratio[shadow].min() == pytest.approx(SHADOW_GAIN, abs=0.03)
    x, e = out.bgr.astype(float)[shadow], bg[shadow]
    a = (x * e).sum(1) / (e * e).sum(1)
    assert np.all(np.linalg.norm(x - a[:, None] * e, axis=1) / (a * np.linalg.norm(e, axis=1)) < 0.05)
    changed = (out.labels == 0) & np.any(out.bgr != cam.background_bgr, axis=2)
    assert np.all(ratio[changed] < 1.0)  # a shadow only darkens, and only near the person's feet
    feet_uv = cam.true_camera.project(np.array([[6.0, 0.0, 0.0]]))[0]
    ys, xs = np.nonzero(changed)
    assert np.hypot(xs - feet_uv[0], ys - feet_uv[1]).max() < 40
    no_shadow = CameraSim(_spec(shadows=False), empty_world, 0).render(0.0, _snapshot([dict(id=0, pos=(6.0, 0.0))]))
    assert np.array_equal(no_shadow.bgr[no_shadow.labels == 0], cam.background_bgr[no_shadow.labels == 0])


def test_rgbd_depth_is_metric_along_the_optical_axis(empty_world: StaticWorld) -> None:
    spec = _spec(position_m=(0.0, 0.0, 1.5), pitch_rad=np.deg2rad(12.0), depth=True, depth_range_m=(0.5, 4.5),
                 depth_noise_m=0.01)
    cam = CameraSim(spec, empty_world, 0)
    snap = _snapshot([dict(id=0, pos=(3.0, 0.2), heading=0.7)])
    out = cam.render(0.0, snap, 2)
    assert out.depth_m.dtype == np.float32
    assert out.depth_m.shape == (240, 320)
    world2cam = cam.true_camera.world2cam

    def z_cam(p: np.ndarray) -> float:
        return float((world2cam[:3, :3] @ p + world2cam[:3, 3])[2])

    head = np.array([3.0, 0.2, 1.75 - 0.065 * 1.75])  # the head is a disc facing the camera through its centre
    u, v = np.round(cam.true_camera.project(head[None])[0]).astype(int)
    patch = out.depth_m[v - 1:v + 2, u - 1:u + 2]
    assert np.nanmean(patch) == pytest.approx(z_cam(head), abs=0.03)
    person = out.depth_m[out.labels == 1]
    assert np.nanmedian(person) == pytest.approx(z_cam(np.array([3.0, 0.2, 0.9])), abs=0.12)
    floor = np.array([3.0, -0.8, 0.0])  # a floor point in range
    u, v = np.round(cam.true_camera.project(floor[None])[0]).astype(int)
    assert np.nanmean(out.depth_m[v - 1:v + 2, u - 1:u + 2]) == pytest.approx(z_cam(floor), abs=0.03)
    assert np.all(np.isnan(out.depth_m[:5]))  # the far floor and the sky: beyond 4.5 m or nothing
    finite = out.depth_m[np.isfinite(out.depth_m)]
    assert finite.min() >= 0.5 - 0.05
    assert finite.max() <= 4.5 + 0.05
    noise = out.depth_m - cam.render(0.0, snap, 3).depth_m
    assert np.nanstd(noise) == pytest.approx(0.01 * np.sqrt(2), rel=0.1)


def test_calibrated_camera_is_the_true_one_turned_by_minus_the_bias(empty_world: StaticWorld) -> None:
    bias = np.deg2rad(3.0)
    cam = CameraSim(_spec(pitch_rad=0.0, yaw_rad=0.4, yaw_bias_rad=bias), empty_world, 0)
    far = np.array([[1e4 * np.cos(0.4), 1e4 * np.sin(0.4), 3.0]])  # on the true optical axis
    u_true, u_cal = cam.true_camera.project(far)[0, 0], cam.calibrated_camera.project(far)[0, 0]
    assert u_true == pytest.approx(160.0, abs=1e-6)
    assert u_true - u_cal == pytest.approx(FX * np.tan(bias), abs=0.05)  # appears left of centre in the belief
    assert np.allclose(cam.calibrated_camera.position_m, cam.true_camera.position_m)
    info = cam.camera_info(123)
    assert info.frame_id == "cam"
    assert info.t_ns == 123
    assert np.allclose(info.K, cam.true_camera.K)
    assert info.D.shape == (5,)
    assert not info.D.any()


def test_same_seed_gives_the_same_image() -> None:
    world = StaticWorld(pillars=np.array([[5.0, 1.0, 0.3]]), roads=np.array([[-5.0, -4.0, 20.0, -4.0, 7.0]]),
                        floor_seed=9)
    snap = _snapshot([dict(id=0, pos=(6.0, 0.0), pattern=3), dict(id=1, kind=KIND_CAR, pos=(9.0, -4.0))])
    spec = _spec(noise_sigma=2.0, depth=True, depth_range_m=(0.5, 12.0))
    a = CameraSim(spec, world, 11).render(1.0, snap, 5)
    b = CameraSim(spec, world, 11).render(1.0, snap, np.random.default_rng(5))
    c = CameraSim(spec, world, 11).render(1.0, snap, 6)
    assert np.array_equal(a.bgr, b.bgr)
    assert np.array_equal(a.labels, b.labels)
    assert np.array_equal(a.depth_m, b.depth_m, equal_nan=True)
    assert np.array_equal(a.boxes_px, b.boxes_px)
    assert np.array_equal(a.visibility, b.visibility)
    assert not np.array_equal(a.bgr, c.bgr)
    assert np.array_equal(a.labels, c.labels)


def test_distorted_image_agrees_with_pinhole_projection(empty_world: StaticWorld) -> None:
    dist = (-0.3, 0.1, 0.002, -0.001, 0.0)
    cam = CameraSim(_spec(dist=dist), empty_world, 0)
    ideal = CameraSim(_spec(), empty_world, 0)
    # near the image corner, where the distortion moves points by several pixels
    snap = _snapshot([dict(id=0, pos=(5.0, 2.4), heading=0.0)])
    out, out_ideal = cam.render(0.0, snap, 0), ideal.render(0.0, snap, 0)
    label_box = _label_box(out.labels, 0)
    assert np.abs(label_box - out.boxes_px[0]).max() < 1.5
    shift = np.abs(out.boxes_px[0] - out_ideal.boxes_px[0]).max()
    assert shift > 5  # the test means something
    feet_uv = cam.true_camera.project(np.array([[5.0, 2.4, 0.0]]))[0]
    ys, xs = np.nonzero(out.labels == 1)
    assert np.min(np.hypot(xs - feet_uv[0], ys - feet_uv[1])) < 4.0
    assert out.visibility[0] == pytest.approx(1.0, abs=0.02)
    assert dataclasses.replace(cam.spec).dist == dist
    assert cam.camera_info(0).D.tolist() == list(dist)


def test_off_image_and_behind_the_camera(empty_world: StaticWorld) -> None:
    cam = CameraSim(_spec(), empty_world, 0)
    snap = _snapshot([dict(id=0, pos=(-5.0, 0.0)), dict(id=1, pos=(4.0, 9.0)), dict(id=2, pos=(0.2, 0.0)),
                      dict(id=3, pos=(4.0, 1.9))])
    out = cam.render(0.0, snap, 0)
    assert np.all(np.isnan(out.boxes_px[0]))
    assert out.visibility[0] == 0.0
    assert out.visibility[1] == 0.0
    assert out.boxes_px[1, 2] < 0
    assert 0.0 < out.visibility[3] < 1.0  # cut by the image border: only part of the silhouette shows
    assert (out.labels == 4).sum() > 0
    empty = cam.render(0.0, AgentSnapshot.empty(0), 0)
    assert empty.boxes_px.shape == (0, 4)
    assert empty.visibility.shape == (0,)
    assert not empty.labels.any()
