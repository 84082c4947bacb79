"""Comparing the cells of a batch campaign: repetitions, effect sizes, and a self-contained report.

A batch's cells differ in network, strategy, ADS (with options) and campaign seed. Cells that differ only
in the seed are repetitions of one **configuration**. For each configuration the distinct findings (one per
signature) are summarised (mean, sd), and two configurations on the same network are compared with the
Mann-Whitney U test (two-sided p) and the Vargha-Delaney A12 effect size (the probability that a
repetition of the first finds more distinct bugs than one of the second; 0.5: no difference), as the
fuzzing literature recommends (Arcuri and Briand 2011; Klees et al. 2018).
"""

from __future__ import annotations

import base64
import html
import io
import statistics
from dataclasses import dataclass
from itertools import combinations
from pathlib import Path
from typing import Any


def mann_whitney_p(x: list[float], y: list[float]) -> float:
    """Two-sided p of the Mann-Whitney U test (SciPy's; 1.0 when every value is equal)."""
    from scipy.stats import mannwhitneyu

    try:
        return float(mannwhitneyu(x, y, alternative="two-sided").pvalue)
    except ValueError:  # every value equal
        return 1.0


def a12(x: list[float], y: list[float]) -> float:
    """Vargha-Delaney A12: the probability that a value of x beats one of y (ties count half)."""
    wins = sum((a > b) + 0.5 * (a == b) for a in x for b in y)
    return wins / (len(x) * len(y))


@dataclass(frozen=True)
class Configuration:
    network: str
    strategy: str
    ads: str  # name and options
    distinct: tuple[float, ...]  # per repetition (campaign seed), in seed order

    @property
    def label(self) -> str:
        return f"{self.network} {self.strategy} {self.ads}"

    @property
    def mean(self) -> float:
        return statistics.fmean(self.distinct)

    @property
    def sd(self) -> float:
        return statistics.stdev(self.distinct) if len(self.distinct) > 1 else 0.0


def configurations(rows: list[dict[str, Any]]) -> list[Configuration]:
    """The rows of ``results_table`` grouped by everything but the seed (cells with executions only)."""
    groups: dict[tuple[str, str, str], list[tuple[int, float]]] = {}
    for r in rows:
        if isinstance(r.get("execs"), int) and r["execs"] > 0:
            ads = r["ads"] + ("" if r.get("ads_options") in (None, "", "{}") else f" {r['ads_options']}")
            groups.setdefault((r["network"], r["strategy"], ads), []).append((int(r["seed"]), float(r["distinct"])))
    return [Configuration(n, s, a, tuple(v for _, v in sorted(reps))) for (n, s, a), reps in groups.items()]


def comparisons(configs: list[Configuration]) -> list[tuple[Configuration, Configuration, float, float]]:
    """(a, b, Mann-Whitney p, A12 of a over b) for every pair on the same network with two or more repetitions."""
    out = []
    for a, b in combinations(configs, 2):
        if a.network == b.network and len(a.distinct) > 1 and len(b.distinct) > 1:
            out.append((a, b, mann_whitney_p(list(a.distinct), list(b.distinct)), a12(list(a.distinct), list(b.distinct))))
    return out


def comparison_markdown(configs: list[Configuration]) -> list[str]:
    lines = ["", "## Configurations (cells that differ only in the seed)", "",
             "| configuration | repetitions | distinct per repetition | mean | sd |", "|---|---|---|---|---|"]
    for c in configs:
        lines.append(f"| {c.label} | {len(c.distinct)} | {' '.join(f'{v:g}' for v in c.distinct)} | {c.mean:.2f} | {c.sd:.2f} |")
    pairs = comparisons(configs)
    if pairs:
        lines += ["", "## Comparisons (distinct findings; Mann-Whitney U, Vargha-Delaney A12)", "",
                  "| A | B | mean A / mean B | p | A12 |", "|---|---|---|---|---|"]
        for a, b, p, e in pairs:
            ratio = f"{a.mean / b.mean:.2f}" if b.mean else "-"
            lines.append(f"| {a.label} | {b.label} | {ratio} | {p:.4f} | {e:.2f} |")
    else:
        lines += ["", "No two configurations of one network have two or more repetitions each: no comparison."]
    return lines


def write_batch_report(out: Path, rows: list[dict[str, Any]]) -> Path:
    """``results.html``: one self-contained page (the plot inline) with the cells, configurations and
    comparisons."""
    from drivefuzz.storage import atomic_write_text

    configs = configurations(rows)
    e = html.escape
    cols = ["cell", "execs", "findings", "distinct", "incidents", "by_oracle", "status"]
    cell_rows = "".join("<tr>" + "".join(f"<td>{e(str(r[c]))}</td>" for c in cols) + "</tr>" for r in rows)
    md = "\n".join(comparison_markdown(configs))
    body = (f"<h1>drivefuzz batch: {e(out.name)}</h1><h2>Cells</h2><table><tr>"
            + "".join(f"<th>{c}</th>" for c in cols) + f"</tr>{cell_rows}</table>"
            + _plot(configs) + "<pre>" + e(md) + "</pre>")
    style = ("body{font-family:sans-serif;margin:2em;max-width:70em}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:.2em .5em;text-align:left}pre{white-space:pre-wrap}")
    page = f"<!doctype html><html><head><meta charset='utf-8'><title>drivefuzz batch</title><style>{style}</style></head><body>{body}</body></html>\n"
    atomic_write_text(out / "results.html", page)
    return out / "results.html"


def _plot(configs: list[Configuration]) -> str:
    if not configs:
        return ""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 0.5 + 0.4 * len(configs)))
    ax.boxplot([list(c.distinct) for c in configs], orientation="horizontal")
    ax.set_yticks(range(1, len(configs) + 1), [c.label for c in configs])
    ax.set_xlabel("distinct findings per repetition")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return f"<h2>Distinct findings</h2><img alt='distinct findings per configuration' src='data:image/png;base64,{base64.b64encode(buf.getvalue()).decode()}'>"
