"""Minimal reproducers: delta debugging keeps the signature, removes what the bug does not need, and stays
within its budget; the shrunk finding replays."""

from __future__ import annotations

import json

from click.testing import CliRunner

from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.cli import main
from drivefuzz.scenario import Actor, AdsSpec, Mission, Puddle, Scenario, SimOptions, Weather
from drivefuzz.scenario.roadmap import load_roadmap
from drivefuzz.sim.execute import execute
from drivefuzz.triage.shrink import TAIL_S, rules_signature, shrink
from oracles.collision import CollisionOracle

from conftest import TOWN


def _walker_in_the_lane() -> Scenario:
    """The ``ignore_pedestrians`` fault drives into a slow walker stepping into its lane; three other actors, a
    puddle and two weather knobs have nothing to do with it."""
    return Scenario(
        network=str(TOWN), ads=AdsSpec(name="ego", options={"fault": "ignore_pedestrians"}),
        mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B0C0", goal_pos=40.0),
        actors=(Actor(id="p0", kind="pedestrian", nav="linear", start_lane="A0B0_0", start_pos=60.0, speed=0.3,
                      dest_xy=(68.4, 7.4)),
                Actor(id="v1", kind="vehicle", nav="immobile", start_lane="C1C2_1", start_pos=40.0, speed=0.0),
                Actor(id="v2", kind="vehicle", nav="autopilot", start_lane="D2C2_1", start_pos=20.0, speed=6.0,
                      dest_edge="C2C3"),
                Actor(id="p3", kind="pedestrian", nav="autopilot", start_lane="B1C1_0", start_pos=20.0, speed=1.2,
                      dest_edge="B1C1"),
                Actor(id="v9", kind="vehicle", nav="autopilot", start_lane="A1B1_1", start_pos=5.0, speed=6.0,
                      depart=50.0, dest_edge="B1C1")),
        puddles=(Puddle(x=300.0, y=300.0, length=6.0, width=4.0, friction=0.3),),
        weather=Weather(wind=30.0, cloud=40.0), sim=SimOptions(time_limit=60.0))


def _setup():
    sc = _walker_in_the_lane()
    rmap = load_roadmap(TOWN)
    judge = rules_signature(rmap)
    runs = []

    def run(s):
        runs.append(s)
        ex = execute(s, oracles=[CollisionOracle()])
        return ex.misbehaviors, ex.trace

    misbehaviors, trace = run(sc)
    m = misbehaviors[0]
    assert m.oracle == "collision" and m.actors == ("p0",)
    return sc, m, judge(sc, m, trace), run, judge, runs


def test_shrinking_keeps_the_signature_and_removes_the_rest():
    sc, m, target, run, judge, runs = _setup()
    out = shrink(sc, m, target, run, judge, budget=30)
    assert [a.id for a in out.scenario.actors] == ["p0"]
    assert out.scenario.puddles == () and out.scenario.weather == Weather() and out.after.knobs == 0
    assert out.after.sim_seconds == round(m.time + TAIL_S, 2) < sc.sim.time_limit
    assert (out.before.actors, out.before.puddles, out.before.knobs) == (5, 1, 2)
    assert out.executions == len(runs) - 1 <= 30
    again, trace = run(out.scenario)  # the minimal scenario fails the same way
    assert judge(out.scenario, again[0], trace) == target
    # deterministic
    assert shrink(sc, m, target, run, judge, budget=30).scenario == out.scenario


def test_a_budget_of_one_execution_is_kept():
    sc, m, target, run, judge, runs = _setup()
    out = shrink(sc, m, target, run, judge, budget=1)
    assert out.executions == 1 == len(runs) - 1
    assert len(out.scenario.actors) == 4  # only the time window was cut (v9 departs after the failure)


def test_drivefuzz_shrink_writes_a_replayable_minimal_finding(tmp_path, town_scenario):
    seed = town_scenario.model_copy(update={"sim": SimOptions(time_limit=40.0)})
    cfg = FuzzConfig(cycles=2, population=2, max_execs=4, ads=AdsSpec(name="ego", options={"fault": "speeding"}))
    (found, *_rest) = Campaign(tmp_path / "out", [seed], cfg).run()
    auto = json.loads((found.path / "verdict.json").read_text())["shrink"]  # the campaign shrank it already
    assert auto["executions"] <= cfg.shrink and (found.path / "minimal" / "verdict.json").exists()
    result = CliRunner().invoke(main, ["shrink", str(found.path), "--budget", "12"])
    assert result.exit_code == 0, result.output
    report = json.loads((found.path / "shrink.json").read_text())
    assert report["after"]["actors"] <= report["before"]["actors"] and report["executions"] <= 12
    assert report["after"]["knobs"] == 0  # speeding needs no weather
    result = CliRunner().invoke(main, ["replay", str(found.path / "minimal")])
    assert result.exit_code == 0 and "reproduced: speeding" in result.output, result.output


def test_ddmin_keeps_the_one_puddle_the_failure_needs_whatever_was_removed_before():
    """The search itself, with a predicate for the run: the failure needs the puddle at x = 320 (the third
    of three) and the walker. Removing the first puddles renumbers the rest; candidates are cut from the
    scenario the search started from, so the needed puddle is never lost or swapped."""
    from drivefuzz.oracle import Misbehavior

    sc = _walker_in_the_lane().model_copy(update={"puddles": tuple(
        Puddle(x=300.0 + 10 * i, y=300.0, length=6.0, width=4.0, friction=0.3) for i in range(3))})
    m = Misbehavior(oracle="collision", kind="pedestrian", frame=100, time=5.0, position=(0.0, 0.0), actors=("p0",))

    def run(s):  # fails (the same way) only with the walker and the puddle at x = 320
        fails = any(p.x == 320.0 for p in s.puddles) and any(a.id == "p0" for a in s.actors)
        return ([m], None) if fails else ([], None)

    out = shrink(sc, m, "sig", run, lambda s, mb, trace: "sig", budget=60)
    assert [p.x for p in out.scenario.puddles] == [320.0]
    assert [a.id for a in out.scenario.actors] == ["p0"]
