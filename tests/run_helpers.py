"""A run in memory saved as a record and loaded back: what the record-based tests start from."""

from __future__ import annotations

from functools import cache

from netsetest.config.schema import Scenario, load_topology
from netsetest.records.record import Record, load_record, save_record
from netsetest.runtime.inmemory import run_inmemory

PAPER6 = "topologies/paper6.toml"


@cache
def recorded_run(case: str, signals: str, seed: int, steps: int, tmp: str) -> tuple[Scenario, Record]:
    """The paper network run in memory (scheduled variant), its record written to ``tmp`` and loaded."""
    sc = load_topology(PAPER6, case, steps)
    res = run_inmemory(sc, signals, "scheduled", seed)
    path = f"{tmp}/{case}-{signals}-{seed}-{steps}.json"
    save_record(path, res.meta, res.parts["truth"], res.parts["nodes"], res.summary)
    return sc, load_record(path)
