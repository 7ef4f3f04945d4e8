"""Checks of command-line values shared by every command, made before anything starts."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

SEED_MAX = 2**63 - 1  # numpy's SeedSequence takes any non-negative integer; keep it to 64 bits


class OutputError(Exception):
    """An output path that cannot be written; the message names the option, the path and why."""


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


def output_file(path: str | None, option: str) -> None:
    """Fail now, not after the run, when ``path`` cannot be written as a file (missing parents are made)."""
    if path is None:
        return
    p = Path(path)
    if "\0" in path:
        raise OutputError(f"{option} {path!r}: a path cannot contain a NUL byte")
    if p.is_dir():
        raise OutputError(f"{option} {path}: is a directory")
    if p.exists() and not p.is_file():
        raise OutputError(f"{option} {path}: not a regular file")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{option} {path}: cannot create its directory ({exc.strerror or exc})") from None
    if not os.access(p.parent, os.W_OK | os.X_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise OutputError(f"{option} {path}: not writable")


def record_file(path: str | None) -> None:
    """``--record``: writable, and its format's optional dependency installed (MissingExtra if not)."""
    from netsetest.records.record import check_record_path  # the records load only for a command that writes one

    output_file(path, "--record")
    check_record_path(path)


def output_dir(path: str, option: str) -> None:
    """Fail now when ``path`` cannot be used as an output directory (it is made if missing)."""
    p = Path(path)
    if "\0" in path:
        raise OutputError(f"{option} {path!r}: a path cannot contain a NUL byte")
    if p.exists() and not p.is_dir():
        raise OutputError(f"{option} {path}: exists and is not a directory")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{option} {path}: cannot create it ({exc.strerror or exc})") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise OutputError(f"{option} {path}: not writable")
