"""The parts of ``netsetest bench`` that ``--only`` can run alone (a light module: the CLI imports it)."""

SECTIONS = ("plant", "network", "scenario")  # a car as the truth: bench/plant.py; what the exchange can buy: bench/network.py;
# the paper's scenario per node and every estimator compared: bench/scenario.py
