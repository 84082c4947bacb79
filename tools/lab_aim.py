"""How often does an aimed build reach its cell, cell by cell, on the committed seeds of one network?

For every seed of ``--network`` and every reachable cell of that seed whose key contains ``--cells``, ``--draws``
aimed builds (:func:`drivefuzz.search.aim.aimed`) are made on the seed itself and run with the reference ADS; the
mutator is first given the seed run's own pace, as a fuzz job does (:meth:`Mutator.observe`). Printed per cell:
draws, builds (a draw the mission cannot offer builds nothing), and builds whose run reached the cell. Unlike
``tools/eval_aim.py`` (aims inside campaigns, on lineage parents), this isolates the builders. Usage::

    python tools/lab_aim.py --network town --cells none/grip --draws 3
    python tools/lab_aim.py --network town --cells "|signal/amber" --draws 2

Prints only; a benchmark, not a test. Deterministic: draw k of a cell on seed i uses ``Random("lab/i/cell/k")``.
"""

from __future__ import annotations

import argparse
import random
import sys
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--network", default="town", help="committed seed set [town]")
    ap.add_argument("--cells", default="", help="only cells whose key contains this [all]")
    ap.add_argument("--draws", type=int, default=3, help="aimed draws per seed and cell [3]")
    ap.add_argument("--verbose", action="store_true", help="each build: what was built, and its run's cells of "
                    "the aimed row (party) or column (condition)")
    args = ap.parse_args()

    from drivefuzz.ads import load_ads
    from drivefuzz.campaign.aiming import seed_reachable
    from drivefuzz.campaign.job import TRAVEL_EVERY_S, ego_travel
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario
    from drivefuzz.search.aim import aimed
    from drivefuzz.search.mutate import Mutator
    from drivefuzz.search.risk import risk_score
    from drivefuzz.sim.execute import execute
    from drivefuzz.triage.coverage import execution_cells

    seeds = [read_scenario(p) for p in list_seeds(REPO / "seeds" / args.network)]
    rmap = load_roadmap(seeds[0].network)
    ads = load_ads("ego")
    draws, built, hits = Counter(), Counter(), Counter()
    for si, sc in enumerate(seeds):
        mut = Mutator(rmap)
        mut.observe(sc, ego_travel(execute(sc, ads=ads, oracles=[]).trace), TRAVEL_EVERY_S)
        for cell in seed_reachable(rmap, sc):
            if args.cells not in cell:
                continue
            for k in range(args.draws):
                m, _ = aimed(mut, sc, cell, random.Random(f"lab/{si}/{cell}/{k}"))
                draws[cell] += 1
                if m.scenario is sc:
                    continue
                built[cell] += 1
                trace = execute(m.scenario, ads=ads, oracles=[]).trace
                cells = execution_cells(m.scenario, trace, rmap, risk_score(trace))
                hits[cell] += cell in cells
                if args.verbose:
                    proj, row_col = cell.split(":", 1)
                    row, col = row_col.split("|", 1)
                    key = f"{proj}:{row}|" if proj != "speed-condition" else f"|{col}"
                    near = sorted(c.split(":", 1)[1] for c in cells if key in c and c.startswith(proj))
                    print(f"    seed {si:03d} {'HIT ' if cell in cells else 'miss'} {m.description[:150]}\n"
                          f"        reached: {', '.join(near) or '-'}")
    print(f"{args.network}, cells with '{args.cells}': draws {sum(draws.values())}, built {sum(built.values())}, "
          f"reached their cell {sum(hits.values())}")
    for c in sorted(draws):
        print(f"  {c:58s} draws {draws[c]:3d}  built {built[c]:3d}  reached {hits[c]:3d}")


if __name__ == "__main__":
    main()
