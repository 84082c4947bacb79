"""The 44 committed seeds load, validate, and the reference ADS completes them with no misbehaviour."""

from __future__ import annotations

import pytest

from drivefuzz.sim.execute import execute
from drivefuzz.oracle import OracleSettings, Termination
from drivefuzz.scenario.seed import list_seeds
from drivefuzz.scenario.sumofiles import read_scenario

from conftest import ROOT

SEEDS = list_seeds(ROOT / "seeds" / "town") + [p for n in ("highway", "interchange", "intersection", "roundabout")
                                               for p in list_seeds(ROOT / "seeds" / n)]


def test_forty_four_seeds_are_committed():
    assert len(SEEDS) == 44  # 8 per network, and 4 long highway missions entering at speed (issue 14)


@pytest.mark.parametrize("folder", SEEDS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_seed_validates_and_passes_its_dry_run(folder):
    sc = read_scenario(folder)
    assert not sc.actors and not sc.puddles
    ex = execute(sc, oracles=OracleSettings().instantiate())
    assert ex.misbehaviors == ()
    assert ex.termination is Termination.GOAL_REACHED
