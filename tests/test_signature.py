"""Semantic signatures on real SUMO runs: the same situation on two networks has the same
signature; different causes differ even when they involve the same actor ID.

Networks: the town grid (see tests/test_attribute.py), the highway (hw0: three lanes, 120 km/h)
and the four-way intersection (signal C; from the south, SC, green for 0-35 s; from the east, EC,
red then). The B1 approach from the west in the town and the C approach from the south in the
intersection have the same geometry (69 m to the stop line, 5.6 m from the stop line of the
crossing road to the ego's lane centre).
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import pytest

from drivefuzz.scenario import Actor, AdsSpec, Mission, Scenario, SimOptions
from drivefuzz.scenario.roadmap import load_roadmap
from drivefuzz.sim.execute import execute
from drivefuzz.triage.attribute import Attribution, Fault, attribute
from drivefuzz.triage.signature import Signature, signature
from oracles.collision import CollisionOracle
from oracles.immobility import ImmobilityOracle

NETWORKS = Path(__file__).resolve().parent.parent / "networks"


def run(net: str, start_lane, start_pos, goal_edge, goal_pos, *actors, fault="none", time_limit=30.0):
    path = str(NETWORKS / f"{net}.net.xml")
    sc = Scenario(network=path, mission=Mission(start_lane=start_lane, start_pos=start_pos, goal_edge=goal_edge,
                                                goal_pos=goal_pos),
                  sim=SimOptions(time_limit=time_limit), ads=AdsSpec(name="ego", options={"fault": fault}),
                  actors=tuple(actors))
    ex = execute(sc, oracles=[CollisionOracle(), ImmobilityOracle({"threshold": 10.0})])
    assert ex.misbehaviors, "the situation must produce a misbehaviour"
    m = ex.misbehaviors[0]
    rmap = load_roadmap(path)
    att = attribute(sc, ex.trace, m, rmap)
    return m, att, signature(sc, ex.trace, m, rmap, att)


def rear_ended(net, lane, goal_edge, actor_id="v2"):
    rammer = Actor(id=actor_id, kind="vehicle", nav="linear", start_lane=lane, start_pos=5.0, speed=8.0,
                   dest_edge=goal_edge)
    return run(net, lane, 40.0, goal_edge, 40.0, rammer, fault="no_control", time_limit=20.0)


def red_light_runner(net, actor_id="v2"):
    if net == "town":
        runner = Actor(id=actor_id, kind="vehicle", nav="linear", start_lane="B0B1_1", start_pos=27.0, speed=10.0,
                       depart=3.0, dest_edge="B1B2")
        return run(net, "A1B1_1", 40.0, "B1C1", 40.0, runner)
    runner = Actor(id=actor_id, kind="vehicle", nav="linear", start_lane="EC_1", start_pos=68.0, speed=10.0,
                   depart=3.0, dest_edge="CW")
    return run(net, "SC_1", 70.8, "CN", 40.0, runner)


def test_rear_ended_while_stopped_has_one_signature_on_two_networks():
    _, _, town = rear_ended("town", "A0B0_1", "B0C0")
    _, _, highway = rear_ended("highway", "hw0_1", "hw2", actor_id="rammer_17")
    assert town == highway and town.key == highway.key
    assert (town.oracle, town.kind, town.maneuver, town.element) == ("collision", "vehicle", "stationary", "edge/none")
    assert (town.other_kind, town.other_nav, town.approach, town.contact_side, town.fault) == \
        ("vehicle", "linear", "behind", "rear", "other")


def test_red_light_runner_has_one_signature_on_two_networks():
    m1, a1, town = red_light_runner("town")
    m2, a2, cross = red_light_runner("intersection", actor_id="npc3")
    assert a1.fault is a2.fault is Fault.OTHER
    assert town == cross, (town.label, cross.label)
    assert town.element == "junction/traffic_light"
    assert (town.maneuver, town.approach, town.contact_side) == ("straight", "right", "right")


def test_two_causes_with_the_same_actor_id_differ():
    _, _, rear = rear_ended("town", "A0B0_1", "B0C0")
    _, _, runner = red_light_runner("town")
    major = Actor(id="v2", kind="vehicle", nav="linear", start_lane="C0B0_1", start_pos=10.0, depart=5.0, speed=8.0,
                  dest_edge="B0A0")
    m, att, no_yield = run("town", "A0B0_1", 10.0, "B0B1", 40.0, major, time_limit=40.0)
    assert {x.actors for x in (m,)} == {("v2",)}
    keys = {rear.key, runner.key, no_yield.key}
    assert len(keys) == 3
    assert no_yield.fault == "ego" and no_yield.maneuver == "left"
    assert no_yield.element == "junction/yield" and no_yield.approach == "oncoming"


def test_blocked_road_signature_names_the_blocker_not_its_id():
    parked = [Actor(id=f"v{i}", kind="vehicle", nav="immobile", start_lane=lane, start_pos=60.0, speed=0.0)
              for i, lane in enumerate(("A0B0_1", "A0B0_2"))]
    m, att, sig = run("town", "A0B0_1", 10.0, "B0C0", 40.0, *parked, time_limit=40.0)
    assert (sig.oracle, sig.maneuver, sig.other_kind, sig.other_nav, sig.approach, sig.fault) == \
        ("immobility", "stationary", "vehicle", "immobile", "ahead", "other")
    # the lone parked car with a free lane next to it: the same picture, the ego's fault, another signature
    m, att2, sig2 = run("town", "A0B0_1", 10.0, "B0C0", 40.0, parked[0], time_limit=40.0)
    assert sig2.fault == "ego" and sig2.key != sig.key


def test_key_and_label():
    s = Signature("collision", "vehicle", "straight", "junction/yield", "vehicle", "linear", "left", "left", "other")
    assert s.key == Signature(*(getattr(s, f.name) for f in fields(s))).key
    assert len(s.key) == 12 and int(s.key, 16) >= 0
    assert s.key != Signature("collision", "vehicle", "straight", "junction/yield", "vehicle", "linear", "left",
                              "left", "ego").key
    assert "\n" not in s.label and "linear vehicle from left" in s.label
    assert s.as_dict()["key"] == s.key
    # fixed: a key must not change between versions, or stored findings lose their records
    assert s.key == _sha("collision|vehicle|straight|junction/yield|vehicle|linear|left|left|other")


def _sha(text: str) -> str:
    import hashlib

    return hashlib.sha256(text.encode()).hexdigest()[:12]


@pytest.mark.parametrize("oracle, kind", [("speeding", "speeding"), ("lane_invasion", "sidewalk")])
def test_signature_without_another_party(oracle, kind):
    from drivefuzz.oracle import Misbehavior

    path = str(NETWORKS / "town.net.xml")
    sc = Scenario(network=path, mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B0C0", goal_pos=40.0))
    ex = execute(sc)
    m = Misbehavior(oracle, kind, 60, 3.0, (0.0, 0.0))
    sig = signature(sc, ex.trace, m, load_roadmap(path), Attribution(Fault.EGO, "x"))
    assert (sig.other_kind, sig.other_nav, sig.approach, sig.contact_side) == ("none",) * 4
    assert sig.maneuver == "straight" and sig.element == "edge/none"
