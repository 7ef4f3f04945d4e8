"""Key expressions — the one place that names them.

    netsetest/<run>/vehicle/input/<i>   NodeInput for node i (measurement, γ, u, Vx, expected neighbours)
    netsetest/<run>/vehicle/truth       Truth (collector only: the truth, faults, assumption flags, losses)
    netsetest/<run>/node/<i>/state      NodeState of node i (to its out-neighbours and the collector)
    netsetest/<run>/node/<i>/reading    Reading of reference node i (its measurement of the step, to every node)
    netsetest/<run>/control/ready/<who> Ready of role <who> (vehicle, collector, node-<i>; start-up barrier)
    netsetest/<run>/control/end         End (vehicle → all)

Every role publishes on its own keys only, which is what the router's access-control rules
(netsetest/runtime/security.py) are built from.
"""

from __future__ import annotations

ROOT = "netsetest"


def node_input(run: str, i: int | str) -> str:
    return f"{ROOT}/{run}/vehicle/input/{i}"


def truth(run: str) -> str:
    return f"{ROOT}/{run}/vehicle/truth"


def node_state(run: str, i: int | str) -> str:
    return f"{ROOT}/{run}/node/{i}/state"


def reading(run: str, i: int | str) -> str:
    return f"{ROOT}/{run}/node/{i}/reading"


def run_root(run: str) -> str:
    """Every key of a run."""
    return f"{ROOT}/{run}/**"


def role_name(role: str, node: int | None = None) -> str:
    """A role's name in keys and certificates: ``vehicle``, ``collector``, ``node-3``."""
    return role if node is None else f"{role}-{node}"


def ready(run: str) -> str:
    """The namespace of the start-up barrier; each role publishes on :func:`ready_of` its name."""
    return f"{ROOT}/{run}/control/ready"


def ready_of(run: str, who: str) -> str:
    """Readiness key of role ``who`` (a :func:`role_name`, or ``*`` for every role)."""
    return f"{ready(run)}/{who}"


def end(run: str) -> str:
    return f"{ROOT}/{run}/control/end"


def matches(pattern: str, key: str) -> bool:
    """Key-expression match for the in-memory bus: ``*`` is one chunk, ``**`` any number of chunks."""
    p, k = pattern.split("/"), key.split("/")

    def go(i: int, j: int) -> bool:
        if i == len(p):
            return j == len(k)
        if p[i] == "**":
            return any(go(i + 1, jj) for jj in range(j, len(k) + 1))
        if j == len(k):
            return False
        return (p[i] == "*" or p[i] == k[j]) and go(i + 1, j + 1)

    return go(0, 0)
