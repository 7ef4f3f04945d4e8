"""Errors of the analyses, and the defaults the CLI shows, in a module without heavy imports (the CLI imports it on
every command)."""

DEFAULT_BUDGET_S = 600.0  # `netsetest exact --budget`: paper6_max_faulty takes ~20 s, a 12-node ring with two groups ~2 min


class ExactError(Exception):
    """A record and topology that cannot be analysed together; the message says why."""


class CompareError(ValueError):
    """Bad input to ``netsetest compare`` (an unknown estimator name, nothing to compare)."""
