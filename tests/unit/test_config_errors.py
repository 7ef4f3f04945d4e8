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

ROOT = Path(__file__).resolve().parents[2]


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
    ("topology", "tau_s = 0.1", "tau_s = inf", r"^tau_s: Input should be a finite number$"),
    ("topology", "tau_s = 0.1", "tau_s = nan", r"^tau_s: Input should be a finite number$"),
    ("topology", "steps = 80", "steps = 12.5", r"^steps: Expected `int`, got `float`$"),
    ("topology", "steps = 80", "steps = true", r"^steps: Expected `int`, got `bool`$"),
    ("topology", "tau_s = 0.1", 'tau_s = "fast"', r"^tau_s: Expected `float`, got `str`$"),
    ("topology", "[speed]", "[speed]\nzz = 1", r"^speed\.zz: Extra inputs are not permitted \(unknown field\)$"),
    ("topology", "to = 6\nfrom = 6", "from = 6", r"^edges\[\d+\]\.to: Field required$"),
    ("topology", "to = 6\nfrom = 6", "to = 6\nfrom = 0", r"^edges\[\d+\]\.from: Input should be greater than or equal to 1$"),
    ("topology", 'profile = "yaw4"', 'profile = "../nodes/yaw4"', r"^nodes\[3\]\.profile: Input should be a file name without"),
    ("topology", 'profile = "yaw4"', 'profile = "yaw4"\nestimator = "magic"', r"^nodes\[3\]: estimator: unknown estimator 'magic'"),
    ("yaw4", "P0 = 0.3", "P0 = [[1.0, 0.0], [0.0, 1.0]]", r"^P0: must be 3×3, got 2 rows"),
    ("yaw4", "P0 = 0.3", "P0 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1e7]]", r"^P0: eigenvalues must lie in \[1e-09, 1e\+06\]"),
    ("yaw4", "P0 = 0.3", "P0 = 1e-10", r"^P0: Input should be greater than or equal to 1e-09$"),
    ("yaw2", "R = 2.0", "R = 1e7", r"^R: Input should be less than or equal to 1000000.0$"),
]


@pytest.mark.parametrize("target,old,new,line_re", CASES, ids=[f"{c[0]}:{c[2]}" for c in CASES])
def test_one_line_names_field_and_reason(topo, target, old, new, line_re):
    path = topo if target == "topology" else topo.parent.parent / "nodes" / f"{target}.toml"
    _edit(path, old, new)
    msg = _error(topo)
    # one line (it once took two: the file, then the field), as the README promises
    assert len(msg.splitlines()) == 1 and msg.startswith(f"{path}: "), msg
    assert re.search(line_re, msg.removeprefix(f"{path}: ")), msg


def test_strict_numbers(topo):
    """No string or fractional value is taken for a number: a quoted ``"from" = "1.0"`` once silently
    rewired an edge (6→5 became 1→5) and the run exited 0.  An integer is still a float (TOML's 1 for 1.0)."""
    for old, new, says in [
        ("steps = 80", 'steps = "12"', "steps: Expected `int`, got `str`"),
        ("steps = 80", "steps = 13.0", "steps: Expected `int`, got `float`"),
        ("to = 5\nfrom = 6", 'to = 5\nfrom = "1.0"', "from: Expected `int`, got `str`"),
    ]:
        text = topo.read_text()
        _edit(topo, old, new)
        assert says in _error(topo)
        topo.write_text(text)
    _edit(topo, "tau_s = 0.1", "tau_s = 1")
    sc = load_topology(topo)
    assert sc.tau_s == 1.0 and isinstance(sc.tau_s, float)


def test_profile_numbers_are_strict(topo):
    prof = topo.parent.parent / "nodes" / "yaw4.toml"
    _edit(prof, "R = 2.0", 'R = "2.0"')
    assert "R: Expected `float`, got `str`" in _error(topo)


@pytest.mark.parametrize(
    "old,new,says",
    [
        ("period_s = 8.0", "period_s = 5e-324", "speed.period_s: Input should be greater than or equal to"),
        ("mean_kmh = 100.0", "mean_kmh = 1e300", "speed.mean_kmh: Input should be less than or equal to"),
    ],
)
def test_physical_ranges_of_the_speed_profile(topo, old, new, says):
    _edit(topo, old, new)
    assert says in _error(topo)


def test_vehicle_parameters_must_be_physical(topo):
    """Found by the configuration fuzzer: a wind gain of 1e300 loaded, then overflowed a node's guaranteed
    fallback set mid-run (FallbackUnavailable)."""
    _edit(topo, "fw = 1360.0", "fw = 1e300")
    assert "vehicle.fw: Input should be less than or equal to" in _error(topo)


def test_fault_bound_must_be_physical(topo):
    """A declared fault bound of 1e300 passed the schema and crashed SAIM nodes (FallbackUnavailable)."""
    _edit(topo.parent.parent / "nodes" / "yaw2.toml", "rate = 0.2", "rate = 1e300")
    assert "fault_bound.rate: Input should be less than or equal to" in _error(topo)


def test_cli_exit_2_without_traceback(topo, capsys):
    _edit(topo, "tau_s = 0.1", "tau_s = inf")
    code = main(["run", str(topo), "--mode", "inmemory", "--steps", "1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert "tau_s: Input should be a finite number" in err


def test_a_wrong_node_dir_is_named(topo, capsys):
    """Issue 41 item 13: a wrong node_dir said only "file not found" (of a profile); the line names node_dir,
    what it resolved to, and, where the directory exists but lacks a profile, the node and its profile."""
    _edit(topo, 'node_dir = "../nodes"', 'node_dir = "../nodez"')
    code = main(["run", str(topo), "--mode", "inmemory", "--steps", "1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert "node_dir '../nodez': no such directory" in err and str(topo.parent.parent / "nodez") in err, err
    _edit(topo, 'node_dir = "../nodez"', 'node_dir = "."')  # a directory, without the profiles
    msg = _error(topo)
    assert msg.startswith(f"{topo}: node 1: profile 'yaw1': yaw1.toml not found in node_dir '.'") and len(msg.splitlines()) == 1, msg
