"""Laser + camera fusion: seed 001's tracking-learning loop (ALGORITHMS.md B11, B15, B16, B17, B19).

* :class:`FusionTracker` — the laser people tracker whose correlated targets are also weighted by the score
  maps of online per-target appearance classifiers, whose merged targets get their identities back from those
  classifiers when they split, and whose noncorrelated targets train them;
* :func:`track_fused` — the same over a recording (the ``people`` pipeline of ``fusiontrack track``), through
  the camera corrected by the horizontal bias it first learns against the lasers (:func:`learn_camera_bias`,
  seed 000);
* :func:`relabel_states` — applies the identity checks' exchanges (:class:`Relabel`) to states already output;
* :class:`LazyFrames` — a recording's camera images, converted only when the tracker needs one.
"""

from .frames import LazyFrames
from .tracker import (
    BiasLearning,
    CameraBias,
    FrameSource,
    FusionParams,
    FusionStats,
    FusionTracker,
    Relabel,
    learn_camera_bias,
    relabel_states,
    track_fused,
)

__all__ = ["BiasLearning", "CameraBias", "FrameSource", "FusionParams", "FusionStats", "FusionTracker", "LazyFrames",
           "Relabel", "learn_camera_bias", "relabel_states", "track_fused"]
