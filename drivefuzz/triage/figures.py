"""The pictures of a campaign report (:mod:`drivefuzz.triage.report`), drawn with matplotlib (Agg) and Pillow:
a finding's top-down scene with trails and its animation (:class:`Scene`), the time series around the failure
(:func:`series_png`), and the risk of every execution (:func:`risk_png`). Each returns PNG or GIF bytes."""

from __future__ import annotations

import io
import math

import numpy as np

from drivefuzz.triage.table import CampaignInfo

#: [s] of the failure drawn as trails and animated
WINDOW_S = 5.0
#: animation frames at most
MAX_GIF_FRAMES = 20
#: [s] of the time series before the failure (and up to the end of the trace after it)
SERIES_S = 20.0

_COLORS = {"ego": "#d62728", "other": "#ff7f0e", "vehicle": "#1f77b4", "pedestrian": "#2ca02c"}



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
def pyplot():
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


def series_png(plt, trace, f: int, other: str | None) -> bytes:
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


def risk_png(plt, info: CampaignInfo) -> bytes:
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
