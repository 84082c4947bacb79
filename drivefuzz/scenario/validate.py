"""Check a Scenario against its road network, and the network itself, before anything runs.

Every problem raises :class:`InvalidScenario` (or :class:`InvalidNetwork`) naming
the file, the field and what would be valid. :func:`validate` returns the ego's
route, which the writer needs anyway.

:func:`check_network` reads the raw XML for what SUMO needs but sumolib does not
check (SUMO segfaults on some of it, and refuses the rest with a message that
names only a temporary folder): the root element, lane indices, finite numbers,
the junctions an edge joins, the traffic lights a connection names.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path

from shapely.geometry import LineString, Polygon

from drivefuzz.errors import InvalidNetwork, InvalidScenario
from drivefuzz.scenario.roadmap import PASSENGER, PEDESTRIAN, RoadMap, load_roadmap, open_network
from drivefuzz.scenario.signals import shiftable
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
        if not pool and vclass == PASSENGER:
            require_car_roads(rmap)  # the network is the mistake, not the lane: say so
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
    check_network(rmap.path)
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
    x0, y0, x1, y1 = _bounds(rmap)
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
        if a.dest_xy is not None and not (x0 <= a.dest_xy[0] <= x1 and y0 <= a.dest_xy[1] <= y1):
            raise InvalidScenario(source, f"actors[{i}]({a.id}).dest_xy", f"{a.dest_xy} is off the network",
                                  f"x in [{x0:.0f}, {x1:.0f}], y in [{y0:.0f}, {y1:.0f}] m")
    for i, sig in enumerate(scenario.signals):
        if shiftable(str(rmap.path), sig.tls) is None:
            raise InvalidScenario(source, f"signals[{i}].tls", f"{sig.tls!r} is not a fixed-time traffic light of "
                                  f"{rmap.path.name}", "the id of a <tlLogic type=\"static\"> of the network")
    for i, p in enumerate(scenario.puddles):
        for name in ("x", "y", "length", "width", "rotation", "friction"):
            if not math.isfinite(getattr(p, name)):
                raise InvalidScenario(source, f"puddles[{i}].{name}", "not a finite number")
        if not (x0 <= p.x <= x1 and y0 <= p.y <= y1):
            raise InvalidScenario(source, f"puddles[{i}]", f"centre ({p.x}, {p.y}) is off the network",
                                  f"x in [{x0:.0f}, {x1:.0f}], y in [{y0:.0f}, {y1:.0f}] m")
    return route


def check_departure(scenario: Scenario, rmap: RoadMap, source: str) -> None:
    """SUMO refuses (FatalTraCIError) an ego that departs faster than its start lane's speed limit.

    Not part of :func:`validate` yet: the round-trip property test writes such
    scenarios (they are well-formed, only not runnable). Called where a scenario
    is about to run from a user's file.
    """
    m = scenario.mission
    limit = rmap.lane(m.start_lane).getSpeed()
    if m.start_speed > limit:
        raise InvalidScenario(source, "mission.start_speed", f"{m.start_speed} m/s is faster than the speed limit "
                              f"of the start lane {m.start_lane!r}", f"0 to {limit:.2f} m/s")


#: [m] around the network's bounding box where puddles and walking targets may still lie
BOUNDS_MARGIN = 100.0


def _bounds(rmap: RoadMap) -> tuple[float, float, float, float]:
    (x0, y0), (x1, y1) = rmap.net.getBBoxXY()
    return x0 - BOUNDS_MARGIN, y0 - BOUNDS_MARGIN, x1 + BOUNDS_MARGIN, y1 + BOUNDS_MARGIN


def require_car_roads(rmap: RoadMap) -> None:
    """Raise InvalidNetwork when no lane of a normal edge allows a passenger car (a railway, a waterway, a
    racing circuit for race cars): the ego has nowhere to drive. SUMO loads such networks; drivefuzz cannot
    fuzz a car on them, and says so before it tries a single mission."""
    if rmap.lanes(PASSENGER):
        return
    classes: dict[str, int] = {}
    for e in rmap.net.getEdges(withInternal=False):
        for lane in e.getLanes():
            for vc in sorted(lane._allowed) if getattr(lane, "_allowed", None) else ():
                classes[vc] = classes.get(vc, 0) + 1
    seen = sorted(classes, key=lambda c: (-classes[c], c))
    raise InvalidNetwork(str(rmap.path), None, "no road a passenger car may use: no lane of its "
                         f"{len(rmap.net.getEdges(withInternal=False))} edges allows the class 'passenger'"
                         + (f" (its lanes allow {_examples(seen, 5)})" if seen else ""),
                         "a network with lanes that allow passenger cars (netconvert: allow=\"passenger\" or no "
                         "allow/disallow at all)")


def load_network(path: str | os.PathLike) -> RoadMap:
    """The network at ``path`` as a RoadMap, after :func:`check_network`."""
    rmap = load_roadmap(path)
    check_network(rmap.path)
    return rmap


_checked: dict[tuple[str, int, int], str | None] = {}


def check_network(path: str | os.PathLike) -> None:
    """Raise InvalidNetwork for what SUMO would crash on or refuse; once per file version per process,
    and not again in a later process for a file found sound before (:mod:`drivefuzz.netcache`)."""
    p = Path(path).resolve()
    st = p.stat()
    key = (str(p), st.st_mtime_ns, st.st_size)
    if key not in _checked:
        try:
            if not _checked_before(p):
                _check_network_xml(p)
                _remember_checked(p)
            _checked[key] = None
        except InvalidNetwork as exc:
            _checked[key] = str(exc)
            raise
    if _checked[key] is not None:
        raise InvalidNetwork(str(path), None, _checked[key].split(": ", 1)[-1])


def _check_key(p: Path) -> str:
    from drivefuzz import netcache

    return netcache.entry_key(p, __file__, "network-check")


def _checked_before(p: Path) -> bool:
    """Whether an earlier process found this very file sound with this very module (disk cache)."""
    from drivefuzz import netcache

    got = netcache.load(_check_key(p))
    return got is not None and got.get("sound") is not None and got["sound"].shape == () and bool(got["sound"])


def _remember_checked(p: Path) -> None:
    """Only a sound network is remembered: a faulty one is checked again, for its exact error."""
    import numpy as np

    from drivefuzz import netcache

    netcache.store(_check_key(p), {"sound": np.array(True)})


_SIGNALS = set("rRyYgGsuoO")


def _finite(text: str | None) -> bool:
    try:
        return text is not None and math.isfinite(float(text))
    except ValueError:
        return False


def _shape_ok(text: str | None) -> bool:
    if text is None:
        return True
    try:
        pts = [tuple(float(c) for c in pt.split(",")) for pt in text.split()]
    except ValueError:
        return False
    return all(len(pt) in (2, 3) and all(math.isfinite(c) for c in pt) for pt in pts)


def _check_network_xml(path: Path) -> None:
    scan = _NetScan(str(path))
    try:
        with open_network(path) as source:
            for event, el in ET.iterparse(source, events=("start", "end")):
                if event == "start":
                    scan.start(el)
                else:
                    scan.end(el)
    except (ET.ParseError, EOFError, OSError) as exc:  # EOFError, OSError: a damaged gzip stream
        raise scan.bad(None, f"malformed XML ({exc})", "a .net.xml written by netconvert") from None
    except RecursionError:
        raise scan.bad(None, "nested too deeply", "a .net.xml written by netconvert") from None
    scan.check_references()


class _NetScan:
    """What :func:`_check_network_xml` learns in one pass over the XML, and the checks of each element."""

    def __init__(self, src: str):
        self.src = src
        self.root_seen = False
        self.junctions: set[str] = set()
        self.edges: dict[str, tuple[str | None, str | None]] = {}  # id -> (from, to) of normal edges
        self.current = ["", 0, False]  # the edge being read, how many lanes it has had, whether it is normal
        self.tls: dict[str, int] = {}  # tlLogic id -> signals in its shortest phase
        self.rail: set[str] = set()  # rail signals and crossings
        self.links: list[tuple[str, int, str]] = []  # (tl, linkIndex, connection)

    def bad(self, field: str | None, problem: str, valid: str | None = None) -> InvalidNetwork:
        return InvalidNetwork(self.src, field, problem, valid)

    def start(self, el: ET.Element) -> None:
        if not self.root_seen:
            self.root_seen = True
            if el.tag != "net":
                raise self.bad(f"<{el.tag}>", "the root element is not <net>", "a .net.xml written by netconvert")
        if el.tag == "edge":
            self.current[:] = [el.get("id", ""), 0, el.get("function") in (None, "normal")]

    def end(self, el: ET.Element) -> None:
        tag = el.tag
        if tag == "lane":
            _check_lane_el(el, self.current, self.bad)
        elif tag == "edge":
            if el.get("function") not in ("internal", "walkingarea", "crossing"):
                self.edges[el.get("id", "")] = (el.get("from"), el.get("to"))
        elif tag == "junction":
            self._junction(el)
        elif tag == "tlLogic":
            self._tl_logic(el)
        elif tag == "connection" and el.get("tl") is not None:
            name = f"connection[{el.get('from')}->{el.get('to')}]"
            try:
                self.links.append((el.get("tl"), int(el.get("linkIndex", "")), name))
            except ValueError:
                raise self.bad(f"{name}.linkIndex", f"{el.get('linkIndex')!r} is not an integer") from None
        elif tag == "location":
            for name in ("netOffset", "convBoundary"):
                if el.get(name) is not None and not all(_finite(v) for v in el.get(name).split(",")):
                    raise self.bad(f"location.{name}", f"{el.get(name)!r} is not a list of finite numbers")
        if tag in ("edge", "junction", "tlLogic", "connection"):
            el.clear()

    def _junction(self, el: ET.Element) -> None:
        jid = el.get("id", "")
        self.junctions.add(jid)
        if el.get("type") in RAIL_SIGNALS:  # SUMO builds their signals itself: no <tlLogic>
            self.rail.add(jid)
        for name in ("x", "y"):
            if not _finite(el.get(name)):
                raise self.bad(f"junction[{jid}].{name}", f"{el.get(name)!r} is not a finite number")
        if not _shape_ok(el.get("shape")):
            raise self.bad(f"junction[{jid}].shape", "not a list of finite x,y points")

    def _tl_logic(self, el: ET.Element) -> None:
        tid = el.get("id", "")
        states = [ph.get("state", "") for ph in el.findall("phase")]
        if not states:
            raise self.bad(f"tlLogic[{tid}]", "has no phases", "<phase duration=... state=.../>")
        for ph in el.findall("phase"):
            d = ph.get("duration")
            if not _finite(d) or float(d) <= 0:
                raise self.bad(f"tlLogic[{tid}].phase.duration", f"{d!r} is not a positive number of seconds")
            if not set(ph.get("state", "")) <= _SIGNALS or len(ph.get("state", "")) != len(states[0]):
                raise self.bad(f"tlLogic[{tid}].phase.state", f"{ph.get('state')!r} is not a signal state "
                               "as long as the others", "characters of rRyYgGsuoO")
        self.tls[tid] = len(states[0])

    def check_references(self) -> None:
        for eid, (a, b) in self.edges.items():
            for end, node in (("from", a), ("to", b)):
                if node is not None and node not in self.junctions:
                    raise self.bad(f"edge[{eid}].{end}", f"unknown junction {node!r}", "the id of a <junction>")
        for tl, index, name in self.links:
            if index == -1 or (tl in self.rail and tl not in self.tls):  # not controlled (OSM), or a rail signal
                continue
            if tl not in self.tls:
                raise self.bad(f"{name}.tl", f"unknown traffic light {tl!r}", "the id of a <tlLogic>")
            if not 0 <= index < self.tls[tl]:
                raise self.bad(f"{name}.linkIndex", f"{index} is not a signal of traffic light {tl!r}",
                               f"0 to {self.tls[tl] - 1}")


#: [m] the longest lane drivefuzz models (SUMO takes any finite length; the longest edges of real motorway
#: networks are some tens of kilometres; a lane of 1e20 m made the reference ADS's lane arrays overflow)
MAX_LANE_LENGTH = 100_000.0
#: [m/s] the highest lane speed limit drivefuzz models (3,600 km/h: no real road comes near it)
MAX_LANE_SPEED = 1_000.0

#: junction types whose signals SUMO builds without a <tlLogic> (connections still name them in ``tl``)
RAIL_SIGNALS = ("rail_signal", "rail_crossing")


def _check_lane_el(el: ET.Element, current: list, bad) -> None:
    lid = el.get("id", "")
    expected = current[1]
    # SUMO segfaults while vehicles drive on a normal edge whose lanes are misnumbered (measured on 1.28), but
    # loads and runs internal edges numbered anyhow (OSM cities number every junction lane 0): only normal
    # edges are checked
    if current[2] and el.get("index") != str(expected):
        raise bad(f"lane[{lid}].index", f"{el.get('index')!r} out of order on edge {current[0]!r}",
                  f"{expected} (an edge's lanes are numbered from 0)")
    current[1] = expected + 1
    for name, most in (("speed", MAX_LANE_SPEED), ("length", MAX_LANE_LENGTH)):
        v = el.get(name)
        if not _finite(v) or float(v) < 0 or (name == "speed" and float(v) == 0):
            raise bad(f"lane[{lid}].{name}", f"{v!r} is not a {'positive' if name == 'speed' else 'non-negative'} "
                      "finite number")
        if float(v) > most:
            raise bad(f"lane[{lid}].{name}", f"{v} {'m/s' if name == 'speed' else 'm'} is beyond what drivefuzz "
                      "can model (the ADS's and the oracles' lane arrays and stopping arithmetic)",
                      f"{'0' if name == 'length' else 'above 0'} to {most:g} {'m/s' if name == 'speed' else 'm'}")
    if el.get("width") is not None and (not _finite(el.get("width")) or float(el.get("width")) <= 0):
        raise bad(f"lane[{lid}].width", f"{el.get('width')!r} is not a positive finite number")
    if not _shape_ok(el.get("shape")):
        raise bad(f"lane[{lid}].shape", "not a list of finite x,y points")


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
