"""Actuation: pure-pursuit path tracking and speed control into steering and pedal commands."""

from __future__ import annotations

import math

from ego.planning import Path


class PurePursuit:
    def __init__(self, wheelbase: float, max_road_wheel_angle: float, k_lookahead: float = 0.6, min_lookahead: float = 4.0):
        self.L = wheelbase
        self.max_delta = max_road_wheel_angle
        self.k = k_lookahead
        self.min_ld = min_lookahead

    def steer(self, path: Path, s_rear: float, rx: float, ry: float, heading: float, speed: float) -> float:
        """Normalised steering command [-1, 1], left positive."""
        ld = max(self.min_ld, self.k * speed)
        tx, ty = path.point_at(s_rear + ld)
        alpha = math.atan2(ty - ry, tx - rx) - heading
        delta = math.atan2(2.0 * self.L * math.sin(alpha), ld)
        return max(-1.0, min(1.0, delta / self.max_delta))


class SpeedController:
    """Feed-forward of the planned acceleration plus a proportional term on speed error.

    The proportional term only adds braking while the planner brakes above its target speed, and
    at most ``max_feedback`` [m/s^2]: the planner has already chosen how hard to brake, and an
    unbounded term turned a drop of the target (a lower speed limit) into full braking.
    """

    def __init__(self, max_accel: float = 3.5, max_decel: float = 9.0, kp: float = 0.4,
                 max_feedback: float = 1.0):
        self.max_accel = max_accel
        self.max_decel = max_decel
        self.kp = kp
        self.max_feedback = max_feedback

    def pedals(self, accel: float, speed: float, target: float) -> tuple[float, float]:
        """(throttle, brake) in [0, 1] for the planned ``accel`` [m/s^2] at ``speed`` towards
        ``target`` [m/s]."""
        a = accel
        if accel < 0 and target < speed:
            a -= min(self.kp * (speed - target), self.max_feedback)
        if a >= 0.0:
            return min(a / self.max_accel, 1.0), 0.0
        if speed < 0.05 and accel <= 0.0:
            return 0.0, 0.3  # hold still
        return 0.0, min(-a / self.max_decel, 1.0)
