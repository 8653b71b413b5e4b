"""Camera overlay: tracked boxes with their ids, foreground contours and the frame number drawn on the image.

Each id has its own colour (hues spaced by the golden angle, so neighbouring ids differ), the same in every
frame; a track's box is drawn thick while a detection confirms it and thin while it coasts or is inside a
group (its situation ``merged``), with a short trail of its bottom centre. Foreground blob contours are
drawn in light yellow, the raw detections (of a detection file) as thin grey boxes.
"""

from __future__ import annotations

import colorsys
from collections import deque
from collections.abc import Sequence
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..types import Detection, Situation, TrackState

if TYPE_CHECKING:
    from .people import FrameResult

__all__ = ["OverlayRenderer", "draw_overlay", "id_colour"]

_GOLDEN = 0.618033988749895
_CONTOUR = (120, 255, 255)  # BGR light yellow
_DETECTION = (170, 170, 170)
_FONT = cv2.FONT_HERSHEY_SIMPLEX


def id_colour(track_id: int) -> tuple[int, int, int]:
    """A saturated BGR colour for ``track_id``: hue ``(id × golden ratio) mod 1``, the same in every frame."""
    hue = (int(track_id) * _GOLDEN) % 1.0
    r, g, b = colorsys.hsv_to_rgb(hue, 0.85, 1.0)
    return int(255 * b), int(255 * g), int(255 * r)


def _pt(x: float, y: float) -> tuple[int, int]:
    return round(x), round(y)


def draw_overlay(image_bgr: np.ndarray, states: Sequence[TrackState], *, contours: Sequence[np.ndarray] = (),
                 detections: Sequence[Detection] = (), frame: int | None = None,
                 trails: dict[int, Sequence[tuple[float, float]]] | None = None) -> np.ndarray:
    """Draw one frame's overlay on a copy of ``image_bgr``.

    Parameters
    ----------
    image_bgr : (H, W, 3) uint8
    states : sequence of TrackState
        With ``box_px``; states without a box are skipped.
    contours : sequence of (m, 1, 2) int32
        Foreground contours (:func:`~fusiontrack.vision.blobs.blob_contours`).
    detections : sequence of Detection
        Drawn as thin grey boxes.
    frame : int, optional
        Frame number written in the top-left corner.
    trails : dict of id -> sequence of (u, v), optional
        Past bottom centres of each track, oldest first.

    Returns
    -------
    (H, W, 3) uint8
    """
    out = np.ascontiguousarray(image_bgr).copy()
    scale = max(out.shape[0] / 480.0, 0.6)
    if len(contours):
        cv2.drawContours(out, list(contours), -1, _CONTOUR, 1, cv2.LINE_AA)
    for d in detections:
        if d.box_px is not None:
            u0, v0, u1, v1 = d.box_px
            cv2.rectangle(out, _pt(u0, v0), _pt(u1, v1), _DETECTION, 1, cv2.LINE_4)
    for tid, pts in (trails or {}).items():
        if len(pts) > 1:
            cv2.polylines(out, [np.round(np.array(pts)).astype(np.int32).reshape(-1, 1, 2)], False,
                          id_colour(tid), 1, cv2.LINE_AA)
    for s in states:
        if s.box_px is None:
            continue
        colour = id_colour(s.track_id)
        u0, v0, u1, v1 = s.box_px
        seen = bool(s.sensors) and s.situation != Situation.MERGED
        cv2.rectangle(out, _pt(u0, v0), _pt(u1, v1), colour, 2 if seen else 1, cv2.LINE_AA)
        label = str(s.track_id) + ("" if seen else "*")
        (tw, th), base = cv2.getTextSize(label, _FONT, 0.45 * scale, 1)
        x, y = _pt(u0, v0)
        y = max(y, th + base + 1)
        cv2.rectangle(out, (x, y - th - base - 1), (x + tw + 2, y), colour, -1)
        cv2.putText(out, label, (x + 1, y - base), _FONT, 0.45 * scale, (0, 0, 0), 1, cv2.LINE_AA)
    if frame is not None:
        text = f"frame {frame}  tracks {sum(s.box_px is not None for s in states)}"
        (tw, th), base = cv2.getTextSize(text, _FONT, 0.5 * scale, 1)
        cv2.rectangle(out, (0, 0), (tw + 8, th + base + 6), (0, 0, 0), -1)
        cv2.putText(out, text, (4, th + 3), _FONT, 0.5 * scale, (255, 255, 255), 1, cv2.LINE_AA)
    return out


class OverlayRenderer:
    """Draws :class:`~fusiontrack.vision.people.FrameResult` records in order, keeping each track's trail.

    Parameters
    ----------
    trail_frames : int
        Length of the trail of bottom centres (20 frames).
    """

    def __init__(self, trail_frames: int = 20) -> None:
        self.trail_frames = int(trail_frames)
        self._trails: dict[int, deque[tuple[float, float]]] = {}

    def render(self, result: FrameResult) -> np.ndarray:
        """The overlay of one frame (frame numbers 1-based, as in MOT files)."""
        alive = set()
        for s in result.states:
            if s.box_px is None:
                continue
            alive.add(s.track_id)
            u0, _, u1, v1 = s.box_px
            self._trails.setdefault(s.track_id, deque(maxlen=self.trail_frames)).append(((u0 + u1) / 2, v1))
        for tid in [t for t in self._trails if t not in alive]:
            del self._trails[tid]
        show_dets = result.mode == "detections"
        return draw_overlay(result.image.bgr(), result.states, contours=result.contours(),
                            detections=result.detections if show_dets else (), frame=result.index + 1,
                            trails=self._trails)
