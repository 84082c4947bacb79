"""The dry run that admits a seed: the reference ADS drives the mission with every built-in oracle on."""

from __future__ import annotations

from drivefuzz.ads import load_ads
from drivefuzz.oracle import OracleSettings, Termination
from drivefuzz.scenario import Scenario
from drivefuzz.sim.execute import execute


def dry_run(scenario: Scenario) -> tuple[bool, str]:
    """(passed, reason): passed when the reference ADS reaches the goal and no oracle fires."""
    ex = execute(scenario, ads=load_ads("ego"), oracles=OracleSettings().instantiate())
    if ex.misbehaviors:
        m = ex.misbehaviors[0]
        return False, f"{m.oracle}/{m.kind} at frame {m.frame}"
    if ex.termination is not Termination.GOAL_REACHED:
        return False, ex.termination.value
    return True, "goal reached"
