"""How smoothly the reference ADS drives the committed seeds, and how it adapts to fog.

Runs every committed seed (``seeds/<net>/NNN``) clean, with the reference ADS (plugin ``ego``)
and the default oracles, and prints per network: the hard-braking frames (the driving-quality
score's ``#hb``: body-frame ``ax/g <= -0.6``, :func:`drivefuzz.search.quality.score_trace`), the
mean mission time [s] (simulated time at the end of the run), and how many seeds reached the goal
with no misbehaviour. With ``--fog F`` it also runs one seed in clear weather and in fog ``F``
and prints the ego's cruise speed in each (the 90th percentile of its speed [m/s] over the run).

Usage::

    python tools/eval_smoothness.py [--nets town,highway,...] [--fog 100] [--fog-seed highway/004]

A benchmark, not a test (STYLE.md rule 17): it prints figures; tests/test_ads_smooth.py asserts
the behaviour.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from drivefuzz.ads import load_ads  # noqa: E402
from drivefuzz.oracle import OracleSettings, Termination  # noqa: E402
from drivefuzz.scenario.seed import list_seeds  # noqa: E402
from drivefuzz.scenario.sumofiles import load_scenario  # noqa: E402
from drivefuzz.search.quality import score_trace  # noqa: E402
from drivefuzz.sim.execute import execute  # noqa: E402

NETS = ("town", "highway", "interchange", "intersection", "roundabout")


def run_clean(folder: Path, weather: dict | None = None):
    """(execution, #hb) of ``folder``'s seed run clean with the reference ADS (optionally other weather)."""
    sc = load_scenario(folder)
    if weather:
        sc = sc.model_copy(update={"weather": sc.weather.model_copy(update=weather)})
    ex = execute(sc, ads=load_ads("ego"), oracles=OracleSettings().instantiate())
    return ex, score_trace(ex.trace).hb


def cruise_speed(trace) -> float:
    """[m/s] the ego's top speed over the run."""
    return float(np.max(trace["speed"]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nets", default=",".join(NETS), help="comma-separated networks (default: all five)")
    ap.add_argument("--fog", type=float, default=100.0, help="fog density for the fog comparison (0: skip)")
    ap.add_argument("--fog-seed", default="highway/004",
                    help="seed of the fog comparison, NET/NNN (default: a long, fast mission)")
    args = ap.parse_args(argv)

    total_hb, times, passed, n = 0, [], 0, 0
    t0 = time.perf_counter()
    print(f"{'network':<14}{'seeds':>6}{'#hb':>6}{'worst':>7}{'mission s':>11}{'pass':>6}")
    for net in args.nets.split(","):
        hbs, net_times, net_pass = [], [], 0
        for folder in list_seeds(REPO / "seeds" / net):
            ex, hb = run_clean(folder)
            hbs.append(hb)
            net_times.append(float(ex.trace["t"][-1]))
            net_pass += ex.termination is Termination.GOAL_REACHED and not ex.misbehaviors
            if hb:
                print(f"  {net}/{folder.name}: {hb} hard-braking frames")
        total_hb += sum(hbs)
        times += net_times
        passed += net_pass
        n += len(hbs)
        print(f"{net:<14}{len(hbs):>6}{sum(hbs):>6}{max(hbs, default=0):>7}"
              f"{np.mean(net_times):>11.1f}{net_pass:>6}")
    print(f"{'all':<14}{n:>6}{total_hb:>6}{'':>7}{np.mean(times):>11.2f}{passed:>6}")
    print(f"hard-braking frames over {n} clean seeds: {total_hb}; mean mission time {np.mean(times):.2f} s; "
          f"{passed}/{n} reached the goal clean ({time.perf_counter() - t0:.0f} s)")

    if args.fog > 0:
        folder = REPO / "seeds" / args.fog_seed
        clear, _ = run_clean(folder)
        fog, fog_hb = run_clean(folder, {"fog": args.fog})
        print(f"{args.fog_seed}: cruise (top) speed clear {cruise_speed(clear.trace):.2f} m/s, "
              f"fog {args.fog:g} {cruise_speed(fog.trace):.2f} m/s; mission time clear "
              f"{clear.trace['t'][-1]:.1f} s, fog {fog.trace['t'][-1]:.1f} s "
              f"({fog.termination.value}, {fog_hb} hard-braking frames in fog)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
