"""Driving-quality score on real executions (SUMO + physics + reference ADS, no mocks).

The ego turns left at the intersection (seed 003, west -> north) once on a dry road and once
with a 12 m x 12 m sheet of ice (mu 0.1) over the junction: the front tyres saturate and
the car runs wide (the understeer experiment of ``tools/eval_quality.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivefuzz.sim.execute import execute
from drivefuzz.search.quality import score_trace
from drivefuzz.scenario import Puddle
from drivefuzz.scenario.sumofiles import load_scenario

SEED = Path(__file__).resolve().parents[1] / "seeds" / "intersection" / "003"
ICE = Puddle(x=-5.0, y=0.0, length=12.0, width=12.0, friction=0.1)


@pytest.fixture(scope="module")
def runs():
    base = load_scenario(SEED)
    dry = execute(base.model_copy(update={"puddles": ()}))
    wet = execute(base.model_copy(update={"puddles": (ICE,)}))
    return wet, dry


def test_low_friction_run_scores_lower_than_its_dry_twin(runs):
    wet, dry = runs
    qw, qd = score_trace(wet.trace), score_trace(dry.trace)
    assert (wet.trace["mu_front"] < 0.5).any()  # the ego really drove over the ice
    assert (dry.trace["mu_front"] == 1.0).all()
    assert qw.score < qd.score
    assert qw.us + qw.os > 0 and qd.us + qd.os == 0


def test_understeer_fires_inside_the_puddle_and_not_on_the_dry_twin(runs):
    wet, dry = runs
    qw, qd = score_trace(wet.trace), score_trace(dry.trace)
    on_ice = np.flatnonzero(wet.trace["mu_front"] < 0.5)
    assert qw.us > 0 and qd.us == 0
    # every understeer frame lies while the front axle is on the ice
    assert set(qw.frames["us"]) <= set(on_ice.tolist())
