"""Array kernels shared by the risk score (:mod:`drivefuzz.search.risk`) and its PET (:mod:`drivefuzz.search.pet`):
per-actor reductions over (frame, actor) rows and the separating axes of two rectangles."""

from __future__ import annotations

import numpy as np


def index_type(n: int):
    """Actor indices as int16 where they fit: numpy's stable sort is then a radix sort."""
    return np.int16 if n < 2**15 else np.int64


def axes(ec, es, el, ew, ac, as_, al, aw):
    """Normals (4, n) of both rectangles' edges and the summed half-extents on each."""
    cr = np.abs(ec * ac + es * as_)
    sr = np.abs(es * ac - ec * as_)
    nx = np.stack([ec, -es, ac, -as_])
    ny = np.stack([es, ec, as_, ac])
    hel, hew, hal, haw = 0.5 * el, 0.5 * ew, 0.5 * al, 0.5 * aw
    r = np.stack([hel + hal * cr + haw * sr, hew + hal * sr + haw * cr,
                  hal + hel * cr + hew * sr, haw + hel * sr + hew * cr])
    return nx, ny, r


def per_actor(val: np.ndarray, j: np.ndarray, f: np.ndarray, n_actors: int,
               largest: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Each actor's smallest (or largest) ``val`` and the ``f`` of its first such row; inf / -1 where none."""
    best = np.full(n_actors, -np.inf if largest else np.inf)
    at = np.full(n_actors, -1, dtype=np.int64)
    if len(val):
        (np.maximum if largest else np.minimum).at(best, j, val)
        hit = np.flatnonzero(val == best[j])[::-1]  # reversed: the first row's write lands last
        at[j[hit]] = f[hit]
    return best, at
