"""Kept campaign cases of excuses that the careful driver's replay overturned (issue 31): each is judged as
``tools/rejudge.py --cases`` judges it, in the order before issue 31 (an excusing rule decided ``other`` before any
replay) and in the current one (the excuse is a hypothesis that the careful driver's replay tests), with
``rejudge.judge_case``, so that the test fails on the old order.

The cases of the other excuses that need a replay live in tests/test_attribute.py (stationary_struck,
other_ran_red, other_failed_to_yield, pedestrian).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

from drivefuzz.oracle import OracleSettings
from drivefuzz.scenario import AdsSpec
from drivefuzz.sim.execute import execute
from drivefuzz.triage.attribute import Fault, needs_replay

ROOT = Path(__file__).resolve().parent.parent
DATA = Path(__file__).resolve().parent / "data"


def _rejudge():
    spec = importlib.util.spec_from_file_location("rejudge", ROOT / "tools" / "rejudge.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


rejudge = _rejudge()


def test_held_up_is_kept_without_a_replay_and_says_why(tmp_path):
    """A campaign's incident (reference ADS with its ``narrow_corridor`` fault, 400 executions, maneuver strategy,
    seed 2), kept as data with the three actors that matter (tests/data/held_up_behind_a_leader_it_slowed): the
    faulty ego, which counts a vehicle only with its centre near its path, turns at B2 close behind v3; v3's script
    slows it to 2.67 m/s once the ego follows within 0.8 s, and it crawls at 1.1 m/s for 100 s with the ego behind
    it; the ego times out 31 m short of its goal. The clean ADS (and the careful driver) follow v3 10 m back, never set
    the trigger off, and arrive: a differential event that the held_up excuse files as an incident. The excuse is
    kept without a replay all the same (attribute's docstring): a replay would test v3's script, which the clean
    ADS's ordinary 1.2 s headway sets off as well elsewhere (tests/data/crawling_leader_on_the_ring). Its reason says
    so in words."""
    m, old, new, sc, ex = rejudge.judge_case(DATA / "held_up_behind_a_leader_it_slowed", tmp_path)
    assert (m.oracle, m.kind) == ("mission", "timeout") and sc.ads.options["fault"] == "narrow_corridor"
    assert (old.fault, old.rule) == (new.fault, new.rule) == (Fault.OTHER, "held_up") and new.evidence["leader"] == "v3"
    assert new.reason.endswith("; no replay needed: a leader it cannot pass holds up any driver behind it, a careful "
                               "one too"), new.reason
    assert not needs_replay(new) and "counterfactual" not in new.evidence
    v3 = next(a for a in sc.actors if a.id == "v3")
    assert [(s.trigger.value, s.at, s.value) for s in v3.maneuvers] == [("headway", 0.8, 2.67)]
    clean = execute(sc.model_copy(update={"ads": AdsSpec(name="ego")}), oracles=OracleSettings().instantiate())
    assert not clean.misbehaviors  # the clean reference ADS, farther back, arrives


def test_a_car_that_appears_at_the_egos_rear_and_strikes_it_is_not_the_egos(tmp_path):
    """A campaign's finding (reference ADS with its ``no_fog_slowdown`` fault, highway, 1,000 executions, seed 2),
    kept as data (tests/data/car_appears_at_the_egos_rear): SUMO inserts v1 at 9.2 s on the off-ramp's lane 1, 1 m
    from its start, at 10.9 m/s, just as the ego leaves the junction on lane 0; v1 strikes the ego's rear-left in the
    frame it appears. The verdict was 'the ego struck the vehicle v1 with its rear at 3.9 m/s' (ego, rule struck): no
    excuse applied, since v1 had not moved in the last 2 s (it was not there). Read as not the ADS's fault (the
    clean ADS is struck alike; the careful driver, slower, was elsewhere at 9.2 s): now the rule ``appeared``."""
    m, old, new, _sc, ex = rejudge.judge_case(DATA / "car_appears_at_the_egos_rear", tmp_path)
    assert (m.oracle, m.kind, m.actors) == ("collision", "vehicle", ("v1",))
    for v in (old, new):
        assert v.fault is Fault.OTHER and v.rule == "appeared", v.reason
    assert new.evidence["appeared_frame"] >= m.frame - 1 and new.evidence["contact_side"] == "rear"
    assert new.reason.startswith("the vehicle v1 appeared 2.7 m from the ego (centre to centre) ")
    assert "no replay needed: no driver reacts within" in new.reason and not needs_replay(new)
