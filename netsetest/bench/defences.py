"""Benchmarks of the defences inside the roles: memory under a long run, stepping under a flood.

- ``flood``: the paper scenario in memory while a thread publishes forged inputs for node 2 (a step
  after the run) at ``rate`` messages per second on node 2's input key — a flood at one node — against
  the same run without the flood.  The flooder runs in the same process (and under the same GIL) as the
  roles, so the figure includes the attacker's own cost; a flood from another process costs the victim
  only the receiving side.  The per-key bounded inbox and a pump that handles at most what was
  queued when it started keep the run stepping (the issue's bound: at least half the normal rate).
The RSS slope over a long run is :mod:`netsetest.bench.soak`.
"""

from __future__ import annotations

import threading
import time

FLOOD_BATCH_S = 0.01  # the flooder publishes a batch every 10 ms


def _forged(target: str, steps: int) -> tuple[str, bytes]:
    """Key and payload of the flood: node 2's input key (one subscriber), or node 3's state key (heard
    by nodes 2 and 4, the vehicle and the collector: in memory, four subscribers in one process)."""
    from netsetest.bus import keys
    from netsetest.messages import NodeInput, NodeState, encode

    if target == "input":
        return keys.node_input("mem", 2), encode(NodeInput(step=steps + 1, node=2, y=0.0, gamma=1.0))
    state = NodeState(step=1, node=3, xhat=[0.0] * 3, P=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], rho=1.0, gamma=1.0, innov=1e3, status="ok")
    return keys.node_state("mem", 3), encode(state)


def flood(steps: int, rate: float, topology_path: str, target: str = "input") -> dict:
    from netsetest.bus.base import MemoryBus
    from netsetest.config.schema import load_topology
    from netsetest.runtime.inmemory import run_inmemory

    sc = load_topology(topology_path, None, steps)

    def one(flood_rate: float) -> dict:
        bus = MemoryBus()
        stop = threading.Event()
        sent = [0]
        key, payload = _forged(target, steps)
        per_batch = max(1, int(flood_rate * FLOOD_BATCH_S))

        def flooder() -> None:
            next_t = time.perf_counter()
            while not stop.is_set():
                for _ in range(per_batch):
                    bus.inject(key, payload)
                sent[0] += per_batch
                next_t += FLOOD_BATCH_S
                time.sleep(max(0.0, next_t - time.perf_counter()))

        th = threading.Thread(target=flooder, daemon=True)
        t0 = time.perf_counter()
        if flood_rate > 0:
            th.start()
        res = run_inmemory(sc, bus=bus, keep=False)
        wall = time.perf_counter() - t0
        stop.set()
        if flood_rate > 0:
            th.join(5)
        return {
            "steps_per_s": steps / wall, "wall_s": wall, "sent": sent[0], "sent_per_s": sent[0] / wall,
            "violations": res.summary.violations_total, "steps_completed": res.summary.steps_completed,
            "dropped": dict(bus.dropped), "drops": res.summary.drops,
        }  # fmt: skip

    base = one(0.0)
    flooded = one(rate)
    return {"steps": steps, "rate": rate, "target": target, "none": base, "flood": flooded,
            "ratio": flooded["steps_per_s"] / base["steps_per_s"]}  # fmt: skip
