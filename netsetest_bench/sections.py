"""The parts of ``netsetest bench`` that ``--only`` can run alone (a light module: the CLI imports it)."""

# speed, memory, runtime and defences: bench/run.py (every section below left out); a car as the truth: bench/plant.py; what the exchange can buy: bench/network.py; the paper's
# scenario per node and every estimator compared: bench/scenario.py; what `netsetest exact` costs under k-of-N health:
# bench/exact_cost.py; a collector that falls behind: bench/flow.py (--only flow alone); the live view's cost and the report
# page in a browser: bench/view.py (--only view alone); a node's per-message budget: bench/node_budget.py (--only node alone);
# published width over exact per coordinate, every estimator with and without its region: bench/widths.py; a run across two
# network namespaces, a router in each, against one: bench/scaleout.py (--only scaleout alone, root); a recorded drive as the
# world (import, replay, calibration from logs): bench/logs.py (--only logs alone); netsetest campaign on the local pool and a
# Dask cluster, and the 1 000-run paper6 campaign: bench/campaign.py (--only campaign alone)
SECTIONS = ("performance", "plant", "network", "scenario", "exact", "flow", "view", "node", "widths", "scaleout", "logs", "campaign")
PARTS = ("plant", "network", "scenario", "exact", "widths")  # the parts a whole run also writes to files of their own, beside its JSON (bench/<part>.json)
