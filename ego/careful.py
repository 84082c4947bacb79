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
  good at a green light);
- it yields to walkers by their predicted line, not their place: a walker it tracks is extrapolated in a
  straight line at its speed over the car's comfortable stopping time plus a second (at least
  :data:`HORIZON`, at most :data:`WALKER_HORIZON` s); where that line crosses its path corridor before the
  car's rear could have cleared it, the car stops :data:`WALKER_MARGIN` short of the crossing, so it never
  stands inside a walker's predicted path (the reference stops a gap short of where the walker is, which a
  walker crossing at an angle walks into);
- it slows for low friction it knows: the road's wetness (it sees rain and a wet road), and the puddles of the
  map (option ``puddles``, which the attribution's replay fills from the scenario: the benchmark of what could
  have been done, as a local driver knows an icy bend): on ground of friction ``mu`` it drives no faster than
  it can stop from at half its grip within :data:`GRIP_SIGHT` m, takes bends at half its grip sideways, slows
  at :data:`FREE_DECEL_CAREFUL` before the patch, and counts on ``0.8 mu g`` (at most :data:`PLANNING_DECEL`)
  for its stopping distance.

What it cannot see: what its sensors miss (range, field of view, fog, occlusion: the reference's sensing); a
walker's or driver's intent (it extrapolates the present heading and speed: a walker who turns, or a car that
will brake, surprises it as it would a human); friction it is not told of (a puddle absent from its option).
Cyclists are not modelled by drivefuzz (actors are vehicles or pedestrians); a slow vehicle is treated as one.

Units: SI, radians ENU.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import replace

from drivefuzz.ads import Control, Observation
from drivefuzz.sim.world import surface_friction

from ego.ads import ReferenceADS
from ego.perception import HEADING, LENGTH, PED, SPEED, WIDTH, X, Y
from ego.planning import idm_accel, profile_accel, stop_accel

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
#: [s] the longest a walker's straight line is extrapolated.
WALKER_HORIZON = 6.0
#: [s] step of that extrapolation.
WALKER_STEP = 0.25
#: [m] it stops this far (front bumper) short of where a walker's predicted line enters its path corridor.
WALKER_MARGIN = 1.5
#: [m] half-width of the corridor a walker's predicted line must keep out of: half the car and a margin.
WALKER_CORRIDOR = 1.0 + 0.9
#: [m] on low friction it drives no faster than it can stop from, at half its grip, within this distance.
GRIP_SIGHT = 30.0
#: [m/s^2] how it slows before a patch of low friction.
FREE_DECEL_CAREFUL = 2.0
#: [m/s^2] gravity
G = 9.81


class CarefulADS(ReferenceADS):
    name = "careful"

    class Options(ReferenceADS.Options):
        speed_margin: float = 0.9
        headway: float = 2.0  # [s] time gap it keeps to vehicles in its path
        min_gap: float = 4.0  # [m] standstill gap
        margin: float = 2.0  # [m] added to its stopping distance before it brakes fully
        #: puddles it knows of: "x,y,length,width,rotation,friction" [m, rad ENU], ";" between (:func:`puddle_option`)
        puddles: str = ""

    def reset(self, mission, roadmap) -> None:
        super().reset(mission, roadmap)
        self._cruise = float(self.options.cruise_speed)
        self._mu_path = _path_friction(self.path, self.options.puddles)  # per path point (None: no puddles)
        self._grip_profile = None  # built at the first step (the road's wetness comes with the observation)

    def step(self, obs: Observation) -> Control:
        if obs.sun_glare:
            obs = replace(obs, sun_glare=False)
        self.options.cruise_speed = self._visibility_cap(obs)
        control = super().step(obs)
        if self.options.fault == "no_control":
            return control
        v = obs.ego.speed
        accel = self._hazard_accel(obs)
        for extra in (self._walker_accel(obs), self._grip_accel(obs)):
            if extra is not None:
                accel = extra if accel is None else min(accel, extra)
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
        stop = v * REACTION + v * v / (2.0 * self._planning_decel(obs)) + self.options.margin
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

    # ------------------------------------------------------------------ walkers' predicted lines
    def _walker_accel(self, obs: Observation) -> float | None:
        """The acceleration [m/s^2] that stops it :data:`WALKER_MARGIN` short of where a walker's predicted line
        enters its path corridor, for each walker whose line crosses the path before the car's rear could have
        cleared it at its present speed (None: no walker to yield to)."""
        tracks = [tr for tr in self.perception.tracks.values() if tr[PED] and tr[SPEED] > 0.2]
        if not tracks:
            return None
        v = obs.ego.speed
        half = obs.ego.length / 2.0
        front, rear = self.s_center + half, self.s_center - half
        horizon = min(max(HORIZON, REACTION + v / VISIBILITY_DECEL + 1.0), WALKER_HORIZON)
        lo, hi = self.path.window(self.path_idx, 120)
        best = None
        for tr in tracks:
            c, s_, spd = math.cos(tr[HEADING]), math.sin(tr[HEADING]), tr[SPEED]
            s_in = s_out = t_in = None
            h = 0.0
            while h <= horizon + 1e-9:
                hit = self.path.locate_near(tr[X] + spd * c * h, tr[Y] + spd * s_ * h, lo, hi)
                if hit is not None and abs(hit[1]) <= WALKER_CORRIDOR + tr[WIDTH] / 2:
                    s_in = hit[0] if s_in is None else min(s_in, hit[0])
                    s_out = hit[0] if s_out is None else max(s_out, hit[0])
                    t_in = h if t_in is None else t_in
                h += WALKER_STEP
            if s_in is None or s_out < rear:
                continue  # its line keeps out of the path, or crosses it behind the car
            if s_in - WALKER_MARGIN < front:
                continue  # too late to stop short: the hazard rule (brake fully, or drive on) decides
            # the car's rear clears the far side of the walker's line (and its margin) at its present speed
            # a second before the walker gets there: no need to wait
            if v > 0.5 and (s_out + WALKER_MARGIN - rear) / v < t_in - 1.0:
                continue
            a = stop_accel(v, s_in - WALKER_MARGIN - front, comfort=3.0)
            best = a if best is None else min(best, a)
        return best

    # ------------------------------------------------------------------ low friction it knows
    def _planning_decel(self, obs: Observation) -> float:
        """[m/s^2] the deceleration its stopping distance counts on: :data:`PLANNING_DECEL`, or ``0.8 mu g`` on
        the lowest friction it knows of within 40 m ahead."""
        mu = self._known_mu(obs, 40.0)
        return min(PLANNING_DECEL, max(0.8 * mu * G, 0.3))

    def _known_mu(self, obs: Observation, ahead_m: float) -> float:
        """The lowest friction it knows of on its path from its rear to ``ahead_m`` [m] ahead (the wet road, the
        puddles of its option)."""
        mu = surface_friction(obs.weather)
        if self._mu_path is None:
            return mu
        s = self.path._s
        i0 = max(self.path_idx - 5, 0)
        i1 = min(bisect.bisect_right(s, s[self.path_idx] + ahead_m, self.path_idx), len(s) - 1)
        return min(mu, min(self._mu_path[i0:i1 + 1]))

    def _grip_accel(self, obs: Observation) -> float | None:
        """The acceleration [m/s^2] that keeps it at or below the speed its known grip allows (None: no cap
        binds): on friction ``mu``, ``sqrt(2 * 0.5 mu g * GRIP_SIGHT)``, reached braking gently before it."""
        if self._grip_profile is None:
            mu0 = surface_friction(obs.weather)
            mus = self._mu_path if self._mu_path is not None else [mu0] * len(self.path._s)
            self._grip_profile = _grip_profile(self.path, [min(m, mu0) for m in mus])
        if self._grip_profile is False:
            return None
        v = obs.ego.speed
        a = profile_accel(self._grip_profile, self.path, self.path_idx, v, max(v * 1.0, 4.0))
        cap = self._grip_profile[self.path_idx]
        if v > cap:
            a = min(a, -FREE_DECEL_CAREFUL)
        return None if not math.isfinite(a) else a


def grip_speed(mu: float) -> float:
    """[m/s] the careful driver's speed on ground of friction ``mu``: it stops from it, braking at half its grip,
    within :data:`GRIP_SIGHT` m."""
    return math.sqrt(2.0 * 0.5 * max(mu, 0.02) * G * GRIP_SIGHT)


def _grip_profile(path, mus: list[float]):
    """Per path point, the highest speed [m/s] that respects :func:`grip_speed` there (and, in a bend, a sideways
    acceleration of half the grip) and, braking at :data:`FREE_DECEL_CAREFUL`, at every later point; False where
    the friction is 0.9 or more all along (the reference's own profile does)."""
    if min(mus) >= 0.9:  # a dry road: the reference's curvature profile and limits do
        return False
    # in a bend, half the grip sideways: v^2 k <= 0.5 mu g
    caps = [min(grip_speed(m), math.sqrt(0.5 * max(m, 0.02) * G / k) if k > 1e-4 else 100.0)
            for m, k in zip(mus, path.curvature.tolist())]
    s = path._s
    prof = list(caps)
    for i in range(len(prof) - 2, -1, -1):
        prof[i] = min(caps[i], math.sqrt(prof[i + 1] ** 2 + 2.0 * FREE_DECEL_CAREFUL * (s[i + 1] - s[i])))
    return prof


def puddle_option(puddles) -> str:
    """The ``puddles`` option that tells the careful driver of a scenario's puddles."""
    return ";".join(",".join(f"{v:.6g}" for v in (p.x, p.y, p.length, p.width, p.rotation, p.friction))
                    for p in puddles)


def _path_friction(path, option: str) -> list[float] | None:
    """Per path point, the lowest friction of the puddles in ``option`` (:func:`puddle_option`) under it (1.0
    elsewhere); None without puddles."""
    if not option.strip():
        return None
    items = []
    for part in option.split(";"):
        x, y, length, width, rot, f = (float(v) for v in part.split(","))
        items.append((x, y, math.cos(rot), math.sin(rot), length / 2.0, width / 2.0, f))
    out = []
    for px, py in path._xy:
        mu = 1.0
        for cx, cy, c, s, hl, hw, f in items:
            dx, dy = px - cx, py - cy
            # the car's half-width counts: a wheel on the patch is on it
            if abs(c * dx + s * dy) <= hl + 1.0 and abs(-s * dx + c * dy) <= hw + 1.0:
                mu = min(mu, f)
        out.append(mu)
    return out
