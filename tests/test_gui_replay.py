"""replay --gui: paced to real time, following the ego, stopping at the failure; what the files tell sumo-gui."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from drivefuzz.scenario import Mission, Puddle, Scenario
from drivefuzz.scenario.sumofiles import PUDDLE_LAYER, write_scenario
from drivefuzz.sim.gui import pace_delay

from conftest import ROOT, TOWN


@pytest.mark.parametrize("started, now, sim_time, speed, wait", [
    (100.0, 100.0, 1.0, 1.0, 1.0),    # real time: 1 simulated second takes 1 wall second
    (100.0, 100.5, 1.0, 1.0, 0.5),
    (100.0, 100.0, 1.0, 4.0, 0.25),   # --speed 4
    (100.0, 103.0, 1.0, 1.0, 0.0),    # behind: no wait
])
def test_pace_delay(started, now, sim_time, speed, wait):
    assert pace_delay(started, now, sim_time, speed) == pytest.approx(wait)


def test_the_sumocfg_says_how_to_watch_a_finding_and_puddles_lie_above_the_road(tmp_path):
    sc = Scenario(network=str(TOWN), mission=Mission(start_lane="A0B0_1", start_pos=10, goal_edge="B1C1", goal_pos=30),
                  puddles=(Puddle(x=60, y=0, length=10, width=8, friction=0.3),))
    write_scenario(sc, tmp_path)
    cfg = (tmp_path / "scenario.sumocfg").read_text()
    assert "drivefuzz drives the ego" in cfg and "drivefuzz replay" in cfg and cfg.index("<!--") < cfg.index("<configuration>")
    assert f'layer="{PUDDLE_LAYER}"' in (tmp_path / "fuzz.add.xml").read_text() and int(PUDDLE_LAYER) > 0


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs a virtual display (Debian's xvfb)")
def test_the_gui_follows_the_ego_at_the_asked_speed_and_stops_at_the_failure(tmp_path):
    script = f"""
import json, sys, time
sys.path.insert(0, {str(ROOT / 'tests')!r})
from drivefuzz.sim.gui import GuiView, VIEW
from drivefuzz.sim.execute import execute
from drivefuzz.scenario import Actor, AdsSpec, Mission, Scenario, SimOptions
from oracles.collision import CollisionOracle
sc = Scenario(network={str(TOWN)!r}, ads=AdsSpec(name="ego", options={{"fault": "ignore_pedestrians"}}),
              mission=Mission(start_lane="A0B0_1", start_pos=10.0, goal_edge="B0C0", goal_pos=40.0),
              actors=(Actor(id="p0", kind="pedestrian", nav="linear", start_lane="A0B0_0", start_pos=60.0, speed=0.3,
                            dest_xy=(68.4, 7.4)),), sim=SimOptions(time_limit=30.0))
seen = {{}}
class Spy(GuiView):
    def after_step(self, sim, t):
        super().after_step(sim, t)
        if self.tracking and "zoom" not in seen:
            seen["zoom"] = sim.gui.getZoom(VIEW)
    def end(self, sim, mbs):
        super().end(sim, mbs)
        seen["offset"] = sim.gui.getOffset(VIEW)
t0 = time.monotonic()
ex = execute(sc, oracles=[CollisionOracle()], gui=Spy(speed=4.0, hold=False))
m = ex.misbehaviors[0]
print(json.dumps({{"wall": time.monotonic() - t0, "sim": m.time, "pos": m.position, **seen}}))
"""
    proc = subprocess.run(["xvfb-run", "-a", sys.executable, "-c", script], capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-2000:]
    import json

    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["zoom"] == pytest.approx(800.0)
    assert got["wall"] >= got["sim"] / 4.0  # paced: no faster than 4x real time
    assert got["offset"] == pytest.approx(got["pos"], abs=0.01)  # the view is on the failure
