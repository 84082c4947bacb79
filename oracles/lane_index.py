"""The lane-invasion oracle's read-only geometry of a network, built on demand.

A city holds thousands of lanes while a run visits a few dozen, so nothing is built for the whole
network up front:

- a lane's segments when the lane is first asked for (:meth:`NetIndex.lane`);
- the grid of lane segments one cell at a time, when a point first falls in it: a scan of the lanes'
  bounding boxes (kept in the disk cache) finds the lanes that may reach the cell, and the cell then
  holds exactly the (lane, segment) pairs, in exactly the order, that a grid of the whole network would;
- the reverse edges, and the lanes of an edge by index, per edge;
- the junction areas (shapely unions over the whole network, the costly part) once per network and
  process, read from the disk cache (:mod:`drivefuzz.netcache`, WKB bytes, exact) when an earlier
  process derived them from the same file with the same code and GEOS.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import Any

from drivefuzz.scenario.roadmap import PASSENGER, PEDESTRIAN
from oracles import wrap_angle

#: Grid cell [m] of the lane-segment index.
CELL = 8.0
#: Lateral reach [m] beyond a lane's half width for which a segment is indexed (>= any sane tolerance).
REACH = 1.5
#: Heading change at one vertex of a lane's shape from which the vertex counts as a street corner.
BEND = math.radians(30.0)


@dataclass(eq=False)
class Lane:
    id: str
    edge: str
    index: int
    width: float
    passenger: bool
    pedestrian: bool
    from_node: str
    to_node: str
    # per segment: x0, y0, ux, uy, length, cumulative start, heading
    segs: list[tuple[float, float, float, float, float, float, float]] = field(default_factory=list)
    starts: list[float] = field(default_factory=list)  # cumulative start of every segment
    total: float = 0.0
    bends: list[float] = field(default_factory=list)  # [m] along the lane: vertices that turn by >= BEND
    rmap: Any = field(default=None, repr=False)

    @property
    def change_left(self) -> bool:
        """Passenger cars may change to the lane on the left (SUMO's ``changeLeft``; read when first asked)."""
        return self.rmap.may_change(self.id, left=True)

    @property
    def change_right(self) -> bool:
        return self.rmap.may_change(self.id, left=False)

    def near_bend(self, s0: float, s1: float) -> bool:
        """Whether a sharp bend lies between ``s0`` and ``s1`` [m along the lane]."""
        k = bisect.bisect_left(self.bends, s0)
        return k < len(self.bends) and self.bends[k] <= s1

    def seg_at(self, s: float) -> int:
        return min(max(bisect.bisect_right(self.starts, s) - 1, 0), len(self.segs) - 1)

    def distance(self, x: float, y: float, i0: int = 0, i1: int | None = None) -> tuple[float, float]:
        """(distance [m] from the centre line, heading there) for a point beside the lane, inf if
        it lies before the lane start or after its end. Only segments i0..i1 are searched."""
        best, head = math.inf, 0.0
        last = len(self.segs) - 1
        for i in range(i0, last + 1 if i1 is None else min(i1, last) + 1):
            x0, y0, ux, uy, ln, _c, h = self.segs[i]
            px, py = x - x0, y - y0
            t = px * ux + py * uy
            if t < 0.0:
                if i == 0:
                    continue
                t = 0.0
            elif t > ln:
                if i == last:
                    continue
                t = ln
            d = math.hypot(px - t * ux, py - t * uy)
            if d < best:
                best, head = d, h
        return best, head

    def cells(self, i: int) -> tuple[int, int, int, int]:
        """The grid cells (cx0, cx1, cy0, cy1, inclusive) within reach of segment ``i``."""
        x0, y0, ux, uy, ln, _c, _h = self.segs[i]
        r = 0.5 * self.width + REACH
        x1, y1 = x0 + ux * ln, y0 + uy * ln
        return (int(math.floor((min(x0, x1) - r) / CELL)), int(math.floor((max(x0, x1) + r) / CELL)),
                int(math.floor((min(y0, y1) - r) / CELL)), int(math.floor((max(y0, y1) + r) / CELL)))


def _make_lane(rmap, ln) -> Lane | None:
    """The oracle's view of sumolib lane ``ln`` of a normal edge; None when its shape has no length."""
    e = ln.getEdge()
    pts = [(float(p[0]), float(p[1])) for p in ln.getShape()]
    lane = Lane(ln.getID(), e.getID(), ln.getIndex(), float(ln.getWidth()), bool(ln.allows(PASSENGER)),
                bool(ln.allows(PEDESTRIAN)), e.getFromNode().getID(), e.getToNode().getID(), rmap=rmap)
    cum = 0.0
    for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:]):
        d = math.hypot(x1 - x0, y1 - y0)
        if d < 1e-9:
            continue
        lane.segs.append((x0, y0, (x1 - x0) / d, (y1 - y0) / d, d, cum, math.atan2(y1 - y0, x1 - x0)))
        lane.starts.append(cum)
        cum += d
    lane.total = cum
    if not lane.segs:
        return None
    lane.bends = [b[5] for a, b in zip(lane.segs[:-1], lane.segs[1:]) if abs(wrap_angle(b[6] - a[6])) >= BEND]
    return lane


class _Lanes:
    """lane id -> :class:`Lane` for the lanes of normal edges that have a length (``.get`` like a dict)."""

    def __init__(self, rmap):
        self.rmap = rmap
        self._known: dict[str, Lane | None] = {}

    def get(self, lane_id: str, default=None) -> Lane | None:
        got = self._known.get(lane_id, False)
        if got is False:
            got = None
            if self.rmap.has_lane(lane_id):
                ln = self.rmap.lane(lane_id)
                if ln.getEdge().getFunction() == "":
                    got = _make_lane(self.rmap, ln)
            self._known[lane_id] = got
        return default if got is None else got

    def __contains__(self, lane_id: str) -> bool:
        return self.get(lane_id) is not None


class NetIndex:
    """Per-network, read-only geometry for the oracle (one per process and network, filled on demand)."""

    def __init__(self, rmap):
        self.rmap = rmap
        self.lanes = _Lanes(rmap)
        self._reverse: dict[str, frozenset[str]] = {}
        self._by_index: dict[str, dict[int, Lane]] = {}
        self._grid: dict[tuple[int, int], list[tuple[Lane, int]]] = {}
        self._boxes = None  # (ids of the normal edges' lanes in network order, (n, 4) boxes of their reach)
        self._areas: tuple[Any, Any] | None = None  # (drivable junction area, walking areas)
        self._parts = None  # the drivable area's polygons in an STRtree, for depths (built when first asked)
        self._drivable_tol: dict[float, tuple[Any, Cells]] = {}

    # ------------------------------------------------------------------ edges
    def _edge_lanes(self, edge) -> list[Lane]:
        return [lane for lane in (self.lanes.get(ln.getID()) for ln in edge.getLanes()) if lane is not None]

    def reverse(self, edge_id: str) -> frozenset[str]:
        """The normal edges (with a lane) that join the same nodes as ``edge_id``, the other way."""
        got = self._reverse.get(edge_id)
        if got is None:
            out = []
            rmap = self.rmap
            if rmap.has_edge(edge_id):
                e = rmap.edge(edge_id)
                if e.getFunction() == "" and self._edge_lanes(e):
                    fr = e.getFromNode()
                    out = [o.getID() for o in e.getToNode().getOutgoing()
                           if o.getToNode() is fr and o.getFunction() == "" and self._edge_lanes(o)]
            got = self._reverse[edge_id] = frozenset(out)
        return got

    def by_index(self, edge_id: str) -> dict[int, Lane]:
        """lane index -> :class:`Lane` of a normal edge."""
        got = self._by_index.get(edge_id)
        if got is None:
            lanes = self._edge_lanes(self.rmap.edge(edge_id)) if self.rmap.has_edge(edge_id) else []
            got = self._by_index[edge_id] = {l.index: l for l in sorted(lanes, key=lambda l: l.index)}
        return got

    # ------------------------------------------------------------------- grid
    def _lane_boxes_cached(self):
        if self._boxes is None:
            import numpy as np

            from drivefuzz import netcache

            key = self._key("lane-boxes")
            got = netcache.load(key)
            try:
                ids, b = got["ids"], got["boxes"]
                if ids.dtype.kind != "U" or ids.ndim != 1 or b.dtype != np.float64 or b.shape != (len(ids), 4):
                    raise ValueError("not a lane-box entry")
            except (TypeError, KeyError, ValueError):
                ids, b = self._lane_boxes()
                netcache.store(key, {"ids": ids, "boxes": b})
            self._boxes = (ids.tolist(), b)
        return self._boxes

    def _lane_boxes(self):
        """The ids of the normal edges' lanes, in network order, and their bounding boxes grown by a
        margin beyond any segment's reach: (n,) str, (n, 4) float [m]."""
        import numpy as np

        ids, boxes = [], []
        for e in self.rmap.net.getEdges(withInternal=False):
            if e.getFunction() != "":
                continue
            for ln in e.getLanes():
                shape = ln.getShape()
                if len(shape) < 2:
                    continue
                xs, ys = [p[0] for p in shape], [p[1] for p in shape]
                m = 0.5 * float(ln.getWidth()) + REACH + 1.0
                ids.append(ln.getID())
                boxes.append((min(xs) - m, min(ys) - m, max(xs) + m, max(ys) + m))
        return np.asarray(ids, dtype=str), np.asarray(boxes, dtype=float).reshape(-1, 4)

    def cell(self, cx: int, cy: int) -> list[tuple[Lane, int]]:
        """The (lane, segment) pairs within reach of grid cell (cx, cy), lanes in network order."""
        got = self._grid.get((cx, cy))
        if got is None:
            ids, b = self._lane_boxes_cached()
            left, bottom, right, top = cx * CELL, cy * CELL, (cx + 1) * CELL, (cy + 1) * CELL
            got = []
            # the lanes whose grown box meets the cell, in network order: a scan of the boxes is cheaper than
            # an STRtree, whose 9,000 box polygons alone took 80 ms to make on Berlin, for a run's ~100 cells
            hits = ((b[:, 0] <= right) & (b[:, 2] >= left) & (b[:, 1] <= top) & (b[:, 3] >= bottom)).nonzero()[0]
            for k in hits.tolist():
                lane = self.lanes.get(ids[k])
                if lane is None:
                    continue
                for i in range(len(lane.segs)):
                    x0, x1, y0, y1 = lane.cells(i)
                    if x0 <= cx <= x1 and y0 <= cy <= y1:
                        got.append((lane, i))
            self._grid[(cx, cy)] = got
        return got

    def lanes_at(self, x: float, y: float) -> dict[str, tuple[Lane, float, float]]:
        """lane id -> (lane, distance from its centre line, lane heading there) for lanes indexed near (x, y)."""
        out: dict[str, tuple[Lane, float, float]] = {}
        for lane, i in self.cell(int(math.floor(x / CELL)), int(math.floor(y / CELL))):
            d, h = lane.distance(x, y, i, i)
            if d == math.inf:
                continue
            prev = out.get(lane.id)
            if prev is None or d < prev[1]:
                out[lane.id] = (lane, d, h)
        return out

    # ------------------------------------------------------------- junctions
    @property
    def drivable(self):
        """Junction areas a car may drive on (shapely), or None."""
        return self._junction_areas()[0]

    @property
    def walk(self):
        """Walking areas (shapely), or None."""
        return self._junction_areas()[1]

    def _junction_areas(self):
        if self._areas is None:
            key = self._key("areas")
            got = _load_geoms(key, ("drivable", "walk"))
            if got is None:
                got = _junction_areas(self.rmap.net)
                _store_geoms(key, dict(zip(("drivable", "walk"), got)))
            self._areas = got
        return self._areas

    def _key(self, kind: str, *extra: str) -> str:
        import shapely

        from drivefuzz import netcache

        return netcache.entry_key(self.rmap.path, __file__, f"lane-index-{kind}", shapely.__version__,
                                  shapely.geos_version_string, *extra)

    def junction_distance(self, x: float, y: float) -> float:
        """Distance [m] from (x, y) to the drivable junction area (inf beyond ``REACH`` + 1 m, or none)."""
        if self.drivable is None:
            return math.inf
        import shapely

        if self._parts is None:
            parts = list(getattr(self.drivable, "geoms", [self.drivable]))
            self._parts = (parts, shapely.STRtree(parts))
        parts, tree = self._parts
        p = shapely.Point(x, y)
        near = tree.query(p.buffer(REACH + 1.0))
        return min((parts[k].distance(p) for k in near.tolist()), default=math.inf)

    def drivable_within(self, tol: float):
        """The drivable junction area grown by ``tol`` (prepared), or None."""
        return self._drivable_and_cells(tol)[0]

    def drivable_cells(self, tol: float) -> "Cells":
        """The grid cells (closed squares of ``CELL``) that touch :meth:`drivable_within`: a point in
        any other cell is certainly outside it, without asking shapely. Each cell is tested when a point
        first falls in it (a city's bounding box holds a million cells; a run visits a few hundred)."""
        return self._drivable_and_cells(tol)[1]

    def _drivable_and_cells(self, tol: float):
        got = self._drivable_tol.get(tol)
        if got is None:
            g = None
            if self.drivable is not None:
                import shapely

                if tol > 0:
                    key = self._key("grown", repr(float(tol)))
                    loaded = _load_geoms(key, ("grown",))
                    if loaded is None:
                        g = self.drivable.buffer(tol)
                        _store_geoms(key, {"grown": g})
                    else:
                        g = loaded[0]
                else:
                    g = self.drivable
                shapely.prepare(g)
            got = (g, Cells(g))
            self._drivable_tol[tol] = got
        return got


def _junction_areas(net):
    """(drivable junction area, walking areas) of a sumolib network, each None where there is none."""
    from shapely.geometry import LineString
    from shapely.ops import unary_union

    junctions, walks = [], []
    junctions.extend(filter(None, (shape_area(node.getShape()) for node in net.getNodes())))
    car_lanes = []
    for e in net.getEdges(withInternal=True):
        func = e.getFunction()
        if func == "walkingarea":
            walks.extend(filter(None, (shape_area(ln.getShape()) for ln in e.getLanes())))
        elif func == "internal":
            # junction lanes for cars: drivable even where the junction shape is small
            for ln in e.getLanes():
                shape = ln.getShape()
                if ln.allows(PASSENGER) and len(shape) >= 2:
                    line = LineString([(p[0], p[1]) for p in shape])
                    if line.length > 1e-6:
                        car_lanes.append(line.buffer(0.5 * ln.getWidth(), cap_style="flat"))
    walk = unary_union(walks) if walks else None
    drivable = None
    if junctions and walk is not None:
        # the junction shape minus its walking areas, but every junction lane for cars whole: on
        # OSM imports a walking area often covers the whole junction of a road that pedestrians
        # share (a footpath meeting a street), and the cars' own lane through it stays drivable
        junctions = [unary_union(junctions).difference(walk)]
    if junctions or car_lanes:
        drivable = unary_union(junctions + car_lanes)
    return drivable, walk


def shape_area(shape):
    """A SUMO shape (a junction's, a walking area's) as a valid polygon, or None where it has no area."""
    import shapely
    from shapely.geometry import Polygon

    if len(shape) < 3:
        return None
    poly = Polygon([(p[0], p[1]) for p in shape]).buffer(0)
    if not poly.is_valid:  # buffer(0) can leave a self-intersection (a walking area of SUMO's Lübeck port)
        poly = _polygonal(shapely.make_valid(poly))
    return poly if poly is not None and poly.area > 0 else None


def _polygonal(geom):
    """The polygons of a geometry (make_valid may return lines and points beside them), or None."""
    from shapely.geometry import MultiPolygon, Polygon

    if isinstance(geom, (Polygon, MultiPolygon)):
        return geom
    parts = [g for g in getattr(geom, "geoms", ()) if isinstance(g, (Polygon, MultiPolygon))]
    return MultiPolygon([q for g in parts for q in (g.geoms if isinstance(g, MultiPolygon) else [g])]) if parts else None


def _load_geoms(key: str, names: tuple[str, ...]) -> tuple | None:
    """Geometries stored under ``key`` as WKB (an empty array for None), or None when not cached."""
    import numpy as np
    import shapely

    from drivefuzz import netcache

    arrays = netcache.load(key)
    if arrays is None:
        return None
    try:
        out = []
        for name in names:
            a = arrays[name]
            if a.dtype != np.uint8 or a.ndim != 1:
                return None
            out.append(shapely.from_wkb(a.tobytes()) if len(a) else None)
        return tuple(out)
    except (KeyError, ValueError, shapely.errors.ShapelyError):
        return None


def _store_geoms(key: str, geoms: dict) -> None:
    import numpy as np
    import shapely

    from drivefuzz import netcache

    netcache.store(key, {name: np.frombuffer(shapely.to_wkb(g), dtype=np.uint8) if g is not None
                         else np.zeros(0, dtype=np.uint8) for name, g in geoms.items()})


class Cells:
    """The grid cells that touch an area, found on demand (``cell in cells``) and remembered."""

    def __init__(self, area):
        self.area = area
        self.known: dict[tuple[int, int], bool] = {}

    def __contains__(self, cell) -> bool:
        hit = self.known.get(cell)
        if hit is None:
            hit = self.known[cell] = self._touches(cell)
        return hit

    def _touches(self, cell) -> bool:
        if self.area is None:
            return False
        import shapely

        cx, cy = cell
        eps = 0.01  # [m] a cell touching the area only within rounding counts as touching
        return bool(shapely.intersects(self.area, shapely.box(cx * CELL - eps, cy * CELL - eps,
                                                              (cx + 1) * CELL + eps, (cy + 1) * CELL + eps)))


_INDEX: dict[tuple[str, float], NetIndex] = {}


def index(rmap) -> NetIndex:
    """The :class:`NetIndex` of ``rmap``'s network (one per process and file version)."""
    import os

    p = str(rmap.path)
    key = (p, os.path.getmtime(p))
    idx = _INDEX.get(key)
    if idx is None:
        idx = _INDEX[key] = NetIndex(rmap)
    return idx
