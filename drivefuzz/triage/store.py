"""From a misbehaviour to a finding: attribution, signature, one folder per signature, reproduction rate.

A seed job hands every execution whose oracles fired to :meth:`FindingStore.triage`:

1. **Attribution by the rules** on the trace (:func:`drivefuzz.triage.attribute.attribute`, no replay).
2. **Signature** (:func:`drivefuzz.triage.signature.signature`): if a folder for it exists already, the
   execution is one more hit of that finding (or incident), and nothing else runs.
3. For a **new** signature: the counterfactual replay by the careful driver when the rules did not excuse
   the ego (the verdict, and so the signature, may change to ``other`` or ``unclear``), then the **reproduction rate** under small
   perturbations (:mod:`drivefuzz.triage.reproduce`; for an incident only with
   ``TriageConfig.reproduce_incidents``), then the folder is written.

4. For a new **finding** (not an incident), with ``TriageConfig.shrink`` executions: a minimal reproducer
   by delta debugging (:mod:`drivefuzz.triage.shrink`), in the folder's ``minimal/``.

Folders: ``findings/<signature>-<oracle>/`` when the ego is at fault (or it is unclear), ``incidents/...``
when it is not. Each holds the SUMO files, ``scenario.json``, the trace, ``verdict.json`` (misbehaviours,
attribution, signature, reproduction, the execution that found it) and ``replay.sh``. How many executions
hit a signature, and which, is in the campaign index; the campaign process writes it into each folder's
``hits.json`` (:func:`write_hits`).

Simulator crashes, hangs and plugin errors have no trace: their signature is their kind and error type, and
their fault is the caller's (:func:`drivefuzz.sim.simhost.failure_fault`). Those of the ADS (it raised or hung)
are findings; the others (SUMO died, drivefuzz or an oracle plugin raised: fault ``tool`` or ``oracle-plugin``)
go to ``errors/<signature>-<status>/``, folders like a finding's (scenario, verdict with the error and its
traceback, replay.sh) that report an error of the tool, never a finding of the ADS.
"""

from __future__ import annotations

import hashlib
import json
import os
import shlex
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import drivefuzz
from drivefuzz.oracle import Misbehavior
from drivefuzz.scenario.sumofiles import write_scenario
from drivefuzz.storage import atomic_dir, atomic_write_json, atomic_write_text

FINDINGS = "findings"
INCIDENTS = "incidents"
ERRORS = "errors"  # failed executions that are not the ADS's fault: errors of the tool or of an oracle plugin
ALIASES = "triage-aliases"  # rules-only signature -> the folder its counterfactual filed it in


def ads_flag(ads_name: str | None) -> str:
    """`` --ads NAME`` for an ADS that is not an installed plugin (replay must name it to trust it), else ''."""
    from drivefuzz.ads import available_ads

    return "" if ads_name is None or ads_name in available_ads() else f" --ads {shlex.quote(ads_name)}"


def replay_script(ads_name: str = "ego") -> str:
    """``replay.sh``, naming the ADS when it is not an installed plugin."""
    return ("#!/bin/sh\n# Runs this finding again and checks it reproduces.\n"
            f'cd "$(dirname "$0")" && exec drivefuzz replay .{ads_flag(ads_name)}\n')


@dataclass(frozen=True)
class Triaged:
    """Where an execution's misbehaviour went: ``rel`` (folder under the campaign), new or a repeat."""

    rel: str
    signature: str
    fault: str
    new: bool
    executions: int  # what triage ran (counterfactual and reproduction)


@dataclass
class TriageConfig:
    counterfactual: bool = True  # replay with the careful driver when the rules blame the ego
    reproduce: int = 5  # perturbed reruns of each new signature's representative (0: none)
    reproduce_incidents: bool = True  # also of a new incident (fault other), not only of a new finding
    shrink: int = 0  # executions to shrink each new finding (not incidents) to a minimal reproducer (0: none)


def _crash_key(m: Misbehavior, fault: str = "ego") -> str:
    # an ADS's failures keep the keys of campaigns filed before faults were told apart (a resume adds hits to
    # their folders); an oracle's ZeroDivisionError is not the same signature as the ADS's
    text = f"{m.oracle}/{m.kind}" if fault == "ego" else f"{m.oracle}/{m.kind}/{fault}"
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def folder_of(fault: str, traced: bool = True) -> str:
    """The campaign subfolder an execution of this ``fault`` is filed in: findings, incidents or errors."""
    if fault == "other":
        return INCIDENTS
    if not traced and fault != "ego":
        return ERRORS
    return FINDINGS


class FindingStore:
    """The findings and incidents of one campaign directory, as seen by one seed job."""

    def __init__(self, out: Path, rmap, run: Callable[[Any], Any], config: TriageConfig | None = None,
                 extra_verdict: dict[str, Any] | None = None):
        """``run(scenario) -> (misbehaviors, trace) | None`` executes a scenario (None: it failed)."""
        self.out = Path(out)
        self.rmap = rmap
        self.run = run
        self.cfg = config or TriageConfig()
        self.extra = extra_verdict or {}

    def _existing(self, key: str) -> str | None:
        for sub in (FINDINGS, INCIDENTS, ERRORS):
            folder = self.out / sub
            if folder.is_dir():
                for p in folder.glob(f"{key}-*"):
                    if (p / "verdict.json").exists():
                        return f"{sub}/{p.name}"
        return None

    def triage(self, scenario, misbehaviors: Sequence[Misbehavior], trace, key: str, termination: str,
               extra: dict[str, Any] | None = None, fault: str = "ego") -> Triaged:
        """File the execution ``key`` of ``scenario`` whose oracles reported ``misbehaviors``. Without a
        ``trace`` (the execution failed) ``fault`` is who failed: "ego", or an error of the tool (see the module)."""
        from drivefuzz.triage.attribute import Fault, attribute, needs_replay
        from drivefuzz.triage.signature import signature

        m = misbehaviors[0]
        if trace is None:  # the simulator crashed or hung, or a plugin raised
            sig_key, att, sig = _crash_key(m, fault), None, {"oracle": m.oracle, "kind": m.kind, "fault": fault}
        else:
            att = attribute(scenario, trace, m, self.rmap)
            sig_obj = signature(scenario, trace, m, self.rmap, att)
            sig_key, fault, sig = sig_obj.key, att.fault.value, _sig_dict(sig_obj)
        seen = self._existing(sig_key) or self._alias(sig_key)
        if seen:
            return Triaged(seen, _key_of(seen), self._fault_of(seen, fault), False, 0)
        rules_key = sig_key
        spent = 0
        if trace is not None and (att.fault is not Fault.OTHER or needs_replay(att)) and self.cfg.counterfactual:
            def replay(sc):
                nonlocal spent
                spent += 1
                got = self.run(sc)
                return ((), None) if got is None else got

            att2 = attribute(scenario, trace, m, self.rmap, replay=replay)
            if att2.fault is not att.fault:
                sig_obj = signature(scenario, trace, m, self.rmap, att2)
                sig_key, fault, sig = sig_obj.key, att2.fault.value, _sig_dict(sig_obj)
                seen = self._existing(sig_key)
                if seen:
                    self._set_alias(rules_key, seen)
                    return Triaged(seen, sig_key, fault, False, spent)
            att = att2
        reproduction = None
        if trace is not None and self.cfg.reproduce > 0 and (fault != "other" or self.cfg.reproduce_incidents):
            from drivefuzz.triage.reproduce import reproduction_rate

            def rerun(sc):
                nonlocal spent
                spent += 1
                got = self.run(sc)
                return None if got is None else got[0]

            reproduction = reproduction_rate(scenario, m, rerun, k=self.cfg.reproduce).as_dict()
        shrunk = None
        if trace is not None and fault != "other" and self.cfg.shrink > 0:
            from drivefuzz.triage.shrink import rules_signature, shrink

            shrunk = shrink(scenario, m, rules_key, self.run, rules_signature(self.rmap), self.cfg.shrink,
                            known=(misbehaviors, trace))  # the run it was found in judges the window's cut
        sub = folder_of(fault, trace is not None)
        rel = f"{sub}/{sig_key}-{m.oracle}"
        with atomic_dir(self.out / rel) as tmp:
            write_scenario(scenario, tmp, portable=True)  # with its network: it replays wherever it is copied
            if trace is not None:
                trace.save(tmp / "trace")
            verdict = {
                "misbehaviors": [x.as_dict() for x in misbehaviors], "termination": termination,
                "scenario_hash": scenario.content_hash(), "key": key,
                "seed_index": int(key.split("/")[0]) if key.split("/")[0].isdigit() else 0,
                "frames": None if trace is None else trace.n_frames,
                "attribution": None if att is None else att.as_dict(), "signature": {"key": sig_key, **sig},
                "reproduction": reproduction, "triage_executions": spent, "ads": scenario.ads.model_dump(mode="json"),
                "drivefuzz": drivefuzz.__version__, **self.extra, **(extra or {}),
            }
            if trace is not None and m.oracle == "collision" and m.kind == "vehicle" and m.actors:
                from drivefuzz.triage.crashtype import crash_type

                verdict["crash_type"] = crash_type(trace, m.frame, m.actors[0], self.rmap)
            if shrunk is not None:
                from drivefuzz.triage.shrink import MINIMAL, write_minimal

                verdict["shrink"] = shrunk.as_dict()
                write_minimal(tmp / MINIMAL, verdict, shrunk, trace)
            atomic_write_json(tmp / "verdict.json", verdict)
            atomic_write_text(tmp / "replay.sh", replay_script(scenario.ads.name))
            os.chmod(tmp / "replay.sh", 0o755)
        if rules_key != sig_key:
            self._set_alias(rules_key, rel)
        return Triaged(rel, sig_key, fault, True, spent)

    # A rules-only signature whose counterfactual changed the verdict points to the folder it ended in, so
    # that a repeat of the event does not replay the careful driver again.
    def _fault_of(self, rel: str, default: str) -> str:
        try:
            v = json.loads((self.out / rel / "verdict.json").read_text())
            att = v.get("attribution") or v.get("signature") or {}  # a failed execution's is in its signature
        except (OSError, ValueError, AttributeError):
            return default
        return att.get("fault", default) if isinstance(att, dict) else default

    def _alias(self, key: str) -> str | None:
        path = self.out / ALIASES / key
        try:
            rel = path.read_text().strip()
        except OSError:
            return None
        return rel if (self.out / rel / "verdict.json").exists() else None

    def _set_alias(self, key: str, rel: str) -> None:
        atomic_write_text(self.out / ALIASES / key, rel + "\n")


def _key_of(rel: str) -> str:
    return rel.split("/", 1)[1].split("-", 1)[0]


def _sig_dict(sig) -> dict[str, Any]:
    d = {k: (v.value if hasattr(v, "value") else v) for k, v in asdict(sig).items() if k != "key"}
    d["label"] = getattr(sig, "label", "")
    return d


def write_hits(out: Path, hits: dict[str, list[str]]) -> None:
    """``hits.json`` in each finding or incident folder: how many executions hit it, and which (key order)."""
    for rel, keys in hits.items():
        folder = Path(out) / rel
        if (folder / "verdict.json").exists():
            path = folder / "hits.json"
            data = {"count": len(keys), "executions": keys}
            try:
                if json.loads(path.read_text()) == data:
                    continue
            except (OSError, ValueError):
                pass
            atomic_write_json(path, data)
