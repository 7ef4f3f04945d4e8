"""The package as a user installs it: a wheel built from the checkout, installed into a fresh venv outside
the checkout, runs the bundled scenario from any directory; scipy and cvxpy are extras, not dependencies.

No network: the wheel is built without build isolation (setuptools and wheel come with the ``dev`` extra)
and installed with ``--no-deps --no-index``; its dependencies come from the test's own environment through
a ``.pth`` line (added after the fresh venv's site-packages, so the installed netsetest wins over any
other copy).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

import netsetest
from netsetest.cli.main import main
from netsetest.scenarios import bundled_topologies, resolve_topology

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ("pyproject.toml", "setup.py", "README.md", "LICENSE", "netsetest", "netsetest_bench", "topologies", "nodes")
OPTIONAL = ("scipy", "cvxpy", "pyarrow", "pandas", "matplotlib", "mcap")  # never a plain dependency


def _clean_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env["PYTHONNOUSERSITE"] = "1"
    return env


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    src = tmp_path_factory.mktemp("src")  # build from a copy: the checkout gets no build/ or egg-info
    for name in SOURCES:
        p = ROOT / name
        if p.is_dir():
            shutil.copytree(p, src / name, symlinks=True, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(p, src / name)
    out = tmp_path_factory.mktemp("dist")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q", "-w", str(out), str(src)],
        check=True,
        env=_clean_env(),
        timeout=240,
    )
    (whl,) = out.glob("netsetest-*.whl")
    return whl


@pytest.fixture(scope="module")
def venv(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("venv") / "v"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(d)], check=True, timeout=120)
    py = d / "bin" / "python"
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", "--no-index", str(wheel)], check=True, env=_clean_env(), timeout=240
    )
    site = subprocess.run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], check=True, capture_output=True, text=True
    ).stdout.strip()
    # the dependencies: this environment's site-packages, after the venv's own
    (Path(site) / "zz_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return d


def _run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=cwd, env=_clean_env(), capture_output=True, text=True, timeout=300)


def test_wheel_contents_and_dependencies(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        meta = next(z.read(n).decode() for n in names if n.endswith(".dist-info/METADATA"))
        for t in ("paper6", "paper6_lossy"):
            assert f"netsetest/scenarios/topologies/{t}.toml" in names
        for i in range(1, 7):
            info = z.getinfo(f"netsetest/scenarios/nodes/yaw{i}.toml")
            assert info.file_size > 100  # the file itself, not a symlink
        assert any(n.endswith(".dist-info/licenses/LICENSE") or n.endswith(".dist-info/LICENSE") for n in names)
        assert {n.split("/")[0] for n in names if not n.startswith("netsetest-")} == {"netsetest"}  # the product alone: no netsetest_bench/
        assert not any("bench" in n or "browser" in n for n in names), sorted(n for n in names if "bench" in n or "browser" in n)
    requires = [ln.split(":", 1)[1].strip() for ln in meta.splitlines() if ln.startswith("Requires-Dist:")]
    plain = [r for r in requires if "extra ==" not in r]
    for dep in OPTIONAL:
        assert not any(r.lower().startswith(dep) for r in plain), (dep, plain)
    assert any(r.startswith("cvxpy") and 'extra == "cvxpy"' in r for r in requires)
    for dep, extra in (("pyarrow", "export"), ("matplotlib", "plot"), ("mcap", "mcap"), ("bokeh", "view"), ("rerun-sdk", "view")):
        assert any(r.startswith(dep) and f'extra == "{extra}"' in r for r in requires), (dep, requires)


def test_installed_wheel_runs_bundled_scenario_from_any_directory(venv: Path, tmp_path: Path) -> None:
    exe = venv / "bin" / "netsetest"
    where = _run(str(venv / "bin" / "python"), "-c", "import netsetest; print(netsetest.__file__)", cwd=tmp_path)
    assert where.returncode == 0 and where.stdout.strip().startswith(str(venv)), where
    v = _run(str(exe), "--version", cwd=tmp_path)
    assert v.returncode == 0 and v.stdout.strip() == f"netsetest {netsetest.__version__}", v
    assert netsetest.__version__[0].isdigit()
    r = _run(str(exe), "run", "paper6", "--mode", "inmemory", "--steps", "5", "--quiet", "--record", "r.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "steps 0–5: contained on 36 of 36 node-steps; the guarantee applied on 36." in r.stdout
    assert (tmp_path / "r.json").is_file()
    # a path still works, and python -m netsetest is the same command
    m = _run(
        str(venv / "bin" / "python"),
        "-m",
        "netsetest",
        "run",
        str(ROOT / "topologies" / "paper6_lossy.toml"),
        "--mode",
        "inmemory",
        "--steps",
        "3",
        "--quiet",
        cwd=tmp_path,
    )
    assert m.returncode == 0, m.stderr
    # the benchmark is not in the wheel: `bench` names the extra (from a checkout), one line, exit 2
    bench = _run(str(exe), "bench", "--quick", cwd=tmp_path)
    assert bench.returncode == 2 and bench.stderr.count("\n") == 1 and "pip install -e '.[bench]'" in bench.stderr, bench
    bad = _run(str(exe), "run", "nosuch", "--mode", "inmemory", cwd=tmp_path)
    assert bad.returncode == 2 and f"bundled topologies: {', '.join(bundled_topologies())}" in bad.stderr and "Traceback" not in bad.stderr


def test_bundled_names_resolve_in_the_checkout(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert bundled_topologies() == [
        "paper6",
        "paper6_car",
        "paper6_car_max_faulty",
        "paper6_car_reference",
        "paper6_lap",
        "paper6_lossy",
        "paper6_max_faulty",
        "paper6_reference",
    ]
    assert resolve_topology("paper6").resolve() == (ROOT / "topologies" / "paper6.toml").resolve()
    assert resolve_topology("paper6.toml").resolve() == (ROOT / "topologies" / "paper6.toml").resolve()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "paper6").write_text("")  # an existing file of that name wins over the bundled one
    assert resolve_topology("paper6") == Path("paper6")
    assert resolve_topology("sub/paper6") == Path("sub/paper6")  # a path is never replaced


def test_version_and_module_entry_point(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"netsetest {netsetest.__version__}"
    r = subprocess.run([sys.executable, "-m", "netsetest", "--version"], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert r.returncode == 0 and r.stdout.strip() == f"netsetest {netsetest.__version__}"
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
