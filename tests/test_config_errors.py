"""Configuration errors as msgspec reports them, rewritten by hand (``schema._explain``) into one line
naming the field and why: the ranges, finiteness, unknown and missing keys, nested tables and lists,
the profile name pattern, and the lax conversions TOML users relied on before (pydantic's)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from netsetest.cli.main import main
from netsetest.config.schema import ConfigError, load_topology

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture()
def topo(tmp_path: Path) -> Path:
    (tmp_path / "topologies").mkdir()
    shutil.copy(ROOT / "topologies" / "paper6.toml", tmp_path / "topologies" / "paper6.toml")
    shutil.copytree(ROOT / "nodes", tmp_path / "nodes")
    return tmp_path / "topologies" / "paper6.toml"


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, f"test setup: {old!r} not in {path.name}"
    path.write_text(text.replace(old, new, 1))


def _error(path: Path) -> str:
    with pytest.raises(ConfigError) as exc:
        load_topology(path)
    return str(exc.value)


CASES = [
    ("topology", "tau_s = 0.1", "tau_s = inf", r"^  tau_s: Input should be a finite number$"),
    ("topology", "tau_s = 0.1", "tau_s = nan", r"^  tau_s: Input should be a finite number$"),
    ("topology", "steps = 80", "steps = 12.5", r"^  steps: Expected `int`, got `float`$"),
    ("topology", "steps = 80", "steps = true", r"^  steps: Expected `int`, got `bool`$"),
    ("topology", "tau_s = 0.1", 'tau_s = "fast"', r"^  tau_s: Expected `float`, got `str`$"),
    ("topology", "[speed]", "[speed]\nzz = 1", r"^  speed\.zz: Extra inputs are not permitted \(unknown field\)$"),
    ("topology", "to = 6\nfrom = 6", "from = 6", r"^  edges\[\d+\]\.to: Field required$"),
    ("topology", "to = 6\nfrom = 6", "to = 6\nfrom = 0", r"^  edges\[\d+\]\.from: Input should be greater than or equal to 1$"),
    ("topology", 'profile = "yaw4"', 'profile = "../nodes/yaw4"', r"^  nodes\[3\]\.profile: Input should be a file name without"),
    ("topology", 'profile = "yaw4"', 'profile = "yaw4"\nestimator = "magic"', r"^  nodes\[3\]: estimator: unknown estimator 'magic'"),
    ("yaw4", "P0 = 0.3", "P0 = [[1.0, 0.0], [0.0, 1.0]]", r"^  P0: must be 3×3, got 2 rows"),
    ("yaw4", "P0 = 0.3", "P0 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1e7]]", r"^  P0: eigenvalues must lie in \[1e-09, 1e\+06\]"),
    ("yaw4", "P0 = 0.3", "P0 = 1e-10", r"^  P0: Input should be greater than or equal to 1e-09$"),
    ("yaw2", "R = 2.0", "R = 1e7", r"^  R: Input should be less than or equal to 1000000.0$"),
]


@pytest.mark.parametrize("target,old,new,line_re", CASES, ids=[f"{c[0]}:{c[2]}" for c in CASES])
def test_one_line_names_field_and_reason(topo, target, old, new, line_re):
    path = topo if target == "topology" else topo.parent.parent / "nodes" / f"{target}.toml"
    _edit(path, old, new)
    msg = _error(topo)
    first, *rest = msg.splitlines()
    assert first == f"{path}: invalid configuration", msg
    assert len(rest) == 1 and re.search(line_re, rest[0]), msg


def test_lax_numbers_as_before(topo):
    """pydantic's lax mode took an integral float or a numeric string for an integer, an integer for
    a float; msgspec's non-strict conversion keeps that."""
    _edit(topo, "steps = 80", 'steps = "12"')
    assert load_topology(topo).steps == 12
    _edit(topo, 'steps = "12"', "steps = 13.0")
    assert load_topology(topo).steps == 13
    _edit(topo, "tau_s = 0.1", "tau_s = 1")
    sc = load_topology(topo)
    assert sc.tau_s == 1.0 and isinstance(sc.tau_s, float)


def test_cli_exit_2_without_traceback(topo, capsys):
    _edit(topo, "tau_s = 0.1", "tau_s = inf")
    code = main(["run", str(topo), "--mode", "inmemory", "--steps", "1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert "tau_s: Input should be a finite number" in err
