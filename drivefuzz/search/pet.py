"""Post-encroachment time (PET) for the risk score (:mod:`drivefuzz.search.risk`): per actor, the least time
between one body leaving a patch of road and the other reaching it, over the nodes (patches of about
``RiskConfig.pet_node_m``) that the ego's and the actor's centres pass. Moved out of ``risk.py`` unchanged (house
style: modules under 600 lines).
"""

from __future__ import annotations

import math

import numpy as np

from drivefuzz.search.rows import axes as _axes, index_type as _index_type, per_actor as _per_actor


def _nodes(body, frame, x, y, ds: float) -> tuple[np.ndarray, np.ndarray]:
    """First and last sample of each occupation node; samples sorted by (body, frame).

    A node starts with a body's first sample, after a missing frame, and whenever the distance
    travelled since the segment's start passes another multiple of ``ds``."""
    n = len(x)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    brk = np.ones(n, dtype=bool)
    brk[1:] = (body[1:] != body[:-1]) | (frame[1:] != frame[:-1] + 1)
    step = np.zeros(n)
    step[1:] = np.hypot(np.diff(x), np.diff(y))
    step[brk] = 0.0
    cum = np.cumsum(step)
    seg_start = np.flatnonzero(brk)
    cum -= cum[seg_start][np.cumsum(brk) - 1]
    cell = np.floor(cum / ds)
    new = brk.copy()
    new[1:] |= cell[1:] != cell[:-1]
    starts = np.flatnonzero(new)
    return starts, np.append(starts[1:], n) - 1


def _neighbour_pairs(ax, ay, bx, by, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i into a, k into b) of points in the same or adjacent grid cells of size ``cell``."""
    if len(ax) == 0 or len(bx) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cxa, cya = np.floor(ax / cell).astype(np.int64), np.floor(ay / cell).astype(np.int64)
    cxb, cyb = np.floor(bx / cell).astype(np.int64), np.floor(by / cell).astype(np.int64)
    y0 = min(cya.min(), cyb.min()) - 1
    m = max(cya.max(), cyb.max()) - y0 + 2
    kb = cxb * m + (cyb - y0)
    order = np.argsort(kb, kind="stable")
    kb = kb[order]
    off = (np.arange(-1, 2)[:, None] * m + np.arange(-1, 2)[None, :]).ravel()
    ka = (cxa * m + (cya - y0))[None, :] + off[:, None]  # (9, na)
    lo = np.searchsorted(kb, ka.ravel(), "left")
    cnt = np.searchsorted(kb, ka.ravel(), "right") - lo
    ia = np.repeat(np.tile(np.arange(len(ax)), 9), cnt)
    start = np.repeat(lo - (np.cumsum(cnt) - cnt), cnt)
    return ia, order[start + np.arange(len(ia))]


def pet(trace, e, cfg) -> tuple[np.ndarray, np.ndarray]:
    """Per actor: the smallest crossing PET [s] (inf: none) and the frame of the later arrival."""
    a = trace.actors
    n_act = len(a.ids)
    pet, at = np.full(n_act, np.inf), np.full(n_act, -1, dtype=np.int64)
    ok_e = np.isfinite(e["x"]) & np.isfinite(e["y"])
    fe = np.flatnonzero(ok_e)
    ok_a = np.isfinite(a.x) & np.isfinite(a.y) & np.isfinite(a.heading)
    order = np.flatnonzero(ok_a)[np.argsort(a.actor[ok_a].astype(_index_type(n_act)), kind="stable")]
    if len(fe) == 0 or len(order) == 0:
        return pet, at
    es, ee = _nodes(np.zeros(len(fe)), fe, e["x"][fe], e["y"][fe], cfg.pet_node_m)
    af, aj = a.frame[order].astype(np.int64), a.actor[order].astype(np.int64)
    ax_, ay_, ahd = a.x[order], a.y[order], a.heading[order]
    as_, ae = _nodes(aj, af, ax_, ay_, cfg.pet_node_m)
    margin = cfg.pet_reach_m + 0.5 * cfg.pet_node_m
    r_e = 0.5 * math.hypot(e["l"], e["w"])
    r_a = 0.5 * np.hypot(a.length, a.width)
    cell = r_e + float(r_a.max()) + margin
    exn, eyn = e["x"][fe[es]], e["y"][fe[es]]
    i, k = _neighbour_pairs(exn, eyn, ax_[as_], ay_[as_], cell)
    ek, ak = es[i], as_[k]  # sample indices of the nodes' first samples
    j = aj[ak]
    feh = fe[ek]
    dist = np.hypot(ax_[ak] - e["x"][feh], ay_[ak] - e["y"][feh])
    near = dist <= r_e + r_a[j] + margin
    dh = np.abs((ahd[ak] - e["h"][feh] + np.pi) % (2 * np.pi) - np.pi)
    crossing = dh >= math.radians(cfg.pet_min_angle_deg)
    # a node of the actor's path on the ego's own path (the ego's nearest node heads its way) is following, not
    # crossing: in a turn the ego's nodes a few metres on head 25 degrees and more away from it, and a car that
    # followed the ego through the turn had a "PET" of its time gap (SUMO's 1 s: a close encounter each time)
    on_path = np.zeros(len(as_), bool)
    if len(k):
        first = np.lexsort((dist, k))
        first = first[np.r_[True, k[first][1:] != k[first][:-1]]]
        on_path[k[first]] = ~crossing[first]
    keep = near & crossing & ~on_path[k]
    i, k, ek, ak, j, feh = (v[keep] for v in (i, k, ek, ak, j, feh))
    if len(i) == 0:
        return pet, at
    ah = ahd[ak]
    nx, ny, r = _axes(e["c"][feh], e["s"][feh], e["l"], e["w"], np.cos(ah), np.sin(ah), a.length[j], a.width[j])
    p0 = (ax_[ak] - e["x"][feh]) * nx + (ay_[ak] - e["y"][feh]) * ny
    touch = (np.abs(p0) - r).max(axis=0) <= margin
    i, k, j = i[touch], k[touch], j[touch]
    if len(i) == 0:
        return pet, at
    t = e["t"]
    fe0, fe1 = fe[es[i]], fe[ee[i]]
    fa0, fa1 = af[as_[k]], af[ae[k]]
    actor_later = t[fa0] - t[fe1]
    ego_later = t[fe0] - t[fa1]
    p = np.maximum(np.maximum(actor_later, ego_later), 0.0)
    frm = np.where(p <= 0.0, np.maximum(fe0, fa0), np.where(actor_later >= ego_later, fa0, fe0))
    return _per_actor(p, j, frm, n_act)
