"""Seed 003's particle-filter tracker of vehicles: modes of particles in the road frame (ALGORITHMS.md D6).

Every tracked object is a *mode*: ``n_particles`` particles ``(X, Y, Ẋ, Ẏ)`` in the road frame plus a colour
model (the HSV histogram of its camera blobs). All modes' particles live in one ``(n_modes, n_particles, 4)``
array, so prediction, weighting and resampling are one numpy pass over every particle (X1). Per step, on the
fused object models of D5 (position, velocity, colour, class, confidence):

* **S0** a fused object that no mode claims, seen with confidence >= ``min_spawn_confidence`` (0.6: a laser, or
  both cameras; one camera's blob alone updates modes but does not start one — in a jam or after a light change
  a single camera's foreground makes ghosts) and farther than ``d_new_m`` from every mode centre starts a
  mode (an imprecise object: farther than 3 σ of its position): particles from N(pos, init_sigma_m²), velocity
  from the object (its laser track) or, unknown, from N(0, init_sigma_v_mps²) (D6 says 0; a vehicle entering at
  15 m/s would lag for seconds), colour from its camera histogram. A mode is reported (``TrackState``) once it
  has been matched in ``n_confirm`` steps. Before that, an unclaimed object is offered to the modes coasting
  (unmatched for over 0.1 s): one whose path since it was last matched — from there to where constant velocity
  has carried it — passes within ``reacquire_m`` (1.5 m) of the object takes it up again (its
  particles redrawn at the object, id and colour kept; event ``reacquired``) [RECON]: a vehicle that braked or
  stopped while hidden reappears short of its prediction, beyond the gate.
* **S1** prediction by the constant-velocity model (Eq. 4), its noise ``σ_p, σ_v`` given per 25 Hz frame and
  scaled by ``sqrt(dt / 0.04 s)`` so the filter behaves the same at any sensor rate.
* **S2** weights ``w ∝ p(y | x)`` (Eq. 3 with the transition prior as proposal), normalised within each mode
  (Eq. 7). Eq. 6: ``p(y | x) = exp(−d_col² / 2σ_col²) · exp(−‖pos − pos_model‖² / 2σ_pos²)`` with
  ``pos_model`` the fused object matched to the mode; ``σ_pos²`` is widened by half the trace of the object's
  covariance (a camera-only object 60 m away is metres uncertain; D6's fixed 0.5 m let it drag the mode).
  Matching is a Hungarian assignment of modes to objects on the same negative log-likelihood (position from the
  predicted mode centre, gated at ``gate_m``; colour where both have one). A mode with no object this step (an
  occlusion) keeps its predicted particles, uniform. A share ``velocity_injection`` of a matched mode's particles
  takes the object's tracked velocity (a mixture proposal, Eq. 3's ``q``).
* **S3** systematic resampling within each mode, one k-means pass (each particle to the nearest mode centre,
  then ``n_particles`` per mode redrawn from the particles now labelled with it; skipped while modes are far
  apart; a mode not yet confirmed neither gives nor takes particles), merging of modes closer than
  ``d_merge_m`` for ``n_merge`` consecutive steps (the older id survives), deletion of a mode whose mean
  unnormalised likelihood stayed below ``tau_del`` for ``t_del_s`` seconds or whose centre left the ROI, and the
  colour update ``c ← 0.95 c + 0.05 c_obs`` when the likelihood is above ``colour_update_min``.

Departures from D6, each for a measured reason:

* Reacquisition (S0), and unconfirmed modes kept out of the k-means pass (S3): on ``benchmarks/traffic.py``'s 60 s
  roads a car braking to a stop while hidden (1.5 s) came back 3.5-5 m short of its mode's prediction and got a
  new id; and a camera-only mode born beside a coasting one (the hidden car's shadow) handed the coasting mode its
  broad prior's velocities through the k-means pass, sending it off the lane. (Clustering on position and
  velocity instead also kept that id, but made D8's jam 14-19 s late on two of three 120 s runs.)

* ``σ_v = 0.15 m/s`` per 25 Hz frame (D6: 0.5, i.e. 12 m/s² of random acceleration, far beyond a car's): with
  0.5 the velocity wanders ±2 m/s and D6's own test 1 (40 frames unseen) ends at 0.54 m RMSE, above its 0.5 m.

* Eq. 6's colour is a per-particle histogram of a box at each particle. Here the colour distance is that of the
  camera blob fused into the matched object: the same for every particle of a mode, so it shapes which object a
  mode takes (identity through an overtaking) and the mode's likelihood (deletion, colour update), not the spread
  of weights within a mode. Per-particle boxes would cost ``n_particles`` histograms per mode per frame.
* Deletion is timed in seconds (``t_del_s = 3``), not in frames (``N_del = 25``, 1 s at 25 Hz): a mode must coast
  through occlusions of up to 2 s (issue 8's target) whatever the sensor rates are.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..types import Event, ObjectClass, TrackState
from .association import hungarian
from .pf import standard_normal, systematic_resample

__all__ = ["FusedObject", "VehicleModeTracker", "VehiclePfParams", "bhattacharyya_distance"]

_FRAME_25HZ_S = 0.04


@dataclass(frozen=True, slots=True, eq=False)
class FusedObject:
    """One object model of D5 at one instant, in the road frame (what the particle filter observes).

    ``hist`` is a normalised colour histogram (or ``None`` without a camera); ``velocity_mps`` is ``None`` when no
    sensor tracked the object; ``box`` is ``(length, width, heading)``; ``sensors`` names the sensors fused.
    """

    position_m: np.ndarray
    covariance_m2: np.ndarray
    velocity_mps: np.ndarray | None = None
    hist: np.ndarray | None = None
    cls: str = ObjectClass.CAR
    confidence: float = 1.0
    sensors: tuple[str, ...] = ()
    box: np.ndarray | None = None
    box_px: dict[str, np.ndarray] | None = None


@dataclass(frozen=True, slots=True)
class VehiclePfParams:
    """D6 defaults (ALGORITHMS.md), global-frame variant; see the module docstring for the two departures."""

    n_particles: int = 150
    sigma_p_m: float = 0.2
    sigma_v_mps: float = 0.15
    sigma_col: float = 0.16
    sigma_pos_m: float = 0.5
    init_sigma_m: float = 0.5
    init_sigma_v_mps: float = 8.0
    gate_m: float = 3.0
    d_new_m: float = 2.0
    d_merge_m: float = 1.0
    n_merge: int = 5
    tau_del: float = 1e-3
    t_del_s: float = 3.0
    n_confirm: int = 3
    report_coast_s: float = 0.5
    min_spawn_confidence: float = 0.6
    velocity_injection: float = 0.1
    colour_rate: float = 0.05
    colour_update_min: float = 0.5
    max_dt_s: float = 0.5
    reacquire_m: float = 1.5
    seed: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "seed":
                continue
            if f.name in ("velocity_injection", "min_spawn_confidence"):
                if not (isinstance(v, int | float) and 0 <= v <= 1):
                    raise ConfigError(f"VehiclePfParams.{f.name}: expected a value in [0, 1], got {v!r}")
                continue
            if f.name in ("n_particles", "n_merge", "n_confirm"):
                if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                    raise ConfigError(f"VehiclePfParams.{f.name}: expected an integer >= 1, got {v!r}")
            elif not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"VehiclePfParams.{f.name}: expected a finite number > 0, got {v!r}")
        if self.colour_rate >= 1:
            raise ConfigError(f"VehiclePfParams.colour_rate: expected a value in (0, 1), got {self.colour_rate!r}")

    @classmethod
    def from_mapping(cls, values: dict[str, Any], source: str = "traffic.tracker") -> VehiclePfParams:
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - names)
        if unknown:
            raise ConfigError(f"{source}: unknown parameter(s) {unknown}; expected some of {sorted(names)}")
        return cls(**values)


def bhattacharyya_distance(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``sqrt(1 − BC)`` between normalised histograms (X4), broadcast over leading axes."""
    bc = np.sqrt(np.clip(p, 0, None) * np.clip(q, 0, None)).sum(axis=-1)
    return np.sqrt(np.clip(1.0 - bc, 0.0, 1.0))


class VehicleModeTracker:
    """Mixture particle filter over vehicle modes (module docstring). ``step(t_ns, objects) -> [TrackState]``.

    Parameters
    ----------
    params : VehiclePfParams
    roi_m : (k, 2) polygon, optional
        A mode whose centre leaves it is deleted (S3.4).
    sensor : str
        Name put on the track states and events.
    """

    def __init__(self, params: VehiclePfParams | None = None, roi_m: Any = None, sensor: str = "traffic") -> None:
        self.p = params or VehiclePfParams()
        self.roi = None if roi_m is None else np.asarray(roi_m, np.float64).reshape(-1, 2)
        if self.roi is not None and self.roi.shape[0] < 3:
            raise ConfigError(f"VehicleModeTracker roi_m: expected a polygon of >= 3 points, got {self.roi.shape[0]}")
        self.sensor = sensor
        self.rng = np.random.default_rng(self.p.seed)
        n = self.p.n_particles
        self.x = np.zeros((0, n, 4))
        self.ids = np.zeros(0, np.int64)
        self.hist: list[np.ndarray | None] = []
        self.cls: list[str] = []
        self.born_ns = np.zeros(0, np.int64)
        self.last_ok_ns = np.zeros(0, np.int64)
        self.seen_xy = np.zeros((0, 2))  # each mode's centre when it was last matched (reacquisition, S0)
        self.n_matched = np.zeros(0, np.int64)
        self.close_count: dict[tuple[int, int], int] = {}
        self.events: list[Event] = []
        self.dropped_steps = 0
        self._t: int | None = None
        self._next_id = itertools.count(1)
        self._roi_path: Any = None

    # ------------------------------------------------------------------ helpers
    def centres(self) -> np.ndarray:
        """Mode centres (weights are uniform after each resampling), ``(n_modes, 4)``."""
        return self.x.mean(axis=1)

    def _predict(self, dt: float) -> None:
        if not self.ids.size or dt <= 0:
            return
        s = math.sqrt(dt / _FRAME_25HZ_S)
        noise = standard_normal(self.rng, self.x.shape)
        self.x[..., 0:2] += self.x[..., 2:4] * dt + noise[..., 0:2] * (self.p.sigma_p_m * s)
        self.x[..., 2:4] += noise[..., 2:4] * (self.p.sigma_v_mps * s)

    def _match(self, objs: Sequence[FusedObject]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Hungarian modes -> objects on the Eq. 6 negative log-likelihood; returns (mode idx, object idx) and, for
        S2, the colour distances ``(n_modes, n_objects)`` and the position variances ``(n_objects,)`` it used."""
        n, k = self.ids.size, len(objs)
        if not n or not k:
            return np.zeros(0, np.intp), np.zeros(0, np.intp), None, None
        pos = np.array([o.position_m for o in objs])
        d = np.linalg.norm(self.centres()[:, None, 0:2] - pos[None], axis=2)
        var = self._pos_var(objs)
        dcol = self._colour_dist(objs)
        m2 = d**2 / var[None]
        cost = 0.5 * m2 + 0.5 * (dcol / self.p.sigma_col) ** 2
        cost[(d > self.p.gate_m) & (m2 > 9.0)] = np.inf  # an imprecise object may be 3 σ away (as in S0)
        pairs, _, _ = hungarian(cost, gate=np.inf)
        return pairs[:, 0], pairs[:, 1], dcol, var

    def _pos_var(self, objs: Sequence[FusedObject]) -> np.ndarray:
        """Per object, ``σ_pos² + ½ tr Σ_obj``: the position term of Eq. 6 widened by the object's own uncertainty."""
        return self.p.sigma_pos_m**2 + 0.5 * np.array([np.trace(o.covariance_m2) for o in objs])

    def _colour_dist(self, objs: Sequence[FusedObject]) -> np.ndarray:
        """(n_modes, n_objects) Bhattacharyya distances; 0 where a mode or an object has no colour."""
        n, k = self.ids.size, len(objs)
        out = np.zeros((n, k))
        has_m = [i for i in range(n) if self.hist[i] is not None]
        has_o = [j for j in range(k) if objs[j].hist is not None]
        if has_m and has_o:
            hm = np.stack([self.hist[i] for i in has_m])
            ho = np.stack([objs[j].hist for j in has_o])
            out[np.ix_(has_m, has_o)] = bhattacharyya_distance(hm[:, None], ho[None])
        return out

    def _inside_roi(self, xy: np.ndarray) -> np.ndarray:
        if self.roi is None or not xy.shape[0]:
            return np.ones(xy.shape[0], bool)
        if self._roi_path is None:
            from matplotlib.path import Path as _MplPath

            self._roi_path = _MplPath(self.roi)
        return self._roi_path.contains_points(xy)

    # ------------------------------------------------------------------ step
    def step(self, t_ns: int, objects: Sequence[FusedObject]) -> list[TrackState]:
        """Advance to ``t_ns`` with the fused objects of that instant; one state per confirmed mode."""
        t_ns = int(t_ns)
        self.events = []
        if self._t is not None and t_ns <= self._t:
            self.dropped_steps += 1
            return []
        dt = 0.0 if self._t is None else min((t_ns - self._t) / 1e9, self.p.max_dt_s)
        self._t = t_ns
        p = self.p
        self._predict(dt)                                                             # S1
        mi, oi, dcol_all, var_all = self._match(objects)
        n = self.ids.size
        lik = np.zeros(n)
        matched = np.zeros(n, bool)
        if mi.size:                                                                   # S2
            pos = np.array([objects[j].position_m for j in oi])
            dcol = dcol_all[mi, oi]
            d2 = ((self.x[mi, :, 0:2] - pos[:, None, :]) ** 2).sum(axis=2)
            col = np.exp(-0.5 * (dcol / p.sigma_col) ** 2)
            var = var_all[oi]
            w_pos = np.exp(-0.5 * d2 / var[:, None])
            w = w_pos * col[:, None]
            lik[mi] = w_pos.mean(axis=1)  # deletion and colour update: the position term (two cameras see a car
            matched[mi] = True             # from front and back; their colours differ more than σ_col allows)
            ok = w.sum(axis=1) > 0
            wn = np.where(ok[:, None], w, 1.0)
            idx = systematic_resample(wn, self.rng, flat_out=True)                   # S3.1
            self.x[mi] = self.x[mi].reshape(-1, 4)[idx].reshape(mi.size, p.n_particles, 4)
            self._inject_velocity(mi, [objects[j] for j in oi])
            for m, j, lk in zip(mi, oi, lik[mi], strict=True):
                o = objects[j]
                if o.hist is not None and (self.hist[m] is None or lk > p.colour_update_min):
                    h = o.hist if self.hist[m] is None else (1 - p.colour_rate) * self.hist[m] + p.colour_rate * o.hist
                    self.hist[m] = h / max(h.sum(), 1e-12)
                if o.cls != ObjectClass.UNKNOWN:
                    self.cls[m] = str(o.cls)
            good = lik >= p.tau_del
            self.last_ok_ns[good] = t_ns
            self.n_matched[matched] += 1
        self._recluster()                                                             # S3.2
        sensors_of = {int(self.ids[m]): objects[j].sensors for m, j in zip(mi, oi, strict=True)}
        self._merge_and_delete(t_ns)                                                  # S3.3, S3.4
        self._spawn(t_ns, objects, oi)                                                # S0
        ok_now = self.last_ok_ns == t_ns
        if ok_now.any():
            self.seen_xy[ok_now] = self.centres()[ok_now, 0:2]
        return self._states(t_ns, sensors_of)

    def _inject_velocity(self, modes: np.ndarray, objs: Sequence[FusedObject]) -> None:
        """A share ``velocity_injection`` of each matched mode's particles takes the object's tracked velocity
        (plus noise): the mixture proposal of Eq. 3. Without it a braking car's mode keeps its speed (the
        random walk of σ_v cannot follow 2.5 m/s², and resampling narrows the velocities further)."""
        k = round(self.p.velocity_injection * self.p.n_particles)
        if k == 0:
            return
        for m, o in zip(modes, objs, strict=True):
            if o.velocity_mps is None:
                continue
            sel = self.rng.choice(self.p.n_particles, k, replace=False)
            self.x[m, sel, 2:4] = o.velocity_mps + standard_normal(self.rng, (k, 2)) * self.p.sigma_v_mps

    def _recluster(self) -> None:
        """One k-means pass: each particle to its nearest mode centre, then each mode redrawn from its particles."""
        n, npart = self.ids.size, self.p.n_particles
        if n < 2:
            return
        c = self.centres()[:, 0:2]
        # modes far apart (every particle nearer its own centre than half the distance to any other centre, the
        # usual case) exchange nothing: the pass is skipped
        d_own = np.sqrt(((self.x[:, :, 0:2] - c[:, None]) ** 2).sum(axis=2).max(axis=1))
        gap = np.linalg.norm(c[:, None] - c[None], axis=2)
        np.fill_diagonal(gap, np.inf)
        if np.all(d_own < 0.49 * gap.min(axis=1)):
            return
        flat = self.x.reshape(-1, 4)
        dx = flat[:, 0, None] - c[None, :, 0]
        dy = flat[:, 1, None] - c[None, :, 1]
        d2 = dx * dx + dy * dy
        own = np.repeat(np.arange(n), npart)
        # a mode not yet confirmed is a broad prior, not evidence: it keeps its particles and takes no other's (a
        # newborn's velocities, drawn from N(0, init_sigma_v²), would otherwise pass to a coasting neighbour)
        young = self.n_matched < self.p.n_confirm
        if young.any():
            d2[:, young] = np.inf
        near = np.argmin(d2, axis=1)
        if young.any():
            near[young[own]] = own[young[own]]
        if (near == own).all():
            return
        W = (near[None, :] == np.arange(n)[:, None]).astype(np.float64)
        keep = W.sum(axis=1) < npart / 4  # a mode left with too few particles keeps its own (no silent take-over)
        if keep.any():
            W[keep] = (own[None, :] == np.flatnonzero(keep)[:, None]).astype(np.float64)
        idx = systematic_resample(W, self.rng, n=npart, flat_out=True) % flat.shape[0]
        self.x = flat[idx].reshape(n, npart, 4)

    def _merge_and_delete(self, t_ns: int) -> None:
        n = self.ids.size
        if not n:
            return
        p = self.p
        c = self.centres()[:, 0:2]
        drop = np.zeros(n, bool)
        if n > 1:
            d = np.linalg.norm(c[:, None] - c[None], axis=2)
            close = {(int(self.ids[a]), int(self.ids[b])) for a, b in zip(*np.nonzero(np.triu(d < p.d_merge_m, 1)),
                                                                          strict=True)}
            self.close_count = {k: self.close_count.get(k, 0) + 1 for k in close}
            pos = {int(i): k for k, i in enumerate(self.ids)}
            for (a, b), cnt in self.close_count.items():
                if cnt >= p.n_merge:
                    ia, ib = pos[a], pos[b]
                    young = ib if (self.born_ns[ib], b) > (self.born_ns[ia], a) else ia
                    old = ia if young == ib else ib
                    if not drop[old]:
                        drop[young] = True
                        self.events.append(Event(t_ns, self.sensor, "mode_merged", track_ids=(int(self.ids[old]),
                                                                                              int(self.ids[young]))))
        stale = (t_ns - self.last_ok_ns) > p.t_del_s * 1e9
        gone = ~self._inside_roi(c)
        for i in np.flatnonzero((stale | gone) & ~drop):
            self.events.append(Event(int(self.last_ok_ns[i]), self.sensor, "left_roi" if gone[i] else "lost", t_ns,
                                     position_m=c[i], track_ids=(int(self.ids[i]),)))
        drop |= stale | gone
        if drop.any():
            keep = ~drop
            dropped = set(self.ids[drop].tolist())
            self.close_count = {k: v for k, v in self.close_count.items() if not dropped & set(k)}
            self.x, self.ids = self.x[keep], self.ids[keep]
            self.born_ns, self.last_ok_ns, self.n_matched = self.born_ns[keep], self.last_ok_ns[keep], \
                self.n_matched[keep]
            self.seen_xy = self.seen_xy[keep]
            self.hist = [h for h, k in zip(self.hist, keep, strict=True) if k]
            self.cls = [c_ for c_, k in zip(self.cls, keep, strict=True) if k]

    def _spawn(self, t_ns: int, objects: Sequence[FusedObject], taken: np.ndarray) -> None:
        p = self.p
        unclaimed = np.ones(len(objects), bool)
        unclaimed[np.asarray(taken, np.intp)] = False
        free = np.flatnonzero(unclaimed)
        centres = self.centres()[:, 0:2]
        reacquired: set[int] = set()
        for j in free:
            o = objects[j]
            if o.confidence < p.min_spawn_confidence or not self._inside_roi(o.position_m[None])[0]:
                continue
            k = self._reacquirable(t_ns, o, centres, reacquired)
            if k is not None:
                self._reacquire(t_ns, k, o)
                reacquired.add(k)
                centres[k] = o.position_m  # where it is now, for the objects after this one
                continue
            reach = max(p.d_new_m, 3.0 * math.sqrt(0.5 * np.trace(o.covariance_m2)))  # an imprecise object: 3 σ
            if centres.shape[0] and np.min(np.linalg.norm(centres - o.position_m, axis=1)) < reach:
                continue
            x = np.empty((1, p.n_particles, 4))
            x[0, :, 0:2] = o.position_m + standard_normal(self.rng, (p.n_particles, 2)) * p.init_sigma_m
            if o.velocity_mps is None:  # unknown: a broad prior the first updates narrow down
                x[0, :, 2:4] = standard_normal(self.rng, (p.n_particles, 2)) * p.init_sigma_v_mps
            else:
                x[0, :, 2:4] = o.velocity_mps
            self.x = np.concatenate([self.x, x])
            tid = next(self._next_id)
            self.ids = np.append(self.ids, tid)
            self.hist.append(None if o.hist is None else o.hist / max(float(o.hist.sum()), 1e-12))
            self.cls.append(str(o.cls))
            self.born_ns = np.append(self.born_ns, t_ns)
            self.last_ok_ns = np.append(self.last_ok_ns, t_ns)
            self.seen_xy = np.vstack([self.seen_xy, o.position_m])
            self.n_matched = np.append(self.n_matched, 1)
            centres = np.vstack([centres, o.position_m])
            self.events.append(Event(t_ns, self.sensor, "born", position_m=o.position_m, track_ids=(tid,)))

    def _reacquirable(self, t_ns: int, o: FusedObject, centres: np.ndarray, taken: set[int]) -> int | None:
        """The coasting mode (unmatched for over 0.1 s) whose path since it was last seen passes within
        ``reacquire_m`` of an object no mode claimed — the segment from where it was last matched to where
        constant velocity has carried it: a vehicle that braked (or stopped) while hidden is on it; the nearest
        such, or None. Colour is not asked: the two cameras see a car from front and back, and after a light
        change, in colours further apart than ``σ_col`` allows (as for S2's likelihood)."""
        p = self.p
        coasting = np.flatnonzero((t_ns - self.last_ok_ns) > 100_000_000)
        coasting = coasting[~np.isin(coasting, list(taken))]
        if not coasting.size:
            return None
        a, b = self.seen_xy[coasting], centres[coasting]
        ab = b - a
        L2 = np.einsum("ij,ij->i", ab, ab)
        u = np.clip(np.einsum("ij,ij->i", o.position_m - a, ab) / np.maximum(L2, 1e-9), -0.1, 1.1)
        d = np.linalg.norm(o.position_m - (a + u[:, None] * ab), axis=1)
        i = int(np.argmin(d))
        return int(coasting[i]) if d[i] < p.reacquire_m else None

    def _reacquire(self, t_ns: int, k: int, o: FusedObject) -> None:
        """Mode ``k`` takes up again at object ``o``: particles redrawn there (velocity from the object when
        known, else half the mode's: it was found short of its prediction), its id and colour kept."""
        p = self.p
        self.x[k, :, 0:2] = o.position_m + standard_normal(self.rng, (p.n_particles, 2)) * p.init_sigma_m
        if o.velocity_mps is not None:
            self.x[k, :, 2:4] = o.velocity_mps
        else:
            self.x[k, :, 2:4] *= 0.5
        self.last_ok_ns[k] = t_ns
        self.events.append(Event(t_ns, self.sensor, "reacquired", position_m=o.position_m,
                                 track_ids=(int(self.ids[k]),)))

    def _states(self, t_ns: int, sensors_of: dict[int, tuple[str, ...]]) -> list[TrackState]:
        out = []
        if not self.ids.size:
            return out
        mean = self.centres()
        dx = self.x - mean[:, None]
        cov = np.einsum("mpi,mpj->mij", dx, dx) / max(self.p.n_particles - 1, 1)
        fresh = (t_ns - self.last_ok_ns) <= self.p.report_coast_s * 1e9
        for i in np.flatnonzero((self.n_matched >= self.p.n_confirm) & fresh):
            sensors = sensors_of.get(int(self.ids[i]), ())
            out.append(TrackState.trusted(t_ns, self.sensor, int(self.ids[i]), mean[i, 0:2], mean[i, 2:4], cov[i],
                                          cls=self.cls[i], sensors=tuple(sensors), score=1.0 if sensors else 0.5))
        return out

    def finish(self) -> list[Event]:
        """Nothing is left open at the end of a run (interface parity with the other trackers)."""
        return []
