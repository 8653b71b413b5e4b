"""Seed 001's appearance learning on hand-built images and data with known answers (ALGORITHMS.md X3, B12-B16).

Patches (B12): the count formula and the geometry. Features (B13): integral-image sums against brute force (X3),
the EOH of a step edge, a uniform patch and mirror-symmetric patterns against B13's stated values, and an EOH
computed independently with SciPy's Sobel. Boosting (B14): the CART weak learner against scikit-learn's, B14's
own Gaussian tests and the keep-the-K-best rule. Bank (B15-B17): red vs blue textures, confusers, exclusions,
cadence, score-map likelihood (B16) and identity (B17), JSON round trip, bad input.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from scipy import ndimage
from sklearn.metrics import roc_auc_score
from sklearn.tree import DecisionTreeClassifier

from fusiontrack.vision import _cart_jit
from fusiontrack.vision.appearance import (
    AppearanceBank,
    AppearanceParams,
    BoostedClassifier,
    BoostParams,
    fit_cart,
    interacting_region,
    predict_tree,
    score_map_likelihood,
    sklearn_cart,
)
from fusiontrack.vision.patches import (
    FeatureParams,
    Patches,
    PatchParams,
    box_visibility,
    clip_boxes,
    extract_features,
    grid_patches,
    integral_channels,
    orientation_energy,
    patch_counts,
    patch_eoh,
    patch_features,
    patch_fraction,
    sample_patches,
)

H, W = 240, 320
S = 12


def _patches(corners: list[tuple[int, int]] | np.ndarray, s: int = S) -> Patches:
    c = np.asarray(corners, np.int64).reshape(-1, 2)
    return Patches(c, np.zeros(len(c), np.int64), s)


def _textured(rng: np.random.Generator, colour_bgr: tuple[int, int, int], h: int, w: int) -> np.ndarray:
    """A (h, w, 3) uint8 texture: blocks of random brightness (0.5-1.0) of one colour plus grey noise."""
    block = rng.uniform(0.5, 1.0, (h // 4 + 1, w // 4 + 1))
    gain = np.kron(block, np.ones((4, 4)))[:h, :w, None]
    noise = rng.normal(0, 8, (h, w, 3))
    return np.clip(gain * np.array(colour_bgr, float) + noise, 0, 255).astype(np.uint8)


def _scene(rng: np.random.Generator, boxes: dict[int, tuple[int, int, int, int]],
           colours: dict[int, tuple[int, int, int]]) -> np.ndarray:
    """A grey noisy background with one textured rectangle per box (integer box edges)."""
    img = np.clip(rng.normal(120, 10, (H, W, 3)), 0, 255).astype(np.uint8)
    for i, (x0, y0, x1, y1) in boxes.items():
        img[y0:y1, x0:x1] = _textured(rng, colours[i], y1 - y0, x1 - x0)
    return img


# ---------------------------------------------------------------------------------------------------------
# B12 patches
@pytest.mark.parametrize(("w", "h", "expected"), [
    (48, 96, 48),  # 1.5 * 4608 / 144 = 48
    (30, 70, 22),  # 1.5 * 2100 / 144 = 21.875
    (20, 20, 10),  # 4.2 -> clipped to 10
    (200, 230, 150),  # 479 -> clipped to 150
])
def test_patch_count_is_b12_formula(w, h, expected):
    box = np.array([50.0, 5.0, 50.0 + w, 5.0 + h])
    assert patch_counts(box, (H, W))[0] == expected
    assert len(sample_patches(box, (H, W), rng=0)) == expected


def test_patches_lie_inside_box_and_image():
    rng = np.random.default_rng(1)
    x0 = rng.uniform(-60, W - 10, 300)
    y0 = rng.uniform(-80, H - 10, 300)
    boxes = np.column_stack([x0, y0, x0 + rng.uniform(14, 120, 300), y0 + rng.uniform(14, 160, 300)])
    boxes = boxes[box_visibility(boxes, (H, W)) > 0]
    p = sample_patches(boxes, (H, W), rng=rng)
    c = p.corners_px
    assert (c >= 0).all()
    assert (c[:, 0] + S <= W).all()
    assert (c[:, 1] + S <= H).all()
    b = clip_boxes(boxes, (H, W))[p.box_index]
    wide = (b[:, 2:] - b[:, :2] >= S).all(axis=1)  # narrower boxes get centred patches (next test)
    assert wide.mean() > 0.9
    assert (c[wide] >= b[wide, :2]).all()
    assert (c[wide] + S <= b[wide, 2:]).all()
    vis = box_visibility(boxes, (H, W))
    counts = np.bincount(p.box_index, minlength=len(boxes))
    assert (counts[vis < 0.3] == 0).all()
    assert (counts[vis >= 0.3] >= 10).all()


def test_patch_centres_are_uniform_in_the_shrunk_box():
    box = np.array([[40.0, 20.0, 140.0, 220.0]])  # centres uniform in [46, 134] x [26, 214]
    p = sample_patches(box, (H, W), PatchParams(max_count=10**6, density=300.0), rng=3)
    ctr = p.centres_px
    assert len(p) > 20000
    np.testing.assert_allclose(ctr.mean(axis=0), [90, 120], atol=1.0)
    np.testing.assert_allclose(ctr.std(axis=0), [88 / np.sqrt(12), 188 / np.sqrt(12)], rtol=0.03)
    np.testing.assert_array_equal(ctr.min(axis=0), [46, 26])
    np.testing.assert_array_equal(ctr.max(axis=0), [134, 214])


def test_a_box_narrower_than_a_patch_gets_patches_centred_on_it():
    p = sample_patches([100.2, 50.0, 109.0, 120.0], (H, W), rng=0)  # 8.8 px wide person seen edge-on
    assert len(p) == 10
    np.testing.assert_array_equal(np.unique(p.centres_px[:, 0]), [105.0])  # centre 104.6 rounded
    assert len(sample_patches([100.0, 50.0, 105.0, 120.0], (H, W), rng=0)) == 0  # under s/2 wide


def test_grid_patches_cover_the_region():
    p = grid_patches([10, 20, 70, 60], (H, W), S, stride_px=4)
    xs, ys = np.unique(p.corners_px[:, 0]), np.unique(p.corners_px[:, 1])
    np.testing.assert_array_equal(xs, np.arange(10, 59, 4))
    np.testing.assert_array_equal(ys, np.arange(20, 49, 4))
    assert len(p) == len(xs) * len(ys)


# ---------------------------------------------------------------------------------------------------------
# B13 features and X3 integral images
def test_integral_image_sums_equal_brute_force():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (40, 50, 3), dtype=np.uint8)  # ALGORITHMS.md X3: a random 50x40 image
    ii = integral_channels(img)
    psi = orientation_energy(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float32))
    assert psi.shape == (40, 50, 4)
    chans = np.concatenate([img[..., ::-1].astype(float), psi], axis=2)
    x0 = rng.integers(0, 50, 200)
    y0 = rng.integers(0, 40, 200)
    x1 = x0 + rng.integers(0, 50 - x0 + 1)
    y1 = y0 + rng.integers(0, 40 - y0 + 1)
    got = ii.rect_sums(x0, y0, x1, y1)
    want = np.array([chans[a:b, c:d].sum(axis=(0, 1)) for a, b, c, d in zip(y0, y1, x0, x1, strict=True)])
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-6)


def _scipy_eoh(grey: np.ndarray, corners: np.ndarray, k: int = 4, tau: float = 10.0) -> np.ndarray:
    """EOH energies computed independently: SciPy's Sobel, atan2 in float64, one patch at a time."""
    g = grey.astype(np.float64)
    gx = ndimage.sobel(g, axis=1, mode="mirror") / 8.0  # mirror = OpenCV's BORDER_REFLECT_101
    gy = ndimage.sobel(g, axis=0, mode="mirror") / 8.0
    mag = np.hypot(gx, gy)
    theta = np.mod(np.arctan2(gy, gx), np.pi)
    b = np.floor(theta / (np.pi / k) + 0.5).astype(int) % k
    out = []
    for x, y in corners:
        m, bb = mag[y:y + S, x:x + S], b[y:y + S, x:x + S]
        out.append([m[(bb == j) & (m > tau)].sum() for j in range(k)])
    return np.array(out)


def test_integral_eoh_equals_a_direct_per_patch_computation():
    rng = np.random.default_rng(2)
    grey = ndimage.gaussian_filter(rng.uniform(0, 255, (H, W)), 1.5)
    grey = np.round(grey * 3 - 200).clip(0, 255).astype(np.uint8)  # integers: Sobel is exact in float32
    img = np.repeat(grey[..., None], 3, axis=2)
    p = sample_patches([[0, 0, W, H], [100, 80, 200, 160]], (H, W), PatchParams(max_count=200), rng=4)
    want = _scipy_eoh(grey, p.corners_px)
    assert (want > 0).any(axis=0).all()
    whole = patch_eoh(integral_channels(img), p.corners_px, S)
    np.testing.assert_allclose(whole, want, rtol=1e-5, atol=1e-3)
    # integral images of a region only (with its one-pixel gradient margin) give the same sums
    q = p.subset(p.box_index == 1)
    region = patch_eoh(integral_channels(img, region_px=(90, 70, 215, 175)), q.corners_px, S)
    np.testing.assert_allclose(region, want[p.box_index == 1], rtol=1e-5, atol=1e-3)


def test_vertical_step_edge_puts_its_energy_in_the_zero_bin():
    img = np.full((40, 40, 3), 30, np.uint8)
    img[:, 20:] = 220  # vertical edge: the gradient points along x, theta = 0
    e = patch_eoh(integral_channels(img), np.array([[14, 10]]), S)[0]
    assert e[0] >= 0.95 * e.sum() > 0
    f = patch_features(integral_channels(img), np.array([[14, 10]]), S)[0]
    assert np.argmax(f[12:16]) == 0
    h = patch_eoh(integral_channels(np.ascontiguousarray(img.transpose(1, 0, 2))), np.array([[10, 14]]), S)[0]
    assert h[2] >= 0.95 * h.sum() > 0  # horizontal edge: bin K/2 (90 degrees)


RGB_FEATURES = FeatureParams(colour="rgb")


def _colour(bgr: tuple[int, int, int], kappa: float = 5.0) -> np.ndarray:
    """B13's cell colour ``(I, r, g)`` of a uniform BGR colour, from the definition (κ in grey levels)."""
    b, g, r = (float(v) for v in bgr)
    total = r + g + b
    return np.array([total / 765, (r + kappa) / (total + 3 * kappa), (g + kappa) / (total + 3 * kappa)])


def test_uniform_patch_features():
    img = np.full((30, 30, 3), (40, 90, 200), np.uint8)  # BGR
    for params, cell in ((RGB_FEATURES, [200 / 255, 90 / 255, 40 / 255]),  # B13's R, G, B per cell
                         (FeatureParams(), [330 / 765, 205 / 345, 95 / 345])):  # I, (R+5)/(R+G+B+15), (G+5)/(..)
        f = patch_features(integral_channels(img, params), np.array([[5, 5]]), S, params)[0]
        assert f.shape == (23,) == (params.n_features,)
        np.testing.assert_allclose(f[:12], np.tile(cell, 4))
        np.testing.assert_allclose(f[12:16], 0.25)  # dominant orientations 1/K
        np.testing.assert_allclose(f[16:22], 0.0)  # log ratios
        assert f[22] == 0.0


def test_colour_cells_follow_the_2x2_grid():
    img = np.zeros((12, 12, 3), np.uint8)
    img[:6, :6] = (0, 0, 255)  # red top-left
    img[:6, 6:] = (255, 0, 0)  # blue top-right
    img[6:, :6] = (0, 255, 0)  # green bottom-left
    img[6:, 6:] = (255, 255, 255)
    f = patch_features(integral_channels(img, RGB_FEATURES), np.array([[0, 0]]), S, RGB_FEATURES)[0]
    np.testing.assert_allclose(f[:12], [1, 0, 0, 0, 0, 1, 0, 1, 0, 1, 1, 1])
    f = patch_features(integral_channels(img), np.array([[0, 0]]), S)[0]
    cells = [(0, 0, 255), (255, 0, 0), (0, 255, 0), (255, 255, 255)]
    np.testing.assert_allclose(f[:12], np.concatenate([_colour(c) for c in cells]))
    np.testing.assert_allclose(f[[1, 2, 10, 11]], [260 / 270, 5 / 270, 1 / 3, 1 / 3])  # red; white is neutral


def test_chromaticity_does_not_change_with_shading():
    """The same clothing in full light and in shade (every channel x 0.4): r, g stay, I scales (B13 colour)."""
    rng = np.random.default_rng(0)
    cloth = rng.uniform(120, 250, (1, 1, 3)) * np.array([0.3, 0.6, 1.0])  # an orange-ish BGR cloth
    lit = np.repeat(np.repeat(cloth, S, 0), S, 1)
    img = np.concatenate([lit, 0.4 * lit], axis=1).round().astype(np.uint8)  # lit patch | shaded patch
    corners = np.array([[0, 0], [S, 0]])
    f = patch_features(integral_channels(img), corners, S)
    np.testing.assert_allclose(f[1, 0::3][:4], 0.4 * f[0, 0::3][:4], atol=2 / 255)  # intensity follows the light
    np.testing.assert_allclose(f[1, :12].reshape(4, 3)[:, 1:], f[0, :12].reshape(4, 3)[:, 1:], atol=0.02)
    raw = patch_features(integral_channels(img, RGB_FEATURES), corners, S, RGB_FEATURES)
    assert np.abs(raw[1, :12] - raw[0, :12]).max() > 0.2  # B13's R, G, B all move with the shading


def test_symmetry_feature_of_mirror_symmetric_and_one_sided_patterns():
    lam = np.full((S, S), 40, np.uint8)
    for r in range(S):  # a centred "Λ": two strokes mirror images about the vertical axis x = 6
        half = r // 2
        lam[r, max(5 - half, 0):6 - half + 1] = 230
        lam[r, 6 + half - 1:min(6 + half + 1, S)] = 230
    assert (lam == lam[:, ::-1]).all()
    img = np.repeat(lam[..., None], 3, axis=2)
    f = patch_features(integral_channels(img), np.array([[0, 0]]), S)[0]
    assert f[22] <= 0.05
    rng = np.random.default_rng(0)
    left = np.full((S, S), 120, np.uint8)
    left[:, :5] = rng.integers(0, 256, (S, 5))  # texture in the left half only (no edge reaches the right)
    f = patch_features(integral_channels(np.repeat(left[..., None], 3, axis=2)), np.array([[0, 0]]), S)[0]
    assert f[22] > 0.5


def test_patch_fraction_of_a_mask():
    m = np.zeros((H, W), bool)
    m[:, :100] = True
    frac = patch_fraction(m, _patches([(0, 0), (94, 10), (100, 10)]))
    np.testing.assert_allclose(frac, [1.0, 0.5, 0.0])


# ---------------------------------------------------------------------------------------------------------
# B14 boosting
def _leaf_gini(tree: tuple[np.ndarray, ...], x: np.ndarray, y: np.ndarray, w: np.ndarray) -> float:
    """Σ_leaves Σ_c w_c² / w_leaf of a fitted tree on its training data (larger = purer)."""
    feature, threshold, left, right, _ = tree
    x32 = x.astype(np.float32).astype(np.float64)
    node = np.zeros(len(x), int)
    for _ in range(10):  # walk down to the leaves (independently of predict_tree)
        nxt = np.where(x32[np.arange(len(x)), feature[node]] <= threshold[node], left[node], right[node])
        node = np.where(left[node] >= 0, nxt, node)
    total = 0.0
    for leaf in np.unique(node):
        p, n = w[(node == leaf) & (y > 0)].sum(), w[(node == leaf) & (y < 0)].sum()
        total += (p * p + n * n) / (p + n)
    return total


def test_numpy_cart_equals_scikit_learn_tree():
    rng = np.random.default_rng(0)
    same = trials = 0
    for _ in range(60):
        n, d = int(rng.integers(30, 400)), int(rng.integers(1, 25))
        x = rng.normal(size=(n, d))
        y = np.where(x[:, 0] * rng.normal() + x[:, -1] + rng.normal(size=n) > 0, 1, -1)
        w = rng.random(n)
        depth, leaf = int(rng.integers(1, 5)), int(rng.integers(1, 9))
        ours = fit_cart(x, y, w, depth, leaf)
        ref = DecisionTreeClassifier(max_depth=depth, min_samples_leaf=leaf, random_state=0).fit(x, y, sample_weight=w)
        # the same weighted Gini: the same split, or a tie between splits (then only the tie-break differs)
        assert _leaf_gini(ours, x, y, w) == pytest.approx(_leaf_gini(sklearn_cart(x, y, w, depth, leaf), x, y, w),
                                                           rel=1e-9)
        xt = rng.normal(size=(500, d))
        trials += 1
        same += bool((predict_tree(xt, ours) == ref.predict(xt)).all())
    assert same >= 0.85 * trials


@pytest.mark.skipif(not _cart_jit.ENABLED, reason="numba off (FUSIONTRACK_NUMBA=0) or missing")
def test_compiled_split_search_grows_the_numpy_trees_bit_for_bit():
    """fit_cart's compiled split search (vision/_cart_jit.py) must choose the numpy reference's splits exactly,
    ties included (values rounded to 0.1 make many equal values and equal Gini proxies): every array of every
    tree identical, over batches of B15's sizes and shapes (23 features, boosting weights)."""
    rng = np.random.default_rng(7)
    for trial in range(80):
        n, d = int(rng.integers(12, 900)), int(rng.choice([1, 5, 23]))
        x = rng.normal(size=(n, d)).astype(np.float32)
        if trial % 2:
            x = np.round(x, 1)
        y = np.where(rng.random(n) < rng.uniform(0.1, 0.9), 1, -1)
        w = rng.random(n) ** 3  # uneven, as after boosting rounds
        depth, leaf = int(rng.integers(1, 5)), int(rng.integers(1, 9))
        compiled = fit_cart(x, y, w, depth, leaf, jit=True)
        reference = fit_cart(x, y, w, depth, leaf, jit=False)
        for a, b in zip(compiled, reference, strict=True):
            assert np.array_equal(a, b), trial


def test_array_trees_predict_like_scikit_learn():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(400, 6))
    y = np.where(x[:, 1] - x[:, 4] > 0, 1, -1)
    w = rng.random(400)
    ref = DecisionTreeClassifier(max_depth=3, min_samples_leaf=5, random_state=7).fit(x, y, sample_weight=w)
    tree = sklearn_cart(x, y, w, 3, 5, seed=7)
    thr = ref.tree_.threshold[ref.tree_.feature >= 0]
    xt = np.concatenate([rng.normal(size=(2000, 6)), np.repeat(x[:20], 1, axis=0)])
    xt[:len(thr), ref.tree_.feature[ref.tree_.feature >= 0]] = thr  # values exactly on a threshold
    np.testing.assert_array_equal(predict_tree(xt, tree), ref.predict(xt))
    assert (ref.predict(xt) == 1).any()
    assert (ref.predict(xt) == -1).any()


def _gaussians(rng: np.random.Generator, n: int, shift: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """B14's test classes in R^23: negatives N(0, 1), positives N(1.5 + shift, 1) in every dimension."""
    x = np.concatenate([rng.normal(1.5 + np.asarray(shift), 1.0, (n // 2, 23)), rng.normal(0.0, 1.0, (n // 2, 23))])
    y = np.concatenate([np.ones(n // 2, int), -np.ones(n // 2, int)])
    return x, y


def test_first_batch_of_200_separates_gaussians():
    rng = np.random.default_rng(0)
    clf = BoostedClassifier()
    clf.update(*_gaussians(rng, 200), rng=1)  # ALGORITHMS.md B14: >= 95 % after the first batch of 200
    x, y = _gaussians(rng, 4000)
    assert (np.sign(clf.margin(x)) == y).mean() >= 0.95
    assert clf.n_learners == 10
    c = clf.confidence(x)
    assert c.min() >= -1
    assert c.max() <= 1


def test_alphas_follow_adaboost_on_the_first_batch():
    rng = np.random.default_rng(5)
    x, y = _gaussians(rng, 300)
    clf = BoostedClassifier()
    up = clf.update(x, y, rng=0)
    h = clf.learner_outputs(x)
    w = np.where(y > 0, 1 / (2 * 150), 1 / (2 * 150))
    for m in range(clf.n_learners):  # textbook discrete AdaBoost replayed on the learners' outputs
        e = np.clip(w[h[m] != y].sum(), 1e-6, 0.499)
        assert up.errors[m] == pytest.approx(e)
        assert clf.alphas[m] == pytest.approx(0.5 * np.log((1 - e) / e))
        w = w * np.exp(-clf.alphas[m] * y * h[m])
        w /= w.sum()


def test_update_keeps_the_k_best_learners_of_the_new_batch():
    rng = np.random.default_rng(2)
    clf = BoostedClassifier()
    clf.update(*_gaussians(rng, 200), rng=3)
    shift = np.where(np.arange(23) % 2 == 0, 1.0, -1.0)
    x, y = _gaussians(rng, 240, shift)
    x = x[20:]  # unbalanced: 100 positives, 120 negatives
    y = y[20:]
    before = clf.learner_outputs(x)
    w = np.where(y > 0, 0.5 / 100, 0.5 / 120)  # class-balanced (B14 step 1)
    err = ((before != y) * w).sum(axis=1)
    expected = np.argsort(err, kind="stable")[:7]
    expected = expected[err[expected] < 0.5]
    up = clf.update(x, y, rng=4)
    np.testing.assert_array_equal(up.kept, expected)
    np.testing.assert_allclose(up.previous_errors, err)
    after = clf.learner_outputs(x)
    np.testing.assert_array_equal(after[:len(expected)], before[expected])  # the same trees, best first
    assert clf.n_learners == 10


def test_accuracy_recovers_after_drift():
    # ALGORITHMS.md B14: shift the positive mean by 1 sigma in 10 steps; >= 90 % within 3 update batches
    rng = np.random.default_rng(7)
    direction = np.where(np.arange(23) < 12, -1.0, 1.0)  # half the dimensions towards the negatives
    clf = BoostedClassifier()
    clf.update(*_gaussians(rng, 200), rng=rng)
    for step in range(1, 11):
        clf.update(*_gaussians(rng, 200, 0.1 * step * direction), rng=rng)
    accuracy = []
    for _ in range(3):
        clf.update(*_gaussians(rng, 200, direction), rng=rng)
        x, y = _gaussians(rng, 4000, direction)
        accuracy.append((np.sign(clf.margin(x)) == y).mean())
    assert max(accuracy) >= 0.90


def test_ensemble_follows_a_drift_of_the_informative_dimensions():
    # harder than B14's drift: the positives' separation moves from dimensions (0, 1) to (1, 2), 2.5 sigma each,
    # so the first ensemble's splits on dimension 0 go stale (Bayes accuracy 96 % before and after)
    def batch(rng: np.random.Generator, n: int, mean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.concatenate([rng.normal(mean, 1.0, (n // 2, 23)), rng.normal(0.0, 1.0, (n // 2, 23))])
        return x, np.r_[np.ones(n // 2, int), -np.ones(n // 2, int)]

    rng = np.random.default_rng(0)
    start, end = np.zeros(23), np.zeros(23)
    start[[0, 1]] = 2.5
    end[[1, 2]] = 2.5
    clf = BoostedClassifier()
    clf.update(*batch(rng, 200, start), rng=rng)
    x, y = batch(rng, 4000, end)
    assert (np.sign(clf.margin(x)) == y).mean() < 0.85  # stale
    for step in range(1, 11):
        clf.update(*batch(rng, 200, start + (end - start) * step / 10), rng=rng)
    for _ in range(3):
        clf.update(*batch(rng, 200, end), rng=rng)
        x, y = batch(rng, 4000, end)
        assert (np.sign(clf.margin(x)) == y).mean() >= 0.90


def test_boosting_serialises_to_json_exactly():
    rng = np.random.default_rng(8)
    clf = BoostedClassifier()
    clf.update(*_gaussians(rng, 200), rng=0)
    back = BoostedClassifier.from_dict(json.loads(json.dumps(clf.to_dict())))
    x, _ = _gaussians(rng, 500)
    np.testing.assert_array_equal(back.margin(x), clf.margin(x))


# ---------------------------------------------------------------------------------------------------------
# bank: B15 learning, B16 maps, B17 identity
RED, BLUE, GREEN, YELLOW = (30, 30, 220), (220, 40, 30), (40, 200, 40), (30, 220, 230)
BOXES = {1: (60, 60, 100, 160), 2: (140, 60, 180, 160)}


def _train_red_blue(n_frames: int = 6, seed: int = 0) -> tuple[AppearanceBank, np.random.Generator]:
    rng = np.random.default_rng(seed)
    bank = AppearanceBank(rng=seed)
    for _ in range(n_frames):
        bank.train(_scene(rng, BOXES, {1: RED, 2: BLUE}), BOXES)
    return bank, rng


def test_red_and_blue_textures_are_separated():
    bank, rng = _train_red_blue()
    img = _scene(rng, BOXES, {1: RED, 2: BLUE})  # a new texture realisation
    p = sample_patches(np.array([BOXES[1], BOXES[2]], float), img.shape, rng=rng)
    conf = bank.confidences(extract_features(img, p), [1, 2])
    is_red = p.box_index == 0
    assert roc_auc_score(is_red, conf[0]) >= 0.99
    assert roc_auc_score(~is_red, conf[1]) >= 0.99
    scores = bank.box_scores(img, np.array([BOXES[1], BOXES[2]], float))
    assert scores[0, 0] > 0.5 > -0.5 > scores[1, 0]
    assert scores[1, 1] > 0.5 > -0.5 > scores[0, 1]


def test_identify_tells_which_target_a_box_shows():
    bank, rng = _train_red_blue()
    moved = {1: (200, 100, 240, 200), 2: (30, 40, 70, 140)}  # the two have swapped sides
    img = _scene(rng, moved, {1: RED, 2: BLUE})
    assert bank.identify(img, moved[1], [1, 2])[0] == 1
    assert bank.identify(img, moved[2], [1, 2])[0] == 2
    best, scores = bank.identify(img, moved[2], [1])  # only red's classifier: blue is not red
    assert best is None
    assert scores[0] < 0


def test_negatives_come_from_the_l_closest_targets_and_patches_in_other_boxes_are_dropped():
    flat = {1: (40, 40, 80, 120), 2: (90, 40, 130, 120), 3: (140, 40, 180, 120), 4: (260, 100, 300, 180)}
    colours = {1: RED, 2: BLUE, 3: GREEN, 4: YELLOW}
    img = np.full((H, W, 3), 128, np.uint8)
    for i, (x0, y0, x1, y1) in flat.items():
        img[y0:y1, x0:x1] = colours[i]
    bank = AppearanceBank(rng=0)
    bank.train(img, flat, train_ids=[1])
    assert bank.ids == (1,)
    assert bank.is_trained(1)
    neg = bank.classifier(1).reservoir(-1)
    pos = bank.classifier(1).reservoir(1)
    rgb = _colour  # the default cell colour (I, r, g) of a BGR colour
    assert len(neg) > 0
    assert np.allclose(pos[:, :3], rgb(RED))
    cells = neg[:, :12].reshape(-1, 4, 3)
    # every negative cell is blue, green or grey background; none is yellow (target 4 is the farthest)
    assert not np.isclose(cells, rgb(YELLOW), atol=1e-6).all(axis=2).any()
    assert np.isclose(cells, rgb(BLUE), atol=1e-6).all(axis=2).any()
    assert np.isclose(cells, rgb(GREEN), atol=1e-6).all(axis=2).any()
    # an overlapping box: positives whose centre lies in the other target's box are not learnt (B15)
    over = {1: (40, 40, 120, 120), 2: (80, 40, 160, 120)}
    img = np.full((H, W, 3), 128, np.uint8)
    img[40:120, 40:80] = RED
    img[40:120, 80:160] = BLUE
    bank = AppearanceBank(rng=1)
    bank.train(img, over, train_ids=[1])
    pos = bank.classifier(1).reservoir(1)
    assert len(pos) >= 5
    assert not np.isclose(pos[:, :12].reshape(-1, 4, 3), rgb(BLUE), atol=1e-6).all(axis=(1, 2)).any()


def test_update_cadence_and_dropping_targets():
    small = {1: (40, 40, 60, 60), 2: (100, 40, 120, 60)}  # 10 patches each: 20 samples per target and frame
    rng = np.random.default_rng(0)
    bank = AppearanceBank(rng=0)
    updated = [bank.train(_scene(rng, small, {1: RED, 2: BLUE}), small, train_ids=[1]) for _ in range(12)]
    # first update at once, then every n_upd = 5 frames of samples (B15)
    assert [i for i, u in enumerate(updated) if u] == [0, 5, 10]
    big = {1: (40, 20, 140, 220), 2: (160, 20, 260, 220)}  # 150 patches each: >= 100 new samples every frame
    assert all(bank.train(_scene(rng, big, {1: RED, 2: BLUE}), big, train_ids=[1]) == [1] for _ in range(3))
    assert bank.classifier(1).n_updates == 6
    bank.train(_scene(rng, small, {1: RED, 2: BLUE}), small)  # now both learn
    assert set(bank.ids) == {1, 2}
    bank.drop(1)
    assert bank.ids == (2,)
    assert 1 not in bank


def test_background_negatives_come_from_around_the_box():
    img = np.full((H, W, 3), 128, np.uint8)
    img[60:160, 60:100] = RED
    bank = AppearanceBank(AppearanceParams(background_patches=15), rng=0)
    bank.train(img, {1: (60, 60, 100, 160)})  # a lone target: background is its only negative
    neg = bank.classifier(1).reservoir(-1)
    assert len(neg) == 15
    assert bank.is_trained(1)


def test_score_map_likelihood_formula():
    centres = np.array([[0.0, 0.0], [10.0, 0.0]])
    scores = np.array([[0.8, -0.5], [0.2, 0.6]])  # two targets
    pos = np.array([[[0.0, 12.0], [10.0, 0.0]], [[5.0, 0.0], [0.0, 0.0]]])
    got = score_map_likelihood(centres, scores, pos, sigma_px=12.0, eps0=1e-3)
    want = np.array([[1e-3 + 0.8 * np.exp(-0.5), 1e-3 + 0.8 * np.exp(-100 / 288)],
                     [1e-3 + (0.2 + 0.6) * np.exp(-25 / 288), 1e-3 + 0.2 + 0.6 * np.exp(-100 / 288)]])
    np.testing.assert_allclose(got, want)
    np.testing.assert_allclose(score_map_likelihood(centres, scores[0], pos[0]), want[0])


def test_interacting_region_is_the_dilated_union():
    np.testing.assert_allclose(interacting_region([[10, 20, 30, 60], [40, 10, 60, 50]], 0.2),
                               [8, 6, 62, 64])
    np.testing.assert_allclose(interacting_region([[0, 0, 50, 50]], 0.2, (40, 30)), [0, 0, 30, 40])


def test_score_map_peaks_on_each_target():
    bank, rng = _train_red_blue(8)
    side = {1: (120, 70, 160, 170), 2: (160, 70, 200, 170)}  # side by side, touching
    img = _scene(rng, side, {1: RED, 2: BLUE})
    sm = bank.score_map(img, [1, 2], boxes_px=np.array([side[1], side[2]], float))
    assert sm.scores.shape == (2, 300)
    np.testing.assert_allclose(sm.region_px, [116, 60, 204, 180])
    # particles: candidate box centres across the region; the likelihood peaks inside the right body
    u = np.arange(120, 201, 2.0)
    particles = np.column_stack([u, np.full(len(u), 120.0)])
    like = sm.likelihood(np.stack([particles, particles]))
    assert 120 <= u[np.argmax(like[0])] < 160 <= u[np.argmax(like[1])] <= 200
    dense = bank.score_map(img, [1, 2], region_px=np.array([116, 60, 204, 180]), stride_px=4)
    rows, cols = dense.grid_shape
    red_map = dense.row(1).reshape(rows, cols)
    assert red_map[:, : cols // 2 - 2].mean() > 0.5 > -0.5 > red_map[:, cols // 2 + 2:].mean()


def test_bank_round_trip_through_json_gives_identical_scores_and_learning():
    bank, rng = _train_red_blue(7)
    img = _scene(rng, BOXES, {1: RED, 2: BLUE})
    back = AppearanceBank.from_dict(json.loads(json.dumps(bank.to_dict())))
    assert back.ids == bank.ids
    assert back.params == bank.params
    p = sample_patches(np.array([BOXES[1], BOXES[2]], float), img.shape, rng=5)
    f = extract_features(img, p)
    np.testing.assert_array_equal(back.confidences(f), bank.confidences(f))
    # the random state, the reservoir and the waiting samples travel too: learning continues identically
    assert bank.train(img, BOXES, force_update=True) == back.train(img, BOXES, force_update=True) == [1, 2]
    np.testing.assert_array_equal(back.confidences(f), bank.confidences(f))
    light = AppearanceBank.from_dict(json.loads(json.dumps(bank.to_dict(samples=False))))  # no stored samples
    np.testing.assert_array_equal(light.confidences(f), bank.confidences(f))
    assert len(light.classifier(1).reservoir(1)) == 0
    assert len(json.dumps(light.to_dict())) < len(json.dumps(bank.to_dict())) / 20
    # a state of the first format (no FeatureParams.colour) learnt B13's R, G, B and is read back so
    old = bank.to_dict()
    old["format"] = "fusiontrack.appearance/1"
    del old["params"]["features"]["colour"]
    assert AppearanceBank.from_dict(old).params.features.colour == "rgb"


# ---------------------------------------------------------------------------------------------------------
# bad input
def test_bad_input_raises_value_errors_that_name_the_culprit():
    img = np.zeros((H, W, 3), np.uint8)
    with pytest.raises(ValueError, match="outside"):
        sample_patches([400, 10, 450, 60], (H, W))
    with pytest.raises(ValueError, match="empty box"):
        sample_patches([50, 10, 50, 60], (H, W))
    with pytest.raises(ValueError, match="not finite"):
        sample_patches([np.nan, 10, 60, 60], (H, W))
    with pytest.raises(ValueError, match="image_bgr"):
        extract_features(img.astype(np.float32), _patches([(0, 0)]))
    with pytest.raises(ValueError, match="image_bgr"):
        extract_features(img[..., 0], _patches([(0, 0)]))
    with pytest.raises(ValueError, match="outside"):
        extract_features(img, _patches([(W - 5, 0)]))
    with pytest.raises(ValueError, match="size_px"):
        PatchParams(size_px=13)
    with pytest.raises(ValueError, match="n_keep"):
        BoostParams(n_keep=11)
    with pytest.raises(ValueError, match="n_confusers"):
        AppearanceParams(n_confusers=0)
    with pytest.raises(ValueError, match="labels"):
        BoostedClassifier().update(np.zeros((10, 23)), np.ones(10))
    with pytest.raises(ValueError, match="features"):
        BoostedClassifier().update(np.zeros((10, 5)), np.r_[np.ones(5), -np.ones(5)])
    bank = AppearanceBank(rng=0)
    with pytest.raises(ValueError, match="image"):
        bank.train(np.zeros((H, W, 3), np.float64), BOXES)
    with pytest.raises(ValueError, match="empty box"):
        bank.train(img, {1: (10, 10, 5, 50)})
    with pytest.raises(ValueError, match="train_ids"):
        bank.train(img, BOXES, train_ids=[3])
    with pytest.raises(ValueError, match="mask"):
        bank.train(img, BOXES, mask=np.ones((10, 10), bool))
    with pytest.raises(ValueError, match="ids"):
        bank.box_scores(img, [10, 10, 50, 50], [7])
    with pytest.raises(ValueError, match="format"):
        AppearanceBank.from_dict({"format": "something else"})
    with pytest.raises(ValueError, match="colour"):
        FeatureParams(colour="hsv")
    with pytest.raises(ValueError, match="chroma_eps"):
        FeatureParams(chroma_eps=0.0)
    with pytest.raises(ValueError, match="sigma_px"):
        score_map_likelihood(np.zeros((1, 2)), np.ones(1), np.zeros((1, 2)), sigma_px=0.0)


def test_boxes_off_the_image_are_skipped_by_the_bank():
    rng = np.random.default_rng(0)
    bank = AppearanceBank(rng=0)
    img = _scene(rng, BOXES, {1: RED, 2: BLUE})
    assert bank.train(img, {**BOXES, 3: (400, 10, 450, 60)}) == [1, 2]  # 3 is off the image: no samples
    assert 3 not in bank
    scores = bank.box_scores(img, [[400, 10, 450, 60], [-38, 60, 2, 160], list(BOXES[1])])
    assert np.isnan(scores[:2]).all()  # the 2nd box is only 5 % visible
    assert np.isfinite(scores[2]).all()


def test_background_negatives_for_every_box_whatever_the_id_order():
    """Each training box gets its ``background_patches`` negatives, also when the ids are not in box order."""
    from fusiontrack.vision.appearance import AppearanceBank, AppearanceParams

    bank = AppearanceBank(AppearanceParams(background_patches=10), rng=0)
    boxes = np.array([[100.0, 100.0, 140.0, 200.0], [400.0, 150.0, 440.0, 250.0]])
    for rows in ([0, 1], [1, 0]):
        _, owner = bank._background((480, 640, 3), boxes, rows)
        assert np.bincount(owner, minlength=2).tolist() == [10, 10]


def test_exclusive_box_scores_ignore_the_overlap_of_two_boxes():
    """Red and blue side by side, their boxes drawn too wide so that each covers half of the other person (as
    at a split, when the people are still close): patches in the overlap show either person. Scoring only the
    patches outside the other box (``exclusive``) separates the two better, and a box inside the other one
    gives no score."""
    bank, rng = _train_red_blue()
    people = {1: (60, 60, 100, 160), 2: (100, 60, 140, 160)}
    wide = np.array([[60, 60, 120, 160], [80, 60, 140, 160]], float)  # each box: a third of it is the other
    gaps = {False: [], True: []}
    for _ in range(5):
        img = _scene(rng, people, {1: RED, 2: BLUE})
        for exclusive in (False, True):
            s = bank.box_scores(img, wide, [1, 2], exclusive=exclusive)
            assert s[0, 0] > s[1, 0]
            assert s[1, 1] > s[0, 1]
            gaps[exclusive].append(s[0, 0] - s[1, 0] + s[1, 1] - s[0, 1])
    assert np.mean(gaps[True]) > np.mean(gaps[False]) + 1.0  # (about 4.0 against 1.6)
    inner = np.array([[60, 60, 140, 160], [90, 70, 110, 150]], float)
    s = bank.box_scores(img, inner, [1, 2], exclusive=True)
    assert np.isnan(s[1]).all()  # every patch of the inner box is inside the outer one
    assert np.isfinite(s[0]).all()


def _front_and_back() -> tuple[np.ndarray, dict[int, tuple[int, int, int, int]]]:
    """Red (target 1) standing in front of blue (target 2): red's box covers part of blue's, and there the image
    shows red."""
    boxes = {1: (90, 60, 150, 200), 2: (40, 40, 120, 170)}
    img = np.full((H, W, 3), 128, np.uint8)
    img[40:170, 40:120] = BLUE
    img[60:200, 90:150] = RED  # drawn last: in front
    return img, boxes


def _wholly(samples: np.ndarray, bgr: tuple[int, int, int]) -> np.ndarray:
    return np.isclose(samples[:, :12].reshape(-1, 4, 3), _colour(bgr), atol=1e-6).all(axis=(1, 2))


def test_depth_order_learns_the_overlap_for_the_target_in_front():
    """B15 drops every patch centred where two boxes overlap. With the targets' distances from the camera, the
    patches there show the nearer one: they are learnt for it (the person in front, whole) and still not for the
    one behind; depths closer than ``depth_margin_m`` keep B15's rule."""
    img, boxes = _front_and_back()
    pos = {}
    for name, depth in (("b15", None), ("depth", {1: 3.0, 2: 4.0}), ("level", {1: 3.0, 2: 3.2})):
        bank = AppearanceBank(rng=5)
        bank.train(img, boxes, train_ids=[1, 2], depth_m=depth)
        pos[name] = {tid: bank.classifier(tid).reservoir(1) for tid in (1, 2)}
    red_b15, red_depth = pos["b15"][1], pos["depth"][1]
    # in front: the patches of its box that lie in blue's box are learnt, and they show red, as the image does
    # (39 % of its box overlaps blue's: 1.65x as many expected)
    assert _wholly(red_depth, RED).sum() >= 1.3 * _wholly(red_b15, RED).sum()
    assert not _wholly(red_depth, BLUE).any()
    # behind: no patch centred in red's box is learnt as blue (a wholly red patch would be one)
    assert not _wholly(pos["depth"][2], RED).any()
    assert _wholly(pos["depth"][2], BLUE).any()
    # 0.2 m apart (margin 0.3 m): either may be in front, B15's rule
    for tid in (1, 2):
        assert np.array_equal(pos["level"][tid], pos["b15"][tid])


def test_a_frozen_classifier_votes_as_it_was_while_the_live_one_learns_on():
    """:meth:`AppearanceBank.freeze`: scoring with ``frozen=True`` uses the copy, whatever the classifier learns
    after; :meth:`~AppearanceBank.restore` undoes that learning, :meth:`~AppearanceBank.thaw` and
    :meth:`~AppearanceBank.drop` forget the copy."""
    bank, rng = _train_red_blue()
    test_img = _scene(np.random.default_rng(9), BOXES, {1: RED, 2: BLUE})
    boxes = np.array([BOXES[1], BOXES[2]], float)
    bank.rng = np.random.default_rng(3)
    before = bank.box_scores(test_img, boxes, [1, 2])
    bank.freeze(1)
    assert bank.is_frozen(1)
    assert not bank.is_frozen(2)
    assert bank.frozen_ids == (1,)
    for _ in range(12):  # the laser exchanged them: target 1's box now shows blue, and it learns blue
        bank.train(_scene(rng, BOXES, {1: BLUE, 2: RED}), BOXES, train_ids=[1], force_update=True)
    bank.rng = np.random.default_rng(3)
    frozen = bank.box_scores(test_img, boxes, [1, 2], frozen=True)
    bank.rng = np.random.default_rng(3)
    live = bank.box_scores(test_img, boxes, [1, 2])
    assert np.array_equal(frozen, before)
    assert live[1, 0] > live[0, 0]  # the live classifier of 1 now prefers blue's box
    assert frozen[0, 0] > 0.5 > -0.5 > frozen[1, 0]  # its frozen copy still knows red
    bank.restore(1)
    bank.rng = np.random.default_rng(3)
    assert np.array_equal(bank.box_scores(test_img, boxes, [1, 2]), before)
    assert bank.is_frozen(1)
    bank.thaw(1)
    assert not bank.is_frozen(1)
    with pytest.raises(ValueError, match="no frozen classifier"):
        bank.restore(1)
    bank.freeze(2)
    bank.drop(2)
    assert bank.frozen_ids == ()
