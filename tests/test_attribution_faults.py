"""The reference ADS's faults of issue 31 (``no_walker_prediction``, ``short_headway``, ``narrow_corridor``), each
biting in its own kind of encounter (a walker crossing, a leader braking to a stop, a car changing into the
ego's lane), silent on the committed seeds. ``tools/eval_attribution.py`` runs campaigns with them to measure
attribution's recall and precision; these tests make sure each fault is there and hidden.

Town facts: streets 30 km/h, driving lanes ``_1`` (right) and ``_2`` (left), sidewalk ``_0``.
"""

from __future__ import annotations

import pytest

from drivefuzz.oracle import OracleSettings
from drivefuzz.scenario import Actor, AdsSpec, Maneuver, Mission, Scenario, SimOptions
from drivefuzz.scenario.sumofiles import read_scenario
from drivefuzz.sim.execute import execute

from conftest import ROOT

NET = str(ROOT / "networks" / "town.net.xml")
NEW_FAULTS = ("no_walker_prediction", "short_headway", "narrow_corridor")


def _situation(fault: str) -> Scenario:
    if fault == "no_walker_prediction":  # a walker crossing A0B0 at 1.6 m/s as the ego comes
        actor = Actor(id="p1", kind="pedestrian", nav="linear", start_lane="A0B0_0", start_pos=60.0, speed=1.6,
                      depart=7.0, dest_xy=(60.0, 7.4))
        goal, limit = ("B0C0", 40.0), 30.0
    elif fault == "short_headway":  # a leader at 7 m/s that stops from 6 s on
        actor = Actor(id="v2", kind="vehicle", nav="maneuver", start_lane="A0B0_1", start_pos=40.0, speed=7.0,
                      dest_edge="B0C0", maneuvers=(Maneuver(time=6.0, action="speed", value=0.0),))
        goal, limit = ("B0C0", 60.0), 40.0
    else:  # a car standing on the left lane 40 m on changes into the ego's lane after 1 s
        actor = Actor(id="v0", kind="vehicle", nav="maneuver", start_lane="A0B0_2", start_pos=40.0, speed=0.0,
                      dest_edge="B0C0", maneuvers=(Maneuver(time=1.0, action="lane_right", value=0.0),))
        goal, limit = ("B0C0", 60.0), 25.0
    return Scenario(network=NET, mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge=goal[0],
                                                 goal_pos=goal[1]),
                    sim=SimOptions(time_limit=limit), actors=(actor,))


def _collisions(sc: Scenario, fault: str):
    ex = execute(sc.model_copy(update={"ads": AdsSpec(name="ego", options={"fault": fault})}),
                 oracles=OracleSettings().instantiate())
    return [m for m in ex.misbehaviors if m.oracle == "collision"]


@pytest.mark.parametrize("fault", NEW_FAULTS)
def test_a_fault_of_issue_31_fires_where_the_clean_ads_does_not(fault):
    sc = _situation(fault)
    assert not _collisions(sc, "none")  # the clean reference ADS keeps clear
    faulty = _collisions(sc, fault)
    assert faulty and faulty[0].actors == (sc.actors[0].id,)


@pytest.mark.parametrize("fault", NEW_FAULTS)
def test_a_fault_of_issue_31_is_silent_on_the_committed_seeds(fault):
    from drivefuzz.scenario.seed import list_seeds

    for path in list_seeds(ROOT / "seeds" / "town"):
        ex = execute(read_scenario(path).model_copy(update={"ads": AdsSpec(name="ego", options={"fault": fault})}),
                     oracles=OracleSettings().instantiate())
        assert ex.misbehaviors == (), (path.name, ex.misbehaviors)
