"""What a network's size costs: seed generation, the first execution against later ones, and one
``drivefuzz run`` against SUMO alone. The figures of issue 16 for any network.

    python tools/bench_network.py NET [--seeds 4] [--runs 5] [--cli-runs 5]

1. ``drivefuzz seed NET -n 4`` in a child process: wall time and peak RSS;
2. in this process, the first execution of the first seed (it loads the road map and builds the oracles'
   indexes) against the median of ``--runs`` later executions of the same seed;
3. ``drivefuzz run SEED`` in a child process against ``sumo -c SEED/scenario.sumocfg`` for the same
   simulated time (the seed's actors and puddles, no ADS): the medians of ``--cli-runs`` wall times each,
   taken in turn, and their ratio.

Prints only; a benchmark, not a test. SUMO_HOME's bundled cities: tools/game/DRT/osm.net.xml (Berlin),
tools/game/fkk_in/ingolstadt.net.xml.gz (Ingolstadt).
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def _child(cmd: list[str]) -> tuple[float, str]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(cmd)} failed: {proc.stderr.strip()[-500:]}")
    return time.perf_counter() - t0, proc.stdout


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("network", type=Path)
    ap.add_argument("--seeds", type=int, default=4, help="seeds to generate [4]")
    ap.add_argument("--runs", type=int, default=5, help="later executions to time [5]")
    ap.add_argument("--cli-runs", type=int, default=5, help="drivefuzz run and SUMO alone, each [5]")
    args = ap.parse_args(argv)
    if args.runs < 1 or args.cli_runs < 1 or args.seeds < 1:
        ap.error("--seeds, --runs and --cli-runs must be at least 1")
    import drivefuzz
    from drivefuzz.oracle import OracleSettings
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import read_scenario
    from drivefuzz.sim.execute import execute

    drivefuzz_cli = str(Path(sys.executable).with_name("drivefuzz"))
    with tempfile.TemporaryDirectory(prefix="bench-network-") as tmp:
        seeds_dir = Path(tmp) / "seeds"
        wall_seed, _ = _child([drivefuzz_cli, "seed", str(args.network), "-n", str(args.seeds), "-o", str(seeds_dir)])
        rss_seed = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        seeds = list_seeds(seeds_dir)
        if not seeds:
            raise SystemExit(f"no seed could be generated on {args.network}")
        print(f"network {args.network.name}: drivefuzz seed -n {args.seeds}: {wall_seed:.1f} s, "
              f"peak RSS {rss_seed:.0f} MB ({len(seeds)} seeds)")

        sc = read_scenario(seeds[0])
        times = []
        for _ in range(args.runs + 1):
            t0 = time.perf_counter()
            ex = execute(sc, oracles=OracleSettings().instantiate())
            times.append(time.perf_counter() - t0)
        later = statistics.median(times[1:])
        print(f"first execution {times[0]:.2f} s, later ones (median of {args.runs}) {later:.2f} s: "
              f"ratio {times[0] / later:.2f} (goal: at most 2)")

        end = float(ex.trace["t"][-1])
        sumo_cmd = [drivefuzz.sumo_binary("sumo"), "-X", "never", "-c", str(seeds[0] / "scenario.sumocfg"),
                    "--end", repr(end), "--no-step-log", "true", "--no-warnings", "true"]
        runs, sumos = [], []
        for _ in range(args.cli_runs):  # interleaved, so that a slow spell of the machine hits both
            runs.append(_child([drivefuzz_cli, "run", str(seeds[0])])[0])
            sumos.append(_child(sumo_cmd)[0])
        wall_run, wall_sumo = statistics.median(runs), statistics.median(sumos)
        print(f"drivefuzz run of a seed {wall_run:.2f} s, SUMO alone on its files for the same {end:.1f} simulated s "
              f"{wall_sumo:.2f} s (medians of {args.cli_runs}): ratio {wall_run / wall_sumo:.2f} (goal: at most 3)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
