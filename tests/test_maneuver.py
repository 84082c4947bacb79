"""Maneuver programs (issue 14): lane changes that take their duration, nudges, braking rates, triggers timed
against the ego, and the programs' fairness. Real SUMO on the bundled highway (lanes run along +x)."""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest

from drivefuzz.scenario import Actor, Maneuver, Mission, Scenario, SimOptions, Trigger
from drivefuzz.scenario.roadmap import load_roadmap
from drivefuzz.scenario.seed import list_seeds
from drivefuzz.scenario.sumofiles import load_scenario
from drivefuzz.search.catalogue import add_situation
from drivefuzz.search.fairness import unfair
from drivefuzz.search.mutate import Mutator
from drivefuzz.scenario.model import cut_in_gap
from drivefuzz.search.programs import PROGRAMS
from drivefuzz.sim.execute import execute

ROOT = Path(__file__).resolve().parents[1]
NET = ROOT / "networks" / "highway.net.xml"
LANE_WIDTH = 3.5  # [m] of every highway lane


def highway(*actors: Actor, time_limit: float = 20.0) -> Scenario:
    """The ego from hw0's middle lane to hw2, with ``actors``."""
    return Scenario(network=str(NET), mission=Mission(start_lane="hw0_1", start_pos=20.0, goal_edge="hw2",
                                                      goal_pos=150.0, start_speed=20.0),
                    sim=SimOptions(time_limit=time_limit), seed=3, actors=actors)


def npc(lane: str, pos: float, speed: float, *steps: Maneuver, depart: float = 0.0) -> Actor:
    return Actor(id="v0", kind="vehicle", nav="maneuver", start_lane=lane, start_pos=pos, speed=speed,
                 depart=depart, dest_edge="hw2", maneuvers=steps)


def track(ex, actor_id: str = "v0"):
    """(t, x, y, speed) of an actor's centre over the frames it was in."""
    a = ex.trace.actors
    rows = a.actor == a.ids.index(actor_id)
    return ex.trace["t"][a.frame[rows]], a.x[rows], a.y[rows], a.speed[rows]


def front_y(ex, actor_id: str = "v0"):
    """y [m] of an actor's front bumper: what SUMO's lane change moves at a constant lateral speed (the
    centre follows as the body turns back straight)."""
    a = ex.trace.actors
    j = a.ids.index(actor_id)
    rows = a.actor == j
    return a.y[rows] + 0.5 * a.length[j] * np.sin(a.heading[rows])


def lateral_move(t, y):
    """(start, end) [s] of the one lateral move in ``y``: from 5 % to 95 % of the way."""
    total = y[-1] - y[0]
    frac = (y - y[0]) / total
    return float(t[np.argmax(frac > 0.05)]), float(t[np.argmax(frac > 0.95)])


@pytest.mark.parametrize("duration", [1.5, 3.0])
def test_a_lane_change_takes_its_requested_duration(duration):
    # a car 40 m ahead on the right lane changes into the ego's lane at 1 s
    ex = execute(highway(npc("hw0_0", 60.0, 20.0, Maneuver(time=1.0, action="lane_left", value=duration))),
                 oracles=[], stop_on_misbehavior=False)
    t, x, y, _ = track(ex)
    assert y[-1] - y[0] == pytest.approx(LANE_WIDTH, abs=0.05)  # one lane to the left (+y)
    y = front_y(ex)
    start, end = lateral_move(t, y)
    assert start == pytest.approx(1.0 + 0.05 * duration, abs=0.1)
    assert end - start == pytest.approx(0.9 * duration, abs=0.15)  # 5 % -> 95 % of a move at constant speed
    step = np.abs(np.diff(y)).max()
    assert step <= LANE_WIDTH / duration * ex.trace.step_length * 1.05  # no jump: one step moves w / T * dt


def test_a_nudge_goes_out_and_comes_back():
    ex = execute(highway(npc("hw0_0", 60.0, 20.0, Maneuver(time=1.0, action="nudge_left", value=3.0, depth=1.5))),
                 oracles=[], stop_on_misbehavior=False)
    t, _, y, _ = track(ex)
    assert y.max() - y[0] == pytest.approx(1.5, abs=0.05)
    peak = float(t[np.argmax(y)])
    assert peak == pytest.approx(1.0 + 1.5, abs=0.15)  # half way through the nudge
    assert abs(y[-1] - y[0]) < 0.01  # back in its lane


def test_a_speed_step_brakes_at_its_rate():
    ex = execute(highway(npc("hw0_1", 80.0, 25.0, Maneuver(time=2.0, action="speed", value=5.0, rate=7.0))),
                 oracles=[], stop_on_misbehavior=False)
    t, _, _, v = track(ex)
    braking = (t > 2.2) & (v > 6.0) & (v < 24.0)
    decel = -np.diff(v)[braking[1:]] / ex.trace.step_length
    assert np.median(decel) == pytest.approx(7.0, abs=0.3)
    assert v[-1] == pytest.approx(5.0, abs=0.1)


def test_a_gap_trigger_fires_when_the_npc_is_that_far_ahead_of_the_ego():
    # a faster car starts behind the ego on the next lane and cuts in once its rear is 12 m ahead of the ego
    steps = Maneuver(time=0.0, action="lane_right", value=2.0, trigger=Trigger.GAP, at=12.0)
    ex = execute(highway(npc("hw0_2", 5.0, 33.0, steps)), oracles=[], stop_on_misbehavior=False)
    t, x, y, _ = track(ex)
    start = int(np.argmax(y < y[0] - 0.01))
    assert start > 0, "it never changed lanes"
    f = ex.trace.actors.frame[ex.trace.actors.actor == 0][start]
    gap = (x[start] - 2.5) - (ex.trace["x"][f] + 2.3)  # its rear bumper minus the ego's front (both along +x)
    assert gap == pytest.approx(12.0, abs=1.5)  # one step earlier, plus the start of the move


def test_a_headway_trigger_scales_with_the_egos_speed():
    steps = Maneuver(time=0.0, action="lane_left", value=2.0, trigger=Trigger.HEADWAY, at=1.5)
    ex = execute(highway(npc("hw0_0", 120.0, 18.0, steps), time_limit=25.0), oracles=[], stop_on_misbehavior=False)
    t, x, y, _ = track(ex)
    start = int(np.argmax(y > y[0] + 0.01))
    assert start > 0, "it never changed lanes"
    f = ex.trace.actors.frame[ex.trace.actors.actor == 0][start]
    gap = (x[start] - 2.5) - (ex.trace["x"][f] + 2.3)
    assert gap / ex.trace["speed"][f] == pytest.approx(1.5, abs=0.15)


def test_a_forced_cut_in_waits_for_the_room_a_careful_driver_needs():
    # its program says 'cut in 10 m ahead', but it stands still (1 m/s) and the ego comes at 20 m/s: the
    # executor holds the lane change back (cut_in_gap(19 m/s, 2 s) is about 68 m), so it never cuts in
    steps = Maneuver(time=0.0, action="lane_left", value=2.0, trigger=Trigger.GAP, at=10.0)
    ex = execute(highway(npc("hw0_0", 120.0, 1.0, steps), time_limit=8.0), oracles=[], stop_on_misbehavior=False)
    _, _, y, _ = track(ex)
    assert np.ptp(y) < 0.01
    assert cut_in_gap(19.0, 2.0) > 60.0


def test_programs_are_placed_fairly_on_every_highway_seed():
    seeds = [load_scenario(p) for p in list_seeds(ROOT / "seeds" / "highway")]
    mut = Mutator(load_roadmap(NET))
    rng = random.Random(0)
    for program in PROGRAMS:
        built = [add_situation(mut, sc, program, rng) for sc in seeds]
        placed = [m for m, sc in zip(built, seeds) if m.scenario is not sc]
        assert len(placed) >= 6, f"{program.name}: placed on {len(placed)} of 8 seeds"  # 000 is a short ramp
        for m in placed:
            for a in m.scenario.actors:
                rest = m.scenario.model_copy(update={"actors": tuple(b for b in m.scenario.actors if b is not a)})
                assert unfair(mut, rest, a) is None
                assert a.maneuvers and all(st.trigger is not Trigger.TIME or st.action.value == "speed"
                                           for st in a.maneuvers)


def test_a_cut_in_closer_than_a_careful_driver_can_handle_is_unfair():
    mut = Mutator(load_roadmap(NET))
    sc = highway()
    need = cut_in_gap(33.33 - 20.0, 2.0)
    ok = npc("hw0_2", 150.0, 20.0, Maneuver(time=0.0, action="lane_right", value=2.0, trigger=Trigger.GAP,
                                            at=round(need + 1.0, 1)))
    close = ok.model_copy(update={"maneuvers": (ok.maneuvers[0].model_copy(update={"at": need - 1.0}),)})
    assert unfair(mut, sc, ok) is None
    assert "needs" in unfair(mut, sc, close)
    clock = ok.model_copy(update={"maneuvers": (Maneuver(time=1.0, action="speed", value=20.0),
                                                Maneuver(time=1.0, action="lane_right", value=2.0,
                                                         trigger=Trigger.AFTER))})
    assert "timed by the step before" in unfair(mut, sc, clock)


def test_the_maneuver_strategy_builds_programs_and_their_mutations_stay_fair():
    seeds = [load_scenario(p) for p in list_seeds(ROOT / "seeds" / "highway")]
    mut = Mutator(load_roadmap(NET))
    rng = random.Random(5)
    seen = set()
    for k in range(40):
        sc = seeds[k % len(seeds)]
        m = mut.generate(sc, "maneuver", rng)
        seen.add(m.description.split(":")[0])
        new = m.scenario
        for _ in range(5):
            new = mut.mutate(new, rng).scenario
        for a in new.actors:
            rest = new.model_copy(update={"actors": tuple(b for b in new.actors if b is not a)})
            assert unfair(mut, rest, a) is None, a
    assert len(seen) >= 5  # several programs, not one


# ------------------------------------------------------------------ AV-Fuzzer's crash types, from traces
def crash(sc: Scenario, fault: str):
    from drivefuzz.triage.crashtype import crash_type
    from oracles.collision import CollisionOracle

    sc = sc.model_copy(update={"ads": sc.ads.model_copy(update={"options": {"fault": fault}})})
    ex = execute(sc, oracles=[CollisionOracle()])
    assert ex.misbehaviors, "no collision"
    m = ex.misbehaviors[0]  # (a squeeze may touch both cars in one frame)
    return crash_type(ex.trace, m.frame, m.actors[0], load_roadmap(NET)), m.actors[0]


def test_crash_type_rear_end_of_a_braking_npc():
    # a leader 40 m ahead brakes hard at 3 s; an ego that brakes late runs into it
    leader = npc("hw0_1", 70.0, 20.0, Maneuver(time=3.0, action="speed", value=0.0, rate=8.0))
    assert crash(highway(leader), "late_braking") == ("rear_end_braking", "v0")


def test_crash_type_npc_cuts_in_from_ahead():
    # slower, ahead on the next lane: cuts in 40 m ahead of an ego that does not react (no control)
    cutter = npc("hw0_0", 80.0, 8.0, Maneuver(time=0.0, action="lane_left", value=2.0, trigger=Trigger.GAP, at=40.0))
    assert crash(highway(cutter), "no_control") == ("cut_in", "v0")


def test_crash_type_npc_overtakes_and_cuts_in():
    # from behind on the next lane, faster: cuts in 6 m ahead, then brakes in front of the coasting ego
    overtaker = npc("hw0_2", 5.0, 30.0,
                    Maneuver(time=0.0, action="lane_right", value=1.5, trigger=Trigger.GAP, at=6.0),
                    Maneuver(time=1.5, action="speed", value=0.0, trigger=Trigger.AFTER, rate=8.0))
    assert crash(highway(overtaker), "no_control") == ("overtake_cut_in", "v0")


def test_crash_type_ego_cuts_in():
    # a car rides beside the ego on the left; the ego's steering is forced left (fault) into it
    rider = npc("hw0_2", 22.0, 21.0, Maneuver(time=0.0, action="speed", value=21.0))
    assert crash(highway(rider), "steer_left") == ("ego_cut_in", "v0")


def test_crash_type_squeeze():
    # two cars ahead on both sides swerve into the lane of an ego that does not react
    left = npc("hw0_2", 55.0, 17.0, Maneuver(time=0.0, action="nudge_right", value=8.0, depth=2.2,
                                             trigger=Trigger.GAP, at=15.0))
    right = Actor(**{**npc("hw0_0", 55.0, 17.0, Maneuver(time=0.0, action="nudge_left", value=8.0, depth=2.2,
                                                         trigger=Trigger.GAP, at=15.0)).model_dump(), "id": "v1"})
    kind, _ = crash(highway(left, right), "no_control")
    assert kind == "squeeze"


def test_a_finding_folder_names_its_crash_type(tmp_path):
    import json

    from drivefuzz.triage.store import FindingStore, TriageConfig
    from drivefuzz.triage.table import finding_rows
    from oracles.collision import CollisionOracle

    leader = npc("hw0_1", 70.0, 20.0, Maneuver(time=3.0, action="speed", value=0.0, rate=8.0))
    sc = highway(leader)
    sc = sc.model_copy(update={"ads": sc.ads.model_copy(update={"options": {"fault": "late_braking"}})})
    ex = execute(sc, oracles=[CollisionOracle()])
    store = FindingStore(tmp_path, load_roadmap(NET), lambda s: (ex.misbehaviors, ex.trace),
                         TriageConfig(counterfactual=False, reproduce=0))
    filed = store.triage(sc, list(ex.misbehaviors), ex.trace, "0/0/0/0", "misbehavior")
    verdict = json.loads((tmp_path / filed.rel / "verdict.json").read_text())
    assert verdict["crash_type"] == "rear_end_braking"
    (row,) = finding_rows(tmp_path, incidents=filed.rel.startswith("incidents"))
    assert row.crash_type == "rear_end_braking"


def test_a_car_that_enters_late_behind_a_fast_ego_is_removed(tmp_path):
    """A campaign's incident, kept as data (tests/data/late_entry_behind): highway seed 009's ego enters at 26 m/s;
    the linear car v4, placed 5 m ahead of it at the start at 25.9 m/s, could not be inserted there until 0.7 s
    later, when its spot was 1.2 m behind the ego, and struck the braking ego's rear at 3.6 m/s faster. The
    mutator's fairness rules placed it for its departure, not for where it entered: it is removed as it enters,
    and the run is clean."""
    import shutil

    from drivefuzz.oracle import OracleSettings

    folder = tmp_path / "case"
    shutil.copytree(ROOT / "tests" / "data" / "late_entry_behind", folder)
    shutil.copy(NET, folder / NET.name)
    sc = load_scenario(folder)
    assert {a.id: a.depart for a in sc.actors}["v4"] == 0.0
    ex = execute(sc, oracles=OracleSettings().instantiate())
    assert ex.misbehaviors == () and ex.termination.value == "goal_reached"
    assert "v4" not in ex.trace.actors.ids
    assert {"v0", "v1", "v2", "v3"} <= set(ex.trace.actors.ids)


def _time_gap(ex) -> float:
    """[s] the follower v0's time gap to the ego at the end of the run (ego's rear to its front, at its speed)."""
    t, x, _, v = track(ex)
    ego_x = np.asarray(ex.trace.ego["x"])[-1]
    gap = ego_x - 0.5 * float(ex.trace.meta.get("ego_length", 4.6)) - (x[-1] + 0.5 * 4.6)
    return gap / v[-1]


def test_a_follow_step_closes_the_gap_to_the_time_gap_it_asks_for():
    """SUMO's follower keeps a time gap of 1 s (its tau) and 2.5 m more; a follow step of 0.5 s and 1 m halves the
    gap, and fairness refuses one under MIN_FOLLOW_S or timed against the ego."""
    from drivefuzz.scenario.model import MIN_FOLLOW_S

    plain = execute(highway(npc("hw0_1", 1.0, 30.0), time_limit=25.0), oracles=[], stop_on_misbehavior=False)
    close = execute(highway(npc("hw0_1", 1.0, 30.0, Maneuver(time=0.0, action="follow", value=0.5)),
                            time_limit=25.0), oracles=[], stop_on_misbehavior=False)
    # SUMO's gap is tau x speed plus minGap (2.5 m; 1 m for a follow step): 1.4 s and 0.7 s at the ego's 11.5 m/s
    assert 1.2 < _time_gap(plain) < 1.6
    assert 0.55 < _time_gap(close) < 0.8
    mut = Mutator(load_roadmap(NET))
    sc = highway()
    ahead = ("hw0_0", 120.0, 20.0)  # a car ahead in the lane beside: fair without the step
    assert unfair(mut, sc, npc(*ahead)) is None
    assert unfair(mut, sc, npc(*ahead, Maneuver(time=0.0, action="follow", value=MIN_FOLLOW_S))) is None
    assert "under the" in unfair(mut, sc, npc(*ahead, Maneuver(time=0.0, action="follow", value=0.3)))
    assert "only the clock" in unfair(mut, sc, npc(*ahead, Maneuver(time=0.0, action="follow", value=0.6,
                                                                    trigger=Trigger.GAP, at=-10.0)))


def _least_ttc(ex) -> float:
    """[s] the least time to collision of the follower v0 with the ego (its front to the ego's rear, closing)."""
    t, x, _, v = track(ex)
    frames = ex.trace.actors.frame[ex.trace.actors.actor == ex.trace.actors.ids.index("v0")]
    ego_x = np.asarray(ex.trace.ego["x"])[frames]
    ego_v = np.asarray(ex.trace.ego["speed"])[frames]
    gap = ego_x - 0.5 * float(ex.trace.meta.get("ego_length", 4.6)) - (x + 0.5 * 4.6)
    closing = v - ego_v
    return float(np.min(np.where(closing > 0.1, gap / np.maximum(closing, 0.1), np.inf)))


def test_a_close_step_drives_up_to_its_time_to_collision_before_it_brakes():
    """SUMO's follower brakes early (the least time to collision of a car closing in from behind is over 3 s, no
    close encounter); a close step keeps its speed until the time to collision is the step's (2 s) and then
    brakes as SUMO does: no collision. Fairness refuses one under MIN_CLOSE_TTC or timed against the ego."""
    from drivefuzz.oracle import OracleSettings
    from drivefuzz.scenario.model import MIN_CLOSE_TTC

    runs = {}
    for name, steps in (("plain", ()), ("close", (Maneuver(time=0.0, action="follow", value=0.6),
                                                  Maneuver(time=0.0, action="close", value=0.0, at=2.0)))):
        ex = execute(highway(npc("hw0_1", 1.0, 28.0, *steps), time_limit=25.0),
                     oracles=OracleSettings().instantiate(), stop_on_misbehavior=False)
        assert not [m for m in ex.misbehaviors if m.oracle == "collision"], name
        runs[name] = _least_ttc(ex)
    assert runs["plain"] > 3.0 and 1.9 < runs["close"] < 2.2, runs
    mut = Mutator(load_roadmap(NET))
    sc = highway()
    ahead = ("hw0_0", 120.0, 20.0)
    assert unfair(mut, sc, npc(*ahead, Maneuver(time=0.0, action="close", value=0.0, at=MIN_CLOSE_TTC))) is None
    assert "under" in unfair(mut, sc, npc(*ahead, Maneuver(time=0.0, action="close", value=0.0, at=1.0)))
    assert "only the clock" in unfair(mut, sc, npc(*ahead, Maneuver(time=0.0, action="close", value=0.0, at=2.0,
                                                                    trigger=Trigger.HEADWAY)))
