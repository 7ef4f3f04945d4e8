"""Messages the unit tests build by hand (the wire, the judge): one valid instance of each, changed per test."""

from __future__ import annotations

from typing import Any

import msgspec

from netsetest.messages import NodeState, Truth
from netsetest.proven import ProvenSet

SET_FIELDS = ("xhat", "P", "rho", "region", "fault", "set")  # a ProvenSet's: a state's published set


def make_state(**kw: Any) -> NodeState:
    """A NodeState from NodeState's keywords, those of SET_FIELDS making its published set."""
    pub = {k: kw.pop(k) for k in SET_FIELDS if k in kw}
    return NodeState(published=ProvenSet(**pub), **kw)


def raw_message(msg: Any, **changes: Any) -> dict[str, Any]:
    """``msg``'s fields as plain values (model_dump; a ProvenSet as the map it is sent as) with ``changes``
    (unchecked: tests forge payloads with it); a key of SET_FIELDS changes a state's published set."""
    d = {k: msgspec.to_builtins(v) if isinstance(v, msgspec.Struct) else v for k, v in msg.model_dump(mode="python").items()}
    for k, v in changes.items():
        (d["published"] if k in SET_FIELDS and "published" in d else d)[k] = v
    return d


def truth(**kw: object) -> Truth:
    """A valid truth of step 3 for nodes 1 and 2 (node 2's noise bound broke), with ``kw`` replacing fields."""
    one = {1: 0.5, 2: -0.5}
    base: dict[str, object] = dict(
        step=3,
        x=[0.01, 0.2],
        faults=one,
        u=0.03,
        w=0.1,
        vx=27.0,
        noise=one,
        gamma={1: 0.8, 2: 0.9},
        y=one,
        y_nofault=one,
        sector_ok={1: True, 2: True},
        noise_ok={1: True, 2: False},
        dist_ok=True,
        r={1: 0.1, 2: 0.2},
        fault_ok={1: True, 2: True},
        lost=[(1, 2)],
        alive=[1, 2],
        drops={"stale": 2},
    )
    base.update(kw)
    return Truth(**base)
