"""``netsetest echo`` and ``watch``: decoded messages and the live per-node table of a running run."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import numpy as np
import pytest
from zenoh_helpers import (
    PAPER6,
    ProcessGuard,
    cli,
    free_ports,
    launch_peer_mesh,
    new_run_id,
    parent_run_id,
    start_parent,
    wait_for,
    wait_port,
    wait_roles,
)

from netsetest.bus.base import MemoryBus
from netsetest.cli.main import main
from netsetest.config.schema import load_topology
from netsetest.messages import encode
from netsetest.records.record import load_record
from netsetest.runtime.inmemory import run_inmemory
from netsetest.runtime.live import LiveTable, observed_key
from netsetest.runtime.report import EXIT_INTERRUPTED
from message_helpers import make_state

ROOT = Path(__file__).resolve().parents[2]
STEPS = 30


def _catches(pid: int, signum: int) -> bool:
    """Whether process ``pid`` has a handler for ``signum`` (SigCgt in /proc/PID/status)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    mask = int(next(ln.split()[1] for ln in status.splitlines() if ln.startswith("SigCgt:")), 16)
    return bool(mask >> (signum - 1) & 1)


def _listening_config(path: Path, port: int) -> str:
    """A Zenoh configuration file for an observer that listens (the roles connect to it at start-up)."""
    path.write_text(json.dumps({"mode": "peer", "listen": {"endpoints": [f"tcp/127.0.0.1:{port}"]}, "scouting": {"multicast": {"enabled": False}}}))
    return str(path)


@pytest.mark.zenoh
def test_echo_and_watch_on_a_live_run(procs: ProcessGuard, tmp_path: Path) -> None:
    run = new_run_id("echo")
    p_echo, p_watch = free_ports(2)
    # echo 1 and watch: configured by a file (as on a secured run), listening; the roles connect to them
    e1 = procs.start(
        "echo_cfg",
        cli(
            "echo",
            "node/2/state",
            "--run-id",
            run,
            "--json",
            "--count",
            str(STEPS + 1),
            "--duration",
            "120",
            "--zenoh-config",
            _listening_config(tmp_path / "echo.json5", p_echo),
        ),
        stdout=True,
    )
    w = procs.start(
        "watch", cli("watch", "--run-id", run, "--duration", "120", "--zenoh-config", _listening_config(tmp_path / "watch.json5", p_watch)), stdout=True
    )
    wait_port("127.0.0.1", p_echo, 30)
    wait_port("127.0.0.1", p_watch, 30)
    record, summary = tmp_path / "run.json", tmp_path / "summary.json"
    # echo 2: joins by --connect to an endpoint that is up before the run (echo 1's) and finds the roles by
    # gossip; the vehicle's keys. Connected to a role's endpoint instead, it raced the roles' start-up:
    # Zenoh retries a refused connection after a back-off, and a 30-step lockstep run can be over by then
    e2 = procs.start(
        "echo_connect", cli("echo", "vehicle/**", "--run-id", run, "--connect", f"tcp/127.0.0.1:{p_echo}", "--count", "20", "--duration", "120"), stdout=True
    )
    launch_peer_mesh(procs, PAPER6, run, STEPS, summary, record=record, also_connect=[f"tcp/127.0.0.1:{p_echo}", f"tcp/127.0.0.1:{p_watch}"])
    wait_roles(procs, 180)
    out1, _ = e1.communicate(timeout=60)
    out2, _ = e2.communicate(timeout=60)
    outw, _ = w.communicate(timeout=60)
    assert e1.returncode == 0 and e2.returncode == 0 and w.returncode == 0, procs.logs()
    rec = load_record(record)

    # echo 1: node 2's state of every step, decoded, equal to what the collector recorded
    lines = [json.loads(ln) for ln in out1.decode().splitlines()]
    assert [m["step"] for m in lines] == list(range(STEPS + 1)), procs.logs()
    for m in lines:
        assert m["key"] == f"netsetest/{run}/node/2/state" and m["type"] == "state" and m["node"] == 2
        entry = rec.raw_nodes["2"][m["step"]]
        assert m["published"] == entry["published"] and m.get("continues") == entry.get("continues")

    # echo 2: "key  {json}" lines of this run: the vehicle's inputs and truth
    lines2 = out2.decode().splitlines()
    assert len(lines2) == 20
    kinds = set()
    for ln in lines2:
        key, body = ln.split("  ", 1)
        assert key.startswith(f"netsetest/{run}/")
        kinds.add(json.loads(body)["type"])
    assert kinds == {"input", "truth"}, kinds

    # watch: ended with the run; the final table has every node at the last step with its fault bounds
    text = outw.decode()
    assert f"ended after {STEPS} steps" in text, text
    for i in range(1, 7):
        row = next(ln for ln in text.splitlines() if re.match(rf"^\W*{i}\W+{STEPS}\W", ln))
        lo, hi = rec.nodes[i].bounds(2)
        assert f"{lo[-1]:.4f}" in row and f"{hi[-1]:.4f}" in row, (row, lo[-1], hi[-1])


def test_live_table_matches_the_collector(tmp_path: Path) -> None:
    """The table ``watch`` shows, fed by the same messages the collector sees (in-memory bus)."""
    bus = MemoryBus()
    table = LiveTable()
    bus.subscribe(observed_key("mem", None), lambda key, msg: table.update(msg))
    sc = load_topology(ROOT / "topologies" / "paper6_lossy.toml", steps=12)
    res = run_inmemory(sc, bus=bus)
    assert table.ended is not None and table.ended.steps == 12
    rows = {r.id: r for r in table.sorted_rows()}
    assert sorted(rows) == sc.ids
    summary = {n.id: n for n in res.summary.nodes}
    for i, row in rows.items():
        entries = res.parts["nodes"][str(i)]
        last = entries[-1]
        assert row.step == last["step"] == 12 and row.status == last["status"]
        P = np.asarray(last["published"]["P"]).reshape(3, 3)
        half = np.sqrt(last["published"]["rho"] * P[2, 2])
        lo, hi = last["bounds"][2]  # the published fault interval: the ellipsoid's, cut by its fault range and region
        assert row.fault_lower == pytest.approx(lo, abs=1e-15) and row.fault_upper == pytest.approx(hi, abs=1e-15)
        assert last["published"]["xhat"][2] - half - 1e-12 <= lo <= hi <= last["published"]["xhat"][2] + half + 1e-12  # within the ellipsoid's
        assert row.E_step == 12 and row.E == pytest.approx(last["E"], rel=1e-12)
        assert row.missing == summary[i].neighbour_messages_missing == sum(len(e["missing"]) for e in entries)
        assert row.deadline_misses == 0 and row.dropped == 0
        assert row.lost == sum(1 for t in res.parts["truth"] for j, to in t["lost"] if to == i)
    assert sum(r.lost for r in rows.values()) == res.summary.losses_total > 0  # the lossy scenario


def test_live_table_without_truth_shows_no_E_and_stays_bounded() -> None:
    """An observer that may not see the truth (access control) shows no E and keeps few pending states."""
    table = LiveTable()
    P = [1.0, 0, 0, 0, 1.0, 0, 0, 0, 0.25]
    for k in range(500):
        table.update(
            make_state(
                step=k,
                node=1,
                xhat=[0.0, 0.0, 0.1],
                P=P,
                rho=1.0,
                gamma=1.0,
                innov=0.0,
                status="ok",
                missing=[2] if k % 2 else [],
                late=k % 5 == 0,
                dropped=k // 100,
            )
        )
    (row,) = table.sorted_rows()
    assert row.step == 499 and row.E is None and row.fault_lower == pytest.approx(-0.4) and row.fault_upper == pytest.approx(0.6)
    assert row.missing == 250 and row.deadline_misses == 100 and row.dropped == 4
    assert len(table.pending[1]) <= 51


def test_observed_keys() -> None:
    assert observed_key(None, None) == "netsetest/*/**"
    assert observed_key("r1", None) == "netsetest/r1/**"
    assert observed_key("r1", "node/3/state") == "netsetest/r1/node/3/state"
    assert observed_key("r1", "/vehicle/**") == "netsetest/r1/vehicle/**"
    assert observed_key("r1", "netsetest/r2/control/end") == "netsetest/r2/control/end"


@pytest.mark.parametrize(
    "args, msg",
    [
        (["--connect", "bogus"], None),  # argparse: its usage line and the reason, exit 2
        (["--connect", "tcp/1.2.3.4:99999"], None),  # a port out of range exited 0 silently
        (["--zenoh-config", "/nonexistent/zenoh.json5"], "file not found"),
        (["--zenoh-config", "{bad}"], "not a usable Zenoh configuration"),
        (["--duration", "0"], None),
    ],
)
@pytest.mark.parametrize("command", ["echo", "watch", "view"])
def test_bad_observer_options_exit_2(command: str, args: list[str], msg: str | None, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    if "{bad}" in args:
        bad = tmp_path / "bad.json5"
        bad.write_text('{mode: "peer", no_such_field: 1}')
        args = [str(bad) if a == "{bad}" else a for a in args]
    if msg is None:
        with pytest.raises(SystemExit) as exc:
            main([command, *args])
        assert exc.value.code == 2
        return
    t0 = time.monotonic()
    assert main([command, *args]) == 2
    err = capsys.readouterr().err
    assert msg in err and f"netsetest {command}" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert time.monotonic() - t0 < 10


@pytest.mark.zenoh
def test_observer_decodes_and_reports_undecodable_payloads(tmp_path: Path) -> None:
    """Samples from another session: a valid NodeState is decoded, garbage is reported, never repaired."""
    import zenoh

    from netsetest.bus.zenoh_bus import zenoh_config
    from netsetest.runtime.live import Observer, observer_config

    (port,) = free_ports(1)
    run = new_run_id("obs")
    cfg = observer_config("peer", [], _listening_config(tmp_path / "obs.json5", port))
    obs = Observer(observed_key(run, None), cfg)
    pub = zenoh.open(zenoh_config("peer", (), [f"tcp/127.0.0.1:{port}"]))
    msg = make_state(step=1, node=1, xhat=[0.0, 0.0, 0.1], P=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], rho=1.0, gamma=1.0, innov=0.0, status="ok")
    seen: dict[str, object] = {}
    try:
        deadline = time.monotonic() + 30
        while len(seen) < 2 and time.monotonic() < deadline:  # repeat until the subscription has propagated
            pub.put(f"netsetest/{run}/node/1/state", encode(msg))
            pub.put(f"netsetest/{run}/node/9/state", b"\x93garbage")
            got = obs.get(0.2)
            while got is not None:
                seen[got.key] = got
                got = obs.get(0.05)
    finally:
        pub.close()
        obs.close()
    good, bad = seen.get(f"netsetest/{run}/node/1/state"), seen.get(f"netsetest/{run}/node/9/state")
    assert good is not None and bad is not None, seen
    assert good.message == msg and good.as_json()["published"]["xhat"] == [0.0, 0.0, 0.1]
    assert bad.message is None and bad.as_json() == {"key": f"netsetest/{run}/node/9/state", "undecodable": bad.error}
    assert bad.error.startswith(("not-a-map", "undecodable"))


@pytest.mark.zenoh
@pytest.mark.parametrize("command", ["echo", "watch", "view"])
@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_observer_stops_cleanly_on_signal(command: str, sig: str, procs: ProcessGuard) -> None:
    import signal as _signal

    (port,) = free_ports(1)
    p = procs.start(command, cli(command, "--run-id", new_run_id("sig"), "--connect", f"tcp/127.0.0.1:{port}"), stdout=True)
    # the observer catches SIGTERM from before its session opens (signal mask in /proc): a signal while it opens must also end it cleanly
    wait_for(lambda: _catches(p.pid, _signal.SIGTERM) or p.poll() is not None, 30, what=f"{command} to open its session")
    assert p.poll() is None, procs.logs()
    p.send_signal(getattr(_signal, sig))
    # the view serves until stopped, and says it was (130, as `run`); echo and watch end as asked (0)
    assert procs.wait(command, 15) == (EXIT_INTERRUPTED if command == "view" else 0), procs.logs()
    assert "Traceback" not in procs.stderr(command)


WATCH_HINT = re.compile(r"run id (\S+); watch it with: netsetest watch --run-id (\S+) --connect (\S+)")


@pytest.mark.zenoh
@pytest.mark.timeout(180)
def test_run_watch_hint_works_insecure(procs: ProcessGuard) -> None:
    """--insecure: the printed command's run id and endpoint reach the run (secured runs: test_observer_secured.py)."""
    parent = start_parent(procs, "insecure", [PAPER6, "--insecure", "--steps", "60", "--pace", "0.1"])
    hint = wait_for(lambda: WATCH_HINT.search(procs.stderr("insecure")), 60, what="the watch hint")
    run, watched, endpoint = hint.groups()
    assert watched == run == parent_run_id(parent)
    echo = procs.start("echo_hint", cli("echo", "node/1/state", "--run-id", run, "--connect", endpoint, "--count", "3", "--duration", "60"), stdout=True)
    out, _ = echo.communicate(timeout=90)
    assert echo.returncode == 0 and len(out.decode().splitlines()) == 3, procs.logs()
    assert parent.wait(timeout=120) == 0, procs.logs()


def _documented_insecure_example(doc: Path) -> list[list[str]]:
    """The README's (and docs/records.md's) ``--insecure`` example: its ``run`` line and the ``echo`` line after
    it, each as argv after ``netsetest`` (comments and the shell's ``&`` left out)."""
    lines = [line.split("#")[0].strip().removesuffix("&").split() for line in doc.read_text().splitlines()]
    runs = [n for n, w in enumerate(lines) if w[:2] == ["netsetest", "run"] and "--insecure" in w and "--port" in w]
    assert len(runs) == 1, f"{doc.name}: one --insecure run example with --port"
    run, echo = lines[runs[0]], lines[runs[0] + 1]
    assert echo[:2] == ["netsetest", "echo"], f"{doc.name}: the echo line follows the run"
    return [run[1:], echo[1:]]


@pytest.mark.zenoh
@pytest.mark.timeout(180)
def test_the_documented_insecure_example_hears_the_run(procs: ProcessGuard) -> None:
    """Issue 41 item 12: the README's ``echo … --connect tcp/127.0.0.1:7447`` heard nothing (the run listened on a
    random port).  The documented pair, run as written but on a free port and a run id of the test's (tests run
    side by side), and with --count so that echo ends: echo hears node 3's states."""
    run, echo = _documented_insecure_example(ROOT / "README.md")
    assert [run, echo] == _documented_insecure_example(ROOT / "docs" / "records.md")
    documented_port, documented_id = run[run.index("--port") + 1], run[run.index("--run-id") + 1]
    assert f"tcp/127.0.0.1:{documented_port}" in echo and documented_id in echo
    port, run_id = str(free_ports(1)[0]), new_run_id("doc")
    swap = {documented_port: port, documented_id: run_id, f"tcp/127.0.0.1:{documented_port}": f"tcp/127.0.0.1:{port}"}
    procs.markers.add(run_id)
    parent = procs.start("documented_run", cli(*(swap.get(w, w) for w in run)))
    heard = procs.start("documented_echo", cli(*(swap.get(w, w) for w in echo), "--count", "3", "--duration", "90"), stdout=True)
    out, _ = heard.communicate(timeout=120)
    lines = out.decode().splitlines()
    assert heard.returncode == 0 and len(lines) == 3, procs.logs()
    assert all(line.startswith(f"netsetest/{run_id}/node/3/state") for line in lines), lines
    assert parent.wait(timeout=120) == 0, procs.logs()


@pytest.mark.parametrize("command", ["echo", "watch", "view"])
def test_observer_that_hears_nothing_says_why(command: str) -> None:
    """echo/watch on a secured run without --credentials printed nothing and exited 0 (or waited for ever)."""
    import subprocess
    import sys as _sys

    p = subprocess.run([_sys.executable, "-m", "netsetest", command, "--duration", "4"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0
    assert f"netsetest {command}: nothing heard in 3 s" in p.stderr and "--credentials DIR" in p.stderr, p.stderr


LAG_STEPS = 30


@pytest.mark.timeout(300)
def test_run_view_hands_over_its_lag_behind_a_real_time_run(procs: ProcessGuard, tmp_path: Path) -> None:
    """``run --clock realtime --view --view-lag-json PATH``: the view writes one lag per step whose truth it
    drew and sent, each positive (a truth leaves the view after the vehicle published it: a view that dated a
    step by its deadline instead would show lags below 0 here); the bound on it is the benchmark's
    (netsetest_bench/view.py), a figure of the machine, not a test."""
    pytest.importorskip("rerun")
    lag = tmp_path / "lag.json"
    procs.start("run", cli("run", PAPER6, "--clock", "realtime", "--steps", str(LAG_STEPS), "--view", "--view-lag-json", str(lag), "--quiet"))
    assert procs.wait("run", 240) == 0, procs.logs()
    got = json.loads(lag.read_text())
    if got["dropped_frames"] == 0 and got["unsent"] == 0:  # nothing left out: every step's truth drawn and sent
        assert len(got["lags_s"]) == LAG_STEPS + 1
    assert 0 < len(got["lags_s"]) <= LAG_STEPS + 1 and min(got["lags_s"]) > 0
