"""Crash isolation: a simulation that aborts, hangs or whose plugin raises becomes a finding, and work goes on."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest
from click.testing import CliRunner

from drivefuzz.cli import main
from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.scenario import AdsSpec, SimOptions
from drivefuzz.sim.simhost import CRASH, HANG, OK, PLUGIN_ERROR, SimHost
from drivefuzz.scenario.sumofiles import write_scenario

FAILING = "crashy_plugins:FailingADS"


def _with_ads(sc, time_limit=10.0, **options):
    return sc.model_copy(update={"ads": AdsSpec(name=FAILING, options=options),
                                 "sim": SimOptions(time_limit=time_limit)})


def test_abort_in_the_simulation_is_a_crash_and_the_host_restarts(town_scenario):
    with SimHost(timeout_s=60) as host:
        out = host.execute(_with_ads(town_scenario, failure="abort", at=0.5))
        assert out.status == CRASH and out.error_type == "SIGABRT", out
        again = host.execute(_with_ads(town_scenario, failure="none"))
        assert again.status == OK and again.execution.trace.n_frames > 100
        assert host.starts == 2


def test_hang_is_killed_at_the_wall_clock_limit(town_scenario):
    with SimHost(timeout_s=3.0) as host:
        out = host.execute(_with_ads(town_scenario, failure="hang", at=0.5))
        assert out.status == HANG and 3.0 <= out.wall_time < 10.0
        assert host.proc is None  # killed, restarted on the next execution


def test_exception_in_an_ads_plugin_is_a_plugin_error(town_scenario):
    with SimHost(timeout_s=60) as host:
        out = host.execute(_with_ads(town_scenario, failure="raise", at=0.5))
    assert out.status == PLUGIN_ERROR and out.error_type == "ZeroDivisionError", out
    assert "planned failure" in out.detail


def test_a_plugin_writing_to_stdout_does_not_disturb_the_host(town_scenario):
    with SimHost(timeout_s=60) as host:
        out = host.execute(_with_ads(town_scenario, failure="stdout", at=0.5))
    assert out.status == OK and out.execution.termination.value == "time_limit", out  # ran all 10 s


def test_sys_exit_in_a_plugin_is_a_plugin_error(town_scenario):
    with SimHost(timeout_s=60) as host:
        out = host.execute(_with_ads(town_scenario, failure="exit", at=0.5))
        assert out.status == PLUGIN_ERROR and out.error_type == "SystemExit", out
        assert host.execute(_with_ads(town_scenario, failure="none")).status == OK  # the host lived on


def test_the_host_dies_with_its_parent_even_while_holding_the_gil(tmp_path, town_scenario):
    folder = tmp_path / "s"
    write_scenario(_with_ads(town_scenario, failure="spin", at=0.5), folder)
    script = (
        "import sys\n"
        "from drivefuzz.sim.simhost import SimHost\n"
        "from drivefuzz.scenario.sumofiles import load_scenario\n"
        f"sc = load_scenario({str(folder)!r})\n"
        "h = SimHost(timeout_s=None)\n"
        "h._start()\n"
        "print(h.proc.pid, flush=True)\n"
        "h.execute(sc)\n"
    )
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, env=env)
    child = int(parent.stdout.readline())
    time.sleep(2.0)  # the child is spinning in sum(range(...)) by now
    parent.kill()
    parent.wait()
    t_end = time.monotonic() + 5
    while _alive(child) and time.monotonic() < t_end:
        time.sleep(0.05)
    assert not _alive(child)


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split()[2] != "Z"
    except FileNotFoundError:
        return False


def test_campaign_records_crash_findings_and_goes_on(tmp_path, town_scenario):
    seed = _with_ads(town_scenario, failure="abort", at=0.5)
    cfg = FuzzConfig(cycles=1, population=2, ads=seed.ads)
    campaign = Campaign(tmp_path / "out", [seed, seed], cfg)
    findings = campaign.run()
    # every execution of both seed jobs crashed (the first job's crash did not end the campaign): one finding
    # (one signature), hit by all 6 (each seed's own run and a cycle of 2)
    assert [f.misbehavior.oracle for f in findings] == [CRASH] and campaign.progress.execs == 6
    hits = json.loads((findings[0].path / "hits.json").read_text())
    assert hits["count"] == findings[0].hits == 6 and {k.split("/")[0] for k in hits["executions"]} == {"0", "1"}
    f = findings[0].path
    verdict = json.loads((f / "verdict.json").read_text())
    assert verdict["error"]["type"] == "SIGABRT" and (f / "routes.rou.xml").exists() and (f / "replay.sh").exists()
    result = CliRunner().invoke(main, ["replay", str(f)])  # an ADS that is not installed: not imported
    assert result.exit_code == 2 and f"--ads {FAILING} to trust it" in result.output, result.output
    result = CliRunner().invoke(main, ["replay", str(f), "--ads", FAILING])
    assert result.exit_code == 0 and "reproduced: simulator-crash" in result.output, result.output


@pytest.mark.parametrize("failure, kind", [("none", None), ("hang", HANG)])
def test_cli_campaign_with_exec_timeout(tmp_path, town_scenario, failure, kind):
    seeds = tmp_path / "seeds"
    write_scenario(_with_ads(town_scenario, 60.0, failure=failure, at=0.5), seeds / "000")
    result = CliRunner().invoke(main, ["fuzz", town_scenario.network, "--seeds", str(seeds), "-o", str(tmp_path / "o"),
                                       "--ads", FAILING, "--ads-option", f"failure={failure}", "--ads-option", "at=0.5",
                                       "--cycles", "1", "--population", "1", "--exec-timeout", "3"])
    if kind is None:  # a normal run (about 1 s here) is not mistaken for a hang
        assert result.exit_code == 0 and "0 finding(s)" in result.output, result.output
    else:
        assert result.exit_code == 1 and f"{kind}/timeout" in result.output, result.output


def test_the_host_does_not_import_from_the_current_folder(tmp_path, town_scenario, monkeypatch):
    """A shapely.py where drivefuzz starts (a downloaded finding's folder) must not run in the host."""
    marker = tmp_path / "marker"
    (tmp_path / "shapely.py").write_text(f"open({str(marker)!r}, 'w').write('ran')\n")
    monkeypatch.chdir(tmp_path)
    with SimHost(timeout_s=60) as host:
        out = host.execute(town_scenario.model_copy(update={"sim": SimOptions(time_limit=1.0)}))
    assert out.status == OK, out
    assert not marker.exists()


def test_a_crashed_host_leaves_no_temporary_folder(town_scenario):
    import glob
    import tempfile

    def leftovers():  # this process's hosts only: other test workers start hosts of their own meanwhile
        return set(glob.glob(os.path.join(tempfile.gettempdir(), f"drivefuzz-host-{os.getpid()}-*")))

    before = leftovers()
    with SimHost(timeout_s=60) as host:
        out = host.execute(_with_ads(town_scenario, failure="abort", at=0.5))
        assert out.status == CRASH
        assert host._tmp is None  # removed with the dead child
        mine = leftovers() - before
    assert not mine


def test_the_host_imports_the_drivefuzz_of_its_parent_also_from_the_current_folder(monkeypatch):
    """The current folder is left off the host's import path; a checkout that is the current folder (a tool run
    in a second worktree while another drivefuzz is installed) must still be what the host imports."""
    import drivefuzz
    from drivefuzz.sim import simhost

    root = os.path.dirname(os.path.dirname(os.path.abspath(drivefuzz.__file__)))
    monkeypatch.chdir(root)
    monkeypatch.delenv("PYTHONPATH", raising=False)
    path = SimHost._pythonpath()
    assert path.split(os.pathsep)[0] == root
    probe = simhost._BOOTSTRAP.replace("from drivefuzz.sim.simhost import _serve; _serve()",
                                       "import drivefuzz; print(drivefuzz.__file__)")
    assert probe != simhost._BOOTSTRAP
    out = subprocess.run([sys.executable, "-I", "-c", probe], capture_output=True, text=True, cwd=root,
                         env={**os.environ, simhost.PATH_ENV: path}, check=True).stdout.strip()
    assert os.path.abspath(out) == os.path.abspath(drivefuzz.__file__)
