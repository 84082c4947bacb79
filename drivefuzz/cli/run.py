"""``drivefuzz run`` (one scenario) and ``drivefuzz seed`` (verified seed missions for a network)."""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path

import click

from drivefuzz.cli.common import (DryRuns, EXIT_CLEAN, EXIT_FOUND, ads_from_the_command_line, check_runnable,
                                  handle_errors, load_config_file, manifest_of, oracle_options,
                                  oracle_settings, parse_kv, writable_dir)
from drivefuzz.errors import InvalidConfig


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


@click.command()
@click.argument("scenario", type=click.Path())
@click.option("--gui", is_flag=True, help="Show the run in sumo-gui (through traci; same code path).")
@click.option("--ads", "ads_name", default=None, callback=ads_from_the_command_line, help="ADS plugin (default: the scenario's).")
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
    check_runnable(sc, manifest_of(scenario))
    if not ads_name:  # the scenario's own ADS: imported only if installed (a scenario folder may come from anyone)
        check_trusted(sc.ads.name, manifest_of(scenario), "ads.name")
    if ads_name or ads_option:
        opts = dict(sc.ads.options) if not ads_name or ads_name == sc.ads.name else {}
        opts.update(parse_kv(ads_option, "--ads-option"))
        try:
            sc = sc.model_copy(update={"ads": AdsSpec(name=ads_name or sc.ads.name, options=opts)})
        except ValueError as exc:  # pydantic: an option value that is not a bool, number or string
            raise InvalidConfig("--ads-option", None, str(exc).splitlines()[-1].strip()) from None
    settings = oracle_settings(config, oracle_kv, no_oracle, source=config_file)
    if trace_out:
        writable_dir(trace_out, "--trace")
    try:
        ex = execute(sc, oracles=settings.instantiate(), gui=gui)
    except SimulationError as exc:
        if not str(exc).startswith("SUMO failed to start"):
            raise
        # drivefuzz checked the scenario and its network; what SUMO still refuses is in the user's files
        reason = str(exc).partition(": ")[2] or str(exc)
        raise InvalidScenario(manifest_of(scenario), None, f"SUMO refuses this scenario or its network "
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


# ---------------------------------------------------------------------------- seed
@click.command()
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
    writable_dir(out, "-o")
    verify = DryRuns()
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
