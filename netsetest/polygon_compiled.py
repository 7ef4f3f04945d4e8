"""The hot polygon operations of netsetest/polygon.py compiled with numba: the move (the one-step map and the sum
with the segments), the two-sided cut and the reduction, on the vertices as an (n, 2) float64 array.

Each kernel is the plain-Python operation of netsetest/polygon.py step for step: the same floating-point
operations in the same order (numba does not contract a product and a sum into a fused multiply-add without
``fastmath``), the same outward margins, the same orders and tie rules.  What it cannot decide in floating point it
does not guess: an orientation Shewchuk's filter leaves open (its exact sign needs rational arithmetic), a
direction order the rounded angles got wrong, a vertex a rounding made reflex (the exact hull) make the move
return ``None``, and polygon.py then runs its plain-Python operation, exact predicates and all.  The reduction
and the cut use no predicate.  tests/unit/test_polygon*.py check both paths with the same properties.

Compiled on first use and cached on disk (``cache=True``): numba writes the machine code beside this module, in
netsetest/__pycache__ (where that is not writable, in NUMBA_CACHE_DIR or the user's cache directory,
~/.cache/numba), never in the system's temporary directory.  numba is the optional ``fast`` extra
(pyproject.toml); polygon.py runs the plain-Python operations without it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

OPEN = 2  # a sign the float filter leaves open: the plain-Python operation decides it exactly
# polygon.py's constants come in as one array, ``k`` (polygon._CONSTANTS), never as globals: numba would bake a global
# into the cached machine code, and its cache goes stale only when this file changes, not when polygon.py does
ERRBOUND, TINY_, TWO_PI_, DUPLICATE_, ROUNDING_, MARGIN_, MAX_REACH_ = range(7)  # their places in k


@njit(cache=True)
def _cross(ax: float, ay: float, bx: float, by: float, k: np.ndarray) -> int:
    """The sign of a × b where floating point decides it exactly (polygon._cross_sign's filter; both products
    exactly zero where a factor of each is zero), else OPEN."""
    left = ax * by
    right = ay * bx
    det = left - right
    size = abs(left) + abs(right)
    if abs(det) > k[ERRBOUND] * size and size > k[TINY_]:
        return 1 if det > 0.0 else -1
    if (ax == 0.0 or by == 0.0) and (ay == 0.0 or bx == 0.0):
        return 0
    return OPEN


@njit(cache=True)
def _lower(x: float, y: float) -> bool:
    """The direction's angle in [π, 2π) (polygon._half's 1)."""
    return y < 0.0 or (y == 0.0 and x <= 0.0)


@njit(cache=True)
def _compare(ax: float, ay: float, bx: float, by: float, k: np.ndarray) -> int:
    """polygon._compare: −1 if direction a comes first in [0, 2π), 0 if the same, 1 if b does; OPEN if undecided."""
    ha, hb = _lower(ax, ay), _lower(bx, by)
    if ha != hb:
        return -1 if hb else 1
    s = _cross(ax, ay, bx, by, k)
    return OPEN if s == OPEN else -s


@njit(cache=True)
def _distinct(v: np.ndarray, k: np.ndarray) -> np.ndarray:
    """polygon._distinct: without the vertices within DUPLICATE (relative to the extent) of the one before."""
    n = v.shape[0]
    size = 0.0
    for i in range(n):
        size = max(size, abs(v[i, 0]), abs(v[i, 1]))
    tol = k[DUPLICATE_] * (1.0 + size)
    keep = np.empty(n, dtype=np.bool_)
    px, py = v[n - 1, 0], v[n - 1, 1]
    for i in range(n):
        x, y = v[i, 0], v[i, 1]
        keep[i] = abs(x - px) > tol or abs(y - py) > tol
        px, py = x, y
    out = v[keep]
    return out if out.shape[0] else v[:1].copy()


@njit(cache=True)
def _from_lowest(v: np.ndarray) -> np.ndarray:
    """polygon._from_lowest: rolled to start at the lowest (then leftmost, then first) vertex."""
    i0 = 0
    for k in range(1, v.shape[0]):
        if v[k, 1] < v[i0, 1] or (v[k, 1] == v[i0, 1] and v[k, 0] < v[i0, 0]):
            i0 = k
    out = np.empty_like(v)
    out[: v.shape[0] - i0] = v[i0:]
    out[v.shape[0] - i0 :] = v[:i0]
    return out


@njit(cache=True)
def _steps(w: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, int]:
    """polygon._steps of the edges of w and the ±2g of every segment g (without zero ones), and how many are edges."""
    n, m = w.shape[0], seg.shape[0]
    steps = np.empty((n + 2 * m, 2))
    k = 0
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        ex, ey = w[j, 0] - w[i, 0], w[j, 1] - w[i, 1]
        if ex != 0.0 or ey != 0.0:
            steps[k, 0], steps[k, 1] = ex, ey
            k += 1
    edges = k
    for sign in (2.0, -2.0):
        for i in range(m):
            sx, sy = sign * seg[i, 0], sign * seg[i, 1]
            if sx != 0.0 or sy != 0.0:
                steps[k, 0], steps[k, 1] = sx, sy
                k += 1
    return steps[:k], edges


@njit(cache=True)
def _plus(v: np.ndarray, seg: np.ndarray, k: np.ndarray) -> np.ndarray | None:
    """polygon._plus (its docstring, Polygon.plus_segments', says how); None where it needs an exact sign, the exact
    order or the exact hull."""
    w = _from_lowest(v)
    lx, ly = 0.0, 0.0
    for i in range(seg.shape[0]):  # each segment's lowest (then leftmost) end, summed
        x, y = seg[i, 0], seg[i, 1]
        ex, ey = (x, y) if _lower(x, y) else (-x, -y)
        if i == 0:
            lx, ly = ex, ey
        else:
            lx, ly = lx + ex, ly + ey
    steps, n = _steps(w, seg)
    ns = steps.shape[0]
    if ns == 0:
        return w
    key = np.empty(ns)
    for i in range(ns):
        x, y = steps[i, 0], steps[i, 1]
        key[i] = (8.0 if _lower(x, y) else 0.0) + math.atan2(y, x) % k[TWO_PI_]
    order = np.argsort(key, kind="mergesort")  # (stable: ties in index order, as Python's sorted)
    pairs = np.empty(ns - 1, dtype=np.int64)
    for i in range(ns - 1):
        a, b = order[i], order[i + 1]
        p = _compare(steps[a, 0], steps[a, 1], steps[b, 0], steps[b, 1], k)
        if p == OPEN or p == 1:
            return None  # an exact sign or the exact order: the plain-Python operation
        pairs[i] = p
    last = -1
    for i in range(ns):  # the edges in their own order?
        if order[i] < n:
            if order[i] < last:
                return None  # a rounding made a vertex reflex (or a tie swapped two edges): the plain-Python operation
            last = order[i]
    walk = np.empty((ns, 2))
    bx, by = w[0, 0] + lx, w[0, 1] + ly
    walk[0, 0], walk[0, 1] = bx, by
    cx, cy = steps[order[0], 0], steps[order[0], 1]
    for i in range(1, ns):  # each partial sum in turn
        walk[i, 0], walk[i, 1] = bx + cx, by + cy
        cx, cy = cx + steps[order[i], 0], cy + steps[order[i], 1]
    if ns > 1 and not (pairs == 0).any():
        return _distinct(walk, k)
    a, b = order[ns - 1], order[0]
    first = _compare(steps[a, 0], steps[a, 1], steps[b, 0], steps[b, 1], k)
    if first == OPEN:
        return None
    keep = np.empty(ns, dtype=np.bool_)
    keep[0] = first != 0
    keep[1:] = pairs != 0  # (else the vertex is on a side)
    kept = walk[keep]
    return _distinct(kept if kept.shape[0] else walk[:1], k)


@njit(cache=True)
def moved(v: np.ndarray, A: np.ndarray, t: np.ndarray, g: np.ndarray, k: np.ndarray) -> np.ndarray | None:
    """Polygon.moved's vertices (its docstring says how); None where the plain-Python operation must decide."""
    a00, a01, a10, a11, t0, t1 = A[0, 0], A[0, 1], A[1, 0], A[1, 1], t[0], t[1]
    turn = _cross(a00, a10, a01, a11, k)
    if turn == OPEN:
        return None
    n, m = v.shape[0], g.shape[0]
    w = np.empty((n, 2))
    size = 0.0
    for i in range(n):
        x, y = v[i, 0], v[i, 1]
        j = i if turn >= 0 else n - 1 - i  # (reversed where det A < 0)
        w[j, 0], w[j, 1] = a00 * x + a01 * y + t0, a10 * x + a11 * y + t1
        size = max(size, abs(w[j, 0]), abs(w[j, 1]))
    total = 0.0  # (summed apart, then added: Python's size + sum(…))
    for i in range(m):
        total += max(abs(g[i, 0]), abs(g[i, 1]))
    reach = size + total
    merged = (2 * (n + 2 * m) + 8) * k[DUPLICATE_] * (1.0 + reach)
    pad = max(k[ROUNDING_] * (1.0 + size), merged)
    seg = np.empty((m + 2, 2))
    seg[:m] = g
    seg[m, 0], seg[m, 1], seg[m + 1, 0], seg[m + 1, 1] = pad, 0.0, 0.0, pad
    return _plus(w, seg, k)


@njit(cache=True)
def _clip(v: np.ndarray, c0: float, c1: float, b: float, k: np.ndarray) -> np.ndarray | None:
    """polygon._clip: v ∩ {c0 x + c1 y ≤ b} (Sutherland–Hodgman); None if nothing remains."""
    n = v.shape[0]
    d = np.empty(n)
    top = -np.inf
    for i in range(n):
        d[i] = c0 * v[i, 0] + c1 * v[i, 1] - b
        top = max(top, d[i])
    if top <= 0.0:
        return v
    out = np.empty((2 * n, 2))
    j = 0
    px, py, sp = v[n - 1, 0], v[n - 1, 1], d[n - 1]
    for i in range(n):
        x, y, sq = v[i, 0], v[i, 1], d[i]
        if (sp < 0.0 < sq) or (sq < 0.0 < sp):  # the side from the previous vertex crosses the line
            s = sp / (sp - sq)
            out[j, 0], out[j, 1] = px + s * (x - px), py + s * (y - py)
            j += 1
        if sq <= 0.0:
            out[j, 0], out[j, 1] = x, y
            j += 1
        px, py, sp = x, y, sq
    return _distinct(out[:j], k) if j else None


@njit(cache=True)
def cut(v: np.ndarray, c0: float, c1: float, lo: float, hi: float, k: np.ndarray) -> tuple[int, np.ndarray]:
    """Polygon.cut (its docstring says how): (0, v) where the polygon is its own cut, (1, vertices) for a new one,
    (−1, v) where nothing is left."""
    n = v.shape[0]
    s_min, s_max, size, reach = np.inf, -np.inf, 0.0, 0.0
    for i in range(n):
        x, y = v[i, 0], v[i, 1]
        s = c0 * x + c1 * y
        s_min, s_max = min(s_min, s), max(s_max, s)
        size = max(size, abs(x), abs(y))
        reach = max(reach, abs(c0 * x) + abs(c1 * y))
    if lo <= s_min and s_max <= hi:
        return 0, v
    merged = (2 * n + 2) * k[DUPLICATE_] * (1.0 + size) * (abs(c0) + abs(c1))
    pad = max(k[MARGIN_] * (1.0 + reach), merged)
    if s_max <= hi + pad and -s_min <= -lo + pad:
        return 0, v
    out = _clip(v, c0, c1, hi + pad, k)
    if out is not None:
        out = _clip(out, -c0, -c1, -lo + pad, k)
    return (-1, v) if out is None else (1, out)


@njit(cache=True)
def _cheapest_edges(v: np.ndarray, wanted: int, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """polygon._cheapest_edges: the chosen edges (ascending area, ties in edge order) and each one's q."""
    n = v.shape[0]
    area = np.full(n, np.inf)
    q = np.zeros((n, 2))
    for i in range(n):
        a0x, a0y = v[i - 1, 0], v[i - 1, 1]  # (i − 1 = −1: the last)
        a1x, a1y = v[i, 0], v[i, 1]
        i1, i2 = (i + 1) % n, (i + 2) % n
        b0x, b0y = v[i1, 0], v[i1, 1]
        dax, day = a1x - a0x, a1y - a0y
        dbx, dby = v[i2, 0] - b0x, v[i2, 1] - b0y
        den = dax * dby - day * dbx
        if not den > 1e-300:
            continue  # parallel, or meeting behind: dropping that edge is unbounded
        t = ((b0x - a0x) * dby - (b0y - a0y) * dbx) / den
        if not 1.0 <= t <= k[MAX_REACH_]:
            continue
        qx, qy = a0x + t * dax, a0y + t * day
        if not (qx - b0x) * dbx + (qy - b0y) * dby <= 0.0:
            continue
        a = 0.5 * abs((qx - a1x) * (b0y - a1y) - (qy - a1y) * (b0x - a1x))
        if a < np.inf:
            area[i], q[i, 0], q[i, 1] = a, qx, qy
    chosen = np.empty(wanted, dtype=np.int64)
    near = np.zeros(n, dtype=np.bool_)
    j = 0
    for i in np.argsort(area, kind="mergesort"):
        if j == wanted or area[i] == np.inf:
            break
        if not near[i]:
            chosen[j] = i
            j += 1
            for d in range(-2, 3):
                near[(i + d) % n] = True
    return chosen[:j], q


@njit(cache=True)
def reduced(v: np.ndarray, max_vertices: int, k: np.ndarray) -> np.ndarray:
    """Polygon.reduced's vertices (its docstring says how)."""
    while v.shape[0] > max_vertices:
        n = v.shape[0]
        drops, q = _cheapest_edges(v, n - max_vertices, k)
        if drops.shape[0] == 0:
            break
        out = v.copy()
        keep = np.ones(n, dtype=np.bool_)
        for i in drops:
            out[i, 0], out[i, 1] = q[i, 0], q[i, 1]
            keep[(i + 1) % n] = False
        v = out[keep]
    return v
