"""echo and watch close their Zenoh session however a stop signal falls (an open session keeps the
interpreter from exiting: CI once saw `watch` hang after a Ctrl-C that arrived while it opened)."""

from __future__ import annotations

import argparse
import signal

import pytest

from netsetest.cli import tools


class FakeObserver:
    def __init__(self) -> None:
        self.closed = 0

    def close(self) -> None:
        self.closed += 1


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("when", ["opening", "observing", "closing"])
def test_a_stop_signal_at_any_moment_closes_the_session_once(sig: int, when: str, monkeypatch) -> None:
    """The signal is raised in this (the main) thread, so its handler runs at once, as Ctrl-C does in the
    single-threaded observer: a signal to the process may land in another thread (a pytest-xdist worker has
    one), and its handler then runs later, maybe after the handlers were restored (a stray KeyboardInterrupt)."""
    fake = FakeObserver()
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}

    def opening(a: argparse.Namespace, key: str | None) -> FakeObserver:
        if when == "opening":
            signal.raise_signal(sig)
        return fake

    def closing() -> None:
        if when == "closing":
            signal.raise_signal(sig)  # a second Ctrl-C while closing cannot cut the close short
        fake.closed += 1

    monkeypatch.setattr(tools, "_open_observer", opening)
    monkeypatch.setattr(fake, "close", closing)
    with tools.observing(argparse.Namespace(), None) as (obs, stop):
        assert obs is fake
        assert stop.requested == (when == "opening")  # the loop would not even start
        if when == "observing":
            signal.raise_signal(sig)
            assert stop.requested
    assert fake.closed == 1
    assert stop.requested
    assert {s: signal.getsignal(s) for s in handlers} == handlers  # the caller's handlers are back


def test_an_observer_that_cannot_open_restores_the_handlers(monkeypatch) -> None:
    def failing(a: argparse.Namespace, key: str | None) -> FakeObserver:
        raise tools.ObserverError("--credentials: no such directory")

    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    monkeypatch.setattr(tools, "_open_observer", failing)
    with pytest.raises(tools.ObserverError), tools.observing(argparse.Namespace(), None):
        pytest.fail("the body ran without a session")
    assert {s: signal.getsignal(s) for s in handlers} == handlers
