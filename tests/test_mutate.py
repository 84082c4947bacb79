"""Mutation invariants: every draw is a valid scenario that respects the spatial and temporal constraints."""

from __future__ import annotations

import math
import random

import pytest

from drivefuzz.mutate import STRATEGIES, MutationConfig, Mutator
from drivefuzz.scenario import ActorKind, NavType
from drivefuzz.validate import validate


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
