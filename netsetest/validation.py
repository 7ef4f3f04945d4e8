"""What the two msgspec-validated layers (messages on the wire, configuration files) share: the bound
that makes a float finite, and msgspec's error text split into what and where."""

from __future__ import annotations

import re
import sys
from typing import Annotated

import msgspec
from msgspec import Meta

FLOAT_MAX = sys.float_info.max  # a bound at ±FLOAT_MAX rejects ±inf and NaN (msgspec has no "finite")
Finite = Annotated[float, Meta(ge=-FLOAT_MAX, le=FLOAT_MAX)]
Positive = Annotated[float, Meta(gt=0, le=FLOAT_MAX)]
FINITE_BOUND_TEXT = repr(FLOAT_MAX)  # how msgspec writes that bound in an error

_AT = re.compile(r"^(?P<msg>.*?)(?: - at `\$\.?(?P<loc>[^`]*)`)?$", re.S)


def split_error(err: msgspec.ValidationError) -> tuple[str, str]:
    """msgspec's "Expected `int` >= 1 - at `$.edges[3].from`" as ("Expected `int` >= 1", "edges[3].from");
    the location is "" for the top level (a ``__post_init__`` check of the whole object)."""
    m = _AT.match(str(err))
    assert m is not None  # the pattern matches every string
    return m["msg"], m["loc"] or ""
