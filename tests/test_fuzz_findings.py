"""Findings are real: short campaigns on real SUMO find the misbehaviour that is there, and it replays.

- The reference ADS with a fault switched on: the matching oracle fires within a few executions and
  ``drivefuzz replay`` reproduces the finding (exit 0).
- The clean reference ADS under the entropy strategy: a linear vehicle (one that ignores the ego) runs
  into it from behind or from the side, the collision oracle names that actor, and the finding replays.
"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from drivefuzz.cli import main
from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.scenario import AdsSpec, NavType
from drivefuzz.scenario.sumofiles import read_scenario

from conftest import ROOT

#: A town seed whose route passes a signalised junction that shows red when the ego arrives.
SEED_005 = ROOT / "seeds" / "town" / "005"


def _replays(finding_dir) -> str:
    result = CliRunner().invoke(main, ["replay", str(finding_dir)])
    assert result.exit_code == 0, result.output
    return result.output


@pytest.mark.parametrize("fault, oracle", [
    ("speeding", "speeding"),
    ("steer_left", "lane_invasion"),
    ("no_traffic_lights", "red_light"),
])
def test_injected_fault_is_found_and_replays(tmp_path, fault, oracle):
    seed = read_scenario(SEED_005)
    cfg = FuzzConfig(cycles=2, population=2, max_execs=4, seed=1, strategy="instability",
                     continue_after_finding=True, ads=AdsSpec(name="ego", options={"fault": fault}))
    findings = Campaign(tmp_path / "out", [seed], cfg).run()
    matching = [f for f in findings if f.misbehavior.oracle == oracle]
    assert matching, [f"{f.misbehavior.oracle}/{f.misbehavior.kind}" for f in findings]
    out = _replays(matching[0].path)
    assert f"reproduced: {oracle}/" in out


def test_clean_ads_is_hit_by_a_linear_vehicle_under_entropy(tmp_path, town_scenario):
    cfg = FuzzConfig(cycles=4, population=2, max_execs=8, seed=4, strategy="entropy", continue_after_finding=True)
    findings = Campaign(tmp_path / "out", [town_scenario], cfg).run()
    collisions = [f for f in findings if f.misbehavior.oracle == "collision" and f.misbehavior.kind == "vehicle"]
    assert collisions, [f"{f.misbehavior.oracle}/{f.misbehavior.kind}" for f in findings]
    f = collisions[0]
    sc = read_scenario(f.path)
    (actor_id,) = f.misbehavior.actors
    actor = next(a for a in sc.actors if a.id == actor_id)
    assert actor.nav is NavType.LINEAR and actor.kind.value == "vehicle"
    verdict = json.loads((f.path / "verdict.json").read_text())
    assert verdict["misbehaviors"][0]["actors"] == [actor_id]
    assert "reproduced: collision/vehicle" in _replays(f.path)


def test_cross_traffic_linear_vehicle_hits_the_ego_from_the_side(town):
    """A linear vehicle on another approach, timed to the junction, runs into the clean ADS's side."""
    import random

    from drivefuzz.sim.execute import execute
    from drivefuzz.search.mutate import MutationConfig, Mutator
    from drivefuzz.oracle import OracleSettings
    from drivefuzz.scenario import ActorKind

    seed = read_scenario(SEED_005)
    mut = Mutator(town, MutationConfig(linear_rear_share=0.0, linear_cross_share=1.0))
    hits = []
    for k in range(4):
        sc = mut.add_actor(seed, random.Random(k), ActorKind.VEHICLE, NavType.LINEAR).scenario
        ex = execute(sc, oracles=OracleSettings().instantiate())
        (actor,) = sc.actors
        hits += [m for m in ex.misbehaviors if m.oracle == "collision" and m.actors == (actor.id,)]
        if hits:
            break
    assert hits
    # a side impact: the two headings differ by far more than a rear-end's
    m = hits[0]
    assert m.details["relative_speed"] > abs(m.details["other_speed"] - m.details["ego_speed"]) + 0.5
