"""A phone's dead reckoning placed in the world and corrected by its RGB-D fixes (seed 002; ALGORITHMS.md C3, C8).

The detections of the tracklets a phone owns (:mod:`~fusiontrack.fusion.wearable_assoc`) are its fixes.
:func:`correct_phone`

1. learns the phone's step-length factor from the owned tracklets that moved (their displacement over the dead
   reckoning's: C3's per-person model, its walk of known length measured by the RGB-D cameras);
2. aligns the phone's frame with the world: the rigid fit (X7) of the dead reckoning on its first owned tracklet
   that moved far enough, or its known start pose (C5); seen only while standing, the heading stays unknown
   (translation only, flagged);
3. corrects the drift causally with the thin-plate-spline warp of :func:`fusiontrack.inertial.correct_trajectory`
   (C8): from each control point on, the dead reckoning continues from the warped latest control point.

The causal warp is only ever evaluated at the latest control point, where the spline interpolates the fix. C8's
rigid fallback for collinear control points would move that anchor off the fix -- on a straight walk from one
RGB-D camera to the next it put the anchor 0.9 m away -- so the spline is kept for nearly collinear points
(``collinear_ratio=0``); exactly collinear ones still fall back.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..inertial import control_pairs, correct_trajectory
from .wearable_assoc import GAP_SPEED_MPS, AssocParams, Tracklet, rigid_or_shift, within_span
from .wearable_data import PhoneTrack

__all__ = ["Correction", "correct_phone"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, eq=False)
class Correction:
    """A phone's trajectory in the world (C8 applied causally).

    Attributes
    ----------
    t_ns : (m,) int64
        The phone's grid.
    xy_m : (m, 2) float64
        Corrected positions (world) where ``aligned``; else the dead reckoning in the phone's own frame.
    dr_world_m : (m, 2) float64
        The dead reckoning moved into the world by the alignment only (no drift correction); NaN unaligned.
    corrected : (m,) bool
        At or after the first control point.
    sigma_m : (m,) float64
        Position standard deviation: grows with the distance walked since the latest fix (inf unaligned).
    aligned : bool
        The phone's frame is placed in the world (owned tracklet that moved, or a known start pose).
    scale : float
        Step-length factor learnt from the owned tracklets that moved (1 when none did, or when disabled).
    heading_known : bool
        The rotation of the alignment is known (False: fixes only while standing; translation only).
    control_t_ns : (j,) int64
        Control points used by the TPS.
    fix_t_ns : (f,) int64
    fix_xy_m : (f, 2) float64
        Every owned RGB-D fix.
    """

    t_ns: np.ndarray
    xy_m: np.ndarray
    dr_world_m: np.ndarray
    corrected: np.ndarray
    sigma_m: np.ndarray
    aligned: bool
    scale: float
    heading_known: bool
    control_t_ns: np.ndarray
    fix_t_ns: np.ndarray
    fix_xy_m: np.ndarray

    def at(self, t_ns: int) -> tuple[np.ndarray, float, bool]:
        """Corrected position ``(2,)``, its standard deviation and the ``corrected`` flag at one time."""
        if self.t_ns.size == 0 or not self.t_ns[0] <= t_ns <= self.t_ns[-1]:
            return np.full(2, np.nan), np.inf, False
        k = int(np.clip(np.searchsorted(self.t_ns, t_ns), 1, self.t_ns.size - 1))
        w = (t_ns - self.t_ns[k - 1]) / max(int(self.t_ns[k] - self.t_ns[k - 1]), 1)
        xy = (1 - w) * self.xy_m[k - 1] + w * self.xy_m[k]
        return xy, float(max(self.sigma_m[k - 1], self.sigma_m[k])), bool(self.corrected[k - 1])


def correct_phone(phone: PhoneTrack, owned: list[Tracklet], params: AssocParams | None = None,
                  start_known: bool = False) -> Correction:
    """Align a phone's dead reckoning with the world and correct its drift from its owned fixes (C8)."""
    p = params or AssocParams()
    t = phone.t_ns
    nan = np.full((t.size, 2), np.nan)
    inside = [within_span(phone, tr) for tr in owned]
    fix_t = np.concatenate([t for t, _ in inside]) if owned else np.zeros(0, np.int64)
    fix_xy = np.vstack([xy for _, xy in inside]) if owned else np.zeros((0, 2))
    order = np.argsort(fix_t, kind="stable")
    fix_t, fix_xy = fix_t[order], fix_xy[order]
    if not phone.ok:
        return Correction(t, nan, nan, np.zeros(t.size, bool), np.full(t.size, np.inf), False, 1.0, False,
                          np.zeros(0, np.int64), fix_t, fix_xy)
    moving = [(t, xy) for tr, (t, xy) in zip(owned, inside, strict=True)
              if tr.extent_m >= p.min_align_extent_m and t.size >= 2]
    heading_known = True
    scale = _scale(phone, moving, p) if p.calibrate_scale else 1.0
    origin = phone.xy_m[0]
    dr = origin + scale * (phone.xy_m - origin)  # C3's step lengths times the learnt factor

    def dr_at(tq: np.ndarray) -> np.ndarray:
        return origin + scale * (phone.position_at(tq) - origin)

    if start_known:
        R, shift = np.eye(2), np.zeros(2)
    elif moving:
        _, R, shift = rigid_or_shift(dr_at(moving[0][0]), moving[0][1], 0.5)
    elif fix_t.size:
        R, heading_known = np.eye(2), False
        shift = fix_xy[0] - dr_at(fix_t[:1])[0]
        log.warning("phone %s: seen only while standing; its heading in the world is unknown", phone.name)
    else:
        return Correction(t, phone.xy_m.copy(), nan, np.zeros(t.size, bool), np.full(t.size, np.inf), False, 1.0,
                          False, np.zeros(0, np.int64), fix_t, fix_xy)
    dr_world = dr @ R.T + shift
    ct, src, dst = control_pairs(t, dr_world, fix_t, fix_xy, min_spacing_m=p.control_spacing_m)
    xy = dr_world
    if ct.size:
        try:  # see the module docstring: the anchor is the spline at the latest fix
            xy = correct_trajectory(t, dr_world, ct, src, dst, smoothing=p.smoothing, causal=True, collinear_ratio=0.0)
        except ValueError:  # exactly collinear control points: C8's rigid fallback
            xy = correct_trajectory(t, dr_world, ct, src, dst, smoothing=p.smoothing, causal=True)
    corrected = t >= ct[0] if ct.size else np.zeros(t.size, bool)
    # distance walked since the latest fix (before the first: since the start, or from the first fix)
    anchor = fix_t if fix_t.size else t[:1]
    last = np.clip(np.searchsorted(anchor, t, side="right") - 1, 0, None)
    walked = scale * np.abs(phone.path_m - phone.path_at(anchor[last]))
    sigma = np.hypot(p.fix_sigma_m, p.drift_per_m * walked) + GAP_SPEED_MPS * phone.silent_s(anchor[last], t)
    return Correction(t, xy, dr_world, corrected, sigma, True, scale, heading_known, ct, fix_t, fix_xy)


def _scale(phone: PhoneTrack, moving: list[tuple[np.ndarray, np.ndarray]], p: AssocParams) -> float:
    """Step-length factor: how far the owned tracklets that moved went over how far the dead reckoning went.

    Displacements between the medians of the first and the last few fixes of each tracklet; the per-person step
    model of C3 learnt from walks of a known length, here measured by the RGB-D camera.
    """
    seen = walked = 0.0
    for t, xy in moving:
        k = int(np.clip(t.size // 4, 1, 5))
        d = phone.position_at(t)
        seen += float(np.linalg.norm(np.median(xy[-k:], axis=0) - np.median(xy[:k], axis=0)))
        walked += float(np.linalg.norm(np.median(d[-k:], axis=0) - np.median(d[:k], axis=0)))
    if walked < 1.0:
        return 1.0
    return float(np.clip(seen / walked, *p.scale_range))
