"""A newcomer's run (issue 15): seeds found next to the network, an ADS in the current folder, the analysis
extra, the plain progress lines, the simulated-time column, fuzzing a network netgenerate made."""

from __future__ import annotations

import re
import shutil

import pytest
from click.testing import CliRunner

from drivefuzz.cli import main
from drivefuzz.errors import InvalidConfig

from conftest import ROOT, TOWN


def _no_generation(*_args, **_kwargs):
    raise AssertionError("seeds were generated: the network's own seeds were not found")


def test_seeds_are_found_next_to_the_network_from_any_folder(tmp_path, monkeypatch):
    """networks/town.net.xml -> seeds/town/, whatever the current folder; nothing is written there."""
    from drivefuzz.cli import common as cli
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import load_scenario

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("drivefuzz.scenario.seed.generate_seeds", _no_generation)
    seeds = cli.seeds_for(str(TOWN), None)
    own = [load_scenario(p) for p in list_seeds(ROOT / "seeds" / "town")]
    assert [s.content_hash() for s in seeds] == [s.content_hash() for s in own]
    assert list(tmp_path.iterdir()) == []


def test_a_campaign_file_names_its_seed_folder(tmp_path, monkeypatch):
    """[campaign] seeds = "mine": mine/<net>/ is used before the network's own seeds."""
    from drivefuzz.cli import common as cli
    from drivefuzz.campaign.batch import load_campaign_file
    from drivefuzz.scenario.sumofiles import load_scenario

    mine = tmp_path / "mine" / "town"
    mine.mkdir(parents=True)
    shutil.copytree(ROOT / "seeds" / "town" / "003", mine / "000")
    manifest = mine / "000" / "scenario.json"
    manifest.write_text(re.sub(r'"network": "[^"]*"', f'"network": "{TOWN}"', manifest.read_text()))
    spec_file = tmp_path / "c.toml"
    spec_file.write_text(f'[campaign]\nseeds = "mine"\n[matrix]\nnetworks = ["{TOWN}"]\n')
    spec = load_campaign_file(spec_file)
    assert spec.seeds_root == (tmp_path / "mine").resolve()
    monkeypatch.setattr("drivefuzz.scenario.seed.generate_seeds", _no_generation)
    seeds = cli.seeds_for(str(TOWN), None, 8, spec.seeds_root)
    assert [s.content_hash() for s in seeds] == [load_scenario(mine / "000").content_hash()]
    spec_file.write_text(f'[campaign]\nseeds = "nowhere"\n[matrix]\nnetworks = ["{TOWN}"]\n')
    with pytest.raises(InvalidConfig, match="campaign.seeds"):
        load_campaign_file(spec_file)


def _drivefuzz(args, cwd):
    """The installed console script, as a user runs it (its folder, not ``cwd``, is on its import path)."""
    import subprocess
    import sys
    from pathlib import Path

    exe = Path(sys.executable).with_name("drivefuzz")
    return subprocess.run([str(exe), *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_an_ads_module_in_the_current_folder(tmp_path):
    """--ads mycar:MinimalADS with mycar.py where the user runs drivefuzz: fuzzed in the simulation host (which
    runs with -I); a shapely.py beside it is not imported; a misspelt module is one line and exit 2."""
    import sqlite3

    shutil.copy(ROOT / "examples" / "ads-minimal" / "drivefuzz_ads_minimal.py", tmp_path / "mycar.py")
    marker = tmp_path / "marker"
    (tmp_path / "shapely.py").write_text(f"open({str(marker)!r}, 'w').write('ran')\n")
    net = ROOT / "networks" / "intersection.net.xml"
    r = _drivefuzz(["fuzz", net, "--ads", "mycar:MinimalADS", "--max-execs", "2", "-o", "out"], tmp_path)
    assert r.returncode in (0, 1), r.stderr
    verdicts = [v for (v,) in sqlite3.connect(tmp_path / "out" / "index.sqlite").execute("SELECT verdict FROM executions")]
    assert len(verdicts) == 2 and not any("error" in v or "crash" in v for v in verdicts), verdicts
    assert not marker.exists()
    r = _drivefuzz(["fuzz", net, "--ads", "mycra:MinimalADS", "--max-execs", "1", "-o", "out2"], tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "no module named 'mycra'" in r.stderr
    r = _drivefuzz(["fuzz", net, "--ads", "mycar:Nope", "--max-execs", "1", "-o", "out2"], tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "'Nope'" in r.stderr, r.stderr


def test_the_readme_one_liner_opens_a_trace_with_the_analysis_extra(tmp_path):
    """README: pandas.read_parquet(".../trace/ego.parquet"), pandas from the `analysis` extra (pyproject)."""
    import re
    import tomllib

    pandas = pytest.importorskip("pandas", reason="pip install -e '.[analysis]' (the test extra has it too)")
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert any(d.startswith("pandas") for d in extras["analysis"])
    readme = (ROOT / "README.md").read_text()
    assert re.search(r'pandas\.read_parquet\(.*\n.*pip install -e "\.\[analysis\]"', readme)
    r = CliRunner().invoke(main, ["run", str(ROOT / "seeds" / "intersection" / "000"), "--trace", str(tmp_path / "t")])
    assert r.exit_code in (0, 1), r.output
    ego = pandas.read_parquet(tmp_path / "t" / "ego.parquet")
    assert len(ego) > 10 and {"x", "y"} <= set(ego.columns), ego.columns


def test_progress_off_a_terminal_is_plain_lines_and_the_summary_says_sim_time(tmp_path):
    """Not a terminal (CliRunner's stderr): plain status lines with elapsed, remaining, rate, where, best risk,
    findings, the last finding and workers busy (1 of 1 worker, never more); no terminal control codes. The
    summary's event time is headed 'sim time'."""
    seeds = tmp_path / "seeds"
    shutil.copytree(ROOT / "seeds" / "town" / "005", seeds / "000")
    manifest = seeds / "000" / "scenario.json"
    manifest.write_text(re.sub(r'"network": "[^"]*"', f'"network": "{TOWN}"', manifest.read_text()))
    r = CliRunner().invoke(main, ["fuzz", str(TOWN), "--seeds", str(seeds), "--ads-option", "fault=speeding",
                                  "--max-execs", "3", "--cycles", "1", "--population", "2", "-o", str(tmp_path / "o")])
    assert r.exit_code == 1, r.output
    lines = [line for line in r.stderr.splitlines() if line.startswith("elapsed ")]
    assert lines and "\x1b" not in r.stderr and "\r" not in r.stderr, r.stderr
    last = lines[-1]
    for part in ("remaining 0 executions", "execs 3 (", "/s)", "cycle 0", "best risk ", "findings 1 (",
                 "last: speeding", "jobs 0/1 done"):
        assert part in last, (part, last)
    busy = [int(re.search(r"workers busy (\d+)/1", line).group(1)) for line in lines]
    assert max(busy) <= 1, lines
    assert re.search(r"#\s+hits\s+reproduced\s+sim time", r.stdout), r.stdout


def _netgenerate(tmp_path, name: str, *args: str):
    """A network made by SUMO's netgenerate (it ships with the eclipse-sumo wheel); well under a second."""
    import subprocess
    from pathlib import Path

    import sumo

    net = tmp_path / f"{name}.net.xml"
    subprocess.run([str(Path(sumo.SUMO_HOME) / "bin" / "netgenerate"), *args, "--seed", "1", "-o", str(net)],
                   check=True, capture_output=True, timeout=60)
    return net


def test_obstacles_on_a_generated_grid_leave_the_way_to_the_goal(tmp_path):
    """netgenerate --grid makes roads of one lane with no sidewalks: a stopped car, or a walker, on the goal's
    road before the goal leaves no lawful way there (these made every 'immobility' and 'mission' incident of
    7 seeds on generated networks), nor does one just beyond it, where the queue behind it stands on the goal;
    far enough beyond the goal, or on a road the ego leaves, they are fair."""
    from drivefuzz.scenario import Actor, ActorKind, Mission, NavType, Scenario, SimOptions
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.search.fairness import unfair
    from drivefuzz.search.mutate import MutationConfig, Mutator

    net = _netgenerate(tmp_path, "grid", "--grid", "--grid.number", "4")
    mut = Mutator(load_roadmap(net), MutationConfig())
    sc = Scenario(network=str(net), mission=Mission(start_lane="A0B0_0", start_pos=10.0, goal_edge="B0C0",
                                                    goal_pos=60.0), sim=SimOptions(time_limit=60.0), seed=1)

    def on(nav, kind, pos, lane="B0C0_0"):
        return unfair(mut, sc, Actor(id="a", kind=kind, nav=nav, start_lane=lane, start_pos=pos, speed=(
            0.0 if nav is NavType.IMMOBILE else 1.2), dest_edge=None if nav is NavType.IMMOBILE else "C0D0"))

    assert "before the ego's goal" in on(NavType.IMMOBILE, ActorKind.VEHICLE, 40.0)
    assert "before the ego's goal" in on(NavType.AUTOPILOT, ActorKind.PEDESTRIAN, 40.0)
    assert "one lane" in on(NavType.IMMOBILE, ActorKind.PEDESTRIAN, 60.0, lane="A0B0_0")
    # beyond the goal: the cars that queue behind it must not reach back to the goal (a roundabout campaign
    # lost four incidents to one such queue)
    assert "queue" in on(NavType.IMMOBILE, ActorKind.VEHICLE, 85.0)
    assert on(NavType.IMMOBILE, ActorKind.VEHICLE, 92.0) is None


@pytest.mark.timeout(300)
@pytest.mark.parametrize("args", [["--grid", "--grid.number", "4"], ["--rand", "--tls.guess"]],
                         ids=["grid", "rand-tls"])
def test_fuzzing_a_generated_network(tmp_path, args):
    """A few executions of two unverified seeds on a network netgenerate made: every mutant runs (no internal
    error, no simulator crash, no plugin error), and none is blocked by an obstacle the mutator placed."""
    import sqlite3

    from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
    from drivefuzz.scenario.seed import generate_seeds

    net = _netgenerate(tmp_path, args[0].strip("-"), *args)
    seeds = generate_seeds(net, 2, 0, verify=None)
    assert len(seeds) == 2
    Campaign(tmp_path / "out", seeds, FuzzConfig(cycles=2, population=3, max_execs=10, time_limit=40.0)).run()
    rows = sqlite3.connect(tmp_path / "out" / "index.sqlite").execute(
        "SELECT verdict, mutation, incident FROM executions").fetchall()
    assert len(rows) == 10
    assert not [r for r in rows if r[0].split("/")[0] in ("internal-error", "simulator-crash", "plugin-error", "hang")], rows
    assert not [r for r in rows if r[0] == "immobility/immobile" and r[2]], rows
