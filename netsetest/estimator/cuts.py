"""The SDP step's cuts (docs/estimator.md, "One step"): after the solve, a declared list of pure
functions, each taking the step's sets and returning them cut, each named, each with the assumption it rests on.

A step k → k+1 of :class:`~netsetest.estimator.sdp.LocalEstimator` reads top to bottom:

1. its :class:`StepContext`, built once: the blended model, the own sector and measurement interval, the
   readings' slabs, the k-of-N assessment, the moved region and the LMI data;
2. the solve (and certificate) of the set the node continues from and publishes (the cuts may make another to
   publish);
3. the cuts of :data:`STEP_CUTS`, in order (step 0: :data:`FIRST_CUTS`; a step without a certificate:
   :data:`FALLBACK_CUTS`).

Each cut keeps every point of its input set that satisfies its slab (tests/unit/test_region_cuts.py), so the
step's sets hold the truth wherever the solve's assumptions and the cuts' assumptions did; the readings a cut
rests on join the set's keys, which the node lists (:attr:`StepResult.rests_on`) so that the collector judges
the set under their declarations (docs/coverage.md).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from netsetest.estimator.health import HEALTH_KEY, HealthAssessment
from netsetest.estimator.problem import StepData
from netsetest.estimator import region_engine
from netsetest.estimator.region_engine import Blend, RegionFacts
from netsetest.estimator.sector import FaultBound, Interval, Sector
from netsetest.estimator.slab import cut
from netsetest.models.sensor import NA, NX, Sensor
from netsetest.polygon import REGION_REASONS, Polygon
from netsetest.proven import ProvenSet
from netsetest.sets import NO_CUTS, CutName, IntervalCuts, Slab, ellipsoid_bounds

Status = Literal["ok", "fallback"]
FAULT_AXIS = np.eye(NA)[NA - 1]  # f = e₃ᵀx̄: the direction the fault cuts act along
HEALTH_KEYS = frozenset({HEALTH_KEY})  # what a set cut by the k-of-N facts rests on: every reading of the step
PIN_FLOOR = 1e-6  # a fault proved healthy is published as |f| ≤ max(τ, this): an ellipsoid cannot be flat


@dataclass(frozen=True)
class NodeSet:
    """A node's own set {x̄: (x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ} in the SDP's (x̂, P, ρ) form (sets.Ellipsoid is the published one)."""

    xhat: np.ndarray  # (3,)
    P: np.ndarray  # (3, 3)
    rho: float
    region: Polygon | None = None  # the states x = (β, r) the earlier steps left (None: none kept; docs/estimator.md)
    region_without: frozenset[int] = frozenset()  # the readings the region was cut without at its last step (Contradicted.readings)


@dataclass(frozen=True)
class Rests:
    """What a step's sets rest on beyond the solve's own assumptions: the readings (node ids: a reference's, or
    the own one of a reference) and whether the k-of-N facts (every reading of the step) are among them."""

    readings: frozenset[int]
    health: bool
    sets: frozenset[int] = frozenset()  # in-neighbours whose published set (region, fault range) cut the step's sets


@dataclass(frozen=True)
class StepSet:
    """One certified set of a step, {x̄: (x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ_i} ∩ {lo ≤ f⁺ ≤ hi} (``fault_range``), with the gain and
    the certified radius that made it, what it rests on beyond the solve, and the cuts that narrowed its intervals."""

    xhat: np.ndarray  # (NA,)
    P: np.ndarray  # (NA, NA) published shape: e⁺ᵀ P⁻¹ e⁺ ≤ ρ_i
    rho_cert: float  # ρ' certified for the solver's P (P is published as P_solver·ρ'/ρ_i); NaN: none (fallback, rejoin)
    L: np.ndarray = field(default_factory=lambda: np.zeros((NA, 1)))  # (NA, 1) the gain of (16)
    fault_range: tuple[float, float] | None = None  # the set is the ellipsoid ∩ {lo ≤ f⁺ ≤ hi}
    reading_keys: frozenset[int] = frozenset()  # the readings the set rests on (keys of the context's slabs: node ids, and HEALTH_KEY for the k-of-N facts)
    set_keys: frozenset[int] = frozenset()  # the in-neighbours whose published sets of step k the set rests on (the region's cuts)
    cuts: IntervalCuts = NO_CUTS  # per coordinate, the cuts that narrowed the interval of this set as published (apply_cuts)

    def replaced(self, **changes: Any) -> StepSet:
        """This set with ``changes``: dataclasses.replace without its per-field set-up (several per step; no field has
        init=False or a check in __post_init__, so the result is the same)."""
        assert changes.keys() <= STEP_SET_FIELDS, f"not fields of StepSet: {set(changes) - STEP_SET_FIELDS}"
        new = object.__new__(StepSet)
        new.__dict__.update(self.__dict__, **changes)  # (frozen: set as dataclasses' own __init__ sets them)
        return new


@dataclass(frozen=True)
class StepFigures:
    """How a step's sets were obtained: ``ok`` (certified) or ``fallback``, the solves' wall time and the solver's status."""

    status: Status
    solve_ms: float
    solver_status: str


@dataclass(frozen=True)
class Contradicted:
    """A step whose region cut left nothing: its data contradict what the node assumes (docs/estimator.md, "The set a node
    proves").  ``by``: ``readings``, the step's readings (``readings``: the node ids, HEALTH_KEY for the k-of-N interval)
    leave nothing of the region the node's own data leave, so a declaration they rest on, or an assumption the
    region rests on, broke (the region is kept without them); ``own-data``, the node's own measurement (with the
    fault bound where the step rests on it) leaves nothing of its moved region and ellipsoids, so one of the node's
    own assumptions, or a set its region rests on, broke (no region is kept: the next step seeds one from the set
    the node continues from).  Either way the node publishes a set resting on nothing the contradicted data proved."""

    by: Literal["readings", "own-data"]
    readings: frozenset[int] = frozenset()


@dataclass(frozen=True)
class StepResult:
    """One step's two sets and its figures: the set the node continues from, ``continued`` ∩ ``region``, and the one
    it publishes, ``published`` ∩ ``region`` (the very same object where the node publishes the set it continues
    from), the own sensor's sector of the step and how the sets were obtained."""

    continued: StepSet
    published: StepSet
    figures: StepFigures
    sector: Sector | None = None  # the own sensor's sector of this step (None: no saturation modelled)
    region: Polygon | None = None  # the states x⁺ every step so far leaves (NodeSet.region): both sets'
    region_facts: RegionFacts | None = None  # what the region cut proved of it (its box, the faults over it), with it
    contradicted: Contradicted | None = None  # the step's data contradicted its assumptions: its region cut left nothing (None: it did not)

    @classmethod
    def of(cls, s: StepSet, figures: StepFigures, sector: Sector | None = None) -> StepResult:
        """A step whose node publishes the set it continues from, ``s``."""
        return cls(s, s, figures, sector)

    def replaced(self, **changes: Any) -> StepResult:
        """This result with ``changes`` (as :meth:`StepSet.replaced`)."""
        assert changes.keys() <= STEP_RESULT_FIELDS, f"not fields of StepResult: {set(changes) - STEP_RESULT_FIELDS}"
        new = object.__new__(StepResult)
        new.__dict__.update(self.__dict__, **changes)
        return new

    def continuing(self, s: StepSet) -> StepResult:
        """This result continuing from ``s`` instead, and publishing it too where it published the set it continued from."""
        return self.replaced(continued=s, published=s if self.published is self.continued else self.published)

    def published_set(self, rho: float, own_set: dict | None = None) -> ProvenSet:
        """What the node publishes, as sent: the ellipsoid of ``published`` with radius ρ_i ∩ the region ∩ its fault
        range; or a set estimator's own set (``own_set``, sets.set_to_wire) with the ellipsoid that encloses it.  A
        region no receiver would take (polygon.region_problem, which ProvenSet runs) is left out: a superset, sound."""
        pub = self.published
        fields = dict(
            xhat=pub.xhat.tolist(),  # float64 arrays: the floats [float(a) for a in …] gave, without the loop
            P=pub.P.reshape(NA * NA).tolist(),
            rho=rho,
            fault=None if pub.fault_range is None else [float(pub.fault_range[0]), float(pub.fault_range[1])],
            set=own_set,
        )
        if self.region is not None:
            try:
                return ProvenSet(region=self.region.flat(), **fields)
            except ValueError as exc:
                if str(exc).split(":", 1)[0] not in REGION_REASONS:
                    raise
        return ProvenSet(**fields)

    def continued_ellipsoid(self, rho: float) -> ProvenSet | None:
        """The ellipsoid the node continues from where that set is not the published one (None: it is): the set is it
        ∩ the same region (proven.continued_set), without the fault range (the published one's rests on this step's
        facts alone)."""
        if self.published is self.continued:
            return None
        return ProvenSet(xhat=self.continued.xhat.tolist(), P=self.continued.P.reshape(NA * NA).tolist(), rho=rho)

    @property
    def rests_on(self) -> Rests:
        """The readings both sets rest on (the published one's and the continued one's: both are judged)."""
        pub, cont = self.published, self.continued
        keys = pub.reading_keys | cont.reading_keys
        return Rests(frozenset(keys - {HEALTH_KEY}), HEALTH_KEY in keys, pub.set_keys | cont.set_keys)


STEP_SET_FIELDS = frozenset(f.name for f in dataclasses.fields(StepSet))
STEP_RESULT_FIELDS = frozenset(f.name for f in dataclasses.fields(StepResult))

Slabs = dict[int, Slab]
"""What the step's readings prove: slabs lo ≤ c̄ᵀx̄⁺ ≤ hi (sets.Slab, c̄ (NA,)), keyed by the reference's id, and by HEALTH_KEY
for the k-of-N interval (the keys of the readings' ν slots in the LMI; the node reads :attr:`StepResult.rests_on`)."""


@dataclass(frozen=True)
class CutStatics:
    """What the cuts need of the node, fixed for its run: its id and sensor, its declared fault bound, the k-of-N
    tolerance (None: no k-of-N group) and the objective weights D^½ of the recursion and of the published set."""

    node_id: int
    own: Sensor
    fault_bound: FaultBound
    health_tolerance: float | None
    wh: np.ndarray | None  # recursion objective trace(D P) (None: trace P)
    wh_pub: np.ndarray | None  # objective ``bank``: the published set's (None: the recursion's)
    own_bound: bool = False  # the declared fault bound is relied on at every step (others read the reading with it): cut by it too

    @property
    def wh_published(self) -> np.ndarray | None:
        return self.wh_pub if self.wh_pub is not None else self.wh


@dataclass(frozen=True)
class StepContext:
    """Everything one step knows before its solve, computed once (docs/estimator.md, "One step")."""

    statics: CutStatics
    rho: float  # ρ_i
    y: float  # ỹ_i,k+1
    gamma: float  # γ_i,k+1
    meas: Interval  # C̄ x̄⁺ from the own measurement alone (measurement_interval)
    sector: Sector | None  # the own sensor's sector of the step
    data: StepData  # the LMI of the step
    moved: Polygon  # the previous region (or the prior's seed) through the step's dynamics and bounds
    slabs: Slabs  # what the step's readings prove
    health: HealthAssessment | None  # the k-of-N assessment (None: no k-of-N group, or no reading)
    listed: bool = True  # the step lists readings (False: step 0, whose cone is the prior's)
    blend: Blend | None = None  # the step's blended model (None: step 0, no prediction)
    region_slabs: Slabs = field(default_factory=dict)  # what the bounded readings prove: they cut the region alone
    sets: frozenset[int] = frozenset()  # the in-neighbours whose published sets (region; a bounded reading's rate) ``moved`` and ``region_slabs`` rest on
    region_without: frozenset[int] = frozenset()  # the readings ``moved`` was cut without at the step before (NodeSet.region_without)


CutFn = Callable[[StepContext, StepResult], StepResult]


@dataclass(frozen=True)
class Cut:
    """One cut of the step: ``apply`` takes the step's sets and returns them cut (pure: it never changes its
    input); ``rests_on`` names the assumption beyond the solve's under which it keeps the truth."""

    name: CutName
    rests_on: str
    apply: CutFn


def cut_fault(ctx: StepContext, res: StepResult, lo: float, hi: float, reshape: bool = True, keys: frozenset[int] = frozenset()) -> StepResult | None:
    """The sets with the published one cut by lo ≤ f⁺ ≤ hi (:func:`~netsetest.estimator.slab.cut`, certified; not
    unless ``reshape``) and published as that ellipsoid ∩ {lo ≤ f⁺ ≤ hi} (ProvenSet.fault: no ellipsoid ends
    at the slab's flat face), resting on the readings ``keys`` too; None where the slab does not narrow the published
    fault interval.  The set the node continues from is unchanged."""
    pub, rho = res.published, ctx.rho
    now_lo, now_hi = _fault_interval(pub, rho)  # the published fault interval
    lo, hi = max(lo, now_lo), min(hi, now_hi)
    if not (lo > now_lo or hi < now_hi) or lo > hi:
        return None  # no cut (an empty one means the assumptions broke: the step's set stays as certified)
    wh = ctx.statics.wh_published
    out = cut(pub.xhat, pub.P, rho, Slab(FAULT_AXIS, lo, hi), None if wh is None else wh**2) if reshape else None
    if out is None:  # the ellipsoid gains nothing; the slab still bounds the fault
        new = pub.replaced(fault_range=(lo, hi), reading_keys=pub.reading_keys | keys)
    else:  # ρ' as for a solved set (P published = P_s·ρ'/ρ_i): the cut certifies ρ_i·P_s with radius out[2]
        new = pub.replaced(xhat=out[0], P=out[1], rho_cert=out[2] * rho, fault_range=(lo, hi), reading_keys=pub.reading_keys | keys)
    return res.replaced(published=new)


def _fault_interval(s: StepSet, rho: float) -> tuple[float, float]:
    """The fault interval of ``s``'s set with radius ρ: x̂_f ∓ √(ρ P_ff) within its fault range (sets.ellipsoid_bounds'
    last coordinate, the same floats, without the other two)."""
    x, half = float(s.xhat[-1]), math.sqrt(rho * float(s.P[-1, -1]))
    lo, hi = x - half, x + half
    if s.fault_range is not None:
        lo, hi = max(lo, s.fault_range[0]), min(hi, s.fault_range[1])
    return lo, hi


def carry(ctx: StepContext, res: StepResult, slabs: Slabs) -> StepResult:
    """The set the node continues from cut by slabs cᵀx̄⁺ ∈ [lo, hi] (:func:`~netsetest.estimator.slab.cut`,
    certified, in the recursion's objective), so that they carry over to the later steps; what is published does
    not change.  The keys of the slabs that cut it join its ``reading_keys``."""
    cont = res.continued
    xhat, P, rho_cert, used = cont.xhat, cont.P, cont.rho_cert, set()
    wh = ctx.statics.wh
    for key, slab in slabs.items():
        out = cut(xhat, P, ctx.rho, slab, None if wh is None else wh**2)
        if out is not None:  # ρ' as for a solved set (P = P_s·ρ'/ρ_i)
            xhat, P, rho_cert = out[0], out[1], out[2] * ctx.rho
            used.add(key)
    if not used:
        return res  # no slab cuts it
    # the published set stays as it was (where it was this one: the step's set as solved)
    return res.replaced(continued=cont.replaced(xhat=xhat, P=P, rho_cert=rho_cert, reading_keys=cont.reading_keys | used))


def _readings_cut(ctx: StepContext, res: StepResult) -> StepResult:
    """The set the node continues from cut by every reading's slab (without it the recursion forgets the readings
    at every step while the exact limit keeps them: docs/network.md)."""
    if not ctx.slabs:
        return res
    return carry(ctx, res, ctx.slabs)


def _size_cut(ctx: StepContext, res: StepResult) -> StepResult:
    """Where the step's sector rests on the declared fault bound, the truth's f⁺ lies in [−F, F]: the published set
    is cut by that interval (docs/estimator.md, "One step": `fault-size`)."""
    size, sector = ctx.statics.fault_bound.size, res.sector
    sector_bound = sector is not None and sector.basis == "fault-bound"
    if size is None or not (ctx.statics.own_bound or sector_bound):
        return res
    # (a bound relied on for the other nodes' sake only: the fault range alone, the ellipsoid as solved, what neighbours use)
    out = cut_fault(ctx, res, -size, size, reshape=sector_bound)
    return res if out is None else out


def _region_cut(ctx: StepContext, res: StepResult) -> StepResult:
    """The moved region cut by everything the step proves of x⁺ (docs/estimator.md, "The set a node proves"): every reading
    of the step, the own measurement where the step's sector rests on the declared fault bound (C x⁺ = C̄ x̄⁺ − Ds f⁺
    with |f⁺| ≤ F), and the step's certified ellipsoids (the one the node continues from and the published one).
    The node continues from it and publishes it: the published set is the published ellipsoid ∩ the region, and
    its fault interval is cut by what the own measurement proves over the region.  Where the readings leave nothing,
    the region is cut without them (:func:`_region_without_readings`); where even that leaves nothing, no region is
    kept (the next step seeds one from the set the node continues from).  Either is named in the step's result
    (:class:`Contradicted`).

    A reference (declared fault size 0) cuts by its own measurement too and publishes f⁺ = 0, resting on its own
    reading; not where the step cannot list readings (step 0, whose cone is the prior's)."""
    st = ctx.statics
    size, sector = st.fault_bound.size, res.sector
    reference = size == 0.0 and ctx.listed  # its own reading rests on its declared zero fault (listed, so judged)
    own = size is not None and (reference or st.own_bound or (sector is not None and sector.basis == "fault-bound"))
    readings = frozenset(ctx.slabs) | frozenset(ctx.region_slabs)
    facts = _region_facts(ctx, res, (*ctx.slabs.values(), *ctx.region_slabs.values()), size if own else None, ctx.health)
    if facts is None:
        facts, res = _region_without_readings(ctx, res, readings, size if own else None)
        if facts is None:
            return res
        readings = frozenset()
    keys = readings | ({st.node_id} if reference else frozenset())
    cont = res.continued
    res = res.continuing(cont.replaced(reading_keys=cont.reading_keys | keys, set_keys=cont.set_keys | ctx.sets))
    res = res.replaced(region=facts.region, region_facts=facts)
    fault = (0.0, 0.0) if reference else facts.fault
    # with readings the ellipsoid is cut too (as since the region came); without, it stays as solved (what
    # neighbours use, bit for bit) and only the published fault range narrows: the same published interval
    out = cut_fault(ctx, res, *fault, reshape=bool(readings & ctx.slabs.keys())) if fault is not None else None
    if out is None or not keys:
        return res if out is None else out
    return out.replaced(published=out.published.replaced(reading_keys=out.published.reading_keys | keys))


def _region_facts(ctx: StepContext, res: StepResult, slabs: tuple[Slab, ...], size: float | None, health: HealthAssessment | None) -> RegionFacts | None:
    """The moved region cut by ``slabs``, the own measurement with the fault size ``size`` (None: not) and the step's
    ellipsoids, reduced (:func:`~netsetest.estimator.region_engine.cut`); under k-of-N (``health``), the own fault where
    the own sensor is healthy or the others agree.  None where nothing is left."""
    st = ctx.statics
    sets = (res.continued,) if res.published is res.continued else (res.continued, res.published)
    health = health if st.health_tolerance is not None and st.own.Ds != 0.0 else None  # (the health-fault cut's, computed here)
    return region_engine.cut(
        ctx.moved,
        slabs,
        st.own,
        ctx.meas,
        size,  # C x⁺ = C̄ x̄⁺ − Ds f⁺, |f⁺| ≤ F: the step's cone holds the bound
        ellipses=[(s.xhat, s.P, ctx.rho) for s in sets],
        others=None if health is None else health.others,
        floor=max(st.health_tolerance or 0.0, PIN_FLOOR),
    )  # reduced: the move's margin covers the cuts' rounding (Polygon.moved); None: fewer than three vertices left


def _region_without_readings(ctx: StepContext, res: StepResult, readings: frozenset[int], size: float | None) -> tuple[RegionFacts | None, StepResult]:
    """The region of a step whose cut by ``readings`` left nothing: the moved region cut by the node's own data alone
    (the own measurement with ``size``, the step's ellipsoids), which rests on nothing the published set does not
    (no reading of the step; the moved region's prior and in-neighbours' sets, which the sets name).  With the
    readings dropped the region keeps cutting at every later step instead of restarting, every step, from the box of
    the ellipsoid (what a gross false reading did: tests/inmemory/test_network_value.py).  The result names what was
    contradicted (:class:`Contradicted`): the readings (the region is this one), or the node's own data (nothing is
    left even without them: no region, and the facts are None).

    Where the moved region was cut by those readings at the step before (the first step they contradict), its memory
    may rest on them (a false reading that fitted earlier misled it): the region then starts from the box of the
    step's own set instead (:func:`seed`), as it did before it was kept, and keeps its memory from there on while the
    readings go on contradicting it."""
    if readings and not readings <= ctx.region_without:
        ctx = dataclasses.replace(ctx, moved=seed(NodeSet(res.continued.xhat, res.continued.P, ctx.rho)))
    facts = _region_facts(ctx, res, (), size, None) if readings else None
    if facts is None:
        return None, res.replaced(contradicted=Contradicted("own-data"))
    return facts, res.replaced(contradicted=Contradicted("readings", readings))


def _health_pin(ctx: StepContext, res: StepResult) -> StepResult:
    """Under ``max_faulty``, where no consistent majority of the step's readings leaves this node's sensor out,
    its fault is |f⁺| ≤ τ (docs/network.md): the published set is cut by that interval, widened to
    :data:`PIN_FLOOR` (a superset: sound) so that the published ellipsoid stays full-dimensional, and then rests
    on every reading (the k-of-N facts do); the set the node continues from is cut by it too."""
    tol = ctx.statics.health_tolerance
    if tol is None or ctx.health is None or not ctx.health.pinned:
        return res
    size = max(tol, PIN_FLOOR)
    out = cut_fault(ctx, res, -size, size)
    if out is not None:
        res = out.replaced(published=out.published.replaced(reading_keys=out.published.reading_keys | {HEALTH_KEY}))
    return carry(ctx, res, {HEALTH_KEY: Slab(FAULT_AXIS, -size, size)})


def _health_fault(ctx: StepContext, res: StepResult) -> StepResult:
    """Under ``max_faulty``, the own sensor is healthy (|f⁺| ≤ τ) or the other sensors' readings alone supply N − m
    agreeing ones; then t = uᵀx⁺ lies where they agree within the region, and the own measurement bounds f⁺ over
    that part of it (:meth:`~netsetest.estimator.health.Others.fault`).  The published fault range is cut by the hull
    of the two (docs/network.md): where the others agree nowhere in the region this is the pin's |f⁺| ≤ max(τ, 10⁻⁶),
    elsewhere it drops the faults the own measurement allows only where the own sensor must be healthy.
    The ellipsoid is left as solved and the set the node continues from is unchanged (a later fault is free of this
    one); the published set then rests on every reading."""
    facts = res.region_facts  # (the region cut computed it over the region: region_engine.health_fault)
    if facts is None or facts.health is None:
        return res
    out = cut_fault(ctx, res, *facts.health, reshape=False, keys=HEALTH_KEYS)
    return res if out is None else out


def seed(prior: NodeSet) -> Polygon:
    """The region of a set without one: the box of its ellipsoid's x-projection cut by that ellipse's axes."""
    lo, hi = ellipsoid_bounds(prior.xhat, np.diag(prior.P), prior.rho)
    box = Polygon.box(lo[:NX], hi[:NX])
    return box.ellipse_cut(prior.xhat, prior.P, prior.rho, coordinates=False) or box


READINGS = Cut("readings", "each reading's declaration: a reference's zero fault; k-of-N: at most m of N sensors faulty", _readings_cut)
FAULT_SIZE = Cut("fault-size", "the declared fault size |f| ≤ F, where the step's sector rests on it", _size_cut)
REGION = Cut(
    "region",
    "the prior (Assumption 1), the disturbance and model-mismatch bounds, and the declarations of what cuts it: "
    "the readings', the fault size's (a reference's: its zero fault)",
    _region_cut,
)
HEALTH_PIN = Cut("health-pin", "k-of-N health ([network] max_faulty): no consistent majority of the step's readings leaves the own sensor out", _health_pin)
HEALTH_FAULT = Cut(
    "health-fault",
    "k-of-N health ([network] max_faulty): the own sensor is healthy, or the other sensors' readings alone supply N − m agreeing ones",
    _health_fault,
)

STEP_CUTS: tuple[Cut, ...] = (READINGS, FAULT_SIZE, REGION, HEALTH_PIN, HEALTH_FAULT)  # a step k → k+1, in this order
FIRST_CUTS: tuple[Cut, ...] = (REGION,)  # step 0: the prior updated by ỹ₀ (no readings listed, no size cut)
FALLBACK_CUTS: tuple[Cut, ...] = (REGION,)  # a step without a certificate: the region of its own measurement


def apply_cuts(cuts: tuple[Cut, ...], ctx: StepContext, res: StepResult) -> StepResult:
    """The step's sets through ``cuts``, in order; the published set's ``cuts`` name, per coordinate, every cut that
    narrowed its interval (the ellipsoid's, within the fault range and the region: what the node publishes)."""
    bounds = published_bounds(res, ctx.rho)
    for c in cuts:
        out = c.apply(ctx, res)
        if out.published is res.published and out.region is res.region:
            res = out  # what is published did not change (the set the node continues from may have)
            continue
        now = published_bounds(out, ctx.rho)
        narrowed = [now[m] > bounds[m] for m in range(NA)] + [now[NA + m] < bounds[NA + m] for m in range(NA)]
        if any(narrowed):
            pub = out.published
            b, r, f = (pub.cuts[m] + (c.name,) if narrowed[m] or narrowed[NA + m] else pub.cuts[m] for m in range(NA))
            named = pub.replaced(cuts=(b, r, f))
            out = out.continuing(named) if pub is out.continued else out.replaced(published=named)
        res, bounds = out, now
    return res


def published_bounds(res: StepResult, rho: float) -> list[float]:
    """[lo_β, lo_r, lo_f, hi_β, hi_r, hi_f] of what ``res`` publishes: its ellipsoid's x̂ ∓ √(ρ P_ii), within its fault
    range and the region's intervals of β and r (ProvenSet.bounds, without making the set; plain floats: several a step)."""
    pub = res.published
    x, d = pub.xhat.tolist(), pub.P.diagonal().tolist()
    half = [math.sqrt(max(rho * v, 0.0)) for v in d]
    out = [x[0] - half[0], x[1] - half[1], x[2] - half[2], x[0] + half[0], x[1] + half[1], x[2] + half[2]]
    if pub.fault_range is not None:
        out[2], out[5] = max(out[2], pub.fault_range[0]), min(out[5], pub.fault_range[1])
    if res.region is not None:
        facts = res.region_facts
        if facts is not None and facts.region is res.region:
            b0, b1, b3, b4 = facts.box  # (the region cut's: its vertices' extremes)
        else:
            (b0, b1), (b3, b4) = (v.tolist() for v in res.region.bounds())
        out[0], out[1], out[3], out[4] = max(out[0], b0), max(out[1], b1), min(out[3], b3), min(out[4], b4)
    return out


__all__ = [
    "FALLBACK_CUTS",
    "FAULT_AXIS",
    "FIRST_CUTS",
    "PIN_FLOOR",
    "STEP_CUTS",
    "Cut",
    "Contradicted",
    "CutStatics",
    "NodeSet",
    "Rests",
    "Slabs",
    "StepContext",
    "StepFigures",
    "StepResult",
    "StepSet",
    "apply_cuts",
    "published_bounds",
    "carry",
    "cut_fault",
    "seed",
]
