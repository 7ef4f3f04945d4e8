"""The collector's report to the launcher of its run: progress and the summary, as typed messages on a pipe.

The launcher (runtime/launcher.py) gives the collector the write end of a pipe as file descriptor
:data:`CHANNEL_FD` (``netsetest collector --channel-fd 3``; the fork server puts it there).  The collector
sends :class:`StepChecked` whenever its progress advances and :class:`RunFinished` with the run summary
once it is written; the launcher's :class:`ChannelReader` decodes them into these dataclasses.  Nothing
else is written on the pipe (the collector's stdout and stderr stay what they are), so nothing is parsed
out of text meant for people.

Wire form: one JSON object per line, ``{"type": "step", "step": K}`` or ``{"type": "finished",
"summary": {...}}`` (the summary as :meth:`RunSummary.to_dict`, the same document as ``--summary-json``).
"""

from __future__ import annotations

import json
import os
import threading
import time
from dataclasses import dataclass
from typing import IO, TYPE_CHECKING

if TYPE_CHECKING:  # a node process never loads the summary (it does not import this module either)
    from netsetest.records.summary import RunSummary

CHANNEL_FD = 3  # where a forked collector finds the channel's write end (the first descriptor after stdin, stdout, stderr)


class ChannelError(ValueError):
    """A line on the channel that is not one of its messages."""


@dataclass(frozen=True)
class StepChecked:
    """The collector has judged every step up to ``step`` (the launcher's progress bar, its --rejoin schedule)."""

    step: int


@dataclass(frozen=True)
class RunFinished:
    """The collector's summary of the run (at End, when the vehicle is gone, or when stopped)."""

    summary: RunSummary


ChannelMessage = StepChecked | RunFinished


def encode(msg: ChannelMessage) -> bytes:
    if isinstance(msg, StepChecked):
        doc: dict[str, object] = {"type": "step", "step": msg.step}
    else:
        doc = {"type": "finished", "summary": msg.summary.to_dict()}
    return json.dumps(doc, separators=(",", ":")).encode() + b"\n"


def decode(line: bytes) -> ChannelMessage:
    """One line of the channel as its message (ChannelError if it is none)."""
    try:
        doc = json.loads(line)
        kind = doc["type"]
        if kind == "step" and type(doc["step"]) is int:
            return StepChecked(doc["step"])
        if kind == "finished":
            from netsetest.records.summary import RunSummary

            return RunFinished(RunSummary.from_dict(doc["summary"]))
    except (ValueError, TypeError, KeyError) as exc:
        raise ChannelError(f"not a channel message ({exc})") from None
    raise ChannelError(f"not a channel message: {line[:80]!r}")


class ChannelWriter:
    """The collector's end: sends each message as one line, at once."""

    def __init__(self, fd: int) -> None:
        self.file = os.fdopen(fd, "wb", buffering=0)
        self.last_step = -1
        self.gone = False  # the reader closed its end: nobody is left to tell

    def send(self, msg: ChannelMessage) -> None:
        if self.gone:
            return
        try:
            self.file.write(encode(msg))
        except BrokenPipeError:
            self.gone = True

    def step(self, k: int) -> None:
        """Progress: sent only when it advances."""
        if k > self.last_step:
            self.send(StepChecked(k))
            self.last_step = k

    def close(self) -> None:
        try:
            self.file.close()
        except BrokenPipeError:
            pass


class ChannelReader:
    """The launcher's end: a thread decodes the messages as they arrive and keeps the latest progress and
    the summary; :meth:`wait_closed` once the collector has exited (the pipe then ends)."""

    def __init__(self, stream: IO[bytes]) -> None:
        self.stream = stream
        self.step = -1  # the latest StepChecked (−1: none yet)
        self.summary: RunSummary | None = None  # from RunFinished
        self.checked_at: dict[int, float] = {}  # step → time.monotonic() its StepChecked arrived (the benchmark's clock)
        self.errors: list[str] = []  # lines that were no message (reported by the launcher)
        self._thread = threading.Thread(target=self._read, name="channel", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        with self.stream:
            for line in self.stream:
                self.receive(line)

    def receive(self, line: bytes) -> None:
        try:
            msg = decode(line)
        except ChannelError as exc:
            self.errors.append(str(exc))
            return
        if isinstance(msg, StepChecked):
            self.checked_at.setdefault(msg.step, time.monotonic())
            self.step = max(self.step, msg.step)
        else:
            self.summary = msg.summary

    def wait_closed(self, timeout: float) -> bool:
        """Wait (at most ``timeout`` s) until every message is read; False if the pipe is still open."""
        self._thread.join(timeout)
        return not self._thread.is_alive()
