"""Scenario -> SUMO files -> Scenario, SUMO loading the files, and validation errors."""

from __future__ import annotations

import subprocess

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import drivefuzz
from drivefuzz.errors import InvalidScenario
from drivefuzz.scenario import (Actor, ActorKind, Maneuver, ManeuverAction, Mission, NavType, Puddle, Scenario,
                                SignalShift, SimOptions, Weather)
from drivefuzz.scenario.sumofiles import read_scenario, write_scenario

from conftest import TOWN

ROAD_LANES = ["A0B0_1", "A0B0_2", "B0B1_1", "B0B1_2", "B1C1_1", "B0C0_1"]
SIDEWALKS = ["A0B0_0", "B0B1_0", "B1C1_0"]
finite = dict(allow_nan=False, allow_infinity=False)


@st.composite
def actors(draw, idx):
    kind = draw(st.sampled_from(list(ActorKind)))
    navs = [NavType.AUTOPILOT, NavType.LINEAR, NavType.IMMOBILE] + ([NavType.MANEUVER] if kind is ActorKind.VEHICLE else [])
    nav = draw(st.sampled_from(navs))
    lane = draw(st.sampled_from(SIDEWALKS if kind is ActorKind.PEDESTRIAN else ROAD_LANES))
    fields = dict(id=f"a{idx}", kind=kind, nav=nav, start_lane=lane,
                  start_pos=draw(st.floats(1.0, 60.0, **finite)), speed=draw(st.floats(0.0, 9.0, **finite)),
                  depart=draw(st.floats(0.0, 5.0, **finite)))
    if kind is ActorKind.PEDESTRIAN and nav is NavType.LINEAR:
        fields["dest_xy"] = (draw(st.floats(-50, 400, **finite)), draw(st.floats(-50, 400, **finite)))
    elif nav is not NavType.IMMOBILE:
        fields["dest_edge"] = lane.rsplit("_", 1)[0]
    if nav is NavType.MANEUVER:
        fields["maneuvers"] = tuple(Maneuver(time=draw(st.floats(0, 10, **finite)),
                                             action=draw(st.sampled_from(list(ManeuverAction))),
                                             value=draw(st.floats(0, 5, **finite))) for _ in range(draw(st.integers(0, 3))))
    return Actor(**fields)


@st.composite
def scenarios(draw):
    n = draw(st.integers(0, 4))
    acts = tuple(draw(actors(i)) for i in range(n))
    puddles = tuple(Puddle(x=draw(st.floats(0, 300, **finite)), y=draw(st.floats(0, 300, **finite)),
                           length=draw(st.floats(0.5, 20, **finite)), width=draw(st.floats(0.5, 10, **finite)),
                           rotation=draw(st.floats(-3.14, 3.14, **finite)), friction=draw(st.floats(0.01, 2.0, **finite)))
                    for _ in range(draw(st.integers(0, 2))))
    weather = Weather(**{k: draw(st.floats(0, 100, **finite)) for k in ("cloud", "rain", "wind", "fog", "wetness", "puddle_density")},
                      sun_azimuth_deg=draw(st.floats(0, 360, **finite)), sun_altitude_deg=draw(st.floats(-90, 90, **finite)))
    lights = draw(st.lists(st.sampled_from(["B1", "B2", "C1", "C2"]), unique=True, max_size=2))
    signals = tuple(SignalShift(tls=t, shift=draw(st.floats(0, 90, **finite))) for t in lights)
    return Scenario(network=str(TOWN), signals=signals,
                    mission=Mission(start_lane="A0B0_1", start_pos=draw(st.floats(0, 50, **finite)),
                                                       goal_edge="B1C1", goal_pos=draw(st.floats(0, 100, **finite)),
                                                       start_speed=draw(st.floats(0, 10, **finite))),
                    actors=acts, puddles=puddles, weather=weather, seed=draw(st.integers(0, 2**31)),
                    sim=SimOptions(step_length=draw(st.sampled_from([0.05, 0.1])), time_limit=draw(st.floats(1, 300, **finite))))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sc=scenarios())
def test_round_trip_is_lossless(sc, tmp_path_factory):
    folder = tmp_path_factory.mktemp("sc")
    write_scenario(sc, folder)
    back = read_scenario(folder)
    assert back == sc
    assert back.content_hash() == sc.content_hash()


def test_sumo_loads_the_files_without_warnings(tmp_path):
    sc = Scenario(network=str(TOWN), mission=Mission(start_lane="A0B0_1", start_pos=10, goal_edge="B1C1", goal_pos=30),
                  actors=(Actor(id="v", kind="vehicle", nav="linear", start_lane="A0B0_2", start_pos=40, speed=5, dest_edge="B0B1"),
                          Actor(id="i", kind="vehicle", nav="immobile", start_lane="B0B1_1", start_pos=30, speed=0),
                          Actor(id="p", kind="pedestrian", nav="autopilot", start_lane="A0B0_0", start_pos=20, speed=1, dest_edge="B0B1"),
                          Actor(id="j", kind="pedestrian", nav="linear", start_lane="B0B1_0", start_pos=20, speed=1, dest_xy=(10, 10))),
                  puddles=(Puddle(x=60, y=0, length=10, width=8, friction=0.3),),
                  signals=(SignalShift(tls="B1", shift=12.5),))
    write_scenario(sc, tmp_path)
    proc = subprocess.run([drivefuzz.sumo_binary("sumo"), "-X", "never", "-c", str(tmp_path / "scenario.sumocfg"),
                           "--end", "5", "--no-step-log"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "Warning" not in proc.stderr and "Error" not in proc.stderr, proc.stderr
    add = (tmp_path / "fuzz.add.xml").read_text()
    assert 'type="drivefuzz.puddle"' in add and "friction=" in add
    routes = (tmp_path / "routes.rou.xml").read_text()
    departs = [float(x.split('"')[1]) for x in routes.split("depart=")[1:]]
    assert departs == sorted(departs)


@pytest.mark.parametrize("change, field", [
    (dict(mission=Mission(start_lane="NOPE_1", start_pos=1, goal_edge="B1C1", goal_pos=1)), "mission.start_lane"),
    (dict(mission=Mission(start_lane="A0B0_1", start_pos=1, goal_edge="NOPE", goal_pos=1)), "mission.goal_edge"),
    (dict(mission=Mission(start_lane="A0B0_1", start_pos=9999, goal_edge="B1C1", goal_pos=1)), "mission.start_pos"),
    (dict(mission=Mission(start_lane="A0B0_0", start_pos=1, goal_edge="B1C1", goal_pos=1)), "mission.start_lane"),
    (dict(actors=(Actor(id="v", kind="vehicle", nav="immobile", start_lane="A0B0_0", start_pos=5, speed=0),)), "actors[0](v).start_lane"),
    (dict(actors=(Actor(id="p", kind="pedestrian", nav="immobile", start_lane="A0B0_1", start_pos=5, speed=0),)), "actors[0](p).start_lane"),
    (dict(signals=(SignalShift(tls="NOPE", shift=3.0),)), "signals[0].tls"),
])
def test_invalid_scenarios_name_file_and_field(tmp_path, town_scenario, change, field):
    sc = town_scenario.model_copy(update=change)
    with pytest.raises(InvalidScenario) as err:
        write_scenario(sc, tmp_path)
    assert field in str(err.value)
    assert "scenario.json" in str(err.value)


def test_model_rejects_bad_values():
    with pytest.raises(ValueError, match="friction"):
        Puddle(x=0, y=0, length=1, width=1, friction=2.5)
    with pytest.raises(ValueError):
        Puddle(x=0, y=0, length=-1, width=1, friction=0.5)
    with pytest.raises(ValueError):
        Puddle(x=0, y=0, length=1, width=1, friction=0.0)
