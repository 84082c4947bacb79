"""Sensing: what the car's sensors can see of the ground truth, limited by range, field of view and weather.

Fog and rain shorten the range; rain adds position noise; a sun low and ahead
blinds the traffic-light camera. Randomness comes from the mission seed.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

from drivefuzz.ads import ObjectState, Observation, TrafficLightState


@dataclass
class SensorSpec:
    range_m: float = 100.0  # [m] clear-weather detection range (camera + radar)
    fov_deg: float = 200.0  # [deg] forward field of view
    near_range_m: float = 12.0  # [m] all-around ultrasonic/radar coverage
    tl_range_m: float = 80.0  # [m] traffic-light camera range
    noise_m: float = 0.05  # [m] position noise (std) in clear weather


@dataclass(frozen=True)
class Detections:
    objects: tuple[ObjectState, ...]
    traffic_light: TrafficLightState | None  # None: no light seen (or blinded)
    range_m: float


class Sensors:
    def __init__(self, spec: SensorSpec, seed: int):
        self.spec = spec
        self.rng = random.Random(seed ^ 0x5EED)

    def effective_range(self, weather) -> float:
        """Fog shortens the range by up to 85 %, rain by up to 40 %."""
        return self.spec.range_m * (1.0 - 0.85 * weather.fog / 100.0) * (1.0 - 0.4 * weather.rain / 100.0)

    def sense(self, obs: Observation, tl_enabled: bool = True) -> Detections:
        ego = obs.ego
        rng_m = max(self.effective_range(obs.weather), self.spec.near_range_m)
        half_fov = math.radians(self.spec.fov_deg) / 2.0
        sigma = self.spec.noise_m * (1.0 + 4.0 * obs.weather.rain / 100.0)
        gauss = self.rng.gauss
        seen = []
        for o in obs.objects:
            dx, dy = o.x - ego.x, o.y - ego.y
            d = math.hypot(dx, dy)
            if d > rng_m:
                continue
            if d > self.spec.near_range_m:
                bearing = (math.atan2(dy, dx) - ego.heading + math.pi) % (2 * math.pi) - math.pi
                if abs(bearing) > half_fov:
                    continue
            seen.append(ObjectState(o.id, o.kind, o.x + gauss(0.0, sigma), o.y + gauss(0.0, sigma), o.heading,
                                    o.speed, o.length, o.width))
        tl = obs.traffic_light
        tl_range = min(self.spec.tl_range_m, max(rng_m, 25.0))
        if not tl_enabled or tl is None or tl.distance > tl_range or obs.sun_glare:
            tl = None
        return Detections(tuple(seen), tl, rng_m)
