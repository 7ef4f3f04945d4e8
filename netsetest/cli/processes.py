"""CLI of the Zenoh runtime: role processes (vehicle, node, collector), run --mode zenoh, compose."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}


def add_run_options(p: argparse.ArgumentParser) -> None:
    """Options of ``run`` that only the Zenoh mode uses."""


def add_role_parsers(sub, scenario_args, run_args) -> None:  # type: ignore[no-untyped-def]
    """Sub-commands of the role processes."""


def cmd_run_zenoh(a: argparse.Namespace) -> int:
    print("netsetest run: --mode zenoh is not available yet; use --mode inmemory", file=sys.stderr)
    return 2
