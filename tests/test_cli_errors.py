"""Bad input gives one line naming the file and the problem, exit code 2, no traceback."""

from __future__ import annotations

from click.testing import CliRunner

from drivefuzz.cli import main
from drivefuzz.scenario.sumofiles import write_scenario

from conftest import TOWN


def _invoke(args):
    result = CliRunner().invoke(main, args)
    return result.exit_code, result.output, result.exception


def _one_line_error(code, output, exc, *needles):
    assert code == 2, output
    lines = [l for l in output.splitlines() if l.strip()]
    assert len(lines) == 1, output
    assert "Traceback" not in output
    for n in needles:
        assert n in lines[0], lines[0]


def test_missing_network(tmp_path):
    _one_line_error(*_invoke(["fuzz", str(tmp_path / "no.net.xml"), "-o", str(tmp_path / "o")]), "no.net.xml", "no such network")


def test_malformed_network(tmp_path):
    bad = tmp_path / "bad.net.xml"
    bad.write_text("<net><edge id='x'")
    _one_line_error(*_invoke(["seed", str(bad), "-n", "1"]), "bad.net.xml", "not a readable SUMO network")


def test_a_failed_network_parse_turns_the_garbage_collector_back_on(tmp_path):
    """The road map parses with the cyclic GC off (drivefuzz.scenario.roadmap); an error must not leave it off."""
    import gc

    import pytest

    from drivefuzz.errors import InvalidNetwork
    from drivefuzz.scenario.roadmap import RoadMap

    bad = tmp_path / "bad.net.xml"
    bad.write_text("<net><edge id='x'")
    assert gc.isenabled()
    with pytest.raises(InvalidNetwork):
        RoadMap(bad)
    assert gc.isenabled()
    RoadMap(TOWN)
    assert gc.isenabled()


def test_scenario_with_missing_edge(tmp_path, town_scenario):
    write_scenario(town_scenario, tmp_path / "s")
    routes = tmp_path / "s" / "routes.rou.xml"
    routes.write_text(routes.read_text().replace("B0C0", "ZZZZ"))
    _one_line_error(*_invoke(["run", str(tmp_path / "s")]), "scenario.json", "mission.goal_edge", "ZZZZ")


def test_impossible_mission(tmp_path, town_scenario):
    write_scenario(town_scenario, tmp_path / "s")
    routes = tmp_path / "s" / "routes.rou.xml"
    # the sidewalk lane: not a lane the ego may start on
    routes.write_text(routes.read_text().replace('departLane="1"', 'departLane="0"'))
    _one_line_error(*_invoke(["run", str(tmp_path / "s")]), "mission.start_lane", "does not allow passenger")


def test_malformed_scenario_json(tmp_path, town_scenario):
    write_scenario(town_scenario, tmp_path / "s")
    (tmp_path / "s" / "scenario.json").write_text("{ not json")
    _one_line_error(*_invoke(["run", str(tmp_path / "s")]), "scenario.json", "not valid JSON")


def test_malformed_routes_xml(tmp_path, town_scenario):
    write_scenario(town_scenario, tmp_path / "s")
    (tmp_path / "s" / "routes.rou.xml").write_text("<routes><vehicle")
    _one_line_error(*_invoke(["run", str(tmp_path / "s")]), "routes.rou.xml", "malformed XML")


def test_bad_friction_in_additional(tmp_path, town_scenario):
    from drivefuzz.scenario import Puddle

    write_scenario(town_scenario.model_copy(update={"puddles": (Puddle(x=1, y=1, length=2, width=2, friction=0.5),)}), tmp_path / "s")
    add = tmp_path / "s" / "fuzz.add.xml"
    add.write_text(add.read_text().replace('key="drivefuzz.friction" value="0.5"', 'key="drivefuzz.friction" value="3.5"'))
    _one_line_error(*_invoke(["run", str(tmp_path / "s")]), "fuzz.add.xml", "friction")


def test_bad_config_file_and_options(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[fuzz\ncycles=")
    _one_line_error(*_invoke(["fuzz", str(TOWN), "--config", str(cfg), "-o", str(tmp_path / "o")]), "c.toml", "cannot parse")
    _one_line_error(*_invoke(["fuzz", str(TOWN), "--oracle", "speeding.nope=1", "-o", str(tmp_path / "o")]), "speeding.nope")
    _one_line_error(*_invoke(["fuzz", str(TOWN), "--ads", "nosuch", "-o", str(tmp_path / "o")]), "no ADS plugin")
    _one_line_error(*_invoke(["fuzz", str(TOWN), "--budget", "soon", "-o", str(tmp_path / "o")]), "--budget")


def _edit(tmp_path, town_scenario, fname, old, new, **update):
    write_scenario(town_scenario.model_copy(update=update), tmp_path / "s")
    f = tmp_path / "s" / fname
    text = f.read_text()
    assert old in text
    f.write_text(text.replace(old, new))
    return _invoke(["run", str(tmp_path / "s")])


def test_actor_off_the_road(tmp_path, town_scenario):
    from drivefuzz.scenario import Actor

    a = Actor(id="v", kind="vehicle", nav="immobile", start_lane="B0B1_1", start_pos=20, speed=0)
    _one_line_error(*_edit(tmp_path, town_scenario, "routes.rou.xml", 'value="B0B1_1"', 'value="B0B1_0"', actors=(a,)),
                    "actors[0](v).start_lane", "does not allow passenger")


def test_pedestrian_off_any_walkable_lane(tmp_path, town_scenario):
    from drivefuzz.scenario import Actor

    a = Actor(id="p", kind="pedestrian", nav="immobile", start_lane="B0B1_0", start_pos=20, speed=0)
    _one_line_error(*_edit(tmp_path, town_scenario, "routes.rou.xml", 'value="B0B1_0"', 'value="B0B1_1"', actors=(a,)),
                    "actors[0](p).start_lane", "walkable")


def test_negative_puddle_size(tmp_path, town_scenario):
    from drivefuzz.scenario import Puddle

    p = Puddle(x=1, y=1, length=2, width=2, friction=0.5)
    _one_line_error(*_edit(tmp_path, town_scenario, "fuzz.add.xml", 'key="drivefuzz.length" value="2.0"',
                           'key="drivefuzz.length" value="-2.0"', puddles=(p,)), "fuzz.add.xml", "length")


def test_mission_with_no_route(tmp_path):
    from drivefuzz.scenario import Mission, Scenario

    # the highway has no U-turns: nothing leads from the far end back to the on-ramp
    sc = Scenario(network=str(TOWN.parent / "highway.net.xml"),
                  mission=Mission(start_lane="hw2_0", start_pos=5, goal_edge="onramp", goal_pos=5))
    path = tmp_path / "sc.json"
    path.write_text(sc.model_dump_json())
    _one_line_error(*_invoke(["run", str(path)]), "sc.json", "mission", "no route")


def test_unusable_scheduler(tmp_path):
    """Each in its own process, as a user runs it (one Dask client per process)."""
    import os
    import subprocess
    import sys

    from conftest import ROOT

    bad_json = tmp_path / "s.json"
    bad_json.write_text("{not json")
    cases = (("foo:bar", "cannot reach"), ("udp://127.0.0.1:1", "cannot reach"), (str(bad_json), "cannot reach"),
             (str(tmp_path / "none.json"), "no such scheduler file"), ("slurm", "drivefuzz campaign"),
             ("nowhere", "not a scheduler address"), ("ucx://127.0.0.1:1", "cannot reach"))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    procs = [subprocess.Popen([sys.executable, "-m", "drivefuzz.cli", "fuzz", str(TOWN), "--scheduler", where,
                               "--max-execs", "1", "-o", str(tmp_path / f"o{i}")],
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i, (where, _) in enumerate(cases)]
    for p, (where, needle) in zip(procs, cases):
        out, err = p.communicate(timeout=120)
        _one_line_error(p.returncode, out + err, None, "--scheduler", needle)


def test_campaign_file_oracle_settings_are_named_as_the_files(tmp_path):
    camp = tmp_path / "camp.toml"
    camp.write_text(f'[matrix]\nnetworks = ["{TOWN}"]\n[oracles.speeding]\ntolerance = "x"\n')
    _one_line_error(*_invoke(["campaign", str(camp), "-o", str(tmp_path / "o")]), "camp.toml", "speeding.tolerance")


def test_python_dash_m_drivefuzz_is_the_command(tmp_path):
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-m", "drivefuzz", "run", str(tmp_path / "missing")],
                       capture_output=True, text=True, timeout=60)
    assert p.stdout == ""
    _one_line_error(p.returncode, p.stderr, "missing", "no such scenario")


def test_the_fuzz_command_offers_every_feedback_the_campaign_knows():
    from drivefuzz.campaign.config import FEEDBACKS
    from drivefuzz.cli import main

    (choice,) = [p.type for p in main.commands["fuzz"].params if p.name == "feedback"]
    assert tuple(choice.choices) == FEEDBACKS
