"""The feedback-driven fuzz loop (the paper's Algorithm 1) and its output directory.

For each seed: ``cycles`` times, ``generate`` adds one actor or puddle to the
current scenario, then ``population`` mutants are executed; a mutant that makes
an oracle fire is a finding (and ends that seed's campaign unless
``continue_after_finding``); otherwise the mutant with the lowest driving-quality
score becomes the next scenario (a random one with ``feedback=False``, the
paper's baseline).

Determinism: every random draw comes from ``Random(f"{seed}/{seed_index}/{cycle}/{member}")``,
so a campaign is a pure function of its seed and configuration, and resuming
re-creates exactly the executions that were not finished.

Output directory (a person opens it without drivefuzz)::

    manifest.json           version, command line, configuration, seed
    index.sqlite            one row per execution (written by one process only)
    journal.jsonl           append-only log of executions (fsync'd): the source of truth for --resume
    checkpoint.json         where each seed's campaign stands (atomic)
    corpus/<hash>/          every successor scenario (SUMO files + manifest)
    findings/<n>-<oracle>-<hash>/   SUMO files, scenario manifest, trace/, verdict.json, replay.sh
"""

from __future__ import annotations

import json
import os
import random
import shlex
import sqlite3
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import drivefuzz
from drivefuzz.errors import InvalidConfig
from drivefuzz.execute import Execution, execute
from drivefuzz.mutate import MutationConfig, Mutator
from drivefuzz.oracle import Misbehavior, OracleSettings
from drivefuzz.quality import QualityConfig, score_trace
from drivefuzz.roadmap import load_roadmap
from drivefuzz.scenario import AdsSpec, Scenario
from drivefuzz.storage import atomic_dir, atomic_write_json, atomic_write_text
from drivefuzz.sumofiles import load_scenario, write_scenario

SCHEMA = """
CREATE TABLE IF NOT EXISTS executions (
    exec_id INTEGER PRIMARY KEY,
    seed_index INTEGER, cycle INTEGER, member INTEGER,
    scenario_hash TEXT, parent_hash TEXT, mutation TEXT, retries INTEGER,
    score REAL, components TEXT, verdict TEXT, termination TEXT, finding TEXT,
    frames INTEGER, wall_time REAL
);
"""


@dataclass
class FuzzConfig:
    cycles: int = 10
    population: int = 8
    strategy: str = "all"
    seed: int = 0
    budget_s: float | None = None
    max_execs: int | None = None
    feedback: bool = True
    continue_after_finding: bool = False
    ads: AdsSpec = field(default_factory=AdsSpec)
    oracles: OracleSettings = field(default_factory=OracleSettings)
    mutation: MutationConfig = field(default_factory=MutationConfig)
    quality: QualityConfig = field(default_factory=QualityConfig)
    time_limit: float | None = None  # override the seeds' simulated time limit [s]

    def to_json(self) -> dict[str, Any]:
        return {
            "cycles": self.cycles, "population": self.population, "strategy": self.strategy, "seed": self.seed,
            "budget_s": self.budget_s, "max_execs": self.max_execs, "feedback": self.feedback,
            "continue_after_finding": self.continue_after_finding, "ads": self.ads.model_dump(mode="json"),
            "oracles": self.oracles.settings, "mutation": self.mutation.model_dump(mode="json"),
            "quality": self.quality.model_dump(mode="json"), "time_limit": self.time_limit,
        }

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> "FuzzConfig":
        return cls(
            cycles=d["cycles"], population=d["population"], strategy=d["strategy"], seed=d["seed"],
            budget_s=d.get("budget_s"), max_execs=d.get("max_execs"), feedback=d.get("feedback", True),
            continue_after_finding=d.get("continue_after_finding", False),
            ads=AdsSpec.model_validate(d.get("ads", {})), oracles=OracleSettings(settings=d.get("oracles", {})),
            mutation=MutationConfig.model_validate(d.get("mutation", {})),
            quality=QualityConfig.model_validate(d.get("quality", {})), time_limit=d.get("time_limit"),
        )


@dataclass
class Finding:
    path: Path
    misbehavior: Misbehavior
    scenario_hash: str
    seed_index: int
    exec_id: int


@dataclass
class Progress:
    execs: int = 0
    findings: int = 0
    seed_index: int = 0
    cycle: int = 0
    best_score: float | None = None
    started: float = field(default_factory=time.monotonic)

    @property
    def rate(self) -> float:
        return self.execs / max(time.monotonic() - self.started, 1e-9)


def replay_command(finding_dir: Path) -> str:
    return f"drivefuzz replay {shlex.quote(str(finding_dir))}"


class Campaign:
    """One output directory; runs (or resumes) the loop over a list of seed scenarios."""

    def __init__(self, out: str | os.PathLike, seeds: Sequence[Scenario], config: FuzzConfig,
                 argv: Sequence[str] = (), on_progress: Callable[[Progress], None] | None = None):
        self.out = Path(out)
        self.seeds = list(seeds)
        self.cfg = config
        self.argv = list(argv)
        self.on_progress = on_progress or (lambda p: None)
        self.progress = Progress()
        self.findings: list[Finding] = []
        self.stop_requested = False

    # ------------------------------------------------------------- directory
    def _init_dir(self, resume: bool) -> dict[str, Any]:
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "corpus").mkdir(exist_ok=True)
        (self.out / "findings").mkdir(exist_ok=True)
        seeds_dir = self.out / "seeds"
        if not resume:
            for i, sc in enumerate(self.seeds):
                write_scenario(sc, seeds_dir / f"{i:03d}")
            atomic_write_json(self.out / "manifest.json", {
                "drivefuzz": drivefuzz.__version__, "command": self.argv, "config": self.cfg.to_json(),
                "seed": self.cfg.seed, "seeds": [f"seeds/{i:03d}" for i in range(len(self.seeds))],
                "started": time.strftime("%Y-%m-%dT%H:%M:%S"),
            })
        self.db = sqlite3.connect(self.out / "index.sqlite")
        self.db.executescript(SCHEMA)
        ckpt_path = self.out / "checkpoint.json"
        ckpt = json.loads(ckpt_path.read_text()) if resume and ckpt_path.exists() else {}
        self.journal_path = self.out / "journal.jsonl"
        self.done: dict[str, dict[str, Any]] = {}
        if resume and self.journal_path.exists():
            for line in self.journal_path.read_text().splitlines():
                try:
                    rec = json.loads(line)
                except json.JSONDecodeError:  # a torn last line from a kill
                    continue
                self.done[rec["key"]] = rec
        self.progress.execs = len(self.done)
        for d in sorted((self.out / "findings").glob("*/verdict.json")):
            v = json.loads(d.read_text())
            self.findings.append(Finding(d.parent, Misbehavior.from_dict(v["misbehaviors"][0]), v["scenario_hash"],
                                         v.get("seed_index", 0), v.get("exec_id", 0)))
        self.progress.findings = len(self.findings)
        return ckpt

    def _journal(self, rec: dict[str, Any]) -> None:
        with open(self.journal_path, "a") as fh:
            fh.write(json.dumps(rec, sort_keys=True) + "\n")
            fh.flush()
            os.fsync(fh.fileno())

    def _index(self, rec: dict[str, Any]) -> None:
        self.db.execute(
            "INSERT OR REPLACE INTO executions VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (rec["exec_id"], rec["seed_index"], rec["cycle"], rec["member"], rec["hash"], rec["parent"],
             rec["mutation"], rec["retries"], rec["score"], json.dumps(rec["components"]), rec["verdict"],
             rec["termination"], rec["finding"], rec["frames"], rec["wall_time"]))
        self.db.commit()

    def _save_finding(self, ex: Execution, seed_index: int, exec_id: int) -> Finding:
        m = ex.misbehaviors[0]
        h = ex.scenario.content_hash()
        existing = next((f for f in self.findings if f.scenario_hash == h), None)
        if existing is not None:  # resumed: the same execution was already saved
            return existing
        path = self.out / "findings" / f"{len(self.findings):04d}-{m.oracle}-{h}"
        with atomic_dir(path) as tmp:
            write_scenario(ex.scenario, tmp)
            ex.trace.save(tmp / "trace")
            atomic_write_json(tmp / "verdict.json", {
                "misbehaviors": [x.as_dict() for x in ex.misbehaviors], "termination": ex.termination.value,
                "scenario_hash": h, "seed_index": seed_index, "exec_id": exec_id, "frames": ex.trace.n_frames,
                "oracles": self.cfg.oracles.settings, "drivefuzz": drivefuzz.__version__,
            })
            atomic_write_text(tmp / "replay.sh", "#!/bin/sh\n# Runs this finding again and checks it reproduces.\n"
                              'cd "$(dirname "$0")" && exec drivefuzz replay .\n')
            os.chmod(tmp / "replay.sh", 0o755)
        f = Finding(path, m, h, seed_index, exec_id)
        self.findings.append(f)
        self.progress.findings = len(self.findings)
        return f

    # ------------------------------------------------------------------ loop
    def run(self, resume: bool = False) -> list[Finding]:
        ckpt = self._init_dir(resume)
        cfg = self.cfg
        deadline = None if cfg.budget_s is None else time.monotonic() + cfg.budget_s
        start_seed = ckpt.get("seed_index", 0)
        exec_id = max((r["exec_id"] for r in self.done.values()), default=-1) + 1
        quality = cfg.quality
        for si in range(start_seed, len(self.seeds)):
            seed_sc = self.seeds[si]
            if cfg.time_limit:
                seed_sc = seed_sc.model_copy(update={"sim": seed_sc.sim.model_copy(update={"time_limit": cfg.time_limit})})
            seed_sc = seed_sc.model_copy(update={"ads": cfg.ads})
            rmap = load_roadmap(seed_sc.network_path())
            mutator = Mutator(rmap, cfg.mutation)
            current = seed_sc
            first_cycle = 0
            if ckpt.get("seed_index") == si and ckpt.get("current"):
                current = load_scenario(self.out / ckpt["current"]).model_copy(update={"ads": cfg.ads})
                first_cycle = ckpt.get("cycle", 0)
            self.progress.seed_index = si
            ended = False
            for cycle in range(first_cycle, cfg.cycles):
                self.progress.cycle = cycle
                rng = random.Random(f"{cfg.seed}/{si}/{cycle}/generate")
                gen = mutator.generate(current, cfg.strategy, rng)
                parent = gen.scenario
                population: list[tuple[float, Scenario]] = []
                for member in range(cfg.population):
                    if self._out_of_budget(deadline):
                        self._checkpoint(si, cycle, current)
                        return self.findings
                    key = f"{si}/{cycle}/{member}"
                    mrng = random.Random(f"{cfg.seed}/{si}/{cycle}/{member}")
                    mut = mutator.mutate(parent, mrng)
                    child = mut.scenario
                    if key in self.done:  # finished before a kill: reuse its result
                        rec = self.done[key]
                        if rec["score"] is not None:
                            population.append((rec["score"], child))
                        if rec["finding"] and not cfg.continue_after_finding:
                            ended = True
                            break
                        continue
                    description = f"{gen.description} | {mut.description}"
                    ex = execute(child, oracles=cfg.oracles.instantiate())
                    rec = {"key": key, "exec_id": exec_id, "seed_index": si, "cycle": cycle, "member": member,
                           "hash": child.content_hash(), "parent": current.content_hash(), "mutation": description,
                           "retries": gen.retries + mut.retries, "termination": ex.termination.value,
                           "frames": ex.trace.n_frames, "wall_time": round(ex.wall_time, 4), "finding": None,
                           "score": None, "components": {}, "verdict": "pass"}
                    if ex.misbehaviors:
                        finding = self._save_finding(ex, si, exec_id)
                        m = ex.misbehaviors[0]
                        rec.update(verdict=f"{m.oracle}/{m.kind}", finding=str(finding.path.relative_to(self.out)))
                    else:
                        q = score_trace(ex.trace, quality)
                        rec.update(score=q.score, components=q.as_dict())
                        population.append((q.score, child))
                        if self.progress.best_score is None or q.score < self.progress.best_score:
                            self.progress.best_score = q.score
                    self._journal(rec)
                    self._index(rec)
                    self.done[key] = rec
                    exec_id += 1
                    self.progress.execs += 1
                    self.on_progress(self.progress)
                    if rec["finding"] and not cfg.continue_after_finding:
                        ended = True
                        break
                if ended:
                    break
                if population:
                    if cfg.feedback:
                        current = min(population, key=lambda p: p[0])[1]
                    else:
                        current = random.Random(f"{cfg.seed}/{si}/{cycle}/select").choice(population)[1]
                    write_scenario(current, self.out / "corpus" / current.content_hash())
                self._checkpoint(si, cycle + 1, current)
            self._checkpoint(si + 1, 0, None)
        return self.findings

    def _out_of_budget(self, deadline: float | None) -> bool:
        if self.stop_requested:
            return True
        if deadline is not None and time.monotonic() >= deadline:
            return True
        return self.cfg.max_execs is not None and self.progress.execs >= self.cfg.max_execs

    def _checkpoint(self, si: int, cycle: int, current: Scenario | None) -> None:
        ref = None
        if current is not None:
            ref = f"corpus/{current.content_hash()}"
            if not (self.out / ref / "scenario.json").exists():
                write_scenario(current, self.out / ref)
        atomic_write_json(self.out / "checkpoint.json", {"seed_index": si, "cycle": cycle, "current": ref})


def load_campaign(out: str | os.PathLike) -> tuple[list[Scenario], FuzzConfig, list[str]]:
    """Seeds, configuration and command line of an existing output directory (for --resume)."""
    out = Path(out)
    path = out / "manifest.json"
    if not path.is_file():
        raise InvalidConfig(str(out), None, "not a drivefuzz output directory (no manifest.json)",
                            "a directory written by 'drivefuzz fuzz -o'")
    manifest = json.loads(path.read_text())
    seeds = [load_scenario(out / s) for s in manifest["seeds"]]
    return seeds, FuzzConfig.from_json(manifest["config"]), manifest.get("command", [])
