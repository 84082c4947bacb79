"""Immobility: the ego stands still for too long without a legitimate reason."""

from __future__ import annotations

import math
from typing import Sequence

from pydantic import Field

from drivefuzz.oracle import Frame, Misbehavior, Oracle, RunContext
from oracles import STOP_STATES


class ImmobilityOracle(Oracle):
    """Fires when the ego has been stopped without a legitimate reason for longer than ``threshold``.

    The ego is *stopped* while ``frame.speed < stop_speed``; a *standstill* is
    an unbroken run of stopped frames. Within a standstill the oracle adds up
    the time without a legitimate reason (each frame interval counts when the
    frame that starts it has none) and fires once that sum exceeds
    ``threshold`` (once per standstill). Moving ends the standstill and clears
    the sum. Legitimate intervals pause the clock but do not clear it, so an
    ego that never goes on green is caught even though each red phase
    excuses it again.

    Frames in which the ADS has declared its mission done (``frame.ads_done``)
    do not count either: that stop is the mission oracle's ``stopped_short``,
    recorded the moment it is declared, and one standstill is one finding. In
    turn the mission oracle leaves a time-out that ends in a standstill of
    this oracle's threshold to this oracle (see :class:`oracles.mission.MissionOracle`).

    A stop is legitimate in a frame when one of these holds (checked in order):

    1. **Goal**: the ego is within ``goal_distance`` of the goal point.
    2. **Red light**: the next traffic light on the route (``frame.next_tls``)
       shows red, red-yellow or yellow (``r``, ``u``, ``y``, ``Y``) and its stop
       line is at most ``red_light_distance`` ahead of the front bumper; or the
       ego is on a signalised lane (``frame.lane_links``) whose vehicle links all
       show one of those states and the lane end is at most
       ``red_light_distance`` ahead.
    3. **Pedestrian**: a pedestrian is in the ego's path ahead: its centre is
       between the ego's front bumper and ``pedestrian_distance`` beyond it
       along the ego's heading, and at most ``ego_width / 2 +
       pedestrian_lateral`` to either side of the ego's axis (a pedestrian on
       the crossing in front, or on the road).
    4. **Queue**: the nearest vehicle ahead (centre ahead of the ego's front
       bumper along the heading, at most ``queue_lateral`` to either side of
       the ego's axis, bumper gap at most ``queue_gap``) is either moving
       (``speed >= stop_speed``: the ego is in a moving queue) or is itself
       legitimately stopped, judged from its own pose by the same rules: its
       front within ``red_light_distance`` of the stop line of the ego's next
       traffic light while that shows a stop state (it waits at the red light
       the ego approaches), a pedestrian in its path, or a legitimately stopped
       or moving vehicle ahead of it (recursively, up to ``max_queue`` vehicles).

    Not legitimate, among others: standing behind a vehicle that never moves
    (a broken-down or ``immobile`` car with no light or pedestrian in front of
    it: an ADS should pass it), stopping on green, stopping in the middle of
    the road or at the side of the road away from the goal.

    Kind ``"immobile"``; details: ``stopped_for`` [s] (without a legitimate
    reason), ``standstill`` [s] (in all), ``since`` [s] (simulation time the
    standstill began), ``lane``.
    """

    name = "immobility"
    description = "The ego stands still too long without a legitimate reason (red light, pedestrian, queue, goal)."

    class Config(Oracle.Config):
        threshold: float = Field(60.0, gt=0.0, description="[s] of illegitimate standstill before firing")
        stop_speed: float = Field(0.1, gt=0.0, description="[m/s] below which the ego counts as stopped")
        red_light_distance: float = Field(30.0, ge=0.0, description="[m] stop line ahead of the front bumper")
        pedestrian_distance: float = Field(20.0, ge=0.0, description="[m] ahead of the front bumper")
        pedestrian_lateral: float = Field(1.5, ge=0.0, description="[m] beside the ego's body")
        queue_gap: float = Field(10.0, ge=0.0, description="[m] bumper gap to the vehicle ahead")
        queue_lateral: float = Field(1.6, ge=0.0, description="[m] centre offset from the axis")
        max_queue: int = Field(30, ge=1, description="vehicles followed along a queue")
        goal_distance: float = Field(5.0, ge=0.0, description="[m] from the goal point")

    def reset(self, ctx: RunContext) -> None:
        super().reset(ctx)
        c = self.config
        self._stop = float(c.stop_speed)
        self._threshold = float(c.threshold)
        self._since: float | None = None  # start of the current standstill
        self._illegit = 0.0  # [s] of it without a legitimate reason
        self._legit = False
        self._last_t = 0.0
        self._fired = False
        self._half_len = 0.5 * float(ctx.ego_length)
        self._half_wid = 0.5 * float(ctx.ego_width)
        self._rmap = ctx.roadmap
        self._lane_len: dict[str, float] = {}

    def on_frame(self, frame: Frame) -> Sequence[Misbehavior]:
        t = frame.t
        if frame.speed >= self._stop:
            self._since = None
            self._fired = False
            return ()
        if self._since is None:  # a new standstill
            self._since, self._illegit, self._last_t = t, 0.0, t
            self._legit = frame.ads_done or self.legitimate(frame) is not None
            return ()
        dt = t - self._last_t
        self._last_t = t
        if self._fired:
            return ()
        # the time since the previous frame counts if the stop was illegitimate then (re-checked
        # every frame: the reasons change at a light's switch or when a pedestrian walks off)
        if not self._legit:
            self._illegit += dt
        self._legit = frame.ads_done or self.legitimate(frame) is not None
        if self._illegit <= self._threshold:
            return ()
        self._fired = True
        return (self.report(frame, "immobile", (), stopped_for=round(self._illegit, 3),
                            standstill=round(t - self._since, 3), since=round(self._since, 3), lane=frame.lane),)

    # ------------------------------------------------------------------ reasons
    def legitimate(self, frame: Frame) -> str | None:
        """The legitimate reason the ego stands still in ``frame`` (``None``: there is none)."""
        c = self.config
        if frame.goal_dist <= c.goal_distance:
            return "goal"
        red = self._red_ahead(frame)
        if red is not None and red <= c.red_light_distance:
            return "red_light"
        kinds = frame.actor_kinds
        if not len(kinds):
            return None
        # plain Python on lists: for a few dozen actors this is several times cheaper than numpy
        # (the arithmetic is the same IEEE double arithmetic, so the decisions are identical)
        ax, ay = frame.actor_x.tolist(), frame.actor_y.tolist()
        peds = [k for k, kind in enumerate(kinds) if kind == "pedestrian"]
        h = frame.heading
        if self._blocked_by_pedestrian(frame.x, frame.y, h, self._half_len, self._half_wid, ax, ay, peds):
            return "pedestrian"
        # vehicles: follow the queue ahead
        if len(peds) == len(kinds):
            return None
        pedset = set(peds)
        vehs = [k for k in range(len(kinds)) if k not in pedset]
        vl = frame.actor_length.tolist()
        lateral, max_gap = c.queue_lateral, c.queue_gap
        ch, sh = math.cos(h), math.sin(h)
        px, py, phl, ph = frame.x, frame.y, self._half_len, h
        visited: set[int] = set()
        for _ in range(c.max_queue):
            cp, sp = math.cos(ph), math.sin(ph)
            k, best = -1, math.inf  # the nearest vehicle ahead (first row on a tie)
            for j in vehs:
                dx, dy = ax[j] - px, ay[j] - py
                along = dx * cp + dy * sp
                if along <= phl or along >= best or j in visited:
                    continue
                if abs(-dx * sp + dy * cp) <= lateral and along - phl - 0.5 * vl[j] <= max_gap:
                    k, best = j, along
            if k < 0:
                return None
            visited.add(k)
            if frame.actor_speed[k] >= self._stop:
                return "queue"
            lx, ly, lh, lhl = ax[k], ay[k], float(frame.actor_heading[k]), 0.5 * vl[k]
            lhw = 0.5 * float(frame.actor_width[k])
            if red is not None:
                # the leader's front, projected on the ego's heading, ahead of the ego's front bumper
                lead_front = (lx - frame.x) * ch + (ly - frame.y) * sh + lhl - self._half_len
                if red - lead_front <= c.red_light_distance:
                    return "queue"
            if self._blocked_by_pedestrian(lx, ly, lh, lhl, lhw, ax, ay, peds):
                return "queue"
            px, py, ph, phl = lx, ly, lh, lhl
        return None

    def _red_ahead(self, frame: Frame) -> float | None:
        """Distance [m] from the front bumper to a stop line ahead showing a stop state, or None."""
        nt = frame.next_tls
        if nt is not None and nt[3] in STOP_STATES:
            return float(nt[2])
        links = frame.lane_links
        if links and all(l.state in STOP_STATES for l in links) and frame.lane_pos == frame.lane_pos:
            length = self._lane_len.get(frame.lane)
            if length is None:
                length = self._lane_len[frame.lane] = float(self._rmap.geom(frame.lane).length)
            return max(length - frame.lane_pos, 0.0)
        return None

    def _blocked_by_pedestrian(self, x, y, h, hl, hw, ax, ay, peds) -> bool:
        """A pedestrian (rows ``peds`` of the lists ``ax``, ``ay``) in the path ahead of the body at (x, y, h)."""
        if not peds:
            return False
        c = self.config
        cp, sp = math.cos(h), math.sin(h)
        reach, lim = c.pedestrian_distance, hw + c.pedestrian_lateral
        for k in peds:
            dx, dy = ax[k] - x, ay[k] - y
            along = dx * cp + dy * sp - hl
            if 0.0 <= along <= reach and abs(-dx * sp + dy * cp) <= lim:
                return True
        return False
