"""Lane invasion: the ego's body crosses a boundary it may not cross."""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import Sequence

from pydantic import Field

from drivefuzz.oracle import Frame, Misbehavior, Oracle, RunContext
from drivefuzz.scenario.roadmap import PASSENGER, PEDESTRIAN
from oracles import wrap_angle

#: Grid cell [m] of the lane-segment index.
_CELL = 8.0
#: Lateral reach [m] beyond a lane's half width for which a segment is indexed (>= any sane tolerance).
_REACH = 1.5
#: Heading difference above which a lane runs against the ego.
_OPPOSITE = math.radians(135.0)
#: Heading change at one vertex of a lane's shape from which the vertex counts as a street corner.
_BEND = math.radians(30.0)
#: Severity order when corners disagree.
_SEVERITY = {"opposite_lane": 4, "sidewalk": 3, "solid_line": 2, "off_road": 1}


@dataclass
class _Lane:
    id: str
    edge: str
    index: int
    width: float
    passenger: bool
    pedestrian: bool
    from_node: str
    to_node: str
    # per segment: x0, y0, ux, uy, length, cumulative start, heading
    segs: list[tuple[float, float, float, float, float, float, float]] = field(default_factory=list)
    starts: list[float] = field(default_factory=list)  # cumulative start of every segment
    total: float = 0.0
    change_left: bool = True  # passenger cars may change to the lane on the left
    change_right: bool = True
    bends: list[float] = field(default_factory=list)  # [m] along the lane: vertices that turn by >= _BEND

    def near_bend(self, s0: float, s1: float) -> bool:
        """Whether a sharp bend lies between ``s0`` and ``s1`` [m along the lane]."""
        k = bisect.bisect_left(self.bends, s0)
        return k < len(self.bends) and self.bends[k] <= s1

    def seg_at(self, s: float) -> int:
        return min(max(bisect.bisect_right(self.starts, s) - 1, 0), len(self.segs) - 1)

    def distance(self, x: float, y: float, i0: int = 0, i1: int | None = None) -> tuple[float, float]:
        """(distance [m] from the centre line, heading there) for a point beside the lane, inf if
        it lies before the lane start or after its end. Only segments i0..i1 are searched."""
        best, head = math.inf, 0.0
        last = len(self.segs) - 1
        for i in range(i0, last + 1 if i1 is None else min(i1, last) + 1):
            x0, y0, ux, uy, ln, _c, h = self.segs[i]
            px, py = x - x0, y - y0
            t = px * ux + py * uy
            if t < 0.0:
                if i == 0:
                    continue
                t = 0.0
            elif t > ln:
                if i == last:
                    continue
                t = ln
            d = math.hypot(px - t * ux, py - t * uy)
            if d < best:
                best, head = d, h
        return best, head


class _NetIndex:
    """Per-network, read-only geometry for the oracle (built once per process and network)."""

    def __init__(self, rmap):
        net = rmap.net
        self.lanes: dict[str, _Lane] = {}
        for e in net.getEdges(withInternal=False):
            if e.getFunction() != "":
                continue
            fr, to = e.getFromNode().getID(), e.getToNode().getID()
            for ln in e.getLanes():
                pts = [(float(p[0]), float(p[1])) for p in ln.getShape()]
                lane = _Lane(ln.getID(), e.getID(), ln.getIndex(), float(ln.getWidth()),
                             bool(ln.allows(PASSENGER)), bool(ln.allows(PEDESTRIAN)), fr, to)
                cum = 0.0
                for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:]):
                    d = math.hypot(x1 - x0, y1 - y0)
                    if d < 1e-9:
                        continue
                    lane.segs.append((x0, y0, (x1 - x0) / d, (y1 - y0) / d, d, cum, math.atan2(y1 - y0, x1 - x0)))
                    lane.starts.append(cum)
                    cum += d
                lane.total = cum
                if not lane.segs:
                    continue
                lane.bends = [b[5] for a, b in zip(lane.segs[:-1], lane.segs[1:])
                              if abs(wrap_angle(b[6] - a[6])) >= _BEND]
                lane.change_left = rmap.may_change(lane.id, left=True)
                lane.change_right = rmap.may_change(lane.id, left=False)
                self.lanes[lane.id] = lane
        self.edge_lanes: dict[str, list[_Lane]] = {}
        for lane in self.lanes.values():
            self.edge_lanes.setdefault(lane.edge, []).append(lane)
        for lanes in self.edge_lanes.values():
            lanes.sort(key=lambda l: l.index)
        self.edge_by_index = {e: {l.index: l for l in lanes} for e, lanes in self.edge_lanes.items()}
        # the reverse of every edge: same nodes, swapped
        by_nodes: dict[tuple[str, str], set[str]] = {}
        for lane in self.lanes.values():
            by_nodes.setdefault((lane.from_node, lane.to_node), set()).add(lane.edge)
        self.reverse: dict[str, frozenset[str]] = {}
        for (fr, to), edges in by_nodes.items():
            rev = frozenset(by_nodes.get((to, fr), ()))
            for e in edges:
                self.reverse[e] = rev
        # grid of lane segments
        self.grid: dict[tuple[int, int], list[tuple[_Lane, int]]] = {}
        for lane in self.lanes.values():
            r = 0.5 * lane.width + _REACH
            for i, (x0, y0, ux, uy, ln, _c, _h) in enumerate(lane.segs):
                x1, y1 = x0 + ux * ln, y0 + uy * ln
                for cx in range(int(math.floor((min(x0, x1) - r) / _CELL)), int(math.floor((max(x0, x1) + r) / _CELL)) + 1):
                    for cy in range(int(math.floor((min(y0, y1) - r) / _CELL)),
                                    int(math.floor((max(y0, y1) + r) / _CELL)) + 1):
                        self.grid.setdefault((cx, cy), []).append((lane, i))
        # junction areas a car may drive on: junction shapes minus walking areas; walking areas
        from shapely.geometry import LineString, Polygon
        from shapely.ops import unary_union

        junctions, walks = [], []
        def area(shape):
            """The shape as a valid polygon, or None where it has no area."""
            if len(shape) < 3:
                return None
            poly = Polygon([(p[0], p[1]) for p in shape]).buffer(0)
            return poly if poly.area > 0 else None

        junctions.extend(filter(None, (area(node.getShape()) for node in net.getNodes())))
        car_lanes = []
        for e in net.getEdges(withInternal=True):
            func = e.getFunction()
            if func == "walkingarea":
                walks.extend(filter(None, (area(ln.getShape()) for ln in e.getLanes())))
            elif func == "internal":
                # junction lanes for cars: drivable even where the junction shape is small
                for ln in e.getLanes():
                    shape = ln.getShape()
                    if ln.allows(PASSENGER) and len(shape) >= 2:
                        line = LineString([(p[0], p[1]) for p in shape])
                        if line.length > 1e-6:
                            car_lanes.append(line.buffer(0.5 * ln.getWidth(), cap_style="flat"))
        self.walk = unary_union(walks) if walks else None
        self.drivable = None
        if junctions and self.walk is not None:
            # the junction shape minus its walking areas, but every junction lane for cars whole: on
            # OSM imports a walking area often covers the whole junction of a road that pedestrians
            # share (a footpath meeting a street), and the cars' own lane through it stays drivable
            junctions = [unary_union(junctions).difference(self.walk)]
        self._parts = None  # the drivable area's polygons in an STRtree, for depths (built when first asked)
        if junctions or car_lanes:
            self.drivable = unary_union(junctions + car_lanes)
        self._drivable_tol: dict[float, object] = {}

    def junction_distance(self, x: float, y: float) -> float:
        """Distance [m] from (x, y) to the drivable junction area (inf beyond ``_REACH`` + 1 m, or none)."""
        if self.drivable is None:
            return math.inf
        import shapely

        if self._parts is None:
            parts = list(getattr(self.drivable, "geoms", [self.drivable]))
            self._parts = (parts, shapely.STRtree(parts))
        parts, tree = self._parts
        p = shapely.Point(x, y)
        near = tree.query(p.buffer(_REACH + 1.0))
        return min((parts[k].distance(p) for k in near.tolist()), default=math.inf)

    def drivable_within(self, tol: float):
        """The drivable junction area grown by ``tol`` (prepared), or None."""
        return self._drivable_and_cells(tol)[0]

    def drivable_cells(self, tol: float) -> "_Cells":
        """The grid cells (closed squares of ``_CELL``) that touch :meth:`drivable_within`: a point in
        any other cell is certainly outside it, without asking shapely. Each cell is tested when a point
        first falls in it (a city's bounding box holds a million cells; a run visits a few hundred)."""
        return self._drivable_and_cells(tol)[1]

    def _drivable_and_cells(self, tol: float):
        got = self._drivable_tol.get(tol)
        if got is None:
            g = None
            if self.drivable is not None:
                import shapely

                g = self.drivable.buffer(tol) if tol > 0 else self.drivable
                shapely.prepare(g)
            got = (g, _Cells(g))
            self._drivable_tol[tol] = got
        return got

    def lanes_at(self, x: float, y: float) -> dict[str, tuple[_Lane, float, float]]:
        """lane id -> (lane, distance from its centre line, lane heading there) for lanes indexed near (x, y)."""
        cell = self.grid.get((int(math.floor(x / _CELL)), int(math.floor(y / _CELL))))
        out: dict[str, tuple[_Lane, float, float]] = {}
        if not cell:
            return out
        for lane, i in cell:
            d, h = lane.distance(x, y, i, i)
            if d == math.inf:
                continue
            prev = out.get(lane.id)
            if prev is None or d < prev[1]:
                out[lane.id] = (lane, d, h)
        return out


class _Cells:
    """The grid cells that touch an area, found on demand (``cell in cells``) and remembered."""

    def __init__(self, area):
        self.area = area
        self.known: dict[tuple[int, int], bool] = {}

    def __contains__(self, cell) -> bool:
        hit = self.known.get(cell)
        if hit is None:
            hit = self.known[cell] = self._touches(cell)
        return hit

    def _touches(self, cell) -> bool:
        if self.area is None:
            return False
        import shapely

        cx, cy = cell
        eps = 0.01  # [m] a cell touching the area only within rounding counts as touching
        return bool(shapely.intersects(self.area, shapely.box(cx * _CELL - eps, cy * _CELL - eps,
                                                              (cx + 1) * _CELL + eps, (cy + 1) * _CELL + eps)))


_INDEX: dict[tuple[str, float], _NetIndex] = {}


def _index(rmap) -> _NetIndex:
    import os

    p = str(rmap.path)
    key = (p, os.path.getmtime(p))
    idx = _INDEX.get(key)
    if idx is None:
        idx = _INDEX[key] = _NetIndex(rmap)
    return idx


class LaneInvasionOracle(Oracle):
    """Fires when the ego's body crosses a boundary it may not cross.

    Every frame the four corners of the ego's footprint (from ``frame.x/y/heading``
    and ``ctx.ego_length/width``) are tested against the road map:

    - A corner is **fine** when it lies in a junction's drivable area (the
      junction shapes minus walking areas, plus the whole of every junction
      lane for cars, grown by ``tolerance``: OSM imports lay walking areas
      over the whole junction where a footpath meets a street that pedestrians
      share, and the cars' lanes through it stay drivable), or within ``tolerance`` of the lateral bounds of
      an *allowed* lane: a lane of a normal edge that allows passenger cars,
      does not run against the ego, and is not across a forbidden lane
      boundary from the ego's own lane. While any corner is on a junction
      (entering or leaving it), or the body is within reach of a street
      corner inside its lane's shape (a vertex that turns by 30 degrees or
      more: OSM edges bend round corners without a junction),
      ``junction_tolerance`` replaces ``tolerance`` for the lanes and the
      junction area: a turning body sweeps across the lines that start at the
      junction (the reference ADS's front corner reaches 0.3 m over the centre
      line leaving the tight corner junctions of the town grid, and 0.3 m over
      the inner kerb of the tight junctions and lane bends of OSM imports).
    - A lane **runs against the ego** when its edge is the reverse (same nodes,
      swapped) of the edge the ego drives along (the last edge it was on in its
      own direction and, when that edge is on the route, the next route edge),
      or when its direction differs from the ego's heading by more than 135
      degrees.
    - The ego's **own lane** on an edge is the last lane that held the whole
      body (within ``tolerance``); until there is one and once the body has
      left the junction, the lane SUMO puts the ego on. A lane of the same edge
      is across a **forbidden boundary** when passenger cars may not change
      from the own lane towards it (SUMO's ``changeLeft``/``changeRight`` lane
      attributes, read from the net file as sumolib does not expose them;
      absent means allowed). Lane changes across dashed boundaries are legal,
      whether the route needs them or not.
    - A corner that is not fine is a violation, named by what it lies in
      (strictly, without tolerance), most severe first: an opposite lane
      (``"opposite_lane"``), a sidewalk or walking area (``"sidewalk"``: a lane
      for pedestrians but not cars), a lane behind a forbidden boundary
      (``"solid_line"``), anything else (outside every lane and junction, or on
      a lane cars may not use: ``"off_road"``).

    Fast path: while the ego is on a straight normal lane with its whole body
    within that lane's bounds (and ``tolerance``), the frame costs one exact
    rectangle-in-strip test (curved lanes: one projection per corner). Off it,
    shapely is asked about the junction area only when a corner lies in a grid
    cell that touches it.

    An **episode** is an unbroken run of frames with a violation. It is
    recorded once its deepest corner is at least ``min_depth`` beyond the
    tolerance band, or once it has lasted ``min_duration`` (each violating
    frame counts one step), whichever comes first; shallower and shorter
    grazes are not recorded. Defaults: 0.1 m (a body 0.3 m over a lane line,
    0.6 m over a line at a junction) and 0.3 s (6 steps at 20 Hz): a corner
    that sweeps a few centimetres past the band for a frame or two, where a
    turn leaves a tight junction, is the path tracker rounding a polyline
    corner, not a lane departure, while a drifting car (``steer_left``) goes
    deeper within a few steps. A corner in a forbidden area with no allowed
    lane or junction within reach counts as infinitely deep. One record per
    episode: after a record the oracle is silent until all corners were
    fine again. Kinds ``"opposite_lane"``, ``"sidewalk"``,
    ``"off_road"``, ``"solid_line"``; details: ``lane`` (the lane the worst corner
    lies in, ``""`` if none), ``corner`` (0 front-right, 1 front-left, 2 rear-left,
    3 rear-right), ``corner_xy``, ``depth`` [m] (the deepest corner of the episode so
    far: how far beyond the tolerance band of the nearest allowed lane or
    junction area; ``None`` when none is within reach), ``duration`` [s] (of the
    episode so far), ``since`` [s] (simulation time it began), ``ego_lane``.
    """

    name = "lane_invasion"
    description = "The ego's body enters an opposite lane, a sidewalk, leaves the road, or crosses a solid line."

    class Config(Oracle.Config):
        tolerance: float = Field(0.2, ge=0.0, le=1.0, description="[m] a corner may stick out of its lane or junction")
        junction_tolerance: float = Field(0.5, ge=0.0, le=_REACH,
                                          description="[m] the same while part of the body is on a junction")
        min_depth: float = Field(0.1, ge=0.0, description="[m] beyond the tolerance that fires at once")
        min_duration: float = Field(0.3, ge=0.0, description="[s] a shallower violation must last to fire")

    def reset(self, ctx: RunContext) -> None:
        super().reset(ctx)
        self._idx = _index(ctx.roadmap)
        self._tol = float(self.config.tolerance)
        self._jtol = float(self.config.junction_tolerance)
        self._drivable = self._idx.drivable_within(self._tol)
        self._drivable_cells = self._idx.drivable_cells(self._tol)
        self._drivable_j = self._idx.drivable_within(self._jtol)
        self._drivable_cells_j = self._idx.drivable_cells(self._jtol)
        import shapely

        self._contains_xy = shapely.contains_xy
        self._hl = 0.5 * float(ctx.ego_length)
        self._hw = 0.5 * float(ctx.ego_width)
        self._reach = self._hl + self._hw
        self._route = tuple(ctx.route)
        self._route_next = {e: self._route[i + 1] for i, e in enumerate(self._route[:-1])}
        self._home_lane: _Lane | None = None  # the lane that last held the whole body
        self._ref: frozenset[str] = frozenset()  # edges the ego drives along now
        self._against: frozenset[str] = frozenset()  # their reverse edges
        self._ref_edge = ""
        self._min_depth = float(self.config.min_depth)
        self._min_duration = float(self.config.min_duration) - 1e-9
        self._dt = float(ctx.step_length)
        self._clear()

    def _clear(self) -> None:
        """All corners are fine: the next violation starts a new episode."""
        self._episode = False  # this episode was recorded
        self._pending: list | None = None  # [start t, worst violation, deepest depth] while not yet recorded

    # ------------------------------------------------------------------ frame
    def on_frame(self, frame: Frame) -> Sequence[Misbehavior]:
        lane = self._idx.lanes.get(frame.lane) if frame.lane else None
        aligned = False
        h = frame.heading
        c, s = math.cos(h), math.sin(h)
        hl, hw = self._hl, self._hw
        x, y = frame.x, frame.y
        if lane is not None:
            segs = lane.segs
            if len(segs) == 1:
                x0, y0, ux, uy, ln, _c, _h = segs[0]
            else:
                s0 = frame.lane_pos - hl if frame.lane_pos == frame.lane_pos else 0.0
                x0, y0, ux, uy, ln, _c, _h = segs[lane.seg_at(s0)]
            cos_d = c * ux + s * uy  # cos / sin of the heading relative to the lane
            aligned = cos_d > 0.0 and lane.edge not in self._against
            if aligned:
                if lane.edge != self._ref_edge:
                    self._set_ref(lane.edge)
                if lane.passenger:
                    if len(segs) == 1:
                        # a rectangle in a straight strip: exact, without corners
                        sin_d = s * ux - c * uy
                        qx, qy = x - x0, y - y0
                        t = qx * ux + qy * uy
                        lat = qx * uy - qy * ux
                        ext_lat = hl * abs(sin_d) + hw * cos_d
                        ext_lon = hl * cos_d + hw * abs(sin_d)
                        ok = (abs(lat) + ext_lat <= 0.5 * lane.width + self._tol
                              and t - ext_lon >= 0.0 and t + ext_lon <= ln)
                    else:
                        ok = self._inside_curved(lane, frame, self._corners(x, y, c, s))
                    if ok:
                        if self._home_lane is not lane:
                            self._home_lane = lane
                        if self._pending is not None or self._episode:
                            self._clear()
                        return ()
        return self._slow(frame, self._corners(x, y, c, s), lane if aligned else None)

    def _corners(self, x: float, y: float, c: float, s: float):
        """Front-right, front-left, rear-left, rear-right."""
        fx, fy, lx, ly = self._hl * c, self._hl * s, -self._hw * s, self._hw * c
        return ((x + fx - lx, y + fy - ly), (x + fx + lx, y + fy + ly),
                (x - fx + lx, y - fy + ly), (x - fx - lx, y - fy - ly))

    def _inside_curved(self, lane: _Lane, frame: Frame, pts) -> bool:
        lim = 0.5 * lane.width + self._tol
        s0 = frame.lane_pos - self._hl if frame.lane_pos == frame.lane_pos else 0.0
        i0, i1 = lane.seg_at(s0 - self._reach - 1.0), lane.seg_at(s0 + self._reach + 1.0)
        for px, py in pts:
            if lane.distance(px, py, i0, i1)[0] > lim:
                return False
        return True

    def _set_ref(self, edge: str) -> None:
        self._ref_edge = edge
        ref = {edge}
        nxt = self._route_next.get(edge)
        if nxt is not None:
            ref.add(nxt)
        self._ref = frozenset(ref)
        against: set[str] = set()
        for e in ref:
            against |= self._idx.reverse.get(e, frozenset())
        self._against = frozenset(against)

    def _slow(self, frame: Frame, pts, lane: _Lane | None) -> Sequence[Misbehavior]:
        """Corner by corner; ``lane`` is the ego's SUMO lane when it runs the ego's way (else None)."""
        tol = self._tol
        cells = self._drivable_cells
        if any((math.floor(px / _CELL), math.floor(py / _CELL)) in cells for px, py in pts):
            in_junction = self._contains_xy(self._drivable, [p[0] for p in pts], [p[1] for p in pts]).tolist()
            any_junction = True in in_junction
        else:  # no corner near a junction (or the network has none)
            in_junction, any_junction = [False] * 4, False
        home = self._home_lane
        if home is not None and lane is not None and lane.edge != home.edge:
            home = None
        # a street corner inside a lane's shape (OSM edges turn corners without a junction) is driven
        # like a junction: the body cannot follow a polyline's vertex
        s0 = frame.lane_pos - self._hl if frame.lane_pos == frame.lane_pos else math.nan
        on = self._idx.lanes.get(frame.lane) if frame.lane else None  # aligned or not: it may bend round
        turning = any_junction or (on is not None and bool(on.bends) and s0 == s0
                                   and on.near_bend(s0 - self._reach - 1.0, s0 + self._reach + 1.0))
        if home is None and lane is not None and lane.passenger and not any_junction:
            # no lane of this edge has held the whole body yet: once the body has left the
            # junction, the lane SUMO puts the ego on is its own (a turn may end straddling)
            home = lane
        # entering or leaving a junction, a turning body sweeps across the lines that start there
        tol_lane = max(tol, self._jtol) if turning else tol
        wide = self._jtol > tol and turning  # the junction area, too, gets the junction tolerance
        worst = None  # (severity, kind, corner, lane id)
        depth = -math.inf  # the deepest violating corner [m beyond the tolerance band]
        deep = not self._episode  # depths are needed until the episode is recorded
        for i, (px, py) in enumerate(pts):
            if in_junction[i]:
                continue
            if wide and (math.floor(px / _CELL), math.floor(py / _CELL)) in self._drivable_cells_j \
                    and self._contains_xy(self._drivable_j, px, py):
                continue
            if home is not None and home.edge not in self._against:
                d, lh = home.distance(px, py)
                if d <= 0.5 * home.width + tol_lane and abs(wrap_angle(frame.heading - lh)) <= _OPPOSITE:
                    continue  # in the ego's own lane: fine
            found = self._idx.lanes_at(px, py)
            fine = False
            best_kind, best_lane, best_sev = "off_road", "", 0
            nearest_ok = math.inf
            for ln, d, lh in found.values():
                half = 0.5 * ln.width
                if d > half + _REACH:
                    continue
                opposite = ln.edge in self._against or abs(wrap_angle(frame.heading - lh)) > _OPPOSITE
                if ln.passenger and not opposite:
                    solid = home is not None and ln.edge == home.edge and not self._may_change(ln, home.index)
                    if not solid:
                        if d <= half + tol_lane:
                            fine = True
                            break
                        nearest_ok = min(nearest_ok, d - half - tol_lane)
                        continue
                    kind = "solid_line"
                elif ln.passenger:
                    kind = "opposite_lane"
                elif ln.pedestrian:
                    kind = "sidewalk"
                else:
                    kind = "off_road"
                if d <= half:
                    sev = _SEVERITY[kind]
                    if sev > best_sev:
                        best_kind, best_lane, best_sev = kind, ln.id, sev
            if fine:
                continue
            if best_sev == 0:
                if self._idx.walk is not None:
                    if self._contains_xy(self._idx.walk, px, py):
                        best_kind, best_sev = "sidewalk", _SEVERITY["sidewalk"]
                if best_sev == 0:
                    best_sev = _SEVERITY["off_road"]
            if worst is None or best_sev > worst[0]:
                worst = (best_sev, best_kind, i, best_lane, (round(px, 3), round(py, 3)))
            if deep:
                jtol = tol_lane if wide else tol
                depth = max(depth, min(nearest_ok, self._idx.junction_distance(px, py) - jtol))
        if worst is None:
            if home is not None and home is not self._home_lane:
                self._home_lane = home
            self._clear()
            return ()
        if self._episode:
            return ()
        return self._episode_step(frame, worst, depth)

    def _episode_step(self, frame: Frame, worst: tuple, depth: float) -> Sequence[Misbehavior]:
        """One more violating frame of an episode not yet recorded: record it once it is deep or long enough."""
        pend = self._pending
        if pend is None:
            pend = self._pending = [frame.t, worst, depth]
        else:
            if worst[0] > pend[1][0]:
                pend[1] = worst
            pend[2] = max(pend[2], depth)
        duration = frame.t - pend[0] + self._dt  # each violating frame stands for one step
        if pend[2] < self._min_depth and duration < self._min_duration:
            return ()
        self._episode, self._pending = True, None
        _sev, kind, i, lane_id, xy = pend[1]
        return (self.report(frame, kind, (), lane=lane_id, corner=i, corner_xy=list(xy),
                            depth=None if pend[2] == math.inf else round(pend[2], 3),
                            duration=round(duration, 3), since=round(pend[0], 3), ego_lane=frame.lane),)

    def _may_change(self, target: _Lane, home_index: int) -> bool:
        """Passenger cars may change from lane ``home_index`` of ``target``'s edge to ``target``."""
        if target.index == home_index:
            return True
        by_index = self._idx.edge_by_index.get(target.edge, {})
        if target.index > home_index:  # to the left
            return all(by_index[k].change_left for k in range(home_index, target.index) if k in by_index)
        return all(by_index[k].change_right for k in range(target.index + 1, home_index + 1) if k in by_index)
