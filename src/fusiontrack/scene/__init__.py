"""Scene understanding (seed 003, ALGORITHMS.md D7, D8): incidents from vehicle tracks on a road.

* :mod:`.road` — road geometry (carriageways, lanes, zones) from a TOML file or the simulator's world.json,
  with vectorised point queries.
* :mod:`.rules` — the switching control module (entity type, property selection, constraints) and D8's
  rules: stopped vehicle, road leaving (with its early warning), jam, wrong-way driving; online
  (:class:`SceneUnderstanding`) and in batch (:func:`detect_events`).
* :mod:`.learned` — the supervised alternative: a random forest over 5 s feature windows, same interface.
"""

from .learned import LearnedSceneUnderstanding, SceneClassifier, default_scene_classifier, detect_events_learned
from .road import Lane, Road, RoadGeometry, Zone, load_road_geometry, parse_road_geometry, road_geometry_from_world
from .rules import (
    SceneRules,
    SceneUnderstanding,
    SwitchingControl,
    default_rules,
    detect_events,
    load_rules,
    parse_rules,
)

__all__ = [
    "Lane",
    "LearnedSceneUnderstanding",
    "Road",
    "RoadGeometry",
    "SceneClassifier",
    "SceneRules",
    "SceneUnderstanding",
    "SwitchingControl",
    "Zone",
    "default_rules",
    "default_scene_classifier",
    "detect_events",
    "detect_events_learned",
    "load_road_geometry",
    "load_rules",
    "parse_road_geometry",
    "parse_rules",
    "road_geometry_from_world",
]
