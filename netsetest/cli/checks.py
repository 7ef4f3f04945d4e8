"""Checks of command-line values shared by every command, made before anything starts."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path

from netsetest.models.manoeuvres import DriveSpec
from netsetest.runtime import argtypes

# the parsers a role spec shares (runtime/argtypes.py), under the names every command uses
positive_int, seed, run_id, endpoint = argtypes.positive_int, argtypes.seed, argtypes.run_id, argtypes.endpoint
non_negative_seconds, seed_list = argtypes.non_negative_seconds, argtypes.seed_list
DRAWN_SEED_BITS = 32  # a run's own seed: unguessable by another local user, short enough to type back


class OutputError(Exception):
    """An output path that cannot be written; the message names the option, the path and why."""


def name_list(choices: Sequence[str], what: str) -> Callable[[str], tuple[str, ...]]:
    """argparse type: comma-separated names, each one of ``choices``."""

    def parse(s: str) -> tuple[str, ...]:
        items = tuple(x.strip() for x in s.split(",") if x.strip())
        unknown = [x for x in items if x not in choices]
        if not items or unknown:
            raise argparse.ArgumentTypeError(f"unknown {what} {unknown[0] if unknown else s!r}; choose from {', '.join(choices)}")
        return items

    return parse


def drive_list(s: str) -> tuple[DriveSpec, ...]:
    """argparse type: comma-separated training drives, ``name`` or ``name@amplitude`` (models/manoeuvres.py)."""
    items = [x.strip() for x in s.split(",") if x.strip()]
    if not items:
        raise argparse.ArgumentTypeError(f"no manoeuvre in {s!r}")
    try:
        return tuple(DriveSpec.parse(x) for x in items)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


MAP_SEPARATOR = ":"  # DRIVE:MAP.toml, as scp's and docker's SRC:DST; a drive log never ends in .toml


def log_with_map(s: str) -> tuple[str, str | None]:
    """argparse type: ``DRIVE`` or ``DRIVE:MAP.toml`` (``calibrate --logs``, ``--held-out``), a recorded drive and its
    own mapping (None: ``--map``, else the drive's name with .map.toml, else the topology's; docs/your-log.md).  Split
    at the last ``:`` that a name ending in .toml follows, so a drive's own ``:`` stays its own."""
    drive, sep, mapping = s.rpartition(MAP_SEPARATOR)
    if sep and mapping.endswith(".toml"):
        if not drive.strip() or mapping == ".toml":
            raise argparse.ArgumentTypeError(f"{s!r}: expected DRIVE or DRIVE:MAP.toml, with both names given")
        return drive, mapping
    if s.endswith(".toml"):
        raise argparse.ArgumentTypeError(f"{s!r} is a mapping, not a drive: give it with its drive as DRIVE:MAP.toml (or as --map for every drive)")
    if not s.strip():
        raise argparse.ArgumentTypeError("an empty drive name")
    return s, None


def non_negative_float(s: str) -> float:
    """argparse type: a finite number ≥ 0."""
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {s!r}") from None
    if not (v >= 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a finite number ≥ 0, got {s}")
    return v


def speed_range(s: str) -> tuple[float, float]:
    """argparse type: a speed range LO-HI in km/h, 0 ≤ LO ≤ HI (an operating envelope's)."""
    lo, sep, hi = s.partition("-")
    try:
        a, b = float(lo), float(hi)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a speed range is LO-HI in km/h (e.g. 70-120), got {s!r}") from None
    if not sep or not (math.isfinite(a) and math.isfinite(b) and 0 <= a <= b):
        raise argparse.ArgumentTypeError(f"a speed range is LO-HI in km/h with 0 ≤ LO ≤ HI (e.g. 70-120), got {s!r}")
    return a, b


def positive_float(s: str) -> float:
    """argparse type: a finite number > 0."""
    v = non_negative_float(s)
    if v == 0:
        raise argparse.ArgumentTypeError("must be > 0, got 0")
    return v


def output_file(path: str | None, option: str) -> None:
    """Fail now, not after the run, when ``path`` cannot be written as a file (its directory must exist)."""
    if path is None:
        return
    p = Path(path)
    if "\0" in path:
        raise OutputError(f"{option} {path!r}: a path cannot contain a NUL byte")
    if p.is_dir():
        raise OutputError(f"{option} {path}: is a directory")
    if p.exists() and not p.is_file():
        raise OutputError(f"{option} {path}: not a regular file")
    if not p.parent.is_dir():  # a typo in a directory name must not become a new directory tree
        raise OutputError(f"{option} {path}: the directory {p.parent} does not exist")
    if not os.access(p.parent, os.W_OK | os.X_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise OutputError(f"{option} {path}: not writable")
    why = _cannot_write(p)
    if why:
        raise OutputError(f"{option} {path}: cannot be written ({why})")


def _cannot_write(p: Path) -> str | None:
    """Why a file cannot be created (or appended to) at ``p``, found by trying: os.access says yes to root
    everywhere, /proc included, and the collector then failed after the run."""
    import tempfile  # only for a command that writes a file: a node process never loads it

    try:
        if p.exists():
            with open(p, "ab"):
                pass
        else:
            fd, probe = tempfile.mkstemp(dir=p.parent, prefix=".netsetest-probe-")
            os.close(fd)
            os.unlink(probe)
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


HTML_SUFFIXES = (".html", ".htm")  # what a browser opens as a page from a file: report and compare write HTML, nothing else


def not_replaced(path: str | None, option: str, overwrite: bool) -> None:
    """An output that exists is replaced only when asked (``--overwrite``): a run's record, a report's page."""
    if path is not None and not overwrite and Path(path).exists():
        raise OutputError(f"{option} {path}: the file exists; give --overwrite to replace it")


def html_file(path: str | None, option: str = "--html") -> None:
    """``--html``: a writable file whose name says it is a page (``x.pdf`` once got HTML)."""
    if path is not None and not Path(path).name.lower().endswith(HTML_SUFFIXES):
        raise OutputError(f"{option} {path}: the page is HTML; give a name ending in {' or '.join(HTML_SUFFIXES)}")
    output_file(path, option)


def record_file(path: str | None, overwrite: bool = False) -> None:
    """``--record``: a record name, writable, not an existing file unless ``overwrite``, and its format's
    optional dependency installed (MissingExtra if not)."""
    from netsetest.records.files import being_written
    from netsetest.records.record import RECORD_SUFFIXES, check_record_path  # loaded only by a command that writes one

    if path is not None and not Path(path).name.endswith(RECORD_SUFFIXES):  # out.csv once got JSON Lines
        raise OutputError(f"--record {path}: the name must end in {', '.join(RECORD_SUFFIXES)} (the suffix chooses the format)")
    not_replaced(path, "--record", overwrite)  # two runs once interleaved one record
    if path is not None and being_written(path):  # refused before any role starts (once: exit 1, seven roles stopped)
        raise OutputError(f"--record {path}: another run is writing this record")
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


def seed_or_fresh(value: int | None) -> int:
    """``--seed`` if given, else a fresh random seed (a default everyone knows would let any local user
    recompute the truth the access control hides); the run prints and records it, so ``--seed`` replays it."""
    import secrets  # only for `run` (it loads `random`, which a node process does without)

    return value if value is not None else secrets.randbits(DRAWN_SEED_BITS)
