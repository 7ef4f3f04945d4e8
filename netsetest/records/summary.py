"""The run summary: the per-node table and totals the collector closes a run with.

The same object is the record's last line (``{"kind": "summary", "summary": {...}}``), the MCAP verdict
message and the ``--summary-json`` file.  In code it is a :class:`RunSummary`; at the record boundary
it is converted with :meth:`RunSummary.to_dict` / :meth:`RunSummary.from_dict`, so the file format is
unchanged.  Records written before a field existed load with its default (0, empty, or None), so old
records still load; a field of the wrong type is a ``ValueError`` (the loaders report a malformed record).

Drop and loss counters stay mappings: their keys (roles, reasons, causes) are data, not a schema.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import TypeVar

from netsetest.estimator.names import SDP

T = TypeVar("T")

DEFAULT_ESTIMATOR = SDP  # the node estimator of records written before nodes could run others
RUN_FIELDS = ("mode", "security", "variant", "objective", "case", "signals", "steps", "seed", "clock")
"""The run's settings copied from its meta (each only if the meta has it; written in this order)."""


@dataclass(frozen=True)
class NodeSummary:
    """One node's row of the summary (``max_E`` and the means are None where nothing was measured)."""

    id: int
    estimator: str = DEFAULT_ESTIMATOR
    max_E: float | None = None
    violations: int = 0  # misses where every assumption held
    misses_assumption_broken: int = 0
    assumption_violations: int = 0
    sector_failures: int = 0  # derived sectors that missed C̄ x̄ inside an intact cone
    sectors_assumed: int = 0
    sector_breaks: int = 0
    first_sector_break: int | None = None
    fault_bound_mean_width: float | None = None
    solve_ms_median: float | None = None
    fallbacks: int = 0
    steps_reported: int = 0
    steps_rejected: int = 0
    steps_contested: int = 0
    steps_evaluated: int = 0
    steps_contained: int = 0
    steps_covered: int = 0
    missing_steps: int = 0
    missing_from: int | None = None
    rejoined_at: int | None = None
    neighbour_messages_missing: int = 0
    dropped_messages: int = 0
    drops: dict[str, int] = field(default_factory=dict)  # by reason
    deadline_misses: int = 0

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: Mapping) -> NodeSummary:
        r = _Reader(d, "nodes[]")
        return cls(
            id=r.required("id", int),
            estimator=r.get("estimator", str, DEFAULT_ESTIMATOR),
            max_E=r.optional("max_E", float),
            violations=r.get("violations", int, 0),
            misses_assumption_broken=r.get("misses_assumption_broken", int, 0),
            assumption_violations=r.get("assumption_violations", int, 0),
            sector_failures=r.get("sector_failures", int, 0),
            sectors_assumed=r.get("sectors_assumed", int, 0),
            sector_breaks=r.get("sector_breaks", int, 0),
            first_sector_break=r.optional("first_sector_break", int),
            fault_bound_mean_width=r.optional("fault_bound_mean_width", float),
            solve_ms_median=r.optional("solve_ms_median", float),
            fallbacks=r.get("fallbacks", int, 0),
            steps_reported=r.get("steps_reported", int, 0),
            steps_rejected=r.get("steps_rejected", int, 0),
            steps_contested=r.get("steps_contested", int, 0),
            steps_evaluated=r.get("steps_evaluated", int, 0),
            steps_contained=r.get("steps_contained", int, 0),
            steps_covered=r.get("steps_covered", int, 0),
            missing_steps=r.get("missing_steps", int, 0),
            missing_from=r.optional("missing_from", int),
            rejoined_at=r.optional("rejoined_at", int),
            neighbour_messages_missing=r.get("neighbour_messages_missing", int, 0),
            dropped_messages=r.get("dropped_messages", int, 0),
            drops=r.counts("drops"),
            deadline_misses=r.get("deadline_misses", int, 0),
        )


@dataclass(frozen=True)
class RunSummary:
    """The verdict of a run: totals over node-steps, per-role drop counters and one row per node.

    The run's settings (``mode`` … ``clock``) are None where the meta did not have them (e.g.
    ``security`` outside Zenoh); they are then left out of the dict.
    """

    violations_total: int = 0
    misses_assumption_broken_total: int = 0
    sector_failures_total: int = 0
    steps_completed: int = -1  # the last closed step
    node_steps_reported: int = 0
    node_steps_rejected: int = 0  # no copy matched the truth
    node_steps_contested: int = 0  # more than one matching copy: not judged
    node_steps_evaluated: int = 0
    node_steps_contained: int = 0
    node_steps_covered: int = 0  # evaluated with every assumption held
    node_steps_not_covered: dict[str, int] = field(default_factory=dict)  # evaluated outside the guarantee, by cause
    nodes_missing: list[int] = field(default_factory=list)  # silent at the last step
    nodes_rejoined: list[int] = field(default_factory=list)
    losses: dict[str, int] = field(default_factory=dict)  # scheduled message losses, by kind
    losses_total: int = 0
    dropped_messages: dict[str, int] = field(default_factory=dict)  # by the collector, by reason
    drops: dict[str, dict[str, int]] = field(default_factory=dict)  # role → reason → count
    nodes: list[NodeSummary] = field(default_factory=list)
    mode: str | None = None
    security: str | None = None
    variant: str | None = None
    objective: str | None = None
    case: str | None = None
    signals: str | None = None
    steps: int | None = None
    seed: int | None = None
    clock: str | None = None

    @property
    def fallbacks(self) -> int:
        return sum(n.fallbacks for n in self.nodes)

    def node(self, node_id: int) -> NodeSummary:
        """The row of node ``node_id`` (KeyError if the run has no such node)."""
        for n in self.nodes:
            if n.id == node_id:
                return n
        raise KeyError(node_id)

    def to_dict(self) -> dict:
        """The record's and ``--summary-json``'s object (key order as the collector has always written it)."""
        out: dict = {k: getattr(self, k) for k in RUN_FIELDS if getattr(self, k) is not None}
        for f in fields(self):
            if f.name not in RUN_FIELDS:
                v = getattr(self, f.name)
                out[f.name] = [n.to_dict() for n in v] if f.name == "nodes" else v
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> RunSummary:
        r = _Reader(d, "summary")
        nodes = r.get("nodes", list, [])
        drops = r.get("drops", dict, {})
        return cls(
            violations_total=r.get("violations_total", int, 0),
            misses_assumption_broken_total=r.get("misses_assumption_broken_total", int, 0),
            sector_failures_total=r.get("sector_failures_total", int, 0),
            steps_completed=r.get("steps_completed", int, -1),
            node_steps_reported=r.get("node_steps_reported", int, 0),
            node_steps_rejected=r.get("node_steps_rejected", int, 0),
            node_steps_contested=r.get("node_steps_contested", int, 0),
            node_steps_evaluated=r.get("node_steps_evaluated", int, 0),
            node_steps_contained=r.get("node_steps_contained", int, 0),
            node_steps_covered=r.get("node_steps_covered", int, 0),
            node_steps_not_covered=r.counts("node_steps_not_covered"),
            nodes_missing=r.ints("nodes_missing"),
            nodes_rejoined=r.ints("nodes_rejoined"),
            losses=r.counts("losses"),
            losses_total=r.get("losses_total", int, 0),
            dropped_messages=r.counts("dropped_messages"),
            drops={str(role): _Reader(drops, "summary.drops").counts(role) for role in drops},
            nodes=[NodeSummary.from_dict(_mapping(n, "summary.nodes[]")) for n in nodes],
            mode=r.optional("mode", str),
            security=r.optional("security", str),
            variant=r.optional("variant", str),
            objective=r.optional("objective", str),
            case=r.optional("case", str),
            signals=r.optional("signals", str),
            steps=r.optional("steps", int),
            seed=r.optional("seed", int),
            clock=r.optional("clock", str),
        )


def _mapping(v: object, where: str) -> Mapping:
    if not isinstance(v, Mapping):
        raise ValueError(f"{where}: expected an object, got {type(v).__name__}")
    return v


class _Reader:
    """Typed reads from one JSON object; a value of the wrong type is a ValueError naming the field."""

    def __init__(self, d: object, where: str) -> None:
        self.d, self.where = _mapping(d, where), where

    def _check(self, key: str, v: object, kind: type[T]) -> T:
        ok = isinstance(v, kind) and not (kind is int and isinstance(v, bool))
        if kind is float and isinstance(v, int) and not isinstance(v, bool):
            return float(v)  # type: ignore[return-value]  JSON writes 2.0 as 2 in other encoders
        if not ok:
            raise ValueError(f"{self.where}.{key}: expected {kind.__name__}, got {type(v).__name__}")
        return v  # type: ignore[return-value]

    def required(self, key: str, kind: type[T]) -> T:
        if key not in self.d:
            raise ValueError(f"{self.where}: no {key!r}")
        return self._check(key, self.d[key], kind)

    def get(self, key: str, kind: type[T], default: T) -> T:
        return self._check(key, self.d[key], kind) if key in self.d else default

    def optional(self, key: str, kind: type[T]) -> T | None:
        v = self.d.get(key)
        return None if v is None else self._check(key, v, kind)

    def counts(self, key: str) -> dict[str, int]:
        raw = self.get(key, dict, {})
        return {str(k): _Reader({"n": n}, f"{self.where}.{key}").required("n", int) for k, n in raw.items()}

    def ints(self, key: str) -> list[int]:
        return [self._check(key, v, int) for v in self.get(key, list, [])]


__all__ = ["DEFAULT_ESTIMATOR", "RUN_FIELDS", "NodeSummary", "RunSummary"]
