"""Situations from a catalogue: new components that recreate pre-crash scenarios, not only random placements.

The field's catalogue is the NHTSA pre-crash scenario typology (Najm, Smith and Yanagisawa, 2007: 37
scenarios that cover most light-vehicle crashes). Each :class:`Situation` here builds one of them around
the ego's mission, timed with the mutator's profile of how the ego drives the route, and every actor it
adds passes the fairness rules (:mod:`drivefuzz.search.fairness`). ``docs/catalogue.md`` lists which of
the 37 are covered and why the others are not.

A situation returns the scenario unchanged (with a description saying why) when the mission does not
offer what it needs (a second lane, a junction ahead, a sidewalk).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Callable, NamedTuple

from drivefuzz.scenario import Actor, ActorKind, Maneuver, ManeuverAction, NavType, Puddle, Scenario, SignalShift
from drivefuzz.scenario.roadmap import PASSENGER, PEDESTRIAN
from drivefuzz.scenario.signals import connection_state, phase_starts, shiftable
from drivefuzz.search.fairness import lane_limit, unfair
from drivefuzz.search.mutate import Mutation, Mutator


class Built(NamedTuple):
    """What a situation's builder adds (it returns a plain 4- or 5-tuple of these)."""

    actors: list[Actor]
    puddles: list[Puddle]
    weather: dict  # an update of the scenario's weather
    description: str
    signals: tuple[SignalShift, ...] = ()  # shifted traffic lights


@dataclass(frozen=True)
class Situation:
    name: str
    nhtsa: str  # the pre-crash scenario it recreates (Najm et al. 2007)
    #: the fields of :class:`Built`, or None when not possible this time
    build: Callable[[Mutator, Scenario, random.Random], tuple | None]


def add_situation(mut: Mutator, sc: Scenario, situation: Situation, rng: random.Random) -> Mutation:
    """``sc`` with ``situation`` added (retried up to ``max_retries``), or unchanged with the reason."""
    for attempt in range(mut.cfg.max_retries):
        built = situation.build(mut, sc, rng)
        if built is None:
            continue
        actors, puddles, weather, desc, shifts = Built(*built)
        shifts = tuple(shifts)
        new = sc
        ok = True
        for actor in actors:
            if len(new.actors) >= mut.cfg.max_actors or unfair(mut, new, actor):
                ok = False
                break
            x, y, _ = mut.rmap.geom(actor.start_lane).position(actor.start_pos)
            if not mut._separated(new, x, y):
                ok = False
                break
            new = new.model_copy(update={"actors": new.actors + (actor,)})
        if not ok or len(new.puddles) + len(puddles) > mut.cfg.max_puddles:
            continue
        update: dict = {"actors": new.actors, "puddles": sc.puddles + tuple(puddles)}
        if weather:
            update["weather"] = sc.weather.model_copy(update=weather)
        if shifts:  # a new shift of a light replaces the one it had
            moved = {s.tls for s in shifts}
            update["signals"] = tuple(s for s in sc.signals if s.tls not in moved) + shifts
        return Mutation(sc.model_copy(update=update), f"situation {situation.name}: {desc}", attempt)
    return Mutation(sc, f"situation {situation.name}: not possible on this mission", mut.cfg.max_retries)


# ------------------------------------------------------------------ where the ego will be
def _route_spot(mut: Mutator, sc: Scenario, dist: float) -> tuple[int, str, float] | None:
    """(route index, the lane the ego will drive, position [m]) ``dist`` metres along its route."""
    route = mut._route(sc)
    pos = sc.mission.start_pos + dist
    for i, e in enumerate(route):
        length = mut.rmap.edge(e).getLength()
        if pos <= length:
            return i, mut.ego_lane(sc, i), round(min(max(pos, 1.0), length - 0.5), 2)
        pos -= length
    return None


def _dest(mut: Mutator, sc: Scenario) -> str:
    return mut._route(sc)[-1]


def _ahead(mut: Mutator, sc: Scenario, rng: random.Random, lo: float, hi: float):
    cfg = mut.cfg
    return _route_spot(mut, sc, rng.uniform(max(lo, cfg.immobile_min_range), max(hi, cfg.immobile_min_range + 1)))


# ------------------------------------------------------------------ the situations
def lead_stopped(mut, sc, rng):
    spot = _ahead(mut, sc, rng, 30.0, 120.0)
    if spot is None:
        return None
    _, lane, pos = spot
    a = Actor(id=mut._new_id(sc, "v"), kind=ActorKind.VEHICLE, nav=NavType.IMMOBILE, start_lane=lane, start_pos=pos,
              speed=0.0)
    return [a], [], {}, f"stopped vehicle {a.id} on the ego's lane {lane} @ {pos:.1f} m"


def stopped_in_fog(mut, sc, rng):
    built = lead_stopped(mut, sc, rng)
    if built is None:
        return None
    fog = round(rng.uniform(60.0, 100.0), 1)
    return built[0], [], {"fog": fog}, built[3] + f", fog {fog}"


def lead_slower(mut, sc, rng):
    spot = _ahead(mut, sc, rng, 15.0, 80.0)
    if spot is None:
        return None
    _, lane, pos = spot
    speed = round(lane_limit(mut, lane) * rng.uniform(0.15, 0.5), 2)
    a = Actor(id=mut._new_id(sc, "v"), kind=ActorKind.VEHICLE, nav=NavType.AUTOPILOT, start_lane=lane,
              start_pos=pos, speed=speed, dest_edge=_dest(mut, sc))
    return [a], [], {}, f"slow vehicle {a.id} at {speed:.1f} m/s on {lane} @ {pos:.1f} m"


def lead_brakes(mut, sc, rng):
    spot = _ahead(mut, sc, rng, 12.0, 50.0)
    if spot is None:
        return None
    _, lane, pos = spot
    speed = round(lane_limit(mut, lane) * rng.uniform(0.6, 1.0), 2)
    t_brake = round(rng.uniform(2.0, 12.0), 2)
    t_go = round(t_brake + rng.uniform(2.0, 6.0), 2)
    a = Actor(id=mut._new_id(sc, "v"), kind=ActorKind.VEHICLE, nav=NavType.MANEUVER, start_lane=lane, start_pos=pos,
              speed=speed, dest_edge=_dest(mut, sc),
              maneuvers=(Maneuver(time=t_brake, action=ManeuverAction.SPEED, value=0.0),
                         Maneuver(time=t_go, action=ManeuverAction.SPEED, value=speed)))
    return [a], [], {}, f"leader {a.id} at {speed:.1f} m/s brakes to a stop at {t_brake} s, drives on at {t_go} s"


def cut_in(mut, sc, rng):
    """A vehicle on the next lane, from the ego's rear quarter or just ahead, changes into the ego's lane."""
    spot = _route_spot(mut, sc, rng.uniform(-25.0, 40.0))
    if spot is None:
        return None
    i, lane, pos = spot
    lanes = [l for l in mut.rmap.lane(lane).getEdge().getLanes() if l.allows(PASSENGER)]
    idx = mut.rmap.lane(lane).getIndex()
    beside = [l for l in lanes if abs(l.getIndex() - idx) == 1]
    if not beside:
        return None
    other = rng.choice(beside)
    toward = ManeuverAction.LANE_RIGHT if other.getIndex() > idx else ManeuverAction.LANE_LEFT
    speed = round(lane_limit(mut, lane) * rng.uniform(0.8, 1.2), 2)
    t_change = round(rng.uniform(1.0, 8.0), 2)
    a = Actor(id=mut._new_id(sc, "v"), kind=ActorKind.VEHICLE, nav=NavType.MANEUVER, start_lane=other.getID(),
              start_pos=round(min(pos, other.getLength() - 0.5), 2), speed=speed, dest_edge=_dest(mut, sc),
              maneuvers=(Maneuver(time=t_change, action=toward, value=round(rng.uniform(1.5, 3.5), 2)),))
    return [a], [], {}, f"{a.id} on {other.getID()} at {speed:.1f} m/s cuts into the ego's lane at {t_change} s"


def hidden_stopped(mut, sc, rng):
    """A leader changes lanes and reveals a stopped vehicle ahead of it."""
    spot = _ahead(mut, sc, rng, 15.0, 40.0)
    if spot is None:
        return None
    i, lane, pos = spot
    idx = mut.rmap.lane(lane).getIndex()
    lanes = [l for l in mut.rmap.lane(lane).getEdge().getLanes() if l.allows(PASSENGER)]
    beside = [l for l in lanes if abs(l.getIndex() - idx) == 1]
    far = _route_spot(mut, sc, (pos - sc.mission.start_pos if i == 0 else 0.0) + rng.uniform(40.0, 90.0))
    if not beside or far is None or far[0] != i:
        return None
    toward = ManeuverAction.LANE_RIGHT if beside[0].getIndex() > idx else ManeuverAction.LANE_LEFT
    speed = round(lane_limit(mut, lane) * rng.uniform(0.5, 0.8), 2)
    lead = Actor(id=mut._new_id(sc, "v"), kind=ActorKind.VEHICLE, nav=NavType.MANEUVER, start_lane=lane,
                 start_pos=pos, speed=speed, dest_edge=_dest(mut, sc),
                 maneuvers=(Maneuver(time=round(rng.uniform(2.0, 6.0), 2), action=toward, value=2.0),))
    stopped = Actor(id=mut._new_id(sc, "v", [lead]), kind=ActorKind.VEHICLE, nav=NavType.IMMOBILE, start_lane=lane,
                    start_pos=far[2], speed=0.0)
    return [lead, stopped], [], {}, f"{lead.id} swerves away from stopped {stopped.id} @ {far[2]:.1f} m on {lane}"


def pulls_out(mut, sc, rng):
    """A parked car pulls out ahead of the ego, timed so that a careful ego can still stop."""
    spot = _ahead(mut, sc, rng, 40.0, 120.0)
    if spot is None:
        return None
    _, lane, pos = spot
    d = pos - sc.mission.start_pos if spot[0] == 0 else mut.rmap.route_length(mut._route(sc)[:spot[0] + 1],
                                                                               sc.mission.start_pos, pos)
    t_there = mut._ego_eta(sc, d)
    depart = round(max(t_there - rng.uniform(1.5, 5.0), 0.5), 1)
    a = Actor(id=mut._new_id(sc, "v"), kind=ActorKind.VEHICLE, nav=NavType.AUTOPILOT, start_lane=lane, start_pos=pos,
              speed=round(lane_limit(mut, lane) * rng.uniform(0.3, 0.7), 2), depart=depart, dest_edge=_dest(mut, sc))
    return [a], [], {}, f"{a.id} pulls out on {lane} @ {pos:.1f} m at {depart} s"


def walker_crosses(mut, sc, rng, early=(0.0, 4.0), at: float | None = None):
    """A pedestrian steps off the sidewalk in front of the ego, timed to meet it (a careful ego can stop): it
    reaches the road ``early`` (a range [s]) before the ego is expected there; 20-100 m along the ego's route, or
    at the route distance ``at`` [m]."""
    if not mut._walkable(sc):
        return None
    d = rng.uniform(20.0, 100.0) if at is None else at
    spot = mut._spot_along(sc, rng, d, PEDESTRIAN)
    if spot is None:
        return None
    speed = round(rng.uniform(0.8, 1.0) * mut.cfg.max_pedestrian_speed, 2)
    side = mut._road_side(spot.lane)
    across = mut._road_width(spot.lane) + rng.uniform(1.0, 3.0)
    to_road = mut.rmap.lane(spot.lane).getWidth() / 2 + 0.5
    t_meet = mut._ego_eta(sc, d)
    depart = round(max(t_meet - to_road / speed - rng.uniform(*early), 0.0), 1)
    a = Actor(id=mut._new_id(sc, "p"), kind=ActorKind.PEDESTRIAN, nav=NavType.LINEAR, start_lane=spot.lane,
              start_pos=spot.pos, speed=speed, depart=depart,
              dest_xy=(round(spot.x - side * math.sin(spot.heading) * across, 2),
                       round(spot.y + side * math.cos(spot.heading) * across, 2)))
    return [a], [], {}, f"{a.id} crosses at {spot.lane} @ {spot.pos:.1f} m, leaving at {depart} s"


def crossing_traffic(mut, sc, rng, keep=None, runs_red: bool | None = False, whole: bool = False,
                     clears: tuple[float, float] | None = None, zone: float = 2.0):
    """A lawful vehicle on another approach to a junction of the ego's route, timed to reach the conflict
    point with the ego: whoever must yield has to (straight crossing paths, left turn across path). With
    ``keep``, only the conflicts (``Mutator._conflicts``' tuples) it accepts (:mod:`drivefuzz.search.aim`).
    With ``runs_red``, a driver who ignores its light (and every other rule), reaching the conflict point
    0.2-1.5 s after the ego: where the ego enters on yellow the cross stream's light is red, and a lawful car there
    waits; ``runs_red`` None: such a driver only where no lawful car's light lets it through as the ego comes.
    With ``whole``, at the junctions of the whole route, not only within ``conflict_range``, and a car that would
    drive longer than :data:`LATE_RUN_UP_S` to the conflict departs later, that long before it meets the ego
    (a junction reached after some 60 s needs 400 m of road upstream on the cross approach otherwise: walked back
    at random through the junctions before it, such a start was on the ego's own route on town's seed 005, where
    the car waited at a light ahead of the ego and never came to the junction it was timed for)."""
    options = mut._conflicts(sc, whole=whole, zone=zone)  # (``zone`` [m]: paths that close, not only crossing)
    if keep is not None:
        options = [o for o in options if keep(o)]
    # where some can, a car whose light lets it through when the ego comes (at a signalised crossing the cross
    # stream's green is the ego's red: a car timed to the ego by the clock alone stops at its light, and meets the
    # ego only as a car waiting there); where none can, such a car is all there is
    if not options:
        return None
    free = [] if runs_red else [o for o in options if not _light_stops(
        mut, sc, o[2], o[3], mut._ego_eta(sc, o[1]) - o[4] / (0.8 * lane_limit(mut, o[2])))]
    if runs_red is None:  # where no car can come lawfully, one that runs its red
        runs_red = not free
    i, s_c, lane_id, dest, d_c, node, _, _ = rng.choice(free or options)
    if clears:  # that long before the ego, through its path ahead of it
        lead = -rng.uniform(*clears)
    else:
        lead = rng.uniform(0.2, 1.5) if runs_red else rng.uniform(-1.0, 1.5)
    t_meet = mut._ego_eta(sc, s_c) + lead
    speed = round(lane_limit(mut, lane_id) * rng.uniform(0.6, 1.0), 2)
    lane_len = mut.rmap.lane(lane_id).getLength()
    back = speed * max(t_meet, 0.5) - d_c
    depart = 0.0
    if whole and back > speed * LATE_RUN_UP_S[1]:  # it enters later, a run-up before the meeting (at full speed)
        run = speed * rng.uniform(*LATE_RUN_UP_S) - d_c
        placed = mut._upstream(lane_id, lane_len, run, rng) if run > 0 else None
        if placed is None or (depart := round(t_meet - (placed[2] + d_c) / speed, 1)) <= 0.0:
            return None
    else:
        placed = mut._upstream(lane_id, lane_len, back, rng) if back > 0 else None
    if placed is None:
        return None
    lane, pos, _ = placed
    route = mut.rmap.route(mut.rmap.lane(lane).getEdge().getID(), dest)
    if not route or (whole and mut.rmap.lane(lane_id).getEdge().getID() not in route):
        return None  # (with whole: a run-up upstream whose way to dest does not come through the conflict)
    a = Actor(id=mut._new_id(sc, "v"), kind=ActorKind.VEHICLE, nav=NavType.LINEAR if runs_red else NavType.AUTOPILOT,
              start_lane=lane, start_pos=pos, speed=speed, dest_edge=dest, depart=depart)
    how = ", running its red" if runs_red else ""
    return [a], [], {}, f"{a.id} meets the ego at junction {node} at ~{t_meet:.1f} s ({speed:.1f} m/s{how})"


#: [s] of driving before it meets the ego, for a crossing car that enters later (:func:`crossing_traffic`)
LATE_RUN_UP_S = (4.0, 8.0)


#: link states at which a lawful driver arriving at the stop line stops (red, red-yellow; at yellow it may go on)
STOP_STATES = "rRu"


def _light_stops(mut, sc, lane_id: str, dest: str, t_line: float) -> bool:
    """Whether a car on ``lane_id`` bound for ``dest`` finds its light red (:data:`STOP_STATES`) at its stop line at
    ``t_line`` [s] (the program as ``sc`` shifts it): it stops there. False where the link has no fixed-time light."""
    conn = next((c for c in mut.rmap.lane(lane_id).getOutgoing() if c.getToLane().getEdge().getID() == dest), None)
    state = None if conn is None else connection_state(str(mut.rmap.path), conn, max(t_line, 0.0), sc.signals)
    return state is not None and state in STOP_STATES


def slippery_braking_zone(mut, sc, rng):
    """A low-friction patch where the ego must brake or turn: before a stop line or in a junction turn."""
    route = mut._route(sc)
    if len(route) < 2:
        return None
    i = rng.randrange(len(route) - 1)
    lane = mut.ego_lane(sc, i)
    geom = mut.rmap.geom(lane)
    if rng.random() < 0.5:  # in the turn: the junction passage after edge i
        conns = mut.rmap.connections(route[i], route[i + 1])
        via = conns[0][2] if conns else ""
        if not via:
            return None
        g = mut.rmap.geom(via)
        x, y, h = g.position(g.length / 2)
        where = f"in the junction after {route[i]}"
    else:  # the last metres before the stop line
        x, y, h = geom.position(max(geom.length - rng.uniform(3.0, 20.0), 0.5))
        where = f"before the stop line of {lane}"
    p = Puddle(x=round(x, 2), y=round(y, 2), length=round(rng.uniform(8.0, 20.0), 2), width=round(rng.uniform(3.0, 6.0), 2),
               rotation=round(h, 3), friction=round(rng.uniform(0.05, 0.35), 2))
    return [], [p], {}, f"puddle mu={p.friction} {where}"


def light_changes(mut, sc, rng):
    """A traffic light of the ego's route turns yellow when the ego is a few seconds from its stop line
    (the dilemma zone), by shifting the light's fixed-time program: stop, or clear the junction before red."""
    lights = mut._signals_ahead(sc)
    if not lights:
        return None
    s_stop, tls, link = lights[0] if rng.random() < 0.7 else rng.choice(lights)  # the first is timed best
    prog = shiftable(str(mut.rmap.path), tls)
    onsets = phase_starts(prog, link, "yY")
    if not onsets:
        return None
    u = rng.uniform(0.0, 4.0)  # [s] before the ego's expected arrival at the stop line
    t_yellow = mut._ego_eta(sc, s_stop) - u
    shift = round((t_yellow - prog.offset - rng.choice(onsets)) % prog.cycle, 2)
    return [], [], {}, f"light {tls} turns yellow ~{u:.1f} s before the ego reaches it (shift {shift} s)", [
        SignalShift(tls=tls, shift=shift)]


SITUATIONS: tuple[Situation, ...] = (
    Situation("lead_stopped", "Lead vehicle stopped", lead_stopped),
    Situation("stopped_in_fog", "Lead vehicle stopped (in fog, beyond the sensors' reach)", stopped_in_fog),
    Situation("lead_slower", "Lead vehicle moving at lower constant speed", lead_slower),
    Situation("lead_brakes", "Lead vehicle decelerating", lead_brakes),
    Situation("cut_in", "Vehicle(s) changing lanes - same direction", cut_in),
    Situation("hidden_stopped", "Lead vehicle stopped, revealed by a leader changing lanes", hidden_stopped),
    Situation("pulls_out", "Vehicle(s) parking - same direction (pulling out)", pulls_out),
    Situation("walker_crosses", "Pedestrian crash without prior vehicle maneuver", walker_crosses),
    Situation("crossing_traffic", "Straight crossing paths / LTAP at non-signalized junctions", crossing_traffic),
    Situation("slippery_braking_zone", "Control loss without prior vehicle action", slippery_braking_zone),
    Situation("light_changes", "Running red light (the ego meets the yellow-to-red change at speed)", light_changes),
)
