"""Benchmark of the per-node estimator and the runtimes (``netsetest bench``; docs/performance.md).

A package beside netsetest, not in its wheel: a checkout's tooling, installed with it by ``pip install -e
'.[bench]'`` (the extras its parts run: cvxpy's yardsticks, the car, the view; ``dev`` has them). It uses
netsetest's runtime, never its command line (the CLI calls :func:`netsetest_bench.run.run_bench`), and nothing of
netsetest imports it but that command.  Each part's figures load into typed data (:mod:`netsetest_bench.figures`)
and its prose comes from Markdown templates (templates/, :mod:`netsetest_bench.render`).  The straightforward and
naive reference formulations of the SDP, kept as yardsticks, are in :mod:`netsetest_bench.reference`.
"""
