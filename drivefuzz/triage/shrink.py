"""Minimal reproducers: delta debugging over a finding's scenario.

A finding's scenario holds everything the mutator added on the way to it; most of it is irrelevant. The
shrinker removes what the bug does not need and keeps a candidate only if it still shows the **same
signature** (:mod:`drivefuzz.triage.signature`, which includes the rules' attribution):

1. the time window: the simulation ends :data:`TAIL_S` seconds after the failure, and actors that would
   depart after the failure are dropped (one execution checks both);
2. components, by delta debugging (Zeller's *ddmin*: remove halves, then quarters, ... down to single
   components): every actor, puddle, shifted traffic light and weather knob (a knob goes back to its
   default, e.g. fog 0).

Every candidate costs one execution and the number of executions is bounded (``budget``, default 30); a
shrink that runs out of budget returns the smallest scenario found so far, which always still fails the
same way. Deterministic: the same finding and budget give the same result.

Two candidates are judged without a run of their own (each still counts against the budget, so that the search
and its result are the same as with the run; ``Shrunk.reused`` counts them): a candidate judged before in the same
shrink (ddmin may come back to one; executions are deterministic), and, when the caller gives the original run
(``known``), the time window's cut that drops no actor: it differs from the scenario only in its time limit, which
ends the run after the failure, and nothing before the end reads it (the executor checks it for the end, the
mission oracle reports it at a time-out, no ADS is given it), so its run up to the failure is the original's. If
the search keeps that cut as its result, the cut is run once to give the minimal folder its own trace (and if
that run did not fail the same way, the result is the original scenario).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

from drivefuzz.oracle import Misbehavior
from drivefuzz.scenario import Scenario, Weather

#: [s] simulated after the failure that the shrunk scenario keeps.
TAIL_S = 2.0
DEFAULT_BUDGET = 30

Run = Callable[[Scenario], "tuple[Sequence[Misbehavior], Any] | None"]  # (misbehaviours, trace); None: failed
Judge = Callable[[Scenario, Misbehavior, Any], str]  # the signature key of a misbehaviour in a run


@dataclass(frozen=True)
class Size:
    actors: int
    puddles: int
    knobs: int  # weather aspects away from their defaults, and shifted traffic lights
    sim_seconds: float

    @classmethod
    def of(cls, sc: Scenario) -> "Size":
        return cls(len(sc.actors), len(sc.puddles), len(_knobs(sc.weather)) + len(sc.signals), sc.sim.time_limit)

    def as_dict(self) -> dict[str, Any]:
        return {"actors": self.actors, "puddles": self.puddles, "knobs": self.knobs, "sim_seconds": self.sim_seconds}


@dataclass(frozen=True)
class Shrunk:
    scenario: Scenario
    misbehavior: Misbehavior  # the failure of the shrunk scenario
    before: Size
    after: Size
    executions: int  # candidates judged (the budget's unit)
    signature: str
    trace: Any = None  # of the shrunk scenario's run (None: the original was already minimal)
    reused: int = 0  # of the executions, candidates judged without a run of their own (module docstring)
    runs: int | None = None  # executions actually run (None: ``executions``)

    def as_dict(self) -> dict[str, Any]:
        return {"before": self.before.as_dict(), "after": self.after.as_dict(), "executions": self.executions,
                "signature": self.signature, "frame": self.misbehavior.frame, "reused": self.reused,
                "runs": self.executions if self.runs is None else self.runs}

    @property
    def summary(self) -> str:
        b, a = self.before, self.after
        return (f"actors {b.actors} -> {a.actors}, puddles {b.puddles} -> {a.puddles}, knobs {b.knobs} -> "
                f"{a.knobs}, simulated {b.sim_seconds:.1f} -> {a.sim_seconds:.1f} s, in {self.executions} executions")


def _knobs(w: Weather) -> list[str]:
    default = Weather()
    return [k for k in Weather.model_fields if getattr(w, k) != getattr(default, k)]


def _components(sc: Scenario) -> list[tuple[str, str]]:
    return ([("actor", a.id) for a in sc.actors] + [("puddle", str(i)) for i in range(len(sc.puddles))]
            + [("signal", s.tls) for s in sc.signals] + [("weather", k) for k in _knobs(sc.weather)])


def _keep(sc: Scenario, kept: set[tuple[str, str]]) -> Scenario:
    """``sc`` with only the components in ``kept`` (weather knobs not kept go back to their defaults)."""
    default = Weather()
    weather = sc.weather.model_copy(update={k: getattr(default, k) for k in _knobs(sc.weather)
                                            if ("weather", k) not in kept})
    return sc.model_copy(update={
        "actors": tuple(a for a in sc.actors if ("actor", a.id) in kept),
        "puddles": tuple(p for i, p in enumerate(sc.puddles) if ("puddle", str(i)) in kept),
        "signals": tuple(s for s in sc.signals if ("signal", s.tls) in kept),
        "weather": weather,
    })


class _Tester:
    """Runs candidates within the budget; a candidate passes when it fails with the same signature."""

    def __init__(self, run: Run, judge: Judge, original: Misbehavior, signature: str, budget: int):
        self.run, self.judge, self.original, self.signature = run, judge, original, signature
        self.budget, self.spent, self.reused, self.runs = budget, 0, 0, 0
        self.trace = None  # of the last candidate that passed
        self.seen: list[tuple[Scenario, Misbehavior | None, Any]] = []  # candidates judged: (scenario, result, trace)

    @property
    def exhausted(self) -> bool:
        return self.spent >= self.budget

    def __call__(self, sc: Scenario, known: "tuple[Sequence[Misbehavior], Any] | None" = None) -> Misbehavior | None:
        """Judge ``sc``: its run's misbehaviour with the signature, or None. ``known``: its run's result, given
        (no run); a candidate judged before is judged on its earlier run. Either way it counts against the budget."""
        self.spent += 1
        for prev, m, trace in self.seen:
            if prev == sc:
                self.reused += 1
                if m is not None:
                    self.trace = trace
                return m
        if known is None:
            self.runs += 1
            got = self.run(sc)
        else:
            self.reused += 1
            got = known
        m, trace = self._judge(sc, got)
        self.seen.append((sc, m, trace))
        if m is not None:
            self.trace = trace
        return m

    def _judge(self, sc: Scenario, got) -> tuple[Misbehavior | None, Any]:
        if got is None:
            return None, None
        misbehaviors, trace = got
        for m in misbehaviors:
            if m.oracle == self.original.oracle and m.kind == self.original.kind:
                if self.judge(sc, m, trace) != self.signature:
                    return None, None
                return m, trace
        return None, None


def shrink(scenario: Scenario, original: Misbehavior, signature: str, run: Run, judge: Judge,
           budget: int = DEFAULT_BUDGET, known: "tuple[Sequence[Misbehavior], Any] | None" = None) -> Shrunk:
    """The smallest scenario found within ``budget`` executions that fails with ``signature``. ``known``: the
    (misbehaviours, trace) of ``scenario``'s own run, which judges the time window's cut when it drops no actor
    (module docstring)."""
    test = _Tester(run, judge, original, signature, budget)
    best, best_m = scenario, original
    cut = _cut_window(scenario, original)
    # the cut that only ends the run sooner ran, up to the failure, as the original did
    same_run = known if known is not None and cut.actors == scenario.actors else None
    if cut != scenario and not test.exhausted and (m := test(cut, same_run)) is not None:
        best, best_m = cut, m
    base = best  # components are named in it (puddles by index): candidates are always cut from it
    comps = _components(base)
    n = 2
    while len(comps) >= 1 and not test.exhausted:
        chunks = [comps[i * len(comps) // n:(i + 1) * len(comps) // n] for i in range(n)]
        for chunk in (c for c in chunks if c):
            if test.exhausted:
                break
            rest = [c for c in comps if c not in chunk]
            cand = _keep(base, set(rest))
            if (m := test(cand)) is not None:
                best, best_m, comps = cand, m, rest
                n = max(n - 1, 2)
                break
        else:
            if n >= len(comps):
                break
            n = min(len(comps), 2 * n)
    trace = test.trace if best is not scenario else None
    if best is cut and same_run is not None:  # judged on the original's run: the minimal folder gets its own
        test.runs += 1
        m, trace = test._judge(cut, run(cut))
        if m is None:  # not as argued in the module docstring: keep the original, which fails
            best, best_m, trace = scenario, original, None
        else:
            best_m = m
    return Shrunk(best, best_m, Size.of(scenario), Size.of(best), test.spent, signature, trace, test.reused,
                  test.runs)


def _cut_window(sc: Scenario, m: Misbehavior) -> Scenario:
    """``sc`` ending :data:`TAIL_S` after the failure, without the actors that depart after it."""
    end = min(sc.sim.time_limit, round(m.time + TAIL_S, 2))
    return sc.model_copy(update={"sim": sc.sim.model_copy(update={"time_limit": end}),
                                 "actors": tuple(a for a in sc.actors if a.depart <= m.time)})


def shrink_finding(folder, verdict: dict[str, Any], original: Misbehavior, scenario: Scenario, oracles,
                   budget: int = DEFAULT_BUDGET) -> Shrunk:
    """Shrink the finding in ``folder`` (its verdict, first misbehaviour, scenario and oracle instances) by
    running it in this process; write ``minimal/`` (a replayable finding folder) and ``shrink.json``."""
    from pathlib import Path

    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.sim.execute import execute
    from drivefuzz.sim.trace import Trace
    from drivefuzz.storage import atomic_dir, atomic_write_json

    folder = Path(folder)
    rmap = load_roadmap(scenario.network_path())
    judge = rules_signature(rmap)
    trace = Trace.load(folder / "trace")
    target = judge(scenario, original, trace)

    def run(sc: Scenario):
        ex = execute(sc, oracles=oracles)
        return ex.misbehaviors, ex.trace

    shrunk = shrink(scenario, original, target, run, judge, budget)
    with atomic_dir(folder / MINIMAL) as tmp:
        write_minimal(tmp, verdict, shrunk, trace)
    atomic_write_json(folder / "shrink.json", shrunk.as_dict())
    return shrunk


#: the subfolder of a finding that holds its shrunk scenario
MINIMAL = "minimal"


def write_minimal(dest, verdict: dict[str, Any], shrunk: Shrunk, original_trace) -> None:
    """Write ``shrunk`` into the (new, empty) folder ``dest`` as a finding ``drivefuzz replay`` accepts:
    the scenario with its network, the trace of its run, a verdict with its misbehaviour, replay.sh."""
    import os

    from drivefuzz.scenario.sumofiles import write_scenario
    from drivefuzz.storage import atomic_write_json, atomic_write_text
    from drivefuzz.triage.store import replay_script

    trace = shrunk.trace if shrunk.trace is not None else original_trace
    write_scenario(shrunk.scenario, dest, portable=True)
    trace.save(dest / "trace")
    atomic_write_json(dest / "verdict.json", {
        **verdict, "misbehaviors": [shrunk.misbehavior.as_dict()], "frames": trace.n_frames,
        "scenario_hash": shrunk.scenario.content_hash(), "shrunk_from": verdict.get("key"),
        "shrink": shrunk.as_dict()})
    atomic_write_text(dest / "replay.sh", replay_script(shrunk.scenario.ads.name))
    os.chmod(dest / "replay.sh", 0o755)


def rules_signature(rmap) -> Judge:
    """The signature key of a misbehaviour under the rules' attribution (no counterfactual replay)."""
    from drivefuzz.triage.attribute import attribute
    from drivefuzz.triage.signature import signature

    def judge(sc: Scenario, m: Misbehavior, trace) -> str:
        return signature(sc, trace, m, rmap, attribute(sc, trace, m, rmap)).key

    return judge
