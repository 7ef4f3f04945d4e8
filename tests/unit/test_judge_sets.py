"""The judge's cone of a step cut by an in-neighbour's published set (issue 44, docs/coverage.md): such a step rests on
that whole set (its region, its fault range) holding the truth, not only on the ellipsoid a neighbour's innovation
uses; a step that names no set does not."""

from __future__ import annotations

import dataclasses

import numpy as np

from message_helpers import make_state, truth
from netsetest.config.schema import load_topology
from netsetest.messages import state_digest
from netsetest.models.sensor import augmented
from netsetest.proven import ProvenSet
from netsetest.roles.judge import INHERITED, MISSED, Cone, Containment, CopyCheck, Judge, Origin, StepChecks, StepInputs


def _two_nodes():
    """paper6's sensors 1 and 2, node 1 hearing node 2 (NSNIM)."""
    sc = load_topology("paper6", "nsnim", 5)
    nodes = [dataclasses.replace(n, in_weights={1: {1: 1.0, 2: 1.0}, 2: {2: 1.0}}[n.id]) for n in sc.nodes if n.id in (1, 2)]
    return dataclasses.replace(sc, nodes=nodes)


def test_a_step_cut_by_a_neighbours_set_rests_on_that_whole_set() -> None:
    sc = _two_nodes()
    judge = Judge(sc)
    ok = {1: True, 2: True}
    prev_tr, tr = truth(step=2, noise_ok=ok), truth(step=3, noise_ok=ok)
    xbar = augmented(np.asarray(prev_tr.x), prev_tr.faults[2])
    x, r = prev_tr.x
    off = [x + 0.1, r + 0.1, x + 0.2, r + 0.1, x + 0.2, r + 0.2]  # a region beside the truth; the ellipsoid around it
    cbar = sc.node(2).sensor.Cbar
    copy = make_state(
        step=2,
        node=2,
        xhat=xbar.tolist(),
        P=np.eye(3).ravel().tolist(),
        rho=1.0,
        region=off,
        gamma=prev_tr.gamma[2],
        innov=float(prev_tr.y[2] - cbar @ xbar),
        status="ok",
    )
    check = judge.copy_check(2, copy, prev_tr)
    assert check.as_neighbour is None and check.as_set == MISSED  # its innovation's facts held, its set missed
    prev = StepChecks({2: {state_digest(copy): check}, 1: {"0" * 32: CopyCheck(None, None)}}, {})
    inputs = [(2, state_digest(copy)), (1, "0" * 32)]
    base = dict(step=3, node=1, xhat=[0.0, 0.0, 0.0], P=np.eye(3).ravel().tolist(), rho=1.0, gamma=tr.gamma[1], innov=0.0, status="ok", used=[2], inputs=inputs)
    n1 = sc.node(1)
    for sets, cone in (([2], Cone(False, INHERITED, Origin(2, 2, MISSED))), ([], Cone(True))):
        st = make_state(**base, sets=sets)
        inp = StepInputs(3, tr, prev_tr, {1: st}, frozenset(), {1: [st]})
        assert judge.cone(n1, inp, StepChecks({}, {}), prev) == cone, sets


def test_a_step_judges_each_copy_once_and_as_each_check_alone_would() -> None:
    """Judge.step asks each copy's sets once (StepSets): the judged copy's containment and its copy check share them,
    and the set its node continues from is asked without being built.  The verdicts are those of Judge.containment and
    Judge.copy_check called alone, for copies whose published set or continued set misses the truth, with a point
    truth and with a reference's box."""
    sc = _two_nodes()
    judge = Judge(sc)
    ok = {1: True, 2: True}
    for tr in (truth(step=3, noise_ok=ok), truth(step=3, noise_ok=ok, x_acc=[0.01, 0.02], f_acc={1: 0.0, 2: 0.05})):
        xbar = augmented(np.asarray(tr.x), tr.faults[2])
        x, r = tr.x
        near = [x - 0.1, r - 0.1, x + 0.1, r - 0.1, x + 0.1, r + 0.1, x - 0.1, r + 0.1]  # a region around the truth
        beside = [x + 0.1, r + 0.1, x + 0.2, r + 0.1, x + 0.2, r + 0.2]  # one beside it
        cbar = sc.node(2).sensor.Cbar
        copies = []
        for region, centre in ((near, xbar), (beside, xbar), (near, xbar + 3.0)):
            own = ProvenSet(xhat=(centre + 0.001).tolist(), P=np.eye(3).ravel().tolist(), rho=1.0)
            copies.append(
                make_state(
                    step=3,
                    node=2,
                    xhat=xbar.tolist(),
                    P=(0.5 * np.eye(3)).ravel().tolist(),
                    rho=1.0,
                    region=region,
                    gamma=tr.gamma[2],
                    innov=float(tr.y[2] - cbar @ xbar),
                    status="ok",
                    continues=own,
                )
            )
        verdicts = [judge.step(StepInputs(3, tr, None, {2: c}, frozenset(), {2: copies}), StepChecks({}, {})) for c in copies]
        for c, v in zip(copies, verdicts):
            assert _same(v.nodes[2].containment, Judge.containment(2, c, tr))
            assert v.checks.copies[2] == {state_digest(d): judge.copy_check(2, d, tr) for d in copies}
        held = [(v.nodes[2].containment.contained, v.nodes[2].containment.continues_contained) for v in verdicts]  # type: ignore[union-attr]  # judged: a containment
        assert len(set(held)) > 1, held  # the copies differ in what they hold


def _same(a: Containment | None, b: Containment) -> bool:
    assert a is not None
    same_bounds = (a.bounds is None) == (b.bounds is None) and (a.bounds is None or np.array_equal(a.bounds, b.bounds))
    fields = ("E", "contained", "continues_contained", "missed", "continues_missed")
    return same_bounds and all(getattr(a, f) == getattr(b, f) for f in fields)
