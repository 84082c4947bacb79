"""Shared fixtures: the repository's networks and small scenarios on them (real SUMO, no mocks)."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest

if "DRIVEFUZZ_CACHE" not in os.environ:  # derived network data: not into the user's cache (child processes inherit)
    os.environ["DRIVEFUZZ_CACHE"] = tempfile.mkdtemp(prefix="drivefuzz-test-cache-")
    atexit.register(shutil.rmtree, os.environ["DRIVEFUZZ_CACHE"], True)

ROOT = Path(__file__).resolve().parents[1]
NETWORKS = ROOT / "networks"
TOWN = NETWORKS / "town.net.xml"


@pytest.fixture(scope="session")
def town():
    from drivefuzz.scenario.roadmap import load_roadmap

    return load_roadmap(TOWN)


@pytest.fixture(scope="module")
def town_seeds():
    """The town's committed seed scenarios."""
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario

    return [read_scenario(p) for p in list_seeds(ROOT / "seeds" / "town")]


@pytest.fixture(scope="module")
def highway_seeds():
    """The highway's committed seed scenarios (lanes of 3.5 m)."""
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario

    return [read_scenario(p) for p in list_seeds(ROOT / "seeds" / "highway")]


@pytest.fixture
def town_scenario(town):
    from drivefuzz.scenario import Mission, Scenario, SimOptions

    return Scenario(network=str(TOWN), mission=Mission(start_lane=town.drive_lane("A0B0"), start_pos=10.0,
                                                       goal_edge="B0C0", goal_pos=40.0),
                    sim=SimOptions(time_limit=60.0), seed=7)
