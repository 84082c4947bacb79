"""Where the ego will be, and where an actor must start to meet it: the mutator's route geometry.

:class:`RoutePlacement` is a mixin of :class:`drivefuzz.search.mutate.Mutator` (it uses its road map
``rmap``, configuration ``cfg``, ``_route`` and caches): the lanes the ego drives along its route and where the
route makes it change lanes, the ego's expected motion along its route (a speed profile
of how the reference ADS drives the empty road), the junction passages and conflict points of the route,
and the placement of linear actors timed to meet the ego there. The fairness rules and the situation
catalogue use the same profile. Never imports libsumo.
"""

from __future__ import annotations

import math
import random
from functools import partial
from typing import Sequence

import numpy as np
from shapely.geometry import LineString, Point

from drivefuzz.scenario import Scenario
from drivefuzz.scenario.roadmap import PASSENGER
from drivefuzz.scenario.signals import shiftable, signal_state
from drivefuzz.search.fairness import lane_limit

#: [m] of route distance per metre driven inside a junction. The mutator measures the ego's route by its edges
#: (:meth:`RoadMap.route_length`); the ego's profile gives the metres in junctions their time but (almost) no
#: distance, so that a place x m into a junction is at its incoming edge's end + ``JUNCTION_M * x``.
JUNCTION_M = 1e-6
#: [m/s^2] a light that turns yellow when the ego is nearer than it stops in at this is passed (ego/ads.py)
LIGHT_STOP_DECEL = 4.0

#: share of what the ego drives of a route edge after which it has changed to the lane the route needs (the
#: reference ADS shifts its path over the middle third: on town and the highway its seed runs change lane 0.1-0.2 s
#: after the profile reaches this share)
LANE_CHANGE_AT = 0.45


class RoutePlacement:
    # ---------------------------------------------------------------- the ego's lanes
    def ego_lane(self, sc: Scenario, i: int) -> str:
        """The lane of route edge ``i`` the ego drives: its start lane on the first edge; after that the lane a
        junction leads it into while that lane leads on along the route, else the lane nearest to it that does
        (a lane-keeping driver: the first connection's lane, as before, was not the ego's on 8 of town's 27
        route edges; issue 33)."""
        return sc.mission.start_lane if i == 0 else self._lane_keeping(sc)[i][1]

    def ego_entry_lane(self, sc: Scenario, i: int) -> str:
        """The lane the ego enters route edge ``i`` by (its start lane on the first): where it is not the lane it
        drives on to the next edge, the route makes the ego change lanes on that edge (:meth:`lane_change_at`)."""
        return self._lane_keeping(sc)[i][0]

    def lane_change_at(self, sc: Scenario, i: int) -> float | None:
        """[m] the lane position on route edge ``i`` where the ego changes lanes, None where it does not: across
        the middle of what it drives of the edge (:data:`LANE_CHANGE_AT`)."""
        entry, lane = self._lane_keeping(sc)[i]
        if entry == lane:
            return None
        a = sc.mission.start_pos if i == 0 else 0.0
        return a + LANE_CHANGE_AT * (self.rmap.edge(self._route(sc)[i]).getLength() - a)

    def ego_lane_at(self, sc: Scenario, i: int, pos: float) -> str:
        """The lane the ego is on at lane position ``pos`` [m] of route edge ``i``: the lane it entered by before
        its lane change there (:meth:`lane_change_at`), after it the lane it drives on to the next edge."""
        entry, lane = self._lane_keeping(sc)[i]
        at = self.lane_change_at(sc, i)
        return entry if at is not None and pos < at else lane

    def ego_connection(self, sc: Scenario, i: int) -> tuple[str, str, str] | None:
        """(from lane, to lane, via) of the connection the ego takes from route edge ``i`` to the next: out of the
        lane it drives there (:meth:`ego_lane`) into the lane it enters the next edge by; None at the route's end
        or where the edges do not connect. (The junction passage used to be the connection nearest the start
        lane's index: on town's B3 the ego comes out of its left turn at C3 on the left lane, where the side road's
        left turners merge, but the passage was looked for on the right lane, and no crossing car could be aimed
        at B3.)"""
        route = self._route(sc)
        conns = self.rmap.connections(route[i], route[i + 1]) if i + 1 < len(route) else []
        if not conns:
            return None
        lane, into = self.ego_lane(sc, i), self.ego_entry_lane(sc, i + 1)
        mine = [c for c in conns if c[0] == lane] or conns
        index = self.rmap.lane(lane).getIndex()
        return min(mine, key=lambda c: (c[1] != into, abs(self.rmap.lane(c[0]).getIndex() - index)))

    def _lane_keeping(self, sc: Scenario) -> list[tuple[str, str]]:
        """Per route edge (the lane the ego enters it by, the lane it drives on to the next)."""
        key = (sc.mission.start_lane, sc.mission.goal_edge)
        if key in self._ego_lanes:
            return self._ego_lanes[key]
        route, rmap = self._route(sc), self.rmap
        lanes, cur = [], sc.mission.start_lane
        for i, e in enumerate(route):
            if rmap.lane(cur).getEdge().getID() != e:
                cur = rmap.drive_lane(e)
            entry = cur
            conns = rmap.connections(e, route[i + 1]) if i + 1 < len(route) else []
            leads = sorted({c[0] for c in conns})
            if leads and cur not in leads:
                idx = rmap.lane(cur).getIndex()
                cur = min(leads, key=lambda ln: abs(rmap.lane(ln).getIndex() - idx))
            lanes.append((entry, cur))
            if conns:
                after = {c[0] for c in rmap.connections(route[i + 1], route[i + 2])} if i + 2 < len(route) else None
                mine = [c for c in conns if c[0] == cur]
                cur = next((c[1] for c in mine if after is None or c[1] in after), mine[0][1])
        self._ego_lanes[key] = lanes
        return lanes

    # ---------------------------------------------------------------- roads, and the ego's motion
    def _road_side(self, lane_id: str) -> float:
        """+1 when the rest of the road lies to the left of a walker's lane (a right-hand sidewalk, or the
        rightmost lane of a road without sidewalks), else -1."""
        lane = self.rmap.lane(lane_id)
        road = [l.getIndex() for l in lane.getEdge().getLanes() if l.allows(PASSENGER) and l.getID() != lane_id]
        return 1.0 if not road or lane.getIndex() < min(road) else -1.0

    def _road_width(self, lane_id: str) -> float:
        """[m] across every lane of ``lane_id``'s edge except ``lane_id`` itself, plus half of it."""
        lane = self.rmap.lane(lane_id)
        return sum(l.getWidth() for l in lane.getEdge().getLanes() if l.getID() != lane_id) + lane.getWidth() / 2

    def _ego_profile(self, sc: Scenario) -> tuple[np.ndarray, np.ndarray]:
        """The ego's expected (distance [m] from its start, time [s]) along its route, at 1 m steps.

        A speed cap per metre (``ego_speed_share`` of the limit; in junctions also ``sqrt(ego_lat_accel /
        curvature)``), then a forward pass accelerating at ``ego_accel`` and a backward pass braking at
        ``ego_decel``: how the reference ADS drives an empty road. At a fixed-time light (with the scenario's
        signal shifts) that shows its link red or yellow as it arrives, it stops at the line and waits for green
        (without this, every place past a red light was timed up to a cycle early: 37 s on town's seed 006).

        The distance is counted as the mutator counts it everywhere else (:meth:`RoadMap.route_length`, the
        route's edge lengths): the metres driven inside junctions take their time but add nothing to it. (They
        used to add to it, so every actor timed by this profile for a place past a junction arrived early by the
        time the ego spends in the junctions before it: 1-2 s per junction on town, 15-20 m each.) Each step is
        one metre driven: the speed at a step is 1 m over its time.

        Where the ADS under test was seen driving this mission with no light shifted (:meth:`observe`: the
        seed's own run, in a fuzz job), a scenario of that mission takes that run's times instead: on the
        highway the reference ADS drives 11-16 m/s where the empty-road model says 31 m/s, so every actor timed
        by the model came too early. With lights shifted, the run's times plus the difference the shifts make to
        the model's (a wait at a light shifted to red, none where one shifted to green; tenth session: the model
        alone timed the lights shifted for amber, and everything aimed at them, by an empty-road pace)."""
        m = sc.mission
        key = (m.start_lane, m.start_pos, m.goal_edge, m.start_speed, tuple((x.tls, x.shift) for x in sc.signals))
        if key in self._profile_cache:
            return self._profile_cache[key]
        seen = self._observed.get(_pace_key(m))
        s_route, t = self._model_profile(sc)
        if seen is not None and sc.signals:  # the run's pace, plus what the shifted lights change in the model
            _, plain, waits = self._model_profile(sc.model_copy(update={"signals": ()}), waits=True)
            t = _waits_at_lines(_observed_times(plain, *seen), waits) + (t - plain)
        elif seen is not None:
            t = _observed_times(t, *seen)
        self._profile_cache[key] = (s_route, t)
        return self._profile_cache[key]

    def observe(self, sc: Scenario, travelled: list[float], every: float) -> None:
        """The ego's metres driven from its start every ``every`` s of a run of ``sc``'s mission with the ADS under
        test, no light shifted: scenarios of that mission are timed by it (:meth:`_ego_profile`)."""
        if sc.signals:  # its run waited at shifted lights: it says nothing of the mission's own
            return
        key = _pace_key(sc.mission)
        self._observed[key] = (np.asarray(travelled, dtype=float), every)
        self._profile_cache = {}

    def _model_profile(self, sc: Scenario, waits: bool = False):
        """(the route distance [m] of each step, its time [s]) of the empty-road model (:meth:`_ego_profile`); with
        ``waits``, also {step index of a stop line: [s] waited there} of the lights it stops at."""
        m = sc.mission
        cfg, rmap, route = self.cfg, self.rmap, self._route(sc)
        caps: list[np.ndarray] = []
        ds: list[np.ndarray] = []  # per step, the route distance it adds (an edge's metres; ~0 in a junction)
        lights: list[tuple[int, str, int]] = []  # (step index of the stop line, tls, the ego's link index)
        for i, e in enumerate(route):
            length = rmap.edge(e).getLength() - (m.start_pos if i == 0 else 0.0)
            caps.append(np.full(max(int(length), 1), cfg.ego_speed_share * rmap.edge(e).getSpeed()))
            ds.append(np.full(len(caps[-1]), max(length, 0.0) / len(caps[-1])))
            if i + 1 < len(route):
                passage = self.ego_connection(sc, i)
                if passage is None:
                    continue
                fl, _tl, via = passage
                conn = next((c for c in rmap.lane(fl).getOutgoing() if c.getToLane().getID() == _tl), None)
                if conn is not None and conn.getTLSID() and shiftable(str(rmap.path), conn.getTLSID()) is not None:
                    lights.append((sum(len(c) for c in caps), conn.getTLSID(), conn.getTLLinkIndex()))
                chain = self._internal_chain(via)
                length = sum(rmap.geom(lid).length for lid in chain)
                pts = np.vstack([rmap.geom(fl).pts[-2:]] + [rmap.geom(lid).pts for lid in chain]
                                + [rmap.geom(_tl).pts[:2]])
                heading = np.unwrap(np.arctan2(*np.diff(pts, axis=0).T[::-1]))
                k = abs(float(heading[-1] - heading[0])) / max(length, 1.0)  # mean curvature [1/m]
                v = cfg.ego_speed_share * rmap.geom(chain[0]).speed if chain else caps[-1][-1]
                if k > 1e-4:
                    v = min(v, math.sqrt(cfg.ego_lat_accel / k))
                caps.append(np.full(max(int(round(length)), 1), v))
                ds.append(np.full(len(caps[-1]), JUNCTION_M))
        cap = np.maximum(np.concatenate(caps), 0.5)
        s_route = np.concatenate([[0.0], np.cumsum(np.concatenate(ds))])
        shifts = {x.tls: x.shift for x in sc.signals}
        stops: dict[int, float] = {}  # step index of a stop line -> [s] waited there for green
        t = self._profile_times(cap, m.start_speed, stops)
        for j, tls, link in lights:  # in route order: a red one delays every later arrival
            stops[j] = 0.0
            del stops[j]
            t = self._profile_times(cap, m.start_speed, stops)
            wait = self._red_wait(t, j, partial(signal_state, str(rmap.path), tls, link, shift=shifts.get(tls, 0.0)))
            if wait is not None:
                stops[j] = 0.0
                t = self._profile_times(cap, m.start_speed, stops)  # it brakes to the line: arrives later
                stops[j] = self._red_wait(t, j, partial(signal_state, str(rmap.path), tls, link,
                                                        shift=shifts.get(tls, 0.0)), stopping=True) or 0.0
                t = self._profile_times(cap, m.start_speed, stops)
        return (s_route, t, stops) if waits else (s_route, t)

    @staticmethod
    def _red_wait(t: np.ndarray, j: int, state, stopping: bool = False) -> float | None:
        """[s] the ego waits at the stop line at step ``j`` of a profile with the times ``t``, where ``state(time)``
        is its link's state; None where it drives on: the light is green as it arrives, or it turned yellow when
        the ego was too near to stop at :data:`LIGHT_STOP_DECEL` (it goes, as the reference ADS does). With
        ``stopping``, ``t`` already brakes to the line: only the wait for green is asked."""
        t_arr = float(t[j])
        if not stopping:
            if state(t_arr) in (None, "g", "G", "o", "O"):
                return None
            # when the light turned from green (at most a cycle before), was the ego far enough to stop?
            t_y = next((t_arr - 0.5 * q for q in range(1, 400) if state(t_arr - 0.5 * q) in ("g", "G")), None)
            if t_y is not None and t_y > 0.0:
                k = int(np.clip(np.searchsorted(t, t_y), 0, len(t) - 2))
                v = 1.0 / max(float(t[k + 1] - t[k]), 1e-6)  # each step is 1 m driven
                if j - k < v * v / (2 * LIGHT_STOP_DECEL):
                    return None
            return 0.0
        return next((0.5 * q for q in range(0, 400) if state(t_arr + 0.5 * q) in ("g", "G")), 0.0)

    def _profile_times(self, cap: np.ndarray, v0: float, stops: dict[int, float]) -> np.ndarray:
        """[s] at each step of a profile with the speed caps ``cap`` (one per metre), starting at ``v0`` [m/s],
        stopping at the step indices of ``stops`` and waiting there as long as each says."""
        cfg = self.cfg
        v = np.empty(len(cap) + 1)
        v[0] = min(v0, cap[0])
        for j in range(len(cap)):  # forward: accelerate (from a standstill after a stop)
            v[j + 1] = 0.0 if j + 1 in stops else min(cap[j], math.sqrt(v[j] ** 2 + 2 * cfg.ego_accel))
        for j in range(len(cap) - 1, -1, -1):  # backward: brake ahead of slow parts and stops
            v[j] = min(v[j], math.sqrt(v[j + 1] ** 2 + 2 * cfg.ego_decel))
        dt = 2.0 / np.maximum(v[:-1] + v[1:], 1e-3)  # 1 m at the mean speed
        for j, wait in stops.items():
            if 0 < j <= len(dt):
                dt[j - 1] += wait
        return np.concatenate([[0.0], np.cumsum(dt)])

    def _ego_eta(self, sc: Scenario, dist: float) -> float:
        """[s] until the ego's front bumper is expected ``dist`` metres along its route."""
        s, t = self._ego_profile(sc)
        return float(np.interp(dist, s, t))

    def _ego_progress(self, sc: Scenario, t: float) -> float:
        """[m] the ego's front bumper is expected to have covered at time ``t`` [s]."""
        s, ts = self._ego_profile(sc)
        return float(np.interp(t, ts, s))

    def _via_length(self, from_lane: str, to_lane: str) -> float:
        """[m] through the junction from the end of ``from_lane`` to the start of ``to_lane`` (0 if direct)."""
        for c in self.rmap.lane(from_lane).getOutgoing():
            if c.getToLane().getID() == to_lane and c.getViaLaneID():
                return sum(self.rmap.lane(v).getLength() for v in self._internal_chain(c.getViaLaneID()))
        return 0.0

    def _upstream(self, lane_id: str, pos: float, back: float, rng: random.Random,
                  route: Sequence[str] = ()) -> tuple[str, float, float] | None:
        """(lane, pos, driving distance [m]) about ``back`` metres of driving upstream of (lane_id, pos), through
        incoming passenger lanes and the junctions between them; at least ``back`` (an actor never stands
        inside a junction). Where an incoming lane lies on an edge of ``route`` (the ego's), one of those: a car
        that comes up behind the ego came its way. None when the road ends first."""
        covered = 0.0
        for _ in range(4):
            if pos - back >= 1.0:
                new_pos = round(min(pos - back, self.rmap.lane(lane_id).getLength() - 0.5), 2)
                return lane_id, new_pos, covered + pos - new_pos
            ins = [l for l in self.rmap.lane(lane_id).getIncoming()
                   if l.getEdge().getFunction() == "" and l.allows(PASSENGER)]
            if not ins:
                return None
            lane = rng.choice([l for l in ins if l.getEdge().getID() in route] or ins)
            via = self._via_length(lane.getID(), lane_id)
            covered += pos + via
            back = max(back - pos - via, 0.0)
            lane_id, pos = lane.getID(), lane.getLength()
        return None

    def _rear_place(self, sc: Scenario, rng: random.Random, speed: float):
        """Behind the ego on its own lane, close enough that at ``speed`` it catches the accelerating ego."""
        ego_len = 4.6  # [m] the reference car's body; only sharpens the timing
        # largest front-to-front gap [m] from which the actor still reaches the ego's rear bumper within 30 s
        g_max = max(speed * t - self._ego_progress(sc, t) + ego_len for t in (0.25 * k for k in range(1, 121)))
        g_min = self.cfg.min_separation + ego_len / 2
        if g_max < g_min:
            return None
        gap = rng.uniform(g_min, min(g_max, g_min + self.cfg.behind_range))
        m = sc.mission
        placed = self._upstream(m.start_lane, m.start_pos, gap, rng)
        if placed is None or placed[2] > g_max:
            return None
        lane, pos, gap = placed
        dest = self._route(sc)[-1]
        actor_route = self.rmap.route(self.rmap.lane(lane).getEdge().getID(), dest)
        if not actor_route or m.start_edge not in actor_route:
            return None
        return lane, pos, speed, dest, f", {gap:.1f} m behind the ego"

    def _internal_chain(self, via: str) -> list[str]:
        """Every internal lane of a junction passage that starts with ``via`` (also past internal stop lines)."""
        chain: list[str] = []
        while via and via not in chain:
            chain.append(via)
            nxt = ""
            for c in self.rmap.lane(via).getOutgoing():
                to = c.getToLane()
                nxt = to.getID() if to.getEdge().getFunction() == "internal" else (c.getViaLaneID() or "")
                break
            via = nxt
        return chain

    def _passage(self, from_lane: str, to_lane: str, via: str) -> LineString:
        """The centre line through a junction: the internal lanes of a connection, then ``to_lane``'s first metres."""
        pts: list = [tuple(self.rmap.geom(from_lane).pts[-1])]
        for lid in self._internal_chain(via):
            pts.extend(map(tuple, self.rmap.geom(lid).pts))
        g = self.rmap.geom(to_lane)
        pts.extend(map(tuple, g.pts[g.cum < 15.0]))
        pts.append(self.rmap.geom(to_lane).position(min(15.0, g.length))[:2])
        return LineString(pts)

    def _conflicts(self, sc: Scenario, whole: bool = False,
                   zone: float = 2.0) -> list[tuple[int, float, str, str, float, str, str, str]]:
        """Ways to cross the ego's path at the junctions of its route within ``conflict_range`` (along all of it
        with ``whole``: an aim at a junction's cell; on town seed 000's priority junction B3 lies 289 m on):
        (route index of the junction's incoming edge, ego distance [m] from its start to the conflict point,
        actor lane entering the junction, actor destination edge, actor distance [m] from that lane's end to
        the conflict point, junction id, the ego's and the actor's link states: 'M' major, 'm' minor, 's'
        stop, 'w' all-way stop, 'o' signalised...). Cached per mission."""
        m = sc.mission
        key = (m.start_lane, m.start_pos, m.goal_edge, whole, zone)
        if key in self._conflict_cache:
            return self._conflict_cache[key]
        rmap, route = self.rmap, self._route(sc)
        out = []
        s = -m.start_pos
        for i, e in enumerate(route[:-1]):
            s += rmap.edge(e).getLength()
            if s > self.cfg.conflict_range and not whole:
                break
            passage = self.ego_connection(sc, i)
            if passage is None:
                continue
            fl, tl, via = passage
            ego_state = next((c.getState() for c in rmap.lane(fl).getOutgoing() if c.getToLane().getID() == tl), "")
            ego_line = self._passage(fl, tl, via)
            via_len = sum(rmap.geom(lid).length for lid in self._internal_chain(via))
            ego_zone = ego_line.buffer(zone)  # closer centre lines than this (2 m): the bodies meet
            node = rmap.edge(e).getToNode()
            for inc in node.getIncoming():
                if inc.getID() == e or inc.getFunction() != "":
                    continue
                for lane in inc.getLanes():
                    if not lane.allows(PASSENGER):
                        continue
                    for c in lane.getOutgoing():
                        to = c.getToLane()
                        if to.getEdge().getFunction() != "" or to.getEdge().getToNode() is inc.getFromNode():
                            continue
                        line = self._passage(lane.getID(), to.getID(), c.getViaLaneID() or "")
                        hit = line.intersection(ego_zone)
                        if hit.is_empty:
                            continue
                        d_actor = min(line.project(Point(xy)) for xy in _coords(hit))
                        pt = line.interpolate(d_actor)
                        out.append((i, s + _into_junction(ego_line.project(pt), via_len), lane.getID(),
                                    to.getEdge().getID(), d_actor,
                                    node.getID(), ego_state, c.getState()))
        self._conflict_cache[key] = out
        return out

    def _signals_ahead(self, sc: Scenario) -> list[tuple[float, str, int]]:
        """The fixed-time traffic lights the ego meets on its route within ``conflict_range``: (distance [m]
        from its start to the stop line, tls id, the ego's link index), in route order."""
        rmap, route, m = self.rmap, self._route(sc), sc.mission
        out = []
        s = -m.start_pos
        for i, e in enumerate(route[:-1]):
            s += rmap.edge(e).getLength()
            if s > self.cfg.conflict_range:
                break
            fl = self.ego_lane(sc, i)
            conn = next((c for c in rmap.lane(fl).getOutgoing() if c.getToLane().getEdge().getID() == route[i + 1]),
                        None)
            if conn is None:
                continue
            if conn.getTLSID() and shiftable(str(rmap.path), conn.getTLSID()) is not None and s > 0:
                out.append((s, conn.getTLSID(), conn.getTLLinkIndex()))
        return out

    def _cross_place(self, sc: Scenario, rng: random.Random, speed: float):
        """On another approach to a junction of the ego's route, timed to reach the point where its path
        crosses (or merges into) the ego's just as the ego gets there: a side impact if nobody yields."""
        # a reckless driver crosses only where it has the right of way anyway: the ego must yield to it there
        options = [o for o in self._conflicts(sc) if o[6] in ("m", "s", "w") and o[7] == "M"]
        if not options:
            return None
        i, s_c, lane_id, dest, d_c, node, _, _ = rng.choice(options)
        # the ego's front reaches the conflict point at about t_c (the profile runs a little early, and a
        # reference ADS that sees the actor in its path first simply stops): arrive while the ego's body is there
        t_c = self._ego_eta(sc, s_c)
        t_meet = t_c + rng.uniform(0.0, 1.2)
        rmap = self.rmap
        lane_len = rmap.lane(lane_id).getLength()
        back = speed * t_meet - d_c
        placed = self._upstream(lane_id, lane_len, back, rng) if back > 0 else None
        if placed is None:  # not enough road upstream: start as far back as possible, slower
            placed = (lane_id, 1.0, lane_len - 1.0)
        speed = round((placed[2] + d_c) / max(t_meet, 0.1), 2)  # the junctions on the way make it longer
        limit = min(lane_limit(self, lane_id) * self.cfg.vehicle_speed_share[1], self.cfg.max_vehicle_speed)
        if not 0.3 * limit <= speed <= limit:
            return None
        lane, pos, _ = placed
        actor_route = rmap.route(rmap.lane(lane).getEdge().getID(), dest)
        if not actor_route or rmap.lane(lane_id).getEdge().getID() not in actor_route:
            return None
        return lane, pos, speed, dest, f", crosses the ego's path at {node} at ~{t_meet:.1f} s"


def _into_junction(x: float, via_len: float) -> float:
    """[m] route distance from a junction's entry to a point ``x`` m along the ego's passage through it (the
    junction's ``via_len`` m, then the next edge)."""
    return JUNCTION_M * min(x, via_len) + max(x - via_len, 0.0)


def _coords(geom) -> list[tuple[float, float]]:
    """Every vertex of a shapely geometry (collections and multi-parts included)."""
    if hasattr(geom, "geoms"):
        return [xy for g in geom.geoms for xy in _coords(g)]
    if geom.geom_type == "Polygon":
        return list(geom.exterior.coords)
    return list(geom.coords)


def _pace_key(m) -> tuple:
    """What a run's pace is kept under: the mission less its start lane (a start on another lane of the same edge,
    :func:`drivefuzz.search.aim_place.shifted_start`, drives the route at the pace of its seed: timed by the model
    instead, its lineage lost the ADS's own pace), with its start speed (one that enters moving does not)."""
    return m.start_edge, m.start_pos, m.goal_edge, m.start_speed


#: [m] before a stop line where the model waits that a standstill of the ADS's run is its wait at that light (a queue
#: ahead of it, or its front short of the line: coverage.ARRIVAL_M)
LINE_WAIT_M = 30.0
#: [s] a run's time over one metre above which it stood there
STOOD_S = 1.0


def _waits_at_lines(t_run: np.ndarray, waits: dict[int, float]) -> np.ndarray:
    """The times ``t_run`` of a run's profile (:func:`_observed_times`) with its wait at each light where the model
    waits (``waits``: step of the stop line -> [s]) moved to the line. The run stands its front a metre or two short
    of the line (1.5 m at interchange's tN), the model at it: the metres between took the whole wait, and everything
    timed there with the light shifted (the ego's arrival at a light shifted to turn yellow as it comes, say) was
    that wait late (interchange seed 007, 28 s: the light turned yellow long after the ego had passed on green)."""
    out = t_run.copy()
    for j, wait in waits.items():
        lo = max(j - int(LINE_WAIT_M), 2)
        if wait <= 0.0 or j - lo < 1 or j >= len(out):
            continue
        per_m = np.diff(out[lo - 1:j])  # [s] per metre over the steps lo..j-1
        k = int(np.argmax(per_m))
        stood = float(per_m[k] - per_m[max(k - 1, 0)]) if k > 0 else 0.0
        if stood > STOOD_S:
            out[lo + k:j] -= stood
    return out


def _observed_times(t_model: np.ndarray, travelled: np.ndarray, every: float) -> np.ndarray:
    """The times [s] of a profile's steps (one metre driven each, :meth:`RoutePlacement._ego_profile`) as a run
    drove them (``travelled``: metres driven every ``every`` s); past the run's last metre, the model's time
    differences carry on from there."""
    steps = np.arange(len(t_model), dtype=float)
    d = np.maximum.accumulate(travelled) + 1e-6 * np.arange(len(travelled))  # strictly rising for interp
    t_run = every * np.arange(len(travelled), dtype=float)
    out = np.interp(steps, d, t_run)
    last = int(min(np.searchsorted(steps, d[-1], side="right"), len(t_model))) - 1
    if last < len(t_model) - 1:
        out[last + 1:] = out[max(last, 0)] + (t_model[last + 1:] - t_model[max(last, 0)])
    return out
