"""Reusing one image's integral images (``IntegralCache``, ``AppearanceBank.cache_image``) changes no number: the
features, box scores and score maps are bit for bit those computed afresh for each set of patches."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from fusiontrack.vision.appearance import AppearanceBank
from fusiontrack.vision.patches import (
    FeatureParams,
    IntegralCache,
    PatchParams,
    box_visibility,
    extract_features,
    integral_channels,
    orientation_energy,
    sample_patches,
)

H, W = 240, 320


def _image(seed: int = 0) -> np.ndarray:
    """Smooth shading (gradients near the threshold, in every orientation) plus blocks and noise."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:H, 0:W]
    shade = 120 + 60 * np.sin(x / 17.0) * np.cos(y / 23.0)
    blocks = np.kron(rng.uniform(-40, 40, (H // 8, W // 8)), np.ones((8, 8)))
    img = shade[..., None] + blocks[..., None] + rng.normal(0, 6, (H, W, 3)) + np.array([0, 15, -15])
    return np.clip(img, 0, 255).astype(np.uint8)


def _draw(rng: np.random.Generator, box: tuple[float, ...], n: int = 150):
    return sample_patches(np.array([box], float), (H, W), PatchParams(min_visible=0.0), rng,
                          counts=np.array([n]))


@pytest.mark.parametrize("params", [FeatureParams(), FeatureParams(colour="rgb", grad_threshold=2.5)])
def test_features_from_a_larger_region_equal_fresh_ones(params):
    img = _image()
    rng = np.random.default_rng(1)
    cache = IntegralCache(img, params)
    # a wide region first (touching the image's left and top edges), then regions inside it, then outside it
    boxes = [(0, 0, 200, 180), (30, 20, 90, 150), (0, 100, 60, 180), (150, 10, 200, 60), (210, 60, 320, 240),
             (250, 100, 300, 200), (100, 150, 230, 240)]
    for box in boxes:
        p = _draw(rng, box)
        np.testing.assert_array_equal(cache.features(p), extract_features(img, p, params))
    assert cache.reused >= 3
    assert cache.built + cache.reused == len(boxes)


def test_a_threshold_too_small_for_exact_sums_reuses_nothing():
    img = _image(2)
    params = FeatureParams(grad_threshold=0.0)
    cache = IntegralCache(img, params)
    rng = np.random.default_rng(3)
    for box in [(0, 0, 300, 200), (40, 40, 120, 160), (50, 60, 100, 110)]:
        p = _draw(rng, box)
        np.testing.assert_array_equal(cache.features(p), extract_features(img, p, params))
    assert cache.reused == 0
    assert cache.built == 3


def test_a_bank_scores_the_cached_image_as_without_the_cache():
    img = _image(4)
    img.setflags(write=False)  # the bank caches read-only images only (as the tracker's)
    boxes = {1: (40, 40, 90, 170), 2: (100, 50, 150, 180), 3: (200, 60, 250, 200)}
    banks = []
    for cached in (False, True):
        bank = AppearanceBank(rng=7)
        for k in range(3):
            frame = np.roll(_image(10 + k), 3 * k, axis=1)
            frame.setflags(write=False)
            if cached:
                bank.cache_image(frame)
            bank.train(frame, boxes)
        if cached:
            bank.cache_image(img)
        maps = bank.score_map(img, [1, 2], boxes_px=np.array([boxes[1], boxes[2]], float))
        sc = [bank.box_scores(img, np.array([boxes[1], boxes[2]], float), [1, 2]),
              bank.box_scores(img, np.array([boxes[3]], float), [3, 1]),
              bank.box_scores(img.copy(), np.array([boxes[2]], float))]  # another array: not from the cache
        bank.train(img, boxes, train_ids=[2])
        banks.append((maps, sc, bank.box_scores(img, np.array([boxes[2]], float), [2])))
        if cached:  # the cached run did reuse integral images (else this test compares two uncached runs)
            assert bank._integrals.reused > 0
    (m0, s0, t0), (m1, s1, t1) = banks
    np.testing.assert_array_equal(m0.scores, m1.scores)
    np.testing.assert_array_equal(m0.centres_px, m1.centres_px)
    for a, b in zip(s0, s1, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(t0, t1)


def test_box_visibility_of_partial_empty_and_non_finite_boxes():
    boxes = np.array([[-10, 0, 10, 20], [300, 230, 340, 250], [0, 0, 0, 10], [np.nan, 0, 10, 10],
                      [-np.inf, 0, 10, 10], [0, 0, np.inf, 10], [400, 0, 420, 10]])
    np.testing.assert_allclose(box_visibility(boxes, (H, W)), [0.5, 0.25, 0.0, 0.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("params", [FeatureParams(), FeatureParams(n_bins=6, grad_threshold=3.0),
                                    FeatureParams(grad_threshold=0.0)])
def test_orientation_energy_is_the_per_pixel_definition(params):
    # B13 written out for every pixel: the magnitude in the bin of the unsigned orientation, 0 at or below tau_G
    # (the implementation takes arctan2 of the strong pixels only)
    grey = _image(5)[..., 1].astype(np.float32)
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    mag = np.sqrt(gx * gx + gy * gy)
    k = params.n_bins
    b = np.floor(np.arctan2(gy, gx) * (k / np.pi) + 0.5).astype(np.int64) % k
    expected = np.where((np.arange(k) == b[..., None]) & (mag > params.grad_threshold)[..., None], mag[..., None], 0)
    np.testing.assert_array_equal(orientation_energy(grey, params), expected.astype(np.float32))
    # and the integral images of a region hold the same psi (its sums over single pixels)
    x0, y0, x1, y1 = 37, 21, 150, 130
    table = integral_channels(_image(5), params, (x0, y0, x1, y1)).table
    psi = np.diff(np.diff(table, axis=0), axis=1)[..., 3:]
    full = orientation_energy(cv2.cvtColor(_image(5), cv2.COLOR_BGR2GRAY).astype(np.float32), params)
    np.testing.assert_allclose(psi, full[y0:y1, x0:x1], atol=1e-6 * max(1.0, float(table[-1, -1, 3:].max())))


def test_a_writeable_image_is_not_cached():
    # a buffer refilled in place with the next frame must not give the previous frame's features
    boxes = {1: (40, 40, 90, 170), 2: (100, 50, 150, 180), 3: (200, 60, 250, 200)}
    query = np.array([boxes[1], boxes[2]], float)

    def trained() -> AppearanceBank:
        bank = AppearanceBank(rng=3)
        for k in range(3):
            bank.train(np.roll(_image(10 + k), 3 * k, axis=1), boxes)
        return bank

    bank, fresh = trained(), trained()  # the same classifiers and random streams
    frame = _image(5)
    bank.cache_image(frame)
    whole = np.array([[0, 0, W, H]], float)  # its patches span (nearly) the whole image: a region every later
    first = bank.box_scores(frame, np.vstack([whole, query]), [1, 2])  # scoring could reuse
    np.testing.assert_array_equal(fresh.box_scores(frame.copy(), np.vstack([whole, query]), [1, 2]), first)
    frame[:] = np.roll(_image(5), 60, axis=1)  # the next frame, in the same buffer
    bank.cache_image(frame)
    expected = fresh.box_scores(frame.copy(), query, [1, 2])
    assert not np.array_equal(first[1:], expected)  # the frames differ where the boxes are
    np.testing.assert_array_equal(bank.box_scores(frame, query, [1, 2]), expected)
