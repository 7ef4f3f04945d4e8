"""Every option and argument of every command has help text; the help shows each default and, for
durations, the unit."""

from __future__ import annotations

import argparse
import re

import pytest

from netsetest.cli.main import build_parser, has_default


def _commands() -> dict[str, argparse.ArgumentParser]:
    ap = build_parser()
    sub = next(a for a in ap._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _actions(p: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in p._actions if not isinstance(a, (argparse._HelpAction, argparse._VersionAction))]


def test_every_option_and_argument_has_help() -> None:
    missing = [f"{name} {(a.option_strings or [a.dest])[-1]}" for name, p in _commands().items() for a in _actions(p) if not a.help]
    assert not missing, f"without help text: {missing}"


@pytest.mark.parametrize("name", sorted(_commands()))
def test_help_shows_defaults_and_units(name: str) -> None:
    p = _commands()[name]
    text = "".join(p.format_help().split())  # argparse wraps help text (even inside words): compare without spaces
    for a in _actions(p):
        if not a.option_strings or not has_default(a):
            continue
        # the default is printed next to the option (either by its help text or by the formatter)
        helptext = " ".join(p._get_formatter()._expand_help(a).split())  # argparse's own expansion
        assert "default" in helptext, (name, a.option_strings, helptext)
        assert "".join(helptext.split()) in text
        if a.metavar == "S":  # a duration: the unit is named
            assert re.search(r"\[s\]|seconds", helptext), (name, a.option_strings, helptext)
    assert "Traceback" not in text
