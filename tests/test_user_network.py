"""A user's own network works with no other input: ``drivefuzz fuzz MY.net.xml`` makes and verifies seeds first.

The networks are built here, from nothing, the way users build theirs: ``netgenerate`` (a single-lane
grid without sidewalks, so pedestrians and cut-ins have to make do) and a ``netconvert`` import of a
small hand-written OpenStreetMap file (two-way and one-way streets, a signalised junction, a footway
and a cycleway that cars may not use, dead ends).
"""

from __future__ import annotations

import random
import sqlite3
import subprocess

import pytest
from click.testing import CliRunner

import drivefuzz
from drivefuzz.cli import main
from drivefuzz.scenario.roadmap import PASSENGER, load_roadmap
from drivefuzz.sim.verify import dry_run
from drivefuzz.scenario.seed import doubles_back, generate_seeds, list_seeds, random_missions
from drivefuzz.scenario.sumofiles import read_scenario
from drivefuzz.scenario.validate import validate

OSM = """<?xml version="1.0" encoding="UTF-8"?>
<osm version="0.6" generator="drivefuzz-test">
  <bounds minlat="48.0970" minlon="11.4990" maxlat="48.1050" maxlon="11.5070"/>
  <node id="1" lat="48.1000" lon="11.5000"/>
  <node id="2" lat="48.1000" lon="11.5020"/>
  <node id="3" lat="48.1000" lon="11.5040"><tag k="highway" v="traffic_signals"/></node>
  <node id="4" lat="48.1000" lon="11.5060"/>
  <node id="5" lat="48.1020" lon="11.5040"/>
  <node id="6" lat="48.0980" lon="11.5040"/>
  <node id="7" lat="48.1020" lon="11.5020"/>
  <node id="8" lat="48.1040" lon="11.5040"/>
  <way id="10"><nd ref="1"/><nd ref="2"/><nd ref="3"/><nd ref="4"/>
    <tag k="highway" v="secondary"/><tag k="lanes" v="2"/><tag k="maxspeed" v="50"/><tag k="sidewalk" v="both"/></way>
  <way id="11"><nd ref="6"/><nd ref="3"/><nd ref="5"/><nd ref="8"/>
    <tag k="highway" v="residential"/><tag k="maxspeed" v="30"/></way>
  <way id="12"><nd ref="2"/><nd ref="7"/><nd ref="5"/><tag k="highway" v="residential"/><tag k="oneway" v="yes"/></way>
  <way id="13"><nd ref="7"/><nd ref="8"/><tag k="highway" v="footway"/></way>
  <way id="14"><nd ref="4"/><nd ref="8"/><tag k="highway" v="cycleway"/></way>
</osm>
"""


def _run(tool: str, *args: str) -> None:
    proc = subprocess.run([drivefuzz.sumo_binary(tool), *args], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr


@pytest.fixture(scope="module")
def user_networks(tmp_path_factory):
    d = tmp_path_factory.mktemp("nets")
    grid = d / "mygrid.net.xml"
    _run("netgenerate", "--grid", "--grid.number", "3", "--grid.length", "110", "-L", "1", "--seed", "7",
         "-j", "priority", "-o", str(grid))
    (d / "tiny.osm").write_text(OSM)
    osm = d / "tinycity.net.xml"
    _run("netconvert", "--osm-files", str(d / "tiny.osm"), "--tls.guess-signals", "true", "-o", str(osm))
    return {"grid": grid, "osm": osm}


@pytest.mark.parametrize("which", ["grid", "osm"])
def test_fuzz_on_a_user_network_generates_seeds_first(tmp_path, monkeypatch, user_networks, which):
    net = user_networks[which]
    rmap = load_roadmap(net)
    monkeypatch.chdir(tmp_path)  # seeds/<network>/ is written under the working directory
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["fuzz", str(net), "-o", str(out), "--max-execs", "3", "--cycles", "2",
                                       "--population", "2", "--seed", "1", "--strategy", "all"])
    assert result.exit_code in (0, 1), result.output
    seeds = list_seeds(tmp_path / "seeds" / rmap.name)
    assert seeds, result.output
    for folder in seeds:
        sc = read_scenario(folder)
        assert not sc.actors and not sc.puddles
        route = validate(sc, rmap, source=str(folder))
        assert len(route) >= 2 and not doubles_back(rmap, route)
        assert rmap.lane(sc.mission.start_lane).allows(PASSENGER)
    rows = sqlite3.connect(out / "index.sqlite").execute("SELECT mutation, verdict FROM executions").fetchall()
    assert len(rows) == 3
    assert all(m and not m.startswith("no feasible") for m, _v in rows), rows


def test_random_missions_end_on_a_network_without_any(tmp_path):
    """One two-way street: every route would turn round at a dead end. The generator gives up, not spins."""
    (tmp_path / "s.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="60" y="0"/></nodes>')
    (tmp_path / "s.edg.xml").write_text('<edges><edge id="ab" from="a" to="b" numLanes="1"/>'
                                        '<edge id="ba" from="b" to="a" numLanes="1"/></edges>')
    net = tmp_path / "street.net.xml"
    _run("netconvert", "-n", str(tmp_path / "s.nod.xml"), "-e", str(tmp_path / "s.edg.xml"), "-o", str(net))
    rmap = load_roadmap(net)
    assert rmap.route("ab", "ba") is not None  # SUMO would drive it, with a U-turn at b
    assert list(random_missions(rmap, random.Random(0), str(net), max_draws=300)) == []
    assert generate_seeds(net, 2, 0, verify=dry_run) == []


def test_small_network_gets_shorter_missions_that_never_double_back(tmp_path):
    net = tmp_path / "small.net.xml"
    _run("netgenerate", "--grid", "--grid.number", "2", "--grid.length", "40", "--grid.attach-length", "30",
         "-L", "1", "-o", str(net))
    rmap = load_roadmap(net)
    found = []
    for sc in random_missions(rmap, random.Random(1), str(net), max_draws=400):
        found.append(sc)
        if len(found) == 5:
            break
    assert found
    for sc in found:
        route = validate(sc, rmap, source="seed")
        assert not doubles_back(rmap, route)


@pytest.mark.parametrize("which", ["grid", "osm"])
def test_every_strategy_finds_room_on_a_user_network(user_networks, which):
    """No sidewalks (grid), single lanes, dead ends: every strategy still adds what it should, validly."""
    from drivefuzz.search.mutate import STRATEGIES, Mutator

    net = user_networks[which]
    rmap = load_roadmap(net)
    mut = Mutator(rmap)
    missions = random_missions(rmap, random.Random(2), str(net))
    for seed in (next(missions), next(missions)):
        for strategy in STRATEGIES:
            rng = random.Random(strategy)
            sc = seed
            for _ in range(3):
                g = mut.generate(sc, strategy, rng)
                assert not g.description.startswith("no "), (strategy, g.description)
                sc = mut.mutate(g.scenario, rng).scenario
                validate(sc, rmap, source=f"{which}/{strategy}")
            assert sc.actors or sc.puddles
