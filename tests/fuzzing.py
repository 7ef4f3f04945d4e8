"""How many examples a Hypothesis test of the cuts and the polygon operations draws: its own short, seeded count in
every ``pytest``, 10 000 random ones under the thorough profile (``HYPOTHESIS_PROFILE=thorough``, registered and
loaded in tests/conftest.py; DEVELOPERS.md has the command), or ``NETSETEST_FUZZ_EXAMPLES`` where set."""

from __future__ import annotations

import os

THOROUGH = "thorough"  # the profile's name (HYPOTHESIS_PROFILE)
THOROUGH_EXAMPLES = 10_000


def long_run() -> int | None:
    """The examples of a long run (NETSETEST_FUZZ_EXAMPLES, else the thorough profile's), None in the default run."""
    env = int(os.environ.get("NETSETEST_FUZZ_EXAMPLES", "0"))
    return env or (THOROUGH_EXAMPLES if os.environ.get("HYPOTHESIS_PROFILE") == THOROUGH else None)


def examples(n: int) -> int:
    """``n`` in the default run, the long run's count otherwise."""
    return long_run() or n
