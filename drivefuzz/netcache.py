"""A disk cache of data derived from a network file, so that a new process need not derive it again.

An entry is a numpy ``.npz`` of plain arrays (loaded with ``allow_pickle=False``: a cache file may come
from anywhere and is read as data, never as code), named by a key made of

- the SHA-256 of the network file's bytes,
- the SHA-256 of the source file of the module that derives the data (any edit to it invalidates),
- a ``kind`` and whatever else the deriving code depends on (e.g. the GEOS version).

Entries are written atomically (temporary file + ``os.replace``). A missing, stale, unreadable or
corrupt entry reads as None and the caller derives the data again; a cache that cannot be written
is skipped silently.

Location: ``$DRIVEFUZZ_CACHE`` if set (``off`` disables the cache), else ``$XDG_CACHE_HOME/drivefuzz``
(``~/.cache/drivefuzz``).
"""

from __future__ import annotations

import functools
import hashlib
import io
import os
import zipfile
from pathlib import Path
from typing import Mapping

import numpy as np

#: The entry holding an entry's full key, checked on reading.
_KEY = "__key__"


def cache_dir() -> Path | None:
    """The cache folder, or None when the cache is off."""
    env = os.environ.get("DRIVEFUZZ_CACHE")
    if env is not None:
        return None if env.strip().lower() in ("", "off", "0", "none") else Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "drivefuzz"


@functools.lru_cache(maxsize=64)
def _file_sha256(path: str, mtime_ns: int, size: int) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes (hex), remembered per process while the file is unchanged."""
    p = os.path.realpath(path)
    st = os.stat(p)
    return _file_sha256(p, st.st_mtime_ns, st.st_size)


def entry_key(net: str | os.PathLike, code: str | os.PathLike, kind: str, *extra: str) -> str | None:
    """The key of ``kind`` derived from network ``net`` by the module whose source file is ``code``
    (None, and nothing is cached, where either file cannot be read)."""
    try:
        return "-".join((file_sha256(net)[:32], file_sha256(code)[:16], kind, *extra))
    except OSError:
        return None


def _path(key: str | None) -> Path | None:
    d = cache_dir()
    if d is None or key is None:
        return None
    name = hashlib.sha256(key.encode()).hexdigest()[:40]  # the key may hold any characters
    return d / f"{name}.npz"


def load(key: str | None) -> dict[str, np.ndarray] | None:
    """The arrays stored under ``key``, or None (no entry, or one that is unreadable or not this key's)."""
    path = _path(key)
    if path is None or not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {name: z[name] for name in z.files}
        stored = arrays.pop(_KEY)
        if stored.dtype.kind != "U" or stored.shape != () or str(stored) != key:
            return None
        return arrays
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, RuntimeError):
        return None


def store(key: str | None, arrays: Mapping[str, np.ndarray]) -> bool:
    """Store ``arrays`` under ``key`` atomically; False (silently) when the cache is off or not writable."""
    path = _path(key)
    if path is None:
        return False
    from drivefuzz.storage import atomic_write_bytes

    buf = io.BytesIO()
    np.savez(buf, **{_KEY: np.array(key)}, **{k: np.asarray(v) for k, v in arrays.items()})
    try:
        atomic_write_bytes(path, buf.getvalue())
    except OSError:
        return False
    return True
