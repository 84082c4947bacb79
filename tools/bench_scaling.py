"""Campaign throughput against the number of parallel jobs, and where each process spent its time.

    python tools/bench_scaling.py [--jobs 1,2] [--budget 60] [--repeat 1] [--wait-quiet S] [--network NET]
    python tools/bench_scaling.py --jobs 1,4,8,16      # on a machine with 16 cores or more

For each job count N it runs the same campaign (K seed jobs, K = the largest job
count by default: the network's first committed seeds, repeated where there are
fewer; the clean reference ADS, strategy ``all``, continuing after findings) for the
same wall-clock budget: N = 1 in this process (what ``drivefuzz fuzz`` does), N > 1
on a local Dask cluster of N single-threaded workers (``--jobs N``). With K = N the
one job works through the same seeds, a lineage of each in turn, as the N jobs do
at once: the same mix of work. With more seeds than jobs, one job reaches fewer of
them in the budget than N jobs, and seeds differ in what a run costs and in how many
new signatures (so triage reruns) they give. ``--repeat R`` runs R rounds of all the
job counts, interleaved, and prints the median: the load of others on a shared
machine drifts, and each round's N-job point is compared with its own 1-job point.

Work done is counted four ways, from the campaign's journals and the processes' CPU time:

    runs    executions plus triage reruns (the careful driver's replays, the reproduction
            reruns, the shrinking runs): the headline, "work done"
    sim s   the seconds those runs simulated (seeds differ in how long they simulate)
    host    the CPU seconds the simulation hosts spent on those runs (what they cost)
    execs   executions only (what the search counts; a triage rerun is not one)

Runs differ in cost, and N jobs reach other seeds and more new signatures than 1 job in
the same time, so at short budgets the runs, sim s and host figures bracket the work done.

Efficiency = the work rate at N jobs / (N x the work rate at 1 job), the rate over
the campaign's own run (``Campaign.run``); starting the local Dask cluster is a
fixed cost before it and is printed apart ("start-up"). The CPU column is work per
CPU second of all the campaign's processes against the 1-job figure: what the
campaign layer costs in CPU, whatever the load of others on the machine.

On a shared machine the others' work takes CPU from N jobs first. The ESTIMATE line
takes each job's waits for a CPU (the kernel's run-queue delay of the job's thread and
of its simulation host, which run one at a time) out of its wall time: what the point
would have done with a core free for every job. It also takes out the waits that the
campaign's own other processes caused, so it is an upper estimate; the lead figure is
the measured one.

Then, per point, where the time went, one figure per stage (as ``bench_fuzz.py``):
a column per process that runs jobs (the campaign process at N = 1, each Dask worker
otherwise), the execution stages summed over its executions (the simulation-host
stages are the worker waiting on its host), and what is left of its wall time
outside any execution (round set-up, Dask round trips, waiting); then the CPU time
of every process of the campaign: the campaign process (the thread that runs
jobs or follows the journals apart from Dask's threads: client, local scheduler,
nannies), each worker (its task thread apart from Dask's), each simulation host.
The machine's load average is printed before each point: other work on the
machine depresses the figures at N > 1 first.

Prints only; a benchmark, not a test.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import sqlite3
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivefuzz.campaign.fuzz import Campaign, FuzzConfig  # noqa: E402
from drivefuzz.campaign.job import read_journal  # noqa: E402
from drivefuzz.scenario.seed import list_seeds  # noqa: E402
from drivefuzz.scenario.sumofiles import load_scenario  # noqa: E402

from bench_fuzz import STAGES as FUZZ_STAGES  # noqa: E402  (the same stages and labels as bench_fuzz's table)

#: (key of an execution record's timings, label): bench_fuzz's stages, of which the first eight run in the
#: simulation host; crash isolation (the hand-over from the host) comes right after them here
STAGES = FUZZ_STAGES[:8] + sorted(FUZZ_STAGES[8:], key=lambda stage: stage[0] != "isolation")


# ------------------------------------------------------------------------------ processes
def _cpu_s(proc) -> float:
    t = proc.cpu_times()
    return t.user + t.system


def process_cpu(worker_pids: dict[int, str]) -> dict[int, tuple[str, float]]:
    """{pid: (role, CPU seconds so far)} of this process and every process under it."""
    import psutil

    me = psutil.Process()
    out = {me.pid: ("campaign process", _cpu_s(me))}
    for child in me.children(recursive=True):
        try:
            cmd = " ".join(child.cmdline())
            parent = child.ppid()
            if child.pid in worker_pids:
                role = worker_pids[child.pid]
            elif "drivefuzz.sim.simhost" in cmd:
                role = f"simulation host of {worker_pids.get(parent, 'the campaign process')}"
            elif any(p in worker_pids for p in (c.pid for c in child.children())):
                role = "nanny of " + next(worker_pids[c.pid] for c in child.children() if c.pid in worker_pids)
            else:
                role = "other (Dask/multiprocessing helper)"
            out[child.pid] = (role, _cpu_s(child))
        except psutil.Error:  # ended meanwhile
            continue
    return out


def machine_busy() -> float:
    """CPU seconds the whole machine has been busy (all processes, the kernel's own work included)."""
    import psutil

    t = psutil.cpu_times()
    return sum(t) - t.idle - getattr(t, "iowait", 0.0)


def wait_until_quiet(limit_s: float, cores: float = 0.2, window_s: float = 3.0) -> float:
    """Wait (at most ``limit_s``) until the machine runs less than ``cores`` of other work over ``window_s``;
    return the last reading [cores busy]."""
    t_end = time.monotonic() + limit_s
    while True:
        b0, t0 = machine_busy(), time.monotonic()
        time.sleep(window_s)
        busy = (machine_busy() - b0) / (time.monotonic() - t0)
        if busy < cores or time.monotonic() >= t_end:
            return busy


def thread_cpu(runs_jobs: str = "main") -> dict[str, float]:
    """CPU seconds of this process's threads: the thread that runs the jobs (``main``, or ``dask`` for a Dask
    worker's task threads), and the rest (Dask's event loop and its helpers)."""
    import psutil

    main = threading.main_thread().native_id
    if runs_jobs == "main":
        jobs = {main}
        labels = ("main thread (the jobs, following the journals)", "other threads (Dask client, scheduler, nannies)")
    else:
        jobs = {t.native_id for t in threading.enumerate() if "Dask-Default-Threads" in t.name}
        labels = ("task thread (the job)", "other threads (Dask event loop, monitors)")
    split = dict.fromkeys(labels, 0.0)
    for t in psutil.Process().threads():
        split[labels[0] if t.id in jobs else labels[1]] += t.user_time + t.system_time
    return split


def _worker_threads() -> dict[str, float]:
    return thread_cpu("dask")


def run_delay_s(pid: int, tids: list[int] | None = None) -> float:
    """[s] the threads of process ``pid`` (or only ``tids``) have waited on a run queue: runnable, but no CPU was
    free for them (the kernel's schedstat)."""
    task = Path(f"/proc/{pid}/task")
    total = 0
    try:
        tids = tids if tids is not None else [int(t.name) for t in task.iterdir()]
    except OSError:
        return 0.0
    for tid in tids:
        try:
            total += int((task / str(tid) / "schedstat").read_text().split()[1])
        except (OSError, ValueError, IndexError):
            continue
    return total / 1e9


def _job_thread_delay(dask: bool = True) -> tuple[int, float]:
    """(pid, run delay of the thread that runs jobs): a Dask worker's task thread (none before its first task),
    or this process's main thread."""
    if dask:
        tids = [t.native_id for t in threading.enumerate() if "Dask-Default-Threads" in t.name]
    else:
        tids = [threading.main_thread().native_id]
    return os.getpid(), run_delay_s(os.getpid(), tids)


def chain_delays(names: dict[int, str], client=None) -> dict[str, float]:
    """{job-running process: [s] its job thread and its simulation host have waited for a CPU}. Such a pair runs
    one at a time (each waits on the other), so on a machine with a core free for every job they would not wait."""
    import psutil

    jobs = dict(client.run(_job_thread_delay).values()) if client is not None else dict([_job_thread_delay(False)])
    out = {}
    for pid, delay in jobs.items():
        try:
            hosts = [c.pid for c in psutil.Process(pid).children() if "drivefuzz.sim.simhost" in " ".join(c.cmdline())]
        except psutil.Error:
            hosts = []
        out[names.get(pid, f"pid {pid}")] = delay + sum(run_delay_s(h) for h in hosts)
    return out


class _Timed:
    """Wall seconds the campaign process spends in one of its methods (bench-only wrapper)."""

    def __init__(self, fn):
        self.fn, self.seconds, self.calls = fn, 0.0, 0

    def __call__(self, *a, **kw):
        t0 = time.perf_counter()
        try:
            return self.fn(*a, **kw)
        finally:
            self.seconds += time.perf_counter() - t0
            self.calls += 1


# ------------------------------------------------------------------------------ one point
def run_point(jobs: int, seeds, budget: float, workdir: Path, rep: int = 0) -> dict:
    cfg = FuzzConfig(cycles=1000, population=8, continue_after_finding=True, seed=1, budget_s=budget)
    out = workdir / f"jobs{jobs}-{rep}"
    campaign = Campaign(out, seeds, cfg)
    campaign.poll = poll = _Timed(campaign.poll)
    stops: list[float] = []
    request_stop = campaign.request_stop
    campaign.request_stop = lambda: (stops.append(time.monotonic()), request_stop())
    load = os.getloadavg()
    point: dict = {"jobs": jobs, "load": load, "rep": rep}
    t0 = time.monotonic()
    if jobs == 1:
        names = {os.getpid(): "campaign process"}
        cpu0, busy0, delay0, threads0 = process_cpu({}), machine_busy(), chain_delays(names), thread_cpu()
        t_run = time.monotonic()
        campaign.run()
        t_end = time.monotonic()
        cpu1, busy1, delay1, threads1 = process_cpu({}), machine_busy(), chain_delays(names), thread_cpu()
    else:
        from drivefuzz.campaign.cluster import dask_client

        with dask_client("local", jobs=jobs) as client:
            pids = client.run(os.getpid)
            names = {pid: f"worker {i + 1}" for i, pid in enumerate(sorted(pids.values()))}
            wt0 = client.run(_worker_threads)
            cpu0, busy0, delay0 = process_cpu(names), machine_busy(), chain_delays(names, client)
            threads0 = thread_cpu()  # here: Dask's threads in this process live as long as the cluster
            t_run = time.monotonic()
            campaign.run(client=client)
            t_end = time.monotonic()
            cpu1, busy1, delay1 = process_cpu(names), machine_busy(), chain_delays(names, client)
            threads1 = thread_cpu()
            wt1 = client.run(_worker_threads)
            point["worker_threads"] = {names[pids[a]]: {k: v - wt0.get(a, {}).get(k, 0.0) for k, v in wt1[a].items()}
                                       for a in wt1 if a in pids}
    point["wall"] = t_end - t_run
    point["delay"] = {k: max(v - delay0.get(k, 0.0), 0.0) for k, v in delay1.items()}
    point["startup"] = t_run - t0
    # --jobs 1 stops by the budget check between executions, not by STOP
    point["tail"] = t_end - stops[0] if stops else None
    point["cpu"] = {pid: (role, cpu - cpu0.get(pid, (role, 0.0))[1]) for pid, (role, cpu) in cpu1.items()}
    # what the rest of the machine ran meanwhile: [cores], on average over the point
    point["others"] = max(busy1 - busy0 - sum(cpu for _, cpu in point["cpu"].values()), 0.0) / point["wall"]
    point["threads"] = {k: threads1[k] - threads0.get(k, 0.0) for k in threads1}
    point["poll"] = (poll.seconds, poll.calls)
    point["names"] = names
    point.update(read_work(out))
    return point


def read_work(out: Path) -> dict:
    """Executions, runs, simulated seconds, and the stage timings summed per process, from the journals."""
    recs = [r for path in sorted((out / "jobs").glob("*/journal.jsonl")) for r in read_journal(path)
            if r.get("event") == "end"]
    db = sqlite3.connect(out / "index.sqlite")
    indexed = db.execute("SELECT COUNT(*) FROM executions").fetchone()[0]
    db.close()
    stages: dict[int, dict[str, float]] = {}
    for r in recs:
        acc = stages.setdefault(r["pid"], {})
        for k, v in (r.get("timings") or {}).items():
            acc[k] = acc.get(k, 0.0) + float(v)
    return {"execs": len(recs), "indexed": indexed, "runs": sum(r.get("runs", 1) for r in recs),
            "sim_s": sum(r.get("sim_s", 0.0) for r in recs), "stages": stages,
            "runs_by_pid": {pid: sum(r.get("runs", 1) for r in recs if r["pid"] == pid) for pid in stages},
            "findings": len([p for p in (out / "findings").iterdir() if not p.name.startswith(".")]),
            "incidents": len([p for p in (out / "incidents").iterdir() if not p.name.startswith(".")])}


# ------------------------------------------------------------------------------ printing
def _host_cpu(p: dict) -> float:
    return sum(cpu for role, cpu in p["cpu"].values() if role.startswith("simulation host"))


def _all_cpu(p: dict) -> float:
    return sum(cpu for _, cpu in p["cpu"].values())


def print_point(p: dict) -> None:
    n = p["jobs"]
    print(f"\n=== jobs={n} (round {p['rep'] + 1}): {p['execs']} executions, {p['runs']} runs "
          f"(+{p['runs'] - p['execs']} triage reruns), {p['sim_s']:.0f} s simulated, in {p['wall']:.1f} s "
          f"(+ {p['startup']:.1f} s cluster start-up before it); {p['findings']} findings, {p['incidents']} incidents; "
          f"load average before: {p['load'][0]:.2f} {p['load'][1]:.2f} {p['load'][2]:.2f}")
    print(f"    the rest of the machine (other users, the kernel) kept {p['others']:.2f} cores busy meanwhile")
    if p.get("delay"):
        print("    waiting for a CPU (run queue), each job's thread and its simulation host together: "
              + ", ".join(f"{k} {v:.1f} s" for k, v in sorted(p["delay"].items())))
    if p["indexed"] != p["execs"]:
        print(f"    (the index holds {p['indexed']} executions, the journals {p['execs']})")
    if p["runs"]:
        print(f"    per run: {1000 * _host_cpu(p) / p['runs']:.0f} ms of simulation-host CPU, "
              f"{p['sim_s'] / p['runs']:.1f} s simulated; all processes: {1000 * _all_cpu(p) / p['runs']:.0f} ms CPU")
    if p["tail"] is not None:
        print(f"    the budget ran out {p['tail']:.1f} s before the last job returned (its running execution and "
              f"triage finish first)")
    print_stages(p)
    print_cpu(p)


def _columns(p: dict) -> list[tuple[str, list[float]]]:
    """(heading, a figure per stage, then in and outside executions) per job-running process; with more
    than four of them, the mean, the least and the most over the workers instead."""
    per = []
    for pid in sorted(p["stages"], key=lambda pid: p["names"].get(pid, str(pid))):
        st = p["stages"][pid]
        figures = [sum(st.get(k, 0.0) for k, _ in STAGES[:8])] + [st.get(k, 0.0) for k, _ in STAGES]
        inside = sum(st.values())
        per.append((p["names"].get(pid, f"pid {pid}"), figures + [inside, p["wall"] - inside]))
    if len(per) <= 4:
        return per
    rows = list(zip(*(f for _, f in per)))
    return [(f"mean of {len(per)}", [sum(r) / len(r) for r in rows]), ("least", [min(r) for r in rows]),
            ("most", [max(r) for r in rows])]


def print_stages(p: dict) -> None:
    cols = _columns(p)
    labels = [label for _, label in STAGES[:8]] + ["  (the above: in the simulation host)"] + \
        [label for _, label in STAGES[8:]] + ["in executions", "outside executions (set-up, Dask, idle)"]
    order = list(range(1, 9)) + [0] + list(range(9, len(STAGES) + 1)) + [len(STAGES) + 1, len(STAGES) + 2]
    print(f"  where each job-running process spent its wall time [s] ({p['wall']:.1f} s each):")
    print(f"    {'stage':<42}" + "".join(f"{h:>18}" for h, _ in cols))
    for label, i in zip(labels, order):
        print(f"    {label:<42}" + "".join(f"{f[i]:>18.2f}" for _, f in cols))


def print_cpu(p: dict) -> None:
    print(f"  CPU time of each process [s] (share of the {p['wall']:.1f} s):")
    procs = sorted((role, cpu) for role, cpu in p["cpu"].values() if cpu >= 0.005)
    if p["jobs"] > 4:  # one line per kind of process
        kinds: dict[str, list[float]] = {}
        for role, cpu in procs:
            kind = ("workers" if role.startswith("worker") else "their simulation hosts"
                    if role.startswith("simulation host of worker") else role)
            kinds.setdefault(kind, []).append(cpu)
        for kind, cpus in kinds.items():
            spread = f"  (each {min(cpus):.2f} to {max(cpus):.2f})" if len(cpus) > 1 else ""
            print(f"    {kind + (f' ({len(cpus)})' if len(cpus) > 1 else ''):<48}{sum(cpus):>8.2f}  "
                  f"{100 * sum(cpus) / p['wall']:>5.1f} %{spread}")
    else:
        for role, cpu in procs:
            print(f"    {role:<48}{cpu:>8.2f}  {100 * cpu / p['wall']:>5.1f} %")
    for name, cpu in p["threads"].items():
        print(f"      campaign process, {name:<56}{cpu:>8.2f}")
    splits = sorted(p.get("worker_threads", {}).items())
    if len(splits) > 4:
        splits = [(f"workers (sum of {len(splits)})", {k: sum(s[k] for _, s in splits) for k in splits[0][1]})]
    for worker, split in splits:
        for name, cpu in split.items():
            print(f"      {worker}, {name:<64}{cpu:>8.2f}")
    secs, calls = p["poll"]
    print(f"      campaign process: following the journals + indexing: {secs:.2f} s wall in {calls} polls")


def quiet_rates(p: dict) -> dict[str, float]:
    """Work per second that ``p`` would have done had no job waited for a CPU: each job's work over the wall time
    less its run-queue waits (an estimate for a machine with a core free for every job; it also takes out the
    waits that the campaign's own other processes caused)."""
    rates = {"runs": 0.0, "host": 0.0}
    pid_of = {name: pid for pid, name in p["names"].items()}
    for chain, delay in p.get("delay", {}).items():
        own_wall = max(p["wall"] - delay, 1e-9)
        rates["runs"] += p["runs_by_pid"].get(pid_of.get(chain), 0) / own_wall
        rates["host"] += sum(cpu for role, cpu in p["cpu"].values()
                             if role in (f"simulation host of {chain}", f"simulation host of the {chain}")) / own_wall
    return rates


def efficiencies(p: dict, base: dict) -> dict[str, float]:
    """Work rate at ``p``'s job count over that many times the one-job rate of ``base``, by each measure of work
    (``host``: the simulation hosts' CPU seconds); ``cpu``: runs per CPU second of all the campaign's processes,
    over the one-job figure."""
    n = p["jobs"]
    work = {"runs": p["runs"], "sim_s": p["sim_s"], "execs": p["execs"], "host": _host_cpu(p)}
    one = {"runs": base["runs"], "sim_s": base["sim_s"], "execs": base["execs"], "host": _host_cpu(base)}
    eff = {k: (work[k] / p["wall"]) / (n * one[k] / base["wall"]) if one[k] else float("nan") for k in work}
    eff["cpu"] = (p["runs"] / _all_cpu(p)) / (base["runs"] / _all_cpu(base)) if base["runs"] else float("nan")
    q, q1 = quiet_rates(p), quiet_rates(base)
    for k in q:
        eff[f"quiet_{k}"] = q[k] / (n * q1[k]) if q1[k] else float("nan")
    return eff


def print_summary(rows: list[dict]) -> None:
    print(f"\n{'round':>5} {'jobs':>4} {'load':>5} {'others':>6} {'execs':>6} {'runs':>6} {'sim s':>7} {'wall s':>7} "
          f"{'runs/h':>8}   efficiency: {'work (runs)':>11} {'sim s':>6} {'host CPU':>8} {'execs only':>10}   "
          f"{'CPU':>5}")
    effs: dict[int, list[dict[str, float]]] = {}
    for r in rows:
        base = next((b for b in rows if b["jobs"] == 1 and b["rep"] == r["rep"]), None)
        eff = efficiencies(r, base) if base else dict.fromkeys(
            ("runs", "sim_s", "host", "execs", "cpu", "quiet_runs", "quiet_host"), math.nan)
        effs.setdefault(r["jobs"], []).append(eff)
        print(f"{r['rep'] + 1:>5} {r['jobs']:>4} {r['load'][0]:>5.2f} {r['others']:>6.2f} {r['execs']:>6} "
              f"{r['runs']:>6} {r['sim_s']:>7.0f} {r['wall']:>7.1f} {3600 * r['runs'] / r['wall']:>8.0f}   {'':>11} "
              f"{eff['runs']:>11.2f} {eff['sim_s']:>6.2f} {eff['host']:>8.2f} {eff['execs']:>10.2f}   "
              f"{eff['cpu']:>5.2f}")
    print("\nefficiency = the work rate at N jobs / (N x the rate at 1 job in the same round), over each campaign's "
          "run (cluster start-up apart). Work (the headline) = runs: executions plus triage reruns (the careful "
          "driver's replays, reproduction reruns, shrinking); 'sim s' weighs each run by the seconds it simulated, "
          "'host CPU' by the CPU its simulation host spent on it (runs differ in cost, and N jobs reach other seeds "
          "and more new signatures than 1 in the same time: the three bracket the work done); 'execs only' counts "
          "executions alone. CPU = runs per CPU second of all the campaign's processes relative to 1 job: the "
          "campaign layer's CPU cost, which other users' load does not change. load = the 1-minute load average "
          "before the point (it still holds the previous point's own load); others = the cores that the rest of "
          "the machine (other users, the kernel) kept busy during the point, on average: others' work depresses "
          "N > 1 first.")
    import statistics

    for n, es in sorted(effs.items()):
        if n == 1:
            continue
        med = {k: statistics.median(e[k] for e in es) for k in es[0]}
        what = "median of " + str(len(es)) + " rounds" if len(es) > 1 else "1 round"
        others = sorted(r["others"] for r in rows if r["jobs"] in (1, n))
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        what += (f"; others kept {others[0]:.2f} to {others[-1]:.2f} of the {cores} cores busy during the points"
                 + (": a busy machine, the figure is depressed" if others[-1] > 0.1 * (cores or 1) else ""))
        print(f"RESULT jobs={n}: efficiency {med['runs']:.2f} in work done (runs), {med['sim_s']:.2f} in simulated "
              f"seconds, {med['host']:.2f} in simulation-host CPU, {med['execs']:.2f} in executions only; "
              f"CPU {med['cpu']:.2f} ({what})")
        print(f"ESTIMATE jobs={n} on a quiet machine (each job's waits for a CPU taken out of its wall time): "
              f"efficiency {med['quiet_runs']:.2f} in work done (runs), {med['quiet_host']:.2f} in simulation-host "
              f"CPU")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", default="1,2", help="comma-separated job counts [1,2]")
    ap.add_argument("--budget", type=float, default=60.0, help="wall seconds per point [60]")
    ap.add_argument("--repeat", type=int, default=1,
                    help="rounds of all the job counts, interleaved (1,2,1,2,...): the median is printed [1]")
    ap.add_argument("--seeds", type=int, default=0, metavar="K",
                    help="seed jobs in every point [the largest job count]: the network's seeds, repeated where "
                         "there are fewer")
    ap.add_argument("--wait-quiet", type=float, default=0.0, metavar="S",
                    help="before each point, wait up to S seconds for the machine to be quiet (others < 0.2 cores)")
    ap.add_argument("--network", default=str(ROOT / "networks" / "town.net.xml"))
    args = ap.parse_args()
    counts = [int(x) for x in args.jobs.split(",")]
    name = Path(args.network).name.split(".")[0]
    seeds = [load_scenario(p) for p in list_seeds(ROOT / "seeds" / name)]
    if not seeds:
        sys.exit(f"no seeds in seeds/{name}/")
    n_seeds = args.seeds or max(counts)
    seeds = [seeds[i % len(seeds)] for i in range(n_seeds)]  # a repeated seed is its own job (own random streams)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"machine: {cores} cores; network {name}, {n_seeds} seed jobs, {args.budget:.0f} s per point, "
          f"jobs {','.join(map(str, counts))}, {args.repeat} round(s)")
    if max(counts) > (cores or 1):
        print(f"NOTE: {max(counts)} jobs on {cores} cores: the jobs share cores, efficiency falls below 1 by design")
    # this process runs the one-job points: warm it as a local cluster's workers are warmed before they register
    from drivefuzz.campaign.hosts import warm_worker

    warm_worker()
    workdir = Path(tempfile.mkdtemp(prefix="bench-scaling-"))
    rows = []
    try:
        for rep in range(args.repeat):
            for n in counts:
                if args.wait_quiet > 0:
                    busy = wait_until_quiet(args.wait_quiet)
                    print(f"\n(waited for a quiet machine: {busy:.2f} cores busy just before the point)")
                r = run_point(n, seeds, args.budget, workdir, rep)
                rows.append(r)
                print_point(r)
                sys.stdout.flush()
                shutil.rmtree(workdir / f"jobs{n}-{rep}", ignore_errors=True)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    print_summary(rows)


if __name__ == "__main__":
    main()
