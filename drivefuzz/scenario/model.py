"""The Scenario: everything one execution needs, as validated pydantic models.

A scenario is the unit the mutator rewrites, the executor runs and a finding
stores. It is written as SUMO files by :mod:`drivefuzz.scenario.sumofiles` (actors in a
route file, puddles and weather in an additional file, the rest in a small JSON
manifest) and read back losslessly.

Units: SI (m, s, m/s) and radians, except where a name says otherwise
(weather aspects are the paper's 0-100 scales; sun angles are in degrees).
Positions along a lane are SUMO's: metres from the lane start to the vehicle's
front bumper.
"""

from __future__ import annotations

import hashlib
import math
import json
from enum import Enum
from pathlib import Path
from typing import Literal, Union

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

SCHEMA_VERSION = 1
#: [m] body of the ego car that drivefuzz's physics simulates (every ADS drives the same car)
EGO_LENGTH = 4.6
EGO_WIDTH = 1.9  #: [m]
#: [m/s] the fastest the ego may depart: SUMO's maxSpeed of a passenger car (its vType)
EGO_MAX_SPEED = 55.55

OptionValue = Union[bool, int, float, str]


#: [m/s] the fastest anything in a scenario may go (360 km/h); SUMO fails on more, or on inf
MAX_SPEED = 100.0
#: [s] the longest simulated time anything in a scenario may refer to (a day)
MAX_TIME = 86400.0
#: [m] the largest coordinate or distance in a scenario (SUMO's networks are far smaller)
MAX_COORD = 1e7


class _Model(BaseModel):
    # every number finite: SUMO aborts, hangs or segfaults on inf and nan
    model_config = ConfigDict(extra="forbid", frozen=True, use_enum_values=False, allow_inf_nan=False)


class ActorKind(str, Enum):
    VEHICLE = "vehicle"
    PEDESTRIAN = "pedestrian"


class NavType(str, Enum):
    """DriveFuzz's four navigation types."""

    AUTOPILOT = "autopilot"  # lawful SUMO driver or walker to its destination
    MANEUVER = "maneuver"  # timed sequence of speed and lane-change actions
    LINEAR = "linear"  # ignores every rule: constant speed straight to its destination
    IMMOBILE = "immobile"  # stands still where it was placed


class ManeuverAction(str, Enum):
    SPEED = "speed"  # set the target speed to ``value`` [m/s], at ``rate`` [m/s^2] (0: SUMO's own)
    LANE_LEFT = "lane_left"  # change one lane to the left, taking ``value`` [s]
    LANE_RIGHT = "lane_right"  # change one lane to the right, taking ``value`` [s]
    NUDGE_LEFT = "nudge_left"  # an aborted lane change: ``depth`` [m] to the left and back, in ``value`` [s]
    NUDGE_RIGHT = "nudge_right"  # the same to the right
    #: from now on, follow the vehicle ahead at a time gap of ``value`` [s] (SUMO's tau; its vType's is 1 s) and
    #: :data:`FOLLOW_GAP` m at a standstill: a close follower, as many drivers are (clock triggers only)
    FOLLOW = "follow"
    #: from now on, drive at the actor's speed without braking for the vehicle ahead until the time to collision
    #: with it is ``at`` [s] (at least :data:`MIN_CLOSE_TTC`), then brake as SUMO's car-following (and a follow
    #: step before it) does: a driver who closes in fast and brakes late (clock triggers only)
    CLOSE = "close"


class Trigger(str, Enum):
    """When a step of a maneuver program fires. Steps fire in order: a step is considered only once the
    one before it has fired. ``GAP`` and ``HEADWAY`` time the step against the ego, so that the situation
    survives a change of the ego's speed, and not before ``time`` s after the actor departed. A lane change
    or nudge fires when the measure crosses ``at`` (or at its first look if it is already within 0.5 m or
    0.05 s of it): never nearer than ``at`` to the ego. A speed step fires once the actor is ahead of the ego
    and the measure is ``at`` or less (the ego has closed in)."""

    TIME = "time"  # ``time`` s after the actor departed
    AFTER = "after"  # ``time`` s after the step before fired (after departing, for the first step)
    GAP = "gap"  # the actor's rear is ``at`` m ahead of the ego's front along the ego's heading (< 0: behind)
    HEADWAY = "headway"  # the same gap is ``at`` s of the ego's speed (at least 1 m/s)
    #: a nudge inside the actor's own lane (:func:`in_lane`): deepest as the same gap is ``at`` m; it starts when
    #: the gap, half its duration later at the closing speed of the moment, would be ``at``
    PEAK = "peak"


#: [m] how far an aborted lane change may reach sideways (a lane is about 3.5 m wide)
MAX_NUDGE = 2.5
#: [s] the shortest time gap a ``follow`` step may keep to the vehicle ahead (drivers on motorways keep 0.5-1 s
#: in dense traffic; under half a second is the reckless tail of the distribution) ...
MIN_FOLLOW_S = 0.5
#: ... and [m] the gap it keeps at a standstill (SUMO's minGap; its vType's is 2.5 m)
FOLLOW_GAP = 1.0
#: [s] the least time to collision at which a ``close`` step brakes: it then sheds its closing speed ``c`` at
#: ``c / (2 * 1.5 s)`` (2.7 m/s^2 at 8 m/s), well within a car's braking
MIN_CLOSE_TTC = 1.5
#: A careful driver's reaction [s] and firm braking [m/s^2] on a dry road, and the room [m] left over when it
#: has braked for a vehicle that cut in: the yardstick of every fairness rule (search/fairness.py).
CAREFUL_REACTION, CAREFUL_DECEL, CUT_IN_MARGIN = 0.75, 5.0, 5.0


#: [m] the body width of every other car (SUMO's default passenger vType; drivefuzz's vTypes keep it)
NPC_WIDTH = 1.8
#: [m] what an in-lane drift leaves between the drifting car's side and its lane's line
DRIFT_MARGIN = 0.05


def drift_room(lane_width: float, width: float = NPC_WIDTH) -> float:
    """[m] how far a car of ``width`` centred on a lane of ``lane_width`` may drift sideways inside it."""
    return (lane_width - width) / 2.0 - DRIFT_MARGIN


def in_lane(depth: float, lane_width: float, width: float = NPC_WIDTH) -> bool:
    """Whether a nudge of ``depth`` [m] keeps a car of ``width`` (centred on a lane of ``lane_width``) inside its
    own lane: a drift towards the line, not a lane change. It never enters the lane beside, so it needs no
    room ahead of the ego (:func:`cut_in_gap`) and may happen level with it, as drivers drift in traffic."""
    return depth <= drift_room(lane_width, width) + 1e-9


def cut_in_gap(closing: float, duration: float) -> float:
    """[m] the least gap ahead of the ego at which a vehicle closing at ``closing`` [m/s] may start a lane
    change (or nudge) of ``duration`` [s] into the ego's lane: it is in the lane after a third of the change,
    a careful driver reacts then and brakes, with :data:`CUT_IN_MARGIN` to spare. The mutator places programs
    by it, and the executor holds back a forced lane change that would start with less."""
    closing = max(closing, 0.0)
    return closing * (duration / 3.0 + CAREFUL_REACTION) + closing * closing / (2.0 * CAREFUL_DECEL) + CUT_IN_MARGIN


class Maneuver(_Model):
    time: float = Field(ge=0.0, le=MAX_TIME, description="[s] see Trigger")
    action: ManeuverAction
    value: float = Field(ge=0.0, le=MAX_SPEED, description="[m/s] for speed, [s] duration for lane changes "
                                                            "and nudges, [s] time gap for follow")
    trigger: Trigger = Trigger.TIME
    at: float = Field(default=0.0, ge=-1e3, le=1e3, description="[m] for gap, [s] for headway triggers")
    rate: float = Field(default=0.0, ge=0.0, le=12.0, description="[m/s^2] speed: how fast to reach the "
                                                                  "speed (0: SUMO's own)")
    depth: float = Field(default=0.0, ge=0.0, le=MAX_NUDGE, description="[m] nudges: how far sideways")


class Mission(_Model):
    start_lane: str = Field(min_length=1, description="SUMO lane id the ego starts on")
    start_pos: float = Field(ge=0.0, le=MAX_COORD, description="[m] of the front bumper along start_lane")
    goal_edge: str = Field(min_length=1)
    goal_pos: float = Field(ge=0.0, le=MAX_COORD, description="[m] along goal_edge")
    start_speed: float = Field(default=0.0, ge=0.0, le=EGO_MAX_SPEED,
                               description="[m/s] (SUMO: at most the start lane's limit)")

    @property
    def start_edge(self) -> str:
        return lane_edge(self.start_lane)


class Actor(_Model):
    id: str = Field(pattern=r"^[A-Za-z0-9_.\-]+$")
    kind: ActorKind
    nav: NavType
    start_lane: str = Field(min_length=1)
    start_pos: float = Field(ge=0.0, le=MAX_COORD, description="[m] along start_lane")
    speed: float = Field(ge=0.0, le=MAX_SPEED, description="[m/s] target speed")
    depart: float = Field(default=0.0, ge=0.0, le=MAX_TIME, description="[s]")
    dest_edge: str | None = Field(default=None, description="autopilot/maneuver/linear vehicles: destination edge")
    dest_pos: float | None = Field(default=None, ge=0.0, le=MAX_COORD, description="[m] along dest_edge")
    dest_xy: tuple[float, float] | None = Field(default=None, description="linear pedestrians: straight-line target [m]")
    maneuvers: tuple[Maneuver, ...] = ()

    @property
    def start_edge(self) -> str:
        return lane_edge(self.start_lane)

    @model_validator(mode="after")
    def _nav_fields(self) -> "Actor":
        if self.nav is NavType.MANEUVER and self.kind is ActorKind.PEDESTRIAN:
            raise ValueError("maneuver actors must be vehicles")
        if self.maneuvers and self.nav is not NavType.MANEUVER:
            raise ValueError("only maneuver actors carry maneuvers")
        if self.kind is ActorKind.PEDESTRIAN and self.nav is NavType.LINEAR and self.dest_xy is None:
            raise ValueError("a linear pedestrian needs dest_xy")
        if self.nav is not NavType.IMMOBILE and self.dest_edge is None and self.dest_xy is None:
            raise ValueError(f"a {self.nav.value} actor needs dest_edge")
        return self


class Puddle(_Model):
    """A reduced-friction area: an oriented rectangle."""

    x: float = Field(ge=-MAX_COORD, le=MAX_COORD, description="[m] centre (validate: on the network)")
    y: float = Field(ge=-MAX_COORD, le=MAX_COORD, description="[m] centre")
    length: float = Field(gt=0.0, le=1e4, description="[m] along the rotated x axis")
    width: float = Field(gt=0.0, le=1e4, description="[m]")
    rotation: float = Field(default=0.0, ge=-1e3, le=1e3, description="[rad] ENU, counter-clockwise")
    friction: float = Field(gt=0.0, le=2.0, description="coefficient mu in (0, 2]")

    def corners(self) -> list[tuple[float, float]]:
        """The rectangle's four corners [m], counter-clockwise from the front left."""
        c, s = math.cos(self.rotation), math.sin(self.rotation)
        out = []
        for dx, dy in ((0.5, 0.5), (-0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)):
            lx, ly = dx * self.length, dy * self.width
            out.append((self.x + c * lx - s * ly, self.y + s * lx + c * ly))
        return out


#: [m/s] the wind speed of ``Weather.wind`` = 100 (a near gale, Beaufort 7; CARLA's scale has no unit).
MAX_WIND_SPEED = 15.0


class Weather(_Model):
    """DriveFuzz's eight weather aspects (CARLA's scales)."""

    cloud: float = Field(default=0.0, ge=0.0, le=100.0)
    rain: float = Field(default=0.0, ge=0.0, le=100.0)
    wind: float = Field(default=0.0, ge=0.0, le=100.0)
    fog: float = Field(default=0.0, ge=0.0, le=100.0)
    wetness: float = Field(default=0.0, ge=0.0, le=100.0)
    puddle_density: float = Field(default=0.0, ge=0.0, le=100.0)
    sun_azimuth_deg: float = Field(default=0.0, ge=0.0, le=360.0, description="compass, 0 = north, clockwise")
    sun_altitude_deg: float = Field(default=90.0, ge=-90.0, le=90.0)

    @property
    def wind_speed(self) -> float:
        """[m/s] the crosswind of ``wind`` (0-100): :data:`MAX_WIND_SPEED` at 100, linear."""
        return MAX_WIND_SPEED * self.wind / 100.0


class SignalShift(_Model):
    """A traffic light's fixed-time program moved later in time by ``shift`` seconds (mutation of signal
    timing; :mod:`drivefuzz.scenario.signals`)."""

    tls: str = Field(min_length=1, description="id of a <tlLogic> of the network with a static program")
    shift: float = Field(ge=0.0, le=MAX_TIME, description="[s] added to the program's offset")


class AdsSpec(_Model):
    name: str = "ego"
    options: dict[str, OptionValue] = Field(default_factory=dict)


class SimOptions(_Model):
    step_length: float = Field(default=0.05, ge=0.001, le=1.0, description="[s] (SUMO counts in milliseconds)")
    time_limit: float = Field(default=60.0, gt=0.0, le=MAX_TIME, description="[s] simulated")


class Scenario(_Model):
    """One driving scenario: a network, a mission, and what the fuzzer put around it."""

    network: str = Field(description="path of the .net.xml (absolute, or relative to the manifest)")
    mission: Mission
    actors: tuple[Actor, ...] = ()
    puddles: tuple[Puddle, ...] = ()
    weather: Weather = Weather()
    signals: tuple[SignalShift, ...] = ()
    ads: AdsSpec = AdsSpec()
    seed: int = Field(default=0, ge=0)
    sim: SimOptions = SimOptions()
    name: str = "scenario"

    @field_validator("actors")
    @classmethod
    def _unique_ids(cls, actors: tuple[Actor, ...]) -> tuple[Actor, ...]:
        ids = [a.id for a in actors]
        if dup := _repeated(ids):
            raise ValueError(f"duplicate actor ids {dup}")
        if "ego" in ids:
            raise ValueError("actor id 'ego' is reserved for the ego vehicle")
        return actors

    @field_validator("signals")
    @classmethod
    def _one_shift_per_light(cls, signals: tuple[SignalShift, ...]) -> tuple[SignalShift, ...]:
        if dup := _repeated([s.tls for s in signals]):
            raise ValueError(f"more than one shift of traffic light(s) {dup}")
        return signals

    def network_path(self, base: str | Path | None = None) -> Path:
        p = Path(self.network)
        if not p.is_absolute() and base is not None:
            p = Path(base) / p
        return p

    def content_hash(self) -> str:
        """Stable short hash of everything that decides the execution (the network by name)."""
        data = self.model_dump(mode="json")
        data["network"] = Path(self.network).name
        data.pop("name", None)
        if not data["signals"]:  # scenarios without shifted lights keep the hashes they had before shifts existed
            del data["signals"]
        blob = json.dumps(data, sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


def _repeated(ids: list[str]) -> list[str]:
    """The ids that occur more than once, sorted."""
    return sorted({i for i in ids if ids.count(i) > 1})


def lane_edge(lane_id: str) -> str:
    """Edge id of a SUMO lane id (``edge_index``)."""
    edge, sep, index = lane_id.rpartition("_")
    return edge if sep and index.isdigit() else lane_id


def lane_index(lane_id: str) -> int:
    return int(lane_id.rpartition("_")[2])


Kind = Literal["vehicle", "pedestrian"]
