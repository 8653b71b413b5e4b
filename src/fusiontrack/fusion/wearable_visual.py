"""The visual side of the ``wearable`` pipeline: one compressive tracker per (person, camera), checked by the
person's corrected inertial position projected into the image (seed 002; ALGORITHMS.md C9-C12).

Projection (C9): Eq. 9's P of every camera is the floor-to-image homography of its calibration at torso height
(half the person height), with ``Σ = base_sigma_px² I``. With ``c9_refit`` (off by default) P is also fitted
from aligned pairs as C9 describes: while trackers in that camera are trusted (``ok`` for ``c9_min_ok_frames``
frames in a row, consistent), pairs (box centre, corrected inertial position) are collected and P is refitted
by :func:`fusiontrack.inertial.fit_inertial_projection` (RANSAC + DLT) each time the pairs have grown by half,
once their floor positions spread over an area (a straight walk leaves P undetermined across it). The fit
replaces the current P when it predicts the held-out half of the pairs clearly better and stays within
``c9_max_shift_px`` of the calibration over the pairs (further away, the pairs came from a tracker on the wrong
target). It is off by default because on calibrated cameras it did not help: the calibrated P is exact in
simulation, and fits on pairs from part of the image extrapolated badly to the rest (people near the border
went "out of view").

C11's Σ at a frame is the fit's residual covariance plus the person's position uncertainty projected through
P's Jacobian (:meth:`~fusiontrack.inertial.projection.InertialProjection.image_cov_px2`); that uncertainty grows
with the distance walked since the latest RGB-D fix but is capped at ``max_sigma_m`` [RECON]: with the full
inflation a compressive tracker drifting 20-35 px off a person in the dark still passed the test and learnt
the background (benchmarks/wearable.py, lights scene: 6 of 12 failures recovered within 1 s, 9 with the cap).

Start: a person is tracked in a camera once placed in the world with a standard deviation below
``max_start_sigma_m``, when the box predicted from their position (calibrated camera, ``person_height_m``) lies
inside the image at a usable size, overlaps nobody else's predicted box, and a moving-foreground blob (OpenCV's
MOG2, shadows dropped) of about that size lies near it: the tracker starts on that blob's box [RECON; P002
starts its trackers by hand]. The CT box keeps its size (C10); the reported box keeps the CT centre and scales
with the predicted box height (the inertial distance to the camera), and when that scale has changed by more
than ``rescale_after`` while the tracker is consistent and the person clear of others, a new tracker starts on
the rescaled box [RECON: CT has no scale estimation].

Per frame (:class:`fusiontrack.vision.compressive.MultiTemplateTracker`): C11's test, and on failure the C12
reset to the projected position with the best stored template. Then the person's own foreground blob, when one
is found (:func:`_person_blob`: the size the inertial distance predicts, its bottom where the predicted feet
are, no wider than a person, its centre inside the tracker's box, nobody else's predicted box on it), gives
the reported box, and the CT is put back on its centre when it is failing or recovering, or has drifted from it
by more than ``recentre_fraction`` of its width [RECON, ``refine``]. CT keeps the size of its first box while a
walking person's silhouette widens and narrows with the gait and the body's turn; with the fixed-size box the
issue's recovery test (IoU >= 0.5 with the truth on 3 frames within 1 s of a failure's end) failed on 6 of 28
injected failures, with the blob on none (``benchmarks/wearable.py``, 3 seeds x 3 scenes).

Episodes from the first failure to the next ``ok`` frame become ``visual_failure`` events and their ends
``visual_recovery`` events. A tracker ends when its projection has been out of the image for ``out_of_view_s``;
without inertial data (a silent phone) it runs as plain CT, flagged ``no_inertial``. Optionally a plain
compressive tracker (the visual-only baseline) runs beside each fused one from the same box.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from ..errors import CalibrationError
from ..geometry import PinholeCamera, invert_transform
from ..inertial.projection import InertialProjection, ProjectionParams, fit_inertial_projection
from ..io.recording import Recording
from ..types import Event, Image
from ..vision.blobs import BlobParams, extract_blobs
from ..vision.compressive import CompressiveParams, CompressiveTracker, MultiTemplateParams, MultiTemplateTracker
from ..vision.people import box_iou
from .wearable_correct import Correction
from .wearable_data import CameraModel, PhoneTrack

__all__ = ["VisualParams", "VisualTrack", "torso_homography", "track_visual"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class VisualParams:
    """Settings of the visual side [RECON unless noted]."""

    person_height_m: float = 1.75
    width_ratio: float = 0.40
    min_box_height_px: float = 40.0
    max_box_fraction: float = 0.8
    edge_margin_px: float = 3.0
    max_start_sigma_m: float = 0.45
    start_clear_iou: float = 0.05
    blob_min_overlap: float = 0.3
    blob_min_area_px: int = 60  # smallest foreground blob considered, px
    refine: bool = True  # report the person's own foreground blob when found, and put the CT back on it
    max_width_ratio: float = 0.8  # a person's blob is at most this wide for its height (turning, arms swinging)
    recentre_fraction: float = 0.25  # CT centre this far (x blob width) from the blob's: put back on it
    blob_gate: float = 0.35  # a blob's centre at most this many predicted widths (0.7 m) across from the prediction
    out_of_view_s: float = 1.0
    base_sigma_px: float = 6.0
    c9_refit: bool = False
    c9_min_pairs: int = 30  # C9
    c9_growth: float = 1.5
    c9_min_spread_m: float = 0.75
    c9_max_shift_px: float = 12.0
    c9_min_ok_frames: int = 5
    rescale_after: float = 0.2
    max_sigma_m: float = 0.1
    baseline: bool = False
    multi: MultiTemplateParams = field(default_factory=MultiTemplateParams)
    ct: CompressiveParams = field(default_factory=CompressiveParams)

    def __post_init__(self) -> None:
        for name in ("person_height_m", "min_box_height_px", "max_start_sigma_m", "out_of_view_s", "base_sigma_px",
                     "c9_growth", "c9_min_spread_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a finite value > 0, got {value!r}")
        for name in ("width_ratio", "max_box_fraction", "blob_min_overlap", "max_width_ratio", "recentre_fraction",
                     "blob_gate"):
            if not 0 < getattr(self, name) <= 1:
                raise ValueError(f"{name}: expected a value in (0, 1], got {getattr(self, name)!r}")
        if isinstance(self.blob_min_area_px, bool) or not isinstance(self.blob_min_area_px, int | np.integer) \
                or self.blob_min_area_px < 1:
            raise ValueError(f"blob_min_area_px: expected an integer >= 1, got {self.blob_min_area_px!r}")
        if int(self.c9_min_pairs) < 4:
            raise ValueError(f"c9_min_pairs: expected an integer >= 4, got {self.c9_min_pairs!r}")


@dataclass(frozen=True, slots=True, eq=False)
class VisualTrack:
    """One person's boxes in one camera, frame by frame.

    Attributes
    ----------
    phone, camera : str
    t_ns : (n,) int64
        Frame stamps.
    box_px : (n, 4) float64
        Reported box (CT centre, or the reset box on failure; size scaled with the inertial distance).
    ct_box_px : (n, 4) float64
        The CT detection before any reset (fixed size).
    projected_px : (n, 2) float64
        ``x' = P·X(t)``; NaN without inertial data.
    sim : (n,) float64
        C11 consistency; NaN when not tested.
    status : (n,) str
        :class:`~fusiontrack.vision.compressive.MultiTemplateResult` statuses.
    baseline_box_px : (n, 4) float64 or None
        The plain compressive tracker started from the same box (visual-only baseline).
    segment : (n,) int64
        Tracker number within this (person, camera): a new one starts after the previous ended.
    """

    phone: str
    camera: str
    t_ns: np.ndarray
    box_px: np.ndarray
    ct_box_px: np.ndarray
    projected_px: np.ndarray
    sim: np.ndarray
    status: np.ndarray
    baseline_box_px: np.ndarray | None
    segment: np.ndarray


def torso_homography(camera: PinholeCamera, height_m: float) -> np.ndarray:
    """Floor position ``(X, Y)`` -> image point ``height_m`` above it: ``H = [p1, p2, p3 h + p4]`` of ``P = K[R|t]``."""
    P = camera.projection_matrix()
    H = np.column_stack([P[:, 0], P[:, 1], P[:, 2] * height_m + P[:, 3]])
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 else H


class _CameraState:
    """A camera's projection (C9), its foreground model and its trackers' pairs."""

    def __init__(self, model: CameraModel, p: VisualParams) -> None:
        self.model = model
        self.pinhole = PinholeCamera.from_camera_info(model.info, invert_transform(model.cam2world))
        H0 = torso_homography(self.pinhole, 0.5 * p.person_height_m)
        self.projection = InertialProjection(H0, np.eye(2) * p.base_sigma_px**2, p.base_sigma_px, np.zeros(0, bool))
        self.calibration = self.projection
        self.source = "calibration"
        self.pairs_px: list[np.ndarray] = []
        self.pairs_m: list[np.ndarray] = []
        self.next_fit = p.c9_min_pairs
        self.mog = cv2.createBackgroundSubtractorMOG2(history=300, varThreshold=25, detectShadows=True)
        self.size = (model.info.width, model.info.height)

    def refit(self, p: VisualParams, rng: np.random.Generator) -> None:
        """C9: refit P on the collected pairs; keep it when it predicts the held-out half better."""
        px, m = np.array(self.pairs_px), np.array(self.pairs_m)
        self.next_fit = int(np.ceil(len(px) * p.c9_growth))
        # floor positions along one line (one straight walk) leave P undetermined across it: ask for a spread
        minor_m = np.linalg.svd(m - m.mean(axis=0), compute_uv=False)[-1] / np.sqrt(len(m))
        if minor_m < p.c9_min_spread_m or min(np.ptp(px, axis=0)) < 0.1 * min(self.size):
            return
        train, test = np.arange(0, len(px), 2), np.arange(1, len(px), 2)
        params = ProjectionParams(recommended_pairs=p.c9_min_pairs // 2)
        try:
            half = fit_inertial_projection(m[train], px[train], params, rng)
            err_new = np.nanmedian(np.linalg.norm(half.project(m[test]) - px[test], axis=1))
            err_old = np.nanmedian(np.linalg.norm(self.projection.project(m[test]) - px[test], axis=1))
            if not err_new < 0.8 * err_old - 0.5:  # clearly better on the held-out half, or keep the calibration
                return
            fit = fit_inertial_projection(m, px, ProjectionParams(recommended_pairs=p.c9_min_pairs), rng)
        except (CalibrationError, ValueError) as err:
            log.debug("%s: C9 refit failed (%s)", self.model.name, err)
            return
        shift = float(np.nanmedian(np.linalg.norm(fit.project(m) - self.calibration.project(m), axis=1)))
        if not shift <= p.c9_max_shift_px:  # far from the calibration: pairs from a tracker on the wrong target
            log.info("%s: C9 refit refused, %.1f px from the calibration over its pairs", self.model.name, shift)
            return
        log.info("%s: C9 projection refitted on %d pairs (RMS %.1f px, held-out median %.1f px vs %.1f px)",
                 self.model.name, len(px), fit.rms_px, err_new, err_old)
        self.projection, self.source = fit, "c9"


class _Tracker:
    """A running (person, camera) tracker and its failure episode."""

    def __init__(self, mt: MultiTemplateTracker, baseline: CompressiveTracker | None, h0: float, segment: int) -> None:
        self.mt, self.baseline, self.h0, self.segment = mt, baseline, h0, segment
        self.fail_start: int | None = None
        self.fail_frames = 0
        self.ok_run = 0
        self.out_since: int | None = None


def _person_blob(state: _CameraState, boxes: np.ndarray, pred: np.ndarray, others: np.ndarray, p: VisualParams,
                 near: np.ndarray | None = None) -> np.ndarray | None:
    """The foreground blob box that is this person, or None.

    A blob confirms the box ``pred`` predicted from the person's floor position when its height is 0.85-1.2 of
    the predicted one, its bottom within 0.15 of that height of the predicted bottom, its width at most
    ``max_width_ratio`` of its height (wider: people side by side), it lies inside the image and overlaps no
    other person's predicted box (``others``, IoU above ``start_clear_iou``: whose is it?). Without ``near`` (a
    tracker's start) the one overlapping ``pred`` most (IoU >= ``blob_min_overlap``), clear of the image border.
    With ``near`` (the tracker's box) the one whose centre lies inside ``near`` and within ``blob_gate`` predicted
    widths of the predicted centre across (a bystander without a phone beside the person is not in ``others``),
    closest to the predicted centre; it may then touch the border and be down to 0.6 of the predicted height (the
    head or the shoulders lost against a background of their colour): a short blob is extended upwards to the
    predicted height.
    """
    if boxes.size == 0:
        return None
    w_img, h_img = state.size
    hp = pred[3] - pred[1]
    h, w = boxes[:, 3] - boxes[:, 1], boxes[:, 2] - boxes[:, 0]
    low = 0.85 if near is None else 0.6
    ok = (h >= low * hp) & (h <= 1.2 * hp) & (np.abs(boxes[:, 3] - pred[3]) <= 0.15 * hp) & (w >= 6) \
        & (w <= p.max_width_ratio * np.maximum(h, 0.85 * hp))
    if near is None:  # a tracker starts on a whole person, not one cut by the image border
        ok &= (boxes[:, 0] >= p.edge_margin_px) & (boxes[:, 1] >= p.edge_margin_px) \
            & (boxes[:, 2] <= w_img - p.edge_margin_px) & (boxes[:, 3] <= h_img - p.edge_margin_px)
    ok &= np.all(box_iou(others, boxes) <= p.start_clear_iou, axis=0)
    if near is None:
        score = np.where(ok, box_iou(pred[None], boxes)[0], -1.0)
        k = int(np.argmax(score))
        return boxes[k] if score[k] >= p.blob_min_overlap else None
    c = 0.5 * (boxes[:, :2] + boxes[:, 2:])
    pc = 0.5 * (pred[:2] + pred[2:])
    ok &= np.all((c >= near[:2]) & (c <= near[2:]), axis=1) \
        & (np.abs(c[:, 0] - pc[0]) <= p.blob_gate * (pred[2] - pred[0]))
    if not ok.any():
        return None
    d = np.where(ok, np.abs(c[:, 0] - pc[0]), np.inf)
    b = boxes[int(np.argmin(d))].astype(np.float64)
    if b[3] - b[1] < 0.85 * hp:
        b[1] = b[3] - hp
    return b


def track_visual(path: Any, cameras: dict[str, CameraModel], phones: dict[str, PhoneTrack],
                 corrections: dict[str, Correction], params: VisualParams | None = None, *,
                 gap_s: float = 0.25, rng: np.random.Generator | int | None = None,
                 ) -> tuple[dict[tuple[str, str], VisualTrack], list[Event], dict[str, dict[str, Any]]]:
    """Run the visual side over the images of a recording (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The recording.
    cameras : mapping name -> CameraModel
        Cameras to track in (those with images are used).
    phones, corrections : mapping phone -> PhoneTrack, Correction
        Only people whose correction is aligned with a known heading are tracked.
    params : VisualParams
    gap_s : float
        A phone is silent after ``gap_s`` without samples.
    rng : numpy Generator, int or None

    Returns
    -------
    tracks : mapping (phone, camera) -> VisualTrack
    events : list of Event
        ``visual_start``, ``visual_end``, ``visual_failure`` (``t_end_ns`` at recovery) and ``visual_recovery``.
    info : mapping camera -> dict
        The projection used at the end (``source``, ``pairs``, ``rms_px``).
    """
    p = params or VisualParams()
    rng = np.random.default_rng(rng)
    used = {c: _CameraState(m, p) for c, m in cameras.items() if m.has_image}
    people = [ph for ph in sorted(phones) if ph in corrections and corrections[ph].aligned
              and corrections[ph].heading_known]
    ids = {ph: k for k, ph in enumerate(sorted(phones))}
    trackers: dict[tuple[str, str], _Tracker] = {}
    rows: dict[tuple[str, str], list[tuple]] = {}
    segments: dict[tuple[str, str], int] = {}
    events: list[Event] = []
    if not used or not people:
        return {}, events, {c: {"source": s.source, "pairs": 0} for c, s in used.items()}

    def event(kind: str, t: int, ph: str, cam: str, t_end: int | None = None, **attrs: Any) -> None:
        events.append(Event(t, cam, kind, t_end, track_ids=(ids[ph],), attributes={"phone": ph, "camera": cam,
                                                                                   **attrs}))

    def end(key: tuple[str, str], t: int, why: str) -> None:
        tr = trackers.pop(key)
        if tr.fail_start is not None:
            event("visual_failure", tr.fail_start, *key, t_end=t, recovered=False, frames=tr.fail_frames)
        event("visual_end", t, *key, reason=why)

    with Recording(path) as rec:
        topics = [f"/{c}/image" for c in used]
        for msg in rec.messages(topics):
            if not isinstance(msg, Image) or msg.sensor not in used:
                continue
            cam, t = msg.sensor, msg.t_ns
            state = used[cam]
            bgr = msg.bgr()
            if bgr.shape[1::-1] != state.size:
                continue
            grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
            fg = state.mog.apply(bgr) == 255  # shadows (127) dropped
            blobs = extract_blobs(fg, BlobParams(min_area_px=p.blob_min_area_px)).boxes_px
            where: dict[str, tuple[np.ndarray, float, np.ndarray, bool]] = {}
            for ph in people:
                xy, sigma, _ = corrections[ph].at(t)
                live = bool(phones[ph].reporting_at([t], gap_s)[0]) and np.all(np.isfinite(xy))
                if live:
                    box = state.pinhole.person_box(xy[None, :], p.person_height_m, p.width_ratio)[0]
                    where[ph] = (xy, sigma, box, live)
            for ph in people:
                key = (ph, cam)
                tr = trackers.get(key)
                if tr is None:
                    if ph not in where:
                        continue
                    xy, sigma, pred, _ = where[ph]
                    bh = pred[3] - pred[1]
                    if not (np.all(np.isfinite(pred)) and sigma <= p.max_start_sigma_m
                            and p.min_box_height_px <= bh <= p.max_box_fraction * state.size[1]):
                        continue
                    others = np.array([where[o][2] for o in where if o != ph]).reshape(-1, 4)
                    if others.size and np.nanmax(box_iou(pred[None], others)) > p.start_clear_iou:
                        continue
                    box = _person_blob(state, blobs, pred, others, p)
                    if box is None:
                        continue
                    try:
                        mt = MultiTemplateTracker(grey, box, state.projection.residual_cov_px2, p.multi, p.ct, rng)
                        base = CompressiveTracker(grey, box, p.ct, rng) if p.baseline else None
                    except ValueError as err:
                        log.debug("%s in %s: tracker not started (%s)", ph, cam, err)
                        continue
                    segments[key] = segments.get(key, -1) + 1
                    trackers[key] = _Tracker(mt, base, bh, segments[key])
                    event("visual_start", t, ph, cam, box_px=box.tolist())
                    rows.setdefault(key, []).append((t, box, box, state.projection.project(xy), np.nan, "start",
                                                     box if p.baseline else None, segments[key]))
                    continue
                xp = cov = None
                if ph in where:
                    xy, sigma, pred, _ = where[ph]
                    xp = state.projection.project(xy)
                    cov = state.projection.image_cov_px2(xy, min(sigma, p.max_sigma_m) ** 2)
                r = tr.mt.step(grey, xp, cov)
                base_box = tr.baseline.step(grey).box_px if tr.baseline is not None else None
                scale = (pred[3] - pred[1]) / tr.h0 if ph in where and np.isfinite(pred[3] - pred[1]) else 1.0
                c, half = r.centre_px, 0.5 * (r.box_px[2:] - r.box_px[:2]) * scale
                out = np.r_[c - half, c + half]
                if p.refine and ph in where and np.all(np.isfinite(pred)):
                    others = np.array([where[o][2] for o in where if o != ph]).reshape(-1, 4)
                    blob = _person_blob(state, blobs, pred, others, p, near=out)
                    if blob is not None:  # the person's own silhouette: its box, and the CT put back on it
                        bc = 0.5 * (blob[:2] + blob[2:])
                        if r.status != "ok" or np.linalg.norm(bc - c) > p.recentre_fraction * (blob[2] - blob[0]):
                            tr.mt.ct.reset(bc)
                        out = blob.astype(np.float64)
                if abs(scale - 1.0) > p.rescale_after and r.status == "ok" and r.sim >= 0.3:
                    others = np.array([where[o][2] for o in where if o != ph]).reshape(-1, 4)
                    clear = not others.size or np.nanmax(box_iou(out[None], others)) <= p.start_clear_iou
                    inside = out[0] >= 0 and out[1] >= 0 and out[2] <= state.size[0] and out[3] <= state.size[1]
                    if clear and inside:  # the person's distance changed: a new CT at the new size [RECON]
                        try:
                            tr.mt = MultiTemplateTracker(grey, out, state.projection.residual_cov_px2, p.multi,
                                                         p.ct, rng)
                            tr.h0 = pred[3] - pred[1]
                        except ValueError as err:
                            log.debug("%s in %s: not rescaled (%s)", ph, cam, err)
                rows[key].append((t, out, r.visual_box_px, np.full(2, np.nan) if xp is None else xp, r.sim,
                                  r.status, base_box, tr.segment))
                if r.failure:
                    tr.fail_frames += 1
                    if tr.fail_start is None:
                        tr.fail_start = t
                elif r.status == "ok" and tr.fail_start is not None:
                    event("visual_failure", tr.fail_start, ph, cam, t_end=t, recovered=True, frames=tr.fail_frames)
                    event("visual_recovery", t, ph, cam, after_s=(t - tr.fail_start) * 1e-9)
                    tr.fail_start, tr.fail_frames = None, 0
                tr.ok_run = tr.ok_run + 1 if r.status == "ok" else 0
                if p.c9_refit and tr.ok_run >= p.c9_min_ok_frames and xp is not None and r.sim >= 0.5 \
                        and sigma <= 0.2:
                    state.pairs_px.append(r.centre_px.copy())
                    state.pairs_m.append(xy.copy())
                    if len(state.pairs_px) >= state.next_fit:
                        state.refit(p, rng)
                if r.status == "out_of_view":
                    tr.out_since = t if tr.out_since is None else tr.out_since
                    if (t - tr.out_since) * 1e-9 >= p.out_of_view_s:
                        end(key, t, "out_of_view")
                else:
                    tr.out_since = None
        t_last = rec.end_ns
    for key in list(trackers):
        end(key, t_last, "end_of_recording")
    tracks = {}
    for key, rs in rows.items():
        base = np.array([r[6] if r[6] is not None else np.full(4, np.nan) for r in rs]) if p.baseline else None
        tracks[key] = VisualTrack(key[0], key[1], np.array([r[0] for r in rs], np.int64), np.array([r[1] for r in rs]),
                                  np.array([r[2] for r in rs]), np.array([r[3] for r in rs]),
                                  np.array([r[4] for r in rs], np.float64), np.array([r[5] for r in rs]), base,
                                  np.array([r[7] for r in rs], np.int64))
    info = {c: {"source": s.source, "pairs": len(s.pairs_px), "rms_px": float(s.projection.rms_px)}
            for c, s in used.items()}
    events.sort(key=lambda e: e.t_ns)
    return tracks, events, info
