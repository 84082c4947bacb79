"""Crash isolation: executions run in a persistent child process, the simulation host.

libsumo runs SUMO inside the Python process, so a segfault or abort in SUMO (or in
native code an ADS plugin loads) would kill whoever called it: a campaign, or a
Dask worker. The fuzz loop therefore sends each execution to a child process
and turns whatever goes wrong there into an :class:`Outcome`:

- ``ok``: the child returned the :class:`~drivefuzz.sim.execute.Execution`;
- ``simulator-crash``: the child died (a signal such as SIGSEGV/SIGABRT, or an exit);
- ``hang``: no answer within the wall-clock limit (the child is killed);
- ``plugin-error``: an ADS or oracle plugin raised (:class:`~drivefuzz.errors.PluginError`; ``Outcome.plugin``
  says which);
- ``internal-error``: any other exception in the child (a SUMO error, or a drivefuzz bug).

Only some of these are the ADS's fault (:func:`failure_fault`): an ADS plugin that raises or never answers is a
finding; SUMO dying, drivefuzz's own bugs and an oracle plugin's exceptions are errors of the tool, kept and
shown as such but never counted as findings of the ADS. A child that dies or hangs cannot say who it was in:
:mod:`faulthandler` writes its Python stack to a file in its TMPDIR (on a fatal signal; on a hang the parent
asks for it with SIGUSR1 before the kill), which becomes the Outcome's traceback, and the plugin whose code
was running (:func:`blame_stack`) its ``plugin``: SUMO or drivefuzz itself when neither's was.

The parent restarts a dead child before the next execution (about 0.4 s), so a
campaign goes on. The child is started with :mod:`subprocess`, not
:mod:`multiprocessing`, so it works inside daemonic Dask worker processes without
``distributed.worker.daemon: False``. It ignores SIGINT (the parent decides when a
campaign stops) and exits on its own when its parent dies, even mid-execution.

The child runs ``python -I``: neither the current folder nor ``PYTHONPATH`` is on its
import path by Python's doing, so a ``shapely.py`` lying in the folder drivefuzz was
started from (a downloaded finding, say) is never imported. It gets the parent's import
path instead, less the current folder (unless ``PYTHONPATH`` names it): whatever plugin
the parent can import, the child can. Its temporary files live in a folder of the
parent's (``TMPDIR``), removed when the child ends, so that a child killed mid-execution
leaves no ``drivefuzz-run-*`` behind (and the next host removes those of a parent that was killed).

Protocol on the child's stdin/stdout: 8-byte big-endian length + pickle, both ways.
"""

from __future__ import annotations

import faulthandler
import os
import pickle
import re
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass
from typing import Any, BinaryIO

from drivefuzz.errors import ADS_PLUGIN, ORACLE_PLUGIN, PluginError, SimulationError

OK, CRASH, HANG, PLUGIN_ERROR, INTERNAL_ERROR = "ok", "simulator-crash", "hang", "plugin-error", "internal-error"
#: Finding kinds that are not oracle verdicts but failures of the system under test or of SUMO.
FAILURE_KINDS = (CRASH, HANG, PLUGIN_ERROR, INTERNAL_ERROR)
#: The ``fault`` of a failed execution that is not the ADS's (:func:`failure_fault`): SUMO or drivefuzz
#: itself failed, or an oracle plugin raised. Such an execution is an error of the tool, not a finding.
TOOL_FAULT, ORACLE_FAULT = "tool", "oracle-plugin"

_MAGIC = b"DFZ1"
_HEADER = struct.Struct(">4sQ")  # magic, length: anything else on the pipe is a protocol error
#: [s] for the child to import drivefuzz and libsumo and say it is ready (not part of an execution's time)
START_TIMEOUT = 120.0
#: the parent's import path for the child (``python -I`` ignores PYTHONPATH)
PATH_ENV = "DRIVEFUZZ_SIMHOST_PATH"
#: what the child runs: the parent's import path first, then the host's loop
_BOOTSTRAP = ("import os, sys; "
              f"sys.path[:0] = [p for p in os.environ.get({PATH_ENV!r}, '').split(os.pathsep) if p]; "
              "from drivefuzz.sim.simhost import _serve; _serve()")


class ProtocolError(Exception):
    """The child wrote something that is not a reply."""


@dataclass
class Outcome:
    status: str  # one of OK, CRASH, HANG, PLUGIN_ERROR, INTERNAL_ERROR
    execution: Any = None  # drivefuzz.sim.execute.Execution when status == OK
    detail: str = ""  # one line: the signal, the exception, the limit
    error_type: str = ""  # exception class name, or signal name
    traceback: str = ""
    wall_time: float = 0.0  # [s] as seen by the parent
    plugin: str = ""  # PLUGIN_ERROR: which kind of plugin raised (errors.ADS_PLUGIN, errors.ORACLE_PLUGIN; "": unsaid)

    @property
    def fault(self) -> str:
        """Who a failed execution is blamed on: "ego", or :data:`TOOL_FAULT` / :data:`ORACLE_FAULT`."""
        return failure_fault(self.status, self.plugin)


def failure_fault(status: str, plugin: str = "") -> str:
    """The ``fault`` of a failed execution (``status`` one of :data:`FAILURE_KINDS`).

    "ego" (a finding) when the ADS plugin raised, or when the execution hung: the wall-clock limit is far beyond
    what SUMO and the oracles take, and a planner that never returns is the usual cause (the host cannot tell
    who hung). :data:`ORACLE_FAULT` when an oracle plugin raised. :data:`TOOL_FAULT` for everything else: the
    simulation process died (SUMO's native code, as far as the host can tell), an exception that no plugin
    raised (a SUMO error, a drivefuzz bug), or a plugin error that does not say whose it is."""
    if plugin == ADS_PLUGIN or (status == HANG and plugin == ""):
        return "ego"
    if plugin == ORACLE_PLUGIN:
        return ORACLE_FAULT
    return TOOL_FAULT


#: the child's :mod:`faulthandler` file, in its TMPDIR
STACK_FILE = "faulthandler.txt"
#: ``plugin`` of a crash or hang whose stack shows SUMO or drivefuzz running, not a plugin
NO_PLUGIN = "none"
_FRAME = re.compile(r'^\s*File "(?P<file>.*)", line (?P<line>\d+) in (?P<func>\S+)')
#: where execute.py calls plugins (_Run's method -> the ADS's methods called there, None: only the ADS's; a
#: call there to anything else is an oracle's)
_ADS_CALLS = {"ads_step": None, "take_over_ego": None, "run_oracles": {"done"}, "finish": {"trace_info"},
              "reset_plugins": {"reset"}}


def blame_stack(dump: str) -> str:
    """Whose code ran when the child died or hung, from its faulthandler ``dump``: :data:`ADS_PLUGIN`,
    :data:`ORACLE_PLUGIN`, :data:`NO_PLUGIN` (SUMO, or drivefuzz itself), or "" (no execution's stack in it).

    The main thread's stack (the one through ``_serve``) is read from its innermost frame in
    ``drivefuzz/sim/execute.py``: what that frame called is SUMO's or drivefuzz's when it is a file of
    libsumo, traci or drivefuzz (or there is none: native code called from execute.py), else a plugin's,
    the ADS's or an oracle's by the method it was in."""
    for block in re.split(r"\n(?=\S)", dump):
        frames = [m.groupdict() for m in map(_FRAME.match, block.splitlines()) if m]  # most recent first
        if not any(f["func"] == "_serve" for f in frames):
            continue
        at = next((i for i, f in enumerate(frames) if _in_execute(f["file"])), None)
        if at is None:
            return ""
        callee = frames[at - 1] if at > 0 else None
        if callee is None or _not_a_plugin(callee["file"]):
            return NO_PLUGIN
        step = frames[at]["func"]
        if step not in _ADS_CALLS:  # no plugin is called there: a library drivefuzz called
            return NO_PLUGIN
        if step == "reset_plugins":  # the ADS's reset comes before the oracles' loop in reset_plugins
            return ADS_PLUGIN if int(frames[at]["line"]) < _oracle_reset_line() else ORACLE_PLUGIN
        ads_calls = _ADS_CALLS[step]
        return ADS_PLUGIN if ads_calls is None or callee["func"] in ads_calls else ORACLE_PLUGIN
    return ""


_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # drivefuzz/


def _in_execute(path: str) -> bool:
    return os.path.normpath(path).endswith(os.path.join("drivefuzz", "sim", "execute.py"))


def _not_a_plugin(path: str) -> bool:
    """A file of drivefuzz (this one, which the child runs too) or of SUMO's Python bindings."""
    path = os.path.abspath(path)
    return path.startswith(_PACKAGE + os.sep) or os.path.basename(os.path.dirname(path)) in ("libsumo", "traci")


def _oracle_reset_line() -> int:
    """The line of execute.py's ``_Run.reset_plugins`` where the oracles' resets begin."""
    import inspect

    from drivefuzz.sim.execute import _Run

    lines, first = inspect.getsourcelines(_Run.reset_plugins)
    return first + next(i for i, line in enumerate(lines) if "for oracle" in line)


def _send(fh: BinaryIO, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    fh.write(_HEADER.pack(_MAGIC, len(data)) + data)
    fh.flush()


def _receive(fd: int, deadline: float | None) -> Any:
    """The next message on fd; None on EOF (the child died); TimeoutError; ProtocolError."""
    header = _read_exact(fd, _HEADER.size, deadline)
    if header is None:
        return None
    magic, size = _HEADER.unpack(header)
    if magic != _MAGIC:
        raise ProtocolError(f"unexpected bytes on the result pipe: {header!r}")
    body = _read_exact(fd, size, deadline)
    return None if body is None else pickle.loads(body)


def _read_exact(fd: int, n: int, deadline: float | None) -> bytes | None:
    """Read n bytes from fd; None on EOF; raises TimeoutError past the deadline."""
    chunks, got = [], 0
    while got < n:
        if deadline is not None:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                raise TimeoutError
        chunk = os.read(fd, min(n - got, 1 << 20))
        if not chunk:
            return None
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


def _signal_name(returncode: int) -> str:
    if returncode < 0:
        try:
            return signal.Signals(-returncode).name
        except ValueError:
            return f"signal {-returncode}"
    return f"exit status {returncode}"


class SimHost:
    """A persistent child process that runs executions; use as a context manager."""

    def __init__(self, timeout_s: float | None = 300.0):
        self.timeout_s = timeout_s
        self.proc: subprocess.Popen | None = None
        self._path = ""
        self._tmp: str | None = None  # the child's TMPDIR
        self.starts = 0

    def __enter__(self) -> "SimHost":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> "SimHost":
        """Start the child now (:meth:`execute` starts it when needed): the first execution finds it ready."""
        if self.proc is None or self.proc.poll() is not None:
            self._kill()
            self._start()
        return self

    @staticmethod
    def _pythonpath() -> str:
        """The parent's import path for the child, less the current folder (unless PYTHONPATH names it), and led
        by the folder this drivefuzz was imported from: the host runs the same drivefuzz as its parent, also when
        that is a checkout that is the current folder while another drivefuzz is installed (a benchmark run in a
        second worktree once timed the installed executor in both of its arms)."""
        try:
            cwd = os.getcwd()
        except OSError:  # the current folder was deleted
            cwd = ""
        asked = {os.path.abspath(p) for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p}
        keep = []
        for p in sys.path:
            if not p:
                continue
            p = os.path.abspath(p)
            if p == cwd and p not in asked:
                continue
            if p not in keep:
                keep.append(p)
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # holds drivefuzz/
        if root in keep:
            keep.remove(root)
        keep.insert(0, root)
        return os.pathsep.join(keep)

    def _start(self) -> None:
        env = dict(os.environ)
        # plugins importable in the parent (installed, or on a test's sys.path) must be importable here too
        env[PATH_ENV] = self._path = self._pythonpath()
        _sweep_orphans()
        self._tmp = tempfile.mkdtemp(prefix=f"drivefuzz-host-{os.getpid()}-")
        env["TMPDIR"] = self._tmp
        # its own session: a terminal's Ctrl-C does not reach it, and killpg also ends what a plugin started
        try:
            self.proc = subprocess.Popen([sys.executable, "-I", "-c", _BOOTSTRAP], stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, env=env, close_fds=True, start_new_session=True)
        except OSError:
            self._remove_tmp()
            raise
        self.starts += 1
        try:
            ready = _receive(self.proc.stdout.fileno(), time.monotonic() + START_TIMEOUT)
        except (TimeoutError, ProtocolError):
            ready = None
        if ready != ("ready",):
            self._kill()
            raise SimulationError(f"the simulation host did not start ({sys.executable} -I -c {_BOOTSTRAP!r})")

    def _kill(self) -> None:
        if self.proc is None:
            self._remove_tmp()
            return
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        self.proc.wait()
        for fh in (self.proc.stdin, self.proc.stdout):
            try:
                fh.close()
            except OSError:
                pass
        self.proc = None
        self._remove_tmp()

    def _remove_tmp(self) -> None:
        if self._tmp is not None:  # with whatever a child killed mid-execution left in it
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            try:
                _send(self.proc.stdin, ("exit",))
                self.proc.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                pass
        self._kill()

    def execute(self, scenario, oracle_settings: dict[str, Any] | None = None) -> Outcome:
        """Run ``scenario`` with the oracles of ``oracle_settings`` (OracleSettings.settings) in the child."""
        if self.proc is None or self.proc.poll() is not None or self._path != self._pythonpath():
            self._kill()  # dead, or the parent's import path changed (a plugin was just made importable)
            self._start()
        try:
            return self._execute(scenario, oracle_settings)
        except BaseException:  # e.g. Ctrl-C while waiting: the child's reply would be out of step
            self._kill()
            raise

    def _execute(self, scenario, oracle_settings) -> Outcome:
        t0 = time.monotonic()
        request = ("execute", scenario.model_dump(mode="json"), oracle_settings or {})
        try:
            _send(self.proc.stdin, request)
        except (BrokenPipeError, OSError):
            pass  # the child is already dead; reading below says how
        deadline = None if self.timeout_s is None else t0 + self.timeout_s
        try:
            reply = _receive(self.proc.stdout.fileno(), deadline)
        except TimeoutError:
            stack = self._stack(ask=True)
            self._kill()
            return Outcome(HANG, detail=f"no result within {self.timeout_s:g} s wall-clock",
                           error_type="timeout", wall_time=time.monotonic() - t0, traceback=stack,
                           plugin=blame_stack(stack))
        except (ProtocolError, pickle.UnpicklingError, EOFError) as exc:
            self._kill()
            return Outcome(INTERNAL_ERROR, detail=str(exc)[:500], error_type=type(exc).__name__,
                           wall_time=time.monotonic() - t0)
        if reply is None:
            rc = self.proc.wait()
            stack = self._stack()
            self._kill()
            name = _signal_name(rc)
            return Outcome(CRASH, detail=f"simulation process died: {name}", error_type=name,
                           wall_time=time.monotonic() - t0, traceback=stack, plugin=blame_stack(stack))
        wall = time.monotonic() - t0
        if reply[0] == OK:
            return Outcome(OK, execution=reply[1], wall_time=wall)
        _, status, error_type, detail, tb, *plugin = reply
        return Outcome(status, detail=detail, error_type=error_type, traceback=tb, wall_time=wall,
                       plugin=plugin[0] if plugin else "")


    def _stack(self, ask: bool = False) -> str:
        """The Python stack the child's faulthandler wrote (after a fatal signal; with ``ask``, of a live child
        that is sent SIGUSR1 for it and given up to 2 s to write it), or ""."""
        if self._tmp is None:
            return ""
        path = os.path.join(self._tmp, STACK_FILE)
        if ask and self.proc is not None and self.proc.poll() is None:
            try:
                os.kill(self.proc.pid, signal.SIGUSR1)
            except ProcessLookupError:
                pass
            size, end = -1, time.monotonic() + 2.0
            while time.monotonic() < end:  # until it stops growing: the handler writes it at once
                time.sleep(0.05)
                now = os.path.getsize(path) if os.path.exists(path) else 0
                if now and now == size:
                    break
                size = now
        try:
            with open(path, errors="replace") as fh:
                return fh.read(200_000)
        except OSError:
            return ""


def _sweep_orphans() -> None:
    """Remove the temporary folders of hosts whose parent was killed (SIGKILL skips every cleanup)."""
    import glob

    for path in glob.glob(os.path.join(tempfile.gettempdir(), "drivefuzz-host-*-*")):
        try:
            pid = int(os.path.basename(path).split("-")[2])
            if os.stat(path).st_uid != os.getuid():
                continue
            os.kill(pid, 0)
        except ProcessLookupError:  # its parent is gone
            shutil.rmtree(path, ignore_errors=True)
        except (ValueError, IndexError, OSError):  # not one of ours, or a live process of another user
            continue


# ------------------------------------------------------------------------ child side
def _watch_parent(parent: int) -> None:
    while True:
        time.sleep(0.5)
        if os.getppid() != parent:  # the parent died (SIGKILL skips every cleanup): do not outlive it
            os._exit(0)


def _die_with_parent() -> None:
    """Linux: the kernel kills this process when its parent dies, even while native code holds the GIL."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass


def _serve() -> None:
    parent = os.getppid()
    _die_with_parent()
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(0)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()
    # the protocol gets private copies of fds 0 and 1; whatever a plugin or SUMO writes to fd 1
    # (print, os.write, a subprocess) goes to stderr instead, and nothing can read the requests
    inp = os.fdopen(os.dup(0), "rb")
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    sys.stdout = sys.stderr
    # the stack on a fatal signal, or when the parent asks before killing a hung child (SUMO's or a plugin's?)
    stack = open(os.path.join(tempfile.gettempdir(), STACK_FILE), "w")
    faulthandler.enable(file=stack, all_threads=True)
    faulthandler.register(signal.SIGUSR1, file=stack, all_threads=True)

    from drivefuzz.sim.execute import execute
    from drivefuzz.oracle import OracleSettings
    from drivefuzz.scenario import Scenario

    _send(out, ("ready",))
    while True:
        header = inp.read(_HEADER.size)
        if len(header) < _HEADER.size:
            return
        msg = pickle.loads(inp.read(_HEADER.unpack(header)[1]))
        if msg[0] == "exit":
            return
        _, scenario_json, settings = msg
        os.ftruncate(stack.fileno(), 0)  # only this execution's stack
        os.lseek(stack.fileno(), 0, os.SEEK_SET)
        try:
            sc = Scenario.model_validate(scenario_json)
            ex = execute(sc, oracles=OracleSettings(settings=settings).instantiate())
            reply: tuple = (OK, ex)
        except PluginError as exc:
            reply = ("error", PLUGIN_ERROR, type(exc.__cause__ or exc).__name__, _one_line(exc), traceback.format_exc(),
                     exc.plugin)
        except SystemExit as exc:  # sys.exit() outside a plugin's call (execute names the plugin in those)
            reply = ("error", PLUGIN_ERROR, "SystemExit", f"sys.exit({exc.code!r}) called during the execution",
                     traceback.format_exc())
        except Exception as exc:  # noqa: BLE001 - reported to the parent, which records it and goes on
            reply = ("error", INTERNAL_ERROR, type(exc).__name__, _one_line(exc), traceback.format_exc())
        try:
            _send(out, reply)
        except Exception as exc:  # noqa: BLE001 - e.g. a plugin put something unpicklable in a Misbehavior
            _send(out, ("error", INTERNAL_ERROR, type(exc).__name__,
                        f"the result could not be sent back: {_one_line(exc)}", traceback.format_exc()))


def _one_line(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}" if not isinstance(exc, (PluginError, SimulationError)) else str(exc)
    return " ".join(text.split())[:500]


if __name__ == "__main__":
    _serve()
