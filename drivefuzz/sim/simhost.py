"""Crash isolation: executions run in a persistent child process, the simulation host.

libsumo runs SUMO inside the Python process, so a segfault or abort in SUMO (or in
native code an ADS plugin loads) would kill whoever called it: a campaign, or a
Dask worker. The fuzz loop therefore sends each execution to a child process
and turns whatever goes wrong there into an :class:`Outcome`:

- ``ok``: the child returned the :class:`~drivefuzz.sim.execute.Execution`;
- ``simulator-crash``: the child died (a signal such as SIGSEGV/SIGABRT, or an exit);
- ``hang``: no answer within the wall-clock limit (the child is killed);
- ``plugin-error``: an ADS or oracle plugin raised (:class:`~drivefuzz.errors.PluginError`);
- ``internal-error``: any other exception in the child (a SUMO error, or a drivefuzz bug).

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

import os
import pickle
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

from drivefuzz.errors import PluginError, SimulationError

OK, CRASH, HANG, PLUGIN_ERROR, INTERNAL_ERROR = "ok", "simulator-crash", "hang", "plugin-error", "internal-error"
#: Finding kinds that are not oracle verdicts but failures of the system under test or of SUMO.
FAILURE_KINDS = (CRASH, HANG, PLUGIN_ERROR, INTERNAL_ERROR)

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
            self._kill()
            return Outcome(HANG, detail=f"no result within {self.timeout_s:g} s wall-clock",
                           error_type="timeout", wall_time=time.monotonic() - t0)
        except (ProtocolError, pickle.UnpicklingError, EOFError) as exc:
            self._kill()
            return Outcome(INTERNAL_ERROR, detail=str(exc)[:500], error_type=type(exc).__name__,
                           wall_time=time.monotonic() - t0)
        if reply is None:
            rc = self.proc.wait()
            self._kill()
            name = _signal_name(rc)
            return Outcome(CRASH, detail=f"simulation process died: {name}", error_type=name,
                           wall_time=time.monotonic() - t0)
        wall = time.monotonic() - t0
        if reply[0] == OK:
            return Outcome(OK, execution=reply[1], wall_time=wall)
        _, status, error_type, detail, tb = reply
        return Outcome(status, detail=detail, error_type=error_type, traceback=tb, wall_time=wall)


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
        try:
            sc = Scenario.model_validate(scenario_json)
            ex = execute(sc, oracles=OracleSettings(settings=settings).instantiate())
            reply: tuple = (OK, ex)
        except PluginError as exc:
            reply = ("error", PLUGIN_ERROR, type(exc.__cause__ or exc).__name__, _one_line(exc), traceback.format_exc())
        except SystemExit as exc:  # sys.exit() in a plugin must not end the host quietly
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
