"""The multi-process parts of the benchmark: Zenoh lockstep overhead, real-time capacity, one node's cost.

- ``cli_run``: ``netsetest run TOPOLOGY --mode zenoh|inmemory --clock ...`` end to end, as a user runs it.
- ``observed_lockstep``: a lockstep run through ``netsetest run``'s own launcher (runtime/launcher.py),
  secured by default or ``--insecure``, in this process: the stepping phase timed by the collector's
  progress on the launcher's channel (without process start-up), each role's CPU and peak RSS from its
  rusage at exit.
- ``launch_to_step0``: ``netsetest run`` of a topology (secured, roles forked by the fork server) timed
  from launch to the vehicle's step-0 input.
- ``node_startup``: a one-node network whose vehicle and collector are already up and waiting; a
  node process is launched and timed from ``Popen`` to its first published state (the prior
  ellipsoid, step 0) and to its first solved estimate (step 1).
- ``realtime_ladder``: real-time runs (τs = 0.1 s, nodes as processes) of growing ring-with-chords
  networks until one has a deadline miss or loses a node; each run sampled by :class:`ProcessSampler`
  (CPU per role over the stepping phase, the machine's other work, node RSS) so a failure shows why.
- ``node_memory_profile``: RSS and import time of a node process, stage by stage.

Every role process is started with the environment ``netsetest run`` gives it (``role_env``); the command
lines of the roles this module starts itself (``node_startup``) come from their specs (runtime/rolespec.py).  The
roles of ``netsetest run`` are forked by its fork server: :class:`ProcessSampler` tells them apart by
process name (``ns-node3``), the others by command line.
"""

from __future__ import annotations

import json
import math
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import msgspec  # a default dependency (the bench must not need the dev extra's msgpack)

from netsetest.estimator.objective import DEFAULT_OBJECTIVE
from netsetest.roles.flow import ACK_WINDOW
from netsetest.runtime.forkserver import NAME_PREFIX
from netsetest.runtime.launcher import free_ports
from netsetest.runtime.processes import role_env
from netsetest.runtime.rolespec import Clock, CollectorSpec, NodeSpec, ScenarioSpec, VehicleSpec, ZenohSpec
from netsetest_bench.topologies import RingVariant

if TYPE_CHECKING:
    from netsetest.records.summary import RunSummary

PY = [sys.executable, "-m", "netsetest.cli.main"]


STOP_GRACE_S = 20.0  # SIGTERM first: a launcher stops its roles and removes its run directory (its credentials)


def _kill(procs: list[subprocess.Popen]) -> None:
    """Stop the process groups this module started (each child has its own session): SIGTERM, and SIGKILL
    what is still alive after STOP_GRACE_S (a SIGKILLed launcher leaves its credentials in /tmp)."""
    for sig, wait in ((signal.SIGTERM, STOP_GRACE_S), (signal.SIGKILL, 5.0)):
        live = [p for p in procs if p.poll() is None]
        for p in live:
            try:
                os.killpg(p.pid, sig)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + wait
        for p in live:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass


def cli_run(
    topology: Path,
    mode: str,
    clock: str = "lockstep",
    steps: int | None = None,
    timeout: float = 600.0,
    sample_stepping_s: float | None = None,
    env: dict[str, str] | None = None,
    extra: list[str] | None = None,
) -> dict:
    """One ``netsetest run`` as a subprocess: wall time, exit code and the summary JSON; with
    ``sample_stepping_s`` (how long its stepping lasts), the CPU and memory of its processes
    (:class:`ProcessSampler`) and its record (lateness per step).  ``env``: added to the environment;
    ``extra``: more ``netsetest run`` options."""
    sample = sample_stepping_s is not None
    with tempfile.TemporaryDirectory(prefix="nsbench-") as tmp:
        summary_path, record_path = Path(tmp) / "summary.json", Path(tmp) / "record.json"
        cmd = [*PY, "run", str(topology), "--mode", mode, "--clock", clock, "--quiet", "--summary-json", str(summary_path)]
        if steps:
            cmd += ["--steps", str(steps)]
        cmd += extra or []
        if sample:
            cmd += ["--record", str(record_path)]
        t0 = time.perf_counter()
        proc = subprocess.Popen(  # stdin not a terminal: `run --view` ends with its run instead of serving until Ctrl-C
            cmd,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
            env={**os.environ, **(env or {})},
        )
        sampler = ProcessSampler(proc.pid) if sample else None
        try:
            _, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            _kill([proc])
            return {
                "wall_s": timeout,
                "exit_code": None,
                "summary": None,
                "error": "timeout",
                "processes": sampler.stop(sample_stepping_s) if sampler else None,
            }
        wall = time.perf_counter() - t0
        summary = json.loads(summary_path.read_text()) if summary_path.exists() else None
        late = _late_per_step(record_path) if sample else None
    return {
        "wall_s": wall,
        "exit_code": proc.returncode,
        "summary": summary,
        "stderr_tail": err[-800:] if err else "",
        "processes": sampler.stop(sample_stepping_s) if sampler else None,
        "late_per_step": late,
    }


STEP0_LINE = ("[vehicle] all ", "are ready; clock")  # logged by run_vehicle right before step 0's input goes out


def launch_to_step0(topology: Path, reps: int, steps: int = 3, timeout: float = 120.0) -> dict:
    """``netsetest run TOPOLOGY`` as a user starts it (secured default: mTLS + access control at the
    router in the parent, roles forked by the fork server): seconds from ``Popen`` to the vehicle's
    line "all N nodes and the collector are ready", which it logs right before publishing step 0's
    input; ``reps`` runs of ``steps`` steps, one after another, with the load average before each."""
    rows = []
    for _ in range(reps):
        load = Path("/proc/loadavg").read_text().split()[0]
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            [*PY, "run", str(topology), "--steps", str(steps)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True
        )
        seen: list[float] = []

        def read(stream) -> None:
            for line in stream:
                if not seen and line.startswith(STEP0_LINE[0]) and STEP0_LINE[1] in line:
                    seen.append(time.perf_counter() - t0)

        reader = threading.Thread(target=read, args=(proc.stderr,), daemon=True)
        reader.start()
        try:
            code = proc.wait(timeout)
        except subprocess.TimeoutExpired:
            _kill([proc])
            code = None
        reader.join(5)
        rows.append({"launch_to_step0_s": seen[0] if seen else None, "exit_code": code, "load_before": float(load)})
    values = [r["launch_to_step0_s"] for r in rows if r["launch_to_step0_s"] is not None]
    return {"reps": rows, "median_s": statistics.median(values) if values else None, "steps": steps}


def _late_per_step(record_path: Path) -> dict[int, int] | None:
    """Step → how many nodes published it after its deadline (from the run's record)."""
    from netsetest.records.record import RecordError, load_record

    try:
        record = load_record(record_path)
    except RecordError:
        return None
    late: dict[int, int] = {}
    for rows in record.raw_nodes.values():
        for e in rows:
            if e["late"]:
                late[e["step"]] = late.get(e["step"], 0) + 1
    return dict(sorted(late.items()))


CLK_TCK = os.sysconf("SC_CLK_TCK")
SAMPLE_PERIOD_S = 0.25


def _proc_stat(pid: int) -> tuple[int, float, float, str] | None:
    """(parent pid, CPU seconds, VmHWM MB, role) of a process, from /proc; None once it is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        comm, fields = stat[stat.index("(") + 1 : stat.rindex(")")], stat.rsplit(")", 1)[1].split()
        hwm = next(int(x.split()[1]) for x in Path(f"/proc/{pid}/status").read_text().splitlines() if x.startswith("VmHWM:"))
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except (OSError, StopIteration, IndexError, ValueError):
        return None
    role = argv[3].decode() if len(argv) > 3 and argv[1:3] == [b"-m", b"netsetest.cli.main"] else "?"
    if role == "forkserver" and comm.startswith(NAME_PREFIX):  # a role forked by `netsetest run`'s fork server
        role = comm.removeprefix(NAME_PREFIX).rstrip("0123456789")
    return int(fields[1]), (int(fields[11]) + int(fields[12])) / CLK_TCK, hwm / 1024.0, role


def _machine_busy_s() -> float:
    """CPU seconds all cores spent not idle since boot (/proc/stat: user … steal, without idle and iowait)."""
    fields = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]]
    return (sum(fields) - fields[3] - fields[4]) / CLK_TCK


class ProcessSampler:
    """Samples a run's process tree (and the whole machine's CPU) every 0.25 s: per role the CPU share
    while the run steps, what other work used meanwhile, and the peak RSS of the nodes."""

    def __init__(self, root: int) -> None:
        self.root = root
        self.samples: dict[int, list[tuple[float, float, float, str]]] = {}  # pid → (t, cpu s, hwm MB, role)
        self.machine: list[tuple[float, float]] = []  # (t, busy CPU seconds of the whole machine)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            stats = {int(d): st for d in os.listdir("/proc") if d.isdigit() and (st := _proc_stat(int(d)))}
            tree, todo = set(), [self.root]
            while todo:
                pid = todo.pop()
                tree.add(pid)
                todo += [c for c, st in stats.items() if st[0] == pid and c not in tree]
            now = time.monotonic()
            self.machine.append((now, _machine_busy_s()))
            for pid in tree & stats.keys():
                _, cpu, hwm, role = stats[pid]
                self.samples.setdefault(pid, []).append((now, cpu, hwm, "run" if pid == self.root else role))
            self._stop.wait(SAMPLE_PERIOD_S)

    def stop(self, stepping_s: float | None = None) -> dict:
        """Per-role CPU shares over the stepping phase: the ``stepping_s`` seconds before the vehicle
        exited, without their first and last fifth (whole run if not given or too short to sample)."""
        self._stop.set()
        self._thread.join()
        vehicle_end = max((rows[-1][0] for rows in self.samples.values() if rows[-1][3] == "vehicle"), default=None)
        if stepping_s and vehicle_end is not None:
            lo, hi = vehicle_end - 0.8 * stepping_s, vehicle_end - 0.2 * stepping_s
        else:
            lo, hi = -math.inf, math.inf

        def rate(rows: list) -> float | None:
            inside = [r for r in rows if lo <= r[0] <= hi]
            if len(inside) < 2 or inside[-1][0] - inside[0][0] < SAMPLE_PERIOD_S:
                return None
            return 100.0 * (inside[-1][1] - inside[0][1]) / (inside[-1][0] - inside[0][0])

        shares: dict[str, list[float]] = {}
        hwm: list[float] = []
        for rows in self.samples.values():
            role = rows[-1][3]
            if role == "node":
                hwm.append(max(r[2] for r in rows))
            r = rate(rows)
            if r is not None:
                shares.setdefault(role, []).append(r)
        nodes = shares.pop("node", [])
        busy = rate([(t, b, 0.0, "") for t, b in self.machine])
        ours = sum(nodes) + sum(sum(v) for v in shares.values())
        return {
            "window_s": None if lo == -math.inf else hi - lo,
            "machine_busy_pct": busy,  # every process on the machine, same window
            "other_work_pct": None if busy is None else max(0.0, busy - ours),  # what was not this run
            "node_cpu_pct_median": statistics.median(nodes) if nodes else None,
            "nodes_cpu_pct_total": sum(nodes),
            "role_cpu_pct": {r: sum(v) for r, v in shares.items()},  # run (the parent, with the router), vehicle, collector
            "node_peak_rss_mb_median": statistics.median(hwm) if hwm else None,
        }


class MessageTap:
    """A Zenoh peer that records (arrival time, key, step) of every message of one run."""

    def __init__(self, run_id: str, listen: str, connect: list[str]) -> None:
        import zenoh

        from netsetest.bus.zenoh_bus import zenoh_config

        self.events: list[tuple[float, str, bytes]] = []
        self._lock = threading.Lock()
        self.session = zenoh.open(zenoh_config("peer", [listen], connect))

        def on_sample(sample: zenoh.Sample) -> None:
            t = time.monotonic()
            with self._lock:
                self.events.append((t, str(sample.key_expr), sample.payload.to_bytes()))

        self.sub = self.session.declare_subscriber(f"netsetest/{run_id}/**", on_sample)

    def seen(self, predicate) -> list[tuple[float, str, dict]]:
        with self._lock:
            events = list(self.events)
        out = []
        for t, key, payload in events:
            try:
                msg = msgspec.msgpack.decode(payload)
            except Exception:
                continue
            if isinstance(msg, dict) and predicate(key, msg):
                out.append((t, key, msg))
        return out

    def close(self) -> None:
        self.sub.undeclare()
        self.session.close()


def _vm_hwm_mb(pid: int) -> float | None:
    """Peak RSS of the process's current image (VmHWM; reset at exec, unlike ru_maxrss, which would
    count the pages a child shares with this big benchmark process between fork and exec)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except (OSError, ValueError):
        pass
    return None


def _wait_rusage(procs: dict[str, subprocess.Popen], deadline: float) -> dict[str, dict]:
    """Wait for the children: exit code, peak RSS (last VmHWM read before the exit) and CPU seconds
    (user + system, from the kernel's rusage at the exit) of each."""
    left = dict(procs)
    out: dict[str, dict] = {}
    hwm: dict[str, float] = {}
    while left and time.monotonic() < deadline:
        for name, p in list(left.items()):
            v = _vm_hwm_mb(p.pid)
            if v is not None:
                hwm[name] = max(v, hwm.get(name, 0.0))
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
            if pid:
                p.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
                out[name] = {"exit_code": p.returncode, "peak_rss_mb": hwm.get(name), "cpu_s": usage.ru_utime + usage.ru_stime}
                del left[name]
        time.sleep(0.01)
    if left:
        _kill(list(left.values()))
        for name in left:
            out[name] = {"exit_code": None, "peak_rss_mb": hwm.get(name), "cpu_s": None}
    return out


def _role_argv(topology: Path, run_id: str, steps: int | None, name: str, ports: dict[str, int], clock: Clock, summary_json: str | None = None) -> list[str]:
    """The command line of role ``name`` (collector, vehicle, nodeN) in an open peer mesh on ``ports``."""
    endpoint = lambda n: f"tcp/127.0.0.1:{ports[n]}"  # noqa: E731  # a one-line local helper
    scenario = ScenarioSpec(str(topology), steps=steps)
    zenoh = ZenohSpec(run_id, "peer", (endpoint(name),), tuple(endpoint(other) for other in ports if other != name))
    if name == "collector":
        return CollectorSpec(scenario, clock=clock, summary_json=summary_json, zenoh=zenoh).to_argv()
    if name == "vehicle":
        return VehicleSpec(scenario, clock=clock, zenoh=zenoh).to_argv()
    return NodeSpec(scenario, int(name.removeprefix("node")), clock=clock, zenoh=zenoh).to_argv()


@dataclass(frozen=True)
class RoleUsage:
    """A role process's rusage at its exit (``run``: the launching process's while it launched)."""

    exit_code: int | None
    peak_rss_mb: float | None
    cpu_s: float | None


@dataclass(frozen=True)
class Lockstep:
    """One lockstep run through the launcher (:func:`observed_lockstep`)."""

    security: str  # mtls+acl or insecure
    nodes: int
    steps: int
    stepping_s: float | None  # None: the collector reported too few steps to time it
    total_s: float
    startup_s: float | None
    usage: dict[str, RoleUsage]  # role name (node1, collector, vehicle, run, …) → its usage
    summary: RunSummary | None

    @property
    def node_peak_rss_mb(self) -> list[float]:
        return [u.peak_rss_mb for n, u in self.usage.items() if n.startswith("node") and u.peak_rss_mb is not None]

    @property
    def exit_codes(self) -> dict[str, int | None]:
        return {n: u.exit_code for n, u in self.usage.items()}


def observed_lockstep(topology: Path, steps: int | None = None, insecure: bool = False, ack_window: int | None = ACK_WINDOW) -> Lockstep:
    """One lockstep run of ``topology`` through the launcher ``netsetest run`` uses (runtime/launcher.py, in
    this process): secured by default (mTLS, every role a client of the run's router, roles forked by the
    fork server); ``insecure``: the open peer mesh of ``run --insecure``; ``ack_window``: ``run --ack-window``'s
    (None: unbounded, roles/flow.py).

    The stepping phase is timed by the collector's progress on the launcher's channel: from the first step
    it reports checked to the last, scaled to the run's N+1 steps (the first step's own time is not in it);
    the start-up is launch → that first report.  Each role's CPU seconds and peak RSS come from its rusage
    at its exit (the fork server reaps it); ``run`` is this process while it launched (the router when
    secured, the supervisor, the channel)."""
    import netsetest.bus.zenoh_bus  # imported by the launcher once: not counted in the first run's "run" CPU
    import netsetest.runtime.security  # noqa: F401  # the same (credentials, the router's access control)
    from netsetest.runtime.launcher import LaunchOptions, launch, plan_run
    from netsetest.runtime.report import EXIT_INTERRUPTED

    plan = plan_run(LaunchOptions(str(topology), steps=steps, seed=0, quiet=True, insecure=insecure, ack_window=ack_window))
    n_steps = plan.scenario.steps
    cpu0, t_start = time.process_time(), time.monotonic()
    out = launch(plan)
    t_done = time.monotonic()
    if out.exit_code == EXIT_INTERRUPTED:  # Ctrl-C reached the launcher: the benchmark stops too
        raise KeyboardInterrupt
    usage = {name: RoleUsage(u.exit_code, u.peak_rss_mb, u.cpu_s) for name, u in out.roles.items()}
    usage["run"] = RoleUsage(out.exit_code, None, time.process_time() - cpu0)
    first = min(out.checked_at, default=None)
    stepping = None
    if first is not None and n_steps in out.checked_at and n_steps > first:
        stepping = (out.checked_at[n_steps] - out.checked_at[first]) * (n_steps + 1) / (n_steps - first)
    return Lockstep(
        security="insecure" if insecure else "mtls+acl",
        nodes=len(plan.scenario.ids),
        steps=n_steps,
        stepping_s=stepping,
        total_s=t_done - t_start,
        startup_s=None if first is None else out.checked_at[first] - t_start,
        usage=usage,
        summary=out.summary,
    )


def node_startup(directory: Path, reps: int = 3, timeout: float = 120.0) -> dict:
    """One node process launched into a waiting one-node network: start-up time and peak RSS."""
    from netsetest_bench.topologies import single_node_topology

    topo = single_node_topology(directory, steps=3)
    rows = []
    for rep in range(reps):
        run_id = f"bench{os.getpid()}s{rep}"
        names = ["collector", "vehicle", "node1", "observer"]
        ports = dict(zip(names, free_ports(len(names))))
        role_ports = {k: v for k, v in ports.items()}
        obs = MessageTap(run_id, f"tcp/127.0.0.1:{ports['observer']}", [f"tcp/127.0.0.1:{p}" for n, p in ports.items() if n != "observer"])
        procs: dict[str, subprocess.Popen] = {}
        try:
            for name in ("collector", "vehicle"):
                procs[name] = subprocess.Popen(
                    [*PY, *_role_argv(topo, run_id, None, name, role_ports, "lockstep")],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    stdin=subprocess.DEVNULL,
                    start_new_session=True,
                    env=role_env(),
                )
            # wait until both announce themselves (they then wait for the node at the start-up barrier)
            t_wait = time.monotonic()
            while time.monotonic() - t_wait < timeout:
                roles = {m.get("role") for _, _, m in obs.seen(lambda k, m: m.get("type") == "ready")}
                if {"vehicle", "collector"} <= roles:
                    break
                time.sleep(0.05)
            time.sleep(0.3)  # let the machine settle after their start-up
            t0 = time.monotonic()
            procs["node1"] = subprocess.Popen(
                [*PY, *_role_argv(topo, run_id, None, "node1", role_ports, "lockstep")],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                stdin=subprocess.DEVNULL,
                start_new_session=True,
                env=role_env(),
            )
            usage = _wait_rusage(procs, time.monotonic() + timeout)
        finally:
            _kill(list(procs.values()))
            obs.close()
        st = {m.get("step"): t for t, _, m in sorted(obs.seen(lambda k, m: m.get("type") == "state" and m.get("node") == 1), reverse=True)}
        rows.append(
            {
                "first_state_s": st[0] - t0 if 0 in st else None,
                "first_estimate_s": st[1] - t0 if 1 in st else None,
                "peak_rss_mb": usage["node1"]["peak_rss_mb"],
                "exit_code": usage["node1"]["exit_code"],
            }
        )
    return {"reps": rows}


def _loadavg() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def code_env(code: Path | None) -> dict[str, str]:
    """The environment that runs ``code``'s netsetest (another checkout, the benchmark's baseline; None: this one's):
    PYTHONPATH first, and PYTHONSAFEPATH so that `python -m` does not put the working directory (a checkout, say)
    before it."""
    return {"PYTHONPATH": str(code), "PYTHONSAFEPATH": "1"} if code is not None else {}


def realtime_run(topo: Path, n: int, steps: int, retries: int, log, label: str = "", env: dict[str, str] | None = None) -> tuple[bool, list[dict]]:
    """Real-time runs of one topology (up to ``1 + retries``): whether one ran without a deadline miss or a
    lost node, and every attempt's row.  ``env``: added to the run's environment (:func:`code_env`)."""
    from netsetest_bench.topologies import RING_TAU_S

    rows = []
    for attempt in range(retries + 1):
        load = _loadavg()
        r = cli_run(topo, "zenoh", "realtime", timeout=120 + 3 * n + steps * 0.2, sample_stepping_s=steps * RING_TAU_S, env=env)
        s = r["summary"] or {}
        misses = sum(row.get("deadline_misses") or 0 for row in s.get("nodes", [])) if s else None
        late = r.get("late_per_step") or {}
        row = {
            "nodes": n,
            "attempt": attempt + 1,
            "exit_code": r["exit_code"],
            "wall_s": r["wall_s"],
            "deadline_misses": misses,
            "nodes_missing": s.get("nodes_missing") if s else None,
            "fallbacks": sum(x.get("fallbacks", 0) for x in s.get("nodes", [])) if s else None,
            "violations": s.get("violations_total") if s else None,
            "load_before": load,
            "late_steps": len(late),
            "first_late_step": min(late) if late else None,
            "processes": r["processes"],
            **cpu_demand(r["processes"], n),
        }
        rows.append(row)
        pr = r["processes"] or {}
        log(
            f"  real time{label}, {n} nodes (attempt {attempt + 1}, load {load}): exit {r['exit_code']}, deadline misses {misses} "
            f"in {len(late)} steps, missing {row['nodes_missing']}, {r['wall_s']:.0f} s; node CPU {pr.get('node_cpu_pct_median') or 0:.2f} % "
            f"each, all nodes {pr.get('nodes_cpu_pct_total', 0):.0f} %, others {pr.get('role_cpu_pct')}, other work on the machine "
            f"{pr.get('other_work_pct') or 0:.0f} %; {row['node_cpu_ms_per_step'] or 0:.2f} ms of CPU per node-step, "
            f"{row['demand_cores'] or 0:.2f} cores needed"
        )
        if r["exit_code"] == 0 and misses == 0 and not row["nodes_missing"]:
            return True, rows
    return False, rows


def realtime_ladder(directory: Path, sizes: list[int], steps: int, retries: int = 1, log=print) -> dict:
    """Real-time runs of ring networks of growing size; the largest without a deadline miss."""
    from netsetest_bench.topologies import ring_topology

    runs: list[dict] = []
    best = None
    for n in sizes:
        ok, rows = realtime_run(ring_topology(directory, n, steps), n, steps, retries, log)
        runs += rows
        if not ok:
            break
        best = n
    return {"max_nodes": best, "runs": runs, "steps": steps}


def realtime_fit(directory: Path, variants: tuple[RingVariant, ...], sizes: list[int], start: int | None, steps: int, retries: int = 1, log=print) -> dict:
    """Per ring variant (bench/topologies.py: a reference sensor, k-of-N health per group of six, the
    CommonRoad car as the truth): the largest of ``sizes`` up to ``start`` (the plain ladder's largest) that
    still runs in real time, walking down from ``start``, and its ratio to ``start``."""
    from netsetest_bench.topologies import ring_topology

    out: dict = {}
    for variant in variants:
        runs: list[dict] = []
        best = None
        for n in sorted((m for m in sizes if start is not None and m <= start), reverse=True):
            ok, rows = realtime_run(ring_topology(directory, n, steps, variant=variant), n, steps, retries, log, f" ({variant})")
            runs += rows
            if ok:
                best = n
                break
        out[variant] = {"max_nodes": best, "ratio_to_plain": None if best is None or not start else best / start, "runs": runs}
    return out


MACHINE_CORES = os.cpu_count() or 1


def cpu_demand(processes: dict | None, nodes: int) -> dict:
    """What a real-time run asks of the machine: a node's CPU per step (its share of a core over the
    stepping phase × τs, robust to other work as long as the node keeps up), and the cores the run
    needs at that cost — N nodes × CPU per step / τs, plus what vehicle, collector and router used."""
    from netsetest_bench.topologies import RING_TAU_S

    share = (processes or {}).get("node_cpu_pct_median")
    if share is None:
        return {"node_cpu_ms_per_step": None, "demand_cores": None}
    per_step_ms = share / 100.0 * RING_TAU_S * 1000.0
    roles = sum(((processes or {}).get("role_cpu_pct") or {}).values()) / 100.0
    return {"node_cpu_ms_per_step": per_step_ms, "demand_cores": nodes * per_step_ms / 1000.0 / RING_TAU_S + roles}


def profiling(code: Path | None, directory: str) -> tuple[dict[str, str], list[str]]:
    """The environment and the ``netsetest run`` options that have ``code``'s nodes (:func:`code_env`) write their
    profiles to ``directory``: ``run --profile DIR``; a baseline from before that option (its ``run --help`` does not
    name it) read ``$NETSETEST_PROFILE`` instead, which is what it is given."""
    env = code_env(code)
    if code is not None:
        usage = subprocess.run([*PY, "run", "--help"], capture_output=True, text=True, timeout=60, env={**os.environ, **env}).stdout
        if "--profile" not in usage:
            return {**env, "NETSETEST_PROFILE": directory}, []
    return env, ["--profile", directory]


def profiled_ring_run(directory: Path, nodes: int, steps: int, objective: str | None = None, code: Path | None = None) -> tuple[dict, list[dict], str]:
    """One real-time ring run with every node profiled (``run --profile``, netsetest/profile.py; :func:`profiling`):
    the run (:func:`cli_run`), each node's report (those that stepped) and the load average before it.
    ``objective``: the nodes' ``--objective``; ``code``: another checkout whose netsetest runs (PYTHONPATH,
    the benchmark's baseline), this one's by default."""
    from netsetest_bench.topologies import RING_TAU_S, ring_topology

    topo = ring_topology(directory, nodes, steps)
    with tempfile.TemporaryDirectory(prefix="nsprofile-") as prof:
        env, extra = profiling(code, prof)
        load = _loadavg()
        r = cli_run(
            topo,
            "zenoh",
            "realtime",
            timeout=120 + 3 * nodes + steps * 0.2,
            sample_stepping_s=steps * RING_TAU_S,
            env=env,
            extra=[*extra, "--objective", objective] if objective else extra,
        )
        reports = [json.loads(p.read_text()) for p in sorted(Path(prof).glob("node-*.json"))]
    return r, [x for x in reports if x.get("steps")], load


def realtime_node_profile(directory: Path, nodes: int, steps: int, objective: str | None = None) -> dict:
    """One real-time ring run with every node profiled (:func:`profiled_ring_run`): per phase of the node's
    own thread the median over nodes of CPU ms per step, and its calls per step.  ``objective``: the nodes'
    ``--objective`` (default: the run's default)."""
    r, reports, load = profiled_ring_run(directory, nodes, steps, objective)
    s = r["summary"] or {}
    out: dict = {
        "nodes": nodes,
        "steps": steps,
        "objective": objective or DEFAULT_OBJECTIVE,
        "load_before": load,
        "exit_code": r["exit_code"],
        "profiled_nodes": len(reports),
        "deadline_misses": sum(row.get("deadline_misses") or 0 for row in s.get("nodes", [])) if s else None,
        "processes": r["processes"],
        **cpu_demand(r["processes"], nodes),
    }
    if not reports:
        return out
    med = lambda xs: statistics.median(xs)  # noqa: E731  # a one-line local helper
    out["phases"] = {
        name: {
            "ms_per_step": med([x["phases"][name]["ms_per_step"] for x in reports]),
            "calls_per_step": med([x["phases"][name]["calls_per_step"] for x in reports]),
        }
        for name in reports[0]["phases"]
    }
    out["thread_ms_per_step"] = med([x["thread_ms_per_step"] for x in reports])
    out["process_ms_per_step"] = med([x["process_ms_per_step"] for x in reports])
    return out


# What a node process loads, in the order it loads it (netsetest.cli.main → the node's modules).
NODE_IMPORT_STAGES = (
    "numpy",
    "msgspec",
    "netsetest.messages",
    "netsetest.config.schema",
    "zenoh",
    "clarabel",
    "netsetest.estimator.sdp",
    "netsetest.roles.node",
    "netsetest.cli.main",
    "netsetest.cli.processes",
)
_MEMORY_PROBE = r"""
import json, sys, time
def rss():
    return next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmRSS:")) / 1024.0
rows = [("python", rss(), 0.0)]
for name in sys.argv[1:]:
    t = time.perf_counter(); __import__(name); rows.append((name, rss(), 1e3 * (time.perf_counter() - t)))
import zenoh
from netsetest.bus.zenoh_bus import zenoh_config
t = time.perf_counter(); s = zenoh.open(zenoh_config("peer", ["tcp/127.0.0.1:0"])); time.sleep(0.3)
rows.append(("zenoh session", rss(), 1e3 * (time.perf_counter() - t) - 300.0))
s.close()
print(json.dumps(rows))
"""


def node_memory_profile() -> list[dict]:
    """RSS and wall time a node process adds per import stage and for its Zenoh session (the
    environment of :func:`role_env`): where the node's memory and start-up go."""
    out = subprocess.run([sys.executable, "-c", _MEMORY_PROBE, *NODE_IMPORT_STAGES], capture_output=True, text=True, timeout=120, env=role_env())
    if out.returncode != 0:
        return [{"stage": "error", "detail": out.stderr[-300:]}]
    rows, prev = [], 0.0
    for name, rss, ms in json.loads(out.stdout):
        rows.append({"stage": name, "rss_mb": rss, "added_mb": rss - prev, "ms": ms})
        prev = rss
    return rows
