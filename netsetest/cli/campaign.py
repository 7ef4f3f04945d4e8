"""``netsetest campaign CAMPAIGN.toml``: many runs on every core or a cluster, their rows in a Parquet dataset
(logic in netsetest/campaign/; the file format and the results: docs/campaign.md)."""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from netsetest.extras import MissingExtra, require
from netsetest.runtime import argtypes
from netsetest.runtime.report import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_OK, EXIT_VIOLATION

if TYPE_CHECKING:
    import pyarrow as pa
    from rich.progress import Progress, TaskID

    from netsetest.campaign.engines import Engine
    from netsetest.campaign.runner import Tally
    from netsetest.campaign.spec import Campaign
    from netsetest.campaign.store import Compaction, Store

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}
RESULTS_SUFFIX = ".results"  # the default results directory: the campaign file's name with this instead of .toml
WORST_SHOWN = 5  # runs listed with their replay command at the end (the report lists more)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("campaign", help="many runs (a grid or a list in a TOML file) on every core or a Dask cluster; one Parquet row per run and node")
    p.add_argument("campaign", help="the campaign file (TOML: docs/campaign.md)")
    p.add_argument("--out", metavar="DIR", help=f"the results directory (default: the campaign file's path with {RESULTS_SUFFIX} for .toml)")
    p.add_argument("--workers", type=argtypes.positive_int, metavar="N", help="local worker processes (default: one per core)")
    p.add_argument(
        "--cluster",
        metavar="ADDRESS",
        help="an existing Dask scheduler, e.g. tcp://10.0.0.1:8786, instead of the local pool (the cluster extra; docs/campaign.md)",
    )
    p.add_argument("--report", action="store_true", help="then write DIR/report.html (one self-contained page) and DIR/summary.md (the view extra)")
    p.add_argument("--dry-run", action="store_true", help="only check the file and count the runs to do")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    COMMANDS["campaign"] = cmd_campaign


class _Bar:
    """Runs done, failed and the time left: a rich bar on a terminal, a line every 10 % otherwise (stderr)."""

    def __init__(self, enabled: bool) -> None:
        self.enabled, self.tty = enabled, enabled and sys.stderr.isatty()
        self.rich: Progress | None = None
        self.task: TaskID | None = None
        self.last = -1

    def __call__(self, t: Tally) -> None:
        if not self.enabled:
            return
        eta = t.eta_s()
        text = f"{t.done}/{t.todo} runs, {t.failed} failed, {t.errors} errors" + ("" if eta is None else f", {eta:.0f} s left")
        if self.tty:
            if self.rich is None:
                from rich.console import Console
                from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

                self.rich = Progress(
                    TextColumn("campaign"),
                    BarColumn(),
                    MofNCompleteColumn(),
                    TextColumn("failed {task.fields[failed]}, errors {task.fields[errors]}"),
                    TimeRemainingColumn(),
                    console=Console(stderr=True),
                )
                self.rich.start()
                self.task = self.rich.add_task("runs", total=t.todo, failed=0, errors=0)
            assert self.task is not None  # added with the bar
            self.rich.update(self.task, completed=t.done, failed=t.failed, errors=t.errors)
            return
        tenth = 10 * t.done // max(t.todo, 1)
        if tenth != self.last:
            print(f"campaign: {text}", file=sys.stderr, flush=True)
            self.last = tenth

    def close(self) -> None:
        if self.rich is not None:
            self.rich.stop()


def cmd_campaign(a: argparse.Namespace) -> int:
    from netsetest.campaign.spec import CampaignError, load_campaign

    try:
        c = load_campaign(a.campaign)
        if a.cluster is not None:
            from netsetest.campaign.engines import cluster_address

            if a.workers is not None:
                raise CampaignError("--workers is the local pool's; a cluster has the workers it was started with")
            a.cluster = cluster_address(a.cluster)
            require("distributed", "netsetest campaign --cluster")
        if a.report:
            require("bokeh", "campaign --report")
        require("pyarrow", "netsetest campaign (its Parquet dataset)")
        require("pandas", "netsetest campaign (its verdicts)")
    except (CampaignError, MissingExtra) as exc:
        print(f"netsetest campaign: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    out = Path(a.out) if a.out else Path(a.campaign).with_suffix(RESULTS_SUFFIX)
    try:
        return _run(a, c, out)
    except CampaignError as exc:  # the results directory: locked by another campaign, a damaged file
        print(f"netsetest campaign: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


def _run(a: argparse.Namespace, c: Campaign, out: Path) -> int:
    from netsetest.campaign.engines import engine
    from netsetest.campaign.spec import CampaignError
    from netsetest.campaign.store import Store

    if a.dry_run:
        with contextlib.closing(Store(out)) if out.exists() else contextlib.nullcontext() as store:
            todo = sum(p.key not in (store.written if store else ()) for p in c.runs)
        print(f"campaign {c.name}: {len(c.runs)} runs, {len(c.runs) - todo} already in {out}, {todo} to run")
        return EXIT_OK
    eng = engine(a.cluster, a.workers)  # a cluster is reached before anything is written
    try:
        store = Store(out)
    except CampaignError:
        eng.close()
        raise
    try:
        tally = _campaign(a, c, out, store, eng)
        table = store.table([p.key for p in c.runs])
    finally:
        eng.close()
        store.close()
    if tally is not None and tally.interrupted:
        print(f"netsetest campaign: interrupted; {tally.done} run(s) of this session saved in {out}, the rest runs on the next start", file=sys.stderr)
        return EXIT_INTERRUPTED
    code = _print_outcome(c, table)
    if a.report:
        from netsetest.campaign.report import write_report

        for path in write_report(c, table, out):
            print(f"wrote {path}")
    return code


def _campaign(a: argparse.Namespace, c: Campaign, out: Path, store: Store, eng: Engine) -> Tally | None:
    """The runs ``store`` does not hold yet on ``eng``, with the progress bar (None: nothing to run)."""
    from netsetest.campaign.runner import run_campaign

    todo = sum(p.key not in store.written for p in c.runs)
    where = "nothing to run" if not todo else f"on {a.cluster}" if a.cluster else f"on {eng.workers} local worker(s)"
    print(f"campaign {c.name}: {len(c.runs)} runs, {len(c.runs) - todo} already done, {todo} to run {where}; results in {out}", file=sys.stderr)
    if not todo:
        _say_compacted(store.compact())  # an earlier session's, interrupted after its last run
        return None
    bar = _Bar(not a.quiet)
    t0 = time.monotonic()
    try:
        tally = run_campaign(c, store, eng, bar)
    finally:
        bar.close()
    print(f"ran {tally.done} run(s) in {time.monotonic() - t0:.1f} s", file=sys.stderr)
    for comp in tally.compactions:
        _say_compacted(comp)
    return tally


def _say_compacted(comp: Compaction) -> None:
    """A line where the results were compacted, or could not be (the files are as they were)."""
    if comp.skipped is not None:
        print(f"campaign: the results stay in {comp.files_after} files, not compacted: {comp.skipped}", file=sys.stderr)
    elif comp.partitions:
        print(f"campaign: compacted the results, {comp.files_before} files into {comp.files_after} ({comp.wall_s:.1f} s)", file=sys.stderr)


def _print_outcome(c: Campaign, table: pa.Table) -> int:
    """The campaign's verdicts over all its runs (this session's and earlier ones), the worst runs' replay commands."""
    from netsetest.campaign.report import run_verdicts, worst_runs

    verdicts = run_verdicts(table)
    counts = ", ".join(f"{n} {v}" for v, n in sorted(verdicts.items()))
    missing = len(c.runs) - sum(verdicts.values())
    print(
        f"campaign {c.name}: {sum(verdicts.values())} of {len(c.runs)} runs in the results: {counts or 'none'}"
        + (f"; {missing} not run yet" if missing else "")
    )
    bad = worst_runs(table, WORST_SHOWN)
    for r in bad:
        print(f"  {r['verdict']}: {r['cause']}\n    replay: {r['replay']}")
    failed = sum(n for v, n in verdicts.items() if not v.startswith("PASS"))  # PASS, PASS (partial coverage): exit 0
    return EXIT_VIOLATION if failed else EXIT_OK
