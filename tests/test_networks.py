"""Checks on the bundled road networks in ``networks/``.

Each net must load in SUMO without a single warning, have the features the
fuzzer relies on (signals, crossings, speed limits, a solid line, ramps, a
roundabout), route passenger cars between the edges used for missions, and be
reproducible from its plain-XML sources with ``tools/build_networks.py``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections import deque
from pathlib import Path

import pytest
import sumo
import sumolib

REPO = Path(__file__).resolve().parent.parent
NETWORKS = REPO / "networks"
BUILD_SCRIPT = REPO / "tools" / "build_networks.py"
SUMO_HOME = os.path.dirname(sumo.__file__)
SUMO_BIN = os.path.join(SUMO_HOME, "bin", "sumo")
NETCONVERT_BIN = os.path.join(SUMO_HOME, "bin", "netconvert")
NAMES = ["town", "highway", "interchange", "intersection", "roundabout"]

#: Passenger routes that must exist: (from edge, to edge).
ROUTES = {
    "town": [("A0B0", "D3C3"), ("D3C3", "A0B0"), ("A1B1", "C1C0"), ("B2M2", "C2D2"),
             ("D0C0", "A3A2"), ("B1C1", "C1C2"), ("C1B1", "B1B0")],
    "highway": [("hw0", "hw2"), ("onramp", "hw2"), ("onramp", "offramp"), ("hw0", "offramp")],
    "interchange": [("EB0", "NB2"), ("EB0", "SB2"), ("WB0", "NB2"), ("WB0", "SB2"),
                    ("NB0", "EB2"), ("NB0", "WB2"), ("SB0", "EB2"), ("SB0", "WB2"),
                    ("EB0", "EB2"), ("WB0", "WB2"), ("NB0", "NB2"), ("SB0", "SB2")],
    "intersection": [(a, b) for a in ("NC", "EC", "SC", "WC") for b in ("CN", "CE", "CS", "CW")
                     if a[0] != b[1]],
    "roundabout": [(a + "in", b + "out") for a in "ENWS" for b in "ENWS" if a != b],
}


def _env() -> dict[str, str]:
    return dict(os.environ, SUMO_HOME=SUMO_HOME)


def net_path(name: str) -> Path:
    return NETWORKS / f"{name}.net.xml"


_NETS: dict[str, sumolib.net.Net] = {}


def read(name: str) -> sumolib.net.Net:
    if name not in _NETS:
        _NETS[name] = sumolib.net.readNet(str(net_path(name)), withInternal=True, lxml=False,
                                          withPedestrianConnections=True)
    return _NETS[name]


def road_edges(net: sumolib.net.Net) -> list:
    return [e for e in net.getEdges(withInternal=False) if e.allows("passenger")]


def crossings(net: sumolib.net.Net) -> list:
    return [e for e in net.getEdges(withInternal=True) if e.getFunction() == "crossing"]


def edge_ids(path: Path) -> tuple[set[str], set[str]]:
    net = sumolib.net.readNet(str(path), withInternal=True, lxml=False)
    edges = {e.getID() for e in net.getEdges(withInternal=True)}
    lanes = {lane.getID() for e in net.getEdges(withInternal=True) for lane in e.getLanes()}
    return edges, lanes


@pytest.mark.parametrize("name", NAMES)
def test_loads_without_warnings(name):
    proc = subprocess.run([SUMO_BIN, "-X", "never", "-n", str(net_path(name)),
                           "--begin", "0", "--end", "1", "--no-step-log", "true"],
                          capture_output=True, text=True, env=_env(), timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip() == "", proc.stderr


@pytest.mark.parametrize("name", NAMES)
def test_mission_routes_exist(name):
    net = read(name)
    for a, b in ROUTES[name]:
        path, _cost = net.getShortestPath(net.getEdge(a), net.getEdge(b), vClass="passenger")
        assert path is not None, f"{name}: no passenger route {a} -> {b}"


@pytest.mark.parametrize("name", NAMES)
def test_road_lanes_allow_cars_and_pedestrians_stay_on_sidewalks(name):
    net = read(name)
    for edge in net.getEdges(withInternal=False):
        for lane in edge.getLanes():
            if lane.allows("pedestrian"):
                assert not lane.allows("passenger"), f"{lane.getID()} mixes cars and pedestrians"
            else:
                assert lane.allows("passenger"), f"{lane.getID()} is closed to cars"


def test_town_grid_is_strongly_connected_for_cars():
    net = read("town")
    edges = road_edges(net)

    def reachable(start, forward):
        seen, todo = {start}, deque([start])
        while todo:
            edge = todo.popleft()
            nxt = (edge.getAllowedOutgoing("passenger") if forward
                   else [e for e in edge.getIncoming() if edge in e.getAllowedOutgoing("passenger")])
            for other in nxt:
                if other not in seen and other.getFunction() == "":
                    seen.add(other)
                    todo.append(other)
        return seen

    assert reachable(edges[0], True) >= set(edges)
    assert reachable(edges[0], False) >= set(edges)


def test_town_signals_and_crossings():
    net = read("town")
    tls = net.getTrafficLights()
    assert len(tls) >= 4
    signal_nodes = {n.getID() for n in net.getNodes() if n.getType() == "traffic_light"}
    assert signal_nodes == {"B1", "C1", "B2", "C2"}
    crossing_nodes = {c.getFromNode().getID() for c in crossings(net)}
    assert signal_nodes <= crossing_nodes
    # every arm of every signalised junction has a crossing
    for node_id in signal_nodes:
        node = net.getNode(node_id)
        crossed = {edge.getID() for c in crossings(net) if c.getFromNode() is node
                   for edge in c.getCrossingEdges()}
        arms = {e.getID() for e in node.getIncoming() if e.getFunction() == ""}
        assert len(arms) == 4 and arms <= crossed, node_id
    walkingareas = [e for e in net.getEdges(withInternal=True) if e.getFunction() == "walkingarea"]
    assert walkingareas


def test_town_speed_limits_and_midblock_change():
    net = read("town")
    speeds = {round(lane.getSpeed(), 2) for e in road_edges(net) for lane in e.getLanes()
              if lane.allows("passenger")}
    assert {8.33, 13.89} <= speeds
    # B2 -> M2 -> C2 is one straight street whose limit drops at the mid-block node M2
    first, second = net.getEdge("B2M2"), net.getEdge("M2C2")
    assert first.getToNode() is second.getFromNode()
    assert abs(first.getLength() - second.getLength()) < 5  # M2 is mid-block
    assert first.getSpeed() == pytest.approx(13.89)
    assert second.getSpeed() == pytest.approx(8.33)
    assert second in first.getAllowedOutgoing("passenger")


def test_town_has_solid_line_edges():
    forbidden = {}
    for edge in sumolib.xml.parse(str(net_path("town")), "edge"):
        if edge.hasAttribute("function"):
            continue
        for lane in edge.lane:
            left = lane.getAttributeSecure("changeLeft")
            right = lane.getAttributeSecure("changeRight")
            if left is not None and right is not None:
                if "passenger" not in left.split() and "passenger" not in right.split():
                    forbidden.setdefault(edge.id, []).append(lane.id)
    assert set(forbidden) == {"B1C1", "C1B1"}
    # both road lanes of each solid edge (lane 0 is the sidewalk)
    assert all(len(lanes) == 2 for lanes in forbidden.values())


def test_highway_mainline_and_ramps():
    net = read("highway")
    assert any(e.getLaneNumber() >= 3 and e.getSpeed() >= 30 for e in road_edges(net))
    for ramp in ("onramp", "offramp"):
        edge = net.getEdge(ramp)
        assert edge.getLaneNumber() == 1 and edge.getSpeed() == pytest.approx(22.22)
    accel = net.getEdge("hw1-AddedOnRampEdge")
    assert accel.getLaneNumber() == 4


def test_interchange_is_grade_separated():
    net = read("interchange")
    assert len(net.getTrafficLights()) == 2
    motorway_nodes = {n for e in road_edges(net) if e.getSpeed() > 30
                      for n in (e.getFromNode(), e.getToNode())}
    arterial_nodes = {n for e in road_edges(net) if e.getID()[:2] in ("NB", "SB")
                      for n in (e.getFromNode(), e.getToNode())}
    assert motorway_nodes and arterial_nodes and not motorway_nodes & arterial_nodes
    path, _ = net.getShortestPath(net.getEdge("EB0"), net.getEdge("NB2"), vClass="passenger")
    assert "EBexit" in [e.getID() for e in path]
    path, _ = net.getShortestPath(net.getEdge("SB0"), net.getEdge("EB2"), vClass="passenger")
    assert "EBentry" in [e.getID() for e in path]


def test_intersection_signal_and_crossings():
    net = read("intersection")
    assert len(net.getTrafficLights()) == 1
    assert len(crossings(net)) == 4
    assert [e for e in net.getEdges(withInternal=True) if e.getFunction() == "walkingarea"]
    assert all(e.getLaneNumber() == 3 for e in net.getEdges(withInternal=False))  # sidewalk + 2


def test_roundabout():
    net = read("roundabout")
    (ring,) = net.getRoundabouts()
    assert sorted(ring.getEdges()) == ["ringEN", "ringNW", "ringSE", "ringWS"]
    assert all(len(net.getEdge(e).getShape()) > 2 for e in ring.getEdges())


def _installed_netconvert_version() -> str:
    out = subprocess.run([NETCONVERT_BIN, "--version"], capture_output=True, text=True,
                         env=_env()).stdout
    return out.split("\n", 1)[0].rsplit(" ", 1)[-1]


def test_build_reproduces_committed_networks(tmp_path):
    proc = subprocess.run([sys.executable, str(BUILD_SCRIPT), "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    version = _installed_netconvert_version()
    for name in NAMES:
        built, committed = tmp_path / f"{name}.net.xml", net_path(name)
        header = re.search(r"netconvert (\S+)", committed.read_text(encoding="utf-8")[:300])
        if header and header.group(1) == version:
            assert built.read_bytes() == committed.read_bytes(), (
                f"{name}: networks/{name}.net.xml is stale; run tools/build_networks.py")
        else:  # another SUMO version may format numbers differently
            assert edge_ids(built) == edge_ids(committed), name


def test_build_fails_loudly_on_a_netconvert_warning(tmp_path):
    src = tmp_path / "src" / "roundabout"
    src.mkdir(parents=True)
    for path in (NETWORKS / "src" / "roundabout").iterdir():
        text = path.read_text(encoding="utf-8")
        if path.name == "roundabout.nod.xml":  # a 40 % grade on arm E makes netconvert warn
            text = text.replace('<node id="E" x="125.00" y="0.00"/>',
                                '<node id="E" x="125.00" y="0.00" z="40.00"/>')
        (src / path.name).write_text(text, encoding="utf-8")
    proc = subprocess.run([sys.executable, str(BUILD_SCRIPT), "--src", str(tmp_path / "src"),
                           "--out", str(tmp_path / "out"), "roundabout"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0
    assert "roundabout" in proc.stderr and "Warning" in proc.stderr
    assert not (tmp_path / "out" / "roundabout.net.xml").exists()


def test_a_city_with_rail_signals_and_uncontrolled_links_passes_the_network_check():
    """SUMO's own Berlin (tools/game/DRT): connections name rail signals (junctions, no <tlLogic>) and carry
    linkIndex -1 (not controlled); SUMO loads it, so drivefuzz's check must accept it."""
    import sumo

    from drivefuzz.scenario.validate import check_network

    berlin = Path(sumo.SUMO_HOME) / "tools" / "game" / "DRT" / "osm.net.xml"
    text = berlin.read_text()
    assert 'linkIndex="-1"' in text and 'type="rail_signal"' in text
    check_network(berlin)
