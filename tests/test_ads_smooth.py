"""The reference ADS drives smoothly, slows down where it cannot see far, and still brakes hard for a
hazard (issue 11, item 1). Real SUMO runs of the committed seeds.

Hard braking is the driving-quality score's ``#hb`` (:func:`drivefuzz.search.quality.score_trace`):
a frame whose body-frame ``ax / g <= -0.6``.
"""

from __future__ import annotations

import numpy as np
import pytest

from drivefuzz.ads import load_ads
from drivefuzz.oracle import OracleSettings, Termination
from drivefuzz.scenario import Actor, Mission, Scenario, SimOptions
from drivefuzz.scenario.seed import list_seeds
from drivefuzz.scenario.sumofiles import load_scenario
from drivefuzz.search.quality import score_trace
from drivefuzz.sim.execute import execute
from ego.ads import ACDA_DECEL, ACDA_MARGIN, ACDA_REACTION
from ego.planning import assured_clear_speed
from ego.sensing import Sensors, SensorSpec

from conftest import ROOT

SEEDS = [p for n in ("town", "highway", "interchange", "intersection", "roundabout")
         for p in list_seeds(ROOT / "seeds" / n)]
#: A seed whose mission is long and fast enough to cruise well above the fog speed.
FOG_SEED = ROOT / "seeds" / "highway" / "004"


def run(sc, oracles=True):
    return execute(sc, ads=load_ads("ego"), oracles=OracleSettings().instantiate() if oracles else ())


def with_weather(sc, **weather):
    return sc.model_copy(update={"weather": sc.weather.model_copy(update=weather)})


def test_every_committed_seed_run_clean_has_no_hard_braking():
    """All 44 seeds in one test (about 10 s): the total is the figure that matters."""
    assert len(SEEDS) == 44
    hard = {}
    for folder in SEEDS:
        ex = run(load_scenario(folder))
        assert ex.termination is Termination.GOAL_REACHED and not ex.misbehaviors, folder
        hb = score_trace(ex.trace).hb
        if hb:
            hard[f"{folder.parent.name}/{folder.name}"] = hb
    assert hard == {}


def test_fog_slows_the_cruise_to_the_assured_clear_distance():
    clear_sc = load_scenario(FOG_SEED)
    clear = run(clear_sc)
    fog = run(with_weather(clear_sc, fog=100.0))
    assert fog.termination is Termination.GOAL_REACHED and not fog.misbehaviors
    assert score_trace(fog.trace).hb == 0
    top_clear, top_fog = float(clear.trace["speed"].max()), float(fog.trace["speed"].max())
    # the fog cap: stopping within the 15 m the sensors reach in fog 100 (less half a car and a gap)
    rng = Sensors(SensorSpec(), 0).effective_range(with_weather(clear_sc, fog=100.0).weather)
    cap = assured_clear_speed(rng - ACDA_MARGIN - 4.6 / 2, ACDA_DECEL, ACDA_REACTION)
    assert 5.0 < cap < 10.0
    assert top_clear > cap + 3.0  # the seed cruises faster than that in clear weather ...
    assert top_fog < cap + 0.3  # ... and no faster than the cap in fog
    assert fog.trace["t"][-1] > clear.trace["t"][-1]


def test_rain_shortens_the_range_and_slows_less_than_fog():
    sc = load_scenario(FOG_SEED)
    tops = {w: float(run(with_weather(sc, **kw)).trace["speed"].max())
            for w, kw in (("clear", {}), ("rain", {"rain": 100.0}), ("fog", {"fog": 100.0}))}
    assert tops["fog"] < tops["rain"] <= tops["clear"] + 1e-6


def _jaywalker_scenario():
    """Town: the ego drives east on A0B0 (street, 30 km/h); at 7 s a pedestrian runs across its lane
    from the sidewalk, about 15 m ahead of it."""
    jay = Actor(id="p1", kind="pedestrian", nav="linear", start_lane="A0B0_0", start_pos=60.0, speed=2.0, depart=7.0,
                dest_xy=(68.4, 7.4))
    return Scenario(network=str(ROOT / "networks" / "town.net.xml"),
                    mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B0C0", goal_pos=40.0),
                    sim=SimOptions(time_limit=40.0), actors=(jay,))


def _stopped_car_in_fog_scenario():
    """Highway seed 004 in fog 100 (15 m of sensor range) with a car stopped in the ego's lane 60 m
    ahead: it comes into sight only 15 m ahead."""
    sc = load_scenario(FOG_SEED)
    stopped = Actor(id="v", kind="vehicle", nav="immobile", start_lane=sc.mission.start_lane,
                    start_pos=sc.mission.start_pos + 60.0, speed=0.0)
    return with_weather(sc.model_copy(update={"actors": (stopped,)}), fog=100.0)


@pytest.mark.parametrize("make", [_jaywalker_scenario, _stopped_car_in_fog_scenario],
                         ids=["jaywalker", "stopped-car-in-fog"])
def test_a_near_hazard_still_brings_hard_braking_and_no_collision(make):
    """The smoothing bounds only the braking for limits, bends and visibility: a pedestrian running
    into the lane, or a stopped car that appears at the edge of the sensor range, still makes the ego
    brake hard (and in time: no collision), and only while the hazard is near."""
    sc = make()
    ex = run(sc)
    assert all(m.oracle != "collision" for m in ex.misbehaviors)
    q = score_trace(ex.trace)
    assert q.md is not None and q.md > 0.5
    assert q.hb > 0
    # every hard-braking frame is one where the hazard is near (centre to centre, in view)
    tr, a = ex.trace, ex.trace.actors
    rows = a.actor == 0
    near = dict(zip(a.frame[rows].tolist(), np.hypot(a.x[rows] - tr["x"][a.frame[rows]],
                                                     a.y[rows] - tr["y"][a.frame[rows]]).tolist()))
    assert all(near.get(f, np.inf) < 20.0 for f in q.frames["hb"]), (q.frames["hb"], near)
