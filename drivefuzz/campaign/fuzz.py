"""A fuzz campaign: its output directory, its seed jobs, and the index of every execution.

The campaign process (the client) owns the directory's manifest and its SQLite
index; the seed jobs (:mod:`drivefuzz.campaign.job`, the paper's Algorithm 1 for one seed)
write everything else themselves. With ``--jobs 1`` the jobs run one after another
in this process; otherwise they run at once on Dask (:mod:`drivefuzz.campaign.cluster`),
one simulation per worker process. Either way the client follows the jobs'
journals to keep the index and the progress display current, and stops the jobs
by creating ``STOP`` when the budget runs out or the user presses Ctrl-C. A ``--resume``
starts the unfinished jobs in the order a run without the stop would have come to them (the
fewest lineages finished first, the job the stop interrupted among them), so that a campaign
stopped and resumed runs what one run of the summed budget runs.

Output directory (a person opens it without drivefuzz)::

    manifest.json           version, command line, configuration, campaign seed, seed list
    seeds/NNN/              the seed scenarios (SUMO files + scenario.json)
    jobs/NNN/               each seed job's journal, checkpoint and summary (see drivefuzz.campaign.job)
    index.sqlite            one row per execution; written only by the client, rebuilt from the
                            journals on --resume (it is derived data: SQLite must not be shared over NFS)
    corpus/<hash>/          every successor scenario
    findings/<signature>-<oracle>/   one per signature the ego is to blame for: SUMO files, scenario.json, trace/,
                            verdict.json (attribution, signature, reproduction rate), hits.json, replay.sh
    incidents/<signature>-<oracle>/  the same for events that were not the ego's fault
    errors/<signature>-<status>/     failed executions that are not the ADS's fault (SUMO died, drivefuzz or an
                            oracle plugin raised): errors of the tool, with the error and its traceback, never findings
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import sqlite3
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import drivefuzz
from drivefuzz.errors import InvalidConfig
from drivefuzz.campaign.config import FINISHED, FuzzConfig  # noqa: F401  (FuzzConfig re-exported)
from drivefuzz.campaign.job import STOP_FILE, SeedJob, job_dir, run_seed_job
from drivefuzz.oracle import Misbehavior, OracleSettings
from drivefuzz.scenario import AdsSpec, Scenario
from drivefuzz.storage import atomic_write_json
from drivefuzz.triage.store import ads_flag, write_hits
from drivefuzz.scenario.sumofiles import load_scenario, write_scenario

SCHEMA = """
CREATE TABLE IF NOT EXISTS executions (
    exec_id INTEGER PRIMARY KEY,
    key TEXT UNIQUE,
    seed_index INTEGER, lineage INTEGER, cycle INTEGER, member INTEGER,
    scenario_hash TEXT, parent_hash TEXT, mutation TEXT, retries INTEGER,
    score REAL, risk REAL, components TEXT, verdict TEXT, termination TEXT, finding TEXT,
    incident TEXT, error TEXT, signature TEXT, fault TEXT,
    frames INTEGER, wall_time REAL, timings TEXT, pid INTEGER
);
"""
#: (column, journal record key) of the index's rows
COLUMNS = (("key", "key"), ("seed_index", "seed_index"), ("lineage", "lineage"), ("cycle", "cycle"),
           ("member", "member"), ("scenario_hash", "hash"), ("parent_hash", "parent"), ("mutation", "mutation"),
           ("retries", "retries"), ("score", "score"), ("risk", "risk"), ("components", "components"), ("verdict", "verdict"), ("termination", "termination"),
           ("finding", "finding"), ("incident", "incident"), ("error", "error"), ("signature", "signature"), ("fault", "fault"), ("frames", "frames"), ("wall_time", "wall_time"), ("timings", "timings"),
           ("pid", "pid"))
_INSERT = (f"INSERT OR IGNORE INTO executions ({', '.join(c for c, _ in COLUMNS)}) "
           f"VALUES ({', '.join('?' * len(COLUMNS))})")


@dataclass
class Finding:
    """A finding (or an incident) folder: one signature, its representative execution and its verdict."""

    path: Path
    misbehavior: Misbehavior
    scenario_hash: str
    seed_index: int
    key: str
    signature: dict[str, Any] = field(default_factory=dict)
    attribution: dict[str, Any] | None = None
    reproduction: dict[str, Any] | None = None
    hits: int = 1  # executions that hit this signature
    ads: str | None = None  # the ADS that failed (replay must name it when it is not an installed plugin)

    @property
    def label(self) -> str:
        m = self.misbehavior
        return self.signature.get("label") or f"{m.oracle}/{m.kind}"


@dataclass
class Progress:
    execs: int = 0  # every execution of the campaign, including those before a resume
    new_execs: int = 0  # executions of this run (the rate's numerator)
    findings: int = 0  # distinct signatures the ego is to blame for
    incidents: int = 0  # distinct signatures it is not
    errors: int = 0  # distinct failures of the tool (SUMO, drivefuzz, an oracle plugin): not findings
    seed_index: int = 0
    cycle: int = 0
    lineage: int = 0
    best_risk: float | None = None  # the highest risk score of any execution so far
    jobs_total: int = 0
    jobs_done: int = 0
    jobs_running: int = 0
    started: float = field(default_factory=time.monotonic)
    last_exec_at: float = 0.0  # [s, monotonic] when the last execution was indexed (0: none yet)
    last_finding: str | None = None  # the signature of the finding indexed last
    last_finding_at: float = 0.0  # [s, monotonic]

    @property
    def rate(self) -> float:
        return self.new_execs / max(time.monotonic() - self.started, 1e-9)


def parse_duration(text: str | None, source: str = "--budget") -> float | None:
    """'90', '90s', '10m', '2h', '1h30m' -> seconds."""
    if text is None:
        return None
    m = re.fullmatch(r"\s*(?:(\d+(?:\.\d+)?)h)?\s*(?:(\d+(?:\.\d+)?)m)?\s*(?:(\d+(?:\.\d+)?)s?)?\s*", str(text))
    if not m or not any(m.groups()):
        raise InvalidConfig(source, None, f"cannot read duration {text!r}", "e.g. 90s, 10m, 2h, 1h30m")
    h, mi, sec = (float(g) if g else 0.0 for g in m.groups())
    return h * 3600 + mi * 60 + sec


def replay_command(finding_dir: Path, ads_name: str | None = None) -> str:
    """The command that replays a finding (naming its ADS when that is not an installed plugin)."""
    return f"drivefuzz replay {shlex.quote(str(finding_dir))}{ads_flag(ads_name)}"


def load_finding(path: Path) -> Finding:
    v = json.loads((path / "verdict.json").read_text())
    return Finding(path, Misbehavior.from_dict(v["misbehaviors"][0]), v["scenario_hash"], v.get("seed_index", 0),
                   v.get("key", ""), v.get("signature") or {}, v.get("attribution"), v.get("reproduction"),
                   ads=(v.get("ads") or {}).get("name") if isinstance(v.get("ads"), dict) else None)


class Campaign:
    """One output directory; runs (or resumes) a job per seed, here or on a Dask client."""

    def __init__(self, out: str | os.PathLike, seeds: Sequence[Scenario], config: FuzzConfig,
                 argv: Sequence[str] = (), on_progress: Callable[[Progress], None] | None = None):
        self.out = Path(out)
        self.seeds = list(seeds)
        self.cfg = config
        self.argv = list(argv)
        self.on_progress = on_progress or (lambda p: None)
        self.progress = Progress(jobs_total=len(self.seeds))
        self.findings: list[Finding] = []
        self.incidents: list[Finding] = []  # not the ego's fault: kept apart, not counted as findings
        self.errors: list[Finding] = []  # executions the tool failed (fault tool or oracle-plugin): not findings
        self.failed_jobs: dict[int, str] = {}  # seed index -> why its job failed (Dask gave up on it)
        self.stop_requested = False
        self.stop_reason = ""  # why the run ended, for the summary
        self._offsets: dict[int, int] = {}
        self._deadline: float | None = None
        self._rounds: dict[int, int] = {}  # Dask submissions per seed job
        self._attempts: dict[int, int] = {}  # attempt records of this run per seed job (one per job started)
        self._attempts_at_submit: dict[int, int] = {}  # the same when its current Dask round was submitted
        self._clock_armed = False  # attempts read while preparing are an earlier run's

    # ------------------------------------------------------------- directory
    def prepare(self, resume: bool) -> list[int]:
        """Create (or reopen) the directory and rebuild the index; return the seed indices still to run."""
        self.out.mkdir(parents=True, exist_ok=True)
        for sub in ("corpus", "findings", "incidents", "jobs"):
            (self.out / sub).mkdir(exist_ok=True)
        for sub in ("findings", "incidents", "errors"):  # folders half-written when a job was killed (no job runs yet)
            for leftover in (self.out / sub).glob(".*") if (self.out / sub).is_dir() else ():
                shutil.rmtree(leftover, ignore_errors=True)
        if not resume or not (self.out / "manifest.json").exists():
            for i, sc in enumerate(self.seeds):
                write_scenario(sc, self.out / "seeds" / f"{i:03d}")
            atomic_write_json(self.out / "manifest.json", {
                "drivefuzz": drivefuzz.__version__, "command": self.argv, "config": self.cfg.to_json(),
                "seed": self.cfg.seed, "seeds": [f"seeds/{i:03d}" for i in range(len(self.seeds))],
                "started": time.strftime("%Y-%m-%dT%H:%M:%S"), "run": 1,
            })
        else:  # a resume is a new run, with budgets of its own (and --report-all's reproduction of incidents);
            # the rest of the configuration is the campaign's
            manifest = json.loads((self.out / "manifest.json").read_text())
            manifest["config"].update(budget_s=self.cfg.budget_s, max_execs=self.cfg.max_execs,
                                      reproduce_incidents=self.cfg.reproduce_incidents)
            manifest["run"] = manifest.get("run", 1) + 1
            atomic_write_json(self.out / "manifest.json", manifest)
        (self.out / STOP_FILE).unlink(missing_ok=True)
        self.db = open_index(self.out / "index.sqlite")  # derived data: rebuilt from the journals
        self._offsets = {}
        self.findings, self.incidents, self.errors, self.progress.execs, self.progress.findings = [], [], [], 0, 0
        self._clock_armed = False
        self.poll(quiet=True)
        self._attempts, self._clock_armed = {}, True
        self.progress.new_execs = 0
        self.progress.started = time.monotonic()
        pending = [i for i in range(len(self.seeds)) if not (job_dir(self.out, i) / "summary.json").exists()]
        self.progress.jobs_done = len(self.seeds) - len(pending)
        # the round robin goes on where it stopped (the job it stopped in first), as one run without a stop would
        pending.sort(key=lambda i: (_lineages_done(self.out, i), i))
        return pending

    def poll(self, quiet: bool = False) -> int:
        """Index the executions the jobs have journalled since the last poll; return how many."""
        new = 0
        for si in range(len(self.seeds)):
            path = job_dir(self.out, si) / "journal.jsonl"
            if not path.exists():
                continue
            offset = self._offsets.get(si, 0)
            with open(path, "rb") as fh:
                fh.seek(offset)
                data = fh.read()
            end = data.rfind(b"\n") + 1  # a line being written is read at the next poll
            self._offsets[si] = offset + end
            for line in data[:end].splitlines():
                try:
                    rec = json.loads(line)
                except (ValueError, RecursionError):  # torn by a kill, then appended after
                    continue
                if journal_problem(rec) is not None:
                    continue
                if rec["event"] == "end":
                    self._index(self._checked_finding(rec))
                    new += 1
                elif rec["event"] == "attempt" and self._clock_armed:
                    self._job_started(si, rec)
        if new:
            self.db.commit()
            self.progress.new_execs += new
            if not quiet:
                self.on_progress(self.progress)
        return new

    def _job_started(self, si: int, rec: dict[str, Any]) -> None:
        """A job of this run began to run (its attempt record): the wall-clock budget counts from the first,
        not from submission, so a campaign whose jobs wait for a worker (a batch cell) is not starved."""
        self._attempts[si] = self._attempts.get(si, 0) + 1
        if self._deadline is None and self.cfg.budget_s is not None:
            began = rec.get("time")
            waited = max(0.0, time.time() - began) if isinstance(began, (int, float)) else 0.0
            self._deadline = time.monotonic() - waited + self.cfg.budget_s
            self.progress.started = time.monotonic() - waited

    def jobs_running(self, submitted: list[int]) -> int:
        """How many of the seed jobs with a Dask round in flight (``submitted``) have begun to run: Dask's
        'processing' also counts a round that only waits on a worker, so it is read from the journals."""
        return sum(1 for si in submitted if self._attempts.get(si, 0) > self._attempts_at_submit.get(si, 0))

    def _index(self, rec: dict[str, Any]) -> None:
        row = [json.dumps(rec.get(k, {})) if k in ("components", "timings") else rec.get(k) for _, k in COLUMNS]
        cur = self.db.execute(_INSERT, row)
        if cur.rowcount == 0:  # the same execution journalled twice (a job re-run after a kill)
            return
        p = self.progress
        p.execs += 1
        p.last_exec_at = time.monotonic()
        p.seed_index, p.cycle, p.lineage = rec["seed_index"], rec["cycle"], rec.get("lineage", 0)
        if rec.get("risk") is not None and (p.best_risk is None or rec["risk"] > p.best_risk):
            p.best_risk = rec["risk"]
        for col, kept in (("finding", self.findings), ("incident", self.incidents), ("error", self.errors)):
            if rec.get(col):
                path = self.out / rec[col]
                known = next((f for f in kept if f.path == path), None)
                if known is not None:
                    known.hits += 1
                elif (path / "verdict.json").is_file():
                    kept.append(load_finding(path))
                    if col == "finding":
                        p.last_finding, p.last_finding_at = kept[-1].label, p.last_exec_at
        p.findings, p.incidents, p.errors = len(self.findings), len(self.incidents), len(self.errors)

    def _checked_finding(self, rec: dict[str, Any]) -> dict[str, Any]:
        """``rec``, less a finding or incident whose verdict is unreadable (its folder stays where it is:
        nothing is deleted, it is only left out of the index's list)."""
        for col in ("finding", "incident", "error"):
            folder = rec.get(col)
            if not folder:
                continue
            path = self.out / folder
            try:
                if path.is_dir():
                    load_finding(path)
            except (OSError, ValueError, KeyError, IndexError, TypeError, AttributeError, RecursionError):
                rec = dict(rec, **{col: None})
        return rec

    # ------------------------------------------------------------------ budget
    def out_of_budget(self) -> bool:
        if self.stop_requested:
            self.stop_reason = self.stop_reason or "stopped on request (Ctrl-C)"
            return True
        if self._deadline is not None and time.monotonic() >= self._deadline:
            self.stop_reason = self.stop_reason or f"the time budget of {format_duration(self.cfg.budget_s)} was spent"
            return True
        if self.cfg.max_execs is not None and self.progress.new_execs >= self.cfg.max_execs:
            self.stop_reason = self.stop_reason or f"--max-execs {self.cfg.max_execs} executions were run"
            return True
        return False

    def seconds_left(self) -> float | None:
        """[s] of the time budget left (all of it before the first job runs); None without one."""
        if self.cfg.budget_s is None:
            return None
        return self.cfg.budget_s if self._deadline is None else max(0.0, self._deadline - time.monotonic())

    def execs_left(self) -> int | None:
        """Executions of --max-execs left in this run; None without it."""
        return None if self.cfg.max_execs is None else max(0, self.cfg.max_execs - self.progress.new_execs)

    def request_stop(self) -> None:
        (self.out / STOP_FILE).touch()

    # --------------------------------------------------------------------- run
    def run(self, resume: bool = False, client=None) -> list[Finding]:
        """Run every unfinished seed job; with a Dask ``client`` at once on its workers."""
        pending = self.prepare(resume)
        if client is None:
            self._deadline = None if self.cfg.budget_s is None else time.monotonic() + self.cfg.budget_s
            self._run_here(pending)
        else:
            run_on_dask(client, [(self, pending)])
        return self.finish()

    def finish(self) -> list[Finding]:
        if not hasattr(self, "db"):  # stopped before it was prepared
            return self.findings
        self.poll()
        hits: dict[str, list[str]] = {}
        for rel, key in self.db.execute("SELECT COALESCE(finding, incident, error), key FROM executions WHERE "
                                        "finding IS NOT NULL OR incident IS NOT NULL OR error IS NOT NULL "
                                        "ORDER BY exec_id"):
            hits.setdefault(rel, []).append(key)
        write_hits(self.out, hits)
        if not self.stop_reason:
            if self.failed_jobs and len(self.failed_jobs) == self.progress.jobs_total:
                self.stop_reason = "every seed job failed"
            elif self.cfg.one_lineage_per_seed:
                self.stop_reason = ("single pass done: one lineage per seed" + ("" if self.cfg.single_pass else
                                    " (give --budget or --max-execs to keep fuzzing)"))
            else:
                self.out_of_budget()
        if self.stop_reason and not self.stop_requested and not self.failed_jobs:
            atomic_write_json(self.out / FINISHED, {"reason": self.stop_reason, "executions": self.progress.execs})
        # in the order they were first hit (as `drivefuzz findings` and the report number them)
        first = {rel: i for i, rel in enumerate(hits)}
        self.findings.sort(key=lambda f: first.get(str(f.path.relative_to(self.out)), len(first)))
        self.incidents.sort(key=lambda f: first.get(str(f.path.relative_to(self.out)), len(first)))
        self.errors.sort(key=lambda f: first.get(str(f.path.relative_to(self.out)), len(first)))
        return self.findings

    def _run_here(self, pending: list[int]) -> None:
        """Round robin over the seeds, one lineage each turn, until every job is done or the budget is spent."""
        pending = list(pending)
        while pending and not self.out_of_budget():
            for si in list(pending):
                if self.out_of_budget():
                    break
                self.progress.jobs_running = 1
                summary = SeedJob(self.out, si).run(stop=self.out_of_budget, on_record=lambda rec: self.poll())
                self.progress.jobs_running = 0
                if summary["status"] == "done":
                    self.progress.jobs_done += 1
                    pending.remove(si)
                elif summary["status"] == "stopped":
                    return

    def submit(self, client, pending: list[int]) -> dict[Any, int]:
        """Submit the pending seed jobs to Dask; the budget clock starts when the first of them runs."""
        return {self.resubmit(client, si): si for si in pending}

    def resubmit(self, client, si: int):
        """One more round (lineage) of seed job ``si`` on Dask."""
        self._rounds[si] = self._rounds.get(si, 0) + 1
        self._attempts_at_submit[si] = self._attempts.get(si, 0)
        tag = f"{self.out.resolve().name}-{os.getpid()}"
        return client.submit(run_seed_job, str(self.out.resolve()), si,
                             key=f"drivefuzz-{tag}-seed{si:03d}-round{self._rounds[si]}", pure=False, retries=1)


def _lineages_done(out: Path, si: int) -> int:
    """How many lineages seed job ``si`` has finished, as its checkpoint says (0 without a readable one)."""
    try:
        sched = json.loads((job_dir(out, si) / "checkpoint.json").read_text())["schedule"]
        return max(int(sched["lineages"]) - (sched.get("lineage") is not None), 0)
    except (OSError, ValueError, TypeError, KeyError, RecursionError):
        return 0


def run_on_dask(client, work: list[tuple[Campaign, list[int]]], max_running: int | None = None) -> None:
    """Run the pending jobs of several campaigns on one Dask client, following their journals.

    Campaigns start in order, at most ``max_running`` at once (all by default). Each
    one's wall-clock budget counts from when its first job begins to run (the job's
    attempt record in its journal), so a campaign whose jobs wait in the queue
    behind others' is not starved.
    Only this process writes the campaigns' indexes.
    """
    from distributed import wait

    threads = {w.get("nthreads", 1) for w in client.scheduler_info().get("workers", {}).values()}
    if any(not c.cfg.isolate for c, _ in work) and max(threads, default=1) > 1:
        raise InvalidConfig("--no-isolation", None, "Dask workers with several threads would share one libsumo "
                            "simulation", "workers started with --nthreads 1, or keep isolation on")
    queue = list(work)
    active: dict[Any, tuple[Campaign, int]] = {}
    running: list[Campaign] = []
    stopped: set[int] = set()
    try:
        while queue or active:
            if queue and any(c.stop_requested for c, _ in work):
                queue.clear()  # Ctrl-C: start nothing new
            while queue and (max_running is None or len(running) < max_running):
                campaign, pending = queue.pop(0)
                running.append(campaign)
                active.update({f: (campaign, si) for f, si in campaign.submit(client, pending).items()})
            if active:
                try:
                    wait(list(active), timeout=0.5, return_when="FIRST_COMPLETED")
                except TimeoutError:
                    pass
            for campaign in running:
                campaign.poll()
                if id(campaign) not in stopped and campaign.out_of_budget():
                    campaign.request_stop()
                    stopped.add(id(campaign))
            for fut in [f for f in active if f.done()]:
                campaign, si = active.pop(fut)
                try:
                    summary = fut.result()
                except Exception as exc:  # noqa: BLE001 - e.g. KilledWorker: report it, keep the rest going
                    campaign.failed_jobs[si] = f"{type(exc).__name__}: {exc}"
                    continue
                if summary["status"] == "done":
                    campaign.progress.jobs_done += 1
                elif summary["status"] == "yielded" and not campaign.out_of_budget():
                    active[campaign.resubmit(client, si)] = (campaign, si)
            for campaign in list(running):
                left = [si for c, si in active.values() if c is campaign]
                campaign.progress.jobs_running = campaign.jobs_running(left)
                campaign.on_progress(campaign.progress)
                if not left:
                    campaign.poll()  # what the last jobs journalled after the poll above
                    running.remove(campaign)
    except BaseException:  # Ctrl-C twice, or the client lost the scheduler: stop the jobs, keep their work
        for campaign, _ in work:
            campaign.request_stop()
        raise


def open_index(path: Path) -> sqlite3.Connection:
    """The campaign's index, emptied for a rebuild from the journals.

    The index is derived data: one that SQLite cannot read (a torn or foreign file)
    is deleted and made anew; something else at its path (a folder) is moved aside
    to ``index.sqlite.broken``.
    """
    for attempt in range(2):
        db = None
        try:
            if path.is_dir():
                raise sqlite3.DatabaseError("a folder, not a database")
            db = sqlite3.connect(path)
            # rebuilt from the journals at every start: a commit need not wait for the disk (fsync)
            db.execute("PRAGMA synchronous=OFF")
            db.executescript("DROP TABLE IF EXISTS executions;" + SCHEMA)
            return db
        except sqlite3.DatabaseError as exc:
            if db is not None:
                db.close()
            if attempt:
                raise InvalidConfig(str(path), None, f"cannot rebuild the index ({exc})",
                                    "a campaign folder you may write") from None
            _discard_index(path)
    raise AssertionError("unreachable")


def _discard_index(path: Path) -> None:
    import shutil

    if path.is_dir():
        aside = path.with_name(path.name + ".broken")
        if aside.is_dir():
            shutil.rmtree(aside, ignore_errors=True)
        else:
            aside.unlink(missing_ok=True)
        os.replace(path, aside)
    else:
        path.unlink(missing_ok=True)
    for suffix in ("-journal", "-wal", "-shm"):
        path.with_name(path.name + suffix).unlink(missing_ok=True)


#: what every journal record of an execution's end must carry, and of which type
_END_KEYS = {"key": str, "seed_index": int, "cycle": int, "hash": str}


def journal_problem(rec: Any) -> str | None:
    """Why a journal record cannot be used (None when it can)."""
    if not isinstance(rec, dict) or not isinstance(rec.get("event"), str):
        return "not a JSON object with an event"
    if rec["event"] == "start" and not isinstance(rec.get("key"), str):
        return "a start record without its key"
    if rec["event"] != "end":
        return None
    for key, typ in _END_KEYS.items():
        if not isinstance(rec.get(key), typ) or isinstance(rec.get(key), bool):
            return f"an end record whose {key!r} is missing or not a {typ.__name__}"
    for col in ("finding", "incident", "error"):
        folder = rec.get(col)
        if folder is not None and (not isinstance(folder, str) or Path(folder).is_absolute()
                                   or ".." in Path(folder).parts):
            return f"an end record whose {col} is not a folder of the campaign"
    for _, key in COLUMNS:
        if key not in ("components", "timings") and not isinstance(rec.get(key), (str, int, float, type(None))):
            return f"an end record whose {key!r} is not a plain value"
    return None


def check_journals(out: Path, n_seeds: int) -> None:
    """Raise InvalidConfig naming the journal and line that a resumed job could not read."""
    for si in range(n_seeds):
        path = job_dir(out, si) / "journal.jsonl"
        if not path.is_file():
            continue
        try:
            text = path.read_bytes().decode("utf-8")
        except UnicodeDecodeError:
            raise InvalidConfig(str(path), None, "not a text file", "the journal a seed job wrote") from None
        except OSError as exc:
            raise InvalidConfig(str(path), None, f"cannot read ({exc.strerror})") from None
        for n, line in enumerate(text.splitlines(), 1):
            try:
                rec = json.loads(line)
            except (ValueError, RecursionError):
                continue  # a line torn by a kill: the job skips it
            problem = journal_problem(rec)
            if problem is not None:
                raise InvalidConfig(str(path), f"line {n}", problem, "the journal a seed job wrote") from None


def load_campaign(out: str | os.PathLike) -> tuple[list[Scenario], FuzzConfig, list[str]]:
    """Seeds, configuration and command line of an existing output directory (for --resume).

    Everything is checked here, so that a damaged (or hostile) manifest or journal is
    one error naming the file, not a failure in the middle of a seed job.
    """
    from pydantic import ValidationError

    from drivefuzz.campaign.configfile import ManifestFile, pydantic_error, read_data_file

    out = Path(out)
    path = out / "manifest.json"
    if not path.is_file():
        raise InvalidConfig(str(out), None, "not a drivefuzz output directory (no manifest.json)",
                            "a directory written by 'drivefuzz fuzz -o'")
    data = read_data_file(path, "JSON")
    try:
        manifest = ManifestFile.model_validate(data)
    except ValidationError as exc:
        raise pydantic_error(str(path), exc, ManifestFile) from None
    seeds = [load_scenario(out / s) for s in manifest.seeds]
    try:
        cfg = FuzzConfig.from_json(data["config"])
    except (KeyError, ValueError, TypeError) as exc:
        raise InvalidConfig(str(path), "config", f"unreadable ({type(exc).__name__}: {exc})",
                            "a manifest.json written by 'drivefuzz fuzz'") from None
    cfg.oracles.instantiate(source=f"{path}: config.oracles")
    check_journals(out, len(seeds))
    return seeds, cfg, list(manifest.command)


def format_duration(seconds: float | None) -> str:
    """``1h2m``, ``3m5s``, ``42s``: the inverse of :func:`parse_duration`."""
    if seconds is None:
        return "none"
    m, s = divmod(int(round(seconds)), 60)
    h, m = divmod(m, 60)
    return (f"{h}h" if h else "") + (f"{m}m" if m else "") + (f"{s}s" if s or not (h or m) else "")
