"""Scene understanding learned from labelled tracks: the supervised alternative of ALGORITHMS.md D8.

Per track, every ``period_s`` (0.25 s), a window of the last ``window_s`` (5 s) of the switching control's
properties (:class:`~fusiontrack.scene.rules.SwitchingControl`: median speed, acceleration, signed distance to the
road edge now and 1 s ahead (capped at half a lane, :data:`EDGE_CAP_M`), lateral speed towards the edge, alignment
with the lane, the same-lane neighbours within ±25 m, and whether a sensor confirmed the state or the tracker
coasted) is summarised into :data:`FEATURES` (means, extremes, last values, fractions) and classified by a random
forest into :data:`CLASSES` with a confidence (the forest's vote share). No maximum speed or acceleration: the
simulator's few leaving vehicles all drove at 11-13 m/s before leaving, and a forest given the window's maximum
speed learnt that instead of the leaving (it missed a vehicle that left at 10 m/s); the maximum acceleration of
tracker output is its jitter.

Events have the interface of the rules (:class:`LearnedSceneUnderstanding` with ``update(t_ns, track_states)``,
:func:`detect_events_learned`): a track's ``stopped_vehicle`` / ``road_leaving`` / ``wrong_way`` event starts once the
forest says so with confidence >= ``p_min`` for ``on_s`` (0.25 s: two evaluations), in windows that a sensor mostly
confirmed (``min_measured``), and ends once it has not for ``off_s``; a ``jam`` event of a lane zone starts once >=
``jam_min_tracks`` of its vehicles are classified ``jam`` (also only in windows a sensor mostly confirmed: a
vehicle the tracker only extrapolates does not count towards a jam). ``t_ns`` is the first positive evaluation,
``attributes["alarm_t_ns"]`` the alarm. A track's event that starts where an event of the same kind is going on or ended
moments ago continues it (``rejoin_m``, ``rejoin_s``): one incident, one event, also when the tracker loses a stopped
vehicle and finds it again.

Training (:func:`train_scene_classifier`, ``python -m fusiontrack.scene.learned``): simulated ``road`` runs,
(a) without sensors, the agents as perfect tracks (``agents.csv``), and (b) with sensors, the ``traffic``
pipeline's fusion + particle-filter tracks (:func:`tracked_run`), each window labelled by the agent its track is on
(:func:`match_agents`). Labels come from ``incidents.jsonl`` with the simulator's definitions (``sim/agents.py``):
a stopped vehicle from the incident's start to its end; a road-leaving vehicle from crossing the edge until it
is parked on the verge; a jam member while the jam lasts and it drives slower than 10 km/h (the simulator's
queue condition). The simulator has no wrong-way incident: ``wrong_way`` examples are free-flowing tracks played
backwards in time (same road, motion against the lane), labelled while faster than 3 m/s in a lane. Tracked runs
teach the forest the tracker's own errors as ``none`` (camera-only objects placed a few decimetres beyond the
edge, tracks coasting off the road, a mode drifting off a stopped car); the shipped forest was trained as
:data:`SHIPPED_TRAINING` says (the traffic benchmark's seeds 0-2 are held out).

The forest (30 trees, depth <= 8) is shipped as JSON (``scene/data/scene_classifier.json``, < 200 kB): per tree the
node arrays (feature, threshold, children, leaf class shares), evaluated for all trees and samples at once in numpy, one
depth level per step. A pickle would tie the file to the scikit-learn version and run code when loaded
(``laser/classifier.py`` ships its boosted stumps the same way).
"""

from __future__ import annotations

import functools
import json
import logging
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..io.tracks import flatten_states
from ..types import Event, Track, TrackState
from .road import RoadGeometry
from .rules import EventLog, Frame, Latch, SceneRules, SwitchingControl, _lane_zones, default_rules, frames_of

__all__ = [
    "CLASSES",
    "FEATURES",
    "LearnedSceneUnderstanding",
    "SceneClassifier",
    "default_scene_classifier",
    "detect_events_learned",
    "label_samples",
    "match_agents",
    "tracked_run",
    "tracked_samples",
    "train_scene_classifier",
    "window_samples",
]

log = logging.getLogger(__name__)

CLASSES = ("none", "stopped_vehicle", "road_leaving", "jam", "wrong_way")
_CHANNELS = ("speed", "acceleration", "edge_distance", "lateral_speed", "predicted_edge_distance", "lane_cos",
             "on_road", "in_lane", "nb_count", "nb_speed", "measured")
FEATURES = (
    "speed_last", "speed_mean", "speed_min", "speed_std", "still_frac",
    "accel_mean", "accel_min",
    "edge_last", "edge_min", "edge_mean", "edge_change", "edge_known_frac", "pred_edge_last",
    "lateral_last", "lateral_mean", "lateral_max",
    "lane_cos_last", "lane_cos_mean", "on_road_frac", "in_lane_last",
    "nb_count_last", "nb_count_mean", "nb_speed_last", "nb_speed_mean", "history_s",
    "measured_frac", "measured_last",
)
_MEASURED_FRAC = FEATURES.index("measured_frac")
MODEL_FILE = "scene_classifier.json"
FORMAT = "fusiontrack-forest-1"
NEIGHBOUR_RANGE_M = 25.0
STILL_MPS = 0.5
JAM_SPEED_MPS = 10 / 3.6  # the simulator's queue condition (sim/agents.py JAM_SPEED_MPS)
WRONG_WAY_MIN_MPS = 3.0
EDGE_CAP_M = 1.75
"""Distances to the road edge are capped at half a lane: deeper inside they tell which lane of the training road
a vehicle is in (the simulator's stopped vehicles all stand in an inner lane), not how near it is to leaving."""
SHIPPED_TRAINING: Mapping[str, Any] = {"seeds": (100, 101, 102, *range(104, 120)), "test_seeds": (103,),
                                       "tracked_seeds": (10, 11, 12, 13), "tracked_test_seeds": (14, 15, 16),
                                       "seconds": 120.0, "sample_period_s": 0.1, "min_samples_leaf": 10}
"""How the shipped forest was trained (:func:`main`'s defaults). The traffic benchmark's seeds 0-2 are not
among them."""


# --------------------------------------------------------------------------------------------------
# The forest
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class SceneClassifier:
    """A random forest of ``T`` trees padded to ``N`` nodes, evaluated in numpy.

    Attributes
    ----------
    classes : tuple of str (C,); features : tuple of str
    feature : (T, N) int64 — tested column, -1 at a leaf
    threshold : (T, N) float64 — go left when ``x[feature] <= threshold``
    left, right : (T, N) int64 — child nodes
    value : (T, N, C) float64 — class shares of the training samples at each leaf
    depth : int — the deepest leaf
    """

    classes: tuple[str, ...]
    features: tuple[str, ...]
    feature: np.ndarray
    threshold: np.ndarray
    left: np.ndarray
    right: np.ndarray
    value: np.ndarray
    depth: int

    def predict_proba(self, X: Any) -> np.ndarray:
        """Mean of the trees' leaf class shares, ``(m, C)`` (scikit-learn's ``predict_proba``)."""
        x = np.asarray(X, np.float64)
        if x.ndim != 2 or x.shape[1] != len(self.features):
            raise ValueError(f"X: expected shape (m, {len(self.features)}), got {x.shape}")
        m, t = len(x), self.feature.shape[0]
        node = np.zeros((m, t), np.int64)
        trees = np.broadcast_to(np.arange(t)[None, :], (m, t))
        rows = np.broadcast_to(np.arange(m)[:, None], (m, t))
        for _ in range(self.depth):
            f = self.feature[trees, node]
            leaf = f < 0
            go_left = x[rows, np.maximum(f, 0)] <= self.threshold[trees, node]
            node = np.where(leaf, node, np.where(go_left, self.left[trees, node], self.right[trees, node]))
        return self.value[trees, node].mean(axis=1)

    def predict(self, X: Any) -> tuple[np.ndarray, np.ndarray]:
        """The most probable class ``(m,)`` str and its probability ``(m,)``."""
        p = self.predict_proba(X)
        k = np.argmax(p, axis=1) if len(p) else np.zeros(0, np.int64)
        return np.array(self.classes, dtype=object)[k], p[np.arange(len(p)), k]

    @classmethod
    def fit(cls, X: Any, y: Any, *, n_trees: int = 30, max_depth: int = 8, min_samples_leaf: int = 5,
            rng: np.random.Generator | int | None = 0) -> SceneClassifier:
        """Train a :class:`sklearn.ensemble.RandomForestClassifier` (classes balanced) and keep its trees."""
        from sklearn.ensemble import RandomForestClassifier

        x = np.asarray(X, np.float64)
        labels = np.asarray(y).astype(str)
        if x.ndim != 2 or x.shape[1] != len(FEATURES) or len(labels) != len(x):
            raise ValueError(f"X, y: expected X (m, {len(FEATURES)}) and y (m,), got {x.shape}, {labels.shape}")
        if not np.isfinite(x).all():
            raise ValueError("X: features must be finite")
        unknown = sorted(set(labels) - set(CLASSES))
        if unknown:
            raise ValueError(f"y: classes {unknown} are not among {list(CLASSES)}")
        seed = int(np.random.default_rng(rng).integers(2**31 - 1))
        forest = RandomForestClassifier(n_estimators=n_trees, max_depth=max_depth, min_samples_leaf=min_samples_leaf,
                                        class_weight="balanced_subsample", random_state=seed, n_jobs=1).fit(x, labels)
        return cls.from_sklearn(forest)

    @classmethod
    def from_sklearn(cls, forest: Any, features: Sequence[str] = FEATURES) -> SceneClassifier:
        """The trees of a fitted :class:`sklearn.ensemble.RandomForestClassifier` whose classes are among
        :data:`CLASSES` (its ``predict_proba`` is reproduced exactly)."""
        unknown = sorted({str(c) for c in forest.classes_} - set(CLASSES))
        if unknown:
            raise ValueError(f"forest classes {unknown} are not among {list(CLASSES)}")
        if forest.n_features_in_ != len(features):
            raise ValueError(f"forest: {forest.n_features_in_} features, expected {len(features)}")
        index = np.array([CLASSES.index(str(c)) for c in forest.classes_])
        trees = [e.tree_ for e in forest.estimators_]
        n = max(t.node_count for t in trees)
        t_count = len(trees)
        feat = np.full((t_count, n), -1, np.int64)
        thr = np.zeros((t_count, n))
        left, right = np.zeros((t_count, n), np.int64), np.zeros((t_count, n), np.int64)
        value = np.zeros((t_count, n, len(CLASSES)))
        for i, t in enumerate(trees):
            k = t.node_count
            leaf = t.children_left[:k] < 0
            feat[i, :k] = np.where(leaf, -1, t.feature[:k])
            thr[i, :k] = np.where(leaf, 0.0, t.threshold[:k])
            left[i, :k] = np.where(leaf, 0, t.children_left[:k])
            right[i, :k] = np.where(leaf, 0, t.children_right[:k])
            v = t.value[:k, 0, :]
            value[i, :k][:, index] = v / np.maximum(v.sum(axis=1, keepdims=True), 1e-12)
        depth = int(max(e.get_depth() for e in forest.estimators_))
        return cls(CLASSES, tuple(features), feat, thr, left, right, value, depth)

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        trees = []
        for i in range(self.feature.shape[0]):
            k = int(np.max(np.flatnonzero((self.feature[i] >= 0) | (self.value[i].sum(axis=1) > 0)))) + 1
            leaf = self.feature[i, :k] < 0
            trees.append({
                "feature": self.feature[i, :k].tolist(),
                "threshold": self.threshold[i, :k].tolist(),  # full precision: no sample changes side
                "left": self.left[i, :k].tolist(), "right": self.right[i, :k].tolist(),
                # class shares at the leaves only, 3 decimals
                "value": [[round(float(v), 3) for v in row] if is_leaf else [] for row, is_leaf
                          in zip(self.value[i, :k], leaf, strict=True)]})
        return {"format": FORMAT, "classes": list(self.classes), "features": list(self.features),
                "depth": self.depth, "trees": trees}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "<dict>",
                  expected_features: Sequence[str] | None = FEATURES) -> SceneClassifier:
        """The forest of :meth:`to_dict`; ``expected_features`` (None: any) must be its feature names."""
        try:
            if data.get("format") != FORMAT:
                raise ValueError(f"format {data.get('format')!r}, expected {FORMAT!r}")
            features = tuple(data["features"])
            if expected_features is not None and features != tuple(expected_features):
                raise ValueError(f"features {features} differ from this version's {tuple(expected_features)}")
            classes = tuple(data["classes"])
            trees = data["trees"]
            n = max(len(t["feature"]) for t in trees)
            t_count, c = len(trees), len(classes)
            feat = np.full((t_count, n), -1, np.int64)
            thr = np.zeros((t_count, n))
            left, right = np.zeros((t_count, n), np.int64), np.zeros((t_count, n), np.int64)
            value = np.zeros((t_count, n, c))
            for i, t in enumerate(trees):
                k = len(t["feature"])
                feat[i, :k], thr[i, :k] = t["feature"], t["threshold"]
                left[i, :k], right[i, :k] = t["left"], t["right"]
                for j, row in enumerate(t["value"]):
                    if row:
                        value[i, j] = row
            depth = int(data["depth"])
        except (KeyError, TypeError, ValueError, IndexError) as err:
            raise ConfigError(f"{source}: not a fusiontrack scene classifier: {err}") from err
        inner = feat >= 0
        if (feat >= len(features)).any() or (left[inner] <= 0).any() or (right[inner] <= 0).any() \
                or (left >= n).any() or (right >= n).any() or depth < 0:
            raise ConfigError(f"{source}: inconsistent forest arrays")
        return cls(classes, features, feat, thr, left, right, value, depth)

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), separators=(",", ":")))
        return path

    @classmethod
    def load(cls, path: str | Path) -> SceneClassifier:
        from ..io.datafile import read_json

        return cls.from_dict(read_json(path, "scene classifier"), str(path))


@functools.cache
def default_scene_classifier() -> SceneClassifier:
    """The forest shipped with the package (rebuilt by :func:`train_scene_classifier`)."""
    ref = resources.files("fusiontrack.scene") / "data" / MODEL_FILE
    with resources.as_file(ref) as path:
        return SceneClassifier.load(path)


def default_model_path() -> Path:
    """Where :func:`default_scene_classifier` reads from in a source checkout."""
    return Path(__file__).resolve().parent / "data" / MODEL_FILE


# --------------------------------------------------------------------------------------------------
# Feature windows
# --------------------------------------------------------------------------------------------------


class FeatureWindows:
    """Per track, the last ``window_s`` of the switching control's properties, summarised into :data:`FEATURES`
    every ``period_s`` once ``min_history_s`` is covered."""

    def __init__(self, window_s: float = 5.0, period_s: float = 0.5, min_history_s: float = 1.0) -> None:
        if not (window_s > 0 and period_s > 0 and 0 <= min_history_s <= window_s):
            raise ConfigError(f"window_s, period_s, min_history_s: expected > 0, > 0 and in [0, window_s], got "
                              f"{window_s}, {period_s}, {min_history_s}")
        self.window_ns, self.period_ns = round(window_s * 1e9), round(period_s * 1e9)
        self.min_ns = round(min_history_s * 1e9)
        self._k, self._n = 64, 0
        self._t = np.zeros((0, self._k), np.int64)
        self._x = np.zeros((0, self._k, len(_CHANNELS)))
        self._count = np.zeros(0, np.int64)
        self._first = np.zeros(0, np.int64)
        self._next_eval = np.zeros(0, np.int64)

    def _resize(self, n: int) -> None:
        if n <= self._n:
            return
        grow = n - self._n
        self._t = np.vstack([self._t, np.full((grow, self._k), np.iinfo(np.int64).min)])
        self._x = np.concatenate([self._x, np.full((grow, self._k, len(_CHANNELS)), np.nan)])
        self._count = np.concatenate([self._count, np.zeros(grow, np.int64)])
        self._first = np.concatenate([self._first, np.zeros(grow, np.int64)])
        self._next_eval = np.concatenate([self._next_eval, np.zeros(grow, np.int64)])
        self._n = n

    def _grow_ring(self) -> None:
        k = self._k
        order = (self._count[:, None] + np.arange(k)[None, :]) % k
        order[self._count < k] = np.arange(k)
        rows = np.arange(self._n)[:, None]
        t = np.full((self._n, 2 * k), np.iinfo(np.int64).min)
        x = np.full((self._n, 2 * k, len(_CHANNELS)), np.nan)
        t[:, :k], x[:, :k] = self._t[rows, order], self._x[rows, order]
        self._t, self._x, self._k = t, x, 2 * k
        self._count = np.minimum(self._count, k)

    def reset(self, slots: Iterable[int]) -> None:
        s = np.fromiter(slots, np.int64)
        if s.size and s.max() < self._n:
            self._t[s], self._x[s], self._count[s] = np.iinfo(np.int64).min, np.nan, 0

    def push(self, frame: Frame, channels: np.ndarray, n_slots: int) -> tuple[np.ndarray, np.ndarray]:
        """Add the frame's samples ``(n, len(_CHANNELS))``; returns the slots due for evaluation and their
        features ``(k, len(FEATURES))``."""
        self._resize(n_slots)
        slots, t = frame.slots, frame.t_ns
        new = self._count[slots] == 0
        self._first[slots[new]] = t
        self._next_eval[slots[new]] = t + self.min_ns
        while True:
            w = self._count[slots] % self._k
            if not np.any((self._count[slots] >= self._k) & (self._t[slots, w] > t - self.window_ns)):
                break
            self._grow_ring()
        self._t[slots, w] = t
        self._x[slots, w] = channels
        self._count[slots] += 1
        due = slots[t >= self._next_eval[slots]]
        if not due.size:
            return due, np.zeros((0, len(FEATURES)))
        self._next_eval[due] = t + self.period_ns
        inside = self._t[due] > t - self.window_ns  # (k, K)
        x = np.where(inside[..., None], self._x[due], np.nan)  # (k, K, C)
        last = self._x[due, (self._count[due] - 1) % self._k]  # (k, C)
        oldest = np.argmin(np.where(inside, self._t[due], np.iinfo(np.int64).max), axis=1)
        first = self._x[due, oldest]
        history_s = (t - np.maximum(self._first[due], t - self.window_ns)) * 1e-9
        return due, _summarise(x, last, first, history_s)


def _summarise(x: np.ndarray, last: np.ndarray, first: np.ndarray, history_s: np.ndarray) -> np.ndarray:
    """:data:`FEATURES` from windows ``x`` (k, K, C) (NaN outside), last and first samples (k, C)."""
    c = {name: i for i, name in enumerate(_CHANNELS)}
    import warnings

    with warnings.catch_warnings(), np.errstate(invalid="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        mean, mn, mx = np.nanmean(x, axis=1), np.nanmin(x, axis=1), np.nanmax(x, axis=1)
        std = np.nanstd(x[..., c["speed"]], axis=1)
        valid = ~np.isnan(x)
        n = np.maximum(valid[..., c["speed"]].sum(axis=1), 1)
        still = ((x[..., c["speed"]] < STILL_MPS) & valid[..., c["speed"]]).sum(axis=1) / n
        edge_known = valid[..., c["edge_distance"]].sum(axis=1) / np.maximum(
            (~np.isnan(x[..., c["on_road"]])).sum(axis=1), 1)
    s, a, e, lat = c["speed"], c["acceleration"], c["edge_distance"], c["lateral_speed"]
    cols = [
        last[:, s], mean[:, s], mn[:, s], std, still,
        mean[:, a], mn[:, a],
        last[:, e], mn[:, e], mean[:, e], last[:, e] - first[:, e], edge_known, last[:, c["predicted_edge_distance"]],
        last[:, lat], mean[:, lat], mx[:, lat],
        last[:, c["lane_cos"]], mean[:, c["lane_cos"]], mean[:, c["on_road"]], last[:, c["in_lane"]],
        last[:, c["nb_count"]], mean[:, c["nb_count"]], last[:, c["nb_speed"]], mean[:, c["nb_speed"]], history_s,
        mean[:, c["measured"]], last[:, c["measured"]],
    ]
    return np.nan_to_num(np.column_stack(cols), nan=0.0, posinf=0.0, neginf=0.0)


def _channels(control: SwitchingControl, frame: Frame) -> np.ndarray:
    """The per-frame channels of the updated tracks, ``(n, len(_CHANNELS))``, with same-lane neighbours."""
    p = frame.props
    live = control.live_slots()
    live = live[control.latest_vehicle[live] & (control.latest_lane[live] >= 0)]
    lane, s = control.latest_lane[frame.slots], control.latest_s[frame.slots]
    near = (control.latest_lane[live][None, :] == lane[:, None]) & \
        (np.abs(control.latest_s[live][None, :] - s[:, None]) <= NEIGHBOUR_RANGE_M) & (lane[:, None] >= 0)
    others = near & (live[None, :] != frame.slots[:, None])
    nb_count = others.sum(axis=1).astype(np.float64)
    speeds = np.where(near, control.latest_speed[live][None, :], 0.0)
    nb_speed = np.where(near.any(axis=1), speeds.sum(axis=1) / np.maximum(near.sum(axis=1), 1), np.nan)
    with np.errstate(invalid="ignore"):
        edge = np.minimum(p["edge_distance"], EDGE_CAP_M)
        pred = np.minimum(p["predicted_edge_distance"], EDGE_CAP_M)
    cols = [p["speed"], p["acceleration"], edge, p["lateral_speed"], pred,
            p["lane_cos"], p["on_road"].astype(np.float64), p["in_lane"].astype(np.float64), nb_count, nb_speed,
            p["measured"].astype(np.float64)]
    return np.column_stack(cols)


# --------------------------------------------------------------------------------------------------
# Online engine
# --------------------------------------------------------------------------------------------------


class LearnedSceneUnderstanding:
    """Online incident detection with the forest; the interface of :class:`~.rules.SceneUnderstanding`.

    Parameters
    ----------
    geometry : RoadGeometry
    model : SceneClassifier, optional — :func:`default_scene_classifier` when None
    rules : SceneRules, optional — only its smoothing and entity sections are used (defaults when None)
    window_s, period_s, min_history_s : float — feature window, evaluation period, history needed (s). Period
        0.25 s: on the held-out tracked runs (seeds 14-16) the alarms came 0.3-0.5 s sooner than every 0.5 s, with
        no false alarm more, for ~20 ms of CPU per recording second.
    p_min : float — least confidence of a positive evaluation
    min_measured : float — least share of a window's states that a sensor confirmed (``measured_frac``) for a
        positive evaluation. A window made mostly of the tracker's extrapolation shows how the tracker coasts, not
        how the vehicle behaves (the D8 rules count only measured states for road leaving likewise). 0.5: a
        majority. It applies to the ``jam`` count as well (measured with it: jam P = R = 1 on the tracked runs).
    on_s, off_s : float — a positive class must hold ``on_s`` to start an event, be absent ``off_s`` to end it
    jam_min_tracks : int — vehicles of a lane zone classified ``jam`` that make a jam
    rejoin_m, rejoin_s : float — a track's new event lying within ``rejoin_m`` of an event of the same kind
        (its start, or where one of its tracks was last) that is still open or ended less than ``rejoin_s`` ago
        continues that event (the track id is added; an ended one is reopened and returned again) instead of
        opening a second one: the tracker often loses a stopped or parked vehicle and finds it again under a new
        id. Default 3 m (less than the gap between queued vehicles) and 10 s (D8's ``T_stop``). A jam that
        ends and starts again in the same lane zone within ``rejoin_s`` likewise continues. ``rejoin_s = 0``:
        never.
    sensor : str
    """

    def __init__(self, geometry: RoadGeometry, model: SceneClassifier | None = None, rules: SceneRules | None = None,
                 *, window_s: float = 5.0, period_s: float = 0.25, min_history_s: float = 1.0, p_min: float = 0.5,
                 min_measured: float = 0.5, on_s: float = 0.25, off_s: float = 2.0, jam_min_tracks: int = 3,
                 rejoin_m: float = 3.0, rejoin_s: float = 10.0, sensor: str = "scene_learned",
                 collect: bool = False) -> None:
        if not (0 <= p_min <= 1 and 0 <= min_measured <= 1) or on_s < 0 or off_s < 0 or jam_min_tracks < 1:
            raise ConfigError(f"p_min and min_measured in [0, 1], on_s >= 0, off_s >= 0, jam_min_tracks >= 1; got "
                              f"{p_min}, {min_measured}, {on_s}, {off_s}, {jam_min_tracks}")
        if not (rejoin_m >= 0 and rejoin_s >= 0 and math.isfinite(rejoin_m) and math.isfinite(rejoin_s)):
            raise ConfigError(f"rejoin_m, rejoin_s: expected finite values >= 0, got {rejoin_m}, {rejoin_s}")
        self.rejoin_m, self._rejoin_ns = float(rejoin_m), round(rejoin_s * 1e9)
        # per event id: kind, places seen (start, and where its tracks were last), open holders, end time
        self._places: dict[int, list[np.ndarray]] = {}
        self._holders: dict[int, set[int]] = {}
        self._ended: dict[int, int] = {}
        self._zone_last: dict[int, int] = {}  # jam zone row -> its last event id
        self.geometry = geometry
        self.model = model if model is not None or collect else default_scene_classifier()
        self.control = SwitchingControl(geometry, rules if rules is not None else default_rules())
        self.windows = FeatureWindows(window_s, period_s, min_history_s)
        self.log = EventLog(sensor)
        self.p_min, self.min_measured, self.jam_min_tracks = float(p_min), float(min_measured), int(jam_min_tracks)
        on_ns, off_ns = round(on_s * 1e9), round(off_s * 1e9)
        self._kinds = ("stopped_vehicle", "road_leaving", "wrong_way")
        self._latches = {k: Latch(on_ns, 1, off_ns, 1) for k in self._kinds}
        self._jam_latch = Latch(on_ns, 1, off_ns, 1)
        self._jam_zones = _lane_zones(geometry, (), f"{geometry.source}")
        self._jam_latch.resize(len(self._jam_zones))
        self._label = np.zeros(0, dtype=object)
        self._collect = collect
        self.samples: list[tuple[np.ndarray, int, np.ndarray]] = []  # collect mode: (track ids, t_ns, X)

    @property
    def events(self) -> list[Event]:
        return self.log.events

    @property
    def open_events(self) -> list[Event]:
        return self.log.open_events

    def update(self, t_ns: int, track_states: Iterable[TrackState], *, lengths_m: Mapping[int, float] | None = None,
               laser_counts: Mapping[int, int] | None = None) -> list[Event]:
        """Process the track states of one instant; returns the events that start or end now."""
        out: list[Event] = []
        gone = self.control.expire(int(t_ns))
        for slot, _tid, last_ns in gone:
            for latch in self._latches.values():
                if slot < latch._n:
                    if latch.active[slot] and latch.event[slot] >= 0:
                        out += self._release(int(latch.event[slot]), slot, last_ns, last_ns)
                    latch.reset([slot])
        self.windows.reset(s for s, _, _ in gone)
        frame = self.control.observe(int(t_ns), list(track_states), lengths_m, laser_counts)
        n_slots = self.control.n_slots
        if self._label.size < n_slots:
            self._label = np.concatenate([self._label, np.full(n_slots - self._label.size, "none", dtype=object)])
        self._label[[s for s, _, _ in gone]] = "none"
        if not len(frame):
            return out + self._jam_step(frame.t_ns)
        due, X = self.windows.push(frame, _channels(self.control, frame), n_slots)
        if not due.size:
            return out
        if self._collect:
            self.samples.append((self.control.track_id[due].copy(), frame.t_ns, X))
            return out
        model = self.model
        if model is None:  # only in collect mode, handled above
            return out
        label, prob = model.predict(X)
        confident = (prob >= self.p_min) & (X[:, _MEASURED_FRAC] >= self.min_measured)
        is_vehicle = self.control.latest_vehicle[due]
        self._label[due] = np.where(confident & is_vehicle, label, "none")
        row_of = {int(s): j for j, s in enumerate(frame.slots)}
        for kind, latch in self._latches.items():
            latch.resize(n_slots)
            cond = (label == kind) & confident & is_vehicle
            started, ended = latch.step(due, frame.t_ns, cond, ~cond, self.control.latest_pos[due])
            for s in ended.tolist():
                out += self._release(int(latch.event[s]), s, int(latch.clear_start_ns[s]), frame.t_ns)
                latch.event[s] = -1
            for s in started.tolist():
                j = int(np.flatnonzero(due == s)[0])
                lane = int(frame.lane[row_of[s]])
                attrs = {"rule": "learned", "alarm_t_ns": frame.t_ns,
                         "alarm_position_m": tuple(float(v) for v in self.control.latest_pos[s]),
                         "lane": self.geometry.lane_names[lane] if lane >= 0 else "",
                         "zone": "|".join(self.geometry.zone_names[z]
                                          for z in np.flatnonzero(self.control.latest_zones[s])),
                         "confidence": float(prob[j])}
                eid, evs = self._start(kind, s, int(latch.run_start_ns[s]), latch.run_pos[s], attrs)
                latch.event[s] = eid
                out += evs
        return out + self._jam_step(frame.t_ns)

    # ------------------------------------------------------------------ one event per incident
    def _start(self, kind: str, slot: int, t_start_ns: int, position: np.ndarray, attrs: Mapping[str, Any]
               ) -> tuple[int, list[Event]]:
        """A track's event begins: it continues a nearby recent event of the same kind (``rejoin_m``,
        ``rejoin_s``) or opens a new one. Returns the event id and the events to report."""
        tid = int(self.control.track_id[slot])
        # track events that ended longer than rejoin_s ago can no longer be continued: forget them (a live run
        # would otherwise keep every event it ever opened and scan them all here)
        stale = [e for e, h in self._holders.items() if not h and t_start_ns - self._ended[e] > self._rejoin_ns]
        for e in stale:
            del self._places[e], self._holders[e], self._ended[e]
        if self._rejoin_ns > 0 and np.isfinite(position).all():
            for eid, places in self._places.items():
                if self.log.kind(eid) != kind:
                    continue
                holders = self._holders[eid]
                if not holders and t_start_ns - self._ended[eid] > self._rejoin_ns:
                    continue
                where = np.vstack([*places, self.control.latest_pos[sorted(holders)]]) if holders else \
                    np.vstack(places)
                if np.nanmin(np.linalg.norm(where - position, axis=1), initial=np.inf) > self.rejoin_m:
                    continue
                self.log.add_ids(eid, [tid])
                reopened = not holders
                holders.add(slot)
                return eid, [self.log.reopen(eid)] if reopened else []
        eid, ev = self.log.open(kind, t_start_ns, position, [tid], attrs)
        self._places[eid] = [np.asarray(position, np.float64).reshape(1, 2)]
        self._holders[eid] = {slot}
        return eid, [ev]

    def _release(self, eid: int, slot: int, t_end_ns: int, t_now_ns: int) -> list[Event]:
        """A track's event ends (cleared, or the track is gone): the event ends once none of its tracks holds it."""
        holders = self._holders.get(eid)
        if holders is None:  # not a track event
            return [self.log.close(eid, t_end_ns, t_now_ns)]
        holders.discard(slot)
        self._places[eid].append(self.control.last_pos[slot].reshape(1, 2).copy())
        if holders:
            return []
        self._ended[eid] = int(t_end_ns)
        return [self.log.close(eid, t_end_ns, t_now_ns)]

    def _jam_step(self, t_ns: int) -> list[Event]:
        """Lane zones with >= jam_min_tracks vehicles classified ``jam``."""
        if self._collect:
            return []
        c = self.control
        live = c.live_slots()
        jam = live[c.latest_vehicle[live] & (self._label[live] == "jam")]
        nz = len(self._jam_zones)
        if not nz:
            return []
        in_zone = c.latest_zones[jam][:, self._jam_zones]  # (k, z)
        count = in_zone.sum(axis=0)
        cond = count >= self.jam_min_tracks
        latch = self._jam_latch
        centre = np.array([c.latest_pos[jam[in_zone[:, z]]].mean(axis=0) if count[z] else (np.nan, np.nan)
                           for z in range(nz)]).reshape(nz, 2)
        for z in np.flatnonzero(latch.active[:nz] & cond).tolist():
            self.log.add_ids(int(latch.event[z]), c.track_id[jam[in_zone[:, z]]].tolist())
        started, ended = latch.step(np.arange(nz), t_ns, cond, ~cond, centre)
        out = []
        for z in ended.tolist():
            out.append(self.log.close(int(latch.event[z]), int(latch.clear_start_ns[z]), t_ns))
            self._ended[int(latch.event[z])] = int(latch.clear_start_ns[z])
            latch.event[z] = -1
        for z in started.tolist():
            zone = self.geometry.zones[int(self._jam_zones[z])]
            members = jam[in_zone[:, z]]
            last = self._zone_last.get(z)
            if last is not None and self._rejoin_ns > 0 and latch.run_start_ns[z] - self._ended[last] <= \
                    self._rejoin_ns:
                self.log.add_ids(last, c.track_id[members].tolist())
                latch.event[z] = last
                out.append(self.log.reopen(last))
                continue
            attrs = {"rule": "learned", "alarm_t_ns": int(t_ns),
                     "alarm_position_m": tuple(float(v) for v in centre[z]), "lane": zone.lane or "",
                     "zone": zone.name, "confidence": float(np.nanmean(c.latest_score[members])),
                     "properties": {"count": int(count[z])}}
            eid, ev = self.log.open("jam", int(latch.run_start_ns[z]), latch.run_pos[z],
                                    c.track_id[members].tolist(), attrs)
            latch.event[z] = eid
            self._zone_last[z] = eid
            out.append(ev)
        return out


def detect_events_learned(tracks: Iterable[TrackState | Track], geometry: RoadGeometry,
                          model: SceneClassifier | None = None, *, lengths_m: Mapping[int, float] | None = None,
                          laser_counts: Mapping[int, int] | None = None, **options: Any) -> list[Event]:
    """Run :class:`LearnedSceneUnderstanding` over whole tracks (``options`` go to its constructor)."""
    scene = LearnedSceneUnderstanding(geometry, model, **options)
    for t_ns, states in frames_of(tracks):
        scene.update(t_ns, states, lengths_m=lengths_m, laser_counts=laser_counts)
    return sorted(scene.events, key=lambda e: (e.t_ns, e.kind))


# --------------------------------------------------------------------------------------------------
# Training data
# --------------------------------------------------------------------------------------------------


def window_samples(tracks: Iterable[TrackState | Track], geometry: RoadGeometry, rules: SceneRules | None = None,
                   **options: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The feature windows the online engine would classify: ``(track_ids (m,), t_ns (m,), X (m, F))``."""
    scene = LearnedSceneUnderstanding(geometry, None, rules, collect=True, **options)
    for t_ns, states in frames_of(tracks):
        scene.update(t_ns, states)
    if not scene.samples:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, len(FEATURES)))
    ids = np.concatenate([s[0] for s in scene.samples])
    t = np.concatenate([np.full(s[0].size, s[1], np.int64) for s in scene.samples])
    return ids, t, np.vstack([s[2] for s in scene.samples])


def label_samples(track_ids: np.ndarray, t_ns: np.ndarray, incidents: Sequence[Event], agents: Any) -> np.ndarray:
    """Labels of samples of ground-truth tracks (track id = agent id) from the simulator's incidents.

    A sample is labelled with an incident's kind when its agent is one of the incident's and its time lies in
    the incident; for a jam, also only while the agent drives slower than 10 km/h (the simulator's queue
    condition); for road leaving only while the vehicle still moves (>= ``STILL_MPS``): once parked on the verge
    it is a vehicle standing off the road (the incident lasts to the end of the run, but a window of a parked car
    no longer shows it leaving, and a re-acquired track of it must not raise a new alarm). Otherwise ``"none"``.
    Ids < 0 (samples matched to no agent) are ``"none"``.
    """
    y = np.full(track_ids.size, "none", dtype=object)
    for inc in incidents:
        if inc.kind not in CLASSES:
            continue
        end = np.iinfo(np.int64).max if inc.t_end_ns is None else inc.t_end_ns
        sel = np.isin(track_ids, inc.track_ids) & (t_ns >= inc.t_ns) & (t_ns <= end)
        if inc.kind in ("jam", "road_leaving") and sel.any():
            speed = np.array([_agent_speed(agents, int(a), int(t)) for a, t in zip(track_ids[sel], t_ns[sel],
                                                                                    strict=True)])
            idx = np.flatnonzero(sel)
            moving = speed < JAM_SPEED_MPS if inc.kind == "jam" else speed >= STILL_MPS
            sel[idx[~moving]] = False
        y[sel] = inc.kind
    return y


def _agent_speed(agents: Any, agent_id: int, t_ns: int) -> float:
    rows = agents.rows_of(agent_id)
    if not rows.size:
        return math.nan
    k = rows[np.argmin(np.abs(agents.t_ns[rows] - t_ns))]
    return float(np.hypot(*agents.velocities_mps[k]))


def reversed_tracks(tracks: Sequence[Track], id_offset: int = 1_000_000) -> list[Track]:
    """Tracks played backwards in time over the same span: the motion runs against the lane (wrong way)."""
    out = []
    for tr in tracks:
        t = tr.times_ns()
        t_rev = t[0] + (t[-1] - t[::-1])
        states = tr.states[::-1]
        out.append(Track(tr.track_id + id_offset, tuple(
            TrackState(int(ti), s.sensor, tr.track_id + id_offset, s.position_m, -s.velocity_mps, cls=s.cls,
                       sensors=s.sensors, score=s.score) for ti, s in zip(t_rev, states, strict=True))))
    return out


def match_agents(track_ids: np.ndarray, t_ns: np.ndarray, tracks: Iterable[TrackState | Track], agents: Any, *,
                 match_m: float = 3.0, classes: Sequence[str] = ("car", "bicycle")) -> np.ndarray:
    """The agent each sample of tracker output is on: per sample ``(track id, t_ns)`` the vehicle agent (of
    ``classes``) nearest to the track's position then, at the ground-truth instant nearest in time, when within
    ``match_m``; else -1. ``(m,) int64``."""
    pos_of = {(s.track_id, s.t_ns): s.position_m for s in flatten_states(tracks)}
    out = np.full(track_ids.size, -1, np.int64)
    keep = np.flatnonzero(np.isin(agents.classes, list(classes)))
    if not keep.size or not track_ids.size:
        return out
    a_t = agents.t_ns[keep]
    order = np.argsort(a_t, kind="stable")
    keep, a_t = keep[order], a_t[order]
    times = np.unique(a_t)
    for t in np.unique(t_ns).tolist():
        k = int(np.clip(np.searchsorted(times, t), 1, times.size - 1)) if times.size > 1 else 0
        if times.size > 1 and abs(times[k - 1] - t) <= abs(times[k] - t):
            k -= 1
        lo, hi = np.searchsorted(a_t, [times[k], times[k] + 1])
        rows = keep[lo:hi]
        sel = np.flatnonzero(t_ns == t)
        pos = np.array([pos_of.get((int(i), t), (np.nan, np.nan)) for i in track_ids[sel]], np.float64)
        d = np.linalg.norm(pos[:, None, :] - agents.positions_m[rows][None, :, :], axis=2)
        best = np.argmin(np.where(np.isnan(d), np.inf, d), axis=1)
        near = d[np.arange(sel.size), best] <= match_m
        out[sel[near]] = agents.ids[rows[best[near]]]
    return out


def tracked_samples(tracks: Iterable[TrackState | Track], run_dir: str | Path, *, match_m: float = 3.0,
                    reverse_fraction: float = 0.3, rng: np.random.Generator | int | None = 0, **options: Any
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Labelled feature windows of a tracker's output on a simulated run (``run_dir`` or its ``ground_truth``
    folder): each window takes the label of the agent its track is on (:func:`match_agents`,
    :func:`label_samples`); plus wrong-way windows from a share ``reverse_fraction`` of the tracks that follow a
    vehicle agent (>= 90 % of their windows matched) involved in no incident, played backwards.
    ``(X (m, F), y (m,))``."""
    from ..eval.events import read_agents_csv, read_incidents
    from ..io.tracks import group_tracks
    from .road import road_geometry_from_world

    gt = Path(run_dir)
    gt = gt / "ground_truth" if (gt / "ground_truth").is_dir() else gt
    geometry = road_geometry_from_world(gt / "world.json")
    agents = read_agents_csv(gt / "agents.csv")
    incidents = read_incidents(gt / "incidents.jsonl")
    grouped = group_tracks(flatten_states(tracks))
    ids, t, X = window_samples(grouped, geometry, **options)
    agent = match_agents(ids, t, grouped, agents, match_m=match_m)
    y = label_samples(agent, t, incidents, agents)
    involved = {i for inc in incidents for i in inc.track_ids}
    on_incident = set(ids[np.isin(agent, list(involved))].tolist())
    # wrong-way examples: real vehicles played backwards, i.e. tracks on an agent in >= 90 % of their windows
    # (a ghost track played backwards is still a ghost: it shows the forest no wrong-way driver)
    tids, n_win = np.unique(ids, return_counts=True)
    n_on = np.bincount(np.searchsorted(tids, ids[agent >= 0]), minlength=tids.size)
    real = set(tids[n_on >= 0.9 * n_win].tolist())
    free = [tr for tr in grouped if tr.track_id in real and tr.track_id not in on_incident and len(tr.states) > 1]
    gen = np.random.default_rng(rng)
    pick = [free[i] for i in np.flatnonzero(gen.random(len(free)) < reverse_fraction)]
    if pick:
        _, _, r_X = window_samples(reversed_tracks(pick), geometry, **options)
        c = {name: i for i, name in enumerate(FEATURES)}
        wrong = (r_X[:, c["speed_last"]] > WRONG_WAY_MIN_MPS) & (r_X[:, c["in_lane_last"]] > 0.5)
        X = np.vstack([X, r_X])
        y = np.concatenate([y, np.where(wrong, "wrong_way", "none").astype(object)])
    return X, y


def run_samples(run_dir: str | Path, *, reverse_fraction: float = 0.3, rng: np.random.Generator | int | None = 0,
                **options: Any) -> tuple[np.ndarray, np.ndarray]:
    """Labelled feature windows of one simulated road run (its agents as tracks), plus wrong-way windows from
    a share ``reverse_fraction`` of its incident-free tracks played backwards: ``(X (m, F), y (m,))``."""
    from ..eval.events import agent_tracks, read_agents_csv, read_incidents
    from .road import road_geometry_from_world

    run = Path(run_dir)
    geometry = road_geometry_from_world(run / "ground_truth" / "world.json")
    agents = read_agents_csv(run)
    incidents = read_incidents(run)
    tracks = agent_tracks(agents)
    ids, t, X = window_samples(tracks, geometry, **options)
    y = label_samples(ids, t, incidents, agents)
    involved = {i for inc in incidents for i in inc.track_ids}
    free = [tr for tr in tracks if tr.track_id not in involved]
    gen = np.random.default_rng(rng)
    pick = [free[i] for i in np.flatnonzero(gen.random(len(free)) < reverse_fraction)]
    if pick:
        rev = reversed_tracks(pick)
        _, _, r_X = window_samples(rev, geometry, **options)
        c = {name: i for i, name in enumerate(FEATURES)}
        wrong = (r_X[:, c["speed_last"]] > WRONG_WAY_MIN_MPS) & (r_X[:, c["in_lane_last"]] > 0.5)
        X = np.vstack([X, r_X])
        y = np.concatenate([y, np.where(wrong, "wrong_way", "none").astype(object)])
    return X, y


def tracked_run(work_dir: str | Path, seed: int, seconds: float = 120.0,
                progress: Callable[[str], None] | None = None) -> Path:
    """A simulated ``road`` run with its sensors, tracked by the ``traffic`` pipeline (fusion + particle filter):
    ``work_dir/tracked_<seed>_<seconds>/`` with ``tracks.jsonl`` (the ``fusion_pf`` states) and the simulator's
    ``ground_truth/``; the recording itself is deleted once tracked (3+ GB for 120 s). Reused when present.
    The run is ``benchmarks/traffic.py``'s (camera_0's illumination drop to 0.55 at a third of the run), without
    its injected occlusions."""
    import shutil

    from ..fusion.traffic import track_traffic
    from ..io.tracks import write_jsonl
    from ..sim.scenario import load_scenario
    from ..sim.simulator import simulate

    say = progress or (lambda _msg: None)
    out = Path(work_dir) / f"tracked_{seed}_{int(seconds)}"
    if (out / "tracks.jsonl").is_file() and (out / "ground_truth" / "incidents.jsonl").is_file():
        return out
    rec = out / "recording"
    if rec.exists():
        shutil.rmtree(rec)
    say(f"simulating road seed {seed} ({seconds:g} s) with its sensors")
    scenario = load_scenario("road").with_overrides(seconds=seconds, seed=seed, settings={
        "cameras.0.illumination": [[seconds / 3, 0.55]]})
    simulate(scenario, rec)
    say(f"tracking seed {seed} (traffic pipeline, fusion + PF)")
    res = track_traffic(rec, variants=("fusion_pf",))
    shutil.copytree(rec / "ground_truth", out / "ground_truth", dirs_exist_ok=True)
    write_jsonl(out / "tracks.jsonl", res.states["fusion_pf"])
    shutil.rmtree(rec)
    return out


def train_scene_classifier(work_dir: str | Path, *, seeds: Sequence[int] = (100, 101, 102),
                           test_seeds: Sequence[int] = (103,), seconds: float = 120.0,
                           tracked_seeds: Sequence[int] = (), tracked_test_seeds: Sequence[int] = (),
                           tracked_seconds: float = 120.0, sample_period_s: float = 0.5,
                           progress: Callable[[str], None] | None = None, **fit_options: Any
                           ) -> tuple[SceneClassifier, dict[str, Any]]:
    """Retrain the shipped forest on simulated ``road`` runs: the agents as perfect tracks (``seeds``, no sensors
    simulated) and the traffic pipeline's tracks (``tracked_seeds``, :func:`tracked_run`, labelled through
    :func:`match_agents`), so that the forest also learns the tracker's errors (position bias of camera-only
    objects, coasting, id switches) as ``none``.

    Runs are made in ``work_dir`` (kept and reused). Feature windows are taken every ``sample_period_s`` (the
    online engine evaluates every ``period_s``; denser training windows show the same behaviour at more phases).
    Returns the forest and a report: per class the training and test windows and the held-out (``test_seeds``,
    ``tracked_test_seeds``) window recall and precision. Save with ``model.save(default_model_path())`` to replace
    the shipped file; the command line is ``python -m fusiontrack.scene.learned --help``.
    """
    from ..io.tracks import read_jsonl
    from ..sim.scenario import load_scenario
    from ..sim.simulator import simulate

    say = progress or (lambda _msg: None)
    work = Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    parts: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {"train": [], "test": []}
    for split, split_seeds in (("train", seeds), ("test", test_seeds)):
        for seed in split_seeds:
            out = work / f"road_{seed}_{int(seconds)}"
            if not (out / "ground_truth" / "incidents.jsonl").is_file():
                say(f"simulating road seed {seed} ({seconds:g} s)")
                scenario = load_scenario("road").with_overrides(seconds=seconds, seed=seed,
                                                                settings={"cameras": [], "lasers": []})
                simulate(scenario, out)
            say(f"feature windows of seed {seed}")
            parts[split].append(run_samples(out, rng=seed, period_s=sample_period_s))
    for split, split_seeds in (("train", tracked_seeds), ("test", tracked_test_seeds)):
        for seed in split_seeds:
            out = tracked_run(work, seed, tracked_seconds, say)
            say(f"feature windows of the tracks of seed {seed}")
            parts[split].append(tracked_samples(read_jsonl(out / "tracks.jsonl"), out, rng=seed,
                                                period_s=sample_period_s))
    if not parts["train"]:
        raise ConfigError("train_scene_classifier: no training runs (seeds and tracked_seeds are empty)")
    X = np.vstack([p[0] for p in parts["train"]])
    y = np.concatenate([p[1] for p in parts["train"]])
    say(f"training on {len(y)} windows")
    model = SceneClassifier.fit(X, y, **fit_options)
    report: dict[str, Any] = {"classes": {}}
    if parts["test"]:
        Xt = np.vstack([p[0] for p in parts["test"]])
        yt = np.concatenate([p[1] for p in parts["test"]])
        pred, _ = model.predict(Xt)
        for c in CLASSES:
            truth, said = yt == c, pred == c
            report["classes"][c] = {
                "train": int((y == c).sum()), "test": int(truth.sum()),
                "recall": float((said & truth).sum() / truth.sum()) if truth.any() else math.nan,
                "precision": float((said & truth).sum() / said.sum()) if said.any() else math.nan}
    return model, report


def main(argv: Sequence[str] | None = None) -> None:
    """``python -m fusiontrack.scene.learned WORK [--seeds ...] [--tracked-seeds ...] [--save]``: retrain."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m fusiontrack.scene.learned",
                                 description="Retrain the learned scene model (ALGORITHMS.md D8) on simulated road "
                                             "runs: perfect tracks and the traffic pipeline's tracks.")
    ap.add_argument("work", type=Path, help="folder for the simulated runs (kept and reused)")
    ap.add_argument("--seeds", type=int, nargs="*", default=list(SHIPPED_TRAINING["seeds"]))
    ap.add_argument("--test-seeds", type=int, nargs="*", default=list(SHIPPED_TRAINING["test_seeds"]))
    ap.add_argument("--tracked-seeds", type=int, nargs="*", default=list(SHIPPED_TRAINING["tracked_seeds"]))
    ap.add_argument("--tracked-test-seeds", type=int, nargs="*",
                    default=list(SHIPPED_TRAINING["tracked_test_seeds"]))
    ap.add_argument("--seconds", type=float, default=SHIPPED_TRAINING["seconds"])
    ap.add_argument("--sample-period", type=float, default=SHIPPED_TRAINING["sample_period_s"])
    ap.add_argument("--min-samples-leaf", type=int, default=SHIPPED_TRAINING["min_samples_leaf"])
    ap.add_argument("--save", type=Path, nargs="?", const=default_model_path(), default=None,
                    help="write the forest here (no value: over the shipped scene_classifier.json)")
    a = ap.parse_args(argv)
    model, report = train_scene_classifier(a.work, seeds=a.seeds, test_seeds=a.test_seeds, seconds=a.seconds,
                                           tracked_seeds=a.tracked_seeds, tracked_test_seeds=a.tracked_test_seeds,
                                           tracked_seconds=a.seconds, sample_period_s=a.sample_period,
                                           min_samples_leaf=a.min_samples_leaf, progress=lambda m: print(m, flush=True))
    for c, r in report["classes"].items():
        print(f"{c:16s} train {r['train']:6d}  test {r['test']:6d}  recall {r['recall']:.3f}  "
              f"precision {r['precision']:.3f}")
    if a.save is not None:
        print(f"saved {model.save(a.save)}")


if __name__ == "__main__":
    main()
