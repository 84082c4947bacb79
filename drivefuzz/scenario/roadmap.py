"""The road network as drivefuzz sees it outside SUMO: lanes, routes, geometry.

Built on sumolib; used by scenario validation, seeds, the mutator, ADS plugins
and oracles (none of which may import libsumo). Loaded networks are cached per
process, because a campaign loads the same network thousands of times.
"""

from __future__ import annotations

import bisect
import functools
import gc
import math
import os
import xml.etree.ElementTree as ET
import xml.sax
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import drivefuzz  # noqa: F401  (sets SUMO_HOME)
from drivefuzz.errors import InvalidNetwork

PASSENGER = "passenger"
PEDESTRIAN = "pedestrian"

#: the endings of a network file's name, longest first (SUMO reads a gzipped network as it is)
NET_SUFFIXES = (".net.xml.gz", ".net.xml", ".xml.gz", ".gz")


def open_network(path: str | os.PathLike):
    """The network file ``path`` opened for reading bytes, the way SUMO reads it: gzipped or not, told by
    its first two bytes (gzip's magic number), not by its name."""
    source = open(path, "rb")
    if source.read(2) == b"\x1f\x8b":
        import gzip

        source.close()
        return gzip.open(path, "rb")
    source.seek(0)
    return source


def network_name(path: str | os.PathLike) -> str:
    """``town`` for ``networks/town.net.xml``, ``ingolstadt`` for ``ingolstadt.net.xml.gz``."""
    n = Path(path).name
    for suffix in NET_SUFFIXES:
        if n.endswith(suffix) and len(n) > len(suffix):
            return n[: -len(suffix)]
    return Path(n).stem


@dataclass(frozen=True)
class LaneGeom:
    """A lane's centre line as arrays, for fast projection."""

    id: str
    edge: str
    index: int
    length: float  # [m] SUMO's lane length (may differ slightly from the polyline's)
    width: float  # [m]
    speed: float  # [m/s] limit
    pts: np.ndarray  # (n, 2) polyline
    cum: np.ndarray  # (n,) arc length at each point [m]

    def position(self, pos: float) -> tuple[float, float, float]:
        """(x, y, heading [rad ENU]) at ``pos`` metres along the lane (scaled to the polyline)."""
        s = min(max(pos, 0.0), self.length) * (self.cum[-1] / self.length if self.length > 0 else 1.0)
        i = int(np.searchsorted(self.cum, s, side="right") - 1)
        i = min(max(i, 0), len(self.pts) - 2)
        seg = self.pts[i + 1] - self.pts[i]
        seglen = float(np.hypot(*seg)) or 1e-9
        f = (s - self.cum[i]) / seglen
        x, y = self.pts[i] + f * seg
        return float(x), float(y), math.atan2(seg[1], seg[0])

    def project(self, x: float, y: float) -> tuple[float, float]:
        """(pos along lane [m, SUMO scale], signed lateral offset [m, left positive])."""
        p = self.pts
        d = p[1:] - p[:-1]
        l2 = np.maximum((d * d).sum(1), 1e-12)
        t = np.clip(((x - p[:-1, 0]) * d[:, 0] + (y - p[:-1, 1]) * d[:, 1]) / l2, 0.0, 1.0)
        qx = p[:-1, 0] + t * d[:, 0]
        qy = p[:-1, 1] + t * d[:, 1]
        dist2 = (x - qx) ** 2 + (y - qy) ** 2
        i = int(np.argmin(dist2))
        s = self.cum[i] + t[i] * math.sqrt(l2[i])
        cross = d[i, 0] * (y - p[i, 1]) - d[i, 1] * (x - p[i, 0])
        lat = math.copysign(math.sqrt(dist2[i]), cross)
        scale = self.length / self.cum[-1] if self.cum[-1] > 0 else 1.0
        return float(s * scale), float(lat)

    def positions(self, pos: np.ndarray) -> np.ndarray:
        """(n, 2) points at the positions ``pos`` [m along the lane, SUMO scale]: :meth:`position` for many."""
        s = np.clip(np.asarray(pos, dtype=float), 0.0, self.length) * (
            self.cum[-1] / self.length if self.length > 0 else 1.0)
        return np.stack([np.interp(s, self.cum, self.pts[:, 0]), np.interp(s, self.cum, self.pts[:, 1])], axis=1)

    def lateral(self, x: float, y: float, pos: float) -> float:
        """Signed distance [m, left positive] of (x, y) from the centre line, measured square to the
        lane near ``pos`` [m along the lane, SUMO scale]; before the start or after the end of
        the lane, square to the extended first or last segment.

        Pure ``math`` on cached lists: about a microsecond, for the executor's every frame.
        """
        segs, starts, scale = self._segments
        i = 0
        if len(segs) > 1:
            i = min(max(bisect.bisect_right(starts, pos * scale) - 1, 0), len(segs) - 1)
        x0, y0, ux, uy = segs[i]
        return ux * (y - y0) - uy * (x - x0)

    @functools.cached_property
    def _segments(self) -> tuple[list[tuple[float, float, float, float]], list[float], float]:
        """Per segment (x0, y0, unit direction), the arc length where each starts, and the
        factor from SUMO's lane positions to arc length."""
        pts, cum = self.pts.tolist(), self.cum.tolist()
        segs = []
        for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:]):
            d = math.hypot(x1 - x0, y1 - y0) or 1e-9
            segs.append((x0, y0, (x1 - x0) / d, (y1 - y0) / d))
        return segs, cum[:-1], (cum[-1] / self.length if self.length > 0 else 1.0)


class RoadMap:
    """Read-only view of a SUMO network."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        if not self.path.is_file():
            raise InvalidNetwork(str(path), None, "no such network file", "a SUMO .net.xml file")
        import sumolib

        # The cyclic garbage collector is off while sumolib builds the network: the parse allocates hundreds of
        # thousands of objects that all stay alive, so the collections it would trigger find nothing and cost
        # a third of the load (Berlin, 3,641 edges: 0.40 -> 0.25 s). Then the heap is frozen (moved to the
        # permanent generation): else the next collections of generations 0, 1 and 2 each walk the whole map,
        # once more, for nothing (Berlin: 41 + 51 + 85 ms of a 1.1 s `drivefuzz run`). _load thaws it when it
        # drops a map, so that a map no longer used can be collected (sumolib's objects refer to each other).
        collecting = gc.isenabled()
        gc.disable()
        try:
            # lxml=False: sumolib's lxml reader (taken whenever lxml is installed, as scenariogeneration
            # brings it) leaves crossings without their crossed edges; the SAX reader is what we test
            self.net = sumolib.net.readNet(str(self.path), withInternal=True, withPedestrianConnections=True,
                                           lxml=False)
            gc.freeze()
        except (xml.sax.SAXException, ValueError, KeyError, AttributeError, IndexError, TypeError) as exc:
            raise InvalidNetwork(str(path), None, f"not a readable SUMO network ({type(exc).__name__}: {exc})",
                                 "a .net.xml written by netconvert") from None
        finally:
            if collecting:
                gc.enable()
        if not self.net.getEdges(withInternal=False):
            raise InvalidNetwork(str(path), None, "the network has no edges", "a .net.xml with roads")
        self._geoms: dict[str, LaneGeom] = {}
        self._change: dict[str, tuple[str | None, str | None]] | None = None
        self._route_cache: dict[tuple[str, str, str], tuple[str, ...] | None] = {}

    # ----------------------------------------------------------- look-ups
    @property
    def name(self) -> str:
        return network_name(self.path)

    def has_edge(self, edge_id: str) -> bool:
        return self.net.hasEdge(edge_id)

    def has_lane(self, lane_id: str) -> bool:
        try:
            self.net.getLane(lane_id)
            return True
        except (KeyError, ValueError, IndexError):
            return False

    def lane(self, lane_id: str):
        return self.net.getLane(lane_id)

    def edge(self, edge_id: str):
        return self.net.getEdge(edge_id)

    def geom(self, lane_id: str) -> LaneGeom:
        g = self._geoms.get(lane_id)
        if g is None:
            lane = self.net.getLane(lane_id)
            pts = np.asarray(lane.getShape(), dtype=float)[:, :2]
            if len(pts) < 2:
                pts = np.vstack([pts, pts + 1e-3])
            seg = np.hypot(*(pts[1:] - pts[:-1]).T)
            cum = np.concatenate([[0.0], np.cumsum(seg)])
            g = LaneGeom(lane_id, lane.getEdge().getID(), lane.getIndex(), float(lane.getLength()),
                         float(lane.getWidth()), float(lane.getSpeed()), pts, cum)
            self._geoms[lane_id] = g
        return g

    def may_change(self, lane_id: str, left: bool, vclass: str = PASSENGER) -> bool:
        """Whether ``vclass`` may change from ``lane_id`` to the lane on its left (right).

        From SUMO's ``changeLeft``/``changeRight`` lane attributes (a solid line where the class
        is not listed; absent means allowed), which sumolib does not expose: the net file is
        read once for them.
        """
        if self._change is None:
            self._change = _lane_change_attributes(str(self.path))
        value = self._change.get(lane_id, (None, None))[0 if left else 1]
        if value is None:
            return True
        tokens = set(value.split())
        if vclass == PASSENGER:
            return bool(tokens & {"all", "passenger", "private"})
        return bool(tokens & {"all", vclass})

    def may_change_to(self, frm: str, to: str, vclass: str = PASSENGER) -> bool:
        """Whether ``vclass`` may change, lane by lane, from ``frm`` to ``to`` (same edge) without crossing a
        solid line (:meth:`may_change` at every boundary between them)."""
        i, j = self.lane(frm).getIndex(), self.lane(to).getIndex()
        ids = {l.getIndex(): l.getID() for l in self.lane(frm).getEdge().getLanes()}
        if j > i:
            return all(self.may_change(ids[k], left=True, vclass=vclass) for k in range(i, j))
        return all(self.may_change(ids[k], left=False, vclass=vclass) for k in range(j + 1, i + 1))

    def is_normal_edge(self, edge) -> bool:
        return edge.getFunction() == ""

    def edge_ids(self, vclass: str = PASSENGER) -> list[str]:
        """Normal edges with at least one lane allowing ``vclass``."""
        return sorted(e.getID() for e in self.net.getEdges(withInternal=False)
                      if e.getFunction() == "" and any(l.allows(vclass) for l in e.getLanes()))

    def lanes(self, vclass: str = PASSENGER, *, exclusive_for: str | None = None) -> list[str]:
        """Lanes of normal edges allowing ``vclass`` (sorted ids).

        ``exclusive_for=PEDESTRIAN`` keeps sidewalks only (lanes that allow no passenger car).
        """
        out = []
        for e in self.net.getEdges(withInternal=False):
            if e.getFunction() != "":
                continue
            for lane in e.getLanes():
                if not lane.allows(vclass):
                    continue
                if exclusive_for == PEDESTRIAN and lane.allows(PASSENGER):
                    continue
                out.append(lane.getID())
        return sorted(out)

    def drive_lane(self, edge_id: str) -> str:
        """The rightmost lane of ``edge_id`` that allows passenger cars (goals are placed on it)."""
        for lane in self.edge(edge_id).getLanes():
            if lane.allows(PASSENGER):
                return lane.getID()
        return self.edge(edge_id).getLanes()[0].getID()

    def walkable_lanes(self) -> list[str]:
        """Lanes a pedestrian may stand on: sidewalks and crossings (or shared road lanes)."""
        out = []
        for e in self.net.getEdges(withInternal=True):
            if e.getFunction() not in ("", "crossing"):
                continue
            out.extend(l.getID() for l in e.getLanes() if l.allows(PEDESTRIAN))
        return sorted(out)

    # ------------------------------------------------------------- routes
    def route(self, from_edge: str, to_edge: str, vclass: str = PASSENGER) -> tuple[str, ...] | None:
        """Shortest route of normal edges, or None if there is none."""
        key = (from_edge, to_edge, vclass)
        if key not in self._route_cache:
            if from_edge == to_edge:
                self._route_cache[key] = (from_edge,)
            else:
                try:
                    path, _cost = self.net.getShortestPath(self.edge(from_edge), self.edge(to_edge), vClass=vclass)
                except KeyError:
                    path = None
                self._route_cache[key] = tuple(e.getID() for e in path) if path else None
        return self._route_cache[key]

    def route_length(self, edges: tuple[str, ...], start_pos: float = 0.0, end_pos: float | None = None) -> float:
        total = sum(self.edge(e).getLength() for e in edges)
        last = self.edge(edges[-1]).getLength()
        return total - start_pos - (last - (last if end_pos is None else end_pos))

    def connections(self, from_edge: str, to_edge: str, vclass: str = PASSENGER) -> list[tuple[str, str, str]]:
        """(from lane, to lane, via internal lane or '') for every connection from_edge -> to_edge that
        ``vclass`` may use: a city's bicycle lane is connected to the next edge's too (Ingolstadt)."""
        out = []
        src, dst = self.edge(from_edge), self.edge(to_edge)
        for conn in src.getConnections(dst):
            if not (conn.getFromLane().allows(vclass) and conn.getToLane().allows(vclass)):
                continue
            via = conn.getViaLaneID() or ""
            out.append((conn.getFromLane().getID(), conn.getToLane().getID(), via))
        return out

    def internal_chain(self, via: str) -> list[str]:
        """The internal lanes of a junction passage starting with ``via`` (SUMO may split them)."""
        chain = []
        lane_id = via
        seen = set()
        while lane_id and lane_id not in seen:
            seen.add(lane_id)
            chain.append(lane_id)
            lane = self.net.getLane(lane_id)
            nxt = ""
            for conn in lane.getOutgoing():
                to = conn.getToLane()
                if to.getEdge().getFunction() == "internal":
                    nxt = to.getID()
                break
            lane_id = nxt
        return chain

    def nearest_lane(self, x: float, y: float, radius: float = 5.0, vclass: str | None = None) -> tuple[str, float] | None:
        """(lane id, distance [m]) of the nearest lane within ``radius``, optionally allowing ``vclass``."""
        best = None
        for lane, dist in self.net.getNeighboringLanes(x, y, radius, includeJunctions=True):
            if vclass is not None and not lane.allows(vclass):
                continue
            if best is None or dist < best[1]:
                best = (lane.getID(), float(dist))
        return best

    def tls_ids(self) -> list[str]:
        return sorted(t.getID() for t in self.net.getTrafficLights())

    def bounds(self) -> tuple[float, float, float, float]:
        (x0, y0), (x1, y1) = self.net.getBBoxXY()
        return float(x0), float(y0), float(x1), float(y1)


def _lane_change_attributes(path: str) -> dict[str, tuple[str | None, str | None]]:
    """lane id -> (changeLeft, changeRight) for the lanes of ``path`` that set either."""
    out: dict[str, tuple[str | None, str | None]] = {}
    with open_network(path) as source:
        _scan_lanes(source, out)
    return out


def _scan_lanes(source, out: dict[str, tuple[str | None, str | None]]) -> None:
    for _ev, el in ET.iterparse(source, events=("end",)):
        if el.tag == "lane":
            left, right = el.get("changeLeft"), el.get("changeRight")
            if left is not None or right is not None:
                out[el.get("id", "")] = (left, right)
        elif el.tag in ("edge", "junction", "connection", "tlLogic"):
            el.clear()


#: Road maps kept per process, by (path, mtime), the most recently used last.
_MAPS: "OrderedDict[tuple[str, float], RoadMap]" = OrderedDict()
#: How many :data:`_MAPS` keeps.
MAX_MAPS = 16


def _load(path: str, mtime: float) -> RoadMap:
    key = (path, mtime)
    rmap = _MAPS.get(key)
    if rmap is not None:
        _MAPS.move_to_end(key)
        return rmap
    rmap = _MAPS[key] = RoadMap(path)
    if len(_MAPS) > MAX_MAPS:
        _MAPS.popitem(last=False)
        gc.unfreeze()  # the dropped map, frozen with the heap when it was read, can be collected again
    return rmap


def load_roadmap(path: str | os.PathLike) -> RoadMap:
    """Cached :class:`RoadMap` (re-read when the file changes)."""
    p = Path(path).resolve()
    if not p.is_file():
        raise InvalidNetwork(str(path), None, "no such network file", "a SUMO .net.xml file")
    return _load(str(p), p.stat().st_mtime)
