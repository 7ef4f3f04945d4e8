"""Which packages an install gets (the rest of the configuration is pyproject.toml's).

The wheel is the product: netsetest/ alone.  The benchmark and its browser driver (netsetest_bench/: ``netsetest
bench``, the browser tests) are tooling of a checkout, like tests/: an editable install of the checkout
(``pip install -e '.[bench]'``, or ``.[dev]``) maps them too, a wheel never holds them.
"""

from setuptools import find_packages, setup
from setuptools.command.editable_wheel import editable_wheel

PRODUCT = ["netsetest", "netsetest.*"]
BENCH = ["netsetest_bench", "netsetest_bench.*"]


class EditableWithBench(editable_wheel):
    """An editable install (PEP 660's build_editable runs this command) maps the benchmark beside the product."""

    def run(self) -> None:
        self.distribution.packages = find_packages(include=PRODUCT + BENCH)
        super().run()


setup(packages=find_packages(include=PRODUCT), cmdclass={"editable_wheel": EditableWithBench})
