"""The commands on findings and campaign folders: replay, shrink, export, regress, findings, coverage, report;
and the listings of installed oracles and ADSs."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from drivefuzz.cli.common import (EXIT_CLEAN, EXIT_FOUND, Seconds, ads_from_the_command_line, check_runnable,
                                  handle_errors, parse_kv, read_verdict, writable_dir)
from drivefuzz.errors import InvalidConfig


@click.command()
@click.argument("finding", type=click.Path())
@click.option("--gui", is_flag=True, help="Show the run in sumo-gui, following the ego; it stays open at the failure.")
@click.option("--speed", type=click.FloatRange(min=0.01, max=100.0), default=1.0, show_default=True,
              help="With --gui: simulated seconds per wall-clock second (1 = real time).")
@click.option("--ads", "ads_name", default=None, callback=ads_from_the_command_line, metavar="NAME",
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
    check_runnable(sc, str(folder / "scenario.json"))
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
    return (folder, *read_verdict(folder / "verdict.json"))


# -------------------------------------------------------------------------- shrink
@click.command("shrink")
@click.argument("finding", type=click.Path())
@click.option("--budget", default=30, show_default=True, type=click.IntRange(1, 10_000),
              help="Executions the shrinking may spend.")
@click.option("--ads", "ads_name", default=None, callback=ads_from_the_command_line, metavar="NAME",
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
@click.command("export")
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
    writable_dir(out_dir, "-o")
    xosc_path, xodr_path = export_openscenario(read_scenario(folder), Trace.load(folder / "trace"), want.time,
                                               out_dir, folder.name)
    validate_openscenario(xosc_path)
    click.echo(f"wrote {xosc_path} (OpenSCENARIO 1.2, valid against its schema) and {xodr_path}")


# -------------------------------------------------------------------------- regress
@click.command("regress")
@click.argument("archives", nargs=-1, required=True, type=click.Path())
@click.option("--ads", "ads_name", required=True, callback=ads_from_the_command_line, metavar="NAME",
              help="The ADS to re-run the findings with (a plugin name or package.module:Class).")
@click.option("--ads-option", multiple=True, metavar="K=V", help="Option of that ADS.")
@click.option("--junit", "junit_out", type=click.Path(dir_okay=False), help="Write a JUnit XML file here.")
@click.option("--exec-timeout", type=Seconds(), default=300.0, show_default=True,
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
        writable_dir(Path(junit_out).parent, "--junit")
    outcomes = []
    with SimHost(timeout_s=exec_timeout) as host:
        for folder in folders:
            verdict, want = read_verdict(folder / "verdict.json")
            sc = read_scenario(folder).model_copy(update={"ads": ads})
            check_runnable(sc, str(folder / "scenario.json"))
            outcomes.append(o := regress_one(host, folder, verdict, want, sc))
            click.echo(f"{o.status}: {folder} ({o.detail})", err=True)
    click.echo(format_outcomes(outcomes))
    if junit_out:
        from drivefuzz.storage import atomic_write_text

        atomic_write_text(junit_out, junit_xml(outcomes, ads.name))
        click.echo(f"JUnit: {junit_out}")
    sys.exit(EXIT_FOUND if any(o.failed for o in outcomes) else EXIT_CLEAN)


# ------------------------------------------------------------------------- oracles
@click.command("oracles")
@handle_errors
def oracles_cmd():
    """List the installed oracles and their settings."""
    from drivefuzz.oracle import available_oracles

    for name, cls in available_oracles().items():
        click.echo(f"{name}: {cls.description}")
        for key, f in cls.Config.model_fields.items():
            click.echo(f"    {name}.{key} = {f.default!r}{'  # ' + f.description if f.description else ''}")


@click.command("ads")
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
@click.command("findings")
@click.argument("out", type=click.Path())
@click.option("--json", "as_json", is_flag=True, help="Print the rows as a JSON list.")
@click.option("--incidents", is_flag=True, help="List the incidents (not the ego's fault) too.")
@click.option("--errors", is_flag=True, help="List the executions the tool failed (SUMO, drivefuzz or an oracle "
              "plugin: not findings of the ADS) too.")
@handle_errors
def findings_cmd(out, as_json, incidents, errors):
    """List a campaign's findings, numbered in the order they were first found (exit 0: a listing)."""
    from drivefuzz.triage.table import check_campaign_dir, finding_rows, format_groups, format_table, read_executions

    execs = read_executions(check_campaign_dir(out))
    rows = finding_rows(out, executions=execs)
    extra = finding_rows(out, incidents=True, executions=execs) if incidents else []
    failed = finding_rows(out, executions=execs, errors=True) if errors else []
    if as_json:
        click.echo(json.dumps([r.as_json() for r in rows + extra + failed], indent=2))
        return
    click.echo(format_table(rows, "findings (the ego's fault)"))
    if len(rows) > 1:
        click.echo(format_groups(rows))
    if incidents:
        click.echo(format_table(extra, "incidents (not the ego's fault)"))
    if errors:
        click.echo(format_table(failed, "errors of the tool (SUMO, drivefuzz or an oracle plugin; not findings)"))


@click.command("coverage")
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


@click.command("report")
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
        writable_dir(Path(html_out).parent, "-o")
    html_path, md_path = write_report(out, html_out, max_cards=max_cards, animate=not no_animation)
    click.echo(f"wrote {html_path} and {md_path}")
