"""What a campaign found, from its rows: verdict counts, the worst runs, and ``campaign --report``'s summary
table (DIR/summary.md) and page (DIR/report.html, records/report_html.py's stack: one self-contained Bokeh page).

The summary table has one line per estimator, case and signal family: runs, verdicts, coverage (the share
of judged node-steps the guarantee applied to), violations, the mean published widths, the widths over the
exact limit (where the campaign computed it) and the detection delay.  The page draws, per estimator and
coordinate, the distribution of coverage and of width over exact over the runs' nodes, the detection delay
against the fault's size, and lists the worst runs, each with the command that replays it.
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from netsetest.campaign.rows import ERROR

if TYPE_CHECKING:
    import pandas as pd
    import pyarrow as pa

    from netsetest.campaign.spec import Campaign

WORST_LISTED = 20  # runs in the page's worst-runs table
RUN_COLUMNS = ("run_key", "estimator", "case", "signals", "seed", "topology", "verdict", "exit_code", "cause", "replay", "violations_total")


def _frame(table: pa.Table) -> pd.DataFrame:
    df = table.to_pandas()
    for col in ("estimator", "case"):  # hive partitions come back as categories
        df[col] = df[col].astype(str)
    return df


def _runs(table: pa.Table) -> pd.DataFrame:
    """One row per run (its run-level columns) with its nodes' worst coverage and width over exact."""
    df = _frame(table)
    if df.empty:
        return df
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


def worst_runs(table: pa.Table, n: int, passed: bool = False) -> list[dict]:
    """The ``n`` worst runs: errors, then the most violations, then other verdicts that are not a pass; with
    ``passed`` the runs that passed follow, the lowest coverage and then the widest over the exact limit first."""
    runs = _runs(table)
    if runs.empty:
        return []
    runs = runs.assign(
        rank=np.where(runs["verdict"] == ERROR, 0, np.where(runs["exit_code"].fillna(0) != 0, 1, 2)),
        coverage_key=runs["coverage_min"].fillna(1.0),
        exact_key=-runs["fault_over_exact_max"].fillna(0.0),
    )
    if not passed:
        runs = runs[runs["rank"] < 2]
    order = runs.sort_values(["rank", "violations_total", "coverage_key", "exact_key", "run_key"], ascending=[True, False, True, True, True])
    return order.head(n).to_dict("records")


GROUPS = ("estimator", "case", "signals")
SUMMARY_HEADER = (
    *GROUPS,
    "runs",
    "verdicts",
    "coverage",
    "violations",
    "β width",
    "r width",
    "fault width",
    "β / exact",
    "r / exact",
    "fault / exact",
    "detected",
    "delay median [steps]",
    "false detections",
)


def _f(v: float | None, spec: str = ".4f") -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def summary_rows(table: pa.Table) -> list[tuple[str, ...]]:
    """One line per estimator, case and signal family (module doc)."""
    df = _frame(table)
    out: list[tuple[str, ...]] = []
    if df.empty:
        return out
    for key, g in df.groupby(list(GROUPS), sort=True, observed=True):
        runs = g.drop_duplicates("run_key")
        verdicts = ", ".join(f"{v} {n}" for v, n in sorted(Counter(runs["verdict"]).items()))
        judged = g["steps_evaluated"].sum()
        faulty = g[g["fault_onset"].notna()]
        out.append(
            (
                *(str(k) for k in key),
                str(len(runs)),
                verdicts,
                _f(g["steps_covered"].sum() / judged if judged else None, ".3f"),
                str(int(g["violations"].fillna(0).sum())),
                *(_f(g[c].mean()) for c in ("beta_width", "r_width", "fault_width")),
                *(_f(g[c].mean(), ".3f") for c in ("beta_over_exact", "r_over_exact", "fault_over_exact")),
                f"{int(faulty['first_detection'].notna().sum())}/{len(faulty)}",
                _f(faulty["detection_delay"].median(), ".1f"),
                str(int(g["false_detections"].fillna(0).sum())),
            )
        )
    return out


def markdown(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> str:
    return "\n".join(["| " + " | ".join(header) + " |", "|" + "---|" * len(header), *("| " + " | ".join(r) + " |" for r in rows)]) + "\n"


WORST_HEADER = ("verdict", "estimator", "case", "signals", "seed", "lowest coverage", "widest fault / exact", "cause", "replay")


def _worst_cells(r: dict) -> tuple[str, ...]:
    return (
        r["verdict"],
        r["estimator"],
        r["case"],
        r["signals"],
        str(r["seed"]),
        _f(r["coverage_min"], ".3f"),
        _f(r["fault_over_exact_max"], ".3f"),
        r["cause"] if isinstance(r["cause"], str) else "",  # a missing cause comes back from pandas as NaN
        r["replay"],
    )


def write_report(c: Campaign, table: pa.Table, out: Path) -> list[Path]:
    """DIR/summary.md and DIR/report.html of the campaign's runs in ``table`` (module doc)."""
    from netsetest.records.report_html import CampaignPage, write_campaign

    df = _frame(table)
    rows = summary_rows(table)
    verdicts = run_verdicts(table)
    bad = sum(n for v, n in verdicts.items() if not v.startswith("PASS"))
    counts = ", ".join(f"{n} {v}" for v, n in sorted(verdicts.items())) or "no run"
    verdict = f"{sum(verdicts.values())} of {len(c.runs)} runs: {counts}"
    summary = out / "summary.md"
    summary.write_text(f"# campaign {c.name}\n\n{verdict}\n\n" + markdown(SUMMARY_HEADER, rows), encoding="utf-8")
    worst = [_worst_cells(r) for r in worst_runs(table, WORST_LISTED, passed=True)]
    distributions = {}
    for col, title in (("coverage", "coverage: covered / judged node-steps"), *((f"{k}_over_exact", f"width over exact: {k}") for k in ("beta", "r", "fault"))):
        per = {e: g[col].to_numpy(dtype=float) for e, g in df.groupby("estimator", observed=True)} if not df.empty else {}
        distributions[title] = {e: v for e, v in per.items() if np.isfinite(v).any()}
    detected = df[df["detection_delay"].notna() & df["fault_declared"].fillna(0).gt(0)] if not df.empty else df
    delays = {
        e: (g["fault_peak"].to_numpy(dtype=float) / g["fault_declared"].to_numpy(dtype=float), g["detection_delay"].to_numpy(dtype=float))
        for e, g in detected.groupby("estimator", observed=True)
    }
    page = out / "report.html"
    write_campaign(page, CampaignPage(f"netsetest campaign {c.name}", verdict, bad > 0, SUMMARY_HEADER, rows, distributions, delays, WORST_HEADER, worst))
    return [summary, page]
