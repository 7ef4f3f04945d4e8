"""Attacks on a run as users start it: ``netsetest run`` (the launcher, forked roles), secured by default
(mTLS + access control at the run's router) or ``--insecure`` (the open peer mesh), attacked from a
process of its own.

- ``flood``: the attacker publishes at ``rate`` messages per second on one key — node 2's input key, or
  node 2's state key — for the whole run; figures: the step rate against the same run without the flood,
  and whether every node is still there at the end.  Secured, the attacker holds node 2's certificate (an
  insider): the router's access control lets it publish on node 2's own keys only, so its input-key flood
  never reaches a role.  The payload is an input of node 2 with NaN values (invalid: it once filled the
  node's inbox and lost the node for the whole run) or a schema-valid state of a far step (``state``), or
  forged states of node 2 for every step of the run in turn (``state-run``: the copies the collector must
  reject beside node 2's own, its inbox full of them).
- ``crash``: the insider sends the payloads that once crashed every role that received them (a msgpack
  string of invalid UTF-8, an array nested 1000 deep, a schema-valid ``Ready`` of another node on its own
  ready key, a huge finite number where a square is taken), on node 2's own keys; figure: how many roles
  were lost (exit code 0 and no node missing: 0).

The attacker (``python -m netsetest_bench.attacks``) is a Zenoh client of the run's router with node 2's
identity (secured) or a peer of the mesh that joins through the collector's endpoint (insecure); every
message it sends goes to loopback only, and it stops after ``duration`` seconds.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

ATTACKER = "node-2"  # the insider: the certificate the attacker holds in a secured run
VICTIM = 2
BATCH_S = 0.01  # the attacker publishes a batch every 10 ms
SECURED_LINE = re.compile(r"security: mtls\+acl \(.*router (tls/127\.0\.0\.1:\d+); credentials in (\S+)\)")
INSECURE_LINE = re.compile(r"watch it with: netsetest watch --run-id \S+ --connect (\S+)")
RUN_TIMEOUT_S = 300.0
PY = [sys.executable, "-m", "netsetest"]


@dataclass(frozen=True)
class AttackedRun:
    """What an attacked ``netsetest run`` gave (runtime/inmemory.py's ``RunResult`` is an in-memory run's)."""

    exit_code: int | None
    wall_s: float
    steps_per_s: float
    nodes_missing: list[int]
    drops: dict
    sent: int
    summary: dict  # the run's --summary-json ({} if it wrote none)


def _payloads(kind: str, run_id: str, steps: int) -> list[tuple[str, bytes]]:
    """(key, payload) pairs the attacker cycles through."""
    import msgspec  # a default dependency (the bench must not need the dev extra's msgpack)

    from netsetest.bus import keys
    from netsetest.messages import SCHEMA_VERSION, NodeState, Ready, encode
    from netsetest.proven import ProvenSet

    UNIT_SET = ProvenSet(xhat=[0.0] * 3, P=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], rho=1.0)  # a forged state's set: the unit ball

    if kind == "input":
        raw = {"v": SCHEMA_VERSION, "type": "input", "step": 1, "node": VICTIM, "y": math.nan, "gamma": 1.0}
        return [(keys.node_input(run_id, VICTIM), msgspec.msgpack.encode(raw))]
    if kind in ("state", "state-run"):  # a far step's state, or one (forged, not from the true input) per step of the run
        forged = [
            NodeState(step=k, node=VICTIM, published=UNIT_SET, gamma=1.0, innov=0.0, status="ok")
            for k in ([steps + 5] if kind == "state" else range(1, steps + 1))
        ]
        return [(keys.node_state(run_id, VICTIM), encode(st)) for st in forged]
    if kind == "crash":
        own = keys.node_state(run_id, VICTIM)
        ready = keys.ready_of(run_id, keys.role_name("node", VICTIM))
        huge = {
            "v": SCHEMA_VERSION,
            "type": "state",
            "step": 1,
            "node": VICTIM,
            "published": {"xhat": [1.8e154, 0.0, 0.0], "P": [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], "rho": 1.0},
            "gamma": 1.0,
            "innov": 1.8e154,
            "status": "ok",
        }
        return [
            (own, b"\xa1\xbe"),
            (own, b"\x91" * 1000 + b"\xc0"),
            (ready, encode(Ready(role="node", node=VICTIM + 1, seen_all=True))),
            (own, msgspec.msgpack.encode(huge)),
            (keys.end(run_id), b"\xa1\xbe"),
        ]
    raise ValueError(f"unknown attack {kind!r}")


def attacker_main(argv: list[str] | None = None) -> int:
    """The attacking process: publish the payloads of ``--kind`` at ``--rate`` for ``--duration`` s."""
    from netsetest.bus.zenoh_bus import open_session, zenoh_config

    p = argparse.ArgumentParser(prog="netsetest_bench.attacks")
    p.add_argument("--kind", choices=["input", "state", "state-run", "crash"], required=True)
    p.add_argument("--run-id", required=True)
    p.add_argument("--steps", type=int, required=True)
    p.add_argument("--rate", type=float, required=True)
    p.add_argument("--duration", type=float, required=True)
    p.add_argument("--connect", required=True)
    p.add_argument("--credentials")
    a = p.parse_args(argv)
    if a.credentials:
        from netsetest.runtime.security import client_settings, identity

        cfg = zenoh_config("client", connect=[a.connect], settings=client_settings(identity(a.credentials, ATTACKER)))
    else:
        cfg = zenoh_config("peer", connect=[a.connect])
    session = open_session(cfg, "attacker session")
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda signum, frame: stop.set())  # the run is over: report and close
    sent = 0
    try:
        payloads = _payloads(a.kind, a.run_id, a.steps)
        pubs = {key: session.declare_publisher(key) for key, _ in payloads}
        per_batch = max(1, int(a.rate * BATCH_S))
        end = time.monotonic() + a.duration
        next_t = time.monotonic()
        while time.monotonic() < end and not stop.is_set():
            for n in range(per_batch):
                key, payload = payloads[(sent + n) % len(payloads)]
                pubs[key].put(payload)
            sent += per_batch
            next_t += BATCH_S
            time.sleep(max(0.0, next_t - time.monotonic()))
        for pub in pubs.values():
            pub.undeclare()
    finally:
        session.close()
    print(json.dumps({"sent": sent}), flush=True)
    return 0


def attacked_run(topology: Path, steps: int, secured: bool, kind: str | None, rate: float, pace: float, clock: str = "lockstep") -> AttackedRun:
    """``netsetest run`` (paced so the attack overlaps the whole run; ``clock`` its clock), attacked by ``kind`` (None: not)."""
    with tempfile.TemporaryDirectory(prefix="nsattack-") as tmpd:
        summary = Path(tmpd) / "summary.json"
        run_id = f"attack{int(time.time() * 1000) % 10**9}"
        argv = [
            *PY,
            "run",
            str(topology),
            "--steps",
            str(steps),
            "--seed",
            "0",
            "--pace",
            str(pace),
            "--run-id",
            run_id,
            "--summary-json",
            str(summary),
            "--clock",
            clock,
            *([] if secured else ["--insecure"]),
        ]
        t0 = time.perf_counter()
        parent = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        found: list[tuple[str, str | None]] = []
        attacker: list[subprocess.Popen] = []

        def follow() -> None:
            assert parent.stderr is not None
            for line in parent.stderr:
                m = SECURED_LINE.search(line) if secured else INSECURE_LINE.search(line)
                if m and not found:
                    found.append((m.group(1), m.group(2) if secured else None))
                    if kind is not None:
                        attacker.append(
                            subprocess.Popen(
                                [
                                    sys.executable,
                                    "-m",
                                    "netsetest_bench.attacks",
                                    "--kind",
                                    kind,
                                    "--run-id",
                                    run_id,
                                    "--steps",
                                    str(steps),
                                    "--rate",
                                    str(rate),
                                    "--duration",
                                    str(steps * pace + 30),
                                    "--connect",
                                    m.group(1),
                                    *(["--credentials", m.group(2)] if secured else []),
                                ],
                                stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL,
                                text=True,
                            )
                        )

        reader = threading.Thread(target=follow, daemon=True)
        reader.start()
        try:
            code: int | None = parent.wait(RUN_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            parent.kill()
            code = None
        wall = time.perf_counter() - t0
        reader.join(5)
        sent = 0
        for a in attacker:
            a.terminate()
            try:
                out, _ = a.communicate(timeout=10)
                sent = json.loads(out.strip().splitlines()[-1])["sent"] if out.strip() else 0
            except (subprocess.TimeoutExpired, ValueError, KeyError, IndexError):
                a.kill()
        s = json.loads(summary.read_text()) if summary.exists() else {}
        return AttackedRun(code, wall, steps / wall, s.get("nodes_missing", []), s.get("drops", {}), sent, s)


def flood(topology: Path, steps: int, rate: float, target: str, secured: bool, pace: float = 0.0) -> dict:
    """The run's step rate with the flood against without; every node still present."""
    base = attacked_run(topology, steps, secured, None, rate, pace)
    hit = attacked_run(topology, steps, secured, target, rate, pace)
    return {
        "target": target,
        "secured": secured,
        "rate": rate,
        "steps": steps,
        "ratio": hit.steps_per_s / base.steps_per_s,
        "sent_per_s": hit.sent / hit.wall_s if hit.wall_s else 0.0,
        "nodes_lost": len(hit.nodes_missing),
        "exit_code": hit.exit_code,
        "base_exit_code": base.exit_code,
        "drops": hit.drops,
    }


def crash(topology: Path, steps: int, secured: bool, pace: float) -> dict:
    """The insider's crash payloads during a paced run: roles lost (0 when the run ends with exit 0 and no
    node missing)."""
    r = attacked_run(topology, steps, secured, "crash", 200.0, pace)
    return {
        "secured": secured,
        "exit_code": r.exit_code,
        "nodes_missing": r.nodes_missing,
        "sent": r.sent,
        "roles_lost": 0 if r.exit_code == 0 and not r.nodes_missing else None,
        "drops": r.drops,
    }


if __name__ == "__main__":
    raise SystemExit(attacker_main())
