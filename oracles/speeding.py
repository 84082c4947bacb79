"""Speeding: the ego drives faster than the speed limit of the lane it is on."""

from __future__ import annotations

import math
from typing import Sequence

from pydantic import Field

from drivefuzz.oracle import Frame, Misbehavior, Oracle, RunContext
from oracles import kmh


class SpeedingOracle(Oracle):
    """Fires when ``frame.speed > frame.speed_limit + tolerance``.

    - The limit is SUMO's ``maxSpeed`` of the lane under the ego (junction
      lanes have their own, often lower, limits). Off-road (limit NaN) nothing
      is checked.
    - ``grace`` seconds after the limit changes are not checked, so a driver
      has time to slow down for a lower limit; the first ``grace`` seconds of a
      run count as such a change. Leaving the road and coming back onto a lane
      with the same limit as before is not a change.
    - With the executor told to go on after a misbehaviour, one record is made
      per episode: a new one only after the ego was back within the limit.

    Kind ``"speeding"``; details: ``speed``, ``limit``, ``excess`` [m/s], the same
    in km/h, and ``lane``.
    """

    name = "speeding"
    description = "The ego drives faster than the lane's speed limit (with a tolerance and a grace period)."

    class Config(Oracle.Config):
        tolerance: float = Field(0.0, ge=0.0, description="[m/s] allowed above the limit")
        grace: float = Field(3.0, ge=0.0, description="[s] not checked after a limit change and at the start")

    def reset(self, ctx: RunContext) -> None:
        super().reset(ctx)
        self._limit = math.nan  # last known (non-NaN) limit
        self._changed_at = 0.0
        self._episode = False
        self._tol = float(self.config.tolerance)
        self._grace = float(self.config.grace)

    def on_frame(self, frame: Frame) -> Sequence[Misbehavior]:
        limit = frame.speed_limit
        if limit != limit:  # NaN: off-road
            return ()
        if limit != self._limit:
            if self._limit == self._limit:  # a real change, not the first limit of the run
                self._changed_at = frame.t
            self._limit = limit
        speed = frame.speed
        if speed <= limit + self._tol:
            self._episode = False
            return ()
        if frame.t - self._changed_at < self._grace or self._episode:
            return ()
        self._episode = True
        return (self.report(frame, "speeding", (), speed=round(speed, 3), limit=round(limit, 3),
                            excess=round(speed - limit, 3), speed_kmh=kmh(speed), limit_kmh=kmh(limit),
                            lane=frame.lane),)
