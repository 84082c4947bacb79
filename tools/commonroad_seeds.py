"""Drive committed seeds with a CommonRoad planner plugin and print how many drive clean.

The figure issue 32 asks for (and docs/bugs/commonroad-reactive-planner.md lists): every committed seed
(``seeds/*/*/``) run once with ``--ads`` (default ``commonroad-reactive``) and the default oracles; a seed is
clean when it ends at its goal without a misbehaviour. Per seed it prints the outcome, the misbehaviours,
the planner cycles (plan / none / raised) from the trace's ``ads_info`` and the wall time; at the end
``clean N of M``. One process, one seed at a time (the planner costs about 100x the reference ADS: the
44 seeds take 15-30 minutes).

    python tools/commonroad_seeds.py [--ads NAME] [--ads-option k=v ...] [--jsonl OUT] [SEED ...]
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
        t0 = time.perf_counter()
        ex = execute(sc, ads=load_ads(args.ads, options), oracles=OracleSettings().instantiate())
        wall = time.perf_counter() - t0
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
               "wall_s": round(wall, 1)}
        print(json.dumps(row), flush=True)
        if args.jsonl:
            with open(args.jsonl, "a") as fh:
                fh.write(json.dumps(row) + "\n")
    print(f"clean {clean} of {len(seeds)} ({args.ads} {options or ''})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
