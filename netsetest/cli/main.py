"""``netsetest`` command line: run, inspect, plot (and the role processes of the Zenoh runtime).

Exit codes: 0 success (every ellipsoid contained where the assumptions held); 1 containment violated
on a step where the assumptions held; 2 bad input (file, option); 3 a node stopped reporting;
130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence

from netsetest.config.schema import ConfigError
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, OBJECTIVES
from netsetest.records.record import RecordError
from netsetest.runtime.report import EXIT_BAD_INPUT

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}


def _scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("topology", help="topology file, e.g. topologies/paper6.toml")
    p.add_argument("--case", choices=["nsnim", "saim"], help="override the topology's case")
    p.add_argument("--steps", type=_positive_int, help="override the number of steps")


def _run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--signals", choices=["paper", "worst"], default="paper",
                   help="paper: cos noise and uniform wind; worst: noise and wind at ±bound, random sign")  # fmt: skip
    p.add_argument("--variant", choices=["scheduled", "per-rule"], default="scheduled")
    p.add_argument("--objective", choices=list(OBJECTIVES), default=DEFAULT_OBJECTIVE,
                   help="trace: the paper's trace(P); fault: trace(diag(1, 1, 10)·P), aimed at the fault bound")  # fmt: skip
    p.add_argument("--seed", type=int, default=0)


def _positive_int(s: str) -> int:
    try:
        v = int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {s!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {v}")
    return v


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="netsetest", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="run a whole network (in memory, or as Zenoh processes)")
    _scenario_args(p)
    _run_args(p)
    p.add_argument("--mode", choices=["inmemory", "zenoh"], default="zenoh")
    p.add_argument("--clock", choices=["lockstep", "realtime"], default="lockstep")
    p.add_argument("--record", metavar="PATH", help="write the run record (JSON; .gz compresses)")
    p.add_argument("--summary-json", metavar="PATH", help="write the summary as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    from netsetest.cli import processes

    processes.add_run_options(p)
    processes.add_role_parsers(sub, _scenario_args, _run_args)

    p = sub.add_parser("inspect", help="per-step fault (and state) bounds of one node from a record")
    p.add_argument("record")
    p.add_argument("--node", type=int, help="node id (default: all nodes)")
    p.add_argument("--json", action="store_true", help="JSON rows with state bounds and true values")

    p = sub.add_parser("plot", help="figures like the paper's Figs. 5-8 from a record")
    p.add_argument("record", nargs="+", help="one record, or several (e.g. an nsnim and a saim run) for Fig. 8")
    p.add_argument("--out", required=True, help="output directory for the PNG files")

    p = sub.add_parser("bench", help="benchmark: solve times, scaling, Zenoh overhead, real time, node cost (docs/performance.md)")
    p.add_argument("--quick", action="store_true", help="fewer steps and samples (a few minutes)")
    p.add_argument("--json", metavar="PATH", help="write every figure as JSON")
    p.add_argument("--markdown", metavar="PATH", help="write the report as Markdown")
    return ap


def cmd_run(a: argparse.Namespace) -> int:
    if a.mode == "zenoh":
        from netsetest.cli import processes

        return processes.cmd_run_zenoh(a)
    if a.clock != "lockstep":
        print("netsetest run: --clock realtime needs --mode zenoh (the in-memory bus is lockstep only)", file=sys.stderr)
        return EXIT_BAD_INPUT
    from netsetest.config.schema import load_topology
    from netsetest.runtime.inmemory import run_inmemory
    from netsetest.runtime.report import exit_code, format_table, write_outputs

    sc = load_topology(a.topology, a.case, a.steps)
    res = run_inmemory(sc, a.signals, a.variant, a.seed, progress=not a.quiet, objective=a.objective)
    write_outputs(res.summary, res.meta, res.parts, a.record, a.summary_json)
    print(format_table(res.summary))
    return exit_code(res.summary)


def cmd_inspect(a: argparse.Namespace) -> int:
    from netsetest.records.record import load_record

    rec = load_record(a.record)
    ids = sorted(rec.nodes) if a.node is None else [a.node]
    for i in ids:
        if i not in rec.nodes:
            print(f"netsetest inspect: {a.record}: no node {i} (nodes: {sorted(rec.nodes)})", file=sys.stderr)
            return EXIT_BAD_INPUT
    if a.json:
        json.dump({str(i): rec.state_rows(i) for i in ids} if a.node is None else rec.state_rows(ids[0]), sys.stdout, indent=1)
        sys.stdout.write("\n")
        return 0
    for i in ids:
        print(f"node {i}: fault estimate and bounds f̂ ± √(ρ P33)")
        print(f"{'step':>5} {'f_true':>9} {'f_est':>9} {'lower':>9} {'upper':>9} {'E':>7}  status")
        for r in rec.fault_rows(i):
            ft = "-" if r["fault_true"] is None else f"{r['fault_true']:9.4f}"
            e = "-" if r["E"] is None else f"{r['E']:7.3f}"
            flag = "" if r["contained"] else "  MISS"
            print(f"{r['step']:5d} {ft:>9} {r['fault_estimate']:9.4f} {r['fault_lower']:9.4f} {r['fault_upper']:9.4f} {e:>7}  {r['status']}{flag}")
        print()
    return 0


def cmd_plot(a: argparse.Namespace) -> int:
    from netsetest.records.plots import plot_records
    from netsetest.records.record import load_record

    files = plot_records([load_record(r) for r in a.record], a.out)
    for f in files:
        print(f)
    return 0


def cmd_bench(a: argparse.Namespace) -> int:
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]  # the benchmark lives next to the package, in bench/
    if not (root / "bench" / "run.py").exists():
        print(f"netsetest bench: needs a source checkout ({root / 'bench'} not found)", file=sys.stderr)
        return EXIT_BAD_INPUT
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    from bench.run import run_bench

    return run_bench(a.quick, a.json, a.markdown)


COMMANDS.update(run=cmd_run, inspect=cmd_inspect, plot=cmd_plot, bench=cmd_bench)


def main(argv: Sequence[str] | None = None) -> int:
    ap = build_parser()
    a = ap.parse_args(argv)
    from netsetest.cli import processes

    handler = COMMANDS.get(a.command) or processes.COMMANDS[a.command]
    try:
        return handler(a)
    except (ConfigError, RecordError) as exc:
        print(f"netsetest {a.command}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"netsetest {a.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
