"""Reproducer: at rest in a tight bend, TUM's reactive planner found no moving trajectory and returned its
standstill trajectory, cycle after cycle, on the frame the adapter used to build (the adapter's mistake 5 in
docs/bugs/commonroad-reactive-planner.md; it was read as limitation 8 until issue 32's third session).

The planner alone: the reference path the adapter builds for the committed seed ``seeds/roundabout/001`` (the
entry into the ring: curvature up to 0.17 1/m, the car's limit 0.245), an empty collision checker (no road
boundary, no other road users), the planner's own settings but the horizon (the adapter's 3 s; its default 6 s
is shown too). The car at rest on the reference, then turned 0.04 rad to the left of it, then the state at
which the closed-loop run got None (rear axle 5 cm right of the reference, 0.04 rad, its road wheels at
-0.094 rad) brought to rest. Each on three frames (the option ``frame``): ``resample``, the adapter before the
fix (its heading turns in steps at SUMO's shape vertices while its curvature is smooth, and the planner's
yaw-rate check reads the heading); ``chaikin``, the default now (the path sampled 2 m apart and smoothed by
Chaikin's corner cutting, as CommonRoad's route planner builds reference paths); ``spline``, preprocessed as
the planner's own ``create_coordinate_system`` does. Run: ``python docs/bugs/commonroad_rest_in_bend.py``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import commonroad_dc.pycrcc as pycrcc
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from drivefuzz.ads import MissionInfo  # noqa: E402
from drivefuzz.scenario.roadmap import load_roadmap  # noqa: E402
from drivefuzz.scenario.sumofiles import load_scenario  # noqa: E402

from adapters.commonroad.base import CarState  # noqa: E402
from adapters.commonroad.reactive import ReactivePlannerADS  # noqa: E402


def main() -> int:
    sc = load_scenario(ROOT / "seeds" / "roundabout" / "001")
    m = sc.mission
    rmap = load_roadmap(sc.network_path())
    route = rmap.route(m.start_edge, m.goal_edge)
    gx, gy, _ = rmap.geom(rmap.drive_lane(m.goal_edge)).position(m.goal_pos)
    mission = MissionInfo(m.start_lane, m.start_pos, m.goal_edge, m.goal_pos, (gx, gy), route, 0.05, sc.seed)
    at_rest = CarState(-1.8642, 32.2134, -1.6675, 0.0, 0.0, 0.0, -0.0943)  # the closed-loop run's state, at rest
    for frame in ("resample", "chaikin", "spline"):
        for horizon in (3.0, 6.0):
            ads = ReactivePlannerADS({"horizon": horizon, "frame": frame})
            ads.reset(mission, rmap)
            co = ads.planner.coordinate_system
            s, _ = co.convert_to_curvilinear_coords(at_rest.x, at_rest.y)  # the same place on either frame
            x, y = co.convert_to_cartesian_coords(s, 0.0)
            (x0, y0), (x1, y1) = co.convert_to_cartesian_coords(s - 0.5, 0.0), co.convert_to_cartesian_coords(s + 0.5, 0.0)
            h = math.atan2(y1 - y0, x1 - x0)
            (xa, ya), (xb, yb) = co.convert_to_cartesian_coords(s - 1.0, 0.0), co.convert_to_cartesian_coords(s + 1.0, 0.0)
            k = (math.atan2(yb - y, xb - x) - math.atan2(y - ya, x - xa)) / 1.0  # the reference's curvature there
            pos, kk = np.asarray(co.ref_pos), np.asarray(co.ref_curv)
            turn = np.diff(np.unwrap(np.asarray(co.ref_theta))) / np.diff(pos)
            mismatch = float(np.max(np.abs(turn - (kk[1:] + kk[:-1]) / 2.0)))
            cases = (("at rest on the reference", CarState(x, y, h, 0.0, 0.0, 0.0, math.atan(2.8 * k))),
                     ("at rest, turned 0.04 rad left of it", CarState(x, y, h + 0.04, 0.0, 0.0, 0.0, math.atan(2.8 * k))),
                     ("at rest, the closed-loop run's state", at_rest))
            print(f"frame={frame}, horizon {horizon:.0f} s: the frame's heading turns up to {mismatch:.3f} 1/m more or less "
                  f"than its curvature; reference curvature here {k:+.3f} 1/m")
            for label, state in cases:
                plan = ads.plan(state, pycrcc.CollisionChecker(), desired_speed=3.57)
                p = ads.planner
                got = "None" if plan is None else f"a plan reaching {max(plan.v):.2f} m/s"
                print(f"  {label}: {got}; {p.infeasible_count_kinematics} samples kinematically infeasible "
                      f"{dict(p.infeasible_reason_dict)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
