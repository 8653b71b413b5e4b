"""numba kernel of the CART split search of :func:`fusiontrack.vision.appearance.fit_cart` (B14's weak learners).

Why: B15 fits a few hundred small trees per minute of video, and with a few hundred samples a node's split search
costs what its dozen numpy calls on ``(features, samples)`` arrays cost, not what its arithmetic costs: the kernel
is ~6x faster on a 500-sample node (a tree ~3x). The numpy code in ``fit_cart`` stays the reference and
tests/test_vision_appearance.py holds the kernel to it. The arithmetic is the numpy code's, in its order (running
sums added one sample at a time as ``cumsum`` adds them, squares as products, no fused multiply-add), so the split
chosen is the same, bit for bit: the first of the best in feature-major order, as ``argmax`` takes it.
``FUSIONTRACK_NUMBA=0``, or numba missing, keeps the numpy code (:mod:`fusiontrack.tracking._jit`).
"""

from __future__ import annotations

import numpy as np

from ..tracking._jit import ENABLED, njit

__all__ = ["ENABLED", "best_split"]

if ENABLED:

    @njit(cache=True)
    def best_split(xs, wpo, wno, sp, sn, lo, hi):  # type: ignore[no-untyped-def]
        """The split after sorted position ``lo + i`` of feature ``f`` maximising the weighted Gini proxy
        ``Σ_children Σ_c w_c² / w_child``, among the positions ``lo..hi`` where the sorted values ``xs (d, m)``
        rise by more than 1e-7; ``wpo, wno (d, m)``: the positive and negative weights in each feature's sorted
        order, ``sp, sn`` their sums. ``(f, i)``, or ``(-1, -1)`` when no position is valid."""
        d = xs.shape[0]
        best = -np.inf
        bf, bi = -1, -1
        for f in range(d):
            cp = 0.0
            cn = 0.0
            for k in range(lo):
                cp += wpo[f, k]
                cn += wno[f, k]
            for k in range(lo, hi + 1):
                cp += wpo[f, k]
                cn += wno[f, k]
                if not xs[f, k + 1] > xs[f, k] + 1e-7:
                    continue
                cpr = sp - cp
                cnr = sn - cn
                wl = cp + cn
                wr = cpr + cnr
                v = ((cp * cp + cn * cn) / wl if wl > 0 else 0.0) + ((cpr * cpr + cnr * cnr) / wr if wr > 0 else 0.0)
                if v > best:
                    best = v
                    bf, bi = f, k - lo
        return bf, bi

else:  # pragma: no cover
    best_split = None
