"""Online blob tracker with fragmentation and grouping through an inference graph (seed 000, ALGORITHMS.md A5).

Framework of Bose, Wang & Grimson (CVPR 2007) in the online form of Choi et al. [seed 000, ref. 9]:

1. **Association events.** ``A_ij = 1`` when predicted node box ``i`` and blob ``j`` overlap by at least
   ``τ_ov`` of the smaller area, or their centroids are within ``d_a``. Per connected component of ``A``:
   one node and one blob *continue*; a node without blob *disappears* (coasts ``N_coast`` frames); a blob
   without node *appears*; several nodes on one blob *merge*; one node on several blobs *splits*; several
   on several is *complex* = merge then split. A complex component that is a one-to-one matching of
   gated pairs (people walking close but still apart) is read as several *continue* events.
2. **Inference graph.** A node is a blob-track segment between events; a merge creates a node with edges
   from each merging node, a split creates children with edges from their parent (:meth:`BlobTracker.graph`).
3. **Generic object model.** Two nodes are one object when, over ``W`` frames, their boxes stay within
   ``d_frag`` (gap) and ``std_t(c_i − c_j) <= σ_coh`` (coherent motion).
4. **Labels**, decided ``W`` frames after a split: children that stay coherent are *fragments* of their
   parent (its id, the union box); children of an object that diverge mean the object was an unresolved
   group (new ids); children of a group that diverge get their members' ids back by Hungarian assignment
   (X2) on ``1 − BC`` (X4) of colour histograms stored before the merge, cost above 0.6 = new id. A merge
   of nodes with two or more objects is a *group* whose members are the union.
5. **Output.** One :class:`TrackedObject` per object: its own box, or the group's box with ``in_group``.

Size prior (A5 §3-4): the expected box area of one person ``A_p(v_bottom)`` is a straight line of area against
bottom row, fitted robustly (Theil–Sen) to confirmed single objects once ``size_samples`` of them spread over
at least ``size_spread_px`` rows (:func:`fit_person_area`); with a calibrated camera an a-priori ``A_p`` (the
projected box of a ``person_height_m`` person) is used wherever the learnt line is not yet valid. With
``n̂ = area / A_p``: a new node with ``n̂ >= group_n_hat`` is a group of an unknown number of people, and so is
each diverging child of a split with ``n̂ >= group_n_hat``. Such a group carries a *placeholder* object id
(it stands for two or more people); it is reported with ``in_group``, ``count_known = False`` and
``group_size`` from ``n̂``. A placeholder that later turns out to be one person (a split child, or a group that
stays one person's size for ``W`` frames) becomes an ordinary object under the same id.
The rule is off by default (``group_n_hat = 0``; A5's value is 1.7): on the simulated ``groups`` and ``crowd``
(``benchmarks/camera_people.py``, 3 seeds, A5's objects alone) it took MOTA from 35.4 / 36.4 % to 34.5 / 34.6 %
(IDF1 51.8 / 51.7 → 50.9 / 49.5): most blobs it marks are two people one behind the other, whose box as a
single object still matched one of them at IoU >= 0.5. The learnt ``A_p`` is always kept (``group_collapse``).

Blobs that appear together within ``d_frag`` of each other are born as a pending split of one new object
(a person first seen in two pieces keeps one id). A new object is reported once its node has been seen
``n_confirm`` frames. Without colour histograms a group's members cannot be told apart at a split; they then
get their ids back in an arbitrary order.
"""

from __future__ import annotations

import enum
import logging
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import theilslopes

from ..geometry import PinholeCamera
from ..tracking.association import hungarian
from ..tracking.kalman import cv_matrices, predict, update
from .blobs import Blobs

__all__ = ["AreaLaw", "BlobEvent", "BlobTracker", "BlobTrackerParams", "NodeLabel", "TrackedObject", "box_gaps",
           "fit_person_area"]

log = logging.getLogger(__name__)


class NodeLabel(enum.StrEnum):
    """Label of an inference-graph node (A5 §2)."""

    OBJECT = "object"
    FRAGMENT = "fragment"
    GROUP = "group"


@dataclass(frozen=True, slots=True)
class BlobTrackerParams:
    """A5's parameters [RECON] and X5's image-blob Kalman filter.

    Attributes
    ----------
    tau_ov : float
        Overlap of predicted box and blob, as a fraction of the smaller area, that associates them (0.1).
    d_a_px : float
        Centroid distance that associates them (20 px).
    n_coast : int
        Frames a node without blob coasts before it ends (10).
    window : int
        ``W``, frames of the coherence test and the labelling delay (10).
    d_frag_px : float
        Largest box gap of two fragments of one object (20 px ≈ 0.3 × a person's height at 320×240).
    sigma_coh_px : float
        Largest ``std_t`` of the centroid difference of two fragments (3 px).
    max_colour_cost : float
        Largest ``1 − BC`` of a restored identity (0.6).
    n_confirm : int
        Frames a new object's node must be seen before the object is reported (3).
    q_px2 : float
        X5 acceleration noise for image blobs (25 px²/s³).
    r_px2 : float
        X5 centroid measurement variance (4 px²).
    frame_dt_s : float
        Time step when :meth:`BlobTracker.step` gets no ``t_ns`` (0.1 s).
    size_rate : float
        Rate at which a node's box size follows its blob (0.5).
    hist_rate : float
        Rate at which an object's colour histogram follows it while it is alone (0.1).
    group_collapse : float
        A5 §3's optional size prior: a group whose blob stays smaller than this many expected single-person
        areas ``A_p(v_bottom)`` for ``W`` frames keeps only its best-matching member (1.3; 0 = off) [RECON].
    size_samples : int
        Confirmed single objects (frames) needed before ``A_p``, a straight-line fit of area against bottom
        row, is used (50).
    size_spread_px : float
        Least spread (5th to 95th percentile) of their bottom rows before the line is used (30 px) [RECON].
    group_n_hat : float
        A5 §4: a new node, or a diverging child of a split, with ``n̂ = area / A_p >= group_n_hat`` is a group
        of unknown member count (A5's value is 1.7; default 0 = off: on the simulated ``groups`` and ``crowd``
        it lowers the MOTA of A5's single objects, see the module docstring).
    person_height_m, person_width_ratio : float
        The person of the a-priori ``A_p`` from a calibrated camera (1.72 m; width 0.40 of the height, B11).
    """

    tau_ov: float = 0.1
    d_a_px: float = 20.0
    n_coast: int = 10
    window: int = 10
    d_frag_px: float = 20.0
    sigma_coh_px: float = 3.0
    max_colour_cost: float = 0.6
    n_confirm: int = 3
    q_px2: float = 25.0
    r_px2: float = 4.0
    frame_dt_s: float = 0.1
    size_rate: float = 0.5
    hist_rate: float = 0.1
    group_collapse: float = 1.3
    size_samples: int = 50
    size_spread_px: float = 30.0
    group_n_hat: float = 0.0
    person_height_m: float = 1.72
    person_width_ratio: float = 0.40

    def __post_init__(self) -> None:
        for name in ("n_coast", "window", "n_confirm"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < (2 if name == "window" else 0):
                raise ValueError(f"BlobTrackerParams.{name}: expected an integer >= {2 if name == 'window' else 0}, "
                                 f"got {v!r}")
        for name in ("tau_ov", "d_a_px", "d_frag_px", "sigma_coh_px", "q_px2", "r_px2", "frame_dt_s",
                     "size_spread_px", "group_n_hat"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"BlobTrackerParams.{name}: expected a finite value >= 0, got {v!r}")
        if not (np.isfinite(self.group_collapse) and self.group_collapse >= 0):
            raise ValueError(f"BlobTrackerParams.group_collapse: expected a finite value >= 0, got "
                             f"{self.group_collapse!r}")
        for name in ("person_height_m", "person_width_ratio"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"BlobTrackerParams.{name}: expected a finite value > 0, got {v!r}")
        if isinstance(self.size_samples, bool) or not isinstance(self.size_samples, int) or self.size_samples < 2:
            raise ValueError(f"BlobTrackerParams.size_samples: expected an integer >= 2, got {self.size_samples!r}")
        for name in ("max_colour_cost", "size_rate", "hist_rate"):
            v = getattr(self, name)
            if not 0 <= v <= 1:
                raise ValueError(f"BlobTrackerParams.{name}: expected a value in [0, 1], got {v!r}")


@dataclass(frozen=True, slots=True, eq=False)
class TrackedObject:
    """One physical object in one frame (A5 §5).

    Attributes
    ----------
    object_id : int
        Stable id, owned by the tracker instance.
    box_px : (4,) float64
        ``(u_min, v_min, u_max, v_max)``: the object's own box, or its group's box when ``in_group``.
    in_group : bool
        The object is inside a blob with other objects.
    group_id : int
        Node id of the group (-1 when alone).
    missed : int
        Frames since its blob(s) were last seen (0 = seen now; coasting up to ``n_coast``).
    group_size : int
        People in the box: 1 alone, the member count of a group, or for a group of unknown member count
        its estimate ``max(round(n̂), members + 1)`` (at least 2).
    count_known : bool
        False for a group of unknown member count (A5 §4): ``object_id`` may then stand for several people,
        and the group's other members have no record.
    """

    object_id: int
    box_px: np.ndarray
    in_group: bool = False
    group_id: int = -1
    missed: int = 0
    group_size: int = 1
    count_known: bool = True

    def __post_init__(self) -> None:
        box = np.array(self.box_px, dtype=np.float64).reshape(4)
        box.setflags(write=False)
        object.__setattr__(self, "box_px", box)


@dataclass(frozen=True, slots=True)
class BlobEvent:
    """One association event (A5 §1): ``kind`` in continue/appear/disappear/merge/split/complex/end."""

    frame: int
    kind: str
    before: tuple[int, ...]  # node ids
    after: tuple[int, ...]


@dataclass(slots=True, eq=False)
class _Node:
    node_id: int
    x: np.ndarray  # (4,) centroid and velocity, px and px/s
    P: np.ndarray  # (4, 4)
    size: np.ndarray  # (2,) width, height px
    label: NodeLabel
    members: frozenset[int]
    born: int
    parents: tuple[int, ...] = ()
    children: list[int] = field(default_factory=list)
    hist: np.ndarray | None = None
    missed: int = 0
    n_seen: int = 0
    alive: bool = True
    split: int = -1  # pending split this node is a child of
    small: int = 0  # consecutive frames a group node looked like one person (size prior)
    history: deque = field(default_factory=lambda: deque(maxlen=64))  # (frame, centroid (2,), box (4,))

    def box(self) -> np.ndarray:
        return np.concatenate([self.x[:2] - self.size / 2, self.x[:2] + self.size / 2])


@dataclass(slots=True, eq=False)
class _Split:
    parent_label: NodeLabel
    members: frozenset[int]
    children: list[int]
    frame: int


def box_gaps(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean gap between boxes ``a (n, 4)`` and ``b (m, 4)`` (0 when they touch or overlap), ``(n, m)`` px."""
    a = np.asarray(a, np.float64).reshape(-1, 4)
    b = np.asarray(b, np.float64).reshape(-1, 4)
    dx = np.maximum(0.0, np.maximum(b[None, :, 0] - a[:, None, 2], a[:, None, 0] - b[None, :, 2]))
    dy = np.maximum(0.0, np.maximum(b[None, :, 1] - a[:, None, 3], a[:, None, 1] - b[None, :, 3]))
    return np.hypot(dx, dy)


@dataclass(frozen=True, slots=True)
class AreaLaw:
    """A5 §3's ``A_p(v) = intercept + slope · v`` (px²), valid for bottom rows ``v_lo <= v <= v_hi``."""

    slope: float
    intercept: float
    v_lo: float
    v_hi: float

    def __call__(self, v_bottom_px: np.ndarray) -> np.ndarray:
        """``A_p`` at bottom rows ``v`` (any shape); NaN outside ``[v_lo, v_hi]`` or where the line is <= 0."""
        v = np.asarray(v_bottom_px, np.float64)
        a = self.intercept + self.slope * v
        return np.where((v >= self.v_lo) & (v <= self.v_hi) & (a > 0), a, np.nan)


def fit_person_area(v_bottom_px: np.ndarray, area_px2: np.ndarray, *, min_samples: int = 50,
                    min_spread_px: float = 30.0, max_fit: int = 300) -> AreaLaw | None:
    """Robust straight line of single-person box area against bottom row (Theil–Sen), or None if too few.

    Parameters
    ----------
    v_bottom_px, area_px2 : (n,) float
        Bottom rows and box areas of confirmed single objects (non-finite pairs are ignored).
    min_samples : int
        Fewer finite samples give None.
    min_spread_px : float
        Rows whose 5th-95th percentile range is narrower give None (the slope is not determined).
    max_fit : int
        At most this many samples, evenly spaced, enter the O(n²) Theil–Sen fit.

    Returns
    -------
    AreaLaw or None
        Valid over the 5th-95th percentile band of the rows widened by a quarter of its width each side.
    """
    v = np.asarray(v_bottom_px, np.float64).ravel()
    a = np.asarray(area_px2, np.float64).ravel()
    if v.shape != a.shape:
        raise ValueError(f"fit_person_area: v_bottom_px {v.shape} and area_px2 {a.shape} differ")
    ok = np.isfinite(v) & np.isfinite(a)
    v, a = v[ok], a[ok]
    if v.size < max(min_samples, 2):
        return None
    lo, hi = np.percentile(v, [5.0, 95.0])
    if hi - lo < min_spread_px or hi - lo <= 0:
        return None
    if v.size > max_fit:
        keep = np.linspace(0, v.size - 1, max_fit).round().astype(np.int64)
        v, a = v[keep], a[keep]
    slope, intercept, _, _ = theilslopes(a, v, method="joint")  # intercept: median of a − slope·v
    margin = 0.25 * (hi - lo)
    return AreaLaw(float(slope), float(intercept), float(lo - margin), float(hi + margin))


def _box_area(boxes: np.ndarray) -> np.ndarray:
    return np.prod(np.clip(boxes[..., 2:] - boxes[..., :2], 0.0, None), axis=-1)


def _overlap_fraction(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over the smaller area, ``(n, m)``."""
    lo = np.maximum(a[:, None, :2], b[None, :, :2])
    hi = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(hi - lo, 0.0, None), axis=2)
    area = lambda x: np.prod(np.clip(x[:, 2:] - x[:, :2], 0.0, None), axis=1)  # noqa: E731
    return inter / np.maximum(np.minimum(area(a)[:, None], area(b)[None, :]), 1e-9)


def _components(adj: np.ndarray) -> np.ndarray:
    """Connected components of a small undirected graph given as a square bool matrix, ``(n,)`` int64 labels
    numbered in the order of each component's lowest vertex (as ``scipy.sparse.csgraph.connected_components``
    numbers them). Union-find over the edges: the graphs here have a few dozen vertices, for which building
    sparse matrices costs far more than the search."""
    n = adj.shape[0]
    parent = list(range(n))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in zip(*np.nonzero(np.triu(adj | adj.T, 1)), strict=True):
        ri, rj = root(int(i)), root(int(j))
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)
    return np.unique([root(i) for i in range(n)], return_inverse=True)[1].astype(np.int64).reshape(n)


def _bc_cost(p: np.ndarray | None, q: np.ndarray | None) -> float:
    """``1 − BC(p, q)`` (X4), 0.5 when either histogram is unknown."""
    if p is None or q is None:
        return 0.5
    return float(1.0 - np.sum(np.sqrt(p * q)))


class BlobTracker:
    """A5's tracker for one camera; :meth:`step` once per frame with that frame's blobs.

    Parameters
    ----------
    params : BlobTrackerParams, optional
    camera : PinholeCamera, optional
        The calibrated camera of the blobs: gives an a-priori ``A_p`` (a person's projected box) before one is
        learnt from the scene.
    """

    def __init__(self, params: BlobTrackerParams | None = None, camera: PinholeCamera | None = None) -> None:
        self.params = BlobTrackerParams() if params is None else params
        self._prior = None if camera is None else self._camera_prior(camera)
        self._law: AreaLaw | None = None
        self._n_sized = 0  # samples ever added to _sizes
        self._n_fitted = 0  # ... when _law was last fitted
        self._placeholders: set[int] = set()  # object ids standing for a group of unknown member count
        self._nodes: dict[int, _Node] = {}
        self._splits: dict[int, _Split] = {}
        self._object_hist: dict[int, np.ndarray | None] = {}
        self._next_node = 0
        self._next_object = 1
        self._next_split = 0
        self._frame = -1
        self._t_ns: int | None = None
        self._sizes: deque[tuple[float, float]] = deque(maxlen=1000)  # (bottom row px, area px²) of single objects
        self.events: deque[BlobEvent] = deque(maxlen=10000)

    # -- public -------------------------------------------------------------------------------------

    @property
    def frame(self) -> int:
        """Index of the last frame stepped (-1 before the first)."""
        return self._frame

    def graph(self) -> dict[int, tuple[int, ...]]:
        """The inference graph: node id -> ids of its children (merge and split edges, A5 §2)."""
        return {k: tuple(n.children) for k, n in self._nodes.items()}

    def node_labels(self) -> dict[int, tuple[str, frozenset[int]]]:
        """Label and member object ids of every node ever created."""
        return {k: (str(n.label), n.members) for k, n in self._nodes.items()}

    def step(self, blobs: Blobs, histograms: np.ndarray | None = None, t_ns: int | None = None
             ) -> list[TrackedObject]:
        """Advance one frame.

        Parameters
        ----------
        blobs : Blobs
            This frame's blobs (A4).
        histograms : (n_blobs, n_bins) float, optional
            Normalised colour histograms of the blobs (:func:`~fusiontrack.vision.blobs.blob_histograms`);
            needed to give group members their ids back when the group splits.
        t_ns : int, optional
            Frame time; without it frames are ``frame_dt_s`` apart.

        Returns
        -------
        list of TrackedObject
            Confirmed objects, sorted by id.
        """
        p = self.params
        n_b = len(blobs)
        if histograms is not None:
            histograms = np.asarray(histograms, np.float64)
            if histograms.ndim != 2 or histograms.shape[0] != n_b:
                raise ValueError(f"histograms: expected ({n_b}, n_bins), got {histograms.shape}")
        dt = p.frame_dt_s
        if t_ns is not None:
            if self._t_ns is not None:
                if t_ns <= self._t_ns:
                    raise ValueError(f"t_ns: {t_ns} is not after the previous frame's {self._t_ns}")
                dt = (t_ns - self._t_ns) * 1e-9
            self._t_ns = int(t_ns)
        self._frame += 1
        live = [n for n in self._nodes.values() if n.alive]
        if live:
            F, Q = cv_matrices(dt, p.q_px2)
            xs, Ps = predict(np.array([n.x for n in live]), np.array([n.P for n in live]), F, Q)
            for n, x, P in zip(live, xs, Ps, strict=True):
                n.x, n.P = x, P
        hists = [None if histograms is None else histograms[j] for j in range(n_b)]
        boxes = blobs.boxes_px
        cents = blobs.centroids_px
        A = np.zeros((len(live), n_b), bool)
        if live and n_b:
            pred = np.array([n.box() for n in live])
            dist = np.linalg.norm(np.array([n.x[:2] for n in live])[:, None] - cents[None], axis=2)
            A = (_overlap_fraction(pred, boxes) >= p.tau_ov) | (dist <= p.d_a_px)
        n_n = len(live)
        full = np.zeros((n_n + n_b, n_n + n_b), bool)  # nodes, then blobs
        full[:n_n, n_n:] = A
        comp = _components(full)
        appeared: list[int] = []
        for c in np.unique(comp):
            nodes = [live[i] for i in np.flatnonzero(comp[:n_n] == c)]
            js = [int(j) for j in np.flatnonzero(comp[n_n:] == c)]
            if not js:
                for n in nodes:
                    self._coast(n)
            elif not nodes:
                appeared += js
            elif len(nodes) == 1 and len(js) == 1:
                self._continue(nodes[0], boxes[js[0]], cents[js[0]], hists[js[0]])
            elif len(nodes) == len(js) and self._one_to_one(nodes, js, A[np.ix_([live.index(n) for n in nodes], js)],
                                                            boxes, cents, hists):
                pass
            elif len(js) == 1:
                self._merge(nodes, boxes[js[0]], cents[js[0]], hists[js[0]])
            else:
                self._split(nodes, [boxes[j] for j in js], [cents[j] for j in js], [hists[j] for j in js])
        self._appear(appeared, boxes, cents, hists)
        self._decide_splits()
        self._check_fragments()
        self._size_prior()
        return self._output()

    # -- events -------------------------------------------------------------------------------------

    def _new_node(self, box: np.ndarray, centroid: np.ndarray, hist: np.ndarray | None, label: NodeLabel,
                  members: frozenset[int], parents: tuple[int, ...] = (), velocity: np.ndarray | None = None
                  ) -> _Node:
        p = self.params
        x = np.r_[centroid, np.zeros(2) if velocity is None else velocity]
        P = np.diag([p.r_px2, p.r_px2, 100.0**2, 100.0**2])  # a walker moves up to ~100 px/s at 320x240
        n = _Node(self._next_node, x, P, box[2:] - box[:2], label, members, self._frame, parents, hist=hist,
                  n_seen=1)
        n.history.append((self._frame, np.asarray(centroid, np.float64), np.asarray(box, np.float64)))
        self._next_node += 1
        self._nodes[n.node_id] = n
        for q in parents:
            self._nodes[q].children.append(n.node_id)
        return n

    def _new_object(self, hist: np.ndarray | None) -> int:
        oid = self._next_object
        self._next_object += 1
        self._object_hist[oid] = hist
        return oid

    def _end(self, n: _Node) -> None:
        n.alive = False

    def _continue(self, n: _Node, box: np.ndarray, centroid: np.ndarray, hist: np.ndarray | None) -> None:
        p = self.params
        x, P = update(n.x[None], n.P[None], centroid[None], R=p.r_px2)
        n.x, n.P = x[0], P[0]
        n.size += p.size_rate * ((box[2:] - box[:2]) - n.size)
        n.missed = 0
        n.n_seen += 1
        if hist is not None:
            n.hist = hist if n.hist is None else (1 - p.hist_rate) * n.hist + p.hist_rate * hist
        n.history.append((self._frame, np.asarray(centroid, np.float64), np.asarray(box, np.float64)))
        if len(n.members) == 1 and n.label == NodeLabel.OBJECT and hist is not None:
            (oid,) = n.members
            old = self._object_hist.get(oid)
            self._object_hist[oid] = hist if old is None else (1 - p.hist_rate) * old + p.hist_rate * hist
        self.events.append(BlobEvent(self._frame, "continue", (n.node_id,), (n.node_id,)))

    def _coast(self, n: _Node) -> None:
        n.missed += 1
        if n.missed > self.params.n_coast:
            self._end(n)
            self.events.append(BlobEvent(self._frame, "end", (n.node_id,), ()))
        elif n.missed == 1:
            self.events.append(BlobEvent(self._frame, "disappear", (n.node_id,), ()))

    def _one_to_one(self, nodes: list[_Node], js: list[int], gated: np.ndarray, boxes: np.ndarray,
                    cents: np.ndarray, hists: list[np.ndarray | None]) -> bool:
        """As many nodes as blobs and a one-to-one matching of gated pairs (X2 on centroid distance): continues."""
        d = np.linalg.norm(np.array([n.x[:2] for n in nodes])[:, None] - cents[js][None], axis=2)
        pairs, _, _ = hungarian(np.where(gated, d, np.inf))
        if len(pairs) != len(nodes):
            return False
        for r, c in pairs:
            self._continue(nodes[r], boxes[js[c]], cents[js[c]], hists[js[c]])
        return True

    def _merge(self, nodes: list[_Node], box: np.ndarray, centroid: np.ndarray, hist: np.ndarray | None) -> None:
        self._settle_before_merge(nodes)
        members = frozenset().union(*(n.members for n in nodes))
        label = NodeLabel.GROUP if len(members) > 1 or members & self._placeholders else NodeLabel.OBJECT
        vel = np.mean([n.x[2:] for n in nodes], axis=0)
        g = self._new_node(box, centroid, hist, label, members, tuple(n.node_id for n in nodes), vel)
        g.n_seen = max(n.n_seen for n in nodes) + 1
        for n in nodes:
            self._end(n)
        self.events.append(BlobEvent(self._frame, "merge", tuple(n.node_id for n in nodes), (g.node_id,)))

    def _split(self, nodes: list[_Node], boxes: list[np.ndarray], cents: list[np.ndarray],
               hists: list[np.ndarray | None]) -> None:
        if len(nodes) > 1:
            self._settle_before_merge(nodes)
        members = frozenset().union(*(n.members for n in nodes))
        kind = "split" if len(nodes) == 1 else "complex"
        label = NodeLabel.GROUP if len(members) > 1 or members & self._placeholders else NodeLabel.OBJECT
        parents = tuple(n.node_id for n in nodes)
        vel = np.mean([n.x[2:] for n in nodes], axis=0)
        sid = self._next_split
        self._next_split += 1
        children = []
        for b, c, h in zip(boxes, cents, hists, strict=True):
            child = self._new_node(b, c, h, label, members, parents, vel)
            child.n_seen = max(n.n_seen for n in nodes) + 1
            child.split = sid
            children.append(child.node_id)
        self._splits[sid] = _Split(label, members, children, self._frame)
        for n in nodes:
            self._end(n)
            if n.split >= 0 and n.split in self._splits:  # a child of a pending split splits again
                s = self._splits[n.split]
                s.children = [k for k in s.children if k != n.node_id]
        self.events.append(BlobEvent(self._frame, kind, parents, tuple(children)))

    def _appear(self, js: list[int], boxes: np.ndarray, cents: np.ndarray, hists: list[np.ndarray | None]) -> None:
        """New blobs; those within ``d_frag`` of each other are one new object born in pieces (a pending split)."""
        if not js:
            return
        comp = _components(box_gaps(boxes[js], boxes[js]) <= self.params.d_frag_px)
        for c in np.unique(comp):
            group = [js[k] for k in np.flatnonzero(comp == c)]
            bx = boxes[group]
            crowd = self._is_crowd(np.r_[bx[:, :2].min(axis=0), bx[:, 2:].max(axis=0)])  # A5 §4: n̂ >= 1.7
            hist = hists[group[0]] if len(group) == 1 else None
            oid = self._placeholder(hist) if crowd else self._new_object(hist)
            label = NodeLabel.GROUP if crowd else NodeLabel.OBJECT
            if len(group) == 1:
                n = self._new_node(boxes[group[0]], cents[group[0]], hists[group[0]], label, frozenset({oid}))
                self.events.append(BlobEvent(self._frame, "appear", (), (n.node_id,)))
                continue
            sid = self._next_split
            self._next_split += 1
            children = []
            for j in group:
                n = self._new_node(boxes[j], cents[j], hists[j], label, frozenset({oid}))
                n.split = sid
                children.append(n.node_id)
            self._splits[sid] = _Split(label, frozenset({oid}), children, self._frame)
            self.events.append(BlobEvent(self._frame, "appear", (), tuple(children)))

    # -- labelling (A5 §3-4) ------------------------------------------------------------------------

    def _coherent(self, a: _Node, b: _Node) -> bool:
        """A5 §3 over the last ``W`` frames both were seen in: gap <= d_frag and std of c_a − c_b <= σ_coh."""
        p = self.params
        ha = {f: (c, bx) for f, c, bx in a.history if f > self._frame - p.window}
        hb = {f: (c, bx) for f, c, bx in b.history if f > self._frame - p.window}
        common = sorted(set(ha) & set(hb))
        if len(common) < max(2, p.window // 2):
            return False
        ca = np.array([ha[f][0] for f in common])
        cb = np.array([hb[f][0] for f in common])
        ba = np.array([ha[f][1] for f in common])
        bb = np.array([hb[f][1] for f in common])
        gap = np.diagonal(box_gaps(ba, bb)).max()
        spread = float(np.linalg.norm(np.std(ca - cb, axis=0)))
        return gap <= p.d_frag_px and spread <= p.sigma_coh_px

    def _clusters(self, nodes: list[_Node]) -> list[list[_Node]]:
        k = len(nodes)
        same = np.eye(k, dtype=bool)
        for i in range(k):
            for j in range(i + 1, k):
                same[i, j] = same[j, i] = self._coherent(nodes[i], nodes[j])
        comp = _components(same)
        return [[nodes[i] for i in np.flatnonzero(comp == c)] for c in np.unique(comp)]

    def _decide_splits(self) -> None:
        p = self.params
        for sid in list(self._splits):
            s = self._splits[sid]
            kids = [self._nodes[k] for k in s.children if self._nodes[k].alive and self._nodes[k].split == sid]
            if len(kids) <= 1:  # the pieces merged again or vanished: nothing to decide
                for n in kids:
                    n.split = -1
                del self._splits[sid]
            elif self._frame - s.frame >= p.window:
                self._resolve(sid, kids)

    def _resolve(self, sid: int, kids: list[_Node]) -> None:
        """A5 §4 for the pieces ``kids`` of pending split ``sid``."""
        s = self._splits.pop(sid)
        clusters = self._clusters(kids)
        for n in kids:
            n.split = -1
        if len(clusters) == 1:  # fragments of the parent (an object or a group) that never separated
            for n in kids:
                n.label = NodeLabel.FRAGMENT if s.parent_label == NodeLabel.OBJECT else NodeLabel.GROUP
            return
        hist = [self._cluster_hist(c) for c in clusters]
        crowd = [self._is_crowd(self._union_box(c)) for c in clusters]  # A5 §4: each child is O, or G if n̂ >= 1.7
        if len(s.members) <= 1:  # an object (or an unknown group) that splits into diverging parts: new ids
            owners = [frozenset({self._placeholder(h) if g else self._new_object(h)})
                      for h, g in zip(hist, crowd, strict=True)]
        else:  # a group splits: members get their ids back by colour (X2 on 1 − BC)
            owners = self._restore(sorted(s.members), hist)
        for k, (c, own) in enumerate(zip(clusters, owners, strict=True)):
            if crowd[k] and len(own) == 1 and not own & self._placeholders:
                if own <= s.members:  # one known person and others
                    own = owners[k] = own | {self._placeholder(None)}
                else:  # a new id (no member looked like it): it stands for the whole group
                    self._placeholders |= own
            elif not crowd[k] and len(own) == 1:  # one person's size: a placeholder id is now that person's
                self._placeholders -= own
            label = NodeLabel.GROUP if len(own) > 1 or own & self._placeholders else \
                (NodeLabel.OBJECT if len(c) == 1 else NodeLabel.FRAGMENT)
            for n in c:
                n.members = own
                n.label = label
        log.debug("frame %d: split of %s into %s", self._frame, sorted(s.members), [sorted(o) for o in owners])

    def _settle_before_merge(self, nodes: list[_Node]) -> None:
        """A piece of a pending *group* split that merges with something else: share the members out first.

        Otherwise the merged node and the piece's siblings would all claim the whole group. (A piece of an
        object keeps the object's id; the siblings' claim wins in :meth:`_dedupe`.)
        """
        for sid in {n.split for n in nodes if n.split >= 0}:
            s = self._splits.get(sid)
            if s is None or len(s.members) <= 1:
                continue
            kids = [self._nodes[k] for k in s.children if self._nodes[k].alive and self._nodes[k].split == sid]
            if any(k not in nodes for k in kids) and len(kids) > 1:
                self._resolve(sid, kids)

    def _cluster_hist(self, cluster: list[_Node]) -> np.ndarray | None:
        hs = [(n.hist, float(np.prod(n.size))) for n in cluster if n.hist is not None]
        if not hs:
            return None
        h = sum(w * hh for hh, w in hs) / max(sum(w for _, w in hs), 1e-9)
        return h / max(h.sum(), 1e-12)

    def _restore(self, members: list[int], hists: list[np.ndarray | None]) -> list[frozenset[int]]:
        """Members (object ids) to clusters: Hungarian on ``1 − BC``; leftovers join the most similar cluster."""
        cost = np.array([[_bc_cost(h, self._object_hist.get(m)) for m in members] for h in hists])
        pairs, free_rows, free_cols = hungarian(cost, gate=self.params.max_colour_cost)
        owners: list[set[int]] = [set() for _ in hists]
        for r, c in pairs:
            owners[r].add(members[c])
        for c in free_cols:  # a member no piece looks like: it stays with the closest piece (still in a group)
            r = int(np.argmin(cost[:, c]))
            if cost[r, c] <= self.params.max_colour_cost and owners[r]:
                owners[r].add(members[c])
        for r in free_rows:
            owners[r].add(self._new_object(hists[r]))
        return [frozenset(o) for o in owners]

    def _check_fragments(self) -> None:
        """Fragments of one object that stop being coherent become separate objects (A5 edge case: a bag)."""
        p = self.params
        by_owner: dict[frozenset[int], list[_Node]] = {}
        for n in self._nodes.values():
            if n.alive and n.split < 0 and n.label == NodeLabel.FRAGMENT and n.missed == 0:
                by_owner.setdefault(n.members, []).append(n)
        for owner, nodes in by_owner.items():
            if len(nodes) < 2 or self._frame % p.window:
                continue
            clusters = self._clusters(nodes)
            if len(clusters) == 1:
                continue
            clusters.sort(key=lambda c: -sum(float(np.prod(n.size)) for n in c))
            for i, c in enumerate(clusters):
                own = owner if i == 0 else frozenset({self._new_object(self._cluster_hist(c))})
                for n in c:
                    n.members = own
                    n.label = NodeLabel.OBJECT if len(c) == 1 else NodeLabel.FRAGMENT

    @property
    def area_law(self) -> AreaLaw | None:
        """The learnt straight line ``A_p(v)``, None until enough single objects spread over rows were seen."""
        p = self.params
        if self._n_sized - self._n_fitted >= p.window or (self._law is None and self._n_sized > self._n_fitted):
            self._n_fitted = self._n_sized
            if len(self._sizes) >= p.size_samples:
                v, a = np.array(self._sizes).T
                self._law = fit_person_area(v, a, min_samples=p.size_samples, min_spread_px=p.size_spread_px)
        return self._law

    def expected_area(self, v_bottom_px: np.ndarray) -> np.ndarray:
        """A5's size prior ``A_p(v)``: one person's box area at bottom rows ``v`` (px²); NaN where unknown.

        The learnt line (:attr:`area_law`) where it is valid, else the camera's a-priori area, else NaN.
        """
        v = np.asarray(v_bottom_px, np.float64)
        law = self.area_law
        out = np.full(v.shape, np.nan) if law is None else law(v)
        if self._prior is not None:
            rows, areas = self._prior
            prior = np.interp(v, rows, areas, left=np.nan, right=np.nan)
            out = np.where(np.isfinite(out), out, prior)
        return out

    def n_hat(self, boxes_px: np.ndarray) -> np.ndarray:
        """``n̂ = area / A_p(v_bottom)`` of boxes ``(n, 4)``: how many people they hold; NaN where ``A_p`` is unknown."""
        b = np.asarray(boxes_px, np.float64).reshape(-1, 4)
        return _box_area(b) / self.expected_area(b[:, 3])

    def _camera_prior(self, camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray] | None:
        """Projected box area of an upright person whose feet are at row ``v`` of the central column."""
        p = self.params
        rows = np.arange(0.0, camera.height + 1.0, 2.0)
        feet = camera.backproject_to_floor(np.column_stack([np.full(rows.size, camera.K[0, 2]), rows]))
        ok = np.all(np.isfinite(feet), axis=1)
        if not ok.any():
            log.warning("camera %dx%d sees no floor: no a-priori person size", camera.width, camera.height)
            return None
        boxes = camera.person_box(feet[ok, :2], p.person_height_m, p.person_width_ratio)
        boxes = np.clip(boxes, 0.0, [camera.width, camera.height, camera.width, camera.height])
        area = _box_area(boxes)
        good = np.isfinite(area) & (area > 0)
        if good.sum() < 2:
            return None
        return rows[ok][good], area[good]

    def _union_box(self, nodes: list[_Node]) -> np.ndarray:
        boxes = np.array([n.history[-1][2] if n.missed == 0 else n.box() for n in nodes])
        return np.concatenate([boxes[:, :2].min(axis=0), boxes[:, 2:].max(axis=0)])

    def _is_crowd(self, box: np.ndarray) -> bool:
        """A5 §4's ``n̂ >= group_n_hat`` (False while ``A_p`` is unknown or the rule is off)."""
        g = self.params.group_n_hat
        return g > 0 and bool(self.n_hat(box)[0] >= g)

    def _placeholder(self, hist: np.ndarray | None) -> int:
        oid = self._new_object(hist)
        self._placeholders.add(oid)
        return oid

    def _size_prior(self) -> None:
        """Learn ``A_p`` from confirmed single objects; collapse groups that stay one person's size (A5 §3)."""
        p = self.params
        for owner, nodes in self._owners().items():
            seen = [n for n in nodes if n.missed == 0]
            if not seen:
                continue
            box = self._union_box(seen)
            area = float(_box_area(box))
            if len(owner) == 1 and not owner & self._placeholders \
                    and all(n.label == NodeLabel.OBJECT and n.n_seen >= p.window for n in nodes):
                self._sizes.append((float(box[3]), area))
                self._n_sized += 1
                continue
            if p.group_collapse <= 0 or (len(owner) == 1 and not owner & self._placeholders):
                continue
            expected = float(self.expected_area(np.array([box[3]]))[0])
            if not np.isfinite(expected):
                continue
            small = area < p.group_collapse * expected
            for n in nodes:
                n.small = n.small + 1 if small else 0
            if min(n.small for n in nodes) >= p.window:
                hist = self._cluster_hist(nodes)
                real = sorted(owner - self._placeholders) or sorted(owner)
                keep = min(real, key=lambda m: _bc_cost(hist, self._object_hist.get(m)))
                log.debug("frame %d: group %s has one person's size; keeps %d", self._frame, sorted(owner), keep)
                self._placeholders.discard(keep)
                for n in nodes:
                    n.members = frozenset({keep})
                    n.label = NodeLabel.OBJECT if len(nodes) == 1 else NodeLabel.FRAGMENT
                    n.small = 0

    # -- output -------------------------------------------------------------------------------------

    def _owners(self) -> dict[frozenset[int], list[_Node]]:
        by_owner: dict[frozenset[int], list[_Node]] = {}
        for n in self._nodes.values():
            if n.alive and n.members:
                by_owner.setdefault(n.members, []).append(n)
        return by_owner

    def _dedupe(self) -> None:
        """An object seen alone (a node set that is just it) is no longer a member of any other node's set.

        Pieces of a pending split all carry their parent's members; when one piece merges with someone else
        and the other is later resolved, an id can sit in two sets. A set left empty is a new object.
        """
        by_owner = self._owners()
        alone = {next(iter(o)) for o, nodes in by_owner.items() if len(o) == 1 and any(n.missed == 0 for n in nodes)}
        for owner, nodes in by_owner.items():
            if len(owner) > 1 and owner & alone:
                rest = owner - alone
                if not rest:
                    rest = frozenset({self._new_object(self._cluster_hist(nodes))})
                for n in nodes:
                    n.members = rest
                    if len(rest) == 1 and n.label == NodeLabel.GROUP and not rest & self._placeholders:
                        n.label = NodeLabel.OBJECT if len(nodes) == 1 else NodeLabel.FRAGMENT

    def _output(self) -> list[TrackedObject]:
        """One record per object: from the smallest node set that claims it (then the most recently seen)."""
        p = self.params
        self._dedupe()
        by_owner = self._owners()
        best: dict[int, tuple[tuple[int, int], frozenset[int]]] = {}
        for owner, nodes in by_owner.items():
            key = (len(owner), min(n.missed for n in nodes))
            for oid in owner:
                if oid not in best or key < best[oid][0]:
                    best[oid] = (key, owner)
        out = []
        for oid, (_, owner) in best.items():
            nodes = by_owner[owner]
            if max(n.n_seen for n in nodes) < p.n_confirm:
                continue
            box = self._union_box([n for n in nodes if n.missed == 0] or nodes)
            unknown = owner & self._placeholders
            group = len(owner) > 1 or bool(unknown)
            gid = min(n.node_id for n in nodes) if group else -1
            size = len(owner)
            if unknown:  # a placeholder stands for two or more people
                n_hat = float(self.n_hat(box)[0])
                size = max(size + len(unknown), round(n_hat) if np.isfinite(n_hat) else 0)
            out.append(TrackedObject(oid, box, group, gid, min(n.missed for n in nodes), size, not unknown))
        return sorted(out, key=lambda o: o.object_id)
