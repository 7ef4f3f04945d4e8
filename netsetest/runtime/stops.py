"""Stop requests: SIGTERM and SIGINT noted where a loop can stop safely, instead of raised wherever the signal lands
(the Zenoh collector's loop, runtime/processes.py; the in-memory run, runtime/inmemory.py)."""

from __future__ import annotations

import signal


class StopRequests:
    """SIGTERM/SIGINT noted, not raised, while this context is open (the handlers before are restored after): for
    a loop that must stop only where it is safe.  The collector's: an exception raised by the handler in the middle
    of a step it was writing (between two node-states, or between a line's number and the line) left the step
    half-written, and closing the run then wrote it again: a Ctrl-C'd record was damaged 1 time in 8 (issue 41)."""

    def __init__(self) -> None:
        self.signal: str | None = None  # the last signal's name (None: none came)
        self._before: dict[int, object] = {}

    def _note(self, signum: int, frame: object) -> None:
        self.signal = signal.Signals(signum).name

    def __enter__(self) -> StopRequests:
        for sig in (signal.SIGTERM, signal.SIGINT):
            self._before[sig] = signal.signal(sig, self._note)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._before.items():
            signal.signal(sig, handler)  # type: ignore[arg-type]  # what signal.signal returned: a handler or a constant
