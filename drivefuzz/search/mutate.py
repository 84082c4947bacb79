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

Linear vehicles (the entropy strategy's reckless drivers, which ignore the ego)
are placed where they will meet it, timed with a simple profile of how the
reference ADS drives the empty route (accelerate, cruise below the limit, slow
for junction turns): *rear* ones on the ego's lane behind it, no further back
than the distance from which their constant speed still catches the
accelerating ego; *cross* ones on another approach to a junction of the
ego's route whose passage crosses or merges into the ego's, placed so that they
reach the conflict point as the ego's body passes it; the rest ahead on the
route. Linear pedestrians jaywalk across the road from the sidewalk. On roads
without sidewalks pedestrians use the edge of a shared lane, and on single-lane
roads a maneuver actor brakes hard in front of the ego instead of cutting in.

An infeasible draw is retried (up to ``max_retries``); the retries are counted.
Every operation returns a one-line description of what it did.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from drivefuzz.scenario.roadmap import PASSENGER, PEDESTRIAN, RoadMap
from drivefuzz.search.fairness import lane_limit, unfair
from drivefuzz.search.placement import RoutePlacement
from drivefuzz.scenario.model import MAX_NUDGE, MIN_CLOSE_TTC, MIN_FOLLOW_S
from drivefuzz.scenario import (
    Actor,
    ActorKind,
    Maneuver,
    ManeuverAction,
    NavType,
    Puddle,
    Scenario,
    Trigger,
    Weather,
)

MPH = 0.44704  # [m/s]
#: The weather aspects that change something (sensing, friction, wind, glare). ``cloud`` and
#: ``puddle_density`` stay in the model for the files' sake but are read nowhere, so they are not mutated.
EFFECTIVE_WEATHER = ("rain", "wind", "fog", "wetness", "sun_azimuth_deg", "sun_altitude_deg")
STRATEGIES = ("all", "congestion", "entropy", "instability", "maneuver")
Strategy = Literal["all", "congestion", "entropy", "instability", "maneuver"]
#: the members that move the riskiest actor while a job still has cells to aim at; the rest add a component aimed at
#: one. tools/eval_coverage.py --execs 1000 --reps 5 at 0.5 (as without cells), 0.3 and 0.15: interchange 84.3, 86.3
#: and 85.2 % of its reachable cells, intersection 87.2, 88.0 and 88.6 % (docs/coverage.md, eighteenth session)
AIMED_TARGET_SHARE = 0.3


class MutationConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")
    min_range: float = Field(default=5.0, ge=0.0, description="[m] along the route from the ego's start")
    max_range: float = Field(default=80.0, gt=0.0, description="[m]")
    behind_range: float = Field(default=40.0, ge=0.0, description="[m] behind the ego (linear rear-enders)")
    min_separation: float = Field(default=7.0, ge=0.0, description="[m] between any two bodies' centres")
    max_vehicle_speed: float = Field(default=40.0, gt=0.0, description="[m/s] a cap over the lane-relative speeds")
    vehicle_speed_share: tuple[float, float] = Field(default=(0.4, 1.0), description="NPC vehicle speeds as a share "
                                                     "of their lane's limit (low, high)")
    immobile_min_range: float = Field(default=25.0, ge=0.0, description="[m] along the route: no obstacle closer "
                                      "to the ego's start")
    target_share: float = Field(default=0.5, ge=0.0, le=1.0, description="members that move the riskiest actor "
                                "instead of adding a component")
    aimed_target_share: float = Field(default=AIMED_TARGET_SHARE, ge=0.0, le=1.0, description="target_share while "
                                      "the job has interaction-coverage cells to aim at (guided feedback)")
    catalogue_share: float = Field(default=0.5, ge=0.0, le=1.0, description="new components drawn from the "
                                   "situation catalogue (the rest by random placement)")
    aim_share: float = Field(default=1.0, ge=0.0, le=1.0, description="new components aimed at an interaction-"
                             "coverage cell the job has not reached (when the job names them: guided feedback)")
    max_pedestrian_speed: float = Field(default=6 * MPH, gt=0.0, description="[m/s]")
    max_actors: int = Field(default=12, ge=0)
    max_puddles: int = Field(default=4, ge=0)
    puddle_probability: float = Field(default=0.25, ge=0.0, le=1.0)
    max_retries: int = Field(default=50, ge=1)
    #: Linear vehicles (entropy): share placed behind the ego to rear-end it, and share sent across a junction
    #: on the ego's route timed to meet it there (side impact); the rest go ahead of the ego on its route.
    entropy_linear_share: float = Field(default=0.75, ge=0.0, le=1.0, description="entropy: linear (else immobile)")
    linear_rear_share: float = Field(default=0.0, ge=0.0, le=1.0, description="reckless rear-enders: unfair, "
                                     "so off by default (the fairness check rejects them anyway)")
    linear_cross_share: float = Field(default=0.45, ge=0.0, le=1.0)
    conflict_range: float = Field(default=160.0, gt=0.0, description="[m] along the route: junctions where linear "
                                  "vehicles are timed to cross the ego's path")
    #: The ego's expected motion, used only to time linear actors: acceleration and share of the speed limit.
    ego_accel: float = Field(default=2.0, gt=0.0, description="[m/s^2]")
    ego_decel: float = Field(default=1.2, gt=0.0, description="[m/s^2]")
    ego_lat_accel: float = Field(default=1.5, gt=0.0, description="[m/s^2] in junction turns (mean curvature)")
    ego_speed_share: float = Field(default=0.94, gt=0.0, le=1.5)
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


class Mutator(RoutePlacement):
    def __init__(self, rmap: RoadMap, config: MutationConfig | None = None):
        self.rmap = rmap
        self.cfg = config or MutationConfig()
        self._route_cache: dict[tuple, tuple[str, ...]] = {}
        # (start lane, goal edge) -> per route edge (the lane the ego enters by, the lane it drives on)
        self._ego_lanes: dict[tuple[str, str], list[tuple[str, str]]] = {}
        self._conflict_cache: dict[tuple, list] = {}
        self._profile_cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        self._observed: dict[tuple, tuple[np.ndarray, float]] = {}  # mission -> a run's metres driven (observe)
        self._walkable_cache: dict[tuple, bool] = {}

    # ---------------------------------------------------------------- helpers
    def _route(self, sc: Scenario) -> tuple[str, ...]:
        key = (sc.mission.start_edge, sc.mission.goal_edge)
        if key not in self._route_cache:
            self._route_cache[key] = self.rmap.route(*key) or (sc.mission.start_edge,)
        return self._route_cache[key]

    def _spot_along(self, sc: Scenario, rng: random.Random, dist: float, vclass: str,
                    ego_lane: bool = False) -> _Spot | None:
        """A lane position ``dist`` metres along the ego's route from its start (negative: behind); with
        ``ego_lane``, on the lane the ego will drive there."""
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
        if vclass == PEDESTRIAN:  # a sidewalk; on roads without one, the edge of a lane walkers may use
            lanes = ([l for l in edge.getLanes() if l.allows(PEDESTRIAN) and not l.allows(PASSENGER)]
                     or [l for l in edge.getLanes()[:1] if l.allows(PEDESTRIAN)])
        elif ego_lane:
            lanes = [self.rmap.lane(self.ego_lane(sc, i))]
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

    def _new_id(self, sc: Scenario, prefix: str, taken: tuple[Actor, ...] | list[Actor] = ()) -> str:
        """An unused actor id: ``prefix`` and a number, not used by ``sc`` nor by the actors ``taken`` for it."""
        used = {a.id for a in sc.actors} | {a.id for a in taken}
        k = len(sc.actors) + len(taken)
        while f"{prefix}{k}" in used:
            k += 1
        return f"{prefix}{k}"

    def _dest_edge(self, sc: Scenario, spot: _Spot, rng: random.Random) -> str:
        route = self._route(sc)
        options = route[spot.route_index:]
        return rng.choice(options[-2:]) if len(options) > 1 else options[0]

    def _walkable(self, sc: Scenario) -> bool:
        """Whether pedestrians can be placed along the ego's route at all."""
        key = (sc.mission.start_edge, sc.mission.goal_edge)
        if key not in self._walkable_cache:
            self._walkable_cache[key] = any(l.allows(PEDESTRIAN) for e in self._route(sc)
                                            for l in self.rmap.edge(e).getLanes())
        return self._walkable_cache[key]

    def _vehicle_speed(self, lane_id: str, rng: random.Random) -> float:
        """[m/s] a vehicle's speed drawn relative to its lane's limit (``vehicle_speed_share``)."""
        lo, hi = self.cfg.vehicle_speed_share
        return round(min(lane_limit(self, lane_id) * rng.uniform(lo, hi), self.cfg.max_vehicle_speed), 2)

    def _kind(self, sc: Scenario, rng: random.Random) -> ActorKind:
        kind = rng.choice(list(ActorKind))
        return kind if kind is ActorKind.VEHICLE or self._walkable(sc) else ActorKind.VEHICLE

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
            kind = self._kind(sc, rng)
            other = ActorKind.VEHICLE if kind is ActorKind.PEDESTRIAN else ActorKind.PEDESTRIAN
            return self._first_feasible(sc, rng, [(kind, NavType.AUTOPILOT), (other, NavType.AUTOPILOT)])
        if strategy == "entropy":
            nav = NavType.LINEAR if rng.random() < self.cfg.entropy_linear_share else NavType.IMMOBILE
            kind = self._kind(sc, rng)
            other = NavType.IMMOBILE if nav is NavType.LINEAR else NavType.LINEAR
            return self._first_feasible(sc, rng, [(kind, nav), (kind, other)])
        if strategy == "maneuver":
            return self.add_program(sc, rng)
        if strategy == "all":
            navs = [NavType.AUTOPILOT, NavType.LINEAR, NavType.IMMOBILE, NavType.MANEUVER]
            nav = rng.choice(navs)
            kind = ActorKind.VEHICLE if nav is NavType.MANEUVER else self._kind(sc, rng)
            rest = [n for n in navs if n is not nav]
            rng.shuffle(rest)
            return self._first_feasible(sc, rng, [(kind, nav)] + [
                (ActorKind.VEHICLE if n is NavType.MANEUVER else kind, n) for n in rest])
        raise ValueError(f"unknown strategy {strategy!r}")

    def add_program(self, sc: Scenario, rng: random.Random) -> Mutation:
        """One of the adversarial maneuver programs (:mod:`drivefuzz.search.programs`), the others in turn when
        the mission does not offer what it needs (a lane beside the ego's), else a single-step maneuver."""
        from drivefuzz.search.catalogue import add_situation
        from drivefuzz.search.programs import PROGRAMS

        retries = 0
        for program in rng.sample(PROGRAMS, len(PROGRAMS)):
            m = add_situation(self, sc, program, rng)
            retries += m.retries
            if m.scenario is not sc:
                return Mutation(m.scenario, m.description, retries)
        m = self.add_actor(sc, rng, ActorKind.VEHICLE, NavType.MANEUVER)
        return Mutation(m.scenario, m.description, retries + m.retries)

    def _first_feasible(self, sc: Scenario, rng: random.Random, options: list[tuple[ActorKind, NavType]]) -> Mutation:
        """The first of ``options`` (kind, navigation) that can be placed fairly; else the last one's reason.
        On a network of one-lane roads without sidewalks, say, no standing walker is fair on the ego's route."""
        retries = 0
        for kind, nav in options:
            m = self.add_actor(sc, rng, kind, nav)
            retries += m.retries
            if m.scenario is not sc:
                return Mutation(m.scenario, m.description, retries)
        return Mutation(sc, m.description, retries)

    def add_actor(self, sc: Scenario, rng: random.Random, kind: ActorKind, nav: NavType) -> Mutation:
        cfg = self.cfg
        vclass = PEDESTRIAN if kind is ActorKind.PEDESTRIAN else PASSENGER
        vmax = cfg.max_pedestrian_speed if kind is ActorKind.PEDESTRIAN else cfg.max_vehicle_speed
        linear_vehicle = nav is NavType.LINEAR and kind is ActorKind.VEHICLE
        for attempt in range(cfg.max_retries):
            speed = 0.0 if nav is NavType.IMMOBILE else round(rng.uniform(0.3 * vmax, vmax), 2)
            aid = self._new_id(sc, "p" if kind is ActorKind.PEDESTRIAN else "v")
            extra = ""
            if linear_vehicle:
                u = rng.random()
                mode = ("rear" if u < cfg.linear_rear_share else
                        "cross" if u < cfg.linear_rear_share + cfg.linear_cross_share else "ahead")
                if mode != "ahead":
                    speed = self._vehicle_speed(sc.mission.start_lane, rng)
                    placed = self._rear_place(sc, rng, speed) if mode == "rear" else self._cross_place(sc, rng, speed)
                    if placed is None:
                        continue
                    lane, pos, speed, dest, extra = placed
                    x, y, _ = self.rmap.geom(lane).position(pos)
                    if not self._separated(sc, x, y):
                        continue
                    try:
                        actor = Actor(id=aid, kind=kind, nav=nav, start_lane=lane, start_pos=pos, speed=speed,
                                      dest_edge=dest)
                    except ValueError:
                        continue
                    if unfair(self, sc, actor):
                        continue
                    return Mutation(sc.model_copy(update={"actors": sc.actors + (actor,)}),
                                    f"add linear vehicle {aid} on {lane} @ {pos:.1f} m, {speed:.1f} m/s{extra}",
                                    attempt)
            spot = self._spot_along(sc, rng, rng.uniform(cfg.min_range, cfg.max_range), vclass)
            if spot is None or not self._separated(sc, spot.x, spot.y):
                continue
            if kind is ActorKind.VEHICLE and nav is not NavType.IMMOBILE:
                speed = self._vehicle_speed(spot.lane, rng)
            fields = dict(id=aid, kind=kind, nav=nav, start_lane=spot.lane, start_pos=spot.pos, speed=speed)
            if kind is ActorKind.PEDESTRIAN:
                if nav is NavType.LINEAR:  # jaywalk: straight across the road, perpendicular to it
                    side = self._road_side(spot.lane)
                    across = self._road_width(spot.lane) + rng.uniform(1.0, 4.0)
                    fields["dest_xy"] = (round(spot.x - side * math.sin(spot.heading) * across, 2),
                                         round(spot.y + side * math.cos(spot.heading) * across, 2))
                    extra = ", across the road"
                elif nav is NavType.AUTOPILOT:
                    fields["dest_edge"] = self._dest_edge(sc, spot, rng)
            elif nav is not NavType.IMMOBILE:
                fields["dest_edge"] = self._dest_edge(sc, spot, rng)
            if nav is NavType.MANEUVER:
                lanes = [l for l in self.rmap.lane(spot.lane).getEdge().getLanes() if l.allows(PASSENGER)]
                t_m = round(rng.uniform(0.5, 6.0), 2)
                if len(lanes) >= 2:  # cut in: change towards the other lanes
                    idx = self.rmap.lane(spot.lane).getIndex()
                    toward = ManeuverAction.LANE_LEFT if idx == lanes[0].getIndex() else ManeuverAction.LANE_RIGHT
                    fields["maneuvers"] = (Maneuver(time=t_m, action=toward, value=round(rng.uniform(1.0, 3.0), 2)),)
                    extra = f", {toward.value} at {t_m} s"
                else:  # a single lane: brake hard in front of the ego, then drive on
                    slow = round(rng.uniform(0.0, 0.3) * speed, 2)
                    t_go = round(t_m + rng.uniform(1.0, 4.0), 2)
                    fields["maneuvers"] = (Maneuver(time=t_m, action=ManeuverAction.SPEED, value=slow),
                                           Maneuver(time=t_go, action=ManeuverAction.SPEED, value=speed))
                    extra = f", slows to {slow:.1f} m/s at {t_m} s until {t_go} s"
            try:
                actor = Actor(**fields)
            except ValueError:
                continue
            if unfair(self, sc, actor):
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
            # where the ego will drive: on its lane (the catalogue adds puddles in its braking zones and turns)
            spot = self._spot_along(sc, rng, rng.uniform(cfg.min_range + 5.0, cfg.max_range), PASSENGER,
                                    ego_lane=True)
            if spot is None:
                continue
            p = Puddle(x=round(spot.x, 2), y=round(spot.y, 2), length=round(rng.uniform(4.0, 15.0), 2),
                       width=round(rng.uniform(3.0, 8.0), 2), rotation=round(rng.uniform(-math.pi, math.pi), 3),
                       friction=round(rng.uniform(0.05, 0.6), 2))
            new = sc.model_copy(update={"puddles": sc.puddles + (p,)})
            return Mutation(new, f"add puddle mu={p.friction} {p.length}x{p.width} m at ({p.x:.1f}, {p.y:.1f}) "
                                 f"near {spot.lane}", attempt)
        return Mutation(sc, f"no feasible puddle after {cfg.max_retries} retries", cfg.max_retries)

    # -------------------------------------------------------------- successor
    def successor(self, sc: Scenario, strategy: str, rng: random.Random, hint: str | None = None,
                  aim: Sequence[str] | None = None) -> Mutation:
        """One member of a population (the job calls this once per member, each with its own ``rng``).

        With ``target_share`` (``aimed_target_share`` while there are cells to aim at), a targeted move of the
        actor that carried the most risk in ``sc``'s run
        (``hint``; a random actor without one); otherwise a new component of its own: aimed at one of the
        interaction-coverage cells ``aim`` (the job's unreached cells, :mod:`drivefuzz.search.aim`) with
        ``aim_share``, else from the situation catalogue (``catalogue_share``) or placed by the strategy;
        then the weather (unless the aim set it).
        """
        if sc.actors and rng.random() < (self.cfg.aimed_target_share if aim else self.cfg.target_share):
            ids = [a.id for a in sc.actors]
            i = ids.index(hint) if hint in ids else rng.randrange(len(ids))
            m = self.target(sc, i, rng)
            if m.scenario is not sc:
                return m
        u = rng.random()  # drawn whether or not there is an aim: a job without one keeps the same streams
        if aim and strategy in ("all", "mix") and u < self.cfg.aim_share:
            from drivefuzz.search.aim import AIM_DRAWS, aimed, pick_cell

            cells = list(aim)
            for _ in range(AIM_DRAWS):  # a cell the mission cannot offer now: another, before a component unaimed
                cell = pick_cell(cells, rng)
                m, weather_set = aimed(self, sc, cell, rng)
                if m.scenario is not sc:
                    if weather_set:
                        return m
                    w, wdesc = self._mutate_weather(m.scenario.weather, rng)
                    return Mutation(m.scenario.model_copy(update={"weather": w}), f"{m.description}; {wdesc}",
                                    m.retries)
                cells.remove(cell)
                if not cells:
                    break
        from drivefuzz.search.catalogue import SITUATIONS, add_situation

        if strategy in ("all", "mix") and rng.random() < self.cfg.catalogue_share and len(sc.actors) < self.cfg.max_actors:
            gen = add_situation(self, sc, rng.choice(SITUATIONS), rng)
        else:
            gen = self.generate(sc, strategy, rng)
        w, wdesc = self._mutate_weather(gen.scenario.weather, rng)
        return Mutation(gen.scenario.model_copy(update={"weather": w}), f"{gen.description}; {wdesc}", gen.retries)

    def target(self, sc: Scenario, i: int, rng: random.Random) -> Mutation:
        """Move actor ``i`` where it matters: its arrival time (departure), its start along its lane, its
        lane, or its speed relative to the lane's limit. Every move is checked for fairness and separation."""
        a = sc.actors[i]
        aspects = ["start", "lane"] if a.nav is NavType.IMMOBILE else ["timing", "start", "speed"]
        if a.kind is ActorKind.VEHICLE and a.nav is not NavType.IMMOBILE:
            aspects.append("lane")
        geom = self.rmap.geom(a.start_lane)
        for attempt in range(self.cfg.max_retries):
            aspect = rng.choice(aspects)
            if aspect == "timing":
                upd = {"depart": round(max(a.depart + rng.uniform(-3.0, 3.0), 0.0), 1)}
                desc = f"target {a.id}: depart {a.depart:.1f} -> {upd['depart']:.1f} s"
            elif aspect == "start":
                pos = round(min(max(a.start_pos + rng.choice((-1, 1)) * rng.uniform(2.0, 25.0), 1.0),
                                geom.length - 0.5), 2)
                if pos == a.start_pos:
                    continue
                upd, desc = {"start_pos": pos}, f"target {a.id}: start {a.start_pos:.1f} -> {pos:.1f} m"
            elif aspect == "speed":
                speed = (self._vehicle_speed(a.start_lane, rng) if a.kind is ActorKind.VEHICLE
                         else round(rng.uniform(0.3, 1.0) * self.cfg.max_pedestrian_speed, 2))
                upd, desc = {"speed": speed}, f"target {a.id}: speed {a.speed:.1f} -> {speed:.1f} m/s"
            else:
                vclass = PEDESTRIAN if a.kind is ActorKind.PEDESTRIAN else PASSENGER
                lanes = [l for l in self.rmap.lane(a.start_lane).getEdge().getLanes()
                         if l.allows(vclass) and l.getID() != a.start_lane]
                if not lanes:
                    continue
                lane = rng.choice(lanes)
                pos = round(min(a.start_pos, lane.getLength() - 0.5), 2)
                upd, desc = {"start_lane": lane.getID(), "start_pos": pos}, f"target {a.id}: lane -> {lane.getID()}"
            if "start_pos" in upd:
                x, y, _ = self.rmap.geom(upd.get("start_lane", a.start_lane)).position(upd["start_pos"])
                if not self._separated(sc, x, y, skip=a.id):
                    continue
            m = self._replace_actor(sc, i, upd, desc, attempt)
            if m.scenario is not sc:
                return m
        return Mutation(sc, f"no fair targeted move of {a.id}", self.cfg.max_retries)

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
            if a.kind is ActorKind.VEHICLE:
                vmax = min(vmax, 1.2 * lane_limit(self, a.start_lane))
            speed = round(min(max(a.speed * rng.uniform(0.6, 1.4), 0.2), vmax), 2)
            update = {"speed": speed}
            desc = f"{a.id} speed {a.speed:.1f} -> {speed:.1f} m/s"
        else:
            k = rng.randrange(len(a.maneuvers))
            m, step = a.maneuvers[k], self._mutate_step(a, a.maneuvers[k], rng)
            mans = list(a.maneuvers)
            mans[k] = step
            if all(mm.trigger is Trigger.TIME for mm in mans):
                mans.sort(key=lambda mm: mm.time)
            update = {"maneuvers": tuple(mans)}
            changed = {f: getattr(step, f) for f in ("time", "at", "value", "rate", "depth")
                       if getattr(step, f) != getattr(m, f)}
            desc = f"{a.id} maneuver {k} ({m.action.value}): " + (
                ", ".join(f"{f} {getattr(m, f):g} -> {v:g}" for f, v in changed.items()) or "unchanged")
        return self._replace_actor(sc, i, update, desc, retries)

    def _mutate_step(self, a: Actor, m: Maneuver, rng: random.Random) -> Maneuver:
        """Step ``m`` of ``a``'s program with its timing (the clock, or the gap or headway to the ego) or one
        of its parameters (speed, duration, braking rate, nudge depth) moved; fairness is checked after."""
        aspect = rng.choice(["timing", "parameter"])
        if aspect == "timing":
            if m.trigger in (Trigger.GAP, Trigger.PEAK):
                return m.model_copy(update={"at": round(m.at + rng.uniform(-5.0, 5.0), 1)})
            if m.trigger is Trigger.HEADWAY:
                return m.model_copy(update={"at": round(max(m.at + rng.uniform(-0.5, 0.5), 0.1), 2)})
            return m.model_copy(update={"time": round(max(m.time + rng.uniform(-1.5, 1.5), 0.0), 2)})
        if m.action is ManeuverAction.SPEED:
            if m.rate > 0.0 and rng.random() < 0.5:  # no harder than a car brakes on a dry road (8 m/s^2)
                return m.model_copy(update={"rate": round(min(max(m.rate * rng.uniform(0.6, 1.4), 0.5), 8.0), 1)})
            limit = lane_limit(self, a.start_lane)
            return m.model_copy(update={"value": round(min(max(m.value * rng.uniform(0.6, 1.4), 0.0),
                                                               1.2 * limit), 2)})
        if m.action is ManeuverAction.FOLLOW:
            gap = min(max(m.value * rng.uniform(0.6, 1.4), MIN_FOLLOW_S), 2.0)  # [s] time gap
            return m.model_copy(update={"value": round(gap, 2)})
        if m.action is ManeuverAction.CLOSE:  # [s] the time to collision at which it brakes
            return m.model_copy(update={"at": round(min(max(m.at * rng.uniform(0.7, 1.3), MIN_CLOSE_TTC), 3.0), 2)})
        if m.depth > 0.0 and rng.random() < 0.5:
            return m.model_copy(update={"depth": round(min(max(m.depth * rng.uniform(0.6, 1.4), 0.3), MAX_NUDGE), 2)})
        return m.model_copy(update={"value": round(min(max(m.value * rng.uniform(0.6, 1.4), 1.0), 5.0), 2)})

    def _replace_actor(self, sc: Scenario, i: int, update: dict, desc: str, retries: int = 0) -> Mutation:
        """``sc`` with actor ``i`` changed by ``update``; unchanged (and said so) when that would be unfair."""
        actors = list(sc.actors)
        try:
            actors[i] = Actor.model_validate({**sc.actors[i].model_dump(), **update})
        except ValueError as exc:
            return Mutation(sc, f"{desc}: invalid ({str(exc).splitlines()[0]}), not applied", retries)
        others = sc.model_copy(update={"actors": tuple(a for k, a in enumerate(sc.actors) if k != i)})
        why = unfair(self, others, actors[i])
        if why:
            return Mutation(sc, f"{desc}: unfair ({why}), not applied", retries)
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
        fields = list(EFFECTIVE_WEATHER)
        name = rng.choice(fields)
        if name == "sun_azimuth_deg":
            value = round(rng.uniform(0.0, 360.0), 1)
        elif name == "sun_altitude_deg":
            value = round(rng.uniform(-90.0, 90.0), 1)
        else:
            value = round(rng.uniform(0.0, 100.0), 1)
        return w.model_copy(update={name: value}), f"weather {name} {getattr(w, name)} -> {value}"
