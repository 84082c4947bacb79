"""Hostile input (issue 15): every case gives exit 2, one line on stderr naming the file (or option), no traceback.

The cases are generated from the categories of issue 15: scenario folders out of
bounds, broken networks (SUMO would segfault or refuse them), config files and
campaign files of the wrong types, out-of-range command-line options, damaged
campaign, batch and finding folders, outputs that cannot be written. Each builds
its input in a fresh folder and runs the real CLI in this process (none gets as
far as SUMO), from that folder: nothing may be written there but under the
output directory, and nothing may be left in the (test's own) temporary folder.
The networks that made SUMO segfault also run in a process of their own (no
signal death). The security routes (code named by a data file, or lying in the
folder drivefuzz starts from) run the CLI as a user would, in a process of its
own, and check that a marker file was not created.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import sqlite3
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import pytest
from click.testing import CliRunner

from drivefuzz.cli import main

from conftest import ROOT, TOWN

SEEDS = ROOT / "seeds" / "town"
SMALL_NET = ROOT / "networks" / "intersection.net.xml"
SMALL_SEED = ROOT / "seeds" / "intersection" / "000"


def invoke(args, cwd: Path | None = None):
    old = os.getcwd()
    if cwd is not None:
        os.chdir(cwd)
    try:
        return CliRunner().invoke(main, [str(a) for a in args])
    finally:
        os.chdir(old)


def assert_one_line(result, needle: str) -> str:
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Traceback" not in result.output, result.output
    assert result.exit_code == 2, result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    assert needle in lines[0], lines[0]
    return lines[0]


# ----------------------------------------------------------------------------- builders
def scenario_dir(tmp: Path) -> Path:
    """A copy of a verified seed (its network referred to by absolute path)."""
    dst = tmp / "s"
    shutil.copytree(SMALL_SEED, dst)
    m = json.loads((dst / "scenario.json").read_text())
    m["network"] = str(SMALL_NET)
    (dst / "scenario.json").write_text(json.dumps(m))
    return dst


def edit(path: Path, pattern: str, repl: str, count: int = 0, flags: int = 0) -> None:
    text = path.read_text()
    new = re.sub(pattern, repl, text, count=count, flags=flags)
    assert new != text, (path, pattern)
    path.write_text(new)


def edit_json(path: Path, fn: Callable[[dict], object]) -> None:
    data = json.loads(path.read_text())
    data = fn(data) or data
    path.write_text(json.dumps(data))


def with_actor(s: Path, **attrs) -> None:
    """Put one linear vehicle (or pedestrian) into the scenario's route file."""
    routes = s / "routes.rou.xml"
    text = routes.read_text()
    edge = re.search(r'<route edges="(\S+)', text).group(1)
    a = dict(speed="5.0", depart="0.0", dest_xy=None) | attrs
    params = (f'<param key="drivefuzz.nav" value="linear"/><param key="drivefuzz.start_lane" value="{edge}_1"/>'
              f'<param key="drivefuzz.speed" value="{a["speed"]}"/><param key="drivefuzz.dest_edge" value="{edge}"/>')
    if a["dest_xy"]:
        params += f'<param key="drivefuzz.dest_xy" value="{a["dest_xy"]}"/>'
    actor = (f'<trip id="v" type="drivefuzz_linear" depart="{a["depart"]}" departLane="1" departPos="5.0" '
             f'departSpeed="max" from="{edge}" to="{edge}">{params}</trip>')
    routes.write_text(text.replace("</routes>", actor + "\n</routes>"))


def with_puddle(s: Path, x: str = "10.0", y: str = "10.0") -> None:
    add = s / "fuzz.add.xml"
    poly = (f'<poly id="puddle_0" type="drivefuzz.puddle" color="0,90,200" shape="0,0 1,0 1,1">'
            f'<param key="drivefuzz.x" value="{x}"/><param key="drivefuzz.y" value="{y}"/>'
            '<param key="drivefuzz.length" value="2.0"/><param key="drivefuzz.width" value="2.0"/>'
            '<param key="drivefuzz.rotation" value="0.0"/><param key="drivefuzz.friction" value="0.5"/></poly>')
    add.write_text(add.read_text().replace("</additional>", poly + "\n</additional>"))


def bad_network(tmp: Path, mutate: Callable[[str], str]) -> Path:
    net = tmp / "bad.net.xml"
    text = SMALL_NET.read_text()
    new = mutate(text)
    assert new != text
    net.write_text(new)
    return net


def scenario_on(tmp: Path, net: Path) -> Path:
    s = scenario_dir(tmp)
    edit_json(s / "scenario.json", lambda m: m.update(network=str(net)))
    return s


DEEP_JSON = "[" * 100_000 + "]" * 100_000
DEEP_TOML = "a = " + "[" * 5000 + "]" * 5000 + "\n"


# ----------------------------------------------------------------------------- cases
@dataclass
class Case:
    id: str
    run: Callable[[Path], tuple[list, str]]  # tmp -> (CLI args, what the one line must name)


def _run_scenario(prepare: Callable[[Path], None], needle: str):
    def run(tmp):
        s = scenario_dir(tmp)
        prepare(s)
        return ["run", s], needle
    return run


SCENARIO_CASES = [
    Case("start_speed-inf", _run_scenario(lambda s: edit(s / "routes.rou.xml", r'departSpeed="[^"]*"', 'departSpeed="inf"', 1), "routes.rou.xml")),
    Case("start_speed-1e6", _run_scenario(lambda s: edit(s / "routes.rou.xml", r'departSpeed="[^"]*"', 'departSpeed="1e6"', 1), "routes.rou.xml")),
    Case("start_speed-over-the-limit", _run_scenario(lambda s: edit(s / "routes.rou.xml", r'departSpeed="[^"]*"', 'departSpeed="20.0"', 1), "scenario.json")),
    Case("empty-ego-route", _run_scenario(lambda s: edit(s / "routes.rou.xml", r'<route edges="[^"]*"', '<route edges=""'), "routes.rou.xml")),
    Case("deep-scenario-json", _run_scenario(lambda s: (s / "scenario.json").write_text(DEEP_JSON), "scenario.json")),
    Case("scenario-json-is-a-list", _run_scenario(lambda s: (s / "scenario.json").write_text("[1, 2]"), "scenario.json")),
    Case("ads-name-not-a-string", _run_scenario(lambda s: edit_json(s / "scenario.json", lambda m: m.update(ads={"name": 5})), "scenario.json")),
    Case("ads-not-installed", _run_scenario(lambda s: edit_json(s / "scenario.json", lambda m: m.update(ads={"name": "evil_mod:X"})), "scenario.json")),
    Case("step_length-0.0001", _run_scenario(lambda s: edit_json(s / "scenario.json", lambda m: m["sim"].update(step_length=0.0001)), "scenario.json")),
    Case("time_limit-inf", _run_scenario(lambda s: edit(s / "scenario.json", r'"time_limit": [0-9.]+', '"time_limit": Infinity'), "scenario.json")),
    Case("actor-speed-inf", _run_scenario(lambda s: with_actor(s, speed="inf"), "routes.rou.xml")),
    Case("actor-depart-inf", _run_scenario(lambda s: with_actor(s, depart="inf"), "routes.rou.xml")),
    Case("actor-dest_xy-nan", _run_scenario(lambda s: with_actor(s, dest_xy="nan,nan"), "routes.rou.xml")),
    Case("actor-dest_xy-far-away", _run_scenario(lambda s: with_actor(s, dest_xy="1e6,1e6"), "scenario.json")),
    Case("puddle-at-1e308", _run_scenario(lambda s: with_puddle(s, x="1e308"), "fuzz.add.xml")),
    Case("puddle-off-the-network", _run_scenario(lambda s: with_puddle(s, x="50000.0"), "scenario.json")),
    Case("deep-maneuvers", _run_scenario(lambda s: (with_actor(s), edit(s / "routes.rou.xml", "</trip>", f'<param key="drivefuzz.maneuvers" value="{DEEP_JSON[:4000] + DEEP_JSON[-4000:]}"/></trip>')), "routes.rou.xml")),
]

NETWORK_MUTATIONS = {  # what SUMO segfaults on, refuses, or what reached the ADS as a ValueError
    "lane-index-7": lambda t: re.sub(r'(<lane [^>]*?)index="\d+"', r'\1index="7"', t),
    "lane-speed-nan": lambda t: re.sub(r'(<lane [^>]*?)speed="[^"]*"', r'\1speed="nan"', t),
    "lane-length-inf": lambda t: re.sub(r'(<lane [^>]*?)length="[^"]*"', r'\1length="inf"', t),
    "lane-shape-nan": lambda t: re.sub(r'(<lane [^>]*?)shape="[^"]*"', r'\1shape="nan,nan 1,1"', t),
    "wrong-root": lambda t: t.replace("<net ", "<nett ").replace("</net>", "</nett>"),
    "unknown-node": lambda t: re.sub(r'(<edge id="[^:"][^"]*" )from="[^"]*"', r'\1from="NOPE"', t, count=1),
    "missing-traffic-light": lambda t: re.sub(r"<tlLogic .*?</tlLogic>", "", t, flags=re.S),
    "junction-x-nan": lambda t: re.sub(r'(<junction [^>]*?)x="[^"]*"', r'\1x="nan"', t, count=1),
    "link-index-999": lambda t: re.sub(r'linkIndex="\d+"', 'linkIndex="999"', t, count=1),
    # SUMO runs these; drivefuzz's lane arrays and stopping arithmetic cannot (the ADS raised at reset, exit 3)
    "lane-length-1e20": lambda t: re.sub(r'(<lane id="[^:][^>]*?)length="[^"]*"', r'\1length="1e20"', t),
    "lane-speed-1e308": lambda t: re.sub(r'(<lane id="[^:][^>]*?)speed="[^"]*"', r'\1speed="1e308"', t),
    # a railway: SUMO loads it, and no lane allows a passenger car
    "no-car-roads": lambda t: re.sub(r'(<lane [^>]*?)(?:dis)?allow="[^"]*"', r'\1',
                                     t).replace("<lane ", '<lane allow="rail" '),
}


def _network_case(mutate, command):
    def run(tmp):
        net = bad_network(tmp, mutate)
        if command == "run":
            return ["run", scenario_on(tmp, net)], "bad.net.xml"
        if command == "seed":
            return ["seed", net, "-n", "1", "-o", tmp / "seeds"], "bad.net.xml"
        return ["fuzz", net, "-o", tmp / "o", "--max-execs", "1"], "bad.net.xml"
    return run


NETWORK_CASES = [Case(f"net-{name}-{cmd}", _network_case(fn, cmd))
                 for name, fn in NETWORK_MUTATIONS.items() for cmd in ("run", "fuzz")]
NETWORK_CASES += [Case(f"net-{name}-seed", _network_case(NETWORK_MUTATIONS[name], "seed"))
                  for name in ("lane-index-7", "no-car-roads", "lane-length-1e20")]
#: every edge a self-loop (it ends at the junction it starts from): SUMO loads it, sumolib's link index raised
SELF_LOOPS = ("self-loops", lambda t: re.sub(r'(<edge id="[^:"][^"]*" from="([^"]*)") to="[^"]*"', r'\1 to="\2"', t))
NETWORK_CASES += [Case(f"net-self-loops-{cmd}", _network_case(SELF_LOOPS[1], cmd)) for cmd in ("seed", "fuzz")]

CONFIGS = {  # (file name, text, what the line names besides the file)
    "strategy-nope": ("c.toml", '[fuzz]\nstrategy = "nope"\n', "fuzz.strategy"),
    "cycles-ten": ("c.toml", '[fuzz]\ncycles = "ten"\n', "fuzz.cycles"),
    "cycles-0": ("c.toml", "[fuzz]\ncycles = 0\n", "fuzz.cycles"),
    "exec_timeout-inf": ("c.toml", "[fuzz]\nexec_timeout = inf\n", "fuzz.exec_timeout"),
    "exec_timeout-nan": ("c.toml", "[fuzz]\nexec_timeout = nan\n", "fuzz.exec_timeout"),
    "unknown-fuzz-key": ("c.toml", "[fuzz]\ncylces = 3\n", "fuzz.cylces"),
    "unknown-section": ("c.toml", "[fuz]\ncycles = 3\n", "fuz"),
    "oracles-5": ("c.toml", "oracles = 5\n", "oracles"),
    "oracles-speeding-5": ("c.toml", "[oracles]\nspeeding = 5\n", "speeding"),
    "oracle-setting": ("c.toml", '[oracles.speeding]\ntolerance = "x"\n', "speeding.tolerance"),
    "unknown-oracle": ("c.toml", "[oracles.nope]\nx = 1\n", "nope"),
    "ads-options-x": ("c.toml", '[ads]\noptions = "x"\n', "ads.options"),
    "mutation-key": ("c.toml", "[mutation]\nnope = 1\n", "mutation.nope"),
    "budget-soon": ("c.toml", '[fuzz]\nbudget = "soon"\n', "fuzz.budget"),
    "deep-toml": ("c.toml", DEEP_TOML, "nested too deeply"),
    "config-is-a-list": ("c.json", "[1, 2]", "not a table"),
    "deep-json": ("c.json", DEEP_JSON, "nested too deeply"),
}


def _config_case(name, text, needle, command):
    def run(tmp):
        cfg = tmp / name
        cfg.write_text(text)
        if command == "run":
            return ["run", scenario_dir(tmp), "--config", cfg], f"{cfg}: "
        return ["fuzz", TOWN, "--config", cfg, "--seeds", SEEDS, "-o", tmp / "o"], f"{cfg}: "
    return run


CONFIG_CASES = [Case(f"config-{key}-{cmd}", _config_case(name, text, needle, cmd))
                for key, (name, text, needle) in CONFIGS.items() for cmd in ("fuzz", "run")]

OPTIONS = {  # fuzz options out of range: (arguments, what the line names)
    "population-0": (["--population", "0"], "--population"),
    "cycles-0": (["--cycles", "0"], "--cycles"),
    "exec-timeout-0": (["--exec-timeout", "0"], "--exec-timeout"),
    "exec-timeout-inf": (["--exec-timeout", "inf"], "--exec-timeout"),
    "exec-timeout-nan": (["--exec-timeout", "nan"], "--exec-timeout"),
    "time-limit-inf": (["--time-limit", "inf"], "--time-limit"),
    "max-execs-0": (["--max-execs", "0"], "--max-execs"),
    "max-execs--1": (["--max-execs", "-1"], "--max-execs"),
    "jobs-100000": (["--jobs", "100000"], "--jobs"),
    "jobs-0": (["--jobs", "0"], "--jobs"),
    "ads-abstract": (["--ads", "drivefuzz.ads:ADS"], "abstract"),
    "ads-missing-module": (["--ads", "no_such_module_x:Y"], "no_such_module_x"),
    "ads-not-an-ads": (["--ads", "os:path"], "os:path"),
    "ads-option-list": (["--ads-option", "fault=[1]"], "--ads-option"),
    "unknown-option": (["--bogus"], "--bogus"),
    "strategy-nope": (["--strategy", "nope"], "--strategy"),
}


def _option_case(extra, needle):
    def run(tmp):
        return ["fuzz", TOWN, "--seeds", SEEDS, "-o", tmp / "o", *extra], needle
    return run


OPTION_CASES = [Case(f"option-{key}", _option_case(extra, needle)) for key, (extra, needle) in OPTIONS.items()]
OPTION_CASES += [
    Case("usage-missing-argument", lambda tmp: (["run"], "SCENARIO")),
    Case("usage-unknown-command", lambda tmp: (["fuz"], "fuz")),
    Case("seed-n-0", lambda tmp: (["seed", TOWN, "-n", "0", "-o", tmp / "x"], "-n")),
]


def _unwritable(command):
    def run(tmp):
        if command == "fuzz":
            return ["fuzz", TOWN, "--seeds", SEEDS, "-o", "/proc/x/out"], "/proc/x/out"
        if command == "seed":
            return ["seed", TOWN, "-n", "1", "-o", "/proc/x/out"], "/proc/x/out"
        return ["run", scenario_dir(tmp), "--trace", "/proc/x/trace"], "/proc/x/trace"
    return run


def _seed_into_existing(tmp):
    out = tmp / "other"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    return ["seed", TOWN, "-n", "1", "-o", out], str(out)


def _seeds_from_a_foreign_folder(tmp):
    foreign = tmp / "etc"
    foreign.mkdir()
    (foreign / "passwd").write_text("root:x:0:0")
    return ["fuzz", TOWN, "--seeds", foreign, "-o", tmp / "o"], str(foreign)


OUTPUT_CASES = [Case(f"unwritable-{c}", _unwritable(c)) for c in ("fuzz", "seed", "run")] + [
    Case("seed-into-a-folder-of-other-things", _seed_into_existing),
    Case("seeds-from-a-folder-with-no-seeds", _seeds_from_a_foreign_folder),
]


# ----------------------------------------------------------------------------- campaign folders
@pytest.fixture(scope="module")
def campaign_template(tmp_path_factory):
    """A campaign folder as 'drivefuzz fuzz' leaves it before its first execution."""
    from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
    from drivefuzz.scenario.sumofiles import load_scenario

    out = tmp_path_factory.mktemp("campaign") / "c"
    Campaign(out, [load_scenario(SMALL_SEED)], FuzzConfig(cycles=1, population=1)).prepare(resume=False)
    (out / "jobs" / "000").mkdir(parents=True, exist_ok=True)
    return out


def _resume_case(damage: Callable[[Path], None], needle: str):
    def run(tmp, template):
        out = tmp / "c"
        shutil.copytree(template, out)
        damage(out)
        return ["fuzz", "--resume", out, "--max-execs", "1"], needle
    return run


def _manifest(fn):
    return lambda out: edit_json(out / "manifest.json", fn)


def _journal(text: bytes):
    return lambda out: (out / "jobs" / "000" / "journal.jsonl").write_bytes(text)


RESUME_CASES = [
    Case("manifest-cycles-ten", _resume_case(_manifest(lambda m: m["config"].update(cycles="ten")), "manifest.json")),
    Case("manifest-seeds-5", _resume_case(_manifest(lambda m: m.update(seeds=5)), "manifest.json")),
    Case("manifest-seeds-outside", _resume_case(_manifest(lambda m: m.update(seeds=["/etc"])), "manifest.json")),
    Case("manifest-config-list", _resume_case(_manifest(lambda m: m.update(config=[])), "manifest.json")),
    Case("manifest-exec-timeout-x", _resume_case(_manifest(lambda m: m["config"].update(exec_timeout_s="x")), "manifest.json")),
    Case("manifest-oracles-5", _resume_case(_manifest(lambda m: m["config"].update(oracles={"speeding": 5})), "manifest.json")),
    Case("manifest-unknown-oracle", _resume_case(_manifest(lambda m: m["config"].update(oracles={"nope": {}})), "manifest.json")),
    Case("manifest-is-a-list", _resume_case(lambda out: (out / "manifest.json").write_text("[]"), "manifest.json")),
    Case("manifest-deep", _resume_case(lambda out: (out / "manifest.json").write_text(DEEP_JSON), "manifest.json")),
    Case("manifest-ads-not-installed", _resume_case(_manifest(lambda m: m["config"]["ads"].update(name="evil_mod:X")), "manifest.json")),
    Case("journal-binary", _resume_case(_journal(bytes(range(256)) * 4), "journal.jsonl")),
    Case("journal-missing-keys", _resume_case(_journal(b'{"event": "end", "key": "k"}\n'), "journal.jsonl")),
    Case("journal-not-an-object", _resume_case(_journal(b"[1, 2]\n"), "journal.jsonl")),
    Case("journal-finding-outside", _resume_case(_journal(
        b'{"event": "end", "key": "k", "seed_index": 0, "cycle": 0, "hash": "h", "finding": "/etc"}\n'), "journal.jsonl")),
]


# ----------------------------------------------------------------------------- finding folders
def _finding(tmp: Path, verdict: object | str) -> Path:
    f = tmp / "finding"
    shutil.copytree(scenario_dir(tmp), f)
    text = verdict if isinstance(verdict, str) else json.dumps(verdict)
    (f / "verdict.json").write_text(text)
    return f


GOOD_VERDICT = {"misbehaviors": [{"oracle": "collision", "kind": "vehicle", "frame": 10, "time": 0.5,
                                  "position": [0.0, 0.0]}], "scenario_hash": "x", "oracles": {},
                "exec_timeout_s": 300.0}


def _replay_case(verdict, needle, scenario_edit=None):
    def run(tmp):
        f = _finding(tmp, verdict)
        if scenario_edit:
            edit_json(f / "scenario.json", scenario_edit)
        return ["replay", f], needle
    return run


REPLAY_CASES = [
    Case("verdict-garbage", _replay_case("\x00garbage", "verdict.json")),
    Case("verdict-list", _replay_case([1], "verdict.json")),
    Case("verdict-deep", _replay_case(DEEP_JSON, "verdict.json")),
    Case("verdict-misbehavior-types", _replay_case(GOOD_VERDICT | {"misbehaviors": [{"oracle": 1, "kind": [], "frame": "x"}]}, "verdict.json")),
    Case("verdict-exec-timeout-x", _replay_case(GOOD_VERDICT | {"exec_timeout_s": "x"}, "verdict.json")),
    Case("verdict-oracles-5", _replay_case(GOOD_VERDICT | {"oracles": 5}, "verdict.json")),
    Case("verdict-oracle-setting", _replay_case(GOOD_VERDICT | {"oracles": {"speeding": {"nope": 1}}}, "verdict.json")),
    Case("replay-ads-not-installed", _replay_case(GOOD_VERDICT, "scenario.json", lambda m: m.update(ads={"name": "evil_mod:X"}))),
]


def _campaign_file_case(text, needle):
    def run(tmp):
        f = tmp / "camp.toml"
        f.write_text(text)
        return ["campaign", f, "-o", tmp / "o"], needle
    return run


NET_LINE = f'[matrix]\nnetworks = ["{TOWN}"]\n'
CAMPAIGN_FILES = {  # a campaign file's text -> what the line names besides the file
    "deep-toml": (DEEP_TOML, "nested too deeply"),
    "not-toml": ("[matrix\nnetworks = ", "cannot parse"),
    "binary": ("\x00\xff" * 50, "camp.toml"),
    "no-matrix": ("[campaign]\ncycles = 2\n", "matrix"),
    "networks-5": ("[matrix]\nnetworks = 5\n", "matrix.networks"),
    "networks-empty": ("[matrix]\nnetworks = []\n", "matrix.networks"),
    "network-missing": ('[matrix]\nnetworks = ["nowhere.net.xml"]\n', "matrix.networks"),
    "unknown-section": (NET_LINE + "[nope]\nx = 1\n", "nope"),
    "unknown-key": (NET_LINE + "[campaign]\nbudgett = '1m'\n", "campaign.budgett"),
    "budget-soon": (NET_LINE + "[campaign]\nbudget = 'soon'\n", "campaign.budget"),
    "exec-timeout-inf": (NET_LINE + "[campaign]\nexec_timeout = inf\n", "campaign.exec_timeout"),
    "cycles-0": (NET_LINE + "[campaign]\ncycles = 0\n", "campaign.cycles"),
    "seeds-folder-missing": (NET_LINE + "[campaign]\nseeds = 'nowhere'\n", "campaign.seeds"),
    "strategy": (NET_LINE + "strategies = ['chaos']\n", "matrix.strategies"),
    "ads-missing": (NET_LINE + "ads = [{name = 'nosuchads'}]\n", "matrix.ads"),
    "ads-option": (NET_LINE + "ads = [{name = 'ego', options = {fault = 'bogus'}}]\n", "matrix.ads"),
    "cells-clash": (NET_LINE + "seeds = [0, 0]\n", "share the directory"),
    "where-moon": (NET_LINE + "[run]\nwhere = 'moon'\n", "run.where"),
    "jobs-0": (NET_LINE + "[run]\njobs = 0\n", "run.jobs"),
    "cluster-cores-0": (NET_LINE + "[cluster]\ncores = 0\n", "cluster.cores"),
    "oracle-setting": (NET_LINE + "[oracles.speeding]\ntolerance = 'x'\n", "speeding.tolerance"),
}
CAMPAIGN_CASES = [Case(f"campaign-{key}", _campaign_file_case(text, needle))
                  for key, (text, needle) in CAMPAIGN_FILES.items()]


def _batch_resume_case(content: str, needle: str):
    """``drivefuzz campaign --resume DIR`` of a batch folder whose campaign.json is damaged."""
    def run(tmp):
        d = tmp / "batch"
        d.mkdir()
        (d / "campaign.json").write_text(content)
        return ["campaign", "--resume", d], needle
    return run


GOOD_BATCH = {"matrix": {"networks": [str(TOWN)]}}
BATCH_CASES = [
    Case("batch-json-garbage", _batch_resume_case("\x00garbage", "campaign.json")),
    Case("batch-json-list", _batch_resume_case("[]", "campaign.json")),
    Case("batch-json-deep", _batch_resume_case(DEEP_JSON, "campaign.json")),
    Case("batch-json-types", _batch_resume_case(json.dumps({"matrix": {"networks": 5}}), "campaign.json")),
    Case("batch-ads-not-installed", _batch_resume_case(json.dumps(
        GOOD_BATCH | {"matrix": {"networks": [str(TOWN)], "ads": [{"name": "evil_mod:X"}]}}), "campaign.json")),
    Case("batch-no-campaign-json", lambda tmp: (["campaign", "--resume", tmp], str(tmp))),
]

CASES = (SCENARIO_CASES + NETWORK_CASES + CONFIG_CASES + OPTION_CASES + OUTPUT_CASES + REPLAY_CASES
         + CAMPAIGN_CASES + BATCH_CASES)


@pytest.fixture
def private_tmp(tmp_path, monkeypatch):
    """The system's temporary folder of this test alone (other processes share /tmp): nothing may be left there."""
    import tempfile

    folder = tmp_path.parent / f"{tmp_path.name}-systmp"
    folder.mkdir()
    monkeypatch.setenv("TMPDIR", str(folder))
    monkeypatch.setattr(tempfile, "tempdir", None)  # read TMPDIR again
    yield folder
    tempfile.tempdir = None


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_one_line_and_exit_2(case, tmp_path, private_tmp):
    """Every generated case: exit 2, one line naming the file (or option), no traceback; nothing written in
    the current folder (the test's folder) but under the output directory ``o``, nothing left in /tmp."""
    args, needle = case.run(tmp_path)
    before = _snapshot(tmp_path)
    assert_one_line(invoke(args, cwd=tmp_path), needle)
    written = {p for p in _snapshot(tmp_path) - before if p != "o" and not p.startswith("o/")}
    assert not written, written  # nothing written outside the output directory
    assert not list(private_tmp.iterdir()), list(private_tmp.iterdir())


@pytest.mark.parametrize("case", RESUME_CASES, ids=[c.id for c in RESUME_CASES])
def test_damaged_campaign_folder(case, tmp_path, campaign_template):
    args, needle = case.run(tmp_path, campaign_template)
    assert_one_line(invoke(args, cwd=tmp_path), needle)


def _snapshot(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


# ----------------------------------------------------------------------------- the index
@pytest.mark.parametrize("damage", ["byte-18", "byte-100", "garbage", "folder"])
def test_a_corrupt_index_is_rebuilt_from_the_journals(tmp_path, campaign_template, damage):
    from drivefuzz.campaign.fuzz import Campaign, load_campaign

    out = tmp_path / "c"
    shutil.copytree(campaign_template, out)
    ends = [{"event": "end", "key": f"k{i}", "seed_index": 0, "cycle": 0, "member": i, "hash": f"h{i}",
             "verdict": "pass"} for i in range(3)]
    (out / "jobs" / "000" / "journal.jsonl").write_text("".join(json.dumps(r) + "\n" for r in ends))
    index = out / "index.sqlite"
    if damage == "folder":
        index.unlink()
        index.mkdir()
        (index / "x").write_text("x")
    elif damage == "garbage":
        index.write_bytes(b"not a database at all" * 100)
    else:
        data = bytearray(index.read_bytes())
        data[int(damage.split("-")[1])] ^= 0xFF
        index.write_bytes(bytes(data))
    seeds, cfg, argv = load_campaign(out)
    camp = Campaign(out, seeds, cfg, argv)
    camp.prepare(resume=True)
    camp.db.close()
    assert sqlite3.connect(index).execute("SELECT COUNT(*) FROM executions").fetchone()[0] == 3


# ----------------------------------------------------------------------------- seeds
def test_seeds_are_not_written_into_a_foreign_default_folder(tmp_path, monkeypatch):
    """No --seeds, and ./seeds/<network>/ holds other things: they stay untouched."""
    from drivefuzz.cli import common as cli
    from drivefuzz.scenario.sumofiles import load_scenario

    monkeypatch.chdir(tmp_path)
    net = tmp_path / "a" / "b" / "town.net.xml"  # no seeds next to it
    net.parent.mkdir(parents=True)
    shutil.copy(TOWN, net)
    foreign = tmp_path / "seeds" / "town"
    foreign.mkdir(parents=True)
    (foreign / "notes.txt").write_text("mine")
    new = load_scenario(SEEDS / "000")
    monkeypatch.setattr("drivefuzz.scenario.seed.generate_seeds", lambda *a, **k: [new])  # no dry runs
    assert cli.seeds_for(str(net), None) == [new]
    assert sorted(p.name for p in foreign.iterdir()) == ["notes.txt"]


def test_seed_overwrites_only_with_force(tmp_path):
    out = tmp_path / "s"
    out.mkdir()
    (out / "000").mkdir()
    (out / "000" / "keep").write_text("x")
    assert_one_line(invoke(["seed", TOWN, "-n", "1", "-o", out, "--no-verify"]), "--force")
    assert (out / "000" / "keep").exists()
    result = invoke(["seed", TOWN, "-n", "1", "-o", out, "--no-verify", "--force"])
    assert result.exit_code == 0, result.output
    assert (out / "000" / "scenario.json").exists()


# ----------------------------------------------------------------------------- code named by a data folder
EVIL = "import pathlib\npathlib.Path({marker!r}).write_text('ran')\nclass X: pass\n"


def _user_cli(args, cwd: Path) -> subprocess.CompletedProcess:
    """The CLI as a user runs it from ``cwd`` (``python -m`` puts that folder on the import path)."""
    return subprocess.run([sys.executable, "-m", "drivefuzz.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=300, env=dict(os.environ, PYTHONPATH=os.pathsep.join(
                              [str(cwd)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])))


def _plant(folder: Path) -> Path:
    marker = folder.parent / "marker"
    (folder / "evil_mod.py").write_text(EVIL.format(marker=str(marker)))
    return marker


@pytest.mark.parametrize("command", ["replay", "run"])
def test_a_finding_folder_cannot_name_code_to_import(tmp_path, command):
    f = _finding(tmp_path, GOOD_VERDICT)
    edit_json(f / "scenario.json", lambda m: m.update(ads={"name": "evil_mod:X"}))
    marker = _plant(f)
    r = _user_cli([command, "."], cwd=f)
    assert r.returncode == 2 and "--ads evil_mod:X to trust it" in r.stderr, r.stderr
    assert not marker.exists()


def test_a_campaign_folder_cannot_name_code_to_import(tmp_path, campaign_template):
    out = tmp_path / "c"
    shutil.copytree(campaign_template, out)
    edit_json(out / "manifest.json", lambda m: m["config"]["ads"].update(name="evil_mod:X"))
    marker = _plant(out)
    r = _user_cli(["fuzz", "--resume", ".", "--max-execs", "1"], cwd=out)
    assert r.returncode == 2 and "manifest.json" in r.stderr and len(r.stderr.splitlines()) == 1, r.stderr
    assert not marker.exists()


def test_a_batch_folder_cannot_name_code_to_import(tmp_path):
    """campaign --resume of a downloaded batch whose campaign.json names an ADS module lying beside it."""
    d = tmp_path / "batch"
    d.mkdir()
    (d / "campaign.json").write_text(json.dumps({"matrix": {"networks": [str(TOWN)], "ads": [{"name": "evil_mod:X"}]}}))
    marker = _plant(d)
    r = _user_cli(["campaign", "--resume", "."], cwd=d)
    assert r.returncode == 2 and "--ads evil_mod:X to trust it" in r.stderr and len(r.stderr.splitlines()) == 1, r.stderr
    assert not marker.exists()


@pytest.mark.parametrize("name", ["lane-index-7", "lane-speed-nan"])
def test_networks_that_crashed_sumo_are_one_line_in_a_process_of_their_own(tmp_path, name):
    """The networks that made SUMO segfault (exit 139, no message): as a user runs drivefuzz, exit 2 and one
    line naming the network, with no signal death."""
    net = bad_network(tmp_path, NETWORK_MUTATIONS[name])
    r = _user_cli(["run", scenario_on(tmp_path, net)], cwd=tmp_path)
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.net.xml" in lines[0] and "Traceback" not in r.stderr, r.stderr


# ----------------------------------------------------------------------------- real networks SUMO loads
def _gzipped(tmp: Path) -> Path:
    import gzip

    net = tmp / "city.net.xml.gz"
    with gzip.open(net, "wt") as fh:
        fh.write(SMALL_NET.read_text())
    return net


def _internal_lanes_numbered_0(tmp: Path) -> Path:
    """OSM cities: every lane of a junction's internal edge has index="0"."""
    net = tmp / "city.net.xml"
    text = TOWN.read_text()
    new = re.sub(r'<edge id=":[^"]*" function="internal">.*?</edge>',
                 lambda m: re.sub(r'index="\d+"', 'index="0"', m.group(0)), text, flags=re.S)
    assert new.count('index="0"') > text.count('index="0"')
    net.write_text(new)
    return net


def _empty_internal_lanes(tmp: Path) -> Path:
    """A port network: a junction with incoming roads and intLanes="" (SUMO accepts the empty attribute)."""
    net = tmp / "city.net.xml"
    text = TOWN.read_text()
    new = re.sub(r'(<junction id="[^:"][^"]*" type="priority"[^>]*?)intLanes="[^"]*"', r'\1intLanes=""', text)
    assert new.count('intLanes=""') >= 1 and new != text
    net.write_text(new)
    return net


REAL_NETWORKS = {"gzipped": _gzipped, "internal-lanes-numbered-0": _internal_lanes_numbered_0,
                 "empty-intLanes": _empty_internal_lanes}


@pytest.mark.parametrize("name", REAL_NETWORKS)
def test_networks_that_sumo_loads_give_seeds_and_run(tmp_path, name):
    """Issue 30: what SUMO 1.28 loads without a word, drivefuzz runs on: seeds come out, verified by the
    reference ADS's dry run, and a campaign of a few executions runs on them to its end."""
    net = REAL_NETWORKS[name](tmp_path)
    r = invoke(["seed", net, "-n", "2", "-o", tmp_path / "seeds"], cwd=tmp_path)
    assert r.exit_code == 0 and "Traceback" not in r.output, r.output
    assert len(list((tmp_path / "seeds").glob("*/scenario.json"))) == 2
    r = invoke(["fuzz", net, "--seeds", tmp_path / "seeds", "--max-execs", "3", "-o", tmp_path / "o"], cwd=tmp_path)
    assert r.exit_code in (0, 1) and "Traceback" not in r.output, r.output
    assert "3 executions" in r.stdout, r.stdout


def test_a_network_without_car_roads_is_refused_for_what_it_is(tmp_path):
    """A railway is not a network 'where no mission passed the dry run': it has no road for the ego at all."""
    net = bad_network(tmp_path, NETWORK_MUTATIONS["no-car-roads"])
    line = assert_one_line(invoke(["seed", net, "-n", "1", "-o", tmp_path / "s"], cwd=tmp_path), "bad.net.xml")
    assert "no road a passenger car may use" in line and "rail" in line, line


def test_a_bicycle_lane_connected_to_the_next_road_is_not_a_lane_for_cars(tmp_path):
    """Ingolstadt (SUMO's wheel): a bicycle lane has connections to the next edge like the car lanes; the
    mutator took it for the lane the ego drives and placed a car on it, which SUMO refused, and the campaign
    ended in exit 2 naming a scenario of its own making."""
    from drivefuzz.scenario.roadmap import RoadMap

    net = tmp_path / "bikes.net.xml"
    text = TOWN.read_text()
    new = re.sub(r'(<lane id="A0A1_1" index="1" )(?:dis)?allow="[^"]*"', r'\1allow="bicycle"', text)
    if new == text:  # no allow/disallow on that lane
        new = text.replace('<lane id="A0A1_1" index="1" ', '<lane id="A0A1_1" index="1" allow="bicycle" ')
    assert new != text
    net.write_text(new)
    rmap = RoadMap(net)
    from_lanes = {fl for fl, _tl, _via in rmap.connections("A0A1", "A1B1")}
    assert from_lanes == {"A0A1_2"}, from_lanes
    assert "A0A1_1" in {fl for fl, _tl, _via in rmap.connections("A0A1", "A1B1", "bicycle")}


def test_seeds_of_another_network_are_refused_in_one_line(tmp_path):
    """`fuzz NET --seeds DIR` with seeds written for another network: they were re-pointed to NET unchecked,
    and the first look-up of their lanes ended in a KeyError traceback."""
    r = invoke(["fuzz", SMALL_NET, "--seeds", SEEDS, "--max-execs", "1", "-o", tmp_path / "o"], cwd=tmp_path)
    line = assert_one_line(r, "scenario.json")
    assert "unknown lane" in line and SMALL_NET.name in line, line
