"""Role specs (runtime/rolespec.py): a spec's command line is the exact inverse of its parser, and the
CLI's role commands parse into the same spec (they are built from it: one parser, not two)."""

from __future__ import annotations

import argparse
import os

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.cli.main import build_parser
from netsetest.estimator.names import NODE_ESTIMATOR_NAMES
from netsetest.estimator.objective import OBJECTIVES
from netsetest.models.manoeuvres import MANOEUVRES, WITH_AMPLITUDE
from netsetest.roles.flow import ACK_STRIDE, MAX_ACK_WINDOW
from netsetest.runtime.argtypes import SEED_MAX
from netsetest.runtime.rolespec import (
    DEFAULT_RUN_ID,
    ROLE_SPECS,
    RUN_ID_ENV,
    CollectorSpec,
    NodeSpec,
    RoleSpec,
    RouterSpec,
    ScenarioSpec,
    VehicleSpec,
    ZenohSpec,
)

EXAMPLES = int(os.environ.get("NETSETEST_FUZZ_EXAMPLES", "0")) or None
ROUND_TRIP = settings(max_examples=EXAMPLES or 100, derandomize=EXAMPLES is None, deadline=None, database=None)
READABLE = ("pyproject.toml", "README.md")  # --zenoh-config is checked to be a readable file when parsed
WRITABLE = ("docs", "tests")  # --profile: a directory the node can write in, checked when parsed

# any text a path or name may be, as long as it is one argv entry (no NUL); a positional cannot start with '-',
# and no value can be '--' (argparse drops it; to_argv refuses it)
texts = st.text(st.characters(blacklist_characters="\0", blacklist_categories=("Cs",)), max_size=20).filter(lambda s: s != "--")
positional = texts.filter(lambda s: not s.startswith("-"))
maybe = lambda s: st.none() | s  # noqa: E731  # a one-line local helper
run_ids = st.from_regex(r"[A-Za-z0-9_-]{1,64}", fullmatch=True).filter(lambda s: s != "--")
endpoints = st.builds(
    lambda proto, host, port: f"{proto}/{host}:{port}",
    st.sampled_from(["tcp", "tls", "udp", "quic"]),
    st.sampled_from(["127.0.0.1", "localhost", "router", "[::1]"]),
    st.integers(0, 65535),
)
seconds = st.floats(min_value=1e-9, max_value=1e9, allow_nan=False, allow_infinity=False)
non_negative = st.just(0.0) | seconds
pairs = st.tuples(st.integers(-5, 200), st.integers(-5, 10_000))
clocks = st.sampled_from(["lockstep", "realtime"])

finite = lambda lo, hi: st.floats(min_value=lo, max_value=hi, allow_nan=False, allow_infinity=False)  # noqa: E731  # a one-line local helper
drives = st.sampled_from(MANOEUVRES) | st.builds(lambda m, a: f"{m}@{a!r}", st.sampled_from(WITH_AMPLITUDE), finite(1e-6, 1.0))
scenarios = st.builds(
    ScenarioSpec,
    positional,
    maybe(st.sampled_from(["nsnim", "saim"])),
    maybe(st.integers(1, 10**6)),
    maybe(st.sampled_from(NODE_ESTIMATOR_NAMES)),
    maybe(texts),  # --log DRIVE (a recorded drive, docs/your-log.md)
    maybe(texts),  # --map MAP.toml
    maybe(drives),
    maybe(finite(1e-3, 500.0)),
    maybe(finite(0.0, 10.0)),
)
zenohs = st.builds(
    ZenohSpec,
    maybe(run_ids),
    st.sampled_from(["peer", "client"]),
    st.lists(endpoints, max_size=3).map(tuple),
    st.lists(endpoints, max_size=3).map(tuple),
    maybe(texts),
    maybe(st.sampled_from(READABLE)),
)
SPECS: dict[type[RoleSpec], st.SearchStrategy] = {
    VehicleSpec: st.builds(
        VehicleSpec,
        scenarios,
        st.sampled_from(["paper", "worst"]),
        st.integers(0, SEED_MAX),
        clocks,
        seconds,
        non_negative,
        seconds,
        st.booleans(),
        st.lists(pairs, max_size=3).map(tuple),
        maybe(st.integers(ACK_STRIDE, MAX_ACK_WINDOW)),  # --ack-window N, or unbounded (roles/flow.py)
        zenohs,
    ),
    NodeSpec: st.builds(
        NodeSpec,
        scenarios,
        st.integers(-10, 10**6),
        st.sampled_from(["scheduled", "per-rule"]),
        st.sampled_from(OBJECTIVES),
        clocks,
        seconds,
        st.booleans(),
        maybe(st.integers(-10, 10**6)),
        maybe(st.sampled_from(WRITABLE)),  # --profile DIR (netsetest/profile.py)
        zenohs,
    ),
    CollectorSpec: st.builds(
        CollectorSpec,
        scenarios,
        st.sampled_from(["paper", "worst"]),
        st.sampled_from(["scheduled", "per-rule"]),
        st.sampled_from(OBJECTIVES),
        maybe(st.integers(0, SEED_MAX)),
        clocks,
        maybe(texts),
        maybe(texts),
        maybe(st.integers(0, 1024)),
        seconds,
        zenohs,
    ),
    RouterSpec: st.builds(
        RouterSpec,
        maybe(positional),
        maybe(texts),
        st.lists(endpoints, max_size=3).map(tuple),
        st.lists(endpoints, max_size=3).map(tuple),
        maybe(run_ids),
        maybe(st.sampled_from(READABLE)),
    ),
}
any_spec = st.one_of(*SPECS.values())


CLI = build_parser()  # parse_args leaves the parser as it was: one for every example


def test_every_role_has_a_strategy() -> None:
    assert set(SPECS) == set(ROLE_SPECS)


@ROUND_TRIP
@given(any_spec)
def test_the_command_line_is_the_inverse_of_the_parser(spec: RoleSpec) -> None:
    argv = spec.to_argv()
    assert all(isinstance(x, str) for x in argv) and argv[0] == spec.ROLE
    assert type(spec).from_argv(argv) == spec


@ROUND_TRIP
@given(any_spec)
def test_the_cli_parses_a_role_command_line_into_the_same_spec(spec: RoleSpec) -> None:
    ns = CLI.parse_args(spec.to_argv())
    assert ns.command == spec.ROLE and type(spec).from_namespace(ns) == spec


def test_the_cli_role_commands_have_the_specs_options() -> None:
    """The role commands are built from the specs (the same flags, in the same order, with the same help)."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for spec in ROLE_SPECS:
        ours = [(a.option_strings, a.dest, a.help) for a in spec.parser()._actions if not isinstance(a, argparse._HelpAction)]
        cli = [(a.option_strings, a.dest, a.help) for a in sub.choices[spec.ROLE]._actions if not isinstance(a, argparse._HelpAction)]
        assert cli == ours, spec.ROLE


def test_defaults_are_left_out_and_values_that_look_like_options_survive() -> None:
    sc = ScenarioSpec("paper6")
    assert NodeSpec(sc, 3).to_argv() == ["node", "paper6", "--id", "3"]
    assert VehicleSpec(sc).to_argv() == ["vehicle", "paper6"]
    odd = CollectorSpec(sc, record="-r.json", summary_json="--x")
    assert odd.to_argv() == ["collector", "paper6", "--record=-r.json", "--summary-json=--x"]
    assert CollectorSpec.from_argv(odd.to_argv()) == odd
    assert NodeSpec.from_argv(NodeSpec(sc, -1, crash_after=-2).to_argv()) == NodeSpec(sc, -1, crash_after=-2)
    with pytest.raises(ValueError, match="cannot start with '-'"):
        VehicleSpec(ScenarioSpec("-odd.toml")).to_argv()
    with pytest.raises(ValueError, match="cannot take '--'"):
        VehicleSpec(sc, zenoh=ZenohSpec(run_id="--")).to_argv()
    with pytest.raises(ValueError, match="not a node command line"):
        NodeSpec.from_argv(["vehicle", "paper6"])


def test_bad_values_are_refused_as_on_the_command_line() -> None:
    for argv in (
        ["node", "paper6"],
        ["vehicle", "paper6", "--run-id", "a/b"],
        ["vehicle", "paper6", "--pace", "-1"],
        ["collector", "paper6", "--connect", "tcp/h:99999"],
        ["node", "paper6", "--id", "1", "--clock", "soon"],
    ):
        with pytest.raises(SystemExit) as exc:
            ROLE_SPECS[[s.ROLE for s in ROLE_SPECS].index(argv[0])].from_argv(argv)
        assert exc.value.code == 2, argv


def test_the_run_id_comes_from_the_environment_of_the_role_process(monkeypatch: pytest.MonkeyPatch) -> None:
    spec = VehicleSpec(ScenarioSpec("paper6"))
    monkeypatch.delenv(RUN_ID_ENV, raising=False)
    assert spec.zenoh.resolved_run_id == DEFAULT_RUN_ID
    monkeypatch.setenv(RUN_ID_ENV, "from-env")
    assert spec.zenoh.resolved_run_id == "from-env" and "--run-id" not in spec.to_argv()  # compose relies on it
    assert VehicleSpec(spec.scenario, zenoh=ZenohSpec(run_id="mine")).zenoh.resolved_run_id == "mine"
    assert RouterSpec().resolved_run_id == "from-env" and RouterSpec().endpoints == ["tcp/0.0.0.0:7447"]


def test_a_collector_refuses_a_channel_that_is_not_open(capsys: pytest.CaptureFixture[str]) -> None:
    from netsetest.cli.main import main

    assert main(["collector", "paper6", "--channel-fd", "987"]) == 2
    assert "--channel-fd 987: not an open file descriptor" in capsys.readouterr().err


def test_only_the_vehicle_of_a_run_from_a_log_reads_it(tmp_path) -> None:
    """A role started from a log's spec (with the steps `run` decided) loads its mapping but never the log: the nodes
    and the collector build on a file that is no log at all; the vehicle reads it and says why it cannot."""
    from pathlib import Path

    from netsetest.bus.base import MemoryBus
    from netsetest.logs.readers import LogError
    from netsetest.roles.collector import Collector
    from netsetest.roles.node import Node
    from netsetest.roles.vehicle import Vehicle

    examples = Path(__file__).resolve().parents[2] / "examples" / "logs"
    log = tmp_path / "drive.csv"
    log.write_text("not,a,log\n")
    spec = ScenarioSpec("paper6", steps=5, log=str(log), mapping=str(examples / "drive_csv.map.toml"))
    sc = spec.load()
    assert sc.log is not None and sc.steps == 5
    bus = MemoryBus()
    Collector(sc, bus, "t")
    [Node(sc, i, bus, "t") for i in sc.ids]
    with pytest.raises(LogError, match="no column"):
        Vehicle(sc, bus, "t")
