"""The scale-out part's figures (bench/scaleout.json: ``netsetest bench --only scaleout``) as typed data."""

from __future__ import annotations

from dataclasses import dataclass, field

from netsetest_bench.render import typed


@dataclass(frozen=True)
class Range:
    median: float | None
    min: float | None
    max: float | None


@dataclass(frozen=True)
class LayoutRun:
    load_before: str
    violations: int | None
    nodes_missing: list[int] | None
    error: str | None = None
    step_rate: float | None = None

    def failed(self) -> bool:
        return bool(self.error) or not self.step_rate


@dataclass(frozen=True)
class Summary:
    """A layout's figures over its runs (empty where no run finished)."""

    step_rate: Range
    cpu_ms_per_step: Range
    ceiling_step_rate: Range
    of_ceiling: Range
    cpu_ms_per_step_by_host: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Layout:
    hosts: int
    runs: list[LayoutRun]
    summary: Summary | None = None


@dataclass(frozen=True)
class Scaleout:
    nodes: int
    steps: int
    reps: int
    cores: int
    warm_steps: int
    layouts: dict[str, Layout]
    ratio: float | None = None


def load(doc: dict, what: str = "the scale-out figures") -> Scaleout:
    """``doc`` as :class:`Scaleout`; a layout's empty summary (no run finished) is None."""
    layouts = doc.get("layouts")
    if isinstance(layouts, dict):
        doc = doc | {"layouts": {k: (v | {"summary": v.get("summary") or None}) if isinstance(v, dict) else v for k, v in layouts.items()}}
    return typed(Scaleout, doc, what)
