"""Validate the understeer and oversteer detectors on real runs (the paper's appendix figures).

Two experiments, each run through :func:`drivefuzz.sim.execute.execute` with the reference ADS
together with a *dry twin* (the same scenario without the puddle):

* **understeer** (paper: f:usfig / f:usgraph): a low-friction puddle covers the junction where
  the ego turns left (intersection seed 003, west -> north). The front tyres saturate, the car
  runs wide with the steering at full lock.
* **oversteer** (paper: f:osfig / f:osgraph): a narrow strip of ice lies diagonally across
  the same left turn. The ego reaches it already yawing; the front axle crosses it first
  and regains grip while the rear axle is still on the ice, so the rear slides out.

For each run the script prints where the detections fall and where the car really slides,
judged from the physics, not from the detector: the slip angle of each axle against the
slip angle at which the magic-formula tyre reaches its peak force for the friction under that
axle (trace ``mu_front``/``mu_rear``). An axle whose slip angle is past that peak is
*sliding*. It prints PASS/FAIL lines:

* the detector fires at least once, and every detection lies inside a slip interval of the
  relevant axle (front for understeer, rear for oversteer), widened by ``--tolerance`` seconds
  (default 0.5 s, for the smear of the 0.5 Hz zero-phase filter);
* the detector stays silent on the dry twin.

It saves the figures (``understeer.png``, ``oversteer.png``) into ``--out`` (default
``eval_quality_out/``) and prints the cost of scoring a trace of about 1,200 frames against the
wall time of the execution that made it (goal: at most 5 %).

Usage::

    python tools/eval_quality.py [--out DIR] [--tolerance S]

Exit status 0 when every check passes, 1 otherwise. Needs the ``plots`` extra (matplotlib).
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from drivefuzz.sim.execute import Execution, execute  # noqa: E402
from drivefuzz.sim.physics import VehicleParams  # noqa: E402
from drivefuzz.search.quality import QualityConfig, score_trace, signals  # noqa: E402
from drivefuzz.scenario import Puddle, Scenario  # noqa: E402
from drivefuzz.scenario.sumofiles import load_scenario  # noqa: E402

BASE_SEED = REPO / "seeds" / "intersection" / "003"  # WC -> CN: a left turn at a signalised junction
TIMING_SEED = REPO / "seeds" / "town" / "000"  # ~1,200 frames of clean driving

#: Puddles of the two experiments (coordinates of networks/intersection.net.xml).
PUDDLES = {
    # 12 m x 12 m of ice over the junction's left-turn path
    "understeer": Puddle(x=-5.0, y=0.0, length=12.0, width=12.0, rotation=0.0, friction=0.1),
    # a 4.5 m wide strip laid diagonally (45 deg) across the turn path where the ego yaws at ~30 deg/s
    "oversteer": Puddle(x=-3.5, y=0.9, length=8.0, width=4.5, rotation=math.radians(135.0), friction=0.1),
}


def puddle_scenario(name: str) -> tuple[Scenario, Scenario]:
    """(wet, dry) scenarios of experiment ``name``."""
    base = load_scenario(BASE_SEED)
    dry = base.model_copy(update={"puddles": (), "name": f"{name}-dry"})
    wet = base.model_copy(update={"puddles": (PUDDLES[name],), "name": f"{name}-wet"})
    return wet, dry


# ---------------------------------------------------------------------------- physics ground truth
def axle_saturation(trace, params: VehicleParams | None = None) -> dict[str, np.ndarray]:
    """Per frame: slip angle of each axle [rad] and its ratio to the peak-force slip angle.

    Peak of ``sin(C atan(B a))`` is at ``B a = tan(pi / (2 C))`` with ``B = k / (C mu_eff)``
    (drivefuzz.sim.physics), so ``a_peak = tan(pi/(2C)) C mu grip / k``. Load transfer is ignored
    (a few per cent).
    """
    p = params or VehicleParams()
    vx = np.maximum(np.abs(trace["vx"]), 0.5)
    vy, r, delta = trace["vy"], trace["yaw_rate"], trace["road_wheel_angle"]
    lf, lr = p.cg_to_front, p.wheelbase - p.cg_to_front
    alpha_f = delta - np.arctan2(vy + lf * r, vx)
    alpha_r = -np.arctan2(vy - lr * r, vx)
    peak_f = math.tan(math.pi / (2 * p.tyre_shape_front)) * p.tyre_shape_front * p.lateral_grip_front \
        * trace["mu_front"] / p.tyre_stiffness_front
    peak_r = math.tan(math.pi / (2 * p.tyre_shape_rear)) * p.tyre_shape_rear * p.lateral_grip_rear \
        * trace["mu_rear"] / p.tyre_stiffness_rear
    moving = np.abs(trace["vx"]) > 1.0
    return {
        "alpha_f": alpha_f, "alpha_r": alpha_r,
        "sat_f": np.where(moving, np.abs(alpha_f) / peak_f, 0.0),
        "sat_r": np.where(moving, np.abs(alpha_r) / peak_r, 0.0),
    }


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive (first, last) frame of every run of True."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.flatnonzero(np.diff(m.astype(int)))
    return [(int(a), int(b) - 1) for a, b in zip(d[::2], d[1::2])]


def fmt_runs(mask) -> str:
    rs = runs(mask)
    return ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in rs) or "none"


# ---------------------------------------------------------------------------- figures
def _plot(name: str, wet: Execution, dry: Execution, cfg: QualityConfig, out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sw, sd = signals(wet.trace, cfg), signals(dry.trace, cfg)
    sat = axle_saturation(wet.trace)
    axle = "f" if name == "understeer" else "r"
    event = "us" if name == "understeer" else "os"
    if name == "understeer":
        panels = [("FD", "FD [-]", None), ("USI", "USI [0-10]", cfg.us_threshold),
                  ("SWA", "SWA [deg, steering wheel]", cfg.us_min_swa_h_deg), ("Vx", "V_x [km/h]", cfg.min_vx_kmh)]
    else:
        panels = [("dSWA", "dSWA [deg]", None), ("dAy", "dA_y [g]", cfg.os_min_ay_d_g),
                  ("AVz", "yaw rate [deg/s]", None), ("Vx", "V_x [km/h]", cfg.min_vx_kmh),
                  ("OSI", "OSI [0-10]", cfg.os_threshold)]
    n_wet = wet.trace.n_frames
    fw, fd = np.arange(n_wet), np.arange(dry.trace.n_frames)
    # show the part of the run around the puddle and the slip (the ego waits at a red light first)
    on = (wet.trace["mu_front"] < 0.99) | (wet.trace["mu_rear"] < 0.99) | (sat[f"sat_{axle}"] >= 1.0)
    idx = np.flatnonzero(on)
    lo, hi = (max(0, idx[0] - 80), min(n_wet, idx[-1] + 80)) if len(idx) else (0, n_wet)
    fig, axes = plt.subplots(len(panels) + 2, 1, sharex=True, figsize=(8, 1.55 * (len(panels) + 2)))
    det = np.flatnonzero(sw[f"{event}_mask"])
    slide = runs(sat[f"sat_{axle}"] >= 1.0)
    for ax, (key, label, thr) in zip(axes, panels):
        ax.plot(fd, sd[key], color="0.7", lw=1, label="dry twin")
        ax.plot(fw, sw[key], color="C0", lw=1.2, label="puddle")
        if thr is not None:
            ax.axhline(thr, color="C0", ls=":", lw=1)
            if key in ("SWA",):
                ax.axhline(-thr, color="C0", ls=":", lw=1)
        ax.set_ylabel(label, fontsize=8)
    ax = axes[len(panels)]
    ax.plot(fw, sat["sat_f"], color="C2", lw=1, label="front")
    ax.plot(fw, sat["sat_r"], color="C3", lw=1, label="rear")
    ax.plot(fw, wet.trace["mu_front"], color="C2", ls="--", lw=0.8, label="mu front")
    ax.plot(fw, wet.trace["mu_rear"], color="C3", ls="--", lw=0.8, label="mu rear")
    ax.axhline(1.0, color="k", ls=":", lw=0.8)
    ax.set_ylim(0, 3)
    ax.set_ylabel("|slip| / peak slip\n(physics), mu", fontsize=8)
    ax.legend(fontsize=6, loc="upper right", ncol=4)
    ax = axes[-1]
    ax.step(fw, sw[f"{event}_mask"].astype(int), where="mid", color="C1", lw=1.2, label="puddle")
    ax.step(fd, sd[f"{event}_mask"].astype(int) * 0.5, where="mid", color="0.5", lw=1, label="dry twin (x0.5)")
    ax.set_ylabel(f"{'understeer' if event == 'us' else 'oversteer'}\ndetected", fontsize=8)
    ax.set_yticks([0, 1])
    ax.legend(fontsize=6, loc="upper right")
    for a in axes:
        for s0, s1 in slide:
            a.axvspan(s0, s1, color="C3" if axle == "r" else "C2", alpha=0.12, lw=0)
        for k in det:
            a.axvline(k, color="C1", ls="--", lw=0.5, alpha=0.6)
    axes[0].legend(fontsize=6, loc="upper right")
    axes[-1].set_xlim(lo, hi)
    axes[-1].set_xlabel("frame (0.05 s)")
    axle_name = "front" if axle == "f" else "rear"
    fig.suptitle(f"{name}: signals over frames; shaded = {axle_name} axle sliding (physics), "
                 f"dashed = detections", fontsize=9)
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{name}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------- experiments
@dataclass
class Check:
    name: str
    ok: bool
    detail: str

    def line(self) -> str:
        return f"{'PASS' if self.ok else 'FAIL'}  {self.name}: {self.detail}"


def run_experiment(name: str, cfg: QualityConfig, tolerance_s: float, out: Path) -> list[Check]:
    wet_sc, dry_sc = puddle_scenario(name)
    wet, dry = execute(wet_sc), execute(dry_sc)
    event, axle = ("us", "f") if name == "understeer" else ("os", "r")
    other = "os" if event == "us" else "us"
    qw, qd = score_trace(wet.trace, cfg), score_trace(dry.trace, cfg)
    sw = signals(wet.trace, cfg)
    sat = axle_saturation(wet.trace)
    sat_d = axle_saturation(dry.trace)
    tr = wet.trace
    dt = tr.step_length
    print(f"\n=== {name}: puddle {PUDDLES[name].model_dump()}")
    print(f"  wet run: {tr.n_frames} frames, {wet.termination.value}, wall {wet.wall_time:.2f} s; "
          f"dry twin: {dry.trace.n_frames} frames, {dry.termination.value}")
    print(f"  front axle on the puddle: frames {fmt_runs(tr['mu_front'] < 0.99)}")
    print(f"  rear axle on the puddle:  frames {fmt_runs(tr['mu_rear'] < 0.99)}")
    print(f"  front axle sliding (|slip| > peak slip): frames {fmt_runs(sat['sat_f'] >= 1.0)}")
    print(f"  rear axle sliding  (|slip| > peak slip): frames {fmt_runs(sat['sat_r'] >= 1.0)}")
    print(f"  dry twin sliding: front {fmt_runs(sat_d['sat_f'] >= 1.0)}, rear {fmt_runs(sat_d['sat_r'] >= 1.0)}")
    ay_g = np.abs(tr["ay"]) / cfg.g
    print(f"  max |A_y| on the puddle: {ay_g[(tr['mu_front'] < 0.99) | (tr['mu_rear'] < 0.99)].max():.2f} g "
          f"(mu g = {PUDDLES[name].friction:.2f} g); max yaw rate {np.degrees(np.abs(tr['yaw_rate'])).max():.0f} deg/s "
          f"(dry twin {np.degrees(np.abs(dry.trace['yaw_rate'])).max():.0f} deg/s)")
    for e in ("us", "os"):
        print(f"  {e} detections, puddle:   frames {fmt_runs(sw[f'{e}_mask'])}  (#{e} = {getattr(qw, e)})")
        print(f"  {e} detections, dry twin: #{e} = {getattr(qd, e)}"
              + (f" at frames {qd.frames[e]}" if getattr(qd, e) else ""))
    print(f"  score: puddle {qw.score:.2f} {_terms(qw)}; dry twin {qd.score:.2f} {_terms(qd)}")

    det = np.asarray(qw.frames[event], dtype=int)
    sliding = sat[f"sat_{axle}"] >= 1.0  # the axle that defines the event
    any_sliding = (sat["sat_f"] >= 1.0) | (sat["sat_r"] >= 1.0)
    tol = int(round(tolerance_s / dt))
    near = np.zeros_like(any_sliding)
    for a, b in runs(any_sliding):
        near[max(0, a - tol): b + tol + 1] = True
    inside = near[det] if len(det) else np.array([], bool)
    during = sliding[det] if len(det) else np.array([], bool)
    axle_name = "front" if axle == "f" else "rear"
    checks = [
        Check(f"{name}: detector fires in the puddle run", len(det) > 0, f"#{event} = {len(det)}"),
        Check(f"{name}: it fires while the {axle_name} axle slides", bool(during.any()),
              f"{int(during.sum())}/{len(det)} detections during the {axle_name}-axle slip {fmt_runs(sliding)}"),
        Check(f"{name}: every detection inside the slip (any axle sliding, +-{tolerance_s:g} s)",
              len(det) > 0 and bool(inside.all()),
              f"{int(inside.sum())}/{len(det)} inside; sliding frames {fmt_runs(any_sliding)}; "
              f"detections {fmt_runs(sw[f'{event}_mask'])}"),
        Check(f"{name}: silent on the dry twin", getattr(qd, event) == 0, f"#{event} = {getattr(qd, event)}"),
        Check(f"{name}: the other detector ({other}) silent on the dry twin", getattr(qd, other) == 0,
              f"#{other} = {getattr(qd, other)}"),
        Check(f"{name}: puddle run scores lower than its dry twin", qw.score < qd.score,
              f"{qw.score:.2f} < {qd.score:.2f}"),
    ]
    png = _plot(name, wet, dry, cfg, out)
    print(f"  figure: {png}")
    return checks


def _terms(q) -> str:
    return f"(ha {q.ha}, hb {q.hb}, ht {q.ht}, os {q.os}, us {q.us}, c/md {q.md_term:.2f})"


def timing(cfg: QualityConfig, repeats: int = 50) -> Check:
    ex = execute(load_scenario(TIMING_SEED))
    tr = ex.trace
    score_trace(tr, cfg)  # warm the filter-design cache
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        score_trace(tr, cfg)
        ts.append(time.perf_counter() - t0)
    med = statistics.median(ts)
    share = med / ex.wall_time
    print(f"\n=== timing: {TIMING_SEED.relative_to(REPO)} ({tr.n_frames} frames)")
    print(f"  execution wall time: {ex.wall_time * 1e3:.1f} ms")
    print(f"  score_trace: median {med * 1e3:.2f} ms, min {min(ts) * 1e3:.2f} ms over {repeats} runs "
          f"= {100 * share:.2f} % of the execution")
    return Check("scoring costs at most 5 % of the execution", share <= 0.05, f"{100 * share:.2f} %")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("eval_quality_out"), help="folder for the PNGs")
    ap.add_argument("--tolerance", type=float, default=0.5, help="[s] slack around a slip interval")
    args = ap.parse_args(argv)
    cfg = QualityConfig()
    checks: list[Check] = []
    for name in ("understeer", "oversteer"):
        checks += run_experiment(name, cfg, args.tolerance, args.out)
    checks.append(timing(cfg))
    print()
    for c in checks:
        print(c.line())
    return 0 if all(c.ok for c in checks) else 1


if __name__ == "__main__":
    sys.exit(main())
