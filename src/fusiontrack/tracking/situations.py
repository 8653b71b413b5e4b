"""The tracking-situation switch of seed 001, as per-frame decisions on arrays (ALGORITHMS.md B7).

:func:`classify_situations` takes the association states of one frame (B6: ``c``, ``r``, ``found``)
plus what only the tracker knows (which targets are merged targets, which targets and detections lie
on the edge of the covered area) and applies B7's rules in order. It holds no state: confirmation
and miss counters (``N_confirm = 3``, ``N_confirm' = 10``, ``N_miss = 25``), the creation of merged
targets and the suspension of their members are the tracker's job; this module says, for this
frame, which rule fires for every target and every detection.

The targets passed in are the *active* ones: ordinary targets and merged targets M, not the
suspended members of an M.

Rules (B7), evaluated in this order:

1. **Merge** — detection j with ``r_j = 2`` whose gating targets all have ``c_k = 1``: those targets
   are ``MERGING`` into one merged target (group keyed by j). A merged target can be one of them
   (a third person joins): the tracker unites the memberships.
2. **Split** — a merged target with ``c = 2`` whose gated detections all have ``r = 1``: ``SPLITTING``
   (identity recovery, B17). A *non-merged* target in that position is not a split: it keeps its
   nearest detection and its other detections are ``SPLIT_CANDIDATE`` (new targets once they
   persist ``N_confirm`` frames). So are those found by it alone (``r = 1``) when another of its detections
   is shared (``r = 2``) [RECON completion: otherwise a person walking beside a correlated pair, whose segment
   lies only in the gate of a target that keeps its nearest detection, is never assigned and never born].
3. **Correlated** — a non-merged target with ``c = 2``: ``CORRELATED`` (B16). So is a non-merged
   target with ``c = 1`` whose detection is shared with a target that found two (rule 1 does not
   fire, rule 4 does not apply; it interacts with that target) [RECON completion].
4. **Noncorrelated** — ``c = 1`` and its detection has ``r = 1``: ``NONCORRELATED`` (B10). A merged
   target with ``c >= 1`` that neither merges nor splits stays ``MERGED``.
5. **Disappear** — ``c = 0`` on the edge: ``DISAPPEARING``; ``c = 0`` elsewhere: ``COASTING``
   (predict only, for up to ``N_miss`` frames).
6. **Appear** — a detection with ``r = 0``: ``APPEAR_EDGE`` on the edge (new target after
   ``N_confirm = 3`` frames), ``APPEAR_INTERIOR`` elsewhere (after ``N_confirm' = 10``).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from ..types import Situation

__all__ = [
    "SITUATION_OF_LABEL",
    "DetectionLabel",
    "SituationFrame",
    "TargetLabel",
    "boundary_distance",
    "classify_situations",
    "on_edge",
]


class TargetLabel(enum.IntEnum):
    """What B7 decides for a target this frame."""

    NONCORRELATED = 0  # rule 4 -> laser PF (B10)
    CORRELATED = 1  # rule 3 -> score-map PF (B16)
    MERGING = 2  # rule 1 -> joins a merged target (B17)
    MERGED = 3  # a merged target that stays merged
    SPLITTING = 4  # rule 2 -> identity recovery (B17)
    COASTING = 5  # rule 5, away from the edge -> prediction only, up to N_miss frames
    DISAPPEARING = 6  # rule 5, on the edge -> save the state and stop tracking


class DetectionLabel(enum.IntEnum):
    """What B7 decides for a detection this frame."""

    MATCHED = 0  # r = 1
    SHARED = 1  # r = 2
    APPEAR_EDGE = 2  # rule 6: r = 0 on the edge -> new target after N_confirm = 3 frames
    APPEAR_INTERIOR = 3  # rule 6: r = 0 elsewhere -> new target after N_confirm' = 10 frames
    SPLIT_CANDIDATE = 4  # rule 2 note: extra detection of a non-merged target -> new target after N_confirm


SITUATION_OF_LABEL: dict[TargetLabel, Situation] = {
    TargetLabel.NONCORRELATED: Situation.NONCORRELATED,
    TargetLabel.CORRELATED: Situation.CORRELATED,
    TargetLabel.MERGING: Situation.MERGED,
    TargetLabel.MERGED: Situation.MERGED,
    # a merged target whose gate holds two detections, each its own: the people in it interact, each seen (B7
    # rule 3's situation) while the split waits to be sure (n_split, split_min_m)
    TargetLabel.SPLITTING: Situation.CORRELATED,
    TargetLabel.COASTING: Situation.NONCORRELATED,  # an occluded loner; not an interaction
    TargetLabel.DISAPPEARING: Situation.DISAPPEARING,
}


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, slots=True, eq=False)
class SituationFrame:
    """B7's decisions for one frame.

    Attributes
    ----------
    target_labels : (n_t,) int8
        :class:`TargetLabel` codes.
    det_labels : (n_d,) int8
        :class:`DetectionLabel` codes.
    merge_det : (n_t,) int64
        For a ``MERGING`` target, the shared detection it merges into; ``-1`` otherwise. Targets with
        the same value form one merge group.
    nearest_det : (n_t,) int64
        The nearest detection the target found (B10's nearest neighbour; for ``CORRELATED`` targets
        a hint only), ``-1`` when ``c = 0``.
    found : (n_t, n_d) bool
        The gate matrix the decisions were made from (a ``SPLITTING`` target's detections are its row).
    """

    target_labels: np.ndarray
    det_labels: np.ndarray
    merge_det: np.ndarray
    nearest_det: np.ndarray
    found: np.ndarray

    @property
    def merge_groups(self) -> dict[int, np.ndarray]:
        """``{shared detection: member target indices (sorted)}`` for every merge this frame."""
        on = self.merge_det >= 0
        if not np.count_nonzero(on):  # the usual frame: no merge (np.unique is slow on tiny arrays)
            return {}
        dets = np.unique(self.merge_det[on])
        return {int(j): np.flatnonzero(self.merge_det == j) for j in dets}

    @property
    def splitting(self) -> np.ndarray:
        """Indices of the merged targets that split this frame."""
        return np.flatnonzero(self.target_labels == TargetLabel.SPLITTING)

    @property
    def split_candidates(self) -> np.ndarray:
        """Indices of detections that may become new targets by splitting off an unmerged target."""
        return (self.det_labels == _D_SPLIT_CANDIDATE).nonzero()[0]

    @property
    def appear_candidates(self) -> np.ndarray:
        """Indices of detections nobody found (on the edge or inside)."""
        return np.flatnonzero((self.det_labels == DetectionLabel.APPEAR_EDGE)
                              | (self.det_labels == DetectionLabel.APPEAR_INTERIOR))

    def situations(self) -> list[str]:
        """Each target's :class:`~fusiontrack.types.Situation` (for ``TrackState.situation``)."""
        return [str(SITUATION_OF_LABEL[TargetLabel(int(v))]) for v in self.target_labels]


def classify_situations(c: np.ndarray, r: np.ndarray, found: np.ndarray, merged_mask: np.ndarray,
                        on_edge_targets: np.ndarray, on_edge_dets: np.ndarray,
                        D: np.ndarray | None = None) -> SituationFrame:
    """Apply B7's ordered rules to one frame (module docstring for the rules).

    Parameters
    ----------
    c : (n_t,) int
        Detections found per target, capped at 2 (B6).
    r : (n_d,) int
        Targets that found each detection, capped at 2 (B6).
    found : (n_t, n_d) bool
        ``D_kj < G``.
    merged_mask : (n_t,) bool
        Which targets are merged targets M.
    on_edge_targets : (n_t,) bool
        Predicted centre within ``d_edge`` of the boundary (:func:`on_edge`).
    on_edge_dets : (n_d,) bool
        Detection centre within ``d_edge`` of the boundary.
    D : (n_t, n_d) float, optional
        Gate distances, to choose the nearest detection; without them the first found one is used.

    Returns
    -------
    SituationFrame
    """
    fnd = np.asarray(found, dtype=bool)
    if fnd.ndim != 2:
        raise ValueError(f"found: expected shape (n_t, n_d), got {fnd.shape}")
    n_t, n_d = fnd.shape
    cc = np.asarray(c, dtype=np.int64).reshape(-1)
    rr = np.asarray(r, dtype=np.int64).reshape(-1)
    merged = np.asarray(merged_mask, dtype=bool).reshape(-1)
    edge_t = np.asarray(on_edge_targets, dtype=bool).reshape(-1)
    edge_d = np.asarray(on_edge_dets, dtype=bool).reshape(-1)
    for name, arr, n in (("c", cc, n_t), ("merged_mask", merged, n_t), ("on_edge_targets", edge_t, n_t),
                         ("r", rr, n_d), ("on_edge_dets", edge_d, n_d)):
        if arr.shape != (n,):
            raise ValueError(f"{name}: expected shape ({n},) to match found {fnd.shape}, got {arr.shape}")

    # The matrix work in numpy, the per-target and per-detection rules in plain Python over lists (a frame holds
    # a few targets and detections: cheaper than ~50 numpy calls on tiny arrays; the same integers).
    if n_d:
        dist = np.where(fnd, 0.0, np.inf) if D is None else np.where(fnd, np.asarray(D, dtype=np.float64), np.inf)
        nearest_l = dist.argmin(axis=1).tolist()
    else:
        nearest_l = [-1] * n_t
    c_l, r_l = cc.tolist(), rr.tolist()
    for i in range(n_t):
        if not c_l[i] > 0:
            nearest_l[i] = -1
    # rule 1: a shared detection whose gating targets all found only it
    # (such targets have c = 1: one detection each)
    # (no detection found by two targets, the usual frame: no merge)
    if 2 in r_l:
        merge_at = (rr == 2) & ~np.logical_or.reduce(fnd[cc != 1], axis=0) if c_l.count(1) != n_t else rr == 2
        merging = np.logical_or.reduce(fnd[:, merge_at], axis=1).tolist() if np.count_nonzero(merge_at) \
            else [False] * n_t
    else:
        merging = [False] * n_t
    # rule 2: every gated detection found by this target alone (read for targets with c = 2 only)
    all_r1 = (~np.logical_or.reduce(fnd[:, rr != 1], axis=1)).tolist() if 2 in c_l else [False] * n_t
    merged_l, edge_t_l = merged.tolist(), edge_t.tolist()
    labels_l = [0] * n_t
    merge_det_l = [-1] * n_t
    apart_rows = []
    for i in range(n_t):
        ci = c_l[i]
        if ci == 0:  # rule 5 (the last assignment of the rules' order wins)
            lab = _T_DISAPPEARING if edge_t_l[i] else _T_COASTING
        elif merging[i]:
            lab = _T_MERGING
        elif merged_l[i]:
            lab = _T_SPLITTING if ci == 2 and all_r1[i] else _T_MERGED
        elif ci == 1 and n_d and r_l[nearest_l[i]] == 1:  # rule 4: one detection, found by nobody else
            lab = _T_NONCORRELATED
        else:  # rule 3 and its completion
            lab = _T_CORRELATED
        if ci == 2 and not merged_l[i]:  # unmerged, c = 2: not a split; its other detections found by it alone
            apart_rows.append(i)
        labels_l[i] = lab
        if merging[i]:
            merge_det_l[i] = nearest_l[i]
    labels = np.array(labels_l, dtype=np.int8)
    nearest = np.array(nearest_l, dtype=np.int64)
    merge_det = np.array(merge_det_l, dtype=np.int64)

    edge_d_l = edge_d.tolist()
    det_l = [_D_MATCHED] * n_d
    for j in range(n_d):
        rj = r_l[j]
        if rj == 0:
            det_l[j] = _D_APPEAR_EDGE if edge_d_l[j] else _D_APPEAR_INTERIOR
        elif rj == 2:
            det_l[j] = _D_SHARED
    if apart_rows:
        extra = np.logical_or.reduce(fnd[apart_rows], axis=0).tolist()
        for i in apart_rows:
            extra[nearest_l[i]] = False
        for j in range(n_d):
            if extra[j] and r_l[j] == 1:
                det_l[j] = _D_SPLIT_CANDIDATE
    det_labels = np.array(det_l, dtype=np.int8)
    # (the frozen dataclass's own constructor sets each field through object.__setattr__: slower than the slots')
    frame = object.__new__(SituationFrame)
    for set_field, value in zip(_FRAME_SETTERS, (labels, det_labels, merge_det, nearest, fnd.copy()), strict=True):
        set_field(frame, _frozen(value))
    return frame


_FRAME_SETTERS = tuple(SituationFrame.__dict__[name].__set__
                       for name in ("target_labels", "det_labels", "merge_det", "nearest_det", "found"))
assert len(_FRAME_SETTERS) == len(SituationFrame.__slots__)  # every field is set

_T_NONCORRELATED, _T_CORRELATED, _T_MERGING, _T_MERGED, _T_SPLITTING, _T_COASTING, _T_DISAPPEARING = (
    int(TargetLabel.NONCORRELATED), int(TargetLabel.CORRELATED), int(TargetLabel.MERGING), int(TargetLabel.MERGED),
    int(TargetLabel.SPLITTING), int(TargetLabel.COASTING), int(TargetLabel.DISAPPEARING))
_D_MATCHED, _D_SHARED, _D_APPEAR_EDGE, _D_APPEAR_INTERIOR, _D_SPLIT_CANDIDATE = (
    int(DetectionLabel.MATCHED), int(DetectionLabel.SHARED), int(DetectionLabel.APPEAR_EDGE),
    int(DetectionLabel.APPEAR_INTERIOR), int(DetectionLabel.SPLIT_CANDIDATE))


def boundary_distance(points_m: np.ndarray, polygon_m: np.ndarray) -> np.ndarray:
    """Signed distance from points to the boundary of the covered area: positive inside, negative outside.

    Parameters
    ----------
    points_m : (n, 2) float
    polygon_m : (m, 2) float
        Vertices of a simple polygon in order (either orientation; not closed: the last vertex
        joins the first). A rectangle ``(x0, y0, x1, y1)`` is ``[[x0, y0], [x1, y0], [x1, y1], [x0, y1]]``.

    Returns
    -------
    distance_m : (n,) float64
    """
    p = np.asarray(points_m, dtype=np.float64).reshape(-1, 2)
    a = np.asarray(polygon_m, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 2 or a.shape[0] < 3:
        raise ValueError(f"polygon_m: expected (m >= 3, 2) vertices, got {a.shape}")
    b = np.roll(a, -1, axis=0)
    ab = b - a  # (m, 2)
    ap = p[:, None, :] - a[None, :, :]  # (n, m, 2)
    len2 = np.einsum("mk,mk->m", ab, ab)
    t = np.clip(np.einsum("nmk,mk->nm", ap, ab) / np.where(len2 > 0, len2, 1.0), 0.0, 1.0)
    closest = ap - t[..., None] * ab
    dist = np.sqrt(np.einsum("nmk,nmk->nm", closest, closest).min(axis=1))
    # even-odd ray casting towards +x
    py = p[:, 1:2]
    crosses = (a[None, :, 1] > py) != (b[None, :, 1] > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = a[None, :, 0] + (py - a[None, :, 1]) * ab[None, :, 0] / ab[None, :, 1]
    inside = (np.count_nonzero(crosses & (p[:, 0:1] < x_cross), axis=1) % 2) == 1
    return np.where(inside, dist, -dist)


def on_edge(points_m: np.ndarray, polygon_m: np.ndarray, d_edge_m: float = 0.5) -> np.ndarray:
    """True for points within ``d_edge_m`` of the boundary or outside it (B7 rules 5-6), ``(n,)`` bool."""
    return boundary_distance(points_m, polygon_m) < d_edge_m
