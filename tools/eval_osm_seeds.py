"""Seed verification on OSM-imported cities: how many random missions the dry run rejects, and why.

    python tools/eval_osm_seeds.py [--missions N] [--rng-seed S] [--net berlin|ingolstadt|PATH ...]
                                   [--oracle NAME.KEY=VALUE ...] [--details] [--save DIR]

For each network, draws ``N`` candidate seeds with :func:`drivefuzz.scenario.seed.random_missions`
(the missions ``drivefuzz seed`` would try) and drives each with the clean reference ADS and every
built-in oracle on, as :func:`drivefuzz.sim.verify.dry_run` does. Prints, per network, the rejection
rate and the reasons (``oracle/kind`` of the first misbehaviour, or the termination), and with
``--details`` every lane-invasion record (where the corner was, which lane, how deep).

The default networks are SUMO's own OSM imports: ``$SUMO_HOME/tools/game/DRT/osm.net.xml`` (Berlin)
and ``$SUMO_HOME/tools/game/fkk_in/ingolstadt.net.xml.gz``. ``--oracle`` passes oracle settings, as
``drivefuzz seed --oracle`` would (e.g. ``lane_invasion.min_duration=0`` to see the old behaviour).
``--save DIR`` writes each rejected candidate as a scenario folder (``drivefuzz run DIR/<name>``).
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _networks(names: list[str]) -> list[Path]:
    import drivefuzz  # noqa: F401 - sets SUMO_HOME

    game = Path(os.environ["SUMO_HOME"]) / "tools" / "game"
    known = {"berlin": game / "DRT" / "osm.net.xml", "ingolstadt": game / "fkk_in" / "ingolstadt.net.xml.gz"}
    return [known.get(n, Path(n)) for n in names]


def evaluate(net: Path, n: int, rng_seed: int, settings, details: bool, save: Path | None) -> Counter:
    from drivefuzz.ads import load_ads
    from drivefuzz.oracle import Termination
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.seed import random_missions
    from drivefuzz.sim.execute import execute

    rmap = load_roadmap(net)
    reasons: Counter = Counter()
    t0 = time.perf_counter()
    for k, cand in enumerate(random_missions(rmap, random.Random(rng_seed), str(net.resolve()))):
        if k >= n:
            break
        ex = execute(cand, ads=load_ads("ego"), oracles=settings.instantiate())
        if ex.misbehaviors:
            m = ex.misbehaviors[0]
            why = f"{m.oracle}/{m.kind}"
            if details and m.oracle == "lane_invasion":
                d = m.details
                print(f"  {k:3d} t={m.time:6.2f} {m.kind:13s} corner {d['corner']} at {d['corner_xy']} in "
                      f"{d['lane'] or '-'!s:20s} ego on {d['ego_lane']!s:20s} depth {d['depth']} "
                      f"for {d.get('duration', '-')} s ({cand.mission.start_lane} -> {cand.mission.goal_edge})")
        elif ex.termination is not Termination.GOAL_REACHED:
            why = ex.termination.value
        else:
            why = "ok"
        reasons[why] += 1
        if why != "ok" and save is not None:
            from drivefuzz.scenario.sumofiles import write_scenario

            write_scenario(cand.model_copy(update={"name": f"{net.stem}-{k:03d}"}), save / f"{net.stem}-{k:03d}")
    reasons["_wall"] = round(time.perf_counter() - t0)
    return reasons


def main(argv=None) -> int:
    from drivefuzz.oracle import parse_oracle_options

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--missions", "-n", type=int, default=30, help="candidate missions per network")
    ap.add_argument("--rng-seed", type=int, default=0)
    ap.add_argument("--net", nargs="+", default=["berlin", "ingolstadt"], help="berlin, ingolstadt or a path")
    ap.add_argument("--oracle", action="append", default=[], help="NAME.KEY=VALUE")
    ap.add_argument("--details", action="store_true", help="print every lane-invasion record")
    ap.add_argument("--save", type=Path, default=None)
    args = ap.parse_args(argv)
    settings = parse_oracle_options(args.oracle)
    for net in _networks(args.net):
        print(f"{net.name}:")
        reasons = evaluate(net, args.missions, args.rng_seed, settings, args.details, args.save)
        wall = reasons.pop("_wall")
        total = sum(reasons.values())
        rejected = total - reasons["ok"]
        lane = sum(v for k, v in reasons.items() if k.startswith("lane_invasion/"))
        print(f"  rejected {rejected}/{total} ({100.0 * rejected / max(total, 1):.0f} %), "
              f"as lane invasion {lane}/{total} ({100.0 * lane / max(total, 1):.0f} %)  [{wall} s]")
        for why, count in reasons.most_common():
            if why != "ok":
                print(f"    {count:3d}  {why}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
