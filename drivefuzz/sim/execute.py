"""The test executor: runs one Scenario through SUMO with an ADS driving drivefuzz's car.

This is the only module that imports libsumo (or traci, for ``--gui``).

Setup: the scenario's SUMO files are written to a work folder and SUMO starts on
them with ``-X never`` (friction steps are not in the XSD), no teleports, and
collision warnings. Every actor departs from the loaded files; the first step
inserts them and the ego together, and only then do actor behaviours and the
ADS start ("no abrupt creation"). The ADS is reset with the mission and the
road map, and the physics takes the ego over from where SUMO inserted it.

Every step, in this fixed order (frame k is the world after SUMO step k)::

    1. read the world: ego lane/edge/speed limit/next light, every actor's pose
    2. record frame k (ego state from the physics + world)
    3. run the oracles on frame k
    4. check termination: an oracle fired, goal reached, time limit, ego lost
    5. build the ADS's Observation (ground truth within the sensor horizon + weather)
    6. ADS.step(observation) -> Control
    7. the physics integrates the Control, with the friction under each axle and wind
    8. place the ego in SUMO with moveToXY (keepRoute=2) and keep its route current
    9. apply per-step actor commands (linear, maneuver schedules, jaywalking)
   10. step SUMO

The ego is a SUMO vehicle with speed mode 0 and lane-change mode 0 that is
moved every step, so other traffic sees and yields to it; SUMO's own collision
detection is only a cross-check (it misses lateral and off-lane contact).
Linear and immobile pedestrians are placed by the executor (``person.moveToXY``)
every step; their recorded speed is the walked one. An exception in plugin code
(ADS or oracle) leaves :func:`execute` as a :class:`~drivefuzz.errors.PluginError`
naming the plugin. ``Execution.timings``: seconds per stage, ``setup``, ``sumo``
(steps 9-10), ``world`` (1), ``record`` (2), ``oracles`` (3), ``observe`` (5),
``ads`` (6), ``physics`` (7-8); ``tools/bench_exec.py`` prints them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import random
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from itertools import chain
from pathlib import Path
from typing import Sequence

import numpy as np

import drivefuzz
from drivefuzz.ads import ADS, EgoState, MissionInfo, Observation, TrafficLightState, load_ads
from drivefuzz.errors import PluginError, SimulationError
from drivefuzz.oracle import Frame, LaneLink, Misbehavior, Oracle, RunContext, Termination
from drivefuzz.sim.physics import VehicleParams, VehiclePhysics, place_state
from drivefuzz.scenario.roadmap import load_roadmap
from drivefuzz.scenario import Scenario
from drivefuzz.scenario.sumofiles import ADDITIONAL, EGO_ID, ROUTES, write_scenario
from drivefuzz.sim.trace import Recorder, Trace
from drivefuzz.sim.world import (
    ActorDriver,
    Actors,
    Puddles,
    static_obstacles,
    sun_glare,
    surface_friction,
    tls_link_table,
)

#: Distance [m] from the ego centre to the goal point that counts as arrived (the paper's 2 m).
GOAL_RADIUS = 2.0
#: Speed [m/s] below which an ego at the goal counts as stopped there.
GOAL_STOP_SPEED = 0.5


@dataclass(frozen=True)
class Execution:
    """The outcome of one execution."""

    scenario: Scenario
    trace: Trace
    termination: Termination
    misbehaviors: tuple[Misbehavior, ...]
    wall_time: float  # [s]
    timings: dict[str, float] = field(default_factory=dict)  # [s] per stage

    @property
    def failed(self) -> bool:
        return bool(self.misbehaviors)


def _sumo_args(scenario: Scenario, folder: Path, net: Path, gui: bool) -> list[str]:
    binary = drivefuzz.sumo_binary("sumo-gui" if gui else "sumo")
    args = [
        binary, "-X", "never",
        "-n", str(net), "-r", str(folder / ROUTES), "-a", str(folder / ADDITIONAL),
        "--step-length", repr(scenario.sim.step_length),
        "--seed", str(scenario.seed % 2**31),
        "--time-to-teleport", "-1",
        "--collision.action", "warn", "--collision.check-junctions", "true", "--collision.mingap-factor", "0",
        "--pedestrian.model", "striping",
        "--pedestrian.striping.jamtime", "-1", "--pedestrian.striping.jamtime.crossing", "-1",
        "--default.speeddev", "0",
        "--no-step-log", "true", "--no-warnings", "true", "--duration-log.disable", "true",
        "--end", repr(scenario.sim.time_limit + 10.0),
    ]
    if gui:
        args += ["--start", "--quit-on-end", "--delay", "50"]
    return args


def execute(
    scenario: Scenario,
    *,
    ads: ADS | None = None,
    oracles: Sequence[Oracle] = (),
    gui: bool = False,
    stop_on_misbehavior: bool = True,
    workdir: str | os.PathLike | None = None,
    vehicle: VehicleParams | None = None,
) -> Execution:
    """Run ``scenario`` once and return its :class:`Execution`.

    ``ads`` defaults to the scenario's ADS plugin. ``workdir`` keeps the SUMO
    files (a temporary folder otherwise).
    """
    wall0 = time.perf_counter()
    params = vehicle or VehicleParams()
    ads = ads if ads is not None else load_ads(scenario.ads.name, scenario.ads.options)
    net = scenario.network_path().resolve()
    rmap = load_roadmap(net)
    tmp = None
    if workdir is None:
        tmp = tempfile.mkdtemp(prefix="drivefuzz-run-")
        folder = Path(tmp)
    else:
        folder = Path(workdir)
    try:
        write_scenario(scenario, folder, durable=False)
        if gui:
            import traci as sim  # the GUI needs a traci connection; same API as libsumo
        else:
            import libsumo as sim
        try:
            sim.start(_sumo_args(scenario, folder, net, gui))
        except Exception as exc:  # TraCIException cannot be pickled: re-raise plainly
            raise SimulationError(f"SUMO failed to start on {folder}: {type(exc).__name__}: {exc}") from None
        try:
            result = _run(sim, scenario, rmap, ads, list(oracles), params, stop_on_misbehavior, wall0)
        finally:
            try:
                sim.close()
            except Exception:  # noqa: BLE001 - closing a dead connection must not hide the real error
                pass
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return dataclasses.replace(result, wall_time=time.perf_counter() - wall0)


def _plugin_error(what: str, name: str, exc: BaseException, where: str) -> PluginError:
    """A plugin's own exception as a PluginError that names the plugin (raise it ``from exc``)."""
    return PluginError(f"{what} {name!r} raised {type(exc).__name__} {where}: {exc}")


@contextlib.contextmanager
def _blame(what: str, name: str, where: str):
    """:func:`_plugin_error` around a block (the per-frame calls use try/except: it is cheaper)."""
    try:
        yield
    except Exception as exc:
        raise _plugin_error(what, name, exc, where) from exc


def _run(sim, scenario: Scenario, rmap, ads: ADS, oracles: list[Oracle], params: VehicleParams,
         stop_on_misbehavior: bool, wall0: float) -> Execution:
    dt = scenario.sim.step_length
    mission = scenario.mission
    planned = rmap.route(mission.start_edge, mission.goal_edge)
    route = list(planned)  # SUMO's route for the ego, kept current from the edge it is on
    gx, gy, _ = rmap.geom(rmap.drive_lane(mission.goal_edge)).position(mission.goal_pos)
    # the goal is reached on any passenger lane of the goal edge
    goal_pts = [rmap.geom(l.getID()).position(mission.goal_pos)[:2]
                for l in rmap.edge(mission.goal_edge).getLanes() if l.allows("passenger")]
    half_len, half_wid = params.length / 2.0, params.width / 2.0
    to_front_axle, to_rear_axle = params.centre_to_front_axle, params.centre_to_rear_axle
    rng = random.Random(scenario.seed)
    weather = scenario.weather
    timings = dict.fromkeys(("setup", "sumo", "world", "record", "oracles", "observe", "ads", "physics"), 0.0)
    perf = time.perf_counter
    ads_name = ads.name or type(ads).__name__
    oracle_names = [o.name or type(o).__name__ for o in oracles]

    # -- setup: insert everything, then take the ego over ---------------------------------
    t0 = perf()
    for _ in range(int(round(1.0 / dt)) + 1):
        sim.simulationStep()
        if EGO_ID in sim.vehicle.getIDList():
            break
    else:
        raise SimulationError(f"SUMO could not insert the ego on {mission.start_lane} at {mission.start_pos} m "
                              "(blocked by an actor?)")
    timings["sumo"] += perf() - t0
    driver = ActorDriver(sim, scenario, rmap)  # starts the actors' behaviours in the first frame
    if ads.sumo_driven:
        # SUMO drives: hold the ego at the goal instead of letting it arrive and vanish.
        goal_len = rmap.edge(mission.goal_edge).getLength()
        sim.vehicle.setStop(EGO_ID, mission.goal_edge, pos=min(mission.goal_pos + params.length / 2, goal_len),
                            laneIndex=rmap.lane(rmap.drive_lane(mission.goal_edge)).getIndex(), duration=1e6)
        with _blame("ADS", ads_name, "at reset"):
            settings = ads.vtype_settings()
        for key, value in settings.items():  # e.g. accel -> vehicle.setAccel
            getattr(sim.vehicle, "set" + key[0].upper() + key[1:])(EGO_ID, value)
    else:
        sim.vehicle.setSpeedMode(EGO_ID, 0)
        sim.vehicle.setLaneChangeMode(EGO_ID, 0)
    fx, fy = sim.vehicle.getPosition(EGO_ID)
    heading = math.radians(90.0 - sim.vehicle.getAngle(EGO_ID))
    cx, cy = fx - half_len * math.cos(heading), fy - half_len * math.sin(heading)
    physics = VehiclePhysics(params, place_state(cx, cy, heading, mission.start_speed, params))
    with _blame("ADS", ads_name, "at reset"):
        ads.reset(MissionInfo(mission.start_lane, mission.start_pos, mission.goal_edge, mission.goal_pos, (gx, gy),
                              planned, dt, scenario.seed), rmap)
    ctx = RunContext(scenario, rmap, planned, (gx, gy), params.length, params.width, dt,
                     static_obstacles(sim))
    for oracle, name in zip(oracles, oracle_names):
        with _blame("oracle", name, "at reset"):
            oracle.reset(ctx)
    tls_links = tls_link_table(sim)
    puddles = Puddles(scenario.puddles)
    mu_surface = surface_friction(weather)
    wind_amp = 0.5 * 1.2 * 0.9 * (params.length * 1.5) * (15.0 * weather.wind / 100.0) ** 2  # [N]
    wind_phase = rng.uniform(0.0, 2.0 * math.pi)
    speed_limits: dict[str, float] = {}
    links_seen: dict[tuple, tuple[LaneLink, ...]] = {}
    recorder = Recorder(int(scenario.sim.time_limit / dt) + 8)
    actors = Actors(sim, recorder, driver)
    frame = Frame()
    prev_front = (fx, fy)
    misbehaviors: list[Misbehavior] = []
    termination = Termination.TIME_LIMIT
    last_edge = ""
    steer = throttle = brake = 0.0
    time_limit = scenario.sim.time_limit
    start_t = sim.simulation.getTime()
    route_index = {e: i for i, e in reversed(list(enumerate(route)))}
    v_get = sim.vehicle
    timings["setup"] = perf() - wall0 - timings["sumo"]

    while True:
        # 1. read the world --------------------------------------------------------------
        t1 = perf()
        t = sim.simulation.getTime() - start_t
        vids = v_get.getIDList()
        try:
            k_ego = vids.index(EGO_ID)
        except ValueError:
            termination = Termination.EGO_LOST
            break
        others = vids[:k_ego] + vids[k_ego + 1:]
        pids = sim.person.getIDList()
        if (others, pids) != actors.key:  # someone departed or arrived: start what departed
            for aid in chain(others, pids):
                driver.on_depart(aid, t)
        if ads.sumo_driven:
            fx, fy = v_get.getPosition(EGO_ID)
            h = math.radians(90.0 - v_get.getAngle(EGO_ID))
            v = v_get.getSpeed(EGO_ID)
            st = physics.state
            yaw_rate = ((h - st.heading + math.pi) % (2 * math.pi) - math.pi) / dt
            ax = (v - st.vx) / dt
            st.x, st.y = fx - half_len * math.cos(h), fy - half_len * math.sin(h)
            st.heading, st.vx, st.vy, st.yaw_rate, st.ax, st.ay = h, v, 0.0, yaw_rate, ax, v * yaw_rate
        state = physics.state
        ex, ey = state.x, state.y
        ch, sh = math.cos(state.heading), math.sin(state.heading)
        front = (ex + half_len * ch, ey + half_len * sh)
        lane = v_get.getLaneID(EGO_ID)
        edge = v_get.getRoadID(EGO_ID)
        if lane:
            lane_pos = v_get.getLanePosition(EGO_ID)
            limit = speed_limits.get(lane)
            if limit is None:
                limit = speed_limits[lane] = sim.lane.getMaxSpeed(lane)
            # the centre's offset, square to the lane where the centre is (SUMO reports the front's)
            lat = rmap.geom(lane).lateral(ex, ey, lane_pos - half_len)
        else:
            lane_pos = limit = lat = math.nan
        if edge != last_edge and edge and not edge.startswith(":"):
            k = route_index.get(edge)
            if k is None:  # off the route (an ADS may plan its own): SUMO's ego goes to the goal from here
                rest = rmap.route(edge, mission.goal_edge)
                if rest:
                    route, k = list(rest), 0
                    route_index = {e: i for i, e in reversed(list(enumerate(route)))}
            if k is not None and tuple(v_get.getRoute(EGO_ID)) != tuple(route[k:]):
                try:
                    v_get.setRoute(EGO_ID, route[k:])
                except Exception:  # noqa: BLE001 - SUMO refuses a route it cannot follow; keep its own
                    pass
            last_edge = edge
        nxt = v_get.getNextTLS(EGO_ID)
        next_tls = (nxt[0][0], nxt[0][1], nxt[0][2], nxt[0][3]) if nxt else None
        links = ()
        if lane in tls_links:
            lane_tls, lane_links = tls_links[lane]
            key = (lane, tuple(sim.trafficlight.getRedYellowGreenState(tls) for tls in lane_tls))
            links = links_seen.get(key)
            if links is None:  # the same lights show the same states again and again
                states = dict(zip(lane_tls, key[1]))
                links = links_seen[key] = tuple(LaneLink(tls, idx, out_lane, via, states[tls][idx])
                                                for tls, idx, out_lane, via in lane_links)
        ax_, ay_, ah_, av_ = actors.read(others, pids)
        ids, kinds = actors.ids, actors.kinds
        collisions = tuple((c.collider, c.victim, c.type) for c in sim.simulation.getCollisions()
                           if EGO_ID in (c.collider, c.victim))
        goal_dist = min(math.hypot(ex - px, ey - py) for px, py in goal_pts)
        timings["world"] += perf() - t1

        # 2. record frame ----------------------------------------------------------------------
        t2 = perf()
        mu_f = puddles.friction_at(ex + to_front_axle * ch, ey + to_front_axle * sh, mu_surface)
        mu_r = puddles.friction_at(ex - to_rear_axle * ch, ey - to_rear_axle * sh, mu_surface)
        fidx = recorder.add_frame(
            [t, ex, ey, state.heading, state.speed, state.vx, state.vy, state.ax, state.ay, state.yaw_rate,
             state.road_wheel_angle * params.steering_ratio, state.road_wheel_angle, steer, throttle, brake,
             mu_f, mu_r, limit, next_tls[2] if next_tls else math.nan, lane_pos, goal_dist],
            edge, lane, next_tls[3] if next_tls else "")
        if ids:
            recorder.add_actor_columns(fidx, actors.index_list, *actors.lists)
        timings["record"] += perf() - t2

        # 3. oracles ----------------------------------------------------------------------------
        t3 = perf()
        fwd_x, fwd_y, lft_x, lft_y = half_len * ch, half_len * sh, -half_wid * sh, half_wid * ch
        frame.index, frame.t = fidx, t
        frame.x, frame.y, frame.heading, frame.speed = ex, ey, state.heading, state.speed
        frame.prev_front, frame.front = prev_front, front
        # front-right, front-left, rear-left, rear-right, as drivefuzz.geometry.corners
        frame.corners = np.array(((ex + fwd_x - lft_x, ey + fwd_y - lft_y), (ex + fwd_x + lft_x, ey + fwd_y + lft_y),
                                  (ex - fwd_x + lft_x, ey - fwd_y + lft_y), (ex - fwd_x - lft_x, ey - fwd_y - lft_y)))
        frame.edge, frame.lane, frame.lane_pos, frame.speed_limit = edge, lane, lane_pos, limit
        frame.lat_offset = lat
        frame.route_index = route_index.get(edge, -1)
        frame.goal_dist = goal_dist
        frame.lane_links = links
        frame.next_tls = next_tls
        try:
            frame.ads_done = ads.done()
        except Exception as exc:
            raise _plugin_error("ADS", ads_name, exc, f"at frame {fidx}") from exc
        frame.actor_ids, frame.actor_kinds = ids, kinds
        frame.actor_x, frame.actor_y, frame.actor_heading, frame.actor_speed = ax_, ay_, ah_, av_
        frame.actor_length, frame.actor_width = actors.length, actors.width
        frame.sumo_collisions = collisions
        fired: list[Misbehavior] = []
        for oracle, name in zip(oracles, oracle_names):
            try:
                out = oracle.on_frame(frame)
            except Exception as exc:
                raise _plugin_error("oracle", name, exc, f"at frame {fidx}") from exc
            if out:
                fired.extend(out)
        timings["oracles"] += perf() - t3
        prev_front = front

        # 4. termination -------------------------------------------------------------------------
        if fired:
            misbehaviors.extend(fired)
            if stop_on_misbehavior:
                termination = Termination.MISBEHAVIOR
                break
        if goal_dist <= GOAL_RADIUS and state.speed <= GOAL_STOP_SPEED:
            termination = Termination.GOAL_REACHED
            break
        if t >= time_limit - 1e-9:
            termination = Termination.TIME_LIMIT
            break

        # 5-6. observation and ADS ------------------------------------------------------------------
        t5 = perf()
        obs = Observation(
            t=t,
            ego=EgoState(ex, ey, state.heading, state.speed, state.vx, state.vy, state.yaw_rate,
                         state.ax, state.road_wheel_angle, params.length, params.width, params.wheelbase),
            lane=lane, lane_pos=lane_pos, speed_limit=limit, objects=actors.observed(ex, ey),
            traffic_light=TrafficLightState(*next_tls) if next_tls else None,
            weather=weather, sun_glare=sun_glare(weather, state.heading),
        )
        t6 = perf()
        timings["observe"] += t6 - t5
        try:
            control = ads.step(obs)
            steer, throttle, brake = float(control.steer), float(control.throttle), float(control.brake)
        except Exception as exc:
            raise _plugin_error("ADS", ads_name, exc, f"at frame {fidx}") from exc
        timings["ads"] += perf() - t6

        # 7-8. physics and placement ----------------------------------------------------------------
        if not ads.sumo_driven:
            t7 = perf()
            wind = wind_amp * math.sin(2.0 * math.pi * t / 7.0 + wind_phase) if wind_amp else 0.0
            state = physics.step(steer, throttle, brake, dt, mu_f, mu_r, wind)
            ch, sh = math.cos(state.heading), math.sin(state.heading)
            nx, ny = state.x + half_len * ch, state.y + half_len * sh
            angle = (90.0 - math.degrees(state.heading)) % 360.0
            hint = edge if edge and not edge.startswith(":") else ""
            v_get.moveToXY(EGO_ID, hint, -1, nx, ny, angle, 2)
            timings["physics"] += perf() - t7

        # 9-10. actors and SUMO step ------------------------------------------------------------------
        t9 = perf()
        driver.step(t, vids, pids)
        sim.simulationStep()
        timings["sumo"] += perf() - t9

    t_end = perf()
    trace = recorder.freeze({
        "step_length": dt, "ego_length": params.length, "ego_width": params.width,
        "wheelbase": params.wheelbase, "steering_ratio": params.steering_ratio,
        "scenario_hash": scenario.content_hash(), "termination": termination.value,
        "goal_xy": [gx, gy], "route": list(planned), "drivefuzz": drivefuzz.__version__,
    })
    timings["record"] += perf() - t_end
    t_end = perf()
    for oracle, name in zip(oracles, oracle_names):
        with _blame("oracle", name, "at the end of the run"):
            misbehaviors.extend(oracle.on_end(trace, termination))
    timings["oracles"] += perf() - t_end
    wall = time.perf_counter() - wall0
    return Execution(scenario, trace, termination, tuple(misbehaviors), wall, timings)
