"""Does the driving-quality feedback help? Like the paper's feedback-effectiveness figure (f:feedback).

Two configurations fuzz the clean reference ADS (no fault switched on, so every finding is a real
weakness of it) from the same seed scenarios, with the same execution budget and the same
strategy: with the feedback (the lowest driving-quality score becomes the next scenario) and
without it (``feedback=False``: a random mutant does, the paper's baseline). Each runs ``--reps``
times with different campaign seeds (rep r uses campaign seed r in both configurations), and goes
on after a finding (``continue_after_finding``), as the paper's six-hour runs did.

Printed per repetition and as a mean: misbehaviours found (executions on which an oracle fired)
and distinct misbehaviours (``Misbehavior.signature()``: oracle, kind, actors involved and the
place on a 10 m grid). Crashes and hangs of the simulator are counted apart, not as misbehaviours.
The paper saw 19 (feedback) versus 10 (none) misbehaviours, on average over 3 runs of 6 hours.

Usage::

    python tools/eval_feedback.py [--execs 48] [--reps 3] [--strategy all] [--seeds 001,005]
                                  [--population 4] [--jobs 1]

Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def run_one(seed_names: list[str], feedback: bool, rep: int, args: dict) -> dict:
    """One campaign; returns its counts (runs in a worker process with --jobs > 1)."""
    from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
    from drivefuzz.sim.simhost import FAILURE_KINDS
    from drivefuzz.scenario.sumofiles import read_scenario

    seeds = [read_scenario(REPO / "seeds" / "town" / name) for name in seed_names]
    cycles = -(-args["execs"] // (len(seeds) * args["population"]))  # every seed gets its share
    cfg = FuzzConfig(cycles=cycles, population=args["population"], strategy=args["strategy"], seed=rep,
                     max_execs=args["execs"], feedback=feedback, continue_after_finding=True)
    with tempfile.TemporaryDirectory(prefix="eval-feedback-") as tmp:
        t0 = time.perf_counter()
        campaign = Campaign(Path(tmp) / "out", seeds, cfg)
        findings = campaign.run()
        wall = time.perf_counter() - t0
        execs = campaign.progress.execs
    real = [f.misbehavior for f in findings if f.misbehavior.oracle not in FAILURE_KINDS]
    kinds: dict[str, int] = {}
    for m in real:
        kinds[f"{m.oracle}/{m.kind}"] = kinds.get(f"{m.oracle}/{m.kind}", 0) + 1
    return {"feedback": feedback, "rep": rep, "execs": execs, "found": len(real),
            "distinct": len({m.signature() for m in real}), "failures": len(findings) - len(real),
            "kinds": kinds, "wall": wall}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--execs", type=int, default=48, help="executions per campaign [48]")
    ap.add_argument("--reps", type=int, default=3, help="repetitions per configuration [3]")
    ap.add_argument("--strategy", default="all", help="mutation strategy [all]")
    ap.add_argument("--seeds", default="001,005", help="town seed folders, comma-separated [001,005]")
    ap.add_argument("--population", type=int, default=4, help="mutants per cycle [4]")
    ap.add_argument("--jobs", type=int, default=1, help="campaigns at once, in separate processes [1]")
    args = ap.parse_args(argv)
    if args.reps < 1 or args.execs < 1:
        ap.error("--reps and --execs must be at least 1")
    seed_names = [s.strip() for s in args.seeds.split(",") if s.strip()]
    opts = {"execs": args.execs, "population": args.population, "strategy": args.strategy}
    work = [(seed_names, fb, rep, opts) for rep in range(args.reps) for fb in (True, False)]
    t0 = time.perf_counter()
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as pool:
            results = list(pool.map(run_one, *zip(*work)))
    else:
        results = [run_one(*w) for w in work]
    wall = time.perf_counter() - t0

    print(f"clean reference ADS, town seeds {','.join(seed_names)}, strategy {args.strategy}, "
          f"{args.execs} executions per campaign (population {args.population}), continue after finding")
    print(f"{'configuration':<14}{'rep':>4}{'execs':>7}{'found':>7}{'distinct':>10}{'crashes':>9}  oracles")
    for fb in (True, False):
        name = "feedback" if fb else "no feedback"
        rows = [r for r in results if r["feedback"] is fb]
        for r in rows:
            kinds = ", ".join(f"{k} {v}" for k, v in sorted(r["kinds"].items())) or "-"
            print(f"{name:<14}{r['rep']:>4}{r['execs']:>7}{r['found']:>7}{r['distinct']:>10}{r['failures']:>9}  {kinds}")
        found = [r["found"] for r in rows]
        distinct = [r["distinct"] for r in rows]
        sd = (lambda xs: statistics.stdev(xs) if len(xs) > 1 else 0.0)
        print(f"{name + ' mean':<18}{statistics.mean(r['execs'] for r in rows):>7.0f}{statistics.mean(found):>7.1f}"
              f"{statistics.mean(distinct):>10.1f}   (sd {sd(found):.1f} / {sd(distinct):.1f})")
    fb_mean = statistics.mean(r["distinct"] for r in results if r["feedback"])
    nf_mean = statistics.mean(r["distinct"] for r in results if not r["feedback"])
    if nf_mean:
        print(f"distinct misbehaviours, feedback vs none: {fb_mean:.1f} vs {nf_mean:.1f} "
              f"({100 * (fb_mean - nf_mean) / nf_mean:+.0f} %); the paper: 19 vs 10 (+90 %)")
    print(f"wall clock: {wall:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
