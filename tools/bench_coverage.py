"""What interaction coverage costs per execution: the corpus scenarios of a campaign, run again.

For the first N scenarios under ``OUT/corpus/`` (real SUMO, the reference ADS): the execution's wall time, the
risk score's, and :func:`drivefuzz.triage.coverage.execution_cells` (warm: after one call, mean of five), as a
share of the execution. Usage::

    python tools/bench_coverage.py OUT [N=25]

Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def main(argv: list[str]) -> int:
    from drivefuzz.ads import load_ads
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.sumofiles import load_scenario
    from drivefuzz.search.risk import risk_score
    from drivefuzz.sim.execute import execute
    from drivefuzz.triage.coverage import close_encounters, execution_cells

    if not argv:
        print(__doc__.strip().splitlines()[-3], file=sys.stderr)
        return 2
    refs = sorted(p for p in (Path(argv[0]) / "corpus").iterdir() if (p / "scenario.json").is_file())
    refs = refs[:int(argv[1]) if len(argv) > 1 else 25]
    t_exec = t_risk = t_cells = 0.0
    encounters = 0
    for ref in refs:
        sc = load_scenario(ref)
        rmap = load_roadmap(sc.network_path())
        t = time.perf_counter()
        ex = execute(sc, ads=load_ads("ego"), oracles=[])
        t_exec += time.perf_counter() - t
        t = time.perf_counter()
        r = risk_score(ex.trace)
        t_risk += time.perf_counter() - t
        execution_cells(sc, ex.trace, rmap, r)  # warm: the map's features and the route are cached
        t = time.perf_counter()
        for _ in range(5):
            execution_cells(sc, ex.trace, rmap, r)
        t_cells += (time.perf_counter() - t) / 5
        encounters += len(close_encounters(r))
    n = max(len(refs), 1)
    print(f"{len(refs)} executions, {encounters} close encounters: execution {1000 * t_exec / n:.0f} ms, risk score "
          f"{1000 * t_risk / n:.1f} ms, execution_cells {1000 * t_cells / n:.2f} ms per execution "
          f"({100 * t_cells / max(t_exec, 1e-9):.2f} % of the execution)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
