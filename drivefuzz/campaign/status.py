"""What a person watching a running campaign sees: a status screen on a terminal, plain lines elsewhere.

In the spirit of AFL's status screen: how long it has run and how much budget is
left, executions per second, where the search is (seed, lineage, cycle), the best
risk so far, the findings by signature with their hits, the last finding, and how
many workers are busy. ``drivefuzz fuzz`` and ``drivefuzz campaign`` (``cli/``)
hand a :class:`StatusPrinter` their campaigns; on a terminal it redraws a rich
table in place (``rich.live.Live``), elsewhere (a log file, a pipe, CI) it prints
one plain line every :data:`PLAIN_EVERY_S` seconds, so that a log stays readable.
"""

from __future__ import annotations

import itertools
import sys
import time
from dataclasses import dataclass
from typing import Any, Sequence, TextIO

from drivefuzz.campaign.fuzz import format_duration

#: [s] between two plain lines (not a terminal)
PLAIN_EVERY_S = 10.0
#: [s] between two redraws of the screen
SCREEN_EVERY_S = 0.25
#: signatures listed on the screen (the rest are counted)
SHOWN_SIGNATURES = 8


@dataclass(frozen=True)
class Status:
    """One reading of the campaigns' progress (several campaigns: the cells of a batch, summed)."""

    elapsed_s: float  # [s] since the first job began to run
    remaining: str  # what is left of the budget, in words ("-" without one)
    execs: int
    rate: float  # [executions/s] of this run
    where: str  # the last execution's seed, lineage and cycle
    best_risk: float | None
    findings: tuple[tuple[str, int], ...]  # (signature, hits) of the findings (the ego's fault), first found first
    incidents: int
    last_finding: str | None
    busy: int  # workers running a job now
    workers: int | None  # workers there are (None: a scheduler's, not known here)
    jobs: str  # "3/8 done"
    coverage: str = "-"  # interaction coverage: "N/M cells (P %)" (drivefuzz.triage.coverage)
    errors: int = 0  # signatures of executions the tool failed (SUMO, drivefuzz, an oracle plugin): not findings


def read_status(campaigns: Sequence[Any], workers: int | None) -> Status:
    """The :class:`Status` of ``campaigns`` (:class:`drivefuzz.campaign.fuzz.Campaign`) now."""
    now = time.monotonic()
    ps = [c.progress for c in campaigns]
    started = min((p.started for p in ps), default=now)
    new_execs = sum(p.new_execs for p in ps)
    last = max(ps, key=lambda p: p.last_exec_at, default=None)
    where = "-" if last is None or last.last_exec_at == 0.0 else (
        f"seed {last.seed_index}, lineage {last.lineage}, cycle {last.cycle}")
    risks = [p.best_risk for p in ps if p.best_risk is not None]
    found = [f for c in campaigns for f in c.findings]
    newest = max(ps, key=lambda p: p.last_finding_at, default=None)
    return Status(
        elapsed_s=now - started, remaining=_remaining(campaigns), execs=sum(p.execs for p in ps),
        rate=new_execs / max(now - started, 1e-9), where=where, best_risk=max(risks, default=None),
        findings=tuple((f.label, f.hits) for f in found), incidents=sum(len(c.incidents) for c in campaigns),
        last_finding=newest.last_finding if newest is not None else None,
        busy=sum(p.jobs_running for p in ps), workers=workers,
        jobs=f"{sum(p.jobs_done for p in ps)}/{sum(p.jobs_total for p in ps)} done",
        coverage=_coverage(campaigns), errors=sum(len(getattr(c, "errors", ())) for c in campaigns))


#: id(campaign) -> (campaign, its JournalCells, the cells its seeds offer, the cells its executions reached)
_COVERAGE: dict[int, tuple[Any, Any, set[str], set[str]]] = {}


def _coverage(campaigns: Sequence[Any]) -> str:
    """"N/M cells (P %)": the interaction-coverage cells reached of those the seeds offer (a batch: summed),
    read from the journals incrementally; "-" where it cannot be read (no seeds, a network that does not load)."""
    reached = total = 0
    for c in campaigns:
        try:
            entry = _COVERAGE.get(id(c))
            if entry is None or entry[0] is not c:
                from drivefuzz.scenario.roadmap import load_roadmap
                from drivefuzz.triage.coverage import JournalCells, reachable

                cells = set(reachable(load_roadmap(c.seeds[0].network_path()), c.seeds)) if c.seeds else set()
                entry = _COVERAGE[id(c)] = (c, JournalCells(c.out), cells, set())
            _, journals, cells, seen = entry
            new = journals.update()
            # only the new records' cells: the union of them all at every redraw took 15 ms at 40 000
            # executions (6 % of a core at 4 redraws a second, growing with the campaign)
            seen.update(cell for rec in itertools.islice(reversed(journals.records.values()), new)
                        for cell in rec["cells"])
            reached += len(seen & cells)
            total += len(cells)
        except Exception:  # noqa: BLE001 - the screen shows what it can; `drivefuzz coverage` reports errors
            continue
    return f"{reached}/{total} cells ({100.0 * reached / total:.0f} %)" if total else "-"


def _remaining(campaigns: Sequence[Any]) -> str:
    """The budget left: of the campaign, or (a batch) of the cell that has the most left."""
    parts = []
    seconds = [s for s in (c.seconds_left() for c in campaigns) if s is not None]
    if seconds:
        parts.append(f"{format_duration(max(seconds))} of {format_duration(campaigns[0].cfg.budget_s)}")
    execs = [n for n in (c.execs_left() for c in campaigns) if n is not None]
    if execs:
        parts.append(f"{sum(execs)} executions")
    return ", ".join(parts) or "-"


def plain_line(s: Status) -> str:
    """The status on one line, for a log."""
    risk = "-" if s.best_risk is None else f"{s.best_risk:.2f}"
    hits = sum(n for _, n in s.findings)
    last = f"  last: {s.last_finding}" if s.last_finding else ""
    return (f"elapsed {format_duration(s.elapsed_s)}  remaining {s.remaining}  execs {s.execs} ({s.rate:.2f}/s)  "
            f"{s.where}  best risk {risk}  findings {len(s.findings)} ({hits} hits), incidents {s.incidents}"
            f"{f', tool errors {s.errors}' if s.errors else ''}{last}  workers busy {_busy(s)}  jobs {s.jobs}  "
            f"coverage {s.coverage}")


def _busy(s: Status) -> str:
    return f"{s.busy}/{s.workers}" if s.workers else str(s.busy)


def screen(s: Status, title: str):
    """The status as a rich renderable: the figures, then the findings by signature."""
    from rich.console import Group
    from rich.table import Table

    figures = Table.grid(padding=(0, 2))
    figures.add_column(style="bold cyan", justify="right")
    figures.add_column()
    figures.add_column(style="bold cyan", justify="right")
    figures.add_column()
    risk = "-" if s.best_risk is None else f"{s.best_risk:.2f}"
    figures.add_row("elapsed", format_duration(s.elapsed_s), "executions", f"{s.execs} ({s.rate:.2f}/s)")
    figures.add_row("remaining", s.remaining, "best risk", risk)
    figures.add_row("now at", s.where, "workers busy", _busy(s))
    figures.add_row("jobs", s.jobs, "incidents", f"{s.incidents} (not the ego's fault)")
    figures.add_row("last finding", s.last_finding or "-", "coverage", s.coverage)
    if s.errors:  # SUMO, drivefuzz or an oracle plugin failed: the user must know, but they are not findings
        figures.add_row("", "", "tool errors", f"{s.errors} (not findings: errors/)")
    found = Table(title=f"findings by signature ({len(s.findings)})", title_justify="left", expand=True)
    found.add_column("#", justify="right", width=3)
    found.add_column("hits", justify="right", width=5)
    found.add_column("signature", overflow="fold")
    for i, (label, hits) in enumerate(s.findings[:SHOWN_SIGNATURES]):
        found.add_row(str(i), str(hits), label)
    if len(s.findings) > SHOWN_SIGNATURES:
        found.add_row("", "", f"... and {len(s.findings) - SHOWN_SIGNATURES} more")
    from rich.panel import Panel

    return Panel(Group(figures, found), title=title, title_align="left")


class StatusPrinter:
    """The ``on_progress`` of running campaigns: a live screen on a terminal, plain lines otherwise."""

    def __init__(self, campaigns: Sequence[Any], workers: int | None, title: str,
                 stream: TextIO | None = None, terminal: bool | None = None):
        self.campaigns = campaigns
        self.workers = workers
        self.title = title
        self.stream = stream or sys.stderr
        self.terminal = self.stream.isatty() if terminal is None else terminal
        self._live = None
        self._last = 0.0

    def __call__(self, _progress: Any = None) -> None:
        now = time.monotonic()
        if now - self._last < (SCREEN_EVERY_S if self.terminal else PLAIN_EVERY_S):
            return
        self._last = now
        status = read_status(self.campaigns, self.workers)
        if not self.terminal:
            print(plain_line(status), file=self.stream, flush=True)
            return
        if self._live is None:
            from rich.console import Console
            from rich.live import Live

            self._live = Live(console=Console(file=self.stream), auto_refresh=False, transient=False)
            self._live.start()
        self._live.update(screen(status, self.title), refresh=True)

    def close(self) -> None:
        """Show the last state (a log ends with it) and give the terminal back; the summary follows."""
        status = read_status(self.campaigns, self.workers)
        if not self.terminal:
            print(plain_line(status), file=self.stream, flush=True)
        elif self._live is not None:
            self._live.update(screen(status, self.title), refresh=True)
            self._live.stop()
            self._live = None
