"""RunSpec (runtime/runspec.py): the one way a run is built. Its command line is what `netsetest run` parses
back into the same spec, so a campaign's replay command is the run it reports."""

from __future__ import annotations

import os
import shlex

from hypothesis import given, settings
from hypothesis import strategies as st
from test_rolespec import scenarios

from netsetest.cli.main import build_parser
from netsetest.estimator.objective import OBJECTIVES
from netsetest.runtime.argtypes import SEED_MAX
from netsetest.runtime.rolespec import ScenarioSpec
from netsetest.runtime.runspec import RunSpec

EXAMPLES = int(os.environ.get("NETSETEST_FUZZ_EXAMPLES", "0")) or None
ROUND_TRIP = settings(
    max_examples=EXAMPLES or 30,  # the full parser per example: test_rolespec fuzzes the scenario part harder
    derandomize=EXAMPLES is None,
    deadline=None,
    database=None,
)
CLI = build_parser()

runs = st.builds(
    RunSpec,
    scenarios,
    st.sampled_from(["paper", "worst"]),
    st.sampled_from(["scheduled", "per-rule"]),
    st.sampled_from(list(OBJECTIVES)),
    st.integers(0, SEED_MAX),
)


@ROUND_TRIP
@given(runs)
def test_run_parses_the_replay_command_into_the_same_spec(spec: RunSpec) -> None:
    argv = spec.argv()
    assert argv[0] == "run" and "--mode" in argv and argv[argv.index("--mode") + 1] == "inmemory"
    assert RunSpec.from_namespace(CLI.parse_args(argv)) == spec
    assert shlex.split(spec.command()) == ["netsetest", *argv]


def test_defaults_are_left_out_but_the_seed_is_always_given() -> None:
    assert RunSpec(ScenarioSpec("paper6")).argv() == ["run", "paper6", "--mode", "inmemory", "--seed", "0"]
    spec = RunSpec(ScenarioSpec("paper6", "saim", 20, "interval", manoeuvre="sine-dwell@0.03", speed=90.0, fault_scale=0.5), "worst", seed=7)
    assert spec.argv() == [
        *("run", "paper6", "--case", "saim", "--steps", "20", "--estimator", "interval", "--manoeuvre", "sine-dwell@0.03"),
        *("--speed", "90.0", "--fault-scale", "0.5", "--mode", "inmemory", "--signals", "worst", "--seed", "7"),
    ]
