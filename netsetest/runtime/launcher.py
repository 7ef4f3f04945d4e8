"""The launcher of a Zenoh run (``netsetest run TOPOLOGY``): one process per role, followed to the end.

:func:`plan_run` checks a :class:`LaunchOptions` against its topology (a :class:`LaunchError` names the
bad option) and :func:`launch` runs the resulting :class:`RunPlan` in three parts:

- *network set-up* (:func:`open_network`, :class:`Network`): secured (the default), per-run mTLS credentials
  and the run's router (access control) in this process, every role a client of it; ``insecure``, a full
  peer mesh on loopback, each role listening on its own free port;
- *role start* (:class:`RoleStarter`): each role's typed spec (runtime/rolespec.py) from the plan and the
  network, forked by the run's fork server (runtime/forkserver.py), which starts first so that it imports
  while the launcher writes credentials and opens the router: 1 collector, one process per node, 1 vehicle;
- the *supervisor* (:class:`Supervisor`): follows the collector's progress and summary on its channel
  (runtime/channel.py), kills and restarts nodes mid-run (``kill``, ``rejoin``), logs the roles' exits,
  and stops every child on Ctrl-C, on SIGTERM, when the vehicle or the collector fails, or when the vehicle
  gave up on a collector stalled past the stall limit (then, and on Ctrl-C, with the summary the collector
  writes when it is stopped).  A node that
  dies is not a failure of the run: the others go on without it and the summary says so (exit code 3,
  from the collector).  It only polls, signals and restarts processes: tests/unit/test_supervisor.py runs
  it on fake ones.
"""

from __future__ import annotations

import contextlib
import io
import os
import secrets
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import IO, TYPE_CHECKING, Protocol

from netsetest.config.schema import Case, Scenario
from netsetest.logs.drive import with_log_steps
from netsetest.estimator.names import SDP
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, Objective
from netsetest.records.summary import RunSummary
from netsetest.roles.flow import ACK_WINDOW, check_window, show_window
from netsetest.runtime.channel import CHANNEL_FD, ChannelReader
from netsetest.runtime.forkserver import ForkServer, ForkServerError
from netsetest.runtime.report import EXIT_BAD_INPUT, EXIT_COLLECTOR_STALLED, EXIT_INTERRUPTED, EXIT_VIOLATION, Progress, exit_code, log
from netsetest.runtime.rolespec import Clock, CollectorSpec, NodeSpec, ScenarioSpec, VehicleSpec, ZenohSpec
from netsetest.runtime.timeouts import NEIGHBOUR_TIMEOUT_S, NODE_TIMEOUT_S, STALL_LIMIT_S, START_TIMEOUT_S
from netsetest.runtime.view_process import ViewProcess, start_view
from netsetest.runtime.view_server import PortTaken, ViewError

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
    manoeuvre: str | None = None  # the drive's overrides (ScenarioSpec)
    speed: float | None = None
    fault_scale: float | None = None
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
    stall_limit: float = STALL_LIMIT_S  # every session's Zenoh lease; the vehicle's wait for the collector
    ack_window: int | None = ACK_WINDOW  # lockstep: the vehicle's lead on the collector's acknowledgment (None: unbounded; roles/flow.py)
    kill: tuple[tuple[int, int], ...] = ()  # (node, step): SIGKILL the node right after that step
    rejoin: tuple[tuple[int, int], ...] = ()  # (node, step): restart the node with --rejoin at that step
    insecure: bool = False
    zenoh_config: str | None = None
    run_id: str | None = None  # None: a fresh random one (a guessable id, run<pid>, named every key of the run)
    view: bool = False  # a live view beside the run (runtime/view_process.py), an observer like `watch`
    view_port: int = 0  # its web port (0: a free one)
    view_lag_json: str | None = None  # where the view writes its lag behind the run when it stops (the benchmark's)
    profile: str | None = None  # a directory every node writes its CPU per step by phase to (netsetest/profile.py; the benchmark's)
    port: int = 0  # the run's port on loopback: its router's, or (insecure) its collector's, which observers connect to (0: a free one)
    log: str | None = None  # a recorded drive as the world (docs/your-log.md)
    mapping: str | None = None  # its mapping file

    @property
    def scenario(self) -> ScenarioSpec:
        """Which run, as every role is told it (the topology and the command line's overrides)."""
        return ScenarioSpec(
            self.topology,
            self.case,
            self.steps,
            self.estimator,
            log=self.log,
            mapping=self.mapping,
            manoeuvre=self.manoeuvre,
            speed=self.speed,
            fault_scale=self.fault_scale,
        )


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
class RoleUsage:
    """What one role process cost, from its rusage at its exit (None: not known, e.g. killed with the fork server)."""

    exit_code: int | None
    cpu_s: float | None  # user + system
    peak_rss_mb: float | None


@dataclass(frozen=True)
class RunOutcome:
    """How a launched run ended: the launcher's exit code and the collector's summary, if it wrote one (at the end
    of the run, when interrupted, when it stalled past the stall limit; not when the vehicle failed).  :func:`launch` adds
    what the benchmark measures: each role's usage (its last process) and when the launcher heard that
    the collector had checked each step (``time.monotonic()``)."""

    exit_code: int
    summary: RunSummary | None
    roles: Mapping[str, RoleUsage] = field(default_factory=dict)
    checked_at: Mapping[int, float] = field(default_factory=dict)


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
    # a recorded drive's steps are decided here, from the log, and every role is started with them: only the vehicle reads the log
    sc = with_log_steps(opts.scenario.load())
    for node, _ in (*opts.kill, *opts.rejoin):
        if sc.node(node).estimator != SDP:
            raise LaunchError(f"--kill/--rejoin {node}@…: node {node} runs {sc.node(node).estimator!r}, which cannot rejoin (only the SDP can)")
    try:
        schedule = kill_schedule(opts.kill, opts.rejoin, sc.steps)
    except ValueError as exc:
        raise LaunchError(str(exc)) from None
    try:
        check_window(opts.ack_window)  # (the command line's is checked as it is parsed; a caller's here)
    except ValueError as exc:
        raise LaunchError(f"--ack-window {show_window(opts.ack_window)}: {exc}") from None
    if opts.view_lag_json is not None and not opts.view:
        raise LaunchError("--view-lag-json: the live view's lag needs a live view (--view)")
    if opts.neighbour_timeout >= opts.node_timeout:
        # else a node waiting for a dead neighbour is itself declared dead by the vehicle
        raise LaunchError(f"--neighbour-timeout ({opts.neighbour_timeout:g} s) must be shorter than --node-timeout ({opts.node_timeout:g} s)")
    if opts.port and not port_free(opts.port):  # before any role starts (the router, or the collector, could not listen)
        raise LaunchError(f"--port {opts.port}: 127.0.0.1:{opts.port} is taken (another run or program listens there): choose another, or leave --port out")
    if opts.zenoh_config:
        from netsetest.bus.zenoh_bus import BusError, zenoh_config

        try:
            zenoh_config("peer", base_file=opts.zenoh_config)
        except BusError as exc:
            raise LaunchError(f"--zenoh-config: {exc}") from None
    return RunPlan(opts, sc, schedule)


# ---------------------------------------------------------------- the role processes


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


def port_free(port: int) -> bool:
    """Whether a listener could bind TCP ``port`` on loopback now (SO_REUSEADDR, as a listener binds: a closed
    connection's TIME_WAIT does not take the port)."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


class RoleProcess(Protocol):
    """What the launcher needs of a role process (a :class:`ForkedProcess`; a fake one in the unit tests)."""

    returncode: int | None
    pipes: dict[int, IO[bytes]]
    cpu_s: float | None  # once ended: its rusage (None: not known)
    peak_rss_mb: float | None

    def poll(self) -> int | None: ...
    def wait(self, timeout: float | None = None) -> int: ...
    def send_signal(self, sig: int) -> None: ...
    def kill(self) -> None: ...


Spawn = Callable[[str, list[str], Sequence[int]], RoleProcess]  # (name, argv, pipes) → the started process


class Children:
    """The role processes of a run by name; :meth:`stop_all` leaves none running."""

    def __init__(self, spawn: Spawn) -> None:
        self.spawn = spawn
        self.procs: dict[str, RoleProcess] = {}

    def start(self, name: str, argv: list[str], pipes: Sequence[int] = ()) -> RoleProcess:
        """A role process running ``netsetest ARGV`` (``pipes``: descriptors of the child that are pipes to us)."""
        proc = self.spawn(name, argv, pipes)
        self.procs[name] = proc
        return proc

    def forget(self, name: str) -> None:
        """Forget a process that ended (a killed node about to be restarted)."""
        self.procs.pop(name).wait()

    def stop_all(self, grace: float, keep: Sequence[str] = ()) -> None:
        """SIGTERM every live child except ``keep``, SIGKILL those still alive after ``grace`` s.  Each is also
        continued (SIGCONT): a stopped process acts on nothing else (a collector stopped could not write its summary)."""
        live = [p for n, p in self.procs.items() if p.poll() is None and n not in keep]
        for p in live:
            p.send_signal(signal.SIGTERM)
            p.send_signal(signal.SIGCONT)
        deadline = time.monotonic() + grace
        for p in live:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def fork_server(run_id: str) -> ForkServer:
    """The run's fork server, started at once: it imports while the launcher writes credentials and opens the router."""
    from netsetest.runtime.processes import role_env

    return ForkServer([sys.executable, "-m", ROLE_MODULE, "forkserver", "--run-id", run_id], role_env())


def router_session(listen: list[str], base_file: str | None, security: dict[str, object] | None, connect: Sequence[str] = (), lease_s: float = STALL_LIMIT_S):
    """Open a Zenoh router session (BusError naming the option: a bad --zenoh-config, or cannot --listen);
    ``connect``: the run's other routers (a run spanning hosts); ``lease_s``: the run's stall limit."""
    from netsetest.bus.zenoh_bus import BusError, open_session, zenoh_config

    try:
        cfg = zenoh_config("router", listen, connect, base_file=base_file, settings=security, lease_s=lease_s)
    except BusError as exc:
        raise BusError(f"--zenoh-config: {exc}") from None
    try:
        return open_session(cfg, f"router on {', '.join(listen)}")
    except BusError as exc:
        raise BusError(f"--listen: {exc}") from None


# ---------------------------------------------------------------- network set-up


class Network:
    """How each role connects: as an mTLS client of the launcher's router (``router_endpoint``), or as a
    peer of the open mesh (insecure: each role listens on its own port and connects to every other)."""

    def __init__(
        self,
        names: list[str],
        run_id: str,
        config: str | None,
        router_endpoint: str | None = None,
        credentials: str | None = None,
        router: object | None = None,
        collector_port: int = 0,
        stall_limit: float = STALL_LIMIT_S,
    ) -> None:
        self.names, self.run_id, self.config, self.stall_limit = names, run_id, config, stall_limit
        self.router_endpoint, self.credentials, self.router = router_endpoint, credentials, router
        self.ports = dict(zip(names, [p for p in free_ports(len(names) + 1) if p != collector_port]))  # one spare: none is the fixed port
        if collector_port:  # run --insecure --port: the endpoint observers are told to connect to
            self.ports["collector"] = collector_port

    @property
    def secured(self) -> bool:
        return self.router_endpoint is not None

    def endpoint(self, name: str) -> str:
        return f"tcp/127.0.0.1:{self.ports[name]}"

    def zenoh(self, name: str) -> ZenohSpec:
        """How role ``name`` connects."""
        if self.router_endpoint is not None:
            return ZenohSpec(self.run_id, "client", (), (self.router_endpoint,), self.credentials, self.config, self.stall_limit)
        others = tuple(self.endpoint(other) for other in self.names if other != name)
        return ZenohSpec(self.run_id, "peer", (self.endpoint(name),), others, None, self.config, self.stall_limit)

    def renew(self, name: str) -> None:
        """A fresh port for a restarted role (its old one may linger in TIME_WAIT)."""
        self.ports[name] = free_ports(1)[0]

    def observer_args(self) -> list[str]:
        """The options with which ``watch`` and ``view`` join this run."""
        if self.secured:
            return ["--credentials", str(self.credentials)]
        return ["--run-id", self.run_id, "--connect", self.endpoint("collector")]

    def describe(self) -> list[str]:
        """The launcher's lines about the network: its security, and how to watch the run."""
        from netsetest.runtime.security import SECURITY_INSECURE, SECURITY_MTLS

        if self.secured:
            return [
                f"security: {SECURITY_MTLS} (mTLS per role, access control at the run's router {self.router_endpoint}; credentials in {self.credentials})",
                f"run id {self.run_id}; watch it with: netsetest watch --credentials {self.credentials}",
            ]
        return [
            f"security: {SECURITY_INSECURE} (open peer mesh: any local process can read and forge messages)",
            f"run id {self.run_id}; watch it with: netsetest watch --run-id {self.run_id} --connect {self.endpoint('collector')}",
        ]

    def close(self) -> None:
        if self.router is not None:
            self.router.close()  # type: ignore[attr-defined]  # a zenoh.Session (zenoh ships no types)
            self.router = None


def role_names(sc: Scenario) -> list[str]:
    """The run's role processes, in the order they start: the collector first, the vehicle last."""
    return ["collector", *(f"node{i}" for i in sc.ids), "vehicle"]


def open_network(plan: RunPlan, run_id: str, tmp: str) -> Network:
    """Secured: write the run's credentials into ``tmp`` and open its router on ``--port`` (BusError naming the
    option); insecure: pick a port per role, ``--port`` the collector's."""
    from netsetest.runtime.security import ROUTER, identity, router_settings, write_credentials, write_observer_access
    from netsetest.runtime.security import role_names as certificate_names

    o, sc = plan.options, plan.scenario
    names = role_names(sc)
    if o.insecure:
        return Network(names, run_id, o.zenoh_config, collector_port=o.port, stall_limit=o.stall_limit)
    creds = str(Path(tmp) / "credentials")
    write_credentials(creds, certificate_names(sc))
    endpoint = f"tls/127.0.0.1:{o.port or free_ports(1)[0]}"
    router = router_session([endpoint], o.zenoh_config, router_settings(identity(creds, ROUTER), sc, run_id), lease_s=o.stall_limit)
    write_observer_access(creds, run_id, [endpoint])
    return Network(names, run_id, o.zenoh_config, endpoint, creds, router, stall_limit=o.stall_limit)


# ---------------------------------------------------------------- role start


class RoleStarter:
    """Each role's spec from the plan and the network, started as a child (the only place the launcher
    writes a role's command line: ``spec.to_argv()``)."""

    def __init__(self, plan: RunPlan, network: Network, children: Children) -> None:
        o = plan.options
        self.plan, self.network, self.children = plan, network, children
        lg = plan.scenario.log
        self.scenario = (
            o.scenario
            if lg is None  # the roles read their paths from the working directory the run was started in
            else replace(o.scenario, steps=plan.scenario.steps, log=os.path.abspath(lg.path), mapping=os.path.abspath(lg.mapping.path))
        )

    def collector(self) -> CollectorSpec:
        o = self.plan.options
        return CollectorSpec(
            self.scenario, o.signals, o.variant, o.objective, o.seed, o.clock, o.record, o.summary_json, CHANNEL_FD, zenoh=self.network.zenoh("collector")
        )

    def node(self, i: int, rejoin: bool = False, after: int = 0) -> NodeSpec:
        """Node ``i``; ``after``: the step it (re)joins at (its --crash-after is the next --kill from there)."""
        o = self.plan.options
        return NodeSpec(
            self.scenario,
            i,
            o.variant,
            o.objective,
            o.clock,
            o.neighbour_timeout,
            rejoin,
            self.plan.schedule.next_kill(i, after),
            o.profile,
            self.network.zenoh(f"node{i}"),
        )

    def vehicle(self) -> VehicleSpec:
        o, schedule = self.plan.options, self.plan.schedule
        awaits = tuple((i, r) for i, rs in schedule.rejoins.items() for r in rs)
        return VehicleSpec(
            self.scenario,
            o.signals,
            o.seed,
            o.clock,
            o.node_timeout,
            o.pace,
            run_start_timeout(len(self.network.names)),
            o.quiet,
            awaits,
            o.ack_window,
            self.network.zenoh("vehicle"),
        )

    def start_all(self) -> ChannelReader:
        """Collector, nodes, vehicle (it waits for everyone else); the collector's channel, being read."""
        col = self.children.start("collector", self.collector().to_argv(), pipes=[CHANNEL_FD])
        channel = ChannelReader(col.pipes[CHANNEL_FD])
        for i in self.plan.scenario.ids:
            self.children.start(f"node{i}", self.node(i).to_argv())
        self.children.start("vehicle", self.vehicle().to_argv())
        return channel

    def restart_node(self, i: int, step: int) -> None:
        """Node ``i`` again, with --rejoin at ``step``, on a fresh port."""
        name = f"node{i}"
        self.network.renew(name)
        self.children.forget(name)
        self.children.start(name, self.node(i, rejoin=True, after=step).to_argv())


# ---------------------------------------------------------------- the supervisor


class Supervisor:
    """Follows a started run to its end: the collector's progress (its channel), the --rejoin schedule,
    the roles' exits; on Ctrl-C/SIGTERM it stops the vehicle and the nodes, then the collector.  It
    only polls, signals and restarts processes, so it runs on fake ones (tests/unit/test_supervisor.py)."""

    def __init__(
        self,
        children: Children,
        schedule: Schedule,
        channel: ChannelReader,
        restart_node: Callable[[int, int], None],
        bar: Progress | None = None,
        sleep: Callable[[float], None] = time.sleep,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.children, self.schedule, self.channel, self.restart_node = children, schedule, channel, restart_node
        self.bar, self.sleep, self.clock = bar, sleep, clock
        self.rejoins = sorted((r, i) for i, rs in schedule.rejoins.items() for r in rs)  # (step, node) still to do
        self.reported: set[str] = set()  # nodes whose exit was logged

    def follow(self) -> RunOutcome:
        """Until the collector exits (its exit code and summary), the vehicle ends the run for a collector stalled
        past the stall limit (the collector's summary, which names its stall) or fails (EXIT_VIOLATION)."""
        while True:
            self.sleep(FOLLOW_PERIOD_S)
            self._show_progress()
            self._rejoin_due()
            if self.children.procs["collector"].poll() is not None:
                return self._finish()
            veh = self.children.procs["vehicle"].poll()
            if veh == EXIT_COLLECTOR_STALLED:
                log("run", "the collector acknowledged nothing for the stall limit; stopping the run and continuing the collector to write its summary")
                summary = self._wind_down()
                return RunOutcome(exit_code(summary) if summary is not None else EXIT_VIOLATION, summary)
            if veh not in (None, 0):
                log("run", f"the vehicle process failed (exit {veh}); stopping the run")
                return RunOutcome(EXIT_VIOLATION, None)
            self._report_exits()

    def _show_progress(self) -> None:
        if self.bar is not None:
            self.bar.update(max(self.channel.step, 0))

    def _rejoin_due(self) -> None:
        for step, node in list(self.rejoins):
            if self.channel.step >= step and self.children.procs[f"node{node}"].poll() is not None:
                log("run", f"restarting node {node} with --rejoin at step {self.channel.step}")
                self.restart_node(node, step)
                self.reported.discard(f"node{node}")
                self.rejoins.remove((step, node))

    def _report_exits(self) -> None:
        """A node that died is logged once (the run goes on without it)."""
        for name, proc in self.children.procs.items():
            code = proc.poll()
            if not name.startswith("node") or name in self.reported or code in (None, 0):
                continue
            self.reported.add(name)
            if code == -signal.SIGKILL and self.schedule.kills.get(int(name.removeprefix("node"))):
                log("run", f"{name} killed (SIGKILL) as --kill asked")
            else:
                log("run", f"{name} exited with code {code}; the run goes on without it")

    def _finish(self) -> RunOutcome:
        """The collector has exited: the last progress, a moment for the others to end on End, its summary."""
        self.channel.wait_closed(ROLE_GRACE_S)  # its write end closed with it: every message is in
        self._show_progress()
        if self.bar is not None:
            self.bar.close()
        deadline = self.clock() + ROLE_GRACE_S  # one moment for all: a wait per process took 80 × 5 s on a hung ring
        for p in self.children.procs.values():  # vehicle and nodes end on End; the launcher stops the rest
            try:
                p.wait(timeout=max(0.0, deadline - self.clock()))
            except subprocess.TimeoutExpired:
                pass
        col = self.children.procs["collector"]
        for why in self.channel.errors:
            log("run", f"the collector's channel: {why}")
        if self.channel.summary is None:
            log("run", f"the collector exited with code {col.returncode} without a summary")
            return RunOutcome(EXIT_VIOLATION, None)
        assert col.returncode is not None  # follow() saw it exit
        return RunOutcome(col.returncode, self.channel.summary)

    @classmethod
    def idle(cls, children: Children) -> Supervisor:
        """A supervisor of roles not started yet (Ctrl-C during the set-up: stop what was started)."""
        return cls(children, Schedule({}, {}), ChannelReader(io.BytesIO(b"")), lambda node, step: None)

    def interrupted(self, summary_json: str | None) -> RunOutcome:
        """Ctrl-C/SIGTERM: stop the vehicle and the nodes, then let the collector write what it has; its summary (the
        counts so far, the verdict INTERRUPTED) when it wrote one."""
        log("run", "interrupted: stopping the vehicle and the nodes, then letting the collector write what it has")
        summary = self._wind_down()
        if summary_json and Path(summary_json).exists():
            log("run", f"partial summary written to {summary_json}")
        return RunOutcome(EXIT_INTERRUPTED, summary)

    def _wind_down(self) -> RunSummary | None:
        """Stop the vehicle and the nodes, then the collector (it writes its record and summary on SIGTERM); the
        summary it sent on its channel (None: it wrote none in its grace period, or never started)."""
        self.children.stop_all(ROLE_GRACE_S, keep=["collector"])
        self.children.stop_all(COLLECTOR_GRACE_S)
        self.channel.wait_closed(ROLE_GRACE_S)  # its write end closed with it: every message is in
        if self.bar is not None:
            self.bar.close()
        return self.channel.summary


# ---------------------------------------------------------------- the run


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """SIGTERM stops the launcher (and the benchmark's namespaced runs) as Ctrl-C does (the handler before is restored after)."""

    def on_term(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    before = signal.signal(signal.SIGTERM, on_term)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)


def launch(plan: RunPlan) -> RunOutcome:
    """Run the plan's role processes to the end: network set-up (:func:`open_network`), role start
    (:class:`RoleStarter`), then the :class:`Supervisor`; on Ctrl-C/SIGTERM stop them and let the
    collector write what it has.  Leaves no process behind and closes the router."""
    from netsetest.bus.zenoh_bus import BusError

    o = plan.options
    run_id = o.run_id or f"run-{secrets.token_hex(RUN_ID_BYTES)}"
    with tempfile.TemporaryDirectory(prefix="netsetest-") as tmp, sigterm_as_interrupt():  # mode 0700 (mkdtemp)
        server = fork_server(run_id)  # first: it imports while we set up
        children = Children(server.spawn)
        network: Network | None = None
        supervisor: Supervisor | None = None
        view: ViewProcess | None = None
        try:
            network = open_network(plan, run_id, tmp)
            if not o.quiet:  # --quiet: nothing on success; the summary and the record name the security mode
                for line in network.describe():
                    log("run", line)
            if o.view:  # subscribed before the first role starts: it sees step 0
                view = start_view(network.observer_args(), plan.scenario.tau_s, o.view_port, o.view_lag_json)
                log("run", f"live view: {view.url}")
            starter = RoleStarter(plan, network, children)
            bar = Progress(plan.scenario.steps, f"zenoh ({len(plan.scenario.ids)} nodes + vehicle + collector)", enabled=not o.quiet)
            supervisor = Supervisor(children, plan.schedule, starter.start_all(), starter.restart_node, bar)
            outcome = supervisor.follow()
            if view is not None and sys.stdin.isatty():
                log("run", f"the run is over; its live view stays at {view.url} until Ctrl-C")
                with contextlib.suppress(KeyboardInterrupt):
                    signal.pause()
        except PortTaken as exc:
            log("run", f"--view-port {o.view_port}: {exc}")
            outcome = RunOutcome(EXIT_BAD_INPUT, None)
        except ViewError as exc:
            log("run", str(exc))
            outcome = RunOutcome(EXIT_BAD_INPUT, None)
        except BusError as exc:  # the router: a bad --zenoh-config, or it cannot listen
            log("run", str(exc))
            outcome = RunOutcome(EXIT_BAD_INPUT, None)
        except ForkServerError as exc:
            log("run", f"{exc}; stopping the run")
            outcome = RunOutcome(EXIT_VIOLATION, None)
        except KeyboardInterrupt:
            if supervisor is None:
                log("run", "interrupted while starting the run")
            outcome = (supervisor or Supervisor.idle(children)).interrupted(o.summary_json)
        finally:
            if view is not None:
                view.stop()
            children.stop_all(ROLE_GRACE_S)
            if network is not None:
                network.close()
            server.close()
    usage = {name: RoleUsage(p.returncode, p.cpu_s, p.peak_rss_mb) for name, p in children.procs.items()}
    return replace(outcome, roles=usage, checked_at=dict(supervisor.channel.checked_at) if supervisor else {})
