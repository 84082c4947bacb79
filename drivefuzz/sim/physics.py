"""Vehicle physics: a dynamic single-track (bicycle) model with friction-limited tyres.

Every ADS under test drives the same simulated car; the executor calls
:meth:`VehiclePhysics.step` once per simulation step (``dt`` 0.05 s or 0.1 s) and
places the car in SUMO.

Model
-----
* **Dynamic single-track model** in the body frame at the centre of gravity (CG):
  states ``vx`` (forward), ``vy`` (left), ``yaw_rate`` (CCW), plus the pose and the
  rate-limited front road-wheel angle.  Modelled on the CommonRoad single-track drift
  model (STD) but without its wheel-spin states (see below).
* **Lateral tyre force** per axle: simplified Pacejka magic formula
  ``Fy = D sin(C atan(B a - E (B a - atan(B a))))``, peak ``D = mu_eff * Fz`` with the
  axle normal load ``Fz`` including longitudinal load transfer and
  ``mu_eff = lateral_grip * mu * (1 - s (Fz - Fz_static) / Fz_static)`` (mild tyre
  load sensitivity ``s``).  The linear cornering stiffness is given *per unit load*
  (``tyre_stiffness_front/rear`` = ``C_alpha / Fz`` [1/rad]) and ``B = k / (C mu_eff)``:
  the small-slip behaviour does not depend on friction, while the saturation force and
  the slip angle of the peak scale with ``mu`` (on ice the tyres saturate early).
  Beyond the peak the force falls to ``sin(C pi/2)`` (~0.81) of it.
* **Limit balance**: a single-track model has no lateral load transfer, which is what
  makes real cars understeer at the limit.  It is lumped into ``lateral_grip_front``
  (0.9: the front axle's effective lateral friction); with it, and with the front-wheel
  drive, the car understeers at the limit of a uniform surface (the front saturates and
  the car runs wide) but spins when the rear is on a much slipperier surface.
* **Longitudinal tyre forces** (drive, brake) are demanded directly (ideal ABS /
  traction control, no wheel-spin states): brakes are distributed in proportion to the
  axle loads (EBD), and each axle's force is capped at ``max_long_utilisation_* * mu_eff
  * Fz``.  **Combined slip**: at the front the lateral force is scaled by the friction
  ellipse ``sqrt(1 - (Fx / (mu_eff Fz))^2)`` (hard braking or driving costs steering);
  the rear is lateral-priority (its brake force only gets the friction the lateral force
  leaves, as EBD/ABS/ESC keep the rear stable), so braking in a bend does not spin the car.
* **Resistances**: aerodynamic drag ``0.5 rho CdA vx^2`` and rolling resistance
  ``c_rr m g``.  With the brakes they act as Coulomb-like resistances that can stop the
  car but never reverse it (semi-implicit friction projection): a braked car stops and
  stays exactly stopped.  Throttle only drives forward; there is no reverse gear.
  (``vx`` can only go negative in a spin, when the car slides backwards.)
* **Integration**: fixed internal sub-steps ``h = dt / ceil(dt / max_substep)``
  (12.5 ms: 4 per 0.05 s step).  The stiff lateral tyre dynamics (time constant
  ``~ m vx / C_alpha``, which vanishes as ``vx -> 0``) are integrated *linearly
  implicitly* (one Newton step of implicit Euler, tyre slopes clamped at >= 0), which is
  stable at any speed; the Coriolis coupling uses the updated lateral states (symplectic
  Euler, so a fast spin neither gains nor loses energy numerically); the pose is
  semi-implicit with the mid-point heading.

  One step (:meth:`VehiclePhysics.step`): clip the inputs (``_clip_inputs``), fix the
  step's constants (``_step_constants``), then each sub-step (``_substeps``), in order:
  1. the rate-limited steering actuator, 2. the axle loads and peak tyre forces, 3. the
  weight of the dynamic model, 4. ``tyre_forces`` (rear lateral, drive and brakes),
  5. ``lateral_dynamics`` (front lateral, linearly implicit lateral/yaw update),
  6. ``velocities`` (longitudinal speed, kinematic blend; 4-6 in :mod:`drivefuzz.sim.substep`),
  7. the pose.  The small stages
  1-3 and 7 are written out in ``_substeps``: a call per sub-step costs more than they do.
* **Low speed**: between ``kinematic_blend_high`` (2 m/s) and ``kinematic_blend_low``
  (1 m/s) the lateral states are blended (smoothstep in the speed) into the kinematic
  single-track model ``r = vx tan(delta) / L``, ``vy = lr r`` (as the CommonRoad STD
  model does).  The pull towards the kinematic state is limited by the available
  friction, so a car sliding slowly on ice keeps sliding for a while.

Why not CommonRoad's ``vehicle_dynamics_std`` itself (measured, commonroad-vehicle-models
3.0.2, CPython 3.11): one evaluation of its right-hand side costs ~13 us, and its
wheel-spin states are so stiff that an explicit integrator needs <= 2 ms steps at low
speed (10 ms at 15 m/s): 65-340 us per 0.05 s step with Euler, 130-1360 us with RK4, and
0.75-2.2 ms with ``scipy.integrate.odeint`` as its documentation does -- against a
budget of ~40 us.  This module is scalar pure-``math`` Python: ~16 us per 0.05 s step
(``tools/bench_physics.py``).

Conventions: SI units, angles in rad; heading ENU (0 = east, CCW positive, wrapped to
[-pi, pi]); body frame x forward, y left; steering left-positive.  The state's ``x, y``
is the *geometric centre* of the body rectangle (what :mod:`drivefuzz.geometry` uses),
not the CG (``VehicleParams.centre_to_cg`` ahead of it).
"""

from __future__ import annotations

import math
from math import cos, hypot, sin
from dataclasses import dataclass

from drivefuzz.scenario.model import EGO_LENGTH, EGO_WIDTH
from drivefuzz.sim.substep import lateral_dynamics, tyre_forces, velocities

__all__ = ["G", "VehicleParams", "VehicleState", "VehiclePhysics", "place_state"]

G = 9.81  # [m/s^2]

_MU_MIN = 0.01
_MU_MAX = 2.0
_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class VehicleParams:
    """Parameters of the simulated car: a ~1.5 t, 110 kW front-wheel-drive mid-size saloon.

    Handling: understeer gradient ~0.0025 rad s^2/m (~1.4 deg/g, characteristic speed
    ~34 m/s), lateral limit ~0.9 mu g, 0-100 km/h ~8 s, top speed ~63 m/s, full braking
    ~8.6 m/s^2 on a dry road.
    """

    length: float = EGO_LENGTH  # [m] body
    width: float = EGO_WIDTH  # [m]
    wheelbase: float = 2.8  # [m]
    cg_to_front: float = 1.3  # [m] lf: CG to front axle; lr = wheelbase - lf
    front_overhang: float = 0.95  # [m] front axle to front bumper
    mass: float = 1500.0  # [kg]
    yaw_inertia: float = 2500.0  # [kg m^2]
    cg_height: float = 0.55  # [m]
    steering_ratio: float = 15.0  # steering-wheel angle / road-wheel angle
    max_road_wheel_angle: float = 0.6  # [rad] (~34 deg)
    max_steer_rate: float = 0.8  # [rad/s] road-wheel angle rate limit (actuator)
    max_drive_force: float = 6000.0  # [N] -> ~3.9 m/s^2 at low speed on a dry road
    max_power: float = 110_000.0  # [W] limits the drive force above ~18 m/s
    front_drive_fraction: float = 1.0  # share of the drive force on the front axle (1 = FWD)
    max_brake_decel: float = 9.0  # [m/s^2] requested at brake=1 (grip may limit it)
    max_long_utilisation_front: float = 0.9  # ABS/TC: max |Fx| / (mu Fz) on the front axle
    max_long_utilisation_rear: float = 0.8  # rear kept further from the limit (EBD/ABS stability)
    drag_area: float = 0.65  # [m^2] Cd * A
    air_density: float = 1.2  # [kg/m^3]
    rolling_resistance: float = 0.012  # c_rr (force = c_rr m g)
    # Tyres (per axle, two tyres lumped): magic-formula lateral force, B = k / (C mu_eff).
    tyre_stiffness_front: float = 16.0  # [1/rad] cornering stiffness per unit load C_af / Fzf
    tyre_stiffness_rear: float = 26.0  # [1/rad] C_ar / Fzr (rear stiffer -> understeer)
    tyre_shape_front: float = 1.4  # Pacejka C (large-slip force = sin(C pi/2) ~ 0.81 peak)
    tyre_shape_rear: float = 1.4
    lateral_grip_front: float = 0.9  # effective axle lateral friction / mu (lumps the
    lateral_grip_rear: float = 1.0  # lateral load transfer a single-track model lacks)
    tyre_load_sensitivity: float = 0.15  # mu_eff = mu (1 - s (Fz - Fz_static) / Fz_static)
    tyre_curvature_front: float = 0.0  # Pacejka E (< 1)
    tyre_curvature_rear: float = 0.0
    # Numerics
    max_substep: float = 0.0125  # [s] internal integration step (0.05 s -> 4 sub-steps)
    kinematic_blend_low: float = 1.0  # [m/s] below: kinematic single-track model
    kinematic_blend_high: float = 2.0  # [m/s] above: dynamic model

    def __post_init__(self) -> None:
        positive = (
            "length", "width", "wheelbase", "cg_to_front", "mass", "yaw_inertia",
            "steering_ratio", "max_road_wheel_angle", "max_steer_rate", "max_substep",
            "tyre_stiffness_front", "tyre_stiffness_rear", "tyre_shape_front", "tyre_shape_rear",
        )
        for name in positive:
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"VehicleParams.{name} must be finite and > 0, got {v!r}")
        nonneg = (
            "front_overhang", "cg_height", "max_drive_force", "max_power", "max_brake_decel",
            "drag_area", "air_density", "rolling_resistance", "kinematic_blend_low",
        )
        for name in nonneg:
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"VehicleParams.{name} must be finite and >= 0, got {v!r}")
        if not self.cg_to_front < self.wheelbase:
            raise ValueError("cg_to_front must be < wheelbase")
        if self.rear_overhang < 0.0:
            raise ValueError("wheelbase + front_overhang must not exceed length")
        if not 0.0 <= self.front_drive_fraction <= 1.0:
            raise ValueError("front_drive_fraction must be in [0, 1]")
        for name in ("max_long_utilisation_front", "max_long_utilisation_rear"):
            if not 0.0 < getattr(self, name) < 1.0:
                raise ValueError(f"{name} must be in (0, 1)")
        if not self.kinematic_blend_high > self.kinematic_blend_low:
            raise ValueError("kinematic_blend_high must be > kinematic_blend_low")
        if not self.max_road_wheel_angle < 1.4:
            raise ValueError("max_road_wheel_angle must be < 1.4 rad")
        for name in ("tyre_shape_front", "tyre_shape_rear"):
            if not getattr(self, name) < 2.0:
                raise ValueError(f"{name} (Pacejka C) must be < 2")
        for name in ("lateral_grip_front", "lateral_grip_rear"):
            if not 0.0 < getattr(self, name) <= 1.5:
                raise ValueError(f"{name} must be in (0, 1.5]")
        if not 0.0 <= self.tyre_load_sensitivity <= 0.5:
            raise ValueError("tyre_load_sensitivity must be in [0, 0.5]")
        for name in ("tyre_curvature_front", "tyre_curvature_rear"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v < 1.0):
                raise ValueError(f"{name} (Pacejka E) must be < 1")

    # ---- geometry helpers -------------------------------------------------------------
    @property
    def cg_to_rear(self) -> float:
        """lr [m]: CG to rear axle."""
        return self.wheelbase - self.cg_to_front

    @property
    def rear_overhang(self) -> float:
        """[m] rear bumper to rear axle."""
        return self.length - self.wheelbase - self.front_overhang

    @property
    def centre_to_cg(self) -> float:
        """[m] longitudinal offset of the CG from the geometric centre (+ = CG ahead)."""
        return self.rear_overhang + self.cg_to_rear - 0.5 * self.length

    @property
    def centre_to_front_axle(self) -> float:
        """[m] geometric centre to front axle (forward)."""
        return self.centre_to_cg + self.cg_to_front

    @property
    def centre_to_rear_axle(self) -> float:
        """[m] geometric centre to rear axle (backward, positive)."""
        return self.cg_to_rear - self.centre_to_cg

    # ---- linear tyre / handling helpers (static axle loads) ---------------------------
    @property
    def static_load_front(self) -> float:
        return self.mass * G * self.cg_to_rear / self.wheelbase

    @property
    def static_load_rear(self) -> float:
        return self.mass * G * self.cg_to_front / self.wheelbase

    @property
    def cornering_stiffness_front(self) -> float:
        """[N/rad] linear cornering stiffness of the front axle at the static load."""
        return self.tyre_stiffness_front * self.static_load_front

    @property
    def cornering_stiffness_rear(self) -> float:
        """[N/rad] linear cornering stiffness of the rear axle at the static load."""
        return self.tyre_stiffness_rear * self.static_load_rear

    @property
    def understeer_gradient(self) -> float:
        """K_us [rad s^2/m] = m/L (lr/C_af - lf/C_ar); > 0 understeer."""
        return self.mass / self.wheelbase * (
            self.cg_to_rear / self.cornering_stiffness_front
            - self.cg_to_front / self.cornering_stiffness_rear
        )


@dataclass(slots=True)
class VehicleState:
    x: float  # [m] geometric centre of the body rectangle
    y: float
    heading: float  # [rad] ENU, 0 = east, CCW positive
    vx: float  # [m/s] body-frame velocity at the CG, forward
    vy: float  # [m/s] body-frame velocity at the CG, left
    yaw_rate: float  # [rad/s] CCW positive
    road_wheel_angle: float  # [rad] front wheel angle, left positive
    ax: float = 0.0  # [m/s^2] body-frame acceleration at the CG over the last step
    ay: float = 0.0  # [m/s^2] lateral, includes the centripetal part vx * yaw_rate

    @property
    def speed(self) -> float:
        return math.hypot(self.vx, self.vy)

    @property
    def sideslip(self) -> float:
        """[rad] body sideslip angle at the CG (0 when stopped)."""
        if self.vx == 0.0 and self.vy == 0.0:
            return 0.0
        return math.atan2(self.vy, self.vx)


def place_state(x: float, y: float, heading: float, speed: float, params: VehicleParams) -> VehicleState:
    """A state rolling straight ahead at ``speed`` [m/s] with the centre at ``(x, y)``."""
    speed = float(speed)
    if not math.isfinite(speed) or speed < 0.0:
        raise ValueError(f"speed must be finite and >= 0, got {speed!r}")
    return VehicleState(float(x), float(y), float(heading), speed, 0.0, 0.0, 0.0)


def _clip01(v: float) -> float:
    if v > 0.0:  # False for NaN
        return 1.0 if v > 1.0 else float(v)
    return 0.0


def _clip_inputs(steer, throttle, brake, mu_front, mu_rear, wind_force_lat) -> tuple[float, ...]:
    """``(steer, throttle, brake, mu_front, mu_rear, wind)`` clipped as :meth:`VehiclePhysics.step` says."""
    steer = float(steer)
    if steer > 1.0:
        steer = 1.0
    elif steer < -1.0:
        steer = -1.0
    elif steer != steer:
        steer = 0.0
    throttle = _clip01(throttle)
    brake = _clip01(brake)
    muf = float(mu_front)
    mur = float(mu_rear)
    muf = _MU_MAX if muf > _MU_MAX else (muf if muf > _MU_MIN else _MU_MIN)  # NaN -> min
    mur = _MU_MAX if mur > _MU_MAX else (mur if mur > _MU_MIN else _MU_MIN)
    fw = float(wind_force_lat)
    if not (-1e6 < fw < 1e6):
        fw = 0.0 if fw != fw else math.copysign(1e6, fw)
    return steer, throttle, brake, muf, mur, fw


class VehiclePhysics:
    """Integrates the car; ``state`` is the only mutable data (it may be reassigned)."""

    def __init__(self, params: VehicleParams, state: VehicleState):
        self.params = params
        self.state = state
        p = params
        self._m = p.mass
        self._iz = p.yaw_inertia
        self._lf = p.cg_to_front
        self._lr = p.cg_to_rear
        self._L = p.wheelbase
        self._hcg = p.cg_height
        self._mg = p.mass * G
        self._dcg = p.centre_to_cg
        self._kf = p.tyre_stiffness_front
        self._kr = p.tyre_stiffness_rear
        self._Cf = p.tyre_shape_front
        self._Cr = p.tyre_shape_rear
        self._Ef = p.tyre_curvature_front
        self._Er = p.tyre_curvature_rear
        self._drag = 0.5 * p.air_density * p.drag_area
        self._rr = p.rolling_resistance * self._mg
        # friction-limited pull towards the kinematic state: max |d vy| and |d r| per second per unit mu
        self._kin_dvy = G
        self._kin_dr = 2.0 * self._mg * self._lf * self._lr / (self._L * self._iz)
        self._fz_min = 0.05 * self._mg

    # ---- helpers ----------------------------------------------------------------------
    def steering_wheel_angle(self) -> float:
        """[rad] steering-wheel angle = road-wheel angle * steering ratio (left positive)."""
        return self.state.road_wheel_angle * self.params.steering_ratio

    def axle_positions(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """World ``(x, y)`` of the front and rear axle centres."""
        s = self.state
        c, sn = math.cos(s.heading), math.sin(s.heading)
        df = self.params.centre_to_front_axle
        dr = self.params.centre_to_rear_axle
        return (s.x + df * c, s.y + df * sn), (s.x - dr * c, s.y - dr * sn)

    def cg_position(self) -> tuple[float, float]:
        s = self.state
        d = self._dcg
        return s.x + d * math.cos(s.heading), s.y + d * math.sin(s.heading)

    @staticmethod
    def steady_state_yaw_rate(params: VehicleParams, vx: float, road_wheel_angle: float) -> float:
        """Linear single-track steady-state yaw rate ``vx d / (L + K_us vx^2)`` [rad/s]."""
        return vx * road_wheel_angle / (params.wheelbase + params.understeer_gradient * vx * vx)

    # ---- integration ------------------------------------------------------------------
    def step(
        self,
        steer: float,
        throttle: float,
        brake: float,
        dt: float,
        mu_front: float = 1.0,
        mu_rear: float = 1.0,
        wind_force_lat: float = 0.0,
    ) -> VehicleState:
        """Advance by ``dt`` [s] and return the new state (a new object, also ``self.state``).

        ``steer`` in [-1, 1] is the commanded fraction of ``max_road_wheel_angle`` (left
        positive; the actuator is rate limited), ``throttle`` and ``brake`` in [0, 1];
        inputs are clipped and NaN counts as 0.  ``mu_front``/``mu_rear`` is the friction
        under each axle (clipped to [0.01, 2]; NaN -> 0.01); ``wind_force_lat`` [N] acts
        sideways at the CG (left positive; below ``kinematic_blend_low`` the tyres hold it).
        ``dt`` must be > 0; any value works (internal sub-steps of <= ``max_substep``).
        """
        dt = float(dt)
        if not (dt > 0.0 and dt < 1e6):
            raise ValueError(f"dt must be > 0 and finite, got {dt!r}")
        steer, throttle, brake, muf, mur, fw = _clip_inputs(steer, throttle, brake, mu_front, mu_rear, wind_force_lat)
        n = int(math.ceil(dt / self.params.max_substep - 1e-9))
        if n < 1:
            n = 1
        s = self.state
        x, y, psi, vx, vy, r, delta, sum_rvy, sum_vxr = self._substeps(
            s, self._step_constants(steer, throttle, brake, muf, mur, fw, dt / n), n)
        if psi > math.pi or psi < -math.pi:
            psi = math.remainder(psi, _TWO_PI)
        new = VehicleState(
            x, y, psi, vx, vy, r, delta,
            (vx - s.vx) / dt - sum_rvy / n,
            (vy - s.vy) / dt + sum_vxr / n,
        )
        self.state = new
        return new

    def _step_constants(self, steer: float, throttle: float, brake: float, muf: float, mur: float,
                        fw: float, h: float) -> tuple:
        """What stays fixed over one step's sub-steps of ``h`` [s], grouped for the sub-step functions.

        ``(d_target, d_rate, loads, blend, rear, front, drive, body, motion)``: the
        steering target and rate [rad, rad per sub-step], then one tuple per sub-step
        function (see their docstrings for the order).
        """
        p = self.params
        m = self._m
        lf = self._lf
        lr = self._lr
        L = self._L
        mg = self._mg
        fz_min = self._fz_min
        Cf = self._Cf
        Cr = self._Cr
        gr_lat_f = p.lateral_grip_front
        gr_lat = p.lateral_grip_rear
        Bf = self._kf / (Cf * muf * gr_lat_f)
        Br = self._kr / (Cr * mur * gr_lat)
        v_lo = p.kinematic_blend_low
        v_hi = p.kinematic_blend_high
        mu_avg = 0.5 * (muf + mur)
        fzf0 = mg * lr / L
        return (
            steer * p.max_road_wheel_angle,
            p.max_steer_rate * h,
            (m, mg, self._hcg, lr, L, fz_min, mg - fz_min, p.tyre_load_sensitivity, fzf0, mg - fzf0, muf, mur),
            (v_lo, v_hi, v_hi - v_lo),
            (Br, Cr, self._Er, gr_lat, p.max_long_utilisation_rear, lr),
            (Bf, Cf, self._Ef, gr_lat_f, lf),
            (p.max_drive_force * throttle, p.max_power * throttle, p.front_drive_fraction,
             p.max_brake_decel * m * brake, mg, p.max_long_utilisation_front),
            (m, self._iz, lf, lr, fw, h),
            (m, self._drag, self._rr, L, lr, self._kin_dvy * mu_avg * h, self._kin_dr * mu_avg * h, h),
        )

    def _substeps(self, s: VehicleState, k: tuple, n: int) -> tuple:
        """Integrate ``n`` sub-steps from ``s`` with the step constants ``k``.

        Returns ``(x, y, heading, vx, vy, yaw_rate, road_wheel_angle, sum_rvy, sum_vxr)``
        (heading unwrapped; the sums of ``r vy`` and ``vx r`` over the sub-steps give the
        step's mean accelerations).  The small stages are written out here: a call per
        sub-step costs more than they do.
        """
        d_target, d_rate, loads, blend, rear, front, drive, body, motion = k
        m, mg, hcg, lr, L, fz_min, fz_max, ls, fzf0, fzr0, muf, mur = loads
        v_lo, v_hi, v_span = blend
        dcg = self._dcg
        h = motion[-1]
        x, y, psi, vx, vy, r, delta, ax = s.x, s.y, s.heading, s.vx, s.vy, s.yaw_rate, s.road_wheel_angle, s.ax
        sum_rvy = sum_vxr = 0.0
        fyf = vy_d = r_d = 0.0  # the dynamic lateral states, only used while the dynamic weight is > 0
        for _ in range(n):
            # 1. steering actuator (rate limited)
            if delta < d_target:
                delta += d_rate
                if delta > d_target:
                    delta = d_target
            elif delta > d_target:
                delta -= d_rate
                if delta < d_target:
                    delta = d_target
            cd = cos(delta)
            sd = sin(delta)
            # 2. axle loads with the load transfer of the last sub-step's ax; peak tyre force
            #    per axle (friction-ellipse radius), mu falling off with load
            fzf = (mg * lr - m * ax * hcg) / L
            if fzf < fz_min:
                fzf = fz_min
            elif fzf > fz_max:
                fzf = fz_max
            fzr = mg - fzf
            t = 1.0 - ls * (fzf - fzf0) / fzf0
            capf = muf * fzf * (t if t > 0.2 else 0.2)
            t = 1.0 - ls * (fzr - fzr0) / fzr0
            capr = mur * fzr * (t if t > 0.2 else 0.2)
            # 3. weight of the dynamic model against the kinematic one (smoothstep in the speed)
            v = hypot(vx, vy)
            if v >= v_hi:
                w = 1.0
            elif v <= v_lo:
                w = 0.0
            else:
                t = (v - v_lo) / v_span
                w = t * t * (3.0 - 2.0 * t)
            # 4.-6. tyre forces, lateral dynamics, velocities
            fyr, gr, fxf, pf, qf, pr_, qr = tyre_forces(w, vx, vy, r, fzf, capf, capr, rear, drive)
            if w > 0.0:
                fyf, vy_d, r_d = lateral_dynamics(vx, vy, r, cd, sd, capf, fxf, fyr, gr, front, body)
            vx, vy, r, ax = velocities(w, vx, vy, r, cd, sd, pf, qf, pr_, qr, fyf, vy_d, r_d, motion)
            sum_rvy += r * vy
            sum_vxr += vx * r
            # 7. pose of the geometric centre (semi-implicit, mid-point heading)
            if r != 0.0:
                psi_mid = psi + 0.5 * h * r
                psi += h * r
            else:
                psi_mid = psi
            if vx != 0.0 or vy != 0.0:
                c = cos(psi_mid)
                sn = sin(psi_mid)
                vcy = vy - dcg * r
                x += h * (vx * c - vcy * sn)
                y += h * (vx * sn + vcy * c)
        return x, y, psi, vx, vy, r, delta, sum_rvy, sum_vxr
