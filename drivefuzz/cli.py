"""The ``drivefuzz`` command. The only module that turns errors into exit codes.

Exit codes: 0 ran clean; 1 misbehaviour found (``fuzz``, ``run``) or not
reproduced (``replay``); 2 usage or input error (one line on stderr, no
traceback); 3 the simulator or a plugin failed (or, in a campaign, only
internal errors were found); 130 aborted by a second Ctrl-C.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import gc
import json
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import click

import drivefuzz
from drivefuzz.errors import DriveFuzzError, InvalidConfig, InvalidInput

EXIT_CLEAN, EXIT_FOUND, EXIT_INPUT, EXIT_INTERNAL = 0, 1, 2, 3
EXIT_ABORTED = 130  # a second Ctrl-C: what was finished is saved; --resume continues


def _fail(msg: str, code: int) -> None:
    click.echo(f"drivefuzz: error: {' '.join(str(msg).split())}", err=True)
    sys.exit(code)


def handle_errors(fn):
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except InvalidInput as exc:
            _fail(str(exc), EXIT_INPUT)
        except DriveFuzzError as exc:
            _fail(str(exc), EXIT_INTERNAL)
    return wrapper


@functools.cache
def _freeze_heap_at_exit() -> None:
    """At interpreter exit, move every object to the permanent generation: the final collections of
    the shutdown then skip the road map's hundred thousand objects instead of walking them (Berlin,
    3,641 edges: 0.23 of a 1.4 s ``drivefuzz run``). Registered once per process; nothing is freed
    earlier than before."""
    atexit.register(gc.freeze)


class _Main(click.Group):
    """The command group: click's usage errors in one line, like every other input error."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        _freeze_heap_at_exit()
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.UsageError as exc:
            where = exc.ctx.command_path if exc.ctx is not None else "drivefuzz"
            _fail(f"{where}: {exc.format_message()} (see '{where} --help')", EXIT_INPUT)
        except click.ClickException as exc:  # e.g. click.FileError
            _fail(exc.format_message(), EXIT_INPUT)
        except click.Abort:  # Ctrl-C outside a campaign
            click.echo("aborted", err=True)
            sys.exit(EXIT_ABORTED)
        sys.exit(rv if isinstance(rv, int) else EXIT_CLEAN)


class _Seconds(click.ParamType):
    """A positive, finite number of seconds, at most a day."""

    name = "SECONDS"

    def convert(self, value, param, ctx):
        try:
            x = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number of seconds", param, ctx)
        if not (0.0 < x <= MAX_SECONDS):
            self.fail(f"{value} is not a number of seconds in (0, {MAX_SECONDS:g}]", param, ctx)
        return x


MAX_SECONDS = 86400.0


def _ads_from_the_command_line(_ctx, _param, value):
    """An ADS named by ``--ads`` is the user's word: a ``mymodule:Class`` in the current folder is found
    (the security rule of issue 15 keeps names read from data files to installed plugins)."""
    from drivefuzz.ads import allow_current_folder

    for name in (value if isinstance(value, tuple) else [value] if value else []):
        allow_current_folder(name)
    return value


#: at most this many local workers per CPU: more only queue, each holding a SUMO and semaphores
JOBS_PER_CPU = 4


def parse_kv(pairs: Sequence[str], option: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, raw = pair.partition("=")
        if not sep or not key:
            raise InvalidConfig(option, pair, "expected KEY=VALUE", "e.g. fault=speeding")
        try:
            out[key] = json.loads(raw)
        except (json.JSONDecodeError, RecursionError):
            out[key] = raw
    return out


def load_config_file(path: str | None) -> dict[str, Any]:
    """A TOML or JSON file with sections ``[fuzz]``, ``[oracles.NAME]``, ``[mutation]``, ``[quality]``, ``[ads]``."""
    from drivefuzz.campaign.configfile import load_config_file as load

    return load(path)


def _writable_dir(path: str | Path, option: str) -> Path:
    """Create ``path`` (and its parents) now: an output folder that cannot be made is an input error."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".drivefuzz-probe-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as exc:
        raise InvalidConfig(option, str(path), f"cannot write there ({exc.strerror or exc})",
                            "a folder you may create and write") from None
    return path


def oracle_options(fn):
    fn = click.option("--oracle", "oracle_kv", multiple=True, metavar="NAME.KEY=VALUE",
                      help="Set an oracle threshold, e.g. speeding.tolerance=1.0.")(fn)
    fn = click.option("--no-oracle", "no_oracle", multiple=True, metavar="NAME", help="Disable an oracle.")(fn)
    fn = click.option("--config", "config_file", type=click.Path(dir_okay=False),
                      help="TOML/JSON file with [fuzz], [oracles.NAME], [mutation], [quality], [ads] sections.")(fn)
    return fn


def _oracle_settings(config: dict[str, Any], kv, disabled, source: str | None = None):
    """The file's oracle settings (checked as the file's), then the command line's on top."""
    from drivefuzz.oracle import OracleSettings, parse_oracle_options

    base = config.get("oracles", {})
    if source and base:
        OracleSettings(settings=base).instantiate(source=source)
    settings = parse_oracle_options(kv, disabled, base=base)
    settings.instantiate()  # validate names and values now, not in the middle of a campaign
    return settings


@click.group(cls=_Main, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(drivefuzz.__version__, prog_name="drivefuzz")
def main() -> None:
    """drivefuzz: find safety-critical misbehaviour of automated-driving controllers in SUMO."""


# ----------------------------------------------------------------------------- run
def _risk_line(trace) -> str:
    """'risk 0.42: time-to-collision 1.9 s with v3 at t=12.3 s, gap 0.8 m with p0, ...' (absolute: no baseline)."""
    from drivefuzz.search.risk import risk_score

    r = risk_score(trace)
    t = trace["t"]
    parts = []
    for name, value, unit, frame, actor in (("time-to-collision", r.ttc, "s", r.ttc_frame, r.ttc_actor),
                                             ("gap", r.gap, "m", r.gap_frame, r.gap_actor),
                                             ("post-encroachment time", r.pet, "s", r.pet_frame, r.pet_actor)):
        if value is not None:
            parts.append(f"{name} {value:.2f} {unit}" + (f" with {actor}" if actor else "")
                         + (f" at t={float(t[frame]):.1f} s" if frame is not None else ""))
    parts.append(f"grip use {r.grip:.2f}")
    return f"risk {r.score:.2f} (the default feedback, without a baseline): " + ", ".join(parts)


@main.command()
@click.argument("scenario", type=click.Path())
@click.option("--gui", is_flag=True, help="Show the run in sumo-gui (through traci; same code path).")
@click.option("--ads", "ads_name", default=None, callback=_ads_from_the_command_line, help="ADS plugin (default: the scenario's).")
@click.option("--ads-option", multiple=True, metavar="K=V", help="ADS option, e.g. fault=speeding.")
@click.option("--trace", "trace_out", type=click.Path(file_okay=False), help="Save the trace (Parquet) here.")
@click.option("--quality", "show_quality", is_flag=True,
              help="Also print the paper's driving-quality score (what --feedback paper uses).")
@oracle_options
@handle_errors
def run(scenario, gui, ads_name, ads_option, trace_out, show_quality, oracle_kv, no_oracle, config_file):
    """Run one SCENARIO (a scenario folder or its scenario.json) and print its outcome.

    A run without misbehaviour prints how close it came: its risk (what the fuzzer's default feedback
    maximises, docs/feedback.md) with its nearest time-to-collision, gap and crossing."""
    from drivefuzz.ads import check_trusted
    from drivefuzz.errors import InvalidScenario, SimulationError
    from drivefuzz.sim.execute import execute
    from drivefuzz.scenario import AdsSpec
    from drivefuzz.scenario.sumofiles import load_scenario

    config = load_config_file(config_file)
    sc = load_scenario(scenario)
    _check_runnable(sc, _manifest_of(scenario))
    if not ads_name:  # the scenario's own ADS: imported only if installed (a scenario folder may come from anyone)
        check_trusted(sc.ads.name, _manifest_of(scenario), "ads.name")
    if ads_name or ads_option:
        opts = dict(sc.ads.options) if not ads_name or ads_name == sc.ads.name else {}
        opts.update(parse_kv(ads_option, "--ads-option"))
        try:
            sc = sc.model_copy(update={"ads": AdsSpec(name=ads_name or sc.ads.name, options=opts)})
        except ValueError as exc:  # pydantic: an option value that is not a bool, number or string
            raise InvalidConfig("--ads-option", None, str(exc).splitlines()[-1].strip()) from None
    settings = _oracle_settings(config, oracle_kv, no_oracle, source=config_file)
    if trace_out:
        _writable_dir(trace_out, "--trace")
    try:
        ex = execute(sc, oracles=settings.instantiate(), gui=gui)
    except SimulationError as exc:
        if not str(exc).startswith("SUMO failed to start"):
            raise
        # drivefuzz checked the scenario and its network; what SUMO still refuses is in the user's files
        reason = str(exc).partition(": ")[2] or str(exc)
        raise InvalidScenario(_manifest_of(scenario), None, f"SUMO refuses this scenario or its network "
                              f"{Path(sc.network).name} ({reason})") from None
    click.echo(f"{sc.name}: {ex.termination.value} after {ex.trace.n_frames} frames "
               f"({ex.trace.n_frames * sc.sim.step_length:.1f} s simulated, {ex.wall_time:.2f} s wall)")
    for m in ex.misbehaviors:
        click.echo(f"  MISBEHAVIOR {m.oracle}/{m.kind} at frame {m.frame} (t={m.time:.2f} s)"
                   f"{' with ' + ', '.join(m.actors) if m.actors else ''}")
    if not ex.misbehaviors:
        click.echo(f"  {_risk_line(ex.trace)}")
        if show_quality:  # scipy's filters: 0.4 s to import, so only when asked
            from drivefuzz.search.quality import score_trace

            q = score_trace(ex.trace)
            click.echo(f"  quality score {q.score:.2f} ({json.dumps({k: v for k, v in q.as_dict().items() if k in ('ha', 'hb', 'ht', 'os', 'us', 'md')})})")
    if trace_out:
        try:
            ex.trace.save(trace_out)
        except OSError as exc:
            raise InvalidConfig("--trace", trace_out, f"cannot write there ({exc.strerror or exc})") from None
        click.echo(f"  trace saved to {trace_out}")
    sys.exit(EXIT_FOUND if ex.misbehaviors else EXIT_CLEAN)


def _check_runnable(sc, source: str) -> None:
    """What SUMO refuses at run time but a well-formed scenario may hold (see validate.check_departure)."""
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.validate import check_departure

    check_departure(sc, load_roadmap(sc.network_path()), source)


def _manifest_of(scenario: str | Path) -> str:
    """The file a scenario's fields come from: its scenario.json (or the JSON file itself)."""
    p = Path(scenario)
    return str(p / "scenario.json") if p.is_dir() else str(p)


# ---------------------------------------------------------------------------- seed
@main.command()
@click.argument("network", type=click.Path())
@click.option("-n", "count", default=8, show_default=True, type=click.IntRange(1, 1000), help="How many seeds.")
@click.option("-o", "out", type=click.Path(file_okay=False), help="Output folder (default seeds/<network>/).")
@click.option("--seed", "rng_seed", default=0, show_default=True, type=click.IntRange(min=0), help="RNG seed.")
@click.option("--no-verify", is_flag=True, help="Skip the dry run of the reference ADS.")
@click.option("--force", is_flag=True, help="Write into an output folder that is not empty (replacing 000, 001...).")
@handle_errors
def seed(network, count, out, rng_seed, no_verify, force):
    """Write COUNT seed missions for NETWORK, each verified by a dry run of the reference ADS."""
    from drivefuzz.scenario.seed import generate_seeds
    from drivefuzz.scenario.sumofiles import write_scenario
    from drivefuzz.scenario.validate import load_network, require_car_roads

    rmap = load_network(network)
    require_car_roads(rmap)
    out = Path(out or Path("seeds") / rmap.name)
    if out.exists() and not out.is_dir():
        raise InvalidConfig("-o", str(out), "is a file", "a new or empty folder")
    if out.is_dir() and any(out.iterdir()) and not force:
        raise InvalidConfig("-o", str(out), "folder is not empty (its seeds would be overwritten)",
                            "a new or empty folder, or --force to replace them")
    made = not out.exists()
    _writable_dir(out, "-o")
    verify = _DryRuns()
    seeds = generate_seeds(network, count, rng_seed, verify=None if no_verify else verify,
                           log=lambda s: click.echo(f"  {s}"))
    if not seeds:
        if made:
            with contextlib.suppress(OSError):
                out.rmdir()  # a refused network leaves nothing behind
        raise InvalidConfig(network, None, f"no mission on this network passed the dry run{verify.why()}",
                            "a network with connected roads that passenger cars may drive")
    for i, sc in enumerate(seeds):
        write_scenario(sc, out / f"{i:03d}")
    click.echo(f"wrote {len(seeds)} seed(s) to {out}")


class _DryRuns:
    """The reference ADS's dry run of a candidate seed (:func:`drivefuzz.sim.verify.dry_run`), counting why
    candidates were rejected, so that a network where none passes is refused in one line that says why."""

    def __init__(self):
        self.rejected: dict[str, int] = {}

    def __call__(self, scenario):
        from drivefuzz.sim.verify import dry_run

        ok, why = dry_run(scenario)
        if not ok:
            key = why.split(" at frame ")[0].split(" (")[0]
            self.rejected[key] = self.rejected.get(key, 0) + 1
        return ok, why

    def why(self) -> str:
        """`` (21 candidates rejected: 15 lane_invasion/opposite_lane, 6 mission/timeout)``, or nothing."""
        if not self.rejected:
            return ""
        top = sorted(self.rejected.items(), key=lambda kv: (-kv[1], kv[0]))
        return (f" ({sum(self.rejected.values())} candidates rejected: "
                + ", ".join(f"{n} {k}" for k, n in top[:3]) + (", ..." if len(top) > 3 else "") + ")")


# ---------------------------------------------------------------------------- fuzz
@main.command()
@click.argument("network", type=click.Path(), required=False)
@click.option("-o", "out", type=click.Path(file_okay=False), help="Output directory (default: new under ./drivefuzz-out/).")
@click.option("--resume", "resume_dir", type=click.Path(file_okay=False), help="Continue the campaign in this directory.")
@click.option("--strategy", type=click.Choice(["all", "congestion", "entropy", "instability", "maneuver", "mix"]),
              default=None, help="Mutation strategy [all].")
@click.option("--cycles", type=click.IntRange(min=1), default=None, help="Cycles of one lineage at most [10].")
@click.option("--population", type=click.IntRange(min=1), default=None, help="Mutants per cycle [8].")
@click.option("--budget", default=None, help="Wall-clock budget of this run, e.g. 90s, 10m, 2h.")
@click.option("--max-execs", type=click.IntRange(min=1), default=None, help="Stop after N executions (per run: a resume runs N more).")
@click.option("--seed", "rng_seed", type=click.IntRange(min=0), default=None, help="Campaign RNG seed [0].")
@click.option("--seeds", "seeds_dir", type=click.Path(file_okay=False), help="Seed folder (default: <network's folder>/../seeds/<network>/, else ./seeds/<network>/).")
@click.option("--ads", "ads_name", default=None, callback=_ads_from_the_command_line, help="ADS plugin under test [ego].")
@click.option("--ads-option", multiple=True, metavar="K=V", help="ADS option, e.g. fault=speeding.")
@click.option("--feedback", type=click.Choice(["risk", "paper", "random", "coverage", "product"]), default=None,
              help="How successors are chosen: the risk score, the paper's driving-quality score, at random, new "
                   "coverage cells first (risk breaks ties), or risk x (1 + new cells) [risk]; docs/coverage.md.")
@click.option("--no-feedback", is_flag=True, help="Same as --feedback random (the paper's baseline).")
@click.option("--single-pass", is_flag=True, help="One lineage per seed, then stop (the default without a budget).")
@click.option("--report-all", is_flag=True,
              help="Count incidents (not the ego's fault) as findings too, and measure their reproduction rates.")
@click.option("--report", "write_html", is_flag=True, help="Write OUT/report.html and report.md at the end.")
@click.option("--continue-after-finding", is_flag=True, help="Keep fuzzing a seed after a finding.")
@click.option("--shrink", type=click.IntRange(0, 1000), default=None,
              help="Executions spent shrinking each new finding to a minimal reproducer, 0: none [10].")
@click.option("--time-limit", type=_Seconds(), default=None, help="Simulated seconds per execution (default: the seed's).")
@click.option("--jobs", "-j", type=click.IntRange(1, JOBS_PER_CPU * (os.cpu_count() or 1)), default=None, help="Seed campaigns at once on a local Dask cluster [1].")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run the jobs on an existing Dask scheduler (tcp://HOST:PORT or a scheduler.json).")
@click.option("--exec-timeout", type=_Seconds(), default=None, help="Wall seconds before an execution is a 'hang' [300].")
@click.option("--no-isolation", is_flag=True, help="Run executions in this process (no crash isolation; for debugging).")
@oracle_options
@handle_errors
def fuzz(network, out, resume_dir, strategy, cycles, population, budget, max_execs, rng_seed, seeds_dir, ads_name,
         ads_option, feedback, no_feedback, single_pass, report_all, write_html, continue_after_finding, shrink, time_limit, jobs, scheduler, exec_timeout, no_isolation,
         oracle_kv, no_oracle, config_file):
    """Fuzz the ADS on NETWORK (a .net.xml). Exit 0: nothing found; 1: misbehaviour found; 2: bad input."""
    from drivefuzz.ads import check_trusted
    from drivefuzz.campaign.fuzz import Campaign, load_campaign, parse_duration
    from drivefuzz.campaign.status import StatusPrinter

    argv = ["drivefuzz", *sys.argv[1:]]
    if resume_dir:
        seeds, cfg, argv = load_campaign(resume_dir)
        manifest = str(Path(resume_dir) / "manifest.json")
        if ads_name is not None and ads_name != cfg.ads.name:
            raise InvalidConfig("--ads", ads_name, f"the campaign in {resume_dir} fuzzes {cfg.ads.name!r}",
                                f"--ads {cfg.ads.name} (to trust it), or a new campaign")
        check_trusted(cfg.ads.name, manifest, "config.ads.name", command_line=ads_name)
        out_dir = Path(resume_dir)
        if budget is not None:
            cfg.budget_s = parse_duration(budget)
        if max_execs is not None:
            cfg.max_execs = max_execs
        if report_all:
            cfg.reproduce_incidents = True
    else:
        if not network:
            raise InvalidConfig("fuzz", "NETWORK", "missing", "a .net.xml file, or --resume OUT")
        from drivefuzz.scenario.validate import load_network

        load_network(network)  # a bad network is the first thing to report
        config = load_config_file(config_file)
        cfg = _fuzz_config(config, config_file, dict(
            cycles=cycles, population=population, strategy=strategy, seed=rng_seed, budget=budget,
            max_execs=max_execs, feedback=feedback, no_feedback=no_feedback, single_pass=single_pass,
            continue_after_finding=continue_after_finding, shrink=shrink, time_limit=time_limit,
            no_isolation=no_isolation, exec_timeout=exec_timeout, report_all=report_all), ads_name, ads_option,
            oracle_kv, no_oracle)
        from drivefuzz.ads import load_ads

        load_ads(cfg.ads.name, cfg.ads.options)  # fail now on an unknown ADS or option
        out_dir = Path(out) if out else Path("drivefuzz-out") / time.strftime(f"{Path(network).name.split('.')[0]}-%Y%m%d-%H%M%S")
        if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
            raise InvalidConfig("-o", str(out_dir), "output directory exists and is not empty",
                                "a new directory, or --resume to continue it")
    from drivefuzz.campaign.cluster import BATCH_SYSTEMS

    if scheduler in BATCH_SYSTEMS:
        raise InvalidConfig("--scheduler", scheduler, "batch systems are run by 'drivefuzz campaign'",
                            "tcp://HOST:PORT or a scheduler.json here; where = \"slurm\" in a campaign file")
    _writable_dir(out_dir, "-o")
    if not resume_dir:
        seeds = _seeds_for(network, seeds_dir)
    campaign = Campaign(out_dir, seeds, cfg, argv)
    where = scheduler or ("local" if (jobs or 1) > 1 else None)
    campaign.on_progress = status = StatusPrinter([campaign], None if scheduler else jobs or 1,
                                                  f"drivefuzz fuzz -> {out_dir}")
    try:
        findings = _run_campaign(campaign, bool(resume_dir), where, jobs or 1)
    except KeyboardInterrupt:
        status.close()
        findings = campaign.finish()
        _print_summary(campaign, findings, out_dir, report_all)
        click.echo("aborted", err=True)
        sys.exit(EXIT_ABORTED)
    status.close()
    _print_summary(campaign, findings, out_dir, report_all)
    if write_html:
        from drivefuzz.triage.report import write_report

        click.echo("report: {} and {}".format(*write_report(out_dir)))
    sys.exit(_exit_code(findings + (campaign.incidents if report_all else []), bool(campaign.failed_jobs)))


def _fuzz_config(config: dict[str, Any], config_file: str | None, cli: dict[str, Any], ads_name, ads_option,
                 oracle_kv, no_oracle):
    """The campaign's FuzzConfig: the command line's options over the config file's ``[fuzz]``, over defaults."""
    from drivefuzz.campaign.fuzz import FuzzConfig, parse_duration
    from drivefuzz.search.mutate import MutationConfig
    from drivefuzz.search.quality import QualityConfig
    from drivefuzz.scenario import AdsSpec

    fz = config.get("fuzz", {})

    def pick(key, default=None):
        value = cli.get(key)
        return value if value is not None and value is not False else fz.get(key, default)

    ads_cfg = config.get("ads", {})
    ads_opts = dict(ads_cfg.get("options", {}))
    ads_opts.update(parse_kv(ads_option, "--ads-option"))
    try:
        ads = AdsSpec(name=ads_name or ads_cfg.get("name", "ego"), options=ads_opts)
    except ValueError as exc:  # pydantic: an option value that is not a bool, number or string
        raise InvalidConfig("--ads-option", None, str(exc).splitlines()[-1].strip()) from None
    budget = cli["budget"]
    return FuzzConfig(
        cycles=pick("cycles", 10), population=pick("population", 8), strategy=pick("strategy", "all"),
        seed=pick("seed", 0),
        budget_s=parse_duration(budget) if budget is not None else parse_duration(fz.get("budget")),
        max_execs=pick("max_execs"),
        feedback="random" if pick("no_feedback", False) else pick("feedback", "risk"),
        single_pass=pick("single_pass", False),
        continue_after_finding=pick("continue_after_finding", False), shrink=pick("shrink", 10), ads=ads,
        reproduce_incidents=bool(cli.get("report_all")),  # incidents measured like the findings they count as
        oracles=_oracle_settings(config, oracle_kv, no_oracle, source=config_file),
        mutation=MutationConfig.model_validate(config.get("mutation", {})),
        quality=QualityConfig.model_validate(config.get("quality", {})),
        time_limit=pick("time_limit"), isolate=not pick("no_isolation", False),
        exec_timeout_s=pick("exec_timeout", 300.0),
    )


def _exit_code(findings, failed_jobs: bool) -> int:
    from drivefuzz.sim.simhost import INTERNAL_ERROR

    if any(f.misbehavior.oracle != INTERNAL_ERROR for f in findings):
        return EXIT_FOUND
    return EXIT_INTERNAL if findings or failed_jobs else EXIT_CLEAN


@contextlib.contextmanager
def _stop_on_ctrl_c(campaigns):
    """The first Ctrl-C asks every campaign to stop after its current executions; a second one aborts."""
    def _stop(signum, _frame):
        for campaign in campaigns:
            campaign.stop_requested = True
        click.echo("\nstopping after the current execution(s) (Ctrl-C again to abort)...", err=True)
        signal.signal(signal.SIGINT, signal.default_int_handler)

    old = signal.signal(signal.SIGINT, _stop)
    try:
        yield
    finally:
        with contextlib.suppress(ValueError):
            signal.signal(signal.SIGINT, old)


def _run_campaign(campaign, resume: bool, where: str | None, jobs: int):
    """Run a Campaign here or on Dask, stopping cleanly (everything saved) on the first Ctrl-C."""
    def _started():
        click.echo(f"fuzzing {len(campaign.seeds)} seed(s) -> {campaign.out}"
                   + (f" on {jobs} local workers" if where == "local" else f" on {where}" if where else ""), err=True)

    with _stop_on_ctrl_c([campaign]):
        if where is None:
            _started()
            return campaign.run(resume=resume)
        from drivefuzz.campaign.cluster import dask_client

        with dask_client(where, jobs=jobs) as client:
            _started()
            return campaign.run(resume=resume, client=client)


def _print_summary(campaign, findings, out_dir, report_all: bool = False) -> None:
    """Findings by signature (the ego's fault), then the incidents kept apart, then why the run stopped."""
    p = campaign.progress
    click.echo("", err=True)
    incidents = campaign.incidents
    click.echo(f"{p.execs} executions ({p.new_execs} in this run, {p.rate:.2f}/s); {len(findings)} finding(s) "
               f"and {len(incidents)} incident(s), one per signature; output in {out_dir}")
    _print_findings("findings (the ego's fault)" if findings else "", findings)
    if len(findings) > 1:
        _print_groups(findings)
    if incidents:
        _print_findings("incidents (not the ego's fault" + (", reported as findings by --report-all)" if report_all
                        else "; kept apart, --report-all counts them)"), incidents)
    for si, why in sorted(campaign.failed_jobs.items()):
        click.echo(f"job for seed {si} failed: {why}; its executions so far are saved, --resume retries it", err=True)
    if campaign.stop_reason:
        click.echo(f"why it stopped: {campaign.stop_reason}", err=True)
    _write_coverage(out_dir)
    if p.jobs_done < p.jobs_total:
        click.echo(f"stopped; continue with: drivefuzz fuzz --resume {out_dir}", err=True)


def _write_coverage(out_dir) -> None:
    """OUT/coverage.json, summed over every run of the campaign, and its figure in one line."""
    from drivefuzz.triage.coverage import campaign_coverage

    try:
        cov = campaign_coverage(out_dir)
    except (DriveFuzzError, OSError, ValueError) as exc:
        click.echo(f"coverage: not written ({exc})", err=True)
        return
    click.echo(f"coverage {cov['reached']}/{cov['reachable']} cells ({100.0 * cov['share']:.0f} %); "
               f"drivefuzz coverage {out_dir} lists them", err=True)


def _print_findings(title: str, findings) -> None:
    """One row per signature: hits, reproduction, simulated time of the event, the signature; then the replay."""
    from drivefuzz.campaign.fuzz import replay_command

    if not findings:
        return
    click.echo(title)
    click.echo(f"{'#':>3} {'hits':>5}  {'reproduced':<16} {'sim time':>9}  signature / replay")
    for i, f in enumerate(findings):
        m = f.misbehavior
        when = f"{m.time:>8.2f}s" if m.frame >= 0 else "        -"
        rep = f.reproduction or {}
        rate = f"{rep['reproduced']}/{rep['runs']} {'robust' if rep.get('robust') else 'knife-edge'}" if rep else "-"
        click.echo(f"{i:>3} {f.hits:>5}  {rate:<16} {when}  {f.label}")
        click.echo(f"{'':>38}{replay_command(f.path, f.ads)}")


def _print_groups(findings) -> None:
    """The likely bugs behind the findings: those one attribution rule blamed on the ego, by oracle and kind."""
    from types import SimpleNamespace

    from drivefuzz.triage.table import format_groups

    rows = []
    for i, f in enumerate(findings):
        att = f.attribution or {}
        rows.append(SimpleNamespace(number=i, hits=f.hits, verdict=f"{f.misbehavior.oracle}/{f.misbehavior.kind}",
                                    fault=str(att.get("fault", "")), rule=str(att.get("rule", ""))))
    click.echo(format_groups(rows))


def _seed_folder(network: Path, name: str, seeds_dir: str | None, seeds_root: Path | None) -> Path:
    """Where a network's seeds are: ``--seeds``; else the first of ``<seeds_root>/<name>/`` (a campaign
    file's ``seeds``), ``<network's folder>/../seeds/<name>/`` (the layout of this repository: a run from
    any folder finds the network's own verified seeds) and ``./seeds/<name>/`` that holds seeds; else
    ``./seeds/<name>/``, where new ones are generated."""
    from drivefuzz.scenario.seed import list_seeds

    if seeds_dir:
        return Path(seeds_dir)
    here = Path("seeds") / name
    candidates = ([seeds_root / name] if seeds_root else []) + [network.resolve().parent.parent / "seeds" / name, here]
    return next((c for c in candidates if c.is_dir() and list_seeds(c)), here)


def _seeds_for(network: str, seeds_dir: str | None, count: int = 4, seeds_root: Path | None = None):
    """The seeds of :func:`_seed_folder`, or ``count`` new ones.

    New seeds are written into that folder only when it is new or empty: a folder
    that holds something else is never written into (the campaign keeps its seeds
    in its own output directory anyway). A ``--seeds`` folder with something else
    in it is a mistake in the command line.
    """
    from drivefuzz.scenario.seed import generate_seeds, list_seeds
    from drivefuzz.scenario.sumofiles import load_scenario, write_scenario
    from drivefuzz.scenario.validate import load_network, require_car_roads, validate

    rmap = load_network(network)
    folder = _seed_folder(Path(network), rmap.name, seeds_dir, seeds_root)
    if folder.exists() and not folder.is_dir():
        raise InvalidConfig("--seeds", str(folder), "is a file", "a folder of seed scenarios (000/, 001/...)")
    found = list_seeds(folder) if folder.is_dir() else []
    if found:
        seeds = []
        for p in found:
            sc = load_scenario(p)
            if Path(sc.network).resolve() != Path(network).resolve():
                # a seed written for another file: it must fit this network (seeds of another city do not)
                sc = sc.model_copy(update={"network": str(Path(network).resolve())})
                validate(sc, rmap, str(p / "scenario.json"))
            _check_runnable(sc, str(p / "scenario.json"))
            seeds.append(sc)
        return seeds
    other = folder.is_dir() and any(folder.iterdir())
    if other and seeds_dir:
        raise InvalidConfig("--seeds", str(folder), "holds no seeds (no NNN/scenario.json) but is not empty",
                            "a folder of seeds, or a new or empty folder to generate them into")
    require_car_roads(rmap)
    click.echo(f"no seeds in {folder}: generating and verifying {count} for {rmap.path.name}...")
    verify = _DryRuns()
    seeds = generate_seeds(network, count, 0, verify=verify)
    if not seeds:
        raise InvalidConfig(network, None, "could not generate a seed mission that the reference ADS "
                            f"completes{verify.why()}", "a network with connected passenger roads")
    if other:  # not ours to write into: the campaign keeps them in its output directory
        click.echo(f"{folder} is not empty: the seeds are kept in the output directory only", err=True)
        return seeds
    try:
        for i, sc in enumerate(seeds):
            write_scenario(sc, folder / f"{i:03d}")
    except OSError as exc:
        click.echo(f"cannot write the seeds into {folder} ({exc.strerror or exc}): the output directory "
                   "keeps them", err=True)
    return seeds


# ------------------------------------------------------------------------ campaign
@main.command()
@click.argument("campaign_file", type=click.Path(), required=False)
@click.option("-o", "out", type=click.Path(file_okay=False), help="Output directory (default: new under ./drivefuzz-out/).")
@click.option("--resume", "resume_dir", type=click.Path(file_okay=False), help="Continue the batch in this directory.")
@click.option("--ads", "trusted_ads", multiple=True, callback=_ads_from_the_command_line, metavar="NAME",
              help="With --resume: an ADS of the batch's campaign.json that is not installed, to import it anyway.")
@handle_errors
def campaign(campaign_file, out, resume_dir, trusted_ads):
    """Run a batch: every cell of CAMPAIGN_FILE's matrix (networks x strategies x ADS x seeds) on Dask."""
    from drivefuzz.campaign.batch import (NO_EXECUTIONS, CampaignFile, cell_spent, cells, load_campaign_file,
                                          results_table, write_results)
    from drivefuzz.campaign.cluster import BATCH_SYSTEMS, dask_client
    from drivefuzz.campaign.fuzz import Campaign, FuzzConfig, load_campaign, parse_duration, run_on_dask
    from drivefuzz.campaign.status import StatusPrinter
    from drivefuzz.oracle import OracleSettings
    from drivefuzz.storage import atomic_write_json

    if resume_dir:
        out_dir = Path(resume_dir)
        path = out_dir / "campaign.json"
        if not path.is_file():
            raise InvalidConfig(resume_dir, None, "not a campaign directory (no campaign.json)",
                                "a directory written by 'drivefuzz campaign'")
        try:
            spec = CampaignFile.model_validate_json(path.read_text())
        except (ValueError, RecursionError, UnicodeDecodeError) as exc:
            raise InvalidConfig(str(path), None, f"unreadable ({str(exc).splitlines()[0]})") from None
        from drivefuzz.ads import check_trusted

        for i, ads in enumerate(spec.matrix.ads):  # the folder may come from anyone: import only what is trusted
            check_trusted(ads.name, str(path), f"matrix.ads[{i}].name",
                          command_line=ads.name if ads.name in trusted_ads else None)
    else:
        if not campaign_file:
            raise InvalidConfig("campaign", "CAMPAIGN_FILE", "missing", "a TOML file, or --resume DIR")
        spec = load_campaign_file(campaign_file)
        if spec.run.where in BATCH_SYSTEMS:
            from drivefuzz.campaign.cluster import check_submit_command

            check_submit_command(spec.run.where)
        settings = OracleSettings(settings=spec.oracles)
        settings.instantiate(source=campaign_file)  # unknown oracles or settings fail now, with the file's name
        out_dir = Path(out) if out else Path("drivefuzz-out") / time.strftime("campaign-%Y%m%d-%H%M%S")
        if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
            raise InvalidConfig("-o", str(out_dir), "output directory exists and is not empty",
                                "a new directory, or --resume to continue it")
        _writable_dir(out_dir, "-o")
        atomic_write_json(out_dir / "campaign.json", spec.model_dump(mode="json"))
    c = spec.campaign
    budget_s = parse_duration(c.budget)
    argv = ["drivefuzz", *sys.argv[1:]]
    work, campaigns = [], []
    where = spec.run.where
    status = StatusPrinter(campaigns, spec.run.jobs if where == "local" else None, f"drivefuzz campaign -> {out_dir}")
    for name, network, strategy, ads, seed in cells(spec):
        cell_dir = out_dir / "cells" / name
        if (cell_dir / "manifest.json").exists():  # resuming: the cell's own seeds, wherever this runs from
            seeds = load_campaign(cell_dir)[0]
        else:
            seeds = _seeds_for(network, None, c.seeds_per_network, spec.seeds_root)[:c.seeds_per_network]
        cfg = FuzzConfig(cycles=c.cycles, population=c.population, strategy=strategy, seed=seed, budget_s=budget_s,
                         max_execs=c.max_execs, feedback="random" if c.no_feedback else c.feedback,
                         continue_after_finding=c.continue_after_finding, ads=ads,
                         oracles=OracleSettings(settings=spec.oracles), mutation=spec.mutation, quality=spec.quality,
                         time_limit=c.time_limit, exec_timeout_s=c.exec_timeout)
        camp = Campaign(cell_dir, seeds, cfg, argv, on_progress=status)
        spent = cell_spent(cell_dir)  # a cell that spent its budget in an earlier run is done
        pending = camp.prepare(resume=(cell_dir / "manifest.json").exists())
        work.append((camp, [] if spent else pending))
        campaigns.append(camp)

    click.echo(f"{len(campaigns)} cell(s) on {where} -> {out_dir}", err=True)
    aborted = False
    try:
        with _stop_on_ctrl_c(campaigns), dask_client(where, jobs=spec.run.jobs,
                                                     batch=spec.cluster if where in BATCH_SYSTEMS else None) as client:
            run_on_dask(client, work, max_running=spec.run.cells_at_once)
    except KeyboardInterrupt:
        aborted = True
    finally:
        status.close()
        for camp in campaigns:
            camp.finish()
        rows = results_table(out_dir, spec)
        write_results(out_dir, rows)
    click.echo("", err=True)
    click.echo(f"{'cell':<44} {'execs':>6} {'found':>6} {'distinct':>8}  status")
    for r in rows:
        click.echo(f"{r['cell']:<44} {r['execs']:>6} {r['findings']:>6} {r['distinct']:>8}  {r['status']}")
    for r in rows:
        if r["execs"] == 0:
            click.echo(f"{r['cell']} ({r['folder']}): {NO_EXECUTIONS}", err=True)
    click.echo(f"results in {out_dir / 'results.csv'}")
    if any(r["status"] != "done" for r in rows):
        click.echo(f"continue with: drivefuzz campaign --resume {out_dir}", err=True)
    if aborted:
        sys.exit(EXIT_ABORTED)
    failed = any(camp.failed_jobs for camp in campaigns)
    sys.exit(EXIT_FOUND if any(r["findings"] for r in rows) else (EXIT_INTERNAL if failed else EXIT_CLEAN))


# -------------------------------------------------------------------------- replay
@main.command()
@click.argument("finding", type=click.Path())
@click.option("--gui", is_flag=True, help="Show the run in sumo-gui, following the ego; it stays open at the failure.")
@click.option("--speed", type=click.FloatRange(min=0.01, max=100.0), default=1.0, show_default=True,
              help="With --gui: simulated seconds per wall-clock second (1 = real time).")
@click.option("--ads", "ads_name", default=None, callback=_ads_from_the_command_line, metavar="NAME",
              help="The finding's ADS when it is not an installed plugin (package.module:Class): import it anyway.")
@handle_errors
def replay(finding, gui, speed, ads_name):
    """Run a FINDING directory again; 'reproduced' only if the same oracle fires at the same frame."""
    from drivefuzz.sim.execute import execute
    from drivefuzz.sim.simhost import FAILURE_KINDS

    folder, verdict, want, sc, oracles = _load_finding(finding, ads_name)
    if want.oracle in FAILURE_KINDS:  # a crash, hang or plugin error: run it isolated again
        from drivefuzz.sim.simhost import SimHost

        with SimHost(timeout_s=verdict["exec_timeout_s"]) as host:
            out = host.execute(sc, verdict["oracles"])
        if out.status == want.oracle and (out.error_type or out.status) == want.kind:
            click.echo(f"reproduced: {out.status} ({out.detail})")
            sys.exit(EXIT_CLEAN)
        got = f"{out.status} ({out.detail})" if out.status != "ok" else "a normal execution"
        click.echo(f"NOT reproduced: expected {want.oracle}/{want.kind}, got {got}")
        sys.exit(EXIT_FOUND)
    view = None
    if gui:
        from drivefuzz.sim.gui import GuiView

        view = GuiView(speed=speed, say=lambda text: click.echo(text, err=True))
    ex = execute(sc, oracles=oracles, gui=view or False)
    got = ex.misbehaviors[0] if ex.misbehaviors else None
    if got is not None and got.oracle == want.oracle and got.kind == want.kind and got.frame == want.frame:
        click.echo(f"reproduced: {got.oracle}/{got.kind} at frame {got.frame} (t={got.time:.2f} s)")
        _echo_stored_verdict(verdict)
        sys.exit(EXIT_CLEAN)
    seen = f"{got.oracle}/{got.kind} at frame {got.frame}" if got else f"no misbehaviour ({ex.termination.value})"
    click.echo(f"NOT reproduced: expected {want.oracle}/{want.kind} at frame {want.frame}, got {seen}")
    sys.exit(EXIT_FOUND)


def _echo_stored_verdict(verdict: dict) -> None:
    """The finding's stored attribution, as triage filed it: fault, the likely bug, and the reason (text
    from a folder that may come from anyone: printed without its control characters)."""
    from drivefuzz.triage.attribute import bug_class

    att = verdict.get("attribution")
    if not isinstance(att, dict) or not isinstance(att.get("reason"), str):
        return
    m = verdict["misbehaviors"][0]

    def clean(x) -> str:
        return "".join(c for c in str(x) if c.isprintable())

    _key, title = bug_class(clean(f"{m['oracle']}/{m['kind']}"), clean(att.get("fault", "?")),
                            clean(att.get("rule", "")))
    click.echo(f"  fault {clean(att.get('fault', '?'))}: {clean(att['reason'])}")
    click.echo(f"  likely bug: {title}")


def _load_finding(finding: str, ads_name: str | None):
    """A finding folder, checked: (folder, verdict, its first Misbehavior, scenario, oracle instances)."""
    from drivefuzz.ads import check_trusted
    from drivefuzz.oracle import OracleSettings
    from drivefuzz.scenario.sumofiles import read_scenario

    folder, verdict, want = _finding_verdict(finding)
    sc = read_scenario(folder)
    _check_runnable(sc, str(folder / "scenario.json"))
    if ads_name is not None and ads_name != sc.ads.name:
        raise InvalidConfig("--ads", ads_name, f"the finding was made with {sc.ads.name!r}",
                            f"--ads {sc.ads.name} (to trust it)")
    check_trusted(sc.ads.name, str(folder / "scenario.json"), "ads.name", command_line=ads_name)
    return folder, verdict, want, sc, OracleSettings(settings=verdict["oracles"]).instantiate(
        source=str(folder / "verdict.json"))


def _finding_verdict(finding: str):
    """(folder, its checked verdict.json, the first Misbehavior) of a finding folder."""
    folder = Path(finding)
    if not (folder / "verdict.json").is_file():
        raise InvalidConfig(finding, None, "not a finding directory (no verdict.json)", "findings/<n>-<oracle>-<hash>/")
    return (folder, *_read_verdict(folder / "verdict.json"))


# -------------------------------------------------------------------------- shrink
@main.command("shrink")
@click.argument("finding", type=click.Path())
@click.option("--budget", default=30, show_default=True, type=click.IntRange(1, 10_000),
              help="Executions the shrinking may spend.")
@click.option("--ads", "ads_name", default=None, callback=_ads_from_the_command_line, metavar="NAME",
              help="The finding's ADS when it is not an installed plugin (package.module:Class): import it anyway.")
@handle_errors
def shrink_cmd(finding, budget, ads_name):
    """Shrink a FINDING to a minimal reproducer (FINDING/minimal/, replayable) with the same signature."""
    from drivefuzz.triage.shrink import shrink_finding

    folder, verdict, want, sc, oracles = _load_finding(finding, ads_name)
    if verdict.get("frames") is None:
        raise InvalidConfig(str(folder / "verdict.json"), "frames", "a crash or hang has no trace to shrink against",
                            "a finding of an oracle")
    shrunk = shrink_finding(folder, verdict, want, sc, oracles, budget)
    click.echo(f"{shrunk.summary}")
    click.echo(f"minimal reproducer: {folder / 'minimal'}  (drivefuzz replay {folder / 'minimal'})")


# -------------------------------------------------------------------------- export
@main.command("export")
@click.argument("finding", type=click.Path())
@click.option("--to", "fmt", type=click.Choice(["openscenario"]), default="openscenario", show_default=True,
              help="The format: OpenSCENARIO 1.2 (.xosc) with its road as OpenDRIVE (.xodr).")
@click.option("-o", "out", type=click.Path(file_okay=False), default=None,
              help="Output folder (default: FINDING/openscenario/).")
@handle_errors
def export_cmd(finding, fmt, out):
    """Export a FINDING (its road, its actors' traced trajectories, the weather) for other simulators."""
    from drivefuzz.scenario.sumofiles import read_scenario
    from drivefuzz.sim.trace import Trace
    from drivefuzz.triage.export import export_openscenario, validate_openscenario

    folder, _verdict, want = _finding_verdict(finding)
    if not (folder / "trace").is_dir():
        raise InvalidConfig(str(folder), "trace", "the finding has no trace (a crash or hang)", "a finding of an oracle")
    out_dir = Path(out) if out else folder / "openscenario"
    _writable_dir(out_dir, "-o")
    xosc_path, xodr_path = export_openscenario(read_scenario(folder), Trace.load(folder / "trace"), want.time,
                                               out_dir, folder.name)
    validate_openscenario(xosc_path)
    click.echo(f"wrote {xosc_path} (OpenSCENARIO 1.2, valid against its schema) and {xodr_path}")


# -------------------------------------------------------------------------- regress
@main.command("regress")
@click.argument("archives", nargs=-1, required=True, type=click.Path())
@click.option("--ads", "ads_name", required=True, callback=_ads_from_the_command_line, metavar="NAME",
              help="The ADS to re-run the findings with (a plugin name or package.module:Class).")
@click.option("--ads-option", multiple=True, metavar="K=V", help="Option of that ADS.")
@click.option("--junit", "junit_out", type=click.Path(dir_okay=False), help="Write a JUnit XML file here.")
@click.option("--exec-timeout", type=_Seconds(), default=300.0, show_default=True,
              help="Wall seconds before a rerun counts as a hang.")
@handle_errors
def regress_cmd(archives, ads_name, ads_option, junit_out, exec_timeout):
    """Re-run every finding of ARCHIVE... (campaign directories or finding folders) with another ADS.

    Each finding is 'still failing', 'failing differently' or 'fixed'. Exit 1 when any still fails or
    fails differently, 0 when all are fixed, 2 on bad input."""
    from drivefuzz.ads import load_ads
    from drivefuzz.scenario import AdsSpec
    from drivefuzz.scenario.sumofiles import read_scenario
    from drivefuzz.sim.simhost import SimHost
    from drivefuzz.triage.regress import finding_folders, format_outcomes, junit_xml, regress_one

    folders = finding_folders(archives)
    try:
        ads = AdsSpec(name=ads_name, options=parse_kv(ads_option, "--ads-option"))
    except ValueError as exc:
        raise InvalidConfig("--ads-option", None, str(exc).splitlines()[-1].strip()) from None
    load_ads(ads.name, ads.options)  # fail now on an unknown ADS or option
    if junit_out:
        _writable_dir(Path(junit_out).parent, "--junit")
    outcomes = []
    with SimHost(timeout_s=exec_timeout) as host:
        for folder in folders:
            verdict, want = _read_verdict(folder / "verdict.json")
            sc = read_scenario(folder).model_copy(update={"ads": ads})
            _check_runnable(sc, str(folder / "scenario.json"))
            outcomes.append(o := regress_one(host, folder, verdict, want, sc))
            click.echo(f"{o.status}: {folder} ({o.detail})", err=True)
    click.echo(format_outcomes(outcomes))
    if junit_out:
        from drivefuzz.storage import atomic_write_text

        atomic_write_text(junit_out, junit_xml(outcomes, ads.name))
        click.echo(f"JUnit: {junit_out}")
    sys.exit(EXIT_FOUND if any(o.failed for o in outcomes) else EXIT_CLEAN)


def _read_verdict(path: Path):
    """A finding's verdict.json, checked: (the verdict, its first Misbehavior)."""
    import math

    from drivefuzz.oracle import Misbehavior

    valid = "a verdict.json written by drivefuzz fuzz"
    try:
        verdict = json.loads(path.read_text())
    except (ValueError, RecursionError) as exc:
        raise InvalidConfig(str(path), None, f"unreadable verdict ({type(exc).__name__})", valid) from None
    if not isinstance(verdict, dict):
        raise InvalidConfig(str(path), None, "not a JSON object", valid)
    try:
        want = Misbehavior.from_dict(verdict["misbehaviors"][0])
        if not all(isinstance(x, str) for x in (want.oracle, want.kind)):
            raise TypeError("oracle and kind must be strings")
    except (ValueError, KeyError, IndexError, TypeError, AttributeError) as exc:
        raise InvalidConfig(str(path), "misbehaviors[0]", f"unreadable ({type(exc).__name__}: {exc})", valid) from None
    timeout = verdict.setdefault("exec_timeout_s", 300.0)
    if (not isinstance(timeout, (int, float)) or isinstance(timeout, bool) or not math.isfinite(timeout)
            or not 0 < timeout <= MAX_SECONDS):
        raise InvalidConfig(str(path), "exec_timeout_s", f"{timeout!r} is not a number of seconds",
                            f"a number in (0, {MAX_SECONDS:g}]")
    oracles = verdict.setdefault("oracles", {})
    if not isinstance(oracles, dict) or not all(isinstance(v, dict) for v in oracles.values()):
        raise InvalidConfig(str(path), "oracles", "not a table of oracle settings", 'e.g. {"speeding": {...}}')
    return verdict, want


# ------------------------------------------------------------------------- oracles
@main.command("oracles")
@handle_errors
def oracles_cmd():
    """List the installed oracles and their settings."""
    from drivefuzz.oracle import available_oracles

    for name, cls in available_oracles().items():
        click.echo(f"{name}: {cls.description}")
        for key, f in cls.Config.model_fields.items():
            click.echo(f"    {name}.{key} = {f.default!r}{'  # ' + f.description if f.description else ''}")


@main.command("ads")
@handle_errors
def ads_cmd():
    """List the installed ADS plugins and their options."""
    from drivefuzz.ads import available_ads

    for name, ep in sorted(available_ads().items()):
        cls = ep.load()
        click.echo(f"{name}: {ep.value}")
        for key, f in cls.Options.model_fields.items():
            click.echo(f"    {key} = {f.default!r}")


# ------------------------------------------------------------------ findings, report
@main.command("findings")
@click.argument("out", type=click.Path())
@click.option("--json", "as_json", is_flag=True, help="Print the rows as a JSON list.")
@click.option("--incidents", is_flag=True, help="List the incidents (not the ego's fault) too.")
@handle_errors
def findings_cmd(out, as_json, incidents):
    """List a campaign's findings, numbered in the order they were first found (exit 0: a listing)."""
    from drivefuzz.triage.table import check_campaign_dir, finding_rows, format_groups, format_table, read_executions

    execs = read_executions(check_campaign_dir(out))
    rows = finding_rows(out, executions=execs)
    extra = finding_rows(out, incidents=True, executions=execs) if incidents else []
    if as_json:
        click.echo(json.dumps([r.as_json() for r in rows + extra], indent=2))
        return
    click.echo(format_table(rows, "findings (the ego's fault)"))
    if len(rows) > 1:
        click.echo(format_groups(rows))
    if incidents:
        click.echo(format_table(extra, "incidents (not the ego's fault)"))


@main.command("coverage")
@click.argument("out", type=click.Path())
@click.option("--json", "as_json", is_flag=True, help="Print the coverage as JSON (as OUT/coverage.json holds it).")
@handle_errors
def coverage_cmd(out, as_json):
    """Print a campaign's interaction coverage: the cells its seeds can offer, how often each was reached,
    which produced findings (F) or incidents (I), and those never reached (writes OUT/coverage.json)."""
    from drivefuzz.triage.coverage import campaign_coverage, format_coverage
    from drivefuzz.triage.table import check_campaign_dir

    out_dir = check_campaign_dir(out)
    if not (out_dir / "manifest.json").is_file():
        raise InvalidConfig(str(out_dir), None, "no manifest.json: coverage needs the campaign's seeds",
                            "a directory written by 'drivefuzz fuzz -o OUT'")
    cov = campaign_coverage(out_dir)
    click.echo(json.dumps(cov, indent=2) if as_json else format_coverage(cov))


@main.command("report")
@click.argument("out", type=click.Path())
@click.option("-o", "html_out", type=click.Path(dir_okay=False), help="The HTML file [OUT/report.html]; report.md beside it.")
@click.option("--max-cards", type=click.IntRange(0, 1000), default=50, show_default=True, help="Finding cards at most.")
@click.option("--no-animation", is_flag=True, help="Leave out the animations (faster).")
@handle_errors
def report_cmd(out, html_out, max_cards, no_animation):
    """Write one self-contained HTML report of campaign OUT (and its Markdown twin)."""
    from drivefuzz.triage.report import write_report
    from drivefuzz.triage.table import check_campaign_dir

    check_campaign_dir(out)
    if html_out:
        _writable_dir(Path(html_out).parent, "-o")
    html_path, md_path = write_report(out, html_out, max_cards=max_cards, animate=not no_animation)
    click.echo(f"wrote {html_path} and {md_path}")


if __name__ == "__main__":  # pragma: no cover
    main()
