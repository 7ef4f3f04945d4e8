"""The exact part's report (netsetest_bench/exact_cost.py): issue 34's targets are read from the right rows, and
memory that grows from the middle step to the last is not called flat."""

from __future__ import annotations

from netsetest_bench.exact_cost import exact_cost_markdown
from netsetest_bench.exact_cost import targets as typed_targets
from netsetest_bench.figures.exact_cost import ExactRun
from netsetest_bench.render import typed


def targets(rows: list[dict]) -> list[tuple[str, str, bool]]:
    """The targets of rows as a figures file holds them."""
    return typed_targets(typed(list[ExactRun], rows))


def _row(topology: str, case: str, cpu: float, peak: float, exact: int, rss: list[float]) -> dict:
    return {
        "topology": topology,
        "nodes": 12,
        "case": case,
        "signals": "worst",
        "steps": 80,
        "budget_s": 600.0,
        "cpu_s": cpu,
        "wall_s": 2 * cpu,
        "peak_mb": peak,
        "rss_mb": rss,
        "ends": 100,
        "exact_ends": exact,
        "relaxed_ends": 100 - exact,
        "solves": 500,
        "out_of_time": None,
        "infeasible_steps": [],
    }


def test_the_targets_are_issue_34s() -> None:
    flat = [100.0, 120.0, 130.0, 131.0]
    met = dict(
        (what, ok)
        for what, _, ok in targets([_row("ring12, two groups", "saim", 100.0, 900.0, 96, flat), _row("paper6_max_faulty", "saim", 19.0, 80.0, 100, flat)])
    )
    assert met == {
        "ring12 SAIM worst: CPU": True,
        "ring12 SAIM worst: peak memory": True,
        "ring12 SAIM worst: ends exact": True,
        "paper6_max_faulty SAIM worst: CPU": True,
        "every run: memory flat": True,
    }
    growing = [100.0, 400.0, 700.0, 1000.0]
    missed = dict((what, ok) for what, _, ok in targets([_row("ring12, two groups", "saim", 130.0, 1100.0, 94, growing)]))
    assert not any(missed.values())
    text = exact_cost_markdown({"steps": 80, "rows": [_row("ring12, two groups", "saim", 130.0, 1100.0, 94, growing)], "load": "1 before, 2 after"})
    assert "| ring12, two groups | 12 | SAIM | 600 | 130.0 (260) | 1100 | +300 | 94 of 100 | 6 | 500 |" in text and "Load average 1 before, 2 after" in text


def test_the_network_row_times_the_limit_as_the_command_computes_it(monkeypatch) -> None:
    """``exact --network`` computes the central limit first and hands it on (each node's program imports its boxes,
    docs/exact.md): the benchmark's network row must time that, not the network limit without the central one."""
    import netsetest.analysis.exact as exact
    import netsetest.config.schema as schema
    import netsetest.records.record as record
    from netsetest_bench.exact_cost import measure_one

    calls: list[tuple[str, object]] = []

    class Meta:
        steps = 3

    class Rec:
        meta = Meta()

    class Limit:
        health = None
        infeasible_steps = ()

    central = Limit()

    def exact_bounds(sc, rec, fault_bounds, **kw):
        calls.append(("exact_bounds", kw.get("network", False)))
        return central if not kw.get("network") else Limit()  # (the old row: the network limit without the central one)

    def network_limit(sc, rec, given, **kw):
        calls.append(("network_limit", given))
        return Limit()

    monkeypatch.setattr(record, "load_record", lambda path: Rec())
    monkeypatch.setattr(schema, "load_topology", lambda *a: None)
    monkeypatch.setattr(exact, "exact_bounds", exact_bounds)
    monkeypatch.setattr(exact, "network_limit", network_limit)
    measure_one("topology.toml", "saim", "record.json", 600.0, network=True)
    assert calls == [("exact_bounds", False), ("network_limit", central)]
    calls.clear()
    measure_one("topology.toml", "saim", "record.json", 600.0)
    assert calls == [("exact_bounds", False)]
