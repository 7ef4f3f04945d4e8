"""Figures like the paper's Figs. 5-8 (Mousavinejad et al., Sec. VI) from one or more run records.

``fig5_measurements.png``  per node: the measurement ỹ_i with the fault (``y``) and the same measurement
                           without it (``y_nofault``), against time t = k·τs.
``fig6_states.png``        one row per node, β [rad] left and r [rad/s] right: the true state, the node's
                           estimate x̂, the bounds of its published set (shaded: the ellipsoid ∩ region ∩ fault
                           range, what the guarantee is about) and, for an SDP node, the bounds of the paper's
                           ellipsoid alone, x̂ ± √(ρ P_kk) (dotted; the region can only narrow it).  The y axes
                           leave out the first :data:`TRANSIENT_S` s of the bounds (the initial ellipsoid is far
                           wider than everything after it); every true value stays inside, and a note says so.
``fig7_faults.png``        per node: the true fault f_i, the estimate f̂_i, the published set's bounds (shaded)
                           and the paper's ellipsoid's, f̂_i ± √(ρ P_33) (dotted), as in Fig. 6.
``fig8_E.png``             per node: E_i,k = eᵀP⁻¹e against the step k with the radius ρ_i (dotted); one
                           curve per record, labelled ``case/signals``; red crosses mark misses (E > ρ) and
                           shaded bands the steps whose assumptions did not hold (colour of the record).
                           The E axis turns logarithmic when some E exceeds 10·ρ.

One record: the four files as named above.  Several records (e.g. an nsnim and a saim run): Figs. 5-7 are
drawn for every record with the file names prefixed by ``<case>_<signals>_`` (plus ``<n>_``, the record's
position counted from 0, if two records share case and signals), and one ``fig8_E.png`` overlays all records.

Per-node figures show at most :data:`MAX_PANELS` panels (Fig. 6: ``MAX_PANELS // 2`` node rows); the
title says so when nodes are left out.  A node's estimate, bounds and E are drawn only for the steps it
published: where it did not report (dead, killed, lost) the curves break and the steps are shaded grey
(never interpolated across).  E is NaN where the truth of a step is unknown and leaves a gap too.
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from netsetest.estimator.names import SDP
from netsetest.records.record import Record, mismatch

MAX_PANELS = 12
TRANSIENT_S = 1.0  # Fig. 6: y limits ignore the bounds of the first second (Sec. VI: they settle within ~1 s)
Y_PAD = 0.1  # fraction of the data range added above and below
SILENT_COLOUR, SILENT_ALPHA = "0.6", 0.25
LEGEND_TOP_IN = 0.4  # Fig. 6: inches from the top edge to its legend (below the title, above the panels)
_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:cyan")


def plot_records(records: list[Record], out_dir: str) -> list[str]:
    """Write the PNG files of Figs. 5-8 into ``out_dir`` (created if needed); return their paths."""
    if not records:
        raise ValueError("plot_records needs at least one record")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    labels = _labels(records)
    written: list[str] = []
    for n, rec in enumerate(records):
        prefix = "" if len(records) == 1 else labels[n].replace("/", "_").replace("#", "_") + "_"
        for name, draw in (("fig5_measurements", _fig5), ("fig6_states", _fig6), ("fig7_faults", _fig7)):
            written.append(_save(draw(rec, labels[n]), out / f"{prefix}{name}.png"))
        if any(tr.fdi is not None and any(tr.fdi) for tr in rec.nodes.values()):
            written.append(_save(_fig_fdi(rec, labels[n]), out / f"{prefix}fault_detection.png"))
        if mismatch(rec) is not None:  # a plant other than the T-S model generated the truth
            written.append(_save(_fig_mismatch(rec, labels[n]), out / f"{prefix}mismatch.png"))
    written.append(_save(_fig8(records, labels), out / "fig8_E.png"))
    return written


# ---------------------------------------------------------------------------------------- helpers


def _labels(records: list[Record]) -> list[str]:
    base = [f"{r.meta.case or '?'}/{r.meta.signals or '?'}" for r in records]
    dup = Counter(base)
    return [b if dup[b] == 1 else f"{b}#{n}" for n, b in enumerate(base)]


def _node_ids(rec: Record) -> list[int]:
    return sorted(set(rec.nodes) | set(rec.meta.node_ids))


def _grid(ids: list[int], cap: int) -> tuple[list[int], int, int, str]:
    shown = ids[:cap]
    ncols = 1 if len(shown) == 1 else 2 if len(shown) <= 6 else 3
    note = f" (first {cap} of {len(ids)} nodes)" if len(ids) > cap else ""
    return shown, max(1, math.ceil(len(shown) / ncols)), ncols, note


def _panels(ids: list[int], cap: int, title: str, xlabel: str) -> tuple[Figure, list[tuple[int, Axes]]]:
    """One panel per node (row-major); the lowest visible panel of each column gets the x label."""
    shown, nrows, ncols, note = _grid(ids, cap)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.5 * ncols, 2.6 * nrows), squeeze=False, sharex=True)
    flat = list(axes.flat)
    for ax in flat[len(shown) :]:
        ax.set_visible(False)
    for c in range(ncols):
        col = [ax for ax in axes[:, c] if ax.get_visible()]
        if col:
            col[-1].xaxis.set_tick_params(labelbottom=True)
            col[-1].set_xlabel(xlabel)
    fig.suptitle(title + note)
    return fig, list(zip(shown, flat))


def _times(rec: Record, steps: np.ndarray | None = None) -> np.ndarray:
    """t = k·τs for the given steps (default: the truth's steps)."""
    if steps is None:
        steps = np.array([e["step"] for e in rec.truth], dtype=float)
    return steps.astype(float) * rec.meta.tau_s


def _truth_series(rec: Record, field: str, node: int) -> tuple[np.ndarray, np.ndarray]:
    """Time and value of a per-node truth field (NaN where the entry lacks the node)."""
    return _times(rec), np.array([e.get(field, {}).get(node, np.nan) for e in rec.truth], dtype=float)


def _gapped(steps: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Steps (as float) and values with a NaN row between published steps that are not consecutive, so
    lines and bands break where the node did not report instead of being interpolated across."""
    breaks = np.flatnonzero(np.diff(steps) > 1) + 1
    gx = np.insert(steps.astype(float), breaks, steps[breaks - 1] + 0.5)
    return gx, np.insert(values.astype(float), breaks, np.nan, axis=0)


def _silent_spans(rec: Record, node: int) -> list[tuple[float, float]]:
    """Steps (±½) of the run for which ``node`` published nothing."""
    all_steps = np.array(sorted({int(e["step"]) for e in rec.truth}), dtype=int)
    tr = rec.nodes.get(node)
    published = set() if tr is None else {int(k) for k in tr.steps}
    return _spans(all_steps, np.array([k not in published for k in all_steps], dtype=bool))


def _shade_silent(ax: Axes, rec: Record, node: int, scale: float) -> bool:
    """Grey bands over the steps ``node`` did not report (x in steps × ``scale``); True if any."""
    spans = _silent_spans(rec, node)
    for a, b in spans:
        ax.axvspan(a * scale, b * scale, color=SILENT_COLOUR, alpha=SILENT_ALPHA, lw=0, label="not reported" if a == spans[0][0] else None)
    return bool(spans)


PUBLISHED_LABEL = "published set (ellipsoid ∩ region ∩ fault range)"  # Figs. 6-7's band: what the guarantee is about
ELLIPSOID_LABEL = "paper's ellipsoid x̂ ± √(ρP_kk)"  # the SDP's ellipsoid alone, as the paper draws it


def _is_sdp(rec: Record, node: int) -> bool:
    """Whether the node ran the SDP (a set estimator's ellipsoid is only the wire's summary of its set, not a paper's)."""
    return rec.meta.estimators.get(node, SDP) == SDP


def _estimate(ax: Axes, rec: Record, node: int, comp: int, truth: tuple[np.ndarray, np.ndarray]) -> None:
    ax.plot(*truth, color="k", lw=1.6, label="true")
    tau = rec.meta.tau_s
    _shade_silent(ax, rec, node, tau)
    tr = rec.nodes.get(node)
    if tr is None or len(tr.steps) == 0:
        ax.text(0.5, 0.5, "no ellipsoids published", transform=ax.transAxes, ha="center", color="r")
        return
    lo, hi = tr.bounds(comp)
    e_lo, e_hi = tr.ellipsoid_bounds(comp)
    k, vals = _gapped(tr.steps, np.column_stack([lo, hi, tr.xhat[:, comp], e_lo, e_hi]))
    t = k * tau
    ax.fill_between(t, vals[:, 0], vals[:, 1], color="tab:blue", alpha=0.2, lw=0, label=PUBLISHED_LABEL)
    if _is_sdp(rec, node):
        for side, label in ((3, ELLIPSOID_LABEL), (4, None)):
            ax.plot(t, vals[:, side], color="tab:blue", lw=0.9, ls=":", label=label)
    ax.plot(t, vals[:, 2], color="tab:blue", lw=1.2, ls="--", label="estimate")


def _settled_limits(rec: Record, ids: list[int], comp: int, truth: np.ndarray) -> tuple[float, float] | None:
    """y limits covering every true value and the bounds (the published set's and an SDP node's ellipsoid's) after
    :data:`TRANSIENT_S`; None if the run is too
    short to have a transient worth leaving out."""
    tau = rec.meta.tau_s
    vals = [truth[np.isfinite(truth)]]
    for i in ids:
        tr = rec.nodes.get(i)
        if tr is None or len(tr.steps) == 0:
            continue
        late = tr.steps * tau >= TRANSIENT_S
        if not late.any() or tr.steps[-1] * tau < 2 * TRANSIENT_S:
            return None
        lo, hi = tr.bounds(comp)
        vals += [lo[late], hi[late]]
        if _is_sdp(rec, i):  # the paper's ellipsoid is drawn too: in view beside the published set
            e_lo, e_hi = tr.ellipsoid_bounds(comp)
            vals += [e_lo[late], e_hi[late]]
    v = np.concatenate(vals)
    if v.size == 0:
        return None
    a, b = float(v.min()), float(v.max())
    pad = Y_PAD * max(b - a, 1e-12)
    return a - pad, b + pad


def _legend(target: Axes | Figure, fig: Figure, **kw: Any) -> None:
    """One legend on ``target`` (a panel, or the figure) with every label drawn anywhere in ``fig`` (e.g.
    "not reported" of one node)."""
    entries: dict[str, Any] = {}  # label → artist
    for a in fig.axes:
        for h, label in zip(*a.get_legend_handles_labels()):
            entries.setdefault(label, h)
    target.legend(list(entries.values()), list(entries), fontsize=7, **kw)


def _save(fig: Figure, path: Path) -> str:
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


# ---------------------------------------------------------------------------------------- figures


def _fig5(rec: Record, label: str) -> Figure:
    fig, panels = _panels(_node_ids(rec), MAX_PANELS, f"Fig. 5: measurements with and without fault ({label})", "t [s]")
    for i, ax in panels:
        ax.plot(*_truth_series(rec, "y", i), color="tab:red", lw=1.2, label="with fault")
        ax.plot(*_truth_series(rec, "y_nofault", i), color="tab:blue", lw=1.2, ls="--", label="without fault")
        r_max = rec.meta.r_max.get(i)
        if isinstance(r_max, (int, float)):  # SAIM: the saturation limits a reading cannot pass (times γ ≤ 1)
            for sign in (1, -1):
                ax.axhline(sign * r_max, color="0.4", lw=0.8, ls=":", label="saturation limit ±r_max")
        gamma = _truth_series(rec, "gamma", i)
        if len(gamma[1]) and np.nanmin(gamma[1]) < 1.0:  # incomplete measurements: γ on a second axis
            ax2 = ax.twinx()
            ax2.plot(*gamma, color="tab:green", lw=0.8, alpha=0.7, label="γ (right axis)")
            ax2.set_ylim(0, 1.05)
            ax2.set_ylabel("γ [–]", fontsize=8, color="tab:green")
        ax.set_title(f"sensor {i}", fontsize=9)
        ax.set_ylabel("ỹ [rad/s]")
    _legend(panels[0][1], fig)
    fig.tight_layout()
    return fig


def _fig6(rec: Record, label: str) -> Figure:
    ids = _node_ids(rec)
    cap = MAX_PANELS // 2
    shown = ids[:cap]
    note = f" (first {cap} of {len(ids)} nodes)" if len(ids) > cap else ""
    fig, axes = plt.subplots(len(shown), 2, figsize=(11, 1.9 * len(shown) + 1.2), squeeze=False, sharex=True)
    fig.suptitle(f"Fig. 6: state estimates and bounds ({label}){note}")
    t = _times(rec)
    clipped = False
    for comp, name in ((0, "β [rad]"), (1, "r [rad/s]")):
        truth = np.array([e["x"][comp] for e in rec.truth], dtype=float)
        limits = _settled_limits(rec, shown, comp, truth)
        for r, i in enumerate(shown):
            ax = axes[r, comp]
            _estimate(ax, rec, i, comp, (t, truth))
            ax.set_ylabel(f"node {i}\n{name}" if comp == 0 else name, fontsize=9)
            if limits is not None:
                ax.set_ylim(*limits)
                clipped = True
        axes[0, comp].set_title(name.split()[0], fontsize=10)
        axes[-1, comp].set_xlabel("t [s]")
    if clipped:
        fig.text(
            0.5,
            0.005,
            f"y axes show the bounds from t = {TRANSIENT_S:g} s on (the initial ellipsoid is much wider); every true value is inside the axes",
            ha="center",
            fontsize=8,
            color="0.3",
        )
    _legend(fig, fig, loc="upper center", ncol=4, bbox_to_anchor=(0.5, 1.0 - LEGEND_TOP_IN / fig.get_figheight()))
    fig.tight_layout(rect=(0, 0.02, 1, 1.0 - (LEGEND_TOP_IN + 0.05) / fig.get_figheight()))
    return fig


def _fig7(rec: Record, label: str) -> Figure:
    fig, panels = _panels(_node_ids(rec), MAX_PANELS, f"Fig. 7: fault estimates and bounds ({label})", "t [s]")
    clipped = False
    for i, ax in panels:
        truth = _truth_series(rec, "faults", i)
        _estimate(ax, rec, i, 2, truth)
        limits = _settled_limits(rec, [i], 2, truth[1])  # the same rule as Fig. 6: not the first second's bounds
        if limits is not None:
            ax.set_ylim(*limits)
            clipped = True
        ax.set_title(f"fault f{i}", fontsize=9)
        ax.set_ylabel("f [rad/s]")
    _legend(panels[0][1], fig)
    if clipped:
        fig.text(0.5, 0.005, f"y axes show the bounds from t = {TRANSIENT_S:g} s on; every true value is inside the axes", ha="center", fontsize=8, color="0.3")
    fig.tight_layout(rect=(0, 0.02, 1, 1))
    return fig


def _spans(steps: np.ndarray, flags: np.ndarray) -> list[tuple[float, float]]:
    """Contiguous runs of flagged steps as (start − ½, end + ½)."""
    out: list[tuple[float, float]] = []
    for k in steps[flags]:
        if out and k - 0.5 <= out[-1][1]:
            out[-1] = (out[-1][0], k + 0.5)
        else:
            out.append((k - 0.5, k + 0.5))
    return out


FDI_COLOURS = {"detected": "tab:red", "healthy": "tab:green"}


def _fig_fdi(rec: Record, label: str) -> Figure:
    """Per node: the true fault, the published fault interval, and the steps it proves a fault (red) or
    proves none (green) — docs/fdi.md."""
    fig, panels = _panels(_node_ids(rec), MAX_PANELS, f"Fault detection: detected where the fault interval excludes 0 ({label})", "t [s]")
    tau = rec.meta.tau_s
    for i, ax in panels:
        rows = rec.fault_rows(i) if i in rec.nodes else []
        if not rows:
            continue
        t = np.array([r["step"] for r in rows], dtype=float) * tau
        ax.fill_between(t, [r["fault_lower"] for r in rows], [r["fault_upper"] for r in rows], color="tab:blue", alpha=0.2, label="published fault interval")
        ax.plot(*_truth_series(rec, "faults", i), color="black", lw=1.0, label="true fault")
        ax.axhline(0.0, color="0.5", lw=0.6)
        for status, colour in FDI_COLOURS.items():
            for a, b in _spans(np.array([r["step"] for r in rows]), np.array([r["fdi"] == status for r in rows])):
                ax.axvspan(a * tau, b * tau, color=colour, alpha=0.15, lw=0, label=status)
        ax.set_title(f"sensor {i}", fontsize=9)
        ax.set_ylabel("f [rad/s]")
        lo = min(min(r["fault_lower"] for r in rows[len(rows) // 8 :]), -0.05)
        hi = max(max(r["fault_upper"] for r in rows[len(rows) // 8 :]), 0.05)
        ax.set_ylim(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo))  # the settled intervals, not the prior's
    _legend(panels[0][1], fig)
    fig.tight_layout()
    return fig


def _fig_mismatch(rec: Record, label: str) -> Figure:
    """e_k of the plant against the declared bound: each component with the bound's half-widths (the box
    itself, or the box around an ellipsoid), and the size of e_k in the bound's own norm (≤ 1 inside)."""
    m = mismatch(rec)
    assert m is not None  # called only where mismatch() found one (plot_records checks)
    t = m.steps * rec.meta.tau_s
    fig, axes = plt.subplots(3, 1, figsize=(8, 6.5), sharex=True)
    fig.suptitle(f"Model mismatch e_k of {rec.meta.plant} against the declared bound ({label})")
    for comp, (ax, name) in enumerate(zip(axes[:2], ("e_β [rad]", "e_r [rad/s]"))):
        ax.plot(t, m.e[:, comp], color="tab:purple", lw=1.0, label="e_k (plant − T-S model)")
        if m.radius is not None:
            for sign in (1, -1):
                ax.axhline(sign * m.radius[comp], color="0.3", lw=0.9, ls="--", label="declared bound" if sign > 0 else None)
        ax.set_ylabel(name)
    if m.size is not None:
        axes[2].plot(t, m.size, color="tab:purple", lw=1.0)
        axes[2].axhline(1.0, color="tab:red", lw=0.9, ls="--", label="bound (1)")
        axes[2].set_ylabel("‖G⁻¹e_k‖ (box: ∞-norm)")
    else:
        axes[2].text(0.5, 0.5, "no [model_uncertainty] declared: e_k = 0 is assumed", ha="center", transform=axes[2].transAxes)
    axes[2].set_xlabel("t [s]")
    _legend(axes[0], fig)
    fig.tight_layout()
    return fig


def _fig8(records: list[Record], labels: list[str]) -> Figure:
    ids = sorted(set().union(*(_node_ids(r) for r in records)))
    tau = records[0].meta.tau_s
    fig, panels = _panels(ids, MAX_PANELS, "Fig. 8: E_i = eᵀP⁻¹e and radius ρ_i (dimensionless)", f"step k (τs = {tau:g} s)")
    handles: dict[str, Any] = {}  # label → artist
    for i, ax in panels:
        top = 0.0
        for n, rec in enumerate(records):
            tr, col = rec.nodes.get(i), _COLOURS[n % len(_COLOURS)]
            if tr is None or len(tr.steps) == 0:
                continue
            k, vals = _gapped(tr.steps, np.column_stack([tr.E, tr.rho]))
            handles[labels[n]] = ax.plot(k, vals[:, 0], color=col, lw=1.2, marker=".", ms=3)[0]
            handles["ρ"] = ax.plot(k, vals[:, 1], color="k", lw=1.0, ls=":")[0]
            if _shade_silent(ax, rec, i, 1.0):
                handles["not reported"] = Patch(color=SILENT_COLOUR, alpha=SILENT_ALPHA)
            miss = tr.missed & ~np.isnan(tr.E)  # proven misses only: an undecided step (a reference's box) is neither
            if miss.any():
                handles["miss (E > ρ)"] = ax.plot(tr.steps[miss], tr.E[miss], "x", color="red", ms=7, mew=2)[0]
            for a, b in _spans(tr.steps, ~tr.assumptions_ok):
                ax.axvspan(a, b, color=col, alpha=0.15, lw=0)
                handles[f"assumption broken ({labels[n]})"] = Patch(color=col, alpha=0.15)
            finite = tr.E[np.isfinite(tr.E)]
            top = max(top, float(finite.max() / max(tr.rho.max(), 1e-300)) if finite.size else 0.0)
        if top > 10.0:
            ax.set_yscale("log")
        ax.set_title(f"node {i}", fontsize=9)
        ax.set_ylabel("E [–]")
    fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=4, fontsize=8)
    legend_in = 0.15 + 0.22 * math.ceil(len(handles) / 4)  # inches reserved below the panels
    fig.tight_layout(rect=(0, min(0.4, legend_in / fig.get_figheight()), 1, 1))
    return fig
