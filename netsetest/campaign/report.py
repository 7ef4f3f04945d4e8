"""What a campaign found, from its rows: verdict counts, the worst runs, and ``campaign --report``'s summary
table (DIR/summary.md) and page (DIR/report.html, records/report_html.py's stack: one self-contained Bokeh page).

The summary table has one line per estimator, case and signal family: runs, verdicts, coverage (the share
of judged node-steps the guarantee applied to), violations, the mean published widths, the widths over the
exact limit (where the campaign computed it) and the detection delay.  The page draws, per estimator and
coordinate, the distribution of coverage and of width over exact over the runs' nodes, the detection delay
against the fault's size, and lists the worst runs, each with the command that replays it.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING

from netsetest.campaign.rows import ERROR

if TYPE_CHECKING:
    import pandas as pd
    import pyarrow as pa

    from netsetest.campaign.spec import Campaign

WORST_LISTED = 20  # runs in the page's worst-runs table
RUN_COLUMNS = ("run_key", "estimator", "case", "signals", "seed", "topology", "verdict", "exit_code", "cause", "replay", "violations_total")


def _runs(table: pa.Table) -> pd.DataFrame:
    """One row per run (its run-level columns) with its nodes' worst coverage and width over exact."""
    df = table.to_pandas()
    if df.empty:
        return df
    for col in ("estimator", "case"):  # hive partitions come back as categories
        df[col] = df[col].astype(str)
    agg = df.groupby("run_key").agg(
        coverage_min=("coverage", "min"),
        fault_over_exact_max=("fault_over_exact", "max"),
        narrower=("narrower_than_exact", "sum"),
    )
    first = df.drop_duplicates("run_key").set_index("run_key")[[c for c in RUN_COLUMNS if c != "run_key"]]
    return first.join(agg).reset_index()


def run_verdicts(table: pa.Table) -> Counter:
    """Verdict word → runs."""
    runs = _runs(table)
    return Counter() if runs.empty else Counter(runs["verdict"].tolist())


def worst_runs(table: pa.Table, n: int) -> list[dict]:
    """The ``n`` worst runs that did not pass (errors first, then most violations, then other non-zero verdicts),
    then, to fill, none: a run that passed is not listed."""
    runs = _runs(table)
    if runs.empty:
        return []
    bad = runs[(runs["verdict"] == ERROR) | (runs["exit_code"].fillna(0) != 0)].copy()
    bad["order"] = (bad["verdict"] != ERROR).astype(int)
    bad = bad.sort_values(["order", "violations_total", "run_key"], ascending=[True, False, True])
    return bad.head(n).to_dict("records")


def write_report(c: Campaign, table: pa.Table, out: Path) -> list[Path]:
    """DIR/summary.md and DIR/report.html (module doc)."""
    raise NotImplementedError
