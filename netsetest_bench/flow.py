"""The benchmark's flow-control figures (``netsetest bench --only flow``): a collector that falls behind
loses nothing, and what the lockstep window costs (roles/flow.py ``ACK_WINDOW``, issue 33).

- ``paused``: ``netsetest run paper6`` unpaced (lockstep), recording ``.jsonl.gz``, with its collector
  stopped (SIGSTOP) for a few seconds mid-run and then continued (SIGCONT): the exit code, the steps and
  node-steps judged and lost, the nodes reported missing or rejoined (all must be 0), the wall time.
- ``records``: the issue's reproduction, ``netsetest run paper6_lossy --steps 3000 --seed 0 --record r.jsonl.gz``
  and the same recording ``.mcap`` (the slow records), nothing paused: the same figures.
- ``soak``: unpaced 3000-step paper6 runs, nothing paused, one after another on whatever else loads the
  machine (the soak that failed 2 of 2 before the window): exit code and node-steps lost per run.
- ``ratio``: the unpaced paper6 lockstep run over Zenoh against the same run in memory (what the
  performance part's ``zenoh.ratio`` measures, with the same functions), with the window and without it
  (``netsetest run --ack-window unbounded``, roles/flow.py: the same launcher, the vehicle never held), the three runs interleaved, medians of three: the window's cost is the difference of the two
  ratios, measured side by side in one run.  Both arms send the collector's acknowledgments (one small
  message per ``ACK_STRIDE`` steps, the collector does not know the vehicle's window): the difference is
  what holding the vehicle costs, the acknowledgments' own (a Ready decoded by each role every other step)
  is in both.  The stepping time is the collector's (its first to its last step checked, as the performance
  part times it): a run is done when its steps are judged, so a collector the unbounded vehicle left behind
  lengthens it by the backlog it still has to take in.
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

from netsetest.roles.flow import ACK_STRIDE, ACK_WINDOW, show_window
from netsetest.scenarios import TOPOLOGY_DIR
from netsetest_bench.figures.flow import load as load_flow
from netsetest_bench.render import figure, fill
from netsetest_bench.config import BenchConfig

PAPER6 = TOPOLOGY_DIR / "paper6.toml"
PAPER6_LOSSY = TOPOLOGY_DIR / "paper6_lossy.toml"  # the reproduction: scheduled losses, a 3000-step record
RECORD_SUFFIXES = (".jsonl.gz", ".mcap")  # the slow records (gzip, MCAP) that made a collector fall behind
UNDER_WAY_BYTES = 50_000  # the record (gzip) has grown this much: the run is under way, pause its collector now
RATIO_REPS = 3  # interleaved repetitions of the ratio's three runs: medians of three


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


def paused_run(tmp: Path, steps: int, pause_s: float, timeout: float = 900.0, seed: int = 0, topology: Path = PAPER6, record_suffix: str = ".jsonl.gz") -> dict:
    """One unpaced run of ``topology`` (``netsetest run`` as users start it, recording ``record_suffix``) whose
    collector is stopped for ``pause_s`` once the run is under way (0: never)."""
    run_id = f"flow{os.getpid()}p{int(pause_s * 1000)}s{seed}{topology.stem}{record_suffix.replace('.', '_')}"
    record, summary = tmp / f"{run_id}{record_suffix}", tmp / f"{run_id}.json"
    cmd = [sys.executable, "-m", "netsetest.cli.main", "run", str(topology), "--steps", str(steps), "--seed", str(seed), "--quiet"]
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
        "topology": topology.stem,
        "record": record_suffix,
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


def lockstep_ratio(steps: int | None, reps: int = RATIO_REPS) -> dict:
    """The unpaced paper6 lockstep run over Zenoh against in memory, with the window (the default) and
    without it (``--ack-window unbounded``): the same launcher ``netsetest run`` uses, the three
    runs interleaved ``reps`` times so that the machine's load falls on each alike, the two Zenoh runs in
    turn first (a run right after another may pay for its predecessor's teardown); medians, and the load
    average before each repetition (the spread of the repetitions is the figure's noise)."""
    from netsetest_bench.zenoh_runs import observed_lockstep
    from netsetest.config.schema import load_topology
    from netsetest.runtime.inmemory import run_inmemory

    sc = load_topology(PAPER6, "nsnim", steps)
    mem: list[float] = []
    zen: dict[str, list[float | None]] = {"window": [], "unbounded": []}
    codes: dict[str, list[int | None]] = {"window": [], "unbounded": []}
    loads: list[float] = []
    arms: tuple[tuple[str, int | None], ...] = (("window", ACK_WINDOW), ("unbounded", None))
    for rep in range(reps):
        loads.append(os.getloadavg()[0])
        t0 = time.perf_counter()
        run_inmemory(sc, "paper", "scheduled", 0)
        mem.append(time.perf_counter() - t0)
        for case, window in arms if rep % 2 == 0 else arms[::-1]:
            obs = observed_lockstep(PAPER6, steps, ack_window=window)
            zen[case].append(obs.stepping_s)
            codes[case].append(obs.usage["run"].exit_code)
    out: dict = {"steps": sc.steps, "reps": reps, "load_before": loads, "inmemory_s": mem}
    for case, times in zen.items():
        out[f"zenoh_{case}_s"] = times
        out[f"zenoh_{case}_exit_codes"] = codes[case]
        z = _median(times)
        out[f"ratio_{case}"] = None if z is None else z / statistics.median(mem)
    w, u = out["ratio_window"], out["ratio_unbounded"]
    out["window_cost"] = None if w is None or u is None else w - u  # the medians' ratios' difference: in-memory run times
    return out


def _logged(r: dict) -> dict:
    _log(f"  exit {r['exit_code']}, node-steps lost {r['node_steps_lost']}, missing {r['nodes_missing']}, rejoined {r['nodes_rejoined']}, {r['wall_s']:.1f} s")
    return r


def flow_figures(cfg: BenchConfig, tmp: Path) -> dict:
    out: dict = {"ack_window": ACK_WINDOW, "ack_stride": ACK_STRIDE, "paused": [], "records": [], "soak": []}
    for pause in cfg.flow_pauses_s:
        _log(f"collector paused {pause:g} s in an unpaced {cfg.flow_steps}-step paper6 run")
        out["paused"].append(_logged(paused_run(tmp, cfg.flow_steps, pause)))
    for suffix in RECORD_SUFFIXES:
        _log(f"an unpaced {cfg.flow_record_steps}-step paper6_lossy run recording {suffix}")
        out["records"].append(_logged(paused_run(tmp, cfg.flow_record_steps, 0.0, topology=PAPER6_LOSSY, record_suffix=suffix)))
    for seed in range(cfg.flow_soak_runs):
        _log(f"soak: an unpaced {cfg.flow_soak_steps}-step paper6 run, seed {seed}")
        out["soak"].append(_logged(paused_run(tmp, cfg.flow_soak_steps, 0.0, seed=seed)))
    _log("the unpaced paper6 lockstep ratio (Zenoh / in memory), with the window and without it, interleaved")
    q = out["ratio"] = lockstep_ratio(cfg.flow_ratio_steps)
    _log(f"  ratio with the window {q['ratio_window']}, without {q['ratio_unbounded']}: the window's cost {q['window_cost']}")
    return out


def _median(xs: list[float | None]) -> float | None:
    timed = [x for x in xs if x is not None]  # a run that failed has no stepping time
    return statistics.median(timed) if timed else None


def flow_markdown(doc: dict) -> str:
    f, T = load_flow(doc), "flow"
    lines = [fill(T, "head", f=f)]
    for r in [*f.paused, *f.records]:
        drops = ", ".join(f"{k} {v}" for k, v in r.collector_drops.items()) or fill(T, "no-drops")
        paused = fill(T, "not-paused" if not r.pause_s else "ended-first" if r.paused_at_s is None else "paused", r=r)
        lines.append(fill(T, "run-row", r=r, paused=paused, drops=drops))
    if f.soak:
        loads = ", ".join(figure(r.load_before, ".1f") for r in f.soak)
        lines.append(fill(T, "soak", clean=sum(r.clean() for r in f.soak), runs=len(f.soak), steps=f.soak[0].steps, loads=loads))
    q = f.ratio
    lines.append(fill(T, "ratio-head", q=q, unbounded=show_window(None)))
    for n, (m, w, u) in enumerate(zip(q.inmemory_s, q.zenoh_window_s, q.zenoh_unbounded_s)):
        rw, ru = (None if z is None else z / m for z in (w, u))
        lines.append(fill(T, "ratio-row", n=n + 1, load=q.load_before[n], inmemory=m, window=w, unbounded=u, ratio_window=rw, ratio_unbounded=ru))
    lines.append(fill(T, "ratio-medians", q=q, inmemory=_median(list(q.inmemory_s)), window=_median(q.zenoh_window_s), unbounded=_median(q.zenoh_unbounded_s)))
    return "\n".join(lines)
