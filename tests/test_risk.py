"""Risk-shaped feedback: each component on hand-made traces with known answers, then real runs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from drivefuzz.search.risk import COMPONENTS, G, RiskConfig, RiskScore, risk_score, signals
from drivefuzz.sim.trace import trace_from_arrays

DT = 0.05
ROOT = Path(__file__).resolve().parent.parent


def drive(n=400, v=10.0, actors=None, **channels):
    """The ego drives east along y = 0 at ``v`` m/s from x = 0 (centre), 4.6 x 1.9 m, dry road."""
    t = np.arange(n) * DT
    ego = {"t": t, "x": v * t, "y": np.zeros(n), "heading": np.zeros(n), "speed": np.full(n, v),
           "vx": np.full(n, v), "vy": np.zeros(n), "ax": np.zeros(n), "ay": np.zeros(n),
           "yaw_rate": np.zeros(n), "mu_front": np.ones(n), "mu_rear": np.ones(n)}
    ego.update({k: np.broadcast_to(np.asarray(val, dtype=float), (n,)).copy() for k, val in channels.items()})
    return trace_from_arrays(ego, {"step_length": DT, "ego_length": 4.6, "ego_width": 1.9}, actors)


def car(aid, x, y, heading, speed, kind="vehicle", length=4.6, width=1.9):
    return {"id": aid, "kind": kind, "length": length, "width": width, "x": x, "y": y,
            "heading": heading, "speed": speed}


def along(n, x0, v, y=0.0):
    """An actor driving east in the ego's lane (``y = 0``) or beside it."""
    t = np.arange(n) * DT
    return x0 + v * t, np.full(n, y)


# --------------------------------------------------------------------------- TTC and DRAC
def test_closing_leader_gives_falling_ttc_and_outscores_a_receding_one():
    n = 200  # 10 s: a leader 60 m ahead at 5 m/s, the ego at 10 m/s -> gap 55.4 m .. 5.4 m
    x, y = along(n, 60.0, 5.0)
    closing = drive(n, actors=[car("lead", x, y, 0.0, 5.0)])
    sig = signals(closing)
    ttc = sig["ttc"]
    finite = np.isfinite(ttc)
    assert finite[-1] and not finite[0]  # beyond the 5 s horizon at first
    assert np.all(np.diff(ttc[finite]) < 0)  # falls every frame while it closes
    assert ttc[-1] == pytest.approx((55.4 - 5.0 * DT * (n - 1)) / 5.0, abs=1e-9)  # gap / closing speed
    r_close = risk_score(closing)
    assert r_close.ttc == pytest.approx((55.4 - 5.0 * DT * (n - 1)) / 5.0, abs=1e-6)
    assert r_close.ttc_actor == "lead" and r_close.ttc_frame == n - 1
    # DRAC: 5 m/s to shed within TTC on mu = 1: 5 / (2 TTC) / g
    assert r_close.drac == pytest.approx(5.0 / (2.0 * r_close.ttc) / G, rel=1e-6)
    x, y = along(n, 60.0, 15.0)
    r_away = risk_score(drive(n, actors=[car("lead", x, y, 0.0, 15.0)]))
    assert r_away.ttc is None and r_away.drac is None and r_away.risks["ttc"] == 0.0
    assert r_close.score > r_away.score + 0.3
    assert r_close.riskiest_actor == "lead"


@pytest.mark.parametrize(("speed", "x0"), [(10.0, 0.0), (13.0, -20.0), (7.0, 20.0)])  # beside, overtaking, overtaken
def test_parallel_car_in_the_next_lane_gives_no_ttc(speed, x0):
    n = 300
    x, y = along(n, x0, speed, y=3.2)  # lane centres 3.2 m apart: 1.3 m between the bodies
    r = risk_score(drive(n, actors=[car("side", x, y, 0.0, speed)]))
    assert r.ttc is None and r.risks["ttc"] == 0.0 and r.drac is None
    assert r.pet is None  # same direction: no crossing conflict
    assert r.gap == pytest.approx(1.3, abs=1e-9)
    assert r.score < 0.15  # only the 1.3 m clearance, which is routine


def test_stopped_car_ahead_counts_while_a_curve_the_ego_leaves_does_not():
    # the ego brakes to a stop 2 m behind a parked car: the TTC is taken on its path ahead, which
    # the trace cuts short (the ray along its heading carries it on)
    n = 200
    t = np.arange(n) * DT
    v = np.maximum(10.0 - 2.5 * t, 0.0)
    x = np.cumsum(v) * DT
    parked_x = x[-1] + 4.6 + 2.0
    r = risk_score(drive(n, actors=[car("parked", parked_x, 0.0, 0.0, 0.0)], x=x, speed=v, vx=v, ax=-2.5))
    assert r.ttc is not None and r.ttc_actor == "parked"
    # the ego turns north at once; a parked car straight ahead of its initial heading (constant
    # velocity: contact in 1.5 s) is off the path the ego then drives
    h = np.minimum(t * 1.0, math.pi / 2)
    ex, ey = np.cumsum(5.0 * np.cos(h)) * DT, np.cumsum(5.0 * np.sin(h)) * DT
    turning = drive(n, v=5.0, actors=[car("off", 12.0, 0.0, math.pi / 2, 0.0)], x=ex, y=ey, heading=h)
    assert risk_score(turning).ttc is None
    straight = drive(n, v=5.0, actors=[car("off", 12.0 + 5.0 * 2.0, 0.0, math.pi / 2, 0.0)])
    assert risk_score(straight).ttc_actor == "off"


# --------------------------------------------------------------------------- PET
def crossing(t_cross, n=400, speed=5.0, x_c=100.0):
    """An actor driving north along x = ``x_c`` whose centre crosses y = 0 at ``t_cross`` [s]."""
    t = np.arange(n) * DT
    return car("cross", np.full(n, x_c), speed * (t - t_cross), math.pi / 2, speed)


def test_crossing_actor_just_behind_the_ego_has_a_small_pet_and_outscores_a_late_one():
    # the ego's rear leaves the actor's lane (x = 100 +- 0.95) at t = 10.325 s; the actor's front
    # enters the ego's lane at t_cross - 0.65 s (less the 0.5 m reach and half a node)
    near = risk_score(drive(actors=[crossing(11.5)]))
    late = risk_score(drive(actors=[crossing(16.0)]))
    assert near.pet is not None and 0.2 < near.pet < 1.0
    assert late.pet is not None and 4.5 < late.pet < 5.5
    assert near.pet_actor == "cross" and near.pet_frame > 200  # the actor's arrival, after the ego's
    assert near.risks["pet"] > 0.9 and late.risks["pet"] < 0.05
    assert near.score > late.score + 0.5


def test_crossing_ahead_of_the_ego_counts_the_ego_as_the_later_arrival():
    r = risk_score(drive(actors=[crossing(9.0)]))  # the actor clears the lane before the ego arrives
    assert r.pet is not None and r.pet < 1.0
    assert r.pet_frame is not None and r.pet_frame * DT < 10.0  # the ego's arrival


def test_a_car_following_the_ego_through_a_turn_has_no_pet():
    """A car that follows the ego's path 1 s behind through a 90-degree turn of 8 m radius is following, not
    crossing: before, the ego's nodes a few metres along the bend headed 25 degrees and more away from the
    follower's, and the follower had a "PET" of its time gap (a close encounter every time a car followed the
    ego through a junction). A car crossing the bend's exit still has one."""
    n, v, r = 400, 8.0, 8.0

    def path(t):  # east along y = -r to x = 0, a quarter circle left about (0, 0), then north along x = r
        s = v * t - 40.0  # [m] along the path from the start of the bend
        arc = math.pi / 2 * r
        x = np.where(s < 0, s, np.where(s < arc, r * np.sin(np.clip(s, 0, arc) / r), r))
        y = np.where(s < 0, -r, np.where(s < arc, -r * np.cos(np.clip(s, 0, arc) / r), s - arc))
        h = np.where(s < 0, 0.0, np.where(s < arc, np.clip(s, 0, arc) / r, math.pi / 2))
        return x, y, h

    t = np.arange(n) * DT
    ex, ey, eh = path(t)
    ego = {"t": t, "x": ex, "y": ey, "heading": eh, "speed": np.full(n, v), "vx": v * np.cos(eh),
           "vy": v * np.sin(eh), "ax": np.zeros(n), "ay": np.zeros(n), "yaw_rate": np.zeros(n),
           "mu_front": np.ones(n), "mu_rear": np.ones(n)}
    fx, fy, fh = path(t - 1.0)
    exit_y = 20.0  # a car crossing the northbound exit at y = 20 from the east, 0.6 s after the ego passed
    t_ego = (40.0 + math.pi / 2 * r + exit_y) / v
    cx = r + 12.0 - 10.0 * (t - (t_ego + 0.6 - 0.7))
    actors = [car("follower", fx, fy, fh, np.full(n, v)),
              car("cross", cx, np.full(n, exit_y), np.full(n, math.pi), np.full(n, 10.0))]
    trace = trace_from_arrays(ego, {"step_length": DT, "ego_length": 4.6, "ego_width": 1.9}, actors)
    r = risk_score(trace)
    pets = {a: v for a, c, v, _ in r.encounters if c == "pet"}
    assert "follower" not in pets, pets
    assert pets.get("cross") is not None and pets["cross"] < 1.5


# --------------------------------------------------------------------------- gap, grip, harsh
def test_min_gap_is_exact_and_near_miss_outweighs_routine_harsh_braking():
    n = 2400  # two minutes of brake chatter at 6 m/s^2 with nothing near: counts nothing
    chatter = np.where(np.arange(n) % 2 == 0, -6.0, 0.0)
    routine = risk_score(drive(n, ax=chatter))
    assert routine.harsh == 0.0 and routine.risks["harsh"] == 0.0 and routine.harsh_frame is None
    # a car passing 0.4 m beside the ego in the opposite direction, once
    n = 400
    x = 150.0 - 10.0 * np.arange(n) * DT
    miss = risk_score(drive(n, actors=[car("oncoming", x, np.full(n, 1.9 + 0.4), math.pi, 10.0)]))
    assert miss.gap == pytest.approx(0.4, abs=1e-9) and miss.gap_actor == "oncoming"
    assert miss.ttc is None  # it never enters the ego's path
    assert miss.score > routine.score + 0.3
    # the same chatter *with* that car near does count
    chatter = np.where(np.arange(n) % 2 == 0, -6.0, 0.0)
    gated_trace = drive(n, ax=chatter, actors=[car("oncoming", x, np.full(n, 2.3), math.pi, 10.0)])
    gated = risk_score(gated_trace)
    hazard = signals(gated_trace)["hazard"]
    # near while the true gap is under 10 m: |dx| < 4.6 + sqrt(10^2 - 0.4^2) at 20 m/s closing
    assert abs(hazard.sum() - 2 * (4.6 + math.sqrt(100 - 0.16)) / 20.0 / DT) <= 1.5
    assert gated.harsh == pytest.approx(DT * (hazard & (chatter <= -4.0)).sum())
    assert gated.harsh > 0.5 and gated.risks["harsh"] > 0.3


def test_friction_use_near_one_on_low_mu():
    n = 200
    ay = np.full(n, 2.0)  # a steady turn at 2 m/s^2
    dry = risk_score(drive(n, ay=ay))
    ice = risk_score(drive(n, ay=ay, mu_front=0.2, mu_rear=0.25))
    assert dry.grip == pytest.approx(2.0 / G, rel=1e-9)
    assert ice.grip == pytest.approx(2.0 / (0.2 * G), rel=1e-9)  # the axle nearer its limit
    assert ice.risks["grip"] > 0.75 > 0.01 > dry.risks["grip"]
    assert ice.score > dry.score
    # one spike frame is not held for grip_window_s: it does not count
    spike = ay.copy()
    spike[100] = 9.0
    assert risk_score(drive(n, ay=spike)).grip == pytest.approx(2.0 / G, rel=1e-9)


# --------------------------------------------------------------------------- combination and baseline
def test_score_is_bounded_and_contact_saturates():
    n = 200
    x, y = along(n, 30.0, 0.0)
    crash = risk_score(drive(n, actors=[car("wall", x, y, 0.0, 0.0)]))  # driven into at 10 m/s
    cfg = RiskConfig()
    top = max(cfg.weight(c) for c in COMPONENTS) + cfg.tie * sum(cfg.weight(c) for c in COMPONENTS)
    assert crash.gap == 0.0 and crash.ttc == 0.0
    assert 1.0 <= crash.score <= top
    assert risk_score(drive(n)).score == pytest.approx(0.0, abs=1e-3)


def test_baseline_subtracts_routine_risk_per_component():
    n = 400
    turn = np.where((np.arange(n) > 100) & (np.arange(n) < 200), 7.0, 0.0)  # a tight bend in the map
    clean = drive(n, ay=turn)
    base = risk_score(clean)
    assert base.risks["grip"] > 0.3
    assert risk_score(clean, baseline=base).score == 0.0
    mutant = drive(n, ay=turn, actors=[crossing(11.5, n=n)])
    alone = risk_score(mutant)
    rel = risk_score(mutant, baseline=base)
    assert rel.contributions["grip"] == 0.0 and alone.contributions["grip"] > 0.0
    assert rel.contributions["pet"] == alone.contributions["pet"] > 0.9
    assert rel.score < alone.score
    # a baseline read back from the journal works the same
    again = RiskScore.from_dict(json.loads(json.dumps(base.as_dict())))
    assert risk_score(mutant, baseline=again).score == rel.score


def test_as_dict_is_json_safe_and_config_is_strict():
    x, y = along(200, 60.0, 5.0)
    r = risk_score(drive(200, actors=[car("lead", x, y, 0.0, 5.0)]))
    d = json.loads(json.dumps(r.as_dict(), allow_nan=False))
    assert d["riskiest_actor"] == "lead" and d["frame"] == r.frame and d["time"] == pytest.approx(r.time)
    assert set(d["risks"]) == set(COMPONENTS)
    empty = risk_score(drive(0))
    assert empty.score == 0.0 and empty.n_frames == 0
    with pytest.raises(ValidationError):
        RiskConfig(w_tcc=1.0)
    with pytest.raises(ValidationError):
        RiskConfig().w_ttc = 2.0  # type: ignore[misc]


# --------------------------------------------------------------------------- real runs
@pytest.fixture(scope="module")
def seed():
    from drivefuzz.scenario.sumofiles import load_scenario

    sc = load_scenario(ROOT / "seeds" / "town" / "000")
    return sc.model_copy(update={"sim": sc.sim.model_copy(update={"time_limit": 30.0})})


def _run(sc):
    from drivefuzz.ads import load_ads
    from drivefuzz.sim.execute import execute

    return execute(sc, ads=load_ads("ego"), oracles=[]).trace


def test_real_run_clean_is_small_and_a_car_ahead_raises_it(seed):
    from drivefuzz.scenario import Actor

    clean = _run(seed)
    base = risk_score(clean)
    assert math.isfinite(base.score) and base.score < 0.3
    assert base.ttc is None and base.gap is None and base.riskiest_actor is None
    assert risk_score(clean, baseline=base).score == 0.0
    lane = seed.mission.start_lane
    slow = Actor(id="slow", kind="vehicle", nav="immobile", start_lane=lane,
                 start_pos=seed.mission.start_pos + 35.0, speed=0.0)
    busy = _run(seed.model_copy(update={"actors": (slow,)}))
    r = risk_score(busy, baseline=base)
    assert r.riskiest_actor == "slow" and r.ttc_actor == "slow"
    assert r.gap is not None and r.ttc is not None
    assert r.score > 0.1 and r.score > risk_score(clean, baseline=base).score


def test_run_prints_a_passing_runs_risk_and_the_quality_score_only_on_request(seed, tmp_path):
    """`drivefuzz run` of a run without misbehaviour: the risk line names the nearest time-to-collision and gap
    and their actor; the paper's quality score (scipy's filters, 0.4 s to import) only with --quality."""
    from click.testing import CliRunner

    from drivefuzz.cli import main
    from drivefuzz.scenario import Actor
    from drivefuzz.scenario.sumofiles import write_scenario

    slow = Actor(id="slow", kind="vehicle", nav="immobile", start_lane=seed.mission.start_lane,
                 start_pos=seed.mission.start_pos + 35.0, speed=0.0)
    write_scenario(seed.model_copy(update={"actors": (slow,), "sim": seed.sim.model_copy(update={"time_limit": 20.0})}),
                   tmp_path / "s")
    args = ["run", str(tmp_path / "s"), "--no-oracle", "mission", "--no-oracle", "immobility"]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    line = next(l for l in r.output.splitlines() if l.strip().startswith("risk "))
    assert float(line.split()[1]) > 0.1
    assert "time-to-collision" in line and "gap" in line and "with slow" in line
    assert "quality score" not in r.output
    r = CliRunner().invoke(main, args + ["--quality"])
    assert r.exit_code == 0 and "quality score" in r.output, r.output
