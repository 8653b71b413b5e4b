"""ForegroundModel (ALGORITHMS.md A1 + A2 + A3) on synthetic frames with sensor noise, built here.

Known answers: A1's tests (constant pixel, step), the absorption time of a stopped object by the
conventional MoG predicted from MOG2's weight recursion, A2's stopped-rectangle scenario (>= 98 % kept
for 1000 frames, <= 1 % ghost three frames after it leaves), A2's moving-rectangle bound, and recovery
from illumination jumps, black frames and bad input.
"""

from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest

from fusiontrack.types import Image
from fusiontrack.vision import ForegroundModel, ForegroundParams, PixelLabel

H, W = 240, 320
RECT_W, RECT_H, RECT_V = 40, 80, 80  # A2's 40 x 80 px rectangle, top row 80
COLOUR = (40.0, 60.0, 200.0)


@pytest.fixture(scope="module")
def scene() -> tuple[np.ndarray, np.ndarray]:
    """A textured background (grey levels ~80-180) and 16 frames of Gaussian sensor noise (σ = 3)."""
    rng = np.random.default_rng(0)
    bg = cv2.GaussianBlur(rng.uniform(0, 1, (H, W, 3)).astype(np.float32), (0, 0), 3)
    bg = 130 + (bg - bg.mean()) / bg.std() * 25
    noise = rng.normal(0, 3, (16, H, W, 3)).astype(np.float32)
    return bg, noise


def render(scene: tuple[np.ndarray, np.ndarray], i: int, u0: int | None = None, gain: float = 1.0) -> np.ndarray:
    bg, noise = scene
    f = bg * gain
    if u0 is not None:
        f = f.copy()
        f[RECT_V:RECT_V + RECT_H, max(u0, 0):max(u0 + RECT_W, 0)] = np.array(COLOUR) * gain
    return np.clip(f + noise[i % len(noise)], 0, 255).astype(np.uint8)


def rect_mask(u0: int) -> np.ndarray:
    m = np.zeros((H, W), bool)
    m[RECT_V:RECT_V + RECT_H, max(u0, 0):max(u0 + RECT_W, 0)] = True
    return m


def mog2_absorption_frames(alpha: float, T: float, c_t: float = 0.05) -> int:
    """Frames after which MOG2 calls a new static colour background (its weight recursion, computed here).

    OpenCV's BackgroundSubtractorMOG2 (Zivkovic & van der Heijden 2006): every component's weight becomes
    ``(1 − α) w − α c_T`` (+ α for the matched one), then the weights are normalised; a colour that matches
    no component gets a new one of weight α (the others × (1 − α)). The matched component is background
    when the weights of the components ranked before it sum to less than ``T``.
    """
    w_bg, w_obj = 1.0 - alpha, alpha  # frame 1 of the object: a long-static pixel has one component of weight 1
    n = 1
    while True:
        n += 1
        bg_raw = (1 - alpha) * w_bg - alpha * c_t
        obj_raw = (1 - alpha) * w_obj - alpha * c_t + alpha
        if bg_raw < T or obj_raw > bg_raw:
            return n
        w_bg, w_obj = bg_raw / (bg_raw + obj_raw), obj_raw / (bg_raw + obj_raw)


# -- A1 -------------------------------------------------------------------------------------------


def test_constant_pixel_is_background_by_the_second_frame(scene):
    model = ForegroundModel()
    still = np.clip(scene[0], 0, 255).astype(np.uint8)
    results = [model.apply(still) for _ in range(3)]
    assert [int(r.mog_mask.sum()) for r in results] == [0, 0, 0]  # A1: background after at most 2 frames
    noisy = ForegroundModel()
    results = [noisy.apply(render(scene, i)) for i in range(5)]
    assert all(r.valid for r in results)
    assert max(r.mog_mask.mean() for r in results) < 0.005  # σ = 3 noise: a few tail pixels at most


def test_step_is_foreground_at_the_first_frame():
    model = ForegroundModel()
    for _ in range(10):
        model.apply(np.full((H, W, 3), 100, np.uint8))
    frame = np.full((H, W, 3), 100, np.uint8)
    frame[50:100, 60:120] = 200
    r = model.apply(frame)
    assert r.mog_mask[50:100, 60:120].all()
    assert not r.mog_mask[:50].any()
    # a grey step by 2x is neither a shadow nor a highlight (a = 2 > 1.6): an object
    assert (r.labels[50:100, 60:120] == PixelLabel.FOREGROUND).all()


def test_mog2_weight_recursion_near_a1_figure():
    # A1 quotes 62 frames for OpenCV's older MOG, whose background weight starts at 0.952; MOG2's starts at 1,
    # so without pruning and normalisation it would be ln(T) / ln(1 − α) = 71.2 frames
    n = mog2_absorption_frames(0.005, 0.7)
    assert abs(n - np.log(0.7) / np.log(0.995)) < 4
    assert mog2_absorption_frames(0.05, 0.7) < 10  # at 10 α (illumination relearning) within 10 frames


# -- A2 -------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def stop_and_go(scene):
    """A2's scenario: the rectangle enters at 3 px/frame, stops for 1000 frames, then leaves at 3 px/frame."""
    warm, speed, u_stop = 250, 3, 150
    positions: list[int | None] = [None] * warm
    positions += list(range(-RECT_W, u_stop, speed))
    stop = len(positions)
    positions += [u_stop] * 1000
    leave = len(positions)
    positions += list(range(u_stop + speed, W, speed))
    model = ForegroundModel()
    footprint = rect_mask(u_stop)
    kept, kept_mog, ghost, ghost_mog, other = [], [], [], [], []
    for i, u0 in enumerate(positions):
        r = model.apply(render(scene, i, u0))
        if stop <= i < leave:
            kept.append(r.mask[footprint].mean())
            kept_mog.append(r.mog_mask[footprint].mean())
        elif i >= leave:
            uncovered = footprint & ~rect_mask(u0)
            ghost.append(r.mask[uncovered].sum() / footprint.sum())
            ghost_mog.append(r.mog_mask[uncovered].sum() / footprint.sum())
        if i >= warm:
            other.append(r.mask[~footprint & ~rect_mask(u0 if u0 is not None else -RECT_W)].mean())
    return dict(kept=np.array(kept), kept_mog=np.array(kept_mog), ghost=np.array(ghost),
                ghost_mog=np.array(ghost_mog), other=np.array(other))


def test_conventional_mog_absorbs_the_stopped_object(stop_and_go):
    lost = int(np.argmax(stop_and_go["kept_mog"] < 0.10))  # frames after the stop
    n_star = mog2_absorption_frames(0.005, 0.7)
    # the last columns were covered on the stop frame itself, the first ones up to 13 frames before it
    assert n_star - 3 <= lost <= n_star + 2, (lost, n_star)
    assert stop_and_go["kept_mog"][: n_star - 15].min() > 0.98


def test_augmented_mask_keeps_the_stopped_object_for_1000_frames(stop_and_go):
    assert stop_and_go["kept"].size == 1000
    assert stop_and_go["kept"].min() >= 0.98


def test_no_ghost_three_frames_after_it_leaves(stop_and_go):
    assert stop_and_go["ghost_mog"][3] > 0.05  # without A2 the uncovered background is a ghost
    assert stop_and_go["ghost"][3:].max() <= 0.01
    assert stop_and_go["other"].max() < 0.002  # and nothing else lights up


def test_moving_rectangle_adds_no_lasting_augmented_pixels(scene):
    model = ForegroundModel()
    p = model.params.stopped
    for i in range(100):
        model.apply(render(scene, i))
    run = np.zeros((H, W), np.int32)
    longest = 0
    for i, u0 in enumerate(range(-RECT_W, W, 2)):  # 2 px/frame
        r = model.apply(render(scene, 100 + i, u0))
        added = r.augmented_mask & ~r.mog_mask
        run = np.where(added, run + 1, 0)
        longest = max(longest, int(run.max()))
    assert longest <= p.n_stop + p.n_release


def test_bumped_camera_does_not_fill_the_augmented_mask(scene):
    # the camera moves by (3, 2) px for good: 70 % of the textured frame changes at once, A2's mass triggers are
    # suppressed (their new colour becomes the background) and MoG relearns at 10 α
    model = ForegroundModel()
    for i in range(100):
        model.apply(render(scene, i))
    shift = np.float32([[1, 0, 3], [0, 1, 2]])
    results = [model.apply(cv2.warpAffine(render(scene, i), shift, (W, H), borderMode=cv2.BORDER_REFLECT))
               for i in range(100, 160)]
    assert model.augmented.suppressed_frames >= 1
    assert max(r.augmented_mask.mean() for r in results) < 0.05
    assert max(r.augmented_mask.mean() for r in results[25:]) < 0.001
    assert max(r.mask.mean() for r in results[MOG_RECOVERY_FRAMES:]) < 0.005


# -- A3 in a frame ---------------------------------------------------------------------------------


def test_cast_shadow_is_labelled_and_removed(scene):
    model = ForegroundModel()
    for i in range(100):
        model.apply(render(scene, i))
    bg, noise = scene
    f = bg.copy()
    f[100:180, 100:140] = COLOUR  # the object
    f[180:200, 100:180] *= 0.6  # its ground shadow (the simulator's SHADOW_GAIN)
    f[20:40, 200:260] *= 1.3  # a highlight
    r = model.apply(np.clip(f + noise[0], 0, 255).astype(np.uint8))
    assert (r.labels[100:180, 100:140] == PixelLabel.FOREGROUND).mean() > 0.99
    assert (r.labels[182:198, 102:178] == PixelLabel.SHADOW).mean() > 0.95
    assert (r.labels[22:38, 202:258] == PixelLabel.HIGHLIGHT).mean() > 0.95
    assert r.mask[180:200, 100:180].mean() < 0.02
    assert np.array_equal(r.mask, r.labels == PixelLabel.FOREGROUND)


# -- illumination, black frames, bad input ---------------------------------------------------------

RECOVERY_FRAMES = 1  # object mask below 1 % of the frame from the first frame after the jump
MOG_RECOVERY_FRAMES = 10  # the raw MoG mask, relearning at 10 α


@pytest.mark.parametrize("gain", [0.35, 0.7, 1.3, 1.8])
def test_illumination_jump_recovers(scene, gain):
    model = ForegroundModel()
    for i in range(100):
        model.apply(render(scene, i))
    results = [model.apply(render(scene, i, gain=gain)) for i in range(100, 160)]
    assert results[0].relearning
    assert model.n_illumination_events == 1
    assert max(r.mask.mean() for r in results[RECOVERY_FRAMES - 1:]) < (0.03 if gain > 1.6 else 0.01)
    assert max(r.mask.mean() for r in results[MOG_RECOVERY_FRAMES:]) < 0.001
    assert max(r.mog_mask.mean() for r in results[MOG_RECOVERY_FRAMES:]) < 0.001
    assert max(r.augmented_mask.mean() for r in results) == 0.0


@pytest.mark.parametrize("gain", [0.35, 1.3])
def test_people_stay_foreground_during_an_illumination_jump(scene, gain):
    # MoG relearning at 10 α absorbs whatever sits on a pixel for ~8 frames; A2 (rescaled by the measured
    # gain) keeps the moving rectangle, and nothing else becomes "stopped"
    model = ForegroundModel()
    for i in range(100):
        model.apply(render(scene, i))
    for i, u0 in enumerate(range(20, 200, 3)):
        r = model.apply(render(scene, 100 + i, u0, gain=gain))
        assert r.mask[rect_mask(u0)].mean() > 0.95
        assert r.mask[~rect_mask(u0)].mean() < 0.005
    assert r.augmented_mask[~rect_mask(u0)].mean() < 0.001  # a few pixels where the dimmed colours coincide


def test_black_frame_mid_stream_is_skipped(scene, caplog):
    model = ForegroundModel()
    for i in range(50):
        model.apply(render(scene, i))
    with caplog.at_level(logging.WARNING, logger="fusiontrack.vision.foreground"):
        for _ in range(3):
            r = model.apply(np.zeros((H, W, 3), np.uint8))
            assert not r.valid
            assert not r.mask.any()
            assert r.labels.shape == (H, W)
    assert sum("black frame" in rec.message for rec in caplog.records) == 1  # warned once
    assert model.n_skipped == 3
    assert model.n_frames == 50
    r = model.apply(render(scene, 50))
    assert r.valid
    assert r.mask.mean() < 0.001


def test_black_first_frame_then_video(scene):
    model = ForegroundModel()
    assert not model.apply(np.zeros((H, W, 3), np.uint8)).valid
    assert model.shape is None
    for i in range(5):
        r = model.apply(render(scene, i))
    assert r.valid
    assert r.mask.mean() < 0.001


def test_grey_frames_and_image_records(scene):
    model = ForegroundModel()
    grey = cv2.cvtColor(render(scene, 0), cv2.COLOR_BGR2GRAY)
    assert model.apply(grey).labels.shape == (H, W)
    r = model.apply(Image(0, "camera", "camera", cv2.cvtColor(render(scene, 1), cv2.COLOR_BGR2GRAY), "mono8"))
    assert r.valid
    assert r.mask.mean() < 0.01


@pytest.mark.parametrize(("frame", "match"), [
    (np.zeros((H, W, 3), np.float32), "dtype"),
    (np.zeros((H, W, 4), np.uint8), "shape"),
    (np.zeros((0, 0, 3), np.uint8), "empty"),
    ([[1, 2], [3, 4]], "numpy array"),
    (Image(0, "cam", "cam", np.zeros((4, 4), np.uint16), "mono16"), "mono16"),
])
def test_bad_frames_raise(frame, match):
    with pytest.raises(ValueError, match=match) as info:
        ForegroundModel().apply(frame)
    assert "frame" in str(info.value)


def test_size_change_raises(scene):
    model = ForegroundModel()
    model.apply(render(scene, 0))
    with pytest.raises(ValueError, match="differs from the first frame"):
        model.apply(np.zeros((120, 160, 3), np.uint8))


@pytest.mark.parametrize(("field", "value"), [
    ("history", 0), ("n_mixtures", 9), ("background_ratio", 1.5), ("lambda_m", -1.0),
    ("illumination_fraction", 0.0), ("black_level", 300.0), ("var_min", 100.0), ("background_every", 0),
])
def test_bad_params_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        ForegroundParams(**{field: value})


def test_plain_mog_switches_a2_and_a3_off(scene):
    model = ForegroundModel(ForegroundParams(stopped=None, shadows=None))
    for i in range(20):
        r = model.apply(render(scene, i, 10 + 3 * i))
    assert model.augmented is None
    assert not r.augmented_mask.any()
    assert np.array_equal(r.mask, r.mog_mask)
