"""A campaign's configuration: what every seed job of it reads from the manifest."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from drivefuzz.oracle import OracleSettings
from drivefuzz.scenario import AdsSpec
from drivefuzz.search.mutate import MutationConfig
from drivefuzz.search.quality import QualityConfig


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
    isolate: bool = True  # run executions in a simulation-host child (crash isolation)
    exec_timeout_s: float = 300.0  # [s] wall clock; longer is a 'hang' finding

    def to_json(self) -> dict[str, Any]:
        return {
            "cycles": self.cycles, "population": self.population, "strategy": self.strategy, "seed": self.seed,
            "budget_s": self.budget_s, "max_execs": self.max_execs, "feedback": self.feedback,
            "continue_after_finding": self.continue_after_finding, "ads": self.ads.model_dump(mode="json"),
            "oracles": self.oracles.settings, "mutation": self.mutation.model_dump(mode="json"),
            "quality": self.quality.model_dump(mode="json"), "time_limit": self.time_limit,
            "isolate": self.isolate, "exec_timeout_s": self.exec_timeout_s,
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
            isolate=d.get("isolate", True), exec_timeout_s=d.get("exec_timeout_s", 300.0),
        )
