"""``netsetest report --html`` and ``compare --html``: what the page holds, its size, and bad input.
The page in a real browser: tests/process/test_browser.py."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from netsetest.cli.main import main
from netsetest.records.meta import RunMeta
from netsetest.records.record import Record, load_record, record_from_parts
from netsetest.records.report_html import MAX_POINTS, RecordPage, write_report

ROOT = Path(__file__).resolve().parents[2]
TOPOLOGY = str(ROOT / "topologies" / "paper6.toml")
SIZE_LIMIT = 5_000_000  # bytes: the target for 1000 steps × 24 nodes


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("report")
    rec, ex = d / "run.jsonl", d / "exact.json"
    assert main(["run", TOPOLOGY, "--mode", "inmemory", "--steps", "30", "--seed", "3", "--record", str(rec), "--quiet"]) == 0
    assert main(["exact", str(rec), "--json", str(ex)]) == 0
    return {"dir": d, "record": rec, "exact": ex}


def test_report_page_holds_verdict_tables_graph_figures_and_exact_ratios(run: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    out = run["dir"] / "page.html"
    assert main(["report", str(run["record"]), "--exact", str(run["exact"]), "--html", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    page = out.read_text()
    assert "PASS: inmemory run, case nsnim" in page and "contained on 186 of 186 node-steps" in page
    assert "fault detection (detected: the published fault interval excludes 0" in page  # the second table
    assert "Exact limit (fault bounds" in page and "width / exact" in page
    exact = json.loads(run["exact"].read_text())
    assert f"{exact['ratios']['nodes']['1']['f']['width_ratio']:.3f}" in page
    for i in range(1, 7):  # every node's line in every figure, and in the graph
        for fig in ("fig5", "fig6-0", "fig6-1", "fig7", "fig8"):
            assert f'"{fig}-node-{i}"' in page
    assert '"graph-nodes"' in page
    # the cuts each node named for its published intervals, per coordinate, counted over its steps (issue 46)
    rec = load_record(run["record"])
    table = re.search(r'<table class="cuts">(.*?)</table>', page, re.S)
    assert table is not None
    for i, tr in rec.nodes.items():
        named = [name for cuts in tr.interval_cuts(2) for name in cuts or ("own set",)]
        top = max(set(named), key=named.count)
        assert f"<td>{i}</td>" in table.group(1) and f"{top} {named.count(top)}" in table.group(1)
    assert not re.search(r"<script[^>]+src=", page), "every script is inline: the page opens offline"
    assert not re.search(r'<link[^>]+href="https?:', page), "no stylesheet from the network"


def test_report_without_exact_has_no_exact_section_and_two_records_share_fig8(run: dict[str, Path]) -> None:
    out = run["dir"] / "two.html"
    assert main(["report", str(run["record"]), str(run["record"]), "--html", str(out)]) == 0
    page = out.read_text()
    assert "Exact limit" not in page
    assert '"mismatch-size"' not in page  # the T-S model drove: no e_k to draw
    assert page.count('"fig8-node-1"') == 1 and page.count('"fig7-node-1"') == 2  # Fig. 8 overlays the records


@pytest.mark.parametrize(
    "args, message",
    [
        (["missing.jsonl"], "missing.jsonl: file not found"),
        (["{record}", "--exact", "{record}"], "not a readable exact document"),
        (["{record}", "--exact", "{other_exact}"], "which is not among the records given"),
        (["{record}", "--html", "{dir}/no/such/dir/x.html"], "does not exist"),
        (["{record}", "--html", "{dir}/x.pdf"], "x.pdf: the page is HTML; give a name ending in .html or .htm"),  # issue 41 item 11
    ],
)
def test_bad_input_is_one_line_and_exit_2(run: dict[str, Path], args: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    other = run["dir"] / "other_exact.json"
    doc = json.loads(run["exact"].read_text())
    other.write_text(json.dumps(doc | {"record": str(run["dir"] / "elsewhere.jsonl")}))
    fill = {"record": str(run["record"]), "other_exact": str(other), "dir": str(run["dir"])}
    argv = ["report", *(a.format(**fill) for a in args)]
    if "--html" not in argv:
        argv += ["--html", str(run["dir"] / "bad.html")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_report_refuses_to_replace_a_page_unless_told(run: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 41 item 11: like ``run --record``, an existing page is replaced only with --overwrite."""
    out = run["dir"] / "kept.html"
    out.write_text("mine")
    assert main(["report", str(run["record"]), "--html", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--html {out}: the file exists; give --overwrite to replace it" in err and len(err.strip().splitlines()) == 1
    assert out.read_text() == "mine"
    assert main(["report", str(run["record"]), "--html", str(out), "--overwrite"]) == 0
    assert "PASS: inmemory run" in out.read_text()


def test_the_page_opens_on_the_node_whose_run_most_needs_a_look(run: dict[str, Path]) -> None:
    """Issue 41 item 14 (the page in Chromium: tests/process/test_browser.py): the node the figures open on is the
    first by outcome (a miss, lost, late, a detected fault), then a node with a fault; node 1 only when all are alike."""
    import dataclasses

    from netsetest.records.record import load_record
    from netsetest.records.report_html import first_detection, focus_node

    rec = load_record(run["record"])
    assert rec.summary is not None
    detected = [i for i in range(1, 7) if rec.summary.node(i).first_detection is not None]
    assert focus_node(rec) == detected[0] and first_detection(rec, detected[0]) == rec.summary.node(detected[0]).first_detection

    def with_rows(**changes: dict) -> Record:
        nodes = [dataclasses.replace(r, **changes.get(str(r.id), {})) for r in rec.summary.nodes]
        return dataclasses.replace(rec, summary=dataclasses.replace(rec.summary, nodes=nodes))

    assert focus_node(with_rows(**{"5": {"missing_from": 12}})) == 5
    assert focus_node(with_rows(**{"5": {"missing_from": 12}, "6": {"violations": 1}})) == 6
    calm = with_rows(**{str(i): {"first_detection": None, "fault_onset": None} for i in range(1, 7)} | {"3": {"first_detection": None, "fault_onset": 9}})
    assert focus_node(calm) == 3


def test_compare_refuses_a_page_that_is_not_html(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The same rule for ``compare --html``, before anything runs."""
    assert main(["compare", TOPOLOGY, "--steps", "2", "--html", str(tmp_path / "cmp.pdf")]) == 2
    err = capsys.readouterr().err
    assert "cmp.pdf: the page is HTML" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "cmp.pdf").exists()


def _synthetic(steps: int, n: int) -> object:
    """A record of ``steps`` × ``n`` nodes on a ring, made from parts (no run: the page's size is what is tested)."""
    rng = np.random.default_rng(0)
    ids = list(range(1, n + 1))
    meta = RunMeta(name="ring24", case="nsnim", signals="paper", steps=steps, tau_s=0.1, node_ids=ids, in_weights={i: {i % n + 1: 0.5} for i in ids})
    truth = [
        {
            "step": k,
            "x": rng.normal(size=2).tolist(),
            "faults": {str(i): float(rng.normal()) for i in ids},
            "y": {str(i): float(rng.normal()) for i in ids},
            "y_nofault": {str(i): float(rng.normal()) for i in ids},
        }
        for k in range(steps)
    ]
    eye = np.eye(3).ravel().tolist()
    nodes = {
        str(i): [
            {
                "step": k,
                "xhat": rng.normal(size=3).tolist(),
                "P": eye,
                "rho": 1.0,
                "E": float(rng.random()),
                "contained": True,
                "assumptions_ok": True,
                "status": "ok",
                "solve_ms": 1.0,
            }
            for k in range(steps)
        ]
        for i in ids
    }
    return record_from_parts(meta, truth, nodes, None)


def test_1000_steps_of_24_nodes_stay_under_5_mb_and_lines_are_decimated(tmp_path: Path) -> None:
    rec = _synthetic(1000, 24)
    size = write_report(tmp_path / "big.html", [RecordPage(rec, "ring24", "", "")])
    assert size < SIZE_LIMIT, f"{size} bytes"
    assert 1000 > MAX_POINTS  # the test decimates, so it checks that the data shown is cut


def test_compare_html_writes_the_table_and_one_figure_per_node(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "compare.html"
    assert main(["compare", TOPOLOGY, "--steps", "12", "--estimators", "sdp,interval", "--html", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    page = out.read_text()
    assert "no estimator missed the truth" in page and "<th>fault/exact</th>" in page and "<td>interval" in page
    for i in range(1, 7):
        assert f'"compare-node-{i}"' in page


def test_a_plant_run_shows_its_e_k_against_the_bound(tmp_path: Path) -> None:
    """paper6_car (a nonlinear car drives the truth): the page draws e_k and its size in the bound's norm, as
    ``plot``'s mismatch figure does (one computation: records.record.mismatch)."""
    pytest.importorskip("vehiclemodels")
    rec, out = tmp_path / "car.jsonl", tmp_path / "car.html"
    assert main(["run", str(ROOT / "topologies" / "paper6_car.toml"), "--mode", "inmemory", "--steps", "15", "--record", str(rec), "--quiet"]) == 0
    assert main(["report", str(rec), "--html", str(out)]) == 0
    page = out.read_text()
    assert '"mismatch-size"' in page and "Model mismatch e_k of" in page
