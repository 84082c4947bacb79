"""The executor on real SUMO: it drives missions, is deterministic across processes, and the trace is complete."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from drivefuzz import geometry
from drivefuzz.errors import PluginError
from drivefuzz.sim.execute import execute
from drivefuzz.oracle import Oracle, OracleSettings, Termination
from drivefuzz.scenario import Actor, Mission, Puddle, Scenario, SimOptions, Weather
from drivefuzz.sim.trace import EGO_FLOAT_FIELDS, Trace
from ego.ads import ReferenceADS

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
    from drivefuzz.scenario.sumofiles import write_scenario

    write_scenario(sc, tmp_path / "sc")
    code = ("import sys; from drivefuzz.scenario.sumofiles import read_scenario; from drivefuzz.sim.execute import execute; "
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


# ------------------------------------------------------------------ frame contents
class _FrameLog(Oracle):
    """Keeps a copy of what every frame says about the ego (the executor reuses one Frame)."""

    name = "frame_log"

    def reset(self, ctx):
        super().reset(ctx)
        self.rows = []

    def on_frame(self, frame):
        self.rows.append((frame.x, frame.y, frame.heading, frame.lane, frame.lane_pos, frame.lat_offset,
                          None if frame.corners is None else frame.corners.copy()))
        return ()


def test_frame_lat_offset_is_the_centres_and_corners_are_the_footprint(town):
    # A0B0_1 -> A0B0_2 is a lane change the route needs: the body is at an angle to the lane there
    sc = Scenario(network=str(TOWN), mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B0B1",
                                                     goal_pos=40.0), sim=SimOptions(time_limit=40.0))
    log = _FrameLog()
    ex = execute(sc, oracles=[log])
    L, W = ex.trace.meta["ego_length"], ex.trace.meta["ego_width"]
    checked, lat_seen = 0, []
    for x, y, h, lane, lane_pos, lat, corners in log.rows:
        assert corners is not None and corners.shape == (4, 2)
        np.testing.assert_allclose(corners, geometry.corners(x, y, h, L, W), atol=1e-9)
        if not lane or lane.startswith(":"):
            continue
        g = town.geom(lane)
        if 5.0 < lane_pos - L / 2 < g.length - 5.0:  # the centre is well inside the lane
            assert lat == pytest.approx(g.project(x, y)[1], abs=1e-6)
            checked += 1
            lat_seen.append(lat)
    assert checked > 100
    assert max(lat_seen) > 1.0  # it really changed lanes (the centre crossed towards the left lane)


def test_linear_and_immobile_pedestrians_walk_and_stand_on_their_lanes(town):
    start = town.geom("B0B1_0").position(20.0)
    sc = Scenario(
        network=str(TOWN), seed=5,
        mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B0C0", goal_pos=40.0),
        actors=(Actor(id="walker", kind="pedestrian", nav="linear", start_lane="B0B1_0", start_pos=20.0, speed=1.2,
                      dest_xy=(start[0] - 6.0, start[1])),
                Actor(id="statue", kind="pedestrian", nav="immobile", start_lane="B0B1_0", start_pos=40.0, speed=0.0)),
        sim=SimOptions(time_limit=10.0), ads={"name": "ego", "options": {"fault": "no_control"}})
    ex = execute(sc)
    a, n = ex.trace.actors, ex.trace.n_frames
    walker, statue = a.actor == a.ids.index("walker"), a.actor == a.ids.index("statue")
    assert statue.sum() == n  # the immobile one stays all along
    # the walker walks 6 m at 1.2 m/s (5 s), then leaves at its target instead of standing on the road for ever
    assert 0.9 * 5.0 / sc.sim.step_length < walker.sum() < 1.1 * 5.0 / sc.sim.step_length + 2 < n
    v, x = a.speed[walker], a.x[walker]
    walking = np.flatnonzero(v > 0)
    assert len(walking) > 50
    assert np.allclose(v[walking[0]:walking[-1]], 1.2)  # the recorded speed is its real one
    step = np.abs(np.diff(x))[walking[0]:walking[-1] - 1]
    assert np.allclose(step, 1.2 * sc.sim.step_length, atol=1e-6)
    assert x[-1] == pytest.approx(start[0] - 6.0, abs=0.2)
    # the immobile one stands on its sidewalk (SUMO would put a waiting person ~3 m off it)
    g = town.geom("B0B1_0")
    lats = [abs(g.project(px, py)[1]) for px, py in zip(a.x[statue], a.y[statue])]
    assert max(lats) < g.width / 2
    assert np.all(a.speed[statue] == 0.0)


# ------------------------------------------------------------------ solid lines
@pytest.mark.parametrize("start_lane,goal_edge", [("A1B1_2", "C1C0"), ("A1B1_1", "C1C2"),
                                                  ("D1C1_2", "B1B2"), ("D1C1_1", "B1B0")])
def test_reference_ads_takes_its_lane_before_a_solid_line(start_lane, goal_edge):
    # B1C1 / C1B1 forbid lane changes (changeLeft/Right="authority"); each mission needs the other
    # lane at its end, so the lane must be chosen before entering the avenue
    sc = Scenario(network=str(TOWN), mission=Mission(start_lane=start_lane, start_pos=20.0, goal_edge=goal_edge,
                                                     goal_pos=40.0), sim=SimOptions(time_limit=200.0))
    ex = execute(sc, oracles=OracleSettings().instantiate())
    assert ex.misbehaviors == ()
    assert ex.termination is Termination.GOAL_REACHED
    on_avenue = {str(l) for l in ex.trace["lane"] if str(l).startswith(("B1C1", "C1B1"))}
    assert len(on_avenue) == 1  # one lane all along


def test_lane_plan_respects_forbidden_changes(town):
    from ego.planning import lane_plan

    plan = lane_plan(town, ("A1B1", "B1C1", "C1C0"))  # right turn at C1 from B1C1_1 only
    assert plan[1] == {"B1C1_1"}
    assert plan[0] and all(c[1] == "B1C1_1" for e in plan[0] for c in town.connections("A1B1", "B1C1")
                           if c[0] == e and c[1] in plan[1])


def test_a_start_lane_behind_a_solid_line_takes_another_way(town):
    from ego.planning import lawful_route

    # C1B1 -> B1B0 is a left turn from C1B1_2 only; starting on C1B1_1 the car may not change to it
    planned = town.route("C1B1", "A1B1")
    assert planned[1] == "B1B0"
    assert lawful_route(town, planned, "C1B1_2") == planned
    other = lawful_route(town, planned, "C1B1_1")
    assert other[0] == "C1B1" and other[1] != "B1B0" and other[-1] == "A1B1"
    sc = Scenario(network=str(TOWN), mission=Mission(start_lane="C1B1_1", start_pos=15.0, goal_edge="A1B1",
                                                     goal_pos=30.0), sim=SimOptions(time_limit=240.0))
    ex = execute(sc, oracles=OracleSettings().instantiate())
    assert ex.misbehaviors == ()
    assert ex.termination is Termination.GOAL_REACHED
    assert other[1] in set(ex.trace["edge"])
    assert np.isfinite(ex.trace["tls_dist"][ex.trace["edge"] == other[1]]).any()  # SUMO's route followed it


def test_random_traffic_never_makes_the_reference_ads_cross_a_solid_line(monkeypatch):
    monkeypatch.syspath_prepend(str(TOWN.parents[1] / "tools"))
    from bench_exec import busy_scenario  # the benchmark's random traffic: 25 vehicles, 6 pedestrians

    sc = busy_scenario(n_veh=25, n_ped=6, seed=4)
    sc = sc.model_copy(update={"mission": Mission(start_lane="A1B1_2", start_pos=20.0, goal_edge="C1C0",
                                                  goal_pos=40.0), "sim": SimOptions(time_limit=120.0)})
    ex = execute(sc, oracles=OracleSettings().instantiate(), stop_on_misbehavior=False)
    assert "solid_line" not in [m.kind for m in ex.misbehaviors]
    assert "B1C1_1" in set(ex.trace["lane"])  # it did drive the avenue


# ------------------------------------------------------------------ plugin errors
class _BoomADS(ReferenceADS):
    name = "boom"
    at = 12

    def step(self, obs):
        if round(obs.t / 0.05) == self.at:
            return 1 / 0
        return super().step(obs)


class _BoomOracle(Oracle):
    name = "boom_oracle"
    where = "on_frame"

    def reset(self, ctx):
        super().reset(ctx)
        if self.where == "reset":
            raise KeyError("no such thing")

    def on_frame(self, frame):
        if self.where == "on_frame" and frame.index == 7:
            raise ValueError("bad frame")
        return ()

    def on_end(self, trace, termination):
        if self.where == "on_end":
            raise RuntimeError("bad end")
        return ()


def _short(town_scenario):
    return town_scenario.model_copy(update={"sim": SimOptions(time_limit=3.0)})


def test_an_ads_exception_becomes_a_plugin_error_naming_it(town_scenario):
    with pytest.raises(PluginError) as err:
        execute(_short(town_scenario), ads=_BoomADS())
    msg = str(err.value)
    assert msg.startswith("ADS 'boom' raised ZeroDivisionError at frame 12: ")
    assert isinstance(err.value.__cause__, ZeroDivisionError)


@pytest.mark.parametrize("where,exc,text", [("reset", KeyError, "at reset"),
                                            ("on_frame", ValueError, "at frame 7"),
                                            ("on_end", RuntimeError, "at the end of the run")])
def test_an_oracle_exception_becomes_a_plugin_error_naming_it(town_scenario, where, exc, text):
    oracle = type("Boom", (_BoomOracle,), {"where": where})()
    with pytest.raises(PluginError) as err:
        execute(_short(town_scenario), oracles=[oracle])
    assert str(err.value).startswith(f"oracle 'boom_oracle' raised {exc.__name__} {text}: ")
    assert isinstance(err.value.__cause__, exc)


def test_an_ads_reset_exception_becomes_a_plugin_error(town_scenario):
    class BadReset(ReferenceADS):
        name = "bad_reset"

        def reset(self, mission, roadmap):
            raise AttributeError("nope")

    with pytest.raises(PluginError, match=r"^ADS 'bad_reset' raised AttributeError at reset: nope") as err:
        execute(_short(town_scenario), ads=BadReset())
    assert isinstance(err.value.__cause__, AttributeError)


def test_an_actor_that_cannot_enter_in_time_is_dropped_not_inserted_later(town):
    """A linear car placed 0.7 m ahead of the ego's front could not enter at 0 s; SUMO used to insert it
    once the ego had driven past its spot, 5 m behind the ego at 7.5 m/s: a rear-end no rule had checked
    (a campaign's incident). Now it enters within MAX_DEPART_DELAY or never."""
    from drivefuzz.sim.execute import MAX_DEPART_DELAY

    sc = Scenario(network=str(TOWN), sim=SimOptions(time_limit=15.0),
                  mission=Mission(start_lane="D2C2_1", start_pos=45.9, goal_edge="C3D3", goal_pos=48.6),
                  actors=(Actor(id="v4", kind="vehicle", nav="linear", start_lane="D2C2_1", start_pos=51.6, speed=7.5,
                                dest_edge="C2C3"),
                          Actor(id="v5", kind="vehicle", nav="linear", start_lane="D2C2_2", start_pos=60.0, speed=7.5,
                                dest_edge="C2C3")))
    tr = execute(sc).trace
    a = tr.actors
    first_seen = {a.ids[int(j)]: float(tr["t"][k]) for k in range(tr.n_frames - 1, -1, -1) for j in a.actor[a.rows(k)]}
    assert "v5" in first_seen  # a car with room enters as placed
    assert first_seen.get("v4", 0.0) <= MAX_DEPART_DELAY
