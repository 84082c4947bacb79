"""A campaign's configuration: what every seed job of it reads from the manifest."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from drivefuzz.oracle import OracleSettings
from drivefuzz.scenario import AdsSpec
from drivefuzz.search.mutate import MutationConfig
from drivefuzz.search.quality import QualityConfig
from drivefuzz.search.risk import RiskConfig
from drivefuzz.search.schedule import ScheduleConfig

#: A campaign directory's marker that a run ended by spending its budget (a batch does not run it again).
FINISHED = "finished.json"
#: How successors are chosen: the risk score (default), the paper's driving-quality score, or at random;
#: ``coverage`` and ``product`` weigh the interaction-coverage cells differently (drivefuzz.search.schedule).
FEEDBACKS = ("risk", "paper", "random", "coverage", "product")


@dataclass
class FuzzConfig:
    cycles: int = 10  # cycles of one lineage at most
    population: int = 8
    strategy: str = "all"
    seed: int = 0
    budget_s: float | None = None
    max_execs: int | None = None
    feedback: str = "risk"  # one of FEEDBACKS
    continue_after_finding: bool = False  # a finding ends its lineage (not the campaign) unless this is set
    single_pass: bool = False  # one lineage per seed, even with a budget
    patience: int = 3  # cycles without a new best before a lineage yields
    reproduce: int = 5  # perturbed reruns of each new signature's representative (0: none)
    reproduce_incidents: bool = False  # reproduction rates of incidents too (not the ego's fault: --report-all)
    shrink: int = 10  # executions spent shrinking each new finding to a minimal reproducer (0: none)
    ads: AdsSpec = field(default_factory=AdsSpec)
    oracles: OracleSettings = field(default_factory=OracleSettings)
    mutation: MutationConfig = field(default_factory=MutationConfig)
    quality: QualityConfig = field(default_factory=QualityConfig)
    risk: RiskConfig = field(default_factory=RiskConfig)
    time_limit: float | None = None  # override the seeds' simulated time limit [s]
    isolate: bool = True  # run executions in a simulation-host child (crash isolation)
    exec_timeout_s: float = 300.0  # [s] wall clock; longer is a 'hang' finding

    def __post_init__(self) -> None:
        if self.feedback is True or self.feedback is False:  # manifests before the risk feedback: a flag
            self.feedback = "paper" if self.feedback else "random"
        if self.feedback not in FEEDBACKS:
            raise ValueError(f"feedback must be one of {', '.join(FEEDBACKS)}, not {self.feedback!r}")

    @property
    def one_lineage_per_seed(self) -> bool:
        """A single pass: asked for, or implied when nothing else would end the campaign."""
        return self.single_pass or (self.budget_s is None and self.max_execs is None)

    @property
    def schedule(self) -> ScheduleConfig:
        return ScheduleConfig(max_cycles=self.cycles, patience=self.patience)

    def to_json(self) -> dict[str, Any]:
        return {
            "cycles": self.cycles, "population": self.population, "strategy": self.strategy, "seed": self.seed,
            "budget_s": self.budget_s, "max_execs": self.max_execs, "feedback": self.feedback,
            "continue_after_finding": self.continue_after_finding, "single_pass": self.single_pass,
            "patience": self.patience, "reproduce": self.reproduce, "reproduce_incidents": self.reproduce_incidents,
            "shrink": self.shrink, "ads": self.ads.model_dump(mode="json"),
            "oracles": self.oracles.settings, "mutation": self.mutation.model_dump(mode="json"),
            "quality": self.quality.model_dump(mode="json"), "risk": self.risk.model_dump(mode="json"),
            "time_limit": self.time_limit, "isolate": self.isolate, "exec_timeout_s": self.exec_timeout_s,
        }

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> "FuzzConfig":
        return cls(
            cycles=d["cycles"], population=d["population"], strategy=d["strategy"], seed=d["seed"],
            budget_s=d.get("budget_s"), max_execs=d.get("max_execs"), feedback=d.get("feedback", "risk"),
            continue_after_finding=d.get("continue_after_finding", False), single_pass=d.get("single_pass", False),
            patience=d.get("patience", 3), reproduce=d.get("reproduce", 5),
            reproduce_incidents=d.get("reproduce_incidents", True),  # campaigns from before it reproduced them
            shrink=d.get("shrink", 0),
            ads=AdsSpec.model_validate(d.get("ads", {})), oracles=OracleSettings(settings=d.get("oracles", {})),
            mutation=MutationConfig.model_validate(d.get("mutation", {})),
            quality=QualityConfig.model_validate(d.get("quality", {})),
            risk=RiskConfig.model_validate(d.get("risk", {})), time_limit=d.get("time_limit"),
            isolate=d.get("isolate", True), exec_timeout_s=d.get("exec_timeout_s", 300.0),
        )
