"""Benchmark of the per-node estimator and the runtimes (``netsetest bench``; docs/performance.md).

Lives next to the package (a source checkout is needed); the straightforward and naive reference
formulations of the SDP, kept as yardsticks, are in :mod:`bench.reference`.
"""
