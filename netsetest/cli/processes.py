"""CLI of the Zenoh runtime: the role processes (vehicle, node, collector), ``run --mode zenoh``, router,
credentials, compose.  Each command parses its options and hands over to netsetest/runtime: ``run``
to the launcher (runtime/launcher.py), which starts and follows the role processes.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable

from netsetest.cli import checks
from netsetest.estimator.names import NODE_ESTIMATOR_NAMES
from netsetest.runtime import argtypes
from netsetest.runtime.report import EXIT_BAD_INPUT
from netsetest.roles.flow import ACK_WINDOW
from netsetest.runtime.rolespec import (
    ACK_WINDOW_HELP,
    ESTIMATOR_HELP,
    FAULT_SCALE_HELP,
    MANOEUVRE_HELP,
    PROFILE_HELP,
    SPEED_HELP,
    ROLE_SPECS,
    RUN_ID_ENV,
    STALL_LIMIT_HELP,
    ZENOH_CONFIG_HELP,
    CollectorSpec,
    NodeSpec,
    RouterSpec,
    VehicleSpec,
)
from netsetest.runtime.security import RUN_ENV_FILE
from netsetest.scenarios import topology_help
from netsetest.runtime.timeouts import NEIGHBOUR_TIMEOUT_S, NODE_TIMEOUT_S, STALL_LIMIT_S

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}
ROLE_COMMANDS: tuple[str, ...] = tuple(spec.ROLE for spec in ROLE_SPECS)  # a role process each (`run` starts them; a deployment by hand)
INTERNAL_COMMANDS = ("forkserver",)  # started by `run` alone: left out of `netsetest --help`


# ---------------------------------------------------------------- option groups


_at, _seconds, _non_negative = argtypes.node_at, argtypes.seconds, argtypes.non_negative_seconds
DEFAULT_VALIDITY_DAYS = 30


# the options only a Zenoh run has, with their defaults: `run --mode inmemory` refuses any other value
ZENOH_ONLY: dict[str, tuple[str, object]] = {
    "--node-timeout": ("node_timeout", NODE_TIMEOUT_S),
    "--neighbour-timeout": ("neighbour_timeout", NEIGHBOUR_TIMEOUT_S),
    "--pace": ("pace", 0.0),
    "--stall-limit": ("stall_limit", STALL_LIMIT_S),
    "--ack-window": ("ack_window", ACK_WINDOW),
    "--kill": ("kill", []),
    "--rejoin": ("rejoin", []),
    "--insecure": ("insecure", False),
    "--run-id": ("run_id", None),
    "--port": ("port", 0),
    "--zenoh-config": ("zenoh_config", None),
    "--view": ("view", False),
    "--view-port": ("view_port", 0),
    "--view-lag-json": ("view_lag_json", None),
    "--profile": ("profile", None),
}


def zenoh_options_given(a: argparse.Namespace) -> list[str]:
    """The Zenoh-only options set to something other than their default."""
    return [opt for opt, (dest, default) in ZENOH_ONLY.items() if getattr(a, dest) != default]


def add_run_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("zenoh mode")
    g.add_argument("--node-timeout", type=_seconds, default=NODE_TIMEOUT_S, metavar="S", help="lockstep: a node silent this long [s] is declared dead")
    g.add_argument(
        "--neighbour-timeout", type=_seconds, default=NEIGHBOUR_TIMEOUT_S, metavar="S", help="lockstep: how long [s] a node waits for a neighbour's message"
    )
    g.add_argument("--pace", type=_non_negative, default=0.0, metavar="S", help="lockstep: at least S seconds per step (default: 0, as fast as possible)")
    g.add_argument("--stall-limit", type=argtypes.stall_limit, default=STALL_LIMIT_S, metavar="S", help=STALL_LIMIT_HELP)
    g.add_argument("--ack-window", type=argtypes.ack_window, default=ACK_WINDOW, metavar="N", help=ACK_WINDOW_HELP)
    g.add_argument(
        "--kill", type=_at, action="append", default=[], metavar="NODE@STEP", help="SIGKILL node NODE once step STEP is checked (repeatable; default: none)"
    )
    g.add_argument(
        "--rejoin", type=_at, action="append", default=[], metavar="NODE@STEP", help="restart node NODE with --rejoin at step STEP (repeatable; default: none)"
    )
    g.add_argument(
        "--insecure",
        action="store_true",
        help="no credentials, no access control: an open peer mesh any local process can join (labelled in the summary; default: secured)",
    )
    g.add_argument("--run-id", type=checks.run_id, metavar="ID", help="the run's key-expression namespace (default: a fresh random one, printed)")
    g.add_argument(
        "--port",
        type=argtypes.port,
        default=0,
        metavar="N",
        help="the run's port on 127.0.0.1: its router's, or with --insecure its collector's, the endpoint echo, watch and view "
        "connect to (default: 0, a free one; the run prints how to watch it)",
    )
    g.add_argument("--zenoh-config", type=argtypes.readable_file, metavar="FILE", help=ZENOH_CONFIG_HELP)
    g.add_argument(
        "--view",
        action="store_true",
        help="a live view in Rerun's web viewer, served from this machine (`netsetest view` beside the run; extra view); its address is printed",
    )
    g.add_argument(
        "--view-port",
        type=argtypes.port,
        default=0,
        metavar="N",
        help="the live view's one port on 127.0.0.1, its page and its stream (default: 0, a free one; fix it to forward it with ssh -L)",
    )
    g.add_argument(
        "--view-lag-json",
        metavar="PATH",
        help="with --view: the view writes its lag behind a real-time run per step, and the frames it dropped, as JSON to PATH "
        "when it stops (the benchmark's measure; default: none)",
    )
    g.add_argument("--profile", type=argtypes.writable_dir, metavar="DIR", help=f"every node's --profile: {PROFILE_HELP}")


def scenario_overrides(p: argparse.ArgumentParser) -> None:
    """``run``'s overrides of the topology: the options of rolespec.ScenarioSpec, which every role is told."""
    p.add_argument("--estimator", choices=list(NODE_ESTIMATOR_NAMES), metavar="NAME", help=ESTIMATOR_HELP)
    p.add_argument("--manoeuvre", type=argtypes.drive, metavar="NAME[@AMP]", help=MANOEUVRE_HELP)
    p.add_argument("--speed", type=argtypes.speed_kmh, metavar="KMH", help=SPEED_HELP)
    p.add_argument("--fault-scale", type=argtypes.fault_scale, metavar="S", help=FAULT_SCALE_HELP)


def add_role_parsers(sub: argparse._SubParsersAction) -> None:
    for spec in ROLE_SPECS:  # one definition of each role's options: its spec (runtime/rolespec.py)
        spec.add_arguments(sub.add_parser(spec.ROLE, help=spec.HELP))

    p = sub.add_parser("credentials", help="write per-role mTLS credentials (CA, certificates, keys) and run.env for a deployment")
    p.add_argument("dir", help="output directory (created with mode 0700)")
    p.add_argument("topology", help=topology_help())
    p.add_argument("--run-id", type=checks.run_id, help="the deployment's run id (default: a random one)")
    p.add_argument(
        "--router-host",
        action="append",
        default=[],
        metavar="NAME",
        help="a name or address the router is reached at (repeatable; default: localhost, 127.0.0.1 and router, always included)",
    )
    p.add_argument("--days", type=checks.positive_int, default=DEFAULT_VALIDITY_DAYS, help="validity of the certificates in days")

    # internal, so without help: argparse lists a command only with one (`netsetest forkserver --help` still has its text)
    p = sub.add_parser("forkserver", description="internal: the fork server of `netsetest run` (imports once, forks each role process)")
    p.add_argument("--run-id", type=checks.run_id, required=True, help="the run it serves (in its command line and its children's, to find them)")
    p.add_argument("--control-fd", type=int, required=True, help="file descriptor of the launcher's control socket")

    p = sub.add_parser("compose", help="print a docker-compose.yml for a topology (router + one service per role)")
    p.add_argument("topology", help=topology_help())
    p.add_argument("--image", default="netsetest:latest", help="image with netsetest installed (built from the Dockerfile)")


# ---------------------------------------------------------------- role commands


def cmd_vehicle(a: argparse.Namespace) -> int:
    from netsetest.runtime.processes import vehicle_main

    return vehicle_main(VehicleSpec.from_namespace(a))


def cmd_node(a: argparse.Namespace) -> int:
    from netsetest.runtime.processes import node_main

    return node_main(NodeSpec.from_namespace(a))


def _open_fd(fd: int) -> bool:
    import os

    try:
        os.fstat(fd)
    except (OSError, OverflowError):
        return False
    return True


def cmd_collector(a: argparse.Namespace) -> int:
    from netsetest.runtime.processes import collector_main
    from netsetest.runtime.report import format_table

    spec = CollectorSpec.from_namespace(a)
    checks.record_file(spec.record, overwrite=True)  # before the run; the parent refused an existing file, the lock guards the rest
    checks.output_file(spec.summary_json, "--summary-json")
    if spec.channel_fd is not None and not _open_fd(spec.channel_fd):
        print(f"netsetest collector: --channel-fd {spec.channel_fd}: not an open file descriptor (the parent passes one)", file=sys.stderr)
        return EXIT_BAD_INPUT
    show = None if spec.channel_fd is not None else (lambda s: print(format_table(s), flush=True))
    return collector_main(spec, show)


def cmd_router(a: argparse.Namespace) -> int:
    from netsetest.bus.zenoh_bus import BusError
    from netsetest.config.schema import load_topology
    from netsetest.runtime.launcher import router_session
    from netsetest.runtime.processes import Stop, install_signal_handlers
    from netsetest.runtime.report import log
    from netsetest.runtime.security import ROUTER, CredentialsError, identity, router_settings

    spec = RouterSpec.from_namespace(a)
    security = None
    if spec.credentials:
        if not spec.topology:
            log("router", "--credentials needs the TOPOLOGY (the access-control rules are built from it)")
            return EXIT_BAD_INPUT
        try:
            security = router_settings(identity(spec.credentials, ROUTER), load_topology(spec.topology), spec.resolved_run_id)
        except CredentialsError as exc:
            log("router", f"--credentials: {exc}")
            return EXIT_BAD_INPUT
    listen = spec.endpoints
    install_signal_handlers()
    try:
        session = router_session(listen, spec.zenoh_config, security, spec.connect, spec.stall_limit)
    except BusError as exc:
        log("router", str(exc))
        return EXIT_BAD_INPUT
    log(
        "router",
        f"listening on {', '.join(listen)}"
        + (f"; connecting to {', '.join(spec.connect)}" if spec.connect else "")
        + (f"; mTLS and access control for run {spec.resolved_run_id}" if security else ""),
    )
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
    try:
        out = write_credentials(a.dir, role_names(sc), [*ROUTER_HOSTS, *a.router_host], datetime.timedelta(days=a.days))
        (out / RUN_ENV_FILE).write_text(f"{RUN_ID_ENV}={run_id}\n")
    except OSError as exc:
        print(f"netsetest credentials: {a.dir}: cannot write the credentials there ({exc.strerror or exc})", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"credentials for {len(role_names(sc))} roles, an observer (echo/watch) and the router in {out} (run id {run_id}, valid {a.days} days)")
    return 0


def cmd_compose(a: argparse.Namespace) -> int:
    from netsetest.runtime.compose import compose_yaml

    sys.stdout.write(compose_yaml(a.topology, a.image))
    return 0


COMMANDS.update(vehicle=cmd_vehicle, node=cmd_node, collector=cmd_collector, router=cmd_router, credentials=cmd_credentials, compose=cmd_compose)


# ---------------------------------------------------------------- run --mode zenoh: the parent


def cmd_run_zenoh(a: argparse.Namespace) -> int:
    from netsetest.runtime.launcher import LaunchError, LaunchOptions, launch, plan_run
    from netsetest.runtime.report import exit_code, format_table

    checks.output_file(a.view_lag_json, "--view-lag-json")
    opts = LaunchOptions(
        topology=a.topology,
        case=a.case,
        steps=a.steps,
        estimator=a.estimator,
        manoeuvre=a.manoeuvre,
        speed=a.speed,
        fault_scale=a.fault_scale,
        signals=a.signals,
        variant=a.variant,
        objective=a.objective,
        seed=a.seed,
        clock=a.clock,
        record=a.record,
        summary_json=a.summary_json,
        quiet=a.quiet,
        node_timeout=a.node_timeout,
        neighbour_timeout=a.neighbour_timeout,
        pace=a.pace,
        stall_limit=a.stall_limit,
        ack_window=a.ack_window,
        kill=tuple(a.kill),
        rejoin=tuple(a.rejoin),
        insecure=a.insecure,
        zenoh_config=a.zenoh_config,
        run_id=a.run_id,
        view=a.view,
        view_port=a.view_port,
        view_lag_json=a.view_lag_json,
        profile=a.profile,
        port=a.port,
        log=a.log,
        mapping=a.map,
    )
    if a.view:
        from netsetest.extras import require

        require("rerun", "--view")
    try:
        plan = plan_run(opts)
    except LaunchError as exc:
        print(f"netsetest run: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    outcome = launch(plan)
    if outcome.summary is not None:
        print(format_table(outcome.summary, a.strict))  # its last line names the security mode and the verdict
        # the collector exits with its summary's code; a role that failed after it keeps its own
        return exit_code(outcome.summary, a.strict) if outcome.exit_code == exit_code(outcome.summary) else outcome.exit_code
    return outcome.exit_code
