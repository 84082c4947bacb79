"""``drivefuzz report OUT``: one self-contained HTML file about a campaign, and its Markdown twin.

Reads what :mod:`drivefuzz.triage.table` reads, plus each finding folder's trace and scenario,
and draws with matplotlib (Agg) and Pillow. The HTML holds its CSS and its pictures inline
(``data:`` URIs), so it opens anywhere with no network; ``report.md`` next to it holds the same
text and tables without the pictures.

Contents: the campaign (executions, rate, budget, search, ADS, oracles, why it stopped), the risk of
every execution, the findings by signature, then a card per signature (:data:`MAX_CARDS` at most):
a top-down picture of the failure, an animation of its last seconds (:mod:`drivefuzz.triage.figures`), time series of
the ego's speed, the gap to the other party, throttle, brake and steer, and the replay command.
Incidents (not the ego's fault) follow in a section of their own.

A folder whose trace or network cannot be read gets a card with a note instead of pictures; without
matplotlib the report has no pictures at all, and says so.
"""

from __future__ import annotations

import base64
import html
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from drivefuzz.triage.crashtype import LABELS as CRASH_LABELS
from drivefuzz.triage.figures import Scene, pyplot, risk_png, series_png
from drivefuzz.triage.table import CampaignInfo, FindingRow, finding_rows, load_campaign_info

#: cards at most (findings first, then incidents): the report stays quick to write and to open
MAX_CARDS = 50

@dataclass
class Card:
    """What one finding's card shows."""

    row: FindingRow
    misbehavior: dict[str, Any] = field(default_factory=dict)
    other: str | None = None  # the other party's actor id
    scene_png: bytes | None = None
    gif: bytes | None = None
    series_png: bytes | None = None
    notes: list[str] = field(default_factory=list)
    ads: Any = None  # the ADS's own record up to the event (drivefuzz.triage.ads_info.AdsSummary), if it keeps one


# ------------------------------------------------------------------- the report
def write_report(out: str | Path, html_path: str | Path | None = None, max_cards: int = MAX_CARDS,
                 animate: bool = True, log: Callable[[str], None] | None = None) -> tuple[Path, Path]:
    """Write ``report.html`` (default: in ``out``) and ``report.md`` beside it; return both paths."""
    log = log or (lambda s: None)
    info = load_campaign_info(out)
    findings = finding_rows(info.out, executions=info.executions)
    incidents = finding_rows(info.out, incidents=True, executions=info.executions)
    errors = finding_rows(info.out, executions=info.executions, errors=True)  # listed, no cards: no trace
    plt = pyplot()
    cards: list[Card] = []
    for row in (findings + incidents)[:max_cards]:
        t0 = time.perf_counter()
        cards.append(make_card(info.out, row, plt, animate))
        log(f"card {row.folder}: {time.perf_counter() - t0:.1f} s")
    risk = risk_png(plt, info) if plt is not None and info.executions else None
    html_path = Path(html_path) if html_path else info.out / "report.html"
    md_path = html_path.with_suffix(".md")
    skipped = len(findings) + len(incidents) - len(cards)
    notes = ([] if plt is not None else ["matplotlib is not installed: no pictures"]) + (
        [f"{skipped} more card(s) left out (at most {max_cards})"] if skipped > 0 else [])
    from drivefuzz.storage import atomic_write_text

    cov = _coverage(info.out)
    for path, text in ((html_path, render_html(info, findings, incidents, cards, risk, notes, cov, errors)),
                       (md_path, render_markdown(info, findings, incidents, cards, notes, cov, errors))):
        atomic_write_text(path, text)
        path.chmod(0o644)  # a report is for reading (the temporary file it replaced was private)
    return html_path, md_path


def _coverage(out: Path) -> dict[str, Any] | None:
    """The campaign's interaction coverage (also written to coverage.json); None where it cannot be read."""
    from drivefuzz.errors import DriveFuzzError
    from drivefuzz.triage.coverage import campaign_coverage

    if not (out / "manifest.json").is_file():
        return None
    try:
        return campaign_coverage(out)
    except (DriveFuzzError, OSError, ValueError):
        return None


def campaign_facts(info: CampaignInfo) -> list[tuple[str, str]]:
    """(label, value) lines describing the run, for both the HTML and the Markdown."""
    c, m = info.config, info.manifest
    ads = c.get("ads") if isinstance(c.get("ads"), dict) else {}
    opts = ads.get("options") if isinstance(ads.get("options"), dict) else {}
    budget = []
    if c.get("budget_s") is not None:
        budget.append(f"{_seconds(c['budget_s'])} wall clock")
    if c.get("max_execs") is not None:
        budget.append(f"{c['max_execs']} executions")
    counts = info.verdict_counts()
    rate = info.rate
    return [
        ("executions", f"{len(info.executions)}" + (f" in {_seconds(info.wall_s)} ({rate:.2f}/s)" if rate else "")),
        ("outcomes", ", ".join(f"{v} {k}" for k, v in counts.items()) or "-"),
        ("budget", " or ".join(budget) or "none (one pass over the seeds)"),
        ("why it stopped", info.stop_reason or "not recorded (stopped early, still running, or resumed later)"),
        ("search", f"strategy {c.get('strategy', '-')}, feedback {c.get('feedback', '-')}, "
                   f"population {c.get('population', '-')}, at most {c.get('cycles', '-')} cycles per lineage, "
                   f"campaign seed {c.get('seed', '-')}"),
        ("seeds", str(len(m.get("seeds") or []) or "-")),
        ("ADS", f"{ads.get('name', '-')}" + (" (" + ", ".join(f"{k}={v}" for k, v in opts.items()) + ")"
                                             if opts else " (default options)")),
        ("oracles", _oracles_text(c.get("oracles") if isinstance(c.get("oracles"), dict) else {})),
        ("command", " ".join(str(a) for a in m.get("command") or []) or "-"),
        ("started", f"{m.get('started', '-')} (run {m.get('run', 1)}), drivefuzz {m.get('drivefuzz', '-')}"),
    ]


def _oracles_text(overrides: dict[str, Any]) -> str:
    """Every installed oracle with its effective settings (the campaign's over the defaults)."""
    try:
        from drivefuzz.oracle import available_oracles, make_config

        parts = []
        for name, cls in available_oracles().items():
            cfg = make_config(cls, overrides.get(name, {}), "manifest.json").model_dump(mode="json")
            if not cfg.pop("enabled", True):
                parts.append(f"{name} (off)")
                continue
            parts.append(f"{name} (" + ", ".join(f"{k}={v}" for k, v in cfg.items()) + ")" if cfg else name)
        return "; ".join(parts)
    except Exception:  # a plugin gone since the run: show what the campaign set
        return "; ".join(f"{k} {v}" for k, v in overrides.items()) or "defaults"


def _seconds(s: float | None) -> str:
    if s is None:
        return "-"
    s = float(s)
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} min" if s < 7200 else f"{s / 3600:.1f} h"


# ----------------------------------------------------------------------- a card
def make_card(out: Path, row: FindingRow, plt, animate: bool = True) -> Card:
    """The pictures of one finding folder (notes where a piece is missing)."""
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.sumofiles import read_scenario
    from drivefuzz.sim.trace import Trace

    folder = out / row.folder
    card = Card(row)
    try:
        v = json.loads((folder / "verdict.json").read_text())
        card.misbehavior = dict(v["misbehaviors"][0])
        att = v.get("attribution") or {}
    except (OSError, ValueError, KeyError, IndexError, TypeError):
        card.notes.append("verdict.json is unreadable")
        return card
    card.ads = _ads_summary(folder, card.misbehavior)
    if plt is None:
        return card
    try:
        trace = Trace.load(folder / "trace")
    except Exception as exc:  # no trace (a crash or hang) or an unreadable one
        card.notes.append(f"no trace to draw ({type(exc).__name__})" if (folder / "trace").exists()
                          else "no trace (the simulator did not finish this execution)")
        return card
    scenario = rmap = None
    try:
        scenario = read_scenario(folder, validate_network=False)
        rmap = load_roadmap(scenario.network)
    except Exception as exc:
        card.notes.append(f"network not drawn ({type(exc).__name__}: {exc})")
    f = min(max(int(card.misbehavior.get("frame", trace.n_frames - 1)), 0), trace.n_frames - 1)
    card.other = other_party(trace, card.misbehavior, att if isinstance(att, dict) else {}, f)
    try:
        scene = Scene(trace, f, card.other, rmap, scenario)
        card.scene_png = scene.png(plt)
        card.gif = scene.gif(plt) if animate else None
        card.series_png = series_png(plt, trace, f, card.other)
    except Exception as exc:  # a trace that does not add up: the card keeps its text
        plt.close("all")
        card.notes.append(f"pictures failed ({type(exc).__name__}: {exc})")
    return card


def _ads_summary(folder: Path, misbehavior: dict[str, Any]):
    """The ADS's record of its decisions (``trace/meta.json``'s ``ads_info``) up to the event, or None."""
    from drivefuzz.triage.ads_info import summarize

    try:
        info = json.loads((folder / "trace" / "meta.json").read_text()).get("ads_info")
        t = float(misbehavior["time"]) if "time" in misbehavior else None
    except (OSError, ValueError, AttributeError, TypeError):
        return None
    return summarize(info, t)


def other_party(trace, misbehavior: dict[str, Any], attribution: dict[str, Any], f: int) -> str | None:
    """The actor the event involved: the oracle's, the attribution's, else the nearest at frame ``f``."""
    ids = trace.actors.ids
    ev = attribution.get("evidence") if isinstance(attribution.get("evidence"), dict) else {}
    for cand in (*(misbehavior.get("actors") or ()), ev.get("other"), ev.get("leader")):
        if isinstance(cand, str) and cand in ids:
            return cand
    a, rows = trace.actors, trace.actors.rows(f)
    if rows.stop <= rows.start:
        return None
    d = np.hypot(a.x[rows] - trace["x"][f], a.y[rows] - trace["y"][f])
    k = int(np.argmin(d))
    return ids[int(a.actor[rows][k])] if d[k] < 30.0 else None




# ------------------------------------------------------------------- HTML and MD
_CSS = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;color:#202124;max-width:1240px;margin:0 auto;padding:16px 24px;background:#fafafa}
h1{font-size:22px;margin:8px 0 2px}h2{font-size:18px;margin:28px 0 8px;border-bottom:2px solid #e0e0e0;padding-bottom:4px}
h3{font-size:15px;margin:0 0 6px}.sub{color:#5f6368;margin:0 0 12px}
table{border-collapse:collapse;width:100%;background:#fff;font-size:13px}th,td{border:1px solid #e0e0e0;padding:4px 7px;text-align:left;vertical-align:top}
th{background:#f1f3f4}td.n{text-align:right;white-space:nowrap}dl.facts{display:grid;grid-template-columns:150px 1fr;gap:3px 12px;background:#fff;padding:10px 14px;border:1px solid #e0e0e0;margin:0}
dl.facts dt{color:#5f6368}dl.facts dd{margin:0;word-break:break-word}
.card{background:#fff;border:1px solid #dadce0;border-radius:6px;padding:12px 14px;margin:14px 0;box-shadow:0 1px 2px rgba(0,0,0,.05)}
.card.incident{border-left:5px solid #ff7f0e}.card.finding{border-left:5px solid #d62728}
.pics{display:flex;flex-wrap:wrap;gap:10px;align-items:flex-start;margin:8px 0}.pics img{border:1px solid #e0e0e0;max-width:100%}
.meta{color:#3c4043;font-size:13px;margin:2px 0}code,pre{font:12px/1.4 ui-monospace,Menlo,Consolas,monospace}
pre{background:#f1f3f4;padding:6px 9px;border-radius:4px;overflow-x:auto;margin:6px 0}.note{color:#b06000;font-size:13px}
.pill{display:inline-block;border-radius:9px;padding:0 7px;font-size:12px;background:#e8eaed}.pill.ego{background:#fce8e6;color:#a50e0e}.pill.other{background:#feefe3;color:#b06000}
"""


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _img(data: bytes | None, mime: str, alt: str) -> str:
    if not data:
        return ""
    return f'<img alt="{_e(alt)}" src="data:{mime};base64,{base64.b64encode(data).decode()}">'


def _first_seen(r: FindingRow) -> str:
    if r.first_exec is None:
        return f"{r.first_key} (not in the index)"
    when = f", after {_seconds(r.first_time_s)}" if r.first_time_s is not None else ""
    return f"exec {r.first_exec} ({r.first_key}{when})"


def _table_html(rows: list[FindingRow]) -> str:
    head = "<tr><th>#</th><th>signature</th><th>fault</th><th>hits</th><th>reproduced</th><th>first seen</th><th>attribution</th></tr>"
    body = "".join(
        f'<tr><td class="n"><a href="#{_e(r.folder)}">{r.number}</a></td><td>{_e(r.label)}</td>'
        f'<td><span class="pill {_e(r.fault)}">{_e(r.fault)}</span></td><td class="n">{r.hits}</td>'
        f"<td>{_e(r.reproduction)}</td><td>{_e(_first_seen(r))}</td><td>{_e(r.reason)}</td></tr>" for r in rows)
    return f"<table>{head}{body}</table>"


def _event_text(m: dict[str, Any]) -> str:
    """When the oracle fired, with whom, and its details, on one line."""
    details = m.get("details") if isinstance(m.get("details"), dict) else {}
    what = ", ".join(f"{k} {v}" for k, v in details.items() if not isinstance(v, (dict, list)))
    when = f"at t = {float(m['time']):.2f} s (frame {m.get('frame')})" if "time" in m and int(m.get("frame", -1)) >= 0 else ""
    who = f" with {', '.join(m.get('actors') or [])}" if m.get("actors") else ""
    return f"{when}{who}{' · ' + what if what else ''}"


def _card_html(c: Card) -> str:
    r, m = c.row, c.misbehavior
    pics = (_img(c.scene_png, "image/png", f"top-down view of {r.folder}") + _img(c.gif, "image/gif", "the last seconds")
            + _img(c.series_png, "image/png", "time series"))
    from drivefuzz.triage.ads_info import to_html

    notes = "".join(f'<p class="note">{_e(n)}</p>' for n in c.notes) + to_html(c.ads)
    kind = "incident" if r.incident else "finding"
    return (f'<div class="card {kind}" id="{_e(r.folder)}" data-folder="{_e(r.folder)}">'
            f"<h3>#{r.number} {_e(r.label)}</h3>"
            f'<p class="meta"><b>{_e(r.verdict)}</b> {_e(_event_text(m))}</p>'
            f'<p class="meta">fault <span class="pill {_e(r.fault)}">{_e(r.fault)}</span> {_e(r.reason)}</p>'
            + (f'<p class="meta">AV-Fuzzer crash type {_e(CRASH_LABELS[r.crash_type])}</p>'
               if r.crash_type in CRASH_LABELS and r.crash_type != "other" else "") +
            f'<p class="meta">{r.hits} hit(s) &middot; reproduced {_e(r.reproduction)} &middot; first seen {_e(_first_seen(r))}'
            f" &middot; folder <code>{_e(r.folder)}</code></p>"
            f'<div class="pics">{pics}</div>{notes}<pre>{_e(r.replay)}</pre>{_minimal_html(r)}</div>')


def _minimal_html(r) -> str:
    if r.minimal is None:
        return ""
    return (f'<p class="meta">minimal reproducer ({_e(r.minimal.split(": ", 1)[0])}):</p>'
            f"<pre>{_e(r.minimal_replay)}</pre>")


def render_html(info: CampaignInfo, findings: list[FindingRow], incidents: list[FindingRow], cards: list[Card],
                risk_png: bytes | None, notes: list[str], coverage: dict[str, Any] | None = None,
                errors: list[FindingRow] = ()) -> str:
    from drivefuzz.triage.coverage_map import CSS as COVERAGE_CSS, section_html

    facts = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in campaign_facts(info))
    by_folder = {c.row.folder: c for c in cards}
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>drivefuzz report: {_e(info.out.name)}</title><style>{_CSS}{COVERAGE_CSS}</style></head><body>",
        f"<h1>drivefuzz report: {_e(info.out.name)}</h1>",
        f'<p class="sub">{len(findings)} finding(s) and {len(incidents)} incident(s), one per signature; '
        + (f"{len(errors)} error(s) of the tool (not findings); " if errors else "") +
        f"written {_e(time.strftime('%Y-%m-%d %H:%M'))}</p>",
        *(f'<p class="note">{_e(n)}</p>' for n in notes),
        f'<h2>The campaign</h2><dl class="facts">{facts}</dl>',
        "<h2>Risk over the campaign</h2>" + (_img(risk_png, "image/png", "risk per execution") or "<p>-</p>"),
        section_html(coverage),
        *(["<h2>Likely bugs</h2>" + _groups_html(findings)] if len(findings) > 1 else []),
        "<h2>Findings (the ego's fault)</h2>" + (_table_html(findings) if findings else "<p>None.</p>"),
        *(_card_html(by_folder[r.folder]) for r in findings if r.folder in by_folder),
        "<h2>Incidents (not the ego's fault)</h2>" + (_table_html(incidents) if incidents else "<p>None.</p>"),
        *(_card_html(by_folder[r.folder]) for r in incidents if r.folder in by_folder),
        *([f"<h2>{_e(_ERRORS_TITLE)}</h2><p>{_e(_ERRORS_NOTE)}</p>" + _table_html(list(errors))] if errors else []),
        "</body></html>",
    ]
    return "\n".join(parts)


_ERRORS_TITLE = "Errors of the tool (not findings of the ADS)"
_ERRORS_NOTE = ("Executions that SUMO, drivefuzz or an oracle plugin failed (fault tool or oracle-plugin): not bugs of "
                "the ADS. Each folder's verdict.json holds the error and its traceback; replay.sh runs it again.")

_GROUPS_NOTE = ("Findings that one attribution rule blamed on the ego, with the same oracle and kind, are likely "
                "one bug of the ADS met in several situations (signatures).")


def _groups_html(rows: list[FindingRow]) -> str:
    from drivefuzz.triage.table import bug_groups

    body = "".join(f'<tr><td class="n">{len(g.rows)}</td><td class="n">{g.hits}</td><td>{_e(g.title)}</td><td>'
                   + " ".join(f'<a href="#{_e(r.folder)}">#{r.number}</a>' for r in g.rows) + "</td></tr>"
                   for g in bug_groups(rows))
    return (f"<p>{_e(_GROUPS_NOTE)}</p><table><thead><tr><th>signatures</th><th>hits</th><th>likely bug</th>"
            f"<th>findings</th></tr></thead><tbody>{body}</tbody></table>")


def _groups_md(rows: list[FindingRow]) -> list[str]:
    from drivefuzz.triage.table import bug_groups

    out = ["## Likely bugs", "", _GROUPS_NOTE, "", "| signatures | hits | likely bug | findings |", "|---:|---:|---|---|"]
    out += [f"| {len(g.rows)} | {g.hits} | {_md_cell(g.title)} | {g.numbers} |" for g in bug_groups(rows)]
    return out + [""]


def _md_cell(x: Any) -> str:
    return str(x).replace("|", "\\|").replace("\n", " ")


def _table_md(rows: list[FindingRow]) -> list[str]:
    if not rows:
        return ["None.", ""]
    out = ["| # | signature | fault | hits | reproduced | first seen | folder |", "|---:|---|---|---:|---|---|---|"]
    out += [f"| {r.number} | {_md_cell(r.label)} | {r.fault} | {r.hits} | {r.reproduction} | {_md_cell(_first_seen(r))} "
            f"| `{r.folder}` |" for r in rows]
    return out + [""]


def render_markdown(info: CampaignInfo, findings: list[FindingRow], incidents: list[FindingRow], card_list: list[Card],
                    notes: list[str], coverage: dict[str, Any] | None = None, errors: list[FindingRow] = ()) -> str:
    from drivefuzz.triage.ads_info import to_markdown
    from drivefuzz.triage.coverage_map import section_md

    cards = {c.row.folder: c for c in card_list}
    lines = [f"# drivefuzz report: {info.out.name}", "",
             f"{len(findings)} finding(s) and {len(incidents)} incident(s), one per signature. "
             + (f"{len(errors)} error(s) of the tool (not findings). " if errors else "") +
             "The pictures are in report.html.", "", *(f"> {n}" for n in notes), "", "## The campaign", ""]
    lines += [f"- **{k}**: {_md_cell(v)}" for k, v in campaign_facts(info)] + [""]
    lines += section_md(coverage)
    if len(findings) > 1:
        lines += _groups_md(findings)
    for title, rows in (("Findings (the ego's fault)", findings), ("Incidents (not the ego's fault)", incidents)):
        lines += [f"## {title}", "", *_table_md(rows)]
        for r in rows:
            event = _event_text(cards[r.folder].misbehavior) if r.folder in cards else ""
            lines += [f"### #{r.number} {r.label}", "", f"- verdict: {r.verdict} {event}".rstrip(),
                      f"- fault: {r.fault} ({r.reason})",
                      *([f"- AV-Fuzzer crash type {CRASH_LABELS[r.crash_type]}"]
                        if r.crash_type in CRASH_LABELS and r.crash_type != "other" else []),
                      f"- {r.hits} hit(s); reproduced {r.reproduction}; first seen {_first_seen(r)}",
                      f"- folder: `{r.folder}`", "", *to_markdown(cards[r.folder].ads if r.folder in cards else None),
                      "```sh", r.replay, "```", ""]
            if r.minimal is not None:
                lines += [f"- minimal reproducer ({r.minimal.split(': ', 1)[0]}):", "", "```sh", r.minimal_replay,
                          "```", ""]
    if errors:
        lines += [f"## {_ERRORS_TITLE}", "", _ERRORS_NOTE, "", *_table_md(list(errors))]
    return "\n".join(lines)
