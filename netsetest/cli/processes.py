"""CLI of the Zenoh runtime: the role processes (vehicle, node, collector), ``run --mode zenoh``, router,
credentials, compose.  Each command parses its options and hands over to netsetest/runtime: ``run``
to the launcher (runtime/launcher.py), which starts and follows the role processes.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections.abc import Callable

from netsetest.bus import keys
from netsetest.cli import checks
from netsetest.estimator.names import NODE_ESTIMATOR_NAMES
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, OBJECTIVE_HELP, OBJECTIVES
from netsetest.runtime.report import EXIT_BAD_INPUT
from netsetest.runtime.security import RUN_ENV_FILE, RUN_ID_ENV
from netsetest.runtime.timeouts import NEIGHBOUR_TIMEOUT_S, NODE_TIMEOUT_S, START_TIMEOUT_S

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}
ZENOH_DEFAULT_PORT = 7447


# ---------------------------------------------------------------- option groups


def _readable_file(s: str) -> str:
    if not os.path.isfile(s) or not os.access(s, os.R_OK):
        raise argparse.ArgumentTypeError(f"{s}: not a readable file")
    return s


def _zenoh_config_arg(g: argparse._ArgumentGroup) -> None:
    g.add_argument("--zenoh-config", type=_readable_file, metavar="FILE",
                   help="a Zenoh configuration (JSON5) to start from; netsetest sets mode, endpoints, scouting and security on top (default: none)")


def _zenoh_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("zenoh")
    g.add_argument("--run-id", type=checks.run_id, default=os.environ.get(RUN_ID_ENV, "default"),
                   help=f"key-expression namespace of the run (netsetest/<run-id>/...); default ${RUN_ID_ENV} or 'default'")
    g.add_argument("--zenoh-mode", choices=["peer", "client"], default="peer", help="peer (one host) or client of a router")
    g.add_argument("--listen", type=checks.endpoint, action="append", default=[], metavar="ENDPOINT",
                   help="endpoint to listen on, e.g. tcp/127.0.0.1:7450 (repeatable; default: none)")
    g.add_argument("--connect", type=checks.endpoint, action="append", default=[], metavar="ENDPOINT",
                   help="endpoint to connect to, e.g. tls/10.0.0.1:7447 (repeatable; default: none)")
    g.add_argument("--credentials", metavar="DIR",
                   help="mTLS: this role's certificate and key from DIR (`netsetest credentials`); connect on tls/ endpoints (default: none, no TLS)")
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


# the options only a Zenoh run has, with their defaults: `run --mode inmemory` refuses any other value
ZENOH_ONLY: dict[str, tuple[str, object]] = {
    "--node-timeout": ("node_timeout", NODE_TIMEOUT_S), "--neighbour-timeout": ("neighbour_timeout", NEIGHBOUR_TIMEOUT_S),
    "--pace": ("pace", 0.0), "--kill": ("kill", []), "--rejoin": ("rejoin", []), "--insecure": ("insecure", False),
    "--run-id": ("run_id", None), "--zenoh-config": ("zenoh_config", None),
}


def zenoh_options_given(a: argparse.Namespace) -> list[str]:
    """The Zenoh-only options set to something other than their default."""
    return [opt for opt, (dest, default) in ZENOH_ONLY.items() if getattr(a, dest) != default]


def add_run_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("zenoh mode")
    g.add_argument("--node-timeout", type=_seconds, default=NODE_TIMEOUT_S, metavar="S", help="lockstep: a node silent this long [s] is declared dead")
    g.add_argument("--neighbour-timeout", type=_seconds, default=NEIGHBOUR_TIMEOUT_S, metavar="S", help="lockstep: how long [s] a node waits for a neighbour's message")
    g.add_argument("--pace", type=_non_negative, default=0.0, metavar="S", help="lockstep: at least S seconds per step (default: 0, as fast as possible)")
    g.add_argument("--kill", type=_at, action="append", default=[], metavar="NODE@STEP", help="SIGKILL node NODE once step STEP is checked (repeatable; default: none)")
    g.add_argument("--rejoin", type=_at, action="append", default=[], metavar="NODE@STEP", help="restart node NODE with --rejoin at step STEP (repeatable; default: none)")
    g.add_argument("--insecure", action="store_true",
                   help="no credentials, no access control: an open peer mesh any local process can join (labelled in the summary; default: secured)")
    g.add_argument("--run-id", type=checks.run_id, metavar="ID", help="the run's key-expression namespace (default: a fresh random one, printed)")
    _zenoh_config_arg(g)


def estimator_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--estimator", choices=list(NODE_ESTIMATOR_NAMES), metavar="NAME",
                   help=f"every node's estimator, overriding the topology's per-node 'estimator' ({', '.join(NODE_ESTIMATOR_NAMES)}; default: the file's, else sdp)")


def add_role_parsers(sub: argparse._SubParsersAction, scenario_args: Callable, run_args: Callable) -> None:
    p = sub.add_parser("vehicle", help="the vehicle process (truth, measurements) of a Zenoh run")
    scenario_args(p)
    estimator_arg(p)
    p.add_argument("--signals", choices=["paper", "worst"], default="paper", help="noise and wind: the paper's, or held at ±bound")
    p.add_argument("--seed", type=checks.seed, default=0, help="random seed of noise, wind and losses")
    p.add_argument("--clock", choices=["lockstep", "realtime"], default="lockstep", help="lockstep: wait for every node; realtime: one step every τs")
    p.add_argument("--node-timeout", type=_seconds, default=NODE_TIMEOUT_S, metavar="S", help="lockstep: a node silent this long [s] is declared dead")
    p.add_argument("--pace", type=_non_negative, default=0.0, metavar="S", help="lockstep: at least S seconds per step")
    p.add_argument("--start-timeout", type=_seconds, default=START_TIMEOUT_S, metavar="S", help=f"how long [s] to wait for every role to be ready (default: {START_TIMEOUT_S:g})")
    p.add_argument("--quiet", action="store_true", help="no line on success (errors are still logged)")
    p.add_argument("--await-rejoin", type=_at, action="append", default=[], metavar="NODE@STEP",
                   help="lockstep: before step STEP+1 wait (at most --node-timeout) for node NODE to come back (repeatable; default: none)")
    _zenoh_args(p)

    p = sub.add_parser("node", help="one sensing-node process of a Zenoh run")
    scenario_args(p)
    estimator_arg(p)
    p.add_argument("--id", type=int, required=True, help="node id in the topology")
    p.add_argument("--variant", choices=["scheduled", "per-rule"], default="scheduled", help="estimator: one SDP with the scheduled model, or one per T-S rule")
    p.add_argument("--objective", choices=list(OBJECTIVES), default=DEFAULT_OBJECTIVE, help=OBJECTIVE_HELP)
    p.add_argument("--clock", choices=["lockstep", "realtime"], default="lockstep", help="lockstep: wait for neighbours; realtime: step on the vehicle's input")
    p.add_argument("--neighbour-timeout", type=_seconds, default=NEIGHBOUR_TIMEOUT_S, metavar="S", help="lockstep: how long [s] to wait for a neighbour's message")
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
    p.add_argument("--listen", type=checks.endpoint, action="append", default=[], metavar="ENDPOINT",
                   help=f"endpoint to listen on (repeatable; default: tcp/0.0.0.0:{ZENOH_DEFAULT_PORT}, or tls/0.0.0.0:{ZENOH_DEFAULT_PORT} with --credentials)")
    p.add_argument("--credentials", metavar="DIR", help="mTLS with DIR/router.pem and the run's access-control rules (default: none, open router)")
    p.add_argument("--run-id", type=checks.run_id, default=os.environ.get(RUN_ID_ENV, "default"), help=f"the run whose keys the access control grants (default: ${RUN_ID_ENV} or 'default')")
    _zenoh_config_arg(p)

    p = sub.add_parser("credentials", help="write per-role mTLS credentials (CA, certificates, keys) and run.env for a deployment")
    p.add_argument("dir", help="output directory (created with mode 0700)")
    p.add_argument("topology", help="topology file or bundled name, e.g. paper6")
    p.add_argument("--run-id", type=checks.run_id, help="the deployment's run id (default: a random one)")
    p.add_argument("--router-host", action="append", default=[], metavar="NAME",
                   help="a name or address the router is reached at (repeatable; default: localhost, 127.0.0.1 and router, always included)")
    p.add_argument("--days", type=checks.positive_int, default=DEFAULT_VALIDITY_DAYS, help="validity of the certificates in days")

    p = sub.add_parser("forkserver", help="internal: the fork server of `netsetest run` (imports once, forks each role process)")
    p.add_argument("--run-id", type=checks.run_id, required=True, help="the run it serves (in its command line and its children's, to find them)")
    p.add_argument("--control-fd", type=int, required=True, help="file descriptor of the launcher's control socket")

    p = sub.add_parser("compose", help="print a docker-compose.yml for a topology (router + one service per role)")
    p.add_argument("topology", help="topology file or bundled name, e.g. paper6")
    p.add_argument("--image", default="netsetest:latest", help="image with netsetest installed (built from the Dockerfile)")


# ---------------------------------------------------------------- role commands


def _open_bus(a: argparse.Namespace, name: str):
    from netsetest.bus.zenoh_bus import ZenohBus
    from netsetest.runtime.security import client_settings, identity

    settings = client_settings(identity(a.credentials, name)) if a.credentials else None
    return ZenohBus(a.zenoh_mode, a.listen, a.connect, base_file=a.zenoh_config, settings=settings)


def _role(name: str, who: str, a: argparse.Namespace, body: Callable) -> int:
    """Run a role process: ``name`` for its log lines, ``who`` its certificate name (keys.role_name)."""
    from netsetest.bus.zenoh_bus import BusError
    from netsetest.config.schema import load_topology
    from netsetest.runtime.processes import EXIT_STOPPED, Stop, install_signal_handlers, log, release_free_memory
    from netsetest.runtime.security import CredentialsError

    sc = load_topology(a.topology, a.case, a.steps, a.estimator)
    install_signal_handlers()
    release_free_memory()
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
        a.await_rejoin, a.quiet))


def cmd_node(a: argparse.Namespace) -> int:
    from netsetest.runtime.processes import run_node

    def body(sc, bus) -> int:
        sc.node(a.id)  # unknown id → ConfigError, exit 2
        return run_node(sc, a.id, bus, a.run_id, a.variant, a.clock == "realtime", a.neighbour_timeout, a.rejoin,
                        a.objective, a.crash_after)

    return _role(f"node {a.id}", keys.role_name("node", a.id), a, body)


def cmd_collector(a: argparse.Namespace) -> int:
    from netsetest.runtime.inmemory import run_meta
    from netsetest.runtime.processes import run_collector
    from netsetest.runtime.report import format_table
    from netsetest.runtime.security import SECURITY_INSECURE, SECURITY_MTLS

    checks.record_file(a.record, overwrite=True)  # before the run; the parent refused an existing file, the lock guards the rest
    checks.output_file(a.summary_json, "--summary-json")

    def body(sc, bus) -> int:
        meta = run_meta(sc, "zenoh", a.clock, a.signals, a.variant, a.seed, a.run_id, a.objective)
        meta["security"] = SECURITY_MTLS if a.credentials else SECURITY_INSECURE
        show = None if a.progress else (lambda s: print(format_table(s), flush=True))
        return run_collector(sc, bus, a.run_id, meta, a.record, a.summary_json, a.progress, a.idle_timeout, show)

    return _role("collector", keys.role_name("collector"), a, body)


def cmd_router(a: argparse.Namespace) -> int:
    from netsetest.bus.zenoh_bus import BusError
    from netsetest.config.schema import load_topology
    from netsetest.runtime.launcher import router_session
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


COMMANDS.update(vehicle=cmd_vehicle, node=cmd_node, collector=cmd_collector, router=cmd_router, credentials=cmd_credentials,
                compose=cmd_compose)


# ---------------------------------------------------------------- run --mode zenoh: the parent


def cmd_run_zenoh(a: argparse.Namespace) -> int:
    from netsetest.runtime.launcher import LaunchError, LaunchOptions, launch, plan_run
    from netsetest.runtime.report import format_table

    opts = LaunchOptions(
        topology=a.topology, case=a.case, steps=a.steps, estimator=a.estimator, signals=a.signals, variant=a.variant,
        objective=a.objective, seed=a.seed, clock=a.clock, record=a.record, summary_json=a.summary_json, quiet=a.quiet,
        node_timeout=a.node_timeout, neighbour_timeout=a.neighbour_timeout, pace=a.pace, kill=tuple(a.kill), rejoin=tuple(a.rejoin),
        insecure=a.insecure, zenoh_config=a.zenoh_config, run_id=a.run_id,
    )
    try:
        plan = plan_run(opts)
    except LaunchError as exc:
        print(f"netsetest run: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    outcome = launch(plan)
    if outcome.summary is not None:
        print(format_table(outcome.summary))  # its last line names the security mode and the verdict
    return outcome.exit_code
