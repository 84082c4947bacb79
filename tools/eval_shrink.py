"""How much do minimal reproducers shrink, and do they keep the bug? The figures of issue 13.

For every finding folder (one per signature) of the given campaign directories, or of a fresh town campaign
(``--execs`` executions of the clean reference ADS, campaign seed ``--seed``), shrink the representative
with ``drivefuzz shrink``'s delta debugging (``--budget`` executions) and check that the minimal scenario
replays with the same signature. Prints one line per finding, then the medians of actors, puddles and
weather knobs before and after, the executions spent, and how many shrunk findings reproduce.

Usage::

    python tools/eval_shrink.py [--execs 600] [--seed 2] [--budget 30] [--campaign DIR ...]

Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def _campaign(out: Path, execs: int, seed: int) -> Path:
    from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario

    seeds = [read_scenario(p) for p in list_seeds(REPO / "seeds" / "town")]
    Campaign(out, seeds, FuzzConfig(max_execs=execs, seed=seed, shrink=0)).run()
    return out


def _shrink_one(folder: Path, budget: int) -> dict:
    from drivefuzz.oracle import Misbehavior, OracleSettings
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.sumofiles import read_scenario
    from drivefuzz.sim.execute import execute
    from drivefuzz.triage.shrink import rules_signature, shrink_finding

    verdict = json.loads((folder / "verdict.json").read_text())
    want = Misbehavior.from_dict(verdict["misbehaviors"][0])
    sc = read_scenario(folder)
    oracles = OracleSettings(settings=verdict["oracles"]).instantiate(source=str(folder))
    t0 = time.perf_counter()
    shrunk = shrink_finding(folder, verdict, want, sc, oracles, budget)
    wall = time.perf_counter() - t0
    minimal = read_scenario(folder / "minimal")
    ex = execute(minimal, oracles=OracleSettings(settings=verdict["oracles"]).instantiate(source=str(folder)))
    same = [m for m in ex.misbehaviors if (m.oracle, m.kind) == (want.oracle, want.kind)]
    again = bool(same) and rules_signature(load_roadmap(minimal.network_path()))(minimal, same[0], ex.trace) == shrunk.signature
    return {"folder": folder, "before": shrunk.before, "after": shrunk.after, "execs": shrunk.executions,
            "wall": wall, "reproduces": again}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--execs", type=int, default=600, help="executions of the fresh campaign [600]")
    ap.add_argument("--seed", type=int, default=2, help="campaign seed of the fresh campaign [2]")
    ap.add_argument("--budget", type=int, default=30, help="executions per shrink [30]")
    ap.add_argument("--campaign", type=Path, nargs="+", help="shrink the findings of these campaign directories")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="eval-shrink-") as tmp:
        camps = args.campaign or [_campaign(Path(tmp) / "town", args.execs, args.seed)]
        folders = [f for c in camps for f in sorted((c / "findings").glob("*")) if (f / "verdict.json").exists()]
        if not folders:
            print("no findings to shrink")
            return 0
        rows = [_shrink_one(f, args.budget) for f in folders]
    print(f"{'actors':>9} {'puddles':>9} {'knobs':>7} {'sim s':>13} {'execs':>5} {'wall s':>6}  same signature  finding")
    for r in rows:
        b, a = r["before"], r["after"]
        print(f"{b.actors:>3} -> {a.actors:<3} {b.puddles:>3} -> {a.puddles:<3} {b.knobs:>2} -> {a.knobs:<2} "
              f"{b.sim_seconds:>5.1f} -> {a.sim_seconds:<5.1f} {r['execs']:>5} {r['wall']:>6.1f}  "
              f"{'yes' if r['reproduces'] else 'NO':<14}  {r['folder'].parent.parent.name}/{r['folder'].name}")
    med = statistics.median
    print(f"\n{len(rows)} findings; median actors {med(r['before'].actors for r in rows):g} -> "
          f"{med(r['after'].actors for r in rows):g}, puddles {med(r['before'].puddles for r in rows):g} -> "
          f"{med(r['after'].puddles for r in rows):g}, knobs {med(r['before'].knobs for r in rows):g} -> "
          f"{med(r['after'].knobs for r in rows):g}; median {med(r['execs'] for r in rows):g} executions per shrink")
    print(f"shrunk findings that reproduce the same signature: {sum(r['reproduces'] for r in rows)}/{len(rows)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
