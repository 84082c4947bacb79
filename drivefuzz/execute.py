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
"""

from __future__ import annotations

import math
import os
import random
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

import drivefuzz
from drivefuzz.ads import (
    ADS,
    OBSERVATION_RADIUS,
    EgoState,
    MissionInfo,
    Observation,
    ObjectState,
    TrafficLightState,
    load_ads,
)
from drivefuzz.errors import SimulationError
from drivefuzz.oracle import Frame, LaneLink, Misbehavior, Obstacle, Oracle, RunContext, Termination
from drivefuzz.physics import VehicleParams, VehiclePhysics, place_state
from drivefuzz.roadmap import load_roadmap
from drivefuzz.scenario import ActorKind, ManeuverAction, NavType, Scenario
from drivefuzz.sumofiles import ADDITIONAL, EGO_ID, ROUTES, write_scenario
from drivefuzz.trace import EGO_FLOAT_FIELDS, Recorder, Trace

#: Distance [m] from the ego centre to the goal point that counts as arrived (the paper's 2 m).
GOAL_RADIUS = 2.0
#: Speed [m/s] below which an ego at the goal counts as stopped there.
GOAL_STOP_SPEED = 0.5
#: POI/polygon types the collision oracle treats as solid (a user's polygon file may use them).
OBSTACLE_TYPES = ("building", "obstacle", "barrier", "pole", "fence", "wall", "drivefuzz.obstacle")


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


def sun_glare(weather, heading: float) -> bool:
    """The sun is low (< 20 deg) and within 30 deg of the driving direction."""
    if not -5.0 < weather.sun_altitude_deg < 20.0:
        return False
    compass = (90.0 - math.degrees(heading)) % 360.0
    diff = abs((weather.sun_azimuth_deg - compass + 180.0) % 360.0 - 180.0)
    return diff < 30.0


def surface_friction(weather) -> float:
    """Friction of the dry road (1.0) reduced by wetness and rain (at most by 30 %)."""
    return 1.0 - 0.3 * max(weather.wetness, weather.rain) / 100.0


class _Puddles:
    """Point-in-rotated-rectangle test for the axles (cheap: a few puddles, two points a step)."""

    def __init__(self, puddles):
        self.items = [(p.x, p.y, math.cos(p.rotation), math.sin(p.rotation), p.length / 2, p.width / 2, p.friction)
                      for p in puddles]

    def friction_at(self, x: float, y: float, default: float) -> float:
        mu = default
        for cx, cy, c, s, hl, hw, f in self.items:
            dx, dy = x - cx, y - cy
            if abs(c * dx + s * dy) <= hl and abs(-s * dx + c * dy) <= hw:
                mu = min(mu, f)
        return mu


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


class _ActorDriver:
    """Applies the behaviour carried in the scenario's params to SUMO actors each step."""

    def __init__(self, sim, scenario: Scenario):
        self.sim = sim
        self.spec = {a.id: a for a in scenario.actors}
        self.started: set[str] = set()
        self.maneuver_next: dict[str, int] = {}
        self.walkers: dict[str, list[float]] = {}  # linear pedestrians: [x, y, ux, uy, remaining]
        self.dt = scenario.sim.step_length

    def on_depart(self, actor_id: str, t: float) -> None:
        a = self.spec.get(actor_id)
        if a is None or actor_id in self.started:
            return
        self.started.add(actor_id)
        sim = self.sim
        if a.kind is ActorKind.VEHICLE:
            if a.nav is NavType.LINEAR:
                sim.vehicle.setSpeedMode(actor_id, 0)
                sim.vehicle.setLaneChangeMode(actor_id, 0)
                sim.vehicle.setSpeed(actor_id, a.speed)
            elif a.nav is NavType.AUTOPILOT:
                sim.vehicle.setMaxSpeed(actor_id, max(a.speed, 0.1))
            elif a.nav is NavType.MANEUVER:
                sim.vehicle.setMaxSpeed(actor_id, max(a.speed, 0.1))
                sim.vehicle.setLaneChangeMode(actor_id, 512)
                self.maneuver_next[actor_id] = 0
        else:
            if a.nav is NavType.LINEAR and a.dest_xy is not None:
                x, y = sim.person.getPosition(actor_id)
                dx, dy = a.dest_xy[0] - x, a.dest_xy[1] - y
                d = math.hypot(dx, dy) or 1.0
                self.walkers[actor_id] = [x, y, dx / d, dy / d, d]
            elif a.nav is NavType.AUTOPILOT:
                sim.person.setSpeed(actor_id, max(a.speed, 0.05))

    def step(self, t: float, alive_vehicles: set[str], alive_persons: set[str]) -> None:
        sim = self.sim
        for vid, k in list(self.maneuver_next.items()):
            a = self.spec[vid]
            if vid not in alive_vehicles:
                continue
            while k < len(a.maneuvers) and t - a.depart >= a.maneuvers[k].time:
                m = a.maneuvers[k]
                if m.action is ManeuverAction.SPEED:
                    sim.vehicle.setSpeed(vid, m.value)
                else:
                    idx = sim.vehicle.getLaneIndex(vid) + (1 if m.action is ManeuverAction.LANE_LEFT else -1)
                    lane = sim.vehicle.getLaneID(vid)
                    n_lanes = sim.edge.getLaneNumber(sim.lane.getEdgeID(lane)) if lane else 0
                    if 0 <= idx < n_lanes:
                        sim.vehicle.changeLane(vid, idx, max(m.value, self.dt))
                k += 1
            self.maneuver_next[vid] = k
        for pid, w in list(self.walkers.items()):
            if pid not in alive_persons:
                del self.walkers[pid]
                continue
            step = min(self.spec[pid].speed * self.dt, w[4])
            w[0] += w[2] * step
            w[1] += w[3] * step
            w[4] -= step
            angle = (90.0 - math.degrees(math.atan2(w[3], w[2]))) % 360.0
            sim.person.moveToXY(pid, "", w[0], w[1], angle, 2)


def _tls_link_table(sim) -> dict[str, list[tuple[str, int, str, str]]]:
    """lane id -> [(tls, link index, to lane, via)] for every signalised vehicle link."""
    table: dict[str, list[tuple[str, int, str, str]]] = {}
    for tls in sim.trafficlight.getIDList():
        for idx, links in enumerate(sim.trafficlight.getControlledLinks(tls)):
            for in_lane, out_lane, via in links:
                table.setdefault(in_lane, []).append((tls, idx, out_lane, via))
    return table


def _static_obstacles(sim) -> list[Obstacle]:
    from shapely.geometry import Point, Polygon

    out = []
    for pid in sim.polygon.getIDList():
        if sim.polygon.getType(pid) in OBSTACLE_TYPES:
            shape = sim.polygon.getShape(pid)
            if len(shape) >= 3:
                out.append(Obstacle(pid, Polygon(shape)))
    for pid in sim.poi.getIDList():
        if sim.poi.getType(pid) in OBSTACLE_TYPES:
            x, y = sim.poi.getPosition(pid)
            out.append(Obstacle(pid, Point(x, y).buffer(0.3)))
    return out


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
        write_scenario(scenario, folder)
        if gui:
            import traci as sim  # the GUI needs a traci connection; same API as libsumo
        else:
            import libsumo as sim
        try:
            sim.start(_sumo_args(scenario, folder, net, gui))
        except Exception as exc:  # TraCIException cannot be pickled: re-raise plainly
            raise SimulationError(f"SUMO failed to start on {folder}: {type(exc).__name__}: {exc}") from None
        try:
            return _run(sim, scenario, rmap, ads, list(oracles), params, stop_on_misbehavior, wall0)
        finally:
            try:
                sim.close()
            except Exception:  # noqa: BLE001 - closing a dead connection must not hide the real error
                pass
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def _run(sim, scenario: Scenario, rmap, ads: ADS, oracles: list[Oracle], params: VehicleParams,
         stop_on_misbehavior: bool, wall0: float) -> Execution:
    dt = scenario.sim.step_length
    mission = scenario.mission
    route = list(rmap.route(mission.start_edge, mission.goal_edge))
    gx, gy, _ = rmap.geom(rmap.drive_lane(mission.goal_edge)).position(mission.goal_pos)
    # the goal is reached on any passenger lane of the goal edge
    goal_pts = [rmap.geom(l.getID()).position(mission.goal_pos)[:2]
                for l in rmap.edge(mission.goal_edge).getLanes() if l.allows("passenger")]
    half_len = params.length / 2.0
    rng = random.Random(scenario.seed)
    weather = scenario.weather
    timings = dict.fromkeys(("sumo", "physics", "ads", "oracles", "record", "world"), 0.0)
    perf = time.perf_counter

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
    driver = _ActorDriver(sim, scenario)
    for vid in sim.vehicle.getIDList():
        driver.on_depart(vid, 0.0)
    for pid in sim.person.getIDList():
        driver.on_depart(pid, 0.0)
    if ads.sumo_driven:
        # SUMO drives: hold the ego at the goal instead of letting it arrive and vanish.
        goal_len = rmap.edge(mission.goal_edge).getLength()
        sim.vehicle.setStop(EGO_ID, mission.goal_edge, pos=min(mission.goal_pos + params.length / 2, goal_len),
                            laneIndex=rmap.lane(rmap.drive_lane(mission.goal_edge)).getIndex(), duration=1e6)
        for key, value in ads.vtype_settings().items():  # e.g. accel -> vehicle.setAccel
            getattr(sim.vehicle, "set" + key[0].upper() + key[1:])(EGO_ID, value)
    else:
        sim.vehicle.setSpeedMode(EGO_ID, 0)
        sim.vehicle.setLaneChangeMode(EGO_ID, 0)
    fx, fy = sim.vehicle.getPosition(EGO_ID)
    heading = math.radians(90.0 - sim.vehicle.getAngle(EGO_ID))
    cx, cy = fx - half_len * math.cos(heading), fy - half_len * math.sin(heading)
    physics = VehiclePhysics(params, place_state(cx, cy, heading, mission.start_speed, params))
    ads.reset(MissionInfo(mission.start_lane, mission.start_pos, mission.goal_edge, mission.goal_pos, (gx, gy),
                          tuple(route), dt, scenario.seed), rmap)
    ctx = RunContext(scenario, rmap, tuple(route), (gx, gy), params.length, params.width, dt,
                     _static_obstacles(sim))
    for oracle in oracles:
        oracle.reset(ctx)
    tls_links = _tls_link_table(sim)
    puddles = _Puddles(scenario.puddles)
    mu_surface = surface_friction(weather)
    wind_amp = 0.5 * 1.2 * 0.9 * (params.length * 1.5) * (15.0 * weather.wind / 100.0) ** 2  # [N]
    wind_phase = rng.uniform(0.0, 2.0 * math.pi)
    speed_limits: dict[str, float] = {}
    recorder = Recorder(int(scenario.sim.time_limit / dt) + 8)
    frame = Frame()
    prev_front = (fx, fy)
    control = None
    misbehaviors: list[Misbehavior] = []
    termination = Termination.TIME_LIMIT
    actor_sizes: dict[str, tuple[float, float, int]] = {}  # length, width, recorder index
    last_edge = ""
    steer = throttle = brake = 0.0
    time_limit = scenario.sim.time_limit
    start_t = sim.simulation.getTime()

    while True:
        # 1. read the world --------------------------------------------------------------
        t1 = perf()
        t = sim.simulation.getTime() - start_t
        vids = sim.vehicle.getIDList()
        if EGO_ID not in vids:
            termination = Termination.EGO_LOST
            break
        pids = sim.person.getIDList()
        for vid in sim.simulation.getDepartedIDList():
            driver.on_depart(vid, t)
        for pid in sim.simulation.getDepartedPersonIDList():
            driver.on_depart(pid, t)
        if ads.sumo_driven:
            fx, fy = sim.vehicle.getPosition(EGO_ID)
            h = math.radians(90.0 - sim.vehicle.getAngle(EGO_ID))
            v = sim.vehicle.getSpeed(EGO_ID)
            st = physics.state
            yaw_rate = ((h - st.heading + math.pi) % (2 * math.pi) - math.pi) / dt
            ax = (v - st.vx) / dt
            st.x, st.y = fx - half_len * math.cos(h), fy - half_len * math.sin(h)
            st.heading, st.vx, st.vy, st.yaw_rate, st.ax, st.ay = h, v, 0.0, yaw_rate, ax, v * yaw_rate
        state = physics.state
        ch, sh = math.cos(state.heading), math.sin(state.heading)
        front = (state.x + half_len * ch, state.y + half_len * sh)
        lane = sim.vehicle.getLaneID(EGO_ID)
        edge = sim.vehicle.getRoadID(EGO_ID)
        lane_pos = sim.vehicle.getLanePosition(EGO_ID) if lane else math.nan
        if lane:
            limit = speed_limits.get(lane)
            if limit is None:
                limit = speed_limits[lane] = sim.lane.getMaxSpeed(lane)
        else:
            limit = math.nan
        if edge != last_edge and edge and not edge.startswith(":"):
            if edge in route:
                k = route.index(edge)
                if tuple(sim.vehicle.getRoute(EGO_ID)) != tuple(route[k:]):
                    try:
                        sim.vehicle.setRoute(EGO_ID, route[k:])
                    except Exception:  # noqa: BLE001 - SUMO refuses a route it cannot follow; keep its own
                        pass
            last_edge = edge
        nxt = sim.vehicle.getNextTLS(EGO_ID)
        next_tls = (nxt[0][0], nxt[0][1], nxt[0][2], nxt[0][3]) if nxt else None
        links = ()
        if lane in tls_links:
            states: dict[str, str] = {}
            lst = []
            for tls, idx, out_lane, via in tls_links[lane]:
                s = states.get(tls)
                if s is None:
                    s = states[tls] = sim.trafficlight.getRedYellowGreenState(tls)
                lst.append(LaneLink(tls, idx, out_lane, via, s[idx]))
            links = tuple(lst)
        ids, kinds = [], []
        rows = []
        for kind, domain, actor_ids in (("vehicle", sim.vehicle, vids), ("pedestrian", sim.person, pids)):
            for aid in actor_ids:
                if aid == EGO_ID:
                    continue
                info = actor_sizes.get(aid)
                if info is None:  # sizes are fixed: read them once per actor
                    length, width = domain.getLength(aid), domain.getWidth(aid)
                    info = actor_sizes[aid] = (length, width, recorder.actor_index(aid, kind, length, width))
                px, py = domain.getPosition(aid)
                h = math.radians(90.0 - domain.getAngle(aid))
                hl = info[0] / 2.0
                rows.append((info[2], px - hl * math.cos(h), py - hl * math.sin(h), h, domain.getSpeed(aid),
                             info[0], info[1]))
                ids.append(aid)
                kinds.append(kind)
        arr = np.asarray(rows, dtype=float).reshape(-1, 7)
        collisions = tuple((c.collider, c.victim, c.type) for c in sim.simulation.getCollisions()
                           if EGO_ID in (c.collider, c.victim))
        goal_dist = min(math.hypot(state.x - px, state.y - py) for px, py in goal_pts)
        timings["world"] += perf() - t1

        # 2. record frame ----------------------------------------------------------------------
        t2 = perf()
        mu_f = puddles.friction_at(*physics.axle_positions()[0], mu_surface)
        mu_r = puddles.friction_at(*physics.axle_positions()[1], mu_surface)
        lat = sim.vehicle.getLateralLanePosition(EGO_ID) if lane else math.nan
        fidx = recorder.add_frame(
            [t, state.x, state.y, state.heading, state.speed, state.vx, state.vy, state.ax, state.ay, state.yaw_rate,
             state.road_wheel_angle * params.steering_ratio, state.road_wheel_angle, steer, throttle, brake,
             mu_f, mu_r, limit, next_tls[2] if next_tls else math.nan, lane_pos, goal_dist],
            edge, lane, next_tls[3] if next_tls else "")
        if len(arr):
            recorder.add_actors(fidx, arr[:, :5])
        timings["record"] += perf() - t2

        # 3. oracles ----------------------------------------------------------------------------
        t3 = perf()
        frame.index, frame.t = fidx, t
        frame.x, frame.y, frame.heading, frame.speed = state.x, state.y, state.heading, state.speed
        frame.prev_front, frame.front = prev_front, front
        frame.corners = None
        frame.edge, frame.lane, frame.lane_pos, frame.speed_limit = edge, lane, lane_pos, limit
        frame.lat_offset = lat
        frame.route_index = route.index(edge) if edge in route else -1
        frame.goal_dist = goal_dist
        frame.lane_links = links
        frame.next_tls = next_tls
        frame.ads_done = ads.done()
        frame.actor_ids, frame.actor_kinds = ids, kinds
        frame.actor_x, frame.actor_y, frame.actor_heading = arr[:, 1], arr[:, 2], arr[:, 3]
        frame.actor_speed, frame.actor_length, frame.actor_width = arr[:, 4], arr[:, 5], arr[:, 6]
        frame.sumo_collisions = collisions
        fired: list[Misbehavior] = []
        for oracle in oracles:
            fired.extend(oracle.on_frame(frame))
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
        objects = []
        for k in range(len(ids)):
            x, y = arr[k, 1], arr[k, 2]
            if abs(x - state.x) < OBSERVATION_RADIUS and abs(y - state.y) < OBSERVATION_RADIUS:
                objects.append(ObjectState(ids[k], kinds[k], x, y, arr[k, 3], arr[k, 4], arr[k, 5], arr[k, 6]))
        obs = Observation(
            t=t,
            ego=EgoState(state.x, state.y, state.heading, state.speed, state.vx, state.vy, state.yaw_rate,
                         state.ax, state.road_wheel_angle, params.length, params.width, params.wheelbase),
            lane=lane, lane_pos=lane_pos, speed_limit=limit, objects=tuple(objects),
            traffic_light=TrafficLightState(*next_tls) if next_tls else None,
            weather=weather, sun_glare=sun_glare(weather, state.heading),
        )
        control = ads.step(obs)
        steer, throttle, brake = float(control.steer), float(control.throttle), float(control.brake)
        timings["ads"] += perf() - t5

        # 7-8. physics and placement ----------------------------------------------------------------
        if not ads.sumo_driven:
            t7 = perf()
            wind = wind_amp * math.sin(2.0 * math.pi * t / 7.0 + wind_phase) if wind_amp else 0.0
            state = physics.step(steer, throttle, brake, dt, mu_f, mu_r, wind)
            ch, sh = math.cos(state.heading), math.sin(state.heading)
            nx, ny = state.x + half_len * ch, state.y + half_len * sh
            angle = (90.0 - math.degrees(state.heading)) % 360.0
            hint = edge if edge and not edge.startswith(":") else ""
            sim.vehicle.moveToXY(EGO_ID, hint, -1, nx, ny, angle, 2)
            timings["physics"] += perf() - t7

        # 9-10. actors and SUMO step ------------------------------------------------------------------
        t9 = perf()
        driver.step(t, set(vids), set(pids))
        sim.simulationStep()
        timings["sumo"] += perf() - t9

    trace = recorder.freeze({
        "step_length": dt, "ego_length": params.length, "ego_width": params.width,
        "wheelbase": params.wheelbase, "steering_ratio": params.steering_ratio,
        "scenario_hash": scenario.content_hash(), "termination": termination.value,
        "goal_xy": [gx, gy], "route": route, "drivefuzz": drivefuzz.__version__,
    })
    for oracle in oracles:
        misbehaviors.extend(oracle.on_end(trace, termination))
    wall = time.perf_counter() - wall0
    return Execution(scenario, trace, termination, tuple(misbehaviors), wall, timings)
