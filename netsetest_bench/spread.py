"""How noisy the benchmark is: the headline figures of several runs of the same benchmark, side by side.

``netsetest bench --spread A.json B.json C.json --json bench/spread.json`` measures nothing: it reads the
figures files of repeated ``netsetest bench --quick --only performance`` runs and reports, per headline
figure (:data:`netsetest_bench.run.TARGETS`), every run's value, the median, the relative spread
(max − min) / median and whether the target was met in every run.  A figure whose spread is wider than
the distance to its target is not a result on this machine, only a range.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

from netsetest_bench.figures.spread import load as load_spread
from netsetest_bench.render import MISSING, fill
from netsetest_bench.run import TARGETS

MIN_RUNS = 2  # a spread needs two runs at least
NEGLIGIBLE = 1e-9  # a median this close to 0 (a slope of nothing) has no relative spread
RUNS_DIR = "bench/runs"  # the committed runs: `netsetest bench --quick --only performance --json bench/runs/N.json`


class SpreadError(ValueError):
    """A figures file cannot be read, or is not a whole performance run."""


def _load(path: Path) -> dict:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise SpreadError(f"{path}: cannot be read as a figures file ({e})") from e
    if not isinstance(doc, dict) or "meta" not in doc or "solve_ms_median" not in doc:
        raise SpreadError(f"{path}: not the figures of a performance run (`netsetest bench --only performance --json …`)")
    return doc


def spread_figures(paths: list[Path]) -> dict:
    """Every headline figure of every run, its median, relative spread and whether all runs met the target."""
    if len(paths) < MIN_RUNS:
        raise SpreadError(f"--spread needs {MIN_RUNS} figures files at least, got {len(paths)}")
    docs = [_load(p) for p in paths]
    figures = []
    for key, target, ok in TARGETS:
        values = [d.get(key) for d in docs]
        measured = [float(v) for v in values if v is not None]
        med = statistics.median(measured) if measured else None
        rel = (max(measured) - min(measured)) / abs(med) if measured and med is not None and abs(med) > NEGLIGIBLE else None
        figures.append(
            {
                "key": key,
                "target": target,
                "values": values,
                "median": med,
                "relative_spread": rel,
                "met_in_every_run": bool(measured) and len(measured) == len(values) and all(ok(v) for v in measured),
            }
        )
    runs = [
        {"file": str(p), "date": d["meta"].get("date"), "quick": d["meta"].get("quick"), "load_before": d["meta"].get("load_before")}
        for p, d in zip(paths, docs)
    ]
    return {"meta": {"runs": runs}, "figures": figures}


def _num(v: float | None) -> str:
    if v is None:
        return MISSING
    return format(v, ".0f") if abs(v) >= 100 else format(v, ".3g")


def spread_markdown(doc: dict) -> str:
    """One row per headline figure: each run's value, the median, the spread and the target."""
    s, T = load_spread(doc), "spread"
    runs = s.meta.runs
    lines = [
        fill(
            T,
            "head",
            n=len(runs),
            files=", ".join(fill(T, "file", r=r) for r in runs),
            loads="; ".join(fill(T, "run-load", r=r) for r in runs),
            columns=" | ".join(fill(T, "column", i=i) for i in range(1, len(runs) + 1)),
            dashes="---|" * len(runs),
        )
    ]
    for f in s.figures:
        spread = MISSING if f.relative_spread is None else fill(T, "percent", pct=100 * f.relative_spread)
        values = " | ".join(_num(v) for v in f.values)
        lines.append(fill(T, "row", f=f, values=values, median=_num(f.median), spread=spread, met="yes" if f.met_in_every_run else "no"))
    return "\n".join(lines) + "\n"


def write_spread(paths: list[Path], json_path: str | None, markdown_path: str | None = None) -> str:
    """The spread of ``paths`` as Markdown; its figures and that Markdown written to the paths given."""
    res = spread_figures(paths)
    md = spread_markdown(res)
    if json_path:
        Path(json_path).write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    if markdown_path:
        Path(markdown_path).write_text(md, encoding="utf-8")
    return md


__all__ = ["SpreadError", "spread_figures", "spread_markdown", "write_spread"]
