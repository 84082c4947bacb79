"""Drive committed seeds with a CommonRoad planner plugin and print how many drive clean.

The figure issue 32 asks for (and docs/bugs/commonroad-reactive-planner.md lists): every committed seed
(``seeds/*/*/``) run once with ``--ads`` (default ``commonroad-reactive``) and the default oracles; a seed is
clean when it ends at its goal without a misbehaviour. Per seed it prints the outcome, the misbehaviours,
the planner cycles (plan / none / raised) from the trace's ``ads_info``, the wall time and where the planner's
time went (``plan_s``: in the subclass's ``plan()``; ``rest_s``: of it, in cycles that began at rest;
``rest_held_s``: of those, in cycles where standing was what the adapter wanted); at the end
``clean N of M``. ``--traces DIR`` keeps each seed's trace (DIR/<network>_<seed>/) for reading. One process, one seed at a time (the planner costs about 100x the reference ADS: the
44 seeds take 15-30 minutes).

    python tools/commonroad_seeds.py [--ads NAME] [--ads-option k=v ...] [--jsonl OUT] [--traces DIR] [SEED ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seeds", nargs="*", help="seed folders (default: every seeds/*/*/)")
    ap.add_argument("--ads", default="commonroad-reactive")
    ap.add_argument("--ads-option", action="append", default=[], metavar="K=V")
    ap.add_argument("--jsonl", help="append one JSON line per seed here")
    ap.add_argument("--traces", help="keep each seed's trace in this folder")
    args = ap.parse_args(argv)

    from drivefuzz.ads import load_ads
    from drivefuzz.oracle import OracleSettings
    from drivefuzz.scenario.sumofiles import load_scenario
    from drivefuzz.sim.execute import execute

    options = {}
    for kv in args.ads_option:
        k, _, v = kv.partition("=")
        try:
            options[k] = json.loads(v)
        except json.JSONDecodeError:
            options[k] = v
    seeds = [Path(s) for s in args.seeds] or sorted(p.parent for p in ROOT.glob("seeds/*/*/scenario.json"))
    clean = 0
    for seed in seeds:
        sc = load_scenario(seed)
        ads = load_ads(args.ads, options)
        spent = _time_plans(ads)
        t0 = time.perf_counter()
        ex = execute(sc, ads=ads, oracles=OracleSettings().instantiate())
        wall = time.perf_counter() - t0
        if args.traces:
            ex.trace.save(Path(args.traces) / f"{seed.parent.name}_{seed.name}")
        info = ex.trace.meta.get("ads_info", {})
        cycles = info.get("cycles", {})
        first_bad = next(((t, o, e) for t, o, e in zip(cycles.get("t", []), cycles.get("outcome", []),
                                                       cycles.get("error", [])) if o != "plan"), None)
        ok = ex.termination.value == "goal_reached" and not ex.misbehaviors
        clean += ok
        row = {"seed": str(seed.relative_to(ROOT)) if seed.is_absolute() else str(seed), "clean": ok,
               "termination": ex.termination.value,
               "misbehaviors": [f"{m.oracle}/{m.kind}@{m.time:.1f}" for m in ex.misbehaviors],
               "counts": info.get("counts"), "first_not_plan": first_bad,
               "shim_caught": info.get("domain_shim_caught"), "sim_s": round(float(ex.trace["t"][-1]), 2),
               "wall_s": round(wall, 1), **{k: round(v, 1) for k, v in spent.items()},
               "denser_levels_asked": info.get("denser_levels_asked")}
        print(json.dumps(row), flush=True)
        if args.jsonl:
            with open(args.jsonl, "a") as fh:
                fh.write(json.dumps(row) + "\n")
    print(f"clean {clean} of {len(seeds)} ({args.ads} {options or ''})")
    return 0


def _time_plans(ads) -> dict[str, float]:
    """Wrap ``ads.plan`` to add up its wall time [s]: all cycles, those from rest, those from rest where
    standing was wanted (the dict is filled as the execution runs)."""
    spent = {"plan_s": 0.0, "rest_s": 0.0, "rest_held_s": 0.0}
    inner = ads.plan

    def timed(state, checker, desired_speed):
        t0 = time.perf_counter()
        try:
            return inner(state, checker, desired_speed)
        finally:
            dt = time.perf_counter() - t0
            spent["plan_s"] += dt
            if state.speed <= 0.05:
                spent["rest_s"] += dt
                spent["rest_held_s"] += dt if getattr(ads, "standing_wanted", False) else 0.0

    ads.plan = timed
    return spent


if __name__ == "__main__":
    sys.exit(main())
