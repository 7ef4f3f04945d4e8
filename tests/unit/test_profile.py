"""The profile's observer of a bus (netsetest/profile.py): with a node's ``--profile`` it wraps a bus's methods on the
instance and charges each phase; without it nothing is wrapped, so the hot path carries no profiling code (the class
is never touched).  The node's: tests/inmemory/test_profile_node.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from netsetest.bus import keys
from netsetest.bus.base import Bus, MemoryBus
from netsetest.cli.main import main
from netsetest.messages import Ready
from netsetest.profile import PhaseProfile, observe_bus
from netsetest.runtime.report import EXIT_BAD_INPUT
from netsetest.runtime.rolespec import NodeSpec, ScenarioSpec

PAPER6 = Path(__file__).resolve().parents[2] / "topologies" / "paper6.toml"


def test_an_observed_bus_charges_each_phase_and_another_bus_is_untouched() -> None:
    prof = PhaseProfile()
    bus, plain = MemoryBus(), MemoryBus()
    observe_bus(bus, prof)
    seen: list[str] = []
    bus.subscribe(keys.ready_of("r", "*"), lambda key, msg: seen.append(key))
    plain.subscribe(keys.ready_of("r", "*"), lambda key, msg: seen.append(key))
    bus.publish(keys.ready_of("r", "vehicle"), Ready(role="vehicle"))
    assert bus.pump() == 1 and bus.pump(timeout=0.001) == 0
    assert seen == [keys.ready_of("r", "vehicle")]
    assert {p: prof.calls[p] for p in ("encode", "put", "decode", "handle", "wait")} == {"encode": 1, "put": 1, "decode": 1, "handle": 1, "wait": 1}
    assert prof.messages == {"sent": 1, "received": 1}
    plain.publish(keys.ready_of("r", "vehicle"), Ready(role="vehicle"))
    assert plain.pump() == 1 and prof.calls["handle"] == 1  # the other bus is not observed
    assert "publish" not in vars(plain) and Bus.publish is not bus.publish


def test_profiling_is_an_option_of_the_node_and_of_run_and_a_bad_directory_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A node's ``--profile DIR`` (``run --profile DIR`` passes it to every node; no environment variable): a directory
    the process can write in, else exit 2 with one line naming it; only a Zenoh run has it."""
    sc = ScenarioSpec("paper6")
    assert NodeSpec.from_argv(["node", "paper6", "--id", "1", "--profile", str(tmp_path)]) == NodeSpec(sc, 1, profile=str(tmp_path))
    assert NodeSpec.from_argv(["node", "paper6", "--id", "1"]).profile is None
    missing, a_file = tmp_path / "absent", tmp_path / "f"
    a_file.write_text("")
    for bad in (missing, a_file):
        for argv in (["node", "paper6", "--id", "1", "--profile", str(bad)], ["run", str(PAPER6), "--steps", "2", "--profile", str(bad)]):
            with pytest.raises(SystemExit) as exc:
                main(argv)
            err = capsys.readouterr().err
            assert exc.value.code == 2 and "Traceback" not in err
            assert err.splitlines()[-1].endswith(f"argument --profile: {bad}: not a directory this process can write in")
    assert main(["run", str(PAPER6), "--mode", "inmemory", "--steps", "2", "--quiet", "--profile", str(tmp_path)]) == EXIT_BAD_INPUT
    assert capsys.readouterr().err.startswith("netsetest run: --profile: only a Zenoh run has it")
