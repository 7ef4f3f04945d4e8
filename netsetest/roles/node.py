"""The node role: one yaw-rate sensing node running its local estimator.

At step k+1 node i needs its :class:`NodeInput` of step k+1 (ỹ_i,k+1, γ_i,k+1, u_k, Vx_k) and the
step-k states of the in-neighbours the vehicle told it to expect.  A neighbour message that is
scheduled lost, or has not arrived when the runtime gives up waiting, is left out of the step and its
η slots are zeroed (the guarantee holds with the neighbours that did arrive).  Node i never sees the
truth.  decode() has already checked types, sizes and the shape; every message is then checked in
context and dropped and counted by reason otherwise, never repaired:

- anything naming a step after the run or a node the topology does not have (:class:`RunScope`);
- an input not for us, not ahead of our step, further ahead than ``MAX_AHEAD``, a second copy of a
  step (the first counts), or with values the scenario rules out (speed, steering, γ range, unknown
  neighbours, no u/Vx after step 0);
- a neighbour state not from a real in-neighbour on its own key, stale, too far ahead, a second copy,
  or one that cannot be honest (:mod:`netsetest.roles.plausibility`: an innovation its own ellipsoid and
  noise bound cannot produce, or a (β, r) set disjoint from our own certified one of that step);
- a reference's reading (the same-step exchange phase, docs/network.md) not from a reference on its own
  key, for a step we have already taken, a second copy, or with a γ the scenario rules out;
- an End not naming the scheduled last step; one that arrives before we published that step is
  counted (``end-early``) and takes effect only once we have.

A reference node publishes its reading of a step as soon as it has the step's input, before it
estimates; an SDP node waits for the references' readings of its next step (bounded like neighbour
states) and, when one is here, its update uses them instead of its neighbours' states of the previous
step (estimator/sdp.py).

Buffers are bounded: at most ``MAX_AHEAD`` steps of inputs and of neighbour states, one per sender.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any
from collections import Counter

import numpy as np

from netsetest.bus import keys
from netsetest.bus.base import Bus
from netsetest.config.schema import Scenario
from netsetest.estimator import base
from netsetest.estimator.names import SDP
from netsetest.estimator.objective import DEFAULT_OBJECTIVE
from netsetest.estimator.registry import node_set_estimator
from netsetest.polygon import Polygon
from netsetest.estimator.rejoin import predict_x, rejoin_ellipsoid, resume_ellipsoid
from netsetest.estimator.sdp import NodeSet, LocalEstimator, NeighbourState, Objective, Prepared, UpdateInput, StepFigures, StepResult, StepSet, Variant
from netsetest.estimator.sector import FaultBound, Interval, Sector, derive_sector, measurement_interval
from netsetest.messages import End, Message, NodeInput, NodeState, NodeStatus, Reading, RunScope, decode, encode, state_digest
from netsetest.models.sensor import NA, NX
from netsetest.roles.plausibility import innovation_possible, states_disjoint
from netsetest.sets import NO_CUTS, RegionSet, set_to_wire


MAX_AHEAD = 50  # steps ahead of our own: more is a corrupt or hostile message (bounds the buffers)
GAMMA_RTOL = 1e-12  # γ = lo + (hi − lo)·rand may round a hair outside [lo, hi]
LATE_START_EVIDENCE = 3  # inputs of later steps and none of step 0: the run started without us, rejoin
BOX_WIDEN = 1e-9  # relative widening of a published set's interval hull: rounding of c ± h stays inside
MIN_HALF_WIDTH = 1e-12  # a flat coordinate of a set is widened to this, so the enclosing P is definite


def enclosing_ellipsoid(s: base.GuaranteedSet, rho: float) -> tuple[np.ndarray, np.ndarray]:
    """(x̂, P) with {x: (x − x̂)ᵀP⁻¹(x − x̂) ≤ ρ} ⊇ s: the ellipsoid through the corners of s's interval hull.

    Proof: with c the hull's centre, h its half-widths and P = n·diag(h²)/ρ (n = 3), every x of the hull
    has (x − c)ᵀP⁻¹(x − c) = ρ·Σ (x_i − c_i)²/(n h_i²) ≤ ρ·Σ 1/n = ρ.  h is widened (never narrowed) for
    rounding and flat coordinates.  Among the axis-aligned ellipsoids through the corners it is the one of
    minimum volume."""
    lo, hi = s.bounds()
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise base.EstimatorError("the set is unbounded: no ellipsoid encloses it")
    c = (lo + hi) / 2
    h = np.maximum((hi - lo) / 2 * (1 + BOX_WIDEN), MIN_HALF_WIDTH * np.maximum(1.0, np.abs(c)))
    return c, np.diag(NA * h**2 / rho)


def _symmetric(p: list[float]) -> np.ndarray:
    """The row-major 3×3 ``p`` made exactly symmetric, ½(P + Pᵀ), in plain floats: the same roundings as
    the arrays' (numpy's per-call cost on 3×3 was most of it, for every neighbour state a node keeps)."""
    p0, p1, p2, p3, p4, p5, p6, p7, p8 = p
    a01, a02, a12 = 0.5 * (p1 + p3), 0.5 * (p2 + p6), 0.5 * (p5 + p7)
    return np.array([[0.5 * (p0 + p0), a01, a02], [a01, 0.5 * (p4 + p4), a12], [a02, a12, 0.5 * (p8 + p8)]])


@dataclass(frozen=True)
class Publication:
    """What a node publishes for one step: ``res`` (kept as its own set) and what its state message says
    about how it was made."""

    inp: NodeInput
    status: NodeStatus
    res: StepResult
    used: list[int] = field(default_factory=list)  # neighbours whose states the step used
    missing: list[int] = field(default_factory=list)  # expected neighbours it went on without
    inputs: list[tuple[int, str]] = field(default_factory=list)  # (node, digest) of every state copy used
    wire_set: dict | None = None  # a set estimator's own set, on the wire
    readings: list[tuple[int, float, float]] = field(default_factory=list)  # (node, lo, hi) of the step
    health: bool = False  # the k-of-N health assumption was applied
    sets: list[int] = field(default_factory=list)  # in-neighbours whose published sets cut the step's sets
    resumed_from: int | None = None  # status "resume": the step of the own set it was carried from


@dataclass(frozen=True)
class Gap:
    """Steps without a reading (docs/your-log.md): the node's last published step ``since`` and that state's digest,
    and the x set its own set is carried to, {x: (x − xc)ᵀSx⁻¹(x − xc) ≤ 1} (estimator/rejoin.py)."""

    since: int
    digest: str
    xc: np.ndarray  # (NX,)
    Sx: np.ndarray  # (NX, NX)


class Node:
    def __init__(
        self,
        scenario: Scenario,
        node_id: int,
        bus: Bus,
        run_id: str,
        variant: Variant = "scheduled",
        rejoin: bool = False,
        objective: Objective = DEFAULT_OBJECTIVE,
        lazy: bool = False,
        early: bool = False,
    ) -> None:
        """``lazy``: neighbour states and readings do not wake the node: they are used when its next input
        arrives, which does wake it (a runtime waiting for one polls; netsetest/bus/base.py, runtime/processes.py).
        ``early``: while only a step's readings are missing, compute the part of the step they do not enter
        (:meth:`_prepare`; a process, whose readings cross the network: in memory there is no hop to overlap)."""
        self.sc, self.bus, self.run = scenario, bus, run_id
        self.cfg = scenario.node(node_id)
        self.id = node_id
        self.variant, self.objective = variant, objective
        self.others = [j for j in self.cfg.in_weights if j != node_id]
        self.sensors = {j: scenario.node(j).sensor for j in self.cfg.in_weights}  # looked up per message
        self.estimator = self._new_estimator()
        self.set_estimator: base.SetEstimator | None = None  # a non-SDP method (it ignores neighbours)
        self.last_set: base.GuaranteedSet | None = None  # its last published set
        if self.cfg.estimator != SDP:
            self.set_estimator = node_set_estimator(scenario, node_id)
        self.publishes_reading = scenario.publishes_reading(node_id)  # a reference, or every node under max_faulty
        # the nodes whose reading of each step this node waits for and uses (its estimator must use them)
        uses = self.set_estimator is None or self.set_estimator.uses_readings
        self.read_from = (
            list(scenario.reading_sources(node_id, bounded=self.set_estimator is None)) if uses else []
        )  # (a set estimator uses no bounded reading)
        self.readings: dict[int, dict[int, tuple[float, float]]] = {}  # step → sender j → (ỹ_j, γ_j)
        # senders whose reading did not come before we gave up on it: not waited for until one arrives (a
        # dead reference must not cost every later step a timeout; a neighbour's state is not expected once
        # the vehicle stops hearing from it, but the vehicle says nothing of non-neighbours)
        self.silent: set[int] = set()
        # estimator state, plain arrays: centre, shape, radius, and our own last published message
        self.xhat = self.cfg.x0_hat.copy()
        self.P = self.cfg.P0.copy()
        self.region: Polygon | None = None  # the region of x the readings left (netsetest/polygon.py)
        self.region_without: frozenset[int] = frozenset()  # the readings the region was last cut without (cuts.Contradicted)
        self.rho = self.cfg.rho
        self.k = -1  # last published step
        self.own: NeighbourState | None = None
        self.inputs: dict[int, NodeInput] = {}
        self.inbox: dict[int, dict[int, NeighbourState]] = {}  # step → j → state
        self.digests: dict[int, dict[int, str]] = {}  # step → j → state_digest of the copy in the inbox
        self.own_digest: str | None = None  # of our last published state: the next step's prior
        self.screened: set[int] = set()  # neighbours whose state of screened_step was compared with our own set of it
        self.screened_step = -1
        # step → neighbours whose state of that step we dropped: it spoke, so it answers our wait (it is
        # left out of the step, which is always sound) — else we would wait the neighbour timeout for it
        self.refused: dict[int, set[int]] = {}
        self.waiting_since: float | None = None
        self.early = early
        self.prepared: tuple[int, Prepared] | None = None  # (step, the part of it its readings do not enter)
        self.give_up = False  # set by the runtime when the neighbour deadline passed
        self.ended = False
        self.end_seen = False  # the scheduled End arrived (perhaps before our last step)
        self.scope = RunScope(frozenset(scenario.ids), scenario.steps)
        self.drops: Counter[str] = Counter()
        self.rejoin = rejoin  # started into a running network: initialise from a neighbour's ellipsoid
        self.gap: Gap | None = None  # in steps without a reading: where the own set is carried (_carry)
        self.late_start_evidence = 0
        bus.subscribe(keys.node_input(run_id, node_id), self.on_message, screen=self._passed_input)
        for j in self.others:
            bus.subscribe(keys.node_state(run_id, j), self.on_message, lazy=lazy, screen=self._passed_state)
        for j in self.read_from:
            bus.subscribe(keys.reading(run_id, j), self.on_message, lazy=lazy, screen=self._passed_reading)
        bus.subscribe(keys.end(run_id), self.on_message)
        bus.declare_publisher(keys.node_state(run_id, node_id))
        if self.publishes_reading:
            bus.declare_publisher(keys.reading(run_id, node_id))

    def _new_estimator(self) -> LocalEstimator:
        return LocalEstimator.for_node(self.sc, self.id, self.variant, self.objective)

    def warm_up(self) -> None:
        """Run a step 0 and a step 1 on made-up data (the priors) through the node's estimator, build,
        encode and decode the state it would publish, and put the neighbours' made-up states through the
        plausibility checks; nothing of it is kept or sent.

        A process's first step costs ≈14 ms of CPU against ≈2 ms later (first calls into numpy.linalg,
        Clarabel and the message models), and an estimator's first step of each φ pattern ≈0.4 ms more
        than later ones (its η layout and Clarabel solver are built then); in real time a hundred nodes
        take their step 0 and 1 at the same moment, so a role process does this while it waits for the
        others to start.  Only the estimator's caches keep anything of it (layouts, T and G per γ, the
        Clarabel solvers, whose data every solve replaces: a solver updated in place answers bit for bit
        like a new one), so its results are those of a node that did not warm up (tests/inmemory/test_warm_up.py)."""
        if self.set_estimator is not None:
            return
        sc, cfg = self.sc, self.cfg
        est = self.estimator
        gamma = sum(cfg.gamma_range) / 2 if sc.case == "saim" and cfg.gamma_range is not None else 1.0

        def prior_state(j: int, ell: NodeSet, sector: Sector | None) -> NeighbourState:
            sensor = sc.node(j).sensor
            y = float(sensor.Cbar @ ell.xhat)
            if sector is None:
                sector = derive_sector(sensor, FaultBound(), measurement_interval(sensor, y, gamma), None)
            return NeighbourState(ell.xhat, ell.P, ell.rho, gamma, 0.0, sector)

        prior = NodeSet(cfg.x0_hat.copy(), cfg.P0.copy(), self.rho)
        y = float(cfg.sensor.Cbar @ prior.xhat)
        first = est.first(prior, y, gamma)
        own = NodeSet(first.continued.xhat, first.continued.P, self.rho)
        neigh = {j: prior_state(j, NodeSet(sc.node(j).x0_hat, sc.node(j).P0, sc.node(j).rho), None) for j in self.others}
        if self.id in cfg.in_weights:
            neigh[self.id] = prior_state(self.id, own, first.sector)
        u, vx = (sc.steer_low + sc.steer_high) / 2, sc.vx(0)
        res = est.step(own, UpdateInput(sc.model.weights(vx), u, y, gamma, neigh))
        if self.read_from:  # a step that uses readings (their slabs and cuts)
            readings = {j: (float(sc.node(j).sensor.Cbar @ cfg.x0_hat), gamma) for j in self.read_from}
            est.step(own, UpdateInput(sc.model.weights(vx), u, y, gamma, {}, readings))
            decode(encode(Reading(step=1, node=self.id, y=y, gamma=gamma)))
        inp = NodeInput(step=1, node=self.id, y=y, gamma=gamma, u_prev=u, vx_prev=vx, expect_from=self.others)
        decode(encode(inp))
        decode(encode(self._state_message(Publication(inp, res.figures.status, res, used=self.others))))
        for j in self.others:  # the checks every neighbour state of step 1 goes through (results unused)
            nb = neigh[j]
            innovation_possible(self.sensors[j], nb.xhat, nb.P, nb.rho, nb.gamma, nb.sector, nb.innov)
            states_disjoint(res.continued.xhat, res.continued.P, self.rho, nb.xhat, nb.P, nb.rho)

    # ------------------------------------------------------------------ receiving

    def on_message(self, key: str, msg: Message) -> None:
        reason = self.scope.reject(msg)
        if reason is not None:
            self.drop(reason)
        elif isinstance(msg, End):
            self._on_end(key, msg)
        elif isinstance(msg, NodeInput):
            self._on_input(key, msg)
        elif isinstance(msg, NodeState):
            self._on_neighbour(key, msg)
        elif isinstance(msg, Reading):
            self._on_reading(key, msg)
        else:
            self.drop("unexpected-type")

    # What the bus drops undecoded (a subscription's screen, netsetest/bus/base.py): a copy naming a step after
    # the run or one we have passed, which the handlers below drop for the same reason whatever it holds; k
    # only grows, so the reason still holds when the handler would have run.  Called on the transport's thread.

    def _passed_input(self, step: int) -> str | None:
        return self.scope.beyond(step) or ("node-input-mismatch" if step <= self.k else None)

    def _passed_state(self, step: int) -> str | None:
        return self.scope.beyond(step) or ("stale" if step < self.k else None)  # k: our next step uses it

    def _passed_reading(self, step: int) -> str | None:
        return self.scope.beyond(step) or ("stale" if step <= self.k else None)  # a reading serves its own step

    def drop(self, reason: str) -> None:
        self.drops[reason] += 1

    def drop_report(self) -> dict[str, int]:
        """Drop counters by reason: this role's, and its bus's unless the bus is shared with other roles."""
        return dict(self.drops + (Counter() if self.bus.shared else self.bus.dropped))

    def _on_end(self, key: str, msg: End) -> None:
        if key != keys.end(self.run) or msg.steps != self.sc.steps:
            self.drop("end-not-scheduled")
            return
        if self.k < self.sc.steps:
            self.drop("end-early")  # counted; it takes effect once our last step is out
        self.end_seen = True
        self._check_end()

    def _check_end(self) -> None:
        self.ended = self.end_seen and self.k >= self.sc.steps

    def _on_input(self, key: str, msg: NodeInput) -> None:
        if msg.node != self.id or key != keys.node_input(self.run, self.id) or msg.step <= self.k:
            self.drop("node-input-mismatch")
            return
        if msg.step in self.inputs:
            self.drop("duplicate-input")  # the first copy counts
            return
        why = self._implausible_input(msg)
        if why is not None:
            self.drop(why)
            return
        if self.k < 0 and not self.rejoin and msg.step > 0 and 0 not in self.inputs:
            # a fresh node starts at step 0; later steps without it mean a hostile message or a run we
            # missed (with step 0 in hand they are the next steps, arriving before we took step 0)
            self.drop("implausible-step" if msg.step > MAX_AHEAD else "before-start")
            self.late_start_evidence += 1
            if self.late_start_evidence >= LATE_START_EVIDENCE and 0 not in self.inputs:
                self.rejoin = True  # the run started without us (a start-up race): re-enter safely
            return
        if self.k >= 0 and msg.step > self.k + MAX_AHEAD:
            self.drop("implausible-step")
            return
        self.inputs[msg.step] = msg
        if len(self.inputs) > MAX_AHEAD:  # a rejoining node before it re-entered: keep the newest
            del self.inputs[min(self.inputs)]
        if (
            self.publishes_reading and msg.step > 0 and msg.y is not None
        ):  # the same-step exchange phase (step 0 uses none): our reading goes out before we estimate
            self.bus.publish(keys.reading(self.run, self.id), Reading(step=msg.step, node=self.id, y=msg.y, gamma=msg.gamma))

    def _implausible_input(self, msg: NodeInput) -> str | None:
        """Why the scenario rules this input out (the vehicle's values are known ranges), or None."""
        sc = self.sc
        if not set(msg.expect_from) | set(msg.lost_from) <= set(self.others):
            return "input-not-neighbours"
        if (msg.y is None) != (self.id in msg.unread) or not set(msg.unread) <= set(self.sc.ids):
            return "input-unread"
        if msg.step > 0:
            if msg.u_prev is None or msg.vx_prev is None:
                return "input-incomplete"
            lo, hi = sc.steering_range()
            if not lo <= msg.u_prev <= hi:
                return "input-steering"
            if not sc.speed_plausible(msg.step - 1, msg.vx_prev):  # the speed profile is part of the scenario
                return "input-speed"
        if not self._gamma_possible(self.id, msg.gamma):
            return "input-gamma"
        return None

    def _on_reading(self, key: str, msg: Reading) -> None:
        if msg.node not in self.read_from or key != keys.reading(self.run, msg.node):
            self.drop("not-a-reference")
            return
        # a reading serves the step it was taken at: once that step is done it is stale
        why = self._out_of_window(msg.step, msg.node, self.k + 1, self.readings, "duplicate-reading")
        if why is None and not self._gamma_possible(msg.node, msg.gamma):
            why = "reading-gamma"
        if why is not None:
            self.drop(why)
            return
        if len(self.readings) >= MAX_AHEAD and msg.step not in self.readings:
            del self.readings[min(self.readings)]  # not started (rejoin): keep the newest steps only
        self.readings.setdefault(msg.step, {})[msg.node] = (msg.y, msg.gamma)
        self.silent.discard(msg.node)

    def _on_neighbour(self, key: str, msg: NodeState) -> None:
        if msg.node not in self.others or key != keys.node_state(self.run, msg.node):
            self.drop("not-a-neighbour")
            return
        why = self._out_of_window(msg.step, msg.node, self.k, self.inbox, "duplicate-state")  # k: our next step uses it
        if why is not None:
            self.drop(why)
            return
        if msg.innov is None:  # its node had no reading: no innovation to use (the vehicle told us not to expect it)
            return
        sensor = self.sensors[msg.node]
        if (msg.sector is not None) != sensor.saturated:
            self._refuse(msg, "sector-mismatch")  # a saturating sensor publishes its sector, no other one does
            return
        pub = msg.published  # neighbours use its ellipsoid alone
        P = _symmetric(pub.P)  # symmetric positive definite: checked by decode()
        sector = Sector(msg.sector[0], msg.sector[1], msg.sector_basis) if msg.sector is not None else None
        if not innovation_possible(sensor, np.asarray(pub.xhat), P, pub.rho, msg.gamma, sector, msg.innov):
            self._refuse(msg, "neighbour-innovation")
            return
        if self.k < 0 and len(self.inbox) >= MAX_AHEAD and msg.step not in self.inbox:
            oldest = min(self.inbox)  # not started (rejoin): keep the newest steps only
            del self.inbox[oldest]
            self.digests.pop(oldest, None)
        est = self.estimator
        region = pub.polygon if est.neighbour_sets else None  # what the step takes of its set beyond the ellipsoid
        fault = None
        if msg.node in est.bounded and est.bounded[msg.node][1].rate is not None:
            fault = pub.fault_bounds()
        self.inbox.setdefault(msg.step, {})[msg.node] = NeighbourState(np.asarray(pub.xhat), P, pub.rho, msg.gamma, msg.innov, sector, region, fault)
        self.digests.setdefault(msg.step, {})[msg.node] = state_digest(msg)
        self._screen()

    def _out_of_window(self, step: int, node: int, first: int, buffered: dict[int, dict[int, Any]], duplicate: str) -> str | None:
        """Why a message of ``node`` for ``step`` is dropped before its content is looked at: earlier than
        ``first`` (too late to be used), further ahead than the buffers take (not started: any step, the
        newest few kept), or a second copy (``duplicate``: the first counts); None if none applies."""
        if step < first:
            return "stale"
        if self.k >= 0 and step > self.k + MAX_AHEAD:
            return "implausible-step"
        return duplicate if node in buffered.get(step, {}) else None

    def _gamma_possible(self, node: int, gamma: float) -> bool:
        """γ within node's availability range (SAIM; NSNIM: 1), up to the rounding of lo + (hi − lo)·rand."""
        g = self.sc.node(node).gamma_range if self.sc.case == "saim" else (1.0, 1.0)
        return g is None or g[0] * (1 - GAMMA_RTOL) <= gamma <= g[1] * (1 + GAMMA_RTOL)

    def _refuse(self, msg: NodeState, reason: str) -> None:
        """Drop a neighbour state that cannot be honest; its sender no longer holds up that step."""
        self.drop(reason)
        if len(self.refused) < MAX_AHEAD or msg.step in self.refused:  # bounded like the inbox
            self.refused.setdefault(msg.step, set()).add(msg.node)

    def _screen(self) -> None:
        """Drop the neighbour states of our current step whose (β, r) set is disjoint from our own."""
        if self.own is None or self.k < 0:
            return
        have = self.inbox.get(self.k, {})
        if self.screened_step != self.k:  # what was screened before our step: no longer asked
            self.screened_step, self.screened = self.k, set()
        for j in [j for j in have if j not in self.screened]:
            nb = have[j]
            self.screened.add(j)
            if states_disjoint(self.own.xhat, self.own.P, self.own.rho, nb.xhat, nb.P, nb.rho):
                del have[j]
                self.drop("neighbour-disjoint")
                self.refused.setdefault(self.k, set()).add(j)

    # ------------------------------------------------------------------ stepping

    def next_input(self) -> NodeInput | None:
        if self.k >= 0:
            return self.inputs.get(self.k + 1)
        if self.rejoin:
            return self.inputs[max(self.inputs)] if self.inputs else None  # re-enter at the newest step
        return self.inputs.get(0)

    def missing(self) -> list[int]:
        """Expected messages for the next step that have not arrived: the neighbours' states of our step and
        the references' readings of the next one (none without a reading, or resuming: that step uses neither)."""
        inp = self.next_input()
        if inp is None or self.k < 0 or inp.y is None or self.gap is not None:
            return []
        unread = self._unread(inp)
        if self.set_estimator is not None:  # it uses no neighbour state
            return unread
        have, refused = self.inbox.get(self.k, {}), self.refused.get(self.k, set())
        return [j for j in inp.expect_from if j not in have and j not in refused] + unread

    def awaiting_readings(self) -> bool:
        """Whether a reading of the next step has not arrived (the real-time clock waits a budget for it:
        runtime/processes.py); never for a step without our own reading or resuming, which uses none (:meth:`missing`)."""
        inp = self.next_input()
        return inp is not None and self.k >= 0 and inp.y is not None and self.gap is None and bool(self._unread(inp))

    def _unread(self, inp: NodeInput) -> list[int]:
        """The senders whose reading of ``inp``'s step we still wait for (not the silent ones, nor those the vehicle
        says have none at that step)."""
        readings = self.readings.get(inp.step, {})  # (who sent one: their order is _readings_of's business)
        return [j for j in self.read_from if j not in readings and j not in self.silent and j not in inp.unread]

    def _readings_of(self, step: int) -> dict[int, tuple[float, float]]:
        """The readings of ``step`` that arrived, by sender: in id order, not arrival order, so that a step's cuts (whose
        rounding follows their order) give over Zenoh what they give in memory."""
        return dict(sorted(self.readings.get(step, {}).items()))

    def _prior(self) -> NodeSet:
        """The set the next step starts from."""
        return NodeSet(self.xhat, self.P, self.rho, self.region, self.region_without)

    def _step_input(self, inp: NodeInput, neigh: dict[int, NeighbourState], readings: dict[int, tuple[float, float]]) -> UpdateInput:
        """The estimator's input of a step > 0 (its u and Vx are there: _implausible_input dropped inputs without them)."""
        assert inp.u_prev is not None and inp.vx_prev is not None and inp.y is not None  # a step without a reading is _carry's
        return UpdateInput(self.sc.model.weights(inp.vx_prev), inp.u_prev, inp.y, inp.gamma, neigh, readings)

    def try_step(self, now: float | None = None) -> bool:
        """Compute and publish the next step if its inputs are here (or the runtime gave up waiting)."""
        inp = self.next_input()
        if inp is None or self.k >= self.sc.steps:
            return False
        if self.k < 0:
            stepped = self._start(inp)
        elif self.set_estimator is None and (inp.y is None or self.gap is not None):
            self._carry(inp)  # no reading: nothing published; the first reading after resumes (estimator/rejoin.py)
            stepped = True
        elif not self.give_up and self.missing():
            if self.waiting_since is None:
                self.waiting_since = now if now is not None else time.monotonic()
            self._prepare(inp)
            return False
        else:
            # whoever's reading is still missing: not waited for again until one arrives (a step without ours waited for none)
            if self.give_up and inp.y is not None:
                self.silent |= set(self._unread(inp))
            self._update(inp)
            stepped = True
        if stepped:
            self._screen()  # neighbour states of our new step that arrived before it
            self._check_end()
        return stepped

    def _start(self, inp: NodeInput) -> bool:
        """Step 0: the prior ellipsoid (Assumption 1) updated by ỹ₀, certified like every step (the prior
        itself if that fails); without ỹ₀ the prior itself (status no-reading), from which the node resumes at its
        next reading as after any step without one (:meth:`_carry`).  Rejoin: see :mod:`netsetest.estimator.rejoin`."""
        if self.set_estimator is not None:
            if inp.step != 0:
                return False  # a set estimator starts from its prior at step 0 only: no rejoin
            self._publish_set(inp, "init" if inp.y is not None else "no-reading")
            return True
        if inp.y is None:
            if inp.step != 0:
                return False  # a rejoin needs its own reading
            sector = derive_sector(self.cfg.sensor, FaultBound(), Interval(-np.inf, np.inf), None)
            self._publish(Publication(inp, "no-reading", StepResult.of(StepSet(self.xhat, self.P, float("nan")), StepFigures("ok", 0.0, "no-reading"), sector)))
            assert self.own_digest is not None
            self.gap = Gap(0, self.own_digest, self.xhat[:NX].copy(), self.rho * self.P[:NX, :NX])  # the next step resumes from the prior
            return True
        if inp.step == 0:
            res = self.estimator.first(NodeSet(self.xhat, self.P, self.rho), inp.y, inp.gamma)
            status: NodeStatus = "init" if res.figures.status == "ok" else "init-prior"
            self._publish(Publication(inp, status, res))
            return True
        have = self.inbox.get(inp.step, {})
        if not have:
            return False  # wait for a neighbour's ellipsoid of this step
        xhat, P = rejoin_ellipsoid(self.cfg.sensor, inp.y, inp.gamma, self.rho, list(have.values()))
        sector = derive_sector(self.cfg.sensor, FaultBound(), measurement_interval(self.cfg.sensor, inp.y, inp.gamma), None)
        res = StepResult.of(StepSet(xhat, P, float("nan")), StepFigures("ok", 0.0, "rejoin"), sector)
        self._publish(Publication(inp, "rejoin", res, used=sorted(have), inputs=self._inputs(inp.step, sorted(have), own=False)))
        return True

    def _carry(self, inp: NodeInput) -> None:
        """A step after one without a reading, or without one itself: the own set's x part carried through the
        transition by the model alone (:func:`~netsetest.estimator.rejoin.predict_x`); with a reading, the
        node resumes from it and the reading (:func:`~netsetest.estimator.rejoin.resume_ellipsoid`) and
        publishes ``resume``; without, it publishes nothing (its neighbours are told it has no state)."""
        assert inp.u_prev is not None and inp.vx_prev is not None and self.own_digest is not None
        if self.gap is None:  # the own set of the last step with a reading
            self.gap = Gap(self.k, self.own_digest, self.xhat[:NX].copy(), self.rho * self.P[:NX, :NX])
        a, b, d = self.sc.model.blend(self.sc.model.weights(inp.vx_prev))
        xc, Sx = predict_x(self.gap.xc, self.gap.Sx, a, b[:, 0], d[:, 0], inp.u_prev, self.sc.W, self.sc.uncertainty)
        if inp.y is None:
            self.gap = Gap(self.gap.since, self.gap.digest, xc, Sx)
            self.own, self.prepared = None, None  # no own set of this step: neighbour states are not screened against one
            self._taken(inp.step)
            return
        xhat, P = resume_ellipsoid(self.cfg.sensor, inp.y, inp.gamma, self.rho, xc, Sx)
        sector = derive_sector(self.cfg.sensor, FaultBound(), measurement_interval(self.cfg.sensor, inp.y, inp.gamma), None)
        res = StepResult.of(StepSet(xhat, P, float("nan")), StepFigures("ok", 0.0, "resume"), sector)
        since, digest = self.gap.since, self.gap.digest
        self.gap = None
        self._publish(Publication(inp, "resume", res, inputs=[(self.id, digest)], resumed_from=since))

    def _neighbours(self, inp: NodeInput) -> dict[int, NeighbourState]:
        """The states the step of ``inp`` uses: the expected neighbours' that arrived, and our own (self-loop)."""
        have = self.inbox.get(self.k, {})
        neigh = {j: have[j] for j in inp.expect_from if j in have}
        if self.id in self.cfg.in_weights:
            neigh[self.id] = self.own  # type: ignore[assignment]  # the own NodeSet stands in for the NeighbourState the self-loop reads (same fields)
        return neigh

    def _prepare(self, inp: NodeInput) -> None:
        """While only the step's readings are missing (every expected neighbour's state is here or refused):
        the part of the step they do not enter, once (LocalEstimator.prepare), so that the exchange's hop
        overlaps the solve instead of preceding it.  The step's result is the same with or without it."""
        if not self.early or self.set_estimator is not None or self.k < 0 or (self.prepared is not None and self.prepared[0] == inp.step):
            return
        have, refused = self.inbox.get(self.k, {}), self.refused.get(self.k, set())
        if any(j not in have and j not in refused for j in inp.expect_from) or not self._unread(inp):
            return
        self.prepared = (inp.step, self.estimator.prepare(self._prior(), self._step_input(inp, self._neighbours(inp), {})))

    def _update(self, inp: NodeInput) -> None:
        if self.set_estimator is not None:
            self._publish_set(inp, "ok" if inp.y is not None else "no-reading")
            return
        readings = self._readings_of(inp.step)
        own_reading = {self.id: (inp.y, inp.gamma)}  # a reference's own measurement is one of the step's readings
        neigh = self._neighbours(inp)
        step_in = self._step_input(inp, neigh, readings)
        prior = self._prior()
        prepared = self.prepared[1] if self.prepared is not None and self.prepared[0] == inp.step else None
        self.prepared = None
        if prepared is not None and not prepared.of(prior, step_in):
            prepared = None  # the step's neighbours changed since (a state came after all): solved afresh, as sound
        res = self.estimator.step(prior, step_in, prepared)
        # the readings the step's sets rest on: the published one's and the ones the set it continues from was
        # cut by (both are judged under the step's cone: docs/coverage.md)
        rests = res.rests_on
        health = rests.health
        refs = sorted(set(readings) | (rests.readings & {self.id})) if health else sorted(rests.readings)  # the k-of-N facts rest on every reading
        used = sorted(j for j in neigh if j != self.id)
        self._publish(
            Publication(
                inp,
                res.figures.status,
                res,
                used=used,
                missing=self.missing(),
                inputs=self._inputs(self.k, used, own=True),
                readings=[(j, *(readings | own_reading)[j]) for j in refs],
                health=health,
                sets=sorted(rests.sets & set(used)),
            )
        )

    def _inputs(self, step: int, used: list[int], own: bool) -> list[tuple[int, str]]:
        """(node, digest) of every state copy a step used: the neighbours' of ``step`` and our own prior."""
        have = self.digests.get(step, {})
        out = [(j, have[j]) for j in used]
        if own and self.own_digest is not None:
            out.append((self.id, self.own_digest))
        return out

    def _publish_set(self, inp: NodeInput, status: NodeStatus) -> None:
        """Step the set estimator and publish its set with an enclosing ellipsoid (the neighbour-facing
        summary: SDP neighbours and the plausibility checks use it unchanged) and the step's sector."""
        assert self.set_estimator is not None
        t0 = time.perf_counter()
        readings = self._readings_of(inp.step) if inp.step > 0 and inp.y is not None else {}  # no reading: prediction only
        try:
            s = self.set_estimator.step(base.StepInput(inp.step, inp.y, inp.gamma, inp.u_prev, inp.vx_prev, readings))
        except base.EstimatorError:
            # the measurement contradicts the set: an assumption broke (the collector's cone shows which).
            # Nothing guaranteed can be published; the last set is, marked "fallback", and the run goes on.
            if self.last_set is None:
                raise
            s, status = self.last_set, "fallback"
        self.last_set = s
        inputs = self._inputs(self.k, [], own=True) if inp.step > 0 else []
        xhat, P = enclosing_ellipsoid(s, self.rho)
        solve_ms = 1000 * (time.perf_counter() - t0)
        sensor = self.cfg.sensor
        # the sector from the measurement, and (declared fault bound: basis "fault-bound", so the collector
        # also requires it) from C̄ x̄ over the node's own set
        r_set = Interval(-s.support(-sensor.Cbar), s.support(sensor.Cbar))
        fault_bound = FaultBound(self.cfg.fault_rate, self.cfg.fault_size)
        meas = Interval(-np.inf, np.inf) if inp.y is None else measurement_interval(sensor, inp.y, inp.gamma)
        sector = derive_sector(sensor, fault_bound, meas, r_set)
        own = StepSet(xhat, P, float("nan"), cuts=s.cuts if isinstance(s, RegionSet) else NO_CUTS)
        res = StepResult.of(own, StepFigures("ok", solve_ms, status), sector)
        used_readings = [(j, *readings[j]) for j in sorted(readings)] if status == "ok" else []  # "fallback": the last set
        health = bool(used_readings) and self.sc.health_group(self.id) is not None
        self._publish(Publication(inp, status, res, missing=self.missing(), inputs=inputs, wire_set=set_to_wire(s), readings=used_readings, health=health))

    def _publish(self, pub: Publication) -> None:
        """Keep ``pub.res`` as the node's own set (its next step starts from it) and publish ``res.published``."""
        inp, res = pub.inp, pub.res
        self.xhat, self.P, self.region = res.continued.xhat, res.continued.P, res.region
        self.region_without = res.contradicted.readings if res.contradicted is not None else frozenset()
        sector = res.sector
        cbar = self.cfg.sensor.Cbar
        # (no reading: no innovation, so nothing of this step is a neighbour state, our own self-loop's either)
        self.own = None if inp.y is None else NeighbourState(self.xhat.copy(), self.P.copy(), self.rho, inp.gamma, float(inp.y - cbar @ self.xhat), sector)
        msg, self.own_digest = self._built(pub)
        self._taken(inp.step)
        self.bus.publish(keys.node_state(self.run, self.id), msg)

    def _built(self, p: Publication) -> tuple[NodeState, str]:
        """The state message of ``p`` and its digest."""
        msg = self._state_message(p)
        return msg, state_digest(msg)

    def _taken(self, k: int) -> None:
        """Step k is taken (published, or passed without a reading): forget what only earlier steps could use."""
        self.k = k
        self.inputs = {s: m for s, m in self.inputs.items() if s > k}
        self.inbox = {s: m for s, m in self.inbox.items() if s >= k}  # the neighbours' states of k serve step k+1
        self.refused = {s: js for s, js in self.refused.items() if s >= k}
        self.digests = {s: d for s, d in self.digests.items() if s >= k}
        self.readings = {s: r for s, r in self.readings.items() if s > k}
        self.waiting_since, self.give_up = None, False

    def _state_message(self, p: Publication) -> NodeState:
        """The state message of ``p.res.published`` for the step of ``p.inp`` (validated)."""
        inp, res = p.inp, p.res
        pub, sector = res.published, res.sector
        innov = None if inp.y is None else float(inp.y - self.cfg.sensor.Cbar @ pub.xhat)
        rho_cert = pub.rho_cert if np.isfinite(pub.rho_cert) else None
        drops = self.drop_report()
        return NodeState(
            step=inp.step,
            node=self.id,
            published=res.published_set(self.rho, p.wire_set),
            continues=res.continued_ellipsoid(self.rho),
            gamma=inp.gamma,
            innov=innov,
            status=p.status,
            rho_cert=rho_cert,
            solve_ms=res.figures.solve_ms,
            used=p.used,
            missing=p.missing,
            late=inp.deadline is not None and time.time() > inp.deadline,
            dropped=sum(drops.values()),
            drops=drops,
            sector=(sector.h1, sector.h) if sector is not None else None,
            sector_basis=sector.basis if sector is not None else "none",
            inputs=p.inputs,
            readings=p.readings,
            health=p.health,
            sets=p.sets,
            resumed_from=p.resumed_from,
            cuts=[list(c) for c in pub.cuts] if any(pub.cuts) else [],
        )
