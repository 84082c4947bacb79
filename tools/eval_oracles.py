"""Oracle correctness, like the paper's tbl:oracle: inject each error into N scenarios and count
true positives and false negatives; run clean scenarios and count false alarms.

    python tools/eval_oracles.py [--scenarios N] [--jobs J] [--rng-seed S] [--save DIR]

Rows (the injected error, and the oracle that must fire):

=============  =====================================================  ==============
misbehaviour   injected error                                          oracle
=============  =====================================================  ==============
collision      a linear vehicle behind the ego, faster, rear-ends it  collision
speeding       ADS fault ``speeding`` (target 1.3 x limit + 2 m/s)    speeding
red light      ADS fault ``no_traffic_lights`` on an approach that     red_light
               is red when the ego reaches its stop line
immobility     ADS fault ``no_control``                                immobility
lane invasion  ADS fault ``steer_left``, ego on the leftmost lane      lane_invasion
=============  =====================================================  ==============

Scenarios are drawn with one seeded RNG: a network, a mission (a committed seed under
``seeds/<net>/`` or a fresh random mission on that network), the start position and speed,
the simulation seed, a few walkers on the sidewalks, and the row's own parameters (the
rammer's gap and speed, the signalised approach and its distance to the stop line...).

Every run has all installed oracles on and goes on after a misbehaviour, so the oracle under
test is never masked by another one. Whether the error really manifested is decided by an
independent *ground truth* computed here from the frozen trace with different code (shapely
polygons, the trace's own signal channel): a run where it did not (the rammer never reached
the ego, the ego never exceeded a limit, met no red light, drifted left within its own lane)
is an **invalid injection**. Invalid injections are counted and listed, never counted as true
positives, and replaced by a fresh draw (at most ``--max-draws`` x N draws per row) so that each
row aims at N valid injections:

- TP: valid injection and the row's oracle fired (for collision: naming the rammer);
- FN: valid injection and it did not;
- disputed: the ground truth says the error did not manifest but the oracle fired (a false
  positive of the oracle or of the ground truth: look at it); errors: the run raised.
A run whose ground truth is within a small margin of an oracle threshold is "borderline" and
counts as invalid (e.g. a corner 0.2-0.25 m over a lane edge, tolerance 0.2 m).

Clean runs: every committed seed, and N committed seeds with 1-6 lawful actors added by the
mutator's ``congestion`` strategy. Every misbehaviour reported there is an alarm; the ground
truth of its oracle tells a real ADS misbehaviour (``confirmed``, e.g. the reference ADS
really touched a car) from a **false alarm**; a mission time-out of a run held up behind slow
lawful traffic for most of its time is counted apart (``traffic``: true, but the seed's time
limit did not allow for the traffic). Ground-truth events no oracle reported are listed as misses.

``--save DIR`` writes every FN, invalid injection and alarm as a scenario folder (replay it
with ``drivefuzz run DIR/<name>``). Prints the table and the wall time.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import sys
import time
import xml.etree.ElementTree as ET
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivefuzz.scenario.roadmap import PASSENGER, PEDESTRIAN, load_roadmap  # noqa: E402
from drivefuzz.scenario import Actor, ActorKind, AdsSpec, Mission, NavType, Scenario, SimOptions  # noqa: E402

NETWORKS = ("highway", "interchange", "intersection", "roundabout", "town")
ROWS = ("collision", "speeding", "red_light", "immobility", "lane_invasion")
FAULT = {"speeding": "speeding", "red_light": "no_traffic_lights", "immobility": "no_control",
         "lane_invasion": "steer_left"}
LABEL = {"collision": "collision", "speeding": "speeding", "red_light": "red light", "immobility": "immobility",
         "lane_invasion": "lane invasion"}
INJECTED = {"collision": "a vehicle rear-ends the ego", "speeding": "fault=speeding",
            "red_light": "fault=no_traffic_lights", "immobility": "fault=no_control",
            "lane_invasion": "fault=steer_left"}

#: Ground-truth margins beyond the oracles' default thresholds: a run within them is "borderline"
#: and does not count as a valid injection (nor as a miss on a clean run).
SPEED_MARGIN = 0.1  # [m/s] above the limit
GRACE = 3.5  # [s] limit unchanged before (the speeding oracle's grace is 3 s)
LANE_MARGIN = 0.05  # [m] beyond the lane-invasion tolerance
LANE_TOL, JUNCTION_TOL = 0.2, 0.5  # [m] the lane-invasion oracle's defaults
IMMOBILE_S = 61.0  # [s] illegitimate standstill (the oracle's threshold is 60 s)
RED_LIGHT_DISTANCE = 30.0  # [m] a stop line this close excuses a standstill (the oracle's default)


@dataclass
class Case:
    row: str  # one of ROWS, or "seed" / "traffic" for clean runs
    index: int
    scenario: Scenario
    info: dict[str, Any] = field(default_factory=dict)  # what was drawn (printed for FNs and invalids)


# ============================================================================ scenario drawing
def committed_seeds() -> dict[str, list[Scenario]]:
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario

    return {net: [read_scenario(p) for p in list_seeds(ROOT / "seeds" / net)] for net in NETWORKS}


def _with(sc: Scenario, **update) -> Scenario:
    return sc.model_copy(update=update)


def _mission(sc: Scenario, **update) -> Scenario:
    return _with(sc, mission=sc.mission.model_copy(update=update))


def _fault(sc: Scenario, fault: str) -> Scenario:
    return _with(sc, ads=AdsSpec(name="ego", options={"fault": fault}))


class Drawer:
    """Draws the scenarios of every row from one seeded RNG."""

    def __init__(self, rng_seed: int):
        self.rng = random.Random(rng_seed)
        self.seeds = committed_seeds()
        self.rmaps = {net: load_roadmap(ROOT / "networks" / f"{net}.net.xml") for net in NETWORKS}
        self._random_missions: dict[str, Any] = {}
        self._drawn: set[str] = set()

    # ---------------------------------------------------------------- missions
    def mission(self, nets=NETWORKS) -> tuple[str, Scenario, str]:
        """(network, scenario, origin): a committed seed or a fresh random mission, a new sim seed."""
        rng = self.rng
        net = rng.choice(nets)
        if rng.random() < 0.5:
            k = rng.randrange(len(self.seeds[net]))
            sc, origin = self.seeds[net][k], f"seeds/{net}/{k:03d}"
        else:
            from drivefuzz.scenario.seed import random_missions

            gen = self._random_missions.get(net)
            if gen is None:
                gen = self._random_missions[net] = random_missions(
                    self.rmaps[net], random.Random(rng.randrange(2**31)), str(self.rmaps[net].path))
            sc, origin = next(gen), f"random mission on {net}"
        sc = _with(sc, seed=rng.randrange(2**31), ads=AdsSpec(name="ego"))
        return net, sc, origin

    def long_mission(self, net: str, min_m: float, max_m: float) -> Scenario | None:
        """A random mission whose route is ``min_m``..``max_m`` metres long (None if the draw missed)."""
        rng = self.rng
        rmap = self.rmaps[net]
        edges = [e for e in rmap.edge_ids(PASSENGER) if rmap.edge(e).getLength() >= 30.0]
        start, goal = rng.choice(edges), rng.choice(edges)
        route = rmap.route(start, goal)
        if not route or len(route) < 2:
            return None
        start_len, goal_len = rmap.edge(start).getLength(), rmap.edge(goal).getLength()
        start_pos = round(rng.uniform(5.0, start_len * 0.5), 1)
        goal_pos = round(rng.uniform(10.0, goal_len - 10.0), 1)
        length = rmap.route_length(route, start_pos, goal_pos)
        if not min_m <= length <= max_m:
            return None
        lanes = [l.getID() for l in rmap.edge(start).getLanes()
                 if l.allows(PASSENGER) and any(c.getTo().getID() == route[1] for c in l.getOutgoing())]
        from drivefuzz.scenario.seed import time_limit_for

        return Scenario(network=str(rmap.path), ads=AdsSpec(name="ego"), seed=rng.randrange(2**31),
                        mission=Mission(start_lane=rng.choice(lanes) if lanes else rmap.drive_lane(start),
                                        start_pos=start_pos, goal_edge=goal, goal_pos=goal_pos),
                        sim=SimOptions(time_limit=time_limit_for(rmap, route, length)))

    def walkers(self, sc: Scenario, net: str, k: int) -> Scenario:
        """Up to ``k`` lawful walkers on the sidewalks along the route (they stay off the road)."""
        from drivefuzz.search.mutate import Mutator

        m = Mutator(self.rmaps[net])
        for _ in range(k):
            sc = m.add_actor(sc, self.rng, ActorKind.PEDESTRIAN, NavType.AUTOPILOT).scenario
        return sc

    # ---------------------------------------------------------------- rows
    def collision(self) -> tuple[Scenario, dict] | None:
        rng = self.rng
        net, sc, origin = self.mission()
        rmap = self.rmaps[net]
        lane = sc.mission.start_lane
        length = rmap.geom(lane).length
        gap = round(rng.uniform(8.0, 30.0), 1)  # [m] front bumper to front bumper
        if length < gap + 12.0:
            return None
        pos = round(rng.uniform(gap + 5.0, max(gap + 5.0, min(length - 5.0, gap + 60.0))), 1)
        speed = round(rng.uniform(2.2 * math.sqrt(gap), 22.0), 1)  # catches an ego accelerating at ~2 m/s^2
        start_speed = round(rng.choice((0.0, 0.0, rng.uniform(0.0, 4.0))), 1)
        sc = _mission(sc, start_pos=pos, start_speed=start_speed)
        sc = self.walkers(sc, net, rng.randint(0, 2))
        rammer = Actor(id="rammer", kind="vehicle", nav="linear", start_lane=lane, start_pos=round(pos - gap, 1),
                       speed=speed, dest_edge=sc.mission.goal_edge)
        sc = _with(sc, actors=sc.actors + (rammer,), name=f"collision-{net}")
        return sc, {"origin": origin, "gap": gap, "rammer_speed": speed, "start_speed": start_speed}

    def speeding(self) -> tuple[Scenario, dict] | None:
        """A mission with room to speed: the reference ADS brakes ~130 m ahead of its goal and of a
        red light and slows for curves, so short missions from a standstill never exceed a limit.
        The ego starts at 50-100 % of its lane's limit on routes of at least 150 m."""
        rng = self.rng
        if rng.random() < 0.3:
            net, sc, origin = self.mission()
            rmap = self.rmaps[net]
            route = rmap.route(sc.mission.start_edge, sc.mission.goal_edge)
            if not route or rmap.route_length(route, sc.mission.start_pos, sc.mission.goal_pos) < 150.0:
                return None
        else:
            net = rng.choice(NETWORKS)
            sc, origin = self.long_mission(net, 250.0, 1200.0), f"long random mission on {net}"
            if sc is None:
                return None
            rmap = self.rmaps[net]
        limit = rmap.geom(sc.mission.start_lane).speed
        # past the 3 s grace it is still above the limit only if it need not brake before then
        if free_run(rmap, sc) < 0.6 * (3.5 * (limit + 1.0) + (limit + 1.0) ** 2 / 1.5):
            return None
        start_speed = round(rng.uniform(0.7, 1.0) * limit, 1)
        sc = _fault(_mission(sc, start_speed=start_speed), FAULT["speeding"])
        sc = self.walkers(sc, net, rng.randint(0, 2))
        return _with(sc, name=f"speeding-{net}"), {"origin": origin, "start_speed": start_speed}

    def immobility(self) -> tuple[Scenario, dict] | None:
        rng = self.rng
        net, sc, origin = self.mission()
        # long enough that red phases (at most ~50 % of a cycle) cannot excuse 60 s
        sc = _fault(_with(sc, sim=SimOptions(step_length=sc.sim.step_length, time_limit=200.0)),
                    FAULT["immobility"])
        sc = self.walkers(sc, net, rng.randint(0, 2))
        return _with(sc, name=f"immobility-{net}"), {"origin": origin}

    def lane_invasion(self) -> tuple[Scenario, dict] | None:
        rng = self.rng
        net, sc, origin = self.mission()
        rmap = self.rmaps[net]
        lanes = [l for l in rmap.edge(sc.mission.start_edge).getLanes() if l.allows(PASSENGER)]
        left = max(lanes, key=lambda l: l.getIndex()).getID()  # drifting left leaves the carriageway
        start_speed = round(rng.choice((0.0, rng.uniform(0.0, 6.0))), 1)
        sc = _fault(_mission(sc, start_lane=left, start_speed=start_speed), FAULT["lane_invasion"])
        sc = self.walkers(sc, net, rng.randint(0, 2))
        return _with(sc, name=f"lane_invasion-{net}"), {"origin": origin, "start_lane": left}

    def red_light(self) -> tuple[Scenario, dict] | None:
        """An approach whose link is red from t = 0 for long enough, started close enough that the
        ego (accelerating to the limit, ignoring the light) reaches the stop line well inside it."""
        rng = self.rng
        net = rng.choice([n for n in NETWORKS if red_approaches(n)])
        in_lane, out_lane, red_until = rng.choice(red_approaches(net))
        rmap = self.rmaps[net]
        g = rmap.geom(in_lane)
        v0 = 0.95 * g.speed
        start_speed = round(rng.choice((0.0, rng.uniform(0.0, 0.5 * v0))), 1)
        # latest arrival we accept: 8 s before the red ends (curves and walkers slow the ego down)
        d_max = min(g.length - 6.0, reach_in(red_until - 8.0, v0, start_speed))
        if d_max < 12.0:
            return None
        dist = round(rng.uniform(12.0, d_max), 1)
        out_edge = rmap.lane(out_lane).getEdge().getID()
        goal_edge = out_edge
        # sometimes drive on beyond the junction
        succ = [e.getID() for e in rmap.edge(out_edge).getOutgoing() if e.getFunction() == ""
                and e.getID() != rmap.lane(in_lane).getEdge().getID()]
        if succ and rng.random() < 0.4:
            goal_edge = rng.choice(sorted(succ))
        route = rmap.route(rmap.lane(in_lane).getEdge().getID(), goal_edge)
        if not route or len(route) < 2 or route[1] != out_edge:
            return None
        glen = rmap.edge(goal_edge).getLength()
        goal_pos = round(rng.uniform(min(10.0, glen / 2), max(10.0, glen - 10.0)), 1)
        sc = Scenario(network=str(rmap.path), name=f"red_light-{net}",
                      mission=Mission(start_lane=in_lane, start_pos=round(g.length - dist, 1), goal_edge=goal_edge,
                                      goal_pos=goal_pos, start_speed=start_speed),
                      ads=AdsSpec(name="ego", options={"fault": FAULT["red_light"]}), seed=rng.randrange(2**31),
                      sim=SimOptions(time_limit=60.0))
        return sc, {"approach": f"{in_lane}->{out_lane}", "dist": dist, "red_until": red_until,
                    "start_speed": start_speed}

    def traffic(self) -> tuple[Scenario, dict]:
        """A committed seed with 1-6 lawful actors (the mutator's congestion strategy)."""
        from drivefuzz.search.mutate import Mutator

        rng = self.rng
        net = rng.choice(NETWORKS)
        k = rng.randrange(len(self.seeds[net]))
        sc = _with(self.seeds[net][k], seed=rng.randrange(2**31))
        m = Mutator(self.rmaps[net])
        descr = []
        for _ in range(rng.randint(1, 6)):
            mut = m.generate(sc, "congestion", rng)
            sc = mut.scenario
            descr.append(mut.description)
        return _with(sc, name=f"traffic-{net}-{k:03d}"), {"origin": f"seeds/{net}/{k:03d}", "added": descr}

    def draw(self, row: str) -> tuple[Scenario, dict]:
        """A scenario for ``row`` that differs from every one drawn before (by content hash)."""
        for _ in range(500):
            got = getattr(self, row)()
            if got is not None and got[0].content_hash() not in self._drawn:
                self._drawn.add(got[0].content_hash())
                return got
        raise RuntimeError(f"could not draw a {row} scenario")


def free_run(rmap, sc: Scenario) -> float:
    """Metres [m] the reference ADS can drive from its start before it must slow down: for a sharp
    curve (curve speed below the start lane's limit), the first signalised stop line, or its goal
    (it brakes ~v^2/1.5 m ahead of a stop, so a fault that only raises its target speed shows
    only on a long free run)."""
    from ego.planning import build_path

    m = sc.mission
    route = rmap.route(m.start_edge, m.goal_edge)
    if not route:
        return 0.0
    path, edge_s = build_path(rmap, route, m.start_lane, m.start_pos, m.goal_edge, m.goal_pos)
    _, s0, _ = path.locate(*rmap.geom(m.start_lane).position(m.start_pos)[:2], hint=0, window=len(path.pts))
    _, s_goal, _ = path.locate(*rmap.geom(rmap.drive_lane(m.goal_edge)).position(m.goal_pos)[:2], hint=0,
                               window=len(path.pts))
    end = s_goal
    limit = rmap.geom(m.start_lane).speed
    sharp = np.flatnonzero((path.curvature > 2.5 / limit**2) & (path.s > s0))
    if len(sharp):
        end = min(end, float(path.s[sharp[0]]))
    for e in route[:-1]:
        if rmap.edge(e).getToNode().getType().startswith("traffic_light"):
            end = min(end, edge_s[e] + rmap.edge(e).getLength())
            break
    return end - s0


def reach_in(t: float, v0: float, v_start: float, a_max: float = 2.0, dt: float = 0.05) -> float:
    """Distance [m] the reference ADS covers in ``t`` s, accelerating freely (IDM) to ``v0``."""
    v, s = v_start, 0.0
    for _ in range(int(max(t, 0.0) / dt)):
        v += a_max * (1.0 - (v / v0) ** 4) * dt
        s += v * dt
    return s


@lru_cache(maxsize=None)
def red_approaches(net: str) -> list[tuple[str, str, float]]:
    """(incoming lane, outgoing lane, red until [s]) for every vehicle link that is red from t = 0
    for at least 20 s (fixed-time programs, offset 0, read from the net file)."""
    path = ROOT / "networks" / f"{net}.net.xml"
    phases: dict[str, list[tuple[float, str]]] = {}
    offsets: dict[str, float] = {}
    for el in ET.parse(path).getroot().iter("tlLogic"):
        phases[el.get("id")] = [(float(p.get("duration")), p.get("state")) for p in el.iter("phase")]
        offsets[el.get("id")] = float(el.get("offset", "0"))
    rmap = load_roadmap(path)
    out = []
    for tls in rmap.net.getTrafficLights():
        prog = phases.get(tls.getID())
        if not prog or offsets[tls.getID()] != 0.0:
            continue
        for in_lane, out_lane, idx in tls.getConnections():
            if not (in_lane.allows(PASSENGER) and out_lane.allows(PASSENGER)):
                continue
            t = 0.0
            for dur, state in prog:
                if state[idx] not in "r":
                    break
                t += dur
            if t >= 20.0:
                out.append((in_lane.getID(), out_lane.getID(), t))
    return sorted(out)


def build_cases(n: int, rng_seed: int) -> tuple[Drawer, list[Case]]:
    d = Drawer(rng_seed)
    cases = []
    for row in ROWS:
        for i in range(n):
            sc, info = d.draw(row)
            cases.append(Case(row, i, sc, info))
    for net in NETWORKS:
        for k, sc in enumerate(d.seeds[net]):
            cases.append(Case("seed", len(cases), sc, {"origin": f"seeds/{net}/{k:03d}"}))
    for i in range(n):
        sc, info = d.traffic()
        cases.append(Case("traffic", i, sc, info))
    return d, cases


# ============================================================================ ground truth
def _rects(x, y, h, length, width):
    """Shapely polygons of oriented rectangles (vectorised)."""
    import shapely

    x, y, h = np.asarray(x, float), np.asarray(y, float), np.asarray(h, float)
    length = np.broadcast_to(np.asarray(length, float), x.shape)
    width = np.broadcast_to(np.asarray(width, float), x.shape)
    c, s = np.cos(h), np.sin(h)
    pts = []
    for dl, dw in ((0.5, -0.5), (0.5, 0.5), (-0.5, 0.5), (-0.5, -0.5)):
        pts.append(np.stack([x + c * dl * length - s * dw * width, y + s * dl * length + c * dw * width], -1))
    ring = np.stack(pts + [pts[0]], axis=1)
    return shapely.polygons(ring)


def gt_collisions(trace) -> dict[str, int]:
    """actor id -> first frame its body overlaps the ego's (intersection area > 1 cm^2)."""
    import shapely

    a = trace.actors
    if not len(a.frame):
        return {}
    f = a.frame
    ex, ey, eh = trace["x"][f], trace["y"][f], trace["heading"][f]
    near = np.hypot(a.x - ex, a.y - ey) < 8.0
    if not near.any():
        return {}
    f, j = f[near], a.actor[near]
    ego = _rects(ex[near], ey[near], eh[near], trace.meta["ego_length"], trace.meta["ego_width"])
    other = _rects(a.x[near], a.y[near], a.heading[near], a.length[j], a.width[j])
    area = shapely.area(shapely.intersection(ego, other))
    out: dict[str, int] = {}
    for k in np.flatnonzero(area > 1e-4):
        out.setdefault(a.ids[int(j[k])], int(f[k]))
    return out


def gt_speeding(trace, grace: float = GRACE, margin: float = SPEED_MARGIN) -> int | None:
    """First frame faster than the lane limit (+ margin) with the limit unchanged for GRACE s."""
    v, lim, t = trace["speed"], trace["speed_limit"], trace["t"]
    n = len(v)
    since = None
    prev = math.nan
    for k in range(n):
        if lim[k] != lim[k]:
            continue
        if lim[k] != prev:
            since, prev = (t[k] if prev == prev else 0.0), lim[k]
        if t[k] - since >= grace and v[k] > lim[k] + margin:
            return k
    return None


def gt_red_crossings(trace) -> list[tuple[int, str]]:
    """(frame, state) for every stop line the ego's front bumper passes, from the trace's own
    signal channel (SUMO's next-light distance drops to the line, then jumps or vanishes)."""
    d, st, v = trace["tls_dist"], trace["tls_state"], trace["speed"]
    dt = trace.step_length
    out = []
    for k in range(len(d) - 1):
        if not d[k] == d[k] or d[k] > v[k] * dt * 3 + 1.0 or v[k] < 0.05:
            continue
        if not d[k + 1] == d[k + 1] or d[k + 1] > d[k] + 5.0:
            out.append((k, str(st[k])))
    return out


def gt_immobile(trace) -> float:
    """Longest illegitimate standstill [s]: stopped, not near the goal, no stop-state light within
    RED_LIGHT_DISTANCE (pedestrians and queues are not modelled: runs here have none in front)."""
    v, d, st, gd = trace["speed"], trace["tls_dist"], trace["tls_state"], trace["goal_dist"]
    dt = trace.step_length
    best = cur = 0.0
    for k in range(len(v)):
        if v[k] >= 0.1:
            cur = 0.0
            continue
        excused = gd[k] <= 5.0 or (str(st[k]) in ("r", "u", "y", "Y") and d[k] <= RED_LIGHT_DISTANCE)
        if not excused:
            cur += dt
            best = max(best, cur)
    return best


class _LaneTruth:
    """The area the ego may drive on along its route, as one shapely geometry.

    Lanes of the route's edges that allow cars (on an edge with forbidden lane changes only the
    lane the ego entered it on), the junctions at their ends and the car lanes through them,
    minus walking areas. A body corner farther than the tolerance from it is an invasion.
    Independent of the oracle's corner classification and lane-segment grid.
    """

    def __init__(self, rmap, route: tuple[str, ...], fixed_lanes: dict[str, str]):
        import shapely
        from shapely.geometry import LineString, Polygon
        from shapely.ops import unary_union

        net = rmap.net
        restricted = _restricted_edges(str(rmap.path))
        lanes, junctions, walks = [], [], []
        nodes = set()
        for e in route:
            edge = rmap.edge(e)
            nodes |= {edge.getFromNode(), edge.getToNode()}
            for ln in edge.getLanes():
                if not ln.allows(PASSENGER):
                    continue
                if e in restricted and fixed_lanes.get(e, ln.getID()) != ln.getID():
                    continue
                lanes.append(LineString([p[:2] for p in ln.getShape()]).buffer(ln.getWidth() / 2, cap_style="flat"))
        for node in nodes:
            shape = node.getShape()
            if len(shape) >= 3:
                junctions.append(Polygon([p[:2] for p in shape]).buffer(0))
        for e in net.getEdges(withInternal=True):
            func = e.getFunction()
            if func == "walkingarea" and e.getFromNode() in nodes:
                for ln in e.getLanes():
                    if len(ln.getShape()) >= 3:
                        walks.append(Polygon([p[:2] for p in ln.getShape()]).buffer(0))
            elif func == "internal" and e.getFromNode() in nodes:
                for ln in e.getLanes():
                    if ln.allows(PASSENGER) and len(ln.getShape()) >= 2:
                        junctions.append(LineString([p[:2] for p in ln.getShape()]).buffer(ln.getWidth() / 2,
                                                                                             cap_style="flat"))
        junction = unary_union(junctions) if junctions else Polygon()
        walk = unary_union(walks) if walks else Polygon()
        self.junction = junction.difference(walk)
        self.lanes = unary_union(lanes).difference(walk) if lanes else Polygon()
        shapely.prepare(self.lanes)
        shapely.prepare(self.junction)

    def depth(self, trace, rows) -> np.ndarray:
        """Per frame (of ``rows``): how far [m] the farthest body point is outside the area, minus
        the tolerance that applies (the junction tolerance while a corner is in a junction)."""
        import shapely

        L, W = trace.meta["ego_length"], trace.meta["ego_width"]
        x, y, h = trace["x"][rows], trace["y"][rows], trace["heading"][rows]
        c, s = np.cos(h), np.sin(h)
        offs = [(0.5, -0.5), (0.5, 0.5), (-0.5, 0.5), (-0.5, -0.5), (0.5, 0.0), (0.0, 0.5), (-0.5, 0.0), (0.0, -0.5)]
        px = np.stack([x + c * a * L - s * b * W for a, b in offs], 1)
        py = np.stack([y + s * a * L + c * b * W for a, b in offs], 1)
        in_junction = shapely.contains_xy(self.junction, px, py)
        dj = np.zeros(px.shape)
        if (~in_junction).any():
            dj[~in_junction] = shapely.distance(shapely.points(px[~in_junction], py[~in_junction]), self.junction)
        in_lane = shapely.contains_xy(self.lanes, px, py)
        dl = np.zeros(px.shape)
        if (~in_lane).any():
            dl[~in_lane] = shapely.distance(shapely.points(px[~in_lane], py[~in_lane]), self.lanes)
        # a point is fine within LANE_TOL of a junction, or within the lane tolerance of a lane
        # (JUNCTION_TOL while a body corner is in a junction: a turning body sweeps over lines)
        tol_lane = np.where(in_junction[:, :4].any(axis=1), JUNCTION_TOL, LANE_TOL)[:, None]
        return np.minimum(dj - LANE_TOL, dl - tol_lane).max(axis=1)


@lru_cache(maxsize=None)
def _restricted_edges(path: str) -> frozenset[str]:
    out = set()
    for el in ET.parse(path).getroot().iter("edge"):
        for ln in el.iter("lane"):
            if ln.get("changeLeft") is not None or ln.get("changeRight") is not None:
                out.add(el.get("id"))
    return frozenset(out)


def gt_lane_depth(trace, rmap) -> np.ndarray:
    """Per frame, see :meth:`_LaneTruth.depth`. The area is that of the route edge the ego is on
    (the last one its front was on), the one before and the one after, less any edge running
    against the current one (a route may come back the other way, e.g. around a roundabout)."""
    route = tuple(trace.meta["route"])
    fixed: dict[str, str] = {}
    k, ks = 0, np.zeros(trace.n_frames, dtype=int)
    for f, lane in enumerate(trace["lane"]):
        if lane and not lane.startswith(":"):
            edge = lane.rsplit("_", 1)[0]
            fixed.setdefault(edge, lane)  # the first lane the ego held on each edge
            if edge in route[k:]:
                k = route.index(edge, k)
        ks[f] = k
    out = np.empty(trace.n_frames)
    for k in np.unique(ks):
        cur = rmap.edge(route[k])
        ends = {cur.getFromNode().getID(), cur.getToNode().getID()}
        window = tuple(e for e in route[max(k - 1, 0):k + 2]
                       if e == route[k] or {rmap.edge(e).getFromNode().getID(), rmap.edge(e).getToNode().getID()}
                       != ends)
        rows = ks == k
        out[rows] = _LaneTruth(rmap, window, fixed).depth(trace, rows)
    return out


def ground_truth(trace, rmap, termination: str) -> dict[str, Any]:
    lane = gt_lane_depth(trace, rmap)
    reds = [k for k, s in gt_red_crossings(trace) if s in ("r", "u")]
    return {
        "collision": gt_collisions(trace),
        "speeding": gt_speeding(trace),
        "speeding_exact": gt_speeding(trace, 3.0, 0.0),  # the oracle's own thresholds, no margin
        "red_light": reds[0] if reds else None,
        "red_crossings": gt_red_crossings(trace),
        "immobility": round(gt_immobile(trace), 2),
        "lane_invasion": float(lane.max()) if len(lane) else -1.0,
        "timeout": termination == "time_limit",
        "held_up": round(held_up(trace), 3),
    }


def held_up(trace) -> float:
    """Fraction of the run a slower vehicle was close ahead of the ego (within 1.6 m of its axis,
    at most 15 m bumper to bumper): how much lawful traffic, not the ADS, set the ego's pace."""
    a = trace.actors
    if not len(a.frame):
        return 0.0
    f = a.frame
    h = trace["heading"][f]
    dx, dy = a.x - trace["x"][f], a.y - trace["y"][f]
    along = dx * np.cos(h) + dy * np.sin(h)
    lat = -dx * np.sin(h) + dy * np.cos(h)
    veh = np.array([a.kinds[j] == "vehicle" for j in a.actor], dtype=bool)
    gap = along - 0.5 * trace.meta["ego_length"] - 0.5 * a.length[a.actor]
    ahead = veh & (along > 0) & (np.abs(lat) < 1.6) & (gap < 15.0) & (a.speed < trace["speed_limit"][f] * 0.8)
    return len(np.unique(f[ahead])) / max(trace.n_frames, 1)


def manifested(row: str, gt: dict[str, Any]) -> tuple[bool | None, str]:
    """Whether the injected error really happened: True, False, or None (borderline)."""
    if row == "collision":
        return ("rammer" in gt["collision"]), "rammer overlapped the ego" if "rammer" in gt["collision"] \
            else "the rammer never touched the ego"
    if row == "speeding":
        if gt["speeding"] is not None:
            return True, "over the limit"
        if gt["speeding_exact"] is not None:
            return None, "borderline: over the limit by less than 0.1 m/s, or only 3-3.5 s after a change"
        return False, "never over a limit for more than the grace period"
    if row == "red_light":
        if gt["red_light"] is not None:
            return True, "crossed a stop line on red"
        states = "".join(s for _, s in gt["red_crossings"]) or "none"
        return False, f"met no red light (stop lines crossed on: {states})"
    if row == "immobility":
        ok = gt["immobility"] >= IMMOBILE_S
        return ok, f"illegitimate standstill {gt['immobility']:.1f} s"
    if row == "lane_invasion":
        depth = gt["lane_invasion"]
        if depth > LANE_MARGIN:
            return True, f"body {depth + LANE_TOL:.2f} m outside its lanes"
        if depth > 0.0:
            return None, f"borderline: {depth:.3f} m beyond the tolerance"
        return False, "the body stayed within its own carriageway"
    raise ValueError(row)


# ============================================================================ one run
_ORACLES = None


def run_case(case: Case) -> dict[str, Any]:
    """Runs in a worker process (libsumo: one simulation per process)."""
    from drivefuzz.ads import load_ads
    from drivefuzz.sim.execute import execute
    from drivefuzz.oracle import OracleSettings

    sc = case.scenario
    t0 = time.perf_counter()
    try:
        ex = execute(sc, ads=load_ads(sc.ads.name, sc.ads.options), oracles=OracleSettings().instantiate(),
                     stop_on_misbehavior=False)
    except Exception as exc:  # noqa: BLE001 - reported as an invalid run, with the reason
        return {"error": f"{type(exc).__name__}: {exc}", "wall": time.perf_counter() - t0}
    rmap = load_roadmap(sc.network)
    gt = ground_truth(ex.trace, rmap, ex.termination.value)
    return {
        "termination": ex.termination.value,
        "fired": [(m.oracle, m.kind, m.frame, round(m.time, 2), m.actors) for m in ex.misbehaviors],
        "gt": gt,
        "wall": time.perf_counter() - t0,
        "sim": float(ex.trace["t"][-1]) if ex.trace.n_frames else 0.0,
    }


def _run_all(cases: list[Case], jobs: int) -> list[dict[str, Any]]:
    if jobs <= 1:
        return [run_case(c) for c in cases]
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        return list(pool.map(run_case, cases, chunksize=4))


# ============================================================================ scoring
def score_injected(case: Case, res: dict[str, Any]) -> tuple[str, str]:
    """('tp' | 'fn' | 'invalid' | 'disputed' | 'error', reason). Disputed: the ground truth says the
    error did not manifest, but the oracle fired (a false positive of the oracle, or of the truth)."""
    if "error" in res:
        return "error", res["error"]
    ok, why = manifested(case.row, res["gt"])
    fired = [f for f in res["fired"] if f[0] == case.row]
    if case.row == "collision":
        fired = [f for f in fired if "rammer" in f[4]]
    if not ok:
        if fired and ok is False:
            return "disputed", f"{why}, but {case.row}/{fired[0][1]} fired at {fired[0][3]} s"
        return "invalid", why
    if fired:
        return "tp", why
    return "fn", why


def confirm_alarm(oracle: str, kind: str, actors, gt: dict[str, Any]) -> bool | str | None:
    """Whether the ground truth confirms an alarm on a clean run (None: no ground truth; "traffic":
    a true time-out, but slow lawful traffic ahead, not the ADS, set the pace for most of the run)."""
    if oracle == "collision":
        return bool(set(actors) & set(gt["collision"]))
    if oracle == "speeding":
        return gt["speeding"] is not None
    if oracle == "red_light":
        return gt["red_light"] is not None
    if oracle == "immobility":
        return gt["immobility"] >= IMMOBILE_S
    if oracle == "lane_invasion":
        return gt["lane_invasion"] > 0.0
    if oracle == "mission":
        if kind == "timeout" and gt["timeout"]:
            return "traffic" if gt["held_up"] > 0.3 else True
        return None
    return None


def gt_events(gt: dict[str, Any]) -> list[str]:
    """Ground-truth misbehaviours of a clean run (compared with what the oracles reported)."""
    out = []
    if gt["collision"]:
        out.append("collision")
    if gt["speeding"] is not None:
        out.append("speeding")
    if gt["red_light"] is not None:
        out.append("red_light")
    if gt["immobility"] >= IMMOBILE_S:
        out.append("immobility")
    if gt["lane_invasion"] > LANE_MARGIN:
        out.append("lane_invasion")
    return out


def save_case(folder: Path, case: Case, tag: str) -> Path:
    from drivefuzz.scenario.sumofiles import write_scenario

    out = folder / f"{case.row}-{case.index:03d}-{tag}"
    write_scenario(case.scenario, out)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", "-n", type=int, default=100, help="injections per row, clean traffic runs")
    ap.add_argument("--jobs", "-j", type=int, default=1, help="worker processes")
    ap.add_argument("--rng-seed", type=int, default=0, help="seed of the scenario draw")
    ap.add_argument("--max-draws", type=float, default=4.0,
                    help="draw at most this many x N scenarios per row while replacing invalid injections")
    ap.add_argument("--save", type=Path, default=None, help="write FNs, invalid injections and alarms here")
    ap.add_argument("--verbose", "-v", action="store_true")
    args = ap.parse_args(argv)
    wall0 = time.perf_counter()
    from drivefuzz.oracle import available_oracles

    names = list(available_oracles())
    drawer, cases = build_cases(args.scenarios, args.rng_seed)
    results = _run_all(cases, args.jobs)

    verdicts: dict[str, Counter] = defaultdict(Counter)
    invalid: dict[str, list[str]] = defaultdict(list)
    disputed: dict[str, list[str]] = defaultdict(list)
    errors: dict[str, list[str]] = defaultdict(list)
    fns: dict[str, list[str]] = defaultdict(list)
    notes: list[str] = []
    pending = [(c, r) for c, r in zip(cases, results) if c.row in ROWS]
    clean = [(c, r) for c, r in zip(cases, results) if c.row not in ROWS]
    n_runs = len(cases)
    drawn = Counter(c.row for c, _ in pending)
    while pending:
        redo = []
        for case, res in pending:
            v, why = score_injected(case, res)
            if v in ("invalid", "disputed", "error"):
                {"invalid": invalid, "disputed": disputed, "error": errors}[v][case.row].append(
                    f"{case.scenario.name} {case.info}: {why}")
                if args.save:
                    save_case(args.save, case, v)
                if drawn[case.row] < args.max_draws * args.scenarios:
                    redo.append(case.row)
                continue
            verdicts[case.row][v] += 1
            if v == "fn":
                fns[case.row].append(f"{case.scenario.name} {case.info}: {why}; fired {res['fired']}")
                if args.save:
                    save_case(args.save, case, "fn")
        new = []
        for row in redo:
            sc, info = drawer.draw(row)
            new.append(Case(row, drawn[row], sc, info))
            drawn[row] += 1
        pending = list(zip(new, _run_all(new, args.jobs))) if new else []
        n_runs += len(new)

    alarms: dict[str, Counter] = defaultdict(Counter)
    alarm_lines: list[str] = []
    miss_lines: list[str] = []
    sim_s = 0.0
    for case, res in clean:
        if "error" in res:
            notes.append(f"clean run {case.scenario.name} failed: {res['error']}")
            continue
        sim_s += res["sim"]
        seen = set()
        for oracle, kind, frame, t, actors in res["fired"]:
            seen.add(oracle)
            ok = confirm_alarm(oracle, kind, actors, res["gt"])
            key = ok if isinstance(ok, str) else "confirmed" if ok else ("false" if ok is False else "unchecked")
            alarms[oracle][key] += 1
            alarms[oracle]["all"] += 1
            alarm_lines.append(f"[{key}] {case.scenario.name} {case.info.get('origin')}: {oracle}/{kind} at {t} s "
                               f"actors={list(actors)}")
            if args.save:
                save_case(args.save, case, f"alarm-{oracle}")
        for ev in gt_events(res["gt"]):
            if ev not in seen:
                miss_lines.append(f"{case.scenario.name} {case.info.get('origin')}: ground truth {ev}, no alarm "
                                  f"({res['gt'][ev]})")

    wall = time.perf_counter() - wall0
    n_seed = sum(1 for c, _ in clean if c.row == "seed")
    n_traffic = sum(1 for c, _ in clean if c.row == "traffic")
    print(f"Oracle correctness (tbl:oracle): {args.scenarios} valid injections per row aimed at, "
          f"rng seed {args.rng_seed}")
    print()
    print(f"{'misbehaviour':<14} {'injected error':<28} {'TP/N':>9} {'FN':>4} {'invalid':>8} {'disputed':>9}"
          f" {'errors':>7}")
    for row in ROWS:
        tp, fn = verdicts[row]["tp"], verdicts[row]["fn"]
        print(f"{LABEL[row]:<14} {INJECTED[row]:<28} {f'{tp}/{tp + fn}':>9} {fn:>4} {len(invalid[row]):>8} "
              f"{len(disputed[row]):>9} {len(errors[row]):>7}")
    print()
    print(f"False alarms on {n_seed} committed seeds + {n_traffic} seeds with random lawful traffic "
          f"({sim_s / 60:.0f} simulated minutes):")
    print(f"{'oracle':<14} {'alarms':>7} {'confirmed':>10} {'traffic':>8} {'false':>6} {'unchecked':>10}")
    for name in names:
        a = alarms[name]
        print(f"{name:<14} {a['all']:>7} {a['confirmed']:>10} {a['traffic']:>8} "
              f"{a['false']:>6} {a['unchecked']:>10}")
    print("(confirmed: the ground truth shows the misbehaviour; traffic: a true time-out behind slow lawful traffic)")
    print()
    for row in ROWS:
        for line in fns[row]:
            print(f"FN {row}: {line}")
    if alarm_lines:
        print("Alarms on clean runs:")
        for line in alarm_lines:
            print("  " + line)
    if miss_lines:
        print("Ground-truth events on clean runs that no oracle reported:")
        for line in miss_lines:
            print("  " + line)
    shown = invalid if args.verbose else {r: v[:3] for r, v in invalid.items()}
    if any(invalid.values()):
        print("Invalid injections (the error did not manifest; redrawn):")
        for row in ROWS:
            if invalid[row]:
                print(f"  {row}: {len(invalid[row])}")
                for line in shown.get(row, []):
                    print(f"    {line}")
    for title, table in (("Disputed (oracle fired, ground truth says the error did not manifest; redrawn)", disputed),
                         ("Runs that raised (redrawn)", errors)):
        if any(table.values()):
            print(title + ":")
            for row in ROWS:
                for line in table[row]:
                    print(f"  {row}: {line}")
    for line in notes:
        print(line)
    print()
    print(f"{n_runs} executions, wall time {wall:.1f} s ({args.jobs} job{'s' if args.jobs != 1 else ''})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
