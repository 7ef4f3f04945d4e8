"""The benchmark's network figures (docs/network.md): what the exchange between nodes can buy at best.

Per scenario, case and signals: each node's exact limit from its own data alone over the exact limit from
every node's data (``netsetest exact --local``), mean width from step 10, for its own fault and the yaw
rate. ``paper6``: the paper's assumptions (every fault free at every step); ``paper6_reference``: sensor 3
declared fault-free. The estimators do not exchange same-step data yet, so these are the limits an
exchange could reach, not what the SDP network reaches.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from netsetest.scenarios import TOPOLOGY_DIR

SCENARIOS = ("paper6", "paper6_reference")


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def network_figures(cfg: dict, tmp: Path) -> dict:
    from netsetest.analysis.exact import local_limits
    from netsetest.config.schema import load_topology
    from netsetest.records.record import load_record
    from netsetest.runtime.inmemory import run_inmemory

    rows = []
    for name in SCENARIOS:
        for case in ("nsnim", "saim"):
            sc = load_topology(TOPOLOGY_DIR / f"{name}.toml", case, cfg["network_steps"])
            for sig in ("paper", "worst"):
                for seed in cfg["network_seeds"]:
                    path = tmp / "network.json"
                    run_inmemory(sc, sig, "scheduled", seed, record=str(path), keep=False)
                    limits = local_limits(sc, load_record(str(path)))
                    rows.append({"topology": name, "case": case, "signals": sig, "seed": seed,
                                 "nodes": {lim.node: {"fault": _num(lim.fault_ratio), "r": _num(lim.r_ratio)} for lim in limits}})
                    faults = [v["fault"] for v in rows[-1]["nodes"].values() if v["fault"] is not None]
                    _log(f"  {name} {case} {sig} seed {seed}: own fault local/central {min(faults):.3f}–{max(faults):.3f}")
    return {"steps": cfg["network_steps"], "seeds": cfg["network_seeds"], "runs": rows}


def _num(v: float) -> float | None:
    return None if math.isnan(v) else v


def network_markdown(res: dict) -> str:
    """The README's "When the network helps" table."""
    seeds = ", ".join(map(str, res["seeds"]))
    lines = [f"Exact limit from the node's own data over the exact limit from every node's data (mean width from step 10; "
             f"{res['steps']} steps, seeds {seeds}, mean over the seeds; `declared 0`: the reference's own fault):", "",
             "| topology | case | signals | own fault, node 1 … 6 | yaw rate, every node |", "|---|---|---|---|---|"]
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for r in res["runs"]:
        groups.setdefault((r["topology"], r["case"], r["signals"]), []).append(r)
    for (topo, case, sig), runs in groups.items():
        ids = sorted(runs[0]["nodes"], key=int)
        faults = []
        for i in ids:
            vals = [r["nodes"][i]["fault"] for r in runs]
            faults.append("declared 0" if any(v is None for v in vals) else f"{sum(vals) / len(vals):.2f}")
        rs = [r["nodes"][i]["r"] for r in runs for i in ids if r["nodes"][i]["r"] is not None]
        lines.append(f"| `{topo}` | {case} | {sig} | {' / '.join(faults)} | {min(rs):.2f}–{max(rs):.2f} |")
    return "\n".join(lines) + "\n"


__all__ = ["network_figures", "network_markdown"]
