"""The cyclic garbage collector's policy for a run: fewer, larger collections of the young generation.

A run allocates container objects all the time (every decoded message and its lists, the estimator's small lists and
tuples, the judge's rows) and frees nearly all of them by reference counting: the cyclic collector finds almost nothing
to free.  CPython's default still runs it every 700 net allocations, and each run traverses what the young objects
reference: in a 96-node in-memory ring (`netsetest bench`'s scaling, 20 steps), 306 collections took 50–105 µs per
node-step, 5–10 % of the run, and landed inside whatever was running, the estimator's timed step included (measured
with ``gc.callbacks``, 2026-12-08).  Every :data:`YOUNG_THRESHOLD` allocations instead: 18 collections, 24–30 µs per
node-step.  Cycles are still collected, a little later: what that holds meanwhile is at most that many young objects.
Nothing a run computes depends on when the collector runs (no finalizer of ours does anything).
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

YOUNG_THRESHOLD = 10_000  # net allocations of container objects between two young collections (CPython's default: 700)


@contextmanager
def long_run() -> Iterator[None]:
    """The run's policy inside the block (or the decorated function: a role's loop, an in-memory run), the caller's
    restored after it; a threshold the caller set higher, or 0 (the collector off), is kept."""
    old = gc.get_threshold()
    if 0 < old[0] < YOUNG_THRESHOLD:
        gc.set_threshold(YOUNG_THRESHOLD, *old[1:])
    try:
        yield
    finally:
        gc.set_threshold(*old)
