"""The standstill rules of attribution: an ego that stood still (immobility) or did not reach its goal in time
(mission): blocked, a pedestrian in its lane, a queue that will move, held up behind slower traffic it could not pass
(excuses), or it stayed behind a stationary body, or trailed slower traffic, with a lawful lane free (the ego's,
decided).

A mixin of :class:`drivefuzz.triage.attribute._Event` (rule 6 of :mod:`drivefuzz.triage.attribute`, whose docstring
gives the order and which of these excuses the careful driver's replay tests): it reads the event's ``trace``,
frame ``f``, ``rmap``, ``scenario``, misbehaviour ``mb`` and ego speed ``v``, and gives its verdict through
``other``/``ego``.

Units: SI; positions along a lane from its start.
"""

from __future__ import annotations

from typing import Mapping

from drivefuzz.triage.blockage import blocked_lanes, held_up, never_moved, passing_lanes
from drivefuzz.triage.evidence import actor_track
from drivefuzz.triage.verdict import KEPT, Attribution

#: [m] room a driver needs past a stationary body to merge back into a lane that leads on along the route.
MERGE_ROOM = 20.0


def _were_free(lanes: list[str]) -> str:
    """'A was free', 'A and B were free', 'A, B and C were free'."""
    if len(lanes) < 2:
        return f"{''.join(lanes)} was free"
    return f"{', '.join(lanes[:-1])} and {lanes[-1]} were free"


class StandstillRules:
    """The standstill rules, as methods of the event they judge (:meth:`standstill` gives the verdict)."""

    def _leads(self) -> set[str] | None:
        """The lanes of the ego's edge that connect to its route's next edge; None when any lane will do
        (the goal edge, off the route, or in a junction)."""
        m = self.scenario.mission
        route = self.rmap.route(m.start_edge, m.goal_edge) or ()
        lane = str(self.trace["lane"][self.f])
        if not lane or lane.startswith(":") or not self.rmap.has_lane(lane):
            return None
        edge = self.rmap.lane(lane).getEdge().getID()
        if edge not in route or route.index(edge) + 1 >= len(route):
            return None
        return {fl for fl, _tl, _via in self.rmap.connections(edge, route[route.index(edge) + 1])}

    def _leading_on(self, free: list[str], blocked: Mapping[str, str], leads: set[str] | None) -> list[str]:
        """The free lanes that are a way forward along the route: a lane that connects to the route's next
        edge, or one the ego can pass the blocker on and still merge back (:data:`MERGE_ROOM` before the
        end of a blocked lane that connects); ``leads``: :meth:`_leads`."""
        if leads is None:
            return free
        out = [l for l in free if l in leads]
        if out or not free:
            return out
        for l, body in blocked.items():  # pass on a free lane, merge back into a blocked one that leads on
            if l in leads and self._room_after(l, body) >= MERGE_ROOM:
                return free
        return []

    def _room_to_pass(self, lanes: Mapping[str, str], leads: set[str] | None) -> list[str]:
        """The blocked lanes that do not block the way: a neighbour of a lane that leads on, whose
        stationary body stands at least :data:`MERGE_ROOM` (bumper to bumper) beyond that lane's blocker,
        which has the same room after it. The ego can pass the blocker there and merge back in front of it."""
        out = set()
        for l, body in lanes.items():
            if (leads is not None and l not in leads) or self._room_after(l, body) < MERGE_ROOM:
                continue
            end = self._along(l, body) + actor_track(self.trace, body).length / 2
            for n, other in lanes.items():
                if n != l and self._along(n, other) - actor_track(self.trace, other).length / 2 - end >= MERGE_ROOM:
                    out.add(n)
        return sorted(out)

    def _along(self, lane: str, body: str) -> float:
        """[m] of ``body``'s centre along ``lane`` at the event."""
        tr = actor_track(self.trace, body)
        return self.rmap.geom(lane).project(float(tr.x[self.f]), float(tr.y[self.f]))[0]

    def _room_after(self, lane: str, body: str) -> float:
        """[m] of ``lane`` left beyond ``body``'s centre."""
        return self.rmap.geom(lane).length - self._along(lane, body)

    def standstill(self) -> Attribution:
        trace, f = self.trace, self.f
        if self.v > 0.5:
            held = held_up(trace, f)
            if self.mb.kind == "timeout" and held is not None:
                share, leader = held
                # slower traffic with a lawful lane free beside it (free of slower traffic too, and leading on): not
                # passing it is the ego's, decided, as staying behind a stationary body is (the careful driver does
                # not overtake either, so its replay would say nothing)
                limit = float(trace["speed_limit"][f])
                free = passing_lanes(trace, self.rmap, f, 0.8 * limit)
                free = self._leading_on(free, {}, self._leads()) if free else []
                if free:
                    return self.ego("trailed", f"the ego trailed slower traffic ({leader}) for {share:.0%} of the run "
                                    f"although {_were_free(free)}", decided=True, held_share=share, leader=leader,
                                    free_lanes=free)
                # kept without a replay: a replay would test the leader, not the ego (a scripted leader slows when the
                # ego follows within a headway, tests/data/crawling_leader_on_the_ring: a careful driver 2 s back
                # never sets it off)
                return self.other("held_up", f"held up behind slower traffic ({leader}) for {share:.0%} of the run",
                                  held_share=share, leader=leader,
                                  **{KEPT: "a leader it cannot pass holds up any driver behind it, a careful one too"})
            # a moving ego, not held up: fog, rain and ice slow a careful driver too, and a time limit too
            # short for the route holds for everyone, which its replay shows
            self.replay_may_settle = self.mb.kind == "timeout"
            return self.ego("slow", f"the ego did not reach its goal in time ({self.mb.oracle}/{self.mb.kind})")
        blocked = blocked_lanes(trace, self.rmap, f)
        if blocked is None:
            self.replay_may_settle = True  # the rules may have missed a blocker (mid-turn in a junction)
            return self.ego("no_blocker", f"the ego stood still with nothing blocking its way ({self.mb.oracle}/{self.mb.kind})")
        lanes, free, queue, root = blocked
        leads = self._leads()
        passable = self._room_to_pass(lanes, leads)
        lanes = {l: b for l, b in lanes.items() if l not in passable}
        free = self._leading_on(free + passable, lanes, leads)
        ev = {"lanes": {l: b for l, b in lanes.items()}, "free_lanes": free}
        own = lanes.get(str(trace["lane"][f]))
        if own is not None and actor_track(trace, own).kind == "pedestrian":
            return self.other("pedestrian_in_lane", f"the pedestrian {own} stands in the ego's path", **ev)
        if not free and lanes:
            what = ", ".join(f"{l} by {b}" for l, b in lanes.items())
            return self.other("blocked", f"every lawful way forward is blocked by stationary bodies: {what}", **ev)
        if queue is not None and (leads is None or str(trace["lane"][f]) in leads):  # a queue on the way on
            return self.other("queue", f"the ego waits in a queue that will move: {queue}", queue=queue, **ev)
        behind = own or next(iter(lanes.values()), None)  # mid-lane-change: the blocker of the lane it wants
        were_free = _were_free(free)
        if behind is not None:
            if root is not None and own is not None:  # a queue that will not move: the blocker is its head
                how = "parked" if never_moved(actor_track(trace, root), f) else "stalled"
                ev["blocker"] = root
                return self.ego("stayed_behind", f"the ego stayed behind the stationary {behind} in a queue that the {how} {root} "
                                f"holds up, although {were_free}", decided=True, **ev)
            return self.ego("stayed_behind", f"the ego stayed behind the stationary {behind} although {were_free}",
                            decided=True, **ev)
        return self.ego("stood_still", f"the ego stood still although {were_free}", decided=True, **ev)
