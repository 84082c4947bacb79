"""The real distributed path: Dask schedulers and workers as OS processes on 127.0.0.1, one killed mid-job.

Each test starts its own processes in their own sessions and kills every one of
them at the end. What must hold after a worker is SIGKILLed in the middle of a
seed job: the campaign completes, the interrupted job resumes from its journal
(not from scratch), no execution is indexed twice and no finding is lost.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.scenario import AdsSpec, SimOptions
from drivefuzz.scenario.sumofiles import write_scenario

from conftest import ROOT, TOWN

pytestmark = pytest.mark.timeout(240)
DASK = str(Path(sys.executable).parent / "dask")


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "tests"), env.get("PYTHONPATH", "")])
    env["DASK_DISTRIBUTED__SCHEDULER__WORKER_SATURATION"] = "1.0"
    return env


class Processes:
    """Processes started in their own session; all of them are killed, with their children, at the end."""

    def __init__(self):
        self.procs: list[subprocess.Popen] = []

    def start(self, args, **kw) -> subprocess.Popen:
        p = subprocess.Popen(args, start_new_session=True, env=_env(), stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, **kw)
        self.procs.append(p)
        return p

    def close(self) -> None:
        for p in self.procs:
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + 10
        for p in self.procs:
            try:
                p.wait(max(deadline - time.monotonic(), 0.1))
            except subprocess.TimeoutExpired:
                pass
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            p.wait()


@pytest.fixture
def procs():
    p = Processes()
    yield p
    p.close()


def _seeds(town_scenario, n):
    # different start positions make different seeds; speeding makes every execution a (short) finding
    return [town_scenario.model_copy(update={
        "mission": town_scenario.mission.model_copy(update={"start_pos": 5.0 + 5 * i}),
        "sim": SimOptions(time_limit=20.0)}) for i in range(n)]


CFG = dict(cycles=3, population=3, continue_after_finding=True,
           ads=AdsSpec(name="ego", options={"fault": "speeding"}))


def _journal(out: Path, si: int) -> list[dict]:
    path = out / "jobs" / f"{si:03d}" / "journal.jsonl"
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.endswith("}")]


def _kill_worker_mid_job(out: Path, si: int, done_before: int = 2, timeout: float = 120.0) -> int:
    """Once job ``si`` has finished ``done_before`` executions, SIGKILL the worker running it; return its pid."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        recs = _journal(out, si)
        if sum(r["event"] == "end" for r in recs) >= done_before:
            pid = [r for r in recs if r["event"] == "attempt"][-1]["pid"]
            os.kill(pid, signal.SIGKILL)
            return pid
        time.sleep(0.02)
    raise AssertionError(f"job {si} never reached {done_before} executions")


def _check_complete(out: Path, n_seeds: int, killed_pid: int, killed_job: int) -> None:
    execs_per_job = 1 + CFG["cycles"] * CFG["population"]  # the seed's own run, then one lineage
    for si in range(n_seeds):
        summary = json.loads((out / "jobs" / f"{si:03d}" / "summary.json").read_text())
        assert summary["status"] == "done" and summary["execs"] == execs_per_job
    attempts = [r for r in _journal(out, killed_job) if r["event"] == "attempt"]
    assert len(attempts) == 2 and attempts[0]["pid"] == killed_pid != attempts[1]["pid"]
    assert attempts[1]["resumed_from"] >= 2  # continued from its journal, not from scratch
    db = sqlite3.connect(out / "index.sqlite")
    keys = [k for (k,) in db.execute("SELECT key FROM executions")]
    assert len(keys) == len(set(keys)) == n_seeds * execs_per_job
    indexed = {f for (f,) in db.execute("SELECT finding FROM executions WHERE finding IS NOT NULL")}
    on_disk = {f"findings/{p.name}" for p in (out / "findings").iterdir() if not p.name.startswith(".")}
    assert indexed == on_disk  # every finding the index names is on disk, and no folder is unindexed
    # the speeding fault makes nearly every execution a speeding finding, one signature; a mutant may add another
    # (an immobile car ahead: the ego stays behind it), which the index must name as well
    (rel,) = [f for f in on_disk if f.endswith("-speeding")]
    assert (out / rel / "verdict.json").exists() and (out / rel / "routes.rou.xml").exists()
    hits = json.loads((out / rel / "hits.json").read_text())
    speeding = [k for (k,) in db.execute("SELECT key FROM executions WHERE finding = ?", (rel,))]
    assert sorted(hits["executions"]) == sorted(speeding) and hits["count"] > n_seeds * execs_per_job // 2
    # every finding's hits are exactly the executions the index files under it: none lost or counted twice by the
    # killed worker's job (which mutants add a second signature depends on the mutator, not on the kill)
    for f in on_disk:
        rows = sorted(k for (k,) in db.execute("SELECT key FROM executions WHERE finding = ?", (f,)))
        assert sorted(json.loads((out / f / "hits.json").read_text())["executions"]) == rows


def test_scheduler_and_two_workers_survive_a_killed_worker(tmp_path, town_scenario, procs):
    from distributed import Client

    sched_file = tmp_path / "scheduler.json"
    procs.start([DASK, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                 "--scheduler-file", str(sched_file)])
    for _ in range(2):
        procs.start([DASK, "worker", "--scheduler-file", str(sched_file), "--nthreads", "1", "--host", "127.0.0.1",
                     "--no-dashboard", "--death-timeout", "30"])
    t_end = time.monotonic() + 60
    while not sched_file.exists() and time.monotonic() < t_end:
        time.sleep(0.1)
    out = tmp_path / "out"
    with Client(scheduler_file=str(sched_file), timeout="30s") as client:
        client.wait_for_workers(2, timeout=60)
        campaign = Campaign(out, _seeds(town_scenario, 3), FuzzConfig(**CFG))
        result: dict = {}
        runner = threading.Thread(target=lambda: result.setdefault("findings", campaign.run(client=client)))
        runner.start()
        killed = _kill_worker_mid_job(out, 0)
        runner.join(180)
        assert not runner.is_alive()
    _check_complete(out, 3, killed, 0)
    # one record per signature: the executions found speeding again and again, hits of one finding
    found = result["findings"]
    db = sqlite3.connect(out / "index.sqlite")
    (with_finding,) = db.execute("SELECT COUNT(*) FROM executions WHERE finding IS NOT NULL").fetchone()
    assert found and sum(f.hits for f in found) == with_finding >= 26 and not campaign.failed_jobs


def test_local_cluster_jobs_2_survives_a_killed_worker(tmp_path, town_scenario, procs):
    seeds = tmp_path / "seeds"
    for i, sc in enumerate(_seeds(town_scenario, 2)):
        write_scenario(sc, seeds / f"{i:03d}")
    out = tmp_path / "out"
    cli = procs.start([sys.executable, "-m", "drivefuzz.cli", "fuzz", str(TOWN), "--seeds", str(seeds), "-o", str(out),
                       "--jobs", "2", "--cycles", "3", "--population", "3", "--continue-after-finding",
                       "--ads-option", "fault=speeding"])
    killed = _kill_worker_mid_job(out, 1)
    assert cli.wait(180) == 1  # findings were made
    _check_complete(out, 2, killed, 1)
    pids = {r["pid"] for si in range(2) for r in _journal(out, si) if r["event"] == "end"}
    assert len(pids) >= 2  # the jobs really ran in separate worker processes


def test_crashing_simulations_leave_the_dask_worker_alive(tmp_path, town_scenario):
    from drivefuzz.campaign.cluster import dask_client

    seeds = [sc.model_copy(update={"sim": SimOptions(time_limit=5.0)}) for sc in _seeds(town_scenario, 2)]
    cfg = FuzzConfig(cycles=1, population=2, continue_after_finding=True,
                     ads=AdsSpec(name="crashy_plugins:FailingADS", options={"failure": "abort", "at": 0.3}))
    with dask_client("local", jobs=2) as client:
        findings = Campaign(tmp_path / "out", seeds, cfg).run(client=client)
        worker_pids = set(client.run(os.getpid).values())
    # every one of the 6 executions crashed (the seeds' own runs too): one finding, hit 6 times
    assert [(f.misbehavior.oracle, f.hits) for f in findings] == [("simulator-crash", 6)]
    job_pids = {r["pid"] for si in range(2) for r in _journal(tmp_path / "out", si) if r["event"] == "attempt"}
    assert job_pids <= worker_pids  # the same workers ran the jobs and are still there: no worker died


def test_ctrl_c_to_the_whole_terminal_group_stops_jobs_2_cleanly(tmp_path, town_scenario, procs):
    """A terminal's Ctrl-C reaches the local workers too: they must survive it and the campaign stop cleanly."""
    seeds = tmp_path / "seeds"
    for i, sc in enumerate(_seeds(town_scenario, 2)):
        write_scenario(sc, seeds / f"{i:03d}")
    out = tmp_path / "out"
    cli = subprocess.Popen([sys.executable, "-m", "drivefuzz.cli", "fuzz", str(TOWN), "--seeds", str(seeds),
                            "-o", str(out), "--jobs", "2", "--cycles", "30", "--population", "3",
                            # a budget: without one each seed runs one lineage, which may end (and the campaign
                            # with it, nothing left to resume) before the Ctrl-C lands
                            "--budget", "10m", "--continue-after-finding", "--ads-option", "fault=speeding"],
                           start_new_session=True, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    procs.procs.append(cli)
    t_end = time.monotonic() + 120
    while sum(r["event"] == "end" for si in range(2) for r in _journal(out, si)) < 3:
        assert time.monotonic() < t_end and cli.poll() is None
        time.sleep(0.05)
    os.killpg(cli.pid, signal.SIGINT)  # what a terminal does: the client, its local cluster and its workers
    stdout, stderr = cli.communicate(timeout=60)
    assert cli.returncode == 1, stderr  # stopped with its (speeding) findings, not aborted
    assert "continue with: drivefuzz fuzz --resume" in stderr and "Traceback" not in stderr, stderr
    ended = [r for si in range(2) for r in _journal(out, si) if r["event"] == "end"]
    assert 3 <= len(ended) < 180
    rows = sqlite3.connect(out / "index.sqlite").execute("SELECT COUNT(*) FROM executions").fetchone()[0]
    assert rows == len(ended)  # everything journalled is indexed
    assert f"{len(ended)} executions" in stdout


def test_max_execs_is_exact_with_parallel_jobs(tmp_path, town_scenario):
    from drivefuzz.campaign.cluster import dask_client

    cfg = FuzzConfig(max_execs=3, **CFG)
    with dask_client("local", jobs=2) as client:
        Campaign(tmp_path / "out", _seeds(town_scenario, 2), cfg).run(client=client)
    ended = [r for si in range(2) for r in _journal(tmp_path / "out", si) if r["event"] == "end"]
    assert len(ended) == 3
