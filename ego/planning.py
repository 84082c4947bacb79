"""Planning: a reference path along the route (with the lane changes it needs) and a target speed.

The path is a dense polyline through the lanes of the route and the junction
lanes between them. The lanes come from :func:`lane_plan`, which looks ahead
along the whole route: where the lane the car is on does not lead on, the path
shifts (over the middle of the edge) to the nearest lane that does and that can
be reached without crossing a solid line, so a lane needed after an edge where
changing is forbidden is taken before that edge. If the start lane cannot reach
such a lane at all, :func:`lawful_route` drives another way to the goal.
The speed plan is an intelligent-driver-model acceleration towards the lowest
of: the speed limit, a curvature limit, the speed from which the car can stop
within what it sees, the leader, a red light's stop line, a pedestrian in the
path, and the goal.

The curvature limit is a :func:`speed_profile` along the path, computed once per
mission: at every path point the highest speed [m/s] from which the car can slow
down, at a comfortable deceleration, to the curvature limit of every point after
it. It depends on the distance along the path only, never on the car's speed, so
the target speed cannot flip between frames as the car slows (a look-ahead window
of ``3 v`` metres did: a tight bend dropped in and out of it on alternate frames).
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from drivefuzz.scenario.roadmap import PASSENGER, RoadMap


#: Cell size [m] of a path's point grid: every path point within this distance of a query is found.
CELL = 5.0


class Path:
    """A dense polyline (points about 1 m apart) with its arc length and curvature.

    Look-ups run every step for the car and for every object near it, so besides the arrays
    the path keeps its points as Python lists and in a grid of :data:`CELL` cells: a query
    near the path costs a few dozen float operations instead of a numpy call. Assign
    ``pts`` (rather than writing into the array) to move the path: that rebuilds both.
    """

    def __init__(self, pts: np.ndarray, s: np.ndarray, curvature: np.ndarray):
        self.s = s  # (n,) arc length [m]
        self.curvature = curvature  # (n,) [1/m]
        self.pts = pts  # (n, 2) [m]

    @property
    def pts(self) -> np.ndarray:
        return self._pts

    @pts.setter
    def pts(self, pts: np.ndarray) -> None:
        self._pts = pts
        self._xy = pts.tolist()
        self._s = self.s.tolist()
        # every point is listed in its cell and the eight around it, so one look-up finds all
        # points within CELL of a query (in index order)
        grid: dict[tuple[int, int], list[int]] = {}
        for i, (x, y) in enumerate(self._xy):
            cx, cy = math.floor(x / CELL), math.floor(y / CELL)
            for gx in (cx - 1, cx, cx + 1):
                for gy in (cy - 1, cy, cy + 1):
                    grid.setdefault((gx, gy), []).append(i)
        self._grid = grid

    def _nearest(self, x: float, y: float, lo: int, hi: int) -> tuple[int, float] | None:
        """(index, squared distance) of the first closest point in ``lo..hi``, if it is within
        :data:`CELL` (then it is also the closest of all points in ``lo..hi``), else None."""
        idx = self._grid.get((math.floor(x / CELL), math.floor(y / CELL)))
        if idx is None:
            return None
        xy = self._xy
        best, best_d2 = -1, CELL * CELL
        # ascending: the first of equally close points wins, as with argmin
        for k in range(bisect.bisect_left(idx, lo), bisect.bisect_right(idx, hi)):
            i = idx[k]
            px, py = xy[i]
            d2 = (px - x) * (px - x) + (py - y) * (py - y)
            if d2 < best_d2:
                best, best_d2 = i, d2
        return (best, best_d2) if best >= 0 else None

    def window(self, hint: int, window: int) -> tuple[int, int]:
        """The index range ``lo..hi`` that :meth:`locate` searches around ``hint``."""
        return max(hint - 10, 0), min(hint + window, len(self._xy) - 1)

    def _project(self, i: int, x: float, y: float) -> tuple[float, float]:
        j = min(i, len(self._xy) - 2)
        (x0, y0), (x1, y1) = self._xy[j], self._xy[j + 1]
        dx, dy = x1 - x0, y1 - y0
        seglen = math.hypot(dx, dy) or 1e-9
        along = ((x - x0) * dx + (y - y0) * dy) / seglen
        lat = (dx * (y - y0) - dy * (x - x0)) / seglen
        return self._s[j] + along, lat

    def locate(self, x: float, y: float, hint: int, window: int = 60) -> tuple[int, float, float]:
        """(index, s [m], lateral offset [m, left +]) of the closest path point near ``hint``."""
        lo, hi = self.window(hint, window)
        near = self._nearest(x, y, lo, hi)
        if near is not None:
            i = near[0]
        else:  # farther than a cell from the path: search the whole window
            seg = self.pts[lo:hi + 1]
            i = lo + int(np.argmin((seg[:, 0] - x) ** 2 + (seg[:, 1] - y) ** 2))
        s, lat = self._project(i, x, y)
        return i, s, lat

    def locate_near(self, x: float, y: float, lo: int, hi: int) -> tuple[float, float] | None:
        """(s [m], lateral offset [m, left +]) as :meth:`locate` with the window ``lo..hi``
        (:meth:`window`), for a point within :data:`CELL` of one of those path points; None
        for a point farther away."""
        near = self._nearest(x, y, lo, hi)
        return None if near is None else self._project(near[0], x, y)

    def point_at(self, s: float) -> tuple[float, float]:
        """The point at arc length ``s`` [m] (clamped to the path)."""
        ss = self._s
        if s <= 0.0:
            return tuple(self._xy[0])
        if s >= ss[-1]:
            return tuple(self._xy[-1])
        j = bisect.bisect_right(ss, s) - 1
        (x0, y0), (x1, y1) = self._xy[j], self._xy[j + 1]
        f = (s - ss[j]) / ((ss[j + 1] - ss[j]) or 1e-9)
        return x0 + f * (x1 - x0), y0 + f * (y1 - y0)


def _resample(pts: np.ndarray, step: float = 1.0) -> np.ndarray:
    seg = np.hypot(*(pts[1:] - pts[:-1]).T)
    keep = np.concatenate([[True], seg > 1e-6])
    pts = pts[keep]
    if len(pts) < 2:
        return pts
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*(pts[1:] - pts[:-1]).T))])
    n = max(int(cum[-1] / step), 1)
    s = np.linspace(0.0, cum[-1], n + 1)
    return np.stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])], axis=1)


def _lane_points(rmap: RoadMap, lane_id: str, s0: float, s1: float) -> np.ndarray:
    return rmap.geom(lane_id).positions(np.append(np.arange(s0, s1, 1.0), s1))


def _change_path(rmap: RoadMap, frm: str, to: str) -> bool:
    """Passenger cars may change, lane by lane, from ``frm`` to ``to`` (same edge) without a solid line."""
    return rmap.may_change_to(frm, to)


def lane_plan(rmap: RoadMap, route: tuple[str, ...]) -> list[set[str]]:
    """Per route edge, the lanes from which the rest of the route can be driven without ever
    changing lanes across a forbidden boundary (SUMO's ``changeLeft``/``changeRight``).

    Computed backwards: on the last edge every car lane will do; on an earlier edge, a lane
    qualifies when it connects to a lane of the next edge from which a qualifying lane can be
    reached by permitted changes. An empty set means the route cannot be driven lawfully
    from anywhere on that edge (the planner then falls back to any connecting lane).
    """
    n = len(route)
    good: list[set[str]] = [set() for _ in route]
    good[-1] = {l.getID() for l in rmap.edge(route[-1]).getLanes() if l.allows(PASSENGER)}
    for i in range(n - 2, -1, -1):
        nxt = {l.getID() for l in rmap.edge(route[i + 1]).getLanes() if l.allows(PASSENGER)}
        reach = {l for l in nxt if any(_change_path(rmap, l, g) for g in good[i + 1])}
        good[i] = {c[0] for c in rmap.connections(route[i], route[i + 1]) if c[1] in reach}
    return good


def lawful_route(rmap: RoadMap, route: tuple[str, ...], start_lane: str) -> tuple[str, ...]:
    """``route``, or when it cannot be driven from ``start_lane`` without crossing a solid line
    (the lane it needs is behind one), the shortest route to the same goal that can."""
    if len(route) < 2:
        return route
    plan = lane_plan(rmap, route)
    if any(_change_path(rmap, start_lane, lane) for lane in plan[0]):
        return route
    start, goal = route[0], route[-1]
    best, best_len = route, math.inf
    for lane in rmap.edge(start).getLanes():
        if not lane.allows(PASSENGER) or not _change_path(rmap, start_lane, lane.getID()):
            continue
        for conn in lane.getOutgoing():
            nxt = conn.getToLane().getEdge().getID()
            rest = rmap.route(nxt, goal) if rmap.is_normal_edge(conn.getToLane().getEdge()) else None
            if not rest or start in rest:
                continue
            cand = (start,) + rest
            length = rmap.route_length(cand)
            if length < best_len and any(_change_path(rmap, start_lane, l) for l in lane_plan(rmap, cand)[0]):
                best, best_len = cand, length
    return best


def build_path(rmap: RoadMap, route: tuple[str, ...], start_lane: str, start_pos: float,
               goal_edge: str, goal_pos: float) -> tuple[Path, dict[str, float]]:
    """The reference path and the path coordinate [m] where each route edge starts.

    The lanes come from :func:`lane_plan`: on every edge the path changes (over the middle
    of the edge) to the nearest lane that both can be reached without crossing a solid line
    and leads on along the route, so a lane the route needs is taken before an edge where
    changing is forbidden.
    """
    pieces: list[np.ndarray] = []
    edge_s: dict[str, float] = {}
    plan = lane_plan(rmap, route)
    cur_lane = start_lane
    total = 0.0
    for i, edge in enumerate(route):
        last = i == len(route) - 1
        lane_len = rmap.geom(cur_lane).length
        a = max(start_pos - 8.0, 0.0) if i == 0 else 0.0
        b = min(goal_pos + 40.0, lane_len) if last else lane_len
        conns = [] if last else [c for c in rmap.connections(edge, route[i + 1])
                                 if rmap.lane(c[1]).allows(PASSENGER)]
        target = cur_lane
        if conns and cur_lane not in plan[i]:
            cur_idx = rmap.lane(cur_lane).getIndex()
            lawful = [l for l in plan[i] if _change_path(rmap, cur_lane, l)]
            # best effort where no lawful lane is reachable (e.g. a start lane behind a solid line)
            options = lawful or sorted(plan[i]) or sorted({c[0] for c in conns})
            if cur_lane not in options:
                target = min(sorted(options), key=lambda l: abs(rmap.lane(l).getIndex() - cur_idx))
        edge_s[edge] = total - a if i == 0 else total
        if target == cur_lane:
            piece = _lane_points(rmap, cur_lane, a, b)
        else:  # lane change over the middle third of the remaining edge
            g0, g1 = rmap.geom(cur_lane), rmap.geom(target)
            s = np.append(np.arange(a, b, 1.0), b)
            m0, m1 = a + (b - a) * 0.25, a + (b - a) * 0.65
            w = np.clip((s - m0) / max(m1 - m0, 1e-6), 0.0, 1.0)
            w = (w * w * (3 - 2 * w))[:, None]
            piece = (1 - w) * g0.positions(s) + w * g1.positions(np.minimum(s, g1.length))
            cur_lane = target
        pieces.append(piece)
        total += float(np.hypot(*(piece[1:] - piece[:-1]).T).sum()) if len(piece) > 1 else 0.0
        if conns:
            mine = [c for c in conns if c[0] == cur_lane] or conns
            # into a lane that needs no further change if there is one, else one that can change lawfully
            nxt_good = plan[i + 1]
            conn = next((c for c in mine if c[1] in nxt_good), None)
            if conn is None:
                conn = next((c for c in mine if any(_change_path(rmap, c[1], g) for g in nxt_good)), mine[0])
            if conn[2]:
                for via in rmap.internal_chain(conn[2]):
                    vp = np.asarray(rmap.lane(via).getShape(), dtype=float)[:, :2]
                    pieces.append(vp)
                    total += float(np.hypot(*(vp[1:] - vp[:-1]).T).sum())
            cur_lane = conn[1]
    pts = _resample(np.vstack(pieces), 1.0)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*(pts[1:] - pts[:-1]).T))])
    head = np.unwrap(np.arctan2(*(np.diff(pts, axis=0)[:, ::-1].T)))
    curv = np.zeros(len(pts))
    if len(head) > 2:
        dk = np.abs(np.diff(head)) / np.maximum(np.diff(s[:-1]), 1e-6)
        k = np.convolve(dk, np.ones(5) / 5, mode="same")
        curv[1:-1] = k
    return Path(pts, s, curv), edge_s


def speed_profile(path: Path, max_lat_accel: float, decel: float, lead_m: float = 0.0,
                  v_max: float = 100.0) -> list[float]:
    """Per path point, the highest speed [m/s] that respects the curvature limit
    ``sqrt(max_lat_accel / curvature)`` of every point up to ``lead_m`` metres ahead (the path
    tracker steers towards a point ahead, so the car turns before its centre reaches the bend)
    and, braking at ``decel`` [m/s^2], of every later point (a backward pass; ``v_max`` [m/s]
    where the path is straight)."""
    k = path.curvature.tolist()
    s = path.s.tolist()
    n = len(k)
    k_min = max_lat_accel / (v_max * v_max)
    lim = [math.sqrt(max_lat_accel / ki) if ki > k_min else v_max for ki in k]
    prof = [v_max] * n
    nxt = v_max
    j = n - 1  # the window i..j holds the points within lead_m of point i
    window: list[int] = []  # indices of a monotone (increasing limit) queue over the window
    for i in range(n - 1, -1, -1):
        while j > i and s[j] - s[i] > lead_m:
            if window and window[0] == j:
                window.pop(0)
            j -= 1
        while window and lim[window[-1]] >= lim[i]:
            window.pop()
        window.append(i)
        if i < n - 1:
            nxt = math.sqrt(nxt * nxt + 2.0 * decel * (s[i + 1] - s[i]))
        nxt = min(lim[window[0]], nxt)
        prof[i] = nxt
    return prof


def profile_accel(prof: list[float], path: Path, i: int, v: float, horizon: float) -> float:
    """Acceleration [m/s^2] that brings speed ``v`` [m/s] at path point ``i`` down to the profile
    ``prof`` (:func:`speed_profile`) ``horizon`` metres ahead; +inf when the car is below it there."""
    s = path._s
    j = min(bisect.bisect_left(s, s[i] + horizon, i), len(s) - 1)
    target = prof[j]
    if target >= v or j == i:
        return math.inf
    return (target * target - v * v) / (2.0 * (s[j] - s[i]))


def assured_clear_speed(clear_m: float, decel: float, reaction_s: float) -> float:
    """[m/s] the highest speed from which the car stops within ``clear_m`` metres: ``reaction_s``
    seconds at that speed, then braking at ``decel`` [m/s^2] (0 when ``clear_m <= 0``)."""
    if clear_m <= 0.0:
        return 0.0
    return decel * (-reaction_s + math.sqrt(reaction_s * reaction_s + 2.0 * clear_m / decel))


def idm_accel(v: float, v0: float, gap: float, dv: float, a_max: float = 2.0, b: float = 3.0,
              s0: float = 2.5, T: float = 1.2) -> float:
    """Intelligent-driver-model acceleration [m/s^2]; gap [m] to an obstacle closing at dv [m/s]."""
    free = 1.0 - (v / max(v0, 0.1)) ** 4 if v0 > 0.1 else -v
    if not math.isfinite(gap):
        return a_max * free
    s_star = s0 + max(0.0, v * T + v * dv / (2.0 * math.sqrt(a_max * b)))
    return a_max * (free - (s_star / max(gap, 0.1)) ** 2)


def stop_accel(v: float, dist: float, comfort: float = 3.0) -> float:
    """Deceleration [m/s^2] (< 0) to stop within ``dist`` metres; +inf (no constraint) while far away."""
    if dist <= 0.3:
        # at the stop point: brake fully if still moving fast (an overshoot), else just settle
        # (a creep of ~0.3 m/s is stopped within centimetres without a jolt)
        if v > 1.0:
            return -8.0
        return -2.5 if v > 0.05 else -1.0
    need = v * v / (2.0 * dist)
    if need > 0.3 * comfort:
        return -need * 1.1
    # close to the stop point and slow: creep up to it instead of stopping short
    return min(0.5, 0.5 * (dist - 0.5)) if dist < 8.0 else math.inf
