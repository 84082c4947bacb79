"""Shifted traffic-light programs: SUMO runs the shift the files say, triage computes the same states,
and the catalogue's ``light_changes`` makes the ego meet the yellow-to-red change at speed."""

from __future__ import annotations

import random

import libsumo
import pytest

from drivefuzz.scenario import SignalShift
from drivefuzz.scenario.roadmap import load_roadmap
from drivefuzz.scenario.signals import phase_starts, shiftable, signal_state
from drivefuzz.scenario.sumofiles import load_scenario, write_scenario
from drivefuzz.search.catalogue import SITUATIONS, add_situation
from drivefuzz.search.mutate import Mutator
from drivefuzz.sim.execute import execute

from conftest import ROOT, TOWN

SEED = ROOT / "seeds" / "town" / "000"
LIGHT_CHANGES = next(s for s in SITUATIONS if s.name == "light_changes")


def test_sumo_shows_the_states_of_the_shifted_program(tmp_path):
    sc = load_scenario(SEED)
    shifts = {"B1": 17.5, "C2": 3.0}
    sc = sc.model_copy(update={"signals": tuple(SignalShift(tls=t, shift=s) for t, s in shifts.items())})
    write_scenario(sc, tmp_path)
    net = str(sc.network_path())
    libsumo.start(["sumo", "-c", str(tmp_path / "scenario.sumocfg"), "-X", "never", "--no-step-log"])
    try:
        seen = {"B1": set(), "B2": set()}
        for _ in range(2000):  # 100 s: more than a cycle
            libsumo.simulationStep()
            t = libsumo.simulation.getTime()
            for tls in ("B1", "C2", "B2"):
                state = libsumo.trafficlight.getRedYellowGreenState(tls)
                expect = "".join(signal_state(net, tls, i, t, shifts.get(tls, 0.0)) for i in range(len(state)))
                assert state == expect, (t, tls)
                if tls in seen:
                    seen[tls].add((round(t, 2), state))
    finally:
        libsumo.close()
    assert seen["B1"] != seen["B2"]  # B1 and B2 share a program: the shift moved B1's


def test_a_scenario_without_shifts_keeps_its_hash():
    # the hash the seed had before signal shifts existed: corpora and journals of older campaigns stay valid
    assert load_scenario(SEED).content_hash() == "1b0bada6e082aec2"


def test_the_shifted_light_turns_yellow_as_the_ego_approaches():
    sc = load_scenario(SEED)
    mut = Mutator(load_roadmap(sc.network_path()))
    lights = mut._signals_ahead(sc)
    assert lights and lights[0][1] == "C2"
    m = add_situation(mut, sc, LIGHT_CHANGES, random.Random(1))
    (sig,) = m.scenario.signals
    assert "turns yellow" in m.description
    tr = execute(m.scenario).trace
    states, dist, speed = list(tr["tls_state"]), tr["tls_dist"], tr["speed"]
    onset = next(k for k in range(1, len(states)) if states[k] in "yY" and states[k - 1] not in "yY")
    # the ego is a few seconds from the stop line, at speed, when its light turns yellow
    assert 0.0 < dist[onset] < 5.0 * speed[onset] and speed[onset] > 5.0
    prog = shiftable(str(sc.network_path()), sig.tls)
    assert phase_starts(prog, lights[0][2], "yY")


def test_different_draws_shift_differently():
    sc = load_scenario(SEED)
    mut = Mutator(load_roadmap(sc.network_path()))
    shifts = {add_situation(mut, sc, LIGHT_CHANGES, random.Random(k)).scenario.signals[0].shift for k in range(6)}
    assert len(shifts) == 6


@pytest.mark.parametrize("link, chars, expect", [(4, "yY", [40.0]), (0, "yY", [85.0]), (4, "rR", [43.0]), (0, "gG", [45.0])])
def test_phase_starts(link, chars, expect):
    prog = shiftable(str(TOWN), "C2")
    assert phase_starts(prog, link, chars) == expect
