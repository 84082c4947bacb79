"""Does drivefuzz run on every network SUMO loads? A sweep of real networks, as a new user would try them.

    python tools/eval_networks.py [NET ...] [--no-wheel] [--seeds 2] [--execs 30] [--timeout 600]

For every ``.net.xml`` / ``.net.xml.gz`` under ``$SUMO_HOME`` (the networks that SUMO's own wheel ships), and every
network given on the command line, in child processes as a user would type them:

1. ``drivefuzz seed NET -n 2 -o DIR``: the outcome, wall time and peak memory (RSS);
2. where seeds came out, ``drivefuzz fuzz NET --seeds DIR --max-execs 30 -o OUT``: the same figures.

A network passes when both end as promised: exit 0 or 1 (clean or findings), or a refusal in exactly one line on
stderr with exit 2 for a network that has no road a passenger car may use. Anything else (a traceback, exit 3, a
signal, more than one line with exit 2, a refusal of a network that has car roads) is a failure, printed in a line
of its own. The exit code is the number of failures (capped at 100), so the tool can gate a CI job.

A network "has car roads" when a normal edge has a lane that allows passenger cars: read from the XML, the way SUMO
reads it (gzip included), independently of drivefuzz's road map.
"""

from __future__ import annotations

import argparse
import gzip
import os
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

#: exit codes drivefuzz promises (drivefuzz.cli): 0 clean, 1 findings, 2 input error
PROMISED = (0, 1)


@dataclass
class Step:
    """One child process: what it was, how it ended, what it cost."""

    rc: int
    wall_s: float
    peak_mb: float
    stderr: str

    def lines(self) -> list[str]:
        return [ln for ln in self.stderr.splitlines() if ln.strip()]

    def brief(self) -> str:
        return f"rc={self.rc} {self.wall_s:6.1f}s {self.peak_mb:6.0f}MB"


@dataclass
class Outcome:
    net: Path
    car_roads: bool
    seed: Step | None = None
    fuzz: Step | None = None
    failures: list[str] = field(default_factory=list)


def _open(path: Path):
    with open(path, "rb") as f:
        magic = f.read(2)
    return gzip.open(path, "rb") if magic == b"\x1f\x8b" else open(path, "rb")


def has_car_roads(path: Path) -> bool:
    """Whether a normal edge has a lane that a passenger car may use (SUMO's defaults: all classes allowed)."""
    with _open(path) as src:
        in_normal_edge = False
        for event, el in ET.iterparse(src, events=("start", "end")):
            if event == "start":
                if el.tag == "edge":
                    in_normal_edge = el.get("function") in (None, "normal")
                continue
            if el.tag == "lane" and in_normal_edge and _lane_allows_passenger(el):
                return True
            if el.tag in ("edge", "junction", "connection"):
                el.clear()
    return False


def _lane_allows_passenger(el: ET.Element) -> bool:
    allow, disallow = el.get("allow"), el.get("disallow")
    if allow is not None:
        classes = allow.split()
        return "all" in classes or "passenger" in classes
    if disallow is not None:
        classes = disallow.split()
        return "all" not in classes and "passenger" not in classes
    return True


def run_child(cmd: list[str], timeout_s: float) -> Step:
    """Run ``cmd``; its own peak RSS from wait4 (not the children's maximum over the whole sweep)."""
    t0 = time.perf_counter()
    err = tempfile.TemporaryFile()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, stdin=subprocess.DEVNULL)
    deadline = t0 + timeout_s
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        if time.perf_counter() > deadline:
            proc.kill()
            pid, status, usage = os.wait4(proc.pid, 0)
            break
        time.sleep(0.05)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    err.seek(0)
    text = err.read().decode("utf-8", "replace")
    if wall > timeout_s:
        text += f"\n(killed after {timeout_s:.0f} s)"
    return Step(proc.returncode, wall, usage.ru_maxrss / 1024.0, text)


def judge(step: Step, what: str, car_roads: bool) -> list[str]:
    """The broken promises of one step, each a line for the user to read."""
    lines = step.lines()
    if "Traceback (most recent call last)" in step.stderr:
        last = lines[-1] if lines else ""
        return [f"{what}: traceback ({last[:160]})"]
    if step.rc in PROMISED:
        return []
    if step.rc == 2:
        out = []
        if len(lines) != 1:
            out.append(f"{what}: exit 2 with {len(lines)} lines on stderr (one is promised)")
        if car_roads:
            out.append(f"{what}: refused a network with car roads: {lines[-1][:200] if lines else ''}")
        return out
    return [f"{what}: exit {step.rc}: {lines[-1][:200] if lines else '(no message)'}"]


def evaluate(net: Path, work: Path, n_seeds: int, execs: int, timeout_s: float) -> Outcome:
    exe = [sys.executable, "-m", "drivefuzz.cli"]
    out = Outcome(net, has_car_roads(net))
    seeds = work / "seeds"
    out.seed = run_child(exe + ["seed", str(net), "-n", str(n_seeds), "-o", str(seeds)], timeout_s)
    out.failures += judge(out.seed, "seed", out.car_roads)
    if out.seed.rc == 2 and not out.car_roads and len(out.seed.lines()) == 1:
        return out  # refused as promised: nothing to fuzz
    if out.seed.rc not in PROMISED:
        return out
    out.fuzz = run_child(exe + ["fuzz", str(net), "--seeds", str(seeds), "--max-execs", str(execs),
                                "--seed", "1", "-o", str(work / "out")], timeout_s)
    out.failures += judge(out.fuzz, "fuzz", out.car_roads)
    return out


def wheel_networks() -> list[Path]:
    home = os.environ.get("SUMO_HOME")
    if not home:
        import sumo

        home = sumo.SUMO_HOME
    return sorted(p for p in Path(home).rglob("*") if p.name.endswith((".net.xml", ".net.xml.gz")))


def _label(net: Path) -> str:
    parts = net.parts
    return "/".join(parts[-3:]) if len(parts) >= 3 else str(net)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("nets", nargs="*", type=Path, help="more networks to try")
    ap.add_argument("--no-wheel", action="store_true", help="only the networks given, not SUMO's own")
    ap.add_argument("--seeds", type=int, default=2, help="seeds per network [2]")
    ap.add_argument("--execs", type=int, default=30, help="executions of the fuzz campaign [30]")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per child process [600]")
    args = ap.parse_args(argv)
    nets = ([] if args.no_wheel else wheel_networks()) + [p.resolve() for p in args.nets]
    failures = 0
    print(f"{'network':58s} {'cars':4s} {'seed':24s} {'fuzz':24s} verdict")
    for net in nets:
        work = Path(tempfile.mkdtemp(prefix="eval-net-"))
        try:
            o = evaluate(net, work, args.seeds, args.execs, args.timeout)
        finally:
            shutil.rmtree(work, ignore_errors=True)
        verdict = "FAIL" if o.failures else ("refused" if o.fuzz is None else "ok")
        print(f"{_label(net):58s} {'yes' if o.car_roads else 'no':4s} {o.seed.brief():24s} "
              f"{o.fuzz.brief() if o.fuzz else '-':24s} {verdict}", flush=True)
        if o.fuzz is None and o.seed.lines():
            print(f"    refused: {o.seed.lines()[-1][:200]}")
        for f in o.failures:
            print(f"    FAILURE {f}")
        failures += bool(o.failures)
    print(f"{len(nets)} networks, {failures} failing")
    return min(failures, 100)


if __name__ == "__main__":
    sys.exit(main())
