"""Estimator names, in a module without heavy imports (the CLI's help lists them)."""

SDP = "sdp"  # this project's ellipsoidal SDP (estimator/sdp.py), run by roles/node.py
EXACT = "exact"  # the exact limit (analysis/exact.py): a comparison row, not a real-time estimator
SET_ESTIMATOR_NAMES: tuple[str, ...] = ("zonotope", "zonotope-q10", "interval", "interval-classical", "strip", "setprop")
NO_REGION = "-noregion"  # a set estimator as its paper defines it: its own set, without the region (estimator/region.py)
NO_REGION_NAMES: tuple[str, ...] = tuple(n + NO_REGION for n in ("zonotope", "interval", "strip", "setprop"))
ESTIMATOR_NAMES: tuple[str, ...] = (SDP, *SET_ESTIMATOR_NAMES, *NO_REGION_NAMES, EXACT)
DEFAULT_COMPARE: tuple[str, ...] = (SDP, "zonotope", "interval", "strip", "setprop", EXACT)
NODE_ESTIMATOR_NAMES: tuple[str, ...] = (SDP, *SET_ESTIMATOR_NAMES, *NO_REGION_NAMES)  # what a node can run in the network (`run --estimator`)
