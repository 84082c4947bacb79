"""The ``too_close`` oracle: the ego passes a pedestrian too closely, too fast.

An example of an oracle plugin living in its own package; it is registered in the
``drivefuzz.oracles`` entry-point group by this package's ``pyproject.toml``.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from pydantic import Field

from drivefuzz.geometry import rect_distance
from drivefuzz.oracle import Frame, Misbehavior, Oracle, RunContext

__all__ = ["TooCloseOracle"]


class TooCloseOracle(Oracle):
    """Fires when the ego's body comes within ``distance`` of a pedestrian's body while the ego
    drives faster than ``min_speed``.

    - Bodies are oriented rectangles: the ego's from ``frame.x/y/heading`` and
      ``ctx.ego_length/width``, each pedestrian's from its row of ``frame.actor_*``. The
      distance is the exact gap between the two rectangles (0 when they touch or overlap:
      a contact is also "too close"; the collision oracle reports it as well).
    - Only pedestrians within ``distance`` plus both half-diagonals (centre to centre) are
      measured exactly, so a frame costs a few vector operations.
    - One record per pedestrian per episode: a new one only after that pedestrian was
      farther than ``distance`` again, or the ego slowed to ``min_speed`` or below.

    Kind ``"pedestrian"``; ``actors=(pedestrian id,)``; details: ``gap`` [m] (the distance
    between the bodies), ``ego_speed`` [m/s], ``ego_speed_kmh``, ``distance`` and ``min_speed``
    (the settings that applied).
    """

    name = "too_close"
    description = "The ego passes a pedestrian closer than a set distance while faster than a set speed."

    class Config(Oracle.Config):
        distance: float = Field(1.0, ge=0.0, description="[m] body-to-body gap that is too close")
        min_speed: float = Field(3.0, ge=0.0, description="[m/s] the ego must be faster than this")

    def reset(self, ctx: RunContext) -> None:
        super().reset(ctx)
        self._len = float(ctx.ego_length)
        self._wid = float(ctx.ego_width)
        self._dist = float(self.config.distance)
        self._vmin = float(self.config.min_speed)
        self._reach = self._dist + 0.5 * math.hypot(self._len, self._wid)
        self._close: set[str] = set()  # pedestrians in a reported episode

    def on_frame(self, frame: Frame) -> Sequence[Misbehavior]:
        if frame.speed <= self._vmin or not len(frame.actor_ids):
            self._close.clear()
            return ()
        ped = np.fromiter((k == "pedestrian" for k in frame.actor_kinds), dtype=bool, count=len(frame.actor_kinds))
        ax, ay = frame.actor_x, frame.actor_y
        reach = self._reach + 0.5 * np.hypot(frame.actor_length, frame.actor_width)
        near = ped & (np.hypot(ax - frame.x, ay - frame.y) <= reach)
        rows = np.flatnonzero(near)
        if not len(rows):
            self._close.clear()
            return ()
        gap = rect_distance(frame.x, frame.y, frame.heading, self._len, self._wid, ax[rows], ay[rows],
                            frame.actor_heading[rows], frame.actor_length[rows], frame.actor_width[rows])
        out = []
        close = set()
        for k, g in zip(rows.tolist(), np.atleast_1d(gap).tolist()):
            if g > self._dist:
                continue
            pid = frame.actor_ids[k]
            close.add(pid)
            if pid not in self._close:
                out.append(self.report(frame, "pedestrian", (pid,), gap=round(g, 3), ego_speed=round(frame.speed, 3),
                                       ego_speed_kmh=round(frame.speed * 3.6, 2), distance=self._dist,
                                       min_speed=self._vmin))
        self._close = close
        return tuple(out)
