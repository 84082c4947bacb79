"""Conflict points found from the networks' junction logic, and seed missions that drive through them.

The networks under networks/ are the ground truth: the intersection is one signalised junction
with four crossings and protected-nothing left turns, the town a grid of signalised and priority
junctions with crossings, the highway a single on-ramp, the interchange two ramp junctions and
two signals, the roundabout four yielding entries.
"""

from __future__ import annotations

import itertools
import random
from collections import Counter

import pytest

from drivefuzz.ads import load_ads
from drivefuzz.oracle import OracleSettings
from drivefuzz.scenario.conflicts import (
    APPROACH_MIN_M,
    ConflictKind,
    ConflictPoint,
    conflict_missions,
    conflict_points,
    _passage,
    conflict_seed_name,
    mission_through,
    passes,
)
from drivefuzz.scenario.roadmap import PASSENGER, load_roadmap
from drivefuzz.scenario.seed import MAX_ROUTE_M, MIN_ROUTE_M, time_limit_for
from drivefuzz.scenario.validate import validate
from drivefuzz.sim.execute import execute
from drivefuzz.sim.verify import dry_run

from conftest import NETWORKS

K = ConflictKind
NAMES = ("town", "intersection", "highway", "interchange", "roundabout")


@pytest.fixture(scope="module")
def maps():
    return {n: load_roadmap(NETWORKS / f"{n}.net.xml") for n in NAMES}


@pytest.fixture(scope="module")
def points(maps):
    return {n: conflict_points(rm) for n, rm in maps.items()}


def _of(pts: list[ConflictPoint], kind: ConflictKind) -> list[ConflictPoint]:
    return [p for p in pts if p.kind is kind]


def _conn(rmap, p: ConflictPoint):
    lane = rmap.lane(p.in_lane)
    (conn,) = [c for c in lane.getOutgoing() if c.getToLane().getID() == p.out_lane]
    return conn


# ------------------------------------------------------------------ conflict points
def test_kinds_present_per_network(points):
    kinds = {n: {p.kind for p in pts} for n, pts in points.items()}
    assert kinds["town"] == set(ConflictKind)
    assert kinds["intersection"] == {K.UNPROTECTED_LEFT, K.CROSSWALK, K.SIGNALISED}  # one light, no priority rules
    assert kinds["highway"] == {K.MERGE}
    assert kinds["interchange"] == {K.UNPROTECTED_LEFT, K.MERGE, K.SIGNALISED}  # it has no crossings
    assert kinds["roundabout"] == {K.YIELD, K.MERGE}


def test_points_are_deterministic_and_unique(maps, points):
    for n, rm in maps.items():
        again = conflict_points(rm)
        assert again == points[n]
        keys = [(p.kind, p.in_lane, p.out_lane) for p in again]
        assert len(keys) == len(set(keys)), n


def test_intersection_unprotected_lefts_yield_to_the_oncoming_straights(maps, points):
    rm = maps["intersection"]
    ul = _of(points["intersection"], K.UNPROTECTED_LEFT)
    assert {(p.in_lane, p.out_lane) for p in ul} == {("NC_2", "CE_2"), ("EC_2", "CS_2"), ("SC_2", "CW_2"),
                                                    ("WC_2", "CN_2")}
    opposite = {"NC": "SC", "SC": "NC", "EC": "WC", "WC": "EC"}
    for p in ul:
        assert _conn(rm, p).getDirection() == "l"
        assert p.foe_lanes and {f.rsplit("_", 1)[0] for f in p.foe_lanes} == {opposite[p.in_edge]}
        assert p.via == _conn(rm, p).getViaLaneID()
        assert abs(p.x) < 10.4 and abs(p.y) < 10.4  # inside the junction, where the paths cross
        # the point lies on the ego's passage
        assert min(abs(rm.geom(l).project(p.x, p.y)[1]) for l in _passage(rm, p.via)) < 0.5


def test_signalised_points_are_every_signal_link_at_its_stop_line(maps, points):
    for n, rm in maps.items():
        expected = {(c.getFromLane().getID(), c.getToLane().getID())
                    for e in rm.net.getEdges(withInternal=False) if e.getFunction() == ""
                    for lane in e.getLanes() if lane.allows(PASSENGER)
                    for c in lane.getOutgoing()
                    if c.getTLSID() and c.getTo().getFunction() == "" and c.getToLane().allows(PASSENGER)}
        sig = _of(points[n], K.SIGNALISED)
        assert {(p.in_lane, p.out_lane) for p in sig} == expected, n
        for p in sig:
            end = rm.geom(p.in_lane).pts[-1]
            assert (p.x, p.y) == pytest.approx((float(end[0]), float(end[1])), abs=0.01)
    assert len(_of(points["intersection"], K.SIGNALISED)) == 16


def test_crosswalk_points_cross_a_crossing_that_can_be_green_at_the_same_time(maps, points):
    for n in ("town", "intersection"):
        rm = maps[n]
        cw = _of(points[n], K.CROSSWALK)
        assert cw, n
        for p in cw:
            assert p.foe_vias and all(rm.lane(v).getEdge().getFunction() == "crossing" for v in p.foe_vias)
            assert all(rm.lane(f).getEdge().getFunction() == "walkingarea" for f in p.foe_lanes)
            # the point is where the passage meets the centre line of one of its crossings
            assert min(abs(rm.geom(v).project(p.x, p.y)[1]) for v in p.foe_vias) < 0.01
    # at the intersection a straight link is green only while the crossings it passes are red
    rm = maps["intersection"]
    dirs = Counter(_conn(rm, p).getDirection() for p in _of(points["intersection"], K.CROSSWALK))
    assert dirs == {"l": 4, "r": 4}
    # the town's priority junctions have crossings too (walkers have right of way there)
    assert any(not _conn(maps["town"], p).getTLSID() for p in _of(points["town"], K.CROSSWALK))


def test_highway_merge_is_the_on_ramp_onto_a_lane_that_ends(maps, points):
    rm = maps["highway"]
    (m,) = points["highway"]
    assert (m.kind, m.in_lane, m.out_lane, m.lane_ends) == (K.MERGE, "onramp_0", "hw1-AddedOnRampEdge_0", True)
    assert m.foe_lanes == ("hw0_0",)  # the stream in the lane beside it
    end = rm.geom(m.out_lane).pts[-1]
    assert (m.x, m.y) == pytest.approx((float(end[0]), float(end[1])))
    merges = _of(points["interchange"], K.MERGE)
    assert sum(p.lane_ends for p in merges) == 2  # both on-ramps
    assert any(not p.lane_ends for p in merges)  # a right turn and a left turn into one ramp lane


def test_roundabout_entries_yield_to_the_ring(maps, points):
    rm = maps["roundabout"]
    y = _of(points["roundabout"], K.YIELD)
    assert sorted(p.in_lane for p in y) == ["Ein_0", "Nin_0", "Sin_0", "Win_0"]
    for p in y:
        assert _conn(rm, p).getState() == "m"
        assert p.foe_lanes and all(f.startswith("ring") for f in p.foe_lanes)


def test_town_yields_are_minor_links_and_not_left_turns(maps, points):
    rm = maps["town"]
    y = _of(points["town"], K.YIELD)
    assert y
    for p in y:
        c = _conn(rm, p)
        assert c.getState() in ("m", "s", "w", "=") or c.getTLSID()
        assert c.getDirection() not in ("l", "L")
    for p in _of(points["town"], K.UNPROTECTED_LEFT):
        assert _conn(rm, p).getDirection() in ("l", "L") and p.foe_lanes


# ------------------------------------------------------------------ missions
def _route_checks(rm, p: ConflictPoint, sc) -> tuple[str, ...]:
    m = sc.mission
    route = validate(sc, rm, "test")
    assert route == rm.route(m.start_edge, m.goal_edge)
    assert passes(route, p), (p, route)
    assert not m.start_edge.startswith(":") and not m.goal_edge.startswith(":")
    if m.start_edge == p.in_edge:
        assert m.start_lane == p.in_lane  # the ego starts on the link's own lane
    i = route.index(p.in_edge)
    approach = sum(rm.edge(e).getLength() for e in route[: i + 1]) - m.start_pos
    assert approach >= APPROACH_MIN_M - 0.1
    assert route.index(m.goal_edge) > i
    if p.lane_ends:
        assert m.goal_edge != p.out_edge
    length = rm.route_length(route, m.start_pos, m.goal_pos)
    assert MIN_ROUTE_M <= length <= MAX_ROUTE_M
    assert sc.sim.time_limit == time_limit_for(rm, route, length)
    return route


def test_missions_route_through_their_point(maps, points):
    for n, rm in maps.items():
        made = Counter()
        for j, p in enumerate(points[n]):
            rng = random.Random(j)
            for _ in range(30):
                sc = mission_through(rm, rng, p, str(rm.path))
                if sc is not None:
                    _route_checks(rm, p, sc)
                    made[p.kind] += 1
                    break
        # every kind on every network gets missions, and most points do
        assert set(made) == {p.kind for p in points[n]}, n
        assert sum(made.values()) >= 0.8 * len(points[n]), (n, sum(made.values()), len(points[n]))


def test_missions_cycle_over_the_kinds(maps, points):
    for n, rm in maps.items():
        kinds = [k for k in ConflictKind if any(p.kind is k for p in points[n])]
        got = list(itertools.islice(conflict_missions(rm, random.Random(3), str(rm.path)), 3 * len(kinds)))
        assert [k for k, _ in got] == kinds * 3, n
        for k, sc in got:
            route = rm.route(sc.mission.start_edge, sc.mission.goal_edge)
            assert any(passes(route, p) for p in _of(points[n], k)), (n, k, route)


def test_missions_are_deterministic_for_a_seed(maps):
    rm = maps["town"]

    def draw(seed):
        it = conflict_missions(rm, random.Random(seed), str(rm.path))
        return [(k, sc.model_dump()) for k, sc in itertools.islice(it, 20)]

    assert draw(11) == draw(11)
    assert draw(11) != draw(12)


def test_seed_name_carries_the_kind():
    assert conflict_seed_name("town", K.UNPROTECTED_LEFT, 0) == "town-conflict-unprotected_left-000"


def _lanes_driven(trace) -> list[str]:
    seq = [l for l in trace["lane"] if l]
    return [l for i, l in enumerate(seq) if i == 0 or seq[i - 1] != l]


def _drove_link(lanes: list[str], p: ConflictPoint) -> bool:
    """Whether the ego left ``p.in_lane`` into the point's passage (its via, or the outgoing lane)."""
    for i, lane in enumerate(lanes[:-1]):
        if lane == p.in_lane and lanes[i + 1] in (p.via, p.out_lane):
            return True
    return False


@pytest.mark.parametrize("name", NAMES)
def test_missions_pass_the_dry_run_and_drive_the_link(name, maps, points):
    """Three rounds over the kinds: each kind has a mission the reference ADS completes, and its
    trace shows the ego leaving the point's incoming lane into the point's passage."""
    rm = maps[name]
    tally: dict[ConflictKind, list[int]] = {}
    for kind, sc in itertools.islice(conflict_missions(rm, random.Random(0), str(rm.path)),
                                     3 * len({p.kind for p in points[name]})):
        ok, _why = dry_run(sc)
        t = tally.setdefault(kind, [0, 0])
        t[1] += 1
        if not ok:
            continue
        t[0] += 1
        route = rm.route(sc.mission.start_edge, sc.mission.goal_edge)
        lanes = _lanes_driven(execute(sc, ads=load_ads("ego"), oracles=OracleSettings().instantiate()).trace)
        candidates = [p for p in _of(points[name], kind) if passes(route, p)]
        assert any(_drove_link(lanes, p) for p in candidates), (kind, lanes, candidates)
    print(f"{name} dry-run pass rate: " + ", ".join(f"{k.value} {a}/{b}" for k, (a, b) in tally.items()))
    assert set(tally) == {p.kind for p in points[name]}
    assert all(a >= 1 for a, _b in tally.values()), tally
