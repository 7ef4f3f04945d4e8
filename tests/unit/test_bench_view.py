"""The view part's tables (netsetest_bench/view.py): what they conclude follows from the figures, and the
page's miss is put on the machine only when the page's own CPU was under the target."""

from __future__ import annotations

from netsetest_bench.view import view_markdown, view_summary_markdown


def _res(ready_ms: float, cpu_ms: float, cpu_with: float = 3.0) -> dict:
    run = {"steps": 10, "load_before": 1.0, "exit_code": 0, "deadline_misses": 0, "late_steps": 0, "other_work_pct": 5.0}
    view = {"view_cpu_pct": 10.0, "lag_median_s": 0.01, "lag_p95_s": 0.02, "lag_max_s": 0.03, "dropped_frames": 0}
    off = {"view": False, **run, "node_cpu_ms_per_step": 3.0, **dict.fromkeys(view)}
    on = {"view": True, **run, "node_cpu_ms_per_step": cpu_with, **view}
    opening = {"load_before": 1.0, "errors": 0, "load_event_ms": 100.0, "first_contentful_paint_ms": 120.0, "ready_ms": ready_ms}
    page = {"size_mb": 1.5, "opens": [{**opening, "main_thread_cpu_ms": cpu_ms, "renderer_cpu_ms": cpu_ms}]}
    return {
        "live": {"steps": 10, "pairs": 1, "tau_s": 0.1, "runs": [on, off]},
        "page": {"nodes": 6, "steps": 80, **page},
        "big_page": {"nodes": 24, "steps": 1000, "max_points": 400, **page},
    }


def test_a_slow_opening_is_put_on_the_machine_only_when_the_page_itself_is_cheap() -> None:
    busy = view_summary_markdown(_res(ready_ms=5000.0, cpu_ms=1000.0))
    assert "| **missed** |" in busy and "the miss is the loaded machine's" in busy
    slow = view_summary_markdown(_res(ready_ms=5000.0, cpu_ms=3000.0))
    assert "the miss is the loaded machine's" not in slow and slow.count("| **missed** |") == 2
    fast = view_summary_markdown(_res(ready_ms=800.0, cpu_ms=700.0))
    assert "**missed**" not in fast and "loaded machine" not in fast


def test_within_noise_means_the_ranges_overlap() -> None:
    assert "met (the ranges overlap)" in view_summary_markdown(_res(800.0, 700.0, cpu_with=3.0))
    assert "**missed** (the ranges are apart)" in view_summary_markdown(_res(800.0, 700.0, cpu_with=4.0))


def test_every_run_and_opening_has_its_row() -> None:
    text = view_markdown(_res(800.0, 700.0))
    assert text.count("| with |") == 1 and text.count("| without |") == 1
    assert "| paper6, 80 steps | 1.50 MB |" in text and "| 24-node ring, 1000 steps | 1.50 MB |" in text
