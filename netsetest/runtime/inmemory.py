"""The whole network in one process over the in-memory bus: deterministic, used by most tests."""

from __future__ import annotations

from dataclasses import dataclass

from netsetest.bus.base import MemoryBus
from netsetest.config.schema import Scenario
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, Objective
from netsetest.estimator.sdp import Variant
from netsetest.models.signals import SignalKind
from netsetest.roles.collector import Collector
from netsetest.roles.node import Node
from netsetest.roles.vehicle import Vehicle
from netsetest.runtime.report import Progress


@dataclass
class RunResult:
    summary: dict
    meta: dict
    parts: dict  # truth and node entries of the record


def run_meta(
    scenario: Scenario, mode: str, clock: str, signals: str, variant: str, seed: int, run_id: str, objective: str = DEFAULT_OBJECTIVE
) -> dict:
    return {
        "topology": scenario.path, "name": scenario.name, "mode": mode, "clock": clock, "case": scenario.case,
        "signals": signals, "variant": variant, "objective": objective, "seed": seed, "steps": scenario.steps, "tau_s": scenario.tau_s,
        "run_id": run_id, "node_ids": scenario.ids,
        "in_weights": {str(n.id): {str(j): a for j, a in n.in_weights.items()} for n in scenario.nodes},
        "r_max": {str(n.id): (n.sensor.r_max if n.sensor.saturated else None) for n in scenario.nodes},
        "h1": {str(n.id): n.sensor.h1 for n in scenario.nodes},
        "C": {str(n.id): list(n.sensor.Cbar) for n in scenario.nodes},
    }  # fmt: skip


def run_inmemory(
    scenario: Scenario,
    signals: SignalKind = "paper",
    variant: Variant = "scheduled",
    seed: int = 0,
    progress: bool = False,
    bus: MemoryBus | None = None,
    objective: Objective = DEFAULT_OBJECTIVE,
) -> RunResult:
    """Run vehicle, nodes and collector in lockstep; the same role code as the Zenoh processes."""
    run_id = "mem"
    bus = bus or MemoryBus()
    vehicle = Vehicle(scenario, bus, run_id, signals, seed)
    nodes = [Node(scenario, i, bus, run_id, variant, objective=objective) for i in scenario.ids]
    collector = Collector(scenario, bus, run_id)
    bar = Progress(scenario.steps, "inmemory", enabled=progress)
    vehicle.advance()
    while not vehicle.done:
        bus.pump()
        stepped = False
        for n in nodes:
            while n.try_step():
                stepped = True
                bus.pump()
        bus.pump()
        if vehicle.ready_to_advance():
            bar.update(vehicle.k)
            vehicle.advance()
        elif not stepped:
            # in one process a message that has not arrived never will: proceed without it
            for n in nodes:
                if n.missing():
                    n.give_up = True
    bus.pump()
    bar.close()
    meta = run_meta(scenario, "inmemory", "lockstep", signals, variant, seed, run_id, objective)
    summary, parts = collector.finish(meta)
    return RunResult(summary, meta, parts)
