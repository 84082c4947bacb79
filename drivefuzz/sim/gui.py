"""How ``drivefuzz replay --gui`` shows a run in sumo-gui, so that a person can follow it.

- The view follows the ego (``gui.trackVehicle``) at a street-level zoom.
- Steps are paced by the wall clock to ``speed`` times real time (1.0: real time), not by SUMO's
  ``--delay``, which adds a fixed pause per step whatever the step length.
- At the end the view centres on the failure and stays open (``hold``) until the window is closed.

The executor calls :meth:`GuiView.start`, :meth:`GuiView.after_step` and :meth:`GuiView.end`; nothing
here runs without a display except :func:`pace_delay`.
"""

from __future__ import annotations

import time
from typing import Callable, Sequence

#: sumo-gui's first (and only) view
VIEW = "View #0"


def pace_delay(started: float, now: float, sim_time: float, speed: float) -> float:
    """[s] to wait so that ``sim_time`` simulated seconds take ``sim_time / speed`` wall seconds since
    ``started``; 0 when the run is behind."""
    return max(started + sim_time / speed - now, 0.0)


class GuiView:
    def __init__(self, speed: float = 1.0, hold: bool = True, zoom: float = 800.0,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 say: Callable[[str], None] = lambda s: None):
        if not speed > 0:
            raise ValueError(f"speed must be positive, not {speed!r}")
        self.speed, self.hold, self.zoom = speed, hold, zoom
        self.clock, self.sleep, self.say = clock, sleep, say
        self.started = 0.0
        self.tracking = False

    def start(self, sim) -> None:
        self.started = self.clock()

    def after_step(self, sim, sim_time: float) -> None:
        if not self.tracking and "ego" in sim.vehicle.getIDList():
            sim.gui.trackVehicle(VIEW, "ego")
            sim.gui.setZoom(VIEW, self.zoom)
            self.tracking = True
        wait = pace_delay(self.started, self.clock(), sim_time, self.speed)
        if wait > 0:
            self.sleep(wait)

    def end(self, sim, misbehaviors: Sequence) -> None:
        """Centre the view on the first misbehaviour, then keep the window open until it is closed."""
        if misbehaviors and getattr(misbehaviors[0], "frame", -1) >= 0:
            m = misbehaviors[0]
            sim.gui.trackVehicle(VIEW, "")
            sim.gui.setOffset(VIEW, float(m.position[0]), float(m.position[1]))
            self.say(f"stopped at the failure: {m.oracle}/{m.kind} at {m.time:.2f} s (frame {m.frame})")
        if not self.hold:
            return
        self.say("close the sumo-gui window to finish")
        try:
            while True:
                self.sleep(0.25)
                sim.simulation.getTime()  # raises once the window is closed
        except Exception:  # noqa: BLE001 - traci's FatalTraCIError: the user closed the window
            return
