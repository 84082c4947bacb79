"""Adversarial maneuver programs: the ``maneuver`` strategy (drivefuzz's AV-Fuzzer).

AV-Fuzzer perturbs what the vehicles around the ego do, not where they stand. Here each program is one
or two vehicles, each with a sequence of timed steps (:class:`~drivefuzz.scenario.Maneuver`): speeds
relative to the lane's limit (0.6-1.2 x; a vehicle ahead also slower than the ego), lane changes that take their duration, nudges (aborted lane
changes), braking at a chosen deceleration. The steps that matter are timed against the ego (a gap or a
headway trigger), so that a mutant keeps its situation when the ego drives differently.

The programs, and the crash type of AV-Fuzzer (ISSRE 2020) each aims at:

- ``overtake_cut_in`` (1, an NPC overtakes and cuts in): from behind on a lane beside the ego, faster,
  changes into the ego's lane once it is ``at`` m ahead, and slows down gently as it does;
- ``beside`` (2, the ego cuts in and hits): rides on the lane beside, near the ego, where an ego that
  changes lanes must look;
- ``cut_in`` (3, another NPC cuts in): ahead on the lane beside, slower, changes in at a chosen headway;
- ``brake_check`` (4, the ego rear-ends a braking NPC) and ``slow_ahead``: ahead on the ego's lane, brakes
  at a chosen deceleration when the ego is within a chosen headway, then drives on (or stays slow);
- ``squeeze`` (5, two NPCs squeeze the ego): on both sides (or beside and ahead), closing in together;
- ``aborted_lane_change``: ahead on the lane beside, starts towards the ego's lane and turns back.

**Fair by construction.** A step that moves a vehicle in front of the ego is triggered by the gap or
headway to the ego, never by the clock, and its ``at`` leaves a careful driver room for the closing speed
(:func:`~drivefuzz.scenario.model.cut_in_gap`); :func:`drivefuzz.search.fairness.unfair` checks it again after every mutation.
"""

from __future__ import annotations

import random

import numpy as np

from drivefuzz.scenario import Actor, ActorKind, Maneuver, ManeuverAction, NavType, Scenario, Trigger
from drivefuzz.scenario.roadmap import PASSENGER
from drivefuzz.scenario.model import cut_in_gap
from drivefuzz.search.catalogue import Situation, _dest, _route_spot
from drivefuzz.search.fairness import lane_limit
from drivefuzz.search.mutate import Mutator

#: NPC speeds as a share of their lane's limit (a 33 m/s motorway: 20-40 m/s)
SPEED_SHARE = (0.6, 1.2)
#: [s] how long a program's lane change takes
LANE_CHANGE_S = (1.5, 3.5)
#: [m/s^2] how hard a braking NPC brakes (a car's limit on a dry road is about 9)
BRAKE_RATE = (3.0, 8.0)


def _beside(mut: Mutator, lane_id: str) -> list:
    """The passenger lanes next to ``lane_id`` on its edge."""
    lane = mut.rmap.lane(lane_id)
    idx = lane.getIndex()
    return [l for l in lane.getEdge().getLanes() if l.allows(PASSENGER) and abs(l.getIndex() - idx) == 1]


def _toward(from_lane, to_lane) -> tuple[ManeuverAction, ManeuverAction]:
    """(lane change, nudge) from ``from_lane`` towards ``to_lane`` (sumolib lanes of one edge)."""
    if to_lane.getIndex() > from_lane.getIndex():
        return ManeuverAction.LANE_LEFT, ManeuverAction.NUDGE_LEFT
    return ManeuverAction.LANE_RIGHT, ManeuverAction.NUDGE_RIGHT


def _leader_speed(mut: Mutator, lane_id: str, rng: random.Random, lo: float, hi: float, v_ego: float) -> float:
    """A vehicle ahead: ``lo``..``hi`` of the lane's limit, but slower than the ego is expected to drive
    there (half to 0.95 of it), or the ego never catches up (a short mission from a standstill)."""
    return round(max(min(lane_limit(mut, lane_id) * rng.uniform(lo, hi), v_ego * rng.uniform(0.5, 0.95)), 2.0), 2)


def _ego_speed(mut: Mutator, sc: Scenario, dist: float) -> float:
    """[m/s] the ego's expected speed ``dist`` m along its route (the mutator's profile of the empty road)."""
    s, t = mut._ego_profile(sc)
    j = min(max(int(np.searchsorted(s, dist)), 0), len(s) - 2)
    return float(1.0 / max(t[j + 1] - t[j], 1e-6))  # each step of the profile is 1 m driven


def _place(mut: Mutator, sc: Scenario, rng: random.Random, lo: float, hi: float, rel: float,
           own_lane: bool = False):
    """Where and when a program's vehicle starts: a spot ``lo``..``hi`` m along the ego's route, on the
    ego's lane (``own_lane``) or a lane beside it, departing when the ego's front is expected ``rel`` m
    past the spot (negative: still before it). Returns (the ego's lane there, the vehicle's lane, position
    [m], departure [s], the ego's expected speed there [m/s]) or None."""
    goal = mut.rmap.route_length(mut._route(sc), sc.mission.start_pos, sc.mission.goal_pos)
    hi = min(hi, 0.7 * goal)  # where the ego still has road left to meet it
    if hi <= lo:
        return None
    d = rng.uniform(lo, hi)
    spot = _route_spot(mut, sc, d)
    if spot is None:
        return None
    _, ego_lane, pos = spot
    if own_lane:
        lane = mut.rmap.lane(ego_lane)
    else:
        beside = _beside(mut, ego_lane)
        if not beside:
            return None
        lane = rng.choice(beside)
    pos = round(min(pos, lane.getLength() - 0.5), 2)
    depart = round(max(mut._ego_eta(sc, max(d + rel, 0.0)), 0.0), 1) if d + rel > 0 else 0.0
    return ego_lane, lane, pos, depart, max(_ego_speed(mut, sc, d), 1.0)


def _vehicle(mut: Mutator, sc: Scenario, lane, pos: float, speed: float, depart: float, steps, taken=()) -> Actor:
    return Actor(id=mut._new_id(sc, "v", list(taken)), kind=ActorKind.VEHICLE, nav=NavType.MANEUVER,
                 start_lane=lane.getID(), start_pos=pos, speed=speed, depart=depart, dest_edge=_dest(mut, sc),
                 maneuvers=tuple(steps))


# ------------------------------------------------------------------------------ the programs
def overtake_cut_in(mut, sc, rng):
    """From behind on the lane beside, faster than the ego, cut in ``at`` m ahead, then slow down below the
    ego's speed (AV-Fuzzer's type 1 needs the second half: a faster car that cuts in only pulls away)."""
    placed = _place(mut, sc, rng, -30.0, 150.0, rel=rng.uniform(10.0, 40.0))
    if placed is None:
        return None
    ego_lane, lane, pos, depart, v_ego = placed
    speed = round(min(SPEED_SHARE[1] * lane_limit(mut, lane.getID()), v_ego * rng.uniform(1.05, 1.25)), 2)
    duration = round(rng.uniform(*LANE_CHANGE_S), 2)
    at = round(rng.uniform(cut_in_gap(0.0, duration), 25.0), 1)  # it is the faster: no closing speed
    change, _ = _toward(lane, mut.rmap.lane(ego_lane))
    slow = round(v_ego * rng.uniform(0.3, 0.8), 2)
    # as it cuts in (while the ego is within ``at`` + 5-20 m), it slows, no harder than a careful follower
    # 5 m behind answers after its reaction (braking at 5 m/s^2)
    rate = round(rng.uniform(1.5, 3.0), 1)
    within = round(at + rng.uniform(5.0, 20.0), 1)
    a = _vehicle(mut, sc, lane, pos, speed, depart, [
        Maneuver(time=0.5, action=change, value=duration, trigger=Trigger.GAP, at=at),
        Maneuver(time=0.5, action=ManeuverAction.SPEED, value=slow, trigger=Trigger.GAP, at=within, rate=rate)])
    return [a], [], {}, (f"{a.id} overtakes from {lane.getID()} at {speed:.1f} m/s, cuts in {at} m ahead "
                         f"({duration} s) and slows to {slow:.1f} m/s at {rate} m/s^2")


def beside(mut, sc, rng):
    """Rides on the lane beside the ego at about its speed, where a lane change of the ego must look."""
    placed = _place(mut, sc, rng, -20.0, 150.0, rel=rng.uniform(-10.0, 15.0))
    if placed is None:
        return None
    ego_lane, lane, pos, depart, v_ego = placed
    speed = round(min(v_ego * rng.uniform(0.9, 1.1), 1.2 * lane_limit(mut, lane.getID())), 2)
    a = _vehicle(mut, sc, lane, pos, speed, depart, [Maneuver(time=0.0, action=ManeuverAction.SPEED, value=speed)])
    return [a], [], {}, f"{a.id} rides beside the ego on {lane.getID()} at {speed:.1f} m/s"


def cut_in(mut, sc, rng):
    """Ahead on the lane beside, slower than the ego, cuts in when the ego is ``at`` s behind it."""
    placed = _place(mut, sc, rng, 25.0, 200.0, rel=-rng.uniform(15.0, 40.0))
    if placed is None:
        return None
    ego_lane, lane, pos, depart, v_ego = placed
    speed = _leader_speed(mut, lane.getID(), rng, SPEED_SHARE[0], 0.95, v_ego)
    duration = round(rng.uniform(*LANE_CHANGE_S), 2)
    limit = lane_limit(mut, ego_lane)  # the fairness rule's worst case: the ego at the limit
    low = cut_in_gap(limit - speed, duration) / limit
    at = round(rng.uniform(low, low + 1.5), 2)
    change, _ = _toward(lane, mut.rmap.lane(ego_lane))
    a = _vehicle(mut, sc, lane, pos, speed, depart,
                 [Maneuver(time=0.5, action=change, value=duration, trigger=Trigger.HEADWAY, at=at)])
    return [a], [], {}, f"{a.id} on {lane.getID()} at {speed:.1f} m/s cuts in at a headway of {at} s ({duration} s)"


def brake_check(mut, sc, rng):
    """Ahead on the ego's lane, brakes hard when the ego is within ``at`` s, then drives on."""
    placed = _place(mut, sc, rng, 25.0, 200.0, rel=-rng.uniform(15.0, 40.0), own_lane=True)
    if placed is None:
        return None
    ego_lane, lane, pos, depart, v_ego = placed
    speed = _leader_speed(mut, lane.getID(), rng, 0.7, 1.0, v_ego)
    at = round(rng.uniform(0.6, 2.5), 2)
    rate = round(rng.uniform(*BRAKE_RATE), 1)
    slow = round(speed * rng.uniform(0.0, 0.5), 2)
    hold = round(rng.uniform(1.0, 4.0), 1)
    a = _vehicle(mut, sc, lane, pos, speed, depart, [
        Maneuver(time=0.5, action=ManeuverAction.SPEED, value=slow, trigger=Trigger.HEADWAY, at=at, rate=rate),
        Maneuver(time=hold, action=ManeuverAction.SPEED, value=speed, trigger=Trigger.AFTER, rate=2.5)])
    return [a], [], {}, (f"{a.id} ahead on {lane.getID()} at {speed:.1f} m/s brakes at {rate} m/s^2 to "
                         f"{slow:.1f} m/s when the ego is {at} s behind, for {hold} s")


def slow_ahead(mut, sc, rng):
    """Ahead on the ego's lane, slows down for good (to 0.2-0.6 of the limit) when the ego comes near."""
    placed = _place(mut, sc, rng, 25.0, 200.0, rel=-rng.uniform(20.0, 60.0), own_lane=True)
    if placed is None:
        return None
    ego_lane, lane, pos, depart, v_ego = placed
    speed = _leader_speed(mut, lane.getID(), rng, SPEED_SHARE[0], 1.0, v_ego)
    slow = round(speed * rng.uniform(0.2, 0.6), 2)
    at = round(rng.uniform(1.0, 4.0), 2)
    rate = round(rng.uniform(1.0, 3.0), 1)
    a = _vehicle(mut, sc, lane, pos, speed, depart, [
        Maneuver(time=0.5, action=ManeuverAction.SPEED, value=slow, trigger=Trigger.HEADWAY, at=at, rate=rate)])
    return [a], [], {}, f"{a.id} ahead on {lane.getID()} slows from {speed:.1f} to {slow:.1f} m/s at {at} s headway"


def aborted_lane_change(mut, sc, rng):
    """Ahead on the lane beside, starts changing into the ego's lane and turns back."""
    placed = _place(mut, sc, rng, 20.0, 200.0, rel=-rng.uniform(15.0, 40.0))
    if placed is None:
        return None
    ego_lane, lane, pos, depart, v_ego = placed
    speed = _leader_speed(mut, lane.getID(), rng, 0.7, 1.0, v_ego)
    duration = round(rng.uniform(2.0, 4.0), 2)
    depth = round(rng.uniform(1.0, 2.5), 2)
    at = round(cut_in_gap(lane_limit(mut, ego_lane) - speed, duration) + rng.uniform(0.0, 15.0), 1)
    _, nudge = _toward(lane, mut.rmap.lane(ego_lane))
    a = _vehicle(mut, sc, lane, pos, speed, depart, [
        Maneuver(time=0.5, action=nudge, value=duration, trigger=Trigger.GAP, at=at, depth=depth)])
    return [a], [], {}, f"{a.id} on {lane.getID()} swerves {depth} m towards the ego {at} m ahead and back"


def squeeze(mut, sc, rng):
    """Two vehicles close in on the ego together: from both sides, or from beside and ahead."""
    placed = _place(mut, sc, rng, 20.0, 200.0, rel=-rng.uniform(5.0, 30.0))
    if placed is None:
        return None
    ego_lane, lane, pos, depart, v_ego = placed
    ego = mut.rmap.lane(ego_lane)
    sides = _beside(mut, ego_lane)
    speed = _leader_speed(mut, lane.getID(), rng, 0.8, 1.0, v_ego)
    duration = round(rng.uniform(2.0, 4.0), 2)
    at = round(cut_in_gap(lane_limit(mut, ego_lane) - speed, duration) + rng.uniform(0.0, 8.0), 1)
    _, nudge = _toward(lane, ego)
    first = _vehicle(mut, sc, lane, pos, speed, depart, [
        Maneuver(time=0.5, action=nudge, value=duration, trigger=Trigger.GAP, at=at,
                 depth=round(rng.uniform(1.0, 1.8), 2))])
    other = [l for l in sides if l.getID() != lane.getID()]
    if other:  # the other side: it cuts in a little further ahead
        lane2 = other[0]
        change, _ = _toward(lane2, ego)
        at2 = round(at + rng.uniform(3.0, 12.0), 1)
        second = _vehicle(mut, sc, lane2, round(min(pos + 8.0, lane2.getLength() - 0.5), 2), speed, depart, [
            Maneuver(time=0.5, action=change, value=duration, trigger=Trigger.GAP, at=at2)], taken=[first])
        how = f"from both sides ({lane.getID()}, {lane2.getID()})"
    else:  # the ego's own lane: a leader that brakes as the other closes in from beside
        ahead = round(min(pos + rng.uniform(15.0, 35.0), ego.getLength() - 0.5), 2)
        rate = round(rng.uniform(*BRAKE_RATE), 1)
        second = _vehicle(mut, sc, ego, ahead, speed, depart, [
            Maneuver(time=0.5, action=ManeuverAction.SPEED, value=round(speed * 0.5, 2), trigger=Trigger.HEADWAY,
                     at=round(rng.uniform(0.8, 2.0), 2), rate=rate)], taken=[first])
        how = f"from {lane.getID()} and ahead on {ego.getID()}"
    return [first, second], [], {}, f"{first.id} and {second.id} squeeze the ego {how} at {speed:.1f} m/s"


PROGRAMS: tuple[Situation, ...] = (
    Situation("overtake_cut_in", "AV-Fuzzer type 1: an NPC overtakes and cuts in", overtake_cut_in),
    Situation("beside", "AV-Fuzzer type 2: the ego cuts in and hits (a vehicle where it changes lanes)", beside),
    Situation("cut_in", "AV-Fuzzer type 3: another NPC cuts in front of the ego", cut_in),
    Situation("brake_check", "AV-Fuzzer type 4: the ego rear-ends a braking NPC", brake_check),
    Situation("slow_ahead", "Lead vehicle slowing down, then moving at lower constant speed", slow_ahead),
    Situation("squeeze", "AV-Fuzzer type 5: two adjacent NPCs squeeze the ego", squeeze),
    Situation("aborted_lane_change", "Vehicle(s) drifting - same direction (an aborted lane change)",
              aborted_lane_change),
)
