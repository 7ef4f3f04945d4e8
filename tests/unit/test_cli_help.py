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


def test_top_level_help_names_every_command_of_the_registry(capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 41 item 13: ``netsetest --help`` named 5 of its commands.  Every command with a handler (the
    registry, main.handlers()) has a parser and is named in the description and listed with its help, except the
    internal ones, which are neither."""
    from netsetest.cli.main import handlers
    from netsetest.cli.processes import INTERNAL_COMMANDS

    registry = set(handlers())
    assert registry == set(_commands()), "a command without a parser, or a parser without a handler"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--help"])
    text = capsys.readouterr().out
    description, _, listing = text.partition("positional arguments:")
    named = set(re.findall(r"[a-z][a-z-]*[a-z]", " ".join(description.split("commands:", 1)[1].split("\n\n", 1)[0].split())))
    listed = {line.split()[0] for line in listing.splitlines() if re.match(r"^    \S", line)}
    for name in registry - set(INTERNAL_COMMANDS):
        assert name in named, f"{name} is not named in the description"
        assert name in listed, f"{name} is not listed with its help"
    for name in INTERNAL_COMMANDS:
        assert name not in named and name not in listed


def test_every_topology_argument_names_every_bundled_topology() -> None:
    """Issue 41 item 13: ``run --help`` named 2 of the bundled topologies; every command taking a topology
    names all of them, as the package holds them (scenarios.bundled_topologies)."""
    from netsetest.scenarios import bundled_topologies

    bundled = bundled_topologies()
    assert len(bundled) > 2
    takers = {name: p for name, p in _commands().items() for a in _actions(p) if a.dest.split(".")[-1] == "topology"}
    assert {"run", "compare", "calibrate", "exact", "vehicle", "node", "collector", "router", "credentials", "compose"} <= set(takers)
    for name, p in takers.items():
        text = " ".join(p.format_help().split())
        missing = [t for t in bundled if not re.search(rf"\b{re.escape(t)}\b", text)]
        assert not missing, (name, missing)
