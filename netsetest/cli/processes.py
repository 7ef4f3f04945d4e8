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
import math
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from netsetest.bus import keys
from netsetest.cli import checks
from netsetest.estimator.names import NODE_ESTIMATOR_NAMES, SDP
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, OBJECTIVE_HELP, OBJECTIVES
from netsetest.records.summary import RunSummary
from netsetest.runtime.report import EXIT_BAD_INPUT, EXIT_VIOLATION, read_summary

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}
ZENOH_DEFAULT_PORT = 7447
RUN_ENV_FILE = "run.env"  # written by `netsetest credentials`: the deployment's run id, for compose's env_file
START_TIMEOUT_S = 60.0  # the vehicle's default wait for every role to be ready


# ---------------------------------------------------------------- option groups


RUN_ID_ENV = "NETSETEST_RUN_ID"  # default of --run-id (compose services read it from the credentials' run.env)
RUN_ID_RE = re.compile(r"[A-Za-z0-9_-]{1,64}")
# proto/host:port with an optional Zenoh suffix (?metadata, #config); host a name, an IPv4 or a [IPv6]
ENDPOINT_RE = re.compile(r"(tcp|udp|tls|quic)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.-]+):(\d{1,5})([?#].*)?")
MAX_PORT = 65535


def _run_id(s: str) -> str:
    if not RUN_ID_RE.fullmatch(s):
        raise argparse.ArgumentTypeError(f"{s!r}: only letters, digits, '_' and '-' (1 to 64), it is a key-expression chunk")
    return s


def _endpoint(s: str) -> str:
    m = ENDPOINT_RE.fullmatch(s)
    if not m or int(m.group(3)) > MAX_PORT:
        raise argparse.ArgumentTypeError(f"{s!r}: expected PROTO/HOST:PORT with PROTO tcp, udp, tls or quic, e.g. tls/127.0.0.1:7447")
    return s


def _readable_file(s: str) -> str:
    if not os.path.isfile(s) or not os.access(s, os.R_OK):
        raise argparse.ArgumentTypeError(f"{s}: not a readable file")
    return s


def _zenoh_config_arg(g: argparse._ArgumentGroup) -> None:
    g.add_argument("--zenoh-config", type=_readable_file, metavar="FILE",
                   help="a Zenoh configuration (JSON5) to start from; netsetest sets mode, endpoints, scouting and security on top (default: none)")  # fmt: skip


def _zenoh_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("zenoh")
    g.add_argument("--run-id", type=_run_id, default=os.environ.get(RUN_ID_ENV, "default"),
                   help=f"key-expression namespace of the run (netsetest/<run-id>/...); default ${RUN_ID_ENV} or 'default'")  # fmt: skip
    g.add_argument("--zenoh-mode", choices=["peer", "client"], default="peer", help="peer (one host) or client of a router")
    g.add_argument("--listen", type=_endpoint, action="append", default=[], metavar="ENDPOINT",
                   help="endpoint to listen on, e.g. tcp/127.0.0.1:7450 (repeatable; default: none)")  # fmt: skip
    g.add_argument("--connect", type=_endpoint, action="append", default=[], metavar="ENDPOINT",
                   help="endpoint to connect to, e.g. tls/10.0.0.1:7447 (repeatable; default: none)")  # fmt: skip
    g.add_argument("--credentials", metavar="DIR",
                   help="mTLS: this role's certificate and key from DIR (`netsetest credentials`); connect on tls/ endpoints (default: none, no TLS)")  # fmt: skip
    _zenoh_config_arg(g)


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
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be a finite number of seconds, got {s!r}")
        if v < 0 or (v == 0 and not allow_zero):
            raise argparse.ArgumentTypeError(f"must be {'≥' if allow_zero else '>'} 0, got {v}")
        return v

    return parse


_seconds, _non_negative = _seconds_type(False), _seconds_type(True)
DEFAULT_VALIDITY_DAYS = 30


def add_run_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("zenoh mode")
    g.add_argument("--node-timeout", type=_seconds, default=10.0, metavar="S", help="lockstep: a node silent this long [s] is declared dead")
    g.add_argument("--neighbour-timeout", type=_seconds, default=5.0, metavar="S", help="lockstep: how long [s] a node waits for a neighbour's message")
    g.add_argument("--pace", type=_non_negative, default=0.0, metavar="S", help="lockstep: at least S seconds per step (default: 0, as fast as possible)")
    g.add_argument("--kill", type=_at, action="append", default=[], metavar="NODE@STEP", help="SIGKILL node NODE once step STEP is checked (repeatable; default: none)")
    g.add_argument("--rejoin", type=_at, action="append", default=[], metavar="NODE@STEP", help="restart node NODE with --rejoin at step STEP (repeatable; default: none)")
    g.add_argument("--insecure", action="store_true",
                   help="no credentials, no access control: an open peer mesh any local process can join (labelled in the summary; default: secured)")  # fmt: skip
    _zenoh_config_arg(g)


def estimator_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--estimator", choices=list(NODE_ESTIMATOR_NAMES), metavar="NAME",
                   help=f"every node's estimator, overriding the topology's per-node 'estimator' ({', '.join(NODE_ESTIMATOR_NAMES)}; default: the file's, else sdp)")  # fmt: skip


def add_role_parsers(sub: argparse._SubParsersAction, scenario_args: Callable, run_args: Callable) -> None:
    p = sub.add_parser("vehicle", help="the vehicle process (truth, measurements) of a Zenoh run")
    scenario_args(p)
    estimator_arg(p)
    p.add_argument("--signals", choices=["paper", "worst"], default="paper", help="noise and wind: the paper's, or held at ±bound")
    p.add_argument("--seed", type=checks.seed, default=0, help="random seed of noise, wind and losses")
    p.add_argument("--clock", choices=["lockstep", "realtime"], default="lockstep", help="lockstep: wait for every node; realtime: one step every τs")
    p.add_argument("--node-timeout", type=_seconds, default=10.0, metavar="S", help="lockstep: a node silent this long [s] is declared dead")
    p.add_argument("--pace", type=_non_negative, default=0.0, metavar="S", help="lockstep: at least S seconds per step")
    p.add_argument("--start-timeout", type=_seconds, default=START_TIMEOUT_S, metavar="S", help=f"how long [s] to wait for every role to be ready (default: {START_TIMEOUT_S:g})")
    p.add_argument("--await-rejoin", type=_at, action="append", default=[], metavar="NODE@STEP",
                   help="lockstep: before step STEP+1 wait (at most --node-timeout) for node NODE to come back (repeatable; default: none)")  # fmt: skip
    _zenoh_args(p)

    p = sub.add_parser("node", help="one sensing-node process of a Zenoh run")
    scenario_args(p)
    estimator_arg(p)
    p.add_argument("--id", type=int, required=True, help="node id in the topology")
    p.add_argument("--variant", choices=["scheduled", "per-rule"], default="scheduled", help="estimator: one SDP with the scheduled model, or one per T-S rule")
    p.add_argument("--objective", choices=list(OBJECTIVES), default=DEFAULT_OBJECTIVE, help=OBJECTIVE_HELP)
    p.add_argument("--clock", choices=["lockstep", "realtime"], default="lockstep", help="lockstep: wait for neighbours; realtime: step on the vehicle's input")
    p.add_argument("--neighbour-timeout", type=_seconds, default=5.0, metavar="S", help="lockstep: how long [s] to wait for a neighbour's message")
    p.add_argument("--rejoin", action="store_true", help="join a running network (after a crash or restart)")
    p.add_argument("--crash-after", type=int, metavar="STEP", help="SIGKILL itself right after publishing step STEP (run --kill; default: never)")
    _zenoh_args(p)

    p = sub.add_parser("collector", help="the collector process: checks containment, writes record and summary")
    scenario_args(p)
    estimator_arg(p)
    run_args(p)
    p.add_argument("--clock", choices=["lockstep", "realtime"], default="lockstep", help="the run's clock (recorded in the summary)")
    p.add_argument("--record", metavar="PATH", help="write the run record (.json, .json.gz or .mcap; default: none)")
    p.add_argument("--summary-json", metavar="PATH", help="write the summary as JSON (default: none)")
    p.add_argument("--progress", action="store_true", help="print '@progress K' lines for a parent process")
    p.add_argument("--idle-timeout", type=_seconds, default=60.0, metavar="S", help="give up when no message arrives for S seconds")
    _zenoh_args(p)

    p = sub.add_parser("router", help="a Zenoh router in Python (for client-mode roles on several hosts)")
    p.add_argument("topology", nargs="?", help="topology whose access-control rules the router enforces (with --credentials)")
    p.add_argument("--listen", type=_endpoint, action="append", default=[], metavar="ENDPOINT",
                   help=f"endpoint to listen on (repeatable; default: tcp/0.0.0.0:{ZENOH_DEFAULT_PORT}, or tls/0.0.0.0:{ZENOH_DEFAULT_PORT} with --credentials)")  # fmt: skip
    p.add_argument("--credentials", metavar="DIR", help="mTLS with DIR/router.pem and the run's access-control rules (default: none, open router)")
    p.add_argument("--run-id", type=_run_id, default=os.environ.get(RUN_ID_ENV, "default"), help=f"the run whose keys the access control grants (default: ${RUN_ID_ENV} or 'default')")
    _zenoh_config_arg(p)

    p = sub.add_parser("credentials", help="write per-role mTLS credentials (CA, certificates, keys) and run.env for a deployment")
    p.add_argument("dir", help="output directory (created with mode 0700)")
    p.add_argument("topology", help="topology file or bundled name, e.g. paper6")
    p.add_argument("--run-id", type=_run_id, help="the deployment's run id (default: a random one)")
    p.add_argument("--router-host", action="append", default=[], metavar="NAME",
                   help="a name or address the router is reached at (repeatable; default: localhost, 127.0.0.1 and router, always included)")  # fmt: skip
    p.add_argument("--days", type=checks.positive_int, default=DEFAULT_VALIDITY_DAYS, help="validity of the certificates in days")

    p = sub.add_parser("compose", help="print a docker-compose.yml for a topology (router + one service per role)")
    p.add_argument("topology", help="topology file or bundled name, e.g. paper6")
    p.add_argument("--image", default="netsetest:latest", help="image with netsetest installed (built from the Dockerfile)")


# ---------------------------------------------------------------- role commands


def _open_bus(a: argparse.Namespace, name: str):  # noqa: ANN202
    from netsetest.bus.zenoh_bus import ZenohBus
    from netsetest.runtime.security import client_settings, identity

    settings = client_settings(identity(a.credentials, name)) if a.credentials else None
    return ZenohBus(a.zenoh_mode, a.listen, a.connect, base_file=a.zenoh_config, settings=settings)


def _role(name: str, who: str, a: argparse.Namespace, body: Callable) -> int:
    """Run a role process: ``name`` for its log lines, ``who`` its certificate name (keys.role_name)."""
    from netsetest.bus.zenoh_bus import BusError
    from netsetest.config.schema import load_topology
    from netsetest.runtime.processes import EXIT_STOPPED, Stop, install_signal_handlers, log
    from netsetest.runtime.security import CredentialsError

    sc = load_topology(a.topology, a.case, a.steps, a.estimator)
    install_signal_handlers()
    try:
        bus = _open_bus(a, who)
    except (BusError, CredentialsError) as exc:
        log(name, str(exc))
        return EXIT_BAD_INPUT
    try:
        return body(sc, bus)
    except Stop as why:
        log(name, f"stopped by {why}")
        return EXIT_STOPPED
    finally:
        bus.close()


def cmd_vehicle(a: argparse.Namespace) -> int:
    from netsetest.runtime.processes import run_vehicle

    return _role("vehicle", keys.role_name("vehicle"), a, lambda sc, bus: run_vehicle(
        sc, bus, a.run_id, a.signals, a.seed, a.clock == "realtime", a.node_timeout, a.start_timeout, a.pace,
        a.await_rejoin))  # fmt: skip


def cmd_node(a: argparse.Namespace) -> int:
    from netsetest.runtime.processes import run_node

    def body(sc, bus) -> int:  # noqa: ANN001
        sc.node(a.id)  # unknown id → ConfigError, exit 2
        return run_node(sc, a.id, bus, a.run_id, a.variant, a.clock == "realtime", a.neighbour_timeout, a.rejoin,
                        a.objective, a.crash_after)

    return _role(f"node {a.id}", keys.role_name("node", a.id), a, body)


def cmd_collector(a: argparse.Namespace) -> int:
    from netsetest.runtime.inmemory import run_meta
    from netsetest.runtime.processes import run_collector
    from netsetest.runtime.report import format_table
    from netsetest.runtime.security import SECURITY_INSECURE, SECURITY_MTLS

    checks.record_file(a.record)  # before the run, not after it
    checks.output_file(a.summary_json, "--summary-json")

    def body(sc, bus) -> int:  # noqa: ANN001
        meta = run_meta(sc, "zenoh", a.clock, a.signals, a.variant, a.seed, a.run_id, a.objective)
        meta["security"] = SECURITY_MTLS if a.credentials else SECURITY_INSECURE
        show = None if a.progress else (lambda s: print(format_table(s), flush=True))
        return run_collector(sc, bus, a.run_id, meta, a.record, a.summary_json, a.progress, a.idle_timeout, show)

    return _role("collector", keys.role_name("collector"), a, body)


def router_session(listen: list[str], base_file: str | None, security: dict[str, object] | None):  # noqa: ANN201
    """Open a Zenoh router session (BusError naming the option: a bad --zenoh-config, or cannot --listen)."""
    from netsetest.bus.zenoh_bus import BusError, open_session, zenoh_config

    try:
        cfg = zenoh_config("router", listen, base_file=base_file, settings=security)
    except BusError as exc:
        raise BusError(f"--zenoh-config: {exc}") from None
    try:
        return open_session(cfg, f"router on {', '.join(listen)}")
    except BusError as exc:
        raise BusError(f"--listen: {exc}") from None


def cmd_router(a: argparse.Namespace) -> int:
    from netsetest.bus.zenoh_bus import BusError
    from netsetest.config.schema import load_topology
    from netsetest.runtime.processes import Stop, install_signal_handlers, log
    from netsetest.runtime.security import ROUTER, CredentialsError, identity, router_settings

    security = None
    if a.credentials:
        if not a.topology:
            log("router", "--credentials needs the TOPOLOGY (the access-control rules are built from it)")
            return EXIT_BAD_INPUT
        try:
            security = router_settings(identity(a.credentials, ROUTER), load_topology(a.topology), a.run_id)
        except CredentialsError as exc:
            log("router", f"--credentials: {exc}")
            return EXIT_BAD_INPUT
    proto = "tls" if a.credentials else "tcp"
    listen = a.listen or [f"{proto}/0.0.0.0:{ZENOH_DEFAULT_PORT}"]
    install_signal_handlers()
    try:
        session = router_session(listen, a.zenoh_config, security)
    except BusError as exc:
        log("router", str(exc))
        return EXIT_BAD_INPUT
    log("router", f"listening on {', '.join(listen)}" + (f"; mTLS and access control for run {a.run_id}" if security else ""))
    try:
        while True:
            time.sleep(3600)
    except Stop:
        return 0
    finally:
        session.close()


def cmd_credentials(a: argparse.Namespace) -> int:
    import datetime
    import secrets

    from netsetest.config.schema import load_topology
    from netsetest.runtime.security import ROUTER_HOSTS, role_names, write_credentials

    sc = load_topology(a.topology)
    run_id = a.run_id or f"run-{secrets.token_hex(8)}"
    out = write_credentials(a.dir, role_names(sc), [*ROUTER_HOSTS, *a.router_host], datetime.timedelta(days=a.days))
    (out / RUN_ENV_FILE).write_text(f"{RUN_ID_ENV}={run_id}\n")
    print(f"credentials for {len(role_names(sc))} roles and the router in {out} (run id {run_id}, valid {a.days} days)")
    return 0


def cmd_compose(a: argparse.Namespace) -> int:
    from netsetest.runtime.compose import compose_yaml

    sys.stdout.write(compose_yaml(a.topology, a.image))
    return 0


COMMANDS.update(vehicle=cmd_vehicle, node=cmd_node, collector=cmd_collector, router=cmd_router, credentials=cmd_credentials,
                compose=cmd_compose)


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
        self.ended: list[subprocess.Popen] = []

    def start(self, name: str, argv: list[str], **kw: object) -> subprocess.Popen:
        from netsetest.runtime.processes import role_env

        cmd = [sys.executable, "-m", "netsetest.cli.main", *argv]
        proc = subprocess.Popen(cmd, start_new_session=True, preexec_fn=_die_with_parent, stdin=subprocess.DEVNULL, env=role_env(), **kw)  # type: ignore[call-overload]
        self.procs[name] = proc
        return proc

    def start_again(self, name: str) -> None:
        """Forget a process that ended (a killed node about to be restarted); it was waited for."""
        self.procs[name].wait()
        self.ended.append(self.procs.pop(name))

    def stop_all(self, grace: float, keep: Sequence[str] = ()) -> None:
        """SIGTERM every live child except ``keep``, SIGKILL those still alive after ``grace`` s."""
        live = [p for n, p in self.procs.items() if p.poll() is None and n not in keep]
        for p in live:
            p.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + grace
        for p in live:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


@dataclass(frozen=True)
class Schedule:
    """``--kill`` / ``--rejoin`` per node, checked: kill and rejoin alternate, steps increase, within the run."""

    kills: dict[int, list[int]]
    rejoins: dict[int, list[int]]

    def next_kill(self, node: int, after: int) -> int | None:
        """The first kill step of ``node`` at or after step ``after`` (its process' --crash-after)."""
        return min((k for k in self.kills.get(node, []) if k >= after), default=None)


def kill_schedule(kill: list[tuple[int, int]], rejoin: list[tuple[int, int]], steps: int) -> Schedule:
    """Validate the kill/rejoin options (ValueError naming the option); a kill lands right after its step."""
    events: dict[int, list[tuple[int, str]]] = {}
    for opt, pairs in (("kill", kill), ("rejoin", rejoin)):
        for node, step in pairs:
            if not 0 <= step < steps:
                raise ValueError(f"--{opt} {node}@{step}: the step must be in 0..{steps - 1} (the run has {steps} steps)")
            events.setdefault(node, []).append((step, opt))
    for node, evs in events.items():
        evs.sort()
        for n, (step, opt) in enumerate(evs):
            want = "kill" if n % 2 == 0 else "rejoin"
            if opt != want or (n and step <= evs[n - 1][0]):
                raise ValueError(f"--{opt} {node}@{step}: each node's --kill and --rejoin must alternate, kill first, at increasing steps")
    by = lambda opt: {i: [s for s, o in evs if o == opt] for i, evs in events.items()}  # noqa: E731
    return Schedule(by("kill"), by("rejoin"))


START_S_PER_ROLE = 1.0  # `run`: each role process imports for ≈0.35 s of CPU; 100 of them share a few cores


def run_start_timeout(roles: int) -> float:
    """The vehicle's start-up timeout in a ``run`` of ``roles`` processes: large networks take longer to start."""
    return max(START_TIMEOUT_S, START_S_PER_ROLE * roles)


COLLECTOR_GRACE_S = 10.0  # on Ctrl-C/SIGTERM: how long the collector may take to write its record and summary
ROLE_GRACE_S = 5.0  # how long a role may take to leave after SIGTERM (or after End)


def cmd_run_zenoh(a: argparse.Namespace) -> int:
    from netsetest.bus.zenoh_bus import BusError, zenoh_config
    from netsetest.config.schema import load_topology
    from netsetest.runtime.processes import log
    from netsetest.runtime.report import Progress, format_table
    from netsetest.runtime.security import (
        ROUTER, SECURITY_INSECURE, SECURITY_MTLS, identity, role_names, router_settings, write_credentials,
    )  # fmt: skip

    sc = load_topology(a.topology, a.case, a.steps, a.estimator)
    for node, _ in a.kill + a.rejoin:
        if sc.node(node).estimator != SDP:
            log("run", f"--kill/--rejoin {node}@…: node {node} runs {sc.node(node).estimator!r}, which cannot rejoin (only the SDP can)")
            return EXIT_BAD_INPUT
    try:
        schedule = kill_schedule(a.kill, a.rejoin, sc.steps)
    except ValueError as exc:
        log("run", str(exc))
        return EXIT_BAD_INPUT
    if a.neighbour_timeout >= a.node_timeout:
        # else a node waiting for a dead neighbour is itself declared dead by the vehicle
        log("run", f"--neighbour-timeout ({a.neighbour_timeout:g} s) must be shorter than --node-timeout ({a.node_timeout:g} s)")
        return EXIT_BAD_INPUT
    if a.zenoh_config:
        try:
            zenoh_config("peer", base_file=a.zenoh_config)
        except BusError as exc:
            log("run", f"--zenoh-config: {exc}")
            return EXIT_BAD_INPUT
    security = SECURITY_INSECURE if a.insecure else SECURITY_MTLS
    run_id = f"run{os.getpid()}"
    tmp = tempfile.TemporaryDirectory(prefix="netsetest-")  # mode 0700 (mkdtemp)
    summary_path = a.summary_json or str(Path(tmp.name) / "summary.json")
    children = Children()
    router = None
    common = [a.topology, "--run-id", run_id, *(["--zenoh-config", a.zenoh_config] if a.zenoh_config else [])]
    if a.case:
        common += ["--case", a.case]
    if a.steps:
        common += ["--steps", str(a.steps)]
    if a.estimator:
        common += ["--estimator", a.estimator]
    names = ["collector", "vehicle", *(f"node{i}" for i in sc.ids)]
    ports = dict(zip(names, free_ports(len(names))))

    def net(name: str) -> list[str]:
        if router is not None:  # star: every role is an mTLS client of the parent's router
            return ["--zenoh-mode", "client", "--connect", router_endpoint, "--credentials", creds]
        endpoint = lambda n: f"tcp/127.0.0.1:{ports[n]}"  # noqa: E731
        out = ["--zenoh-mode", "peer", "--listen", endpoint(name)]  # insecure: today's full peer mesh
        for other in names:
            if other != name:
                out += ["--connect", endpoint(other)]
        return out

    def on_term(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)
    try:
        if not a.insecure:
            creds = str(Path(tmp.name) / "credentials")
            write_credentials(creds, role_names(sc))
            router_endpoint = f"tls/127.0.0.1:{free_ports(1)[0]}"
            try:
                router = router_session([router_endpoint], a.zenoh_config, router_settings(identity(creds, ROUTER), sc, run_id))
            except BusError as exc:
                log("run", str(exc))
                return EXIT_BAD_INPUT
        log("run", f"security: {security}" + (f" (mTLS per role, access control at the run's router {router_endpoint}; credentials in {creds})"
                                               if router is not None else " (open peer mesh: any local process can read and forge messages)"))  # fmt: skip
        if not a.quiet:  # how to look inside the run from another terminal (README: Live views)
            log("run", f"run id {run_id}; " + (
                f"watch it with: netsetest watch --run-id {run_id} --connect tcp/127.0.0.1:{ports['collector']}" if router is None
                else "outside observers are shut out of a secured run (watch it from another terminal: run with --insecure)"))  # fmt: skip
        bar = Progress(sc.steps, f"zenoh ({len(sc.ids)} nodes + vehicle + collector)", enabled=not a.quiet)
        progress = [-1]

        def follow(stream) -> None:  # noqa: ANN001
            for line in stream:
                if line.startswith("@progress "):
                    progress[0] = int(line.split()[1])

        def start_node(i: int, rejoin: bool, after: int) -> None:
            crash = schedule.next_kill(i, after)
            children.start(f"node{i}", ["node", *common, "--id", str(i), "--variant", a.variant, "--objective", a.objective, "--clock", a.clock,
                                        "--neighbour-timeout", str(a.neighbour_timeout), *net(f"node{i}"),
                                        *(["--rejoin"] if rejoin else []), *([] if crash is None else ["--crash-after", str(crash)])],
                           stdout=subprocess.DEVNULL)  # fmt: skip

        col = children.start(
            "collector",
            ["collector", *common, "--signals", a.signals, "--variant", a.variant, "--objective", a.objective, "--seed", str(a.seed), "--clock", a.clock,
             "--summary-json", summary_path, "--progress", *(["--record", a.record] if a.record else []), *net("collector")],
            stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        threading.Thread(target=follow, args=(col.stdout,), daemon=True).start()
        for i in sc.ids:
            start_node(i, False, 0)
        awaits = [f"{i}@{r}" for i, rs in schedule.rejoins.items() for r in rs]
        children.start(
            "vehicle",
            ["vehicle", *common, "--signals", a.signals, "--seed", str(a.seed), "--clock", a.clock,
             "--node-timeout", str(a.node_timeout), "--pace", str(a.pace), "--start-timeout", str(run_start_timeout(len(names))),
             *net("vehicle"),
             *(x for w in awaits for x in ("--await-rejoin", w))],
            stdout=subprocess.DEVNULL,
        )  # fmt: skip
        rejoins = sorted((r, i) for i, rs in schedule.rejoins.items() for r in rs)
        reported: set[str] = set()
        while True:
            time.sleep(0.05)
            bar.update(max(progress[0], 0))
            for step, node in list(rejoins):
                if progress[0] >= step and children.procs[f"node{node}"].poll() is not None:
                    log("run", f"restarting node {node} with --rejoin at step {progress[0]}")
                    ports[f"node{node}"] = free_ports(1)[0]
                    children.start_again(f"node{node}")
                    reported.discard(f"node{node}")
                    start_node(node, True, step)
                    rejoins.remove((step, node))
            if col.poll() is not None:
                break
            veh = children.procs["vehicle"].poll()
            if veh not in (None, 0):
                log("run", f"the vehicle process failed (exit {veh}); stopping the run")
                return EXIT_VIOLATION
            for name, proc in children.procs.items():
                code = proc.poll()
                if not name.startswith("node") or name in reported or code in (None, 0):
                    continue
                reported.add(name)
                if code == -signal.SIGKILL and schedule.kills.get(int(name.removeprefix("node"))):
                    log("run", f"{name} killed (SIGKILL) as --kill asked")
                else:
                    log("run", f"{name} exited with code {code}; the run goes on without it")
        bar.update(max(progress[0], 0))
        bar.close()
        code = col.returncode
        for p in children.procs.values():  # vehicle and nodes end on End; give them a moment
            try:
                p.wait(timeout=ROLE_GRACE_S)
            except subprocess.TimeoutExpired:
                pass
        return _print_summary(summary_path, code, format_table)
    except KeyboardInterrupt:
        log("run", "interrupted: stopping the vehicle and the nodes, then letting the collector write what it has")
        children.stop_all(ROLE_GRACE_S, keep=["collector"])
        children.stop_all(COLLECTOR_GRACE_S)
        if Path(summary_path).exists() and a.summary_json:
            log("run", f"partial summary written to {summary_path}")
        return 130
    finally:
        children.stop_all(ROLE_GRACE_S)
        if router is not None:
            router.close()
        tmp.cleanup()


def _print_summary(summary_path: str, code: int, format_table: Callable[[RunSummary], str]) -> int:
    if not Path(summary_path).exists():
        print(f"netsetest run: the collector exited with code {code} without a summary", file=sys.stderr)
        return EXIT_VIOLATION
    print(format_table(read_summary(summary_path)))  # its last line names the security mode and the verdict
    return code
