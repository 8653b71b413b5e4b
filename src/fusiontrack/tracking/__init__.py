"""Tracking maths of seed 001 (and the shared CV filter): pure, vectorised functions on arrays.

The block diagram, one module per block (ALGORITHMS.md sections in brackets):

- :mod:`.pf` — SIR particle-filter core over ``(n_targets, n_particles, ...)`` arrays [X1]
- :mod:`.walking` — two-feet walking model, standing random walk, constant velocity [B8, B18, X5]
- :mod:`.likelihood` — laser feet/walking-pattern likelihood, centroid likelihood [B9, B18]
- :mod:`.association` — statistical-distance gate, association states c/r, Hungarian [B6, B10, X2]
- :mod:`.situations` — the per-frame situation switch [B7]
- :mod:`.kalman` — constant-velocity Kalman predict/update [X5]
- :mod:`.tracker` — the stateful laser people tracker that strings them together (B6-B10, B17), and
  :func:`track_recording` (detector + tracker over a recording)
- :mod:`.baseline` — constant-velocity Kalman + Hungarian tracker, the comparison baseline
- :mod:`.online` — :class:`OnlineLaserTracker`: detector + tracker fed one scan at a time (a live scanner)
"""

from .baseline import CVKalmanTracker
from .online import OnlineLaserTracker
from .tracker import LaserPeopleTracker, TrackerParams, track_recording

__all__ = ["CVKalmanTracker", "LaserPeopleTracker", "OnlineLaserTracker", "TrackerParams", "track_recording"]
