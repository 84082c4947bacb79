"""``commonroad-reactive``: TUM's CommonRoad reactive planner (``commonroad-reactive-planner`` 2025.1).

A sampling-based Frenet planner: quartic/quintic polynomials in the curvilinear frame of the reference
path, ranked by cost, checked for kinematic feasibility and then for collisions with the
drivability checker's C++ checker (``pycrcc``); a standstill trajectory when the car is at rest.
This subclass only sets it up and calls it; everything else is :class:`adapters.commonroad.base.CommonRoadADS`.

Set-up, as measured (issue 32): ``debug.multiproc`` off (with it each plan starts six processes
and is 2.5x slower); the planner's constructor insists on a CommonRoad scenario, so it gets an
empty one and a planning problem at the start; the reference path goes in as a coordinate
system (``set_reference_path(reference_path=...)`` fails with commonroad-clcs 2025.x), preprocessed as the
planner's own ``create_coordinate_system`` does (a cubic smoothing spline, resampled 0.5-1 m apart: option
``frame``; resampled only, the frame's heading turned in steps at SUMO's shape vertices while its
curvature did not, and at low speed in a bend the yaw-rate check refused every sample; the base class has
already opened the bends to what the car can turn; the frame's curve subdivision cut the interchange's tight
left turns by 2.2 m, into the opposite lanes); the car is
drivefuzz's (wheelbase, 0.6 rad road-wheel angle, 0.8 rad/s steering rate, 9 m/s^2 braking and
the power limit as CommonRoad's switching speed), not the default BMW 320i, whose steering rate
rejects every sample of a 90-degree town turn. ``set_desired_velocity`` ignores the requested speed
when ``current_speed == 0.0`` (it takes the planning problem's speed instead, and a car at rest stays
there), so a car at rest is passed as moving at :data:`AT_REST` m/s (option ``rest_fix``, on by default).

One fix of the planner's contract (option ``domain_shim``, on by default): its kinematic check asks the
coordinate system for each sample's Cartesian points and treats None as "out of the projection domain,
infeasible"; commonroad-clcs 2025.x (which the planner's own requirements bring) raises
``CurvilinearProjectionDomainLateralError`` or ``...LongitudinalError`` instead, so one sample that
leaves the domain aborts the whole cycle (on the town seed 000, 36 of 324 cycles on a straight road with
the first, unsmoothed reference; the trace's ``ads_info.domain_shim_caught`` counts the catches).
:class:`DomainAsNone` turns those two exceptions back into None; ``domain_shim=false`` shows the
planner as installed. docs/bugs/commonroad-reactive-planner.md, bug 1. A second fix (option ``mode_fix``,
on by default) sets the planner's velocity mode before ``reset()`` converts the car's state (bug 3), and a
third (``rest_fix``) passes a car at rest as barely moving to ``set_desired_velocity`` (bug 2), and a fourth
(``level_fix``) asks the planner's denser sampling levels when, at rest, ``plan()`` stood still on its first (bug 10).
Both are recorded in the options the trace's scenario carries; every other setting is the planner's own.
"""

from __future__ import annotations

import logging
import warnings

import numpy as np
from typing import Literal

from pydantic import Field

with warnings.catch_warnings():  # commonroad-io's generated protobuf code and the route planner warn on import
    warnings.simplefilter("ignore", DeprecationWarning)
    from commonroad.common.util import Interval
    from commonroad_clcs.config import CLCSParams, ProcessingOption, ResamplingOption
    from commonroad_clcs.pycrccosy import (CurvilinearProjectionDomainLateralError,
                                           CurvilinearProjectionDomainLongitudinalError)
    from commonroad.planning.goal import GoalRegion
    from commonroad.planning.planning_problem import PlanningProblem
    from commonroad.scenario.scenario import Scenario
    from commonroad.scenario.state import CustomState, InitialState
    from commonroad_rp.reactive_planner import ReactivePlanner
    from commonroad_rp.state import ReactivePlannerState
    from commonroad_rp.utility.config import ReactivePlannerConfiguration
    from commonroad_rp.utility.utils_coordinate_system import CoordinateSystem
    from commonroad_route_planner.utility.route_util import chaikins_corner_cutting

from drivefuzz.sim.physics import VehicleParams

from adapters.commonroad.base import CarState, CommonRoadADS, Plan
from adapters.commonroad.scene import _resample

#: [m/s] the speed a car at rest is given for ``set_desired_velocity`` (see the module docstring).
AT_REST = 1e-3
#: [m/s] the planner's own test for standing still (``plan()``'s standstill check)
STANDING = 0.05
#: [s] after the denser sampling levels found nothing that moves (``level_fix``), they are asked again only this
#: much later while the car stays at rest: a stuck cycle that walks them costs about 25 first-level plans
LEVEL_RETRY = 2.0


def planner_config(params: VehicleParams, dt: float, steps: int) -> ReactivePlannerConfiguration:
    """The planner's configuration for drivefuzz's car, a horizon of ``steps`` x ``dt`` seconds."""
    config = ReactivePlannerConfiguration()
    config.planning.dt = dt
    config.planning.time_steps_computation = steps
    config.planning.planning_horizon = dt * steps
    config.debug.multiproc = False
    config.debug.logging_level = "ERROR"
    v = config.vehicle
    v.length, v.width = params.length, params.width
    v.wb_front_axle, v.wb_rear_axle = params.centre_to_front_axle, params.centre_to_rear_axle
    v.a_max = params.max_brake_decel
    # CommonRoad's acceleration limit above the switching speed is a_max * v_switch / v: a power limit
    v.v_switch = params.max_power / (params.mass * params.max_brake_decel)
    v.delta_min, v.delta_max = -params.max_road_wheel_angle, params.max_road_wheel_angle
    v.v_delta_min, v.v_delta_max = -params.max_steer_rate, params.max_steer_rate
    v._update_computed_params()
    return config


def frame_params(spline: bool) -> CLCSParams:
    """The curvilinear frame's preprocessing: with ``spline``, the planner's own
    (``commonroad_rp.utility.utils_coordinate_system.create_coordinate_system``'s defaults); else resampled only."""
    if not spline:
        return CLCSParams(processing_option=ProcessingOption.RESAMPLE)
    params = CLCSParams(processing_option=ProcessingOption.SPLINE_SMOOTHING)
    params.spline.degree_spline = 3
    params.spline.smoothing_factor = 2.0
    params.resampling.option = ResamplingOption.ADAPTIVE
    params.resampling.min_step = 0.5
    params.resampling.max_step = 1.0
    return params


class DomainAsNone(CoordinateSystem):
    """The planner's coordinate system, answering None (as the planner expects) where clcs 2025.x raises."""

    caught = 0  # exceptions turned into None (per instance once one is caught)

    def convert_to_cartesian_coords(self, s: float, d: float):
        try:
            return super().convert_to_cartesian_coords(s, d)
        except (CurvilinearProjectionDomainLateralError, CurvilinearProjectionDomainLongitudinalError):
            self.caught += 1
            return None


class ReactivePlannerADS(CommonRoadADS):
    name = "commonroad-reactive"

    class Options(CommonRoadADS.Options):
        domain_shim: bool = True  # samples out of the projection domain are infeasible, not an exception
        # [m/s] the planner's own switch to its low-velocity sampling (4.0, as shipped)
        low_vel_threshold: float = Field(4.0, ge=0.0)
        # the planner's continuous collision check (off, as shipped): off, it checks only the poses at its time
        # steps, and a pedestrian crossing between two of them is not seen (bug 4)
        continuous_check: bool = False
        # reset() converts the car's state into the curvilinear frame in the previous cycle's velocity mode
        # (plan() switches the mode only afterwards): true (default) sets the mode first; false: as shipped,
        # where the first cycle below 4 m/s in a bend has no feasible sample (bug 3; 8 of 44 seeds fail on it)
        mode_fix: bool = True
        # set_desired_velocity ignores the requested speed when current_speed == 0.0 (it takes the planning
        # problem's): true (default) passes a car at rest as moving at AT_REST m/s; false: as shipped, a car that
        # starts at rest stays there (bug 2)
        rest_fix: bool = True
        # at rest, plan() stops at its first sampling level when that level's best sample stands still (every moving
        # one infeasible), and returns its standstill trajectory without trying its denser levels: true (default)
        # asks those levels through plan(current_sampling_level=...), unless standing is what the adapter wants
        # (self.standing_wanted: waiting at a red light's stop line; walking the levels at each waiting cycle took
        # 98 of town/004's 122 s of planner time), and, after a walk that found nothing moving, not again for
        # LEVEL_RETRY seconds while the car stays at rest; false: as shipped (bug 10)
        level_fix: bool = True
        # the curvilinear frame's reference path: "chaikin" (default), the adapter's path sampled 2 m apart and
        # smoothed by Chaikin's corner cutting, as CommonRoad's route planner builds its reference paths, then
        # resampled; "spline", preprocessed as the planner's own create_coordinate_system does it (a cubic smoothing
        # spline, then resampled 0.5-1 m apart); "resample": resampled only, as before issue 32's third
        # session, when the frame's heading turned in steps at SUMO's shape vertices while its curvature did not,
        # and low-speed samples in a bend failed the yaw-rate check (the adapter's mistake 5)
        frame: Literal["spline", "chaikin", "resample"] = "chaikin"

    def make_planner(self, reference: np.ndarray, params: VehicleParams) -> None:
        dt = self.options.planner_dt
        config = planner_config(params, dt, self.steps)
        config.planning.low_vel_mode_threshold = self.options.low_vel_threshold
        config.planning.continuous_collision_check = self.options.continuous_check
        x, y = reference[0]
        start = InitialState(time_step=0, position=np.array([x, y]), orientation=0.0, velocity=0.0,
                             acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
        goal = GoalRegion([CustomState(time_step=Interval(0, 100000))])
        config.update(scenario=Scenario(dt), planning_problem=PlanningProblem(1, start, goal))
        self.planner = ReactivePlanner(config)
        logging.getLogger("RP_LOGGER").setLevel(logging.ERROR)
        self.caught_before = 0  # what the shim caught on earlier reference windows
        self.denser_asked = 0  # plan() calls at a denser sampling level (level_fix)
        self.walk_again = 0  # level_fix: the cycle (self.k) from which the denser levels may be asked again
        self.set_reference(reference)

    def set_reference(self, reference: np.ndarray) -> None:
        """A new curvilinear frame on ``reference`` (the planner's own set-up is kept)."""
        old = getattr(self.planner, "_co", None)
        cls = DomainAsNone if self.options.domain_shim else CoordinateSystem
        if self.options.frame == "chaikin":
            reference = _resample(chaikins_corner_cutting(_resample(reference, 2.0)), 1.0)
        co = cls(reference, clcs_params=frame_params(self.options.frame == "spline"))
        self.caught_before += getattr(old, "caught", 0)
        self.planner.set_reference_path(coordinate_system=co)

    def trace_info(self) -> dict:
        """The base class's record, and how many samples the domain shim turned from an exception into None."""
        info = super().trace_info()
        co = getattr(getattr(self, "planner", None), "_co", None)
        info["domain_shim_caught"] = getattr(self, "caught_before", 0) + getattr(co, "caught", 0)
        info["denser_levels_asked"] = getattr(self, "denser_asked", 0)
        return info

    def _denser_levels(self, result):
        """From rest, ``plan()`` stops at the first sampling level whose best sample stands still (every moving
        sample there infeasible) and returns its standstill trajectory: ask the denser levels in turn, as
        ``plan()`` itself does when a level has nothing (bug 10). A level with no feasible sample at all raises
        bug 6's TypeError from the standstill fallback's log line: the standstill trajectory then stays."""
        planner = self.planner
        for level in range(2, planner.sampling_level):
            if max(s.velocity for s in result[0].state_list) > STANDING:
                break
            self.denser_asked += 1
            try:
                result = planner.plan(current_sampling_level=level) or result
            except TypeError:
                pass
        if max(s.velocity for s in result[0].state_list) <= STANDING:  # nothing moves: not again for a while
            self.walk_again = self.k + int(round(LEVEL_RETRY / self.mission.step_length))
        return result

    def plan(self, state: CarState, checker, desired_speed: float) -> Plan | None:
        planner = self.planner
        x0 = ReactivePlannerState(time_step=0, position=np.array([state.x, state.y]), orientation=state.heading,
                                  velocity=state.speed, acceleration=state.accel, yaw_rate=state.yaw_rate,
                                  steering_angle=state.steer)
        if self.options.mode_fix:
            planner._low_vel_mode = state.speed < planner.config.planning.low_vel_mode_threshold
        planner.reset(initial_state_cart=x0, collision_checker=checker)
        current = max(state.speed, AT_REST) if self.options.rest_fix else state.speed
        planner.set_desired_velocity(desired_speed, current_speed=current)
        result = planner.plan()
        if state.speed > STANDING:
            self.walk_again = 0
        if (self.options.level_fix and result is not None and state.speed <= STANDING and desired_speed > STANDING
                and not self.standing_wanted and self.k >= self.walk_again):
            result = self._denser_levels(result)
        if result is None:
            return None
        states = result[0].state_list
        dt = self.options.planner_dt
        return Plan(np.array([s.time_step * dt for s in states]),
                    np.array([s.position[0] for s in states]), np.array([s.position[1] for s in states]),
                    np.array([s.orientation for s in states]), np.array([s.velocity for s in states]),
                    np.array([s.acceleration for s in states]))
