"""A minimal drivefuzz ADS: keeps its lane at a constant speed and stops at the goal.

It steers by pure pursuit towards a point ``lookahead`` metres ahead on the lane it is on
(so it goes straight on through junctions: it follows no route) and holds ``speed`` with a
proportional pedal controller, braking to stop with its centre on the goal point.
"""

from __future__ import annotations

import math

from pydantic import Field

from drivefuzz.ads import ADS, Control, MissionInfo, Observation
from drivefuzz.sim.physics import VehicleParams

MAX_WHEEL_ANGLE = VehicleParams().max_road_wheel_angle  # [rad] the car's full lock


class MinimalADS(ADS):
    name = "minimal"

    class Options(ADS.Options):
        speed: float = Field(8.0, gt=0.0, description="[m/s] cruise speed")
        lookahead: float = Field(6.0, gt=0.0, description="[m] pure-pursuit look-ahead")

    def reset(self, mission: MissionInfo, roadmap) -> None:
        self.mission, self.roadmap, self._done = mission, roadmap, False

    def step(self, obs: Observation) -> Control:
        ego, opt = obs.ego, self.options
        steer = 0.0
        if obs.lane:  # on a lane: aim at a point ahead on it
            tx, ty, _ = self.roadmap.geom(obs.lane).position(obs.lane_pos + opt.lookahead)
            alpha = math.atan2(ty - ego.y, tx - ego.x) - ego.heading
            steer = math.atan2(2.0 * ego.wheelbase * math.sin(alpha), opt.lookahead) / MAX_WHEEL_ANGLE
        gx, gy = self.mission.goal_xy
        to_goal = math.hypot(gx - ego.x, gy - ego.y)
        target = min(opt.speed, math.sqrt(2.0 * 2.0 * max(to_goal - 0.5, 0.0)))  # 2 m/s^2 to stop there
        self._done = self._done or (to_goal < 2.0 and ego.speed < 0.5)
        error = 0.0 - ego.speed if self._done else target - ego.speed
        return Control(steer=max(-1.0, min(1.0, steer)), throttle=max(0.0, min(1.0, 0.5 * error)),
                       brake=max(0.0, min(1.0, -0.5 * error)))

    def done(self) -> bool:
        return self._done
