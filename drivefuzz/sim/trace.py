"""Per-frame record of one execution: a :class:`Recorder` during the run, a frozen :class:`Trace` after.

The executor fills the recorder once per simulation step; oracles, the quality
score, replay and analysts read the frozen trace. On disk a trace is a folder of
Parquet files an analyst opens in one line::

    pandas.read_parquet("finding/trace/ego.parquet")

Conventions (SI, radians): positions are the *geometric centre* of a body,
headings are ENU (0 = east, counter-clockwise), body-frame ``vy``/``ay`` are
left-positive.
"""

from __future__ import annotations

import json
import os
from itertools import chain
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

#: Numeric ego channels, one value per frame.
EGO_FLOAT_FIELDS: tuple[str, ...] = (
    "t",  # [s] simulation time after the step
    "x", "y",  # [m] geometric centre
    "heading",  # [rad] ENU
    "speed",  # [m/s] magnitude of the velocity
    "vx", "vy",  # [m/s] body frame (vy left-positive)
    "ax", "ay",  # [m/s^2] body frame (ay includes the centripetal part)
    "yaw_rate",  # [rad/s] counter-clockwise positive
    "steer_wheel_angle",  # [rad] steering-wheel angle (road-wheel angle x steering ratio), left-positive
    "road_wheel_angle",  # [rad]
    "steer",  # [-1, 1] commanded steering, left-positive
    "throttle", "brake",  # [0, 1] commanded
    "mu_front", "mu_rear",  # [-] friction under each axle
    "speed_limit",  # [m/s] of the lane under the ego (nan off-road)
    "tls_dist",  # [m] to the next traffic light's stop line along the route (nan if none)
    "lane_pos",  # [m] along the lane (nan off-road)
    "goal_dist",  # [m] straight-line distance to the goal point
)
#: String ego channels.
EGO_STR_FIELDS: tuple[str, ...] = ("edge", "lane", "tls_state")

#: Per-actor, per-frame channels (long format: one row per actor and frame).
ACTOR_FIELDS: tuple[str, ...] = ("x", "y", "heading", "speed")


@dataclass(frozen=True)
class ActorSamples:
    """Actor states in long format, sorted by frame.

    ``frame[k]``, ``actor[k]`` say which frame and which actor (an index into
    ``ids``) row ``k`` belongs to. ``offsets[f]:offsets[f+1]`` are the rows of frame f.
    """

    ids: tuple[str, ...]
    kinds: tuple[str, ...]  # "vehicle" | "pedestrian"
    length: np.ndarray  # [m] per actor
    width: np.ndarray  # [m] per actor
    frame: np.ndarray
    actor: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    offsets: np.ndarray

    def rows(self, frame: int) -> slice:
        return slice(int(self.offsets[frame]), int(self.offsets[frame + 1]))


@dataclass(frozen=True)
class Trace:
    """The frozen record of one execution."""

    ego: Mapping[str, np.ndarray]
    actors: ActorSamples
    meta: Mapping[str, Any] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(len(self.ego["t"]))

    @property
    def step_length(self) -> float:
        return float(self.meta.get("step_length", 0.05))

    def __getitem__(self, name: str) -> np.ndarray:
        return self.ego[name]

    # ------------------------------------------------------------------ disk
    def save(self, folder: str | os.PathLike) -> Path:
        """Write ``ego.parquet``, ``actors.parquet`` and ``meta.json`` into ``folder`` atomically."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        from drivefuzz.storage import atomic_dir

        folder = Path(folder)
        with atomic_dir(folder) as tmp:
            ego_table = pa.table({k: pa.array(np.asarray(v)) for k, v in self.ego.items()})
            pq.write_table(ego_table, tmp / "ego.parquet")
            a = self.actors
            ids = np.array(a.ids, dtype=object)
            kinds = np.array(a.kinds, dtype=object)
            actor_table = pa.table(
                {
                    "frame": a.frame,
                    "id": pa.array(ids[a.actor] if len(a.actor) else np.array([], dtype=object), type=pa.string()),
                    "kind": pa.array(kinds[a.actor] if len(a.actor) else np.array([], dtype=object), type=pa.string()),
                    "x": a.x, "y": a.y, "heading": a.heading, "speed": a.speed,
                    "length": a.length[a.actor] if len(a.actor) else np.array([], dtype=float),
                    "width": a.width[a.actor] if len(a.actor) else np.array([], dtype=float),
                }
            )
            pq.write_table(actor_table, tmp / "actors.parquet")
            (tmp / "meta.json").write_text(json.dumps(dict(self.meta), indent=2, sort_keys=True, default=str))
        return folder

    @classmethod
    def load(cls, folder: str | os.PathLike) -> "Trace":
        import pyarrow.parquet as pq

        folder = Path(folder)
        ego_t = pq.read_table(folder / "ego.parquet")
        ego = {}
        for name in ego_t.column_names:
            col = ego_t.column(name).to_numpy(zero_copy_only=False)
            ego[name] = np.asarray(col, dtype=object) if name in EGO_STR_FIELDS else np.asarray(col, dtype=float)
        at = pq.read_table(folder / "actors.parquet").to_pydict()
        meta = json.loads((folder / "meta.json").read_text())
        ids: list[str] = []
        index: dict[str, int] = {}
        kinds: list[str] = []
        length: list[float] = []
        width: list[float] = []
        actor_idx = np.empty(len(at["id"]), dtype=np.int32)
        for k, (aid, kind, ln, wd) in enumerate(zip(at["id"], at["kind"], at["length"], at["width"])):
            j = index.get(aid)
            if j is None:
                j = index[aid] = len(ids)
                ids.append(aid), kinds.append(kind), length.append(ln), width.append(wd)
            actor_idx[k] = j
        frame = np.asarray(at["frame"], dtype=np.int32)
        n = len(ego["t"])
        samples = ActorSamples(
            ids=tuple(ids), kinds=tuple(kinds),
            length=np.asarray(length, dtype=float), width=np.asarray(width, dtype=float),
            frame=frame, actor=actor_idx,
            x=np.asarray(at["x"], dtype=float), y=np.asarray(at["y"], dtype=float),
            heading=np.asarray(at["heading"], dtype=float), speed=np.asarray(at["speed"], dtype=float),
            offsets=_offsets(frame, n),
        )
        return cls(ego=_freeze(ego), actors=samples, meta=meta)


def _offsets(frame: np.ndarray, n_frames: int) -> np.ndarray:
    return np.searchsorted(frame, np.arange(n_frames + 1), side="left").astype(np.int64)


def _freeze(arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    out = {}
    for k, v in arrays.items():
        v = np.asarray(v)
        v.setflags(write=False)
        out[k] = v
    return out


class Recorder:
    """Collects per-frame values during a run; :meth:`freeze` returns the :class:`Trace`.

    A step only appends references (the ego's value list, the actors' column lists): the
    arrays are built once, at :meth:`freeze`. Between two SUMO steps that is cheaper than
    writing into numpy arrays, and the caller's lists must simply not be changed afterwards.
    """

    def __init__(self, capacity: int = 1024):  # capacity: kept for callers; lists need none
        self._n = 0
        self._ego: list = []  # per frame: values in EGO_FLOAT_FIELDS order
        self._strs: dict[str, list[str]] = {k: [] for k in EGO_STR_FIELDS}
        self._ids: list[str] = []
        self._index: dict[str, int] = {}
        self._kinds: list[str] = []
        self._length: list[float] = []
        self._width: list[float] = []
        self._blocks: list[tuple] = []  # (frame, actor indices, x, y, heading, speed), each (k,)

    @property
    def n_frames(self) -> int:
        return self._n

    def actor_index(self, actor_id: str, kind: str, length: float, width: float) -> int:
        j = self._index.get(actor_id)
        if j is None:
            j = self._index[actor_id] = len(self._ids)
            self._ids.append(actor_id)
            self._kinds.append(kind)
            self._length.append(float(length))
            self._width.append(float(width))
        return j

    def add_frame(self, ego_values, edge: str, lane: str, tls_state: str) -> int:
        """Append one frame; ``ego_values`` follows :data:`EGO_FLOAT_FIELDS`. Returns the frame index."""
        if len(ego_values) != len(EGO_FLOAT_FIELDS):
            raise ValueError(f"expected {len(EGO_FLOAT_FIELDS)} ego values, got {len(ego_values)}")
        self._ego.append(ego_values)
        self._strs["edge"].append(edge)
        self._strs["lane"].append(lane)
        self._strs["tls_state"].append(tls_state)
        self._n += 1
        return self._n - 1

    def add_actors(self, frame: int, rows: np.ndarray) -> None:
        """Append actor rows ``[actor_index, x, y, heading, speed]`` (shape (k, 5)) for ``frame``."""
        rows = np.asarray(rows, dtype=float).reshape(-1, 5)
        if len(rows):
            self._blocks.append((frame, rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3], rows[:, 4]))

    def add_actor_columns(self, frame: int, index, x, y, heading, speed) -> None:
        """Append one frame's actors as columns (recorder actor index, x, y, heading, speed), each of length k."""
        if len(index):
            self._blocks.append((frame, index, x, y, heading, speed))

    def freeze(self, meta: Mapping[str, Any] | None = None) -> Trace:
        n = self._n
        values = np.array(self._ego, dtype=float).reshape(n, len(EGO_FLOAT_FIELDS))
        ego = {name: values[:, i].copy() for i, name in enumerate(EGO_FLOAT_FIELDS)}
        for name, strs in self._strs.items():
            ego[name] = np.array(strs, dtype=object)
        blocks = self._blocks
        if blocks:
            sizes = [len(b[1]) for b in blocks]
            total = sum(sizes)
            frame = np.repeat(np.array([b[0] for b in blocks], dtype=np.int32), sizes)
            cols = [np.fromiter(chain.from_iterable(b[c] for b in blocks), float, total) for c in range(1, 6)]
        else:
            frame, cols = np.empty(0, dtype=np.int32), [np.empty(0) for _ in range(5)]
        actors = ActorSamples(
            ids=tuple(self._ids), kinds=tuple(self._kinds),
            length=np.asarray(self._length, dtype=float), width=np.asarray(self._width, dtype=float),
            frame=frame, actor=cols[0].astype(np.int32),
            x=cols[1], y=cols[2], heading=cols[3], speed=cols[4],
            offsets=_offsets(frame, n),
        )
        return Trace(ego=_freeze(ego), actors=actors, meta=dict(meta or {}))


def trace_from_arrays(ego: Mapping[str, Any], meta: Mapping[str, Any] | None = None,
                      actors: list[dict[str, Any]] | None = None) -> Trace:
    """Build a trace from plain arrays (for tests and synthetic experiments).

    Missing float channels are NaN (``t`` defaults to ``frame * step_length``); missing string
    channels are empty. ``actors`` is a list of ``{"id", "kind", "length", "width", "x", "y",
    "heading", "speed"}`` with per-frame arrays (NaN where the actor is absent).
    """
    meta = dict(meta or {})
    n = len(next(iter(ego.values())))
    dt = float(meta.setdefault("step_length", 0.05))
    rec = Recorder(n)
    cols = []
    for name in EGO_FLOAT_FIELDS:
        if name in ego:
            cols.append(np.asarray(ego[name], dtype=float))
        elif name == "t":
            cols.append((np.arange(n) + 1) * dt)
        else:
            cols.append(np.full(n, np.nan))
    values = np.stack(cols, axis=1)
    for f in range(n):
        rec.add_frame(values[f], *(str(ego[s][f]) if s in ego else "" for s in EGO_STR_FIELDS))
    for spec in actors or []:
        j = rec.actor_index(spec["id"], spec.get("kind", "vehicle"), spec.get("length", 4.6), spec.get("width", 1.9))
        spec_arrays = {k: np.broadcast_to(np.asarray(spec[k], dtype=float), (n,)) for k in ACTOR_FIELDS}
        spec["_j"] = j
        spec["_arrays"] = spec_arrays
    for f in range(n):
        rows = [
            [s["_j"], *(s["_arrays"][k][f] for k in ACTOR_FIELDS)]
            for s in actors or []
            if not np.isnan(s["_arrays"]["x"][f])
        ]
        if rows:
            rec.add_actors(f, np.asarray(rows, dtype=float))
    return rec.freeze(meta)
