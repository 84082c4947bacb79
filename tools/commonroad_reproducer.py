"""Make a replayable finding folder for a planner bug from a scenario: docs/bugs' reproducers.

Runs SCENARIO (a scenario folder: a committed seed, a finding) with the ADS options given (for example the
CommonRoad adapter's fixes switched off, ``mode_fix=false``: the planner as shipped), the oracle settings
given (for example ``immobility.threshold=5``, so that a car that stops for good is reported within
seconds), and a time limit; it must end in a misbehaviour. The folder it writes holds what
``drivefuzz replay`` needs: the scenario with the options and its network (portable), the trace, a
verdict with the misbehaviour, the oracle settings and the first planning cycle that was not a plan
(from the trace's ``ads_info``), and replay.sh. ``drivefuzz replay FOLDER`` then checks the same oracle
fires at the same frame; tests/test_commonroad.py replays the kept folders.

    python tools/commonroad_reproducer.py SCENARIO OUT [--ads NAME] [--ads-option k=v ...]
        [--oracle NAME.KEY=VALUE ...] [--time-limit S] [--note TEXT]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _value(raw: str):
    try:
        return json.loads(raw)
    except json.JSONDecodeError:
        return raw


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("out")
    ap.add_argument("--ads", default="commonroad-reactive")
    ap.add_argument("--ads-option", action="append", default=[], metavar="K=V")
    ap.add_argument("--oracle", action="append", default=[], metavar="NAME.KEY=VALUE")
    ap.add_argument("--time-limit", type=float, default=None, help="[s] of simulated time")
    ap.add_argument("--note", default="", help="what the folder shows (kept in its verdict)")
    args = ap.parse_args(argv)

    from drivefuzz.ads import load_ads
    from drivefuzz.oracle import parse_oracle_options
    from drivefuzz.scenario.sumofiles import load_scenario, write_scenario
    from drivefuzz.sim.execute import execute
    from drivefuzz.storage import atomic_write_json, atomic_write_text
    from drivefuzz.triage.store import replay_script

    options = dict(kv.partition("=")[::2] for kv in args.ads_option)
    options = {k: _value(v) for k, v in options.items()}
    oracles = parse_oracle_options(args.oracle)
    sc = load_scenario(args.scenario)
    sim = sc.sim if args.time_limit is None else sc.sim.model_copy(update={"time_limit": args.time_limit})
    sc = sc.model_copy(update={"ads": sc.ads.model_copy(update={"name": args.ads, "options": options}), "sim": sim,
                               "name": Path(args.out).name})
    ex = execute(sc, ads=load_ads(args.ads, options), oracles=oracles.instantiate())
    if not ex.misbehaviors:
        print(f"no misbehaviour ({ex.termination.value}): nothing written")
        return 1
    m = ex.misbehaviors[0]
    cycles = ex.trace.meta.get("ads_info", {}).get("cycles", {})
    first = next(({"t": t, "outcome": o, "error": e} for t, o, e in zip(cycles.get("t", []), cycles.get("outcome", []),
                                                                        cycles.get("error", [])) if o != "plan"), None)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=False)
    write_scenario(sc, out, portable=True)
    ex.trace.save(out / "trace")
    atomic_write_json(out / "verdict.json", {
        "ads": {"name": args.ads, "options": options}, "misbehaviors": [mm.as_dict() for mm in ex.misbehaviors],
        "oracles": oracles.settings, "frames": ex.trace.n_frames, "exec_timeout_s": 600.0,
        "scenario_hash": sc.content_hash(), "first_cycle_without_plan": first, "note": args.note,
        "made_by": "tools/commonroad_reproducer.py " + " ".join(sys.argv[1:] if argv is None else argv)})
    atomic_write_text(out / "replay.sh", replay_script(args.ads))
    os.chmod(out / "replay.sh", 0o755)
    print(f"{out}: {m.oracle}/{m.kind} at frame {m.frame} (t={m.time:.2f} s); first cycle without a plan: {first}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
