"""The view part's figures (bench/view.json: ``netsetest bench --only view``) as typed data."""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from netsetest_bench.render import typed


@dataclass(frozen=True)
class LiveRun:
    """A real-time paper6 run with the live view or without (the view's figures None without it)."""

    view: bool
    load_before: float
    exit_code: int | None
    deadline_misses: int
    late_steps: int
    node_cpu_ms_per_step: float | None = None
    other_work_pct: float | None = None
    view_cpu_pct: float | None = None
    lag_median_s: float | None = None
    lag_p95_s: float | None = None
    lag_max_s: float | None = None
    dropped_frames: int | None = None


@dataclass(frozen=True)
class Live:
    tau_s: float
    steps: int
    runs: list[LiveRun]

    def side(self, view: bool) -> list[LiveRun]:
        return [r for r in self.runs if r.view == view]


@dataclass(frozen=True)
class Opening:
    """A report page opened in headless Chromium [ms from the navigation's start]."""

    load_before: float
    errors: int
    load_event_ms: float | None = None
    first_contentful_paint_ms: float | None = None
    ready_ms: float | None = None
    main_thread_cpu_ms: float | None = None
    renderer_cpu_ms: float | None = None


@dataclass(frozen=True)
class Page:
    nodes: int
    steps: int
    size_mb: float
    opens: list[Opening]
    max_points: int = 0


@dataclass(frozen=True)
class Spread:
    """A figure over runs: median, least and largest (None: no run has it)."""

    median: float | None
    lo: float | None
    hi: float | None


def spread(values: Sequence[float | None]) -> Spread:
    v = [x for x in values if x is not None]
    return Spread(statistics.median(v), min(v), max(v)) if v else Spread(None, None, None)


@dataclass(frozen=True)
class View:
    live: Live
    page: Page
    big_page: Page


def load(doc: dict, what: str = "the view figures") -> View:
    return typed(View, doc, what)
