"""How many executions of a campaign placed a walker that walks along a lane cars use?

Such a walker (a linear walker whose line runs along a car lane) meets the ego only after the ego has stopped
behind it, or walks into the ego's side; the fairness rule :func:`drivefuzz.search.fairness.walks_along_lane`
keeps the mutator from placing one (issue 33: 10 of 16 signatures of one town campaign were such walkers).
This reads a campaign folder (data only: its scenario.json files and verdicts) and prints, over the executed
scenarios the campaign kept (its corpus, findings and incidents), the walkers, the linear ones, those that walk
along a car lane, and the findings and incidents whose misbehaviour involved a walker. Usage::

    python tools/eval_walkers.py OUT [OUT ...]
    python tools/eval_walkers.py --run town --execs 1000 --seed 0   # runs the campaign first (in a temp folder)

Prints only; a measurement, not a test.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def scan(out: Path) -> dict[str, int]:
    """The counts for the campaign folder ``out``."""
    from drivefuzz.scenario import ActorKind, NavType
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.sumofiles import read_scenario
    from drivefuzz.search.fairness import walks_along_lane
    from drivefuzz.search.mutate import Mutator

    counts = {"scenarios": 0, "walkers": 0, "linear walkers": 0, "walking along a car lane": 0,
              "findings": 0, "incidents": 0, "findings or incidents with a walker": 0}
    muts: dict[str, Mutator] = {}
    folders = [(kind, p) for kind in ("corpus", "findings", "incidents") for p in sorted((out / kind).glob("*"))
               if (p / "scenario.json").is_file()]
    for kind, folder in folders:
        try:
            sc = read_scenario(folder)
        except Exception as exc:  # a damaged record is reported, not fatal
            print(f"eval_walkers: {folder}: skipped ({exc})", file=sys.stderr)
            continue
        counts["scenarios"] += 1
        net = str(sc.network_path())
        mut = muts.setdefault(net, Mutator(load_roadmap(sc.network_path())))
        walkers = [a for a in sc.actors if a.kind is ActorKind.PEDESTRIAN]
        counts["walkers"] += len(walkers)
        counts["linear walkers"] += sum(a.nav is NavType.LINEAR for a in walkers)
        counts["walking along a car lane"] += sum(walks_along_lane(mut, a) is not None for a in walkers)
        if kind != "corpus":
            counts[kind] += 1
            verdict = json.loads((folder / "verdict.json").read_text()) if (folder / "verdict.json").is_file() else {}
            ids = {a.id for a in walkers}
            involved = {x for m in verdict.get("misbehaviors", ()) for x in (m.get("actors") or ())}
            counts["findings or incidents with a walker"] += bool(ids & involved)
    return counts


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", nargs="*", type=Path, help="campaign folders")
    ap.add_argument("--run", metavar="NETWORK", help="run a campaign on networks/NETWORK.net.xml first")
    ap.add_argument("--execs", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    outs = list(args.out)
    with tempfile.TemporaryDirectory(prefix="eval-walkers-") as tmp:
        if args.run:
            from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
            from drivefuzz.scenario.seed import list_seeds
            from drivefuzz.scenario.sumofiles import read_scenario

            out = Path(tmp) / "out"
            seeds = [read_scenario(p) for p in list_seeds(REPO / "seeds" / args.run)]
            Campaign(out, seeds, FuzzConfig(max_execs=args.execs, seed=args.seed)).run()
            outs.append(out)
        if not outs:
            ap.error("give a campaign folder, or --run NETWORK")
        for out in outs:
            if not out.is_dir():
                print(f"eval_walkers: {out}: not a campaign folder", file=sys.stderr)
                return 2
            counts = scan(out)
            print(f"{args.run or out}: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
