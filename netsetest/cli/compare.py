"""``netsetest compare``: one table, one row per guaranteed estimator (logic in analysis/compare.py)."""

from __future__ import annotations

import argparse
import json
import sys
import textwrap
from collections.abc import Callable

from netsetest.cli import checks
from netsetest.estimator.names import DEFAULT_COMPARE, ESTIMATOR_NAMES
from netsetest.models.signals import SIGNAL_KINDS

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}


def add_parser(sub: argparse._SubParsersAction, scenario_args: Callable[[argparse.ArgumentParser], None]) -> None:
    p = sub.add_parser("compare", help="every guaranteed estimator on the same vehicle, network and data: one row each")
    scenario_args(p)
    p.add_argument(
        "--estimators",
        type=checks.name_list(ESTIMATOR_NAMES, "estimator"),
        default=DEFAULT_COMPARE,
        metavar="A,B,…",
        help=f"rows, from {', '.join(ESTIMATOR_NAMES)} (default: {','.join(DEFAULT_COMPARE)})",
    )
    p.add_argument(
        "--signals",
        type=checks.name_list(SIGNAL_KINDS, "signal kind"),
        default=("paper",),
        metavar="KINDS",
        help="paper and/or worst, comma-separated (default: paper)",
    )
    p.add_argument("--seeds", type=checks.seed_list, default=(0,), metavar="S,…", help="seeds, comma-separated, ranges A-B allowed (default: 0)")
    p.add_argument(
        "--alone",
        action="store_true",
        help="two more rows, what the network is worth: sdp-alone (every node run on its own: a self-loop "
        "only, no reading) and exact-local (each node's exact limit from its own data), against the same "
        "central exact limit (docs/network.md)",
    )
    p.add_argument("--json", metavar="PATH", help="write the rows as a JSON list")
    p.add_argument("--markdown", metavar="PATH", help="write the table as Markdown")
    p.add_argument("--plot", metavar="DIR", help="one figure per node: every estimator's fault bounds and the truth (first run)")
    p.add_argument("--html", metavar="PATH", help="the table and per node every estimator's fault bounds as one self-contained page, PATH.html (extra view)")
    COMMANDS["compare"] = cmd_compare


TERMINAL_WIDTH = 100  # characters: the table folds its columns into blocks that fit (--markdown has them in one)


def folded_table(rows: list[tuple[str, ...]], width: int) -> list[str]:
    """The table in blocks of columns, each block at most ``width`` wide and led by the first column."""
    widths = [max(len(r[j]) for r in rows) for j in range(len(rows[0]))]
    blocks: list[list[int]] = [[]]
    for j in range(1, len(widths)):
        used = widths[0] + sum(widths[c] + 2 for c in blocks[-1])
        if blocks[-1] and used + widths[j] + 2 > width:
            blocks.append([])
        blocks[-1].append(j)
    out: list[str] = []
    for n, cols in enumerate(blocks):
        if n:
            out.append("")
        out += ["  ".join(r[j].ljust(widths[j]) for j in (0, *cols)).rstrip() for r in rows]
    return out


def cmd_compare(a: argparse.Namespace) -> int:
    from netsetest.analysis.compare import (
        TABLE_HEADER,
        assumptions_notes,
        compare,
        comparison_document,
        markdown_table,
        node_ratio_lines,
        plot_fault_bounds,
        table_rows,
    )

    checks.output_file(a.json, "--json")
    checks.output_file(a.markdown, "--markdown")
    checks.html_file(a.html)
    if a.html:
        from netsetest.extras import require

        require("bokeh", "compare --html")
    if a.plot:
        checks.output_dir(a.plot, "--plot")
    from netsetest.runtime.report import Progress

    bar = Progress(1, "compare")

    def on_progress(done: int, total: int, what: str) -> None:
        bar.total = total  # known once compare has counted its runs and estimators
        bar.update(done, what)

    c = compare(a.topology, a.estimators, (a.case,), a.signals, a.seeds, a.steps, progress=on_progress, alone=a.alone)
    bar.close()
    print(f"compare {c.topology}: runs {', '.join(c.runs)}, {c.steps} steps; widths: mean over nodes and steps ≥ 10")
    for line in folded_table([TABLE_HEADER, *table_rows(c)], TERMINAL_WIDTH):
        print(line)
    for note in assumptions_notes(c):
        print(textwrap.fill(note, TERMINAL_WIDTH, subsequent_indent="  "))
    for line in node_ratio_lines(c):
        print(line)
    for row in c.rows:
        for reason in row.refused:
            print(f"  {row.estimator} refused: {reason}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(comparison_document(c), fh, indent=1)
    if a.markdown:
        with open(a.markdown, "w") as fh:
            fh.write(markdown_table(c))
    if a.plot:
        for path in plot_fault_bounds(c, a.plot):
            print(f"wrote {path}")
    failed = [r.estimator for r in c.rows if r.violations]
    if a.html:
        from netsetest.records.report_html import ComparePage, write_compare

        title = f"netsetest compare {c.topology}: runs {', '.join(c.runs)}, {c.steps} steps"
        write_compare(a.html, ComparePage(title, TABLE_HEADER, table_rows(c), c.tau_s, c.truth_fault, c.bounds, failed, assumptions_notes(c)))
        print(f"wrote {a.html}")
    if failed:
        print(f"containment violated where the assumptions held: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0
