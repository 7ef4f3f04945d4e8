"""Typed role specs: everything one role process of a Zenoh run is started with, and its command line.

One frozen dataclass per role (:class:`VehicleSpec`, :class:`NodeSpec`, :class:`CollectorSpec`,
:class:`RouterSpec`), sharing :class:`ScenarioSpec` (which run) and :class:`ZenohSpec` (how the role
connects).  Each field carries its option (flag, parser, help) in its metadata, so a spec has one
definition from which three things are derived:

- :meth:`RoleSpec.add_arguments`: the argparse options of ``netsetest ROLE`` (the CLI's role commands
  are built from it, so there is no second parser);
- :meth:`RoleSpec.to_argv`: the command line that starts the role (``["node", TOPOLOGY, "--id", "3",
  ...]``; options at their default are left out);
- :meth:`RoleSpec.from_argv` / :meth:`RoleSpec.from_namespace`: the spec back from a command line.

``from_argv(spec.to_argv()) == spec`` for every valid spec (tests/unit/test_rolespec.py).  The launcher
(runtime/launcher.py), the benchmark and ``netsetest compose`` write role command lines only through these
classes; the role main loops (runtime/processes.py) take them.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Sequence
from dataclasses import MISSING, dataclass, field, fields
from typing import TYPE_CHECKING, ClassVar, Literal, TypeVar

from netsetest.estimator.names import NODE_ESTIMATOR_NAMES
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, OBJECTIVE_HELP, OBJECTIVES
from netsetest.roles.flow import ACK_WINDOW, MAX_ACK_WINDOW, UNBOUNDED, show_window
from netsetest.runtime import argtypes
from netsetest.runtime.timeouts import NEIGHBOUR_TIMEOUT_S, NODE_TIMEOUT_S, STALL_LIMIT_S, START_TIMEOUT_S
from netsetest.scenarios import topology_help

if TYPE_CHECKING:  # annotations only: a role process loads the estimator and the models when it needs them
    from netsetest.config.schema import Case, Scenario
    from netsetest.estimator.objective import Objective
    from netsetest.estimator.sdp import Variant
    from netsetest.models.signals import SignalKind

Clock = Literal["lockstep", "realtime"]
ZenohMode = Literal["peer", "client"]
RUN_ID_ENV = "NETSETEST_RUN_ID"  # default of --run-id (compose services read it from the credentials' run.env)
DEFAULT_RUN_ID = "default"  # the run id of a role started by hand without --run-id or $NETSETEST_RUN_ID
COLLECTOR_IDLE_TIMEOUT_S = 60.0  # the collector gives up when no message arrives this long (the vehicle is gone)
ZENOH_DEFAULT_PORT = 7447


@dataclass(frozen=True)
class Opt:
    """How one field of a spec appears on the command line.

    ``flag`` None: a positional argument (``optional``: it may be left out); ``switch``: a flag without
    a value (the field is a bool); ``many``: repeatable, the field a tuple of its values; ``show``
    writes one value back as text (the inverse of ``parse``)."""

    flag: str | None
    help: str
    parse: Callable[[str], object] = str
    show: Callable[[object], str] = str
    choices: Sequence[str] | None = None
    metavar: str | None = None
    switch: bool = False
    many: bool = False
    optional: bool = False


def _opt(default: object = MISSING, /, *args: object, **kw: object):
    """A dataclass field with its option: ``_opt(DEFAULT, FLAG, HELP, ...)`` (no default: required)."""
    meta = {"opt": Opt(*args, **kw)}  # type: ignore[arg-type]  # the keywords are Opt's, checked when it is built
    return field(metadata=meta) if default is MISSING else field(default=default, metadata=meta)


def _group(spec: type, title: str | None, required: bool = False):
    """A nested spec (its options in an argparse group named ``title``; None: among the role's own);
    ``required``: no default (the scenario: its topology has none)."""
    meta = {"spec": spec, "group": title}
    return field(metadata=meta) if required else field(default_factory=spec, metadata=meta)


def _show_at(v: object) -> str:
    """A (node, step) pair as argtypes.node_at parses it: NODE@STEP."""
    assert isinstance(v, tuple) and len(v) == 2
    return f"{v[0]}@{v[1]}"


def _tokens(flag: str, text: str) -> list[str]:
    """``--flag value``; ``--flag=value`` when the value starts with '-' (argparse would take it for an option).
    A value of exactly '--' cannot be given at all (argparse drops it: ValueError)."""
    if text == "--":
        raise ValueError(f"{flag} '--': argparse cannot take '--' as a value")
    return [f"{flag}={text}"] if text.startswith("-") else [flag, text]


S = TypeVar("S", bound="RoleSpec")


class RoleSpec:
    """What every role spec can do with its fields' options (a mixin of the dataclasses below)."""

    ROLE: ClassVar[str]  # the command: netsetest ROLE ...
    HELP: ClassVar[str]

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        """The role's options on ``parser`` (the CLI's ``netsetest ROLE`` and :meth:`from_argv`)."""
        _add_arguments(cls, parser, parser, "")

    @classmethod
    def from_namespace(cls: type[S], ns: argparse.Namespace) -> S:
        """The spec from what :meth:`add_arguments`' options parsed."""
        return _from_namespace(cls, ns, "")  # type: ignore[return-value]  # _from_namespace builds cls itself

    @classmethod
    def parser(cls) -> argparse.ArgumentParser:
        p = argparse.ArgumentParser(prog=f"netsetest {cls.ROLE}", description=cls.HELP)
        cls.add_arguments(p)
        return p

    @classmethod
    def from_argv(cls: type[S], argv: Sequence[str]) -> S:
        """The spec of a role command line (``[ROLE, ...]``, as :meth:`to_argv` writes it); argparse's
        SystemExit(2) on a bad one."""
        if not argv or argv[0] != cls.ROLE:
            raise ValueError(f"not a {cls.ROLE} command line: {list(argv)[:1]}")
        return cls.from_namespace(cls.parser().parse_args(list(argv[1:])))

    def to_argv(self) -> list[str]:
        """The command line of this role (``[ROLE, positionals..., options...]``), options at their default left out."""
        pos, opts = _argv(self)
        return [self.ROLE, *pos, *opts]


def _add_arguments(cls: type, parser: argparse.ArgumentParser, where, prefix: str) -> None:
    for f in fields(cls):
        dest = prefix + f.name
        if "spec" in f.metadata:
            group = parser.add_argument_group(f.metadata["group"]) if f.metadata["group"] else where
            _add_arguments(f.metadata["spec"], parser, group, dest + ".")
            continue
        o: Opt = f.metadata["opt"]
        if o.flag is None:
            where.add_argument(dest, metavar=f.name, help=o.help, **({"nargs": "?"} if o.optional else {}))
        elif o.switch:
            where.add_argument(o.flag, dest=dest, action="store_true", help=o.help)
        elif o.many:
            where.add_argument(o.flag, dest=dest, type=o.parse, action="append", default=[], metavar=o.metavar, help=o.help)
        else:
            kw = {"default": f.default} if f.default is not MISSING else {"required": True}
            where.add_argument(o.flag, dest=dest, type=o.parse, choices=o.choices, metavar=o.metavar, help=o.help, **kw)


def _from_namespace(cls: type, ns: argparse.Namespace, prefix: str) -> object:
    values = {}
    for f in fields(cls):
        dest = prefix + f.name
        if "spec" in f.metadata:
            values[f.name] = _from_namespace(f.metadata["spec"], ns, dest + ".")
        else:
            v = getattr(ns, dest)
            values[f.name] = tuple(v or ()) if f.metadata["opt"].many else v
    return cls(**values)


def _argv(spec: object) -> tuple[list[str], list[str]]:
    """(positionals, options) of a spec, nested specs included."""
    pos: list[str] = []
    opts: list[str] = []
    for f in fields(spec):  # type: ignore[arg-type]  # every spec is a dataclass
        v = getattr(spec, f.name)
        if "spec" in f.metadata:
            inner_pos, inner_opts = _argv(v)
            pos += inner_pos
            opts += inner_opts
            continue
        o: Opt = f.metadata["opt"]
        if o.flag is None:
            if v is not None:
                text = o.show(v)
                if text.startswith("-"):
                    raise ValueError(f"{f.name} {text!r}: a positional argument cannot start with '-' (write ./{text})")
                pos.append(text)
        elif f.default is not MISSING and v == f.default:
            continue
        elif o.switch:
            opts.append(o.flag)
        elif o.many:
            for x in v:
                opts += _tokens(o.flag, o.show(x))
        else:
            opts += _tokens(o.flag, o.show(v))
    return pos, opts


# ---------------------------------------------------------------- the parts every role shares


LOG_HELP = "a recorded drive as the world: a ROS 2 bag, an MDF4 file, a Parquet or CSV table (docs/your-log.md; default: the topology's)"
MAP_HELP = "the log's mapping (default: the topology's [vehicle] mapping, else DRIVE's name with .map.toml)"
ESTIMATOR_HELP = f"every node's estimator, overriding the topology's per-node 'estimator' ({', '.join(NODE_ESTIMATOR_NAMES)}; default: the file's, else sdp)"
MANOEUVRE_HELP = (
    "override the topology's [vehicle] manoeuvre (paper, step-steer, sine-dwell, double-lane-change, lap); NAME@AMP also its "
    "steering amplitude [rad] ([steering] high) (default: the file's)"
)
SPEED_HELP = "override the speed reference's mean, [speed] mean_kmh [km/h] (default: the file's)"
FAULT_SCALE_HELP = "every faulty node's fault scaled to S × its declared [fault_bound] size at its peak, its shape kept (default: the file's faults)"
ZENOH_CONFIG_HELP = "a Zenoh configuration (JSON5) to start from; netsetest sets mode, endpoints, scouting, security and the lease on top (default: none)"
ACK_WINDOW_HELP = (
    f"lockstep: how many steps the vehicle may lead the collector's acknowledgment, up to {MAX_ACK_WINDOW} (a paused "
    f"collector's backlog stays within its inbox); {UNBOUNDED}: no window, a slow collector may then lose messages "
    f"(the benchmark's measure of what the window costs) (default: {ACK_WINDOW})"
)
PROFILE_HELP = (
    "write the node's CPU per step by phase of its own thread to DIR/node-<id>.json when it ends (netsetest/profile.py; "
    "the benchmark's; default: not profiled, nothing on the hot path)"
)
STALL_LIMIT_HELP = (
    "how long [s] a role may not run (stopped, a swapping machine) and the run go on: every session's Zenoh lease, and the "
    "longest the vehicle waits for the collector; a collector stalled longer ends the run with a verdict naming its stall "
    f"(default: {STALL_LIMIT_S:g})"
)


@dataclass(frozen=True)
class ScenarioSpec:
    """Which run: the topology and what the command line overrides of it."""

    topology: str = _opt(MISSING, None, topology_help())
    case: Case | None = _opt(None, "--case", "override the topology's case (default: the file's)", choices=("nsnim", "saim"))
    steps: int | None = _opt(None, "--steps", "override the number of steps of τs each (default: the file's)", argtypes.positive_int, metavar="N")
    estimator: str | None = _opt(None, "--estimator", ESTIMATOR_HELP, choices=NODE_ESTIMATOR_NAMES, metavar="NAME")
    log: str | None = _opt(None, "--log", LOG_HELP, metavar="DRIVE")
    mapping: str | None = _opt(None, "--map", MAP_HELP, metavar="MAP.toml")
    manoeuvre: str | None = _opt(None, "--manoeuvre", MANOEUVRE_HELP, argtypes.drive, metavar="NAME[@AMP]")
    speed: float | None = _opt(None, "--speed", SPEED_HELP, argtypes.speed_kmh, metavar="KMH")
    fault_scale: float | None = _opt(None, "--fault-scale", FAULT_SCALE_HELP, argtypes.fault_scale, metavar="S")

    def load(self) -> Scenario:
        """The scenario (ConfigError naming what is wrong with the file or an override).  A recorded drive is named
        and its mapping read, but the log itself is read only by the vehicle (logs/drive.py): a role of a run
        from a log is started with its steps (``run`` decides them once, from the log)."""
        from netsetest.config.schema import load_topology
        from netsetest.models.manoeuvres import DriveSpec

        drive = DriveSpec.parse(self.manoeuvre) if self.manoeuvre is not None else None
        return load_topology(
            self.topology,
            self.case,
            self.steps,
            self.estimator,
            manoeuvre=drive.manoeuvre if drive else None,
            steer_high=drive.amplitude if drive else None,
            speed_kmh=self.speed,
            fault_scale=self.fault_scale,
            log=self.log,
            mapping=self.mapping,
        )

    def to_argv(self) -> list[str]:
        """The topology and the overrides given, as ``run`` and every role take them (``[TOPOLOGY, --case, ...]``)."""
        pos, opts = _argv(self)
        return [*pos, *opts]


def _resolve_run_id(run_id: str | None) -> str:
    return run_id or os.environ.get(RUN_ID_ENV) or DEFAULT_RUN_ID


_RUN_ID_HELP = f"key-expression namespace of the run (netsetest/<run-id>/...); default ${RUN_ID_ENV} or '{DEFAULT_RUN_ID}'"


@dataclass(frozen=True)
class ZenohSpec:
    """How a role connects.  ``run_id`` None: ``$NETSETEST_RUN_ID``, else 'default' (:attr:`resolved_run_id`,
    read in the role process: a compose service gets it from the credentials' run.env)."""

    run_id: str | None = _opt(None, "--run-id", _RUN_ID_HELP, argtypes.run_id)
    mode: ZenohMode = _opt("peer", "--zenoh-mode", "peer (one host) or client of a router", choices=("peer", "client"))
    listen: tuple[str, ...] = _opt(
        (), "--listen", "endpoint to listen on, e.g. tcp/127.0.0.1:7450 (repeatable; default: none)", argtypes.endpoint, metavar="ENDPOINT", many=True
    )
    connect: tuple[str, ...] = _opt(
        (), "--connect", "endpoint to connect to, e.g. tls/10.0.0.1:7447 (repeatable; default: none)", argtypes.endpoint, metavar="ENDPOINT", many=True
    )
    credentials: str | None = _opt(
        None,
        "--credentials",
        "mTLS: this role's certificate and key from DIR (`netsetest credentials`); connect on tls/ endpoints (default: none, no TLS)",
        metavar="DIR",
    )
    config: str | None = _opt(None, "--zenoh-config", ZENOH_CONFIG_HELP, argtypes.readable_file, metavar="FILE")
    stall_limit: float = _opt(STALL_LIMIT_S, "--stall-limit", STALL_LIMIT_HELP, argtypes.stall_limit, metavar="S")

    @property
    def resolved_run_id(self) -> str:
        return _resolve_run_id(self.run_id)


_CLOCK_CHOICES = ("lockstep", "realtime")
_SIGNALS_CHOICES = ("paper", "worst")
_VARIANT_CHOICES = ("scheduled", "per-rule")
_VARIANT_HELP = "estimator: one SDP with the scheduled model, or one per T-S rule"


# ---------------------------------------------------------------- the roles


@dataclass(frozen=True)
class VehicleSpec(RoleSpec):
    """``netsetest vehicle``: the truth and the measurements, the lockstep clock."""

    ROLE: ClassVar[str] = "vehicle"
    HELP: ClassVar[str] = "the vehicle process (truth, measurements) of a Zenoh run"

    scenario: ScenarioSpec = _group(ScenarioSpec, None, required=True)
    signals: SignalKind = _opt("paper", "--signals", "noise and wind: the paper's, or held at ±bound", choices=_SIGNALS_CHOICES)
    seed: int = _opt(0, "--seed", "random seed of noise, wind and losses", argtypes.seed)
    clock: Clock = _opt("lockstep", "--clock", "lockstep: wait for every node; realtime: one step every τs", choices=_CLOCK_CHOICES)
    node_timeout: float = _opt(NODE_TIMEOUT_S, "--node-timeout", "lockstep: a node silent this long [s] is declared dead", argtypes.seconds, metavar="S")
    pace: float = _opt(0.0, "--pace", "lockstep: at least S seconds per step", argtypes.non_negative_seconds, metavar="S")
    start_timeout: float = _opt(
        START_TIMEOUT_S, "--start-timeout", f"how long [s] to wait for every role to be ready (default: {START_TIMEOUT_S:g})", argtypes.seconds, metavar="S"
    )
    quiet: bool = _opt(False, "--quiet", "no line on success (errors are still logged)", switch=True)
    await_rejoin: tuple[tuple[int, int], ...] = _opt(
        (),
        "--await-rejoin",
        "lockstep: before step STEP+1 wait (at most --node-timeout) for node NODE to come back (repeatable; default: none)",
        argtypes.node_at,
        _show_at,
        metavar="NODE@STEP",
        many=True,
    )
    ack_window: int | None = _opt(ACK_WINDOW, "--ack-window", ACK_WINDOW_HELP, argtypes.ack_window, show_window, metavar="N")  # roles/flow.py
    zenoh: ZenohSpec = _group(ZenohSpec, "zenoh")


@dataclass(frozen=True)
class NodeSpec(RoleSpec):
    """``netsetest node``: one sensing node and its estimator."""

    ROLE: ClassVar[str] = "node"
    HELP: ClassVar[str] = "one sensing-node process of a Zenoh run"

    scenario: ScenarioSpec = _group(ScenarioSpec, None, required=True)
    id: int = _opt(MISSING, "--id", "node id in the topology", int)
    variant: Variant = _opt("scheduled", "--variant", _VARIANT_HELP, choices=_VARIANT_CHOICES)
    objective: Objective = _opt(DEFAULT_OBJECTIVE, "--objective", OBJECTIVE_HELP, choices=OBJECTIVES)
    clock: Clock = _opt("lockstep", "--clock", "lockstep: wait for neighbours; realtime: step on the vehicle's input", choices=_CLOCK_CHOICES)
    neighbour_timeout: float = _opt(
        NEIGHBOUR_TIMEOUT_S, "--neighbour-timeout", "lockstep: how long [s] to wait for a neighbour's message", argtypes.seconds, metavar="S"
    )
    rejoin: bool = _opt(False, "--rejoin", "join a running network (after a crash or restart)", switch=True)
    crash_after: int | None = _opt(None, "--crash-after", "SIGKILL itself right after publishing step STEP (run --kill; default: never)", int, metavar="STEP")
    profile: str | None = _opt(None, "--profile", PROFILE_HELP, argtypes.writable_dir, metavar="DIR")  # netsetest/profile.py
    zenoh: ZenohSpec = _group(ZenohSpec, "zenoh")


@dataclass(frozen=True)
class CollectorSpec(RoleSpec):
    """``netsetest collector``: judges every published set, writes the record and the summary.  ``channel_fd``:
    where it reports progress and the summary to the launcher (runtime/channel.py)."""

    ROLE: ClassVar[str] = "collector"
    HELP: ClassVar[str] = "the collector process: checks containment, writes record and summary"

    scenario: ScenarioSpec = _group(ScenarioSpec, None, required=True)
    signals: SignalKind = _opt("paper", "--signals", "the run's noise and wind (recorded in the summary)", choices=_SIGNALS_CHOICES)
    variant: Variant = _opt("scheduled", "--variant", "the nodes' estimator variant (recorded in the summary)", choices=_VARIANT_CHOICES)
    objective: Objective = _opt(DEFAULT_OBJECTIVE, "--objective", "the nodes' objective (recorded in the summary)", choices=OBJECTIVES)
    seed: int | None = _opt(None, "--seed", "the run's random seed (recorded in the summary; default: none)", argtypes.seed)
    clock: Clock = _opt("lockstep", "--clock", "the run's clock (recorded in the summary)", choices=_CLOCK_CHOICES)
    record: str | None = _opt(None, "--record", "write the run record (.json, .json.gz or .mcap; default: none)", metavar="PATH")
    summary_json: str | None = _opt(None, "--summary-json", "write the summary as JSON (default: none)", metavar="PATH")
    channel_fd: int | None = _opt(
        None,
        "--channel-fd",
        "report progress and the summary to the parent process on this inherited file "
        "descriptor (runtime/channel.py; `netsetest run`) instead of printing the table (default: none)",
        int,
        metavar="FD",
    )
    idle_timeout: float = _opt(COLLECTOR_IDLE_TIMEOUT_S, "--idle-timeout", "give up when no message arrives for S seconds", argtypes.seconds, metavar="S")
    zenoh: ZenohSpec = _group(ZenohSpec, "zenoh")


@dataclass(frozen=True)
class RouterSpec(RoleSpec):
    """``netsetest router``: a Zenoh router (with ``credentials``: mTLS and the run's access control)."""

    ROLE: ClassVar[str] = "router"
    HELP: ClassVar[str] = "a Zenoh router in Python (for client-mode roles on several hosts)"

    topology: str | None = _opt(None, None, topology_help("the topology whose access-control rules the router enforces (with --credentials)"), optional=True)
    credentials: str | None = _opt(
        None, "--credentials", "mTLS with DIR/router.pem and the run's access-control rules (default: none, open router)", metavar="DIR"
    )
    listen: tuple[str, ...] = _opt(
        (),
        "--listen",
        f"endpoint to listen on (repeatable; default: tcp/0.0.0.0:{ZENOH_DEFAULT_PORT}, or tls/0.0.0.0:{ZENOH_DEFAULT_PORT} with --credentials)",
        argtypes.endpoint,
        metavar="ENDPOINT",
        many=True,
    )
    connect: tuple[str, ...] = _opt(
        (),
        "--connect",
        "another router of the run to connect to, e.g. tls/10.0.0.1:7447: a run spanning hosts, a router on each (repeatable; default: none)",
        argtypes.endpoint,
        metavar="ENDPOINT",
        many=True,
    )
    run_id: str | None = _opt(None, "--run-id", f"the run whose keys the access control grants (default: ${RUN_ID_ENV} or '{DEFAULT_RUN_ID}')", argtypes.run_id)
    zenoh_config: str | None = _opt(None, "--zenoh-config", ZENOH_CONFIG_HELP, argtypes.readable_file, metavar="FILE")
    stall_limit: float = _opt(STALL_LIMIT_S, "--stall-limit", "the Zenoh lease it announces: the run's --stall-limit [s]", argtypes.stall_limit, metavar="S")

    @property
    def resolved_run_id(self) -> str:
        return _resolve_run_id(self.run_id)

    @property
    def endpoints(self) -> list[str]:
        """Where it listens: ``listen``, else the default port on every interface (tls/ with credentials)."""
        return list(self.listen) or [f"{'tls' if self.credentials else 'tcp'}/0.0.0.0:{ZENOH_DEFAULT_PORT}"]


ROLE_SPECS: tuple[type[RoleSpec], ...] = (VehicleSpec, NodeSpec, CollectorSpec, RouterSpec)
