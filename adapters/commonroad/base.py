"""The base of every CommonRoad-style planner plugin: all of the ADS except the planner call.

A planner plugs in with a subclass that implements :meth:`CommonRoadADS.make_planner` (once per
mission, with the first window of the reference path and the car), optionally
:meth:`CommonRoadADS.set_reference` (a new window; by default the planner is made again) and
:meth:`CommonRoadADS.plan` (one planning cycle:
the car's rear-axle state, a ``pycrcc.CollisionChecker`` holding the road boundary, the predicted
road users and a stop-line wall, and the desired speed; it returns a :class:`Plan` or None).
:mod:`adapters.commonroad.reactive` is the first; docs/ads.md says how to add another.

The planner gets the whole reference path in one curvilinear frame when it can: a route that turns by
more than a full circle (a loop ramp, a roundabout taken three quarters round) cannot be, since the frame
refuses headings beyond +-2 pi. Such a route goes in as a window that moves with the car (:data:`WINDOW_BACK`
behind it, up to :data:`WINDOW_AHEAD` ahead, cut before its heading leaves that range), as CommonRoad users
do on long routes. (A window on every route was tried: the planner's low-speed bends are so sensitive to
the frame's discretisation that two clean seeds failed and none was gained.) The window moves
when the car is :data:`WINDOW_MOVE` metres into it or nears its end; each cycle records where its window begins.

Every ``replan_period`` seconds the base builds the planner's inputs (:mod:`adapters.commonroad.scene`)
and asks for a plan; every step it tracks the newest plan: pure pursuit on the plan's rear-axle path
(continued along the reference path past its end) for the steering, the plan's acceleration plus a
proportional term on its speed for the pedals. A planner that returns None or raises is an ADS
failure: the fail-safe brakes at ``failsafe_decel`` along the last plan's path, and the event is
recorded. Within :data:`GOAL_BRAKE` of the goal it brakes and then holds the car still. Every cycle's
decisions (outcome, wall, desired speed, the plan's top speed) are kept and handed to the trace by :meth:`trace_info`
(``meta.json``, key ``ads_info``).

Units: SI, radians ENU. Deterministic: no clock, no randomness; the cycle falls on step counts.
"""

from __future__ import annotations

import abc
import math
from typing import Any, Literal, NamedTuple

import numpy as np
import commonroad_dc.pycrcc as pycrcc
from pydantic import Field

from drivefuzz.ads import ADS, Control, MissionInfo, Observation
from drivefuzz.sim.physics import VehicleParams
from ego.actuation import PurePursuit
from ego.planning import speed_profile

from adapters.commonroad import scene

#: [m] the plan's path is continued this far along the reference path past its last point, for the path tracker.
TRACK_TAIL = 30.0
#: [m] from this far before the goal (or once past it) the adapter brakes to a stop there.
GOAL_BRAKE = 1.0
#: The reference path's bends are opened to this share of the car's tightest curvature.
REF_CURVATURE_SHARE = 0.85
#: [s] the desired speed's ramp to a stop point aims this many seconds (at the current speed) short of it
STOP_LAG = 1.0
#: [m/s^2] the desired speed's braking ramp before a bend (the reference ADS's).
CURVE_DECEL = 1.5
#: [m/s^2] per [m/s]: the pedal command's proportional term on the plan's speed.
SPEED_GAIN = 1.0
#: [s] the tracker reads the plan's speed and acceleration this far ahead (the actuators' lag).
PREVIEW = 0.1
#: [m] the planner's reference window starts this far behind the car (near its ends the frame's projection
#: domain narrows) ...
WINDOW_BACK = 30.0
#: [m] ... and reaches this far past its start, or less where its heading would leave +-(2 pi - WINDOW_TURN_MARGIN)
WINDOW_AHEAD = 230.0
#: [rad] the window's heading stays this far inside the frame's limit of +-2 pi
WINDOW_TURN_MARGIN = 0.3
#: [m] the window moves on once the car is this far past its start ...
WINDOW_MOVE = WINDOW_BACK + 60.0
#: [m] ... or once less than this (plus twice the horizon's reach) is left ahead of the car
WINDOW_REACH = 30.0
#: [m] while a red or yellow stop line's wall is up and the front bumper is within this of the line, the car at
#: rest is where the adapter wants it (waiting): :attr:`CommonRoadADS.standing_wanted` (two car lengths)
WALL_HOLD = 10.0
#: Outcome codes of a planning cycle, as recorded in the trace.
PLANNED, NO_PLAN, RAISED = "plan", "none", "raised"


class Plan(NamedTuple):
    """A planned trajectory: per state, time [s from the cycle's start], rear-axle position [m],
    heading [rad], speed [m/s] and acceleration [m/s^2]."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    v: np.ndarray
    a: np.ndarray


class CarState(NamedTuple):
    """The car as the planner gets it: the rear axle's position [m], heading [rad], speed [m/s],
    acceleration [m/s^2], yaw rate [rad/s] and road-wheel angle [rad]."""

    x: float
    y: float
    heading: float
    speed: float
    accel: float
    yaw_rate: float
    steer: float


class CommonRoadADS(ADS):
    """Everything but the planner call; see the module docstring."""

    name = ""

    class Options(ADS.Options):
        replan_period: float = Field(0.3, gt=0.0)  # [s] between planning cycles (rounded to whole steps)
        horizon: float = Field(3.0, gt=0.0)  # [s] planning horizon
        planner_dt: float = Field(0.1, gt=0.0)  # [s] the planner's time step
        speed_margin: float = Field(0.95, gt=0.0)  # desired speed: this fraction of the speed limit ...
        max_lat_accel: float = Field(2.25, ge=0.0)  # [m/s^2] ... and the bends' limit at this (0: none)
        stop_decel: float = Field(2.0, gt=0.0)  # [m/s^2] the desired speed falls to stop at the goal or a wall
        failsafe_decel: float = Field(6.0, gt=0.0)  # [m/s^2] braking when the planner has no plan
        # [m] the reference path reaches at least this far past the goal (with the goal lane's rest); set lower
        # than its default, it ends there: samples past its end leave the curvilinear frame's projection domain
        # (bug 1's reproducer, with domain_shim=false)
        past_goal: float = Field(scene.PAST_GOAL, gt=0.0)
        # how other road users move on over the horizon (scene.predictions): constant_acceleration (acceleration and
        # yaw rate read between planning cycles, clamped), or constant_velocity along the heading (before; four
        # campaign collisions with braking or accelerating cars were that prediction's, docs/bugs)
        prediction: scene.Prediction = "constant_acceleration"
        # the road boundary's boxes reach past their segments' ends: "outside" (default) only where the road's edge
        # turns left, so that no box reaches into the road; "every_end": at every end, as before issue 32's fourth
        # session, when at a kerb the road bends round a box reached up to 0.25 m into the road (mistake 6)
        boundary_ends: Literal["outside", "every_end"] = "outside"
        # [s] the desired speed takes the bends' limit this far ahead (at the current speed): the planner reaches a
        # desired speed only by the end of its samples (0: the limit where the car is, as before)
        curve_lead: float = Field(0.0, ge=0.0)

    def reset(self, mission: MissionInfo, roadmap) -> None:
        self.params = params = VehicleParams()
        self.mission = mission
        # bends the car can turn, with a margin: the planner's samples curve about the reference too
        k_car = math.tan(params.max_road_wheel_angle) / params.wheelbase
        edges: list[str] = []
        self.ref_pts = scene.reference_path(roadmap, tuple(mission.route), mission.start_lane, mission.start_pos,
                                            mission.goal_edge, mission.goal_pos, past_goal=self.options.past_goal,
                                            max_curvature=REF_CURVATURE_SHARE * k_car, edges_out=edges)
        self.ref = scene.as_path(self.ref_pts)
        _, self.s_goal, _ = self.ref.locate(*mission.goal_xy, hint=0, window=len(self.ref_pts))
        end = int(self.s_goal + self.options.past_goal) + 2  # the points are 1 m apart
        if self.options.past_goal < scene.PAST_GOAL and end < len(self.ref_pts):
            self.ref_pts = self.ref_pts[:end]
            self.ref = scene.as_path(self.ref_pts)
        self.profile = _curve_profile(self.ref_pts, self.options.max_lat_accel)
        self.boundary, self.n_boundary = scene.boundary_group(scene.boundary_segments(roadmap, edges), self.ref_pts,
                                                               every_end=self.options.boundary_ends == "every_end")
        opts = self.options
        self.steps = max(int(round(opts.horizon / opts.planner_dt)), 1)
        self.replan_every = max(int(round(opts.replan_period / mission.step_length)), 1)
        self.tracker = PurePursuit(params.wheelbase, params.max_road_wheel_angle)
        self.k = 0  # steps since reset
        self.ref_idx = 0
        self.limit = 13.89  # [m/s] until the first lane with a limit is seen
        self.plan_: Plan | None = None
        self.plan_t0 = 0.0
        self.plan_path = None
        self.failsafe = False
        self._done = False
        self.log: dict[str, list] = {"t": [], "outcome": [], "error": [], "wall": [], "v_des": [], "v_plan_max": [],
                                     "ref_from": []}
        self.setup_error = ""
        self.standing_wanted = False  # this cycle: a plan that stands still is what the adapter wants (see _cycle)
        self.tracks = scene.Tracks()  # each road user's speed and heading at the last cycle (prediction)
        self.window = reference_window(self.ref_pts, 0)
        try:  # a planner that cannot be set up is the ADS failing: every cycle is then recorded as raised
            self.make_planner(self.ref_pts[self.window[0]:self.window[1]], params)
        except Exception as exc:
            self.setup_error = f"at set-up: {type(exc).__name__}: {exc}"[:200]

    # -- for subclasses ---------------------------------------------------------------------------
    @abc.abstractmethod
    def make_planner(self, reference: np.ndarray, params: VehicleParams) -> None:
        """Set the planner up for one mission: ``reference`` (n, 2) [m] reaches past the goal; ``params``
        is drivefuzz's car (every ADS drives the same car)."""

    def set_reference(self, reference: np.ndarray) -> None:
        """Give the planner a new window of the reference path (n, 2) [m]; by default it is made again."""
        self.make_planner(reference, self.params)

    @abc.abstractmethod
    def plan(self, state: CarState, checker: "pycrcc.CollisionChecker", desired_speed: float) -> Plan | None:
        """One planning cycle from ``state`` (time step 0), avoiding what ``checker`` holds (time-variant
        objects over ``self.steps`` steps of ``self.options.planner_dt``); None when there is no plan.
        ``self.standing_wanted`` says whether a plan that stands still is what the adapter wants this cycle
        (waiting within :data:`WALL_HOLD` of a red light's stop line, or no speed desired): a planner-specific
        search for a moving plan (the reactive planner's ``level_fix``) need not run then."""

    # -- the ADS ----------------------------------------------------------------------------------
    def done(self) -> bool:
        return self._done

    def trace_info(self) -> dict[str, Any]:
        """The adapter's decisions, one entry per planning cycle, and their counts."""
        out = self.log["outcome"]
        return {"adapter": type(self).__name__, "replan_period_steps": self.replan_every, "horizon_steps": self.steps,
                "boundary_boxes": self.n_boundary,
                "counts": {k: out.count(k) for k in (PLANNED, NO_PLAN, RAISED)}, "cycles": dict(self.log)}

    def step(self, obs: Observation) -> Control:
        ego = obs.ego
        if math.isfinite(obs.speed_limit) and obs.speed_limit > 0:
            self.limit = obs.speed_limit
        self.ref_idx, s_c, _ = self.ref.locate(ego.x, ego.y, self.ref_idx)
        to_goal = self.s_goal - s_c
        if to_goal < GOAL_BRAKE:
            # the adapter stops the car at the goal: the planner, asked for 0 m/s, creeps on at ~0.6 m/s
            self._done = self._done or ego.speed < 0.5
            brake = 0.3 if self._done else self.options.failsafe_decel / self.params.max_brake_decel
            return Control(0.0, 0.0, brake)
        if self.k % self.replan_every == 0:
            self._cycle(obs, s_c, to_goal)
        self.k += 1
        return self._track(obs)

    def _cycle(self, obs: Observation, s_c: float, to_goal: float) -> None:
        """One planning cycle: the planner's inputs, its call, and the record of what happened."""
        ego, opts = obs.ego, self.options
        # (with curve_lead, the bends' limit read that many seconds ahead at the current speed, as the stop ramp is)
        ahead = self.ref_idx + int(opts.curve_lead * ego.speed) + 1  # the points are 1 m apart
        v_des = min(self.limit * opts.speed_margin, min(self.profile[self.ref_idx:ahead]))
        # the planner reaches a desired speed only by the end of its samples: the ramp aims short by STOP_LAG
        lag = STOP_LAG * ego.speed
        v_des = min(v_des, scene.stop_speed(to_goal, opts.stop_decel, margin=lag))
        checker = pycrcc.CollisionChecker()
        checker.add_collision_object(self.boundary)
        for tvo in scene.predictions(obs, self.steps, opts.planner_dt, reach=ego.speed * opts.horizon + 60.0,
                                     mode=opts.prediction, tracks=self.tracks):
            checker.add_collision_object(tvo)
        wall = scene.stop_wall(obs, self.ref, s_c + ego.length / 2.0)
        if wall is not None:
            checker.add_collision_object(scene.wall_shape(wall))
            v_des = min(v_des, scene.stop_speed(obs.traffic_light.distance, opts.stop_decel, margin=1.0 + lag))
        # a plan that stands still is what the adapter asks for: waiting at the wall, or no speed desired
        self.standing_wanted = (wall is not None and obs.traffic_light.distance < WALL_HOLD) or v_des < 0.05
        r = self.params.centre_to_rear_axle
        ch, sh = math.cos(ego.heading), math.sin(ego.heading)
        state = CarState(ego.x - r * ch, ego.y - r * sh, ego.heading, ego.speed, ego.ax, ego.yaw_rate,
                         ego.road_wheel_angle)
        error = self.setup_error or self._move_window(ego.speed)
        try:
            result = None if error else self.plan(state, checker, v_des)
        except Exception as exc:  # the planner's failure is the ADS's failure: fail-safe, recorded
            result, error = None, f"{type(exc).__name__}: {exc}"[:200]
        outcome = PLANNED if result is not None else (RAISED if error else NO_PLAN)
        log = self.log
        log["t"].append(round(obs.t, 6))
        log["outcome"].append(outcome)
        log["error"].append(error)
        log["wall"].append(wall is not None)
        log["v_des"].append(round(v_des, 4))
        log["v_plan_max"].append(round(float(np.max(result.v)), 4) if result is not None else None)
        log["ref_from"].append(self.window[0])
        self.failsafe = result is None
        if result is not None:
            self.plan_, self.plan_t0 = result, obs.t
            self.plan_path = _track_path(result, self.ref)
        elif self.plan_path is None:  # no plan yet: steer along the reference path
            self.plan_path = self.ref

    def _move_window(self, speed: float) -> str:
        """Move the planner's reference window on when the car is far enough into it or near its end;
        '' or the error that the planner raised on the new window (the cycle then has no plan)."""
        lo, hi = self.window
        if lo == 0 and hi == len(self.ref_pts):
            return ""  # the whole route in one frame
        ahead = (hi - 1) - self.ref_idx
        if self.ref_idx - lo < WINDOW_BACK + 10.0:
            return ""  # just moved (a window cut short by its heading would otherwise move every cycle)
        if self.ref_idx - lo < WINDOW_MOVE and (ahead >= WINDOW_REACH + 2.0 * speed * self.options.horizon
                                               or hi >= len(self.ref_pts)):
            return ""
        new = reference_window(self.ref_pts, self.ref_idx)
        if new == self.window:
            return ""
        self.window = new
        try:
            self.set_reference(self.ref_pts[new[0]:new[1]])
        except Exception as exc:
            return f"at reference window: {type(exc).__name__}: {exc}"[:200]
        return ""

    def _track(self, obs: Observation) -> Control:
        """Steering and pedals that follow the newest plan (the fail-safe brakes along its path)."""
        ego = obs.ego
        v = ego.speed
        r = self.params.centre_to_rear_axle
        ch, sh = math.cos(ego.heading), math.sin(ego.heading)
        rx, ry = ego.x - r * ch, ego.y - r * sh
        path = self.plan_path
        _, s_rear, _ = path.locate(rx, ry, hint=0, window=len(path.pts))
        steer = self.tracker.steer(path, s_rear, rx, ry, ego.heading, v)
        plan = self.plan_
        rel = obs.t - self.plan_t0 + PREVIEW
        if self.failsafe or plan is None or rel > plan.t[-1]:
            accel = -self.options.failsafe_decel
            v_plan = 0.0
        else:
            v_plan = float(np.interp(rel, plan.t, plan.v))
            accel = float(np.interp(rel, plan.t, plan.a)) + SPEED_GAIN * (v_plan - v)
        return Control(steer, *self._pedals(accel, v, v_plan))

    def _pedals(self, accel: float, v: float, v_plan: float) -> tuple[float, float]:
        """(throttle, brake) for ``accel`` [m/s^2]; a car at rest with a plan to stay there holds still."""
        if v < 0.05 and v_plan < 0.05 and accel <= 0.0:
            return 0.0, 0.3
        if accel >= 0.0:
            return min(accel / 3.5, 1.0), 0.0
        return 0.0, min(-accel / self.params.max_brake_decel, 1.0)


def reference_window(pts: np.ndarray, i_car: int) -> tuple[int, int]:
    """(first, end) indices of the planner's window of the reference path ``pts`` (1 m apart) for a car at
    point ``i_car``: the whole path when its heading (unwrapped from its first segment's, in [-pi, pi]) stays
    within +-(2 pi - :data:`WINDOW_TURN_MARGIN`); otherwise from :data:`WINDOW_BACK` behind the car to
    :data:`WINDOW_AHEAD` past that, cut where its heading would leave that range."""
    if _turn_limit(pts) is None:
        return 0, len(pts)
    lo = max(int(i_car) - int(WINDOW_BACK), 0)
    hi = min(lo + int(WINDOW_AHEAD) + 1, len(pts))
    cut = _turn_limit(pts[lo:hi])
    return lo, hi if cut is None else lo + max(cut, 2)


def _turn_limit(pts: np.ndarray) -> int | None:
    """The first segment of ``pts`` whose heading, unwrapped from the first's, leaves the frame's range; or None."""
    d = np.diff(pts, axis=0)
    out = np.flatnonzero(np.abs(np.unwrap(np.arctan2(d[:, 1], d[:, 0]))) > 2.0 * math.pi - WINDOW_TURN_MARGIN)
    return int(out[0]) if len(out) else None


def _track_path(plan: Plan, ref):
    """The plan's rear-axle path, 1 m apart, continued :data:`TRACK_TAIL` metres along the reference path
    ``ref`` (the fail-safe brakes along it when the plan has run out)."""
    pts = scene._dedup(np.stack([plan.x, plan.y], axis=1))
    _, s_end, _ = ref.locate(float(pts[-1, 0]), float(pts[-1, 1]), hint=0, window=len(ref.pts))
    tail = np.array([ref.point_at(s_end + k) for k in range(2, int(TRACK_TAIL) + 1)])
    return scene.as_path(scene._resample(scene._dedup(np.vstack([pts, tail])), 1.0))


def _curve_profile(ref_pts: np.ndarray, max_lat_accel: float) -> list[float]:
    """Per reference point, the bends' speed limit [m/s] with a braking ramp before each (the reference
    ADS's :func:`ego.planning.speed_profile`); no limit when ``max_lat_accel`` is 0."""
    if max_lat_accel <= 0.0:
        return [math.inf] * len(ref_pts)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(ref_pts, axis=0).T))])
    head = np.unwrap(np.arctan2(*(np.diff(ref_pts, axis=0)[:, ::-1].T)))
    curv = np.zeros(len(ref_pts))
    if len(head) > 2:
        dk = np.abs(np.diff(head)) / np.maximum(np.diff(s[:-1]), 1e-6)
        curv[1:-1] = np.convolve(dk, np.ones(5) / 5, mode="same")
    return speed_profile(scene.Path(ref_pts, s, curv), max_lat_accel, CURVE_DECEL, lead_m=4.0)
