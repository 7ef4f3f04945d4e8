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
    "distributed": "cluster",
}


class MissingExtra(Exception):
    """An optional dependency is not installed; the message names the feature and what to install."""


def require(module: str, what: str) -> None:
    """Raise :class:`MissingExtra` unless ``module`` (a key of :data:`EXTRAS`) can be imported."""
    try:
        importlib.import_module(module)
    except ImportError:
        raise MissingExtra(f"{what} needs {module}: pip install 'netsetest[{EXTRAS[module]}]'") from None
