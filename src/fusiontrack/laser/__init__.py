"""Laser people detection (seed 000 / seed 001; ALGORITHMS.md A7, A8, B2–B5).

* :mod:`~fusiontrack.laser.background` — per-beam range background with separate foreground and
  background learning rates (A7), initialised by the histogram mode (B3).
* :mod:`~fusiontrack.laser.clustering` — range-adaptive breakpoint clustering in beam order (A8),
  mean-shift two-feet segments (B4) and the feet inside them (B5); pure functions on arrays.
* :mod:`~fusiontrack.laser.detector` — :class:`LaserPeopleDetector`: several scanners in, world-frame
  :class:`~fusiontrack.types.Detection` s out.
"""

from fusiontrack.laser.background import BeamBackground, clean_ranges, histogram_mode
from fusiontrack.laser.clustering import (
    Feet,
    ScanClusters,
    Segments,
    breakpoint_c1,
    cluster_scan,
    extract_feet,
    mean_shift_modes,
    mean_shift_segments,
)
from fusiontrack.laser.detector import LaserPeopleDetector, planar_pose

__all__ = [
    "BeamBackground",
    "Feet",
    "LaserPeopleDetector",
    "ScanClusters",
    "Segments",
    "breakpoint_c1",
    "clean_ranges",
    "cluster_scan",
    "extract_feet",
    "histogram_mode",
    "mean_shift_modes",
    "mean_shift_segments",
    "planar_pose",
]
