"""The benchmark's flow-control figures (``netsetest bench --only flow``): a collector that falls behind
loses nothing, and what the lockstep window costs (roles/vehicle.py ``ACK_WINDOW``, issue 33).

- ``paused``: ``netsetest run paper6`` unpaced (lockstep), recording ``.jsonl.gz``, with its collector
  stopped (SIGSTOP) for a few seconds mid-run and then continued (SIGCONT): the exit code, the steps and
  node-steps judged and lost, the nodes reported missing or rejoined (all must be 0), the wall time.
- ``soak``: unpaced 3000-step paper6 runs, nothing paused, one after another on whatever else loads the
  machine (the soak that failed 2 of 2 before the window): exit code and node-steps lost per run.
- ``ratio``: the unpaced paper6 lockstep run over Zenoh against the same run in memory, interleaved,
  medians of three (what the performance part's ``zenoh.ratio`` measures, with the same functions), beside
  that part's committed figure measured before the window existed: the window's cost is their difference.
"""

from __future__ import annotations

import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

from netsetest.roles.vehicle import ACK_STRIDE, ACK_WINDOW
from netsetest.scenarios import TOPOLOGY_DIR

PAPER6 = TOPOLOGY_DIR / "paper6.toml"
UNDER_WAY_BYTES = 50_000  # the record (gzip) has grown this much: the run is under way, pause its collector now
COMMITTED_PERFORMANCE = Path(__file__).resolve().parents[2] / "bench" / "results.json"  # read, never written here


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _collector_of(run_id: str) -> int | None:
    """The pid of the run's collector (forked by the fork server: process name ns-collector, the run id in its argv)."""
    for entry in os.listdir("/proc"):
        try:
            argv = Path(f"/proc/{entry}/cmdline").read_bytes().split(b"\0")
            comm = Path(f"/proc/{entry}/comm").read_text().strip()
        except (OSError, ValueError):
            continue
        if comm == "ns-collector" and run_id.encode() in argv:
            return int(entry)
    return None


def paused_run(tmp: Path, steps: int, pause_s: float, timeout: float = 900.0, seed: int = 0) -> dict:
    """One unpaced paper6 run whose collector is stopped for ``pause_s`` once the run is under way (0: never)."""
    run_id = f"flow{os.getpid()}p{int(pause_s * 1000)}s{seed}"
    record, summary = tmp / f"{run_id}.jsonl.gz", tmp / f"{run_id}.json"
    cmd = [sys.executable, "-m", "netsetest.cli.main", "run", str(PAPER6), "--steps", str(steps), "--seed", str(seed), "--quiet"]
    cmd += ["--record", str(record), "--summary-json", str(summary), "--run-id", run_id]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    paused_at = None
    try:
        while pause_s > 0 and proc.poll() is None and paused_at is None:
            time.sleep(0.05)
            col = _collector_of(run_id)
            if col is not None and record.exists() and record.stat().st_size > UNDER_WAY_BYTES:
                os.kill(col, signal.SIGSTOP)
                paused_at = time.perf_counter() - t0
                time.sleep(pause_s)
                os.kill(col, signal.SIGCONT)
        code = proc.wait(timeout=timeout)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)  # its own session: the run and its roles only
            proc.wait()
    s = json.loads(summary.read_text()) if summary.exists() else {}
    expected = (steps + 1) * len(s.get("nodes", []))
    record.unlink(missing_ok=True)  # a 3000-step record is large: the temporary directory holds one at a time
    return {
        "steps": steps,
        "seed": seed,
        "load_before": os.getloadavg()[0],
        "pause_s": pause_s,
        "paused_at_s": paused_at,
        "exit_code": code,
        "wall_s": time.perf_counter() - t0,
        "steps_completed": s.get("steps_completed"),
        "node_steps_judged": s.get("node_steps_evaluated"),
        "node_steps_lost": expected - s.get("node_steps_evaluated", 0) if s else None,
        "nodes_missing": s.get("nodes_missing"),
        "nodes_rejoined": s.get("nodes_rejoined"),
        "collector_drops": s.get("drops", {}).get("collector", {}),
    }


def lockstep_ratio(steps: int | None) -> dict:
    """The unpaced paper6 lockstep run over Zenoh against in memory (medians of three, interleaved)."""
    from netsetest.bench.zenoh_runs import observed_lockstep
    from netsetest.config.schema import load_topology
    from netsetest.runtime.inmemory import run_inmemory

    sc = load_topology(PAPER6, "nsnim", steps)
    mem, zen = [], []
    for _ in range(3):
        t0 = time.perf_counter()
        run_inmemory(sc, "paper", "scheduled", 0)
        mem.append(time.perf_counter() - t0)
        zen.append(observed_lockstep(PAPER6, steps)["stepping_s"])
    before = None
    if COMMITTED_PERFORMANCE.exists():
        before = json.loads(COMMITTED_PERFORMANCE.read_text()).get("zenoh", {}).get("ratio")
    timed = [z for z in zen if z is not None]  # a run that failed has no stepping time
    ratio = statistics.median(timed) / statistics.median(mem) if timed else None
    return {"steps": sc.steps, "inmemory_s": mem, "zenoh_stepping_s": zen, "ratio": ratio, "ratio_before_window": before}


def flow_figures(cfg: dict, tmp: Path) -> dict:
    pauses = cfg.get("flow_pauses_s", (3.0, 10.0))
    out: dict = {"ack_window": ACK_WINDOW, "ack_stride": ACK_STRIDE, "paused": []}
    for pause in pauses:
        _log(f"collector paused {pause:g} s in an unpaced {cfg['flow_steps']}-step paper6 run")
        r = paused_run(tmp, cfg["flow_steps"], pause)
        _log(
            f"  exit {r['exit_code']}, node-steps lost {r['node_steps_lost']}, missing {r['nodes_missing']}, rejoined {r['nodes_rejoined']}, {r['wall_s']:.1f} s"
        )
        out["paused"].append(r)
    out["soak"] = []
    for seed in range(cfg["flow_soak_runs"]):
        _log(f"soak: an unpaced {cfg['flow_soak_steps']}-step paper6 run, seed {seed}")
        r = paused_run(tmp, cfg["flow_soak_steps"], 0.0, seed=seed)
        _log(
            f"  exit {r['exit_code']}, node-steps lost {r['node_steps_lost']}, missing {r['nodes_missing']}, rejoined {r['nodes_rejoined']}, {r['wall_s']:.1f} s"
        )
        out["soak"].append(r)
    _log("the unpaced paper6 lockstep ratio with the window (Zenoh / in memory)")
    out["ratio"] = lockstep_ratio(cfg.get("flow_ratio_steps"))
    _log(f"  ratio {out['ratio']['ratio']}, before the window {out['ratio']['ratio_before_window']}")
    return out


def flow_markdown(res: dict) -> str:
    f = lambda v, spec=".2f": "—" if v is None else format(v, spec)  # noqa: E731  # a one-line local helper
    lines = [
        f"The vehicle publishes step k + {res['ack_window']} only once the collector has acknowledged step k (every "
        f"{res['ack_stride']} steps). A collector stopped mid-run (SIGSTOP, then SIGCONT), recording gzip:",
        "",
        "| pause | steps | exit | node-steps lost | nodes missing | nodes rejoined | collector drops | wall |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in res["paused"]:
        drops = ", ".join(f"{k} {v}" for k, v in r["collector_drops"].items()) or "none"
        lines.append(
            f"| {r['pause_s']:g} s | {r['steps']} | {r['exit_code']} | {r['node_steps_lost']} | {r['nodes_missing']} | {r['nodes_rejoined']} | {drops} | {f(r['wall_s'], '.1f')} s |"
        )
    soak = res.get("soak", [])
    if soak:
        clean = sum(r["exit_code"] == 0 and r["node_steps_lost"] == 0 and not r["nodes_missing"] and not r["nodes_rejoined"] for r in soak)
        loads = ", ".join(f(r["load_before"], ".1f") for r in soak)
        lines += [
            "",
            f"Soak: {clean} of {len(soak)} unpaced {soak[0]['steps']}-step paper6 runs ended with exit 0, every node-step judged and "
            f"no node reported missing or rejoined (load average before each: {loads}).",
        ]
    q = res["ratio"]
    lines += [
        "",
        f"The unpaced paper6 lockstep run ({q['steps']} steps) over Zenoh takes {f(q['ratio'])}× the in-memory run with the window "
        f"({f(q['ratio_before_window'])}× in the performance part's committed figures, measured before it).",
        "",
    ]
    return "\n".join(lines)
