"""Thin-plate-spline correction of a dead-reckoned trajectory (seed 002 Eqs. 4–8; ALGORITHMS.md C8).

Control pairs are (dead-reckoned position, observed position) at the same instant -- the observed one
from an RGB-D camera in seed 002. A warp ``f`` with ``f(M_1j) ≈ M_2j`` and least bending energy is
fitted with :class:`scipy.interpolate.RBFInterpolator` (``kernel="thin_plate_spline"``, affine
polynomial part), and applied to the trajectory.

Kernel and smoothing (ALGORITHMS.md E2, E3): scipy's thin-plate kernel is ``r² log r``, half of
Bookstein's ``U = r² log r²``; the factor goes into the weights, so the interpolant is the same. Its
``smoothing`` ``s`` enters as ``K + s·I``; C8's regularised fit (Eq. 8 with the squared norm and the
``1/M`` factor) solves ``U + Mλ·I``, so ``s = M·λ/2``. ``smoothing=0`` interpolates exactly. The seed's
printed kernel ``||P − M_1j||`` (E2) is ``kernel="linear"`` (``−r``) here, kept only for comparison.

Degenerate control sets (C8 edge cases) use an affine fallback instead of the spline: nothing
(identity) for no point, a translation for one, a rigid motion (Kabsch, X7) for two or for points
that are (nearly) collinear -- a full affine map is undetermined across the line they lie on.

Applying it: :func:`correct_trajectory` either re-maps the whole trajectory with the fit of all
control points (C8, "re-fit using all control points ... re-map the whole stored trajectory"), or
causally: from each control point on, with the fit of the control points seen so far, continuing
the dead reckoning from the corrected position of the latest control point (C8, "after the last
control point"), turned by the heading error seen during the latest pass of control points (a rigid
fit of that pass; C8's optional heading fix, which suggests the warp's local Jacobian instead -- also
available, but the spline bends at the end of a cluster of control points and the turn it gives
there can be far off).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.spatial import cKDTree

from ..errors import CalibrationError
from ..geometry import fit_rigid_2d

__all__ = ["Correction", "control_pairs", "correct_trajectory", "fit_correction"]

log = logging.getLogger(__name__)

KINDS = ("identity", "translation", "rigid", "tps")
ROTATIONS = ("pass", "warp", "none")


def _xy(value: Any, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name}: expected an array of shape (m, 2), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: row {int(np.flatnonzero(~np.isfinite(arr).all(1))[0])} is not finite")
    return arr


@dataclass(frozen=True, slots=True, eq=False)
class Correction:
    """A fitted warp of the floor plane; call it on ``(k, 2)`` points.

    Attributes
    ----------
    kind : {"identity", "translation", "rigid", "tps"}
    src_m, dst_m : (m, 2) float64
        The control pairs used (after de-duplication).
    R : (2, 2) float64
        Rotation of the affine fallback (identity for ``"tps"``).
    t : (2,) float64
        Translation of the affine fallback.
    smoothing : float
        ``RBFInterpolator`` smoothing of the spline.
    """

    kind: str
    src_m: np.ndarray
    dst_m: np.ndarray
    R: np.ndarray = field(default_factory=lambda: np.eye(2))
    t: np.ndarray = field(default_factory=lambda: np.zeros(2))
    smoothing: float = 0.0
    rbf: RBFInterpolator | None = None

    def __call__(self, xy_m: Any) -> np.ndarray:
        """Warp points ``(k, 2)`` -> ``(k, 2)`` (also ``(2,)`` -> ``(2,)``)."""
        p = np.asarray(xy_m, dtype=np.float64)
        flat = p.reshape(-1, 2)
        if self.rbf is None:
            return (flat @ self.R.T + self.t).reshape(p.shape)
        return (self.rbf(flat) if flat.shape[0] else flat.copy()).reshape(p.shape)

    def rotation_at(self, xy_m: Any, delta_m: float = 0.5) -> np.ndarray:
        """Angle of the local rotation of the warp at points ``(k, 2)`` -> ``(k,)`` rad.

        The rotation part (polar decomposition) of the Jacobian, by central differences of ``±delta_m``.
        """
        p = _xy(np.atleast_2d(xy_m), "xy_m")
        if self.rbf is None:
            return np.full(p.shape[0], np.arctan2(self.R[1, 0], self.R[0, 0]))
        e = np.array([[delta_m, 0.0], [0.0, delta_m]])
        cols = [(self(p + e[i]) - self(p - e[i])) / (2 * delta_m) for i in range(2)]
        J = np.stack(cols, axis=-1)  # (k, 2, 2), columns d f / dx, d f / dy
        # rotation of the closest orthogonal matrix: atan2 of the antisymmetric over the symmetric part
        return np.arctan2(J[:, 1, 0] - J[:, 0, 1], J[:, 0, 0] + J[:, 1, 1])


def fit_correction(src_m: Any, dst_m: Any, *, smoothing: float = 0.0, kernel: str = "thin_plate_spline",
                   collinear_ratio: float = 0.05, dedupe_m: float = 0.01) -> Correction:
    """Fit the warp taking dead-reckoned ``src_m`` to observed ``dst_m`` (ALGORITHMS.md C8).

    Parameters
    ----------
    src_m : (m, 2) float
        Dead-reckoned positions ``M_1``, m.
    dst_m : (m, 2) float
        Observed positions ``M_2`` at the same instants, m.
    smoothing : float
        ``RBFInterpolator`` smoothing, ``>= 0`` (``= M·λ/2`` of C8; 0 interpolates exactly).
    kernel : str
        ``RBFInterpolator`` kernel; ``"thin_plate_spline"`` (C8), ``"linear"`` for the seed's ``|r|``.
    collinear_ratio : float
        Points whose centred singular values have ratio (smallest / largest) below this are
        collinear (C8: 0.05), and get the rigid fallback.
    dedupe_m : float
        Control points closer than this to an earlier one are dropped (C8: 1 cm), since duplicates
        make the spline system singular.

    Returns
    -------
    Correction
    """
    src, dst = _xy(src_m, "src_m"), _xy(dst_m, "dst_m")
    if src.shape != dst.shape:
        raise ValueError(f"src_m, dst_m: expected the same shape, got {src.shape} and {dst.shape}")
    if not np.isfinite(smoothing) or smoothing < 0:
        raise ValueError(f"smoothing: expected a finite value >= 0, got {smoothing!r}")
    if not 0 <= collinear_ratio < 1:
        raise ValueError(f"collinear_ratio: expected a value in [0, 1), got {collinear_ratio!r}")
    if src.shape[0] > 1 and dedupe_m > 0:
        pairs = cKDTree(src).query_pairs(dedupe_m, output_type="ndarray")
        if pairs.size:
            keep = np.ones(src.shape[0], bool)
            keep[pairs.max(axis=1)] = False
            log.debug("fit_correction: %d duplicate control point(s) dropped", int((~keep).sum()))
            src, dst = src[keep], dst[keep]
    m = src.shape[0]
    if m == 0:
        return Correction("identity", src, dst)
    if m == 1:
        return Correction("translation", src, dst, np.eye(2), dst[0] - src[0])
    sv = np.linalg.svd(src - src.mean(axis=0), compute_uv=False)
    if m == 2 or sv[-1] < collinear_ratio * sv[0]:
        try:
            R, t = fit_rigid_2d(src, dst)
        except CalibrationError:  # dst all at one place: a translation is all there is
            return Correction("translation", src, dst, np.eye(2), dst.mean(axis=0) - src.mean(axis=0))
        return Correction("rigid", src, dst, R, t)
    try:
        rbf = RBFInterpolator(src, dst, kernel=kernel, smoothing=smoothing, degree=1)
    except (ValueError, np.linalg.LinAlgError) as err:
        raise ValueError(f"kernel, smoothing: the spline cannot be fitted to {m} control points ({err})") from err
    return Correction("tps", src, dst, smoothing=float(smoothing), rbf=rbf)


def control_pairs(traj_t_ns: Any, traj_xy_m: Any, obs_t_ns: Any, obs_xy_m: Any, *,
                  min_spacing_m: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pair observations with the dead-reckoned trajectory at the same times (ALGORITHMS.md C8, Eq. 4).

    The trajectory is interpolated linearly at each observation time (observations outside its time
    span are dropped); then observations are thinned so consecutive kept ones are at least
    ``min_spacing_m`` apart (in the observed positions).

    Parameters
    ----------
    traj_t_ns : (n,) int
        Times of the trajectory knots, non-decreasing.
    traj_xy_m : (n, 2) float
        Dead-reckoned positions.
    obs_t_ns : (m,) int
        Observation times, non-decreasing.
    obs_xy_m : (m, 2) float
        Observed positions.
    min_spacing_m : float
        C8: 0.5 m.

    Returns
    -------
    t_ns : (j,) int64
    src_m : (j, 2) float64
        Dead-reckoned positions at ``t_ns``.
    dst_m : (j, 2) float64
        Observed positions.
    """
    tt = np.asarray(traj_t_ns, dtype=np.int64)
    traj = _xy(traj_xy_m, "traj_xy_m")
    to = np.asarray(obs_t_ns, dtype=np.int64)
    obs = _xy(obs_xy_m, "obs_xy_m")
    if tt.ndim != 1 or tt.size != traj.shape[0] or tt.size == 0:
        raise ValueError(f"traj_t_ns: expected ({traj.shape[0]},) times matching traj_xy_m, got {tt.shape}")
    if to.ndim != 1 or to.size != obs.shape[0]:
        raise ValueError(f"obs_t_ns: expected ({obs.shape[0]},) times matching obs_xy_m, got {to.shape}")
    for name, t in (("traj_t_ns", tt), ("obs_t_ns", to)):
        if np.any(np.diff(t) < 0):
            raise ValueError(f"{name}: times must be non-decreasing")
    if not np.isfinite(min_spacing_m) or min_spacing_m < 0:
        raise ValueError(f"min_spacing_m: expected a finite value >= 0, got {min_spacing_m!r}")
    inside = (to >= tt[0]) & (to <= tt[-1])
    to, obs = to[inside], obs[inside]
    x = (to - tt[0]) * 1e-9
    kx = (tt - tt[0]) * 1e-9
    src = np.stack([np.interp(x, kx, traj[:, 0]), np.interp(x, kx, traj[:, 1])], axis=1)
    keep = []
    last = None
    for i, p in enumerate(obs):  # greedy thinning: sequential by definition, m is small
        if last is None or np.hypot(*(p - last)) >= min_spacing_m:
            keep.append(i)
            last = p
    k = np.asarray(keep, dtype=np.int64)
    return to[k], src[k], obs[k]


def _pass_rotation(src: np.ndarray, dst: np.ndarray, min_extent_m: float) -> float:
    """Angle of the rigid fit (X7) of a pass of control points; 0 when they span too little to say."""
    if src.shape[0] < 2 or float(np.ptp(src, axis=0).max()) < min_extent_m:
        return 0.0
    try:
        R, _ = fit_rigid_2d(src, dst)
    except CalibrationError:
        return 0.0
    return float(np.arctan2(R[1, 0], R[0, 0]))


def correct_trajectory(t_ns: Any, xy_m: Any, control_t_ns: Any, control_src_m: Any, control_dst_m: Any, *,
                       smoothing: float = 0.0, causal: bool = True, rotate: str = "pass", pass_s: float = 10.0,
                       min_pass_extent_m: float = 1.0, **fit_kwargs: Any) -> np.ndarray:
    """Apply the C8 correction to a whole trajectory.

    Parameters
    ----------
    t_ns : (n,) int
        Trajectory times, non-decreasing.
    xy_m : (n, 2) float
        Dead-reckoned positions.
    control_t_ns : (m,) int
        Times of the control pairs, non-decreasing (e.g. from :func:`control_pairs`).
    control_src_m, control_dst_m : (m, 2) float
        Dead-reckoned and observed positions at ``control_t_ns``.
    smoothing : float
        Spline smoothing (see :func:`fit_correction`).
    causal : bool
        ``False``: one fit of all control points re-maps every position (C8, offline). ``True``:
        positions before the first control point are unchanged; from control point ``j`` on (until
        the next one) the fit ``f_j`` of control points ``1..j`` is used, and the dead reckoning
        continues from the corrected latest control point (C8, "after the last control point"):
        ``x' = f_j(s_j) + R_j (x − s_j)``. At a control point itself this is ``f_j(s_j)``, which is
        ``d_j`` when ``smoothing = 0``.
    rotate : {"pass", "warp", "none"}
        ``R_j`` (C8's optional heading fix): ``"pass"``, the rotation of a rigid fit (X7) of the control
        pairs of the last ``pass_s`` seconds, when they span at least ``min_pass_extent_m`` (the
        heading error of the dead reckoning during the current pass); ``"warp"``, the local rotation
        of ``f_j`` at ``s_j`` (C8's Jacobian; unreliable at the end of a cluster of control points,
        where the spline bends); ``"none"``, no turn.
    pass_s, min_pass_extent_m : float
        See ``rotate="pass"``.
    **fit_kwargs
        Passed to :func:`fit_correction` (``kernel``, ``collinear_ratio``, ``dedupe_m``).

    Returns
    -------
    (n, 2) float64
        Corrected positions.
    """
    t = np.asarray(t_ns, dtype=np.int64)
    xy = _xy(xy_m, "xy_m")
    tc = np.asarray(control_t_ns, dtype=np.int64)
    src, dst = _xy(control_src_m, "control_src_m"), _xy(control_dst_m, "control_dst_m")
    if t.ndim != 1 or t.size != xy.shape[0]:
        raise ValueError(f"t_ns: expected ({xy.shape[0]},) times matching xy_m, got {t.shape}")
    if tc.ndim != 1 or tc.size != src.shape[0] or src.shape != dst.shape:
        raise ValueError(f"control_t_ns, control_src_m, control_dst_m: expected (m,), (m, 2), (m, 2), got "
                         f"{tc.shape}, {src.shape}, {dst.shape}")
    if np.any(np.diff(tc) < 0) or np.any(np.diff(t) < 0):
        raise ValueError("t_ns, control_t_ns: times must be non-decreasing")
    if rotate not in ROTATIONS:
        raise ValueError(f"rotate: expected one of {ROTATIONS}, got {rotate!r}")
    if not np.isfinite(pass_s) or pass_s <= 0:
        raise ValueError(f"pass_s: expected a finite value > 0, got {pass_s!r}")
    if not causal:
        return fit_correction(src, dst, smoothing=smoothing, **fit_kwargs)(xy)
    out = xy.copy()
    # samples in [tc_j, tc_{j+1}) use the fit of control points 0..j (several pairs at one instant are
    # one update: searchsorted picks the last of them)
    seg = np.searchsorted(tc, t, side="right") - 1
    for j in np.unique(seg[seg >= 0]):
        f = fit_correction(src[: j + 1], dst[: j + 1], smoothing=smoothing, **fit_kwargs)
        anchor_src = src[j]
        if rotate == "pass":
            recent = slice(int(np.searchsorted(tc, tc[j] - round(pass_s * 1e9), side="left")), j + 1)
            a = _pass_rotation(src[recent], dst[recent], min_pass_extent_m)
        elif rotate == "warp":
            a = float(f.rotation_at(anchor_src)[0])
        else:
            a = 0.0
        c, s = np.cos(a), np.sin(a)
        sel = seg == j
        out[sel] = f(anchor_src) + (xy[sel] - anchor_src) @ np.array([[c, -s], [s, c]]).T
    return out
