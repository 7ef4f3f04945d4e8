"""Layering: the command line sits on top.  Nothing below netsetest/cli imports it (the launcher of a
Zenoh run is runtime/launcher.py; the benchmark, netsetest_bench, uses the runtime, never the command
line), and nothing in the package reaches outside it (the old top-level bench/ is gone)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGE, CLI, BENCH = ROOT / "netsetest", ROOT / "netsetest" / "cli", ROOT / "netsetest_bench"


def _imported(path: Path) -> set[str]:
    """Every module a file imports, anywhere in it (also inside functions): ``from a import b`` gives a and a.b."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
    return out


def _offenders(files: list[Path], banned: str) -> dict[str, list[str]]:
    """File → the modules it imports at or below ``banned``."""
    hits = {}
    for f in files:
        bad = sorted(m for m in _imported(f) if m == banned or m.startswith(banned + "."))
        if bad:
            hits[f.name if not f.is_relative_to(ROOT) else str(f.relative_to(ROOT))] = bad
    return hits


def test_the_check_sees_every_form_of_import(tmp_path: Path) -> None:
    forms = ["from netsetest import cli", "import netsetest.cli.main", "from netsetest.cli.processes import free_ports"]
    for n, line in enumerate(forms):
        f = tmp_path / f"m{n}.py"
        f.write_text(f"def g():\n    {line}\n")  # inside a function: a lazy import counts too
        assert _offenders([f], "netsetest.cli"), line
    ok = tmp_path / "ok.py"
    ok.write_text("import netsetest.client_tools\nfrom netsetest.runtime import launcher\n")
    assert not _offenders([ok], "netsetest.cli")


def test_nothing_below_the_cli_imports_it() -> None:
    entry = PACKAGE / "__main__.py"  # `python -m netsetest` runs the CLI: above it, not below
    below = [f for f in PACKAGE.rglob("*.py") if CLI not in f.parents and f != entry]
    assert len(below) > 20  # the package is really there
    assert _offenders(below, "netsetest.cli") == {}


def test_bench_is_below_the_cli_and_the_product_never_imports_it() -> None:
    assert len(list(BENCH.glob("*.py"))) >= 5 and _offenders(sorted(BENCH.glob("*.py")), "netsetest.cli") == {}
    below = [f for f in PACKAGE.rglob("*.py") if CLI not in f.parents]
    assert _offenders(below, "netsetest_bench") == {}  # not in the wheel: only the CLI's `bench` reaches it
    assert _offenders(sorted(PACKAGE.rglob("*.py")), "bench") == {}  # a top-level bench/ would not be in the wheel either


def test_bench_without_cvxpy_exits_2_before_any_work() -> None:
    """``netsetest bench`` names the missing extra, as every command does, without a traceback."""
    code = "import sys; sys.modules['cvxpy'] = None; from netsetest.cli.main import main; sys.exit(main(['bench', '--quick']))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out.stderr[-500:]
    assert "needs cvxpy" in out.stderr and "pip install 'netsetest[cvxpy]'" in out.stderr and "Traceback" not in out.stderr


@pytest.mark.parametrize("args", [["--quick"], ["--only", "widths", "--baseline", "x"], ["--render-docs"], ["--spread", "a.json"], ["--only", "nosuch"]])
def test_bench_not_installed_exits_2_naming_its_extra(args: list[str]) -> None:
    """Where netsetest_bench is missing (an install of the wheel, which does not hold it), every form of ``netsetest
    bench`` says so on one line, naming the extra and that it needs a checkout, before any work, with no traceback."""
    code = f"import sys; sys.modules['netsetest_bench'] = None; from netsetest.cli.main import main; sys.exit(main(['bench', *{args!r}]))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out.stderr[-500:]
    assert out.stderr.count("\n") == 1 and "Traceback" not in out.stderr
    assert out.stderr.startswith("netsetest bench: the benchmark (netsetest_bench) is not installed") and "pip install -e '.[bench]'" in out.stderr
