"""Each bench part's figures as frozen dataclasses, one module per part (field names are its JSON's keys).

A run builds its figures as a dict and writes them (bench/<part>.json); every renderer reads them through the
part's ``load`` (netsetest_bench/render.py, ``typed``), once, and never indexes the dict itself.
"""
