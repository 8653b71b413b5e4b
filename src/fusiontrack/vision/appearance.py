"""Per-target appearance classifiers learned online (seed 001, ALGORITHMS.md B14, B15, B16, B17).

Seed 001 ("learning by tracking"): while a target is tracked reliably by the laser, random patches of
its projected box (B12) are positives and patches of its ``L`` closest targets ("possible confusing
targets") are negatives for a boosted classifier of its own; when targets interact, each classifier
scores patches of the interacting region and the score map becomes the visual observation model of a
particle filter ("tracking by learning", B16), and at a split the classifiers say which target is which
(B17).

* :class:`BoostedClassifier` (B14): discrete AdaBoost over CART trees (Gini, depth ≤ 3, min leaf 5); each
  update keeps the ``K_keep = 7`` old trees with the lowest weighted error on the new batch (and error
  < 0.5), re-weights them in ascending order of error and trains ``M − kept`` new trees (``M = 10``) on
  the re-weighted batch — Avidan's (2007) ensemble update as seed 001 words it. Trees are fitted by
  :func:`fit_cart` (scikit-learn's CART rule in NumPy, ~2-10x faster than ``DecisionTreeClassifier`` on
  these small batches; ``BoostParams(tree_backend="sklearn")`` uses scikit-learn) and stored as plain
  arrays, so prediction is vectorised over trees and patches and the state serialises to JSON.
* :class:`AppearanceClassifier` (B15): one target's ensemble, the samples gathered since its last
  update, and a reservoir of up to 500 past samples per class mixed 50/50 into every update; updates
  every ``n_upd = 5`` frames or at 100 new samples (the first one at once).
* :class:`AppearanceBank`: one classifier per target id; :meth:`~AppearanceBank.train` samples every
  box's patches and computes their features once per frame, then feeds each training target (an optional
  foreground mask keeps floor patches out); :meth:`~AppearanceBank.box_scores`,
  :meth:`~AppearanceBank.identify` and :func:`assign_identities` (B17) and :meth:`~AppearanceBank.score_map`
  (B16).
* :func:`score_map_likelihood` (B16): ``p(z | x) ∝ ε0 + Σ_i max(s_i, 0) exp(−‖d(x) − d_i‖² / 2σ_d²)``
  for particles at image positions ``d(x)``, vectorised over targets, particles and patches.

Scores are the normalised confidence ``conf(s) = H(s) / Σ_m α_m ∈ [−1, 1]`` of B14 (0 for a classifier
that has not been trained yet). Identity from one box alone compares differently calibrated classifiers;
:func:`assign_identities` (Hungarian over all boxes and members, B17) is the more reliable decision.
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment
from sklearn.tree import DecisionTreeClassifier

from . import _cart_jit
from .patches import (
    FeatureParams,
    IntegralCache,
    Patches,
    PatchParams,
    as_boxes,
    box_visibility,
    extract_features,
    grid_patches,
    patch_centres,
    patch_fraction,
    sample_patches,
    validate_image,
)

__all__ = [
    "AppearanceBank",
    "AppearanceClassifier",
    "AppearanceParams",
    "BoostParams",
    "BoostUpdate",
    "BoostedClassifier",
    "ScoreMap",
    "assign_identities",
    "balanced_weights",
    "fit_cart",
    "interacting_region",
    "predict_tree",
    "score_map_likelihood",
    "sklearn_cart",
]

log = logging.getLogger(__name__)

_FORMAT = "fusiontrack.appearance/2"
_FORMAT_RGB = "fusiontrack.appearance/1"  # before FeatureParams.colour: its classifiers learnt mean R, G, B


def _check_int(owner: str, name: str, value: Any, lo: int, hi: int | None = None) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < lo or (hi is not None
                                                                                          and value > hi):
        rng = f">= {lo}" if hi is None else f"in {lo}..{hi}"
        raise ValueError(f"{owner}.{name}: expected an integer {rng}, got {value!r}")


# --------------------------------------------------------------------------------------------------
# B14: boosted CART ensemble
@dataclass(frozen=True, slots=True)
class BoostParams:
    """Online boosting, ALGORITHMS.md B14 [RECON values].

    Attributes
    ----------
    n_learners : int
        Ensemble size ``M`` (10).
    n_keep : int
        ``K_keep``, old learners kept at each update (7); Avidan kept 4 of 5.
    max_depth : int
        CART depth (3).
    min_samples_leaf : int
        CART minimum leaf size in samples (5).
    min_error, max_error : float
        Clip of the weighted error before ``α = ½ ln((1 − ε)/ε)`` (1e-6, 0.499).
    tree_backend : str
        ``"numpy"`` (:func:`fit_cart`, default) or ``"sklearn"`` (``DecisionTreeClassifier``, same trees up to
        ties, ~10x slower on small batches).
    """

    n_learners: int = 10
    n_keep: int = 7
    max_depth: int = 3
    min_samples_leaf: int = 5
    min_error: float = 1e-6
    max_error: float = 0.499
    tree_backend: str = "numpy"

    def __post_init__(self) -> None:
        if self.tree_backend not in ("numpy", "sklearn"):
            raise ValueError(f"BoostParams.tree_backend: expected 'numpy' or 'sklearn', got {self.tree_backend!r}")
        _check_int("BoostParams", "n_learners", self.n_learners, 1, 1000)
        _check_int("BoostParams", "n_keep", self.n_keep, 0, self.n_learners)
        _check_int("BoostParams", "max_depth", self.max_depth, 1, 12)
        _check_int("BoostParams", "min_samples_leaf", self.min_samples_leaf, 1)
        if not 0 < self.min_error < self.max_error < 0.5:
            raise ValueError(f"BoostParams.min_error, max_error: expected 0 < min_error < max_error < 0.5, got "
                             f"{self.min_error!r}, {self.max_error!r}")

    @property
    def max_nodes(self) -> int:
        """Nodes of a full binary tree of depth ``max_depth``."""
        return 2 ** (self.max_depth + 1) - 1


@dataclass(frozen=True, slots=True, eq=False)
class BoostUpdate:
    """What one :meth:`BoostedClassifier.update` did.

    Attributes
    ----------
    kept : (k,) int64
        Indices, in the ensemble *before* the update, of the learners kept (ascending error on the batch).
    previous_errors : (M_old,) float64
        Weighted error of every old learner on the batch under class-balanced weights (step 2 of B14).
    errors : (M,) float64
        Weighted error of each learner of the new ensemble when it was (re)weighted, clipped.
    n_samples : int
    """

    kept: np.ndarray
    previous_errors: np.ndarray
    errors: np.ndarray
    n_samples: int


def balanced_weights(labels: np.ndarray) -> np.ndarray:
    """Class-balanced AdaBoost start weights ``(n,)``: ``1/(2 n_+)`` for positives, ``1/(2 n_−)`` for negatives
    (B14)."""
    pos = labels > 0
    n_pos = np.count_nonzero(pos)
    n_neg = len(labels) - n_pos
    return np.where(pos, 0.5 / max(n_pos, 1), 0.5 / max(n_neg, 1))


def _check_batch(features: Any, labels: Any, n_features: int) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != n_features:
        raise ValueError(f"features: expected (n, {n_features}) values, got shape {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError("features: expected finite values")
    y = np.asarray(labels)
    if y.shape != (len(x),) or not np.isin(y, (-1, 1)).all():
        raise ValueError(f"labels: expected ({len(x)},) values in {{-1, +1}}, got shape {y.shape}")
    y = y.astype(np.int64)
    if not ((y > 0).any() and (y < 0).any()):
        raise ValueError("labels: a batch needs both positive (+1) and negative (-1) samples")
    return x, y


class BoostedClassifier:
    """Boosted CART ensemble updated batch by batch, keeping the ``K_keep`` best learners (ALGORITHMS.md B14).

    Parameters
    ----------
    params : BoostParams, optional
    n_features : int
        Feature dimension ``d`` (23 for B13's features).

    Notes
    -----
    Learner ``m`` is stored as arrays over its nodes (padded to ``2^(depth+1) − 1``): split feature,
    threshold, left and right child (−1 at a leaf) and the leaf output ±1. Prediction follows
    scikit-learn's rule ``x_f (as float32) <= threshold`` → left, so it equals the fitted tree's ``predict``.
    """

    def __init__(self, params: BoostParams | None = None, n_features: int = 23) -> None:
        self.params = params or BoostParams()
        _check_int("BoostedClassifier", "n_features", n_features, 1)
        self.n_features = int(n_features)
        n = self.params.max_nodes
        self._feature = np.zeros((0, n), np.int64)
        self._threshold = np.zeros((0, n), np.float64)
        self._left = np.full((0, n), -1, np.int64)
        self._right = np.full((0, n), -1, np.int64)
        self._output = np.zeros((0, n), np.float64)
        self._alpha = np.zeros(0, np.float64)

    # -- state --------------------------------------------------------------------------------------
    @property
    def n_learners(self) -> int:
        return len(self._alpha)

    @property
    def is_trained(self) -> bool:
        return self.n_learners > 0

    @property
    def alphas(self) -> np.ndarray:
        """``(M,)`` learner weights ``α_m`` (a copy)."""
        return self._alpha.copy()

    # -- prediction ---------------------------------------------------------------------------------
    def learner_outputs(self, features: np.ndarray) -> np.ndarray:
        """``h_m(s)`` of every learner: ``(M, n)`` float64 in {−1, +1}, vectorised over learners and samples."""
        x = np.asarray(features)
        if x.ndim != 2 or x.shape[1] != self.n_features:
            raise ValueError(f"features: expected (n, {self.n_features}) values, got shape {x.shape}")
        m, n = self.n_learners, len(x)
        if m == 0 or n == 0:
            return np.zeros((m, n))
        x32 = x.astype(np.float32).astype(np.float64).ravel()  # scikit-learn compares float32 features
        # flat indices into the (M, max_nodes) node tables and the (n, d) features: ``take`` on a flat index
        # costs half of two-dimensional fancy indexing at these sizes (tens of learners, hundreds of patches)
        base = (np.arange(m) * self._left.shape[1])[:, None]
        col = (np.arange(n) * self.n_features)[None, :]
        left_t, right_t = self._left.ravel(), self._right.ravel()
        feature_t, threshold_t = self._feature.ravel(), self._threshold.ravel()
        node = np.zeros((m, n), np.int64)
        for _ in range(self.params.max_depth):  # one step down every tree at once per level
            at = base + node
            left = left_t.take(at)
            value = x32.take(col + np.maximum(feature_t.take(at), 0))
            nxt = np.where(value <= threshold_t.take(at), left, right_t.take(at))
            node = np.where(left >= 0, nxt, node)
        return self._output.ravel().take(base + node)

    def margin(self, features: np.ndarray) -> np.ndarray:
        """Strong score ``H(s) = Σ_m α_m h_m(s)`` ``(n,)`` (B14)."""
        return self._alpha @ self.learner_outputs(features)

    def confidence(self, features: np.ndarray) -> np.ndarray:
        """Normalised confidence ``conf(s) = H(s)/Σ α_m`` ``(n,)`` in [−1, 1]; 0 while untrained (B14)."""
        total = self._alpha.sum()
        h = self.margin(features)
        return h / total if total > 0 else np.zeros_like(h)

    # -- learning -----------------------------------------------------------------------------------
    def _alpha_of(self, error: float) -> tuple[float, float]:
        e = float(np.clip(error, self.params.min_error, self.params.max_error))
        return e, 0.5 * np.log((1.0 - e) / e)

    def _fit_tree(self, x: np.ndarray, y: np.ndarray, w: np.ndarray, seed: int) -> tuple[np.ndarray, ...]:
        p = self.params
        if p.tree_backend == "numpy":
            return fit_cart(x, y, w, p.max_depth, p.min_samples_leaf)
        return sklearn_cart(x, y, w, p.max_depth, p.min_samples_leaf, seed)

    def update(self, features: np.ndarray, labels: np.ndarray,
               rng: np.random.Generator | int | None = None) -> BoostUpdate:
        """Learn a batch: discrete AdaBoost on the first, "keep the K best + train new ones" afterwards (B14).

        Parameters
        ----------
        features : (n, d) float
        labels : (n,) int in {−1, +1}
            Both classes must be present.
        rng : numpy.random.Generator or int or None
            Seeds the trees' tie-breaking.

        Returns
        -------
        BoostUpdate
        """
        p = self.params
        rng = np.random.default_rng(rng)
        x, y = _check_batch(features, labels, self.n_features)
        w = balanced_weights(y)  # step 1: reset to class-balanced weights
        old = self.learner_outputs(x)  # (M_old, n)
        prev_err = ((old != y) * w).sum(axis=1)  # step 2
        order = np.argsort(prev_err, kind="stable")
        kept = order[: p.n_keep]
        kept = kept[prev_err[kept] < 0.5]  # step 3
        arrays = [a[kept] for a in (self._feature, self._threshold, self._left, self._right, self._output)]
        parts: list[list[np.ndarray]] = [[a] for a in arrays]
        alphas: list[float] = []
        errors: list[float] = []
        for h in old[kept]:  # step 4: ascending error, α from the current weights, reweight
            e, a = self._alpha_of(((h != y) * w).sum())
            w = w * np.exp(-a * y * h)
            w /= w.sum()
            alphas.append(a)
            errors.append(e)
        for _ in range(p.n_learners - len(kept)):  # step 5: new learners, sequential AdaBoost rounds
            tree = self._fit_tree(x, y, w, int(rng.integers(2**31 - 1)))
            for part, arr in zip(parts, tree, strict=True):
                part.append(arr[None, :])
            self_h = predict_tree(x, tree)
            e, a = self._alpha_of(((self_h != y) * w).sum())
            w = w * np.exp(-a * y * self_h)
            w /= w.sum()
            alphas.append(a)
            errors.append(e)
        self._feature, self._threshold, self._left, self._right, self._output = (np.concatenate(q) for q in parts)
        self._alpha = np.asarray(alphas, np.float64)
        return BoostUpdate(kept.astype(np.int64), prev_err, np.asarray(errors), len(y))

    # -- serialisation ------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready state (lists and numbers only); :meth:`from_dict` restores identical predictions."""
        return {
            "params": asdict(self.params),
            "n_features": self.n_features,
            "alpha": self._alpha.tolist(),
            "feature": self._feature.tolist(),
            "threshold": self._threshold.tolist(),
            "left": self._left.tolist(),
            "right": self._right.tolist(),
            "output": self._output.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> BoostedClassifier:
        """Inverse of :meth:`to_dict`; ``ValueError`` on a malformed state."""
        try:
            out = cls(BoostParams(**data["params"]), int(data["n_features"]))
            m, n = len(data["alpha"]), out.params.max_nodes
            out._alpha = np.asarray(data["alpha"], np.float64).reshape(m)
            out._feature = np.asarray(data["feature"], np.int64).reshape(m, n)
            out._threshold = np.asarray(data["threshold"], np.float64).reshape(m, n)
            out._left = np.asarray(data["left"], np.int64).reshape(m, n)
            out._right = np.asarray(data["right"], np.int64).reshape(m, n)
            out._output = np.asarray(data["output"], np.float64).reshape(m, n)
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"BoostedClassifier state: malformed ({err})") from err
        if out._feature.size and (out._feature.min() < 0 or out._feature.max() >= out.n_features):
            raise ValueError("BoostedClassifier state: a split feature is out of range")
        return out


def _empty_tree(max_depth: int) -> tuple[np.ndarray, ...]:
    size = 2 ** (max_depth + 1) - 1
    return (np.zeros(size, np.int64), np.zeros(size), np.full(size, -1, np.int64), np.full(size, -1, np.int64),
            np.zeros(size))


def _split_numpy(xs: np.ndarray, wpo: np.ndarray, wno: np.ndarray, sp: float, sn: float, lo: int,
                 hi: int) -> tuple[int, int]:
    """:func:`fit_cart`'s split search, vectorised over features and split points (the reference of
    :func:`fusiontrack.vision._cart_jit.best_split`, which says what it returns)."""
    cpl = np.cumsum(wpo, axis=1)[:, lo:hi + 1]
    cnl = np.cumsum(wno, axis=1)[:, lo:hi + 1]
    cpr, cnr = sp - cpl, sn - cnl
    wl, wr = cpl + cnl, cpr + cnr
    with np.errstate(invalid="ignore", divide="ignore"):
        # Gini proxy: Σ_children Σ_c w_c² / w_child, as in scikit-learn
        proxy = np.where(wl > 0, (cpl**2 + cnl**2) / wl, 0.0) + np.where(wr > 0, (cpr**2 + cnr**2) / wr, 0.0)
    valid = xs[:, lo + 1:hi + 2] > xs[:, lo:hi + 1] + 1e-7
    if not valid.any():
        return -1, -1
    proxy[~valid] = -np.inf
    f, i = np.unravel_index(int(np.argmax(proxy)), proxy.shape)
    return int(f), int(i)


def fit_cart(features: np.ndarray, labels: np.ndarray, weights: np.ndarray, max_depth: int = 3,
             min_samples_leaf: int = 5, jit: bool | None = None) -> tuple[np.ndarray, ...]:
    """Fit one weighted CART classification tree (Gini impurity, Breiman et al. 1984), as B14's weak learner.

    The same rule as scikit-learn's ``DecisionTreeClassifier(max_depth, min_samples_leaf)`` (features compared as
    float32, thresholds half-way between consecutive distinct values, a split maximising the weighted Gini
    decrease, leaves voting by weight, ties to −1), but vectorised over features and split points in NumPy:
    ~10x faster on B15's batches of a few hundred samples, where scikit-learn's per-call overhead dominates.
    Only exact ties between candidate splits may be resolved differently.

    Parameters
    ----------
    features : (n, d) float
    labels : (n,) int in {−1, +1}
    weights : (n,) float >= 0
    max_depth, min_samples_leaf : int
    jit : bool, optional
        The split search compiled (:mod:`fusiontrack.vision._cart_jit`, the same splits) or in numpy; default:
        compiled when numba is there.

    Returns
    -------
    feature, threshold, left, right, output : (2^(max_depth+1) − 1,) arrays
        Split feature and threshold (go left when ``x_f <= threshold``), children (−1 at a leaf) and the leaf
        output ±1, node 0 the root; unused nodes are padding.
    """
    jit = _cart_jit.ENABLED if jit is None else bool(jit) and _cart_jit.ENABLED
    x = np.asarray(features, dtype=np.float32)
    y = np.asarray(labels)
    w = np.asarray(weights, dtype=np.float64)
    feature, threshold, left, right, output = _empty_tree(max_depth)
    wp = np.where(y > 0, w, 0.0)
    wn = np.where(y > 0, 0.0, w)
    xt = x.T.astype(np.float64)  # (d, n)
    # sort every feature once; a child's orders are its parent's filtered by membership (stable, no re-sort)
    stack = [(np.argsort(x.T, axis=1, kind="stable"), 0, 0)]
    next_node = 1
    while stack:  # at most 2^max_depth − 1 splits: a loop over tree nodes, each vectorised over samples
        order, depth, node = stack.pop()  # order: (d, m) sample indices sorted by each feature
        m = order.shape[1]
        members = order[0]
        sp, sn = wp[members].sum(), wn[members].sum()
        output[node] = 1.0 if sp > sn else -1.0
        total = sp + sn
        if depth >= max_depth or m < 2 * min_samples_leaf or m < 2 or total <= 0:
            continue
        if 1.0 - (sp * sp + sn * sn) / (total * total) <= 1e-7:  # pure (scikit-learn's EPSILON)
            continue
        xs = np.take_along_axis(xt, order, axis=1)
        lo, hi = min_samples_leaf - 1, m - min_samples_leaf - 1  # split after sorted position i in [lo, hi]
        f, i = (_cart_jit.best_split if jit else _split_numpy)(xs, wp[order], wn[order], sp, sn, lo, hi)
        if f < 0:  # no two distinct values inside the leaf-size limits
            continue
        a, b = xs[f, lo + i], xs[f, lo + i + 1]
        thr = a / 2.0 + b / 2.0
        if thr == b or not np.isfinite(thr):
            thr = a
        feature[node], threshold[node] = f, thr
        go_left = np.zeros(len(x), bool)
        go_left[order[f, : lo + i + 1]] = True
        in_left = go_left[order]
        n_left = lo + i + 1
        left[node], right[node] = next_node, next_node + 1
        stack.append((order[~in_left].reshape(len(xt), m - n_left), depth + 1, next_node + 1))
        stack.append((order[in_left].reshape(len(xt), n_left), depth + 1, next_node))
        next_node += 2
    return feature, threshold, left, right, output


def sklearn_cart(features: np.ndarray, labels: np.ndarray, weights: np.ndarray, max_depth: int = 3,
                 min_samples_leaf: int = 5, seed: int = 0) -> tuple[np.ndarray, ...]:
    """:func:`fit_cart` through scikit-learn's ``DecisionTreeClassifier`` (the reference; ~3 ms a tree)."""
    tree = DecisionTreeClassifier(max_depth=max_depth, min_samples_leaf=min_samples_leaf, random_state=seed)
    tree.fit(features, labels, sample_weight=weights)
    t = tree.tree_
    n = t.node_count
    feature, threshold, left, right, output = _empty_tree(max_depth)
    leaf = t.children_left[:n] < 0
    feature[:n] = np.where(leaf, 0, t.feature[:n])
    threshold[:n] = np.where(leaf, 0.0, t.threshold[:n])
    left[:n] = t.children_left[:n]
    right[:n] = t.children_right[:n]
    output[:n] = tree.classes_[np.argmax(t.value[:n, 0, :], axis=1)]
    return feature, threshold, left, right, output


def predict_tree(features: np.ndarray, tree: tuple[np.ndarray, ...]) -> np.ndarray:
    """Outputs ``(n,)`` ±1 of one tree stored as arrays (as :func:`fit_cart` returns them).

    Parameters
    ----------
    features : (n, d) float
        Compared as float32 with the thresholds, like scikit-learn.
    tree : (feature, threshold, left, right, output)
        Arrays over the ``2^(depth+1) − 1`` nodes.
    """
    feature, threshold, left, right, output = tree
    x32 = np.asarray(features).astype(np.float32).astype(np.float64)
    node = np.zeros(len(x32), np.int64)
    cols = np.arange(len(x32))
    depth = int(np.log2(len(left) + 1)) - 1
    for _ in range(depth):
        lft = left[node]
        nxt = np.where(x32[cols, feature[node]] <= threshold[node], lft, right[node])
        node = np.where(lft >= 0, nxt, node)
    return output[node]


# --------------------------------------------------------------------------------------------------
# B15 / B16 parameters
@dataclass(frozen=True, slots=True)
class AppearanceParams:
    """Learning by tracking (B15) and score maps (B16) around B12-B14.

    Attributes
    ----------
    patches, features, boost : PatchParams, FeatureParams, BoostParams
        B12, B13, B14.
    n_confusers : int
        ``L``, the closest other targets whose patches are negatives (2, B15 [RECON]).
    update_every : int
        ``n_upd``: frames of samples between two updates (5, B15 [RECON]).
    update_samples : int
        Update earlier once this many new samples are waiting (100, B15 [RECON]).
    reservoir_size : int
        Past samples kept per class and mixed 50/50 with new ones (500, B15 [RECON]); 0 disables it.
    background_patches : int
        Extra negatives per target from the ring around its box (box dilated by ``background_margin``),
        centres outside every box (0 = off; the paper names only confusing targets) [RECON].
    background_margin : float
        Dilation of the box, as a fraction of its size, for background negatives (0.5).
    map_patches : int
        ``N_map``, random patches of a score map (300, B16 [RECON]).
    region_dilation : float
        The interacting region is the union of the boxes dilated by this fraction (0.2, B16).
    map_eps : float
        ``ε0`` of the score-map likelihood (1e-3, B16).
    min_score : float
        ``s_min`` of B17: an identity whose mean confidence is below it is rejected (0).
    min_foreground : float
        When a foreground mask is given, a box patch needs at least this fraction of foreground pixels to be
        learnt or scored (0.5) [RECON: keeps the floor seen through a box out of both classes].
    depth_margin_m : float
        When the targets' distances from the camera are given (``depth_m``), a patch centred where two boxes
        overlap shows the nearer target if it is at least this much nearer: it is kept for that one and dropped
        for the other; closer in depth than this, it is dropped for both, as B15 drops every such patch
        (0.3 m, about a body's depth) [RECON, extends B15].
    """

    patches: PatchParams = field(default_factory=PatchParams)
    features: FeatureParams = field(default_factory=FeatureParams)
    boost: BoostParams = field(default_factory=BoostParams)
    n_confusers: int = 2
    update_every: int = 5
    update_samples: int = 100
    reservoir_size: int = 500
    background_patches: int = 0
    background_margin: float = 0.5
    map_patches: int = 300
    region_dilation: float = 0.2
    map_eps: float = 1e-3
    min_score: float = 0.0
    min_foreground: float = 0.5
    depth_margin_m: float = 0.3

    def __post_init__(self) -> None:
        for name, kind in (("patches", PatchParams), ("features", FeatureParams), ("boost", BoostParams)):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(f"AppearanceParams.{name}: expected a {kind.__name__}, got "
                                 f"{type(getattr(self, name)).__name__}")
        _check_int("AppearanceParams", "n_confusers", self.n_confusers, 1)
        _check_int("AppearanceParams", "update_every", self.update_every, 1)
        _check_int("AppearanceParams", "update_samples", self.update_samples, 1)
        _check_int("AppearanceParams", "reservoir_size", self.reservoir_size, 0)
        _check_int("AppearanceParams", "background_patches", self.background_patches, 0)
        _check_int("AppearanceParams", "map_patches", self.map_patches, 1)
        for name in ("background_margin", "region_dilation"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"AppearanceParams.{name}: expected a finite fraction >= 0, got {v!r}")
        if not (np.isfinite(self.map_eps) and self.map_eps > 0):
            raise ValueError(f"AppearanceParams.map_eps: expected a finite value > 0, got {self.map_eps!r}")
        if not 0 <= self.min_foreground <= 1:
            raise ValueError(f"AppearanceParams.min_foreground: expected a fraction in [0, 1], got "
                             f"{self.min_foreground!r}")
        if isinstance(self.depth_margin_m, bool) or not (np.isfinite(self.depth_margin_m) and self.depth_margin_m > 0):
            raise ValueError(f"AppearanceParams.depth_margin_m: expected a finite distance > 0, got "
                             f"{self.depth_margin_m!r}")
        if not -1 <= self.min_score <= 1:
            raise ValueError(f"AppearanceParams.min_score: expected a confidence in [-1, 1], got {self.min_score!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AppearanceParams:
        d = dict(data)
        try:
            d["patches"] = PatchParams(**d.get("patches", {}))
            d["features"] = FeatureParams(**d.get("features", {}))
            d["boost"] = BoostParams(**d.get("boost", {}))
            return cls(**d)
        except TypeError as err:
            raise ValueError(f"AppearanceParams: malformed ({err})") from err


# --------------------------------------------------------------------------------------------------
# B15: one target's learner
class AppearanceClassifier:
    """One target's online appearance model: a B14 ensemble, B15's reservoir and update cadence.

    Samples are added frame by frame with :meth:`add_samples`; :meth:`due` says when B15 wants an update
    (at once for the first, then every ``update_every`` frames of samples or at ``update_samples`` waiting
    samples); :meth:`update` learns the waiting samples mixed 50/50 (per class) with a random draw from the
    reservoir of past samples, then adds them to the reservoir (Vitter's algorithm R, uniform over the past).
    """

    def __init__(self, params: AppearanceParams | None = None) -> None:
        self.params = params or AppearanceParams()
        d = self.params.features.n_features
        self.ensemble = BoostedClassifier(self.params.boost, d)
        self._pending_x: list[np.ndarray] = []
        self._pending_y: list[np.ndarray] = []
        self.pending_frames = 0
        self.n_updates = 0
        self._reservoir = {c: np.zeros((0, d)) for c in (1, -1)}
        self._seen = {1: 0, -1: 0}

    @property
    def is_trained(self) -> bool:
        return self.ensemble.is_trained

    @property
    def n_pending(self) -> int:
        return int(sum(len(y) for y in self._pending_y))

    def reservoir(self, label: int) -> np.ndarray:
        """Past samples ``(n, d)`` of class ``label`` (+1 or −1), a copy."""
        return self._reservoir[1 if label > 0 else -1].copy()

    def add_samples(self, features: np.ndarray, labels: np.ndarray) -> None:
        """Queue one frame's samples ``(n, d)`` with labels ``(n,)`` in {−1, +1} (either class may be absent)."""
        x = np.asarray(features, dtype=np.float64)
        y = np.asarray(labels)
        d = self.ensemble.n_features
        if x.ndim != 2 or x.shape[1] != d or y.shape != (len(x),) or not np.isin(y, (-1, 1)).all():
            raise ValueError(f"features, labels: expected (n, {d}) and (n,) in {{-1, +1}}, got {x.shape}, {y.shape}")
        self._pending_x.append(x)
        self._pending_y.append(y.astype(np.int64))
        self.pending_frames += 1

    def _pending_has_both(self) -> bool:
        return any((y > 0).any() for y in self._pending_y) and any((y < 0).any() for y in self._pending_y)

    def due(self) -> bool:
        """True when B15 wants an update now (and the waiting samples hold both classes)."""
        if not self._pending_has_both():
            return False
        p = self.params
        return (not self.is_trained or self.pending_frames >= p.update_every
                or self.n_pending >= p.update_samples)

    def update(self, rng: np.random.Generator | int | None = None) -> BoostUpdate | None:
        """Learn the waiting samples (+ reservoir draw) now; None when they do not hold both classes."""
        if not self._pending_has_both():
            return None
        rng = np.random.default_rng(rng)
        x_new = np.concatenate(self._pending_x)
        y_new = np.concatenate(self._pending_y)
        xs, ys = [x_new], [y_new]
        for c in (1, -1):  # 50/50: as many past samples of a class as new ones, without replacement (B15)
            res = self._reservoir[c]
            k = min(int(np.count_nonzero(y_new == c)), len(res))
            if k:
                xs.append(res[rng.choice(len(res), k, replace=False)])
                ys.append(np.full(k, c, np.int64))
        result = self.ensemble.update(np.concatenate(xs), np.concatenate(ys), rng)
        for c in (1, -1):
            self._add_to_reservoir(c, x_new[y_new == c], rng)
        self._pending_x.clear()
        self._pending_y.clear()
        self.pending_frames = 0
        self.n_updates += 1
        return result

    def _add_to_reservoir(self, c: int, x: np.ndarray, rng: np.random.Generator) -> None:
        cap = self.params.reservoir_size
        res, seen = self._reservoir[c], self._seen[c]
        self._seen[c] = seen + len(x)
        if cap == 0 or len(x) == 0:
            return
        free = cap - len(res)
        res = np.concatenate([res, x[:free]]) if free > 0 else res.copy()
        rest = x[max(free, 0):]
        if len(rest):
            # algorithm R: the i-th sample seen (0-based) replaces a random slot with probability cap/(i+1)
            index = seen + max(free, 0) + np.arange(len(rest))
            j = np.floor(rng.random(len(rest)) * (index + 1)).astype(np.int64)
            hit = j < cap
            res[j[hit]] = rest[hit]
        self._reservoir[c] = res

    def confidence(self, features: np.ndarray) -> np.ndarray:
        """``conf`` ``(n,)`` in [−1, 1] of the current ensemble (0 while untrained)."""
        return self.ensemble.confidence(features)

    def to_dict(self, samples: bool = True) -> dict[str, Any]:
        """JSON-ready state: ensemble, counters and (``samples``) the reservoir and the waiting samples.

        With ``samples=False`` the state is ~100x smaller (no ~1000 x 23 stored features) and scores the same,
        but learning restarts without the past samples.
        """
        keep = samples
        return {
            "ensemble": self.ensemble.to_dict(),
            "reservoir_pos": self._reservoir[1].tolist() if keep else [],
            "reservoir_neg": self._reservoir[-1].tolist() if keep else [],
            "seen_pos": self._seen[1] if keep else 0,
            "seen_neg": self._seen[-1] if keep else 0,
            "pending_x": [x.tolist() for x in self._pending_x] if keep else [],
            "pending_y": [y.tolist() for y in self._pending_y] if keep else [],
            "pending_frames": self.pending_frames if keep else 0,
            "n_updates": self.n_updates,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], params: AppearanceParams | None = None) -> AppearanceClassifier:
        out = cls(params)
        d = out.ensemble.n_features
        try:
            out.ensemble = BoostedClassifier.from_dict(data["ensemble"])
            out._reservoir = {1: np.asarray(data["reservoir_pos"], np.float64).reshape(-1, d),
                              -1: np.asarray(data["reservoir_neg"], np.float64).reshape(-1, d)}
            out._seen = {1: int(data["seen_pos"]), -1: int(data["seen_neg"])}
            out._pending_x = [np.asarray(x, np.float64).reshape(-1, d) for x in data["pending_x"]]
            out._pending_y = [np.asarray(y, np.int64).reshape(-1) for y in data["pending_y"]]
            out.pending_frames = int(data["pending_frames"])
            out.n_updates = int(data["n_updates"])
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"AppearanceClassifier state: malformed ({err})") from err
        if out.ensemble.n_features != d:
            raise ValueError(f"AppearanceClassifier state: {out.ensemble.n_features} features, params say {d}")
        return out


# --------------------------------------------------------------------------------------------------
# B16: score maps and their likelihood
@dataclass(frozen=True, slots=True, eq=False)
class ScoreMap:
    """Classifier confidences of patches of one image region (B16).

    Attributes
    ----------
    ids : tuple of int
        Target of each row of ``scores``.
    centres_px : (n_patches, 2) float64
        Patch centres ``d_i`` ``(u, v)``.
    scores : (n_ids, n_patches) float64
        ``s_i^k = conf_k(patch_i)`` in [−1, 1].
    size_px : int
        Patch side (the default bandwidth ``σ_d``).
    region_px : (4,) float64
        The region sampled.
    grid_shape : (rows, cols) or None
        For a grid map, ``scores[k].reshape(grid_shape)`` is an image of the map.
    """

    ids: tuple[int, ...]
    centres_px: np.ndarray
    scores: np.ndarray
    size_px: int
    region_px: np.ndarray
    grid_shape: tuple[int, int] | None = None

    def row(self, target_id: int) -> np.ndarray:
        """Scores ``(n_patches,)`` of one target."""
        try:
            return self.scores[self.ids.index(target_id)]
        except ValueError as err:
            raise ValueError(f"target_id: {target_id} is not in this score map ({list(self.ids)})") from err

    def likelihood(self, positions_px: np.ndarray, target_id: int | None = None, sigma_px: float | None = None,
                   eps0: float = 1e-3) -> np.ndarray:
        """B16 likelihood of particles at image positions; see :func:`score_map_likelihood`.

        ``positions_px`` is ``(n_particles, 2)`` for one ``target_id``, or ``(n_ids, n_particles, 2)`` for all
        targets (``target_id=None``, rows in the order of :attr:`ids`).
        """
        s = self.scores if target_id is None else self.row(target_id)
        sigma = float(self.size_px) if sigma_px is None else sigma_px
        return score_map_likelihood(self.centres_px, s, positions_px, sigma, eps0)


def score_map_likelihood(centres_px: np.ndarray, scores: np.ndarray, positions_px: np.ndarray,
                         sigma_px: float = 12.0, eps0: float = 1e-3) -> np.ndarray:
    """Score-map observation likelihood of B16, vectorised over targets, particles and patches.

    ``p(z | x) ∝ ε0 + Σ_i max(s_i, 0) · exp(−‖d(x) − d_i‖² / (2 σ_d²))`` (seed 001, ALGORITHMS.md B16 [RECON]).

    Parameters
    ----------
    centres_px : (n_patches, 2) float
        Patch centres ``d_i``.
    scores : (..., n_patches) float
        Confidences ``s_i`` (one row per target, or a single row).
    positions_px : (..., n_particles, 2) float
        Box centres ``d(x)`` of the particles, broadcast against ``scores``' leading axes.
    sigma_px : float
        Bandwidth ``σ_d`` (the patch size, px).
    eps0 : float
        Floor ``ε0`` so that no particle has zero likelihood.

    Returns
    -------
    (..., n_particles) float64
    """
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise ValueError(f"sigma_px: expected a finite bandwidth > 0 px, got {sigma_px!r}")
    if not (np.isfinite(eps0) and eps0 >= 0):
        raise ValueError(f"eps0: expected a finite value >= 0, got {eps0!r}")
    c = np.asarray(centres_px, dtype=np.float64)
    s = np.asarray(scores, dtype=np.float64)
    x = np.asarray(positions_px, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 2 or s.shape[-1:] != c.shape[:1]:
        raise ValueError(f"centres_px, scores: expected (n, 2) and (..., n), got {c.shape} and {s.shape}")
    if x.ndim < 2 or x.shape[-1] != 2:
        raise ValueError(f"positions_px: expected (..., n_particles, 2), got {x.shape}")
    # ‖x − c‖² = ‖x‖² − 2 x·c + ‖c‖²; the kernel matrix (..., n_particles, n_patches) times the scores, built in
    # one buffer (the same operations, in place: a few hundred particles times 300 patches per score map)
    k = x @ c.T
    k *= -2.0
    k += (x**2).sum(-1)[..., None]
    k += (c**2).sum(-1)
    np.maximum(k, 0.0, out=k)
    np.negative(k, out=k)
    k /= 2.0 * sigma_px**2
    np.exp(k, out=k)
    return eps0 + (k @ np.maximum(s, 0.0)[..., None])[..., 0]


def assign_identities(scores: np.ndarray, min_score: float = 0.0) -> list[tuple[int, int]]:
    """B17's split: one-to-one assignment of boxes to identities maximising the summed score (Hungarian, X2).

    Parameters
    ----------
    scores : (n_boxes, n_ids) float
        ``score_jk``, e.g. :meth:`AppearanceBank.box_scores`; NaN = impossible.
    min_score : float
        ``s_min``: an assigned pair scoring less is rejected (the box becomes a new target).

    Returns
    -------
    list of (box_index, id_index)
        The accepted pairs, by box index.
    """
    s = np.asarray(scores, dtype=np.float64)
    if s.ndim != 2:
        raise ValueError(f"scores: expected (n_boxes, n_ids), got shape {s.shape}")
    if s.size == 0:
        return []
    cost = np.where(np.isfinite(s), -s, 1e9)  # forbidden pairs: X2's large cost
    rows, cols = linear_sum_assignment(cost)
    keep = np.isfinite(s[rows, cols]) & (s[rows, cols] >= min_score)
    return [(int(r), int(c)) for r, c in zip(rows[keep], cols[keep], strict=True)]


def interacting_region(boxes_px: np.ndarray, dilation: float = 0.2,
                       image_shape: tuple[int, ...] | None = None) -> np.ndarray:
    """The union ``(4,)`` of boxes, each dilated by ``dilation`` of its size about its centre, clipped to the image
    when ``image_shape`` is given (B16's interacting region)."""
    b = as_boxes(boxes_px)
    if not (np.isfinite(dilation) and dilation >= 0):
        raise ValueError(f"dilation: expected a finite fraction >= 0, got {dilation!r}")
    half = (b[:, 2:] - b[:, :2]) * (1 + dilation) / 2
    mid = (b[:, 2:] + b[:, :2]) / 2
    region = np.concatenate([(mid - half).min(axis=0), (mid + half).max(axis=0)])
    if image_shape is not None:
        h, w = image_shape[:2]
        region = np.clip(region, 0, [w, h, w, h])
    return region


def _inside(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """``(n_points, n_boxes)`` bool: point in the half-open box ``[u_min, u_max) × [v_min, v_max)``."""
    p = points[:, None, :]
    return ((boxes[None, :, :2] <= p) & (p < boxes[None, :, 2:])).all(axis=2)


def _hidden(points: np.ndarray, owner: np.ndarray, boxes: np.ndarray, depth: np.ndarray | None,
            margin: float) -> np.ndarray:
    """``(n_points,)`` bool: which patch centres ``points`` of box ``owner`` may show another target, being
    inside another box: any other box (B15), or with the targets' distances from the camera ``depth`` (NaN where
    unknown), another box whose target is not at least ``margin`` farther than the owner (it may be in front)."""
    inside = _inside(points, boxes)
    inside[np.arange(len(owner)), owner] = False
    if depth is not None:
        d = np.asarray(depth, np.float64)
        behind = d[None, :] - d[owner][:, None] >= margin  # NaN compares False: such a box may be in front
        inside &= ~behind
    return inside.any(axis=1)


# --------------------------------------------------------------------------------------------------
# the bank
class AppearanceBank:
    """One :class:`AppearanceClassifier` per target id, trained from boxes and queried for scores.

    Parameters
    ----------
    params : AppearanceParams, optional
    rng : numpy.random.Generator or int or None
        Normalised once; draws every patch and seeds every tree.
    """

    def __init__(self, params: AppearanceParams | None = None,
                 rng: np.random.Generator | int | None = None) -> None:
        self.params = params or AppearanceParams()
        self.rng = np.random.default_rng(rng)
        self._targets: dict[int, AppearanceClassifier] = {}
        self._frozen: dict[int, AppearanceClassifier] = {}  # :meth:`freeze`
        self._integrals: IntegralCache | None = None  # :meth:`cache_image`

    def cache_image(self, image: np.ndarray | None) -> None:
        """Reuse the integral images (B13, X3) of ``image`` across the scorings and trainings on it that follow,
        until another image (or None) is given: :class:`~fusiontrack.vision.patches.IntegralCache` (the same
        features). The array is kept by reference; another array, even with the same pixels, is not cached, and
        neither is a writeable one (a buffer refilled in place with the next frame would give the old features:
        the tracker's images are read-only)."""
        if image is None or image.flags.writeable:
            self._integrals = None
        elif self._integrals is None or self._integrals.image is not image:
            self._integrals = IntegralCache(image, self.params.features)

    def _features(self, img: np.ndarray, patches: Patches) -> np.ndarray:
        cache = self._integrals
        if cache is not None and cache.image is img and cache.params == self.params.features:
            return cache.features(patches)
        return extract_features(img, patches, self.params.features)

    # -- container ----------------------------------------------------------------------------------
    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(self._targets)

    def __len__(self) -> int:
        return len(self._targets)

    def __contains__(self, target_id: object) -> bool:
        return target_id in self._targets

    def classifier(self, target_id: int, frozen: bool = False) -> AppearanceClassifier:
        """The classifier of one target (``ValueError`` if unknown); ``frozen``: its frozen copy if it has one."""
        if frozen and int(target_id) in self._frozen:
            return self._frozen[int(target_id)]
        try:
            return self._targets[int(target_id)]
        except KeyError as err:
            raise ValueError(f"target_id: no classifier for target {target_id} (known: {list(self._targets)})") from err

    def is_trained(self, target_id: int) -> bool:
        return target_id in self._targets and self._targets[target_id].is_trained

    def drop(self, target_ids: int | Iterable[int]) -> None:
        """Forget targets (unknown ids are ignored), and their frozen copies."""
        for i in [target_ids] if isinstance(target_ids, int | np.integer) else list(target_ids):
            self._targets.pop(int(i), None)
            self._frozen.pop(int(i), None)

    # -- frozen copies --------------------------------------------------------------------------------
    def freeze(self, target_id: int) -> None:
        """Keep a copy of the target's classifier as it is now: scorings with ``frozen=True`` use it, while the
        classifier itself goes on learning (a vote taken by the copy is not swayed by what was learnt since,
        perhaps of the wrong person); replaces an earlier copy."""
        self._frozen[int(target_id)] = copy.deepcopy(self.classifier(target_id))

    @property
    def frozen_ids(self) -> tuple[int, ...]:
        return tuple(self._frozen)

    def is_frozen(self, target_id: int) -> bool:
        return int(target_id) in self._frozen

    def thaw(self, target_id: int) -> None:
        """Forget the target's frozen copy (if any)."""
        self._frozen.pop(int(target_id), None)

    def restore(self, target_id: int) -> None:
        """Undo what the target learnt since it was frozen (it learnt the wrong person): the classifier becomes a
        copy of the frozen one, which is kept."""
        tid = int(target_id)
        if tid not in self._frozen:
            raise ValueError(f"restore: target {tid} has no frozen classifier")
        self._targets[tid] = copy.deepcopy(self._frozen[tid])

    # -- training (B15) -----------------------------------------------------------------------------
    def samples_from(self, boxes_px: np.ndarray, image_shape: tuple[int, ...]) -> np.ndarray:
        """``(n,) bool``: which boxes are enough inside an image of ``image_shape`` to give patches
        (``patches.min_visible`` of their area; none that is wholly off it), for :meth:`train` and
        :meth:`box_scores` alike."""
        return box_visibility(boxes_px, image_shape) >= max(self.params.patches.min_visible, 1e-12)

    def train(self, image: Any, boxes_by_id: Mapping[int, Sequence[float] | np.ndarray],
              train_ids: Iterable[int] | None = None, positions_m: Mapping[int, Sequence[float]] | None = None,
              mask: np.ndarray | None = None, force_update: bool = False,
              depth_m: Mapping[int, float] | None = None) -> list[int]:
        """Add one frame of samples for the training targets and update those B15 says are due.

        Parameters
        ----------
        image : (H, W, 3) uint8 BGR or fusiontrack.types.Image
        boxes_by_id : mapping id -> (4,) px
            Boxes ``(u_min, v_min, u_max, v_max)`` of *every* tracked target in the image (confusers included).
        train_ids : iterable of int, optional
            The targets that learn this frame (B15: noncorrelated targets with another one within 1.5 m; the
            tracker decides); all of ``boxes_by_id`` by default.
        positions_m : mapping id -> (2,) m, optional
            Ground positions choosing the ``L`` closest confusers (B15); image distances between box
            bottom-centres otherwise.
        mask : (H, W) bool, optional
            Foreground mask (e.g. :class:`~fusiontrack.vision.ForegroundModel`'s): box patches with less than
            ``min_foreground`` of their pixels set are not learnt, for positives and negatives alike.
        force_update : bool
            Update every training target that has samples of both classes now, whatever the cadence.
        depth_m : mapping id -> m, optional
            Each target's distance from the camera (for a tracked person, from the camera's floor point to the
            person's): where boxes overlap, a patch is kept for the target at least ``depth_margin_m`` nearer
            than the others there (it is in front) instead of being dropped for all.

        Returns
        -------
        list of int
            Ids whose ensemble was updated this frame.

        Notes
        -----
        A box less than ``min_visible`` inside the image (or off it) gives no samples and is skipped. A patch
        whose centre lies in another target's box is dropped (B15), for positives and negatives alike, unless
        ``depth_m`` puts its own target in front of that one.
        Targets without a negative this frame (no visible confuser and no background patches) queue their
        positives only; the update waits for both classes.
        """
        img = validate_image(image, "image")
        p = self.params
        ids = [int(i) for i in boxes_by_id]
        if len(set(ids)) != len(ids):
            raise ValueError("boxes_by_id: duplicate target ids")
        learners = ids if train_ids is None else list(dict.fromkeys(int(i) for i in train_ids))
        unknown = set(learners) - set(ids)
        if unknown:
            raise ValueError(f"train_ids: {sorted(unknown)} have no box in boxes_by_id")
        if not ids:
            return []
        row_of = {tid: k for k, tid in enumerate(ids)}
        boxes = as_boxes(np.array([np.asarray(boxes_by_id[i], np.float64).reshape(4) for i in ids]), "boxes_by_id")
        vis = self.samples_from(boxes, img.shape)
        rows = np.flatnonzero(vis)
        patches = sample_patches(boxes[rows], img.shape, p.patches, self.rng) if len(rows) else \
            Patches(np.zeros((0, 2), np.int64), np.zeros(0, np.int64), p.patches.size_px)
        owner = rows[patches.box_index]  # index into ids
        depth = self._depths(ids, depth_m)
        # B15: no patch centred in another target's box (unless the depths put its own target in front)
        keep = ~_hidden(patches.centres_px, owner, boxes, depth, p.depth_margin_m)
        if mask is not None:
            keep &= self._on_mask(mask, img.shape, patches)
        patches, owner = patches.subset(keep), owner[keep]
        n_bg = p.background_patches
        bg_owner = np.zeros(0, np.int64)
        if n_bg:
            bg, bg_owner = self._background(img.shape, boxes, [row_of[i] for i in learners if vis[row_of[i]]])
            patches = Patches(np.concatenate([patches.corners_px, bg.corners_px]),
                              np.concatenate([patches.box_index, bg.box_index]), p.patches.size_px)
        feats = self._features(img, patches)
        n_box = len(owner)
        box_feats, bg_feats = feats[:n_box], feats[n_box:]
        has = np.bincount(owner, minlength=len(ids)) > 0
        where = self._positions(ids, boxes, positions_m)
        updated = []
        for tid in learners:
            k = row_of[tid]
            if not has[k]:
                log.debug("appearance: target %d has no visible patches this frame", tid)
                continue
            dist = np.linalg.norm(where - where[k], axis=1)
            dist[k] = np.inf
            dist[~has] = np.inf
            near = np.argsort(dist, kind="stable")[: p.n_confusers]
            near = near[np.isfinite(dist[near])]
            neg = np.isin(owner, near)
            x_parts = [box_feats[owner == k], box_feats[neg]]
            if n_bg:
                x_parts.append(bg_feats[bg_owner == k])
            x = np.concatenate(x_parts)
            y = np.concatenate([np.ones(len(x_parts[0]), np.int64), -np.ones(len(x) - len(x_parts[0]), np.int64)])
            clf = self._targets.get(tid)
            if clf is None:
                clf = self._targets[tid] = AppearanceClassifier(p)
            clf.add_samples(x, y)
            if (clf.due() or force_update) and clf.update(self.rng) is not None:
                updated.append(tid)
        return updated

    def _background(self, image_shape: tuple[int, ...], boxes: np.ndarray,
                    rows: list[int]) -> tuple[Patches, np.ndarray]:
        """Background negatives around the boxes ``rows``: centres in the dilated box, outside every box."""
        p = self.params
        s = p.patches.size_px
        if not rows:
            return Patches(np.zeros((0, 2), np.int64), np.zeros(0, np.int64), s), np.zeros(0, np.int64)
        b = boxes[rows]
        pad = (b[:, 2:] - b[:, :2]) * p.background_margin + s
        ring = np.concatenate([b[:, :2] - pad, b[:, 2:] + pad], axis=1)
        ring = np.clip(ring, 0, [image_shape[1], image_shape[0]] * 2)
        ok = (ring[:, 2] - ring[:, 0] >= s) & (ring[:, 3] - ring[:, 1] >= s)
        ring_rows = np.flatnonzero(ok)
        if not len(ring_rows):
            return Patches(np.zeros((0, 2), np.int64), np.zeros(0, np.int64), s), np.zeros(0, np.int64)
        cand = sample_patches(ring[ring_rows], image_shape, PatchParams(s, min_visible=0.0), self.rng,
                              counts=np.full(len(ring_rows), 4 * p.background_patches))
        free = ~_inside(cand.centres_px, boxes).any(axis=1)
        cand_owner = np.asarray(rows)[ring_rows][cand.box_index]
        # the first ``background_patches`` free candidates of each box (candidates are grouped by box)
        # rank of each free candidate within its box (box_index is grouped but not sorted by owner id)
        order = np.flatnonzero(free)
        group = cand.box_index[order]
        order = order[np.argsort(group, kind="stable")]
        group = cand.box_index[order]
        first = np.searchsorted(group, group, side="left")
        rank = np.arange(len(order)) - first
        take = order[rank < p.background_patches]
        return cand.subset(take), cand_owner[take]

    def _on_mask(self, mask: np.ndarray, image_shape: tuple[int, ...], patches: Patches) -> np.ndarray:
        m = np.asarray(mask)
        if m.shape != tuple(image_shape[:2]):
            raise ValueError(f"mask: expected shape {tuple(image_shape[:2])} like the image, got {m.shape}")
        return patch_fraction(m, patches) >= self.params.min_foreground

    @staticmethod
    def _depths(ids: Sequence[int], depth_m: Mapping[int, float] | None) -> np.ndarray | None:
        """``(len(ids),)`` distances from the camera (NaN where unknown) of ``depth_m``; None without any."""
        if depth_m is None:
            return None
        d = np.array([float(depth_m.get(i, np.nan)) for i in ids])
        if np.isinf(d).any() or (d < 0).any():
            raise ValueError("depth_m: expected distances >= 0 (NaN where unknown)")
        return d

    @staticmethod
    def _positions(ids: list[int], boxes: np.ndarray, positions_m: Mapping[int, Sequence[float]] | None) -> np.ndarray:
        if positions_m is None:
            return np.column_stack([(boxes[:, 0] + boxes[:, 2]) / 2, boxes[:, 3]])
        missing = [i for i in ids if i not in positions_m]
        if missing:
            raise ValueError(f"positions_m: no position for targets {missing}")
        pos = np.array([np.asarray(positions_m[i], np.float64).reshape(-1)[:2] for i in ids])
        if not np.isfinite(pos).all():
            raise ValueError("positions_m: expected finite positions")
        return pos

    # -- scoring ------------------------------------------------------------------------------------
    def _rows(self, ids: Iterable[int] | None) -> list[int]:
        out = list(self._targets) if ids is None else [int(i) for i in ids]
        unknown = [i for i in out if i not in self._targets]
        if unknown:
            raise ValueError(f"ids: no classifier for targets {unknown} (known: {list(self._targets)})")
        return out

    def confidences(self, features: np.ndarray, ids: Iterable[int] | None = None, frozen: bool = False
                    ) -> np.ndarray:
        """``conf_k`` of feature vectors: ``(n_ids, n)`` float64 in [−1, 1] (rows in the order of ``ids``);
        ``frozen``: by the frozen copies (:meth:`freeze`) where there are any."""
        rows = self._rows(ids)
        x = np.asarray(features, dtype=np.float64)
        return np.stack([self.classifier(i, frozen).confidence(x) for i in rows]) if rows else np.zeros((0, len(x)))

    def patch_scores(self, image: Any, patches: Patches, ids: Iterable[int] | None = None, frozen: bool = False
                     ) -> np.ndarray:
        """``conf_k`` of given patches of an image: ``(n_ids, n_patches)``."""
        img = validate_image(image, "image")
        return self.confidences(self._features(img, patches), ids, frozen)

    def box_scores(self, image: Any, boxes_px: np.ndarray, ids: Iterable[int] | None = None,
                   mask: np.ndarray | None = None, exclusive: bool = False,
                   frozen: bool = False) -> np.ndarray:
        """Mean confidence of each target's classifier over B12 patches of each box (B17's ``score_jk``).

        Parameters
        ----------
        image : (H, W, 3) uint8 BGR or Image
        boxes_px : (n_boxes, 4) or (4,) px
        ids : iterable of int, optional
            Classifiers to use (all by default).
        mask : (H, W) bool, optional
            Foreground mask: only patches with at least ``min_foreground`` foreground pixels count.
        exclusive : bool
            Drop the patches centred in another of the boxes (B15's rule for training samples, applied to
            scoring: where two boxes overlap, a patch may show either person).
        frozen : bool
            Score with the targets' frozen copies (:meth:`freeze`) where they have one.

        Returns
        -------
        (n_boxes, n_ids) float64
            NaN for a box that gives no patches (less than ``min_visible`` in the image, off it, or smaller
            than a patch, or, ``exclusive``, covered by the other boxes).
        """
        img = validate_image(image, "image")
        rows = self._rows(ids)
        boxes = as_boxes(boxes_px)
        vis = np.flatnonzero(self.samples_from(boxes, img.shape))
        out = np.full((len(boxes), len(rows)), np.nan)
        if not len(vis):
            return out
        patches = sample_patches(boxes[vis], img.shape, self.params.patches, self.rng)
        if mask is not None:
            patches = patches.subset(self._on_mask(mask, img.shape, patches))
        if exclusive and len(boxes) > 1:
            patches = patches.subset(~_hidden(patches.centres_px, vis[patches.box_index], boxes, None, 0.0))
        conf = self.patch_scores(img, patches, rows, frozen)  # (n_ids, n_patches)
        count = np.bincount(patches.box_index, minlength=len(vis)).astype(np.float64)
        onehot = np.zeros((len(vis), len(patches)))
        onehot[patches.box_index, np.arange(len(patches))] = 1.0
        with np.errstate(invalid="ignore", divide="ignore"):
            out[vis] = (onehot @ conf.T) / count[:, None]
        return out

    def identify(self, image: Any, box_px: np.ndarray, ids: Iterable[int] | None = None,
                 mask: np.ndarray | None = None, min_score: float | None = None) -> tuple[int | None, np.ndarray]:
        """Which of the targets ``ids`` an unknown box shows (B17): the best mean confidence, if >= ``min_score``.

        Parameters
        ----------
        image : (H, W, 3) uint8 BGR or Image
        box_px : (4,) px
        ids : iterable of int, optional
            Candidate identities (all classifiers by default).
        mask : (H, W) bool, optional
            Foreground mask (see :meth:`box_scores`).
        min_score : float, optional
            B17's ``s_min`` (``params.min_score``, 0, by default); −1 always names a candidate.

        Returns
        -------
        best : int or None
            The target id, or None when every score is below ``min_score`` (a new target) or NaN.
        scores : (n_ids,) float64
            Mean confidence per target, in the order of ``ids``.
        """
        rows = self._rows(ids)
        scores = self.box_scores(image, np.asarray(box_px, np.float64).reshape(1, 4), rows, mask)[0]
        if not rows or not np.isfinite(scores).any():
            return None, scores
        j = int(np.nanargmax(scores))
        s_min = self.params.min_score if min_score is None else min_score
        return (rows[j] if scores[j] >= s_min else None), scores

    def score_map(self, image: Any, ids: Iterable[int] | None = None, boxes_px: np.ndarray | None = None,
                  region_px: np.ndarray | None = None, stride_px: int | None = None,
                  mask: np.ndarray | None = None) -> ScoreMap:
        """Score map of the interacting region for each target (B16).

        Parameters
        ----------
        image : (H, W, 3) uint8 BGR or Image
        ids : iterable of int, optional
            The interacting targets (all by default).
        boxes_px : (n, 4), optional
            Their boxes: the region is their union dilated by ``region_dilation`` (B16).
        region_px : (4,), optional
            The region itself (instead of ``boxes_px``).
        stride_px : int, optional
            Patches on a grid with this step; ``map_patches`` random patches when None (B16).
        mask : (H, W) bool, optional
            Foreground mask: patches with less than ``min_foreground`` foreground pixels score 0 (they add
            nothing to the likelihood).

        Returns
        -------
        ScoreMap
        """
        img = validate_image(image, "image")
        rows = self._rows(ids)
        p = self.params
        if (boxes_px is None) == (region_px is None):
            raise ValueError("boxes_px, region_px: give exactly one of them")
        if region_px is None:
            region = interacting_region(boxes_px, p.region_dilation, img.shape)
        else:
            region = np.clip(as_boxes(region_px, "region_px")[0], 0, [img.shape[1], img.shape[0]] * 2)
        if region[2] <= region[0] or region[3] <= region[1]:
            raise ValueError(f"region: {region.tolist()} does not overlap the {img.shape[1]}x{img.shape[0]} image")
        s = p.patches.size_px
        grid = None
        if stride_px is None:
            patches = sample_patches(region, img.shape, PatchParams(s, min_visible=0.0), self.rng,
                                     counts=np.array([p.map_patches]))
        else:
            patches = grid_patches(region, img.shape, s, stride_px)
            if len(patches):
                xs = np.unique(patches.corners_px[:, 0])
                grid = (len(patches) // len(xs), len(xs))
        scores = self.patch_scores(img, patches, rows)
        if mask is not None:
            scores[:, ~self._on_mask(mask, img.shape, patches)] = 0.0
        return ScoreMap(tuple(rows), patch_centres(patches.corners_px, s), scores, s, region, grid)

    # -- serialisation ------------------------------------------------------------------------------
    def to_dict(self, samples: bool = True) -> dict[str, Any]:
        """JSON-ready state: parameters, every target's classifier and the random generator's state (PCG64).

        ``samples=False`` leaves out the reservoirs and waiting samples (see :meth:`AppearanceClassifier.to_dict`).
        Frozen copies (:meth:`freeze`) are not saved: a bank read back scores with its classifiers as they are.
        """
        bitgen = self.rng.bit_generator
        rng_state = bitgen.state if type(bitgen).__name__ == "PCG64" else None
        return {
            "format": _FORMAT,
            "params": self.params.to_dict(),
            "rng": rng_state,
            "targets": {str(i): c.to_dict(samples) for i, c in self._targets.items()},
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AppearanceBank:
        """Inverse of :meth:`to_dict` (``ValueError`` on another format or a malformed state).

        A state of the first format (``fusiontrack.appearance/1``, saved before ``FeatureParams.colour``
        existed) is read with ``colour="rgb"``, the features its classifiers learnt.
        """
        if not isinstance(data, Mapping) or data.get("format") not in (_FORMAT, _FORMAT_RGB):
            got = data.get("format") if isinstance(data, Mapping) else type(data).__name__
            raise ValueError(f"appearance state: expected format {_FORMAT!r}, got {got!r}")
        if not isinstance(data.get("params"), Mapping):
            raise ValueError("appearance state: malformed params (expected a mapping)")
        raw = dict(data["params"])
        if data["format"] == _FORMAT_RGB:
            raw["features"] = {"colour": "rgb", **raw.get("features", {})}
        params = AppearanceParams.from_dict(raw)
        out = cls(params)
        if data.get("rng") is not None:
            try:
                out.rng.bit_generator.state = data["rng"]
            except (TypeError, ValueError, KeyError) as err:
                raise ValueError(f"appearance state: bad random generator state ({err})") from err
        try:
            out._targets = {int(k): AppearanceClassifier.from_dict(v, params) for k, v in data["targets"].items()}
        except (KeyError, AttributeError) as err:
            raise ValueError(f"appearance state: malformed targets ({err})") from err
        return out
