"""Perception: tracks objects over frames, remembers traffic-light states, knows the speed limit."""

from __future__ import annotations

import math
from dataclasses import dataclass

from drivefuzz.ads import Observation

from ego.sensing import Detections

#: Indices into a track, a :data:`ego.sensing.Detected` tuple: id, is pedestrian, x [m], y [m],
#: heading [rad ENU], speed [m/s], length [m], width [m].
ID, PED, X, Y, HEADING, SPEED, LENGTH, WIDTH = range(8)


@dataclass
class World:
    tracks: list[tuple]  # see ID ... WIDTH
    tl_state: str | None  # last seen state of the next light ('' unknown)
    tl_distance: float  # [m] estimated distance to its stop line
    speed_limit: float  # [m/s]


class Perception:
    """Keeps tracks alive for ``hold_s`` after the last detection (bridges sensor dropouts)."""

    def __init__(self, hold_s: float = 0.5):
        self.hold_s = hold_s
        self.tracks: dict[str, tuple] = {}
        self.seen: dict[str, float] = {}  # [s] when each track was last detected
        self.tl: tuple[str, str, float, float] | None = None  # (tls id, state, distance, odometer at sighting)
        self.odometer = 0.0
        self.last_t = 0.0
        self.speed_limit = 13.89

    def update(self, obs: Observation, det: Detections) -> World:
        t = obs.t
        dt = max(t - self.last_t, 0.0)
        self.last_t = t
        self.odometer += obs.ego.speed * dt
        tracks, seen = self.tracks, self.seen
        for d in det.objects:
            tracks[d[ID]] = d
            seen[d[ID]] = t
        if len(tracks) > len(det.objects):
            for tid, tr in list(tracks.items()):
                if seen[tid] < t:
                    if t - seen[tid] > self.hold_s:
                        del tracks[tid], seen[tid]
                    else:  # dead-reckon a track that was not seen this frame
                        v, h = tr[SPEED], tr[HEADING]
                        tracks[tid] = (tid, tr[PED], tr[X] + v * math.cos(h) * dt, tr[Y] + v * math.sin(h) * dt,
                                       h, v, tr[LENGTH], tr[WIDTH])
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
        return World(list(tracks.values()), tl_state, tl_dist, self.speed_limit)
