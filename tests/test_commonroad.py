"""The CommonRoad adapter (adapters/commonroad) and TUM's reactive planner behind it, on real SUMO runs.

Skipped, with the reason, where the ``commonroad`` extra is not installed (``pip install -e ".[commonroad]"``;
CI installs it). The planner costs about 100x the reference ADS, so the runs here are short.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("commonroad_rp", reason="the commonroad extra is not installed: pip install -e '.[commonroad]'")

from drivefuzz.ads import EgoState, MissionInfo, Observation, TrafficLightState, load_ads  # noqa: E402
from drivefuzz.oracle import OracleSettings  # noqa: E402
from drivefuzz.scenario.sumofiles import load_scenario  # noqa: E402
from drivefuzz.sim.execute import execute  # noqa: E402

from adapters.commonroad import scene  # noqa: E402
from adapters.commonroad.base import NO_PLAN, PLANNED, RAISED  # noqa: E402
from adapters.commonroad.reactive import ReactivePlannerADS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: a short committed seed the planner drives clean (13 s simulated, about 9 s of wall time)
SHORT_SEED = ROOT / "seeds" / "highway" / "003"


def _obs(x=0.0, v=10.0, light=None) -> Observation:
    ego = EgoState(x, 0.0, 0.0, v, v, 0.0, 0.0, 0.0, 0.0, 4.6, 1.9, 2.8)
    return Observation(0.0, ego, "L_0", 10.0, 13.9, (), light, None)


def _straight():
    return scene.as_path(np.stack([np.arange(0.0, 200.0), np.zeros(200)], axis=1))


# -- the stop-line wall --------------------------------------------------------------------------------------
def test_a_red_light_puts_a_wall_across_the_road_just_past_its_stop_line():
    path = _straight()
    wall = scene.stop_wall(_obs(light=TrafficLightState("J", 0, 30.0, "r")), path, s_front=12.3)
    assert wall is not None
    x, y, h = wall
    assert x == pytest.approx(12.3 + 30.0 + scene.STOP_WALL_HALF_DEPTH) and y == pytest.approx(0.0)
    assert h == pytest.approx(0.0)
    # the wall is a box as wide as the planner's lateral samples and the car: a sample 3 m aside still meets it
    car_beside = scene.pycrcc.RectOBB(2.3, 0.95, 0.0, x, 3.0)
    assert scene.wall_shape(wall).collide(car_beside)
    assert not scene.wall_shape(wall).collide(scene.pycrcc.RectOBB(2.3, 0.95, 0.0, x - 3.5, 0.0))


@pytest.mark.parametrize("state, distance, speed, expected", [
    ("G", 30.0, 10.0, False),  # green: no wall
    ("y", 30.0, 10.0, True),  # yellow with room to stop (10^2 / 8 = 12.5 m < 30 m)
    ("y", 10.0, 10.0, False),  # yellow, too close to stop comfortably: go
    ("r", 10.0, 10.0, True),  # red: always
    ("r", 200.0, 10.0, False),  # too far to matter yet
])
def test_the_wall_follows_the_light_state(state, distance, speed, expected):
    obs = _obs(v=speed, light=TrafficLightState("J", 0, distance, state))
    assert (scene.stop_wall(obs, _straight(), 0.0) is not None) is expected


def test_no_light_no_wall():
    assert scene.stop_wall(_obs(), _straight(), 0.0) is None


# -- the reference path and the road boundary -----------------------------------------------------------------
@pytest.mark.parametrize("seed", ["town/000", "highway/000", "roundabout/000"])
def test_the_reference_path_reaches_well_past_the_goal_and_the_planner_frame_covers_it(seed):
    from commonroad_clcs.config import CLCSParams, ProcessingOption
    from commonroad_rp.utility.utils_coordinate_system import CoordinateSystem
    from drivefuzz.scenario.roadmap import load_roadmap

    sc = load_scenario(ROOT / "seeds" / seed)
    m = sc.mission
    rmap = load_roadmap(sc.network_path())
    edges: list[str] = []
    pts = scene.reference_path(rmap, rmap.route(m.start_edge, m.goal_edge), m.start_lane, m.start_pos,
                               m.goal_edge, m.goal_pos, edges_out=edges)
    path = scene.as_path(pts)
    gx, gy, _ = rmap.geom(rmap.drive_lane(m.goal_edge)).position(m.goal_pos)
    _, s_goal, lat = path.locate(gx, gy, hint=0, window=len(pts))
    assert abs(lat) < 4.0  # the goal is beside the path (on one of the goal edge's lanes)
    assert path.s[-1] - s_goal >= scene.PAST_GOAL - 1.0
    # the planner's own frame (as the adapter builds it, without the shim) reaches past the goal by the
    # longest horizon at town speeds: samples there no longer raise
    co = CoordinateSystem(pts, clcs_params=CLCSParams(processing_option=ProcessingOption.CURVE_SUBDIVISION))
    s_cl, _ = co.convert_to_curvilinear_coords(gx, gy)
    assert co.convert_to_cartesian_coords(s_cl + 60.0, 0.0) is not None
    # and the car at its start lies on the road, clear of the boundary
    x, y, h = rmap.geom(m.start_lane).position(m.start_pos)
    group, n = scene.boundary_group(scene.boundary_segments(rmap, edges), pts)
    assert n > 0
    car = scene.pycrcc.RectOBB(2.3, 0.95, h, x - 2.3 * math.cos(h), y - 2.3 * math.sin(h))
    assert not group.collide(car)


def test_a_bend_tighter_than_the_car_can_turn_is_opened_and_the_straights_stay():
    # a right-angle corner with a 2.5 m radius between two straights, 1 m apart
    arc = [(2.5 * math.sin(a), 2.5 - 2.5 * math.cos(a)) for a in np.linspace(0.0, math.pi / 2, 5)[1:-1]]
    pts = np.vstack([np.stack([np.arange(-30.0, 0.0), np.zeros(30)], axis=1), arc,
                     np.stack([np.full(30, 2.5), np.arange(2.5, 32.5)], axis=1)])
    pts = scene._resample(pts, 1.0)
    k_max = 0.85 * math.tan(0.6) / 2.8
    assert scene.curvature(pts).max() > 1.5 * k_max
    out = scene.limit_curvature(pts, k_max)
    assert scene.curvature(out).max() <= k_max
    from scipy.spatial import cKDTree

    off_road = cKDTree(scene._resample(pts, 0.05)).query(out)[0]
    # an arc of the wider radius would cut the corner by (4.8 - 2.5) (sqrt 2 - 1) = 0.95 m; the local
    # smoothing cuts more (1.7 m on this near-kink; 0.8-1.1 m on the seeds' junction lanes), within bounds
    assert 0.5 < off_road.max() < 2.0
    moved = np.hypot(*(out - pts).T)
    assert moved[:15].max() == 0.0 and moved[-15:].max() == 0.0


def test_the_road_boundary_keeps_the_other_direction_out_and_its_pieces_are_computed_once(town):
    from shapely import Point

    assert scene._parts(town) is scene._parts(town)
    area = scene.road_area(town, ["A0B0"])
    a, b = town.geom(town.drive_lane("A0B0")), town.geom(town.drive_lane("B0A0"))
    assert area.contains(Point(*a.position(a.length / 2)[:2]))
    assert not area.contains(Point(*b.position(b.length / 2)[:2]))


def test_no_boundary_box_reaches_into_the_road_at_a_kerb_the_road_bends_round(town):
    """Each box reaches past its segment's ends only where the road's edge turns left (outside the road): carried on
    straight at a right turn it reached 0.25 m into the road (intersection/002: a car turning right with 0.22 m to
    the kerb met it, the planner returned None and never started again)."""
    from shapely import Polygon

    area = scene.road_area(town, None)
    group, n = scene.boundary_group(scene.boundary_segments(town, None), np.zeros((1, 2)), reach=1e9)
    assert n > 400
    inside = 0.0
    for box in group.unpack():
        (cx, cy), hx, hy, ux, uy = box.center(), box.r_x(), box.r_y(), box.local_x_axis(), box.local_y_axis()
        corners = [(cx + a * hx * ux[0] + b * hy * uy[0], cy + a * hx * ux[1] + b * hy * uy[1])
                   for a, b in ((1, 1), (1, -1), (-1, -1), (-1, 1))]
        inside += Polygon(corners).intersection(area).area
    assert inside < 1e-3  # [m^2] over the whole town (31 m^2 when every box reached past both ends)


# -- the fail-safe ----------------------------------------------------------------------------------------------
class _RaisesAfterOneSecond(ReactivePlannerADS):
    def plan(self, state, checker, desired_speed):
        if self.k * self.mission.step_length >= 1.0:
            raise RuntimeError("planner exploded")
        return super().plan(state, checker, desired_speed)


class _NeverPlans(ReactivePlannerADS):
    def plan(self, state, checker, desired_speed):
        return None


def _short(town_scenario, limit):
    return town_scenario.model_copy(update={"sim": town_scenario.sim.model_copy(update={"time_limit": limit})})


def test_a_planner_that_raises_is_an_ads_failure_the_fail_safe_brakes_and_the_trace_says_so(town_scenario):
    ex = execute(_short(town_scenario, 4.0), ads=_RaisesAfterOneSecond({}), oracles=[])
    info = ex.trace.meta["ads_info"]
    cycles = info["cycles"]
    assert info["counts"][PLANNED] >= 3 and info["counts"][RAISED] >= 5
    first = cycles["outcome"].index(RAISED)
    assert cycles["t"][first] >= 1.0 and "RuntimeError: planner exploded" in cycles["error"][first]
    speed, t = ex.trace["speed"], ex.trace["t"]
    at_raise = speed[np.searchsorted(t, cycles["t"][first])]
    assert at_raise > 1.0  # it had started
    assert speed[-1] < 0.05 and speed[-1] < at_raise  # and then it braked to a stop, and stayed


def test_a_planner_that_returns_nothing_leaves_the_car_braking_at_rest(town_scenario):
    ex = execute(_short(town_scenario, 2.0), ads=_NeverPlans({}), oracles=[])
    info = ex.trace.meta["ads_info"]
    assert set(info["cycles"]["outcome"]) == {NO_PLAN}
    assert float(np.max(ex.trace["speed"])) < 0.05
    assert float(np.max(ex.trace["throttle"])) == 0.0


def test_an_ads_without_a_record_leaves_the_trace_as_it_was(town_scenario):
    ex = execute(_short(town_scenario, 0.5), ads=load_ads("ego"), oracles=[])
    assert "ads_info" not in ex.trace.meta


def test_the_options_are_validated():
    from drivefuzz.errors import InvalidConfig

    with pytest.raises(InvalidConfig, match="replan_period"):
        load_ads("commonroad-reactive", {"replan_period": 0})
    ads = load_ads("commonroad-reactive", {"replan_period": 0.5, "horizon": 2.0})
    assert ads.options.horizon == 2.0


# -- the real planner, end to end ---------------------------------------------------------------------------------
def _trace_cols(trace):
    return {k: np.asarray(trace[k]) for k in ("x", "y", "heading", "speed")}


def test_a_short_seed_drives_clean_and_the_same_in_another_process(tmp_path):
    sc = load_scenario(SHORT_SEED)
    ex = execute(sc, ads=load_ads("commonroad-reactive"), oracles=OracleSettings().instantiate())
    assert ex.termination.value == "goal_reached" and not ex.misbehaviors
    info = ex.trace.meta["ads_info"]
    assert info["counts"][PLANNED] > 0 and info["counts"][RAISED] == 0

    env = dict(os.environ)
    out = tmp_path / "trace"
    cmd = [sys.executable, "-m", "drivefuzz.cli", "run", str(SHORT_SEED), "--ads", "commonroad-reactive",
           "--trace", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=240)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "goal_reached" in proc.stdout
    from drivefuzz.sim.trace import Trace

    other = Trace.load(out)
    assert json.loads((out / "meta.json").read_text())["ads_info"] == json.loads(json.dumps(info))
    mine, theirs = _trace_cols(ex.trace), _trace_cols(other)
    for k in mine:
        np.testing.assert_array_equal(mine[k], theirs[k], err_msg=k)


# -- a route that turns by more than a full circle: the planner gets a moving window ------------------------------
def _loop(turns: float, radius: float = 20.0) -> np.ndarray:
    a = np.arange(0.0, 2.0 * math.pi * turns * radius, 1.0) / radius
    return np.stack([radius * np.sin(a), radius * (1.0 - np.cos(a))], axis=1)


def test_a_route_within_a_turn_goes_whole_and_a_loop_goes_as_a_window_the_frame_accepts():
    from commonroad_clcs.config import CLCSParams, ProcessingOption
    from commonroad_rp.utility.utils_coordinate_system import CoordinateSystem

    from adapters.commonroad.base import WINDOW_BACK, reference_window

    half = _loop(0.5)
    assert reference_window(half, 40) == (0, len(half))
    loop = _loop(1.6)  # a loop ramp's 1.6 turns, 201 m
    params = CLCSParams(processing_option=ProcessingOption.RESAMPLE)
    with pytest.raises(Exception, match="orientation"):  # the planner's frame refuses the whole route
        CoordinateSystem(loop, clcs_params=params)
    for i_car in (0, 60, 150):
        lo, hi = reference_window(loop, i_car)
        # ahead of the car: 60 m or the rest of the route (a 3 s horizon at the loop's 8 m/s is 24 m)
        assert lo == max(i_car - int(WINDOW_BACK), 0) and hi - i_car >= min(60, len(loop) - i_car)
        CoordinateSystem(loop[lo:hi], clcs_params=params)  # and accepts each window


# -- the curvilinear frame: its heading turns as its curvature says ------------------------------------------------
def _mission(seed: str):
    from drivefuzz.scenario.roadmap import load_roadmap

    sc = load_scenario(ROOT / "seeds" / seed)
    m = sc.mission
    rmap = load_roadmap(sc.network_path())
    gx, gy, _ = rmap.geom(rmap.drive_lane(m.goal_edge)).position(m.goal_pos)
    return MissionInfo(m.start_lane, m.start_pos, m.goal_edge, m.goal_pos, (gx, gy),
                       rmap.route(m.start_edge, m.goal_edge), 0.05, sc.seed), rmap


def test_the_frames_heading_turns_as_its_curvature_says_and_the_car_starts_from_rest_in_a_bend():
    """The adapter's mistake 5 (docs/bugs/commonroad-reactive-planner.md): a frame on the resampled polyline turned
    its heading in steps at SUMO's shape vertices (0.25 rad in one metre, 0.03 in the next) while its curvature
    said 0.1-0.17 1/m; the planner's yaw-rate check reads the heading, so in the roundabout's entry bend no
    moving sample passed and the car, once at rest there, never started again. The default frame (the path
    smoothed as CommonRoad's route planner smooths its reference paths) and the planner's own spline preprocessing
    both start it."""
    from commonroad_dc.pycrcc import CollisionChecker

    from adapters.commonroad.base import CarState

    mission, rmap = _mission("roundabout/001")
    # the car at rest in the entry bend (the closed-loop state where limitation 8 was read), the road wheels turned
    at_rest = CarState(-1.8642, 32.2134, -1.6675, 0.0, 0.0, 0.0, -0.0943)
    top, mismatch, off = {}, {}, {}
    for frame in ("resample", "chaikin", "spline"):
        ads = ReactivePlannerADS({"frame": frame})
        ads.reset(mission, rmap)
        co = ads.planner.coordinate_system
        pos, k = np.asarray(co.ref_pos), np.asarray(co.ref_curv)
        turn = np.diff(np.unwrap(np.asarray(co.ref_theta))) / np.diff(pos)
        mismatch[frame] = float(np.max(np.abs(turn - (k[1:] + k[:-1]) / 2.0)))
        # how far the frame strays from the adapter's reference path, start to goal
        off[frame] = max(abs(ads.ref.locate(*co.convert_to_cartesian_coords(s, 0.0), hint=0, window=len(ads.ref.pts))[2])
                         for s in np.arange(31.0, ads.s_goal, 1.0))
        plan = ads.plan(at_rest, CollisionChecker(), desired_speed=3.57)
        top[frame] = None if plan is None else float(np.max(plan.v))
    assert ads.options.frame == "spline" and ReactivePlannerADS({}).options.frame == "chaikin"
    assert mismatch["chaikin"] < 0.04 and mismatch["spline"] < 0.04 and mismatch["resample"] > 0.1  # [1/m]
    assert off["chaikin"] < 0.2 and off["spline"] < 0.7  # [m]
    assert top["chaikin"] > 2.0 and top["spline"] > 2.0  # it starts
    assert top["resample"] == 0.0  # the former frame: the planner's standstill trajectory


def test_at_rest_before_a_bend_the_denser_sampling_levels_are_asked_when_the_first_one_only_stands():
    """Bug 10: plan() stops at the first sampling level whose best sample stands still and returns its standstill
    trajectory; its denser levels hold moving samples (docs/bugs/commonroad_standstill_first_level.py)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("standstill_first_level",
                                                  ROOT / "docs" / "bugs" / "commonroad_standstill_first_level.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    shipped, fixed = mod.standing_then_levels(False), mod.standing_then_levels(True)
    assert shipped[0][1] == 0.0 and shipped[1][1] == 0.0  # plan(), and its first level alone: standing
    assert shipped[2][1] > 1.0  # the next level moves
    assert fixed[0][1] == shipped[2][1]  # level_fix takes the first level that moves


def _bug10_ads(options: dict):
    """Bug 10's planner-alone reproducer (docs/bugs/commonroad_standstill_first_level.py, as a module) and a
    ``commonroad-reactive`` ADS with ``options`` set up at its place (seeds/interchange/001, its left turn's stop line)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("standstill_first_level",
                                                  ROOT / "docs" / "bugs" / "commonroad_standstill_first_level.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod, mod.ads_at_the_stop_line(options)


def test_at_rest_within_reach_of_a_red_lights_wall_the_denser_levels_are_not_walked_and_on_green_they_are():
    """level_fix asks the denser sampling levels only where a moving plan is wanted: not while the car waits within
    WALL_HOLD of a red light's stop line (the first level's standstill is then the answer; walking the levels at
    every waiting cycle took 98 of town/004's 122 s of planner time). The same car on green still moves (bug 10)."""
    from adapters.commonroad.base import WALL_HOLD

    seen = {}
    for light in (TrafficLightState("J", 0, WALL_HOLD - 7.7, "r"), TrafficLightState("J", 0, 2.3, "G")):
        mod, ads = _bug10_ads({"boundary_ends": "every_end"})  # bug 10's state: the first level stands
        rear = mod.AT_REST
        r = ads.params.centre_to_rear_axle
        x, y = rear.x + r * math.cos(rear.heading), rear.y + r * math.sin(rear.heading)
        ego = EgoState(x, y, rear.heading, 0.0, 0.0, 0.0, 0.0, 0.0, rear.steer, 4.6, 1.9, ads.params.wheelbase)
        ads.ref_idx, s_c, _ = ads.ref.locate(x, y, hint=0, window=len(ads.ref_pts))
        ads._cycle(Observation(100.0, ego, "L", 0.0, 13.9, (), light, None), s_c, ads.s_goal - s_c)
        seen[light.state] = (ads.standing_wanted, ads.denser_asked, ads.log["outcome"][-1], ads.log["v_plan_max"][-1],
                             ads.log["v_des"][-1])
    held, asked, outcome, top, v_des = seen["r"]
    assert held and asked == 0 and outcome == PLANNED and top == 0.0 and v_des > 0.05  # waits, one level asked
    held, asked, outcome, top, v_des = seen["G"]
    assert not held and asked >= 1 and outcome == PLANNED and top > 1.0  # moves off: a denser level was asked


def test_when_the_denser_levels_find_nothing_that_moves_they_are_asked_again_only_after_level_retry():
    """A stuck cycle that walks the denser levels costs about 25 first-level plans: after a walk that found nothing
    moving, level_fix waits LEVEL_RETRY seconds (while the car stays at rest) before it walks them again."""
    import commonroad_dc.pycrcc as pycrcc
    from adapters.commonroad.reactive import LEVEL_RETRY

    mod, ads = _bug10_ads({})
    rear = mod.AT_REST
    checker = pycrcc.CollisionChecker()
    checker.add_collision_object(ads.boundary)
    # a wall 12 m wide across the lane 1 m ahead of the front bumper: nothing can move
    front = 2.8 + 0.9 + 1.0 + 0.5
    checker.add_collision_object(pycrcc.RectOBB(0.5, 6.0, rear.heading, rear.x + front * math.cos(rear.heading),
                                                rear.y + front * math.sin(rear.heading)))
    asked = []
    for k in (0, 6, 12, int(round(LEVEL_RETRY / 0.05))):
        ads.k = k
        plan = ads.plan(rear, checker, mod.V_DES)
        assert plan is not None and float(np.max(plan.v)) == 0.0  # it stands
        asked.append(ads.denser_asked)
    assert asked[0] == 2  # the first stuck cycle walks levels 2 and 3
    assert asked[1] == asked[2] == 2  # 0.3 and 0.6 s later: not again
    assert asked[3] == 4  # LEVEL_RETRY later: again


# -- the kept reproducers of docs/bugs/commonroad-reactive-planner.md ----------------------------------------------
BUGS = ROOT / "docs" / "bugs" / "commonroad-reactive-planner"
#: the reproducers that drive 13-23 s before the car stops (30-50 s each on a busy machine)
SLOW_REPLAYS = {"velocity-mode-stale-in-reset", "standstill-fallback-typeerror", "no-start-from-rest-in-bend"}


@pytest.mark.parametrize("folder", [pytest.param(p.name, marks=[pytest.mark.slow] if p.name in SLOW_REPLAYS else [])
                                    for p in sorted(BUGS.iterdir()) if (p / "verdict.json").is_file()])
def test_each_kept_reproducer_replays_to_its_misbehaviour_at_its_frame_with_the_same_planner_cycles(folder):
    from drivefuzz.scenario.sumofiles import read_scenario

    verdict = json.loads((BUGS / folder / "verdict.json").read_text())
    sc = read_scenario(BUGS / folder)
    assert sc.ads.name == "commonroad-reactive"
    ex = execute(sc, oracles=OracleSettings(settings=verdict["oracles"]).instantiate())
    want = verdict["misbehaviors"][0]
    got = ex.misbehaviors[0]
    assert (got.oracle, got.kind, got.frame) == (want["oracle"], want["kind"], want["frame"])
    stored = json.loads((BUGS / folder / "trace" / "meta.json").read_text())["ads_info"]["cycles"]
    now = json.loads(json.dumps(ex.trace.meta["ads_info"]["cycles"]))
    for key in ("t", "outcome", "wall", "v_des"):  # the adapter's decisions and the planner's answers
        assert now[key] == stored[key], key
    # a cycle that raised raised the same error, up to which of the frame's two projection-domain errors the C++
    # frame reports first: that is not stable from run to run (seen in CI and in a group run of these replays:
    # Lateral one time, Longitudinal the other, at the same cycle, with the same misbehaviour at the same frame)
    assert [_domain_error(e) for e in now["error"]] == [_domain_error(e) for e in stored["error"]]


def _domain_error(error: str) -> str:
    """``error`` with the curvilinear frame's two projection-domain errors named as one."""
    for side in ("CurvilinearProjectionDomainLateralError: Lateral", "CurvilinearProjectionDomainLongitudinalError: "
                 "Longitudinal"):
        if error.startswith(side):
            return "CurvilinearProjectionDomainError" + error[len(side):]
    return error
