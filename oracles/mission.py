"""Mission: the ego does not complete its mission (time-out, stops short, drives past the goal)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Sequence

from pydantic import Field

from drivefuzz.oracle import Frame, Misbehavior, Oracle, RunContext, Termination


class MissionOracle(Oracle):
    """Fires when the ego fails its mission, in one of three ways.

    The ego *is at the goal* when its centre is within ``distance`` of the goal
    point (``frame.goal_dist``); it is *stopped* while ``speed < stop_speed``.

    - ``"stopped_short"`` (during the run): the ADS declares its mission done
      (``frame.ads_done``) while the ego is not at the goal.
    - ``"overshoot"`` (during the run; the paper's bugs #16 and #24): the ego
      keeps driving past the goal. Either its centre, on the goal edge, is more
      than ``overshoot`` metres beyond ``goal_pos`` along the edge (centre
      position = ``frame.lane_pos`` of the front bumper minus half the ego's
      length) after it was on the goal edge at or before that point; or, after
      its centre was on the goal edge beyond ``goal_pos``, it is on any other
      edge (a junction, the next road) or off the road.
    - ``"timeout"``: at the end of a run that ended by the time limit
      (``Termination.TIME_LIMIT``; never when an oracle's misbehaviour ended
      the run, the ego was lost, or the goal was reached) with the ego not at
      the goal, unless the ego ends the run in a standstill of at least
      ``stop_time`` seconds.

    **One standstill, one finding.** A standstill away from the goal belongs
    to the immobility oracle, which fires once its illegitimate part exceeds
    its threshold (60 s) and judges whether a red light, a pedestrian or a
    queue excuses it. So a timed-out run that ends in a standstill as long as
    that threshold (``stop_time``, 60 s: keep the two equal) is left to it:
    immobility has fired on it, or the stop was legitimate (a blocked road is
    not the ADS's failure). The one standstill the mission owns is the one
    the ADS declares final (``"stopped_short"``, recorded the moment it is
    declared); immobility does not count the frames after that declaration.

    Each kind is recorded at most once per run, and no ``"timeout"`` follows a
    ``"stopped_short"`` or ``"overshoot"`` already recorded (possible only when
    the executor was told to go on after a misbehaviour).

    Details: ``goal_dist`` [m]; ``"overshoot"``: ``beyond`` [m past the goal
    along the edge, when on it], ``edge``; ``"stopped_short"``: ``stopped_for``
    [s], ``ads_done``; ``"timeout"``: ``time_limit`` [s], ``speed`` [m/s], ``stopped_for`` [s]
    (the standstill it ended in, 0 if moving).
    """

    name = "mission"
    description = "The ego fails its mission: does not reach the goal in time, stops short, or drives past it."

    class Config(Oracle.Config):
        distance: float = Field(5.0, ge=0.0, description="[m] from the goal point that counts as at the goal")
        stop_time: float = Field(60.0, ge=0.0, description="[s] a timed-out run ending in a standstill this long "
                                 "is left to immobility (keep equal to immobility.threshold)")
        stop_speed: float = Field(0.1, gt=0.0, description="[m/s] below which the ego counts as stopped")
        overshoot: float = Field(5.0, ge=0.0, description="[m] past the goal along the goal edge")

    def reset(self, ctx: RunContext) -> None:
        super().reset(ctx)
        sc = ctx.scenario
        self._goal_edge = sc.mission.goal_edge
        self._goal_pos = float(sc.mission.goal_pos)
        self._half_len = 0.5 * float(ctx.ego_length)
        self._approached = False  # centre on the goal edge, at or before goal_pos + overshoot
        self._passed = False  # centre on the goal edge beyond goal_pos
        self._stopped_since: float | None = None
        self._reported: set[str] = set()
        self._last = None

    def on_frame(self, frame: Frame) -> Sequence[Misbehavior]:
        c = self.config
        if frame.speed < c.stop_speed:
            if self._stopped_since is None:
                self._stopped_since = frame.t
        else:
            self._stopped_since = None
        self._last = (frame.index, frame.t, frame.x, frame.y, frame.goal_dist, frame.speed, frame.next_tls,
                      frame.ads_done)
        out: list[Misbehavior] = []
        if frame.ads_done and frame.goal_dist > c.distance and "stopped_short" not in self._reported:
            self._reported.add("stopped_short")
            out.append(self.report(frame, "stopped_short", (), goal_dist=round(frame.goal_dist, 3), ads_done=True,
                                   stopped_for=round(self._stopped_for(frame.t), 3)))
        if "overshoot" in self._reported:
            return tuple(out)
        if frame.edge == self._goal_edge:
            pos = frame.lane_pos - self._half_len
            if pos != pos:
                return tuple(out)
            if pos <= self._goal_pos + c.overshoot:
                self._approached = True
            elif self._approached:
                self._reported.add("overshoot")
                out.append(self.report(frame, "overshoot", (), goal_dist=round(frame.goal_dist, 3),
                                       beyond=round(pos - self._goal_pos, 3), edge=frame.edge))
                return tuple(out)
            if pos > self._goal_pos:
                self._passed = True
        elif self._passed:
            self._reported.add("overshoot")
            out.append(self.report(frame, "overshoot", (), goal_dist=round(frame.goal_dist, 3), beyond=None,
                                   edge=frame.edge))
        return tuple(out)

    def _stopped_for(self, t: float) -> float:
        return 0.0 if self._stopped_since is None else t - self._stopped_since

    def on_end(self, trace, termination: Termination) -> Sequence[Misbehavior]:
        c = self.config
        if termination is not Termination.TIME_LIMIT or self._last is None:
            return ()
        index, t, x, y, goal_dist, speed, nt, ads_done = self._last
        if goal_dist <= c.distance:
            return ()
        if self._reported & {"stopped_short", "overshoot"}:
            return ()
        snap = SimpleNamespace(index=index, t=t, x=x, y=y)
        stopped = self._stopped_for(t)
        if self._stopped_since is not None and stopped >= c.stop_time:
            return ()  # the immobility oracle's standstill
        self._reported.add("timeout")
        return (self.report(snap, "timeout", (), goal_dist=round(goal_dist, 3),
                            time_limit=float(self.ctx.scenario.sim.time_limit), speed=round(speed, 3),
                            stopped_for=round(stopped, 3)),)
