"""Installed plugins' entry points, read once per state of the import path.

``importlib.metadata.entry_points`` reads every installed distribution's metadata
(about 3 ms here): once for the ADS and once for the oracles of every execution,
that was a fixed cost of each. The answer only changes when the import path does,
or when something is installed into (or removed from) one of its folders, which
changes that folder's modification time: both are the cache's key (a few ``stat``
calls), so a plugin installed mid-campaign is still found.
"""

from __future__ import annotations

import os
import sys
from importlib.metadata import entry_points as _entry_points

_CACHE: dict[str, tuple[tuple, tuple]] = {}


def _path_state() -> tuple:
    state = []
    for p in sys.path:
        p = p or os.getcwd()  # "" is the current folder, whichever it is now
        try:
            state.append((p, os.stat(p).st_mtime_ns))
        except OSError:
            state.append((p, None))
    return tuple(state)


def entry_points(group: str) -> tuple:
    """The entry points of ``group`` (as ``importlib.metadata.entry_points(group=...)``), as a tuple."""
    key = _path_state()
    hit = _CACHE.get(group)
    if hit is not None and hit[0] == key:
        return hit[1]
    eps = tuple(_entry_points(group=group))
    _CACHE[group] = (key, eps)
    return eps
