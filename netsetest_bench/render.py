"""A part's figures as typed data, and its prose as Markdown templates (``netsetest_bench/templates/*.md``).

Each part's JSON (bench/<part>.json, or a run's figures before they are written) is converted once into the
part's frozen dataclasses (:func:`typed`: msgspec checks every field's type on the way in); its renderer then
fills the part's template with them.  A template file holds named blocks, each opened by a line
``<!-- NAME -->`` and running to the next; a block is Python's format string syntax over the named fields it is
given (``{figures.solve_ms_median:.2f}``, ``{met[naive_ratio]}``), with two rules of the docs: a missing figure
(None) prints as ``—`` whatever its format (a template's block ``missing``, if it has one, says what it prints
instead), and the format ``thousands`` groups digits with spaces (10 000).
"""

from __future__ import annotations

import dataclasses
import functools
import re
import string
from pathlib import Path
from typing import Any, TypeVar

import msgspec

TEMPLATES = Path(__file__).with_name("templates")
MISSING = "—"  # a figure the run did not measure
_BLOCK = re.compile(r"^<!-- ([a-z0-9_-]+) -->\n", re.MULTILINE)

T = TypeVar("T")


class FiguresError(ValueError):
    """A figures file that does not hold what its part's types say (one line: which file, which field)."""


def typed(kind: type[T], doc: object, what: str = "the figures") -> T:
    """``doc`` (JSON as loaded: string keys) as ``kind``; FiguresError naming the field that does not fit."""
    try:
        return msgspec.convert(doc, kind, strict=False)  # strict=False: JSON's string keys become the int keys the types declare
    except msgspec.ValidationError as e:
        raise FiguresError(f"{what}: {e}") from None


def as_fields(figures: object) -> dict[str, object]:
    """A figures dataclass as its file holds it, one level (the inverse of :func:`typed`): its fields by name, a field
    whose ``json`` metadata names another key under that key (``with``, a keyword in Python)."""
    return {f.metadata.get("json", f.name): getattr(figures, f.name) for f in dataclasses.fields(figures)}  # type: ignore[arg-type]  # a dataclass instance: run.py's _jsonable checks


class _Formatter(string.Formatter):
    def __init__(self, missing: str = MISSING) -> None:
        self.missing = missing

    def format_field(self, value: Any, format_spec: str) -> str:
        if value is None:
            return self.missing
        if format_spec == "thousands":
            return format(value, ",").replace(",", " ")
        return super().format_field(value, format_spec)


def figure(value: object, spec: str = ".2f", missing: str = MISSING) -> str:
    """One figure as a template prints it (for the lists a renderer joins itself)."""
    return _Formatter(missing).format_field(value, spec)


@functools.cache
def blocks(name: str) -> dict[str, str]:
    """The named blocks of ``templates/<name>.md`` (each without the newline that ends its last line)."""
    text = (TEMPLATES / f"{name}.md").read_text(encoding="utf-8")
    parts = _BLOCK.split(text)
    if parts[0].strip():
        raise ValueError(f"{TEMPLATES / name}.md: text before its first block")
    return {parts[i]: parts[i + 1].removesuffix("\n") for i in range(1, len(parts), 2)}


@functools.cache
def _formatter(template: str) -> _Formatter:
    return _Formatter(blocks(template).get("missing", MISSING))


def fill(template: str, block: str, /, **fields: object) -> str:
    """Block ``block`` of ``templates/<template>.md`` with ``fields`` filled in."""
    return _formatter(template).vformat(blocks(template)[block], (), fields)


__all__ = ["MISSING", "TEMPLATES", "FiguresError", "as_fields", "blocks", "figure", "fill", "typed"]
