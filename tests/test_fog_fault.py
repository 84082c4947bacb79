"""Where the reference ADS's ``no_fog_slowdown`` fault can bite (issue 31: it gave no differential event in 800
executions on the town). Without its assured-clear-distance cap the ADS keeps its clear-weather speed in fog, but its
obstacle braking (up to full braking, 0.3 s reaction) still stops it for a stationary car once it sees one: the cap
matters only where the sensors' range is shorter than that stopping distance. On the town's avenues (13.9 m/s) that
is fog 100 with some rain, or fog 90 with heavy rain (about 16 m of range); on its streets (8.3 m/s) never; on the
highway (33 m/s) fog 80. Each case: a stationary car ahead in the ego's lane, the clean ADS and the faulty one.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from drivefuzz.oracle import OracleSettings
from drivefuzz.scenario import Actor, AdsSpec, Mission, Scenario, SimOptions, Weather
from drivefuzz.sim.execute import execute

NETS = Path(__file__).resolve().parent.parent / "networks"


def _struck(net: str, lane: str, goal: str, blocker_pos: float, fog: float, rain: float, fault: str) -> bool:
    sc = Scenario(network=str(NETS / f"{net}.net.xml"),
                  mission=Mission(start_lane=lane, start_pos=5.0, goal_edge=goal, goal_pos=40.0),
                  sim=SimOptions(time_limit=20.0), ads=AdsSpec(name="ego", options={"fault": fault}),
                  weather=Weather(fog=fog, rain=rain),
                  actors=(Actor(id="v0", kind="vehicle", nav="immobile", start_lane=lane, start_pos=blocker_pos,
                                speed=0.0),))
    ex = execute(sc, oracles=OracleSettings().instantiate())
    return any(m.oracle == "collision" and m.actors == ("v0",) for m in ex.misbehaviors)


@pytest.mark.parametrize("net, lane, goal, pos, fog, rain, bites", [
    ("town", "A0B0_1", "B0C0", 85.0, 100.0, 100.0, False),  # a street: never
    ("town", "A1B1_1", "B1C1", 85.0, 100.0, 0.0, False),  # an avenue, fog alone (15 m of range): it still stops
    ("town", "A1B1_1", "B1C1", 85.0, 90.0, 75.0, True),  # an avenue, fog and heavy rain (16 m)
    ("highway", "hw0_1", "hw2", 190.0, 60.0, 0.0, False),  # the highway, fog 60 (49 m): it still stops
    ("highway", "hw0_1", "hw2", 190.0, 80.0, 0.0, True),  # the highway, fog 80 (32 m)
])
def test_no_fog_slowdown_bites_only_where_the_range_is_shorter_than_its_stopping_distance(net, lane, goal, pos, fog,
                                                                                          rain, bites):
    assert not _struck(net, lane, goal, pos, fog, rain, "none")  # the clean ADS slows for the fog and stops
    assert _struck(net, lane, goal, pos, fog, rain, "no_fog_slowdown") is bites
