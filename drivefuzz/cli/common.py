"""What the commands share: exit codes, the one-line error, option types and checks, where seeds come from.

Only the commands (this package) turn errors into exit codes: :func:`handle_errors` wraps each.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import signal
import sys
from pathlib import Path
from typing import Any, Sequence

import click

from drivefuzz.errors import DriveFuzzError, InvalidConfig, InvalidInput

EXIT_CLEAN, EXIT_FOUND, EXIT_INPUT, EXIT_INTERNAL = 0, 1, 2, 3
EXIT_ABORTED = 130  # a second Ctrl-C: what was finished is saved; --resume continues


def fail(msg: str, code: int) -> None:
    click.echo(f"drivefuzz: error: {' '.join(str(msg).split())}", err=True)
    sys.exit(code)


def handle_errors(fn):
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except InvalidInput as exc:
            fail(str(exc), EXIT_INPUT)
        except DriveFuzzError as exc:
            fail(str(exc), EXIT_INTERNAL)
    return wrapper


class Seconds(click.ParamType):
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


def ads_from_the_command_line(_ctx, _param, value):
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


def writable_dir(path: str | Path, option: str) -> Path:
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


def oracle_settings(config: dict[str, Any], kv, disabled, source: str | None = None):
    """The file's oracle settings (checked as the file's), then the command line's on top."""
    from drivefuzz.oracle import OracleSettings, parse_oracle_options

    base = config.get("oracles", {})
    if source and base:
        OracleSettings(settings=base).instantiate(source=source)
    settings = parse_oracle_options(kv, disabled, base=base)
    settings.instantiate()  # validate names and values now, not in the middle of a campaign
    return settings


def check_runnable(sc, source: str) -> None:
    """What SUMO refuses at run time but a well-formed scenario may hold (see validate.check_departure)."""
    from drivefuzz.scenario.roadmap import load_roadmap
    from drivefuzz.scenario.validate import check_departure

    check_departure(sc, load_roadmap(sc.network_path()), source)


def manifest_of(scenario: str | Path) -> str:
    """The file a scenario's fields come from: its scenario.json (or the JSON file itself)."""
    p = Path(scenario)
    return str(p / "scenario.json") if p.is_dir() else str(p)


class DryRuns:
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


@contextlib.contextmanager
def stop_on_ctrl_c(campaigns):
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


def seed_folder(network: Path, name: str, seeds_dir: str | None, seeds_root: Path | None) -> Path:
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


def seeds_for(network: str, seeds_dir: str | None, count: int = 4, seeds_root: Path | None = None):
    """The seeds of :func:`seed_folder`, or ``count`` new ones.

    New seeds are written into that folder only when it is new or empty: a folder
    that holds something else is never written into (the campaign keeps its seeds
    in its own output directory anyway). A ``--seeds`` folder with something else
    in it is a mistake in the command line.
    """
    from drivefuzz.scenario.seed import generate_seeds, list_seeds
    from drivefuzz.scenario.sumofiles import load_scenario, write_scenario
    from drivefuzz.scenario.validate import load_network, require_car_roads, validate

    rmap = load_network(network)
    folder = seed_folder(Path(network), rmap.name, seeds_dir, seeds_root)
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
            check_runnable(sc, str(p / "scenario.json"))
            seeds.append(sc)
        return seeds
    other = folder.is_dir() and any(folder.iterdir())
    if other and seeds_dir:
        raise InvalidConfig("--seeds", str(folder), "holds no seeds (no NNN/scenario.json) but is not empty",
                            "a folder of seeds, or a new or empty folder to generate them into")
    require_car_roads(rmap)
    click.echo(f"no seeds in {folder}: generating and verifying {count} for {rmap.path.name}...")
    verify = DryRuns()
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


def read_verdict(path: Path):
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
