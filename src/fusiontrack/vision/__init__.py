"""Camera path of seed 000 (ALGORITHMS.md A1-A5): foreground, blobs and the blob tracker.

* :mod:`~fusiontrack.vision.foreground` — :class:`ForegroundModel`: OpenCV MOG2 (A1) + seed 000's
  stopped-object augmented mask (A2, :mod:`~fusiontrack.vision.stopped`) + shadow/highlight removal
  (A3, :mod:`~fusiontrack.vision.shadows`), with recovery from illumination jumps and black frames.
* :mod:`~fusiontrack.vision.blobs` — :func:`extract_blobs` (A4): morphology, connected components,
  boxes, centroids, contours and HSV histograms.
* :mod:`~fusiontrack.vision.blob_tracker` — :class:`BlobTracker` (A5): association events, inference
  graph, fragments and groups, identities restored by colour after a group splits.
* :mod:`~fusiontrack.vision.people` — :class:`CameraPeopleTracker`, the vision-only people tracker (image
  boxes, floor positions through a calibrated camera), fed by the blobs or a MOT detection file;
  :func:`track_camera` runs it over a video or a recording's camera.
* :mod:`~fusiontrack.vision.overlay` — the overlay video: boxes, ids, foreground contours, frame number.
"""

from fusiontrack.vision.blob_tracker import BlobEvent, BlobTracker, BlobTrackerParams, NodeLabel, TrackedObject
from fusiontrack.vision.blobs import BlobParams, Blobs, blob_contours, blob_histograms, clean_mask, extract_blobs
from fusiontrack.vision.foreground import ForegroundModel, ForegroundParams, ForegroundResult
from fusiontrack.vision.overlay import OverlayRenderer, draw_overlay, id_colour
from fusiontrack.vision.people import (
    CameraPeopleTracker,
    CameraRunStats,
    CameraTrackerParams,
    FrameResult,
    blob_detections,
    box_containment,
    box_iou,
    camera_from_recording,
    camera_truth_boxes,
    complete_person_boxes,
    floor_positions,
    mot_detections,
    track_camera,
)
from fusiontrack.vision.shadows import PixelLabel, ShadowParams, brightness_chromaticity, shadow_highlight_labels
from fusiontrack.vision.stopped import AugmentedMask, AugmentedMaskParams

__all__ = [
    "AugmentedMask",
    "AugmentedMaskParams",
    "BlobEvent",
    "BlobParams",
    "BlobTracker",
    "BlobTrackerParams",
    "Blobs",
    "CameraPeopleTracker",
    "CameraRunStats",
    "CameraTrackerParams",
    "ForegroundModel",
    "ForegroundParams",
    "ForegroundResult",
    "FrameResult",
    "NodeLabel",
    "OverlayRenderer",
    "PixelLabel",
    "ShadowParams",
    "TrackedObject",
    "blob_contours",
    "blob_detections",
    "blob_histograms",
    "box_containment",
    "box_iou",
    "brightness_chromaticity",
    "camera_from_recording",
    "camera_truth_boxes",
    "clean_mask",
    "complete_person_boxes",
    "draw_overlay",
    "extract_blobs",
    "floor_positions",
    "id_colour",
    "mot_detections",
    "shadow_highlight_labels",
    "track_camera",
]
