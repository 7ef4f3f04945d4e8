"""The one-step coverage rule (docs/coverage.md) against the transitive rule it replaced, on runs where both
can be decided: every node-step the transitive rule covered is still covered, unless an input it used
missed the truth (then the step's premise was false and it is honestly not covered); and the one-step
rule covers more where only an unjudgeable or broken step lies upstream."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import pytest

from netsetest.config.schema import load_topology
from netsetest.runtime.inmemory import run_inmemory

ROOT = Path(__file__).resolve().parents[2]
OWN_CAUSES = {"sector", "noise", "fault bound", "initial set", "truth unknown", "disturbance"}


def _transitive(parts: dict) -> dict[tuple[int, int], bool]:
    """The previous rule, recomputed from the record: covered iff the step's own assumptions held and every
    input (neighbours used, and the node itself) was covered, judged and uncontested at the step before."""
    rows = {(int(i), e["step"]): e for i, es in parts["nodes"].items() for e in es}
    last = max(k for _, k in rows)
    ids = sorted({i for i, _ in rows})
    old: dict[tuple[int, int], bool] = {}
    for k in range(last + 1):
        for i in ids:
            e = rows.get((i, k))
            if e is None:
                continue
            own = e["assumptions_ok"] or e["not_covered_cause"] in ("inherited", "fallback")
            deps = [] if k == 0 else [*e["used"], i]
            old[(i, k)] = (
                own
                and all(old.get((j, k - 1), False) and not rows[(j, k - 1)]["contested"] for j in deps if (j, k - 1) in rows)
                and all((j, k - 1) in rows for j in deps)
            )
    return old


def _compare(parts: dict) -> tuple[int, int]:
    old = _transitive(parts)
    new_only = old_only = 0
    for i, es in parts["nodes"].items():
        for e in es:
            if not e["judged"]:
                continue
            o, n = old[(int(i), e["step"])], e["assumptions_ok"]
            if o and not n:
                assert e["not_covered_cause"] == "inherited" and e["inherited_from"][2] == "missed the truth", (i, e)
                old_only += 1
            new_only += n and not o
    return new_only, old_only


@pytest.mark.parametrize("case,signals", [("nsnim", "paper"), ("saim", "paper"), ("saim", "worst")])
def test_one_step_rule_covers_what_the_transitive_rule_covered(case: str, signals: str) -> None:
    for topo in ("paper6.toml", "paper6_lossy.toml"):
        res = run_inmemory(load_topology(ROOT / "topologies" / topo, case, 40), signals, "scheduled", 3)
        new_only, old_only = _compare(res.parts)
        assert old_only == 0 and res.summary.violations_total == 0


def test_a_false_fault_bound_costs_only_the_steps_that_rest_on_it(tmp_path: Path) -> None:
    """Node 2 declares a fault rate its own fault breaks: its SAIM sector rests on a false premise. The
    transitive rule took every later step of every node that ever heard from it out of the guarantee; the
    one-step rule keeps every step whose inputs held the truth and whose facts held."""
    (tmp_path / "topologies").mkdir()
    shutil.copy(ROOT / "topologies" / "paper6.toml", tmp_path / "topologies" / "paper6.toml")
    shutil.copytree(ROOT / "nodes", tmp_path / "nodes")
    prof = tmp_path / "nodes" / "yaw2.toml"
    prof.write_text(prof.read_text().replace("rate = 0.2", "rate = 0.001"))
    sc = load_topology(tmp_path / "topologies" / "paper6.toml", "saim", 40)
    # the states' cone alone: with bounded readings the nodes reading node 2's reading rest on its bound too, and inherit
    # "fault bound" from it (tests/inmemory/test_network_sets.py), which no transitive rule over states knew
    res = run_inmemory(dataclasses.replace(sc, bounded_readings=False), "paper", "scheduled", 3)
    s = res.summary
    assert s.node_steps_not_covered.get("sector", 0) > 0  # the sector's premise (the fault bound) broke, named
    new_only, old_only = _compare(res.parts)
    assert old_only == 0 and new_only > 0
    assert s.violations_total == 0
