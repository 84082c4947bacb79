"""The verdict of attribution and its vocabulary: :class:`Fault`, :class:`Attribution`, the rules a verdict may name
(:data:`RULES`), and which excuses the careful driver's replay tests (:data:`AVOIDED`, :func:`needs_replay`).

Shared by :mod:`drivefuzz.triage.attribute` (the rules and their order), :mod:`drivefuzz.triage.counterfactual`
(the careful driver's replay), the signatures, the triage store and the reports (:func:`bug_class`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Mapping

import numpy as np


class Fault(str, Enum):
    EGO = "ego"
    OTHER = "other"
    UNCLEAR = "unclear"



#: The rules, by the name a verdict records (``Attribution.rule``), with what each says happened. Findings
#: of one oracle and kind that one rule blamed on the ego are likely one bug of the ADS, however their
#: signatures differ (a roundabout entry not yielded to, with the ego going straight or right, the other car
#: an autopilot or a linear one, struck front or side): the report and the summaries group them so.
RULES: dict[str, str] = {
    # the ego's fault
    "own_driving": "its own driving",
    "obstacle": "it drove into a static obstacle",
    "lane_change_into": "it moved sideways into a vehicle alongside",
    "ran_red": "it entered a junction on red and hit someone",
    "failed_to_yield": "it did not yield where its link must yield",
    "struck": "it struck another road user",
    "slow": "it did not reach its goal in time",
    "no_blocker": "it stood still with nothing in its way",
    "stayed_behind": "it stayed behind a stationary body with a lane free",
    "trailed": "it trailed slower traffic to a time-out with a lane free to pass",
    "stood_still": "it stood still with a lane free",
    "stood_in_lane": "it stood reaching into another's lane, in its way",
    # an excuse that the careful driver's replay overturned (:data:`AVOIDED`): the ego's
    "stopped_in_the_way": "it stopped where a careful driver did not, and was struck there",
    "rear_end_avoidable": "it was struck from behind where a careful driver was not",
    "cut_in_avoidable": "a vehicle cut in that a careful driver kept clear of",
    "right_of_way_avoidable": "another did not give way, and a careful driver kept clear of it",
    "pedestrian_avoidable": "it met a pedestrian that a careful driver kept clear of",
    "blocked_avoidable": "it stood blocked or held up where a careful driver got on",
    # another's
    "stationary_struck": "it was struck while standing still",
    "rear_ended": "it was struck from behind while driving lawfully",
    "cut_in": "a vehicle cut in closer than a careful driver can brake for",
    "appeared": "another road user appeared beside it too late for any driver to react",
    "other_ran_red": "another vehicle entered the junction on red",
    "other_failed_to_yield": "another vehicle did not yield",
    "pedestrian": "a pedestrian stepped out too close, unseen, or into its side",
    "held_up": "slower traffic held it up",
    "pedestrian_in_lane": "a pedestrian stood in its lane",
    "blocked": "every lawful way on was blocked",
    "queue": "it waited in a queue that will move",
    # neither
    "no_evidence": "the trace lacks the evidence",
}


#: The rules that excuse the ego (``other``), each a hypothesis that the careful driver's replay tests, with the
#: rule an ``ego`` verdict names when the careful driver avoided what the rule excused.
AVOIDED: dict[str, str] = {
    "stationary_struck": "stopped_in_the_way",
    "rear_ended": "rear_end_avoidable",
    "cut_in": "cut_in_avoidable",
    "other_ran_red": "right_of_way_avoidable",
    "other_failed_to_yield": "right_of_way_avoidable",
    "pedestrian": "pedestrian_avoidable",
    "pedestrian_in_lane": "blocked_avoidable",
    "blocked": "blocked_avoidable",
    "queue": "blocked_avoidable",
    "held_up": "blocked_avoidable",
}
#: Evidence key of an excuse that holds without a replay (its value says why).
KEPT = "kept_without_replay"


def needs_replay(att: "Attribution") -> bool:
    """Whether ``att`` (a verdict from the rules alone) is an excuse that the careful driver's replay must test
    before it holds: the triage runs the replay for these as for the ego's verdicts."""
    return att.fault is Fault.OTHER and att.rule in AVOIDED and KEPT not in att.evidence


def bug_class(verdict: str, fault: str, rule: str) -> tuple[str, str]:
    """(key, title) of the likely bug behind a finding: its oracle/kind (``verdict``), fault and rule. A verdict
    that names no rule (one filed before verdicts recorded theirs) is a class of its oracle and kind alone."""
    what = RULES.get(rule)
    # an unclear finding is not the ego's yet; a crash, hang or plugin error has no trace, so no verdict to show
    tail = "" if fault == Fault.EGO.value else f" (fault: {fault})" if fault else " (no trace: not attributed)"
    if what is None:
        return f"{verdict}|{fault}", verdict + tail
    return f"{verdict}|{fault}|{rule}", f"{verdict}: {what}{tail}"



@dataclass(frozen=True)
class Attribution:
    """A verdict, the one-line reason a reader can check, its evidence (JSON-safe), and the name of the rule
    that gave it (a key of :data:`RULES`; the counterfactual keeps the rule whose verdict it tested)."""

    fault: Fault
    reason: str
    evidence: Mapping[str, Any] = field(default_factory=dict)
    rule: str = ""

    def __post_init__(self):
        if self.rule and self.rule not in RULES:
            raise ValueError(f"attribution rule {self.rule!r} is not described in RULES")

    def as_dict(self) -> dict[str, Any]:
        return {"fault": self.fault.value, "reason": self.reason, "rule": self.rule,
                "evidence": _json_safe(self.evidence)}


def _json_safe(v):
    if isinstance(v, Mapping):
        return {str(k): _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return None if not math.isfinite(float(v)) else round(float(v), 3)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    if isinstance(v, Enum):
        return v.value
    return v

