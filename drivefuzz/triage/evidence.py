"""Evidence for attribution and signatures: what the frozen trace and the road map say about one event.

Read by :mod:`drivefuzz.triage.attribute` (its rules) and :mod:`drivefuzz.triage.signature`:
other parties' tracks, where a contact is on the ego, where the other came from, the ego's red
lights and lane changes, junction links and their signals and right of way (SUMO's connections,
link states, response bits and fixed-time programs), when a pedestrian entered the ego's path and
became visible. What stands in the ego's way (blocked lanes, queues, slower traffic) is in
:mod:`drivefuzz.triage.blockage`. Nothing here gives a verdict.

Units: SI; positions are body centres; headings radians ENU (as in the trace).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from drivefuzz.geometry import corners
from drivefuzz.scenario.model import EGO_LENGTH, EGO_WIDTH, lane_edge

#: [m/s^2] braking a following driver must expect; harder braking needs a hazard ahead.
COMFORT_DECEL = 3.5
#: [m/s] at or below this the ego counts as stationary.
STATIONARY_SPEED = 0.1
#: [s] reaction (perception + actuation) before the brakes act.
REACTION_TIME = 0.3
#: [m/s^2] the car's full braking when grip allows (drivefuzz.sim.physics.VehicleParams.max_brake_decel).
MAX_BRAKE = 9.0
G = 9.81  #: [m/s^2]
#: [s] a lane change this recent makes a rear-end the ego's cut-in, not the follower's fault.
LANE_CHANGE_WINDOW = 3.0
#: [s] how long a body must have stood still to block a lane.
STILL_FOR = 5.0
#: Signal states that mean stop.
RED = frozenset("rRu")
# ---------------------------------------------------------------------- the event
@dataclass
class Track:
    """One actor's states by frame (NaN where it was absent)."""

    id: str
    kind: str  # "vehicle" | "pedestrian"
    length: float
    width: float
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray

    def present(self, f: int) -> bool:
        return 0 <= f < len(self.x) and not math.isnan(self.x[f])


def actor_track(trace, actor_id: str) -> Track | None:
    """The per-frame states of ``actor_id``, or None if the trace never saw it."""
    a = trace.actors
    if actor_id not in a.ids:
        return None
    j = a.ids.index(actor_id)
    rows = a.actor == j
    n = trace.n_frames
    out = [np.full(n, np.nan) for _ in range(4)]
    fr = a.frame[rows]
    for arr, src in zip(out, (a.x, a.y, a.heading, a.speed)):
        arr[fr] = src[rows]
    return Track(actor_id, a.kinds[j], float(a.length[j]), float(a.width[j]), *out)


def to_local(trace, f: int, x: float, y: float) -> tuple[float, float]:
    """(forward, left) [m] of (x, y) in the ego's body frame at frame ``f``."""
    ex, ey, h = float(trace["x"][f]), float(trace["y"][f]), float(trace["heading"][f])
    dx, dy = x - ex, y - ey
    c, s = math.cos(h), math.sin(h)
    return dx * c + dy * s, -dx * s + dy * c


#: [s] of the ego's path, before and after the moment, along which :func:`along_path` reads a place
PATH_S = 10.0
#: [m] the path runs on straight beyond its ends
PATH_RUN_M = 50.0


def along_path(trace, k: int, x: float, y: float, heading: bool = False) -> tuple[float, ...]:
    """(forward, left) [m] of (x, y) from the ego at frame ``k``, along the path it drives from
    :data:`PATH_S` s before ``k`` to as long after (straight on beyond either end) and off it. In the body frame,
    a car ahead in the ego's lane on a bend, or on the lane its turn leads into, is beside it (a roundabout's ring
    turns left: the car ahead on it read as ``vehicle/left``); on the path it is ahead. With ``heading``, also the
    path's heading [rad] at the point nearest (x, y): the ego's way there."""
    span = int(round(PATH_S / trace.step_length))
    lo, hi = max(k - span, 0), min(k + span, trace.n_frames - 1)
    px = np.asarray(trace["x"][lo:hi + 1], dtype=float)
    py = np.asarray(trace["y"][lo:hi + 1], dtype=float)
    ok = np.isfinite(px) & np.isfinite(py)
    if ok.sum() < 2:
        return (*to_local(trace, k, x, y), float(trace["heading"][k])) if heading else to_local(trace, k, x, y)
    idx = np.flatnonzero(ok)
    px, py = px[idx], py[idx]
    keep = np.concatenate(([True], np.hypot(np.diff(px), np.diff(py)) > 0.05))  # standing still: one point
    px, py, idx = px[keep], py[keep], idx[keep]
    ego = int(np.searchsorted(idx, k - lo, side="right")) - 1  # the path point the ego is at (or last passed)
    h0, h1 = float(trace["heading"][lo + idx[0]]), float(trace["heading"][lo + idx[-1]])
    px = np.concatenate(([px[0] - PATH_RUN_M * math.cos(h0)], px, [px[-1] + PATH_RUN_M * math.cos(h1)]))
    py = np.concatenate(([py[0] - PATH_RUN_M * math.sin(h0)], py, [py[-1] + PATH_RUN_M * math.sin(h1)]))
    ego += 1
    ax, ay, bx, by = px[:-1], py[:-1], px[1:], py[1:]
    dx, dy = bx - ax, by - ay
    seg = np.hypot(dx, dy)
    u = np.clip(((x - ax) * dx + (y - ay) * dy) / np.maximum(seg * seg, 1e-12), 0.0, 1.0)
    d = np.hypot(ax + u * dx - x, ay + u * dy - y)
    i = int(np.argmin(d))
    s = np.concatenate(([0.0], np.cumsum(seg)))
    ex, ey = float(trace["x"][k]), float(trace["y"][k])
    if math.isfinite(ex + ey):  # the ego's own place on the path: its point, or between it and the next
        j = max(min(ego, len(seg) - 1), 0)
        ue = float(np.clip(((ex - ax[j]) * dx[j] + (ey - ay[j]) * dy[j]) / max(seg[j] ** 2, 1e-12), 0.0, 1.0))
        s_ego = s[j] + ue * seg[j]
    else:
        s_ego = s[ego]
    cross = dx[i] * (y - ay[i]) - dy[i] * (x - ax[i])
    out = float(s[i] + u[i] * seg[i] - s_ego), float(math.copysign(d[i], cross) if d[i] > 0 else 0.0)
    return (*out, math.atan2(dy[i], dx[i])) if heading else out


def contact_point(trace, f: int, other: Track) -> tuple[float, float] | None:
    """Where on the ego the contact is, (forward, left) [m] in its body frame at frame ``f``: the
    centroid of the overlap of the two bodies, or the ego's point nearest the other body."""
    from shapely.geometry import Polygon
    from shapely.ops import nearest_points

    if not other.present(f):
        return None
    ego = Polygon(corners(trace["x"][f], trace["y"][f], trace["heading"][f], EGO_LENGTH, EGO_WIDTH))
    oth = Polygon(corners(other.x[f], other.y[f], other.heading[f], other.length, other.width))
    inter = ego.intersection(oth)
    p = inter.centroid if inter.area > 1e-6 else nearest_points(ego, oth)[0]
    return to_local(trace, f, p.x, p.y)


def contact_side(point: tuple[float, float] | None) -> str:
    """front/rear/left/right of a body-frame contact point (by the ego's normalised extents)."""
    if point is None:
        return "none"
    u, v = point[0] / (EGO_LENGTH / 2), point[1] / (EGO_WIDTH / 2)
    if abs(u) >= abs(v):
        return "front" if u > 0 else "rear"
    return "left" if v > 0 else "right"


def approach(trace, f: int, other: Track, before: float = 2.0) -> str:
    """Where ``other`` came from relative to the ego, ``before`` seconds ahead of frame ``f`` (or when it
    first appeared): behind/ahead (travelling the ego's way, or standing), oncoming, left/right
    (crossing; the side it was on). "none" without the other."""
    k = max(f - int(round(before / trace.step_length)), 0)
    present = [j for j in range(k, f + 1) if other.present(j)]
    if not present:
        return "none"
    k = present[0]
    lx, ly = to_local(trace, k, float(other.x[k]), float(other.y[k]))
    if float(other.speed[k]) > 0.5:
        dh = abs(wrap_angle(float(other.heading[k]) - float(trace["heading"][k])))
        if dh >= 3 * math.pi / 4:
            return "oncoming"
        if dh > math.pi / 4:
            return "left" if ly > 0 else "right"
        return "ahead" if lx > 0 else "behind"
    if abs(lx) >= abs(ly):
        return "ahead" if lx > 0 else "behind"
    return "left" if ly > 0 else "right"


def frames_before(trace, f: int, seconds: float) -> slice:
    """The frames from ``seconds`` before ``f`` up to ``f`` (inclusive)."""
    return slice(max(f - int(round(seconds / trace.step_length)), 0), f + 1)


def ran_red(trace, f: int, seconds: float = 10.0) -> int | None:
    """The frame (within ``seconds`` before ``f``) at which the ego entered a junction while its light
    showed a stop state, or None."""
    lane, state, dist = trace["lane"], trace["tls_state"], trace["tls_dist"]
    w = frames_before(trace, f, seconds)
    for k in range(max(w.start, 1), w.stop):
        if str(lane[k]).startswith(":") and not str(lane[k - 1]).startswith(":") and str(state[k - 1]) in RED \
                and dist[k - 1] < 5.0:
            return k
    return None


#: [m] before the stop line over which the ego's braking for a red light is read.
RED_APPROACH_M = 40.0


@dataclass(frozen=True)
class RedApproach:
    """How the ego came to a red light it entered at frame ``f``: from the frame its light last stopped showing
    green (``onset``; the first recorded frame of this light when it showed no green before)."""

    onset: int
    state: str  # the light's state at the onset: 'y' (yellow) or a stop state
    distance: float  # [m] from the front bumper to the stop line at the onset
    speed: float  # [m/s] at the onset
    needed: float  # [m/s^2] the constant deceleration that stops the car at the line from the onset
    braked: float  # [m/s^2] its hardest deceleration over the last RED_APPROACH_M (or from the onset, if later)
    entry_speed: float  # [m/s] at the entry
    from_start: bool  # the light showed no green in the whole recorded approach

    def describe(self) -> str:
        if self.from_start:
            shown = "yellow, then red," if self.state in "yY" else "red"
            how = f"the light was {shown} all along from {self.distance:.1f} m out"
        else:
            how = (f"the light turned {'yellow' if self.state in 'yY' else 'red'} {self.distance:.1f} m out at "
                   f"{self.speed:.1f} m/s (a stop needed {self.needed:.1f} m/s^2)")
        return (f"{how}; over its last {RED_APPROACH_M:.0f} m it braked at most {self.braked:.1f} m/s^2 and "
                f"entered at {self.entry_speed:.1f} m/s")


def red_approach(trace, f: int) -> RedApproach | None:
    """The approach to the light the ego entered on red at frame ``f`` (see :class:`RedApproach`); None when
    the frame before shows no light ahead."""
    state, dist, speed = trace["tls_state"], trace["tls_dist"], trace["speed"]
    last = f - 1
    if last < 0 or str(state[last]) not in RED or not math.isfinite(float(dist[last])):
        return None
    stop_or_yellow = RED | {"y", "Y"}
    k = last
    # back while the light ahead shows yellow or a stop state and is the same light (its distance grows backwards)
    while k > 0 and str(state[k - 1]) in stop_or_yellow and math.isfinite(float(dist[k - 1])) \
            and float(dist[k - 1]) >= float(dist[k]) - 0.01:
        k -= 1
    from_start = k == 0 or not math.isfinite(float(dist[k - 1])) or str(state[k - 1]) in stop_or_yellow
    d0, v0 = float(dist[k]), float(speed[k])
    near = k
    while near < last and float(dist[near]) > RED_APPROACH_M:
        near += 1
    dv = np.diff(speed[near:f + 1]) / trace.step_length
    braked = float(max(-dv.min(), 0.0)) if len(dv) else 0.0
    return RedApproach(k, str(state[k]), d0, v0, v0 * v0 / (2.0 * max(d0, 0.1)), braked, float(speed[f]),
                       from_start)


def lane_changed(trace, f: int, seconds: float = LANE_CHANGE_WINDOW) -> bool:
    """The ego moved between lanes of one normal edge within ``seconds`` before ``f``."""
    lanes = [str(l) for l in trace["lane"][frames_before(trace, f, seconds)] if l and not str(l).startswith(":")]
    return any(a != b and lane_edge(a) == lane_edge(b) for a, b in zip(lanes, lanes[1:]))


def lateral_shift(trace, rmap, f: int, seconds: float = LANE_CHANGE_WINDOW) -> float:
    """[m] how far sideways the ego moved over ``seconds`` before ``f``, square to the lane it was on then (0 where
    it was not on one normal edge all along): a lane change under way shows before the ego's centre crosses the
    line."""
    w = frames_before(trace, f, seconds)
    k = w.start
    lane, now = str(trace["lane"][k]), str(trace["lane"][f])
    if not lane or lane.startswith(":") or not rmap.has_lane(lane) or lane_edge(now) != lane_edge(lane):
        return 0.0
    g = rmap.geom(lane)
    return abs(g.project(float(trace["x"][f]), float(trace["y"][f]))[1]
               - g.project(float(trace["x"][k]), float(trace["y"][k]))[1])


def sideways_into(trace, rmap, oth: Track, f: int, side: str, seconds: float = 1.5) -> tuple[float, float] | None:
    """(ego's, other's) sideways movement [m] towards each other over ``seconds`` before ``f``, measured
    square to the lane the ego was on then, when the ego moved at least 0.5 m towards ``side`` and
    more than the other moved towards it (the ego changed lanes into it); else None."""
    k = frames_before(trace, f, seconds).start
    lane = str(trace["lane"][k])
    if not lane or lane.startswith(":") or not rmap.has_lane(lane) or not oth.present(k):
        return None
    if lane_edge(str(trace["lane"][f])) != lane_edge(lane):  # turns are right-of-way questions
        return None
    g = rmap.geom(lane)
    sign = 1.0 if side == "left" else -1.0
    ego = sign * (g.project(float(trace["x"][f]), float(trace["y"][f]))[1]
                  - g.project(float(trace["x"][k]), float(trace["y"][k]))[1])
    other = -sign * (g.project(float(oth.x[f]), float(oth.y[f]))[1] - g.project(float(oth.x[k]), float(oth.y[k]))[1])
    if ego >= 0.5 and ego > other:
        return ego, other
    return None


@dataclass(frozen=True)
class CutIn:
    """A vehicle that moved into the ego's lane ahead of it: from frame ``entered`` (when it began to move
    towards the lane, on the way to overlapping it) to the event, both bodies' centres along the lane [m]."""

    entered: int
    ego_s: np.ndarray  # [m] along the lane, frames entered..f
    other_s: np.ndarray
    overlap: float  # [m] how far its body reached into the lane at the event


#: [m/s] sideways speed towards the ego's lane from which a vehicle shows that it is coming in.
CUT_IN_LATERAL_SPEED = 0.2
#: [rad] a vehicle that overlaps the ego's lane heading farther from the lane's way than this crosses or
#: comes the other way: a right-of-way question, not a cut-in.
CUT_IN_HEADING = math.radians(60.0)


def cut_in(trace, rmap, oth: Track, f: int, seconds: float = 4.0) -> CutIn | None:
    """How ``oth`` came into the ego's lane within ``seconds`` before ``f``, measured on the normal lane the
    ego was on at ``f`` (and stayed on since the window began, or since it entered that lane), from the first
    frame ``oth`` was there: None unless its body was wholly outside the lane at some frame and overlapped it
    from a later frame up to ``f``, travelling the lane's way (within :data:`CUT_IN_HEADING` of it) with its
    centre ahead of the ego's then. A position beyond either end of the lane (a car crossing past the stop
    line) is outside it. It counts as coming in from the first frame of the run of frames, up to the overlap,
    in which it moved towards the lane at :data:`CUT_IN_LATERAL_SPEED` or more: a careful driver sees a car
    nose towards its lane before the car is in it."""
    lane = str(trace["lane"][f])
    if not lane or lane.startswith(":") or not rmap.has_lane(lane) or not oth.present(f):
        return None
    w = frames_before(trace, f, seconds)
    k0 = w.start
    lanes = trace["lane"]
    # frames before the ego came onto the lane are measured elsewhere, and before the other appeared not at all
    while k0 < f and (str(lanes[k0]) != lane or not oth.present(k0)):
        k0 += 1
    if any(str(lanes[k]) != lane or not oth.present(k) for k in range(k0, f + 1)):
        return None
    g = rmap.geom(lane)
    half_lane = 0.5 * g.width
    off, ego_s, other_s = [], [], []
    for k in range(k0, f + 1):
        s_o, lat = g.project(float(oth.x[k]), float(oth.y[k]))
        s_e, _ = g.project(float(trace["x"][k]), float(trace["y"][k]))
        off.append(abs(lat) if 0.0 < s_o < g.length else math.inf)  # pinned to an end: beyond the lane
        ego_s.append(s_e)
        other_s.append(s_o)
    inside = [half_lane + 0.5 * oth.width - o > 0.0 for o in off]
    if all(inside) or not inside[-1]:
        return None
    lane_heading = g.position(other_s[-1])[2]
    if abs(wrap_angle(float(oth.heading[f]) - lane_heading)) > CUT_IN_HEADING:  # oncoming or crossing
        return None
    i_in = max(i for i, v in enumerate(inside) if not v) + 1
    step = CUT_IN_LATERAL_SPEED * trace.step_length
    while i_in > 0 and math.isfinite(off[i_in - 1]) and off[i_in - 1] - off[i_in] >= step:  # never onto an end
        i_in -= 1
    if other_s[i_in] <= ego_s[i_in]:
        return None
    overlap = half_lane + 0.5 * oth.width - off[-1]
    return CutIn(k0 + i_in, np.asarray(ego_s[i_in:]), np.asarray(other_s[i_in:]), overlap)


def sensor_range(weather) -> float:
    """[m] the reference sensors' range in this weather (fog and rain shorten it; 12 m all round)."""
    return max(100.0 * (1.0 - 0.85 * weather.fog / 100.0) * (1.0 - 0.4 * weather.rain / 100.0), 12.0)


def stopping_distance(v: float, mu: float) -> float:
    """[m] reaction plus braking distance from ``v`` [m/s] with friction ``mu``."""
    decel = min(max(mu, 0.05) * G, MAX_BRAKE)
    return v * REACTION_TIME + v * v / (2.0 * decel)


# ---------------------------------------------------------------------- junction links
def lane_of(rmap, x: float, y: float, internal: bool | None = None) -> str | None:
    """The passenger lane whose centre line is nearest (x, y), within 3 m: a junction's (``internal``), a
    normal one (not ``internal``), or either (None)."""
    best = None
    for lane, dist in rmap.net.getNeighboringLanes(x, y, 3.0, includeJunctions=True):
        if not lane.allows("passenger"):
            continue
        if internal is not None and lane.getID().startswith(":") != internal:
            continue
        if best is None or dist < best[1]:
            best = (lane.getID(), dist)
    return best[0] if best else None


def other_link(trace, rmap, oth: Track, f: int, seconds: float = 10.0):
    """(connection, frame it crossed the stop line) of the junction passage ``oth`` was making at
    ``f``, judged from its positions; None when it was not in or at the end of a junction."""
    dt = trace.step_length
    frames = [k for k in range(max(f - int(seconds / dt), 0), f + 1) if oth.present(k)]
    if not frames:
        return None
    stride = max(int(0.25 / dt), 1)
    sample = frames[::-1][::stride]  # newest first
    lane_in, k_last = None, None
    for k in sample:
        lane = lane_of(rmap, float(oth.x[k]), float(oth.y[k]), internal=False)
        if lane is None:
            continue
        g = rmap.geom(lane)
        pos, lat = g.project(float(oth.x[k]), float(oth.y[k]))
        if abs(lat) < g.width / 2 and abs(wrap_angle(float(oth.heading[k]) - g.position(pos)[2])) < math.pi / 4:
            lane_in, k_last = lane, k  # the newest normal lane it drove along
            break
    if lane_in is None:
        return None
    conns = [c for c in rmap.lane(lane_in).getOutgoing() if c.getViaLaneID()]
    if not conns:
        return None
    g = rmap.geom(lane_in)

    def past_line(k: int) -> bool:  # its front beyond the end of the lane (the stop line)
        fx = oth.x[k] + math.cos(oth.heading[k]) * oth.length / 2
        fy = oth.y[k] + math.sin(oth.heading[k]) * oth.length / 2
        return g.project(float(fx), float(fy))[0] >= g.length - 0.2

    # the frame its front crossed the stop line: after k_last if it was still short of it then, else the
    # start of the run of frames it has stood past it, however long before the window that began (a car
    # that stopped across the line a minute ago entered then, not at the contact)
    if past_line(k_last):
        k_in = k_last
        while oth.present(k_in - 1) and past_line(k_in - 1):
            k_in -= 1
    else:
        k_in = next((k for k in frames if k > k_last and past_line(k)), None)
    if k_in is None:
        return None  # it had not reached the junction
    after = [k for k in frames if k >= k_in]
    pts = np.stack([oth.x[after], oth.y[after]], axis=1)

    def mismatch(c) -> float:
        shape = np.vstack([np.asarray(rmap.lane(v).getShape())[:, :2] for v in rmap.internal_chain(c.getViaLaneID())]
                          + [np.asarray(c.getToLane().getShape())[:2, :2]])
        return float(np.mean([_point_polyline(p, shape) for p in pts]))

    return min(conns, key=mismatch), k_in


def ego_link(trace, rmap, f: int, seconds: float = 15.0):
    """The connection of the ego's junction passage around ``f`` (from its lane channel), or None.

    The passage's internal lanes are tried newest first: where two connections from one lane overlap
    before they part (a roundabout's exit and its ring), SUMO may place the ego on either at first, and
    only the later frames tell which one it took."""
    lanes = trace["lane"]
    w = frames_before(trace, f, seconds)
    run: list[str] = []  # the passage's internal lanes, newest first
    k = None
    for j in range(f, w.start - 1, -1):
        lane = str(lanes[j])
        if lane.startswith(":"):
            if lane not in run:
                run.append(lane)
            k = j
        elif run:
            break
    if not run:  # not yet in the junction: the next frames do not exist; use the lane's only links
        return None
    prev = next((str(lanes[j]) for j in range(k, w.start - 1, -1) if lanes[j] and not str(lanes[j]).startswith(":")),
                None)
    if prev is None:
        return None
    conns = [(c, rmap.internal_chain(c.getViaLaneID())) for c in rmap.lane(prev).getOutgoing() if c.getViaLaneID()]
    for via in run:
        for c, chain in conns:
            if via in chain:
                return c
    return None


def wrap_angle(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _point_polyline(p: np.ndarray, poly: np.ndarray) -> float:
    a, b = poly[:-1], poly[1:]
    d = b - a
    l2 = np.maximum((d * d).sum(1), 1e-12)
    t = np.clip(((p - a) * d).sum(1) / l2, 0.0, 1.0)
    q = a + t[:, None] * d
    return float(np.min(np.hypot(*(p - q).T)))


# ---------------------------------------------------------------------- pedestrians
def _ego_polyline(trace, k: int, f: int) -> np.ndarray:
    """The ego's centre path from ``k`` to ``f``, extended half a car ahead of its last pose."""
    xs, ys = trace["x"][k:f + 1], trace["y"][k:f + 1]
    h = float(trace["heading"][f])
    tip = (xs[-1] + math.cos(h) * EGO_LENGTH / 2, ys[-1] + math.sin(h) * EGO_LENGTH / 2)
    return np.vstack([np.stack([xs, ys], axis=1), [tip]])


def path_entry(trace, oth: Track, f: int, seconds: float = 10.0) -> int | None:
    """The frame from which ``oth`` stayed in the ego's path ahead until ``f`` (the ego's footprint
    swept from then to ``f``), or None if it was not ahead of the ego's front when it entered."""
    dt = trace.step_length
    corridor = EGO_WIDTH / 2 + oth.width / 2 + 0.2
    k_in = None
    for k in range(f, max(f - int(seconds / dt), 0) - 1, -1):
        if not oth.present(k):
            break
        poly = _ego_polyline(trace, k, f)
        p = np.array([oth.x[k], oth.y[k]])
        if _point_polyline(p, poly) > corridor:
            break
        k_in = k
    if k_in is None:
        return None
    lx, _ = to_local(trace, k_in, float(oth.x[k_in]), float(oth.y[k_in]))
    return k_in if lx > EGO_LENGTH / 2 - 0.3 else None


def gap_ahead(trace, k: int, oth: Track) -> float:
    lx, _ = to_local(trace, k, float(oth.x[k]), float(oth.y[k]))
    return max(lx - EGO_LENGTH / 2 - oth.length / 2, 0.0)


def first_visible(trace, oth: Track, f: int, scenario) -> int | None:
    """The first frame up to ``f`` at which the reference sensors could see ``oth``: within range
    (weather), inside the 200 degree field of view or 12 m all round, not hidden behind a vehicle."""
    from shapely.geometry import LineString, Polygon

    rng = sensor_range(scenario.weather) if scenario is not None else 100.0
    cos_half = math.cos(math.radians(100.0))
    a = trace.actors
    for k in range(f + 1):
        if not oth.present(k):
            continue
        lx, ly = to_local(trace, k, float(oth.x[k]), float(oth.y[k]))
        d = math.hypot(lx, ly)
        if d > rng or (d > 12.0 and lx < cos_half * d):
            continue
        sight = LineString([(trace["x"][k], trace["y"][k]), (oth.x[k], oth.y[k])])
        r = a.rows(k)
        hidden = False
        for j, x, y, h in zip(a.actor[r], a.x[r], a.y[r], a.heading[r]):
            if a.ids[int(j)] == oth.id or a.kinds[int(j)] != "vehicle":
                continue
            if math.hypot(x - trace["x"][k], y - trace["y"][k]) > d + 5.0:
                continue
            if sight.intersects(Polygon(corners(x, y, h, a.length[int(j)], a.width[int(j)]))):
                hidden = True
                break
        if not hidden:
            return k
    return None


# ---------------------------------------------------------------------- blocked roads
def footprint_half(length: float, width: float, skew: float) -> float:
    """[m] half the width of a body's footprint square to a lane it stands at ``skew`` [rad] to (a car at an
    angle across a lane covers more of it than its width); by the width alone when the skew is unknown (NaN)."""
    if not math.isfinite(skew):
        skew = 0.0
    return 0.5 * (length * abs(math.sin(skew)) + width * abs(math.cos(skew)))


def ego_reach_into(trace, rmap, lane: str, f: int) -> float | None:
    """[m] how far the ego's body reached across the edge of ``lane`` (a normal lane) into it at ``f``, by its
    footprint square to the lane (negative: it stayed clear of it); None beside either end of the lane."""
    if not lane or lane.startswith(":") or not rmap.has_lane(lane):
        return None
    g = rmap.geom(lane)
    pos, lat = g.project(float(trace["x"][f]), float(trace["y"][f]))
    if not 0.0 < pos < g.length:
        return None
    length, width = float(trace.meta.get("ego_length", EGO_LENGTH)), float(trace.meta.get("ego_width", EGO_WIDTH))
    half = footprint_half(length, width, float(trace["heading"][f]) - g.position(pos)[2])
    return g.width / 2 + half - abs(lat)


def kept_lane(rmap, oth: Track, frames: Sequence[int]) -> str | None:
    """The normal lane ``oth`` kept its centre on over ``frames`` (present in all, nearest the same passenger
    lane within 3 m, and within that lane's width), or None."""
    lane = None
    for k in frames:
        if not oth.present(k):
            return None
        here = lane_of(rmap, float(oth.x[k]), float(oth.y[k]), internal=False)
        if here is None or (lane is not None and here != lane):
            return None
        lane = here
        g = rmap.geom(lane)
        if abs(g.project(float(oth.x[k]), float(oth.y[k]))[1]) > g.width / 2:
            return None
    return lane
