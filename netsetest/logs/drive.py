"""A recorded drive, step by step: what the vehicle role publishes when a log is the world (docs/your-log.md).

:class:`LogDrive` reads the mapped signals once (logs/readers.py), puts them on the run's steps (logs/align.py)
and keeps only those per-step arrays.  Step k gives the inputs (u_k the road-wheel angle, the speed and the Vx
the model is scheduled with), each node's reading ỹ_i,k (None: a missing measurement) with the declared fault
f_i(k) of its profile injected on top (ỹ = logged + Ds·f: the fault is known, the noise is real), and the truth
as far as the reference proves it: x_k in the box x_ref ± accuracy, each node's fault exactly the injected one
where the logged sensor is declared healthy, else the interval its reading less the reference leaves (within
its noise bound and the accuracy).

Rules of time (the stated ones, also in docs/your-log.md): step 0 is at ``[log] start_s``, by default the
latest first sample of the inputs and readings; the gap tolerance defaults to 0.5 τs; an input (speed,
steering) without a sample within the tolerance at a step the run takes is an error (the model needs it at
every step); a log that cannot give the run's steps is an error (``--steps`` at most what it holds); without
``steps`` in the topology or ``--steps`` the run takes every step the log holds (:func:`with_log_steps`).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from netsetest.config.logmap import LogMapping
from netsetest.estimator.names import SDP
from netsetest.logs.align import Aligned, at_or_before, step_times
from netsetest.logs.readers import Channel, LogError, read_signals

if TYPE_CHECKING:
    from netsetest.config.schema import Scenario

DEFAULT_GAP_STEPS = 0.5  # the gap tolerance in τs when the mapping declares none: a sensor sampled every τs never gives one sample to two steps


@dataclass(frozen=True)
class LogStep:
    """Step k of a recorded drive (module doc): the inputs, the readings (None: missing) and the reference."""

    k: int
    t_s: float  # the step's log time
    u: float  # road-wheel steering angle [rad]
    speed: float  # the logged speed [m/s]
    vx: float  # the speed the T-S model is scheduled with: the logged one held inside the model's range
    y_log: dict[int, float | None]  # node → the logged reading [rad/s] (None: a missing measurement)
    faults: dict[int, float]  # node → the injected fault f_i(k)
    healthy: dict[int, bool]  # node → the logged sensor declared fault-free at this step
    x_ref: np.ndarray | None  # (2,) the reference's β, r (None: no reference at this step)
    accuracy: tuple[float, float]  # the reference's half-widths (β, r)


@functools.lru_cache(maxsize=2)
def _signals(path: str, mapping: LogMapping) -> dict[str, Channel]:
    """The cleaned mapped signals (one read per process: the steps' count and the drive share it)."""
    return read_signals(Path(path), mapping)


def _start_ns(mapping: LogMapping, ch: dict[str, Channel]) -> int:
    if mapping.start_s is not None:
        return round(mapping.start_s * 1e9)
    firsts = [int(ch[s.name].t_ns[0]) for s in (mapping.speed, mapping.steering, *(m.signal for m in mapping.sensors))]
    return max(firsts)


def log_steps(sc: Scenario) -> int:
    """The last step the log can give the run: every step up to it has both inputs within the gap tolerance
    (a gap inside them is reported by the drive itself)."""
    assert sc.log is not None
    m = sc.log.mapping
    ch = _signals(sc.log.path, m)
    start = _start_ns(m, ch)
    end = min(int(ch[s.name].t_ns[-1]) for s in (m.speed, m.steering))
    tau_ns = round(sc.tau_s * 1e9)
    tol = _tolerance_ns(sc)
    last = (end + tol - start) // tau_ns  # step times up to the last input sample plus its tolerance
    if last < 1:
        raise LogError(f"{sc.log.path}: the log's inputs cover less than two steps of τs = {sc.tau_s:g} s from t = {start / 1e9:.6g} s")
    return int(last)


def _tolerance_ns(sc: Scenario) -> int:
    assert sc.log is not None
    g = sc.log.mapping.gap_tolerance_s
    return round((g if g is not None else DEFAULT_GAP_STEPS * sc.tau_s) * 1e9)


def with_log_steps(sc: Scenario) -> Scenario:
    """The scenario with the run's steps decided against the log: every step it holds when none were given,
    else the given ones if the log holds them (LogError otherwise)."""
    if sc.log is None:
        return sc
    have = log_steps(sc)
    if sc.log.steps_given:
        if sc.steps > have:
            raise LogError(
                f"{sc.log.path}: the log holds steps 0–{have} of τs = {sc.tau_s:g} s, the run asks 0–{sc.steps}: "
                f"give --steps {have} or less (a log shorter than the run is never padded)"
            )
        return sc
    return dataclasses.replace(sc, steps=have, log=dataclasses.replace(sc.log, steps_given=True))


class LogDrive:
    """The recorded drive of a run (module doc); :meth:`step` gives step k, in any order."""

    def __init__(self, sc: Scenario) -> None:
        assert sc.log is not None
        self.sc, m = sc, sc.log.mapping
        path = sc.log.path
        ch = _signals(path, m)
        tau_ns = round(sc.tau_s * 1e9)
        self.start_ns = _start_ns(m, ch)
        tol = _tolerance_ns(sc)
        t = step_times(self.start_ns, tau_ns, sc.steps)
        self.t_s = t / 1e9
        al = {name: at_or_before(c.t_ns, c.v, t, tol) for name, c in ch.items()}
        for s in (m.speed, m.steering):
            self._inputs_present(path, s.name, al[s.name], tol)
        self.u, self.speed = al[m.steering.name].value, al[m.speed.name].value
        p = sc.model.params
        self.vx = np.clip(self.speed, p.vx_min, p.vx_max)
        self.y = {s.node: al[s.signal.name] for s in m.sensors}
        for i, a in self.y.items():
            if not a.present[0]:
                raise LogError(
                    f"{path}: yaw rate of node {i}: no sample within the gap tolerance {tol / 1e9:g} s at step 0 (t = {self.t_s[0]:.6g} s): "
                    "a run starts with every reading (choose [log] start_s, or leave it to the default: the latest first sample)"
                )
            if not a.present.all() and sc.node(i).estimator != SDP:
                k = int(np.flatnonzero(~a.present)[0])
                raise LogError(
                    f"{path}: yaw rate of node {i} missing at step {k} (t = {self.t_s[k]:.6g} s): node {i} runs {sc.node(i).estimator}, "
                    "which cannot resume after a missing measurement (the sdp estimator does: docs/your-log.md); choose the steps around the gap"
                )
        self.healthy = {s.node: np.array([s.healthy_at(ts) for ts in self.t_s]) for s in m.sensors}
        self.ref: tuple[Aligned, Aligned] | None = None if m.beta is None or m.r is None else (al[m.beta.name], al[m.r.name])
        speed_kmh = self.speed * 3.6
        inside = (self.speed >= p.vx_min) & (self.speed <= p.vx_max)
        if not inside.any():
            raise LogError(
                f"{path}: speed: the log's {speed_kmh.min():.1f}–{speed_kmh.max():.1f} km/h never reaches the model's "
                f"{p.vx_min * 3.6:.0f}–{p.vx_max * 3.6:.0f} km/h: is the mapping's speed unit right (or the topology's vx_min_kmh, vx_max_kmh)?"
            )

    def _inputs_present(self, path: str, name: str, a: Aligned, tol: int) -> None:
        gone = np.flatnonzero(~a.present)
        if gone.size:
            k = int(gone[0])
            age = "no sample before it" if a.age_ns[k] == np.iinfo(np.int64).max else f"its newest sample {a.age_ns[k] / 1e9:.3g} s old"
            raise LogError(
                f"{path}: {name} missing at step {k} (t = {self.t_s[k]:.6g} s: {age}, gap tolerance {tol / 1e9:g} s): an input the model needs "
                "at every step (choose the steps with [log] start_s and --steps, or a larger gap_tolerance_s)"
            )

    def step(self, k: int) -> LogStep:
        ref = None
        if self.ref is not None and self.ref[0].present[k] and self.ref[1].present[k]:
            ref = np.array([self.ref[0].value[k], self.ref[1].value[k]])
        y = {i: (float(a.value[k]) if a.present[k] else None) for i, a in self.y.items()}
        assert self.sc.log is not None
        return LogStep(
            k=k,
            t_s=float(self.t_s[k]),
            u=float(self.u[k]),
            speed=float(self.speed[k]),
            vx=float(self.vx[k]),
            y_log=y,
            faults={n.id: n.fault(k) for n in self.sc.nodes},
            healthy={i: bool(h[k]) for i, h in self.healthy.items()},
            x_ref=ref,
            accuracy=self.sc.log.mapping.accuracy,
        )


__all__ = ["LogDrive", "LogError", "LogStep", "log_steps", "with_log_steps"]
