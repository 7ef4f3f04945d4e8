"""What the figures draw: units on every axis, no line or band across steps a node did not report, and
Fig. 6's y axes not dominated by the initial ellipsoid (while every true value stays visible)."""

from __future__ import annotations

import copy

import matplotlib.pyplot as plt
import numpy as np
import pytest

import netsetest
from netsetest.records import plots
from netsetest.records.record import load_record, save_record

SILENT = range(20, 35)  # node 3 published nothing for these steps


@pytest.fixture(scope="module")
def gap_record(tmp_path_factory: pytest.TempPathFactory):
    d = tmp_path_factory.mktemp("plots")
    netsetest.simulate("paper6", steps=60).save(d / "full.json")
    full = load_record(d / "full.json")
    nodes = {**full.raw_nodes, "3": [e for e in full.raw_nodes["3"] if e["step"] not in SILENT]}
    save_record(d / "gap.json", full.meta, full.truth, nodes, full.summary)
    return load_record(d / "gap.json")


def _node3_axes(fig, rec) -> list:
    return [ax for ax in fig.axes if "node 3" in ax.get_ylabel() or ax.get_title() in ("node 3", "fault f3")]


def _assert_no_data_in_gap(ax, scale: float) -> None:
    lo, hi = (SILENT.start - 0.5) * scale, (SILENT.stop - 0.5) * scale
    for line in ax.get_lines():
        x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
        if line.get_color() in ("k", "black") or len(x) < 2:
            continue  # the truth exists at every step
        inside = (x > lo + 1e-9) & (x < hi - 1e-9) & np.isfinite(y)
        assert not inside.any(), (ax.get_title(), x[inside])
        assert np.isnan(y).any()  # the break
    for coll in ax.collections:  # the bounds band: no polygon vertex inside the silent steps
        for path in coll.get_paths():
            vx = path.vertices[:, 0]
            assert not ((vx > lo + 1e-9) & (vx < hi - 1e-9)).any(), ax.get_title()
    assert any(abs(p.get_x() - lo) < 1e-9 for p in ax.patches), "silent steps are shaded"


@pytest.mark.parametrize("fig_fn, scale", [(plots._fig6, 0.1), (plots._fig7, 0.1)])
def test_no_interpolation_across_a_silent_node(gap_record, fig_fn, scale) -> None:
    fig = fig_fn(gap_record, "x")
    axes = _node3_axes(fig, gap_record)
    assert axes
    for ax in axes:
        _assert_no_data_in_gap(ax, scale)
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend()] + list(fig.legends)
    assert len(legends) == 1 and "not reported" in [t.get_text() for t in legends[0].get_texts()]
    plt.close(fig)


def test_fig8_breaks_E_where_the_node_was_silent(gap_record) -> None:
    fig = plots._fig8([gap_record], ["x"])
    (ax,) = [a for a in fig.axes if a.get_title() == "node 3"]
    _assert_no_data_in_gap(ax, 1.0)
    plt.close(fig)


def test_units_on_every_axis(gap_record) -> None:
    for fn in (plots._fig5, plots._fig6, plots._fig7):
        fig = fn(gap_record, "x")
        for ax in fig.axes:
            if ax.get_ylabel():
                assert "[" in ax.get_ylabel() and "]" in ax.get_ylabel(), (fn.__name__, ax.get_ylabel())
            if ax.get_xlabel():
                assert ax.get_xlabel() == "t [s]"
        plt.close(fig)
    fig = plots._fig8([gap_record], ["x"])
    assert all("[–]" in ax.get_ylabel() for ax in fig.axes if ax.get_ylabel())
    assert any("τs = 0.1 s" in ax.get_xlabel() for ax in fig.axes)
    plt.close(fig)


def test_fig6_leaves_out_the_initial_transient_but_shows_every_true_value(gap_record) -> None:
    fig = plots._fig6(gap_record, "x")
    truth = np.array([e["x"] for e in gap_record.truth])
    rows = [ax for ax in fig.axes if ax.get_ylabel()]
    assert len(rows) == 12
    for ax in rows:
        comp = 0 if "β" in ax.get_ylabel() else 1
        y0, y1 = ax.get_ylim()
        assert y0 <= truth[:, comp].min() and truth[:, comp].max() <= y1
        i = int(ax.get_ylabel().split()[1]) if ax.get_ylabel().startswith("node") else None
        if i is not None:  # the initial bounds are outside the axes: the transient is left out
            lo, hi = gap_record.nodes[i].bounds(comp)
            assert lo[0] < y0 and hi[0] > y1
            late = gap_record.nodes[i].steps * 0.1 >= plots.TRANSIENT_S
            assert y0 <= lo[late].min() and hi[late].max() <= y1  # settled bounds fully visible
    plt.close(fig)


def test_short_run_keeps_full_limits() -> None:
    res = netsetest.simulate("paper6", steps=8)  # shorter than 2·TRANSIENT_S: nothing to leave out
    fig = plots._fig6(res.record, "x")
    ax = next(a for a in fig.axes if a.get_ylabel().startswith("node 1"))
    lo, hi = res.record.nodes[1].bounds(0)
    y0, y1 = ax.get_ylim()
    assert y0 <= lo.min() and hi.max() <= y1
    plt.close(fig)


@pytest.fixture(scope="module")
def saim_record(tmp_path_factory: pytest.TempPathFactory):
    d = tmp_path_factory.mktemp("saim")
    netsetest.simulate("paper6", steps=40, case="saim").save(d / "saim.json")
    return load_record(d / "saim.json")


def test_fig5_shows_the_saturation_limit_and_gamma(saim_record) -> None:
    """Fig. 5 drew neither the saturation limit nor γ (SAIM)."""
    fig = plots._fig5(saim_record, "saim")
    r_max = saim_record.meta.r_max[1]
    first = next(ax for ax in fig.axes if ax.get_title() == "sensor 1")
    levels = {round(float(ln.get_ydata()[0]), 12) for ln in first.get_lines() if ln.get_label().startswith("saturation")}
    assert levels == {round(r_max, 12), round(-r_max, 12)}
    gamma_axes = [ax for ax in fig.axes if ax.get_ylabel().startswith("γ")]
    assert gamma_axes and all(ax.get_ylim() == (0, 1.05) for ax in gamma_axes)
    plt.close(fig)


def test_fig7_leaves_out_the_initial_transient_like_fig6(saim_record) -> None:
    """Fig. 7 does not let the first second's (wide) bounds set the y range: widening them moves no limit.
    (Comparing the range with the whole run's was data-dependent: with the SAIM size cut, node 6's settled
    bounds padded by Y_PAD spanned more than its first second's.)"""
    tau = saim_record.meta.tau_s
    wide = copy.deepcopy(saim_record)
    for track in wide.nodes.values():
        early = track.steps * tau < plots.TRANSIENT_S
        track.P[early] *= 100.0
        if track.set_bounds is not None:  # the published set's bounds: ten times as wide around their middle
            b = track.set_bounds[early]
            mid = b.mean(axis=2, keepdims=True)
            track.set_bounds[early] = mid + 10.0 * (b - mid)
    fig, fig_wide = plots._fig7(saim_record, "saim"), plots._fig7(wide, "saim")
    for i, track in saim_record.nodes.items():
        ax, ax_wide = (next(a for a in f.axes if a.get_title() == f"fault f{i}") for f in (fig, fig_wide))
        lo, hi = track.bounds(2)
        y0, y1 = ax.get_ylim()
        late = track.steps * tau >= plots.TRANSIENT_S
        assert y0 <= lo[late].min() and hi[late].max() <= y1
        w_lo, w_hi = wide.nodes[i].bounds(2)
        assert w_lo.min() < y0 and y1 < w_hi.max()  # the widened first second reaches beyond the axis
        assert ax_wide.get_ylim() == (y0, y1), f"node {i}: the initial bounds still set the range"
    plt.close(fig)
    plt.close(fig_wide)


@pytest.mark.parametrize(("fig_fn", "comps"), [(plots._fig6, (0, 1)), (plots._fig7, (2,))])
def test_figs_6_and_7_draw_the_published_set_and_the_papers_ellipsoid_labelled(gap_record, fig_fn, comps) -> None:
    """Issue 41 item 16: the figures drew the region-cut set while their docstring said x̂ ± √(ρP_kk).  Each SDP node's
    panel now draws both, labelled: the published set's bounds (the band: Record.bounds, what the guarantee is about)
    and the paper's ellipsoid's (dotted lines: Record.ellipsoid_bounds), and the region narrows the first somewhere."""
    fig = fig_fn(gap_record, "x")
    legend = next(iter([ax.get_legend() for ax in fig.axes if ax.get_legend()] + list(fig.legends)))
    labels = [t.get_text() for t in legend.get_texts()]
    assert plots.PUBLISHED_LABEL in labels and plots.ELLIPSOID_LABEL in labels
    narrower = False
    for i in (1, 3):  # node 3: with the steps it did not report
        tr = gap_record.nodes[i]
        # Fig. 6: node i's row, β then r (row-major); Fig. 7: its panel
        axes = fig.axes[2 * (i - 1) : 2 * i] if len(comps) == 2 else [ax for ax in fig.axes if ax.get_title() == f"fault f{i}"]
        assert len(axes) == len(comps) and (len(comps) == 1 or axes[0].get_ylabel().startswith(f"node {i}"))
        for ax, comp in zip(axes, comps):
            dotted = [ln for ln in ax.get_lines() if ln.get_linestyle() == ":"]
            assert len(dotted) == 2 and dotted[0].get_label() == plots.ELLIPSOID_LABEL
            t = tr.steps * gap_record.meta.tau_s
            for line, want in zip(dotted, tr.ellipsoid_bounds(comp)):
                x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
                drawn = dict(zip(np.round(x[np.isfinite(y)], 9), y[np.isfinite(y)]))
                np.testing.assert_allclose([drawn[round(v, 9)] for v in t], want, rtol=1e-12, atol=0)
            (band,) = [c for c in ax.collections if c.get_label() == plots.PUBLISHED_LABEL]
            lo, hi = tr.bounds(comp)
            verts = np.concatenate([p.vertices for p in band.get_paths()])
            assert np.isin(np.round(lo, 12), np.round(verts[:, 1], 12)).all() and np.isin(np.round(hi, 12), np.round(verts[:, 1], 12)).all()
            e_lo, e_hi = tr.ellipsoid_bounds(comp)
            assert (lo >= e_lo - 1e-12).all() and (hi <= e_hi + 1e-12).all()  # the region only narrows the ellipsoid
            narrower |= bool(((lo > e_lo + 1e-9) | (hi < e_hi - 1e-9)).any())
    assert narrower, "the two sets coincide everywhere: this record shows no difference"
    plt.close(fig)
