"""Bird's-eye view: laser points (and, later, tracks) drawn on a metric floor grid.

Points are rasterised with one fancy-indexing assignment per frame (no Python loop over points).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True, slots=True)
class BirdseyeView:
    """A fixed window on the floor plane: ``x`` to the right of the picture, ``y`` up.

    Parameters
    ----------
    x_range_m, y_range_m : (min, max) of the window in the world (or sensor) frame.
    px_per_m : resolution.
    """

    x_range_m: tuple[float, float]
    y_range_m: tuple[float, float]
    px_per_m: float = 60.0

    def __post_init__(self) -> None:
        for name in ("x_range_m", "y_range_m"):
            lo, hi = getattr(self, name)
            if not hi > lo:
                raise ValueError(f"{name}: expected (min, max) with max > min, got ({lo}, {hi})")
        if self.px_per_m <= 0:
            raise ValueError(f"px_per_m: expected > 0, got {self.px_per_m}")

    @classmethod
    def fit(cls, points_m: np.ndarray, margin_m: float = 0.5, px_per_m: float = 60.0, max_px: int = 960,
            min_span_m: float = 4.0, height_px: int | None = None) -> BirdseyeView:
        """A window around all finite points (at least ``min_span_m`` on each side).

        The resolution is ``px_per_m``, lowered so no side exceeds ``max_px``; with ``height_px`` the
        picture is instead exactly that tall (and at most twice as wide).
        """
        pts = np.asarray(points_m, np.float64).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if pts.size == 0:
            pts = np.zeros((1, 2))
        lo = pts.min(axis=0) - margin_m
        hi = pts.max(axis=0) + margin_m
        grow = np.maximum(min_span_m - (hi - lo), 0.0) / 2
        lo, hi = lo - grow, hi + grow
        span = hi - lo
        if height_px is not None:
            px_per_m = min(height_px / span[1], 2 * height_px / span[0])
        else:
            px_per_m = min(px_per_m, max_px / float(span.max()))
        return cls((float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])), px_per_m)

    @property
    def size_px(self) -> tuple[int, int]:
        """(width, height) in pixels, each even (video encoders want even sizes)."""
        w = int(np.ceil((self.x_range_m[1] - self.x_range_m[0]) * self.px_per_m))
        h = int(np.ceil((self.y_range_m[1] - self.y_range_m[0]) * self.px_per_m))
        return w + w % 2, h + h % 2

    def to_pixels(self, points_m: np.ndarray) -> np.ndarray:
        """``(n, 2)`` floor points -> ``(n, 2)`` integer pixel (u, v); non-finite points -> -1."""
        pts = np.asarray(points_m, np.float64).reshape(-1, 2)
        u = (pts[:, 0] - self.x_range_m[0]) * self.px_per_m
        v = (self.y_range_m[1] - pts[:, 1]) * self.px_per_m
        uv = np.stack([u, v], axis=1)
        ok = np.all(np.isfinite(uv), axis=1)
        out = np.full(uv.shape, -1, np.int64)
        out[ok] = np.floor(uv[ok]).astype(np.int64)
        return out

    def background(self, grid_m: float = 1.0) -> np.ndarray:
        """An empty frame with a metric grid every ``grid_m`` and the origin's axes."""
        w, h = self.size_px
        img = np.full((h, w, 3), 24, np.uint8)
        xs = np.arange(np.ceil(self.x_range_m[0] / grid_m), np.floor(self.x_range_m[1] / grid_m) + 1) * grid_m
        ys = np.arange(np.ceil(self.y_range_m[0] / grid_m), np.floor(self.y_range_m[1] / grid_m) + 1) * grid_m
        cols = self.to_pixels(np.stack([xs, np.full_like(xs, self.y_range_m[1])], 1))[:, 0]
        rows = self.to_pixels(np.stack([np.full_like(ys, self.x_range_m[0]), ys], 1))[:, 1]
        img[:, cols.clip(0, w - 1)] = 48
        img[rows.clip(0, h - 1), :] = 48
        origin = self.to_pixels(np.zeros((1, 2)))[0]
        if 0 <= origin[0] < w and 0 <= origin[1] < h:
            cv2.arrowedLine(img, tuple(int(c) for c in origin), (int(origin[0] + self.px_per_m), int(origin[1])),
                            (0, 0, 200), 2, tipLength=0.2)
            cv2.arrowedLine(img, tuple(int(c) for c in origin), (int(origin[0]), int(origin[1] - self.px_per_m)),
                            (0, 200, 0), 2, tipLength=0.2)
        return img

    def draw_points(self, img: np.ndarray, points_m: np.ndarray, color_bgr: tuple[int, int, int],
                    radius_px: int = 1) -> np.ndarray:
        """Draw points in place as small squares of side ``2 * radius_px + 1``; returns ``img``."""
        h, w = img.shape[:2]
        uv = self.to_pixels(points_m)
        uv = uv[(uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] < w) & (uv[:, 1] < h)]
        if uv.size == 0:
            return img
        offsets = np.arange(-radius_px, radius_px + 1)
        du, dv = np.meshgrid(offsets, offsets)
        uu = (uv[:, 0, None] + du.ravel()[None, :]).clip(0, w - 1)
        vv = (uv[:, 1, None] + dv.ravel()[None, :]).clip(0, h - 1)
        img[vv.ravel(), uu.ravel()] = color_bgr
        return img

    def label(self, img: np.ndarray, text: str) -> np.ndarray:
        cv2.putText(img, text, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (230, 230, 230), 1, cv2.LINE_AA)
        return img
