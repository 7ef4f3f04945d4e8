"""A run across two "hosts" against the same run on one (``netsetest bench --only scaleout``, issue 31).

When one machine's cores are not enough, a run spans hosts through Zenoh routers: a router on each host,
every role an mTLS client of its own host's router, the routers linked (``netsetest router --connect``).
Here the hosts are network namespaces on this machine (netsetest/runtime/netns.py), and one lockstep
ring (bench/topologies.py) runs in two layouts, alternately, ``reps`` times each:

- **one host**: one namespace, one router (mTLS + access control, the secured default), every role its
  client on loopback;
- **two hosts**: two namespaces joined by a veth pair, a router in each (the second connects to the
  first over the pair), the vehicle, the collector and the first half of the ring's nodes on host a,
  the other half on host b (:func:`placement`: a ring cut into two arcs).

Per run: the lockstep step rate of the stepping phase (the collector's progress on its channel, as the
launcher reads it: steps checked per second from step :data:`WARM_STEPS` on), the CPU of every process
per step (/proc, read every :data:`POLL_S`, per host) from step :data:`WARM_STEPS` checked to the
last but one (the last step's End lets the processes go), the ceiling the machine's cores put on the step rate at that CPU
per step (cores / CPU per step: every core busy with the run and nothing else), and the run's verdict.
Two namespaces on one machine add no core: the figure says what the second router and the link cost,
not what a second machine would add (docs/performance.md, *Scale out*).
"""

from __future__ import annotations

import json
import os
import secrets
import statistics
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

from netsetest_bench.figures.scaleout import Range
from netsetest_bench.figures.scaleout import load as load_scaleout
from netsetest_bench.render import MISSING, figure, fill
from netsetest_bench.topologies import ring_topology
from netsetest_bench.zenoh_runs import CLK_TCK, MACHINE_CORES, PY, _kill
from netsetest.runtime import netns
from netsetest.runtime.channel import ChannelReader
from netsetest.runtime.launcher import RUN_ID_BYTES, sigterm_as_interrupt
from netsetest.runtime.processes import role_env
from netsetest.runtime.rolespec import CollectorSpec, NodeSpec, RouterSpec, ScenarioSpec, VehicleSpec, ZenohSpec
from netsetest_bench.config import BenchConfig

LAYOUTS = {"one": 1, "two": 2}  # layout → hosts
HOST_NAMES = "ab"  # host index → its name in the tables
LINK_ADDR = ("10.231.0.1", "10.231.0.2")  # the veth pair between host a and host b (a /30)
ROUTER_PORT = 7447
LOCAL = f"tls/127.0.0.1:{ROUTER_PORT}"  # each host's router, as its own clients reach it
WARM_STEPS = 2  # the step rate is measured from this step on (the first steps carry the start-up's stragglers)
ROUTER_START_S = 30.0
POLL_S = 0.02  # how often the run's processes' CPU and the collector's progress are read


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def placement(ids: Sequence[int], hosts: int) -> dict[str, int]:
    """Role name → host index: the collector and the vehicle on host 0, the nodes in ``hosts`` contiguous
    arcs of the ring of near-equal size (only the arcs' ends and the chords cross hosts)."""
    ordered = sorted(ids)
    return {"collector": 0, "vehicle": 0, **{f"node{i}": k * hosts // len(ordered) for k, i in enumerate(ordered)}}


def step_rate(checked_at: Mapping[int, float], first: int) -> float | None:
    """Steps per second from the first step reported checked at or after ``first`` to the last one reported
    (the collector reports its progress when it advances, several steps at once at times; None: fewer than
    two such reports)."""
    ks = sorted(k for k in checked_at if k >= first)
    if len(ks) < 2:
        return None
    return (ks[-1] - ks[0]) / (checked_at[ks[-1]] - checked_at[ks[0]])


def _cpu_s(pid: int) -> float | None:
    """CPU seconds (user + system) of a process so far (None: it is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def _start(ns: str, argv: list[str], err: Path, pass_fds: Sequence[int] = ()) -> subprocess.Popen:
    with open(err, "wb") as fh:  # the child keeps its own descriptor
        return subprocess.Popen(
            [*netns.exec_prefix(ns), *PY, *argv],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=fh,
            start_new_session=True,
            env=role_env(),
            pass_fds=pass_fds,
        )


def scaleout_run(directory: Path, topology: Path, hosts: int, steps: int, timeout: float) -> dict:
    """One secured lockstep run of ``topology`` across ``hosts`` namespaces (module doc); every process
    stopped and every namespace deleted on the way out, a failed run too."""
    from netsetest.config.schema import load_topology
    from netsetest.runtime.security import ROUTER_HOSTS, write_credentials
    from netsetest.runtime.security import role_names as certificate_names

    sc = load_topology(topology, steps=steps)
    run_id = f"scale-{secrets.token_hex(RUN_ID_BYTES)}"
    where = placement(sc.ids, hosts)
    run_dir = Path(directory) / run_id
    run_dir.mkdir()
    summary_path = run_dir / "summary.json"
    nets = netns.Namespaces("nsb")
    procs: dict[str, subprocess.Popen] = {}
    host: dict[str, int] = {}
    load = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    row: dict = {"hosts": hosts, "run_id": run_id, "load_before": load, "error": None, "step_rate": None, "exit_codes": {}}
    try:
        names = [nets.add(HOST_NAMES[h]) for h in range(hosts)]
        row["namespaces"] = names
        if hosts > 1:
            nets.link(names[0], f"{LINK_ADDR[0]}/30", names[1], f"{LINK_ADDR[1]}/30")
        creds = str(write_credentials(run_dir / "credentials", certificate_names(sc), [*ROUTER_HOSTS, LINK_ADDR[0]]))
        _start_routers(names, topology, creds, run_id, run_dir, procs, host)
        scenario = ScenarioSpec(str(topology), steps=steps)
        zenoh = ZenohSpec(run_id, "client", (), (LOCAL,), creds)
        r_fd, w_fd = os.pipe()
        try:
            collector = CollectorSpec(scenario, summary_json=str(summary_path), channel_fd=w_fd, zenoh=zenoh)
            procs["collector"] = _start(names[where["collector"]], collector.to_argv(), run_dir / "collector.err", pass_fds=(w_fd,))
        finally:
            os.close(w_fd)  # the collector holds the write end: the channel ends when it exits
        reader = ChannelReader(os.fdopen(r_fd, "rb"))
        for i in sc.ids:
            procs[f"node{i}"] = _start(names[where[f"node{i}"]], NodeSpec(scenario, i, zenoh=zenoh).to_argv(), run_dir / f"node{i}.err")
        procs["vehicle"] = _start(names[where["vehicle"]], VehicleSpec(scenario, zenoh=zenoh).to_argv(), run_dir / "vehicle.err")
        host.update(where)
        roles = [n for n in procs if not n.startswith("router")]
        cpu = _watch(procs, host, roles, reader, hosts, steps, timeout)
        row["exit_codes"] = {n: procs[n].poll() for n in roles}
        if None in row["exit_codes"].values():
            raise TimeoutError(f"the run did not end within {timeout:g} s")
        reader.wait_closed(5.0)
        row["step_rate"] = step_rate(reader.checked_at, WARM_STEPS)
        if len(cpu) == 2 and cpu[1][0] > cpu[0][0]:
            (k0, c0), (k1, c1) = cpu
            row["cpu_ms_per_step_by_host"] = {HOST_NAMES[h]: 1e3 * (c1[h] - c0[h]) / (k1 - k0) for h in sorted(c1)}
    except (netns.NamespaceError, RuntimeError, OSError) as exc:
        row["error"] = str(exc)
    finally:
        _kill(list(procs.values()))
        left = nets.delete()
        if left:
            row["error"] = f"namespaces left behind: {left}"
    return row | _verdict(summary_path)


def _start_routers(names: list[str], topology: Path, creds: str, run_id: str, run_dir: Path, procs: dict[str, subprocess.Popen], host: dict[str, int]) -> None:
    """A router in each namespace of ``names`` (host a's listening on the link too, host b's connected to it there),
    into ``procs`` and ``host``; back when each says it listens, RuntimeError where one did not start."""
    hosts = len(names)
    linked = f"tls/{LINK_ADDR[0]}:{ROUTER_PORT}"  # host a's router, as host b's router reaches it
    for h, ns in enumerate(names):
        listen = (LOCAL, linked) if h == 0 and hosts > 1 else (LOCAL,)
        spec = RouterSpec(topology=str(topology), credentials=creds, listen=listen, connect=(linked,) if h > 0 else (), run_id=run_id)
        procs[f"router{h}"], host[f"router{h}"] = _start(ns, spec.to_argv(), run_dir / f"router{h}.err"), h
    up = time.monotonic() + ROUTER_START_S
    while not all("listening on" in (run_dir / f"router{h}.err").read_text(errors="replace") for h in range(hosts)):
        if time.monotonic() > up or any(procs[f"router{h}"].poll() is not None for h in range(hosts)):
            raise RuntimeError("a router did not start: " + " | ".join((run_dir / f"router{h}.err").read_text(errors="replace")[-300:] for h in range(hosts)))
        time.sleep(0.05)


def _watch(
    procs: dict[str, subprocess.Popen], host: dict[str, int], roles: list[str], reader: ChannelReader, hosts: int, steps: int, timeout: float
) -> list[tuple[int, dict[int, float]]]:
    """Until the roles end (or ``timeout``): each process's CPU, read every POLL_S; the CPU seconds by host when the
    collector has checked WARM_STEPS and the last step but one, with the step (the window the CPU per step is over)."""
    last: dict[str, float] = {}  # each process's CPU seconds when last read (a process gone: its last reading)
    cpu: list[tuple[int, dict[int, float]]] = []  # (step checked, CPU seconds by host) at the window's two ends
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and any(procs[n].poll() is None for n in roles):
        last.update((name, c) for name, p in procs.items() if (c := _cpu_s(p.pid)) is not None)
        if len(cpu) < 2 and reader.step >= (WARM_STEPS, steps - 1)[len(cpu)] and len(last) == len(procs):
            cpu.append((reader.step, {h: sum(c for name, c in last.items() if host[name] == h) for h in range(hosts)}))
        time.sleep(POLL_S)
    return cpu


def _verdict(summary_path: Path) -> dict:
    """What the run's summary says of it (every figure None where none was written, or it was cut short by the stop)."""
    try:
        s = json.loads(summary_path.read_text())
    except (OSError, ValueError):  # none written, or cut short by the stop
        s = {}
    return {
        k: s.get(key)
        for k, key in (("steps_completed", "steps_completed"), ("violations", "violations_total"), ("nodes_missing", "nodes_missing"), ("security", "security"))
    }


def _summary(runs: list[dict]) -> dict:
    """Median and range over the runs of the step rate, the CPU per step and the cores' ceiling."""
    ok = [r for r in runs if r.get("step_rate") and r.get("cpu_ms_per_step_by_host")]
    if not ok:
        return {}
    cpu = [sum(r["cpu_ms_per_step_by_host"].values()) for r in ok]
    ceiling = [1e3 * MACHINE_CORES / c for c in cpu]
    rate = [r["step_rate"] for r in ok]

    def m(v: list[float]) -> dict[str, float]:
        return {"median": statistics.median(v), "min": min(v), "max": max(v)}

    by_host = {h: statistics.median(r["cpu_ms_per_step_by_host"].get(h, 0.0) for r in ok) for h in ok[0]["cpu_ms_per_step_by_host"]}
    return {
        "runs": len(ok),
        "step_rate": m(rate),
        "cpu_ms_per_step": m(cpu),
        "cpu_ms_per_step_by_host": by_host,
        "ceiling_step_rate": m(ceiling),
        "of_ceiling": m([a / b for a, b in zip(rate, ceiling)]),
    }


def scaleout_figures(cfg: BenchConfig, tmp: Path) -> dict:
    """Both layouts of one ring, alternately (module doc)."""
    nodes, steps, reps = cfg.scaleout_nodes, cfg.scaleout_steps, cfg.scaleout_reps
    topo = ring_topology(tmp, nodes, steps)
    runs: dict[str, list[dict]] = {name: [] for name in LAYOUTS}
    with sigterm_as_interrupt():  # SIGTERM, like Ctrl-C, stops the run in progress and deletes its namespaces
        for rep in range(reps):
            for name, hosts in LAYOUTS.items():
                row = scaleout_run(tmp, topo, hosts, steps, timeout=120.0 + 2.0 * nodes + steps)
                runs[name].append(row)
                _log(
                    f"  {name} host(s), run {rep + 1}/{reps} (load {row['load_before']}): {row['step_rate'] or float('nan'):.2f} steps/s, "
                    f"CPU per step {row.get('cpu_ms_per_step_by_host')} ms, violations {row['violations']}, missing {row['nodes_missing']}"
                    + (f"; error: {row['error']}" if row["error"] else "")
                )
    return layouts_figures(runs, nodes, steps, reps)


def layouts_figures(runs: Mapping[str, list[dict]], nodes: int, steps: int, reps: int) -> dict:
    """The part's figures from each layout's runs (:func:`scaleout_run` rows): per layout its runs and their
    summary, and the step rate of two hosts over one (None unless both have a run that measured it)."""
    out: dict = {"nodes": nodes, "steps": steps, "reps": reps, "cores": MACHINE_CORES, "warm_steps": WARM_STEPS}
    out["layouts"] = {name: {"hosts": LAYOUTS[name], "runs": runs[name], "summary": _summary(runs[name])} for name in LAYOUTS}
    one, two = (out["layouts"][k]["summary"] for k in LAYOUTS)
    out["ratio"] = two["step_rate"]["median"] / one["step_rate"]["median"] if one and two else None
    return out


def _range(r: Range, spec: str = ".2f") -> str:
    return fill("scaleout", "range", r=r, spec=spec)


def scaleout_markdown(doc: dict) -> str:
    s, T = load_scaleout(doc), "scaleout"
    lines = [fill(T, "head", s=s)]
    for name, lay in s.layouts.items():
        runs = "; ".join(
            fill(
                T,
                "run",
                load=r.load_before.split()[0],
                r=r,
                missing=MISSING if r.nodes_missing is None else len(r.nodes_missing),
                failed=fill(T, "failed") if r.failed() else "",
            )
            for r in lay.runs
        )
        layout = fill(T, name)
        m = lay.summary
        if m is None:
            lines.append(fill(T, "no-summary", layout=layout, runs=runs))
            continue
        hosts = " / ".join(figure(m.cpu_ms_per_step_by_host.get(h), ".1f") for h in HOST_NAMES[: lay.hosts])
        lines.append(
            fill(
                T,
                "row",
                layout=layout,
                step_rate=_range(m.step_rate),
                cpu=_range(m.cpu_ms_per_step, ".1f"),
                hosts=hosts,
                ceiling=_range(m.ceiling_step_rate),
                of_ceiling=_range(m.of_ceiling),
                runs=runs,
            )
        )
    lines.append(fill(T, "ratio", s=s))
    return "\n".join(lines) + "\n"
