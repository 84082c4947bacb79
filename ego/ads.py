"""The reference ADS: sensing -> perception -> planning -> actuation.

Options (``--ads-option K=V``):

- ``fault``: switch on a named fault, for evaluating oracles (the paper's tbl:oracle):
  ``speeding`` (target speed above the limit), ``no_traffic_lights`` (traffic-light
  detection disabled), ``no_control`` (control module disabled: no control output),
  ``steer_left`` (steering forced left: from :data:`STEER_LEFT_DELAY` s after the first
  step the steering command is a constant :data:`STEER_LEFT_COMMAND` of full lock to the
  left, open loop, whatever the path tracker asks; on every committed seed the car
  leaves its lane within three seconds of the takeover).
- ``speed_margin``: fraction of the speed limit it aims for (default 0.95).
- ``max_lat_accel``: comfort limit in curves [m/s^2].
- ``sensor_range``: clear-weather sensor range [m].
"""

from __future__ import annotations

import math
from typing import Literal

from drivefuzz.ads import ADS, Control, MissionInfo, Observation
from drivefuzz.sim.physics import VehicleParams

from ego.actuation import PurePursuit, SpeedController
from ego.perception import HEADING, LENGTH, PED, SPEED, WIDTH, X, Y, Perception
from ego.planning import CELL, build_path, idm_accel, lawful_route, stop_accel
from ego.sensing import Sensors, SensorSpec

FAULTS = ("none", "speeding", "no_traffic_lights", "no_control", "steer_left")
#: [s] the ``steer_left`` fault drives normally this long after the first step, then takes over.
STEER_LEFT_DELAY = 1.0
#: Steering command of the ``steer_left`` fault, as a fraction of full lock (0.15 rad at the road wheels).
STEER_LEFT_COMMAND = 0.25


class ReferenceADS(ADS):
    name = "ego"

    class Options(ADS.Options):
        fault: Literal["none", "speeding", "no_traffic_lights", "no_control", "steer_left"] = "none"
        speed_margin: float = 0.95
        max_lat_accel: float = 2.5
        sensor_range: float = 100.0
        cruise_speed: float = 0.0  # [m/s] cap below the limit (0: none)

    def reset(self, mission: MissionInfo, roadmap) -> None:
        params = VehicleParams()
        self.mission = mission
        self.rmap = roadmap
        self.sensors = Sensors(SensorSpec(range_m=self.options.sensor_range), mission.seed)
        self.perception = Perception()
        # drivefuzz's route, unless it needs a lane the car cannot reach from its start lane lawfully
        self.route = lawful_route(roadmap, tuple(mission.route), mission.start_lane)
        self.path, self.edge_s = build_path(roadmap, self.route, mission.start_lane, mission.start_pos,
                                            mission.goal_edge, mission.goal_pos)
        self._curvature = self.path.curvature.tolist()  # [1/m] a slice of it is read every step
        _, self.s_goal, _ = self.path.locate(*mission.goal_xy, hint=0, window=len(self.path.pts))
        self.path_idx = 0
        self.params = params
        self._rear_off = params.centre_to_rear_axle
        self.tracker = PurePursuit(params.wheelbase, params.max_road_wheel_angle)
        self.speed = SpeedController(max_decel=params.max_brake_decel)
        self._done = False
        self.s_center = 0.0
        self._fault_t0: float | None = None  # [s] first step, for the ``steer_left`` fault

    def done(self) -> bool:
        return self._done

    def step(self, obs: Observation) -> Control:
        fault = self.options.fault
        if fault == "no_control":
            return Control(0.0, 0.0, 0.0)
        det = self.sensors.sense(obs, tl_enabled=fault != "no_traffic_lights")
        world = self.perception.update(obs, det)
        ego = obs.ego
        ch, sh = math.cos(ego.heading), math.sin(ego.heading)
        self.path_idx, s_c, lat_c = self.path.locate(ego.x, ego.y, self.path_idx)
        self.s_center = s_c
        half = ego.length / 2.0
        rear_off = self._rear_off
        rx, ry = ego.x - rear_off * ch, ego.y - rear_off * sh
        v = ego.speed

        # target speed: limit, curvature ahead
        limit = world.speed_limit
        v0 = limit * self.options.speed_margin
        if fault == "speeding":
            v0 = limit * 1.3 + 2.0
        if self.options.cruise_speed > 0:
            v0 = min(v0, self.options.cruise_speed)
        i0 = self.path_idx
        i1 = min(i0 + int(max(v * 3.0, 15.0)), len(self.path.pts) - 1)
        kmax = max(self._curvature[i0:i1 + 1]) if i1 > i0 else 0.0
        if kmax > 1e-4:
            v0 = min(v0, math.sqrt(self.options.max_lat_accel / kmax))
        accel = idm_accel(v, v0, math.inf, 0.0)

        # obstacles in the path: leaders and pedestrians (pedestrians also predicted 1.5 s ahead).
        # An object in the corridor (at most ~4 m to the side) is within a grid cell of the path,
        # and at most ~90 m (plus the car's own offset from the path) from the car.
        path = self.path
        lo, hi = path.window(self.path_idx, 120)
        reach = 90.0 + abs(lat_c)
        ex, ey = ego.x, ego.y
        for tr in world.tracks:
            ped = tr[PED]
            corridor = 1.3 + tr[WIDTH] / 2 + (0.8 if ped else 0.0)
            for horizon in (0.0, 1.5) if ped else (0.0,):
                px = tr[X] + tr[SPEED] * math.cos(tr[HEADING]) * horizon if horizon else tr[X]
                py = tr[Y] + tr[SPEED] * math.sin(tr[HEADING]) * horizon if horizon else tr[Y]
                if abs(px - ex) > reach or abs(py - ey) > reach:
                    continue
                if corridor < CELL - 1.0:
                    hit = path.locate_near(px, py, lo, hi)
                    if hit is None:
                        continue
                    s_o, lat_o = hit
                else:  # a very wide object: the corridor reaches beyond a grid cell
                    _, s_o, lat_o = path.locate(px, py, self.path_idx, window=120)
                ahead = s_o - s_c
                if ahead <= 0 or ahead > 80 or abs(lat_o) > corridor:
                    continue
                gap = ahead - half - tr[LENGTH] / 2
                dv = v - tr[SPEED] * max(math.cos(tr[HEADING] - ego.heading), 0.0)
                accel = min(accel, idm_accel(v, v0, gap, dv))

        # traffic light
        if world.tl_state is not None and world.tl_state in "rRyYu" and world.tl_distance < 120:
            dist = world.tl_distance - 1.0
            if world.tl_state in "yY" and dist < v * v / (2 * 4.0):
                pass  # too close to stop comfortably on yellow: go
            else:
                accel = min(accel, stop_accel(v, dist))

        # goal: stop with the centre on the goal point
        to_goal = self.s_goal - s_c
        accel = min(accel, stop_accel(v, to_goal, comfort=2.5))
        if to_goal < 1.5 and v < 0.5:
            self._done = True
        if self._done:
            accel = min(accel, -3.0)

        throttle, brake = self.speed.pedals(accel, v, v0)
        s_rear = s_c - rear_off
        steer = self.tracker.steer(self.path, s_rear, rx, ry, ego.heading, v)
        if fault == "steer_left":
            # open loop: a bias on the tracker's command would be corrected by the tracker itself
            if self._fault_t0 is None:
                self._fault_t0 = obs.t
            if obs.t - self._fault_t0 >= STEER_LEFT_DELAY:
                steer = STEER_LEFT_COMMAND
        return Control(steer, throttle, brake)
