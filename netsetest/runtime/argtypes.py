"""Parsers of command-line values that role specs (runtime/rolespec.py) and the CLI share: each takes the
text of one option and returns its value or raises :class:`argparse.ArgumentTypeError` naming why.

They live below the CLI because a role spec parses its own command line (``RoleSpec.from_argv``); the
CLI's checks (cli/checks.py) use the same functions, so each rule is written once.
"""

from __future__ import annotations

import argparse
import math
import os
import re
from collections.abc import Callable

from netsetest.roles.flow import parse_window

SEED_MAX = 2**63 - 1
RUN_ID_RE = re.compile(r"[A-Za-z0-9_-]{1,64}")
# proto/host:port with an optional Zenoh suffix (?metadata, #config); host a name, an IPv4 or a [IPv6]
ENDPOINT_RE = re.compile(r"(tcp|udp|tls|quic)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.-]+):(\d{1,5})([?#].*)?")
MAX_PORT = 65535


def positive_int(s: str) -> int:
    """argparse type: an integer ≥ 1 (steps, counts)."""
    try:
        v = int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {s!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {v}")
    return v


def seed(s: str) -> int:
    """argparse type of ``--seed``: a non-negative integer (numpy rejects negative seeds)."""
    try:
        v = int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {s!r}") from None
    if not 0 <= v <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"must be between 0 and 2**63 − 1, got {v}")
    return v


SEED_RANGE_RE = re.compile(r"(\d+)\s*-\s*(\d+)")
SEED_RANGE_MAX = (
    10_000  # seeds one range may name (a typo like 0-99999999 is not a request)  # numpy's SeedSequence takes any non-negative integer; keep it to 64 bits
)


def seed_list(s: str) -> tuple[int, ...]:
    """argparse type: comma-separated seeds and ranges A-B (inclusive), e.g. ``0-4,9`` (``--seeds``, a campaign's seeds)."""
    out: list[int] = []
    for part in s.split(","):
        m = SEED_RANGE_RE.fullmatch(part.strip())
        if m is None:  # one seed (a negative number is a seed, and an error, not a range)
            out.append(seed(part))
            continue
        a, b = seed(m[1]), seed(m[2])
        if b < a or b - a >= SEED_RANGE_MAX:
            raise argparse.ArgumentTypeError(f"seed range {part.strip()!r}: must be A-B with A ≤ B and at most {SEED_RANGE_MAX} seeds")
        out.extend(range(a, b + 1))
    return tuple(out)


def run_id(s: str) -> str:
    """argparse type of ``--run-id``: one key-expression chunk (no '/', '*', '$': they would widen the keys)."""
    if not RUN_ID_RE.fullmatch(s):
        raise argparse.ArgumentTypeError(f"{s!r}: only letters, digits, '_' and '-' (1 to 64), it is a key-expression chunk")
    return s


def endpoint(s: str) -> str:
    """argparse type of a Zenoh endpoint: PROTO/HOST:PORT with a port in range."""
    m = ENDPOINT_RE.fullmatch(s)
    if not m or int(m.group(3)) > MAX_PORT:
        raise argparse.ArgumentTypeError(f"{s!r}: expected PROTO/HOST:PORT with PROTO tcp, udp, tls or quic and a port ≤ {MAX_PORT}, e.g. tls/127.0.0.1:7447")
    return s


def readable_file(s: str) -> str:
    """argparse type: the name of a file this process can read."""
    if not os.path.isfile(s) or not os.access(s, os.R_OK):
        raise argparse.ArgumentTypeError(f"{s}: not a readable file")
    return s


def writable_dir(s: str) -> str:
    """argparse type: an existing directory this process can write in (``--profile``)."""
    if not os.path.isdir(s) or not os.access(s, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{s}: not a directory this process can write in")
    return s


def node_at(s: str) -> tuple[int, int]:
    """argparse type of ``NODE@STEP`` (``--kill``, ``--rejoin``, ``--await-rejoin``)."""
    try:
        node, step = s.split("@")
        return int(node), int(step)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NODE@STEP, e.g. 3@20, got {s!r}") from None


def _seconds_type(allow_zero: bool) -> Callable[[str], float]:
    """argparse type for a duration: > 0, or ≥ 0 with ``allow_zero``."""

    def parse(s: str) -> float:
        try:
            v = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number of seconds: {s!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be a finite number of seconds, got {s!r}")
        if v < 0 or (v == 0 and not allow_zero):
            raise argparse.ArgumentTypeError(f"must be {'≥' if allow_zero else '>'} 0, got {v}")
        return v

    return parse


seconds, non_negative_seconds = _seconds_type(False), _seconds_type(True)

MIN_STALL_LIMIT_S = 1.0  # a shorter Zenoh lease (keep-alives every quarter of it) closes sessions on a merely busy machine


def stall_limit(s: str) -> float:
    """argparse type: ``--stall-limit``, seconds ≥ MIN_STALL_LIMIT_S."""
    v = seconds(s)
    if v < MIN_STALL_LIMIT_S:
        raise argparse.ArgumentTypeError(f"must be at least {MIN_STALL_LIMIT_S:g} s (Zenoh's lease), got {v:g}")
    return v


def ack_window(s: str) -> int | None:
    """argparse type of ``--ack-window``: the lockstep window in steps, or ``unbounded`` (None; roles/flow.py)."""
    try:
        return parse_window(s)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


MAX_PORT = 65535


def port(s: str) -> int:
    """argparse type: a TCP port, 0 for a free one."""
    try:
        v = int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {s!r}") from None
    if not 0 <= v <= MAX_PORT:
        raise argparse.ArgumentTypeError(f"must be 0-{MAX_PORT}, got {v}")
    return v


def drive(s: str) -> str:
    """argparse type of ``--manoeuvre``: ``NAME`` or ``NAME@AMPLITUDE`` (models/manoeuvres.py ``DriveSpec``),
    returned in one canonical spelling (the amplitude's repr: the replayed run gets the same float)."""
    from netsetest.models.manoeuvres import AMPLITUDE_SEP, DriveSpec

    try:
        d = DriveSpec.parse(s.strip())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return d.manoeuvre if d.amplitude is None else f"{d.manoeuvre}{AMPLITUDE_SEP}{d.amplitude!r}"


def _number(s: str, what: str, ok: Callable[[float], bool], rule: str) -> float:
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {s!r}") from None
    if not (math.isfinite(v) and ok(v)):
        raise argparse.ArgumentTypeError(f"{what} must be {rule}, got {s!r}")
    return v


def speed_kmh(s: str) -> float:
    """argparse type of ``--speed``: the speed reference's mean [km/h], in the configuration's range."""
    from netsetest.config.schema import SPEED_MAX_KMH

    return _number(s, "a speed [km/h]", lambda v: 0 < v <= SPEED_MAX_KMH, f"> 0 and ≤ {SPEED_MAX_KMH:g}")


def fault_scale(s: str) -> float:
    """argparse type of ``--fault-scale``: a fraction of the declared ``[fault_bound] size`` (config/schema.py)."""
    from netsetest.config.schema import FAULT_SCALE_MAX

    return _number(s, "a fault scale", lambda v: 0 <= v <= FAULT_SCALE_MAX, f"between 0 and {FAULT_SCALE_MAX:g}")
