"""``watch`` (runtime/live.py LiveTable) and the live view (runtime/view.py LiveView) judge a node-step by the
collector's rule (roles/judge.py ``Judge.containment``: the published set, the ellipsoid ∩ the region ∩ the fault
range), not by E ≤ ρ, the ellipsoid alone: a state whose ellipsoid holds the truth while its region does not is a
miss in both, as in the collector's record (issue 41, item 1)."""

from __future__ import annotations

import msgspec

import numpy as np
import pytest

from message_helpers import make_state, truth
from netsetest.messages import NodeState, Truth
from netsetest.models.sensor import augmented
from netsetest.roles.judge import Judge
from netsetest.runtime.live import LiveTable

TRUTH = truth()  # step 3: x = (0.01, 0.2), node 1's fault 0.5
X = [0.01, 0.2]
F1 = TRUTH.faults[1]
FAR = [0.5, 0.5, 0.6, 0.5, 0.6, 0.6, 0.5, 0.6]  # a square of (β, r) counter-clockwise, away from the true x
AROUND = [0.0, 0.1, 0.1, 0.1, 0.1, 0.3, 0.0, 0.3]  # one holding it


def _state(region: list[float] | None, node: int = 1) -> NodeState:
    """Node ``node``'s state of the truth's step: an ellipsoid centred on the truth (E = 0 ≤ ρ) and a fault range
    around its true fault, cut by ``region``."""
    f = TRUTH.faults[node]
    return make_state(
        step=TRUTH.step,
        node=node,
        xhat=[*X, f],
        P=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
        rho=1.0,
        region=region,
        fault=[f - 0.1, f + 0.1],
        gamma=0.8,
        innov=0.0,
        status="ok",
    )


def _judged(msgs: list[NodeState | Truth]) -> LiveTable:
    table = LiveTable(judged=[])
    for m in msgs:
        table.update(m)
    return table


def test_the_states_ellipsoid_holds_the_truth_and_its_region_does_not() -> None:
    """The premise: the case E ≤ ρ alone would call contained, and the collector's judge calls a miss."""
    st = _state(FAR)
    xbar = augmented(np.asarray(X), F1)
    assert st.published.E(xbar) <= st.published.rho
    assert not st.published.polygon.contains(np.asarray(X))  # type: ignore[union-attr]  # a region is set
    assert not st.published.contains(xbar)  # the judge's rule (proven.ProvenSet.contains)
    assert _state(AROUND).published.contains(xbar)


@pytest.mark.parametrize("truth_first", [False, True])
def test_watch_counts_a_miss_where_only_the_region_misses(truth_first: bool) -> None:
    st = _state(FAR)
    table = _judged([TRUTH, st] if truth_first else [st, TRUTH])
    (row,) = table.sorted_rows()
    assert row.E_step == TRUTH.step and row.E is not None and row.E <= row.rho  # type: ignore[operator]  # set above
    assert row.contained is False and row.missed == 1 and row.judged == 1
    ((node, step, c),) = table.judged  # type: ignore[misc]  # judged=[]: a list
    assert (node, step) == (1, TRUTH.step)
    ref = Judge.containment(1, st, TRUTH)  # the collector's containment, not a copy of its rule
    assert (c.E, c.contained, c.continues_contained) == (ref.E, ref.contained, ref.continues_contained)
    assert np.array_equal(c.bounds, ref.bounds)  # type: ignore[arg-type]  # both set: a region is kept


def test_watch_counts_a_held_step_where_the_region_holds_the_truth() -> None:
    (row,) = _judged([_state(AROUND), TRUTH]).sorted_rows()
    assert row.contained is True and row.missed == 0 and row.judged == 1


def test_the_live_view_colours_and_counts_that_step_missed() -> None:
    rr = pytest.importorskip("rerun")
    from netsetest.runtime.view import APP_ID, COLOURS, LiveView

    rec = rr.RecordingStream(APP_ID)
    stream = rr.binary_stream(recording=rec)  # in memory: nothing leaves the test
    view = LiveView(rec, tau_s=0.1)
    for m in (_state(FAR, node=1), _state(AROUND, node=2), TRUTH):
        view.feed(m)
    stream.read()
    rec.disconnect()
    assert (view.coverage.judged, view.coverage.contained) == (2, 1)
    assert view.node_colour == {1: COLOURS["missed"], 2: COLOURS["contained"]}


def test_watch_and_the_view_call_a_box_across_the_sets_edge_undecided() -> None:
    """A recorded drive's truth is a box (the reference's accuracy): where it overlaps the published set without
    lying inside it, the collector says undecided (judge.Containment: neither held nor missed); watch and the view
    say so too, never "missed" and never "contained"."""
    rr = pytest.importorskip("rerun")
    from netsetest.runtime.view import APP_ID, COLOURS, LiveView

    edge = [0.005, 0.1, 0.1, 0.1, 0.1, 0.3, 0.005, 0.3]  # its left side at β = 0.005, inside the box β ∈ 0.01 ± 0.02
    box_truth = msgspec.structs.replace(TRUTH, x_acc=[0.02, 0.0], f_acc={1: 0.0, 2: 0.0})
    st = _state(edge)
    c = Judge.containment(1, st, box_truth)
    assert not c.contained and not c.missed  # the premise: the collector's judge leaves it undecided
    (row,) = _judged([st, box_truth]).sorted_rows()
    assert (row.judged, row.missed, row.undecided, row.contained, row.certain_miss) == (1, 0, 1, False, False)
    rec = rr.RecordingStream(APP_ID)
    stream = rr.binary_stream(recording=rec)
    view = LiveView(rec, tau_s=0.1)
    for m in (st, box_truth):
        view.feed(m)
    stream.read()
    rec.disconnect()
    assert (view.coverage.judged, view.coverage.contained, view.coverage.missed) == (1, 0, 0)
    assert view.node_colour == {1: COLOURS["undecided"]}
