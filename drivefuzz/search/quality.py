"""Driving-quality feedback: the score DriveFuzz uses to pick the scenario worth mutating.

    score = -(w_ha*#ha + w_hb*#hb + w_ht*#ht + w_os*#os + w_us*#us + c_md / max(md, md_eps))

(paper, eq. ``eq:score``; all weights 1 and ``c_md = 1`` by default). Each ``#`` is a count
of *frames*; ``md`` is the smallest body-to-body distance between the ego and any actor.
:func:`score_trace` returns a :class:`QualityScore` with every component and the frames
where each event fired; :func:`signals` returns the intermediate signals for plots.

Units and definitions (decisions documented here once)
------------------------------------------------------
* ``g = 9.80665 m/s^2`` (the constant behind the original's 0.0283254 = 1/(3.6 g)).
* **#ha / #hb**: ``K_ab = A_x / g`` with ``A_x`` the trace's body-frame longitudinal
  acceleration ``ax`` (not differentiated speed, which in the original added the
  spawn-drop's vertical speed). A frame counts when ``K_ab >= 0.6`` (ha) or ``<= -0.6`` (hb).
  If ``ax`` is missing (NaN) it is replaced by the time derivative of ``vx``.
* **#ht**: ``SWA`` is the **steering-wheel** angle (trace ``steer_wheel_angle``) in degrees,
  as the paper says, not the road-wheel angle the original code used; ``V_y`` is the
  body-frame lateral speed ``vy`` in km/h. Both as absolute values. A frame counts when
  ``|SWA| >= 20 deg`` and ``K_t = |V_y| / |SWA| >= 0.18 (km/h)/deg``. (Under this reading
  a hard turn needs a large side-slip, e.g. 16 km/h of lateral speed at 90 deg of wheel.)
* **Fuzzy inputs** (the original's units): SWA in steering-wheel degrees, ``V_x`` in km/h,
  yaw rate ``AV_z`` in deg/s (trace ``yaw_rate``), lateral acceleration ``A_y`` in g from the
  trace's ``ay`` (body frame, *including* the centripetal part ``v * yaw_rate``, i.e. what an
  accelerometer reads; the original differentiated the lateral speed, which is ~0 in a
  steady turn and so cannot express a steering-to-acceleration gain).
* **Filters**: ``LP(x, f)`` is a 4th-order Butterworth low-pass, zero-phase
  (``scipy.signal.sosfiltfilt``), designed for the trace's real sample rate
  ``1/step_length``. "light" = 3.5 Hz, "heavy" = 0.5 Hz. A cut-off at or above Nyquist
  leaves the signal unfiltered; traces shorter than scipy's padding (16 samples) are
  filtered with the padding reduced to ``n - 1``; a 1-sample trace is left as is.
* Band-passes: ``dSWA = SA_d = |LP(SWA,3.5) - LP(LP(SWA,3.5),0.5)|`` (the original applied
  this to the lateral *speed* by mistake), ``dAy = Ay_d`` likewise on ``A_y``;
  ``SWA_h = |LP(SWA,0.5)|``, ``Ay_h = |LP(Ay,0.5)|``, ``YR_h = |LP(AV_z,0.5)|``,
  ``Vx_f = |LP(V_x,3.5)|``.
* **Oversteer** (Mamdani, the original's rules): universes ``sa`` 0..50 deg step 5,
  ``la`` 0..0.5 g step 0.05, ``yr`` 0..45 deg/s step 5, output 0..10 step 1; triangles
  low/med/high as in the original (``sa`` (0,0,20) (5,25,45) (30,50,50); ``la`` (0,0,.2)
  (.05,.25,.45) (.3,.5,.5); ``yr`` (0,0,17.5) (4,22.5,41) (27.5,45,45); output (0,0,4)
  (1,5,9) (6,10,10)), each sampled on its universe grid and linearly interpolated like
  scikit-fuzzy's ``trimf`` + ``interp_membership``. Rules: ``sa low & la low -> low``,
  ``sa med & la med -> med``, ``sa high & la high -> high``, ``yr low/med/high ->
  low/med/high``; AND = min, implication = min, aggregation = max; defuzzification = the
  centroid of the piecewise-linear aggregate over the 11 output points (scikit-fuzzy's
  trapezoid-area ``centroid``; an empty aggregate gives 0). **Fix:** inputs are *clamped*
  into their universe (above the top = fully "high"), so a yaw rate above 45 deg/s no
  longer switches the yaw-rate rules off. The ``sa`` universe is read in
  **steering-wheel degrees** (the paper's unit for SWA) and is not rescaled: a band-passed
  steering-wheel correction of 25 deg is "medium", 50 deg "high". (Read as road-wheel
  degrees, 50 deg of band-passed road-wheel angle, ~750 deg at the wheel, is unreachable.)
  The universe tops are configurable (``os_sa_max_deg``, ``os_la_max_g``,
  ``os_yr_max_degs``); the triangles scale with them. A frame counts when ``OSI >= 4``,
  ``Vx_f > 5 km/h`` and ``dAy > 0.1 g``.
* **Understeer**: the steering-to-lateral-acceleration gain ``Ay_h / (SWA_h * Vx_h^2)``
  (``Vx_h = |LP(V_x,0.5)|``: path curvature per steering-wheel radian, 1/(m rad), constant in
  a turn driven with grip at any speed, so slowing down in a bend is not mistaken for
  understeer; ``us_gain="raw"`` gives the literal ``Ay_h/SWA_h`` in g/deg). Here ``A_y`` is
  ``vx * yaw_rate`` (``us_ay="centripetal"``, the default): the trace's measured ``ay`` also
  holds ``d(vy)/dt``, which at junction speeds doubles the apparent gain while the car turns
  in and shrinks it while it unwinds, although the car follows its steering exactly
  (``us_ay="measured"`` uses it anyway). The gain is *read* only where it means something:
  ``SWA_h >= 10 deg``, ``Vx_f > 5 km/h``, the car turns the way it is steered
  (``sign LP(A_y) = sign LP(SWA)``), and the steering is quasi-steady,
  ``|d SWA_h/dt| / SWA_h <= us_max_steer_rate`` (0.5 1/s): the lateral acceleration lags the
  steering, so during a ramp the ratio dips by ``lag * rate`` with no loss of grip.
  ``peak`` is the gain's maximum over the trailing ``us_peak_window_s`` (2 s, current frame
  included) *within the current turn* (the reference restarts when ``LP(SWA)`` changes sign),
  and ``FD = (peak - gain) / peak`` in [0, 1] is the fractional **drop** below that recent
  peak (0 where the gain is not read). **Fix:** the original's ``(gain - peak)/peak`` fired at
  the gain's local maxima instead. The fuzzy system keeps the original's rule
  ``FD high (0,1,1) -> us high (0,10,10)`` and adds its complement
  ``FD low (0,0,1) -> us low (0,0,10)``: with the single rule any FD > 0 gives
  USI ~ 5.25 >= 4 (a step at 0+, so numerical jitter would fire), with both rules USI rises
  monotonically from 3.33 (FD = 0) to 6.67 (FD = 1) and crosses 4 at FD ~ 0.29.
  A frame counts when ``USI >= 4``, ``Vx_f > 5 km/h`` and ``SWA_h > 10 deg``.
  (Without the three reading conditions and with the measured ``ay``, clean runs of the
  reference ADS counted 55-260 understeer frames each, about -150 per run: turn-in, unwinding
  and zero crossings of the steering, not slides. With them clean seeds count 0; see
  docs/quality.md.)
* **md**: exact minimum distance between the ego's rectangle (``meta['ego_length']``,
  ``meta['ego_width']``, defaults 4.6 m x 1.9 m) and each actor's rectangle over all frames
  (:func:`drivefuzz.geometry.rect_distance`), 0 on contact. The term is
  ``c_md / max(md, md_eps)`` with ``md_eps = 0.1 m``, so contact gives a finite
  ``10 * c_md``; without any actor ``md`` is ``None`` and the term 0.

Default weights and units of the score: every weight 1 and ``c_md = 1 m`` (the paper treats all
factors equally), so each counted frame costs 1 point and an actor 1 m away costs 1 point
(0.1 m or contact: 10 points, the ``md_eps`` floor). Counts are frames at the trace's step
(0.05 s): they are not normalised by duration, as in the paper. SI in the trace; the paper's
units (deg, km/h, deg/s, g) only inside :func:`signals` and the thresholds that use them.

Missing channels (all NaN) fall back: ``vx`` <- ``speed``; ``ax`` <- d(vx)/dt; ``yaw_rate``
<- d(heading)/dt; ``ay`` <- ``vx * yaw_rate``; ``steer_wheel_angle`` <- ``road_wheel_angle *
meta['steering_ratio']`` (15 if absent); ``vy`` <- 0. Isolated NaNs are interpolated.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from drivefuzz.geometry import rect_distance

__all__ = [
    "G",
    "EVENTS",
    "SIGNAL_KEYS",
    "QualityConfig",
    "QualityScore",
    "score_trace",
    "signals",
    "oversteer_index",
    "understeer_index",
    "min_distance",
]

#: Standard gravity [m/s^2].
G = 9.80665
_KMH = 3.6
_DEG = 180.0 / np.pi
_DEFAULT_EGO_LENGTH = 4.6
_DEFAULT_EGO_WIDTH = 1.9
_DEFAULT_STEERING_RATIO = 15.0

#: Counted events, in score order.
EVENTS: tuple[str, ...] = ("ha", "hb", "ht", "os", "us")


class QualityConfig(BaseModel):
    """Weights, thresholds and filter settings of the driving-quality score (defaults: the paper)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    # --- weights of eq:score
    w_ha: float = Field(1.0, ge=0, description="weight of #ha")
    w_hb: float = Field(1.0, ge=0, description="weight of #hb")
    w_ht: float = Field(1.0, ge=0, description="weight of #ht")
    w_os: float = Field(1.0, ge=0, description="weight of #os")
    w_us: float = Field(1.0, ge=0, description="weight of #us")
    c_md: float = Field(1.0, ge=0, description="coefficient c of the c/md term [m]")
    md_eps: float = Field(0.1, gt=0, description="[m] md is floored at this before dividing (contact -> c/eps)")

    g: float = Field(G, gt=0, description="[m/s^2] gravity for K_ab and A_y in g")
    # --- hard acceleration / braking / turn
    ha_g: float = Field(0.6, gt=0, description="#ha: K_ab = ax/g >= ha_g")
    hb_g: float = Field(0.6, gt=0, description="#hb: K_ab <= -hb_g")
    ht_swa_deg: float = Field(20.0, ge=0, description="#ht: |steering-wheel angle| >= this [deg]")
    ht_kt: float = Field(0.18, ge=0, description="#ht: K_t = |V_y| [km/h] / |SWA| [deg] >= this")

    # --- filters
    filter_order: int = Field(4, ge=1, le=12)
    light_hz: float = Field(3.5, gt=0, description="'light' low-pass cut-off [Hz]")
    heavy_hz: float = Field(0.5, gt=0, description="'heavy' low-pass cut-off [Hz]")

    # --- fuzzy detection
    os_threshold: float = Field(4.0, description="#os: OSI >= this (output universe 0..10)")
    us_threshold: float = Field(4.0, description="#us: USI >= this (output universe 0..10)")
    min_vx_kmh: float = Field(5.0, ge=0, description="#os/#us need LP(Vx, light) > this [km/h]")
    os_min_ay_d_g: float = Field(0.1, ge=0, description="#os needs dAy > this [g]")
    us_min_swa_h_deg: float = Field(10.0, ge=0, description="#us needs SWA_h > this [deg, steering wheel]")
    os_sa_max_deg: float = Field(50.0, gt=0, description="top of the oversteer sa universe [deg, steering wheel]")
    os_la_max_g: float = Field(0.5, gt=0, description="top of the oversteer la universe [g]")
    os_yr_max_degs: float = Field(45.0, gt=0, description="top of the oversteer yr universe [deg/s]")
    us_gain: Literal["speed_normalised", "raw"] = Field(
        "speed_normalised", description="understeer gain Ay_h/(SWA_h*Vx_h^2) or the literal Ay_h/SWA_h"
    )
    us_ay: Literal["centripetal", "measured"] = Field(
        "centripetal", description="understeer A_y: vx*yaw_rate (steady-state part) or the trace's measured ay"
    )
    us_max_steer_rate: float = Field(
        0.5, ge=0, description="[1/s] the gain is read only where |d SWA_h/dt| / SWA_h is at most this"
    )
    us_peak_window_s: float = Field(
        2.0, gt=0, description="[s] FD compares the gain with its max over this trailing window"
    )


@dataclass(frozen=True)
class QualityScore:
    """Every component of the score of one execution (stored with it, for the SQLite index)."""

    ha: int
    hb: int
    ht: int
    os: int
    us: int
    md: float | None  # [m] min body distance to any actor; None when there was no actor
    md_term: float  # c_md / max(md, md_eps); 0 without actors
    score: float
    frames: dict[str, list[int]] = field(default_factory=dict)  # event -> frame indices where it fired
    md_frame: int | None = None  # frame of the minimum distance
    md_actor: str | None = None  # actor id at the minimum distance
    n_frames: int = 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (plain ints/floats/None/lists)."""
        return {
            "ha": int(self.ha), "hb": int(self.hb), "ht": int(self.ht), "os": int(self.os), "us": int(self.us),
            "md": None if self.md is None else float(self.md),
            "md_term": float(self.md_term),
            "score": float(self.score),
            "frames": {k: [int(i) for i in v] for k, v in self.frames.items()},
            "md_frame": None if self.md_frame is None else int(self.md_frame),
            "md_actor": self.md_actor,
            "n_frames": int(self.n_frames),
        }


# ---------------------------------------------------------------------------- filters
@lru_cache(maxsize=64)
def _butter(order: int, cutoff: float, fs: float) -> np.ndarray | None:
    if not (fs > 0) or cutoff >= 0.5 * fs:
        return None  # at/above Nyquist: nothing to remove
    from scipy import signal  # imported when first needed: scipy.signal alone takes 0.4 s to import

    return signal.butter(order, cutoff, btype="low", fs=fs, output="sos")


def _lowpass(x: np.ndarray, cutoff: float, fs: float, order: int) -> np.ndarray:
    """Zero-phase Butterworth low-pass along the last axis; robust to short inputs."""
    sos = _butter(order, float(cutoff), float(fs))
    n = x.shape[-1]
    if sos is not None:
        sos = sos.copy()  # the cached design stays pristine (scipy wants a writable array)
    if sos is None or n < 2:
        return np.array(x, dtype=float, copy=True)
    # scipy's default padding, reduced for short traces (it needs n > padlen)
    default_pad = 3 * (2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))
    from scipy import signal

    return signal.sosfiltfilt(sos, x, axis=-1, padlen=min(default_pad, n - 1))


# ---------------------------------------------------------------------------- fuzzy logic
def _trimf(x: np.ndarray, a: float, b: float, c: float) -> np.ndarray:
    """scikit-fuzzy's ``trimf`` sampled on grid ``x``."""
    y = np.zeros_like(x)
    if a != b:
        i = (a < x) & (x < b)
        y[i] = (x[i] - a) / (b - a)
    if b != c:
        i = (b < x) & (x < c)
        y[i] = (c - x[i]) / (c - b)
    y[np.isclose(x, b, rtol=0, atol=1e-12 * max(1.0, abs(b)))] = 1.0
    return y


class _Var:
    """A fuzzy variable: a grid universe and its low/med/high triangles sampled on it."""

    def __init__(self, top: float, steps: int, tris: dict[str, tuple[float, float, float]]):
        self.grid = np.linspace(0.0, top, steps + 1)
        self.mf = {k: _trimf(self.grid, *(top * v for v in abc)) for k, abc in tris.items()}

    def member(self, value: np.ndarray, term: str) -> np.ndarray:
        # np.interp clamps outside the grid: below 0 -> value at 0, above the top -> value at the top.
        return np.interp(value, self.grid, self.mf[term])


_OUT = _Var(10.0, 10, {"low": (0, 0, 0.4), "med": (0.1, 0.5, 0.9), "high": (0.6, 1, 1)})
_US_OUT = _Var(10.0, 10, {"low": (0, 0, 1), "high": (0, 1, 1)})
_FD = _Var(1.0, 10, {"low": (0, 0, 1), "high": (0, 1, 1)})
# fractions of the universe top (original: sa 0..50, la 0..0.5, yr 0..45)
_SA_LA_TRIS = {"low": (0, 0, 0.4), "med": (0.1, 0.5, 0.9), "high": (0.6, 1, 1)}
_YR_TRIS = {"low": (0, 0, 17.5 / 45), "med": (4 / 45, 22.5 / 45, 41 / 45), "high": (27.5 / 45, 1, 1)}


@lru_cache(maxsize=16)
def _os_vars(sa_top: float, la_top: float, yr_top: float) -> tuple[_Var, _Var, _Var]:
    return _Var(sa_top, 10, _SA_LA_TRIS), _Var(la_top, 10, _SA_LA_TRIS), _Var(yr_top, 9, _YR_TRIS)


def _mamdani(out: _Var, strengths: dict[str, np.ndarray]) -> np.ndarray:
    """min-implication, max-aggregation, trapezoid-area centroid over ``out.grid``; per frame."""
    agg = None
    for term, s in strengths.items():
        clipped = np.minimum(np.asarray(s, dtype=float)[..., None], out.mf[term])
        agg = clipped if agg is None else np.maximum(agg, clipped)
    x = out.grid
    h = np.diff(x)
    y1, y2 = agg[..., :-1], agg[..., 1:]
    area = 0.5 * h * (y1 + y2)
    moment = area * x[:-1] + h * h * (y1 + 2.0 * y2) / 6.0
    return moment.sum(axis=-1) / np.maximum(area.sum(axis=-1), np.finfo(float).eps)


def oversteer_index(sa, la, yr, config: QualityConfig | None = None) -> np.ndarray:
    """OSI in [0, 10] from ``sa`` = dSWA [deg, steering wheel], ``la`` = dAy [g], ``yr`` = YR_h [deg/s].

    Inputs are taken as absolute values and clamped into their universes.
    """
    cfg = config or QualityConfig()
    vsa, vla, vyr = _os_vars(cfg.os_sa_max_deg, cfg.os_la_max_g, cfg.os_yr_max_degs)
    sa, la, yr = np.broadcast_arrays(*(np.abs(np.asarray(v, dtype=float)) for v in (sa, la, yr)))
    strengths = {
        t: np.maximum(np.minimum(vsa.member(sa, t), vla.member(la, t)), vyr.member(yr, t))
        for t in ("low", "med", "high")
    }
    return _mamdani(_OUT, strengths)


def understeer_index(fd) -> np.ndarray:
    """USI in [0, 10] from the fractional drop ``fd`` in [0, 1] (clamped) of the steering gain."""
    fd = np.asarray(fd, dtype=float)
    return _mamdani(_US_OUT, {"low": _FD.member(fd, "low"), "high": _FD.member(fd, "high")})


# ---------------------------------------------------------------------------- channels
def _fill(v: np.ndarray | None) -> np.ndarray | None:
    """Interpolate NaNs; None if nothing is finite."""
    if v is None:
        return None
    v = np.asarray(v, dtype=float)
    ok = np.isfinite(v)
    if ok.all():
        return v
    if not ok.any():
        return None
    idx = np.arange(len(v))
    return np.interp(idx, idx[ok], v[ok])


def _deriv(v: np.ndarray, dt: float) -> np.ndarray:
    return np.gradient(v, dt) if len(v) > 1 else np.zeros_like(v)


def _channels(trace) -> dict[str, np.ndarray]:
    """SI ego channels with fallbacks for missing ones (see the module docstring)."""
    n = trace.n_frames
    dt = trace.step_length
    ego = trace.ego
    get = lambda k: _fill(ego.get(k))  # noqa: E731
    zeros = np.zeros(n)
    vx = get("vx")
    if vx is None:
        vx = get("speed")
    vx = zeros if vx is None else vx
    ax = get("ax")
    if ax is None:
        ax = _deriv(vx, dt)
    yr = get("yaw_rate")
    if yr is None:
        hd = get("heading")
        yr = zeros if hd is None else _deriv(np.unwrap(hd), dt)
    ay = get("ay")
    if ay is None:
        ay = vx * yr
    swa = get("steer_wheel_angle")
    if swa is None:
        rwa = get("road_wheel_angle")
        ratio = float(trace.meta.get("steering_ratio") or _DEFAULT_STEERING_RATIO)
        swa = zeros if rwa is None else rwa * ratio
    vy = get("vy")
    vy = zeros if vy is None else vy
    return {"vx": vx, "vy": vy, "ax": ax, "ay": ay, "yaw_rate": yr, "swa": swa}


def _trailing_max(v: np.ndarray, w: int, segment: np.ndarray | None = None) -> np.ndarray:
    """max(v[i-w+1 .. i]) ignoring NaN (NaN if the whole window is NaN).

    With ``segment`` (an integer label per frame, non-decreasing) the window also stops at the
    first frame of frame i's segment.
    """
    n = len(v)
    if n == 0:
        return v.copy()
    w = max(1, min(int(w), n))
    vv = np.where(np.isnan(v), -np.inf, v)
    pad = np.concatenate([np.full(w - 1, -np.inf), vv])
    win = np.lib.stride_tricks.sliding_window_view(pad, w)  # row i: v[i-w+1 .. i]
    if segment is not None:
        seg = np.concatenate([np.full(w - 1, -1), np.asarray(segment)])
        same = np.lib.stride_tricks.sliding_window_view(seg, w) == np.asarray(segment)[:, None]
        win = np.where(same, win, -np.inf)
    m = win.max(axis=-1)
    return np.where(np.isneginf(m), np.nan, m)


#: Keys of :func:`signals` (arrays of one value per frame).
SIGNAL_KEYS: tuple[str, ...] = (
    "t", "Kab", "Vy", "Kt",
    "SWA", "Vx", "AVz", "Ay", "Vx_f", "dSWA", "dAy", "YR_h", "OSI",
    "SWA_h", "Ay_h", "gain", "peak", "FD", "USI",
    "ha_mask", "hb_mask", "ht_mask", "os_mask", "us_mask",
)


def signals(trace, config: QualityConfig | None = None) -> dict[str, np.ndarray]:
    """Intermediate signals of the score, one value per frame (units as in the paper's figures).

    ``t`` [s]; ``Kab`` = ax/g; ``Vy`` [km/h, |.|]; ``Kt`` [(km/h)/deg, NaN where SWA = 0];
    ``SWA`` [deg, signed steering-wheel angle]; ``Vx`` [km/h, signed]; ``AVz`` yaw rate
    [deg/s, signed]; ``Ay`` [g, signed]; ``Vx_f`` = |LP(Vx, light)| [km/h]; ``dSWA`` = SA_d
    [deg]; ``dAy`` = Ay_d [g]; ``YR_h`` [deg/s]; ``OSI`` oversteer index [0..10]; ``SWA_h``
    [deg]; ``Ay_h`` [g] (of the understeer A_y, see ``us_ay``); ``gain`` / ``peak``
    understeer gain and its trailing peak (units per ``config.us_gain``, NaN where the gain
    is not read); ``FD`` fractional drop [0..1]; ``USI``
    understeer index [0..10]; ``*_mask`` boolean detections for ha, hb, ht, os, us.
    """
    cfg = config or QualityConfig()
    n = trace.n_frames
    dt = trace.step_length
    fs = 1.0 / dt
    ch = _channels(trace)

    swa = ch["swa"] * _DEG
    vx = ch["vx"] * _KMH
    avz = ch["yaw_rate"] * _DEG
    ay = ch["ay"] / cfg.g
    kab = ch["ax"] / cfg.g

    # light low-pass of SWA, Ay, Vx; heavy low-pass of those light outputs and of SWA, Ay, AVz, Vx
    ay_us = ch["vx"] * ch["yaw_rate"] / cfg.g if cfg.us_ay == "centripetal" else ay
    light = _lowpass(np.stack([swa, ay, vx]), cfg.light_hz, fs, cfg.filter_order)
    heavy = _lowpass(np.vstack([light[:2], np.stack([swa, ay_us, avz, vx])]), cfg.heavy_hz, fs, cfg.filter_order)
    d_swa = np.abs(light[0] - heavy[0])
    d_ay = np.abs(light[1] - heavy[1])
    swa_h, ay_h, yr_h, vx_h = (np.abs(heavy[k]) for k in range(2, 6))
    swa_sign = np.sign(heavy[2])
    same_sign = swa_sign * np.sign(heavy[3]) > 0  # the car turns the way it is steered
    vx_f = np.abs(light[2])

    # hard acceleration / braking / turn
    ha = kab >= cfg.ha_g
    hb = kab <= -cfg.hb_g
    vy_kmh = np.abs(ch["vy"]) * _KMH
    aswa = np.abs(swa)
    with np.errstate(all="ignore"):
        kt = np.where(aswa > 0, vy_kmh / aswa, np.nan)
    ht = (aswa >= cfg.ht_swa_deg) & (kt >= cfg.ht_kt)

    # oversteer
    osi = oversteer_index(d_swa, d_ay, yr_h, cfg)
    moving = vx_f > cfg.min_vx_kmh
    os_mask = (osi >= cfg.os_threshold) & moving & (d_ay > cfg.os_min_ay_d_g)

    # understeer: fractional drop of the steering gain below its recent peak
    steer_rate = np.abs(_deriv(swa_h, dt)) / np.maximum(swa_h, 1e-9)
    valid = (swa_h >= cfg.us_min_swa_h_deg) & moving & (swa_h > 0)
    valid &= same_sign & (steer_rate <= cfg.us_max_steer_rate)
    with np.errstate(all="ignore"):
        if cfg.us_gain == "raw":
            gain = ay_h / swa_h
        else:  # curvature per steering-wheel radian [1/(m rad)]
            v_ms = np.maximum(vx_h / _KMH, 0.5)
            gain = (ay_h * cfg.g) / (np.radians(swa_h) * v_ms * v_ms)
    gain = np.where(valid & np.isfinite(gain), gain, np.nan)
    w = max(1, int(round(cfg.us_peak_window_s / dt)) + 1)
    # a new turn (the filtered steering changes sign) starts a new reference
    turn = np.concatenate([[0], np.cumsum(swa_sign[1:] != swa_sign[:-1])])
    peak = _trailing_max(gain, w, turn)
    with np.errstate(all="ignore"):
        fd = np.where(np.isfinite(gain) & (peak > 0), (peak - gain) / peak, 0.0)
    fd = np.clip(fd, 0.0, 1.0)
    usi = understeer_index(fd)
    us_mask = (usi >= cfg.us_threshold) & moving & (swa_h > cfg.us_min_swa_h_deg)

    t = _fill(trace.ego.get("t"))
    if t is None:
        t = (np.arange(n) + 1) * dt
    return {
        "t": t, "Kab": kab, "Vy": vy_kmh, "Kt": kt,
        "SWA": swa, "Vx": vx, "AVz": avz, "Ay": ay, "Vx_f": vx_f,
        "dSWA": d_swa, "dAy": d_ay, "YR_h": yr_h, "OSI": osi,
        "SWA_h": swa_h, "Ay_h": ay_h, "gain": gain, "peak": peak, "FD": fd, "USI": usi,
        "ha_mask": ha, "hb_mask": hb, "ht_mask": ht, "os_mask": os_mask, "us_mask": us_mask,
    }


# ---------------------------------------------------------------------------- minimum distance
def min_distance(trace) -> tuple[float | None, int | None, str | None]:
    """``(md [m], frame, actor id)`` of the smallest ego-to-actor body distance; Nones without actors.

    Exact oriented-rectangle distances are computed only for the (frame, actor) pairs whose
    circumscribed-circle lower bound does not exceed the best inscribed-circle upper bound.
    """
    a = trace.actors
    if len(a.frame) == 0 or trace.n_frames == 0:
        return None, None, None
    meta = trace.meta
    el = float(meta.get("ego_length") or _DEFAULT_EGO_LENGTH)
    ew = float(meta.get("ego_width") or _DEFAULT_EGO_WIDTH)
    f = a.frame
    ex, ey, eh = (np.asarray(trace.ego[k], dtype=float)[f] for k in ("x", "y", "heading"))
    al, aw = a.length[a.actor], a.width[a.actor]
    ok = np.isfinite(ex) & np.isfinite(ey) & np.isfinite(eh)
    ok &= np.isfinite(a.x) & np.isfinite(a.y) & np.isfinite(a.heading)
    if not ok.any():
        return None, None, None
    idx = np.flatnonzero(ok)
    dc = np.hypot(a.x[idx] - ex[idx], a.y[idx] - ey[idx])
    r_out = 0.5 * np.hypot(el, ew) + 0.5 * np.hypot(al[idx], aw[idx])
    r_in = 0.5 * min(el, ew) + 0.5 * np.minimum(al[idx], aw[idx])
    lower = np.maximum(dc - r_out, 0.0)
    upper = np.maximum(dc - r_in, 0.0)
    cand = idx[lower <= upper.min()]
    d = rect_distance(ex[cand], ey[cand], eh[cand], el, ew,
                      a.x[cand], a.y[cand], a.heading[cand], al[cand], aw[cand])
    k = int(np.argmin(d))
    row = cand[k]
    return float(d[k]), int(f[row]), a.ids[int(a.actor[row])]


# ---------------------------------------------------------------------------- score
def score_trace(trace, config: QualityConfig | None = None) -> QualityScore:
    """Score one execution's :class:`~drivefuzz.sim.trace.Trace` (higher = smoother, safer driving)."""
    cfg = config or QualityConfig()
    if trace.n_frames == 0:
        return QualityScore(0, 0, 0, 0, 0, None, 0.0, 0.0, {e: [] for e in EVENTS}, None, None, 0)
    sig = signals(trace, cfg)
    frames = {e: np.flatnonzero(sig[f"{e}_mask"]).tolist() for e in EVENTS}
    counts = {e: len(frames[e]) for e in EVENTS}
    md, md_frame, md_actor = min_distance(trace)
    md_term = 0.0 if md is None else cfg.c_md / max(md, cfg.md_eps)
    penalty = (cfg.w_ha * counts["ha"] + cfg.w_hb * counts["hb"] + cfg.w_ht * counts["ht"]
               + cfg.w_os * counts["os"] + cfg.w_us * counts["us"] + md_term)
    return QualityScore(
        ha=counts["ha"], hb=counts["hb"], ht=counts["ht"], os=counts["os"], us=counts["us"],
        md=md, md_term=float(md_term), score=-float(penalty) + 0.0,
        frames=frames, md_frame=md_frame, md_actor=md_actor, n_frames=trace.n_frames,
    )
