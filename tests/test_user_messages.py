"""Errors and warnings a user meets say what is wrong and where (file, table, key), in plain words.

Each case is a mistake a user can make (a typo in a pipeline file's table, an empty CSV, a cut-off bag, a scenario
without sensors); the message must name the file or table, the offending key and what is known or expected, and
must not show Python internals (tuple reprs, internal function names, ``nan``).
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.errors import ConfigError, RecordingError
from fusiontrack.fusion import FusionParams
from fusiontrack.fusion.wearable import run_wearable
from fusiontrack.inertial import calibrate_imu
from fusiontrack.inertial.pdr_io import load_imu
from fusiontrack.inertial.step_length import StepLengthModel, fit_step_model
from fusiontrack.io import Recording
from fusiontrack.io.imu_csv import read_imu_csv
from fusiontrack.io.tracks import TRACKS_CSV_COLUMNS
from fusiontrack.sim.scenario import builtin_names, load_scenario, parse_scenario

README = Path(__file__).resolve().parents[1] / "README.md"
DEMO_BAG = "laser/leg_tracker_demo/demo_stationary_simple_environment.bag"


def _cli(monkeypatch, capsys, *args: str) -> tuple[int, str]:
    """Run ``fusiontrack ARGS`` in this process as a user would (main(): one error line, exit code 2)."""
    from fusiontrack.cli import main

    monkeypatch.delenv("FUSIONTRACK_DEBUG", raising=False)
    monkeypatch.setattr(sys, "argv", ["fusiontrack", *args])
    with pytest.raises(SystemExit) as exit_info:
        main()
    return exit_info.value.code, capsys.readouterr().err


# 1. [fusion.appearance]: a typo names the table, the key and the known keys ---------------------------------------
@pytest.mark.parametrize(("table", "where", "typo", "a_known_key"), [
    ({"appearance": {"map_patchs": 300}}, "fusion.appearance", "map_patchs", "map_patches"),
    ({"appearance": {"boost": {"n_trees": 5}}}, "fusion.appearance.boost", "n_trees", "n_learners"),
    ({"appearance": {"patches": {"sise_px": 8}}}, "fusion.appearance.patches", "sise_px", "size_px"),
    ({"scoremap": True}, "fusion", "scoremap", "score_map"),
])
def test_a_typo_in_the_fusion_tables_lists_the_known_keys(table, where, typo, a_known_key):
    with pytest.raises(ConfigError) as err:
        FusionParams.from_mapping(table, "site.toml: fusion")
    msg = str(err.value)
    assert msg.startswith(f"site.toml: {where}: unknown key(s) {typo}; known: ")
    assert a_known_key in msg.split("known: ")[1].split(", ")
    assert "__init__" not in msg
    assert "malformed" not in msg


def test_an_appearance_sub_table_that_is_not_a_table_is_named():
    with pytest.raises(ConfigError, match=r"^site\.toml: fusion\.appearance\.boost: expected a table"):
        FusionParams.from_mapping({"appearance": {"boost": 3}}, "site.toml: fusion")


def test_good_appearance_keys_still_reach_the_classifiers():
    p = FusionParams.from_mapping({"appearance": {"map_patches": 150, "boost": {"n_learners": 12}}})
    assert (p.appearance.map_patches, p.appearance.boost.n_learners) == (150, 12)


# 2. [wearable]: the table is named, not an internal function ---------------------------------------------------
def test_a_typo_in_the_wearable_table_names_the_table_and_the_known_keys(tmp_path):
    with pytest.raises(ConfigError) as err:
        run_wearable(tmp_path / "nowhere", tmp_path / "out", foo=1)
    msg = str(err.value)
    assert msg.startswith("wearable: unknown option 'foo'")
    assert "[wearable]" in msg
    known = msg.split("known: ")[1].split(", ")
    assert {"gate", "phones", "seed", "visual"} <= set(known)
    assert not (tmp_path / "out").exists()


def test_a_bad_wearable_value_is_named_under_the_wearable_table(tmp_path):
    with pytest.raises(ConfigError, match=r"^wearable: .*gate"):
        run_wearable(tmp_path / "nowhere", tmp_path / "out", gate=-1.0)


# 3. an empty CSV is called empty -------------------------------------------------------------------------------
def test_an_empty_imu_csv_is_called_empty(tmp_path, monkeypatch, capsys):
    empty = tmp_path / "empty.csv"
    empty.write_bytes(b"")
    for read in (read_imu_csv, load_imu):
        with pytest.raises(RecordingError, match=r"empty\.csv: empty file") as err:
            read(empty)
        assert "columns without a header" not in str(err.value)
    for command in (["info", str(empty)], ["pdr", str(empty), "-o", str(tmp_path / "pdr")]):
        code, stderr = _cli(monkeypatch, capsys, *command)
        assert code == 2
        assert "empty.csv: empty file" in stderr


def test_a_csv_of_only_comments_says_it_has_no_data(tmp_path):
    notes = tmp_path / "notes.csv"
    notes.write_text("# recorded on the stairs\n\n")
    with pytest.raises(RecordingError, match=r"notes\.csv: no data: only blank or comment lines"):
        read_imu_csv(notes)


# 4. a truncated bag: plain text, no tuple repr -----------------------------------------------------------------
def test_a_cut_off_bag_is_described_in_plain_text(shared_data, tmp_path):
    data = (shared_data / DEMO_BAG).read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError) as err:
        Recording(cut)
    msg = str(err.value)
    assert msg.startswith(f"{cut}: cannot open the recording (")
    assert "Header could not be read from file." in msg  # what rosbags found, as a sentence
    assert "('" not in msg
    assert "',)" not in msg
    assert "fusiontrack repair" in msg


# 6. a scenario without sensors is refused; the built-in ones load ----------------------------------------------
@pytest.mark.parametrize("text", ["", '[world]\nsetting = "room"\n\n[agents]\nplan = "crossing"\n'])
def test_a_scenario_file_without_sensors_is_refused(tmp_path, text):
    path = tmp_path / "hall.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_scenario(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: no sensors")
    assert "[[lasers]]" in msg
    assert "[[cameras]]" in msg
    assert "[[phones]]" in msg


def test_every_built_in_scenario_loads_with_sensors():
    for name in builtin_names():
        c = load_scenario(name).config
        assert c.lasers or c.cameras or c.phones, name


def test_a_ground_truth_only_scenario_can_still_be_made_on_purpose():
    # the scene models train on ground truth alone (fusiontrack.scene.learned): sensors removed from a loaded one
    sc = load_scenario("road").with_overrides(settings={"cameras": [], "lasers": []})
    assert not (sc.config.lasers)
    assert not (sc.config.cameras)
    assert not (sc.config.phones)
    assert not parse_scenario({}, "library call").config.lasers


def test_the_simulate_command_refuses_a_scenario_without_sensors(tmp_path, monkeypatch, capsys):
    path = tmp_path / "empty.toml"
    path.write_bytes(b"")
    code, stderr = _cli(monkeypatch, capsys, "simulate", str(path), "-o", str(tmp_path / "out"))
    assert code == 2
    assert f"{path}: no sensors" in stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("setting", "named", "valid"), [
    ("agents.mean_present=-3", "mean_present: expected > 0, got -3", "duration_s"),
    ("agents.interacting_pairs=-1", "interacting_pairs: expected >= 0, got -1", "mean_present"),
    ("agents.group_fraction=1.5", "group_fraction: expected in [0, 1], got 1.5", "stop_probability"),
])
def test_a_bad_crowd_setting_is_named_alone(tmp_path, monkeypatch, capsys, setting, named, valid):
    """The crowd plan's checks name the one value that is wrong, not valid ones beside it."""
    code, stderr = _cli(monkeypatch, capsys, "simulate", "crowd", "--set", setting, "-o", str(tmp_path / "out"))
    assert code == 2
    assert named in stderr
    assert valid not in stderr


# 7. a step model fitted from walk totals says why it has no rms ----------------------------------------------
def test_a_step_model_from_walk_totals_says_why_it_has_no_rms():
    walks = [np.full(40, 0.50), np.full(36, 0.60)]
    model = fit_step_model(walks, total_length_m=[40 * 0.65, 36 * 0.74])
    assert np.isnan(model.rms_m)  # per-step errors are not measured from totals
    assert model.rms_text.startswith("rms unknown: fitted from each walk's total length")
    assert "nan" not in model.rms_text
    assert StepLengthModel().rms_text == "rms unknown: not fitted to anybody's steps"


def test_a_step_model_from_step_lengths_on_a_line_reports_zero_rms():
    d = np.linspace(0.4, 0.7, 20)
    model = fit_step_model(d, 0.8 * d + 0.25)  # exactly on a line: no residual
    assert model.rms_text == "rms 0.000 m"


# 8. IMU warnings describe the rule, not a design document ------------------------------------------------------
def test_still_period_warnings_state_the_rule_itself(caplog):
    rng = np.random.default_rng(0)
    t = np.arange(2000, dtype=np.int64) * 10_000_000  # 20 s at 100 Hz
    accel = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.01, (t.size, 3))
    with caplog.at_level(logging.WARNING, logger="fusiontrack"):
        calibrate_imu(t, accel, still=None)
        calibrate_imu(t, accel, still=(int(t[0]), int(t[300])))  # 3 s of the 10 s wanted
    messages = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(messages) == 2
    assert all("ALGORITHMS" not in m and "C1" not in m for m in messages)
    assert "no still period" in messages[0]
    assert ">= 10 s" in messages[0]
    assert "3.0 s" in messages[1]
    assert ">= 10 s" in messages[1]


# 9. the README matches the code ---------------------------------------------------------------------------------
def test_the_readme_names_every_built_in_scenario_and_the_class_column():
    text = README.read_text(encoding="utf-8")
    line = next(x for x in text.splitlines() if x.startswith("fusiontrack scenarios"))
    assert sorted(n.strip() for n in line.split("#", 1)[1].split(",")) == builtin_names()
    assert "class" in TRACKS_CSV_COLUMNS
    assert "`cls` in tracks.csv" not in text


def test_the_readme_cli_reference_lists_every_command_with_options_it_has():
    """The README's CLI reference has a row for every command, and every option it names (in its row, or for track
    in the per-pipeline list) is one of that command's options: nothing missing, nothing invented."""
    import re

    import typer

    from fusiontrack.cli import app

    group = typer.main.get_command(app)
    section = README.read_text(encoding="utf-8").split("## CLI reference", 1)[1].split("\n## ", 1)[0]
    rows = {m.group(1): m.group(2) for m in re.finditer(r"^\| `([a-z-]+)[^`]*` \|(.*)$", section, re.M)}
    assert sorted(rows) == sorted(group.commands)
    rows["track"] += section.split("`track` options by pipeline:", 1)[1]
    for name, text in rows.items():
        params = group.commands[name].params
        known = {o for p in params for o in (*p.opts, *p.secondary_opts)}
        named = set(re.findall(r"(?<![\w-])(--?[a-z][a-z-]*)", text))
        assert named <= known, (name, sorted(named - known))


def test_help_shows_the_pipeline_file_tables_it_names():
    """--help is rendered as rich markup, where [laser] would be a style tag and vanish: the tables a help text
    names are escaped and shown."""
    from typer.testing import CliRunner

    from fusiontrack.cli import app

    def help_of(command: str) -> str:
        result = CliRunner().invoke(app, [command, "--help"], env={"COLUMNS": "300"})
        assert result.exit_code == 0, result.output
        return " ".join(result.output.replace("│", " ").split())

    assert "clock offsets, [laser] and [tracking] parameters" in help_of("track")
    assert "(or [traffic] calibration = FILE in the pipeline file)" in help_of("track")
    assert "laser poses (``[sensors.<name>] pose``) become" in help_of("convert")
