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

from dataclasses import dataclass

import numpy as np

from netsetest.config.schema import NodeConfig, Scenario
from netsetest.estimator.names import SDP
from netsetest.estimator.registry import node_set_estimator
from netsetest.estimator.sector import Sector, sector_ok
from netsetest.messages import NodeState, Truth, state_digest
from netsetest.models.envelope import MODEL_MISMATCH, OUTSIDE_ENVELOPE
from netsetest.models.sensor import augmented

INNOV_RTOL = 1e-12  # the node computes ỹ − C̄ x̂ with the same numbers: rounding only across machines

# why an input of a node-step gives it no guarantee (docs/coverage.md)
TRUTH_UNKNOWN = "truth unknown"  # no single consistent truth of that step: nothing can be judged
COLLECTOR_OVERLOADED = "collector overloaded"  # the step before was closed unjudged for the collector's own loss
NOT_FROM_INPUT = "not from its true input"  # its γ or innovation is not what the true measurement gives
MISSED = "missed the truth"
NOT_JUDGED = "not judged"  # no copy with that digest reached the collector, or several matched the truth
HEALTH = "k-of-N health"  # more than [network] max_faulty sensors faulty at a step whose set used it (docs/network.md)
INHERITED = "inherited"  # the cause of a node-step whose input failed: its Origin says which and why


@dataclass(frozen=True)
class CopyCheck:
    """One copy of a node's state of a closed step, as an input of a later step: None where every fact a
    step takes from it held, else why not."""

    as_neighbour: str | None  # its published set held the truth; its innovation's noise and sector facts held
    as_prior: str | None  # the set its node continues from held the truth (self-loop: and those facts)


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
    """A judged state against its step's truth: E = eᵀP⁻¹e of its ellipsoid, whether its set holds the truth,
    whether the set its node continues from does (the same set unless the state sends ``continues``),
    and the set's per-coordinate bounds (3, 2) where it is not the ellipsoid alone (a set estimator's set, or
    the SDP's ellipsoid ∩ its fault range; None: the ellipsoid's)."""

    E: float
    contained: bool
    continues_contained: bool
    bounds: np.ndarray | None = None

    @property
    def held(self) -> bool:
        """Both sets of the step hold the truth: on a covered node-step anything else is a violation."""
        return self.contained and self.continues_contained


@dataclass(frozen=True)
class StepChecks:
    """What a step leaves for the next one to judge its inputs by: every copy's check, and each node's sole
    judged copy (for states from before digests)."""

    copies: dict[int, dict[str, CopyCheck]]
    sole: dict[int, str]


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


@dataclass(frozen=True)
class StepVerdict:
    nodes: dict[int, NodeVerdict]
    checks: StepChecks  # for the next step's inputs


def published_sector(st: NodeState) -> Sector | None:
    return Sector(st.sector[0], st.sector[1], st.sector_basis) if st.sector is not None else None


def _in_prior(n: NodeConfig, tr: Truth) -> bool:
    """Assumption 1: the true x̄_0 lies in node n's prior ellipsoid."""
    e = augmented(tr.x, tr.faults[str(n.id)]) - n.x0_hat
    return float(e @ np.linalg.solve(n.P0, e)) <= n.rho


def isclose(a: float, b: float, rtol: float) -> bool:
    """np.isclose(a, b, rtol, atol=1e-300) for finite scalars (messages carry finite numbers only),
    without numpy's per-call cost: it runs for every node at every step."""
    return abs(a - b) <= 1e-300 + rtol * abs(b)


def state_mismatch(n: NodeConfig, st: NodeState, tr: Truth) -> str | None:
    """Why ``st`` cannot be node n's own state computed from its true input (None: it can)."""
    s = str(n.id)
    if st.gamma != tr.gamma[s]:
        return "state-not-from-input"
    innov = float(tr.y[s] - n.sensor.Cbar @ st.published.centre)
    if not isclose(st.innov, innov, INNOV_RTOL):
        return "state-not-from-input"
    if (st.published.set is None) != (n.estimator == SDP):
        return "state-wrong-method"  # a set estimator publishes its set, the SDP none
    if (st.step == 0) != (st.status in ("init", "init-prior")):
        return "state-not-prior"  # step 0 publishes the prior (updated by ỹ₀), no other step does
    pub = st.published
    if st.status == "init-prior" and (pub.rho != n.rho or not np.array_equal(pub.xhat, n.x0_hat) or not np.array_equal(pub.P_matrix, n.P0)):
        return "state-not-prior"
    return None


class Judge:
    """The verdicts of one scenario's node-steps (module doc)."""

    def __init__(self, scenario: Scenario) -> None:
        self.sc = scenario
        self.node_cfg = {n.id: n for n in scenario.nodes}
        self.references = set(scenario.references())  # whose readings rest on their declared zero fault
        # nodes running a set estimator whose guarantee also rests on the declared fault bound (its cone)
        self.needs_fault_bound = {n.id for n in scenario.nodes if n.estimator != SDP and "fault_bound" in node_set_estimator(scenario, n.id).assumptions}

    def step(self, inp: StepInputs, prev: StepChecks) -> StepVerdict:
        """Every node's verdict of one closed step, and the copy checks its successor judges inputs by."""
        tr = inp.truth
        checks = StepChecks(
            {j: {state_digest(c): self.copy_check(j, c, tr) for c in copies} for j, copies in inp.copies.items()},
            {i: state_digest(st) for i, st in inp.judged.items() if i not in inp.contested},
        )
        out = {}
        for n in self.sc.nodes:
            st = inp.judged.get(n.id)
            judged = st is not None and tr is not None and n.id not in inp.contested
            out[n.id] = NodeVerdict(
                n.id,
                inp.step,
                self.cone(n, inp, checks, prev),
                self.containment(n.id, st, tr) if judged else None,  # type: ignore[arg-type]  # judged: st and tr are set
            )
        return StepVerdict(out, checks)

    @staticmethod
    def containment(i: int, st: NodeState, tr: Truth) -> Containment:
        """The state's published set and the set it continues from against the truth (ProvenSet.contains); E is the
        published ellipsoid's (a set estimator's: the one around its set, its neighbour-facing summary).  Needs no
        scenario: ``watch`` and the live view (runtime/live.py) judge what they hear by it, the collector's rule."""
        xbar = augmented(tr.x, tr.faults[str(i)])
        pub = st.published
        E = pub.E(xbar)
        inside = pub.contains(xbar, E)
        continues = inside if st.continues is None else st.continued.contains(xbar)
        return Containment(E, inside, continues, None if pub.is_ellipsoid else np.stack(pub.bounds(), axis=1))

    def sector_premise(self, n: NodeConfig, st: NodeState | None, tr: Truth) -> bool:
        """What the node's step sector rests on held: nothing more than the noise bound (measurement),
        the declared fault bound (fault-bound), or the sector itself against the truth (assumed); without
        a judged state, the profile's fixed sector."""
        s = str(n.id)
        if not n.sensor.saturated:
            return True
        if st is None:
            return tr.sector_ok[s]
        if st.sector_basis == "assumed":
            return sector_ok(n.sensor, published_sector(st), tr.r[s])
        if st.sector_basis == "fault-bound":
            return tr.fault_ok[s]
        return True

    def sector_failed(self, i: int, st: NodeState, tr: Truth | None, covered: bool) -> bool:
        """A derived sector (measurement or fault-bound basis) missing the truth's C̄ x̄ although its
        premises held: an estimator bug."""
        n = self.node_cfg[i]
        if tr is None or not covered or not n.sensor.saturated or st.sector_basis in ("none", "assumed"):
            return False
        return not sector_ok(n.sensor, published_sector(st), tr.r[str(i)])

    def copy_check(self, j: int, c: NodeState, tr: Truth | None) -> CopyCheck:
        """One copy of node j's state of a step, judged as an input of a later step."""
        if tr is None:
            return CopyCheck(TRUTH_UNKNOWN, TRUTH_UNKNOWN)
        n, s = self.node_cfg[j], str(j)
        if state_mismatch(n, c, tr):
            return CopyCheck(NOT_FROM_INPUT, NOT_FROM_INPUT)
        facts = None
        if not tr.noise_ok[s]:
            facts = "noise"
        elif n.sensor.saturated and not (s in tr.r and sector_ok(n.sensor, published_sector(c), tr.r[s])):
            facts = "sector"
        xbar = augmented(tr.x, tr.faults[s])
        published_in = c.published.E(xbar) <= c.published.rho  # neighbours use the ellipsoid alone
        prior_in = c.continued.contains(xbar)
        self_loop = j in n.in_weights  # its own innovation enters its next step: the same facts
        return CopyCheck(
            as_neighbour=facts or (None if published_in else MISSED),
            as_prior=(facts if self_loop else None) or (None if prior_in else MISSED),
        )

    def own_cause(self, n: NodeConfig, st: NodeState | None, tr: Truth, prev: Truth | None, k: int, prev_overloaded: bool = False) -> str | None:
        """The first of the step's own assumptions that broke (None: all held); the plant's transition first,
        as the cause a user acts on (recalibrate, or drive inside the envelope: docs/plant.md).  Without the
        previous truth the transition is unknown: the collector's own overload where it closed that step
        unjudged (``prev_overloaded``), else truth unknown."""
        s = str(n.id)
        rejoin = st is not None and st.status == "rejoin"  # no transition crossed (below)
        if k > 0 and prev is not None and prev.step == k - 1 and not prev.mismatch_ok and not rejoin:
            return mismatch_cause(prev)
        if not self.sector_premise(n, st, tr):
            return "sector"
        if not tr.noise_ok[s]:
            return "noise"
        if n.id in self.needs_fault_bound and not tr.fault_ok.get(s, False):
            return "fault bound"
        if k == 0:
            return None if _in_prior(n, tr) else "initial set"
        if st is not None and st.status == "rejoin":
            return None  # built from the neighbours' sets of this very step: no transition crossed
        if prev is None or prev.step != k - 1:
            return COLLECTOR_OVERLOADED if prev_overloaded else TRUTH_UNKNOWN
        if not prev.dist_ok:
            return "disturbance"
        return None

    def cone(self, n: NodeConfig, inp: StepInputs, checks: StepChecks, prev: StepChecks) -> Cone:
        """Whether node-step (n, k) is covered: its own assumptions held and every input it used was judged
        and held the truth (one step deep, over judged inputs: docs/coverage.md)."""
        i, k, tr = n.id, inp.step, inp.truth
        if tr is None:
            return Cone(False, TRUTH_UNKNOWN)
        st = inp.judged.get(i)
        own = self.own_cause(n, st, tr, inp.prev_truth, k, inp.prev_overloaded)
        if own is not None:
            return Cone(False, own)
        if st is None or k == 0:
            return Cone(True)
        for j, y, gamma in st.readings:  # the readings of this very step
            why = self.reading_cause(j, y, gamma, tr)
            if why is not None:
                return Cone(False, INHERITED, Origin(j, k, why))
        if st.health and not self.sc.group_health_holds(i, inp.faults):
            return Cone(False, HEALTH)  # its group's k-of-N interval rested on more healthy sensors than there were
        if st.status == "fallback" and st.published.set is not None:
            return Cone(False, "fallback")  # the previous step's set again: no guarantee for this step
        for j, m, digest, as_prior in _inputs_of(st, k):
            by = checks if m == k else prev
            if digest is None:
                digest = by.sole.get(j)
            c = by.copies.get(j, {}).get(digest) if digest is not None else None
            why = NOT_JUDGED if c is None else (c.as_prior if as_prior else c.as_neighbour)
            if why is not None:
                return Cone(False, INHERITED, Origin(j, m, why))
        return Cone(True)

    def reading_cause(self, j: int, y: float, gamma: float, tr: Truth) -> str | None:
        """Why node j's reading of the step gives no guarantee (None: it is the true measurement, its noise
        bound held and, for a reference, its declared fault-free sensor had no fault)."""
        s = str(j)
        if s not in tr.y or y != tr.y[s] or gamma != tr.gamma[s]:
            return NOT_FROM_INPUT
        if not tr.noise_ok[s]:
            return "noise"
        if j in self.references and not tr.fault_ok.get(s, False):
            return "fault bound"  # its declared size 0
        return None


def mismatch_cause(t: Truth | dict) -> str:
    """Why a transition's e_k left its bound: the car outside the declared envelope, or the bound too small."""
    ok = t.get("envelope_ok", True) if isinstance(t, dict) else t.envelope_ok
    return MODEL_MISMATCH if ok else OUTSIDE_ENVELOPE


def _inputs_of(st: NodeState, k: int) -> list[tuple[int, int, str | None, bool]]:
    """(node, step, digest, whether it is the node's own prior) of every input of the step; digest None:
    a state from before digests, whose inputs are its neighbours' sole judged copies (and its own)."""
    m = k if st.status == "rejoin" else k - 1
    if st.inputs:
        return [(j, m, d, j == st.node) for j, d in st.inputs]
    deps: list[tuple[int, int, str | None, bool]] = [(j, m, None, False) for j in st.used]
    return deps if st.status == "rejoin" else [*deps, (st.node, m, None, True)]


def history_cone(sc: Scenario, truth: list[dict], node: int, fault_bound: bool) -> list[str | None]:
    """Per step of a recorded run (``truth``: its truth entries in step order), for an exact limit of one
    node's data: None where every assumption of the whole history held, else the first broken one (an exact
    limit uses every datum up to the step, so its cone is never one step deep)."""
    n, s = sc.node(node), str(node)
    e = np.r_[truth[0]["x"], truth[0]["faults"][s]] - n.x0_hat
    broken: str | None = None if float(e @ np.linalg.solve(n.P0, e)) <= n.rho else "prior"
    out: list[str | None] = []
    for k, t in enumerate(truth):
        if broken is None and k > 0 and not truth[k - 1].get("mismatch_ok", True):
            broken = mismatch_cause(truth[k - 1])  # every estimator uses the declared bound on e_k (docs/plant.md)
        if broken is None and k > 0 and not truth[k - 1]["dist_ok"]:
            broken = "disturbance"
        if broken is None and not t["noise_ok"][s]:
            broken = "noise"
        if broken is None and fault_bound and not t.get("fault_ok", {}).get(s, True):
            broken = "fault_bound"
        out.append(broken)
    return out


__all__ = [
    "HEALTH",
    "INHERITED",
    "MISSED",
    "MODEL_MISMATCH",
    "NOT_FROM_INPUT",
    "NOT_JUDGED",
    "NO_CHECKS",
    "OUTSIDE_ENVELOPE",
    "TRUTH_UNKNOWN",
    "COLLECTOR_OVERLOADED",
    "Cone",
    "Containment",
    "CopyCheck",
    "Judge",
    "NodeVerdict",
    "Origin",
    "StepChecks",
    "StepInputs",
    "StepVerdict",
    "history_cone",
    "isclose",
    "mismatch_cause",
    "published_sector",
    "state_mismatch",
]
