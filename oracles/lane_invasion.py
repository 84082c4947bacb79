"""Lane invasion: the ego's body crosses a boundary it may not cross."""

from __future__ import annotations

import math
from typing import Sequence

from pydantic import Field

from drivefuzz.oracle import Frame, Misbehavior, Oracle, RunContext
from oracles import wrap_angle
from oracles.lane_index import CELL as _CELL, REACH as _REACH, Lane as _Lane, index as _index

#: Heading difference above which a lane runs against the ego.
_OPPOSITE = math.radians(135.0)
#: Severity order when corners disagree.
_SEVERITY = {"opposite_lane": 4, "sidewalk": 3, "solid_line": 2, "off_road": 1}


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
            against |= self._idx.reverse(e)
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
        by_index = self._idx.by_index(target.edge)
        if target.index > home_index:  # to the left
            return all(by_index[k].change_left for k in range(home_index, target.index) if k in by_index)
        return all(by_index[k].change_right for k in range(target.index + 1, home_index + 1) if k in by_index)
