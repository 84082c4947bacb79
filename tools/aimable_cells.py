"""Which reachable interaction-coverage cells can the mutator aim at on no seed of a network?

Per committed seed set: the cells the network and the seeds' routes offer
(:func:`drivefuzz.triage.coverage.reachable`) and those for which no offering seed gets an aimed build in
:data:`drivefuzz.campaign.aiming.AIM_TRIES` draws (:func:`drivefuzz.campaign.aiming.can_aim`, the mutator's model
pace: a campaign times by the ADS's own pace, so a cell listed here may still be built there). The campaign's
shares give such a cell to some seed all the same; its aims then build nothing, and only an encounter of another
aim can reach it. Usage::

    python tools/aimable_cells.py [--networks town,intersection,...]

Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
NETWORKS = ("town", "highway", "roundabout", "interchange", "intersection")


def main(argv: list[str] | None = None) -> int:
    from drivefuzz.campaign.aiming import can_aim, seed_places
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--networks", default=",".join(NETWORKS), help="committed seed sets [all five]")
    args = ap.parse_args(argv)
    for net in (n.strip() for n in args.networks.split(",") if n.strip()):
        folder = REPO / "seeds" / net
        if not folder.is_dir():
            print(f"aimable_cells: {folder}: no committed seed set of that name (valid: {', '.join(NETWORKS)})",
                  file=sys.stderr)
            return 2
        t0 = time.perf_counter()
        seeds = [read_scenario(p) for p in list_seeds(folder)]
        rmap = load_roadmap(seeds[0].network_path())
        places = [seed_places(rmap, sc) for sc in seeds]
        cells = sorted(set().union(*places))
        none = [c for c in cells if not any(c in p and can_aim(rmap, seeds[i], c, i) for i, p in enumerate(places))]
        print(f"{net}: {len(cells)} reachable cells, {len(none)} that no seed can aim at "
              f"({time.perf_counter() - t0:.1f} s)")
        for c in none:
            print(f"    {c}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
