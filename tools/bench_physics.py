"""Micro-benchmark of drivefuzz.sim.physics: microseconds per ``VehiclePhysics.step()`` call.

Usage: ``python tools/bench_physics.py [--dt 0.05] [--calls 20000] [--repeats 7]``

For each speed (1, 15 and 35 m/s) the car is put on a mildly curved, speed-holding
trajectory (so every code path of a normal step runs: dynamic or kinematic lateral
model, drive force, load transfer) and ``step()`` is timed in batches; the figure printed
is the median over ``repeats`` batches of the mean per call, plus the minimum batch.
Each batch restarts from the same state, so the car stays near the nominal speed.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from drivefuzz.sim.physics import VehicleParams, VehiclePhysics, place_state  # noqa: E402


def bench(speed: float, dt: float, calls: int, repeats: int) -> tuple[float, float]:
    params = VehicleParams()
    start = place_state(0.0, 0.0, 0.0, speed, params)
    # throttle that roughly holds the speed (drag + rolling resistance), a small steer
    resist = params.rolling_resistance * params.mass * 9.81 + 0.5 * params.air_density * params.drag_area * speed**2
    throttle = min(1.0, resist / min(params.max_drive_force, params.max_power / max(speed, 1.0)))
    steer = 0.05
    per_call = []
    for _ in range(repeats):
        ph = VehiclePhysics(params, start)
        step = ph.step
        t0 = time.perf_counter()
        for _ in range(calls):
            step(steer, throttle, 0.0, dt, 1.0, 1.0, 0.0)
        per_call.append((time.perf_counter() - t0) / calls * 1e6)
    return statistics.median(per_call), min(per_call)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dt", type=float, default=0.05)
    ap.add_argument("--calls", type=int, default=20000)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args(argv)
    n_sub = max(1, -(-round(args.dt * 1e6) // round(VehicleParams().max_substep * 1e6)))
    print(f"VehiclePhysics.step() at dt={args.dt} s ({n_sub} internal sub-steps), "
          f"{args.calls} calls x {args.repeats} batches, Python {sys.version.split()[0]}")
    for speed in (1.0, 15.0, 35.0):
        med, best = bench(speed, args.dt, args.calls, args.repeats)
        print(f"  {speed:5.1f} m/s: median {med:6.2f} us/step   (best batch {best:6.2f} us/step)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
