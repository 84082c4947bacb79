"""``drivefuzz campaign``: a batch (a matrix of networks, strategies, ADSs and seeds) on Dask or a batch system."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import click

from drivefuzz.cli.common import (EXIT_ABORTED, EXIT_CLEAN, EXIT_FOUND, EXIT_INTERNAL,
                                  ads_from_the_command_line, handle_errors, seeds_for, stop_on_ctrl_c,
                                  writable_dir)
from drivefuzz.errors import InvalidConfig


@click.command()
@click.argument("campaign_file", type=click.Path(), required=False)
@click.option("-o", "out", type=click.Path(file_okay=False), help="Output directory (default: new under ./drivefuzz-out/).")
@click.option("--resume", "resume_dir", type=click.Path(file_okay=False), help="Continue the batch in this directory.")
@click.option("--ads", "trusted_ads", multiple=True, callback=ads_from_the_command_line, metavar="NAME",
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
        writable_dir(out_dir, "-o")
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
            seeds = seeds_for(network, None, c.seeds_per_network, spec.seeds_root)[:c.seeds_per_network]
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
        with stop_on_ctrl_c(campaigns), dask_client(where, jobs=spec.run.jobs,
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
        if r.get("errors"):
            click.echo(f"{r['cell']} ({r['folder']}): {r['errors']} error(s) of the tool (SUMO, drivefuzz or an oracle "
                       "plugin failed; not findings): drivefuzz findings --errors lists them", err=True)
    click.echo(f"results in {out_dir / 'results.csv'}")
    if any(r["status"] != "done" for r in rows):
        click.echo(f"continue with: drivefuzz campaign --resume {out_dir}", err=True)
    if aborted:
        sys.exit(EXIT_ABORTED)
    failed = any(camp.failed_jobs or camp.errors for camp in campaigns)
    sys.exit(EXIT_FOUND if any(r["findings"] for r in rows) else (EXIT_INTERNAL if failed else EXIT_CLEAN))
