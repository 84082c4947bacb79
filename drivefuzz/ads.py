"""The interface between drivefuzz and an automated-driving system (ADS) plugin.

An ADS is a class registered in the entry-point group ``drivefuzz.ads``. The
executor calls :meth:`ADS.reset` once with the mission and the road map, then
:meth:`ADS.step` once per simulation step with an :class:`Observation`, and
moves drivefuzz's car with the returned :class:`Control`. The ADS never touches
SUMO: what it knows of the world is the observation (ground truth within the
sensor horizon, plus the weather; its own sensing layer decides what it can
really see).

Observation and Control are plain frozen dataclasses, not pydantic models: they
are built and read every step, on the hot path.
"""

from __future__ import annotations

import abc
import importlib
import inspect
import os
import sys
from dataclasses import dataclass, field
from drivefuzz.entrypoints import entry_points
from typing import Any, ClassVar, Mapping, NamedTuple

from pydantic import BaseModel, ConfigDict, ValidationError

from drivefuzz.errors import ADS_PLUGIN, InvalidConfig, PluginError

ADS_GROUP = "drivefuzz.ads"

#: Radius [m] of the ground truth handed to the ADS each step; the ADS's sensors see less.
OBSERVATION_RADIUS = 150.0


@dataclass(frozen=True, slots=True)
class EgoState:
    """The ego car as its own odometry and localisation report it. SI units, ENU radians."""

    x: float  # [m] geometric centre
    y: float
    heading: float  # [rad]
    speed: float  # [m/s]
    vx: float  # [m/s] body frame
    vy: float
    yaw_rate: float  # [rad/s]
    ax: float  # [m/s^2]
    road_wheel_angle: float  # [rad]
    length: float  # [m]
    width: float  # [m]
    wheelbase: float  # [m]


class ObjectState(NamedTuple):
    """One other road user (ground truth). A NamedTuple: immutable, and three times cheaper to build than a
    frozen dataclass, which matters at 20 objects x 1200 steps per execution."""

    id: str
    kind: str  # "vehicle" | "pedestrian"
    x: float  # [m] geometric centre
    y: float
    heading: float  # [rad] ENU
    speed: float  # [m/s]
    length: float  # [m]
    width: float  # [m]


@dataclass(frozen=True, slots=True)
class TrafficLightState:
    """The next traffic light along the ego's route."""

    tls_id: str
    link_index: int
    distance: float  # [m] from the front bumper to the stop line
    state: str  # SUMO's signal character: r y G g s u o O


@dataclass(frozen=True, slots=True)
class Observation:
    t: float  # [s]
    ego: EgoState
    lane: str  # SUMO lane id under the ego ("" off-road)
    lane_pos: float  # [m] of the front bumper along ``lane``
    speed_limit: float  # [m/s] of ``lane`` (nan off-road)
    objects: tuple[ObjectState, ...]
    traffic_light: TrafficLightState | None
    weather: Any  # drivefuzz.scenario.Weather
    sun_glare: bool = False  # the sun is low and ahead (camera blinded)


@dataclass(frozen=True, slots=True)
class Control:
    """Commands for the car: steering left-positive as a fraction of full lock; pedals in [0, 1]."""

    steer: float = 0.0
    throttle: float = 0.0
    brake: float = 0.0


@dataclass(frozen=True)
class MissionInfo:
    """What the ADS is told at reset."""

    start_lane: str
    start_pos: float  # [m]
    goal_edge: str
    goal_pos: float  # [m]
    goal_xy: tuple[float, float]  # [m]
    route: tuple[str, ...]  # normal edges, as planned by drivefuzz (the ADS may plan its own)
    step_length: float  # [s]
    seed: int
    extras: Mapping[str, Any] = field(default_factory=dict)


class ADS(abc.ABC):
    """Base class of ADS plugins.

    Subclasses declare their options as a pydantic model in ``Options``; the
    scenario's ``ads.options`` (and ``--ads-option K=V``) are validated against it.
    """

    name: ClassVar[str] = ""

    class Options(BaseModel):
        model_config = ConfigDict(extra="forbid")

    def __init__(self, options: Mapping[str, Any] | None = None):
        try:
            self.options = self.Options.model_validate(dict(options or {}))
        except ValidationError as exc:
            err = exc.errors()[0]
            loc = ".".join(str(p) for p in err["loc"])
            fields = ", ".join(self.Options.model_fields) or "none"
            raise InvalidConfig("--ads-option", f"{self.name or type(self).__name__}.{loc}", err["msg"],
                                f"options: {fields}") from None

    @abc.abstractmethod
    def reset(self, mission: MissionInfo, roadmap) -> None:
        """Called once before the first step. ``roadmap`` is a :class:`drivefuzz.scenario.roadmap.RoadMap`."""

    @abc.abstractmethod
    def step(self, obs: Observation) -> Control:
        """Return the control for the next step."""

    def done(self) -> bool:
        """True once the ADS believes its mission is complete (used by the mission oracle)."""
        return False

    def trace_info(self) -> Mapping[str, Any] | None:
        """What the ADS wants kept with the trace (``meta.json``, key ``ads_info``; JSON-able): its
        decisions, for a person reading a finding. Called once, after the last step; None: nothing."""
        return None

    # An ADS that lets SUMO drive the ego (like the ``sumo`` plugin) overrides this to True;
    # the executor then does not move the car and reads its state from SUMO instead.
    sumo_driven: ClassVar[bool] = False

    def vtype_settings(self) -> dict[str, float]:
        """When ``sumo_driven``: vehicle settings (``accel``, ``tau``...) applied with libsumo's setters."""
        return {}


def available_ads() -> dict[str, Any]:
    return {ep.name: ep for ep in entry_points(group=ADS_GROUP)}


def check_trusted(name: str, source: str, field: str, command_line: str | None = None) -> None:
    """Refuse an ADS that a data file names unless it is installed or the command line names it too.

    A scenario.json, a finding's verdict or a campaign's manifest may come from
    anyone; ``package.module:Class`` from such a file would import (run) code that
    lies beside it. Installed plugins (entry points of ``drivefuzz.ads``) were
    installed on purpose, and ``--ads NAME`` is the user's own word.
    """
    eps = available_ads()
    if name in eps or (command_line is not None and name == command_line):
        return
    raise InvalidConfig(source, field, f"names ADS {name!r}, which is not an installed plugin; drivefuzz does "
                        "not import code named by a data file",
                        f"an installed ADS ({', '.join(sorted(eps)) or 'none'}), or --ads {name} to trust it")


#: folders whose modules the user named with ``--ads module:Class`` on the command line (the current folder);
#: the environment carries them to Dask workers and simulation hosts, which run with ``python -I``
ADS_PATH_ENV = "DRIVEFUZZ_ADS_PATH"


def allow_current_folder(name: str) -> None:
    """``--ads mymodule:Class`` on the command line finds ``mymodule.py`` (or ``mymodule/``) in the current
    folder: the user's own word, as for any ADS named there. Only that folder is added, and only for such a
    module; it goes last on the import path, so a ``shapely.py`` lying beside it shadows nothing."""
    module = name.partition(":")[0].split(".")[0]
    if ":" not in name or name in available_ads() or not module.isidentifier():
        return
    cwd = os.getcwd()
    if not (os.path.isfile(os.path.join(cwd, module + ".py")) or os.path.isdir(os.path.join(cwd, module))):
        return
    paths = _user_paths()
    if cwd not in paths:
        os.environ[ADS_PATH_ENV] = os.pathsep.join(paths + [cwd])


def _user_paths() -> list[str]:
    return [p for p in os.environ.get(ADS_PATH_ENV, "").split(os.pathsep) if p]


def load_ads(name: str, options: Mapping[str, Any] | None = None, source: str = "--ads") -> ADS:
    """The ADS plugin registered as ``name``, or the class at ``name`` = ``package.module:Class``.

    The second form runs an ADS under development without packaging it; the module
    must be importable (installed, on PYTHONPATH, or in the folder :func:`allow_current_folder`
    was given on the command line). Callers that read ``name`` from
    a file check it with :func:`check_trusted` first.
    """
    eps = available_ads()
    if name not in eps and ":" not in name:
        raise InvalidConfig(source, None, f"no ADS plugin named {name!r}",
                            (", ".join(sorted(eps)) or "none installed") + ", or package.module:Class")
    if name in eps:
        try:
            cls = eps[name].load()
        except Exception as exc:  # a broken plugin must not take the tool down with a traceback
            raise PluginError(f"ADS plugin {name!r} ({eps[name].value}) failed to load: "
                              f"{type(exc).__name__}: {exc}", ADS_PLUGIN) from exc
    else:
        cls = _import_class(name, source)
    problem = None
    if not (isinstance(cls, type) and issubclass(cls, ADS)):
        problem = "is not a drivefuzz.ads.ADS subclass"
    elif inspect.isabstract(cls):
        problem = f"is an abstract class (implements none of {', '.join(sorted(cls.__abstractmethods__))})"
    if problem and name in eps:  # an installed plugin that is broken: not the user's mistake
        raise PluginError(f"ADS plugin {name!r} ({eps[name].value}) {problem}", ADS_PLUGIN)
    if problem:
        raise InvalidConfig(source, name, problem, "a subclass of drivefuzz.ads.ADS that implements reset and step")
    try:
        return cls(options)
    except InvalidConfig:
        raise
    except Exception as exc:
        raise PluginError(f"ADS plugin {name!r} failed to start: {type(exc).__name__}: {exc}", ADS_PLUGIN) from exc


def _import_class(name: str, source: str) -> Any:
    """The object at ``package.module:Class``; a module or class that is not there is the user's mistake."""
    module, _, attr = name.partition(":")
    valid = ("an installed ADS, or package.module:Class with the module in the current folder, installed, "
             "or on PYTHONPATH")
    if not module or not attr.isidentifier():
        raise InvalidConfig(source, name, "not of the form package.module:Class", valid)
    sys.path.extend(p for p in _user_paths() if p not in sys.path)
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name is not None and module.split(".")[0] == exc.name.split(".")[0]:
            raise InvalidConfig(source, name, f"no module named {exc.name!r}", valid) from None
        raise PluginError(f"ADS plugin {name!r} failed to load: {type(exc).__name__}: {exc}", ADS_PLUGIN) from exc
    except Exception as exc:  # a broken plugin must not take the tool down with a traceback
        raise PluginError(f"ADS plugin {name!r} failed to load: {type(exc).__name__}: {exc}", ADS_PLUGIN) from exc
    if not hasattr(mod, attr):
        raise InvalidConfig(source, name, f"module {module!r} has no attribute {attr!r}", valid)
    return getattr(mod, attr)
