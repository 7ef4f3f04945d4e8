"""A recorded drive, step by step: what the vehicle role publishes when a log is the world (docs/your-log.md).

:class:`LogDrive` reads the whole log once as a stream to check it and to plan the run (:func:`plan_log`, the
import), then streams it again as the steps go (logs/readers.py, logs/align.py): a role never holds the log, only
the samples a step needs and the reorder window.  Step k gives the inputs (u_k the road-wheel angle, the speed and the Vx
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
from netsetest.logs.align import StepAligner, step_time
from netsetest.logs.readers import MAX_GAPS, NEVER, LogError, SignalScan, open_stream, scan_signals

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


@dataclass(frozen=True)
class LogPlan:
    """What the whole log gives a run (its import, :func:`plan_log`): step 0's log time [ns], the last step both
    inputs reach, the first step (if any) at which an input has no sample within the tolerance, and each signal's
    scan (logs/readers.py)."""

    start_ns: int
    last_step: int
    scans: dict[str, SignalScan]

    def first_missing(self, name: str, tau_ns: int, tol: int, steps: int, first: int = 0) -> tuple[int, int] | None:
        """(step, age of its newest sample [ns]) of the first step in ``first``..``steps`` at which signal ``name`` has no
        sample within the tolerance, or None: before its first sample, inside a gap (a, b) (the steps strictly inside
        (a + tol, b)), or after its last sample plus the tolerance."""
        sc, start = self.scans[name], self.start_ns
        if start + first * tau_ns < sc.first_ns:
            return first, NEVER
        if sc.more_gaps:
            raise LogError(f"{name}: more than {MAX_GAPS} gaps longer than the gap tolerance {tol / 1e9:g} s: is it sampled that slowly?")
        for a, b in (*sc.gaps, (sc.last_ns, NEVER)):
            k = max(first, (a + tol - start) // tau_ns + 1)
            if k <= steps and start + k * tau_ns < b:
                return int(k), start + k * tau_ns - a
        return None


def _tolerance_ns(sc: Scenario) -> int:
    assert sc.log is not None
    g = sc.log.mapping.gap_tolerance_s
    return round((g if g is not None else DEFAULT_GAP_STEPS * sc.tau_s) * 1e9)


@functools.lru_cache(maxsize=4)
def _plan(path: str, stamp: tuple[int, int], mapping: LogMapping, tau_ns: int, tol: int) -> LogPlan:
    scans = scan_signals(Path(path), mapping, tol)
    if mapping.start_s is not None:
        start = round(mapping.start_s * 1e9)
    else:  # the latest first sample of the inputs and readings: every one of them has a value at step 0
        start = max(scans[s.name].first_ns for s in (*mapping.inputs, *(m.signal for m in mapping.sensors)))
    end = min(scans[s.name].last_ns for s in mapping.inputs)
    last = (end + tol - start) // tau_ns  # step times up to the last input sample plus its tolerance
    if last < 1:
        raise LogError(f"{path}: the log's inputs cover less than two steps of τs = {tau_ns / 1e9:g} s from t = {start / 1e9:.6g} s")
    return LogPlan(start, int(last), scans)


def plan_log(sc: Scenario) -> LogPlan:
    """The log read once, in this process (cached: the steps' count and the drive share it; a changed file is read again)."""
    assert sc.log is not None
    st = Path(sc.log.path).stat()
    return _plan(sc.log.path, (st.st_mtime_ns, st.st_size), sc.log.mapping, round(sc.tau_s * 1e9), _tolerance_ns(sc))


def log_steps(sc: Scenario) -> int:
    """The last step the log can give the run: every step up to it has both inputs within the gap tolerance
    (a gap inside them is reported by the drive itself)."""
    return plan_log(sc).last_step


def with_log_steps(sc: Scenario, whole: bool = False) -> Scenario:
    """The scenario with the run's steps decided against the log: every step it holds when none were given (or
    ``whole``: whatever was given, as ``calibrate --logs`` reads each log), else the given ones if the log holds them
    (LogError otherwise)."""
    if sc.log is None:
        return sc
    have = log_steps(sc)
    if sc.log.steps_given and not whole:
        if sc.steps > have:
            raise LogError(
                f"{sc.log.path}: the log holds steps 0–{have} of τs = {sc.tau_s:g} s, the run asks 0–{sc.steps}: "
                f"give --steps {have} or less (a log shorter than the run is never padded)"
            )
        return sc
    return dataclasses.replace(sc, steps=have, log=dataclasses.replace(sc.log, steps_given=True))


class LogDrive:
    """The recorded drive of a run (module doc): its import checks the whole log (:func:`plan_log`), then
    :meth:`step` gives step k, in increasing order, reading the log only as far as step k needs."""

    def __init__(self, sc: Scenario) -> None:
        assert sc.log is not None
        self.sc, m = sc, sc.log.mapping
        path = sc.log.path
        plan = plan_log(sc)
        self.start_ns, self.tau_ns, tol = plan.start_ns, round(sc.tau_s * 1e9), _tolerance_ns(sc)
        for sig in m.inputs:
            gap = plan.first_missing(sig.name, self.tau_ns, tol, sc.steps)
            if gap is not None:
                k, age = gap
                seen = "no sample before it" if age == NEVER else f"its newest sample {age / 1e9:.3g} s old"
                raise LogError(
                    f"{path}: {sig.name} missing at step {k} (t = {(self.start_ns + k * self.tau_ns) / 1e9:.6g} s: {seen}, gap tolerance {tol / 1e9:g} s): "
                    "an input the model needs at every step (choose the steps with [log] start_s and --steps, or a larger gap_tolerance_s)"
                )
        p = sc.model.params
        speed = plan.scans[m.speed.name]
        if speed.hi < p.vx_min or speed.lo > p.vx_max:
            raise LogError(
                f"{path}: speed: the log's {speed.lo * 3.6:.1f}–{speed.hi * 3.6:.1f} km/h never reaches the model's "
                f"{p.vx_min * 3.6:.0f}–{p.vx_max * 3.6:.0f} km/h: is the mapping's speed unit right (or the topology's vx_min_kmh, vx_max_kmh)?"
            )
        self._check_gaps(plan, tol)
        self.aligner = StepAligner(open_stream(Path(path), m), tol)

    def _check_gaps(self, plan: LogPlan, tol: int) -> None:
        """A node running a set estimator carries its fault through a step > 0 without its reading by its declared fault
        bound alone (estimator/base.py): without one, a gap after step 0 is refused (step 0's is the prior's)."""
        sc = self.sc
        assert sc.log is not None
        for s in sc.log.mapping.sensors:
            n = sc.node(s.node)
            problem = None if n.estimator == SDP else n.gap_problem()
            gap = None if problem is None else plan.first_missing(s.signal.name, self.tau_ns, tol, sc.steps, first=1)  # step 0's: the prior
            if gap is not None:
                raise LogError(
                    f"{sc.log.path}: yaw rate of node {s.node} missing at step {gap[0]}: node {s.node} runs {n.estimator}; {problem} "
                    "(or choose the steps around the gap: docs/your-log.md)"
                )

    def step(self, k: int) -> LogStep:
        """Step k (k ≥ the last step asked: the log streams)."""
        sc = self.sc
        m = sc.log.mapping  # type: ignore[union-attr]  # a log's drive
        t_ns = step_time(self.start_ns, self.tau_ns, k)
        at = self.aligner.at(t_ns)
        t_s = t_ns / 1e9
        ref = None
        if m.beta is not None and m.r is not None and at[m.beta.name].present and at[m.r.name].present:
            ref = np.array([at[m.beta.name].value, at[m.r.name].value])
        speed = at[m.speed.name].value
        p = sc.model.params
        return LogStep(
            k=k,
            t_s=t_s,
            u=at[m.steering.name].value,
            speed=speed,
            vx=min(max(speed, p.vx_min), p.vx_max),
            y_log={s.node: (at[s.signal.name].value if at[s.signal.name].present else None) for s in m.sensors},
            faults={n.id: n.fault(k) for n in sc.nodes},
            healthy={s.node: s.healthy_at(t_s) for s in m.sensors},
            x_ref=ref,
            accuracy=m.accuracy,
        )


__all__ = ["LogDrive", "LogError", "LogPlan", "LogStep", "log_steps", "plan_log", "with_log_steps"]
