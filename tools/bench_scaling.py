"""Campaign throughput against the number of parallel jobs (issue 7's scaling figure).

    python tools/bench_scaling.py [--jobs 1,2] [--budget 60] [--network networks/town.net.xml]

For each job count N it runs the same campaign (the network's committed seeds,
the clean reference ADS, strategy ``all``, continuing after findings) for the
same wall-clock budget: N = 1 in this process (what ``drivefuzz fuzz`` does),
N > 1 on a local Dask cluster of N single-threaded workers (``--jobs N``). It
prints executions per hour and the efficiency, throughput / (N x the one-job
throughput). Cluster start-up is inside the budget, as a user would see it; the
executions-per-hour column also excludes it ("steady").
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivefuzz.campaign.fuzz import Campaign, FuzzConfig  # noqa: E402
from drivefuzz.scenario.seed import list_seeds  # noqa: E402
from drivefuzz.scenario.sumofiles import load_scenario  # noqa: E402


def run_point(jobs: int, seeds, budget: float, workdir: Path) -> dict[str, float]:
    cfg = FuzzConfig(cycles=1000, population=8, continue_after_finding=True, seed=1, budget_s=budget)
    out = workdir / f"jobs{jobs}"
    campaign = Campaign(out, seeds, cfg)
    first: list[float] = []
    campaign.on_progress = lambda p: first.append(time.monotonic()) if not first and p.execs else None
    t0 = time.monotonic()
    if jobs == 1:
        campaign.run()
    else:
        from drivefuzz.campaign.cluster import dask_client

        with dask_client("local", jobs=jobs) as client:
            campaign.run(client=client)
    wall = time.monotonic() - t0
    execs = campaign.progress.execs
    steady = wall - (first[0] - t0) if first else wall
    return {"execs": execs, "wall": wall, "per_hour": execs / wall * 3600,
            "steady_per_hour": max(execs - 1, 0) / max(steady, 1e-9) * 3600}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", default="1,2", help="comma-separated job counts [1,2]")
    ap.add_argument("--budget", type=float, default=60.0, help="wall seconds per point [60]")
    ap.add_argument("--network", default=str(ROOT / "networks" / "town.net.xml"))
    args = ap.parse_args()
    counts = [int(x) for x in args.jobs.split(",")]
    name = Path(args.network).name.split(".")[0]
    seeds = [load_scenario(p) for p in list_seeds(ROOT / "seeds" / name)]
    if len(seeds) < max(counts):
        sys.exit(f"need at least {max(counts)} seeds in seeds/{name}/, found {len(seeds)}")
    print(f"machine: {os.cpu_count()} cores; network {name}, {len(seeds)} seeds, {args.budget:.0f} s per point")
    workdir = Path(tempfile.mkdtemp(prefix="bench-scaling-"))
    rows = []
    try:
        for n in counts:
            r = run_point(n, seeds, args.budget, workdir)
            rows.append((n, r))
            print(f"  jobs={n}: {r['execs']} executions in {r['wall']:.1f} s", flush=True)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    base = next((r for n, r in rows if n == 1), None)
    print(f"\n{'jobs':>4} {'execs':>6} {'execs/hour':>11} {'steady/hour':>12} {'efficiency':>11}")
    for n, r in rows:
        eff = r["per_hour"] / (n * base["per_hour"]) if base else float("nan")
        print(f"{n:>4} {r['execs']:>6} {r['per_hour']:>11.0f} {r['steady_per_hour']:>12.0f} {eff:>11.2f}")


if __name__ == "__main__":
    main()
