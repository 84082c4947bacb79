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
    """Feed-forward of the planned acceleration plus a proportional term on speed error."""

    def __init__(self, max_accel: float = 3.5, max_decel: float = 9.0, kp: float = 0.4):
        self.max_accel = max_accel
        self.max_decel = max_decel
        self.kp = kp

    def pedals(self, accel: float, speed: float, target: float) -> tuple[float, float]:
        a = accel + self.kp * (target - speed) * (1.0 if accel < 0 and target < speed else 0.0)
        if a >= 0.0:
            return min(a / self.max_accel, 1.0), 0.0
        if speed < 0.05 and accel <= 0.0:
            return 0.0, 0.3  # hold still
        return 0.0, min(-a / self.max_decel, 1.0)
