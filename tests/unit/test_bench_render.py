"""The benchmark's figures load into typed data and its prose comes from templates (netsetest_bench/render.py):
a missing figure prints as —, a file that does not fit its part's types is a one-line error naming the field."""

from __future__ import annotations

import ast
import importlib
import json
import shutil
from pathlib import Path

import pytest

from netsetest_bench.docs import PARTS, DocsError, render_docs
from netsetest_bench.figures import network, performance
from netsetest_bench.render import TEMPLATES, FiguresError, blocks, figure, fill

ROOT = Path(__file__).resolve().parents[2]


def test_a_missing_figure_prints_as_a_dash_whatever_its_format() -> None:
    assert figure(None) == figure(None, ".0f") == "—"
    assert figure(1.234) == "1.23" and figure(30000, "thousands") == "30 000"


def test_every_template_block_fills_and_names_only_fields() -> None:
    names = sorted(p.stem for p in TEMPLATES.glob("*.md"))
    assert {"performance", "report", "network"} <= set(names)
    for name in names:
        assert blocks(name), name  # each file is blocks, nothing outside them
    with pytest.raises(KeyError):
        fill("network", "delay", network="1")  # a field the block names and nobody gave: an error, not a blank


def test_the_committed_figures_load_into_their_types() -> None:
    p = performance.load(json.loads((ROOT / "bench" / "results.json").read_text()))
    assert p.meta.config.flood_rate and p.paper["nsnim/scheduled"].fast_ms.median is not None
    assert all(isinstance(k, int) for row in p.inmemory_scaling.rows for k in row.estimator_ms_median_by_degree)  # JSON's "3" is degree 3
    n = network.load(json.loads((ROOT / "bench" / "network.json").read_text())["network"])
    assert n.runs and all(isinstance(i, int) for r in n.runs for i in r.nodes)


def test_figures_of_the_wrong_type_name_the_field() -> None:
    doc = json.loads((ROOT / "bench" / "network.json").read_text())["network"]
    doc["runs"][0]["nodes"]["1"]["delay_network"] = "soon"
    with pytest.raises(FiguresError, match=r"delay_network"):
        network.load(doc)


def test_render_docs_names_the_file_whose_figures_do_not_fit(tmp_path: Path) -> None:
    for source in {p.source for p in PARTS.values()}:
        (tmp_path / source).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / source, tmp_path / source)
    bad = json.loads((ROOT / "bench" / "results.json").read_text())
    bad["launch"]["reps"] = "none"
    (tmp_path / "bench" / "results.json").write_text(json.dumps(bad))
    with pytest.raises(DocsError, match=r"bench/results.json: .*launch"):
        render_docs(tmp_path)


# names of data, not of fields: the figures map an estimator, a case, a case's variant, a coordinate to its figures,
# and the code may pick one by its name
DATA_NAMES = {"sdp", "sdp-ellipsoid", "nsnim", "saim", "nsnim/scheduled", "saim/scheduled", "nsnim/per-rule", "saim/per-rule", "f"}

# the measuring modules whose figures are typed from the measurement on (netsetest_bench/figures/): they build each
# figure as its dataclass and read it by attribute, in every function, not only in their renderers
TYPED_MEASURING = ("run.py", "widths.py", "network_sets.py", "campaign.py")

# string-keyed mappings that are no figures: the product's run parts by name (netsetest/runtime/inmemory.py's
# RunResult.parts, "truth" and "nodes"), and a role's usage by role name (bench/zenoh_runs.py's Lockstep.usage)
NOT_FIGURES = {"parts", "usage"}


def _string_keyed(node: ast.AST) -> list[str]:
    """Every figures[\"key\"] and figures.get(\"key\") under ``node`` (but the names of data, and the mappings of
    :data:`NOT_FIGURES`)."""
    found = []
    for n in ast.walk(node):
        if isinstance(n, ast.Subscript) and isinstance(n.slice, ast.Constant) and isinstance(n.slice.value, str) and n.slice.value not in DATA_NAMES:
            if isinstance(n.value, ast.Attribute) and n.value.attr in NOT_FIGURES:
                continue
            found.append(f"[{n.slice.value!r}] at line {n.lineno}")
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "get" and n.args:
            if isinstance(n.args[0], ast.Constant) and isinstance(n.args[0].value, str):
                found.append(f".get({n.args[0].value!r}) at line {n.lineno}")
    return found


def test_no_renderer_indexes_the_figures_by_string_keys() -> None:
    """Every ``*_markdown`` renderer reads typed figures (netsetest_bench/figures/), none a dict by its keys."""
    checked = 0
    for path in sorted((ROOT / "netsetest_bench").glob("*.py")):
        for fn in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(fn, ast.FunctionDef) and fn.name.endswith("markdown"):
                checked += 1
                assert _string_keyed(fn) == [], f"{path.name}: {fn.name}"
    assert checked >= 20


@pytest.mark.parametrize("name", TYPED_MEASURING)
def test_the_measuring_code_builds_and_reads_typed_figures(name: str) -> None:
    """No function of a measuring module of :data:`TYPED_MEASURING` indexes a dict by a field's name: each figure is
    built as its part's dataclass (netsetest_bench/figures/) and read by attribute, from the measurement to the file."""
    tree = ast.parse((ROOT / "netsetest_bench" / name).read_text(encoding="utf-8"))
    functions = [fn for fn in ast.walk(tree) if isinstance(fn, ast.FunctionDef)]
    assert functions and any(fn.name.endswith("_figures") or fn.name == "run_bench" for fn in functions)
    assert _string_keyed(tree) == [], name


def test_the_string_key_check_sees_a_figure_read_by_its_name() -> None:
    """The check above finds what it looks for: a measuring function that reads a figure by its key, or writes one."""
    code = "def f(cfg, out):\n    out['ratio'] = cfg['steps'] / run.parts['truth']\n    return out.get('x'), rows['sdp']\n"
    assert [x.split(" at")[0] for x in _string_keyed(ast.parse(code))] == ["['ratio']", "['steps']", ".get('x')"]


@pytest.mark.parametrize("part", ["widths", "campaign", "results"])
def test_the_committed_figures_round_trip_through_their_types(part: str) -> None:
    """A part's file loads into its types and writes back as it was (every key kept: the types hold the whole file,
    so a run that builds its figures typed writes what the committed file holds; a figure the file leaves out, an
    optional one, is written as null)."""
    from netsetest_bench.figures import campaign, widths
    from netsetest_bench.run import _as_written

    doc = json.loads((ROOT / "bench" / f"{part}.json").read_text())
    figures = doc if part == "results" else doc[part]
    load = {"widths": widths.load, "campaign": campaign.load, "results": performance.load}[part]
    written = _as_written(load(figures))
    if part == "results":  # the whole file's other parts and its meta's config are not the performance part's types
        figures = {k: v for k, v in figures.items() if k in written} | {"meta": figures["meta"] | {"config": written["meta"]["config"]}}
    assert _without_nulls_absent_from(written, figures) == json.loads(json.dumps(figures))


def _without_nulls_absent_from(written: object, original: object) -> object:
    """``written`` less the null figures ``original`` does not hold (an optional figure left out)."""
    if isinstance(written, dict) and isinstance(original, dict):
        return {k: _without_nulls_absent_from(v, original.get(k)) for k, v in written.items() if k in original or v is not None}
    if isinstance(written, list) and isinstance(original, list) and len(written) == len(original):
        return [_without_nulls_absent_from(w, o) for w, o in zip(written, original)]
    return written


@pytest.mark.parametrize("part", ["plant", "network", "scenario", "exact", "flow", "view", "node", "scaleout", "logs", "widths", "campaign"])
def test_a_part_run_alone_reports_what_render_docs_makes_of_its_file(
    part: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``netsetest bench --only PART --json F --markdown M`` (its measuring faked: the committed figures, numbers as numpy's)
    renders its report from the figures as F holds them, the same text --render-docs makes of that file."""
    import numpy as np

    import netsetest_bench.run as run
    from netsetest_bench.docs import PARTS as DOC_PARTS

    committed = json.loads((ROOT / "bench" / f"{part}.json").read_text())[part]

    def numpy(o: object) -> object:  # a live run's figures: numpy's numbers where the measurements made them
        if isinstance(o, dict):
            return {k: numpy(v) for k, v in o.items()}
        if isinstance(o, list):
            return [numpy(v) for v in o]
        return np.float64(o) if type(o) is float else np.int64(o) if type(o) is int else o

    # the module run_bench imports from (sys.modules': test_bench_extras re-imports the benchmark, so the package's
    # attribute may be another copy), its measuring replaced
    module = importlib.import_module("netsetest_bench." + {"exact": "exact_cost", "node": "node_budget"}.get(part, part))
    monkeypatch.setattr(module, f"{part}_figures", lambda *a: numpy(committed))
    assert run.run_bench(True, str(tmp_path / f"{part}.json"), str(tmp_path / f"{part}.md"), part) == 0
    capsys.readouterr()
    report = (tmp_path / f"{part}.md").read_text()
    written = json.loads((tmp_path / f"{part}.json").read_text())[part]
    doc_part = DOC_PARTS["exact-cost" if part == "exact" else part]  # the section of docs/results.md the part's run measures
    assert doc_part.source == f"bench/{part}.json" and doc_part.draw(written) in report
