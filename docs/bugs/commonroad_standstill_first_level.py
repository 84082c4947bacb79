"""Reproducer: at rest, TUM's reactive planner returns its standstill trajectory when the first sampling level's
best sample stands still, without trying its denser levels, which hold moving, feasible, collision-free samples
(docs/bugs/commonroad-reactive-planner.md, bug 10).

The planner alone, as the adapter sets it up for the committed seed ``seeds/interchange/001`` (default frame,
the reference window the closed-loop run had then, the road boundary in the collision checker, nothing else):
the car at rest 2.3 m before the stop line of a left turn (the frame's curvature rises to 0.18 1/m within 8 m),
the light green, asked for 4.18 m/s: the state of the closed-loop run with ``level_fix=false`` at t = 100 s,
where it stood for good. ``plan()`` as shipped, then each sampling level on its own
(``plan(current_sampling_level=...)``). Run: ``python docs/bugs/commonroad_standstill_first_level.py``.
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

from adapters.commonroad.base import CarState, reference_window  # noqa: E402
from adapters.commonroad.reactive import ReactivePlannerADS  # noqa: E402

#: the car's rear axle [m], heading [rad], at rest, its road wheels at 0.049 rad
AT_REST = CarState(-1.7340, -49.6824, -1.51664, 0.0, 0.0, 0.0, 0.04877)
#: [m] where the closed-loop run's reference window began then (``ads_info.cycles.ref_from``)
WINDOW_FROM = 231
V_DES = 4.1804


def ads_at_the_stop_line(options: dict) -> ReactivePlannerADS:
    """A ``commonroad-reactive`` ADS with ``options`` set up for seeds/interchange/001's mission, with the reference
    window the closed-loop run had at the stop line of its left turn (where :data:`AT_REST` stands)."""
    sc = load_scenario(ROOT / "seeds" / "interchange" / "001")
    m = sc.mission
    rmap = load_roadmap(sc.network_path())
    gx, gy, _ = rmap.geom(rmap.drive_lane(m.goal_edge)).position(m.goal_pos)
    mission = MissionInfo(m.start_lane, m.start_pos, m.goal_edge, m.goal_pos, (gx, gy),
                          rmap.route(m.start_edge, m.goal_edge), 0.05, sc.seed)
    ads = ReactivePlannerADS(options)
    ads.reset(mission, rmap)
    ads.window = reference_window(ads.ref_pts, WINDOW_FROM + 30)
    ads.set_reference(ads.ref_pts[ads.window[0]:ads.window[1]])
    return ads


def standing_then_levels(level_fix: bool) -> list[tuple[str, float | None]]:
    """(what was asked, the plan's top speed or None) for ``plan()`` and then each level on its own."""
    # the road boundary as the closed-loop run had it (its boxes reached past every end, 0.25 m into the road at
    # kerbs: the adapter's mistake 6); with the corrected boundary the first level moves at this state
    ads = ads_at_the_stop_line({"level_fix": level_fix, "boundary_ends": "every_end"})
    checker = pycrcc.CollisionChecker()
    checker.add_collision_object(ads.boundary)
    plan = ads.plan(AT_REST, checker, V_DES)
    out = [(f"the adapter's plan(), level_fix={str(level_fix).lower()}",
            None if plan is None else float(max(plan.v)))]
    planner = ads.planner
    for level in range(1, planner.sampling_level):
        try:
            res = planner.plan(current_sampling_level=level)
            out.append((f"level {level} alone", None if res is None else max(s.velocity for s in res[0].state_list)))
        except TypeError as exc:  # bug 6: a level with no feasible sample at all
            out.append((f"level {level} alone: TypeError {exc}", None))
    return out


def main() -> int:
    for fix in (False, True):
        for label, top in standing_then_levels(fix):
            print(f"{label}: {'None' if top is None else f'top speed {top:.2f} m/s'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
