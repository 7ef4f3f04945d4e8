"""Lockstep flow control (issue 33): the vehicle publishes step k + ACK_WINDOW only once the collector has
acknowledged step k, and its End only once the last step is acknowledged (roles/vehicle.py, roles/flow.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from netsetest.bus import keys
from netsetest.bus.base import MAX_PER_KEY, MemoryBus
from netsetest.config.schema import load_topology
from netsetest.messages import Ready
from netsetest.cli.main import main
from netsetest.roles.flow import ACK_STRIDE, ACK_WINDOW, MAX_ACK_WINDOW, UNBOUNDED, Acknowledgments, Hold, parse_window
from netsetest.roles.vehicle import Vehicle
from netsetest.runtime.launcher import LaunchError, LaunchOptions, plan_run
from netsetest.runtime.rolespec import VehicleSpec

ROOT = Path(__file__).resolve().parents[2]
PAPER6 = ROOT / "topologies" / "paper6.toml"
RUN = "u"
STEPS = 3 * ACK_WINDOW


def test_the_window_fits_the_inbox_bound() -> None:
    assert 2 <= ACK_STRIDE <= ACK_WINDOW < MAX_ACK_WINDOW <= MAX_PER_KEY // 2  # a few steps, far inside the bound


def _ack(bus: MemoryBus, step: int) -> None:
    bus.publish(keys.ready_of(RUN, "collector"), Ready(role="collector", seen_all=True, acked=step))
    bus.pump()


def test_the_vehicle_waits_for_the_collector() -> None:
    sc = load_topology(PAPER6, None, STEPS)
    bus = MemoryBus()
    vehicle = Vehicle(sc, bus, RUN, "paper", 0)
    vehicle.advance()  # step 0
    while vehicle.window_open():
        vehicle.advance()  # nobody waits for the nodes here: the window alone
    assert vehicle.k == ACK_WINDOW - 1, "with nothing acknowledged, steps 0 … ACK_WINDOW − 1 go out"
    _ack(bus, 0)
    assert vehicle.window_open()
    vehicle.advance()
    assert not vehicle.window_open()
    _ack(bus, 10 * STEPS)  # more than was published: capped at the vehicle's own step
    assert vehicle.acked == vehicle.k
    bus.publish(keys.ready_of(RUN, "collector"), Ready(role="collector", seen_all=True))  # a start-up Ready: no ack
    bus.pump()
    assert vehicle.acked == vehicle.k
    while vehicle.k < STEPS:
        _ack(bus, vehicle.k - 1)
        vehicle.advance()
    assert vehicle.k == STEPS and not vehicle.window_open(), "the End waits until the last step is acknowledged"
    _ack(bus, STEPS)
    assert vehicle.window_open()


@pytest.mark.parametrize(
    ("value", "window"),
    [(None, ACK_WINDOW), (str(ACK_STRIDE), ACK_STRIDE), (str(MAX_ACK_WINDOW), MAX_ACK_WINDOW), (UNBOUNDED, None), (f" {UNBOUNDED}\n", None)],
)
def test_the_benchmarks_window_setting(value: str | None, window: int | None) -> None:
    """The vehicle's --ack-window (its spec's option; ``netsetest run`` passes it on): left out, the default window."""
    argv = ["vehicle", "paper6"] if value is None else ["vehicle", "paper6", "--ack-window", value]
    assert VehicleSpec.from_argv(argv).ack_window == window
    if value is not None:
        assert parse_window(value) == window


@pytest.mark.parametrize("value", [str(ACK_STRIDE - 1), str(MAX_ACK_WINDOW + 1), str(MAX_PER_KEY), "0", "-8", "8.0", "", "none", "1e9"])
def test_a_window_setting_outside_its_range_is_refused(value: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ValueError, match=f"^must be a whole number of steps from {ACK_STRIDE} .* to {MAX_ACK_WINDOW} "):
        parse_window(value)
    with pytest.raises(SystemExit) as exc:
        VehicleSpec.from_argv(["vehicle", "paper6", "--ack-window", value])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.splitlines()[-1].startswith("netsetest vehicle: error: argument --ack-window: must be a whole number")


def test_run_refuses_a_bad_window_setting_before_any_role_starts(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(LaunchError, match=f"^--ack-window {MAX_PER_KEY}: must be a whole number"):
        plan_run(LaunchOptions(str(PAPER6), steps=3, ack_window=MAX_PER_KEY))
    with pytest.raises(SystemExit) as exc:
        main(["run", str(PAPER6), "--steps", "3", "--quiet", "--ack-window", str(MAX_PER_KEY)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "Traceback" not in err
    assert err.splitlines()[-1].startswith(f"netsetest run: error: argument --ack-window: must be a whole number of steps from {ACK_STRIDE}")


def test_an_unbounded_vehicle_never_waits_for_the_collector_but_before_its_end() -> None:
    sc = load_topology(PAPER6, None, STEPS)
    vehicle = Vehicle(sc, MemoryBus(), RUN, "paper", 0, window=None)
    vehicle.advance()
    while vehicle.window_open():
        vehicle.advance()
    assert vehicle.k == STEPS, "nothing acknowledged, and every step went out"
    assert not vehicle.done, "the End still waits for the last step's acknowledgment"


def test_the_collector_acknowledges_every_stride_and_the_last_step_at_once() -> None:
    """The collector's side (roles/flow.py Acknowledgments): with every truth up to ``head`` taken in."""
    acks = Acknowledgments(last=STEPS)
    assert acks.due(-1) is None and acks.due(ACK_STRIDE - 2) is None
    assert acks.due(ACK_STRIDE - 1) == ACK_STRIDE - 1, "the first stride's step"
    assert acks.due(ACK_STRIDE) is None and acks.due(2 * ACK_STRIDE - 1) == 2 * ACK_STRIDE - 1
    assert acks.due(STEPS - 1) == STEPS - 1 and acks.due(STEPS) == STEPS, "the last step at once: the vehicle's End waits for it"
    assert acks.due(STEPS) is None


def test_a_held_vehicle_says_so_once_and_gives_up_past_the_stall_limit() -> None:
    """The vehicle held by a shut window (roles/flow.py Hold): a collector that still acknowledges is only behind."""
    hold = Hold(tell_after=10.0, limit=60.0)
    assert hold.held(0.0, acked=4) == "waiting" and hold.held(10.5, acked=4) == "tell" and hold.held(11.0, acked=4) == "waiting"
    assert hold.held(50.0, acked=6) == "waiting", "a new acknowledgment: the wait starts again"
    assert hold.held(109.0, acked=6) == "waiting" and hold.held(110.5, acked=6) == "stalled"
    hold.released()
    assert hold.held(200.0, acked=8) == "waiting" and hold.held(210.5, acked=8) == "tell", "a new hold is said again"
