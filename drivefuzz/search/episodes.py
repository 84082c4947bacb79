"""Close encounters as episodes: each time an actor comes close to the ego, not only its closest moment.

An actor is *close* to the ego on a frame where its in-path time-to-collision is under :data:`TTC_S`, their
bodies are under :data:`GAP_M` apart, or (an event, not a state) its crossing's post-encroachment time is under
:data:`PET_S`. An *episode* is a run of such frames of one actor with no stretch of :data:`EPISODE_GAP_S` or more
between them; its moment is its most severe frame (value / threshold smallest). A follower that closes in while
the ego cruises, falls back and closes in again as the ego stops at a light has two episodes, each a close
encounter of its own (:mod:`drivefuzz.triage.coverage` classifies each); counted once per actor, at its closest
moment, the first was never seen.

Pure numpy on the rows the risk score computes anyway (:func:`drivefuzz.search.risk.risk_score`).
"""

from __future__ import annotations

import numpy as np

TTC_S = 3.0  #: [s] in-path time-to-collision under this is a close encounter
PET_S = 2.0  #: [s] post-encroachment time under this is one
GAP_M = 1.5  #: [m] body gap under this is one
#: [s] an actor not close for this long ends its episode: a later close frame starts another (the manoeuvre
#: window of coverage, so that two encounters of one actor are read over windows that do not overlap)
EPISODE_GAP_S = 3.0

LIMITS = {"ttc": TTC_S, "pet": PET_S, "gap": GAP_M}
_COMPONENTS = ("ttc", "pet", "gap")


def episodes(samples: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]], ids: tuple[str, ...],
             dt: float) -> tuple[tuple[str, str, float, int], ...]:
    """``(actor, component, value, frame)`` of each episode's most severe sample, in actor then frame order.

    ``samples`` maps a component (``ttc``, ``pet``, ``gap``) to ``(actor index, frame, value)`` arrays of its
    samples (any order; the ones over the component's threshold are ignored); ``dt`` [s] is the frame step."""
    js, fs, vs, cs = [], [], [], []
    for code, comp in enumerate(_COMPONENTS):
        if comp not in samples:
            continue
        j, f, v = (np.asarray(a) for a in samples[comp])
        keep = np.flatnonzero(v < LIMITS[comp])
        js.append(j[keep].astype(np.int64))
        fs.append(f[keep].astype(np.int64))
        vs.append(v[keep].astype(float))
        cs.append(np.full(len(keep), code, dtype=np.int64))
    if not js or not sum(len(j) for j in js):
        return ()
    j, f, v, c = (np.concatenate(x) for x in (js, fs, vs, cs))
    sev = v / np.array([LIMITS[k] for k in _COMPONENTS])[c]
    order = np.lexsort((sev, f, j))  # by actor, frame, then the more severe first within a frame
    j, f, v, c, sev = j[order], f[order], v[order], c[order], sev[order]
    gap_frames = max(int(round(EPISODE_GAP_S / max(dt, 1e-6))), 1)
    new = np.ones(len(j), dtype=bool)
    new[1:] = (j[1:] != j[:-1]) | (f[1:] - f[:-1] >= gap_frames)
    seg = np.cumsum(new) - 1
    best = np.full(int(seg[-1]) + 1, np.inf)
    np.minimum.at(best, seg, sev)
    first = np.flatnonzero(sev == best[seg])  # the earliest of a segment's most severe samples comes first
    first = first[np.concatenate(([True], seg[first][1:] != seg[first][:-1]))]
    return tuple((ids[int(j[k])], _COMPONENTS[int(c[k])], float(v[k]), int(f[k])) for k in first)
