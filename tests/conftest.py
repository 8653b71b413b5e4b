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


@pytest.fixture(scope="session")
def simulated(tmp_path_factory: pytest.TempPathFactory):
    """``simulated(name, seconds=, seed=, settings=)``: the folder of that simulated recording, made once per test
    session and shared by every test that asks for the same scenario, in any module and on any xdist worker (the
    first to ask simulates under a lock, the others wait for it or find it made). Read it, never write into it."""
    import fcntl
    import hashlib
    import json
    import os
    import shutil

    from fusiontrack.sim.scenario import load_scenario
    from fusiontrack.sim.simulator import simulate

    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's folder, above each worker's own
    root = root / "simulated"
    root.mkdir(exist_ok=True)

    def get(name: str, *, seconds: float, seed: int, settings: dict | None = None) -> Path:
        settings = settings or {}
        key = json.dumps([name, seconds, seed, settings], sort_keys=True)
        out = root / f"{name}_{hashlib.sha1(key.encode()).hexdigest()[:12]}"
        done = out.with_name(out.name + ".done")
        with open(out.with_name(out.name + ".lock"), "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not done.exists():
                shutil.rmtree(out, ignore_errors=True)  # a run that failed half-way
                simulate(load_scenario(name).with_overrides(seconds=seconds, seed=seed, settings=settings), out)
                done.write_text(key)
        return out

    return get
