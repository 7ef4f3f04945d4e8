"""The polygon operations as numpy computed them before issue 28's speed-up (netsetest/polygon.py and
estimator/cuts.py's ``ellipse_cut`` at bb92f3e, unchanged but for what the tests do not call), the reference
tests/unit/test_polygon_same.py and tests/inmemory/test_polygon_runs_same.py hold the plain-float code to; and how
close it must stay (:func:`differs`): the same set to the roundings of the operation, not bit for bit, since
numpy's products here go through OpenBLAS, whose kernel (picked by CPU: ``OPENBLAS_CORETYPE``) may round them
otherwise than plain floats do (with a fused multiply-add or without).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
from exact_polygons import EPS, cut_rounding, exact, gap, merged, move_rounding, reduction_rounding, sum_rounding

from netsetest import polygon as fast

from netsetest.polygon import CCW_ERRBOUND, DUPLICATE, MARGIN, MAX_REACH, MAX_VERTICES, ROUNDING, TINY


@dataclass(frozen=True)
class Polygon:
    """A convex polygon, vertices (n, 2) counter-clockwise."""

    vertices: np.ndarray

    def affine(self, A: np.ndarray, t: np.ndarray) -> Polygon:
        """{A x + t}: A (2, 2); the vertices' order reversed where det A < 0 (its sign exact: a rounded determinant
        of a near-singular A could flip the orientation)."""
        v = self.vertices @ A.T + t
        det = _cross_sign(0.0, 0.0, float(A[0, 0]), float(A[1, 0]), 0.0, 0.0, float(A[0, 1]), float(A[1, 1]))
        return Polygon(v if det >= 0 else v[::-1].copy())

    def plus_segments(self, segments: list[np.ndarray]) -> Polygon:
        """The sum with the segments {s g : |s| ≤ 1} of ``segments`` (each g (2,)): the polygon's edges and every ±2g
        merged by direction in one pass (two more vertices per segment), walked from the lowest (then leftmost)
        vertex plus every segment's lowest (then leftmost) end, where that order starts.  The directions are
        compared exactly (half-plane, then the sign of the cross product), never by a rounded angle: an edge a few
        ulps below horizontal comes last, not first.  Where a rounding has made a vertex reflex (the edges do not
        turn one way from there), the walk is over the exact hull of the vertices, which holds them all; parallel
        directions in a row leave no vertex between them.  Sound to the walk's rounding and the merge of vertices
        closer than DUPLICATE (:func:`_distinct`), which the margin of :meth:`moved` covers."""
        v = _from_lowest(self.vertices)
        edges = _after(v) - v
        if not _turn_one_way(edges):
            v = _hull(v)  # from its lowest (then leftmost) vertex
            edges = _after(v) - v
        g = np.array(segments, dtype=float).reshape(-1, 2)
        up = (g[:, 1] > 0.0) | ((g[:, 1] == 0.0) & (g[:, 0] > 0.0))
        low = np.where(up[:, None], -g, g).sum(axis=0)  # each segment's lowest (then leftmost) end
        steps = np.vstack([edges, 2.0 * g, -2.0 * g])
        steps = steps[np.any(steps != 0.0, axis=1)]  # a repeated vertex, a zero segment: no direction
        if len(steps) == 0:
            return Polygon(v.copy())
        order, pairs = _ordered(steps)
        steps = steps[order]
        walk = v[0] + low + np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0)[:-1]])
        if pairs is None:  # (the exact sort compared no neighbours; the numpy sort's check did: reused)
            pairs = _pair_order(steps[:-1], steps[1:])
        turns = np.concatenate([_pair_order(steps[-1:], steps[:1]), pairs]) != 0  # each step against the one before (else the vertex is on a side)
        return Polygon(_distinct(walk[turns] if turns.any() else walk[:1]))

    def moved(self, A: np.ndarray, t: np.ndarray, segments: list[np.ndarray]) -> Polygon:
        """{A x + t} summed with the segments and a square of half-side ROUNDING of the coordinates' size, in one
        merge: every side moves out by at least that, which covers the step's rounding (this move's, the cuts'
        that follow, each widened by its own margin, and the vertices merged as duplicates); at least what that
        merge can leave out where the segments reach far beyond the image (a flat or tiny image)."""
        v = self.affine(A, t)
        size = float(np.abs(v.vertices).max())
        reach = size + sum(float(np.abs(g).max()) for g in segments)
        merged = (2 * (len(v.vertices) + 2 * len(segments)) + 8) * DUPLICATE * (1.0 + reach)
        pad = max(ROUNDING * (1.0 + size), merged)  # (ROUNDING's at every physical state range: bit for bit)
        return v.plus_segments([*segments, np.array([pad, 0.0]), np.array([0.0, pad])])

    def cut(self, c: np.ndarray, lo: float, hi: float) -> Polygon | None:
        """The part with lo ≤ cᵀx ≤ hi, widened outward by the margin (relative to max Σᵢ |cᵢ xᵢ|, which bounds the
        rounding of cᵀx where its terms cancel), and at least by what merging its vertices closer than DUPLICATE
        can leave out along c (a slab thin next to the coordinates' size); None if empty (flat if this polygon
        is: a segment's part is one)."""
        s = self.vertices @ c
        if lo <= s.min() and s.max() <= hi:  # inside the slab itself, so inside it widened by any pad ≥ 0: what both
            return self  # clips below would keep (most cuts of a step)
        a = np.abs(self.vertices)
        merged = (2 * len(a) + 2) * DUPLICATE * (1.0 + float(a.max())) * float(np.abs(c).sum())
        pad = max(MARGIN * (1.0 + float((a @ np.abs(c)).max())), merged)
        if s.max() <= hi + pad and -s.min() <= -lo + pad:  # no vertex outside the widened slab: likewise
            return self  # (v @ −c is −(v @ c) exactly: every rounding is symmetric in sign)
        v = _clip(self.vertices, c, hi + pad)
        if v is not None:
            v = _clip(v, -c, -lo + pad)
        return None if v is None else Polygon(v)

    def reduced(self, max_vertices: int = MAX_VERTICES) -> Polygon:
        """At most ``max_vertices`` vertices, containing this polygon: an edge is dropped by extending its two
        neighbours until they meet, the ones that add the least area first (edges at least three apart at once:
        their neighbours' lines are then untouched)."""
        v = self.vertices
        while len(v) > max_vertices:
            drops = _cheapest_edges(v, len(v) - max_vertices)
            if not drops:
                break  # no edge can be dropped without an unbounded extension (for n > 4 only where a rounding
                # puts two neighbours' meeting a hair behind an edge: near-duplicate vertices)
            v = _drop_edges(v, drops)
        return Polygon(v)


def _after(a: np.ndarray, k: int = 1) -> np.ndarray:
    """The rows of a rolled to start k after the first (np.roll(a, −k, axis=0) for −n ≤ k ≤ n, without its generic
    set-up: several calls per polygon operation, every step)."""
    return np.concatenate((a[k:], a[:k]))


def _half(x: float, y: float) -> int:
    """0 for a direction in the upper half-plane, angle in [0, π); 1 for the lower, [π, 2π)."""
    return 0 if y > 0.0 or (y == 0.0 and x > 0.0) else 1


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


def _compare(a: np.ndarray, b: np.ndarray) -> int:
    """The order of the directions a and b (each (2,), nonzero) by angle in [0, 2π), exactly: −1 if a comes first,
    0 if they are the same direction, 1 if b comes first."""
    ha, hb = _half(float(a[0]), float(a[1])), _half(float(b[0]), float(b[1]))
    if ha != hb:
        return -1 if ha < hb else 1
    return -_cross_sign(0.0, 0.0, float(a[0]), float(a[1]), 0.0, 0.0, float(b[0]), float(b[1]))


def _turn_one_way(edges: np.ndarray) -> bool:
    """Whether the edges (from the lowest, then leftmost, vertex) turn counter-clockwise all the way: their
    directions in [0, 2π) never decrease (a repeated vertex, a zero edge, is skipped)."""
    e = edges[np.any(edges != 0.0, axis=1)]
    return bool(np.all(_pair_order(e[:-1], e[1:]) <= 0))


def _halves(d: np.ndarray) -> np.ndarray:
    """:func:`_half` of every row of d (m, 2)."""
    return np.where((d[:, 1] > 0.0) | ((d[:, 1] == 0.0) & (d[:, 0] > 0.0)), 0, 1)


def _pair_order(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`_compare` of the rows a[k], b[k] (each (m, 2), nonzero), exactly, as an int array (m,): the float
    filter of :func:`_cross_sign` decides almost every pair at once; the rest are taken in rational arithmetic."""
    ha, hb = _halves(a), _halves(b)
    left, right = a[:, 0] * b[:, 1], a[:, 1] * b[:, 0]
    det, size = left - right, np.abs(left) + np.abs(right)
    cross = np.sign(det).astype(int)
    for k in np.flatnonzero((ha == hb) & ~((np.abs(det) > CCW_ERRBOUND * size) & (size > TINY))):
        cross[k] = _cross_sign(0.0, 0.0, float(a[k, 0]), float(a[k, 1]), 0.0, 0.0, float(b[k, 0]), float(b[k, 1]))
    return np.where(ha == hb, -cross, np.where(ha < hb, -1, 1))


def _ordered(d: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`_by_direction`'s order and, where the numpy sort stood, the :func:`_pair_order` of each sorted
    neighbour with the next (m − 1,), which the walk of :meth:`Polygon.plus_segments` needs again; else None."""
    order = np.lexsort((np.mod(np.arctan2(d[:, 1], d[:, 0]), 2.0 * np.pi), _halves(d)))
    s = d[order]
    pairs = _pair_order(s[:-1], s[1:])
    if (pairs <= 0).all():
        return order, pairs  # (ties of the same direction may stand in another order: the walk leaves no vertex between them)

    def by_direction(i: int, j: int) -> int:
        return _compare(d[i], d[j])

    return np.array(sorted(range(len(d)), key=functools.cmp_to_key(by_direction)), dtype=int), None  # stable


def _from_lowest(v: np.ndarray) -> np.ndarray:
    """The vertices rolled to start at the lowest (then leftmost) one."""
    return _after(v, int(np.lexsort((v[:, 0], v[:, 1]))[0]))


def _hull(v: np.ndarray) -> np.ndarray:
    """The convex hull of the points v (n, 2), exactly (Andrew's monotone chain, exact orientation): its vertices
    counter-clockwise without collinear ones, from the lowest (then leftmost); one or two rows if it is flat."""
    pts = sorted({(float(x), float(y)) for x, y in v})
    if len(pts) <= 2:
        out = sorted(pts, key=lambda p: (p[1], p[0]))
        return np.array(out, dtype=float).reshape(-1, 2)

    def chain(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for p in points:
            while len(out) >= 2 and _cross_sign(*out[-2], *out[-1], *out[-2], *p) <= 0:
                out.pop()
            out.append(p)
        return out

    ring = chain(pts)[:-1] + chain(pts[::-1])[:-1]  # every point on one line: its two ends
    first = min(range(len(ring)), key=lambda i: (ring[i][1], ring[i][0]))
    return np.array(ring[first:] + ring[:first], dtype=float)


def _clip(v: np.ndarray, c: np.ndarray, b: float) -> np.ndarray | None:
    """The polygon ∩ {cᵀx ≤ b} (Sutherland–Hodgman against one half-plane); None if nothing remains."""
    s = v @ c - b
    if (s <= 0.0).all():
        return v
    nxt = _after(v)
    s_nxt = _after(s)
    crosses = ((s < 0.0) & (s_nxt > 0.0)) | ((s > 0.0) & (s_nxt < 0.0))
    t = np.where(crosses, s / np.where(crosses, s - s_nxt, 1.0), 0.0)
    points = np.stack([v, v + t[:, None] * (nxt - v)], axis=1).reshape(-1, 2)  # per edge: its start, its crossing
    out = points[np.stack([s <= 0.0, crosses], axis=1).reshape(-1)]
    return _distinct(out) if len(out) else None


def _distinct(v: np.ndarray) -> np.ndarray:
    """Without the vertices within DUPLICATE (relative to the extent) of the one before: an edge that short has a
    direction of rounding noise, which the containment test would read as a side (the margin covers the move)."""
    tol = DUPLICATE * (1.0 + float(np.abs(v).max()))
    keep = np.abs(v - _after(v, -1)).max(axis=1) > tol
    return v[keep] if keep.any() else v[:1]


def _cheapest_edges(v: np.ndarray, wanted: int) -> dict[int, np.ndarray]:
    """Up to ``wanted`` edges i → q: dropping edge (v_i, v_i+1) by meeting its neighbours' lines at q adds the
    least area, q beyond both ends of the edge along them (the drop then holds the edge's triangle); the edges
    chosen are at least three apart (cyclically)."""
    n = len(v)
    a0, a1 = _after(v, -1), v  # the edge before edge i
    b0, b1 = _after(v), _after(v, 2)  # the edge after it
    da, db = a1 - a0, b1 - b0
    den = da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0]
    ok = den > 1e-300  # else parallel, or meeting behind: dropping that edge is unbounded
    t = np.where(ok, ((b0[:, 0] - a0[:, 0]) * db[:, 1] - (b0[:, 1] - a0[:, 1]) * db[:, 0]) / np.where(ok, den, 1.0), -1.0)
    ok &= (t >= 1.0) & (t <= MAX_REACH)  # (farther, q's rounding could cut the polygon: near-parallel neighbours)
    q = a0 + t[:, None] * da
    ok &= np.einsum("ij,ij->i", q - b0, db) <= 0.0  # and before b0 on the edge after (else the drop cuts b0 off: where
    # near-duplicate vertices leave a side whose direction is rounding noise)
    area = 0.5 * np.abs((q[:, 0] - a1[:, 0]) * (b0[:, 1] - a1[:, 1]) - (q[:, 1] - a1[:, 1]) * (b0[:, 0] - a1[:, 0]))
    area = np.where(ok & np.isfinite(area), area, np.inf)
    chosen: dict[int, np.ndarray] = {}
    for i in np.argsort(area, kind="stable"):
        if len(chosen) == wanted or not np.isfinite(area[i]):
            break
        if all(min((i - j) % n, (j - i) % n) >= 3 for j in chosen):
            chosen[int(i)] = q[i]
    return chosen


def _drop_edges(v: np.ndarray, drops: dict[int, np.ndarray]) -> np.ndarray:
    """The vertices with each dropped edge's two ends replaced by its q."""
    n = len(v)
    out = v.copy()
    keep = np.ones(n, dtype=bool)
    for i, q in drops.items():  # (dropped edges are at least three apart: no end is another's start)
        out[i] = q
        keep[(i + 1) % n] = False
    return out[keep]


def ellipse_cut(region: Polygon, xhat: np.ndarray, P: np.ndarray, rho: float, coordinates: bool = True) -> Polygon | None:
    """estimator/cuts.py's ``ellipse_cut`` as it was."""
    pxx = 0.5 * (P[:2, :2] + P[:2, :2].T)
    _, vecs = np.linalg.eigh(pxx)
    dirs = [*np.eye(2), *vecs.T] if coordinates else [*vecs.T]
    out: Polygon | None = region
    for d in dirs:
        if out is None:
            return None
        centre, half = float(d @ xhat[:2]), float(np.sqrt(max(rho * float(d @ pxx @ d), 0.0)))
        out = out.cut(d, centre - half, centre + half)
    return out


# --- how close the plain-float code must stay to it -----------------------------------------------------------


def differs(got: fast.Polygon | None, want: Polygon | None, bound: Fraction) -> str | None:
    """Why ``got`` (netsetest/polygon.py's answer) is not ``want`` (this module's) to ``bound``, None if it is: each
    holds the other shrunk by ``bound`` (gap ≤ bound both ways).  ``got`` holding ``want`` shrunk is the direction
    soundness needs (the fast code drops no point the numpy code kept, beyond the rounding); the other, that it
    keeps no more.  Both or neither empty.  (Equal vertices: at once.)"""
    if got is None or want is None:
        return None if got is None and want is None else f"empty on one side only: got {got}, want {want}"
    a, b = got.vertices, want.vertices
    if a.shape == b.shape and a.tobytes() == b.tobytes():
        return None
    lost, added = gap(exact(b), exact(a)), gap(exact(a), exact(b))
    if lost > bound:
        return f"the numpy code's set reaches {float(lost):.3g} beyond the fast code's (bound {float(bound):.3g})"
    if added > bound:
        return f"the fast code's set reaches {float(added):.3g} beyond the numpy code's (bound {float(bound):.3g})"
    return None


def bound(name: str, v: np.ndarray, *args: Any, **kwargs: Any) -> Fraction:
    """:func:`differs`'s bound for the operation ``name`` (a method of Polygon, or ``ellipse_cut``) with ``args`` on the
    polygon ``v`` (``kwargs``: ellipse_cut's ``coordinates``).  Each code holds the exact result to within its operation's rounding, from both sides
    (tests/exact_polygons.py: tests/unit/test_polygon_exact.py holds netsetest/polygon.py to it, the reference does
    the same arithmetic) and may merge near-duplicate vertices the other keeps; so the two are within twice that of
    each other.  Their differences on this machine's OpenBLAS kernels are a few ulps; a change of the operation, say
    a margin left out (10⁻⁹ of the coordinates' size for a cut, 10⁻¹⁰ for a move), is far beyond."""
    n = len(v)
    if name == "plus_segments":
        segments = args[0]
        return 2 * sum_rounding(v, segments) + 2 * merged(v, n + 2 * len(segments))
    if name == "moved":
        A, t, segments = args
        image = v @ A.T + t
        return 2 * move_rounding(image, segments) + 2 * merged(image, n + 2 * len(segments) + 4)
    if name == "cut":
        return 2 * cut_rounding(v) + 2 * merged(v, 2 * n)
    if name == "reduced":
        return 2 * reduction_rounding(v)
    if name == "ellipse_cut":
        return ellipse_cut_bound(v, *args, **kwargs)
    raise ValueError(name)


def ellipse_cut_bound(v: np.ndarray, xhat: np.ndarray, P: np.ndarray, rho: float, coordinates: bool = True) -> Fraction:
    """How far the two codes' :func:`ellipse_cut` of the polygon ``v`` may differ (the gap, both ways).

    They cut by the same slabs (the same directions: numpy.linalg.eigh's, which netsetest.linalg.eigh is), but round
    each slab's ends dᵀx̂ ± √(ρ dᵀP_xx d) otherwise: numpy's 2-vector products (OpenBLAS's kernel) against plain
    floats, each product and sum rounded.  A 2-term dot product is within 2ε of its exact value relative to the sum
    of its terms' magnitudes, whichever way it is rounded, so the two centres differ by at most 4ε Σ|dᵢx̂ᵢ| and the two
    dᵀP_xx d (two such products in turn) by 8ε |d|ᵀ|P_xx||d|; then ρ· and √ (each rounded: 2ε more relative) and the
    end's sum (2ε of its terms).  A √ of values a, b: |√a − √b| ≤ min(√|a − b|, |a − b| / √max(a, b)), which for a
    thin ellipse (P_xx's condition up to 10¹⁰) makes the end of its short axis differ by far more ulps than the
    inputs did.  A slab's end moved by δ moves the cut set by at most δ (in the gap's ∞-norm, d a unit vector); on
    top of that each cut of either code rounds its crossings and may merge vertices (:func:`cut_rounding`,
    :func:`merged`), at most two vertices more per cut."""
    pxx = 0.5 * (P[:2, :2] + P[:2, :2].T)
    _, vecs = np.linalg.eigh(pxx)
    dirs = [*np.eye(2), *vecs.T] if coordinates else [*vecs.T]
    total = Fraction(0)
    n = len(v)
    for d in dirs:
        n += 2
        centre_terms = float(np.abs(d) @ np.abs(xhat[:2]))
        q_terms = float(np.abs(d) @ np.abs(pxx) @ np.abs(d))
        q = rho * float(d @ pxx @ d)
        dq = rho * 9.0 * EPS * q_terms + 2.0 * EPS * abs(q)  # (9 for 8: the products' own second order)
        dhalf = min(math.sqrt(dq), dq / math.sqrt(q)) if q > 0.0 else math.sqrt(dq)
        half = math.sqrt(max(q, 0.0))
        ends = 5.0 * EPS * centre_terms + dhalf + 2.0 * EPS * half + 2.0 * EPS * (abs(float(d @ xhat[:2])) + half)
        total += Fraction(ends) + 2 * cut_rounding(v, n) + 2 * merged(v, 2 * n)
    return total
