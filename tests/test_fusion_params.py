"""The fused pipeline's options from a pipeline file's ``[fusion]`` table (FusionParams.from_mapping)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import pytest

from fusiontrack.errors import ConfigError
from fusiontrack.fusion import FusionParams


@pytest.mark.parametrize("params", [
    FusionParams(),
    FusionParams(score_map=False, split_identity=True, check_margin=0.4, learn_all_s=1.5, reid_min_alone=None),
    FusionParams(depth_order=False, contact_learn_s=None),
])
def test_a_table_written_from_the_params_reads_back_the_same(params):
    # asdict nests the appearance options (patches, features, boost) as a TOML file would
    assert FusionParams.from_mapping(dataclasses.asdict(params)) == params


def test_false_turns_off_an_option_that_none_turns_off():
    """TOML has no null: ``contact_learn_s = false`` is None (B15's learning as seed 001 words it); ``true`` is
    not a number."""
    assert FusionParams.from_mapping({"contact_learn_s": False}).contact_learn_s is None
    assert FusionParams.from_mapping({"learn_all_s": False}).learn_all_s is None
    with pytest.raises(ConfigError, match="contact_learn_s"):
        FusionParams.from_mapping({"contact_learn_s": True})


def test_nested_appearance_options_reach_the_classifiers():
    p = FusionParams.from_mapping({"appearance": {"n_confusers": 3, "patches": {"size_px": 8},
                                                  "boost": {"n_learners": 12}}})
    assert (p.appearance.n_confusers, p.appearance.patches.size_px, p.appearance.boost.n_learners) == (3, 8, 12)
    assert p.appearance.features == FusionParams().appearance.features  # the rest keeps its defaults


@pytest.mark.parametrize(("table", "named"), [
    ({"scoremap": True}, "scoremap"),  # a typo never passes silently
    ({"score_map": "yes"}, "score_map"),  # a string is not a switch
    ({"check_margin": -1.0}, "check_margin"),
    ({"check_margin": "high"}, "check_margin"),
    ({"check_frames": 0}, "check_frames"),
    ({"check_voters": 3}, "check_voters"),  # a check has two tracks
    ({"check_voters": True}, "check_voters"),
    ({"check_voters": 2.0}, "check_voters"),  # an integer, as check_min_updates
    ({"reid_min": 2.0}, "reid_min"),
    ({"contact_learn_s": 0}, "contact_learn_s"),
    ({"contact_learn_s": True}, "contact_learn_s"),
    ({"depth_order": 1}, "depth_order"),
    ({"appearance": {"depth_margin_m": -0.1}}, "depth_margin_m"),
    ({"appearance": {"depth_margin_m": 0}}, "depth_margin_m"),  # 0: each of two at one depth would be in front
    ({"appearance": {"depth_margin_m": True}}, "depth_margin_m"),
    ({"reid_min_alone": True}, "reid_min_alone"),  # not a confidence of 1
    ({"appearance": 3}, "appearance"),
    ({"appearance": {"patches": {"size_px": 7}}}, "size_px"),
    ({"appearance": {"n_trees": 5}}, "n_trees"),
])
def test_bad_options_are_config_errors_naming_the_file_and_the_key(table, named):
    with pytest.raises(ConfigError, match=rf"site\.toml: fusion.*{named}"):
        FusionParams.from_mapping(table, "site.toml: fusion")


def test_the_track_command_reports_a_bad_fusion_table(shared_data, tmp_path):
    cfg = tmp_path / "site.toml"
    cfg.write_text("[fusion]\ncheck_margin = -0.5\n")
    bag = shared_data / "laser/leg_tracker_demo/training/negative_2.bag"
    result = subprocess.run([sys.executable, "-m", "fusiontrack", "track", str(bag), "--pipeline", "people",
                             "-c", str(cfg), "-o", str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert f"{cfg}: [fusion]" in result.stderr
    assert "check_margin" in result.stderr
    assert not (tmp_path / "out" / "tracks.csv").exists()


def test_appearance_options_given_as_a_plain_dict_are_refused_at_once():
    with pytest.raises(ConfigError, match="appearance"):
        FusionParams(appearance={"map_patches": 150})
