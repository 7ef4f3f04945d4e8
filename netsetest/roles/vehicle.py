"""The vehicle role: simulates the truth and publishes what each party may see.

Step k: the vehicle draws u_k, w_k, v_i,k, γ_i,k, computes ỹ_i,k and publishes to node i a
:class:`NodeInput` (ỹ_i,k, γ_i,k, u_{k−1}, Vx_{k−1}, which neighbour messages of step k−1 to expect),
and to the collector a :class:`Truth` (x_k, f_i,k, assumption flags, scheduled losses, and the model
mismatch e_k of the step to come).  The plant (models/plant.py: the T-S model (8) itself by default, or a
nonlinear CommonRoad car) then advances to x_{k+1} under the manoeuvre's steering (models/manoeuvres.py)
and the wind; e_k = x_{k+1} − (Ā_k x_k + B̄_k u_k + D̄_k w_k) with the matrices of the published Vx_k.

Lockstep: the next step is published once every alive node has published its step-k state (the
runtime decides what to do with nodes that stay silent) and the step is inside the collector's window:
step k + ``ACK_WINDOW`` (roles/flow.py) waits until the collector has acknowledged step k (its Ready's ``acked``), so a
collector that falls behind (a slow record, a loaded machine, a paused process) holds the run instead of
losing the run's own messages at its bounded inbox.  Real time: the runtime calls :meth:`advance` every τs
whatever the nodes did (the collector then keeps up within its memory budget, roles/collector.py).

The vehicle remembers who reported for the last ``dead_after`` steps only (constant memory), drops
states outside the run or on a foreign key, and counts an End it did not send (someone else speaks
on its key); its drop counters travel in every Truth.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from typing import NamedTuple

import numpy as np

from netsetest.bus import keys
from netsetest.bus.base import Bus
from netsetest.config.schema import NodeConfig, Scenario
from netsetest.messages import End, Message, NodeInput, NodeState, Ready, RunScope, Truth
from netsetest.logs.drive import LogDrive, LogStep
from netsetest.models.drive import Drive
from netsetest.models.sensor import augmented
from netsetest.models.signals import SignalKind
from netsetest.roles.flow import ACK_WINDOW, Window


def mismatch_holds(sc: Scenario, e: np.ndarray) -> bool:
    """e_k inside the declared [model_uncertainty] (none declared: the model is exact, e_k = 0)."""
    if sc.uncertainty is None:
        return bool(np.all(np.asarray(e) == 0.0))
    return sc.uncertainty.holds(np.asarray(e))


def envelope_holds(sc: Scenario, ay: float | None, speed: float | None) -> bool:
    """The transition inside the declared [envelope] (none declared, or nothing to check: True)."""
    if sc.envelope is None or ay is None or speed is None:
        return True
    return sc.envelope.holds(ay, speed)


def fault_bound_holds(n: NodeConfig, k: int) -> bool:
    """The node's declared fault bound at step k: |f_k − f_k−1| ≤ δ (k ≥ 1) and |f_k| ≤ F, where declared."""
    f = n.fault(k)
    tol = 1 + 1e-12
    if n.fault_size is not None and abs(f) > n.fault_size * tol:
        return False
    return not (n.fault_rate is not None and k > 0 and abs(f - n.fault(k - 1)) > n.fault_rate * tol)


class LossSchedule:
    """Seeded packet loss of node messages: i.i.d. per link and step plus configured bursts."""

    def __init__(self, scenario: Scenario, seed: int) -> None:
        self.scenario = scenario
        self.rng = np.random.default_rng([seed, 0x1055])
        self.links = [(j, n.id) for n in scenario.nodes for j in n.in_weights if j != n.id]

    def lost_at(self, k: int) -> list[tuple[int, int]]:
        """Links (j, i) whose step k−1 message to step k is lost; one draw per link per step."""
        loss = self.scenario.loss
        draws = self.rng.random(len(self.links))
        out = []
        for (j, i), r in zip(self.links, draws):
            burst = any(b.from_ == j and b.to == i and b.start <= k < b.start + b.length for b in loss.bursts)
            if burst or r < loss.probability:
                out.append((j, i))
        return out


class Vehicle:
    def __init__(
        self,
        scenario: Scenario,
        bus: Bus,
        run_id: str,
        signals: SignalKind = "paper",
        seed: int = 0,
        realtime: bool = False,
        dead_after_steps: int = 20,
        window: int | None = ACK_WINDOW,
    ) -> None:
        """``window``: lockstep, how many steps the vehicle may lead the collector's acknowledgment
        (roles/flow.py; None: no window, the benchmark's measure of what it costs)."""
        self.sc, self.bus, self.run = scenario, bus, run_id
        self.flow = Window(window, scenario.steps)  # lockstep flow control, the vehicle's side
        # lockstep: a node not heard at step k is dead; real time: not heard for dead_after_steps steps
        self.realtime, self.dead_after = realtime, dead_after_steps
        # the world: the model's drive (the plant, the manoeuvre, the seeded signals) or a recorded one (docs/your-log.md)
        self.log = LogDrive(scenario) if scenario.log is not None else None
        self.drive = Drive(scenario, signals, seed) if self.log is None else None
        self.losses = LossSchedule(scenario, seed)
        self.x = scenario.x0.copy()
        self.k = -1  # last published step
        self.u = self.w = self.vx = 0.0
        self.heard: dict[int, set[int]] = {}  # the last dead_after steps (lockstep: 1) only
        self.alive = set(scenario.ids)
        self.unread: set[int] = set()  # nodes without a reading at the current step (an SDP node's after step 0: it publishes nothing)
        self.done = False
        self.scope = RunScope(frozenset(scenario.ids), scenario.steps)
        self.drops: Counter[str] = Counter()
        if realtime:
            # nothing waits for a state (the clock steps) and every pump collects them: a ring per node's key,
            # drained in the vehicle's thread, rather than a Python callback and a wake-up per state (N per step)
            for i in scenario.ids:
                bus.subscribe(keys.node_state(run_id, i), self.on_message, lazy=True, screen=self.scope.beyond)
        else:
            bus.subscribe(keys.node_state(run_id, "*"), self.on_message, screen=self.scope.beyond)
        bus.subscribe(keys.end(run_id), self.on_message)
        bus.subscribe(keys.ready_of(run_id, keys.role_name("collector")), self.on_ack)
        for key in [keys.truth(run_id), keys.end(run_id), *(keys.node_input(run_id, i) for i in scenario.ids)]:
            bus.declare_publisher(key)

    def on_message(self, key: str, msg: Message) -> None:
        """Record who reported; a node declared dead that reports again (late, or rejoined) is alive
        from the next step on — the vehicle only waits for the nodes alive at the current step."""
        if isinstance(msg, End):
            if not self.done:
                self.drops["end-not-ours"] += 1  # ours is sent once, after the last step
            return
        if not isinstance(msg, NodeState):
            self.drops["unexpected-type"] += 1
            return
        reason = self.scope.reject(msg)
        if reason is not None:
            self.drops[reason] += 1
        elif key != keys.node_state(self.run, msg.node):
            self.drops["state-on-foreign-key"] += 1
        elif msg.step <= self.k and msg.step in self._window():
            self.heard.setdefault(msg.step, set()).add(msg.node)
        elif msg.step > self.k:
            self.drops["state-ahead"] += 1  # a step not published yet cannot have been computed

    def on_ack(self, key: str, msg: Message) -> None:
        """The collector's acknowledgment: a Ready on its key with ``acked`` (roles/flow.py)."""
        if not isinstance(msg, Ready) or msg.role != "collector":
            self.drops["unexpected-type"] += 1
        elif msg.acked is not None:
            self.flow.acknowledged(msg.acked, self.k)

    @property
    def acked(self) -> int:
        """The newest step the collector acknowledged."""
        return self.flow.acked

    def window_open(self) -> bool:
        """Lockstep: the next step, or the End, is inside the collector's window (roles/flow.py)."""
        return self.flow.open(self.k)

    def _window(self) -> range:
        """Steps whose reports decide who is alive at the next step."""
        return range(max(0, self.k - self.dead_after + 1), self.k + 1) if self.realtime else range(self.k, self.k + 1)

    def drop_report(self) -> dict[str, int]:
        """Drop counters by reason: this role's, and its bus's unless the bus is shared with other roles."""
        return dict(self.drops + (Counter() if self.bus.shared else self.bus.dropped))

    def waiting_for(self) -> set[int]:
        """Alive nodes that publish at the current step (with a reading, or running a set estimator, or at step 0:
        Scenario.silent_without_reading) whose state of it has not arrived."""
        silent = {i for i in self.unread if self.sc.silent_without_reading(i, self.k)}
        return self.alive - silent - self.heard.get(self.k, set())

    def ready_to_advance(self) -> bool:
        return self.k >= 0 and not self.done and not self.waiting_for()

    def advance(self) -> None:
        """Publish step k+1 (or End after the last step).  Nodes not heard at step k count as dead."""
        if self.done:
            return
        if self.k >= 0:
            window = self._window()
            # a node without a reading at step k may have published nothing and is not dead: it resumes at its next reading
            self.alive = set().union(*(self.heard.get(s, set()) for s in window)) | (self.alive & self.unread)
            self.heard = {s: self.heard[s] for s in window[1:] if s in self.heard}  # bounded memory
            if self.k == self.sc.steps:
                self.bus.publish(keys.end(self.run), End(steps=self.sc.steps))
                self.done = True
                return
        self.k += 1
        self._publish_step(self.k)

    def _publish_inputs(self, k: int, y: dict[int, float], gamma: dict[int, float], lost: list[tuple[int, int]], deadline: float | None) -> None:
        """Each node's input of step k: its reading (absent from ``y``: none at this step), γ, the inputs held over
        k−1 → k, the neighbours to expect (not those without a reading at k−1: they published nothing)."""
        u_prev, vx_prev = (self.u, self.vx) if k > 0 else (None, None)
        quiet_before, self.unread = self.unread, {i for i in self.sc.ids if i not in y}
        unread = sorted(self.unread)
        for n in self.sc.nodes:
            lost_from = sorted(j for (j, i) in lost if i == n.id)
            expect = sorted(j for j in n.in_weights if j != n.id and j in self.alive and j not in lost_from and j not in quiet_before) if k > 0 else []
            self.bus.publish(
                keys.node_input(self.run, n.id),
                NodeInput(
                    step=k,
                    node=n.id,
                    y=y.get(n.id),
                    gamma=gamma[n.id],
                    u_prev=u_prev,
                    vx_prev=vx_prev,
                    expect_from=expect,
                    lost_from=lost_from,
                    deadline=deadline,
                    unread=unread,
                ),
            )

    def _publish_step(self, k: int) -> None:
        if self.log is not None:
            self._publish_log_step(k)
            return
        sc = self.sc
        assert self.drive is not None
        d = self.drive.step(k)
        self.x, w, v, gamma, e = d.x, d.w, d.v, d.gamma, d.e
        ay, speed = (d.ay, d.speed) if sc.plant != "ts" else (None, None)  # the T-S plant has no envelope
        lost = self.losses.lost_at(k) if k > 0 else []
        deadline = time.time() + sc.tau_s if self.realtime else None
        y, y0, faults, sector_ok, noise_ok, r, fault_ok = {}, {}, {}, {}, {}, {}, {}
        for idx, n in enumerate(sc.nodes):
            f = n.fault(k)
            xbar = augmented(self.x, f)
            r[n.id] = float(n.sensor.Cbar @ xbar)
            fault_ok[n.id] = fault_bound_holds(n, k)
            y[n.id] = n.sensor.measure(xbar, gamma[idx], v[idx])
            y0[n.id] = n.sensor.measure(augmented(self.x, 0.0), gamma[idx], v[idx])
            faults[n.id] = f
            sector_ok[n.id] = n.sensor.sector_holds(xbar)
            noise_ok[n.id] = bool(v[idx] ** 2 <= n.sensor.R * (1 + 1e-12))
        self._publish_inputs(k, y, {n.id: float(gamma[idx]) for idx, n in enumerate(sc.nodes)}, lost, deadline)
        self.u, self.w, self.vx = d.u, w, d.vx
        self.bus.publish(
            keys.truth(self.run),
            Truth(
                step=k,
                x=list(map(float, self.x)),
                faults=faults,
                u=self.u,
                w=self.w,
                vx=self.vx,
                noise={n.id: float(v[i]) for i, n in enumerate(sc.nodes)},
                gamma={n.id: float(gamma[i]) for i, n in enumerate(sc.nodes)},
                y=y,
                y_nofault=y0,
                sector_ok=sector_ok,
                noise_ok=noise_ok,
                r=r,
                fault_ok=fault_ok,
                dist_ok=bool(self.w**2 <= sc.W * (1 + 1e-12)),
                lost=lost,
                alive=sorted(self.alive),
                drops=self.drop_report(),
                e=None if e is None else list(map(float, e)),
                mismatch_ok=e is None or mismatch_holds(sc, e),
                health_ok=sc.health_holds(faults),
                speed=speed,
                ay=ay,
                envelope_ok=envelope_holds(sc, ay, speed),
            ),
        )

    def _publish_log_step(self, k: int) -> None:
        """Step k of a recorded drive: the logged readings with the declared faults on top, and the truth as far as
        the reference proves it (logs/drive.py; the flags say an assumption broke only where the reference proves it)."""
        sc = self.sc
        assert self.log is not None
        d = self.log.step(k)
        lost = self.losses.lost_at(k) if k > 0 else []
        deadline = time.time() + sc.tau_s if self.realtime else None
        y = _with_faults(sc, d)
        self._publish_inputs(k, y, {n.id: 1.0 for n in sc.nodes}, lost, deadline)
        self.u, self.w, self.vx = d.u, 0.0, d.vx
        self.x = d.x_ref if d.x_ref is not None else np.zeros(2)
        truth = {i: _log_truth(sc.node(i), d, k) for i in sc.ids}
        of = {name: {i: getattr(t, name) for i, t in truth.items()} for name in _NodeTruth._fields}  # each part, by node
        read = [i for i in sc.ids if d.y_log[i] is not None]
        p = sc.model.params
        ay = d.speed * float(d.x_ref[1]) if d.x_ref is not None else None  # v·r: the reference gives no β̇ (docs/your-log.md)
        self.bus.publish(
            keys.truth(self.run),
            Truth(
                step=k,
                x=list(map(float, self.x)),
                faults=of["fault"],
                u=self.u,
                w=0.0,  # the side wind of a recorded drive is unknown: its bound is declared, never checked
                vx=self.vx,
                noise=of["noise"],
                gamma=dict.fromkeys(sc.ids, 1.0),
                y={i: y[i] for i in read},
                y_nofault={i: float(d.y_log[i]) for i in read},  # type: ignore[arg-type]  # read: a reading is there
                sector_ok=dict.fromkeys(sc.ids, True),  # the nsnim case: no saturation
                noise_ok=of["noise_ok"],
                r=of["r"],
                fault_ok=of["fault_ok"],
                dist_ok=True,
                lost=lost,
                alive=sorted(self.alive),
                drops=self.drop_report(),
                health_ok=sc.health_holds(of["fault"]),
                speed=d.speed,
                ay=ay,
                # the model scheduled at a speed it does not cover describes no transition of the car
                mismatch_ok=p.vx_min <= d.speed <= p.vx_max,
                envelope_ok=envelope_holds(sc, ay, d.speed),
                x_acc=list(d.accuracy),
                f_acc=of["f_acc"],
                reference=d.x_ref is not None,
                no_reading=[i for i in sc.ids if d.y_log[i] is None],
                fault_unknown=[i for i in sc.ids if d.y_log[i] is None and d.x_ref is not None and not d.healthy[i]],
            ),
        )


def _with_faults(sc: Scenario, d: LogStep) -> dict[int, float]:
    """A recorded step's readings with the declared faults on top (a node without a reading: absent)."""
    return {i: float(yl) + sc.node(i).sensor.Ds * d.faults[i] for i, yl in d.y_log.items() if yl is not None}


class _NodeTruth(NamedTuple):
    fault: float  # the fault's centre
    f_acc: float  # its half-width
    noise: float  # v's centre
    noise_ok: bool  # the noise bound not proven broken
    r: float  # C̄ x̄ at the centre
    fault_ok: bool  # the declared fault bound not proven broken


def _log_truth(n: NodeConfig, d: LogStep, k: int) -> _NodeTruth:
    """Node n's truth at a recorded step (:class:`_NodeTruth`).  Declared healthy: the fault is the injected one and
    the noise v = (ỹ_log − C x)/Dv an interval the reference's box leaves (broken only if all of it lies beyond √R);
    not declared healthy: the logged fault is what the reading less the reference leaves within the noise bound."""
    sen, f_inj, y_log = n.sensor, d.faults[n.id], d.y_log[n.id]
    if d.x_ref is None or y_log is None:  # (not declared healthy: the injected fault is not the truth, which nothing tells)
        ok = fault_bound_holds(n, k) or not d.healthy[n.id]
        return _NodeTruth(f_inj, 0.0, 0.0, True, float(sen.Cbar @ augmented(np.zeros(2), f_inj)), ok)
    cx = float(sen.C @ d.x_ref)
    cx_half = float(np.abs(sen.C) @ np.asarray(d.accuracy))
    if d.healthy[n.id]:
        v = (y_log - cx) / sen.Dv
        v_min = max(abs(v) - cx_half / abs(sen.Dv), 0.0)
        return _NodeTruth(f_inj, 0.0, v, v_min * v_min <= sen.R * (1 + 1e-12), float(sen.Cbar @ augmented(d.x_ref, f_inj)), fault_bound_holds(n, k))
    f_c = f_inj + (y_log - cx) / sen.Ds
    f_half = (cx_half + abs(sen.Dv) * math.sqrt(sen.R)) / abs(sen.Ds)
    size_ok = n.fault_size is None or abs(f_c) - f_half <= n.fault_size * (1 + 1e-12)
    return _NodeTruth(f_c, f_half, 0.0, True, float(sen.Cbar @ augmented(d.x_ref, f_c)), size_ok)
