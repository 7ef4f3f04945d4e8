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
    _, test = readme_commands()
    ci = [ln for ln in (ROOT / ".ci" / "run").read_text().splitlines() if ln and not ln.startswith("#")]
    assert ci[-1] == test


def test_the_generated_section_is_what_the_committed_figures_make() -> None:
    """README's "How close to a real car" tables are bench/plant.json rendered (`netsetest bench --only plant
    --readme README.md`), never typed: editing either alone fails here."""
    import json

    from netsetest.bench.docs import BEGIN, END, render

    readme = (ROOT / "README.md").read_text()
    assert readme.count(BEGIN) == readme.count(END) == 1
    results = json.loads((ROOT / "bench" / "plant.json").read_text())
    assert render(readme, results) == readme
    section = readme[readme.index(BEGIN) : readme.index(END)]
    assert "| held-out drive |" in section and "| estimator | fault width, car |" in section


def test_a_broken_generated_section_is_an_error() -> None:
    import pytest

    from netsetest.bench.docs import BEGIN, END, DocsError, render

    with pytest.raises(DocsError):
        render("# no markers\n", {})
    with pytest.raises(DocsError):
        render(f"{END}\n{BEGIN}\n", {})
