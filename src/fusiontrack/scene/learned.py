"""Scene understanding learned from labelled tracks: the supervised alternative of ALGORITHMS.md D8.

Per track, every ``period_s`` (0.5 s), a window of the last ``window_s`` (5 s) of the switching control's
properties (:class:`~fusiontrack.scene.rules.SwitchingControl`: median speed, acceleration, signed distance to the
road edge now and 1 s ahead, lateral speed towards the edge, alignment with the lane, plus the same-lane
neighbours within ±25 m) is summarised into :data:`FEATURES` (means, extremes, last values, fractions) and
classified by a random forest into :data:`CLASSES` with a confidence (the forest's vote share).

Events have the interface of the rules (:class:`LearnedSceneUnderstanding` with ``update(t_ns, track_states)``,
:func:`detect_events_learned`): a track's ``stopped_vehicle`` / ``road_leaving`` / ``wrong_way`` event starts
once the forest says so with confidence >= ``p_min`` for ``on_s`` (two evaluations), and ends once it has not
for ``off_s``; a ``jam`` event of a lane zone starts once >= ``jam_min_tracks`` of its vehicles are classified
``jam``. ``t_ns`` is the first positive evaluation, ``attributes["alarm_t_ns"]`` the alarm.

Training (:func:`train_scene_classifier`): simulated ``road`` runs without sensors; the agents are the tracks
(``agents.csv``), the labels come from ``incidents.jsonl`` with the simulator's definitions (``sim/agents.py``):
a stopped or road-leaving vehicle from the incident's start to its end; a jam member while the jam lasts and
it drives slower than 10 km/h (the simulator's queue condition). The simulator has no wrong-way incident:
``wrong_way`` examples are free-flowing tracks played backwards in time (same road, motion against the lane),
labelled while faster than 3 m/s in a lane.

The forest (30 trees, depth <= 8) is shipped as JSON (``scene/data/scene_classifier.json``, ~80 kB): per tree the
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
    "train_scene_classifier",
    "window_samples",
]

log = logging.getLogger(__name__)

CLASSES = ("none", "stopped_vehicle", "road_leaving", "jam", "wrong_way")
_CHANNELS = ("speed", "acceleration", "edge_distance", "lateral_speed", "predicted_edge_distance", "lane_cos",
             "on_road", "in_lane", "nb_count", "nb_speed")
FEATURES = (
    "speed_last", "speed_mean", "speed_min", "speed_max", "speed_std", "still_frac",
    "accel_mean", "accel_min", "accel_max",
    "edge_last", "edge_min", "edge_mean", "edge_change", "edge_known_frac", "pred_edge_last",
    "lateral_last", "lateral_mean", "lateral_max",
    "lane_cos_last", "lane_cos_mean", "on_road_frac", "in_lane_last",
    "nb_count_last", "nb_count_mean", "nb_speed_last", "nb_speed_mean", "history_s",
)
MODEL_FILE = "scene_classifier.json"
FORMAT = "fusiontrack-forest-1"
NEIGHBOUR_RANGE_M = 25.0
STILL_MPS = 0.5
JAM_SPEED_MPS = 10 / 3.6  # the simulator's queue condition (sim/agents.py JAM_SPEED_MPS)
WRONG_WAY_MIN_MPS = 3.0


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
        last[:, s], mean[:, s], mn[:, s], mx[:, s], std, still,
        mean[:, a], mn[:, a], mx[:, a],
        last[:, e], mn[:, e], mean[:, e], last[:, e] - first[:, e], edge_known, last[:, c["predicted_edge_distance"]],
        last[:, lat], mean[:, lat], mx[:, lat],
        last[:, c["lane_cos"]], mean[:, c["lane_cos"]], mean[:, c["on_road"]], last[:, c["in_lane"]],
        last[:, c["nb_count"]], mean[:, c["nb_count"]], last[:, c["nb_speed"]], mean[:, c["nb_speed"]], history_s,
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
    cols = [p["speed"], p["acceleration"], p["edge_distance"], p["lateral_speed"], p["predicted_edge_distance"],
            p["lane_cos"], p["on_road"].astype(np.float64), p["in_lane"].astype(np.float64), nb_count, nb_speed]
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
    window_s, period_s, min_history_s : float — feature window, evaluation period, history needed (s)
    p_min : float — least confidence of a positive evaluation
    on_s, off_s : float — a positive class must hold ``on_s`` to start an event, be absent ``off_s`` to end it
    jam_min_tracks : int — vehicles of a lane zone classified ``jam`` that make a jam
    sensor : str
    """

    def __init__(self, geometry: RoadGeometry, model: SceneClassifier | None = None, rules: SceneRules | None = None,
                 *, window_s: float = 5.0, period_s: float = 0.5, min_history_s: float = 1.0, p_min: float = 0.5,
                 on_s: float = 0.5, off_s: float = 2.0, jam_min_tracks: int = 3, sensor: str = "scene_learned",
                 collect: bool = False) -> None:
        if not 0 <= p_min <= 1 or on_s < 0 or off_s < 0 or jam_min_tracks < 1:
            raise ConfigError(f"p_min in [0, 1], on_s >= 0, off_s >= 0, jam_min_tracks >= 1; got {p_min}, {on_s}, "
                              f"{off_s}, {jam_min_tracks}")
        self.geometry = geometry
        self.model = model if model is not None or collect else default_scene_classifier()
        self.control = SwitchingControl(geometry, rules if rules is not None else default_rules())
        self.windows = FeatureWindows(window_s, period_s, min_history_s)
        self.log = EventLog(sensor)
        self.p_min, self.jam_min_tracks = float(p_min), int(jam_min_tracks)
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
                        out.append(self.log.close(int(latch.event[slot]), last_ns, last_ns))
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
        confident = prob >= self.p_min
        is_vehicle = self.control.latest_vehicle[due]
        self._label[due] = np.where(confident & is_vehicle, label, "none")
        row_of = {int(s): j for j, s in enumerate(frame.slots)}
        for kind, latch in self._latches.items():
            latch.resize(n_slots)
            cond = (label == kind) & confident & is_vehicle
            started, ended = latch.step(due, frame.t_ns, cond, ~cond, self.control.latest_pos[due])
            for s in ended.tolist():
                out.append(self.log.close(int(latch.event[s]), int(latch.clear_start_ns[s]), frame.t_ns))
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
                eid, ev = self.log.open(kind, int(latch.run_start_ns[s]), latch.run_pos[s],
                                        [int(self.control.track_id[s])], attrs)
                latch.event[s] = eid
                out.append(ev)
        return out + self._jam_step(frame.t_ns)

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
            latch.event[z] = -1
        for z in started.tolist():
            zone = self.geometry.zones[int(self._jam_zones[z])]
            members = jam[in_zone[:, z]]
            attrs = {"rule": "learned", "alarm_t_ns": int(t_ns),
                     "alarm_position_m": tuple(float(v) for v in centre[z]), "lane": zone.lane or "",
                     "zone": zone.name, "confidence": float(np.nanmean(c.latest_score[members])),
                     "properties": {"count": int(count[z])}}
            eid, ev = self.log.open("jam", int(latch.run_start_ns[z]), latch.run_pos[z],
                                    c.track_id[members].tolist(), attrs)
            latch.event[z] = eid
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
    condition). Otherwise ``"none"``.
    """
    y = np.full(track_ids.size, "none", dtype=object)
    for inc in incidents:
        if inc.kind not in CLASSES:
            continue
        end = np.iinfo(np.int64).max if inc.t_end_ns is None else inc.t_end_ns
        sel = np.isin(track_ids, inc.track_ids) & (t_ns >= inc.t_ns) & (t_ns <= end)
        if inc.kind == "jam" and sel.any():
            speed = np.array([_agent_speed(agents, int(a), int(t)) for a, t in zip(track_ids[sel], t_ns[sel],
                                                                                    strict=True)])
            idx = np.flatnonzero(sel)
            sel[idx[~(speed < JAM_SPEED_MPS)]] = False
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


def train_scene_classifier(work_dir: str | Path, *, seeds: Sequence[int] = (100, 101, 102),
                           test_seeds: Sequence[int] = (103,), seconds: float = 120.0,
                           progress: Callable[[str], None] | None = None, **fit_options: Any
                           ) -> tuple[SceneClassifier, dict[str, Any]]:
    """Retrain the shipped forest on simulated ``road`` runs (no sensors: only the agents are needed).

    Runs are simulated into ``work_dir`` (kept and reused). Returns the forest and a report: per class the
    training and test windows and the held-out recall and precision. Save with ``model.save(default_model_path())``
    to replace the shipped file.
    """
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
            parts[split].append(run_samples(out, rng=seed))
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
