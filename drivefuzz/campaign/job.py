"""One seed's fuzz campaign: the unit of work of a campaign, run one lineage (a *round*) at a time.

A job runs in the campaign's own process (``--jobs 1``) or in a Dask worker. It
is idempotent and resumable, and it persists everything itself, inside the
campaign directory, before it returns; its return value is only a small summary.
A worker that dies therefore loses at most the execution it was running, and
the job that Dask starts again elsewhere continues from its journal.

First the seed runs as it is: its risk is the baseline that every mutant's risk is measured against
(and a faulty ADS may already fail there). Then lineages, the paper's Algorithm 1 inside the schedule of
:mod:`drivefuzz.search.schedule`: each cycle, ``population`` members are made from the current scenario
(:meth:`drivefuzz.search.mutate.Mutator.successor`: a targeted move of the riskiest actor, or a new
component of their own from the catalogue or the strategy) and executed; the member with the highest
feedback value (risk by default; the paper's score, or a random member as the baseline) that found
nothing becomes the next current scenario and, when it raised the lineage's best, a corpus entry.
Oracles' reports go to :class:`drivefuzz.triage.store.FindingStore` (attribution, signature, one folder
per signature). A lineage ends after ``cycles`` cycles, after ``patience`` cycles without a new best,
or at a finding (unless ``continue_after_finding``); then :meth:`SeedJob.run` returns "yielded" and the
campaign gives the next seed its turn, until the budget is spent. Without a budget (or with
``single_pass``) each seed runs one lineage and its job is "done".

Determinism: every random draw comes from ``Random(f"{seed}/{seed_index}/{lineage}/{cycle}/{parent hash}/...")``,
so two configurations that choose different successors have different futures, and a job is a pure
function of its seed scenario, the configuration, the executions' results and (under guided feedback) what
the other jobs had reached when each of its lineages began, which its journal records; a resumed job re-creates
exactly the executions it had not finished. Run in turns (``--jobs 1``) the whole campaign is a pure function of
its seeds and configuration; on Dask what the other jobs had reached depends on their pace.

Files of job ``NNN`` (the seed index) under ``jobs/NNN/``::

    journal.jsonl     append-only: {"event": "start", key, pid} before an
                      execution (attributes a crash to its scenario), then
                      {"event": "end", ...the execution's record} after it; each record is
                      handed to the OS at once (a killed process loses none), and the file is
                      fsync'd before every checkpoint and at the end of a round, not per record
                      (two fsyncs per execution cost 5 % of a campaign's time): a power cut
                      loses at most the current cycle's records, whose executions a resume
                      runs again with the same results; under guided feedback, at the start of
                      each lineage after the first, {"event": "peers", lineage, cells, given_up}:
                      what the other jobs had reached and the cells they had given up aiming at
                      (campaign.aiming.PeerView), which a resume reads back
    checkpoint.json   the schedule (corpus, the current lineage) and the seed's baseline risk (atomic)
    summary.json      written last, when the job has finished its seed: the DONE marker
    owner             the attempt that owns the job: an older attempt that is still running
                      (its client died, or Dask lost touch with its worker) stops at its next execution

Budgets: ``--max-execs`` counts the executions of one run of the campaign (a resume
is a new run). Each execution first claims a ticket, a file ``budget/run<R>/<n>``
created with O_EXCL, so parallel jobs never run more than the budget between them.
Triage reruns (counterfactual, reproduction) are not search executions and take no ticket.

Findings go to ``findings/<signature>-<oracle>/``, incidents to ``incidents/...``, failed executions that are
not the ADS's fault (SUMO died, drivefuzz or an oracle plugin raised) to ``errors/...``, and successors to
``corpus/<hash>/``. A file ``STOP`` in the campaign directory makes every job return after its
current execution (the budget ran out, or the user pressed Ctrl-C).
"""

from __future__ import annotations

import functools
import json
import os
import random
import time
import uuid
from pathlib import Path
from typing import Any, Callable

from drivefuzz.campaign.aiming import (PeerView, aim_cells, cached_shares, can_aim, count_misses, seed_places,
                                      seed_reachable, shares_by_place)
from drivefuzz.campaign.config import FuzzConfig
from drivefuzz.campaign.hosts import Runner, warm_up
from drivefuzz.oracle import Misbehavior
from drivefuzz.storage import atomic_write_json, atomic_write_text
from drivefuzz.search.effect import effect_hash
from drivefuzz.search.schedule import GUIDED
from drivefuzz.triage.store import FindingStore, TriageConfig
from drivefuzz.scenario.sumofiles import load_scenario, write_scenario

STOP_FILE = "STOP"
#: the journal's record of what the other jobs had reached when a lineage began (:class:`PeerView`)
PEERS = "peers"
HANDED = "given_up"  #: the key of a peers record that lists the cells the other jobs gave up on
#: the campaign's cells shared among its seed jobs (campaign.aiming.share_cells), written by the first job
SHARES_FILE = "aim_shares.json"
#: Draws of a population member that repeats (in effect) an execution of its job, its parent or a sibling
#: before the member is skipped (it is not run: a repeat would only cost the time of an execution).
MAX_REDRAWS = 8


def job_dir(out: Path, seed_index: int) -> Path:
    return out / "jobs" / f"{seed_index:03d}"


def read_journal(path: Path) -> list[dict[str, Any]]:
    """Every complete record of a journal; a torn last line (a kill mid-write) is skipped."""
    if not path.exists():
        return []
    records = []
    for line in path.read_text().splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


def _append(path: Path, rec: dict[str, Any], after_kill: bool = False, sync: bool = False) -> None:
    """Append ``rec`` as one line; handed to the OS at once, on the disk at once only with ``sync``."""
    with open(path, "ab+") as fh:
        lead = b""
        if after_kill and fh.tell() > 0:  # a kill may have torn the last line: start on a line of our own
            fh.seek(-1, os.SEEK_END)
            lead = b"" if fh.read(1) == b"\n" else b"\n"
        fh.write(lead + json.dumps(rec, sort_keys=True).encode() + b"\n")
        fh.flush()
        if sync:
            os.fsync(fh.fileno())


def _sync(path: Path) -> None:
    """fsync a journal: what a checkpoint (or the campaign) relies on is on the disk before it."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class SeedJob:
    """The campaign of one seed inside the campaign directory ``out``."""

    def __init__(self, out: str | os.PathLike, seed_index: int):
        self.out = Path(out)
        self.si = seed_index
        self.dir = job_dir(self.out, seed_index)
        manifest = json.loads((self.out / "manifest.json").read_text())
        self.cfg = FuzzConfig.from_json(manifest["config"])
        self.run_id = manifest.get("run", 1)
        self._ticket = 0
        self.seed_refs: list[str] = manifest["seeds"]  # the campaign's seeds, in seed-index order
        self.seed = load_scenario(self.out / self.seed_refs[seed_index])
        self.journal = self.dir / "journal.jsonl"
        self.findings: list[str] = []
        self.views: dict[int, frozenset[str]] = {}  # per lineage: the other jobs' cells it aims past (PeerView)
        self.handed: dict[int, frozenset[str]] = {}  # per lineage: the cells the other jobs gave up on (PeerView)

    # ---------------------------------------------------------------- files
    def _owned(self) -> bool:
        try:
            return (self.dir / "owner").read_text() == self.token
        except FileNotFoundError:
            return False

    def _claim_ticket(self) -> bool:
        """Take one execution out of this run's --max-execs budget; False when it is spent."""
        limit = self.cfg.max_execs
        if limit is None:
            return True
        folder = self.out / "budget" / f"run{self.run_id}"
        folder.mkdir(parents=True, exist_ok=True)
        while self._ticket < limit:
            n, self._ticket = self._ticket, self._ticket + 1
            try:
                os.close(os.open(folder / f"{n:07d}", os.O_CREAT | os.O_EXCL | os.O_WRONLY))
                return True
            except FileExistsError:
                continue
        return False

    def _corpus_ref(self, scenario) -> str:
        """The scenario's folder under ``corpus/`` (written once; the hash names its content)."""
        ref = f"corpus/{scenario.content_hash()}"
        if not (self.out / ref / "scenario.json").exists():
            write_scenario(scenario, self.out / ref)
        return ref

    def _checkpoint(self, schedule, baseline: dict[str, Any] | None, misses: dict[str, int] | None = None) -> None:
        _sync(self.journal)  # the checkpoint never gets ahead of the journal on the disk
        atomic_write_json(self.dir / "checkpoint.json", {"schedule": schedule.to_json(), "baseline": baseline,
                                                         "aim_misses": misses or {}})

    def _read_checkpoint(self, schedule_cls) -> tuple[dict[str, Any], Any]:
        """(checkpoint, schedule) as the last run left them; empty and a new schedule when there is none.

        The journal is what a resume trusts: the checkpoint only saves the replay of the journal's records.
        Every execution's key and every random draw are keyed on the campaign seed and the scenario's content,
        so a new schedule walks the same lineages again, taking each result from the journal without running
        it. A damaged checkpoint (empty, truncated, not ours) is therefore set aside, not fatal."""
        path = self.dir / "checkpoint.json"
        if path.exists():
            try:
                ckpt = json.loads(path.read_text())
                if not isinstance(ckpt, dict):
                    raise ValueError("not a JSON object")
                return ckpt, schedule_cls.from_json(self.cfg.schedule, ckpt.get("schedule"), self.cfg.feedback)
            except (ValueError, TypeError, KeyError, AttributeError, IndexError, OSError, RecursionError) as exc:
                _append(self.journal, {"event": "checkpoint-rebuilt", "why": f"{type(exc).__name__}: {exc}"[:300],
                                       "pid": os.getpid()})
        return {}, schedule_cls.from_json(self.cfg.schedule, None, self.cfg.feedback)

    # ------------------------------------------------------------------ run
    def run(self, stop: Callable[[], bool] | None = None,
            on_record: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
        """Run (or continue) the seed's campaign until it ends or ``stop()``; return the summary."""
        summary_path = self.dir / "summary.json"
        if summary_path.exists():
            return json.loads(summary_path.read_text())
        self.dir.mkdir(parents=True, exist_ok=True)
        stop_file = self.out / STOP_FILE
        user_stop = stop or (lambda: False)

        def should_stop() -> bool:
            return stop_file.exists() or user_stop()

        if should_stop():  # before loading anything: queued jobs return at once when the budget is spent
            return {"seed_index": self.si, "status": "stopped", "execs": None, "findings": [], "pid": os.getpid()}
        self.token = f"{os.uname().nodename}:{os.getpid()}:{uuid.uuid4().hex}"
        atomic_write_text(self.dir / "owner", self.token)
        history = read_journal(self.journal)
        done = {r["key"]: r for r in history if r.get("event") == "end"}
        self.views, self.handed = peer_views(history), peer_views(history, HANDED)
        attempts = sum(1 for r in history if r.get("event") == "attempt") + 1
        _append(self.journal, {"event": "attempt", "pid": os.getpid(), "resumed_from": len(done),
                               "host": os.uname().nodename, "time": time.time(), "run": self.run_id}, after_kill=True,
                sync=True)
        self.findings = sorted({r["finding"] for r in done.values() if r.get("finding")})
        resumed_from = len(done)
        try:
            status = self._loop(done, should_stop, on_record or (lambda rec: None))
        finally:
            _sync(self.journal)  # the round's records are on the disk before it returns
        if status == "superseded":
            return {"seed_index": self.si, "status": status, "execs": len(done), "pid": os.getpid()}
        summary = {"seed_index": self.si, "status": status, "execs": len(done), "findings": self.findings,
                   "resumed_from": resumed_from, "attempts": attempts, "pid": os.getpid()}
        if status == "done":
            atomic_write_json(summary_path, summary)
        return summary

    def _loop(self, done: dict[str, dict], should_stop, on_record) -> str:
        """Run lineages until this round ends: "yielded" (a lineage ended and the budget goes on), "done"
        (single pass: the seed's one lineage ended), "stopped" or "superseded"."""
        from drivefuzz.scenario.roadmap import load_roadmap
        from drivefuzz.search.mutate import Mutator
        from drivefuzz.search.schedule import Schedule

        cfg = self.cfg
        seed_sc = self.seed
        if cfg.time_limit:
            seed_sc = seed_sc.model_copy(update={"sim": seed_sc.sim.model_copy(update={"time_limit": cfg.time_limit})})
        seed_sc = seed_sc.model_copy(update={"ads": cfg.ads})
        mutator = Mutator(load_roadmap(seed_sc.network_path()), cfg.mutation)
        ckpt, schedule = self._read_checkpoint(Schedule)
        runner = Runner(cfg)
        if runner.host is not None:
            warm_up()
        store = FindingStore(self.out, mutator.rmap, runner.misbehaviors,
                             TriageConfig(reproduce=cfg.reproduce, reproduce_incidents=cfg.reproduce_incidents,
                                          shrink=cfg.shrink),
                             {"oracles": cfg.oracles.settings, "exec_timeout_s": cfg.exec_timeout_s})

        def execute(key: str, scenario, parent, description: str, retries: int, t_mutate: float,
                    lineage: int, cycle: int, member: int, baseline, extra: dict | None = None) -> dict[str, Any] | str:
            """The record of one execution (from the journal if it ran before), or why it did not run."""
            if key in done:  # finished before a stop or a kill: reuse its result
                return done[key]
            if not self._owned():
                return "superseded"
            if should_stop() or not self._claim_ticket():
                return "stopped"
            h = scenario.content_hash()
            _append(self.journal, {"event": "start", "key": key, "hash": h, "pid": os.getpid()})
            rec = {"event": "end", "key": key, "seed_index": self.si, "lineage": lineage, "cycle": cycle,
                   "member": member, "hash": h, "parent": parent, "mutation": description,
                   "retries": retries, "finding": None, "score": None, "risk": None, "hint": None,
                   "components": {}, "verdict": "pass", "pid": os.getpid(), **(extra or {})}
            self._execute_into(rec, runner, store, scenario, key, t_mutate, baseline)
            _append(self.journal, rec)
            done[key] = rec
            on_record(rec)
            return rec

        # The seed's clean run: the baseline that risk is measured against (and a finding if the seed fails).
        if "baseline" not in ckpt:
            rec = execute(f"{self.si}/seed", seed_sc, None, "the seed as it is", 0, 0.0, -1, -1, 0, None,
                          {"effect": effect_hash(seed_sc)})
            if isinstance(rec, str):
                return rec
            ckpt["baseline"] = rec.get("risk_detail")
            self._checkpoint(schedule, ckpt["baseline"])
        baseline = _baseline(ckpt["baseline"])
        seed_rec = done.get(f"{self.si}/seed") or {}
        if seed_rec.get("ego_travel"):  # the ADS under test's own pace times the aimed actors
            mutator.observe(seed_sc, seed_rec["ego_travel"], TRAVEL_EVERY_S)
        # no wasted executions: what this job has run, by effect (drivefuzz.search.effect); the journal's records
        # come before any execution not yet run, so a resumed job avoids exactly what the first run avoided
        executed = {r["effect"] for r in done.values() if r.get("effect")} | {effect_hash(seed_sc)}
        reach = seed_reachable(mutator.rmap, seed_sc) if cfg.feedback in GUIDED else ()
        own = self._own_cells(mutator.rmap) if reach else ()
        peers = self._peer_view() if reach else None  # what the other jobs reached in their earlier lineages
        buildable = functools.cache(lambda c: can_aim(mutator.rmap, seed_sc, c, self.si))  # once per cell, not cycle
        misses: dict[str, int] = dict(ckpt.get("aim_misses") or {})  # per cell: aimed builds that missed it

        while True:
            if schedule.lineage is None:
                if cfg.one_lineage_per_seed and schedule.lineages >= 1:
                    return "done"
                schedule.start_lineage(random.Random(f"{cfg.seed}/{self.si}/lineage/{schedule.lineages}"))
                self._checkpoint(schedule, ckpt["baseline"], misses)
            lin = schedule.lineage
            parent = seed_sc if lin.current is None else load_scenario(self.out / lin.current).model_copy(
                update={"ads": cfg.ads})
            parent_hash = parent.content_hash()
            members: list[tuple[dict[str, Any], Any]] = []
            seen = {effect_hash(parent)}
            elsewhere = self._elsewhere(peers, lin.number) if peers is not None else ()
            handed = self.handed.get(lin.number, ())  # (recorded with the view)
            aim = aim_cells(reach, schedule.cells, misses, own, elsewhere, buildable, handed)  # its unreached cells
            for member in range(cfg.population):
                t0 = time.perf_counter()
                key = f"{self.si}/{lin.number}/{lin.cycle}/{member}"
                drawn = self._draw(mutator, parent, parent_hash, lin, member, aim, seen | executed, done.get(key))
                if drawn is None:  # every draw repeats an execution of this job: skipped, not run
                    _append(self.journal, {"event": "duplicate", "key": key, "pid": os.getpid()})
                    continue
                mut, eff, redraw = drawn
                seen.add(eff)
                executed.add(eff)
                rec = execute(key, mut.scenario, parent_hash, mut.description, mut.retries, time.perf_counter() - t0,
                              lin.number, lin.cycle, member, baseline, {"effect": eff, "redraw": redraw})
                if isinstance(rec, str):
                    return rec
                members.append((rec, mut.scenario))
            count_misses(misses, [rec for rec, _ in members])
            found = any(rec["finding"] for rec, _ in members)
            ref, hint, value = self._select(members, schedule, random.Random(
                f"{cfg.seed}/{self.si}/{lin.number}/{lin.cycle}/{parent_hash}/select"))
            schedule.cycle_done(value, ref, hint, found, cfg.continue_after_finding)
            self._checkpoint(schedule, ckpt["baseline"], misses)
            if schedule.lineage is None:
                return "done" if cfg.one_lineage_per_seed else "yielded"

    def _draw(self, mutator, parent, parent_hash: str, lin, member: int, aim: list[str], avoid: set[str],
              prior: dict[str, Any] | None):
        """(mutation, effect hash, draw number) of a population member: the first of :data:`MAX_REDRAWS` draws
        whose effect the job has not executed (nor the parent, nor a sibling); None when every draw repeats
        one. A member the journal has (``prior``: a resume) is drawn as it was then, without the check."""
        cfg = self.cfg
        draws = [int(prior["redraw"])] if prior is not None and "redraw" in prior else range(MAX_REDRAWS)
        for redraw in draws:
            rng = random.Random(f"{cfg.seed}/{self.si}/{lin.number}/{lin.cycle}/{parent_hash}/{member}"
                                + (f"/{redraw}" if redraw else ""))
            mut = mutator.successor(parent, cfg.strategy, rng, hint=lin.hint, aim=aim)
            eff = effect_hash(mut.scenario)
            if prior is not None or eff not in avoid:
                return mut, eff, redraw
        return None

    def _own_cells(self, rmap) -> list[str]:
        """The cells of :func:`share_cells` that fall to this job, from the manifest's seeds (all of one network
        in a campaign; a seed on another network offers none of this one's cells). Every job reads the same seed
        files, so all compute the same shares; the first to finish writes them to the campaign folder
        (:data:`SHARES_FILE`, about 1 s of aimed builds saved for each later job and a resume), and to the disk
        cache of network-derived data for the next campaign on the same seeds (:func:`cached_shares`)."""
        path = self.out / SHARES_FILE
        try:
            shares = json.loads(path.read_text())
            if isinstance(shares, list) and len(shares) == len(self.seed_refs) and \
                    all(isinstance(x, list) and all(isinstance(c, str) for c in x) for x in shares):
                return shares[self.si]
        except (OSError, ValueError):
            pass
        seeds = [load_scenario(self.out / ref) for ref in self.seed_refs]
        same = [sc.network_path() == self.seed.network_path() for sc in seeds]
        if all(same):  # a campaign over several networks: each network's jobs share among their own seeds
            shares = cached_shares(rmap, seeds)
            atomic_write_json(path, shares)
            return shares[self.si]
        places = [seed_places(rmap, sc) if ok else {} for sc, ok in zip(seeds, same)]
        return shares_by_place(rmap, seeds, places)[self.si]

    def _elsewhere(self, peers: PeerView, lineage: int) -> frozenset[str]:
        """The other jobs' cells this lineage aims past: as the journal recorded them when the lineage began (a
        resumed job aims as the first run did), else read now and recorded before its first execution."""
        if lineage not in self.views:
            self.views[lineage] = peers.reached(lineage)
            self.handed[lineage] = peers.given_up(lineage)
            if lineage > 0:
                _append(self.journal, {"event": PEERS, "lineage": lineage, "cells": sorted(self.views[lineage]),
                                       HANDED: sorted(self.handed[lineage]), "pid": os.getpid()})
        return self.views[lineage]

    def _peer_view(self) -> PeerView:
        """The view of what the campaign's other jobs on this seed's network reached (:class:`PeerView`)."""
        mine = self.seed.network_path()
        peers = [j for j, ref in enumerate(self.seed_refs) if j != self.si
                 and load_scenario(self.out / ref).network_path() == mine]
        return PeerView([job_dir(self.out, j) / "journal.jsonl" for j in peers])

    def _select(self, members: list[tuple[dict[str, Any], Any]], schedule, rng: random.Random):
        """(corpus folder, riskiest actor, feedback value) of the member that becomes the next scenario, or
        Nones. Findings and incidents do not become parents: the lineage goes on from a mutant that passed.
        A value is the feedback times the weight of the member's situation (behavioural coverage, see
        :mod:`drivefuzz.search.schedule`); members that met a new situation enter the corpus too."""
        from drivefuzz.search.schedule import member_value, pick_successor

        candidates = [(rec, sc) for rec, sc in members
                      if not rec["finding"] and not rec.get("incident") and rec["risk"] is not None]
        values = [member_value(self.cfg.feedback, _feedback_value(rec, self.cfg.feedback),
                               schedule.weight(rec.get("situation")), schedule.new_cells(rec.get("cells")),
                               schedule.cell_bonus(rec.get("cells"))) for rec, _ in candidates]
        pick = pick_successor(values, self.cfg.feedback, rng)
        for (rec, sc), value in zip(candidates, values):
            if schedule.is_new(rec.get("situation"), rec["risk"], rec.get("cells")):
                schedule.add_new(self._corpus_ref(sc), value, rec.get("hint"))
        schedule.observe([rec.get("situation") for rec, _ in members],
                         [rec.get("situation") for rec, _ in members if rec["finding"]],
                         [rec.get("cells") for rec, _ in members])
        if pick is None:
            return None, None, None
        rec, successor = candidates[pick]
        return self._corpus_ref(successor), rec.get("hint"), values[pick]

    def _execute_into(self, rec: dict[str, Any], runner, store, scenario, key: str, t_mutate: float,
                      baseline) -> None:
        """Run ``scenario`` and fill ``rec`` with its outcome, feedback and timings (saving a finding)."""
        from drivefuzz.search.quality import score_trace
        from drivefuzz.search.risk import risk_score
        from drivefuzz.sim.simhost import OK
        from drivefuzz.triage.coverage import execution_cells
        from drivefuzz.triage.signature import situation

        runs0, sim0 = runner.runs, runner.sim_s
        out = runner.execute(scenario)
        timings = {"mutation": t_mutate, "isolation": 0.0}
        t_store = time.perf_counter()
        if out.status == OK:
            ex = out.execution
            timings.update(ex.timings)
            timings["isolation"] = max(out.wall_time - ex.wall_time, 0.0)
            rec.update(termination=ex.termination.value, frames=ex.trace.n_frames, wall_time=round(ex.wall_time, 4))
            t0 = time.perf_counter()
            q = score_trace(ex.trace, self.cfg.quality)
            r = risk_score(ex.trace, self.cfg.risk, baseline)
            timings["quality"] = time.perf_counter() - t0
            rec.update(score=q.score, components=q.as_dict(), risk=r.score, hint=r.riskiest_actor,
                       risk_detail=r.as_dict())
            if self.cfg.feedback in GUIDED and r.frame is not None and r.riskiest_actor is not None:
                rec["situation"] = situation(scenario, ex.trace, store.rmap, r.frame, r.riskiest_actor)
            rec["cells"] = execution_cells(scenario, ex.trace, store.rmap, r)  # interaction coverage
            if self.cfg.feedback in GUIDED:  # and the cells it came near (drivefuzz coverage says so)
                rec["near"] = [c for c in execution_cells(scenario, ex.trace, store.rmap, r, near=True)
                               if c not in rec["cells"]]
            if key.endswith("/seed"):  # how fast the ADS under test drives the mission (Mutator.observe)
                rec["ego_travel"] = ego_travel(ex.trace)
            t_store = time.perf_counter()
            if ex.misbehaviors:
                m = ex.misbehaviors[0]
                t0 = time.perf_counter()
                filed = store.triage(scenario, list(ex.misbehaviors), ex.trace, key, ex.termination.value)
                timings["triage"] = time.perf_counter() - t0
                # every hit's scenario is kept (its folder only has the first one's): a signature's later hits
                # can be read, replayed and compared too
                rec.update(verdict=f"{m.oracle}/{m.kind}", signature=filed.signature, fault=filed.fault,
                           triage_execs=filed.executions, scenario=self._corpus_ref(scenario),
                           **{"incident" if filed.fault == "other" else "finding": filed.rel})
        else:  # the simulator crashed or hung, or a plugin raised: a record of its own kind, a finding only when
            # the ADS raised or hung; SUMO's, drivefuzz's and an oracle plugin's failures are errors of the tool
            m = Misbehavior(oracle=out.status, kind=out.error_type or out.status, frame=-1, time=0.0,
                            position=(0.0, 0.0), details={"detail": out.detail})
            t0 = time.perf_counter()
            filed = store.triage(scenario, [m], None, key, out.status,
                                 {"error": {"status": out.status, "type": out.error_type, "plugin": out.plugin,
                                            "detail": out.detail, "traceback": out.traceback}}, fault=out.fault)
            timings["triage"] = time.perf_counter() - t0
            rec.update(termination=out.status, frames=0, wall_time=round(out.wall_time, 4),
                       verdict=f"{m.oracle}/{m.kind}", signature=filed.signature, fault=filed.fault,
                       **{"finding" if filed.fault == "ego" else "error": filed.rel})
        timings["storage"] = time.perf_counter() - t_store - timings.get("triage", 0.0)  # triage has its own key
        rec["timings"] = {k: round(v, 6) for k, v in timings.items()}
        # the work this record stands for: the execution and every triage rerun (careful driver, reproduction,
        # shrinking), in runs and in simulated seconds (tools/bench_scaling.py counts work by them)
        rec["runs"], rec["sim_s"] = runner.runs - runs0, round(runner.sim_s - sim0, 3)


def peer_views(history: list[dict[str, Any]], key: str = "cells") -> dict[int, frozenset[str]]:
    """The other jobs' cells each lineage of a job aimed past, by lineage, as its journal recorded them (a record
    that is not one is skipped: the lineage's view is read again); with ``key`` :data:`HANDED`, the cells they had
    given up on (none where a journal of an older version did not record them)."""
    views: dict[int, frozenset[str]] = {}
    for r in history:
        if r.get("event") == PEERS and isinstance(r.get("lineage"), int) and isinstance(r.get("cells"), list) \
                and all(isinstance(c, str) for c in r["cells"]):
            got = r.get(key, [])
            views.setdefault(r["lineage"], frozenset(got) if isinstance(got, list) and all(
                isinstance(c, str) for c in got) else frozenset())
    return views


def _feedback_value(rec: dict[str, Any], mode: str) -> float:
    """Higher = riskier: the risk score, or the negated driving-quality score (the paper's, lower = worse)."""
    if mode == "paper":
        return -float(rec["score"])
    return float(rec["risk"])


#: [s] the seed run's metres driven are journalled at this interval (Mutator.observe)
TRAVEL_EVERY_S = 0.5


def ego_travel(trace) -> list[float]:
    """[m] the ego drove from its start, every :data:`TRAVEL_EVERY_S` s of ``trace``."""
    import numpy as np

    d = np.concatenate([[0.0], np.cumsum(np.asarray(trace.ego["speed"], dtype=float)[:-1]) * trace.step_length])
    k = max(int(round(TRAVEL_EVERY_S / trace.step_length)), 1)
    return [round(float(x), 1) for x in d[::k]]


def _baseline(detail: dict[str, Any] | None):
    from drivefuzz.search.risk import RiskScore

    return None if detail is None else RiskScore.from_dict(detail)


def run_seed_job(out: str, seed_index: int) -> dict[str, Any]:
    """The Dask task: run one seed's job in this worker; everything is persisted under ``out``."""
    return SeedJob(out, seed_index).run()
