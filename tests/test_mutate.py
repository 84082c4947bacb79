"""Mutation invariants: every draw is a valid scenario that respects the spatial and temporal constraints."""

from __future__ import annotations

import math
import random

import pytest

from drivefuzz.search.mutate import STRATEGIES, MutationConfig, Mutator
from drivefuzz.scenario import ActorKind, NavType
from drivefuzz.scenario.validate import validate


@pytest.mark.parametrize("strategy", STRATEGIES + ("mix",))
def test_generate_and_mutate_keep_constraints(town, town_scenario, strategy):
    cfg = MutationConfig()
    mut = Mutator(town, cfg)
    rng = random.Random(strategy)
    sc = town_scenario
    kinds_before = {}
    for step in range(8):
        g = mut.generate(sc, strategy, rng)
        assert g.description
        sc = g.scenario
        kinds_before.update({a.id: (a.kind, a.nav) for a in sc.actors})
        m = mut.mutate(sc, rng)
        assert m.description and "weather" in m.description
        sc = m.scenario
        validate(sc, town, source="mutant")
        for a in sc.actors:
            assert kinds_before[a.id] == (a.kind, a.nav)  # mutate never changes type or navigation type
            vmax = cfg.max_pedestrian_speed if a.kind is ActorKind.PEDESTRIAN else cfg.max_vehicle_speed
            assert a.speed <= vmax + 1e-9
        pts = mut._bodies(sc)
        for i in range(len(pts)):
            for j in range(i + 1, len(pts)):
                assert math.dist(pts[i], pts[j]) >= cfg.min_separation - 1e-6
    if strategy == "instability":
        assert sc.puddles and not sc.actors
    if strategy == "congestion":
        assert sc.actors and all(a.nav is NavType.AUTOPILOT for a in sc.actors)
    if strategy == "entropy":
        assert sc.actors and all(a.nav in (NavType.LINEAR, NavType.IMMOBILE) for a in sc.actors)
    if strategy == "maneuver":
        assert sc.actors and all(a.nav is NavType.MANEUVER and a.maneuvers for a in sc.actors)


def test_mutation_is_deterministic(town, town_scenario):
    def chain(seed):
        rng = random.Random(seed)
        mut = Mutator(town)
        sc = town_scenario
        for _ in range(5):
            sc = mut.mutate(mut.generate(sc, "all", rng).scenario, rng).scenario
        return sc

    assert chain(1) == chain(1)
    assert chain(1) != chain(2)


def test_linear_vehicles_are_placed_to_meet_the_ego(town):
    """Entropy's reckless drivers: never behind the ego (unfair), but on another approach to a junction of the
    ego's route where they have the right of way over the ego, within the speed limit and the separation."""
    from conftest import ROOT
    from drivefuzz.scenario.sumofiles import read_scenario

    sc = read_scenario(ROOT / "seeds" / "town" / "005")
    cfg = MutationConfig(linear_rear_share=1.0, linear_cross_share=0.0)
    for k in range(6):  # a reckless car behind the ego cannot be escaped: the fairness rules refuse it
        m = Mutator(town, cfg).add_actor(sc, random.Random(k), ActorKind.VEHICLE, NavType.LINEAR)
        assert not m.scenario.actors and "no feasible" in m.description
    cfg = MutationConfig(linear_rear_share=0.0, linear_cross_share=1.0)
    placed = 0
    for path in sorted((ROOT / "seeds" / "town").glob("*/scenario.json")):
        sc = read_scenario(path.parent)
        mut = Mutator(town, cfg)
        route = mut._route(sc)
        junctions = {town.edge(e).getToNode().getID() for e in route[:-1]}
        for k in range(4):
            m = mut.add_actor(sc, random.Random(k), ActorKind.VEHICLE, NavType.LINEAR)
            if "crosses the ego's path" not in m.description:
                continue
            placed += 1
            (a,) = m.scenario.actors
            assert a.nav is NavType.LINEAR and 0 < a.speed <= town.geom(a.start_lane).speed + 1e-9
            validate(m.scenario, town, source="mutant")
            pts = mut._bodies(m.scenario)
            assert math.dist(pts[0], pts[1]) >= cfg.min_separation - 1e-6
            assert a.start_edge not in route
            passes = {town.edge(e).getToNode().getID() for e in town.route(a.start_edge, a.dest_edge)[:-1]}
            assert passes & junctions  # it drives through a junction the ego drives through
            node = m.description.split(" at ")[-2].split()[-1]
            states = {o[6] for o in mut._conflicts(sc) if o[5] == node and o[7] == "M"}
            assert states & {"m", "s", "w"}  # where the ego must yield
    assert placed


def test_every_kind_of_move_is_named_in_its_description(town, town_scenario):
    """tools/eval_operators.py sorts executions by kind of move from their mutation descriptions: each
    successor's description must name a situation, a targeted aspect or a strategy's component."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "tools" / "eval_operators.py"
    spec = importlib.util.spec_from_file_location("eval_operators", path)
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    mut = Mutator(town)
    sc, kinds = town_scenario, set()
    for k in range(60):
        m = mut.successor(sc, ("all", "entropy", "instability")[k % 3], random.Random(k),
                          hint=sc.actors[0].id if sc.actors else None)
        kind = tool.kind_of(m.description)
        assert kind.split()[0] in ("situation", "target", "add"), (kind, m.description)
        kinds.add(kind.split()[0])
        if k % 4 == 0 and len(m.scenario.actors) < 6:
            sc = m.scenario
    assert kinds == {"situation", "target", "add"}
    assert tool.kind_of("the seed as it is") == ""
