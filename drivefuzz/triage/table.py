"""A campaign directory read back for triage: its configuration, its executions, and one row per finding.

Used by ``drivefuzz findings OUT`` (the table to triage after a run) and by
:mod:`drivefuzz.triage.report`. Everything here reads files a campaign wrote
(``manifest.json``, ``index.sqlite``, ``finished.json``, the finding folders' ``verdict.json``
and ``hits.json``) and nothing else; a piece that is missing or unreadable shows as ``None``
(printed ``-``), so that a campaign stopped half-way, or written by an older drivefuzz, still
has a table.

Numbering: findings (and, separately, incidents) are numbered from 0 in the order they were
**first found**, i.e. by the ``exec_id`` of their first hit in the index; folders the index does
not mention come last, in the order of the execution key their verdict names.
"""

from __future__ import annotations

import json
import sqlite3
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from drivefuzz.errors import InvalidConfig

FINDINGS, INCIDENTS, ERRORS = "findings", "incidents", "errors"  # errors: of the tool (triage.store), not findings
#: per-execution timings that add up to its share of the campaign's wall time [s]
#: (``storage`` includes triage; the simulation's own parts are inside ``wall_time``)
ELAPSED_PARTS = ("isolation", "mutation", "quality", "storage")


@dataclass(frozen=True)
class FindingRow:
    """One finding (or incident) folder, as the triage table shows it."""

    number: int
    folder: str  # relative to the campaign directory: findings/<signature>-<oracle>
    signature: str  # the signature's key
    label: str  # one-line description of the signature
    verdict: str  # oracle/kind
    fault: str  # ego | other | unclear | -
    reason: str  # the attribution's reason
    hits: int  # executions that hit this signature
    reproduced: int | None  # of ``runs`` perturbed reruns
    runs: int | None
    robust: bool | None
    first_exec: int | None  # exec_id of the first hit in the index
    first_key: str  # execution key of the first hit (seed/lineage/cycle/member)
    first_time_s: float | None  # [s] of campaign time (executions before it, summed) when it was first hit
    sim_time_s: float | None  # [s] simulated time of the event in its execution
    replay: str  # the command that replays it
    incident: bool = False
    minimal: str | None = None  # the shrunk reproducer: what it kept, and the command that replays it
    crash_type: str | None = None  # a collision with a vehicle: AV-Fuzzer's crash type (triage/crashtype.py)
    rule: str = ""  # the attribution rule that gave the verdict (triage.attribute.RULES; "" in older campaigns)

    @property
    def minimal_replay(self) -> str | None:
        return None if self.minimal is None else self.minimal.split(": ", 1)[1]

    @property
    def reproduction(self) -> str:
        if self.runs is None or self.reproduced is None:
            return "-"
        return f"{self.reproduced}/{self.runs} {'robust' if self.robust else 'knife-edge'}"

    def as_json(self) -> dict[str, Any]:
        return {**asdict(self), "reproduction": self.reproduction}


@dataclass(frozen=True)
class Execution:
    """One row of the index, the part the report plots."""

    exec_id: int
    key: str
    risk: float | None
    score: float | None
    verdict: str | None
    fault: str | None
    folder: str | None
    elapsed_s: float  # [s] this execution's share of the campaign's wall time (estimated from its timings)


@dataclass
class CampaignInfo:
    """What the campaign directory says about the run as a whole."""

    out: Path
    manifest: dict[str, Any]
    executions: list[Execution]
    stop_reason: str | None
    wall_s: float | None  # [s] from the manifest's start to the last journal write (None: not known)
    finished: dict[str, Any] = field(default_factory=dict)

    @property
    def config(self) -> dict[str, Any]:
        c = self.manifest.get("config")
        return c if isinstance(c, dict) else {}

    @property
    def rate(self) -> float | None:
        """Executions per wall-clock second."""
        if not self.wall_s or not self.executions:
            return None
        return len(self.executions) / self.wall_s

    def verdict_counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for e in self.executions:
            v = e.verdict or "pass"
            out[v] = out.get(v, 0) + 1
        return dict(sorted(out.items(), key=lambda kv: (-kv[1], kv[0])))


def check_campaign_dir(out: str | Path) -> Path:
    out = Path(out)
    if not out.is_dir() or not ((out / "manifest.json").is_file() or (out / FINDINGS).is_dir()):
        raise InvalidConfig(str(out), None, "not a campaign directory (no manifest.json, no findings/)",
                            "a directory written by 'drivefuzz fuzz -o OUT'")
    return out


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError, RecursionError, UnicodeDecodeError):
        return None


def read_executions(out: Path) -> list[Execution]:
    """Every execution in the index, by exec_id (empty if there is no readable index)."""
    path = out / "index.sqlite"
    if not path.is_file():
        return []
    try:
        db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            rows = db.execute("SELECT exec_id, key, risk, score, verdict, fault, COALESCE(finding, incident), "
                              "wall_time, timings FROM executions ORDER BY exec_id").fetchall()
        finally:
            db.close()
    except sqlite3.Error:
        return []
    out_rows = []
    for exec_id, key, risk, score, verdict, fault, folder, wall, timings in rows:
        t = _read_timings(timings)
        elapsed = float(wall or 0.0) + sum(float(t.get(k) or 0.0) for k in ELAPSED_PARTS)
        out_rows.append(Execution(int(exec_id), str(key or ""), _num(risk), _num(score),
                                  None if verdict in (None, "", "pass") else str(verdict), fault, folder, elapsed))
    return out_rows


def _read_timings(text: Any) -> dict[str, Any]:
    try:
        t = json.loads(text) if text else {}
    except (TypeError, ValueError):
        return {}
    return t if isinstance(t, dict) else {}


def _num(v: Any) -> float | None:
    try:
        return None if v is None else float(v)
    except (TypeError, ValueError):
        return None


def _wall_span(out: Path, manifest: dict[str, Any]) -> float | None:
    """[s] from the manifest's ``started`` to the newest journal write (one run's span, roughly)."""
    import time

    started = manifest.get("started")
    if not isinstance(started, str):
        return None
    try:
        t0 = time.mktime(time.strptime(started, "%Y-%m-%dT%H:%M:%S"))
    except ValueError:
        return None
    last = [p.stat().st_mtime for p in (out / "jobs").glob("*/journal.jsonl")]
    return max(max(last) - t0, 1.0) if last else None


def load_campaign_info(out: str | Path) -> CampaignInfo:
    out = check_campaign_dir(out)
    manifest = _read_json(out / "manifest.json")
    manifest = manifest if isinstance(manifest, dict) else {}
    finished = _read_json(out / "finished.json")
    finished = finished if isinstance(finished, dict) else {}
    reason = finished.get("reason") if isinstance(finished.get("reason"), str) else None
    return CampaignInfo(out, manifest, read_executions(out), reason, _wall_span(out, manifest), finished)


def finding_rows(out: str | Path, incidents: bool = False,
                 executions: list[Execution] | None = None, errors: bool = False) -> list[FindingRow]:
    """One row per finding folder (or incident folder, or with ``errors`` a folder of an execution the tool
    failed: SUMO, drivefuzz or an oracle plugin; not a finding), numbered in the order they were first found."""
    from drivefuzz.campaign.fuzz import replay_command

    out = check_campaign_dir(out)
    sub = ERRORS if errors else INCIDENTS if incidents else FINDINGS
    execs = read_executions(out) if executions is None else executions
    first: dict[str, tuple[int, str, float]] = {}  # folder -> (exec_id, key, campaign time) of its first hit
    counts: dict[str, int] = {}
    clock = 0.0
    for e in execs:
        clock += e.elapsed_s
        if e.folder:
            counts[e.folder] = counts.get(e.folder, 0) + 1
            first.setdefault(e.folder, (e.exec_id, e.key, clock))
    folders = [p for p in sorted((out / sub).glob("*")) if p.is_dir() and not p.name.startswith(".")]
    rows = []
    for p in folders:
        rel = f"{sub}/{p.name}"
        v = _read_json(p / "verdict.json")
        v = v if isinstance(v, dict) else {}
        rows.append((rel, p, v))
    never = (1 << 62,)

    def order(item):
        rel, _p, v = item
        hit = first.get(rel)
        return (hit[0],) if hit else (*never, str(v.get("key", "")), rel)

    table = []
    for n, (rel, p, v) in enumerate(sorted(rows, key=order)):
        table.append(_row(n, rel, p, v, first.get(rel), counts.get(rel), incidents, replay_command))
    return table


def _row(n: int, rel: str, path: Path, v: dict[str, Any], first, indexed_hits, incident: bool,
         replay_command) -> FindingRow:
    sig = v.get("signature") if isinstance(v.get("signature"), dict) else {}
    att = v.get("attribution") if isinstance(v.get("attribution"), dict) else {}
    rep = v.get("reproduction") if isinstance(v.get("reproduction"), dict) else {}
    mbs = v.get("misbehaviors") if isinstance(v.get("misbehaviors"), list) else []
    m = mbs[0] if mbs and isinstance(mbs[0], dict) else {}
    verdict = f"{m.get('oracle', '?')}/{m.get('kind', '?')}" if m else "-"
    hits_file = _read_json(path / "hits.json")
    hits = hits_file.get("count") if isinstance(hits_file, dict) else None
    if not isinstance(hits, int):
        hits = indexed_hits or 1
    ads = v.get("ads") if isinstance(v.get("ads"), dict) else {}
    frame = m.get("frame")
    return FindingRow(
        number=n, folder=rel, signature=str(sig.get("key") or path.name.split("-", 1)[0]),
        label=str(sig.get("label") or verdict), verdict=verdict, fault=str(att.get("fault") or sig.get("fault") or "-"),
        reason=str(att.get("reason") or "-"), hits=hits,
        reproduced=rep.get("reproduced") if isinstance(rep.get("reproduced"), int) else None,
        runs=rep.get("runs") if isinstance(rep.get("runs"), int) else None,
        robust=rep.get("robust") if isinstance(rep.get("robust"), bool) else None,
        first_exec=first[0] if first else None, first_key=first[1] if first else str(v.get("key") or "-"),
        first_time_s=round(first[2], 2) if first else None,
        sim_time_s=_num(m.get("time")) if isinstance(frame, int) and frame >= 0 else None,
        replay=replay_command(path, ads.get("name") if isinstance(ads.get("name"), str) else None),
        incident=incident, minimal=_minimal(path, v, ads.get("name") if isinstance(ads.get("name"), str) else None,
                                            replay_command),
        crash_type=v["crash_type"] if isinstance(v.get("crash_type"), str) else None,
        rule=att["rule"] if isinstance(att.get("rule"), str) else "",
    )


def _minimal(path: Path, v: dict[str, Any], ads_name: str | None, replay_command) -> str | None:
    """'<sizes before -> after>: <replay command>' of the finding's minimal reproducer, if it has one."""
    shrink = v.get("shrink")
    if not isinstance(shrink, dict) or not (path / "minimal" / "verdict.json").exists():
        return None
    b = shrink.get("before") if isinstance(shrink.get("before"), dict) else {}
    a = shrink.get("after") if isinstance(shrink.get("after"), dict) else {}
    sizes = ", ".join(f"{k} {b.get(k)} -> {a.get(k)}" for k in ("actors", "puddles", "knobs", "sim_seconds"))
    return f"{sizes}: {replay_command(path / 'minimal', ads_name)}"


@dataclass(frozen=True)
class BugGroup:
    """Findings that one attribution rule gave the same verdict on (same oracle, kind and fault): likely one
    bug, seen in as many situations (signatures) as it has rows."""

    title: str  # "<oracle>/<kind>: <what the rule says happened>"
    rows: tuple[FindingRow, ...]

    @property
    def hits(self) -> int:
        return sum(r.hits for r in self.rows)

    @property
    def numbers(self) -> str:
        """The findings' numbers, '#1 #3'."""
        return " ".join(f"#{r.number}" for r in self.rows)

    def line(self) -> str:
        n = len(self.rows)
        return (f"{n:>3} signature{'s' if n != 1 else ' '} {self.hits:>5} hit{'s' if self.hits != 1 else ' '}  "
                f"{self.title}  ({self.numbers})")


def bug_groups(rows) -> list[BugGroup]:
    """The rows (:class:`FindingRow`, or anything with its ``number``, ``hits``, ``verdict``, ``fault`` and
    ``rule``) grouped by :func:`~drivefuzz.triage.attribute.bug_class`: the largest group first, groups of one
    size in the order of their first row, and each row in its place within its group."""
    from drivefuzz.triage.attribute import bug_class

    groups: dict[str, tuple[str, list[FindingRow]]] = {}
    for r in rows:
        key, title = bug_class(r.verdict, r.fault, r.rule)
        groups.setdefault(key, (title, []))[1].append(r)
    out = [BugGroup(title, tuple(members)) for title, members in groups.values()]
    return sorted(out, key=lambda g: -len(g.rows))


def format_groups(rows) -> str:
    """The likely bugs behind ``rows`` (the ``findings`` command prints them under the table)."""
    groups = bug_groups(rows)
    if not groups:
        return ""
    return "\n".join([f"likely bugs: {len(groups)} (findings that one attribution rule gave the same verdict, "
                      f"by oracle and kind)"] + [f"  {g.line()}" for g in groups])


def format_table(rows: list[FindingRow], title: str) -> str:
    """The rows as a fixed-width text table (the ``findings`` command's output)."""
    if not rows:
        return f"{title}: none"
    lines = [f"{title}:", f"{'#':>3}  {'hits':>5}  {'fault':<7} {'reproduced':<16} {'first seen':<22} folder",
             f"{'':>5}signature"]
    for r in rows:
        seen = f"exec {r.first_exec} ({r.first_key})" if r.first_exec is not None else f"({r.first_key})"
        lines.append(f"{r.number:>3}  {r.hits:>5}  {r.fault:<7} {r.reproduction:<16} {seen:<22} {r.folder}")
        lines.append(f"{'':>5}{r.label}")
    return "\n".join(lines)
