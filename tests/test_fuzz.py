"""End to end: short campaigns on real SUMO find real misbehaviour, replay it, and resume after a stop."""

from __future__ import annotations

import json
import sqlite3

from click.testing import CliRunner

from drivefuzz.cli import main
from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.scenario import AdsSpec, SimOptions


def _ended(out, records=False):
    """The finished executions of seed job 0, in journal order."""
    recs = [json.loads(line) for line in (out / "jobs" / "000" / "journal.jsonl").read_text().splitlines()]
    recs = [r for r in recs if r["event"] == "end"]
    return recs if records else [r["key"] for r in recs]


def test_faulty_ads_is_found_and_the_finding_replays(tmp_path, town_scenario):
    seed = town_scenario.model_copy(update={"sim": SimOptions(time_limit=40.0)})
    cfg = FuzzConfig(cycles=2, population=2, max_execs=4, ads=AdsSpec(name="ego", options={"fault": "speeding"}))
    findings = Campaign(tmp_path / "out", [seed], cfg).run()
    assert findings and findings[0].misbehavior.oracle == "speeding"
    f = findings[0].path
    for name in ("scenario.json", "routes.rou.xml", "fuzz.add.xml", "verdict.json", "replay.sh", "trace/ego.parquet"):
        assert (f / name).exists(), name
    result = CliRunner().invoke(main, ["replay", str(f)])
    assert result.exit_code == 0, result.output
    assert "reproduced: speeding" in result.output
    rows = sqlite3.connect(tmp_path / "out" / "index.sqlite").execute("SELECT verdict, finding FROM executions").fetchall()
    assert ("speeding/speeding", str(f.relative_to(tmp_path / "out"))) in rows


def test_resume_continues_without_losing_or_repeating(tmp_path, town_scenario):
    seed = town_scenario.model_copy(update={"sim": SimOptions(time_limit=20.0)})
    out = tmp_path / "out"
    cfg0 = dict(cycles=3, population=2, seed=5, continue_after_finding=True)
    first = Campaign(out, [seed], FuzzConfig(max_execs=3, **cfg0)).run()
    keys_first = _ended(out)
    assert len(keys_first) == 3
    from drivefuzz.campaign.fuzz import load_campaign

    seeds, cfg, _ = load_campaign(out)
    cfg.max_execs = 3  # a resume is a new run with a budget of its own
    Campaign(out, seeds, cfg).run(resume=True)
    keys = _ended(out)
    assert keys[:3] == keys_first and len(keys) == len(set(keys)) == 6
    # the same campaign in one go gives the same executions
    findings = sorted(p.name for p in (out / "findings").iterdir())
    assert len(findings) == len({n.split("-", 1)[0] for n in findings})  # no signature saved twice
    assert set(f.path.name for f in first) <= set(findings)  # none lost
    Campaign(tmp_path / "again", [seed], FuzzConfig(max_execs=6, **cfg0)).run()
    again = _ended(tmp_path / "again", records=True)
    resumed = _ended(out, records=True)
    assert [r["hash"] for r in again] == [r["hash"] for r in resumed]
    assert [r["score"] for r in again] == [r["score"] for r in resumed]


def test_an_attempt_that_lost_ownership_of_its_job_stops(tmp_path, town_scenario):
    """A job re-submitted elsewhere (its old client died) takes over; the old attempt stops at its next execution."""
    from drivefuzz.campaign.job import SeedJob

    seed = town_scenario.model_copy(update={"sim": SimOptions(time_limit=10.0)})
    out = tmp_path / "out"
    cfg = FuzzConfig(cycles=2, population=2, continue_after_finding=True, max_execs=1)
    Campaign(out, [seed], cfg).run()
    cfg.max_execs = None
    Campaign(out, [seed], cfg).prepare(resume=True)  # a new run, as a client would start it
    job = SeedJob(out, 0)
    calls = []

    def newer_attempt_takes_over():
        calls.append(1)
        if len(calls) == 2:  # call 1 is the check at the job's start, call 2 the one before its next execution
            (out / "jobs" / "000" / "owner").write_text("another-host:1:abc")
        return False

    summary = job.run(stop=newer_attempt_takes_over)
    assert summary["status"] == "superseded" and not (out / "jobs" / "000" / "summary.json").exists()
    assert len(_ended(out)) == 2  # it finished the execution it had started, and no other


def test_a_finding_replays_wherever_it_is_copied(tmp_path, town_scenario, monkeypatch):
    """The finding carries its network (checked by content hash): copied to another folder, with the network
    it was made on gone, it still replays; a changed network copy is refused with one line."""
    import shutil

    net = tmp_path / "maps" / "mytown.net.xml"
    net.parent.mkdir()
    shutil.copyfile(town_scenario.network, net)
    seed = town_scenario.model_copy(update={"network": str(net), "sim": SimOptions(time_limit=40.0)})
    cfg = FuzzConfig(cycles=2, population=2, max_execs=4, ads=AdsSpec(name="ego", options={"fault": "speeding"}))
    (found, *_rest) = Campaign(tmp_path / "out", [seed], cfg).run()
    manifest = json.loads((found.path / "scenario.json").read_text())
    assert manifest["network"] == "mytown.net.xml" and len(manifest["network_sha256"]) == 64
    elsewhere = tmp_path / "elsewhere" / "bug"
    shutil.copytree(found.path, elsewhere)
    shutil.rmtree(tmp_path / "maps")
    shutil.rmtree(tmp_path / "out")
    monkeypatch.chdir(tmp_path / "elsewhere")
    result = CliRunner().invoke(main, ["replay", "bug"])
    assert result.exit_code == 0, result.output
    assert "reproduced: speeding" in result.output
    copy = elsewhere / "mytown.net.xml"
    copy.write_text(copy.read_text().replace('speed="13.89"', 'speed="13.80"', 1))
    result = CliRunner().invoke(main, ["replay", "bug"])
    assert result.exit_code == 2
    assert "scenario.json" in result.output and "not the network this scenario was made on" in result.output
