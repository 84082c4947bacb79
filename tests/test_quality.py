"""Driving-quality score: every term on synthetic traces with known answers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from drivefuzz.search.quality import (
    EVENTS,
    G,
    SIGNAL_KEYS,
    QualityConfig,
    QualityScore,
    oversteer_index,
    score_trace,
    signals,
    understeer_index,
)
from drivefuzz.sim.trace import trace_from_arrays

DT = 0.05
EGO_L, EGO_W = 4.6, 1.9
L_RATIO = 2.8 * 15.0  # wheelbase x steering ratio of the synthetic kinematic car


def smoothstep(t, t0, t1):
    s = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)
    return s * s * (3 - 2 * s)


def make_trace(n=400, dt=DT, actors=None, **channels):
    """Straight drive east at 10 m/s unless channels override; ego 4.6 x 1.9 m."""
    t = np.arange(n) * dt
    v = np.asarray(channels.pop("vx", np.full(n, 10.0)), dtype=float)
    ego = {
        "vx": v, "speed": np.abs(v), "vy": np.zeros(n), "ax": np.zeros(n), "ay": np.zeros(n),
        "yaw_rate": np.zeros(n), "steer_wheel_angle": np.zeros(n), "road_wheel_angle": np.zeros(n),
        "x": np.cumsum(v) * dt, "y": np.zeros(n), "heading": np.zeros(n),
    }
    ego.update({k: np.asarray(val, dtype=float) for k, val in channels.items()})
    meta = {"step_length": dt, "ego_length": EGO_L, "ego_width": EGO_W, "steering_ratio": 15.0}
    return trace_from_arrays(ego, meta, actors)


def turning_trace(n=400, v=10.0, swa_deg=90.0, ay_scale=None, dt=DT):
    """Kinematic turn: SWA ramps in at 3-4 s; ay = v^2 * SWA / (L * ratio) times ``ay_scale``."""
    t = np.arange(n) * dt
    v = np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()
    swa = math.radians(swa_deg) * smoothstep(t, 3, 4)
    ay = v**2 * swa / L_RATIO * (1.0 if ay_scale is None else ay_scale(t))
    return make_trace(n, dt, vx=v, ax=np.gradient(v, dt), ay=ay, yaw_rate=ay / v, steer_wheel_angle=swa)


# --------------------------------------------------------------------------- simple terms
def test_steady_straight_drive_all_zero():
    q = score_trace(make_trace())
    assert (q.ha, q.hb, q.ht, q.os, q.us) == (0, 0, 0, 0, 0)
    assert q.md is None and q.md_term == 0.0 and q.score == 0.0
    assert q.frames == {e: [] for e in EVENTS}
    assert q.n_frames == 400


def test_braking_step_counts_exactly():
    ax = np.zeros(400)
    ax[100:110] = -7.0
    q = score_trace(make_trace(ax=ax))
    assert q.hb == 10 and q.ha == 0
    assert q.frames["hb"] == list(range(100, 110))
    assert q.score == -10.0


def test_acceleration_step_counts_exactly():
    ax = np.zeros(400)
    ax[50:60] = 0.61 * G
    ax[60:70] = 0.59 * G  # just below: not counted
    q = score_trace(make_trace(ax=ax))
    assert q.ha == 10 and q.hb == 0
    assert q.frames["ha"] == list(range(50, 60))


def test_weights_scale_the_score():
    ax = np.zeros(400)
    ax[100:110] = -7.0
    q = score_trace(make_trace(ax=ax), QualityConfig(w_hb=2.5))
    assert q.hb == 10 and q.score == -25.0


def test_hard_turn_uses_steering_wheel_degrees_and_kmh():
    n = 100
    swa = np.zeros(n)
    vy = np.zeros(n)
    # 7 frames: |SWA| = 30 deg, |Vy| = 6 km/h -> K_t = 0.2 >= 0.18
    swa[10:17], vy[10:17] = math.radians(30), 6 / 3.6
    # 3 frames turning right (negative both): counted on absolute values
    swa[20:23], vy[20:23] = -math.radians(30), -6 / 3.6
    # K_t = 0.1: not counted
    swa[30:40], vy[30:40] = math.radians(30), 3 / 3.6
    # SWA below 20 deg with a large Vy: not counted
    swa[50:60], vy[50:60] = math.radians(15), 10 / 3.6
    q = score_trace(make_trace(n, steer_wheel_angle=swa, vy=vy))
    assert q.ht == 10
    assert q.frames["ht"] == list(range(10, 17)) + list(range(20, 23))


# --------------------------------------------------------------------------- minimum distance
def _actor(n, y_offset, x_offset=0.0, heading=0.0, length=EGO_L, width=EGO_W, aid="car1", kind="vehicle"):
    x = np.cumsum(np.full(n, 10.0)) * DT + x_offset
    return {"id": aid, "kind": kind, "length": length, "width": width,
            "x": x, "y": np.broadcast_to(y_offset, (n,)).astype(float), "heading": heading, "speed": 10.0}


def test_md_parallel_actor_known_body_distance():
    n = 60
    gap = np.full(n, 1.0)
    gap[30] = 0.3
    q = score_trace(make_trace(n, actors=[_actor(n, EGO_W + gap)]))
    assert q.md == pytest.approx(0.3, abs=1e-9)
    assert q.md_frame == 30 and q.md_actor == "car1"
    assert q.md_term == pytest.approx(1 / 0.3)
    assert q.score == pytest.approx(-1 / 0.3)


def test_md_is_body_to_body_not_centre_to_centre():
    n = 20
    # a pedestrian 0.5 x 0.5, rotated, 1 m ahead of the ego's front bumper
    ped = _actor(n, 0.0, x_offset=EGO_L / 2 + 0.25 + 1.0, heading=math.pi / 2, length=0.5, width=0.5,
                 aid="ped", kind="pedestrian")
    far = _actor(n, 30.0, aid="far")
    q = score_trace(make_trace(n, actors=[far, ped]), QualityConfig(c_md=2.0))
    assert q.md == pytest.approx(1.0, abs=1e-9) and q.md_actor == "ped"
    assert q.md_term == pytest.approx(2.0)


def test_md_actor_present_only_in_some_frames():
    n = 40
    y = np.full(n, np.nan)
    y[10:20] = EGO_W + 0.5
    q = score_trace(make_trace(n, actors=[_actor(n, y)]))
    assert q.md == pytest.approx(0.5, abs=1e-9) and 10 <= q.md_frame < 20


def test_no_actor_md_term_zero():
    q = score_trace(make_trace(30))
    assert q.md is None and q.md_term == 0.0 and q.md_frame is None and q.md_actor is None


def test_contact_gives_finite_md_term():
    n = 30
    q = score_trace(make_trace(n, actors=[_actor(n, EGO_W - 0.5)]))
    assert q.md == 0.0
    assert q.md_term == pytest.approx(1 / 0.1) and math.isfinite(q.score)
    q2 = score_trace(make_trace(n, actors=[_actor(n, EGO_W - 0.5)]), QualityConfig(c_md=2.0, md_eps=0.5))
    assert q2.md_term == pytest.approx(4.0)


# --------------------------------------------------------------------------- fuzzy systems
def test_oversteer_fuzzy_hand_points():
    # all inputs "low": the low output triangle (0,0,4), centroid 4/3 (as in the original)
    assert float(oversteer_index(0, 0, 0)) == pytest.approx(4 / 3)
    # yr fully high, sa/la not low: only the high triangle (6,10,10), centroid 26/3
    assert float(oversteer_index(0, 0.3, 45)) == pytest.approx(26 / 3)
    # sa & la high and yr low: low and high triangles, symmetric -> 5
    assert float(oversteer_index(50, 0.5, 0)) == pytest.approx(5.0)
    # the original's effective behaviour with small sa and la >= 0.12: os >= 4 from 10.5 deg/s
    assert float(oversteer_index(0, 0.12, 10.5)) >= 4.0
    assert float(oversteer_index(0, 0.12, 10.0)) < 4.0


def test_oversteer_yaw_rate_above_universe_is_high():
    # the original zeroed memberships above 45 deg/s (-> 1.33 or 0); clamped, 60 deg/s is fully high
    assert float(oversteer_index(0, 0.3, 60)) == pytest.approx(26 / 3)
    assert float(oversteer_index(0, 0, 60)) == pytest.approx(5.0)  # >= 4: still detected
    np.testing.assert_allclose(oversteer_index(0, 0.3, [45, 90, 1e6]), 26 / 3)


def test_oversteer_vectorised_matches_scalar():
    rng = np.random.default_rng(1)
    sa, la, yr = rng.uniform(0, 60, 50), rng.uniform(0, 0.6, 50), rng.uniform(0, 60, 50)
    vec = oversteer_index(sa, la, yr)
    assert vec.shape == (50,)
    np.testing.assert_allclose(vec, [float(oversteer_index(a, b, c)) for a, b, c in zip(sa, la, yr)])
    assert np.all((vec >= 0) & (vec <= 10))


def test_understeer_fuzzy_drop_side():
    # no drop: only the complementary "low" rule -> centroid of (0,0,10) = 10/3 < 4 (silent)
    assert float(understeer_index(0.0)) == pytest.approx(10 / 3)
    # full drop: the high triangle (0,10,10) -> 20/3; half: symmetric -> 5
    assert float(understeer_index(1.0)) == pytest.approx(20 / 3)
    assert float(understeer_index(0.5)) == pytest.approx(5.0)
    fd = np.linspace(0, 1, 101)
    us = understeer_index(fd)
    assert np.all(np.diff(us) >= -1e-12)  # monotone in the drop
    assert us[fd >= 0.3].min() >= 4.0 and us[fd <= 0.25].max() < 4.0
    assert float(understeer_index(5.0)) == pytest.approx(20 / 3)  # clamped


def test_understeer_fuzzy_hand_point_quarter_drop():
    # FD = 0.25: low = 0.75, high = 0.25; aggregate on x = 0..10:
    # [.75 .75 .75 .7 .6 .5 .4 .3 .25 .25 .25] -> trapezoid centroid 58/15 (< 4: not counted)
    assert float(understeer_index(0.25)) == pytest.approx(58 / 15)


def test_oversteer_fuzzy_hand_point_all_medium():
    # sa = 25, la = 0.25 are grid points where "med" = 1 and low = high = 0; yr = 22.5 lies
    # between grid points 20 and 25 where med = 16/18.5 -> only the med triangle (1,5,9): 5
    assert float(oversteer_index(25, 0.25, 22.5)) == pytest.approx(5.0)
    # yr = 0 adds "low" = 1: aggregate max(low (0,0,4), med (1,5,9)) on x = 0..10 is
    # [1 .75 .5 .5 .75 1 .75 .5 .25 0 0]; trapezoid centroid 257/66 (just below 4)
    assert float(oversteer_index(25, 0.25, 0)) == pytest.approx(257 / 66)


# --------------------------------------------------------------------------- detection on traces
def test_understeer_fires_on_gain_drop():
    # SWA held at 90 deg while the lateral acceleration halves at 10-10.5 s (front grip lost)
    tr = turning_trace(ay_scale=lambda t: 1 - 0.5 * smoothstep(t, 10, 10.5))
    q = score_trace(tr)
    assert q.us > 0
    fired = np.array(q.frames["us"]) * DT
    assert fired.min() >= 10.0 and fired.max() <= 10.5 + 2.0 + 0.1
    s = signals(tr)
    assert s["FD"].max() == pytest.approx(0.5, abs=0.06)
    assert q.os == 0


def test_understeer_silent_when_gain_constant():
    q = score_trace(turning_trace())
    assert q.us == 0 and q.os == 0 and q.score == 0.0


def test_understeer_silent_when_braking_in_a_turn():
    """Ay/SWA falls with v^2 when slowing in a bend; the speed-normalised gain does not."""
    t = np.arange(400) * DT
    tr = turning_trace(v=10 - 5 * smoothstep(t, 8, 10))
    assert score_trace(tr).us == 0
    assert score_trace(tr, QualityConfig(us_gain="raw")).us > 0  # the literal Ay_h/SWA_h would fire


def test_understeer_not_read_while_the_steering_ramps():
    """The lateral acceleration lags the steering (here 0.2 s): during a quick ramp from a held
    15 deg to 135 deg the ratio Ay_h/SWA_h dips without any loss of grip. The gain is only read
    where the steering is quasi-steady, so nothing fires; without that gate the dip counts."""
    n = 400
    t = np.arange(n) * DT
    v = np.full(n, 10.0)
    swa = math.radians(15) * smoothstep(t, 2, 3) + math.radians(120) * smoothstep(t, 8, 8.5)
    ay = v**2 * np.interp(t - 0.2, t, swa, left=0.0) / L_RATIO
    tr = make_trace(n, vx=v, ay=ay, yaw_rate=ay / v, steer_wheel_angle=swa)
    assert score_trace(tr).us == 0
    assert score_trace(tr, QualityConfig(us_max_steer_rate=1e9)).us > 0


def _two_turns(same_side: bool, gain_2: float):
    """Steer left to 90 deg at 3-4 s, then at 8-9 s to 180 deg (same side) or to -90 deg; the
    gain from steering to lateral acceleration is ``gain_2`` times the first one from 8.5 s."""
    n = 400
    t = np.arange(n) * DT
    v = np.full(n, 10.0)
    swa = math.radians(90) * (smoothstep(t, 3, 4) + (1 if same_side else -2) * smoothstep(t, 8, 9))
    gain = np.where(t < 8.5, 1.0, gain_2)
    ay = v**2 * swa * gain / L_RATIO
    return make_trace(n, vx=v, ay=ay, yaw_rate=ay / v, steer_wheel_angle=swa)


def test_understeer_reference_resets_when_the_steering_changes_side():
    # a 40 % lower gain in a turn to the other side is not a drop within one turn ...
    assert score_trace(_two_turns(False, 0.6)).us == 0
    # ... while the same drop while turning further the same way is understeer
    assert score_trace(_two_turns(True, 0.6)).us > 0


def test_understeer_uses_yaw_rate_by_default_and_measured_ay_on_request():
    # the yaw rate (and so vx * yaw_rate) falls by half while the accelerometer's ay does not
    base = turning_trace()
    t = np.arange(400) * DT
    yr = np.asarray(base["yaw_rate"]) * (1 - 0.5 * smoothstep(t, 10, 10.5))
    tr = make_trace(400, vx=base["vx"], ax=base["ax"], ay=base["ay"], yaw_rate=yr,
                    steer_wheel_angle=base["steer_wheel_angle"])
    assert score_trace(tr).us > 0
    assert score_trace(tr, QualityConfig(us_ay="measured")).us == 0


def _yaw_surge_trace(peak_degs):
    n = 400
    t = np.arange(n) * DT
    v = np.full(n, 15.0)
    yr = math.radians(5) + math.radians(peak_degs - 5) * smoothstep(t, 8, 8.4) * (1 - smoothstep(t, 10, 11))
    ay = v * math.radians(5) + 0.5 * G * ((t >= 8) & (t < 9))  # abrupt lateral jolt
    # small steering (5 deg at the wheel), as in the paper's oversteer experiment
    return make_trace(n, vx=v, ay=ay, yaw_rate=yr, steer_wheel_angle=np.full(n, math.radians(5)))


def test_oversteer_fires_on_yaw_surge():
    q = score_trace(_yaw_surge_trace(40))
    assert q.os > 0 and q.us == 0
    fired = np.array(q.frames["os"]) * DT
    assert fired.min() >= 7.5 and fired.max() <= 9.5


def test_oversteer_fires_above_yaw_universe():
    assert score_trace(_yaw_surge_trace(80)).os > 0


def test_oversteer_silent_on_smooth_steady_turn():
    n = 400
    t = np.arange(n) * DT
    v = np.full(n, 15.0)
    yr = math.radians(25) * smoothstep(t, 3, 6)
    tr = make_trace(n, vx=v, ay=v * yr, yaw_rate=yr, steer_wheel_angle=yr / v * L_RATIO)
    s = signals(tr)
    assert s["YR_h"].max() > 20  # a real turn...
    q = score_trace(tr)
    assert q.os == 0 and q.us == 0  # ...but smooth


# --------------------------------------------------------------------------- filters, robustness
def test_filters_follow_the_real_sample_rate():
    """A 2 Hz steering oscillation survives the 3.5 Hz light filter and not the 0.5 Hz heavy one
    at 20 Hz and at 10 Hz sampling alike (a hard-coded 20 Hz would cut it at 10 Hz)."""
    for dt in (0.05, 0.1):
        n = int(20 / dt)
        t = np.arange(n) * dt
        swa = math.radians(30) * np.sin(2 * math.pi * 2.0 * t)
        s = signals(make_trace(n, dt=dt, steer_wheel_angle=swa))
        mid = slice(n // 4, 3 * n // 4)
        assert s["dSWA"][mid].max() == pytest.approx(30, rel=0.1)
        assert s["SWA_h"][mid].max() < 3


def test_cutoff_above_nyquist_does_not_crash():
    q = score_trace(make_trace(50, dt=0.2))
    assert q.score == 0.0


@pytest.mark.parametrize("n", [1, 2, 3, 5, 15, 16, 17])
def test_short_traces_score_without_error(n):
    ax = np.full(n, -7.0)
    q = score_trace(make_trace(n, ax=ax, actors=[_actor(n, EGO_W + 1.0)]))
    assert q.hb == n and q.md == pytest.approx(1.0)
    s = signals(make_trace(n))
    assert all(len(s[k]) == n for k in SIGNAL_KEYS)


def test_missing_channels_fall_back():
    n = 100
    v = np.concatenate([np.full(50, 20.0), 20.0 - 7.0 * DT * np.arange(1, 51)])
    nan = np.full(n, np.nan)
    tr = make_trace(n, vx=v, ax=nan, ay=nan, yaw_rate=nan, steer_wheel_angle=nan)
    q = score_trace(tr)
    assert 48 <= q.hb <= 50 and q.ha == 0  # ax from d(vx)/dt
    s = signals(tr)
    assert all(np.all(np.isfinite(s[k])) for k in ("SWA", "AVz", "Ay", "OSI", "USI", "FD"))


def test_signals_keys_units_and_masks():
    ax = np.zeros(400)
    ax[100:110] = -7.0
    tr = make_trace(ax=ax)
    s = signals(tr)
    assert set(s) == set(SIGNAL_KEYS)
    assert all(len(v) == 400 for v in s.values())
    assert s["Vx"][0] == pytest.approx(36.0)  # km/h
    assert s["hb_mask"].dtype == bool and s["hb_mask"].sum() == 10
    q = score_trace(tr)
    for e in EVENTS:
        assert np.flatnonzero(s[f"{e}_mask"]).tolist() == q.frames[e]


def test_as_dict_is_json_friendly():
    n = 60
    ax = np.zeros(n)
    ax[5:8] = 7.0
    q = score_trace(make_trace(n, ax=ax, actors=[_actor(n, EGO_W + 0.4)]))
    d = json.loads(json.dumps(q.as_dict(), allow_nan=False))
    assert d["ha"] == 3 and d["frames"]["ha"] == [5, 6, 7]
    assert d["md"] == pytest.approx(0.4) and d["md_actor"] == "car1"
    assert d["score"] == pytest.approx(-(3 + 1 / 0.4))
    assert isinstance(q, QualityScore)
    with pytest.raises(Exception):
        q.ha = 0  # frozen
    assert json.loads(json.dumps(score_trace(make_trace(5)).as_dict()))["md"] is None


def test_config_is_validated_and_frozen():
    cfg = QualityConfig()
    assert (cfg.w_ha, cfg.c_md, cfg.md_eps, cfg.ha_g, cfg.ht_swa_deg, cfg.ht_kt) == (1.0, 1.0, 0.1, 0.6, 20.0, 0.18)
    assert (cfg.os_threshold, cfg.us_threshold, cfg.min_vx_kmh, cfg.os_min_ay_d_g, cfg.us_min_swa_h_deg) == (
        4.0, 4.0, 5.0, 0.1, 10.0)
    assert (cfg.light_hz, cfg.heavy_hz, cfg.filter_order) == (3.5, 0.5, 4)
    with pytest.raises(ValidationError):
        QualityConfig(md_eps=0)
    with pytest.raises(ValidationError):
        QualityConfig(unknown=1)
    with pytest.raises(ValidationError):
        cfg.w_ha = 2.0


_finite = st.floats(-30, 30, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 80).flatmap(lambda n: st.lists(st.tuples(_finite, _finite, _finite, _finite, _finite),
                                                        min_size=n, max_size=n)))
def test_random_traces_never_crash(rows):
    a = np.array(rows)
    n = len(a)
    tr = make_trace(n, vx=a[:, 0], ax=a[:, 1], ay=a[:, 2], yaw_rate=a[:, 3] / 10,
                    steer_wheel_angle=a[:, 4] / 5, vy=a[:, 2] / 3)
    q = score_trace(tr)
    assert math.isfinite(q.score) and q.score <= 0
    assert all(0 <= getattr(q, e) <= n for e in EVENTS)


def test_md_pruning_matches_brute_force():
    from drivefuzz.geometry import rect_distance
    from drivefuzz.search.quality import min_distance

    rng = np.random.default_rng(7)
    n = 120
    t = np.arange(n) * DT
    actors = []
    for k in range(25):
        h = rng.uniform(-math.pi, math.pi)
        vv = rng.uniform(0, 12)
        actors.append({"id": f"a{k}", "kind": "vehicle", "length": rng.uniform(0.4, 12), "width": rng.uniform(0.4, 3),
                       "x": rng.uniform(-10, 70) + vv * math.cos(h) * t, "y": rng.uniform(-8, 8) + vv * math.sin(h) * t,
                       "heading": h + 0.1 * t, "speed": vv})
    for ego_y in (0.0, -200.0):  # among the actors (some touch the ego), then clear of them all
        tr = make_trace(n, actors=actors, heading=0.05 * np.sin(t), y=np.full(n, ego_y))
        md, frame, aid = min_distance(tr)
        a = tr.actors
        f = a.frame
        d = rect_distance(tr["x"][f], tr["y"][f], tr["heading"][f], EGO_L, EGO_W,
                          a.x, a.y, a.heading, a.length[a.actor], a.width[a.actor])
        assert md == pytest.approx(d.min(), abs=1e-12)
        if ego_y < 0:
            assert md > 5.0
            k = int(np.argmin(d))
            assert (frame, aid) == (int(f[k]), a.ids[a.actor[k]])
