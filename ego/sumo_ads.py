"""The ``sumo`` ADS: SUMO's own car-following and lane-change models drive the ego.

A second, independent system under test. Options become vType-level
parameters of the ego (``carFollowModel`` parameters such as ``accel``,
``decel``, ``tau``, ``minGap``, ``speedFactor``), applied through libsumo.
"""

from __future__ import annotations

from drivefuzz.ads import ADS, Control, MissionInfo, Observation


class SumoADS(ADS):
    name = "sumo"
    sumo_driven = True

    class Options(ADS.Options):
        accel: float = 2.6
        decel: float = 4.5
        tau: float = 1.0
        minGap: float = 2.5
        speedFactor: float = 1.0

    def reset(self, mission: MissionInfo, roadmap) -> None:
        self.goal = mission.goal_xy

    def step(self, obs: Observation) -> Control:
        return Control()

    def vtype_settings(self) -> dict[str, float]:
        return self.options.model_dump()
