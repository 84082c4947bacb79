"""Sensing: what the car's sensors can see of the ground truth, limited by range, field of view and weather.

Fog and rain shorten the range; rain adds position noise; a sun low and ahead
blinds the traffic-light camera. Randomness comes from the mission seed.

A detection is a plain tuple (see :data:`Detected`): the reference ADS handles a few
dozen objects a step, where Python tuples are cheaper than numpy arrays or objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivefuzz.ads import Observation, TrafficLightState

#: One detected object: (id, is pedestrian, x [m], y [m], heading [rad ENU], speed [m/s],
#: length [m], width [m]); x, y carry the sensor noise.
Detected = tuple[str, bool, float, float, float, float, float, float]


@dataclass
class SensorSpec:
    range_m: float = 100.0  # [m] clear-weather detection range (camera + radar)
    fov_deg: float = 200.0  # [deg] forward field of view
    near_range_m: float = 12.0  # [m] all-around ultrasonic/radar coverage
    tl_range_m: float = 80.0  # [m] traffic-light camera range
    noise_m: float = 0.05  # [m] position noise (std) in clear weather


@dataclass(frozen=True)
class Detections:
    objects: list[Detected]
    traffic_light: TrafficLightState | None  # None: no light seen (or blinded)
    range_m: float


class Sensors:
    def __init__(self, spec: SensorSpec, seed: int):
        self.spec = spec
        self.rng = np.random.Generator(np.random.PCG64(abs(int(seed)) ^ 0x5EED))
        self._normal: list[float] = []  # standard normal draws, made in blocks and used in order
        self._next = 0

    def _draws(self, n: int) -> int:
        """Index of ``n`` unused standard normal draws in ``self._normal``."""
        if self._next + n > len(self._normal):
            self._normal = self.rng.standard_normal(max(4096, n)).tolist()
            self._next = 0
        k = self._next
        self._next += n
        return k

    def effective_range(self, weather) -> float:
        """Fog shortens the range by up to 85 %, rain by up to 40 %."""
        return self.spec.range_m * (1.0 - 0.85 * weather.fog / 100.0) * (1.0 - 0.4 * weather.rain / 100.0)

    def sense(self, obs: Observation, tl_enabled: bool = True) -> Detections:
        ego = obs.ego
        rng_m = max(self.effective_range(obs.weather), self.spec.near_range_m)
        objs = obs.objects
        seen: list[Detected] = []
        if objs:
            sigma = self.spec.noise_m * (1.0 + 4.0 * obs.weather.rain / 100.0)
            r2, n2 = rng_m * rng_m, self.spec.near_range_m ** 2
            # within the field of view: the bearing's cosine is at least that of half the angle
            cos_half = math.cos(math.radians(self.spec.fov_deg) / 2.0)
            ex, ey = ego.x, ego.y
            ch, sh = math.cos(ego.heading), math.sin(ego.heading)
            sqrt = math.sqrt
            k, z = self._draws(2 * len(objs)), self._normal  # two draws per object, seen or not
            for o in objs:
                dx, dy = o.x - ex, o.y - ey
                d2 = dx * dx + dy * dy
                if d2 <= r2 and (d2 <= n2 or dx * ch + dy * sh >= cos_half * sqrt(d2)):
                    seen.append((o.id, o.kind == "pedestrian", o.x + sigma * z[k], o.y + sigma * z[k + 1], o.heading,
                                 o.speed, o.length, o.width))
                k += 2
        tl = obs.traffic_light
        tl_range = min(self.spec.tl_range_m, max(rng_m, 25.0))
        if not tl_enabled or tl is None or tl.distance > tl_range or obs.sun_glare:
            tl = None
        return Detections(seen, tl, rng_m)
