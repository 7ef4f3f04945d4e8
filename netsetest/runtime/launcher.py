"""The launcher of a Zenoh run (``netsetest run TOPOLOGY``): one process per role, followed to the end.

:func:`plan_run` checks a :class:`LaunchOptions` against its topology (a :class:`LaunchError` names the
bad option) and :func:`launch` runs the resulting :class:`RunPlan`: 1 vehicle, 1 collector and one process
per node, forked by the run's fork server (runtime/forkserver.py), which the launcher starts first so
that it imports while the launcher writes credentials and opens the router.  Secured (the default), the launcher writes per-run mTLS credentials and holds the run's
router (access control) in its own process, and every role is a client of it; ``insecure``, the roles
form a full peer mesh on loopback, each listening on its own free port.  The launcher follows the
collector's progress, kills and restarts nodes mid-run (``kill``, ``rejoin``), and stops every child on
Ctrl-C, on SIGTERM or when the vehicle or the collector fails.  A node that dies is not a failure of
the run: the others go on without it and the summary says so (exit code 3, from the collector).
"""

from __future__ import annotations

import secrets
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING

from netsetest.config.schema import Case, Scenario, load_topology
from netsetest.estimator.names import SDP
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, Objective
from netsetest.records.summary import RunSummary
from netsetest.runtime.forkserver import ForkedProcess, ForkServer, ForkServerError
from netsetest.runtime.report import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_VIOLATION, Progress, read_summary
from netsetest.runtime.rolespec import Clock, CollectorSpec, NodeSpec, ScenarioSpec, VehicleSpec, ZenohSpec
from netsetest.runtime.timeouts import NEIGHBOUR_TIMEOUT_S, NODE_TIMEOUT_S, START_TIMEOUT_S

if TYPE_CHECKING:  # annotations only: the estimator and the models load in the role processes, not in the launcher
    from netsetest.estimator.sdp import Variant
    from netsetest.models.signals import SignalKind

START_S_PER_ROLE = 1.0  # each role sets up its estimator, session and barrier; 100 of them share a few cores
COLLECTOR_GRACE_S = 10.0  # on Ctrl-C/SIGTERM: how long the collector may take to write its record and summary
ROLE_GRACE_S = 5.0  # how long a role may take to leave after SIGTERM (or after End)
FOLLOW_PERIOD_S = 0.05  # how often the launcher looks at its children and the collector's progress
ROLE_MODULE = "netsetest.cli.main"  # what a role process runs: ``python -m ROLE_MODULE ROLE ...``


class LaunchError(ValueError):
    """The options of a run do not fit together or do not fit the topology (exit code 2)."""


@dataclass(frozen=True)
class LaunchOptions:
    """What ``netsetest run --mode zenoh`` was asked for."""

    topology: str
    case: Case | None = None
    steps: int | None = None
    estimator: str | None = None  # every node's, overriding the topology's
    signals: SignalKind = "paper"
    variant: Variant = "scheduled"
    objective: Objective = DEFAULT_OBJECTIVE
    seed: int = 0
    clock: Clock = "lockstep"
    record: str | None = None
    summary_json: str | None = None
    quiet: bool = False
    node_timeout: float = NODE_TIMEOUT_S
    neighbour_timeout: float = NEIGHBOUR_TIMEOUT_S
    pace: float = 0.0
    kill: tuple[tuple[int, int], ...] = ()  # (node, step): SIGKILL the node right after that step
    rejoin: tuple[tuple[int, int], ...] = ()  # (node, step): restart the node with --rejoin at that step
    insecure: bool = False
    zenoh_config: str | None = None
    run_id: str | None = None  # None: a fresh random one (a guessable id, run<pid>, named every key of the run)


RUN_ID_BYTES = 8  # of a run's random id (as `netsetest credentials` makes)


@dataclass(frozen=True)
class Schedule:
    """``--kill`` / ``--rejoin`` per node, checked: kill and rejoin alternate, steps increase, within the run."""

    kills: dict[int, list[int]]
    rejoins: dict[int, list[int]]

    def next_kill(self, node: int, after: int) -> int | None:
        """The first kill step of ``node`` at or after step ``after`` (its process' --crash-after)."""
        return min((k for k in self.kills.get(node, []) if k >= after), default=None)


@dataclass(frozen=True)
class RunPlan:
    """A checked run: the options, their scenario and the kill/rejoin schedule."""

    options: LaunchOptions
    scenario: Scenario
    schedule: Schedule


@dataclass(frozen=True)
class RunOutcome:
    """How a launched run ended: the launcher's exit code and the collector's summary, if it wrote one
    at the normal end of the run (not when interrupted or when the vehicle failed)."""

    exit_code: int
    summary: RunSummary | None


def kill_schedule(kill: Sequence[tuple[int, int]], rejoin: Sequence[tuple[int, int]], steps: int) -> Schedule:
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
    by = lambda opt: {i: [s for s, o in evs if o == opt] for i, evs in events.items()}  # noqa: E731  # a one-line local helper
    return Schedule(by("kill"), by("rejoin"))


def run_start_timeout(roles: int) -> float:
    """The vehicle's start-up timeout in a run of ``roles`` processes: large networks take longer to start."""
    return max(START_TIMEOUT_S, START_S_PER_ROLE * roles)


def plan_run(opts: LaunchOptions) -> RunPlan:
    """Load the topology and check the options against it and each other (LaunchError naming the option;
    ConfigError for a bad topology)."""
    sc = load_topology(opts.topology, opts.case, opts.steps, opts.estimator)
    for node, _ in (*opts.kill, *opts.rejoin):
        if sc.node(node).estimator != SDP:
            raise LaunchError(f"--kill/--rejoin {node}@…: node {node} runs {sc.node(node).estimator!r}, which cannot rejoin (only the SDP can)")
    try:
        schedule = kill_schedule(opts.kill, opts.rejoin, sc.steps)
    except ValueError as exc:
        raise LaunchError(str(exc)) from None
    if opts.neighbour_timeout >= opts.node_timeout:
        # else a node waiting for a dead neighbour is itself declared dead by the vehicle
        raise LaunchError(f"--neighbour-timeout ({opts.neighbour_timeout:g} s) must be shorter than --node-timeout ({opts.node_timeout:g} s)")
    if opts.zenoh_config:
        from netsetest.bus.zenoh_bus import BusError, zenoh_config

        try:
            zenoh_config("peer", base_file=opts.zenoh_config)
        except BusError as exc:
            raise LaunchError(f"--zenoh-config: {exc}") from None
    return RunPlan(opts, sc, schedule)


# ---------------------------------------------------------------- processes


def free_ports(n: int) -> list[int]:
    """``n`` distinct TCP ports free on loopback right now (held together, so no two are the same)."""
    socks, ports = [], []
    for _ in range(n):
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        socks.append(s)
        ports.append(s.getsockname()[1])
    for s in socks:
        s.close()
    return ports


class Children:
    """The role processes of a run, forked by the run's fork server; :meth:`close` leaves none behind."""

    def __init__(self, run_id: str) -> None:
        """Starts the fork server at once: it imports while the launcher writes credentials and opens the router."""
        from netsetest.runtime.processes import role_env

        self.server = ForkServer([sys.executable, "-m", ROLE_MODULE, "forkserver", "--run-id", run_id], role_env())
        self.procs: dict[str, ForkedProcess] = {}

    def start(self, name: str, argv: list[str], pipe_stdout: bool = False) -> ForkedProcess:
        """A role process running ``netsetest ARGV`` (stdout: a text pipe to us with ``pipe_stdout``, else /dev/null)."""
        proc = self.server.spawn(name, argv, pipe_stdout)
        self.procs[name] = proc
        return proc

    def start_again(self, name: str) -> None:
        """Forget a process that ended (a killed node about to be restarted)."""
        self.procs.pop(name).wait()

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

    def close(self) -> None:
        """Stop every child (as :meth:`stop_all`), then the fork server."""
        self.stop_all(ROLE_GRACE_S)
        self.server.close()


def router_session(listen: list[str], base_file: str | None, security: dict[str, object] | None):
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


# ---------------------------------------------------------------- the run


class _Network:
    """How each role connects: as an mTLS client of the launcher's router, or as a peer of the open mesh."""

    def __init__(self, names: list[str], router_endpoint: str | None, credentials: str | None) -> None:
        self.names, self.router_endpoint, self.credentials = names, router_endpoint, credentials
        self.ports = dict(zip(names, free_ports(len(names))))

    def endpoint(self, name: str) -> str:
        return f"tcp/127.0.0.1:{self.ports[name]}"

    def zenoh(self, name: str, run_id: str, config: str | None) -> ZenohSpec:
        """How role ``name`` connects."""
        if self.router_endpoint is not None:  # star: every role is an mTLS client of the launcher's router
            return ZenohSpec(run_id, "client", (), (self.router_endpoint,), self.credentials, config)
        others = tuple(self.endpoint(other) for other in self.names if other != name)  # insecure: a full peer mesh
        return ZenohSpec(run_id, "peer", (self.endpoint(name),), others, None, config)

    def renew(self, name: str) -> None:
        """A fresh port for a restarted role (its old one may linger in TIME_WAIT)."""
        self.ports[name] = free_ports(1)[0]


def launch(plan: RunPlan) -> RunOutcome:
    """Run the plan's role processes to the end; on Ctrl-C/SIGTERM stop them and let the collector
    write what it has.  Leaves no process behind and closes the router."""
    from netsetest.bus.zenoh_bus import BusError
    from netsetest.runtime.processes import log
    from netsetest.runtime.security import (
        ROUTER, SECURITY_INSECURE, SECURITY_MTLS, identity, role_names, router_settings, write_credentials, write_observer_access,
    )

    o, sc, schedule = plan.options, plan.scenario, plan.schedule
    security = SECURITY_INSECURE if o.insecure else SECURITY_MTLS
    run_id = o.run_id or f"run-{secrets.token_hex(RUN_ID_BYTES)}"
    tmp = tempfile.TemporaryDirectory(prefix="netsetest-")  # mode 0700 (mkdtemp)
    summary_path = Path(o.summary_json or Path(tmp.name) / "summary.json")
    children = Children(run_id)  # first: the fork server imports while we set up
    router = None
    scenario = ScenarioSpec(o.topology, o.case, o.steps, o.estimator)
    names = ["collector", "vehicle", *(f"node{i}" for i in sc.ids)]

    def on_term(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)
    try:
        if o.insecure:
            net = _Network(names, None, None)
        else:
            creds = str(Path(tmp.name) / "credentials")
            write_credentials(creds, role_names(sc))
            router_endpoint = f"tls/127.0.0.1:{free_ports(1)[0]}"
            try:
                router = router_session([router_endpoint], o.zenoh_config, router_settings(identity(creds, ROUTER), sc, run_id))
            except BusError as exc:
                log("run", str(exc))
                return RunOutcome(EXIT_BAD_INPUT, None)
            write_observer_access(creds, run_id, [router_endpoint])
            net = _Network(names, router_endpoint, creds)
        if not o.quiet:  # --quiet: nothing on success; the summary and the record name the security mode
            log("run", f"security: {security}" + (f" (mTLS per role, access control at the run's router {net.router_endpoint}; credentials in {net.credentials})"
                                                   if router is not None else " (open peer mesh: any local process can read and forge messages)"))
        if not o.quiet:  # how to look inside the run from another terminal (README: Live views)
            log("run", f"run id {run_id}; " + (
                f"watch it with: netsetest watch --run-id {run_id} --connect {net.endpoint('collector')}" if router is None
                else f"watch it with: netsetest watch --credentials {net.credentials}"))
        bar = Progress(sc.steps, f"zenoh ({len(sc.ids)} nodes + vehicle + collector)", enabled=not o.quiet)
        progress = [-1]

        def follow(stream: IO[str]) -> None:
            for line in stream:
                if line.startswith("@progress "):
                    progress[0] = int(line.split()[1])

        def start_node(i: int, rejoin: bool, after: int) -> None:
            spec = NodeSpec(scenario, i, o.variant, o.objective, o.clock, o.neighbour_timeout, rejoin, schedule.next_kill(i, after),
                            net.zenoh(f"node{i}", run_id, o.zenoh_config))
            children.start(f"node{i}", spec.to_argv())

        collector = CollectorSpec(scenario, o.signals, o.variant, o.objective, o.seed, o.clock, o.record, str(summary_path), True,
                                  zenoh=net.zenoh("collector", run_id, o.zenoh_config))
        col = children.start("collector", collector.to_argv(), pipe_stdout=True)
        threading.Thread(target=follow, args=(col.stdout,), daemon=True).start()
        for i in sc.ids:
            start_node(i, False, 0)
        awaits = tuple((i, r) for i, rs in schedule.rejoins.items() for r in rs)
        vehicle = VehicleSpec(scenario, o.signals, o.seed, o.clock, o.node_timeout, o.pace, run_start_timeout(len(names)), o.quiet, awaits,
                              net.zenoh("vehicle", run_id, o.zenoh_config))
        children.start("vehicle", vehicle.to_argv())
        rejoins = sorted((r, i) for i, rs in schedule.rejoins.items() for r in rs)
        reported: set[str] = set()
        while True:
            time.sleep(FOLLOW_PERIOD_S)
            bar.update(max(progress[0], 0))
            for step, node in list(rejoins):
                if progress[0] >= step and children.procs[f"node{node}"].poll() is not None:
                    log("run", f"restarting node {node} with --rejoin at step {progress[0]}")
                    net.renew(f"node{node}")
                    children.start_again(f"node{node}")
                    reported.discard(f"node{node}")
                    start_node(node, True, step)
                    rejoins.remove((step, node))
            if col.poll() is not None:
                break
            veh = children.procs["vehicle"].poll()
            if veh not in (None, 0):
                log("run", f"the vehicle process failed (exit {veh}); stopping the run")
                return RunOutcome(EXIT_VIOLATION, None)
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
        for p in children.procs.values():  # vehicle and nodes end on End; give them a moment
            try:
                p.wait(timeout=ROLE_GRACE_S)
            except subprocess.TimeoutExpired:
                pass
        if not summary_path.exists():
            log("run", f"the collector exited with code {col.returncode} without a summary")
            return RunOutcome(EXIT_VIOLATION, None)
        assert col.returncode is not None  # the loop above ends once the collector has exited
        return RunOutcome(col.returncode, read_summary(summary_path))
    except ForkServerError as exc:
        log("run", f"{exc}; stopping the run")
        return RunOutcome(EXIT_VIOLATION, None)
    except KeyboardInterrupt:
        log("run", "interrupted: stopping the vehicle and the nodes, then letting the collector write what it has")
        children.stop_all(ROLE_GRACE_S, keep=["collector"])
        children.stop_all(COLLECTOR_GRACE_S)
        if summary_path.exists() and o.summary_json:
            log("run", f"partial summary written to {summary_path}")
        return RunOutcome(EXIT_INTERRUPTED, None)
    finally:
        children.stop_all(ROLE_GRACE_S)
        if router is not None:
            router.close()
        children.close()
        tmp.cleanup()
