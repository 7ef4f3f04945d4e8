"""CLI of the Zenoh runtime: the role processes, ``run --mode zenoh`` (spawns them), router, compose.

``netsetest run TOPOLOGY`` starts 1 vehicle, 1 collector and one process per node on loopback, all in
Zenoh peer mode, each listening on its own free port and connecting to all the others (no router).
It follows the collector's progress, can kill and restart nodes mid-run (``--kill``, ``--rejoin``),
and stops every child on Ctrl-C, on SIGTERM or when the vehicle or the collector fails.  A node that
dies is not a failure of the run: the others go on without it and the summary says so (exit code 3).
"""

from __future__ import annotations

import argparse
import ctypes
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

from netsetest.cli import checks
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, OBJECTIVE_HELP, OBJECTIVES
from netsetest.runtime.report import EXIT_BAD_INPUT, EXIT_VIOLATION

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}
ZENOH_DEFAULT_PORT = 7447


# ---------------------------------------------------------------- option groups


def _zenoh_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("zenoh")
    g.add_argument("--run-id", default="default", help="key-expression namespace of the run (netsetest/<run-id>/...)")
    g.add_argument("--zenoh-mode", choices=["peer", "client"], default="peer", help="peer (one host) or client of a router")
    g.add_argument("--listen", action="append", default=[], metavar="ENDPOINT", help="endpoint to listen on, e.g. tcp/127.0.0.1:7450 (repeatable; default: none)")
    g.add_argument("--connect", action="append", default=[], metavar="ENDPOINT", help="endpoint to connect to, e.g. tcp/10.0.0.1:7447 (repeatable; default: none)")


def _at(s: str) -> tuple[int, int]:
    try:
        node, step = s.split("@")
        return int(node), int(step)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NODE@STEP, e.g. 3@20, got {s!r}") from None


def _seconds_type(allow_zero: bool) -> Callable[[str], float]:
    """argparse type for a duration: > 0, or ≥ 0 with ``allow_zero``."""

    def parse(s: str) -> float:
        try:
            v = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number of seconds: {s!r}") from None
        if v < 0 or (v == 0 and not allow_zero):
            raise argparse.ArgumentTypeError(f"must be {'≥' if allow_zero else '>'} 0, got {v}")
        return v

    return parse


_seconds, _non_negative = _seconds_type(False), _seconds_type(True)


def add_run_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("zenoh mode")
    g.add_argument("--node-timeout", type=_seconds, default=10.0, metavar="S", help="lockstep: a node silent this long [s] is declared dead")
    g.add_argument("--neighbour-timeout", type=_seconds, default=5.0, metavar="S", help="lockstep: how long [s] a node waits for a neighbour's message")
    g.add_argument("--pace", type=_non_negative, default=0.0, metavar="S", help="lockstep: at least S seconds per step (default: 0, as fast as possible)")
    g.add_argument("--kill", type=_at, action="append", default=[], metavar="NODE@STEP", help="SIGKILL node NODE once step STEP is checked (repeatable; default: none)")
    g.add_argument("--rejoin", type=_at, action="append", default=[], metavar="NODE@STEP", help="restart node NODE with --rejoin at step STEP (repeatable; default: none)")


def add_role_parsers(sub: argparse._SubParsersAction, scenario_args: Callable, run_args: Callable) -> None:
    p = sub.add_parser("vehicle", help="the vehicle process (truth, measurements) of a Zenoh run")
    scenario_args(p)
    p.add_argument("--signals", choices=["paper", "worst"], default="paper", help="noise and wind: the paper's, or held at ±bound")
    p.add_argument("--seed", type=checks.seed, default=0, help="random seed of noise, wind and losses")
    p.add_argument("--clock", choices=["lockstep", "realtime"], default="lockstep", help="lockstep: wait for every node; realtime: one step every τs")
    p.add_argument("--node-timeout", type=_seconds, default=10.0, metavar="S", help="lockstep: a node silent this long [s] is declared dead")
    p.add_argument("--pace", type=_non_negative, default=0.0, metavar="S", help="lockstep: at least S seconds per step")
    p.add_argument("--start-timeout", type=_seconds, default=60.0, metavar="S", help="how long [s] to wait for every role to be ready")
    _zenoh_args(p)

    p = sub.add_parser("node", help="one sensing-node process of a Zenoh run")
    scenario_args(p)
    p.add_argument("--id", type=int, required=True, help="node id in the topology")
    p.add_argument("--variant", choices=["scheduled", "per-rule"], default="scheduled", help="estimator: one SDP with the scheduled model, or one per T-S rule")
    p.add_argument("--objective", choices=list(OBJECTIVES), default=DEFAULT_OBJECTIVE, help=OBJECTIVE_HELP)
    p.add_argument("--clock", choices=["lockstep", "realtime"], default="lockstep", help="lockstep: wait for neighbours; realtime: step on the vehicle's input")
    p.add_argument("--neighbour-timeout", type=_seconds, default=5.0, metavar="S", help="lockstep: how long [s] to wait for a neighbour's message")
    p.add_argument("--rejoin", action="store_true", help="join a running network (after a crash or restart)")
    _zenoh_args(p)

    p = sub.add_parser("collector", help="the collector process: checks containment, writes record and summary")
    scenario_args(p)
    run_args(p)
    p.add_argument("--clock", choices=["lockstep", "realtime"], default="lockstep", help="the run's clock (recorded in the summary)")
    p.add_argument("--record", metavar="PATH", help="write the run record (.json, .json.gz or .mcap; default: none)")
    p.add_argument("--summary-json", metavar="PATH", help="write the summary as JSON (default: none)")
    p.add_argument("--progress", action="store_true", help="print '@progress K' lines for a parent process")
    p.add_argument("--idle-timeout", type=_seconds, default=60.0, metavar="S", help="give up when no message arrives for S seconds")
    _zenoh_args(p)

    p = sub.add_parser("router", help="a Zenoh router in Python (for client-mode roles on several hosts)")
    p.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                   help=f"endpoint to listen on (repeatable; default: tcp/0.0.0.0:{ZENOH_DEFAULT_PORT})")  # fmt: skip

    p = sub.add_parser("compose", help="print a docker-compose.yml for a topology (router + one service per role)")
    p.add_argument("topology", help="topology file or bundled name, e.g. paper6")
    p.add_argument("--image", default="netsetest:latest", help="image with netsetest installed (built from the Dockerfile)")
    p.add_argument("--zenoh-image", default="eclipse/zenoh:1.10.2", help="image of the Zenoh router")


# ---------------------------------------------------------------- role commands


def _open_bus(a: argparse.Namespace):  # noqa: ANN202
    from netsetest.bus.zenoh_bus import ZenohBus

    return ZenohBus(a.zenoh_mode, a.listen, a.connect)


def _role(name: str, a: argparse.Namespace, body: Callable) -> int:
    from netsetest.bus.zenoh_bus import BusError
    from netsetest.config.schema import load_topology
    from netsetest.runtime.processes import Stop, install_signal_handlers, log

    sc = load_topology(a.topology, a.case, a.steps)
    install_signal_handlers()
    try:
        bus = _open_bus(a)
    except BusError as exc:
        log(name, str(exc))
        return EXIT_BAD_INPUT
    try:
        return body(sc, bus)
    except Stop as why:
        log(name, f"stopped by {why}")
        return 128 + 15
    finally:
        bus.close()


def cmd_vehicle(a: argparse.Namespace) -> int:
    from netsetest.runtime.processes import run_vehicle

    return _role("vehicle", a, lambda sc, bus: run_vehicle(
        sc, bus, a.run_id, a.signals, a.seed, a.clock == "realtime", a.node_timeout, a.start_timeout, a.pace))  # fmt: skip


def cmd_node(a: argparse.Namespace) -> int:
    from netsetest.runtime.processes import run_node

    def body(sc, bus) -> int:  # noqa: ANN001
        sc.node(a.id)  # unknown id → ConfigError, exit 2
        return run_node(sc, a.id, bus, a.run_id, a.variant, a.clock == "realtime", a.neighbour_timeout, a.rejoin, a.objective)

    return _role(f"node {a.id}", a, body)


def cmd_collector(a: argparse.Namespace) -> int:
    from netsetest.runtime.inmemory import run_meta
    from netsetest.runtime.processes import run_collector
    from netsetest.runtime.report import format_table

    checks.record_file(a.record)  # before the run, not after it
    checks.output_file(a.summary_json, "--summary-json")

    def body(sc, bus) -> int:  # noqa: ANN001
        meta = run_meta(sc, "zenoh", a.clock, a.signals, a.variant, a.seed, a.run_id, a.objective)
        show = None if a.progress else (lambda s: print(format_table(s), flush=True))
        return run_collector(sc, bus, a.run_id, meta, a.record, a.summary_json, a.progress, a.idle_timeout, show)

    return _role("collector", a, body)


def cmd_router(a: argparse.Namespace) -> int:
    import zenoh

    from netsetest.bus.zenoh_bus import zenoh_config
    from netsetest.runtime.processes import Stop, install_signal_handlers, log

    install_signal_handlers()
    listen = a.listen or [f"tcp/0.0.0.0:{ZENOH_DEFAULT_PORT}"]
    session = zenoh.open(zenoh_config("router", listen))
    log("router", f"listening on {', '.join(listen)}")
    try:
        while True:
            time.sleep(3600)
    except Stop:
        return 0
    finally:
        session.close()


def cmd_compose(a: argparse.Namespace) -> int:
    from netsetest.runtime.compose import compose_yaml

    sys.stdout.write(compose_yaml(a.topology, a.image, a.zenoh_image))
    return 0


COMMANDS.update(vehicle=cmd_vehicle, node=cmd_node, collector=cmd_collector, router=cmd_router, compose=cmd_compose)


# ---------------------------------------------------------------- run --mode zenoh: the parent


def free_ports(n: int) -> list[int]:
    socks, ports = [], []
    for _ in range(n):
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        socks.append(s)
        ports.append(s.getsockname()[1])
    for s in socks:
        s.close()
    return ports


def _die_with_parent() -> None:
    """In the child, before exec: get SIGKILL if the parent dies, however it dies (Linux)."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:
        pass


class Children:
    """The processes a run started; :meth:`stop_all` leaves none behind."""

    def __init__(self) -> None:
        self.procs: dict[str, subprocess.Popen] = {}
        self.killed: set[str] = set()

    def start(self, name: str, argv: list[str], **kw: object) -> subprocess.Popen:
        cmd = [sys.executable, "-m", "netsetest.cli.main", *argv]
        proc = subprocess.Popen(cmd, start_new_session=True, preexec_fn=_die_with_parent, stdin=subprocess.DEVNULL, **kw)  # type: ignore[call-overload]
        self.procs[name] = proc
        return proc

    def kill(self, name: str) -> None:
        proc = self.procs[name]
        self.killed.add(name)
        proc.send_signal(signal.SIGKILL)
        proc.wait()

    def stop_all(self, grace: float = 5.0) -> None:
        live = [p for p in self.procs.values() if p.poll() is None]
        for p in live:
            p.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + grace
        for p in live:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def cmd_run_zenoh(a: argparse.Namespace) -> int:
    from netsetest.config.schema import load_topology
    from netsetest.runtime.processes import log
    from netsetest.runtime.report import Progress, format_table

    sc = load_topology(a.topology, a.case, a.steps)
    for node, _ in a.kill + a.rejoin:
        sc.node(node)
    if a.neighbour_timeout >= a.node_timeout:
        # else a node waiting for a dead neighbour is itself declared dead by the vehicle
        log("run", f"--neighbour-timeout ({a.neighbour_timeout:g} s) must be shorter than --node-timeout ({a.node_timeout:g} s)")
        return EXIT_BAD_INPUT
    run_id = f"run{os.getpid()}"
    names = ["collector", "vehicle", *(f"node{i}" for i in sc.ids)]
    ports = dict(zip(names, free_ports(len(names))))
    endpoint = lambda name: f"tcp/127.0.0.1:{ports[name]}"  # noqa: E731
    common = [a.topology, "--run-id", run_id, "--zenoh-mode", "peer"]
    if a.case:
        common += ["--case", a.case]
    if a.steps:
        common += ["--steps", str(a.steps)]

    def net(name: str) -> list[str]:
        out = ["--listen", endpoint(name)]
        for other in names:
            if other != name:
                out += ["--connect", endpoint(other)]
        return out

    if not a.quiet:  # how to look inside the run from another terminal (README: Live views)
        log("run", f"run id {run_id}; watch it with: netsetest watch --run-id {run_id} --connect {endpoint('collector')}")
    tmp = tempfile.TemporaryDirectory(prefix="netsetest-")
    summary_path = a.summary_json or str(Path(tmp.name) / "summary.json")
    children = Children()
    bar = Progress(sc.steps, f"zenoh ({len(sc.ids)} nodes + vehicle + collector)", enabled=not a.quiet)
    progress = [-1]

    def follow(stream) -> None:  # noqa: ANN001
        for line in stream:
            if line.startswith("@progress "):
                progress[0] = int(line.split()[1])

    def node_argv(i: int, rejoin: bool) -> list[str]:
        argv = ["node", *common, "--id", str(i), "--variant", a.variant, "--objective", a.objective, "--clock", a.clock,
                "--neighbour-timeout", str(a.neighbour_timeout), *net(f"node{i}")]  # fmt: skip
        return argv + ["--rejoin"] if rejoin else argv

    def on_term(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)
    try:
        col = children.start(
            "collector",
            ["collector", *common, "--signals", a.signals, "--variant", a.variant, "--objective", a.objective, "--seed", str(a.seed), "--clock", a.clock,
             "--summary-json", summary_path, "--progress", *(["--record", a.record] if a.record else []), *net("collector")],
            stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        threading.Thread(target=follow, args=(col.stdout,), daemon=True).start()
        for i in sc.ids:
            children.start(f"node{i}", node_argv(i, False), stdout=subprocess.DEVNULL)
        children.start(
            "vehicle",
            ["vehicle", *common, "--signals", a.signals, "--seed", str(a.seed), "--clock", a.clock,
             "--node-timeout", str(a.node_timeout), "--pace", str(a.pace), *net("vehicle")],
            stdout=subprocess.DEVNULL,
        )  # fmt: skip
        kills, rejoins = sorted(a.kill, key=lambda t: t[1]), sorted(a.rejoin, key=lambda t: t[1])
        reported: set[str] = set()
        while True:
            time.sleep(0.05)
            bar.update(max(progress[0], 0))
            for node, step in list(kills):
                if progress[0] >= step:
                    log("run", f"killing node {node} (SIGKILL) after step {progress[0]}")
                    children.kill(f"node{node}")
                    kills.remove((node, step))
            for node, step in list(rejoins):
                if progress[0] >= step and children.procs[f"node{node}"].poll() is not None:
                    log("run", f"restarting node {node} with --rejoin at step {progress[0]}")
                    ports[f"node{node}"] = free_ports(1)[0]
                    children.start(f"node{node}", node_argv(node, True), stdout=subprocess.DEVNULL)
                    rejoins.remove((node, step))
            if col.poll() is not None:
                break
            veh = children.procs["vehicle"].poll()
            if veh not in (None, 0):
                log("run", f"the vehicle process failed (exit {veh}); stopping the run")
                return EXIT_VIOLATION
            for name, proc in children.procs.items():
                if name.startswith("node") and name not in children.killed and name not in reported and proc.poll() not in (None, 0):
                    log("run", f"{name} exited with code {proc.returncode}; the run goes on without it")
                    reported.add(name)
        bar.update(max(progress[0], 0))
        bar.close()
        code = col.returncode
        for p in children.procs.values():  # vehicle and nodes end on End; give them a moment
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                pass
        if not Path(summary_path).exists():
            log("run", f"the collector exited with code {code} without a summary")
            return EXIT_VIOLATION
        import json

        summary = json.loads(Path(summary_path).read_text())
        print(format_table(summary))
        return code
    except KeyboardInterrupt:
        bar.close()
        log("run", "interrupted: stopping every process")
        return 130
    finally:
        children.stop_all()
        tmp.cleanup()
