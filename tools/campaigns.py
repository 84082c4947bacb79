"""What the evaluation scripts in tools/ share: running a campaign into a folder, and reading its records.

Not a script: ``eval_findings.py`` and ``eval_maneuver.py`` import it (tools/ is on their import path).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any


def run_campaign(out: Path, seeds: list, cfg, argv: list[str], jobs: int) -> float:
    """Run one campaign of ``seeds`` under ``cfg`` (a FuzzConfig) into ``out``, on a local Dask cluster of
    ``jobs`` workers when more than one; return its wall time [s]."""
    from drivefuzz.campaign.fuzz import Campaign

    campaign = Campaign(out, seeds, cfg, argv)
    t0 = time.perf_counter()
    if jobs > 1:
        from drivefuzz.campaign.cluster import dask_client

        with dask_client("local", jobs=jobs) as client:
            campaign.run(client=client)
    else:
        campaign.run()
    return time.perf_counter() - t0


def end_records(out: Path) -> list[dict[str, Any]]:
    """Every execution's record ('end' events) of a campaign's journals, seed by seed."""
    from drivefuzz.campaign.job import read_journal

    return [rec for path in sorted((out / "jobs").glob("*/journal.jsonl")) for rec in read_journal(path)
            if rec.get("event") == "end"]
