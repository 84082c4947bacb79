"""Check a Scenario against its road network before anything runs.

Every problem raises :class:`InvalidScenario` naming the file, the field and
what would be valid. Returns the ego's route, which the writer needs anyway.
"""

from __future__ import annotations

import math

from shapely.geometry import LineString, Polygon

from drivefuzz.errors import InvalidScenario
from drivefuzz.scenario.roadmap import PASSENGER, PEDESTRIAN, RoadMap
from drivefuzz.scenario import ActorKind, Puddle, Scenario, lane_edge


def _examples(items: list[str], n: int = 4) -> str:
    return ", ".join(items[:n]) + (", ..." if len(items) > n else "")


def _check_lane(rmap: RoadMap, src: str, field: str, lane_id: str, pos: float, vclass: str, what: str) -> None:
    if not rmap.has_lane(lane_id):
        pool = rmap.lanes(vclass) if vclass == PASSENGER else rmap.walkable_lanes()
        raise InvalidScenario(src, field, f"unknown lane {lane_id!r} in {rmap.path.name}",
                              f"a lane id such as {_examples(pool)}")
    lane = rmap.lane(lane_id)
    if not lane.allows(vclass):
        pool = rmap.lanes(vclass) if vclass == PASSENGER else rmap.walkable_lanes()
        raise InvalidScenario(src, field, f"{what} placed on lane {lane_id!r}, which does not allow {vclass}s "
                              f"(off the road{' or off any walkable lane' if vclass == PEDESTRIAN else ''})",
                              f"a lane allowing {vclass}s, such as {_examples(pool)}")
    length = lane.getLength()
    if not 0.0 <= pos <= length:
        raise InvalidScenario(src, field.rsplit(".", 1)[0] + ".start_pos" if "." in field else field,
                              f"position {pos} m is off lane {lane_id!r}", f"0 to {length:.2f} m")


def _check_edge(rmap: RoadMap, src: str, field: str, edge_id: str, pos: float | None) -> None:
    if not rmap.has_edge(edge_id):
        raise InvalidScenario(src, field, f"unknown edge {edge_id!r} in {rmap.path.name}",
                              f"an edge id such as {_examples(rmap.edge_ids())}")
    if pos is not None:
        length = rmap.edge(edge_id).getLength()
        if not 0.0 <= pos <= length:
            raise InvalidScenario(src, field.replace("edge", "pos"), f"position {pos} m is off edge {edge_id!r}",
                                  f"0 to {length:.2f} m")


def validate(scenario: Scenario, rmap: RoadMap, source: str) -> tuple[str, ...]:
    """Raise InvalidScenario on the first problem; return the ego's route (normal edges)."""
    m = scenario.mission
    _check_lane(rmap, source, "mission.start_lane", m.start_lane, m.start_pos, PASSENGER, "the ego is")
    _check_edge(rmap, source, "mission.goal_edge", m.goal_edge, m.goal_pos)
    route = rmap.route(m.start_edge, m.goal_edge)
    if route is None:
        raise InvalidScenario(source, "mission", f"no route for a passenger car from {m.start_edge!r} to "
                              f"{m.goal_edge!r} in {rmap.path.name}", "a goal edge reachable from the start lane")
    if len(route) == 1 and m.goal_pos <= m.start_pos:
        raise InvalidScenario(source, "mission.goal_pos", f"goal {m.goal_pos} m lies behind the start "
                              f"{m.start_pos} m on the same edge", "a goal position ahead of the start")
    for i, a in enumerate(scenario.actors):
        field = f"actors[{i}]({a.id}).start_lane"
        if a.kind is ActorKind.PEDESTRIAN:
            _check_lane(rmap, source, field, a.start_lane, a.start_pos, PEDESTRIAN, f"pedestrian {a.id!r} is")
            if lane_edge(a.start_lane).startswith(":"):
                raise InvalidScenario(source, field, f"pedestrian {a.id!r} starts on junction lane {a.start_lane!r}",
                                      "a sidewalk lane of a normal edge")
        else:
            _check_lane(rmap, source, field, a.start_lane, a.start_pos, PASSENGER, f"vehicle {a.id!r} is")
        if a.dest_edge is not None:
            _check_edge(rmap, source, f"actors[{i}]({a.id}).dest_edge", a.dest_edge, a.dest_pos)
            vclass = PEDESTRIAN if a.kind is ActorKind.PEDESTRIAN else PASSENGER
            if a.kind is ActorKind.VEHICLE and rmap.route(a.start_edge, a.dest_edge, vclass) is None:
                raise InvalidScenario(source, f"actors[{i}]({a.id}).dest_edge",
                                      f"no route from {a.start_edge!r} to {a.dest_edge!r}",
                                      "a destination reachable from the actor's start")
    for i, p in enumerate(scenario.puddles):
        for name in ("x", "y", "length", "width", "rotation", "friction"):
            if not math.isfinite(getattr(p, name)):
                raise InvalidScenario(source, f"puddles[{i}].{name}", "not a finite number")
    return route


def puddle_polygon(p: Puddle) -> Polygon:
    return Polygon(p.corners())


def puddle_lanes(p: Puddle, rmap: RoadMap) -> list[str]:
    """Road lanes (normal edges, passenger) whose centre line crosses the puddle."""
    poly = puddle_polygon(p)
    radius = math.hypot(p.length, p.width) / 2 + 10.0
    out = set()
    for lane, _d in rmap.net.getNeighboringLanes(p.x, p.y, radius, includeJunctions=False):
        if lane.getEdge().getFunction() != "" or not lane.allows(PASSENGER):
            continue
        if LineString([pt[:2] for pt in lane.getShape()]).intersects(poly):
            out.add(lane.getID())
    return sorted(out)
