"""The mutation engine (the paper's Mutation Engine): Scenario -> Scenario, never touching SUMO.

``generate`` adds one actor or puddle according to the strategy; ``mutate``
changes aspects of existing components (position, speed, maneuver timing,
a puddle's place, size and friction) and the weather, never an actor's kind or
navigation type. Every draw respects:

- placement: vehicles on passenger lanes, pedestrians on sidewalks, within
  ``MutationConfig.min_range``..``max_range`` metres ahead of (or just behind) the
  ego's start along its route, so the ego will meet them;
- spatial constraint: at least ``min_separation`` metres between any two
  actors, the ego and static obstacles;
- temporal constraint: speeds at most ``max_vehicle_speed`` / ``max_pedestrian_speed``
  (20 mph and 6 mph by default).

An infeasible draw is retried (up to ``max_retries``); the retries are counted.
Every operation returns a one-line description of what it did.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from drivefuzz.roadmap import PASSENGER, PEDESTRIAN, RoadMap
from drivefuzz.scenario import (
    Actor,
    ActorKind,
    Maneuver,
    ManeuverAction,
    NavType,
    Puddle,
    Scenario,
    Weather,
)

MPH = 0.44704  # [m/s]
STRATEGIES = ("all", "congestion", "entropy", "instability", "maneuver")
Strategy = Literal["all", "congestion", "entropy", "instability", "maneuver"]


class MutationConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")
    min_range: float = Field(default=5.0, ge=0.0, description="[m] along the route from the ego's start")
    max_range: float = Field(default=80.0, gt=0.0, description="[m]")
    behind_range: float = Field(default=40.0, ge=0.0, description="[m] behind the ego (linear rear-enders)")
    min_separation: float = Field(default=7.0, ge=0.0, description="[m] between any two bodies' centres")
    max_vehicle_speed: float = Field(default=20 * MPH, gt=0.0, description="[m/s]")
    max_pedestrian_speed: float = Field(default=6 * MPH, gt=0.0, description="[m/s]")
    max_actors: int = Field(default=12, ge=0)
    max_puddles: int = Field(default=4, ge=0)
    puddle_probability: float = Field(default=0.25, ge=0.0, le=1.0)
    max_retries: int = Field(default=50, ge=1)
    #: Probabilistic scheduling of strategies: weights per strategy (used when strategy == "mix").
    mix: dict[str, float] = Field(default_factory=lambda: {s: 1.0 for s in STRATEGIES})


@dataclass(frozen=True)
class Mutation:
    scenario: Scenario
    description: str
    retries: int = 0


@dataclass(frozen=True)
class _Spot:
    lane: str
    pos: float
    x: float
    y: float
    heading: float
    route_index: int


class Mutator:
    def __init__(self, rmap: RoadMap, config: MutationConfig | None = None):
        self.rmap = rmap
        self.cfg = config or MutationConfig()
        self._route_cache: dict[tuple, tuple[str, ...]] = {}

    # ---------------------------------------------------------------- helpers
    def _route(self, sc: Scenario) -> tuple[str, ...]:
        key = (sc.mission.start_edge, sc.mission.goal_edge)
        if key not in self._route_cache:
            self._route_cache[key] = self.rmap.route(*key) or (sc.mission.start_edge,)
        return self._route_cache[key]

    def _spot_along(self, sc: Scenario, rng: random.Random, dist: float, vclass: str) -> _Spot | None:
        """A lane position ``dist`` metres along the ego's route from its start (negative: behind)."""
        route = self._route(sc)
        pos = sc.mission.start_pos + dist
        i = 0
        if pos < 0:
            lane = self.rmap.lane(sc.mission.start_lane)
            pos = max(pos, 0.0)
        while i < len(route):
            length = self.rmap.edge(route[i]).getLength()
            if pos <= length:
                break
            pos -= length
            i += 1
        if i >= len(route):
            return None
        edge = self.rmap.edge(route[i])
        if vclass == PEDESTRIAN:
            lanes = [l for l in edge.getLanes() if l.allows(PEDESTRIAN) and not l.allows(PASSENGER)]
        else:
            lanes = [l for l in edge.getLanes() if l.allows(PASSENGER)]
        if not lanes:
            return None
        lane = rng.choice(lanes)
        pos = min(max(pos, 1.0), lane.getLength() - 0.5)
        x, y, h = self.rmap.geom(lane.getID()).position(pos)
        return _Spot(lane.getID(), round(pos, 2), x, y, h, i)

    def _bodies(self, sc: Scenario, skip: str | None = None) -> list[tuple[float, float]]:
        g = self.rmap.geom(sc.mission.start_lane)
        pts = [g.position(max(sc.mission.start_pos - 2.3, 0.0))[:2]]
        for a in sc.actors:
            if a.id != skip:
                pts.append(self.rmap.geom(a.start_lane).position(a.start_pos)[:2])
        return pts

    def _separated(self, sc: Scenario, x: float, y: float, skip: str | None = None) -> bool:
        sep = self.cfg.min_separation
        return all(math.hypot(x - px, y - py) >= sep for px, py in self._bodies(sc, skip))

    def _new_id(self, sc: Scenario, prefix: str) -> str:
        used = {a.id for a in sc.actors}
        k = len(sc.actors)
        while f"{prefix}{k}" in used:
            k += 1
        return f"{prefix}{k}"

    def _dest_edge(self, sc: Scenario, spot: _Spot, rng: random.Random) -> str:
        route = self._route(sc)
        options = route[spot.route_index:]
        return rng.choice(options[-2:]) if len(options) > 1 else options[0]

    # --------------------------------------------------------------- generate
    def generate(self, sc: Scenario, strategy: str, rng: random.Random) -> Mutation:
        """Add one new actor or puddle (a puddle also with ``puddle_probability`` under ``all``)."""
        if strategy == "mix":
            names = list(self.cfg.mix)
            strategy = rng.choices(names, weights=[self.cfg.mix[n] for n in names])[0]
        if strategy == "instability" or (strategy == "all" and rng.random() < self.cfg.puddle_probability):
            return self.add_puddle(sc, rng)
        if len(sc.actors) >= self.cfg.max_actors:
            return Mutation(sc, f"no actor added (limit of {self.cfg.max_actors} reached)")
        if strategy == "congestion":
            return self.add_actor(sc, rng, rng.choice(list(ActorKind)), NavType.AUTOPILOT)
        if strategy == "entropy":
            return self.add_actor(sc, rng, rng.choice(list(ActorKind)), rng.choice([NavType.LINEAR, NavType.IMMOBILE]))
        if strategy == "maneuver":
            return self.add_actor(sc, rng, ActorKind.VEHICLE, NavType.MANEUVER)
        if strategy == "all":
            nav = rng.choice([NavType.AUTOPILOT, NavType.LINEAR, NavType.IMMOBILE, NavType.MANEUVER])
            kind = ActorKind.VEHICLE if nav is NavType.MANEUVER else rng.choice(list(ActorKind))
            return self.add_actor(sc, rng, kind, nav)
        raise ValueError(f"unknown strategy {strategy!r}")

    def add_actor(self, sc: Scenario, rng: random.Random, kind: ActorKind, nav: NavType) -> Mutation:
        cfg = self.cfg
        vclass = PEDESTRIAN if kind is ActorKind.PEDESTRIAN else PASSENGER
        vmax = cfg.max_pedestrian_speed if kind is ActorKind.PEDESTRIAN else cfg.max_vehicle_speed
        for attempt in range(cfg.max_retries):
            if nav is NavType.LINEAR and kind is ActorKind.VEHICLE and rng.random() < 0.5:
                dist = -rng.uniform(cfg.min_range, cfg.behind_range)  # a rear-ender from behind
            else:
                dist = rng.uniform(cfg.min_range, cfg.max_range)
            spot = self._spot_along(sc, rng, dist, vclass)
            if spot is None or not self._separated(sc, spot.x, spot.y):
                continue
            speed = 0.0 if nav is NavType.IMMOBILE else round(rng.uniform(0.3 * vmax, vmax), 2)
            aid = self._new_id(sc, "p" if kind is ActorKind.PEDESTRIAN else "v")
            fields = dict(id=aid, kind=kind, nav=nav, start_lane=spot.lane, start_pos=spot.pos, speed=speed)
            extra = ""
            if kind is ActorKind.PEDESTRIAN:
                if nav is NavType.LINEAR:  # jaywalk across the road, perpendicular to it
                    side = rng.choice((-1.0, 1.0))
                    across = rng.uniform(10.0, 16.0)
                    fields["dest_xy"] = (round(spot.x - side * math.sin(spot.heading) * across, 2),
                                         round(spot.y + side * math.cos(spot.heading) * across, 2))
                elif nav is NavType.AUTOPILOT:
                    fields["dest_edge"] = self._dest_edge(sc, spot, rng)
            elif nav is not NavType.IMMOBILE:
                fields["dest_edge"] = self._dest_edge(sc, spot, rng)
            if nav is NavType.MANEUVER:
                lanes = [l for l in self.rmap.lane(spot.lane).getEdge().getLanes() if l.allows(PASSENGER)]
                if len(lanes) < 2:
                    continue
                idx = self.rmap.lane(spot.lane).getIndex()
                toward = ManeuverAction.LANE_LEFT if idx == lanes[0].getIndex() else ManeuverAction.LANE_RIGHT
                t_lc = round(rng.uniform(0.5, 6.0), 2)
                fields["maneuvers"] = (Maneuver(time=t_lc, action=toward, value=round(rng.uniform(1.0, 3.0), 2)),)
                extra = f", {toward.value} at {t_lc} s"
            try:
                actor = Actor(**fields)
            except ValueError:
                continue
            new = sc.model_copy(update={"actors": sc.actors + (actor,)})
            return Mutation(new, f"add {nav.value} {kind.value} {aid} on {spot.lane} @ {spot.pos:.1f} m, "
                                 f"{speed:.1f} m/s{extra}", attempt)
        return Mutation(sc, f"no feasible {nav.value} {kind.value} after {cfg.max_retries} retries", cfg.max_retries)

    def add_puddle(self, sc: Scenario, rng: random.Random) -> Mutation:
        cfg = self.cfg
        if len(sc.puddles) >= cfg.max_puddles:
            return Mutation(sc, f"no puddle added (limit of {cfg.max_puddles} reached)")
        for attempt in range(cfg.max_retries):
            spot = self._spot_along(sc, rng, rng.uniform(cfg.min_range + 5.0, cfg.max_range), PASSENGER)
            if spot is None:
                continue
            p = Puddle(x=round(spot.x, 2), y=round(spot.y, 2), length=round(rng.uniform(4.0, 15.0), 2),
                       width=round(rng.uniform(3.0, 8.0), 2), rotation=round(rng.uniform(-math.pi, math.pi), 3),
                       friction=round(rng.uniform(0.05, 0.6), 2))
            new = sc.model_copy(update={"puddles": sc.puddles + (p,)})
            return Mutation(new, f"add puddle mu={p.friction} {p.length}x{p.width} m at ({p.x:.1f}, {p.y:.1f}) "
                                 f"near {spot.lane}", attempt)
        return Mutation(sc, f"no feasible puddle after {cfg.max_retries} retries", cfg.max_retries)

    # ----------------------------------------------------------------- mutate
    def mutate(self, sc: Scenario, rng: random.Random) -> Mutation:
        """Change one component's aspects (or only the weather when there are none), then the weather."""
        parts: list[str] = []
        retries = 0
        choices = [("actor", i) for i in range(len(sc.actors))] + [("puddle", i) for i in range(len(sc.puddles))]
        if choices:
            what, i = rng.choice(choices)
            m = self._mutate_actor(sc, i, rng) if what == "actor" else self._mutate_puddle(sc, i, rng)
            sc, retries = m.scenario, m.retries
            parts.append(m.description)
        w = self._mutate_weather(sc.weather, rng)
        sc = sc.model_copy(update={"weather": w[0]})
        parts.append(w[1])
        return Mutation(sc, "; ".join(parts), retries)

    def _mutate_actor(self, sc: Scenario, i: int, rng: random.Random) -> Mutation:
        a = sc.actors[i]
        cfg = self.cfg
        vmax = cfg.max_pedestrian_speed if a.kind is ActorKind.PEDESTRIAN else cfg.max_vehicle_speed
        aspect = rng.choice(["position", "speed", "timing"] if a.maneuvers else ["position", "speed"])
        if a.nav is NavType.IMMOBILE and aspect == "speed":
            aspect = "position"
        update: dict = {}
        desc = ""
        retries = 0
        if aspect == "position":
            lane = self.rmap.geom(a.start_lane)
            for retries in range(cfg.max_retries):
                pos = round(min(max(a.start_pos + rng.uniform(-10.0, 10.0), 1.0), lane.length - 0.5), 2)
                x, y, _ = lane.position(pos)
                if self._separated(sc, x, y, skip=a.id):
                    update = {"start_pos": pos}
                    desc = f"move {a.id} to {a.start_lane} @ {pos:.1f} m"
                    break
            else:
                return Mutation(sc, f"no feasible position for {a.id}", cfg.max_retries)
        elif aspect == "speed":
            speed = round(min(max(a.speed * rng.uniform(0.6, 1.4), 0.2), vmax), 2)
            update = {"speed": speed}
            desc = f"{a.id} speed {a.speed:.1f} -> {speed:.1f} m/s"
        else:
            k = rng.randrange(len(a.maneuvers))
            m = a.maneuvers[k]
            t = round(max(m.time + rng.uniform(-1.5, 1.5), 0.0), 2)
            mans = list(a.maneuvers)
            mans[k] = m.model_copy(update={"time": t})
            update = {"maneuvers": tuple(sorted(mans, key=lambda mm: mm.time))}
            desc = f"{a.id} maneuver {k} ({m.action.value}) at {m.time:.2f} -> {t:.2f} s"
        actors = list(sc.actors)
        actors[i] = Actor.model_validate({**a.model_dump(), **update})
        return Mutation(sc.model_copy(update={"actors": tuple(actors)}), desc, retries)

    def _mutate_puddle(self, sc: Scenario, i: int, rng: random.Random) -> Mutation:
        p = sc.puddles[i]
        aspect = rng.choice(["location", "size", "friction"])
        if aspect == "location":
            upd = {"x": round(p.x + rng.uniform(-5, 5), 2), "y": round(p.y + rng.uniform(-5, 5), 2)}
            desc = f"puddle {i} moved to ({upd['x']:.1f}, {upd['y']:.1f})"
        elif aspect == "size":
            upd = {"length": round(min(max(p.length * rng.uniform(0.6, 1.5), 1.0), 30.0), 2),
                   "width": round(min(max(p.width * rng.uniform(0.6, 1.5), 1.0), 15.0), 2),
                   "rotation": round(p.rotation + rng.uniform(-0.5, 0.5), 3)}
            desc = f"puddle {i} size {upd['length']}x{upd['width']} m"
        else:
            upd = {"friction": round(min(max(p.friction * rng.uniform(0.5, 1.5), 0.02), 2.0), 3)}
            desc = f"puddle {i} friction {p.friction} -> {upd['friction']}"
        puddles = list(sc.puddles)
        puddles[i] = p.model_copy(update=upd)
        return Mutation(sc.model_copy(update={"puddles": tuple(puddles)}), desc)

    def _mutate_weather(self, w: Weather, rng: random.Random) -> tuple[Weather, str]:
        fields = list(Weather.model_fields)
        name = rng.choice(fields)
        if name == "sun_azimuth_deg":
            value = round(rng.uniform(0.0, 360.0), 1)
        elif name == "sun_altitude_deg":
            value = round(rng.uniform(-90.0, 90.0), 1)
        else:
            value = round(rng.uniform(0.0, 100.0), 1)
        return w.model_copy(update={name: value}), f"weather {name} {getattr(w, name)} -> {value}"
