"""Every role's loop and the in-memory run collect garbage under the run's policy (netsetest/runtime/gc_policy.py):
the young threshold is raised while the run's steps are taken, the caller's restored after."""

from __future__ import annotations

import gc

from netsetest.config.schema import load_topology
from netsetest.runtime import processes
from netsetest.runtime.gc_policy import YOUNG_THRESHOLD, long_run
from netsetest.runtime.inmemory import run_inmemory


def test_an_inmemory_run_steps_under_the_policy() -> None:
    seen: list[int] = []
    before = gc.get_threshold()
    run_inmemory(load_topology("paper6", steps=2), observer=lambda *args: seen.append(gc.get_threshold()[0]))
    assert seen and set(seen) == {max(YOUNG_THRESHOLD, before[0])}
    assert gc.get_threshold() == before


def test_the_role_loops_run_under_the_policy() -> None:
    """A role process's loop is decorated with the policy: its wrapper holds a long_run context manager (contextlib's
    decorator form, which enters a fresh one per call)."""
    for run in (processes.run_vehicle, processes.run_node, processes.run_collector):
        held = [c.cell_contents for c in run.__closure__ or ()]
        assert any(getattr(c, "func", None) is long_run.__wrapped__ for c in held), run.__name__  # type: ignore[attr-defined]  # contextmanager keeps the generator function
