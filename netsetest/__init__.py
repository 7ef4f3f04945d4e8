"""netsetest: distributed set-membership joint state and sensor-fault estimation (simulator).

``netsetest.simulate(...)`` runs a scenario from Python (see :mod:`netsetest.api`); it and
``__version__`` are looked up on first use so that role processes, which import this package too, do
not pay for them.
"""

from __future__ import annotations

from typing import Any

__all__ = ["__version__", "simulate", "SimulationResult", "NodeSeries"]


def _version() -> str:
    from importlib import metadata  # ~90 ms: looked up on first use only, never by a role process

    try:
        return metadata.version("netsetest")
    except metadata.PackageNotFoundError:  # a source tree on sys.path without an installation
        return "0+unknown"


def __getattr__(name: str) -> Any:
    if name == "__version__":
        return _version()
    if name in ("simulate", "SimulationResult", "NodeSeries"):
        from netsetest import api

        return getattr(api, name)
    raise AttributeError(f"module 'netsetest' has no attribute {name!r}")
