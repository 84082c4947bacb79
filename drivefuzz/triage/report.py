"""``drivefuzz report OUT``: one self-contained HTML file about a campaign, and its Markdown twin.

Reads what :mod:`drivefuzz.triage.table` reads, plus each finding folder's trace and scenario,
and draws with matplotlib (Agg) and Pillow. The HTML holds its CSS and its pictures inline
(``data:`` URIs), so it opens anywhere with no network; ``report.md`` next to it holds the same
text and tables without the pictures.

Contents: the campaign (executions, rate, budget, search, ADS, oracles, why it stopped), the risk of
every execution, the findings by signature, then a card per signature (:data:`MAX_CARDS` at most):
a top-down picture of the failure, an animation of its last :data:`WINDOW_S` seconds, time series of
the ego's speed, the gap to the other party, throttle, brake and steer, and the replay command.
Incidents (not the ego's fault) follow in a section of their own.

A folder whose trace or network cannot be read gets a card with a note instead of pictures; without
matplotlib the report has no pictures at all, and says so.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from drivefuzz.triage.crashtype import LABELS as CRASH_LABELS
from drivefuzz.triage.table import CampaignInfo, FindingRow, finding_rows, load_campaign_info

#: cards at most (findings first, then incidents): the report stays quick to write and to open
MAX_CARDS = 50
#: [s] of the failure drawn as trails and animated
WINDOW_S = 5.0
#: animation frames at most
MAX_GIF_FRAMES = 20
#: [s] of the time series before the failure (and up to the end of the trace after it)
SERIES_S = 20.0

_COLORS = {"ego": "#d62728", "other": "#ff7f0e", "vehicle": "#1f77b4", "pedestrian": "#2ca02c"}


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
    plt = _pyplot()
    cards: list[Card] = []
    for row in (findings + incidents)[:max_cards]:
        t0 = time.perf_counter()
        cards.append(make_card(info.out, row, plt, animate))
        log(f"card {row.folder}: {time.perf_counter() - t0:.1f} s")
    risk = _risk_png(plt, info) if plt is not None and info.executions else None
    html_path = Path(html_path) if html_path else info.out / "report.html"
    md_path = html_path.with_suffix(".md")
    skipped = len(findings) + len(incidents) - len(cards)
    notes = ([] if plt is not None else ["matplotlib is not installed: no pictures"]) + (
        [f"{skipped} more card(s) left out (at most {max_cards})"] if skipped > 0 else [])
    from drivefuzz.storage import atomic_write_text

    cov = _coverage(info.out)
    for path, text in ((html_path, render_html(info, findings, incidents, cards, risk, notes, cov)),
                       (md_path, render_markdown(info, findings, incidents, cards, notes, cov))):
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
        card.series_png = _series_png(plt, trace, f, card.other)
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


def _track(trace, actor_id: str) -> dict[str, np.ndarray]:
    """Per-frame x, y, heading, speed of one actor (NaN where it is absent)."""
    a = trace.actors
    j = a.ids.index(actor_id)
    sel = a.actor == j
    out = {}
    for name in ("x", "y", "heading", "speed"):
        arr = np.full(trace.n_frames, np.nan)
        arr[a.frame[sel]] = getattr(a, name)[sel]
        out[name] = arr
    out["length"], out["width"] = float(a.length[j]), float(a.width[j])
    return out


def _box(x: float, y: float, heading: float, length: float, width: float) -> np.ndarray:
    """(4, 2) corners of a body centred at (x, y), heading [rad ENU]."""
    c, s = math.cos(heading), math.sin(heading)
    local = np.array([(0.5, 0.5), (-0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)]) * (length, width)
    return np.stack([x + c * local[:, 0] - s * local[:, 1], y + s * local[:, 0] + c * local[:, 1]], axis=1)


# ------------------------------------------------------------------ the pictures
def _pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    return plt


def _png(fig, plt) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi)
    plt.close(fig)
    return buf.getvalue()


class Scene:
    """The top-down view of a failure: lanes, puddles, the ego and the actors with their trails."""

    def __init__(self, trace, frame: int, other: str | None, rmap, scenario):
        self.trace, self.f, self.other, self.rmap, self.scenario = trace, frame, other, rmap, scenario
        dt = trace.step_length
        self.f0 = max(frame - int(round(WINDOW_S / dt)), 0)
        self.ego_len = float(trace.meta.get("ego_length", 4.6))
        self.ego_wid = float(trace.meta.get("ego_width", 1.9))
        a, lo, hi = trace.actors, int(trace.actors.offsets[self.f0]), int(trace.actors.offsets[frame + 1])
        xs = np.concatenate([trace["x"][self.f0:frame + 1], a.x[lo:hi]])
        ys = np.concatenate([trace["y"][self.f0:frame + 1], a.y[lo:hi]])
        ex, ey = float(trace["x"][frame]), float(trace["y"][frame])
        near = np.hypot(xs - ex, ys - ey) < 60.0  # far actors would zoom the picture out
        xs, ys = xs[near], ys[near]
        half = max(float(np.ptp(xs)) if len(xs) else 0.0, float(np.ptp(ys)) if len(ys) else 0.0, 30.0) / 2 + 8.0
        self.cx = (float(xs.min()) + float(xs.max())) / 2 if len(xs) else ex
        self.cy = (float(ys.min()) + float(ys.max())) / 2 if len(ys) else ey
        self.half = half

    def _axes(self, plt, size_in: float = 3.6):
        fig = plt.figure(figsize=(size_in, size_in), dpi=90)
        ax = fig.add_axes((0, 0, 1, 1))
        ax.set_xlim(self.cx - self.half, self.cx + self.half)
        ax.set_ylim(self.cy - self.half, self.cy + self.half)
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_facecolor("#e8efe4")
        fig.patch.set_facecolor("#e8efe4")
        self._draw_map(ax)
        self._draw_puddles(ax)
        return fig, ax

    def _draw_map(self, ax) -> None:
        if self.rmap is None:
            return
        from matplotlib.collections import PolyCollection

        pad = self.half + 20
        road, walk, dividers, centres = _lane_polygons(self.rmap, (self.cx - pad, self.cy - pad,
                                                                   self.cx + pad, self.cy + pad))
        ax.add_collection(PolyCollection(walk, facecolors="#cfcfc8", edgecolors="none", zorder=1))
        ax.add_collection(PolyCollection(road, facecolors="#5f6368", edgecolors="#5f6368", linewidths=0.5, zorder=2))
        for line in dividers:
            ax.plot(line[:, 0], line[:, 1], color="white", lw=0.6, ls=(0, (4, 4)), zorder=3)
        for line in centres:
            ax.plot(line[:, 0], line[:, 1], color="#f2d16b", lw=0.8, zorder=3)

    def _draw_puddles(self, ax) -> None:
        from matplotlib.patches import Polygon

        for p in getattr(self.scenario, "puddles", ()) or ():
            ax.add_patch(Polygon(p.corners(), closed=True, facecolor="#3d8bfd", alpha=0.35 + 0.4 * (1 - min(p.friction, 1.0)),
                                 edgecolor="#1c5cc7", lw=0.8, zorder=4))

    def _draw_bodies(self, ax, f: int, trails: bool) -> list:
        """The ego and the actors at frame ``f`` (trails from the window's start); returns the artists."""
        from matplotlib.patches import Polygon

        t, a = self.trace, self.trace.actors
        artists = []
        rows = a.rows(f)
        for k in range(rows.start, rows.stop):
            aid = a.ids[int(a.actor[k])]
            kind = a.kinds[int(a.actor[k])]
            color = _COLORS["other"] if aid == self.other else _COLORS.get(kind, _COLORS["vehicle"])
            if trails:
                tr = _track(t, aid)
                artists += ax.plot(tr["x"][self.f0:f + 1], tr["y"][self.f0:f + 1], color=color, lw=1.2, alpha=0.6, zorder=5)
            box = _box(a.x[k], a.y[k], a.heading[k], float(a.length[a.actor[k]]), float(a.width[a.actor[k]]))
            artists.append(ax.add_patch(Polygon(box, closed=True, facecolor=color, edgecolor="black", lw=0.6, zorder=6)))
            if aid == self.other or np.hypot(a.x[k] - self.cx, a.y[k] - self.cy) < self.half:
                artists.append(ax.annotate(aid, (a.x[k], a.y[k]), xytext=(4, 4), textcoords="offset points",
                                           fontsize=7, color="#222", zorder=8, annotation_clip=True))
        if trails:
            artists += ax.plot(t["x"][self.f0:f + 1], t["y"][self.f0:f + 1], color=_COLORS["ego"], lw=1.6, alpha=0.7, zorder=5)
        box = _box(t["x"][f], t["y"][f], t["heading"][f], self.ego_len, self.ego_wid)
        artists.append(ax.add_patch(Polygon(box, closed=True, facecolor=_COLORS["ego"], edgecolor="black", lw=0.8, zorder=7)))
        nose = box[[0, 3]].mean(axis=0)  # a dot at the front shows which way it faces
        artists += ax.plot([nose[0]], [nose[1]], "o", color="white", ms=2.5, zorder=8)
        return artists

    def _stamp(self, ax, f: int):
        t = float(self.trace["t"][f])
        return ax.text(0.02, 0.97, f"t = {t:.2f} s  ego {self.trace['speed'][f] * 3.6:.0f} km/h", transform=ax.transAxes,
                       va="top", fontsize=8, bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "none"}, zorder=9)

    def png(self, plt) -> bytes:
        fig, ax = self._axes(plt)
        self._draw_bodies(ax, self.f, trails=True)
        self._stamp(ax, self.f)
        ax.plot([], [], color=_COLORS["ego"], lw=4, label="ego")
        if self.other:
            ax.plot([], [], color=_COLORS["other"], lw=4, label=f"other party ({self.other})")
        ax.legend(loc="lower right", fontsize=7, framealpha=0.8)
        return _png(fig, plt)

    def gif(self, plt) -> bytes | None:
        """The window's frames as a looping GIF at real time (None without Pillow)."""
        try:
            from PIL import Image
        except ImportError:
            return None
        n = self.f - self.f0 + 1
        frames = np.unique(np.linspace(self.f0, self.f, min(n, MAX_GIF_FRAMES)).round().astype(int))
        fig, ax = self._axes(plt, size_in=3.0)
        fig.canvas.draw()
        images = []
        for f in frames:
            artists = self._draw_bodies(ax, int(f), trails=False) + [self._stamp(ax, int(f))]
            fig.canvas.draw()
            rgba = np.asarray(fig.canvas.buffer_rgba())
            images.append(Image.fromarray(rgba[:, :, :3]).quantize(colors=64, method=Image.Quantize.MEDIANCUT))
            for art in artists:
                art.remove()
        plt.close(fig)
        step_ms = int(round(1000 * self.trace.step_length * (self.f - self.f0) / max(len(frames) - 1, 1)))
        durations = [max(step_ms, 20)] * (len(images) - 1) + [1500]  # hold the failure frame
        buf = io.BytesIO()
        images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=durations, loop=0)
        return buf.getvalue()


_LANE_CACHE: dict[int, tuple[list, list, list]] = {}


def _lane_polygons(rmap, bbox) -> tuple[list, list, list, list]:
    """(road polygons, sidewalk polygons, lane dividers, centre lines) of the network within ``bbox``."""
    key = id(rmap)
    if key not in _LANE_CACHE:
        _LANE_CACHE[key] = _network_polygons(rmap)
    polys, dividers, centres = _LANE_CACHE[key]
    x0, y0, x1, y1 = bbox

    def inside(a: np.ndarray) -> bool:
        return a[:, 0].max() >= x0 and a[:, 0].min() <= x1 and a[:, 1].max() >= y0 and a[:, 1].min() <= y1

    return ([p for p, road in polys if road and inside(p)], [p for p, road in polys if not road and inside(p)],
            [m for m in dividers if inside(m)], [m for m in centres if inside(m)])


def _network_polygons(rmap):
    """Every junction's shape and every lane buffered to its width, as (ring, is_road), and the lines
    between lanes of one edge (dashed) and on the left of each edge (solid); once per network."""
    from shapely.geometry import LineString, Polygon

    polys: list[tuple[np.ndarray, bool]] = []
    dividers, centres = [], []

    def add(poly, is_road):
        for g in getattr(poly, "geoms", [poly]):
            if not g.is_empty:
                polys.append((np.asarray(g.exterior.coords)[:, :2], is_road))

    for node in rmap.net.getNodes():
        shape = node.getShape()
        if len(shape) >= 3:
            add(Polygon([p[:2] for p in shape]).buffer(0), True)
    for edge in rmap.net.getEdges(withInternal=True):
        lanes = edge.getLanes()
        for lane in lanes:
            shape = [p[:2] for p in lane.getShape()]
            if len(shape) < 2:
                continue
            road = lane.allows("passenger") or not lane.allows("pedestrian")
            line = LineString(shape)
            add(line.buffer(lane.getWidth() / 2, cap_style="flat"), road)
            if edge.getFunction() == "" and road:
                left = line.offset_curve(lane.getWidth() / 2)
                if not left.is_empty and left.geom_type == "LineString":
                    (dividers if lane.getIndex() < len(lanes) - 1 else centres).append(np.asarray(left.coords)[:, :2])
    return polys, dividers, centres


def _series_png(plt, trace, f: int, other: str | None) -> bytes:
    """Speed, gap to the other party, throttle and brake, steer around the failure."""
    t = np.asarray(trace["t"], dtype=float)
    lo = int(np.searchsorted(t, t[f] - SERIES_S))
    sl = slice(lo, trace.n_frames)
    fig, axes = plt.subplots(4, 1, figsize=(5.6, 4.5), dpi=90, sharex=True,
                             gridspec_kw={"height_ratios": [1.3, 1.0, 1.0, 0.8]})
    ax = axes[0]
    ax.plot(t[sl], trace["speed"][sl] * 3.6, color=_COLORS["ego"], lw=1.4, label="ego")
    if "speed_limit" in trace.ego:
        ax.plot(t[sl], trace["speed_limit"][sl] * 3.6, color="black", lw=0.9, ls="--", label="limit")
    tr = _track(trace, other) if other else None
    if tr is not None:
        ax.plot(t[sl], tr["speed"][sl] * 3.6, color=_COLORS["other"], lw=1.1, label=other)
    ax.set_ylabel("speed\n[km/h]", fontsize=8)
    ax.legend(fontsize=7, loc="upper left", ncol=3, framealpha=0.8)
    ax = axes[1]
    if tr is not None:
        ax.plot(t[sl], _gap(trace, tr)[sl], color=_COLORS["other"], lw=1.2)
        ax.axhline(0.0, color="grey", lw=0.6)
    else:
        ax.text(0.5, 0.5, "no other party", transform=ax.transAxes, ha="center", va="center", fontsize=8, color="grey")
    ax.set_ylabel(f"gap to\n{other or '-'} [m]", fontsize=8)
    ax = axes[2]
    ax.plot(t[sl], trace["throttle"][sl], color="#2ca02c", lw=1.2, label="throttle")
    ax.plot(t[sl], trace["brake"][sl], color="#9467bd", lw=1.2, label="brake")
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("pedals\n[0..1]", fontsize=8)
    ax.legend(fontsize=7, loc="upper left", ncol=2, framealpha=0.8)
    ax = axes[3]
    ax.plot(t[sl], trace["steer"][sl], color="#8c564b", lw=1.2)
    ax.set_ylim(-1.05, 1.05)
    ax.set_ylabel("steer\n[-1..1]", fontsize=8)
    ax.set_xlabel("simulated time [s]", fontsize=8)
    for ax in axes:
        ax.axvline(t[f], color=_COLORS["ego"], lw=0.9, ls=":")
        ax.axvspan(max(t[f] - WINDOW_S, t[lo]), t[f], color="#ffe7cc", alpha=0.5, lw=0)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout(h_pad=0.3)
    return _png(fig, plt)


def _gap(trace, tr: dict[str, np.ndarray]) -> np.ndarray:
    """[m] between the ego's body and the other's, per frame (NaN where it is absent; 0 when they touch)."""
    import shapely

    n = trace.n_frames
    ok = ~np.isnan(tr["x"])
    out = np.full(n, np.nan)
    if not ok.any():
        return out
    ego = [_box(trace["x"][i], trace["y"][i], trace["heading"][i], float(trace.meta.get("ego_length", 4.6)),
                float(trace.meta.get("ego_width", 1.9))) for i in np.flatnonzero(ok)]
    oth = [_box(tr["x"][i], tr["y"][i], tr["heading"][i], tr["length"], tr["width"]) for i in np.flatnonzero(ok)]
    out[ok] = shapely.distance(shapely.polygons(np.asarray(ego)), shapely.polygons(np.asarray(oth)))
    return out


def _risk_png(plt, info: CampaignInfo) -> bytes:
    """Risk per execution (by exec_id), coloured by outcome, and the running maximum."""
    ex = [e for e in info.executions if e.risk is not None]
    fig, ax = plt.subplots(figsize=(8.0, 2.8), dpi=90)
    if ex:
        ids = np.array([e.exec_id for e in ex])
        risk = np.array([e.risk for e in ex])
        kind = np.array(["pass" if not e.verdict else "incident" if (e.folder or "").startswith("incidents/")
                         else "finding" for e in ex])
        for name, color, size in (("pass", "#9aa0a6", 10), ("finding", _COLORS["ego"], 18), ("incident", _COLORS["other"], 18)):
            sel = kind == name
            if sel.any():
                ax.scatter(ids[sel], risk[sel], s=size, color=color, label=f"{name} ({int(sel.sum())})", zorder=3)
        ax.step(ids, np.maximum.accumulate(risk), where="post", color="black", lw=1.2, label="running maximum")
        ax.legend(fontsize=7, loc="lower right", framealpha=0.85)
    ax.set_xlabel("execution (exec_id)", fontsize=8)
    ax.set_ylabel("risk score", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _png(fig, plt)


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
                risk_png: bytes | None, notes: list[str], coverage: dict[str, Any] | None = None) -> str:
    from drivefuzz.triage.coverage_map import CSS as COVERAGE_CSS, section_html

    facts = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in campaign_facts(info))
    by_folder = {c.row.folder: c for c in cards}
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>drivefuzz report: {_e(info.out.name)}</title><style>{_CSS}{COVERAGE_CSS}</style></head><body>",
        f"<h1>drivefuzz report: {_e(info.out.name)}</h1>",
        f'<p class="sub">{len(findings)} finding(s) and {len(incidents)} incident(s), one per signature; '
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
        "</body></html>",
    ]
    return "\n".join(parts)


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
                    notes: list[str], coverage: dict[str, Any] | None = None) -> str:
    from drivefuzz.triage.ads_info import to_markdown
    from drivefuzz.triage.coverage_map import section_md

    cards = {c.row.folder: c for c in card_list}
    lines = [f"# drivefuzz report: {info.out.name}", "",
             f"{len(findings)} finding(s) and {len(incidents)} incident(s), one per signature. "
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
    return "\n".join(lines)
