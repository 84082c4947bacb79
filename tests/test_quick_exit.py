"""``drivefuzz run`` (and ``seed``, ``replay``) end their process without freeing a road map object by
object: the exit status, everything printed and written, and the atexit handlers are as before."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SEED = ROOT / "seeds" / "town" / "000"


def _python(code: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)


def test_run_exits_with_its_status_its_output_and_its_atexit_handlers(tmp_path):
    from drivefuzz.sim.trace import Trace

    trace = tmp_path / "trace"
    r = _python("import atexit, sys\n"
                "atexit.register(lambda: print('atexit ran', flush=True))\n"
                "class Freed:\n"
                "    def __del__(self): print('freed one by one', flush=True)\n"
                "kept = Freed()\n"
                f"sys.argv = ['drivefuzz', 'run', {str(SEED)!r}, '--trace', {str(trace)!r}]\n"
                "from drivefuzz.cli import main\n"
                "main()\n"
                "print('not reached')")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert "goal_reached" in lines[0] and "quality score" in lines[1] and "trace saved" in lines[2]
    assert lines[-1] == "atexit ran" and "not reached" not in r.stdout and "freed" not in r.stdout
    assert Trace.load(trace).n_frames > 100
    bad = _python("import sys\n"
                  f"sys.argv = ['drivefuzz', 'run', {str(tmp_path / 'none')!r}]\n"
                  "from drivefuzz.cli import main\n"
                  "main()")
    assert bad.returncode == 2 and bad.stderr.startswith("drivefuzz: error:") and len(bad.stderr.splitlines()) == 1


def test_in_process_callers_are_not_ended(tmp_path):
    from click.testing import CliRunner

    from drivefuzz.cli import main

    r = CliRunner().invoke(main, ["run", str(SEED)])
    assert r.exit_code == 0 and "goal_reached" in r.output  # still here: CliRunner passes its arguments
