"""Deaths on the edge of the covered area: who is heading out disappears at once, who is not coasts (edge_leave_s)."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.sim.agents import feet_positions
from fusiontrack.tracking.tracker import LaserPeopleTracker
from fusiontrack.types import Detection

FRAME_NS = 40_000_000  # 25 Hz
AREA = (0.0, 0.0, 10.0, 4.0)  # the edge band: within 0.5 m of a side


def _walk(n: int, start_m: tuple[float, float], heading_rad: float, speed: float = 1.3,
          stride: float = 1.4) -> tuple[np.ndarray, np.ndarray]:
    """Body positions (n, 2) and feet (n, 2, 2) of a walker going straight at ``heading_rad``."""
    dt = FRAME_NS / 1e9
    u = np.array([np.cos(heading_rad), np.sin(heading_rad)])
    pos = np.asarray(start_m, float) + np.arange(n)[:, None] * speed * dt * u
    phase = 2 * np.pi * speed * dt * np.arange(n) / stride
    return pos, feet_positions(pos, np.full(n, heading_rad), phase, np.full(n, stride))


def _run(params: dict, pos: np.ndarray, feet: np.ndarray, seen) -> tuple[list, list]:
    """States and events of one walker, detected in the scans ``k`` where ``seen(k, position)``."""
    rng = np.random.default_rng(7)
    trk = LaserPeopleTracker(params, area_m=AREA, rng=0, lateral_m=0.2)
    states, events = [], []
    for k in range(pos.shape[0]):
        dets = []
        if seen(k, pos[k]):
            f = feet[k] + rng.normal(0.0, 0.01, (2, 2))
            sd = float(np.hypot(*(f[0] - f[1])))
            features = {"feet_m": f, "inter_feet_m": np.asarray(sd), "one_foot": np.asarray(sd < 0.12)}
            dets = [Detection(k * FRAME_NS, "laser", position_m=f.mean(axis=0), features=features)]
        states += trk.step(k * FRAME_NS, dets)
        events += trk.events
    return states, events


def _in_band(p: np.ndarray) -> bool:
    return min(p[0] - AREA[0], AREA[2] - p[0], p[1] - AREA[1], AREA[3] - p[1]) < 0.5


@pytest.mark.parametrize("heading_deg", [0.0, 10.0])
def test_a_walker_on_the_edge_not_heading_out_keeps_its_id_when_hidden(heading_deg: float) -> None:
    """Along the wall (0 deg) or slowly inwards (10 deg) in the edge band, hidden for 5 scans (someone passes in
    front of it) after 1.2 s: it is the same person throughout. With the leaving rule: one track, no disappear;
    with B7's rule (a target on the edge with no detection disappears) the person comes back as a new track."""
    n = 60
    pos, feet = _walk(n, (1.0, 0.1 if heading_deg else 0.3), np.deg2rad(heading_deg))
    hidden = range(30, 35)
    assert all(_in_band(pos[k]) for k in hidden)  # the scene is what it claims to be
    seen = lambda k, p: k not in hidden  # noqa: E731
    states, events = _run({"edge_leave_s": 0.5}, pos, feet, seen)
    assert {s.track_id for s in states} == {1}
    assert not [e for e in events if e.kind in ("disappear", "lost")]
    assert "disappearing" not in {s.situation for s in states}  # it coasts: its states do not say it is leaving
    # the coasted track stayed with the person while hidden
    for s in states:
        k = s.t_ns // FRAME_NS
        assert np.hypot(*(s.position_m - pos[k])) < 0.3
    b7_states, b7_events = _run({"edge_leave_s": 0.0}, pos, feet, seen)
    assert len({s.track_id for s in b7_states}) == 2
    assert [e.kind for e in b7_events if e.kind in ("disappear", "lost")] == ["disappear"]


@pytest.mark.parametrize("edge_leave_s", [0.0, 0.5])
def test_a_walker_going_out_disappears_at_once(edge_leave_s: float) -> None:
    """Straight at the bottom wall from 2 m in, unseen once 0.3 m from it (through the door): it disappears there,
    within B7's few frames of its last detection, under either rule."""
    n = 75
    pos, feet = _walk(n, (5.0, 2.0), -np.pi / 2)
    states, events = _run({"edge_leave_s": edge_leave_s}, pos, feet, lambda k, p: p[1] > 0.3)
    ends = [e for e in events if e.kind in ("disappear", "lost")]
    assert [e.kind for e in ends] == ["disappear"]
    assert ends[0].t_end_ns - ends[0].t_ns <= 6 * FRAME_NS
    assert {s.track_id for s in states} == {1}


def test_a_walker_on_the_edge_that_never_comes_back_still_ends() -> None:
    """Along the wall in the edge band, then never seen again (it stopped behind a pillar, or left unseen): the
    track coasts as an interior one and ends after n_miss frames, as a disappear (it is on the edge)."""
    n = 100
    pos, feet = _walk(n, (1.0, 0.3), 0.0)
    _, events = _run({"edge_leave_s": 0.5}, pos, feet, lambda k, p: k < 40)
    ends = [e for e in events if e.kind in ("disappear", "lost")]
    assert len(ends) == 1
    assert ends[0].kind == "disappear"
    missed = (ends[0].t_end_ns - ends[0].t_ns) / FRAME_NS
    assert 25 <= missed <= 27  # n_miss = 25 frames of coasting
