"""The benchmark's exact part (``netsetest bench --only exact``): what ``netsetest exact`` costs under k-of-N health.

Per topology and case, worst-case signals, seed 0: the run's record (in memory, not timed), then the exact limit
with every declared health group applied (analysis/exact.py, its branch and bound analysis/kofn.py) in a process of
its own (:func:`measure_one`, ``python -m netsetest_bench.exact_cost``), so that its CPU time and its peak resident
memory are its own: CPU seconds of the exact limit alone (the machine is shared: wall time says little), peak
resident memory of the whole process (imports and the record included), the resident memory after every step
(flat: what the search keeps does not grow with it), and how many ends are exact, relaxed, and the solves.

Topologies: ``paper6_max_faulty`` (at most 4 of 6 faulty) and rings with chords of 12 and 24 nodes with issue 34's
two interleaved groups (netsetest_bench/topologies.py, variant ``two_groups``).  Then issue 44's target: on the 12-node
ring with two groups, SAIM, worst-case signals, the config's seeds (``exact_network_seeds``), the central limit and each node's network
limit (``exact --network``, docs/exact.md), each in a process of its own; the network row times the network limit as
the command computes it, given the central limit (computed first in the same process, not timed: the central row times
it), whose boxes each node's program imports.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Literal

from netsetest.scenarios import TOPOLOGY_DIR
from netsetest_bench.figures.exact_cost import ExactRun
from netsetest_bench.figures.exact_cost import load as load_exact_cost
from netsetest_bench.render import fill
from netsetest_bench.config import BenchConfig

CASES = ("nsnim", "saim")
RINGS = (12, 24)  # ring sizes with two groups
SIGNALS: Literal["worst"] = "worst"
# targets (issue 34): the 12-node ring's SAIM run and paper6_max_faulty's, on one core
TARGET_RING12_CPU_S = 120.0
TARGET_RING12_PEAK_MB = 1024.0
TARGET_RING12_EXACT = 0.95  # share of ends exact
TARGET_PAPER6_CPU_S = 20.0
FLAT_MB = 64.0  # resident memory may grow by this from the middle step to the last (the programs grow with the horizon)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _rss_mb() -> float:
    """This process's resident memory now (MB), from /proc (NaN where there is none)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, IndexError, ValueError):
        return float("nan")
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def measure_one(topology: str, case: str, record: str, budget_s: float | None, network: bool = False) -> dict:
    """The exact limit of one record in this process (``network``: each node's network limit as ``exact --network``
    computes it, given the central limit, which is computed first and not timed: its own row times it): CPU, wall,
    peak and per-step resident memory, and the search."""
    from netsetest.analysis.exact import exact_bounds, network_limit
    from netsetest.config.schema import load_topology
    from netsetest.records.record import load_record

    rec = load_record(record)
    sc = load_topology(topology, case, rec.meta.steps)  # type: ignore[arg-type]  # one of CASES
    rss: list[float] = []
    central = exact_bounds(sc, rec, "used", budget_s=budget_s) if network else None
    t0, w0 = time.process_time(), time.perf_counter()

    def on_step(k: int, total: int) -> None:
        rss.append(_rss_mb())

    ex = (
        exact_bounds(sc, rec, "used", progress=on_step, budget_s=budget_s)
        if central is None
        else network_limit(sc, rec, central, progress=on_step, budget_s=budget_s)
    )
    cpu, wall = time.process_time() - t0, time.perf_counter() - w0
    rss.append(_rss_mb())
    h = ex.health
    return {
        "cpu_s": cpu,
        "wall_s": wall,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,  # Linux: KiB
        "rss_mb": rss,  # before each step, then after the last
        "ends": None if h is None else h.ends,
        "exact_ends": None if h is None else h.exact_ends,
        "relaxed_ends": None if h is None else len(h.relaxed),
        "solves": None if h is None else h.solves,
        "out_of_time": None if h is None else h.out_of_time,
        "budget_s": budget_s,
        "infeasible_steps": list(ex.infeasible_steps),
    }


def _measure(topology: Path, case: str, record: Path, budget_s: float, network: bool = False) -> dict:
    """:func:`measure_one` in a process of its own (its peak memory is then the exact limit's alone)."""
    from netsetest.runtime.processes import role_env

    out = subprocess.run(
        [sys.executable, "-m", "netsetest_bench.exact_cost", str(topology), case, str(record), repr(budget_s), *(["network"] if network else [])],
        capture_output=True,
        text=True,
        check=True,
        env=role_env(),
    )
    return json.loads(out.stdout)


def exact_figures(cfg: BenchConfig, tmp: Path) -> dict:
    from netsetest.analysis.errors import DEFAULT_BUDGET_S
    from netsetest_bench.topologies import ring_topology
    from netsetest.config.schema import load_topology
    from netsetest.runtime.inmemory import run_inmemory

    steps = cfg.exact_steps
    load_before = _load()
    rows = []
    runs = [("paper6_max_faulty", 0, DEFAULT_BUDGET_S), *((f"ring{n}, two groups", n, budget) for n, budget in cfg.exact_rings)]
    for name, n, budget in runs:  # smallest first
        for case in CASES:
            topo = TOPOLOGY_DIR / f"{name}.toml" if not n else ring_topology(tmp, n, steps, case, variant="two_groups")
            sc = load_topology(topo, case, steps)  # type: ignore[arg-type]  # one of CASES
            record = tmp / "exact_record.json"
            run_inmemory(sc, SIGNALS, "scheduled", 0, record=str(record), keep=False)
            row = {"topology": name, "nodes": len(sc.ids), "case": case, "signals": SIGNALS, "steps": steps, **_measure(topo, case, record, budget)}
            record.unlink()
            rows.append(row)
            _log(
                f"  exact {name} {case}: {row['cpu_s']:.1f} s CPU ({row['wall_s']:.0f} s wall), peak {row['peak_mb']:.0f} MB, "
                f"{row['exact_ends']} of {row['ends']} ends exact"
            )
    return {
        "steps": steps,
        "rows": rows,
        "network": network_rows(tmp, steps, cfg.exact_network_seeds),
        "load": f"{load_before} before, {_load()} after",
    }


def network_rows(tmp: Path, steps: int, seeds: list[int] | tuple[int, ...]) -> list[dict]:
    """Issue 44's target: the 12-node ring with two groups, SAIM, worst-case signals, per seed, the central limit and
    each node's network limit, each in a process of its own (the command's default budget)."""
    from netsetest.analysis.errors import DEFAULT_BUDGET_S
    from netsetest_bench.topologies import ring_topology
    from netsetest.config.schema import load_topology
    from netsetest.runtime.inmemory import run_inmemory

    topo = ring_topology(tmp, 12, steps, "saim", variant="two_groups")
    sc = load_topology(topo, "saim", steps)
    rows = []
    for seed in seeds:
        record = tmp / "exact_record.json"
        run_inmemory(sc, SIGNALS, "scheduled", seed, record=str(record), keep=False)
        for network in (False, True):
            row = {"topology": "ring12, two groups", "nodes": 12, "case": "saim", "signals": SIGNALS, "steps": steps, "seed": seed}
            row |= {"limit": "network" if network else "central", **_measure(topo, "saim", record, DEFAULT_BUDGET_S, network)}
            rows.append(row)
            _log(
                f"  exact{' --network' if network else ''} ring12 seed {seed}: {row['cpu_s']:.1f} s CPU, peak {row['peak_mb']:.0f} MB, {row['exact_ends']} of {row['ends']} ends exact"
            )
        record.unlink()
    return rows


def _load() -> str:
    """The 1, 5 and 15 minute load averages: the machine is shared, and wall time says how busy it was."""
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def targets(rows: list[ExactRun]) -> list[tuple[str, str, bool]]:
    """(what, target, met) for issue 34's targets, from the rows that have them."""
    out = []
    for r in rows:
        if r.topology == "ring12, two groups" and r.case == "saim" and r.steps >= 80:
            share = r.exact_ends / r.ends
            out += [
                ("ring12 SAIM worst: CPU", f"≤ {TARGET_RING12_CPU_S:g} s", r.cpu_s <= TARGET_RING12_CPU_S),
                ("ring12 SAIM worst: peak memory", f"≤ {TARGET_RING12_PEAK_MB:g} MB", r.peak_mb <= TARGET_RING12_PEAK_MB),
                ("ring12 SAIM worst: ends exact", f"≥ {100 * TARGET_RING12_EXACT:g} %", share >= TARGET_RING12_EXACT),
            ]
        if r.topology == "paper6_max_faulty" and r.case == "saim":
            out.append(("paper6_max_faulty SAIM worst: CPU", f"≤ {TARGET_PAPER6_CPU_S:g} s", r.cpu_s <= TARGET_PAPER6_CPU_S))
    out.append(("every run: memory flat", f"≤ {FLAT_MB:g} MB from the middle step to the last", all(r.growth() <= FLAT_MB for r in rows)))
    return out


def exact_cost_markdown(doc: dict) -> str:
    """One row per run: CPU, peak and growth of resident memory, the ends; then the targets."""
    e = load_exact_cost(doc)
    T = "exact_cost"
    lines = [fill(T, "head", e=e)]
    lines += [fill(T, "row", r=r, case=r.case.upper(), growth=r.growth()) for r in e.rows]
    lines.append(fill(T, "targets-head"))
    lines += [fill(T, "target-row", what=what, target=target, met="yes" if met else "no") for what, target, met in targets(e.rows)]
    if e.network:
        lines.append(fill(T, "network-head", steps=e.network[0].steps, cpu_s=TARGET_RING12_CPU_S, peak_mb=TARGET_RING12_PEAK_MB))
        for r in e.network:
            met = r.cpu_s <= TARGET_RING12_CPU_S and r.peak_mb <= TARGET_RING12_PEAK_MB
            lines.append(fill(T, "network-row", r=r, met="yes" if met else fill(T, "not-met")))
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # measure_one in a process of its own: TOPOLOGY CASE RECORD BUDGET_S [network]
    topology, case, record, budget = sys.argv[1:5]
    print(json.dumps(measure_one(topology, case, record, float(budget), sys.argv[5:] == ["network"])))


__all__ = ["exact_cost_markdown", "exact_figures", "measure_one", "targets"]
