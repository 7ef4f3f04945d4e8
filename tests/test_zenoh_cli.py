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
