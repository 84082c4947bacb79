"""Which encounters does a campaign classify into cells that the derivation does not offer, and how were they read?

The share of interaction coverage is of the derived cells (:func:`drivefuzz.triage.coverage.reachable`), so a cell
a campaign reaches outside them is either a case the derivation misses or a reading the classifier gets wrong. This
runs one campaign (as ``tools/eval_coverage.py`` runs one repetition: the clean reference ADS, strategy all,
population 8, the repetition's number as the seed) and prints, for every close encounter of an execution that lands
outside, one JSON line: its cells, the ego's lane at the encounter and 2 s before (where the party is read), the
other party's place and heading against the ego's heading then (``rel``, ``dh_deg``) and along the path the ego
drives (``along``: forward, left, heading against the ego's way there), and whether it moved. The scenario of each
such execution is kept under ``--keep`` to be replayed. Usage::

    python tools/eval_coverage.py --from-dump N.json                         # which cells, in which repetitions
    python tools/outside_cells.py --network roundabout --rep 4 --execs 1000 --keep /tmp/outside
    python tools/outside_cells.py --network town --rep 0 --cells "vehicle/right|turn_right"   # a derived cell too

Prints only; a measurement, not a test.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def reading(scenario, trace, rmap, actor: str | None, f: int, cells: list[str]) -> dict:
    """What the classifier read for the encounter with ``actor`` at frame ``f``."""
    from drivefuzz.triage import coverage as cov
    from drivefuzz.triage.evidence import actor_track, along_path, to_local

    out: dict = {"actor": actor, "frame": f, "cells": cells, "ego_lane": str(trace["lane"][f]),
                 "speed": round(float(trace["speed"][f]), 1)}
    track = actor_track(trace, actor) if actor else None
    if track is None:
        return out
    k0 = max(f - int(round(cov.APPROACH_S / trace.step_length)), 0)
    k = next((j for j in range(k0, f + 1) if track.present(j)), f)
    x, y = float(track.x[k]), float(track.y[k])
    lx, ly = to_local(trace, k, x, y)
    ax, ay, way = along_path(trace, k, x, y, heading=True)
    h = float(track.heading[k])
    out.update(read_at=k, ego_lane_then=str(trace["lane"][k]), kind=track.kind, rel=[round(lx, 1), round(ly, 1)],
               dh_deg=round(math.degrees(cov.wrap_angle(h - float(trace["heading"][k])))),
               along=[round(ax, 1), round(ay, 1), round(math.degrees(cov.wrap_angle(h - way)))],
               moved=bool(any(float(v) > 0.5 for v in track.speed[k:f + 1] if math.isfinite(float(v)))))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--network", required=True, help="a committed seed set (town, intersection, ...)")
    ap.add_argument("--rep", type=int, default=0, help="the repetition (the campaign's seed) [0]")
    ap.add_argument("--execs", type=int, default=1000, help="executions [1000]")
    ap.add_argument("--keep", default="", help="a folder for the scenarios of the executions that land outside")
    ap.add_argument("--cells", default="", help="comma-separated cell keys (or parts of them) to print too, derived "
                                                "or not: how a rare cell was read")
    args = ap.parse_args(argv)

    import drivefuzz.triage.coverage as cov
    from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
    from drivefuzz.scenario import AdsSpec
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario, write_scenario

    seeds = [read_scenario(p) for p in list_seeds(REPO / "seeds" / args.network)]
    derived: set[str] = set()
    watch = [w for w in args.cells.split(",") if w]
    count = [0, 0, 0]  # executions; with a cell outside the derivation; with a watched derived cell
    classify_cells = cov.execution_cells

    def watched(scenario, trace, rmap, risk, near=False):
        """The fuzz job's call, unchanged; the encounters outside the derivation printed on the side."""
        cells = classify_cells(scenario, trace, rmap, risk, near)
        count[0] += not near
        if near:
            return cells
        if not derived:
            derived.update(cov.reachable(rmap, seeds))
        outside = {c for c in cells if c not in derived or any(w in c for w in watch)}
        if not outside:
            return cells
        count[1] += any(c not in derived for c in outside)
        count[2] += any(c in derived for c in outside)
        if args.keep:
            write_scenario(scenario, Path(args.keep) / scenario.content_hash())
        for actor, f in cov.close_encounters(risk):
            mine = [c for c in cov.classify(scenario, trace, rmap, actor, f).cells() if c in outside]
            if mine:
                seen = reading(scenario, trace, rmap, actor, f, mine)
                print(json.dumps({"scenario": scenario.content_hash(), **seen}), flush=True)
        return cells

    cov.execution_cells = watched  # the job imports it from the module when it runs
    cfg = FuzzConfig(population=8, strategy="all", seed=args.rep, max_execs=args.execs, feedback="risk",
                     ads=AdsSpec(name="ego", options={}), reproduce=0, shrink=0)
    with tempfile.TemporaryDirectory(prefix="outside-cells-") as tmp:
        Campaign(Path(tmp) / "out", seeds, cfg).run()
    print(f"{args.network} rep {args.rep}: {count[1]} of {count[0]} executions reached a cell outside the derivation"
          + (f", {count[2]} one of the watched cells (--cells)" if watch else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
