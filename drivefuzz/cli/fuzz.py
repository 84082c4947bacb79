"""``drivefuzz fuzz``: one campaign on a network, here or on Dask, with its summary."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Any

import click

from drivefuzz.cli.common import (EXIT_ABORTED, EXIT_CLEAN, EXIT_FOUND, EXIT_INTERNAL, JOBS_PER_CPU, Seconds,
                                  ads_from_the_command_line, handle_errors, load_config_file, oracle_options,
                                  oracle_settings, parse_kv, seeds_for, stop_on_ctrl_c, writable_dir)
from drivefuzz.errors import DriveFuzzError, InvalidConfig


@click.command()
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
@click.option("--ads", "ads_name", default=None, callback=ads_from_the_command_line, help="ADS plugin under test [ego].")
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
@click.option("--time-limit", type=Seconds(), default=None, help="Simulated seconds per execution (default: the seed's).")
@click.option("--jobs", "-j", type=click.IntRange(1, JOBS_PER_CPU * (os.cpu_count() or 1)), default=None, help="Seed campaigns at once on a local Dask cluster [1].")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run the jobs on an existing Dask scheduler (tcp://HOST:PORT or a scheduler.json).")
@click.option("--exec-timeout", type=Seconds(), default=None, help="Wall seconds before an execution is a 'hang' [300].")
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
    writable_dir(out_dir, "-o")
    if not resume_dir:
        seeds = seeds_for(network, seeds_dir)
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
    sys.exit(_exit_code(findings + (campaign.incidents if report_all else []),
                        bool(campaign.failed_jobs or campaign.errors)))


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
        oracles=oracle_settings(config, oracle_kv, no_oracle, source=config_file),
        mutation=MutationConfig.model_validate(config.get("mutation", {})),
        quality=QualityConfig.model_validate(config.get("quality", {})),
        time_limit=pick("time_limit"), isolate=not pick("no_isolation", False),
        exec_timeout_s=pick("exec_timeout", 300.0),
    )


def _exit_code(findings, tool_failed: bool) -> int:
    """1 for a finding of the ADS; else 3 when the tool failed (an execution's error of the tool or an oracle
    plugin, a job that failed), else 0. An ``internal-error`` finding is one filed by a drivefuzz older than
    the errors/ folder (a resumed campaign): it stays an error of the tool."""
    from drivefuzz.sim.simhost import INTERNAL_ERROR

    if any(f.misbehavior.oracle != INTERNAL_ERROR for f in findings):
        return EXIT_FOUND
    return EXIT_INTERNAL if findings or tool_failed else EXIT_CLEAN


def _run_campaign(campaign, resume: bool, where: str | None, jobs: int):
    """Run a Campaign here or on Dask, stopping cleanly (everything saved) on the first Ctrl-C."""
    def _started():
        click.echo(f"fuzzing {len(campaign.seeds)} seed(s) -> {campaign.out}"
                   + (f" on {jobs} local workers" if where == "local" else f" on {where}" if where else ""), err=True)

    with stop_on_ctrl_c([campaign]):
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
    _print_errors(campaign.errors)
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


def _print_errors(errors) -> None:
    """The executions the tool failed (SUMO died, drivefuzz or an oracle plugin raised), on stderr: not findings
    of the ADS, but each kept in a folder with its error and traceback, and replayable."""
    from drivefuzz.campaign.fuzz import replay_command

    if not errors:
        return
    click.echo(f"errors of the tool, not findings of the ADS ({len(errors)}; error and traceback in each "
               "folder's verdict.json):", err=True)
    for i, f in enumerate(errors):
        m = f.misbehavior
        click.echo(f"{i:>3} {f.hits:>5}  {f.signature.get('fault', 'tool'):<14} {m.oracle}/{m.kind}: "
                   f"{str(m.details.get('detail', ''))[:160]}", err=True)
        click.echo(f"{'':>10}{replay_command(f.path, f.ads)}", err=True)


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
