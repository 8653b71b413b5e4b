"""Laser + camera fusion: seed 001's tracking-learning loop (ALGORITHMS.md B11, B15, B16, B17, B19).

* :class:`FusionTracker` — the laser people tracker whose noncorrelated targets train online per-target
  appearance classifiers; those classifiers check identities after close contact (exchanging them back when
  the laser swapped them), give a reborn track the id of the person it recognises, and their score maps are the
  observation of correlated targets (B16). Optional (off by default, :class:`FusionParams`): the identities of
  the pieces of a split decided by appearance (B17);
* :func:`track_fused` — the same over a recording (the ``people`` pipeline of ``fusiontrack track``), through
  the camera corrected by the horizontal bias it first learns against the lasers (:func:`learn_camera_bias`,
  seed 000);
* :func:`relabel_states` — applies the identity decisions (:class:`Relabel`: exchanges and re-identifications)
  to states already output;
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
    camera_boxes,
    learn_camera_bias,
    relabel_states,
    track_fused,
)

__all__ = ["BiasLearning", "CameraBias", "FrameSource", "FusionParams", "FusionStats", "FusionTracker", "LazyFrames",
           "Relabel", "camera_boxes", "learn_camera_bias", "relabel_states", "track_fused"]
