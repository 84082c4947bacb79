"""drivefuzz's built-in misbehaviour oracles (the paper's tbl:oracle).

Each module holds one :class:`drivefuzz.oracle.Oracle` subclass, registered in
the ``drivefuzz.oracles`` entry-point group:

========================  ============================================================
``collision``             the ego's body overlaps a vehicle, a pedestrian or an obstacle
``lane_invasion``         the ego's body enters an opposite lane, a sidewalk, leaves the
                          road, or crosses a lane boundary where changing is forbidden
``speeding``              the ego is faster than the lane's limit
``red_light``             the ego's front bumper crosses a stop line on red (yellow opt-in)
``immobility``            the ego stands still too long without a legitimate reason
``mission``               the ego does not complete its mission (time-out, stops short,
                          or drives past the goal)
========================  ============================================================

Every oracle is cheap per frame (a few microseconds on the common path: the
executor calls all of them after every simulation step) and keeps only a few
scalars of state. Units are SI (m, s, m/s); reports add km/h where a person
reads speeds.

This module holds the small helpers several oracles share; ``lane_index`` holds the
lane-invasion oracle's network geometry (built on demand, its junction areas cached on disk).
"""

from __future__ import annotations

import math

#: Signal states that forbid entering (``u`` is red-yellow: still red).
RED_STATES = frozenset("ru")
#: Yellow (amber) states.
YELLOW_STATES = frozenset("yY")
#: States at which a lawful driver stops (or stays stopped).
STOP_STATES = RED_STATES | YELLOW_STATES

KMH = 3.6


def kmh(v: float) -> float:
    """m/s -> km/h, rounded for reports."""
    return round(v * KMH, 2)


def wrap_angle(a: float) -> float:
    """Angle difference wrapped into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi
