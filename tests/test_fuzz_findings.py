"""Findings are real: short campaigns on real SUMO find the misbehaviour that is there, and it replays.

- The reference ADS with a fault switched on: the matching oracle fires within a few executions and
  ``drivefuzz replay`` reproduces the finding (exit 0).
- The clean reference ADS hit from the side by a linear vehicle (one that ignores the ego) on a road where
  the ego has the right of way: the collision oracle names that actor, and triage files it as an incident.
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
    # and what triage filed: the fault, its reason and the likely bug
    assert "  fault ego: the ego's own driving: " in out and f"  likely bug: {oracle}/" in out


class _Reckless:
    """A mutator that sends reckless crossers everywhere, also where the ego has the right of way (the real one
    only sends them where the ego must yield to them: elsewhere no driver could avoid them)."""

    def __new__(cls, town):
        from drivefuzz.search.mutate import MutationConfig, Mutator

        class Reckless(Mutator):
            def _conflicts(self, sc):
                return [o[:6] + ("m", "M") for o in super()._conflicts(sc)]

        return Reckless(town, MutationConfig(linear_rear_share=0.0, linear_cross_share=1.0))


def test_reckless_crossers_are_incidents_when_they_run_the_red_and_findings_when_the_ego_must_yield(tmp_path, town):
    """Linear vehicles on other approaches, timed to the junction, run into the clean ADS's side. The collision
    oracle names them; triage files the one that entered on red as an incident (not the ego's fault), and the
    one the ego turned left across without yielding as a finding (the ego's fault: a real bug of the
    reference ADS). A repeat of an event is one more hit of its folder, with no triage reruns."""
    import random

    from drivefuzz.oracle import OracleSettings
    from drivefuzz.scenario import ActorKind
    from drivefuzz.sim.execute import execute
    from drivefuzz.triage.store import FindingStore, TriageConfig

    def run(scenario):
        again = execute(scenario, oracles=OracleSettings().instantiate())
        return tuple(again.misbehaviors), again.trace

    seed = read_scenario(SEED_005)
    mut = _Reckless(town)
    store = FindingStore(tmp_path, town, run, TriageConfig(reproduce=1, reproduce_incidents=False))
    filed = {}
    for k in range(6):
        sc = mut.add_actor(seed, random.Random(k), ActorKind.VEHICLE, NavType.LINEAR).scenario
        ex = execute(sc, oracles=OracleSettings().instantiate())
        (actor,) = sc.actors
        collisions = [m for m in ex.misbehaviors if m.oracle == "collision"]
        if not collisions:  # the timing missed: the ego passed before the crosser came
            continue
        (m,) = collisions
        assert m.actors == (actor.id,)
        # a side impact: the two headings differ by far more than a rear-end's
        assert m.details["relative_speed"] > abs(m.details["other_speed"] - m.details["ego_speed"]) + 0.5
        got = store.triage(sc, list(ex.misbehaviors), ex.trace, f"0/0/0/{k}", ex.termination.value)
        verdict = json.loads((tmp_path / got.rel / "verdict.json").read_text())
        filed.setdefault(got.fault, []).append((got, verdict["attribution"]["reason"]))
    (incident, reason), *_ = filed["other"]
    assert incident.rel.startswith("incidents/") and "on red" in reason
    (finding, reason), *repeats = filed["ego"]
    assert finding.rel.startswith("findings/") and "did not yield" in reason
    assert repeats and all(r.rel == finding.rel and not r.new and r.executions == 0 for r, _ in repeats)
    # the finding was re-run (reproduce=1); the incident was not (reproduce_incidents=False)
    reproduction = {got.fault: json.loads((tmp_path / got.rel / "verdict.json").read_text())["reproduction"]
                    for got in (incident, finding)}
    assert reproduction["other"] is None and reproduction["ego"]["runs"] == 1
    # its one execution is the careful driver's replay that tested the excuse (issue 31), which failed too
    assert incident.executions == 1 and "could not avoid it either" in filed["other"][0][1]


def test_report_all_measures_the_reproduction_of_incidents_too():
    """--report-all counts incidents as findings, so their reproduction rates are measured like the findings';
    without it they are not (their reruns would be executions taken from the search). A manifest from before
    the option resumes as it ran: incidents reproduced."""
    from drivefuzz.campaign.fuzz import FuzzConfig
    from drivefuzz.cli.fuzz import _fuzz_config

    def cfg(**cli):
        return _fuzz_config({}, None, {"budget": None, **cli}, None, (), (), ())

    assert cfg().reproduce_incidents is False
    assert cfg(report_all=True).reproduce_incidents is True
    c = cfg(report_all=True)
    assert FuzzConfig.from_json(json.loads(json.dumps(c.to_json()))).reproduce_incidents is True
    old = FuzzConfig().to_json()
    del old["reproduce_incidents"]
    assert FuzzConfig.from_json(old).reproduce_incidents is True
