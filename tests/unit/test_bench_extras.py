"""`netsetest bench` with the extras the README names (cvxpy, and plant for its car part), not the dev
extra: it once stopped with a ModuleNotFoundError traceback for msgpack (a test-only package), exit 1."""

from __future__ import annotations

import importlib
import math
import pkgutil
import sys

import msgspec
import pytest

import netsetest_bench
from netsetest.cli.main import main


def test_the_benchmark_imports_and_forges_without_msgpack(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "msgpack", None)  # as if not installed: importing it raises
    for name in [m for m in sys.modules if m.startswith("netsetest_bench.")]:
        monkeypatch.delitem(sys.modules, name)
    for mod in pkgutil.iter_modules(netsetest_bench.__path__, "netsetest_bench."):
        importlib.import_module(mod.name)
    from netsetest_bench.attacks import _payloads

    (_, nan_input), *_ = _payloads("input", "r", 10)
    assert math.isnan(msgspec.msgpack.decode(nan_input)["y"])  # the NaN input the access control refuses
    crash = [msgspec.msgpack.decode(p) for _, p in _payloads("crash", "r", 10)[3:4]]
    assert crash[0]["published"]["xhat"][0] == 1.8e154


def test_a_missing_extra_of_the_bench_is_exit_2_before_any_work(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    real = importlib.import_module

    def import_module(name: str, *a: object) -> object:  # vehiclemodels (the plant extra) as if not installed
        if name.startswith("vehiclemodels"):
            raise ImportError(name)
        return real(name, *a)

    monkeypatch.setattr("netsetest.extras.importlib.import_module", import_module)
    monkeypatch.setattr("netsetest_bench.run.run_bench", lambda *a: pytest.fail("the bench ran without its extra"))
    assert main(["bench", "--only", "plant"]) == 2
    assert capsys.readouterr().err == "netsetest bench: the benchmark's car part needs vehiclemodels: pip install 'netsetest[plant]'\n"


def test_the_view_part_without_a_browser_is_exit_2_before_any_work(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("rerun")  # with its extras, only the browser is missing
    pytest.importorskip("bokeh")
    monkeypatch.setattr("netsetest_bench.browser.shutil.which", lambda name: None)  # no Chromium on the PATH
    monkeypatch.setattr("netsetest_bench.run.run_bench", lambda *a: pytest.fail("the bench ran without a browser"))
    assert main(["bench", "--only", "view"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("netsetest bench: --only view: no Chromium on this machine") and err.count("\n") == 1
