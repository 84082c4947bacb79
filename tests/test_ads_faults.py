"""The reference ADS's hidden faults: silent on the committed seeds, revealed by a situation the fuzzer builds.

``tools/eval_feedback.py --faults`` measures how many executions each search needs to reveal them; these
tests make sure each fault is really there (it fires where the clean ADS does not) and really hidden.
"""

from __future__ import annotations

import pytest

from drivefuzz.ads import load_ads
from drivefuzz.oracle import OracleSettings
from drivefuzz.scenario import Actor, AdsSpec, SimOptions, Weather
from drivefuzz.scenario.sumofiles import read_scenario
from drivefuzz.sim.execute import execute

from conftest import ROOT


def _collisions(sc, fault):
    ex = execute(sc.model_copy(update={"ads": AdsSpec(name="ego", options={"fault": fault})}),
                 oracles=OracleSettings().instantiate())
    return [m for m in ex.misbehaviors if m.oracle == "collision"], ex


def _situation(town_scenario, fault):
    if fault == "no_fog_slowdown":  # highway speeds in fog 100 (15 m of sensor range), a car stopped ahead
        sc = read_scenario(ROOT / "seeds" / "highway" / "004")
        stopped = Actor(id="v0", kind="vehicle", nav="immobile", start_lane=sc.mission.start_lane,
                        start_pos=sc.mission.start_pos + 60.0, speed=0.0)
        return sc.model_copy(update={"actors": (stopped,), "weather": Weather(fog=100.0),
                                     "sim": SimOptions(time_limit=20.0)})
    if fault == "crossing_left_blind":  # town seed 002: a car from the left (C1C0) crosses at B0 as the ego arrives
        sc = read_scenario(ROOT / "seeds" / "town" / "002")
        car = Actor(id="v0", kind="vehicle", nav="autopilot", start_lane="C1C0_1", start_pos=60.6, speed=6.28,
                    dest_edge="B0A0")
        return sc.model_copy(update={"actors": (car,), "sim": SimOptions(time_limit=35.0)})
    if fault == "low_sun_blind":  # highway speeds, a car stopped ahead, the sun low ahead of the ego
        import math

        from drivefuzz.scenario.roadmap import load_roadmap

        sc = read_scenario(ROOT / "seeds" / "highway" / "004")
        pos = sc.mission.start_pos + 95.0
        heading = load_roadmap(sc.network_path()).geom(sc.mission.start_lane).position(pos)[2]
        stopped = Actor(id="v0", kind="vehicle", nav="immobile", start_lane=sc.mission.start_lane, start_pos=pos,
                        speed=0.0)
        sun = Weather(sun_altitude_deg=10.0, sun_azimuth_deg=round((90.0 - math.degrees(heading)) % 360.0, 1))
        return sc.model_copy(update={"actors": (stopped,), "weather": sun, "sim": SimOptions(time_limit=25.0)})
    sc = town_scenario.model_copy(update={"sim": SimOptions(time_limit=25.0)})
    if fault in ("ignore_pedestrians", "right_walker_blind"):  # a walker slowly crossing the ego's street, in the road long before
        actor = Actor(id="p0", kind="pedestrian", nav="linear", start_lane="A0B0_0", start_pos=80.0, speed=0.25,
                      depart=0.0, dest_xy=(88.4, 0.5))
    else:  # a car stopped on the ego's lane
        actor = Actor(id="v0", kind="vehicle", nav="immobile", start_lane="A0B0_1", start_pos=80.0, speed=0.0)
    return sc.model_copy(update={"actors": (actor,)})


#: single-encounter faults (issue 33): each bites in one kind of encounter only
SINGLE = ["right_walker_blind", "crossing_left_blind", "low_sun_blind"]


@pytest.mark.parametrize("fault", ["ignore_pedestrians", "late_braking", "no_fog_slowdown", *SINGLE])
def test_a_hidden_fault_fires_where_the_clean_ads_does_not(town_scenario, fault):
    sc = _situation(town_scenario, fault)
    clean, _ = _collisions(sc, "none")
    assert not clean  # the clean reference ADS stops in time
    faulty, _ = _collisions(sc, fault)
    assert faulty and faulty[0].actors == (sc.actors[0].id,)


@pytest.mark.parametrize("fault", ["ignore_pedestrians", "late_braking", "no_fog_slowdown"])
def test_a_hidden_fault_is_silent_on_the_committed_seeds(fault):
    from drivefuzz.scenario.seed import list_seeds

    for path in list_seeds(ROOT / "seeds" / "town"):
        ex = execute(read_scenario(path).model_copy(update={"ads": AdsSpec(name="ego", options={"fault": fault})}),
                     oracles=OracleSettings().instantiate())
        assert ex.misbehaviors == (), (path.name, ex.misbehaviors)


@pytest.mark.parametrize("fault", SINGLE)
def test_a_single_encounter_fault_is_silent_on_every_committed_seed_of_every_network(fault):
    from drivefuzz.scenario.seed import list_seeds

    for net in ("highway", "interchange", "intersection", "roundabout", "town"):
        for path in list_seeds(ROOT / "seeds" / net):
            ex = execute(read_scenario(path).model_copy(update={"ads": AdsSpec(name="ego", options={"fault": fault})}),
                         oracles=OracleSettings().instantiate())
            assert ex.misbehaviors == (), (net, path.name, ex.misbehaviors)


@pytest.mark.parametrize("fault,other", [("right_walker_blind", "low_sun_blind"),
                                         ("crossing_left_blind", "right_walker_blind"),
                                         ("low_sun_blind", "crossing_left_blind")])
def test_a_single_encounter_fault_does_not_bite_in_another_ones_encounter(town_scenario, fault, other):
    sc = _situation(town_scenario, other)  # where ``other`` collides, ``fault`` drives like the clean ADS
    faulty, _ = _collisions(sc, fault)
    assert not faulty


def test_the_faults_are_options_of_the_reference_ads():
    for fault in ("ignore_pedestrians", "late_braking", "no_fog_slowdown", *SINGLE):
        assert load_ads("ego", {"fault": fault}).options.fault == fault
