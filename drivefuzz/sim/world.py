"""The world around the ego during an execution: actors' behaviour and poses, puddles, weather, obstacles.

Used only by :mod:`drivefuzz.sim.execute`, which passes in the simulation module
(libsumo, or traci for ``--gui``); nothing here imports either.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import chain, compress, repeat
from typing import Sequence

import numpy as np

from drivefuzz.ads import OBSERVATION_RADIUS, ObjectState
from drivefuzz.oracle import Obstacle
from drivefuzz.scenario import ActorKind, Maneuver, ManeuverAction, NavType, Scenario, Trigger
from drivefuzz.scenario.model import CAREFUL_DECEL, CAREFUL_REACTION, FOLLOW_GAP, MIN_CLOSE_TTC, cut_in_gap, in_lane
from drivefuzz.sim.trace import Recorder

#: POI/polygon types the collision oracle treats as solid (a user's polygon file may use them).
OBSTACLE_TYPES = ("building", "obstacle", "barrier", "pole", "fence", "wall", "drivefuzz.obstacle")


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


class Puddles:
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


#: SUMO speedFactor of maneuver actors: their programs may drive them above the lane's limit (up to 1.3 x)
MANEUVER_SPEED_FACTOR = 1.3
#: [m], [s]: a gap or headway trigger within this of its value fires at its first look
GAP_TOLERANCE, HEADWAY_TOLERANCE = 0.5, 0.05
#: [m] gap and headway triggers fire only while the actor is at most this far to the side of the ego
TRIGGER_LATERAL = 10.0
#: [m] sideways, and [m] left over: a program's vehicle that appears on the ego's path must leave this
POP_UP_LATERAL, POP_UP_MARGIN = 2.5, 2.0
#: [m/s^2] SUMO's default deceleration and acceleration of a passenger car (a program may ask for more)
SUMO_DECEL, SUMO_ACCEL = 4.5, 2.6
#: SUMO's speed modes: its default (every check on), and a close step's (the safe speed to the leader off; the
#: limits of acceleration and braking, right of way and red lights kept)
SUMO_SPEED_MODE, CLOSE_SPEED_MODE = 31, 30
#: [m] how far ahead a close step looks for its leader, and [m] the gap at which it brakes whatever its TTC
CLOSE_LOOK, CLOSE_GAP = 150.0, 3.0


def _room_to_shed(shed: float) -> float:
    """[m] a careful driver needs ahead to shed ``shed`` [m/s] (react, then brake), with POP_UP_MARGIN left."""
    return shed * CAREFUL_REACTION + shed * shed / (2.0 * CAREFUL_DECEL) + POP_UP_MARGIN


@dataclass
class _Program:
    """Where a maneuver actor is in its program."""

    k: int = 0  # the next step
    fired: float = 0.0  # [s] when the step before fired (the departure for the first)
    above: bool | None = None  # whether the gap or headway was above the next step's ``at`` at the last look
    armed: bool = False  # the gap or headway has reached the next step's ``at`` (it fires when it may)
    ramp: tuple[float, float] | None = None  # (target speed [m/s], rate [m/s^2]) of a speed step under way
    nudge: tuple[float, float, float] | None = None  # (start [s], duration [s], signed depth [m], left > 0)
    close: float | None = None  # [s] a close step under way: the time to collision at which it brakes


class ActorDriver:
    """Applies the behaviour carried in the scenario's params to SUMO actors each step.

    Maneuver actors run their programs (:class:`~drivefuzz.scenario.Maneuver` steps, in order): speed steps
    at SUMO's own or a given rate; lane changes in SUMO's continuous lane-change model, taking the step's
    duration (the lateral speed is the lane's width over it); nudges (aborted lane changes) as a lateral
    offset in the lane, out and back along a sine. A step timed against the ego forces its lane change
    (lane-change mode 0): the trigger, chosen fair by the mutator, is what keeps the gap.
    """

    def __init__(self, sim, scenario: Scenario, rmap):
        self.sim = sim
        self.rmap = rmap
        self.spec = {a.id: a for a in scenario.actors}
        self.started: set[str] = set()
        self.programs: dict[str, _Program] = {}
        #: pedestrians the executor moves itself: [x, y, ux, uy, remaining [m], speed of the last step [m/s]]
        self.walkers: dict[str, list[float]] = {}
        self.dt = scenario.sim.step_length

    def on_depart(self, actor_id: str, t: float, ego=None) -> bool:
        """Start what ``actor_id`` does, in the frame it appeared; False when it was removed instead: a
        program's vehicle that appeared where a careful ego could not react (see :meth:`_pops_up`), or a
        vehicle that entered late in the ego's way (:meth:`_late_in_the_way`). ``ego``: as for :meth:`step`."""
        a = self.spec.get(actor_id)
        if a is None or actor_id in self.started:
            return True
        self.started.add(actor_id)
        sim = self.sim
        if a.kind is ActorKind.VEHICLE and ego is not None and (
                (a.nav is NavType.MANEUVER and self._pops_up(actor_id, a, ego))
                or self._late_in_the_way(actor_id, a, ego)):
            sim.vehicle.remove(actor_id)
            return False
        if a.kind is ActorKind.VEHICLE:
            if a.nav is NavType.LINEAR:
                sim.vehicle.setSpeedMode(actor_id, 0)
                sim.vehicle.setLaneChangeMode(actor_id, 0)
                sim.vehicle.setSpeed(actor_id, a.speed)
            elif a.nav is NavType.AUTOPILOT:
                sim.vehicle.setMaxSpeed(actor_id, max(a.speed, 0.1))
            elif a.nav is NavType.MANEUVER:
                sim.vehicle.setMaxSpeed(actor_id, max(a.speed, 0.1))
                sim.vehicle.setSpeedFactor(actor_id, MANEUVER_SPEED_FACTOR)
                # SUMO keeps a car from passing on the right (it matches the speed of one on its left): an
                # overtaker must be free to pass on either side
                sim.vehicle.setParameter(actor_id, "laneChangeModel.lcOvertakeRight", "1")
                if sim.vehicle.getSpeed(actor_id) > a.speed:  # inserted at the lane's limit: enter at its own
                    sim.vehicle.setPreviousSpeed(actor_id, a.speed)
                sim.vehicle.setLaneChangeMode(actor_id, 512)
                self.programs[actor_id] = _Program(fired=t)
        elif a.nav in (NavType.IMMOBILE, NavType.LINEAR):
            # SUMO puts a person's stop beside the lane (~3 m off a 2 m sidewalk): stand on the lane instead
            x, y, h = self.rmap.geom(a.start_lane).position(a.start_pos)
            # (moved every step: a person moved once leaves its stop and vanishes)
            ux, uy, d = math.cos(h), math.sin(h), 0.0
            if a.nav is NavType.LINEAR and a.dest_xy is not None:
                dx, dy = a.dest_xy[0] - x, a.dest_xy[1] - y
                d = math.hypot(dx, dy)
                if d > 0.0:
                    ux, uy = dx / d, dy / d
            self.walkers[actor_id] = [x, y, ux, uy, d, 0.0]
            sim.person.moveToXY(actor_id, "", x, y, (90.0 - math.degrees(math.atan2(uy, ux))) % 360.0, 2)
        elif a.nav is NavType.AUTOPILOT:
            sim.person.setSpeed(actor_id, max(a.speed, 0.05))
        return True

    def _pops_up(self, vid: str, a, ego) -> bool:
        """Whether a program's vehicle appeared on or across the ego's path (within 2.5 m to its side) nearer
        than a careful driver needs to shed the speed difference, or overlapping the ego. The mutator times
        departures with its profile of how the reference ADS drives; another ADS (or a mutant) is elsewhere."""
        gap, lateral, _, length = self._from_ego(vid, ego)
        if abs(lateral) > POP_UP_LATERAL:
            return False
        if gap < 0.0:
            return gap + length + 2 * ego[5] > 0.0  # beside the ego's body (behind it is no pop-up)
        return gap < _room_to_shed(max(ego[4] - a.speed, 0.0))

    def _late_in_the_way(self, vid: str, a, ego) -> bool:
        """Whether a vehicle that SUMO inserted late (its spot was taken when it was due, see
        ``MAX_DEPART_DELAY``) appeared where the mutator's fairness rules, which placed it for its departure
        time, no longer hold: ahead on the ego's path nearer than a careful driver needs to shed the speed
        difference, beside the ego's body, or behind it and closing faster than it can stop (a linear vehicle
        never brakes). On a highway the ego covers 25 m in a second: a car placed ahead of it at the start
        and held back 0.7 s entered right behind it at 26 m/s."""
        if self.sim.vehicle.getDepartDelay(vid) <= self.dt + 1e-6:
            return False
        gap, lateral, _, length = self._from_ego(vid, ego)
        if abs(lateral) > POP_UP_LATERAL:
            return False
        speed = a.speed if a.nav is NavType.LINEAR else self.sim.vehicle.getSpeed(vid)
        if gap >= 0.0:
            return gap < _room_to_shed(max(ego[4] - speed, 0.0))
        behind = -(gap + length + 2 * ego[5])  # [m] from its front bumper to the ego's rear
        closing = speed - ego[4]
        if behind < 0.0:  # beside the ego's body
            return True
        if closing <= 0.0:
            return False
        return a.nav is NavType.LINEAR or behind < closing * closing / (2.0 * SUMO_DECEL) + POP_UP_MARGIN

    def _from_ego(self, vid: str, ego) -> tuple[float, float, float, float]:
        """(gap [m] from the ego's front to the vehicle's rear along the ego's heading, negative when it is
        not ahead; its centre's offset [m] to the ego's left; its heading [rad]; its length [m])."""
        ex, ey, ch, sh, _, half = ego
        fx, fy = self.sim.vehicle.getPosition(vid)  # the front bumper
        h = math.radians(90.0 - self.sim.vehicle.getAngle(vid))
        length = self.sim.vehicle.getLength(vid)
        dx, dy = fx - 0.5 * length * math.cos(h) - ex, fy - 0.5 * length * math.sin(h) - ey
        return ch * dx + sh * dy - 0.5 * length - half, -sh * dx + ch * dy, h, length

    def step(self, t: float, alive_vehicles: Sequence[str], alive_persons: Sequence[str],
             ego: tuple[float, float, float, float, float, float] | None = None) -> None:
        """One step's actor commands. ``ego``: (x, y, cos, sin of its heading, speed, half its length) [m, m/s],
        for the program steps timed against it."""
        sim = self.sim
        if self.programs:
            alive = set(alive_vehicles)
            for vid, p in self.programs.items():
                if vid not in alive:
                    continue
                steps = self.spec[vid].maneuvers
                while p.k < len(steps) and self._due(vid, steps[p.k], p, t, ego):
                    self._start(vid, steps[p.k], p, t)
                    p.k += 1
                    p.fired, p.above, p.armed = t, None, False
                if p.ramp is not None:
                    self._ramp(vid, p)
                if p.nudge is not None:
                    self._nudge(vid, p, t)
                if p.close is not None:
                    self._close(vid, p)
        if self.walkers:
            alive = set(alive_persons)
            for pid, w in list(self.walkers.items()):
                if pid not in alive:
                    del self.walkers[pid]
                    continue
                if w[4] <= 0.0 and self.spec[pid].nav is NavType.LINEAR:
                    # at its target: a jaywalker leaves the road (standing on it for ever blocked the traffic)
                    sim.person.remove(pid)
                    del self.walkers[pid]
                    continue
                step = min(self.spec[pid].speed * self.dt, w[4])
                w[0] += w[2] * step
                w[1] += w[3] * step
                w[4] -= step
                w[5] = step / self.dt
                angle = (90.0 - math.degrees(math.atan2(w[3], w[2]))) % 360.0
                sim.person.moveToXY(pid, "", w[0], w[1], angle, 2)

    def _due(self, vid: str, m: Maneuver, p: _Program, t: float, ego) -> bool:
        """Whether step ``m`` of ``vid``'s program fires at ``t`` (see :class:`~drivefuzz.scenario.Trigger`)."""
        depart = self.spec[vid].depart
        if m.trigger is Trigger.TIME:
            return t - depart >= m.time - 1e-9
        if m.trigger is Trigger.AFTER:
            return t - p.fired >= m.time - 1e-9
        if ego is None or t - depart < m.time - 1e-9:
            return False
        gap, lateral, h, _ = self._from_ego(vid, ego)
        if abs(lateral) > TRIGGER_LATERAL:
            return False
        _, _, ch, sh, speed, _ = ego
        def closing() -> float:  # [m/s] the ego closes in on it along the ego's heading
            return speed - self.sim.vehicle.getSpeed(vid) * math.cos(h - math.atan2(sh, ch))

        if m.trigger is Trigger.PEAK:  # the gap half the nudge later, at this closing speed
            value, tol = gap - closing() * m.value / 2.0, GAP_TOLERANCE
        else:
            value, tol = (gap, GAP_TOLERANCE) if m.trigger is Trigger.GAP else (gap / max(speed, 1.0), HEADWAY_TOLERANCE)
        if m.action is ManeuverAction.SPEED:  # ahead of the ego, and the ego at ``at`` or nearer
            return gap > 0.0 and value <= m.at
        above = value > m.at
        if (p.above is not None and above != p.above) or abs(value - m.at) <= tol:
            p.armed = True
        p.above = above
        lane = self.sim.vehicle.getLaneID(vid)
        if not p.armed or not lane or lane.startswith(":"):  # no lane change inside a junction: after it
            return False
        if m.trigger is Trigger.PEAK:  # a drift inside its own lane takes none of the ego's room; anything else
            return m.action in (ManeuverAction.NUDGE_LEFT, ManeuverAction.NUDGE_RIGHT) and in_lane(  # never starts
                m.depth, self.sim.lane.getWidth(lane), self.sim.vehicle.getWidth(vid))
        # fair by construction: never into less room than a careful driver needs at the real closing speed
        # (the NPC may be slower than its program says: stopped at the end of a merge lane, in a queue)
        return gap >= cut_in_gap(closing(), max(m.value, self.dt))

    def _start(self, vid: str, m: Maneuver, p: _Program, t: float) -> None:
        sim = self.sim
        if m.action is ManeuverAction.SPEED:
            if m.rate > 0.0:
                p.ramp = (m.value, m.rate)
                sim.vehicle.setDecel(vid, max(SUMO_DECEL, m.rate))
                sim.vehicle.setAccel(vid, max(SUMO_ACCEL, m.rate))
            else:
                p.ramp = None
                sim.vehicle.setSpeed(vid, m.value)
        elif m.action in (ManeuverAction.NUDGE_LEFT, ManeuverAction.NUDGE_RIGHT):
            side = 1.0 if m.action is ManeuverAction.NUDGE_LEFT else -1.0
            p.nudge = (t, max(m.value, 2 * self.dt), side * m.depth)
        elif m.action is ManeuverAction.FOLLOW:
            sim.vehicle.setTau(vid, max(m.value, self.dt))  # a user's file may ask for 0: SUMO wants a step at least
            sim.vehicle.setMinGap(vid, FOLLOW_GAP)
        elif m.action is ManeuverAction.CLOSE:
            p.close = max(m.at, MIN_CLOSE_TTC)
            sim.vehicle.setSpeedMode(vid, CLOSE_SPEED_MODE)  # SUMO's safe speed off: it does not brake for the leader
            sim.vehicle.setSpeed(vid, self.spec[vid].speed)
        else:
            lane = sim.vehicle.getLaneID(vid)
            if not lane or lane.startswith(":"):
                return
            idx = sim.vehicle.getLaneIndex(vid) + (1 if m.action is ManeuverAction.LANE_LEFT else -1)
            if 0 <= idx < sim.edge.getLaneNumber(sim.lane.getEdgeID(lane)):
                duration = max(m.value, self.dt)
                sim.vehicle.setMaxSpeedLat(vid, sim.lane.getWidth(lane) / duration)
                if m.trigger in (Trigger.GAP, Trigger.HEADWAY):
                    sim.vehicle.setLaneChangeMode(vid, 0)
                sim.vehicle.changeLane(vid, idx, duration)

    def _ramp(self, vid: str, p: _Program) -> None:
        """One step of a speed step with a rate: the commanded speed moves ``rate * dt`` towards the target."""
        target, rate = p.ramp
        v = self.sim.vehicle.getSpeed(vid)
        dv = rate * self.dt
        v = min(v + dv, target) if v < target else max(v - dv, target)
        self.sim.vehicle.setSpeed(vid, v)
        if v == target:
            p.ramp = None

    def _close(self, vid: str, p: _Program) -> None:
        """One step of a close step: once the time to collision with the vehicle ahead (whoever it is) is
        ``p.close`` or less, or its gap under :data:`CLOSE_GAP`, SUMO's car-following takes over again and brakes."""
        sim = self.sim
        leader = sim.vehicle.getLeader(vid, CLOSE_LOOK)
        if leader is not None and leader[0]:
            gap = leader[1] + sim.vehicle.getMinGap(vid)  # SUMO's leader gap leaves out the minGap
            closing = sim.vehicle.getSpeed(vid) - sim.vehicle.getSpeed(leader[0])
            if gap < CLOSE_GAP or (closing > 0.0 and gap / closing <= p.close):
                sim.vehicle.setSpeedMode(vid, SUMO_SPEED_MODE)
                sim.vehicle.setSpeed(vid, -1.0)  # back to its car-following (and the time gap of a follow step)
                p.close = None

    def _nudge(self, vid: str, p: _Program, t: float) -> None:
        t0, duration, depth = p.nudge
        u = (t - t0) / duration
        if u >= 1.0:
            p.nudge = None
            self.sim.vehicle.setLateralLanePosition(vid, 0.0)
        else:
            self.sim.vehicle.setLateralLanePosition(vid, depth * math.sin(math.pi * u))


def tls_link_table(sim) -> dict[str, tuple[tuple[str, ...], list[tuple[str, int, str, str]]]]:
    """lane id -> (its lights, [(tls, link index, to lane, via)]) for every signalised link."""
    table: dict[str, list[tuple[str, int, str, str]]] = {}
    for tls in sim.trafficlight.getIDList():
        for idx, links in enumerate(sim.trafficlight.getControlledLinks(tls)):
            for in_lane, out_lane, via in links:
                table.setdefault(in_lane, []).append((tls, idx, out_lane, via))
    return {lane: (tuple(dict.fromkeys(l[0] for l in links)), links) for lane, links in table.items()}


def static_obstacles(sim) -> list[Obstacle]:
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


_NONE = np.empty(0)
_NONE.setflags(write=False)  # the arrays of a frame without actors, shared


class Actors:
    """Every other actor's pose, read each step into arrays (geometric centres, ENU radians).

    With libsumo the module-level C getters are called directly (``_libsumo.vehicle_getAngle``),
    which skips one Python wrapper call per value; with traci (``--gui``) the usual ones.
    """

    def __init__(self, sim, recorder: Recorder, driver: ActorDriver):
        self.sim, self.recorder, self.driver = sim, recorder, driver
        raw = getattr(sim, "_libsumo", None)
        self.raw = raw is not None and hasattr(raw, "vehicle_getPosition")
        src = ((raw.vehicle_getPosition, raw.person_getPosition, raw.vehicle_getAngle, raw.person_getAngle,
                raw.vehicle_getSpeed, raw.person_getSpeed) if self.raw else
               (sim.vehicle.getPosition, sim.person.getPosition, sim.vehicle.getAngle, sim.person.getAngle,
                sim.vehicle.getSpeed, sim.person.getSpeed))
        self.v_pos, self.p_pos, self.v_angle, self.p_angle, self.v_speed, self.p_speed = src
        self.sizes: dict[str, tuple[float, float, int]] = {}  # id -> length, width, recorder index
        self.key: tuple = ((), ())  # (vehicle ids, person ids) of the last read
        self._set_ids((), ())

    def _set_ids(self, vehicles: Sequence[str], persons: Sequence[str]) -> None:
        sim, rec, sizes = self.sim, self.recorder, self.sizes
        rows = []
        for kind, domain, ids in (("vehicle", sim.vehicle, vehicles), ("pedestrian", sim.person, persons)):
            for aid in ids:
                info = sizes.get(aid)
                if info is None:  # sizes are fixed: read them once per actor
                    length, width = domain.getLength(aid), domain.getWidth(aid)
                    info = sizes[aid] = (length, width, rec.actor_index(aid, kind, length, width))
                rows.append(info)
        self.ids = list(vehicles) + list(persons)
        self.kinds = ["vehicle"] * len(vehicles) + ["pedestrian"] * len(persons)
        a = np.asarray(rows, dtype=float).reshape(-1, 3)
        self.length, self.width, self.index = a[:, 0].copy(), a[:, 1].copy(), a[:, 2].copy()
        self.length_list, self.width_list = self.length.tolist(), self.width.tolist()
        self.half_list = [0.5 * length for length in self.length_list]
        self.index_list = [int(i) for i in self.index.tolist()]
        self.row = {aid: k for k, aid in enumerate(self.ids)}

    def read(self, vehicles: Sequence[str], persons: Sequence[str]):
        """(x, y, heading, speed) arrays aligned with ``self.ids`` for this step.

        Plain Python on lists, then one array per column: for a few dozen actors between two
        SUMO steps this is cheaper than numpy arithmetic, and it leaves SUMO's data in the
        cache (numpy's code paths measurably slow the next SUMO step down).
        """
        key = (vehicles, persons)
        if key != self.key:
            self.key = key
            self._set_ids(vehicles, persons)
        if not self.ids:
            self.lists = ([], [], [], [])
            return _NONE, _NONE, _NONE, _NONE
        if self.raw:  # the C getters take (id, includeZ)
            pos = chain(map(self.v_pos, vehicles, repeat(False)), map(self.p_pos, persons, repeat(False)))
        else:
            pos = chain(map(self.v_pos, vehicles), map(self.p_pos, persons))
        deg = math.pi / 180.0
        hs = [(90.0 - a) * deg for a in chain(map(self.v_angle, vehicles), map(self.p_angle, persons))]
        vs = list(chain(map(self.v_speed, vehicles), map(self.p_speed, persons)))
        cos, sin = math.cos, math.sin
        xs, ys = [], []
        for (px, py), half, h in zip(pos, self.half_list, hs):  # SUMO positions are front bumpers
            xs.append(px - half * cos(h))
            ys.append(py - half * sin(h))
        if self.driver.walkers:  # SUMO's speed of a person moved by moveToXY is not its walking speed
            for pid, w in self.driver.walkers.items():
                k = self.row.get(pid)
                if k is not None:
                    vs[k] = w[5]
        self.lists = (xs, ys, hs, vs)
        return np.array(xs), np.array(ys), np.array(hs), np.array(vs)

    def observed(self, ex: float, ey: float) -> tuple[ObjectState, ...]:
        """The actors of the last :meth:`read` within :data:`OBSERVATION_RADIUS` of (ex, ey), for the ADS."""
        xs, ys, hs, vs = self.lists
        if not xs:
            return ()
        r2 = OBSERVATION_RADIUS ** 2
        near = [(x - ex) * (x - ex) + (y - ey) * (y - ey) < r2 for x, y in zip(xs, ys)]
        rows = compress(zip(self.ids, self.kinds, xs, ys, hs, vs, self.length_list, self.width_list), near)
        # tuple.__new__ makes the same ObjectState as its constructor without its Python-level __new__
        # (a third of this method's time at 16 objects)
        return tuple(map(tuple.__new__, repeat(ObjectState), rows))
