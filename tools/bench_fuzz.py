"""Where a fuzzing campaign's time goes, like the paper's fuzzing-overhead figure (f:perf).

Runs a short campaign on the bundled town seeds (real SUMO, the reference ADS or ``--ads``), then reads the
per-execution ``timings`` column of the campaign's ``index.sqlite`` and prints, per stage, the
total time, the mean per execution and the share of the campaign's wall-clock time; then the
executions per hour and drivefuzz's own share of the time.

Stages (keys of the ``timings`` column):

    sumo        SUMO: starting it and stepping it (incl. the per-step actor commands)
    physics     drivefuzz's vehicle model, and placing the ego in SUMO (moveToXY)
    ads         the ADS under test (ADS.step)
    observe     building the ADS's observation
    world       reading the world from SUMO each step
    record      recording the trace
    oracles     the misbehaviour oracles
    setup       writing and validating the SUMO files, ADS reset, first step bookkeeping
    quality     the feedback: risk score and driving-quality score
    triage      attribution, signature, and for a new signature the counterfactual replay and the
                reproduction reruns (whole executions of their own, counted here, not as executions)
    mutation    generate + mutate, with their retries
    storage     journal, index, corpus and finding directories
    isolation   handing the execution to the simulation-host child process and back
    (other)     campaign wall time not in any execution's timings (start-up, scheduling)

The paper's figure: 150 s per execution, 94 % of it in the simulator, 6 % in DriveFuzz itself.

Usage::

    python tools/bench_fuzz.py [--execs 60] [--strategy all] [--seed 0] [--seeds 4] [--population 4] [--out DIR]
                               [--reproduce 5] [--shrink N]
                               [--ads NAME [--ads-option K=V]]   (e.g. --ads commonroad-reactive)

Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sqlite3
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

STAGES = [
    ("sumo", "SUMO start + stepping"),
    ("physics", "physics (+ moveToXY)"),
    ("ads", "ADS under test"),
    ("observe", "ADS observation"),
    ("world", "world read-out"),
    ("record", "trace recording"),
    ("oracles", "oracles"),
    ("setup", "execution setup"),
    ("quality", "feedback (risk + quality)"),
    ("triage", "triage (+ its reruns)"),
    ("mutation", "mutation (+ retries)"),
    ("storage", "storage"),
    ("isolation", "crash isolation (IPC)"),
]
#: The paper's white boxes: what drivefuzz adds to simulating and driving (not SUMO, not the ADS).
DRIVEFUZZ_ONLY = ("observe", "world", "record", "oracles", "setup", "quality", "mutation", "storage", "isolation",
                  "triage")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--execs", type=int, default=60, help="executions to run [60]")
    ap.add_argument("--strategy", default="all", help="mutation strategy [all]")
    ap.add_argument("--seed", type=int, default=0, help="campaign RNG seed [0]")
    ap.add_argument("--seeds", type=int, default=4, help="how many town seeds to fuzz [4]")
    ap.add_argument("--population", type=int, default=4)
    ap.add_argument("--reproduce", type=int, default=5, help="reruns of each new signature [5]")
    ap.add_argument("--shrink", type=int, help="shrink budget of each new finding (fuzz --shrink) [the campaign's: 10]")
    ap.add_argument("--out", type=Path, help="keep the campaign directory here (default: a temporary one)")
    ap.add_argument("--ads", default="ego", help="the ADS under test [ego]; e.g. commonroad-reactive (its extra)")
    ap.add_argument("--ads-option", action="append", default=[], metavar="K=V", help="an option of that ADS")
    args = ap.parse_args(argv)

    from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
    from drivefuzz.cli.common import parse_kv
    from drivefuzz.scenario.model import AdsSpec
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario

    seeds = [read_scenario(p) for p in list_seeds(REPO / "seeds" / "town")[: args.seeds]]
    # spread the executions over the seeds: each seed's job gets about the same share
    cycles = -(-args.execs // (len(seeds) * args.population))
    cfg = FuzzConfig(cycles=cycles, population=args.population, strategy=args.strategy, seed=args.seed,
                     max_execs=args.execs, continue_after_finding=True, reproduce=args.reproduce,
                     ads=AdsSpec(name=args.ads, options=parse_kv(args.ads_option, "--ads-option")),
                     **({} if args.shrink is None else {"shrink": args.shrink}))
    tmp = None
    out = args.out
    if out is None:
        tmp = tempfile.mkdtemp(prefix="bench-fuzz-")
        out = Path(tmp) / "out"
    try:
        t0 = time.perf_counter()
        Campaign(out, seeds, cfg).run()
        total = time.perf_counter() - t0
        report(out / "index.sqlite", total, args, cfg)
        triage_cost(out, seeds[0].sim.step_length)
    finally:
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


def report(index: Path, total: float, args, cfg) -> None:
    db = sqlite3.connect(index)
    cols = {r[1] for r in db.execute("PRAGMA table_info(executions)")}
    if "timings" not in cols:
        sys.exit(f"{index}: the executions table has no 'timings' column (columns: {sorted(cols)})")
    rows = db.execute("SELECT timings, retries, frames, verdict FROM executions").fetchall()
    n = len(rows)
    if not n:
        sys.exit("no executions recorded")
    sums: dict[str, float] = {}
    for timings, *_ in rows:
        for k, v in json.loads(timings or "{}").items():
            sums[k] = sums.get(k, 0.0) + float(v)
    known = {k for k, _ in STAGES}
    unknown = set(sums) - known
    frames = sum(r[2] or 0 for r in rows)
    retries = [r[1] or 0 for r in rows]
    findings = sum(1 for r in rows if r[3] != "pass")

    print(f"campaign: {n} executions of ADS {cfg.ads.name} on {min(args.seeds, 40)} town seed(s), strategy {cfg.strategy}, "
          f"seed {cfg.seed}, {cfg.cycles} cycles x {cfg.population}, continue after finding; "
          f"{findings} execution(s) with a finding")
    print(f"simulated: {frames} frames ({frames * 0.05:.0f} s at 50 ms), {frames / n:.0f} frames per execution")
    print()
    print(f"{'stage':<26}{'total [s]':>10}{'per exec [ms]':>15}{'share':>8}")
    accounted = 0.0
    for key, label in STAGES + [(k, k) for k in sorted(unknown)]:
        v = sums.get(key, 0.0)
        accounted += v
        print(f"{label:<26}{v:>10.2f}{1000 * v / n:>15.1f}{100 * v / total:>7.1f}%")
    other = max(total - accounted, 0.0)
    print(f"{'(other: start-up, loop)':<26}{other:>10.2f}{1000 * other / n:>15.1f}{100 * other / total:>7.1f}%")
    print(f"{'total (wall clock)':<26}{total:>10.2f}{1000 * total / n:>15.1f}{100.0:>7.1f}%")
    print()
    sumo = sums.get("sumo", 0.0)
    own = total - sumo
    dfz = sum(sums.get(k, 0.0) for k in DRIVEFUZZ_ONLY) + other
    print(f"executions per hour: {3600 * n / total:,.0f}   ({total / n:.3f} s per execution; the paper: 150 s)")
    # triage's cost follows what the campaign found (each new signature is replayed), not the per-execution
    # pipeline: two versions whose mutants meet different bugs differ here even at equal per-execution cost
    untriaged = total - sums.get("triage", 0.0)
    print(f"  without triage: {3600 * n / untriaged:,.0f}   (the pipeline alone; triage {sums.get('triage', 0.0):.2f} s, "
          f"{findings} execution(s) with a finding)")
    print(f"mutation retries per execution: mean {sum(retries) / n:.1f}, max {max(retries)}")
    print(f"outside SUMO stepping (physics, ADS and drivefuzz): {100 * own / total:.1f} % of the time")
    print(f"drivefuzz's own share (not SUMO, not the ADS, not the physics): {100 * dfz / total:.1f} %  "
          f"(the paper: 6 %)")


def triage_cost(out: Path, step: float) -> None:
    """What triage cost per new signature, in executions' worth (the goal: at most 15), and in what: the runs of
    the careful driver and the reproduction, the shrink's, and the frames they simulated (``step``: the seeds'
    simulation step [s])."""
    recs = []
    for path in sorted((out / "jobs").glob("*/journal.jsonl")):
        recs += [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    recs = [r for r in recs if r.get("event") == "end"]
    plain = [r["wall_time"] for r in recs if r.get("wall_time") and not r.get("signature")]
    new = [r for r in recs if r.get("triage_execs")]
    hits = [r for r in recs if r.get("signature") and not r.get("triage_execs")]
    if not new or not plain:
        print("triage: no new signature in this campaign")
        return
    mean_exec = sum(plain) / len(plain)
    t_new = [r["timings"].get("triage", 0.0) for r in new]
    t_hit = [r["timings"].get("triage", 0.0) for r in hits] or [0.0]
    # a record's runs and simulated seconds count its execution and every triage rerun, the shrink's included
    reruns = sum(r.get("runs", 1 + r["triage_execs"]) - 1 for r in new)
    replays = sum(r["triage_execs"] for r in new)
    extra = [round(r.get("sim_s", 0.0) / step) - (r.get("frames") or 0) for r in new]  # frames triage simulated
    frames = sum(extra)
    print(f"triage: {len(new)} new signature(s), {reruns} reruns ({reruns / len(new):.1f} each: {replays} careful "
          f"driver and reproduction, {reruns - replays} shrink), {frames:,} frames; per new signature "
          f"{sum(t_new) / len(new):.2f} s = {sum(t_new) / len(new) / mean_exec:.1f} executions' worth (mean execution "
          f"{mean_exec:.3f} s); a repeat of a known signature {1000 * sum(t_hit) / len(t_hit):.1f} ms")
    for r, n in zip(new, extra):
        print(f"  {r['signature']} {r.get('verdict', '?'):<28} {r.get('runs', 1) - 1:>3} reruns "
              f"{n:>7,} frames {r['timings'].get('triage', 0.0):6.2f} s")


if __name__ == "__main__":
    sys.exit(main())
