"""The careful reference driver: the yardstick of the counterfactual in attribution.

:mod:`drivefuzz.triage.attribute` replays a misbehaviour's scenario with this ADS (plugin name
``careful``); if it fails the same way, a careful human-like driver could not have avoided the
situation either, and the finding is not the ego's fault.

It is the reference ADS (same sensing, perception, path and actuation) with four habits on top,
applied through public hooks only (the observation it passes on, its options, the tracks its
perception keeps and the control the reference chose), so it follows the reference as that changes:

- it brakes at once, fully, for any hazard within its stopping distance (plus a margin), a
  hazard being a tracked body in its path corridor now or, for pedestrians and moving vehicles,
  predicted there within :data:`HORIZON` s by the time the car would get there;
- it keeps a larger headway (:attr:`Options.headway`, default 2 s) to vehicles in its path;
- where fog or rain shorten its sensor range, it drives no faster than it can stop from comfortably
  within 60 % of what it sees; it aims at a lower fraction of the speed limit;
- a low sun ahead does not blind it to the traffic lights: a driver shades the eyes and reads the light,
  where the reference's camera sees none and holds the last state it saw (a red can then hold it for
  good at a green light).

Units: SI, radians ENU.
"""

from __future__ import annotations

import math
from dataclasses import replace

from drivefuzz.ads import Control, Observation

from ego.ads import ReferenceADS
from ego.perception import HEADING, LENGTH, PED, SPEED, WIDTH, X, Y
from ego.planning import idm_accel

#: [s] how far ahead pedestrians and moving vehicles are predicted.
HORIZON = 3.0
#: [s] prediction steps.
STEPS = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
#: [s] its own reaction before full braking acts.
REACTION = 0.2
#: [m/s^2] the deceleration it counts on for its stopping distance (below full braking: wet roads).
PLANNING_DECEL = 6.0
#: [m/s^2] in fog or rain it drives no faster than it can stop from at this deceleration ...
VISIBILITY_DECEL = 3.0
#: ... within this share of its (shortened) sensor range.
SIGHT_SHARE = 0.6


class CarefulADS(ReferenceADS):
    name = "careful"

    class Options(ReferenceADS.Options):
        speed_margin: float = 0.9
        headway: float = 2.0  # [s] time gap it keeps to vehicles in its path
        min_gap: float = 4.0  # [m] standstill gap
        margin: float = 2.0  # [m] added to its stopping distance before it brakes fully

    def reset(self, mission, roadmap) -> None:
        super().reset(mission, roadmap)
        self._cruise = float(self.options.cruise_speed)

    def step(self, obs: Observation) -> Control:
        if obs.sun_glare:
            obs = replace(obs, sun_glare=False)
        self.options.cruise_speed = self._visibility_cap(obs)
        control = super().step(obs)
        if self.options.fault == "no_control":
            return control
        v = obs.ego.speed
        accel = self._hazard_accel(obs)
        if accel is None:
            return control
        if accel <= -self.params.max_brake_decel + 1e-6:
            return Control(control.steer, 0.0, 1.0)
        planned = control.throttle * self.speed.max_accel if control.throttle > 0 else \
            -control.brake * self.speed.max_decel
        if accel >= planned:
            return control
        throttle, brake = self.speed.pedals(accel, v, v)
        return Control(control.steer, throttle, brake)

    def _visibility_cap(self, obs: Observation) -> float:
        """[m/s] when weather shortens its sensor range, the speed it can stop from comfortably within
        :data:`SIGHT_SHARE` of what it sees (0: no cap beyond the option)."""
        rng = self.sensors.effective_range(obs.weather)
        if rng >= self.sensors.spec.range_m - 1e-6:
            return self._cruise
        a, d = VISIBILITY_DECEL, SIGHT_SHARE * rng
        cap = max(a * (-REACTION + math.sqrt(REACTION * REACTION + 2.0 * d / a)), 2.0)
        return min(cap, self._cruise) if self._cruise > 0 else cap

    def _hazard_accel(self, obs: Observation) -> float | None:
        """The acceleration [m/s^2] its hazards allow (None: no constraint); ``-max_brake`` = brake fully."""
        tracks = list(self.perception.tracks.values())
        if not tracks:
            return None
        ego = obs.ego
        v = ego.speed
        path = self.path
        lo, hi = path.window(self.path_idx, 120)
        s_c = self.s_center
        half = ego.length / 2.0
        stop = v * REACTION + v * v / (2.0 * PLANNING_DECEL) + self.options.margin
        best = None
        for tr in tracks:
            ped, spd = tr[PED], tr[SPEED]
            corridor = 1.3 + tr[WIDTH] / 2 + (1.0 if ped else 0.4)
            moving = spd > 0.3
            for h in STEPS if (ped or moving) else (0.0,):
                px = tr[X] + spd * math.cos(tr[HEADING]) * h
                py = tr[Y] + spd * math.sin(tr[HEADING]) * h
                hit = path.locate_near(px, py, lo, hi)
                if hit is None:
                    continue
                s_o, lat_o = hit
                ahead = s_o - s_c
                if ahead <= 0 or ahead > 80 or abs(lat_o) > corridor:
                    continue
                # a predicted position counts if the car would not have passed it by then
                if h > 0 and ahead / max(v, 0.5) + 1.0 < h:
                    continue
                gap = ahead - half - tr[LENGTH] / 2
                along = spd * math.cos(tr[HEADING] - ego.heading)
                if gap < stop and (ped or along < v - 0.5 or h > 0 or not moving):
                    return -self.params.max_brake_decel
                if not ped and h == 0.0:
                    dv = v - max(along, 0.0)
                    a = idm_accel(v, 100.0, gap, dv, s0=self.options.min_gap, T=self.options.headway)  # the gap term only
                    best = a if best is None else min(best, a)
                break
        return best
