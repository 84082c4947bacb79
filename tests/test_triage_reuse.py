"""Triage made cheaper without changing what it decides (issue 33): the shrink judges the time window's cut on the
run a finding was found in, and a candidate it judged before on that earlier run. Both still count against its
budget, so the search and its minimal reproducer are those of running them; only the runs are fewer."""

from __future__ import annotations

import json

from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.oracle import Misbehavior, OracleSettings
from drivefuzz.scenario import Actor, AdsSpec, Mission, Scenario, SimOptions, Weather
from drivefuzz.scenario.roadmap import load_roadmap
from drivefuzz.scenario.sumofiles import load_scenario
from drivefuzz.sim.execute import execute
from drivefuzz.sim.trace import Trace
from drivefuzz.triage.shrink import _cut_window, rules_signature, shrink
from oracles.collision import CollisionOracle

from conftest import TOWN
from test_shrink import _walker_in_the_lane


def _found(sc: Scenario):
    """(scenario, its first misbehaviour, the rules' signature, the run it was found in, run, judge, runs made)."""
    judge = rules_signature(load_roadmap(TOWN))
    calls: list[Scenario] = []

    def run(s):
        calls.append(s)
        ex = execute(s, oracles=[CollisionOracle()])
        return ex.misbehaviors, ex.trace

    found = run(sc)
    m = found[0][0]
    target = judge(sc, m, found[1])
    calls.clear()
    return m, target, found, run, judge, calls


def _walker_without_late_actors() -> Scenario:
    """The walker in the lane of test_shrink, without the car that departs after the collision: the window's cut
    then differs from the scenario only in its time limit."""
    sc = _walker_in_the_lane()
    return sc.model_copy(update={"actors": tuple(a for a in sc.actors if a.depart == 0.0)})


def test_the_window_cut_is_judged_on_the_run_the_finding_came_from():
    sc = _walker_without_late_actors()
    m, target, found, run, judge, calls = _found(sc)
    cut = _cut_window(sc, m)
    assert cut != sc and cut.actors == sc.actors  # only the time limit is cut

    ran = shrink(sc, m, target, run, judge, budget=30)  # the cut is run, as before
    ran_calls = list(calls)
    calls.clear()
    reused = shrink(sc, m, target, run, judge, budget=30, known=found)
    assert cut in ran_calls and cut not in calls
    # the same search, the same minimal reproducer, its own trace; one run fewer
    assert reused.scenario == ran.scenario and reused.misbehavior == ran.misbehavior
    assert (reused.executions, reused.after, reused.signature) == (ran.executions, ran.after, ran.signature)
    assert reused.scenario != cut and [a.id for a in reused.scenario.actors] == ["p0"]
    assert reused.runs == len(calls) == ran.runs - 1 and reused.reused == ran.reused + 1
    assert reused.trace.n_frames == ran.trace.n_frames
    assert reused.trace.meta["scenario_hash"] == reused.scenario.content_hash()
    again, trace = run(reused.scenario)  # it replays the same way
    assert judge(reused.scenario, again[0], trace) == target


def test_a_cut_kept_as_the_result_is_run_for_its_own_trace():
    sc = _walker_without_late_actors()
    m, target, found, run, judge, calls = _found(sc)
    out = shrink(sc, m, target, run, judge, budget=1, known=found)  # only the cut fits the budget
    assert out.scenario == _cut_window(sc, m) and out.executions == 1
    assert calls == [out.scenario] and out.runs == 1 and out.reused == 1
    assert out.trace is not found[1] and out.trace.meta["scenario_hash"] == out.scenario.content_hash()
    assert out.misbehavior.frame == m.frame


def _predicate_case(needed: set[str]):
    """A scenario of four walkers and two weather knobs whose 'run' fails (the same way) when it holds every
    component in ``needed``; the search itself, without SUMO."""
    actors = tuple(Actor(id=f"p{i}", kind="pedestrian", nav="immobile", start_lane="A0B0_0", start_pos=10.0 + 5 * i,
                         speed=0.0) for i in range(4))
    sc = Scenario(network=str(TOWN), ads=AdsSpec(name="ego"),
                  mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B0C0", goal_pos=40.0),
                  actors=actors, weather=Weather(wind=30.0, cloud=40.0), sim=SimOptions(time_limit=60.0))
    m = Misbehavior(oracle="collision", kind="pedestrian", frame=100, time=5.0, position=(0.0, 0.0), actors=("p0",))
    calls: list[Scenario] = []

    def holds(s) -> set[str]:
        return {a.id for a in s.actors} | {k for k in ("wind", "cloud") if getattr(s.weather, k) != 0}

    def run(s):
        calls.append(s)
        return ([m], None) if needed <= holds(s) else ([], None)

    return sc, m, run, calls


def test_a_candidate_judged_before_is_not_run_again_but_still_counts():
    sc, m, run, calls = _predicate_case({"p0", "p1"})
    out = shrink(sc, m, "sig", run, lambda s, mb, trace: "sig", budget=60)
    assert [a.id for a in out.scenario.actors] == ["p0", "p1"] and out.scenario.weather == Weather()
    assert len(calls) == len({c.model_dump_json() for c in calls}) == out.runs  # each candidate run once
    assert out.reused == 2 and out.executions == out.runs + out.reused == 10  # ddmin came back to two of them
    assert out.as_dict()["runs"] == out.runs and out.as_dict()["reused"] == 2


def test_a_cut_that_does_not_fail_when_run_leaves_the_original():
    """If the cut, judged on the original run, did not fail the same way when run (it would take a plugin that
    reads the time limit before the end), the result is the original scenario, which does."""
    sc, m, run_all, calls = _predicate_case({"p0", "p1", "p2", "p3", "wind", "cloud"})

    def run(s):  # fails only with every component and the original time limit
        got = run_all(s)
        return got if s.sim.time_limit == sc.sim.time_limit else ([], None)

    out = shrink(sc, m, "sig", run, lambda s, mb, trace: "sig", budget=60, known=([m], None))
    assert out.scenario == sc and out.misbehavior == m and out.trace is None
    assert calls[-1] == _cut_window(sc, m) and out.runs == len(calls)


def test_a_campaign_finding_shrinks_as_it_would_with_the_cut_run(tmp_path, town_scenario):
    """A real campaign's finding (the speeding fault): the minimal reproducer its triage wrote is the one the
    shrink makes when it runs the window's cut, in as many candidates, with one run fewer unless the cut itself
    is the result."""
    parked = Actor(id="v1", kind="vehicle", nav="immobile", start_lane="C1C2_1", start_pos=40.0, speed=0.0)
    seed = town_scenario.model_copy(update={"sim": SimOptions(time_limit=40.0), "actors": (parked,)})
    cfg = FuzzConfig(cycles=2, population=2, max_execs=4, ads=AdsSpec(name="ego", options={"fault": "speeding"}))
    (found, *_rest) = Campaign(tmp_path / "out", [seed], cfg).run()
    verdict = json.loads((found.path / "verdict.json").read_text())
    sc, trace = load_scenario(found.path), Trace.load(found.path / "trace")
    m = Misbehavior.from_dict(verdict["misbehaviors"][0])
    judge = rules_signature(load_roadmap(sc.network_path()))
    settings = OracleSettings(settings=verdict.get("oracles") or {})

    def run(s):
        ex = execute(s, oracles=settings.instantiate())
        return ex.misbehaviors, ex.trace

    ran = shrink(sc, m, judge(sc, m, trace), run, judge, cfg.shrink)
    kept = verdict["shrink"]
    # the cut was judged on the campaign's run; run once more only when it is the result (for its own trace)
    kept_cut = ran.scenario == _cut_window(sc, m)
    assert not kept_cut  # the parked car is not needed: the search went past the cut
    assert kept["reused"] == ran.reused + 1 and kept["runs"] == ran.runs - (0 if kept_cut else 1)
    assert {k: v for k, v in kept.items() if k not in ("reused", "runs")} == \
        {k: v for k, v in ran.as_dict().items() if k not in ("reused", "runs")}
    assert load_scenario(found.path / "minimal").content_hash() == ran.scenario.content_hash()
