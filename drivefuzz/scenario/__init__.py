"""The ground of the pipeline: what a scenario is, and how it becomes the files SUMO reads.

- :mod:`~drivefuzz.scenario.model`: the :class:`Scenario` value (pydantic) and its parts;
- :mod:`~drivefuzz.scenario.sumofiles`: Scenario <-> route, additional and manifest files (lossless);
- :mod:`~drivefuzz.scenario.validate`: the checks a scenario must pass on its network;
- :mod:`~drivefuzz.scenario.roadmap`: the network as drivefuzz reads it (lanes, routes, junctions);
- :mod:`~drivefuzz.scenario.seed`: random missions on a network.

Nothing here imports libsumo. The model's names are re-exported, so ``from drivefuzz.scenario import Scenario``.
"""

from drivefuzz.scenario.model import (  # noqa: F401  (re-exported)
    SCHEMA_VERSION,
    Actor,
    ActorKind,
    AdsSpec,
    Maneuver,
    ManeuverAction,
    Mission,
    NavType,
    Puddle,
    Scenario,
    SignalShift,
    SimOptions,
    Trigger,
    Weather,
    lane_edge,
    lane_index,
)
