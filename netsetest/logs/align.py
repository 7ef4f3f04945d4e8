"""Putting a channel's samples on the run's steps as the log streams, one rule for every signal (docs/your-log.md).

Step k is at log time t_k = start + k·τs, in integer nanoseconds (a sample stamped exactly at a step is at it,
whatever the file's time unit).  The value of a channel at step k is its newest sample stamped at or before t_k
(a zero-order hold for the inputs, the sample at or before the step for the readings and the reference) if that
sample is at most the gap tolerance old; otherwise the channel has no value at step k: a missing measurement for
a reading, no reference for the truth, and an error for an input the model needs.  A sample is never used at a
step before it was taken, and a gap is never filled.

:class:`StepAligner` reads the stream (logs/readers.py :class:`~netsetest.logs.readers.SampleStream`) only as far
as step k needs: until every sample stamped at or before t_k is final, keeping per signal its newest sample at
or before the step and the few after it already read.  Steps are asked in increasing order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from netsetest.logs.readers import NEVER, SampleStream


@dataclass(frozen=True)
class Sample:
    """A channel at a step: its newest sample at or before the step (``value``; NaN where there is none) and that
    sample's age [ns] (:data:`~netsetest.logs.readers.NEVER` where there is none); ``present``: within the tolerance."""

    value: float
    age_ns: int
    present: bool


def step_time(start_ns: int, tau_ns: int, k: int) -> int:
    """t_k = start + k·τs [ns]."""
    return start_ns + tau_ns * k


class StepAligner:
    """Each step's newest sample of every signal, as the stream goes (module doc)."""

    def __init__(self, stream: SampleStream, tolerance_ns: int) -> None:
        self.stream, self.tol = stream, tolerance_ns
        self.newest: dict[str, tuple[int, float] | None] = dict.fromkeys(stream.sigs)  # at or before the last step asked
        self.ahead: dict[str, tuple[np.ndarray, np.ndarray]] = {n: (np.empty(0, dtype=np.int64), np.empty(0)) for n in stream.sigs}
        self.t_prev = -NEVER

    def at(self, t_ns: int) -> dict[str, Sample]:
        """Every signal at step time ``t_ns`` (not earlier than the last one asked)."""
        if t_ns < self.t_prev:
            raise ValueError("steps are aligned in increasing order")
        self.t_prev = t_ns
        s = self.stream
        while any(s.horizon(n) < t_ns for n in s.sigs) and s.pull():
            pass
        out = {}
        for name in s.sigs:
            t, v = s.take(name)
            at, av = self.ahead[name]
            if t.size:
                at, av = (t, v) if not at.size else (np.concatenate([at, t]), np.concatenate([av, v]))
            i = int(np.searchsorted(at, t_ns, side="right"))
            if i:
                self.newest[name] = (int(at[i - 1]), float(av[i - 1]))
                at, av = at[i:], av[i:]
            self.ahead[name] = (at, av)
            last = self.newest[name]
            age = NEVER if last is None else t_ns - last[0]
            present = age <= self.tol
            out[name] = Sample(last[1] if present and last is not None else float("nan"), age, present)
        return out


__all__ = ["Sample", "StepAligner", "step_time"]
