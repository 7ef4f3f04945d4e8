"""A run in memory saved as a record and loaded back: what the record-based tests start from."""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

import numpy as np

from netsetest.analysis.exact import step_data
from netsetest.config.schema import Scenario, load_topology
from netsetest.estimator.base import SetEstimator, StepInput
from netsetest.records.record import Record, load_record, save_record
from netsetest.runtime.inmemory import RunResult, run_inmemory

PAPER6 = "topologies/paper6.toml"
ROOT = Path(__file__).resolve().parents[1]
MIXED = {4: "zonotope", 5: "interval", 6: "strip"}  # the mixed network: nodes 1–3 the SDP


@cache
def recorded_run(case: str, signals: str, seed: int, steps: int, tmp: str) -> tuple[Scenario, Record]:
    """The paper network run in memory (scheduled variant), its record written to ``tmp`` and loaded."""
    sc = load_topology(PAPER6, case, steps)
    res = run_inmemory(sc, signals, "scheduled", seed)
    path = f"{tmp}/{case}-{signals}-{seed}-{steps}.json"
    save_record(path, res.meta, res.parts["truth"], res.parts["nodes"], res.summary)
    return sc, load_record(path)


@cache
def shared_run(case: str, signals: str, seed: int, steps: int | None = None, topology: str = "paper6") -> RunResult:
    """A bundled network's in-memory run (scheduled variant), made once per session (under pytest-xdist: once
    per worker, so shared between modules that land on the same one) and shared by the tests that only read it
    (test_containment, test_sector, test_fdi ask for the same paper6 runs): a test must never change what it
    gets; one that checks that runs repeat runs its own."""
    return run_inmemory(load_topology(ROOT / "topologies" / f"{topology}.toml", case, steps), signals, "scheduled", seed)


def mixed_topology(tmp: Path, estimators: dict[int, str] = MIXED) -> Path:
    """paper6 with a per-node ``estimator`` in its [[nodes]] tables (tests/inmemory/test_mixed_network.py,
    tests/process/test_zenoh_mixed.py)."""
    text = (ROOT / "topologies/paper6.toml").read_text()
    text = text.replace('node_dir = "../nodes"', f'node_dir = "{ROOT / "nodes"}"')
    for i, name in estimators.items():
        text, n = re.subn(rf"(\[\[nodes\]\]\nid = {i}\nprofile = \"[^\"]+\")", rf'\1\nestimator = "{name}"', text)
        assert n == 1
    path = tmp / "mixed.toml"
    path.write_text(text)
    return path


def stepped_bounds(est: SetEstimator, rec: Record, node: int) -> np.ndarray:
    """(K, 3, 2) the bounds ``est`` publishes stepped through node ``node``'s data of the record."""
    out, prev = [], None
    for d in step_data(rec):
        inp = StepInput(d.step, d.y[node], d.gamma[node], None if prev is None else prev.u, None if prev is None else prev.vx)
        lo, hi = est.step(inp).bounds()
        out.append(np.stack([lo, hi], axis=1))
        prev = d
    return np.array(out)
