"""The camera-bias pass's laser backgrounds primed from the recording's first scans (ALGORITHMS.md A7, A10).

Online, the A7 background of each laser needs ``bg_n_init`` scans (2 s at 25 Hz) before any beam is foreground,
so no camera frame can update the bias before then. Primed, the backgrounds are learnt first from the first
scans, read ahead; the pass then classifies those scans against them without learning from them again. Checked
on a simulated ``crowd`` whose camera is turned 3 degrees from its calibration (the simulator's truth): the
first update comes before online learning could make one, the backgrounds after the priming are the online
ones, and the bias still converges to the simulator's 3 degrees.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.calibration import BiasParams
from fusiontrack.calibration.bias_run import bias_from_recording, open_bias_inputs
from fusiontrack.errors import ConfigError, RecordingError
from fusiontrack.fusion import learn_camera_bias, track_fused
from fusiontrack.io.recording import Recording
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import Simulation
from fusiontrack.types import GroundTruth

YAW_ERROR_DEG = 3.0


@pytest.fixture(scope="module")
def crowd(simulated) -> dict:
    """9 s of ``crowd`` (two lasers at 25 Hz, a camera at 15 Hz) whose camera is turned 3 degrees."""
    settings = {"cameras.0.yaw_bias_deg": YAW_ERROR_DEG}
    scenario = load_scenario("crowd").with_overrides(seconds=9, seed=0, settings=settings)
    path: Path = simulated("crowd", seconds=9, seed=0, settings=settings)
    offsets_ms = {c.name: c.clock_offset_ms for c in [*scenario.config.lasers, *scenario.config.cameras]}
    with Recording(path) as rec:
        boxes = [g for g in rec.messages(["/ground_truth/camera_0"]) if isinstance(g, GroundTruth)]
    cam = Simulation(scenario).cameras[0]
    return {"path": path, "offsets_ms": offsets_ms, "boxes": boxes, "true": cam.true_camera,
            "calibrated": cam.calibrated_camera, "lasers": [c.name for c in scenario.config.lasers]}


def _scan_stream(crowd: dict) -> tuple[object, list]:
    inputs = open_bias_inputs(crowd["path"], "camera_0", clock_offsets_ms=crowd["offsets_ms"])
    return inputs, list(inputs.scans())


def _online_ready_ns(scans: list, n_init: int) -> int:
    """When every laser has sent ``n_init`` scans: online, no beam is foreground before then."""
    t: dict[str, list[int]] = {}
    for s in scans:
        t.setdefault(s.sensor, []).append(s.t_ns)
    return max(ts[n_init - 1] for ts in t.values())


def _backgrounds(est, lasers: list[str]) -> dict[str, np.ndarray | None]:
    return {n: None if est.background(n) is None else np.array(est.background(n).background_m) for n in lasers}


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(
        (x is None and y is None) or (x is not None and y is not None and np.array_equal(x, y, equal_nan=True))
        for x, y in ((a[k], b[k]) for k in a))


def test_primed_backgrounds_are_the_online_ones_and_the_primed_scans_are_not_learnt_again(crowd):
    inputs, scans = _scan_stream(crowd)
    lasers = crowd["lasers"]
    online, primed = inputs.estimator(), inputs.estimator()
    used = primed.prime(iter(scans))
    n_init = BiasParams().bg_n_init
    n_primed = sum(used.values())
    assert min(used.values()) >= n_init  # every laser initialised ...
    assert n_primed < 4 * n_init * len(lasers)  # ... well within the default bound
    after_priming = _backgrounds(primed, lasers)
    for k, scan in enumerate(scans):
        online.observe_scan(scan)
        primed.observe_scan(scan)
        if k + 1 < n_primed:  # scans the priming read: classified, not learnt from again
            assert _same(_backgrounds(primed, lasers), after_priming)
        else:  # from the end of the priming on: the same numbers as online learning
            assert _same(_backgrounds(primed, lasers), _backgrounds(online, lasers)), k
        if k + 1 == n_primed:
            assert _same(after_priming, _backgrounds(online, lasers))


def test_a_laser_with_too_few_scans_is_left_to_learn_online(crowd):
    inputs, scans = _scan_stream(crowd)
    lasers = crowd["lasers"]
    n_init = 10
    counts = dict.fromkeys(lasers, 0)
    for k, s in enumerate(scans):  # stop the priming as the first laser reaches n_init scans
        counts[s.sensor] += 1
        if max(counts.values()) == n_init:
            limit = k + 1
            break
    slow = min(counts, key=counts.get)
    assert counts[slow] < n_init
    params = BiasParams(bg_n_init=n_init)
    online, primed = inputs.estimator(params), inputs.estimator(params)
    used = primed.prime(iter(scans), max_scans=limit)
    assert used == counts
    assert primed.background(slow) is None  # not half primed
    for s in scans:
        online.observe_scan(s)
        primed.observe_scan(s)
        for name in lasers:
            if name == slow or s.t_ns > scans[limit - 1].t_ns:
                # the slow laser learns online from its first scan, the other once past its primed scans
                assert _same(_backgrounds(primed, [name]), _backgrounds(online, [name]))


def test_primed_bias_moves_before_online_learning_could(crowd):
    """With the simulator's boxes (the laser side alone): online, the first update waits for every laser's
    ``bg_n_init``-th scan (2 s); primed, it comes with the first frames, people being in view from the start."""
    _, scans = _scan_stream(crowd)
    ready = _online_ready_ns(scans, BiasParams().bg_n_init)
    assert ready - scans[0].t_ns >= 1.9e9
    first_seen = next(g.t_ns for g in crowd["boxes"] if len(g.ids))
    first = {}
    for mode in ("learn", "prime"):
        run = bias_from_recording(crowd["path"], "camera_0", boxes="truth", clock_offsets_ms=crowd["offsets_ms"],
                                  background=mode)
        h = run.history
        first[mode] = int(h.t_ns[np.flatnonzero(h.n_used)[0]])
        assert math.degrees(run.bias_rad) == pytest.approx(YAW_ERROR_DEG, abs=0.2), mode
    assert first["learn"] >= ready
    assert first["prime"] < ready - 1e9
    assert first["prime"] - first_seen <= 0.5e9


def test_primed_bias_pass_converges_to_the_true_misalignment(crowd):
    """The pipeline's pass (vision path, stop rule) primed: its first update before online learning could make
    one, settled at the simulator's 3 degrees, and the corrected camera looks where the true camera does."""
    _, scans = _scan_stream(crowd)
    ready = _online_ready_ns(scans, BiasParams().bg_n_init)
    corrections = {k: -round(v * 1e6) for k, v in crowd["offsets_ms"].items()}
    bias = learn_camera_bias(crowd["path"], "camera_0", clock_corrections_ns=corrections, background="prime")
    with Recording(crowd["path"]) as rec:  # read through the caller's open recording (as track_fused does)
        shared = learn_camera_bias(crowd["path"], "camera_0", clock_corrections_ns=corrections, background="prime",
                                   recording=rec)
        assert next(iter(rec.messages(["/camera_0/image"])), None) is not None  # left open for the caller
    for field in ("t_ns", "bias_rad", "n_used"):  # the same pass
        np.testing.assert_array_equal(getattr(shared.history, field), getattr(bias.history, field))
    h = bias.history
    assert h.t_ns[np.flatnonzero(h.n_used)[0]] < ready
    assert bias.settled
    assert bias.applied
    assert math.degrees(bias.bias_rad) == pytest.approx(YAW_ERROR_DEG, abs=0.15)
    true, corrected = crowd["true"], bias.corrected_camera

    def axis_azimuth(cam) -> float:
        z = np.asarray(cam.cam2world)[:3, 2]
        return math.atan2(z[1], z[0])

    err = math.degrees(abs(math.remainder(axis_azimuth(corrected) - axis_azimuth(true), 2 * math.pi)))
    assert err <= 0.15
    assert math.degrees(abs(math.remainder(axis_azimuth(crowd["calibrated"]) - axis_azimuth(true), 2 * math.pi))) \
        == pytest.approx(YAW_ERROR_DEG, abs=0.01)


class _Stop(Exception):
    pass


@pytest.mark.parametrize("mode", ["prime", "learn"])
def test_track_fused_passes_its_background_choice_to_the_bias_pass(crowd, mode, monkeypatch):
    import fusiontrack.fusion.tracker as ft

    seen = []

    def spy(*args, **kw):
        seen.append(kw.get("background"))
        raise _Stop

    monkeypatch.setattr(ft, "learn_camera_bias", spy)
    with pytest.raises(_Stop):
        track_fused(crowd["path"], background=mode)
    assert seen == [mode]


@pytest.mark.parametrize("bad", ["Prime", "none", "", None, 1])
def test_bad_background_is_a_config_error_naming_it(bad, tmp_path):
    missing = tmp_path / "nothing"
    for call in (lambda: learn_camera_bias(missing, "camera_0", background=bad),
                 lambda: bias_from_recording(missing, "camera_0", background=bad)):
        with pytest.raises(ConfigError, match="background"):
            call()
    with pytest.raises(RecordingError):  # a good value goes on to open the recording
        bias_from_recording(missing, "camera_0", background="prime")


def test_bad_priming_calls_name_the_argument(crowd):
    inputs, scans = _scan_stream(crowd)
    with pytest.raises(ConfigError, match="background"):
        inputs.estimator(background="online")
    est = inputs.estimator()
    with pytest.raises(ValueError, match="max_scans"):
        est.prime(iter(scans), max_scans=-1)
    est.observe_scan(scans[0])
    with pytest.raises(ValueError, match="prime"):  # priming comes before the first scan
        est.prime(iter(scans))


def test_a_repeated_camera_frame_is_skipped_and_the_bias_still_learnt(crowd, monkeypatch, caplog):
    """One camera frame delivered twice (a driver's hiccup) is skipped with a warning: the pass goes on and settles
    at the simulator's 3 degrees (it used to end the pass: the blob tracker's frames must advance)."""
    from fusiontrack.calibration.bias_run import FrameObjects
    from fusiontrack.types import Image

    original = Recording.messages

    def repeat_fifth_image(self, *args, **kwargs):
        n = 0
        for msg in original(self, *args, **kwargs):
            yield msg
            if isinstance(msg, Image):
                n += 1
                if n == 5:
                    yield msg

    monkeypatch.setattr(Recording, "messages", repeat_fifth_image)
    corrections = {k: -round(v * 1e6) for k, v in crowd["offsets_ms"].items()}
    with caplog.at_level("WARNING"):
        bias = learn_camera_bias(crowd["path"], "camera_0", clock_corrections_ns=corrections, background="prime")
    assert bias.settled
    assert math.degrees(bias.bias_rad) == pytest.approx(YAW_ERROR_DEG, abs=0.15)
    inputs = open_bias_inputs(crowd["path"], "camera_0", clock_offsets_ms=crowd["offsets_ms"])
    with caplog.at_level("WARNING"):
        frames = [x for x in inputs if isinstance(x, FrameObjects)]
    assert np.all(np.diff([f.t_ns for f in frames]) > 0)
    assert "1 frame(s) not after the previous one skipped" in caplog.text
