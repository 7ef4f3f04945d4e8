"""bench/node_budget.py (``netsetest bench --only node``): the per-message budget computed from a node's
profile report (netsetest/profile.py), with and without the message counters (a baseline checkout's
profile has none), its table, and ``--baseline`` refused where it means nothing."""

from __future__ import annotations

import math
import sys

import pytest

from netsetest_bench.node_budget import FIGURES, OUTSIDE, node_budget, node_markdown
from netsetest.cli.main import main
from netsetest.runtime.report import EXIT_BAD_INPUT


def _report(messages: bool = True) -> dict:
    ms = {"wait": 0.02, "decode": 0.06, "handle": 0.14, "solve": 2.0, "build": 0.06, "encode": 0.01, "put": 0.05, "other": 0.26, "threads": 0.4}
    calls = {"decode": 4.0, "put": 1.0}
    report = {
        "steps": 40,
        "process_ms_per_step": sum(ms.values()),
        "thread_ms_per_step": sum(ms.values()) - ms["threads"],
        "phases": {p: {"ms_per_step": v, "calls_per_step": calls.get(p, 0.0)} for p, v in ms.items()},
    }
    if messages:
        report["messages_per_step"] = {"received": 5.0, "sent": 1.0}  # one screened out undecoded
    return report


def test_budget_splits_the_step_and_divides_by_the_messages() -> None:
    b = node_budget(_report())
    assert b["solve_us"] == pytest.approx(2000.0) and b["outside_us"] == pytest.approx(1000.0)
    assert b["outside_us"] == pytest.approx(sum(b[f"{p}_us"] for p in OUTSIDE))
    assert b["outside_ratio"] == pytest.approx(1.5)
    assert (b["received"], b["sent"]) == (5.0, 1.0)
    assert b["per_received_us"] == pytest.approx((60 + 140) / 5)
    assert b["per_sent_us"] == pytest.approx((60 + 10 + 50) / 1)
    assert b["threads_per_message_us"] == pytest.approx(400 / 6)
    assert b["outside_per_message_us"] == pytest.approx(1000 / 6)
    assert set(b) == {key for key, _, _ in FIGURES}


def test_a_profile_without_message_counters_counts_its_decodes_and_puts() -> None:
    b = node_budget(_report(messages=False))
    assert (b["received"], b["sent"]) == (4.0, 1.0) and b["per_received_us"] == pytest.approx(200 / 4)
    silent = _report(messages=False)
    silent["phases"]["put"]["calls_per_step"] = 0.0
    assert math.isnan(node_budget(silent)["per_sent_us"])  # nothing sent: no per-message figure, no ZeroDivisionError


def test_the_table_has_the_ratio_column_only_beside_a_baseline() -> None:
    figures = node_budget(_report())
    summary = {k: {"median": v, "min": v, "max": v} for k, v in figures.items()}
    run = {"load_before": "1.0 1.0 1.0", "deadline_misses": 0, "exit_code": 0, "figures": figures}
    alone = {"nodes": 12, "steps": 40, "reps": 1, "baseline_code": None, "this": {"runs": [run], "summary": summary}}
    assert "this / baseline" not in node_markdown(alone) and "| the estimator's step (`solve`) [µs] | 2000 (2000–2000) |" in node_markdown(alone)
    both = {**alone, "baseline_code": "/x/main", "commits": {"this": "a", "baseline": "b"}, "baseline": {"runs": [run], "summary": summary}}
    both["ratio"] = dict.fromkeys(figures, 1.0)
    text = node_markdown(both)
    assert "this / baseline" in text and "commit `b`" in text and "| 2000 (2000–2000) | 1.00 |" in text


@pytest.mark.parametrize(
    "args",
    [
        ["--baseline", "."],
        ["--only", "node", "--baseline", "/nonexistent"],
        ["--only", "widths", "--baseline", "/nonexistent"],
        ["--only", "performance", "--baseline", "/nonexistent"],
        ["--only", "plant", "--baseline", "."],
    ],
)
def test_baseline_needs_the_node_widths_or_performance_part_and_a_checkout(
    args: list[str], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sys, "argv", ["netsetest", "bench", *args])
    assert main(["bench", *args]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert "--baseline" in err and "Traceback" not in err


@pytest.mark.parametrize("what", ["--render-docs", "--spread"])
def test_baseline_measures_so_it_does_not_go_with_what_measures_nothing(what: str, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["bench", what, *(["bench/results.json"] if what == "--spread" else []), "--baseline", "."]
    assert main(args) == EXIT_BAD_INPUT
    assert f"{what} measures nothing; --baseline does not go with it" in capsys.readouterr().err


def test_the_floor_table_stands_beside_the_node_and_says_whether_the_bus_alone_is_over_the_target() -> None:
    from netsetest_bench.bus_floor import FIGURES as FLOOR

    figures = node_budget(_report())
    summary = {k: {"median": v, "min": v, "max": v} for k, v in figures.items()}
    run = {"load_before": "1.0 1.0 1.0", "deadline_misses": 0, "exit_code": 0, "figures": figures}
    res = {"nodes": 12, "steps": 40, "reps": 1, "baseline_code": None, "this": {"runs": [run], "summary": summary}}
    assert "Zenoh's floor" not in node_markdown(res)  # a node.json of before the floor renders as it did

    def floor(process_us: float) -> dict:
        row = {key: 1.0 for key, _, _ in FLOOR} | {"process_us": process_us, "load_before": "1.0 1.0 1.0"}
        return {"runs": [row], "summary": {key: {"median": row[key], "min": row[key], "max": row[key]} for key, _, _ in FLOOR}}

    res["floor"] = {"node": 4, "in_neighbours": 3, "secured": floor(700.0), "insecure": floor(1000.0)}
    text = node_markdown(res)
    assert "| CPU per step, every thread [µs] | 700 (700–700) | 1000 (1000–1000) | 3000 (3000–3000) |" in text  # the node: its process CPU
    assert "costs the node 700 µs of CPU per step" in text and "above the 300 µs target" in text
    res["floor"]["secured"] = floor(250.0)
    assert "within the 300 µs target" in node_markdown(res)
    res["floor"]["insecure"] = {"runs": [{"load_before": "9 9 9", "error": "the bare process never reported ready"}], "summary": {}}
    assert "never reported ready" in node_markdown(res)
