"""The test executor: runs one Scenario through SUMO with an ADS driving drivefuzz's car.

This is the only module that imports libsumo (or traci, for ``--gui``).

Setup: the scenario's SUMO files are written to a work folder and SUMO starts on
them with ``-X never`` (friction steps are not in the XSD), no teleports, and
collision warnings. Every actor departs from the loaded files; the first step
inserts them and the ego together, and only then do actor behaviours and the
ADS start ("no abrupt creation"). The ADS is reset with the mission and the
road map, and the physics takes the ego over from where SUMO inserted it.

Every step, in this fixed order (frame k is the world after SUMO step k), one method of
``_Run`` each, which ``_Run.run`` calls in turn::

    1. read_world: ego lane/edge/speed limit/next light, every actor's pose
    2. record_frame: frame k (ego state from the physics + world)
    3. run_oracles: the oracles on frame k
    4. check_termination: an oracle fired, goal reached, time limit (ego lost: step 1)
    5. observe: the ADS's Observation (ground truth within the sensor horizon + weather)
    6. ads_step: ADS.step(observation) -> Control
    7. move_ego: the physics integrates the Control, with the friction under each axle and wind,
    8.   and places the ego in SUMO with moveToXY (keepRoute=2) (read_world keeps its route current)
    9. step_sumo: per-step actor commands (linear, maneuver schedules, jaywalking),
   10.   then step SUMO

Setup (``_Run.setup``: insert, take_over_ego, reset_plugins) and ``_Run.finish``
(freeze the trace, the oracles' end-of-run checks) bracket the loop.

The ego is a SUMO vehicle with speed mode 0 and lane-change mode 0 that is
moved every step, so other traffic sees and yields to it; SUMO's own collision
detection is only a cross-check (it misses lateral and off-lane contact).
Linear and immobile pedestrians are placed by the executor (``person.moveToXY``)
every step; their recorded speed is the walked one. An exception in plugin code
(ADS or oracle) leaves :func:`execute` as a :class:`~drivefuzz.errors.PluginError`
naming the plugin and saying which kind it is (``plugin``). ``Execution.timings``: seconds per stage, ``setup``,
``sumo`` (steps 9-10, and SUMO's own start and close), ``world`` (1), ``record`` (2), ``oracles`` (3), ``observe`` (5),
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
from drivefuzz.errors import ADS_PLUGIN, ORACLE_PLUGIN, PluginError, SimulationError
from drivefuzz.oracle import Frame, LaneLink, Misbehavior, Oracle, RunContext, Termination
from drivefuzz.sim.physics import VehicleParams, VehiclePhysics, place_state
from drivefuzz.sim.gui import GuiView
from drivefuzz.scenario.roadmap import load_roadmap
from drivefuzz.scenario import Scenario
from drivefuzz.scenario.sumofiles import ADDITIONAL, EGO_ID, LANE_CHANGE_DURATION, ROUTES, write_scenario
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

#: [m] the radius within which moveToXY looks for the lane to map the ego onto. SUMO's default is 100 m, and
#: the search over every lane in it was most of the call (10 -> 2-3.5 us on the town, 50-110 -> 8-40 us on
#: Berlin). SUMO maps a point onto a lane only within about a metre of the lane's edge and off the road beyond
#: (on the highway's 3.5 m lanes 2.5 m from the outer lane's centre mapped onto it, 3.0 m was off-road, with
#: every radius from 5 to 100 m), so 15 m leaves every mapping as it was: the committed seeds and 120 campaign
#: findings and incidents ran bit for bit the same with 10, 15, 20 and 100 m.
MATCH_RADIUS = 15.0

#: Distance [m] from the ego centre to the goal point that counts as arrived (the paper's 2 m).
GOAL_RADIUS = 2.0
#: Speed [m/s] below which an ego at the goal counts as stopped there.
GOAL_STOP_SPEED = 0.5
#: [s] an actor SUMO could not insert this long after its departure time is dropped (see ``_sumo_args``)
MAX_DEPART_DELAY = 1.0


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


class _LiveFrame(Frame):
    """The executor's reused :class:`Frame`: ``corners`` is built when an oracle first reads it in a frame
    (the built-in oracles never do; an array a frame cost 1.5 us). :meth:`set_pose` gives its inputs."""

    def set_pose(self, ex: float, ey: float, fwd_x: float, fwd_y: float, lft_x: float, lft_y: float) -> None:
        self._pose = (ex, ey, fwd_x, fwd_y, lft_x, lft_y)

    @property
    def corners(self):
        pose = self.__dict__.get("_pose")
        if pose is not None:
            ex, ey, fwd_x, fwd_y, lft_x, lft_y = pose
            # front-right, front-left, rear-left, rear-right, as drivefuzz.geometry.corners
            self._corners = np.array(((ex + fwd_x - lft_x, ey + fwd_y - lft_y), (ex + fwd_x + lft_x, ey + fwd_y + lft_y),
                                      (ex - fwd_x + lft_x, ey - fwd_y + lft_y), (ex - fwd_x - lft_x, ey - fwd_y - lft_y)))
            self._pose = None
        return self.__dict__.get("_corners")

    @corners.setter
    def corners(self, value) -> None:
        self._corners, self._pose = value, None


def _sumo_args(scenario: Scenario, folder: Path, net: Path, gui: bool) -> list[str]:
    binary = drivefuzz.sumo_binary("sumo-gui" if gui else "sumo")
    args = [
        binary, "-X", "never",
        "-n", str(net), "-r", str(folder / ROUTES), "-a", str(folder / ADDITIONAL),
        "--step-length", repr(scenario.sim.step_length),
        "--seed", str(scenario.seed % 2**31),
        "--time-to-teleport", "-1",
        "--lanechange.duration", repr(LANE_CHANGE_DURATION),
        # an actor that cannot enter where and when it was placed (the spot is taken) is dropped: entering
        # later, wherever the spot then is free, it would be a situation no fairness rule checked (one that
        # enters within the delay in the ego's way is removed: ActorDriver._late_in_the_way)
        "--max-depart-delay", repr(MAX_DEPART_DELAY),
        "--collision.action", "warn", "--collision.check-junctions", "true", "--collision.mingap-factor", "0",
        "--pedestrian.model", "striping",
        "--pedestrian.striping.jamtime", "-1", "--pedestrian.striping.jamtime.crossing", "-1",
        "--default.speeddev", "0",
        "--no-step-log", "true", "--no-warnings", "true", "--duration-log.disable", "true",
        "--end", repr(scenario.sim.time_limit + 10.0),
    ]
    if gui:  # drivefuzz paces the steps and closes the window (sim/gui.py)
        args += ["--start", "--quit-on-end", "--delay", "0"]
    return args


def execute(
    scenario: Scenario,
    *,
    ads: ADS | None = None,
    oracles: Sequence[Oracle] = (),
    gui: "bool | GuiView" = False,
    stop_on_misbehavior: bool = True,
    workdir: str | os.PathLike | None = None,
    vehicle: VehicleParams | None = None,
) -> Execution:
    """Run ``scenario`` once and return its :class:`Execution`.

    ``ads`` defaults to the scenario's ADS plugin. ``workdir`` keeps the SUMO
    files (a temporary folder otherwise). ``gui``: show the run in sumo-gui (True, or a
    :class:`~drivefuzz.sim.gui.GuiView` that says how).
    """
    view = (GuiView() if gui is True else gui) or None
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
        t_start = time.perf_counter()
        try:
            sim.start(_sumo_args(scenario, folder, net, gui))
        except Exception as exc:  # TraCIException cannot be pickled: re-raise plainly
            raise SimulationError(f"SUMO failed to start on {folder}: {type(exc).__name__}: {exc}") from None
        t_start = time.perf_counter() - t_start
        try:
            if view is not None:
                view.start(sim)
            result = _run(sim, scenario, rmap, ads, list(oracles), params, stop_on_misbehavior, wall0, view)
            if view is not None:
                view.end(sim, result.misbehaviors)
        finally:
            t_close = time.perf_counter()
            try:
                sim.close()
            except Exception:  # noqa: BLE001 - closing a dead connection must not hide the real error
                pass
            t_close = time.perf_counter() - t_close
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    # SUMO's own start (loading the network and the files) and close are SUMO's time, not the setup's
    result.timings["sumo"] += t_start + t_close
    result.timings["setup"] -= t_start
    return dataclasses.replace(result, wall_time=time.perf_counter() - wall0)


def _plugin_error(what: str, name: str, exc: BaseException, where: str) -> PluginError:
    """A plugin's own exception as a PluginError that names the plugin (raise it ``from exc``); ``what`` is
    "ADS" or "oracle", and the error's ``plugin`` says which (an ADS's exception is a finding, an oracle's not)."""
    return PluginError(f"{what} {name!r} raised {type(exc).__name__} {where}: {exc}",
                       ADS_PLUGIN if what == "ADS" else ORACLE_PLUGIN)


@contextlib.contextmanager
def _blame(what: str, name: str, where: str):
    """:func:`_plugin_error` around a block (the per-frame calls use try/except: it is cheaper)."""
    try:
        yield
    except (Exception, SystemExit) as exc:  # sys.exit() too: the plugin is named
        raise _plugin_error(what, name, exc, where) from exc


def _run(sim, scenario: Scenario, rmap, ads: ADS, oracles: list[Oracle], params: VehicleParams,
         stop_on_misbehavior: bool, wall0: float, view: "GuiView | None" = None) -> Execution:
    return _Run(sim, scenario, rmap, ads, oracles, params, stop_on_misbehavior, wall0, view).run()


class _Run:
    """One execution under way: its state between ticks, and one method per step of a tick.

    The attributes are what lives longer than one step; ``read_world`` leaves the world
    of frame k on it for the later steps of the same tick.
    """

    def __init__(self, sim, scenario: Scenario, rmap, ads: ADS, oracles: list[Oracle], params: VehicleParams,
                 stop_on_misbehavior: bool, wall0: float, view: GuiView | None = None):
        self.sim, self.scenario, self.rmap, self.ads, self.oracles = sim, scenario, rmap, ads, oracles
        self.params, self.stop_on_misbehavior, self.wall0 = params, stop_on_misbehavior, wall0
        self.dt = dt = scenario.sim.step_length
        self.mission = mission = scenario.mission
        self.planned = rmap.route(mission.start_edge, mission.goal_edge)
        self.route = list(self.planned)  # SUMO's route for the ego, kept current from the edge it is on
        self.gx, self.gy, _ = rmap.geom(rmap.drive_lane(mission.goal_edge)).position(mission.goal_pos)
        # the goal is reached on any passenger lane of the goal edge
        self.goal_pts = [rmap.geom(l.getID()).position(mission.goal_pos)[:2]
                         for l in rmap.edge(mission.goal_edge).getLanes() if l.allows("passenger")]
        self.half_len, self.half_wid = params.length / 2.0, params.width / 2.0
        self.to_front_axle, self.to_rear_axle = params.centre_to_front_axle, params.centre_to_rear_axle
        self.rng = random.Random(scenario.seed)
        self.weather = scenario.weather
        self.timings = dict.fromkeys(("setup", "sumo", "world", "record", "oracles", "observe", "ads", "physics"), 0.0)
        self.ads_name = ads.name or type(ads).__name__
        self.oracle_names = [o.name or type(o).__name__ for o in oracles]
        self.sumo_driven = ads.sumo_driven
        self.misbehaviors: list[Misbehavior] = []
        self.steer = self.throttle = self.brake = 0.0
        self.time_limit = scenario.sim.time_limit
        self.view = view  # sumo-gui's pacing and view (replay --gui)

    def run(self) -> Execution:
        """Set up, then tick in the module docstring's order until the run terminates."""
        self.setup()
        while True:
            if not self.read_world():  # 1
                termination = Termination.EGO_LOST
                break
            self.record_frame()  # 2
            fired = self.run_oracles()  # 3
            termination = self.check_termination(fired)  # 4
            if termination is not None:
                break
            obs = self.observe()  # 5
            self.ads_step(obs)  # 6
            if not self.sumo_driven:
                self.move_ego()  # 7-8
            self.step_sumo()  # 9-10
        return self.finish(termination)

    # -- setup ---------------------------------------------------------------------------------
    def setup(self) -> None:
        """Insert everything, take the ego over, reset the ADS and the oracles."""
        perf = time.perf_counter
        sim, timings = self.sim, self.timings
        t0 = perf()
        self.insert()
        timings["sumo"] += perf() - t0
        self.driver = ActorDriver(sim, self.scenario, self.rmap)  # starts the actors' behaviours in the first frame
        self.take_over_ego()
        self.reset_plugins()
        weather, params = self.weather, self.params
        self.tls_links = tls_link_table(sim)
        self.puddles = Puddles(self.scenario.puddles)
        self.mu_surface = surface_friction(weather)
        self.wind_amp = 0.5 * 1.2 * 0.9 * (params.length * 1.5) * weather.wind_speed ** 2  # [N]
        self.wind_phase = self.rng.uniform(0.0, 2.0 * math.pi)
        self.speed_limits: dict[str, float] = {}
        self.links_seen: dict[tuple, tuple[LaneLink, ...]] = {}
        self.recorder = Recorder(int(self.time_limit / self.dt) + 8)
        self.actors = Actors(sim, self.recorder, self.driver)
        self.frame = _LiveFrame()
        self.last_edge = ""
        self.start_t = sim.simulation.getTime()
        self.route_index = {e: i for i, e in reversed(list(enumerate(self.route)))}
        timings["setup"] = perf() - self.wall0 - timings["sumo"]

    def insert(self) -> None:
        """Step SUMO until the ego (and every actor with it) is inserted."""
        sim, mission = self.sim, self.mission
        for _ in range(int(round(1.0 / self.dt)) + 1):
            sim.simulationStep()
            if EGO_ID in sim.vehicle.getIDList():
                break
        else:
            raise SimulationError(f"SUMO could not insert the ego on {mission.start_lane} at {mission.start_pos} m "
                                  "(blocked by an actor?)")

    def take_over_ego(self) -> None:
        """Hand the ego to the ADS's driver (SUMO or the physics), from where SUMO inserted it."""
        sim, rmap, mission, params, ads = self.sim, self.rmap, self.mission, self.params, self.ads
        if ads.sumo_driven:
            # SUMO drives: hold the ego at the goal instead of letting it arrive and vanish.
            goal_len = rmap.edge(mission.goal_edge).getLength()
            sim.vehicle.setStop(EGO_ID, mission.goal_edge, pos=min(mission.goal_pos + params.length / 2, goal_len),
                                laneIndex=rmap.lane(rmap.drive_lane(mission.goal_edge)).getIndex(), duration=1e6)
            with _blame("ADS", self.ads_name, "at reset"):
                settings = ads.vtype_settings()
            for key, value in settings.items():  # e.g. accel -> vehicle.setAccel
                getattr(sim.vehicle, "set" + key[0].upper() + key[1:])(EGO_ID, value)
        else:
            sim.vehicle.setSpeedMode(EGO_ID, 0)
            sim.vehicle.setLaneChangeMode(EGO_ID, 0)
        fx, fy = sim.vehicle.getPosition(EGO_ID)
        heading = math.radians(90.0 - sim.vehicle.getAngle(EGO_ID))
        cx, cy = fx - self.half_len * math.cos(heading), fy - self.half_len * math.sin(heading)
        self.physics = VehiclePhysics(params, place_state(cx, cy, heading, mission.start_speed, params))
        self.prev_front = (fx, fy)

    def reset_plugins(self) -> None:
        """Reset the ADS with the mission and the road map, then every oracle with the run's context."""
        mission, scenario, params, rmap = self.mission, self.scenario, self.params, self.rmap
        gx, gy = self.gx, self.gy
        with _blame("ADS", self.ads_name, "at reset"):
            self.ads.reset(MissionInfo(mission.start_lane, mission.start_pos, mission.goal_edge, mission.goal_pos,
                                       (gx, gy), self.planned, self.dt, scenario.seed), rmap)
        ctx = RunContext(scenario, rmap, self.planned, (gx, gy), params.length, params.width, self.dt,
                         static_obstacles(self.sim))
        for oracle, name in zip(self.oracles, self.oracle_names):
            with _blame("oracle", name, "at reset"):
                oracle.reset(ctx)

    # -- one tick ----------------------------------------------------------------------------
    def read_world(self) -> bool:
        """1. Read the world of frame k onto ``self``; False when the ego has left SUMO."""
        perf = time.perf_counter
        t1 = perf()
        sim, v_get, half_len, actors = self.sim, self.sim.vehicle, self.half_len, self.actors
        self.t = t = sim.simulation.getTime() - self.start_t
        self.vids = vids = v_get.getIDList()
        try:
            k_ego = vids.index(EGO_ID)
        except ValueError:
            return False
        self.others = others = vids[:k_ego] + vids[k_ego + 1:]
        self.pids = pids = sim.person.getIDList()
        if self.sumo_driven:
            self.ego_from_sumo()
        self.state = state = self.physics.state
        self.ex, self.ey = ex, ey = state.x, state.y
        self.ch, self.sh = ch, sh = math.cos(state.heading), math.sin(state.heading)
        if (others, pids) != actors.key:  # someone departed or arrived: start what departed
            on_depart, ego = self.driver.on_depart, (ex, ey, ch, sh, state.speed, half_len)
            for aid in chain(others, pids):
                if not on_depart(aid, t, ego):  # removed again (it appeared where no driver could react)
                    self.others = others = tuple(v for v in others if v != aid)
        self.front = (ex + half_len * ch, ey + half_len * sh)
        self.lane = lane = v_get.getLaneID(EGO_ID)
        self.edge = edge = v_get.getRoadID(EGO_ID)
        if lane:
            self.lane_pos = lane_pos = v_get.getLanePosition(EGO_ID)
            limit = self.speed_limits.get(lane)
            if limit is None:
                limit = self.speed_limits[lane] = sim.lane.getMaxSpeed(lane)
            self.limit = limit
            # the centre's offset, square to the lane where the centre is (SUMO reports the front's)
            self.lat = self.rmap.geom(lane).lateral(ex, ey, lane_pos - half_len)
        else:
            self.lane_pos = self.limit = self.lat = math.nan
        if edge != self.last_edge and edge and not edge.startswith(":"):
            self.keep_route_current(edge)
        nxt = v_get.getNextTLS(EGO_ID)
        self.next_tls = (nxt[0][0], nxt[0][1], nxt[0][2], nxt[0][3]) if nxt else None
        self.links = self.lane_links(lane) if lane in self.tls_links else ()
        self.actor_state = actors.read(others, pids)
        collisions = sim.simulation.getCollisions()
        self.collisions = tuple((c.collider, c.victim, c.type) for c in collisions
                                if EGO_ID in (c.collider, c.victim)) if collisions else ()
        if len(self.goal_pts) == 1:
            (px, py), = self.goal_pts
            self.goal_dist = math.hypot(ex - px, ey - py)
        else:
            self.goal_dist = min(math.hypot(ex - px, ey - py) for px, py in self.goal_pts)
        self.timings["world"] += perf() - t1
        return True

    def ego_from_sumo(self) -> None:
        """When SUMO drives the ego: its pose and speed into the physics state (no physics runs)."""
        v_get, dt, half_len = self.sim.vehicle, self.dt, self.half_len
        fx, fy = v_get.getPosition(EGO_ID)
        h = math.radians(90.0 - v_get.getAngle(EGO_ID))
        v = v_get.getSpeed(EGO_ID)
        st = self.physics.state
        yaw_rate = ((h - st.heading + math.pi) % (2 * math.pi) - math.pi) / dt
        ax = (v - st.vx) / dt
        st.x, st.y = fx - half_len * math.cos(h), fy - half_len * math.sin(h)
        st.heading, st.vx, st.vy, st.yaw_rate, st.ax, st.ay = h, v, 0.0, yaw_rate, ax, v * yaw_rate

    def keep_route_current(self, edge: str) -> None:
        """The ego entered ``edge`` (not an internal one): make SUMO's route for it start there."""
        v_get, route = self.sim.vehicle, self.route
        k = self.route_index.get(edge)
        if k is None:  # off the route (an ADS may plan its own): SUMO's ego goes to the goal from here
            rest = self.rmap.route(edge, self.mission.goal_edge)
            if rest:
                self.route = route = list(rest)
                k = 0
                self.route_index = {e: i for i, e in reversed(list(enumerate(route)))}
        if k is not None and tuple(v_get.getRoute(EGO_ID)) != tuple(route[k:]):
            try:
                v_get.setRoute(EGO_ID, route[k:])
            except Exception:  # noqa: BLE001 - SUMO refuses a route it cannot follow; keep its own
                pass
        self.last_edge = edge

    def lane_links(self, lane: str) -> tuple[LaneLink, ...]:
        """The signalled links out of ``lane`` with the states their lights show now."""
        lane_tls, lane_links = self.tls_links[lane]
        key = (lane, tuple(self.sim.trafficlight.getRedYellowGreenState(tls) for tls in lane_tls))
        links = self.links_seen.get(key)
        if links is None:  # the same lights show the same states again and again
            states = dict(zip(lane_tls, key[1]))
            links = self.links_seen[key] = tuple(LaneLink(tls, idx, out_lane, via, states[tls][idx])
                                                 for tls, idx, out_lane, via in lane_links)
        return links

    def record_frame(self) -> None:
        """2. Record frame k: the ego from the physics, the friction under each axle, the world."""
        perf = time.perf_counter
        t2 = perf()
        ex, ey, ch, sh, state, next_tls = self.ex, self.ey, self.ch, self.sh, self.state, self.next_tls
        puddles, mu_surface, to_front_axle, to_rear_axle = (self.puddles, self.mu_surface, self.to_front_axle,
                                                            self.to_rear_axle)
        self.mu_f = mu_f = puddles.friction_at(ex + to_front_axle * ch, ey + to_front_axle * sh, mu_surface)
        self.mu_r = mu_r = puddles.friction_at(ex - to_rear_axle * ch, ey - to_rear_axle * sh, mu_surface)
        recorder = self.recorder
        self.fidx = fidx = recorder.add_frame(
            [self.t, ex, ey, state.heading, state.speed, state.vx, state.vy, state.ax, state.ay, state.yaw_rate,
             state.road_wheel_angle * self.params.steering_ratio, state.road_wheel_angle, self.steer, self.throttle,
             self.brake, mu_f, mu_r, self.limit, next_tls[2] if next_tls else math.nan, self.lane_pos,
             self.goal_dist],
            self.edge, self.lane, next_tls[3] if next_tls else "")
        actors = self.actors
        if actors.ids:
            recorder.add_actor_columns(fidx, actors.index_list, *actors.lists)
        self.timings["record"] += perf() - t2

    def run_oracles(self) -> list[Misbehavior]:
        """3. Fill the oracles' Frame for frame k and run every oracle on it; what fired."""
        perf = time.perf_counter
        t3 = perf()
        frame, actors, state, fidx = self.frame, self.actors, self.state, self.fidx
        ex, ey, ch, sh, half_len, half_wid = self.ex, self.ey, self.ch, self.sh, self.half_len, self.half_wid
        fwd_x, fwd_y, lft_x, lft_y = half_len * ch, half_len * sh, -half_wid * sh, half_wid * ch
        frame.index, frame.t = fidx, self.t
        frame.x, frame.y, frame.heading, frame.speed = ex, ey, state.heading, state.speed
        frame.prev_front, frame.front = self.prev_front, self.front
        frame.set_pose(ex, ey, fwd_x, fwd_y, lft_x, lft_y)  # the footprint, built if an oracle reads it
        frame.edge, frame.lane, frame.lane_pos, frame.speed_limit = self.edge, self.lane, self.lane_pos, self.limit
        frame.lat_offset = self.lat
        frame.route_index = self.route_index.get(self.edge, -1)
        frame.goal_dist = self.goal_dist
        frame.lane_links = self.links
        frame.next_tls = self.next_tls
        try:
            frame.ads_done = self.ads.done()
        except (Exception, SystemExit) as exc:  # sys.exit() too: the plugin is named
            raise _plugin_error("ADS", self.ads_name, exc, f"at frame {fidx}") from exc
        frame.actor_ids, frame.actor_kinds = actors.ids, actors.kinds
        frame.actor_x, frame.actor_y, frame.actor_heading, frame.actor_speed = self.actor_state
        frame.actor_length, frame.actor_width = actors.length, actors.width
        frame.sumo_collisions = self.collisions
        fired: list[Misbehavior] = []
        for oracle, name in zip(self.oracles, self.oracle_names):
            try:
                out = oracle.on_frame(frame)
            except (Exception, SystemExit) as exc:  # sys.exit() too: the plugin is named
                raise _plugin_error("oracle", name, exc, f"at frame {fidx}") from exc
            if out:
                fired.extend(out)
        self.timings["oracles"] += perf() - t3
        self.prev_front = self.front
        return fired

    def check_termination(self, fired: list[Misbehavior]) -> Termination | None:
        """4. Keep what fired; how the run ends after frame k, or None to go on."""
        if fired:
            self.misbehaviors.extend(fired)
            if self.stop_on_misbehavior:
                return Termination.MISBEHAVIOR
        if self.goal_dist <= GOAL_RADIUS and self.state.speed <= GOAL_STOP_SPEED:
            return Termination.GOAL_REACHED
        if self.t >= self.time_limit - 1e-9:
            return Termination.TIME_LIMIT
        return None

    def observe(self) -> Observation:
        """5. The ADS's Observation: ground truth within the sensor horizon, and the weather."""
        perf = time.perf_counter
        t5 = perf()
        ex, ey, state, params, next_tls, weather = self.ex, self.ey, self.state, self.params, self.next_tls, self.weather
        obs = Observation(
            t=self.t,
            ego=EgoState(ex, ey, state.heading, state.speed, state.vx, state.vy, state.yaw_rate,
                         state.ax, state.road_wheel_angle, params.length, params.width, params.wheelbase),
            lane=self.lane, lane_pos=self.lane_pos, speed_limit=self.limit, objects=self.actors.observed(ex, ey),
            traffic_light=TrafficLightState(*next_tls) if next_tls else None,
            weather=weather, sun_glare=sun_glare(weather, state.heading),
        )
        self.timings["observe"] += perf() - t5
        return obs

    def ads_step(self, obs: Observation) -> None:
        """6. ADS.step(observation) -> the Control, kept for the physics and the next frame's record."""
        perf = time.perf_counter
        t6 = perf()
        try:
            control = self.ads.step(obs)
            self.steer, self.throttle, self.brake = float(control.steer), float(control.throttle), float(control.brake)
        except (Exception, SystemExit) as exc:  # sys.exit() too: the plugin is named
            raise _plugin_error("ADS", self.ads_name, exc, f"at frame {self.fidx}") from exc
        self.timings["ads"] += perf() - t6

    def move_ego(self) -> None:
        """7-8. Integrate the Control with the friction under each axle and wind; place the ego in SUMO."""
        perf = time.perf_counter
        t7 = perf()
        wind_amp, half_len, edge = self.wind_amp, self.half_len, self.edge
        wind = wind_amp * math.sin(2.0 * math.pi * self.t / 7.0 + self.wind_phase) if wind_amp else 0.0
        state = self.physics.step(self.steer, self.throttle, self.brake, self.dt, self.mu_f, self.mu_r, wind)
        ch, sh = math.cos(state.heading), math.sin(state.heading)
        nx, ny = state.x + half_len * ch, state.y + half_len * sh
        angle = (90.0 - math.degrees(state.heading)) % 360.0
        hint = edge if edge and not edge.startswith(":") else ""
        self.sim.vehicle.moveToXY(EGO_ID, hint, -1, nx, ny, angle, 2, MATCH_RADIUS)
        self.timings["physics"] += perf() - t7

    def step_sumo(self) -> None:
        """9-10. Per-step actor commands (linear, maneuver schedules, jaywalking), then step SUMO."""
        perf = time.perf_counter
        t9 = perf()
        self.driver.step(self.t, self.vids, self.pids,
                         (self.ex, self.ey, self.ch, self.sh, self.state.speed, self.half_len))
        self.sim.simulationStep()
        self.timings["sumo"] += perf() - t9
        if self.view is not None:
            self.view.after_step(self.sim, self.t + self.dt)

    def finish(self, termination: Termination) -> Execution:
        """Freeze the trace, run the oracles' end-of-run checks, and return the Execution."""
        perf = time.perf_counter
        params, timings, misbehaviors = self.params, self.timings, self.misbehaviors
        t_end = perf()
        meta = {
            "step_length": self.dt, "ego_length": params.length, "ego_width": params.width,
            "wheelbase": params.wheelbase, "steering_ratio": params.steering_ratio,
            "scenario_hash": self.scenario.content_hash(), "termination": termination.value,
            "goal_xy": [self.gx, self.gy], "route": list(self.planned), "drivefuzz": drivefuzz.__version__,
        }
        with _blame("ADS", self.ads_name, "at the end of the run"):
            ads_info = self.ads.trace_info()
        if ads_info is not None:  # an ADS's own record of its decisions (adapters: every planning cycle)
            meta["ads_info"] = ads_info
        trace = self.recorder.freeze(meta)
        timings["record"] += perf() - t_end
        t_end = perf()
        for oracle, name in zip(self.oracles, self.oracle_names):
            with _blame("oracle", name, "at the end of the run"):
                misbehaviors.extend(oracle.on_end(trace, termination))
        timings["oracles"] += perf() - t_end
        wall = time.perf_counter() - self.wall0
        return Execution(self.scenario, trace, termination, tuple(misbehaviors), wall, timings)
