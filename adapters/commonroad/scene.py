"""The planner's world, built from drivefuzz's road map and one Observation.

Everything here is a decision the adapter makes for the planner, kept simple and visible
(DESIGN.md: an adapter is a boundary, not a driver):

- :func:`reference_path`: the reference ADS's lane-level path along the mission route
  (:func:`ego.planning.build_path`), continued along the road (or straight on) for
  :data:`PAST_GOAL` metres past the goal, because the CommonRoad curvilinear frame raises
  ``CurvilinearProjectionDomainLongitudinalError`` for samples past its end;
- :func:`limit_curvature`: the reference path's bends no tighter than the car can turn (SUMO's junction
  lanes turn on radii down to 2.6 m, drivefuzz's car on 4.1 m; the planner samples around the
  reference, and where it is tighter than the car every sample is kinematically infeasible);
- :func:`boundary_segments`: the edge of the drivable area as short segments: the passenger lanes
  of the edges the reference path runs along and the junctions at their ends (shape and internal
  lanes); sidewalks and, outside junctions, the other direction's lanes are off the road (the
  pieces are computed once per network); :func:`boundary_group` makes them thin boxes just outside;
- :func:`predictions`: every other road user as a box over the planning horizon (a time-variant
  collision object), moving at constant velocity along its heading (``constant_velocity``) or, for
  vehicles, with the acceleration and yaw rate that :class:`Tracks` reads from the change between
  two planning cycles (``constant_acceleration``; clamped to what a car can do, never backwards);
- :func:`stop_wall`: a virtual wall across the road at a red (or, when there is room to stop
  comfortably, yellow) stop line;
- :func:`stop_speed`: the desired speed that stops the car at a point (the goal, the wall).

Units: SI, radians ENU (0 = east, counter-clockwise).
"""

from __future__ import annotations

import math
import weakref
from typing import Literal, get_args

import numpy as np
import commonroad_dc.pycrcc as pycrcc
from shapely import LineString, Polygon, unary_union
from shapely.geometry.polygon import orient

from drivefuzz.ads import Observation
from drivefuzz.scenario.roadmap import PASSENGER, RoadMap
from ego.planning import Path, build_path, lawful_route

#: [m] the reference path goes on this far past the goal ...
PAST_GOAL = 120.0
#: [m] ... and starts this far (straight back) behind the car's start: near its ends the curvilinear
#: frame's projection domain narrows, and a car within a few metres of the start raised
#: ``CurvilinearProjectionDomainLateralError`` for its lateral samples.
BEFORE_START = 30.0
#: [m] half the thickness of a boundary box; the box lies just outside the road.
WALL_HALF = 0.25
#: [m] boundary segments farther than this from the reference path are left out of a mission's checker.
BOUNDARY_REACH = 40.0
#: [m] half the width of the stop-line wall: wider than the planner's lateral samples (+-3 m) and half a car.
STOP_WALL_HALF_WIDTH = 4.5
#: [m] half the depth of the stop-line wall (it starts at the stop line).
STOP_WALL_HALF_DEPTH = 0.5
#: [m/s^2] a yellow light gets a wall only if the car can stop before the line at this deceleration
#: (the reference ADS's rule).
YELLOW_DECEL = 4.0

_PARTS: "weakref.WeakKeyDictionary[RoadMap, tuple[dict, dict]]" = weakref.WeakKeyDictionary()


def _parts(rmap: RoadMap) -> tuple[dict, dict]:
    """Per normal edge, its passenger lanes buffered to their width; per junction, its shape and its internal
    passenger lanes (shapely); computed once per road map (a campaign runs thousands of missions on one)."""
    parts = _PARTS.get(rmap)
    if parts is None:
        edges: dict[str, list] = {}
        nodes: dict[str, list] = {}
        for edge in rmap.net.getEdges(withInternal=True):
            fn = edge.getFunction()
            if fn not in ("", "internal"):
                continue
            key = edge.getToNode().getID() if fn == "internal" else edge.getID()
            into = nodes if fn == "internal" else edges
            for lane in edge.getLanes():
                shape = [p[:2] for p in lane.getShape()]
                if lane.allows(PASSENGER) and len(shape) >= 2 and LineString(shape).length > 0.01:
                    into.setdefault(key, []).append(LineString(shape).buffer(lane.getWidth() / 2.0, cap_style="flat"))
        for node in rmap.net.getNodes():
            shape = [p[:2] for p in node.getShape()]
            if len(shape) >= 3:
                poly = Polygon(shape).buffer(0)
                if not poly.is_empty:
                    nodes.setdefault(node.getID(), []).append(poly)
        parts = _PARTS[rmap] = (edges, nodes)
    return parts


def road_area(rmap: RoadMap, edges: "list[str] | None" = None):
    """The drivable area (shapely): the passenger lanes of ``edges`` (all normal edges when None) and the
    junctions at their ends (shape and internal lanes), closed by 0.1 m so that the seams between
    neighbouring lanes vanish. The lanes of the other direction are outside, but for junctions."""
    by_edge, by_node = _parts(rmap)
    if edges is None:
        edges = list(by_edge)
    polys = []
    nodes = set()
    for e in dict.fromkeys(edges):
        polys += by_edge.get(e, [])
        edge = rmap.edge(e)
        nodes.update((edge.getFromNode().getID(), edge.getToNode().getID()))
    for n in sorted(nodes):
        polys += by_node.get(n, [])
    return unary_union(polys).buffer(0.1, join_style="mitre").buffer(-0.1, join_style="mitre")


def boundary_segments(rmap: RoadMap, edges: "list[str] | None" = None) -> np.ndarray:
    """(n, 4) the edge of :func:`road_area` as segments ``x0, y0, x1, y1`` [m] with the road on their left."""
    area = road_area(rmap, edges)
    polys = list(area.geoms) if hasattr(area, "geoms") else [area]
    rows = []
    for poly in polys:
        poly = orient(poly, 1.0)  # exterior counter-clockwise, holes clockwise: the road is on the left
        for ring in (poly.exterior, *poly.interiors):
            pts = np.asarray(ring.coords)
            rows.append(np.hstack([pts[:-1], pts[1:]]))
    seg = np.vstack(rows) if rows else np.zeros((0, 4))
    return seg[np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) > 1e-3]


def boundary_group(segments: np.ndarray, path_pts: np.ndarray, reach: float = BOUNDARY_REACH, every_end: bool = False):
    """A ``pycrcc.ShapeGroup`` of thin boxes just outside the road along the segments within ``reach``
    metres of ``path_pts`` (n, 2). A box reaches past its segment's end by its own thickness only where the
    road's edge turns left there (a convex corner of the road: the gap between two boxes is outside); where it
    turns right (a kerb the road bends round) the neighbouring boxes already overlap outside, and a box carried
    on straight would reach into the road, by up to its thickness (0.25 m at a right angle: it stopped a car
    turning right with 0.22 m of clearance to the kerb, issue 32). ``every_end``: past every end, as before."""
    from scipy.spatial import cKDTree

    group = pycrcc.ShapeGroup()
    if len(segments) == 0:
        return group, 0
    mid = (segments[:, :2] + segments[:, 2:]) / 2.0
    half_len = np.hypot(segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1]) / 2.0
    dist, _ = cKDTree(path_pts).query(mid)
    keep = np.flatnonzero(dist - half_len <= reach)
    d = segments[:, 2:] - segments[:, :2]
    starts = cKDTree(segments[:, :2])
    _, nxt = starts.query(segments[:, 2:], distance_upper_bound=0.01)  # the segment that goes on from each end
    _, prv = cKDTree(segments[:, 2:]).query(segments[:, :2], distance_upper_bound=0.01)
    n = len(segments)
    for i in keep.tolist():
        x0, y0, x1, y1 = segments[i].tolist()
        ang = math.atan2(y1 - y0, x1 - x0)
        j, k = int(nxt[i]), int(prv[i])
        # reach past an end unless the edge turns right there (cross product < 0), or the neighbour is not known
        ext1 = WALL_HALF if every_end or j >= n or d[i, 0] * d[j, 1] - d[i, 1] * d[j, 0] >= 0.0 else 0.0
        ext0 = WALL_HALF if every_end or k >= n or d[k, 0] * d[i, 1] - d[k, 1] * d[i, 0] >= 0.0 else 0.0
        along = (ext1 - ext0) / 2.0
        # the road is on the left: the box goes to the right, outside
        cx = (x0 + x1) / 2.0 + WALL_HALF * math.sin(ang) + along * math.cos(ang)
        cy = (y0 + y1) / 2.0 - WALL_HALF * math.cos(ang) + along * math.sin(ang)
        group.add_shape(pycrcc.RectOBB(float(half_len[i]) + (ext0 + ext1) / 2.0, WALL_HALF, ang, cx, cy))
    return group, len(keep)


def reference_path(rmap: RoadMap, route: tuple[str, ...], start_lane: str, start_pos: float, goal_edge: str,
                   goal_pos: float, past_goal: float = PAST_GOAL, max_curvature: float | None = None,
                   edges_out: "list[str] | None" = None) -> np.ndarray:
    """(n, 2) the reference path [m], 1 m apart: the reference ADS's lane plan along the route, then on
    along the road past the goal (the straightest connection at each junction, straight on at a dead
    end) until it reaches ``past_goal`` metres beyond the goal; it starts :data:`BEFORE_START` metres
    straight back behind the start; with ``max_curvature`` [1/m], smoothed by :func:`limit_curvature`.
    ``edges_out`` receives the normal edges it runs along."""
    route = lawful_route(rmap, tuple(route), start_lane)
    edges = list(route)
    path, _ = build_path(rmap, route, start_lane, start_pos, goal_edge, goal_pos)
    pts = [path.pts]
    goal_lane = rmap.drive_lane(goal_edge)
    gx, gy, _ = rmap.geom(goal_lane).position(goal_pos)
    end = path.pts[-1]
    # which lane the path ends on: the goal edge's lane nearest to its last point
    lanes = [l for l in rmap.edge(goal_edge).getLanes() if l.allows(PASSENGER)]
    lane = min(lanes, key=lambda l: abs(rmap.geom(l.getID()).project(*end)[1]))
    pos = rmap.geom(lane.getID()).project(*end)[0]
    have = (path.s[-1] - path.locate(gx, gy, hint=0, window=len(path.pts))[1])
    tail = rmap.geom(lane.getID())
    if pos < tail.length - 0.5:
        pts.append(tail.positions(np.append(np.arange(pos + 1.0, tail.length, 1.0), tail.length)))
        have += tail.length - pos
    seen = {lane.getID()}
    while have < past_goal:
        nxt = _straightest(lane)
        if nxt is None or nxt[1].getID() in seen:
            break
        via, lane = nxt
        seen.add(lane.getID())
        edges.append(lane.getEdge().getID())
        for v in ([] if not via else rmap.internal_chain(via)):
            vp = np.asarray(rmap.lane(v).getShape(), dtype=float)[:, :2]
            pts.append(vp)
            have += float(np.hypot(*np.diff(vp, axis=0).T).sum())
        lp = rmap.geom(lane.getID()).pts
        pts.append(lp)
        have += float(rmap.geom(lane.getID()).cum[-1])
    out = _dedup(np.vstack(pts))
    d = out[0] - out[1]
    d = d / (np.hypot(*d) or 1.0)
    out = np.vstack([out[0] + d * np.arange(BEFORE_START, 0.0, -1.0)[:, None], out])
    if have < past_goal:  # a dead end: straight on
        d = out[-1] - out[-2]
        d = d / (np.hypot(*d) or 1.0)
        extra = past_goal - have + 1.0
        out = np.vstack([out, out[-1] + d * np.arange(1.0, extra + 1.0)[:, None]])
    out = _within_a_turn(_resample(out, 1.0), gx, gy, past_goal)
    if edges_out is not None:
        edges_out.extend(edges)
    return out if max_curvature is None else _resample(limit_curvature(out, max_curvature), 1.0)


def _within_a_turn(pts: np.ndarray, gx: float, gy: float, past_goal: float) -> np.ndarray:
    """``pts`` (1 m apart), its part past the goal cut where its heading has turned beyond +-(2 pi - 0.5)
    (the curvilinear frame refuses orientations outside +-2 pi: a continuation round a roundabout after
    the goal did) and continued straight on instead, still ``past_goal`` metres past the goal."""
    d = np.diff(pts, axis=0)
    theta = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    out_of = np.flatnonzero(np.abs(theta) > 2.0 * math.pi - 0.5)
    i_goal = int(np.argmin(np.hypot(pts[:, 0] - gx, pts[:, 1] - gy)))
    if len(out_of) == 0 or out_of[0] <= i_goal + 2:
        return pts  # within the limit, or beyond it before the goal (the planner cannot be set up then)
    cut = pts[: out_of[0]]
    u = (cut[-1] - cut[-2]) / (np.hypot(*(cut[-1] - cut[-2])) or 1.0)
    extra = max(past_goal - (len(cut) - 1 - i_goal), 0.0)
    return np.vstack([cut, cut[-1] + u * np.arange(1.0, extra + 1.0)[:, None]])


def curvature(pts: np.ndarray) -> np.ndarray:
    """[1/m] per point, of the circle through the points two before and two after it (0 at the ends)."""
    k = np.zeros(len(pts))
    if len(pts) < 5:
        return k
    a, b, c = pts[:-4], pts[2:-2], pts[4:]
    ab, bc, ca = np.hypot(*(b - a).T), np.hypot(*(c - b).T), np.hypot(*(a - c).T)
    cross = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    k[2:-2] = 2.0 * np.abs(cross) / np.maximum(ab * bc * ca, 1e-9)
    return k


def limit_curvature(pts: np.ndarray, max_curvature: float, passes: int = 400) -> np.ndarray:
    """``pts`` (1 m apart) with every bend opened to at most ``max_curvature`` [1/m]: local Laplacian
    smoothing of the points within 4 m of a bend that is too tight, pass after pass, then two more
    passes there (they even out the change of curvature). The road's other points stay where they were;
    the bend moves inwards by what the wider radius needs (0.8 m at the town's and the intersection's
    tightest turns, 1.1 m at the interchange's)."""
    p = pts.copy()
    near, extra = None, 0
    for _ in range(passes):
        bad = curvature(p) > max_curvature
        if bad.any():
            near = np.convolve(bad.astype(float), np.ones(9), mode="same") > 0
            near[:3] = near[-3:] = False
        elif near is None or extra == 2:
            break
        else:
            extra += 1
        q = p.copy()
        q[1:-1] += 0.5 * ((p[:-2] + p[2:]) / 2.0 - p[1:-1])
        p[near] = q[near]
    return p


def _straightest(lane):
    """(via lane id or '', next lane) of the connection out of ``lane`` that turns least, or None."""
    best, best_turn = None, math.inf
    shape = lane.getShape()
    h0 = math.atan2(shape[-1][1] - shape[-2][1], shape[-1][0] - shape[-2][0])
    for conn in lane.getOutgoing():
        to = conn.getToLane()
        if not to.allows(PASSENGER):
            continue
        s = to.getShape()
        h1 = math.atan2(s[1][1] - s[0][1], s[1][0] - s[0][0])
        turn = abs((h1 - h0 + math.pi) % (2 * math.pi) - math.pi)
        if turn < best_turn - 1e-9:
            best, best_turn = (conn.getViaLaneID() or "", to), turn
    return best


def _dedup(pts: np.ndarray) -> np.ndarray:
    keep = np.concatenate([[True], np.hypot(*np.diff(pts, axis=0).T) > 0.05])
    return pts[keep]


def _resample(pts: np.ndarray, step: float) -> np.ndarray:
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    s = np.append(np.arange(0.0, cum[-1], step), cum[-1])
    return np.stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])], axis=1)


def as_path(pts: np.ndarray) -> Path:
    """The points as an :class:`ego.planning.Path` (for locating the car and other points on it)."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    return Path(pts, s, np.zeros(len(pts)))


#: The prediction modes of :func:`predictions` (the type of the adapter's option ``prediction``).
Prediction = Literal["constant_velocity", "constant_acceleration"]
PREDICTIONS = get_args(Prediction)
#: [m/s^2] a predicted vehicle's acceleration is clamped to ``-MAX_DECEL .. MAX_ACCEL`` (full braking on
#: dry asphalt; a strong car's acceleration) ...
MAX_DECEL = 9.0
MAX_ACCEL = 4.0
#: [rad/s] ... its yaw rate to this, and to what :data:`MAX_LAT_ACCEL` [m/s^2] allows at its speed
MAX_YAW_RATE = 0.6
MAX_LAT_ACCEL = 4.0
#: integration steps per planner time step of a predicted motion with acceleration or yaw rate
SUBSTEPS = 4


class Tracks:
    """Per road-user id, its speed and heading at the previous planning cycle, and from them its
    acceleration [m/s^2] and yaw rate [rad/s] now: the change between the two cycles over the time between
    them, clamped by :func:`clamp_motion`. A road user first seen now (or after a gap) gets 0 and 0. The
    memory forgets everything when time goes back (a new mission on the same ADS)."""

    def __init__(self) -> None:
        self.t = -math.inf
        self.last: dict[str, tuple[float, float]] = {}

    def update(self, obs: Observation) -> dict[str, tuple[float, float]]:
        """(acceleration, yaw rate) per id of ``obs.objects``; remembers their speed and heading for the next call."""
        dt = obs.t - self.t
        if dt <= 0.0:
            self.last = {}
        out = {}
        for o in obs.objects:
            prev = self.last.get(o.id)
            if prev is None:
                out[o.id] = (0.0, 0.0)
                continue
            v0, h0 = prev
            dh = (o.heading - h0 + math.pi) % (2.0 * math.pi) - math.pi
            out[o.id] = clamp_motion(o.speed, (o.speed - v0) / dt, dh / dt)
        self.t = obs.t
        self.last = {o.id: (o.speed, o.heading) for o in obs.objects}
        return out


def clamp_motion(speed: float, accel: float, yaw_rate: float) -> tuple[float, float]:
    """(acceleration, yaw rate) within what a car can do: :data:`MAX_DECEL`, :data:`MAX_ACCEL`,
    :data:`MAX_YAW_RATE` and :data:`MAX_LAT_ACCEL` at ``speed`` [m/s]."""
    accel = min(max(accel, -MAX_DECEL), MAX_ACCEL)
    w_max = min(MAX_YAW_RATE, MAX_LAT_ACCEL / max(speed, 0.1))
    return accel, min(max(yaw_rate, -w_max), w_max)


def motion(x: float, y: float, heading: float, speed: float, accel: float, yaw_rate: float, steps: int,
           dt: float) -> np.ndarray:
    """(steps + 1, 3) x [m], y [m], heading [rad] at time steps ``0..steps`` (``dt`` seconds apart) of a body
    moving on with constant ``accel`` [m/s^2] and ``yaw_rate`` [rad/s] (both stop once it stands: it never
    goes backwards), integrated by the midpoint rule in :data:`SUBSTEPS` pieces per step; with both 0 the
    exact straight line at ``speed``."""
    out = np.empty((steps + 1, 3))
    if accel == 0.0 and yaw_rate == 0.0:
        t = np.arange(steps + 1) * dt
        out[:, 0] = x + speed * math.cos(heading) * t
        out[:, 1] = y + speed * math.sin(heading) * t
        out[:, 2] = heading
        return out
    h = dt / SUBSTEPS
    v = speed
    out[0] = x, y, heading
    for k in range(1, steps + 1):
        for _ in range(SUBSTEPS):
            v1 = max(v + accel * h, 0.0)
            if v1 == 0.0 and accel < 0.0:  # it stops within this piece: it covers v^2 / 2|a|
                dist, dturn = v * v / (-2.0 * accel), yaw_rate * v / -accel if v > 0.0 else 0.0
            else:
                dist, dturn = (v + v1) / 2.0 * h, yaw_rate * h if v1 > 0.0 or v > 0.0 else 0.0
            hm = heading + dturn / 2.0
            x += dist * math.cos(hm)
            y += dist * math.sin(hm)
            heading += dturn
            v = v1
        out[k] = x, y, heading
    return out


def predictions(obs: Observation, steps: int, dt: float, reach: float, mode: str = "constant_velocity",
                tracks: "Tracks | None" = None):
    """One ``pycrcc.TimeVariantCollisionObject`` per road user within ``reach`` metres of the ego: its
    box at time steps ``0..steps`` (``dt`` seconds apart). ``constant_velocity``: moving on at its current
    speed and heading; ``constant_acceleration``: a vehicle with the acceleration and yaw rate ``tracks``
    (updated here, once per planning cycle) reads for it (pedestrians, whose SUMO heading turns at every
    walking-area corner, stay at constant velocity)."""
    if mode not in PREDICTIONS:
        raise ValueError(f"prediction {mode!r}: expected one of {', '.join(PREDICTIONS)}")
    rates = tracks.update(obs) if mode == "constant_acceleration" and tracks is not None else {}
    out = []
    ex, ey = obs.ego.x, obs.ego.y
    for o in obs.objects:
        if abs(o.x - ex) > reach or abs(o.y - ey) > reach:
            continue
        accel, yaw_rate = rates.get(o.id, (0.0, 0.0)) if o.kind == "vehicle" else (0.0, 0.0)
        track = motion(o.x, o.y, o.heading, o.speed, accel, yaw_rate, steps, dt)
        tvo = pycrcc.TimeVariantCollisionObject(0)
        hl, hw = o.length / 2.0, o.width / 2.0
        for x, y, h in track.tolist():
            tvo.append_obstacle(pycrcc.RectOBB(hl, hw, h, x, y))
        out.append(tvo)
    return out


def stop_wall(obs: Observation, path: Path, s_front: float) -> tuple[float, float, float] | None:
    """(x, y, heading) of the wall's centre when the next light on the route is red, or yellow with room
    to stop at :data:`YELLOW_DECEL`; None otherwise. ``s_front``: the front bumper's arc length on ``path``."""
    tl = obs.traffic_light
    if tl is None or tl.state not in "rRyYu" or tl.distance > 150.0:
        return None
    v = obs.ego.speed
    if tl.state in "yY" and tl.distance < v * v / (2.0 * YELLOW_DECEL):
        return None  # too close to stop comfortably on yellow: go
    s_wall = s_front + tl.distance + STOP_WALL_HALF_DEPTH
    x, y = path.point_at(s_wall)
    x1, y1 = path.point_at(s_wall + 1.0)
    x0, y0 = path.point_at(s_wall - 1.0)
    return x, y, math.atan2(y1 - y0, x1 - x0)


def wall_shape(wall: tuple[float, float, float]):
    x, y, h = wall
    return pycrcc.RectOBB(STOP_WALL_HALF_DEPTH, STOP_WALL_HALF_WIDTH, h, x, y)


def stop_speed(dist: float, decel: float, margin: float = 0.0) -> float:
    """[m/s] the speed from which the car stops ``margin`` metres short of a point ``dist`` metres ahead,
    braking at ``decel`` [m/s^2] (0 once there)."""
    d = dist - margin
    return math.sqrt(2.0 * decel * d) if d > 0.0 else 0.0
