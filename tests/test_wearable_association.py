"""Seed 002's association of RGB-D tracklets with the phones' dead-reckoned paths (ALGORITHMS.md C5, C7, X2, X7):
which detections are which phone's carrier, on a short simulated ``corridor`` (truth: the simulator's plans and
floor tracks) and on synthetic paths. (A file of its own: ``make test`` spreads test files over its workers.)"""

from __future__ import annotations

import csv

import numpy as np

from fusiontrack.fusion.wearable import WearableParams, track_wearable
from fusiontrack.fusion.wearable_assoc import Tracklet, associate
from fusiontrack.fusion.wearable_data import PhoneTrack
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import Simulation


def _truth_at(track: np.ndarray, t_ns: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(t_ns, track[:, 0], track[:, 1]), np.interp(t_ns, track[:, 0], track[:, 2])])


def test_a_passer_by_walking_straight_is_not_taken_for_the_phone_carrier(simulated):
    """``corridor`` (seed 002's setting: one phone carrier and three passers-by; RGB-D cameras see short straight
    stretches of the corridors), cut to 30 s, seed 2. Every tracklet is a steady straight walk, which a similarity
    takes onto any other: the one decided, a passer-by's, matched the phone's path at cost 0, and the corrected path
    was 1 m off the carrier (15 m at 60 s). A steady walk now places a phone in the world only if another tracklet,
    decided then for the phone, confirms it: here none does, nothing is owned and the phone keeps its dead reckoning
    (the carrier's stretches confirming each other: the synthetic test below). Truth: the carrier (the simulator's
    plan) and the agents' floor tracks."""
    sim = Simulation(load_scenario("corridor").with_overrides(seconds=30.0, seed=2))
    (carrier,) = [p.agent_id for p in sim.pedestrian_plans if p.phone]
    recording = simulated("corridor", seconds=30.0, seed=2)
    truth: dict[int, list] = {}
    with open(recording / "ground_truth" / "agents.csv", newline="") as f:
        for r in csv.DictReader(f):
            truth.setdefault(int(r["id"]), []).append((int(r["t_ns"]), float(r["x"]), float(r["y"])))
    truth_xy = {k: np.array(v) for k, v in truth.items()}
    result = track_wearable(recording, WearableParams(cameras=()))
    walkers = set()  # whose walk each tracklet is
    for tr in result.tracklets:
        dist = {a: np.median(np.linalg.norm(_truth_at(xs, tr.t_ns) - tr.xy_m, axis=1)) for a, xs in truth_xy.items()}
        walkers.add(min(dist, key=dist.get))
    assert walkers - {carrier}  # passers-by's tracklets are there to be mistaken
    assert (result.owner < 0).all()
    (pr,) = result.people.values()
    assert not pr.correction.aligned


def _phone(name: str, velocity, seconds: float = 60.0) -> PhoneTrack:
    """A phone's dead reckoning from (0, 0) at 50 Hz, its velocity a function of time (s)."""
    hz = 50
    t = np.arange(0, seconds * hz + 1) / hz
    v = np.array([velocity(x) for x in t])
    xy = np.vstack([[0.0, 0.0], np.cumsum(v[1:] / hz, axis=0)])
    path = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]
    return PhoneTrack(name, (t * 1e9).astype(np.int64), xy, path, np.ones(t.size, bool), np.zeros((0, 2), np.int64),
                      object(), "", t.size)


def _tracklet(t_s: np.ndarray, xy: np.ndarray, seed: int = 0) -> Tracklet:
    xy = xy + np.random.default_rng(seed).normal(0, 0.03, xy.shape)  # (RGB-D detections' noise)
    return Tracklet(np.arange(t_s.size), (t_s * 1e9).astype(np.int64), xy)


def test_two_steady_stretches_of_the_carrier_confirm_each_other_and_a_lone_passer_by_is_refused():
    """A phone walks east for 20 s, then north; in the world its frame is turned 60 degrees and moved (5, -3) m. An
    RGB-D camera sees its carrier walk straight at 5-10 s and at 30-35 s, and a passer-by walk straight at 12-16 s
    elsewhere. Each stretch alone is a steady walk, which the phone's path matches whoever walks it: alone, the
    carrier's and the passer-by's are both left to nobody (the passer-by's was taken: cost 0). Together, the
    carrier's two confirm each other (placed by the first, the phone meets the second where it walks) and the
    passer-by's stays nobody's."""
    phone = _phone("A", lambda t: (1.3, 0.0) if t < 20 else (0.0, 1.3), seconds=45.0)
    turn = np.radians(60)
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])

    def carrier(t0: float, t1: float, seed: int):
        t = np.arange(t0, t1, 1 / 15)
        return _tracklet(t, phone.position_at((t * 1e9).astype(np.int64)) @ rot.T + [5.0, -3.0], seed)

    t = np.arange(12, 16, 1 / 15)
    passer = _tracklet(t, np.array([20.0, 10.0]) + np.outer(t - 12, [-1.2, 0.3]), seed=1)
    first, second = carrier(5, 10, 2), carrier(30, 35, 3)
    for alone in (first, passer):
        assert associate([alone], [phone])[0].tolist() == [-1]
    owner, _ = associate([first, passer, second], [phone])
    assert owner.tolist() == [0, -1, 0]


def test_a_steady_walk_refused_to_one_phone_still_counts_against_another():
    """Phone A is not in the world yet and its carrier walks straight east; phone B is (its start is known) and walks
    east 2 m beside. A tracklet of A's carrier (a steady walk) explains A's path at cost 0.03, B's at 0.8: the two are
    ambiguous and it is left to nobody. A refuses it only until confirmed; counted as impossible, the refusal made B
    look certain, and B took the tracklet of A's carrier (margin 8.2)."""
    a = _phone("A", lambda t: (1.3, 0.0))
    b = _phone("B", lambda t: (1.3, 0.0) if t < 30 else (0.0, 1.3))
    t = np.arange(30, 35, 1 / 15)  # A's carrier seen at 30-35 s, on y = 2 m (B's path is on y = 0)
    tracklet = _tracklet(t, np.column_stack([1.3 * t, np.full(t.size, 2.0)]))
    owner, _ = associate([tracklet], [a, b], start_known={"B": True})
    assert owner[0] != 1  # not B's
