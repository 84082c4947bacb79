"""Does the feedback help? Distinct misbehaviours at an equal budget, like the paper's figure f:feedback.

Configurations fuzz the same ADS from the same committed seeds with the same strategy and the same number
of executions, and differ only in how successors are chosen:

- ``risk``: the risk score (drivefuzz's default, :mod:`drivefuzz.search.risk`);
- ``paper``: DriveFuzz's driving-quality score (:mod:`drivefuzz.search.quality`);
- ``random``: a random mutant (the paper's baseline; the schedule then ignores the feedback too).

Each runs ``--reps`` times per network with campaign seeds 0..reps-1 (rep r uses seed r in every
configuration). A campaign spends its whole budget (``--max-execs``): a finding ends its lineage, not the
campaign. Every repetition runs in its own process (``--jobs`` at once). Reproduction reruns are off
(``reproduce=0``): they do not change what is counted, only the wall time; the counterfactual replay stays.

**Distinct misbehaviours** are counted by the finding's semantic signature (:mod:`drivefuzz.triage.signature`:
oracle, kind, the ego's manoeuvre, road element and right-of-way class, the other party and its approach,
contact side) and only those attributed to the ego (:mod:`drivefuzz.triage.attribute`); a repeated event
is one. Without the triage package it falls back to (oracle, kind, the other party's kind and navigation,
junction or edge). Crashes and hangs of the simulator are not misbehaviours.

Printed: per configuration and network the repetitions, mean and sd, then Mann-Whitney U's two-sided p and
Vargha-Delaney A12 of each feedback against ``random``, and the last line::

    distinct misbehaviours, feedback / random: X.XX (p = ...)

With ``--faults``, also the executions to the first finding of each hidden fault of the reference ADS
(faults that are silent on every committed seed), per configuration.

Usage::

    python tools/eval_feedback.py [--execs 600] [--reps 5] [--networks town,intersection] [--strategy all]
                                  [--configs risk,paper,random] [--jobs 2] [--faults] [--fault-execs 300]

Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from drivefuzz.campaign.compare import a12, mann_whitney_p  # noqa: E402

#: Faults of the reference ADS that no committed seed shows: only a situation the fuzzer builds reveals them.
HIDDEN_FAULTS = ("ignore_pedestrians", "late_braking", "no_fog_slowdown")


def _seeds(network: str):
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario

    return [read_scenario(p) for p in list_seeds(REPO / "seeds" / network)]


def _distinct_key(finding_dir: Path):
    """The finding's signature key and whether it counts (the ego's fault); the fallback without triage."""
    v = json.loads((finding_dir / "verdict.json").read_text())
    sig, att = v.get("signature"), v.get("attribution")
    if sig is not None:
        return sig["key"], (att or {}).get("fault", "ego") == "ego"
    m = v["misbehaviors"][0]
    return (m["oracle"], m["kind"], tuple(sorted(m.get("actors", ()))) and "other", m.get("details", {}).get(
        "element", "")), True


def run_one(network: str, feedback: str, rep: int, opts: dict) -> dict:
    """One campaign; returns its counts (runs in a worker process)."""
    from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
    from drivefuzz.scenario import AdsSpec
    from drivefuzz.sim.simhost import FAILURE_KINDS

    ads = AdsSpec(name="ego", options={"fault": opts["fault"]} if opts.get("fault") else {})
    cfg = FuzzConfig(cycles=opts["cycles"], population=opts["population"], strategy=opts["strategy"], seed=rep,
                     max_execs=opts["execs"], feedback=feedback, ads=ads, reproduce=0)
    with tempfile.TemporaryDirectory(prefix="eval-feedback-") as tmp:
        t0 = time.perf_counter()
        campaign = Campaign(Path(tmp) / "out", _seeds(network), cfg)
        findings = campaign.run()
        wall = time.perf_counter() - t0
        real = [f for f in findings if f.misbehavior.oracle not in FAILURE_KINDS]
        keys = {}
        for f in real:
            key, counts = _distinct_key(f.path)
            if counts:
                keys[key] = keys.get(key, 0) + 1
        first = None
        if real:
            import sqlite3

            db = sqlite3.connect(Path(tmp) / "out" / "index.sqlite")
            row = db.execute("SELECT MIN(exec_id) FROM executions WHERE finding IS NOT NULL "
                             "AND verdict NOT LIKE 'simulator-crash%' AND verdict NOT LIKE 'hang%'").fetchone()
            first = row[0]
    return {"network": network, "feedback": feedback, "rep": rep, "execs": campaign.progress.execs,
            "found": len(real), "distinct": len(keys), "first": first, "wall": wall, "fault": opts.get("fault"),
            "failures": len(findings) - len(real)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--execs", type=int, default=600, help="executions per campaign [600]")
    ap.add_argument("--reps", type=int, default=5, help="repetitions per configuration and network [5]")
    ap.add_argument("--networks", default="town,intersection", help="committed seed sets [town,intersection]")
    ap.add_argument("--strategy", default="all", help="mutation strategy [all]")
    ap.add_argument("--configs", default="risk,paper,random", help="feedbacks to compare [risk,paper,random]")
    ap.add_argument("--population", type=int, default=8, help="mutants per cycle [8]")
    ap.add_argument("--cycles", type=int, default=10, help="cycles of a lineage at most [10]")
    ap.add_argument("--jobs", type=int, default=2, help="campaigns at once, in separate processes [2]")
    ap.add_argument("--faults", action="store_true", help="also: executions to the first finding of hidden faults")
    ap.add_argument("--fault-execs", type=int, default=300, help="budget of a fault campaign [300]")
    ap.add_argument("--fault-reps", type=int, default=3, help="repetitions of a fault campaign [3]")
    args = ap.parse_args(argv)
    if args.reps < 1 or args.execs < 1:
        ap.error("--reps and --execs must be at least 1")
    networks = [n.strip() for n in args.networks.split(",") if n.strip()]
    configs = [c.strip() for c in args.configs.split(",") if c.strip()]
    opts = {"execs": args.execs, "population": args.population, "strategy": args.strategy, "cycles": args.cycles}
    work = [(net, fb, rep, opts) for net in networks for rep in range(args.reps) for fb in configs]
    if args.faults:
        fopts = [dict(opts, execs=args.fault_execs, fault=f) for f in HIDDEN_FAULTS]
        work += [("town", fb, rep, fo) for fo in fopts for rep in range(args.fault_reps) for fb in configs]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max(args.jobs, 1)) as pool:
        results = list(pool.map(run_one, *zip(*work)))
    wall = time.perf_counter() - t0

    main_runs = [r for r in results if r["fault"] is None]
    print(f"clean reference ADS, strategy {args.strategy}, {args.execs} executions per campaign "
          f"(population {args.population}, lineages of at most {args.cycles} cycles), {args.reps} repetitions")
    print(f"{'network':<14}{'feedback':<9}" + "".join(f"{'rep' + str(r):>6}" for r in range(args.reps))
          + f"{'mean':>8}{'sd':>6}{'found':>7}")
    per_config: dict[str, list[float]] = {c: [] for c in configs}
    for net in networks:
        for fb in configs:
            rows = sorted((r for r in main_runs if r["network"] == net and r["feedback"] == fb), key=lambda r: r["rep"])
            d = [r["distinct"] for r in rows]
            per_config[fb].extend(d)
            sd = statistics.stdev(d) if len(d) > 1 else 0.0
            print(f"{net:<14}{fb:<9}" + "".join(f"{x:>6}" for x in d) + f"{statistics.mean(d):>8.2f}{sd:>6.2f}"
                  f"{statistics.mean(r['found'] for r in rows):>7.1f}")
    print("\ndistinct misbehaviours per campaign, all networks (each feedback against random):")
    base = per_config.get("random")
    ratio_line = ""
    for fb in configs:
        x = per_config[fb]
        line = f"  {fb:<8} mean {statistics.mean(x):6.2f}  sd {statistics.stdev(x) if len(x) > 1 else 0.0:5.2f}"
        if base is not None and fb != "random":
            p, a = mann_whitney_p(x, base), a12(x, base)
            ratio = statistics.mean(x) / statistics.mean(base) if statistics.mean(base) else math.inf
            line += f"  ratio {ratio:5.2f}  Mann-Whitney p {p:.4f}  A12 {a:.2f}"
            if fb == configs[0]:
                ratio_line = f"distinct misbehaviours, feedback / random: {ratio:.2f} (p = {p:.4f}, A12 = {a:.2f})"
        print(line)
    if args.faults:
        print(f"\nexecutions to the first finding of each hidden fault (town, {args.fault_execs} executions, "
              f"{args.fault_reps} repetitions; '-' = not found):")
        print(f"{'fault':<22}" + "".join(f"{c:>24}" for c in configs))
        for f in HIDDEN_FAULTS:
            cells = []
            for fb in configs:
                rows = sorted((r for r in results if r["fault"] == f and r["feedback"] == fb), key=lambda r: r["rep"])
                cells.append(",".join("-" if r["first"] is None else str(r["first"]) for r in rows))
            print(f"{f:<22}" + "".join(f"{c:>24}" for c in cells))
    print(f"\nwall clock: {wall:.0f} s for {sum(r['execs'] for r in results)} executions")
    if ratio_line:
        print(ratio_line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
