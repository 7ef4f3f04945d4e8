"""Every generated doc, from the committed benchmark figures (no number in them is typed by hand).

Measuring writes bench/<part>.json (``netsetest bench [--quick] [--only PART] --json …``, one command per
part, :data:`PARTS`); ``netsetest bench --render-docs`` then writes, from those files alone and without
measuring, docs/results.md (every part, whole) and the generated sections of the files in
:data:`SECTIONED` (each between :func:`begin` and :func:`end`).  tests/unit/test_docs_generated.py
checks that the committed docs are what :func:`render_docs` makes of the committed figures.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from netsetest_bench.campaign import campaign_markdown
from netsetest_bench.exact_cost import exact_cost_markdown
from netsetest_bench.flow import flow_markdown
from netsetest_bench.logs import logs_markdown, logs_summary_markdown
from netsetest_bench.network import network_markdown, network_summary_markdown
from netsetest_bench.node_budget import node_markdown
from netsetest_bench.plant import plant_markdown, plant_summary_markdown
from netsetest_bench.render import FiguresError
from netsetest_bench.run import performance_markdown
from netsetest_bench.scaleout import scaleout_markdown
from netsetest_bench.scenario import compare_markdown, exact_markdown, scenario_markdown
from netsetest_bench.spread import RUNS_DIR, spread_markdown
from netsetest_bench.view import view_markdown, view_summary_markdown
from netsetest_bench.widths import region_markdown, sets_section, widths_markdown, widths_summary_markdown


@dataclass(frozen=True)
class Part:
    """One generated section: which committed file holds its figures and how it is drawn."""

    title: str  # its heading in docs/results.md
    source: str  # the figures' file, relative to the checkout
    key: str | None  # the part's figures in that file (None: the whole document)
    draw: Callable[[dict], str]
    measure: str  # the command that measures it (and writes ``source``)
    in_results: bool = True  # a heading of its own in docs/results.md (False: a short form for the README)


_SCENARIO = "netsetest bench --quick --only scenario --json bench/scenario.json --markdown bench/scenario.md"
_VIEW = "netsetest bench --quick --only view --json bench/view.json --markdown bench/view.md"
_WIDTHS = "netsetest bench --quick --only widths --baseline BEFORE_REGION --json bench/widths.json --markdown bench/widths.md"  # a checkout of 29290ba
_LOGS = "netsetest bench --quick --only logs --json bench/logs.json --markdown bench/logs.md"
PARTS: dict[str, Part] = {
    "scenario": Part("The paper's scenario, per node", "bench/scenario.json", "scenario", scenario_markdown, _SCENARIO),
    "compare": Part("The papers' estimators compared", "bench/scenario.json", "scenario", compare_markdown, _SCENARIO),
    "exact": Part("The SDP against the exact limit", "bench/scenario.json", "scenario", exact_markdown, _SCENARIO),
    "exact-cost": Part(
        "What the exact limit costs under k-of-N health",
        "bench/exact.json",
        "exact",
        exact_cost_markdown,
        "netsetest bench --quick --only exact --json bench/exact.json --markdown bench/exact.md",
    ),
    "network": Part(
        "What the network exchange buys",
        "bench/network.json",
        "network",
        network_markdown,
        "netsetest bench --quick --only network --json bench/network.json --markdown bench/network.md",
    ),
    "plant": Part(
        "A car as the truth",
        "bench/plant.json",
        "plant",
        plant_markdown,
        "netsetest bench --quick --only plant --json bench/plant.json --markdown bench/plant.md",
    ),
    "network-summary": Part(
        "What the network exchange buys, in short",
        "bench/network.json",
        "network",
        network_summary_markdown,
        "netsetest bench --quick --only network --json bench/network.json --markdown bench/network.md",
        in_results=False,
    ),
    "plant-summary": Part(
        "A car as the truth, in short",
        "bench/plant.json",
        "plant",
        plant_summary_markdown,
        "netsetest bench --quick --only plant --json bench/plant.json --markdown bench/plant.md",
        in_results=False,
    ),
    "view": Part("Looking at a run: the live view's cost and lag, the report page in a browser", "bench/view.json", "view", view_markdown, _VIEW),
    "view-summary": Part("The live view and the report page against their targets", "bench/view.json", "view", view_summary_markdown, _VIEW, in_results=False),
    "flow": Part(
        "A collector that falls behind",
        "bench/flow.json",
        "flow",
        flow_markdown,
        "netsetest bench --only flow --json bench/flow.json --markdown bench/flow.md",
    ),
    "widths": Part("Published width over the exact limit, per coordinate", "bench/widths.json", "widths", widths_markdown, _WIDTHS),
    "widths-summary": Part("Published width over the exact limit, in short", "bench/widths.json", "widths", widths_summary_markdown, _WIDTHS, in_results=False),
    "widths-region": Part("What the region buys the set estimators", "bench/widths.json", "widths", region_markdown, _WIDTHS, in_results=False),
    "widths-sets": Part("What a node takes from its network", "bench/widths.json", "widths", sets_section, _WIDTHS, in_results=False),
    "performance": Part(
        "Performance",
        "bench/results.json",
        None,
        performance_markdown,
        "netsetest bench --quick --only performance --baseline BEFORE_ISSUE_45 --json bench/results.json --markdown bench/results.md",  # a checkout of 16f81b4
    ),
    "node": Part(
        "A node's per-message budget",
        "bench/node.json",
        "node",
        node_markdown,
        "netsetest bench --quick --only node --baseline MAIN --json bench/node.json --markdown bench/node.md",
    ),
    "scaleout": Part(
        "A run across two hosts",
        "bench/scaleout.json",
        "scaleout",
        scaleout_markdown,
        "netsetest bench --quick --only scaleout --json bench/scaleout.json --markdown bench/scaleout.md",
    ),
    "logs": Part("A recorded drive as the world", "bench/logs.json", "logs", logs_markdown, _LOGS),
    "logs-summary": Part("A recorded drive as the world, against its targets", "bench/logs.json", "logs", logs_summary_markdown, _LOGS, in_results=False),
    "campaign": Part(
        "Campaigns: every core, a cluster, resume",
        "bench/campaign.json",
        "campaign",
        campaign_markdown,
        "netsetest bench --quick --only campaign --json bench/campaign.json --markdown bench/campaign.md",
    ),
    "spread": Part(
        "How noisy the benchmark is",
        "bench/spread.json",
        None,
        spread_markdown,
        f"netsetest bench --spread {RUNS_DIR}/1.json {RUNS_DIR}/2.json {RUNS_DIR}/3.json --json bench/spread.json --markdown bench/spread.md",
    ),
}
SECTIONED = (
    "README.md",
    "docs/performance.md",
    "docs/exact.md",
    "docs/records.md",
    "docs/summary.md",
    "docs/estimator.md",
    "docs/network.md",
    "docs/your-log.md",
)  # files with generated sections between markers
RESULTS = "docs/results.md"  # written whole
RENDER_COMMAND = "netsetest bench --render-docs"


def begin(part: str) -> str:
    return f"<!-- the generated {part} section, by `{RENDER_COMMAND}` from {PARTS[part].source}: do not edit -->"


def end(part: str) -> str:
    return f"<!-- end of the generated {part} section -->"


class DocsError(ValueError):
    """A doc has a broken generated section, or a figures file is missing."""


def render(text: str, sections: dict[str, str], name: str = "the file") -> str:
    """``text`` with every generated section it has (of the parts in ``sections``) replaced."""
    for part, body in sections.items():
        b, e = begin(part), end(part)
        start, stop = text.find(b), text.find(e)
        if start < 0 and stop < 0:
            continue
        if start < 0 or stop < start or text.count(b) != 1 or text.count(e) != 1:
            raise DocsError(f"{name}: its generated {part} section is broken (markers missing, repeated or out of order)")
        text = text[: start + len(b)] + "\n" + body + text[stop:]
    return text


def results_document(docs: dict[str, dict], sections: dict[str, str]) -> str:
    """docs/results.md: every part under its heading, with the date and command of its measurement."""
    lines = [
        "# Results",
        "",
        f"Generated by `{RENDER_COMMAND}` from the committed figures in `bench/`: do not edit. Every table below",
        "is measured by the command under its heading, which writes its figures file; `" + RENDER_COMMAND + "`",
        "then rewrites this page and the generated sections of " + ", ".join(SECTIONED) + " from those",
        "files, without measuring. tests/unit/test_docs_generated.py fails when they differ.",
        "",
    ]
    for part, p in PARTS.items():
        if not p.in_results:
            continue
        meta = docs[p.source].get("meta", {})
        report = p.source.removesuffix(".json") + ".md"  # the measuring run's own report (its --markdown)
        lines += [
            f"## {p.title}",
            "",
            f"Measured {meta.get('date', '(date not recorded)')} by `{p.measure}` (every figure of that run: [{report}](../{report})).",
            "",
            sections[part].rstrip("\n"),
            "",
        ]
    return "\n".join(lines)


def render_docs(root: Path) -> dict[str, str]:
    """Every generated doc's text (path relative to ``root`` → text) from the figures under ``root``."""
    docs: dict[str, dict] = {}
    for p in PARTS.values():
        if p.source not in docs:
            path = root / p.source
            if not path.is_file():
                raise DocsError(f"{path}: no such figures file; measure it with `{p.measure}`")
            docs[p.source] = json.loads(path.read_text(encoding="utf-8"))
    sections = {}
    for part, p in PARTS.items():
        figures = docs[p.source] if p.key is None else docs[p.source].get(p.key)
        if figures is None:
            raise DocsError(f"{root / p.source}: no {p.key!r} figures in it; measure them with `{p.measure}`")
        try:
            sections[part] = p.draw(figures)
        except FiguresError as e:  # a file whose figures do not have their part's types
            raise DocsError(f"{root / p.source}: {e}") from None
    out = {name: render((root / name).read_text(encoding="utf-8"), sections, name) for name in SECTIONED}
    out[RESULTS] = results_document(docs, sections)
    return out


def write_docs(root: Path) -> list[str]:
    """Write every generated doc under ``root``; the names of those whose text changed."""
    changed = []
    for name, text in render_docs(root).items():
        path = root / name
        if not path.is_file() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
            changed.append(name)
    return changed


__all__ = ["PARTS", "RESULTS", "SECTIONED", "DocsError", "Part", "begin", "end", "render", "render_docs", "write_docs"]
