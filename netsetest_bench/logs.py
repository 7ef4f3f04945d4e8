"""The benchmark's logs part (``netsetest bench --only logs``): a recorded drive as the world, issue 42's targets.

- ``import``: a 30-minute drive at 100 Hz with 9 channels (6 IMUs' ``sensor_msgs/msg/Imu``, the odometry's speed, the
  steering, one INS message with β and r), generated here (never committed) as a ROS 2 bag (MCAP) and, for
  comparison, as MDF4, Parquet and CSV; each read as the vehicle role reads it (logs/drive.py ``LogDrive``: the
  import checks the whole log and plans the run, then every step streams), in a process of its own
  (:func:`measure_import`, ``python -m netsetest_bench.logs``), so that its time and peak resident memory are the
  reading's alone (with the imports a role has anyway).  The nodes and the collector never read the log.  For the
  bag, then, rosbags' own reading of every mapped message with nothing decoded, timed alone in the same process:
  the floor under a bag's import, which reads the whole log once.
- ``replay``: paper6 in memory from a log of its own simulated run (accuracy 0), beside the same run from the model,
  alternately: how many times faster than real time, and that the replay's verdict is the run's; of the replay's time,
  the nodes' estimator steps (each step's time as the estimator's observer gets it, estimator/sdp.py ``StepObserver``),
  the rest being the roles, the bus, the judge and the log around them.
- ``calibration``: synthetic drives of paper6_car's car (logs/example.py, the sensors' biases the car's), training
  drives calibrated with ``calibrate --logs`` (analysis/calibrate.py), and a held-out drive (another seed, gentler
  steering) declared with the calibrated mismatch box, envelope and noise bounds, replayed with a reference of
  accuracy 0 and with an INS-grade one (r ± 0.1 °/s, β ± 0.15 °): contained, missed, undecided.
"""

from __future__ import annotations

import json
import math
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from netsetest_bench.figures.logs import Logs
from netsetest_bench.figures.logs import load as load_logs
from netsetest_bench.render import fill
from netsetest_bench.config import BenchConfig

BIG_MINUTES = 30.0
BIG_HZ = 100.0
BIG_CHANNELS = 9  # 6 IMUs, speed, steering, the INS (β and r in one message)
IMPORT_FORMATS = ("rosbag-mcap", "mdf4", "parquet", "csv")
TARGET_IMPORT_S = 10.0
TARGET_PEAK_MB = 300.0
TARGET_REALTIME = 20.0
INS = (math.radians(0.15), math.radians(0.1))  # the target's INS grade: β ± 0.15°, r ± 0.1 °/s
HELD_OUT_SEED = 100
HELD_OUT_STEER = 0.75  # the held-out drive's steering amplitude, as a share of the topology's: inside the envelope
RSS_SAMPLES = 20  # resident memory samples over the streamed steps


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def _rss_mb() -> float:
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, IndexError, ValueError):
        return float("nan")
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def _peak_mb() -> float:
    """This process's peak resident memory (MB): /proc's VmHWM, which starts afresh at exec (getrusage's ru_maxrss
    keeps the forking parent's, which wrote the log)."""
    try:
        line = next(ln for ln in Path("/proc/self/status").read_text().splitlines() if ln.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return float("nan")
    return int(line.split()[1]) / 1024  # kB


# ---------------------------------------------------------------- the big drive


def big_drive(minutes: float, hz: float, seed: int):
    """paper6's T-S car driven for ``minutes`` (its speed profile, random steering and wind), logged at ``hz``: each
    channel the newest model step's value (τs = 0.1 s) with each sensor's noise within 0.9 of its bound; the
    reference the truth (accuracy 0), in one INS message."""
    from netsetest.config.schema import load_topology
    from netsetest.logs.write import DriveTable

    sc = load_topology("paper6")
    rng = np.random.default_rng([seed, 0xB16])
    steps = round(minutes * 60 / sc.tau_s)
    x = np.zeros((steps + 1, 2))
    u = rng.uniform(sc.steer_low, sc.steer_high, steps + 1)
    vx = np.array([sc.vx(k) for k in range(steps + 1)])
    w = rng.uniform(-1.0, 1.0, steps) * math.sqrt(sc.W)
    for k in range(steps):
        x[k + 1] = sc.model.step(x[k], u[k], w[k], vx[k])
    t = np.arange(round(minutes * 60 * hz)) / hz
    k = np.minimum((t / sc.tau_s + 1e-9).astype(int), steps)
    yaw = {}
    for n in sc.nodes:
        bound = abs(n.sensor.Dv) * math.sqrt(n.sensor.R)
        yaw[n.id] = x[k] @ n.sensor.C + rng.uniform(-0.9, 0.9, t.size) * bound
    return DriveTable(
        t=t + 1.0,  # a bag's stamps cannot be negative
        speed=vx[k],
        steering=u[k],
        yaw=yaw,
        beta=x[k, 0],
        r=x[k, 1],
        description=f"SYNTHETIC: netsetest bench's {minutes:g}-minute {hz:g} Hz drive of paper6's T-S car",
        ins_message=True,
    )


def _rosbags_reading_cpu(log: Path, topics: set[str]) -> float:
    """CPU seconds of rosbags' reading of the bag's messages on ``topics``, none decoded (the raw payloads handed over)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    c0 = time.process_time()
    with AnyReader([log], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for _ in reader.messages(connections=[c for c in reader.connections if c.topic in topics]):
            pass
    return time.process_time() - c0


def measure_import(topology: str, log: str, mapping: str) -> dict:
    """As the vehicle role reads a log, in this process: the import (the whole log checked, the run planned, step 0),
    then every step streamed; times, CPU, peak and sampled resident memory; for a bag, then rosbags' reading alone."""
    from netsetest.config.logmap import log_format
    from netsetest.config.schema import load_topology
    from netsetest.logs.drive import LogDrive, with_log_steps

    rss_before = _rss_mb()
    t0, c0 = time.perf_counter(), time.process_time()
    sc = with_log_steps(load_topology(topology, log=log, mapping=mapping), whole=True)  # every step the log holds
    drive = LogDrive(sc)
    import_s, import_cpu = time.perf_counter() - t0, time.process_time() - c0
    rss = [_rss_mb()]
    every = max(1, sc.steps // RSS_SAMPLES)
    t1, c1 = time.perf_counter(), time.process_time()
    for k in range(1, sc.steps + 1):
        drive.step(k)
        if k % every == 0:
            rss.append(_rss_mb())
    return {
        "steps": sc.steps,
        "import_s": import_s,
        "import_cpu_s": import_cpu,
        "stream_s": time.perf_counter() - t1,
        "stream_cpu_s": time.process_time() - c1,
        "rss_before_mb": rss_before,
        "rss_mb": rss,  # after the import, then every steps/RSS_SAMPLES steps
        "peak_mb": _peak_mb(),
        **(
            {"rosbags_cpu_s": _rosbags_reading_cpu(Path(log), {s.channel for s in sc.log.mapping.signals})}
            if sc.log is not None and log_format(Path(log), sc.log.mapping) == "rosbag"
            else {}
        ),
    }


def _measure(topology: str, log: Path, mapping: Path) -> dict:
    from netsetest.runtime.processes import role_env

    out = subprocess.run(
        [sys.executable, "-m", "netsetest_bench.logs", topology, str(log), str(mapping)], capture_output=True, text=True, check=True, env=role_env()
    )
    return json.loads(out.stdout.splitlines()[-1])  # the last line: asammdf 8.8 prints a line of its own when a fragment took over 10 s


def _size_mb(path: Path) -> float:
    files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
    return sum(p.stat().st_size for p in files) / 2**20


def import_figures(tmp: Path) -> dict:
    from netsetest.logs.write import DriveTable, log_path, mapping_toml, write_log

    _log(f"logs: a {BIG_MINUTES:g}-minute {BIG_HZ:g} Hz drive with {BIG_CHANNELS} channels, written in each format (not timed)")
    d = big_drive(BIG_MINUTES, BIG_HZ, 0)
    rows = []
    for fmt in IMPORT_FORMATS:
        table = d if fmt.startswith("rosbag") else DriveTable(d.t, d.speed, d.steering, d.yaw, d.beta, d.r, description=d.description)
        t0 = time.perf_counter()
        log = write_log(table, log_path(tmp, "big", fmt), fmt)
        written = time.perf_counter() - t0
        mapping = tmp / f"big_{fmt}.map.toml"
        mapping.write_text(mapping_toml(table, fmt, (0.0, 0.0)))
        load = _load()
        row = {"format": fmt, "size_mb": _size_mb(log), "write_s": written, "load": load, **_measure("paper6", log, mapping)}
        rows.append(row)
        _log(f"  {fmt}: {row['size_mb']:.0f} MB, import {row['import_s']:.1f} s ({row['import_cpu_s']:.1f} s CPU), peak {row['peak_mb']:.0f} MB; load {load}")
        for p in [log] if log.is_file() else sorted(log.rglob("*"), reverse=True) + [log]:
            p.rmdir() if p.is_dir() else p.unlink()
    return {"minutes": BIG_MINUTES, "hz": BIG_HZ, "channels": BIG_CHANNELS, "samples": int(d.t.size) * (len(d.yaw) + 4), "rows": rows}


# ---------------------------------------------------------------- replay speed


def replay_figures(cfg: BenchConfig, tmp: Path) -> dict:
    """paper6 from a log of its own run and from the model, alternately (:data:`cfg` logs_replay_steps, logs_reps)."""
    from netsetest.config.schema import load_topology
    from netsetest.logs.drive import with_log_steps
    from netsetest.logs.write import from_truth, mapping_toml, write_log
    from netsetest.runtime.inmemory import run_inmemory

    steps, reps = cfg.logs_replay_steps, cfg.logs_reps
    sc = load_topology("paper6", steps=steps)
    res = run_inmemory(sc, "paper", seed=1)
    assert res.parts is not None
    d = from_truth(res.parts["truth"], sc.tau_s, "synthetic: the benchmark's paper6 run")
    log = write_log(d, tmp / "replay.parquet", "parquet")
    mapping = tmp / "replay.map.toml"
    mapping.write_text(mapping_toml(d, "parquet", (0.0, 0.0)))
    scl = with_log_steps(load_topology("paper6", steps=steps, log=str(log), mapping=str(mapping)))
    times: dict[str, list[tuple[float, float]]] = {"log": [], "model": []}
    estimator: list[float] = []  # per log run: the wall seconds of every node's estimator step (its observer's figure)
    same = True
    for _ in range(reps):
        for name, scenario, seed in (("log", scl, 0), ("model", sc, 1)):
            spent = [0.0]

            def observe(est: object, prev: object, inp: object, res: object, ms: float, spent: list[float] = spent) -> None:
                spent[0] += ms / 1e3

            t0, c0 = time.perf_counter(), time.process_time()
            out = run_inmemory(scenario, "paper", seed=seed, keep=False, observer=observe)
            times[name].append((time.perf_counter() - t0, time.process_time() - c0))
            if name == "log":
                estimator.append(spent[0])
                same &= out.summary.node_steps_contained == out.summary.node_steps_evaluated == res.summary.node_steps_evaluated
    drive_s = steps * sc.tau_s
    med = {n: (statistics.median(w for w, _ in ts), statistics.median(c for _, c in ts)) for n, ts in times.items()}
    est_s = statistics.median(estimator)
    _log(
        f"  replay of {drive_s:g} s: log {med['log'][0]:.2f} s wall ({med['log'][1]:.2f} s CPU; the estimators' steps {est_s:.2f} s), "
        f"model {med['model'][0]:.2f} s"
    )
    return {
        "steps": steps,
        "drive_s": drive_s,
        "reps": reps,
        "log_wall_s": med["log"][0],
        "log_cpu_s": med["log"][1],
        "model_wall_s": med["model"][0],
        "model_cpu_s": med["model"][1],
        "realtime_wall": drive_s / med["log"][0],
        "realtime_cpu": drive_s / med["log"][1],
        "estimator_s": est_s,
        "same_verdict": same,
        "load": _load(),
    }


# ---------------------------------------------------------------- calibrate, then a held-out drive


def _declared_topology(tmp: Path, cal) -> Path:
    """paper6_car with the calibrated mismatch box and envelope, its nodes' profiles with the calibrated noise bounds:
    what a user pastes from ``calibrate --logs``."""
    from netsetest.config.schema import load_topology
    from netsetest.scenarios import TOPOLOGY_DIR

    sc = load_topology("paper6_car")
    nodes = tmp / "nodes"
    nodes.mkdir(exist_ok=True)
    src = TOPOLOGY_DIR.parent / "nodes"  # the bundled profiles, named by their labels
    for n in sc.nodes:
        text = (src / f"{n.label}.toml").read_text()
        (nodes / f"{n.label}.toml").write_text(re.sub(r"(?m)^R = .*$", f"R = {cal.R[n.id]!r}", text, count=1))
    text = (TOPOLOGY_DIR / "paper6_car.toml").read_text().replace('node_dir = "../nodes"', f'node_dir = "{nodes}"')
    text = re.sub(r"\[model_uncertainty\]\nbox = \[[^\]]*\]\n", cal.box.as_toml(), text)
    path = tmp / "paper6_car_calibrated.toml"
    path.write_text(text + "\n" + cal.envelope.as_toml())
    return path


def _write_drive(d, tmp: Path, name: str, accuracy: tuple[float, float]) -> Path:
    from netsetest.logs.write import DriveTable, mapping_toml, write_log

    flat = DriveTable(d.t, d.speed, d.steering, d.yaw, d.beta, d.r, description=d.description)
    log = write_log(flat, tmp / f"{name}.parquet", "parquet")
    (tmp / f"{name}.map.toml").write_text(mapping_toml(flat, "parquet", accuracy))
    return log


def _counts(s) -> dict:
    return {
        "evaluated": s.node_steps_evaluated,
        "contained": s.node_steps_contained,
        "missed": s.node_steps_missed,
        "undecided": s.node_steps_undecided,
        "covered": s.node_steps_covered,
        "not_covered": dict(s.node_steps_not_covered),
        "violations": s.violations_total,
    }


def calibration_figures(cfg: BenchConfig, tmp: Path) -> dict:
    from netsetest.analysis.calibrate import calibrate_logs, check_held_out
    from netsetest.config.schema import load_topology
    from netsetest.logs.drive import with_log_steps
    from netsetest.logs.example import EXAMPLE_TOPOLOGY, example_drive
    from netsetest.runtime.inmemory import run_inmemory

    seeds, train_s, held_s = cfg.logs_train_seeds, cfg.logs_train_s, cfg.logs_held_s
    train = [_write_drive(example_drive(train_s, s, (0.0, 0.0)), tmp, f"train{s}", (0.0, 0.0)) for s in seeds]
    load = lambda topo, log: with_log_steps(load_topology(topo, log=str(log)), whole=True)  # noqa: E731  # a one-line local helper
    cal = calibrate_logs([load(EXAMPLE_TOPOLOGY, log) for log in train])
    steer = HELD_OUT_STEER * load_topology(EXAMPLE_TOPOLOGY).steer_high
    declared = _declared_topology(tmp, cal)
    runs = {}
    for name, acc in (("exact", (0.0, 0.0)), ("ins", INS)):
        log = _write_drive(example_drive(held_s, HELD_OUT_SEED, acc, steer_high=steer), tmp, f"held_{name}", acc)
        sc = load(declared, log)
        held = check_held_out(sc, cal)
        res = run_inmemory(sc, seed=0, keep=False)
        runs[name] = {"accuracy": list(acc), "held_out": {"inside": held.inside, "outside": held.outside, "noise": held.noise}, **_counts(res.summary)}
        _log(f"  held out, reference ± {acc[0]:.3g} rad, ± {acc[1]:.3g} rad/s: {runs[name]}")
    return {
        "train_seeds": list(seeds),
        "train_s": train_s,
        "held_s": held_s,
        "held_seed": HELD_OUT_SEED,
        "held_steer": steer,
        "transitions": cal.transitions,
        "box": np.diag(cal.box.G).tolist(),
        "envelope": {"ay_max": cal.envelope.ay_max, "speed_kmh": list(cal.envelope.speed_kmh)},
        "R": {str(i): R for i, R in cal.R.items()},
        "runs": runs,
        "load": _load(),
    }


def logs_figures(cfg: BenchConfig, tmp: Path) -> dict:
    load_before = _load()
    out: dict[str, object] = {"import": import_figures(tmp)}
    _log("logs: paper6 replayed from a log, beside the model")
    out["replay"] = replay_figures(cfg, tmp)
    _log("logs: calibrate on synthetic drives, then a held-out one")
    out["calibration"] = calibration_figures(cfg, tmp)
    out["load"] = f"{load_before} before, {_load()} after"
    return out


# ---------------------------------------------------------------- report


def targets(doc: dict) -> list[tuple[str, str, str, bool]]:
    """(figure, target, measured, met) for issue 42's targets."""
    return _targets(load_logs(doc))


def _targets(lg: Logs) -> list[tuple[str, str, str, bool]]:
    T, imp, rp = "logs", lg.import_, lg.replay
    bag = imp.bag()
    ex, ins = lg.calibration.runs["exact"], lg.calibration.runs["ins"]
    share = ins.undecided / ins.evaluated if ins.evaluated else float("nan")
    floor = fill(T, "import-floor", bag=bag) if bag.rosbags_cpu_s is not None else ""
    return [
        (
            fill(T, "import-what", imp=imp),
            fill(T, "import-target", target=TARGET_IMPORT_S),
            fill(T, "import-got", bag=bag, floor=floor),
            bag.import_s <= TARGET_IMPORT_S,
        ),
        (fill(T, "peak-what"), fill(T, "peak-target", target=TARGET_PEAK_MB), fill(T, "peak-got", bag=bag), bag.peak_mb <= TARGET_PEAK_MB),
        (
            fill(T, "replay-what"),
            fill(T, "replay-target", target=TARGET_REALTIME),
            fill(T, "replay-got", rp=rp),
            rp.realtime_wall >= TARGET_REALTIME,
        ),
        (fill(T, "exact-what"), fill(T, "exact-target"), fill(T, "exact-got", r=ex), ex.evaluated > 0 and ex.contained == ex.evaluated),
        (fill(T, "ins-what"), fill(T, "ins-target"), fill(T, "ins-got", r=ins, share=100 * share), ins.missed == 0),
    ]


def _target_rows(lg: Logs) -> list[str]:
    return [fill("logs", "target-row", what=what, target=target, got=got, met="yes" if met else "no") for what, target, got, met in _targets(lg)]


def logs_markdown(doc: dict) -> str:
    lg, T = load_logs(doc), "logs"
    imp, rp, cal = lg.import_, lg.replay, lg.calibration
    lines = [fill(T, "head", imp=imp)]
    lines += [fill(T, "import-row", r=r, growth=r.rss_mb[-1] - r.rss_mb[0]) for r in imp.rows]
    bag = next((r for r in imp.rows if r.rosbags_cpu_s is not None), None)
    if bag is not None:
        lines.append(fill(T, "bag", bag=bag))
    lines.append(
        fill(
            T,
            "replay",
            rp=rp,
            split=fill(
                T, "replay-split", rp=rp, share=100 * rp.estimator_s / rp.log_wall_s, rest=rp.log_wall_s - rp.estimator_s, need=rp.drive_s / TARGET_REALTIME
            )
            if rp.estimator_s is not None
            else "",
            cal=cal,
            same=fill(T, "yes" if rp.same_verdict else "no"),
            drives=len(cal.train_seeds),
            seeds=", ".join(map(str, cal.train_seeds)),
        )
    )
    for r in cal.runs.values():
        h = r.held_out
        accuracy = fill(T, "exact") if not any(r.accuracy) else fill(T, "accuracy", beta_deg=math.degrees(r.accuracy[0]), r_deg=math.degrees(r.accuracy[1]))
        causes = ", ".join(f"{c} {n}" for c, n in r.not_covered.items()) or "-"
        lines.append(fill(T, "run-row", accuracy=accuracy, h=h, r=r, inside=h.inside.total(), outside=h.outside.total(), causes=causes))
    lines += [fill(T, "load", load=lg.load), fill(T, "targets-head"), *_target_rows(lg)]
    return "\n".join(lines) + "\n"


def logs_summary_markdown(doc: dict) -> str:
    """The targets alone (docs/your-log.md)."""
    lg = load_logs(doc)
    return "\n".join([fill("logs", "targets-head"), *_target_rows(lg)]) + "\n"


if __name__ == "__main__":  # measure_import in a process of its own: TOPOLOGY LOG MAP
    print(json.dumps(measure_import(*sys.argv[1:4])))


__all__ = ["big_drive", "logs_figures", "logs_markdown", "logs_summary_markdown", "measure_import", "targets"]
