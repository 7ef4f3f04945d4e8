"""The README's first two commands are what a new user copies; CI must run the second one verbatim."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def readme_commands() -> list[str]:
    lines = (ROOT / "README.md").read_text().splitlines()
    assert lines[0].startswith("```"), "the README must start with the two commands"
    return [lines[1], lines[2]]


def test_readme_starts_with_run_and_test_commands():
    run, test = readme_commands()
    assert "pip install" in run and "netsetest run topologies/paper6.toml" in run
    assert "pip install" in test and '".[dev]"' in test and test.rstrip().endswith("pytest")


def test_ci_runs_the_readme_test_command_verbatim():
    """.ci/run runs it as its first command after the system packages, then the blas tests under every other
    OpenBLAS kernel the CPU runs (.ci/blas_kernels.py)."""
    _, test = readme_commands()
    text = (ROOT / ".ci" / "run").read_text()
    ci = [ln for ln in text.splitlines() if ln and not ln.startswith(("#", " "))]
    assert test in ci and ci[ci.index(test) - 1] == "fi"  # the README's command right after the system packages' block
    after = ci[ci.index(test) + 1 :]
    assert after == ["for kernel in $(python .ci/blas_kernels.py); do", "done"]
    assert "OPENBLAS_CORETYPE=$kernel pytest -q -m blas" in text
