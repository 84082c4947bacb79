"""False alarms the oracles must not raise (issue 12, item 3), each with the twin that must fire.

- One standstill is one finding: immobility owns a standstill away from the goal, the mission
  oracle owns the stop the ADS declares final (``stopped_short``), and neither reports the
  other's, even when the executor goes on after a misbehaviour.
- OSM-imported cities: a walking area laid over a whole junction where a footpath meets a
  street that pedestrians share is not a sidewalk for the cars' lane through it.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

import drivefuzz  # noqa: F401 - sets SUMO_HOME
from drivefuzz.oracle import Frame, RunContext, Termination
from drivefuzz.scenario import AdsSpec, Mission, Scenario, SimOptions
from drivefuzz.scenario.roadmap import load_roadmap
from drivefuzz.sim.execute import execute
from ego.ads import ReferenceADS
from oracles.immobility import ImmobilityOracle
from oracles.lane_invasion import LaneInvasionOracle
from oracles.mission import MissionOracle

TOWN = str(Path(__file__).resolve().parent.parent / "networks" / "town.net.xml")
BERLIN = Path(os.environ["SUMO_HOME"]) / "tools" / "game" / "DRT" / "osm.net.xml"
EGO_L, EGO_W = 4.6, 1.9


def town(time_limit: float, fault: str = "none") -> Scenario:
    return Scenario(network=TOWN, mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B0C0",
                                                  goal_pos=60.0),
                    sim=SimOptions(time_limit=time_limit), ads=AdsSpec(name="ego", options={"fault": fault}))


class ShortStopADS(ReferenceADS):
    """Stops 30 m before the goal and declares the mission done."""

    def reset(self, mission, roadmap):
        super().reset(mission, roadmap)
        self.s_goal -= 30.0


def records(ex) -> list[tuple[str, str]]:
    return [(m.oracle, m.kind) for m in ex.misbehaviors]


# ------------------------------------------------------------------- one standstill, one finding
def test_a_standstill_past_the_immobility_threshold_is_one_immobility_finding():
    # the ego never moves for 75 s; the executor goes on after the first record
    ex = execute(town(75.0, "no_control"), oracles=[ImmobilityOracle(), MissionOracle()], stop_on_misbehavior=False)
    assert ex.termination is Termination.TIME_LIMIT
    assert records(ex) == [("immobility", "immobile")]
    # the twin: with stop_time above the standstill the mission reports the time-out of the same
    # run, so its silence above is the ownership rule, not blindness
    ex = execute(town(75.0, "no_control"), oracles=[MissionOracle({"stop_time": 80.0})], stop_on_misbehavior=False)
    assert records(ex) == [("mission", "timeout")]


def test_a_stop_the_ads_declares_final_is_one_mission_finding():
    ex = execute(town(100.0), ads=ShortStopADS(), oracles=[ImmobilityOracle(), MissionOracle()],
                 stop_on_misbehavior=False)
    assert records(ex) == [("mission", "stopped_short")]
    stopped = ex.trace["speed"] < 0.1
    assert stopped.sum() * ex.trace.step_length > 61.0  # it did stand there past immobility's 60 s


# ------------------------------------------------------------------- OSM maps
def _berlin_frame(offset: float) -> Frame:
    """The ego in the middle of the junction lane :3180391909_0_0 (Berlin), ``offset`` m to its left."""
    (x0, y0), (x1, y1) = (1250.29, 1143.91), (1246.91, 1147.61)
    h = math.atan2(y1 - y0, x1 - x0)
    x, y = 0.5 * (x0 + x1) - offset * math.sin(h), 0.5 * (y0 + y1) + offset * math.cos(h)
    return Frame(x=x, y=y, heading=h, lane=":3180391909_0_0", edge=":3180391909_0", lane_pos=2.5)


@pytest.mark.skipif(not BERLIN.is_file(), reason="SUMO's Berlin OSM network is not installed")
def test_walking_area_over_a_shared_junction_is_not_a_sidewalk_for_the_car_lane():
    # node 3180391909: a footpath meets street 180789857, whose lane pedestrians share; SUMO lays one
    # walking area over the whole junction, across the cars' lane through it
    rmap = load_roadmap(BERLIN)
    o = LaneInvasionOracle({"min_duration": 0.0})  # any touch beyond the tolerance would fire at once
    o.reset(RunContext(None, rmap, ("180789857#3", "180789857#4"), (0.0, 0.0), EGO_L, EGO_W, 0.05))
    assert o.on_frame(_berlin_frame(0.0)) == ()
    # the twin: the same body 2.5 m to the left, off the cars' lane and into the walking area, fires
    f = _berlin_frame(2.5)
    (m,) = o.on_frame(f)
    assert m.kind in ("sidewalk", "off_road")


# ------------------------------------------------------------------- seed time limits
def test_seed_time_limits_let_the_immobility_oracle_fire():
    import json

    from drivefuzz.scenario import seed

    threshold = ImmobilityOracle().config.threshold
    assert seed.IMMOBILITY_S == threshold == MissionOracle().config.stop_time
    floor = threshold + seed.IMMOBILITY_MARGIN_S
    rmap = load_roadmap(TOWN)
    assert seed.time_limit_for(rmap, ("A0B0", "B0C0"), 80.0) == floor  # 46 s by distance alone
    assert seed.time_limit_for(rmap, ("A0B0", "B0B1", "B1C1"), 400.0) > floor  # B1 is signalised
    root = Path(__file__).resolve().parent.parent / "seeds"
    limits = {p.parent.relative_to(root).as_posix(): json.loads(p.read_text())["sim"]["time_limit"]
              for p in root.glob("*/*/scenario.json")}
    assert len(limits) == 44
    assert {k: v for k, v in limits.items() if v < floor} == {}
