"""``netsetest report --html`` and ``compare --html``: one self-contained page (extra ``view``: Bokeh).

The page holds its scripts (BokehJS, inline: only the bundles the page uses) and its data, so it opens
offline and travels as one file (a CI artifact, a mail).  Per record: the verdict and the summary tables
as the terminal prints them, the topology graph with each node coloured by its run's outcome, interactive
Figs. 5–8 like ``netsetest plot`` draws them (:mod:`netsetest.records.plots`), the exact-limit ratios when
``netsetest exact --json`` was run on the record, and the plant's e_k against its bound where a plant drove.

Every per-node figure has one legend entry per node: a click shows or hides that node (one node is shown when
the page opens, the one whose run most needs a look, :func:`focus_node`); the wheel zooms, hovering a line shows
its values.  Fig. 7 marks each node's first detection.  The verdict stands once, in its box; no text scrolls
sideways (long lines wrap).
What the page draws is decimated to :data:`MAX_POINTS` per line (every NaN gap kept, so a node that did
not report still breaks its line); the record itself and ``netsetest export`` keep every step.

Layering: this module knows records only; the verdict and tables (runtime/report.py) and the comparison
(analysis/compare.py) are handed in as text and arrays by the CLI.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from netsetest.extras import require
from netsetest.records.errors import RecordError
from netsetest.records.record import Record, mismatch

MAX_POINTS = 400  # points per drawn line: 1000 steps × 24 nodes stay well under 5 MB (module doc)
TRANSIENT_S = 1.0  # as Fig. 6/7 of `plot`: the initial y range leaves out the first second's wide bounds
FIG_WIDTH = 900  # px
GRAPH_EXTENT = 1.35  # the graph's nodes sit on the unit circle: room for their discs and the legend
EDGE_COLOUR = "#555555"
LEGEND_ROW_PX = 21  # a legend entry's height: a figure is tall enough to list every node
EXACT_FORMAT = "netsetest-exact"  # the `netsetest exact --json` document (analysis/exact.py, exact_document)

# a node's outcome over its run (the graph's colours); the first that applies wins
OUTCOME_COLOURS = {
    "missed the truth": "#d62728",  # a miss where every assumption held
    "lost": "#7f7f7f",  # stopped reporting
    "late": "#ff7f0e",  # deadline misses
    "fault detected": "#9467bd",
    "covered": "#2ca02c",  # contained on every step the guarantee applied to
}


@dataclass(frozen=True)
class RecordPage:
    """One record's part of the page: the record, its label, the verdict line and the summary tables as
    ``netsetest run`` prints them (empty for a partial record), and its exact document if any."""

    record: Record
    label: str
    verdict: str
    tables: str
    exact: dict | None = None


@dataclass(frozen=True)
class ComparePage:
    """``compare --html``: the table and, per node, every estimator's fault bounds against the truth (first run)."""

    title: str
    header: Sequence[str]
    rows: Sequence[Sequence[str]]
    tau_s: float
    truth_fault: dict[int, np.ndarray]  # node → (K,)
    bounds: dict[str, dict[int, np.ndarray]]  # estimator → node → (K, 3, 2)
    failed: Sequence[str]  # estimators that violated containment where the assumptions held
    notes: Sequence[str] = ()  # what the rows' assumptions mean for their widths (analysis/compare.py, assumptions_notes)


def load_exact(path: str | Path) -> dict:
    """A ``netsetest exact --json`` document, checked enough to draw its ratios (RecordError: one line)."""
    try:
        doc = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise RecordError(f"{path}: file not found") from None
    except (OSError, ValueError) as exc:
        raise RecordError(f"{path}: not a readable exact document ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != EXACT_FORMAT:
        raise RecordError(f"{path}: not an exact document (write one with `netsetest exact RECORD --json PATH`)")
    ratios = doc.get("ratios")
    if not isinstance(doc.get("record"), str) or not isinstance(ratios, dict) or not isinstance(ratios.get("nodes"), dict):
        raise RecordError(f"{path}: malformed exact document (record or ratios missing)")
    return doc


def attach_exact(records: Sequence[Record], docs: Sequence[tuple[str, dict]]) -> list[dict | None]:
    """Each record's exact document: the one whose ``record`` names the same file (RecordError when a
    document names none of them, or two name the same record)."""
    out: list[dict | None] = [None] * len(records)
    where = {Path(r.path).resolve(): n for n, r in enumerate(records)}
    for path, doc in docs:
        n = where.get(Path(doc["record"]).resolve())
        if n is None:
            raise RecordError(f"{path}: the exact limit of {doc['record']}, which is not among the records given")
        if out[n] is not None:
            raise RecordError(f"{path}: a second exact document for {records[n].path}")
        out[n] = doc
    return out


# ------------------------------------------------------------------------------------- helpers


def _decimate(x: np.ndarray, *ys: np.ndarray) -> list[np.ndarray]:
    """Every s-th point (s so that at most :data:`MAX_POINTS` remain), the last point and every NaN gap."""
    n = len(x)
    stride = max(1, math.ceil(n / MAX_POINTS))
    keep = np.arange(n) % stride == 0
    if n:
        keep[-1] = True
    for y in ys:
        keep |= np.isnan(y)
    return [np.asarray(a, dtype=float)[keep] for a in (x, *ys)]


def _gapped(steps: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A NaN row between published steps that are not consecutive: lines break where a node was silent."""
    breaks = np.flatnonzero(np.diff(steps) > 1) + 1
    return np.insert(steps.astype(float), breaks, steps[breaks - 1] + 0.5), np.insert(values.astype(float), breaks, np.nan, axis=0)


def _palette(n: int) -> list[str]:
    from bokeh.palettes import Category10, Category20

    colours = list(Category10[10] if n <= 10 else Category20[20])
    return [colours[k % len(colours)] for k in range(n)]


def _node_ids(rec: Record) -> list[int]:
    return sorted(set(rec.nodes) | set(rec.meta.node_ids))


def _figure(title: str, x_label: str, y_label: str, legend_rows: int, **kw: Any) -> Any:
    from bokeh.plotting import figure

    fig = figure(
        title=title,
        width=FIG_WIDTH,
        height=max(300, LEGEND_ROW_PX * legend_rows + 80),
        x_axis_label=x_label,
        y_axis_label=y_label,
        tools="pan,wheel_zoom,box_zoom,reset,save",
        active_scroll="wheel_zoom",
        **kw,
    )
    return fig


def _legend(fig: Any, items: list[tuple[str, list[Any]]], shown: Sequence[int] = (0,)) -> None:
    """One legend entry per node (click: show or hide); only the entries ``shown`` (their positions) are shown at
    first: the node the page opens on (:func:`focus_node`), and the truth where it is an entry of its own."""
    from bokeh.models.annotations.legends import Legend, LegendItem

    for n, (_, renderers) in enumerate(items):
        for r in renderers:
            r.visible = n in shown
    legend = Legend(items=[LegendItem(label=label, renderers=rs) for label, rs in items], click_policy="hide", label_text_font_size="8pt")
    fig.add_layout(legend, "right")


def _line(fig: Any, x: np.ndarray, y: np.ndarray, node: int, name: str | None = None, **kw: Any) -> Any:
    from bokeh.models import ColumnDataSource

    xd, yd = _decimate(x, y)
    src = ColumnDataSource({"x": xd.astype(np.float32), "y": yd.astype(np.float32), "node": np.full(len(xd), node, dtype=np.int32)})
    return fig.line("x", "y", source=src, name=name, **kw)


def _band(fig: Any, x: np.ndarray, lo: np.ndarray, hi: np.ndarray, **kw: Any) -> Any:
    xd, lod, hid = _decimate(x, lo, hi)
    return fig.varea(x=xd.astype(np.float32), y1=lod.astype(np.float32), y2=hid.astype(np.float32), **kw)


def _hover(fig: Any, renderers: list[Any], y_label: str, x_label: str = "t [s]") -> None:
    from bokeh.models import HoverTool

    fig.add_tools(HoverTool(renderers=renderers, tooltips=[("node", "@node"), (x_label, "@x{0.00}"), (y_label, "@y{0.0000}")], mode="mouse"))


def _y_range(rec: Record, ids: list[int], comp: int, truth: np.ndarray) -> tuple[float, float] | None:
    """Every true value and the bounds after :data:`TRANSIENT_S` (None: a run too short to leave any out)."""
    tau, vals = rec.meta.tau_s, [truth[np.isfinite(truth)]]
    for i in ids:
        tr = rec.nodes.get(i)
        if tr is None or len(tr.steps) == 0 or tr.steps[-1] * tau < 2 * TRANSIENT_S:
            return None
        late = tr.steps * tau >= TRANSIENT_S
        lo, hi = tr.bounds(comp)
        vals += [lo[late & np.isfinite(lo)], hi[late & np.isfinite(hi)]]
    v = np.concatenate(vals)
    if v.size == 0:
        return None
    a, b = float(v.min()), float(v.max())
    pad = 0.1 * max(b - a, 1e-9)
    return a - pad, b + pad


# ------------------------------------------------------------------------------------- figures


def _fig5(rec: Record, label: str) -> Any:
    ids, tau = _node_ids(rec), rec.meta.tau_s
    focus = ids.index(focus_node(rec))
    fig = _figure(f"Fig. 5: measurements with fault (solid) and without (dashed) ({label})", "t [s]", "ỹ [rad/s]", len(ids))
    t = np.array([e["step"] for e in rec.truth], dtype=float) * tau
    items, lines = [], []
    for i, colour in zip(ids, _palette(len(ids))):
        y = np.array([e.get("y", {}).get(i, np.nan) for e in rec.truth], dtype=float)
        y0 = np.array([e.get("y_nofault", {}).get(i, np.nan) for e in rec.truth], dtype=float)
        rs = [_line(fig, t, y, i, name=f"fig5-node-{i}", color=colour, line_width=1.4), _line(fig, t, y0, i, color=colour, line_dash="dashed")]
        items.append((f"sensor {i}", rs))
        lines += rs
    _hover(fig, lines, "ỹ [rad/s]")
    _legend(fig, items, (focus,))
    return fig


def _estimate_fig(rec: Record, label: str, comp: int, title: str, y_label: str, per_node_truth: bool) -> Any:
    """Figs. 6 (β, r) and 7 (f): per node its bounds (band) and estimate (dashed), against the truth; Fig. 7 marks
    the step at which each node's fault was first detected (a dotted vertical line, shown and hidden with the node)."""
    from bokeh.models import Range1d

    ids, tau = _node_ids(rec), rec.meta.tau_s
    fig = _figure(f"{title} ({label})", "t [s]", y_label, len(ids) + 1)
    t = np.array([e["step"] for e in rec.truth], dtype=float) * tau
    items: list[tuple[str, list[Any]]] = []
    hover: list[Any] = []
    truth_all = np.array([e["x"][comp] for e in rec.truth], dtype=float) if not per_node_truth else np.array([], dtype=float)
    for i, colour in zip(ids, _palette(len(ids))):
        rs: list[Any] = []
        tr = rec.nodes.get(i)
        if tr is not None and len(tr.steps):
            lo, hi = tr.bounds(comp)
            k, vals = _gapped(tr.steps, np.column_stack([lo, hi, tr.xhat[:, comp]]))
            rs.append(_band(fig, k * tau, vals[:, 0], vals[:, 1], color=colour, alpha=0.2))
            rs.append(_line(fig, k * tau, vals[:, 2], i, name=f"{'fig7' if per_node_truth else f'fig6-{comp}'}-node-{i}", color=colour, line_dash="dashed"))
            hover.append(rs[-1])
        entry = f"node {i}"
        if per_node_truth:
            f = np.array([e.get("faults", {}).get(i, np.nan) for e in rec.truth], dtype=float)
            rs.append(_line(fig, t, f, i, color="black", line_width=1.6))
            hover.append(rs[-1])
            truth_all = np.concatenate([truth_all, f])
            detected = first_detection(rec, i)
            if detected is not None:  # where the published fault interval first excluded 0 (docs/fdi.md)
                rs.append(fig.vspan(x=[detected * tau], line_color=colour, line_width=2, line_dash="dotted", name=f"detect-node-{i}"))
                entry += f" (detected at step {detected})"
        items.append((entry, rs))
    focus = ids.index(focus_node(rec))
    if not per_node_truth:
        truth = _line(fig, t, truth_all, -1, color="black", line_width=1.6)
        items.insert(0, ("true", [truth]))
        hover.append(truth)
    _hover(fig, hover, y_label)
    _legend(fig, items, (focus,) if per_node_truth else (0, focus + 1))  # the truth is an entry of its own in Fig. 6
    limits = _y_range(rec, ids, comp, truth_all)
    if limits is not None:
        fig.y_range = Range1d(start=limits[0], end=limits[1])
    return fig


def _fig8(pages: Sequence[RecordPage]) -> Any:
    ids = sorted(set().union(*(_node_ids(p.record) for p in pages)))
    focus = ids.index(focus_node(*(p.record for p in pages)))
    tops = [np.nanmax(tr.E / np.maximum(tr.rho, 1e-300)) for p in pages for tr in p.record.nodes.values() if len(tr.steps) and np.isfinite(tr.E).any()]
    log = bool(tops) and max(tops) > 10.0
    fig = _figure("Fig. 8: E = eᵀP⁻¹e (solid) and radius ρ (dotted); × a miss", "step k", "E [–]", len(ids), y_axis_type="log" if log else "linear")
    colours = _palette(len(pages))
    items, hover = [], []
    for i in ids:
        rs: list[Any] = []
        for p, colour in zip(pages, colours):
            tr = p.record.nodes.get(i)
            if tr is None or len(tr.steps) == 0:
                continue
            k, vals = _gapped(tr.steps, np.column_stack([tr.E, tr.rho]))
            rs.append(_line(fig, k, vals[:, 0], i, name=f"fig8-node-{i}" if not rs else None, color=colour, line_width=1.4))
            hover.append(rs[-1])
            rs.append(_line(fig, k, vals[:, 1], i, color=colour, line_dash="dotted"))
            miss = tr.missed & ~np.isnan(tr.E)  # proven misses only: an undecided step (a reference's box) is neither
            if miss.any():
                rs.append(fig.scatter(tr.steps[miss].astype(float), tr.E[miss], marker="x", size=9, color="red", line_width=2))
        items.append((f"node {i}" + ("" if len(pages) == 1 else f" ({', '.join(p.label for p in pages)})"), rs))
    _hover(fig, hover, "E", x_label="k")
    _legend(fig, items, (focus,))
    return fig


def node_outcome(rec: Record, node: int) -> str:
    """The node's run in one word (a key of :data:`OUTCOME_COLOURS`), from the record's summary."""
    if rec.summary is None:
        return "lost" if node not in rec.nodes else "covered"
    try:
        row = rec.summary.node(node)
    except KeyError:
        return "lost"
    if row.violations:
        return "missed the truth"
    if row.missing_from is not None:
        return "lost"
    if row.deadline_misses:
        return "late"
    if row.first_detection is not None:
        return "fault detected"
    return "covered"


def first_detection(rec: Record, node: int) -> int | None:
    """The first step at which the node's published fault interval excluded 0 (the summary's; a partial record's
    from its rows), None where there was none."""
    if rec.summary is not None:
        try:
            return rec.summary.node(node).first_detection
        except KeyError:
            return None
    tr = rec.nodes.get(node)
    detected = [int(k) for k, f in zip(tr.steps, tr.fdi) if f == "detected"] if tr is not None and tr.fdi is not None else []
    return detected[0] if detected else None


def _had_fault(rec: Record, node: int) -> bool:
    if rec.summary is None:
        return False
    try:
        return rec.summary.node(node).fault_onset is not None
    except KeyError:
        return False


def focus_node(*records: Record) -> int:
    """The node the page's figures open on: the first whose run most needs a look (OUTCOME_COLOURS' order: it
    missed the truth, was lost, was late, its fault was detected), then one whose sensor had a fault (an onset the
    summary names), over ``records`` in turn; else the first node."""
    rank = list(OUTCOME_COLOURS)
    best: tuple[int, int, int, int] | None = None
    for n, rec in enumerate(records):
        for i in _node_ids(rec):
            key = (rank.index(node_outcome(rec, i)), 0 if _had_fault(rec, i) else 1, n, i)
            best = key if best is None or key < best else best
    return best[3] if best is not None else 1


def _focus_note(rec: Record) -> str:
    """The line that says which node the figures open on, and why."""
    focus = focus_node(rec)
    outcome, detected = node_outcome(rec, focus), first_detection(rec, focus)
    why = (
        outcome
        if detected is None
        else f"fault detected at step {detected}"
        if outcome == "fault detected"
        else f"{outcome}; fault detected at step {detected}"
    )
    return (
        f'<p class="note" id="focus">The figures below open on node {focus} ({html.escape(why)}): the first node whose run most needs '
        "a look; click a legend entry to show another.</p>"
    )


def _graph(rec: Record, label: str) -> Any:
    """The topology: node j → node i for every in-neighbour weight a_ij, nodes coloured by their outcome."""
    from bokeh.models import ColumnDataSource, HoverTool, Range1d
    from bokeh.models.annotations.arrows import Arrow, NormalHead
    from bokeh.models.annotations.labels import LabelSet
    from bokeh.plotting import figure

    ids = _node_ids(rec)
    angle = {i: math.pi / 2 - 2 * math.pi * n / max(1, len(ids)) for n, i in enumerate(ids)}
    pos = {i: (math.cos(a), math.sin(a)) for i, a in angle.items()}
    fig = figure(
        title=f"Topology ({label}): j → i where node i uses node j's state",
        width=520,
        height=520,
        tools="pan,wheel_zoom,reset,save",
        x_range=Range1d(start=-GRAPH_EXTENT, end=GRAPH_EXTENT),
        y_range=Range1d(start=-GRAPH_EXTENT, end=GRAPH_EXTENT),
    )
    fig.axis.visible = False
    fig.grid.visible = False
    shrink = 0.12  # arrows stop short of the node discs
    edges: dict[str, list[float]] = {"x0": [], "y0": [], "x1": [], "y1": []}
    for b, row in rec.meta.in_weights.items():
        for a in row:
            if a == b or a not in pos or b not in pos:
                continue
            (x0, y0), (x1, y1) = pos[a], pos[b]
            d = math.hypot(x1 - x0, y1 - y0) or 1.0
            ux, uy = (x1 - x0) / d, (y1 - y0) / d
            for key, v in zip(edges, (x0 + shrink * ux, y0 + shrink * uy, x1 - shrink * ux, y1 - shrink * uy)):
                edges[key].append(v)
    head = NormalHead(size=9, fill_color=EDGE_COLOUR, line_color=EDGE_COLOUR)
    arrows = Arrow(end=head, source=ColumnDataSource(edges), x_start="x0", y_start="y0", x_end="x1", y_end="y1", line_color=EDGE_COLOUR)  # type: ignore[call-arg]  # Bokeh's stubs miss the line properties Arrow has
    fig.add_layout(arrows)
    outcome = [node_outcome(rec, i) for i in ids]
    src = ColumnDataSource(
        {
            "x": [pos[i][0] for i in ids],
            "y": [pos[i][1] for i in ids],
            "node": ids,
            "label": [str(i) for i in ids],
            "outcome": outcome,
            "colour": [OUTCOME_COLOURS[o] for o in outcome],
        }
    )
    nodes = fig.scatter("x", "y", source=src, size=34, fill_color="colour", line_color="black", name="graph-nodes", legend_field="outcome")
    fig.add_layout(LabelSet(x="x", y="y", text="label", source=src, text_align="center", text_baseline="middle", text_color="white", text_font_style="bold"))
    fig.add_tools(HoverTool(renderers=[nodes], tooltips=[("node", "@node"), ("outcome", "@outcome")]))
    fig.legend.location = "top_left"
    fig.legend.label_text_font_size = "8pt"
    return fig


def _mismatch_fig(rec: Record, label: str) -> Any | None:
    """The plant's e_k against its declared bound (None: the T-S model drove, e_k = 0)."""
    m = mismatch(rec)
    if m is None:
        return None
    from bokeh.models.annotations.geometry import Span

    t = m.steps * rec.meta.tau_s
    fig = _figure(f"Model mismatch e_k of {rec.meta.plant} in its declared bound's norm ({label}); ≤ 1 inside", "t [s]", "‖G⁻¹e_k‖  |  e", 4)
    items = []
    for comp, (name, colour) in enumerate((("e_β [rad]", "#9467bd"), ("e_r [rad/s]", "#8c564b"))):
        items.append((name, [_line(fig, t, m.e[:, comp], comp, color=colour)]))
    if m.size is not None:
        items.insert(0, ("‖G⁻¹e_k‖ (box: ∞-norm)", [_line(fig, t, m.size, -1, name="mismatch-size", color="black", line_width=1.6)]))
        fig.add_layout(Span(location=1.0, dimension="width", line_color="red", line_dash="dashed"))
    _hover(fig, [r for _, rs in items for r in rs], "value")
    _legend(fig, items)
    for _, rs in items:
        for r in rs:
            r.visible = True
    return fig


# ------------------------------------------------------------------------------------- HTML


# pre-wrap: a line longer than the page (a Zenoh run's verdict, a drops line) wraps instead of scrolling sideways
_STYLE = """body{font-family:system-ui,sans-serif;margin:1.5em;max-width:1200px;color:#222}
pre{background:#f6f6f6;padding:.6em;white-space:pre-wrap;overflow-wrap:anywhere;font-size:12px}
table{border-collapse:collapse;font-size:13px;margin:.5em 0}td,th{border:1px solid #ccc;padding:2px 8px;text-align:right}
th{background:#eee}.verdict{font-size:1.1em;font-weight:bold;padding:.4em .6em;border-left:6px solid #2ca02c;background:#f1f8f1}
.verdict.fail{border-color:#d62728;background:#fbeeee}.note{color:#555;font-size:.9em}"""


COORDINATES = ("β", "r", "f")  # the published set's intervals, in NodeState.cuts' order


def cuts_html(rec: Record) -> str:
    """Per node and coordinate, the cuts that narrowed the published interval (NodeState.cuts, as the node named them)
    and on how many of its steps; "own set" where none did (the solve's ellipsoid or the method's own set)."""
    rows = []
    for i in _node_ids(rec):
        tr, cells = rec.nodes[i], [str(i)]
        for comp in range(len(COORDINATES)):
            named = tr.interval_cuts(comp)
            if any(c is None for c in named):
                cells.append("not recorded")  # a record from before states carried their cuts
                continue
            counts: dict[str, int] = {}
            for cuts in named:
                for name in cuts or ("own set",):
                    counts[name] = counts.get(name, 0) + 1
            cells.append(", ".join(f"{name} {n}" for name, n in sorted(counts.items(), key=lambda kv: -kv[1])))
        rows.append(cells)
    return (
        '<h3>What narrowed each published interval</h3><p class="note">Per node, the cuts the node named for each '
        "coordinate (docs/estimator.md) and on how many of its steps; own set: the solve's ellipsoid or the method's set alone.</p>"
        + _table(["node", *COORDINATES], rows, "cuts")
    )


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], cls: str = "") -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows)
    return f'<table class="{cls}"><tr>{head}</tr>{body}</table>'


def _ratio(v: object) -> str:
    return f"{v:.3f}" if isinstance(v, (int, float)) else "–"


def _exact_html(doc: dict) -> str:
    """The ratios of ``netsetest exact --json``: published width / exact width per node and coordinate; with
    ``--network``, published width / each node's network limit beside it."""
    nodes = doc["ratios"]["nodes"]
    network = doc.get("network") if isinstance(doc.get("network"), dict) else None
    net_nodes = network.get("ratios", {}).get("nodes", {}) if network is not None and isinstance(network.get("ratios"), dict) else {}
    coords = sorted({c for per in nodes.values() if isinstance(per, dict) for c in per})
    header = ["node", *(f"{c}: width / exact" for c in coords), *(f"{c}: width / network" for c in coords if net_nodes)]
    header += [f"{c}: rms radius rel." for c in coords]
    rows = []
    for i in sorted(nodes, key=lambda s: int(s) if s.isdigit() else 0):
        per = nodes[i] if isinstance(nodes[i], dict) else {}
        net = net_nodes[i] if isinstance(net_nodes.get(i), dict) else {}
        cells = [i, *(_ratio(per.get(c, {}).get("width_ratio")) for c in coords)]
        cells += [_ratio(net.get(c, {}).get("width_ratio")) for c in coords if net_nodes]
        rows.append([*cells, *(_ratio(per.get(c, {}).get("rms_radius_rel")) for c in coords)])
    overall = doc["ratios"].get("overall_width_ratio")
    beside = " and over each node's network limit (what the topology carries to it, `exact --network`)" if net_nodes else ""
    return (
        f"<h3>Exact limit (fault bounds '{html.escape(str(doc.get('fault_bounds')))}', from step {html.escape(str(doc.get('from_step')))})</h3>"
        f'<p class="note">published width / exact width{beside}, mean over steps; 1.000 is the tightest any guaranteed estimator could publish '
        f"(docs/exact.md). Overall: {_ratio(overall)}</p>" + _table(header, rows, "exact")
    )


def _render(path: str | Path, title: str, parts: list[Any]) -> int:
    """Write ``parts`` (HTML strings and Bokeh models, in order) as one page with BokehJS inline; the size."""
    from bokeh.embed import file_html
    from bokeh.models import Model
    from bokeh.resources import INLINE

    models = [p for p in parts if isinstance(p, Model)]
    texts: dict[str, str] = {}
    body = []
    for n, p in enumerate(parts):
        if isinstance(p, Model):
            p.name = f"root{n}"
            body.append(f"{{{{ embed(roots.root{n}) }}}}")
        else:
            texts[f"part{n}"] = p
            body.append(f"{{{{ part{n} }}}}")
    # Bokeh's own page (file.html) with our blocks: the style, and the contents in order
    template = (
        f"{{% from macros import embed %}}{{% block postamble %}}<style>{_STYLE}</style>{{% endblock %}}{{% block contents %}}{''.join(body)}{{% endblock %}}"
    )
    page = file_html(models, INLINE, title=title, template=template, template_variables=texts)
    Path(path).write_text(page, encoding="utf-8")
    return len(page.encode())


def write_report(path: str | Path, pages: Sequence[RecordPage]) -> int:
    """The report page of one or more records (one Fig. 8 over all); returns its size in bytes."""
    require("bokeh", "the HTML report")
    title = "netsetest report: " + ", ".join(p.label for p in pages)
    parts: list[Any] = [f"<h1>{html.escape(title)}</h1>"]
    for p in pages:
        rec, fail = p.record, p.verdict.startswith("FAIL")
        caption = f"{rec.meta.name}, {p.label}"  # the figures' titles: plain text (Bokeh draws it), never HTML-escaped
        parts.append(
            f'<h2>{html.escape(p.label)}</h2><p class="note">{html.escape(Path(rec.path).name)}: topology {html.escape(str(rec.meta.name))}, '
            f"{len(_node_ids(rec))} nodes, τs = {rec.meta.tau_s:g} s, plant {html.escape(rec.meta.plant)}</p>"
        )
        if rec.partial:
            parts.append(f'<p class="verdict fail">partial record: the run did not finish (last complete step {rec.last_complete_step}); no verdict</p>')
        else:
            tables = p.tables.removesuffix(p.verdict).rstrip("\n")  # the verdict, the tables' last line, is in its box above
            parts.append(f'<p class="verdict{" fail" if fail else ""}" id="verdict">{html.escape(p.verdict)}</p><pre>{html.escape(tables)}</pre>')
        parts.append(_graph(rec, caption))
        parts.append(_focus_note(rec))
        parts.append(cuts_html(rec))
        if p.exact is not None:
            parts.append(_exact_html(p.exact))
        parts += [
            _fig5(rec, caption),
            _estimate_fig(rec, caption, 0, "Fig. 6: sideslip β, bounds (band), estimate (dashed) and truth (black)", "β [rad]", per_node_truth=False),
            _estimate_fig(rec, caption, 1, "Fig. 6: yaw rate r, bounds (band), estimate (dashed) and truth (black)", "r [rad/s]", per_node_truth=False),
            _estimate_fig(
                rec,
                caption,
                2,
                "Fig. 7: fault f_i, bounds (band), estimate (dashed), truth (black), first detection (dotted)",
                "f [rad/s]",
                per_node_truth=True,
            ),
        ]
        m = _mismatch_fig(rec, caption)
        if m is not None:
            parts.append(m)
    parts.append(_fig8(pages))
    parts.append(
        f'<p class="note">Lines show at most {MAX_POINTS} points each (the record and `netsetest export` keep every step). '
        "Click a legend entry to show or hide a node; the wheel zooms; hover for values.</p>"
    )
    return _render(path, title, parts)


def write_compare(path: str | Path, c: ComparePage) -> int:
    """The comparison page: the table and, per node, every estimator's fault bounds; returns its size."""
    require("bokeh", "the HTML comparison")
    parts: list[Any] = [f"<h1>{html.escape(c.title)}</h1>"]
    verdict = (
        ("containment violated where the assumptions held: " + ", ".join(c.failed)) if c.failed else "no estimator missed the truth where its assumptions held"
    )
    parts.append(f'<p class="verdict{" fail" if c.failed else ""}" id="verdict">{html.escape(verdict)}</p>')
    parts.append(_table(c.header, c.rows, "compare"))
    parts += [f'<p class="note assumptions">{html.escape(note)}</p>' for note in c.notes]
    names = list(c.bounds)
    colours = _palette(len(names))
    for i, truth in sorted(c.truth_fault.items()):
        fig = _figure(f"node {i}: every estimator's fault bounds and the true fault", "t [s]", f"f_{i} [rad/s]", len(names) + 1)
        t = np.arange(len(truth)) * c.tau_s
        lines = [_line(fig, t, truth, i, name=f"compare-node-{i}", color="black", line_width=2)]
        items = [("true f", [lines[0]])]
        for name, colour in zip(names, colours):
            b = c.bounds[name].get(i)
            if b is None:
                continue
            tt = np.arange(len(b)) * c.tau_s
            edges = [_line(fig, tt, b[:, 2, side], i, color=colour) for side in (0, 1)]
            items.append((name, [_band(fig, tt, b[:, 2, 0], b[:, 2, 1], color=colour, alpha=0.15), *edges]))
            lines += edges
        _hover(fig, lines, "f")
        _legend(fig, items)
        for _, rs in items[:2]:  # the truth and the first estimator; click the legend for the others
            for r in rs:
                r.visible = True
        span = float(np.ptp(truth[np.isfinite(truth)])) if np.isfinite(truth).any() else 0.0
        if span > 0:
            from bokeh.models import Range1d

            fig.y_range = Range1d(start=float(np.nanmin(truth)) - 2 * span, end=float(np.nanmax(truth)) + 2 * span)
        parts.append(fig)
    return _render(path, c.title, parts)


@dataclass(frozen=True)
class CampaignPage:
    """``campaign --report``: the summary table, distributions over the runs' nodes per estimator, detection
    delay against fault size, and the worst runs with the command that replays each (netsetest/campaign/report.py)."""

    title: str
    verdict: str
    failed: bool  # a run failed its verdict or errored
    header: Sequence[str]
    rows: Sequence[Sequence[str]]
    distributions: dict[str, dict[str, np.ndarray]]  # a figure's title (its quantity) → estimator → values over its runs' nodes
    delays: dict[str, tuple[np.ndarray, np.ndarray]]  # estimator → (fault size / declared bound, detection delay [steps]) per detected node
    worst_header: Sequence[str]
    worst_rows: Sequence[Sequence[str]]


HISTOGRAM_BINS = 30
DEGENERATE_SPAN, HISTOGRAM_PAD = 1e-6, 0.05  # a histogram of values closer than this (relative) spans ±HISTOGRAM_PAD around them


def _histograms(title: str, per_estimator: dict[str, np.ndarray]) -> Any:
    """One step line per estimator: the share of its values in each bin (bins shared by every estimator)."""
    values = np.concatenate([v[np.isfinite(v)] for v in per_estimator.values()] or [np.zeros(0)])
    lo, hi = (float(values.min()), float(values.max())) if len(values) else (0.0, 1.0)
    if hi - lo < DEGENERATE_SPAN * max(1.0, abs(hi)):  # every value alike (say every coverage 1): a readable axis around it
        lo, hi = lo - HISTOGRAM_PAD, hi + HISTOGRAM_PAD
    edges = np.linspace(lo, hi, HISTOGRAM_BINS + 1)
    fig = _figure(title, title.split(": ")[-1], "share of the estimator's nodes × runs", len(per_estimator))
    items = []
    for (name, v), colour in zip(per_estimator.items(), _palette(len(per_estimator))):
        v = v[np.isfinite(v)]
        counts = np.histogram(v, edges)[0] / max(len(v), 1)
        items.append((f"{name} ({len(v)})", [fig.step(edges, np.append(counts, 0.0), mode="after", color=colour, line_width=2)]))
    _legend(fig, items)
    for _, rs in items:  # every estimator shown at first: the distributions are compared side by side
        for r in rs:
            r.visible = True
    return fig


def _delay_fig(delays: dict[str, tuple[np.ndarray, np.ndarray]]) -> Any:
    from bokeh.models import ColumnDataSource, HoverTool

    fig = _figure("detection delay against the fault's size", "the fault's peak / its declared bound", "detection delay [steps]", len(delays))
    items, renderers = [], []
    for (name, (size, delay)), colour in zip(delays.items(), _palette(len(delays))):
        jitter = np.linspace(-0.004, 0.004, len(size)) if len(size) > 1 else np.zeros(len(size))  # equal sizes stay apart
        src = ColumnDataSource({"x": size + jitter, "y": delay, "size": size})
        r = fig.scatter("x", "y", source=src, color=colour, alpha=0.6, size=6)
        items.append((name, [r]))
        renderers.append(r)
    fig.add_tools(HoverTool(renderers=renderers, tooltips=[("size / bound", "@size{0.000}"), ("delay", "@y")]))
    _legend(fig, items)
    for _, rs in items:
        for r in rs:
            r.visible = True
    return fig


def write_campaign(path: str | Path, c: CampaignPage) -> int:
    """The campaign's page (:class:`CampaignPage`); returns its size in bytes."""
    require("bokeh", "the campaign report")
    parts: list[Any] = [f"<h1>{html.escape(c.title)}</h1>", f'<p class="verdict{" fail" if c.failed else ""}" id="verdict">{html.escape(c.verdict)}</p>']
    parts.append(_table(c.header, c.rows, "summary"))
    parts += [_histograms(title, per) for title, per in c.distributions.items() if per]
    if c.delays:
        parts.append(_delay_fig(c.delays))
    else:
        parts.append('<p class="note">no fault was detected in these runs: no detection delay to draw</p>')
    if c.worst_rows:
        parts.append("<h2>The worst runs, each with the command that replays it</h2>" + _table(c.worst_header, c.worst_rows, "worst"))
    return _render(path, c.title, parts)
