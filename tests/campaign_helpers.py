"""Shared by the campaign tests (tests/inmemory/test_campaign*.py, tests/process/test_campaign*.py): a module's
campaign file, the rows of a campaign's runs made one by one in this process, a results directory's rows, and
their comparison.

Rows are compared without the columns that say how and where a run went (rows.VARYING: times, worker);
integers and strings must be equal, floats within REL_TOL: the workers and this process run the same code on
the same machine with the same BLAS kernel (OPENBLAS_CORETYPE is inherited), but a worker is started with
OPENBLAS_NUM_THREADS=1, and a BLAS may sum in another order on another thread count, so floats are held to a
bound far below any figure's meaning instead of to the bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from pathlib import Path

import pytest

from netsetest.campaign.rows import COLUMNS, VARYING, rows_of
from netsetest.campaign.runner import tasks_of
from netsetest.campaign.spec import load_campaign
from netsetest.campaign.worker import execute

REL_TOL = 1e-9
Rows = dict[tuple[str, int], dict]


def campaign_file_fixture(text: str) -> Callable[..., Path]:
    """A module's ``campaign_file`` fixture: ``text`` written once as c.toml in a directory of its own."""

    @pytest.fixture(scope="module")
    def campaign_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
        path = tmp_path_factory.mktemp("campaign") / "c.toml"
        path.write_text(text)
        return path

    return campaign_file


def by_row(rows: Iterable[dict]) -> Rows:
    """(run key, node) → row; a (run, node) twice fails."""
    out: Rows = {}
    for r in rows:
        key = (r["run_key"], r["node"])
        assert key not in out, f"run {key[0]} node {key[1]} twice"
        out[key] = r
    return out


def one_by_one(campaign: Path) -> Rows:
    """Every run of the campaign in this process, one after the other: the reference rows."""
    c = load_campaign(campaign)
    planned = {p.key: p for p in c.runs}
    return by_row(r for t in tasks_of(c, set()) for r in rows_of(c, planned[t.key], execute(t)))


def dataset(out: Path) -> Rows:
    """The rows of a results directory's dataset."""
    import pyarrow.dataset as ds

    return by_row(ds.dataset(out / "runs", format="parquet", partitioning="hive").to_table().to_pylist())


def _same(a: object, b: object) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=REL_TOL, abs_tol=1e-300)
    return a == b


def assert_same_rows(got: Rows, want: Rows) -> None:
    assert got.keys() == want.keys(), f"runs × nodes differ: {len(got)} rows, {len(want)} expected"
    for key, row in want.items():
        for col in (c.name for c in COLUMNS if c.name not in VARYING):
            assert _same(got[key][col], row[col]), f"run {key[0]} node {key[1]}: {col} {got[key][col]!r} != {row[col]!r}"
