"""Geometric and motion features of laser segments for the object classifier (seed 001; ALGORITHMS.md B18).

Two pure functions on arrays:

* :func:`segment_features` — the per-frame shape of every segment of a point set at once (B18 features
  1–10), vectorised over segments with ``bincount`` sums: no loop over segments or points.
* :func:`window_features` — a window of ``W`` frames of one object per row (B18's ``W_c = 10``): the mean
  of its shape features plus motion (features 11–13: speed, its spread, heading change rate, gait
  periodicity), vectorised over rows.

The feature list follows Arras, Mozos & Burgard (2007), "Using boosted features for the detection of people
in 2D range data", adapted as B18 says. Points of a segment are expected in scan order (consecutive beams
of one scanner) for the boundary features (8, 9, 10); the others do not depend on the order.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["GEOMETRIC_FEATURES", "MOTION_FEATURES", "WINDOW_FEATURES", "segment_features", "window_features"]

GEOMETRIC_FEATURES = (
    "n_points", "std_m", "mad_median_m", "width_m", "thickness_m", "linearity_m", "circularity_m", "radius_m",
    "boundary_length_m", "boundary_regularity_m", "mean_curvature_rad", "n_subclusters", "axis_rad",
)
"""Names of the columns of :func:`segment_features` (B18 features 1–10; 7 gives two columns; ``axis_rad``
is the direction of the first principal axis, used only with the motion)."""
MOTION_FEATURES = ("speed_mps", "speed_std_mps", "heading_rate_radps", "gait_periodicity", "width_std_m",
                   "motion_alignment")
"""Names of the motion columns :func:`window_features` appends (B18 11–13; plus the spread of the width,
which the two-feet gait makes oscillate and a rigid object keeps still, and ``|cos|`` of the angle between
the motion and the segment's long axis: a bicycle moves along its line, a car seen end-on across it)."""
WINDOW_FEATURES = GEOMETRIC_FEATURES[:-1] + MOTION_FEATURES
"""Names of the columns of :func:`window_features`."""

_RADIUS_CAP_M = 5.0  # a straight line's circle fit has an unbounded radius: cap it so the feature stays finite
_GAIT_BAND_HZ = (0.6, 2.0)  # B18 13: the gait frequency band
_I_WIDTH = GEOMETRIC_FEATURES.index("width_m")
_I_AXIS = GEOMETRIC_FEATURES.index("axis_rad")
_MOVING_MPS = 0.3  # slower steps carry no reliable direction for the motion alignment


def segment_features(points_m: Any, labels: Any, n_segments: int | None = None, *,
                     gap_factor: float = 2.5, min_gap_m: float = 0.08) -> np.ndarray:
    """B18 shape features 1–10 of every segment of a point set.

    Parameters
    ----------
    points_m : (n, 2) float
        Points, metres; within a segment in scan order.
    labels : (n,) int
        Segment of each point, ``0 .. k - 1``; negative labels are ignored.
    n_segments : int, optional
        ``k`` (default ``labels.max() + 1``); segments without points get zeros.
    gap_factor, min_gap_m :
        Feature 10 counts the sub-clusters as one plus the gaps between consecutive points longer than
        ``max(min_gap_m, gap_factor * median spacing of the segment)``.

    Returns
    -------
    (k, len(GEOMETRIC_FEATURES)) float64
        Columns as :data:`GEOMETRIC_FEATURES`: number of points; standard deviation ``sqrt(tr C)``; mean
        distance from the median point; extents along the first and second principal axes (width,
        thickness); RMS residual of the least-squares line (``sqrt`` of the smaller eigenvalue of ``C``);
        RMS residual and radius of the algebraic (Kåsa) circle fit; boundary length and the standard
        deviation of the distances between consecutive points; mean turning angle between consecutive
        steps; number of sub-clusters; direction of the first principal axis in ``(-pi/2, pi/2]``.
    """
    p = np.asarray(points_m, dtype=np.float64).reshape(-1, 2)
    lab = np.asarray(labels).astype(np.int64, copy=False).reshape(-1)
    if lab.shape[0] != p.shape[0]:
        raise ValueError(f"labels: expected {p.shape[0]} labels (one per point), got {lab.shape[0]}")
    on = lab >= 0
    p, lab = p[on], lab[on]
    k = int(n_segments) if n_segments is not None else (int(lab.max()) + 1 if lab.size else 0)
    out = np.zeros((k, len(GEOMETRIC_FEATURES)))
    if k == 0 or lab.size == 0:
        return out
    if lab.max() >= k:
        raise ValueError(f"labels: a label {int(lab.max())} >= n_segments {k}")
    # Stable order by segment keeps each segment's points in their given (scan) order.
    order = np.argsort(lab, kind="stable")
    p, lab = p[order], lab[order]
    n = np.bincount(lab, minlength=k).astype(np.float64)
    has = n > 0
    nn = np.maximum(n, 1.0)

    def seg_sum(v: np.ndarray) -> np.ndarray:
        return np.bincount(lab, weights=v, minlength=k)

    mean = np.column_stack([seg_sum(p[:, 0]), seg_sum(p[:, 1])]) / nn[:, None]
    d = p - mean[lab]
    sxx, syy, sxy = seg_sum(d[:, 0] ** 2) / nn, seg_sum(d[:, 1] ** 2) / nn, seg_sum(d[:, 0] * d[:, 1]) / nn
    out[:, 0] = n
    out[:, 1] = np.sqrt(sxx + syy)

    # 3: mean distance from the per-segment (coordinate-wise) median.
    starts = np.concatenate([[0], np.cumsum(n[:-1])]).astype(np.int64)
    med = np.zeros((k, 2))
    for c in range(2):
        key = np.lexsort((p[:, c], lab))
        sorted_c = p[key, c]
        lo = starts + (n.astype(np.int64) - 1) // 2
        hi = starts + n.astype(np.int64) // 2
        lo, hi = np.minimum(lo, p.shape[0] - 1), np.minimum(hi, p.shape[0] - 1)
        med[:, c] = 0.5 * (sorted_c[lo] + sorted_c[hi])
    out[:, 2] = seg_sum(np.hypot(*(p - med[lab]).T)) / nn

    # 4, 5, 6: principal axes of the 2x2 covariance, closed form.
    half_tr, det = 0.5 * (sxx + syy), sxx * syy - sxy**2
    disc = np.sqrt(np.maximum(half_tr**2 - det, 0.0))
    lam_small = np.maximum(half_tr - disc, 0.0)
    theta = 0.5 * np.arctan2(2 * sxy, sxx - syy)
    axis1 = np.column_stack([np.cos(theta), np.sin(theta)])
    axis2 = np.column_stack([-axis1[:, 1], axis1[:, 0]])
    u = np.einsum("ij,ij->i", d, axis1[lab])
    v = np.einsum("ij,ij->i", d, axis2[lab])
    out[:, 3] = _seg_extent(u, lab, k)
    out[:, 4] = _seg_extent(v, lab, k)
    out[:, 5] = np.sqrt(lam_small)
    out[:, 12] = theta

    # 7: Kåsa circle fit, x^2 + y^2 + D x + E y + F = 0 in centred coordinates, solved per segment from
    # its 3x3 normal equations (batched solve).
    x, y = d[:, 0], d[:, 1]
    z = x * x + y * y
    a = np.empty((k, 3, 3))
    a[:, 0, 0], a[:, 0, 1], a[:, 0, 2] = seg_sum(x * x), seg_sum(x * y), seg_sum(x)
    a[:, 1, 1], a[:, 1, 2], a[:, 2, 2] = seg_sum(y * y), seg_sum(y), n
    a[:, 1, 0], a[:, 2, 0], a[:, 2, 1] = a[:, 0, 1], a[:, 0, 2], a[:, 1, 2]
    b = -np.column_stack([seg_sum(x * z), seg_sum(y * z), seg_sum(z)])
    ok = (n >= 3) & (np.abs(np.linalg.det(a)) > 1e-18)
    sol = np.zeros((k, 3))
    if ok.any():
        sol[ok] = np.linalg.solve(a[ok], b[ok][..., None])[..., 0]
    cx, cy = -sol[:, 0] / 2, -sol[:, 1] / 2
    r2 = cx**2 + cy**2 - sol[:, 2]
    ok &= r2 > 0
    radius = np.where(ok, np.sqrt(np.maximum(r2, 0.0)), _RADIUS_CAP_M)
    resid = np.hypot(x - cx[lab], y - cy[lab]) - radius[lab]
    circ = np.sqrt(seg_sum(resid**2) / nn)
    # A line-like segment fits a huge circle: cap both so the features stay finite and comparable.
    big = radius > _RADIUS_CAP_M
    out[:, 6] = np.where(ok & ~big, circ, out[:, 5])
    out[:, 7] = np.minimum(radius, _RADIUS_CAP_M)

    # 8, 9, 10: consecutive points of the same segment.
    same = lab[1:] == lab[:-1]
    step = np.diff(p, axis=0)
    dist = np.hypot(step[:, 0], step[:, 1])
    sl = lab[1:][same]
    ds = dist[same]
    n_steps = np.bincount(sl, minlength=k).astype(np.float64)
    out[:, 8] = np.bincount(sl, weights=ds, minlength=k)
    mean_ds = out[:, 8] / np.maximum(n_steps, 1)
    out[:, 9] = np.sqrt(np.maximum(np.bincount(sl, weights=ds**2, minlength=k) / np.maximum(n_steps, 1)
                                   - mean_ds**2, 0.0))
    # Turning angle between consecutive steps of the same segment.
    same2 = same[1:] & same[:-1]
    h = np.arctan2(step[:, 1], step[:, 0])
    turn = np.abs(np.angle(np.exp(1j * (h[1:] - h[:-1]))))[same2]
    tl = lab[2:][same2]
    out[:, 10] = np.bincount(tl, weights=turn, minlength=k) / np.maximum(np.bincount(tl, minlength=k), 1)
    med_ds = _seg_median(ds, sl, k)
    gap = ds > np.maximum(min_gap_m, gap_factor * med_ds[sl])
    out[:, 11] = np.where(has, 1.0 + np.bincount(sl, weights=gap.astype(np.float64), minlength=k), 0.0)
    out[~has] = 0.0
    return out


def _seg_extent(v: np.ndarray, lab: np.ndarray, k: int) -> np.ndarray:
    hi = np.full(k, -np.inf)
    lo = np.full(k, np.inf)
    np.maximum.at(hi, lab, v)
    np.minimum.at(lo, lab, v)
    ext = hi - lo
    return np.where(np.isfinite(ext), ext, 0.0)


def _seg_median(v: np.ndarray, lab: np.ndarray, k: int) -> np.ndarray:
    """Median of ``v`` per label (0 for labels without values)."""
    out = np.zeros(k)
    if v.size == 0:
        return out
    key = np.lexsort((v, lab))
    vs, ls = v[key], lab[key]
    cnt = np.bincount(ls, minlength=k)
    start = np.concatenate([[0], np.cumsum(cnt[:-1])])
    has = cnt > 0
    lo = start + (cnt - 1) // 2
    hi = start + cnt // 2
    out[has] = 0.5 * (vs[lo[has]] + vs[hi[has]])
    return out


def window_features(geometric: Any, centres_m: Any, t_s: Any, valid: Any = None) -> np.ndarray:
    """B18 classifier input: a window of frames per object, shape averaged and motion added.

    Parameters
    ----------
    geometric : (m, W, len(GEOMETRIC_FEATURES)) float
        :func:`segment_features` rows of ``m`` objects over ``W`` frames, oldest first.
    centres_m : (m, W, 2) float
        The object's position in each frame (world frame, metres).
    t_s : (m, W) or (W,) float
        Frame times, seconds.
    valid : (m, W) bool, optional
        Frames in which the object was seen (default all); the others are ignored.

    Returns
    -------
    (m, len(WINDOW_FEATURES)) float64
        Mean of each shape feature (but the axis direction) over the valid frames, then: speed (net
        displacement over the window's time span), standard deviation of the frame-to-frame speed, heading
        change rate (between the window's two halves, rad/s; 0 unless both halves move at least 5 cm), gait
        periodicity (the largest normalised
        autocorrelation of the width at lags in the 0.6–2 Hz band; 0 when the window is too short) and the
        standard deviation of the width, and ``|cos|`` of the angle between the net displacement and the
        long axis (0.5 when the object moves slower than 0.3 m/s).
    """
    g = np.asarray(geometric, dtype=np.float64)
    if g.ndim != 3 or g.shape[2] != len(GEOMETRIC_FEATURES):
        raise ValueError(f"geometric: expected shape (m, W, {len(GEOMETRIC_FEATURES)}), got {g.shape}")
    m, w, _ = g.shape
    c = np.asarray(centres_m, dtype=np.float64)
    if c.shape != (m, w, 2):
        raise ValueError(f"centres_m: expected shape {(m, w, 2)}, got {c.shape}")
    t = np.asarray(t_s, dtype=np.float64)
    if t.shape != (m, w):
        t = np.broadcast_to(t, (m, w))
    ok = np.ones((m, w), bool) if valid is None else np.asarray(valid, dtype=bool).reshape(m, w)
    ok = ok & np.isfinite(c).all(axis=2) & np.isfinite(g).all(axis=2)
    n_ok = ok.sum(axis=1)
    okf = ok[..., None].astype(np.float64)
    mean_g = (np.where(okf, g, 0.0).sum(axis=1) / np.maximum(n_ok, 1)[:, None])[:, :_I_AXIS]

    # Consecutive valid frames: compact each row's valid frames to the front (stable), then difference.
    if np.count_nonzero(ok) == ok.size:  # the usual window, every frame valid: already in place
        cc, tt, ww = c, t, g[..., _I_WIDTH]
    else:
        order = np.argsort(~ok, axis=1, kind="stable")
        cc = np.take_along_axis(c, order[..., None], axis=1)
        tt = np.take_along_axis(t, order, axis=1)
        ww = np.take_along_axis(g[..., _I_WIDTH], order, axis=1)
    pair = np.arange(w - 1)[None, :] < (n_ok - 1)[:, None]  # (m, W-1) both ends valid
    step = np.diff(cc, axis=1)
    dt = np.diff(tt, axis=1)
    pair &= dt > 0
    dist = np.hypot(step[..., 0], step[..., 1])
    speed = np.where(pair, dist / np.where(pair, dt, 1.0), 0.0)
    n_pair = pair.sum(axis=1)
    step_speed = speed.sum(axis=1) / np.maximum(n_pair, 1)
    speed_std = np.sqrt(np.maximum((speed**2).sum(axis=1) / np.maximum(n_pair, 1) - step_speed**2, 0.0))
    # Speed and heading from displacements over the window (its two halves), not from frame-to-frame steps:
    # a centroid jitters from frame to frame (several scanners see different sides of an object, a
    # segment's extent changes) and step speeds would make a still object move.
    last = np.maximum(n_ok - 1, 0)
    mid = last // 2
    rows = np.arange(m)

    def disp(i0: np.ndarray, i1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return cc[rows, i1] - cc[rows, i0], tt[rows, i1] - tt[rows, i0]

    net, span_t = disp(np.zeros(m, np.int64), last)
    mean_speed = np.where(span_t > 0, np.hypot(net[:, 0], net[:, 1]) / np.where(span_t > 0, span_t, 1.0), 0.0)
    d1, t1 = disp(np.zeros(m, np.int64), mid)
    d2, t2 = disp(mid, last)
    moving = (np.hypot(*d1.T) >= 0.05) & (np.hypot(*d2.T) >= 0.05) & (t1 > 0) & (t2 > 0)
    dh = np.abs(np.angle(np.exp(1j * (np.arctan2(d2[:, 1], d2[:, 0]) - np.arctan2(d1[:, 1], d1[:, 0])))))
    heading_rate = np.where(moving, dh / np.where(moving, 0.5 * (t1 + t2), 1.0), 0.0)
    # Alignment of the motion with the segment's long axis (axial mean of the axis directions; 0.5 when
    # the object does not move: the expected |cos| of a random angle is 2/pi, 0.5 sits between both ends).
    axis2 = np.where(ok, np.exp(2j * g[..., _I_AXIS]), 0.0).sum(axis=1)
    axis = 0.5 * np.angle(axis2)
    fast = mean_speed >= _MOVING_MPS
    alignment = np.where(fast, np.abs(np.cos(np.arctan2(net[:, 1], net[:, 0]) - axis)), 0.5)

    # Gait periodicity of the width (the feet open and close; B8's S_d drives the segment's extent).
    valid_w = np.arange(w)[None, :] < n_ok[:, None]
    mean_w = np.where(valid_w, ww, 0.0).sum(axis=1) / np.maximum(n_ok, 1)
    x = np.where(valid_w, ww - mean_w[:, None], 0.0)
    var = (x**2).sum(axis=1)
    width_std = np.sqrt(var / np.maximum(n_ok, 1))
    span = np.where(n_ok > 1, (np.where(valid_w, tt, -np.inf).max(axis=1) - tt[:, 0]), 0.0)
    frame_dt = span / np.maximum(n_ok - 1, 1)
    period = np.zeros(m)
    # lag * frame_dt inside the band's periods [1/2, 1/0.6] s, and enough overlap to be meaningful; every lag
    # at once (lags, m), then only the lags where some row is in the band
    lags = np.arange(2, max(w - 1, 2))
    f = np.where(frame_dt > 0, 1.0 / np.maximum(lags[:, None] * frame_dt, 1e-9), 0.0)
    in_bands = (f >= _GAIT_BAND_HZ[0]) & (f <= _GAIT_BAND_HZ[1]) & (n_ok - lags[:, None] >= 3) & (var > 1e-12)
    for lag, in_band in zip(lags[in_bands.any(axis=1)].tolist(), in_bands[in_bands.any(axis=1)], strict=True):
        ac = (x[:, lag:] * x[:, :-lag]).sum(axis=1) / np.maximum(var, 1e-12) * (n_ok / np.maximum(n_ok - lag, 1))
        period = np.where(in_band, np.maximum(period, ac), period)
    out = np.column_stack([mean_g, mean_speed, speed_std, heading_rate, np.clip(period, -1.0, 1.0), width_std,
                           alignment])
    out[n_ok == 0] = 0.0
    return out
