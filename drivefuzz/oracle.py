"""Misbehaviour oracles: the plugin interface and the records they produce.

An oracle is a class in the entry-point group ``drivefuzz.oracles``. For every
execution the executor creates a fresh instance, calls :meth:`Oracle.reset`
with a :class:`RunContext`, :meth:`Oracle.on_frame` after every simulation
step with the live :class:`Frame`, and :meth:`Oracle.on_end` with the frozen
trace. Any :class:`Misbehavior` returned from ``on_frame`` stops the run (unless
the executor was told to go on).

Settings are a pydantic model in ``Config``; users set them with
``--oracle NAME.KEY=VALUE`` or a config file, and switch an oracle off with
``--no-oracle NAME``.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from enum import Enum
from drivefuzz.entrypoints import entry_points
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError

from drivefuzz.errors import ORACLE_PLUGIN, InvalidConfig, PluginError

ORACLE_GROUP = "drivefuzz.oracles"


class Termination(str, Enum):
    """Why an execution stopped."""

    GOAL_REACHED = "goal_reached"
    TIME_LIMIT = "time_limit"
    MISBEHAVIOR = "misbehavior"
    EGO_LOST = "ego_lost"  # SUMO removed the ego (should not happen; reported, not hidden)


@dataclass(frozen=True)
class Misbehavior:
    oracle: str
    kind: str
    frame: int
    time: float  # [s]
    position: tuple[float, float]  # [m] ego centre
    actors: tuple[str, ...] = ()
    details: Mapping[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {"oracle": self.oracle, "kind": self.kind, "frame": self.frame, "time": self.time,
                "position": list(self.position), "actors": list(self.actors), "details": dict(self.details)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Misbehavior":
        return cls(oracle=d["oracle"], kind=d["kind"], frame=int(d["frame"]), time=float(d["time"]),
                   position=tuple(d["position"]), actors=tuple(d.get("actors", ())), details=d.get("details", {}))

    def signature(self) -> tuple:
        """What makes two findings 'the same' misbehaviour: oracle, kind, actors, place (10 m grid)."""
        return (self.oracle, self.kind, tuple(sorted(self.actors)),
                (round(self.position[0] / 10.0), round(self.position[1] / 10.0)))


@dataclass(frozen=True)
class LaneLink:
    """One signalised connection leaving the ego's current lane."""

    tls_id: str
    link_index: int
    to_lane: str
    via: str
    state: str


@dataclass(frozen=True)
class Obstacle:
    """A static solid obstacle (SUMO polygon or POI of an obstacle type)."""

    id: str
    polygon: Any  # shapely Polygon


@dataclass
class RunContext:
    """Fixed facts about one execution, given to oracles at reset."""

    scenario: Any  # drivefuzz.scenario.Scenario
    roadmap: Any  # drivefuzz.scenario.roadmap.RoadMap
    route: tuple[str, ...]
    goal_xy: tuple[float, float]
    ego_length: float
    ego_width: float
    step_length: float
    obstacles: Sequence[Obstacle] = ()


@dataclass
class Frame:
    """The world after one step. The executor reuses one object: copy what you keep."""

    index: int = 0
    t: float = 0.0
    # ego (geometric centre, ENU)
    x: float = 0.0
    y: float = 0.0
    heading: float = 0.0
    speed: float = 0.0
    front: tuple[float, float] = (0.0, 0.0)  # [m] front-bumper centre
    prev_front: tuple[float, float] = (0.0, 0.0)
    corners: np.ndarray | None = None  # (4, 2) [m] ego footprint, order of drivefuzz.geometry.corners
    edge: str = ""
    lane: str = ""  # "" off-road
    lane_pos: float = float("nan")  # [m] of the front bumper
    lat_offset: float = float("nan")  # [m] of the centre from the lane centre, left positive
    speed_limit: float = float("nan")  # [m/s]
    route_index: int = 0  # index of ``edge`` in the current route
    goal_dist: float = float("nan")  # [m]
    lane_links: tuple[LaneLink, ...] = ()
    next_tls: tuple[str, int, float, str] | None = None  # (tls, link, distance [m], state)
    ads_done: bool = False
    # other actors: arrays aligned by row
    actor_ids: Sequence[str] = ()
    actor_kinds: Sequence[str] = ()
    actor_x: np.ndarray = field(default_factory=lambda: np.empty(0))
    actor_y: np.ndarray = field(default_factory=lambda: np.empty(0))
    actor_heading: np.ndarray = field(default_factory=lambda: np.empty(0))
    actor_speed: np.ndarray = field(default_factory=lambda: np.empty(0))
    actor_length: np.ndarray = field(default_factory=lambda: np.empty(0))
    actor_width: np.ndarray = field(default_factory=lambda: np.empty(0))
    sumo_collisions: tuple[tuple[str, str, str], ...] = ()  # (collider, victim, type) from SUMO


class Oracle(abc.ABC):
    name: ClassVar[str] = ""
    description: ClassVar[str] = ""

    class Config(BaseModel):
        model_config = ConfigDict(extra="forbid")
        enabled: bool = True

    def __init__(self, config: Mapping[str, Any] | "Oracle.Config" | None = None):
        if isinstance(config, BaseModel):
            self.config = config
        else:
            self.config = make_config(type(self), config or {})

    def reset(self, ctx: RunContext) -> None:
        self.ctx = ctx

    def on_frame(self, frame: Frame) -> Sequence[Misbehavior]:
        return ()

    def on_end(self, trace, termination: Termination) -> Sequence[Misbehavior]:
        return ()

    def report(self, frame: Frame, kind: str, actors: Sequence[str] = (), **details: Any) -> Misbehavior:
        return Misbehavior(self.name, kind, frame.index, round(frame.t, 6), (round(frame.x, 3), round(frame.y, 3)),
                           tuple(actors), details)


def make_config(cls: type[Oracle], values: Mapping[str, Any], source: str = "--oracle") -> BaseModel:
    keys = ", ".join(cls.Config.model_fields)
    if not isinstance(values, Mapping):
        raise InvalidConfig(source, cls.name, f"settings must be a table of KEY = VALUE, not {values!r}",
                            f"settings: {keys}")
    for key, value in values.items():
        if isinstance(value, float) and value != value:
            raise InvalidConfig(source, f"{cls.name}.{key}", "nan is not a setting", "a number")
    try:
        return cls.Config.model_validate(dict(values))
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        raise InvalidConfig(source, f"{cls.name}.{loc}", err["msg"], f"settings: {keys}") from None


def available_oracles() -> dict[str, type[Oracle]]:
    """Every installed oracle class by name. A plugin that fails to import raises PluginError."""
    out: dict[str, type[Oracle]] = {}
    for ep in sorted(entry_points(group=ORACLE_GROUP), key=lambda e: e.name):
        try:
            cls = ep.load()
        except Exception as exc:
            raise PluginError(f"oracle plugin {ep.name!r} ({ep.value}) failed to load: {type(exc).__name__}: {exc}",
                              ORACLE_PLUGIN) from exc
        if not (isinstance(cls, type) and issubclass(cls, Oracle)):
            raise PluginError(f"oracle plugin {ep.name!r} is not a drivefuzz.oracle.Oracle subclass", ORACLE_PLUGIN)
        out[ep.name] = cls
    return out


class OracleSettings(BaseModel):
    """Per-oracle settings by name: ``{"speeding": {"tolerance": 1.0}, "red_light": {"enabled": False}}``."""

    model_config = ConfigDict(extra="forbid")
    settings: dict[str, dict[str, Any]] = {}

    def instantiate(self, source: str = "--oracle") -> list[Oracle]:
        """One configured instance of every enabled oracle; ``source`` names where bad settings came from."""
        classes = available_oracles()
        unknown = set(self.settings) - set(classes)
        if unknown:
            raise InvalidConfig(source, None, f"unknown oracle(s) {sorted(unknown)}", ", ".join(classes))
        out = []
        for name, cls in classes.items():
            cfg = make_config(cls, self.settings.get(name, {}), source)
            if cfg.enabled:
                try:
                    out.append(cls(cfg))
                except Exception as exc:  # a plugin's bug, not the ADS's: the oracle is named and blamed
                    raise PluginError(f"oracle plugin {name!r} failed to start: {type(exc).__name__}: {exc}",
                                      ORACLE_PLUGIN) from exc
        return out


def parse_oracle_options(pairs: Sequence[str], disabled: Sequence[str] = (),
                         base: Mapping[str, Mapping[str, Any]] | None = None) -> OracleSettings:
    """``NAME.KEY=VALUE`` strings and ``--no-oracle`` names into settings (values parsed as JSON when they can be)."""
    import json

    settings: dict[str, dict[str, Any]] = {k: dict(v) for k, v in (base or {}).items()}
    for pair in pairs:
        key, sep, raw = pair.partition("=")
        name, dot, field_ = key.partition(".")
        if not sep or not dot or not name or not field_:
            raise InvalidConfig("--oracle", pair, "expected NAME.KEY=VALUE", "e.g. speeding.tolerance=1.5")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        settings.setdefault(name, {})[field_] = value
    for name in disabled:
        settings.setdefault(name, {})["enabled"] = False
    return OracleSettings(settings=settings)
