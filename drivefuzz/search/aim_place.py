"""Where and when an aimed encounter should happen: the place on the ego's route that a cell's column asks for.

:mod:`drivefuzz.search.aim` builds a component for an unreached interaction-coverage cell. The cell's row says
who the other party is; its column says where or while doing what the ego meets it. :func:`meeting` turns the
column into a place (a distance along the ego's route, as the mutator counts it) and, where the column asks
for a light's phase, a shifted light:

- a junction column (``signal/*``, ``priority``, ``yield``, ``turn_left``, ``turn_right``): the stop line of
  one of the route's junctions with that control or turn (for a turn, 2-8 m past the junction: the turn is
  read from the ego's heading over the 3 s before the encounter); ``signal/amber`` shifts its light so that it
  turns yellow as the ego arrives, ``signal/red`` so that it turns yellow a few seconds before (the ego stops
  and waits at red: what meets it there meets it at a red light);
- a manoeuvre column, read from the mutator's profile of the ego (:meth:`Mutator._ego_profile`, which waits at
  red lights): ``stop_go`` where the ego is expected to stand (a red light; else a light is shifted to red; else
  its start), ``accelerate`` and ``brake`` where it is expected to speed up or slow down, ``cruise`` where it
  holds its speed;
- ``edge``: a place more than 35 m from every junction of the route.

The builders that can be timed to a place take it (:func:`passes`, :func:`follower_at`); the others are kept
only when their actor starts within 50 m before it. Never imports libsumo.
"""

from __future__ import annotations

import math
import random
from typing import Sequence

import numpy as np

from drivefuzz.scenario import ActorKind, Maneuver, ManeuverAction, NavType, Puddle, Scenario, SignalShift, Trigger
from drivefuzz.scenario.model import EGO_LENGTH, EGO_WIDTH, MIN_CLOSE_TTC, MIN_FOLLOW_S, NPC_WIDTH, drift_room
from drivefuzz.scenario.roadmap import PASSENGER
from drivefuzz.scenario.signals import phase_starts, shiftable
from drivefuzz.search import catalogue as cat
from drivefuzz.search import programs as prog
from drivefuzz.search.fairness import lane_limit
from drivefuzz.search.mutate import Mutator
from drivefuzz.sim.world import SUMO_DECEL

#: [m] the element is ``edge`` only this far from a junction (coverage reads a junction within 30 m)
EDGE_CLEAR_M = 35.0
#: [m/s^2] the profile's acceleration above / below which the ego accelerates / brakes (coverage: 0.7, -1.0)
ACCEL, BRAKE = 0.7, -1.0
#: [s] after a standstill within which an aimed acceleration, braking or cruise would be met in stop and go: the
#: 3 s coverage reads a manoeuvre over, and half a second for the encounter's frame
STOP_GO_S = 3.5
#: share of the followers built to close in, and [s] the time gaps they follow at (``follow`` steps)
TAILGATE_SHARE, TAILGATE_S = 0.5, (MIN_FOLLOW_S, 0.9)
#: [s] the time to collision at which a close-in follower brakes (a close step, ``MIN_CLOSE_TTC`` at least)
CLOSE_TTC = (MIN_CLOSE_TTC, 2.5)
#: [m] a cruise or acceleration aimed at keeps this far from a ring or ramp edge (on one it counts as the
#: roundabout or merge column: a car behind the ego cruising the roundabout's ring was ``behind|roundabout``)
RING_MARGIN_M = 10.0
#: [m/s^2] how hard a car that enters to stand (:func:`stopped_past`) stops: at once, just after it entered
STAND_DECEL = 8.0
JUNCTION_COLUMNS = ("signal/green", "signal/amber", "signal/red", "priority", "yield", "turn_left", "turn_right")


#: [m] route distances where the ego is still pulling away from a standing start (``stop_go`` where the route has
#: no stop and no light to turn red)
START_SPOTS_M = (5.0, 10.0, 15.0)
#: [m] from the ego's start that a ring edge must begin for a car to stand on it (:func:`stopped_on_ring`)
RING_ENTRY_CLEAR_M = 10.0


def meeting(mut: Mutator, sc: Scenario, col: str, rng: random.Random) -> tuple[Scenario, float | None, str]:
    """(the scenario, with a light shifted where the column asks for its phase; the route distance [m] where the
    encounter should happen, None when the column does not say or the route has no such place; what was done)."""
    from drivefuzz.search.aim import _junction_spots, _marks

    marks = _marks(mut, sc)
    if col in JUNCTION_COLUMNS:
        spots = _junction_spots(marks, col) or []
        if not spots:
            return sc, None, ""
        at = rng.choice(spots)
        if col in ("turn_left", "turn_right"):  # just out of the junction: the ego's heading has turned
            return sc, at + rng.uniform(2.0, 8.0), ""
        if col.startswith("signal/"):
            new, desc = shift_light(mut, sc, at, col, rng)
            return (new, at, desc) if new is not None else (sc, None, "")
        return sc, at, ""
    if col == "edge":
        goal = _goal(mut, sc)
        junctions = [s for s, *_ in marks["junctions"]]
        free = [d for d in np.arange(5.0, 0.8 * goal, 5.0) if all(abs(d - s) > EDGE_CLEAR_M for s in junctions)]
        return sc, (float(rng.choice(free)) if free else None), ""
    if col not in ("stop_go", "accelerate", "brake", "cruise"):
        return sc, None, ""
    spots = profile_spots(mut, sc, col)
    if col in ("accelerate", "cruise"):  # on a ring or a ramp these are the roundabout and merge columns instead
        special = marks["rings"] + marks["ramps"]
        spots = [d for d in spots if not any(s0 - RING_MARGIN_M <= d <= s1 + RING_MARGIN_M for s0, s1 in special)]
    if col == "stop_go" and not spots:  # nowhere to stand: a light of the route turns red as the ego comes
        lights = [s for s, _, c, _, _ in marks["junctions"] if c == "signal"]
        if lights:
            at = rng.choice(lights)
            new, desc = shift_light(mut, sc, at, "signal/red", rng)
            if new is not None:
                return new, at, desc
        spots = [d for d in START_SPOTS_M if d < _goal(mut, sc)]  # its start
    return sc, (float(rng.choice(spots)) if spots else None), ""


def lane_change_moves(mut: Mutator, sc: Scenario) -> list[tuple[float, str, str, str]]:
    """(route distance [m], side ``left`` / ``right``, from lane, to lane) of each lane change the route makes the
    ego do: on each route edge where the lane it enters by (:meth:`Mutator.ego_entry_lane`) does not lead on, to
    the nearest lane that does, at :meth:`Mutator.lane_change_at`."""
    rmap, route = mut.rmap, mut._route(sc)
    out, s = [], -sc.mission.start_pos
    for i, e in enumerate(route[:-1]):
        at = mut.lane_change_at(sc, i)
        if at is not None:
            frm, to = mut.ego_entry_lane(sc, i), mut.ego_lane_at(sc, i, at)
            side = "left" if rmap.lane(to).getIndex() > rmap.lane(frm).getIndex() else "right"
            out.append((max(s + at, 1.0), side, frm, to))
        s += rmap.edge(e).getLength()
    return out


#: how a start on another lane says so (a job stops building them after a few misses: campaign/aiming.py)
SHIFTED_START = "the ego starts on"
#: [m] from the ego's start to its start edge's end that a start on another lane needs: the reference ADS changes
#: lanes across the middle of what is left (ego/planning.py), done this far on at least 25 m before the stop line
START_SHIFT_ROOM_M = 60.0


def shifted_start(mut: Mutator, sc: Scenario, rng: random.Random,
                  room: tuple[float, float] | None = None) -> tuple[Scenario, str] | None:
    """(``sc`` with the ego starting on another lane of its start edge, from which its route makes it change
    lanes on that edge; what was done), None where no such lane will do. The route, start position and goal stay:
    the ego starts on a lane that does not lead on (a car parked on the left of a one-way street, a driver who
    took the wrong lane), and a careful driver changes lanes in the room left. A lane qualifies when passenger cars
    may use it and change from it to a lane that leads on without crossing a solid line, with
    :data:`START_SHIFT_ROOM_M` to the edge's end, the start speed within its limit, and no actor's start within
    the separation of the ego's new one. On a route whose lanes lead on everywhere (every seed of the
    intersection), it is what makes an ADS that changes lanes only where its route needs it change lanes at all.
    With ``room`` [m] (a range), the ego also starts that far before the edge's end, where there is so much room:
    it changes lanes late, a few seconds before the junction (``aim._first_junction``)."""
    rmap, m = mut.rmap, sc.mission
    start = rmap.lane(m.start_lane)
    edge = start.getEdge()
    if edge.getLength() - m.start_pos < (room[1] if room else START_SHIFT_ROOM_M):
        return None
    if room:
        m = m.model_copy(update={"start_pos": round(edge.getLength() - rng.uniform(*room), 2)})
        if _left_behind(mut, sc, m.start_pos):
            return None
    options = []
    for lane in edge.getLanes():
        lane_id = lane.getID()
        if lane_id == m.start_lane or not lane.allows(PASSENGER) or m.start_speed > lane.getSpeed():
            continue
        new = sc.model_copy(update={"mission": m.model_copy(update={"start_lane": lane_id})})
        at = mut.lane_change_at(new, 0)
        to = mut.ego_lane_at(new, 0, edge.getLength())
        if at is None or not rmap.may_change_to(lane_id, to):
            continue
        if not _ego_fits(mut, sc, lane_id, m.start_pos):
            continue
        options.append((new, lane_id))
    if not options:
        return None
    new, lane_id = rng.choice(options)
    late = f", {m.start_pos:.0f} m on (was {sc.mission.start_pos:.0f} m)" if room else ""
    return new, f"{SHIFTED_START} {lane_id}{late} (was {sc.mission.start_lane}): its route makes it change lanes"


def standing_start(mut: Mutator, sc: Scenario, rng: random.Random,
                   room: tuple[float, float]) -> tuple[Scenario, str] | None:
    """(``sc`` with the ego standing on its start lane ``room`` [m] (a range) before its start edge's end; what was
    done), None where that lane does not lead on, the seed starts it closer, or an actor the seed placed would be
    left behind or too close. The route and goal stay: a driver who pulls away from the kerb near a junction, still
    speeding up as it comes to it (``aim._standing_before_crossing``)."""
    rmap, m = mut.rmap, sc.mission
    edge = rmap.lane(m.start_lane).getEdge()
    if edge.getLength() - m.start_pos < room[1] or mut.lane_change_at(sc, 0) is not None:
        return None
    pos = round(edge.getLength() - rng.uniform(*room), 2)
    if _left_behind(mut, sc, pos) or not _ego_fits(mut, sc, m.start_lane, pos):
        return None
    new = sc.model_copy(update={"mission": m.model_copy(update={"start_pos": pos, "start_speed": 0.0})})
    return new, (f"the ego starts standing {edge.getLength() - pos:.0f} m before the end of {edge.getID()} (was "
                 f"{m.start_pos:.0f} m on, at {m.start_speed:.1f} m/s)")


def _ego_fits(mut: Mutator, sc: Scenario, lane_id: str, pos: float) -> bool:
    """Whether the ego started at ``pos`` [m] on ``lane_id`` keeps the separation from every actor's start."""
    sep = mut.cfg.min_separation + EGO_LENGTH / 2
    x, y, _ = mut.rmap.geom(lane_id).position(pos)
    return all(math.hypot(x - ax, y - ay) >= sep for ax, ay, _ in
               (mut.rmap.geom(a.start_lane).position(a.start_pos) for a in sc.actors))


def _left_behind(mut: Mutator, sc: Scenario, pos: float) -> bool:
    """Whether an actor the seed placed on the ego's start edge lies between its start and a later start at ``pos``
    [m] (5 m either side): moved on, the ego would leave it behind."""
    edge = mut.rmap.lane(sc.mission.start_lane).getEdge().getID()
    return any(mut.rmap.lane(a.start_lane).getEdge().getID() == edge
               and sc.mission.start_pos - 5.0 < a.start_pos < pos + 5.0 for a in sc.actors)


#: [m] before its start edge's end that the ego stands for a crossing car met as it speeds up: at 2 m/s^2 it has
#: driven 9 m in the 3 s that count as stop and go, and comes to the stop line 3.5-4.7 s after it sets off
STANDING_CROSS_ROOM_M = (12.0, 22.0)


#: [m] before its start edge's end that the ego starts for a lane change late (``aim._first_junction``): the reference
#: ADS crosses the lane line 45 % of the way from 8 m behind its start to the edge's end, here 20-27 m before the
#: stop line (from 60 m, as a start on another lane needs, some 40 m: 4-6 s before the junction on town)
LATE_CHANGE_ROOM_M = (30.0, 40.0)
#: [s] before the ego that a car crossing after its late lane change passes the conflict point: in the ego's path
#: ahead (a time to collision under 3 s) within 3 s of the ego's change
LATE_CHANGE_CLEARS_S = (0.8, 2.2)


#: link states (SUMO's) through which a car entering at speed need not be able to stop: major, or uncontrolled
FREE_LINKS = ("M", "O", "o")


def started_at_speed(mut: Mutator, sc: Scenario, lo: float, hi: float,
                     rng: random.Random) -> tuple[Scenario, str] | None:
    """(``sc`` with the ego entering at a speed inside the band ``lo``-``hi`` [m/s]; what was done), None where its
    start lane's limit does not allow one (at most 0.95 of it), or, where that lane does not go on into the route's
    next edge with the right of way, the room to stop before its end. For a speed band that a route too short to
    speed up on never reaches: the ego is already moving at the start, as on a motorway it joined before."""
    lane = mut.rmap.lane(sc.mission.start_lane)
    top = min(0.9 * hi, 0.95 * lane.getSpeed())
    route = mut._route(sc)
    if len(route) > 1 and not any(c.getTo().getID() == route[1] and c.getState() in FREE_LINKS
                                  for c in lane.getOutgoing()):
        # it must stop or change lanes before the junction ahead; SUMO inserts no car that could not stop there
        # ("will not be able to depart ... (junction too close)": the run was an error)
        room = max(lane.getLength() - sc.mission.start_pos, 0.0)
        top = min(top, 0.95 * math.sqrt(2.0 * SUMO_DECEL * room))
    if top <= 1.1 * lo or sc.mission.start_speed >= lo:
        return None
    v = round(rng.uniform(1.1 * lo, top), 2)
    new = sc.model_copy(update={"mission": sc.mission.model_copy(update={"start_speed": v})})
    return new, f"the ego enters at {v:.1f} m/s (was {sc.mission.start_speed:.1f})"


#: [s] the time to collision at which a car closes in from behind on the lane the ego has just changed into
INTO_LANE_TTC = (1.2, 2.6)


def into_lane(mut: Mutator, sc: Scenario, rng: random.Random, move: tuple[float, str, str, str], where: str):
    """A car on the lane the ego changes into (``move``, :func:`lane_change_moves`), there as the ego changes
    lanes: ``behind``, 3-5 m/s faster and its front :data:`INTO_LANE_TTC` times that behind the ego's rear (the
    ego changes in front of it); ``rear``, 1-3 m/s faster and its front about level with the ego's rear (in the
    rear quarter the ego moves towards); ``level``, abreast, 15-40 % slower than the ego (it starts ahead). A maneuver
    vehicle without steps: SUMO drives it in its lane at its speed and brakes for the ego once the ego is ahead.
    A careful driver looks before changing lanes and waits for the gap; what follows is the ego's doing."""
    at, _, _, to_lane = move
    spot = cat._route_spot(mut, sc, at)
    if spot is None:
        return None
    pos = spot[2]  # the ego's front
    v = prog._ego_speed(mut, sc, at)
    t_at = mut._ego_eta(sc, at)
    top = prog.SPEED_SHARE[1] * lane_limit(mut, to_lane)
    if where == "behind":  # the gap from the speed it really gets (the lane's limit caps it)
        speed = min(v + rng.uniform(3.0, 5.0), top)
        front = pos - EGO_LENGTH - max(speed - v, 1.0) * rng.uniform(*INTO_LANE_TTC)
    elif where == "rear":
        speed, front = min(v + rng.uniform(1.0, 3.0), top), pos - EGO_LENGTH + rng.uniform(-1.0, 2.0)
    else:  # slower: it starts ahead of the ego (SUMO would insert a car level with it beside it)
        speed, front = v * (1.0 - rng.uniform(0.15, 0.4)), pos + (NPC_LENGTH - EGO_LENGTH) / 2.0 + rng.uniform(-1, 1)
    speed = round(speed, 2)
    # its run-up stays on the lane: one through the junction before it slowed in the turn and came 20-40 m late
    lead = min(rng.uniform(3.0, 6.0), (front - 1.0) / max(speed, 0.1), t_at)
    if speed < 1.0 or lead < 1.0:
        return None
    start, depart = round(front - speed * lead, 2), round(t_at - lead, 1)
    a = prog._vehicle(mut, sc, mut.rmap.lane(to_lane), start, speed, depart, [])
    return [a], [], {}, (f"{a.id} on {to_lane} at {speed:.1f} m/s, {where} the ego as it changes lanes into it at "
                         f"{at:.0f} m ({t_at:.1f} s)")


#: [m] before the place where a patch aimed at it begins, and [m] how long it is (``grip_at``)
GRIP_BEFORE_M, GRIP_LENGTH_M = 20.0, (25.0, 35.0)
#: friction of a patch aimed at a place: ice (an accelerating or lane-changing ego uses 1 m/s^2 of it at most)
GRIP_MU = (0.05, 0.15)
#: [m] length of a patch aimed where the ego accelerates (GRIP_MU): crossed within a second, so that its driven
#: wheels spin and grip again while the last second's mean acceleration is still over the 0.7 m/s^2 coverage counts.
#: On a 25-35 m patch the reference ADS gained 0.34 m/s^2 on ice, and at mu 0.37, 1.5 m/s^2 with 0.54 of its grip
#: (the driven axle carries part of the weight): a cruise, or no encounter.
#: `python tools/lab_aim.py --network interchange --cells "none/grip|accelerate" --draws 2`: 1 of 16 reached the
#: cell on that patch, 9 on this one
GRIP_ACCEL_LENGTH_M = (3.0, 6.0)
#: [m] behind the ego's front at its standing start that a patch aimed at its pulling away begins (its rear axle
#: is some 3.7 m behind), and [m] how long it is: it leaves the patch within the 3 s after the standstill in which
#: the manoeuvre counts as stop and go (from 20 m before the place and 25-35 m long, the ego was still on it or
#: met its grip limit later: `python tools/lab_aim.py --network roundabout --cells "grip|stop_go"`, 0 of 16)
GRIP_START_BEHIND_M, GRIP_START_LENGTH_M, GRIP_START_MU = 5.5, (6.0, 8.0), (0.15, 0.25)


def grip_at(mut: Mutator, sc: Scenario, rng: random.Random, at: float,
            length_m: tuple[float, float] = GRIP_LENGTH_M, before_m: float = GRIP_BEFORE_M,
            mu: tuple[float, float] = GRIP_MU):
    """A low-friction patch (:data:`GRIP_MU`) across the ego's lane and the lanes beside it, from
    :data:`GRIP_BEFORE_M` before the route distance ``at`` [m]: the ego changes lanes, brakes, turns (or drives on)
    on it there; ``at`` 0 (its standing start): from ``before_m`` behind its front, where it pulls away.
    (From 5 m before, mu 0.05-0.3: the ego had changed lanes when it came to it, and used a third of its grip.)"""
    spot = cat._route_spot(mut, sc, max(at - before_m, 0.0))
    if spot is None:
        return None
    _, lane, pos = spot
    if at <= 0.0:  # aimed at the ego's start: from behind it, under its wheels as it pulls away
        pos -= before_m
    length = rng.uniform(*length_m)
    x, y, h = mut.rmap.geom(lane).position(max(pos + length / 2.0, 0.0))
    p = Puddle(x=round(x, 2), y=round(y, 2), length=round(length, 2), width=round(rng.uniform(6.0, 8.0), 2),
               rotation=round(h, 3), friction=round(rng.uniform(*mu), 2))
    return [], [p], {}, f"puddle mu={p.friction} on {lane} from {pos:.0f} m, where the ego is expected at {at:.0f} m"


def _goal(mut: Mutator, sc: Scenario) -> float:
    return mut.rmap.route_length(mut._route(sc), sc.mission.start_pos, sc.mission.goal_pos)


def profile_spots(mut: Mutator, sc: Scenario, col: str, band: tuple[float, float] | None = None) -> list[float]:
    """Route distances [m] (every 5 m, before 0.8 of the route) where the ego's profile does what ``col`` says
    (``speed``: drives at ``band`` [m/s], lowest to highest)."""
    s, t = mut._ego_profile(sc)
    dt = np.maximum(np.diff(t), 1e-6)
    v = 1.0 / dt  # each step is 1 m driven
    a = np.diff(v, append=v[-1]) / dt
    if col == "speed":
        want = (v >= band[0]) & (v < band[1])
    else:
        want = {"stop_go": v < 0.5, "accelerate": a > ACCEL, "brake": a < BRAKE,
                "cruise": (np.abs(a) < 0.3) & (v > 3.0)}[col]
    if col == "stop_go" or (col == "speed" and band[0] <= 0.0):  # a stop: the steps just before it count too
        want = want | (np.concatenate([want[1:], [False]]))
    elif col in ("accelerate", "brake", "cruise"):  # not where the manoeuvre counts as stop and go
        want = want & ~_after_standstill(t, v, sc.mission.start_speed)
    goal = 0.8 * _goal(mut, sc)
    picked = sorted({round(float(x) / 5.0) * 5.0 for x in s[:-1][want] if 1.0 <= x <= goal})
    return picked


def _after_standstill(t: np.ndarray, v: np.ndarray, start_speed: float) -> np.ndarray:
    """Per metre of the profile (reached at ``t[k]`` [s], driven at ``v[k]`` [m/s] on to ``t[k + 1]``): whether the
    ego stood within :data:`STOP_GO_S` before it: at its start (``start_speed`` under
    :data:`~drivefuzz.triage.coverage.STANDSTILL`), or on a metre it took longer than 1 / STANDSTILL s to drive (a
    wait at a light), counted from the end of that metre. There an encounter's manoeuvre is ``stop_go``
    (:func:`drivefuzz.triage.coverage.manoeuvre` reads the 3 s before it): of the interchange's aimed
    accelerations, the first 3 s after the standing start, two or three of each seed's nine to fourteen places,
    could only be met in stop and go."""
    from drivefuzz.triage.coverage import STANDSTILL

    stood = t[1:][v < STANDSTILL]
    if start_speed < STANDSTILL:
        stood = np.concatenate(([t[0]], stood))
    if not len(stood):
        return np.zeros(len(v), dtype=bool)
    k = np.searchsorted(stood, t[:-1], side="right") - 1  # the last standstill at or before each metre
    return (k >= 0) & (t[:-1] - stood[np.maximum(k, 0)] <= STOP_GO_S)


#: per aimed phase: the states whose onset is shifted, the range [s] of how long before the ego arrives that onset
#: comes, and what the description says. Amber: while the ego enters or stands at the line (drawn up to 1 s after
#: its arrival, as before, 7 of 11 misses in seven town campaigns met it at green); red: it stops and waits;
#: green: well inside the 35-40 s greens of the committed networks' lights (:func:`shift_light`)
LIGHT_SHIFTS = {"signal/amber": ("yY", (0.2, 2.5), "yellow"), "signal/red": ("yY", (4.0, 12.0), "yellow, then red,"),
                "signal/green": ("gG", (1.0, 6.0), "green")}


def shift_light(mut: Mutator, sc: Scenario, at: float, col: str, rng: random.Random) -> tuple[Scenario | None, str]:
    """``sc`` with the light of the route's junction at ``at`` shifted so that it turns yellow as the ego arrives
    (``signal/amber``: 0.2-2.5 s before: it drives in on yellow, or stands at the line while it is yellow) or
    several seconds before (``signal/red``: it stops and waits at red), or green shortly before
    (``signal/green``: 1-6 s, it arrives on green without stopping, wherever the seed's own run met the light);
    (None, "") where it has no such light."""
    light = next(((tls, link) for s, tls, link in _lights(mut, sc) if abs(s - at) < 1.0), None)
    if light is None:
        return None, ""
    tls, link = light
    program = shiftable(str(mut.rmap.path), tls)
    states, early, what = LIGHT_SHIFTS.get(col, LIGHT_SHIFTS["signal/red"])
    onsets = phase_starts(program, link, states)
    if program is None or not onsets:
        return None, ""
    base = sc.model_copy(update={"signals": tuple(x for x in sc.signals if x.tls != tls)})
    # when the ego reaches the line without waiting there: the profile waits at a red light, so the light's own
    # program could put the arrival a cycle late (the light then turned yellow long before the ego came, and it
    # passed on the next green: 7 town seeds, a car behind at a red light, 0 hits); the earliest over four shifts
    t_arrive = min(mut._ego_eta(base.model_copy(update={"signals": base.signals + (
        SignalShift(tls=tls, shift=round(k * program.cycle / 4, 2)),)}), max(at - 0.5, 0.0)) for k in range(4))
    before = rng.uniform(*early)  # [s] the light turns this long before the ego arrives
    shift = round((t_arrive - before - program.offset - rng.choice(onsets)) % program.cycle, 2)
    new = base.model_copy(update={"signals": base.signals + (SignalShift(tls=tls, shift=shift),)})
    return new, f"light {tls} turns {what} ~{before:.1f} s before the ego reaches it (shift {shift} s)"


def _lights(mut: Mutator, sc: Scenario) -> list[tuple[float, str, int]]:
    """(route distance [m] of the stop line, tls id, the ego's link index) of every fixed-time light on the ego's
    route (the mutator's ``_signals_ahead`` stops at ``conflict_range``, 160 m: on town, the second and later
    lights of a route could not be shifted for an amber or red aim)."""
    rmap, route = mut.rmap, mut._route(sc)
    out, s = [], -sc.mission.start_pos
    for i, e in enumerate(route[:-1]):
        s += rmap.edge(e).getLength()
        conn = next((c for c in rmap.lane(mut.ego_lane(sc, i)).getOutgoing()
                     if c.getToLane().getEdge().getID() == route[i + 1]), None)
        if conn is not None and conn.getTLSID() and s > 0 and shiftable(str(rmap.path), conn.getTLSID()) is not None:
            out.append((s, conn.getTLSID(), conn.getTLLinkIndex()))
    return out


#: [m] the body gap aimed for at an in-lane drift's deepest (a close encounter is a gap under 1.5 m)
DRIFT_GAP = (0.6, 1.2)
#: [s] an in-lane drift, out and back
DRIFT_S = (3.0, 5.0)
#: [m] the drifting car's length: SUMO's default passenger car (its centre is level with the ego's at a gap of
#: -(EGO_LENGTH + NPC_LENGTH) / 2 from the ego's front to its rear)
NPC_LENGTH = 5.0


def drift(mut: Mutator, ego_lane: str, lane, rng: random.Random) -> Maneuver | None:
    """A drift of the car on ``lane`` towards the ego on ``ego_lane`` inside its own lane (out and back: the
    executor needs no room for it, :func:`drivefuzz.scenario.model.in_lane`), deepest as the two are level
    (:attr:`~drivefuzz.scenario.Trigger.PEAK`: the executor starts it by the real closing speed), that leaves a
    body gap of :data:`DRIFT_GAP` where the lanes allow it. None where its lane leaves no room."""
    e = mut.rmap.lane(ego_lane)
    room = drift_room(lane.getWidth())
    if room < 0.1:
        return None
    apart = (lane.getWidth() + e.getWidth()) / 2.0 - (NPC_WIDTH + EGO_WIDTH) / 2.0  # the body gap, both centred
    depth = math.floor(100.0 * min(max(apart - rng.uniform(*DRIFT_GAP), 0.1), room)) / 100.0  # in lane, rounded
    _, nudge = prog._toward(lane, e)
    return Maneuver(time=0.5, action=nudge, value=round(rng.uniform(*DRIFT_S), 2), trigger=Trigger.PEAK, depth=depth,
                    at=round(-(EGO_LENGTH + NPC_LENGTH) / 2.0 + rng.uniform(-1.0, 1.0), 1))


def _lanes_beside(mut: Mutator, ego_lane: str, side: str | None) -> list:
    """The lanes beside ``ego_lane`` that cars use, on ``side`` (``left``, ``right``; None: either)."""
    i = mut.rmap.lane(ego_lane).getIndex()
    return [ln for ln in prog._beside(mut, ego_lane)
            if side is None or (ln.getIndex() > i) == (side == "left")]


def run_up(mut: Mutator, lane: str, pos: float, speed: float, lead: float, t_at: float,
           rng: random.Random, route: Sequence[str] = ()) -> tuple[str, float, float] | None:
    """(lane, position [m], departure [s]) of a car at ``speed`` that is at ``pos`` on ``lane`` at ``t_at`` [s]
    after driving ``lead`` s (less where ``t_at`` is sooner: it starts further on at 0 s); where that run-up is
    longer than the lane before ``pos``, it starts upstream, on a lane that leads into ``lane`` (the highway's
    edges after a ramp are 60-130 m long: a car at 30 m/s for 3 s does not fit on one), on ``route`` where one
    does (the ego's: a follower aimed just past a turn had come from another approach, and waited at its red
    light). None where no road is long enough."""
    lead = min(lead, t_at)
    back = speed * lead
    if pos - back >= 1.0:
        return lane, round(pos - back, 2), round(t_at - lead, 1)
    placed = mut._upstream(lane, pos, back, rng, route)
    if placed is None:
        return None
    up_lane, up_pos, covered = placed
    depart = t_at - covered / max(speed, 0.1)
    return (up_lane, up_pos, round(depart, 1)) if depart >= 0.0 else None


def passes(mut: Mutator, sc: Scenario, rng: random.Random, at: float | None = None, side: str | None = None):
    """From behind on the lane beside, faster than the ego: it draws level with the ego's rear where the ego is
    expected at ``at`` (else, in 7 of 10 draws the slowest of 8 places drawn along the route: a start, a turn, a
    light, where the speed difference is large; else one of them) and passes close by, drifting towards the ego
    inside its own lane as it comes level (:func:`drift`: lanes of 3.5 m leave 1.65 m between centred bodies, no
    close encounter): 2 s before the closest moment it is still behind the ego's rear, in its rear quarter. (An
    overtaker that cuts in meets the ego ahead of it, after it has passed: no rear-quarter encounter.) A maneuver
    vehicle: SUMO drives it at its speed (at most 1.2 x the lane's limit), stopping at lights and for what is
    ahead of it. ``side``: the lane beside on that side only."""
    goal = _goal(mut, sc)
    if goal < 20.0:
        return None
    draws = [max(at - 0.5, 0.0)] if at is not None else sorted(rng.uniform(5.0, 0.8 * goal) for _ in range(8))
    options = []
    for d in draws:
        spot = cat._route_spot(mut, sc, d)
        if spot is not None and _lanes_beside(mut, spot[1], side):
            options.append((prog._ego_speed(mut, sc, d) / lane_limit(mut, spot[1]), d, spot))
    if not options:
        return None
    _, d, (_, ego_lane, pos) = min(options) if rng.random() < 0.7 else rng.choice(options)
    lane = rng.choice(_lanes_beside(mut, ego_lane, side))
    v_ego = prog._ego_speed(mut, sc, d)
    speed = round(min(prog.SPEED_SHARE[1] * lane_limit(mut, lane.getID()), v_ego + rng.uniform(4.0, 9.0)), 2)
    lead = rng.uniform(3.0, 7.0)  # [s] it drives before it draws level
    t_level = mut._ego_eta(sc, max(d - 0.5, 0.0)) + (rng.uniform(0.0, 4.0) if v_ego < 1.0 else 0.0)
    # its front at the ego's rear
    placed = run_up(mut, lane.getID(), min(pos, lane.getLength() - 0.5) - EGO_LENGTH, speed, lead, t_level, rng,
                    mut._route(sc))
    if placed is None:
        return None
    start_lane, start, depart = placed
    step = drift(mut, ego_lane, lane, rng)
    a = prog._vehicle(mut, sc, mut.rmap.lane(start_lane), start, speed, depart, [step] if step else [])
    return [a], [], {}, (f"{a.id} passes the ego from behind on {lane.getID()} at {speed:.1f} m/s, level with it "
                         f"at {pos:.0f} m ({t_level:.1f} s)" + (f", drifting {step.depth} m towards it" if step else ""))


def drawn_level(mut: Mutator, sc: Scenario, rng: random.Random, at: float | None = None, side: str | None = None):
    """Ahead on the lane beside and slower than the ego, which draws level with it where the ego is expected at
    ``at`` (or up to 15 m either side of it, where the lane beside begins too near to start it there; without
    ``at``, at a place drawn on the route); it drifts towards the ego inside its own lane as the two are level
    (:func:`drift`). 2 s before the closest moment it is beside or ahead of the ego in the other lane (on
    ``side`` only, where given). None where the ego is expected too slow there (under 4 m/s) to pass it."""
    goal = _goal(mut, sc)
    if goal < 20.0:
        return None
    draws = [at - 0.5, at - 15.0, at + 15.0] if at is not None else [rng.uniform(10.0, 0.8 * goal) for _ in range(4)]
    lead = rng.uniform(2.5, 6.0)  # [s] it drives before the ego draws level
    slower = rng.uniform(0.15, 0.4)  # share of the ego's expected speed (the ADS may well drive slower than that)
    for d in draws:
        spot = cat._route_spot(mut, sc, max(d, 0.0))
        v_ego = prog._ego_speed(mut, sc, max(d, 0.0))
        lanes = _lanes_beside(mut, spot[1], side) if spot is not None and v_ego >= 4.0 else []
        if not lanes:
            continue
        _, ego_lane, pos = spot
        lane = rng.choice(lanes)
        speed = round(min(v_ego * (1.0 - slower), v_ego - 2.0), 2)
        t_level = mut._ego_eta(sc, max(d, 0.0))
        front = min(pos + (NPC_LENGTH - EGO_LENGTH) / 2.0, lane.getLength() - 0.5)  # level: the centres abreast
        start, depart = front - speed * lead, t_level - lead
        if depart < 0.0:
            start, depart = start - speed * depart, 0.0
        # it starts ahead of the ego (its rear 5 m before the ego's front), or it would pass the ego first
        ahead = d - (front - start) - NPC_LENGTH - mut._ego_progress(sc, depart)
        if start >= 1.0 and ahead >= 5.0:
            break
    else:
        return None
    step = drift(mut, ego_lane, lane, rng)
    if step is None:
        return None
    a = prog._vehicle(mut, sc, lane, round(start, 2), speed, round(depart, 1), [step])
    return [a], [], {}, (f"{a.id} on {lane.getID()} at {speed:.1f} m/s is drawn level with at {pos:.0f} m "
                         f"({t_level:.1f} s) and drifts {step.depth} m towards the ego")


#: [s] after the ego is expected at a turn's place (2-8 m into the junction) that a follower aimed at the turn, close
#: behind it since before the junction, closes in on it
FOLLOW_TURN_CLOSE_S = (0.0, 1.5)
#: [m] before a turn's place where such a follower comes up behind the ego
FOLLOW_TURN_BEFORE_M = 30.0


def follower_at(mut: Mutator, sc: Scenario, rng: random.Random, at: float,
                close_after_s: tuple[float, float] | None = None):
    """A vehicle on the ego's lane behind the place ``at`` that reaches the ego's rear as the ego gets there: where
    the ego is expected to stand there (a red light, say), a lawful car arriving 0.5-4 s after it, half of them
    following close (a follow step); where it is expected to move, a car 3-6 m/s faster (at most 1.2 x the limit)
    that follows close and closes in without braking until its time to collision is 1.5-2.5 s (a close step).
    Either closes in from behind. ``close_after_s`` (a turn: :data:`FOLLOW_TURN_CLOSE_S`): it comes up behind the
    ego before the place and follows it close into the turn, and closes in that many seconds (a range) after the ego
    is expected at the place."""
    t_close = mut._ego_eta(sc, max(at - 0.5, 0.0)) + rng.uniform(*close_after_s) if close_after_s else None
    if t_close is not None:  # it comes up behind the ego where it still drives straight, before the turn
        at = max(at - FOLLOW_TURN_BEFORE_M, 0.0)
    spot = cat._route_spot(mut, sc, max(at - 0.5, 0.0))
    if spot is None:
        return None
    _, lane, pos = spot
    limit = lane_limit(mut, lane)
    v_ego = prog._ego_speed(mut, sc, max(at - 0.5, 0.0))
    t_meet = mut._ego_eta(sc, max(at - 0.5, 0.0))
    # a maneuver vehicle either way: it keeps its lane (an autopilot car pulled out beside a waiting ego and met it
    # in a rear quarter, 4 of 7 aimed builds for a car behind at a red light on town's seeds)
    nav = NavType.MANEUVER
    if v_ego < 1.0:
        speed, lead = round(limit * rng.uniform(0.8, 1.05), 2), rng.uniform(3.0, 6.0)
        t_meet += rng.uniform(0.5, 4.0)
    else:
        lead = rng.uniform(4.0, 8.0)
        speed = round(min(prog.SPEED_SHARE[1] * limit, v_ego + rng.uniform(3.0, 6.0)), 2)
    placed = run_up(mut, lane, pos - EGO_LENGTH - 2.0, speed, lead, t_meet, rng, mut._route(sc))
    if placed is None:
        return None
    start_lane, start, depart = placed
    # SUMO's follower keeps a time gap of 1 s and closes in at a time to collision of about 3.7 s, no close
    # encounter; many drivers follow closer (a maneuver step: TAILGATE_S), and where the ego moves, close in fast
    # and brake late (a close step: CLOSE_TTC; with the follow step alone, 0 of 8 aimed builds for a car behind
    # the cruising ego on the highway's seeds met it, all of them at its stop at the goal instead)
    steps: tuple[Maneuver, ...] = ()
    how = ""
    if v_ego >= 1.0 or t_close is not None or rng.random() < TAILGATE_SHARE:
        steps = (Maneuver(time=0.0, action=ManeuverAction.FOLLOW, value=round(rng.uniform(*TAILGATE_S), 2)),)
        how = f", following at a time gap of {steps[0].value:.2f} s"
    if v_ego >= 1.0 or t_close is not None:
        when = 0.0 if t_close is None else round(max(t_close - depart, 0.0), 1)
        steps += (Maneuver(time=when, action=ManeuverAction.CLOSE, value=0.0, at=round(rng.uniform(*CLOSE_TTC), 2)),)
        how += f" and, from {depart + when:.1f} s, braking at a time to collision of {steps[1].at:.2f} s"
    a = cat.Actor(id=mut._new_id(sc, "v"), kind=ActorKind.VEHICLE, nav=nav, start_lane=start_lane, start_pos=start,
                  speed=speed, depart=depart, dest_edge=cat._dest(mut, sc), maneuvers=steps)
    return [a], [], {}, (f"{a.id} comes up behind the ego on {lane} at {speed:.1f} m/s, reaching it at "
                         f"~{t_meet:.1f} s{how}")


def stopped_past(mut: Mutator, sc: Scenario, rng: random.Random, at: float,
                 past: tuple[float, float] = (4.0, 14.0), side: str | None = None):
    """A vehicle standing on the lane the ego turns into (or changes into), ``past`` m past the place ``at`` (4-14 m:
    just out of the turn's junction): the end of a queue, or a car waiting to turn off, that the ego sees as its
    heading comes round and meets while it still turns. It drives on 2-6 s after the ego is expected there (an ADS
    that waits behind a stopped car, as the reference ADS does, would otherwise stand there until the immobility
    oracle fires, one more execution of that finding). (The catalogue's vehicles ahead start before the junction:
    the ego met them there, going straight; 0 of 7 aimed builds for a car ahead in a left turn on town's seeds.)
    ``side``: on the lane beside that one on that side instead (None where there is none), which the turning ego
    passes close by: centred on lanes of 3.2 m, the bodies are 1.4 m apart (the catalogue's cars beside need the
    ego at 4 m/s or more, which it does not drive in a turn: 0 of 26 aimed builds on the interchange's seeds).
    ``at`` 0: ahead of the ego as it stands at its start, met as it pulls away."""
    past = rng.uniform(*past)  # farther, the ego had come out of the turn when it met it (braking, cruising)
    spot = cat._route_spot(mut, sc, at + past)
    turn = cat._route_spot(mut, sc, at)
    if spot is None or turn is None or spot[0] != turn[0]:  # past the next junction: not the turn's exit
        return None
    i, _, pos = spot
    lane = mut.ego_lane_at(sc, i, pos)  # the lane the turn leads into, before any lane change the route needs
    if side is not None:
        beside = _lanes_beside(mut, lane, side)
        if not beside:
            return None
        lane = beside[0].getID() if len(beside) == 1 else min(
            beside, key=lambda ln: abs(ln.getIndex() - mut.rmap.lane(lane).getIndex())).getID()
    speed = round(lane_limit(mut, lane) * rng.uniform(0.4, 0.7), 2)
    roll = speed * speed / (2.0 * STAND_DECEL)  # it enters at its speed and stops at once
    release = round(mut._ego_eta(sc, at + past) + rng.uniform(2.0, 6.0), 1)
    steps = (Maneuver(time=0.0, action=ManeuverAction.SPEED, value=0.0, rate=STAND_DECEL),
             Maneuver(time=release, action=ManeuverAction.SPEED, value=speed))
    a = cat.Actor(id=mut._new_id(sc, "v"), kind=ActorKind.VEHICLE, nav=NavType.MANEUVER, start_lane=lane,
                  start_pos=round(max(pos - roll, 1.0), 2), speed=speed, dest_edge=cat._dest(mut, sc), maneuvers=steps)
    where = ("level with where the ego stops" if past <= 0.0 else "ahead of where the ego starts" if at <= 0.0
             else "just past the turn")
    where = where if side is None else f"on the ego's {side}, {where}"
    return [a], [], {}, (f"vehicle {a.id} standing on {lane} @ {pos:.1f} m, {where}, until {release} s")


def stopped_on_ring(mut: Mutator, sc: Scenario, rng: random.Random):
    """A vehicle standing on a ring edge of the route, 4-14 m past where the ego comes onto it (from the approach or
    from the ring edge before): the end of a queue on the ring, met while the ego still drives round (its heading
    turns all the way on a ring, so the coverage's manoeuvre is the roundabout until it stops). (The catalogue's
    vehicles ahead start 15-40 m ahead of the ego, slower than it: on a ring it leaves before the ego closes up.
    ``python tools/lab_aim.py --network roundabout --cells "ahead|roundabout"``: 1 of 111 builds reached.)"""
    from drivefuzz.search.aim import _marks

    starts = [s0 for s0, _ in _marks(mut, sc)["rings"] if s0 >= RING_ENTRY_CLEAR_M]
    if not starts:  # the ego starts on the route's last ring edge, or its route has none
        return None
    return stopped_past(mut, sc, rng, at=rng.choice(starts) + 0.5)


def walker_from_left(mut: Mutator, sc: Scenario, rng: random.Random, early=(-1.0, 1.5), at: float | None = None):
    """A walker crossing the ego's road from its left: the catalogue's crossing walker (who starts on the
    pavement of the ego's own edge, on its right where traffic keeps right) mirrored: it starts on the pavement
    of the road the other way and walks to that spot, leaving earlier by the time it takes to cross the other
    carriageway. The fairness rule for jaywalkers is applied here (the shared check cannot place a walker
    whose pavement is off the ego's route): it steps onto the road while the ego can still stop. ``at``: where
    it crosses, as for the catalogue's."""
    from drivefuzz.search import fairness

    built = cat.walker_crosses(mut, sc, rng, early=early, at=at)
    if built is None:
        return None
    a = built[0][0]
    lane = mut.rmap.lane(a.start_lane)
    edge = lane.getEdge()
    x0, y0, _ = mut.rmap.geom(a.start_lane).position(a.start_pos)
    for other in edge.getToNode().getOutgoing():
        if other.getToNode() != edge.getFromNode() or not mut.rmap.is_normal_edge(other):
            continue
        walks = [ln for ln in other.getLanes() if ln.allows("pedestrian") and not ln.allows("passenger")]
        road = sum(ln.getWidth() for ln in other.getLanes() if ln.allows("passenger"))
        for sw in walks:
            pos, _ = mut.rmap.geom(sw.getID()).project(*a.dest_xy)
            if not 1.0 <= pos <= sw.getLength() - 0.5:
                continue
            new = a.model_copy(update={"start_lane": sw.getID(), "start_pos": round(pos, 2),
                                       "depart": round(max(a.depart - road / max(a.speed, 0.1), 0.0), 1),
                                       "dest_xy": (round(x0, 2), round(y0, 2))})
            d = fairness.route_distance(mut, sc, a.start_lane, a.start_pos)
            if d is None or fairness.walks_along_lane(mut, new) or fairness._jaywalker(mut, sc, new, d) \
                    or fairness.walks_into_stopped_ego(mut, sc, new, d):
                return None
            return [new], [], {}, f"{new.id} crosses from the left from {sw.getID()} @ {pos:.1f} m, leaving at {new.depart} s"
    return None


def road_beside(mut: Mutator, sc: Scenario, side: str | None) -> list[tuple[float, float, str, float]]:
    """Where another road's lane for cars runs beside the ego's on the route's ramps (a one-lane ramp has no lane
    beside of its own: the highway beside an on-ramp or an exit ramp, :func:`drivefuzz.triage.coverage.beside_sides`):
    (centre-line distance [m], route distance [m], that lane, the position [m] on it level with the ego), every 2 m,
    on ``side`` (``left``, ``right``; None: either). Cached per mission."""
    key = (sc.mission.start_edge, sc.mission.start_pos, sc.mission.goal_edge, side)
    cache = mut.__dict__.setdefault("_road_beside", {})
    if key not in cache:
        cache[key] = _road_beside(mut, sc, side)
    return cache[key]


def _road_beside(mut: Mutator, sc: Scenario, side: str | None) -> list[tuple[float, float, str, float]]:
    from drivefuzz.search.aim import _marks
    from drivefuzz.triage.coverage import lanes_beside
    from shapely.geometry import Point

    route = {ln.getID() for e in mut._route(sc) for ln in mut.rmap.edge(e).getLanes()}  # the ego's own way
    out = []
    for s0, s1 in _marks(mut, sc)["ramps"]:
        for d in np.arange(max(s0, 0.0) + 1.0, s1 - 0.5, 2.0):
            spot = cat._route_spot(mut, sc, float(d))
            if spot is None:
                continue
            x, y, h = mut.rmap.geom(spot[1]).position(spot[2])
            out += [(round(gap, 2), float(d), lane, round(t, 2)) for lane, gap, t, on in
                    lanes_beside(mut.rmap, Point(x, y), h, route) if side in (None, on)]
    return out


#: [m] a car beside a ramp meets the ego where the road beside comes within this of its nearest to the ramp
BESIDE_RAMP_SLACK_M = 0.5
#: [m] before a ramp's end that a car beside it is level with the ego at the latest: the closest moment comes a little
#: after that, and met at the very end it was on the road after the ramp (``rear_left|cruise``, not ``|merge``)
BESIDE_RAMP_END_M = 14.0


def beside_ramp(mut: Mutator, sc: Scenario, rng: random.Random, side: str, rear: bool = False):
    """A car on the road beside a one-lane ramp of the route (:func:`road_beside`), level with the ego where that
    road comes nearest the ramp (the end of an on-ramp, the start of an exit ramp: 3.7-4.5 m between the centre
    lines on the interchange and the highway), drifting towards it inside its own lane there (:func:`drift`'s body
    gap); ``rear``: from behind and faster, level with the ego's rear there (2 s before, in its rear quarter), else
    at the ego's speed, beside it. Until the twenty-second session nothing placed a car there: the side cells on a
    ramp (``left|ramp``, ``rear_left|merge``) were reached only where the traffic happened to be there."""
    from drivefuzz.search.aim import _marks

    ends = [s1 for _, s1 in _marks(mut, sc)["ramps"]]  # the encounter dated on the ramp, not just past its end
    spots = road_beside(mut, sc, side)
    if not spots:
        return None
    early = [s for s in spots if not any(e - BESIDE_RAMP_END_M < s[1] <= e for e in ends)]
    if early:  # the nearest of them
        nearest = min(g for g, *_ in early)
        gap, d, lane_id, t = rng.choice([s for s in early if s[0] <= nearest + BESIDE_RAMP_SLACK_M])
    else:  # a road beside only the ramp's last metres (the highway's on-ramp): the first of them
        gap, d, lane_id, t = min(spots, key=lambda s: s[1])
    v_ego = prog._ego_speed(mut, sc, d)
    if v_ego < 2.0:
        return None
    top = prog.SPEED_SHARE[1] * lane_limit(mut, lane_id)
    t_level, lead = mut._ego_eta(sc, d), rng.uniform(3.0, 7.0)
    if rear:  # faster than the ego over the run-up (it slows on the ramp: at its speed at the place it came from
        # ahead, and the ego met it from behind), so that it starts behind the ego
        lead = min(lead, t_level)
        over = (d - mut._ego_progress(sc, t_level - lead)) / max(lead, 0.1)
        speed = round(min(top, max(v_ego, over) + rng.uniform(3.0, 7.0)), 2)
        front = t - EGO_LENGTH  # its front at the ego's rear
    else:
        speed = round(min(top, v_ego * rng.uniform(0.95, 1.05)), 2)
        front = t + (NPC_LENGTH - EGO_LENGTH) / 2.0  # the centres abreast
    placed = run_up(mut, lane_id, max(front, 0.5), speed, lead, t_level, rng)
    if placed is None:
        return None
    start_lane, start, depart = placed
    if mut.rmap.lane(start_lane).getEdge().getID() in mut._route(sc):  # run up on the ego's own way: a follower
        return None
    lane = mut.rmap.lane(lane_id)
    apart = gap - (NPC_WIDTH + EGO_WIDTH) / 2.0  # the body gap, both centred
    depth = math.floor(100.0 * min(max(apart - rng.uniform(*DRIFT_GAP), 0.1), drift_room(lane.getWidth()))) / 100.0
    steps = []
    if depth >= 0.1:
        steps.append(Maneuver(time=0.5, action=ManeuverAction.NUDGE_RIGHT if side == "left" else
                              ManeuverAction.NUDGE_LEFT, value=round(rng.uniform(*DRIFT_S), 2), trigger=Trigger.PEAK,
                              depth=depth, at=round(-(EGO_LENGTH + NPC_LENGTH) / 2.0 + rng.uniform(-1.0, 1.0), 1)))
    a = prog._vehicle(mut, sc, mut.rmap.lane(start_lane), start, speed, depart, steps)
    a = a.model_copy(update={"dest_edge": _onward(mut, lane_id)})  # its own road's way on, not the ego's goal
    if not mut.rmap.route(mut.rmap.lane(start_lane).getEdge().getID(), a.dest_edge):
        return None
    how = "passes the ego from behind" if rear else "drives beside the ego"
    return [a], [], {}, (f"{a.id} {how} on {lane_id} beside the ramp at {speed:.1f} m/s, level with it at {d:.0f} m "
                         f"({t_level:.1f} s)" + (f", drifting {depth} m towards it" if steps else ""))


def _onward(mut: Mutator, lane_id: str, hops: int = 2) -> str:
    """The edge ``hops`` links on from ``lane_id``'s edge, by its lane's first link to a normal edge each time (or
    as far as there is one): a destination past the place where a car on it meets the ego."""
    lane = mut.rmap.lane(lane_id)
    for _ in range(hops):
        nxt = next((c.getToLane() for c in lane.getOutgoing() if mut.rmap.is_normal_edge(c.getToLane().getEdge())
                    and c.getToLane().allows(PASSENGER)), None)
        if nxt is None:
            break
        lane = nxt
    return lane.getEdge().getID()
