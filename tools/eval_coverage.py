"""Does coverage steer the search? The share of reachable interaction-coverage cells reached at equal budgets.

Per network, campaigns fuzz the clean reference ADS from the committed seeds with the same strategy and the
same number of executions, and differ only in what the feedback does:

- ``risk``: the default search (risk score, situation weight, the bonus for cells the job had not reached,
  and the mutator aimed at those cells: drivefuzz.search.aim);
- ``random``: a random mutant, the schedule ignoring the feedback and nothing aimed (``--feedback random``).

Each runs ``--reps`` times with campaign seeds 0..reps-1 (``--first-rep`` K: K..K+reps-1; rep r uses seed r in
both). Coverage is summed from the campaign's journals (:func:`drivefuzz.triage.coverage.campaign_coverage`)
over the cells its network and seeds offer (:func:`drivefuzz.triage.coverage.reachable`). Reproduction reruns
and shrinking are off: they do not change coverage, only the wall time.

Printed: per network the reachable cells, per configuration the share reached in each repetition, its mean,
and Mann-Whitney U's two-sided p of ``risk`` against ``random``, then the union over the repetitions and how many
cells every, some and none of them reached (``--missed`` lists the last two with their aimed executions); with
``--faults``, the executions to the first finding of each hidden fault of the reference ADS on its network
(``-``: not found), how many campaigns found it, and the distinct finding signatures per campaign. A finding
is the fault's only when its scenario, run again with the clean reference ADS, does not show the same
misbehaviour (the clean ADS has findings of its own: a car stopped for good behind an obstacle, say); every
execution with a finding is judged, and in brackets, where it differs, the first finding of each signature only
(:func:`_fault_finding`).
``--configs`` may add the other guided feedbacks (``coverage``, ``product``: the value that picks successors,
drivefuzz.search.schedule); each is compared with ``random``. The last lines::

    coverage, default / random: X.XX (p = ...)

Usage::

    python tools/eval_coverage.py [--execs 1000] [--reps 5] [--networks town,...] [--jobs 2]
                                  [--configs risk,random,coverage,product] [--dump results.json]
                                  [--faults [--fault-execs N] [--fault-list f1,f2] [--stop-at-first] [--no-clean]]
                                  [--missed]
    python tools/eval_coverage.py --from-dump results.json [--missed]   # the tables again, nothing run

Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from drivefuzz.campaign.compare import mann_whitney_p  # noqa: E402

NETWORKS = ("highway", "interchange", "intersection", "roundabout", "town")
#: Faults of the reference ADS that no committed seed shows (tools/eval_feedback.py, issue 31's three, and
#: issue 33's three that each bite in one kind of encounter), with the network each is measured on (town,
#: unless its encounter needs more speed than town's 50 km/h streets give: no_fog_slowdown bites only where the
#: sensors see less than the stopping distance, never on a town street, tests/test_fog_fault.py).
HIDDEN_FAULTS = ("ignore_pedestrians", "late_braking", "no_fog_slowdown", "no_walker_prediction", "short_headway",
                 "narrow_corridor", "right_walker_blind", "crossing_left_blind", "low_sun_blind")
FAULT_NETWORK = {"low_sun_blind": "highway", "no_fog_slowdown": "highway"}


def _seeds(network: str):
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario

    return [read_scenario(p) for p in list_seeds(REPO / "seeds" / network)]


def run_one(network: str, feedback: str, rep: int, opts: dict) -> dict:
    """One campaign; its coverage and first finding (runs in a worker process)."""
    from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
    from drivefuzz.scenario import AdsSpec
    from drivefuzz.triage.coverage import campaign_coverage

    ads = AdsSpec(name="ego", options={"fault": opts["fault"]} if opts.get("fault") else {})
    cfg = FuzzConfig(population=opts["population"], strategy=opts["strategy"], seed=rep, max_execs=opts["execs"],
                     feedback=feedback, ads=ads, reproduce=0, shrink=0)
    judged: dict[str, bool] = {}  # execution key -> the fault's own (the clean ADS does not fail there)

    class FirstFinding(Campaign):
        """A campaign that ends at the fault's first finding (``--stop-at-first``: only the time to it counts)."""

        judged_hits = 0  # executions with a finding when the findings were last judged

        def out_of_budget(self) -> bool:
            hits = sum(f.hits for f in self.findings)
            if hits > self.judged_hits and _fault_finding(self.out, judged)[0] is not None:
                self.stop_reason = self.stop_reason or "the fault's first finding"
                return True
            self.judged_hits = hits
            return super().out_of_budget()

    with tempfile.TemporaryDirectory(prefix="eval-coverage-") as tmp:
        t0 = time.perf_counter()
        kind = FirstFinding if opts.get("fault") and opts.get("stop_at_first") else Campaign
        campaign = kind(Path(tmp) / "out", _seeds(network), cfg)
        campaign.run()
        wall = time.perf_counter() - t0
        cov = campaign_coverage(Path(tmp) / "out", write=False)
        first, first_of_signature, signatures = (_fault_finding(Path(tmp) / "out", judged, every=True)
                                                 if opts.get("fault") else (None, None, 0))
    return {"network": network, "feedback": feedback, "rep": rep, "fault": opts.get("fault"),
            "execs": campaign.progress.execs, "reachable": cov["reachable"], "reached": cov["reached"],
            "share": cov["share"], "first": first, "first_of_signature": first_of_signature, "signatures": signatures,
            "wall": wall,
            "cells": sorted(c for c, h in cov["cells"].items() if h["count"]),
            "aimed": {c: h["aimed"] for c, h in cov["cells"].items() if h.get("aimed")},
            "outside": sorted(cov.get("outside") or ())}


def _fault_finding(out: Path, judged: dict[str, bool], every: bool = False) -> tuple[int | None, int | None, int]:
    """When the campaign in ``out`` found the fault: (the execution number of its first finding that is the
    fault's own, the same counting only each signature's first finding, the fault's own signatures).

    A finding is the fault's own when its scenario, run again with the clean reference ADS, does not show the
    same misbehaviour (the clean ADS has findings of its own: a car stopped for good behind an obstacle, say).
    A signature abstracts the situation, so one finding record can hold executions of both causes (on town
    the clean ADS, too, fails to yield to a car from the left at B0 in some scenarios): the first number judges
    every execution with a finding (the record lists them all, each replayable), the second only the first of
    each signature (the one the findings list shows), which misses the fault wherever the clean ADS's own
    failure came first. ``judged`` caches the verdict per execution key (one replay each). Without ``every``
    the judging stops at the first own finding (the signature count is then a lower bound)."""
    import json as _json
    import sqlite3

    from drivefuzz.oracle import OracleSettings
    from drivefuzz.scenario import AdsSpec
    from drivefuzz.scenario.sumofiles import load_scenario
    from drivefuzz.sim.execute import execute

    db = sqlite3.connect(out / "index.sqlite")
    rows = db.execute("SELECT exec_id, key, signature, verdict FROM executions WHERE finding IS NOT NULL AND "
                      "verdict NOT LIKE 'simulator-crash%' AND verdict NOT LIKE 'hang%' ORDER BY exec_id").fetchall()
    db.close()
    refs: dict[str, str] | None = None
    first = first_of_signature = None
    own: set[str] = set()  # signatures whose first finding is the fault's own
    seen: set[str] = set()
    for exec_id, key, signature, verdict in rows:
        representative = signature not in seen
        seen.add(signature)
        if first is not None and not (every and representative):
            continue
        if key not in judged:
            if refs is None:  # the scenario of every hit is kept (a corpus folder named in the journal)
                refs = {}
                for path in (out / "jobs").glob("*/journal.jsonl"):
                    for line in path.read_text().splitlines():
                        try:
                            rec = _json.loads(line)
                        except ValueError:
                            continue
                        if rec.get("event") == "end" and rec.get("scenario"):
                            refs[rec["key"]] = rec["scenario"]
            if key not in refs:
                continue
            sc = load_scenario(out / refs[key]).model_copy(update={"ads": AdsSpec(name="ego")})
            clean = execute(sc, oracles=OracleSettings().instantiate())
            judged[key] = not any(f"{m.oracle}/{m.kind}" == verdict for m in clean.misbehaviors)
        if judged[key]:
            first = exec_id if first is None else first
            if representative:
                own.add(signature)
                first_of_signature = exec_id if first_of_signature is None else first_of_signature
        if first is not None and not every:
            break
    return first, first_of_signature, len(own)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--execs", type=int, default=1000, help="executions per campaign [1000]")
    ap.add_argument("--reps", type=int, default=5, help="repetitions per configuration and network [5]")
    ap.add_argument("--first-rep", type=int, default=0,
                    help="campaign seed of the first repetition (more repetitions later without rerunning these) [0]")
    ap.add_argument("--networks", default=",".join(NETWORKS), help="committed seed sets [all five]")
    ap.add_argument("--strategy", default="all", help="mutation strategy [all]")
    ap.add_argument("--population", type=int, default=8, help="mutants per cycle [8]")
    ap.add_argument("--configs", default="risk,random", help="feedbacks to compare [risk,random]")
    ap.add_argument("--jobs", type=int, default=2, help="campaigns at once, in separate processes [2]")
    ap.add_argument("--faults", action="store_true", help="also: executions to the first finding of hidden faults")
    ap.add_argument("--fault-execs", type=int, default=1000, help="budget of a fault campaign [1000]")
    ap.add_argument("--fault-list", default="", help="with --faults: only these faults (comma-separated) [all]")
    ap.add_argument("--stop-at-first", action="store_true", help="with --faults: end a fault campaign at its "
                    "first finding (the time to it is what is measured; the signature counts then mean little)")
    ap.add_argument("--dump", default="", help="also write every campaign's result (its reached cells too) "
                    "to this JSON file")
    ap.add_argument("--no-clean", action="store_true", help="with --faults: skip the clean coverage campaigns")
    ap.add_argument("--missed", action="store_true", help="also list the cells some repetitions reached and others "
                    "not, and those aimed at and reached by none, with each repetition's aimed executions")
    ap.add_argument("--from-dump", default="", help="print the tables of a --dump file instead of running campaigns")
    args = ap.parse_args(argv)
    if args.from_dump:
        return _reprint(args, Path(args.from_dump))
    if args.reps < 1 or args.execs < 1 or args.first_rep < 0:
        ap.error("--reps and --execs must be at least 1, --first-rep at least 0")
    reps = range(args.first_rep, args.first_rep + args.reps)
    networks = [n.strip() for n in args.networks.split(",") if n.strip()]
    configs = [c.strip() for c in args.configs.split(",") if c.strip()]
    opts = {"execs": args.execs, "population": args.population, "strategy": args.strategy}
    faults = [f.strip() for f in args.fault_list.split(",") if f.strip()] if args.fault_list else HIDDEN_FAULTS
    work = [] if args.no_clean else [(net, fb, rep, opts) for net in networks for rep in reps for fb in configs]
    if args.faults:
        work += [(FAULT_NETWORK.get(f, "town"), fb, rep, dict(opts, execs=args.fault_execs, fault=f,
                                                              stop_at_first=args.stop_at_first))
                 for f in faults for rep in reps for fb in configs]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max(args.jobs, 1)) as pool:
        results = list(pool.map(run_one, *zip(*work)))
    wall = time.perf_counter() - t0
    if args.dump:
        Path(args.dump).write_text(json.dumps(results, indent=1))

    clean = [r for r in results if r["fault"] is None]
    if clean:
        _coverage_table(args, networks, configs, clean)
    if args.faults:
        _fault_table(args, configs, faults, results)
    print(f"\nwall clock: {wall:.0f} s for {sum(r['execs'] for r in results)} executions")
    return 0


def _reprint(args, dump: Path) -> int:
    """The tables of a ``--dump`` file (its networks, configurations and repetitions)."""
    try:
        results = json.loads(dump.read_text())
        clean = [r for r in results if r["fault"] is None]
        networks = list(dict.fromkeys(r["network"] for r in clean))
        configs = list(dict.fromkeys(r["feedback"] for r in results))
        reps = sorted({r["rep"] for r in results})
    except (OSError, ValueError, TypeError, KeyError) as e:
        print(f"eval_coverage: {dump}: not a --dump file of this tool ({e})", file=sys.stderr)
        return 2
    args.first_rep, args.reps = (reps[0], len(reps)) if reps else (0, 0)
    args.execs = max((r["execs"] for r in clean), default=args.execs)
    if clean:
        _coverage_table(args, networks, configs, clean)
    faults = list(dict.fromkeys(r["fault"] for r in results if r["fault"]))
    if faults:
        _fault_table(args, configs, faults, results)
    return 0


def _coverage_table(args, networks, configs, clean) -> None:
    """Per network and configuration the share reached in each repetition, its mean and p against random."""
    print(f"clean reference ADS, strategy {args.strategy}, {args.execs} executions per campaign "
          f"(population {args.population}), {args.reps} repetitions; share of reachable cells reached")
    print(f"{'network':<14}{'cells':>6}  {'config':<8}"
          + "".join(f"{'rep' + str(r):>7}" for r in range(args.first_rep, args.first_rep + args.reps))
          + f"{'mean':>8}{'p':>9}")
    pooled: dict[str, list[float]] = {c: [] for c in configs}
    for net in networks:
        shares = {}
        for fb in configs:
            rows = sorted((r for r in clean if r["network"] == net and r["feedback"] == fb), key=lambda r: r["rep"])
            shares[fb] = [r["share"] for r in rows]
            pooled[fb].extend(shares[fb])
        for fb in configs:
            p = "" if fb == "random" or "random" not in shares else \
                f"{mann_whitney_p(shares[fb], shares['random']):9.4f}"
            cells = next((r["reachable"] for r in clean if r["network"] == net), 0)
            print(f"{net:<14}{cells:>6}  {fb:<8}" + "".join(f"{100 * s:>6.1f}%" for s in shares[fb])
                  + f"{100 * statistics.mean(shares[fb]):>7.1f}%{p}")
        for fb in configs:
            rows = [r for r in clean if r["network"] == net and r["feedback"] == fb]
            _spread(fb, rows, args.missed)
    for fb in configs:
        if fb != "random" and pooled.get("random"):
            ratio = statistics.mean(pooled[fb]) / max(statistics.mean(pooled["random"]), 1e-9)
            name = "default" if fb == "risk" else fb
            print(f"coverage, {name} / random: {ratio:.2f} (p = {mann_whitney_p(pooled[fb], pooled['random']):.4f})")


def _spread(fb: str, rows: list[dict], missed: bool) -> None:
    """The cells reached by every repetition, by some and by none (the union's complement), with ``missed`` listed
    with the aimed executions each had in every repetition: what a campaign reaches reliably, and what only a
    lucky one does."""
    if not rows or "cells" not in rows[0]:
        return
    reached = [set(r["cells"]) for r in rows]
    union, every = set().union(*reached), set.intersection(*reached)
    total = rows[0]["reachable"]
    print(f"{'':<14}{'':>6}  {fb:<8}union {len(union)} ({100 * len(union) / max(total, 1):.1f}%), in every "
          f"repetition {len(every)}, in some {len(union - every)}, in none {total - len(union)}")
    outside = [set(r.get("outside") or ()) for r in rows]
    if any(outside):  # reached, not derived: where the derivation says the network cannot offer a cell it did
        print(f"{'':<14}{'':>6}  {fb:<8}outside the derivation: "
              + ", ".join(f"{c} ({sum(c in o for o in outside)}/{len(rows)})" for c in sorted(set().union(*outside))))
    if not missed:
        return
    for cell in sorted(union - every):
        print(f"{'':<24}some ({sum(cell in r for r in reached)}/{len(rows)}) {cell}  aimed "
              + ",".join(str(r["aimed"].get(cell, 0)) for r in rows if cell not in r["cells"]))
    for cell in sorted({c for r in rows for c in r["aimed"]} - union):
        print(f"{'':<24}none {cell}  aimed " + ",".join(str(r["aimed"].get(cell, 0)) for r in rows))


def _fault_table(args, configs, faults, results) -> None:
    """Per hidden fault and configuration the executions to the first finding, and distinct signatures."""
    print(f"\nexecutions to the first finding of each hidden fault ({args.fault_execs} executions, "
          f"{args.reps} repetitions; '-' = not found; in brackets where it differs: counting each signature's "
          "first finding only)")
    print(f"{'fault':<22}{'network':<10}" + "".join(f"{c:>30}" for c in configs))
    for f in faults:
        cells = []
        for fb in configs:
            rows = sorted((r for r in results if r["fault"] == f and r["feedback"] == fb), key=lambda r: r["rep"])
            cells.append(",".join(_first(r) for r in rows))
        print(f"{f:<22}{FAULT_NETWORK.get(f, 'town'):<10}" + "".join(f"{c:>30}" for c in cells))
    print("found (campaigns with a finding; each signature's first only) and the fault's own signatures per "
          "campaign (mean):")
    for fb in configs:
        rows = [r for r in results if r["fault"] and r["feedback"] == fb]
        if rows:
            print(f"  {fb:<10}found {sum(r['first'] is not None for r in rows)}/{len(rows)} "
                  f"({sum(r['first_of_signature'] is not None for r in rows)}/{len(rows)}), "
                  f"the fault's own signatures {statistics.mean(r['signatures'] for r in rows):.2f}")


def _first(r: dict) -> str:
    """``first`` of a fault campaign, and the signature-first count in brackets where it differs."""
    def show(n):
        return "-" if n is None else str(n)

    strict = r.get("first_of_signature", r["first"])
    return show(r["first"]) + ("" if strict == r["first"] else f"({show(strict)})")


if __name__ == "__main__":
    sys.exit(main())
