"""A failed execution is the ADS's finding only when the ADS failed.

An ADS plugin that raises, aborts or hangs is a bug of the ADS under test (a finding, fault ``ego``). SUMO
failing, drivefuzz's own errors and an oracle plugin's exceptions are errors of the tool: filed under
``errors/`` with their error and traceback, replayable, shown apart, and never counted as findings (the exit
code says the tool failed). Real SUMO runs; the failing oracle is a plugin registered through a
``.dist-info`` folder on ``sys.path``, as an installed one would be.
"""

from __future__ import annotations

import json
import sqlite3
import sys
import textwrap

import pytest
from click.testing import CliRunner

from drivefuzz.cli import main
from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.errors import ADS_PLUGIN, ORACLE_PLUGIN
from drivefuzz.oracle import OracleSettings
from drivefuzz.scenario import AdsSpec, SimOptions
from drivefuzz.scenario.sumofiles import write_scenario
from drivefuzz.sim.simhost import (CRASH, HANG, INTERNAL_ERROR, NO_PLUGIN, OK, ORACLE_FAULT, PLUGIN_ERROR,
                                   TOOL_FAULT, SimHost, blame_stack, failure_fault)

FAILING = "crashy_plugins:FailingADS"
MODULE = "failing_oracle_plugin"

ORACLE_SOURCE = textwrap.dedent('''
    import os
    import time
    from typing import Literal

    from drivefuzz.oracle import Oracle


    class FailingOracle(Oracle):
        """Reports nothing; from simulated time ``at`` on it raises, aborts the process or hangs."""

        name = "failing_oracle"

        class Config(Oracle.Config):
            failure: Literal["raise", "abort", "hang", "none"] = "raise"
            at: float = 0.5  # [s] simulated time

        def on_frame(self, frame):
            if frame.t >= self.config.at:
                if self.config.failure == "raise":
                    raise ZeroDivisionError("the oracle's own bug")
                if self.config.failure == "abort":
                    os.abort()
                if self.config.failure == "hang":
                    time.sleep(3600)
            return ()
''')


@pytest.fixture
def failing_oracle(tmp_path, monkeypatch):
    """The oracle ``failing_oracle`` installed (module and entry point) for this test, and for its host."""
    site = tmp_path / "site"
    (site / f"{MODULE}-0.1.dist-info").mkdir(parents=True)
    (site / f"{MODULE}.py").write_text(ORACLE_SOURCE)
    (site / f"{MODULE}-0.1.dist-info" / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {MODULE}\nVersion: 0.1\n")
    (site / f"{MODULE}-0.1.dist-info" / "entry_points.txt").write_text(
        f"[drivefuzz.oracles]\nfailing_oracle = {MODULE}:FailingOracle\n")
    monkeypatch.syspath_prepend(str(site))
    yield site
    sys.modules.pop(MODULE, None)


def _short(sc, **ads_options):
    sc = sc.model_copy(update={"sim": SimOptions(time_limit=5.0)})
    if ads_options:
        sc = sc.model_copy(update={"ads": AdsSpec(name=FAILING, options=ads_options)})
    return sc


def _index(out):
    with sqlite3.connect(out / "index.sqlite") as db:
        return db.execute("SELECT key, verdict, fault, finding, error FROM executions ORDER BY exec_id").fetchall()


def test_an_oracle_plugin_that_raises_is_an_error_of_the_tool_not_a_finding(tmp_path, town_scenario,
                                                                             failing_oracle):
    cfg = FuzzConfig(cycles=1, population=1, shrink=0, reproduce=0)
    campaign = Campaign(tmp_path / "out", [_short(town_scenario)], cfg)
    findings = campaign.run()
    assert findings == [] and campaign.progress.findings == 0, [f.path for f in findings]
    assert not any((tmp_path / "out" / "findings").iterdir())
    (err,) = campaign.errors  # one signature, hit by the seed's run and its one mutant
    assert err.path.parent.name == "errors" and err.hits == 2
    assert err.signature["fault"] == ORACLE_FAULT and err.misbehavior.oracle == PLUGIN_ERROR
    verdict = json.loads((err.path / "verdict.json").read_text())
    assert verdict["error"]["plugin"] == ORACLE_PLUGIN and verdict["error"]["type"] == "ZeroDivisionError"
    assert "failing_oracle" in verdict["error"]["detail"] and "the oracle's own bug" in verdict["error"]["traceback"]
    assert (err.path / "replay.sh").exists() and (err.path / "scenario.json").exists()  # kept and replayable
    rows = _index(tmp_path / "out")
    assert [(fault, finding, error) for _, _, fault, finding, error in rows] == \
        [(ORACLE_FAULT, None, str(err.path.relative_to(tmp_path / "out")))] * 2


def test_an_ads_plugin_that_raises_stays_a_finding_of_the_ads(tmp_path, town_scenario):
    seed = _short(town_scenario, failure="raise", at=0.5)
    cfg = FuzzConfig(cycles=1, population=1, shrink=0, reproduce=0, ads=seed.ads)
    campaign = Campaign(tmp_path / "out", [seed], cfg)
    (f,) = campaign.run()
    assert f.path.parent.name == "findings" and f.misbehavior.oracle == PLUGIN_ERROR and campaign.errors == []
    verdict = json.loads((f.path / "verdict.json").read_text())
    assert verdict["error"]["plugin"] == ADS_PLUGIN and verdict["signature"]["fault"] == "ego"
    assert {(fault, error) for _, _, fault, _, error in _index(tmp_path / "out")} == {("ego", None)}


def test_the_cli_counts_an_oracle_error_as_the_tool_failing_not_as_a_finding(tmp_path, town_scenario,
                                                                              failing_oracle):
    seeds = tmp_path / "seeds"
    write_scenario(_short(town_scenario), seeds / "000")
    result = CliRunner().invoke(main, ["fuzz", town_scenario.network, "--seeds", str(seeds), "-o", str(tmp_path / "o"),
                                       "--cycles", "1", "--population", "1", "--shrink", "0"])
    assert result.exit_code == 3, result.output  # the tool failed; nothing was found
    assert "0 finding(s)" in result.output and "errors of the tool, not findings of the ADS" in result.output
    assert "oracle-plugin" in result.output and "drivefuzz replay" in result.output
    rows = CliRunner().invoke(main, ["findings", str(tmp_path / "o"), "--json"])
    assert rows.exit_code == 0 and json.loads(rows.output) == [], rows.output
    rows = CliRunner().invoke(main, ["findings", str(tmp_path / "o"), "--errors", "--json"])
    assert [(r["folder"].split("/")[0], r["fault"]) for r in json.loads(rows.output)] == [("errors", ORACLE_FAULT)]
    report = CliRunner().invoke(main, ["report", str(tmp_path / "o")])
    assert report.exit_code == 0, report.output
    md = (tmp_path / "o" / "report.md").read_text()
    assert "0 finding(s)" in md and "## Errors of the tool (not findings of the ADS)" in md and ORACLE_FAULT in md


def test_a_crash_or_hang_is_blamed_on_the_plugin_whose_code_was_running(town_scenario, failing_oracle):
    settings = OracleSettings(settings={"failing_oracle": {"failure": "abort"}}).settings
    with SimHost(timeout_s=3.0) as host:
        out = host.execute(_short(town_scenario), settings)
        assert out.status == CRASH and out.plugin == ORACLE_PLUGIN and out.fault == ORACLE_FAULT, out
        assert f"{MODULE}.py" in out.traceback and "in on_frame" in out.traceback
        quiet = {"failing_oracle": {"failure": "none"}}
        out = host.execute(_short(town_scenario, failure="abort", at=0.5), quiet)
        assert out.status == CRASH and out.plugin == ADS_PLUGIN and out.fault == "ego", out
        out = host.execute(_short(town_scenario, failure="hang", at=0.5), quiet)
        assert out.status == HANG and out.plugin == ADS_PLUGIN and out.fault == "ego", out
        assert "crashy_plugins.py" in out.traceback and "in ads_step" in out.traceback
        out = host.execute(_short(town_scenario), {"failing_oracle": {"failure": "hang"}})
        assert out.status == HANG and out.fault == ORACLE_FAULT, out
        assert host.execute(_short(town_scenario), quiet).status == OK


def test_sumo_refusing_its_input_is_an_error_of_the_tool(tmp_path, town_scenario):
    net = tmp_path / "town.net.xml"
    net.write_text((town_scenario.network_path()).read_text())
    sc = _short(town_scenario).model_copy(update={"network": str(net)})
    net.write_text("<net>cut short")  # after the scenario was made: the host's SUMO cannot load it
    with SimHost(timeout_s=60) as host:
        out = host.execute(sc)
    assert out.status == INTERNAL_ERROR and out.fault == TOOL_FAULT, out


def _dump(*frames: tuple[str, str]) -> str:
    lines = [f'  File "{path}", line {10 + i} in {func}' for i, (path, func) in enumerate(frames)]
    return "Fatal Python error: Segmentation fault\n\nCurrent thread 0x1 (most recent call first):\n" + "\n".join(lines)


def test_blame_stack_reads_who_was_running():
    import drivefuzz

    execute_py = drivefuzz.__file__.replace("__init__.py", "sim/execute.py")
    serve = (drivefuzz.__file__.replace("__init__.py", "sim/simhost.py"), "_serve")
    sumo = _dump(("/site-packages/libsumo/libsumo.py", "simulationStep"), (execute_py, "step_sumo"), serve)
    assert blame_stack(sumo) == NO_PLUGIN and failure_fault(CRASH, NO_PLUGIN) == TOOL_FAULT
    assert failure_fault(HANG, NO_PLUGIN) == TOOL_FAULT  # SUMO hung
    assert blame_stack(_dump(("/x/ego/ads.py", "done"), (execute_py, "run_oracles"), serve)) == ADS_PLUGIN
    assert blame_stack(_dump(("/x/oracles/mine.py", "on_frame"), (execute_py, "run_oracles"), serve)) == ORACLE_PLUGIN
    assert blame_stack(_dump(("/x/oracles/mine.py", "on_end"), (execute_py, "finish"), serve)) == ORACLE_PLUGIN
    assert blame_stack("") == "" and failure_fault(CRASH) == TOOL_FAULT and failure_fault(HANG) == "ego"
    assert failure_fault(INTERNAL_ERROR) == TOOL_FAULT and failure_fault(PLUGIN_ERROR) == TOOL_FAULT
