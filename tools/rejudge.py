"""Re-judge the findings and incidents of campaign folders with the current attribution rules.

For every folder under ``CAMPAIGN/findings/`` and ``CAMPAIGN/incidents/`` with a trace (not a simulator crash):
the stored scenario, trace and first misbehaviour are judged again
(:func:`drivefuzz.triage.attribute.attribute`, with the careful driver's replay under the campaign's oracle
settings, as its triage ran it) and signed again (:func:`drivefuzz.triage.signature.signature`). Prints
each folder whose fault, reason or signature changed, the old and the new, then a count::

    python tools/rejudge.py CAMPAIGN [CAMPAIGN ...]

For reading what a change to the rules does to real verdicts before it lands. Nothing is written: the
folders keep their verdict.json. Prints only; an evaluation script, not a test.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("campaigns", type=Path, nargs="+", help="campaign output folders")
    args = ap.parse_args(argv)

    from drivefuzz.oracle import Misbehavior, OracleSettings
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.sumofiles import load_scenario
    from drivefuzz.sim.execute import execute
    from drivefuzz.sim.trace import Trace
    from drivefuzz.triage.attribute import attribute
    from drivefuzz.triage.signature import signature

    total = changed = faults = 0
    for camp in args.campaigns:
        folders = sorted(p for kind in ("findings", "incidents") for p in (camp / kind).glob("*") if p.is_dir())
        if not folders:
            print(f"{camp}: no findings/ or incidents/ folders", file=sys.stderr)
        for d in folders:
            old = json.loads((d / "verdict.json").read_text())
            if not (d / "trace").is_dir():  # a crash or hang of the simulator: nothing to judge
                continue
            settings = OracleSettings(settings=old.get("oracles") or {})  # the campaign's, as its triage ran

            def careful(sc, settings=settings):
                ex = execute(sc, oracles=settings.instantiate())
                return ex.misbehaviors, ex.trace

            sc = load_scenario(d)
            trace = Trace.load(d / "trace")
            m = Misbehavior.from_dict(old["misbehaviors"][0])
            rmap = load_roadmap(sc.network_path())
            new = attribute(sc, trace, m, rmap, replay=careful)
            sig = signature(sc, trace, m, rmap, new)
            was, was_sig = old.get("attribution") or {}, (old.get("signature") or {}).get("label")
            total += 1
            if (new.fault.value, new.reason, sig.label) == (was.get("fault"), was.get("reason"), was_sig):
                continue
            changed += 1
            faults += new.fault.value != was.get("fault")
            print(f"{d}\n  was {was.get('fault')}: {was.get('reason')}\n  now {new.fault.value}: {new.reason}")
            if sig.label != was_sig:
                print(f"  signature was {was_sig}\n            now {sig.label}")
    print(f"{changed} of {total} verdicts changed, {faults} of them in fault")
    return 0


if __name__ == "__main__":
    sys.exit(main())
