"""Reproduction rate: does a finding survive small perturbations, or is it knife-edge?

Exact replay (``drivefuzz replay``) re-runs a finding bit for bit. Here the representative of a new
signature is re-run ``k`` times under perturbations that a real test track could not control either:

- SUMO's random seed (the actors' driver imperfection and insertion);
- every actor's departure by up to ``depart_jitter_s`` (default 0.1 s) either way;
- every actor's start position by up to ``position_jitter_m`` (default 0.2 m) either way.

A rerun *reproduces* when the same oracle fires with the same kind (and, when the original involved other
actors, with one of them). The finding records ``reproduced k/N``; at least ``robust_share`` of the reruns
make it *robust*, fewer make it *knife-edge*. Each perturbation is drawn from a ``random.Random`` seeded
with the scenario's content hash, so the rates themselves are reproducible.
"""

from __future__ import annotations

import random
from dataclasses import dataclass
from typing import Any, Callable, Sequence

from drivefuzz.oracle import Misbehavior
from drivefuzz.scenario import Scenario


@dataclass(frozen=True)
class Reproduction:
    runs: int
    reproduced: int
    robust: bool

    @property
    def label(self) -> str:
        return f"reproduced {self.reproduced}/{self.runs} ({'robust' if self.robust else 'knife-edge'})"

    def as_dict(self) -> dict[str, Any]:
        return {"runs": self.runs, "reproduced": self.reproduced, "robust": self.robust, "label": self.label}


def perturb(scenario: Scenario, rng: random.Random, depart_jitter_s: float = 0.1,
            position_jitter_m: float = 0.2) -> Scenario:
    """``scenario`` with a new SUMO seed and every actor's departure and start position jittered."""
    actors = []
    for a in scenario.actors:
        actors.append(a.model_copy(update={
            "depart": round(max(a.depart + rng.uniform(-depart_jitter_s, depart_jitter_s), 0.0), 3),
            "start_pos": round(max(a.start_pos + rng.uniform(-position_jitter_m, position_jitter_m), 0.0), 3),
        }))
    return scenario.model_copy(update={"actors": tuple(actors), "seed": rng.randrange(2**31)})


def same_misbehavior(original: Misbehavior, again: Sequence[Misbehavior]) -> bool:
    """Whether ``again`` holds the original's oracle and kind (with one of its actors, if it had any)."""
    for m in again:
        if m.oracle == original.oracle and m.kind == original.kind:
            if not original.actors or set(original.actors) & set(m.actors):
                return True
    return False


def reproduction_rate(scenario: Scenario, original: Misbehavior,
                      run: Callable[[Scenario], Sequence[Misbehavior] | None], k: int = 5,
                      robust_share: float = 0.8, depart_jitter_s: float = 0.1,
                      position_jitter_m: float = 0.2) -> Reproduction:
    """Re-run ``scenario`` ``k`` times perturbed; ``run`` returns a run's misbehaviours (None: it failed)."""
    rng = random.Random(f"reproduce/{scenario.content_hash()}")
    hits = 0
    for _ in range(k):
        got = run(perturb(scenario, rng, depart_jitter_s, position_jitter_m))
        hits += bool(got) and same_misbehavior(original, got)
    return Reproduction(k, hits, k > 0 and hits >= robust_share * k)
