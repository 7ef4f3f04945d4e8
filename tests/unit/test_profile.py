"""The profile's observer of a bus (netsetest/profile.py): with NETSETEST_PROFILE it wraps a bus's methods on the
instance and charges each phase; without it nothing is wrapped, so the hot path carries no profiling code (the class
is never touched).  The node's: tests/inmemory/test_profile_node.py."""

from __future__ import annotations

from netsetest.bus import keys
from netsetest.bus.base import Bus, MemoryBus
from netsetest.messages import Ready
from netsetest.profile import PhaseProfile, observe_bus


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
