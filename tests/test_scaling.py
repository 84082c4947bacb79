"""What campaign scaling rests on (issue 34): the work each record stands for, journals fsync'd per checkpoint
rather than per record, local Dask workers warm and quiet before their first job. Real SUMO throughout."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from drivefuzz.campaign.fuzz import Campaign, FuzzConfig
from drivefuzz.scenario import AdsSpec, SimOptions

pytestmark = pytest.mark.timeout(240)

#: speeding makes every execution a finding: the first of its signature is triaged (careful driver, reproduction,
#: shrinking), the rest are hits of it
CFG = dict(cycles=2, population=3, continue_after_finding=True, shrink=2, reproduce=2,
           ads=AdsSpec(name="ego", options={"fault": "speeding"}))


def _seeds(town_scenario, n):
    return [town_scenario.model_copy(update={
        "mission": town_scenario.mission.model_copy(update={"start_pos": 5.0 + 5 * i}),
        "sim": SimOptions(time_limit=20.0)}) for i in range(n)]


def _ends(out: Path) -> list[dict]:
    recs = []
    for path in sorted((out / "jobs").glob("*/journal.jsonl")):
        recs += [r for r in map(json.loads, path.read_text().splitlines()) if r["event"] == "end"]
    return recs


def test_records_count_their_triage_reruns_and_simulated_seconds(tmp_path, town_scenario):
    Campaign(tmp_path / "a", _seeds(town_scenario, 1), FuzzConfig(**CFG)).run()
    ends = _ends(tmp_path / "a")
    assert len(ends) == 1 + CFG["cycles"] * CFG["population"]
    new = [r for r in ends if r.get("triage_execs")]
    # each signature is triaged once, at its first execution: speeding's (every execution speeds), and any other a
    # mutant adds (an immobile car ahead the ego stays behind, for one)
    assert len({r["finding"] for r in new}) == len(new) >= 1
    assert [r["finding"].endswith("-speeding") for r in new].count(True) == 1
    for first in new:
        verdict = json.loads((tmp_path / "a" / first["finding"] / "verdict.json").read_text())
        shrink_runs = (verdict.get("shrink") or {}).get("runs", 0)  # its candidates less those judged without a run
        # the execution, its counterfactual and reproduction reruns (triage_execs), and the shrinking runs
        assert first["runs"] == 1 + first["triage_execs"] + shrink_runs > 1 + CFG["reproduce"]
    step = town_scenario.sim.step_length
    for r in ends:
        if r not in new:
            assert r["runs"] == 1  # a hit of a known signature (or no finding) runs nothing more
            assert r["sim_s"] == pytest.approx(r["frames"] * step, abs=1e-3)
        assert r["sim_s"] >= r["frames"] * step - 1e-3 > 0
    # deterministic: the same campaign again counts the same work
    Campaign(tmp_path / "b", _seeds(town_scenario, 1), FuzzConfig(**CFG)).run()
    again = {r["key"]: (r["runs"], r["sim_s"]) for r in _ends(tmp_path / "b")}
    assert again == {r["key"]: (r["runs"], r["sim_s"]) for r in ends}


def test_journal_is_fsynced_before_each_checkpoint_not_per_record(tmp_path, town_scenario, monkeypatch):
    synced: list[str] = []
    real_fsync = os.fsync

    def spy(fd):  # the real fsync, and which file it was for
        synced.append(os.path.basename(os.readlink(f"/proc/self/fd/{fd}")) if os.path.exists("/proc/self/fd")
                      else "?")
        return real_fsync(fd)

    if not os.path.exists("/proc/self/fd"):
        pytest.skip("needs /proc to name an fd's file")
    monkeypatch.setattr(os, "fsync", spy)
    cfg = FuzzConfig(**{**CFG, "ads": AdsSpec(name="ego")})  # clean: no findings, only the search's files
    Campaign(tmp_path / "out", _seeds(town_scenario, 1), cfg).run()
    ends = _ends(tmp_path / "out")
    journal = [i for i, name in enumerate(synced) if name == "journal.jsonl"]
    checkpoints = [i for i, name in enumerate(synced) if name.startswith(".checkpoint.json")]
    assert checkpoints and len(journal) < len(ends)  # not once (or twice) per execution
    for c in checkpoints:  # the journal reached the disk just before every checkpoint
        assert c - 1 in journal
    # and the journal holds every record, in order
    lines = (tmp_path / "out" / "jobs" / "000" / "journal.jsonl").read_text().splitlines()
    records = [json.loads(line) for line in lines]
    assert [r["event"] for r in records][0] == "attempt" and sum(r["event"] == "start" for r in records) == len(ends)


def test_warm_worker_leaves_a_started_host_that_the_first_job_adopts(town_scenario):
    from drivefuzz.campaign import hosts
    from drivefuzz.sim.simhost import OK

    import threading

    got: dict = {}

    def in_a_new_thread():  # a thread of its own, as a Dask worker's task thread: no host of its own yet
        hosts.warm_worker()
        spare = hosts._SPARE[-1]
        got["alive"] = spare.proc is not None and spare.proc.poll() is None
        got["starts"] = spare.starts
        host = hosts._host_for_this_thread(60.0)
        got["adopted"] = host is spare
        got["status"] = host.execute(town_scenario.model_copy(update={"sim": SimOptions(time_limit=3.0)})).status
        got["restarted"] = host.starts != got["starts"]
        hosts._HOSTS.pop(threading.get_ident()).close()

    t = threading.Thread(target=in_a_new_thread)
    t.start()
    t.join(120)
    assert got == {"alive": True, "starts": 1, "adopted": True, "status": OK, "restarted": False}


def test_local_workers_are_warm_and_quiet_before_their_first_job():
    import dask

    from drivefuzz.campaign.cluster import DASK_SETTINGS, dask_client

    def state():
        import sys

        import dask as d

        from drivefuzz.campaign import hosts

        return {"spare": [h.proc.poll() is None for h in hosts._SPARE], "scipy": "scipy.signal" in sys.modules,
                **{k: d.config.get(k) for k in DASK_SETTINGS}}

    with dask_client("local", jobs=1) as client:
        (seen,) = client.run(state).values()
    assert seen == {"spare": [True], "scipy": True, **DASK_SETTINGS}
    assert dask.config.get("distributed.worker.profile.enabled") is True  # set for the cluster only


def test_status_coverage_reads_only_new_records_and_agrees_with_a_full_read(tmp_path):
    """The status screen's coverage figure is kept up incrementally; it must equal the union over all records."""
    import random
    from types import SimpleNamespace

    from drivefuzz.campaign import status
    from drivefuzz.triage.coverage import JournalCells

    rng = random.Random(5)
    cells = [f"cell-{i}" for i in range(60)]
    offered = set(cells[::2])
    campaign = SimpleNamespace(out=tmp_path, seeds=[])
    status._COVERAGE[id(campaign)] = (campaign, JournalCells(tmp_path), offered, set())
    try:
        for _ in range(25):
            for si in range(3):
                path = tmp_path / "jobs" / f"{si:03d}" / "journal.jsonl"
                path.parent.mkdir(parents=True, exist_ok=True)
                with open(path, "a") as fh:
                    for _ in range(rng.randint(0, 3)):  # keys repeat: a re-run job journals an execution twice
                        fh.write(json.dumps({"event": "end", "key": f"{si}/{rng.randint(0, 30)}",
                                             "cells": rng.sample(cells, 2)}) + "\n")
            full = JournalCells(tmp_path)
            full.update()
            want = len(full.reached() & offered)
            assert status._coverage([campaign]) == f"{want}/{len(offered)} cells ({100.0 * want / len(offered):.0f} %)"
        assert 0 < want < len(offered)
    finally:
        status._COVERAGE.pop(id(campaign), None)
