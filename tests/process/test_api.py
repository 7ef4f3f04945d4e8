"""The Python API: ``netsetest.simulate`` and the README's example, which runs as written."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import netsetest
from netsetest.config.schema import ConfigError
from netsetest.records.record import load_record

ROOT = Path(__file__).resolve().parents[2]


def readme_api_example() -> str:
    text = (ROOT / "README.md").read_text()
    section = text.split("## Python API", 1)[1]
    m = re.search(r"```python\n(.*?)```", section, re.S)
    assert m, "the README's Python API section has no python code block"
    return m.group(1)


def test_readme_api_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)  # a bundled name, not a path: works from any directory
    ns: dict = {}
    exec(compile(readme_api_example(), "README.md:python-api", "exec"), ns)
    out = capsys.readouterr().out
    res = ns["res"]
    assert isinstance(res, netsetest.SimulationResult)
    assert res.violations == 0 and "violations 0" in out
    assert ns["inside"].all()  # every node-step contained (and covered: the paper case breaks nothing)
    assert ns["width"][-1] < ns["width"][0]
    assert len(ns["df"]) == 6 * 21


def test_simulate_arrays_match_the_record(tmp_path: Path) -> None:
    res = netsetest.simulate("paper6_lossy", case="saim", steps=8, seed=3)
    res.save(tmp_path / "r.json")
    rec = load_record(tmp_path / "r.json")
    assert rec.summary == res.summary and rec.meta.case == "saim" and rec.meta.seed == 3
    for i, s in res.nodes.items():
        tr = rec.nodes[i]
        assert s.steps.dtype.kind == "i" and list(s.steps) == list(range(9))
        assert np.array_equal(s.centre, tr.xhat) and np.array_equal(s.E, tr.E, equal_nan=True)
        for j in range(3):
            lo, hi = tr.bounds(j)
            assert np.array_equal(s.lower[:, j], lo) and np.array_equal(s.upper[:, j], hi)
        for n, k in enumerate(s.steps):
            t = rec.truth_at(int(k))
            assert list(s.truth[n]) == [t["x"][0], t["x"][1], t["faults"][i]]
        assert np.allclose(s.t, s.steps * 0.1, rtol=0, atol=1e-12)
        # covered steps are counted from the record's flags; with the derived sector SAIM is covered throughout
        assert res.covered_steps[i] == int(tr.assumptions_ok.sum()) == len(s.steps)
        assert res.covered_steps[i] == res.summary.node(i).steps_covered
        assert (s.contained == (s.E <= s.rho)).all()


def test_simulate_is_deterministic_and_rejects_bad_input() -> None:
    a = netsetest.simulate("paper6", steps=3, signals="worst", seed=1)
    b = netsetest.simulate("paper6", steps=3, signals="worst", seed=1)
    assert all(np.array_equal(a.nodes[i].centre, b.nodes[i].centre) for i in a.nodes)
    with pytest.raises(ConfigError, match="nosuch"):
        netsetest.simulate("nosuch")
    with pytest.raises(ConfigError, match="mode"):
        netsetest.simulate("paper6", steps=2, mode="bogus")


@pytest.mark.zenoh
def test_simulate_over_zenoh_equals_in_memory() -> None:
    """mode="zenoh" runs one process per role; lockstep reproduces the in-memory run bit for bit."""
    z = netsetest.simulate("paper6", steps=6, mode="zenoh")
    m = netsetest.simulate("paper6", steps=6)
    assert z.summary.mode == "zenoh" and z.violations == 0
    for i in m.nodes:
        assert np.array_equal(z.nodes[i].centre, m.nodes[i].centre) and np.array_equal(z.nodes[i].upper, m.nodes[i].upper)
