"""The simulation hosts of a worker process, and the runner through which a seed job executes.

A seed job runs every execution isolated in a simulation host (:mod:`drivefuzz.sim.simhost`), one per thread of
the process, kept between jobs (a Dask worker runs many); :func:`warm_worker` starts one, with the imports a job
makes, before the worker is given its first job. ``--no-isolation`` runs executions in the job's own process.
"""

from __future__ import annotations

import time
from typing import Any

_WARMED = False


def _warm_imports() -> None:
    try:
        import scipy.signal  # noqa: F401
        import pyarrow as pa
        import pyarrow.parquet as pq

        # the first write_table imports pandas (0.5-1.3 s on a shared 2-core machine); a finding's trace pays it
        pq.write_table(pa.table({"x": [0.0]}), pa.BufferOutputStream())
    except Exception:  # noqa: BLE001 - the score and the trace import them again and report what is wrong
        pass


def warm_up() -> None:
    """Import scipy.signal (the driving-quality score's filters: 0.4 s, once per process) and pyarrow's Parquet
    writer, with the pandas that its first write imports (a finding's trace), on a thread of its own while the
    first executions run in the simulation host: this process only waits on the host then, so the imports cost
    a short campaign no wall time instead of delaying the first score and the first finding."""
    global _WARMED
    if _WARMED:
        return
    _WARMED = True
    import threading

    threading.Thread(target=_warm_imports, name="drivefuzz-warm-up", daemon=True).start()


#: what a seed job imports as it goes (drivefuzz.sim.execute and trace: to read the host's results)
_JOB_MODULES = ("drivefuzz.ads", "drivefuzz.scenario.roadmap", "drivefuzz.search.catalogue", "drivefuzz.search.mutate",
                "drivefuzz.search.quality", "drivefuzz.search.risk", "drivefuzz.search.schedule",
                "drivefuzz.sim.execute", "drivefuzz.sim.trace", "drivefuzz.triage.attribute",
                "drivefuzz.triage.coverage", "drivefuzz.triage.reproduce", "drivefuzz.triage.shrink",
                "drivefuzz.triage.signature")


def warm_worker() -> None:
    """Ready this process for seed jobs before it is given one (a local Dask worker's preload): the imports a
    job makes as it starts, and a simulation host, started. A cold worker did that inside the campaign's
    budget, where no core is free for it (on 2 cores, 2 jobs' first rounds waited 1-2 s each on scipy's
    import, a job on its own 0.2 s); here it is part of the cluster's start-up. Best effort: whatever fails
    here fails again, and is reported, where a job needs it."""
    import importlib

    global _WARMED
    _WARMED = True
    _warm_imports()
    for module in _JOB_MODULES:
        try:
            importlib.import_module(module)
        except Exception:  # noqa: BLE001 - see above
            pass
    try:
        from drivefuzz.sim.simhost import SimHost

        host = SimHost().start()
    except Exception:  # noqa: BLE001 - see above
        return
    _close_hosts_at_exit()
    _SPARE.append(host)


_HOSTS: dict[int, Any] = {}  # one simulation host per thread of this process, kept between jobs
_SPARE: list[Any] = []  # hosts started before a thread asked for one (warm_worker)
_AT_EXIT: list[bool] = []


def _close_hosts_at_exit() -> None:
    if not _AT_EXIT:
        import atexit

        _AT_EXIT.append(True)
        atexit.register(lambda: [h.close() for h in [*_HOSTS.values(), *_SPARE]])


def _host_for_this_thread(timeout_s: float):
    """The calling thread's simulation host (started lazily; a Dask worker reuses it for every job)."""
    import threading

    from drivefuzz.sim.simhost import SimHost

    tid = threading.get_ident()
    host = _HOSTS.get(tid)
    if host is None:
        _close_hosts_at_exit()
        host = _HOSTS[tid] = _SPARE.pop() if _SPARE else SimHost()
    host.timeout_s = timeout_s
    return host


class Runner:
    """Runs executions isolated in a simulation host (the default) or in this process."""

    def __init__(self, cfg):
        self.cfg = cfg
        self.host = _host_for_this_thread(cfg.exec_timeout_s) if cfg.isolate else None
        self.runs = 0  # executions run, triage reruns included
        self.sim_s = 0.0  # [s] simulated by those that ran to the end

    def _count(self, scenario, out):
        from drivefuzz.sim.simhost import OK

        self.runs += 1
        if out.status == OK:
            self.sim_s += out.execution.trace.n_frames * scenario.sim.step_length
        return out

    def misbehaviors(self, scenario):
        """(misbehaviors, trace) of a triage rerun, or None when it did not run to the end."""
        from drivefuzz.sim.simhost import OK

        out = self.execute(scenario)
        return (tuple(out.execution.misbehaviors), out.execution.trace) if out.status == OK else None

    def execute(self, scenario):
        return self._count(scenario, self._execute(scenario))

    def _execute(self, scenario):
        if self.host is not None:
            return self.host.execute(scenario, self.cfg.oracles.settings)
        from drivefuzz.errors import PluginError
        from drivefuzz.sim.execute import execute
        from drivefuzz.sim.simhost import OK, PLUGIN_ERROR, Outcome

        t0 = time.monotonic()
        try:
            ex = execute(scenario, oracles=self.cfg.oracles.instantiate())
        except PluginError as exc:  # without isolation only a plugin's exception can be survived
            return Outcome(PLUGIN_ERROR, detail=str(exc), error_type=type(exc.__cause__ or exc).__name__,
                           wall_time=time.monotonic() - t0, plugin=exc.plugin)
        return Outcome(OK, execution=ex, wall_time=time.monotonic() - t0)
