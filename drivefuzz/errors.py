"""The one exception root of drivefuzz.

User mistakes subclass both :class:`DriveFuzzError` and the matching builtin, and
their message names the file, the field and what would be valid. Only the commands (``drivefuzz/cli/``)
turn them into exit codes.
"""

from __future__ import annotations


class DriveFuzzError(Exception):
    """Root of every error drivefuzz raises on purpose."""


class InvalidInput(DriveFuzzError, ValueError):
    """A user-supplied file or option is wrong. ``str(err)`` is one line for the user."""

    def __init__(self, source: str | None, field: str | None, problem: str, valid: str | None = None):
        self.source, self.field, self.problem, self.valid = source, field, problem, valid
        parts = []
        if source:
            parts.append(str(source))
        if field:
            parts.append(field)
        head = ": ".join(parts)
        msg = f"{head}: {problem}" if head else problem
        if valid:
            msg += f" (valid: {valid})"
        super().__init__(msg)


class InvalidScenario(InvalidInput):
    """A scenario (model or its SUMO files) is malformed or impossible."""


class InvalidNetwork(InvalidInput):
    """A SUMO network file cannot be used."""


class InvalidConfig(InvalidInput):
    """A configuration file or CLI option is wrong."""


#: :attr:`PluginError.plugin`: which kind of plugin failed (who is to blame for a failed execution)
ADS_PLUGIN, ORACLE_PLUGIN = "ads", "oracle"


class PluginError(DriveFuzzError, RuntimeError):
    """An ADS or oracle plugin could not be loaded or raised during a run.

    ``plugin`` says which: :data:`ADS_PLUGIN` (a bug of the ADS under test: a finding), :data:`ORACLE_PLUGIN`
    (a bug of the tool's configuration, not of the ADS), or "" when the raiser did not say."""

    def __init__(self, message: str = "", plugin: str = ""):
        super().__init__(message)
        self.plugin = plugin

    def __reduce__(self):  # pickled with its plugin (args holds only the message)
        return (type(self), (str(self), self.plugin))


class SimulationError(DriveFuzzError, RuntimeError):
    """SUMO failed during an execution (not the user's fault)."""
