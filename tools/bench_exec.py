"""Executor overhead: a 60 s execution on the town network with 40 vehicles and 10 pedestrians.

Prints the wall time of one full drivefuzz execution (reference ADS, physics, all oracles,
trace), the same traffic in SUMO alone with the ego as a plain SUMO vehicle, their ratio,
and executions per hour on one core.  Usage: python tools/bench_exec.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import random
import statistics
import tempfile
import time
from pathlib import Path

import drivefuzz
from drivefuzz.execute import _sumo_args, execute
from drivefuzz.oracle import OracleSettings
from drivefuzz.roadmap import load_roadmap
from drivefuzz.scenario import Actor, Mission, Scenario, SimOptions
from drivefuzz.sumofiles import write_scenario

NET = Path(__file__).resolve().parents[1] / "networks" / "town.net.xml"


def busy_scenario(n_veh: int = 40, n_ped: int = 10, seed: int = 1) -> Scenario:
    rmap = load_roadmap(NET)
    rng = random.Random(seed)
    lanes = [l for l in rmap.lanes("passenger") if rmap.geom(l).length > 40]
    walks = rmap.lanes("pedestrian", exclusive_for="pedestrian")
    edges = rmap.edge_ids()
    actors, used = [], set()
    while len(actors) < n_veh:
        lane = rng.choice(lanes)
        pos = round(rng.uniform(10, rmap.geom(lane).length - 5), 1)
        key = (lane, int(pos // 12))
        if key in used or lane.startswith("A0B0"):
            continue
        dest = rng.choice(edges)
        if rmap.route(lane.rsplit("_", 1)[0], dest) is None:
            continue
        used.add(key)
        actors.append(Actor(id=f"v{len(actors)}", kind="vehicle", nav="autopilot", start_lane=lane, start_pos=pos,
                            speed=round(rng.uniform(5, 12), 1), dest_edge=dest))
    for i in range(n_ped):
        lane = rng.choice(walks)
        actors.append(Actor(id=f"p{i}", kind="pedestrian", nav="autopilot", start_lane=lane,
                            start_pos=round(rng.uniform(1, rmap.geom(lane).length - 1), 1), speed=1.2,
                            dest_edge=rng.choice(walks).rsplit("_", 1)[0]))
    return Scenario(network=str(NET), mission=Mission(start_lane="A0B0_1", start_pos=5, goal_edge="D3C3", goal_pos=60),
                    actors=tuple(actors), sim=SimOptions(time_limit=60.0), seed=seed)


def sumo_alone(sc: Scenario) -> float:
    import libsumo

    with tempfile.TemporaryDirectory() as d:
        write_scenario(sc, d)
        t0 = time.perf_counter()
        libsumo.start(_sumo_args(sc, Path(d), sc.network_path(), gui=False))
        steps = int(round(sc.sim.time_limit / sc.sim.step_length))
        for _ in range(steps):
            libsumo.simulationStep()
            for vid in libsumo.vehicle.getIDList():  # the same reads the executor does, nothing more
                libsumo.vehicle.getPosition(vid)
        libsumo.close()
        return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    sc = busy_scenario()
    # no goal inside 60 s, no early stop: run the full minute
    full, alone, stages = [], [], []
    for _ in range(args.repeat):
        ex = execute(sc, oracles=OracleSettings().instantiate(), stop_on_misbehavior=False)
        full.append(ex.wall_time)
        stages.append(ex.timings)
        alone.append(sumo_alone(sc))
    f, a = statistics.median(full), statistics.median(alone)
    print(f"frames per execution        {ex.trace.n_frames}  (termination: {ex.termination.value})")
    print(f"full execution (wall)       {f:.3f} s")
    print(f"SUMO alone, same traffic    {a:.3f} s")
    print(f"ratio                       {f / a:.2f}")
    print(f"executions per hour, 1 core {3600 / f:.0f}")
    print("per stage (median of runs):")
    for k in stages[0]:
        print(f"  {k:<10} {statistics.median(s[k] for s in stages):.3f} s")


if __name__ == "__main__":
    main()
