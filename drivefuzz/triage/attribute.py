"""Attribution: was a misbehaviour the ego's fault?

Used by the fuzz loop's triage (a finding is reported only when the ego is at fault; the
rest are incidents) and by the signatures (:mod:`drivefuzz.triage.signature`).

:func:`attribute` reads the frozen trace, the scenario and the road map. Two sources decide:

- **Rules on the trace** (each gives ``other`` with its evidence, or does not apply):

  0. (``ego``, decided) the ego entered the junction on red; its link had to yield to the other's;
     it changed lanes into a vehicle alongside (moved sideways towards it more than it came);
  1. *stationary*: the ego stood still when it was struck, since :data:`STOPPED_BEFORE` seconds at least
     (and stood where it may: it had not just crossed a stop line on red, and it did not reach more than
     :data:`IN_LANE_MARGIN` into the lane of a vehicle that kept that lane and struck it; such an ego stood in
     that vehicle's way, the ego's fault unless the careful driver's replay is struck too);
  2. *rear*: the ego was struck in its rear half while lawfully in its lane (no lane change in
     the last :data:`LANE_CHANGE_WINDOW` seconds, no red light crossed) and it had not braked
     harder than :data:`COMFORT_DECEL` without a hazard ahead;
  3. *cut-in*: a vehicle moved into the ego's lane ahead of it (its body wholly outside the lane, then in it,
     within :data:`CUT_IN_WINDOW` seconds) or alongside it, and a careful driver reacting
     (``CAREFUL_REACTION``) and braking (``CAREFUL_DECEL``, less on low friction) from when it began to
     move over would still have reached where it went (the careful driver the fairness rules assume);
  4. *right of way*: the other vehicle entered the junction on red, or from a link that must
     yield to the ego's (SUMO's junction logic: the response bits of the two connections),
     while the ego entered lawfully;
  5. *pedestrian*: a pedestrian entered the ego's path (or walked into its side) closer than the
     distance the ego needed to stop: reaction time plus braking at the grip under it
     (``min(mu g, max brake)``), counted from the later of the moment it entered the path and
     the moment the ego could see it (sensor range shortened by fog and rain, field of view,
     line of sight past other vehicles);
  6. *blocked* (immobility and mission): every lane the ego may lawfully use is blocked ahead by a
     stationary body (in a junction: the body right ahead), a pedestrian stands in its lane ahead,
     or the ego waits in a queue that will move (no parked car in it, and its head waits at the end of
     its lane, in a junction, or for a body ahead of it); a mission time-out while the ego spent most
     of the run held up behind slower traffic it could not pass. Waiting behind a stationary body with a
     lawful lane free is the ego's (decided: the careful driver does not overtake either), also when cars
     queue between the ego and that body (a parked car in the queue, or a car stalled in mid-lane at its
     head: it will not move); so is trailing slower traffic to a time-out with a lawful lane beside it free
     of slower traffic (``trailed``).

  Rules 1-4 excuse the ego only for a body that came to it: one that moved in the last
  :data:`APPROACH_WINDOW` seconds (farther than the stationary speed takes a body, or farther than
  the ego). An ego that crept (below the stationary speed) into a parked car, or drove into a car
  that stood in a junction it had entered on red, struck it.

- **Excuses are hypotheses** that the careful driver's replay tests
  (:func:`drivefuzz.triage.counterfactual.test_excuse`, which says when the excuse holds), when the caller gives
  ``replay``: an excusing rule's ``other`` holds only if the careful driver fails the same way, or its replay says
  nothing about the event; otherwise the verdict is the ego's, under the rule of :data:`AVOIDED`, and its reason
  says what the careful driver did instead. Three excuses hold without a replay (their evidence says why, under
  :data:`KEPT`, and their reason says it after "no replay needed"), because the ego could not have been elsewhere
  in a way that matters, or a replay would test another party rather than the ego:

  - *stationary*, struck in its rear half by a vehicle that did not slow by more than 1 m/s in the
    :data:`APPROACH_WINDOW`: such a car strikes whatever stands or drives slower in that lane, wherever the
    ego had stopped, and the ego stood lawfully there (not on red, not reaching into another's lane);
  - *rear*, struck from behind while lawfully in its lane and braking no harder than :data:`COMFORT_DECEL`:
    the follower's to avoid by any driver's standard. A hard stop for a hazard keeps the rule's excuse only if
    the careful driver, who anticipates, had to brake and was struck too; so does any stop just after the ego took
    its way through a junction ahead of the follower on a link that had to yield to the follower's
    (:data:`YIELD_WINDOW`): a careful driver yields there, and the follower is then ahead of it, not behind
    (tests/data/merged_ahead_of_a_car_it_had_to_yield_to_then_braked_hard: the careful driver let a car that never
    brakes turn in ahead of it, which struck the ego, braking hard with the ``no_walker_prediction`` fault or gently
    without it). SUMO's own followers brake for the ego (their emergency braking, 9 m/s^2, matches its hardest), so
    the follower that strikes a braking ego is one that never brakes (a linear car), which strikes a careful driver
    in its lane as well: the careful driver escapes it by not being in that lane ahead of it (it yielded to it);
  - *held up* (a time-out behind slower traffic it could not pass: no lawful lane beside it that leads on was
    free of slower traffic at the end): a leader holds up any driver behind it alike. A replay tests the leader
    instead: the fuzzer's leaders may slow when the ego follows within a headway (a maneuver's headway trigger),
    and a careful driver 2 s back does not set one off
    (tests/data/crawling_leader_on_the_ring: the clean ADS followed within 1.97 s, and the careful driver's
    replay got on; tests/data/held_up_behind_a_leader_it_slowed: a ``narrow_corridor`` ego came within 0.8 s).

  Without ``replay`` an excuse stands from the rules alone (the triage's first, cheap verdict that names the
  signature; :func:`needs_replay` says which verdicts the triage must replay before it files them).

- **Avoidability by counterfactual replay** (:func:`drivefuzz.triage.counterfactual.counterfactual`): when no
  rule excuses the ego and the caller gives ``replay``, the same scenario is driven by the careful reference
  driver (ADS ``careful``, :mod:`ego.careful`). If it fails the same way (same oracle, same other party), the
  situation was unavoidable: ``other``. Not after a rule that found the ego's own fault (it entered on red; it
  stayed behind a stationary body with a lane free): the careful driver would share the one (it does not
  overtake either) and never meet the other. A red light run is the ego's without a replay,
  unless it met ice on the way in (the careful driver may not stop on it either). Lane keeping is replayed
  only on ice or in a strong crosswind (the careful driver tracks its path as the reference does), and a
  mission time-out only when the ego kept moving (fog, rain and ice slow a careful driver too, and a time
  limit too short for the route holds for everyone); such an ``other`` verdict names the ice, the wind or
  the fog. An ``ego`` verdict that the careful driver avoided on the same ice names the ice too (neither
  driver senses friction: the careful one got through by braking earlier and keeping further back).

Otherwise the verdict is ``ego`` with what the ego did; ``unclear`` when the trace lacks the
evidence (the other party is not in it, the frame is outside it).

Units: SI; positions are body centres; headings radians ENU (as in the trace).
"""

from __future__ import annotations

import math
import numpy as np

from drivefuzz.scenario.model import CAREFUL_DECEL, CAREFUL_REACTION, EGO_LENGTH, EGO_WIDTH
from drivefuzz.triage.evidence import (
    COMFORT_DECEL,
    G,
    RED,
    STATIONARY_SPEED,
    Track,
    actor_track,
    contact_point,
    contact_side,
    cut_in,
    ego_link,
    ego_reach_into,
    first_visible,
    frames_before,
    gap_ahead,
    kept_lane,
    lane_changed,
    other_link,
    path_entry,
    ran_red,
    red_approach,
    sideways_into,
    stopping_distance,
    to_local,
    wrap_angle,
)
# the verdict's vocabulary and the careful driver's replay, importable from here as before the split
from drivefuzz.triage.counterfactual import (  # noqa: F401
    CAREFUL_ADS,
    MET_M,
    REACHED_M,
    STANDSTILL,
    VEHICLE_EXCUSES,
    Replay,
    careful_scenario,
    counterfactual,
    test_excuse,
)
from drivefuzz.scenario.signals import connection_state
from drivefuzz.triage.conditions import dazzled, short_sight, slippery, windy
from drivefuzz.triage.standstill import StandstillRules
from drivefuzz.triage.verdict import AVOIDED, KEPT, RULES, Attribution, Fault, bug_class, needs_replay  # noqa: F401


#: [s] before a contact, over which the rules that excuse a struck ego look for the other body's approach.
APPROACH_WINDOW = 2.0
#: [s] an ego at rest this long before a contact was struck: it had stopped (for a walker it braked for, say)
#: before the other reached it, and it cannot have moved into it since.
STOPPED_BEFORE = 0.25
#: [s] before a contact, over which a vehicle that moved into the ego's lane counts as cutting in.
CUT_IN_WINDOW = 4.0
#: [s] before a contact, over which a follower's passage through the junction the ego had just crossed counts: the ego
#: took its way ahead of the follower there.
YIELD_WINDOW = 5.0
#: [m] how far a stationary ego may reach across the edge of the lane of a vehicle that strikes it (mirrors and a
#: centre line drawn a little off) before it stood in that vehicle's way.
IN_LANE_MARGIN = 0.3


def _travelled(x: np.ndarray, y: np.ndarray) -> float:
    """Path length [m] of a body's positions (frames where it was absent are skipped)."""
    keep = ~(np.isnan(x) | np.isnan(y))
    x, y = x[keep], y[keep]
    return float(np.hypot(np.diff(x), np.diff(y)).sum()) if len(x) > 1 else 0.0


#: Oracles whose verdicts the counterfactual does not settle (see :func:`attribute`).
NO_COUNTERFACTUAL = frozenset({"lane_invasion", "immobility", "mission"})

# ---------------------------------------------------------------------- entry point
def attribute(scenario, trace, misbehavior, rmap, *, replay: Replay | None = None) -> Attribution:
    """The verdict on ``misbehavior`` (see the module docstring for the rules).

    ``replay(scenario) -> (misbehaviors, trace)`` runs a scenario (the caller's executor, oracles and
    settings); given, it runs the counterfactual with the careful driver (one execution) when no
    rule decided: none excused the ego and none saw its own fault. Without it, such a verdict is
    ``ego`` (or ``unclear``) from the rules alone.
    """
    n = trace.n_frames
    if n == 0:
        return Attribution(Fault.UNCLEAR, "the trace is empty", {"frame": misbehavior.frame}, "no_evidence")
    f = min(max(int(misbehavior.frame), 0), n - 1)
    ev = _Event(scenario, trace, misbehavior, rmap, f)
    verdict = ev.judge()
    # the careful driver shares the reference's path tracking and never overtakes: for standstills, and for
    # lane keeping on a dry, calm road, its failing too says nothing about avoidability (the rules decide);
    # lane keeping lost to ice or wind may have been unavoidable, which the replay can show
    oracle = misbehavior.oracle
    # what may make a lane impossible to keep: ice, or a strong crosswind
    unkeepable = (slippery(trace, f) or windy(scenario)) if oracle == "lane_invasion" else None
    settles = oracle not in NO_COUNTERFACTUAL or ev.replay_may_settle or unkeepable is not None
    if replay is not None and needs_replay(verdict):
        return test_excuse(scenario, trace, misbehavior, replay, verdict)
    if verdict.fault is not Fault.OTHER and not ev.decided and replay is not None and settles:
        out = counterfactual(scenario, misbehavior, replay, verdict)
        if out.fault is Fault.OTHER:  # name what the careful driver could not master either
            if oracle == "lane_invasion":
                cause = unkeepable
            elif oracle == "mission":  # slow all the way: fog, or ice anywhere
                cause = short_sight(scenario) or slippery(trace, f, window_s=float(trace["t"][f]) + 1.0)
            else:
                cause = slippery(trace, f)
            if cause is not None:
                out = Attribution(out.fault, f"{out.reason}: {cause}", {**out.evidence, "cause": cause}, out.rule)
        elif out.fault is Fault.EGO and oracle not in ("mission", "red_light"):  # the careful driver mastered
            # the same ice: say so (a red-light verdict names the ice already)
            ground = slippery(trace, f)
            if ground is not None:
                out = Attribution(out.fault, f"{out.reason} ({ground})", {**out.evidence, "ground": ground}, out.rule)
        return out
    return verdict



class _Event(StandstillRules):
    """One misbehaviour with what the rules need; :meth:`judge` applies them."""

    def __init__(self, scenario, trace, mb, rmap, f: int):
        self.scenario, self.trace, self.mb, self.rmap, self.f = scenario, trace, mb, rmap, f
        #: an ``ego`` verdict from a rule that saw the ego's own fault (the careful driver would
        #: share it or never meet it): no counterfactual
        self.decided = False
        self._came: dict[str, bool] = {}  # other body id -> whether it came to the ego (_came_to_ego)
        #: a verdict of an oracle in NO_COUNTERFACTUAL that the replay may still settle
        self.replay_may_settle = False
        self.v = float(trace["speed"][f])
        self.base = {"frame": f, "time": round(float(trace["t"][f]), 3), "ego_speed": self.v,
                     "ego_lane": str(trace["lane"][f])}

    def other(self, rule: str, reason: str, **evidence) -> Attribution:
        if KEPT in evidence:  # an excuse kept without a replay says why, in the words a reader checks
            reason = f"{reason}; no replay needed: {evidence[KEPT]}"
        return Attribution(Fault.OTHER, reason, {**self.base, **evidence}, rule)

    def ego(self, rule: str, reason: str, decided: bool = False, **evidence) -> Attribution:
        self.decided = decided
        return Attribution(Fault.EGO, reason, {**self.base, **evidence}, rule)

    def judge(self) -> Attribution:
        oracle = self.mb.oracle
        if oracle == "collision":
            return self.collision()
        if oracle in ("immobility", "mission"):
            return self.standstill()
        if oracle == "red_light":
            return self.red_light()
        # the speed limit binds whatever the others do; lane keeping may be lost to wind or ice, which the
        # counterfactual can show
        return self.ego("own_driving", f"the ego's own driving: {oracle}/{self.mb.kind}", decided=oracle == "speeding")

    def red_light(self) -> Attribution:
        """A red light binds whatever the others do: the ego's, with how it came to the light and what kept
        it from seeing it (a low sun ahead, fog or rain), for whoever triages it. Ice under the ego on the way
        in leaves it to the careful driver's replay: a driver who cannot see the ice may not stop on it."""
        head = f"the ego's own driving: {self.mb.oracle}/{self.mb.kind}"
        app = red_approach(self.trace, self.f)
        if app is None:
            return self.ego("own_driving", head, decided=True)
        notes = [app.describe()]
        glare = dazzled(self.scenario, self.trace, app.onset, self.f)
        sight = short_sight(self.scenario)
        # on ice met on the way in, a stop at the line may have been beyond any driver who cannot see the ice:
        # the careful driver's replay decides
        t = self.trace["t"]
        ice = slippery(self.trace, self.f, window_s=max(6.0, float(t[self.f] - t[app.onset])))
        notes += [n for n in (glare, sight, ice) if n]
        return self.ego("own_driving", f"{head}: {'; '.join(notes)}", decided=ice is None,
                        light_onset_frame=app.onset, light_at_onset=app.state,
                        distance_at_onset=round(app.distance, 2), speed_at_onset=round(app.speed, 2),
                        decel_needed=round(app.needed, 2), decel_max=round(app.braked, 2), dazzled=glare is not None)

    # ------------------------------------------------------------------ collisions
    def collision(self) -> Attribution:
        mb, trace, f = self.mb, self.trace, self.f
        if mb.kind == "obstacle":
            return self.ego("obstacle", f"the ego drove into the static obstacle {mb.actors[0] if mb.actors else '?'} at "
                            f"{self.v:.1f} m/s", other=list(mb.actors))
        if not mb.actors:
            return Attribution(Fault.UNCLEAR, "the collision names no other party", dict(self.base), "no_evidence")
        oth = actor_track(trace, mb.actors[0])
        if oth is None or not oth.present(f):
            return Attribution(Fault.UNCLEAR, f"{mb.actors[0]} is not in the trace at the contact",
                               {**self.base, "other": mb.actors[0]}, "no_evidence")
        point = contact_point(trace, f, oth)
        side = contact_side(point)
        self.base.update(other=oth.id, other_kind=oth.kind, other_speed=float(oth.speed[f]), contact_side=side,
                         contact_point=list(point) if point else None)
        appeared = self.rule_appeared(oth)
        if appeared is not None:
            return appeared
        red = ran_red(trace, f)
        if self.rule_stationary(oth, point, side, red) is None and side in ("left", "right") and oth.kind == "vehicle":
            moved = sideways_into(trace, self.rmap, oth, f, side)
            if moved is not None:
                return self.ego("lane_change_into", f"the ego changed lanes into the vehicle {oth.id} alongside (it moved {moved[0]:.1f} m "
                                f"sideways towards it, {oth.id} {round(moved[1], 1) + 0.0:.1f} m)", decided=True,
                                ego_sideways=moved[0], other_sideways=moved[1])
        for rule in (self.rule_in_its_lane, self.rule_stationary, self.rule_rear, self.rule_cut_in,
                     self.rule_right_of_way, self.rule_pedestrian):
            verdict = rule(oth, point, side, red)
            if verdict is not None:
                return verdict
        if red is not None:
            return self.ego("ran_red", f"the ego entered the junction on red (frame {red}) and hit {oth.id}", decided=True,
                            red_frame=red)
        if oth.kind == "vehicle" and self._ego_must_yield_to(oth):
            mine = ego_link(trace, self.rmap, f)
            return self.ego("failed_to_yield", f"the ego did not yield to the vehicle {oth.id} at {mine.getJunction().getID()}: its link "
                            f"from {mine.getFromLane().getID()} must yield", decided=True,
                            ego_from=mine.getFromLane().getID())
        still = float(np.nanmax(oth.speed[frames_before(trace, f, 2.0)])) <= STATIONARY_SPEED
        what = f"stationary {oth.kind}" if still else oth.kind
        # the speed it struck at: that of the frame before, when the ego braked within the step of the contact
        # (a car that pulled off at 0.4 m/s into a parked one and braked fully reads 0.0 m/s at the contact)
        impact = max(self.v, float(trace["speed"][f - 1])) if f > 0 else self.v
        return self.ego("struck", f"the ego struck the {what} {oth.id} with its {side} at {impact:.1f} m/s",
                        impact_speed=impact)

    def rule_appeared(self, oth: Track) -> Attribution | None:
        """The other party entered the simulation less than :data:`CAREFUL_REACTION` before the contact (SUMO put a car
        on the lane beside or behind the ego as it passed): no driver reacts to a body that was not there; a careful
        driver's replay that missed it was elsewhere by timing. Kept without a replay."""
        trace, f = self.trace, self.f
        here = ~np.isnan(oth.x[:f + 1])
        first = int(np.argmax(here))
        since = float(trace["t"][f] - trace["t"][first])
        if first == 0 or since >= CAREFUL_REACTION:
            return None
        gap = float(np.hypot(oth.x[first] - trace["x"][first], oth.y[first] - trace["y"][first]))
        return self.other("appeared", f"the {oth.kind} {oth.id} appeared {gap:.1f} m from the ego (centre to centre) "
                          f"{since:.2f} s before it struck the ego's {self.base['contact_side']}",
                          appeared_frame=first, appeared_gap=round(gap, 2),
                          **{KEPT: f"no driver reacts within {since:.2f} s to a {oth.kind} that was not there before"})

    def _stood(self, red) -> bool:
        """Whether the ego stood still since :data:`STOPPED_BEFORE` before the contact, on a lane, and not just
        past a stop line on red."""
        trace, f = self.trace, self.f
        w = frames_before(trace, f, STOPPED_BEFORE)
        return float(np.max(trace["speed"][w])) <= STATIONARY_SPEED and red is None and bool(trace["lane"][f])

    def rule_in_its_lane(self, oth: Track, point, side: str, red) -> Attribution | None:
        """A stationary ego that reached more than :data:`IN_LANE_MARGIN` into the lane of a vehicle that kept
        that lane stood in its way (stopped at an angle, its nose in the next lane while it waited to merge):
        SUMO's drivers do not see a body whose centre is in another lane, and a careful driver does not stop so.
        The ego's, unless the careful driver's replay is struck too."""
        if oth.kind != "vehicle" or not self._stood(red) or not self._came_to_ego(oth):
            return None
        trace, f = self.trace, self.f
        lane = kept_lane(self.rmap, oth, range(frames_before(trace, f, APPROACH_WINDOW).start, f + 1))
        if lane is None or lane == str(trace["lane"][f]):
            return None
        reach = ego_reach_into(trace, self.rmap, lane, f)
        if reach is None or reach <= IN_LANE_MARGIN:
            return None
        return self.ego("stood_in_lane", f"the ego stood {reach:.1f} m into {lane}, the lane of the vehicle {oth.id}, "
                        f"which kept to it and struck its {side}", other_lane=lane, ego_reach=round(reach, 3))

    def rule_stationary(self, oth: Track, point, side: str, red) -> Attribution | None:
        if not self._stood(red):
            return None
        # an ego creeping below the stationary speed into a body that stood still (a waiting car's throttle-brake
        # chatter) struck it, whatever its speedometer said
        if not self._came_to_ego(oth):
            return None
        reason = f"the ego was stationary ({self.v:.2f} m/s) when the {oth.kind} {oth.id} struck its {side}"
        kept = self._never_braked(oth) if oth.kind == "vehicle" and point is not None and point[0] < 0.0 else None
        if kept is not None:  # from behind, by a car that never braked: it would have struck whatever stood there
            return self.other("stationary_struck", reason, **{KEPT: kept})
        return self.other("stationary_struck", reason)

    def _never_braked(self, oth: Track) -> str | None:
        """Why an excuse against ``oth``, which struck the ego from behind, holds without a replay: it did not
        slow down by more than 1 m/s over the :data:`APPROACH_WINDOW` before the contact (so it would have struck
        any car that stood, or drove slower, where the ego was); None when it braked."""
        w = frames_before(self.trace, self.f, APPROACH_WINDOW)
        sp = oth.speed[w]
        if not np.any(~np.isnan(sp)):
            return None
        shed = float(np.nanmax(sp)) - float(oth.speed[self.f])
        if shed > 1.0:
            return None
        return (f"{oth.id} struck from behind without braking (it shed {max(shed, 0.0):.1f} m/s): it would have struck "
                f"a careful driver standing there too")

    def _came_to_ego(self, oth: Track) -> bool:
        """Whether the other body moved in the last :data:`APPROACH_WINDOW` seconds: farther than the
        stationary speed would take it, or farther than the ego (the distances go into the evidence). Its path,
        not its speed: SUMO's speed is longitudinal, and a car that swings sideways into the next lane at a
        standstill reports 0. The rules that excuse the ego because the other struck it (stationary, rear,
        right of way) need it: a body that stood still while the ego moved to it was the ego's to avoid, even
        one that had stopped where it should not (the counterfactual still decides whether a careful driver
        could)."""
        came = self._came.get(oth.id)
        if came is None:  # three rules ask: measured once
            w = frames_before(self.trace, self.f, APPROACH_WINDOW)
            ego_moved = _travelled(self.trace["x"][w], self.trace["y"][w])
            other_moved = _travelled(oth.x[w], oth.y[w])
            self.base.update(ego_travelled=round(ego_moved, 3), other_travelled=round(other_moved, 3))
            came = self._came[oth.id] = other_moved > STATIONARY_SPEED * APPROACH_WINDOW or other_moved > ego_moved
        return came

    def rule_rear(self, oth: Track, point, side: str, red) -> Attribution | None:
        trace, f = self.trace, self.f
        if oth.kind != "vehicle" or point is None or point[0] >= 0.0 or side in ("front",):
            return None
        if not self._came_to_ego(oth):
            return None
        if red is not None or not trace["lane"][f] or lane_changed(trace, f):
            return None
        # from behind: travelling the ego's way (a crossing or oncoming car that clips the rear
        # half is a right-of-way question, not a rear-end)
        if abs(wrap_angle(float(oth.heading[f]) - float(trace["heading"][f]))) > math.pi / 4:
            return None
        if str(trace["lane"][f]).startswith(":") and self._ego_must_yield_to(oth):
            return None
        w = frames_before(trace, f, 3.0)
        decel = -trace["ax"][w]
        peak = float(np.nanmax(decel)) if len(decel) else 0.0
        if peak > COMFORT_DECEL:
            hard = [w.start + int(k) for k in np.flatnonzero(decel > COMFORT_DECEL)]
            hazard = self._hazard_ahead(hard[0], exclude=oth.id)
            if hazard is None:
                return None
        else:
            hazard = None
        dv = float(oth.speed[f]) - self.v
        why = f" (it braked for {hazard})" if hazard else ""
        # a way through a junction just taken ahead of the follower, that had to yield to the follower's: a careful
        # driver yields there (then the follower is not behind it), which the replay tests
        took = self._took_way_of(oth)
        if took is not None:
            why += f"; its way through {took} had to yield to {oth.id}'s"
        # braking no harder than comfort, lawfully in its lane: the follower's to avoid, wherever the ego drove;
        # hard braking, even for a hazard, may be what a careful driver's anticipation spares: the replay tests it
        kept = {KEPT: "it drove lawfully in its lane and braked gently, as a careful driver does: the follower's to "
                      "avoid"} if hazard is None and took is None else {}
        how = "drove in its lane" if took else "drove lawfully in its lane"
        return self.other("rear_ended", f"the vehicle {oth.id} struck the ego's rear half at {dv:.1f} m/s faster while the ego "
                          f"{how}, braking at most {max(peak, 0.0):.1f} m/s^2{why}",
                          peak_decel=peak, hazard=hazard, **({"took_way_at": took} if took else {}), **kept)

    def rule_cut_in(self, oth: Track, point, side: str, red) -> Attribution | None:
        """A vehicle moved into the ego's lane ahead of it (or alongside), and a careful driver, braking
        from when it came in, could not have kept clear of where it then went."""
        trace, f = self.trace, self.f
        if oth.kind != "vehicle" or point is None or point[0] < 0.0 or red is not None:
            return None
        if not self._came_to_ego(oth):
            return None
        entry = cut_in(trace, self.rmap, oth, f, CUT_IN_WINDOW)
        if entry is None:
            return None
        k = entry.entered
        t = trace["t"][k:f + 1] - trace["t"][k]
        v0 = float(trace["speed"][k])
        grip = np.fmin(trace["mu_front"][k:f + 1], trace["mu_rear"][k:f + 1])
        mu = float(np.nanmin(grip)) if np.any(~np.isnan(grip)) else 1.0  # off-road all along: a dry road
        decel = min(CAREFUL_DECEL, max(min(mu, 1.0), 0.05) * G)
        braking = np.clip(t - CAREFUL_REACTION, 0.0, v0 / decel)
        careful_s = entry.ego_s[0] + v0 * np.minimum(t, CAREFUL_REACTION) + v0 * braking - 0.5 * decel * braking ** 2
        reach = 0.5 * (float(oth.length) + EGO_LENGTH)
        gap0 = float(entry.other_s[0] - entry.ego_s[0]) - reach
        closest = float(np.min(entry.other_s - careful_s)) - reach
        ev = dict(entered_frame=k, gap=round(gap0, 3), speed_then=v0, careful_gap=round(closest, 3), mu=mu)
        if closest > 0.0:
            self.base.update(ev)
            return None
        how = ("moved into the ego's lane alongside it" if gap0 < 0.0 else
               f"cut into the ego's lane from {gap0:.1f} m ahead (moving over from {float(trace['t'][k]):.1f} s)")
        return self.other("cut_in", f"the vehicle {oth.id} {how}; braking {CAREFUL_REACTION:.2f} s later at {decel:.1f} "
                          f"m/s^2, a careful driver could not have kept clear of it", **ev)

    def _ego_must_yield_to(self, oth: Track) -> bool:
        mine = ego_link(self.trace, self.rmap, self.f)
        link = other_link(self.trace, self.rmap, oth, self.f)
        if mine is None or link is None or mine.getJunction().getID() != link[0].getJunction().getID():
            return False
        try:
            return bool(mine.getJunction().forbids(link[0], mine))
        except (IndexError, KeyError, AttributeError):
            return False

    def _took_way_of(self, oth: Track) -> str | None:
        """The junction the ego passed ahead of ``oth`` on a link that must yield to the one ``oth`` took through it in
        the last :data:`YIELD_WINDOW` seconds (``oth``'s passage read while it made it: by the contact it may be on the
        lane beyond), or None."""
        trace, f = self.trace, self.f
        mine = ego_link(trace, self.rmap, f)
        if mine is None:
            return None
        w = frames_before(trace, f, YIELD_WINDOW)
        for k in range(f, w.start - 1, -max(int(0.25 / trace.step_length), 1)):
            link = other_link(trace, self.rmap, oth, k)
            if link is None:
                continue
            node = mine.getJunction()
            if node.getID() != link[0].getJunction().getID():
                return None
            try:
                return node.getID() if node.forbids(link[0], mine) else None
            except (IndexError, KeyError, AttributeError):
                return None
        return None

    def _hazard_ahead(self, k: int, exclude: str) -> str | None:
        """What justified hard braking at frame ``k``: a body in the path ahead, or a stop light."""
        trace = self.trace
        v = float(trace["speed"][k])
        reach = v * 3.0 + 10.0
        a = trace.actors
        r = a.rows(k)
        for aid_i, x, y, length, width in zip(a.actor[r], a.x[r], a.y[r], a.length[a.actor[r]], a.width[a.actor[r]]):
            aid = a.ids[int(aid_i)]
            if aid == exclude:
                continue
            lx, ly = to_local(trace, k, float(x), float(y))
            if 0.0 < lx < reach + EGO_LENGTH / 2 and abs(ly) < EGO_WIDTH / 2 + width / 2 + 0.8:
                return aid
        if str(trace["tls_state"][k]) in (RED | {"y", "Y"}) and trace["tls_dist"][k] < v * v / 2.0 + 10.0:
            return f"a {trace['tls_state'][k]} light"
        return None

    def rule_right_of_way(self, oth: Track, point, side: str, red) -> Attribution | None:
        if oth.kind != "vehicle" or red is not None or not self._came_to_ego(oth):
            return None
        link = other_link(self.trace, self.rmap, oth, self.f)
        if link is None:
            return None
        conn, k_in = link
        t_in = float(self.trace["t"][k_in])
        tls = conn.getTLSID()
        ev = {"other_from": conn.getFromLane().getID(), "other_via": conn.getViaLaneID(), "other_entered_frame": k_in}
        if tls:
            state = connection_state(str(self.rmap.path), conn, t_in, self.scenario.signals)
            if state is not None and state in RED:
                return self.other("other_ran_red", f"the vehicle {oth.id} entered junction {conn.getJunction().getID()} on red "
                                  f"({state!r} at {t_in:.1f} s) and struck the ego's {side}",
                                  other_signal=state, **ev)
        mine = ego_link(self.trace, self.rmap, self.f)
        if mine is None or mine.getJunction().getID() != conn.getJunction().getID():
            return None
        node = conn.getJunction()
        try:
            other_yields = node.forbids(mine, conn)
            ego_yields = node.forbids(conn, mine)
        except (IndexError, KeyError, AttributeError):
            return None
        if other_yields and not ego_yields:
            return self.other("other_failed_to_yield", f"the vehicle {oth.id} came from {conn.getFromLane().getID()}, a link that must yield, "
                              f"into the ego's right of way at {node.getID()}",
                              ego_from=mine.getFromLane().getID(), **ev)
        return None

    def rule_pedestrian(self, oth: Track, point, side: str, red) -> Attribution | None:
        if oth.kind != "pedestrian":
            return None
        trace, f = self.trace, self.f
        k_in = path_entry(trace, oth, f)
        if side in ("left", "right") and k_in is None:
            return self.other("pedestrian", f"the pedestrian {oth.id} walked into the ego's {side} side")
        if k_in is None:
            return None
        k_vis = first_visible(trace, oth, f, self.scenario)
        if k_vis is None:
            return self.other("pedestrian", f"the pedestrian {oth.id} was never visible before it was struck",
                              entered_frame=k_in)
        k0 = max(k_in, k_vis)
        v = float(trace["speed"][k0])
        mu = float(np.nanmin([trace["mu_front"][k0], trace["mu_rear"][k0], 1.0]))
        gap = gap_ahead(trace, k0, oth)
        need = stopping_distance(v, mu)
        ev = dict(entered_frame=k_in, visible_frame=k_vis, gap=gap, speed_then=v, mu=mu, stopping_distance=need)
        if gap < need:
            return self.other("pedestrian", f"the pedestrian {oth.id} entered the ego's path {gap:.1f} m ahead at {v:.1f} m/s; "
                              f"stopping needed {need:.1f} m (mu {mu:.2f})", **ev)
        self.base.update(ev)
        return None
