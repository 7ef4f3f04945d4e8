"""Benchmark of the per-node estimator and the runtimes (``python -m bench.run``; docs/performance.md).

Lives next to the package, not in it (a source checkout with the ``dev`` extra is needed); it uses
netsetest's runtime, never its command line. the straightforward and naive reference
formulations of the SDP, kept as yardsticks, are in :mod:`bench.reference`.
"""
