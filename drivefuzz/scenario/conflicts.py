"""Conflict points of a network, and seed missions whose route crosses one.

Random missions (:mod:`drivefuzz.scenario.seed`) mostly drive straight through green lights; the
situations where driving bugs live are rarer: an unprotected left turn, a give-way line, a merge,
a crosswalk, a signal change met at speed. This module finds those places from the network's own
junction logic and builds missions that drive through them. The seed command (and the campaign,
when it wants new seeds) calls :func:`conflict_missions` beside the random missions; a targeted
mutator may read :func:`conflict_points` to place a foe on one of a point's ``foe_lanes``.

What the junction logic gives (SUMO's ``.net.xml``, read with sumolib where it can):

- every *link* of a junction (one connection from an incoming lane to an outgoing lane, or one
  pedestrian crossing) has an index; ``<request index=i response=… foes=…>`` holds, as bit strings
  with link 0 rightmost, the links that link ``i`` must yield to (``response``) and those whose
  paths it conflicts with (``foes``);
- a connection's ``state`` (``M`` major, ``m`` minor, ``s`` stop, ``w`` all-way stop, ``=`` equal)
  says how it passes a junction without signals; at a traffic light it is ``o`` and the signal
  program's phase strings say, per link, ``G`` (green, priority), ``g`` (green, yield) or red.

sumolib reads the request bits but not ``response`` as a public per-index look-up, and RoadMap
loads no signal programs, so both are read from the file once per call (``_junction_logic``).

A link may be a conflict point of several kinds (a left turn at a light is ``signalised`` and
maybe ``unprotected_left`` and ``crosswalk``); each gives its own :class:`ConflictPoint`. The one
exception: a left turn that yields is ``unprotected_left``, not also ``yield``, so that the two
kinds seed different situations.

Nothing here imports libsumo.
"""

from __future__ import annotations

import random
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from enum import Enum
from typing import Iterator

from drivefuzz.scenario import AdsSpec, Mission, Scenario, SimOptions
from drivefuzz.scenario.roadmap import PASSENGER, RoadMap, open_network
from drivefuzz.scenario.seed import MAX_ROUTE_M, MIN_EDGE_M, MIN_ROUTE_M, doubles_back, time_limit_for

#: Distance [m] of the ego's start before the stop line it must reach at speed.
APPROACH_MIN_M = 50.0
APPROACH_MAX_M = 150.0
#: Distance [m] of the goal beyond the junction.
BEYOND_MIN_M = 30.0
BEYOND_MAX_M = 150.0
#: Draws in a row [count] after which a kind that yields no mission is given up.
MAX_DRAWS_PER_KIND = 200

_LEFT = ("l", "L")
_TURN = ("t", "T")
_GREEN = "Gg"


class ConflictKind(str, Enum):
    """Why a passage through a junction is risky."""

    UNPROTECTED_LEFT = "unprotected_left"  # a left turn that must yield to vehicles (minor link or 'g' phase)
    YIELD = "yield"  # any other passage that must yield to vehicles, or stop (state s / w)
    MERGE = "merge"  # two links into the same outgoing lane, or an outgoing lane that ends (a ramp)
    CROSSWALK = "crosswalk"  # the passage crosses a pedestrian crossing
    SIGNALISED = "signalised"  # through a traffic light: a yellow / red change can be met at speed


@dataclass(frozen=True)
class ConflictPoint:
    """One place where the ego's passage through a junction meets foes.

    ``in_lane`` -> ``via`` -> ``out_lane`` is the ego's link; ``(x, y)`` [m, network coordinates]
    is where it meets its first foe (the stop line for ``signalised``, the end of the lane for a
    merge onto a lane that ends). ``foe_lanes`` are the incoming lanes of the foe links (a walking
    area for a crossing); ``foe_vias`` their internal lanes (the crossing lane itself for walkers).
    """

    kind: ConflictKind
    junction: str
    in_lane: str
    out_lane: str
    via: str  # first internal lane of the passage ('' in a network built without internal lanes)
    x: float
    y: float
    foe_lanes: tuple[str, ...]
    foe_vias: tuple[str, ...]
    lane_ends: bool = False  # a merge onto an outgoing lane that ends: the goal must lie beyond it

    @property
    def in_edge(self) -> str:
        return self.in_lane.rsplit("_", 1)[0]

    @property
    def out_edge(self) -> str:
        return self.out_lane.rsplit("_", 1)[0]


@dataclass(frozen=True)
class _Link:
    """One link of a junction (a vehicle connection or a pedestrian crossing)."""

    index: int  # in the junction's <request> list
    from_lane: str
    to_lane: str
    path: tuple[str, ...]  # internal lanes of the passage, in driving order (the crossing lane for walkers)
    direction: str  # SUMO's dir: s, l, r, t, L, R (walkers: s)
    state: str  # SUMO's static link state (o at a traffic light)
    tl_index: int  # -1 without a signal
    crossing: bool


@dataclass(frozen=True)
class _Logic:
    """A junction's request bits and, if signalised, its phase strings (all programs)."""

    response: dict[int, str]
    foes: dict[int, str]
    phases: tuple[str, ...]


def conflict_seed_name(network_name: str, kind: ConflictKind, i: int) -> str:
    """The seed name the caller gives the ``i``-th mission of ``kind``: ``town-conflict-yield-003``."""
    return f"{network_name}-conflict-{kind.value}-{i:03d}"


# ------------------------------------------------------------------ junction logic
def _read_logic(path: str) -> tuple[dict[str, tuple[dict[int, str], dict[int, str]]], dict[str, tuple[str, ...]]]:
    """(junction id -> (response, foes) per link index, tls id -> phase strings) from the net file."""
    requests: dict[str, tuple[dict[int, str], dict[int, str]]] = {}
    phases: dict[str, list[str]] = {}
    junction = None
    with open_network(path) as source:
        for ev, el in ET.iterparse(source, events=("start", "end")):
            if ev == "start":
                if el.tag == "junction":
                    junction = el.get("id", "")
                    requests[junction] = ({}, {})
                elif el.tag == "tlLogic":
                    junction = None
                continue
            if el.tag == "request" and junction is not None:
                i = int(el.get("index", "-1"))
                requests[junction][0][i] = el.get("response", "")
                requests[junction][1][i] = el.get("foes", "")
            elif el.tag == "tlLogic":
                phases.setdefault(el.get("id", ""), []).extend(p.get("state", "") for p in el.iter("phase"))
                el.clear()
            elif el.tag in ("edge", "junction", "connection"):
                el.clear()
    return requests, {k: tuple(v) for k, v in phases.items()}


def _bit(bits: str, j: int) -> bool:
    """Bit ``j`` of a request string (link 0 is the rightmost character)."""
    return 0 <= j < len(bits) and bits[len(bits) - 1 - j] == "1"


def _passage(rmap: RoadMap, via: str) -> tuple[str, ...]:
    """Internal lanes from ``via`` to the outgoing lane (SUMO splits a passage at internal junctions)."""
    chain: list[str] = []
    lane_id = via
    while lane_id and lane_id not in chain:
        chain.append(lane_id)
        nxt = ""
        for conn in rmap.lane(lane_id).getOutgoing():
            if conn.getViaLaneID():
                nxt = conn.getViaLaneID()
            elif conn.getToLane().getEdge().getFunction() == "internal":
                nxt = conn.getToLane().getID()
            break
        lane_id = nxt
    return tuple(chain)


def _junction_index(conn) -> int:
    """The connection's index in its junction's request list, or -1 where sumolib cannot tell: its
    ``getLinkIndex`` raises IndexError for a lane listed in ``incLanes`` whose edge does not end at the
    junction (a network of self-loops, which SUMO loads)."""
    try:
        return conn.getJunctionIndex()
    except (IndexError, ValueError, KeyError):
        return -1


def _links(rmap: RoadMap, node) -> dict[int, _Link]:
    """The vehicle links (normal edge to normal edge) and crossings of ``node``, by request index."""
    out: dict[int, _Link] = {}
    for edge in node.getIncoming():
        if edge.getFunction() != "":
            continue
        for lane in edge.getLanes():
            for conn in lane.getOutgoing():
                if conn.getTo().getFunction() != "":
                    continue
                i = _junction_index(conn)
                if i < 0:
                    continue
                via = conn.getViaLaneID() or ""
                out[i] = _Link(i, lane.getID(), conn.getToLane().getID(), _passage(rmap, via) if via else (),
                               conn.getDirection(), conn.getState(), conn.getTLLinkIndex() if conn.getTLSID() else -1,
                               False)
    for i, lane_id in enumerate(node.getInternal()):
        if not lane_id or not rmap.has_lane(lane_id):  # intLanes="" (SUMO accepts it): sumolib reads ['']
            continue
        lane = rmap.lane(lane_id)
        if lane.getEdge().getFunction() != "crossing":
            continue
        walk, tl = "", -1
        for inc in lane.getIncoming():
            walk = inc.getID()
            for conn in inc.getEdge().getOutgoing().get(lane.getEdge(), []):
                if conn.getTLSID():
                    tl = conn.getTLLinkIndex()
        out[i] = _Link(i, walk, lane_id, (lane_id,), "s", "", tl, True)
    return out


def _green_together(phases: tuple[str, ...], a: int, b: int, a_states: str = _GREEN) -> bool:
    """Whether some phase shows link ``a`` one of ``a_states`` while link ``b`` is green."""
    for s in phases:
        if a < len(s) and b < len(s) and s[a] in a_states and s[b] in _GREEN:
            return True
    return False


# ------------------------------------------------------------------ geometry
def _polyline(rmap: RoadMap, link: _Link) -> list[tuple[float, float]]:
    """The centre line of a link's passage (stop line to outgoing lane without internal lanes)."""
    pts: list[tuple[float, float]] = []
    for lane_id in link.path:
        pts.extend((float(x), float(y)) for x, y in rmap.geom(lane_id).pts)
    if not pts:
        a = rmap.geom(link.from_lane).pts[-1]
        b = rmap.geom(link.to_lane).pts[0]
        pts = [(float(a[0]), float(a[1])), (float(b[0]), float(b[1]))]
    return pts


def _segment_hit(p, p2, q, q2) -> float | None:
    """Fraction along p->p2 where it crosses q->q2, or None."""
    rx, ry = p2[0] - p[0], p2[1] - p[1]
    sx, sy = q2[0] - q[0], q2[1] - q[1]
    den = rx * sy - ry * sx
    if abs(den) < 1e-12:
        return None
    qpx, qpy = q[0] - p[0], q[1] - p[1]
    t = (qpx * sy - qpy * sx) / den
    u = (qpx * ry - qpy * rx) / den
    return t if 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0 else None


def _first_crossing(ego: list[tuple[float, float]], foes: list[list[tuple[float, float]]]) -> tuple[float, float] | None:
    """The first point along ``ego`` where it crosses any polyline of ``foes``."""
    for a, b in zip(ego[:-1], ego[1:]):
        best = None
        for foe in foes:
            for q, q2 in zip(foe[:-1], foe[1:]):
                t = _segment_hit(a, b, q, q2)
                if t is not None and (best is None or t < best):
                    best = t
        if best is not None:
            return a[0] + best * (b[0] - a[0]), a[1] + best * (b[1] - a[1])
    return None


# ------------------------------------------------------------------ classification
def _lane_ends(rmap: RoadMap, lane_id: str) -> bool:
    """Whether a lane has no onward connection while its edge goes on (an acceleration lane)."""
    lane = rmap.lane(lane_id)
    if any(c.getTo().getFunction() == "" for c in lane.getOutgoing()):
        return False
    return any(c.getTo().getFunction() == "" for other in lane.getEdge().getLanes() if other is not lane
               for c in other.getOutgoing())


def _point(kind: ConflictKind, node, link: _Link, xy: tuple[float, float], foes: list[_Link],
           lane_ends: bool = False) -> ConflictPoint:
    return ConflictPoint(kind, node.getID(), link.from_lane, link.to_lane, link.path[0] if link.path else "",
                         round(xy[0], 2), round(xy[1], 2),
                         tuple(sorted({f.from_lane for f in foes})),
                         tuple(sorted({f.path[0] if f.path else f.to_lane for f in foes})), lane_ends)


def _junction_points(rmap: RoadMap, node, logic: _Logic) -> list[ConflictPoint]:
    """Every conflict point of one junction, in link order, each link's kinds in enum order."""
    links = _links(rmap, node)
    out: list[ConflictPoint] = []
    centre = tuple(float(c) for c in node.getCoord()[:2])
    for i in sorted(links):
        link = links[i]
        if link.crossing or not rmap.lane(link.from_lane).allows(PASSENGER) \
                or not rmap.lane(link.to_lane).allows(PASSENGER):
            continue
        signal = link.tl_index >= 0 and bool(logic.phases)

        def active(other: _Link, states: str = _GREEN) -> bool:
            if not signal or other.tl_index < 0:
                return True
            return _green_together(logic.phases, link.tl_index, other.tl_index, states)

        vehicles = [o for j, o in sorted(links.items()) if j != i and not o.crossing]
        # at a light, a link yields only in its minor-green ('g') phases
        yields_to = [o for o in vehicles if _bit(logic.response.get(i, ""), o.index) and active(o, "g")]
        walkers = [o for j, o in sorted(links.items()) if o.crossing
                   and (_bit(logic.foes.get(i, ""), j) or _bit(logic.response.get(i, ""), j)) and active(o)]
        merging = [o for o in vehicles if o.to_lane == link.to_lane and o.from_lane != link.from_lane and active(o)]
        ego = _polyline(rmap, link)

        def at(foes: list[_Link], fallback) -> tuple[float, float]:
            return _first_crossing(ego, [_polyline(rmap, f) for f in foes]) or fallback

        if yields_to and link.direction in _LEFT:
            out.append(_point(ConflictKind.UNPROTECTED_LEFT, node, link, at(yields_to, centre), yields_to))
        elif (yields_to or link.state in ("s", "w")) and link.direction not in _TURN:
            out.append(_point(ConflictKind.YIELD, node, link, at(yields_to, centre), yields_to))
        if merging:
            out.append(_point(ConflictKind.MERGE, node, link, ego[-1], merging))
        elif _lane_ends(rmap, link.to_lane):
            geom = rmap.geom(link.to_lane)
            beside = f"{geom.edge}_{geom.index + 1}"
            feeders = [o for o in vehicles if o.to_lane == beside]
            end = geom.pts[-1]
            out.append(_point(ConflictKind.MERGE, node, link, (float(end[0]), float(end[1])), feeders, True))
        if walkers:
            out.append(_point(ConflictKind.CROSSWALK, node, link, at(walkers, centre), walkers))
        if link.tl_index >= 0:
            stop = rmap.geom(link.from_lane).pts[-1]
            foes = [o for o in vehicles if _bit(logic.foes.get(i, ""), o.index)]
            out.append(_point(ConflictKind.SIGNALISED, node, link, (float(stop[0]), float(stop[1])), foes))
    return out


def conflict_points(rmap: RoadMap) -> list[ConflictPoint]:
    """Every conflict point a passenger car can drive through on ``rmap``, sorted by junction and link.

    Only links between normal edges that allow passenger cars count; dead ends and internal
    junctions are skipped. Deterministic: the same network gives the same list.
    """
    requests, phases = _read_logic(str(rmap.path))
    out: list[ConflictPoint] = []
    for node in sorted(rmap.net.getNodes(), key=lambda n: n.getID()):
        if node.getType() in ("internal", "dead_end") or node.getID() not in requests:
            continue
        response, foes = requests[node.getID()]
        tls = node.getTLSID()
        logic = _Logic(response, foes, phases.get(tls, ()) if tls else ())
        out.extend(_junction_points(rmap, node, logic))
    return out


# ------------------------------------------------------------------ missions
def _drivable(rmap: RoadMap, edge) -> bool:
    return edge.getFunction() == "" and any(l.allows(PASSENGER) for l in edge.getLanes())


def _upstream(rmap: RoadMap, rng: random.Random, edge_id: str, approach: float) -> tuple[list[str], float] | None:
    """Edges driven up to ``edge_id`` and the start position [m] on the first, about ``approach``
    metres before the end of ``edge_id``; None if the way back runs out. A start on an earlier
    edge keeps 15 m from that edge's end, so the ego does not start in front of a junction."""
    path = [edge_id]
    remaining = approach
    while remaining > rmap.edge(path[0]).getLength() - 5.0:
        head = rmap.edge(path[0])
        remaining = max(remaining - head.getLength(), 15.0)
        preds = sorted((e for e in head.getIncoming() if _drivable(rmap, e) and e.getID() not in path
                        and e.getFromNode().getID() != head.getToNode().getID()), key=lambda e: e.getID())
        if not preds or len(path) > 4:
            return None
        path.insert(0, rng.choice(preds).getID())
    return path, round(rmap.edge(path[0]).getLength() - remaining, 1)


def _downstream(rmap: RoadMap, rng: random.Random, edge_id: str, beyond: float) -> tuple[list[str], float] | None:
    """Edges driven from ``edge_id`` on and the goal position [m] on the last, ``beyond`` metres
    past the start of ``edge_id``; None if the road runs out."""
    path = [edge_id]
    remaining = beyond
    while remaining > rmap.edge(path[-1]).getLength() - 12.0:
        remaining -= rmap.edge(path[-1]).getLength()
        tail = rmap.edge(path[-1])
        succs = sorted((e for e in tail.getOutgoing() if _drivable(rmap, e) and e.getID() not in path
                        and e.getToNode().getID() != tail.getFromNode().getID()), key=lambda e: e.getID())
        if not succs or len(path) > 4:
            return None
        path.append(rng.choice(succs).getID())
        remaining = max(remaining, min(12.0, rmap.edge(path[-1]).getLength() / 2))
    return path, round(min(remaining, rmap.edge(path[-1]).getLength() - 1.0), 1)


def passes(route: tuple[str, ...], point: ConflictPoint) -> bool:
    """Whether ``route`` drives from the point's incoming edge straight into its outgoing edge."""
    return any(a == point.in_edge and b == point.out_edge for a, b in zip(route[:-1], route[1:]))


def mission_through(rmap: RoadMap, rng: random.Random, point: ConflictPoint, network: str) -> Scenario | None:
    """One candidate seed whose route drives through ``point``, or None if this draw gave none.

    The ego starts ``APPROACH_MIN_M``..``APPROACH_MAX_M`` before the stop line (on the point's
    own incoming lane when that edge is long enough, so the link taken is the point's), and its
    goal lies ``BEYOND_MIN_M``..``BEYOND_MAX_M`` past the junction (past the end of the lane for
    a merge onto a lane that ends). The route is the road map's shortest route, as the executor
    drives it; a draw whose shortest route misses the point, drives a road both ways, or falls
    outside the random missions' length range is refused.
    """
    back = _upstream(rmap, rng, point.in_edge, rng.uniform(APPROACH_MIN_M, APPROACH_MAX_M))
    out_len = rmap.edge(point.out_edge).getLength()
    beyond = rng.uniform(BEYOND_MIN_M, BEYOND_MAX_M) + (out_len if point.lane_ends else 0.0)
    ahead = _downstream(rmap, rng, point.out_edge, beyond)
    if back is None or ahead is None:
        return None
    (before, start_pos), (after, goal_pos) = back, ahead
    start, goal = before[0], after[-1]
    if rmap.edge(start).getLength() < MIN_EDGE_M or rmap.edge(goal).getLength() < MIN_EDGE_M or start == goal:
        return None
    if point.lane_ends and goal == point.out_edge:
        return None
    route = rmap.route(start, goal)
    if route is None or len(route) < 2 or not passes(route, point) or doubles_back(rmap, route):
        return None
    length = rmap.route_length(route, start_pos, goal_pos)
    if not MIN_ROUTE_M <= length <= MAX_ROUTE_M:
        return None
    if start == point.in_edge:
        start_lanes = [point.in_lane]
    else:
        start_lanes = [l.getID() for l in rmap.edge(start).getLanes()
                       if l.allows(PASSENGER) and any(c.getTo().getID() == route[1] for c in l.getOutgoing())]
    if not start_lanes:
        return None
    return Scenario(
        network=network,
        mission=Mission(start_lane=rng.choice(start_lanes), start_pos=start_pos, goal_edge=goal, goal_pos=goal_pos),
        ads=AdsSpec(name="ego"),
        seed=rng.randrange(2**31),
        sim=SimOptions(time_limit=time_limit_for(rmap, route, length)),
        name="seed",
    )


def conflict_missions(rmap: RoadMap, rng: random.Random, network_path: str,
                      max_draws: int = MAX_DRAWS_PER_KIND) -> Iterator[tuple[ConflictKind, Scenario]]:
    """Candidate seeds (unverified) through conflict points, as (kind, scenario), kinds in turn.

    Cycles over the kinds present on ``rmap`` in enum order, one mission per kind per round, so
    every kind is represented; within a kind the points are visited in a shuffled order before
    any repeats. A kind whose points gave no mission in ``max_draws`` draws in a row drops out;
    the iterator ends when every kind has (it is otherwise endless: take what you need). The
    scenarios are named "seed"; the caller names them (:func:`conflict_seed_name`). Deterministic
    for a given state of ``rng``.
    """
    by_kind: dict[ConflictKind, list[ConflictPoint]] = {}
    for p in conflict_points(rmap):
        by_kind.setdefault(p.kind, []).append(p)
    queues: dict[ConflictKind, list[ConflictPoint]] = {}
    kinds = [k for k in ConflictKind if k in by_kind]
    while kinds:
        for kind in list(kinds):
            for _ in range(max_draws):
                if not queues.get(kind):
                    queues[kind] = list(by_kind[kind])
                    rng.shuffle(queues[kind])
                mission = mission_through(rmap, rng, queues[kind].pop(), network_path)
                if mission is not None:
                    yield kind, mission
                    break
            else:
                kinds.remove(kind)
