"""A third-party ADS plugin, installed for real: examples/ads-minimal, registered in ``drivefuzz.ads``.

The package is pip-installed into a temporary folder (``--target``), never into the shared
environment; entry points are found through the ``.dist-info`` folder on ``sys.path`` (in this
process) or on ``PYTHONPATH`` (in a ``drivefuzz`` subprocess).
"""

from __future__ import annotations

import importlib.util
import math
import os
import shutil
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pytest

from conftest import ROOT

EXAMPLE = ROOT / "examples" / "ads-minimal"
SEED = ROOT / "seeds" / "town" / "000"


def _setuptools_builds_wheels() -> bool:
    """Whether this environment can build a wheel with its own setuptools (no build isolation):
    setuptools >= 70.1 has ``bdist_wheel`` built in, older ones need the ``wheel`` package."""
    if importlib.util.find_spec("setuptools") is None:
        return False
    major, minor = (int(p) for p in version("setuptools").split(".")[:2])
    return (major, minor) >= (70, 1) or importlib.util.find_spec("wheel") is not None


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory) -> Path:
    """The example installed with pip into a fresh folder; returns that folder."""
    work = tmp_path_factory.mktemp("ads-minimal")
    src, target = work / "src", work / "site"
    shutil.copytree(EXAMPLE, src)  # setuptools writes build/ and *.egg-info next to the sources
    cmd = [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target)]
    if _setuptools_builds_wheels():
        cmd += ["--no-build-isolation", "--no-index"]  # offline, with this environment's setuptools
    # else pip builds in an isolated environment with setuptools from its configured index
    subprocess.run(cmd + [str(src)], check=True, timeout=300, capture_output=True, text=True)
    assert (target / "drivefuzz_ads_minimal.py").is_file()
    return target


def test_the_installed_plugin_is_found_through_its_entry_point(plugin_site, monkeypatch):
    from drivefuzz.ads import ADS, available_ads, load_ads

    assert "minimal" not in available_ads()  # not installed in the environment itself
    monkeypatch.syspath_prepend(str(plugin_site))
    eps = available_ads()
    assert eps["minimal"].value == "drivefuzz_ads_minimal:MinimalADS"
    ads = load_ads("minimal", {"speed": 6.0})
    assert isinstance(ads, ADS) and ads.name == "minimal"
    assert ads.options.speed == 6.0


def test_the_installed_plugin_drives_a_seed(plugin_site, monkeypatch):
    from drivefuzz.ads import load_ads
    from drivefuzz.sim.execute import execute
    from drivefuzz.scenario.sumofiles import read_scenario

    monkeypatch.syspath_prepend(str(plugin_site))
    sc = read_scenario(SEED)
    sc = sc.model_copy(update={"sim": sc.sim.model_copy(update={"time_limit": 15.0})})
    ex = execute(sc, ads=load_ads("minimal", {"speed": 6.0}))
    tr = ex.trace
    assert tr.n_frames > 100
    travelled = math.hypot(tr["x"][-1] - tr["x"][0], tr["y"][-1] - tr["y"][0])
    assert travelled > 30.0  # about 6 m/s for most of 15 s
    assert 5.0 < tr["speed"].max() < 7.0  # its constant speed, not more
    assert tr["throttle"].max() > 0.0


def _drivefuzz(plugin_site: Path, *args: str) -> subprocess.CompletedProcess:
    script = Path(sys.executable).with_name("drivefuzz")
    cmd = [str(script)] if script.is_file() else [sys.executable, "-m", "drivefuzz.cli"]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(plugin_site), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    return subprocess.run(cmd + list(args), env=env, capture_output=True, text=True, timeout=300)


def test_the_cli_lists_the_plugin_from_pythonpath(plugin_site):
    out = _drivefuzz(plugin_site, "ads")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    k = lines.index("minimal: drivefuzz_ads_minimal:MinimalADS")
    assert lines[k + 1].strip() == "speed = 8.0"


def test_the_cli_runs_a_seed_with_the_plugin(plugin_site):
    out = _drivefuzz(plugin_site, "run", str(SEED), "--ads", "minimal", "--ads-option", "speed=6")
    # it follows no route, so the oracles may well report it (exit 1); it must not be a usage error
    assert out.returncode in (0, 1), out.stdout + out.stderr
    assert out.stdout.startswith("town-seed-000: ")
    assert "frames" in out.stdout
