"""Benchmark of the per-node estimator and the runtimes (``netsetest bench``; docs/performance.md).

Needs the ``cvxpy`` extra (its yardsticks; ``dev`` has it).  It uses netsetest's runtime, never its
command line (the CLI calls :func:`netsetest_bench.run.run_bench`).  The straightforward and naive
reference formulations of the SDP, kept as yardsticks, are in :mod:`netsetest_bench.reference`.
"""
