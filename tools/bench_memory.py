"""Memory of a long-lived worker: RSS growth over many executions (issue 16: at most 20 MB over 2,000).

A campaign's worker keeps one simulation host (a child process that runs every execution: SUMO through
libsumo, the ADS, the physics, the oracles) for its whole life, so a leak there grows with the campaign.
This runs ``--execs`` executions of mutated town scenarios (the seeds, each with 0-4 actors and a puddle
added by the ``all`` strategy, cycling) through one :class:`~drivefuzz.sim.simhost.SimHost`, and prints
the RSS of the host child and of this (the worker's) process after a warm-up and every ``--every``
executions, then the growth from the warm-up to the end.

Usage: ``python tools/bench_memory.py [--execs 2000] [--warmup 50] [--every 250] [--network town]``.
Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def rss_mb(pid: int | str = "self") -> float:
    """[MB] resident set size of a process (Linux /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def scenarios(network: str, n: int, rng: random.Random):
    """``n`` mutants of the network's committed seeds (0-4 components each), built once up front."""
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import load_scenario
    from drivefuzz.search.mutate import Mutator

    seeds = [load_scenario(p) for p in list_seeds(REPO / "seeds" / network)]
    mut = Mutator(load_roadmap(seeds[0].network_path()))
    pool = []
    for k in range(min(n, 200)):  # a pool of 200 distinct scenarios, cycled
        sc = seeds[k % len(seeds)]
        for _ in range(rng.randrange(5)):
            sc = mut.generate(sc, "all", rng).scenario
        pool.append(sc)
    return [pool[k % len(pool)] for k in range(n)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--execs", type=int, default=2000)
    ap.add_argument("--warmup", type=int, default=50, help="executions before the baseline is taken [50]")
    ap.add_argument("--every", type=int, default=250, help="print the RSS every N executions [250]")
    ap.add_argument("--network", default="town")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    from drivefuzz.oracle import OracleSettings
    from drivefuzz.sim.simhost import SimHost

    work = scenarios(args.network, args.warmup + args.execs, random.Random(args.seed))
    settings = OracleSettings().settings
    t0 = time.perf_counter()
    statuses: dict[str, int] = {}
    with SimHost() as host:
        base = None
        print(f"{'executions':>10} {'host RSS [MB]':>14} {'worker RSS [MB]':>16}")
        for k, sc in enumerate(work, start=1):
            out = host.execute(sc, settings)
            statuses[out.status] = statuses.get(out.status, 0) + 1
            done = k - args.warmup
            if done == 0:
                base = (rss_mb(host.proc.pid), rss_mb())
                print(f"{'warm-up':>10} {base[0]:>14.1f} {base[1]:>16.1f}")
            elif done > 0 and (done % args.every == 0 or done == args.execs):
                print(f"{done:>10} {rss_mb(host.proc.pid):>14.1f} {rss_mb():>16.1f}", flush=True)
        end = (rss_mb(host.proc.pid), rss_mb())
        restarts = host.starts - 1
    wall = time.perf_counter() - t0
    print(f"executions: {args.execs} after {args.warmup} of warm-up, {wall:.0f} s; outcomes {statuses}; "
          f"host restarts {restarts}")
    print(f"RSS growth over {args.execs} executions: host {end[0] - base[0]:+.1f} MB, worker {end[1] - base[1]:+.1f} MB "
          f"(goal: at most 20 MB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
