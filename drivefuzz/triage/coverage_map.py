"""The report's coverage map: one grid per projection of :mod:`drivefuzz.triage.coverage`.

A cell shows how many executions reached it, shaded by that count; ``F`` / ``I`` mark cells met in
executions that produced a finding / an incident; reachable cells never reached are grey, cells the
network and the seeds cannot offer are blank. Used by :func:`drivefuzz.triage.report.write_report`
(HTML and Markdown); plain HTML and CSS, no pictures.
"""

from __future__ import annotations

import html
import math
from typing import Any, Mapping

from drivefuzz.triage.coverage import AXIS_VALUES, PROJECTIONS, split

CSS = """
table.cov { border-collapse: collapse; margin: 0.4em 0 1.2em; font-size: 12px; width: auto; }
table.cov th { font-weight: normal; color: #444; padding: 2px 5px; text-align: left; white-space: nowrap; }
table.cov thead th { writing-mode: vertical-rl; transform: rotate(180deg); vertical-align: bottom; }
table.cov td { width: 34px; height: 22px; text-align: center; border: 1px solid #fff; }
table.cov td.na { background: #fff; color: #ccc; }
table.cov td.never { background: #ddd; color: #888; }
table.cov td.hit { color: #000; }
table.cov td.found { outline: 2px solid #d62728; outline-offset: -2px; font-weight: bold; }
table.cov td.inc { box-shadow: inset 0 -3px 0 #ff7f0e; }
.cov-legend span { display: inline-block; padding: 1px 6px; margin-right: 8px; font-size: 12px; }
"""


def _e(x: Any) -> str:
    return html.escape(str(x))


def _shade(count: int, top: int) -> str:
    """A green from pale (1 hit) to strong (the projection's most hit cell), on a log scale."""
    k = math.log1p(count) / math.log1p(max(top, 1))
    light = 88 - 48 * k
    return f"hsl(130, 55%, {light:.0f}%)"


def grid_html(cov: Mapping[str, Any], name: str) -> str:
    """One projection's grid (rows: its first axis, columns: its second) as an HTML table."""
    row_axis, col_axis = PROJECTIONS[name]
    cells = {split(c)[1:]: h for c, h in cov["cells"].items() if c.startswith(name + ":")}
    rows = [r for r in AXIS_VALUES[row_axis] if any(k[0] == r for k in cells)]
    cols = [c for c in AXIS_VALUES[col_axis] if any(k[1] == c for k in cells)]
    top = max((h["count"] for h in cells.values()), default=0)
    head = "<tr><th></th>" + "".join(f"<th>{_e(c)}</th>" for c in cols) + "</tr>"
    body = []
    for r in rows:
        tds = []
        for c in cols:
            h = cells.get((r, c))
            if h is None:
                tds.append('<td class="na" title="not offered by the network and the seeds">&middot;</td>')
                continue
            title = (f"{r} / {c}: reached {h['count']}x, findings {h['findings']}, incidents {h['incidents']}, "
                     f"aimed at {h.get('aimed', 0)}x")
            if not h["count"]:
                title += f", came near {h.get('near', 0)}x"
                tds.append(f'<td class="never" title="{_e(title)}">0</td>')
                continue
            cls = "hit" + (" found" if h["findings"] else "") + (" inc" if h["incidents"] else "")
            mark = "F" if h["findings"] else ""
            tds.append(f'<td class="{cls}" style="background:{_shade(h["count"], top)}" title="{_e(title)}">'
                       f'{h["count"]}{mark}</td>')
        body.append(f"<tr><th>{_e(r)}</th>{''.join(tds)}</tr>")
    p = cov["projections"][name]
    return (f"<h3>{_e(row_axis)} &times; {_e(col_axis)}: {p['reached']}/{p['reachable']} reached</h3>"
            f'<table class="cov"><thead>{head}</thead><tbody>{"".join(body)}</tbody></table>')


def section_html(cov: Mapping[str, Any] | None) -> str:
    """The report's coverage section (a note when the coverage could not be read)."""
    if cov is None:
        return "<h2>Interaction coverage</h2><p>-</p>"
    legend = ('<p class="cov-legend"><span style="background:hsl(130,55%,60%)">n: reached n times</span>'
              '<span style="outline:2px solid #d62728">F: a finding came of it</span>'
              '<span style="box-shadow: inset 0 -3px 0 #ff7f0e">incident</span>'
              '<span style="background:#ddd">0: never reached</span><span>&middot;: not offered</span>'
              '<span>hover a cell: how often the search aimed at it</span></p>')
    return (f"<h2>Interaction coverage</h2><p>{cov['reached']}/{cov['reachable']} reachable cells reached "
            f"({100.0 * cov['share']:.0f} %) over {cov.get('executions', 0)} executions; close encounters "
            "classified as docs/coverage.md says.</p>" + legend + "".join(grid_html(cov, n) for n in PROJECTIONS))


def section_md(cov: Mapping[str, Any] | None) -> list[str]:
    """The Markdown twin: the figures per projection and the cells never reached."""
    if cov is None:
        return []
    out = ["## Interaction coverage", "",
           f"{cov['reached']}/{cov['reachable']} reachable cells reached ({100.0 * cov['share']:.0f} %).", ""]
    for name, (a, b) in PROJECTIONS.items():
        p = cov["projections"][name]
        never = [split(c)[1] + " / " + split(c)[2] + _tried(h)
                 for c, h in cov["cells"].items() if c.startswith(name + ":") and not h["count"]]
        out.append(f"- {a} x {b}: {p['reached']}/{p['reachable']}" + (f"; never: {', '.join(never)}" if never else ""))
    return out + [""]


def _tried(h: dict) -> str:
    """`` (aimed Nx, near Mx)`` for a cell never reached: the executions aimed at it and those that came near it."""
    said = [f"{k} {h[k]}x" for k in ("aimed", "near") if h.get(k)]
    return f" ({', '.join(said)})" if said else ""
