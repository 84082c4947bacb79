"""Re-judge the findings and incidents of campaign folders with the current attribution rules.

For every folder under ``CAMPAIGN/findings/`` and ``CAMPAIGN/incidents/`` with a trace (not a simulator crash):
the stored scenario, trace and first misbehaviour are judged again
(:func:`drivefuzz.triage.attribute.attribute`, with the careful driver's replay under the campaign's oracle
settings, as its triage ran it) and signed again (:func:`drivefuzz.triage.signature.signature`). Prints
each folder whose fault, reason or signature changed, the old and the new, then a count::

    python tools/rejudge.py CAMPAIGN [CAMPAIGN ...]
    python tools/rejudge.py --cases tests/data        # scenario folders without a stored verdict

``--cases DIR``: every scenario folder under DIR (such as the campaign cases kept in tests/data) is run with
every oracle and its first misbehaviour judged twice: in the order before issue 31 (an excusing rule decides
``other`` before any replay) and in the current one (the excuse is a hypothesis the careful driver's replay
tests); each folder whose verdict differs is printed with both. The network is looked for in the folder, then
in networks/.

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
    ap.add_argument("campaigns", type=Path, nargs="*", help="campaign output folders")
    ap.add_argument("--cases", type=Path, help="a folder of scenario folders to run and judge (tests/data)")
    args = ap.parse_args(argv)
    if args.cases:
        return cases(args.cases)

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


def both_orders(sc, trace, m, rmap, replay):
    """(old, new): the verdict on ``m`` in the order before issue 31 (an excusing rule decides ``other`` before any
    replay) and in the current one (the excuse is a hypothesis that ``replay``, the careful driver's, tests)."""
    from drivefuzz.triage.attribute import Fault, attribute

    rules = attribute(sc, trace, m, rmap)
    new = attribute(sc, trace, m, rmap, replay=replay)
    return (rules if rules.fault is Fault.OTHER else new), new


def careful_replay(sc):
    """The careful driver's replay as the fuzz loop's triage runs it by default: every oracle, default settings."""
    from drivefuzz.oracle import OracleSettings
    from drivefuzz.sim.execute import execute

    ex = execute(sc, oracles=OracleSettings().instantiate())
    return ex.misbehaviors, ex.trace


def judge_case(case: Path, workdir: Path):
    """Run the scenario folder ``case`` (copied into ``workdir``, with its network: the folder's own, else the one
    of that name in networks/) with every oracle; (first misbehaviour, old verdict, new verdict, scenario,
    execution) by :func:`both_orders`, or (None, None, None, scenario, execution) when nothing misbehaved."""
    import shutil

    from drivefuzz.oracle import OracleSettings
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.sumofiles import load_scenario
    from drivefuzz.sim.execute import execute

    net = json.loads((case / "scenario.json").read_text())["network"]
    folder = workdir / case.name
    shutil.copytree(case, folder)
    if not (folder / Path(net).name).exists():
        shutil.copy(REPO / "networks" / Path(net).name, folder / Path(net).name)
    sc = load_scenario(folder)
    ex = execute(sc, oracles=OracleSettings().instantiate())
    if not ex.misbehaviors:
        return None, None, None, sc, ex
    m = ex.misbehaviors[0]
    old, new = both_orders(sc, ex.trace, m, load_roadmap(sc.network_path()), careful_replay)
    return m, old, new, sc, ex


def cases(root: Path) -> int:
    """Run and judge each scenario folder under ``root`` in the old order and the current one."""
    import tempfile

    total = changed = 0
    for d in sorted(p for p in root.iterdir() if (p / "scenario.json").exists()):
        with tempfile.TemporaryDirectory() as tmp:
            m, old, new, _sc, _ex = judge_case(d, Path(tmp))
        if m is None:
            print(f"{d.name}: no misbehaviour")
            continue
        total += 1
        if (old.fault, old.rule) == (new.fault, new.rule):
            print(f"{d.name}: {m.oracle}/{m.kind} {new.fault.value} ({new.rule}), unchanged")
            continue
        changed += 1
        print(f"{d.name}: {m.oracle}/{m.kind}\n  was {old.fault.value} ({old.rule}): {old.reason}\n"
              f"  now {new.fault.value} ({new.rule}): {new.reason}")
    print(f"{changed} of {total} verdicts changed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
