"""`netsetest bench --spread`: the headline figures of repeated runs side by side (how noisy the benchmark is)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from netsetest_bench.run import TARGETS
from netsetest_bench.spread import SpreadError, spread_figures, spread_markdown
from netsetest.runtime.report import EXIT_BAD_INPUT

ROOT = Path(__file__).resolve().parents[2]
COMMITTED = ROOT / "bench" / "results.json"


def _copy(tmp_path: Path, name: str, **changes: float | None) -> Path:
    doc = json.loads(COMMITTED.read_text())
    doc.update(changes)
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def test_median_spread_and_targets_per_figure(tmp_path: Path) -> None:
    runs = [_copy(tmp_path, f"{i}.json", solve_ms_median=v, launch_to_step0_s=s) for i, (v, s) in enumerate([(0.2, 0.5), (0.4, 1.5), (0.3, 0.7)])]
    res = spread_figures(runs)
    by = {f["key"]: f for f in res["figures"]}
    assert [f["key"] for f in res["figures"]] == [k for k, _, _ in TARGETS]
    assert by["solve_ms_median"]["values"] == [0.2, 0.4, 0.3]
    assert by["solve_ms_median"]["median"] == pytest.approx(0.3)
    assert by["solve_ms_median"]["relative_spread"] == pytest.approx((0.4 - 0.2) / 0.3)
    assert by["solve_ms_median"]["met_in_every_run"]
    assert not by["launch_to_step0_s"]["met_in_every_run"]  # 1.5 s misses < 1 s in one run
    md = spread_markdown(res)
    assert "| `solve_ms_median` | 0.2 | 0.4 | 0.3 | 0.3 | 67 % | ≤ 2 ms | yes |" in md


def test_a_figure_missing_in_one_run_is_not_met(tmp_path: Path) -> None:
    runs = [_copy(tmp_path, "a.json"), _copy(tmp_path, "b.json", node_rss_mb=None)]
    by = {f["key"]: f for f in spread_figures(runs)["figures"]}
    assert not by["node_rss_mb"]["met_in_every_run"]


def test_bad_inputs_are_refused(tmp_path: Path) -> None:
    with pytest.raises(SpreadError, match="2 figures files at least"):
        spread_figures([COMMITTED])
    with pytest.raises(SpreadError, match="not the figures of a performance run"):
        spread_figures([COMMITTED, ROOT / "bench" / "plant.json"])
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(SpreadError, match="cannot be read"):
        spread_figures([COMMITTED, tmp_path / "bad.json"])


def test_the_command_writes_json_and_refuses_measuring_options(tmp_path: Path) -> None:
    out = tmp_path / "spread.json"
    cli = [sys.executable, "-m", "netsetest.cli.main", "bench", "--spread", str(COMMITTED), str(_copy(tmp_path, "b.json"))]
    p = subprocess.run([*cli, "--json", str(out)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert json.loads(out.read_text())["figures"][0]["key"] == TARGETS[0][0]
    p = subprocess.run([*cli, "--only", "plant"], capture_output=True, text=True, timeout=60)
    assert p.returncode == EXIT_BAD_INPUT and "--spread measures nothing; --only" in p.stderr and "Traceback" not in p.stderr
