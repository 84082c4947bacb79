"""Tests of the vehicle physics (drivefuzz.sim.physics): pure Python, fast."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivefuzz.sim.physics import G, VehicleParams, VehiclePhysics, VehicleState, place_state

P = VehicleParams()


def _finite(s: VehicleState) -> bool:
    return all(
        math.isfinite(v)
        for v in (s.x, s.y, s.heading, s.vx, s.vy, s.yaw_rate, s.road_wheel_angle, s.ax, s.ay)
    )


def _hold_speed(ph: VehiclePhysics, v_ref: float) -> float:
    """Simple P throttle controller (no brake)."""
    return min(1.0, max(0.0, 0.05 + 0.5 * (v_ref - ph.state.vx)))


def _corner(v: float, steer: float, mu_f: float, mu_r: float, t_end: float, dt: float = 0.05):
    """Drive straight at ``v`` then step-steer at t = 0.5 s holding speed; return the states."""
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, v, P))
    out = []
    for i in range(int(round(t_end / dt))):
        s = ph.step(steer if i * dt >= 0.5 else 0.0, _hold_speed(ph, v), 0.0, dt, mu_f, mu_r)
        assert _finite(s)
        out.append(s)
    return out


# ---------------------------------------------------------------------------- geometry


def test_params_geometry():
    assert P.cg_to_rear == pytest.approx(1.5)
    assert P.rear_overhang == pytest.approx(P.length - P.wheelbase - P.front_overhang)
    assert P.centre_to_front_axle + P.centre_to_rear_axle == pytest.approx(P.wheelbase)
    # the body extends front_overhang beyond the front axle and rear_overhang behind the rear one
    assert P.centre_to_front_axle + P.front_overhang == pytest.approx(P.length / 2)
    assert P.centre_to_rear_axle + P.rear_overhang == pytest.approx(P.length / 2)
    assert P.understeer_gradient > 0.0  # understeering car
    with pytest.raises(ValueError):
        VehicleParams(wheelbase=4.0, front_overhang=1.0)  # does not fit the body
    with pytest.raises(ValueError):
        VehicleParams(mass=0.0)


def test_place_state_axles_and_steering_wheel():
    s = place_state(10.0, -5.0, math.pi / 2, 12.0, P)
    assert (s.vx, s.vy, s.yaw_rate, s.road_wheel_angle) == (12.0, 0.0, 0.0, 0.0)
    assert s.speed == 12.0
    ph = VehiclePhysics(P, s)
    (fx, fy), (rx, ry) = ph.axle_positions()
    assert math.hypot(fx - rx, fy - ry) == pytest.approx(P.wheelbase)
    assert fx == pytest.approx(10.0) and rx == pytest.approx(10.0)
    assert fy == pytest.approx(-5.0 + P.centre_to_front_axle)  # heading north: front is +y
    assert ry == pytest.approx(-5.0 - P.centre_to_rear_axle)
    ph.state.road_wheel_angle = 0.1
    assert ph.steering_wheel_angle() == pytest.approx(0.1 * P.steering_ratio)
    with pytest.raises(ValueError):
        place_state(0, 0, 0, -1.0, P)


def test_steering_actuator_rate_limit_and_clipping():
    ph = VehiclePhysics(P, place_state(0, 0, 0, 10.0, P))
    s = ph.step(5.0, 0.0, 0.0, 0.05)  # clipped to 1
    assert s.road_wheel_angle == pytest.approx(P.max_steer_rate * 0.05)
    for _ in range(40):
        s = ph.step(1.0, 0.0, 0.0, 0.05)
    assert s.road_wheel_angle == pytest.approx(P.max_road_wheel_angle)
    s = ph.step(-1.0, 0.0, 0.0, 0.1)
    assert s.road_wheel_angle == pytest.approx(P.max_road_wheel_angle - P.max_steer_rate * 0.1)
    s = ph.step(float("nan"), float("nan"), float("nan"), 0.05, float("nan"), float("inf"), float("nan"))
    assert _finite(s)
    with pytest.raises(ValueError):
        ph.step(0.0, 0.0, 0.0, 0.0)


# -------------------------------------------------------------- 1. linear steady state


@pytest.mark.parametrize("v,steer,dt", [(15.0, 0.02, 0.05), (20.0, 0.02, 0.05), (20.0, 0.03, 0.1), (30.0, 0.01, 0.05)])
def test_linear_steady_state_yaw_rate(v, steer, dt):
    states = _corner(v, steer, 1.0, 1.0, 6.0, dt)
    s = states[-1]
    r_lin = VehiclePhysics.steady_state_yaw_rate(P, s.vx, s.road_wheel_angle)
    assert s.road_wheel_angle == pytest.approx(steer * P.max_road_wheel_angle)
    assert s.yaw_rate == pytest.approx(r_lin, rel=0.10)
    assert s.yaw_rate == pytest.approx(r_lin, rel=0.02)  # in fact much closer
    assert s.ay == pytest.approx(s.vx * s.yaw_rate, rel=0.02)  # steady: ay = vx r
    assert abs(s.vx - v) < 0.3  # P-controller offset


# ------------------------------------------------------------- 2. low-mu understeer


def test_low_mu_saturates_and_understeers():
    mu, v, steer = 0.2, 15.0, 0.2
    s = _corner(v, steer, mu, mu, 6.0)[-1]
    dry = _corner(v, steer, 1.0, 1.0, 6.0)[-1]
    r_lin = VehiclePhysics.steady_state_yaw_rate(P, s.vx, s.road_wheel_angle)
    assert 0.7 * mu * G <= abs(s.ay) <= 1.1 * mu * G
    assert 0.0 < s.yaw_rate < 0.4 * r_lin  # understeer: much less yaw than commanded
    assert s.yaw_rate < 0.4 * dry.yaw_rate
    # path radius (v / r) much larger than the linear (commanded) radius
    assert s.speed / s.yaw_rate > 2.5 * s.vx / r_lin
    assert abs(s.vy) < 0.1 * s.vx  # the front slides, the rear holds: no spin


def test_dry_limit_is_bounded_by_friction():
    s = _corner(20.0, 0.5, 1.0, 1.0, 4.0)[-1]
    assert abs(s.ay) <= 1.1 * G


# ---------------------------------------------------------------- 3. braking distance


def _braking_distance(mu: float, v0: float = 20.0, dt: float = 0.05) -> float:
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, v0, P))
    for _ in range(2000):
        s = ph.step(0.0, 0.0, 1.0, dt, mu, mu)
        assert s.vx >= 0.0 and _finite(s)
        if s.vx == 0.0:
            return s.x
    raise AssertionError("did not stop")


@pytest.mark.parametrize("dt", [0.05, 0.1])
def test_braking_distance_scales_with_inverse_mu(dt):
    d1, d05, d025 = (_braking_distance(mu, dt=dt) for mu in (1.0, 0.5, 0.25))
    assert 20.0**2 / (2 * 9.5) < d1 < 20.0**2 / (2 * 7.0)
    assert d05 / d1 == pytest.approx(2.0, rel=0.15)
    assert d025 / d1 == pytest.approx(4.0, rel=0.15)


# ------------------------------------------------------------------------ 4. stability


@pytest.mark.parametrize("dt", [0.05, 0.1])
def test_standstill_to_motorway_and_back(dt):
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.3, 0.0, P))
    t = 0.0
    vmax = 0.0
    while ph.state.vx < 40.0:  # full throttle with a steering sweep shrinking with speed
        amp = 0.6 / (1.0 + ph.state.vx / 2.0)
        s = ph.step(amp * math.sin(1.5 * t), 1.0, 0.0, dt)
        t += dt
        assert _finite(s) and s.vx >= 0.0 and abs(s.yaw_rate) < 1.5
        vmax = max(vmax, s.speed)
        assert t < 40.0, "never reached 40 m/s"
    assert 8.0 < t < 25.0
    t_brake = t
    while ph.state.speed > 0.0:  # full brake with a sweep
        s = ph.step(0.05 * math.sin(2.0 * t), 0.0, 1.0, dt)
        t += dt
        assert _finite(s) and s.vx >= 0.0 and s.speed <= vmax + 1e-9
        assert t - t_brake < 10.0, "never stopped"
    stopped = ph.state
    assert (stopped.vx, stopped.vy, stopped.yaw_rate) == (0.0, 0.0, 0.0)
    for i in range(60):  # brake held, steering moving: stays exactly put
        s = ph.step(math.sin(i), 0.0, 1.0, dt)
        assert (s.x, s.y, s.heading, s.vx, s.vy, s.yaw_rate) == (
            stopped.x, stopped.y, stopped.heading, 0.0, 0.0, 0.0)
    for _ in range(20):  # released, no throttle: still exactly put
        s = ph.step(0.0, 0.0, 0.0, dt)
        assert (s.x, s.y, s.vx) == (stopped.x, stopped.y, 0.0)


_segment = st.tuples(
    st.floats(-1.0, 1.0),  # steer
    st.floats(0.0, 1.0),  # throttle
    st.sampled_from([0.0, 0.0, 0.3, 1.0]),  # brake
    st.integers(1, 40),  # steps held
)


@settings(max_examples=60, deadline=None)
@given(
    v0=st.floats(0.0, 40.0),
    dt=st.sampled_from([0.05, 0.1]),
    segments=st.lists(_segment, min_size=1, max_size=8),
)
def test_property_random_controls_dry(v0, dt, segments):
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, v0, P))
    for steer, throttle, brake, k in segments:
        for _ in range(k):
            s = ph.step(steer, throttle, brake, dt)
            assert _finite(s)
            assert s.speed < 70.0
            assert abs(s.yaw_rate) < 3.0
            assert abs(s.road_wheel_angle) <= P.max_road_wheel_angle + 1e-12
            assert -math.pi <= s.heading <= math.pi


@settings(max_examples=40, deadline=None)
@given(
    v0=st.floats(0.0, 40.0),
    dt=st.sampled_from([0.05, 0.1]),
    mu_f=st.floats(0.05, 2.0),
    mu_r=st.floats(0.05, 2.0),
    wind=st.floats(-3000.0, 3000.0),
    segments=st.lists(_segment, min_size=1, max_size=6),
)
def test_property_random_controls_any_friction(v0, dt, mu_f, mu_r, wind, segments):
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, v0, P))
    for steer, throttle, brake, k in segments:
        for _ in range(k):
            s = ph.step(steer, throttle, brake, dt, mu_f, mu_r, wind)
            assert _finite(s)
            assert s.speed < 70.0
            assert abs(s.yaw_rate) < 12.0  # a pirouette on slicks-front / ice-rear is fast


# ------------------------------------------------------------------------ 5. oversteer


def test_rear_on_ice_oversteers_and_spins_up():
    v, steer = 15.0, 0.1
    states = _corner(v, steer, 1.0, 0.2, 4.0)
    r_dry = VehiclePhysics.steady_state_yaw_rate(P, v, steer * P.max_road_wheel_angle)
    r_max = max(abs(s.yaw_rate) for s in states)
    assert r_max > 1.5 * r_dry
    assert max(abs(math.atan2(s.vy, s.vx)) for s in states if s.vx > 0) > 0.3  # large sideslip
    # on a uniformly dry road the same manoeuvre stays close to the linear value
    dry = _corner(v, steer, 1.0, 1.0, 4.0)
    assert max(abs(s.yaw_rate) for s in dry) < 1.2 * r_dry


def test_full_spin_then_brake_stops_and_stays():
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, 25.0, P))
    seen_backwards = False
    for i in range(300):
        s = ph.step(0.3 if i < 40 else 0.0, 0.0, 0.0 if i < 40 else 1.0, 0.05, 1.0, 0.1)
        assert _finite(s) and s.speed <= 25.0 + 1e-9  # no energy from nowhere
        seen_backwards |= s.vx < -1.0
    assert seen_backwards  # the spin went past 90 deg: the car slid backwards
    assert (s.vx, s.vy, s.yaw_rate) == (0.0, 0.0, 0.0)


# ------------------------------------------------------------- 6. coasting / standstill


def test_coasting_decelerates_more_at_speed():
    decel = {}
    for v in (10.0, 30.0):
        ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, v, P))
        s = ph.step(0.0, 0.0, 0.0, 0.05)
        assert s.vx < v and s.ax < 0.0
        decel[v] = -s.ax
        for _ in range(100):
            s = ph.step(0.0, 0.0, 0.0, 0.05)
        assert s.vx < v - 0.5
    assert decel[30.0] > decel[10.0] > P.rolling_resistance * G * 0.9


def test_stationary_zero_input_stays_exactly_put():
    s0 = place_state(3.0, 4.0, 1.0, 0.0, P)
    ph = VehiclePhysics(P, s0)
    for _ in range(200):
        s = ph.step(0.0, 0.0, 0.0, 0.05)
    assert s == VehicleState(3.0, 4.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def test_no_reverse_from_brake_or_throttle():
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, 0.3, P))
    for _ in range(100):
        s = ph.step(0.0, 0.2, 1.0, 0.05)  # brake beats a little throttle
        assert s.vx >= 0.0
    assert s.vx == 0.0
    s = ph.step(0.0, 1.0, 0.0, 0.05)  # throttle only ever drives forward
    assert s.vx > 0.0 and s.ax > 0.0


# ------------------------------------------------------------------------- misc


def test_launch_acceleration_and_top_speed_power_limit():
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, 0.0, P))
    s = ph.step(0.0, 1.0, 0.0, 0.05)
    assert 3.5 <= s.ax <= 4.0
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, 40.0, P))
    s = ph.step(0.0, 1.0, 0.0, 0.05)
    assert 0.0 < s.ax < P.max_power / 40.0 / P.mass


def test_left_steer_turns_left_and_wind_pushes_left():
    s = _corner(10.0, 0.1, 1.0, 1.0, 3.0)[-1]
    assert s.yaw_rate > 0.0 and s.heading > 0.0 and s.y > 0.0 and s.ay > 0.0
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, 25.0, P))
    for _ in range(40):
        s = ph.step(0.0, _hold_speed(ph, 25.0), 0.0, 0.05, wind_force_lat=1500.0)
    assert s.y > 0.0


def test_dt_consistency():
    def run(dt):
        ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, 12.0, P))
        for i in range(int(round(6.0 / dt))):
            t = i * dt
            ph.step(0.3 * math.sin(t), 0.3, 0.0, dt, 0.6, 0.6)
        return ph.state

    a, b = run(0.05), run(0.1)
    assert math.hypot(a.x - b.x, a.y - b.y) < 0.5
    assert abs(a.heading - b.heading) < 0.05
    assert abs(a.vx - b.vx) < 0.1


def test_low_speed_follows_kinematic_model():
    ph = VehiclePhysics(P, place_state(0.0, 0.0, 0.0, 0.0, P))
    for _ in range(60):
        s = ph.step(1.0, 0.1, 0.0, 0.05)
    assert 0.2 < s.vx < 1.0
    assert s.yaw_rate == pytest.approx(s.vx * math.tan(s.road_wheel_angle) / P.wheelbase, rel=1e-6)
    assert s.vy == pytest.approx(P.cg_to_rear * s.yaw_rate, rel=1e-6)
