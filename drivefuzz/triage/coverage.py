"""Interaction coverage: which kinds of close encounter a campaign has created, and which it could create.

Every execution's trace is read for its *close encounters*: per actor and episode of closeness
(:mod:`drivefuzz.search.episodes`), an in-path time-to-collision under :data:`TTC_S`, a post-encroachment
time under :data:`PET_S` or a body gap under :data:`GAP_M` (from the rows that
:func:`drivefuzz.search.risk.risk_score` computes anyway), and tyre grip use over :data:`GRIP` (an encounter
with no other party). Each encounter is classified at its frame
(:func:`classify`) along six axes:

- ``party``: ``vehicle/<approach>`` with approach ``ahead behind left right rear_left rear_right oncoming
  crossing_left crossing_right``; ``pedestrian/<approach>`` with ``crossing_left crossing_right along``;
  ``none/grip`` for grip use near the limit;
- ``manoeuvre`` of the ego: ``cruise accelerate brake stop_go turn_left turn_right lane_change``, and
  ``merge`` on a ramp, ``roundabout`` on a ring (where the element says so);
- ``element`` and its control: ``edge``, ``signal/<phase at arrival: green amber red>``, ``priority``,
  ``yield`` (yield or stop sign), ``roundabout``, ``ramp``;
- ``speed`` band of the ego (:data:`SPEED_BANDS`) and the ``conditions`` (``fog wet wind low_sun
  low_friction``, or ``clear``).

The full cross product (10^4 cells, most of them impossible) is neither reachable nor readable, so an
encounter counts in three *projections* (:data:`PROJECTIONS`): party x manoeuvre, party x element, speed x
condition. A cell's key is ``"<projection>:<row>|<column>"``.

:func:`reachable` derives the cells a network and its seeds' routes can offer at all (a mission's route is never
mutated; an aim may start the ego on another lane of its start edge, or at speed): no roundabout cells off a ring,
no pedestrian cells without sidewalks or crossings on the route, no lane-change or side cells without a multi-lane
edge, turns only where a route turns, speed bands up to the route's limits. It is an over-approximation
(docs/coverage.md says where).

Pure functions of Trace + Scenario + RoadMap (+ RiskScore); used by the fuzz job (each execution's
cells go into its journal record), the schedule (novelty), ``drivefuzz coverage``, the status screen and
the report. Units SI; headings radians ENU as in the trace.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np
from shapely import STRtree
from shapely.geometry import LineString, Point
from shapely.ops import nearest_points

from drivefuzz.search.episodes import GAP_M, PET_S, TTC_S  # the thresholds of a close encounter
from drivefuzz.sim.world import sun_glare
from drivefuzz.storage import read_new_lines
from drivefuzz.triage.evidence import (actor_track, along_path, frames_before, lane_changed, lateral_shift, to_local,
                                       wrap_angle)
from drivefuzz.triage.signature import element as signature_element

GRIP = 0.85  #: [-] tyre friction use at or over this is an encounter with no other party
#: [m] from its light's stop line within which the ego's first standstill is its arrival at the light (:func:`_phase`)
ARRIVAL_M = 30.0
STANDSTILL = 0.5  #: [m/s] under this the ego is at rest
WINDOW_S = 3.0  #: [s] before the encounter over which the ego's manoeuvre is read
APPROACH_S = 2.0  #: [s] before the encounter at which the other party's approach is read
TURN = math.radians(30.0)  #: [rad] heading change that makes a turn
SAME_LANE_M = 1.8  #: [m] lateral offset within which a same-direction vehicle is ahead / behind
LANE_SHIFT_M = 1.0  #: [m] sideways on one edge over the window that makes a lane change (one under way counts)
#: (upper bound [m/s], name) of the ego's speed bands
SPEED_BANDS: tuple[tuple[float, str], ...] = ((2.8, "0-10 km/h"), (8.3, "10-30 km/h"), (16.7, "30-60 km/h"),
                                               (math.inf, "60+ km/h"))
CONDITIONS = ("clear", "fog", "wet", "wind", "low_sun", "low_friction")
FOG, WET, WIND = 30.0, 30.0, 40.0  #: weather levels (0-100) from which a condition counts
LOW_MU = 0.6  #: [-] friction under an axle below this is a low-friction patch
#: an encounter within this factor of a threshold (TTC under 4.5 s, PET under 3 s, gap under 2.25 m) but not
#: under it is *near* its cells: no cell counts it; the journal keeps them (``near``) and ``drivefuzz coverage``
#: says how often each cell never reached was come near
NEAR = 1.5

VEHICLE_APPROACHES = ("ahead", "behind", "left", "right", "rear_left", "rear_right", "oncoming",
                      "crossing_left", "crossing_right")
PEDESTRIAN_APPROACHES = ("crossing_left", "crossing_right", "along")
PARTIES = tuple(f"vehicle/{a}" for a in VEHICLE_APPROACHES) + tuple(
    f"pedestrian/{a}" for a in PEDESTRIAN_APPROACHES) + ("none/grip",)
MANOEUVRES = ("cruise", "accelerate", "brake", "stop_go", "turn_left", "turn_right", "lane_change", "merge",
              "roundabout")
ELEMENTS = ("edge", "signal/green", "signal/amber", "signal/red", "priority", "yield", "roundabout", "ramp")
#: projection name -> (row axis, column axis)
PROJECTIONS: dict[str, tuple[str, str]] = {
    "party-manoeuvre": ("party", "manoeuvre"),
    "party-element": ("party", "element"),
    "speed-condition": ("speed", "condition"),
}
AXIS_VALUES: dict[str, tuple[str, ...]] = {"party": PARTIES, "manoeuvre": MANOEUVRES, "element": ELEMENTS,
                                           "speed": tuple(n for _, n in SPEED_BANDS), "condition": CONDITIONS}


@dataclass(frozen=True)
class Encounter:
    """One close encounter, classified."""

    actor: str | None  # None: grip use, no other party
    frame: int
    party: str
    manoeuvre: str
    element: str
    speed: str
    conditions: tuple[str, ...]

    def cells(self) -> list[str]:
        """Its cell keys, one per projection (speed x condition: one per condition)."""
        out = [f"party-manoeuvre:{self.party}|{self.manoeuvre}", f"party-element:{self.party}|{self.element}"]
        out += [f"speed-condition:{self.speed}|{c}" for c in self.conditions]
        return out


# ------------------------------------------------------------------------------------------- encounters
def close_encounters(risk, near: bool = False) -> list[tuple[str | None, int]]:
    """``(actor, frame)`` of every close encounter in a :class:`~drivefuzz.search.risk.RiskScore`: each episode
    of an actor's closeness at its most severe moment (:mod:`drivefuzz.search.episodes`; an actor close twice,
    3 s or more apart, met the ego twice), then grip. With ``near``: of every near one instead (an actor never
    close whose most severe value is within :data:`NEAR` of its threshold; grip use from :data:`GRIP` /
    :data:`NEAR` up to :data:`GRIP`)."""
    if near:
        best: dict[str, tuple[float, int]] = {}
        limits = {"ttc": TTC_S, "pet": PET_S, "gap": GAP_M}
        for actor, comp, value, frame in getattr(risk, "encounters", ()):
            sev = value / limits[comp]
            if sev < NEAR and (actor not in best or sev < best[actor][0]):
                best[actor] = (sev, frame)
        out: list[tuple[str | None, int]] = [(a, f) for a, (sev, f) in sorted(best.items()) if sev >= 1.0]
    else:
        out = [(actor, frame) for actor, _, _, frame in getattr(risk, "episodes", ())]
    grip = risk.grip if risk.grip is not None else 0.0
    if risk.grip_frame is not None and ((GRIP / NEAR <= grip < GRIP) if near else grip >= GRIP):
        out.append((None, int(risk.grip_frame)))
    return out


def execution_cells(scenario, trace, rmap, risk, near: bool = False) -> list[str]:
    """The sorted, distinct cells of one execution's close encounters (what its journal record keeps); with
    ``near``, of its near encounters (:data:`NEAR`)."""
    if trace is None or trace.n_frames == 0:
        return []
    cells: set[str] = set()
    for actor, f in close_encounters(risk, near):
        try:
            cells.update(classify(scenario, trace, rmap, actor, f).cells())
        except (KeyError, ValueError, IndexError):  # a lane or link the map does not have: not classified, and
            continue  # the execution's record is still written (coverage must never cost a campaign its journal)
    return sorted(cells)


def classify(scenario, trace, rmap, actor: str | None, f: int) -> Encounter:
    """Classify the encounter with ``actor`` (None: grip) at frame ``f`` (see the module docstring)."""
    f = min(max(int(f), 0), trace.n_frames - 1)
    elem = element(scenario, trace, rmap, f)
    return Encounter(actor, f, party(trace, actor, f, rmap), manoeuvre(trace, f, elem, rmap), elem,
                     speed_band(float(trace["speed"][f])), conditions(scenario, trace, f))


def party(trace, actor: str | None, f: int, rmap=None) -> str:
    """``<kind>/<approach>`` of the other party, read :data:`APPROACH_S` s before ``f`` (or when it appeared). A
    vehicle's heading is read against the ego's heading then, or (given ``rmap``) where the ego is on a roundabout's
    ring or in its junctions then, against the ego's way where that vehicle is (the ring bends under the ego: a car
    coming onto the ring ahead heads 30 degrees off the ego's heading, or against it, and 60-90 degrees off the ego's
    way there; until the twenty-first session it was read beside the ego, or oncoming)."""
    if actor is None:
        return "none/grip"
    track = actor_track(trace, actor)
    if track is None:
        return "none/grip"
    k0 = max(f - int(round(APPROACH_S / trace.step_length)), 0)
    k = next((j for j in range(k0, f + 1) if track.present(j)), f)
    lx, ly = to_local(trace, k, float(track.x[k]), float(track.y[k]))
    side = "left" if ly > 0 else "right"
    if track.kind == "pedestrian":  # by its walk up to f (a walker's first frames may stand still)
        j = next((i for i in range(f, k, -1) if track.present(i)), k)
        dx, dy = float(track.x[j] - track.x[k]), float(track.y[j] - track.y[k])
        if not math.isfinite(dx + dy) or math.hypot(dx, dy) < 0.5:
            return "pedestrian/along"
        dh = abs(wrap_angle(math.atan2(dy, dx) - float(trace["heading"][k])))
        return f"pedestrian/crossing_{side}" if math.pi / 4 < dh < 3 * math.pi / 4 else "pedestrian/along"
    with np.errstate(invalid="ignore"):  # NaN where it was not there: not moving
        moving = bool(np.any(np.asarray(track.speed[k:f + 1], dtype=float) > 0.5))
    lx, ly, way = along_path(trace, k, float(track.x[k]), float(track.y[k]), heading=True)
    ring = rmap is not None and _on_ring(str(trace["lane"][k]), _features(rmap))
    dh = abs(wrap_angle(float(track.heading[k]) - (way if ring else float(trace["heading"][k]))))
    # on the ego's path and going its way there (a car behind it, or ahead of it, as it turns): neither oncoming nor
    # crossing, however the ego itself heads now (by that alone a car following it through a turn crossed it)
    if moving and not (abs(ly) < SAME_LANE_M and abs(wrap_angle(float(track.heading[k]) - way)) <= math.pi / 4):
        if dh >= 3 * math.pi / 4:
            return "vehicle/oncoming"
        if dh > math.pi / 4:
            return f"vehicle/crossing_{('left' if ly > 0 else 'right') if ring else side}"
    side = "left" if ly > 0 else "right"
    if abs(ly) < SAME_LANE_M:
        return "vehicle/ahead" if lx > 0 else "vehicle/behind"
    half = 0.5 * float(trace.meta.get("ego_length") or 4.6)
    return f"vehicle/rear_{side}" if lx < -half else f"vehicle/{side}"


def manoeuvre(trace, f: int, elem: str, rmap=None) -> str:
    """The ego's manoeuvre over the :data:`WINDOW_S` s up to ``f``; ``merge`` / ``roundabout`` on those elements.
    A lane change: the ego's lane changed on one edge, or (given ``rmap``) it moved :data:`LANE_SHIFT_M` sideways
    on one (a lane change under way, or given up: a car met as the ego pulls out meets it in a lane change)."""
    speed = trace["speed"]
    w = frames_before(trace, f, WINDOW_S)
    base = "cruise"
    if float(np.min(speed[w])) < 0.5:
        base = "stop_go"
    else:
        heading = np.unwrap(np.asarray(trace["heading"][w], dtype=float))
        turn = float(heading[-1] - heading[0]) if len(heading) > 1 else 0.0
        if abs(turn) >= TURN:
            base = "turn_left" if turn > 0 else "turn_right"
        elif lane_changed(trace, f, WINDOW_S) or (rmap is not None and _has_lanes_beside(trace, rmap, f)
                                                   and lateral_shift(trace, rmap, f, WINDOW_S) >= LANE_SHIFT_M):
            base = "lane_change"
        else:
            ax = trace["ax"][frames_before(trace, f, 1.0)]
            mean = float(np.nanmean(ax)) if len(ax) else 0.0
            base = "brake" if mean < -1.0 else "accelerate" if mean > 0.7 else "cruise"
    if elem == "ramp" and base in ("cruise", "accelerate", "lane_change", "turn_left", "turn_right"):
        return "merge"
    if elem == "roundabout" and base in ("cruise", "accelerate", "turn_left", "turn_right"):
        return "roundabout"
    return base


def _has_lanes_beside(trace, rmap, f: int) -> bool:
    """Whether the ego's edge at the start of the window up to ``f`` has another lane for cars: a metre sideways
    within the only lane (a swerve, a wide line on a ring) is no lane change (until the twenty-first session it
    counted as one, and the roundabout's campaigns met cars in 'lane changes' that its one-lane roads cannot
    offer)."""
    lane = str(trace["lane"][frames_before(trace, f, WINDOW_S).start])
    return bool(lane) and not lane.startswith(":") and rmap.has_lane(lane) and _multilane(rmap.lane(lane).getEdge())


def element(scenario, trace, rmap, f: int) -> str:
    """The road element of the ego at ``f``: roundabout or ramp where the network says so, else the
    junction control of the signature's element (the link crossed or approached), else ``edge``."""
    feats = _features(rmap)
    lane = str(trace["lane"][f])
    if _on_ring(lane, feats):
        return "roundabout"
    if not lane.startswith(":") and lane.rsplit("_", 1)[0] in feats["ramp_edges"]:
        return "ramp"
    cls = signature_element(scenario, trace, rmap, f).split("/", 1)[1]
    if cls == "traffic_light":
        return f"signal/{_phase(trace, f)}"
    return {"priority": "priority", "yield": "yield", "stop": "yield"}.get(cls, "edge")


def _on_ring(lane_id: str, feats: Mapping[str, frozenset[str]]) -> bool:
    """Whether ``lane_id`` lies on a roundabout's ring or inside one of its junctions (an internal lane is
    ``:<node>_<i>_<j>``): every frame of the ego there is the roundabout (:func:`element`, :func:`link_turn`)."""
    edge = lane_id.rsplit("_", 1)[0]
    if lane_id.startswith(":"):
        return edge.lstrip(":").rsplit("_", 1)[0] in feats["ring_nodes"]
    return edge in feats["ring_edges"]


def _phase(trace, f: int) -> str:
    """The ego's light at arrival, as signal engineering counts arrivals on green and on red: its state when the
    ego came to rest at the light (its first standstill within :data:`ARRIVAL_M` of the stop line on this
    approach: at the line, or at the back of a short queue), or else at the last frame before it entered the
    junction (or at ``f``, still on the approach). An ego that stops as the light turns yellow and is hit from
    behind while it waits at red arrived on amber; one that waited at red and meets a late crossing car as it
    sets off on green arrived on red (until the thirteenth session the state as it entered: both read green)."""
    lanes, states, dist, speed = trace["lane"], trace["tls_state"], trace["tls_dist"], trace["speed"]
    k = f
    while k > 0 and str(lanes[k]).startswith(":"):
        k -= 1
    j, rest = k, None
    # back over this approach to the same light (its distance grows backwards, or stays while at rest)
    while j >= 0 and math.isfinite(float(dist[j])) and float(dist[j]) <= ARRIVAL_M \
            and (j == k or float(dist[j]) >= float(dist[j + 1]) - 0.01):
        if float(speed[j]) < STANDSTILL:
            rest = j
        j -= 1
    s = str(states[k if rest is None else rest])[:1]
    if s and s in "yY":
        return "amber"
    return "red" if s and s in "rRu" else "green"


def speed_band(v: float) -> str:
    """The band of speed ``v`` [m/s] (the lowest for a speed the trace does not have)."""
    return next((name for top, name in SPEED_BANDS if v < top), SPEED_BANDS[0][1]) if math.isfinite(v) \
        else SPEED_BANDS[0][1]


def conditions(scenario, trace, f: int) -> tuple[str, ...]:
    """The conditions at ``f`` (``clear`` when none)."""
    w = scenario.weather
    out = []
    if w.fog >= FOG:
        out.append("fog")
    if max(w.rain, w.wetness) >= WET:
        out.append("wet")
    if w.wind >= WIND:
        out.append("wind")
    if sun_glare(w, float(trace["heading"][f])):
        out.append("low_sun")
    if scenario.puddles:
        win = frames_before(trace, f, 2.0)
        mu = np.fmin(np.asarray(trace["mu_front"][win], dtype=float), np.asarray(trace["mu_rear"][win], dtype=float))
        if np.any(mu < LOW_MU):
            out.append("low_friction")
    return tuple(out) or ("clear",)


# ------------------------------------------------------------------------------------------- the network
@lru_cache(maxsize=16)
def _features(rmap) -> dict[str, frozenset[str]]:
    """Ring edges and nodes (SUMO's roundabouts) and ramp edges (edge type containing ``ramp``)."""
    ring_edges, ring_nodes = set(), set()
    for rb in rmap.net.getRoundabouts():
        ring_edges.update(rb.getEdges())
        ring_nodes.update(rb.getNodes())
    ramps = {e.getID() for e in rmap.net.getEdges(withInternal=False) if "ramp" in (e.getType() or "").lower()}
    return {"ring_edges": frozenset(ring_edges), "ring_nodes": frozenset(ring_nodes), "ramp_edges": frozenset(ramps)}


def reachable(rmap, scenarios: Iterable) -> list[str]:
    """The cells that the network of ``rmap`` and these seeds' routes can offer (sorted keys); the keys of
    :func:`reachable_places`."""
    return sorted(reachable_places(rmap, scenarios))


def reachable_places(rmap, scenarios: Iterable) -> dict[str, frozenset[str]]:
    """Every cell that the network of ``rmap`` and these seeds' routes can offer, with the junctions (node ids)
    where the routes offer it: a party at a junction's control or in a turn there; the other cells (on an edge,
    a ring or a ramp, the manoeuvres that happen anywhere, speed x condition) have no junction of their own
    (an empty set). The aiming shares a cell that several seeds offer at different junctions among them
    (:func:`drivefuzz.campaign.aiming.share_cells`).

    Per *place* of a route (an edge, and the junction at its end with the link the route takes): its element,
    its turn, and the parties that can meet the ego there (sides only on a multi-lane edge, oncoming only with
    a road the other way, crossing vehicles only from a side whose paths meet the ego's (:func:`crossing_sides`),
    walkers only with a pavement or a crossing there). A party x element or party x turn cell is offered only where one place has
    both; the manoeuvres that happen anywhere (cruise, accelerate, brake, stop and go) take every party of the
    route (cruise and accelerate not those met only on a ring or a ramp, where they are the roundabout and the
    merge); a lane change, the parties of its multi-lane edges and their junctions."""
    places = _route_places(rmap, scenarios)
    if not places:
        return {}
    cells: dict[str, set[str]] = {}

    def offer(key: str, node: str | None = None) -> None:
        at = cells.setdefault(key, set())
        if node:
            at.add(node)

    anywhere = set().union(*(p["parties"] | p["along"] for p in places))
    # on a ring (its junctions too) or a ramp a cruise or an acceleration is the roundabout or the merge
    off = set().union(*(p["parties"] | p["along"] for p in places if p["element"] not in ("roundabout", "ramp")))
    for p in anywhere:
        for m in ("cruise", "accelerate", "brake", "stop_go"):
            if p in off or m in ("brake", "stop_go"):
                offer(f"party-manoeuvre:{p}|{m}")
    for pl in places:
        parties = pl["parties"]
        # a car across the ego's way meets it on the road after the junction too: a post-encroachment is dated at
        # the later arrival, and a car coming the other way on the road turned into is read across it mid-turn
        for p in parties | pl["along"]:  # and a car on a road beside this one, anywhere along it
            if pl["element"] == "roundabout":  # every frame on a ring is the roundabout
                continue
            if not p.startswith("vehicle/crossing") or pl["element"] is None or pl["after"] == "edge":
                offer(f"party-element:{p}|edge")
            elif pl["after"] == "ramp":
                offer(f"party-element:{p}|ramp")
                offer(f"party-manoeuvre:{p}|merge")
        if pl["element"]:  # a ring or a ramp is its own place, a control is its junction's
            node = pl["node"] if pl["element"] not in ("ramp", "roundabout") else None
            for p in parties:
                for e in _phases(pl["element"]):
                    offer(f"party-element:{p}|{e}", node)
        if pl["turn"]:
            for p in parties:
                offer(f"party-manoeuvre:{p}|{pl['turn']}", pl["node"])
        if pl["multilane"]:  # a lane change on the approach, then whoever meets the ego at its junction
            for p in parties:
                offer(f"party-manoeuvre:{p}|lane_change")
        if pl["element"] == "ramp":
            for p in parties:
                offer(f"party-manoeuvre:{p}|merge")
        if pl["element"] == "roundabout":  # traffic entering the ring meets the ego across its path
            for p in parties:
                offer(f"party-manoeuvre:{p}|roundabout")
    vmax = max(pl["vmax"] for pl in places)
    bands = [name for top, name in SPEED_BANDS]
    bands = bands[:next(i for i, (top, _) in enumerate(SPEED_BANDS) if vmax * 1.1 < top) + 1]
    for b in bands:
        for c in CONDITIONS:
            offer(f"speed-condition:{b}|{c}")
    return {key: frozenset(at) for key, at in sorted(cells.items())}


def _phases(element: str) -> tuple[str, ...]:
    """A signalised link offers all three phases at arrival (signal shifts are a mutation)."""
    return ("signal/green", "signal/amber", "signal/red") if element == "signal" else (element,)


def _route_places(rmap, scenarios: Iterable) -> list[dict[str, Any]]:
    """Per route edge of every seed: its element at the end (``signal``, ``priority``, ``yield``; ``ramp`` or
    ``roundabout`` for such an edge; None for a plain edge's end), its turn there, the junction there (``node``),
    whether it is multi-lane, its limit, the parties that can meet the ego there, those met anywhere along the edge
    (``along``: a road beside it) and the kind of road after the junction (``after``: edge, ramp, roundabout)."""
    feats = _features(rmap)
    out: list[dict[str, Any]] = []
    done: set[tuple[str, str, str]] = set()
    for sc in scenarios:
        route = rmap.route(sc.mission.start_edge, sc.mission.goal_edge) or (sc.mission.start_edge,)
        for i, eid in enumerate(route):
            nxt = route[i + 1] if i + 1 < len(route) else ""
            before = route[i - 1] if i else ""
            if (before, eid, nxt) in done:
                continue
            done.add((before, eid, nxt))
            edge = rmap.edge(eid)
            lanes = edge.getLanes()
            drive = [ln for ln in lanes if ln.allows("passenger")]
            node = edge.getToNode()
            link: dict[str, Any] = {"elements": set(), "turns": set(), "crossing": set()}
            if nxt:
                _link_features(rmap, edge, rmap.edge(nxt), node, link)
            parties = {"vehicle/ahead", "vehicle/behind", "none/grip"} | _road_parties(edge)
            multilane = len(drive) >= 2
            parties |= link["crossing"] | beside_sides(rmap, eid, APPROACH_M)  # beside it near its junction
            sidewalk = any(ln.allows("pedestrian") and not ln.allows("passenger") for ln in lanes)
            if node.getID() in _crossing_nodes(rmap):
                parties |= {f"pedestrian/{a}" for a in PEDESTRIAN_APPROACHES}
            element = ("roundabout" if eid in feats["ring_edges"] else "ramp" if eid in feats["ramp_edges"] else None)
            vmax = max((ln.getSpeed() for ln in drive), default=0.0)
            after = ("roundabout" if nxt in feats["ring_edges"] else "ramp" if nxt in feats["ramp_edges"] else
                     "edge" if nxt else None)  # the road the ego is on after the junction
            along = set(beside_sides(rmap, eid))  # a road beside this one, anywhere along it (not at its junction)
            base = {"multilane": multilane, "vmax": vmax, "parties": parties, "node": node.getID(), "after": after,
                    "along": along}
            if before in feats["ring_edges"] and eid not in feats["ring_edges"]:  # off the ring: the turn out of
                out_turn = link_turn(rmap, before, eid)  # it counts on this road, with this road's parties and
                if out_turn:  # the traffic that comes across its way out there
                    out.append(dict(base, element=None, turn=out_turn, node=edge.getFromNode().getID(),
                                    parties=parties | read_along(rmap, before, eid)))
            if element is None and node.getID() in feats["ring_nodes"] and nxt in feats["ring_edges"]:
                # onto the ring: in its junction the ego is on the roundabout, the ring's traffic crosses it there (and,
                # as the ego turns in, comes in beside it), and a car leaving by this arm's way out comes towards it
                ring = {"vehicle/ahead", "vehicle/behind", "none/grip"} | link["crossing"] | read_along(rmap, eid, nxt)
                ring |= beside_sides(rmap, eid, APPROACH_M)
                ring |= {"vehicle/oncoming"} if _has_opposite(edge) else set()
                out.append(dict(base, element="roundabout", turn=None, parties=ring))
                # before the way onto the ring, its traffic comes across from the other side too: 2 s before it comes
                # round to meet the ego, a car on the ring's far side heads the other way across the ego's (the
                # roundabout's 'from the right' in 3 of 5 campaigns of the twentieth session)
                if link["crossing"]:  # (in place: base["parties"] is this set, so the yield line's places take both)
                    parties |= {"vehicle/crossing_left", "vehicle/crossing_right"}
            turns = sorted(link["turns"]) or [None]
            into = _into(rmap, eid, nxt, turns[0]) if turns[0] else set()  # a turn counts on the road it leads into
            if element:  # a ring or ramp edge: its own element (and the manoeuvre it implies), no turns
                own = set(parties) | (read_along(rmap, eid, nxt) if element == "roundabout" and nxt else set())
                if element == "ramp":  # on a ramp up to a junction, the cars that cross the ego's turn there
                    own |= {p for p in into if p.startswith("vehicle/crossing")}
                own |= along
                if not sidewalk:  # nobody walks on a ring or a ramp without a pavement
                    own = {p for p in own if not p.startswith("pedestrian/")}
                out.append(dict(base, element=element, turn=None, parties=own))
                if element == "roundabout":  # on the ring every frame is the roundabout, its nodes too
                    continue
            controls = sorted(link["elements"]) or [None]
            for control in controls:
                for turn in turns:
                    out.append(dict(base, element=control, turn=turn) if turn is None else
                               dict(base, element=control, turn=turn, parties=parties | into))
    return out


def _into(rmap, edge_id: str, next_id: str, turn: str) -> set[str]:
    """Who can meet the ego as it turns (``turn``) from ``edge_id`` into ``next_id`` on the road turned into: its
    road parties (:func:`_road_parties`), a car the other way only where :func:`oncoming_into` says, and that car
    also as crossing from the turn's side (read mid-turn, or on a ramp just before the turn, its heading is square
    to the ego's: the interchange's campaigns met cars on the road turned into 'from the left' as the ego drove up
    its exit ramp, in every repetition of the twentieth session)."""
    into = _road_parties(rmap.edge(next_id))
    if "vehicle/oncoming" in into:
        if oncoming_into(rmap, edge_id, next_id):
            into.add(f"vehicle/crossing_{turn.split('_', 1)[1]}")
        else:
            into.discard("vehicle/oncoming")
    return into


def _road_parties(edge) -> set[str]:
    """Who can be beside or come towards the ego on ``edge``: the sides and rear quarters on a road of several
    lanes for cars, oncoming cars where a road runs the other way, walkers where it has a pavement."""
    out = set()
    if _multilane(edge):
        out |= {f"vehicle/{a}" for a in ("left", "right", "rear_left", "rear_right")}
    if _has_opposite(edge):
        out.add("vehicle/oncoming")
    if any(ln.allows("pedestrian") and not ln.allows("passenger") for ln in edge.getLanes()):
        out |= {f"pedestrian/{a}" for a in PEDESTRIAN_APPROACHES}
    return out


def _multilane(edge) -> bool:
    """Whether ``edge`` has two lanes for cars or more."""
    return sum(1 for ln in edge.getLanes() if ln.allows("passenger")) >= 2


def _has_opposite(edge) -> bool:
    """A road the other way between the same two nodes."""
    return any(o.getToNode() == edge.getFromNode() for o in edge.getToNode().getOutgoing())


@lru_cache(maxsize=16)
def _crossing_nodes(rmap) -> frozenset[str]:
    """Nodes with a pedestrian crossing (a crossing's id is ``:<node>_c<n>``)."""
    return frozenset(e.getID()[1:].rsplit("_", 1)[0] for e in rmap.net.getEdges(withInternal=True)
                     if e.getFunction() == "crossing")


def _link_features(rmap, edge, nxt, node, out: dict[str, Any]) -> None:
    """What the route's link from ``edge`` to ``nxt`` at ``node`` offers: control, turn, crossing traffic."""
    from drivefuzz.triage.signature import right_of_way

    conns = [c for c in edge.getConnections(nxt) if c.getFromLane().allows("passenger")]
    for c in conns:
        cls = right_of_way(c)
        if cls == "traffic_light":
            out["elements"].add("signal")
        elif cls in ("priority", "yield", "stop"):
            out["elements"].add("yield" if cls == "stop" else cls)
    turn = link_turn(rmap, edge.getID(), nxt.getID())
    if turn:
        out["turns"].add(turn)
    out["crossing"] |= crossing_sides(rmap, edge.getID(), nxt.getID())


#: [m] two centre lines through a junction closer than this let the bodies on them come within the close-encounter
#: gap (:data:`GAP_M`, a car's width, and room for both to be off their lines: the reference ADS swung out of a
#: roundabout's exit to within 0.7 m of a car on the road in beside it, whose centre line is 3.5 m from the exit's)
CONFLICT_M = 5.0
APPROACH_M = 30.0  #: [m] the approach to a junction, where a car beside the ego meets it at that junction


@lru_cache(maxsize=4096)
def _link_lines(rmap, edge_id: str, next_id: str) -> tuple[LineString, ...]:
    """The ego's centre lines through the link from ``edge_id`` to ``next_id``: per connection, the last 15 m of its
    lane, the junction's internal lanes, and the first 15 m of the lane it leads into."""
    return tuple(_line(rmap, *c) for c in rmap.connections(edge_id, next_id))


def _line(rmap, frm: str, to: str, via: str) -> LineString:
    g = rmap.geom(to)
    pts = _tail(rmap, frm) + [p for lid in rmap.internal_chain(via) for p in rmap.geom(lid).pts]
    pts += [p for p in g.pts[g.cum < 15.0]] + [g.position(min(15.0, g.length))[:2]]
    return _polyline(pts)


def _polyline(pts) -> LineString:
    """A line through the (x, y) of ``pts``."""
    return LineString([tuple(map(float, p[:2])) for p in pts])


def _tail(rmap, lane_id: str) -> list:
    """The points of the last 15 m of ``lane_id``."""
    f = rmap.geom(lane_id)
    return [f.position(max(f.length - 15.0, 0.0))[:2]] + list(f.pts[f.cum > f.length - 15.0])


@lru_cache(maxsize=4096)
def oncoming_into(rmap, edge_id: str, next_id: str) -> bool:
    """Whether a car coming the other way can meet the ego as it turns from ``edge_id`` into ``next_id``: the
    road the other way beside ``next_id`` has a lane whose last 15 m come within :data:`CONFLICT_M` of the ego's
    way, or a path through the junction from the opposite approach does (a left turner into the same road). On the
    interchange the ego turns right from the off-ramp into the near lane of a road with two lanes each way: the
    other way's lanes pass 6 m from it, and none of 35 campaigns (seventeenth to nineteenth sessions) met a car
    from there in that turn."""
    ego = _link_lines(rmap, edge_id, next_id)
    nxt = rmap.edge(next_id)
    for o in nxt.getToNode().getOutgoing():
        if o.getToNode() != nxt.getFromNode() or not rmap.is_normal_edge(o):
            continue
        for lane in o.getLanes():
            if lane.allows("passenger"):
                end = _polyline(_tail(rmap, lane.getID()))
                if any(end.distance(m) < CONFLICT_M for m in ego):
                    return True
    return "vehicle/oncoming" in _approaches_near(rmap, edge_id, next_id)


@lru_cache(maxsize=4096)
def crossing_sides(rmap, edge_id: str, next_id: str) -> frozenset[str]:
    """``vehicle/crossing_left`` / ``_right``: the sides from which a car can cross the ego's way through the link
    from ``edge_id`` to ``next_id``. A side counts where a road for cars enters that junction at 45-135 degrees to
    the route's (a ramp merging at a shallow angle comes from the side, not across) from that side, and a path
    through the junction out of one of its lanes comes within :data:`CONFLICT_M` of one of the ego's (crosses it,
    or merges into the road it takes). Until the nineteenth session both sides counted wherever any road entered
    across: the way onto a roundabout (its ring comes from the left) offered cars crossing from the right, and the
    turn out of it cars from the left."""
    return _approaches_near(rmap, edge_id, next_id) - {"vehicle/oncoming"}


#: [m] another road's lane whose centre line runs this close to the ego's lane, at under 45 degrees to it, carries
#: cars that :func:`party` counts beside the ego; measured: the interchange's one-lane exit ramp leaves the
#: highway's lane 4.2-6 m beside it, and its campaigns met cars there 'behind left' (twentieth session)
BESIDE_M = 6.0


@lru_cache(maxsize=16)
def _car_lanes(rmap) -> tuple[tuple[str, ...], tuple[LineString, ...], STRtree]:
    """Every lane for cars on a normal edge: ids, centre lines, and a tree over the lines."""
    ids, lines = [], []
    for e in rmap.net.getEdges(withInternal=False):
        for ln in e.getLanes():
            if ln.allows("passenger") and rmap.is_normal_edge(e):
                ids.append(ln.getID())
                lines.append(_polyline(rmap.geom(ln.getID()).pts))
    return tuple(ids), tuple(lines), STRtree(lines)


@lru_cache(maxsize=4096)
def beside_sides(rmap, edge_id: str, last_m: float | None = None) -> frozenset[str]:
    """``vehicle/left``, ``rear_left`` (and the right's) where another road's lane for cars runs beside a lane of
    ``edge_id`` (over its last ``last_m`` m only, where given: the approach to its junction): within
    :data:`BESIDE_M` of it, further than a car beside in the ego's own lane (:data:`SAME_LANE_M`), at under 45
    degrees (a one-lane ramp beside a highway). The lanes the edge continues from and into are the ego's own way. A
    road of several lanes offers its sides anyway (:func:`_road_parties`); until the twenty-first session only such
    a road offered any."""
    edge = rmap.edge(edge_id)
    mine = []
    for ln in edge.getLanes():
        if ln.allows("passenger"):
            g = rmap.geom(ln.getID())
            pts = g.pts if last_m is None else [g.position(max(g.length - last_m, 0.0))[:2]] + list(
                g.pts[g.cum > g.length - last_m])
            mine.append(_polyline(pts))
    own = {ln.getID() for ln in edge.getLanes()}  # and the lanes it continues from and into: the ego's own way
    own |= {c.getToLane().getID() for ln in edge.getLanes() for c in ln.getOutgoing()}
    own |= {c.getFromLane().getID() for e in edge.getIncoming() for c in e.getConnections(edge)}
    out: set[str] = set()
    for way in mine:
        for d in np.arange(0.0, way.length, 2.0):
            p = way.interpolate(d)
            for *_, side in lanes_beside(rmap, p, _heading_at(way, d + 0.5), own):
                out |= {f"vehicle/{side}", f"vehicle/rear_{side}"}
        if len(out) == 4:
            break
    return frozenset(out)


def lanes_beside(rmap, p: Point, heading: float, own=frozenset()) -> list[tuple[str, float, float, str]]:
    """(lane id, centre-line distance [m], position on that lane level with ``p`` [m], side) of every lane for cars
    beside the point ``p`` of a way heading ``heading`` [rad]: within :data:`BESIDE_M`, further than a car beside in
    the ego's own lane (:data:`SAME_LANE_M`), at under 45 degrees; not the lanes ``own``."""
    ids, lines, tree = _car_lanes(rmap)
    out = []
    for i in tree.query(p, predicate="dwithin", distance=BESIDE_M):
        other = lines[i]
        gap = other.distance(p)
        if ids[i] in own or gap < SAME_LANE_M:
            continue
        t = other.project(p)
        if abs(wrap_angle(_heading_at(other, t) - heading)) >= math.pi / 4:
            continue
        c = other.interpolate(t)
        side = "left" if math.cos(heading) * (c.y - p.y) - math.sin(heading) * (c.x - p.x) > 0 else "right"
        out.append((ids[i], gap, t, side))
    return out


#: [m] back along another car's path from where it comes nearest the ego's: where it was 2 s before it met the ego
#: (:data:`APPROACH_S`) at the speeds of a roundabout
READ_BACK_M = (5.0, 10.0, 15.0)


@lru_cache(maxsize=4096)
def read_along(rmap, edge_id: str, next_id: str) -> frozenset[str]:
    """The vehicle parties that :func:`party` reads, against the ego's way, for the cars whose paths through the
    junction at the end of ``edge_id`` come within :data:`CONFLICT_M` of the ego's to ``next_id``: where the ego is
    on a roundabout's ring or in its junctions (there the classifier reads a car's heading and side against the
    ego's way where that car is). Each such path is read :data:`READ_BACK_M` m back from its nearest point, against
    the ego's line there: square to it, crossing from that side; against it, oncoming; within 45 degrees of it,
    beside it on that side, or behind it on its line (a car coming onto the ring merges in). On the
    roundabout's ways out the road in beside them runs the other way: a car there is oncoming, not crossing from
    the right as :func:`crossing_sides` reads the junction (until the twenty-first session, when the classifier read
    it against the ego's heading, still round the ring)."""
    edge = rmap.edge(edge_id)
    node = edge.getToNode()
    ego = _link_lines(rmap, edge_id, next_id)
    out: set[str] = set()
    for e in node.getIncoming():
        if e.getID() == edge_id or not rmap.is_normal_edge(e) or not e.allows("passenger"):
            continue
        for theirs in _paths_from(rmap, e.getID()):
            for mine in ego:
                if theirs.distance(mine) >= CONFLICT_M:
                    continue
                t0 = theirs.project(nearest_points(theirs, mine)[0])
                for back in READ_BACK_M:
                    out.add(_read_at(mine, theirs, max(t0 - back, 0.0)))
    return frozenset(out)


@lru_cache(maxsize=4096)
def _paths_from(rmap, edge_id: str) -> tuple[LineString, ...]:
    """The centre lines of the paths for cars from ``edge_id`` through the junction at its end (:func:`_line`),
    U-turns left out."""
    e = rmap.edge(edge_id)
    out = []
    for lane in e.getLanes():
        if not lane.allows("passenger"):
            continue
        for c in lane.getOutgoing():
            to = c.getToLane()
            if rmap.is_normal_edge(to.getEdge()) and to.getEdge().getToNode() is not e.getFromNode():
                out.append(_line(rmap, lane.getID(), to.getID(), c.getViaLaneID() or ""))
    return tuple(out)


def _read_at(mine: LineString, theirs: LineString, t: float) -> str:
    """The party a car at ``t`` m along ``theirs`` is against the ego's way ``mine`` (:func:`party`)."""
    p, h = theirs.interpolate(t), _heading_at(theirs, t + 0.5)
    u = mine.project(p)
    way, c = _heading_at(mine, u), mine.interpolate(u)
    side = "left" if math.cos(way) * (p.y - c.y) - math.sin(way) * (p.x - c.x) > 0 else "right"
    dh = abs(wrap_angle(h - way))
    if dh >= 3 * math.pi / 4:
        return "vehicle/oncoming"
    if dh > math.pi / 4:
        return f"vehicle/crossing_{side}"
    return f"vehicle/{side}" if c.distance(p) >= SAME_LANE_M else "vehicle/behind"


def _heading_at(line: LineString, t: float) -> float:
    """[rad] the heading of ``line`` over the metre around ``t`` m along it (cut at its ends)."""
    a, b = line.interpolate(max(t - 0.5, 0.0)), line.interpolate(min(t + 0.5, line.length))
    return math.atan2(b.y - a.y, b.x - a.x)


def _approaches_near(rmap, edge_id: str, next_id: str) -> frozenset[str]:
    """The approaches (``vehicle/crossing_left``, ``_right``, ``vehicle/oncoming``) to the junction at the end of
    ``edge_id`` from which a path through it comes within :data:`CONFLICT_M` of one of the ego's to ``next_id``
    (:func:`_link_lines`): a road for cars that enters at 45-135 degrees to the route's from that side, or
    at more than 135 degrees (the other way)."""
    edge = rmap.edge(edge_id)
    node = edge.getToNode()
    ego = _link_lines(rmap, edge_id, next_id)
    h = _end_heading(edge)
    out = set()
    for e in node.getIncoming():
        if e.getID() == edge_id or not rmap.is_normal_edge(e) or not e.allows("passenger"):
            continue
        dh = wrap_angle(_end_heading(e) - h)
        if abs(dh) >= 3 * math.pi / 4:
            side = "vehicle/oncoming"
        elif math.pi / 4 < abs(dh):
            side = "vehicle/crossing_right" if dh > 0 else "vehicle/crossing_left"  # heads to the ego's left
        else:
            continue
        if side not in out and any(theirs.distance(mine) < CONFLICT_M for theirs in _paths_from(rmap, e.getID())
                                   for mine in ego):
            out.add(side)
    return frozenset(out)


@lru_cache(maxsize=4096)
def link_turn(rmap, edge_id: str, next_id: str) -> str | None:
    """``turn_left`` / ``turn_right`` where the ego can turn through the link from ``edge_id`` to ``next_id`` as
    :func:`manoeuvre` counts a turn: its path (the lane, the junction's internal lanes, the next lane) bends by
    :data:`TURN` or more within the distance driven in :data:`WINDOW_S` at 1.1 x the faster lane's limit, that
    distance ending off a roundabout's ring and its junctions (there every frame is the roundabout); else None.
    SUMO's link direction is not enough: the highway's off-ramp is a right turn to SUMO and bends 23 degrees over
    those 110 m; a roundabout's entry is a right turn to SUMO and counts as the roundabout as soon as the ego
    turns; its exit is part of the ring to SUMO and counts as a turn on the road out."""
    feats = _features(rmap)
    best = 0.0
    for frm, to, via in rmap.connections(edge_id, next_id):
        reach = WINDOW_S * 1.1 * max(rmap.lane(frm).getSpeed(), rmap.lane(to).getSpeed())
        lanes = [frm, *rmap.internal_chain(via), to]
        parts = [rmap.geom(lid).pts for lid in lanes]
        flags = [np.full(len(p), not _on_ring(lid, feats)) for p, lid in zip(parts, lanes)]
        bend = _max_bend(np.concatenate(parts), reach, np.concatenate(flags))
        if abs(bend) > abs(best):
            best = bend
    if abs(best) < TURN:
        return None
    return "turn_left" if best > 0 else "turn_right"


def _max_bend(xy: np.ndarray, reach: float, counted: np.ndarray, chord: float = 10.0) -> float:
    """[rad] the largest heading change (signed, left positive) along the polyline ``xy`` from one of its
    ``chord``-m chords to one that begins up to ``reach`` m further on, at a point where ``counted`` (per point of
    ``xy``; a metre takes its segment's start). Chords, not segments: a lane that widens shifts its centre line
    3.6 m over 8 m (38 degrees), which no car follows at speed and which turns nobody."""
    d = np.diff(xy, axis=0)
    cum = np.concatenate(([0.0], np.cumsum(np.hypot(d[:, 0], d[:, 1]))))
    if cum[-1] <= chord:
        return 0.0
    s = np.arange(0.0, cum[-1] + 1e-9, 1.0)  # every metre
    x, y = np.interp(s, cum, xy[:, 0]), np.interp(s, cum, xy[:, 1])
    ok = counted[np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(counted) - 1)]
    n = int(chord)
    heading = np.unwrap(np.arctan2(y[n:] - y[:-n], x[n:] - x[:-n]))
    ok = ok[n:]  # a chord counts where it ends
    span = max(int(reach), 1)
    best = 0.0
    for j in np.flatnonzero(ok):
        window = heading[j] - heading[max(j - span, 0):j + 1]
        k = int(np.argmax(np.abs(window)))
        if abs(window[k]) > abs(best):
            best = float(window[k])
    return best


def _end_heading(edge) -> float:
    """[rad] ENU heading of an edge's last shape segment."""
    pts = edge.getShape()
    (x0, y0), (x1, y1) = pts[-2][:2], pts[-1][:2]
    return math.atan2(y1 - y0, x1 - x0)


# ------------------------------------------------------------------------------------------- a campaign
def summarise(records: Iterable[Mapping[str, Any]], reach: Iterable[str]) -> dict[str, Any]:
    """A campaign's coverage from its journal records: per cell how often it was reached, in how many
    executions that produced a finding or an incident, how many executions the search aimed at it (their
    ``mutation`` begins ``aim <cell>:``, :func:`aimed_cell`) and how many came near it (``near``: within
    :data:`NEAR` of a threshold); reachable, reached, unreached; per projection too.
    A cell never reached that was aimed at is one the search tried and missed; one never aimed at, one it did
    not try (its job reached all it aimed at first, the budget ended, or the feedback aims at nothing: random,
    paper)."""
    reach = sorted(set(reach))
    hits: dict[str, dict[str, int]] = {}
    aims: dict[str, int] = {}
    nears: dict[str, int] = {}
    for rec in records:
        for c in rec.get("near") or ():
            nears[c] = nears.get(c, 0) + 1
        for c in rec.get("cells") or ():
            h = hits.setdefault(c, {"count": 0, "findings": 0, "incidents": 0})
            h["count"] += 1
            h["findings"] += bool(rec.get("finding"))
            h["incidents"] += bool(rec.get("incident"))
        cell = aimed_cell(rec)
        if cell:
            aims[cell] = aims.get(cell, 0) + 1
    reached = [c for c in reach if c in hits]
    per = {}
    for name in PROJECTIONS:
        r = [c for c in reach if c.startswith(name + ":")]
        per[name] = {"reachable": len(r), "reached": sum(1 for c in r if c in hits)}
    empty = {"count": 0, "findings": 0, "incidents": 0}
    return {"reachable": len(reach), "reached": len(reached),
            "share": round(len(reached) / len(reach), 4) if reach else 0.0,
            "projections": per,
            "cells": {c: {**hits.get(c, empty), "aimed": aims.get(c, 0), "near": nears.get(c, 0)} for c in reach},
            "outside": {c: h for c, h in sorted(hits.items()) if c not in set(reach)}}


def aimed_cell(rec: Mapping[str, Any]) -> str | None:
    """The cell an execution's mutation was aimed at (``"aim <cell>: ..."``), None when it was not aimed; a
    record that :class:`JournalCells` keeps names it as ``aim``."""
    if "aim" in rec:
        return rec["aim"] if isinstance(rec["aim"], str) else None
    mutation = rec.get("mutation")
    if isinstance(mutation, str) and mutation.startswith("aim "):
        return mutation[4:].split(": ", 1)[0]
    return None


def split(cell: str) -> tuple[str, str, str]:
    """(projection, row, column) of a cell key."""
    proj, rest = cell.split(":", 1)
    row, col = rest.split("|", 1)
    return proj, row, col


# ------------------------------------------------------------------------------------------- a campaign folder
COVERAGE_FILE = "coverage.json"


def campaign_reachable(out: Path) -> list[str]:
    """The reachable cells of the campaign in ``out``: from its manifest's seeds and their network."""
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.sumofiles import load_scenario

    manifest = json.loads((out / "manifest.json").read_text())
    seeds = [load_scenario(out / s) for s in manifest.get("seeds", [])]
    if not seeds:
        return []
    return reachable(load_roadmap(seeds[0].network_path()), seeds)


class JournalCells:
    """The cells of a campaign's executions, read from its jobs' journals (``jobs/*/journal.jsonl``), each
    execution once (a job re-run after a kill journals some twice); :meth:`update` reads only what is new."""

    def __init__(self, out: str | Path):
        self.out = Path(out)
        self.records: dict[str, dict[str, Any]] = {}
        self._offsets: dict[Path, int] = {}

    def update(self) -> int:
        """Read the journals' new complete lines; return how many new executions."""
        new = 0
        for path in sorted((self.out / "jobs").glob("*/journal.jsonl")):
            recs, self._offsets[path] = read_new_lines(path, self._offsets.get(path, 0))
            for rec in recs:
                if isinstance(rec, dict) and rec.get("event") == "end" and isinstance(rec.get("key"), str) \
                        and rec["key"] not in self.records:
                    self.records[rec["key"]] = {"cells": [c for c in rec.get("cells") or () if isinstance(c, str)],
                                                "near": [c for c in rec.get("near") or () if isinstance(c, str)],
                                                "finding": rec.get("finding"), "incident": rec.get("incident"),
                                                "aim": aimed_cell(rec)}
                    new += 1
        return new

    def reached(self) -> set[str]:
        return {c for r in self.records.values() for c in r["cells"]}


def campaign_coverage(out: str | Path, write: bool = True) -> dict[str, Any]:
    """The coverage of the campaign in ``out``, summed over every execution in its journals (a resumed
    campaign's too), as :func:`summarise` gives it with ``executions``; written to ``out/coverage.json``."""
    from drivefuzz.storage import atomic_write_json

    out = Path(out)
    journals = JournalCells(out)
    journals.update()
    cov = summarise(journals.records.values(), campaign_reachable(out))
    cov["executions"] = len(journals.records)
    cov["with_cells"] = sum(1 for r in journals.records.values() if r["cells"])
    if write:
        atomic_write_json(out / COVERAGE_FILE, cov)
    return cov


def format_coverage(cov: Mapping[str, Any]) -> str:
    """``drivefuzz coverage``'s text: the totals, then per projection the reached cells (how often, with
    findings F and incidents I) and the cells never reached (with the executions that came near them)."""
    lines = [f"coverage {cov['reached']}/{cov['reachable']} cells ({100.0 * cov['share']:.0f} %) over "
             f"{cov.get('executions', 0)} executions ({cov.get('with_cells', 0)} with a close encounter)"]
    cells = cov["cells"]
    for name, (row_axis, col_axis) in PROJECTIONS.items():
        p = cov["projections"][name]
        lines.append("")
        lines.append(f"{row_axis} x {col_axis}: {p['reached']}/{p['reachable']} reached")
        mine = [(c, h) for c, h in cells.items() if c.startswith(name + ":")]
        for c, h in sorted(mine, key=lambda ch: -ch[1]["count"]):
            if h["count"]:
                marks = "".join(f"  {k[0].upper()}{h[k]}" for k in ("findings", "incidents") if h[k])
                lines.append(f"  {h['count']:6d}  {c.split(':', 1)[1]}{marks}")
        never = [(c.split(":", 1)[1], h.get("aimed", 0), h.get("near", 0)) for c, h in mine if not h["count"]]
        tried = [f"{c} ({n}{f'; near {k}' if k else ''})" for c, n, k in sorted(never, key=lambda cn: -cn[1]) if n]
        untried = [c + (f" (near {k})" if k else "") for c, n, k in never if not n]
        if tried:
            lines.append(f"  never reached, aimed at and missed ({len(tried)}; aimed executions, and those that came "
                         "near): " + ", ".join(tried))
        if untried:
            lines.append(f"  never reached, never aimed at ({len(untried)}): " + ", ".join(untried))
    if cov.get("outside"):
        lines.append("")
        lines.append("reached but not derived as reachable (the derivation under-estimates here): "
                     + ", ".join(f"{c} ({h['count']})" for c, h in cov["outside"].items()))
    return "\n".join(lines)
