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
     of the run held up behind slower traffic. Waiting behind a stationary body with a lawful lane free is the ego's (decided:
     the careful driver does not overtake either), also when cars queue between the ego and that
     body (a parked car in the queue, or a car stalled in mid-lane at its head: it will not move).

  Rules 1-4 excuse the ego only for a body that came to it: one that moved in the last
  :data:`APPROACH_WINDOW` seconds (farther than the stationary speed takes a body, or farther than
  the ego). An ego that crept (below the stationary speed) into a parked car, or drove into a car
  that stood in a junction it had entered on red, struck it.

- **Excuses are hypotheses** that the careful driver's replay tests (:func:`test_excuse`), when the caller gives
  ``replay``: several rules measure the situation with the ego's own speed and place, which its bug chose (a
  walker "walked into its side": into a car that should not have been there; an ego "stationary when struck"
  may have stopped where a careful driver would not). An excusing rule's ``other`` holds only if the careful
  driver fails the same way (same oracle, same other party; for a standstill, :data:`STANDSTILL`, it stands
  still or times out too, or stood at the same place at the event's time), or its replay says nothing about
  the event (it failed first, never came near, did not run); otherwise the verdict is the ego's, under the rule of
  :data:`AVOIDED` (``stationary_struck`` -> ``stopped_in_the_way``, ``pedestrian`` -> ``pedestrian_avoidable``,
  ...), and its reason says what the careful driver did instead (how close it came to the other party, where
  and how fast it was at the event's time). A replay that never came within :data:`MET_M` of the other party
  and was farther than that from the place at the event's time says nothing either: it passed before or after
  the other came, which is timing, not care; so does one that passed another vehicle whose conduct is the
  excuse (ran a red, did not yield, struck from behind) without slowing for it (:data:`VEHICLE_EXCUSES`).
  Three excuses hold without a replay (their evidence says why, under :data:`KEPT`), because the ego could not
  have been elsewhere in a way that matters:

  - *stationary*, struck in its rear half by a vehicle that did not slow by more than 1 m/s in the
    :data:`APPROACH_WINDOW`: such a car strikes whatever stands or drives slower in that lane, wherever the
    ego had stopped, and the ego stood lawfully there (not on red, not reaching into another's lane);
  - *rear*, struck from behind while lawfully in its lane and braking no harder than :data:`COMFORT_DECEL`:
    the follower's to avoid by any driver's standard. A hard stop for a hazard keeps the rule's excuse only if
    the careful driver, who anticipates, had to brake and was struck too;
  - *held up* (a time-out behind slower traffic it could not pass): a leader holds up any driver behind it
    alike, and a replay in which SUMO's leader drives differently (it reacts to the ego) would test the
    leader, not the ego.

  Without ``replay`` an excuse stands from the rules alone (the triage's first, cheap verdict that names the
  signature; :func:`needs_replay` says which verdicts the triage must replay before it files them).

- **Avoidability by counterfactual replay**: when no rule excuses the ego and the caller gives
  ``replay``, the same scenario is driven by the careful reference driver (ADS ``careful``,
  :mod:`ego.careful`). If it fails the same way (same oracle, same other party), the situation
  was unavoidable: ``other``. Not after a rule that found the ego's own fault (it entered on red;
  it stayed behind a stationary body with a lane free): the careful driver would share the one
  (it does not overtake either) and never meet the other. A red light run is the ego's without a replay,
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
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from drivefuzz.scenario.model import CAREFUL_DECEL, CAREFUL_REACTION, EGO_LENGTH, EGO_WIDTH, AdsSpec
from drivefuzz.triage.evidence import (
    COMFORT_DECEL,
    G,
    RED,
    STATIONARY_SPEED,
    Track,
    actor_track,
    blocked_lanes,
    contact_point,
    contact_side,
    cut_in,
    ego_link,
    ego_reach_into,
    first_visible,
    frames_before,
    gap_ahead,
    held_up,
    kept_lane,
    lane_changed,
    never_moved,
    other_link,
    path_entry,
    ran_red,
    red_approach,
    sensor_range,
    sideways_into,
    signal_state,
    stopping_distance,
    to_local,
    wrap_angle,
)

#: [s] before a contact, over which the rules that excuse a struck ego look for the other body's approach.
APPROACH_WINDOW = 2.0
#: [s] an ego at rest this long before a contact was struck: it had stopped (for a walker it braked for, say)
#: before the other reached it, and it cannot have moved into it since.
STOPPED_BEFORE = 0.25
#: [s] before a contact, over which a vehicle that moved into the ego's lane counts as cutting in.
CUT_IN_WINDOW = 4.0
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
#: [m] a sensor range below which fog and rain count as the cause of a slow journey.
SHORT_SIGHT = 50.0
#: [m] room a driver needs past a stationary body to merge back into a lane that leads on along the route.
MERGE_ROOM = 20.0
#: [m] how close the careful driver's replay must come to the event's place to say anything about it.
REACHED_M = 10.0
#: The ADS the counterfactual replay uses.
CAREFUL_ADS = "careful"
#: [m/s] a crosswind from which a lane may be lost however carefully one drives (Beaufort 5, a fresh breeze;
#: below it the car's drift is centimetres): then the careful driver's replay may settle a lane invasion.
WINDY = 8.0

Replay = Callable[[Any], tuple[Sequence[Any], Any]]


class Fault(str, Enum):
    EGO = "ego"
    OTHER = "other"
    UNCLEAR = "unclear"


#: The rules, by the name a verdict records (``Attribution.rule``), with what each says happened. Findings
#: of one oracle and kind that one rule blamed on the ego are likely one bug of the ADS, however their
#: signatures differ (a roundabout entry not yielded to, with the ego going straight or right, the other car
#: an autopilot or a linear one, struck front or side): the report and the summaries group them so.
RULES: dict[str, str] = {
    # the ego's fault
    "own_driving": "its own driving",
    "obstacle": "it drove into a static obstacle",
    "lane_change_into": "it moved sideways into a vehicle alongside",
    "ran_red": "it entered a junction on red and hit someone",
    "failed_to_yield": "it did not yield where its link must yield",
    "struck": "it struck another road user",
    "slow": "it did not reach its goal in time",
    "no_blocker": "it stood still with nothing in its way",
    "stayed_behind": "it stayed behind a stationary body with a lane free",
    "stood_still": "it stood still with a lane free",
    "stood_in_lane": "it stood reaching into another's lane, in its way",
    # an excuse that the careful driver's replay overturned (:data:`AVOIDED`): the ego's
    "stopped_in_the_way": "it stopped where a careful driver did not, and was struck there",
    "rear_end_avoidable": "it was struck from behind where a careful driver was not",
    "cut_in_avoidable": "a vehicle cut in that a careful driver kept clear of",
    "right_of_way_avoidable": "another did not give way, and a careful driver kept clear of it",
    "pedestrian_avoidable": "it met a pedestrian that a careful driver kept clear of",
    "blocked_avoidable": "it stood blocked or held up where a careful driver got on",
    # another's
    "stationary_struck": "it was struck while standing still",
    "rear_ended": "it was struck from behind while driving lawfully",
    "cut_in": "a vehicle cut in closer than a careful driver can brake for",
    "other_ran_red": "another vehicle entered the junction on red",
    "other_failed_to_yield": "another vehicle did not yield",
    "pedestrian": "a pedestrian stepped out too close, unseen, or into its side",
    "held_up": "slower traffic held it up",
    "pedestrian_in_lane": "a pedestrian stood in its lane",
    "blocked": "every lawful way on was blocked",
    "queue": "it waited in a queue that will move",
    # neither
    "no_evidence": "the trace lacks the evidence",
}


#: The rules that excuse the ego (``other``), each a hypothesis that the careful driver's replay tests, with the
#: rule an ``ego`` verdict names when the careful driver avoided what the rule excused.
AVOIDED: dict[str, str] = {
    "stationary_struck": "stopped_in_the_way",
    "rear_ended": "rear_end_avoidable",
    "cut_in": "cut_in_avoidable",
    "other_ran_red": "right_of_way_avoidable",
    "other_failed_to_yield": "right_of_way_avoidable",
    "pedestrian": "pedestrian_avoidable",
    "pedestrian_in_lane": "blocked_avoidable",
    "blocked": "blocked_avoidable",
    "queue": "blocked_avoidable",
    "held_up": "blocked_avoidable",
}
#: [m] centre to centre: a careful driver whose replay never came this close to the other party, and was farther
#: than this from the event's place at its time, never met it (it came by earlier or later): its keeping clear
#: says nothing about the ego's excuse.
MET_M = 15.0
#: [s] before its closest approach to the other party over which the careful driver's slowing down counts.
REACT_WINDOW = 3.0
#: Excuses about another vehicle's conduct at a junction or from behind: the careful driver avoided it only if it
#: slowed for the vehicle (:func:`_reacted`); one that came by at its cruising speed was elsewhere when the other
#: came, by timing. (A cut-in is not among them: the careful driver's longer headway is the care that avoids it.)
VEHICLE_EXCUSES = frozenset({"other_ran_red", "other_failed_to_yield", "rear_ended"})
#: The oracles of a standstill: an excuse of one (blocked, held up) holds when the careful driver fails either.
STANDSTILL = frozenset({"immobility", "mission"})
#: Evidence key of an excuse that holds without a replay (its value says why).
KEPT = "kept_without_replay"


def needs_replay(att: "Attribution") -> bool:
    """Whether ``att`` (a verdict from the rules alone) is an excuse that the careful driver's replay must test
    before it holds: the triage runs the replay for these as for the ego's verdicts."""
    return att.fault is Fault.OTHER and att.rule in AVOIDED and KEPT not in att.evidence


def bug_class(verdict: str, fault: str, rule: str) -> tuple[str, str]:
    """(key, title) of the likely bug behind a finding: its oracle/kind (``verdict``), fault and rule. A verdict
    that names no rule (one filed before verdicts recorded theirs) is a class of its oracle and kind alone."""
    what = RULES.get(rule)
    tail = "" if fault == Fault.EGO.value else f" (fault: {fault})"  # an unclear finding is not the ego's yet
    if what is None:
        return f"{verdict}|{fault}", verdict + tail
    return f"{verdict}|{fault}|{rule}", f"{verdict}: {what}{tail}"


@dataclass(frozen=True)
class Attribution:
    """A verdict, the one-line reason a reader can check, its evidence (JSON-safe), and the name of the rule
    that gave it (a key of :data:`RULES`; the counterfactual keeps the rule whose verdict it tested)."""

    fault: Fault
    reason: str
    evidence: Mapping[str, Any] = field(default_factory=dict)
    rule: str = ""

    def __post_init__(self):
        if self.rule and self.rule not in RULES:
            raise ValueError(f"attribution rule {self.rule!r} is not described in RULES")

    def as_dict(self) -> dict[str, Any]:
        return {"fault": self.fault.value, "reason": self.reason, "rule": self.rule,
                "evidence": _json_safe(self.evidence)}


def _json_safe(v):
    if isinstance(v, Mapping):
        return {str(k): _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return None if not math.isfinite(float(v)) else round(float(v), 3)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    if isinstance(v, Enum):
        return v.value
    return v


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
    unkeepable = (_slippery(trace, f) or _windy(scenario)) if oracle == "lane_invasion" else None
    settles = oracle not in NO_COUNTERFACTUAL or ev.replay_may_settle or unkeepable is not None
    if replay is not None and needs_replay(verdict):
        return test_excuse(scenario, trace, misbehavior, replay, verdict)
    if verdict.fault is not Fault.OTHER and not ev.decided and replay is not None and settles:
        out = counterfactual(scenario, misbehavior, replay, verdict)
        if out.fault is Fault.OTHER:  # name what the careful driver could not master either
            if oracle == "lane_invasion":
                cause = unkeepable
            elif oracle == "mission":  # slow all the way: fog, or ice anywhere
                cause = _short_sight(scenario) or _slippery(trace, f, window_s=float(trace["t"][f]) + 1.0)
            else:
                cause = _slippery(trace, f)
            if cause is not None:
                out = Attribution(out.fault, f"{out.reason}: {cause}", {**out.evidence, "cause": cause}, out.rule)
        elif out.fault is Fault.EGO and oracle not in ("mission", "red_light"):  # the careful driver mastered
            # the same ice: say so (a red-light verdict names the ice already)
            ground = _slippery(trace, f)
            if ground is not None:
                out = Attribution(out.fault, f"{out.reason} ({ground})", {**out.evidence, "ground": ground}, out.rule)
        return out
    return verdict


def _were_free(lanes: list[str]) -> str:
    """'A was free', 'A and B were free', 'A, B and C were free'."""
    if len(lanes) < 2:
        return f"{''.join(lanes)} was free"
    return f"{', '.join(lanes[:-1])} and {lanes[-1]} were free"


def _slippery(trace, f: int, window_s: float = 6.0) -> str | None:
    """Friction under an axle below 0.5 in the ``window_s`` seconds before ``f`` (a car that slid on ice may
    leave its lane, or reach what it braked for, seconds later), described; None on grippy ground."""
    k0 = max(f - int(window_s / trace.step_length), 0)
    mu = np.fmin(trace["mu_front"][k0:f + 1], trace["mu_rear"][k0:f + 1])
    slippery = np.flatnonzero(mu < 0.5)  # NaN compares False
    if not len(slippery):
        return None
    k = k0 + int(slippery[0])
    return f"friction {float(np.nanmin(mu)):.2f} under the ego from {float(trace['t'][k]):.1f} s"


def _short_sight(scenario) -> str | None:
    """Fog and rain that shorten the sensors' range below :data:`SHORT_SIGHT` m (a careful driver then
    drives no faster than it can stop within what it sees), described; None in clear weather."""
    w = scenario.weather
    rng = sensor_range(w)
    if rng >= SHORT_SIGHT:
        return None
    causes = [f"{name} {value:.0f}" for name, value in (("fog", w.fog), ("rain", w.rain)) if value > 0]
    return f"{' and '.join(causes)} limit{'s' if len(causes) == 1 else ''} the sensors to {rng:.0f} m"


def _dazzled(scenario, trace, k0: int, f: int) -> str | None:
    """A low sun ahead of the ego (the observation's ``sun_glare``) between frames ``k0`` and ``f``, described
    from where it began; None when the sun was never in its eyes."""
    from drivefuzz.sim.world import sun_glare

    w = scenario.weather
    heading, dist = trace["heading"], trace["tls_dist"]
    for k in range(k0, f):
        if sun_glare(w, float(heading[k])):
            return f"a low sun ahead (altitude {w.sun_altitude_deg:.1f} deg) dazzled it from {float(dist[k]):.1f} m out"
    return None


def _windy(scenario) -> str | None:
    """A crosswind of at least :data:`WINDY` m/s, described; None in a breeze or calm."""
    wind = scenario.weather.wind_speed
    return f"a crosswind of {wind:.1f} m/s" if wind >= WINDY else None


def _reached(trace, position, radius: float = REACHED_M) -> bool:
    """Whether the replay's ego came within ``radius`` [m] of the event's ``position`` (True when the trace
    does not say: a stand-in without the ego's channels)."""
    ego = getattr(trace, "ego", None)
    if ego is None or "x" not in ego or len(ego["x"]) == 0:
        return True
    d2 = (np.asarray(ego["x"]) - position[0]) ** 2 + (np.asarray(ego["y"]) - position[1]) ** 2
    return bool(np.nanmin(d2) <= radius * radius)


def careful_scenario(scenario):
    """``scenario`` driven by the careful driver, told of its puddles (their friction is map knowledge: the
    benchmark of what could have been done; the option's format is ``ego.careful.puddle_option``'s)."""
    options = {}
    if scenario.puddles:
        fields = ((p.x, p.y, p.length, p.width, p.rotation, p.friction) for p in scenario.puddles)
        options["puddles"] = ";".join(",".join(f"{v:.6g}" for v in f) for f in fields)
    return scenario.model_copy(update={"ads": AdsSpec(name=CAREFUL_ADS, options=options)})


def _careful_replay(scenario, misbehavior, replay: Replay, verdict: Attribution, same_failure, **record):
    """The careful driver's replay of ``scenario``: (its misbehaviours, its trace, those that are the same failure
    as ``misbehavior`` by ``same_failure``, the verdict's evidence with the replay's record, and why the replay says
    nothing about the event, or None: it failed first, did not run, or never came near the place)."""
    others, ctrace = replay(careful_scenario(scenario))
    same = [m for m in others if same_failure(m)]
    evidence = dict(verdict.evidence)
    evidence["counterfactual"] = {"ads": CAREFUL_ADS, "misbehaviors": [f"{m.oracle}/{m.kind}" for m in others],
                                  "same_failure": bool(same), **record}
    earlier = [m for m in others if m.time <= misbehavior.time]
    silent = None
    if ctrace is None or earlier or not _reached(ctrace, misbehavior.position):
        silent = (f"it failed first: {earlier[0].oracle}/{earlier[0].kind} at {earlier[0].time:.1f} s" if earlier else
                  "it did not run" if ctrace is None else "it never came near the place")
    return others, ctrace, same, evidence, silent


def _same_oracle_and_party(misbehavior):
    return lambda m: m.oracle == misbehavior.oracle and set(m.actors) == set(misbehavior.actors)


def counterfactual(scenario, misbehavior, replay: Replay, verdict: Attribution) -> Attribution:
    """Drive ``scenario`` with the careful driver; the same failure makes the verdict ``other``."""
    _others, _trace, same, evidence, silent = _careful_replay(scenario, misbehavior, replay, verdict,
                                                             _same_oracle_and_party(misbehavior))
    if same:
        m = same[0]
        return Attribution(Fault.OTHER, f"a careful driver could not avoid it either ({m.oracle}/{m.kind} "
                                        f"at {m.time:.1f} s)", evidence, verdict.rule)
    if silent is not None:  # it never got there: the replay says nothing about this event
        return Attribution(Fault.UNCLEAR, verdict.reason + f"; the careful driver's replay failed first "
                           f"({silent.removeprefix('it failed first: ').removeprefix('it ')})", evidence, verdict.rule)
    return Attribution(verdict.fault, verdict.reason + "; a careful driver avoided it", evidence, verdict.rule)


def test_excuse(scenario, trace, misbehavior, replay: Replay, verdict: Attribution) -> Attribution:
    """Drive ``scenario`` with the careful driver to test the excuse ``verdict`` (``other``, a rule of
    :data:`AVOIDED`): it holds if the careful driver fails the same way (same oracle, same other party), or if the
    replay says nothing (it failed first, never came near the place, or did not run); otherwise the verdict is
    the ego's, and its reason says what the careful driver did instead."""
    stuck = misbehavior.oracle in STANDSTILL  # held up or blocked: standing still and timing out are one failure
    same_failure = (lambda m: m.oracle in STANDSTILL) if stuck else _same_oracle_and_party(misbehavior)
    _others, ctrace, same, evidence, silent = _careful_replay(scenario, misbehavior, replay, verdict, same_failure,
                                                              excuse=verdict.rule)
    if same:
        m = same[0]
        return Attribution(Fault.OTHER, f"{verdict.reason}; a careful driver could not avoid it either ({m.oracle}/"
                                        f"{m.kind} at {m.time:.1f} s)", evidence, verdict.rule)
    if silent is not None:
        return Attribution(Fault.OTHER, f"{verdict.reason}; the careful driver's replay says nothing ({silent})",
                           evidence, verdict.rule)
    instead = _what_careful_did(ctrace, trace, misbehavior)
    evidence["counterfactual"].update(instead[1])
    if stuck and instead[1]["careful_distance_to_place"] <= REACHED_M and instead[1]["careful_speed_then"] <= 0.5:
        # no oracle fired on the replay, but it stood at the same place at the event's time: it was held the same
        return Attribution(Fault.OTHER, f"{verdict.reason}; a careful driver stood there too at "
                                        f"{misbehavior.time:.1f} s", evidence, verdict.rule)
    closest = instead[1].get("careful_closest")
    far = instead[1]["careful_distance_to_place"] > MET_M
    if closest is not None and closest > MET_M and far:  # it never met the other party: timing, not care
        return Attribution(Fault.OTHER, f"{verdict.reason}; the careful driver's replay says nothing (it never met "
                                        f"{misbehavior.actors[0]}: {closest:.0f} m at the closest)", evidence,
                           verdict.rule)
    if closest is not None and verdict.rule in VEHICLE_EXCUSES and not _reacted(instead[1]):
        # it passed the other vehicle without slowing for it: it came by at another time, which is no care
        return Attribution(Fault.OTHER, f"{verdict.reason}; the careful driver's replay says nothing (it passed "
                                        f"{misbehavior.actors[0]} without slowing for it)", evidence, verdict.rule)
    return Attribution(Fault.EGO, f"{verdict.reason}, but the careful driver's replay avoided it: {instead[0]}",
                       evidence, AVOIDED[verdict.rule])


def _reacted(ev: Mapping[str, Any]) -> bool:
    """Whether the careful driver slowed for the other party: at its closest approach it drove below 70 % of its
    fastest in the :data:`REACT_WINDOW` before, or below 1 m/s."""
    return ev["careful_speed_closest"] < max(0.7 * ev["careful_speed_before"], 1.0)


def _what_careful_did(ctrace, trace, mb) -> tuple[str, dict[str, Any]]:
    """What the careful driver's replay ``ctrace`` did about the event ``mb`` of ``trace``, in words, and as
    evidence: how close it came to the other party, and where it was (and how fast) at the event's time."""
    t_event = float(mb.time)
    tc = np.asarray(ctrace["t"], dtype=float)
    k = int(np.clip(np.searchsorted(tc, t_event), 0, len(tc) - 1))
    x, y, v = np.asarray(ctrace["x"], float), np.asarray(ctrace["y"], float), np.asarray(ctrace["speed"], float)
    px, py = mb.position
    at = float(math.hypot(x[k] - px, y[k] - py))
    ev: dict[str, Any] = {"careful_distance_to_place": round(at, 2), "careful_speed_then": round(float(v[k]), 2)}
    where = (f"at {t_event:.1f} s it was {at:.1f} m from the place at {float(v[k]):.1f} m/s" if at > 1.0 else
             f"at {t_event:.1f} s it was at the place at {float(v[k]):.1f} m/s")
    who = mb.actors[0] if mb.actors else None
    tr = actor_track(ctrace, who) if who is not None else None
    if tr is not None:
        d = np.hypot(tr.x - x, tr.y - y)
        if np.any(~np.isnan(d)):
            j = int(np.nanargmin(d))
            gap = float(d[j]) - 0.5 * (float(tr.length) + EGO_LENGTH) if tr.kind == "vehicle" else \
                float(d[j]) - 0.5 * EGO_LENGTH
            before = v[max(j - int(REACT_WINDOW / max(float(tc[1] - tc[0]), 1e-3)) if len(tc) > 1 else j, 0):j + 1]
            ev.update(careful_closest=round(float(d[j]), 2), careful_speed_closest=round(float(v[j]), 2),
                      careful_speed_before=round(float(np.nanmax(before)), 2))
            how = "stood" if v[j] <= STATIONARY_SPEED else f"drove at {float(v[j]):.1f} m/s"
            return (f"it came no closer to {who} than {float(d[j]):.1f} m centre to centre (about "
                    f"{max(gap, 0.0):.1f} m clear; it {how} then), and {where}", ev)
    if mb.oracle in ("immobility", "mission"):
        return f"it got on ({where})", ev
    return where, ev


class _Event:
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
        glare = _dazzled(self.scenario, self.trace, app.onset, self.f)
        sight = _short_sight(self.scenario)
        # on ice met on the way in, a stop at the line may have been beyond any driver who cannot see the ice:
        # the careful driver's replay decides
        t = self.trace["t"]
        ice = _slippery(self.trace, self.f, window_s=max(6.0, float(t[self.f] - t[app.onset])))
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
        return f"{oth.id} struck from behind without braking (it shed {max(shed, 0.0):.1f} m/s)"

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
        # braking no harder than comfort, lawfully in its lane: the follower's to avoid, wherever the ego drove;
        # hard braking, even for a hazard, may be what a careful driver's anticipation spares: the replay tests it
        kept = {KEPT: "it drove lawfully in its lane and braked gently"} if hazard is None else {}
        return self.other("rear_ended", f"the vehicle {oth.id} struck the ego's rear half at {dv:.1f} m/s faster while the ego "
                          f"drove lawfully in its lane, braking at most {max(peak, 0.0):.1f} m/s^2{why}",
                          peak_decel=peak, hazard=hazard, **kept)

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
        how = (f"moved into the ego's lane alongside it" if gap0 < 0.0 else
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
            shift = next((s.shift for s in self.scenario.signals if s.tls == tls), 0.0)
            state = signal_state(str(self.rmap.path), tls, conn.getTLLinkIndex(), t_in, shift)
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

    # ------------------------------------------------------------------ standstills
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
                return self.other("held_up", f"held up behind slower traffic ({leader}) for {share:.0%} of the run",
                                  held_share=share, leader=leader,
                                  **{KEPT: "a leader it cannot pass holds up any driver behind it alike"})
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

