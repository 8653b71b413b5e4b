"""The trusted (unchecked) constructors of Detection and TrackState give the same records as the checked ones."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.types import Detection, TrackState


def _fields(rec: object) -> dict:
    return {n: getattr(rec, n) for n in type(rec).__slots__}


def _same(a: object, b: object) -> None:
    fa, fb = _fields(a), _fields(b)
    assert fa.keys() == fb.keys()
    for k in fa:
        x, y = fa[k], fb[k]
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert x.dtype == y.dtype, k
            assert np.array_equal(x, y), k
            assert not x.flags.writeable, k
            assert not y.flags.writeable, k
        elif k in ("features", "class_probs"):
            assert dict(x).keys() == dict(y).keys(), k
            for kk in x:
                assert np.array_equal(x[kk], y[kk]), (k, kk)
            with pytest.raises(TypeError):
                x["new"] = 1  # read-only mapping
        else:
            assert x == y, k
            assert type(x) is type(y), k


def test_detection_trusted_equals_checked() -> None:
    pos, cov, box = np.array([1.5, -2.0]), np.array([[0.1, 0.01], [0.01, 0.2]]), np.array([1.0, 2.0, 30.0, 40.0])
    feats = {"box": np.array([1.5, -2.0, 4.5, 1.8, 0.1]), "track_id": np.array([7], np.int64)}
    probs = {"car": 0.75, "unknown": 0.25}
    checked = Detection(10, "laser_0", pos, cov, box, 0.9, "car", probs, feats)
    fast = Detection.trusted(10, "laser_0", pos.copy(), cov.copy(), box.copy(), 0.9, "car", dict(probs),
                             {k: v.copy() for k, v in feats.items()})
    _same(fast, checked)
    bare = Detection.trusted(3, "camera_0", None, None, box.copy())
    assert bare.position_m is None
    assert bare.cls == "unknown"
    assert dict(bare.features) == {}


def test_detection_trusted_arrays_become_read_only() -> None:
    pos = np.array([0.0, 1.0])
    d = Detection.trusted(1, "s", pos, np.eye(2), features={"v": np.ones(2)})
    with pytest.raises(ValueError, match="read-only"):
        d.position_m[0] = 5.0
    with pytest.raises(ValueError, match="read-only"):
        d.features["v"][0] = 5.0


def test_moved_shares_everything_but_the_position() -> None:
    d = Detection(5, "laser_1", [1.0, 2.0], np.eye(2) * 0.01, cls="car",
                  features={"velocity_mps": np.array([10.0, 0.0])})
    m = d.moved(d.position_m + d.features["velocity_mps"] * 0.1)
    assert np.allclose(m.position_m, [2.0, 2.0])
    assert not m.position_m.flags.writeable
    assert np.array_equal(d.position_m, [1.0, 2.0])  # the original is untouched
    assert m.features is d.features
    assert m.covariance_m2 is d.covariance_m2
    assert (m.t_ns, m.sensor, m.cls) == (
        d.t_ns, d.sensor, d.cls)


def test_trackstate_trusted_equals_checked() -> None:
    pos, vel, cov = np.array([3.0, 4.0]), np.array([1.0, -1.0]), np.eye(4) * 0.5
    checked = TrackState(20, "fusion_pf", 4, pos, vel, cov, cls="car", sensors=("camera_0", "laser_0"), score=0.5)
    fast = TrackState.trusted(20, "fusion_pf", 4, pos.copy(), vel.copy(), cov.copy(), cls="car",
                              sensors=("camera_0", "laser_0"), score=0.5)
    _same(fast, checked)


def test_records_with_read_only_mappings_survive_pickling() -> None:
    """Detections, events and ground truth cross process boundaries (the traffic pipeline's camera workers):
    a pickle round trip gives an equal record, still read-only."""
    import pickle

    from fusiontrack.types import Event, GroundTruth, records_equal

    recs = [
        Detection(t_ns=5, sensor="camera_0", position_m=[1.0, 2.0], box_px=[1, 2, 30, 40], cls="car",
                  class_probs={"car": 0.9}, features={"hist_hsv": np.arange(6.0), "track_id": np.array([3])}),
        Detection.trusted(6, "laser_0", np.zeros(2), np.eye(2), None, 0.5, "car", features={"a": np.ones(2)}),
        Event(t_ns=7, sensor="fusion_pf", kind="jam", position_m=[3.0, 4.0], track_ids=(1, 2),
              attributes={"alarm_t_ns": 9}),
        GroundTruth(t_ns=8, sensor="sim", frame_id="world", ids=[1, 2], positions_m=np.zeros((2, 2)),
                    classes=("car", "person"), attributes={"heading_rad": np.array([0.1, 0.2])}),
    ]
    for rec in recs:
        back = pickle.loads(pickle.dumps(rec))
        assert type(back) is type(rec)
        assert records_equal(rec, back)
        for name in type(rec).__slots__:
            v = getattr(back, name)
            if isinstance(v, np.ndarray):
                assert not v.flags.writeable, name
            if name in ("features", "class_probs", "attributes"):
                with pytest.raises(TypeError):
                    v["new"] = 1
                assert all(not a.flags.writeable for a in v.values() if isinstance(a, np.ndarray))
