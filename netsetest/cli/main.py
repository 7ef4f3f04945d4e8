"""``netsetest`` command line: every command's parser (:func:`build_parser`) and handler (:func:`handlers`).

``netsetest --help`` lists the commands from the parser itself (:func:`describe`), so no command is left out.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import math
import os
import sys
import textwrap
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from netsetest.analysis.errors import DEFAULT_BUDGET_S as DEFAULT_EXACT_BUDGET_S
from netsetest.analysis.errors import CompareError, ExactError
from netsetest.cli import checks
from netsetest.config.schema import ConfigError
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, OBJECTIVE_HELP, OBJECTIVES
from netsetest.models.manoeuvres import MANOEUVRES, WITH_AMPLITUDE
from netsetest.models.signals import SIGNAL_KINDS
from netsetest.extras import MissingExtra, require
from netsetest.logs.readers import LogError
from netsetest.records.errors import RecordError
from netsetest.models.uncertainty import DEFAULT_MARGIN
from netsetest.runtime.report import EXIT_BAD_INPUT, EXIT_INTERRUPTED
from netsetest.scenarios import topology_help
from netsetest.runtime.rolespec import LOG_HELP, MAP_HELP

if TYPE_CHECKING:  # a role process never loads the records (memory: docs/performance-history.md)
    from netsetest.analysis.calibrate import Calibration, DriveMismatch, HeldOutLog, LogCalibration
    from netsetest.analysis.exact import ExactBounds
    from netsetest.config.schema import Scenario
    from netsetest.models.envelope import OperatingEnvelope
    from netsetest.models.plant import PlantKind
    from netsetest.records.record import Record

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}

HELP_WIDTH = 100  # characters: the description's paragraphs (RawDescriptionHelpFormatter keeps the exit codes' lines)
SUMMARY = "netsetest: guaranteed (set-membership) estimation of a car's state and its yaw-rate sensors' faults by a network of nodes."
EXIT_CODES = """Exit codes: 0 success (every set contained the truth where the assumptions held); 1 containment violated
on a step where the assumptions held; 2 bad input (file, option); 3 a node stopped reporting;
130 interrupted."""


def _scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("topology", help=topology_help())
    p.add_argument("--case", choices=["nsnim", "saim"], help="override the topology's case (default: the file's)")
    p.add_argument("--steps", type=checks.positive_int, metavar="N", help="override the number of steps of τs each (default: the file's)")


def _run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--signals", choices=["paper", "worst"], default="paper", help="paper: cos noise and uniform wind; worst: noise and wind at ±bound, random sign"
    )
    p.add_argument("--variant", choices=["scheduled", "per-rule"], default="scheduled", help="estimator: one SDP with the scheduled model, or one per T-S rule")
    p.add_argument("--objective", choices=list(OBJECTIVES), default=DEFAULT_OBJECTIVE, help=OBJECTIVE_HELP)
    p.add_argument(
        "--seed",
        type=checks.seed,
        default=None,
        help="non-negative integer: random seed of noise, wind and losses (default: a fresh random one, printed with the verdict)",
    )


def has_default(action: argparse.Action) -> bool:
    """Whether an option has a default worth printing (not unset, not an off flag, not an empty list)."""
    d = action.default
    return d is not None and d is not False and d is not argparse.SUPPRESS and d != []


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Appends "(default: X)" to an option's help unless the help names its default or it has none."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if not action.option_strings or "default" in text or not has_default(action):
            return text
        return f"{text} (default: %(default)s)"


class ShowVersion(argparse.Action):
    """``--version``: the installed version, looked up only when asked for (it costs ~90 ms)."""

    def __init__(self, option_strings: list[str], dest: str, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object, option_string: str | None = None) -> None:
        import netsetest

        print(f"netsetest {netsetest.__version__}")
        parser.exit()


def describe(sub: argparse._SubParsersAction) -> str:
    """``netsetest --help``'s description: every command the parser has (a role process's apart, the
    internal ones left out), in the order they are listed below it."""
    from netsetest.cli.processes import INTERNAL_COMMANDS, ROLE_COMMANDS

    users = [c for c in sub.choices if c not in ROLE_COMMANDS and c not in INTERNAL_COMMANDS]
    commands = (
        f"commands: {', '.join(users)}; the role processes of a Zenoh run or deployment: {', '.join(ROLE_COMMANDS)} (netsetest COMMAND --help says more)."
    )
    return "\n\n".join((textwrap.fill(SUMMARY, HELP_WIDTH), textwrap.fill(commands, HELP_WIDTH, break_on_hyphens=False), EXIT_CODES))  # a name stays whole


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="netsetest", formatter_class=HelpFormatter)
    ap.add_argument("--version", action=ShowVersion, help="print the version and exit")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")

    from netsetest.cli import processes

    p = sub.add_parser("run", help="run a whole network (in memory, or as Zenoh processes)")
    _scenario_args(p)
    _run_args(p)
    processes.scenario_overrides(p)
    p.add_argument("--mode", choices=["inmemory", "zenoh"], default="zenoh", help="one process, or one process per role over Zenoh")
    p.add_argument(
        "--clock",
        choices=["lockstep", "realtime"],
        default="lockstep",
        help="lockstep: the vehicle waits for every node; realtime: one step every τs (zenoh mode)",
    )
    p.add_argument("--record", metavar="PATH", help="write the run record: JSON, .gz compresses, .mcap for Foxglove (default: none)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --record file (default: refuse it)")
    p.add_argument("--summary-json", metavar="PATH", help="write the summary as JSON (default: none)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.add_argument("--strict", action="store_true", help="exit 1 where any set missed the truth outside the guarantee too (default: only misses it covered)")
    p.add_argument("--log", metavar="DRIVE", help=LOG_HELP)
    p.add_argument("--map", metavar="MAP.toml", help=MAP_HELP)
    processes.add_run_options(p)
    processes.add_role_parsers(sub)

    p = sub.add_parser("inspect", help="per-step fault (and state) bounds of one node from a record")
    p.add_argument("record", help="record file (.json, .json.gz or .mcap)")
    p.add_argument("--node", type=int, help="node id (default: all nodes)")
    p.add_argument("--json", action="store_true", help="JSON rows with state bounds and true values")
    p.add_argument("--state", action="store_true", help="β, r and f bounds per step and the cut each interval rests on")

    p = sub.add_parser("plot", help="figures like the paper's Figs. 5-8 from a record")
    p.add_argument("record", nargs="+", help="one record, or several (e.g. an nsnim and a saim run) for Fig. 8")
    p.add_argument("--out", required=True, help="output directory for the PNG files")

    p = sub.add_parser("exact", help="the exact tightest bounds any guaranteed estimator could publish, against a record")
    p.add_argument("record", help="a run record (JSON, JSON Lines, .gz or .mcap)")
    p.add_argument("--json", metavar="PATH", help="write the per-step exact intervals and the ratios as JSON")
    p.add_argument("--topology", metavar="PATH", help=topology_help("the record's topology (default: the one the record names)"))
    p.add_argument(
        "--fault-bounds",
        choices=["used", "all", "none"],
        default="used",
        help="declared fault bounds: where the estimator relies on them (saturating sensors) and reference sensors (size = 0), everywhere, or nowhere",
    )
    p.add_argument(
        "--local",
        action="store_true",
        help="also each node's exact limit from its own data alone, against the whole network's: what the exchange could buy it at best (docs/network.md)",
    )
    p.add_argument(
        "--network",
        action="store_true",
        help="also each node's network limit: the tightest it could publish from what the topology carries to it by each "
        "step (node j's data d(j→i) steps late), against the record and against the central limit (docs/exact.md)",
    )
    p.add_argument(
        "--no-health",
        action="store_true",
        help="leave out a declared [network] max_faulty (the k-of-N health, applied by branch and bound otherwise): an outer bound of the limit (docs/exact.md)",
    )
    p.add_argument(
        "--budget",
        type=checks.non_negative_seconds,
        default=DEFAULT_EXACT_BUDGET_S,
        metavar="SECONDS",
        help=f"CPU seconds for the exact limit under k-of-N health (default {DEFAULT_EXACT_BUDGET_S:g}); past them every end "
        "one solve does not settle is relaxed: an outer bound, labelled (docs/exact.md)",
    )
    p = sub.add_parser("calibrate", help="the smallest model-mismatch bound covering a plant's e_k on training manoeuvres")
    p.add_argument("topology", help=topology_help("a topology with a nonlinear plant ([vehicle] plant, e.g. paper6_car)"))
    p.add_argument(
        "--manoeuvres",
        type=checks.drive_list,
        metavar="A,B@AMP,...",
        help=f"training manoeuvres, comma-separated: {', '.join(MANOEUVRES)}; NAME@AMP steers "
        f"{', '.join(WITH_AMPLITUDE)} with amplitude AMP rad instead of [steering] high (e.g. an "
        "FMVSS 126 series sine-dwell@0.012,sine-dwell@0.02,sine-dwell@0.03)",
    )
    p.add_argument("--seeds", type=checks.seed_list, default=tuple(range(5)), metavar="A-B,...", help="seeds of the training drives, e.g. 0-9 (default: 0-4)")
    p.add_argument(
        "--signals",
        type=checks.name_list(SIGNAL_KINDS, "signal kind"),
        default=SIGNAL_KINDS,
        metavar="A,B",
        help="signal families of the training drives (default: paper,worst)",
    )
    p.add_argument("--steps", type=checks.positive_int, help="steps per drive (default: the topology's)")
    p.add_argument(
        "--margin",
        type=checks.non_negative_float,
        default=DEFAULT_MARGIN,
        help=f"relative enlargement of the half-widths and semi-axes (default: {DEFAULT_MARGIN})",
    )
    p.add_argument(
        "--causes",
        action="store_true",
        help="also drive the same car's simpler models (multi-body → single-track → linear tyres): how much of e_k each cause contributes",
    )
    p.add_argument("--json", metavar="PATH", help="write the bounds and the per-drive maxima as JSON")
    p.add_argument(
        "--envelope",
        action="store_true",
        help="instead of --manoeuvres: a sweep of step steers and sines with dwell filling the operating envelope --ay-max, --speed; "
        "prints the bound and the [envelope] it holds for (docs/plant.md)",
    )
    p.add_argument("--toml", metavar="PATH", help="also write the box (and with --envelope the [envelope] table) to PATH, to append to the topology")
    p.add_argument(
        "--ay-max", type=checks.positive_float, metavar="M/S2", help="the envelope's largest |lateral acceleration| the tyres carry [m/s²] (with --envelope)"
    )
    p.add_argument("--speed", type=checks.speed_range, metavar="LO-HI", help="the envelope's speed range [km/h], e.g. 70-120 (with --envelope)")
    p.add_argument(
        "--logs",
        nargs="+",
        type=checks.log_with_map,
        metavar="TRAIN[:MAP.toml]",
        help="instead of --manoeuvres: recorded drives with a reference (docs/your-log.md), each with its own mapping after a ':' where "
        "it has one: the mismatch bound from the reference's states (its accuracy carried through the model), each sensor's noise bound "
        "over its healthy stretches, the envelope they covered",
    )
    p.add_argument(
        "--held-out",
        nargs="+",
        type=checks.log_with_map,
        metavar="TEST[:MAP.toml]",
        help="with --logs: drives checked against what the training logs gave (each with its own mapping after a ':' where it has one)",
    )
    p.add_argument(
        "--map",
        metavar="MAP.toml",
        help="with --logs: the mapping of every drive named without its own (default: each log's name with .map.toml, else the topology's)",
    )

    p = sub.add_parser("log-example", help="write the synthetic example drives of docs/your-log.md (every log format, with mappings)")
    p.add_argument("directory", help="where to write them (created)")
    p.add_argument("--seconds", type=checks.positive_float, default=10.0, help="the drive's length [s]")
    p.add_argument("--seed", type=checks.seed, default=1, help="the drive's seed (the same seed writes the same drive)")

    p = sub.add_parser("bench", help="the performance benchmark: solve times, tightness, Zenoh overhead, start-up, memory, real-time scale, defences")
    p.add_argument("--quick", action="store_true", help="fewer steps and samples (the report's header says how long the run took)")
    p.add_argument("--json", metavar="PATH", help="write every figure as JSON (default: none)")
    p.add_argument("--markdown", metavar="PATH", help="write the report as Markdown (default: none)")
    p.add_argument(
        "--only",
        choices=_bench_sections(),
        help="run one part alone: plant = a car as the truth, network = what the exchange can buy, scenario = the paper's "
        "scenario per node and every estimator compared, exact = what `netsetest exact` costs under k-of-N health, view = the live "
        "view's cost and lag and the report page in headless Chromium, scaleout = a run across two network namespaces against one (root), "
        "logs = a recorded drive as the world: a 30-minute bag's import, replay speed, calibration from logs and a held-out drive "
        "(default: every part)",
    )
    p.add_argument(
        "--baseline",
        metavar="DIR",
        help="with --only node, widths or performance: another checkout (node: say main's; widths: 29290ba's; performance: "
        "16f81b4's, issue 45's figures) measured alternately beside this one",
    )
    p.add_argument(
        "--render-docs",
        nargs="?",
        const=".",
        metavar="ROOT",
        help="measure nothing: rewrite docs/results.md and the generated sections of README.md, docs/performance.md, docs/exact.md, docs/records.md "
        "under ROOT (default: .) from the committed figures, bench/*.json",
    )
    p.add_argument(
        "--spread",
        nargs="+",
        metavar="FIGURES",
        help="measure nothing: the headline figures of several runs' --json files side by side, their median and spread "
        "(how noisy the benchmark is); with --json / --markdown, write them",
    )

    from netsetest.cli import campaign, compare, tools

    tools.add_parsers(sub)
    compare.add_parser(sub, _scenario_args)
    campaign.add_parser(sub)
    for command in sub.choices.values():
        command.formatter_class = HelpFormatter
    ap.description = describe(sub)
    return ap


def cmd_run(a: argparse.Namespace) -> int:
    checks.record_file(a.record, a.overwrite)
    checks.output_file(a.summary_json, "--summary-json")
    a.seed = checks.seed_or_fresh(a.seed)
    if a.mode == "zenoh":
        from netsetest.cli import processes

        return processes.cmd_run_zenoh(a)
    if a.clock != "lockstep":
        print("netsetest run: --clock realtime needs --mode zenoh (the in-memory bus is lockstep only)", file=sys.stderr)
        return EXIT_BAD_INPUT
    from netsetest.cli.processes import zenoh_options_given

    given = zenoh_options_given(a)
    if given:
        print(
            f"netsetest run: {', '.join(given)}: only a Zenoh run has {'it' if len(given) == 1 else 'them'} "
            "(--mode zenoh, the default); the in-memory run would ignore it",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    from netsetest.runtime.report import exit_code, format_table, write_summary
    from netsetest.runtime.runspec import RunSpec

    from netsetest.runtime.stops import StopRequests

    with StopRequests() as stop:  # Ctrl-C or SIGTERM: the steps judged so far, the verdict INTERRUPTED (exit 130)
        res = RunSpec.from_namespace(a).execute(progress=not a.quiet, record=a.record, keep=False, stop=stop)
    write_summary(res.summary, a.summary_json)
    print(format_table(res.summary, a.strict))
    return exit_code(res.summary, a.strict)


def _note_partial(command: str, rec: Record) -> None:
    if rec.partial:
        print(
            f"netsetest {command}: {rec.path}: partial record (the run did not finish; last complete step {rec.last_complete_step} of {rec.meta.steps})",
            file=sys.stderr,
        )


def cmd_inspect(a: argparse.Namespace) -> int:
    from netsetest.records.record import load_record

    rec = load_record(a.record)
    _note_partial("inspect", rec)
    ids = sorted(rec.nodes) if a.node is None else [a.node]
    for i in ids:
        if i not in rec.nodes:
            print(f"netsetest inspect: {a.record}: no node {i} (nodes: {sorted(rec.nodes)})", file=sys.stderr)
            return EXIT_BAD_INPUT
    if a.json:
        json.dump({str(i): rec.state_rows(i) for i in ids} if a.node is None else rec.state_rows(ids[0]), sys.stdout, indent=1)
        sys.stdout.write("\n")
        return 0
    if a.state:
        for i in ids:
            _print_state(rec, i)
        return 0
    for i in ids:
        _print_faults(rec, i)
    return 0


def _print_faults(rec: Record, i: int) -> None:
    """``inspect``'s table of node ``i``: its fault estimate and bounds per step, and what the collector found."""
    method = rec.meta.estimators.get(i, "sdp")
    if method == "sdp":
        cut = rec.nodes[i].has_fault_range  # the slab of a declared bound, the k-of-N pin or the region (ProvenSet.fault)
        print(
            f"node {i}: fault estimate f̂ (its ellipsoid's centre) and bounds: the ellipsoid {{x̄: (x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ}}'s "
            "extent in f" + (", cut by its fault range (a declared |f| ≤ F or the k-of-N pin) on the steps that have one" if cut else "")
        )
    else:  # a set estimator publishes its own set: its bounds are that set's interval hull
        print(f"node {i} ({method}): fault bounds of its published set (interval hull), estimate their midpoint")
    print(f"{'step':>5} {'f_true':>9} {'f_est':>9} {'lower':>9} {'upper':>9} {'E':>7}  {'fault':<9}  status")
    for r in rec.fault_rows(i):
        ft = "-" if r["fault_true"] is None else f"{r['fault_true']:9.4f}"
        e = "-" if r["E"] is None else f"{r['E']:7.3f}"
        fdi = r["fdi"] or "-"  # detected: the interval excludes 0 (docs/fdi.md)
        print(f"{r['step']:5d} {ft:>9} {r['fault_estimate']:9.4f} {r['fault_lower']:9.4f} {r['fault_upper']:9.4f} {e:>7}  {fdi:<9}  {r['status']}{_flag(r)}")
    print()


def _flag(r: dict) -> str:
    """What the collector found of a fault row's step: not judged (and why), a miss, undecided, not covered (why)."""
    flag = (
        ("  not judged; its own reading contradicts its declared bounds" if r["inconsistent"] else "  not judged")
        if not r["judged"]
        else ("" if r["contained"] else "  MISS" if r["missed"] else "  undecided (the reference's box overlaps the set)")
    )
    if r["judged"] and r["contained"] and r["continues_contained"] is False:
        flag = "  MISS (the set it continues from)"
    if r["cause"] is not None:  # outside the guarantee: why, beside a miss or alone
        flag += f"  [not covered: {r['cause']}]"
    return flag


def _print_state(rec: Record, i: int) -> None:
    """``inspect --state``: node i's β, r, f intervals per step, each with the true value and what it rests on, from the
    cuts the node named (ellipsoid, region, fault range; a set estimator's: set; ``--json``: the cuts' names)."""
    print(f"node {i}: published intervals of β [rad], r [rad/s], f [rad/s] (true value; the cut each rests on)")
    print(f"{'step':>5}  " + "  ".join(f"{name:^41}" for name in ("sideslip β", "yaw rate r", "fault f")) + "  status")
    for r in rec.state_rows(i):
        cells = []
        for name in ("beta", "r", "fault"):
            t = r[f"{name}_true"]
            cells.append(f"[{r[f'{name}_lower']:8.4f}, {r[f'{name}_upper']:8.4f}] {'-' if t is None else format(t, '8.4f'):>8} {r[f'{name}_rests_on']:<11}")
        flag = "" if not r["judged"] or r["contained"] else "  MISS" if r["missed"] else "  undecided"
        print(f"{r['step']:5d}  " + "  ".join(cells) + f"  {r['status']}{flag}")
    print()


def cmd_plot(a: argparse.Namespace) -> int:
    require("matplotlib", "drawing the figures")
    from netsetest.records.plots import plot_records
    from netsetest.records.record import load_record

    checks.output_dir(a.out, "--out")
    records = [load_record(r) for r in a.record]
    for rec in records:
        _note_partial("plot", rec)
    files = plot_records(records, a.out)
    for f in files:
        print(f)
    return 0


def cmd_exact(a: argparse.Namespace) -> int:
    import os
    import time

    from netsetest.analysis.exact import compare_record, eta_s, exact_bounds, exact_document, topology_mismatch
    from netsetest.analysis.exact_table import exact_table
    from netsetest.config.schema import load_topology
    from netsetest.records.record import load_record

    checks.output_file(a.json, "--json")
    rec = load_record(a.record)
    topology = a.topology or rec.meta.topology
    if not a.topology and not (isinstance(topology, str) and os.path.exists(topology)):
        print(f"netsetest exact: {a.record} names topology {topology!r}, not found from here (give --topology PATH)", file=sys.stderr)
        return EXIT_BAD_INPUT
    drive = rec.meta.log or {}  # a recorded drive's run: its topology with that log (plant "log"; the log itself is not read)
    sc = load_topology(str(topology), rec.meta.case, rec.meta.steps, log=drive.get("path"), mapping=drive.get("mapping"))  # type: ignore[arg-type]  # an unknown case is refused by load_topology
    if differs := topology_mismatch(sc, rec):
        print(f"netsetest exact: {a.record} was not run on topology {topology}: {differs}", file=sys.stderr)
        return EXIT_BAD_INPUT
    from netsetest.runtime.report import Progress

    t0, cpu0 = time.perf_counter(), time.process_time()
    bar = Progress(1, "exact")

    def on_progress(k: int, total: int) -> None:
        bar.total = total
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - t0
        left = eta_s(cpu, k, total, a.budget)  # CPU seconds left, shown as wall seconds at this run's pace so far
        bar.update(k, "" if left is None else f"ETA {left * wall / max(cpu, 1e-9):.0f} s")

    ex = exact_bounds(sc, rec, a.fault_bounds, progress=on_progress, health=not a.no_health, budget_s=a.budget)
    bar.close()
    cmp = compare_record(rec, ex)
    print("\n".join(exact_table(a.record, sc.case, ex, cmp, time.perf_counter() - t0).lines()))
    doc = exact_document(rec, ex, cmp)
    if a.local:
        doc["local_over_central"] = _exact_local(a, sc, rec, ex)
    if a.network:
        doc["network"] = _exact_network(a, sc, rec, ex)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(doc, fh, indent=1)
    return 0


def _exact_local(a: argparse.Namespace, sc: Scenario, rec: Record, central: ExactBounds) -> list[dict]:
    """``exact --local``: each node's exact limit from its own data over the central one, printed; the JSON document's
    ``local_over_central`` list."""
    from netsetest.analysis.exact import limit_ratios_document, local_limits
    from netsetest.analysis.exact_table import local_table
    from netsetest.runtime.report import Progress

    bar = Progress(len(sc.ids), "exact --local")
    limits = local_limits(sc, rec, a.fault_bounds, central=central, progress=lambda n, total: bar.update(n))
    bar.close()
    print("\n".join(local_table(limits).lines()))
    return limit_ratios_document(limits)


def _exact_network(a: argparse.Namespace, sc: Scenario, rec: Record, central: ExactBounds) -> dict:
    """``exact --network``: each node's network limit, its ratios against the record and against the central limit,
    printed; the JSON document's ``network`` object."""
    from netsetest.analysis.exact import compare_record, exact_bounds, network_document
    from netsetest.analysis.exact_table import network_table
    from netsetest.runtime.report import Progress

    bar = Progress(1, "exact --network")

    def on_progress(k: int, total: int) -> None:
        bar.total = total
        bar.update(k)

    net = exact_bounds(sc, rec, a.fault_bounds, progress=on_progress, health=not a.no_health, budget_s=a.budget, network=True, central=central)
    bar.close()
    cmp = compare_record(rec, net)
    print("\n".join(network_table(sc, net, cmp, central).lines()))
    return network_document(sc, net, cmp, central)


def _seed_text(seeds: Sequence[int]) -> str:
    return f"{seeds[0]}-{seeds[-1]}" if list(seeds) == list(range(seeds[0], seeds[-1] + 1)) and len(seeds) > 1 else ",".join(map(str, seeds))


def _calibration_envelope(a: argparse.Namespace) -> OperatingEnvelope | None | int:
    """The envelope ``calibrate --envelope`` fills (None: --manoeuvres instead), or exit 2 on a wrong mix."""
    from netsetest.models.envelope import OperatingEnvelope

    if not a.envelope:
        given = [o for o, v in (("--ay-max", a.ay_max), ("--speed", a.speed)) if v is not None]
        if given or a.manoeuvres is None:
            what = f"{', '.join(given)} only go with --envelope" if given else "give --manoeuvres, or --envelope with --ay-max and --speed"
            print(f"netsetest calibrate: {what}", file=sys.stderr)
            return EXIT_BAD_INPUT
        return None
    if a.manoeuvres is not None or a.ay_max is None or a.speed is None:
        what = "--envelope chooses its own drives: leave out --manoeuvres" if a.manoeuvres is not None else "--envelope needs --ay-max and --speed"
        print(f"netsetest calibrate: {what}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return OperatingEnvelope(a.ay_max, a.speed)


def _print_drives(cal: Calibration, plant: str, simpler: dict[PlantKind, list[DriveMismatch]]) -> None:
    """Per training drive: its largest |e_β|, |e_r| on the car (and each simpler model), beside what the car
    did: peak |a_y|, |r|, |β|, its speed range and peak steering rate (what bounds e_k in practice)."""
    from netsetest.analysis.calibrate import envelope_by_drive, max_by_drive

    columns = [plant, *simpler]
    maxima = [max_by_drive(cal.drives), *(max_by_drive(ds) for ds in simpler.values())]
    did = envelope_by_drive(cal.drives)
    width = max(26, *(len(label) for label in maxima[0]))
    print(f"{'plant:':>{width + 8}}" + "".join(f"  {p:^23}" for p in columns))
    print(
        f"{'drive':>{width}} {'drives':>7}"
        + f"  {'max|e_β| rad':>11} {'max|e_r| /s':>11}" * len(columns)
        + f"  {'|a_y| m/s²':>10} {'|r| rad/s':>9} {'|β| rad':>8} {'speed km/h':>12} {'|δ̇| rad/s':>10}"
    )
    for label in maxima[0]:
        d = did[label]
        print(
            f"{label:>{width}} {sum(x.label == label for x in cal.drives):>7}"
            + "".join(f"  {m[label][0]:>11.3e} {m[label][1]:>11.3e}" for m in maxima)
            + f"  {d.ay_peak:>10.2f} {d.r_peak:>9.3f} {d.beta_peak:>8.4f} {d.speed_kmh[0]:>5.1f}–{d.speed_kmh[1]:<6.1f} {d.steer_rate_peak:>10.3f}"
        )


def _calibration_doc(
    a: argparse.Namespace, cal: Calibration, sc: Scenario, envelope: OperatingEnvelope | None, simpler: dict[PlantKind, list[DriveMismatch]]
) -> dict[str, object]:
    """``calibrate --json``'s document: the bounds, the envelope they hold for, and each drive's figures."""
    import numpy as np

    from netsetest.analysis.calibrate import max_by_drive

    return {
        "topology": sc.path,
        "plant": sc.plant,
        "vehicle": sc.vehicle_id,
        "steps": sc.steps,
        "margin": a.margin,
        "seeds": list(a.seeds),
        "signals": a.signals,
        "box": np.diag(cal.box.G).tolist(),
        "ellipsoid": cal.ellipsoid.E.tolist(),
        "envelope": None if envelope is None else {"ay_max": envelope.ay_max, "speed_kmh": list(envelope.speed_kmh)},
        "drives": [
            {
                "manoeuvre": d.drive.manoeuvre,
                "amplitude": d.drive.amplitude,
                "speed_kmh": d.speed_kmh,
                "signals": d.signals,
                "seed": d.seed,
                "max_abs": d.max_abs.tolist(),
                **dataclasses.asdict(d.envelope),
            }
            for d in cal.drives
        ],
        "simpler": {plant: {label: mx.tolist() for label, mx in max_by_drive(ds).items()} for plant, ds in simpler.items()},
    }


def cmd_calibrate(a: argparse.Namespace) -> int:

    from netsetest.analysis.calibrate import calibrate, envelope_sweep, simpler_mismatch
    from netsetest.config.schema import load_topology
    from netsetest.models.plant import VEHICLE_NAMES
    from netsetest.runtime.report import Progress

    checks.output_file(a.json, "--json")
    checks.output_file(a.toml, "--toml")
    if a.logs is not None or a.held_out is not None or a.map is not None:
        return _calibrate_logs(a)
    envelope = _calibration_envelope(a)
    if isinstance(envelope, int):
        return envelope
    base = load_topology(a.topology, steps=a.steps)
    if base.plant == "ts":
        print(f"netsetest calibrate: {a.topology}: plant 'ts' is the T-S model itself (e_k = 0): nothing to calibrate", file=sys.stderr)
        return EXIT_BAD_INPUT
    bar = Progress(1, "calibrate")

    def on_progress(n: int, total: int) -> None:
        bar.total = total
        bar.update(n)

    if envelope is not None:
        try:
            scenarios = envelope_sweep(base, envelope, progress=on_progress)
        except ValueError as exc:
            bar.close()
            print(f"netsetest calibrate: {a.topology}: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
    else:
        scenarios = [load_topology(a.topology, steps=a.steps, manoeuvre=d.manoeuvre, steer_high=d.amplitude) for d in a.manoeuvres]
    try:
        cal = calibrate(scenarios, list(a.seeds), a.signals, a.margin, progress=on_progress, envelope=envelope)
    except ValueError as exc:
        bar.close()
        print(f"netsetest calibrate: {a.topology}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    simpler = simpler_mismatch(scenarios, list(a.seeds), a.signals, progress=on_progress, swept=envelope is not None) if a.causes else {}
    bar.close()
    sc = scenarios[0]
    print(
        f"model mismatch of {sc.name}: plant {sc.plant} (CommonRoad vehicle {sc.vehicle_id}, {VEHICLE_NAMES[sc.vehicle_id]}), "
        f"{sc.steps} steps per drive, seeds {_seed_text(a.seeds)}, signals {','.join(a.signals)}"
        + (f"; drives filling the envelope {envelope.text}" if envelope is not None else "")
    )
    _print_drives(cal, sc.plant, simpler)
    held = f"every e_k inside the envelope ({len(cal.samples())} transitions)" if envelope is not None else "every e_k"
    print(f"bounds covering {held} with margin {a.margin:g} (declare one in the topology):")
    print(cal.box.as_toml() + "# or\n" + cal.ellipsoid.as_toml(), end="")
    if envelope is not None:
        print("# the operating envelope it holds for (declare it beside the bound: the run checks every step against it)")
        print(envelope.as_toml(), end="")
    if a.toml:
        with open(a.toml, "w") as fh:
            fh.write("\n" + cal.box.as_toml() + ("\n" + envelope.as_toml() if envelope is not None else ""))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(_calibration_doc(a, cal, sc, envelope, simpler), fh, indent=1)
    return 0


def _logs_options_wrong(a: argparse.Namespace) -> str | None:
    """What is wrong with ``calibrate --logs``'s options (None: nothing): --held-out and --map need --logs, which
    chooses its own drives."""
    others = [o for o, v in (("--manoeuvres", a.manoeuvres), ("--envelope", a.envelope or None), ("--causes", a.causes or None), ("--steps", a.steps)) if v]
    if a.logs is None:
        return "--held-out and --map go with --logs"
    return f"--logs chooses its own drives: leave out {', '.join(others)}" if others else None


def _print_held_out(held: list[Scenario], checked: list[HeldOutLog]) -> None:
    """Per held-out drive: its transitions inside and outside the envelope, e_k against the box, each sensor's noise."""
    for t, h in zip(held, checked):
        total = sum(h.inside.values())
        print(
            f"held out {h.path} (mapping {t.log.mapping.path}): {total} transitions inside the envelope: e_k inside the box on {h.inside['inside']}, possibly outside on "  # type: ignore[union-attr]  # a log's scenario
            f"{h.inside['overlap']}, certainly outside on {h.inside['disjoint']}; outside the envelope {sum(h.outside.values())} "
            f"(certainly outside the box on {h.outside['disjoint']})"
        )
        for i, c in h.noise.items():
            if c["overlap"] or c["disjoint"]:
                print(f"  node {i}: noise possibly beyond its calibrated bound on {c['overlap']} healthy steps, certainly on {c['disjoint']}")


def _calibration_logs_doc(a: argparse.Namespace, cal: LogCalibration, train: list[Scenario], checked: list[HeldOutLog]) -> dict[str, object]:
    """``calibrate --logs --json``'s document: the bounds, the envelope and noise bounds, the held-out drives' checks."""
    import numpy as np

    return {
        "topology": train[0].path,
        "logs": cal.logs,
        "maps": [t.log.mapping.path for t in train],  # type: ignore[union-attr]  # a log's scenario
        "margin": a.margin,
        "transitions": cal.transitions,
        "box": np.diag(cal.box.G).tolist(),
        "ellipsoid": cal.ellipsoid.E.tolist(),
        "envelope": {"ay_max": cal.envelope.ay_max, "speed_kmh": list(cal.envelope.speed_kmh)},
        "R": {str(i): R for i, R in cal.R.items()},
        "noise_steps": {str(i): n for i, n in cal.noise_steps.items()},
        "held_out": [dataclasses.asdict(h) | {"noise": {str(i): c for i, c in h.noise.items()}} for h in checked],
    }


def _calibrate_logs(a: argparse.Namespace) -> int:
    """``calibrate TOPOLOGY --logs TRAIN… [--held-out TEST…]``: the bounds from recorded drives (analysis/calibrate.py)."""

    from netsetest.analysis.calibrate import calibrate_logs, check_held_out
    from netsetest.config.schema import load_topology
    from netsetest.logs.drive import with_log_steps
    from netsetest.runtime.report import Progress

    if what := _logs_options_wrong(a):
        print(f"netsetest calibrate: {what}", file=sys.stderr)
        return EXIT_BAD_INPUT
    # every step of each log, read with its own mapping, else --map's, else the default (its name with .map.toml, the topology's)
    load = lambda log, own: with_log_steps(load_topology(a.topology, log=log, mapping=own or a.map), whole=True)  # noqa: E731  # a one-line local helper
    train = [load(log, own) for log, own in a.logs]
    held = [load(log, own) for log, own in a.held_out or []]
    bar = Progress(len(train), "calibrate")
    try:
        cal = calibrate_logs(train, a.margin, progress=lambda n, total: bar.update(n))
    except ValueError as exc:
        bar.close()
        print(f"netsetest calibrate: {a.topology}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    checked = [check_held_out(sc, cal) for sc in held]
    bar.close()
    sc = train[0]
    accuracies = dict.fromkeys(t.log.mapping.accuracy for t in train)  # type: ignore[union-attr]  # a log's scenario
    acc = "; ".join(f"± {b:.3g} rad, ± {r:.3g} rad/s" for b, r in accuracies)
    print(
        f"calibration of {sc.name} from {len(train)} recorded drive(s): {cal.transitions} transitions with the reference at both ends "
        f"(its accuracy {acc} carried through the model; the wind taken as 0), margin {a.margin:g}"
    )
    for t in train:
        print(f"  {t.log.path}: mapping {t.log.mapping.path}")  # type: ignore[union-attr]  # a log's scenario
    print("the model-mismatch bound covering every transition's e_k (declare one in the topology):")
    print(cal.box.as_toml() + "# or\n" + cal.ellipsoid.as_toml(), end="")
    print("# the operating envelope the logs covered (|a_y| = v·r as the run measures it, the speeds)")
    print(cal.envelope.as_toml(), end="")
    print("# each sensor's noise bound over its healthy stretches (v² ≤ R; in its node profile, nodes/<profile>.toml)")
    for i, R in cal.R.items():
        n = sc.node(i)
        print(f"R = {R!r}  # node {i} (profile {n.label}): |v| ≤ {math.sqrt(R):.4g} over {cal.noise_steps[i]} steps; declared now: R = {n.sensor.R:g}")
    _print_held_out(held, checked)
    if a.toml:
        with open(a.toml, "w") as fh:
            fh.write("\n" + cal.box.as_toml() + "\n" + cal.envelope.as_toml())
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(_calibration_logs_doc(a, cal, train, checked), fh, indent=1)
    return 0


def cmd_log_example(a: argparse.Namespace) -> int:
    from pathlib import Path

    require("vehiclemodels", "the example drives (drawn from a CommonRoad car)")
    require("rosbags", "the example drives (a ROS 2 bag)")
    require("asammdf", "the example drives (an MDF4 file)")
    from netsetest.logs.example import write_examples

    for path in write_examples(Path(a.directory), a.seconds, a.seed):
        print(path)
    return 0


BENCH_MISSING = "netsetest bench: the benchmark (netsetest_bench) is not installed, it is not in the wheel: pip install -e '.[bench]' in a checkout"


def _bench_sections() -> tuple[str, ...] | None:
    """The parts ``bench --only`` may name; None where the benchmark is not installed (an install of the wheel)."""
    if importlib.util.find_spec("netsetest_bench") is None:
        return None
    from netsetest_bench.sections import SECTIONS

    return SECTIONS


def cmd_bench(a: argparse.Namespace) -> int:
    if _bench_sections() is None:
        print(BENCH_MISSING, file=sys.stderr)
        return EXIT_BAD_INPUT
    if a.render_docs is not None:
        return _render_docs(a)
    if a.spread is not None:
        return _spread(a)
    from pathlib import Path

    if a.baseline is not None and (a.only not in ("node", "widths", "performance") or not Path(a.baseline, "netsetest", "__init__.py").is_file()):
        print(
            f"netsetest bench: --baseline {a.baseline}: needs --only node, widths or performance and a checkout of netsetest (DIR/netsetest/__init__.py)",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    if a.only == "scaleout":
        from netsetest.runtime.netns import unavailable

        if (why := unavailable()) is not None:
            print(f"netsetest bench: --only scaleout: {why}", file=sys.stderr)
            return EXIT_BAD_INPUT
    if a.only in (None, "performance"):
        require("cvxpy", "the benchmark (its reference formulations)")
    if a.only in (None, "plant"):
        require("vehiclemodels", "the benchmark's car part")
    if a.only == "view":
        require("rerun", "the benchmark's view part")
        require("bokeh", "the benchmark's view part")
        from netsetest_bench.browser import NoBrowser, chromium

        try:
            chromium()
        except NoBrowser as e:
            print(f"netsetest bench: --only view: {e}", file=sys.stderr)
            return 2
    checks.output_file(a.json, "--json")
    checks.output_file(a.markdown, "--markdown")
    from netsetest_bench.run import run_bench

    return run_bench(a.quick, a.json, a.markdown, a.only, Path(a.baseline).resolve() if a.baseline is not None else None)


def _render_docs(a: argparse.Namespace) -> int:
    from pathlib import Path

    from netsetest_bench.docs import DocsError, write_docs

    measuring = [
        opt for opt, given in (("--quick", a.quick), ("--json", a.json), ("--markdown", a.markdown), ("--only", a.only), ("--baseline", a.baseline)) if given
    ]
    if measuring:
        print(f"netsetest bench: --render-docs measures nothing; {measuring[0]} does not go with it", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        changed = write_docs(Path(a.render_docs))
    except (DocsError, OSError) as e:
        print(f"netsetest bench: --render-docs: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print("rewrote " + ", ".join(changed) if changed else "every generated doc is up to date")
    return 0


def _spread(a: argparse.Namespace) -> int:
    from pathlib import Path

    from netsetest_bench.spread import SpreadError, write_spread

    measuring = [opt for opt, given in (("--quick", a.quick), ("--only", a.only), ("--baseline", a.baseline)) if given]
    if measuring:
        print(f"netsetest bench: --spread measures nothing; {measuring[0]} does not go with it", file=sys.stderr)
        return EXIT_BAD_INPUT
    checks.output_file(a.json, "--json")
    checks.output_file(a.markdown, "--markdown")
    try:
        print(write_spread([Path(p) for p in a.spread], a.json, a.markdown), end="")
    except SpreadError as e:
        print(f"netsetest bench: --spread: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return 0


def cmd_forkserver(a: argparse.Namespace) -> int:
    """The launcher's fork server (internal): each forked role runs ``main`` on its command line."""
    from netsetest.runtime.forkserver import serve

    return serve(a.control_fd, main)


COMMANDS.update(
    run=cmd_run,
    inspect=cmd_inspect,
    plot=cmd_plot,
    exact=cmd_exact,
    calibrate=cmd_calibrate,
    bench=cmd_bench,
    **{"log-example": cmd_log_example},
    forkserver=cmd_forkserver,
)


def handlers() -> dict[str, Callable[[argparse.Namespace], int]]:
    """Every command's handler by name: the one registry (each CLI module registers its own)."""
    from netsetest.cli import campaign, compare, processes, tools

    return {**COMMANDS, **tools.COMMANDS, **compare.COMMANDS, **campaign.COMMANDS, **processes.COMMANDS}


def main(argv: Sequence[str] | None = None) -> int:
    ap = build_parser()
    a = ap.parse_args(argv)
    handler = handlers()[a.command]
    from netsetest.cli import tools

    from netsetest import polygon

    try:
        polygon.use_backend_from_env()  # a bad NETSETEST_POLYGON: one line here, not a failure in a run's first step
        return handler(a)
    except (ConfigError, RecordError, MissingExtra, ExactError, CompareError, checks.OutputError, tools.ObserverError, LogError, polygon.BackendError) as exc:
        print(f"netsetest {a.command}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # `netsetest inspect R | head`: the reader has gone, which is not an error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # else the interpreter's final flush raises again
        return 0
    except KeyboardInterrupt:
        print(f"netsetest {a.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
