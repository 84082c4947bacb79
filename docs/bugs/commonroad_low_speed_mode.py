"""Reproducer: TUM's reactive planner finds no trajectory once the car slows below ``low_vel_mode_threshold``
in a bend it was planning through a moment before (docs/bugs/commonroad-reactive-planner.md, bug 3).

The planner alone: the reference path the adapter builds for the committed seed ``seeds/highway/001`` (the
off-ramp, curvature at most 0.21 1/m, the car's limit 0.245), an empty collision checker (no road boundary,
no other road users: nothing the adapter adds), and one initial state taken from the closed-loop run
(rear axle, heading, acceleration, road-wheel angle), planned twice: at 4.05 m/s and at 3.95 m/s, either
side of the planner's 4.0 m/s low-velocity threshold. Run: ``python docs/bugs/commonroad_low_speed_mode.py``.
"""

from __future__ import annotations

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
    ads = ReactivePlannerADS({})
    ads.reset(MissionInfo(m.start_lane, m.start_pos, m.goal_edge, m.goal_pos, (gx, gy), route, 0.05, sc.seed), rmap)
    for v in (4.05, 3.95):
        state = CarState(345.6, -8.9, -0.10, v, -2.62, v * 0.0, -0.116)
        plan = ads.plan(state, pycrcc.CollisionChecker(), desired_speed=3.96)
        p = ads.planner
        print(f"v0 = {v:.2f} m/s: {'a trajectory' if plan is not None else 'None'}; "
              f"{p.infeasible_count_kinematics} of {p.total_count_samples} samples kinematically infeasible "
              f"{dict(p.infeasible_reason_dict)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
