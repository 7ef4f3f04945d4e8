"""bench/scaleout.py (``netsetest bench --only scaleout``): where each role runs, the step rate from the
collector's progress, the figures and table built from the runs (a failed run shown, not counted), and
the part refused with one line where namespaces cannot be made.  The run itself in namespaces:
tests/process/test_zenoh_netns.py."""

from __future__ import annotations

import pytest

import netsetest.runtime.netns as netns
from netsetest_bench.scaleout import LAYOUTS, WARM_STEPS, layouts_figures, placement, scaleout_markdown, step_rate
from netsetest_bench.zenoh_runs import MACHINE_CORES
from netsetest.cli.main import main
from netsetest.runtime.report import EXIT_BAD_INPUT


def test_placement_cuts_the_ring_into_arcs_with_vehicle_and_collector_on_the_first_host() -> None:
    ids = list(range(1, 25))
    two = placement(ids, 2)
    assert two["vehicle"] == two["collector"] == 0
    assert [i for i in ids if two[f"node{i}"] == 0] == list(range(1, 13)) and [i for i in ids if two[f"node{i}"] == 1] == list(range(13, 25))
    assert set(placement(ids, 1).values()) == {0}
    odd = placement([5, 1, 3, 2, 4], 2)  # any ids, any order: contiguous arcs of near-equal size
    assert [odd[f"node{i}"] for i in (1, 2, 3, 4, 5)] == [0, 0, 0, 1, 1]


def test_step_rate_counts_the_steps_between_the_first_and_last_reported() -> None:
    assert step_rate({0: 0.0, 2: 10.0, 40: 14.0}, 2) == pytest.approx(38 / 4.0)
    # progress reported several steps at once: from the first report at or after step 2 (here 3) to the last
    assert step_rate({1: 9.0, 3: 10.0, 38: 13.0, 40: 14.0}, 2) == pytest.approx(37 / 4.0)
    assert step_rate({0: 0.0, 40: 14.0}, 2) is None  # one report in the window: no figure, not a guess
    assert step_rate({}, 2) is None


def _row(hosts: int, rate: float | None, cpu: dict[str, float] | None, error: str | None = None) -> dict:
    return {
        "hosts": hosts,
        "load_before": "3.0 2.0 1.0",
        "error": error,
        "step_rate": rate,
        "cpu_ms_per_step_by_host": cpu,
        "violations": 0 if error is None else None,
        "nodes_missing": [] if error is None else None,
    }


def test_figures_and_table_from_the_runs() -> None:
    runs = {
        "one": [_row(1, 10.0, {"a": 100.0}), _row(1, 12.0, {"a": 120.0})],
        "two": [_row(2, 9.0, {"a": 60.0, "b": 50.0}), _row(2, None, None, "a router did not start")],
    }
    res = layouts_figures(runs, 24, 40, 2)
    one, two = res["layouts"]["one"]["summary"], res["layouts"]["two"]["summary"]
    assert one["step_rate"] == {"median": 11.0, "min": 10.0, "max": 12.0} and one["runs"] == 2
    assert two["runs"] == 1 and two["cpu_ms_per_step"]["median"] == pytest.approx(110.0)  # the failed run is not counted
    assert two["cpu_ms_per_step_by_host"] == {"a": 60.0, "b": 50.0}
    assert two["ceiling_step_rate"]["median"] == pytest.approx(1e3 * MACHINE_CORES / 110.0)
    assert two["of_ceiling"]["median"] == pytest.approx(9.0 / (1e3 * MACHINE_CORES / 110.0))
    assert res["ratio"] == pytest.approx(9.0 / 11.0)
    text = scaleout_markdown(res)
    assert "| one host: one namespace, one router | 11.00 (10.00–12.00) | 110.0 (100.0–120.0) | 110.0 |" in text
    assert "| 60.0 / 50.0 |" in text and "(failed)" in text and f"step {WARM_STEPS} on" in text
    assert "Two hosts / one host, step rate: **0.82**." in text


def test_no_ratio_without_a_measured_run_in_both_layouts() -> None:
    res = layouts_figures({name: [_row(h, None, None, "no namespaces")] for name, h in LAYOUTS.items()}, 4, 8, 1)
    assert res["ratio"] is None and all(not lay["summary"] for lay in res["layouts"].values())
    assert "| one host: one namespace, one router | — |" in scaleout_markdown(res)


def test_the_part_is_refused_in_one_line_without_namespaces(monkeypatch, capsys) -> None:
    monkeypatch.setattr(netns, "unavailable", lambda: "network namespaces need root (ip netns add)")
    assert main(["bench", "--only", "scaleout"]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.strip()
    assert err == "netsetest bench: --only scaleout: network namespaces need root (ip netns add)"
