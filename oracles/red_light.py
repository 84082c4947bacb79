"""Red light: the ego's front bumper crosses a stop line while its signal shows red."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Sequence

from pydantic import Field

from drivefuzz.oracle import Frame, LaneLink, Misbehavior, Oracle, RunContext
from drivefuzz.scenario.roadmap import PASSENGER
from oracles import RED_STATES, YELLOW_STATES, kmh


class _StopLine:
    """The stop line of one signalised incoming lane: the segment across the lane end."""

    __slots__ = ("lane", "edge", "px", "py", "ux", "uy", "half")

    def __init__(self, lane: str, edge: str, pts, width: float, margin: float):
        (x0, y0), (x1, y1) = pts[-2], pts[-1]
        d = math.hypot(x1 - x0, y1 - y0) or 1e-9
        self.lane, self.edge = lane, edge
        self.px, self.py = float(x1), float(y1)
        self.ux, self.uy = (x1 - x0) / d, (y1 - y0) / d
        self.half = 0.5 * width + margin

    def crossed(self, prev: tuple[float, float], cur: tuple[float, float]) -> bool:
        """The segment prev -> cur goes from behind or on the line to strictly beyond it, within its width."""
        s0 = (prev[0] - self.px) * self.ux + (prev[1] - self.py) * self.uy
        s1 = (cur[0] - self.px) * self.ux + (cur[1] - self.py) * self.uy
        if not (s0 <= 0.0 < s1):
            return False
        f = -s0 / (s1 - s0)
        qx = prev[0] + f * (cur[0] - prev[0])
        qy = prev[1] + f * (cur[1] - prev[1])
        lat = -(qx - self.px) * self.uy + (qy - self.py) * self.ux
        return abs(lat) <= self.half


def _category(state: str) -> str:
    if state in RED_STATES:
        return "red"
    if state in YELLOW_STATES:
        return "yellow"
    return "go"


class RedLightOracle(Oracle):
    """Fires when the front bumper crosses a stop line while the signal of the link taken is red.

    Method B of the SUMO notes (sec. 8), which also works when the ego is not
    where SUMO maps it:

    - The stop line of a signalised lane is the segment across the end of the
      lane, perpendicular to its last segment, one lane width wide plus
      ``lateral_margin`` on each side (so an ego straddling two lanes is caught).
    - While the ego is on a lane with signalised links (``frame.lane_links``)
      the oracle remembers that lane's stop line and the links' states. It keeps
      them while the ego is on a junction lane or off the road, and forgets
      them when the ego is on another normal lane without links.
    - A crossing is the front-bumper segment ``frame.prev_front -> frame.front``
      going from behind (or exactly on) the line to strictly beyond it. An ego
      that stops with its bumper on the line does not cross it.
    - The state is the one of the last frame before the crossing (the light
      during that step). If all vehicle links from the lane agree (all red, all
      yellow, all green), that decides. If they differ, the link actually taken
      decides: the one whose junction lanes (``via`` and its chain) or target
      lane the ego is on in the following frames; if none is identified within
      ``decide_within`` seconds (or by the end of the run), the links leading
      to the next edge of the route decide if they agree; otherwise nothing is
      reported (mixed signals and an unknown link are no certain violation).
    - Red is ``r`` and ``u`` (red-yellow). Yellow (``y``/``Y``) is kind
      ``"yellow"`` and reported only with ``report_yellow``. Pedestrian links
      (to lanes that do not allow cars) are ignored.

    Kinds ``"red"``, ``"yellow"``; details: ``tls``, ``link``, ``state``, ``lane``,
    ``to_lane``, ``speed`` (and km/h), ``decided_by`` (``"all"``, ``"taken"``,
    ``"route"``).
    """

    name = "red_light"
    description = "The ego's front bumper crosses a stop line while its signal shows red (yellow optional)."

    class Config(Oracle.Config):
        report_yellow: bool = False
        lateral_margin: float = Field(1.0, ge=0.0, description="[m] stop line extended beyond the lane on each side")
        decide_within: float = Field(3.0, gt=0.0, description="[s] to identify the link taken when states differ")

    _lines_cache: dict[tuple[str, str, float], _StopLine] = {}

    def reset(self, ctx: RunContext) -> None:
        super().reset(ctx)
        self._rmap = ctx.roadmap
        self._route = tuple(ctx.route)
        self._cand: _StopLine | None = None
        self._links: tuple[LaneLink, ...] = ()
        self._pending = None  # a crossing on mixed signals: (snapshot, links, edge, deadline, lane)
        self._vehicle_lane: dict[str, bool] = {}
        self._chains: dict[str, tuple[str, ...]] = {}
        self._margin = float(self.config.lateral_margin)
        self._cand_lane = ""
        self._all_vehicle = True

    # ------------------------------------------------------------------ helpers
    def _line(self, lane: str) -> _StopLine:
        key = (str(self._rmap.path), lane, self._margin)
        line = self._lines_cache.get(key)
        if line is None:
            g = self._rmap.geom(lane)
            line = _StopLine(lane, g.edge, g.pts, g.width, self._margin)
            self._lines_cache[key] = line
        return line

    def _is_vehicle_link(self, link: LaneLink) -> bool:
        ok = self._vehicle_lane.get(link.to_lane)
        if ok is None:
            try:
                ok = bool(self._rmap.lane(link.to_lane).allows(PASSENGER))
            except Exception:  # noqa: BLE001 - unknown lane: keep the link
                ok = True
            self._vehicle_lane[link.to_lane] = ok
        return ok

    def _chain(self, via: str) -> tuple[str, ...]:
        c = self._chains.get(via)
        if c is None:
            try:
                c = tuple(self._rmap.internal_chain(via)) if via else ()
            except Exception:  # noqa: BLE001
                c = (via,) if via else ()
            self._chains[via] = c
        return c

    def _taken(self, links: Sequence[LaneLink], lane: str) -> LaneLink | None:
        if not lane:
            return None
        for link in links:
            if lane == link.to_lane or lane in self._chain(link.via):
                return link
        return None

    def _verdict(self, snap, link: LaneLink, by: str) -> list[Misbehavior]:
        cat = _category(link.state)
        if cat == "red" or (cat == "yellow" and self.config.report_yellow):
            return [self.report(snap, cat, (), tls=link.tls_id, link=link.link_index, state=link.state,
                                lane=self._cand_lane, to_lane=link.to_lane, speed=round(snap.speed, 3),
                                speed_kmh=kmh(snap.speed), decided_by=by)]
        return []

    # -------------------------------------------------------------------- frame
    def on_frame(self, frame: Frame) -> Sequence[Misbehavior]:
        out: list[Misbehavior] = []
        lane = frame.lane
        if self._pending is not None:
            out.extend(self._resolve(frame))
        cand = self._cand
        if cand is not None and cand.crossed(frame.prev_front, frame.front):
            self._cand_lane = cand.lane
            out.extend(self._crossing(frame, self._links, cand.edge))
            self._cand = cand = None
            self._links = ()
        links = frame.lane_links
        if links:
            if cand is None or cand.lane != lane:
                self._cand = self._line(lane)
                self._all_vehicle = all(self._is_vehicle_link(l) for l in links)
            self._links = links if self._all_vehicle else tuple(l for l in links if self._is_vehicle_link(l))
            if not self._links:
                self._cand = None
        elif cand is not None and lane and lane[0] != ":" and lane != cand.lane:
            self._cand = None
            self._links = ()
        return tuple(out)

    def _crossing(self, frame: Frame, links: Sequence[LaneLink], edge: str) -> list[Misbehavior]:
        if not links:
            return []
        snap = SimpleNamespace(index=frame.index, t=frame.t, x=frame.x, y=frame.y, speed=frame.speed)
        cats = {_category(l.state) for l in links}
        if len(cats) == 1:
            return self._verdict(snap, self._taken(links, frame.lane) or links[0], "all")
        taken = self._taken(links, frame.lane)
        if taken is not None:
            return self._verdict(snap, taken, "taken")
        self._pending = (snap, tuple(links), edge, frame.t + self.config.decide_within, self._cand_lane)
        return []

    def _resolve(self, frame: Frame) -> list[Misbehavior]:
        snap, links, edge, deadline, lane = self._pending
        self._cand_lane = lane
        taken = self._taken(links, frame.lane)
        if taken is not None:
            self._pending = None
            return self._verdict(snap, taken, "taken")
        if frame.t < deadline:
            return []
        self._pending = None
        nxt = None
        if edge in self._route:
            k = self._route.index(edge)
            if k + 1 < len(self._route):
                nxt = self._route[k + 1]
        if nxt is not None:
            on_route = [l for l in links if self._rmap.lane(l.to_lane).getEdge().getID() == nxt]
            if on_route and len({_category(l.state) for l in on_route}) == 1:
                return self._verdict(snap, on_route[0], "route")
        return []  # mixed signals and the link taken unknown: not a certain violation

    def on_end(self, trace, termination) -> Sequence[Misbehavior]:
        # A crossing whose link was never identified: decide as at the deadline.
        if self._pending is None:
            return ()
        snap, links, edge, _deadline, lane = self._pending
        self._pending = (snap, links, edge, -math.inf, lane)
        return tuple(self._resolve(SimpleNamespace(lane="", t=math.inf)))
