"""Shared fixtures: the real recordings in ../shared/data (see its README)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = (ROOT / ".." / "shared" / "data").resolve()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        raise FileNotFoundError(
            f"the real-data folder {SHARED_DATA} is missing: fusiontrack's tests expect ../shared/data "
            "beside the repository (as in CI)"
        )
    return SHARED_DATA


@pytest.fixture(scope="session")
def outdoor_bag(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The leg_tracker outdoor bag, unzipped once per test session into a temporary folder."""
    zipped = shared_data / "laser" / "leg_tracker_outdoor" / "person_following_outdoor_1.bag.zip"
    out = tmp_path_factory.mktemp("outdoor")
    with zipfile.ZipFile(zipped) as zf:
        zf.extractall(out)
    (bag,) = out.glob("**/*.bag")
    return bag
