"""Collision: the ego's body overlaps another vehicle, a pedestrian or a static obstacle."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from pydantic import Field

from drivefuzz.geometry import corners, rect_penetration, rects_overlap
from drivefuzz.oracle import Frame, Misbehavior, Oracle, RunContext
from oracles import kmh


class CollisionOracle(Oracle):
    """Fires when the ego's footprint overlaps another body.

    - The ego is the oriented rectangle ``(frame.x, frame.y, frame.heading,
      ctx.ego_length, ctx.ego_width)``; every vehicle and pedestrian is the
      rectangle of its row in ``frame.actor_*``; static obstacles are the
      shapely polygons in ``ctx.obstacles``.
    - A vehicle or pedestrian counts when the separating-axis penetration depth
      is strictly greater than ``margin`` (default 0: bodies that only touch do
      not collide; a negative margin also flags bodies closer than ``-margin``).
      An obstacle counts when the ego polygon intersects it in more than a
      boundary touch.
    - Only bodies within reach (centre offset along x and y at most the sum
      of the two bodies' half-diagonals, bounded once per set of actors) are
      tested exactly, so a frame costs one plain pass over the actors.
    - SUMO's own collision list (``frame.sumo_collisions``) is only a
      cross-check: ``details["sumo_confirmed"]`` says whether SUMO reported the
      same pair in this frame or the ``sumo_window`` seconds before. SUMO misses
      lateral, off-lane and most pedestrian contacts, so it never decides.
    - With the executor told to go on, each body is reported once per contact
      (again only after the bodies separated).

    Kinds ``"vehicle"``, ``"pedestrian"``, ``"obstacle"``; ``actors=(id,)``;
    details: ``penetration`` [m] (vehicles and pedestrians), ``ego_speed``,
    ``other_speed``, ``relative_speed`` [m/s] (and km/h), ``sumo_confirmed``,
    ``sumo_type``.
    """

    name = "collision"
    description = "The ego's body overlaps a vehicle, a pedestrian or a static obstacle."

    class Config(Oracle.Config):
        margin: float = Field(0.0, description="[m] penetration depth that must be exceeded (negative: a safety gap)")
        sumo_window: float = Field(1.0, ge=0.0, description="[s] how far back a SUMO collision confirms one")

    def reset(self, ctx: RunContext) -> None:
        super().reset(ctx)
        self._len = float(ctx.ego_length)
        self._wid = float(ctx.ego_width)
        self._margin = float(self.config.margin)
        self._ego_r = 0.5 * math.hypot(self._len, self._wid) + max(-self._margin, 0.0)
        self._obstacles = [(o.id, o.polygon, o.polygon.bounds) for o in ctx.obstacles]
        self._sizes_of: tuple = (None, None)  # the actor_length / actor_width arrays _reach was made for
        self._reach: list[float] = []  # [m] per actor row, see _candidates
        self._contact: set[str] = set()
        self._sumo_seen: dict[str, tuple[float, str]] = {}

    def on_frame(self, frame: Frame) -> Sequence[Misbehavior]:
        if frame.sumo_collisions:
            for collider, victim, kind in frame.sumo_collisions:
                other = victim if collider == "ego" else collider
                self._sumo_seen[other] = (frame.t, kind)
        cand = self._candidates(frame) if len(frame.actor_ids) else ()
        if not cand and not self._obstacles:  # the common case: nobody within reach
            if self._contact:
                self._contact = set()
            return ()
        out: list[Misbehavior] = []
        touching: set[str] = set()
        if cand:
            idx = np.asarray(cand)
            ah = frame.actor_heading[idx]
            cx, cy = frame.actor_x[idx], frame.actor_y[idx]
            cl, cw = frame.actor_length[idx], frame.actor_width[idx]
            hit = rects_overlap(frame.x, frame.y, frame.heading, self._len, self._wid, cx, cy, ah, cl, cw,
                                margin=self._margin)
            if hit.any():
                depth = rect_penetration(frame.x, frame.y, frame.heading, self._len, self._wid,
                                         cx, cy, ah, cl, cw)
                for j in np.flatnonzero(hit):
                    k = int(idx[j])
                    aid = frame.actor_ids[k]
                    touching.add(aid)
                    if aid in self._contact:
                        continue
                    out.append(self._record(frame, frame.actor_kinds[k], aid, float(frame.actor_speed[k]),
                                            float(ah[j]), penetration=round(float(depth[j]), 4)))
        if self._obstacles:
            ego_poly = None
            c = math.cos(frame.heading)
            s = math.sin(frame.heading)
            ex = 0.5 * (self._len * abs(c) + self._wid * abs(s))
            ey = 0.5 * (self._len * abs(s) + self._wid * abs(c))
            for oid, poly, (x0, y0, x1, y1) in self._obstacles:
                if frame.x + ex < x0 or frame.x - ex > x1 or frame.y + ey < y0 or frame.y - ey > y1:
                    continue
                if ego_poly is None:
                    from shapely.geometry import Polygon

                    ego_poly = Polygon(corners(frame.x, frame.y, frame.heading, self._len, self._wid))
                if ego_poly.intersects(poly) and not ego_poly.touches(poly):
                    touching.add(oid)
                    if oid not in self._contact:
                        out.append(self._record(frame, "obstacle", oid, 0.0, frame.heading))
        self._contact = touching
        return tuple(out)

    def _candidates(self, frame: Frame) -> list[int]:
        """Rows whose body may overlap the ego's.

        Broad phase: the centre is within ``reach`` of the ego's centre along x and along y, where
        ``reach`` is the ego's half-diagonal (grown by a negative margin) plus half the body's
        length plus width (at least its half-diagonal), computed once per set of actors. Plain
        Python on lists: for a few dozen actors this measured cheaper than numpy. The few
        survivors must also not be separated along one of the ego's two axes; whoever is left is
        tested exactly by the caller."""
        length, width = frame.actor_length, frame.actor_width
        if length is not self._sizes_of[0] or width is not self._sizes_of[1]:
            # the executor replaces these arrays only when actors come or go: once per actor set
            self._sizes_of = (length, width)
            self._reach = (self._ego_r + 0.5 * (length + width)).tolist()
        x, y = frame.x, frame.y
        near = [k for k, (ax, ay, r) in enumerate(zip(frame.actor_x.tolist(), frame.actor_y.tolist(), self._reach))
                if -r <= ax - x <= r and -r <= ay - y <= r]
        if not near:
            return near
        c, s = math.cos(frame.heading), math.sin(frame.heading)
        hl = 0.5 * self._len - min(self._margin, 0.0)
        hw = 0.5 * self._wid - min(self._margin, 0.0)
        out = []
        cos, sin = math.cos, math.sin
        for k in near:
            dx, dy = float(frame.actor_x[k]) - x, float(frame.actor_y[k]) - y
            al, aw, ah = float(length[k]), float(width[k]), float(frame.actor_heading[k])
            ca, sa = cos(ah), sin(ah)
            # projections of the actor's half-extents on the ego's forward and left axes
            cr, sr = abs(c * ca + s * sa), abs(s * ca - c * sa)
            if abs(dx * c + dy * s) > hl + 0.5 * (al * cr + aw * sr):
                continue
            if abs(-dx * s + dy * c) > hw + 0.5 * (al * sr + aw * cr):
                continue
            out.append(k)
        return out

    def _record(self, frame: Frame, kind: str, other: str, other_speed: float, other_heading: float,
                **extra) -> Misbehavior:
        seen = self._sumo_seen.get(other)
        confirmed = seen is not None and frame.t - seen[0] <= self.config.sumo_window + 1e-9
        # relative speed: |v_ego - v_other| as vectors
        rvx = frame.speed * math.cos(frame.heading) - other_speed * math.cos(other_heading)
        rvy = frame.speed * math.sin(frame.heading) - other_speed * math.sin(other_heading)
        rel = math.hypot(rvx, rvy)
        return self.report(frame, kind, (other,), **extra,
                           ego_speed=round(frame.speed, 3), other_speed=round(other_speed, 3),
                           relative_speed=round(rel, 3), ego_speed_kmh=kmh(frame.speed),
                           relative_speed_kmh=kmh(rel), sumo_confirmed=bool(confirmed),
                           sumo_type=seen[1] if confirmed else None)
