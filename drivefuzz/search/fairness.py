"""Fair adversaries: the timing rules that every placed or moved actor must meet.

A finding must be a bug a careful driver would have avoided, so the mutator never builds a situation that
no driver could get out of. After every placement, position, timing or speed change, :func:`unfair` checks:

- **followers can stop**: a vehicle behind the ego on its lane (or on a lane feeding it) must be able to stop
  for a stopped ego from its speed at ``NPC_DECEL``, with ``MARGIN`` to spare; a *linear* vehicle (which
  ignores everyone) is never placed behind the ego at all;
- **no pop-ups**: an actor that departs later must not appear inside the ego's stopping distance ahead of
  where the ego is expected to be by then (or inside a follower's stopping distance behind it); where the
  ego enters at speed, an actor there from the start must leave it room to shed the speed difference;
- **walkers step out in time**: a jaywalker must reach the ego's path either after the ego has passed or
  while the ego can still stop before it (careful braking ``EGO_DECEL`` after ``REACTION``);
- **walkers do not walk into a stopped ego** (:func:`walks_into_stopped_ego`): a jaywalker (who ignores
  everyone) must not cross the ego's route where the ego is expected to stand while the walker is on the road
  (waiting at a light, as the mutator's profile of the ego has it), nor just behind another jaywalker's line
  while that one is on the road too (the ego that stops for the first, short of its line, stands on the
  second's: no driver avoids a walker who walks into its side while it waits);
- **walkers cross, they do not walk along** (:func:`walks_along_lane`): a jaywalker whose straight line runs
  ``ALONG_LANE_M`` metres or more along a lane that cars use (at under 45 degrees to it; a targeted move of its
  start leaves its destination where it was) can only ever meet an ego that has stopped for it, from behind
  or in its side: it is not placed;
- **cut-ins leave room**: a maneuver program's lane change or nudge is triggered by the gap or the headway to
  the ego (or by the clock, with SUMO's own safety gaps), and its gap leaves a careful driver room to react to
  the closing speed and brake (:func:`drivefuzz.scenario.model.cut_in_gap`; the executor holds back a lane
  change whose real closing speed needs more); a nudge timed to its peak (``Trigger.PEAK``) must keep the car
  inside its own lane (a drift towards the line, :func:`drivefuzz.scenario.model.in_lane`): it takes none of the
  ego's room and may come level with it (a nudge timed by the gap keeps the rule above, as before); a program's
  vehicle that starts on a lane beside the ego's is
  not a follower of the ego, and one that appears ahead of it later needs room only for the speed the ego
  must shed, not for a full stop;
- **nobody enters within reach** (:func:`inserted_within_reach`): a vehicle (or a jaywalker) that departs later
  does not enter where it and the ego, as the ego is expected to be then, would close their gap within a
  reaction time (SUMO would insert it beside or behind the ego, and it strikes the ego before any driver could
  react);
- **obstacles are not at the start**: an immobile actor stands at least ``MutationConfig.immobile_min_range``
  metres ahead of the ego's start along its route (or behind it);
- **obstacles leave a way on**: an immobile vehicle on the ego's route (or a walker standing or walking on a
  lane cars use, as on networks without sidewalks) does not stand in a junction's exit, and leaves another
  lane that leads on along the route, or room to pass it and merge back; on the goal's road it leaves another
  lane, or stands beyond the goal with room for a queue (``QUEUE_CARS`` cars) between the goal and its rear:
  the cars that queue behind it on a road of one lane would otherwise stand on the goal.

The ego's expected motion comes from the mutator's profile of how the reference ADS drives the empty route
(:meth:`drivefuzz.search.mutate.Mutator._ego_profile`). Never imports libsumo.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from drivefuzz.scenario import Actor, ActorKind, ManeuverAction, NavType, Scenario, Trigger
from drivefuzz.scenario.model import (CAREFUL_DECEL, CAREFUL_REACTION, EGO_LENGTH, MIN_CLOSE_TTC, MIN_FOLLOW_S,
                                      cut_in_gap, in_lane)
from drivefuzz.scenario.roadmap import PASSENGER

if TYPE_CHECKING:  # pragma: no cover
    from drivefuzz.search.mutate import Mutator

NPC_DECEL = 4.5  # [m/s^2] SUMO's default comfortable deceleration of a passenger car
EGO_DECEL = CAREFUL_DECEL  # [m/s^2] a careful driver's firm braking on a dry road
REACTION = CAREFUL_REACTION  # [s] a careful driver's reaction time
MARGIN = 2.0  # [m] left over after a stop
VEHICLE_LENGTH = 5.0  # [m] SUMO's default passenger car
MERGE_ROOM = 20.0  # [m] past an obstacle, to merge back into the only lane that leads on
JUNCTION_EXIT = 15.0  # [m] the first metres of an edge after a junction: no obstacle there
QUEUE_CARS = 3  # cars that may queue behind an obstacle beyond the goal on a road of one lane
SUMO_MIN_GAP = 2.5  # [m] SUMO's default minGap between queued cars
INSERT_MARGIN = 1.0  # [m] left between a vehicle entering later and the ego, beyond a reaction's closing
WALKER_RADIUS = 0.5  # [m] a walker's body, for the same rule


def stopping_distance(speed: float, decel: float, reaction: float = 0.0) -> float:
    """[m] to stop from ``speed`` [m/s] braking at ``decel`` [m/s^2] after ``reaction`` [s]."""
    return speed * reaction + speed * speed / (2.0 * decel)


def route_distance(mut: "Mutator", sc: Scenario, lane_id: str, pos: float) -> float | None:
    """[m] along the ego's route from its front bumper at the start to ``pos`` on ``lane_id``; negative behind
    the ego (its own lane, or a lane that feeds it); None when the lane is elsewhere."""
    rmap, m = mut.rmap, sc.mission
    edge = rmap.lane(lane_id).getEdge().getID()
    route = mut._route(sc)
    if edge in route:
        i = route.index(edge)
        return sum(rmap.edge(e).getLength() for e in route[:i]) + pos - m.start_pos
    for inc in rmap.lane(m.start_lane).getIncoming():  # a lane that feeds the ego's start lane
        if inc.getID() == lane_id:
            return -(m.start_pos + mut._via_length(lane_id, m.start_lane) + inc.getLength() - pos)
    return None


def _ego_at(mut: "Mutator", sc: Scenario, t: float) -> tuple[float, float]:
    """(distance [m] covered by the ego's front bumper, speed [m/s]) expected at time ``t`` [s]."""
    s, ts = mut._ego_profile(sc)
    d = float(np.interp(t, ts, s))
    j = int(np.clip(np.searchsorted(ts, t), 1, len(ts) - 1))
    v = 1.0 / max(ts[j] - ts[j - 1], 1e-6)  # each step of the profile is 1 m driven
    return d, float(v)


def unfair(mut: "Mutator", sc: Scenario, actor: Actor) -> str | None:
    """Why ``actor`` in ``sc`` would leave a careful ego no way out, or None when it is fair."""
    d = route_distance(mut, sc, actor.start_lane, actor.start_pos)
    if actor.kind is ActorKind.PEDESTRIAN:
        if actor.nav is NavType.LINEAR:
            why = walks_along_lane(mut, actor)
            if not why and d is not None:
                why = _jaywalker(mut, sc, actor, d) or walks_into_stopped_ego(mut, sc, actor, d)
            return why or inserted_within_reach(mut, sc, actor)
        if actor.nav is NavType.IMMOBILE and d is not None and 0.0 <= d < mut.cfg.immobile_min_range:
            return f"stands {d:.1f} m ahead of the ego's start"
        if actor.nav in (NavType.IMMOBILE, NavType.AUTOPILOT) and d is not None and d > 0.0 \
                and mut.rmap.lane(actor.start_lane).allows(PASSENGER):  # no sidewalk: a slow obstacle
            return _blocks_the_route(mut, sc, actor)
        return None
    if actor.nav is NavType.MANEUVER:
        why = _program_unfair(mut, actor)
        if why:
            return why
    why = inserted_within_reach(mut, sc, actor)
    if why:
        return why
    if d is None:
        return None
    if actor.nav is NavType.IMMOBILE and actor.depart <= 0.0 and 0.0 <= d < mut.cfg.immobile_min_range:
        return f"stands {d:.1f} m ahead of the ego's start"
    if actor.nav is NavType.IMMOBILE and d > 0.0:
        why = _blocks_the_route(mut, sc, actor)
        if why:
            return why
    ego_front, ego_v = _ego_at(mut, sc, actor.depart)
    # SUMO's lane position of a vehicle is its front bumper
    gap_behind = ego_front - EGO_LENGTH - d  # actor's front -> ego's rear
    gap_ahead = d - VEHICLE_LENGTH - ego_front  # ego's front -> actor's rear
    beside = actor.nav is NavType.MANEUVER and \
        actor.start_lane != _ego_lane_at(mut, sc, actor.start_lane, actor.start_pos)
    if gap_behind > -1.0:  # starts behind the ego
        if beside:  # on a lane beside the ego's: not its follower (its cut-ins are checked above)
            return None
        if actor.nav is NavType.LINEAR:
            return "a reckless vehicle behind the ego (no driver can escape it)"
        need = stopping_distance(actor.speed, NPC_DECEL) + MARGIN
        if actor.nav is not NavType.IMMOBILE and gap_behind < need:
            return f"{gap_behind:.1f} m behind the ego at {actor.speed:.1f} m/s, needs {need:.1f} m to stop"
        return None
    if actor.depart > 0.0:  # appears later, ahead of the ego (or on it)
        # a program's vehicle appears moving: the ego sheds only the speed difference
        shed = max(ego_v - actor.speed, 0.0) if actor.nav is NavType.MANEUVER else ego_v
        need = stopping_distance(shed, EGO_DECEL, REACTION) + MARGIN
        if gap_ahead < need:
            return f"appears {gap_ahead:.1f} m ahead of the ego at {actor.depart:.1f} s, it needs {need:.1f} m"
    elif sc.mission.start_speed > 0.0:  # there from the start, ahead of an ego that enters at speed
        ego_v = sc.mission.start_speed
        shed = ego_v if actor.nav is NavType.IMMOBILE else max(ego_v - actor.speed, 0.0)
        need = stopping_distance(shed, EGO_DECEL, REACTION) + MARGIN
        if gap_ahead < need:
            return (f"{gap_ahead:.1f} m ahead of the ego at the start, which enters {shed:.1f} m/s faster, "
                    f"it needs {need:.1f} m")
    return None


def _ego_pose(mut: "Mutator", sc: Scenario, front: float) -> tuple[float, float, float] | None:
    """(x, y [m], heading [rad ENU]) of the ego's centre when its front bumper is ``front`` m along its route
    (None: beyond the route's end)."""
    route = mut._route(sc)
    pos = sc.mission.start_pos + front - EGO_LENGTH / 2.0
    for i, e in enumerate(route):
        length = mut.rmap.edge(e).getLength()
        if pos <= length:
            g = mut.rmap.geom(mut.ego_lane_at(sc, i, pos))
            return g.position(min(max(pos, 0.0), g.length))
        pos -= length
    return None


def inserted_within_reach(mut: "Mutator", sc: Scenario, actor: Actor) -> str | None:
    """A vehicle that departs later must not enter the simulation within reach of the ego: where the ego is
    expected to be at its departure (the mutator's profile), the bodies must be further apart than the two
    close in one reaction time (:data:`REACTION`, at their relative velocity) plus :data:`INSERT_MARGIN`. SUMO
    inserts such a car beside or behind the ego (on the lane beside, on a road entering a junction the ego is
    crossing) and it strikes the ego within a second: triage then excuses the ego (the attribution rule
    ``appeared``) and the execution was spent on nothing. The same holds for a jaywalker (a linear walker, who
    ignores everyone) stepping off the pavement beside the passing ego; other walkers keep to the pavement."""
    walker = actor.kind is ActorKind.PEDESTRIAN
    if actor.depart <= 0.0 or (walker and actor.nav is not NavType.LINEAR):
        return None
    front, v_ego = _ego_at(mut, sc, actor.depart)
    ego = _ego_pose(mut, sc, front)
    if ego is None:
        return None
    g = mut.rmap.geom(actor.start_lane)
    half = WALKER_RADIUS if walker else VEHICLE_LENGTH / 2.0
    x, y, h = g.position(min(max(actor.start_pos - (0.0 if walker else half), 0.0), g.length))
    if walker and actor.dest_xy is not None:
        h = math.atan2(actor.dest_xy[1] - y, actor.dest_xy[0] - x)
    v = actor.speed if actor.nav is not NavType.IMMOBILE else 0.0
    v_rel = math.hypot(v * math.cos(h) - v_ego * math.cos(ego[2]), v * math.sin(h) - v_ego * math.sin(ego[2]))
    gap = math.hypot(x - ego[0], y - ego[1]) - EGO_LENGTH / 2.0 - half
    need = v_rel * REACTION + INSERT_MARGIN
    if gap < need:
        return (f"enters {gap:.1f} m from the ego's body at {actor.depart:.1f} s, closing at {v_rel:.1f} m/s: "
                f"it needs {need:.1f} m")
    return None


def _ego_lane_at(mut: "Mutator", sc: Scenario, lane_id: str, pos: float) -> str | None:
    """The lane the ego is on at ``pos`` of ``lane_id``'s edge (before or after a lane change the route makes it
    do there; None off its route)."""
    route = mut._route(sc)
    edge = mut.rmap.lane(lane_id).getEdge().getID()
    return mut.ego_lane_at(sc, route.index(edge), pos) if edge in route else None


def _program_unfair(mut: "Mutator", actor: Actor) -> str | None:
    """A lane change or nudge timed against the ego must leave the room of :func:`cut_in_gap`; one timed by
    the clock keeps SUMO's own safety gaps (sim/world.py), and one timed after a step before it is not
    allowed (nothing would keep its gap)."""
    limit = lane_limit(mut, actor.start_lane)
    closing = limit - actor.speed  # the ego at the limit: the most it closes in
    for k, m in enumerate(actor.maneuvers):
        if m.action is ManeuverAction.SPEED:
            continue
        if m.action is ManeuverAction.FOLLOW:  # SUMO's car-following keeps the gap; how close is the question
            if m.trigger not in (Trigger.TIME, Trigger.AFTER):
                return f"step {k} (follow) is timed against the ego: only the clock may start it"
            if m.value < MIN_FOLLOW_S:
                return f"step {k} follows at a time gap of {m.value:.2f} s, under the {MIN_FOLLOW_S} s drivers keep"
            continue
        if m.action is ManeuverAction.CLOSE:  # it brakes at a time to collision it can still stop from
            if m.trigger not in (Trigger.TIME, Trigger.AFTER):
                return f"step {k} (close) is timed against the ego: only the clock may start it"
            if m.at < MIN_CLOSE_TTC:
                return f"step {k} brakes at a time to collision of {m.at:.2f} s, under {MIN_CLOSE_TTC} s"
            continue
        if m.trigger is Trigger.AFTER:
            return f"step {k} ({m.action.value}) is timed by the step before, not by the gap to the ego"
        if m.trigger is Trigger.PEAK:  # a drift inside its own lane takes none of the ego's room
            if m.action in (ManeuverAction.NUDGE_LEFT, ManeuverAction.NUDGE_RIGHT) and in_lane(
                    m.depth, mut.rmap.lane(actor.start_lane).getWidth()):
                continue
            return f"step {k} ({m.action.value}) is timed to its peak, which only a drift inside its lane may be"
        need = cut_in_gap(closing, m.value)
        if m.trigger is Trigger.GAP and m.at < need:
            return f"step {k} ({m.action.value}) starts {m.at:.1f} m ahead of the ego, needs {need:.1f} m"
        if m.trigger is Trigger.HEADWAY and m.at * limit < need:
            return (f"step {k} ({m.action.value}) starts at a headway of {m.at:.2f} s, needs "
                    f"{need / limit:.2f} s at {limit:.1f} m/s")
    return None


def _blocks_the_route(mut: "Mutator", sc: Scenario, actor: Actor) -> str | None:
    """An obstacle must leave a lawful way on along the ego's route: another lane of its edge that leads to
    the route's next edge, or room (``MERGE_ROOM``) to pass it and merge back before its lane ends; and it
    must not stand in a junction's exit (the first ``JUNCTION_EXIT`` metres of an edge after the start)."""
    rmap, route = mut.rmap, mut._route(sc)
    edge = rmap.lane(actor.start_lane).getEdge().getID()
    if edge not in route:
        return None
    i = route.index(edge)
    if i > 0 and actor.start_pos < JUNCTION_EXIT:
        return f"stands {actor.start_pos:.1f} m into {edge}, in the exit of the junction the ego comes through"
    others = [l for l in rmap.edge(edge).getLanes() if l.allows(PASSENGER) and l.getID() != actor.start_lane]
    if i + 1 >= len(route):  # the goal's road: the way on is another lane, or the goal lies before the obstacle
        rear = actor.start_pos - VEHICLE_LENGTH  # SUMO's lane position is the front bumper
        if others:
            return None
        if rear <= sc.mission.goal_pos + MARGIN:
            return f"blocks {edge}, a road of one lane, before the ego's goal at {sc.mission.goal_pos:.1f} m"
        queue = QUEUE_CARS * (VEHICLE_LENGTH + SUMO_MIN_GAP)
        if rear < sc.mission.goal_pos + MARGIN + queue:
            return (f"stands {rear - sc.mission.goal_pos:.1f} m beyond the ego's goal on {edge}, a road of one "
                    f"lane: the cars that queue behind it would stand on the goal (needs {MARGIN + queue:.1f} m)")
        return None
    leads = {fl for fl, _tl, _via in rmap.connections(edge, route[i + 1])}
    if leads - {actor.start_lane}:
        return None  # another lane leads on
    if not others:
        return f"blocks {edge}, a road of one lane on the ego's route"
    room = rmap.lane(actor.start_lane).getLength() - actor.start_pos
    if room < MERGE_ROOM:
        return f"blocks {actor.start_lane}, the only lane on to {route[i + 1]}, {room:.1f} m before its end"
    return None


def _jaywalker(mut: "Mutator", sc: Scenario, actor: Actor, d: float) -> str | None:
    """A walker crossing the ego's route at ``d`` [m] must reach the ego's lane when the ego can still stop
    (or after it has passed)."""
    rmap = mut.rmap
    lane = rmap.lane(actor.start_lane)
    road = [l for l in lane.getEdge().getLanes() if l.allows(PASSENGER)]
    if not road or actor.speed <= 0.0:
        return None
    # walking distance to the nearest road lane's edge: half its own lane, and any lanes in between
    between = sum(l.getWidth() for l in lane.getEdge().getLanes()
                  if min(lane.getIndex(), road[0].getIndex()) < l.getIndex() < max(lane.getIndex(), road[-1].getIndex())
                  and not l.allows(PASSENGER))
    t_enter = actor.depart + (lane.getWidth() / 2 + between) / actor.speed if lane not in road else actor.depart
    ego_front, ego_v = _ego_at(mut, sc, t_enter)
    remaining = d - ego_front
    if remaining < -EGO_LENGTH:  # the ego has passed
        return None
    need = stopping_distance(ego_v, EGO_DECEL, REACTION)
    if remaining < need:
        return (f"steps onto the road at {t_enter:.1f} s, {max(remaining, 0.0):.1f} m ahead of the ego, "
                f"which needs {need:.1f} m to stop")
    return None


def lane_limit(mut: "Mutator", lane_id: str) -> float:
    """[m/s] the lane's speed limit (a floor of 5 m/s for odd networks)."""
    return max(mut.rmap.geom(lane_id).speed, 5.0) if math.isfinite(mut.rmap.geom(lane_id).speed) else 13.9


#: [m] behind another jaywalker's line (along the ego's route) where the ego that stops for that walker stands:
#: its standstill gap and prediction margin before the line, and its length.
STOPPED_FOR_WALKER = 12.0
#: [m/s] an expected speed below which the ego counts as standing (its profile's stops at lights and the goal).
STANDING = 0.5


def _on_road(mut: "Mutator", actor: Actor) -> tuple[float, float] | None:
    """[s] (from, to) when the jaywalker ``actor`` is on the road lanes it crosses (None: it does not move)."""
    lane = mut.rmap.lane(actor.start_lane)
    lanes = lane.getEdge().getLanes()
    road = [l for l in lanes if l.allows(PASSENGER)]
    if not road or actor.speed <= 0.0:
        return None
    lo, hi = min(l.getIndex() for l in road), max(l.getIndex() for l in road)
    between = sum(l.getWidth() for l in lanes if min(lane.getIndex(), lo) < l.getIndex() < max(lane.getIndex(), hi)
                  and not l.allows(PASSENGER))
    t0 = actor.depart + ((lane.getWidth() / 2 + between) / actor.speed if lane not in road else 0.0)
    return t0, t0 + sum(l.getWidth() for l in road) / actor.speed


def walks_into_stopped_ego(mut: "Mutator", sc: Scenario, actor: Actor, d: float) -> str | None:
    """Why the jaywalker ``actor``, crossing the ego's route ``d`` [m] from its start, would walk into an ego that
    stands still (None: it would not): the ego is expected to stand on its line while it crosses, or another
    jaywalker crosses up to :data:`STOPPED_FOR_WALKER` m beyond its line while both are on the road (the ego
    waits for that one on this one's line); and the same with ``actor`` as the one the ego waits for."""
    window = _on_road(mut, actor)
    if window is None:
        return None
    for t in np.arange(window[0], window[1] + 0.25, 0.5):
        front, v = _ego_at(mut, sc, float(t))
        if v < STANDING and -EGO_LENGTH - MARGIN <= d - front <= MARGIN:
            return f"crosses at {t:.1f} s where the ego is expected to stand: it would walk into it"
    for other in sc.actors:
        if other.id == actor.id or other.kind is not ActorKind.PEDESTRIAN or other.nav is not NavType.LINEAR:
            continue
        d2 = route_distance(mut, sc, other.start_lane, other.start_pos)
        w2 = _on_road(mut, other)
        if d2 is None or w2 is None or w2[1] < window[0] or window[1] < w2[0]:
            continue
        if 0.0 < d2 - d <= STOPPED_FOR_WALKER:
            return (f"crosses {d2 - d:.1f} m before {other.id} while it crosses too: it would walk into the ego "
                    f"waiting for it")
        if 0.0 < d - d2 <= STOPPED_FOR_WALKER:
            return (f"crosses {d - d2:.1f} m beyond {other.id} while it crosses too: {other.id} would walk into the "
                    f"ego waiting for it")
    return None


#: [m] of a jaywalker's line that may run along one lane cars use (at under :data:`ALONG_ANGLE_DEG` to it)
ALONG_LANE_M = 4.0
ALONG_ANGLE_DEG = 45.0


def walks_along_lane(mut: "Mutator", actor: Actor) -> str | None:
    """Why the linear walker ``actor`` walks along a lane that cars use (None: it crosses, or stays off them).

    Its line from its start to ``dest_xy`` is sampled every metre; a sample counts for the car lane it lies on
    (within half the lane's width) when the line runs at under :data:`ALONG_ANGLE_DEG` to the lane there. Such
    a walker meets the ego only after the ego has stopped behind it, or walks into the ego's side (the town
    campaigns' walker-along-a-lane incidents)."""
    if actor.kind is not ActorKind.PEDESTRIAN or actor.nav is not NavType.LINEAR or actor.dest_xy is None:
        return None
    rmap = mut.rmap
    x0, y0, _ = rmap.geom(actor.start_lane).position(actor.start_pos)
    dx, dy = actor.dest_xy[0] - x0, actor.dest_xy[1] - y0
    length = math.hypot(dx, dy)
    if length < ALONG_LANE_M:
        return None
    ux, uy = dx / length, dy / length
    cos_max = math.cos(math.radians(ALONG_ANGLE_DEG))
    along: dict[str, int] = {}
    for s in np.arange(0.5, length, 1.0):
        x, y = x0 + ux * s, y0 + uy * s
        near = rmap.nearest_lane(x, y, radius=3.0, vclass=PASSENGER)
        if near is None:
            continue
        g = rmap.geom(near[0])
        if near[1] > g.width / 2:
            continue
        _, _, h = g.position(g.project(x, y)[0])
        if abs(math.cos(h) * ux + math.sin(h) * uy) >= cos_max:
            along[near[0]] = along.get(near[0], 0) + 1
    lane, metres = max(along.items(), key=lambda kv: (kv[1], kv[0]), default=(None, 0))
    if metres >= ALONG_LANE_M:
        return f"walks {metres} m along {lane}, a lane cars use: it could only meet an ego stopped for it"
    return None
