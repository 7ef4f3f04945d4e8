"""Figures like the paper's Figs. 5-8 (Mousavinejad et al., Sec. VI) from one or more run records.

``fig5_measurements.png``  per node: the measurement ỹ_i with the fault (``y``) and the same measurement
                           without it (``y_nofault``), against time t = k·τs.
``fig6_states.png``        top row β, bottom row r, one column per node: the true state, the node's
                           estimate x̂ and its bounds x̂ ± √(ρ P_kk) (shaded).
``fig7_faults.png``        per node: the true fault f_i, the estimate f̂_i and its bounds f̂_i ± √(ρ P_33).
``fig8_E.png``             per node: E_i,k = eᵀP⁻¹e against the step k with the radius ρ_i (dotted); one
                           curve per record, labelled ``case/signals``; red crosses mark misses (E > ρ) and
                           shaded bands the steps whose assumptions did not hold (colour of the record).
                           The E axis turns logarithmic when some E exceeds 10·ρ.

One record: the four files as named above.  Several records (e.g. an nsnim and a saim run): Figs. 5-7 are
drawn for every record with the file names prefixed by ``<case>_<signals>_`` (plus ``<n>_``, the record's
position counted from 0, if two records share case and signals), and one ``fig8_E.png`` overlays all records.

Per-node figures show at most :data:`MAX_PANELS` panels (Fig. 6: ``MAX_PANELS // 2`` node columns); the
title says so when nodes are left out.  A node that stopped reporting is drawn for the steps it
published; E is NaN where the truth of a step is unknown and leaves a gap in the curve.
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from netsetest.records.record import Record  # noqa: E402

MAX_PANELS = 12
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
    written.append(_save(_fig8(records, labels), out / "fig8_E.png"))
    return written


# ---------------------------------------------------------------------------------------- helpers


def _labels(records: list[Record]) -> list[str]:
    base = [f"{r.meta.get('case', '?')}/{r.meta.get('signals', '?')}" for r in records]
    dup = Counter(base)
    return [b if dup[b] == 1 else f"{b}#{n}" for n, b in enumerate(base)]


def _node_ids(rec: Record) -> list[int]:
    return sorted(set(rec.nodes) | {int(i) for i in rec.meta.get("node_ids", [])})


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
    for ax in flat[len(shown):]:
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
    return steps.astype(float) * float(rec.meta.get("tau_s", 1.0))


def _truth_series(rec: Record, field: str, node: int) -> tuple[np.ndarray, np.ndarray]:
    """Time and value of a per-node truth field (NaN where the entry lacks the node)."""
    return _times(rec), np.array([e.get(field, {}).get(str(node), np.nan) for e in rec.truth], dtype=float)


def _estimate(ax: Axes, rec: Record, node: int, comp: int, truth: tuple[np.ndarray, np.ndarray]) -> None:
    ax.plot(*truth, color="k", lw=1.6, label="true")
    tr = rec.nodes.get(node)
    if tr is None or len(tr.steps) == 0:
        ax.text(0.5, 0.5, "no ellipsoids published", transform=ax.transAxes, ha="center", color="r")
        return
    t, (lo, hi) = _times(rec, tr.steps), tr.bounds(comp)
    ax.fill_between(t, lo, hi, color="tab:blue", alpha=0.2, lw=0, label="bounds")
    ax.plot(t, tr.xhat[:, comp], color="tab:blue", lw=1.2, ls="--", label="estimate")
    if tr.steps[-1] < max((e["step"] for e in rec.truth), default=-1):
        ax.axvline(t[-1], color="r", lw=0.8, ls=":", label="last report")


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
        ax.set_title(f"sensor {i}", fontsize=9)
        ax.set_ylabel("ỹ")
    panels[0][1].legend(fontsize=7)
    fig.tight_layout()
    return fig


def _fig6(rec: Record, label: str) -> Figure:
    ids = _node_ids(rec)
    cap = MAX_PANELS // 2
    shown = ids[:cap]
    note = f" (first {cap} of {len(ids)} nodes)" if len(ids) > cap else ""
    fig, axes = plt.subplots(2, len(shown), figsize=(3.2 * len(shown), 5.2), squeeze=False, sharex=True, sharey="row")
    fig.suptitle(f"Fig. 6: state estimates and bounds ({label}){note}")
    t = _times(rec)
    for c, i in enumerate(shown):
        for comp, name in ((0, "β [rad]"), (1, "r [rad/s]")):
            ax = axes[comp, c]
            _estimate(ax, rec, i, comp, (t, np.array([e["x"][comp] for e in rec.truth], dtype=float)))
            if c == 0:
                ax.set_ylabel(name)
        axes[0, c].set_title(f"node {i}", fontsize=9)
        axes[1, c].set_xlabel("t [s]")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def _fig7(rec: Record, label: str) -> Figure:
    fig, panels = _panels(_node_ids(rec), MAX_PANELS, f"Fig. 7: fault estimates and bounds ({label})", "t [s]")
    for i, ax in panels:
        _estimate(ax, rec, i, 2, _truth_series(rec, "faults", i))
        ax.set_title(f"fault f{i}", fontsize=9)
        ax.set_ylabel("f")
    panels[0][1].legend(fontsize=7)
    fig.tight_layout()
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


def _fig8(records: list[Record], labels: list[str]) -> Figure:
    ids = sorted(set().union(*(_node_ids(r) for r in records)))
    fig, panels = _panels(ids, MAX_PANELS, "Fig. 8: E_i = eᵀP⁻¹e and radius ρ_i", "step k")
    handles: dict[str, object] = {}
    for i, ax in panels:
        top = 0.0
        for n, rec in enumerate(records):
            tr, col = rec.nodes.get(i), _COLOURS[n % len(_COLOURS)]
            if tr is None or len(tr.steps) == 0:
                continue
            handles[labels[n]] = ax.plot(tr.steps, tr.E, color=col, lw=1.2, marker=".", ms=3)[0]
            handles["ρ"] = ax.plot(tr.steps, tr.rho, color="k", lw=1.0, ls=":")[0]
            miss = ~tr.contained & ~np.isnan(tr.E)
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
        ax.set_ylabel("E")
    fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=4, fontsize=8)
    legend_in = 0.15 + 0.22 * math.ceil(len(handles) / 4)  # inches reserved below the panels
    fig.tight_layout(rect=(0, min(0.4, legend_in / fig.get_figheight()), 1, 1))
    return fig
