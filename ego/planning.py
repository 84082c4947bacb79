"""Planning: a reference path along the route (with the lane changes it needs) and a target speed.

The path is a dense polyline through the lanes of the route and the junction
lanes between them. Where the lane the car arrives on does not continue to the
next edge, the path shifts to a lane that does over the middle of the edge.
The speed plan is an intelligent-driver-model acceleration towards the lowest
of: the speed limit, a curvature limit, the leader, a red light's stop line,
a pedestrian in the path, and the goal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivefuzz.roadmap import PASSENGER, RoadMap


@dataclass
class Path:
    pts: np.ndarray  # (n, 2)
    s: np.ndarray  # (n,) arc length [m]
    curvature: np.ndarray  # (n,) [1/m]

    def locate(self, x: float, y: float, hint: int, window: int = 60) -> tuple[int, float, float]:
        """(index, s [m], lateral offset [m, left +]) of the closest path point near ``hint``."""
        lo, hi = max(hint - 10, 0), min(hint + window, len(self.pts) - 1)
        seg = self.pts[lo:hi + 1]
        d2 = (seg[:, 0] - x) ** 2 + (seg[:, 1] - y) ** 2
        i = lo + int(np.argmin(d2))
        j = min(i, len(self.pts) - 2)
        dx, dy = self.pts[j + 1] - self.pts[j]
        seglen = math.hypot(dx, dy) or 1e-9
        along = ((x - self.pts[j, 0]) * dx + (y - self.pts[j, 1]) * dy) / seglen
        lat = (dx * (y - self.pts[j, 1]) - dy * (x - self.pts[j, 0])) / seglen
        return i, float(self.s[j] + along), float(lat)

    def point_at(self, s: float) -> tuple[float, float]:
        s = min(max(s, 0.0), float(self.s[-1]))
        return float(np.interp(s, self.s, self.pts[:, 0])), float(np.interp(s, self.s, self.pts[:, 1]))


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
    g = rmap.geom(lane_id)
    s = np.arange(s0, s1, 1.0).tolist() + [s1]
    return np.array([g.position(v)[:2] for v in s])


def build_path(rmap: RoadMap, route: tuple[str, ...], start_lane: str, start_pos: float,
               goal_edge: str, goal_pos: float) -> tuple[Path, dict[str, float]]:
    """The reference path and the path coordinate [m] where each route edge starts."""
    pieces: list[np.ndarray] = []
    edge_s: dict[str, float] = {}
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
        if conns and all(c[0] != cur_lane for c in conns):
            cur_idx = rmap.lane(cur_lane).getIndex()
            target = min((c[0] for c in conns), key=lambda l: abs(rmap.lane(l).getIndex() - cur_idx))
        edge_s[edge] = total - a if i == 0 else total
        if target == cur_lane:
            piece = _lane_points(rmap, cur_lane, a, b)
        else:  # lane change over the middle third of the remaining edge
            g0, g1 = rmap.geom(cur_lane), rmap.geom(target)
            s = np.arange(a, b, 1.0).tolist() + [b]
            m0, m1 = a + (b - a) * 0.25, a + (b - a) * 0.65
            rows = []
            for v in s:
                w = min(max((v - m0) / max(m1 - m0, 1e-6), 0.0), 1.0)
                w = w * w * (3 - 2 * w)
                p0, p1 = g0.position(v)[:2], g1.position(min(v, g1.length))[:2]
                rows.append(((1 - w) * p0[0] + w * p1[0], (1 - w) * p0[1] + w * p1[1]))
            piece = np.array(rows)
            cur_lane = target
        pieces.append(piece)
        total += float(np.hypot(*(piece[1:] - piece[:-1]).T).sum()) if len(piece) > 1 else 0.0
        if conns:
            conn = next(c for c in conns if c[0] == cur_lane)
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
        return -8.0 if v > 0.05 else -1.0
    need = v * v / (2.0 * dist)
    if need > 0.3 * comfort:
        return -need * 1.1
    # close to the stop point and slow: creep up to it instead of stopping short
    return min(0.5, 0.5 * (dist - 0.5)) if dist < 8.0 else math.inf
