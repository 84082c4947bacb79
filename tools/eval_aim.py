"""How often does the aimed mutator hit the cell it aimed at? Read from campaigns' journals.

A member built for a cell (drivefuzz.search.aim; its journal record's ``mutation`` begins ``aim <cell>:``) *hits*
when its execution reached that cell (the record's ``cells``), and *hits the row* when it reached any cell of the
same projection and row (the party, or the speed band). Printed per row and per column of the aimed cells: aimed
members, cell hits, row hits; then the reachable cells that no campaign reached, and the mutation time per
execution (the journal's ``timings.mutation``).

Either runs ``--reps`` default (``--feedback risk``) campaigns of ``--execs`` executions on ``--network`` (seeds
0..reps-1, one process each, ``--jobs`` at once; reproduction and shrinking off), or reads campaign folders
given as arguments. Usage::

    python tools/eval_aim.py [--network town] [--execs 200] [--reps 2] [--jobs 2] [--aim-share F] [--keep DIR]
    python tools/eval_aim.py OUT [OUT ...]

Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def _campaign(network: str, rep: int, execs: int, out: str, feedback: str, aim_share: float | None = None) -> str:
    from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
    from drivefuzz.search.mutate import MutationConfig
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario

    seeds = [read_scenario(p) for p in list_seeds(REPO / "seeds" / network)]
    mutation = MutationConfig() if aim_share is None else MutationConfig(aim_share=aim_share)
    cfg = FuzzConfig(population=8, strategy="all", seed=rep, max_execs=execs, feedback=feedback, reproduce=0,
                     shrink=0, mutation=mutation)
    Campaign(Path(out), seeds, cfg).run()
    return out


def aimed_cell(mutation: str) -> str | None:
    """The full cell key a member was aimed at, from its ``mutation`` description (None: not aimed)."""
    from drivefuzz.triage.coverage import ELEMENTS, MANOEUVRES

    if not mutation.startswith("aim "):
        return None
    head = mutation[4:].split(": ", 1)[0]
    if ":" in head.split("|", 1)[0]:  # "aim <projection>:<row>|<col>"
        return head
    row, _, col = head.partition("|")  # older journals: "aim <row>|<col>"
    if "km/h" in row:
        return f"speed-condition:{head}"
    return f"party-manoeuvre:{head}" if col in MANOEUVRES and col not in ELEMENTS else f"party-element:{head}"


def records(out: Path) -> list[dict]:
    """The executions' records of a campaign's journals."""
    from drivefuzz.campaign.job import read_journal

    return [r for path in sorted((out / "jobs").glob("*/journal.jsonl")) for r in read_journal(path)
            if r.get("event") == "end"]


def hit_table(recs: list[dict]) -> dict:
    """Per aimed row and column: [aimed, cell hits, row hits]."""
    rows: dict[str, list[int]] = {}
    cols: dict[str, list[int]] = {}
    for rec in recs:
        cell = aimed_cell(rec.get("mutation") or "")
        if cell is None:
            continue
        proj, rest = cell.split(":", 1)
        row, col = rest.split("|", 1)
        got = set(rec.get("cells") or ())
        hit = cell in got
        row_hit = any(c.startswith(f"{proj}:{row}|") for c in got)
        for table, name in ((rows, f"{proj[:5]} {row}"), (cols, f"{proj[:5]} {col}")):
            t = table.setdefault(name, [0, 0, 0])
            t[0] += 1
            t[1] += hit
            t[2] += row_hit
    return {"rows": rows, "cols": cols}


def report(outs: list[Path]) -> None:
    from drivefuzz.triage.coverage import campaign_coverage

    all_recs, unreached, mut_ms, shares = [], None, [], []
    for out in outs:
        recs = records(out)
        all_recs += recs
        mut_ms += [1000 * r["timings"]["mutation"] for r in recs if r.get("timings") and r.get("parent")]
        cov = campaign_coverage(out, write=False)
        shares.append(cov["share"])
        miss = {c for c, h in cov["cells"].items() if not h["count"]}
        unreached = miss if unreached is None else unreached & miss
    t = hit_table(all_recs)
    n = sum(v[0] for v in t["rows"].values())
    hits = sum(v[1] for v in t["rows"].values())
    row_hits = sum(v[2] for v in t["rows"].values())
    print(f"{len(outs)} campaigns, {len(all_recs)} executions, coverage " +
          ", ".join(f"{100 * s:.1f} %" for s in shares))
    print(f"aimed {n} ({100 * n / max(len(all_recs), 1):.0f} %): cell hit {hits} ({100 * hits / max(n, 1):.0f} %), "
          f"row hit {row_hits} ({100 * row_hits / max(n, 1):.0f} %)")
    for title, table in (("row", t["rows"]), ("column", t["cols"])):
        print(f"\nper aimed {title}: aimed, cell hits, row hits")
        for name, (a, h, r) in sorted(table.items(), key=lambda kv: -kv[1][0]):
            print(f"  {name:<36}{a:>5}{h:>6} ({100 * h / a:3.0f} %){r:>6} ({100 * r / a:3.0f} %)")
    print(f"\nreachable cells no campaign reached ({len(unreached or ())}):")
    by = Counter(c.split(":", 1)[0] for c in unreached or ())
    for proj in sorted(by):
        print(f"  {proj}: " + ", ".join(c.split(":", 1)[1] for c in sorted(unreached) if c.startswith(proj + ":")))
    if mut_ms:
        print(f"\nmutation per execution: mean {statistics.mean(mut_ms):.1f} ms, median {statistics.median(mut_ms):.1f} ms")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outs", nargs="*", help="campaign folders to read (else: run campaigns)")
    ap.add_argument("--network", default="town")
    ap.add_argument("--execs", type=int, default=200)
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--feedback", default="risk")
    ap.add_argument("--aim-share", type=float, default=None, help="MutationConfig.aim_share [its default]")
    ap.add_argument("--keep", default="", help="run the campaigns into DIR/rep<r> and keep them")
    args = ap.parse_args(argv)
    if args.outs:
        report([Path(o) for o in args.outs])
        return 0
    with tempfile.TemporaryDirectory(prefix="eval-aim-") as tmp:
        base = Path(args.keep or tmp)
        outs = [str(base / f"rep{r}") for r in range(args.reps)]
        t0 = time.perf_counter()
        with ProcessPoolExecutor(max(args.jobs, 1)) as pool:
            list(pool.map(_campaign, [args.network] * args.reps, range(args.reps), [args.execs] * args.reps, outs,
                          [args.feedback] * args.reps, [args.aim_share] * args.reps))
        print(f"{args.network}, {args.execs} executions x {args.reps}, feedback {args.feedback}: "
              f"{time.perf_counter() - t0:.0f} s")
        report([Path(o) for o in outs])
    return 0


if __name__ == "__main__":
    sys.exit(main())
