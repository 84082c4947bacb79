"""One seed's fuzz campaign (the paper's Algorithm 1 for one seed): the unit of work of a campaign.

A job runs in the campaign's own process (``--jobs 1``) or in a Dask worker. It
is idempotent and resumable, and it persists everything itself, inside the
campaign directory, before it returns; its return value is only a small summary.
A worker that dies therefore loses at most the execution it was running, and
the job that Dask starts again elsewhere continues from its journal.

For each of ``cycles`` cycles, ``generate`` adds one actor or puddle to the
current scenario, then ``population`` mutants are executed. A mutant that makes
an oracle fire (or crashes, hangs or breaks a plugin, see :mod:`drivefuzz.sim.simhost`)
is a finding, which ends the seed's campaign unless ``continue_after_finding``.
Otherwise the mutant with the lowest driving-quality score becomes the next
scenario (a random one with ``feedback=False``, the paper's baseline).

Determinism: every random draw comes from ``Random(f"{seed}/{seed_index}/{cycle}/...")``,
so a job is a pure function of its seed scenario and the configuration, and a
resumed job re-creates exactly the executions it had not finished.

Files of job ``NNN`` (the seed index) under ``jobs/NNN/``::

    journal.jsonl     append-only, fsync'd: {"event": "start", key, pid} before an
                      execution (attributes a crash to its scenario), then
                      {"event": "end", ...the execution's record} after it
    checkpoint.json   the cycle reached and the current scenario (atomic)
    summary.json      written last, when the job has finished its seed: the DONE marker
    owner             the attempt that owns the job: an older attempt that is still running
                      (its client died, or Dask lost touch with its worker) stops at its next execution

Budgets: ``--max-execs`` counts the executions of one run of the campaign (a resume
is a new run). Each execution first claims a ticket, a file ``budget/run<R>/<n>``
created with O_EXCL, so parallel jobs never run more than the budget between them.

Findings go to ``findings/NNN-KK-<oracle>-<hash>/`` and successors to ``corpus/<hash>/``.
A file ``STOP`` in the campaign directory makes every job return after its
current execution (the budget ran out, or the user pressed Ctrl-C).
"""

from __future__ import annotations

import json
import os
import random
import time
import uuid
from pathlib import Path
from typing import Any, Callable

import drivefuzz
from drivefuzz.campaign.config import FuzzConfig
from drivefuzz.oracle import Misbehavior
from drivefuzz.storage import atomic_dir, atomic_write_json, atomic_write_text
from drivefuzz.scenario.sumofiles import load_scenario, write_scenario

STOP_FILE = "STOP"


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


def _append(path: Path, rec: dict[str, Any], after_kill: bool = False) -> None:
    with open(path, "ab+") as fh:
        lead = b""
        if after_kill and fh.tell() > 0:  # a kill may have torn the last line: start on a line of our own
            fh.seek(-1, os.SEEK_END)
            lead = b"" if fh.read(1) == b"\n" else b"\n"
        fh.write(lead + json.dumps(rec, sort_keys=True).encode() + b"\n")
        fh.flush()
        os.fsync(fh.fileno())


def replay_script() -> str:
    return ("#!/bin/sh\n# Runs this finding again and checks it reproduces.\n"
            'cd "$(dirname "$0")" && exec drivefuzz replay .\n')


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
        self.seed = load_scenario(self.out / manifest["seeds"][seed_index])
        self.journal = self.dir / "journal.jsonl"
        self.findings: list[str] = []

    # ---------------------------------------------------------------- files
    def _save_finding(self, scenario, misbehaviors: list[Misbehavior], key: str, trace=None,
                      termination: str = "", extra: dict[str, Any] | None = None) -> str:
        h = scenario.content_hash()
        for rel in self.findings:  # a resumed job re-running an execution whose finding was saved
            if rel.endswith(h):
                return rel
        m = misbehaviors[0]
        rel = f"findings/{self.si:03d}-{len(self.findings):02d}-{m.oracle}-{h}"
        with atomic_dir(self.out / rel) as tmp:
            write_scenario(scenario, tmp)
            if trace is not None:
                trace.save(tmp / "trace")
            atomic_write_json(tmp / "verdict.json", {
                "misbehaviors": [x.as_dict() for x in misbehaviors], "termination": termination,
                "scenario_hash": h, "seed_index": self.si, "key": key,
                "frames": None if trace is None else trace.n_frames,
                "oracles": self.cfg.oracles.settings, "exec_timeout_s": self.cfg.exec_timeout_s,
                "drivefuzz": drivefuzz.__version__, **(extra or {}),
            })
            atomic_write_text(tmp / "replay.sh", replay_script())
            os.chmod(tmp / "replay.sh", 0o755)
        self.findings.append(rel)
        return rel

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

    def _sweep(self) -> None:
        """Remove this job's half-written finding folders (a kill inside atomic_dir)."""
        import shutil

        for leftover in (self.out / "findings").glob(f".{self.si:03d}-*"):
            shutil.rmtree(leftover, ignore_errors=True)

    def _checkpoint(self, cycle: int, current) -> None:
        ref = None
        if current is not None:
            ref = f"corpus/{current.content_hash()}"
            if not (self.out / ref / "scenario.json").exists():
                write_scenario(current, self.out / ref)
        atomic_write_json(self.dir / "checkpoint.json", {"cycle": cycle, "current": ref})

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
        self._sweep()
        history = read_journal(self.journal)
        done = {r["key"]: r for r in history if r.get("event") == "end"}
        attempts = sum(1 for r in history if r.get("event") == "attempt") + 1
        _append(self.journal, {"event": "attempt", "pid": os.getpid(), "resumed_from": len(done),
                               "host": os.uname().nodename, "time": time.time(), "run": self.run_id}, after_kill=True)
        self.findings = sorted({r["finding"] for r in done.values() if r.get("finding")})
        resumed_from = len(done)
        status = self._loop(done, should_stop, on_record or (lambda rec: None))
        if status == "superseded":
            return {"seed_index": self.si, "status": status, "execs": len(done), "pid": os.getpid()}
        summary = {"seed_index": self.si, "status": status, "execs": len(done), "findings": self.findings,
                   "resumed_from": resumed_from, "attempts": attempts, "pid": os.getpid()}
        if status == "done":
            atomic_write_json(summary_path, summary)
        return summary

    def _loop(self, done: dict[str, dict], should_stop, on_record) -> str:
        from drivefuzz.search.mutate import Mutator
        from drivefuzz.scenario.roadmap import load_roadmap
        from drivefuzz.sim.simhost import OK

        cfg = self.cfg
        seed_sc = self.seed
        if cfg.time_limit:
            seed_sc = seed_sc.model_copy(update={"sim": seed_sc.sim.model_copy(update={"time_limit": cfg.time_limit})})
        seed_sc = seed_sc.model_copy(update={"ads": cfg.ads})
        mutator = Mutator(load_roadmap(seed_sc.network_path()), cfg.mutation)
        ckpt_path = self.dir / "checkpoint.json"
        ckpt = json.loads(ckpt_path.read_text()) if ckpt_path.exists() else {}
        current, first_cycle = seed_sc, 0
        if ckpt.get("current"):
            current = load_scenario(self.out / ckpt["current"]).model_copy(update={"ads": cfg.ads})
        first_cycle = ckpt.get("cycle", 0)
        runner = _Runner(cfg)
        for cycle in range(first_cycle, cfg.cycles):
            t0 = time.perf_counter()
            gen = mutator.generate(current, cfg.strategy, random.Random(f"{cfg.seed}/{self.si}/{cycle}/generate"))
            t_generate = time.perf_counter() - t0
            population: list[tuple[float, Any]] = []
            for member in range(cfg.population):
                key = f"{self.si}/{cycle}/{member}"
                t0 = time.perf_counter()
                mut = mutator.mutate(gen.scenario, random.Random(f"{cfg.seed}/{self.si}/{cycle}/{member}"))
                t_mutate = time.perf_counter() - t0 + (t_generate if member == 0 else 0.0)
                child = mut.scenario
                if key in done:  # finished before a stop or a kill: reuse its result
                    rec = done[key]
                    if rec["score"] is not None:
                        population.append((rec["score"], child))
                    if rec["finding"] and not cfg.continue_after_finding:
                        return "done"
                    continue
                if not self._owned():
                    return "superseded"
                if should_stop() or not self._claim_ticket():
                    self._checkpoint(cycle, current)
                    return "stopped"
                _append(self.journal, {"event": "start", "key": key, "hash": child.content_hash(),
                                       "pid": os.getpid()})
                out = runner.execute(child)
                rec = {"event": "end", "key": key, "seed_index": self.si, "cycle": cycle, "member": member,
                       "hash": child.content_hash(), "parent": current.content_hash(),
                       "mutation": f"{gen.description} | {mut.description}",
                       "retries": gen.retries + mut.retries, "finding": None, "score": None,
                       "components": {}, "verdict": "pass", "pid": os.getpid()}
                timings = {"mutation": t_mutate, "isolation": 0.0}
                t_store = time.perf_counter()
                if out.status == OK:
                    ex = out.execution
                    timings.update(ex.timings)
                    timings["isolation"] = max(out.wall_time - ex.wall_time, 0.0)
                    rec.update(termination=ex.termination.value, frames=ex.trace.n_frames,
                               wall_time=round(ex.wall_time, 4))
                    if ex.misbehaviors:
                        m = ex.misbehaviors[0]
                        t_store = time.perf_counter()
                        rel = self._save_finding(child, list(ex.misbehaviors), key, ex.trace, ex.termination.value)
                        rec.update(verdict=f"{m.oracle}/{m.kind}", finding=rel)
                    else:
                        from drivefuzz.search.quality import score_trace

                        t0 = time.perf_counter()
                        q = score_trace(ex.trace, cfg.quality)
                        timings["quality"] = time.perf_counter() - t0
                        rec.update(score=q.score, components=q.as_dict())
                        population.append((q.score, child))
                        t_store = time.perf_counter()
                else:  # the simulator crashed or hung, or a plugin raised: a finding of its own kind
                    m = Misbehavior(oracle=out.status, kind=out.error_type or out.status, frame=-1, time=0.0,
                                    position=(0.0, 0.0), details={"detail": out.detail})
                    rel = self._save_finding(child, [m], key, None, out.status,
                                             {"error": {"status": out.status, "type": out.error_type,
                                                        "detail": out.detail, "traceback": out.traceback}})
                    rec.update(termination=out.status, frames=0, wall_time=round(out.wall_time, 4),
                               verdict=f"{m.oracle}/{m.kind}", finding=rel)
                timings["storage"] = time.perf_counter() - t_store
                rec["timings"] = {k: round(v, 6) for k, v in timings.items()}
                _append(self.journal, rec)
                done[key] = rec
                on_record(rec)
                if rec["finding"] and not cfg.continue_after_finding:
                    return "done"
            if population:
                if cfg.feedback:
                    current = min(population, key=lambda p: p[0])[1]
                else:
                    current = random.Random(f"{cfg.seed}/{self.si}/{cycle}/select").choice(population)[1]
            self._checkpoint(cycle + 1, current)
        return "done"


_HOSTS: dict[int, Any] = {}  # one simulation host per thread of this process, kept between jobs


def _host_for_this_thread(timeout_s: float):
    """The calling thread's simulation host (started lazily; a Dask worker reuses it for every job)."""
    import atexit
    import threading

    from drivefuzz.sim.simhost import SimHost

    tid = threading.get_ident()
    host = _HOSTS.get(tid)
    if host is None:
        if not _HOSTS:
            atexit.register(lambda: [h.close() for h in _HOSTS.values()])
        host = _HOSTS[tid] = SimHost()
    host.timeout_s = timeout_s
    return host


class _Runner:
    """Runs executions isolated in a simulation host (the default) or in this process."""

    def __init__(self, cfg):
        self.cfg = cfg
        self.host = _host_for_this_thread(cfg.exec_timeout_s) if cfg.isolate else None

    def execute(self, scenario):
        if self.host is not None:
            return self.host.execute(scenario, self.cfg.oracles.settings)
        from drivefuzz.errors import PluginError
        from drivefuzz.sim.execute import execute
        from drivefuzz.sim.simhost import OK, PLUGIN_ERROR, Outcome

        t0 = time.monotonic()
        try:
            ex = execute(scenario, oracles=self.cfg.oracles.instantiate())
        except PluginError as exc:  # without isolation only a plugin's exception can be survived
            return Outcome(PLUGIN_ERROR, detail=str(exc), error_type=type(exc.__cause__ or exc).__name__,
                           wall_time=time.monotonic() - t0)
        return Outcome(OK, execution=ex, wall_time=time.monotonic() - t0)


def run_seed_job(out: str, seed_index: int) -> dict[str, Any]:
    """The Dask task: run one seed's job in this worker; everything is persisted under ``out``."""
    return SeedJob(out, seed_index).run()
