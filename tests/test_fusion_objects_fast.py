"""D5 fusion (fuse_objects) against its equations on well-separated vehicles: the information-weighted mean of the
members' positions, velocity from the lasers, colour the mean camera histogram, confidence by sensor count."""

from __future__ import annotations

import numpy as np

from fusiontrack.fusion.objects import DetectionBuffer, fuse_objects
from fusiontrack.types import Detection


def _scene(seed: int = 3):
    rng = np.random.default_rng(seed)
    cars = np.column_stack([np.arange(6) * 12.0 - 30.0, rng.choice([-1.75, 1.75], 6)])
    vel = np.column_stack([rng.uniform(5, 15, 6) * np.sign(cars[:, 1]), np.zeros(6)])
    per: dict[str, list[Detection]] = {}
    truth: dict[int, list[Detection]] = {i: [] for i in range(6)}
    for s in ("laser_0", "laser_1", "camera_0", "camera_1"):
        per[s] = []
        for i in rng.permutation(6):
            laser = s.startswith("laser")
            a = rng.normal(size=(2, 2)) * (0.05 if laser else 0.4)
            cov = a @ a.T + np.eye(2) * (0.003 if laser else 0.05)
            pos = cars[i] + rng.multivariate_normal([0, 0], cov)
            feats = {"velocity_mps": vel[i] + rng.normal(size=2) * 0.2}
            if laser:
                feats["box"] = np.array([*pos, 4.4, 1.8, 0.0])
                d = Detection(0, s, pos, cov, cls="car", features=feats)
            else:
                h = rng.random(16)
                feats["hist_hsv"] = h / h.sum()
                d = Detection(0, s, pos, cov, box_px=[0.0, 0.0, 10.0, 10.0], cls="car", features=feats)
            per[s].append(d)
            truth[i].append(d)
    return cars, per, truth


def test_fused_objects_follow_the_d5_equations() -> None:
    cars, per, truth = _scene()
    objs = fuse_objects(per)
    assert len(objs) == 6
    for o in objs:
        i = int(np.argmin(np.linalg.norm(cars - o.position_m, axis=1)))
        members = truth[i]
        info = sum(np.linalg.inv(d.covariance_m2 + np.eye(2) * 1e-6) for d in members)
        vec = sum(np.linalg.inv(d.covariance_m2 + np.eye(2) * 1e-6) @ d.position_m for d in members)
        assert np.allclose(o.position_m, np.linalg.solve(info, vec), atol=1e-9)
        assert np.allclose(o.covariance_m2, np.linalg.inv(info), atol=1e-12)
        lasers = [d for d in members if d.box_px is None]
        assert np.allclose(o.velocity_mps, np.mean([d.features["velocity_mps"] for d in lasers], axis=0))
        h = np.mean([d.features["hist_hsv"] for d in members if d.box_px is not None], axis=0)
        assert np.allclose(o.hist, h / h.sum())
        assert o.confidence == 1.0
        assert o.sensors == ("camera_0", "camera_1", "laser_0", "laser_1")
        assert o.cls == "car"
        assert np.allclose(o.box[:2], [4.4, 1.8])


def test_single_sensor_and_empty_inputs() -> None:
    _, per, _ = _scene(5)
    cam = fuse_objects({"camera_0": per["camera_0"]})
    assert len(cam) == 6
    assert all(o.velocity_mps is not None and o.confidence == 0.4 and o.box is None for o in cam)
    for o, d in zip(cam, per["camera_0"], strict=True):  # one member: its own position and covariance
        assert np.allclose(o.position_m, d.position_m)
        assert np.allclose(o.covariance_m2, d.covariance_m2, atol=1e-9)
    assert fuse_objects({}) == []
    assert fuse_objects({"laser_0": []}) == []
    nan = Detection(0, "laser_0", [np.nan, 0.0], np.eye(2))
    assert fuse_objects({"laser_0": [nan]}) == []


def test_buffer_moves_detections_with_their_velocity() -> None:
    buf = DetectionBuffer(0.15)
    d = Detection(0, "laser_0", [1.0, 0.0], np.eye(2) * 0.01, features={"velocity_mps": np.array([10.0, 0.0])})
    buf.put("laser_0", 0, [d])
    moved = buf.at(50_000_000)["laser_0"][0]
    assert np.allclose(moved.position_m, [1.5, 0.0])
    assert moved.features is d.features
    assert not moved.position_m.flags.writeable
    assert np.allclose(d.position_m, [1.0, 0.0])


def test_a_tie_of_the_cameras_class_votes_does_not_depend_on_the_hash_seed() -> None:
    """Two cameras see one object, one says car and the other bicycle (no laser box): the class was the set of votes'
    first by string hash, so it changed with PYTHONHASHSEED between identical runs. Each interpreter below runs the
    same fusion with another hash seed: one answer, the first camera's vote."""
    import os
    import subprocess
    import sys

    code = ("import numpy as np\n"
            "from fusiontrack.fusion.objects import fuse_objects\n"
            "from fusiontrack.types import Detection\n"
            "d = lambda s, c: Detection(0, s, [5.0, 1.0], np.eye(2) * 0.1, box_px=[0, 0, 10, 10], cls=c)\n"
            "two = {'camera_0': [d('camera_0', 'car')], 'camera_1': [d('camera_1', 'bicycle')]}\n"
            "print(fuse_objects(two)[0].cls)\n")
    got = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                          env={**os.environ, "PYTHONHASHSEED": str(h)}).stdout.strip()
           for h in range(6)}
    assert got == {"car"}
