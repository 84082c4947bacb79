"""Does the maneuver strategy reach AV-Fuzzer's five crash types, and fairly?

Runs one ``maneuver`` campaign per ADS on the highway's committed seeds (``FuzzConfig(max_execs=N,
strategy="maneuver", seed=SEED)``, everything else as ``drivefuzz fuzz`` has it; by default the clean
reference ADS, ``sumo`` and the reference ADS with its ``late_braking`` fault), then, for every execution whose collision oracle fired, replays the
scenario the campaign kept for it (``corpus/<hash>``, named in its journal record) and classifies the
contact from the trace (:func:`drivefuzz.triage.crashtype.crash_type`: who changed lanes, where the
other vehicle was before). It prints, per ADS and per crash type:

- the collisions (executions) and the distinct signatures they were filed under;
- how many of them were the ego's fault (the campaign's attribution: rules and the careful driver's
  counterfactual replay);
- the reproduction of their signatures' folders (``reproduced k/N`` under small perturbations; findings only:
  incidents are not re-run unless a campaign counts them as findings, ``--report-all``);

then how many of the campaign's finding folders ``drivefuzz replay`` reproduces (same oracle, same frame),
and the crash types that never occurred.

Usage::

    python tools/eval_maneuver.py [--execs 1000] [--seed 0] [--ads ego,sumo,ego:fault=late_braking] [--jobs 2]
                                  [--keep DIR]
    python tools/eval_maneuver.py --report DIR/ego DIR/sumo

Prints only; an evaluation, not a test.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from collections import Counter, defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from campaigns import end_records, run_campaign  # noqa: E402  (tools/, beside this script)

NETWORK = REPO / "networks" / "highway.net.xml"
#: The clean reference ADS, SUMO's own driver, and the reference ADS with a known bug (it sees obstacles only
#: within 4 m): the crash types an ADS shows depend on its bugs, and a buggy one shows what the strategy can reach
DEFAULT_ADS = ("ego", "sumo", "ego:fault=late_braking")
from drivefuzz.triage.crashtype import LABELS  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--execs", type=int, default=1000, help="executions per campaign [1000]")
    ap.add_argument("--seed", type=int, default=0, help="campaign RNG seed [0]")
    ap.add_argument("--ads", default=",".join(DEFAULT_ADS), help="comma-separated ADS plugins, one campaign "
                    f"each, with options as NAME:KEY=VALUE [{','.join(DEFAULT_ADS)}]")
    ap.add_argument("--jobs", type=int, default=2, help="seed jobs at once on a local Dask cluster [2]")
    ap.add_argument("--keep", type=Path, help="keep the campaign directories here (DIR/<ads>)")
    ap.add_argument("--report", type=Path, nargs="+", help="only classify and print these campaign directories")
    args = ap.parse_args(argv)

    if args.report:
        for out in args.report:
            report(out, wall_s=None)
        return 0
    tmp = None
    base = args.keep
    if base is None:
        tmp = tempfile.mkdtemp(prefix="eval-maneuver-")
        base = Path(tmp)
    try:
        for name in [s.strip() for s in args.ads.split(",") if s.strip()]:
            out = base / name.replace(":", "-").replace("=", "-")
            if out.exists() and any(out.iterdir()):
                sys.exit(f"{out} exists and is not empty: give another --keep, or remove it")
            wall = run_ads(out, name, args)
            report(out, wall_s=wall)
    finally:
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


def run_ads(out: Path, ads: str, args) -> float:
    """Run the maneuver campaign of one ADS (NAME or NAME:KEY=VALUE) into ``out``; return its wall time [s]."""
    from drivefuzz.campaign.fuzz import FuzzConfig
    from drivefuzz.scenario import AdsSpec
    from drivefuzz.scenario.seed import list_seeds
    from drivefuzz.scenario.sumofiles import load_scenario

    seeds = [load_scenario(p) for p in list_seeds(REPO / "seeds" / "highway")]
    seeds = [s.model_copy(update={"network": str(NETWORK)}) for s in seeds]
    name, _, option = ads.partition(":")
    options = dict([option.split("=", 1)]) if option else {}
    cfg = FuzzConfig(max_execs=args.execs, strategy="maneuver", seed=args.seed, ads=AdsSpec(name=name, options=options))
    argv = ["tools/eval_maneuver.py", "--execs", str(args.execs), "--seed", str(args.seed), "--ads", ads]
    print(f"running: maneuver, ADS {ads}, {args.execs} executions, {len(seeds)} highway seeds, seed {args.seed}, "
          f"{args.jobs} job(s) -> {out}", file=sys.stderr, flush=True)
    return run_campaign(out, seeds, cfg, argv, args.jobs)


def classify(out: Path, rec: dict, ads: dict) -> tuple[str, str]:
    """(crash type, note) of one collision record: its kept scenario replayed, the contact classified."""
    from drivefuzz.oracle import OracleSettings
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.sumofiles import load_scenario
    from drivefuzz.sim.execute import execute
    from drivefuzz.triage.crashtype import crash_type

    sc = load_scenario(out / rec["scenario"])
    manifest = json.loads((out / "manifest.json").read_text())
    oracles = OracleSettings.model_validate(manifest.get("config", {}).get("oracles", {})).instantiate()
    ex = execute(sc.model_copy(update={"ads": sc.ads.model_copy(update=ads)}), oracles=oracles)
    hits = [m for m in ex.misbehaviors if m.oracle == "collision"]
    if not hits:
        return "other", "replay: no collision"
    m = hits[0]
    other = m.actors[0] if m.actors else ""
    return crash_type(ex.trace, m.frame, other, load_roadmap(sc.network_path())), ""


def report(out: Path, wall_s: float | None) -> None:
    manifest = json.loads((out / "manifest.json").read_text())
    ads = (manifest.get("config") or {}).get("ads") or {"name": "ego", "options": {}}
    recs = end_records(out)
    collisions = [r for r in recs if str(r.get("verdict", "")).startswith("collision")]
    who = ads["name"] + "".join(f" {k}={v}" for k, v in (ads.get("options") or {}).items())
    print(f"\n== {out}  ADS {who}: {len(recs)} executions"
          + (f" in {wall_s:.0f} s" if wall_s else "") + f", {len(collisions)} collisions")
    by_type: dict[str, list[dict]] = defaultdict(list)
    notes = Counter()
    for r in collisions:
        if "scenario" not in r:
            notes["no kept scenario (a campaign from before the scenario was kept)"] += 1
            continue
        kind, note = classify(out, r, ads)
        if note:
            notes[note] += 1
        by_type[kind].append(r)
    print(f"{'crash type':38} {'collisions':>10} {'signatures':>10} {'ego fault':>10}   reproduction of their folders")
    for kind, label in LABELS.items():
        rows = by_type.get(kind, [])
        folders = {r.get("finding") or r.get("incident") for r in rows}
        ego = sum(1 for r in rows if r.get("fault") in ("ego", "unclear"))
        share = f"{ego}/{len(rows)}" if rows else "-"
        print(f"{label:38} {len(rows):>10} {len(folders):>10} {share:>10}   {_reproduction(out, folders)}")
    missing = [LABELS[k] for k in LABELS if k != "other" and not by_type.get(k)]
    print("types not seen: " + (", ".join(missing) if missing else "none (all five occurred)"))
    for note, n in notes.items():
        print(f"  note: {n} x {note}")
    _replays(out)


def _reproduction(out: Path, folders: set) -> str:
    rates = []
    for rel in sorted(f for f in folders if f):
        v = json.loads((out / rel / "verdict.json").read_text())
        rep = v.get("reproduction") or {}
        if rep.get("runs"):
            rates.append((rep["reproduced"], rep["runs"]))
    if not rates:
        return "-"
    k, n = sum(r[0] for r in rates), sum(r[1] for r in rates)
    robust = sum(1 for r in rates if r[0] >= 0.8 * r[1])
    return f"{k}/{n} reruns ({100 * k / n:.0f} %), {robust}/{len(rates)} folders robust (>= 80 %)"


def _replays(out: Path) -> None:
    """``drivefuzz replay`` every finding folder (the user's command): how many reproduce."""
    folders = sorted(p for p in (out / "findings").glob("*") if (p / "verdict.json").exists())
    ok = 0
    for p in folders:
        done = subprocess.run([sys.executable, "-m", "drivefuzz.cli", "replay", str(p)], capture_output=True,
                              text=True)
        ok += done.returncode == 0
        if done.returncode != 0:
            print(f"  NOT reproduced: {p.name}: {done.stdout.strip() or done.stderr.strip()}")
    print(f"drivefuzz replay: {ok}/{len(folders)} finding folders reproduced (same oracle, same frame)")


if __name__ == "__main__":
    raise SystemExit(main())
