"""Each bench part's figures as frozen dataclasses, one module per part (field names are its JSON's keys).

Every renderer reads a part's figures through its ``load`` (netsetest_bench/render.py, ``typed``), once, and never
indexes the dict itself.  The performance, widths and campaign parts build their figures as these dataclasses from
the measurement on (tests/unit/test_bench_render.py checks that their measuring code reads no figure by its key, and
that their committed files round-trip through the types); the other parts still build a dict and write it.
"""
