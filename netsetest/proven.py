"""What a node proves at a step, as one typed set: :class:`ProvenSet` (issue 28).

The SDP's set is its ellipsoid {x̄: (x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ} ∩ (region × ℝ) ∩ {lo ≤ f ≤ hi}: the region a convex
polygon of x = (β, r) (netsetest/polygon.py), the slab the fault range a declared bound, the k-of-N pin or the own
measurement over the region proves (estimator/cuts.py).  A set estimator's set is its own (``set``, in the wire
form of netsetest/sets.py, itself cut by its region and fault range where it keeps one: sets.RegionSet); its
ellipsoid is then the one through the corners of that set's interval hull, the summary its neighbours use.

Every layer reads the set through this type: its per-coordinate bounds (made once per set), membership (the
judge's rule), its wire form (a msgspec Struct, checked on decode: a malformed set fails
:func:`netsetest.messages.decode`, so a role drops the message) and what a state's digest hashes of it.
"""

from __future__ import annotations

import math
from functools import cached_property
from typing import Annotated, Any, Literal

import msgspec
import numpy as np
from msgspec import Meta, Struct

from netsetest.models.sensor import NA, NX
import netsetest.linalg as linalg
from netsetest.polygon import MAX_VERTICES, MIN_VERTICES, Polygon, region_problem
from netsetest.sets import Box, Ellipsoid, RegionSet, SumSet, Zonotope, ellipsoid_bounds, set_from_wire
from netsetest.validation import Finite, Positive

Vec3 = Annotated[list[Finite], Meta(min_length=NA, max_length=NA)]
Vec2 = Annotated[list[Finite], Meta(min_length=2, max_length=2)]
Mat3 = Annotated[list[Finite], Meta(min_length=NA * NA, max_length=NA * NA)]
RegionCoords = Annotated[list[Finite], Meta(min_length=2 * MIN_VERTICES, max_length=2 * MAX_VERTICES)]
SYM_RTOL, SYM_ATOL = 1e-9, 1e-15  # P = Pᵀ up to rounding, as np.allclose(P, P.T, rtol, atol)


def spd_problem(p: list[float]) -> str | None:
    """Why the row-major 3×3 ``p`` is not symmetric positive definite (None if it is).

    Plain floats rather than np.allclose and np.linalg.cholesky: the same tests, ten times cheaper
    (≈3 µs against ≈30 µs), and every role pays them for every state it receives.
    """
    for a, b in ((1, 3), (2, 6), (5, 7)):  # (0,1), (0,2), (1,2) against their transposes
        if abs(p[a] - p[b]) > SYM_ATOL + SYM_RTOL * min(abs(p[a]), abs(p[b])):
            return "P is not symmetric"
    # Cholesky of the lower triangle (LAPACK potrf's order): positive definite iff every pivot is > 0
    if not p[0] > 0:
        return "P is not positive definite"
    l00 = math.sqrt(p[0])
    l10, l20 = p[3] / l00, p[6] / l00
    d1 = p[4] - l10 * l10
    if not d1 > 0:
        return "P is not positive definite"
    l21 = (p[7] - l20 * l10) / math.sqrt(d1)
    if not p[8] - l20 * l20 - l21 * l21 > 0:
        return "P is not positive definite"
    return None


class ProvenSet(Struct, frozen=True, kw_only=True, forbid_unknown_fields=True, omit_defaults=True, dict=True):
    """The ellipsoid (x̂, P row-major, ρ) ∩ (``region`` × ℝ) ∩ {fault[0] ≤ f ≤ fault[1]}, or a set estimator's
    ``set`` (then ``region`` and ``fault`` are absent: its set carries its own, and the ellipsoid encloses it).

    ``region``: the polygon's vertices counter-clockwise, flattened [β₁, r₁, β₂, r₂, …] (None: no region kept).
    The cross-field checks (P symmetric positive definite, a region a node may publish: polygon.region_problem, lo ≤
    hi, a set that parses) run on construction and on decode (a ValueError there fails the message's decode; a
    region's names its reason first).
    """

    xhat: Vec3
    P: Mat3
    rho: Positive
    region: RegionCoords | None = None
    fault: Vec2 | None = None
    set: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        problem = spd_problem(self.P)
        if problem:
            raise ValueError(problem)
        if self.fault is not None and not self.fault[0] <= self.fault[1]:
            raise ValueError(f"fault: lo > hi ({self.fault})")
        if self.region is not None and (bad_region := region_problem(self.region)):
            raise ValueError(": ".join(bad_region))  # the reason first: decode drops the message under it
        if self.set is not None:
            if self.region is not None or self.fault is not None:
                raise ValueError("a set estimator's set carries its own region and fault range")
            self.own_set  # parsed (SetFormatError, a ValueError, if malformed) and kept for bounds and membership

    @cached_property
    def own_set(self) -> Ellipsoid | Zonotope | Box | SumSet | RegionSet | None:
        """A set estimator's set, parsed once (None: the SDP's ellipsoid form)."""
        return None if self.set is None else set_from_wire(self.set, NA)

    @cached_property
    def P_matrix(self) -> np.ndarray:
        """P as a (3, 3) array (read-only: shared by every reader of this set)."""
        m = np.asarray(self.P, dtype=float).reshape(NA, NA)
        m.flags.writeable = False
        return m

    @cached_property
    def centre(self) -> np.ndarray:
        """x̂ as a (3,) array (read-only)."""
        c = np.asarray(self.xhat, dtype=float)
        c.flags.writeable = False
        return c

    @cached_property
    def polygon(self) -> Polygon | None:
        """The region as a polygon of x = (β, r) (None: none kept)."""
        return None if self.region is None else Polygon.from_flat(self.region)

    @cached_property
    def _bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if self.own_set is not None:
            return self.own_set.bounds()
        lo, hi = ellipsoid_bounds(self.centre, np.diag(self.P_matrix), self.rho, self.fault)  # (new arrays: x̂ ∓ half)
        if self.polygon is not None:  # the ellipsoid ∩ the region: x's bounds are the tighter of the two
            low, high = self.polygon.bounds()
            lo[:NX], hi[:NX] = np.maximum(lo[:NX], low), np.minimum(hi[:NX], high)
        return lo, hi

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds (3,) over [β, r, f_i], computed once per set (copies: the caller may change them)."""
        lo, hi = self._bounds
        return lo.copy(), hi.copy()

    def fault_bounds(self) -> tuple[float, float]:
        """:meth:`bounds`' last coordinate, the fault's, alone: what a node takes of a neighbour's set whose reading it
        uses with its declared bound.  The region, over x, leaves it as the ellipsoid ∩ the fault range has it, so it
        needs neither the region parsed nor the other coordinates (the same floats: √ and the products correctly
        rounded in both)."""
        if self.own_set is not None or "_bounds" in self.__dict__:
            lo, hi = self._bounds
            return float(lo[-1]), float(hi[-1])
        half = math.sqrt(self.rho * self.P[-1])
        lo_f, hi_f = self.xhat[-1] - half, self.xhat[-1] + half
        return (lo_f, hi_f) if self.fault is None else (max(lo_f, self.fault[0]), min(hi_f, self.fault[1]))

    @property
    def is_ellipsoid(self) -> bool:
        """The set is the ellipsoid alone (no region, no fault range, no set estimator's set)."""
        return self.region is None and self.fault is None and self.set is None

    def E(self, xbar: np.ndarray) -> float:
        """eᵀP⁻¹e with e = x̄ − x̂: where x̄ lies against the ellipsoid (inside iff ≤ ρ)."""
        e = xbar - self.centre
        return float(e @ linalg.solve(self.P_matrix, e))  # (numpy.linalg's own LAPACK call, the same floats, without its set-up)

    def contains(self, xbar: np.ndarray, E: float | None = None) -> bool:
        """x̄ = (β, r, f) lies in the set: the judge's rule.  A set estimator's set by its own ``contains`` (relative
        tolerance sets.MEMBERSHIP_TOL); the SDP's: E ≤ ρ exactly, lo ≤ f ≤ hi exactly, x in the polygon
        (Polygon.contains).  ``E``: eᵀP⁻¹e where the caller has it."""
        if self.own_set is not None:
            return self.own_set.contains(xbar)
        return self._outside_region_holds(xbar, E) and (self.polygon is None or self.polygon.contains(xbar[:NX]))

    def _outside_region_holds(self, xbar: np.ndarray, E: float | None = None) -> bool:
        """The SDP's set less its region holds x̄: E ≤ ρ, lo ≤ f ≤ hi (exactly)."""
        if not (self.E(xbar) if E is None else E) <= self.rho:
            return False
        return self.fault is None or self.fault[0] <= float(xbar[-1]) <= self.fault[1]

    def relation(self, lo: np.ndarray, hi: np.ndarray) -> Relation:
        """Where the box [lo, hi] (3,) of x̄ lies against the set (a recorded drive's truth, docs/your-log.md):
        ``inside`` when the set holds the whole box (every corner: the set is convex), ``disjoint`` when it is proven
        apart (a separating coordinate of the set's bounds or a side of its region, or the ellipsoid's least
        eᵀP⁻¹e over the box above ρ with a margin for rounding), else ``overlap``.  Sound both ways: a box called
        disjoint never meets the set, one called inside lies in it; some disjoint boxes may be called overlap."""
        corners = _corners(lo, hi)
        if all(self.contains(c) for c in corners):
            return "inside"
        slo, shi = self.bounds()
        if np.any(lo > shi) or np.any(hi < slo):
            return "disjoint"
        if self.polygon is not None and _separated(self.polygon, lo[:NX], hi[:NX]):
            return "disjoint"
        if self.own_set is None and box_min_E(self.centre, self.P_matrix, lo, hi) > self.rho * (1 + DISJOINT_RTOL):
            return "disjoint"
        return "overlap"

    def E_max(self, lo: np.ndarray, hi: np.ndarray) -> float:
        """The largest eᵀP⁻¹e over the box [lo, hi]: at a corner (a convex function); ≤ ρ iff the ellipsoid holds the box."""
        return max(self.E(c) for c in _corners(lo, hi))

    def ellipsoid_only(self) -> ProvenSet:
        """The ellipsoid alone (what a neighbour uses of a state)."""
        return ProvenSet(xhat=self.xhat, P=self.P, rho=self.rho)

    def without_fault(self) -> ProvenSet:
        """The same ellipsoid and region without the fault range."""
        return ProvenSet(xhat=self.xhat, P=self.P, rho=self.rho, region=self.region)

    def digest_content(self) -> tuple[Any, ...]:
        """What a state's digest hashes of this set: every field, as sent."""
        return (self.xhat, self.P, self.rho, self.region, self.fault, self.set)


DISJOINT_RTOL = 1e-9  # the least eᵀP⁻¹e over a box must exceed ρ by this (relative) before the two are called disjoint
Relation = Literal["inside", "disjoint", "overlap"]


def _corners(lo: np.ndarray, hi: np.ndarray) -> list[np.ndarray]:
    """The box's distinct corners (a flat coordinate gives one, a point box one corner)."""
    out = [np.empty(0)]
    for a, b in zip(lo, hi):
        out = [np.append(c, v) for c in out for v in ((a,) if a == b else (a, b))]
    return out


def _separated(poly: Polygon, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether a side's outward or inward normal (or a side's direction) separates the box of x from the polygon."""
    v = poly.vertices
    e = np.roll(v, -1, axis=0) - v
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    d = np.vstack([n, -n, e, -e])
    box_min = np.minimum(d[:, 0] * lo[0], d[:, 0] * hi[0]) + np.minimum(d[:, 1] * lo[1], d[:, 1] * hi[1])
    return bool(np.any(box_min > (v @ d.T).max(axis=0)))


def box_min_E(c: np.ndarray, P: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """min (x − c)ᵀP⁻¹(x − c) over lo ≤ x ≤ hi, exactly: at the minimum every coordinate is at a bound or free with
    zero gradient (KKT), so the least value over the 3ⁿ patterns whose free coordinates solve Q_FF x_F = Q_FF c_F −
    Q_FX (x_X − c_X) inside their bounds is it."""
    Q = np.linalg.inv(P)
    n = c.size
    best = np.inf
    for pattern in np.ndindex(*(3,) * n):  # 0: at lo, 1: at hi, 2: free
        x = np.where(np.array(pattern) == 0, lo, hi).astype(float)
        free = [i for i in range(n) if pattern[i] == 2]
        fixed = [i for i in range(n) if pattern[i] != 2]
        if free:
            rhs = Q[np.ix_(free, free)] @ c[free] - Q[np.ix_(free, fixed)] @ (x[fixed] - c[fixed])
            xf = np.linalg.solve(Q[np.ix_(free, free)], rhs)
            if np.any(xf < lo[free]) or np.any(xf > hi[free]):
                continue
            x[free] = xf
        e = x - c
        best = min(best, float(e @ Q @ e))
    return best


def continued_set(published: ProvenSet, continues: ProvenSet | None) -> ProvenSet:
    """The whole set a node continues from: the published one, or the ellipsoid ``continues`` gives ∩ the published
    region (a node keeps one region, and both its sets are cut by it: the wire sends it once)."""
    if continues is None:
        return published
    return ProvenSet(xhat=continues.xhat, P=continues.P, rho=continues.rho, region=published.region)


def contains_both(published: ProvenSet, continues: ProvenSet | None, xbar: np.ndarray, E: float | None = None) -> tuple[bool, bool]:
    """``published.contains(xbar, E)`` and ``continued_set(published, continues).contains(xbar)``, without building
    that set (a new set, its region checked and parsed again) and with x's membership in the one region both sets
    share (the published one, parsed once with it) asked once: the exact polygon test is most of the judge's
    membership.  The same floats, the same rules (``continues`` None: the published set, whose answer is both)."""
    if continues is None:
        inside = published.contains(xbar, E)
        return inside, inside
    if published.own_set is not None:  # (a set estimator continues from the set it publishes: not sent so)
        return published.contains(xbar, E), continues.contains(xbar) and (published.polygon is None or published.polygon.contains(xbar[:NX]))
    pub_holds, cont_holds = published._outside_region_holds(xbar, E), continues.contains(xbar)
    in_region = (pub_holds or cont_holds) and (published.polygon is None or published.polygon.contains(xbar[:NX]))
    return pub_holds and in_region, cont_holds and in_region


def proven_sets(entry: dict) -> tuple[ProvenSet, ProvenSet | None]:
    """A record's state entry's published set and the whole set its node continued from (None: the published one),
    checked (ValueError if malformed).  Entries written before issue 28 name the published ellipsoid xhat, P, rho,
    with fault_range (its fault range), own_xhat and own_P (the ellipsoid continued from, where not the published
    one) and own_region (the region of both) beside it: converted here, the only reader of that form.  Their node
    continued from its ellipsoid ∩ its region without the fault range, so a fault range alone makes the two differ."""
    if "published" in entry:
        pub = msgspec.convert(entry["published"], ProvenSet)
        cont = entry.get("continues")
        return pub, None if cont is None else continued_set(pub, msgspec.convert(cont, ProvenSet))
    region, fault = entry.get("own_region"), entry.get("fault_range")
    pub = msgspec.convert({"xhat": entry["xhat"], "P": entry["P"], "rho": entry["rho"], "region": region, "fault": fault}, ProvenSet)
    if entry.get("own_xhat") is not None:
        return pub, msgspec.convert({"xhat": entry["own_xhat"], "P": entry["own_P"], "rho": entry["rho"], "region": region}, ProvenSet)
    return pub, None if fault is None else pub.without_fault()
