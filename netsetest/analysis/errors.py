"""Errors of the analyses, in a module without heavy imports (the CLI imports it on every command)."""


class ExactError(Exception):
    """A record and topology that cannot be analysed together; the message says why."""


class CompareError(ValueError):
    """Bad input to ``netsetest compare`` (an unknown estimator name, nothing to compare)."""
