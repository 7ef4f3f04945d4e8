"""Zenoh-side option values are checked before anything starts: exit 2 and one line naming the option."""

from __future__ import annotations

import subprocess

import pytest
from zenoh_helpers import EXIT_BAD_INPUT, PAPER6, ROOT, cli

BAD = [
    (["run", PAPER6, "--pace", "nan"], "--pace"),
    (["run", PAPER6, "--pace", "inf"], "--pace"),
    (["run", PAPER6, "--node-timeout", "nan"], "--node-timeout"),
    (["run", PAPER6, "--neighbour-timeout", "inf"], "--neighbour-timeout"),
    (["run", PAPER6, "--neighbour-timeout", "-1"], "--neighbour-timeout"),
    (["run", PAPER6, "--zenoh-config", "/nonexistent.json5"], "--zenoh-config"),
    (["router", "--listen", "tcp/300.1.2.3:99999"], "--listen"),
    (["router", "--listen", "nonsense"], "--listen"),
    (["router", "--credentials", "/nonexistent"], "--credentials needs the TOPOLOGY"),
    (["router", "--zenoh-config", "pyproject.toml"], "--zenoh-config"),
    (["run", PAPER6, "--zenoh-config", "pyproject.toml"], "--zenoh-config"),
    (["vehicle", PAPER6, "--run-id", "a/b*"], "--run-id"),
    (["node", PAPER6, "--id", "1", "--connect", "tcp/127.0.0.1"], "--connect"),
    (["collector", PAPER6, "--listen", "tcp//x:1"], "--listen"),
    (["credentials", "/tmp/x", PAPER6, "--run-id", "a b"], "--run-id"),
    (["credentials", "/tmp/x", PAPER6, "--days", "0"], "--days"),
]


@pytest.mark.parametrize("argv, option", BAD, ids=[" ".join(a[:1] + a[2:]) for a, _ in BAD])
def test_bad_zenoh_option_exits_2_naming_it(argv: list[str], option: str) -> None:
    out = subprocess.run(cli(*argv), cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == EXIT_BAD_INPUT, out.stderr
    assert option in out.stderr and "Traceback" not in out.stderr, out.stderr
    assert "security:" not in out.stderr and "listening on" not in out.stderr, "started before the options were checked"


def test_router_port_in_use_exits_2() -> None:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        out = subprocess.run(cli("router", "--listen", f"tcp/127.0.0.1:{port}"), cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == EXIT_BAD_INPUT, out.stderr
    assert "--listen" in out.stderr and "Traceback" not in out.stderr


@pytest.mark.zenoh
@pytest.mark.timeout(120)
def test_run_with_a_user_zenoh_config_stays_secured(tmp_path) -> None:
    """--zenoh-config is the base of every role's and the router's configuration; security goes on top."""
    import json

    cfg = tmp_path / "zenoh.json5"
    cfg.write_text("// a user's tuning\n{ transport: { unicast: { max_links: 2 } } }\n")
    summary = tmp_path / "summary.json"
    out = subprocess.run(
        cli("run", PAPER6, "--steps", "5", "--quiet", "--zenoh-config", str(cfg), "--summary-json", str(summary)),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=110,
    )
    assert out.returncode == 0, out.stderr
    s = json.loads(summary.read_text())
    assert s["security"] == "mtls+acl" and s["steps_completed"] == 5 and s["violations_total"] == 0
    last = out.stdout.rstrip().splitlines()[-1]  # the run, its security mode and the coverage verdict
    n = s["node_steps_evaluated"]
    assert n == s["node_steps_contained"] == s["node_steps_covered"] > 0
    assert "(security: mtls+acl)" in last and f"contained on {n} of {n} node-steps; the guarantee applied on {n}" in last, last
