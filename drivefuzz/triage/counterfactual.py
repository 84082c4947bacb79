"""The careful driver's replay: whether a careful driver, in the same scenario, avoided what the ego met.

Used by :func:`drivefuzz.triage.attribute.attribute` in two ways (the rules and their order are there):

- :func:`test_excuse`: **an excuse is a hypothesis** (issue 31). Several rules measure the situation with the ego's
  own speed and place, which its bug chose (a walker "walked into its side": into a car that should not have been
  there; an ego "stationary when struck" may have stopped where a careful driver would not). An excusing rule's
  ``other`` holds only if the careful driver fails the same way (same oracle, same other party; for a standstill,
  :data:`STANDSTILL`, it stands still or times out too, or stood at the same place at the event's time), or its
  replay says nothing about the event (it failed first, never came near, did not run); otherwise the verdict is the
  ego's, under the rule of :data:`~drivefuzz.triage.verdict.AVOIDED` (``stationary_struck`` -> ``stopped_in_the_way``,
  ``pedestrian`` -> ``pedestrian_avoidable``, ...), and its reason says what the careful driver did instead (how
  close it came to the other party, where and how fast it was at the event's time). A replay that never came
  within :data:`MET_M` of the other party and was farther than that from the place at the event's time says
  nothing either: it passed before or after the other came, which is timing, not care; so does one that passed
  another vehicle whose conduct is the excuse (ran a red, did not yield, struck from behind) without slowing for
  it (:data:`VEHICLE_EXCUSES`).
- :func:`counterfactual`: **avoidability** of a verdict that no rule excused: if the careful driver fails the same
  way (same oracle, same other party), the situation was unavoidable: ``other``; if it failed first or never came
  near, ``unclear``; otherwise the verdict stands and says that a careful driver avoided it.

The careful driver is the ADS ``careful`` (:mod:`ego.careful`), told of the scenario's puddles
(:func:`careful_scenario`). ``replay(scenario) -> (misbehaviors, trace)`` is the caller's executor.

Units: SI; positions are body centres.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from drivefuzz.scenario.model import EGO_LENGTH, AdsSpec
from drivefuzz.triage.evidence import STATIONARY_SPEED, actor_track
from drivefuzz.triage.verdict import AVOIDED, Attribution, Fault

#: [m] how close the careful driver's replay must come to the event's place to say anything about it.
REACHED_M = 10.0
#: The ADS the counterfactual replay uses.
CAREFUL_ADS = "careful"
#: [m] centre to centre: a careful driver whose replay never came this close to the other party, and was farther
#: than this from the event's place at its time, never met it (it came by earlier or later): its keeping clear
#: says nothing about the ego's excuse.
MET_M = 15.0
#: [m] from its stop line, a careful driver that waits at a red or yellow light is held by the light.
AT_STOP_LINE_M = 10.0
#: [s] before its closest approach to the other party over which the careful driver's slowing down counts.
REACT_WINDOW = 3.0
#: Excuses about another vehicle's conduct at a junction or from behind: the careful driver avoided it only if it
#: slowed for the vehicle (:func:`_reacted`); one that came by at its cruising speed was elsewhere when the other
#: came, by timing. (A cut-in is not among them: the careful driver's longer headway is the care that avoids it.)
VEHICLE_EXCUSES = frozenset({"other_ran_red", "other_failed_to_yield", "rear_ended"})
#: The oracles of a standstill: an excuse of one (blocked, held up) holds when the careful driver fails either.
STANDSTILL = frozenset({"immobility", "mission"})

Replay = Callable[[Any], tuple[Sequence[Any], Any]]


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
    if (stuck and instead[1]["careful_distance_to_place"] <= REACHED_M and instead[1]["careful_speed_then"] <= 0.5
            and "careful_goal_s" not in instead[1]):
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
    if closest is not None and verdict.rule in VEHICLE_EXCUSES and "careful_held_at_light" in instead[1]:
        # it slowed, but for a light at its stop line, not for the other vehicle: it was elsewhere by timing
        light = instead[1]["careful_held_at_light"]
        return Attribution(Fault.OTHER, f"{verdict.reason}; the careful driver's replay says nothing (it stood at a "
                                        f"{light} light when {misbehavior.actors[0]} came)", evidence, verdict.rule)
    return Attribution(Fault.EGO, f"{verdict.reason}, but the careful driver's replay avoided it: {instead[0]}",
                       evidence, AVOIDED[verdict.rule])


def _reacted(ev: Mapping[str, Any]) -> bool:
    """Whether the careful driver slowed for the other party: at its closest approach it drove below 70 % of its
    fastest in the :data:`REACT_WINDOW` before, or below 1 m/s."""
    return ev["careful_speed_closest"] < max(0.7 * ev["careful_speed_before"], 1.0)


def _held_at_light(ctrace, j: int) -> str | None:
    """The state of the light the careful driver waited at in frame ``j`` of its replay (red or yellow, its stop line
    within :data:`AT_STOP_LINE_M`, below the stationary speed), or None: what held it there, if not another party."""
    if "tls_state" not in getattr(ctrace, "ego", {}):
        return None
    state = str(ctrace["tls_state"][j])
    near = float(ctrace["tls_dist"][j]) <= AT_STOP_LINE_M  # NaN: no light ahead
    if state in ("r", "R", "y", "Y") and near and float(ctrace["speed"][j]) <= 1.0:
        return {"r": "red", "R": "red"}.get(state, "yellow")
    return None


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
    meta = getattr(ctrace, "meta", None) or {}
    if meta.get("termination") == "goal_reached" and float(tc[-1]) < t_event:  # its run ended before the event's time
        ev["careful_goal_s"] = round(float(tc[-1]), 2)
        where = f"it reached its goal at {float(tc[-1]):.1f} s, before the event's {t_event:.1f} s"
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
            light = _held_at_light(ctrace, j)
            if light is not None:
                ev["careful_held_at_light"] = light
            how = "stood" if v[j] <= STATIONARY_SPEED else f"drove at {float(v[j]):.1f} m/s"
            return (f"it came no closer to {who} than {float(d[j]):.1f} m centre to centre (about "
                    f"{max(gap, 0.0):.1f} m clear; it {how} then), and {where}", ev)
    if mb.oracle in ("immobility", "mission"):
        return f"it got on ({where})", ev
    return where, ev

