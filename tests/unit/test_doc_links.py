"""Every relative link in README.md, DEVELOPERS.md and docs/ leads somewhere: the file exists and, with a
``#fragment``, has a heading of that anchor (GitHub's rule: lower case, punctuation dropped, spaces to
hyphens, ``-1``, ``-2`` … for repeats).  And every doc's part the code, the tests and the docs name in prose
(``docs/estimator.md, "One step"``, ``docs/…md#anchor``, ``docs/design.md §2``) is there (issue 46: 4 of the 8
headings the code named had gone)."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = sorted([ROOT / "README.md", ROOT / "DEVELOPERS.md", *(ROOT / "docs").rglob("*.md")])
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)
CODE = re.compile(r"`[^`\n]*`")


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in FENCE.sub("", path.read_text(encoding="utf-8")).splitlines():
        m = re.match(r"#{1,6} (.*)", line)
        if not m:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def links(path: Path) -> list[str]:
    text = CODE.sub("", FENCE.sub("", path.read_text(encoding="utf-8")))
    return [t for t in LINK.findall(text) if not re.match(r"[a-z]+:", t)]


def test_the_docs_have_links_to_check() -> None:
    assert sum(len(links(p)) for p in DOCS) > 20


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(doc: Path) -> None:
    broken = []
    for target in links(doc):
        file, _, fragment = target.partition("#")
        path = (doc.parent / file).resolve() if file else doc
        if not path.exists():
            broken.append(f"{target}: no such file")
        elif fragment and path.suffix == ".md" and fragment not in anchors(path):
            broken.append(f"{target}: no heading with that anchor")
    assert not broken, f"{doc.relative_to(ROOT)}: " + "; ".join(broken)


# ---------------------------------------------------------------- headings the code and the docs cite in prose

# Every text that names a doc's part, wherever it is written: the package, the tests, the benchmark's code and its
# prose templates (netsetest_bench/templates/), the generated figures' Markdown (bench/) and the docs themselves.  A citation is PATH#anchor, PATH "Heading", PATH, "Heading",
# PATH ("Heading"), PATH *Heading*, PATH, *Heading* (also after "section"), or PATH §N; PATH is docs/….md,
# README.md or DEVELOPERS.md, from the repository's root.
CITING = sorted(
    [
        *(ROOT / "netsetest").rglob("*.py"),
        *(ROOT / "netsetest_bench").rglob("*.py"),
        *(ROOT / "netsetest_bench" / "templates").glob("*.md"),
        *(ROOT / "tests").rglob("*.py"),
        *(ROOT / "bench").rglob("*.md"),
        *DOCS,
    ]
)
CITATION = re.compile(
    r"(?P<doc>(?:docs/[\w./-]+|README|DEVELOPERS)\.md)"
    r"(?:#(?P<anchor>[\w-]+)"
    r"|(?:,\s*\(?|\s+\(?)(?:section\s+)?(?:\"(?P<quoted>\w[^\"]*)\"|\*(?P<starred>\w[^*]*)\*)"
    r"|,?\s*§\s*(?P<number>\d+))"
)
LINE_BREAK = re.compile(r"\s*\n\s*(?:#+\s+)?")  # a citation broken over lines (a comment's, a docstring's) is one text
NUMBERED = re.compile(r"(\d+)\.?\s+")  # "## 4. Calibration (…)"
LABEL = re.compile(r"\*\*([^*]+?)\.?\*\*")  # a paragraph that opens with its name in bold: "**Start-up barrier.** …"


def titles(path: Path) -> list[str]:
    """What a citation may name in ``path``: its headings (a section number left off) and its paragraphs' bold
    opening labels, the docs' run-in subsections."""
    out = []
    for line in FENCE.sub("", path.read_text(encoding="utf-8")).splitlines():
        if m := re.match(r"#{1,6} (.*)", line):
            out.append(NUMBERED.sub("", m.group(1).strip(), count=1) if NUMBERED.match(m.group(1).strip()) else m.group(1).strip())
        elif m := LABEL.match(line):
            out.append(m.group(1).strip())
    return out


def names(cited: str, title: str) -> bool:
    """``cited`` names ``title``: the whole of it or its beginning, up to a word's end ("Adaptive sector" names
    "Adaptive sector: a derived guarantee …"), case aside."""
    c, t = cited.strip().lower(), title.lower()
    return t.startswith(c) and (len(t) == len(c) or not (t[len(c)].isalnum() or t[len(c)] == "_"))


def citations(path: Path) -> list[re.Match[str]]:
    return list(CITATION.finditer(LINE_BREAK.sub(" ", path.read_text(encoding="utf-8"))))


def test_the_code_cites_doc_headings_to_check() -> None:
    cited = [m for p in CITING if p.suffix == ".py" for m in citations(p)]
    assert sum(m["quoted"] is not None or m["starred"] is not None for m in cited) >= 10


def test_every_heading_cited_in_prose_exists() -> None:
    """A doc's part named in a comment, a docstring, a help text or a doc's prose (not only in a Markdown link) is
    there: a heading or a bold-labelled paragraph of that name, an anchor of a heading, a numbered section."""
    broken = []
    for source in CITING:
        for m in citations(source):
            where = f"{source.relative_to(ROOT)}: {m.group(0)}"
            doc = ROOT / m["doc"]
            if not doc.is_file():
                broken.append(f"{where}: no such file")
            elif m["anchor"] is not None:
                if m["anchor"] not in anchors(doc):
                    broken.append(f"{where}: no heading with that anchor")
            elif m["number"] is not None:
                if not any(re.match(rf"#{{1,6}} {m['number']}[.\s]", line) for line in doc.read_text(encoding="utf-8").splitlines()):
                    broken.append(f"{where}: no section of that number")
            elif not any(names(m["quoted"] or m["starred"], t) for t in titles(doc)):
                broken.append(f"{where}: no heading or labelled paragraph of that name")
    assert not broken, "\n".join(broken)
