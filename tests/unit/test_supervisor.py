"""The launcher's supervisor and role start (runtime/launcher.py) on fake processes: no Zenoh, no fork.

A fake role process exits when the test's script says so (one step of the script per supervisor period)
or when it is signalled; the collector's channel gets its messages the way the reader thread would
hand them over (:meth:`ChannelReader.receive`)."""

from __future__ import annotations

import io
import signal
import subprocess
from collections.abc import Callable, Sequence
from pathlib import Path

import pytest

from netsetest.records.summary import RunSummary
from netsetest.runtime.channel import CHANNEL_FD, ChannelReader, RunFinished, StepChecked, decode, encode
from netsetest.runtime.launcher import (
    Children,
    LaunchOptions,
    Network,
    RoleStarter,
    RunOutcome,
    Schedule,
    Supervisor,
    kill_schedule,
    plan_run,
    role_names,
)
from netsetest.runtime.report import EXIT_COLLECTOR_STALLED, EXIT_INTERRUPTED, EXIT_NODE_LOST, EXIT_OK, EXIT_VIOLATION
from netsetest.runtime.rolespec import CollectorSpec, NodeSpec, VehicleSpec

ROOT = Path(__file__).resolve().parents[2]
PAPER6 = str(ROOT / "topologies" / "paper6.toml")
NODES = [1, 2, 3, 4, 5, 6]


class FakeProcess:
    """A role process that ends when told (``exit``) or signalled; SIGTERM is ignored with ``stubborn``."""

    def __init__(self, name: str, events: list[tuple[str, int]], stubborn: bool = False) -> None:
        self.name, self.events, self.stubborn = name, events, stubborn
        self.returncode: int | None = None
        self.pipes: dict[int, io.BytesIO] = {}

    def exit(self, code: int) -> None:
        if self.returncode is None:
            self.returncode = code

    def poll(self) -> int | None:
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is None:
            raise subprocess.TimeoutExpired(self.name, timeout or 0.0)
        return self.returncode

    def send_signal(self, sig: int) -> None:
        self.events.append((self.name, sig))
        if sig == signal.SIGKILL or not self.stubborn:
            self.exit(-sig)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class Run:
    """A fake run: its children, the collector's channel, and a script of what happens at each period."""

    def __init__(self, schedule: Schedule | None = None, stubborn: Sequence[str] = ()) -> None:
        self.events: list[tuple[str, int]] = []  # (process, signal) in the order they were sent
        self.spawned: list[tuple[str, list[str], Sequence[int]]] = []
        self.children = Children(self.spawn)
        self.stubborn = set(stubborn)
        for name in role_names_of(NODES):
            self.children.start(name, [name])
        self.channel = ChannelReader(io.BytesIO(b""))
        self.channel.wait_closed(5.0)  # the empty stream: its thread is done, the test feeds receive()
        self.script: dict[int, Callable[[], None]] = {}
        self.tick = 0
        self.restarts: list[tuple[int, int]] = []
        self.bar = FakeBar()
        self.supervisor = Supervisor(self.children, schedule or Schedule({}, {}), self.channel, self.restart, self.bar, sleep=self.step)

    def spawn(self, name: str, argv: list[str], pipes: Sequence[int]) -> FakeProcess:
        self.spawned.append((name, argv, pipes))
        proc = FakeProcess(name, self.events, stubborn=name in self.stubborn)
        proc.pipes = {fd: io.BytesIO(b"") for fd in pipes}  # a pipe whose writer has gone
        return proc

    def proc(self, name: str) -> FakeProcess:
        p = self.children.procs[name]
        assert isinstance(p, FakeProcess)
        return p

    def step(self, seconds: float) -> None:
        self.tick += 1
        if self.tick in self.script:
            self.script[self.tick]()
        assert self.tick < 100, "the supervisor never stopped"

    def restart(self, node: int, step: int) -> None:
        self.restarts.append((node, step))
        self.children.forget(f"node{node}")
        self.children.start(f"node{node}", [f"node{node}", "--rejoin"])

    def progress(self, k: int) -> None:
        self.channel.receive(encode(StepChecked(k)))

    def end(self, code: int = EXIT_OK, summary: RunSummary | None = None) -> None:
        """The normal end: the collector reports its summary and exits; the others end on End."""
        if summary is not None:
            self.channel.receive(encode(RunFinished(summary)))
        for name in self.children.procs:
            self.proc(name).exit(code if name == "collector" else 0)


class FakeBar:
    def __init__(self) -> None:
        self.shown: list[int] = []
        self.closed = False

    def update(self, done: int, extra: str = "") -> None:
        self.shown.append(done)

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def run() -> Run:
    """A fake run of the paper network: every role started, nothing scripted, the plain schedule."""
    return Run()


def writes_summary_on(run: Run, sig: int, written: RunSummary) -> None:
    """The fake collector hands ``written`` to the channel when it gets ``sig`` (as the real one writes its summary when
    stopped, or once continued), then acts on the signal as before."""
    collector = run.proc("collector")
    told = collector.send_signal

    def write_and_leave(s: int) -> None:
        if s == sig:
            run.channel.receive(encode(RunFinished(written)))
        told(s)

    collector.send_signal = write_and_leave  # type: ignore[method-assign]  # this fake writes its summary on sig


def role_names_of(ids: list[int]) -> list[str]:
    return ["collector", *(f"node{i}" for i in ids), "vehicle"]


def summary(**kw: object) -> RunSummary:
    return RunSummary.from_dict({"steps": 10, "mode": "zenoh", **kw})


def test_a_run_that_ends_gives_the_collectors_exit_code_and_summary(run: Run) -> None:
    run.script = {1: lambda: run.progress(3), 2: lambda: run.progress(7), 3: lambda: (run.progress(10), run.end(EXIT_NODE_LOST, summary(violations_total=0)))}
    out = run.supervisor.follow()
    assert out == RunOutcome(EXIT_NODE_LOST, summary(violations_total=0))
    assert run.bar.shown[:2] == [3, 7] and run.bar.shown[-1] == 10 and run.bar.closed
    assert run.events == []  # nobody was signalled


def test_the_collector_ending_without_a_summary_fails_the_run(run: Run, capsys: pytest.CaptureFixture[str]) -> None:
    run.script = {2: lambda: run.end(EXIT_OK, None)}
    assert run.supervisor.follow() == RunOutcome(EXIT_VIOLATION, None)
    assert "the collector exited with code 0 without a summary" in capsys.readouterr().err


def test_a_failed_vehicle_stops_the_run(run: Run, capsys: pytest.CaptureFixture[str]) -> None:
    run.script = {3: lambda: run.proc("vehicle").exit(1)}
    assert run.supervisor.follow() == RunOutcome(EXIT_VIOLATION, None)
    assert "the vehicle process failed (exit 1)" in capsys.readouterr().err


def test_a_dead_node_is_reported_once_and_the_run_goes_on(run: Run, capsys: pytest.CaptureFixture[str]) -> None:
    run.script = {2: lambda: run.proc("node4").exit(1), 6: lambda: run.end(EXIT_NODE_LOST, summary())}
    assert run.supervisor.follow().exit_code == EXIT_NODE_LOST
    err = capsys.readouterr().err
    assert err.count("node4 exited with code 1; the run goes on without it") == 1


def test_kill_and_rejoin_follow_the_schedule_and_the_progress(capsys: pytest.CaptureFixture[str]) -> None:
    run = Run(kill_schedule([(2, 3)], [(2, 6)], 10))
    run.script = {
        1: lambda: run.progress(3),
        2: lambda: (run.proc("node2").exit(-signal.SIGKILL), run.progress(4)),  # killed itself after step 3 (--crash-after)
        4: lambda: run.progress(5),
        6: lambda: run.progress(6),  # the rejoin step: restarted now, not before
        9: lambda: run.end(EXIT_OK, summary()),
    }
    assert run.supervisor.follow().exit_code == EXIT_OK
    assert run.restarts == [(2, 6)]
    err = capsys.readouterr().err
    assert err.count("node2 killed (SIGKILL) as --kill asked") == 1
    assert err.index("killed (SIGKILL)") < err.index("restarting node 2 with --rejoin at step 6")


def test_a_rejoin_waits_for_the_node_to_be_dead() -> None:
    run = Run(kill_schedule([(5, 2)], [(5, 4)], 10))
    run.script = {1: lambda: run.progress(6), 5: lambda: run.proc("node5").exit(-signal.SIGKILL), 8: lambda: run.end(EXIT_OK, summary())}
    run.supervisor.follow()
    assert run.restarts == [(5, 4)]  # at the first look after it died, once


def test_an_interrupt_stops_vehicle_and_nodes_before_the_collector() -> None:
    run = Run(stubborn=["node3"])  # one node ignores SIGTERM: it gets SIGKILL after the grace period
    out = run.supervisor.interrupted(None)
    assert out == RunOutcome(EXIT_INTERRUPTED, None)
    sent = [name for name, sig in run.events if sig == signal.SIGTERM]
    assert set(sent[:-1]) == {"vehicle", *(f"node{i}" for i in NODES)} and sent[-1] == "collector"
    assert ("node3", signal.SIGKILL) in run.events and run.events.index(("node3", signal.SIGKILL)) < run.events.index(("collector", signal.SIGTERM))
    assert all(p.poll() is not None for p in run.children.procs.values())


def test_an_interrupt_names_the_partial_summary(run: Run, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "s.json"
    path.write_text("{}")
    run.supervisor.interrupted(str(path))
    assert f"partial summary written to {path}" in capsys.readouterr().err


def test_stop_all_leaves_what_is_kept_and_what_has_ended(run: Run) -> None:
    run.proc("node1").exit(0)
    run.children.stop_all(0.0, keep=["collector"])
    assert {name for name, _ in run.events} == {"vehicle", *(f"node{i}" for i in NODES[1:])}
    assert run.proc("collector").poll() is None


def test_the_channel_carries_typed_messages() -> None:
    s = summary(violations_total=2, nodes_missing=[3])
    assert decode(encode(StepChecked(7))) == StepChecked(7)
    assert decode(encode(RunFinished(s))) == RunFinished(s)
    reader = ChannelReader(io.BytesIO(encode(StepChecked(2)) + b"@progress 5\n" + encode(StepChecked(4)) + encode(RunFinished(s))))
    assert reader.wait_closed(5.0)
    assert reader.step == 4 and reader.summary == s and len(reader.errors) == 1


# ---------------------------------------------------------------- role start


def test_the_starter_writes_each_role_through_its_spec() -> None:
    plan = plan_run(LaunchOptions(PAPER6, steps=20, seed=5, kill=((2, 5), (2, 12)), rejoin=((2, 9),), insecure=True, run_id="t1"))
    run = Run()
    run.children.procs.clear()
    net = Network(role_names(plan.scenario), "t1", None)
    starter = RoleStarter(plan, net, run.children)
    run.spawned.clear()
    starter.start_all()
    order = [name for name, _, _ in run.spawned]
    assert order == role_names(plan.scenario) == ["collector", *(f"node{i}" for i in NODES), "vehicle"]
    argv = {name: a for name, a, _ in run.spawned}
    col = CollectorSpec.from_argv(argv["collector"])
    assert col.channel_fd == CHANNEL_FD and [p for n, _, p in run.spawned if n == "collector"] == [[CHANNEL_FD]]
    assert col.seed == 5 and col.summary_json is None and col.zenoh.run_id == "t1" and col.zenoh.listen == (net.endpoint("collector"),)
    assert NodeSpec.from_argv(argv["node2"]).crash_after == 5 and NodeSpec.from_argv(argv["node1"]).crash_after is None
    veh = VehicleSpec.from_argv(argv["vehicle"])
    assert veh.await_rejoin == ((2, 9),) and len(veh.zenoh.connect) == len(NODES) + 1
    old = net.ports["node2"]
    run.proc("node2").exit(-signal.SIGKILL)
    starter.restart_node(2, 9)
    again = NodeSpec.from_argv(run.spawned[-1][1])
    assert again.rejoin and again.crash_after == 12 and again.zenoh.listen == (net.endpoint("node2"),) and net.ports["node2"] != old


def test_a_secured_network_makes_every_role_a_client_of_the_router() -> None:
    net = Network(["collector", "node1", "vehicle"], "t2", None, "tls/127.0.0.1:7999", "/creds")
    z = net.zenoh("node1")
    assert (z.mode, z.connect, z.listen, z.credentials) == ("client", ("tls/127.0.0.1:7999",), (), "/creds")
    assert "mtls" in net.describe()[0] and "--credentials /creds" in net.describe()[1]


def test_an_insecure_run_on_a_fixed_port_listens_and_is_watched_there() -> None:
    """Issue 41 item 12: ``run --insecure --port N``: the collector listens on N, the other roles connect to it there,
    the run prints that endpoint and the observers join there; no other role gets N."""
    import socket

    with socket.socket() as s:  # a port free now, for the plan
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    plan = plan_run(LaunchOptions(PAPER6, steps=5, insecure=True, run_id="demo", port=port))
    from netsetest.runtime.launcher import open_network

    net = open_network(plan, "demo", "/nonexistent")  # insecure: nothing is written
    endpoint = f"tcp/127.0.0.1:{port}"
    assert net.zenoh("collector").listen == (endpoint,) and all(endpoint in net.zenoh(n).connect for n in net.names if n != "collector")
    assert sorted(net.ports.values()).count(port) == 1
    assert net.observer_args() == ["--run-id", "demo", "--connect", endpoint]
    assert f"watch it with: netsetest watch --run-id demo --connect {endpoint}" in net.describe()[1]


def test_a_taken_port_is_refused_before_anything_starts() -> None:
    import socket

    from netsetest.runtime.launcher import LaunchError

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        for insecure in (True, False):
            with pytest.raises(LaunchError, match=rf"^--port {port}: 127.0.0.1:{port} is taken"):
                plan_run(LaunchOptions(PAPER6, steps=5, insecure=insecure, port=port))


def test_roles_that_do_not_end_on_end_share_one_grace_period(run: Run) -> None:
    """The collector has finished; nodes that never leave are waited for ROLE_GRACE_S in all, not each (an
    80-node ring whose nodes hung in their Zenoh close held `netsetest run` for 80 × 5 s)."""
    from netsetest.runtime import launcher

    now = [0.0]
    waited: list[float] = []

    def wait(self: FakeProcess, timeout: float | None = None) -> int:
        if self.returncode is None:
            waited.append(timeout or 0.0)
            now[0] += timeout or 0.0  # a process that does not end takes its whole timeout
            raise subprocess.TimeoutExpired(self.name, timeout or 0.0)
        return self.returncode

    run.supervisor.clock = lambda: now[0]
    for name in run.children.procs:
        p = run.proc(name)
        p.wait = wait.__get__(p)  # type: ignore[method-assign]  # this fake's wait advances the fake clock
    run.channel.receive(encode(RunFinished(summary())))
    run.script[1] = lambda: run.proc("collector").exit(EXIT_OK)
    run.supervisor.follow()
    assert waited and sum(waited) <= launcher.ROLE_GRACE_S + 1e-9, waited


def test_an_interrupt_returns_the_summary_the_collector_writes_on_sigterm(run: Run) -> None:
    """Issue 41, item 8: Ctrl-C on a Zenoh run printed no verdict; the launcher now hands on the summary the
    collector writes when it is stopped (the CLI prints its table and verdict, INTERRUPTED)."""
    partial = summary(stopped="interrupted", steps_completed=4)
    writes_summary_on(run, signal.SIGTERM, partial)
    assert run.supervisor.interrupted(None) == RunOutcome(EXIT_INTERRUPTED, partial)
    assert run.bar.closed


def test_every_stopped_role_is_also_continued() -> None:
    """A stopped (SIGSTOP) process acts on SIGTERM only once continued: stop_all sends SIGCONT after it."""
    run = Run(stubborn=["collector"])
    run.children.stop_all(0.0)
    collector = [sig for name, sig in run.events if name == "collector"]
    assert collector[:2] == [signal.SIGTERM, signal.SIGCONT] and collector[-1] == signal.SIGKILL


def test_a_vehicle_that_gave_up_on_a_stalled_collector_ends_the_run_with_the_collectors_verdict(run: Run, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 41, item 6: the vehicle waits for the collector's acknowledgment at most the stall limit, then exits
    EXIT_COLLECTOR_STALLED; the launcher stops the nodes and continues the collector, whose summary names its stall."""
    stalled = summary(stopped="collector stalled", steps_completed=51, collector_stall_s=70.0, collector_stall_step=51)
    writes_summary_on(run, signal.SIGCONT, stalled)
    run.script = {3: lambda: run.proc("vehicle").exit(EXIT_COLLECTOR_STALLED)}
    assert run.supervisor.follow() == RunOutcome(EXIT_VIOLATION, stalled)
    assert "the collector acknowledged nothing for the stall limit" in capsys.readouterr().err
    assert all(p.poll() is not None for p in run.children.procs.values())


def test_a_role_stopped_while_it_opens_its_session_exits_quietly(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C while a run still starts its roles: the signal reaches a role inside role_bus (its session opening);
    it leaves with EXIT_STOPPED and one log line, no traceback, and its body never runs."""
    from netsetest.runtime import processes
    from netsetest.runtime.rolespec import ScenarioSpec, ZenohSpec

    def opening(who: str, zenoh: ZenohSpec) -> None:
        signal.raise_signal(signal.SIGINT)  # the handler install_signal_handlers set raises Stop here
        raise AssertionError("unreachable: the signal stops the role")

    monkeypatch.setattr(processes, "role_bus", opening)
    saved = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        spec = ScenarioSpec(topology="paper6")
        code = processes.serve_role("node 1", "node-1", spec, ZenohSpec(), lambda sc, bus: pytest.fail("the body ran"))
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    assert code == processes.EXIT_STOPPED
    err = capsys.readouterr().err
    assert "stopped by SIGINT while opening its session" in err and "Traceback" not in err
