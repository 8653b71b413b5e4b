"""Which RGB-D detection is which phone's carrier (seed 002; ALGORITHMS.md C5, C7, X2, X7).

The owner of an RGB-D detection is not given. The detections of all depth cameras are first linked into
short world-frame *tracklets* (:func:`link_tracklets`: nearest neighbour on a constant-velocity prediction,
Hungarian per frame, X2); a tracklet is cut wherever the link is ambiguous (another detection or tracklet
within ``ambiguity_m``), so it holds one person. A tracklet is then matched to the dead-reckoned path of
each phone over the same times (:func:`associate`):

* **shape** -- the dead-reckoned positions are registered onto the tracklet by a similarity (X7 with a scale
  in ``scale_range``, Umeyama: the step-length model of an uncalibrated phone is off by 10-30 %) and the
  residual RMS (over the samples where either moves) is compared with ``shape_sigma_m`` plus ``shape_scale`` x
  the tracklet's extent. Being invariant to the unknown start pose and heading of a phone, it compares the
  motion itself: when the person starts and stops, where they turn, how their pace changes;
* **position** -- once the phone has an owned tracklet, its world position is predicted from the nearest
  owned fix in time and the heading offset found on the nearest owned tracklet that moved far enough, with
  a standard deviation growing with the distance walked from that fix (``position_sigma_m``,
  ``drift_per_m``) and with the IMU gaps in between (:data:`GAP_SPEED_MPS` per second of gap).

Tracklets are decided in time order, jointly with the undecided tracklets that overlap them in time
(Hungarian with a "nobody" column at the gate cost), and a pair is accepted only when every other
explanation costs at least ``ambiguity_margin`` more; a phone not yet placed in the world can only take a
tracklet that moved at least ``min_align_extent_m``, and one that its path explains better than a steady
straight walk does (by ``ambiguity_margin``; the same four degrees of freedom) or that is confirmed: placed in
the world by it, the phone then takes another undecided tracklet, decided as here (:func:`_confirmed`) [a
passer-by walking straight down a corridor matched any phone that walked straight too, at cost 0. On ``corridor``
cut to 30 s, seeds 0-3, the one tracklet owned was a passer-by's in all four runs (corrected paths 1-16 m off):
now none is owned and the phone keeps its dead reckoning. At 60 s: seeds 0 and 3 own the carrier's stretches as
before, seed 2 no longer owns a passer-by's (15 m off), and seed 1 no longer owns the carrier's, unconfirmed. At
90 s (seeds 1, 2) a passer-by's is still owned, confirmed by the carrier's a long walk later (see
:func:`_confirmed`). The 200 s runs (seeds 0-2) and the ``wearable_*`` scenes (seeds 0-2) own what they owned. A
refused steady walk still counts as an explanation against the other phones]. Passes repeat until nothing
changes, so a tracklet left open early may be decided once its candidates are placed. Symmetric scenes (two
people starting at the same moment, mirror-image paths) are ambiguous by shape alone: the tracklets are then left
to nobody rather than guessed, and the phones stay uncorrected until a later tracklet tells them apart.

The owned detections become the phone's fixes (:mod:`~fusiontrack.fusion.wearable_correct`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..errors import CalibrationError
from ..geometry import fit_rigid_2d
from ..tracking.association import hungarian
from .wearable_data import Detections, PhoneTrack

__all__ = ["GAP_SPEED_MPS", "AssocParams", "Tracklet", "associate", "link_tracklets", "pair_cost", "rigid_or_shift",
           "within_span"]

log = logging.getLogger(__name__)

MOVING_MPS = 0.3
"""Speed above which a tracklet or a dead-reckoned path counts as moving (for the shape comparison)."""
GAP_SPEED_MPS = 1.5
"""Walking speed assumed over an IMU gap: how fast the position becomes unknown while the phone is silent."""


@dataclass(frozen=True, slots=True)
class AssocParams:
    """Tracklet linking, ownership and correction settings [RECON unless noted]."""

    link_gate_m: float = 0.6
    max_gap_s: float = 0.5
    ambiguity_m: float = 0.6
    min_detections: int = 8
    min_duration_s: float = 0.5
    shape_sigma_m: float = 0.12
    shape_scale: float = 0.02
    position_sigma_m: float = 0.35
    drift_per_m: float = 0.08
    gate: float = 9.0
    ambiguity_margin: float = 3.0
    min_align_extent_m: float = 1.5
    min_coverage: float = 0.5
    max_passes: int = 4
    control_spacing_m: float = 0.5  # C8
    smoothing: float = 0.0  # C8 λ = 0: the fixes are interpolated
    calibrate_scale: bool = True
    scale_range: tuple[float, float] = (0.7, 1.4)
    fix_sigma_m: float = 0.15

    def __post_init__(self) -> None:
        for name in ("link_gate_m", "max_gap_s", "shape_sigma_m", "position_sigma_m", "gate", "min_align_extent_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a finite value > 0, got {value!r}")
        lo, hi = self.scale_range
        if not 0 < lo <= 1 <= hi:
            raise ValueError(f"scale_range: expected (low, high) with 0 < low <= 1 <= high, got {self.scale_range}")
        for name in ("ambiguity_m", "shape_scale", "drift_per_m", "ambiguity_margin", "min_duration_s",
                     "control_spacing_m", "smoothing", "fix_sigma_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name}: expected a finite value >= 0, got {value!r}")
        if not 0 < self.min_coverage <= 1:
            raise ValueError(f"min_coverage: expected a value in (0, 1], got {self.min_coverage!r}")
        for name in ("min_detections", "max_passes"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {getattr(self, name)!r}")


@dataclass(frozen=True, slots=True, eq=False)
class Tracklet:
    """Detections of one person linked over time: ``index`` into :class:`Detections`, times, world positions."""

    index: np.ndarray
    t_ns: np.ndarray
    xy_m: np.ndarray

    @property
    def span_ns(self) -> tuple[int, int]:
        return int(self.t_ns[0]), int(self.t_ns[-1])

    @property
    def extent_m(self) -> float:
        """Diagonal of the bounding box of the positions, m."""
        return float(np.linalg.norm(np.ptp(self.xy_m, axis=0)))

    def overlaps(self, other: Tracklet) -> bool:
        return self.span_ns[0] <= other.span_ns[1] and other.span_ns[0] <= self.span_ns[1]


def link_tracklets(det: Detections, params: AssocParams | None = None) -> list[Tracklet]:
    """Link time-ordered floor detections of every depth camera into tracklets (see the module docstring).

    Returns the tracklets with at least ``min_detections`` detections over ``min_duration_s``, by start time.
    """
    p = params or AssocParams()
    active: list[dict] = []
    done: list[list[int]] = []
    if len(det) == 0:
        return []
    keys = det.t_ns * 64 + det.camera  # one frame = one (stamp, camera)
    starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    for a, b in zip(starts, np.r_[starts[1:], len(det)], strict=True):
        t = int(det.t_ns[a])
        done += [tr["idx"] for tr in active if t - tr["t"] > p.max_gap_s * 1e9]
        active = [tr for tr in active if t - tr["t"] <= p.max_gap_s * 1e9]
        xy = det.xy_m[a:b]
        if active:
            dt = np.array([(t - tr["t"]) * 1e-9 for tr in active])
            pred = np.array([tr["xy"] + tr["v"] * min(d, 0.5) for tr, d in zip(active, dt, strict=True)])
            cost = np.linalg.norm(pred[:, None, :] - xy[None, :, :], axis=2)
            pairs, _, _ = hungarian(cost, p.link_gate_m)
        else:
            cost, pairs = np.zeros((0, b - a)), np.zeros((0, 2), np.int64)
        matched = set()
        closed = set()
        for k, j in pairs:
            row, col = np.sort(cost[k]), np.sort(cost[:, j])
            if (row.size > 1 and row[1] < p.ambiguity_m) or (col.size > 1 and col[1] < p.ambiguity_m):
                closed.add(int(k))  # two candidates: cut here so that a tracklet never holds two people
                continue
            tr = active[k]
            dt_s = max((t - tr["t"]) * 1e-9, 1e-3)
            v = (xy[j] - tr["xy"]) / dt_s
            tr["v"] = 0.7 * tr["v"] + 0.3 * np.clip(v, -3.0, 3.0) if len(tr["idx"]) > 1 else np.clip(v, -3.0, 3.0)
            tr["xy"], tr["t"] = xy[j].copy(), t
            tr["idx"].append(a + int(j))
            matched.add(int(j))
        done += [active[k]["idx"] for k in closed]
        active = [tr for k, tr in enumerate(active) if k not in closed]
        for j in range(b - a):
            if j not in matched:
                active.append({"idx": [a + j], "t": t, "xy": xy[j].copy(), "v": np.zeros(2)})
    done += [tr["idx"] for tr in active]
    out = []
    for idx in done:
        i = np.asarray(idx, np.int64)
        if i.size >= p.min_detections and (det.t_ns[i[-1]] - det.t_ns[i[0]]) * 1e-9 >= p.min_duration_s:
            out.append(Tracklet(i, det.t_ns[i], det.xy_m[i]))
    return sorted(out, key=lambda tr: tr.span_ns)


def within_span(phone: PhoneTrack, tr: Tracklet) -> tuple[np.ndarray, np.ndarray]:
    """The tracklet's times ``(k,)`` and positions ``(k, 2)`` within the phone's span."""
    ok = (tr.t_ns >= phone.t_ns[0]) & (tr.t_ns <= phone.t_ns[-1]) if phone.ok else np.zeros(tr.t_ns.size, bool)
    return tr.t_ns[ok], tr.xy_m[ok]


def _speed(t_ns: np.ndarray, xy: np.ndarray, window: int = 5) -> np.ndarray:
    """Speed ``(n,)`` m/s along positions ``(n, 2)``, from a moving average over ``window`` samples."""
    if t_ns.size < 3:
        return np.zeros(t_ns.size)
    k = min(window, t_ns.size)
    kernel = np.ones(k) / k
    sm = np.column_stack([np.convolve(np.pad(xy[:, j], (k // 2, k - 1 - k // 2), mode="edge"), kernel, "valid")
                          for j in range(2)])
    t = (t_ns - t_ns[0]) * 1e-9
    if np.any(np.diff(t) <= 0):  # two cameras at one stamp: nudge so the gradient stays finite
        t = t + np.arange(t.size) * 1e-6
    return np.hypot(*np.gradient(sm, t, axis=0).T)


def _similar(src: np.ndarray, dst: np.ndarray, scale_range: tuple[float, float],
             weight: np.ndarray | None = None) -> float:
    """Residual RMS of the similarity (X7 with a scale clipped to ``scale_range``, Umeyama) taking ``src`` onto ``dst``.

    The scale absorbs a step-length error of the phone's (not yet calibrated) model. The RMS is over the samples
    selected by ``weight`` (all when None) -- the fit itself uses every sample.
    """
    ok = np.all(np.isfinite(src), axis=1) & np.all(np.isfinite(dst), axis=1)
    if ok.sum() < 2:
        return np.inf
    weight = None if weight is None else weight[ok]
    src, dst = src[ok], dst[ok]
    a, b = src - src.mean(axis=0), dst - dst.mean(axis=0)
    try:
        u, sv, vt = np.linalg.svd(a.T @ b)
    except np.linalg.LinAlgError:
        return np.inf
    sign = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    R = vt.T @ np.diag([1.0, sign]) @ u.T
    var = float(np.sum(a**2))
    k = float(np.clip((sv[0] + sign * sv[1]) / var, *scale_range)) if var > 1e-12 else 1.0
    res = np.sum((b - k * a @ R.T) ** 2, axis=1)
    if weight is not None and weight.any():
        res = res[weight]
    return float(np.sqrt(np.mean(res)))


def rigid_or_shift(src: np.ndarray, dst: np.ndarray, min_extent_m: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Rigid (or, when either set hardly moves, translation-only) fit of ``src`` onto ``dst``: residual RMS, R, t."""
    ok = np.all(np.isfinite(src), axis=1) & np.all(np.isfinite(dst), axis=1)
    src, dst = src[ok], dst[ok]
    if src.shape[0] == 0:
        return np.inf, np.eye(2), np.zeros(2)
    if min(np.linalg.norm(np.ptp(src, axis=0)), np.linalg.norm(np.ptp(dst, axis=0))) >= min_extent_m:
        try:
            R, t = fit_rigid_2d(src, dst)
            res = dst - (src @ R.T + t)
            return float(np.sqrt(np.mean(np.sum(res**2, axis=1)))), R, t
        except (CalibrationError, np.linalg.LinAlgError):
            pass
    t = dst.mean(axis=0) - src.mean(axis=0)
    res = dst - (src + t)
    return float(np.sqrt(np.mean(np.sum(res**2, axis=1)))), np.eye(2), t


@dataclass
class _PhoneState:
    """What the owned tracklets (or a known start pose) say about a phone's place in the world."""

    fix_t: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    fix_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    turn_t: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # mid-times of aligning tracklets
    turn_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def aligned(self) -> bool:
        return self.turn_t.size > 0 and self.fix_t.size > 0


def _state(phone: PhoneTrack, owned: list[Tracklet], start_known: bool, p: AssocParams) -> _PhoneState:
    s = _PhoneState()
    if start_known:  # the dead reckoning is already in the world frame: the start is a fix, no turn
        s.fix_t, s.fix_xy = phone.t_ns[:1].copy(), phone.xy_m[:1].copy()
        s.turn_t, s.turn_rad = phone.t_ns[:1].copy(), np.zeros(1)
    for tr in owned:
        t, xy = within_span(phone, tr)
        s.fix_t = np.concatenate([s.fix_t, t])
        s.fix_xy = np.vstack([s.fix_xy, xy])
        if tr.extent_m >= p.min_align_extent_m and t.size >= 2:
            _, R, _ = rigid_or_shift(phone.position_at(t), xy, 0.5)
            s.turn_t = np.append(s.turn_t, (tr.span_ns[0] + tr.span_ns[1]) // 2)
            s.turn_rad = np.append(s.turn_rad, np.arctan2(R[1, 0], R[0, 0]))
    order = np.argsort(s.fix_t, kind="stable")
    s.fix_t, s.fix_xy = s.fix_t[order], s.fix_xy[order]
    return s


def _predict(phone: PhoneTrack, s: _PhoneState, t_ns: np.ndarray, p: AssocParams) -> tuple[np.ndarray, np.ndarray]:
    """World positions ``(n, 2)`` and their standard deviations ``(n,)`` from the nearest fix and turn."""
    i = np.clip(np.searchsorted(s.fix_t, t_ns), 1, s.fix_t.size) - 1
    j = np.minimum(i + 1, s.fix_t.size - 1)
    a = np.where(np.abs(s.fix_t[j] - t_ns) < np.abs(s.fix_t[i] - t_ns), j, i)  # nearest fix in time
    k = np.argmin(np.abs(s.turn_t[None, :] - t_ns[:, None]), axis=1)
    c, sn = np.cos(s.turn_rad[k]), np.sin(s.turn_rad[k])
    d = phone.position_at(t_ns) - phone.position_at(s.fix_t[a])
    pred = s.fix_xy[a] + np.column_stack([c * d[:, 0] - sn * d[:, 1], sn * d[:, 0] + c * d[:, 1]])
    walked = np.abs(phone.path_at(t_ns) - phone.path_at(s.fix_t[a]))
    lost = GAP_SPEED_MPS * phone.silent_s(s.fix_t[a], t_ns)  # walking an IMU gap hid, heading included
    return pred, np.hypot(p.position_sigma_m, p.drift_per_m * walked) + lost


def pair_cost(phone: PhoneTrack, s: _PhoneState, tr: Tracklet, p: AssocParams, gap_s: float = 0.25,
              steady: bool = True) -> float:
    """Normalised cost of "tracklet ``tr`` is the carrier of ``phone``" (inf when it cannot be decided; with
    ``steady`` False, a steady walk is not refused to a phone not yet in the world)."""
    if not phone.ok:
        return np.inf
    live = phone.reporting_at(tr.t_ns, gap_s)  # compared where the phone reports: it misses the steps of a gap
    live &= (tr.t_ns >= phone.t_ns[0]) & (tr.t_ns <= phone.t_ns[-1])
    if live.mean() < p.min_coverage:
        return np.inf
    # and between two gaps only (the dead reckoning is shifted across a gap): the longest such run
    run = np.searchsorted(phone.gaps_ns[:, 1], tr.t_ns, side="right")
    counts = np.bincount(run[live], minlength=run.max() + 1)
    live &= run == int(np.argmax(counts))
    if live.sum() < p.min_detections:
        return np.inf
    t, y = tr.t_ns[live], tr.xy_m[live]
    d = phone.position_at(t)
    # judged where someone moves: a long wait both agree on would dilute a mismatch of when and how they walk
    moving = (_speed(t, y) > MOVING_MPS) | (_speed(t, d) > MOVING_MPS)
    weight = moving if moving.sum() >= 5 else None
    e = _similar(d, y, p.scale_range, weight)
    extent = max(tr.extent_m, float(np.linalg.norm(np.ptp(d, axis=0))))
    cost = (e / (p.shape_sigma_m + p.shape_scale * extent)) ** 2
    if s.aligned:
        pred, sigma = _predict(phone, s, t, p)
        cost += float(np.mean(np.sum((y - pred) ** 2, axis=1) / sigma**2)) / 2.0
    elif tr.extent_m < p.min_align_extent_m:
        return np.inf  # a phone not yet in the world cannot tell standing people apart
    elif steady and (_steady(t, y, weight) / (p.shape_sigma_m + p.shape_scale * extent)) ** 2 - cost < \
            p.ambiguity_margin:
        # nor people walking straight on at a steady pace: the similarity takes any such walk onto any other (a
        # passer-by's tracklet in a corridor matched the phone's path at cost 0.00): the phone's path must explain
        # the tracklet better than a steady walk does (the same 4 degrees of freedom), by ``ambiguity_margin``;
        # else only a later (or earlier) tracklet can confirm it (:func:`associate`)
        return np.inf
    return float(cost)


def _steady(t_ns: np.ndarray, xy: np.ndarray, weight: np.ndarray | None = None) -> float:
    """Residual RMS of the straight walk at a constant velocity that best fits positions ``(n, 2)`` at ``t_ns``:
    how well "somebody walking steadily" explains them (over the samples selected by ``weight``, all when None;
    the fit uses every sample, as :func:`_similar`)."""
    ok = np.all(np.isfinite(xy), axis=1)
    if ok.sum() < 2:
        return np.inf
    weight = None if weight is None else weight[ok]
    t = (t_ns[ok] - t_ns[ok][0]) * 1e-9
    a = np.column_stack([np.ones_like(t), t])
    coef, *_ = np.linalg.lstsq(a, xy[ok], rcond=None)
    res = np.sum((xy[ok] - a @ coef) ** 2, axis=1)
    if weight is not None and weight.any():
        res = res[weight]
    return float(np.sqrt(np.mean(res)))


def _decide(cost: np.ndarray, p: AssocParams) -> tuple[int, float]:
    """The phone the first row's tracklet goes to (-1: nobody, or undecided) and by how much every other
    explanation of the rows costs more."""
    best, total = _assign(cost, p.gate)
    c = int(best[0])
    if c < 0:
        return -1, np.nan
    alt = cost.copy()
    alt[0, c] = np.inf
    _, total_alt = _assign(alt, p.gate)
    return (c, total_alt - total) if total_alt - total >= p.ambiguity_margin else (-1, np.nan)


def _confirmed(i: int, c: int, tracklets: list[Tracklet], owner: np.ndarray, phones: list[PhoneTrack],
               states: list[_PhoneState], p: AssocParams, known: dict[str, bool], gap_s: float) -> float | None:
    """Phone ``c`` placed in the world by tracklet ``i`` (with what it owns): the margin by which it then takes
    another undecided tracklet that does not overlap ``i`` in time, decided as :func:`associate` decides (jointly
    with the tracklets overlapping that one, against every phone and nobody); None when no tracklet does.

    The placement's spread grows with the distance walked (``drift_per_m``): a tracklet a long walk away confirms
    little (on ``corridor``, 90 s, seed 2, a passer-by's tracklet was confirmed by the carrier's 40 m later, 6 m
    off the prediction). Asking for a spread under 1 m confirmed nothing on ``corridor``'s 200 s, whose RGB-D spots
    are further apart, where the first steady tracklet decided is the carrier's: not asked for."""
    phone = phones[c]
    trial = list(states)
    trial[c] = _state(phone, [t for t, o in zip(tracklets, owner, strict=True) if o == c] + [tracklets[i]],
                      known.get(phone.name, False), p)
    if not trial[c].aligned:
        return None
    for k, tr in enumerate(tracklets):
        if k == i or owner[k] >= 0 or tr.overlaps(tracklets[i]):
            continue
        group = [k] + [g for g, o in enumerate(tracklets) if g not in (i, k) and owner[g] < 0 and tr.overlaps(o)]
        taken = {int(owner[g]) for g, o in enumerate(tracklets) if owner[g] >= 0 and tr.overlaps(o)}
        cost = np.array([[np.inf if q in taken else pair_cost(phones[q], trial[q], tracklets[g], p, gap_s,
                                                              steady=False)
                          for q in range(len(phones))] for g in group])
        q, gain = _decide(cost, p)
        if q == c:
            return gain
    return None


def _assign(cost: np.ndarray, gate: float) -> tuple[np.ndarray, float]:
    """Min-cost assignment of rows to columns or to "nobody" (at ``gate``): column per row (-1) and total."""
    n, m = cost.shape
    big = 1e9
    aug = np.full((n, m + n), big)
    aug[:, :m] = np.where(np.isfinite(cost) & (cost <= gate), cost, big)
    aug[np.arange(n), m + np.arange(n)] = gate
    rows, cols = linear_sum_assignment(aug)
    out = np.full(n, -1)
    out[rows] = np.where(cols < m, cols, -1)
    return out, float(aug[rows, cols].sum())


def associate(tracklets: list[Tracklet], phones: list[PhoneTrack], params: AssocParams | None = None,
              start_known: dict[str, bool] | None = None, gap_s: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """Decide the owner of every tracklet (see the module docstring).

    Returns
    -------
    owner : (n_tracklets,) int64
        Index into ``phones``, or -1 (nobody, or undecided).
    margin : (n_tracklets,) float64
        How much more the best alternative explanation costs (inf when there is none; NaN if undecided).
    """
    p = params or AssocParams()
    known = start_known or {}
    n, m = len(tracklets), len(phones)
    owner = np.full(n, -1, np.int64)
    margin = np.full(n, np.nan)
    if n == 0 or m == 0:
        return owner, margin
    states = [_state(ph, [], known.get(ph.name, False), p) for ph in phones]
    for _ in range(p.max_passes):
        changed = False
        for i, tr in enumerate(tracklets):
            if owner[i] >= 0:
                continue
            group = [i] + [k for k, o in enumerate(tracklets) if k != i and owner[k] < 0 and tr.overlaps(o)]
            taken = {int(owner[k]) for k, o in enumerate(tracklets) if owner[k] >= 0 and tr.overlaps(o)}
            # (a steady walk counts as an explanation here: refused, it would make the other phones look certain)
            cost = np.array([[np.inf if c in taken else pair_cost(phones[c], states[c], tracklets[g], p, gap_s,
                                                                  steady=False)
                              for c in range(m)] for g in group])
            c, gain = _decide(cost, p)
            if c < 0:
                continue
            if not np.isfinite(pair_cost(phones[c], states[c], tr, p, gap_s)):
                # a steady walk places a phone in the world only if it is confirmed: placed so, the phone takes
                # another tracklet soon after (or before), where and as it walks; the margin is then that one's
                gain = _confirmed(i, c, tracklets, owner, phones, states, p, known, gap_s)
                if gain is None:
                    continue
            owner[i], margin[i] = c, gain
            states[c] = _state(phones[c], [t for t, o in zip(tracklets, owner, strict=True) if o == c],
                               known.get(phones[c].name, False), p)
            changed = True
        if not changed:
            break
    return owner, margin
