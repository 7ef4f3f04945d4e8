"""The parts of ``netsetest bench`` that ``--only`` can run alone (a light module: the CLI imports it)."""

SECTIONS = ("performance", "plant", "network", "scenario", "exact")  # speed, memory, runtime and defences: bench/run.py (every section
# below left out); a car as the truth: bench/plant.py; what the exchange can buy: bench/network.py; the paper's scenario per
# node and every estimator compared: bench/scenario.py; what `netsetest exact` costs under k-of-N health: bench/exact_cost.py
PARTS = SECTIONS[1:]  # the parts a whole run also writes to files of their own, beside its JSON (bench/<part>.json)
