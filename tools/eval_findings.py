"""How trustworthy are a campaign's findings? Verdicts, signatures against findings, reproduction rates.

Runs one fuzz campaign per mutation strategy on a network's committed seeds with the clean
reference ADS (``FuzzConfig(max_execs=N, strategy=S, seed=SEED)``, everything else as
``drivefuzz fuzz`` has it), then reads each campaign directory and prints:

- executions and wall time; the executions on which an oracle fired;
- findings (folders under ``findings/``: distinct signatures with fault ``ego`` or ``unclear``) and
  incidents (folders under ``incidents/``: fault ``other``);
- per verdict (ego / other / unclear): the number of folders and of hits (executions filed there);
- signatures against findings: executions with a misbehaviour per distinct signature (the dedup factor);
- likely bugs: the findings grouped by the attribution rule that blamed the ego (same oracle and kind);
- reproduction rates: the distribution of ``reproduced k/N`` over the new signatures, robust vs knife-edge;
- the triage cost: ``triage_executions`` of each folder's ``verdict.json`` (the counterfactual replay
  and the reproduction reruns of a new signature), and the same in executions' worth of wall time;
- one line per finding (and per incident): hits, reproduction, signature label, attribution reason.

Usage::

    python tools/eval_findings.py [--execs 600] [--strategies all,entropy] [--seed 0] [--network town]
                                  [--jobs 2] [--keep DIR] [--reproduce 5] [--reproduce-incidents] [--report DIR ...]

``--keep DIR`` keeps each campaign in ``DIR/<strategy>`` so that a person can read its traces;
``--report DIR`` prints the figures of existing campaign directories without running anything.
Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sqlite3
import sys
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from campaigns import end_records, run_campaign  # noqa: E402  (tools/, beside this script)

VERDICTS = ("ego", "other", "unclear")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--execs", type=int, default=600, help="executions per campaign [600]")
    ap.add_argument("--strategies", default="all,entropy", help="comma-separated mutation strategies [all,entropy]")
    ap.add_argument("--seed", type=int, default=0, help="campaign RNG seed [0]")
    ap.add_argument("--network", default="town", help="a bundled network name or a .net.xml [town]")
    ap.add_argument("--jobs", type=int, default=2, help="seed jobs at once on a local Dask cluster [2]")
    ap.add_argument("--reproduce", type=int, default=5, help="perturbed reruns of each new finding [5]")
    ap.add_argument("--reproduce-incidents", action="store_true",
                    help="re-run the new incidents too (what drivefuzz fuzz --report-all does)")
    ap.add_argument("--keep", type=Path, help="keep the campaign directories here (DIR/<strategy>)")
    ap.add_argument("--report", type=Path, nargs="+", help="only print the figures of these campaign directories")
    args = ap.parse_args(argv)

    if args.report:
        for out in args.report:
            report(out, strategy=out.name, wall_s=None)
        return 0
    strategies = [s.strip() for s in args.strategies.split(",") if s.strip()]
    tmp = None
    base = args.keep
    if base is None:
        tmp = tempfile.mkdtemp(prefix="eval-findings-")
        base = Path(tmp)
    try:
        for s in strategies:
            out = base / s
            if out.exists() and any(out.iterdir()):
                sys.exit(f"{out} exists and is not empty: give another --keep, or remove it")
            wall = run_strategy(out, s, args)
            report(out, strategy=s, wall_s=wall)
    finally:
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


def _network_and_seeds(name: str):
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import load_scenario

    net = Path(name) if name.endswith(".xml") or name.endswith(".gz") else REPO / "networks" / f"{name}.net.xml"
    stem = net.name.split(".")[0]
    seeds = []
    for p in list_seeds(REPO / "seeds" / stem):
        sc = load_scenario(p)
        if Path(sc.network).resolve() != net.resolve():
            sc = sc.model_copy(update={"network": str(net.resolve())})
        seeds.append(sc)
    if not seeds:
        sys.exit(f"no committed seeds under seeds/{stem}")
    return net, seeds


def run_strategy(out: Path, strategy: str, args) -> float:
    """Run one campaign into ``out``; return its wall time [s]."""
    from drivefuzz.campaign.fuzz import FuzzConfig

    net, seeds = _network_and_seeds(args.network)
    cfg = FuzzConfig(max_execs=args.execs, strategy=strategy, seed=args.seed, reproduce=args.reproduce,
                     reproduce_incidents=args.reproduce_incidents)
    argv = ["tools/eval_findings.py", "--execs", str(args.execs), "--strategies", strategy, "--seed", str(args.seed),
            "--network", args.network]
    print(f"running: strategy {strategy}, {args.execs} executions, {len(seeds)} seeds of {net.name}, "
          f"seed {args.seed}, {args.jobs} job(s) -> {out}", file=sys.stderr, flush=True)
    return run_campaign(out, seeds, cfg, argv, args.jobs)


# ------------------------------------------------------------------------------ reading a campaign
def _folders(out: Path, sub: str) -> list[dict[str, Any]]:
    """Each folder of ``out/sub`` with its verdict.json and hits.json."""
    rows = []
    for p in sorted((out / sub).glob("*/verdict.json")):
        v = json.loads(p.read_text())
        hits_path = p.parent / "hits.json"
        hits = json.loads(hits_path.read_text()).get("count", 1) if hits_path.exists() else 1
        att = v.get("attribution") or {}
        first = (v.get("misbehaviors") or [{}])[0]
        rows.append({"folder": f"{sub}/{p.parent.name}", "verdict": v, "hits": hits,
                     "fault": att.get("fault") or (v.get("signature") or {}).get("fault") or "ego",
                     "reason": att.get("reason") or f"(no trace: {first.get('kind')})",
                     "label": (v.get("signature") or {}).get("label") or "",
                     "reproduction": v.get("reproduction"), "triage": v.get("triage_executions", 0) or 0,
                     "rule": att.get("rule") or "",
                     "oracle_kind": f"{first.get('oracle')}/{first.get('kind')}" if first.get("oracle") else "-"})
    return rows


def report(out: Path, strategy: str, wall_s: float | None) -> None:
    db = sqlite3.connect(out / "index.sqlite")
    n = db.execute("SELECT COUNT(*) FROM executions").fetchone()[0]
    fired = db.execute("SELECT COUNT(*) FROM executions WHERE verdict IS NOT NULL AND verdict != 'pass'").fetchone()[0]
    by_oracle = Counter(r[0].split("/")[0] for r in db.execute(
        "SELECT verdict FROM executions WHERE verdict IS NOT NULL AND verdict != 'pass'"))
    db.close()
    findings, incidents = _folders(out, "findings"), _folders(out, "incidents")
    folders = findings + incidents
    wall = f"{wall_s:.0f} s ({wall_s / max(n, 1):.2f} s per execution)" if wall_s is not None else "(not run here)"

    print(f"=== strategy {strategy}: {out}")
    print(f"executions: {n}   wall time: {wall}")
    print(f"executions on which an oracle fired: {fired}  ({', '.join(f'{k} {v}' for k, v in by_oracle.most_common())})")
    print(f"findings (findings/, fault ego or unclear): {len(findings)}   incidents (incidents/, fault other): "
          f"{len(incidents)}")
    print(f"{'verdict':<10}{'folders':>9}{'hits':>7}")
    for v in VERDICTS:
        rows = [r for r in folders if r["fault"] == v]
        print(f"{v:<10}{len(rows):>9}{sum(r['hits'] for r in rows):>7}")
    hits = sum(r["hits"] for r in folders)
    sigs = len(folders)
    print(f"signatures against findings: {fired} executions with a misbehaviour, {hits} filed, in {sigs} distinct "
          f"signature(s): dedup factor {fired / max(sigs, 1):.1f}")
    from drivefuzz.triage.attribute import bug_class

    classes = Counter(bug_class(r["oracle_kind"], r["fault"], r["rule"]) for r in findings)
    print(f"likely bugs (findings grouped by the attribution rule that blamed the ego): {len(classes)} for "
          f"{len(findings)} finding(s)" + "".join(f"\n  {n} x {title}" for (_k, title), n in classes.most_common()))
    _print_reproduction(folders)
    _print_triage_cost(out, folders)
    for title, rows in (("findings", findings), ("incidents", incidents)):
        if rows:
            print(f"{title}:")
        for r in sorted(rows, key=lambda r: -r["hits"]):
            rep = (r["reproduction"] or {}).get("label", "reproduction not measured")
            print(f"  {r['folder']}\n      hits {r['hits']}, {rep}\n      {r['label']}\n      reason: {r['reason']}")
    print(flush=True)


def _print_reproduction(folders: list[dict[str, Any]]) -> None:
    """The distribution of ``reproduced k/N`` over the new signatures (all, then the findings alone)."""
    if not any(r["reproduction"] for r in folders):
        print("reproduction: none measured")
        return
    for title, rows in (("all signatures", folders), ("findings", [r for r in folders if r["fault"] != "other"])):
        rr = [r["reproduction"] for r in rows if r["reproduction"]]
        if not rr:
            continue
        d = Counter(f"{x['reproduced']}/{x['runs']}" for x in rr)
        robust = sum(1 for x in rr if x.get("robust"))
        print(f"reproduction ({title}, {len(rr)}): " + ", ".join(f"{k}: {d[k]}" for k in sorted(d, reverse=True))
              + f"   robust {robust}, knife-edge {len(rr) - robust}")


def _print_triage_cost(out: Path, folders: list[dict[str, Any]]) -> None:
    """``triage_executions`` from the folders; wall time of triage from the journal, in executions' worth."""
    total = sum(r["triage"] for r in folders)
    print(f"triage executions (verdict.json triage_executions): {total} over {len(folders)} new signature(s), "
          f"{total / max(len(folders), 1):.1f} each, max {max((r['triage'] for r in folders), default=0)}")
    recs = end_records(out)
    plain = [r["wall_time"] for r in recs if r.get("wall_time") and not r.get("signature")]
    firsts = {r["verdict"].get("key") for r in folders}
    new = [r for r in recs if r.get("key") in firsts]
    repeats = [r for r in recs if r.get("signature") and r.get("key") not in firsts and r.get("triage_execs")]
    if new and plain:
        mean_exec = sum(plain) / len(plain)
        per = sum((r.get("timings") or {}).get("triage", 0.0) for r in new) / len(new)
        print(f"triage wall time per new signature: {per:.2f} s = {per / mean_exec:.1f} executions' worth "
              f"(mean clean execution {mean_exec:.2f} s; the goal: at most 15)")
    if repeats:  # the rules blamed the ego, the counterfactual moved it onto a known incident's signature
        print(f"repeats of a known signature that ran a counterfactual again: {len(repeats)}, "
              f"{sum(r['triage_execs'] for r in repeats)} executions")


if __name__ == "__main__":
    sys.exit(main())
