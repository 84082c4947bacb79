"""Semantic bug signatures: what makes two findings the same bug, across campaigns and networks.

Used by the fuzz loop's triage to keep one finding record per signature (with a count and the
executions that hit it). A signature describes the situation, never where or with whom it
happened: no actor IDs (they are counters), no positions, no element IDs. Its fields:

- ``oracle``, ``kind``: the misbehaviour;
- ``maneuver``: what the ego was doing in the :data:`WINDOW` seconds before the event:
  ``stationary``, ``left``/``right`` (heading change over :data:`TURN_ANGLE`), ``lane_change``,
  ``stopping`` (braking and losing speed), else ``straight``;
- ``element``: ``junction`` or ``edge`` with the right-of-way class of the ego's link (the one it
  is crossing, or the one it is approaching within :data:`APPROACH` m of its lane's end):
  ``traffic_light``, ``priority``, ``yield``, ``stop`` or ``none``, from the network's connections
  (SUMO's link state), e.g. ``"junction/traffic_light"``;
- ``other_kind`` (``vehicle``/``pedestrian``/``obstacle``/``none``) and ``other_nav`` (its navigation
  type in the scenario: ``autopilot``/``linear``/``maneuver``/``immobile``/``none``): the other party,
  for a standstill the body that blocked the ego's lane (the parked or stalled head of a queue that
  would not move, not the car queued behind it);
- ``approach``: where the other party came from relative to the ego's heading
  :data:`APPROACH_BEFORE` s before the event (``behind``/``ahead``/``left``/``right``/``oncoming``);
- ``contact_side``: the side of the ego that was hit (``front``/``rear``/``left``/``right``/``none``);
  a walker who walked into a standing ego (rule ``stationary_struck``) has approach and side ``any``: one
  incident, however she came;
- ``fault``: the attribution's verdict.

``key`` is a short stable hash of the fields; ``label`` a one-line description.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass

import numpy as np

from drivefuzz.triage.attribute import Attribution
from drivefuzz.triage.evidence import (
    STATIONARY_SPEED,
    actor_track,
    approach,
    contact_point,
    contact_side,
    ego_link,
    frames_before,
    lane_changed,
)

#: [s] before the event that the ego's manoeuvre is read from.
WINDOW = 3.0
#: [rad] heading change that makes a turn.
TURN_ANGLE = math.radians(30.0)
#: [m] from the lane's end within which the ego counts as approaching its next link.
APPROACH = 30.0
#: [s] before the event at which the other party's approach is read.
APPROACH_BEFORE = 2.0


@dataclass(frozen=True)
class Signature:
    oracle: str
    kind: str
    maneuver: str  # stationary | left | right | lane_change | stopping | straight
    element: str  # "junction/<class>" or "edge/<class>"; class: traffic_light priority yield stop none
    other_kind: str  # vehicle | pedestrian | obstacle | none
    other_nav: str  # autopilot | linear | maneuver | immobile | none
    approach: str  # behind | ahead | left | right | oncoming | none
    contact_side: str  # front | rear | left | right | none
    fault: str  # ego | other | unclear

    @property
    def key(self) -> str:
        """12 hex digits of a SHA-256 over the fields in order (stable across processes and versions)."""
        blob = "|".join(str(v) for v in asdict(self).values()).encode()
        return hashlib.sha256(blob).hexdigest()[:12]

    @property
    def label(self) -> str:
        other = "nothing else involved" if self.other_kind == "none" else \
            f"{self.other_nav} {self.other_kind} from {self.approach}"
        hit = f", hit {self.contact_side}" if self.contact_side != "none" else ""
        return (f"{self.oracle}/{self.kind}: ego {self.maneuver.replace('_', ' ')} on {self.element}, "
                f"{other}{hit} (fault: {self.fault})")

    def as_dict(self) -> dict[str, str]:
        return {**asdict(self), "key": self.key, "label": self.label}


def signature(scenario, trace, misbehavior, rmap, attribution: Attribution) -> Signature:
    """The signature of ``misbehavior`` in ``trace`` (see the module docstring)."""
    n = trace.n_frames
    f = min(max(int(misbehavior.frame), 0), max(n - 1, 0))
    other_id = _other_party(misbehavior, attribution, trace, f)
    other_kind, other_nav, appr, side = "none", "none", "none", "none"
    if misbehavior.oracle == "collision" and misbehavior.kind == "obstacle":
        other_kind, other_nav = "obstacle", "immobile"
        side = str(attribution.evidence.get("contact_side", "none"))
    elif other_id is not None and n:
        track = actor_track(trace, other_id)
        if track is not None:
            other_kind = track.kind
            other_nav = _nav(scenario, other_id)
            appr = approach(trace, f, track, APPROACH_BEFORE)
            if misbehavior.oracle == "collision":
                side = contact_side(contact_point(trace, f, track))
    moved = maneuver(trace, f) if n else "none"
    if attribution.rule == "stationary_struck" and other_kind == "pedestrian":
        # a walker into a standing ego (an incident): one signature, whichever way she came and wherever she struck
        appr, side, moved = "any", "any", "stationary"
    return Signature(
        oracle=misbehavior.oracle, kind=misbehavior.kind,
        maneuver=moved,
        element=element(scenario, trace, rmap, f) if n else "none",
        other_kind=other_kind, other_nav=other_nav, approach=appr, contact_side=side,
        fault=attribution.fault.value,
    )


def situation(scenario, trace, rmap, f: int, actor: str) -> str:
    """The situation of a risky moment (frame ``f``, the other party ``actor``) without its outcome: the
    fields a finding's signature would share with it (manoeuvre, element, the other's kind, navigation
    and approach), joined by ``|``. The search counts how often it met each (its behavioural coverage)."""
    f = min(max(int(f), 0), max(trace.n_frames - 1, 0))
    track = actor_track(trace, actor)
    kind, nav, appr = ("none", "none", "none") if track is None else (
        track.kind, _nav(scenario, actor), approach(trace, f, track, APPROACH_BEFORE))
    return "|".join((maneuver(trace, f), element(scenario, trace, rmap, f), kind, nav, appr))


def _other_party(mb, attribution: Attribution, trace, f: int) -> str | None:
    if mb.actors:
        return mb.actors[0]
    if attribution.evidence.get("leader"):  # a time-out behind slower traffic
        return str(attribution.evidence["leader"])
    if attribution.evidence.get("blocker"):  # a standstill in a queue behind a parked or stalled car
        return str(attribution.evidence["blocker"])
    lanes = attribution.evidence.get("lanes")
    if isinstance(lanes, dict) and lanes:  # a standstill: the body blocking the ego's own lane, else any
        own = str(trace["lane"][f]) if trace.n_frames else ""
        return lanes.get(own) or next(iter(lanes.values()))
    return None


def _nav(scenario, actor_id: str) -> str:
    for a in getattr(scenario, "actors", ()):
        if a.id == actor_id:
            return a.nav.value
    return "none"


def maneuver(trace, f: int) -> str:
    """The ego's manoeuvre in the :data:`WINDOW` s up to frame ``f``."""
    speed = trace["speed"]
    if speed[f] <= STATIONARY_SPEED and float(np.max(speed[frames_before(trace, f, 1.0)])) <= 3 * STATIONARY_SPEED:
        return "stationary"
    w = frames_before(trace, f, WINDOW)
    heading = np.unwrap(np.asarray(trace["heading"][w], dtype=float))
    turn = float(heading[-1] - heading[0]) if len(heading) > 1 else 0.0
    if abs(turn) >= TURN_ANGLE:
        return "left" if turn > 0 else "right"
    if lane_changed(trace, f, WINDOW):
        return "lane_change"
    recent = frames_before(trace, f, 1.0)
    ax = trace["ax"][recent]
    if len(ax) and float(np.nanmean(ax)) < -1.0 and speed[f] < 0.8 * float(np.max(speed[w])):
        return "stopping"
    return "straight"


def element(scenario, trace, rmap, f: int) -> str:
    """``junction/<class>`` or ``edge/<class>`` of the ego at frame ``f`` (see the module docstring)."""
    lane = str(trace["lane"][f])
    if lane.startswith(":"):
        conn = ego_link(trace, rmap, f)
        return f"junction/{right_of_way(conn)}"
    if not lane or not rmap.has_lane(lane):
        return "edge/none"
    g = rmap.geom(lane)
    pos, _ = g.project(float(trace["x"][f]), float(trace["y"][f]))
    if g.length - pos > APPROACH:
        return "edge/none"
    return f"edge/{right_of_way(_next_link(scenario, rmap, lane))}"


def _next_link(scenario, rmap, lane: str):
    """The connection from ``lane`` the mission's route takes next (any connection of the lane if the
    route does not say)."""
    outgoing = [c for c in rmap.lane(lane).getOutgoing() if c.getToLane().allows("passenger")]
    if not outgoing:
        return None
    edge = rmap.lane(lane).getEdge().getID()
    route = None
    if scenario is not None:
        route = rmap.route(scenario.mission.start_edge, scenario.mission.goal_edge)
    if route and edge in route[:-1]:
        nxt = route[route.index(edge) + 1]
        on_route = [c for c in outgoing if c.getTo().getID() == nxt]
        if on_route:
            return on_route[0]
    return outgoing[0]


#: SUMO link states (net.xml ``state``) to right-of-way classes.
_STATE_CLASS = {"M": "priority", "m": "yield", "=": "yield", "Z": "yield", "s": "stop", "w": "stop",
                "O": "none", "o": "none"}


def right_of_way(conn) -> str:
    """traffic_light / priority / yield / stop / none of a sumolib connection (None: none)."""
    if conn is None:
        return "none"
    if conn.getTLSID():
        return "traffic_light"
    return _STATE_CLASS.get(conn.getState(), "none")

