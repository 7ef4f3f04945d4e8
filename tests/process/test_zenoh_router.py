"""Client mode through a router (``netsetest router``), and the generated docker-compose.yml."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest
from zenoh_helpers import (
    PAPER6,
    ROOT,
    cli,
    free_ports,
    launch_clients,
    new_run_id,
    read_json,
    wait_for,
    wait_port,
    wait_roles,
)

pytestmark = pytest.mark.zenoh


@pytest.mark.timeout(120)
def test_zenoh_client_mode_through_router(procs, tmp_path) -> None:
    steps = 10
    (port,) = free_ports(1)
    router_ep = f"tcp/127.0.0.1:{port}"
    router = procs.start("router", cli("router", "--listen", router_ep))
    wait_port("127.0.0.1", port, 30)
    # the port opens inside zenoh.open(); the router logs the line just after it returns
    wait_for(lambda: f"listening on {router_ep}" in procs.stderr("router"), 10, what="the router's listening line")

    run_id = new_run_id()
    summary_path = tmp_path / "summary.json"
    launch_clients(procs, PAPER6, run_id, steps, summary_path, router_ep)
    codes = wait_roles(procs, 100)
    assert codes == {n: 0 for n in codes}, f"{codes}\n{procs.logs()}"

    s = read_json(summary_path)
    assert s["mode"] == "zenoh" and s["steps_completed"] == steps
    assert s["violations_total"] == 0 and s["nodes_missing"] == []
    for row in s["nodes"]:
        assert row["steps_reported"] == steps + 1 and row["violations"] == 0, row
        assert row["neighbour_messages_missing"] == 0, row

    # the router outlives its clients and stops cleanly on SIGTERM
    assert router.poll() is None
    router.send_signal(signal.SIGTERM)
    assert procs.wait("router", 10) == 0


@pytest.mark.timeout(60)
def test_zenoh_compose_matches_committed_file() -> None:
    out = subprocess.run(cli("compose", PAPER6), cwd=ROOT, capture_output=True, timeout=50)
    assert out.returncode == 0, out.stderr.decode()
    committed = (ROOT / "docker-compose.yml").read_bytes()
    assert out.stdout == committed, "docker-compose.yml is stale: regenerate it with `netsetest compose topologies/paper6.toml`"

    # pyyaml is not among the [dev] extras (pyproject.toml): skip the structural checks where it is missing
    yaml = pytest.importorskip("yaml", reason="pyyaml is needed to parse the compose file")
    doc = yaml.safe_load(out.stdout)
    services = doc["services"]
    nodes = [f"node{i}" for i in range(1, 7)]
    assert set(services) == {"router", "vehicle", "collector", *nodes}
    router = services["router"]
    assert router["command"][:2] == ["netsetest", "router"] and ("--credentials", "/credentials") in zip(router["command"], router["command"][1:])
    assert router["ports"] == ["127.0.0.1:7447:7447"], "the router must not be published on every interface"

    from netsetest.cli.main import build_parser
    from netsetest.runtime.rolespec import ROLE_SPECS

    for name in ["vehicle", "collector", *nodes]:
        svc = services[name]
        cmd = svc["command"]
        assert isinstance(cmd, list) and cmd[0] == "netsetest", (name, cmd)
        role = "node" if name.startswith("node") else name
        assert cmd[1] == role
        pairs = list(zip(cmd, cmd[1:]))
        assert ("--zenoh-mode", "client") in pairs, (name, cmd)
        assert ("--connect", "tls/router:7447") in pairs and ("--credentials", "/credentials") in pairs, (name, cmd)
        assert "router" in (svc.get("depends_on") or []), name
        assert "--run-id" not in cmd, "the run id comes from credentials/run.env, not from the committed file"
        assert svc["env_file"] == ["./credentials/run.env"] and "./credentials:/credentials:ro" in svc["volumes"], name
        # the command line is one netsetest accepts
        a = build_parser().parse_args(cmd[1:])
        spec = next(s for s in ROLE_SPECS if s.ROLE == role).from_namespace(a)
        assert a.command == role and spec.zenoh.mode == "client" and spec.zenoh.connect == ("tls/router:7447",)
        assert spec.scenario.topology == PAPER6
        if role == "node":
            assert spec.id == int(name.removeprefix("node")), (name, cmd)
            assert cmd.count("--id") == 1
        else:
            assert "--id" not in cmd
    # the collector writes its record and summary into the ./runs volume
    col = services["collector"]
    opts = dict(zip(col["command"], col["command"][1:]))
    assert opts["--summary-json"].startswith("/runs/") and opts["--record"].startswith("/runs/")
    assert "./runs:/runs" in col["volumes"]


def test_credentials_command_writes_run_env(tmp_path) -> None:
    import os
    import stat

    out = subprocess.run(cli("credentials", str(tmp_path / "c"), PAPER6), cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    d = tmp_path / "c"
    assert stat.S_IMODE(d.stat().st_mode) == 0o700
    (line,) = (d / "run.env").read_text().splitlines()
    name, run_id = line.split("=")
    assert name == "NETSETEST_RUN_ID" and run_id.startswith("run-") and len(run_id) == 20
    # a compose service gets run.env as its environment: --run-id defaults to it
    probe = "from netsetest.runtime.rolespec import VehicleSpec; print(VehicleSpec.from_argv(['vehicle', 'x.toml']).zenoh.resolved_run_id)"
    got = subprocess.run([sys.executable, "-c", probe], env={**os.environ, name: run_id}, capture_output=True, text=True, timeout=60)
    assert got.stdout.strip() == run_id, got.stderr
    for f in ("ca.pem", "router.pem", "vehicle.pem", "collector.pem", *(f"node-{i}.pem" for i in range(1, 7))):
        assert (d / f).is_file(), f
