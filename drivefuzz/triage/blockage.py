"""Evidence for the standstill rules (:mod:`drivefuzz.triage.standstill`): what stands in the ego's way.

Which lawful lanes stationary bodies block ahead of the ego, which lanes beside it are free of slower traffic,
whether the body ahead heads a queue that waits (at a junction, a light, a body ahead of it) or is parked or
stalled, and whether the ego was held up behind slower traffic for most of the run. Nothing here gives a verdict.

Units: SI; positions are body centres; headings radians ENU (as in the trace).
"""

from __future__ import annotations

import math

import numpy as np

from drivefuzz.scenario.model import EGO_LENGTH, EGO_WIDTH
from drivefuzz.triage.evidence import (STATIONARY_SPEED, STILL_FOR, Track, actor_track, footprint_half, lane_of,
                                       to_local)

def never_moved(track: Track, f: int) -> bool:
    """Whether ``track`` had not moved (faster than 0.1 m/s) up to ``f``: a parked body."""
    return float(np.nanmax(track.speed[: f + 1], initial=0.0)) < 0.1


def _still(track: Track, f: int, dt: float) -> bool:
    w = track.speed[max(f - int(STILL_FOR / dt), 0):f + 1]
    w = w[~np.isnan(w)]
    return len(w) > 0 and float(np.max(w)) <= 0.2


def _bodies_on(trace, rmap, lane: str, f: int, s_from: float, reach: float):
    """(distance along ``lane`` from ``s_from`` [m], actor id) of every body on ``lane`` (and up to 10 m past
    its end, on the extended centre line) between ``s_from`` and ``s_from + reach``. A body is on the lane when
    it reaches more than 0.3 m into it, by the half width of its footprint square to the lane (a car standing
    at an angle across two lanes, stuck mid-change, reaches into both)."""
    g = rmap.geom(lane)
    a = trace.actors
    r = a.rows(f)
    out = []
    end_x, end_y, end_h = g.position(g.length)
    for j, x, y, h in zip(a.actor[r], a.x[r], a.y[r], a.heading[r]):
        j = int(j)
        pos, lat = g.project(float(x), float(y))
        if pos >= g.length - 0.01:  # past the end: along the extended last segment
            dx, dy = x - end_x, y - end_y
            pos = g.length + dx * math.cos(end_h) + dy * math.sin(end_h)
            lat = -dx * math.sin(end_h) + dy * math.cos(end_h)
            if pos > g.length + 10.0:
                continue
        if not (s_from < pos < s_from + reach):
            continue
        half = footprint_half(float(a.length[j]), float(a.width[j]),
                              float(h) - g.position(min(max(pos, 0.0), g.length))[2])
        if abs(lat) > g.width / 2 + half - 0.3:
            continue
        out.append((pos - s_from, a.ids[j]))
    return sorted(out)


def _beside(rmap, lane: str) -> list[str]:
    """The lanes of ``lane``'s edge that a passenger car may reach from it by lane changes its markings permit."""
    edge = rmap.lane(lane).getEdge()
    idx = rmap.lane(lane).getIndex()
    lanes_of = {l.getIndex(): l.getID() for l in edge.getLanes() if l.allows("passenger")}
    out = []
    for step, left in ((1, True), (-1, False)):
        i = idx
        while i + step in lanes_of and rmap.may_change(lanes_of[i], left=left):
            i += step
            out.append(lanes_of[i])
    return out


def passing_lanes(trace, rmap, f: int, slower_than: float, reach: float = 60.0) -> list[str] | None:
    """The lawful lanes beside the ego's at ``f`` (lane changes its markings permit) in which no body from a car length
    behind the ego to ``reach`` m ahead of it moves slower than ``slower_than`` [m/s] (NaN: any body there): lanes
    to pass slower traffic on; None off the normal lanes."""
    lane = str(trace["lane"][f])
    if not lane or lane.startswith(":") or not rmap.has_lane(lane):
        return None
    ego_pos, _ = rmap.geom(lane).project(float(trace["x"][f]), float(trace["y"][f]))
    out = []
    for l in _beside(rmap, lane):
        bodies = _bodies_on(trace, rmap, l, f, ego_pos - EGO_LENGTH, reach + EGO_LENGTH)
        if not any(not float(actor_track(trace, b).speed[f]) >= slower_than for _d, b in bodies):
            out.append(l)
    return out


def blocked_lanes(trace, rmap, f: int, reach: float = 60.0):
    """What blocks the ego standing at ``f``: ``(lanes, free, queue, root)`` with ``lanes`` the lawful
    lanes of its edge whose nearest body ahead stands still (lane -> that body), ``free`` the others,
    and, for the stationary vehicle ahead of the ego in its own lane, either ``queue``, a description
    when it queues for a junction (see :func:`_queue`), or ``root``, the parked or stalled vehicle it
    stands behind (both None when it stands alone); None off the normal lanes."""
    lane = str(trace["lane"][f])
    dt = trace.step_length
    if lane.startswith(":"):  # in a junction there is one way forward: the body right ahead
        ahead = _still_ahead(trace, f, dt) or _still_on_path(trace, rmap, lane, f, dt)
        return ({lane: ahead}, [], None, None) if ahead else None
    if not lane or not rmap.has_lane(lane):
        return None
    tracks: dict[str, Track] = {}

    def track(aid: str) -> Track:
        if aid not in tracks:
            tracks[aid] = actor_track(trace, aid)
        return tracks[aid]

    ego_pos, _ = rmap.geom(lane).project(float(trace["x"][f]), float(trace["y"][f]))
    lawful = [lane] + _beside(rmap, lane)
    blocked, free, queue, root = {}, [], None, None
    for l in lawful:
        s_from = ego_pos if l == lane else ego_pos - EGO_LENGTH  # a body alongside blocks a change too
        bodies = _bodies_on(trace, rmap, l, f, s_from, reach)
        if bodies and _still(track(bodies[0][1]), f, dt):
            blocked[l] = bodies[0][1]
            if l == lane:
                queue, root = _queue(trace, rmap, track(bodies[0][1]), f, track, dt)
        else:
            free.append(l)
    if not blocked:
        return None
    return blocked, free, queue, root


def _still_ahead(trace, f: int, dt: float, reach: float = 15.0) -> str | None:
    """A stationary body right ahead of the ego's front (within ``reach`` m, in its width)."""
    a = trace.actors
    r = a.rows(f)
    best = None
    for j, x, y in zip(a.actor[r], a.x[r], a.y[r]):
        j = int(j)
        lx, ly = to_local(trace, f, float(x), float(y))
        if EGO_LENGTH / 2 < lx < EGO_LENGTH / 2 + reach and abs(ly) < EGO_WIDTH / 2 + a.width[j] / 2:
            t = actor_track(trace, a.ids[j])
            if _still(t, f, dt) and (best is None or lx < best[0]):
                best = (lx, a.ids[j])
    return best[1] if best else None


def _still_on_path(trace, rmap, lane: str, f: int, dt: float, reach: float = 15.0) -> str | None:
    """A stationary body on the ego's way through a junction: within ``reach`` m past its front along the
    internal lane it stands on and the lanes that one leads to, and within both bodies' half widths of
    their centre lines. Mid-turn, what blocks the ego stands to the side of its heading (a car 6 m on
    along a right turn stood 4 m to the right of it), where :func:`_still_ahead` does not look."""
    if not rmap.has_lane(lane):
        return None
    x, y = float(trace["x"][f]), float(trace["y"][f])
    g = rmap.geom(lane)
    s0, _ = g.project(x, y)
    path, arc, lane_id, s = [], 0.0, lane, s0  # (geometry, from, to, path length before it)
    limit = EGO_LENGTH / 2 + reach
    while lane_id and arc < limit and len(path) < 8:
        g = rmap.geom(lane_id)
        path.append((g, s, g.length, arc))
        arc += max(g.length - s, 0.0)
        nxt = rmap.lane(lane_id).getOutgoing() if lane_id.startswith(":") else []
        lane_id, s = (nxt[0].getToLane().getID(), 0.0) if nxt else (None, 0.0)
    a = trace.actors
    r = a.rows(f)
    best = None
    for j, bx, by in zip(a.actor[r], a.x[r], a.y[r]):
        j = int(j)
        half = EGO_WIDTH / 2 + float(a.width[j]) / 2
        for g, s_from, s_to, before in path:
            s_b, lat = g.project(float(bx), float(by))
            along = before + s_b - s_from
            if s_from <= s_b <= s_to and abs(lat) < half and EGO_LENGTH / 2 < along <= limit + float(a.length[j]) / 2:
                if _still(actor_track(trace, a.ids[j]), f, dt) and (best is None or along < best[0]):
                    best = (along, a.ids[j])
                break
    return best[1] if best else None


#: [m] a stationary vehicle this close (bumper to bumper) ahead of another is queued ahead of it; room
#: for a small junction between them, where a car waits for space beyond it.
QUEUE_GAP = 12.0
#: [m] a queue's head this close to the end of its lane waits at the junction.
AT_LANE_END = 3.0


def _queue_ahead(trace, lead: Track, f: int, track, dt: float) -> tuple[list[Track], str | None]:
    """``(chain, front)``: ``lead`` and the stationary vehicles queued ahead of it at ``f``, nearest first
    (each one's rear within :data:`QUEUE_GAP` of the front of the one before, in its width, along its
    heading: the queue is followed across a junction on its way), and ``front``, the body in that reach
    ahead of the last one that is not a stationary vehicle (a pedestrian, or a car moving off), or None."""
    a = trace.actors
    r = a.rows(f)
    rows = [(a.ids[int(j)], float(x), float(y), float(a.length[int(j)]), float(a.width[int(j)]))
            for j, x, y in zip(a.actor[r], a.x[r], a.y[r])]
    chain, seen = [lead], {lead.id}
    while len(chain) <= len(rows):
        cur = chain[-1]
        cx, cy, h = float(cur.x[f]), float(cur.y[f]), float(cur.heading[f])
        c, sn = math.cos(h), math.sin(h)
        best = None
        for aid, x, y, length, width in rows:
            if aid in seen:
                continue
            lx, ly = (x - cx) * c + (y - cy) * sn, -(x - cx) * sn + (y - cy) * c
            if 0.0 < lx < (cur.length + length) / 2 + QUEUE_GAP and abs(ly) < (cur.width + width) / 2 and (
                    best is None or lx < best[0]):
                best = (lx, aid)
        if best is None:
            return chain, None
        nxt = track(best[1])
        if nxt.kind != "vehicle" or not _still(nxt, f, dt):
            return chain, nxt.id
        seen.add(nxt.id)
        chain.append(nxt)
    return chain, None


def _queue(trace, rmap, lead: Track, f: int, track, dt: float) -> tuple[str | None, str | None]:
    """``(queue, root)`` for the stationary ``lead`` ahead of the ego, from the queue :func:`_queue_ahead`
    follows. ``root`` is the first car of it that never moved (a parked car; not the lead itself: that blocks
    alone), or its head when the head stopped in mid-lane with nothing ahead of it (a stalled car): a
    blockage, however many cars queue behind it. Otherwise ``queue`` describes a queue that waits: its head
    stands within :data:`AT_LANE_END` of the end of its lane or in a junction, or waits for a body ahead of
    it (a pedestrian, a car moving off); it will move, and waiting in it is lawful. Both None for a
    pedestrian lead, a lead that never moved, or one that stands alone in mid-lane."""
    if lead.kind == "pedestrian" or never_moved(lead, f):
        return None, None
    chain, front = _queue_ahead(trace, lead, f, track, dt)
    parked = next((t for t in chain if never_moved(t, f)), None)
    if parked is not None:
        return None, parked.id
    head = chain[-1]
    x, y = float(head.x[f]), float(head.y[f])
    where = None
    if front is not None:
        where = f"for {front}"
    else:
        lane = lane_of(rmap, x, y)  # normal or internal: whichever is nearest
        if lane is not None and lane.startswith(":"):
            where = "in the junction"
        elif lane is not None:
            g = rmap.geom(lane)
            if g.length - g.project(x, y)[0] - head.length / 2 < AT_LANE_END:
                where = f"at the end of {lane}"
    if where is not None:
        if head is lead:
            return f"{lead.id} waits {where}", None
        return f"{lead.id} queues behind {head.id}, which waits {where}", None
    return None, (None if head is lead else head.id)


#: [1/m] the tightest bend held_up() follows (a radius of 15 m; the yaw rate of a slow car is noisy).
MAX_CURVATURE = 1.0 / 15.0


def held_up(trace, f: int, gap: float = 30.0) -> tuple[float, str] | None:
    """(share of frames, leader) when a slower vehicle was close ahead in the ego's lane for most of
    the run (at least half of the frames); None otherwise. In a bend, "ahead in its lane" is along the
    arc the ego is turning on (its yaw rate over its speed): on a roundabout's ring of 27 m radius a
    leader 9 m ahead stands 1.5 m to the side of the ego's heading."""
    a = trace.actors
    n = min(f + 1, trace.n_frames)
    count, leaders = 0, {}
    for k in range(0, n, max(int(0.5 / trace.step_length), 1)):
        r = a.rows(k)
        lim = trace["speed_limit"][k]
        speed = float(trace["speed"][k])
        # the arc it turns on, also at a crawl behind a leader at walking pace (a standstill has none)
        curvature = float(trace["yaw_rate"][k]) / speed if speed > STATIONARY_SPEED else 0.0
        radius = 1.0 / min(abs(curvature), MAX_CURVATURE) if curvature else math.inf
        for j, x, y, v in zip(a.actor[r], a.x[r], a.y[r], a.speed[r]):
            lx, ly = to_local(trace, k, float(x), float(y))
            if not 0 < lx < min(gap, radius):  # ahead, and on the near quarter of the circle it turns on
                continue
            arc = math.copysign(radius - math.sqrt(radius * radius - lx * lx), curvature) if curvature else 0.0
            if abs(ly - arc) < 1.5 and (math.isnan(lim) or v < 0.8 * lim):
                count += 1
                leaders[a.ids[int(j)]] = leaders.get(a.ids[int(j)], 0) + 1
                break
    total = len(range(0, n, max(int(0.5 / trace.step_length), 1)))
    if total and count / total >= 0.5:
        return count / total, max(leaders, key=leaders.get)
    return None
