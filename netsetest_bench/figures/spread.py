"""The spread part's figures (bench/spread.json: ``netsetest bench --spread``) as typed data."""

from __future__ import annotations

from dataclasses import dataclass

from netsetest_bench.render import typed


@dataclass(frozen=True)
class SpreadRun:
    """One performance run's figures file."""

    file: str
    date: str
    load_before: str


@dataclass(frozen=True)
class Meta:
    runs: list[SpreadRun]


@dataclass(frozen=True)
class SpreadFigure:
    """One headline figure over the runs."""

    key: str
    target: str
    values: list[float | None]
    median: float | None
    relative_spread: float | None  # (max − min) / median
    met_in_every_run: bool


@dataclass(frozen=True)
class Spread:
    meta: Meta
    figures: list[SpreadFigure]


def load(doc: dict, what: str = "the spread figures") -> Spread:
    return typed(Spread, doc, what)
