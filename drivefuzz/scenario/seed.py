"""Seed scenarios: random missions on a network (the paper's Algorithm 2), verified by a dry run.

A seed is a mission with no actors, no puddles and clear weather: start and goal
on lanes that allow passenger cars, with a route of sensible length between
them. ``drivefuzz seed`` keeps only seeds that the reference ADS completes
without any misbehaviour, so that every later finding is caused by what the
fuzzer added.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Callable, Iterator

from drivefuzz.scenario.roadmap import PASSENGER, RoadMap
from drivefuzz.scenario import AdsSpec, Mission, Scenario, SimOptions

#: Route length [m] a seed mission aims for.
MIN_ROUTE_M = 80.0
MAX_ROUTE_M = 400.0
#: Shortest edge [m] a mission starts or ends on.
MIN_EDGE_M = 25.0


#: [s] The immobility oracle's default threshold (``immobility.threshold``; a test keeps them equal).
IMMOBILITY_S = 60.0
#: [s] Time a seed allows beyond that threshold: for the ego to drive to where it may get stuck,
#: and for the immobility clock to pass the threshold before the time limit ends the run.
IMMOBILITY_MARGIN_S = 30.0


def time_limit_for(rmap: RoadMap, route: tuple[str, ...], length_m: float) -> float:
    """A generous time limit [s]: 5 m/s average plus 45 s for each signalised junction on the route,
    and never less than the immobility threshold plus a margin (90 s), so that an ego that gets
    stuck in a mutant of the seed is caught by the immobility oracle rather than by the time limit."""
    signals = sum(1 for e in route[:-1] if rmap.edge(e).getToNode().getType().startswith("traffic_light"))
    return round(max(30.0 + length_m / 5.0 + 45.0 * signals, IMMOBILITY_S + IMMOBILITY_MARGIN_S), 1)


def doubles_back(rmap: RoadMap, route: tuple[str, ...]) -> bool:
    """Whether ``route`` drives a road in both directions (a U-turn at a dead end, or a loop back)."""
    seen: set[tuple[str, str]] = set()
    for e in route:
        edge = rmap.edge(e)
        a, b = edge.getFromNode().getID(), edge.getToNode().getID()
        if (b, a) in seen:
            return True
        seen.add((a, b))
    return False


def random_missions(rmap: RoadMap, rng: random.Random, network: str, max_draws: int = 5000) -> Iterator[Scenario]:
    """Random candidate seeds (unverified), until ``max_draws`` draws in a row gave none.

    Works on any network a user brings: only normal edges with a passenger lane of at least
    ``MIN_EDGE_M`` are used as start and goal (no sidewalks, bus or bike lanes, junction lanes),
    the ego starts on a lane that continues along its route, and routes that drive a road in
    both directions (U-turns at dead ends) are left out. Networks too small for routes of
    ``MIN_ROUTE_M`` get routes of at least half their longest possible route instead.
    """
    edges = [e for e in rmap.edge_ids(PASSENGER)
             if rmap.edge(e).getLength() >= MIN_EDGE_M and not rmap.edge(e).getID().startswith(":")]
    if not edges:
        return
    min_route = MIN_ROUTE_M
    misses = 0
    longest = 0.0
    while misses < max_draws:
        misses += 1
        if misses == max_draws // 2 and longest < MIN_ROUTE_M:
            min_route = max(longest / 2.0, 2 * MIN_EDGE_M)  # a small network: shorter missions
        start = rng.choice(edges)
        goal = rng.choice(edges)
        route = rmap.route(start, goal)
        if route is None or len(route) < 2 or doubles_back(rmap, route):
            continue
        start_len = rmap.edge(start).getLength()
        goal_len = rmap.edge(goal).getLength()
        start_pos = round(rng.uniform(5.0, max(5.0, min(start_len * 0.5, start_len - 15.0))), 1)
        goal_pos = round(rng.uniform(min(12.0, goal_len / 2), max(12.0, goal_len - 12.0)), 1)
        goal_pos = min(goal_pos, round(goal_len - 1.0, 1))
        length = rmap.route_length(route, start_pos, goal_pos)
        longest = max(longest, length)
        if not min_route <= length <= MAX_ROUTE_M:
            continue
        start_lanes = [l.getID() for l in rmap.edge(start).getLanes()
                       if l.allows(PASSENGER) and any(c.getTo().getID() == route[1] for c in l.getOutgoing())]
        if not start_lanes:
            continue
        misses = 0
        yield Scenario(
            network=network,
            mission=Mission(start_lane=rng.choice(start_lanes), start_pos=start_pos, goal_edge=goal,
                            goal_pos=goal_pos),
            ads=AdsSpec(name="ego"),
            seed=rng.randrange(2**31),
            sim=SimOptions(time_limit=time_limit_for(rmap, route, length)),
            name="seed",
        )


def generate_seeds(network: str | Path, n: int, rng_seed: int = 0, *,
                   verify: Callable[[Scenario], tuple[bool, str]] | None = None, max_tries: int | None = None,
                   conflict_share: float = 0.5, log: Callable[[str], None] = lambda s: None) -> list[Scenario]:
    """``n`` seeds for ``network`` (fewer if the network does not allow them).

    About ``conflict_share`` of them are missions through a conflict point of the network (an unprotected
    left turn, a link that must yield, a merge, a crosswalk, a signalised stop line:
    :mod:`drivefuzz.scenario.conflicts`), taking the kinds in turn; the rest are random missions.
    ``verify`` (for example :func:`drivefuzz.sim.verify.dry_run`) returns (passed, reason) for a candidate;
    candidates that fail it are dropped. Without it, every candidate mission is kept.
    """
    from itertools import islice

    from drivefuzz.scenario.conflicts import conflict_missions
    from drivefuzz.scenario.roadmap import load_roadmap

    rmap = load_roadmap(network)
    rng = random.Random(rng_seed)
    path = str(Path(network).resolve())
    randoms = ((None, sc) for sc in random_missions(rmap, rng, path))
    conflicts = conflict_missions(rmap, random.Random(f"{rng_seed}/conflicts"), path) if conflict_share > 0 else iter(())
    out: list[Scenario] = []
    tries = 0
    max_tries = max_tries or 20 * n
    while len(out) < n and tries < max_tries:
        want_conflict = len([s for s in out if "-conflict-" in s.name]) < round(conflict_share * n)
        cand = next(islice(conflicts, 1), None) if want_conflict else None
        if cand is None:
            cand = next(randoms, None)
            if cand is None:
                break
        kind, sc = cand
        tries += 1
        if verify is not None:
            ok, why = verify(sc)
            log(f"candidate {sc.mission.start_lane}->{sc.mission.goal_edge}"
                f"{'' if kind is None else ' (' + kind.value + ')'}: {'ok' if ok else 'rejected: ' + why}")
            if not ok:
                continue
        what = "seed" if kind is None else f"conflict-{kind.value}"
        out.append(sc.model_copy(update={"name": f"{rmap.name}-{what}-{len(out):03d}"}))
    return out


def list_seeds(folder: str | Path) -> list[Path]:
    """Seed folders (those holding scenario.json) under ``folder``, sorted."""
    folder = Path(folder)
    return sorted(p.parent for p in folder.glob("*/scenario.json"))
