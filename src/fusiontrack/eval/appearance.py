"""How well seed 001's appearance classifiers tell people apart in a video, without annotated identities.

The fused tracker trusts its per-target classifiers (B14, B15) to say, after two people met, whether their tracks
still follow the same people (the identity checks) and who a reborn track is (re-identification). Whether they can
depends on the camera: its resolution, the light, the people's clothes. :func:`neighbour_evidence` measures it on a
video with person detections (e.g. MOTChallenge's public ones) the way the fused tracker uses the classifiers:

* identities come from :func:`iou_tracklets`: a detection continues a tracklet of the previous frame only where the
  link is unambiguous (mutual best overlap, well ahead of the second best); wherever it is not, a new tracklet
  starts. A tracklet thus cuts one person's path into pieces, and seldom joins two people: on annotated boxes
  (MOTChallenge ground truth: TUD-Campus, TUD-Stadtmitte, MOT17-05, -09, -11) 9 of 3658 tracklets hold two people,
  where small people walk one behind the other faster than half a box per frame. It is a truth the classifiers
  have no part in, and its rare mistakes count against them (a classifier scoring its "own" box with somebody else
  in it);
* test then train, frame by frame: every ``test_every`` frames each trained target whose box is clear (at most
  ``max_overlap`` of it inside another box) scores its own box and the clear boxes of its neighbours (bottom centres
  within ``near`` box heights); its *evidence* is its confidence on its own box minus that on the neighbour's, in
  ``[-2, 2]``, positive when it tells them apart the right way round (the identity checks' evidence,
  :class:`~fusiontrack.fusion.FusionParams`). Then the targets with a neighbour learn (B15's rule, in the image),
  each at most every ``train_every`` frames, with the neighbours as negatives.

:meth:`NeighbourEvidence.verdicts` turns the evidence into the verdicts identity checks would give.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ..io.tracks import MotBoxes
from ..vision.appearance import AppearanceBank, AppearanceParams
from ..vision.people import box_containment, box_iou

__all__ = ["NeighbourEvidence", "iou_tracklets", "neighbour_evidence"]


def iou_tracklets(frame: np.ndarray, boxes_xyxy: np.ndarray, *, min_iou: float = 0.3, ratio: float = 0.5
                  ) -> np.ndarray:
    """Tracklet ids ``(n,) int64`` of detections (rows in any order) linked only where the link is unambiguous.

    A detection of frame ``f`` continues the tracklet of a detection of frame ``f - 1`` when their overlap (IoU) is
    at least ``min_iou`` and each one's second best is below ``ratio`` times it (so each is the other's best);
    otherwise it starts a tracklet (after a frame without detections, every detection does). Ids are numbered from
    0 in order of appearance.
    """
    if not 0 < min_iou <= 1:
        raise ValueError(f"min_iou: expected a value in (0, 1], got {min_iou!r}")
    if not 0 < ratio <= 1:
        raise ValueError(f"ratio: expected a value in (0, 1], got {ratio!r}")
    try:
        raw = np.asarray(frame, np.float64)
        boxes = np.asarray(boxes_xyxy, np.float64).reshape(-1, 4)
    except (TypeError, ValueError) as err:
        raise ValueError(f"frame, boxes_xyxy: expected numbers ({err})") from None
    if raw.ndim != 1:
        raise ValueError(f"frame: expected a 1-D array of frame numbers, got shape {raw.shape}")
    bad = ~(np.isfinite(raw) & (raw == np.round(raw)))
    if bad.any():
        raise ValueError(f"frame: expected whole frame numbers, got {float(raw[bad][0])!r} (row {int(np.argmax(bad))})")
    frame = raw.astype(np.int64)
    if len(frame) != len(boxes):
        raise ValueError(f"frame and boxes_xyxy: expected as many rows, got {len(frame)} and {len(boxes)}")
    out = np.full(len(frame), -1, np.int64)
    if not len(frame):
        return out
    order = np.argsort(frame, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(frame[order]) != 0, True])
    next_id = 0
    prev_rows, prev_frame = np.empty(0, np.int64), None
    for lo, hi in itertools.pairwise(starts):
        rows = order[lo:hi]
        f = int(frame[rows[0]])
        if prev_frame == f - 1 and len(prev_rows):
            iou = box_iou(boxes[prev_rows], boxes[rows])  # (previous, current)
            best_prev = iou.argmax(axis=0)
            top = np.sort(iou, axis=0)[::-1]
            second_cur = top[1] if len(prev_rows) > 1 else np.zeros(len(rows))
            side = np.sort(iou, axis=1)[:, ::-1]
            second_prev = side[:, 1] if len(rows) > 1 else np.zeros(len(prev_rows))
            for j in range(len(rows)):
                i = best_prev[j]
                v = iou[i, j]
                # (with ``ratio`` <= 1, ``i``'s second best below ``ratio * v`` makes ``j`` its best)
                if v >= min_iou and second_cur[j] < ratio * v and second_prev[i] < ratio * v:
                    out[rows[j]] = out[prev_rows[i]]
        for r in rows:
            if out[r] < 0:
                out[r] = next_id
                next_id += 1
        prev_rows, prev_frame = rows, f
    return out


@dataclass(frozen=True)
class NeighbourEvidence:
    """The scores of :func:`neighbour_evidence`, one row per (target, neighbour, frame) scored.

    Attributes
    ----------
    evidence : (n,) float64
        Own box's confidence minus the neighbour's box's, by the target's classifier, in ``[-2, 2]``.
    frame, target, neighbour : (n,) int64
        The frame and the two tracklets.
    frames, tracklets, detections : int
        Frames read, tracklets in them and their detections (boxes given).
    dropped : int
        Detections in the frames read whose box was empty or not finite (left out).
    """

    evidence: np.ndarray
    frame: np.ndarray
    target: np.ndarray
    neighbour: np.ndarray
    frames: int = 0
    tracklets: int = 0
    detections: int = 0
    dropped: int = 0

    def right_sign(self) -> float:
        """The share of scores with evidence > 0 (NaN without scores)."""
        return float(np.mean(self.evidence > 0)) if self.evidence.size else float("nan")

    def verdicts(self, n: int = 3, margin: float = 0.6) -> dict[str, int]:
        """The verdicts identity checks would give, one per pair of neighbours scored on at least ``n`` frames.

        Frame by frame, the mean evidence of the two classifiers that scored (each its own box against the other's);
        from the ``n``-th frame on, the first time the running mean of those is at least ``margin`` away from 0:
        ``keep`` if above (right), ``exchange`` if below (wrong: the pair was never exchanged); else ``undecided``.
        (A check of the fused tracker also waits for the pair's closest approach and is asked again at later
        contacts: this is its first decision over the whole video.)"""
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
            raise ValueError(f"n: expected an integer >= 1, got {n!r}")
        if not margin >= 0:
            raise ValueError(f"margin: expected a value >= 0, got {margin!r}")
        out = {"keep": 0, "exchange": 0, "undecided": 0}
        if not self.evidence.size:
            return out
        lo, hi = np.minimum(self.target, self.neighbour), np.maximum(self.target, self.neighbour)
        key = np.stack([lo, hi, self.frame], axis=1)
        cells, inverse = np.unique(key, axis=0, return_inverse=True)  # (pair, frame), sorted by pair then frame
        inverse = inverse.ravel()
        per_frame = np.bincount(inverse, self.evidence) / np.bincount(inverse)
        starts = np.flatnonzero(np.r_[True, (np.diff(cells[:, :2], axis=0) != 0).any(axis=1)])
        for a, b in itertools.pairwise(np.r_[starts, len(cells)]):
            if b - a < n:
                continue  # (never scored on n frames: no verdict to count)
            running = np.cumsum(per_frame[a:b]) / np.arange(1, b - a + 1)
            beyond = np.flatnonzero(np.abs(running[n - 1:]) >= margin)
            if not beyond.size:
                out["undecided"] += 1
            else:
                r = running[n - 1 + beyond[0]]
                out["keep" if r > 0 else "exchange" if r < 0 else "undecided"] += 1
        return out


def neighbour_evidence(images: Iterable[tuple[int, np.ndarray]], detections: MotBoxes, *,
                       params: AppearanceParams | None = None, rng: int | None = 0, near: float = 1.5,
                       max_overlap: float = 0.3, test_every: int = 3, train_every: int = 2,
                       min_iou: float = 0.3) -> NeighbourEvidence:
    """Test-then-train evidence of seed 001's classifiers on a video (module docstring).

    Parameters
    ----------
    images : iterable of (frame, BGR image)
        The video's frames, numbered as ``detections`` number them, in order.
    detections : MotBoxes
        Person boxes in those images' pixels (``MotBoxes.scaled`` to resize).
    params, rng :
        Of the :class:`~fusiontrack.vision.appearance.AppearanceBank`.
    near, max_overlap, test_every, train_every, min_iou : see the module docstring (``min_iou``: of
        :func:`iou_tracklets`).
    """
    boxes_all = detections.boxes_xyxy
    size = boxes_all[:, 2:] - boxes_all[:, :2]
    usable = np.isfinite(boxes_all).all(axis=1) & (size > 0).all(axis=1)  # (an empty box has no patch to learn)
    ids_all = np.full(len(boxes_all), -1, np.int64)
    ids_all[usable] = iou_tracklets(detections.frame[usable], boxes_all[usable], min_iou=min_iou)
    last_frame: dict[int, int] = {}  # tracklet -> its last frame (its classifier is dropped after it)
    for t, f in zip(ids_all[usable].tolist(), detections.frame[usable].tolist(), strict=True):
        last_frame[t] = max(f, last_frame.get(t, f))
    bank = AppearanceBank(params or AppearanceParams(), rng=rng)
    last_train: dict[int, int] = {}
    ev: list[float] = []
    meta: list[tuple[int, int, int]] = []
    seen: set[int] = set()
    n_frames = n_det = n_dropped = 0
    for f, img in images:
        n_frames += 1
        rows = detections.rows_at(int(f))
        n_det += len(rows)
        n_dropped += int(np.count_nonzero(~usable[rows]))
        rows = rows[usable[rows]]
        b, ids = boxes_all[rows], ids_all[rows]
        seen.update(ids.tolist())
        if len(rows) >= 2:
            _test_and_train(int(f), img, b, ids, bank, last_train, ev, meta, near=near, max_overlap=max_overlap,
                            test_every=test_every, train_every=train_every)
        ended = [t for t in ids.tolist() if last_frame[t] <= int(f)]  # (a tracklet never resumes)
        if ended:
            bank.drop(ended)
            for t in ended:
                last_train.pop(t, None)
    m = np.array(meta, np.int64).reshape(-1, 3)
    return NeighbourEvidence(np.array(ev, np.float64), m[:, 0], m[:, 1], m[:, 2], frames=n_frames,
                             tracklets=len(seen), detections=n_det, dropped=n_dropped)


def _test_and_train(f: int, img: np.ndarray, b: np.ndarray, ids: np.ndarray, bank: AppearanceBank,
                last_train: dict[int, int], ev: list[float], meta: list[tuple[int, int, int]], *, near: float,
                max_overlap: float, test_every: int, train_every: int) -> None:
    """One frame of :func:`neighbour_evidence`: score (every ``test_every`` frames), then learn."""
    bottom = np.column_stack([(b[:, 0] + b[:, 2]) / 2, b[:, 3]])
    h = b[:, 3] - b[:, 1]
    close = np.linalg.norm(bottom[:, None] - bottom[None], axis=2) < near * np.maximum(h[:, None], h[None])
    np.fill_diagonal(close, False)
    inside = box_containment(b, b)
    np.fill_diagonal(inside, 0.0)
    clear = inside.max(axis=1) <= max_overlap
    if f % test_every == 0:
        for k in np.flatnonzero(clear):
            tid = int(ids[k])
            others = np.flatnonzero(close[k] & clear)
            if not others.size or not bank.is_trained(tid):
                continue
            sc = bank.box_scores(img, b[np.r_[k, others]], [tid])[:, 0]
            for j, v in zip(others, sc[1:], strict=True):
                if np.isfinite(sc[0] - v):
                    ev.append(float(sc[0] - v))
                    meta.append((f, tid, int(ids[j])))
    learners = [int(ids[k]) for k in np.flatnonzero(close.any(axis=1))
                if f - last_train.get(int(ids[k]), -(1 << 30)) >= train_every]
    if learners:
        bank.train(img, {int(t): b[k] for k, t in enumerate(ids)}, train_ids=learners,
                   force_update=any(not bank.is_trained(t) for t in learners))
        last_train.update((t, f) for t in learners)
