"""Perception: tracks objects over frames, remembers traffic-light states, knows the speed limit."""

from __future__ import annotations

import math
from dataclasses import dataclass

from drivefuzz.ads import Observation

from ego.sensing import Detections


@dataclass
class Track:
    id: str
    kind: str
    x: float
    y: float
    heading: float
    speed: float
    length: float
    width: float
    last_seen: float  # [s]


@dataclass
class World:
    tracks: list[Track]
    tl_state: str | None  # last seen state of the next light ('' unknown)
    tl_distance: float  # [m] estimated distance to its stop line
    speed_limit: float  # [m/s]


class Perception:
    """Keeps tracks alive for ``hold_s`` after the last detection (bridges sensor dropouts)."""

    def __init__(self, hold_s: float = 0.5):
        self.hold_s = hold_s
        self.tracks: dict[str, Track] = {}
        self.tl: tuple[str, str, float, float] | None = None  # (tls id, state, distance, odometer at sighting)
        self.odometer = 0.0
        self.last_t = 0.0
        self.speed_limit = 13.89

    def update(self, obs: Observation, det: Detections) -> World:
        dt = max(obs.t - self.last_t, 0.0)
        self.last_t = obs.t
        self.odometer += obs.ego.speed * dt
        for o in det.objects:
            self.tracks[o.id] = Track(o.id, o.kind, o.x, o.y, o.heading, o.speed, o.length, o.width, obs.t)
        for tid in [k for k, tr in self.tracks.items() if obs.t - tr.last_seen > self.hold_s]:
            del self.tracks[tid]
        for tr in self.tracks.values():  # dead-reckon tracks that were not seen this frame
            if tr.last_seen < obs.t:
                tr.x += tr.speed * math.cos(tr.heading) * dt
                tr.y += tr.speed * math.sin(tr.heading) * dt
        if det.traffic_light is not None:
            tl = det.traffic_light
            self.tl = (tl.tls_id, tl.state, tl.distance, self.odometer)
        elif obs.traffic_light is None:
            self.tl = None  # the route has no light ahead any more
        tl_state, tl_dist = None, math.inf
        if self.tl is not None:
            tl_state = self.tl[1]
            tl_dist = self.tl[2] - (self.odometer - self.tl[3])
        if obs.lane and not obs.lane.startswith(":") and math.isfinite(obs.speed_limit):
            self.speed_limit = obs.speed_limit
        return World(list(self.tracks.values()), tl_state, tl_dist, self.speed_limit)
