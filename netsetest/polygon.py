"""Convex polygons in the plane of the vehicle state x = (β, r): the one-step map, the sum with a segment,
the cut by a slab and an outer reduction, each of which keeps every point it held (sound), with an outward
margin for rounding.

A node's *region* (docs/network.md) is such a polygon: the states its prior allows, moved through the
step's dynamics and the disturbance's bound, and cut by the step's readings.  Unlike an ellipsoid it keeps
what every earlier reading proved, as the exact limit does, at a bounded number of vertices.

Vertices are stored counter-clockwise as plain floats, n ≥ 3; a flat polygon (a segment, a point: fewer distinct
vertices, or all on one line) only where its input was flat or a cut left a sliver below the rounding.  Every
operation reads a polygon as the convex hull of its vertices, whatever their order.

The move, the cut and the reduction run here in plain Python, or compiled (``NETSETEST_POLYGON=compiled``, the
``fast`` extra: netsetest/polygon_compiled.py), step for step the same operations and the same vertices; whatever
the compiled move cannot decide in floating point it hands to the plain-Python one here.
"""

from __future__ import annotations

import functools
import itertools
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from types import ModuleType

import numpy as np

import netsetest.linalg as linalg
from netsetest.extras import require

MIN_VERTICES = 3
MAX_VERTICES = 24  # the reduction keeps at most this many (each step adds about 8)
MARGIN = 1e-9  # outward, relative to the polygon's extent: covers the rounding of one step's operations
ROUNDING = 1e-10  # outward, relative to the coordinates' size: far above one step's rounding (ε·n)
MAX_REACH = 1e3  # a drop extends a neighbour by at most this many of its lengths (q's rounding stays ≪ DUPLICATE)
SLIVER = 1e-4  # Polygon.within cuts by a side of the other polygon only where it takes off more than this of the width
_OUTWARD = np.array([[0.0, -1.0], [1.0, 0.0]])  # (e_x, e_y) @ this = (e_y, −e_x): a counter-clockwise side's outward normal
DUPLICATE = 1e-13  # vertices closer than this (relative to the coordinates' size) are one: far below ROUNDING
# A published region (docs/network.md): what decode accepts (:func:`region_problem`), a reason each for what it drops
MAX_COORDINATE = 1e10  # |β| [rad], |r| [rad/s]: over a thousand times the largest prior box a topology may declare (|x̂0| ≤ 10³,
# √(ρ·P0) ≤ 10⁶: config/schema.py, tests/unit/test_polygon_membership.py holds the tie), and far inside the float range
# (every product the checks and the judge form is finite)
CONVEX_TOLERANCE = ROUNDING  # a turn the wrong way this shallow (relative to the coordinates' size) is a rounding's: the
# region is read as its hull, which it holds to within the move's own pad
REGION_ODD, REGION_VERTICES, REGION_NOT_NUMBERS = "region-odd", "region-vertices", "region-not-numbers"
REGION_NOT_FINITE, REGION_SCALE = "region-not-finite", "region-scale"
REGION_NOT_CONVEX, REGION_SELF_INTERSECTING, REGION_CLOCKWISE = "region-not-convex", "region-self-intersecting", "region-clockwise"
REGION_REASONS = frozenset(
    (REGION_ODD, REGION_VERTICES, REGION_NOT_NUMBERS, REGION_NOT_FINITE, REGION_SCALE, REGION_NOT_CONVEX, REGION_SELF_INTERSECTING, REGION_CLOCKWISE)
)


Point = tuple[float, float]
Span = tuple[float, float]  # [min cᵀx, max cᵀx] over a polygon
Direction = np.ndarray | Sequence[float]  # c = (c_β, c_r)
PlaneSlab = tuple[float, float, float, float]  # (c0, c1, lo, hi): lo ≤ c0 β + c1 r ≤ hi, plain floats
Ellipse = tuple[np.ndarray, np.ndarray, float]  # (x̂, P, ρ) of {(x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ}, x̄ = (β, r, …)
INSIDE = 1e-6  # relative, in ρ: a region this far inside the ellipse is held by every slab of Polygon.ellipse_cut ...
INSIDE_COND = 1e8  # ... where P_xx's condition number (at most tr²/det) keeps the test's rounding below a tenth of that
_AXES = ((1.0, 0.0), (0.0, 1.0))  # β and r: the directions of an ellipse cut's coordinate slabs


class Polygon:
    """A convex polygon: its vertices counter-clockwise as plain floats, ``points`` ((β, r) pairs), or as the (n, 2)
    array the compiled operations work on (netsetest/polygon_compiled.py), whichever an operation made: the other
    is made from it when first asked for, once (at 24–34 vertices numpy's per-call set-up costs more than the
    arithmetic of a plain-float operation, and a conversion in every operation costs more than a compiled one).
    Immutable; ``vertices`` is the (n, 2) array, a new one, for the readers who want one."""

    __slots__ = ("_points", "_xy")
    _points: tuple[Point, ...] | None
    _xy: np.ndarray | None

    def __init__(self, vertices: np.ndarray | Sequence[Sequence[float]]) -> None:
        """From the vertices (n, 2), counter-clockwise."""
        xs, ys = np.asarray(vertices, dtype=float).reshape(-1, 2).T.tolist()
        object.__setattr__(self, "_points", tuple(zip(xs, ys)))
        object.__setattr__(self, "_xy", None)

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(f"Polygon is immutable: cannot set {name}")

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Polygon) and self.points == other.points

    def __hash__(self) -> int:
        return hash(self.points)

    def __repr__(self) -> str:
        return f"Polygon(points={self.points!r})"

    def __reduce__(self) -> tuple[object, tuple[tuple[Point, ...]]]:
        return Polygon._of, (self.points,)

    @classmethod
    def _of(cls, points: Sequence[Point]) -> Polygon:
        """The polygon of plain-float vertices an operation made (as they are)."""
        out = object.__new__(cls)
        object.__setattr__(out, "_points", tuple(points))
        object.__setattr__(out, "_xy", None)
        return out

    @classmethod
    def _of_array(cls, xy: np.ndarray) -> Polygon:
        """The polygon of the (n, 2) float64 array a compiled operation made (its own: no one else writes it)."""
        out = object.__new__(cls)
        object.__setattr__(out, "_points", None)
        object.__setattr__(out, "_xy", xy)
        return out

    @property
    def points(self) -> tuple[Point, ...]:
        """The vertices as (β, r) pairs of plain floats."""
        if self._points is None:
            xs, ys = self._xy.T.tolist()  # type: ignore[union-attr]  # one of the two is always set
            object.__setattr__(self, "_points", tuple(zip(xs, ys)))
        return self._points  # type: ignore[return-value]  # set just above

    def _array(self) -> np.ndarray:
        """The vertices as the (n, 2) float64 array the compiled operations take (made once; not to be written)."""
        if self._xy is None:
            object.__setattr__(self, "_xy", np.array(self._points, dtype=float).reshape(-1, 2))
        return self._xy  # type: ignore[return-value]  # set just above

    @classmethod
    def from_flat(cls, coords: Sequence[float]) -> Polygon:
        """From the flattened vertices [β₁, r₁, β₂, r₂, …] (as published)."""
        return cls._of(list(zip(map(float, coords[0::2]), map(float, coords[1::2]))))

    @classmethod
    def box(cls, lo: np.ndarray, hi: np.ndarray) -> Polygon:
        """The box lo ≤ x ≤ hi."""
        (x0, y0), (x1, y1) = (float(lo[0]), float(lo[1])), (float(hi[0]), float(hi[1]))
        return cls._of([(x0, y0), (x1, y0), (x1, y1), (x0, y1)])

    @property
    def vertices(self) -> np.ndarray:
        """The vertices as an (n, 2) array (a new one)."""
        return self._array().copy()

    def flat(self) -> list[float]:
        """The vertices flattened, [β₁, r₁, β₂, r₂, …] (as published: proven.ProvenSet's ``region``)."""
        if self._points is None:
            return self._xy.ravel().tolist()  # type: ignore[union-attr]  # one of the two is always set
        return list(itertools.chain.from_iterable(self._points))

    def __len__(self) -> int:
        return len(self._points) if self._points is not None else len(self._xy)  # type: ignore[arg-type]  # one is set

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The interval hull: each coordinate's lowest and highest vertex, (2,) each (exact: no rounding)."""
        xs, ys = zip(*self.points)
        return np.array([min(xs), min(ys)]), np.array([max(xs), max(ys)])

    def interval(self, c: Direction) -> tuple[float, float]:
        """[min cᵀx, max cᵀx] over the polygon."""
        return _spans(self.points, (c,))[0]

    def contains(self, x: np.ndarray) -> bool:
        """x in the convex hull of the vertices, exactly, whatever their order (a clockwise one, a rounding's reflex
        vertex) and at any finite scale (no margin: for tests and the judge).  Strictly left of every side in turn
        already proves it (each side then sweeps a positive angle seen from x, so the closed path winds around x,
        which no point outside the hull has); else x is checked against the sides of the exact hull.  Every sign is
        :func:`_cross_sign`'s, exact where floating point cannot decide it (rounding, an overflow at 1e308), so a
        point a rounding would put on the wrong side of a side, or an overflow make NaN, is never misjudged."""
        px, py = float(x[0]), float(x[1])
        v = self.points
        ax, ay = v[-1]
        for bx, by in v:
            if _cross_sign(ax, ay, bx, by, ax, ay, px, py) <= 0:
                return _in_hull(_hull(v), px, py)
            ax, ay = bx, by
        return True

    def affine(self, A: np.ndarray, t: np.ndarray) -> Polygon:
        """{A x + t}: A (2, 2); the vertices' order reversed where det A < 0 (its sign exact: a rounded determinant
        of a near-singular A could flip the orientation)."""
        return Polygon._of(_affine(self.points, A, t))

    def plus_segments(self, segments: list[np.ndarray]) -> Polygon:
        """The sum with the segments {s g : |s| ≤ 1} of ``segments`` (each g (2,)): the polygon's edges and every ±2g
        merged by direction in one pass (two more vertices per segment), walked from the lowest (then leftmost)
        vertex plus every segment's lowest (then leftmost) end, where that order starts.  The directions are
        ordered exactly (:func:`_ordered`: half-plane, then the sign of the cross product), never by a rounded
        angle alone: an edge a few ulps below horizontal comes last, not first.  Where a rounding has made a vertex
        reflex (the edges do not turn one way from there), the walk is over the exact hull of the vertices, which
        holds them all; parallel directions in a row leave no vertex between them.  Sound to the walk's rounding and
        the merge of vertices closer than DUPLICATE (:func:`_distinct`), which the margin of :meth:`moved` covers."""
        return Polygon._of(_plus(list(self.points), [(float(x), float(y)) for x, y in segments]))

    def moved(self, A: np.ndarray, t: np.ndarray, segments: list[np.ndarray]) -> Polygon:
        """{A x + t} summed with the segments and a square of half-side ROUNDING of the coordinates' size, in one
        merge: every side moves out by at least that, which covers the step's rounding (this move's, the cuts'
        that follow, each widened by its own margin, and the vertices merged as duplicates); at least what that
        merge can leave out where the segments reach far beyond the image (a flat or tiny image)."""
        kernels = _compiled()
        if kernels is not None:
            out = kernels.moved(self._array(), np.asarray(A, dtype=float), np.asarray(t, dtype=float), _segment_array(segments), _CONSTANTS)
            if out is not None:  # (None: a sign, an order or a hull only exact arithmetic decides, below)
                return Polygon._of_array(out)
        v = _affine(self.points, A, t)
        g = [(float(x), float(y)) for x, y in segments]
        size = max(map(abs, itertools.chain.from_iterable(v)))
        reach = size + sum(max(abs(x), abs(y)) for x, y in g)
        merged = (2 * (len(v) + 2 * len(g)) + 8) * DUPLICATE * (1.0 + reach)
        pad = max(ROUNDING * (1.0 + size), merged)
        return Polygon._of(_plus(v, [*g, (pad, 0.0), (0.0, pad)]))

    def cut(self, c: Direction, lo: float, hi: float) -> Polygon | None:
        """The part with lo ≤ cᵀx ≤ hi, widened outward by the margin (relative to max Σᵢ |cᵢ xᵢ|, which bounds the
        rounding of cᵀx where its terms cancel), and at least by what merging its vertices closer than DUPLICATE
        can leave out along c (a slab thin next to the coordinates' size); None if empty (flat if this polygon
        is: a segment's part is one)."""
        c0, c1, lo, hi = float(c[0]), float(c[1]), float(lo), float(hi)  # (numpy scalars would make the vertices theirs)
        kernels = _compiled()
        if kernels is not None:
            kept, out = kernels.cut(self._array(), c0, c1, lo, hi, _CONSTANTS)
            return self if kept == 0 else None if kept < 0 else Polygon._of_array(out)
        v = self.points
        s = [c0 * x + c1 * y for x, y in v]
        s_min, s_max = min(s), max(s)
        if lo <= s_min and s_max <= hi:  # inside the slab itself, so inside it widened by any pad ≥ 0: what both
            return self  # clips below would keep (most cuts of a step)
        size = max(map(abs, itertools.chain.from_iterable(v)))
        merged = (2 * len(v) + 2) * DUPLICATE * (1.0 + size) * (abs(c0) + abs(c1))
        pad = max(MARGIN * (1.0 + max(abs(c0 * x) + abs(c1 * y) for x, y in v)), merged)
        if s_max <= hi + pad and -s_min <= -lo + pad:  # no vertex outside the widened slab: likewise
            return self  # (−c0 x − c1 y is −(c0 x + c1 y) exactly: every rounding is symmetric in sign)
        out = _clip(list(v), s, c0, c1, hi + pad)
        if out is not None:
            out = _clip(out, None, -c0, -c1, -lo + pad)
        return None if out is None else Polygon._of(out)

    def within(self, other: Polygon, sliver: float = SLIVER) -> Polygon | None:
        """This polygon ∩ ``other``: cut by the supporting half-plane of ``other`` along the outward normal of each of
        its sides (the support over every vertex of ``other``, so the half-plane holds its hull whatever the order or
        a rounding's reflex vertex), each cut widened by :meth:`cut`'s margin; None if nothing is left.  Sound wherever
        both hold the point.  Only the sides this polygon lies beyond by more than ``sliver`` of its own width along
        their normal cut (leaving a half-plane out only keeps more: still sound; on two regions of one scenario 99 % of
        the sides beyond are slivers of rounding and margins, below 10⁻⁶ of the width, each a cut for nothing): where
        there is none, this polygon itself."""
        w = other.vertices
        m = len(w)
        n = (w[_successors(m)] - w) @ _OUTWARD  # the sides' outward normals (a counter-clockwise polygon's), unnormalised
        s = np.concatenate((w, self.vertices)) @ n.T
        support, mine = s[:m].max(axis=0), s[m:]
        top = mine.max(axis=0)
        beyond = np.flatnonzero(top - support > sliver * (top - mine.min(axis=0)))
        if not len(beyond):
            return self
        c = n[beyond] / np.abs(n[beyond]).max(axis=1)[:, None]  # |c|∞ = 1, so that each cut's margin is one of the coordinates' size
        a = np.abs(self.vertices)
        reach = (a @ np.abs(c).T).max(axis=0)  # max Σᵢ |cᵢ xᵢ| over this polygon: over any part of it no more
        v = _clipped(list(self.points), c.tolist(), (w @ c.T).max(axis=0).tolist(), reach.tolist(), float(a.max()))
        return None if v is None else Polygon._of(v)

    def ellipse_cut(self, xhat: np.ndarray, P: np.ndarray, rho: float, coordinates: bool = True) -> Polygon | None:
        """This polygon cut by the slabs of the ellipsoid {(x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ} (x̄'s first two coordinates β, r)
        along β and r (``coordinates``; a box of it needs no such cut) and along the principal axes of its
        x-projection ρ P_xx: an outer octagon of that ellipse.  Sound wherever the ellipsoid holds the truth; None if
        nothing is left.

        Where the polygon lies well inside the ellipse (:func:`_well_inside`: most steps) every slab holds it and each
        cut would return it as it is: it is returned at once, without the eigen decomposition."""
        pxx = 0.5 * (P[:2, :2] + P[:2, :2].T)
        (p00, p01), (p10, p11) = pxx.tolist()
        x0, x1 = float(xhat[0]), float(xhat[1])
        if coordinates and _well_inside(self.points, x0, x1, p00, p01, p11, rho):
            return self
        _, vecs = linalg.eigh(pxx)
        axes = [tuple(d) for d in vecs.T.tolist()]
        out: Polygon | None = self
        for d0, d1 in [*_AXES, *axes] if coordinates else axes:
            if out is None:
                return None
            # dᵀx̂ and (dᵀP_xx) d in plain floats, each product and sum rounded (numpy's 2-vector products go through
            # OpenBLAS, whose kernel may fuse them: the same to a few ulps, tests/unit/test_polygon_same.py)
            w0, w1 = d0 * p00 + d1 * p10, d0 * p01 + d1 * p11
            centre, half = d0 * x0 + d1 * x1, math.sqrt(max(rho * (w0 * d0 + w1 * d1), 0.0))
            out = out.cut((d0, d1), centre - half, centre + half)
        return out

    def extent(self, c: np.ndarray) -> float:
        """max |cᵀx| over the polygon."""
        c0, c1 = float(c[0]), float(c[1])
        return max(abs(c0 * x + c1 * y) for x, y in self.points)

    def reduced(self, max_vertices: int = MAX_VERTICES) -> Polygon:
        """At most ``max_vertices`` vertices, containing this polygon: an edge is dropped by extending its two
        neighbours until they meet, the ones that add the least area first (edges at least three apart at once:
        their neighbours' lines are then untouched)."""
        if len(self) <= max_vertices:
            return self
        kernels = _compiled()
        if kernels is not None:
            return Polygon._of_array(kernels.reduced(self._array(), max_vertices, _CONSTANTS))
        v = list(self.points)
        while len(v) > max_vertices:
            drops = _cheapest_edges(v, len(v) - max_vertices)
            if not drops:
                break  # no edge can be dropped without an unbounded extension (for n > 4 only where a rounding
                # puts two neighbours' meeting a hair behind an edge: near-duplicate vertices)
            v = _drop_edges(v, drops)
        return Polygon._of(v)


def _well_inside(points: Sequence[Point], x0: float, x1: float, p00: float, p01: float, p11: float, rho: float) -> bool:
    """Whether every vertex v has (v − x̂)ᵀ P_xx⁻¹ (v − x̂) ≤ ρ (1 − INSIDE), tested as det·q ≤ det·ρ (1 − INSIDE)
    with P_xx's adjugate (no division) where tr²/det ≤ INSIDE_COND.  Then the test's rounding (relative, at most
    about 12 ε·tr²/det ≈ 1.3·10⁻⁷) leaves every vertex at least ≈ 2·10⁻⁷ of the ellipse's half-width inside each slab
    of :meth:`Polygon.ellipse_cut`, far beyond the rounding of the slab's own ends and of cᵀv, which the cut's margin
    covers: each cut would return the polygon as it is (tests/unit/test_polygon_same.py holds the two to the same set)."""
    det, tr = p00 * p11 - p01 * p01, p00 + p11
    if not (det > 0.0 and tr * tr <= INSIDE_COND * det):
        return False
    bound = rho * (1.0 - INSIDE) * det
    for x, y in points:
        a, b = x - x0, y - x1
        if not p11 * a * a - 2.0 * p01 * a * b + p00 * b * b <= bound:  # det · (v − x̂)ᵀ P_xx⁻¹ (v − x̂)
            return False
    return True


def _spans(points: Sequence[Point], directions: Sequence[Direction]) -> list[Span]:
    """[min cᵀx, max cᵀx] over the points for each direction c (:meth:`Polygon.interval`)."""
    out = []
    for c in directions:
        c0, c1 = float(c[0]), float(c[1])
        s = [c0 * x + c1 * y for x, y in points]
        out.append((min(s), max(s)))
    return out


@dataclass(frozen=True)
class Advanced:
    """A region through one step (:func:`advance`): the moved polygon, which of the other polygons cut it before the
    move (their indices), and its spans along the directions asked for."""

    polygon: Polygon
    used: tuple[int, ...]
    spans: tuple[Span, ...]


def advance(
    region: Polygon, others: Sequence[Polygon], A: np.ndarray, t: np.ndarray, segments: list[np.ndarray], directions: Sequence[Direction] = ()
) -> Advanced:
    """One step of a region in one call: the region cut by each of ``others`` in turn (:meth:`Polygon.within`; at the
    first that leaves no polygon, an assumption broke: no more cuts), then moved (:meth:`Polygon.moved`), and the moved
    polygon's spans along ``directions``."""
    used: list[int] = []
    for k, other in enumerate(others):
        cut = region.within(other)
        if cut is None or len(cut) < MIN_VERTICES:
            break  # the two hold no common point: an assumption broke (one of the sets missed); no more cuts
        if cut is not region:
            region, used = cut, [*used, k]
    moved = region.moved(A, t, segments)
    return Advanced(moved, tuple(used), tuple(_spans(moved.points, directions)) if directions else ())


@dataclass(frozen=True)
class Cut:
    """A region after the step's cuts and its reduction (:func:`cut_all`): the polygon, its interval hull (β lo, r lo,
    β hi, r hi: its vertices' extremes, exact) and its spans along the directions asked for."""

    polygon: Polygon
    box: tuple[float, float, float, float]
    spans: tuple[Span, ...]


def _box_inside(box: tuple[float, float, float, float], c0: float, c1: float, lo: float, hi: float) -> bool:
    """Whether lo ≤ c0 x + c1 y ≤ hi at every vertex, decided from the vertices' extremes (x₀, y₀, x₁, y₁) alone:
    the box's corner with the largest (smallest) c0 x + c1 y, rounded as :meth:`Polygon.cut` rounds each vertex's,
    is at least (at most) every vertex's, since rounding is monotone; True only where :meth:`Polygon.cut` would return
    the polygon itself."""
    x0, y0, x1, y1 = box
    s_max = c0 * (x1 if c0 >= 0.0 else x0) + c1 * (y1 if c1 >= 0.0 else y0)
    s_min = c0 * (x0 if c0 >= 0.0 else x1) + c1 * (y0 if c1 >= 0.0 else y1)
    return lo <= s_min and s_max <= hi


def cut_all(
    region: Polygon, slabs: Sequence[PlaneSlab], ellipses: Sequence[Ellipse] = (), directions: Sequence[Direction] = (), max_vertices: int = MAX_VERTICES
) -> Cut | None:
    """The step's cuts of a region in one call: by every slab in turn (:meth:`Polygon.cut`), then by every ellipse's
    octagon (:meth:`Polygon.ellipse_cut`), then reduced to ``max_vertices`` (:meth:`Polygon.reduced`; the move's
    margin covers the cuts' rounding), with its box and its spans along ``directions``; None where the cuts leave
    nothing, or fewer than MIN_VERTICES vertices (a sliver below the rounding, kept as empty)."""
    out: Polygon | None = region
    box: tuple[float, float, float, float] | None = None  # out's vertices' extremes, while out is unchanged
    for c0, c1, lo, hi in slabs:
        if out is None:
            return None
        if box is None:
            pts = out.points
            xs, ys = [p[0] for p in pts], [p[1] for p in pts]
            box = (min(xs), min(ys), max(xs), max(ys))
        if _box_inside(box, c0, c1, lo, hi):
            continue  # every vertex inside the slab: the cut would keep this polygon itself (most slabs of a step)
        cut = out.cut((c0, c1), lo, hi)
        if cut is not out:
            out, box = cut, None
    for xhat, P, rho in ellipses:
        if out is None:
            return None
        out = out.ellipse_cut(xhat, P, rho)
    if out is None or len(out) < MIN_VERTICES:
        return None
    out = out.reduced(max_vertices)
    pts = out.points
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    return Cut(out, (min(xs), min(ys), max(xs), max(ys)), tuple(_spans(pts, directions)))


BACKEND_ENV = "NETSETEST_POLYGON"  # "compiled": the move, the cut and the reduction compiled (the fast extra)
BACKENDS = ("compiled", "python")
# Plain Python unless chosen: a process's first compiled operation costs about 0.5 s of CPU (numba's import and its
# on-disk cache; 12 s to compile where nothing is cached), which a node process's start-up pays and a short run
# never wins back (about 0.1 ms per NSNIM step; DEVELOPERS.md, "Dependencies")
_kernels: ModuleType | None = None  # netsetest.polygon_compiled once loaded
_backend: str | None = None  # None: not chosen yet (on first use: BACKEND_ENV's, else python)


def _compiled() -> ModuleType | None:
    """The compiled kernels where they are the backend, else None (the plain-Python operations)."""
    if _backend is None:
        _use(os.environ.get(BACKEND_ENV) or "python")
    return _kernels if _backend == "compiled" else None


class BackendError(ValueError):
    """``NETSETEST_POLYGON`` names no backend."""


def use_backend_from_env() -> None:
    """Choose the backend now, from ``NETSETEST_POLYGON`` (else python): the CLI does before any command, so that a
    bad value is one line and exit 2 there, not a failure in a run's first step (BackendError, MissingExtra)."""
    _use(os.environ.get(BACKEND_ENV) or "python")


def _use(backend: str) -> str:
    """Choose the backend of the hot operations, ``compiled`` (numba: netsetest/polygon_compiled.py) or ``python``;
    returns the one before.  ``compiled`` without numba is extras.MissingExtra (the ``fast`` extra: one line, exit
    2 in the CLI); any other name a BackendError naming the choices."""
    global _backend, _kernels
    if backend not in BACKENDS:
        raise BackendError(f"{BACKEND_ENV}={backend!r}: the polygon backend is one of {', '.join(BACKENDS)}")
    before = _backend or "python"
    if backend == "compiled" and _kernels is None:
        require("numba", f"{BACKEND_ENV}=compiled")
        import netsetest.polygon_compiled as polygon_compiled  # (not `from netsetest import`: that names the package, whose api imports this)

        _kernels = polygon_compiled
    _backend = backend
    return before


def _segment_array(segments: list[np.ndarray]) -> np.ndarray:
    """The segments g as an (m, 2) float64 array (m may be 0)."""
    return np.array(segments, dtype=float).reshape(-1, 2)


@functools.cache
def _successors(m: int) -> np.ndarray:
    """The index of each vertex's successor in a polygon of m vertices (made once per size)."""
    out = np.r_[1:m, 0]
    out.flags.writeable = False
    return out


def _affine(v: Sequence[Point], A: np.ndarray, t: np.ndarray) -> list[Point]:
    """The vertices {A x + t}, counter-clockwise (reversed where det A < 0: its sign exact, :func:`_cross_sign`)."""
    (a00, a01), (a10, a11) = A.tolist()
    t0, t1 = float(t[0]), float(t[1])
    out = [(a00 * x + a01 * y + t0, a10 * x + a11 * y + t1) for x, y in v]
    return out if _cross_sign(0.0, 0.0, a00, a10, 0.0, 0.0, a01, a11) >= 0 else out[::-1]


def _half(x: float, y: float) -> int:
    """0 for a direction in the upper half-plane, angle in [0, π); 1 for the lower, [π, 2π)."""
    return 0 if y > 0.0 or (y == 0.0 and x > 0.0) else 1


CCW_ERRBOUND = (3.0 + 16.0 * 2.0**-53) * 2.0**-53  # Shewchuk's orient2d error bound A (unit roundoff 2⁻⁵³)
TINY = 1e-280  # below this the products may have lost precision to underflow: the sign is taken exactly
TWO_PI = 2.0 * math.pi
_CONSTANTS = np.array([CCW_ERRBOUND, TINY, TWO_PI, DUPLICATE, ROUNDING, MARGIN, MAX_REACH])  # the kernels' k (polygon_compiled.py)


def _cross_sign(p0x: float, p0y: float, p1x: float, p1y: float, q0x: float, q0y: float, q1x: float, q1y: float) -> int:
    """The exact sign of (p₁ − p₀) × (q₁ − q₀): in floating point where Shewchuk's error bound (for two products of
    rounded differences) decides it, else in rational arithmetic (every double is a rational)."""
    left = (p1x - p0x) * (q1y - q0y)
    right = (p1y - p0y) * (q1x - q0x)
    det = left - right
    size = abs(left) + abs(right)
    if abs(det) > CCW_ERRBOUND * size and size > TINY:  # (near underflow the bound does not hold)
        return 1 if det > 0.0 else -1
    F = Fraction
    exact = (F(p1x) - F(p0x)) * (F(q1y) - F(q0y)) - (F(p1y) - F(p0y)) * (F(q1x) - F(q0x))
    return (exact > 0) - (exact < 0)


def _pairs(d: Sequence[Point]) -> list[int]:
    """The order of each direction of d (nonzero) and the next by angle in [0, 2π), exactly: −1 if the first comes
    first, 0 if they are the same direction, 1 if the next comes first (half-plane, then the sign of the cross
    product: :func:`_cross_sign`'s float filter inline, which decides almost every pair, else its exact sign)."""
    out = []
    hs = [0 if y > 0.0 or (y == 0.0 and x > 0.0) else 1 for x, y in d]  # (_half)
    for ha, hb, (ax, ay), (bx, by) in zip(hs, hs[1:], d, d[1:]):
        if ha != hb:
            out.append(-1 if ha < hb else 1)
            continue
        left, right = ax * by, ay * bx
        det, size = left - right, abs(left) + abs(right)
        if abs(det) > CCW_ERRBOUND * size and size > TINY:
            out.append(-1 if det > 0.0 else 1)
        else:
            out.append(-_cross_sign(0.0, 0.0, ax, ay, 0.0, 0.0, bx, by))
    return out


def _compare(a: Point, b: Point) -> int:
    """:func:`_pairs` of the two directions a, b."""
    return _pairs((a, b))[0]


def _turn_one_way(edges: list[Point]) -> bool:
    """Whether the edges (from the lowest, then leftmost, vertex) turn counter-clockwise all the way: their
    directions in [0, 2π) never decrease (a repeated vertex, a zero edge, is skipped)."""
    return all(p <= 0 for p in _pairs([d for d in edges if d[0] != 0.0 or d[1] != 0.0]))


def _ordered(d: list[Point]) -> tuple[list[int], list[int]]:
    """The order of the directions d (nonzero) by angle in [0, 2π), exactly, and the :func:`_pairs` of it (which the
    walk of :meth:`Polygon.plus_segments` needs): one sort of floats by half-plane and rounded angle, which stands
    where every neighbouring pair is in order exactly (a total order within a half-plane, so the neighbours decide);
    else (a rounded angle a hair off: rare) sorted by :func:`_compare` alone.  Directions that are the same exactly
    may stand in any order: the walk leaves no vertex between them."""
    key = [(8.0 if y < 0.0 or (y == 0.0 and x <= 0.0) else 0.0) + math.atan2(y, x) % TWO_PI for x, y in d]  # (_half·8)
    order = sorted(range(len(d)), key=key.__getitem__)
    pairs = _pairs([d[i] for i in order])
    if 1 in pairs:  # (a pair out of order)

        def by_direction(i: int, j: int) -> int:
            return _compare(d[i], d[j])

        order = sorted(range(len(d)), key=functools.cmp_to_key(by_direction))
        pairs = _pairs([d[i] for i in order])
    return order, pairs


def _from_lowest(v: list[Point]) -> list[Point]:
    """The vertices rolled to start at the lowest (then leftmost, then first) one."""
    ys = [p[1] for p in v]
    low = min(ys)
    i = ys.index(low) if ys.count(low) == 1 else min((v[k][0], k) for k, y in enumerate(ys) if y == low)[1]
    return v[i:] + v[:i]


def _steps(v: list[Point], extra: list[Point]) -> tuple[list[Point], int]:
    """The edges v[i+1] − v[i] (cyclically) and then ``extra``, without zero ones (a repeated vertex, a zero
    segment: no direction), and how many of them are edges."""
    edges = [(bx - ax, by - ay) for (ax, ay), (bx, by) in zip(v, [*v[1:], v[0]])]
    edges = [e for e in edges if e[0] != 0.0 or e[1] != 0.0]
    return edges + extra, len(edges)


def _segment_steps(segments: list[Point]) -> tuple[Point, list[Point]]:
    """The sum of the segments' lowest (then leftmost) ends, where the walk of :func:`_plus` starts from the lowest
    vertex, and each segment's two steps ±2s (without zero ones)."""
    ends = [(-x, -y) if _half(x, y) == 0 else (x, y) for x, y in segments]  # each segment's lowest (then leftmost) end
    lx, ly = ends[0] if ends else (0.0, 0.0)
    for x, y in ends[1:]:
        lx, ly = lx + x, ly + y
    extra = [s for s in [*((2.0 * x, 2.0 * y) for x, y in segments), *((-2.0 * x, -2.0 * y) for x, y in segments)] if s[0] != 0.0 or s[1] != 0.0]
    return (lx, ly), extra


def _walk(start: Point, steps: list[Point], order: list[int]) -> list[Point]:
    """The points start + the partial sums of the steps in ``order`` (the last step's sum, back at start, left out)."""
    bx, by = start
    walk = [(bx, by)]
    cx, cy = steps[order[0]]
    for k in order[1:]:  # each partial sum in turn
        walk.append((bx + cx, by + cy))
        sx, sy = steps[k]
        cx, cy = cx + sx, cy + sy
    return walk


def _plus(vertices: list[Point], segments: list[Point]) -> list[Point]:
    """The vertices of :meth:`Polygon.plus_segments` (its docstring says how)."""
    v = _from_lowest(vertices)
    (lx, ly), extra = _segment_steps(segments)
    steps, n = _steps(v, extra)
    order, pairs = _ordered(steps) if steps else ([], [])
    edge_order = [i for i in order if i < n]
    if edge_order != sorted(edge_order) and not _turn_one_way(steps[:n]):  # (edges in the
        # exact order in their own order turn one way; out of it, a tie may still have swapped two: checked)
        v = _hull(v)  # from its lowest (then leftmost) vertex: a rounding made a vertex reflex
        steps, n = _steps(v, extra)
        order, pairs = _ordered(steps) if steps else ([], [])
    if not steps:
        return v
    walk = _walk((v[0][0] + lx, v[0][1] + ly), steps, order)
    if len(order) > 1 and 0 not in pairs:  # every step turns from the one before (the last from the first too:
        return _distinct(walk)  # the order rises strictly)
    turns = [_compare(steps[order[-1]], steps[order[0]]), *pairs]  # each step against the one before
    kept = [p for p, turn in zip(walk, turns) if turn != 0]  # (else the vertex is on a side)
    return _distinct(kept or walk[:1])


def _hull(v: Sequence[Point]) -> list[Point]:
    """The convex hull of the points v, exactly (Andrew's monotone chain, exact orientation): its vertices
    counter-clockwise without collinear ones, from the lowest (then leftmost); one or two if it is flat."""
    pts = sorted(set(v))
    if len(pts) <= 2:
        return sorted(pts, key=lambda p: (p[1], p[0]))

    def chain(points: list[Point]) -> list[Point]:
        out: list[Point] = []
        for p in points:
            while len(out) >= 2 and _cross_sign(*out[-2], *out[-1], *out[-2], *p) <= 0:
                out.pop()
            out.append(p)
        return out

    ring = chain(pts)[:-1] + chain(pts[::-1])[:-1]  # every point on one line: its two ends
    first = min(range(len(ring)), key=lambda i: (ring[i][1], ring[i][0]))
    return ring[first:] + ring[:first]


def _in_hull(hull: list[Point], px: float, py: float) -> bool:
    """(px, py) in the hull :func:`_hull` returned (counter-clockwise, no collinear vertices; a point or a segment
    if flat), exactly."""
    if len(hull) == 1:
        return hull[0] == (px, py)
    if len(hull) == 2:  # on the segment: on its line, within its box
        (ax, ay), (bx, by) = hull
        on_line = _cross_sign(ax, ay, bx, by, ax, ay, px, py) == 0
        return on_line and min(ax, bx) <= px <= max(ax, bx) and min(ay, by) <= py <= max(ay, by)
    return all(_cross_sign(ax, ay, bx, by, ax, ay, px, py) >= 0 for (ax, ay), (bx, by) in zip(hull, [*hull[1:], hull[0]]))


def _clip(v: list[Point], s: list[float] | None, c0: float, c1: float, b: float) -> list[Point] | None:
    """The polygon ∩ {c0 x + c1 y ≤ b} (Sutherland–Hodgman against one half-plane; ``s``: each vertex's c0 x + c1 y,
    if known); None if nothing remains."""
    d = [c0 * x + c1 * y - b for x, y in v] if s is None else [e - b for e in s]
    if max(d) <= 0.0:
        return v
    out: list[Point] = []
    (px, py), sp = v[-1], d[-1]
    for (x, y), sq in zip(v, d):
        if (sp < 0.0 < sq) or (sq < 0.0 < sp):  # the side from the previous vertex crosses the line
            t = sp / (sp - sq)
            out.append((px + t * (x - px), py + t * (y - py)))
        if sq <= 0.0:
            out.append((x, y))
        px, py, sp = x, y, sq
    return _distinct(out) if out else None


def _clipped(v: list[Point], planes: list[list[float]], ends: list[float], reach: list[float], size: float) -> list[Point] | None:
    """The polygon ∩ every half-plane cᵀx ≤ end (Sutherland–Hodgman, one plane after the other, on plain floats: a
    few sides cut a polygon of 24–32 vertices, where numpy's per-call cost is most of a cut), each widened outward by
    :meth:`Polygon.cut`'s margin for a plane: MARGIN relative to max Σᵢ |cᵢ xᵢ| (``reach``, over the polygon before
    the first plane: every later part lies in it, so no smaller), at least what merging vertices closer than DUPLICATE
    can leave out (``size``: max |xᵢ| of the polygon), as :func:`_distinct` does after each plane; None if nothing
    remains."""
    for (c0, c1), end, r in zip(planes, ends, reach):
        lim = end + max(MARGIN * (1.0 + r), (2 * len(v) + 2) * DUPLICATE * (1.0 + size) * (abs(c0) + abs(c1)))
        out: list[Point] = []
        px, py = v[-1]
        sp = c0 * px + c1 * py - lim
        for x, y in v:
            sq = c0 * x + c1 * y - lim
            if (sp < 0.0 < sq) or (sq < 0.0 < sp):  # the side from the previous vertex crosses the line
                t = sp / (sp - sq)
                out.append((px + t * (x - px), py + t * (y - py)))
            if sq <= 0.0:
                out.append((x, y))
            px, py, sp = x, y, sq
        if not out:
            return None
        v = _distinct(out)
    return v


def _distinct(v: list[Point]) -> list[Point]:
    """Without the vertices within DUPLICATE (relative to the extent) of the one before: an edge that short has a
    direction of rounding noise, which the containment test would read as a side (the margin covers the move)."""
    tol = DUPLICATE * (1.0 + max(map(abs, itertools.chain.from_iterable(v))))
    px, py = v[-1]
    out = []
    for x, y in v:
        if abs(x - px) > tol or abs(y - py) > tol:
            out.append((x, y))
        px, py = x, y
    return out or v[:1]


def _cheapest_edges(v: list[Point], wanted: int) -> dict[int, tuple[float, float]]:
    """Up to ``wanted`` edges i → q: dropping edge (v_i, v_i+1) by meeting its neighbours' lines at q adds the
    least area, q beyond both ends of the edge along them (the drop then holds the edge's triangle); the edges
    chosen are at least three apart (cyclically)."""
    n = len(v)
    area, q = [math.inf] * n, [(0.0, 0.0)] * n
    ahead = [*v[1:], v[0]]
    edges = [(bx - ax, by - ay) for (ax, ay), (bx, by) in zip(v, ahead)]  # edge i: v_i → v_i+1
    before = [v[-1], *v[:-1]]  # v_i−1
    for i, ((a0x, a0y), (a1x, a1y), (b0x, b0y), (dax, day), (dbx, dby)) in enumerate(
        zip(before, v, ahead, [edges[-1], *edges[:-1]], [*edges[1:], edges[0]])
    ):  # the edge before edge i, a0 → a1, and the one after it, b0 → b1 (each difference as it was, once)
        den = dax * dby - day * dbx
        if not den > 1e-300:
            continue  # parallel, or meeting behind: dropping that edge is unbounded
        t = ((b0x - a0x) * dby - (b0y - a0y) * dbx) / den
        if not 1.0 <= t <= MAX_REACH:
            continue  # (farther, q's rounding could cut the polygon: near-parallel neighbours)
        qx, qy = a0x + t * dax, a0y + t * day
        if not (qx - b0x) * dbx + (qy - b0y) * dby <= 0.0:
            continue  # q must be before b0 on the edge after (else the drop cuts b0 off: where near-duplicate
            # vertices leave a side whose direction is rounding noise)
        a = 0.5 * abs((qx - a1x) * (b0y - a1y) - (qy - a1y) * (b0x - a1x))
        if a < math.inf:  # (finite: a ≥ 0 or NaN)
            area[i], q[i] = a, (qx, qy)
    chosen: dict[int, tuple[float, float]] = {}
    near: set[int] = set()  # the edges fewer than three from a chosen one (cyclically)
    for a, i in sorted(zip(area, range(n))):  # (ties in edge order)
        if len(chosen) == wanted or a == math.inf:
            break
        if i not in near:
            chosen[i] = q[i]
            near.update(((i - 2) % n, (i - 1) % n, i, (i + 1) % n, (i + 2) % n))
    return chosen


def _drop_edges(v: list[Point], drops: dict[int, tuple[float, float]]) -> list[Point]:
    """The vertices with each dropped edge's two ends replaced by its q."""
    n = len(v)
    out = list(v)
    keep = [True] * n
    for i, q in drops.items():  # (dropped edges are at least three apart: no end is another's start)
        out[i] = q
        keep[(i + 1) % n] = False
    return [p for p, k in zip(out, keep) if k]


def region_problem(coords: Sequence[float]) -> tuple[str, str] | None:
    """Why the flattened vertices [β₁, r₁, β₂, r₂, …] are no region a node may publish, as (reason, detail); None if
    they are one: MIN_VERTICES to MAX_VERTICES finite vertices within ±MAX_COORDINATE, counter-clockwise and convex
    to the rounding: the sides wind once around, counter-clockwise, and turn the wrong way nowhere by more than
    CONVEX_TOLERANCE of the coordinates' size (:func:`_turns`).  A region flat to that tolerance (a segment, a point,
    a sliver a cut left) is one whatever its order: its hull is within the tolerance of it.  What is dropped is
    named exactly (only a dropped region pays for it): self-intersecting where two sides meet (exact
    orientations), else clockwise or not convex.  Every role runs it on every region it decodes: one pass, plain
    floats (a few µs at 24 vertices)."""
    if len(coords) % 2:
        return REGION_ODD, f"{len(coords)} coordinates"
    if not MIN_VERTICES <= len(coords) // 2 <= MAX_VERTICES:
        return REGION_VERTICES, f"{len(coords) // 2} vertices, not {MIN_VERTICES} to {MAX_VERTICES}"
    if not math.isfinite(sum(coords)) and not all(map(math.isfinite, coords)):  # (a NaN or an inf makes the sum one)
        return REGION_NOT_FINITE, "a coordinate is not finite"
    size = max(max(coords), -min(coords))
    if size > MAX_COORDINATE:
        return REGION_SCALE, f"a coordinate of size {size:.3g}, beyond ±{MAX_COORDINATE:g}"
    tol = CONVEX_TOLERANCE * (1.0 + size)
    winds, reflex = _turns(coords, tol)
    if winds == 1 and not reflex:
        return None
    v = list(zip(map(float, coords[0::2]), map(float, coords[1::2])))
    if _flat(v, tol):
        return None
    if _sides_meet(v):
        return REGION_SELF_INTERSECTING, f"two sides cross (they wind {winds} times around)"
    if winds == -1:
        return REGION_CLOCKWISE, "the vertices go round clockwise"
    return REGION_NOT_CONVEX, "a vertex turns clockwise"


def _turns(coords: Sequence[float], tol: float) -> tuple[int, bool]:
    """How many times the sides of the closed path [x₁, y₁, x₂, y₂, …] wind around (counter-clockwise positive), and
    whether one turns clockwise from the one before by more than ``tol`` times their lengths (|x| + |y|: a cross
    product's rounding is the coordinates' size times the sides' lengths, in units of the coordinates' ε).  Each
    turn is taken as the smaller angle (where a side doubles back exactly, by +π); the winding counts the turns
    across the direction angle 0: from the lower half-plane to the upper counter-clockwise, +1, the other way
    clockwise, −1 (a repeated vertex has no side)."""
    xs, ys = coords[0::2], coords[1::2]
    k = len(xs) - 1
    while k > 0 and xs[k] == xs[k - 1] and ys[k] == ys[k - 1]:
        k -= 1  # the last side that is one (a repeated vertex has none)
    ax, ay = xs[k] - xs[k - 1], ys[k] - ys[k - 1]  # (k = 0: the side into the first vertex from the last)
    if k == 0 and ax == 0.0 and ay == 0.0:
        return 1, False  # a point
    lower = ay < 0.0 or (ay == 0.0 and ax < 0.0)  # direction angle in [π, 2π)
    winds, reflex = 0, False
    px, py = xs[-1], ys[-1]
    for x, y in zip(xs, ys):
        bx, by = x - px, y - py
        px, py = x, y
        if bx == 0.0 and by == 0.0:
            continue
        cross = ax * by - ay * bx
        if cross <= 0.0 and cross < -tol * (abs(ax) + abs(ay) + abs(bx) + abs(by)):  # (a turn the right way costs no more)
            reflex = True
        b_lower = by < 0.0 or (by == 0.0 and bx < 0.0)
        if lower is not b_lower:
            winds += lower if cross >= 0.0 else -b_lower  # across 0 (the other crossings are across π)
        ax, ay, lower = bx, by, b_lower
    return winds, reflex


def _flat(v: list[Point], tol: float) -> bool:
    """Whether every vertex is within ``tol`` of the line through the first lowest-leftmost one and the vertex
    farthest from it (then the hull of v is a segment to ``tol``; a point if every vertex is that one)."""
    ax, ay = min(v)
    bx, by = max(v, key=lambda p: abs(p[0] - ax) + abs(p[1] - ay))
    length = math.hypot(bx - ax, by - ay)
    return length == 0.0 or all(abs((bx - ax) * (y - ay) - (by - ay) * (x - ax)) <= tol * length for x, y in v)


def _sides_meet(v: list[Point]) -> bool:
    """Whether two sides of the closed path v meet other than where they follow each other (exact orientations)."""
    sides = [(a, b) for a, b in zip(v, [*v[1:], v[0]]) if a != b]
    n = len(sides)
    for i, j in itertools.combinations(range(n), 2):
        (a, b), (c, d) = sides[i], sides[j]
        if j == i + 1 or (i == 0 and j == n - 1):  # consecutive: they share a vertex; they meet beyond it only if
            if _cross_sign(*a, *b, *c, *d) == 0 and _dot_sign(a, b, c, d) < 0:
                return True  # the path doubles back along the same line
            continue
        o1, o2 = _cross_sign(*a, *b, *a, *c), _cross_sign(*a, *b, *a, *d)
        o3, o4 = _cross_sign(*c, *d, *c, *a), _cross_sign(*c, *d, *c, *b)
        if o1 * o2 > 0 or o3 * o4 > 0:
            continue
        if o1 or o2 or o3 or o4:
            return True
        if all(min(a[k], b[k]) <= max(c[k], d[k]) and min(c[k], d[k]) <= max(a[k], b[k]) for k in (0, 1)):
            return True  # on one line, and overlapping
    return False


def _dot_sign(a: Point, b: Point, c: Point, d: Point) -> int:
    """The exact sign of (b − a) · (d − c)."""
    F = Fraction
    exact = (F(b[0]) - F(a[0])) * (F(d[0]) - F(c[0])) + (F(b[1]) - F(a[1])) * (F(d[1]) - F(c[1]))
    return (exact > 0) - (exact < 0)


__all__ = ["MARGIN", "MAX_VERTICES", "MIN_VERTICES", "REGION_REASONS", "Advanced", "Cut", "Polygon", "advance", "cut_all", "region_problem"]
