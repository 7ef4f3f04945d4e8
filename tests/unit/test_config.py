"""Configuration: the paper's topology loads as documented; bad files give exit code 2 and a clear message."""

from __future__ import annotations

import re
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from netsetest.cli.main import main
from netsetest.config.schema import ConfigError, load_topology

ROOT = Path(__file__).resolve().parents[2]
TOPOLOGY = ROOT / "topologies" / "paper6.toml"

# Sec. VI
PAPER_C = [(0.0, 3 / 25), (0.0, 3 / 20), (0.0, 9 / 50), (0.0, 1 / 5), (0.0, 4 / 25), (0.0, 7 / 50)]
PAPER_DV = [0.00873, 0.01047, 0.00542, 0.00698, 0.00785, 0.0096]
PAPER_DS = [0.47, 0.42, 0.56, 0.52, 0.58, 0.61]
PAPER_RMAX = [0.08, 0.07, 0.035, 0.06, 0.03, 0.025]
PAPER_GAMMA = [(0.72, 0.85), (0.82, 0.95), (0.76, 0.91), (0.83, 0.98), (0.78, 0.90), (0.87, 0.96)]
PAPER_X0 = [
    (0.028, 0.168, 0.0),
    (0.032, 0.192, 0.0),
    (0.036, 0.216, 0.0),
    (0.023, 0.138, 0.0),
    (0.033, 0.198, 0.0),
    (0.038, 0.288, 0.0),
]


@pytest.fixture(scope="module")
def nsnim():
    return load_topology(TOPOLOGY)


@pytest.fixture(scope="module")
def saim():
    return load_topology(TOPOLOGY, case="saim")


def test_paper6_common(nsnim):
    sc = nsnim
    assert sc.case == "nsnim" and sc.steps == 80 and sc.tau_s == 0.1 and sc.W == 2.0
    assert sc.ids == [1, 2, 3, 4, 5, 6]
    assert (sc.steer_low, sc.steer_high) == (0.0175, 0.0542)
    np.testing.assert_array_equal(sc.x0, [0.0, 0.0])
    for n, c, dv, ds, x0 in zip(sc.nodes, PAPER_C, PAPER_DV, PAPER_DS, PAPER_X0):
        np.testing.assert_allclose(n.sensor.C, c, rtol=0, atol=1e-15)
        assert n.sensor.Dv == dv and n.sensor.Ds == ds and n.sensor.R == 2.0
        np.testing.assert_array_equal(n.x0_hat, x0)
        np.testing.assert_array_equal(n.P0, 0.3 * np.eye(3))
        assert n.rho == 1.0
        assert n.noise_frequency == n.id  # f_cv = i


def test_paper6_nsnim(nsnim):
    for n in nsnim.nodes:
        assert not n.sensor.saturated
        assert n.sensor.h1 == 1.0 and n.sensor.h2 == 1.0 and n.sensor.r_max == np.inf
        assert n.gamma_range is None
        assert n.sensor.sigma(5.0) == 5.0


def test_paper6_saim(saim):
    assert saim.case == "saim"
    for n, rmax, g in zip(saim.nodes, PAPER_RMAX, PAPER_GAMMA):
        assert n.sensor.saturated
        assert n.sensor.r_max == rmax and n.sensor.h1 == 0.8 and n.sensor.h2 == 1.1
        assert n.gamma_range == pytest.approx(g, abs=1e-15)
        assert n.sensor.sigma(5.0) == rmax and n.sensor.sigma(-5.0) == -rmax


def test_steps_override(nsnim):
    assert load_topology(TOPOLOGY, steps=3).steps == 3


@pytest.mark.parametrize("case", ["nsnim", "saim"])
def test_paper6_graph_is_ring_with_self_loops(case, nsnim, saim):
    sc = nsnim if case == "nsnim" else saim
    for n in sc.nodes:
        i = n.id
        expected = {(i - 2) % 6 + 1, i, i % 6 + 1}  # i−1, i, i+1 (mod 6, ids 1..6)
        assert set(n.in_weights) == expected
        assert all(w == 1.0 for w in n.in_weights.values())
        assert sorted(sc.out_neighbours(i)) == sorted(expected - {i})


# ---------------------------------------------------------------- bad inputs through the CLI


def _copy_scenario(tmp_path: Path) -> Path:
    (tmp_path / "topologies").mkdir()
    shutil.copy(TOPOLOGY, tmp_path / "topologies" / "paper6.toml")
    shutil.copytree(ROOT / "nodes", tmp_path / "nodes")
    return tmp_path / "topologies" / "paper6.toml"


def _sub(old: str, new: str, count: int = 1) -> Callable[[str], str]:
    """Text edit that must apply (a no-op mutation would make the test meaningless)."""

    def edit(text: str) -> str:
        assert old in text, f"test setup: {old!r} not in file"
        return text.replace(old, new, count)

    return edit


def _drop_section(name: str) -> Callable[[str], str]:
    def edit(text: str) -> str:
        out, skipping, found = [], False, False
        for line in text.splitlines(keepends=True):
            if line.startswith("["):
                skipping = line.split("#")[0].strip() == f"[{name}]"
                found = found or skipping
            if not skipping:
                out.append(line)
        assert found, f"test setup: no [{name}] section"
        return "".join(out)

    return edit


def test_copy_is_valid(tmp_path):
    """Positive control: the unmodified copy loads in both cases."""
    topo = _copy_scenario(tmp_path)
    assert len(load_topology(topo).nodes) == 6
    assert load_topology(topo, case="saim").nodes[5].sensor.r_max == 0.025


# (id, file edited: "topology" or a profile name or None, edit, extra CLI args, expected file,
#  field regex, reason regex)
BAD = [
    ("missing-file", None, None, [], "nosuch.toml", None, r"not found"),
    ("toml-syntax", "topology", _sub("steps = 80", "steps = = 80"), [], "paper6.toml", r"line \d+", r"not valid TOML"),
    ("unknown-field", "topology", _sub("tau_s = 0.1", "tua_s = 0.1"), [], "paper6.toml", r"\btua_s\b", r"[Ee]xtra|not permitted"),
    ("edge-unknown-node", "topology", _sub("to = 6\nfrom = 6", "to = 6\nfrom = 7"), [], "paper6.toml", r"\bedges\b", r"unknown node 7"),
    ("duplicate-node", "topology", _sub("id = 6", "id = 5"), [], "paper6.toml", r"\bnodes\b", r"duplicate"),
    ("steps-zero", "topology", _sub("steps = 80", "steps = 0"), [], "paper6.toml", r"\bsteps\b", r"greater than or equal to 1"),
    ("tau-negative", "topology", _sub("tau_s = 0.1", "tau_s = -0.1"), [], "paper6.toml", r"\btau_s\b", r"greater than or equal to 0.0001"),
    ("speed-outside", "topology", _sub("amplitude_kmh = 18.0", "amplitude_kmh = 25.0"), [], "paper6.toml", r"\bspeed\b", r"outside"),
    ("profile-missing-C", "yaw3", _sub("C = [0.0, 0.18]", "# no C"), [], "yaw3.toml", r"\.toml: C\b", r"[Rr]equired|missing"),
    ("profile-R-negative", "yaw2", _sub("R = 2.0", "R = -1"), [], "yaw2.toml", r"\.toml: R\b", r"greater than or equal to 1e-12|0\.000000000001"),
    (
        "profile-P0-not-spd",
        "yaw4",
        _sub("P0 = 0.3", "P0 = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]"),
        [],
        "yaw4.toml",
        r"\bP0\b",
        r"positive definite",
    ),
    ("profile-Ds-zero", "yaw5", _sub("Ds = 0.58", "Ds = 0"), [], "yaw5.toml", r"\bDs\b", r"at least 1e-06.*unobservable"),
    ("saturation-h1", "yaw1", _sub("h1 = 0.8", "h1 = 1.2"), [], "yaw1.toml", r"\bh1\b", r"less than 1"),
    ("gamma-order", "yaw6", _sub("gamma_min = 0.87\ngamma_max = 0.96", "gamma_min = 0.96\ngamma_max = 0.87"), [], "yaw6.toml", r"gamma_min", r"exceed"),
    ("missing-profile", "topology", _sub('profile = "yaw4"', 'profile = "nosuch"'), [], "nosuch.toml", None, r"not found"),
    ("saim-no-saturation", "yaw2", _drop_section("saturation"), ["--case", "saim"], "yaw2.toml", r"saturation", r"saim"),
]


@pytest.mark.parametrize("name,target,edit,extra,fname,field_re,reason_re", BAD, ids=[b[0] for b in BAD])
def test_bad_input_exit_2(tmp_path, capsys, name, target, edit, extra, fname, field_re, reason_re):
    topo = _copy_scenario(tmp_path)
    if target == "topology":
        f = topo
    elif target is not None:
        f = tmp_path / "nodes" / f"{target}.toml"
    if target is not None:
        f.write_text(edit(f.read_text()))
    arg = str(tmp_path / "nosuch.toml") if name == "missing-file" else str(topo)
    code = main(["run", arg, "--mode", "inmemory", "--steps", "1", "--quiet", *extra])
    out, err = capsys.readouterr()
    assert code == 2, f"exit {code}\nstdout: {out}\nstderr: {err}"
    assert "Traceback" not in err and "Traceback" not in out
    assert fname in err and len(err.strip().splitlines()) == 1, err  # one line: the file, the field, why
    if field_re:
        assert re.search(field_re, err), f"field {field_re!r} not named in: {err}"
    assert re.search(reason_re, err), f"reason {reason_re!r} not in: {err}"
    # the direct API raises ConfigError with the same text
    if name != "missing-file":
        with pytest.raises(ConfigError):
            load_topology(topo, case="saim" if extra else None)


@pytest.mark.parametrize("bad", ["0", "-3", "x"])
def test_bad_steps_option(tmp_path, capsys, bad):
    topo = _copy_scenario(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["run", str(topo), "--mode", "inmemory", "--steps", bad, "--quiet"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--steps" in err and "Traceback" not in err


@pytest.mark.parametrize(
    "target,content,fname,reason_re",
    [
        ("topology", "", "paper6.toml", r"\bname\b.*[Rr]equired"),
        ("directory", None, "topologies", r"cannot read|directory"),
        pytest.param("topology", b'name = "\xff\xfe"\n', "paper6.toml", r"TOML|UTF-8|utf-8|decode"),
        pytest.param("yaw3", b'label = "\xff"\n', "yaw3.toml", r"TOML|UTF-8|utf-8|decode"),
    ],
    ids=["empty-topology", "directory", "non-utf8-topology", "non-utf8-profile"],
)
def test_unreadable_files_exit_2(tmp_path, capsys, target, content, fname, reason_re):
    topo = _copy_scenario(tmp_path)
    arg = str(topo)
    if target == "directory":
        arg = str(topo.parent)
    elif target == "topology":
        topo.write_bytes(content if isinstance(content, bytes) else content.encode())
    else:
        (tmp_path / "nodes" / f"{target}.toml").write_bytes(content)
    code = main(["run", arg, "--mode", "inmemory", "--steps", "1", "--quiet"])
    out, err = capsys.readouterr()
    assert code == 2, f"exit {code}\nstderr: {err}"
    assert "Traceback" not in err
    assert fname in err and re.search(reason_re, err, re.S), err
