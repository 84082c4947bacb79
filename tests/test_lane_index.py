"""The lane-invasion oracle's on-demand network index gives the answers a whole-network index gives,
and its junction areas survive the disk cache exactly (a corrupt or stale entry is rebuilt)."""

from __future__ import annotations

import math
import random
from pathlib import Path

import numpy as np
import pytest
import shapely

from drivefuzz import netcache
from drivefuzz.scenario.roadmap import PASSENGER, PEDESTRIAN, RoadMap
from oracles.lane_index import BEND, CELL, REACH, NetIndex, _junction_areas
from oracles import wrap_angle

NETWORKS = sorted((Path(__file__).resolve().parent.parent / "networks").glob("*.net.xml"))


def _eager(rmap):
    """The whole-network index as the oracle built it before it was built on demand: lanes (id -> (edge,
    index, segments, bends)), reverse edges, the grid of (lane id, segment) and the lanes of each edge."""
    lanes = {}
    for e in rmap.net.getEdges(withInternal=False):
        if e.getFunction() != "":
            continue
        for ln in e.getLanes():
            pts = [(float(p[0]), float(p[1])) for p in ln.getShape()]
            segs, cum = [], 0.0
            for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:]):
                d = math.hypot(x1 - x0, y1 - y0)
                if d < 1e-9:
                    continue
                segs.append((x0, y0, (x1 - x0) / d, (y1 - y0) / d, d, cum, math.atan2(y1 - y0, x1 - x0)))
                cum += d
            if segs:
                bends = [b[5] for a, b in zip(segs[:-1], segs[1:]) if abs(wrap_angle(b[6] - a[6])) >= BEND]
                lanes[ln.getID()] = (e.getID(), ln.getIndex(), float(ln.getWidth()), segs, bends,
                                     e.getFromNode().getID(), e.getToNode().getID(), bool(ln.allows(PASSENGER)),
                                     bool(ln.allows(PEDESTRIAN)))
    by_nodes: dict = {}
    for edge, _i, _w, _s, _b, fr, to, _p, _q in lanes.values():
        by_nodes.setdefault((fr, to), set()).add(edge)
    reverse = {}
    for (fr, to), edges in by_nodes.items():
        for e in edges:
            reverse[e] = frozenset(by_nodes.get((to, fr), ()))
    grid: dict = {}
    for lid, (_e, _i, width, segs, _b, _f, _t, _p, _q) in lanes.items():
        r = 0.5 * width + REACH
        for i, (x0, y0, ux, uy, ln, _c, _h) in enumerate(segs):
            x1, y1 = x0 + ux * ln, y0 + uy * ln
            for cx in range(int(math.floor((min(x0, x1) - r) / CELL)), int(math.floor((max(x0, x1) + r) / CELL)) + 1):
                for cy in range(int(math.floor((min(y0, y1) - r) / CELL)), int(math.floor((max(y0, y1) + r) / CELL)) + 1):
                    grid.setdefault((cx, cy), []).append((lid, i))
    by_index: dict = {}
    for lid, (edge, index, *_rest) in lanes.items():
        by_index.setdefault(edge, {})[index] = lid
    return lanes, reverse, grid, by_index


@pytest.mark.parametrize("net", NETWORKS, ids=lambda p: p.stem)
def test_on_demand_index_matches_the_whole_network_index(net):
    rmap = RoadMap(net)
    lanes, reverse, grid, by_index = _eager(rmap)
    idx = NetIndex(rmap)
    every_lane = [l.getID() for e in rmap.net.getEdges(withInternal=True) for l in e.getLanes()]
    for lid in every_lane + ["no-such-lane"]:
        got = idx.lanes.get(lid)
        if lid not in lanes:
            assert got is None, lid
            continue
        edge, index, width, segs, bends, fr, to, passenger, pedestrian = lanes[lid]
        assert (got.edge, got.index, got.width, got.segs, got.bends, got.from_node, got.to_node, got.passenger,
                got.pedestrian) == (edge, index, width, segs, bends, fr, to, passenger, pedestrian)
        assert got.change_left == rmap.may_change(lid, left=True)
        assert got.change_right == rmap.may_change(lid, left=False)
    for e in rmap.net.getEdges(withInternal=True):
        assert idx.reverse(e.getID()) == reverse.get(e.getID(), frozenset()), e.getID()
        assert {k: l.id for k, l in idx.by_index(e.getID()).items()} == by_index.get(e.getID(), {})
    # every cell of the whole-network grid, and the empty ones around it, in the same order
    cells = set(grid)
    cells |= {(cx + dx, cy + dy) for cx, cy in list(cells) for dx in (-1, 1) for dy in (-1, 1)}
    for cx, cy in sorted(cells):
        assert [(l.id, i) for l, i in idx.cell(cx, cy)] == grid.get((cx, cy), []), (cx, cy)
    rng = random.Random(1)
    x0, y0, x1, y1 = rmap.bounds()
    fresh = NetIndex(rmap)  # asked point by point, as a run asks
    for _ in range(300):
        x, y = rng.uniform(x0, x1), rng.uniform(y0, y1)
        got = {k: (v[1], v[2]) for k, v in fresh.lanes_at(x, y).items()}
        want = {}
        for lid, i in grid.get((int(math.floor(x / CELL)), int(math.floor(y / CELL))), []):
            d, h = idx.lanes.get(lid).distance(x, y, i, i)
            if d != math.inf and (lid not in want or d < want[lid][0]):
                want[lid] = (d, h)
        assert list(got.items()) == list(want.items())


def _wkb(g):
    return None if g is None else shapely.to_wkb(g)


@pytest.mark.parametrize("net", NETWORKS, ids=lambda p: p.stem)
def test_junction_areas_from_the_cache_are_exact(net, tmp_path, monkeypatch):
    monkeypatch.setenv("DRIVEFUZZ_CACHE", str(tmp_path))
    rmap = RoadMap(net)
    drivable, walk = _junction_areas(rmap.net)
    grown = drivable.buffer(0.5) if drivable is not None else None
    first = NetIndex(rmap)  # derives them and fills the cache
    assert (_wkb(first.drivable), _wkb(first.walk), _wkb(first.drivable_within(0.5))) == \
        (_wkb(drivable), _wkb(walk), _wkb(grown))
    assert list(tmp_path.glob("*.npz"))
    second = NetIndex(rmap)  # reads them
    assert (_wkb(second.drivable), _wkb(second.walk), _wkb(second.drivable_within(0.5))) == \
        (_wkb(drivable), _wkb(walk), _wkb(grown))


def test_lane_boxes_come_from_the_cache_and_a_malformed_entry_is_rebuilt(tmp_path, monkeypatch):
    monkeypatch.setenv("DRIVEFUZZ_CACHE", str(tmp_path))
    rmap = RoadMap(NETWORKS[-1])
    x, y = rmap.geom(rmap.lanes()[0]).position(5.0)[:2]
    cell = (int(math.floor(x / CELL)), int(math.floor(y / CELL)))
    first = NetIndex(rmap)
    want = [(l.id, i) for l, i in first.cell(*cell)]
    assert want
    key = first._key("lane-boxes")
    stored = netcache.load(key)
    assert stored["ids"].tolist() == first._lane_boxes()[0].tolist()
    assert [(l.id, i) for l, i in NetIndex(rmap).cell(*cell)] == want  # from the entry
    for ids, boxes in ((stored["ids"], stored["boxes"][:, :3]),  # a wrong shape
                       (np.arange(len(stored["ids"])), stored["boxes"]),  # ids that are not strings
                       (np.stack([stored["ids"], stored["ids"]], axis=1), stored["boxes"])):  # ids in two columns
        netcache.store(key, {"ids": ids, "boxes": boxes})
        assert [(l.id, i) for l, i in NetIndex(rmap).cell(*cell)] == want
        assert netcache.load(key)["boxes"].shape == stored["boxes"].shape  # rewritten whole


def test_a_corrupt_or_foreign_cache_entry_is_rebuilt(tmp_path, monkeypatch):
    monkeypatch.setenv("DRIVEFUZZ_CACHE", str(tmp_path))
    rmap = RoadMap(NETWORKS[-1])
    want = _wkb(_junction_areas(rmap.net)[0])
    NetIndex(rmap).drivable
    (entry,) = tmp_path.glob("*.npz")
    for bad in (b"not a zip file", entry.read_bytes()[:200]):
        entry.write_bytes(bad)
        assert _wkb(NetIndex(rmap).drivable) == want
        assert netcache.load(NetIndex(rmap)._key("areas")) is not None  # rewritten whole
    # an entry under the right name whose key is another's, or whose WKB is garbage
    key = NetIndex(rmap)._key("areas")
    np.savez(entry, __key__=np.array("another key"), drivable=np.zeros(3, np.uint8), walk=np.zeros(0, np.uint8))
    assert netcache.load(key) is None
    assert _wkb(NetIndex(rmap).drivable) == want
    np.savez(entry, __key__=np.array(key), drivable=np.frombuffer(b"\x01\x02garbage", np.uint8),
             walk=np.zeros(0, np.uint8))
    assert _wkb(NetIndex(rmap).drivable) == want


def test_the_cache_reads_data_never_objects(tmp_path, monkeypatch):
    monkeypatch.setenv("DRIVEFUZZ_CACHE", str(tmp_path))
    key = "some key"
    assert netcache.store(key, {"a": np.arange(3.0)})
    assert netcache.load(key)["a"].tolist() == [0.0, 1.0, 2.0]
    (entry,) = tmp_path.glob("*.npz")
    np.savez(entry, __key__=np.array(key), a=np.array([{"x": 1}], dtype=object))  # pickled inside
    assert netcache.load(key) is None
    monkeypatch.setenv("DRIVEFUZZ_CACHE", "off")
    assert netcache.cache_dir() is None and not netcache.store(key, {}) and netcache.load(key) is None


def test_a_changed_network_file_is_a_new_key(tmp_path, monkeypatch):
    net = tmp_path / "n.net.xml"
    net.write_bytes(NETWORKS[0].read_bytes())
    code = Path(netcache.__file__)
    k1 = netcache.entry_key(net, code, "x")
    net.write_bytes(NETWORKS[0].read_bytes() + b"\n")
    assert netcache.entry_key(net, code, "x") != k1


def test_a_sound_network_is_not_checked_again_but_a_faulty_one_is(tmp_path, monkeypatch):
    from drivefuzz.errors import InvalidNetwork
    from drivefuzz.scenario import validate

    monkeypatch.setenv("DRIVEFUZZ_CACHE", str(tmp_path / "cache"))
    net = tmp_path / "n.net.xml"
    net.write_bytes(NETWORKS[0].read_bytes())
    validate.check_network(net)
    assert validate._checked_before(net.resolve())
    monkeypatch.setattr(validate, "_checked", {})  # a new process
    monkeypatch.setattr(validate, "_check_network_xml", lambda p: pytest.fail("checked again"))
    validate.check_network(net)
    monkeypatch.undo()
    monkeypatch.setenv("DRIVEFUZZ_CACHE", str(tmp_path / "cache"))
    for entry in (tmp_path / "cache").glob("*.npz"):
        entry.write_bytes(b"corrupt")
    assert not validate._checked_before(net.resolve())
    bad = tmp_path / "bad.net.xml"
    bad.write_text(NETWORKS[0].read_text().replace("<net ", "<notnet ", 1).replace("</net>", "</notnet>"))
    for _ in range(2):
        monkeypatch.setattr(validate, "_checked", {})
        with pytest.raises(InvalidNetwork, match="root element"):
            validate.check_network(bad)
        assert not validate._checked_before(bad.resolve())


def test_no_key_no_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DRIVEFUZZ_CACHE", str(tmp_path))
    assert netcache.entry_key(tmp_path / "gone.net.xml", netcache.__file__, "x") is None
    assert not netcache.store(None, {"a": np.zeros(1)}) and netcache.load(None) is None


def test_a_walking_area_that_buffer_0_leaves_invalid_is_made_valid():
    """SUMO's Lübeck port network (DLR-TS/sumo-scenarios) has a walking area whose shape is five nearly
    collinear points: GEOS's buffer(0) turns it into a self-intersecting polygon, and the union of the walking
    areas then raised a TopologyException at the lane-invasion oracle's reset (exit 3 for a network SUMO runs)."""
    import shapely

    from oracles.lane_index import shape_area

    shape = [(11136.38, 8313.08), (11134.45, 8312.57), (11131.35, 8311.76), (11128.26, 8310.95), (11126.32, 8310.44)]
    assert not shapely.Polygon(shape).buffer(0).is_valid  # the GEOS behaviour this guards against
    poly = shape_area(shape)
    assert poly is None or poly.is_valid  # valid geometry is what GEOS's overlays require of their input
