"""Camera path of seed 000 (ALGORITHMS.md A1-A5): foreground, blobs and the blob tracker.

* :mod:`~fusiontrack.vision.foreground` — :class:`ForegroundModel`: OpenCV MOG2 (A1) + seed 000's
  stopped-object augmented mask (A2, :mod:`~fusiontrack.vision.stopped`) + shadow/highlight removal
  (A3, :mod:`~fusiontrack.vision.shadows`), with recovery from illumination jumps and black frames.
* :mod:`~fusiontrack.vision.blobs` — :func:`extract_blobs` (A4): morphology, connected components,
  boxes, centroids, contours and HSV histograms.
* :mod:`~fusiontrack.vision.blob_tracker` — :class:`BlobTracker` (A5): association events, inference
  graph, fragments and groups, identities restored by colour after a group splits.
"""

from fusiontrack.vision.blob_tracker import BlobEvent, BlobTracker, BlobTrackerParams, NodeLabel, TrackedObject
from fusiontrack.vision.blobs import BlobParams, Blobs, blob_contours, blob_histograms, clean_mask, extract_blobs
from fusiontrack.vision.foreground import ForegroundModel, ForegroundParams, ForegroundResult
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
    "ForegroundModel",
    "ForegroundParams",
    "ForegroundResult",
    "NodeLabel",
    "PixelLabel",
    "ShadowParams",
    "TrackedObject",
    "blob_contours",
    "blob_histograms",
    "brightness_chromaticity",
    "clean_mask",
    "extract_blobs",
    "shadow_highlight_labels",
]
