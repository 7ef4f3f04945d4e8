"""``campaign --report``'s page in a real browser (headless Chromium, netsetest_bench/browser.py): it renders
without a console error, with the summary table, the distributions, the detection delay against the fault's
size and the worst runs' replay commands; its screenshot is not blank.  Skips where Chromium is not installed."""

from __future__ import annotations

from pathlib import Path

import pytest

from campaign_helpers import campaign_file_fixture
from netsetest.cli.main import main
from netsetest_bench.browser import BOKEH_READY, NoBrowser, chromium, load_page

ROOTS = "(() => { const d = Bokeh.documents[0]; return (typeof d.roots === 'function' ? d.roots() : d.roots).length; })()"  # the page's figures
MIN_PIXEL_STD = 10.0  # grey levels: a blank (or one-colour) page is about 0
CAMPAIGN = """
name = "page"
[grid]
topology = "paper6"
estimator = ["sdp", "interval"]
seeds = 0
steps = 24  # past the faults' onsets (steps 10-20): detection delays to draw
fault_scale = [0.5, 1.0]
[compute]
figures = ["verdict", "widths", "detection", "exact"]
"""


campaign_file = campaign_file_fixture(CAMPAIGN)


def test_campaign_page_renders_in_chromium(campaign_file: Path, tmp_path: Path) -> None:
    pytest.importorskip("bokeh")
    try:
        chromium()
    except NoBrowser as e:
        pytest.skip(str(e))
    assert main(["campaign", str(campaign_file), "--out", str(tmp_path / "out"), "--workers", "2", "--report", "--quiet"]) == 0
    page = tmp_path / "out" / "report.html"
    seen = load_page(page.resolve().as_uri(), tmp_path, {"text": "document.body.innerText", "figures": ROOTS}, ready=BOKEH_READY)
    assert seen.errors == [] and seen.failed_requests == []
    text = seen.values["text"]
    assert "4 of 4 runs: 4 PASS" in text and "The worst runs, each with the command that replays it" in text
    assert text.count("netsetest run paper6 --steps 24 --estimator") == 4
    assert seen.values["figures"] == 5  # coverage, β, r, fault over exact, detection delay
    assert seen.pixel_std() > MIN_PIXEL_STD
