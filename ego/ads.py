"""The reference ADS: sensing -> perception -> planning -> actuation.

Options (``--ads-option K=V``):

- ``fault``: switch on a named fault, for evaluating oracles (the paper's tbl:oracle):
  ``speeding`` (target speed above the limit), ``no_traffic_lights`` (traffic-light
  detection disabled), ``no_control`` (control module disabled: no control output),
  ``steer_left`` (steering forced left: from :data:`STEER_LEFT_DELAY` s after the first
  step the steering command is a constant :data:`STEER_LEFT_COMMAND` of full lock to the
  left, open loop, whatever the path tracker asks; on every committed seed the car
  leaves its lane within three seconds of the takeover).
  Hidden faults, silent on every committed seed (no actors, clear weather), for measuring how fast a search
  reveals a bug that only a situation it builds can show: ``ignore_pedestrians`` (pedestrians are never
  obstacles), ``late_braking`` (obstacles count only within :data:`LATE_BRAKING_M` m), ``no_fog_slowdown``
  (no assured-clear-distance cap: it keeps its clear-weather speed in fog), and three that bite in other
  encounters (issue 31, for ``tools/eval_attribution.py``): ``no_walker_prediction`` (a walker counts only
  where it is, never where it walks to, and only once in the car's own corridor: it drives into walkers'
  paths), ``short_headway`` (it follows vehicles at a :data:`SHORT_HEADWAY_S` s time gap and
  :data:`SHORT_HEADWAY_GAP` m at a standstill, blind to how fast it closes in: a leader that brakes hard is
  struck), ``narrow_corridor`` (a vehicle counts only with its centre within :data:`NARROW_CORRIDOR_M` m plus
  half its width of the path: a car cutting or nosing in is seen late).
  Three that bite in one kind of encounter each (issue 33, for ``tools/eval_coverage.py --faults``):
  ``right_walker_blind`` (a walker right of the car that walks leftwards, across its path from the right, is
  not an obstacle until it has crossed the car's centre line), ``crossing_left_blind`` (a moving vehicle heading
  45-135 degrees to the car's right, crossing its path from the left, is not an obstacle) and
  ``low_sun_blind`` (with the sun low ahead, the camera is dazzled: obstacles farther than
  :data:`GLARE_BLIND_M` m along the path are not seen). Two more were tried and dropped, no situation the
  fuzzer built made them collide where the clean ADS did not: ``left_turn_oncoming`` (blind to oncoming
  vehicles in a left turn: the oncoming SUMO drivers yield) and ``crossing_right_blind`` (the mirror of
  ``crossing_left_blind``: the only unsignalised junction with traffic from the right, town's B0, makes
  the clean ADS collide too).
- ``speed_margin``: fraction of the speed limit it aims for (default 0.95).
- ``max_lat_accel``: comfort limit in curves [m/s^2].
- ``sensor_range``: clear-weather sensor range [m].

Target speed. The lowest of: the speed limit (times ``speed_margin``); the curvature profile
(:func:`ego.planning.speed_profile`: the curve limit ``sqrt(LAT_ACCEL_SHARE * max_lat_accel / k)``
with a :data:`CURVE_DECEL` braking ramp before every bend, fixed along the path, so it does not
chatter); and the assured clear distance ahead: the speed from which the car stops, after
:data:`ACDA_REACTION` s, at :data:`ACDA_DECEL` (less on a wet road) within the range its
sensors have in the current weather, less :data:`ACDA_MARGIN` and half its length. In clear
weather that is about 32 m/s (100 m of range), in dense fog about 9 m/s (15 m).

Braking. Reaching that target speed never brakes harder than :data:`FREE_DECEL`: the speed limit
and the bends are known in advance and are no hazard. Leaders, pedestrians, a red light and the
goal keep their own terms, which may brake fully.
"""

from __future__ import annotations

import math
from typing import Literal

from drivefuzz.ads import ADS, Control, MissionInfo, Observation
from drivefuzz.sim.physics import VehicleParams

from ego.actuation import PurePursuit, SpeedController
from ego.perception import HEADING, LENGTH, PED, SPEED, WIDTH, X, Y, Perception
from ego.planning import (CELL, assured_clear_speed, build_path, idm_accel, lawful_route, profile_accel,
                          speed_profile, stop_accel)
from ego.sensing import Sensors, SensorSpec

FAULTS = ("none", "speeding", "no_traffic_lights", "no_control", "steer_left", "ignore_pedestrians", "late_braking",
          "no_fog_slowdown", "no_walker_prediction", "short_headway", "narrow_corridor", "right_walker_blind",
          "crossing_left_blind", "low_sun_blind")
#: [m] the ``low_sun_blind`` fault sees obstacles only this far ahead (along the path) under sun glare
GLARE_BLIND_M = 8.0
#: the encounter each single-encounter fault drops (``_unseen``; "far": beyond GLARE_BLIND_M under glare)
_BLIND = {"right_walker_blind": "right_walker", "crossing_left_blind": "crossing_left", "low_sun_blind": "far"}
#: [m] the ``late_braking`` fault sees obstacles only this close (front bumper to their centre, along the path).
LATE_BRAKING_M = 4.0
#: [s], [m] the ``short_headway`` fault's time gap and standstill gap to vehicles (the IDM's T and s0).
SHORT_HEADWAY_S, SHORT_HEADWAY_GAP = 0.3, 0.5
#: [m] the ``narrow_corridor`` fault's corridor for vehicles beyond half their width (the clean ADS: 1.3 m).
NARROW_CORRIDOR_M = 0.2
#: [s] the ``steer_left`` fault drives normally this long after the first step, then takes over.
STEER_LEFT_DELAY = 1.0
#: Steering command of the ``steer_left`` fault, as a fraction of full lock (0.15 rad at the road wheels).
STEER_LEFT_COMMAND = 0.25
#: [m/s^2] deceleration of the braking ramp before a bend in the curvature profile.
CURVE_DECEL = 1.5
#: The curvature profile plans for this share of ``max_lat_accel``: the path's curvature is a 5 m
#: average and the tracker turns in a little harder, so planning at the full limit overshot it
#: (2.64 m/s^2 against 2.5 at the intersection seed 003's left turn).
LAT_ACCEL_SHARE = 0.9
#: [m] a bend's limit holds from this far before it: the path tracker's shortest look-ahead (4 m from
#: the rear axle), where the car starts to turn.
CURVE_LEAD = 4.0
#: [s] the car follows the curvature profile this far ahead of it (at least :data:`PROFILE_MIN_M`).
PROFILE_LEAD_S = 1.0
#: [m] shortest look-ahead on the curvature profile.
PROFILE_MIN_M = 4.0
#: [m/s^2] the hardest braking used to reach the target speed (limit, bends, visibility).
FREE_DECEL = 3.0
#: [m/s^2] assured clear distance: the deceleration it counts on to stop on a dry road ...
ACDA_DECEL = 6.0
#: ... after this reaction [s] ...
ACDA_REACTION = 0.3
#: ... short of the sensor range by this [m] (plus half its own length): half a car and a gap.
ACDA_MARGIN = 3.5


class ReferenceADS(ADS):
    name = "ego"

    class Options(ADS.Options):
        fault: Literal["none", "speeding", "no_traffic_lights", "no_control", "steer_left", "ignore_pedestrians",
                       "late_braking", "no_fog_slowdown", "no_walker_prediction", "short_headway",
                       "narrow_corridor", "right_walker_blind", "crossing_left_blind",
                       "low_sun_blind"] = "none"
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
        self._profile = speed_profile(self.path, LAT_ACCEL_SHARE * self.options.max_lat_accel, CURVE_DECEL,
                                      CURVE_LEAD)  # [m/s] per point
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
        rear_off = self._rear_off
        rx, ry = ego.x - rear_off * ch, ego.y - rear_off * sh
        v = ego.speed

        v0 = self._target_speed(obs, world.speed_limit, det.range_m)
        accel = max(idm_accel(v, v0, math.inf, 0.0), -FREE_DECEL)
        accel = min(accel, max(profile_accel(self._profile, self.path, self.path_idx, v,
                                             max(v * PROFILE_LEAD_S, PROFILE_MIN_M)), -FREE_DECEL))
        accel = min(accel, self._obstacle_accel(world, ego, s_c, lat_c, v0, obs.sun_glare))
        accel = min(accel, self._light_accel(world, v))

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

    def _target_speed(self, obs: Observation, limit: float, range_m: float) -> float:
        """[m/s] the speed it aims for here: the limit, the curvature profile, the assured clear
        distance ahead in the sensor range ``range_m`` [m] it has now, and the ``cruise_speed`` cap."""
        v0 = limit * self.options.speed_margin
        if self.options.fault == "speeding":
            v0 = limit * 1.3 + 2.0
        if self.options.cruise_speed > 0:
            v0 = min(v0, self.options.cruise_speed)
        v0 = min(v0, self._profile[self.path_idx])
        w = obs.weather
        # a wet road grips less (the driver sees it): count on less braking
        decel = ACDA_DECEL * (1.0 - 0.3 * max(w.wetness, w.rain) / 100.0)
        clear = range_m - ACDA_MARGIN - obs.ego.length / 2.0
        if self.options.fault == "no_fog_slowdown":
            return v0
        return min(v0, max(assured_clear_speed(clear, decel, ACDA_REACTION), 1.0))

    def _obstacle_accel(self, world, ego, s_c: float, lat_c: float, v0: float, glare: bool = False) -> float:
        """Acceleration [m/s^2] the obstacles in the path allow (+inf: none): leaders and
        pedestrians (pedestrians also predicted 1.5 s ahead). An object in the corridor (at most
        ~4 m to the side) is within a grid cell of the path, and at most ~90 m (plus the car's own
        offset from the path) from the car."""
        v = ego.speed
        half = ego.length / 2.0
        # the free-road part of the IDM is handled (and its braking bounded) by the caller
        v_free = max(v0, v)
        accel = math.inf
        path = self.path
        lo, hi = path.window(self.path_idx, 120)
        reach = 90.0 + abs(lat_c)
        ex, ey = ego.x, ego.y
        fault = self.options.fault
        # the faults of issue 31, settled once per step, not per object
        ped_horizons, ped_side = ((0.0,), 0.0) if fault == "no_walker_prediction" else ((0.0, 1.5), 0.8)
        veh_side = NARROW_CORRIDOR_M - 1.3 if fault == "narrow_corridor" else 0.0
        headway = fault == "short_headway"
        blind = _BLIND.get(fault)
        if blind == "far" and not glare:  # the low_sun_blind fault: only under glare
            blind = None
        ch, sh = (math.cos(ego.heading), math.sin(ego.heading)) if blind else (1.0, 0.0)
        for tr in world.tracks:
            ped = tr[PED]
            if ped and fault == "ignore_pedestrians":
                continue
            if blind and blind != "far" and _unseen(blind, tr, ex, ey, ch, sh, ego.heading):
                continue
            corridor = 1.3 + tr[WIDTH] / 2 + (ped_side if ped else veh_side)
            for horizon in ped_horizons if ped else (0.0,):
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
                if fault == "late_braking" and ahead - half > LATE_BRAKING_M:
                    continue
                if blind == "far" and ahead - half > GLARE_BLIND_M:
                    continue
                gap = ahead - half - tr[LENGTH] / 2
                dv = v - tr[SPEED] * max(math.cos(tr[HEADING] - ego.heading), 0.0)
                if headway and not ped:  # and blind to the closing speed: it reads the leader's speed as its own
                    accel = min(accel, idm_accel(v, v_free, gap, 0.0, s0=SHORT_HEADWAY_GAP, T=SHORT_HEADWAY_S))
                else:
                    accel = min(accel, idm_accel(v, v_free, gap, dv))
        return accel

    def _light_accel(self, world, v: float) -> float:
        """Acceleration [m/s^2] the next traffic light allows (+inf: none): stop for red, and for
        yellow unless too close to stop comfortably."""
        if world.tl_state is None or world.tl_state not in "rRyYu" or world.tl_distance >= 120:
            return math.inf
        dist = world.tl_distance - 1.0
        if world.tl_state in "yY" and dist < v * v / (2 * 4.0):
            return math.inf  # too close to stop comfortably on yellow: go
        return stop_accel(v, dist)



def _unseen(blind: str, tr, ex: float, ey: float, ch: float, sh: float, heading: float) -> bool:
    """Whether track ``tr`` falls in the ``blind`` encounter (ego at (ex, ey), heading cos/sin ``ch``/``sh``)."""
    ped = tr[PED]
    if blind == "right_walker":
        if not ped:
            return False
        lat = -(tr[X] - ex) * sh + (tr[Y] - ey) * ch  # [m] left of the car
        v_lat = tr[SPEED] * math.sin(tr[HEADING] - heading)  # [m/s] leftwards
        return lat < 0.0 and v_lat > 0.2
    if ped or tr[SPEED] < 0.5:
        return False
    dh = math.remainder(tr[HEADING] - heading, math.tau)
    return -3 * math.pi / 4 < dh < -math.pi / 4  # crossing_left: it heads to the car's right
