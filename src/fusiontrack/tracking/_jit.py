"""numba kernels of the laser people tracker's particle-filter step (ALGORITHMS.md B8-B10, X1).

Why: with a few targets the vectorised numpy step costs what its ~100 numpy calls cost (about 1 µs each), not what
its arithmetic costs. These kernels do the walking prediction with its noise, the laser likelihood, the reweight,
the walking centres, the systematic resampling and the velocity / standing bookkeeping in a handful of compiled
calls: the step is ~2x faster on the simulated scenes (benchmarks/laser_baselines.py, laser_people.py).

The numpy code stays the reference: each public function (``predict_people_cols``, ``laser_log_likelihood_cols``,
``reweight``, ``resample_where_cols``) calls its kernel when numba is there, and tests/test_tracking_jit.py holds
every kernel to it. Every random number is still drawn by the caller from its ``numpy.random.Generator``, with
the calls the numpy code makes (``rng.random`` uniforms, in the same order and count), and passed in, so the
stream of draws is unchanged. The arithmetic follows the numpy code; the transcendental functions do not round
as numpy's SIMD ones do (float32 ``sin``/``cos`` here are a branch-free polynomial, ~1 ulp apart at times, that
lets the loops vectorise: libm's scalar calls cost what numpy's vectorised ones save), so a run is not bit for bit
the numpy path's: the particle filters' resampling turns last-bit differences into a different draw of particles,
with the same tracking quality (MOTA / IDF1 within the spread of ``--rng`` draws).

Kernels are compiled on first use and cached next to this file (``NUMBA_CACHE_DIR`` moves the cache; a few
seconds the first time, ~0.2 s after). ``FUSIONTRACK_NUMBA=0`` (or ``false``, ``no``, ``off``) in the environment,
or numba missing, keeps the numpy path.
"""

from __future__ import annotations

import logging
import math
import os

import numpy as np

_log = logging.getLogger(__name__)

ENABLED = os.environ.get("FUSIONTRACK_NUMBA", "1").strip().lower() not in ("0", "false", "no", "off")
try:
    if not ENABLED:
        raise ImportError
    from numba import njit as _njit
except ImportError:  # pragma: no cover
    ENABLED = False
    _njit = None


def njit(**options):  # type: ignore[no-untyped-def]
    """numba's ``njit`` as the kernels need it: numpy's floating-point error model (a division by zero gives inf or
    NaN, as in the numpy code, not ``ZeroDivisionError``), and the on-disk cache when numba finds a writable place
    for it (a read-only install with no writable cache folder compiles in every process instead of failing at
    import; a damaged cache file, e.g. cut short by a full disk or a killed process, is compiled again with a
    warning instead of numba's unpickling traceback: :func:`_tolerant_cache`)."""
    options.setdefault("error_model", "numpy")

    def wrap(fn):  # type: ignore[no-untyped-def]
        try:
            return _tolerant_cache(_njit(**options)(fn))
        except RuntimeError:  # "cannot cache function ...: no locator available"
            return _njit(**{**options, "cache": False})(fn)

    return wrap


def _tolerant_cache(dispatcher):  # type: ignore[no-untyped-def]
    """``dispatcher`` whose on-disk cache, when a file of it cannot be read back (truncated, garbled), counts as a
    miss: the kernel is compiled again and the file rewritten (numba raises from the unpickling otherwise, at the
    kernel's first call). Works on numba's ``_cache`` attribute (numba < 1); without it, numba's own behaviour."""
    cache = getattr(dispatcher, "_cache", None)
    if cache is None or not hasattr(cache, "load_overload") or not hasattr(cache, "save_overload"):
        return dispatcher  # pragma: no cover
    load, save = cache.load_overload, cache.save_overload
    name = getattr(dispatcher, "__qualname__", "kernel")

    def load_overload(sig, target_context):  # type: ignore[no-untyped-def]
        try:
            return load(sig, target_context)
        except Exception as err:  # any unreadable file: compile instead
            _log.warning("numba cache of %s (%s) cannot be read (%s: %s): compiling it again", name,
                         getattr(cache, "cache_path", "?"), type(err).__name__, err)
            return None

    def save_overload(sig, data):  # type: ignore[no-untyped-def]
        try:
            save(sig, data)
        except Exception:  # a damaged index: drop it, then save afresh
            index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
            try:
                if index:
                    os.remove(index)
                save(sig, data)
            except Exception as err:  # the kernel runs; only the next process compiles again
                _log.warning("numba cache of %s cannot be written (%s: %s)", name, type(err).__name__, err)

    cache.load_overload, cache.save_overload = load_overload, save_overload
    return dispatcher


TWO_PI = 2.0 * np.pi
PI = np.pi
INV_TWO_PI = 1.0 / TWO_PI
P_LO, P_HI, S_LO, S_HI = 0.8, 1.6, 0.4, 2.0  # PERIOD_RANGE_S, STRIDE_RANGE_M (walking.py)

if ENABLED:

    @njit(cache=True, inline="always")
    def _wrap(a):
        return a + TWO_PI * np.floor((PI - a) * INV_TWO_PI)

    _TWO_OVER_PI = 2.0 / np.pi
    _PIO2_HI = 1.5707963267341256e+00  # π/2 in two parts (fdlibm's): the reduction r = x - q π/2 stays exact
    _PIO2_LO = 6.0771005065061922e-11
    _S1, _S2, _S3, _S4, _S5 = -1.0 / 6, 1.0 / 120, -1.0 / 5040, 1.0 / 362880, -1.0 / 39916800
    _C1, _C2, _C3, _C4, _C5, _C6 = -0.5, 1.0 / 24, -1.0 / 720, 1.0 / 40320, -1.0 / 3628800, 1.0 / 479001600

    @njit(cache=True, inline="always")
    def _sincos32(a):
        """``sin, cos`` of ``float32(a)`` as float64 values rounded to float32 (what numpy's float32 ``sin``/``cos``
        compute, there within ~1 ulp, here correctly rounded but for ~4e-6 of the arguments). Branch-free (Taylor
        polynomials on |r| <= π/4 after a quadrant reduction) so that loops over it vectorise; for |a| < ~1e5."""
        x = np.float64(np.float32(a))
        q = np.floor(x * _TWO_OVER_PI + 0.5)
        r = (x - q * _PIO2_HI) - q * _PIO2_LO
        r2 = r * r
        s = r + r * r2 * (_S1 + r2 * (_S2 + r2 * (_S3 + r2 * (_S4 + r2 * _S5))))
        c = 1.0 + r2 * (_C1 + r2 * (_C2 + r2 * (_C3 + r2 * (_C4 + r2 * (_C5 + r2 * _C6)))))
        qi = np.int64(q)
        swap = (qi & 1) == 1
        sn = np.float64(1 - (qi & 2)) * (c if swap else s)
        cs = np.float64(1 - ((qi + 1) & 2)) * (s if swap else c)
        return np.float64(np.float32(sn)), np.float64(np.float32(cs))

    @njit(cache=True)
    def _box_muller(u, lo, n, out):
        """``standard_normal``'s values from the uniforms ``u[lo:lo + n]`` (``n`` even) into ``out[:n]``: radius from
        the first half, float32 angle from the second; cos to the first half of the output, sin to the second."""
        h = n // 2
        for k in range(h):  # log(1 - u) = log1p(-u): 1 - u is exact for u on numpy's 2^-53 grid
            out[k] = math.sqrt(-2.0 * math.log(1.0 - u[lo + k]))
        for k in range(h):
            sn, cs = _sincos32(u[lo + h + k] * TWO_PI)
            out[h + k] = out[k] * sn
            out[k] = out[k] * cs

    @njit(cache=True, inline="always")
    def _walk_row(cols, out, t, n_p, noise, nw, iw, wsig, walk_noise, dt, two_dt, half_dt):
        """The walking model on row ``t`` (its particles are columns ``iw..iw + n_p`` of the (8, nw) noise)."""
        for p in range(n_p):
            lx = cols[0, t, p]
            ly = cols[1, t, p]
            rx = cols[2, t, p]
            ry = cols[3, t, p]
            psi = cols[4, t, p]
            phi = cols[5, t, p]
            period = cols[6, t, p]
            stride = cols[7, t, p]
            if walk_noise:
                k = iw + p
                lx = lx + noise[k] * wsig[0]
                ly = ly + noise[nw + k] * wsig[1]
                rx = rx + noise[2 * nw + k] * wsig[2]
                ry = ry + noise[3 * nw + k] * wsig[3]
                psi = psi + noise[4 * nw + k] * wsig[4]
                phi = phi + noise[5 * nw + k] * wsig[5]
                period = min(max(period + noise[6 * nw + k] * wsig[6], P_LO), P_HI)
                stride = min(max(stride + noise[7 * nw + k] * wsig[7], S_LO), S_HI)
            uy, ux = _sincos32(psi)
            sphi, cphi = _sincos32(phi)
            mean_speed = stride / period
            omega_dt = two_dt / period
            base = mean_speed * dt
            swing = sphi * dt
            swing = swing + half_dt * omega_dt * cphi
            swing = swing * mean_speed
            step = base + swing
            out[0, t, p] = lx + step * ux
            out[1, t, p] = ly + step * uy
            step = base - swing
            out[2, t, p] = rx + step * ux
            out[3, t, p] = ry + step * uy
            out[4, t, p] = _wrap(psi)
            out[5, t, p] = _wrap(phi + omega_dt)
            out[6, t, p] = period
            out[7, t, p] = stride

    @njit(cache=True)
    def predict_people(cols, standing, u, wsig, walk_noise, ssig, dt, out):
        """``predict_people_cols`` into ``out`` (8, n_t, n_p). ``u``: the uniforms of ``standard_normal`` for the
        walking rows ((8 n_w n_p) of them, when ``walk_noise``) followed by those of the standing rows
        (8 n_s n_p). ``wsig``: the 8 walking σ (already scaled); ``ssig``: k*foot, k*body, k*heading, k*phase."""
        n_t = cols.shape[1]
        n_p = cols.shape[2]
        n_s = 0
        for t in range(n_t):
            if standing[t]:
                n_s += 1
        n_w = n_t - n_s
        nw = n_w * n_p  # particles walking; the walking noise is (8, nw) in row-major order
        n_wn = 8 * nw if walk_noise else 0
        ns = 8 * n_s * n_p  # the standing noise, (n_s, n_p, 8) row-major, after the walking uniforms
        noise = np.empty(n_wn + ns)
        if n_wn:
            _box_muller(u, 0, n_wn, noise)
        if ns:
            _box_muller(u[n_wn:], 0, ns, noise[n_wn:])
        two_dt = TWO_PI * dt
        half_dt = 0.5 * dt
        iw = 0  # walking particle counter (column of the (8, nw) noise)
        i_s = n_wn  # start of the current standing particle's noise
        for t in range(n_t):
            if standing[t]:
                for p in range(n_p):
                    for c in range(4):
                        out[c, t, p] = cols[c, t, p] + ssig[0] * noise[i_s + c]
                    bx = ssig[1] * noise[i_s + 6]
                    by = ssig[1] * noise[i_s + 7]
                    out[0, t, p] += bx
                    out[1, t, p] += by
                    out[2, t, p] += bx
                    out[3, t, p] += by
                    out[4, t, p] = _wrap(cols[4, t, p] + ssig[2] * noise[i_s + 4])
                    out[5, t, p] = _wrap(cols[5, t, p] + ssig[3] * noise[i_s + 5])
                    out[6, t, p] = cols[6, t, p]
                    out[7, t, p] = cols[7, t, p]
                    i_s += 8
            else:
                _walk_row(cols, out, t, n_p, noise, nw, iw, wsig, walk_noise, dt, two_dt, half_dt)
                iw += n_p

    @njit(cache=True, inline="always")
    def _sq(ax, ay, bx, by):
        """``|a - b|²`` as ``dx² + dy²`` (the numpy code's order)."""
        dx = ax - bx
        dy = ay - by
        return dx * dx + dy * dy

    @njit(cache=True, inline="always")
    def _ll_one(cols, t, p, f1x, f1y, f2x, f2y, sd, one, cf, c1, cw, kappa, lateral):
        lx = cols[0, t, p]
        ly = cols[1, t, p]
        rx = cols[2, t, p]
        ry = cols[3, t, p]
        dl1 = _sq(lx, ly, f1x, f1y)
        dl2 = _sq(lx, ly, f2x, f2y)
        dr1 = _sq(rx, ry, f1x, f1y)
        dr2 = _sq(rx, ry, f2x, f2y)
        l_to_1 = dl1 <= dl2
        if one:
            sq = (dl1 + dr1) if l_to_1 else (dl2 + dr2)
            return sq * (-c1)  # P_walk = 1
        straight = dl1 + dr2
        crossed = dl2 + dr1
        # both feet nearest the same barycentre: the smaller total Euclidean distance (computed branch-free)
        by_dist = math.sqrt(dl1) + math.sqrt(dr2) <= math.sqrt(dl2) + math.sqrt(dr1)
        pick = by_dist if l_to_1 == (dr1 <= dr2) else straight <= crossed
        sq = straight if pick else crossed
        sq = sq * (-cf)
        along = kappa * cols[7, t, p] * abs(_sincos32(cols[5, t, p])[1])
        # hypot(along, lateral) as sqrt(a² + l²): within an ulp of libm's hypot, and vectorisable
        d_pred = along if lateral == 0.0 else math.sqrt(along * along + lateral * lateral)
        lw = sd - d_pred
        lw = lw * lw
        lw = lw * (-cw)
        return sq + lw

    @njit(cache=True)
    def laser_ll(cols, feet, sd, one, missing, prm, out):
        """``laser_log_likelihood_cols`` into ``out`` (n_t, n_p); ``prm``: cf, c1, cw, kappa, lateral."""
        n_t = cols.shape[1]
        n_p = cols.shape[2]
        for t in range(n_t):
            if missing[t]:
                for p in range(n_p):
                    out[t, p] = 0.0
                continue
            for p in range(n_p):
                out[t, p] = _ll_one(cols, t, p, feet[t, 0, 0], feet[t, 0, 1], feet[t, 1, 0], feet[t, 1, 1], sd[t],
                                    one[t], prm[0], prm[1], prm[2], prm[3], prm[4])

    @njit(cache=True)
    def _reweight_rows(w, ll, out):
        """``reweight`` (the finite path) into ``out``; returns False (nothing usable) if a row's maximum is not
        finite (NaN, all ``-inf`` or ``+inf``: the caller takes numpy's general path)."""
        n_t, n_p = w.shape
        for t in range(n_t):
            m = -np.inf
            nan = False
            wp = np.nan  # (no weight equals it: the first one takes its log)
            lg = 0.0
            for p in range(n_p):
                if w[t, p] != wp:  # after a resampling every weight is 1/n_p: one log
                    wp = w[t, p]
                    lg = math.log(wp)
                v = lg + ll[t, p]
                out[t, p] = v
                if v != v:
                    nan = True
                elif v > m:
                    m = v
            if nan or not math.isfinite(m):
                return False
            s = 0.0
            for p in range(n_p):
                out[t, p] = math.exp(out[t, p] - m)
                s += out[t, p]
            for p in range(n_p):
                out[t, p] = out[t, p] / s
        return True

    @njit(cache=True)
    def reweight(w, ll, out):
        return _reweight_rows(w, ll, out)

    @njit(cache=True)
    def _resample_rows(cols, w, sel, u, div, out_cols, out_w):
        """``resample_where_cols`` into ``out_cols``/``out_w``; the offsets are ``u / div`` (``u``:
        ``rng.random(n_sel)`` and ``div = n_p``, or given offsets and ``div = 1``), one per selected row."""
        n_t = cols.shape[1]
        n_p = cols.shape[2]
        d = cols.shape[0]
        cum = np.empty(n_p)
        anc = np.empty(n_p, np.int64)
        k = 0
        for t in range(n_t):
            if not sel[t]:
                for p in range(n_p):
                    out_w[t, p] = w[t, p]
                    for c in range(d):
                        out_cols[c, t, p] = cols[c, t, p]
                continue
            u0 = u[k] / div
            k += 1
            s = 0.0
            for p in range(n_p):
                s += w[t, p]
                cum[p] = s
            if not cum[n_p - 1] > 0:
                for p in range(n_p):
                    cum[p] = p + 1.0
            last = cum[n_p - 1]
            j = 0
            prev = 0
            for p in range(n_p):
                below = n_p if p == n_p - 1 else math.ceil((cum[p] / last - u0) * n_p)
                if below < prev or below > n_p:  # negative weights: numpy's path raises
                    return False
                for _ in range(below - prev):
                    anc[j] = p
                    j += 1
                prev = below
            for c in range(d):
                for q in range(n_p):
                    out_cols[c, t, q] = cols[c, t, anc[q]]
            for p in range(n_p):
                out_w[t, p] = 1.0 / n_p
        return True

    @njit(cache=True)
    def resample(cols, w, sel, u, div, out_cols, out_w):
        return _resample_rows(cols, w, sel, u, div, out_cols, out_w)

    @njit(cache=True, inline="always")
    def _centres(cols, w, out):
        """``_walking_centres``: ``0.5 Σ_p w_tp (left + right)_tp``, summed particle after particle."""
        n_t = cols.shape[1]
        n_p = cols.shape[2]
        for t in range(n_t):
            sx = w[t, 0] * (cols[0, t, 0] + cols[2, t, 0])
            sy = w[t, 0] * (cols[1, t, 0] + cols[3, t, 0])
            for p in range(1, n_p):
                sx += w[t, p] * (cols[0, t, p] + cols[2, t, p])
                sy += w[t, p] * (cols[1, t, p] + cols[3, t, p])
            out[t, 0] = 0.5 * sx
            out[t, 1] = 0.5 * sy

    @njit(cache=True)
    def centres(cols, w, out):
        _centres(cols, w, out)

    @njit(cache=True)
    def update(cols, w, det_feet, det_sd, det_one, aw, u, prm, ll, w_new, out_cols, out_w, pos):
        """The tracker's walking update in one call: likelihood of each target's assigned detection (``aw``,
        -1: none), reweight, the walking centres of the reweighted particles (``pos``), systematic resampling
        of the updated rows (``u``: ``rng.random(n_upd)``). Returns False when the reweight needs numpy's
        general path (nothing is written to ``out_*``, ``ll`` holds the likelihoods)."""
        n_t = cols.shape[1]
        n_p = cols.shape[2]
        for t in range(n_t):
            j = aw[t]
            if j < 0:
                for p in range(n_p):
                    ll[t, p] = 0.0
                continue
            for p in range(n_p):
                ll[t, p] = _ll_one(cols, t, p, det_feet[j, 0, 0], det_feet[j, 0, 1], det_feet[j, 1, 0],
                                   det_feet[j, 1, 1], det_sd[j], det_one[j], prm[0], prm[1], prm[2], prm[3], prm[4])
        if not _reweight_rows(w, ll, w_new):
            return False
        _centres(cols, w_new, pos)
        sel = aw >= 0
        return _resample_rows(cols, w_new, sel, u, float(n_p), out_cols, out_w)  # (True: the weights are >= 0)

    @njit(cache=True)
    def track_velocity(pos, lag, vel, slow, standing, dt, a, lag_s, thr, resume, n_frames, reseed, speed,
                       slow_out, standing_out, rows):
        """``_track_velocity`` up to its draws: the lagged position (``lag`` in place), ``vel`` (in place when
        ``dt > 0``), ``speed``, the standing switch into ``slow_out``/``standing_out``, and the rows to reseed into
        ``rows``. Returns (targets that start walking again, rows to reseed)."""
        n = pos.shape[0]
        n_started = 0
        n_rows = 0
        for i in range(n):
            if dt > 0:
                for c in range(2):
                    lag[i, c] = lag[i, c] + a * (pos[i, c] - lag[i, c])
                    vel[i, c] = (pos[i, c] - lag[i, c]) / lag_s
            s = math.hypot(vel[i, 0], vel[i, 1])
            speed[i] = s
            slow_out[i] = slow[i] + 1 if s < thr else 0
            was = standing[i]
            now = (not (s >= resume)) if was else slow_out[i] >= n_frames
            standing_out[i] = now
            if was and not now:
                n_started += 1
            if reseed and not now and s > resume:
                rows[n_rows] = i
                n_rows += 1
        return n_started, n_rows

    @njit(cache=True)
    def reseed_heading(x, rows, n_rows, vel, u, sigma, start, k):
        """The reseed of ``_track_velocity``: ``x[PSI, rows, start:start + k] = atan2(v) + σ e`` with ``e`` the
        ``standard_normal((n_rows, k))`` of the uniforms ``u`` (``2 ceil(n_rows k / 2)`` of them)."""
        n = n_rows * k
        h = (n + 1) // 2
        e = np.empty(2 * h)
        for q in range(h):
            e[q] = math.sqrt(-2.0 * math.log(1.0 - u[q]))
        for q in range(h):
            sn, cs = _sincos32(u[h + q] * TWO_PI)
            e[h + q] = e[q] * sn
            e[q] = e[q] * cs
        for r in range(n_rows):
            i = rows[r]
            psi = math.atan2(vel[i, 1], vel[i, 0])
            for j in range(k):
                x[4, i, start + j] = psi + sigma * e[r * k + j]
