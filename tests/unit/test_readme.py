"""The README's first two commands are what a new user copies; CI must run the second one verbatim."""

from pathlib import Path

import pytest

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


@pytest.mark.parametrize(("part", "expect"), [("plant", ("| held-out drive |", "| estimator | fault width, car |")),
                                             ("network", ("| topology | case | signals |",))])
def test_the_generated_sections_are_what_the_committed_figures_make(part: str, expect: tuple[str, ...]) -> None:
    """README's generated tables are bench/<part>.json rendered (`netsetest bench --only <part> --readme
    README.md`), never typed: editing either alone fails here."""
    import json

    from netsetest.bench.docs import begin, end, render

    readme = (ROOT / "README.md").read_text()
    assert readme.count(begin(part)) == readme.count(end(part)) == 1
    results = json.loads((ROOT / "bench" / f"{part}.json").read_text())
    assert render(readme, results) == readme
    section = readme[readme.index(begin(part)) : readme.index(end(part))]
    assert all(e in section for e in expect)


def test_a_broken_generated_section_is_an_error() -> None:
    from netsetest.bench.docs import DocsError, begin, check_markers, end, render

    with pytest.raises(DocsError):
        render("# no markers\n", {"plant": {}})
    with pytest.raises(DocsError):
        render(f"{end('plant')}\n{begin('plant')}\n", {"plant": {}})
    assert check_markers("# none\n", "network") == "no generated network section (markers) in it"
