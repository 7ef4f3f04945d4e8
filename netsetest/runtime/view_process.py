"""The live view as a process of its own: ``run --view`` starts ``netsetest view`` beside the run (an observer like
``watch``) and reads its address (:func:`start_view`, :class:`ViewProcess`); the view hands its lag behind a
real-time run to whoever asked for it (``netsetest view --lag-json PATH``, ``run --view-lag-json PATH``: the
benchmark's, netsetest_bench/view.py) when it stops (:func:`write_lag`).

What the view draws is runtime/view.py (messages to Rerun entities); what it serves, runtime/view_server.py.
"""

from __future__ import annotations

import json
import select
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from netsetest.runtime.view_server import ViewError, check_port, die_with_parent

if TYPE_CHECKING:  # the parent (`run --view`) never draws: Rerun's side stays in the view's process
    from netsetest.runtime.view import LiveView

VIEW_START_TIMEOUT_S = 60.0  # the view process imports Rerun and opens its session and servers
VIEW_STOP_S = 5.0


def write_lag(view: LiveView, path: str) -> None:
    """The view's lag per step (s), the truths not sent in time and the frames it dropped, as JSON to ``path``."""
    Path(path).write_text(json.dumps({**view.lag.to_dict(), "dropped_frames": view.coverage.dropped_frames}))


@dataclass
class ViewProcess:
    """``run --view``: a ``netsetest view`` process beside the run (an observer like ``watch``), and its address."""

    proc: subprocess.Popen
    url: str

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)  # the view closes its session and servers
            try:
                self.proc.wait(VIEW_STOP_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()


def start_view(observer_args: list[str], tau_s: float, port: int, lag_json: str | None = None) -> ViewProcess:
    """Start ``netsetest view`` with the run's observer options (``lag_json``: where it writes its lag when it stops);
    return once it subscribes and serves (its first line is the address, read on a pipe: the address is the
    capability to the view, so never on a command line).  PortTaken at once when ``port`` is taken, ViewError when
    the view does not start."""
    check_port(port)  # one clear line before any role starts (the view itself would say it on its own stderr)
    argv = [sys.executable, "-m", "netsetest", "view", *observer_args, "--tau-s", repr(tau_s), "--port", str(port)]
    if lag_json is not None:
        argv += ["--lag-json", lag_json]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, text=True, preexec_fn=die_with_parent)
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], VIEW_START_TIMEOUT_S)
    line = proc.stdout.readline() if ready else ""
    if "http://" not in line:
        ViewProcess(proc, "").stop()
        raise ViewError(f"the live view did not start (exit {proc.returncode}); run `netsetest view` by hand to see why")
    return ViewProcess(proc, line[line.index("http://") :].strip())
