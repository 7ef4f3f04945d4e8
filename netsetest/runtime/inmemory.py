"""The whole network in one process over the in-memory bus: deterministic, used by most tests."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from netsetest.bus.base import MemoryBus
from netsetest.config.schema import Scenario
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, Objective
from netsetest.estimator.sdp import StepObserver, Variant
from netsetest.models.signals import SignalKind
from netsetest.records.meta import RunMeta
from netsetest.records.summary import RunSummary
from netsetest.roles.collector import Collector
from netsetest.roles.node import Node
from netsetest.roles.vehicle import Vehicle
from netsetest.runtime.gc_policy import long_run
from netsetest.runtime.report import Progress, record_sink
from netsetest.runtime.stops import StopRequests


@dataclass
class RunResult:
    summary: RunSummary
    meta: RunMeta
    parts: dict | None  # truth and node entries of the record (None when not kept in memory)


def run_meta(
    scenario: Scenario, mode: str, clock: str, signals: str, variant: str, seed: int | None, run_id: str, objective: str = DEFAULT_OBJECTIVE
) -> RunMeta:
    return RunMeta(
        topology=str(scenario.path),
        name=scenario.name,
        mode=mode,
        clock=clock,
        case=scenario.case,
        signals=signals,
        variant=variant,
        objective=objective,
        seed=seed,
        steps=scenario.steps,
        tau_s=scenario.tau_s,
        run_id=run_id,
        node_ids=list(scenario.ids),
        in_weights={n.id: dict(n.in_weights) for n in scenario.nodes},
        r_max={n.id: (n.sensor.r_max if n.sensor.saturated else None) for n in scenario.nodes},
        h1={n.id: n.sensor.h1 for n in scenario.nodes},
        C={n.id: list(n.sensor.Cbar) for n in scenario.nodes},
        estimators={n.id: n.estimator for n in scenario.nodes},
        plant=scenario.plant_label,
        manoeuvre=scenario.manoeuvre,
        model_uncertainty=None if (u := scenario.uncertainty) is None else {"kind": u.kind, "G": u.G.tolist()},
        started_ns=time.time_ns(),  # the run's start on the wall clock (an MCAP record's log times start here)
        settings_digest=scenario.settings_digest,
        log=None if (lg := scenario.log) is None else {"path": lg.path, "mapping": lg.mapping.path, "accuracy": list(lg.mapping.accuracy)},
    )


def _step_all(nodes: list[Node], bus: MemoryBus) -> bool:
    """Every node takes every step it can (delivering what each step publishes); whether any did."""
    stepped = False
    for n in nodes:
        while n.try_step():
            stepped = True
            bus.pump()
    return stepped


def _lockstep(vehicle: Vehicle, nodes: list[Node], bus: MemoryBus, bar: Progress, on_step: Callable[[int], None] | None, stop: StopRequests | None) -> None:
    """:func:`run_inmemory`'s loop: the vehicle's steps, each once every node has taken what it can, until the last
    or a signal noted in ``stop``; what is still on the bus delivered at the end."""
    vehicle.advance()
    while not vehicle.done:
        if stop is not None and stop.signal is not None:
            break
        bus.pump()
        stepped = _step_all(nodes, bus)
        bus.pump()
        stepped = _step_all(nodes, bus) or stepped  # what that pump delivered (the step's readings) may let a node step
        if vehicle.ready_to_advance() and vehicle.window_open():  # the collector shares the bus: its window never holds
            bar.update(vehicle.k)
            vehicle.advance()
            if on_step is not None:
                on_step(vehicle.k)
        elif not stepped and not bus.pending():
            # in one process a message that has not arrived never will (lost, or dropped as hostile):
            # nodes proceed without the missing neighbours, the vehicle without the silent nodes
            waiting = [n for n in nodes if n.missing()]
            for n in waiting:
                n.give_up = True
            if not waiting:
                vehicle.advance()
    bus.pump()


@long_run()  # the garbage collector's policy for a run (runtime/gc_policy.py)
def run_inmemory(
    scenario: Scenario,
    signals: SignalKind = "paper",
    variant: Variant = "scheduled",
    seed: int = 0,
    progress: bool = False,
    bus: MemoryBus | None = None,
    record: str | None = None,
    keep: bool = True,
    on_step: Callable[[int], None] | None = None,
    objective: Objective = DEFAULT_OBJECTIVE,
    observer: StepObserver | None = None,
    stop: StopRequests | None = None,
) -> RunResult:
    """Run vehicle, nodes and collector in lockstep; the same role code as the Zenoh processes.

    ``record``: stream the record to this file as the run goes; ``keep``: also keep it in memory
    (``RunResult.parts``; a long soak turns it off to run in constant memory); ``on_step(k)``: called
    each time the vehicle publishes step k (the soak benchmark samples memory with it); ``observer``: called
    after every SDP step of every node (estimator/sdp.py ``StepObserver``; the benchmark captures steps with it);
    ``stop``: SIGINT/SIGTERM noted there end the run between two rounds of the loop (``run``'s Ctrl-C): the steps
    closed so far are judged, the summary says "interrupted" and the record is a partial one; without it a signal
    raises as usual (a campaign's worker must not count a run it did not finish).
    """
    run_id = "mem"
    bus = bus or MemoryBus()
    meta = run_meta(scenario, "inmemory", "lockstep", signals, variant, seed, run_id, objective)
    sink, memory = record_sink(record, keep)
    vehicle = Vehicle(scenario, bus, run_id, signals, seed)
    nodes = [Node(scenario, i, bus, run_id, variant, objective=objective) for i in scenario.ids]
    for n in nodes:  # ``observer``: sees every SDP step of every node (the benchmark's capture)
        n.estimator.observer = observer
    collector = Collector(scenario, bus, run_id, sink)
    if sink is not None:
        sink.meta(meta)
    bar = Progress(scenario.steps, "inmemory", enabled=progress)
    _lockstep(vehicle, nodes, bus, bar, on_step, stop)
    bar.close()
    drops = {"bus": dict(bus.dropped)} if bus.dropped else None
    if not vehicle.done:  # stopped by a signal: the steps after the last closed one were cut short, not lost
        return RunResult(
            collector.finish(meta, drops=drops, stopped="interrupted", through=collector.progress), meta, memory.parts() if memory is not None else None
        )
    summary = collector.finish(meta, drops=drops)
    return RunResult(summary, meta, memory.parts() if memory is not None else None)
