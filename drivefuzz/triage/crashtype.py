"""AV-Fuzzer's five crash types (Li et al., ISSRE 2020), read from a trace: who changed lanes, and where
the other vehicle was before the contact.

1. ``overtake_cut_in``: the other vehicle came from behind the ego on a lane beside it (at any time before)
   and cut in;
2. ``ego_cut_in``: the ego changed lanes into the other;
3. ``cut_in``: the other vehicle, ahead of the ego on a lane beside it all along, cut in;
4. ``rear_end_braking``: the ego ran into the back of a vehicle braking ahead of it on its lane;
5. ``squeeze``: two vehicles closed in on the ego at once (a second one within :data:`SQUEEZE_GAP` of it).

Anything else is ``other`` (the ego hit from behind, a vehicle that slowed long before, a crossing). The
finding store records it for every collision with a vehicle (``verdict.json``: ``crash_type``), the report
names it, and ``tools/eval_maneuver.py`` counts it; works on a frozen :class:`~drivefuzz.sim.trace.Trace`
and the road map.
"""

from __future__ import annotations

import numpy as np

from drivefuzz.triage.evidence import frames_before

CRASH_TYPES = ("overtake_cut_in", "ego_cut_in", "cut_in", "rear_end_braking", "squeeze")
#: How a report names each type (and ``other``)
LABELS = {"overtake_cut_in": "1: an NPC overtook and cut in", "ego_cut_in": "2: the ego cut in and hit",
          "cut_in": "3: an NPC cut in front of the ego", "rear_end_braking": "4: the ego rear-ended a braking NPC",
          "squeeze": "5: two NPCs squeezed the ego", "other": "none of the five"}
#: [s] of trace before the contact that the classification reads
WINDOW = 10.0
#: [m] sideways from the ego's centre line beyond which a vehicle is on a lane beside it (lanes ~3.5 m)
BESIDE = 2.2
#: [m] sideways movement of the other vehicle that makes a lane change (or its start)
MOVED = 1.0
#: [m] sideways movement of the ego towards the other that makes the ego's cut-in (contact comes early in it)
EGO_MOVED = 0.5
#: [s] before the contact over which the sideways movements are compared
MOVE_WINDOW = 3.0
#: [m] body gap (about: centre distances less half the bodies) of a second vehicle that squeezes the ego
SQUEEZE_GAP = 2.0
#: [m/s] speed lost within the window that makes the vehicle ahead a braking one
BRAKED = 2.0


def _relative(trace, rows, frames):
    """(longitudinal, lateral) [m] of an actor's centre (``rows`` of the actor samples) in the ego's frame at
    each of ``frames``."""
    a = trace.actors
    ex, ey, eh = trace["x"][frames], trace["y"][frames], trace["heading"][frames]
    dx, dy = a.x[rows] - ex, a.y[rows] - ey
    return np.cos(eh) * dx + np.sin(eh) * dy, -np.sin(eh) * dx + np.cos(eh) * dy


def _window_rows(trace, index: int, w: slice):
    a = trace.actors
    rows = np.flatnonzero((a.actor == index) & (a.frame >= w.start) & (a.frame < w.stop))
    return rows, a.frame[rows]


def _road_heading(trace, rmap, frames) -> np.ndarray:
    """[rad] the direction of the ego's lane at its place in each of ``frames`` (its own heading where the
    trace names no lane drivefuzz knows)."""
    out = np.array(trace["heading"][frames], dtype=float)
    lanes, pos = trace["lane"], trace["lane_pos"]
    for i, k in enumerate(frames):
        lane = str(lanes[k])
        if lane and rmap.has_lane(lane) and np.isfinite(pos[k]):
            out[i] = rmap.geom(lane).position(float(pos[k]))[2]
    return out


def _sideways(speed, heading, road) -> float:
    """[m] moved to the left of the road (negative: right): the speed's component square to it, summed."""
    return float(np.sum(speed * np.sin(heading - road)))


def _off_path(trace, rmap, frame: int, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """[m] signed offset (left +) of points from the ego's path up to ``frame``, square to its lane there: on
    a curved ramp a vehicle ahead is beside the ego's heading but on its road."""
    k = np.arange(0, frame + 1, 2)  # every other frame: 0.1 s apart, a couple of metres at most
    px, py = np.asarray(trace["x"][k], dtype=float), np.asarray(trace["y"][k], dtype=float)
    road = _road_heading(trace, rmap, k)
    i = np.argmin((xs[:, None] - px[None, :]) ** 2 + (ys[:, None] - py[None, :]) ** 2, axis=1)
    return -np.sin(road[i]) * (xs - px[i]) + np.cos(road[i]) * (ys - py[i])


def crash_type(trace, frame: int, other: str, rmap) -> str:
    """The crash type (one of :data:`CRASH_TYPES`, or ``other``) of the ego's contact with vehicle ``other``
    at ``frame``; ``rmap`` is the network's :class:`~drivefuzz.scenario.roadmap.RoadMap` (who moved sideways
    is measured against the road, on curved ramps too)."""
    a = trace.actors
    if other not in a.ids:
        return "other"
    index = a.ids.index(other)
    rows, frames = _window_rows(trace, index, slice(0, frame + 1))
    if len(rows) < 2:
        return "other"
    lon, _ = _relative(trace, rows, frames)
    off = _off_path(trace, rmap, frame, a.x[rows], a.y[rows])  # the other, from the ego's road
    window = frames >= frames_before(trace, frame, WINDOW).start
    recent = frames >= frames_before(trace, frame, MOVE_WINDOW).start
    e = frames[recent]
    ego_recent = _sideways(trace["speed"][e], trace["heading"][e], _road_heading(trace, rmap, e)) * trace.step_length
    other_recent = float(off[recent][-1] - off[recent][0])
    side = float(np.sign(off[recent][0]))  # where the other was: + left of the ego's road, - right
    if _squeezed(trace, frame, other):
        return "squeeze"
    if side * ego_recent >= EGO_MOVED and side * ego_recent > -side * other_recent:
        return "ego_cut_in"  # the ego moved towards the other more than the other towards it
    w_off = off[window]
    if bool(np.any(np.abs(w_off) > BESIDE)) and abs(float(w_off[-1])) < BESIDE \
            and abs(float(w_off[-1] - w_off[0])) >= MOVED:  # it came in from a lane beside
        return "overtake_cut_in" if bool(np.any((lon < 0.0) & (np.abs(off) > BESIDE))) else "cut_in"
    if float(lon[-1]) > 0.0 and abs(float(off[-1])) < BESIDE:
        speed = a.speed[rows[window]]
        if float(np.max(speed)) - float(speed[-1]) >= BRAKED:
            return "rear_end_braking"
    return "other"


def _squeezed(trace, frame: int, other: str) -> bool:
    """A second vehicle (not ``other``) came within :data:`SQUEEZE_GAP` of the ego's body in the last 1.5 s."""
    a = trace.actors
    w = frames_before(trace, frame, 1.5)
    half_l, half_w = 0.5 * trace.meta.get("ego_length", 4.6), 0.5 * trace.meta.get("ego_width", 1.9)
    for j, aid in enumerate(a.ids):
        if aid == other or a.kinds[j] != "vehicle":
            continue
        rows, frames = _window_rows(trace, j, w)
        if not len(rows):
            continue
        lon, lat = _relative(trace, rows, frames)
        gap_lon = np.abs(lon) - half_l - 0.5 * a.length[j]
        gap_lat = np.abs(lat) - half_w - 0.5 * a.width[j]
        if bool(np.any(np.maximum(gap_lon, gap_lat) < SQUEEZE_GAP)):
            return True
    return False
