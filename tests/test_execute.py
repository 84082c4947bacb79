"""The executor on real SUMO: it drives missions, is deterministic across processes, and the trace is complete."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from drivefuzz.execute import execute
from drivefuzz.oracle import Termination
from drivefuzz.scenario import Actor, Mission, Puddle, Scenario, SimOptions, Weather
from drivefuzz.trace import EGO_FLOAT_FIELDS, Trace

from conftest import NETWORKS, TOWN

MISSIONS = {
    "town": ("A0B0_1", 10.0, "B0C0", 40.0),
    "highway": ("onramp_0", 10.0, "hw2", 60.0),
    "interchange": ("EBentry_0", 10.0, "EB2", 60.0),
    "intersection": ("SC_1", 20.0, "CE", 60.0),
    "roundabout": ("Sin_0", 10.0, "Eout", 40.0),
}


@pytest.mark.parametrize("net", sorted(MISSIONS))
def test_reference_ads_completes_a_mission_on_every_network(net):
    lane, pos, goal, gpos = MISSIONS[net]
    sc = Scenario(network=str(NETWORKS / f"{net}.net.xml"),
                  mission=Mission(start_lane=lane, start_pos=pos, goal_edge=goal, goal_pos=gpos),
                  sim=SimOptions(time_limit=150.0))
    ex = execute(sc)
    assert ex.termination is Termination.GOAL_REACHED, (net, ex.trace["goal_dist"][-1])
    assert ex.trace["goal_dist"][-1] <= 2.0


def _busy(town) -> Scenario:
    return Scenario(
        network=str(TOWN), seed=3,
        mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B1C1", goal_pos=40.0),
        actors=(Actor(id="v0", kind="vehicle", nav="autopilot", start_lane="A0B0_2", start_pos=40, speed=6, dest_edge="B0B1"),
                Actor(id="v1", kind="vehicle", nav="linear", start_lane="B0B1_2", start_pos=30, speed=5, dest_edge="B1B2"),
                Actor(id="p0", kind="pedestrian", nav="autopilot", start_lane="A0B0_0", start_pos=50, speed=1.2, dest_edge="B0B1"),
                Actor(id="p1", kind="pedestrian", nav="linear", start_lane="B0B1_0", start_pos=20, speed=1.2,
                      dest_xy=(town.geom("B0B1_0").position(20)[0] - 12, town.geom("B0B1_0").position(20)[1]))),
        puddles=(Puddle(x=60.0, y=town.geom("A0B0_1").position(60)[1], length=8, width=6, friction=0.3),),
        weather=Weather(rain=30, wind=50, fog=20),
        sim=SimOptions(time_limit=25.0),
    )


def test_trace_records_ego_and_actors(town, tmp_path):
    ex = execute(_busy(town))
    tr = ex.trace
    assert tr.n_frames > 100
    for name in EGO_FLOAT_FIELDS:
        assert len(tr[name]) == tr.n_frames
    assert np.all(np.diff(tr["t"]) > 0)
    assert {"v0", "v1", "p0", "p1"} <= set(tr.actors.ids)
    assert set(tr.actors.kinds) == {"vehicle", "pedestrian"}
    assert tr["mu_front"].min() < 0.5  # the puddle was driven over
    assert np.nanmax(tr["speed"]) > 3.0
    tr.save(tmp_path / "trace")
    back = Trace.load(tmp_path / "trace")
    assert back.n_frames == tr.n_frames
    assert np.array_equal(back["x"], tr["x"]) and np.array_equal(back.actors.x, tr.actors.x)


def test_same_scenario_gives_identical_trace_in_two_processes(town, tmp_path):
    sc = _busy(town)
    a = execute(sc).trace
    b = execute(sc).trace
    for name in EGO_FLOAT_FIELDS:
        assert np.array_equal(a[name], b[name], equal_nan=True), name
    from drivefuzz.sumofiles import write_scenario

    write_scenario(sc, tmp_path / "sc")
    code = ("import sys; from drivefuzz.sumofiles import read_scenario; from drivefuzz.execute import execute; "
            "execute(read_scenario(sys.argv[1])).trace.save(sys.argv[2])")
    subprocess.run([sys.executable, "-c", code, str(tmp_path / "sc"), str(tmp_path / "tr")], check=True, timeout=120)
    c = Trace.load(tmp_path / "tr")
    for name in EGO_FLOAT_FIELDS:
        assert np.array_equal(a[name], c[name], equal_nan=True), name
    assert np.array_equal(a.actors.x, c.actors.x)


def test_sumo_ads_drives_the_ego():
    lane, pos, goal, gpos = MISSIONS["town"]
    sc = Scenario(network=str(TOWN), mission=Mission(start_lane=lane, start_pos=pos, goal_edge=goal, goal_pos=gpos),
                  sim=SimOptions(time_limit=120.0), ads={"name": "sumo"})
    ex = execute(sc)
    assert ex.termination is Termination.GOAL_REACHED
    assert np.nanmax(ex.trace["speed"]) > 5.0
