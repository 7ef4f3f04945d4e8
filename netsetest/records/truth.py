"""A record's truth entries at the file boundary: in a :class:`~netsetest.records.record.Record` their node maps are keyed
by int node id, in the record's file (JSON lines, a JSON document, MCAP) by the id's decimal string, as JSON keys are
strings.  Loading converts with :func:`truth_entry`, writing with :func:`truth_json`: nowhere else.
"""

from __future__ import annotations

# a truth entry's maps keyed by node id (messages.Truth's fields of that kind: tests/unit/test_truth_keys.py holds them equal)
TRUTH_NODE_MAPS = ("faults", "noise", "gamma", "y", "y_nofault", "sector_ok", "r", "fault_ok", "noise_ok", "f_acc")


def truth_entry(raw: dict) -> dict:
    """A truth entry as a :class:`Record` holds it: its node maps keyed by int node id (JSON keys them by strings);
    a key that is no integer is a ValueError.  :func:`truth_json` is its inverse."""
    return {k: {int(i): x for i, x in v.items()} if k in TRUTH_NODE_MAPS and isinstance(v, dict) else v for k, v in raw.items()}


def truth_json(entry: dict) -> dict:
    """A truth entry as the record's file holds it: its node maps keyed by the node id's decimal string (JSON's keys)."""
    return {k: {str(i): x for i, x in v.items()} if k in TRUTH_NODE_MAPS and isinstance(v, dict) else v for k, v in entry.items()}
