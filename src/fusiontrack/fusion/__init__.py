"""Laser + camera fusion: seed 001's tracking-learning loop (ALGORITHMS.md B11, B15, B16, B17, B19).

* :class:`FusionTracker` — the laser people tracker whose correlated targets are also weighted by the score
  maps of online per-target appearance classifiers, whose merged targets get their identities back from those
  classifiers when they split, and whose noncorrelated targets train them;
* :func:`track_fused` — the same over a recording (the ``people`` pipeline of ``fusiontrack track``);
* :class:`LazyFrames` — a recording's camera images, converted only when the tracker needs one.
"""

from .frames import LazyFrames
from .tracker import FrameSource, FusionParams, FusionStats, FusionTracker, track_fused

__all__ = ["FrameSource", "FusionParams", "FusionStats", "FusionTracker", "LazyFrames", "track_fused"]
