"""The parts of ``netsetest bench`` that ``--only`` can run alone (a light module: the CLI imports it)."""

SECTIONS = ("plant", "network")  # a car as the truth: bench/plant.py; what the exchange can buy: bench/network.py
