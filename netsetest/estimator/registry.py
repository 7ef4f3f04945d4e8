"""The guaranteed estimators a node can run, by name (``netsetest compare --estimators``).

``sdp`` is this project's ellipsoidal estimator (estimator/sdp.py), run by roles/node.py in the network;
the others implement estimator/base.py and are stepped per node on a run's data, each with a region of x
(estimator/region.py) unless named ``<name>-noregion`` (the method as its paper defines it).
"""

from __future__ import annotations

from collections.abc import Callable

from netsetest.config.schema import ConfigError, Scenario
from netsetest.estimator.base import EstimatorError, SetEstimator
from netsetest.estimator.names import NO_REGION
from netsetest.estimator.region import WithRegion


# Each method's module is imported when a node runs it: an SDP node never loads the others.
def _zonotope(sc: Scenario, i: int, order: int | None = None) -> SetEstimator:
    from netsetest.estimator.zonotope_w_radius import ZonotopeEstimator

    return ZonotopeEstimator(sc, i, order=order)


def _interval(sc: Scenario, i: int, wrapping: bool = False) -> SetEstimator:
    from netsetest.estimator.interval_althoff_rath import IntervalObserver

    return IntervalObserver(sc, i, wrapping=wrapping)


def _strip(sc: Scenario, i: int) -> SetEstimator:
    from netsetest.estimator.strip_althoff_rath import StripObserver

    return StripObserver(sc, i)


def _setprop(sc: Scenario, i: int) -> SetEstimator:
    from netsetest.estimator.set_propagation_althoff_rath import SetPropagationObserver

    return SetPropagationObserver(sc, i)


SET_ESTIMATORS: dict[str, Callable[[Scenario, int], SetEstimator]] = {
    "zonotope": _zonotope,
    "zonotope-q10": lambda sc, i: _zonotope(sc, i, order=10),
    "interval": _interval,
    "interval-classical": lambda sc, i: _interval(sc, i, wrapping=True),
    "strip": _strip,
    "setprop": _setprop,
}


# methods whose set has no bound on the fault once a reading sits at the saturation limit (one-sided):
# on a saturating sensor they need a declared fault bound (the SDP copes with an assumed sector instead)
UNBOUNDED_WHEN_SATURATED = frozenset({"zonotope", "zonotope-q10", "interval", "interval-classical"})


def node_set_estimator(scenario: Scenario, node_id: int) -> SetEstimator:
    """The set estimator node ``node_id`` is configured to run in the network; ConfigError if it refuses
    the node (e.g. ``strip`` without a declared fault bound, or ``zonotope`` on a saturating sensor
    without one: it fell back to its previous set at the first saturated reading and failed the run)."""
    node = scenario.node(node_id)
    name = node.estimator.removesuffix(NO_REGION)  # ``<name>-noregion``: the method's own set alone
    if name in UNBOUNDED_WHEN_SATURATED and node.sensor.saturated and node.fault_rate is None and node.fault_size is None:
        raise ConfigError(
            f"{scenario.path}: node {node_id}: estimator {name!r} on a saturating sensor needs a declared "
            "[fault_bound] rate or size (a reading at the saturation limit leaves the fault unbounded); sdp copes without"
        )
    try:
        est = SET_ESTIMATORS[name](scenario, node_id)
    except EstimatorError as exc:
        raise ConfigError(f"{scenario.path}: node {node_id}: estimator {name!r}: {exc}") from None
    if node.estimator.endswith(NO_REGION):
        return est
    return WithRegion(est, scenario, node_id)
