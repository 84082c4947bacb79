"""Vectorised oriented-rectangle geometry: vehicle and pedestrian bodies as rectangles.

Used by the driving-quality score (minimum ego-actor distance, :mod:`drivefuzz.search.quality`)
and by the collision oracle.

A body is ``(x, y, heading, length, width)``: ``x, y`` the *geometric centre* [m],
``heading`` ENU [rad] (0 = east, counter-clockwise; the length runs along the heading),
``length``/``width`` the full extents [m]. Every function broadcasts its arguments with
numpy rules, so one call handles a frame's worth of actors or a whole trace of pairs.

All results are exact up to floating-point rounding (no sampling, no circles):

* overlap is decided with the separating-axis theorem on the four edge normals;
* the distance between disjoint rectangles is the minimum of the 32 vertex-to-edge
  distances (for two disjoint convex polygons the closest pair always involves a vertex);
* the penetration depth is the smallest overlap of the projections on the four edge
  normals, i.e. the length of the minimum translation that separates the bodies.
"""

from __future__ import annotations

import numpy as np

__all__ = ["corners", "rect_distance", "rect_penetration", "rects_overlap"]

_TINY = 1e-300


def _f(a) -> np.ndarray:
    return np.asarray(a, dtype=float)


def corners(x, y, heading, length, width) -> np.ndarray:
    """Corners of oriented rectangles, shape ``broadcast(...).shape + (4, 2)``.

    Order is counter-clockwise: front-right, front-left, rear-left, rear-right.
    """
    x, y, heading, length, width = np.broadcast_arrays(_f(x), _f(y), _f(heading), _f(length), _f(width))
    c, s = np.cos(heading), np.sin(heading)
    hl, hw = 0.5 * length, 0.5 * width
    # body-frame offsets (forward, left) of the four corners
    fwd = np.stack([hl, hl, -hl, -hl], axis=-1)
    left = np.stack([-hw, hw, hw, -hw], axis=-1)
    c, s = c[..., None], s[..., None]
    out = np.empty(x.shape + (4, 2))
    out[..., 0] = x[..., None] + fwd * c - left * s
    out[..., 1] = y[..., None] + fwd * s + left * c
    return out


def _sat_depth(ax, ay, ah, al, aw, bx, by, bh, bl, bw) -> np.ndarray:
    """Minimum over the four edge normals of (sum of projected half-extents - |centre offset|).

    ``>= 0`` iff the rectangles intersect (touching gives 0); when positive it is the
    penetration depth.
    """
    dx, dy = bx - ax, by - ay
    ca, sa = np.cos(ah), np.sin(ah)
    cb, sb = np.cos(bh), np.sin(bh)
    # cos/sin of the relative heading, for the projections of one rectangle's axes on the other's
    cr = np.abs(ca * cb + sa * sb)
    sr = np.abs(sa * cb - ca * sb)
    hal, haw, hbl, hbw = 0.5 * al, 0.5 * aw, 0.5 * bl, 0.5 * bw
    # axes of A: its forward (ca, sa) and left (-sa, ca)
    d1 = hal + hbl * cr + hbw * sr - np.abs(dx * ca + dy * sa)
    d2 = haw + hbl * sr + hbw * cr - np.abs(-dx * sa + dy * ca)
    # axes of B
    d3 = hbl + hal * cr + haw * sr - np.abs(dx * cb + dy * sb)
    d4 = hbw + hal * sr + haw * cr - np.abs(-dx * sb + dy * cb)
    return np.minimum(np.minimum(d1, d2), np.minimum(d3, d4))


def _points_to_edges(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Min distance from each of 4 points ``p`` (..., 4, 2) to the 4 edges of ``poly`` (..., 4, 2)."""
    a = poly[..., None, :, :]  # (..., 1, 4, 2) edge starts
    b = np.roll(poly, -1, axis=-2)[..., None, :, :]  # edge ends
    q = p[..., :, None, :]  # (..., 4, 1, 2)
    ex, ey = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    px, py = q[..., 0] - a[..., 0], q[..., 1] - a[..., 1]
    den = ex * ex + ey * ey
    t = np.clip((px * ex + py * ey) / np.maximum(den, _TINY), 0.0, 1.0)
    d = np.hypot(px - t * ex, py - t * ey)  # (..., 4, 4)
    return d.min(axis=(-2, -1))


def rect_distance(ax, ay, ah, al, aw, bx, by, bh, bl, bw) -> np.ndarray:
    """Minimum distance [m] between rectangle A and rectangle B (0 when they touch or overlap).

    Arguments broadcast together; the result has the broadcast shape (a 0-d array for scalars).
    """
    args = np.broadcast_arrays(*(_f(v) for v in (ax, ay, ah, al, aw, bx, by, bh, bl, bw)))
    ax, ay, ah, al, aw, bx, by, bh, bl, bw = args
    overlap = _sat_depth(ax, ay, ah, al, aw, bx, by, bh, bl, bw) >= 0.0
    ca = corners(ax, ay, ah, al, aw)
    cb = corners(bx, by, bh, bl, bw)
    d = np.minimum(_points_to_edges(ca, cb), _points_to_edges(cb, ca))
    return np.where(overlap, 0.0, d)


def rect_penetration(ax, ay, ah, al, aw, bx, by, bh, bl, bw) -> np.ndarray:
    """Penetration depth [m] of overlapping rectangles (the shortest translation that separates
    them); 0 for disjoint or touching rectangles."""
    args = np.broadcast_arrays(*(_f(v) for v in (ax, ay, ah, al, aw, bx, by, bh, bl, bw)))
    return np.maximum(_sat_depth(*args), 0.0)


def rects_overlap(ax, ay, ah, al, aw, bx, by, bh, bl, bw, margin: float = 0.0) -> np.ndarray:
    """Boolean array: the rectangles overlap by a penetration depth strictly greater than ``margin`` [m].

    With the default ``margin=0`` touching rectangles do not count as overlapping; a positive
    margin ignores grazes (e.g. SUMO's rounding of lateral positions), a negative one also
    counts rectangles closer than ``-margin`` (for those, use :func:`rect_distance` when the
    exact gap matters: the SAT value is only a lower bound of the gap along one axis).
    """
    args = np.broadcast_arrays(*(_f(v) for v in (ax, ay, ah, al, aw, bx, by, bh, bl, bw)))
    return _sat_depth(*args) > float(margin)
