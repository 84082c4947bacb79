"""An oracle written by a user, in its own package, works without changes to drivefuzz.

``examples/oracle-too-close`` is installed for real with pip into a temporary folder (not into the
environment running the tests), put on ``sys.path``, and found through the ``drivefuzz.oracles``
entry point: by :func:`available_oracles`, in a real SUMO run, and by ``drivefuzz oracles`` in a
subprocess.

Building the package with ``--no-build-isolation`` needs setuptools >= 70.1 (or the ``wheel``
package) in the environment; the ``test`` extra provides it.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from drivefuzz.sim.execute import execute
from drivefuzz.oracle import Misbehavior, OracleSettings, available_oracles, parse_oracle_options
from drivefuzz.scenario import Actor, Mission, Scenario, SimOptions
from ego.ads import ReferenceADS

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "oracle-too-close"
NET = str(ROOT / "networks" / "town.net.xml")


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """``pip install --target`` of a copy of the example (a build writes into its source tree)."""
    tmp = tmp_path_factory.mktemp("too_close")
    src, target = tmp / "src", tmp / "site"
    shutil.copytree(EXAMPLE, src, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    cmd = [sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--no-index",
           "--no-cache-dir", "--disable-pip-version-check", "--quiet", "--target", str(target), str(src)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"pip install failed (needs setuptools>=70.1 or wheel):\n{proc.stderr[-3000:]}"
    assert (target / "drivefuzz_too_close" / "__init__.py").is_file()
    return target


@pytest.fixture
def on_path(installed, monkeypatch) -> Path:
    monkeypatch.syspath_prepend(str(installed))
    yield installed
    for mod in [m for m in sys.modules if m == "drivefuzz_too_close" or m.startswith("drivefuzz_too_close.")]:
        del sys.modules[mod]


def test_not_installed_not_listed():
    assert "too_close" not in available_oracles()


def test_entry_point_lists_it_with_its_settings(on_path):
    oracles = available_oracles()
    assert {"too_close", "collision", "speeding"} <= set(oracles)
    cls = oracles["too_close"]
    assert cls.name == "too_close"
    assert Path(sys.modules[cls.__module__].__file__).is_relative_to(on_path)  # the installed copy
    assert set(cls.Config.model_fields) == {"enabled", "distance", "min_speed"}
    # settable and switchable like the built-in oracles
    names = {o.name for o in parse_oracle_options(["too_close.distance=2.5"]).instantiate()}
    assert "too_close" in names
    (o,) = [o for o in parse_oracle_options(["too_close.distance=2.5"]).instantiate() if o.name == "too_close"]
    assert o.config.distance == 2.5
    assert "too_close" not in {o.name for o in parse_oracle_options([], ["too_close"]).instantiate()}


class PedestrianBlindADS(ReferenceADS):
    """The reference ADS ignoring every other road user: it passes a walker at the kerb at speed."""

    def step(self, obs):
        return super().step(dataclasses.replace(obs, objects=()))


def _walker_at_kerb(y: float) -> Scenario:
    """The ego drives along A0B0_1 (centre y = -4.8, right edge y = -6.4, its right side at -5.75);
    a walker on the sidewalk (A0B0_0, y in [-8.4, -6.4]) walks slowly towards (58, y), near where the
    ego passes it at ~28 km/h."""
    walker = Actor(id="walker", kind="pedestrian", nav="linear", start_lane="A0B0_0", start_pos=60.0, speed=1.0,
                   dest_xy=(58.0, y))
    return Scenario(network=NET, mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="A0B0", goal_pos=90.0),
                    sim=SimOptions(time_limit=25.0), actors=(walker,))


def _run(sc: Scenario):
    oracles = [o for o in OracleSettings().instantiate() if o.name in ("too_close", "collision")]
    assert [o.name for o in oracles] == ["collision", "too_close"]
    return execute(sc, ads=PedestrianBlindADS(), oracles=oracles, stop_on_misbehavior=False)


def test_fires_in_a_real_run_when_passing_close(on_path):
    ex = _run(_walker_at_kerb(-6.45))
    found = [m for m in ex.misbehaviors if m.oracle == "too_close"]
    assert [(m.kind, m.actors) for m in found] == [("pedestrian", ("walker",))]
    (m,) = found
    assert 0.0 < m.details["gap"] <= 1.0 and m.details["ego_speed"] > 3.0
    assert 40.0 < m.position[0] < 62.0  # beside the walker, not somewhere else on the way
    assert not [m for m in ex.misbehaviors if m.oracle == "collision"]  # close, but no contact
    assert Misbehavior.from_dict(m.as_dict()) == m


def test_silent_when_the_walker_stands_farther_away(on_path):
    ex = _run(_walker_at_kerb(-8.2))
    assert ex.misbehaviors == ()
    # the twin really passed the walker, at speed, a little more than 2 m away
    tr, a = ex.trace, ex.trace.actors
    rows = a.actor == a.ids.index("walker")
    f = a.frame[rows]
    passing = abs(tr["x"][f] - a.x[rows]) < 2.0
    assert passing.any() and tr["speed"][f][passing].min() > 3.0
    assert (abs(tr["y"][f] - a.y[rows])[passing] > 2.5).all()


def test_cli_lists_it_in_a_subprocess(installed):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(installed), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    cli = Path(sys.executable).with_name("drivefuzz")
    out = subprocess.run([str(cli), "oracles"], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "too_close: The ego passes a pedestrian" in out.stdout
    assert "too_close.distance = 1.0" in out.stdout and "too_close.min_speed = 3.0" in out.stdout
    assert "collision:" in out.stdout  # the built-ins are still there
    # and without the package on the path it is not
    env.pop("PYTHONPATH")
    out = subprocess.run([str(cli), "oracles"], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0 and "too_close" not in out.stdout
