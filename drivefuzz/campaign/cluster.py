"""Where seed jobs run: a Dask client on a local cluster, an existing scheduler, or a batch system.

- ``local``: a ``LocalCluster`` that drivefuzz starts and stops, one single-threaded
  worker process per job (libsumo allows one simulation per process);
- an address (``tcp://host:8786``) or a scheduler file (``scheduler.json``) of a
  running ``dask scheduler`` whose workers were started with ``dask worker --nthreads 1``;
- ``slurm``, ``pbs``, ``sge``, ``lsf``: dask-jobqueue starts the workers as batch jobs.

Settings measured for long, uneven jobs (``../shared/reference/distributed-notes.md``):
``worker-saturation: 1.0`` gives each worker one job and keeps the rest queued on
the scheduler. Workers need no ``daemon: False``: the simulation host is a plain
subprocess. Every worker must reach the campaign directory (a shared filesystem).
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any, Iterator

from pydantic import BaseModel, ConfigDict, Field

from drivefuzz.errors import InvalidConfig

BATCH_SYSTEMS = ("slurm", "pbs", "sge", "lsf")

DASK_SETTINGS = {
    "distributed.scheduler.worker-saturation": 1.0,  # one job per worker; the rest wait on the scheduler
    "distributed.scheduler.allowed-failures": 3,  # a job may take down 3 workers before Dask gives up on it
    # Dask's own periodic work, cut to what a few long tasks need: it runs on the cores the simulations need.
    # Measured on 2 cores, 2 workers running pure-Python tasks: the workers' Dask threads 2.2 % of a core each
    # and the campaign process's (scheduler, nannies) 2.5 %, against 0.4 % and 0.9 % with these settings.
    "distributed.worker.profile.enabled": False,  # the statistical profiler: a stack sample every 10 ms in
    # the job's own process, for the dashboard's profile page
    "distributed.admin.tick.interval": "1s",  # the event-loop watchdog: every 20 ms in every process
    "distributed.worker.memory.monitor-interval": "1s",  # every 100 ms per worker and per nanny
    "distributed.admin.system-monitor.interval": "2s",  # the dashboard's CPU, memory and network plots
    "distributed.scheduler.work-stealing": False,  # nothing to steal: a worker holds one job at a time
}


class BatchSpec(BaseModel):
    """Worker jobs on a batch system (``[cluster]`` of a campaign file)."""

    model_config = ConfigDict(extra="forbid")
    backend: str = Field(default="slurm", description="slurm, pbs, sge or lsf")
    queue: str | None = None
    account: str | None = None
    cores: int = Field(default=16, ge=1, description="cores per batch job = worker processes per job")
    memory: str = Field(default="32GB", description="memory per batch job")
    walltime: str = Field(default="04:00:00")
    max_jobs: int = Field(default=4, ge=1, description="batch jobs at most (adaptive)")
    prologue: list[str] = Field(default_factory=list, description="shell lines before the worker starts, e.g. activating a venv")
    python: str | None = Field(default=None, description="the workers' Python (default: the one running drivefuzz)")
    local_directory: str | None = None
    log_directory: str | None = None


def make_batch_cluster(spec: BatchSpec):
    """A dask-jobqueue cluster whose every worker is a single-threaded process (``cores == processes``)."""
    import dask_jobqueue

    classes = {"slurm": dask_jobqueue.SLURMCluster, "pbs": dask_jobqueue.PBSCluster,
               "sge": dask_jobqueue.SGECluster, "lsf": dask_jobqueue.LSFCluster}
    if spec.backend not in classes:
        raise InvalidConfig("cluster.backend", spec.backend, "unknown batch system", ", ".join(BATCH_SYSTEMS))
    return classes[spec.backend](**batch_kwargs(spec))


def check_submit_command(backend: str) -> None:
    """Fail now, in one line, where the batch system's submit command is missing (not later, in a hang)."""
    import shutil

    command = {"slurm": "sbatch", "pbs": "qsub", "sge": "qsub", "lsf": "bsub"}[backend]
    if shutil.which(command) is None:
        raise InvalidConfig("run.where", backend, f"'{command}' is not on this machine's PATH",
                            "run drivefuzz campaign on the cluster's login node, or where = \"local\"")


def batch_kwargs(spec: BatchSpec) -> dict[str, Any]:
    """dask-jobqueue arguments for ``spec``: every worker a single-threaded process."""
    kwargs: dict[str, Any] = dict(cores=spec.cores, processes=spec.cores, memory=spec.memory, walltime=spec.walltime,
                                  queue=spec.queue, job_script_prologue=list(spec.prologue))
    if spec.account:
        kwargs["account" if spec.backend != "lsf" else "project"] = spec.account
    if spec.python:
        kwargs["python"] = spec.python
    if spec.local_directory:
        kwargs["local_directory"] = spec.local_directory
    if spec.log_directory:
        kwargs["log_directory"] = spec.log_directory
    # retire workers before the walltime kills them; adapt() starts new ones and the jobs resume there
    kwargs["worker_extra_args"] = ["--lifetime", _lifetime(spec.walltime), "--lifetime-stagger", "2m"]
    return kwargs


def _lifetime(walltime: str) -> str:
    """Retire a worker 10 minutes before its batch job's walltime (its job resumes elsewhere)."""
    parts = [int(p) for p in walltime.split(":")]
    while len(parts) < 3:
        parts.insert(0, 0)
    seconds = parts[0] * 3600 + parts[1] * 60 + parts[2]
    return f"{max(seconds - 600, 60)}s"


@contextlib.contextmanager
def dask_client(where: str = "local", jobs: int = 2, batch: BatchSpec | None = None) -> Iterator[Any]:
    """A Dask client for ``where``: ``local``, an address or scheduler file, or a batch system."""
    import dask
    from distributed import Client, LocalCluster

    with dask.config.set(DASK_SETTINGS), contextlib.ExitStack() as stack:
        if where == "local":
            stack.enter_context(dask.config.set({"distributed.worker.preload": ["drivefuzz.campaign.cluster"]}))
            # no dashboard; the scheduler's HTTP server (health, metrics) on a free port, not on 8787, which
            # another cluster on a shared machine may hold (Dask then warns and takes another anyway)
            cluster = stack.enter_context(LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                                                       dashboard_address=None, silence_logs=40,
                                                       scheduler_kwargs={"dashboard_address": ":0"}))
            client = stack.enter_context(Client(cluster))
        elif where in BATCH_SYSTEMS:
            check_submit_command(where)
            spec = (batch or BatchSpec()).model_copy(update={"backend": where})
            cluster = stack.enter_context(make_batch_cluster(spec))
            cluster.adapt(minimum_jobs=1, maximum_jobs=spec.max_jobs)
            client = stack.enter_context(Client(cluster))
        else:
            client = stack.enter_context(_connect(where))
        yield client


def _connect(where: str):
    from distributed import Client

    is_file = where.endswith(".json") or Path(where).is_file()
    if is_file and not Path(where).is_file():
        raise InvalidConfig("--scheduler", where, "no such scheduler file", "tcp://HOST:PORT or a scheduler.json")
    if not is_file and "://" not in where and ":" not in where:
        raise InvalidConfig("--scheduler", where, "not a scheduler address",
                            "local, tcp://HOST:PORT, a scheduler.json, or " + "/".join(BATCH_SYSTEMS))
    try:
        return Client(scheduler_file=where, timeout="20s") if is_file else Client(where, timeout="20s")
    except (OSError, TimeoutError, ValueError, AssertionError, KeyError, TypeError, ImportError,
            RecursionError) as exc:
        # OSError/TimeoutError: nobody listens; ValueError: a malformed address; AssertionError/KeyError:
        # a scheduler file that is not one; TypeError/ImportError: a protocol (ucx://) this install lacks
        problem = f"cannot reach the Dask scheduler ({type(exc).__name__}: {exc})"
    # the half-built Client must be collected now: collected later, inside another Client's start-up,
    # its __del__ deadlocks on distributed's loop-runner lock
    import gc

    gc.collect()
    raise InvalidConfig("--scheduler", where, problem,
                        "the address a running 'dask scheduler' printed, or its --scheduler-file")


def dask_setup(worker) -> None:
    """Worker preload (``distributed.worker.preload``): a terminal's Ctrl-C reaches every process in the
    foreground group, but only the campaign process decides how a campaign stops. And the worker readies
    itself for seed jobs (imports, a simulation host) before it registers, as part of the cluster's start-up
    (:func:`drivefuzz.campaign.hosts.warm_worker`)."""
    import logging
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    # a local cluster's scheduler lives in the campaign process and closes with it; a worker whose heartbeat
    # falls in between logs the lost connection as an error with a traceback on the user's terminal (CI saw it
    # once after a Ctrl-C). Nothing is lost then (the campaign has stopped its jobs), so that one record is dropped.
    logging.getLogger("distributed.worker").addFilter(_HeartbeatAfterClose())
    from drivefuzz.campaign.hosts import warm_worker

    warm_worker()


class _HeartbeatAfterClose:
    """A logging filter (see :func:`dask_setup`): drops the worker's "Failed to communicate with scheduler during
    heartbeat" record, which a local worker logs when the campaign process and its scheduler close first."""

    def filter(self, record) -> bool:
        return "Failed to communicate with scheduler during heartbeat" not in record.getMessage()
