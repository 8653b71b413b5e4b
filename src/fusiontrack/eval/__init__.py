"""Evaluation: tracking metrics computed with TrackEval, and situation-detection accuracy (seed 001 Table II).

* :mod:`.mot` — CLEAR MOT, identity and HOTA metrics on floor-plane distances or image boxes.
* :mod:`.situations` — true counts, detections and false alarms of merge/split/correlated/appear/disappear.
* :mod:`.switches` — the cause of each identity switch (two tracks exchanging people, a track lost and replaced, a
  track shared by two people walking side by side, an older track taking over).
* :mod:`.appearance` — how well seed 001's classifiers tell people apart in a video with detections, without
  annotated identities (imported on its own: it needs the vision package).
"""

from .errors import EvaluationError
from .mot import (
    MOT16_DISTRACTOR_CLASSES,
    MOT20_DISTRACTOR_CLASSES,
    FrameMatches,
    Metrics,
    MetricsTable,
    combine_metrics,
    evaluate_boxes,
    evaluate_camera_boxes,
    evaluate_floor,
    evaluate_mot_files,
    floor_similarity,
    frame_matches,
    metrics_table,
    truth_at,
)
from .situations import (
    SituationAgreement,
    SituationScore,
    match_events,
    situation_accuracy,
    situation_agreement,
    situation_table,
)
from .switches import SWITCH_CAUSES, IdSwitch, id_switch_causes, switch_cause_counts

__all__ = [
    "MOT16_DISTRACTOR_CLASSES",
    "MOT20_DISTRACTOR_CLASSES",
    "SWITCH_CAUSES",
    "EvaluationError",
    "FrameMatches",
    "IdSwitch",
    "Metrics",
    "MetricsTable",
    "SituationAgreement",
    "SituationScore",
    "combine_metrics",
    "evaluate_boxes",
    "evaluate_camera_boxes",
    "evaluate_floor",
    "evaluate_mot_files",
    "floor_similarity",
    "frame_matches",
    "id_switch_causes",
    "match_events",
    "metrics_table",
    "situation_accuracy",
    "situation_agreement",
    "situation_table",
    "switch_cause_counts",
    "truth_at",
]
