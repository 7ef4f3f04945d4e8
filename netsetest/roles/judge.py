"""The verdict, computed one way: whether a node-step's published set held the truth, and whether the
guarantee covered it (its dependency cone, docs/coverage.md).

Pure: :class:`Judge` holds only what the scenario fixes (the nodes, the references, which set estimators
rest on their declared fault bound); :meth:`Judge.step` takes one closed step's admitted data (its truth,
the state judged for each node, every copy received, the previous step's truth and copy checks) and
returns typed verdicts, with nothing received, stored or written.  The collector (roles/collector.py)
admits messages (defences, duplicates, copies, the truth chain), calls the judge as each step closes,
then records and totals what it returns.  ``compare`` runs every real-time estimator through the
collector, so its rows are these verdicts too; an exact limit, which uses the whole history, is judged
by :func:`history_cone`.

One step deep over judged inputs: the estimate of (i, k) relies on its own sector condition and noise
bound at k, the disturbance (and model-mismatch) bound at k−1, the readings of step k it used, and the
exact copies of the states it used (its own previous set and its neighbours' of k−1, named by digest in
``NodeState.inputs``), each judged directly against the truth of k−1; step 0 relies on the initial
ellipsoid containing x̄_0 (Assumption 1).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

from dataclasses import dataclass, field

import numpy as np

from netsetest.config.schema import NodeConfig, Scenario
from netsetest.estimator.names import SDP
from netsetest.estimator.registry import node_set_estimator
from netsetest.estimator.sector import FaultBound, Propagation, Sector, measurement_interval, prior_interval, sector_ok
from netsetest.messages import NodeState, Truth, state_digest
from netsetest.proven import ProvenSet, Relation, contains_both
from netsetest.models.envelope import MODEL_MISMATCH, OUTSIDE_ENVELOPE
from netsetest.models.sensor import NX, augmented

CONSISTENCY_RTOL = 1e-9  # an own-data inconsistency must clear rounding: a certain one, never a near miss
INNOV_RTOL = 1e-12  # the node computes ỹ − C̄ x̂ with the same numbers: rounding only across machines

# why an input of a node-step gives it no guarantee (docs/coverage.md)
TRUTH_UNKNOWN = "truth unknown"  # no single consistent truth of that step: nothing can be judged
COLLECTOR_OVERLOADED = "collector overloaded"  # the step before was closed unjudged for the collector's own loss
NOT_FROM_INPUT = "not from its true input"  # its γ or innovation is not what the true measurement gives
MISSED = "missed the truth"
NOT_JUDGED = "not judged"  # no copy with that digest reached the collector, or several matched the truth
HEALTH = "k-of-N health"  # more than [network] max_faulty sensors faulty at a step whose set used it (docs/network.md)
INHERITED = "inherited"  # the cause of a node-step whose input failed: its Origin says which and why
NO_REFERENCE = "no reference"  # a recorded drive's step without a reference: the truth is unknown, nothing is judged
UNDECIDED = "undecided"  # an input whose set overlapped the reference's truth box without holding all of it: it may have missed


@dataclass(frozen=True)
class CopyCheck:
    """One copy of a node's state of a closed step, as an input of a later step: None where every fact a
    step takes from it held, else why not."""

    as_neighbour: str | None  # its published set held the truth; its innovation's noise and sector facts held
    as_prior: str | None  # the set its node continues from held the truth (self-loop: and those facts)
    as_set: str | None = None  # its whole published set (region, fault range) held the truth: a neighbour cut by it rests on that


@dataclass(frozen=True)
class Origin:
    """The input a not-covered node-step rests on: node ``node``'s state of step ``step``, and why it failed."""

    node: int
    step: int
    why: str


@dataclass(frozen=True)
class Cone:
    """A node-step's dependency cone: covered, or the first cause that takes it out of the guarantee."""

    ok: bool
    cause: str | None = None
    origin: Origin | None = None


@dataclass(frozen=True)
class Containment:
    """A judged state against its step's truth: E = eᵀP⁻¹e of its ellipsoid (the largest over a reference's truth
    box), whether its set holds the truth (all of the box), whether the set its node continues from does (the same
    set unless the state sends ``continues``), whether each is proven to miss it (disjoint from the box; a point
    truth: not held), and the set's per-coordinate bounds (3, 2) where it is not the ellipsoid alone (a set
    estimator's set, or the SDP's ellipsoid ∩ its fault range; None: the ellipsoid's).  Neither held nor missed is
    *undecided*: a recorded drive's reference cannot tell (docs/your-log.md)."""

    E: float
    contained: bool
    continues_contained: bool
    bounds: np.ndarray | None = None
    missed: bool = False
    continues_missed: bool = False

    @property
    def held(self) -> bool:
        """Both sets of the step hold the truth."""
        return self.contained and self.continues_contained

    @property
    def certain_miss(self) -> bool:
        """A set of the step is proven to miss the truth: on a covered node-step a violation."""
        return self.missed or self.continues_missed

    @property
    def undecided(self) -> bool:
        return not self.held and not self.certain_miss


@dataclass(frozen=True)
class HeldOver:
    """A node silent since step ``step`` (no reading, docs/your-log.md): the checks of its copies of that step, and
    the first assumption that broke on a transition since (None: none did).  A resumed state carries its own
    set of that step through them (estimator/rejoin.py), so its cone holds them too."""

    step: int
    copies: dict[str, CopyCheck]
    broken: str | None = None


@dataclass(frozen=True)
class StepChecks:
    """What a step leaves for the next one to judge its inputs by: every copy's check, each node's sole
    judged copy (for states from before digests), and what the silent nodes' last states left (:class:`HeldOver`)."""

    copies: dict[int, dict[str, CopyCheck]]
    sole: dict[int, str]
    held: dict[int, HeldOver] = field(default_factory=dict)
    states: dict[int, NodeState] = field(default_factory=dict)  # each node's sole judged state (the next step's own-data check)


NO_CHECKS = StepChecks({}, {})


@dataclass(frozen=True)
class StepInputs:
    """One closed step as admitted: its truth (None: no single consistent one), the previous step's, the
    state judged for each node (absent: nothing it sent can be its own), the nodes whose judged state is one
    of several matching copies (contested: judged on none), and every copy received per node."""

    step: int
    truth: Truth | None
    prev_truth: Truth | None
    judged: dict[int, NodeState]
    contested: frozenset[int]
    copies: dict[int, list[NodeState]]
    prev_overloaded: bool = False  # the step before was closed unjudged for the collector's own loss (its truth unread)

    @functools.cached_property
    def faults(self) -> dict[int, float]:
        """The truth's faults by node id (the wire keys them by string), converted once per step."""
        return {} if self.truth is None else {int(j): f for j, f in self.truth.faults.items()}


@dataclass(frozen=True)
class NodeVerdict:
    """One node-step: its cone, and, where the state was judged against a known truth, its containment."""

    node: int
    step: int
    cone: Cone
    containment: Containment | None
    inconsistent: bool = False  # without a reference: its own data prove one of its assumptions broken (Judge.inconsistent)


class StepSets:
    """What one closed step asks of each state copy, computed once: a judged state is also one of its node's copies, so
    its containment and its copy check ask the same memberships, and the set its node continues from
    (:attr:`NodeState.continued`, a new set, checked, each time it is asked) is built once.  Keyed by the copy's
    identity: valid while the step's inputs hold the copies (:meth:`Judge.step`)."""

    def __init__(self, tr: Truth) -> None:
        self.tr = tr
        self._got: dict[tuple[int, str], object] = {}

    def _once(self, st: NodeState, what: str, make: Callable[[], object]) -> Any:
        key = (id(st), what)
        if key not in self._got:
            self._got[key] = make()
        return self._got[key]

    def continued(self, st: NodeState) -> ProvenSet:
        return self._once(st, "continued", lambda: st.continued)

    def point(self, i: int, st: NodeState) -> tuple[float, bool, bool]:
        """Against a point truth x̄ (node i's): E of the published ellipsoid, whether the published set holds x̄, whether
        the set the node continues from does."""

        def make() -> tuple[float, bool, bool]:
            xbar = augmented(self.tr.x, self.tr.faults[i])
            pub = st.published
            E = pub.E(xbar)
            return E, *contains_both(pub, st.continues, xbar, E)

        return self._once(st, "point", make)

    def relations(self, i: int, st: NodeState, box: tuple[np.ndarray, np.ndarray]) -> tuple[Relation, Relation]:
        """Against node i's truth box: where the published set and the set the node continues from lie."""

        def make() -> tuple[Relation, Relation]:
            rel = relation(st.published, self.tr, i, box)
            return rel, rel if st.continues is None else relation(self.continued(st), self.tr, i, box)

        return self._once(st, "box", make)


@dataclass(frozen=True)
class StepVerdict:
    nodes: dict[int, NodeVerdict]
    checks: StepChecks  # for the next step's inputs


def published_sector(st: NodeState) -> Sector | None:
    return Sector(st.sector[0], st.sector[1], st.sector_basis) if st.sector is not None else None


def truth_box(tr: Truth, i: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Node i's x̄ = (β, r, f) as a reference's box (lo, hi), or None where the truth is a point (a model's run, or a
    reference of accuracy 0 with an exactly known fault: judged as a model's run is)."""
    if tr.x_acc is None:
        return None
    h = np.array([tr.x_acc[0], tr.x_acc[1], tr.f_acc.get(i, 0.0)])
    if not h.any() and i not in tr.fault_unknown:
        return None
    c = augmented(tr.x, tr.faults[i])
    return c - h, c + h


def relation(s: ProvenSet, tr: Truth, i: int, box: tuple[np.ndarray, np.ndarray]) -> Relation:
    """Where node i's truth box ``box`` (:func:`truth_box`) lies against ``s`` (ProvenSet.relation).  A fault nothing
    of the step tells (``Truth.fault_unknown``) may be any value: the box's fault side is then taken as the set's own
    fault range, which the set never leaves, so the truth is proven apart exactly where x is, and never held whole."""
    lo, hi = box
    if i not in tr.fault_unknown:
        return s.relation(lo, hi)
    f_lo, f_hi = (b[NX] for b in s.bounds())
    rel = s.relation(np.r_[lo[:NX], f_lo], np.r_[hi[:NX], f_hi])
    return "overlap" if rel == "inside" else rel


def _transition_cause(prev: Truth | None, k: int, prev_overloaded: bool) -> str | None:
    """Why the transition k − 1 → k gives no guarantee (None: the disturbance bound held over it); without the
    previous truth it is unknown: the collector's own overload where it closed that step unjudged."""
    if prev is None or prev.step != k - 1:
        return COLLECTOR_OVERLOADED if prev_overloaded else TRUTH_UNKNOWN
    if not prev.dist_ok:
        return "disturbance"
    return None


def _in_prior(n: NodeConfig, tr: Truth) -> bool:
    """Assumption 1: the true x̄_0 lies in node n's prior ellipsoid (all of a reference's box: else not proven; an
    unknown fault never is)."""
    if n.id in tr.fault_unknown:
        return False
    box = truth_box(tr, n.id)
    points = [augmented(tr.x, tr.faults[n.id])] if box is None else list(_box_corners(*box))
    return all(float((p - n.x0_hat) @ np.linalg.solve(n.P0, p - n.x0_hat)) <= n.rho for p in points)


def _box_corners(lo: np.ndarray, hi: np.ndarray) -> list[np.ndarray]:
    return [np.where(np.array(m, dtype=bool), hi, lo) for m in np.ndindex(2, 2, 2)]


def isclose(a: float, b: float, rtol: float) -> bool:
    """np.isclose(a, b, rtol, atol=1e-300) for finite scalars (messages carry finite numbers only),
    without numpy's per-call cost: it runs for every node at every step."""
    return abs(a - b) <= 1e-300 + rtol * abs(b)


def state_mismatch(n: NodeConfig, st: NodeState, tr: Truth) -> str | None:
    """Why ``st`` cannot be node n's own state computed from its true input (None: it can)."""
    i = n.id
    if (i in tr.y) == (st.innov is None):  # (the state says whether its node had a reading, as the truth does)
        return "state-not-from-input"
    if i not in tr.y and tr.step > 0 and n.estimator == SDP:
        return "state-without-reading"  # an SDP node publishes nothing at a later step without a reading (Scenario.silent_without_reading)
    if st.gamma != tr.gamma[i]:
        return "state-not-from-input"
    if i in tr.y and not isclose(st.innov, float(tr.y[i] - n.sensor.Cbar @ st.published.centre), INNOV_RTOL):  # type: ignore[arg-type]  # a reading: innov is set
        return "state-not-from-input"
    if (st.published.set is None) != (n.estimator == SDP):
        return "state-wrong-method"  # a set estimator publishes its set, the SDP none
    if (st.step == 0) != (st.status in ("init", "init-prior") or st.step == 0 and st.status == "no-reading"):
        return "state-not-prior"  # step 0 publishes the prior (updated by ỹ₀, where there is one), no other step does
    pub = st.published
    prior = st.status == "init-prior" or st.status == "no-reading" and st.step == 0 and n.estimator == SDP
    if prior and (pub.rho != n.rho or not np.array_equal(pub.xhat, n.x0_hat) or not np.array_equal(pub.P_matrix, n.P0)):
        return "state-not-prior"
    return None


class Judge:
    """The verdicts of one scenario's node-steps (module doc)."""

    def __init__(self, scenario: Scenario) -> None:
        self.sc = scenario
        self.node_cfg = {n.id: n for n in scenario.nodes}
        self.references = set(scenario.references())  # whose readings rest on their declared zero fault
        self.bounded = {n.id: set(scenario.bounded_sources(n.id)) for n in scenario.nodes}  # i → whose readings i uses with their declared bound
        # nodes running a set estimator whose guarantee also rests on the declared fault bound (its cone)
        # (an SDP node whose reading others use with its declared bound rests on it at every step too: docs/network.md)
        self.needs_fault_bound = {
            n.id
            for n in scenario.nodes
            if (n.estimator != SDP and "fault_bound" in node_set_estimator(scenario, n.id).assumptions) or (n.estimator == SDP and scenario.bound_relied(n.id))
        }

    def step(self, inp: StepInputs, prev: StepChecks) -> StepVerdict:
        """Every node's verdict of one closed step, and the copy checks its successor judges inputs by."""
        tr = inp.truth
        sets = None if tr is None else StepSets(tr)
        digests = {id(c): state_digest(c) for copies in inp.copies.values() for c in copies}  # (a judged state is one of them)
        checks = StepChecks(
            {j: {digests[id(c)]: self.copy_check(j, c, tr, sets) for c in copies} for j, copies in inp.copies.items()},
            {i: digests.get(id(st)) or state_digest(st) for i, st in inp.judged.items() if i not in inp.contested},
            self._held_over(inp, prev),
            {i: st for i, st in inp.judged.items() if i not in inp.contested},
        )
        out = {}
        for n in self.sc.nodes:
            st = inp.judged.get(n.id)
            judged = st is not None and tr is not None and tr.reference and n.id not in inp.contested
            alone = st is not None and tr is not None and not tr.reference and n.id not in inp.contested  # nothing but its own data to go by
            out[n.id] = NodeVerdict(
                n.id,
                inp.step,
                self.cone(n, inp, checks, prev),
                self.containment(n.id, st, tr, sets) if judged else None,  # type: ignore[arg-type]  # judged: st and tr are set
                alone and self.inconsistent(n, prev.states.get(n.id), inp.prev_truth, tr),  # type: ignore[arg-type]  # alone: tr is set
            )
        return StepVerdict(out, checks)

    def inconsistent(self, n: NodeConfig, before: NodeState | None, prev: Truth | None, tr: Truth) -> bool:
        """Node n's reading of this step is impossible under its declared bounds (noise; wind, model mismatch and fault
        bound across the transition) and its own set of the step before (step 0: its prior, Assumption 1): a certain
        broken assumption, or an earlier set that missed the truth, proven from the node's own data with no reference.

        The reading leaves r = C̄ x̄ in :func:`~netsetest.estimator.sector.measurement_interval`; the node's set of
        the step before, carried through the transition (its ellipsoid, a superset of the set: every detection stays
        certain), leaves it in :meth:`~netsetest.estimator.sector.Propagation.interval`; disjoint (beyond rounding):
        inconsistent.  Without a declared fault bound the fault is free and any reading after step 0 is possible."""
        k, sen = tr.step, n.sensor
        if n.id not in tr.y:
            return False
        bound = FaultBound(n.fault_rate, n.fault_size)
        if k == 0:
            pred = prior_interval(sen, bound, n.x0_hat, n.P0, n.rho)
        elif before is None or before.step != k - 1 or prev is None or prev.step != k - 1:
            return False  # nothing of the node's own to carry: no check
        else:
            e = before.continued
            a, b, d = self.sc.model.blend(self.sc.model.weights(prev.vx))
            pred = Propagation(np.asarray(e.xhat), e.P_matrix, e.rho, a, b[:, 0], d[:, 0], prev.u, self.sc.W, self.sc.uncertainty).interval(sen, bound)
        meas = measurement_interval(sen, tr.y[n.id], tr.gamma[n.id])
        slack = CONSISTENCY_RTOL * max(1.0, abs(pred.lo) if math.isfinite(pred.lo) else 0.0, abs(pred.hi) if math.isfinite(pred.hi) else 0.0)
        return meas.hi < pred.lo - slack or meas.lo > pred.hi + slack

    def _held_over(self, inp: StepInputs, prev: StepChecks) -> dict[int, HeldOver]:
        """Every node that sent nothing at this step: its last step's copy checks, and the transition into this
        step added to what broke since (a node silent for other reasons is carried too: bounded by the nodes)."""
        out = {}
        for i in self.node_cfg:
            if inp.copies.get(i):
                continue
            base = prev.held.get(i) or (HeldOver(inp.step - 1, prev.copies[i]) if i in prev.copies else None)
            if base is not None:
                out[i] = HeldOver(base.step, base.copies, base.broken or transition_cause(inp))
        return out

    @staticmethod
    def containment(i: int, st: NodeState, tr: Truth, sets: StepSets | None = None) -> Containment:
        """The state's published set and the set it continues from against the truth (ProvenSet.contains); E is the
        published ellipsoid's (a set estimator's: the one around its set, its neighbour-facing summary).  Needs no
        scenario: ``watch`` and the live view (runtime/live.py) judge what they hear by it, the collector's rule.
        ``sets``: the step's (:meth:`step`: what the copy checks computed already)."""
        sets = sets or StepSets(tr)
        pub = st.published
        bounds = None if pub.is_ellipsoid else np.stack(pub.bounds(), axis=1)
        box = truth_box(tr, i)
        if box is not None:  # a recorded drive's reference: the set against the whole box (proven.ProvenSet.relation)
            rel, cont = sets.relations(i, st, box)
            return Containment(pub.E_max(*box), rel == "inside", cont == "inside", bounds, rel == "disjoint", cont == "disjoint")
        E, inside, continues = sets.point(i, st)
        return Containment(E, inside, continues, bounds, not inside, not continues)

    def sector_premise(self, n: NodeConfig, st: NodeState | None, tr: Truth) -> bool:
        """What the node's step sector rests on held: nothing more than the noise bound (measurement),
        the declared fault bound (fault-bound), or the sector itself against the truth (assumed); without
        a judged state, the profile's fixed sector."""
        if not n.sensor.saturated:
            return True
        if st is None:
            return tr.sector_ok[n.id]
        if st.sector_basis == "assumed":
            return sector_ok(n.sensor, published_sector(st), tr.r[n.id])
        if st.sector_basis == "fault-bound":
            return tr.fault_ok[n.id]
        return True

    def sector_failed(self, i: int, st: NodeState, tr: Truth | None, covered: bool) -> bool:
        """A derived sector (measurement or fault-bound basis) missing the truth's C̄ x̄ although its
        premises held: an estimator bug."""
        n = self.node_cfg[i]
        if tr is None or not covered or not n.sensor.saturated or st.sector_basis in ("none", "assumed"):
            return False
        return not sector_ok(n.sensor, published_sector(st), tr.r[i])

    def copy_check(self, j: int, c: NodeState, tr: Truth | None, sets: StepSets | None = None) -> CopyCheck:
        """One copy of node j's state of a step, judged as an input of a later step (``sets``: the step's, shared with the
        containment of the judged copy)."""
        if tr is None:
            return CopyCheck(TRUTH_UNKNOWN, TRUTH_UNKNOWN, TRUTH_UNKNOWN)
        if not tr.reference:
            return CopyCheck(NO_REFERENCE, NO_REFERENCE, NO_REFERENCE)
        n = self.node_cfg[j]
        if state_mismatch(n, c, tr):
            return CopyCheck(NOT_FROM_INPUT, NOT_FROM_INPUT, NOT_FROM_INPUT)
        facts = None
        if not tr.noise_ok[j]:
            facts = "noise"
        elif n.sensor.saturated and not (j in tr.r and sector_ok(n.sensor, published_sector(c), tr.r[j])):
            facts = "sector"
        sets = sets or StepSets(tr)
        box = truth_box(tr, j)
        if box is None:
            E, inside, continues = sets.point(j, c)
            published_in: str | None = None if E <= c.published.rho else MISSED  # neighbours use the ellipsoid alone
            prior_in: str | None = None if continues else MISSED
            set_in: str | None = None if inside else MISSED
        else:  # held only where all of the reference's box lies in it; proven apart: missed; else it may have missed
            rel, cont = sets.relations(j, c, box)
            published_in = _held(relation(c.published.ellipsoid_only(), tr, j, box))
            prior_in, set_in = _held(cont), _held(rel)
        self_loop = j in n.in_weights  # its own innovation enters its next step: the same facts
        return CopyCheck(
            as_neighbour=facts or published_in,
            as_prior=(facts if self_loop else None) or prior_in,
            as_set=set_in,
        )

    def own_cause(self, n: NodeConfig, st: NodeState | None, tr: Truth, prev: Truth | None, k: int, prev_overloaded: bool = False) -> str | None:
        """The first of the step's own assumptions that broke (None: all held); the plant's transition first,
        as the cause a user acts on (recalibrate, or drive inside the envelope: docs/plant.md).  Without the
        previous truth the transition is unknown: the collector's own overload where it closed that step
        unjudged (``prev_overloaded``), else truth unknown."""
        rejoin = st is not None and st.status == "rejoin"  # no transition crossed (below)
        if k > 0 and prev is not None and prev.step == k - 1 and not prev.mismatch_ok and not rejoin:
            return mismatch_cause(prev)
        own = self._measurement_cause(n, st, tr, k)
        if own is not None:
            return own
        if k == 0:
            return None if _in_prior(n, tr) else "initial set"
        if rejoin:
            return None  # built from the neighbours' sets of this very step: no transition crossed
        return _transition_cause(prev, k, prev_overloaded)

    def _measurement_cause(self, n: NodeConfig, st: NodeState | None, tr: Truth, k: int) -> str | None:
        """The first of the step's measurement assumptions that broke: the sector, the noise bound, the declared fault
        bound where the step rests on it (None: they held)."""
        read = n.id in tr.y  # without a reading no measurement, so no noise bound or sector, enters the step
        if read and not self.sector_premise(n, st, tr):
            return "sector"
        if read and not tr.noise_ok[n.id]:
            return "noise"
        # a set estimator's step > 0 without a reading carries its fault by the declared bound alone (estimator/base.py)
        if (n.id in self.needs_fault_bound or not read and k > 0 and n.estimator != SDP) and not tr.fault_ok.get(n.id, False):
            return "fault bound"
        return None

    def cone(self, n: NodeConfig, inp: StepInputs, checks: StepChecks, prev: StepChecks) -> Cone:
        """Whether node-step (n, k) is covered: its own assumptions held and every input it used was judged
        and held the truth (one step deep, over judged inputs: docs/coverage.md)."""
        i, k, tr = n.id, inp.step, inp.truth
        if tr is None:
            return Cone(False, TRUTH_UNKNOWN)
        if not tr.reference:
            return Cone(False, NO_REFERENCE)
        st = inp.judged.get(i)
        own = self.own_cause(n, st, tr, inp.prev_truth, k, inp.prev_overloaded)
        if own is not None:
            return Cone(False, own)
        if st is None or k == 0:
            return Cone(True)
        for j, y, gamma in st.readings:  # the readings of this very step
            why = self.reading_cause(j, y, gamma, tr, j in self.bounded[i])
            if why is not None:
                return Cone(False, INHERITED, Origin(j, k, why))
        if st.health and not self.sc.group_health_holds(i, inp.faults):
            return Cone(False, HEALTH)  # its group's k-of-N interval rested on more healthy sensors than there were
        if st.status == "fallback" and st.published.set is not None:
            return Cone(False, "fallback")  # the previous step's set again: no guarantee for this step
        for j, m, digest, as_prior in _inputs_of(st, k):
            if m < k - 1:  # a resumed state: its own set of step m, carried through the steps without a reading
                broken = _resumed_input_cause(prev, j, m, digest)
            else:
                broken = _input_cause(checks if m == k else prev, j, m, digest, as_prior, j in st.sets)
            if broken is not None:
                return broken
        return Cone(True)

    def reading_cause(self, j: int, y: float, gamma: float, tr: Truth, bounded: bool = False) -> str | None:
        """Why node j's reading of the step gives no guarantee (None: it is the true measurement, its noise
        bound held and, for a reference, its declared fault-free sensor had no fault; ``bounded``: the reader may
        use it with j's declared fault bound, which then held too)."""
        if j not in tr.y or y != tr.y[j] or gamma != tr.gamma[j]:
            return NOT_FROM_INPUT
        if not tr.noise_ok[j]:
            return "noise"
        if (j in self.references or bounded) and not tr.fault_ok.get(j, False):
            return "fault bound"  # its declared size 0, or the bound its reader used it with
        return None


def _ids(nodes: list[int]) -> str:
    return ", ".join(map(str, nodes))


def network_rests(sc: Scenario, i: int) -> str:
    """What node i's sets may rest on beyond its own data and its neighbours' innovations, in words (the run's header;
    docs/network.md): the readings it uses and the declaration each rests on, its in-neighbours' whole published sets,
    and its own declared bound where other nodes rely on it.  "" where nothing."""
    n = sc.node(i)
    if n.estimator != SDP:  # a set estimator uses the references' and its group's readings, no neighbour
        read = list(sc.reading_sources(i, bounded=False))
        return f"the readings of {_ids(read)}" if read else ""
    refs = [j for j in sc.reading_sources(i) if j in sc.references()]
    group = sc.health_group(i)
    members = [j for j in sc.reading_sources(i) if group is not None and j in group.nodes]
    bounded = [j for j in sc.bounded_sources(i) if j not in refs]
    parts = []
    if refs:
        parts.append(f"the reading of {_ids(refs)} (fault-free)")
    if group is not None:
        parts.append(f"k-of-N health of {_ids(list(group.nodes))} (max_faulty {group.max_faulty}; readings of {_ids(members) or 'none'})")
    if bounded:
        parts.append(f"the readings of {_ids(bounded)} with their declared fault bounds")
    if sc.neighbour_sets and not sc.reads_everyone(i):
        sets = [j for j in n.in_weights if j != i]
        if sets:
            parts.append(f"the published sets of {_ids(sets)}")
    if sc.bound_relied(i):
        parts.append("its own declared fault bound (others read its reading with it)")
    return "; ".join(parts)


def _resumed_input_cause(prev: StepChecks, j: int, m: int, digest: str | None) -> Cone | None:
    """Why node j's own set of step m, which a resumed state carried through the steps without a reading, is no
    covered input (None: that very copy was judged at m and held, and nothing broke while it was carried)."""
    held = prev.held.get(j)
    c = held.copies.get(digest) if held is not None and held.step == m and digest is not None else None
    why = NOT_JUDGED if c is None else c.as_prior
    if why is None and held is not None and held.broken is not None:
        return Cone(False, held.broken)
    return None if why is None else Cone(False, INHERITED, Origin(j, m, why))


def _input_cause(by: StepChecks, j: int, m: int, digest: str | None, as_prior: bool, as_set: bool = False) -> Cone | None:
    """Why node j's state of step m, used as the node's prior (``as_prior``) or as a neighbour's set, is no covered
    input (None: the copy it names, or j's sole judged copy where it names none, was judged in ``by`` and held;
    ``as_set``: the state's region was cut by that whole set (``NodeState.sets``), which must have held too)."""
    if digest is None:
        digest = by.sole.get(j)
    c = by.copies.get(j, {}).get(digest) if digest is not None else None
    why = NOT_JUDGED if c is None else (c.as_prior if as_prior else c.as_neighbour or (c.as_set if as_set else None))
    return None if why is None else Cone(False, INHERITED, Origin(j, m, why))


def _held(rel: str) -> str | None:
    """A copy's set against a reference's box, as an input's check: held (None), missed or undecided."""
    return None if rel == "inside" else MISSED if rel == "disjoint" else UNDECIDED


def transition_cause(inp: StepInputs) -> str | None:
    """The first assumption that broke on the transition into ``inp``'s step (the model mismatch, then the wind;
    None: neither did); unknown without the previous step's truth."""
    prev = inp.prev_truth
    if prev is None or prev.step != inp.step - 1:
        return COLLECTOR_OVERLOADED if inp.prev_overloaded else TRUTH_UNKNOWN
    if not prev.mismatch_ok:
        return mismatch_cause(prev)
    return None if prev.dist_ok else "disturbance"


def mismatch_cause(t: Truth | dict) -> str:
    """Why a transition's e_k left its bound: the car outside the declared envelope, or the bound too small."""
    ok = t.get("envelope_ok", True) if isinstance(t, dict) else t.envelope_ok
    return MODEL_MISMATCH if ok else OUTSIDE_ENVELOPE


def _inputs_of(st: NodeState, k: int) -> list[tuple[int, int, str | None, bool]]:
    """(node, step, digest, whether it is the node's own prior) of every input of the step; digest None:
    a state from before digests, whose inputs are its neighbours' sole judged copies (and its own)."""
    m = k if st.status == "rejoin" else st.resumed_from if st.resumed_from is not None else k - 1
    if st.inputs:
        return [(j, m, d, j == st.node) for j, d in st.inputs]
    deps: list[tuple[int, int, str | None, bool]] = [(j, m, None, False) for j in st.used]
    return deps if st.status == "rejoin" else [*deps, (st.node, m, None, True)]


def history_cone(sc: Scenario, truth: list[dict], node: int, fault_bound: bool) -> list[str | None]:
    """Per step of a recorded run (``truth``: its truth entries in step order), for an exact limit of one
    node's data: None where every assumption of the whole history held, else the first broken one (an exact
    limit uses every datum up to the step, so its cone is never one step deep)."""
    n = sc.node(node)
    e = np.r_[truth[0]["x"], truth[0]["faults"][node]] - n.x0_hat
    broken: str | None = None if float(e @ np.linalg.solve(n.P0, e)) <= n.rho else "prior"
    out: list[str | None] = []
    for k, t in enumerate(truth):
        if broken is None and k > 0 and not truth[k - 1].get("mismatch_ok", True):
            broken = mismatch_cause(truth[k - 1])  # every estimator uses the declared bound on e_k (docs/plant.md)
        if broken is None and k > 0 and not truth[k - 1]["dist_ok"]:
            broken = "disturbance"
        if broken is None and not t["noise_ok"][node]:
            broken = "noise"
        if broken is None and fault_bound and not t.get("fault_ok", {}).get(node, True):
            broken = "fault_bound"
        out.append(broken)
    return out


__all__ = [
    "HEALTH",
    "INHERITED",
    "MISSED",
    "MODEL_MISMATCH",
    "NO_REFERENCE",
    "NOT_FROM_INPUT",
    "NOT_JUDGED",
    "NO_CHECKS",
    "OUTSIDE_ENVELOPE",
    "TRUTH_UNKNOWN",
    "UNDECIDED",
    "COLLECTOR_OVERLOADED",
    "Cone",
    "Containment",
    "CopyCheck",
    "Judge",
    "NodeVerdict",
    "Origin",
    "StepChecks",
    "StepInputs",
    "StepSets",
    "StepVerdict",
    "history_cone",
    "isclose",
    "mismatch_cause",
    "network_rests",
    "published_sector",
    "state_mismatch",
    "truth_box",
]
