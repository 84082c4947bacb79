"""Batch campaigns: a matrix of networks x strategies x ADS configurations x campaign seeds, from one TOML file.

``drivefuzz campaign CAMPAIGN.toml -o DIR`` runs every cell of the matrix as its
own fuzz campaign (``DIR/cells/<cell>/``, the same layout as ``drivefuzz fuzz -o``)
on one Dask client, and writes ``DIR/results.csv`` and ``DIR/results.md``: one row
per cell. ``drivefuzz campaign --resume DIR`` continues it. Example::

    [campaign]
    budget = "10m"            # wall-clock budget of each cell (and/or max_execs)
    cycles = 10
    population = 8
    seeds_per_network = 8     # seed missions per network (generated when missing)
    seeds = "../seeds"        # optional: a folder with seeds/<net>/ per network (default: next to the
                              # network, <its folder>/../seeds/<net>/, then ./seeds/<net>/)

    [matrix]
    networks = ["networks/town.net.xml", "networks/highway.net.xml"]
    strategies = ["all", "entropy"]
    seeds = [0, 1, 2]         # campaign RNG seeds: repetitions
    ads = [{name = "ego"}, {name = "ego", options = {fault = "speeding"}}]

    [run]
    where = "slurm"           # local | tcp://HOST:PORT | scheduler.json | slurm | pbs | sge | lsf
    jobs = 2                  # local workers (where = "local")
    cells_at_once = 4         # cells running at the same time (default: all)

    [cluster]                 # batch systems only: see drivefuzz.campaign.cluster.BatchSpec
    queue = "normal"
    cores = 16
    memory = "32GB"
    walltime = "04:00:00"
    max_jobs = 10
    prologue = ["source ~/venvs/drivefuzz/bin/activate"]

    [oracles.speeding]        # oracle settings for every cell, as in drivefuzz fuzz --config
    tolerance = 0.5
"""

from __future__ import annotations

import csv
import hashlib
import itertools
import json
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from drivefuzz.campaign.cluster import BATCH_SYSTEMS, BatchSpec
from drivefuzz.campaign.config import FINISHED
from drivefuzz.campaign.configfile import MAX_EXEC_TIMEOUT_S
from drivefuzz.errors import InvalidConfig
from drivefuzz.search.mutate import MutationConfig
from drivefuzz.search.quality import QualityConfig
from drivefuzz.scenario import AdsSpec

STRATEGIES = ("all", "congestion", "entropy", "instability", "maneuver", "mix")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class CampaignSection(_Strict):
    budget: str | None = Field(default=None, description="per cell, e.g. 10m")
    max_execs: int | None = Field(default=None, ge=1, description="per cell")
    cycles: int = Field(default=10, ge=1)
    population: int = Field(default=8, ge=1)
    seeds_per_network: int = Field(default=8, ge=1)
    seeds: str | None = Field(default=None, description="a folder of seed folders, one per network name "
                              "(<seeds>/<net>/NNN/); default: <network's folder>/../seeds/<net>/, then ./seeds/<net>/")
    time_limit: float | None = Field(default=None, gt=0, le=MAX_EXEC_TIMEOUT_S)
    continue_after_finding: bool = False
    no_feedback: bool = False
    feedback: Literal["risk", "paper", "random"] = "risk"
    exec_timeout: float = Field(default=300.0, gt=0, le=MAX_EXEC_TIMEOUT_S)


class MatrixSection(_Strict):
    networks: list[str] = Field(min_length=1)
    strategies: list[str] = Field(default_factory=lambda: ["all"], min_length=1)
    seeds: list[int] = Field(default_factory=lambda: [0], min_length=1)
    ads: list[AdsSpec] = Field(default_factory=lambda: [AdsSpec()], min_length=1)


class RunSection(_Strict):
    where: str = "local"
    jobs: int = Field(default=2, ge=1)
    cells_at_once: int | None = Field(default=None, ge=1)


class CampaignFile(_Strict):
    campaign: CampaignSection = Field(default_factory=CampaignSection)
    matrix: MatrixSection
    run: RunSection = Field(default_factory=RunSection)
    cluster: BatchSpec = Field(default_factory=BatchSpec)
    oracles: dict[str, dict[str, Any]] = Field(default_factory=dict)
    mutation: MutationConfig = Field(default_factory=MutationConfig)
    quality: QualityConfig = Field(default_factory=QualityConfig)

    @property
    def seeds_root(self) -> Path | None:
        return Path(self.campaign.seeds) if self.campaign.seeds else None


def load_campaign_file(path: str | Path) -> CampaignFile:
    """Parse and validate a campaign file; every mistake is one line naming the file and the field."""
    path = Path(path)
    if not path.is_file():
        raise InvalidConfig(str(path), None, "no such campaign file", "a TOML file with [matrix] networks = [...]")
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InvalidConfig(str(path), None, f"cannot parse ({exc})", "valid TOML") from None
    except RecursionError:
        raise InvalidConfig(str(path), None, "cannot parse (nested too deeply)", "valid TOML") from None
    try:
        spec = CampaignFile.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        raise InvalidConfig(str(path), ".".join(str(p) for p in err["loc"]), err["msg"]) from None
    for s in spec.matrix.strategies:
        if s not in STRATEGIES:
            raise InvalidConfig(str(path), "matrix.strategies", f"unknown strategy {s!r}", ", ".join(STRATEGIES))
    where = spec.run.where
    if where != "local" and where not in BATCH_SYSTEMS and "://" not in where and not where.endswith(".json"):
        raise InvalidConfig(str(path), "run.where", f"cannot use {where!r}",
                            "local, tcp://HOST:PORT, a scheduler .json file, " + ", ".join(BATCH_SYSTEMS))
    base = path.parent
    nets = []
    for n in spec.matrix.networks:
        p = Path(n) if Path(n).is_absolute() or Path(n).exists() else base / n
        if not p.is_file():
            raise InvalidConfig(str(path), "matrix.networks", f"no such network {n!r}", "paths to .net.xml files")
        nets.append(str(p.resolve()))
    spec.matrix.networks = nets
    if spec.campaign.seeds is not None:
        root = Path(spec.campaign.seeds) if Path(spec.campaign.seeds).is_absolute() else base / spec.campaign.seeds
        if not root.is_dir():
            raise InvalidConfig(str(path), "campaign.seeds", f"no such folder {spec.campaign.seeds!r}",
                                "a folder with one folder of seeds per network name (seeds/<net>/000/...)")
        spec.campaign.seeds = str(root.resolve())
    from drivefuzz.ads import load_ads
    from drivefuzz.campaign.fuzz import parse_duration

    parse_duration(spec.campaign.budget, source=f"{path}: campaign.budget")
    for ads in spec.matrix.ads:  # an unknown ADS or option is a mistake in this file, not a finding
        try:
            load_ads(ads.name, ads.options)
        except InvalidConfig as exc:
            raise InvalidConfig(str(path), "matrix.ads", exc.problem, exc.valid) from None
    names = [c[0] for c in cells(spec)]
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        raise InvalidConfig(str(path), "matrix", f"cells would share the directory cells/{clash[0]}",
                            "distinct network file names, strategies, ADS entries and seeds")
    return spec


def cell_label(network: str, strategy: str, ads: AdsSpec, seed: int) -> str:
    """The cell as a person reads it in the results: ``town all ego fault=no_traffic_lights seed 0``."""
    opts = "".join(f" {k}={v}" for k, v in sorted(ads.options.items()))
    return f"{Path(network).name.split('.')[0]} {strategy} {ads.name}{opts} seed {seed}"


def cell_name(network: str, strategy: str, ads: AdsSpec, seed: int) -> str:
    """The cell's folder under ``cells/``: safe on any filesystem (options become a short hash)."""
    opts = ""
    if ads.options:
        opts = "-" + hashlib.sha1(json.dumps(ads.options, sort_keys=True).encode()).hexdigest()[:6]
    return f"{Path(network).name.split('.')[0]}-{strategy}-{ads.name.replace(':', '~')}{opts}-s{seed}"


def cells(spec: CampaignFile) -> list[tuple[str, str, str, AdsSpec, int]]:
    """(name, network, strategy, ads, seed) of every cell, in a fixed order."""
    m = spec.matrix
    return [(cell_name(n, s, a, k), n, s, a, k) for n, s, a, k in itertools.product(m.networks, m.strategies, m.ads, m.seeds)]


#: the warning of a cell that ran nothing (its jobs never got a worker, or failed before their first execution)
NO_EXECUTIONS = "WARNING: no executions (resume the batch to run it)"


def cell_spent(cell_dir: Path) -> bool:
    """Whether a cell ended its run by spending its budget. One that ran nothing did not (a starved cell of an
    earlier version wrote finished.json with 0 executions): a resume runs it."""
    try:
        finished = json.loads((cell_dir / FINISHED).read_text())
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(finished, dict) and finished.get("executions") != 0


def results_table(out: Path, spec: CampaignFile) -> list[dict[str, Any]]:
    """One row per cell from the cells' own directories (so it is right after a resume too)."""
    import sqlite3

    rows = []
    for name, network, strategy, ads, seed in cells(spec):
        d = out / "cells" / name
        row: dict[str, Any] = {"cell": cell_label(network, strategy, ads, seed), "folder": f"cells/{name}",
                               "network": Path(network).name, "strategy": strategy, "ads": ads.name,
                               "ads_options": json.dumps(ads.options, sort_keys=True), "seed": seed,
                               "execs": 0, "findings": 0, "distinct": 0, "incidents": 0, "errors": 0, "by_oracle": "",
                               "status": "not started"}
        if (d / "index.sqlite").exists():
            try:
                db = sqlite3.connect(d / "index.sqlite")
                row["execs"] = db.execute("SELECT COUNT(*) FROM executions").fetchone()[0]
                db.close()
            except sqlite3.DatabaseError:  # rebuilt from the journals when the cell runs again
                row["execs"] = "?"
            from drivefuzz.campaign.fuzz import load_finding

            found = [load_finding(f) for f in sorted((d / "findings").iterdir())
                     if not f.name.startswith(".") and (f / "verdict.json").exists()]  # not half-written ones
            row["findings"] = sum(json.loads(f.path.joinpath("hits.json").read_text())["count"]
                                  if f.path.joinpath("hits.json").exists() else 1 for f in found)
            row["distinct"] = len(found)  # one folder per signature
            row["incidents"] = sum(1 for f in (d / "incidents").glob("*/verdict.json")) if (d / "incidents").is_dir() else 0
            # executions the tool failed (SUMO, drivefuzz, an oracle plugin): signatures, not findings
            row["errors"] = sum(1 for f in (d / "errors").glob("*/verdict.json")) if (d / "errors").is_dir() else 0
            counts: dict[str, int] = {}
            for f in found:
                counts[f.misbehavior.oracle] = counts.get(f.misbehavior.oracle, 0) + 1
            row["by_oracle"] = " ".join(f"{k}:{v}" for k, v in sorted(counts.items()))
            manifest = json.loads((d / "manifest.json").read_text())
            done = sum((d / "jobs" / f"{i:03d}" / "summary.json").exists() for i in range(len(manifest["seeds"])))
            if cell_spent(d):  # the run ended by spending its budget (or its single pass)
                row["status"] = "done"
            else:
                row["status"] = "done" if done == len(manifest["seeds"]) else f"{done}/{len(manifest['seeds'])} seeds done"
        if row["execs"] == 0:
            row["status"] += f"; {NO_EXECUTIONS}"
        rows.append(row)
    return rows


def write_results(out: Path, rows: list[dict[str, Any]]) -> None:
    from drivefuzz.storage import atomic_write_text

    if not rows:
        return
    import io

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
    atomic_write_text(out / "results.csv", buf.getvalue())
    cols = ["cell", "folder", "execs", "findings", "distinct", "incidents", "errors", "by_oracle", "status"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(str(r[c]) for c in cols) + " |" for r in rows]
    from drivefuzz.campaign.compare import comparison_markdown, configurations, write_batch_report

    lines += comparison_markdown(configurations(rows))
    atomic_write_text(out / "results.md", "\n".join(lines) + "\n")
    write_batch_report(out, rows)
