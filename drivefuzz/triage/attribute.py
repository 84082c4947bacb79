"""Attribution: was a misbehaviour the ego's fault?

Used by the fuzz loop's triage (a finding is reported only when the ego is at fault; the
rest are incidents) and by the signatures (:mod:`drivefuzz.triage.signature`).

:func:`attribute` reads the frozen trace, the scenario and the road map. Two sources decide:

- **Rules on the trace** (each gives ``other`` with its evidence, or does not apply):

  0. (``ego``, decided) the ego entered the junction on red; its link had to yield to the other's;
     it changed lanes into a vehicle alongside (moved sideways towards it more than it came);
  1. *stationary*: the ego stood still when it was struck (and stood where it may: it had not
     just crossed a stop line on red);
  2. *rear*: the ego was struck in its rear half while lawfully in its lane (no lane change in
     the last :data:`LANE_CHANGE_WINDOW` seconds, no red light crossed) and it had not braked
     harder than :data:`COMFORT_DECEL` without a hazard ahead;
  3. *right of way*: the other vehicle entered the junction on red, or from a link that must
     yield to the ego's (SUMO's junction logic: the response bits of the two connections),
     while the ego entered lawfully;
  4. *pedestrian*: a pedestrian entered the ego's path (or walked into its side) closer than the
     distance the ego needed to stop: reaction time plus braking at the grip under it
     (``min(mu g, max brake)``), counted from the later of the moment it entered the path and
     the moment the ego could see it (sensor range shortened by fog and rain, field of view,
     line of sight past other vehicles);
  5. *blocked* (immobility and mission): every lane the ego may lawfully use is blocked ahead by a
     stationary body (in a junction: the body right ahead), a pedestrian stands in its lane ahead,
     or the queue ahead of the ego is itself blocked; a mission time-out while the ego spent most
     of the run held up behind slower traffic. Waiting behind a stationary body with a lawful lane
     free is the ego's (decided: the careful driver does not overtake either).

- **Avoidability by counterfactual replay**: when no rule excuses the ego and the caller gives
  ``replay``, the same scenario is driven by the careful reference driver (ADS ``careful``,
  :mod:`ego.careful`). If it fails the same way (same oracle, same other party), the situation
  was unavoidable: ``other``. Not after a rule that found the ego's own fault (it entered on red;
  it stayed behind a stationary body with a lane free): the careful driver would share the one
  (it does not overtake either) and never meet the other.

Otherwise the verdict is ``ego`` with what the ego did; ``unclear`` when the trace lacks the
evidence (the other party is not in it, the frame is outside it).

Units: SI; positions are body centres; headings radians ENU (as in the trace).
"""

from __future__ import annotations

import functools
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from drivefuzz.geometry import corners
from drivefuzz.scenario.model import EGO_LENGTH, EGO_WIDTH, AdsSpec, lane_edge

#: [m/s^2] braking a following driver must expect; harder braking needs a hazard ahead.
COMFORT_DECEL = 3.5
#: [m/s] at or below this the ego counts as stationary.
STATIONARY_SPEED = 0.1
#: [s] reaction (perception + actuation) before the brakes act.
REACTION_TIME = 0.3
#: [m/s^2] the car's full braking when grip allows (drivefuzz.sim.physics.VehicleParams.max_brake_decel).
MAX_BRAKE = 9.0
G = 9.81  #: [m/s^2]
#: [s] a lane change this recent makes a rear-end the ego's cut-in, not the follower's fault.
LANE_CHANGE_WINDOW = 3.0
#: [s] how long a body must have stood still to block a lane.
STILL_FOR = 5.0
#: Signal states that mean stop.
RED = frozenset("rRu")
#: The ADS the counterfactual replay uses.
CAREFUL_ADS = "careful"

Replay = Callable[[Any], tuple[Sequence[Any], Any]]


class Fault(str, Enum):
    EGO = "ego"
    OTHER = "other"
    UNCLEAR = "unclear"


@dataclass(frozen=True)
class Attribution:
    """A verdict, the one-line reason a reader can check, and its evidence (JSON-safe)."""

    fault: Fault
    reason: str
    evidence: Mapping[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {"fault": self.fault.value, "reason": self.reason, "evidence": _json_safe(self.evidence)}


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


# ---------------------------------------------------------------------- the event
@dataclass
class Track:
    """One actor's states by frame (NaN where it was absent)."""

    id: str
    kind: str  # "vehicle" | "pedestrian"
    length: float
    width: float
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray

    def present(self, f: int) -> bool:
        return 0 <= f < len(self.x) and not math.isnan(self.x[f])


def actor_track(trace, actor_id: str) -> Track | None:
    """The per-frame states of ``actor_id``, or None if the trace never saw it."""
    a = trace.actors
    if actor_id not in a.ids:
        return None
    j = a.ids.index(actor_id)
    rows = a.actor == j
    n = trace.n_frames
    out = [np.full(n, np.nan) for _ in range(4)]
    fr = a.frame[rows]
    for arr, src in zip(out, (a.x, a.y, a.heading, a.speed)):
        arr[fr] = src[rows]
    return Track(actor_id, a.kinds[j], float(a.length[j]), float(a.width[j]), *out)


def to_local(trace, f: int, x: float, y: float) -> tuple[float, float]:
    """(forward, left) [m] of (x, y) in the ego's body frame at frame ``f``."""
    ex, ey, h = float(trace["x"][f]), float(trace["y"][f]), float(trace["heading"][f])
    dx, dy = x - ex, y - ey
    c, s = math.cos(h), math.sin(h)
    return dx * c + dy * s, -dx * s + dy * c


def contact_point(trace, f: int, other: Track) -> tuple[float, float] | None:
    """Where on the ego the contact is, (forward, left) [m] in its body frame at frame ``f``: the
    centroid of the overlap of the two bodies, or the ego's point nearest the other body."""
    from shapely.geometry import Polygon
    from shapely.ops import nearest_points

    if not other.present(f):
        return None
    ego = Polygon(corners(trace["x"][f], trace["y"][f], trace["heading"][f], EGO_LENGTH, EGO_WIDTH))
    oth = Polygon(corners(other.x[f], other.y[f], other.heading[f], other.length, other.width))
    inter = ego.intersection(oth)
    p = inter.centroid if inter.area > 1e-6 else nearest_points(ego, oth)[0]
    return to_local(trace, f, p.x, p.y)


def contact_side(point: tuple[float, float] | None) -> str:
    """front/rear/left/right of a body-frame contact point (by the ego's normalised extents)."""
    if point is None:
        return "none"
    u, v = point[0] / (EGO_LENGTH / 2), point[1] / (EGO_WIDTH / 2)
    if abs(u) >= abs(v):
        return "front" if u > 0 else "rear"
    return "left" if v > 0 else "right"


def approach(trace, f: int, other: Track, before: float = 2.0) -> str:
    """Where ``other`` came from relative to the ego, ``before`` seconds ahead of frame ``f`` (or when it
    first appeared): behind/ahead (travelling the ego's way, or standing), oncoming, left/right
    (crossing; the side it was on). "none" without the other."""
    k = max(f - int(round(before / trace.step_length)), 0)
    present = [j for j in range(k, f + 1) if other.present(j)]
    if not present:
        return "none"
    k = present[0]
    lx, ly = to_local(trace, k, float(other.x[k]), float(other.y[k]))
    if float(other.speed[k]) > 0.5:
        dh = abs(_angle(float(other.heading[k]) - float(trace["heading"][k])))
        if dh >= 3 * math.pi / 4:
            return "oncoming"
        if dh > math.pi / 4:
            return "left" if ly > 0 else "right"
        return "ahead" if lx > 0 else "behind"
    if abs(lx) >= abs(ly):
        return "ahead" if lx > 0 else "behind"
    return "left" if ly > 0 else "right"


def frames_before(trace, f: int, seconds: float) -> slice:
    """The frames from ``seconds`` before ``f`` up to ``f`` (inclusive)."""
    return slice(max(f - int(round(seconds / trace.step_length)), 0), f + 1)


def ran_red(trace, f: int, seconds: float = 10.0) -> int | None:
    """The frame (within ``seconds`` before ``f``) at which the ego entered a junction while its light
    showed a stop state, or None."""
    lane, state, dist = trace["lane"], trace["tls_state"], trace["tls_dist"]
    w = frames_before(trace, f, seconds)
    for k in range(max(w.start, 1), w.stop):
        if str(lane[k]).startswith(":") and not str(lane[k - 1]).startswith(":") and str(state[k - 1]) in RED \
                and dist[k - 1] < 5.0:
            return k
    return None


def lane_changed(trace, f: int, seconds: float = LANE_CHANGE_WINDOW) -> bool:
    """The ego moved between lanes of one normal edge within ``seconds`` before ``f``."""
    lanes = [str(l) for l in trace["lane"][frames_before(trace, f, seconds)] if l and not str(l).startswith(":")]
    return any(a != b and lane_edge(a) == lane_edge(b) for a, b in zip(lanes, lanes[1:]))


def sideways_into(trace, rmap, oth: Track, f: int, side: str, seconds: float = 1.5) -> tuple[float, float] | None:
    """(ego's, other's) sideways movement [m] towards each other over ``seconds`` before ``f``, measured
    square to the lane the ego was on then, when the ego moved at least 0.5 m towards ``side`` and
    more than the other moved towards it (the ego changed lanes into it); else None."""
    k = frames_before(trace, f, seconds).start
    lane = str(trace["lane"][k])
    if not lane or lane.startswith(":") or not rmap.has_lane(lane) or not oth.present(k):
        return None
    if lane_edge(str(trace["lane"][f])) != lane_edge(lane):  # turns are right-of-way questions
        return None
    g = rmap.geom(lane)
    sign = 1.0 if side == "left" else -1.0
    ego = sign * (g.project(float(trace["x"][f]), float(trace["y"][f]))[1]
                  - g.project(float(trace["x"][k]), float(trace["y"][k]))[1])
    other = -sign * (g.project(float(oth.x[f]), float(oth.y[f]))[1] - g.project(float(oth.x[k]), float(oth.y[k]))[1])
    if ego >= 0.5 and ego > other:
        return ego, other
    return None


def sensor_range(weather) -> float:
    """[m] the reference sensors' range in this weather (fog and rain shorten it; 12 m all round)."""
    return max(100.0 * (1.0 - 0.85 * weather.fog / 100.0) * (1.0 - 0.4 * weather.rain / 100.0), 12.0)


def stopping_distance(v: float, mu: float) -> float:
    """[m] reaction plus braking distance from ``v`` [m/s] with friction ``mu``."""
    decel = min(max(mu, 0.05) * G, MAX_BRAKE)
    return v * REACTION_TIME + v * v / (2.0 * decel)


# ---------------------------------------------------------------------- entry point
def attribute(scenario, trace, misbehavior, rmap, *, replay: Replay | None = None) -> Attribution:
    """The verdict on ``misbehavior`` (see the module docstring for the rules).

    ``replay(scenario) -> (misbehaviors, trace)`` runs a scenario; given, it is used for the
    counterfactual with the careful driver when no rule excuses the ego.
    """
    n = trace.n_frames
    if n == 0:
        return Attribution(Fault.UNCLEAR, "the trace is empty", {"frame": misbehavior.frame})
    f = min(max(int(misbehavior.frame), 0), n - 1)
    ev = _Event(scenario, trace, misbehavior, rmap, f)
    verdict = ev.judge()
    if verdict.fault is Fault.EGO and not ev.decided and replay is not None:
        return counterfactual(scenario, misbehavior, replay, verdict)
    return verdict


def counterfactual(scenario, misbehavior, replay: Replay, verdict: Attribution) -> Attribution:
    """Drive ``scenario`` with the careful driver; the same failure makes the verdict ``other``."""
    careful = scenario.model_copy(update={"ads": AdsSpec(name=CAREFUL_ADS)})
    others, _trace = replay(careful)
    same = [m for m in others if m.oracle == misbehavior.oracle and set(m.actors) == set(misbehavior.actors)]
    evidence = dict(verdict.evidence)
    evidence["counterfactual"] = {"ads": CAREFUL_ADS, "misbehaviors": [f"{m.oracle}/{m.kind}" for m in others],
                                  "same_failure": bool(same)}
    if same:
        m = same[0]
        return Attribution(Fault.OTHER, f"a careful driver could not avoid it either ({m.oracle}/{m.kind} "
                                        f"at {m.time:.1f} s)", evidence)
    return Attribution(verdict.fault, verdict.reason + "; a careful driver avoided it", evidence)


class _Event:
    """One misbehaviour with what the rules need; :meth:`judge` applies them."""

    def __init__(self, scenario, trace, mb, rmap, f: int):
        self.scenario, self.trace, self.mb, self.rmap, self.f = scenario, trace, mb, rmap, f
        #: an ``ego`` verdict from a rule that saw the ego's own fault (the careful driver would
        #: share it or never meet it): no counterfactual
        self.decided = False
        self.v = float(trace["speed"][f])
        self.base = {"frame": f, "time": round(float(trace["t"][f]), 3), "ego_speed": self.v,
                     "ego_lane": str(trace["lane"][f])}

    def other(self, reason: str, **evidence) -> Attribution:
        return Attribution(Fault.OTHER, reason, {**self.base, **evidence})

    def ego(self, reason: str, decided: bool = False, **evidence) -> Attribution:
        self.decided = decided
        return Attribution(Fault.EGO, reason, {**self.base, **evidence})

    def judge(self) -> Attribution:
        oracle = self.mb.oracle
        if oracle == "collision":
            return self.collision()
        if oracle in ("immobility", "mission"):
            return self.standstill()
        return self.ego(f"the ego's own driving: {oracle}/{self.mb.kind}")

    # ------------------------------------------------------------------ collisions
    def collision(self) -> Attribution:
        mb, trace, f = self.mb, self.trace, self.f
        if mb.kind == "obstacle":
            return self.ego(f"the ego drove into the static obstacle {mb.actors[0] if mb.actors else '?'} at "
                            f"{self.v:.1f} m/s", other=list(mb.actors))
        if not mb.actors:
            return Attribution(Fault.UNCLEAR, "the collision names no other party", dict(self.base))
        oth = actor_track(trace, mb.actors[0])
        if oth is None or not oth.present(f):
            return Attribution(Fault.UNCLEAR, f"{mb.actors[0]} is not in the trace at the contact",
                               {**self.base, "other": mb.actors[0]})
        point = contact_point(trace, f, oth)
        side = contact_side(point)
        self.base.update(other=oth.id, other_kind=oth.kind, other_speed=float(oth.speed[f]), contact_side=side,
                         contact_point=list(point) if point else None)
        red = ran_red(trace, f)
        if self.rule_stationary(oth, point, side, red) is None and side in ("left", "right") and oth.kind == "vehicle":
            moved = sideways_into(trace, self.rmap, oth, f, side)
            if moved is not None:
                return self.ego(f"the ego changed lanes into the vehicle {oth.id} alongside (it moved {moved[0]:.1f} m "
                                f"sideways towards it, {oth.id} {round(moved[1], 1) + 0.0:.1f} m)", decided=True,
                                ego_sideways=moved[0], other_sideways=moved[1])
        for rule in (self.rule_stationary, self.rule_rear, self.rule_right_of_way, self.rule_pedestrian):
            verdict = rule(oth, point, side, red)
            if verdict is not None:
                return verdict
        if red is not None:
            return self.ego(f"the ego entered the junction on red (frame {red}) and hit {oth.id}", decided=True,
                            red_frame=red)
        if oth.kind == "vehicle" and self._ego_must_yield_to(oth):
            mine = ego_link(trace, self.rmap, f)
            return self.ego(f"the ego did not yield to the vehicle {oth.id} at {mine.getJunction().getID()}: its link "
                            f"from {mine.getFromLane().getID()} must yield", decided=True,
                            ego_from=mine.getFromLane().getID())
        still = float(np.nanmax(oth.speed[frames_before(trace, f, 2.0)])) <= STATIONARY_SPEED
        what = f"stationary {oth.kind}" if still else oth.kind
        return self.ego(f"the ego struck the {what} {oth.id} with its {side} at {self.v:.1f} m/s")

    def rule_stationary(self, oth: Track, point, side: str, red) -> Attribution | None:
        w = frames_before(self.trace, self.f, 0.5)
        if float(np.max(self.trace["speed"][w])) > STATIONARY_SPEED or red is not None or not self.trace["lane"][self.f]:
            return None
        return self.other(f"the ego was stationary ({self.v:.2f} m/s) when the {oth.kind} {oth.id} struck its {side}")

    def rule_rear(self, oth: Track, point, side: str, red) -> Attribution | None:
        trace, f = self.trace, self.f
        if oth.kind != "vehicle" or point is None or point[0] >= 0.0 or side in ("front",):
            return None
        if red is not None or not trace["lane"][f] or lane_changed(trace, f):
            return None
        # from behind: travelling the ego's way (a crossing or oncoming car that clips the rear
        # half is a right-of-way question, not a rear-end)
        if abs(_angle(float(oth.heading[f]) - float(trace["heading"][f]))) > math.pi / 4:
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
        return self.other(f"the vehicle {oth.id} struck the ego's rear half at {dv:.1f} m/s faster while the ego "
                          f"drove lawfully in its lane, braking at most {max(peak, 0.0):.1f} m/s^2{why}",
                          peak_decel=peak, hazard=hazard)

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
        if oth.kind != "vehicle" or red is not None:
            return None
        link = other_link(self.trace, self.rmap, oth, self.f)
        if link is None:
            return None
        conn, k_in = link
        t_in = float(self.trace["t"][k_in])
        tls = conn.getTLSID()
        ev = {"other_from": conn.getFromLane().getID(), "other_via": conn.getViaLaneID(), "other_entered_frame": k_in}
        if tls:
            state = signal_state(str(self.rmap.path), tls, conn.getTLLinkIndex(), t_in)
            if state is not None and state in RED:
                return self.other(f"the vehicle {oth.id} entered junction {conn.getJunction().getID()} on red "
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
            return self.other(f"the vehicle {oth.id} came from {conn.getFromLane().getID()}, a link that must yield, "
                              f"into the ego's right of way at {node.getID()}",
                              ego_from=mine.getFromLane().getID(), **ev)
        return None

    def rule_pedestrian(self, oth: Track, point, side: str, red) -> Attribution | None:
        if oth.kind != "pedestrian":
            return None
        trace, f = self.trace, self.f
        k_in = path_entry(trace, oth, f)
        if side in ("left", "right") and k_in is None:
            return self.other(f"the pedestrian {oth.id} walked into the ego's {side} side")
        if k_in is None:
            return None
        k_vis = first_visible(trace, oth, f, self.scenario)
        if k_vis is None:
            return self.other(f"the pedestrian {oth.id} was never visible before it was struck",
                              entered_frame=k_in)
        k0 = max(k_in, k_vis)
        v = float(trace["speed"][k0])
        mu = float(np.nanmin([trace["mu_front"][k0], trace["mu_rear"][k0], 1.0]))
        gap = _gap_ahead(trace, k0, oth)
        need = stopping_distance(v, mu)
        ev = dict(entered_frame=k_in, visible_frame=k_vis, gap=gap, speed_then=v, mu=mu, stopping_distance=need)
        if gap < need:
            return self.other(f"the pedestrian {oth.id} entered the ego's path {gap:.1f} m ahead at {v:.1f} m/s; "
                              f"stopping needed {need:.1f} m (mu {mu:.2f})", **ev)
        self.base.update(ev)
        return None

    # ------------------------------------------------------------------ standstills
    def standstill(self) -> Attribution:
        trace, f = self.trace, self.f
        if self.v > 0.5:
            held = held_up(trace, f)
            if self.mb.kind == "timeout" and held is not None:
                share, leader = held
                return self.other(f"held up behind slower traffic ({leader}) for {share:.0%} of the run",
                                  held_share=share, leader=leader)
            return self.ego(f"the ego did not reach its goal in time ({self.mb.oracle}/{self.mb.kind})")
        blocked = blocked_lanes(trace, self.rmap, f)
        if blocked is None:
            return self.ego(f"the ego stood still with nothing blocking its way ({self.mb.oracle}/{self.mb.kind})")
        lanes, free, queue = blocked
        ev = {"lanes": {l: b for l, b in lanes.items()}, "free_lanes": free}
        own = lanes.get(str(trace["lane"][f]))
        if own is not None and actor_track(trace, own).kind == "pedestrian":
            return self.other(f"the pedestrian {own} stands in the ego's path", **ev)
        if not free and lanes:
            what = ", ".join(f"{l} by {b}" for l, b in lanes.items())
            return self.other(f"every lawful way forward is blocked by stationary bodies: {what}", **ev)
        if queue is not None:
            return self.other(f"the queue ahead is itself blocked: {queue}", queue=queue, **ev)
        if own is not None:
            return self.ego(f"the ego stayed behind the stationary {own} although {', '.join(free)} was free",
                            decided=True, **ev)
        return self.ego(f"the ego stood still although {', '.join(free)} was free", decided=True, **ev)


# ---------------------------------------------------------------------- junction links
@functools.lru_cache(maxsize=16)
def _programs(net_path: str) -> dict[str, tuple[str, float, list[tuple[float, str]]]]:
    """tls id -> (type, offset [s], phases (duration [s], state)) of the net file's first program."""
    out: dict[str, tuple[str, float, list[tuple[float, str]]]] = {}
    for _ev, el in ET.iterparse(net_path, events=("end",)):
        if el.tag == "tlLogic":
            tid = el.get("id", "")
            if tid not in out:
                phases = [(float(p.get("duration", "0")), p.get("state", "")) for p in el.findall("phase")]
                out[tid] = (el.get("type", "static"), float(el.get("offset", "0")), phases)
            el.clear()
        elif el.tag in ("edge", "junction", "connection"):
            el.clear()
    return out


def signal_state(net_path: str, tls: str, link: int, t: float) -> str | None:
    """The state of link ``link`` of the fixed-time program ``tls`` at simulation time ``t`` [s];
    None where the program is not fixed-time (the trace does not say what it showed)."""
    prog = _programs(net_path).get(tls)
    if prog is None or prog[0] != "static" or not prog[2]:
        return None
    _type, offset, phases = prog
    cycle = sum(d for d, _ in phases)
    if cycle <= 0:
        return None
    tc = (t - offset) % cycle
    for dur, state in phases:
        if tc < dur:
            return state[link] if link < len(state) else None
        tc -= dur
    return None


def _lane_of(rmap, x: float, y: float, internal: bool) -> str | None:
    best = None
    for lane, dist in rmap.net.getNeighboringLanes(x, y, 3.0, includeJunctions=True):
        if not lane.allows("passenger"):
            continue
        if lane.getID().startswith(":") != internal:
            continue
        if best is None or dist < best[1]:
            best = (lane.getID(), dist)
    return best[0] if best else None


def other_link(trace, rmap, oth: Track, f: int, seconds: float = 10.0):
    """(connection, frame it crossed the stop line) of the junction passage ``oth`` was making at
    ``f``, judged from its positions; None when it was not in or at the end of a junction."""
    dt = trace.step_length
    frames = [k for k in range(max(f - int(seconds / dt), 0), f + 1) if oth.present(k)]
    if not frames:
        return None
    stride = max(int(0.25 / dt), 1)
    sample = frames[::-1][::stride]  # newest first
    lane_in, k_last = None, None
    for k in sample:
        lane = _lane_of(rmap, float(oth.x[k]), float(oth.y[k]), internal=False)
        if lane is None:
            continue
        g = rmap.geom(lane)
        pos, lat = g.project(float(oth.x[k]), float(oth.y[k]))
        if abs(lat) < g.width / 2 and abs(_angle(float(oth.heading[k]) - g.position(pos)[2])) < math.pi / 4:
            lane_in, k_last = lane, k  # the newest normal lane it drove along
            break
    if lane_in is None:
        return None
    conns = [c for c in rmap.lane(lane_in).getOutgoing() if c.getViaLaneID()]
    if not conns:
        return None
    g = rmap.geom(lane_in)
    # the frame its front crossed the end of the lane (the stop line)
    k_in = None
    for k in frames:
        if k < k_last:
            continue
        fx = oth.x[k] + math.cos(oth.heading[k]) * oth.length / 2
        fy = oth.y[k] + math.sin(oth.heading[k]) * oth.length / 2
        if g.project(float(fx), float(fy))[0] >= g.length - 0.2:
            k_in = k
            break
    if k_in is None:
        return None  # it had not reached the junction
    after = [k for k in frames if k >= k_in]
    pts = np.stack([oth.x[after], oth.y[after]], axis=1)

    def mismatch(c) -> float:
        shape = np.vstack([np.asarray(rmap.lane(v).getShape())[:, :2] for v in rmap.internal_chain(c.getViaLaneID())]
                          + [np.asarray(c.getToLane().getShape())[:2, :2]])
        return float(np.mean([_point_polyline(p, shape) for p in pts]))

    return min(conns, key=mismatch), k_in


def ego_link(trace, rmap, f: int, seconds: float = 15.0):
    """The connection of the ego's junction passage around ``f`` (from its lane channel), or None."""
    lanes = trace["lane"]
    w = frames_before(trace, f, seconds)
    via = None
    k = None
    for j in range(f, w.start - 1, -1):
        if str(lanes[j]).startswith(":"):
            via, k = str(lanes[j]), j
        elif via is not None:
            break
    if via is None:  # not yet in the junction: the next frames do not exist; use the lane's only links
        return None
    prev = next((str(lanes[j]) for j in range(k, w.start - 1, -1) if lanes[j] and not str(lanes[j]).startswith(":")),
                None)
    if prev is None:
        return None
    for c in rmap.lane(prev).getOutgoing():
        if c.getViaLaneID() and via in rmap.internal_chain(c.getViaLaneID()):
            return c
    return None


def _angle(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _point_polyline(p: np.ndarray, poly: np.ndarray) -> float:
    a, b = poly[:-1], poly[1:]
    d = b - a
    l2 = np.maximum((d * d).sum(1), 1e-12)
    t = np.clip(((p - a) * d).sum(1) / l2, 0.0, 1.0)
    q = a + t[:, None] * d
    return float(np.min(np.hypot(*(p - q).T)))


# ---------------------------------------------------------------------- pedestrians
def _ego_polyline(trace, k: int, f: int) -> np.ndarray:
    """The ego's centre path from ``k`` to ``f``, extended half a car ahead of its last pose."""
    xs, ys = trace["x"][k:f + 1], trace["y"][k:f + 1]
    h = float(trace["heading"][f])
    tip = (xs[-1] + math.cos(h) * EGO_LENGTH / 2, ys[-1] + math.sin(h) * EGO_LENGTH / 2)
    return np.vstack([np.stack([xs, ys], axis=1), [tip]])


def path_entry(trace, oth: Track, f: int, seconds: float = 10.0) -> int | None:
    """The frame from which ``oth`` stayed in the ego's path ahead until ``f`` (the ego's footprint
    swept from then to ``f``), or None if it was not ahead of the ego's front when it entered."""
    dt = trace.step_length
    corridor = EGO_WIDTH / 2 + oth.width / 2 + 0.2
    k_in = None
    for k in range(f, max(f - int(seconds / dt), 0) - 1, -1):
        if not oth.present(k):
            break
        poly = _ego_polyline(trace, k, f)
        p = np.array([oth.x[k], oth.y[k]])
        if _point_polyline(p, poly) > corridor:
            break
        k_in = k
    if k_in is None:
        return None
    lx, _ = to_local(trace, k_in, float(oth.x[k_in]), float(oth.y[k_in]))
    return k_in if lx > EGO_LENGTH / 2 - 0.3 else None


def _gap_ahead(trace, k: int, oth: Track) -> float:
    lx, _ = to_local(trace, k, float(oth.x[k]), float(oth.y[k]))
    return max(lx - EGO_LENGTH / 2 - oth.length / 2, 0.0)


def first_visible(trace, oth: Track, f: int, scenario) -> int | None:
    """The first frame up to ``f`` at which the reference sensors could see ``oth``: within range
    (weather), inside the 200 degree field of view or 12 m all round, not hidden behind a vehicle."""
    from shapely.geometry import LineString, Polygon

    rng = sensor_range(scenario.weather) if scenario is not None else 100.0
    cos_half = math.cos(math.radians(100.0))
    a = trace.actors
    for k in range(f + 1):
        if not oth.present(k):
            continue
        lx, ly = to_local(trace, k, float(oth.x[k]), float(oth.y[k]))
        d = math.hypot(lx, ly)
        if d > rng or (d > 12.0 and lx < cos_half * d):
            continue
        sight = LineString([(trace["x"][k], trace["y"][k]), (oth.x[k], oth.y[k])])
        r = a.rows(k)
        hidden = False
        for j, x, y, h in zip(a.actor[r], a.x[r], a.y[r], a.heading[r]):
            if a.ids[int(j)] == oth.id or a.kinds[int(j)] != "vehicle":
                continue
            if math.hypot(x - trace["x"][k], y - trace["y"][k]) > d + 5.0:
                continue
            if sight.intersects(Polygon(corners(x, y, h, a.length[int(j)], a.width[int(j)]))):
                hidden = True
                break
        if not hidden:
            return k
    return None


# ---------------------------------------------------------------------- blocked roads
def _still(track: Track, f: int, dt: float) -> bool:
    w = track.speed[max(f - int(STILL_FOR / dt), 0):f + 1]
    w = w[~np.isnan(w)]
    return len(w) > 0 and float(np.max(w)) <= 0.2


def _bodies_on(trace, rmap, lane: str, f: int, s_from: float, reach: float):
    """(distance along ``lane`` from ``s_from`` [m], actor id, still?) of every body on ``lane`` (and
    up to 10 m past its end, on the extended centre line) between ``s_from`` and ``s_from + reach``."""
    g = rmap.geom(lane)
    a = trace.actors
    r = a.rows(f)
    out = []
    end_x, end_y, end_h = g.position(g.length)
    for j, x, y in zip(a.actor[r], a.x[r], a.y[r]):
        j = int(j)
        pos, lat = g.project(float(x), float(y))
        if pos >= g.length - 0.01:  # past the end: along the extended last segment
            dx, dy = x - end_x, y - end_y
            pos = g.length + dx * math.cos(end_h) + dy * math.sin(end_h)
            lat = -dx * math.sin(end_h) + dy * math.cos(end_h)
            if pos > g.length + 10.0:
                continue
        if abs(lat) > g.width / 2 + a.width[j] / 2 - 0.3 or not (s_from < pos < s_from + reach):
            continue
        out.append((pos - s_from, a.ids[j]))
    return sorted(out)


def blocked_lanes(trace, rmap, f: int, reach: float = 60.0):
    """What blocks the ego standing at ``f``: ``(lanes, free, queue)`` with ``lanes`` the lawful lanes
    of its edge whose nearest body ahead stands still (lane -> that body), ``free`` the others, and
    ``queue`` a description when the stationary vehicle ahead of the ego is itself blocked (by a
    stationary body close ahead of it, or at the end of its lane); None off the normal lanes."""
    lane = str(trace["lane"][f])
    dt = trace.step_length
    if lane.startswith(":"):  # in a junction there is one way forward: the body right ahead
        ahead = _still_ahead(trace, f, dt)
        return ({lane: ahead}, [], None) if ahead else None
    if not lane or not rmap.has_lane(lane):
        return None
    tracks: dict[str, Track] = {}

    def track(aid: str) -> Track:
        if aid not in tracks:
            tracks[aid] = actor_track(trace, aid)
        return tracks[aid]

    ego_pos, _ = rmap.geom(lane).project(float(trace["x"][f]), float(trace["y"][f]))
    edge = rmap.lane(lane).getEdge()
    idx = rmap.lane(lane).getIndex()
    lanes_of = {l.getIndex(): l.getID() for l in edge.getLanes() if l.allows("passenger")}
    lawful = [lane]
    for step, left in ((1, True), (-1, False)):
        i = idx
        while i + step in lanes_of and rmap.may_change(lanes_of[i], left=left):
            i += step
            lawful.append(lanes_of[i])
    blocked, free, queue = {}, [], None
    for l in lawful:
        s_from = ego_pos if l == lane else ego_pos - EGO_LENGTH  # a body alongside blocks a change too
        bodies = _bodies_on(trace, rmap, l, f, s_from, reach)
        if bodies and _still(track(bodies[0][1]), f, dt):
            blocked[l] = bodies[0][1]
            if l == lane:
                queue = _queue_blocked(trace, rmap, l, f, bodies, track, dt)
        else:
            free.append(l)
    if not blocked:
        return None
    return blocked, free, queue


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


def _queue_blocked(trace, rmap, lane: str, f: int, bodies, track, dt) -> str | None:
    """Why the stationary leader (first of ``bodies``) cannot go: a stationary body close ahead of
    it, or it stands at the end of the lane (a queue at the junction)."""
    g = rmap.geom(lane)
    d0, lead = bodies[0]
    lt = track(lead)
    if lt.kind == "pedestrian":
        return None
    if len(bodies) > 1 and bodies[1][0] - d0 < lt.length / 2 + 12.0 and _still(track(bodies[1][1]), f, dt):
        return f"{lead} stands behind the stationary {bodies[1][1]}"
    pos, _ = g.project(float(lt.x[f]), float(lt.y[f]))
    if g.length - pos - lt.length / 2 < 3.0:
        return f"{lead} waits at the end of {lane}"
    return None


def held_up(trace, f: int, gap: float = 30.0) -> tuple[float, str] | None:
    """(share of frames, leader) when a slower vehicle was close ahead in the ego's lane for most of
    the run (at least half of the frames); None otherwise."""
    a = trace.actors
    n = min(f + 1, trace.n_frames)
    count, leaders = 0, {}
    for k in range(0, n, max(int(0.5 / trace.step_length), 1)):
        r = a.rows(k)
        lim = trace["speed_limit"][k]
        for j, x, y, v in zip(a.actor[r], a.x[r], a.y[r], a.speed[r]):
            lx, ly = to_local(trace, k, float(x), float(y))
            if 0 < lx < gap and abs(ly) < 1.5 and (math.isnan(lim) or v < 0.8 * lim):
                count += 1
                leaders[a.ids[int(j)]] = leaders.get(a.ids[int(j)], 0) + 1
                break
    total = len(range(0, n, max(int(0.5 / trace.step_length), 1)))
    if total and count / total >= 0.5:
        return count / total, max(leaders, key=leaders.get)
    return None
