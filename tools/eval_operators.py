"""Which kinds of move made the findings: executions, findings and new signatures per kind of mutation.

Reads the journals of campaign folders (``CAMPAIGN/jobs/*/journal.jsonl``) and sorts every mutant's execution
by the kind of move that made it, from its mutation description (:meth:`drivefuzz.search.mutate.Mutator.successor`):

- ``situation NAME``: a situation of the catalogue (docs/catalogue.md) or of the maneuver strategy;
- ``target ASPECT``: a targeted move of the riskiest actor (its departure, start, speed or lane);
- ``add NAV KIND``: a component placed by the strategy (``add linear vehicle``, ``add puddle``, ...).

For each kind it prints the executions, the findings (the ego's fault or unclear; incidents are not findings)
with the ego's fault, the signatures it was the first to find in its campaign, the findings in a situation new
to the seed's job (the coverage the schedule counts, :mod:`drivefuzz.search.schedule`), and those per 100
executions, most productive first::

    python tools/eval_operators.py CAMPAIGN [CAMPAIGN ...]

Use it to read what a campaign's budget bought, or to set ``MutationConfig.target_share`` and
``catalogue_share`` for an ADS. Prints only; an evaluation script, not a test.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections import Counter
from pathlib import Path

_TARGET = re.compile(r"target \S+: (\w+)")
_ADD = re.compile(r"add (\w+(?: \w+)?)")


def kind_of(description: str) -> str:
    """The kind of move named by a mutation description ('' for the seed's own run)."""
    if description.startswith("situation "):
        return "situation " + description.split()[1].rstrip(":")
    m = _TARGET.match(description)
    if m:
        return "target " + m.group(1)
    m = _ADD.match(description)
    if m:
        return "add puddle" if m.group(1).startswith("puddle") else "add " + m.group(1)
    return "" if description.startswith("the seed") else description.split(";")[0][:40]


def _records(journal: Path):
    for line in journal.read_text(errors="replace").splitlines():
        try:
            rec = json.loads(line)
        except ValueError:  # a line cut short by a kill
            continue
        if isinstance(rec, dict) and rec.get("event") == "end" and rec.get("lineage", -1) >= 0:
            yield rec


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("campaigns", type=Path, nargs="+", help="campaign output folders")
    args = ap.parse_args(argv)
    execs, ego, first, new_cov = Counter(), Counter(), Counter(), Counter()
    for camp in args.campaigns:
        journals = sorted(camp.glob("jobs/*/journal.jsonl"))
        if not journals:
            print(f"{camp}: no jobs/*/journal.jsonl (not a campaign folder)", file=sys.stderr)
            continue
        signatures: set[str] = set()
        for journal in journals:
            found_here: set[str] = set()
            for rec in _records(journal):
                kind = kind_of(str(rec.get("mutation", "")))
                execs[kind] += 1
                finding = rec.get("finding")
                if not finding:
                    continue
                situation = rec.get("situation")
                if situation and situation not in found_here:
                    found_here.add(situation)
                    new_cov[kind] += 1
                verdict = camp / str(finding) / "verdict.json"
                if not verdict.is_file():
                    continue
                v = json.loads(verdict.read_text())
                if (v.get("attribution") or {}).get("fault", "ego") != "ego":
                    continue
                ego[kind] += 1
                key = (v.get("signature") or {}).get("key")
                if key and key not in signatures:
                    signatures.add(key)
                    first[kind] += 1
    total = sum(execs.values())
    if not total:
        print("no mutant executions in these folders")
        return 1
    print(f"{total} mutant executions in {len(args.campaigns)} campaign folder(s)")
    print(f"{'kind of move':<34}{'execs':>7}{'share':>7}{'ego':>6}{'first':>7}{'new sit.':>9}"
          f"{'first/100':>10}{'new/100':>9}")
    for kind in sorted(execs, key=lambda k: (-(first[k] / execs[k]), -execs[k])):
        n = execs[kind]
        print(f"{kind or '(other)':<34}{n:>7}{100 * n / total:>6.1f}%{ego[kind]:>6}{first[kind]:>7}{new_cov[kind]:>9}"
              f"{100 * first[kind] / n:>10.2f}{100 * new_cov[kind] / n:>9.2f}")
    print("ego: findings of the ego's fault; first: signatures first found by this kind in its campaign; "
          "new sit.: findings in a situation new to the seed's job")
    return 0


if __name__ == "__main__":
    sys.exit(main())
