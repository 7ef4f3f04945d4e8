"""Exact rational geometry for the polygon tests (every double is a rational, ``fractions``): hulls, supports and
the gap between two polygons; and the rounding each polygon operation is allowed against its exact result, which
tests/unit/test_polygon_exact.py checks against exact references and the comparisons with the numpy code
(tests/polygon_reference.py) derive their bounds from."""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from netsetest.polygon import DUPLICATE

EPS = 2.0**-53  # the unit roundoff of a double: one rounding is within EPS·|x| of the exact result
Point = tuple[Fraction, Fraction]


def exact(v: np.ndarray) -> list[Point]:
    """The rows of ``v`` (n, 2) as exact points."""
    return [(Fraction(float(x)), Fraction(float(y))) for x, y in np.asarray(v, dtype=float).reshape(-1, 2)]


def cross(o: Point, a: Point, b: Point) -> Fraction:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def hull(points: list[Point]) -> list[Point]:
    """The convex hull, counter-clockwise, without collinear vertices (one or two points if flat)."""
    pts = sorted(set(points))
    if len(pts) <= 2:
        return pts

    def chain(ps: list[Point]) -> list[Point]:
        out: list[Point] = []
        for p in ps:
            while len(out) >= 2 and cross(out[-2], out[-1], p) <= 0:
                out.pop()
            out.append(p)
        return out

    return chain(pts)[:-1] + chain(pts[::-1])[:-1]


def normals(h: list[Point]) -> list[Point]:
    """The outward normals of the hull's sides, and both normals and directions of a flat one's."""
    if len(h) == 1:
        return [(Fraction(1), Fraction(0)), (Fraction(-1), Fraction(0)), (Fraction(0), Fraction(1)), (Fraction(0), Fraction(-1))]
    out = []
    for a, b in zip(h, h[1:] + h[:1]):
        e = (b[0] - a[0], b[1] - a[1])
        out.append((e[1], -e[0]))
        if len(h) == 2:
            out += [(-e[1], e[0]), e]
    return out


def support(points: list[Point], d: Point) -> Fraction:
    return max(d[0] * p[0] + d[1] * p[1] for p in points)


def gap(inner: list[Point], outer: list[Point]) -> Fraction:
    """How far (in the ∞-norm, over the sides' directions of both) ``inner`` reaches beyond ``outer``: ≤ 0 if the
    hull of ``outer`` holds it (for a full-dimensional ``outer``, exactly); ≤ b if ``outer`` holds ``inner`` shrunk
    by b (inner ⊆ outer ⊕ b·B∞)."""
    worst = Fraction(-(10**400))
    for d in normals(hull(outer)) + normals(hull(inner)):
        size = abs(d[0]) + abs(d[1])
        if size:
            worst = max(worst, (support(inner, d) - support(outer, d)) / size)
    return worst


def scale(*arrays: np.ndarray) -> float:
    """1 + the sum of the arrays' largest magnitudes: the operands' scale, which a rounding is relative to."""
    return 1.0 + sum(float(np.abs(a).max()) if np.size(a) else 0.0 for a in arrays)


def merged(v: np.ndarray, count: int) -> Fraction:
    """What merging vertices closer than DUPLICATE (polygon._distinct, relative to the coordinates' size) may leave
    out of ``count`` vertices: a chain of them, each that close to the one before (the move's margin covers it)."""
    return Fraction(DUPLICATE) * Fraction(1.0 + float(np.abs(v).max())) * count


# What each operation's result may differ from its exact result by, from the roundings it makes (the walk of the
# sum: one sum per step, the cut's crossings and the reduction's new vertices: a few roundings each, at the
# operands' scale); tests/unit/test_polygon_exact.py holds netsetest/polygon.py to them.


def sum_rounding(v: np.ndarray, segments: list[np.ndarray]) -> Fraction:
    return Fraction(16 * (len(v) + 2 * len(segments) + 2) * EPS * scale(v, *segments))


def move_rounding(image: np.ndarray, segments: list[np.ndarray]) -> Fraction:
    return Fraction(16 * (len(image) + 2 * len(segments) + 8) * EPS * scale(image, *segments))


def cut_rounding(v: np.ndarray, vertices: int | None = None) -> Fraction:
    """(``vertices``: how many the polygon cut has, if not ``v``'s: a polygon at the scale of ``v``, cut in turn.)"""
    return Fraction(64 * (len(v) if vertices is None else vertices) * EPS * scale(v))


def reduction_rounding(v: np.ndarray) -> Fraction:
    return Fraction(64 * len(v) * EPS * scale(v))
