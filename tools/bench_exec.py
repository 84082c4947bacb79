"""Executor overhead: a 60 s execution on the town network with 40 vehicles and 10 pedestrians.

Prints the wall time of one full drivefuzz execution (reference ADS, physics, all oracles,
trace), the same traffic in SUMO alone with the ego as a plain SUMO vehicle (reading every
vehicle's position each step), their ratio, executions per hour on one core, the process CPU
times of both, and the time of each stage of the executor (``Execution.timings``).

The two kinds of run are interleaved and repeated, and the minimum of each is reported: on
a machine shared with other processes the minimum is the figure least disturbed by them (the
medians are printed alongside). Usage: ``python tools/bench_exec.py [--repeat 7]``
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import tempfile
import time
from pathlib import Path

import drivefuzz  # noqa: F401  (sets SUMO_HOME)
from drivefuzz.sim.execute import _sumo_args, execute
from drivefuzz.oracle import OracleSettings
from drivefuzz.scenario.roadmap import load_roadmap
from drivefuzz.scenario import Actor, Mission, Scenario, SimOptions
from drivefuzz.scenario.sumofiles import write_scenario

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


#: SUMO's other lane-change models, in place of drivefuzz's continuous one (``--lanechange.duration 3``)
LANE_CHANGE_MODELS = {"instant (SUMO's default)": ["--lanechange.duration", "0"],
                      "sublane (--lateral-resolution 0.8)": ["--lanechange.duration", "0", "--lateral-resolution", "0.8"]}


def _with(args: list[str], extra: list[str]) -> list[str]:
    """SUMO's command line ``args`` with the options in ``extra`` replacing (or added to) its own."""
    out = list(args)
    for k in range(0, len(extra), 2):
        if extra[k] in out:
            out[out.index(extra[k]) + 1] = extra[k + 1]
        else:
            out += extra[k:k + 2]
    return out


def sumo_alone(sc: Scenario, extra: list[str] = ()) -> float:
    import libsumo

    with tempfile.TemporaryDirectory() as d:
        write_scenario(sc, d)
        t0 = time.perf_counter()
        libsumo.start(_with(_sumo_args(sc, Path(d), sc.network_path(), gui=False), list(extra)))
        steps = int(round(sc.sim.time_limit / sc.sim.step_length))
        for _ in range(steps):
            libsumo.simulationStep()
            for vid in libsumo.vehicle.getIDList():  # the same reads the executor does, nothing more
                libsumo.vehicle.getPosition(vid)
        libsumo.close()
        return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=7, help="executions of each kind; the minimum is reported")
    args = ap.parse_args()
    sc = busy_scenario()
    oracles = OracleSettings().instantiate
    execute(sc, oracles=oracles(), stop_on_misbehavior=False)  # warm-up: imports, network cache, oracle indexes
    # interleaved, so that a burst of load from other processes hits both kinds alike; the minimum is the
    # figure least disturbed by them (no goal inside 60 s, no early stop: the full minute runs)
    full, alone, stages, full_cpu, alone_cpu = [], [], [], [], []
    models: dict[str, list[float]] = {k: [] for k in LANE_CHANGE_MODELS}
    for _ in range(args.repeat):
        for name, extra in LANE_CHANGE_MODELS.items():
            models[name].append(sumo_alone(sc, extra))
        c0 = time.process_time()
        ex = execute(sc, oracles=oracles(), stop_on_misbehavior=False)
        full_cpu.append(time.process_time() - c0)
        full.append(ex.wall_time)
        stages.append(ex.timings)
        c0 = time.process_time()
        alone.append(sumo_alone(sc))
        alone_cpu.append(time.process_time() - c0)
    f, a = min(full), min(alone)
    fc, ac = min(full_cpu), min(alone_cpu)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"scenario                    town, {sum(x.kind.value == 'vehicle' for x in sc.actors)} vehicles, "
          f"{sum(x.kind.value == 'pedestrian' for x in sc.actors)} pedestrians, {sc.sim.time_limit:.0f} s")
    print(f"frames per execution        {ex.trace.n_frames}  (termination: {ex.termination.value})")
    print(f"repetitions                 {args.repeat} of each (minimum reported; load average {load:.1f} "
          f"on {os.cpu_count()} cores)")
    print(f"full execution (wall)       {f:.3f} s   (median {statistics.median(full):.3f})")
    print(f"SUMO alone, same traffic    {a:.3f} s   (median {statistics.median(alone):.3f})")
    print(f"ratio                       {f / a:.2f}")
    print(f"executions per hour, 1 core {3600 / f:.0f}")
    print(f"CPU time (process): full {fc:.3f} s, SUMO alone {ac:.3f} s, ratio {fc / ac:.2f}  "
          "(less disturbed by other processes on a shared machine)")
    print("SUMO alone under other lane-change models (drivefuzz runs SUMO's continuous one, lanechange.duration 3):")
    for name, times in models.items():
        print(f"  {name:<36} {min(times):.3f} s  ({min(times) / a:.2f} x the continuous model)")
    print("per stage (minimum over runs):")
    for k in stages[0]:
        print(f"  {k:<10} {min(s[k] for s in stages):.3f} s")
    print(f"  {'rest':<10} {min(w - sum(t.values()) for w, t in zip(full, stages)):.3f} s"
          "  (the work folder removed, the result returned)")


if __name__ == "__main__":
    main()
