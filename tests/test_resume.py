"""`drivefuzz fuzz` killed (SIGKILL) or interrupted (Ctrl-C) mid-campaign, then `--resume`d: nothing lost or repeated."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time

import pytest

from drivefuzz.scenario import SimOptions
from drivefuzz.scenario.sumofiles import write_scenario

from conftest import ROOT, TOWN

pytestmark = pytest.mark.timeout(240)
ARGS = ["--cycles", "3", "--population", "3", "--continue-after-finding", "--ads-option", "fault=speeding", "--seed", "3"]


def _cli(*args, **kw) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-m", "drivefuzz.cli", *args], env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def _ends(out) -> list[dict]:
    path = out / "jobs" / "000" / "journal.jsonl"
    if not path.exists():
        return []
    recs = [json.loads(line) for line in path.read_text().splitlines() if line.endswith("}")]
    return [r for r in recs if r["event"] == "end"]


def _wait_for(out, n: int, proc: subprocess.Popen) -> None:
    t_end = time.monotonic() + 120
    while len(_ends(out)) < n:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < t_end
        time.sleep(0.02)


@pytest.fixture
def seeds(tmp_path, town_scenario):
    folder = tmp_path / "seeds"
    write_scenario(town_scenario.model_copy(update={"sim": SimOptions(time_limit=25.0)}), folder / "000")
    return folder


def _reference(tmp_path, seeds):
    ref = tmp_path / "ref"
    p = _cli("fuzz", str(TOWN), "--seeds", str(seeds), "-o", str(ref), *ARGS)
    assert p.wait(120) == 1, p.communicate()
    return ref


def _same_as_reference(out, ref) -> None:
    got, want = _ends(out), _ends(ref)
    assert [r["key"] for r in got] == [r["key"] for r in want]  # no execution repeated or skipped
    assert [(r["hash"], r["verdict"]) for r in got] == [(r["hash"], r["verdict"]) for r in want]
    assert sorted(p.name for p in (out / "findings").iterdir()) == sorted(p.name for p in (ref / "findings").iterdir())
    rows = sqlite3.connect(out / "index.sqlite").execute("SELECT COUNT(*), COUNT(DISTINCT key) FROM executions").fetchone()
    assert rows == (10, 10)  # the seed's own run, then 3 cycles of 3


def test_sigkill_then_resume_equals_an_uninterrupted_campaign(tmp_path, seeds):
    out = tmp_path / "out"
    p = _cli("fuzz", str(TOWN), "--seeds", str(seeds), "-o", str(out), *ARGS)
    _wait_for(out, 3, p)
    os.killpg(p.pid, signal.SIGKILL)  # the campaign and its simulation host, mid-execution
    p.wait()
    killed_at = len(_ends(out))
    assert 3 <= killed_at < 10
    r = _cli("fuzz", "--resume", str(out))
    stdout, stderr = r.communicate(timeout=120)
    assert r.returncode == 1, stderr
    assert "10 executions" in stdout and "finding(s)" in stdout
    _same_as_reference(out, _reference(tmp_path, seeds))


def test_ctrl_c_stops_cleanly_and_resume_finishes(tmp_path, seeds):
    out = tmp_path / "out"
    p = _cli("fuzz", str(TOWN), "--seeds", str(seeds), "-o", str(out), *ARGS)
    _wait_for(out, 2, p)
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=60)
    assert "stopped; continue with: drivefuzz fuzz --resume" in stderr, stderr
    assert "Traceback" not in stderr
    stopped_at = len(_ends(out))
    assert stopped_at < 10 and (out / "jobs" / "000" / "checkpoint.json").exists()
    # everything journalled is indexed and every finding is a complete directory
    assert sqlite3.connect(out / "index.sqlite").execute("SELECT COUNT(*) FROM executions").fetchone()[0] == stopped_at
    assert all((f / "verdict.json").exists() for f in (out / "findings").iterdir())
    r = _cli("fuzz", "--resume", str(out))
    r.communicate(timeout=120)
    _same_as_reference(out, _reference(tmp_path, seeds))


def test_resume_with_report_all_reproduces_incidents_from_then_on(tmp_path, seeds):
    """--report-all on a resume reaches the seed jobs (they read the manifest): incidents found from then on
    get their reproduction rates, as the findings they are now counted as."""
    out = tmp_path / "out"
    p = _cli("fuzz", str(TOWN), "--seeds", str(seeds), "-o", str(out), "--max-execs", "1", "--seed", "3")
    p.communicate(timeout=120)
    assert json.loads((out / "manifest.json").read_text())["config"]["reproduce_incidents"] is False
    p = _cli("fuzz", "--resume", str(out), "--max-execs", "1", "--report-all")
    p.communicate(timeout=120)
    assert p.returncode in (0, 1)
    assert json.loads((out / "manifest.json").read_text())["config"]["reproduce_incidents"] is True


def test_a_damaged_checkpoint_is_rebuilt_from_the_journal(tmp_path, seeds):
    """An empty, torn or foreign checkpoint.json (issue 30): the resume walks the schedule again from the journal,
    taking every finished execution's result from it, and ends as an uninterrupted campaign would."""
    import shutil

    partial = tmp_path / "partial"
    p = _cli("fuzz", str(TOWN), "--seeds", str(seeds), "-o", str(partial), *ARGS, "--max-execs", "5")
    p.communicate(timeout=120)
    assert len(_ends(partial)) == 5
    ref = _reference(tmp_path, seeds)
    for i, damage in enumerate([b"", b'{"schedule": ', b"\x00garbage\xff", b"[1, 2]", b'{"schedule": 5}']):
        out = tmp_path / f"out{i}"
        shutil.copytree(partial, out)
        (out / "jobs" / "000" / "checkpoint.json").write_bytes(damage)
        r = _cli("fuzz", "--resume", str(out))
        stdout, stderr = r.communicate(timeout=120)
        assert r.returncode == 1 and "Traceback" not in stderr, (damage, stderr)
        journal = (out / "jobs" / "000" / "journal.jsonl").read_text()
        assert '"event": "checkpoint-rebuilt"' in journal, damage
        starts = [json.loads(line)["key"] for line in journal.splitlines() if '"event": "start"' in line]
        assert len(starts) == len(set(starts)) == 10, damage  # nothing that had run was run again
        _same_as_reference(out, ref)


def test_a_resume_goes_on_with_the_round_robin_where_it_stopped(tmp_path, town_scenario):
    """Two seeds, one lineage of two members each turn: stopped by --max-execs while the second seed's turn has
    begun, a resume runs that turn first, then the first seed's next one, as one run without a stop does (it
    started with the first seed again, whose next lineage then took the budget the second seed's was due)."""
    from click.testing import CliRunner

    from drivefuzz.cli import main

    seeds = tmp_path / "seeds"
    for i in range(2):
        write_scenario(town_scenario.model_copy(update={"sim": SimOptions(time_limit=15.0)}), seeds / f"00{i}")
    args = ["--cycles", "1", "--population", "2", "--continue-after-finding", "--shrink", "0"]

    def fuzz(*more):
        r = CliRunner().invoke(main, ["fuzz", str(TOWN), "--seeds", str(seeds), *args, *more])
        assert r.exit_code in (0, 1), r.output

    def keys(out):
        return {json.loads(line)["key"] for path in (out / "jobs").glob("*/journal.jsonl")
                for line in path.read_text().splitlines() if '"event": "end"' in line}

    fuzz("-o", str(tmp_path / "a"), "--max-execs", "4")  # seed 0, its lineage (2), seed 1
    assert keys(tmp_path / "a") == {"0/seed", "0/0/0/0", "0/0/0/1", "1/seed"}
    fuzz("--resume", str(tmp_path / "a"), "--max-execs", "3")
    fuzz("-o", str(tmp_path / "b"), "--max-execs", "7")
    assert keys(tmp_path / "a") == keys(tmp_path / "b") == {"0/seed", "0/0/0/0", "0/0/0/1", "1/seed", "1/0/0/0",
                                                            "1/0/0/1", "0/1/0/0"}
    # each seed's run journals how far its ego drove (the mutator times aimed actors by it, on a resume too)
    seed_runs = [json.loads(line) for path in (tmp_path / "a" / "jobs").glob("*/journal.jsonl")
                 for line in path.read_text().splitlines() if '"key": "0/seed"' in line or '"key": "1/seed"' in line]
    travel = [r["ego_travel"] for r in seed_runs if r["event"] == "end"]
    assert len(travel) == 2 and all(t[0] == 0.0 and t[-1] > 50.0 and t == sorted(t) for t in travel)
