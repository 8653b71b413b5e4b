"""A4 blob extraction on hand-drawn masks with known boxes, areas and centroids."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from fusiontrack.vision import BlobParams, blob_contours, blob_histograms, clean_mask, extract_blobs

H, W = 240, 320


def test_two_rectangles_give_two_blobs_with_exact_boxes():
    m = np.zeros((H, W), bool)
    m[50:130, 40:80] = True  # 40 x 80
    m[100:160, 200:230] = True  # 30 x 60
    b = extract_blobs(m)
    assert len(b) == 2
    np.testing.assert_array_equal(b.boxes_px, [[40, 50, 80, 130], [200, 100, 230, 160]])
    np.testing.assert_array_equal(b.areas_px, [3200, 1800])
    np.testing.assert_allclose(b.centroids_px, [[59.5, 89.5], [214.5, 129.5]])
    np.testing.assert_allclose(b.bottom_centres_px, [[60, 130], [215, 160]])
    assert (b.mask(0) == (np.arange(W)[None, :] >= 40) & (np.arange(W)[None, :] < 80)
            & (np.arange(H)[:, None] >= 50) & (np.arange(H)[:, None] < 130)).all()
    image = b.blob_image()
    assert set(np.unique(image)) == {0, 1, 2}
    assert (image[m] > 0).all()


def test_one_pixel_gap_is_closed():
    m = np.zeros((H, W), bool)
    m[50:130, 40:80] = True
    m[90, 40:80] = False  # a horizontal 1-px gap (e.g. a belt)
    m[50:130, 150:190] = True
    m[50:130, 170] = False  # a vertical one
    b = extract_blobs(m)
    assert len(b) == 2
    np.testing.assert_array_equal(b.boxes_px, [[40, 50, 80, 130], [150, 50, 190, 130]])
    assert len(extract_blobs(m, BlobParams(close_px=0))) == 4  # without closing: 4 pieces


def test_speckle_and_small_blobs_are_dropped():
    rng = np.random.default_rng(0)
    m = rng.random((H, W)) < 0.02  # isolated noise pixels: opening removes them
    m[10:18, 10:18] = True  # 64 px < A_min = 0.001 * 240 * 320 = 77 (76.8 rounded up)
    m[100:109, 100:109] = True  # 81 px >= 77
    b = extract_blobs(m)
    assert BlobParams().min_area(H, W) == 77
    assert len(b) == 1
    np.testing.assert_array_equal(b.boxes_px[0], [100, 100, 109, 109])
    assert len(extract_blobs(m, BlobParams(min_area_px=50))) == 2


def test_empty_and_full_masks():
    b = extract_blobs(np.zeros((H, W), bool))
    assert len(b) == 0
    assert b.boxes_px.shape == (0, 4)
    assert b.centroids_px.shape == (0, 2)
    assert blob_contours(b) == []
    assert blob_histograms(np.zeros((H, W, 3), np.uint8), b).shape == (0, 256)
    full = extract_blobs(np.ones((H, W), np.uint8))
    np.testing.assert_array_equal(full.boxes_px, [[0, 0, W, H]])


def test_contours_outline_the_blobs():
    m = np.zeros((H, W), np.uint8)
    m[50:130, 40:80] = 255
    cv2.circle(m, (220, 120), 30, 255, -1)
    b = extract_blobs(m)
    contours = blob_contours(b)
    assert len(contours) == 2
    for k, c in enumerate(contours):
        x, y, w, h = cv2.boundingRect(c)
        np.testing.assert_array_equal([x, y, x + w, y + h], b.boxes_px[k])
        assert c.dtype == np.int32
        assert c.shape[1:] == (1, 2)


def test_histograms_of_coloured_blobs():
    frame = np.zeros((H, W, 3), np.uint8)
    frame[50:130, 40:80] = (0, 0, 255)  # red (BGR)
    frame[100:160, 200:230] = (255, 0, 0)  # blue
    b = extract_blobs(frame.any(axis=2))
    hist = blob_histograms(frame, b)
    assert hist.shape == (2, 8 * 8 * 4)
    np.testing.assert_allclose(hist.sum(1), 1.0)
    red_bin = np.ravel_multi_index((0, 7, 3), (8, 8, 4))  # hue 0, saturation 255, value 255
    blue_bin = np.ravel_multi_index((120 * 8 // 180, 7, 3), (8, 8, 4))
    assert hist[0, red_bin] == pytest.approx(1.0)
    assert hist[1, blue_bin] == pytest.approx(1.0)


def test_clean_mask_and_bad_input():
    m = np.zeros((20, 20), bool)
    m[5, 5] = True
    assert clean_mask(m).sum() == 0
    assert clean_mask(m, BlobParams(open_px=0, close_px=0)).sum() == 1
    with pytest.raises(ValueError, match="mask"):
        extract_blobs(np.zeros((4, 4, 3), bool))
    with pytest.raises(ValueError, match="mask"):
        extract_blobs(np.zeros((4, 4), np.float32))
    with pytest.raises(ValueError, match="empty"):
        extract_blobs(np.zeros((0, 5), bool))
    with pytest.raises(ValueError, match="connectivity"):
        BlobParams(connectivity=6)
    with pytest.raises(ValueError, match="open_px"):
        BlobParams(open_px=-1)
    with pytest.raises(ValueError, match="frame_bgr"):
        blob_histograms(np.zeros((4, 4, 3), np.uint8), extract_blobs(np.ones((5, 5), bool)))
    with pytest.raises(IndexError):
        extract_blobs(np.ones((5, 5), bool)).mask(3)
