"""The linter and the type checker run with the tests (so CI runs them): ruff and mypy as configured in pyproject.toml."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_ruff_finds_nothing() -> None:
    ruff = shutil.which("ruff") or str(Path(sys.executable).with_name("ruff"))
    if not Path(ruff).exists():
        pytest.fail("ruff is not installed: pip install -e '.[dev]'")
    p = subprocess.run([ruff, "check", "netsetest", "netsetest_bench", "tests"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr


def test_ruff_format_is_applied() -> None:
    """The code is as `ruff format` writes it (run `ruff format netsetest netsetest_bench tests` before committing)."""
    ruff = shutil.which("ruff") or str(Path(sys.executable).with_name("ruff"))
    p = subprocess.run([ruff, "format", "--check", "netsetest", "netsetest_bench", "tests"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr


def test_mypy_finds_nothing() -> None:
    """The type checker over the package, configured in pyproject.toml ([tool.mypy])."""
    mypy = shutil.which("mypy") or str(Path(sys.executable).with_name("mypy"))
    if not Path(mypy).exists():
        pytest.fail("mypy is not installed: pip install -e '.[dev]'")
    p = subprocess.run([mypy, "--no-error-summary"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr


FMT_SKIP = "# fmt" + ": skip"  # spelled in two parts so that this file does not contain it


def test_every_suppression_says_why() -> None:
    """A `type: ignore[code]` in the package and a `noqa: CODE` anywhere are followed on their line by why
    (mypy and ruff's RUF100 flag unused ones); no formatter directive (the formatter applies everywhere)."""
    import re

    bare = []
    files = sorted((ROOT / "netsetest").rglob("*.py")) + sorted((ROOT / "netsetest_bench").rglob("*.py")) + sorted((ROOT / "tests").rglob("*.py"))
    for path in files:
        for n, line in enumerate(path.read_text().splitlines(), 1):
            typed = "type: ignore" in line and not re.search(r"type: ignore\[[a-z, -]+\]  # \S", line)
            noqa = "# noqa" in line and not re.search(r"# noqa: [A-Z0-9, ]+\s*(#|[-—(])\s*\S", line)
            if path.name != "test_lint.py" and (typed or noqa or FMT_SKIP in line):
                bare.append(f"{path.relative_to(ROOT)}:{n}")
    assert not bare, "a suppression without a reason: " + ", ".join(bare)


def test_no_function_is_above_radon_20() -> None:
    """Cyclomatic complexity as radon counts it (ruff's C901 at 20 leaves out boolean operators and comprehensions'
    conditions, which radon counts) for every function of the package and the benchmark: at most 20 (issue 46)."""
    from radon.complexity import cc_visit

    above = set()
    for path in sorted((ROOT / "netsetest").rglob("*.py")) + sorted((ROOT / "netsetest_bench").rglob("*.py")):
        for block in cc_visit(path.read_text(encoding="utf-8")):
            if block.letter != "C" and block.complexity > 20:  # functions and methods (a class's figure sums its methods)
                name = f"{block.classname}.{block.name}" if getattr(block, "classname", None) else block.name
                above.add(f"{path.relative_to(ROOT)}:{name}")
    assert not above, "above 20 (split it along its seams): " + ", ".join(sorted(above))
