"""Step length from step duration (ALGORITHMS.md C3) and the model's JSON round trip."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.inertial import DEFAULT_STEP_MODEL, StepLengthModel, fit_step_model, load_step_model


def test_c3_ols_recovers_the_line() -> None:
    # ALGORITHMS.md C3 test: 200 noisy samples, a = 0.9, b = 0.2, σ = 0.03 m
    rng = np.random.default_rng(0)
    d = rng.uniform(0.4, 0.8, 200)
    L = 0.9 * d + 0.2 + rng.normal(0.0, 0.03, 200)
    model = fit_step_model(d, L, subject="alice")
    assert abs(model.slope_mps - 0.9) < 0.05
    assert abs(model.intercept_m - 0.2) < 0.03
    assert model.rms_m == pytest.approx(0.03, rel=0.15)
    assert model.n_train == 200
    assert model.subject == "alice"
    assert model.typical_duration_s == pytest.approx(np.median(d))


def test_walk_totals_at_several_paces_give_the_line_exactly() -> None:
    a, b = 1.1, 0.15
    walks = [np.full(60, 0.45), np.full(50, 0.6), np.r_[np.full(30, 0.7), np.full(10, 0.75)]]
    totals = [float(np.sum(a * w + b)) for w in walks]
    model = fit_step_model(walks, total_length_m=totals)
    assert model.slope_mps == pytest.approx(a, abs=1e-9)
    assert model.intercept_m == pytest.approx(b, abs=1e-9)
    assert np.isnan(model.rms_m)


def test_one_walk_scales_the_prior() -> None:
    durations = np.full(100, 0.5)
    model = fit_step_model(durations, total_length_m=70.0)
    assert model.length(durations).sum() == pytest.approx(70.0)
    # the shape of the prior line is kept: the ratio a / b is the default one
    assert model.slope_mps / model.intercept_m == pytest.approx(0.9 / 0.2)


def test_defaults_and_clip() -> None:
    m = DEFAULT_STEP_MODEL
    assert (m.slope_mps, m.intercept_m, m.min_length_m, m.max_length_m) == (0.9, 0.2, 0.2, 1.2)
    np.testing.assert_allclose(m.length([0.0, 0.5, 2.0]), [0.2, 0.65, 1.2])
    assert m.length(0.5).shape == ()


def test_json_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    d = rng.uniform(0.4, 0.8, 50)
    fitted = fit_step_model(d, 0.8 * d + 0.25 + rng.normal(0, 0.01, 50), subject="bob")
    for model in (fitted, DEFAULT_STEP_MODEL):
        back = StepLengthModel.from_json(model.to_json())
        assert back.to_dict() == model.to_dict()
        path = model.save(tmp_path / f"{model.subject}.json")
        assert load_step_model(path).to_dict() == model.to_dict()
        json.loads(path.read_text())  # strict JSON: no NaN tokens
    assert load_step_model(tmp_path / "bob.json") == fitted


def test_bad_inputs_name_the_parameter(tmp_path: Path) -> None:
    d = np.full(10, 0.5)
    with pytest.raises(ValueError, match="exactly one"):
        fit_step_model(d)
    with pytest.raises(ValueError, match="exactly one"):
        fit_step_model(d, d, total_length_m=5.0)
    with pytest.raises(ValueError, match="lengths_m: expected shape"):
        fit_step_model(d, d[:5])
    with pytest.raises(ValueError, match="total_length_m: expected 2"):
        fit_step_model([d, d], total_length_m=5.0)
    with pytest.raises(ValueError, match="durations_s"):
        fit_step_model(np.array([0.5, np.nan]), total_length_m=1.0)
    with pytest.raises(ValueError, match="total_length_m"):
        fit_step_model(d, total_length_m=-3.0)
    with pytest.raises(ValueError, match="min_length_m"):
        StepLengthModel(min_length_m=1.0, max_length_m=0.5)
    with pytest.raises(ValueError, match="unknown field"):
        StepLengthModel.from_json('{"slope": 1.0}')
    with pytest.raises(ValueError, match="format"):
        StepLengthModel.from_json('{"format": "something/else"}')
    with pytest.raises(ValueError, match="not valid JSON"):
        StepLengthModel.from_json("{")
    with pytest.raises(ValueError, match=r"missing\.json"):
        load_step_model(tmp_path / "missing.json")
    with pytest.raises(ValueError, match="duration_s"):
        DEFAULT_STEP_MODEL.length([-1.0])
