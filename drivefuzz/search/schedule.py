"""The schedule that spends a campaign's budget: a corpus of interesting scenarios with AFL-style energy.

The paper's Algorithm 1 is the inner loop: a *lineage* starts from a scenario, and each cycle a population
of mutants of the current scenario runs and the riskiest one becomes the next current scenario. This module
decides where lineages start and when they end:

- A lineage ends (it *yields*) after ``ScheduleConfig.max_cycles`` cycles, or after ``patience`` cycles in a
  row that did not raise its best feedback value, or at a finding (unless the campaign continues after
  findings). Lineages that keep raising risk therefore get more cycles: their energy.
- Every successor that raised its lineage's best value enters the corpus. When a lineage ends at a finding,
  its entries (and the one it started from) lose energy: they lead to a bug already found.
- A new lineage starts from the seed (a fresh one) with probability ``fresh_share``, or when the corpus is
  empty; otherwise from a corpus entry drawn with weight ``(rank_weight + risk rank) / (1 + picks)``: risky
  entries are preferred, and an entry that has been tried often makes way for the others.

- **Behavioural coverage** (risk feedback only): every execution's riskiest moment has a *situation*
  (:func:`drivefuzz.triage.signature.situation`: the ego's manoeuvre and road element, the other party and
  its approach). A member's feedback value is its risk times :meth:`Schedule.weight` of its situation:
  ``1 + novelty / (1 + times seen)`` for a situation the seed's job has met less often, and ``found_weight``
  for the situation of a finding already made. A member whose situation the job had never met, and whose
  risk reaches ``corpus_risk``, enters the corpus even when it is not chosen (AFL keeps an input that
  reaches new coverage). So energy goes to risky situations that have not yet turned into findings.
- **Interaction coverage** (risk feedback only): every execution's close encounters are classified into
  cells (:mod:`drivefuzz.triage.coverage`). A member whose cells include some the seed's job has not
  reached gets :meth:`Schedule.cell_bonus` added to its value (``cell_bonus`` per new cell, at most
  ``cell_bonus_max``), and enters the corpus whatever its risk: the search goes on from what moved coverage.

With ``feedback="random"`` (the baseline) nothing here looks at the feedback: lineages run ``max_cycles``
cycles and corpus entries are drawn uniformly, so that configurations differ only in what the feedback does.

The state is a plain JSON-able dict (the job's checkpoint holds it), and every draw takes an explicit
``random.Random``: the schedule is a pure function of the campaign seed and the executions' results.
This module never imports libsumo.
"""

from __future__ import annotations

import random
from dataclasses import asdict, dataclass, field
from typing import Any

from pydantic import BaseModel, ConfigDict, Field


#: Feedbacks under which the schedule keeps situations and cells and the mutator aims at unreached cells:
#: ``risk`` (the default: risk x situation weight + the cell bonus), ``coverage`` (the new cells first, risk
#: breaks ties) and ``product`` (risk x situation weight x (1 + new cells)); see :func:`member_value`.
GUIDED = ("risk", "coverage", "product")


class ScheduleConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")
    max_cycles: int = Field(default=10, ge=1, description="cycles of one lineage at most")
    patience: int = Field(default=3, ge=1, description="cycles without a new best before a lineage yields")
    fresh_share: float = Field(default=0.3, ge=0.0, le=1.0, description="share of lineages started from the seed")
    min_gain: float = Field(default=1e-6, ge=0.0, description="a rise of the best value smaller than this is none")
    max_corpus: int = Field(default=200, ge=1, description="corpus entries kept per seed (the riskiest)")
    found_penalty: int = Field(default=3, ge=0, description="picks added to the entries of a lineage that found "
                               "something (its energy goes to lineages that have not)")
    novelty: float = Field(default=1.0, ge=0.0, description="extra weight of a situation never met (risk mode)")
    found_weight: float = Field(default=0.5, ge=0.0, description="weight of the situation of a finding made")
    corpus_risk: float = Field(default=0.3, ge=0.0, description="risk at which a new situation enters the corpus")
    cell_bonus: float = Field(default=0.25, ge=0.0, description="value added per interaction-coverage cell the "
                              "job had not reached (risk mode)")
    cell_bonus_max: float = Field(default=0.75, ge=0.0, description="the most that new cells add to a value")


@dataclass
class Entry:
    """A corpus scenario: ``ref`` is its folder relative to the campaign directory."""

    ref: str
    value: float  # the feedback value that got it in (higher = riskier)
    lineage: int
    picks: int = 0
    hint: str | None = None  # the actor that carried the most risk, for targeted mutation


@dataclass
class Lineage:
    number: int
    start: str | None  # corpus ref it started from; None: the seed
    cycle: int = 0  # cycles done
    best: float | None = None
    stagnant: int = 0
    current: str | None = None  # corpus ref of the current scenario; None: the start
    hint: str | None = None


@dataclass
class Schedule:
    cfg: ScheduleConfig
    mode: str = "risk"  # "risk" | "coverage" | "product" | "paper" | "random"
    corpus: list[Entry] = field(default_factory=list)
    lineage: Lineage | None = None
    lineages: int = 0  # lineages started so far
    seen: dict[str, int] = field(default_factory=dict)  # situation -> executions that met it
    found: list[str] = field(default_factory=list)  # situations of findings made
    cells: dict[str, int] = field(default_factory=dict)  # interaction-coverage cell -> executions that reached it

    # ------------------------------------------------------------ state
    def to_json(self) -> dict[str, Any]:
        return {"mode": self.mode, "corpus": [asdict(e) for e in self.corpus],
                "lineage": None if self.lineage is None else asdict(self.lineage), "lineages": self.lineages,
                "seen": dict(self.seen), "found": list(self.found), "cells": dict(self.cells)}

    @classmethod
    def from_json(cls, cfg: ScheduleConfig, data: dict[str, Any] | None, mode: str) -> "Schedule":
        if not data:
            return cls(cfg, mode)
        lin = data.get("lineage")
        return cls(cfg, mode, [Entry(**e) for e in data.get("corpus", [])],
                   None if lin is None else Lineage(**lin), int(data.get("lineages", 0)),
                   {str(k): int(v) for k, v in data.get("seen", {}).items()}, [str(x) for x in data.get("found", [])],
                   {str(k): int(v) for k, v in data.get("cells", {}).items()})

    # ------------------------------------------------------------ behavioural coverage
    def weight(self, situation: str | None) -> float:
        """The factor on a member's risk for meeting ``situation`` (1 in the other modes, or without one)."""
        if self.mode not in GUIDED or not situation:
            return 1.0
        if situation in self.found:
            return self.cfg.found_weight
        return 1.0 + self.cfg.novelty / (1.0 + self.seen.get(situation, 0))

    def new_cells(self, cells: list[str] | None) -> int:
        """How many of an execution's interaction-coverage ``cells`` the job has not reached (risk mode)."""
        if self.mode not in GUIDED or not cells:
            return 0
        return sum(1 for c in cells if c not in self.cells)

    def cell_bonus(self, cells: list[str] | None) -> float:
        """The value added to a member for the cells it reached first (0 in the other modes)."""
        return min(self.cfg.cell_bonus * self.new_cells(cells), self.cfg.cell_bonus_max)

    def is_new(self, situation: str | None, risk: float | None, cells: list[str] | None = None) -> bool:
        """Whether an execution with ``situation``, ``risk`` and ``cells`` reached new coverage (see the
        module docstring)."""
        if self.new_cells(cells):
            return True
        return (self.mode in GUIDED and bool(situation) and situation not in self.seen
                and risk is not None and risk >= self.cfg.corpus_risk)

    def observe(self, situations: list[str | None], found: list[str | None],
                cells: list[list[str] | None] | None = None) -> None:
        """Count a population's situations and cells (after its successor is chosen) and its findings' situations."""
        for s in situations:
            if s:
                self.seen[s] = self.seen.get(s, 0) + 1
        for s in found:
            if s and s not in self.found:
                self.found.append(s)
        for member in cells or ():
            for c in member or ():
                self.cells[c] = self.cells.get(c, 0) + 1

    def add_new(self, ref: str, value: float, hint: str | None) -> None:
        """A member that reached new coverage enters the corpus (from the current lineage)."""
        assert self.lineage is not None, "add_new() outside a lineage"
        self._add(Entry(ref, value, self.lineage.number, hint=hint))

    # ------------------------------------------------------------ lineages
    def start_lineage(self, rng: random.Random) -> Lineage:
        """Begin the next lineage: from the seed, or from a corpus entry drawn by energy."""
        start: Entry | None = None
        if self.corpus and rng.random() >= self.cfg.fresh_share:
            if self.mode == "random":
                start = rng.choice(self.corpus)
            else:
                ranked = sorted(self.corpus, key=lambda e: e.value)
                weights = [(1.0 + rank) / (1.0 + e.picks) for rank, e in enumerate(ranked)]
                start = rng.choices(ranked, weights=weights)[0]
            start.picks += 1
        self.lineage = Lineage(self.lineages, None if start is None else start.ref,
                               best=None if start is None else start.value, current=None if start is None else start.ref,
                               hint=None if start is None else start.hint)
        self.lineages += 1
        return self.lineage

    def cycle_done(self, best_value: float | None, successor_ref: str | None, hint: str | None,
                   found: bool, continue_after_finding: bool) -> bool:
        """Record a finished cycle of the current lineage; True while it goes on, False when it yields.

        ``best_value`` is the chosen successor's feedback value (None: no member ran to the end), and
        ``successor_ref`` its corpus folder (None: the parent stays current, e.g. a population with no signal).
        """
        lin = self.lineage
        assert lin is not None, "cycle_done() outside a lineage"
        lin.cycle += 1
        if successor_ref is not None:
            lin.current, lin.hint = successor_ref, hint
        improved = (best_value is not None and self.mode != "random"
                    and (lin.best is None or best_value > lin.best + self.cfg.min_gain))
        if improved:
            lin.best, lin.stagnant = best_value, 0
            if successor_ref is not None:
                self._add(Entry(successor_ref, best_value, lin.number, hint=hint))
        else:
            lin.stagnant += 1
            if self.mode == "random" and successor_ref is not None and best_value is not None:
                self._add(Entry(successor_ref, best_value, lin.number, hint=hint))
        go_on = lin.cycle < self.cfg.max_cycles and (self.mode == "random" or lin.stagnant < self.cfg.patience)
        if found and not continue_after_finding:
            go_on = False
            if self.mode != "random":  # its entries lead to a bug already found: they make way for the others
                for e in self.corpus:
                    if e.lineage == lin.number or e.ref == lin.start:
                        e.picks += self.cfg.found_penalty
        if not go_on:
            self.lineage = None
        return go_on

    def _add(self, entry: Entry) -> None:
        if any(e.ref == entry.ref for e in self.corpus):
            return
        self.corpus.append(entry)
        if len(self.corpus) > self.cfg.max_corpus:  # drop the least risky (the oldest among equals)
            self.corpus.remove(min(self.corpus, key=lambda e: e.value))


def pick_successor(values: list[float], mode: str, rng: random.Random) -> int | None:
    """Index of the member that becomes the next scenario (``values``: higher = riskier).

    Ties are broken at random with ``rng``; a population with no signal (every value equal, more than one
    member) gives None under the feedback modes, so that the parent is mutated again rather than member 0.
    """
    if not values:
        return None
    if mode == "random":
        return rng.randrange(len(values))
    top = max(values)
    if len(values) > 1 and min(values) == top:
        return None
    best = [i for i, v in enumerate(values) if v == top]
    return best[0] if len(best) == 1 else rng.choice(best)


def member_value(mode: str, feedback: float, weight: float, new_cells: int, bonus: float) -> float:
    """A population member's value for successor choice (higher is chosen).

    ``feedback`` is its risk (or the negated driving-quality score under ``paper``), ``weight`` its
    situation's weight, ``new_cells`` how many cells it reached that its job had not, ``bonus`` the capped
    cell bonus. ``risk``: ``feedback x weight + bonus``; ``coverage``: ``new_cells + feedback / 1000`` (the
    cells decide, the risk only breaks ties); ``product``: ``feedback x weight x (1 + new_cells)``; else
    ``feedback x weight``."""
    if mode == "coverage":
        return new_cells + feedback / 1000.0
    if mode == "product":
        return feedback * weight * (1.0 + new_cells)
    return feedback * weight + bonus
