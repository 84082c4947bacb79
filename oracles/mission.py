"""Mission: the ego does not complete its mission (time-out, stops short, drives past the goal)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Sequence

from pydantic import Field

from drivefuzz.oracle import Frame, Misbehavior, Oracle, RunContext, Termination
from oracles import STOP_STATES


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
    - At the end of a run that ended by the time limit (``Termination.TIME_LIMIT``;
      never when an oracle's misbehaviour ended the run, the ego was lost, or
      the goal was reached) with the ego not at the goal:
      ``"stopped_short"`` if it has been stopped for at least ``stop_time``
      seconds at the end and is not waiting at a red light (the next light on
      its route shows a stop state within ``red_light_distance``); otherwise
      ``"timeout"``.

    Each kind is recorded at most once per run, and no ``"timeout"`` follows a
    ``"stopped_short"`` or ``"overshoot"`` already recorded (possible only when
    the executor was told to go on after a misbehaviour).

    Details: ``goal_dist`` [m]; ``"overshoot"``: ``beyond`` [m past the goal
    along the edge, when on it], ``edge``; ``"stopped_short"``: ``stopped_for``
    [s], ``ads_done``; ``"timeout"``: ``time_limit`` [s], ``speed`` [m/s].
    """

    name = "mission"
    description = "The ego fails its mission: does not reach the goal in time, stops short, or drives past it."

    class Config(Oracle.Config):
        distance: float = Field(5.0, ge=0.0, description="[m] from the goal point that counts as at the goal")
        stop_time: float = Field(20.0, ge=0.0, description="[s] stopped at the end of a timed-out run: stopped short")
        stop_speed: float = Field(0.1, gt=0.0, description="[m/s] below which the ego counts as stopped")
        overshoot: float = Field(5.0, ge=0.0, description="[m] past the goal along the goal edge")
        red_light_distance: float = Field(30.0, ge=0.0, description="[m] a red light this close excuses a stop")

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
        at_red = nt is not None and nt[3] in STOP_STATES and nt[2] <= c.red_light_distance
        if self._stopped_since is not None and stopped >= c.stop_time and not at_red:
            self._reported.add("stopped_short")
            return (self.report(snap, "stopped_short", (), goal_dist=round(goal_dist, 3), ads_done=bool(ads_done),
                                stopped_for=round(stopped, 3)),)
        self._reported.add("timeout")
        return (self.report(snap, "timeout", (), goal_dist=round(goal_dist, 3),
                            time_limit=float(self.ctx.scenario.sim.time_limit), speed=round(speed, 3)),)
