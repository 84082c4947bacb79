"""The ADS's own record of its decisions (``meta.json["ads_info"]``, :meth:`drivefuzz.ads.ADS.trace_info`) on a
finding's card in the report: what the ADS says it decided up to the event.

An ADS plugin may hand the trace any JSON-like record. The CommonRoad adapter (``adapters/commonroad``) records
one entry per planning cycle under ``cycles`` (``t`` [s], ``outcome``: plan / none / raised, ``error``,
``wall``: the stop-line wall was set, ``v_des`` [m/s]: the desired speed, ``v_plan_max`` [m/s]: the plan's top
speed) and their ``counts``; those become a summary and a table of the last cycles before the event, and the
first cycle without a plan. Other scalar entries are listed as they are. Used by :mod:`drivefuzz.triage.report`.
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from typing import Any

#: planning cycles shown before the event
LAST_CYCLES = 6
_COLUMNS = ("t", "outcome", "v_des", "v_plan_max", "wall", "error")
_HEAD = ("t [s]", "outcome", "desired speed [m/s]", "plan's top speed [m/s]", "wall", "error")


@dataclass
class AdsSummary:
    """Lines of text and rows of the last cycles (each a tuple of :data:`_COLUMNS` as text)."""

    lines: list[str] = field(default_factory=list)
    rows: list[tuple[str, ...]] = field(default_factory=list)


def summarize(info: Any, t_event: float | None) -> AdsSummary | None:
    """The card's view of ``ads_info`` up to ``t_event`` [s] (all of it when None); None when there is none."""
    if not isinstance(info, dict) or not info:
        return None
    out = AdsSummary()
    cycles = info.get("cycles")
    scalars = {k: v for k, v in info.items() if isinstance(v, (str, int, float, bool)) and k != "cycles"}
    if scalars:
        out.lines.append(", ".join(f"{k} {v}" for k, v in scalars.items()))
    if not isinstance(cycles, dict) or not isinstance(cycles.get("t"), list) or not isinstance(cycles.get("outcome"), list):
        return out
    n = len(cycles["t"])
    cols = {k: cycles.get(k) if isinstance(cycles.get(k), list) and len(cycles.get(k)) == n else [None] * n
            for k in _COLUMNS}
    upto = [i for i in range(n) if t_event is None or _num(cols["t"][i]) <= t_event + 1e-9]
    counts: dict[str, int] = {}
    for i in upto:
        counts[str(cols["outcome"][i])] = counts.get(str(cols["outcome"][i]), 0) + 1
    walls = sum(1 for i in upto if cols["wall"][i] is True)
    when = "up to the event" if t_event is not None else "in the run"
    out.lines.append(f"{len(upto)} planning cycles {when}: "
                     + ", ".join(f"{v} {k}" for k, v in counts.items()) + f"; stop-line wall set in {walls}")
    first = next((i for i in upto if cols["outcome"][i] != "plan"), None)
    if first is not None:
        err = f": {cols['error'][first]}" if cols["error"][first] else ""
        out.lines.append(f"first cycle without a plan: t = {_num(cols['t'][first]):.2f} s, {cols['outcome'][first]}{err}")
    out.rows = [tuple(_cell(cols[k][i]) for k in _COLUMNS) for i in upto[-LAST_CYCLES:]]
    return out


def to_html(s: AdsSummary | None) -> str:
    if s is None:
        return ""
    e = html.escape
    lines = "".join(f"<li>{e(x)}</li>" for x in s.lines)
    table = ""
    if s.rows:
        head = "".join(f"<th>{e(h)}</th>" for h in _HEAD)
        body = "".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>" for r in s.rows)
        table = f'<table class="ads"><tr>{head}</tr>{body}</table>'
    return f'<div class="ads"><p class="meta"><b>the ADS\'s decisions</b> (its trace record)</p><ul>{lines}</ul>{table}</div>'


def to_markdown(s: AdsSummary | None) -> list[str]:
    if s is None:
        return []
    out = ["- the ADS's decisions (its trace record):", *(f"  - {x}" for x in s.lines), ""]
    if s.rows:
        out += ["| " + " | ".join(_HEAD) + " |", "|" + "---|" * len(_HEAD)]
        out += ["| " + " | ".join(c.replace("|", "/") for c in r) + " |" for r in s.rows] + [""]
    return out


def _num(x: Any) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def _cell(x: Any) -> str:
    if x is None:
        return ""
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float):
        return f"{x:.2f}"
    return str(x)[:120]
