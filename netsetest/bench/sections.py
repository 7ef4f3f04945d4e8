"""The parts of ``netsetest bench`` that ``--only`` can run alone (a light module: the CLI imports it)."""

SECTIONS = ("plant",)  # a car as the truth: netsetest/bench/plant.py
