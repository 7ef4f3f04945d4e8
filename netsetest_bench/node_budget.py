"""The benchmark's per-message budget of a node (``netsetest bench --only node``, issue 31).

A real-time ring (bench/topologies.py, τs = 0.1 s) with every node profiled (``run --profile``,
netsetest/profile.py), a few runs; per node and run, from its profile:

- the node's CPU per step (``process``: every thread), the estimator's step beside it (``solve``) and
  what the node spends outside it (``process − solve``), split as the profile splits it (its own
  thread's phases, ``other``, and ``threads``: Zenoh's runtime and subscriber callbacks);
- the messages it received (payloads the bus took from the transport, those screened out undecoded
  too; a checkout whose profile does not count them: its decodes, one per payload) and sent (its puts)
  per step;
- per received message: the CPU its own thread spent on them (``decode`` + ``handle``) over their
  number; per sent message: ``build`` + ``encode`` + ``put`` over theirs; Zenoh's and the callbacks'
  threads over every message, received or sent (what they do per message: TLS, routing, the callback).

Beside them, Zenoh's floor (netsetest_bench/bus_floor.py): a bare bus process receiving and sending the ring's
typical node's messages at the ring's τs, secured as ``netsetest run`` and ``--insecure``, without estimator or
handling: what the bus alone costs that node per step, every thread, one run of each per run of the ring.

Figures are the median over the nodes of a run, then the median over the runs (with their range).  With
a baseline (``--baseline DIR``, another checkout, say main's), its runs alternate with this checkout's,
the same ring and the same number of runs, and each figure is also given as the ratio of the two
medians: on a machine other work loads, only such side-by-side ratios compare two versions.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
from pathlib import Path

from netsetest_bench import bus_floor
from netsetest_bench.figures.node import FloorSummary, Node, NodeSummary, Range
from netsetest_bench.figures.node import load as load_node
from netsetest_bench.render import MISSING, fill
from netsetest_bench.zenoh_runs import profiled_ring_run
from netsetest_bench.config import BenchConfig

OUTSIDE = ("wait", "decode", "handle", "build", "encode", "put", "other", "threads")  # profile phases outside the estimator
FIGURES = (  # key, what, unit: the rows of the table
    ("process_us", "the node's CPU per step, every thread", "µs"),
    ("solve_us", "the estimator's step (`solve`)", "µs"),
    ("outside_us", "outside the estimator (process − solve)", "µs"),
    ("outside_ratio", "node CPU per step / estimator step", "×"),
    *((f"{p}_us", f"… of it `{p}`", "µs") for p in OUTSIDE),
    ("received", "messages received per step", ""),
    ("sent", "messages sent per step", ""),
    ("per_received_us", "per received message, the node's thread (decode + handle)", "µs"),
    ("per_sent_us", "per sent message, the node's thread (build + encode + put)", "µs"),
    ("threads_per_message_us", "per message received or sent, the other threads (Zenoh, callbacks)", "µs"),
    ("outside_per_message_us", "per message received or sent, everything outside the estimator", "µs"),
)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def node_budget(report: dict) -> dict[str, float]:
    """The budget figures (:data:`FIGURES`) of one node's profile report (netsetest/profile.py)."""
    us = {p: 1000.0 * v["ms_per_step"] for p, v in report["phases"].items()}
    process, solve = 1000.0 * report["process_ms_per_step"], us["solve"]
    counted = report.get("messages_per_step")
    received = counted["received"] if counted else report["phases"]["decode"]["calls_per_step"]
    sent = counted["sent"] if counted else report["phases"]["put"]["calls_per_step"]
    per = lambda cpu, n: cpu / n if n > 0 else float("nan")  # noqa: E731  # a one-line local helper
    return {
        "process_us": process,
        "solve_us": solve,
        "outside_us": process - solve,
        "outside_ratio": per(process, solve),
        **{f"{p}_us": us[p] for p in OUTSIDE},
        "received": received,
        "sent": sent,
        "per_received_us": per(us["decode"] + us["handle"], received),
        "per_sent_us": per(us["build"] + us["encode"] + us["put"], sent),
        "threads_per_message_us": per(us["threads"], received + sent),
        "outside_per_message_us": per(process - solve, received + sent),
    }


THIS_CHECKOUT = Path(__file__).resolve().parents[1]  # the repository the benchmark runs from (netsetest_bench/ is at its top)


def checkout_commit(checkout: Path) -> str | None:
    """The commit a checkout's code is at (None: not a git checkout), so the table says which code it measured."""
    out = subprocess.run(["git", "-C", str(checkout), "rev-parse", "--short=12", "HEAD"], capture_output=True, text=True, check=False)
    return out.stdout.strip() or None if out.returncode == 0 else None


def _median_over_nodes(reports: list[dict]) -> dict[str, float]:
    budgets = [node_budget(r) for r in reports]
    return {key: statistics.median(b[key] for b in budgets) for key, _, _ in FIGURES}


def _profiled(tmp: Path, nodes: int, steps: int, code: Path | None) -> dict:
    r, reports, load = profiled_ring_run(tmp, nodes, steps, code=code)
    s = r["summary"] or {}
    return {
        "exit_code": r["exit_code"],
        "load_before": load,
        "profiled_nodes": len(reports),
        "deadline_misses": sum(row.get("deadline_misses") or 0 for row in s.get("nodes", [])) if s else None,
        "figures": _median_over_nodes(reports) if reports else None,
    }


def _summary(runs: list[dict]) -> dict:
    """Median and range over the runs of each figure (the runs whose nodes reported)."""
    ok = [r["figures"] for r in runs if r["figures"]]
    if not ok:
        return {}
    return {key: {"median": statistics.median(f[key] for f in ok), "min": min(f[key] for f in ok), "max": max(f[key] for f in ok)} for key, _, _ in FIGURES}


FLOOR_MODES = {"secured": True, "insecure": False}  # the bare bus process's runs: as `netsetest run`, and `--insecure`
TARGET_OUTSIDE_US = 300.0  # issue 31's target: a node's CPU per step outside the estimator


def _floor_payloads(tmp: Path, nodes: int, steps: int) -> tuple[Path, bus_floor.RingPayloads]:
    """The ring of the profiled runs and the payloads of its typical node (bus_floor.py)."""
    from netsetest_bench.topologies import ring_topology
    from netsetest.config.schema import load_topology

    directory = tmp / "floor"
    directory.mkdir(exist_ok=True)
    topo = ring_topology(directory, nodes, steps)
    sc = load_topology(str(topo))
    return topo, bus_floor.ring_payloads(sc, bus_floor.median_node(sc))


def node_figures(cfg: BenchConfig, tmp: Path, baseline: Path | None = None) -> dict:
    """The per-message budget (module doc); ``baseline``: a checkout measured alternately beside this one."""
    nodes, steps, reps = cfg.node_budget_nodes, cfg.rt_steps, cfg.node_budget_reps
    codes: dict[str, Path | None] = {"this": None, **({"baseline": baseline} if baseline is not None else {})}
    runs: dict[str, list[dict]] = {name: [] for name in codes}
    floor = _floor_payloads(tmp, nodes, steps)
    floor_runs: dict[str, list[dict]] = {mode: [] for mode in FLOOR_MODES}
    for rep in range(reps):
        for name, code in codes.items():
            row = _profiled(tmp, nodes, steps, code)
            runs[name].append(row)
            f = row["figures"] or {}
            _log(
                f"  {name} run {rep + 1}/{reps} ({nodes} nodes, load {row['load_before']}): exit {row['exit_code']}, "
                f"{row['deadline_misses']} deadline misses; {f.get('process_us', float('nan')):.0f} µs per step, "
                f"{f.get('outside_us', float('nan')):.0f} outside the estimator"
            )
        for mode, secured in FLOOR_MODES.items():
            row = bus_floor.floor_run(floor[0], floor[1], secured, tmp)
            floor_runs[mode].append(row)
            _log(
                f"  bare bus ({mode}) run {rep + 1}/{reps} (node {floor[1].node}, load {row['load_before']}): "
                + (row["error"] if "error" in row else f"{row['process_us']:.0f} µs per step, {row['threads_us']:.0f} of it Zenoh's threads")
            )
    out: dict = {"nodes": nodes, "steps": steps, "reps": reps, "baseline_code": str(baseline) if baseline is not None else None}
    out["commits"] = {name: checkout_commit(code or THIS_CHECKOUT) for name, code in codes.items()}
    out.update({name: {"runs": rows, "summary": _summary(rows)} for name, rows in runs.items()})
    out["floor"] = {
        "node": floor[1].node,
        "in_neighbours": len(floor[1].others),
        **{m: {"runs": r, "summary": bus_floor.floor_summary(r)} for m, r in floor_runs.items()},
    }
    if baseline is not None and out["this"]["summary"] and out["baseline"]["summary"]:
        this, base = out["this"]["summary"], out["baseline"]["summary"]
        out["ratio"] = {key: this[key]["median"] / base[key]["median"] if base[key]["median"] else None for key, _, _ in FIGURES}
    return out


def _number(v: float | None) -> float | None:
    """A figure the table prints; NaN (no messages to divide by) is one it lacks."""
    return None if v is None or v != v else v


def _range(r: Range | None, spec: str) -> str:
    if r is None:
        return MISSING
    return fill("node", "range", median=_number(r.median), lo=_number(r.min), hi=_number(r.max), spec=spec)


def node_markdown(doc: dict) -> str:
    n = load_node(doc)
    T = "node"
    this, base = n.this.summary, n.baseline.summary if n.baseline is not None else None
    runs = "; ".join(fill(T, "run", r=r) for r in n.this.runs)
    head = fill(T, "head", n=n, runs=runs, node_steps=n.nodes * (n.steps + 1))
    if base is not None and n.baseline is not None:
        head += fill(T, "with-baseline", n=n, runs="; ".join(fill(T, "run", r=r) for r in n.baseline.runs))
    if this is None:
        return "\n".join([head, fill(T, "none")])
    lines = [
        head,
        fill(T, "table-head", baseline_head=fill(T, "baseline-head") if base else "", baseline_rule=fill(T, "baseline-rule") if base else ""),
    ]
    for key, what, unit in FIGURES:
        spec = ".2f" if unit in ("×", "") else ".0f"
        baseline = fill(T, "baseline-cells", cell=_range(getattr(base, key), spec), ratio=_number(n.ratio.get(key))) if base else ""
        lines.append(fill(T, "row", what=what, unit=fill(T, "unit", unit=unit) if unit else "", this=_range(getattr(this, key), spec), baseline=baseline))
    return "\n".join(lines) + "\n" + floor_markdown(n)


def floor_markdown(n: Node) -> str:
    """Zenoh's floor beside the ring's node: the bare bus process's figures, secured and ``--insecure``."""
    fl, T = n.floor, "node"
    if not fl:
        return ""
    sec, ins, node = fl.secured.summary, fl.insecure.summary, n.this.summary
    loads = "; ".join(
        fill(
            T,
            "floor-loads",
            mode=m,
            runs=", ".join(fill(T, "floor-run", r=r) + (fill(T, "floor-error", error=r.error) if r.error else "") for r in fl.mode(m).runs),
        )
        for m in FLOOR_MODES
    )
    node_of = _as_floor(node)  # the ring's node, the same figures (its profile, above; per message: its solve is in its CPU)
    lines = [fill(T, "floor-head", fl=fl, loads=loads)]
    for key, what, unit in bus_floor.FIGURES:
        spec = ".2f" if unit == "" else ".0f"
        cells = {name: _range(getattr(s, key), spec) if s else MISSING for name, s in (("secured", sec), ("insecure", ins), ("node", node_of))}
        lines.append(fill(T, "floor-row", what=what, unit=fill(T, "unit", unit=unit) if unit else "", **cells))
    if sec is not None and sec.process_us is not None:
        process = sec.process_us.median
        verdict = fill(T, "above" if process > TARGET_OUTSIDE_US else "within", target=TARGET_OUTSIDE_US)
        lines.append(fill(T, "floor-tail", process=_number(process), threads=_number(sec.threads_us.median if sec.threads_us else None), verdict=verdict))
    return "\n".join(lines) + "\n"


def _as_floor(node: NodeSummary | None) -> FloorSummary | None:
    """The ring's node's figures under the bare bus's names; its own thread: its process less its other threads."""
    if node is None:
        return None
    p, t = node.process_us, node.threads_us
    thread = Range(p.median - t.median, p.min - t.min, p.max - t.max) if p is not None and t is not None else None
    return FloorSummary(
        process_us=p,
        thread_us=thread,
        decode_us=node.decode_us,
        wait_us=node.wait_us,
        put_us=node.put_us,
        threads_us=t,
        received=node.received,
        sent=node.sent,
    )
