"""The network part's report: the ceiling column is the node alone over the exact limit, the most any sound
network estimator could make ``alone / network`` (docs/network.md, *What no network can reach*)."""

from __future__ import annotations

import json
from pathlib import Path


from netsetest_bench.network import network_markdown

ROOT = Path(__file__).resolve().parents[2]


def _node(alone_over_network: float, network_over_exact: float | None) -> dict:
    return {
        "fault": None,
        "r": None,
        "sdp_alone_over_network": alone_over_network,
        "sdp_network_over_exact": network_over_exact,
        "sdp_r_over_exact": 2.0,
        "sdp_beta_over_exact": 3.0,
        "delay_network": None,
        "delay_alone": None,
    }


def test_the_ceiling_is_the_node_alone_over_exact_and_leaves_out_a_declared_zero_fault() -> None:
    run = {
        "topology": "t",
        "case": "nsnim",
        "signals": "paper",
        "seed": 0,
        "exact": False,
        "nodes": {"1": _node(1.5, 1.2), "2": _node(1.0, None), "3": _node(1.1, 1.05)},
    }
    text = network_markdown({"steps": 80, "seeds": [0], "runs": [run]})
    row = next(line for line in text.splitlines() if line.startswith("| `t` |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[3] == "1.000–1.500" and cells[4] == "1.05–1.20"
    assert cells[5] == "1.16–1.80"  # 1.1·1.05 and 1.5·1.2; node 2 (no exact width: a declared-zero fault) left out


def test_no_committed_node_is_narrower_than_exact_so_the_ceiling_bounds_the_gain() -> None:
    """In the committed figures every node's network width is at least the exact limit's (nothing sound is
    narrower): alone / network never exceeds the ceiling the report prints."""
    res = json.loads((ROOT / "bench" / "network.json").read_text())
    res = res.get("network", res)
    checked = 0
    for run in res["runs"]:
        for node in run["nodes"].values():
            over = node["sdp_network_over_exact"]
            if over is None:
                continue
            assert over >= 1.0 - 1e-9, (run["topology"], run["case"], run["signals"], node)
            checked += 1
    assert checked >= 60
