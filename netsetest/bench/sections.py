"""The parts of ``netsetest bench`` that ``--only`` can run alone (a light module: the CLI imports it)."""

SECTIONS = ("performance", "plant", "network", "scenario", "flow")  # speed, memory, runtime and defences: bench/run.py (every
# section below left out); a car as the truth: bench/plant.py; what the exchange can buy: bench/network.py; the paper's scenario
# per node and every estimator compared: bench/scenario.py; a collector that falls behind: bench/flow.py (--only flow alone)
PARTS = ("plant", "network", "scenario")  # the parts a whole run also writes to files of their own, beside its JSON (bench/<part>.json)
