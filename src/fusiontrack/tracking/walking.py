"""Motion models for the particle filters: the two-feet walking model (people) and constant velocity.

Seed 001, two-feet walking model; ALGORITHMS.md B8 (kinematics RECON) and B18 (CV for bicycles and
cars, process noise of X5).

Walking state
-------------
One particle is 8 floats, packed as ``(n_t, n_p, 8)`` float64 with these columns:

====  ==========  =========================================================
col   name        meaning
====  ==========  =========================================================
0, 1  ``LX, LY``  left foot position ``p^L`` (m, world floor frame)
2, 3  ``RX, RY``  right foot position ``p^R`` (m)
4     ``PSI``     heading ψ (rad, in (-π, π]); walking direction ``u = (cos ψ, sin ψ)``
5     ``PHI``     gait phase φ (rad, in (-π, π])
6     ``PERIOD``  walking period T (s), kept in [0.8, 1.6]
7     ``STRIDE``  stride S (m), kept in [0.4, 2.0]
====  ==========  =========================================================

The paper's foot accelerations ``a^L, a^R`` are functions of (φ, ψ, T, S) and are not stored:
:func:`foot_accelerations` recomputes them (ALGORITHMS.md E10).

Kinematics: ``v^L = (S/T)(1 + sin φ) u``, ``v^R = (S/T)(1 - sin φ) u``, ``a^L = -a^R = A cos φ u`` with
``A = 2πS/T²``; the signed separation ``(p^L - p^R)·u`` follows ``-(S/π) cos φ``. Swapping the two
feet is the same as shifting φ by π, so the left/right labelling of a detection does not matter.

Constant-velocity state
-----------------------
``(n_t, n_p, 4)`` float64: ``x, y`` (m), ``vx, vy`` (m/s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import _jit
from .pf import standard_normal

__all__ = [
    "LEFT",
    "LX",
    "LY",
    "PERIOD",
    "PERIOD_RANGE_S",
    "PHI",
    "PSI",
    "RIGHT",
    "RX",
    "RY",
    "STANDING_SPEED_MPS",
    "STATE_DIM",
    "STRIDE",
    "STRIDE_RANGE_M",
    "StandingNoise",
    "WalkingNoise",
    "body_position",
    "foot_accelerations",
    "foot_velocities",
    "heading_from_displacement",
    "init_cv",
    "init_walking",
    "predict_cv",
    "predict_people",
    "predict_people_cols",
    "predict_standing",
    "predict_walking",
    "predicted_feet_distance",
    "signed_separation",
    "update_standing",
]

LX, LY, RX, RY, PSI, PHI, PERIOD, STRIDE = range(8)
STATE_DIM = 8
LEFT = slice(0, 2)
RIGHT = slice(2, 4)
PERIOD_RANGE_S = (0.8, 1.6)
STRIDE_RANGE_M = (0.4, 2.0)
STANDING_SPEED_MPS = 0.1  # B8 "standing people"
TWO_PI = 2.0 * np.pi


def _wrap(a: np.ndarray) -> np.ndarray:
    """Wrap to ``(-π, π]`` (ALGORITHMS.md 0.2); as ``geometry.wrap_angle``, a little faster than ``np.mod``."""
    return a + TWO_PI * np.floor((np.pi - a) * (1.0 / TWO_PI))


def _sincos(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``sin a, cos a`` evaluated in float32, returned as float64.

    numpy vectorises float32 trigonometry (SIMD) but not float64, a 5-10x difference on the hot path.
    The angles are wrapped (|a| <= π + noise), so the float32 rounding of the argument is < 3e-7 rad:
    a 0.1 m step moves < 3e-8 m off course, far below the 2 cm process noise.
    """
    a32 = a.astype(np.float32)
    return np.sin(a32).astype(np.float64), np.cos(a32).astype(np.float64)


def _check_rng(rng: np.random.Generator) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    return rng


def _check_state(state: np.ndarray, dim: int, name: str = "state") -> np.ndarray:
    x = np.asarray(state, dtype=np.float64)
    if x.ndim != 3 or x.shape[-1] != dim:
        raise ValueError(f"{name}: expected shape (n_t, n_p, {dim}), got {x.shape}")
    return x


@dataclass(frozen=True, slots=True)
class WalkingNoise:
    """Per-step process noise of the walking model (B8 defaults, standard deviations).

    Attributes
    ----------
    phase_rad, heading_rad, period_s, stride_m, foot_m : float
        σ of ``n_φ``, ``n_ψ``, ``n_T``, ``n_S`` and of each coordinate of ``n_p`` (both feet independently).
    dt_ref_s : float or None
        ``None`` (B8): the σ are per propagation step whatever ``Δt`` is. A value (e.g. 0.04 s, the
        25 Hz frame interval the defaults were set for) scales every σ by ``sqrt(Δt / dt_ref_s)``, the
        right thing when scans arrive at irregular intervals.
    """

    phase_rad: float = 0.1
    heading_rad: float = float(np.deg2rad(3.0))
    period_s: float = 0.02
    stride_m: float = 0.03
    foot_m: float = 0.02
    dt_ref_s: float | None = None

    @classmethod
    def zero(cls) -> WalkingNoise:
        """No noise: the deterministic kinematics."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0)

    def scale(self, dt_s: float) -> float:
        # math.sqrt: correctly rounded as np.sqrt, without the numpy scalar round trip
        return 1.0 if self.dt_ref_s is None else math.sqrt(max(dt_s, 0.0) / self.dt_ref_s)


@dataclass(frozen=True, slots=True)
class StandingNoise:
    """Random-walk noise for people standing still (B8 "standing people", RECON values).

    Attributes
    ----------
    body_m : float
        σ of a displacement shared by both feet per step (the person shifts), m.
    foot_m : float
        σ of each foot's own displacement per step, m.
    heading_rad, phase_rad : float
        σ of the random walk of ψ and φ per step (keeps diversity for when the person walks off).
    dt_ref_s : float or None
        As in :class:`WalkingNoise`.
    """

    body_m: float = 0.03
    foot_m: float = 0.01
    heading_rad: float = float(np.deg2rad(10.0))
    phase_rad: float = 0.1
    dt_ref_s: float | None = None

    def scale(self, dt_s: float) -> float:
        # math.sqrt: correctly rounded as np.sqrt, without the numpy scalar round trip
        return 1.0 if self.dt_ref_s is None else math.sqrt(max(dt_s, 0.0) / self.dt_ref_s)


# --------------------------------------------------------------------------------------------------
# Kinematics of the walking state
# --------------------------------------------------------------------------------------------------


def foot_velocities(state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Foot velocities ``v^L = (S/T)(1 + sin φ) u`` and ``v^R = (S/T)(1 - sin φ) u`` (B8).

    Parameters
    ----------
    state : (..., 8) float
        Walking state.

    Returns
    -------
    v_left, v_right : (..., 2) float64, m/s
    """
    x = np.asarray(state, dtype=np.float64)
    u = np.stack([np.cos(x[..., PSI]), np.sin(x[..., PSI])], axis=-1)
    mean_speed = x[..., STRIDE] / x[..., PERIOD]
    s = np.sin(x[..., PHI])
    return (mean_speed * (1.0 + s))[..., None] * u, (mean_speed * (1.0 - s))[..., None] * u


def foot_accelerations(state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Foot accelerations ``a^L = A cos φ u = -a^R`` with ``A = 2πS/T²`` (B8).

    Returns
    -------
    a_left, a_right : (..., 2) float64, m/s²
    """
    x = np.asarray(state, dtype=np.float64)
    u = np.stack([np.cos(x[..., PSI]), np.sin(x[..., PSI])], axis=-1)
    a = (TWO_PI * x[..., STRIDE] / x[..., PERIOD] ** 2 * np.cos(x[..., PHI]))[..., None] * u
    return a, -a


def body_position(state: np.ndarray) -> np.ndarray:
    """The feet midpoint (B10 "body position"), ``(..., 2)`` m."""
    x = np.asarray(state, dtype=np.float64)
    return 0.5 * (x[..., LEFT] + x[..., RIGHT])


def signed_separation(state: np.ndarray) -> np.ndarray:
    """``(p^L - p^R)·u``, the fore-aft separation of the feet along the heading, ``(...)`` m."""
    x = np.asarray(state, dtype=np.float64)
    d = x[..., LEFT] - x[..., RIGHT]
    return d[..., 0] * np.cos(x[..., PSI]) + d[..., 1] * np.sin(x[..., PSI])


def predicted_feet_distance(phase_rad: np.ndarray, stride_m: np.ndarray, kappa: float = 1.0 / np.pi,
                            lateral_m: float = 0.0) -> np.ndarray:
    """Predicted inter-feet distance ``D_pred(φ) = κ S |cos φ|`` (B8, used by B9's ``P_walk``).

    Parameters
    ----------
    phase_rad, stride_m : array_like, broadcastable
        Gait phase φ (rad) and stride S (m).
    kappa : float
        ``1/π`` for B8's kinematics; ≈ 0.5 if calibrated on real gait.
    lateral_m : float
        Side-by-side distance of the feet (across the heading). B8 has none (0); the simulator's
        walkers keep their feet 0.2 m apart laterally, and then the distance a detection measures is
        ``sqrt((κ S cos φ)² + lateral²)``.

    Returns
    -------
    distance : float64 array, m
        ``cos φ`` is evaluated in float32 (for speed): relative error < 3e-7, i.e. < 1 µm.
    """
    cos = np.cos(np.asarray(phase_rad, np.float64).astype(np.float32)).astype(np.float64)  # _sincos's cos alone
    along = kappa * np.asarray(stride_m, dtype=np.float64) * np.abs(cos)
    return along if lateral_m == 0.0 else np.hypot(along, lateral_m)


# --------------------------------------------------------------------------------------------------
# Propagation
# --------------------------------------------------------------------------------------------------


def predict_walking(state: np.ndarray, dt_s: float, rng: np.random.Generator,
                    noise: WalkingNoise | None = None) -> np.ndarray:
    """Propagate walking particles one step (B8's discrete propagation).

    Order within a step: all the noises first (``ψ += n_ψ``, ``φ += n_φ``, ``T += n_T`` and ``S += n_S``
    clipped, ``p += n_p``), then the feet move with the velocities and accelerations of the phase at
    the start of the step, ``p ← p + vΔt + ½aΔt²`` (a second-order Taylor step of the continuous
    kinematics, so the signed separation keeps following ``-(S/π) cos φ``), then ``φ ← φ + 2πΔt/T``.
    Angles are wrapped to ``(-π, π]``.

    Parameters
    ----------
    state : (n_t, n_p, 8) float
        Walking state (module docstring for the columns).
    dt_s : float
        Time step Δt, s (>= 0).
    rng : numpy.random.Generator
        Source of the process noise (not drawn from when every σ is 0).
    noise : WalkingNoise, optional
        Default ``WalkingNoise()`` (B8 values); ``WalkingNoise.zero()`` for the deterministic model.

    Returns
    -------
    state : (n_t, n_p, 8) float64
        A new array.
    """
    x = _check_state(state, STATE_DIM)
    if not dt_s >= 0.0:
        raise ValueError(f"dt_s: expected a time step >= 0 s, got {dt_s}")
    # work on contiguous columns, (8, n_t * n_p): numpy is slow on inner axes of length 2-8
    cols = np.ascontiguousarray(x.reshape(-1, STATE_DIM).T)
    _walk_cols(cols, dt_s, rng, noise)
    return np.ascontiguousarray(cols.T).reshape(x.shape)


def _walk_cols(cols: np.ndarray, dt_s: float, rng: np.random.Generator, noise: WalkingNoise | None) -> None:
    """:func:`predict_walking` in place on the column layout ``(8, n)`` (C-contiguous, ``dt_s >= 0``)."""
    nz = WalkingNoise() if noise is None else noise
    sig = _walking_sigmas(nz, nz.scale(dt_s))
    if np.count_nonzero(sig):
        noise_cols = standard_normal(_check_rng(rng), cols.shape)
        noise_cols *= sig[:, None]
        cols += noise_cols  # n_p, n_ψ, n_φ, n_T, n_S
        # clip T and S (np.clip's values: max then min; the ufuncs directly, np.clip's wrapper is slow), both rows
        # at once (PERIOD, STRIDE are rows 6, 7)
        c = cols[PERIOD:STRIDE + 1]
        np.maximum(c, _CLIP_LO, out=c)
        np.minimum(c, _CLIP_HI, out=c)
    phi, period = cols[PHI], cols[PERIOD]
    sin_a, cos_a = _sincos(cols[PSI:PHI + 1])
    ux, uy = cos_a[0], sin_a[0]
    mean_speed = cols[STRIDE] / period
    omega_dt = (TWO_PI * dt_s) / period
    # displacement of each foot along u: (S/T)Δt ± (S/T)(sin φ Δt + ½ ω cos φ Δt²)
    base = mean_speed * dt_s
    swing = sin_a[1]
    swing *= dt_s
    swing += (0.5 * dt_s) * omega_dt * cos_a[1]
    swing *= mean_speed
    step = base + swing
    cols[LX] += step * ux
    cols[LY] += step * uy
    np.subtract(base, swing, out=step)
    cols[RX] += step * ux
    cols[RY] += step * uy
    phi += omega_dt
    ang = cols[PSI:PHI + 1]
    ang += TWO_PI * np.floor((np.pi - ang) * (1.0 / TWO_PI))  # wrap ψ, φ to (-π, π]


_LAST_SIGMAS: list[tuple[WalkingNoise | None, np.ndarray | None]] = [(None, None)]  # (noise, its σ per column)
_CLIP_LO = np.array([[PERIOD_RANGE_S[0]], [STRIDE_RANGE_M[0]]])
_CLIP_HI = np.array([[PERIOD_RANGE_S[1]], [STRIDE_RANGE_M[1]]])


def _walking_sigmas(nz: WalkingNoise, k: float) -> np.ndarray:
    """``k`` times the per-column σ of the walking state.

    The σ of the last noise object are kept (the tracker passes the same one every step; hashing the dataclass
    for a cache keyed by ``(nz, k)`` cost more than the product, and ``k`` changes with every scan interval).
    """
    last = _LAST_SIGMAS[0]
    if last[0] is not nz:
        base = np.array([nz.foot_m, nz.foot_m, nz.foot_m, nz.foot_m, nz.heading_rad, nz.phase_rad, nz.period_s,
                         nz.stride_m])
        base.setflags(write=False)
        last = _LAST_SIGMAS[0] = (nz, base)  # one tuple: read and replaced whole (threads)
    return k * last[1]


def predict_standing(state: np.ndarray, dt_s: float, rng: np.random.Generator,
                     noise: StandingNoise | None = None) -> np.ndarray:
    """Random-walk propagation for people standing still (B8 "standing people", RECON).

    The feet do not advance; both take a common random displacement (the body shifts) plus a small
    one of their own; ψ and φ diffuse, T and S are kept (the person's gait for when they walk again).

    Parameters
    ----------
    state : (n_t, n_p, 8) float
    dt_s : float
        Time step, s; only used when ``noise.dt_ref_s`` is set.
    rng : numpy.random.Generator
    noise : StandingNoise, optional

    Returns
    -------
    state : (n_t, n_p, 8) float64
    """
    x = _check_state(state, STATE_DIM)
    cols = _stand_cols(np.moveaxis(x, -1, 0), dt_s, rng, noise)
    return np.ascontiguousarray(np.moveaxis(cols, 0, -1))


def _stand_cols(x: np.ndarray, dt_s: float, rng: np.random.Generator, noise: StandingNoise | None) -> np.ndarray:
    """:func:`predict_standing` on the column layout ``(8, n_t, n_p)`` (a view of any strides); a new array.

    The noise is drawn as :func:`predict_standing` draws it, ``(n_t, n_p, 8)``: the same values either way.
    """
    nz = StandingNoise() if noise is None else noise
    k = nz.scale(dt_s)
    r = np.moveaxis(standard_normal(_check_rng(rng), (*x.shape[1:], STATE_DIM)), -1, 0)
    out = np.array(x, dtype=np.float64, order="C")
    body = k * nz.body_m * r[6:8]
    out[0:4] += k * nz.foot_m * r[0:4]
    out[LEFT] += body
    out[RIGHT] += body
    out[PSI] = _wrap(x[PSI] + k * nz.heading_rad * r[PSI])
    out[PHI] = _wrap(x[PHI] + k * nz.phase_rad * r[PHI])
    return out


def predict_people(state: np.ndarray, standing: np.ndarray, dt_s: float, rng: np.random.Generator,
                   noise: WalkingNoise | None = None, standing_noise: StandingNoise | None = None) -> np.ndarray:
    """Walking model for walking targets, random walk for standing ones (B8 "standing people").

    Parameters
    ----------
    state : (n_t, n_p, 8) float
    standing : (n_t,) bool
        Which targets use the random-walk model (from :func:`update_standing`).
    dt_s, rng, noise, standing_noise : see :func:`predict_walking` and :func:`predict_standing`.

    Returns
    -------
    state : (n_t, n_p, 8) float64
    """
    x = _check_state(state, STATE_DIM)
    still = np.asarray(standing, dtype=bool)
    if still.shape != (x.shape[0],):
        raise ValueError(f"standing: expected shape ({x.shape[0]},), got {still.shape}")
    if not dt_s >= 0.0 and np.count_nonzero(still) < still.size:  # (as predict_walking checks it)
        raise ValueError(f"dt_s: expected a time step >= 0 s, got {dt_s}")
    cols = predict_people_cols(np.ascontiguousarray(x.reshape(-1, STATE_DIM).T).reshape(STATE_DIM, *x.shape[:2]),
                               still, dt_s, rng, noise, standing_noise)
    return np.ascontiguousarray(cols.reshape(STATE_DIM, -1).T).reshape(x.shape)


def predict_people_cols(cols: np.ndarray, standing: np.ndarray, dt_s: float, rng: np.random.Generator,
                        noise: WalkingNoise | None = None, standing_noise: StandingNoise | None = None) -> np.ndarray:
    """:func:`predict_people` on the column layout ``(8, n_t, n_p)`` (``cols[c]`` is column ``c`` of every
    particle), the layout the laser tracker keeps its particles in: the same values, without transposing the
    particles in and out on every step.

    Parameters
    ----------
    cols : (8, n_t, n_p) float64, C-contiguous
    standing : (n_t,) bool
    dt_s : float
        Time step, s (>= 0; not checked).
    rng, noise, standing_noise : see :func:`predict_people`.

    Returns
    -------
    cols : (8, n_t, n_p) float64
        A new C-contiguous array.
    """
    standing = np.asarray(standing, dtype=bool)
    if cols.ndim != 3 or standing.shape != (cols.shape[1],):  # (the kernel would read past its end)
        raise ValueError(f"standing: expected one flag per target of cols {cols.shape}, got shape {standing.shape}")
    n_s = np.count_nonzero(standing)
    if _jit.ENABLED and cols.dtype == np.float64 and cols.flags.c_contiguous:
        return _predict_people_jit(cols, standing, n_s, dt_s, rng, noise, standing_noise)
    if not n_s:
        out = cols.copy()
        _walk_cols(out.reshape(STATE_DIM, -1), dt_s, rng, noise)
        return out
    if n_s == standing.size:
        return _stand_cols(cols, dt_s, rng, standing_noise)
    out = np.empty_like(cols)
    walk = np.ascontiguousarray(cols[:, ~standing])  # a C-contiguous copy (a fancy index alone gives another order)
    _walk_cols(walk.reshape(STATE_DIM, -1), dt_s, rng, noise)
    out[:, ~standing] = walk
    out[:, standing] = _stand_cols(cols[:, standing], dt_s, rng, standing_noise)
    return out


def _predict_people_jit(cols: np.ndarray, standing: np.ndarray, n_s: int, dt_s: float, rng: np.random.Generator,
                        noise: WalkingNoise | None, standing_noise: StandingNoise | None) -> np.ndarray:
    """:func:`predict_people_cols` by one numba kernel; the uniforms drawn here, as the numpy path draws them."""
    n_t, n_p = cols.shape[1], cols.shape[2]
    n_w = n_t - n_s
    nz = WalkingNoise() if noise is None else noise
    sig = _walking_sigmas(nz, nz.scale(dt_s))
    walk_noise = n_w > 0 and np.count_nonzero(sig) > 0
    n_draw = (STATE_DIM * n_w * n_p if walk_noise else 0) + STATE_DIM * n_s * n_p
    u = _check_rng(rng).random(n_draw) if n_draw else _NO_UNIFORMS
    if n_s:
        snz = StandingNoise() if standing_noise is None else standing_noise
        k = snz.scale(dt_s)
        ssig = np.array([k * snz.foot_m, k * snz.body_m, k * snz.heading_rad, k * snz.phase_rad])
    else:
        ssig = _NO_SSIG
    out = np.empty_like(cols)
    _jit.predict_people(cols, np.ascontiguousarray(standing, dtype=bool), u, sig, walk_noise, ssig, float(dt_s), out)
    return out


_NO_UNIFORMS = np.zeros(0)
_NO_SSIG = np.zeros(4)


def update_standing(speed_mps: np.ndarray, slow_frames: np.ndarray, standing: np.ndarray,
                    threshold_mps: float = STANDING_SPEED_MPS, n_frames: int = 10,
                    resume_mps: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame switch between the walking and the standing model (B8 "standing people", RECON).

    A target whose estimated speed stays below ``threshold_mps`` for ``n_frames`` consecutive frames
    becomes standing; a standing target whose speed rises to ``resume_mps`` walks again (hysteresis,
    so a slow walker does not flicker). The speed must come from the track's estimate (e.g. the
    displacement of the estimated body position over a few frames): the walking model's own
    ``S/T`` cannot go below 0.4/1.6 = 0.25 m/s because of B8's clips.

    Parameters
    ----------
    speed_mps : (n_t,) float
        Estimated body speed this frame; ``NaN`` (unknown) counts as not slow.
    slow_frames : (n_t,) int
        Consecutive slow frames so far (0 for a new target).
    standing : (n_t,) bool
        Current model per target.

    Returns
    -------
    slow_frames : (n_t,) int64
    standing : (n_t,) bool
    """
    v = np.asarray(speed_mps, dtype=np.float64)
    slow = v < threshold_mps
    count = np.where(slow, np.asarray(slow_frames, dtype=np.int64) + 1, 0)
    still = np.asarray(standing, dtype=bool)
    still = np.where(still, ~(v >= resume_mps), count >= n_frames)
    return count, still


# --------------------------------------------------------------------------------------------------
# Initialisation
# --------------------------------------------------------------------------------------------------


def heading_from_displacement(first_m: np.ndarray, second_m: np.ndarray, min_m: float = 0.1) -> np.ndarray:
    """Heading of the move from the first to the second detection (B8 initialisation).

    Parameters
    ----------
    first_m, second_m : (n, 2) float
        Centres of the first two detections of each new target, m.
    min_m : float
        Displacements shorter than this give ``NaN`` (heading unknown: drawn uniformly by
        :func:`init_walking`).

    Returns
    -------
    heading_rad : (n,) float64
    """
    d = np.asarray(second_m, dtype=np.float64) - np.asarray(first_m, dtype=np.float64)
    return np.where(np.hypot(d[..., 0], d[..., 1]) >= min_m, np.arctan2(d[..., 1], d[..., 0]), np.nan)


def init_walking(feet_m: np.ndarray, n_particles: int, rng: np.random.Generator,
                 heading_rad: np.ndarray | None = None, *, period_s: float = 1.1, stride_m: float = 1.4,
                 feet_sigma_m: float = 0.0, heading_sigma_rad: float = 0.0, period_sigma_s: float = 0.0,
                 stride_sigma_m: float = 0.0) -> np.ndarray:
    """Particles of new walking targets from their detected feet (B8 initialisation).

    T = 1.1 s and S = 1.4 m (typical adult gait), φ ~ U[0, 2π) (stored wrapped to (-π, π]), ψ the
    given heading or ~U[-π, π) where it is ``None``/``NaN``, feet = the B5 foot barycentres. The
    optional spreads add Gaussian jitter (clipped to B8's ranges for T and S).

    Parameters
    ----------
    feet_m : (n, 2, 2) float
        ``feet_m[i, 0]`` and ``feet_m[i, 1]``: the two foot barycentres of target i (which one is left
        does not matter, see the module docstring). A one-foot segment gives the centre twice.
    n_particles : int
    rng : numpy.random.Generator
    heading_rad : (n,) float, optional
        From :func:`heading_from_displacement`.

    Returns
    -------
    state : (n, n_particles, 8) float64
    """
    feet = np.asarray(feet_m, dtype=np.float64)
    if feet.ndim != 3 or feet.shape[1:] != (2, 2):
        raise ValueError(f"feet_m: expected shape (n, 2, 2), got {feet.shape}")
    if n_particles < 1:
        raise ValueError(f"n_particles: expected >= 1, got {n_particles}")
    rng = _check_rng(rng)
    n = feet.shape[0]
    shape = (n, n_particles)
    state = np.empty((*shape, STATE_DIM))
    state[..., 0:4] = feet.reshape(n, 1, 4)
    if feet_sigma_m > 0:
        state[..., 0:4] += feet_sigma_m * rng.standard_normal((*shape, 4))
    heading = np.full(n, np.nan) if heading_rad is None else np.broadcast_to(
        np.asarray(heading_rad, dtype=np.float64), (n,))
    psi = np.where(np.isnan(heading)[:, None], rng.uniform(-np.pi, np.pi, shape), heading[:, None])
    if heading_sigma_rad > 0:
        psi = psi + heading_sigma_rad * rng.standard_normal(shape)
    state[..., PSI] = _wrap(psi)
    state[..., PHI] = _wrap(rng.uniform(0.0, TWO_PI, shape))
    state[..., PERIOD] = np.clip(period_s + period_sigma_s * rng.standard_normal(shape), *PERIOD_RANGE_S)
    state[..., STRIDE] = np.clip(stride_m + stride_sigma_m * rng.standard_normal(shape), *STRIDE_RANGE_M)
    return state


# --------------------------------------------------------------------------------------------------
# Constant velocity (bicycles, cars)
# --------------------------------------------------------------------------------------------------


def init_cv(position_m: np.ndarray, n_particles: int, rng: np.random.Generator,
            velocity_mps: np.ndarray | None = None, position_sigma_m: float = 0.1,
            velocity_sigma_mps: float = 1.0) -> np.ndarray:
    """Constant-velocity particles around detected centres.

    Parameters
    ----------
    position_m : (n, 2) float
    n_particles : int
    rng : numpy.random.Generator
    velocity_mps : (n, 2) float, optional
        Initial velocity (default 0), spread by ``velocity_sigma_mps`` per axis.

    Returns
    -------
    state : (n, n_particles, 4) float64, columns ``x, y, vx, vy``
    """
    pos = np.asarray(position_m, dtype=np.float64).reshape(-1, 2)
    vel = np.zeros_like(pos) if velocity_mps is None else np.asarray(velocity_mps, dtype=np.float64).reshape(-1, 2)
    mean = np.concatenate([pos, vel], axis=1)[:, None, :]
    sig = np.array([position_sigma_m, position_sigma_m, velocity_sigma_mps, velocity_sigma_mps])
    return mean + sig * _check_rng(rng).standard_normal((pos.shape[0], n_particles, 4))


def predict_cv(state: np.ndarray, dt_s: float, q: float | np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Constant-velocity propagation with white-noise acceleration (B18; X5 process noise).

    ``x ← F x + n`` with ``F = [[I, Δt I], [0, I]]`` and ``n ~ N(0, Q)``,
    ``Q = q [[Δt³/3 I, Δt²/2 I], [Δt²/2 I, Δt I]]``; the noise is drawn through the closed-form
    Cholesky factor of the per-axis block, ``√q [[√(Δt³/3), 0], [√(3Δt)/2, √Δt/2]]``.

    Parameters
    ----------
    state : (n_t, n_p, 4) float
        ``x, y`` (m), ``vx, vy`` (m/s).
    dt_s : float
        Time step, s (>= 0).
    q : float or (n_t,) float
        Acceleration noise intensity, m²/s³ (bicycle 0.5, car 1.0 in B18).
    rng : numpy.random.Generator

    Returns
    -------
    state : (n_t, n_p, 4) float64
    """
    x = _check_state(state, 4)
    if not dt_s >= 0.0:
        raise ValueError(f"dt_s: expected a time step >= 0 s, got {dt_s}")
    qs = np.asarray(q, dtype=np.float64)
    if np.any(qs < 0):
        raise ValueError(f"q: expected >= 0, got {q}")
    out = x.copy()
    out[..., 0:2] += dt_s * x[..., 2:4]
    if dt_s > 0 and np.any(qs > 0):
        sq = np.sqrt(qs).reshape(-1, 1, 1) if qs.ndim else np.sqrt(qs)
        e = standard_normal(_check_rng(rng), x.shape)
        out[..., 0:2] += sq * np.sqrt(dt_s**3 / 3.0) * e[..., 0:2]
        out[..., 2:4] += sq * (0.5 * np.sqrt(3.0 * dt_s) * e[..., 0:2] + 0.5 * np.sqrt(dt_s) * e[..., 2:4])
    return out
