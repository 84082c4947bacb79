"""Triage campaign findings again with one version of the code, and compare what two versions decided.

For a change to the triage that must not change what it decides (the verdict, attribution, signature,
reproduction rate, shrink and minimal reproducer), only how much it runs::

    python tools/retriage.py --code /tmp/wt-old --dump old.json CAMPAIGN [CAMPAIGN ...]
    python tools/retriage.py --dump new.json CAMPAIGN [CAMPAIGN ...]
    python tools/retriage.py --compare old.json new.json

``--dump``: every folder under ``CAMPAIGN/findings/`` and ``CAMPAIGN/incidents/`` with a trace (not a simulator
crash) is filed again by a fresh :class:`drivefuzz.triage.store.FindingStore` (into a temporary campaign folder),
in this process, with the campaign's oracle settings and its reproduction and shrink budgets, from the folder's
scenario, trace and misbehaviours, as the fuzz loop filed it. The new verdict.json, minimal/verdict.json,
minimal/scenario.json, the runs made and the frames they simulated go to the JSON file. ``--code DIR`` imports
drivefuzz (and ego/, oracles/) from DIR, a git worktree of another commit, instead of this checkout.

``--compare``: per folder, whether the two dumps decided the same (ignoring the drivefuzz version and the
shrink's ``reused`` and ``runs``, which count work, not decisions), and the runs and frames of each. Prints only;
an evaluation script, not a test.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
WORK_KEYS = ("reused", "runs")  # keys of the shrink record that count work


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("campaigns", type=Path, nargs="*", help="campaign output folders (with --dump)")
    ap.add_argument("--dump", type=Path, help="triage the campaigns' folders again; write what was decided here")
    ap.add_argument("--code", type=Path, help="import drivefuzz from this checkout (default: this one)")
    ap.add_argument("--compare", type=Path, nargs=2, metavar=("A", "B"), help="compare two dumps")
    ap.add_argument("--shrink", type=int, default=10, help="the campaigns' shrink budget (fuzz --shrink) [10]")
    args = ap.parse_args(argv)
    if args.compare:
        return compare(*args.compare)
    if not args.dump or not args.campaigns:
        ap.error("give --dump OUT.json and campaign folders, or --compare A B")
    sys.path.insert(0, str(args.code.resolve() if args.code else REPO))
    dump(args.dump, args.campaigns, args.shrink)
    return 0


def dump(out_json: Path, campaigns: list[Path], shrink_budget: int) -> None:
    from drivefuzz.oracle import Misbehavior, OracleSettings
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.sumofiles import load_scenario
    from drivefuzz.sim.execute import execute
    from drivefuzz.sim.trace import Trace
    from drivefuzz.triage.store import FindingStore, TriageConfig

    import drivefuzz

    print(f"drivefuzz from {Path(drivefuzz.__file__).parent}", file=sys.stderr)
    res = {}
    for camp in campaigns:
        folders = sorted(p for k in ("findings", "incidents") for p in (camp / k).glob("*") if (p / "trace").is_dir())
        for d in folders:
            old = json.loads((d / "verdict.json").read_text())
            settings = OracleSettings(settings=old.get("oracles") or {})
            work = [0, 0]  # runs, frames

            def run(sc, settings=settings, work=work):
                ex = execute(sc, oracles=settings.instantiate())
                work[0] += 1
                work[1] += ex.trace.n_frames
                return tuple(ex.misbehaviors), ex.trace

            sc, trace = load_scenario(d), Trace.load(d / "trace")
            mbs = [Misbehavior.from_dict(x) for x in old["misbehaviors"]]
            # as the campaign triaged it: its reproduction reruns, and the shrink budget if it shrank this one
            cfg = TriageConfig(reproduce=(old.get("reproduction") or {}).get("runs", 0),
                               shrink=shrink_budget if old.get("shrink") else 0)
            tmp = Path(tempfile.mkdtemp(prefix="retriage-"))
            t0 = time.perf_counter()
            got = FindingStore(tmp, load_roadmap(sc.network_path()), run, cfg).triage(
                sc, mbs, trace, old["key"], old["termination"])
            folder = tmp / got.rel
            rec = {"verdict": _read(folder / "verdict.json"), "runs": work[0], "frames": work[1],
                   "s": round(time.perf_counter() - t0, 3)}
            if (folder / "minimal").is_dir():
                rec["minimal_verdict"] = _read(folder / "minimal" / "verdict.json")
                rec["minimal_scenario"] = _read(folder / "minimal" / "scenario.json")
                rec["minimal_frames"] = Trace.load(folder / "minimal" / "trace").n_frames
            res[f"{camp.name}/{d.name}"] = rec
            print(f"{camp.name}/{d.name}: {work[0]} runs, {work[1]} frames, {rec['s']:.2f} s", flush=True)
    out_json.write_text(json.dumps(res, indent=1, sort_keys=True, default=str))


def _read(path: Path):
    return json.loads(path.read_text())


def _decided(rec: dict, part: str):
    """What a dump's ``part`` decided: without the drivefuzz version and the shrink's work counts."""
    v = json.loads(json.dumps(rec.get(part) or {}))
    v.pop("drivefuzz", None)
    if isinstance(v.get("shrink"), dict):
        for k in WORK_KEYS:
            v["shrink"].pop(k, None)
    return v


def compare(a_path: Path, b_path: Path) -> int:
    a, b = _read(a_path), _read(b_path)
    differ, work = 0, [0, 0, 0, 0]
    for key in sorted(set(a) | set(b)):
        x, y = a.get(key), b.get(key)
        if x is None or y is None:
            print(f"{key}: only in {'B' if x is None else 'A'}")
            differ += 1
            continue
        parts = [p for p in ("verdict", "minimal_verdict", "minimal_scenario")
                 if _decided(x, p) != _decided(y, p)]
        if x.get("minimal_frames") != y.get("minimal_frames"):
            parts.append("minimal_frames")
        differ += bool(parts)
        work = [work[0] + x["runs"], work[1] + y["runs"], work[2] + x["frames"], work[3] + y["frames"]]
        print(f"{key:<52} {'same' if not parts else 'DIFFERENT: ' + ', '.join(parts)}  runs {x['runs']} -> "
              f"{y['runs']}, frames {x['frames']:,} -> {y['frames']:,}, {x['s']:.2f} -> {y['s']:.2f} s")
        for p in parts[:3]:
            dx, dy = _decided(x, p), _decided(y, p)
            if isinstance(dx, dict) and isinstance(dy, dict):
                for k in sorted(set(dx) | set(dy)):
                    if dx.get(k) != dy.get(k):
                        print(f"    {p}.{k}:\n      A {json.dumps(dx.get(k))[:300]}\n      B {json.dumps(dy.get(k))[:300]}")
    print(f"{len(set(a) | set(b))} folders, {differ} decided differently; runs {work[0]} -> {work[1]}, "
          f"frames {work[2]:,} -> {work[3]:,}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
