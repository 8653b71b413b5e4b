"""A3 shadow/highlight labels against ALGORITHMS.md's known answers (E = (120, 120, 120))."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.vision import PixelLabel, ShadowParams, brightness_chromaticity, shadow_highlight_labels

E = np.array([120.0, 120.0, 120.0])


@pytest.mark.parametrize(("x", "label"), [
    (0.6 * E, PixelLabel.SHADOW),
    (1.3 * E, PixelLabel.HIGHLIGHT),
    (np.array([170.0, 70.0, 120.0]), PixelLabel.FOREGROUND),  # CD ≈ 0.34
    (0.3 * E, PixelLabel.FOREGROUND),  # too dark to be a shadow
    (E, PixelLabel.FOREGROUND),  # a = 1 is in neither band (the pixel is in M for another reason)
    (2.0 * E, PixelLabel.FOREGROUND),  # brighter than the highlight band
])
def test_a3_known_answers(x, label):
    assert shadow_highlight_labels(x, E) == label
    assert shadow_highlight_labels(x.astype(np.uint8), E.astype(np.uint8)) == label


def test_a3_distortions():
    a, cd = brightness_chromaticity(np.array([[170.0, 70.0, 120.0], [72.0, 72.0, 72.0]]), E)
    assert a[0] == pytest.approx(1.0)  # (170 + 70 + 120) / 360
    assert cd[0] == pytest.approx(np.hypot(50, 50) / np.linalg.norm(E), abs=1e-4)  # 0.340
    assert cd[0] == pytest.approx(0.34, abs=0.005)
    assert a[1] == pytest.approx(0.6)
    assert cd[1] == pytest.approx(0.0, abs=1e-6)


def test_scaling_invariants():
    rng = np.random.default_rng(1)
    e = rng.uniform(30, 220, (500, 3))
    k = rng.uniform(0.2, 1.1, (500, 1))
    a, cd = brightness_chromaticity(k * e, e)
    np.testing.assert_allclose(a, k[:, 0], rtol=1e-5)
    np.testing.assert_allclose(cd, 0.0, atol=1e-3)
    # chromaticity distortion does not depend on the brightness of x
    x = rng.uniform(30, 220, (500, 3))
    _, cd1 = brightness_chromaticity(x, e)
    _, cd2 = brightness_chromaticity(0.5 * x, e)
    np.testing.assert_allclose(cd1, cd2, rtol=1e-4, atol=1e-5)


def test_edge_cases_dark_background_and_saturation():
    dark = np.array([10.0, 10.0, 10.0])  # ||E|| = 17 < 20
    assert shadow_highlight_labels(0.6 * dark, dark) == PixelLabel.FOREGROUND
    bright = np.array([200.0, 200.0, 200.0])
    assert shadow_highlight_labels(np.array([255, 255, 255], np.uint8), bright) == PixelLabel.FOREGROUND
    assert shadow_highlight_labels(np.array([250, 250, 250], np.uint8), bright) == PixelLabel.HIGHLIGHT


def test_image_shaped_input_and_params():
    e = np.full((4, 5, 3), 120.0)
    x = e.copy()
    x[0] *= 0.6
    x[1] *= 1.3
    labels = shadow_highlight_labels(x, e)
    assert labels.shape == (4, 5)
    assert labels.dtype == np.uint8
    assert (labels[0] == PixelLabel.SHADOW).all()
    assert (labels[1] == PixelLabel.HIGHLIGHT).all()
    assert (labels[2:] == PixelLabel.FOREGROUND).all()
    narrow = ShadowParams(shadow_min=0.7)
    assert (shadow_highlight_labels(x[0], e[0], narrow) == PixelLabel.FOREGROUND).all()


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"tau_cd": -0.1}, "tau_cd"), ({"shadow_min": 0.96}, "shadow_min"), ({"highlight_max": 1.0}, "highlight_min"),
    ({"dark_norm": np.nan}, "dark_norm"), ({"saturated": 0}, "saturated"),
])
def test_bad_params(kwargs, field):
    with pytest.raises(ValueError, match=field):
        ShadowParams(**kwargs)


def test_bad_shapes():
    with pytest.raises(ValueError, match="pixels"):
        shadow_highlight_labels(np.zeros((4, 2)), E)
    with pytest.raises(ValueError, match="background"):
        brightness_chromaticity(E, np.zeros(4))
