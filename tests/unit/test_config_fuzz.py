"""Fuzzing the configuration loader (Hypothesis): a topology or a node profile with one to three values
replaced by arbitrary TOML values (any type, extremes included), or arbitrary bytes, either loads as a
Scenario that a short run accepts, or raises ConfigError (exit 2) — never anything else.  A profile value
of 1e300 once passed the schema and crashed SAIM nodes mid-run; a quoted number rewired an edge.
``NETSETEST_FUZZ_EXAMPLES`` raises the number of examples for a long run."""

from __future__ import annotations

import math
import os
import re
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from netsetest.config.schema import ConfigError, load_topology
from netsetest.runtime.inmemory import run_inmemory

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = int(os.environ.get("NETSETEST_FUZZ_EXAMPLES", "0")) or None
FUZZ = settings(
    max_examples=EXAMPLES or 80,
    derandomize=EXAMPLES is None,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
VALUE_LINE = re.compile(r"^(\s*[A-Za-z0-9_\"]+\s*=\s*)(.+?)(\s*#.*)?$")


def _toml(v: object) -> str:
    """A TOML literal of v (TOML has no null: None is never drawn)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    raise TypeError(type(v))


_SCALAR = (
    st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**63 - 1)
    | st.integers(-3, 100)
    | st.floats()
    | st.sampled_from([0.0, -0.0, 1e300, -1e300, 5e-324, 0.2, 1.0, 80.0])
    | st.text(alphabet="abcdefghijklmnopqrstuvwxyz0123456789.-_", max_size=6)
)
_VALUE = _SCALAR | st.lists(_SCALAR, max_size=4) | st.lists(st.lists(st.floats(-2, 2) | st.integers(-2, 2), max_size=4), max_size=4)


@pytest.fixture()
def tree(tmp_path: Path) -> Path:
    (tmp_path / "topologies").mkdir()
    shutil.copy(ROOT / "topologies" / "paper6.toml", tmp_path / "topologies" / "paper6.toml")
    shutil.copytree(ROOT / "nodes", tmp_path / "nodes")
    return tmp_path


def _similar(v: object) -> st.SearchStrategy:
    """Values of v's type near and far from it (so that many mutations still load and reach a run)."""
    if isinstance(v, bool):
        return st.booleans()
    if isinstance(v, int):
        return st.integers(v - 3, v + 3) | st.integers(min_value=-(2**63), max_value=2**63 - 1)
    if isinstance(v, float) and not math.isfinite(v):  # a value an earlier mutation put on this line
        return _VALUE
    if isinstance(v, float):
        lo, hi = sorted((v * 0.5, v * 2))
        return st.floats(lo - 1e-3, hi + 1e-3, allow_nan=False) | st.sampled_from([v * 1e3, v * 1e-3, -v, 1e300, 5e-324])
    if isinstance(v, list) and v:
        return st.lists(_similar(v[0]), min_size=len(v), max_size=len(v))
    return _VALUE


def _mutate(path: Path, data: st.DataObject, count: int, after: str | None = None) -> None:
    """Replace ``count`` values of the file (``after``: only on lines after the first that starts with it)."""
    import tomllib

    lines = path.read_text().splitlines()
    first = 0 if after is None else next(n for n, ln in enumerate(lines) if ln.startswith(after))
    values = [n for n, ln in enumerate(lines) if n >= first and VALUE_LINE.match(ln)]
    for _ in range(count):
        n = data.draw(st.sampled_from(values))
        m = VALUE_LINE.match(lines[n])
        assert m is not None
        try:
            current = tomllib.loads("x = " + m.group(2))["x"]
        except tomllib.TOMLDecodeError:
            current = None
        lines[n] = m.group(1) + _toml(data.draw(_similar(current) | _VALUE))
    path.write_text("\n".join(lines) + "\n")


def _one_line(exc: ConfigError, tree: Path) -> None:
    """A configuration error is one line naming the file (then the field and why): 125 of 151 took two."""
    msg = str(exc)
    assert len(msg.splitlines()) == 1 and msg.startswith(str(tree)), msg


def _load_and_run(topo: Path) -> None:
    try:
        sc = load_topology(topo, None, 2)
    except ConfigError as exc:
        _one_line(exc, topo.parent.parent)
        return
    for case in ("nsnim", "saim"):  # what loads must run: a value the schema admits must not crash a node
        run_inmemory(load_topology(topo, case, 2), keep=False)
    assert sc.steps == 2


@FUZZ
@given(st.sampled_from(["topology", "yaw1", "yaw2", "yaw6"]), st.integers(1, 3), st.data())
def test_mutated_configuration_loads_and_runs_or_is_refused(tree: Path, target: str, count: int, data: st.DataObject) -> None:
    topo = tree / "topologies" / "paper6.toml"
    shutil.copytree(ROOT / "nodes", tree / "nodes", dirs_exist_ok=True)
    shutil.copy(ROOT / "topologies" / "paper6.toml", topo)
    _mutate(topo if target == "topology" else tree / "nodes" / f"{target}.toml", data, count)
    _load_and_run(topo)


GROUPS = "\n[[network.health_groups]]\nnodes = [1, 2, 3]\nmax_faulty = 2\n\n[[network.health_groups]]\nnodes = [4, 5, 6]\nmax_faulty = 2\n"


@FUZZ
@given(st.integers(1, 3), st.data())
def test_mutated_health_groups_load_and_run_or_are_refused(tree: Path, count: int, data: st.DataObject) -> None:
    """The k-of-N groups' values replaced (node ids, m: any type, extremes, unknown or shared nodes)."""
    topo = tree / "topologies" / "paper6.toml"
    topo.write_text((ROOT / "topologies" / "paper6.toml").read_text() + GROUPS)
    _mutate(topo, data, count, after="[[network.health_groups]]")
    _load_and_run(topo)


@FUZZ
@given(st.binary(max_size=300))
def test_arbitrary_bytes_as_a_topology(tree: Path, data: bytes) -> None:
    topo = tree / "topologies" / "paper6.toml"
    topo.write_bytes(data)
    try:
        load_topology(topo)
    except ConfigError as exc:
        _one_line(exc, tree)
