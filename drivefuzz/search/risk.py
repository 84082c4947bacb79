"""Risk-shaped feedback: how close one execution came to a crash, from its frozen trace alone.

The search keeps the scenario with the **highest** :attr:`RiskScore.score`. Six components are
read from the :class:`~drivefuzz.sim.trace.Trace` (never from SUMO), each mapped to ``[0, 1]``
by a smooth monotone transform, then combined so that one near miss outweighs any amount of
routine driving (docs/feedback.md has the figures and the reasons):

* **ttc** [s]: minimum constant-velocity time-to-collision of the ego's and an actor's
  rectangles (moving separating-axis test), counted only when the actor's predicted position at
  contact lies on the ego's own path ahead (its trace positions over the horizon, then a ray
  along its heading). A car driving parallel in the next lane never closes on any axis: no TTC.
* **drac** [-]: deceleration required to avoid that crash, ``closing speed along the ego's
  heading / (2 TTC)`` [m/s^2], divided by the friction-limited deceleration ``mu g``.
* **pet** [s]: post-encroachment time. Both bodies' paths are cut into occupation nodes
  (one per ``pet_node_m`` travelled, with the time span the body spent there); where an actor's
  rectangle came within ``pet_reach_m`` of the ego's rectangle at another time, crossing at
  ``pet_min_angle_deg`` or more, the PET is the time between one leaving and the other arriving.
  Same-direction traffic (following, being followed) is TTC's and the gap's business: an actor node on the
  ego's own path (the ego's nearest node heads the actor's way) is following, even in a bend.
* **gap** [m]: minimum rectangle-to-rectangle distance to any actor (0 on contact).
* **grip** [-]: tyre-friction use ``sqrt(ax^2 + ay^2) / (mu g)`` with ``mu`` the lower of the two
  axles' (NaN: ``mu_default``), its peak sustained over ``grip_window_s``.
* **harsh** [s]: time spent braking, accelerating or turning harshly *while a hazard is near*
  (in-path TTC below ``hazard_ttc_s`` or gap lower bound below ``hazard_gap_m``); 0 otherwise.

``score = max_c(contribution_c) + tie * sum_c(contribution_c)`` with
``contribution_c = w_c * max(0, r_c - r_c(baseline))``: relative to the seed's clean run, per
component, so routine risk built into the map (a tight turn's grip use) does not count.

Used by the fuzz loop (feedback), the journal (:meth:`RiskScore.as_dict`) and targeted mutation
(:attr:`RiskScore.riskiest_actor`). Conventions as in the trace: SI, ENU radians, centres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from drivefuzz.geometry import rect_distance
from drivefuzz.search.episodes import GAP_M, episodes
from drivefuzz.search.pet import pet as _pet
from drivefuzz.search.rows import axes as _axes, index_type as _index_type, per_actor as _per_actor
from drivefuzz.scenario.model import EGO_LENGTH, EGO_WIDTH

__all__ = ["G", "COMPONENTS", "ACTOR_COMPONENTS", "RiskConfig", "RiskScore", "risk_score", "component_risks", "signals"]

#: Components, in report order; the first four concern one actor each.
COMPONENTS: tuple[str, ...] = ("ttc", "drac", "pet", "gap", "grip", "harsh")
ACTOR_COMPONENTS: tuple[str, ...] = ("ttc", "drac", "pet", "gap")
G = 9.80665  #: [m/s^2]
_DRAC_CAP = 100.0  # [-] ratio reported for contact (TTC = 0)


class RiskConfig(BaseModel):
    """Weights, transforms and thresholds of the risk score (units in each description)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    # --- weights and combination
    w_ttc: float = Field(1.0, ge=0, description="weight of r_ttc")
    w_drac: float = Field(0.8, ge=0, description="weight of r_drac")
    w_pet: float = Field(1.0, ge=0, description="weight of r_pet")
    w_gap: float = Field(1.0, ge=0, description="weight of r_gap")
    w_grip: float = Field(0.6, ge=0, description="weight of r_grip")
    w_harsh: float = Field(0.2, ge=0, description="weight of r_harsh (bounds what routine manoeuvres can add)")
    tie: float = Field(0.05, ge=0, description="[-] factor of the tie-breaking sum of all contributions")
    # --- transforms: r = 1/(1+(x/x50)^k) for 'smaller is riskier', 1/(1+(x50/x)^k) otherwise
    ttc_50_s: float = Field(1.5, gt=0, description="[s] TTC at which r_ttc = 0.5")
    ttc_k: float = Field(3.0, gt=0, description="steepness of r_ttc")
    drac_50: float = Field(0.5, gt=0, description="[-] DRAC/(mu g) at which r_drac = 0.5")
    drac_k: float = Field(3.0, gt=0, description="steepness of r_drac")
    pet_50_s: float = Field(1.5, gt=0, description="[s] PET at which r_pet = 0.5")
    pet_k: float = Field(3.0, gt=0, description="steepness of r_pet")
    gap_50_m: float = Field(0.6, gt=0, description="[m] body gap at which r_gap = 0.5")
    gap_k: float = Field(3.0, gt=0, description="steepness of r_gap")
    grip_50: float = Field(0.8, gt=0, description="[-] friction use at which r_grip = 0.5")
    grip_k: float = Field(6.0, gt=0, description="steepness of r_grip")
    harsh_tau_s: float = Field(1.0, gt=0, description="[s] r_harsh = 1 - exp(-harsh / tau)")
    # --- TTC and DRAC
    horizon_s: float = Field(5.0, gt=0, description="[s] TTCs beyond this are not counted")
    path_margin_m: float = Field(1.0, ge=0, description="[m] slack of 'on the ego's path ahead' (beyond half the bodies' widths)")
    path_step: int = Field(2, ge=1, description="[frames] spacing of the ego path points checked")
    g: float = Field(G, gt=0, description="[m/s^2] gravity")
    mu_default: float = Field(1.0, gt=0, description="[-] friction where the trace has none")
    # --- PET
    pet_node_m: float = Field(1.0, gt=0, description="[m] spacing of the occupation nodes of a path")
    pet_reach_m: float = Field(0.5, ge=0, description="[m] bodies this close (at different times) share a conflict area")
    pet_min_angle_deg: float = Field(25.0, ge=0, le=180, description="[deg] heading difference for a crossing conflict")
    # --- grip and harsh manoeuvres
    grip_window_s: float = Field(0.15, gt=0, description="[s] friction use must be held this long to count")
    hazard_ttc_s: float = Field(4.0, ge=0, description="[s] a hazard is near while the in-path TTC is below this")
    hazard_gap_m: float = Field(10.0, ge=0, description="[m] ... or while an actor's body is nearer than this")
    harsh_brake_mps2: float = Field(4.0, gt=0, description="[m/s^2] harsh braking: ax <= -this")
    harsh_accel_mps2: float = Field(2.5, gt=0, description="[m/s^2] harsh acceleration: ax >= this")
    harsh_lat_mps2: float = Field(4.0, gt=0, description="[m/s^2] harsh turning: |ay| >= this")

    def weight(self, component: str) -> float:
        return float(getattr(self, f"w_{component}"))


@dataclass(frozen=True)
class RiskScore:
    """Every component of one execution's risk (stored with it; a clean run's is the baseline)."""

    score: float  # higher = riskier; 0 for the baseline run itself
    ttc: float | None = None  # [s] min in-path TTC within the horizon; None: none
    ttc_frame: int | None = None
    ttc_actor: str | None = None
    drac: float | None = None  # [-] max DRAC / (mu g); None: no in-path TTC
    drac_frame: int | None = None
    drac_actor: str | None = None
    pet: float | None = None  # [s] min crossing PET; None: no crossing conflict
    pet_frame: int | None = None  # the later body's arrival
    pet_actor: str | None = None
    gap: float | None = None  # [m] min body gap; None: no actor
    gap_frame: int | None = None
    gap_actor: str | None = None
    grip: float = 0.0  # [-] peak sustained friction use
    grip_frame: int | None = None
    harsh: float = 0.0  # [s] harsh manoeuvring while a hazard was near
    harsh_frame: int | None = None  # the harshest such frame
    risks: dict[str, float] = field(default_factory=dict)  # component -> r in [0, 1], before the baseline
    contributions: dict[str, float] = field(default_factory=dict)  # w * max(0, r - r_baseline)
    actor_risk: dict[str, float] = field(default_factory=dict)  # actor id -> max_c w_c r_c (no baseline)
    riskiest_actor: str | None = None
    component: str | None = None  # the component of the moment below
    frame: int | None = None  # the riskiest actor's riskiest moment (else the top component's)
    time: float | None = None  # [s] trace time of that frame
    n_frames: int = 0
    #: every actor's extreme TTC, PET and gap with its frame: ``(actor, component, value, frame)`` where finite;
    #: what interaction coverage (:mod:`drivefuzz.triage.coverage`) classifies. Not in :meth:`as_dict`.
    encounters: tuple[tuple[str, str, float, int], ...] = ()
    #: every close encounter, one per episode of an actor's closeness (:mod:`drivefuzz.search.episodes`), in the
    #: same form: what interaction coverage classifies. Not in :meth:`as_dict`.
    episodes: tuple[tuple[str, str, float, int], ...] = ()

    def as_dict(self) -> dict[str, Any]:
        """JSON-safe dict (plain floats, ints, strings and None), without :attr:`encounters` and :attr:`episodes`."""
        out: dict[str, Any] = {}
        for k, v in self.__dict__.items():
            if k in ("encounters", "episodes"):
                continue
            if isinstance(v, dict):
                out[k] = {str(a): _num(b) for a, b in v.items()}
            else:
                out[k] = _num(v)
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "RiskScore":
        """Inverse of :meth:`as_dict` (for a baseline read back from a journal)."""
        return cls(**{k: (dict(v) if isinstance(v, Mapping) else v) for k, v in d.items()})

    def raw(self, component: str) -> float | None:
        return self.ttc if component == "ttc" else getattr(self, component)


def _num(v):
    if isinstance(v, (bool, str)) or v is None:
        return v
    if isinstance(v, (int, np.integer)):
        return int(v)
    v = float(v)
    return v if math.isfinite(v) else None


# ---------------------------------------------------------------------------- transforms
def _falling(x: float | None, x50: float, k: float) -> float:
    """1 at x = 0, 0.5 at x50, -> 0 for large x or None."""
    if x is None or not math.isfinite(x):
        return 0.0
    return 1.0 / (1.0 + (max(x, 0.0) / x50) ** k)


def _rising(x: float | None, x50: float, k: float) -> float:
    if x is None or not (x > 0):
        return 0.0
    if not math.isfinite(x):
        return 1.0
    return 1.0 / (1.0 + (x50 / x) ** k)


def component_risks(raw: Mapping[str, float | None], cfg: RiskConfig) -> dict[str, float]:
    """``r`` in [0, 1] of each component from its raw value (see the module docstring)."""
    return {
        "ttc": _falling(raw.get("ttc"), cfg.ttc_50_s, cfg.ttc_k),
        "drac": _rising(raw.get("drac"), cfg.drac_50, cfg.drac_k),
        "pet": _falling(raw.get("pet"), cfg.pet_50_s, cfg.pet_k),
        "gap": _falling(raw.get("gap"), cfg.gap_50_m, cfg.gap_k),
        "grip": _rising(raw.get("grip"), cfg.grip_50, cfg.grip_k),
        "harsh": 1.0 - math.exp(-max(raw.get("harsh") or 0.0, 0.0) / cfg.harsh_tau_s),
    }


# ---------------------------------------------------------------------------- inputs
def _channel(ego: Mapping[str, np.ndarray], name: str, n: int, default: float) -> np.ndarray:
    v = ego.get(name)
    if v is None:
        return np.full(n, default)
    v = np.asarray(v, dtype=float)
    return np.where(np.isfinite(v), v, default)


def _ego(trace, cfg: RiskConfig) -> dict[str, Any]:
    """The ego's per-frame state in SI, world-frame velocity, friction; NaNs replaced."""
    ego, n = trace.ego, trace.n_frames
    meta = trace.meta
    x, y, h = (np.asarray(ego[k], dtype=float) for k in ("x", "y", "heading"))
    speed = _channel(ego, "speed", n, 0.0)
    vx = np.asarray(ego.get("vx", np.full(n, np.nan)), dtype=float)
    vx = np.where(np.isfinite(vx), vx, speed)
    vy = _channel(ego, "vy", n, 0.0)
    c, s = np.cos(h), np.sin(h)
    mu = np.fmin(np.asarray(ego.get("mu_front", np.full(n, np.nan)), dtype=float),
                 np.asarray(ego.get("mu_rear", np.full(n, np.nan)), dtype=float))
    t = np.asarray(ego.get("t", (np.arange(n) + 1) * trace.step_length), dtype=float)
    return {
        "n": n, "x": x, "y": y, "h": h, "c": c, "s": s, "vx": vx,
        "vwx": vx * c - vy * s, "vwy": vx * s + vy * c,
        "ax": _channel(ego, "ax", n, 0.0), "ay": _channel(ego, "ay", n, 0.0),
        "mu": np.where(np.isfinite(mu) & (mu > 0), mu, cfg.mu_default), "t": t,
        "l": float(meta.get("ego_length") or EGO_LENGTH), "w": float(meta.get("ego_width") or EGO_WIDTH),
    }


def _rows(trace, e: dict[str, Any], cfg: RiskConfig) -> dict[str, np.ndarray] | None:
    """One entry per (frame, actor) sample with finite states, in frame order.

    ``near`` marks the rows where contact within the horizon or a gap under ``hazard_gap_m`` is
    possible at all (circle bound); only those get the rectangle tests."""
    a = trace.actors
    if len(a.frame) == 0 or e["n"] == 0:
        return None
    f = np.asarray(a.frame, dtype=np.int64)
    ok = np.isfinite(a.x) & np.isfinite(a.y) & np.isfinite(a.heading)
    ok &= np.isfinite(e["x"][f]) & np.isfinite(e["y"][f]) & np.isfinite(e["h"][f])
    if not ok.any():
        return None
    pick = (lambda v: v) if ok.all() else (lambda v: v[ok])  # noqa: E731
    f, j, ah = pick(f), pick(a.actor).astype(np.int64), pick(a.heading)
    sp = np.nan_to_num(pick(a.speed))
    c, s = np.cos(ah), np.sin(ah)
    rows = {"f": f, "j": j, "x": pick(a.x), "y": pick(a.y), "h": ah, "c": c, "s": s,
            "vx": sp * c, "vy": sp * s, "l": a.length[j], "w": a.width[j]}
    dx, dy = rows["x"] - e["x"][f], rows["y"] - e["y"][f]
    dvx, dvy = rows["vx"] - e["vwx"][f], rows["vy"] - e["vwy"][f]
    radii = 0.5 * math.hypot(e["l"], e["w"]) + 0.5 * np.hypot(a.length, a.width)[j]
    reach = np.maximum(cfg.hazard_gap_m, np.sqrt(dvx * dvx + dvy * dvy) * cfg.horizon_s) + radii
    rows["near"] = dx * dx + dy * dy < reach * reach
    rows["radii"] = radii
    return rows


def _take(rows: dict[str, np.ndarray], mask: np.ndarray) -> dict[str, np.ndarray]:
    idx = np.flatnonzero(mask)
    return {k: rows[k][idx] for k in ("f", "j", "x", "y", "h", "c", "s", "vx", "vy", "l", "w")}


# ---------------------------------------------------------------------------- TTC, DRAC, gap
def _ttc(rows, e, cfg: RiskConfig) -> tuple[np.ndarray, np.ndarray]:
    """Per row: constant-velocity TTC [s] of the two rectangles (inf: none within the horizon)
    and a lower bound of their gap [m]: outside one rectangle's two slabs by ``a`` and ``b``,
    the other is at least ``hypot(a, b)`` away (exact face to face)."""
    f = rows["f"]
    nx, ny, r = _axes(e["c"][f], e["s"][f], e["l"], e["w"], rows["c"], rows["s"], rows["l"], rows["w"])
    dx, dy = rows["x"] - e["x"][f], rows["y"] - e["y"][f]
    vx, vy = rows["vx"] - e["vwx"][f], rows["vy"] - e["vwy"][f]
    p0 = dx * nx + dy * ny
    pv = vx * nx + vy * ny
    out = np.maximum(np.abs(p0) - r, 0.0)  # each rectangle's slab: the other is this far outside it
    sep = np.maximum(np.hypot(out[0], out[1]), np.hypot(out[2], out[3]))
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / pv  # +-inf on an axis without relative motion: inside forever or never
        t1, t2 = (-r - p0) * inv, (r - p0) * inv
    t_in = np.minimum(t1, t2).max(axis=0)
    t_out = np.maximum(t1, t2).min(axis=0)
    hit = (t_in <= t_out) & (t_out >= 0.0) & (t_in <= cfg.horizon_s)
    return np.where(hit, np.maximum(t_in, 0.0), np.inf), sep


def _in_path(rows, idx: np.ndarray, ttc: np.ndarray, e, cfg: RiskConfig) -> np.ndarray:
    """Mask over ``idx``: the actor's predicted centre at contact lies on the ego's path ahead
    (its next ``horizon_s`` of trace positions, then a ray along its heading from there)."""
    if len(idx) == 0:
        return np.zeros(0, dtype=bool)
    n, dt = e["n"], max(float(e["t"][1] - e["t"][0]) if e["n"] > 1 else 0.05, 1e-6)
    f = rows["f"][idx]
    px = rows["x"][idx] + rows["vx"][idx] * ttc
    py = rows["y"][idx] + rows["vy"][idx] * ttc
    reach = 0.5 * e["w"] + 0.5 * np.maximum(rows["l"][idx], rows["w"][idx]) + cfg.path_margin_m
    ks = np.arange(0, int(math.ceil(cfg.horizon_s / dt)) + 1, cfg.path_step)
    fk = np.minimum(f[:, None] + ks[None, :], n - 1)
    d2 = ((e["x"][fk] - px[:, None]) ** 2 + (e["y"][fk] - py[:, None]) ** 2).min(axis=1)
    last = fk[:, -1]
    qx, qy = px - e["x"][last], py - e["y"][last]
    along = qx * e["c"][last] + qy * e["s"][last]
    across = np.abs(-qx * e["s"][last] + qy * e["c"][last])
    ray = np.where(along > 0.0, across, np.inf)
    return (d2 <= reach * reach) | (ray <= reach)


def _gap(rows, near: dict[str, np.ndarray], sep: np.ndarray, e, n_actors: int) -> tuple[np.ndarray, np.ndarray]:
    """Min body gap [m] per actor (inf where absent) and its frame (-1).

    Exact over the ``near`` rows: the row of least lower bound ``sep`` gives an upper bound,
    then ``rect_distance`` runs on the rows whose ``sep`` does not exceed it (one per relative
    pose). An actor's rows beyond ``hazard_gap_m`` count by the row of least centre distance."""
    far = np.flatnonzero(~rows["near"])
    f = rows["f"][far]
    clear = np.hypot(rows["x"][far] - e["x"][f], rows["y"][far] - e["y"][f]) - rows["radii"][far]
    best, at = _per_actor(clear, rows["j"][far], far, n_actors)
    if np.isfinite(best).any():  # ``at`` holds row indices here
        k = at[at >= 0]
        d = _distance(rows, k, e)
        best, at = np.full(n_actors, np.inf), np.full(n_actors, -1, dtype=np.int64)
        best[rows["j"][k]], at[rows["j"][k]] = d, rows["f"][k]
    if len(sep) == 0:
        return best, at
    f, j = near["f"], near["j"]
    _, first = _per_actor(sep, j, np.arange(len(sep)), n_actors)
    first = first[first >= 0]
    upper = np.full(n_actors, np.inf)
    upper[j[first]] = _distance(near, first, e)
    cand = np.flatnonzero(sep <= upper[j] + 1e-9)  # rounding: the bound can exceed the exact value
    cand = cand[_pose_changed(near, cand, e)]
    d_near, at_near = _per_actor(_distance(near, cand, e), j[cand], f[cand], n_actors)
    closer = d_near < best
    return np.where(closer, d_near, best), np.where(closer, at_near, at)


def _distance(rows, k: np.ndarray, e) -> np.ndarray:
    """Exact ego-to-actor rectangle distance [m] of rows ``k``."""
    f = rows["f"][k]
    return rect_distance(e["x"][f], e["y"][f], e["h"][f], e["l"], e["w"],
                         rows["x"][k], rows["y"][k], rows["h"][k], rows["l"][k], rows["w"][k])


def _pose_changed(rows, cand: np.ndarray, e, tol_m: float = 0.01) -> np.ndarray:
    """Mask over ``cand`` (in frame order): the actor's pose relative to the ego differs (on a
    ``tol_m`` grid, heading on a ``tol_m`` rad grid) from the same actor's previous candidate row.

    Standing together, or driving in convoy, repeats one relative pose for hundreds of frames;
    one exact distance per pose is enough (error under ``tol_m`` plus ``tol_m`` rad x half a length)."""
    f, j = rows["f"][cand], rows["j"][cand]
    ec, es = e["c"][f], e["s"][f]
    dx, dy = rows["x"][cand] - e["x"][f], rows["y"][cand] - e["y"][f]
    key = np.stack([np.round((dx * ec + dy * es) / tol_m), np.round((dy * ec - dx * es) / tol_m),
                    np.round(((rows["h"][cand] - e["h"][f]) % (2 * np.pi)) / tol_m), j])
    o = np.argsort(j.astype(_index_type(len(j) and int(j.max()) + 1)), kind="stable")  # per actor, in time order
    change = np.ones(len(cand), dtype=bool)
    change[o[1:]] = (key[:, o[1:]] != key[:, o[:-1]]).any(axis=0)
    return change


def _per_frame_min(values: np.ndarray, f: np.ndarray, n: int) -> np.ndarray:
    out = np.full(n, np.inf)
    np.minimum.at(out, f, values)
    return out


# ---------------------------------------------------------------------------- ego-only components
def _grip(e, cfg: RiskConfig, dt: float) -> tuple[float, int | None]:
    """Peak friction use held for ``grip_window_s`` and the frame where that window ends."""
    use = np.hypot(e["ax"], e["ay"]) / (e["mu"] * cfg.g)
    if len(use) == 0:
        return 0.0, None
    w = min(max(1, int(round(cfg.grip_window_s / dt))), len(use))
    held = np.lib.stride_tricks.sliding_window_view(use, w).min(axis=1) if w > 1 else use
    k = int(np.argmax(held))
    return float(held[k]), k + w - 1


def _harsh(e, hazard: np.ndarray, cfg: RiskConfig, dt: float) -> tuple[float, int | None]:
    """Seconds of harsh braking, acceleration or turning while a hazard was near; the harshest frame."""
    level = np.maximum.reduce([-e["ax"] / cfg.harsh_brake_mps2, e["ax"] / cfg.harsh_accel_mps2,
                               np.abs(e["ay"]) / cfg.harsh_lat_mps2])
    level = np.where(hazard, level, 0.0)
    count = int((level >= 1.0).sum())
    if count == 0:
        return 0.0, None
    return count * dt, int(np.argmax(level))


# ---------------------------------------------------------------------------- score
@dataclass
class _Actors:
    """Per-actor raw values of the actor components and their frames (inf / -1: none)."""

    ttc: np.ndarray
    ttc_at: np.ndarray
    drac: np.ndarray
    drac_at: np.ndarray
    pet: np.ndarray
    pet_at: np.ndarray
    gap: np.ndarray
    gap_at: np.ndarray


def _actor_components(trace, e, cfg: RiskConfig) -> tuple[_Actors | None, np.ndarray, np.ndarray, tuple]:
    """TTC, DRAC, PET and gap per actor; per frame the least in-path TTC [s] and gap bound [m]; the close
    encounters' episodes (:func:`drivefuzz.search.episodes.episodes`)."""
    n = e["n"]
    rows = _rows(trace, e, cfg)
    if rows is None:
        return None, np.full(n, np.inf), np.full(n, np.inf), ()
    n_act = len(trace.actors.ids)
    near = _take(rows, rows["near"])
    ttc, sep = _ttc(near, e, cfg)
    idx = np.flatnonzero(np.isfinite(ttc))
    idx = idx[_in_path(near, idx, ttc[idx], e, cfg)]
    tt, fi, ji = ttc[idx], near["f"][idx], near["j"][idx]
    # DRAC: the closing speed along the ego's heading, shed within the TTC
    close = e["vx"][fi] - (near["vx"][idx] * e["c"][fi] + near["vy"][idx] * e["s"][fi])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.maximum(close, 0.0) / (2.0 * tt * e["mu"][fi] * cfg.g)
    ratio = np.where(close > 0.0, np.minimum(np.nan_to_num(ratio, nan=_DRAC_CAP), _DRAC_CAP), 0.0)
    out = _Actors(*_per_actor(tt, ji, fi, n_act), *_per_actor(ratio, ji, fi, n_act, largest=True),
                  *_pet(trace, e, cfg), *_gap(rows, near, sep, e, n_act))
    close = _episodes(near, sep, e, out, (ji, fi, tt), trace)
    return out, _per_frame_min(tt, fi, n), _per_frame_min(sep, near["f"], n), close


def _episodes(near, sep: np.ndarray, e, acts: _Actors, ttc_rows, trace) -> tuple:
    """The close encounters' episodes from the in-path TTC rows ``(actor, frame, ttc)``, the exact gaps of the
    ``near`` rows whose gap bound is under :data:`~drivefuzz.search.episodes.GAP_M` (a row off ``near`` is
    farther than ``hazard_gap_m``, 10 m by default), and each actor's least PET (a crossing is one event)."""
    cand = np.flatnonzero(sep < GAP_M)
    pet = np.flatnonzero(np.isfinite(acts.pet) & (acts.pet_at >= 0))
    return episodes({"ttc": ttc_rows, "gap": (near["j"][cand], near["f"][cand], _distance(near, cand, e)),
                     "pet": (pet, acts.pet_at[pet], acts.pet[pet])}, trace.actors.ids, trace.step_length)


def _extremes(acts: _Actors | None, ids: tuple[str, ...]):
    """Run-wide raw value, frame and actor of each actor component (absent when never seen)."""
    raw, frames, who = {}, {}, {}
    if acts is None:
        return raw, frames, who
    for c, largest in (("ttc", False), ("drac", True), ("pet", False), ("gap", False)):
        vals = getattr(acts, c)
        if np.isfinite(vals).any():
            k = int(np.argmax(vals) if largest else np.argmin(vals))
            raw[c], frames[c], who[c] = float(vals[k]), int(getattr(acts, f"{c}_at")[k]), ids[k]
    return raw, frames, who


def _encounters(acts: _Actors | None, ids: tuple[str, ...]) -> tuple[tuple[str, str, float, int], ...]:
    """``(actor, component, value, frame)`` of every finite per-actor TTC, PET and gap."""
    if acts is None:
        return ()
    out = []
    for c in ("ttc", "pet", "gap"):
        vals, at = getattr(acts, c), getattr(acts, f"{c}_at")
        for k in np.flatnonzero(np.isfinite(vals) & (at >= 0)):
            out.append((ids[k], c, float(vals[k]), int(at[k])))
    return tuple(out)


def _riskiest(acts: _Actors | None, ids: tuple[str, ...], cfg: RiskConfig):
    """Per actor ``max_c w_c r_c`` (no baseline), and the riskiest actor's component and frame."""
    risk: dict[str, float] = {}
    top: tuple[float, str | None, str | None, int | None] = (0.0, None, None, None)
    if acts is None:
        return risk, top
    for k, aid in enumerate(ids):
        raw = {c: float(getattr(acts, c)[k]) for c in ACTOR_COMPONENTS}
        r = component_risks(raw, cfg)
        c = max(ACTOR_COMPONENTS, key=lambda name: cfg.weight(name) * r[name])
        risk[aid] = cfg.weight(c) * r[c]
        if risk[aid] > top[0]:
            top = (risk[aid], aid, c, int(getattr(acts, f"{c}_at")[k]))
    return risk, top


def signals(trace, config: RiskConfig | None = None) -> dict[str, np.ndarray]:
    """Per-frame signals behind the score, for plots and tests: ``t`` [s]; ``ttc`` least in-path
    TTC [s] (inf: none); ``gap_lb`` lower bound of the least body gap [m] (inf: no actor near);
    ``grip`` friction use [-]; ``hazard`` the 'hazard near' mask that gates harsh manoeuvres."""
    cfg = config or RiskConfig()
    e = _ego(trace, cfg)
    _, ttc_f, gap_f, _ = _actor_components(trace, e, cfg)
    return {"t": e["t"], "ttc": ttc_f, "gap_lb": gap_f, "grip": np.hypot(e["ax"], e["ay"]) / (e["mu"] * cfg.g),
            "hazard": (ttc_f < cfg.hazard_ttc_s) | (gap_f < cfg.hazard_gap_m)}


def risk_score(trace, config: RiskConfig | None = None, baseline: RiskScore | None = None) -> RiskScore:
    """Score one execution's :class:`~drivefuzz.sim.trace.Trace` (higher = riskier).

    ``baseline`` is the :class:`RiskScore` of the seed's clean run: each component counts only
    by how much its ``r`` exceeds the baseline's (recomputed from the baseline's raw values
    with this ``config``), so scoring the clean run against itself gives 0.
    """
    cfg = config or RiskConfig()
    n = trace.n_frames
    zero = {c: 0.0 for c in COMPONENTS}
    if n == 0:
        return RiskScore(score=0.0, risks=dict(zero), contributions=dict(zero))
    dt = trace.step_length
    e = _ego(trace, cfg)
    acts, ttc_f, gap_f, close = _actor_components(trace, e, cfg)
    hazard = (ttc_f < cfg.hazard_ttc_s) | (gap_f < cfg.hazard_gap_m)
    ids = trace.actors.ids
    raw, frames, who = _extremes(acts, ids)
    raw["grip"], frames["grip"] = _grip(e, cfg, dt)
    raw["harsh"], frames["harsh"] = _harsh(e, hazard, cfg, dt)
    risks = component_risks(raw, cfg)
    base = component_risks({c: baseline.raw(c) for c in COMPONENTS}, cfg) if baseline else zero
    contrib = {c: cfg.weight(c) * max(0.0, risks[c] - base[c]) for c in COMPONENTS}
    score = max(contrib.values()) + cfg.tie * sum(contrib.values())
    actor_risk, (_, riskiest, component, frame) = _riskiest(acts, ids, cfg)
    if riskiest is None and score > 0.0:
        component = max(COMPONENTS, key=contrib.__getitem__)
        frame = frames.get(component)
    return RiskScore(
        score=float(score),
        ttc=raw.get("ttc"), ttc_frame=frames.get("ttc"), ttc_actor=who.get("ttc"),
        drac=raw.get("drac"), drac_frame=frames.get("drac"), drac_actor=who.get("drac"),
        pet=raw.get("pet"), pet_frame=frames.get("pet"), pet_actor=who.get("pet"),
        gap=raw.get("gap"), gap_frame=frames.get("gap"), gap_actor=who.get("gap"),
        grip=float(raw["grip"]), grip_frame=frames["grip"],
        harsh=float(raw["harsh"]), harsh_frame=frames["harsh"],
        risks=risks, contributions=contrib, actor_risk=actor_risk,
        riskiest_actor=riskiest, component=component, frame=frame,
        time=None if frame is None else float(e["t"][frame]), n_frames=n, encounters=_encounters(acts, ids),
        episodes=close,
    )
