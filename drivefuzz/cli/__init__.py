"""The ``drivefuzz`` command. This package is the only place that turns errors into exit codes.

Exit codes: 0 ran clean; 1 misbehaviour found (``fuzz``, ``run``) or not
reproduced (``replay``); 2 usage or input error (one line on stderr, no
traceback); 3 the simulator or a plugin failed (or, in a campaign, only
internal errors were found); 130 aborted by a second Ctrl-C.

The commands live in :mod:`.run` (run, seed), :mod:`.fuzz`, :mod:`.batch` (campaign) and :mod:`.triage`
(replay, shrink, export, regress, findings, coverage, report, oracles, ads); :mod:`.common` holds what they share.
"""

from __future__ import annotations

import atexit
import functools
import gc
import sys

import click

import drivefuzz
from drivefuzz.cli import batch, triage
from drivefuzz.cli import fuzz as fuzz_cmd
from drivefuzz.cli import run as run_cmd
from drivefuzz.cli.common import EXIT_ABORTED, EXIT_CLEAN, EXIT_INPUT, fail


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
            fail(f"{where}: {exc.format_message()} (see '{where} --help')", EXIT_INPUT)
        except click.ClickException as exc:  # e.g. click.FileError
            fail(exc.format_message(), EXIT_INPUT)
        except click.Abort:  # Ctrl-C outside a campaign
            click.echo("aborted", err=True)
            sys.exit(EXIT_ABORTED)
        sys.exit(rv if isinstance(rv, int) else EXIT_CLEAN)


@click.group(cls=_Main, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(drivefuzz.__version__, prog_name="drivefuzz")
def main() -> None:
    """drivefuzz: find safety-critical misbehaviour of automated-driving controllers in SUMO."""


for _command in (run_cmd.run, run_cmd.seed, fuzz_cmd.fuzz, batch.campaign, triage.replay, triage.shrink_cmd,
                 triage.export_cmd, triage.regress_cmd, triage.oracles_cmd, triage.ads_cmd, triage.findings_cmd,
                 triage.coverage_cmd, triage.report_cmd):
    main.add_command(_command)
