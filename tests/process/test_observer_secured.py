"""Watching a secured run: the run's credentials hold a read-only ``observer`` certificate.

`netsetest run` (mTLS + access control by default) prints ``watch it with: netsetest watch --credentials
DIR``; with that directory `echo` and `watch` connect to the run's router as the observer, which the
router lets receive every key of the run and publish none.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import pytest
import zenoh
from zenoh_helpers import PAPER6, ProcessGuard, cli, start_parent, wait_for

from netsetest.bus import keys
from netsetest.bus.zenoh_bus import zenoh_config
from netsetest.config.schema import load_topology
from netsetest.messages import End, encode
from netsetest.runtime.security import OBSERVER, acl_config, client_settings, observer_access

SECURED_HINT = re.compile(r"run id (\S+); watch it with: netsetest watch --credentials (\S+)")
STEPS = 60


def test_observer_grant_receives_the_run_and_publishes_nothing() -> None:
    acl = acl_config(load_topology(PAPER6), "r1")
    rules = {r["id"]: r for r in acl["rules"]}
    policy = next(p for p in acl["policies"] if p["subjects"] == [OBSERVER])
    assert not any(rules[r]["messages"] == ["put"] and rules[r]["flows"] == ["ingress"] for r in policy["rules"])
    assert rules[f"{OBSERVER}-receive"]["key_exprs"] == [keys.run_root("r1")]


@pytest.mark.zenoh
@pytest.mark.timeout(240)
def test_echo_and_watch_follow_a_secured_run_and_cannot_publish(procs: ProcessGuard, tmp_path: Path) -> None:
    summary = tmp_path / "summary.json"
    parent = start_parent(procs, "secured", [PAPER6, "--steps", str(STEPS), "--pace", "0.1", "--summary-json", str(summary)])
    run, creds = wait_for(lambda: SECURED_HINT.search(procs.stderr("secured")), 90, what="the watch hint").groups()
    access = observer_access(creds)
    assert access.run_id == run and access.connect

    echo = procs.start("echo", cli("echo", "node/1/state", "--credentials", creds, "--json", "--count", "3", "--duration", "90"), stdout=True)
    watch = procs.start("watch", cli("watch", "--credentials", creds, "--duration", "150"), stdout=True)
    ends = procs.start("ends", cli("echo", "control/end", "--credentials", creds, "--json", "--count", "1", "--duration", "150"), stdout=True)

    # the observer's certificate connects, but the router drops what it publishes: a forged End changes nothing
    cfg = zenoh_config("client", (), list(access.connect), settings=client_settings(access.identity))
    with zenoh.open(cfg) as forger:
        time.sleep(1.0)
        for _ in range(5):
            forger.put(keys.end(run), encode(End(steps=3)))
            time.sleep(0.2)

    out, _ = echo.communicate(timeout=120)
    assert echo.returncode == 0, procs.logs()
    states = [json.loads(line) for line in out.decode().splitlines()]
    assert len(states) == 3 and all(s["key"] == keys.node_state(run, 1) for s in states), out

    assert parent.wait(timeout=180) == 0, procs.logs()
    oute, _ = ends.communicate(timeout=60)
    assert ends.returncode == 0, procs.logs()
    assert [json.loads(line)["steps"] for line in oute.decode().splitlines()] == [STEPS]  # only the vehicle's End
    outw, _ = watch.communicate(timeout=60)
    assert watch.returncode == 0, procs.logs()
    assert f"ended after {STEPS} steps" in outw.decode(), outw.decode()[-2000:]
    assert json.loads(summary.read_text())["steps"] == STEPS  # the forged End did not cut the run


@pytest.mark.zenoh
def test_credentials_errors_are_one_line_exit_2(procs: ProcessGuard, tmp_path: Path) -> None:
    for name, args, why in [
        ("missing", ["--credentials", str(tmp_path / "none")], "no ca.pem"),
    ]:
        procs.start(name, cli("echo", *args, "--duration", "5"))
        assert procs.wait(name, 30) == 2, procs.logs()
        err = procs.stderr(name)
        assert why in err and "Traceback" not in err, err
