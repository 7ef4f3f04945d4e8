"""One in-memory run as ``netsetest run --mode inmemory`` starts it: its typed spec, its command line, the run.

``netsetest run --mode inmemory``, :func:`netsetest.simulate` and every run of a campaign (netsetest/campaign/)
are built from a :class:`RunSpec` and run by :meth:`RunSpec.execute` (``run_inmemory`` underneath), so a
campaign's row is what its replay command, :meth:`RunSpec.command`, prints.  ``RunSpec.from_namespace`` of
``run``'s parsed :meth:`RunSpec.argv` is the spec again (tests/unit/test_runspec.py).
"""

from __future__ import annotations

import shlex
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from netsetest.estimator.objective import DEFAULT_OBJECTIVE
from netsetest.runtime.rolespec import ScenarioSpec

if TYPE_CHECKING:
    import argparse

    from netsetest.config.schema import Scenario
    from netsetest.estimator.objective import Objective
    from netsetest.estimator.sdp import StepObserver, Variant
    from netsetest.models.signals import SignalKind
    from netsetest.runtime.inmemory import RunResult
    from netsetest.runtime.stops import StopRequests

DEFAULT_SIGNALS: SignalKind = "paper"
DEFAULT_VARIANT: Variant = "scheduled"


@dataclass(frozen=True)
class RunSpec:
    """Which scenario (the topology and its overrides) and the run's own settings; the seed is always given
    (``run`` draws a fresh one when it is not, and prints it: a spec names the run it is)."""

    scenario: ScenarioSpec
    signals: SignalKind = DEFAULT_SIGNALS
    variant: Variant = DEFAULT_VARIANT
    objective: Objective = DEFAULT_OBJECTIVE
    seed: int = 0

    def argv(self) -> list[str]:
        """``["run", TOPOLOGY, "--mode", "inmemory", ...]``: options at their default left out, the seed always."""
        out = ["run", *self.scenario.to_argv(), "--mode", "inmemory"]
        out += ["--signals", self.signals] if self.signals != DEFAULT_SIGNALS else []
        out += ["--variant", self.variant] if self.variant != DEFAULT_VARIANT else []
        out += ["--objective", self.objective] if self.objective != DEFAULT_OBJECTIVE else []
        return [*out, "--seed", str(self.seed)]

    def command(self) -> str:
        """The shell command that replays this run (``--record`` added keeps its record)."""
        return shlex.join(["netsetest", *self.argv()])

    @classmethod
    def from_namespace(cls, a: argparse.Namespace) -> RunSpec:
        """The spec of ``run``'s parsed options (the seed already drawn where none was given)."""
        scenario = ScenarioSpec(
            a.topology, a.case, a.steps, a.estimator, log=a.log, mapping=a.map, manoeuvre=a.manoeuvre, speed=a.speed, fault_scale=a.fault_scale
        )
        return cls(scenario, a.signals, a.variant, a.objective, a.seed)

    def load(self) -> Scenario:
        """The run's scenario (ConfigError naming what is wrong): the spec's, a recorded drive's steps decided
        against its log (logs/drive.py ``with_log_steps``, as ``run`` decides them)."""
        from netsetest.logs.drive import with_log_steps

        return with_log_steps(self.scenario.load())

    def execute(
        self,
        progress: bool = False,
        record: str | None = None,
        keep: bool = True,
        on_step: Callable[[int], None] | None = None,
        observer: StepObserver | None = None,
        scenario: Scenario | None = None,
        stop: StopRequests | None = None,
    ) -> RunResult:
        """Load the scenario (:meth:`load`) and run it in this process (runtime/inmemory.py); ``scenario``: this
        spec's, already loaded (a campaign's worker checks its files' digest first); ``stop``: signals noted there end the
        run early with an "interrupted" summary (``run``'s Ctrl-C: runtime/inmemory.py)."""
        from netsetest.runtime.inmemory import run_inmemory

        return run_inmemory(
            scenario or self.load(),
            self.signals,
            self.variant,
            self.seed,
            progress=progress,
            record=record,
            keep=keep,
            on_step=on_step,
            objective=self.objective,
            observer=observer,
            stop=stop,
        )
