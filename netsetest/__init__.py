"""netsetest: distributed set-membership joint state and sensor-fault estimation (simulator).

``netsetest.simulate(...)`` runs a scenario from Python (see :mod:`netsetest.api`); it is imported on
first use so that role processes, which import this package too, do not pay for it.
"""

from __future__ import annotations

from importlib import metadata
from typing import Any

try:
    __version__ = metadata.version("netsetest")
except metadata.PackageNotFoundError:  # a source tree on sys.path without an installation
    __version__ = "0+unknown"

__all__ = ["__version__", "simulate", "SimulationResult", "NodeSeries"]


def __getattr__(name: str) -> Any:
    if name in ("simulate", "SimulationResult", "NodeSeries"):
        from netsetest import api

        return getattr(api, name)
    raise AttributeError(f"module 'netsetest' has no attribute {name!r}")
