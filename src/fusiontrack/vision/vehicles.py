"""Camera branch of seed 003's traffic monitoring (ALGORITHMS.md D3): vehicles on the road from one camera.

Per frame, :class:`CameraVehicleDetector` turns an image into :class:`~fusiontrack.types.Detection` records in
the ROAD frame (the contract of the D5 fusion):

* **Background** (A1-A3): :class:`~fusiontrack.vision.foreground.ForegroundModel` with D3's α = 0.002
  (``history = 500``); A2 keeps a stopped vehicle, A3 removes cast shadows, and an illumination jump (a cloud,
  ``[[70, 0.55]]`` on the simulated camera_0) is absorbed by the model's relearning and gain normalisation:
  vehicle pixels where no vehicle is stay under 0.2 % of the road from the frame of the drop on. Three
  additions for traffic [RECON]:

  - A3's *highlights* count as vehicle: a grey or white car on dark asphalt has the road's chromaticity and
    is brighter, which is what A3 calls a highlight (vehicles cast no highlights on the road).
  - A3 calls shadow the side of a grey car in the shade (darker than the road behind it, same
    chromaticity), which cuts the car in pieces: blobs are the components of vehicle *and* shadow pixels,
    each keeping only its vehicle pixels (:meth:`CameraVehicleDetector._vehicle_blobs`).
  - A road memory learned only where no vehicle is seen vetoes foreground pixels that show the empty road
    (times the frame's gain) where MOG2 and A2 have forgotten it: after a jam crawls through for a minute,
    both have learned the cars, and the reappearing road would otherwise stay a "stopped object"
    (:meth:`CameraVehicleDetector._road_memory_veto`).

* **ROI** [RECON]: the road rectangles ``(x0, y0, x1, y1, width)`` widened by ``road_margin_m`` on every side,
  seen through the ground homography: a pixel is in the ROI when its ray meets the road plane in front of the
  camera inside a road rectangle (:func:`road_roi_mask`: the projected polygon filled, exact under lens
  distortion). Blobs (A4, :func:`~fusiontrack.vision.blobs.extract_blobs`) come from the whole foreground and
  are kept when their ground contact point (bottom-centre) is in the ROI, so the top of a vehicle rising above
  the road's image is not cut off; the minimum area is ``min_footprint_m2`` of road at the blob's
  bottom-centre in pixels (``1 / |det J|``, ``J`` the image-to-road Jacobian), at least ``min_area_px``.
  Only the image *window* that can hold such a vehicle is processed (:meth:`CameraVehicleDetector.window`: the
  ROI's bounding rectangle grown by the image of every road point within 3 m more, lifted to 4.2 m; about half
  of a 640 × 480 frame on the simulated road); A1-A4 and the road memory cost in proportion (17.7 → 10.3 ms of
  CPU per frame on the simulated road, the same detections). A1's illumination test (more than 60 % of the
  frame foreground) keeps measuring the whole frame: a plain MoG on every 8th pixel of every 8th row (at 640 × 480)
  gives the foreground fraction outside the window, and the window's model is told the window fraction at which the
  frame's would pass 60 % (:meth:`CameraVehicleDetector._illumination_test`), so a large near vehicle or a queue
  filling most of the window does not make it relearn (and absorb stopped vehicles) at 10α.
* **Vehicles from blobs** [RECON]: pieces of one vehicle (a sill band under a body A3 lost) are joined when
  they lie inside the image of a car standing on the lowest piece's footprint
  (:meth:`CameraVehicleDetector._join_fragments`); a blob longer than 1.6 car lengths on the road (a queue
  overlapping in the image) is cut where its lower outline jumps along the road
  (:meth:`CameraVehicleDetector._parts`), each part's box then being the image of a car at its position.
  Both need the camera matrix ``P = K [r1 r2 r1×r2 t]``: from ``K`` when given, else ``K`` is estimated from
  the homography (square pixels, principal point at the centre).
* **Ground position** [RECON]: D3's ground point, the image of the box's bottom-centre under ``H_c``, is the
  vehicle's nearest bottom edge, short of its footprint centre by the footprint's half-extent along the
  viewing direction (measured 2.4 m median on the simulated road). On the road plane, the image row of the
  bottom edge is a line ``ℓ`` (through the ground point ``g``, direction ``t``); the footprint touches ``ℓ``
  from the far side, so its centre is ``c = g + h n`` with ``n ⊥ t`` pointing away from the camera and
  ``h = L/2 |cos(θ − φ_n)| + W/2 |sin(θ − φ_n)|`` the support of an ``L × W`` rectangle of heading ``θ`` (the
  road's axis, or the track's course when it moves) along ``n``; ``L × W`` is the class prior (car 4.5 × 1.8 m,
  bicycle 1.7 × 0.6 m), the length raised to the apparent ground length when that is longer. Pixel
  coordinates are continuous (OpenCV: pixel ``(row v, column u)`` has its centre at ``(u, v)``), so A4's box
  edges are moved by −0.5 px first (the true extreme lies anywhere in the last row or column). Residual on the
  simulated road (``benchmarks/camera_vehicles.py``): 0.2-0.5 m median per range band in free traffic,
  0.4-0.9 m through a jam; p95 1-2 m within 60 m of the pole, up to 3-4 m beyond 60 m.
* **Covariance**: ``J (σ_px² I) Jᵀ`` (2 px image noise through the homography's Jacobian at the bottom
  edge: it grows with the squared distance) plus the footprint-centre uncertainty ``σ_n² n nᵀ + σ_t² t tᵀ``;
  a box cut by the image border adds ``(L/2)²`` (``L²`` along ``n`` when cut at the bottom).
* **Features**: ``box_px`` (A4's box, pixel edges), ``"box"`` = ``(cx, cy, apparent length, apparent width,
  heading)``, ``"hist_hsv"`` (A4's normalised HSV 8 × 8 × 4 histogram of the vehicle's pixels,
  :func:`~fusiontrack.vision.blobs.box_histograms`), ``"track_id"``, ``"velocity_mps"`` (when the track has two
  or more hits), ``"ground_point_m"`` (D3's uncorrected bottom-centre on the road), ``"truncated"`` (box cut
  by the image border) and ``"queue"`` (number of parts of its queue, 0 alone). The apparent ground length
  and width are the extents, along and across the road, of the blob's lower outline (lowest pixel of each
  column) mapped to the road: the visible bottom edges, an L seen obliquely, one side seen from behind (a
  lower bound). A vehicle whose apparent width is below ``bicycle_max_width_m`` is a bicycle, else a car.
* **Tracking** (A5-style, X5) [RECON]: a constant-velocity Kalman filter per vehicle on the ROAD plane
  (footprint centre, measurement covariance as above), associated by overlap in the image: each track's last
  box is moved with the image motion of its predicted ground point and scaled by the change of depth; the cost
  is ``1 − IoU`` for ``IoU >= iou_min`` or ``1 + d²/gate`` otherwise, every pair within the chi-square gate
  ``d² <= gate_chi2`` of the ground positions, plus ``colour_weight (1 − BC)`` (X4); Hungarian (X2). A track
  is confirmed after ``n_confirm`` consecutive hits (score 1.0; tentative 0.5), a tentative track ends at
  its first miss, a confirmed one after ``max_coast_s`` without a detection.

The homography is a plain ``(3, 3)`` image-to-road matrix on ideal (undistorted) pixels; with a lens model
(``K``, ``dist``) pixels are undistorted first. Its sign is fixed so that the third homogeneous coordinate is
positive for pixels below the horizon (a road frame with Z up and the camera above the road gives
``det H < 0``). :func:`camera_homography` builds it from a recording's believed calibration (``CameraInfo`` +
the ``<camera>_calibrated`` pose): ``H_c⁻¹ = K [r1 r2 t]``. Black frames (dropouts) and frames out of time
order give no detection and leave the models alone; missing frames only lengthen the tracker's time step.

Known limits: a queue of cars seen from behind along the road (the simulated jam and the platoon after it, on
camera_0) overlaps in the image beyond what the outline split recovers, and A2 slowly loses a vehicle parked
for a minute or more (its stopped pixels are released one by one): image recall falls to 20-50 % there,
against 93-100 % in free traffic.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np
from scipy import ndimage

from ..errors import ConfigError, RecordingError
from ..geometry import PinholeCamera
from ..tracking import kalman
from ..tracking.association import hungarian
from ..types import Detection, Image
from .blobs import BlobParams, Blobs, box_histograms, clean_mask
from .foreground import ForegroundModel, ForegroundParams, ForegroundResult, PixelLabel
from .people import box_iou, camera_from_recording
from .shadows import brightness_chromaticity

__all__ = [
    "CameraVehicleDetector",
    "VehicleDetectorParams",
    "VehicleFrame",
    "camera_ground_homography",
    "camera_homography",
    "orient_homography",
    "road_polygons",
    "road_roi_mask",
    "vehicle_detections_for_recording",
    "vehicle_detectors_for_recording",
]

log = logging.getLogger(__name__)


def _traffic_foreground() -> ForegroundParams:
    return ForegroundParams(history=500)  # D3: A1 with α = 0.002 for traffic


def _traffic_blobs() -> BlobParams:
    return BlobParams(min_area_px=0)  # the minimum area is applied per blob, scaled by its distance


@dataclass(frozen=True, slots=True)
class VehicleDetectorParams:
    """Parameters of :class:`CameraVehicleDetector` [RECON unless noted]; metres, pixels, seconds.

    Attributes
    ----------
    foreground : ForegroundParams
        A1-A3 (D3: α = 0.002, ``history = 500``; the rest A1's defaults).
    blobs : BlobParams
        A4's morphology and connectivity (its minimum area is replaced by the scaled one below).
    highlights_are_vehicles : bool
        A3 highlight pixels count as vehicle (True: a light car on dark asphalt is a "highlight").
    shadow_bridge : bool
        Join blobs through the shadow pixels between them (True; see :meth:`CameraVehicleDetector._vehicle_blobs`).
    shadow_bridge_max_fraction : float
        No joining when shadow covers more of the frame than this (0.2).
    fragment_containment : float
        A blob with this fraction of its pixels inside the expected silhouette of the vehicle below it is a piece
        of that vehicle (0.5; 1 = off; see :meth:`CameraVehicleDetector._join_fragments`).
    road_memory_rate, road_memory_tolerance : float
        Learning rate of the remembered empty road (0.002 per frame) and the relative brightness and chromaticity
        tolerance within which a foreground pixel is that road (0.1; 0 = off; see
        :meth:`CameraVehicleDetector._road_memory_veto`).
    road_memory_warmup : int
        Frames before the road memory starts from MOG2's background (30).
    road_margin_m : float
        The road rectangles are widened by this on every side for the ROI (2.0 m: vehicles on the verge).
    min_footprint_m2 : float
        A blob is kept when its area is at least this much road, in pixels at its bottom-centre (0.5 m²,
        half a bicycle's footprint; the image of a vehicle is larger than its foreshortened footprint).
    min_area_px : int
        Lower bound of the minimum area, px (16).
    pixel_sigma_px : float
        Image noise of the bottom edge (D5: 2 px).
    correct_footprint : bool
        Move the bottom-edge ground point to the footprint centre (True).
    car_size_m, bicycle_size_m : (float, float, float)
        Size prior ``(length, width, height)`` of a car (4.5, 1.8, 1.5) and a bicycle with its rider (1.7, 0.6,
        1.7); the height only shapes the image box of a vehicle in a queue.
    bicycle_max_width_m : float
        Apparent ground width below which a blob is a bicycle (1.1 m).
    split_queues : bool
        Cut a blob longer than ``queue_min_cars`` car lengths into vehicles (True; see
        :meth:`CameraVehicleDetector._parts`). A bus or truck seen without a jump in its outline is cut too:
        raise ``queue_min_cars`` or switch this off where they drive.
    queue_min_cars : float
        A blob (or a stretch of a queue) longer than this many car lengths holds two or more vehicles (1.6).
    queue_jump_m : float
        Smallest jump of the outline's ground coordinate between two vehicles of a queue (1.5 m).
    queue_gap_m : float
        Gap between queued vehicles assumed where no jump separates them (1.5 m).
    footprint_sigma_m : (float, float)
        σ of the footprint centre along and across the viewing direction beyond the pixel noise (0.4, 0.3 m:
        size prior, heading and segmentation; measured on the simulated road).
    iou_min : float
        Smallest overlap of an image association pair (0.1).
    gate_chi2 : float
        Chi-square gate of a pair's ground positions, 2 dof (13.8, 99.9 %).
    colour_weight : float
        Weight of ``1 − BC`` of the colour histograms in the cost (0.3; 0 = off).
    q_m2_s3 : float
        X5 acceleration noise intensity (2.0 m²/s³; X5 suggests 1 for vehicles, the camera's footprint
        centres jump with the class decision).
    velocity0_mps : float
        Prior σ of a new track's speed along each axis (10 m/s).
    n_confirm : int
        Consecutive hits that confirm a track (3).
    max_coast_s : float
        A confirmed track without a detection for longer ends (0.7 s).
    heading_min_speed_mps : float
        Below this track speed the heading is the road's axis, above it the track's course (1.5 m/s).
    frame_dt_s : float
        Time step assumed for the first frame (1/15 s).
    crop_to_road : bool
        Process only the image window that can hold a vehicle standing in the ROI (True; see
        :meth:`CameraVehicleDetector.window`): the background model, masks and blobs cost in proportion.
    window_margin_m, window_height_m : float
        The window holds the road rectangles widened by ``road_margin_m + window_margin_m`` (3.0 m: half a car
        length beyond a contact point at the ROI's edge, and more) from the road up to ``window_height_m``
        (4.2 m: a truck or bus of 3-4 m and more; the class priors, 1.5-1.7 m, are only what the detector
        assumes of a vehicle it cannot see whole). The foreground model's illumination test still looks at the
        whole frame (:meth:`CameraVehicleDetector._illumination_test`).
    processing_scale : int
        The window is shrunk by this factor (``cv2.INTER_AREA``) before A1-A4 and the road memory, the
        morphology, minimum areas and the road memory's dilation scaled with it, and the blobs' label image is
        enlarged back (nearest) to full resolution, so the geometry, the histograms and the tracker work on
        full-resolution pixels as before (1 = off). Measured at 2 on the simulated road: the camera branch costs a
        third of full resolution, but a pixel that mixes a vehicle with its cast shadow is neither to A3, so it
        is called object: boxes grow 2-5 small pixels into the shadow (bottom edges 4-7 px low), which puts the
        ground position 2-5 m short at 40-90 m (0.2-0.5 m at full resolution) and breaks the camera-only tracks.
    """

    foreground: ForegroundParams = field(default_factory=_traffic_foreground)
    blobs: BlobParams = field(default_factory=_traffic_blobs)
    highlights_are_vehicles: bool = True
    shadow_bridge: bool = True
    shadow_bridge_max_fraction: float = 0.2
    fragment_containment: float = 0.5
    road_memory_rate: float = 0.002
    road_memory_tolerance: float = 0.1
    road_memory_warmup: int = 30
    road_margin_m: float = 2.0
    min_footprint_m2: float = 0.5
    min_area_px: int = 16
    pixel_sigma_px: float = 2.0
    correct_footprint: bool = True
    car_size_m: tuple[float, float, float] = (4.5, 1.8, 1.5)
    bicycle_size_m: tuple[float, float, float] = (1.7, 0.6, 1.7)
    bicycle_max_width_m: float = 1.1
    split_queues: bool = True
    queue_min_cars: float = 1.6
    queue_jump_m: float = 1.5
    queue_gap_m: float = 1.5
    footprint_sigma_m: tuple[float, float] = (0.4, 0.3)
    iou_min: float = 0.1
    gate_chi2: float = 13.8
    colour_weight: float = 0.3
    q_m2_s3: float = 2.0
    velocity0_mps: float = 10.0
    n_confirm: int = 3
    max_coast_s: float = 0.7
    heading_min_speed_mps: float = 1.5
    frame_dt_s: float = 1.0 / 15.0
    crop_to_road: bool = True
    window_margin_m: float = 3.0
    window_height_m: float = 4.2
    processing_scale: int = 1

    def __post_init__(self) -> None:
        if not isinstance(self.foreground, ForegroundParams):
            raise ConfigError(f"VehicleDetectorParams.foreground: expected ForegroundParams, got "
                              f"{type(self.foreground).__name__}")
        if not isinstance(self.blobs, BlobParams):
            raise ConfigError(f"VehicleDetectorParams.blobs: expected BlobParams, got {type(self.blobs).__name__}")
        for name in ("n_confirm", "min_area_px", "road_memory_warmup", "processing_scale"):
            v = getattr(self, name)
            lo = 1 if name in ("n_confirm", "processing_scale") else 0
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ConfigError(f"VehicleDetectorParams.{name}: expected an integer >= {lo}, got {v!r}")
        for name in ("shadow_bridge_max_fraction", "fragment_containment", "road_memory_rate", "road_memory_tolerance"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, int | float) and 0 <= v <= 1):
                raise ConfigError(f"VehicleDetectorParams.{name}: expected a value in [0, 1], got {v!r}")
        for name in ("road_margin_m", "min_footprint_m2", "colour_weight", "q_m2_s3", "max_coast_s",
                     "heading_min_speed_mps", "bicycle_max_width_m", "queue_gap_m", "queue_jump_m", "queue_min_cars",
                     "window_margin_m", "window_height_m"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"VehicleDetectorParams.{name}: expected a finite value >= 0, got {v!r}")
        for name in ("pixel_sigma_px", "gate_chi2", "velocity0_mps", "frame_dt_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (np.isfinite(v) and v > 0):
                raise ConfigError(f"VehicleDetectorParams.{name}: expected a finite value > 0, got {v!r}")
        if not (isinstance(self.iou_min, int | float) and 0 < self.iou_min <= 1):
            raise ConfigError(f"VehicleDetectorParams.iou_min: expected a value in (0, 1], got {self.iou_min!r}")
        for name, n in (("car_size_m", 3), ("bicycle_size_m", 3), ("footprint_sigma_m", 2)):
            v = _floats(getattr(self, name), n)
            if v is None or np.any(v < 0) or (n == 3 and np.any(v <= 0)):
                raise ConfigError(f"VehicleDetectorParams.{name}: expected {n} finite values "
                                  f"{'> 0' if n == 3 else '>= 0'} m, got {getattr(self, name)!r}")


def _floats(value: Any, n: int) -> np.ndarray | None:
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return v if v.shape == (n,) and np.all(np.isfinite(v)) else None


# --------------------------------------------------------------------------------------------------
# Road geometry and the homography
# --------------------------------------------------------------------------------------------------


def _roads(roads: Any) -> np.ndarray:
    try:
        r = np.asarray(roads, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"roads: expected an (n, 5) array of (x0, y0, x1, y1, width) in m, got {roads!r}") from err
    r = r.reshape(1, -1) if r.ndim == 1 else r
    if r.ndim != 2 or r.shape[1] != 5 or len(r) == 0:
        raise ConfigError(f"roads: expected an (n, 5) array of (x0, y0, x1, y1, width) in m, got shape {r.shape}")
    if not np.all(np.isfinite(r)):
        raise ConfigError(f"roads: non-finite values in {r.tolist()}")
    bad = np.flatnonzero((r[:, 4] <= 0) | (np.hypot(r[:, 2] - r[:, 0], r[:, 3] - r[:, 1]) <= 0))
    if bad.size:
        raise ConfigError(f"roads: road {int(bad[0])} has zero length or a width <= 0: {r[bad[0]].tolist()}")
    return r


def road_polygons(roads: Any, margin_m: float = 0.0) -> np.ndarray:
    """Corners of each road rectangle widened by ``margin_m`` on every side, ``(n, 4, 2)`` m, counter-clockwise.

    Parameters
    ----------
    roads : (n, 5) float
        ``(x0, y0, x1, y1, width)`` per road: its axis from ``(x0, y0)`` to ``(x1, y1)`` and its full width.
    margin_m : float
    """
    r = _roads(roads)
    a, b = r[:, :2], r[:, 2:4]
    d = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    left = np.column_stack([-d[:, 1], d[:, 0]]) * (r[:, 4:5] / 2 + margin_m)
    a, b = a - margin_m * d, b + margin_m * d
    return np.stack([a - left, b - left, b + left, a + left], axis=1)


def _road_frames(roads: np.ndarray, margin_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Start points ``(n, 2)``, unit axes ``(n, 2)``, lengths ``(n,)`` and half widths ``(n,)`` (with margin)."""
    a, b = roads[:, :2], roads[:, 2:4]
    length = np.linalg.norm(b - a, axis=1)
    return a, (b - a) / length[:, None], length, roads[:, 4] / 2 + margin_m


def _in_roads(xy: np.ndarray, roads: np.ndarray, margin_m: float) -> np.ndarray:
    """``(n,) bool``: road points inside any road rectangle widened by ``margin_m`` (NaN -> False)."""
    a, d, length, half = _road_frames(roads, margin_m)
    inside = np.zeros(len(xy), bool)
    with np.errstate(invalid="ignore"):
        for k in range(len(roads)):  # a handful of roads
            rel = xy - a[k]
            s = rel @ d[k]
            lat = rel[:, 1] * d[k, 0] - rel[:, 0] * d[k, 1]
            inside |= (s >= -margin_m) & (s <= length[k] + margin_m) & (np.abs(lat) <= half[k])
    return inside


_P5_P95 = np.true_divide([5, 95], 100)


def _p5_p95(x: np.ndarray) -> np.ndarray:
    """``np.percentile(x, [5, 95], axis=0)`` (method ``"linear"``), bit for bit, for a small finite sample ``(n >= 1,
    ...)``: the same order statistics and interpolation without ``np.percentile``'s per-call overhead (the outline
    statistics take several per frame)."""
    xs = np.sort(x, axis=0)
    n = xs.shape[0]
    vi = (n - 1) * _P5_P95
    above = vi >= n - 1
    prev = np.where(above, -1.0, np.floor(vi))
    nxt = np.where(above, -1.0, np.floor(vi) + 1)
    g = (vi - prev).reshape((2,) + (1,) * (xs.ndim - 1))
    a, b = xs[prev.astype(np.intp)], xs[nxt.astype(np.intp)]
    d = b - a
    return np.where(g >= 0.5, b - d * (1 - g), a + d * g)


def _nearest_road_axis(xy: np.ndarray, roads: np.ndarray) -> np.ndarray:
    """Unit axis ``(n, 2)`` of the road nearest to each point (distance to its axis segment)."""
    a, d, length, _ = _road_frames(roads, 0.0)
    if len(roads) == 1:  # one road: its axis, wherever the point
        return np.repeat(d, len(xy), axis=0)
    rel = xy[:, None, :] - a[None]  # (n, r, 2)
    s = np.clip(np.einsum("nrk,rk->nr", rel, d), 0.0, length[None])
    dist = np.linalg.norm(rel - s[..., None] * d[None], axis=2)
    k = np.argmin(np.where(np.isfinite(dist), dist, np.inf), axis=1)
    return d[k]


def orient_homography(H_img2road: Any) -> np.ndarray:
    """Validate an image-to-road homography and fix its sign: ``w > 0`` for pixels below the horizon.

    For a camera above a road frame with Z up, ``road2image = K [r1 r2 t]`` (``w`` = depth > 0 in front)
    has determinant ``−fx fy C_z < 0``, so does its inverse; a homography of positive determinant (e.g. from a
    DLT, which fixes no sign) is negated. Returned scaled to unit Frobenius norm.

    Raises
    ------
    ConfigError
        Not a finite, invertible ``(3, 3)`` matrix.
    """
    try:
        H = np.asarray(H_img2road, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"H_img2road: expected a (3, 3) homography, got {H_img2road!r}") from err
    if H.shape != (3, 3) or not np.all(np.isfinite(H)):
        raise ConfigError(f"H_img2road: expected a finite (3, 3) homography, got shape {H.shape}")
    H = H / max(np.linalg.norm(H), 1e-300)
    det = np.linalg.det(H)
    if not abs(det) > 1e-12:
        raise ConfigError(f"H_img2road: singular homography (det {det:.3g})")
    return -H if det > 0 else H


def camera_ground_homography(camera: PinholeCamera) -> np.ndarray:
    """Image-to-road homography ``(3, 3)`` of a posed camera, on ideal (undistorted) pixels: ``(K [r1 r2 t])⁻¹``,
    oriented (:func:`orient_homography`).

    Raises
    ------
    ConfigError
        The camera centre lies on the road plane.
    """
    M = camera.K @ camera.world2cam[:3][:, [0, 1, 3]]
    if abs(np.linalg.det(M)) < 1e-12 * np.linalg.norm(M) ** 3:
        raise ConfigError("camera: its centre lies on the road plane Z = 0 (no ground homography)")
    return orient_homography(np.linalg.inv(M))


def _projection_matrix(H_road2img: np.ndarray, K: np.ndarray) -> np.ndarray | None:
    """``P = K [r1 r2 r1×r2 t]`` ``(3, 4)`` of the camera whose ground homography is ``road2image ∝ K [r1 r2 t]``.

    ``road2image`` must be oriented (third coordinate > 0 in front of the camera); ``None`` when degenerate.
    """
    M = np.linalg.solve(K, H_road2img)
    scale = (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1])) / 2
    if not (np.isfinite(scale) and scale > 0):
        return None
    M = M / scale
    return K @ np.column_stack([M[:, 0], M[:, 1], np.cross(M[:, 0], M[:, 1]), M[:, 2]])


def _intrinsics_from_homography(H_road2img: np.ndarray, width: int, height: int) -> np.ndarray | None:
    """``K`` of a camera with square pixels, no skew and its principal point at the image centre, from its ground
    homography (Zhang's constraints ``r1 ⊥ r2``, ``|r1| = |r2|``, least squares in ``1/f²``); ``None`` when the
    view does not determine ``f``."""
    T = np.array([[1.0, 0.0, width / 2], [0.0, 1.0, height / 2], [0.0, 0.0, 1.0]])
    h1, h2 = np.linalg.solve(T, H_road2img)[:, :2].T
    a = np.array([h1[0] * h2[0] + h1[1] * h2[1], h1[0] ** 2 + h1[1] ** 2 - h2[0] ** 2 - h2[1] ** 2])
    b = np.array([h1[2] * h2[2], h1[2] ** 2 - h2[2] ** 2])
    if not a @ a > 0:
        return None
    k = -(a @ b) / (a @ a)  # 1 / f²
    if not (np.isfinite(k) and k > 0):
        return None
    f = 1.0 / np.sqrt(k)
    return np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])


def camera_homography(rec: Any, camera: str, *, world_frame: str = "world"
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
    """The believed ground homography of a recording's camera (CameraInfo + ``<camera>_calibrated`` in tf).

    Parameters
    ----------
    rec : Recording
    camera : str
        Sensor name of the camera (``"camera_0"``).
    world_frame : str
        The road frame's name in tf.

    Returns
    -------
    H_img2road : (3, 3) float64
        Ideal (undistorted) pixels to road metres, oriented (:func:`orient_homography`).
    K : (3, 3) float64
    dist : (k,) float64
        OpenCV distortion coefficients (possibly empty or all zero).
    size : (int, int)
        ``(width, height)`` px.

    Raises
    ------
    RecordingError
        No CameraInfo for the camera, or no transform from it to ``world_frame``.
    """
    cam = camera_from_recording(rec, camera, camera, world_frame=world_frame)
    if cam is None:
        raise RecordingError(f"{rec.paths[0]}: camera {camera!r} has no CameraInfo or no pose in tf relative to "
                             f"{world_frame!r}: no ground homography (a road calibration poses it: `fusiontrack "
                             f"calibrate-road`, then track --calibration FILE)")
    return camera_ground_homography(cam), np.array(cam.K), np.array(cam.dist), (cam.width, cam.height)


def _apply_h(H: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``H (x, y, 1)`` for ``pts (n, 2)``: the dehomogenised points ``(n, 2)`` and ``w (n,)``."""
    h = pts @ H[:, :2].T + H[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[:, :2] / h[:, 2:], h[:, 2]


class _Lens:
    """Ideal pixels <-> measured pixels through OpenCV's distortion model (identity without one)."""

    def __init__(self, K: Any, dist: Any) -> None:
        d = np.zeros(0) if dist is None else np.asarray(dist, dtype=np.float64).ravel()
        if d.size not in (0, 4, 5, 8, 12, 14) or not np.all(np.isfinite(d)):
            raise ConfigError(f"dist: expected 0, 4, 5, 8, 12 or 14 finite OpenCV coefficients, got {d.tolist()}")
        self.active = bool(np.any(d != 0))
        self.K = None if K is None else np.asarray(K, dtype=np.float64)
        if self.active and (self.K is None or self.K.shape != (3, 3) or not np.all(np.isfinite(self.K))
                            or self.K[2, 2] != 1 or min(self.K[0, 0], self.K[1, 1]) <= 0):
            raise ConfigError(f"K: lens distortion {d.tolist()} needs the (3, 3) camera matrix K, got {K!r}")
        self.dist = d

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        if not self.active or len(uv) == 0:
            return uv
        out = np.full_like(uv, np.nan)
        ok = np.all(np.isfinite(uv), axis=1)
        if ok.any():
            crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
            out[ok] = cv2.undistortPoints(uv[ok].reshape(-1, 1, 2), self.K, self.dist, R=None, P=self.K,
                                          criteria=crit).reshape(-1, 2)
        return out

    def distort(self, uv_ideal: np.ndarray) -> np.ndarray:
        if not self.active or len(uv_ideal) == 0:
            return uv_ideal
        out = np.full_like(uv_ideal, np.nan)
        ok = np.all(np.isfinite(uv_ideal), axis=1)
        if ok.any():
            K = self.K
            xn = np.column_stack([(uv_ideal[ok, 0] - K[0, 2]) / K[0, 0], (uv_ideal[ok, 1] - K[1, 2]) / K[1, 1],
                                  np.ones(int(ok.sum()))])
            out[ok] = cv2.projectPoints(xn, np.zeros(3), np.zeros(3), K, self.dist)[0].reshape(-1, 2)
        return out


def _blobs_of_labels(labels: np.ndarray, min_area_px: int) -> Blobs:
    """The :class:`Blobs` of a label image ``(H, W) int32``: every label with at least ``min_area_px`` pixels, in
    label order, with its box (pixel edges), centroid and area, each measured on the label's bounding box
    (``scipy.ndimage.find_objects``; a loop over labels, a handful per frame)."""
    objs = ndimage.find_objects(labels)
    if len(objs) > 64:  # many specks (a light change): the areas of all labels at once, then the large ones
        area = np.bincount(labels.reshape(-1), minlength=len(objs) + 1)
        objs = [sl if area[c] >= min_area_px else None for c, sl in enumerate(objs, start=1)]
    boxes, cent, areas, ids = [], [], [], []
    for c, sl in enumerate(objs, start=1):
        if sl is None:
            continue
        pix = labels[sl] == c
        rows, cols = pix.sum(axis=1), pix.sum(axis=0)
        n = int(rows.sum())
        if n < max(min_area_px, 1):
            continue
        vs, us = sl[0].start, sl[1].start
        boxes.append((us, vs, sl[1].stop, sl[0].stop))
        cent.append((us + cols @ np.arange(cols.size) / n, vs + rows @ np.arange(rows.size) / n))
        areas.append(n)
        ids.append(c)
    return Blobs(np.array(boxes, np.float64).reshape(-1, 4), np.array(cent, np.float64).reshape(-1, 2),
                 np.array(areas, np.int64), np.array(ids, np.int32), labels)


def _in_frame(blobs: Blobs, offset: tuple[int, int], shape: tuple[int, int], scale: int = 1) -> Blobs:
    """Blobs found in a window whose top-left corner is ``offset = (u0, v0)`` and shrunk by ``scale``, in the
    pixels of the whole image of ``shape = (H, W)`` (the label image enlarged, nearest, and pasted into an empty
    one; a small pixel ``u`` covers the full pixels ``scale u .. scale u + scale - 1``)."""
    u0, v0 = offset
    lab = blobs.label_image
    if (u0, v0) == (0, 0) and lab.shape == shape and scale == 1:
        return blobs
    if scale > 1:
        lab = np.repeat(np.repeat(lab, scale, axis=0), scale, axis=1)
    full = np.zeros(shape, np.int32)
    full[v0:v0 + lab.shape[0], u0:u0 + lab.shape[1]] = lab
    shift = np.array([u0, v0], np.float64)
    return Blobs(blobs.boxes_px * scale + np.tile(shift, 2), blobs.centroids_px * scale + (scale - 1) / 2 + shift,
                 blobs.areas_px * scale**2, blobs.component_ids, full)


def road_roi_mask(H_img2road: Any, roads: Any, width: int, height: int, *, margin_m: float = 2.0,
                  K: Any = None, dist: Any = None) -> np.ndarray:
    """The road ROI of a camera image: pixels whose ray meets the road plane in front of the camera inside a road
    rectangle widened by ``margin_m`` (D3's road polygon seen through ``H_c⁻¹``).

    Parameters
    ----------
    H_img2road : (3, 3) float
        Ideal pixels to road metres (any sign and scale).
    roads : (n, 5) float
        ``(x0, y0, x1, y1, width)``.
    width, height : int
        Image size, px.
    margin_m : float
    K, dist : optional
        Lens model; pixels are undistorted before ``H_img2road`` when ``dist`` is non-zero.

    Returns
    -------
    (height, width) bool
    """
    if int(width) <= 0 or int(height) <= 0:
        raise ConfigError(f"image size: expected positive width and height, got {width}x{height}")
    return _roi(orient_homography(H_img2road), _roads(roads), int(width), int(height), float(margin_m),
                _Lens(K, dist))


def _roi(H: np.ndarray, roads: np.ndarray, width: int, height: int, margin_m: float, lens: _Lens) -> np.ndarray:
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    uv = lens.undistort(np.column_stack([u.ravel(), v.ravel()]))
    xy, w = _apply_h(H, uv)
    with np.errstate(invalid="ignore"):
        inside = (w > 0) & _in_roads(xy, roads, margin_m)
    return inside.reshape(height, width)


# --------------------------------------------------------------------------------------------------
# The tracker (A5-style: CV Kalman on the road plane, overlap association in the image)
# --------------------------------------------------------------------------------------------------


@dataclass(slots=True, eq=False)
class _Track:
    track_id: int
    x: np.ndarray  # (4,) x, y, vx, vy road frame
    P: np.ndarray  # (4, 4)
    box: np.ndarray  # (4,) last measured box, continuous pixels
    ground_bc: np.ndarray  # (2,) road point of the last bottom-centre
    hist: np.ndarray | None
    hits: int = 1
    coast_s: float = 0.0
    confirmed: bool = False


class _Parts:
    """Builder of the vehicles found in a frame's blobs (a whole blob, or one stretch of a queue)."""

    def __init__(self) -> None:
        self.edges_l: list[np.ndarray] = []
        self.masks: list[np.ndarray] = []
        self.axes: list[np.ndarray] = []
        self.sizes: list[tuple[float, float]] = []
        self.queues: list[int] = []
        self.parents: list[np.ndarray] = []

    def add(self, blobs: Blobs, j: int, m: np.ndarray, cols: np.ndarray | None, axis: np.ndarray, length: float,
            width: float, queue: int, u: np.ndarray, low: np.ndarray, top: np.ndarray) -> None:
        if cols is None:
            u0, v0, u1, v1 = (int(c) for c in blobs.boxes_px[j])
            keep_cols = None
        else:
            u0, u1 = int(cols.min()), int(cols.max()) + 1
            v0, v1 = int(top[m].min()), int(low[m].max()) + 1
            keep_cols = np.zeros(u1 - u0, bool)
            keep_cols[cols - u0] = True
        mask = blobs.label_image[v0:v1, u0:u1] == blobs.component_ids[j]
        if keep_cols is not None:
            mask &= keep_cols[None, :]
        self.edges_l.append(np.array([u0, v0, u1, v1], np.float64))
        self.masks.append(mask.view(np.uint8))
        self.axes.append(axis)
        self.sizes.append((length, width))
        self.queues.append(queue)
        self.parents.append(np.asarray(blobs.boxes_px[j], np.float64))

    def done(self) -> _Parts:
        self.edges = np.array(self.edges_l, np.float64).reshape(-1, 4)
        self.axis = np.array(self.axes, np.float64).reshape(-1, 2)
        sz = np.array(self.sizes, np.float64).reshape(-1, 2)
        self.length_m, self.width_m = sz[:, 0], sz[:, 1]
        self.queue = np.array(self.queues, np.int64)
        self.parent_edges = np.array(self.parents, np.float64).reshape(-1, 4)
        return self

    def subset(self, keep: np.ndarray) -> _Parts:
        out = _Parts()
        idx = np.flatnonzero(keep)
        out.edges_l = [self.edges_l[i] for i in idx]
        out.masks = [self.masks[i] for i in idx]
        out.axes = [self.axes[i] for i in idx]
        out.sizes = [self.sizes[i] for i in idx]
        out.queues = [self.queues[i] for i in idx]
        out.parents = [self.parents[i] for i in idx]
        return out.done()


@dataclass(frozen=True, slots=True, eq=False)
class _Assigned:
    track_ids: np.ndarray  # (n,) int64
    velocities: np.ndarray  # (n, 2), NaN when the track has one hit
    confirmed: np.ndarray  # (n,) bool


# --------------------------------------------------------------------------------------------------
# The detector
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class VehicleFrame:
    """The detections of one camera frame.

    Attributes
    ----------
    t_ns : int
    sensor : str
    detections : tuple of Detection
    valid : bool
        False when the frame was skipped (black, out of order, or unreadable).
    """

    t_ns: int
    sensor: str
    detections: tuple[Detection, ...]
    valid: bool = True


class CameraVehicleDetector:
    """Vehicles in one static camera, in the road frame (D3; see the module docstring). Call once per frame.

    Parameters
    ----------
    camera_name : str
        ``Detection.sensor`` of the output.
    H_img2road : (3, 3) float
        Ideal (undistorted) pixels to road metres.
    roads : (n, 5) float
        ``(x0, y0, x1, y1, width)`` per road, road frame.
    params : VehicleDetectorParams, optional
    K, dist : optional
        Lens model: with non-zero ``dist``, pixels are undistorted (needs ``K``) before ``H_img2road``.

    Attributes
    ----------
    last_foreground : ForegroundResult or None
        The foreground of the last frame's processed window (:meth:`window`, shrunk by ``processing_scale``).
    last_mask : (H, W) bool or None
        The vehicle pixels of the last frame (object pixels, with highlights when they count).
    n_frames, n_skipped : int
        Frames processed and frames skipped (black, out of order).

    Examples
    --------
    >>> det = CameraVehicleDetector("camera_0", H, roads)       # doctest: +SKIP
    >>> for image in images:                                    # doctest: +SKIP
    ...     detections = det(image)
    """

    def __init__(self, camera_name: str, H_img2road: Any, roads: Any, params: VehicleDetectorParams | None = None,
                 *, K: Any = None, dist: Any = None) -> None:
        p = VehicleDetectorParams() if params is None else params
        if not isinstance(p, VehicleDetectorParams):
            raise ConfigError(f"params: expected VehicleDetectorParams or None, got {type(p).__name__}")
        if not isinstance(camera_name, str) or not camera_name:
            raise ConfigError(f"camera_name: expected a non-empty string, got {camera_name!r}")
        self.params = p
        self.camera_name = camera_name
        self.H_img2road = orient_homography(H_img2road)
        self.H_road2img = np.linalg.inv(self.H_img2road)
        self.roads = _roads(roads)
        self._lens = _Lens(K, dist)
        self._K = None if K is None else np.asarray(K, dtype=np.float64)
        self._P: np.ndarray | None = None
        self._P_for: tuple[int, int] | None = None
        self._fg = ForegroundModel(p.foreground)
        self._fg_small: ForegroundModel | None = None  # the whole frame, shrunk: the illumination test's outside
        self._small_size: tuple[int, int] = (0, 0)  # the frame size it samples
        self._small_outside = np.zeros((0, 0), bool)
        sc = p.processing_scale
        self._min_area_small = max(1, -(-p.min_area_px // sc**2))
        self._blob_params = replace(p.blobs, min_area_px=self._min_area_small,
                                    open_px=-(-p.blobs.open_px // sc) if p.blobs.open_px > 1 else p.blobs.open_px,
                                    close_px=-(-p.blobs.close_px // sc) if p.blobs.close_px > 1 else p.blobs.close_px)
        self._roi: np.ndarray | None = None
        self._window: tuple[int, int, int, int] | None = None
        self._size: tuple[int, int] | None = None
        self._road: np.ndarray | None = None
        self._road_sample = np.zeros(0, np.int64)
        self._road_gain = 1.0
        self._gain_frame = -1  # the frame it was measured in
        self._tracks: list[_Track] = []
        self._next_id = 1
        self._t_ns: int | None = None
        self.last_foreground: ForegroundResult | None = None
        self._last_labels: np.ndarray | None = None  # the last frame's blob labels (whole frame), or a mask
        self.n_frames = 0
        self.n_skipped = 0

    @property
    def last_mask(self) -> np.ndarray | None:
        """The vehicle pixels ``(H, W)`` bool of the last frame (made on demand from its blob labels)."""
        return None if self._last_labels is None else self._last_labels > 0

    @property
    def n_illumination_events(self) -> int:
        """Illumination changes the foreground model has relearned after (A1's 10α relearning started)."""
        return self._fg.n_illumination_events

    # -- geometry -------------------------------------------------------------------------------------

    def to_road(self, uv: Any) -> np.ndarray:
        """Measured pixels ``(n, 2)`` (continuous, pixel centres at integers) to road points ``(n, 2)`` m.

        NaN for pixels at or above the horizon.
        """
        return self._to_road(np.asarray(uv, dtype=np.float64).reshape(-1, 2))[0]

    def to_image(self, xy: Any) -> np.ndarray:
        """Road points ``(n, 2)`` m to measured pixels ``(n, 2)``; NaN behind the camera."""
        pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        uv, w = _apply_h(self.H_road2img, pts)
        uv[~(w > 0)] = np.nan  # H_road2img has w = depth x (positive scale), positive in front of the camera
        return self._lens.distort(uv)

    def _to_road(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xy, w = _apply_h(self.H_img2road, self._lens.undistort(uv))
        xy[~(w > 0)] = np.nan
        return xy, w

    def _jacobian(self, uv: np.ndarray) -> np.ndarray:
        """``∂(x, y)/∂(u, v)`` at pixels ``(n, 2)``: ``(n, 2, 2)`` m/px (central differences of ±1 px)."""
        n = len(uv)
        steps = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
        xy, _ = self._to_road((uv[None] + steps[:, None]).reshape(-1, 2))
        xy = xy.reshape(4, n, 2)
        return np.stack([(xy[0] - xy[1]) / 2, (xy[2] - xy[3]) / 2], axis=2)

    def projection_matrix(self, width: int, height: int) -> np.ndarray | None:
        """``P`` ``(3, 4)`` (ideal pixels) from the homography and ``K``; without ``K``, ``K`` is estimated from the
        homography for an image of ``width × height`` (square pixels, principal point at the centre)."""
        if self._P_for != (width, height):
            K = self._K if self._K is not None else _intrinsics_from_homography(self.H_road2img, width, height)
            self._P = None if K is None or K.shape != (3, 3) else _projection_matrix(self.H_road2img, K)
            self._P_for = (width, height)
        return self._P

    def _model_boxes(self, P: np.ndarray, centre: np.ndarray, heading: np.ndarray, size: np.ndarray) -> np.ndarray:
        """Image boxes ``(n, 4)`` (continuous pixels) of cuboids ``size (n, 3)`` standing on their footprints."""
        uv = self._model_corners(P, centre, heading, size)
        return np.concatenate([uv.min(axis=1), uv.max(axis=1)], axis=1)

    def _model_corners(self, P: np.ndarray, centre: np.ndarray, heading: np.ndarray, size: np.ndarray
                       ) -> np.ndarray:
        """Image corners ``(n, 8, 2)`` (continuous pixels; NaN behind the camera) of cuboids ``size (n, 3)``
        (length, width, height) standing on footprints centred at ``centre (n, 2)`` with ``heading (n,)``."""
        n = len(centre)
        c, s_ = np.cos(heading), np.sin(heading)
        sign = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]], np.float64)
        dx = sign[None, :, 0] * size[:, None, 0] / 2
        dy = sign[None, :, 1] * size[:, None, 1] / 2
        foot = centre[:, None, :] + np.stack([dx * c[:, None] - dy * s_[:, None], dx * s_[:, None] + dy * c[:, None]],
                                             axis=2)  # (n, 4, 2)
        pts = np.concatenate([np.concatenate([foot, np.zeros((n, 4, 1))], axis=2),
                              np.concatenate([foot, np.broadcast_to(size[:, None, 2:3], (n, 4, 1))], axis=2)],
                             axis=1).reshape(-1, 3)
        h = pts @ P[:, :3].T + P[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.where(h[:, 2:] > 0, h[:, :2] / h[:, 2:], np.nan)
        return self._lens.distort(uv).reshape(n, 8, 2)

    def roi_mask(self, width: int, height: int) -> np.ndarray:
        """The road ROI ``(height, width)`` bool of this camera (cached for the image size)."""
        if self._roi is None or self._roi.shape != (height, width):
            self._roi = _roi(self.H_img2road, self.roads, int(width), int(height), self.params.road_margin_m,
                             self._lens)
            self._roi.setflags(write=False)
        return self._roi

    def window(self, width: int, height: int) -> tuple[int, int, int, int]:
        """The image rectangle ``(u0, v0, u1, v1)`` (pixel edges) that is processed (cached for the image size).

        With ``crop_to_road``: the bounding rectangle, clipped to the image, of the ROI and of the image of every
        road point within ``road_margin_m + window_margin_m`` of a road rectangle, on the road and lifted by
        ``window_height_m`` (a vehicle whose contact point is in the ROI lies inside), plus 4 px for the
        morphology; the whole image otherwise, or when the camera matrix is unknown.
        """
        if self._window is not None and self._size == (width, height):
            return self._window
        p = self.params
        full = (0, 0, int(width), int(height))
        P = self.projection_matrix(width, height) if p.crop_to_road else None
        roi = self.roi_mask(width, height)
        if P is None or not roi.any():
            win = full
        else:
            rows, cols = np.flatnonzero(roi.any(axis=1)), np.flatnonzero(roi.any(axis=0))
            lo, hi = np.array([cols[0], rows[0]], np.float64), np.array([cols[-1], rows[-1]], np.float64) + 1
            size = np.array([width, height], np.float64)
            s = np.linspace(0.0, 1.0, 121)
            border = np.concatenate([np.column_stack([s * width - 0.5, np.full_like(s, e * height - 0.5)])
                                     for e in (0, 1)] + [np.column_stack([np.full_like(s, e * width - 0.5),
                                                                          s * height - 0.5]) for e in (0, 1)])
            ideal = self._lens.undistort(border)  # the ideal-pixel extent the image shows
            ilo, ihi = np.nanmin(ideal, axis=0), np.nanmax(ideal, axis=0)
            grid = s[:, None, None] * np.array([1.0, 0.0]) + s[None, :, None] * np.array([0.0, 1.0])  # (s, s, 2)
            for q in road_polygons(self.roads, p.road_margin_m + p.window_margin_m):  # a handful of roads
                g = (q[0] + grid[..., :1] * (q[1] - q[0]) + grid[..., 1:] * (q[3] - q[0])).reshape(-1, 2)
                for z in (0.0, p.window_height_m):
                    h = g @ P[:, :2].T + z * P[:, 2] + P[:, 3]
                    with np.errstate(divide="ignore", invalid="ignore"):
                        uv = h[h[:, 2] > 1e-9, :2] / h[h[:, 2] > 1e-9, 2:]  # ideal pixels, in front
                    if not uv.size:
                        continue
                    # beyond what the image shows: the window reaches the image's edge on that side (the lens
                    # model does not hold far outside the image, so those points are clipped before it)
                    lo = np.where(np.any(uv < ilo, axis=0), 0.0, lo)
                    hi = np.where(np.any(uv > ihi, axis=0), size, hi)
                    uv = self._lens.distort(np.clip(uv, ilo, ihi))
                    lo = np.minimum(lo, uv.min(axis=0) + 0.5)
                    hi = np.maximum(hi, uv.max(axis=0) + 0.5)
            lo = np.clip(np.floor(lo) - 4, 0, [width, height]).astype(int)
            hi = np.clip(np.ceil(hi) + 4, 0, [width, height]).astype(int)
            win = (int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1])) if np.all(hi - lo >= 8) else full
        sc = p.processing_scale
        u0, v0, u1, v1 = win
        u0, v0 = max(0, u1 - -(-(u1 - u0) // sc) * sc), max(0, v1 - -(-(v1 - v0) // sc) * sc)
        u1, v1 = u0 + (u1 - u0) // sc * sc, v0 + (v1 - v0) // sc * sc  # a multiple of the scale
        self._window, self._size = (u0, v0, u1, v1), (int(width), int(height))
        return self._window

    # -- per frame ------------------------------------------------------------------------------------

    def __call__(self, image: Image | np.ndarray, t_ns: int | None = None) -> list[Detection]:
        """Detect and track the vehicles of one frame.

        Parameters
        ----------
        image : Image or (H, W, 3) uint8 BGR
            Frames in time order, all of one size.
        t_ns : int, optional
            The frame's time; required for a bare array (an :class:`Image` carries its own).

        Returns
        -------
        list of Detection
            Empty for a black (dropout) frame or a frame not after the previous one (logged, skipped).

        Raises
        ------
        ValueError
            Not an image, no time for a bare array, or a frame whose size differs from the first.
        """
        if isinstance(image, Image):
            if image.encoding == "mono16":
                raise ValueError(f"image: expected a colour or mono8 image, got encoding 'mono16' ({image.sensor})")
            t = image.t_ns if t_ns is None else int(t_ns)
            bgr = image.bgr() if image.encoding != "mono8" else cv2.cvtColor(image.pixels, cv2.COLOR_GRAY2BGR)
        else:
            if t_ns is None:
                raise ValueError("t_ns: required when the image is a bare array")
            t = int(t_ns)
            bgr = np.asarray(image)
            if bgr.ndim == 2 and bgr.dtype == np.uint8:
                bgr = cv2.cvtColor(bgr, cv2.COLOR_GRAY2BGR)
        if self._t_ns is not None and t <= self._t_ns:
            log.warning("%s: frame at %d ns is not after the previous one (%d ns); skipped", self.camera_name, t,
                        self._t_ns)
            self.n_skipped += 1
            return []
        if not (isinstance(bgr, np.ndarray) and bgr.ndim == 3 and bgr.shape[2] == 3 and bgr.shape[0] > 0
                and bgr.shape[1] > 0):
            raise ValueError(f"image: expected an (H, W, 3) BGR or (H, W) grey frame, got shape "
                             f"{getattr(bgr, 'shape', None)} ({self.camera_name})")
        h, w = bgr.shape[:2]
        if self._fg.shape is not None and self._size is not None and (w, h) != self._size:
            raise ValueError(f"image: size {w}x{h} differs from the first frame's {self._size[0]}x{self._size[1]} "
                             f"({self.camera_name})")
        u0, v0, u1, v1 = self.window(w, h)
        sc = self.params.processing_scale
        sub = bgr[v0:v1, u0:u1]
        if sc > 1 and sub.dtype == np.uint8:
            sub = cv2.resize(sub, ((u1 - u0) // sc, (v1 - v0) // sc), interpolation=cv2.INTER_AREA)
        self._illumination_test(bgr, (u0, v0, u1, v1))
        fg = self._fg.apply(sub)
        self.last_foreground = fg
        if not fg.valid:  # a black frame: the model is untouched; tracks coast by time at the next frame
            self.n_skipped += 1
            self._last_labels = np.zeros((h, w), bool)
            return []
        bgr = np.ascontiguousarray(bgr)
        dt = self.params.frame_dt_s if self._t_ns is None else (t - self._t_ns) * 1e-9
        self._t_ns = t
        self.n_frames += 1
        blobs = self._vehicle_blobs(self._road_memory_veto(sub, fg))
        self._update_road_memory(sub, blobs.label_image > 0, self.roi_mask(w, h)[v0:v1:sc, u0:u1:sc])
        blobs = _in_frame(blobs, (u0, v0), (h, w), sc)
        self._last_labels = blobs.label_image
        return self._detect(t, dt, bgr, blobs)

    def _illumination_test(self, bgr: np.ndarray, window: tuple[int, int, int, int]) -> None:
        """A1's illumination test on the whole frame while only the window is modelled [RECON].

        A1 relearns at 10α when more than ``illumination_fraction`` (60 %) of the *frame* is MoG foreground. The
        window is about half the frame, so a large near vehicle or a queue in it would pass that share of the
        window alone (and the relearning absorbs stopped vehicles). A plain MoG (A1, same parameters, no A2/A3,
        its own illumination relearning) on every k-th pixel of every k-th row (k = 8 at 640 × 480: 80 samples
        across; MoG decides each pixel on its own, so these are a whole-frame model's decisions there, and no
        resampling is paid for) gives the foreground fraction ``f_o`` of the ``O`` pixels outside the window of
        ``W`` pixels; the window's model is given the threshold ``(0.6 (W + O) − f_o O) / W`` (clipped to (0, 1]) on
        its own fraction, which is A1's test on the frame's fraction ``(f_w W + f_o O) / (W + O)``. With no outside
        (the whole image processed) the model keeps its own test.
        """
        base = self.params.foreground
        h, w = bgr.shape[:2]
        u0, v0, u1, v1 = window
        n_win = (u1 - u0) * (v1 - v0)
        n_out = w * h - n_win
        if n_out <= 0 or n_win <= 0 or base.illumination_frames == 0:
            return
        step = max(1, round(max(w, h) / 80))
        if self._fg_small is None or self._small_size != (w, h):
            self._fg_small = ForegroundModel(replace(base, stopped=None, shadows=None))
            self._small_size = (w, h)
            uc, vc = np.arange(step // 2, w, step), np.arange(step // 2, h, step)  # the sampled pixels
            self._small_outside = ~(((vc >= v0) & (vc < v1))[:, None] & ((uc >= u0) & (uc < u1))[None, :])
        small = self._fg_small.apply(np.ascontiguousarray(bgr[step // 2::step, step // 2::step]))
        outside = self._small_outside
        f_out = (np.count_nonzero(small.mog_mask & outside) / max(1, np.count_nonzero(outside))) if small.valid \
            else 0.0
        thr = (base.illumination_fraction * (n_win + n_out) - f_out * n_out) / n_win
        thr = float(np.clip(round(thr, 4), 1e-6, 1.0))
        if thr != self._fg.params.illumination_fraction:
            self._fg.params = replace(base, illumination_fraction=thr)

    def _background_image(self) -> np.ndarray:
        """MOG2's background image as the foreground model's A3 last took it (``foreground.background_every``:
        at most 4 frames old; it changes at the rate α = 0.002 per frame), fresh in every frame while relearning."""
        return self._fg.recent_background_image()

    def _road_memory_veto(self, bgr: np.ndarray, fg: ForegroundResult) -> np.ndarray:
        """A3's labels with the foreground pixels that show the remembered empty road, where the background models
        have forgotten it, set to background [RECON].

        In a jam crawling at walking pace MOG2 learns the vehicles, and A2's remembered background follows MOG2
        (A2 step 5): when the queue dissolves, the road that reappears is foreground to MOG2 and a "new stable
        colour", a stopped object for good, to A2 (a trail of false vehicle pixels along the lane). The road
        memory ``R`` is learned only where no vehicle was seen, at ``road_memory_rate``, in the light of its first
        frame; the frame's gain ``γ`` against it is the median brightness distortion (A3's ``a``) of a sample of
        the road pixels seen as background (measured every 4th frame, when the memory learns, and in every frame
        while MoG relearns after an illumination change: the light changes slowly otherwise). A pixel is the road
        when its ``|a/γ − 1|`` and chromaticity distortion against ``R`` are both within ``road_memory_tolerance``;
        it is vetoed when only A2 holds it, or when MOG2's background there no longer is the road (a grey car far
        away can look like the road to this test, but MOG2 then still has the road and it stays). A vehicle stopped
        on the road is not learned (it is in the vehicle mask) and does not look like the road, so it stays.
        """
        p = self.params
        labels = fg.labels
        if self._road is None or p.road_memory_tolerance <= 0:
            return labels
        flat = labels.reshape(-1)
        x = bgr.reshape(-1, 3)
        road = self._road.reshape(-1, 3)
        if self._gain_frame < 0 or fg.relearning or self.n_frames - self._gain_frame >= 4:
            sample = self._road_sample[flat[self._road_sample] == PixelLabel.BACKGROUND]
            if sample.size < 100:
                return labels
            a, _ = brightness_chromaticity(np.take(x, sample, axis=0), np.take(road, sample, axis=0))
            self._road_gain, self._gain_frame = float(np.median(a)), self.n_frames
        gain = self._road_gain
        idx = np.flatnonzero(flat != PixelLabel.BACKGROUND)
        if idx.size == 0 or not gain > 0:
            return labels
        g, tol = np.float32(gain), np.float32(p.road_memory_tolerance)
        road_i = np.take(road, idx, axis=0)
        a, cd = brightness_chromaticity(np.take(x, idx, axis=0), road_i)
        road_px = (np.abs(a / g - 1) <= tol) & (cd <= tol)
        if not road_px.any():
            return labels
        idx = idx[road_px]
        a2_only = fg.augmented_mask.reshape(-1)[idx] & ~fg.mog_mask.reshape(-1)[idx]
        a_bg, cd_bg = brightness_chromaticity(np.take(self._background_image().reshape(-1, 3), idx, axis=0),
                                              road_i[road_px])
        forgotten = (np.abs(a_bg / g - 1) > 2 * tol) | (cd_bg > 2 * tol)
        out = labels.copy()
        out.reshape(-1)[idx[a2_only | forgotten]] = PixelLabel.BACKGROUND
        return out

    def _update_road_memory(self, bgr: np.ndarray, vehicles: np.ndarray, roi: np.ndarray) -> None:
        """Learn the empty road where no vehicle (dilated by 5 px) is seen and the frame already looks like the
        memory (within twice the tolerance, after the gain): a queue crawling through for a minute, which MOG2
        learns, does not change it. Starts from MOG2's background once the model has seen
        ``road_memory_warmup`` frames; updated every 4th frame at 4 times the rate."""
        p = self.params
        if p.road_memory_tolerance <= 0:
            return
        if self._road is None:
            if self._fg.n_frames >= p.road_memory_warmup:
                self._road = self._fg.background_image().astype(np.float32)
                roi = roi.reshape(-1)
                self._road_sample = np.flatnonzero(roi)[:: max(1, int(roi.sum()) // 4000)]
            return
        if self.n_frames % 4:
            return
        norm = bgr.astype(np.float32) / np.float32(max(self._road_gain, 1e-3))
        a, cd = brightness_chromaticity(norm, self._road)
        tol = np.float32(2 * p.road_memory_tolerance)
        k = 2 * -(-5 // p.processing_scale) + 1
        free = (cv2.dilate(vehicles.view(np.uint8), np.ones((k, k), np.uint8)) == 0) & (np.abs(a - 1) <= tol) & \
            (cd <= tol)
        cv2.accumulateWeighted(norm, self._road, min(1.0, 4 * p.road_memory_rate), mask=free.view(np.uint8))

    def _vehicle_blobs(self, labels: np.ndarray) -> Blobs:
        """A4's blobs of the vehicle pixels, fragments joined through the shadow pixels between them.

        Vehicle pixels are A3's object pixels (and highlights when they count). A3 also calls shadow the side of
        a grey car in the shade (darker than the road behind it, same chromaticity), which cuts the car in
        pieces; so the components are taken over vehicle and shadow pixels together, and each blob is then the
        component's vehicle pixels only (its box, area and histogram leave the cast shadow out). When shadow
        covers more than ``shadow_bridge_max_fraction`` of the frame (a cloud's shadow, an illumination change
        not yet absorbed) the shadow pixels join nothing.
        """
        p = self.params
        veh = labels == PixelLabel.FOREGROUND
        if p.highlights_are_vehicles:
            veh |= labels == PixelLabel.HIGHLIGHT
        shadow = labels == PixelLabel.SHADOW
        bridge = p.shadow_bridge and np.count_nonzero(shadow) <= p.shadow_bridge_max_fraction * shadow.size
        m = clean_mask(veh | shadow if bridge else veh, self._blob_params)
        # A4's components without OpenCV's statistics (which cost ten times the labelling here): the blobs' areas,
        # boxes and centroids come from their pixels below, only the (few) non-zero ones visited.
        _n, L = cv2.connectedComponentsWithAlgorithm(m, self._blob_params.connectivity, cv2.CV_32S, cv2.CCL_GRANA)
        if bridge:  # each component keeps its vehicle pixels only (the cast shadow is left out)
            L[shadow] = 0
        # A blob needs min_area_px vehicle pixels, so its component (vehicle and shadow) had as many.
        return _blobs_of_labels(L, self._min_area_small)

    def _ground_frames(self, box: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For boxes ``(n, 4)`` (continuous pixels): the road point ``g`` of each bottom-centre, the Jacobian ``J``
        there, and the unit directions ``t`` of the bottom row's ground line and ``n`` normal to it, away from
        the camera (module docstring)."""
        bc = np.column_stack([(box[:, 0] + box[:, 2]) / 2, box[:, 3]])
        g, _ = self._to_road(bc)
        J = self._jacobian(bc)
        with np.errstate(invalid="ignore", divide="ignore"):
            tdir = J[:, :, 0] / np.linalg.norm(J[:, :, 0], axis=1, keepdims=True)
        ndir = np.column_stack([-tdir[:, 1], tdir[:, 0]])
        away = -J[:, :, 1]  # one pixel up the image = farther along the road plane
        ndir *= np.where(np.einsum("ij,ij->i", ndir, away) < 0, -1.0, 1.0)[:, None]
        return g, J, tdir, ndir

    def _join_fragments(self, blobs: Blobs, roi: np.ndarray) -> Blobs:
        """Join the pieces of one vehicle (A3 and MoG can leave a band of its body as background) [RECON].

        From the lowest blob up, each blob whose bottom-centre is on the road is taken for the nearest end of a
        vehicle as large as a car (the lowest piece may be a narrow band of the body, e.g. its dark sill): the
        image of that vehicle's cuboid (size prior, standing on the footprint found as in the module
        docstring, along the road) is its expected silhouette, and any higher blob with at least
        ``fragment_containment`` of its pixels inside the silhouette's convex hull is one of its pieces. Needs
        the camera matrix (given ``K``, or estimated from the homography).
        """
        p = self.params
        h, w = roi.shape
        P = self.projection_matrix(w, h) if p.fragment_containment < 1 and len(blobs) >= 2 else None
        if P is None:
            return blobs
        box = blobs.boxes_px - 0.5
        g, J, tdir, ndir = self._ground_frames(box)
        contact = np.clip(np.floor(np.column_stack([(box[:, 0] + box[:, 2]) / 2, box[:, 3]]) + 0.5).astype(int), 0,
                          [w - 1, h - 1])
        ok = (np.all(np.isfinite(g), axis=1) & np.all(np.isfinite(tdir), axis=1) & roi[contact[:, 1], contact[:, 0]])
        owners = np.flatnonzero(ok)
        if owners.size == 0:
            return blobs
        size = np.broadcast_to(np.asarray(p.car_size_m, np.float64), (owners.size, 3))
        axis = _nearest_road_axis(g[owners], self.roads)
        heading = np.arctan2(axis[:, 1], axis[:, 0])
        zeros = np.zeros(owners.size, bool)
        centre, _ = self._footprint(g[owners], J[owners], tdir[owners], ndir[owners], heading, size, zeros, zeros)
        corners = self._model_corners(P, centre, heading, size)
        L = blobs.label_image
        absorbed = np.full(len(blobs), -1)
        for o in np.argsort(-box[owners, 3], kind="stable"):  # lowest (nearest) first
            i = owners[o]
            if absorbed[i] >= 0 or not np.all(np.isfinite(corners[o])):
                continue
            hull = cv2.convexHull(corners[o].astype(np.float32)).reshape(-1, 2)
            lo, hi = hull.min(axis=0), hull.max(axis=0)
            cand = np.flatnonzero((absorbed < 0) & (box[:, 3] <= box[i, 3] + 1.0) & (box[:, 0] < hi[0])
                                  & (box[:, 2] > lo[0]) & (box[:, 1] < hi[1]) & (box[:, 3] > lo[1]))
            for j in cand[cand != i]:  # a few blobs near one vehicle
                u0, v0, u1, v1 = (int(c) for c in blobs.boxes_px[j])
                pix = L[v0:v1, u0:u1] == blobs.component_ids[j]
                inside = np.zeros(pix.shape, np.uint8)
                cv2.fillConvexPoly(inside, np.round((hull - (u0, v0)) * 16).astype(np.int32), 1, cv2.LINE_8, 4)
                if np.count_nonzero(pix & (inside > 0)) >= p.fragment_containment * np.count_nonzero(pix):
                    absorbed[j] = i
        if not np.any(absorbed >= 0):
            return blobs
        keep = np.flatnonzero(absorbed < 0)
        lut = np.arange(int(L.max()) + 1, dtype=np.int32)
        lut[blobs.component_ids[absorbed >= 0]] = blobs.component_ids[absorbed[absorbed >= 0]]
        boxes = blobs.boxes_px.copy()
        areas = blobs.areas_px.copy()
        csum = blobs.centroids_px * areas[:, None]
        for j in np.flatnonzero(absorbed >= 0):
            i = absorbed[j]
            boxes[i, :2] = np.minimum(boxes[i, :2], boxes[j, :2])
            boxes[i, 2:] = np.maximum(boxes[i, 2:], boxes[j, 2:])
            areas[i] += areas[j]
            csum[i] += csum[j]
        return Blobs(boxes[keep], csum[keep] / areas[keep, None], areas[keep], blobs.component_ids[keep], lut[L])

    def _detect(self, t_ns: int, dt: float, bgr: np.ndarray, blobs: Blobs) -> list[Detection]:
        p = self.params
        h, w = blobs.label_image.shape
        roi = self.roi_mask(w, h)
        if len(blobs) == 0:
            self._track(dt, np.zeros((0, 4)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2, 2)), None)
            return []
        blobs = self._join_fragments(blobs, roi)
        self._last_labels = blobs.label_image
        edges = blobs.boxes_px
        box = edges - 0.5  # continuous pixel coordinates (module docstring)
        bc = np.column_stack([(box[:, 0] + box[:, 2]) / 2, box[:, 3]])
        g, _ = self._to_road(bc)
        J = self._jacobian(bc)
        det_j = np.abs(np.linalg.det(J))
        contact = np.clip(np.floor(bc + 0.5).astype(int), 0, [w - 1, h - 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            min_area = np.maximum(p.min_area_px, p.min_footprint_m2 / det_j)
            keep = (np.all(np.isfinite(g), axis=1) & np.isfinite(min_area) & (blobs.areas_px >= min_area)
                    & roi[contact[:, 1], contact[:, 0]])
        k = np.flatnonzero(keep)
        if k.size == 0:
            self._track(dt, np.zeros((0, 4)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2, 2)), None)
            return []
        parts = self._parts(blobs, k)
        if not len(parts.edges):
            self._track(dt, np.zeros((0, 4)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2, 2)), None)
            return []
        edges = parts.edges
        box = edges - 0.5
        g, J, tdir, ndir = self._ground_frames(box)
        ok = np.all(np.isfinite(g), axis=1) & np.all(np.isfinite(J), axis=(1, 2)) & np.all(np.isfinite(tdir), axis=1)
        if not ok.all():
            parts = parts.subset(ok)
            edges, box, g, J, tdir, ndir = edges[ok], box[ok], g[ok], J[ok], tdir[ok], ndir[ok]
        n = len(edges)
        hists = box_histograms(bgr, edges, masks=parts.masks)
        axis, length_app, width_app = parts.axis, parts.length_m, parts.width_m
        bicycle = (width_app < p.bicycle_max_width_m) & (parts.queue == 0)
        prior = np.where(bicycle[:, None], np.asarray(p.bicycle_size_m), np.asarray(p.car_size_m))
        size = np.column_stack([np.maximum(prior[:, 0], np.nan_to_num(length_app, nan=0.0)), prior[:, 1:]])

        truncated = (box[:, 0] <= -0.5 + 1e-9) | (box[:, 2] >= w - 0.5 - 1e-9) | (box[:, 3] >= h - 0.5 - 1e-9)
        bottom_cut = box[:, 3] >= h - 0.5 - 1e-9
        # heading: the road's axis, or the track's course for moving tracks (after association)
        heading = np.arctan2(axis[:, 1], axis[:, 0])
        centre, cov = self._footprint(g, J, tdir, ndir, heading, size, truncated, bottom_cut)
        queued = np.flatnonzero(parts.queue > 0)
        P = self.projection_matrix(w, h) if queued.size else None
        if P is not None:  # a vehicle in a queue is partly hidden: its box is that of a car standing there
            model = self._model_boxes(P, centre[queued], heading[queued], size[queued]) + 0.5
            parent = parts.parent_edges[queued]
            clipped = np.column_stack([np.maximum(model[:, :2], parent[:, :2]),
                                       np.minimum(model[:, 2:], parent[:, 2:])])
            good = np.all(np.isfinite(clipped), axis=1) & np.all(clipped[:, 2:] - clipped[:, :2] >= 2, axis=1)
            edges[queued[good]] = np.round(clipped[good])
            box = edges - 0.5

        assigned = self._track(dt, box, g, centre, cov, hists)
        speed = np.linalg.norm(np.nan_to_num(assigned.velocities), axis=1)
        moving = assigned.confirmed & (speed >= max(p.heading_min_speed_mps, 1e-9))
        if moving.any():  # refine the footprint centre with the track's course
            v = assigned.velocities[moving]
            heading[moving] = np.arctan2(v[:, 1], v[:, 0])
            centre[moving], cov[moving] = self._footprint(g[moving], J[moving], tdir[moving], ndir[moving],
                                                          heading[moving], size[moving], truncated[moving],
                                                          bottom_cut[moving])
        # the road axis has no direction: point it along the track's motion when there is one
        v = np.nan_to_num(assigned.velocities)
        flip = ~moving & (np.einsum("ij,ij->i", v, axis) < 0)
        heading[flip] = np.arctan2(-axis[flip, 1], -axis[flip, 0])

        # the detections own fresh float64 arrays (Detection.trusted takes them as they are, without copies)
        box_f = np.column_stack([centre, length_app, width_app, heading]).astype(np.float64)
        centre, cov, edges = (np.array(a, np.float64) for a in (centre, cov, edges))
        hists, g = np.array(hists, np.float64), np.array(g, np.float64)
        vel = np.array(assigned.velocities, np.float64)
        has_vel = np.all(np.isfinite(vel), axis=1)
        ids, queue = assigned.track_ids.astype(np.int64).reshape(-1, 1), parts.queue.astype(np.int64).reshape(-1, 1)
        trunc = truncated.reshape(-1, 1).copy()
        out = []
        for i in range(n):
            feats: dict[str, np.ndarray] = {
                "box": box_f[i],
                "hist_hsv": hists[i],
                "track_id": ids[i],
                "ground_point_m": g[i],
                "truncated": trunc[i],
                "queue": queue[i],
            }
            if has_vel[i]:
                feats["velocity_mps"] = vel[i]
            out.append(Detection.trusted(t_ns, self.camera_name, centre[i], cov[i], edges[i],
                                         1.0 if assigned.confirmed[i] else 0.5, "bicycle" if bicycle[i] else "car",
                                         features=feats))
        return out

    def _parts(self, blobs: Blobs, k: np.ndarray) -> _Parts:
        """The vehicles of the kept blobs ``k``: each blob, or its parts when it is a queue.

        A blob's lower outline (the lowest pixel of each column, its bottom edge ``v + 0.5``) is mapped to the road
        and measured along and across the nearest road's axis (5th-95th percentiles: a column at the side of a
        tall box may bottom out above the road): its apparent ground length and width. A blob longer than
        ``queue_min_cars`` car lengths and not bicycle-narrow is a queue of vehicles overlapping in the image (a
        jam seen along the road) [RECON]. Its outline, column by column, runs along each vehicle's visible
        bottom edges and jumps where the next vehicle's begins: it is cut where the ground coordinate along the
        axis jumps by ``queue_jump_m`` or more (and by three times the outline's median step, the pixel size
        on the road there), stretches of fewer than three columns are joined to their neighbour, and a stretch
        still longer than ``queue_min_cars`` car lengths is cut into ``round((length + queue_gap_m) /
        (0.9 L_car + queue_gap_m))`` equal ones. Each stretch's columns form a part: its box (from the blob's
        top to the outline over those columns; replaced after positioning by the image of a car standing there
        when the camera matrix is known) and its outline.
        """
        p = self.params
        L = blobs.label_image
        us, lows, tops, owner = [], [], [], []
        for j in k:  # a loop over blobs; their columns are vectorised
            u0, v0, u1, v1 = (int(c) for c in blobs.boxes_px[j])
            roi = L[v0:v1, u0:u1] == blobs.component_ids[j]
            cols = np.flatnonzero(roi.any(axis=0))
            us.append(u0 + cols)
            lows.append(v1 - 1 - np.argmax(roi[::-1, cols], axis=0))
            tops.append(v0 + np.argmax(roi[:, cols], axis=0))
            owner.append(np.full(cols.size, j))
        u, low, top, own = (np.concatenate(a) for a in (us, lows, tops, owner))
        xy, _ = self._to_road(np.column_stack([u, low + 0.5]).astype(np.float64))
        finite = np.all(np.isfinite(xy), axis=1)
        bottoms = blobs.boxes_px[k] - 0.5
        g, _ = self._to_road(np.column_stack([(bottoms[:, 0] + bottoms[:, 2]) / 2, bottoms[:, 3]]))
        axes = _nearest_road_axis(np.nan_to_num(g), self.roads)
        car_l = p.car_size_m[0]
        out = _Parts()
        for j, axis in zip(k, axes, strict=True):
            m = np.flatnonzero((own == j) & finite)
            if m.size < 2:
                continue
            across = np.array([-axis[1], axis[0]])
            s, lat = xy[m] @ axis, xy[m] @ across
            (s_lo, lat_lo), (s_hi, lat_hi) = _p5_p95(np.column_stack([s, lat]))
            width = lat_hi - lat_lo
            long_ = s_hi - s_lo >= p.queue_min_cars * car_l
            wide = width >= p.queue_min_cars * p.car_size_m[1]
            if not p.split_queues or not (long_ or wide) or width < p.bicycle_max_width_m:
                out.add(blobs, j, m, None, axis, s_hi - s_lo, width, 0, u, low, top)
                continue
            stretches = self._queue_stretches(s)
            for sel in stretches:
                mi = m[sel]
                si = s[sel]
                a0, a1 = _p5_p95(si)
                out.add(blobs, j, mi, u[mi], axis, a1 - a0, width, len(stretches), u, low, top)
        return out.done()

    def _queue_stretches(self, s: np.ndarray) -> list[np.ndarray]:
        """Index arrays of the vehicles of a queue's outline ``s`` (along the road axis, in column order; see
        :meth:`_parts`)."""
        p = self.params
        car_l = p.car_size_m[0]
        ds = np.abs(np.diff(s))
        step = float(np.median(ds)) if ds.size else 0.0
        cuts = np.flatnonzero(ds >= max(p.queue_jump_m, 3.0 * step)) + 1
        bounds = np.r_[0, cuts, s.size]
        merged: list[np.ndarray] = []
        for a, b in itertools.pairwise(bounds):
            piece = np.arange(a, b)
            if merged and (piece.size < 3 or merged[-1].size < 3):  # a step of the outline, not a vehicle
                merged[-1] = np.r_[merged[-1], piece]
            elif piece.size:
                merged.append(piece)
        pitch = 0.9 * car_l + p.queue_gap_m
        out: list[np.ndarray] = []
        for piece in merged:
            lo, hi = _p5_p95(s[piece])
            q = int(np.round((hi - lo + p.queue_gap_m) / pitch)) if hi - lo >= p.queue_min_cars * car_l else 1
            if q < 2:
                out.append(piece)
                continue
            seg = np.clip(np.floor((s[piece] - lo) / max(hi - lo, 1e-9) * q), 0, q - 1).astype(int)
            out += [piece[seg == i] for i in range(q) if np.count_nonzero(seg == i) >= 3]
        return out

    def _footprint(self, g: np.ndarray, J: np.ndarray, tdir: np.ndarray, ndir: np.ndarray, heading: np.ndarray,
                   size: np.ndarray, truncated: np.ndarray, bottom_cut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Footprint centres ``(n, 2)`` and their covariances ``(n, 2, 2)`` (module docstring)."""
        p = self.params
        if p.correct_footprint:
            phi = heading - np.arctan2(ndir[:, 1], ndir[:, 0])
            support = size[:, 0] / 2 * np.abs(np.cos(phi)) + size[:, 1] / 2 * np.abs(np.sin(phi))
            centre = g + support[:, None] * ndir
        else:
            centre = g.copy()
        s_n, s_t = p.footprint_sigma_m
        cov = p.pixel_sigma_px**2 * J @ np.swapaxes(J, 1, 2)
        cov += s_n**2 * ndir[:, :, None] * ndir[:, None, :] + s_t**2 * tdir[:, :, None] * tdir[:, None, :]
        half = (size[:, 0] / 2) ** 2
        cov[truncated] += half[truncated, None, None] * np.eye(2)
        cov[bottom_cut] += (size[bottom_cut, 0] ** 2)[:, None, None] * ndir[bottom_cut, :, None] * \
            ndir[bottom_cut, None, :]
        return centre, 0.5 * (cov + np.swapaxes(cov, 1, 2))

    # -- tracking -------------------------------------------------------------------------------------

    def _predicted_boxes(self, tracks: list[_Track], dt: float) -> np.ndarray:
        """Each track's last box moved with the image motion of its ground point and scaled by the depth change."""
        box = np.array([t.box for t in tracks]).reshape(-1, 4)
        if not tracks:
            return box
        g0 = np.array([t.ground_bc for t in tracks])
        g1 = g0 + dt * np.array([t.x[2:] for t in tracks])
        bc0 = np.column_stack([(box[:, 0] + box[:, 2]) / 2, box[:, 3]])
        bc1 = self.to_image(g1)
        _, w0 = _apply_h(self.H_img2road, self._lens.undistort(bc0))
        _, w1 = _apply_h(self.H_img2road, self._lens.undistort(bc1))
        with np.errstate(divide="ignore", invalid="ignore"):
            s = w1 / w0  # w ∝ 1/depth: the image size scales with it
        ok = np.all(np.isfinite(bc1), axis=1) & np.isfinite(s) & (s > 0.5) & (s < 2.0)
        s = np.where(ok, s, 1.0)
        bc1 = np.where(ok[:, None], bc1, bc0)
        return np.column_stack([bc1[:, 0] - s * (bc0[:, 0] - box[:, 0]), bc1[:, 1] - s * (box[:, 3] - box[:, 1]),
                                bc1[:, 0] + s * (box[:, 2] - bc0[:, 0]), bc1[:, 1]])

    def _track(self, dt: float, box: np.ndarray, ground_bc: np.ndarray, z: np.ndarray, R: np.ndarray,
               hists: np.ndarray | None) -> _Assigned:
        """One tracker step with this frame's detections; their track ids, velocities and confirmation."""
        p = self.params
        n = len(z)
        tracks = self._tracks
        pred_box = self._predicted_boxes(tracks, dt)
        if tracks:
            F, Q = kalman.cv_matrices(dt, p.q_m2_s3)
            x, P = kalman.predict(np.array([t.x for t in tracks]), np.array([t.P for t in tracks]), F, Q)
            for t, xi, Pi in zip(tracks, x, P, strict=True):
                t.x, t.P = xi, Pi
        ids = np.zeros(n, np.int64)
        vel = np.full((n, 2), np.nan)
        conf = np.zeros(n, bool)
        matched = np.zeros(len(tracks), bool)
        if tracks and n:
            x = np.array([t.x for t in tracks])
            P = np.array([t.P for t in tracks])
            y = z[None, :, :] - x[:, None, :2]
            S = P[:, None, :2, :2] + R[None]
            d2 = np.einsum("tdi,tdij,tdj->td", y, np.linalg.inv(S), y)
            iou = box_iou(pred_box, box)
            cost = np.where(iou >= p.iou_min, 1.0 - iou, 1.0 + d2 / p.gate_chi2)
            cost[~(d2 <= p.gate_chi2)] = np.inf
            if hists is not None and p.colour_weight > 0:
                have = [i for i, t in enumerate(tracks) if t.hist is not None]
                if have:
                    th = np.array([tracks[i].hist for i in have])
                    cost[have] += p.colour_weight * (1.0 - np.sqrt(th) @ np.sqrt(hists).T)
            pairs, _, _ = hungarian(cost)
            if len(pairs):
                ti, dj = pairs[:, 0], pairs[:, 1]
                xu, Pu = kalman.update(x[ti], P[ti], z[dj], R=R[dj])
                for a, j, xi, Pi in zip(ti, dj, xu, Pu, strict=True):
                    t = tracks[a]
                    t.x, t.P, t.box, t.ground_bc = xi, Pi, box[j], ground_bc[j]
                    if hists is not None:
                        t.hist = hists[j] if t.hist is None else 0.9 * t.hist + 0.1 * hists[j]
                    t.hits += 1
                    t.coast_s = 0.0
                    t.confirmed = t.confirmed or t.hits >= p.n_confirm
                    matched[a] = True
                    ids[j] = t.track_id
                    vel[j] = t.x[2:]
                    conf[j] = t.confirmed
        keep = []
        for t, m in zip(tracks, matched, strict=True):
            if m:
                keep.append(t)
            elif t.confirmed:
                t.coast_s += dt
                if t.coast_s <= p.max_coast_s:
                    keep.append(t)
        born = np.flatnonzero(ids == 0)
        v0 = p.velocity0_mps**2
        for j in born:
            P0 = np.zeros((4, 4))
            P0[:2, :2] = R[j]
            P0[2, 2] = P0[3, 3] = v0
            keep.append(_Track(self._next_id, np.r_[z[j], 0.0, 0.0], P0, box[j], ground_bc[j],
                               None if hists is None else hists[j], confirmed=p.n_confirm <= 1))
            ids[j] = self._next_id
            conf[j] = p.n_confirm <= 1
            self._next_id += 1
        self._tracks = keep
        return _Assigned(ids, vel, conf)


# --------------------------------------------------------------------------------------------------
# Recording level
# --------------------------------------------------------------------------------------------------


def _camera_names(rec: Any) -> list[str]:
    topics = rec.topic_types()
    return sorted({rec.sensor_of(t) for t, i in topics.items() if i == "sensor_msgs/msg/CameraInfo"})


def vehicle_detectors_for_recording(rec: Any, roads: Any, cameras: Sequence[str] | None = None,
                                    params: VehicleDetectorParams | None = None, *, world_frame: str = "world"
                                    ) -> dict[str, tuple[str, CameraVehicleDetector]]:
    """A :class:`CameraVehicleDetector` per camera of a recording, from its believed calibration.

    Parameters
    ----------
    rec : Recording
    roads : (n, 5) float
        ``(x0, y0, x1, y1, width)`` in the road (world) frame.
    cameras : sequence of str, optional
        Sensor names; default every camera with a CameraInfo.
    params : VehicleDetectorParams, optional
    world_frame : str

    Returns
    -------
    dict
        camera name -> ``(image topic, detector)``.

    Raises
    ------
    RecordingError
        A camera without image topic, CameraInfo or pose.
    """
    names = list(cameras) if cameras is not None else _camera_names(rec)
    if not names:
        raise RecordingError(f"{rec.paths[0]}: no camera with a CameraInfo topic")
    out = {}
    for name in names:
        topic = rec.image_topic(camera=name)
        H, K, dist, _ = camera_homography(rec, name, world_frame=world_frame)
        out[name] = (topic, CameraVehicleDetector(name, H, roads, params, K=K, dist=dist))
    return out


def vehicle_detections_for_recording(rec: Any, roads: Any, cameras: Sequence[str] | None = None,
                                     params: VehicleDetectorParams | None = None, *, world_frame: str = "world",
                                     time_source: str = "header", start_ns: int | None = None,
                                     stop_ns: int | None = None,
                                     on_frame: Callable[[VehicleFrame, float], None] | None = None
                                     ) -> Iterator[VehicleFrame]:
    """Run :class:`CameraVehicleDetector` over a recording's cameras; frames in time order (all cameras merged).

    A frame that cannot be processed (out of order, black, of another size) yields an empty, ``valid=False``
    frame and a warning; the run goes on.

    Parameters
    ----------
    rec : Recording
    roads : (n, 5) float
    cameras : sequence of str, optional
        Default: every camera with a CameraInfo.
    params : VehicleDetectorParams, optional
    world_frame, time_source : str
    start_ns, stop_ns : int, optional
        Time window of the recording to read.
    on_frame : callable, optional
        Called with each frame and its processing time (s), e.g. for a progress bar or timing.

    Yields
    ------
    VehicleFrame
    """
    detectors = vehicle_detectors_for_recording(rec, roads, cameras, params, world_frame=world_frame)
    by_sensor = {det.camera_name: det for _, det in detectors.values()}
    topics = [topic for topic, _ in detectors.values()]
    for msg in rec.messages(topics, start_ns=start_ns, stop_ns=stop_ns, time_source=time_source):
        det = by_sensor.get(getattr(msg, "sensor", ""))
        if det is None or not isinstance(msg, Image) or msg.encoding == "mono16":
            continue
        tic = time.perf_counter()
        skipped = det.n_skipped
        try:
            found = det(msg)
        except ValueError as err:
            log.warning("%s: frame at %d ns skipped: %s", det.camera_name, msg.t_ns, err)
            frame = VehicleFrame(msg.t_ns, det.camera_name, (), False)
        else:
            frame = VehicleFrame(msg.t_ns, det.camera_name, tuple(found), det.n_skipped == skipped)
        if on_frame is not None:
            on_frame(frame, time.perf_counter() - tic)
        yield frame
