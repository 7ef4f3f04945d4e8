"""Lockstep flow control (issue 33): the vehicle publishes step k + ACK_WINDOW only once the collector has
acknowledged step k, and its End only once the last step is acknowledged (roles/vehicle.py)."""

from __future__ import annotations

from pathlib import Path

from netsetest.bus import keys
from netsetest.bus.base import MAX_PER_KEY, MemoryBus
from netsetest.config.schema import load_topology
from netsetest.messages import Ready
from netsetest.roles.vehicle import ACK_STRIDE, ACK_WINDOW, Vehicle

ROOT = Path(__file__).resolve().parents[2]
RUN = "u"
STEPS = 3 * ACK_WINDOW


def test_the_window_fits_the_inbox_bound() -> None:
    assert 2 <= ACK_STRIDE <= ACK_WINDOW < MAX_PER_KEY // 2  # a few steps, far inside the bound


def _ack(bus: MemoryBus, step: int) -> None:
    bus.publish(keys.ready_of(RUN, "collector"), Ready(role="collector", seen_all=True, acked=step))
    bus.pump()


def test_the_vehicle_waits_for_the_collector() -> None:
    sc = load_topology(ROOT / "topologies" / "paper6.toml", None, STEPS)
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
