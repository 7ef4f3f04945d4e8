"""The node role: one yaw-rate sensing node running its local estimator.

At step k+1 node i needs its :class:`NodeInput` of step k+1 (ỹ_i,k+1, γ_i,k+1, u_k, Vx_k) and the
step-k states of the in-neighbours the vehicle told it to expect.  A neighbour message that is
scheduled lost, or has not arrived when the runtime gives up waiting, is left out of the step and its
η slots are zeroed (the guarantee holds with the neighbours that did arrive).  Node i never sees the
truth.  Every neighbour message is checked in context (a real in-neighbour on its own key, a usable
step) and dropped and counted otherwise; decode() has already checked types, sizes and the shape.
"""

from __future__ import annotations

import time

import numpy as np

from netsetest.bus import keys
from netsetest.bus.base import Bus
from netsetest.config.schema import Scenario
from netsetest.estimator.objective import DEFAULT_OBJECTIVE
from netsetest.estimator.rejoin import rejoin_ellipsoid
from netsetest.estimator.sdp import Ellipsoid, LocalEstimator, NeighbourState, Objective, StepInput, StepResult, Variant
from netsetest.estimator.sector import FaultBound, Sector, derive_sector, measurement_interval
from netsetest.messages import End, Message, NodeInput, NodeState
from netsetest.models.sensor import NA


MAX_AHEAD = 50  # steps ahead of our own: more is a corrupt or hostile message (bounds the buffers)
LATE_START_EVIDENCE = 3  # inputs of later steps and none of step 0: the run started without us, rejoin


class Node:
    def __init__(
        self, scenario: Scenario, node_id: int, bus: Bus, run_id: str, variant: Variant = "scheduled", rejoin: bool = False,
        objective: Objective = DEFAULT_OBJECTIVE,
    ) -> None:  # fmt: skip
        self.sc, self.bus, self.run = scenario, bus, run_id
        self.cfg = scenario.node(node_id)
        self.id = node_id
        self.estimator = LocalEstimator(
            node_id,
            self.cfg.sensor,
            {j: scenario.node(j).sensor for j in self.cfg.in_weights},
            self.cfg.in_weights,
            scenario.model,
            scenario.W,
            variant,
            fault_bound=FaultBound(self.cfg.fault_rate, self.cfg.fault_size),
            objective=objective,
        )
        self.others = [j for j in self.cfg.in_weights if j != node_id]
        # estimator state, plain arrays: centre, shape, radius, and our own last published message
        self.xhat = self.cfg.x0_hat.copy()
        self.P = self.cfg.P0.copy()
        self.rho = self.cfg.rho
        self.k = -1  # last published step
        self.own: NeighbourState | None = None
        self.inputs: dict[int, NodeInput] = {}
        self.inbox: dict[int, dict[int, NeighbourState]] = {}  # step → j → state
        self.waiting_since: float | None = None
        self.give_up = False  # set by the runtime when the neighbour deadline passed
        self.ended = False
        self.rejoin = rejoin  # started into a running network: initialise from a neighbour's ellipsoid
        self.late_start_evidence = 0
        bus.subscribe(keys.node_input(run_id, node_id), self.on_message)
        for j in self.others:
            bus.subscribe(keys.node_state(run_id, j), self.on_message)
        bus.subscribe(keys.end(run_id), self.on_message)

    # ------------------------------------------------------------------ receiving

    def on_message(self, key: str, msg: Message) -> None:
        if isinstance(msg, End):
            self.ended = True
        elif isinstance(msg, NodeInput):
            if msg.node != self.id or msg.step <= self.k:
                self.bus.drop("node-input-mismatch")
                return
            if self.k < 0 and not self.rejoin and msg.step > 0:
                # a fresh node starts at step 0; later steps mean a hostile message or a run we missed
                self.bus.drop("implausible-step" if msg.step > MAX_AHEAD else "before-start")
                self.late_start_evidence += 1
                if self.late_start_evidence >= LATE_START_EVIDENCE and 0 not in self.inputs:
                    self.rejoin = True  # the run started without us (a start-up race): re-enter safely
                return
            if self.k >= 0 and msg.step > self.k + MAX_AHEAD:
                self.bus.drop("implausible-step")
                return
            self.inputs[msg.step] = msg
            if len(self.inputs) > MAX_AHEAD:  # a rejoining node before it re-entered: keep the newest
                del self.inputs[min(self.inputs)]
        elif isinstance(msg, NodeState):
            self._on_neighbour(key, msg)
        else:
            self.bus.drop("unexpected-type")

    def _on_neighbour(self, key: str, msg: NodeState) -> None:
        if msg.node not in self.others or key != keys.node_state(self.run, msg.node):
            self.bus.drop("not-a-neighbour")
            return
        if msg.step < self.k:  # too late to be used
            self.bus.drop("stale")
            return
        if self.k >= 0 and msg.step > self.k + MAX_AHEAD:
            self.bus.drop("implausible-step")
            return
        if (msg.sector is not None) != self.sc.node(msg.node).sensor.saturated:
            self.bus.drop("sector-mismatch")  # a saturating sensor publishes its sector, no other one does
            return
        P = msg.P_matrix()  # symmetric positive definite: checked by decode()
        sector = Sector(msg.sector[0], msg.sector[1], msg.sector_basis) if msg.sector is not None else None
        self.inbox.setdefault(msg.step, {})[msg.node] = NeighbourState(
            np.asarray(msg.xhat), 0.5 * (P + P.T), msg.rho, msg.gamma, msg.innov, sector
        )

    # ------------------------------------------------------------------ stepping

    def next_input(self) -> NodeInput | None:
        if self.k >= 0:
            return self.inputs.get(self.k + 1)
        if self.rejoin:
            return self.inputs[max(self.inputs)] if self.inputs else None  # re-enter at the newest step
        return self.inputs.get(0)

    def missing(self) -> list[int]:
        """Expected neighbour messages for the next step that have not arrived."""
        inp = self.next_input()
        if inp is None or self.k < 0:
            return []
        have = self.inbox.get(self.k, {})
        return [j for j in inp.expect_from if j not in have]

    def try_step(self, now: float | None = None) -> bool:
        """Compute and publish the next step if its inputs are here (or the runtime gave up waiting)."""
        inp = self.next_input()
        if inp is None or self.ended and self.k >= self.sc.steps:
            return False
        if self.k < 0:
            return self._start(inp)
        if self.missing() and not self.give_up:
            if self.waiting_since is None:
                self.waiting_since = now if now is not None else time.monotonic()
            return False
        self._update(inp)
        return True

    def _start(self, inp: NodeInput) -> bool:
        """Step 0: the prior ellipsoid (Assumption 1) updated by ỹ₀, certified like every step (the prior
        itself if that fails).  Rejoin: see :mod:`netsetest.estimator.rejoin`."""
        if inp.step == 0:
            res = self.estimator.first(Ellipsoid(self.xhat, self.P, self.rho), inp.y, inp.gamma)
            status = "init" if res.status == "ok" else "init-prior"
            self._publish(inp, status, res, used=[], missing=[])
            return True
        have = self.inbox.get(inp.step, {})
        if not have:
            return False  # wait for a neighbour's ellipsoid of this step
        xhat, P = rejoin_ellipsoid(self.cfg.sensor, inp.y, inp.gamma, self.rho, list(have.values()))
        sector = derive_sector(self.cfg.sensor, FaultBound(), measurement_interval(self.cfg.sensor, inp.y, inp.gamma), None)
        res = StepResult(xhat, P, "ok", float("nan"), 0.0, "rejoin", sector=sector)
        self._publish(inp, "rejoin", res, used=sorted(have), missing=[])
        return True

    def _update(self, inp: NodeInput) -> None:
        have = self.inbox.get(self.k, {})
        neigh = {j: have[j] for j in inp.expect_from if j in have}
        if self.id in self.cfg.in_weights:
            neigh[self.id] = self.own  # type: ignore[assignment]
        alpha = self.sc.model.weights(inp.vx_prev)  # type: ignore[arg-type]
        step_in = StepInput(alpha, inp.u_prev, inp.y, inp.gamma, neigh)  # type: ignore[arg-type]
        res = self.estimator.step(Ellipsoid(self.xhat, self.P, self.rho), step_in)
        self._publish(inp, res.status, res, used=sorted(j for j in neigh if j != self.id), missing=self.missing())

    def _publish(self, inp: NodeInput, status: str, res: StepResult, used: list[int], missing: list[int]) -> None:
        """Keep ``res`` as the node's own set (its next step starts from it) and publish ``res.public``."""
        self.xhat, self.P = res.xhat, res.P
        sector = res.sector
        cbar = self.cfg.sensor.Cbar
        self.own = NeighbourState(self.xhat.copy(), self.P.copy(), self.rho, inp.gamma, float(inp.y - cbar @ self.xhat), sector)
        pub = res.public
        innov = float(inp.y - cbar @ pub.xhat)
        rho_cert = pub.rho_cert if np.isfinite(pub.rho_cert) else None
        msg = NodeState(
            step=inp.step, node=self.id, xhat=[float(a) for a in pub.xhat], P=[float(a) for a in pub.P.reshape(NA * NA)],
            rho=self.rho, gamma=inp.gamma, innov=innov, status=status, rho_cert=rho_cert,  # type: ignore[arg-type]
            solve_ms=res.solve_ms, used=used, missing=missing,
            late=inp.deadline is not None and time.time() > inp.deadline, dropped=sum(self.bus.dropped.values()),
            sector=(sector.h1, sector.h) if sector is not None else None,
            sector_basis=sector.basis if sector is not None else "none",
        )  # fmt: skip
        self.k = inp.step
        self.inputs = {s: m for s, m in self.inputs.items() if s > self.k}
        self.inbox = {s: m for s, m in self.inbox.items() if s >= self.k}
        self.waiting_since, self.give_up = None, False
        self.bus.publish(keys.node_state(self.run, self.id), msg)
