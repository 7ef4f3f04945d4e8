"""No result in the docs is typed by hand: docs/results.md and the generated sections of README.md and
docs/performance.md, docs/exact.md and docs/summary.md are what ``netsetest bench --render-docs`` makes of the committed bench/*.json, so
editing a figure in either place alone fails here (DEVELOPERS.md, *Generated docs*)."""

from pathlib import Path

import pytest

from netsetest_bench.docs import PARTS, RESULTS, SECTIONED, DocsError, begin, end, render, render_docs

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def rendered() -> dict[str, str]:
    return render_docs(ROOT)


@pytest.mark.parametrize("name", [*SECTIONED, RESULTS])
def test_the_committed_doc_is_what_the_committed_figures_make(name: str, rendered: dict[str, str]) -> None:
    committed = (ROOT / name).read_text(encoding="utf-8")
    assert committed == rendered[name], f"{name} differs from what `netsetest bench --render-docs` writes: run it and commit the result"


@pytest.mark.parametrize(
    ("name", "parts"),
    [
        ("README.md", ("scenario", "network-summary", "plant-summary", "performance")),
        ("docs/performance.md", ("performance", "spread")),
        ("docs/exact.md", ("exact",)),
        ("docs/records.md", ("view-summary",)),
        ("docs/summary.md", ("flow",)),
        ("docs/estimator.md", ("widths-summary", "widths-region")),
    ],
)
def test_the_generated_sections_are_there(name: str, parts: tuple[str, ...]) -> None:
    """A deleted marker pair would silently leave a section unchecked."""
    text = (ROOT / name).read_text(encoding="utf-8")
    for part in parts:
        assert text.count(begin(part)) == text.count(end(part)) == 1
        assert "|---|" in text[text.index(begin(part)) : text.index(end(part))]


def test_the_results_page_has_every_part_and_its_measuring_command(rendered: dict[str, str]) -> None:
    text = rendered[RESULTS]
    for part in PARTS.values():
        assert (f"## {part.title}\n" in text) == part.in_results and f"`{part.measure}`" in text


def test_a_broken_generated_section_is_an_error() -> None:
    with pytest.raises(DocsError):
        render(f"{end('plant')}\n{begin('plant')}\n", {"plant": "x\n"})
    with pytest.raises(DocsError):
        render(f"{begin('plant')}\n", {"plant": "x\n"})
    assert render("# no markers\n", {"plant": "x\n"}) == "# no markers\n"
    assert render(f"a\n{begin('plant')}\nold\n{end('plant')}\nb\n", {"plant": "new\n"}) == f"a\n{begin('plant')}\nnew\n{end('plant')}\nb\n"


def test_a_missing_figures_file_names_the_command_that_measures_it(tmp_path: Path) -> None:
    with pytest.raises(DocsError, match="netsetest bench --quick --only scenario"):
        render_docs(tmp_path)
