"""Incident-detection scores (ALGORITHMS.md D8/D9): matching detections to true incidents by kind, time and place."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fusiontrack.errors import RecordingError
from fusiontrack.eval.errors import EvaluationError
from fusiontrack.eval.events import (
    agent_tracks,
    event_table,
    match_incidents,
    read_agents_csv,
    read_incidents,
    score_events,
)
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.types import Event

S = 1_000_000_000
HEADER = ("t,t_ns,id,class,x,y,vx,vy,heading,left_x,left_y,right_x,right_y,length,width,height,group,gait_phase,"
          "situation")


def write_agents(path: Path) -> Path:
    """Agent 1 drives along x at 10 m/s from x = 0 (t = 0..20 s); agent 2 stands at (100, 5); agent 3 is a person."""
    rows = [HEADER]
    for k in range(0, 201):
        t = k / 10
        rows.append(f"{t:.6f},{k * S // 10},1,car,{10 * t:.4f},0.0,10.0,0.0,0.0,nan,nan,nan,nan,4.5,1.8,1.5,-1,0,x")
        rows.append(f"{t:.6f},{k * S // 10},2,car,100.0,5.0,0.0,0.0,0.0,nan,nan,nan,nan,4.5,1.8,1.5,-1,0,x")
        rows.append(f"{t:.6f},{k * S // 10},3,person,1.0,9.0,0.0,0.0,0.0,0,0,0,0,0.3,0.5,1.7,-1,0,x")
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture
def agents(tmp_path):
    return read_agents_csv(write_agents(tmp_path / "agents.csv"))


def ev(kind: str, t0: float, t1: float | None, pos=None, ids=(), sensor="scene", alarm: float | None = None) -> Event:
    attrs = {} if alarm is None else {"alarm_t_ns": round(alarm * S)}
    return Event(round(t0 * S), sensor, kind, None if t1 is None else round(t1 * S), pos, ids, attrs)


def test_agents_table_and_perfect_tracks(agents) -> None:
    assert len(agents) == 3 * 201
    np.testing.assert_allclose(agents.positions_at([1, 2], 5 * S), [[50.0, 0.0], [100.0, 5.0]])
    tracks = agent_tracks(agents)
    assert [t.track_id for t in tracks] == [1, 2]  # cars and bicycles only
    assert tracks[0].states[50].t_ns == 5 * S
    np.testing.assert_allclose(tracks[0].states[50].velocity_mps, [10.0, 0.0])
    assert tracks[0].states[0].cls == "car"


def test_scores_count_hits_misses_and_false_alarms(agents) -> None:
    truth = [ev("stopped_vehicle", 5.0, 15.0, ids=(2,), sensor="ground_truth"),
             ev("road_leaving", 10.0, None, ids=(1,), sensor="ground_truth")]
    det = [
        ev("stopped_vehicle", 5.5, 16.0, (101.0, 4.0), (77,), alarm=15.5),  # hit: 0.5 s late, 1.4 m away
        ev("stopped_vehicle", 6.0, 7.0, (101.0, 4.0), (78,)),  # a second detection of the same: false alarm
        ev("stopped_vehicle", 30.0, None, (100.0, 5.0), (79,)),  # too late: false alarm
        ev("road_leaving", 11.0, None, (30.0, 0.0), (80,)),  # agent 1 is at x = 110 at t = 11 s: too far
        ev("jam", 0.0, 1.0, (0.0, 0.0), (1,)),
    ]
    s = score_events(truth, det, agents)
    st = s["stopped_vehicle"]
    assert (st.true, st.detections, st.true_positives, st.false_alarms) == (1, 3, 1, 2)
    assert st.precision == pytest.approx(1 / 3)
    assert st.recall == 1.0
    assert st.median_latency_s == pytest.approx(0.5)
    assert st.median_alarm_latency_s == pytest.approx(10.5)
    rl = s["road_leaving"]
    assert (rl.true, rl.true_positives, rl.false_alarms) == (1, 0, 1)
    assert rl.recall == 0.0
    assert np.isnan(rl.median_latency_s)
    jam = s["jam"]
    assert (jam.true, jam.detections, jam.false_alarms) == (0, 1, 1)
    assert np.isnan(jam.recall)
    assert list(s) == ["stopped_vehicle", "road_leaving", "jam", "wrong_way"]
    table = event_table(s, title="t")
    assert table.row_count == 4


def test_position_is_compared_at_the_detection_time(agents) -> None:
    truth = [ev("road_leaving", 10.0, None, ids=(1,))]
    assert match_incidents(truth, [ev("road_leaving", 11.0, None, (112.0, 3.0))], agents) == [(0, 0)]
    # the same place 3 s later is 30 m behind the agent
    assert match_incidents(truth, [ev("road_leaving", 14.0, None, (112.0, 3.0))], agents) == []
    # a larger radius, or time alone, accept it
    assert match_incidents(truth, [ev("road_leaving", 14.0, None, (112.0, 3.0))], agents, radius_m=40.0) == [(0, 0)]
    assert match_incidents(truth, [ev("road_leaving", 14.0, None, (112.0, 3.0))], match_by="time") == [(0, 0)]


def test_time_tolerance_and_open_ends(agents) -> None:
    truth = [ev("stopped_vehicle", 5.0, 15.0, ids=(2,))]
    near = ev("stopped_vehicle", 16.5, None, (100.0, 5.0))  # 1.5 s after the end
    far = ev("stopped_vehicle", 18.0, None, (100.0, 5.0))
    assert match_incidents(truth, [near], agents) == [(0, 0)]
    assert match_incidents(truth, [far], agents) == []
    assert match_incidents(truth, [far], agents, time_tolerance_s=3.5) == [(0, 0)]
    early = ev("stopped_vehicle", 1.0, None, (100.0, 5.0))  # still going on: overlaps
    assert match_incidents(truth, [early], agents) == [(0, 0)]


def test_one_to_one_prefers_the_closest_starts(agents) -> None:
    truth = [ev("stopped_vehicle", 5.0, 15.0, ids=(2,)), ev("stopped_vehicle", 12.0, 20.0, ids=(2,))]
    det = [ev("stopped_vehicle", 12.2, 19.0, (100.0, 5.0)), ev("stopped_vehicle", 5.1, 14.0, (100.0, 5.0))]
    assert match_incidents(truth, det, agents) == [(0, 1), (1, 0)]
    s = score_events(truth, det, agents)["stopped_vehicle"]
    assert s.onset_latency_s == pytest.approx((0.1, 0.2))


def test_ids_kind_map_and_pooling(agents) -> None:
    truth = [ev("road_leaving", 10.0, None, ids=(1,))]
    warning = ev("road_leaving_warning", 9.0, 10.0, (90.0, 0.0), ids=(7,))
    s = score_events(truth, [warning], agents, kinds=("road_leaving",),
                     kind_map={"road_leaving_warning": "road_leaving"})
    assert s["road_leaving"].true_positives == 1
    assert s["road_leaving"].median_latency_s == pytest.approx(-1.0)
    assert score_events(truth, [warning], agents)["road_leaving"].detections == 0  # not mapped: ignored
    assert match_incidents(truth, [ev("road_leaving", 10.5, None, ids=(7,))], match_by="ids", id_map={7: 1}) == [(0, 0)]
    assert match_incidents(truth, [ev("road_leaving", 10.5, None, ids=(7,))], match_by="ids") == []
    a = score_events(truth, [ev("road_leaving", 10.5, None, (105.0, 0.0))], agents)["road_leaving"]
    b = score_events(truth, [], agents)["road_leaving"]
    pooled = a + b
    assert (pooled.true, pooled.true_positives, pooled.recall) == (2, 1, 0.5)
    with pytest.raises(EvaluationError, match="pool"):
        a + score_events(truth, [], agents)["jam"]


def test_bad_inputs(tmp_path, agents) -> None:
    truth = [ev("jam", 1.0, 2.0, ids=(1,))]
    with pytest.raises(EvaluationError, match="agents"):
        match_incidents(truth, truth)
    with pytest.raises(EvaluationError, match="match_by"):
        match_incidents(truth, truth, agents, match_by="colour")  # type: ignore[arg-type]
    with pytest.raises(RecordingError, match="no such file"):
        read_agents_csv(tmp_path / "nothing.csv")
    (tmp_path / "bad.csv").write_text("t,id,x\n1,2,3\n")
    with pytest.raises(RecordingError, match=r"bad\.csv, line 1: header lacks"):
        read_agents_csv(tmp_path / "bad.csv")
    rows = write_agents(tmp_path / "worse.csv").read_text().splitlines()
    rows[4] = rows[4].replace(",10.0,", ",ten,", 1)  # agent 1 at t = 0.1 s
    (tmp_path / "worse.csv").write_text("\n".join(rows) + "\n")
    with pytest.raises(RecordingError, match=r"worse\.csv, line 5"):
        read_agents_csv(tmp_path / "worse.csv")


def test_reads_the_simulators_incidents(tmp_path) -> None:
    run = tmp_path / "road"
    simulate(load_scenario("road").with_overrides(seconds=30, seed=2, settings={
        "cameras": [], "lasers": [], "scenario.ground_truth_hz": 5.0}), run)
    incidents = read_incidents(run)
    assert incidents
    assert {e.kind for e in incidents} <= {"stopped_vehicle", "road_leaving", "jam"}
    agents = read_agents_csv(run)
    for inc in incidents:  # every incident names agents that exist during it
        for a in inc.track_ids:
            rows = agents.rows_of(a)
            assert rows.size
            assert agents.t_ns[rows].min() <= inc.t_end_ns
            assert agents.t_ns[rows].max() >= inc.t_ns
