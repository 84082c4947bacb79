"""Regression mode: re-run archived findings against another ADS (or another version of it).

``drivefuzz regress ARCHIVE... --ads NEW`` takes campaign directories (their ``findings/``) and finding
folders, runs every finding's scenario with the new ADS and the finding's own oracle settings, and says
of each:

- ``still failing``: the same misbehaviour (oracle and kind, with one of the same actors if it had any);
- ``failing differently``: another misbehaviour fired;
- ``fixed``: no oracle fired.

A finding of a simulator crash, hang or plugin error is re-run in the crash-isolating simulation host and
still fails when the same failure kind comes back. The result is a table, optionally a JUnit XML file
(one test case per finding, a ``<failure>`` for each that still fails or fails differently), and the exit
code: 1 when any finding still fails or fails differently, else 0.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from drivefuzz.errors import InvalidConfig

STILL = "still failing"
DIFFERENT = "failing differently"
FIXED = "fixed"


@dataclass(frozen=True)
class Outcome:
    folder: Path
    label: str  # the finding's signature label (or oracle/kind)
    expected: str  # oracle/kind of the finding
    status: str  # STILL | DIFFERENT | FIXED
    detail: str  # what the new run showed
    seconds: float  # wall time of the rerun

    @property
    def failed(self) -> bool:
        return self.status != FIXED


def finding_folders(archives: Iterable[str]) -> list[Path]:
    """Every finding folder in ``archives`` (finding folders themselves, or campaign directories)."""
    out: list[Path] = []
    for a in archives:
        p = Path(a)
        if (p / "verdict.json").is_file():
            out.append(p)
        elif (p / "findings").is_dir():
            out += sorted(f for f in (p / "findings").iterdir() if (f / "verdict.json").is_file())
        else:
            raise InvalidConfig(a, None, "neither a finding folder nor a campaign directory",
                                "a folder with verdict.json, or a campaign directory with findings/")
    return out


def regress_one(host, folder: Path, verdict: dict, want, scenario) -> Outcome:
    """Re-run one finding in the simulation ``host`` (its verdict, first misbehaviour ``want``, and its
    scenario already set to the new ADS) with the finding's own oracle settings."""
    import time

    from drivefuzz.sim.simhost import FAILURE_KINDS, OK
    from drivefuzz.triage.reproduce import same_misbehavior

    sig = verdict.get("signature") if isinstance(verdict.get("signature"), dict) else {}
    label = str(sig.get("label") or f"{want.oracle}/{want.kind}")
    t0 = time.perf_counter()
    out = host.execute(scenario, verdict["oracles"])
    seconds = time.perf_counter() - t0
    expected = f"{want.oracle}/{want.kind}"
    if out.status != OK:
        got = f"{out.status}/{out.error_type or out.status}"
        if want.oracle in FAILURE_KINDS and got == expected:
            return Outcome(folder, label, expected, STILL, f"{got} ({out.detail})", seconds)
        return Outcome(folder, label, expected, DIFFERENT, f"{got} ({out.detail})", seconds)
    mbs = out.execution.misbehaviors
    if not mbs:
        return Outcome(folder, label, expected, FIXED, f"no misbehaviour ({out.execution.termination.value})", seconds)
    first = mbs[0]
    where = f"{first.oracle}/{first.kind} at {first.time:.2f} s"
    if want.oracle not in FAILURE_KINDS and same_misbehavior(want, mbs):
        return Outcome(folder, label, expected, STILL, where, seconds)
    return Outcome(folder, label, expected, DIFFERENT, where, seconds)


def format_outcomes(outcomes: list[Outcome]) -> str:
    lines = [f"{'status':<20} {'expected':<24} {'now':<36} finding"]
    for o in outcomes:
        lines.append(f"{o.status:<20} {o.expected:<24} {o.detail[:36]:<36} {o.folder}")
    counts = {s: sum(o.status == s for o in outcomes) for s in (STILL, DIFFERENT, FIXED)}
    lines.append(f"{len(outcomes)} finding(s): " + ", ".join(f"{n} {s}" for s, n in counts.items()))
    return "\n".join(lines)


def junit_xml(outcomes: list[Outcome], ads: str) -> str:
    """JUnit XML: one test suite, one test case per finding; still failing and failing differently fail."""
    failures = sum(o.failed for o in outcomes)
    suite = ET.Element("testsuite", name=f"drivefuzz regress --ads {ads}", tests=str(len(outcomes)),
                       failures=str(failures), errors="0", skipped="0",
                       time=f"{sum(o.seconds for o in outcomes):.3f}")
    for o in outcomes:
        case = ET.SubElement(suite, "testcase", classname=f"drivefuzz.{o.folder.parent.parent.name or 'finding'}",
                             name=f"{o.folder.name}: {o.label}", time=f"{o.seconds:.3f}")
        if o.failed:
            kind = "still-failing" if o.status == STILL else "failing-differently"
            fail = ET.SubElement(case, "failure", type=kind, message=f"{o.status}: expected {o.expected}, got {o.detail}")
            fail.text = f"drivefuzz regress {o.folder} --ads {ads}"
        ET.SubElement(case, "system-out").text = f"{o.status}: {o.detail}"
    ET.indent(suite)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(suite, encoding="unicode") + "\n"
