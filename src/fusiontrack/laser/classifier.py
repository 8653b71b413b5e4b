"""Person / bicycle / car classifier of laser segments (seed 001; ALGORITHMS.md B18).

Discrete AdaBoost with decision stumps, 100 rounds, trained offline by scikit-learn
(:class:`sklearn.ensemble.AdaBoostClassifier`, multi-class SAMME, on :class:`sklearn.tree.DecisionTreeClassifier`
of depth 1); the predicted class is the one with the largest margin.

B18's three classes only. A fourth class for clutter, learnt from leg_tracker's empty-room scans
(``negative_2.bag``, recorded from a moving robot), was tried and dropped: with these features it could not
tell real walking legs from real clutter (0 of 25 held-out real leg windows right, with or without depth-2
trees or fewer features), so it would have thrown real people away.

The trained model is stored as its stumps (feature, threshold, sign, weight) in a small JSON file that ships
inside the package (``laser/models/object_classifier.json``). Two reasons not to ship scikit-learn's pickle:
a pickle is tied to the scikit-learn version that wrote it and runs code when loaded; and evaluating 100
stumps is one vectorised comparison in numpy, ~50x cheaper than ``AdaBoostClassifier.predict``'s per-call
overhead, which matters when the tracker classifies its targets on every scan.
``fusiontrack train-classifier --into-package`` rebuilds the file (:func:`train_default`).
"""

from __future__ import annotations

import functools
import json
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from fusiontrack.errors import ConfigError
from fusiontrack.laser.features import WINDOW_FEATURES
from fusiontrack.types import ObjectClass

__all__ = ["CLASSES", "ObjectClassifier", "default_classifier", "train_default"]

log = logging.getLogger(__name__)

CLASSES = (ObjectClass.PERSON.value, ObjectClass.BICYCLE.value, ObjectClass.CAR.value)
MODEL_FILE = "object_classifier.json"
FORMAT = "fusiontrack-samme-stumps-1"
_WIDTH = WINDOW_FEATURES.index("width_m")


@dataclass(frozen=True, slots=True, eq=False)
class ObjectClassifier:
    """Boosted decision stumps over ``C`` classes, ``M`` rounds (multi-class discrete AdaBoost, SAMME).

    Attributes
    ----------
    classes : tuple of str, (C,)
    features : tuple of str
        Names of the input columns (:data:`~fusiontrack.laser.features.WINDOW_FEATURES`).
    feature : (M,) int64
        Column each stump tests.
    threshold : (M,) float64
        A stump votes for class ``left[m]`` when ``x[feature] <= threshold`` and ``right[m]`` otherwise.
    left, right : (M,) int64
        Class indices.
    alpha : (M,) float64
        Stump weights (AdaBoost's ``estimator_weights_``).
    min_width_m : (C,) float64
        The narrowest window (mean ``width_m``) of each class in the training data. :meth:`predict` does not give
        a class to a window narrower than any of its training windows: the stumps never saw such a window of that
        class, and what they say there is extrapolation (a single leg of 3 points, 8 cm wide, on a real bag came
        out ``car``; the narrowest simulated car window is 0.56 m wide). Zeros (no limit) for a model file
        without it.
    """

    classes: tuple[str, ...]
    features: tuple[str, ...]
    feature: np.ndarray
    threshold: np.ndarray
    left: np.ndarray
    right: np.ndarray
    alpha: np.ndarray
    min_width_m: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.min_width_m is None:
            object.__setattr__(self, "min_width_m", np.zeros(len(self.classes)))

    def margins(self, X: Any) -> np.ndarray:
        """Share of the stumps' weight voting for each class, ``(m, C)`` in ``[0, 1]``, rows summing to 1."""
        x = np.asarray(X, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != len(self.features):
            raise ValueError(f"X: expected shape (m, {len(self.features)}), got {x.shape}")
        vote = np.where(x[:, self.feature] <= self.threshold, self.left, self.right)  # (m, M) class index
        # Each class's weight summed over the stumps in their order (a running sum: the additions of
        # ``np.add.at(out, (rows, vote), alpha)``, whose per-element loop is ~10x slower; adding 0 changes nothing)
        hit = np.where(vote[:, :, None] == np.arange(len(self.classes)), self.alpha[:, None], 0.0)  # (m, M, C)
        out = np.cumsum(hit, axis=1)[:, -1, :] if hit.shape[1] else np.zeros((len(x), len(self.classes)))
        return out / max(float(self.alpha.sum()), 1e-12)

    def predict(self, X: Any, vehicle: Any = None) -> np.ndarray:
        """The class with the largest margin among those whose training windows were ever as narrow as the
        window (``min_width_m``; when none was, the class with the narrowest training window), ``(m,)`` str.

        ``vehicle`` (``(m,)`` bool, optional): rows known not to be people (the detector's rigid objects, whole
        sides a metre long or more); their class is the largest margin among the other classes, whatever their
        width (``min_width_m`` does not apply: they are a metre wide or more)."""
        m = self.margins(X)
        if not len(m):
            return np.zeros(0, object)
        width = np.asarray(X, dtype=np.float64)[:, _WIDTH]
        seen = width[:, None] >= self.min_width_m  # (m, C)
        seen[:, int(np.argmin(self.min_width_m))] = True  # (the narrowest class is the fallback)
        if vehicle is not None:
            rows = np.asarray(vehicle, dtype=bool).reshape(-1)
            if rows.shape != (len(m),):
                raise ValueError(f"vehicle: expected shape ({len(m)},), got {np.shape(vehicle)}")
            person = np.array([c == "person" for c in self.classes])
            if rows.any() and (~person).any():
                seen[rows] = ~person
        return np.array(self.classes, dtype=object)[np.argmax(np.where(seen, m, -1.0), axis=1)]

    # ------------------------------------------------------------------------------------------------
    @classmethod
    def fit(cls, X: Any, y: Any, *, groups: Any = None, n_rounds: int = 100, classes: Sequence[str] = CLASSES,
            rng: np.random.Generator | int | None = 0) -> ObjectClassifier:
        """Train with scikit-learn's :class:`~sklearn.ensemble.AdaBoostClassifier` (SAMME) on depth-1 trees.

        B18 describes one-vs-rest AdaBoost; the multi-class SAMME form (Zhu et al. 2009) is used instead:
        independently trained one-vs-rest margins are not comparable, and on our data their argmax sent half
        of the cars to ``bicycle`` (balanced accuracy 0.84 against 0.97 for SAMME with the same 100 stumps).

        Samples are weighted so every class weighs the same, and within a class every ``groups`` value (the
        data source: simulated vs real people) weighs the same: sources are very unbalanced (thousands of
        simulated people, tens of real ones).
        """
        from sklearn.ensemble import AdaBoostClassifier
        from sklearn.tree import DecisionTreeClassifier

        x = np.asarray(X, dtype=np.float64)
        labels = np.asarray(y).astype(str)
        if x.ndim != 2 or x.shape[1] != len(WINDOW_FEATURES) or len(labels) != len(x):
            raise ValueError(f"X, y: expected X (m, {len(WINDOW_FEATURES)}) and y (m,), got {x.shape}, "
                             f"{labels.shape}")
        if not np.isfinite(x).all():
            raise ValueError("X: features must be finite")
        unknown = sorted(set(labels) - set(classes))
        if unknown:
            raise ValueError(f"y: classes {unknown} are not among {list(classes)}")
        seed = int(np.random.default_rng(rng).integers(2**31 - 1))
        source = np.zeros(len(labels), dtype=object) if groups is None else np.asarray(groups, dtype=object)
        weight = np.zeros(len(labels))
        present = [c for c in classes if (labels == c).any()]
        for c in present:
            in_c = labels == c
            names = set(source[in_c])
            for g in names:
                sel = in_c & (source == g)
                weight[sel] = 1.0 / (len(names) * sel.sum())
        weight *= len(labels) / weight.sum()
        ada = AdaBoostClassifier(DecisionTreeClassifier(max_depth=1), n_estimators=n_rounds,
                                 random_state=seed).fit(x, labels, sample_weight=weight)
        index = {c: i for i, c in enumerate(classes)}
        m = len(ada.estimators_)
        feat, thr = np.zeros(m, np.int64), np.full(m, np.inf)
        left, right = np.zeros(m, np.int64), np.zeros(m, np.int64)
        for j, est in enumerate(ada.estimators_):
            tree = est.tree_
            value = tree.value[:, 0, :]  # (nodes, classes of est)
            if tree.node_count > 1:
                feat[j], thr[j] = tree.feature[0], tree.threshold[0]
                lo, hi = tree.children_left[0], tree.children_right[0]
            else:
                lo = hi = 0
            left[j] = index[str(est.classes_[int(np.argmax(value[lo]))])]
            right[j] = index[str(est.classes_[int(np.argmax(value[hi]))])]
        width = x[:, _WIDTH]
        min_width = np.array([width[labels == c].min() if (labels == c).any() else 0.0 for c in classes])
        return cls(tuple(classes), WINDOW_FEATURES, feat, thr, left, right,
                   np.asarray(ada.estimator_weights_[:m], np.float64), min_width)

    def to_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "classes": list(self.classes), "features": list(self.features),
                "feature": self.feature.tolist(),
                "threshold": [None if not np.isfinite(v) else float(v) for v in self.threshold],
                "left": self.left.tolist(), "right": self.right.tolist(), "alpha": self.alpha.tolist(),
                "min_width_m": np.asarray(self.min_width_m, np.float64).tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "<dict>") -> ObjectClassifier:
        try:
            if data.get("format") != FORMAT:
                raise ValueError(f"format {data.get('format')!r}, expected {FORMAT!r}")
            features = tuple(data["features"])
            if features != WINDOW_FEATURES:
                raise ValueError(f"features {features} differ from this version's {WINDOW_FEATURES}")
            thr = np.array([np.inf if v is None else v for v in data["threshold"]], np.float64)
            min_width = data.get("min_width_m")
            out = cls(tuple(data["classes"]), features, np.asarray(data["feature"], np.int64), thr,
                      np.asarray(data["left"], np.int64), np.asarray(data["right"], np.int64),
                      np.asarray(data["alpha"], np.float64),
                      None if min_width is None else np.asarray(min_width, np.float64))
        except (KeyError, TypeError, ValueError) as err:
            raise ConfigError(f"{source}: not a fusiontrack classifier: {err}") from err
        shape = out.alpha.shape
        arrays = (out.feature, out.threshold, out.left, out.right, out.alpha)
        if len(shape) != 1 or any(a.shape != shape for a in arrays) or (out.feature < 0).any() or \
                (out.feature >= len(features)).any() or (out.left < 0).any() or (out.right < 0).any() or \
                (out.left >= len(out.classes)).any() or (out.right >= len(out.classes)).any() or \
                out.min_width_m.shape != (len(out.classes),) or not np.isfinite(out.min_width_m).all():
            raise ConfigError(f"{source}: inconsistent classifier arrays (expected shape {shape})")
        return out

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict()))
        return path

    @classmethod
    def load(cls, path: str | Path) -> ObjectClassifier:
        from ..io.datafile import read_json

        return cls.from_dict(read_json(path, "classifier"), str(path))


@functools.cache
def default_classifier() -> ObjectClassifier:
    """The classifier shipped with the package (rebuilt by ``fusiontrack train-classifier --into-package``)."""
    ref = resources.files("fusiontrack.laser") / "models" / MODEL_FILE
    with resources.as_file(ref) as path:
        return ObjectClassifier.load(path)


def default_model_path() -> Path:
    """Where :func:`default_classifier` reads from in a source checkout."""
    return Path(__file__).resolve().parent / "models" / MODEL_FILE


def train_default(work_dir: str | Path, *, seeds: Sequence[int] = (0, 1), test_seeds: Sequence[int] = (2,),
                  crowd_seconds: float = 40.0, road_seconds: float = 90.0, data_dir: str | Path | None = None,
                  n_rounds: int = 100, progress: Callable[[str], None] | None = None,
                  ) -> tuple[ObjectClassifier, dict[str, Any]]:
    """Train the shipped classifier: simulated people (``crowd``, ``groups``), cars and bicycles (``road``,
    half bicycles), plus leg_tracker's labelled leg scans (people).

    The simulator runs with ``seeds`` for training and ``test_seeds`` for the held-out test; the real
    bags are split in time (first 70 % train, the rest test). Returns the classifier and a report:
    per source and class, the number of training / test windows and the test accuracy, and the balanced
    (mean per-class recall) test accuracy.
    """
    from fusiontrack.laser.training import Windows, leg_windows, simulated_windows
    from fusiontrack.sim.scenario import load_scenario
    from fusiontrack.sim.simulator import simulate

    say = progress or (lambda _msg: None)
    work = Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    data = Path(data_dir) if data_dir is not None else Path(__file__).resolve().parents[3].parent / "shared/data"
    training = data / "laser" / "leg_tracker_demo" / "training"
    legs_bag = training / "positive_1_extracted.bag"
    if not legs_bag.is_file():
        raise ConfigError(f"{legs_bag}: leg_tracker training bag not found (pass the data folder)")
    sims = [("crowd", crowd_seconds, {}), ("groups", crowd_seconds, {}),
            ("road", road_seconds, {"agents.bicycle_fraction": 0.5})]
    parts: dict[str, dict[str, Windows]] = {"train": {}, "test": {}}
    for split, split_seeds in (("train", seeds), ("test", test_seeds)):
        for name, seconds, extra in sims:
            got = []
            for seed in split_seeds:
                say(f"simulating {name} seed {seed} ({seconds:g} s)")
                scenario = load_scenario(name).with_overrides(seconds=seconds, seed=seed,
                                                              settings={"cameras": [], **extra})
                out = work / f"{name}_{seed}_{int(seconds)}"
                if not out.exists():
                    simulate(scenario, out)
                got.append(simulated_windows(out))
            parts[split][f"sim:{name}"] = Windows.concat(got)
    say("reading leg_tracker's labelled leg scans")
    windows = leg_windows(legs_bag)
    cut = int(0.7 * len(windows))  # windows are in time order: a time split
    parts["train"]["real:legs"] = Windows(windows.X[:cut], windows.y[:cut])
    parts["test"]["real:legs"] = Windows(windows.X[cut:], windows.y[cut:])
    train = Windows.concat(parts["train"].values())
    groups = np.concatenate([np.full(len(w), name, dtype=object) for name, w in parts["train"].items()])
    say(f"training on {len(train)} windows")
    model = ObjectClassifier.fit(train.X, train.y, groups=groups, n_rounds=n_rounds)
    report: dict[str, Any] = {"sources": {}, "classes": {}}
    for name, test in parts["test"].items():
        pred = model.predict(test.X) if len(test) else np.zeros(0, object)
        report["sources"][name] = {"train": len(parts["train"][name]), "test": len(test),
                                   "accuracy": float((pred == test.y).mean()) if len(test) else float("nan")}
    test = Windows.concat(parts["test"].values())
    pred = model.predict(test.X)
    recalls = []
    for c in model.classes:
        sel = test.y == c
        rec = float((pred[sel] == c).mean()) if sel.any() else float("nan")
        report["classes"][c] = {"test": int(sel.sum()), "recall": rec,
                                "train": int((train.y == c).sum())}
        if sel.any():
            recalls.append(rec)
    report["balanced_accuracy"] = float(np.mean(recalls))
    return model, report
