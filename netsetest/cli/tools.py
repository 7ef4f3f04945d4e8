"""``netsetest echo``, ``watch`` (live views of a running run), ``export`` (records as tables) and ``report``
(records as one HTML page)."""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from netsetest.cli import checks
from netsetest.runtime import argtypes

if TYPE_CHECKING:
    from netsetest.runtime.live import Observer

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}
WATCH_REFRESH_HZ = 4.0
PIPE_WIDTH = 160  # watch's table width when stdout is not a terminal (a log, a test): never truncated
POLL_S = 0.1  # how often the loops look at the clock while no message arrives
END_GRACE_S = 2.0  # End can overtake the last states (other paths): wait this long for them, as the collector does


def _seconds(s: str) -> float:
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {s!r}") from None
    if not v > 0 or v == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {s}")
    return v


def _observer_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--run-id", type=checks.run_id, help="the run to observe (default: every run on the network, '*')")
    p.add_argument(
        "--connect",
        type=checks.endpoint,
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="Zenoh endpoint of the run, e.g. tcp/127.0.0.1:7447: a router or a role's --listen endpoint (repeatable; default: none)",
    )
    p.add_argument("--zenoh-mode", choices=["peer", "client"], default="peer", help="peer (default) or client of a router")
    p.add_argument("--zenoh-config", metavar="FILE", help="Zenoh configuration file (JSON5) to start from; --connect adds endpoints to it (default: none)")
    p.add_argument(
        "--credentials",
        metavar="DIR",
        help="a secured run's credentials directory (printed by `netsetest run`, or made by `netsetest credentials`): "
        "connect to its router as the read-only observer; run id and endpoint from DIR unless given (default: none)",
    )
    p.add_argument("--duration", type=_seconds, metavar="S", help="stop after S seconds (default: until Ctrl-C)")


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("echo", help="print the decoded messages of a running run (like ros2 topic echo)")
    p.add_argument("key", nargs="?", help="key expression, relative to the run (node/3/state, vehicle/**) or absolute (netsetest/...); default: everything")
    _observer_args(p)
    p.add_argument("--count", type=checks.positive_int, metavar="N", help="stop after N messages (default: no limit)")
    p.add_argument("--json", action="store_true", help="one JSON object per line: key and message fields")

    p = sub.add_parser(
        "watch",
        help="live per-node table of a running run: step, fault bound, whether the truth is in the published set (the collector's rule), E, drops, deadline misses",
    )
    _observer_args(p)

    p = sub.add_parser("view", help="live view of a running run in Rerun's web viewer, served from this machine (no internet): intervals, sets, graph, verdict")
    _observer_args(p)
    view_args(p)

    p = sub.add_parser("export", help="per-node tables of a record for pandas/polars (Parquet or CSV)")
    p.add_argument("record", help="record file (.json, .json.gz or .mcap)")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--parquet", metavar="DIR", help="write DIR/node_<i>.parquet (needs pip install 'netsetest[export]')")
    g.add_argument("--csv", metavar="DIR", help="write DIR/node_<i>.csv")

    p = sub.add_parser("report", help="one self-contained HTML page of one or more records: verdict, tables, graph, interactive Figs. 5-8")
    p.add_argument("record", nargs="+", help="record files (.jsonl, .json.gz or .mcap)")
    p.add_argument("--html", metavar="PATH", required=True, help="the page to write, PATH.html (needs pip install 'netsetest[view]')")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --html page (default: refuse it)")
    p.add_argument(
        "--exact",
        metavar="JSON",
        action="append",
        default=[],
        help="a `netsetest exact RECORD --json JSON` document: its ratios go beside the record it names (repeatable; default: none)",
    )


def view_args(p: argparse.ArgumentParser) -> None:
    """The live view's options (``view``, and ``run --view`` hands them to the view it starts)."""
    p.add_argument(
        "--port",
        type=argtypes.port,
        default=0,
        metavar="N",
        help="the view's one port on 127.0.0.1: its page and its stream (default: 0, a free one; fix it to forward it with ssh -L; "
        "the address printed is the key to the view)",
    )
    p.add_argument("--tau-s", type=_seconds, metavar="S", help="the run's sampling period: a time axis and the car's path (default: steps only)")
    p.add_argument(
        "--lag-json",
        metavar="PATH",
        help="write the view's lag behind a real-time run per step, and the frames it dropped, as JSON to PATH when it stops "
        "(the benchmark's measure; default: none)",
    )


class ObserverError(Exception):
    """echo/watch cannot observe: bad credentials, no run id for them, or no Zenoh session."""


_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequest:
    """Ctrl-C and SIGTERM ask echo/watch to stop; their loops look between polls.

    A flag rather than an exception: an exception could fall between opening the session and the
    ``try`` that closes it, and an open Zenoh session keeps the interpreter from exiting (CI once saw
    ``watch`` hang after a Ctrl-C that arrived while it opened). A second signal cannot cut the close short."""

    def __init__(self) -> None:
        self.requested = False

    def __call__(self, signum: int, frame: object) -> None:
        self.requested = True


def _open_observer(a: argparse.Namespace, key: str | None) -> Observer:
    from netsetest.bus.zenoh_bus import BusError
    from netsetest.runtime.live import Observer, observed_key, observer_config
    from netsetest.runtime.security import CredentialsError, observer_access

    try:
        access = observer_access(a.credentials) if a.credentials else None
    except CredentialsError as exc:
        raise ObserverError(f"--credentials: {exc}") from None
    run_id = a.run_id or (access.run_id if access else None)
    if access is not None and run_id is None:  # the observer's grant covers one run's keys, not '*'
        raise ObserverError(f"--credentials {a.credentials}: no run id there; give it with --run-id")
    a.run_id = run_id  # what watch's title names
    try:
        return Observer(observed_key(run_id, key), observer_config(a.zenoh_mode, a.connect, a.zenoh_config, access))
    except BusError as exc:
        raise ObserverError(str(exc)) from None


@contextmanager
def observing(a: argparse.Namespace, key: str | None) -> Iterator[tuple[Observer, StopRequest]]:
    """The observer's session, closed however the body ends, and the stop request its loop watches."""
    stop = StopRequest()
    previous = {sig: signal.signal(sig, stop) for sig in _STOP_SIGNALS}  # before the session opens
    try:
        obs = _open_observer(a, key)
        try:
            yield obs, stop
        finally:
            obs.close()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


SILENCE_HINT_S = 3.0  # seconds without a message before echo/watch say why they may hear nothing


class SilenceHint:
    """Says once, on stderr, that nothing was heard and the likely reason (a secured run needs its
    credentials: echo and watch without them printed nothing and exited 0, or waited for ever)."""

    def __init__(self, command: str, a: argparse.Namespace) -> None:
        self.command, self.a = command, a
        self.deadline: float | None = time.monotonic() + SILENCE_HINT_S

    def heard(self) -> None:
        self.deadline = None

    def tick(self) -> None:
        if self.deadline is None or time.monotonic() < self.deadline:
            return
        self.deadline = None
        a = self.a
        why = (
            f"is the run still going, and is its run id {a.run_id!r}?"
            if a.credentials
            else "a secured run (the default) lets no one in without its credentials: give --credentials DIR "
            "(the run prints it: 'watch it with: netsetest watch --credentials DIR')" + ("" if a.connect else "; an --insecure run needs --connect ENDPOINT")
        )
        print(f"netsetest {self.command}: nothing heard in {SILENCE_HINT_S:g} s; {why}", file=sys.stderr, flush=True)


def cmd_echo(a: argparse.Namespace) -> int:
    end = None if a.duration is None else time.monotonic() + a.duration
    shown = 0
    hint = SilenceHint("echo", a)
    with observing(a, a.key) as (obs, stop):
        while not stop.requested and (a.count is None or shown < a.count) and (end is None or time.monotonic() < end):
            got = obs.get(POLL_S)
            if got is None:
                hint.tick()
                continue
            hint.heard()
            doc = got.as_json()
            if a.json:
                print(json.dumps(doc, separators=(",", ":")), flush=True)
            else:
                key = doc.pop("key")
                print(f"{key}  {json.dumps(doc, separators=(', ', ': '))}", flush=True)
            shown += 1
    return 0


def _fmt(v: float | None, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def _render(table, title: str):  # LiveTable → rich Table
    from rich.table import Table

    t = Table(title=title)
    cols = (
        "node",
        "step",
        "status",
        "fault lower",
        "fault upper",
        "fault",
        "detected from",
        "truth",
        "missed",
        "E (step)",
        "ρ",
        "lost",
        "missing",
        "dropped",
        "deadline",
    )
    for col in cols:
        t.add_column(col, justify="right")
    for r in table.sorted_rows():
        E = "-" if r.E is None else f"{r.E:.3f} ({r.E_step})"
        held = (
            "-" if r.contained is None else "in set" if r.contained else "MISSED" if r.certain_miss else "undecided"
        )  # at E's step, by the collector's rule (runtime/live.py)
        t.add_row(
            str(r.id),
            _fmt(r.step, "d"),
            r.status,
            _fmt(r.fault_lower, ".4f"),
            _fmt(r.fault_upper, ".4f"),
            r.fdi,
            _fmt(r.first_detection, "d"),
            held,
            f"{r.missed} of {r.judged}" + (f" ({r.undecided} undecided)" if r.undecided else ""),
            E,
            _fmt(r.rho, ".3g"),
            str(r.lost),
            str(r.missing),
            str(r.dropped),
            str(r.deadline_misses),
        )
    return t


def cmd_watch(a: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.live import Live

    from netsetest.runtime.live import LiveTable

    table = LiveTable()
    end = None if a.duration is None else time.monotonic() + a.duration
    with observing(a, None) as (obs, stop):
        hint = SilenceHint("watch", a)
        title = f"netsetest run {a.run_id or '*'}"
        console = Console(width=None if sys.stdout.isatty() else PIPE_WIDTH)
        with Live(_render(table, title), console=console, refresh_per_second=WATCH_REFRESH_HZ) as live:
            next_draw, ended_at = 0.0, None
            while not stop.requested and (end is None or time.monotonic() < end):
                if table.ended is not None:
                    ended_at = ended_at or time.monotonic()
                    if table.complete or time.monotonic() - ended_at > END_GRACE_S:
                        break
                got = obs.get(POLL_S)
                if got is not None:
                    hint.heard()
                    table.update(got.message)
                else:
                    hint.tick()
                if time.monotonic() >= next_draw or table.ended is not None:
                    live.update(_render(table, title + (f": ended after {table.ended.steps} steps" if table.ended else "")))
                    next_draw = time.monotonic() + 1.0 / WATCH_REFRESH_HZ
    return 0


def cmd_view(a: argparse.Namespace) -> int:
    from netsetest.extras import require

    require("rerun", "the live view")
    from netsetest.runtime.report import EXIT_INTERRUPTED
    from netsetest.runtime.view import APP_ID, LiveView
    from netsetest.runtime.view_process import write_lag
    from netsetest.runtime.view_server import PortTaken, ViewError, serve

    checks.output_file(a.lag_json, "--lag-json")
    with observing(a, None) as (obs, stop):
        try:
            server = serve(a.port, APP_ID)
        except PortTaken as exc:
            raise ObserverError(f"--port {a.port}: {exc}") from None
        except ViewError as exc:
            raise ObserverError(str(exc)) from None
        try:
            view, hint = LiveView(server.rec, a.tau_s, outlet=server.send), SilenceHint("view", a)
            end = None if a.duration is None else time.monotonic() + a.duration  # from here: the viewer's start-up takes seconds on a busy machine
            try:
                print(f"live view of run {a.run_id or '*'}: {server.url}", flush=True)  # stdout only: the address is the key to the view
                while not stop.requested and (end is None or time.monotonic() < end):  # after the run's end it still serves, until Ctrl-C
                    got = obs.get(POLL_S)
                    if got is not None:
                        hint.heard()
                        view.feed(got.message, obs.backlog())
                    else:
                        hint.tick()
            finally:
                if a.lag_json is not None:
                    write_lag(view, a.lag_json)  # first: `run --view` gives the view a few seconds to stop before it kills it
        finally:
            server.close()
    return EXIT_INTERRUPTED if stop.requested else 0  # Ctrl-C or SIGTERM ended it, as `run` reports it


def cmd_export(a: argparse.Namespace) -> int:
    from netsetest.records.export import export_record
    from netsetest.records.record import load_record

    fmt, out = ("parquet", a.parquet) if a.parquet else ("csv", a.csv)
    for f in export_record(load_record(a.record), out, fmt):
        print(f)
    return 0


def cmd_report(a: argparse.Namespace) -> int:
    from netsetest.extras import require

    require("bokeh", "the HTML report")
    from netsetest.records.record import load_record
    from netsetest.records.report_html import RecordPage, attach_exact, load_exact, write_report
    from netsetest.runtime.report import format_table

    checks.html_file(a.html)
    checks.not_replaced(a.html, "--html", a.overwrite)
    records = [load_record(r) for r in a.record]
    exact = attach_exact(records, [(path, load_exact(path)) for path in a.exact])
    labels = [f"{r.meta.case or '?'}/{r.meta.signals or '?'}" + (f" #{n}" if len(records) > 1 else "") for n, r in enumerate(records)]
    pages = []
    for rec, label, doc in zip(records, labels, exact):
        table = "" if rec.summary is None else format_table(rec.summary)
        verdict = table.splitlines()[-1] if table else ""
        pages.append(RecordPage(rec, label, verdict, table, doc))
    size = write_report(a.html, pages)
    print(f"wrote {a.html} ({size / 1e6:.1f} MB)")
    return 0


COMMANDS.update(echo=cmd_echo, watch=cmd_watch, view=cmd_view, export=cmd_export, report=cmd_report)
