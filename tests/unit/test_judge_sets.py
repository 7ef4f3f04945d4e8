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
from netsetest.roles.judge import INHERITED, MISSED, Cone, CopyCheck, Judge, Origin, StepChecks, StepInputs


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
