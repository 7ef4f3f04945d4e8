"""Optional dependencies (``pip install 'netsetest[EXTRA]'``): one check with one clear message."""

from __future__ import annotations

import importlib

EXTRAS = {
    "matplotlib": "plot",
    "mcap": "mcap",
    "pyarrow": "export",
    "pandas": "export",
    "cvxpy": "cvxpy",
    "vehiclemodels": "plant",
    "bokeh": "view",
    "rerun": "view",
    "rosbags": "logs",
    "asammdf": "logs",
    "distributed": "cluster",
    "numba": "fast",
}


class MissingExtra(Exception):
    """An optional dependency is not installed; the message names the feature and what to install."""


def require(module: str, what: str, extra: str | None = None) -> None:
    """Raise :class:`MissingExtra` unless ``module`` (a key of :data:`EXTRAS`) can be imported; ``extra``: the
    extra to name where it is not the module's own (pyarrow reads drive logs too: ``logs``)."""
    try:
        importlib.import_module(module)
    except ImportError:
        raise MissingExtra(f"{what} needs {module}: pip install 'netsetest[{extra or EXTRAS[module]}]'") from None
