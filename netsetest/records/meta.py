"""A run's settings, typed: what the record's first line (``meta``) holds, beside the typed summary.

The runtime builds a :class:`RunMeta` (runtime/inmemory.py ``run_meta``), the record sinks write its
:meth:`~RunMeta.to_dict` (the record format is unchanged), and the loaders read it back with
:meth:`~RunMeta.from_dict`: a field an older record lacks takes its default, a value of the wrong type is
a ValueError naming it (a malformed record), a key this version does not know is ignored.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, fields
from typing import Any

DEFAULT_TAU_S = 1.0  # a record too old to say its sampling period: steps are drawn as seconds


@dataclass(frozen=True)
class RunMeta:
    topology: str | None = None  # the topology file's path
    name: str | None = None
    mode: str | None = None  # inmemory | zenoh
    clock: str | None = None  # lockstep | realtime
    case: str | None = None  # nsnim | saim
    signals: str | None = None  # paper | worst
    variant: str | None = None  # scheduled | per-rule
    objective: str | None = None
    seed: int | None = None  # None: a collector started by hand without --seed
    steps: int | None = None
    tau_s: float = DEFAULT_TAU_S
    run_id: str | None = None
    node_ids: list[int] = field(default_factory=list)
    # per node i (int ids; the record's JSON keys them by the id's string: to_dict, from_dict)
    in_weights: dict[int, dict[int, float]] = field(default_factory=dict)  # i → {j: a_ij}
    r_max: dict[int, float | None] = field(default_factory=dict)  # i → saturation limit (None: not saturating)
    h1: dict[int, float] = field(default_factory=dict)
    C: dict[int, list[float]] = field(default_factory=dict)  # i → C̄_i
    estimators: dict[int, str] = field(default_factory=dict)  # i → the node's estimator
    plant: str = "ts"  # what generated the truth (Scenario.plant_label)
    manoeuvre: str = "paper"
    model_uncertainty: dict | None = None  # {"kind": box | ellipsoid, "G": [[..]]} (docs/plant.md)
    started_ns: int | None = None  # the run's start on the wall clock (an MCAP record's log times start here)
    security: str | None = None  # a Zenoh run's: mtls+acl | insecure
    settings_digest: str | None = None  # the topology's and profiles' values (config/schema.py); None: not from files
    log: dict | None = None  # a recorded drive: {"path", "mapping", "accuracy": [β rad, r rad/s]} (docs/your-log.md); None: a model's run

    def to_dict(self) -> dict:
        """The record's meta object: every field in order, ``security`` only for a Zenoh run."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out.update({name: _json_keys(out[name]) for name in _NODE_MAPS})
        if out["security"] is None:
            del out["security"]
        if out["log"] is None:  # a model's run: the meta as before
            del out["log"]
        return out

    @classmethod
    def from_dict(cls, d: dict) -> RunMeta:
        """The typed meta of a record's object (module doc)."""
        if not isinstance(d, dict):
            raise ValueError(f"meta must be a dict, got {type(d).__name__}")
        given: dict[str, Any] = {}
        for f in fields(cls):
            if f.name not in d or (d[f.name] is None and f.name in _NOT_NONE):
                continue
            given[f.name] = _checked(f.name, d[f.name])
        return cls(**given)

    def with_security(self, security: str) -> RunMeta:
        return dataclasses.replace(self, security=security)


_NOT_NONE = frozenset({"tau_s", "node_ids", "in_weights", "r_max", "h1", "C", "estimators", "plant", "manoeuvre"})
_SCALARS: dict[str, tuple[type, ...]] = {
    "seed": (int,),
    "steps": (int,),
    "started_ns": (int,),
    "tau_s": (int, float),
    "topology": (str,),
    "name": (str,),
    "mode": (str,),
    "clock": (str,),
    "case": (str,),
    "signals": (str,),
    "variant": (str,),
    "objective": (str,),
    "run_id": (str,),
    "plant": (str,),
    "manoeuvre": (str,),
    "security": (str,),
    "settings_digest": (str,),
}
_DICTS = frozenset({"in_weights", "r_max", "h1", "C", "estimators", "model_uncertainty", "log"})
_NODE_MAPS = ("in_weights", "r_max", "h1", "C", "estimators")  # keyed by node id (in_weights: both levels)


def _json_keys(value: dict) -> dict:
    """A node map with the ids as strings (JSON's keys), nested maps too (in_weights)."""
    return {str(i): _json_keys(v) if isinstance(v, dict) else v for i, v in value.items()}


def _int_keys(name: str, value: dict) -> dict:
    """A node map of the record's JSON with int ids, nested maps too; a key that is no integer is a ValueError naming the field."""
    try:
        return {int(i): _int_keys(name, v) if isinstance(v, dict) else v for i, v in value.items()}
    except (TypeError, ValueError):
        raise ValueError(f"meta.{name}: a key is not a node id ({value!r:.60})") from None


def _checked(name: str, value: Any) -> Any:
    """``value`` if it has the field's type (bool is no number), else ValueError naming the field."""
    if value is None and name not in _NOT_NONE:
        return None
    if name in _SCALARS:
        ok = isinstance(value, _SCALARS[name]) and not isinstance(value, bool)
    elif name == "node_ids":
        ok = isinstance(value, list) and all(isinstance(i, int) and not isinstance(i, bool) for i in value)
    else:
        ok = name in _DICTS and isinstance(value, dict)
    if not ok:
        raise ValueError(f"meta.{name}: unexpected value {value!r:.60}")
    if name in _NODE_MAPS:
        return _int_keys(name, value)
    return float(value) if name == "tau_s" else value


__all__ = ["DEFAULT_TAU_S", "RunMeta"]
