"""Reproducer: TUM's reactive planner computes the car's curvilinear state in the previous cycle's velocity
mode, so the first cycle below ``low_vel_mode_threshold`` (4 m/s) finds no feasible trajectory
(docs/bugs/commonroad-reactive-planner.md, bug 3).

The planner alone: the reference path the adapter builds for the committed seed ``seeds/highway/001`` (the
off-ramp, curvature at most 0.21 1/m, the car's limit 0.245), an empty collision checker (no road boundary,
no other road users: nothing the adapter adds), and one state taken from the closed-loop run (rear axle,
heading, road-wheel angle, acceleration), planned at 4.05 m/s, then twice with the same inputs at 3.95 m/s:
as shipped, the first of the two returns None (every sample breaks the curvature limit), the second a plan.
Then the same with the velocity mode set before ``reset()``. Run: ``python docs/bugs/commonroad_low_speed_mode.py``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import commonroad_dc.pycrcc as pycrcc

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from drivefuzz.ads import MissionInfo  # noqa: E402
from drivefuzz.scenario.roadmap import load_roadmap  # noqa: E402
from drivefuzz.scenario.sumofiles import load_scenario  # noqa: E402

from adapters.commonroad.base import CarState  # noqa: E402
from adapters.commonroad.reactive import ReactivePlannerADS  # noqa: E402


def main() -> int:
    sc = load_scenario(ROOT / "seeds" / "highway" / "001")
    m = sc.mission
    rmap = load_roadmap(sc.network_path())
    route = rmap.route(m.start_edge, m.goal_edge)
    gx, gy, _ = rmap.geom(rmap.drive_lane(m.goal_edge)).position(m.goal_pos)
    for fix in (False, True):
        print("as shipped:" if not fix else "with the velocity mode set before reset() (mode_fix=true):")
        ads = ReactivePlannerADS({"mode_fix": fix})
        mission = MissionInfo(m.start_lane, m.start_pos, m.goal_edge, m.goal_pos, (gx, gy), route, 0.05, sc.seed)
        ads.reset(mission, rmap)
        # rear axle x, y [m], heading [rad], road-wheel angle [rad], acceleration [m/s^2] from the closed-loop run
        x, y, h, steer, accel = 345.6, -8.9, -0.10, -0.116, -2.62
        for label, v in (("4.05 m/s (high-velocity mode)", 4.05), ("3.95 m/s, right after it", 3.95),
                         ("3.95 m/s again, the same inputs", 3.95)):
            state = CarState(x, y, h, v, accel, v * math.tan(steer) / 2.8, steer)
            plan = ads.plan(state, pycrcc.CollisionChecker(), desired_speed=3.96)
            p = ads.planner
            got = "None" if plan is None else f"a plan ending at {plan.v[-1]:.2f} m/s"
            print(f"{label}: {got}; {p.infeasible_count_kinematics} of {p.total_count_samples} samples kinematically "
                  f"infeasible {dict(p.infeasible_reason_dict)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
