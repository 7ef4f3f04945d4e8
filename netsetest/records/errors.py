"""The record's error, in a module without heavy imports (the CLI imports it on every command)."""


class RecordError(Exception):
    """A record file that cannot be read; the message names the file and the reason."""
