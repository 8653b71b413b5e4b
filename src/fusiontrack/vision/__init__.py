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
* :mod:`~fusiontrack.vision.patches` — seed 001's random patches in a box (B12) and their RGB + edge
  orientation features from integral images (B13).
* :mod:`~fusiontrack.vision.appearance` — per-target online boosted classifiers keeping the K best learners
  (B14, B15), score maps and their particle likelihood (B16), identities at a split (B17):
  :class:`AppearanceBank`.
* :mod:`~fusiontrack.vision.rgbd` — seed 002's RGB-D particle filter (HSV histograms x depth shape, C6),
  the target's world position from depth (C7) and a depth person detector.
* :mod:`~fusiontrack.vision.compressive` — compressive tracking (C10) with the inertial consistency test
  (C11) and the multi-template buffer that recovers from failures (C12).
"""

from fusiontrack.vision.appearance import (
    AppearanceBank,
    AppearanceClassifier,
    AppearanceParams,
    BoostedClassifier,
    BoostParams,
    BoostUpdate,
    ScoreMap,
    assign_identities,
    interacting_region,
    score_map_likelihood,
)
from fusiontrack.vision.blob_tracker import BlobEvent, BlobTracker, BlobTrackerParams, NodeLabel, TrackedObject
from fusiontrack.vision.blobs import BlobParams, Blobs, blob_contours, blob_histograms, clean_mask, extract_blobs
from fusiontrack.vision.compressive import (
    CompressiveParams,
    CompressiveTracker,
    MultiTemplateParams,
    MultiTemplateResult,
    MultiTemplateTracker,
)
from fusiontrack.vision.foreground import ForegroundModel, ForegroundParams, ForegroundResult
from fusiontrack.vision.overlay import OverlayRenderer, draw_overlay, id_colour
from fusiontrack.vision.patches import (
    FeatureParams,
    Patches,
    PatchParams,
    extract_features,
    patch_features,
    sample_patches,
)
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
from fusiontrack.vision.rgbd import (
    RgbdFix,
    RgbdParticleFilter,
    RgbdPfParams,
    detect_people_rgbd,
    remove_floor,
    target_position,
)
from fusiontrack.vision.shadows import PixelLabel, ShadowParams, brightness_chromaticity, shadow_highlight_labels
from fusiontrack.vision.stopped import AugmentedMask, AugmentedMaskParams

__all__ = [
    "AppearanceBank",
    "AppearanceClassifier",
    "AppearanceParams",
    "AugmentedMask",
    "AugmentedMaskParams",
    "BlobEvent",
    "BlobParams",
    "BlobTracker",
    "BlobTrackerParams",
    "Blobs",
    "BoostParams",
    "BoostUpdate",
    "BoostedClassifier",
    "CameraPeopleTracker",
    "CameraRunStats",
    "CameraTrackerParams",
    "CompressiveParams",
    "CompressiveTracker",
    "FeatureParams",
    "ForegroundModel",
    "ForegroundParams",
    "ForegroundResult",
    "FrameResult",
    "MultiTemplateParams",
    "MultiTemplateResult",
    "MultiTemplateTracker",
    "NodeLabel",
    "OverlayRenderer",
    "PatchParams",
    "Patches",
    "PixelLabel",
    "RgbdFix",
    "RgbdParticleFilter",
    "RgbdPfParams",
    "ScoreMap",
    "ShadowParams",
    "TrackedObject",
    "assign_identities",
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
    "detect_people_rgbd",
    "draw_overlay",
    "extract_blobs",
    "extract_features",
    "floor_positions",
    "id_colour",
    "interacting_region",
    "mot_detections",
    "patch_features",
    "remove_floor",
    "sample_patches",
    "score_map_likelihood",
    "shadow_highlight_labels",
    "target_position",
    "track_camera",
]
