"""Oriented-rectangle geometry: hand-made cases and a property check against shapely."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon

from drivefuzz.geometry import corners, rect_distance, rect_penetration, rects_overlap

CAR = (4.6, 1.9)


def test_corners_order_and_heading():
    c = corners(0.0, 0.0, math.pi / 2, 4.0, 2.0)
    assert c.shape == (4, 2)
    # heading north: forward = +y, left = -x; order front-right, front-left, rear-left, rear-right
    np.testing.assert_allclose(c, [[1, 2], [-1, 2], [-1, -2], [1, -2]], atol=1e-12)
    assert Polygon(c).exterior.is_ccw


def test_corners_broadcast_shape():
    c = corners(np.zeros((3, 1)), 0.0, np.zeros((1, 5)), 4.0, 2.0)
    assert c.shape == (3, 5, 4, 2)


def test_parallel_cars_side_by_side():
    d = rect_distance(0, 0, 0, *CAR, 0, CAR[1] + 0.3, 0, *CAR)
    assert float(d) == pytest.approx(0.3, abs=1e-12)
    # same for any common heading
    h = 0.7
    off = (CAR[1] + 0.3) * np.array([-math.sin(h), math.cos(h)])
    assert float(rect_distance(5, -2, h, *CAR, 5 + off[0], -2 + off[1], h, *CAR)) == pytest.approx(0.3, abs=1e-12)


def test_rotated_45_corner_touching_and_gap():
    half_diag = math.sqrt(2.0)  # 2 x 2 square
    touching = rect_distance(0, 0, 0, 2, 2, 1 + half_diag, 0, math.pi / 4, 2, 2)
    assert float(touching) == pytest.approx(0.0, abs=1e-12)
    assert not rects_overlap(0, 0, 0, 2, 2, 1 + half_diag, 0, math.pi / 4, 2, 2)
    gap = rect_distance(0, 0, 0, 2, 2, 1.5 + half_diag, 0, math.pi / 4, 2, 2)
    assert float(gap) == pytest.approx(0.5, abs=1e-12)


def test_corner_to_corner_diagonal():
    assert float(rect_distance(0, 0, 0, 2, 2, 3, 3, 0, 2, 2)) == pytest.approx(math.sqrt(2), abs=1e-12)


def test_overlap_gives_zero_and_depth():
    assert float(rect_distance(0, 0, 0, 4, 2, 3, 0, 0, 4, 2)) == 0.0
    assert float(rect_penetration(0, 0, 0, 4, 2, 3, 0, 0, 4, 2)) == pytest.approx(1.0)
    assert rects_overlap(0, 0, 0, 4, 2, 3, 0, 0, 4, 2)
    assert not rects_overlap(0, 0, 0, 4, 2, 3, 0, 0, 4, 2, margin=1.5)
    # one inside the other
    assert float(rect_distance(0, 0, 0.3, 10, 10, 0.5, 0.5, 1.0, 1, 1)) == 0.0
    assert float(rect_penetration(0, 0, 0, 4, 2, 9, 0, 0, 4, 2)) == 0.0


def test_broadcast_one_against_many():
    bx = np.array([3.0, 5.0, 10.0])
    d = rect_distance(0, 0, 0, 2, 2, bx, 0, 0, 2, 2)
    assert d.shape == (3,)
    np.testing.assert_allclose(d, [1.0, 3.0, 8.0], atol=1e-12)


_coord = st.floats(-8, 8, allow_nan=False)
_head = st.floats(-math.pi, math.pi, allow_nan=False)
_len = st.floats(0.1, 8, allow_nan=False)
_wid = st.floats(0.1, 3, allow_nan=False)
_rect = st.tuples(_coord, _coord, _head, _len, _wid)


@settings(max_examples=400, deadline=None)
@given(_rect, _rect)
def test_distance_matches_shapely(a, b):
    d = float(rect_distance(*a, *b))
    pa, pb = Polygon(corners(*a)), Polygon(corners(*b))
    assert d == pytest.approx(pa.distance(pb), abs=1e-9)
    assert float(rect_distance(*b, *a)) == pytest.approx(d, abs=1e-12)
    depth = float(rect_penetration(*a, *b))
    if depth > 1e-9:
        assert d == 0.0 and pa.intersection(pb).area > 0 and bool(rects_overlap(*a, *b))
    if d > 1e-9:
        assert depth == 0.0 and not pa.intersects(pb) and not bool(rects_overlap(*a, *b))


@settings(max_examples=100, deadline=None)
@given(_rect, _rect)
def test_penetration_depth_is_minimum_translation(a, b):
    """Moving B by the depth (plus a hair) along the best axis separates them; less does not."""
    depth = float(rect_penetration(*a, *b))
    if depth <= 1e-6:
        return
    pa = Polygon(corners(*a))
    axes = [(math.cos(h), math.sin(h)) for h in (a[2], a[2] + math.pi / 2, b[2], b[2] + math.pi / 2)]

    def separated(shift: float) -> list[bool]:
        out = []
        for ux, uy in axes:
            for sgn in (1, -1):
                bx, by = b[0] + sgn * ux * shift, b[1] + sgn * uy * shift
                out.append(not pa.intersects(Polygon(corners(bx, by, b[2], b[3], b[4]))))
        return out

    assert any(separated(depth + 1e-7))
    assert not any(separated(depth - 1e-7))
