"""Putting a channel's samples on the run's steps, one rule for every signal (docs/your-log.md).

Step k is at log time t_k = start + k·τs, in integer nanoseconds (a sample stamped exactly at a step is at it,
whatever the file's time unit).  The value of a channel at step k is its newest sample stamped at or before t_k
(a zero-order hold for the inputs, the sample at or before the step for the readings and the reference) if that
sample is at most the gap tolerance old; otherwise the channel has no value at step k: a missing measurement for
a reading, no reference for the truth, and an error for an input the model needs.  A sample is never used at a
step before it was taken, and a gap is never filled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Aligned:
    """A channel on the steps: ``value[k]`` (NaN where missing), ``present[k]``, and the age of the sample used [ns]."""

    value: np.ndarray
    present: np.ndarray
    age_ns: np.ndarray


def step_times(start_ns: int, tau_ns: int, steps: int) -> np.ndarray:
    """t_k = start + k·τs for k = 0..steps, int64 nanoseconds."""
    return start_ns + tau_ns * np.arange(steps + 1, dtype=np.int64)


def at_or_before(t_ns: np.ndarray, v: np.ndarray, steps_ns: np.ndarray, tolerance_ns: int) -> Aligned:
    """Each step's newest sample at or before it, no older than ``tolerance_ns`` (``t_ns`` sorted: readers.clean)."""
    idx = np.searchsorted(t_ns, steps_ns, side="right") - 1
    have = idx >= 0
    safe = np.where(have, idx, 0)
    age = np.where(have, steps_ns - t_ns[safe], np.iinfo(np.int64).max)
    present = have & (age <= tolerance_ns)
    return Aligned(np.where(present, v[safe], np.nan), present, age)


__all__ = ["Aligned", "at_or_before", "step_times"]
