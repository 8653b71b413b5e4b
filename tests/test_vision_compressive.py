"""Compressive tracking (ALGORITHMS.md X3, C10, C11) against known answers, the reference code's arithmetic,
brute-force sums, and a textured patch moving over a textured background."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from fusiontrack.vision.compressive import (
    CompressiveParams,
    CompressiveTracker,
    CtTemplate,
    HaarFeatures,
    MultiTemplateParams,
    consistency,
    ct_response,
    disk_offsets,
    failure_threshold,
    haar_features,
    integral_image,
    make_haar_features,
    rect_sums,
    update_gaussians,
)

# ---- X3 -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [np.uint8, np.float64, np.int32])
def test_integral_image_sums_equal_direct_sums(dtype):
    rng = np.random.default_rng(0)
    img = (rng.random((50, 40)) * 255).astype(dtype)  # X3 test: a random 50x40 image
    ii = integral_image(img)
    assert ii.shape == (51, 41)
    assert np.all(ii[0] == 0)
    assert np.all(ii[:, 0] == 0)
    x0, x1 = np.sort(rng.integers(0, 41, (2, 500)), axis=0)
    y0, y1 = np.sort(rng.integers(0, 51, (2, 500)), axis=0)
    want = np.array([img[a:b, c:d].sum(dtype=np.float64) for a, b, c, d in zip(y0, y1, x0, x1, strict=True)])
    np.testing.assert_allclose(rect_sums(ii, x0, y0, x1, y1), want, rtol=1e-12, atol=1e-9)
    # multi-channel: one integral image per channel
    cube = rng.integers(0, 2, (50, 40, 7))
    iic = integral_image(cube)
    np.testing.assert_array_equal(rect_sums(iic, 3, 4, 30, 45), cube[4:45, 3:30].sum(axis=(0, 1)))


# ---- C10: features and classifier ---------------------------------------------------------------


def test_feature_bank_is_sparse_and_inside_the_box():
    f = make_haar_features(40, 60, n_features=50, rng=7)
    assert f.n_features == 50
    assert set(np.unique(f.n_rects)) <= {2, 3}  # floor(U(2, 4)): erratum E12
    for k in (2, 3):
        w = np.abs(f.weights[f.n_rects == k][:, :k])
        np.testing.assert_allclose(w, 1 / math.sqrt(k))
    used = f.weights != 0
    x, y, w, h = (f.rects[..., i][used] for i in range(4))
    assert np.all((x >= 0) & (y >= 0) & (w >= 1) & (h >= 1) & (x + w <= 40) & (y + h <= 60))
    signs = np.sign(f.weights[used])
    assert 0.3 < np.mean(signs > 0) < 0.7  # fair signs


def test_feature_values_equal_brute_force():
    rng = np.random.default_rng(2)
    img = rng.integers(0, 256, (80, 100), dtype=np.uint8)
    f = make_haar_features(30, 20, n_features=12, rng=3)
    origins = np.array([[0, 0], [70, 60], [13, 27]])
    got = haar_features(integral_image(img), f, origins)
    for j, (ox, oy) in enumerate(origins):
        for i in range(f.n_features):
            want = sum(wt * img[oy + y:oy + y + h, ox + x:ox + x + w].astype(float).sum()
                       for (x, y, w, h), wt in zip(f.rects[i], f.weights[i], strict=True) if wt != 0)
            assert got[i, j] == pytest.approx(want)


def test_update_arithmetic_known_answer():
    # C10 test: old μ = 0, σ = 1; batch mean 10, std 2; λ = 0.85 -> μ = 1.5, σ = sqrt(0.85 + 0.6 + 12.75)
    mu, sigma = update_gaussians(np.zeros(1), np.ones(1), np.array([[8.0, 12.0]]), 0.85)
    assert mu[0] == pytest.approx(1.5)
    assert sigma[0] == pytest.approx(math.sqrt(0.85 + 0.6 + 12.75))
    assert sigma[0] == pytest.approx(3.768, abs=5e-4)
    # λ = 0 takes the batch statistics, λ = 1 keeps the old ones
    mu0, s0 = update_gaussians(np.array([3.0]), np.array([5.0]), np.array([[8.0, 12.0]]), 0.0)
    assert (mu0[0], s0[0]) == (10.0, 2.0)
    mu1, s1 = update_gaussians(np.array([3.0]), np.array([5.0]), np.array([[8.0, 12.0]]), 1.0)
    assert (mu1[0], s1[0]) == (3.0, 5.0)


def test_response_matches_the_reference_code_loop():
    # radioClassifier of the authors' C++ code, transliterated scalar by scalar
    rng = np.random.default_rng(4)
    n_f, n_s = 6, 5
    t = CtTemplate(rng.normal(0, 50, n_f), rng.uniform(1, 30, n_f), rng.normal(0, 50, n_f), rng.uniform(1, 30, n_f))
    v = rng.normal(0, 60, (n_f, n_s))
    v[0, 0] = 1e4  # far in both tails: exp underflows and the 1e-30 guards decide
    want = []
    for j in range(n_s):
        s = 0.0
        for i in range(n_f):
            mp, sp, mn, sn = t.mu_pos[i], t.sigma_pos[i], t.mu_neg[i], t.sigma_neg[i]
            p_pos = math.exp((v[i, j] - mp) ** 2 / -(2 * sp**2 + 1e-30)) / (sp + 1e-30)
            p_neg = math.exp((v[i, j] - mn) ** 2 / -(2 * sn**2 + 1e-30)) / (sn + 1e-30)
            s += math.log(p_pos + 1e-30) - math.log(p_neg + 1e-30)
        want.append(s)
    np.testing.assert_allclose(ct_response(v, t), want, rtol=1e-12)


def test_sampling_rings_have_the_papers_counts():
    assert len(disk_offsets(4)) == 45  # the paper's 45 positives
    assert len(disk_offsets(25)) == 1941  # the C++ detection set
    neg = disk_offsets(37.5, 8)
    d2 = (neg**2).sum(axis=1)
    assert d2.min() >= 64
    assert d2.max() < 37.5**2


def test_prior_initialisation_blends_like_the_reference_code():
    rng = np.random.default_rng(5)
    frame = rng.integers(0, 256, (120, 160), dtype=np.uint8)
    box = (60, 30, 100, 90)
    ref = CompressiveTracker(frame, box, CompressiveParams(init="prior"), rng=1)
    fresh = CompressiveTracker(frame, box, CompressiveParams(init="first_frame"), rng=1)
    np.testing.assert_array_equal(ref.features.rects, fresh.features.rects)  # same draws
    # μ = λ·0 + (1 − λ)·μ_b: the reference start is 15 % of the first frame's positive means
    np.testing.assert_allclose(ref.template.mu_pos, 0.15 * fresh.template.mu_pos, rtol=1e-12)


# ---- C10: tracking ------------------------------------------------------------------------------


def _texture(shape, rng, blur, lo=40, hi=220):
    t = cv2.GaussianBlur(rng.random(shape), (0, 0), blur)
    t = (t - t.min()) / np.ptp(t)
    return (lo + (hi - lo) * t).astype(np.uint8)


def moving_patch(seed: int, n: int = 101, size: tuple[int, int] = (40, 60)):
    """A textured 40x60 patch on a smooth noise background (320x240), at most 8 px per frame, with noise."""
    rng = np.random.default_rng(seed)
    bg = _texture((240, 320), rng, 6)
    patch = _texture((size[1], size[0]), rng, 1.5, 0, 255)
    t = np.arange(n)
    cx = 160 + 110 * np.sin(2 * np.pi * t / 90)
    cy = 120 + 50 * np.sin(2 * np.pi * t / 60)
    frames, centres = [], []
    for k in range(n):
        f = bg.copy()
        u0, v0 = round(cx[k] - size[0] / 2), round(cy[k] - size[1] / 2)
        f[v0:v0 + size[1], u0:u0 + size[0]] = patch
        frames.append(np.clip(f + rng.normal(0, 3, f.shape), 0, 255).astype(np.uint8))
        centres.append([u0 + size[0] / 2, v0 + size[1] / 2])
    return frames, np.array(centres)


@pytest.mark.parametrize("seed", range(4))
def test_tracks_a_textured_patch(seed):
    frames, centres = moving_patch(seed)
    assert np.abs(np.diff(centres, axis=0)).max() <= 8
    box = np.r_[centres[0] - [20, 30], centres[0] + [20, 30]]
    ct = CompressiveTracker(frames[0], box, rng=seed)
    err = [np.linalg.norm(ct.step(f).centre_px - c) for f, c in zip(frames[1:], centres[1:], strict=True)]
    assert np.mean(err) < 4.0  # C10 test: mean centre error < 4 px over 100 frames
    assert np.max(err) < 10.0
    # BGR frames are converted to grey
    ct2 = CompressiveTracker(cv2.cvtColor(frames[0], cv2.COLOR_GRAY2BGR), box, rng=seed)
    r = ct2.step(cv2.cvtColor(frames[1], cv2.COLOR_GRAY2BGR))
    assert np.linalg.norm(r.centre_px - centres[1]) < 10
    assert r.n_candidates == 1941


# ---- C11 ----------------------------------------------------------------------------------------


def test_consistency_known_answers():
    assert failure_threshold() == pytest.approx(0.05, abs=1e-4)  # exp(−½·5.991)
    assert consistency([10.0, 20.0], [10.0, 20.0], np.eye(2)) == 1.0
    # Mahalanobis d² = 5.991 gives sim = 0.05: along x with σ_x = 3 px
    d = math.sqrt(5.991) * 3
    assert consistency([d, 0.0], [0.0, 0.0], np.diag([9.0, 1.0])) == pytest.approx(0.0500, abs=1e-4)
    batch = consistency(np.zeros((3, 2)), [[0, 0], [1, 0], [0, 2]], np.eye(2))
    np.testing.assert_allclose(batch, [1.0, math.exp(-0.5), math.exp(-2.0)])


# ---- bad input ----------------------------------------------------------------------------------


def test_bad_input_names_the_parameter():
    frame = np.zeros((120, 160), np.uint8)
    with pytest.raises(ValueError, match="learning_rate"):
        CompressiveParams(learning_rate=1.5)
    with pytest.raises(ValueError, match="n_features"):
        CompressiveParams(n_features=0)
    with pytest.raises(ValueError, match="negative_inner_px"):
        CompressiveParams(negative_inner_px=50)
    with pytest.raises(ValueError, match="init"):
        CompressiveParams(init="zeros")
    with pytest.raises(ValueError, match="tau_sim"):
        MultiTemplateParams(tau_sim=0.0)
    with pytest.raises(ValueError, match="box_px"):
        CompressiveTracker(frame, (10, 10, 5, 40))
    with pytest.raises(ValueError, match="box_px"):
        CompressiveTracker(frame, (100, 10, 200, 40))  # outside the frame
    with pytest.raises(ValueError, match="frame"):
        CompressiveTracker(frame.astype(np.float32), (10, 10, 50, 40))
    ct = CompressiveTracker(frame, (10, 10, 50, 40), rng=0)
    with pytest.raises(ValueError, match="frame"):
        ct.step(np.zeros((100, 100), np.uint8))
    with pytest.raises(ValueError, match="box_w, box_h"):
        make_haar_features(3, 40)
    with pytest.raises(ValueError, match="cov_px2"):
        consistency([0, 0], [1, 1], [[1, 2], [2, 1]])  # not positive definite
    with pytest.raises(ValueError, match="learning_rate"):
        update_gaussians(np.zeros(2), np.ones(2), np.zeros((2, 3)), -0.1)
    with pytest.raises(ValueError, match="values"):
        ct_response(np.zeros((3, 2)), CtTemplate.prior(4))
    with pytest.raises(ValueError, match="rects"):
        HaarFeatures(np.zeros((2, 3, 4)), np.zeros((2, 2)), 10, 10)
