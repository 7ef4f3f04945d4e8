"""`netsetest exact --network`: each node's limit from the data the topology carries to it by each step
(docs/exact.md, *The network limit*), against a brute force written here from the definition alone: node j's
prior and measurements of steps s ≤ k − d(j→i) (and only those), every declared bound, every sequence of k-of-N
hypotheses; and against the central and the local limit it lies between."""

from __future__ import annotations

import dataclasses
import itertools
import math
from functools import cache

import clarabel
import numpy as np
import pytest
from scipy import sparse

from netsetest.analysis.exact import ExactBounds, _plans, _Program, _settings, exact_bounds, step_data
from netsetest.config.schema import HealthGroup, Scenario, load_topology
from netsetest.models.signals import PiecewiseLinearFault
from netsetest.records.record import Record, record_from_parts
from netsetest.runtime.inmemory import run_inmemory

AGREE = 1e-7  # both are Clarabel solves at 1e-10
CHAIN = {1: {1: 1.0}, 2: {1: 1.0, 2: 1.0}, 3: {2: 1.0, 3: 1.0}, 4: {3: 1.0, 4: 1.0}}  # 1 → 2 → 3 → 4, self-loops: node 1 hears nobody


def _chain(case: str, group: bool = False) -> Scenario:
    """Sensors 1, 2 and 3 of paper6 on the chain above, every reading to its out-neighbours only (bounded readings on);
    with ``group``, sensors 1 to 4, one k-of-N group of the four, at most one faulty, and sensor 1's fault at 0.15 from
    step 0, so that which sensor is healthy matters at every step."""
    sc = load_topology("paper6", case, 3)
    nodes = [dataclasses.replace(n, in_weights=CHAIN[n.id]) for n in sc.nodes if n.id in CHAIN and (group or n.id < 4)]
    if group:
        nodes[0] = dataclasses.replace(nodes[0], fault=PiecewiseLinearFault(((0.0, 0.15), (10.0, 0.15))))
    return dataclasses.replace(sc, nodes=nodes, reading_scope="neighbours", health_groups=(HealthGroup((1, 2, 3, 4), 1),) if group else ())


@cache
def _record(case: str, group: bool = False) -> tuple[Scenario, Record]:
    sc = _chain(case, group)
    res = run_inmemory(sc, "worst", "scheduled", 0)
    assert res.parts is not None
    return sc, record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary)


Rows = list[tuple[dict[int, float], float]]  # a·z (=, ≤) b


def _program(sc: Scenario, data: list, d: dict[int, int], d0: dict[int, int], k: int) -> tuple[int, Rows, Rows, list[Rows]]:
    """Horizon k's columns and rows for a viewer whose data delays are ``d`` (``d0``: step 0's, which no reading
    carries): z = [x_0..x_k, w_0..w_{k−1}, f_j,0..k of every node j]; the dynamics (equalities), the wind bound, node
    j's measurement of step s ≥ 1 only where s ≤ k − d_j, its measurement of step 0 and its prior only where
    0 ≤ k − d0_j (second-order cones), every declared fault bound (``used``: this chain's readings rest on all of them)."""
    ids, bounded = sc.ids, set(sc.fault_bounded("used"))
    x = lambda s, c: 2 * s + c  # noqa: E731  # the column of x_s's component c
    f = lambda n, s: 2 * (k + 1) + k + n * (k + 1) + s  # noqa: E731  # the column of f_n,s
    eq: Rows = []
    lin: Rows = []
    soc: list[Rows] = []
    for s in range(k):
        a, b, dw = sc.model.blend(sc.model.weights(data[s].vx))
        for row in range(2):
            eq.append(({x(s + 1, row): 1.0, 2 * (k + 1) + s: -dw[row, 0], x(s, 0): -a[row, 0], x(s, 1): -a[row, 1]}, b[row, 0] * data[s].u))
        lin += [({2 * (k + 1) + s: 1.0}, math.sqrt(sc.W)), ({2 * (k + 1) + s: -1.0}, math.sqrt(sc.W))]
    for n, node in enumerate(sc.nodes):
        known = [s for s in range(k + 1) if node.id in (d0 if s == 0 else d) and s <= k - (d0 if s == 0 else d)[node.id]]
        for s in known:
            lo, hi = node.sensor.measured_interval(data[s].y[node.id], data[s].gamma[node.id])
            r = {x(s, 0): node.sensor.C[0], x(s, 1): node.sensor.C[1], f(n, s): node.sensor.Ds}
            lin += [(r, hi)] if np.isfinite(hi) else []
            lin += [({c: -v for c, v in r.items()}, -lo)] if np.isfinite(lo) else []
        if 0 in known:
            li = np.linalg.inv(np.linalg.cholesky(node.P0))
            cols, centre = (x(0, 0), x(0, 1), f(n, 0)), li @ node.x0_hat
            soc.append([({}, math.sqrt(node.rho))] + [({c: -li[r_, m] for m, c in enumerate(cols)}, -centre[r_]) for r_ in range(3)])
        for s in range(k + 1) if node.id in bounded else ():
            if node.fault_size is not None:
                lin += [({f(n, s): 1.0}, node.fault_size), ({f(n, s): -1.0}, node.fault_size)]
            if node.fault_rate is not None and s > 0:
                lin += [({f(n, s): 1.0, f(n, s - 1): -1.0}, node.fault_rate), ({f(n, s): -1.0, f(n, s - 1): 1.0}, node.fault_rate)]
    return 2 * (k + 1) + k + len(ids) * (k + 1), eq, lin, soc


def _ends(nz: int, eq: Rows, lin: Rows, soc: list[Rows], cols: dict[str, int]) -> dict[str, list[float]]:
    """min and max of each column over the program (inf, −inf where it has no trajectory)."""
    rows = [*eq, *lin, *(r for blk in soc for r in blk)]
    A = sparse.lil_matrix((len(rows), nz))
    for r_, (terms, _) in enumerate(rows):
        for c, v in terms.items():
            A[r_, c] = v
    b = np.array([rhs for _, rhs in rows])
    cones = [clarabel.ZeroConeT(len(eq)), clarabel.NonnegativeConeT(len(lin))] + [clarabel.SecondOrderConeT(4)] * len(soc)
    out = {}
    for coord, col in cols.items():
        out[coord] = [np.inf, -np.inf]
        for side, sign in ((0, 1.0), (1, -1.0)):
            q = np.zeros(nz)
            q[col] = sign
            sol = clarabel.DefaultSolver(sparse.csc_matrix((nz, nz)), q, A.tocsc(), b, cones, _settings()).solve()
            if str(sol.status) in ("Solved", "AlmostSolved"):
                out[coord][side] = sol.x[col]
    return out


def _brute_force(sc: Scenario, rec: Record, viewer: int) -> dict[tuple[str, int], tuple[float, float]]:
    """(coordinate, step) → the viewer's exact interval, from the definition (:func:`_program`, d from the topology: a
    reading's hop costs nothing, a state's one step); under k-of-N, over every sequence of hypotheses (need sensors of
    each group with |f| ≤ τ at each step) the least and greatest value."""
    data, ids = step_data(rec), sc.ids
    hypotheses: list[tuple[int, ...]] = [()]
    for g in sc.health_groups:
        hypotheses = [h + c for h in hypotheses for c in itertools.combinations([ids.index(i) for i in g.nodes], g.need)]
    out: dict[tuple[str, int], tuple[float, float]] = {}
    for k in range(len(data)):
        nz, eq, lin, soc = _program(sc, data, sc.delays(viewer), sc.delays(viewer, first=True), k)
        cols = {"beta": 2 * k, "r": 2 * k + 1, "f": 2 * (k + 1) + k + ids.index(viewer) * (k + 1) + k}
        best = {c: [np.inf, -np.inf] for c in cols}
        for seq in itertools.product(hypotheses, repeat=k + 1):
            healthy = [({2 * (k + 1) + k + n * (k + 1) + s: sign}, sc.fault_tolerance) for s, h in enumerate(seq) for n in h for sign in (1.0, -1.0)]
            for c, (lo, hi) in _ends(nz, eq, lin + healthy, soc, cols).items():
                best[c] = [min(best[c][0], lo), max(best[c][1], hi)]
        out.update({(c, k): (lo, hi) for c, (lo, hi) in best.items()})
    return out


def _agrees(ex: ExactBounds, sc: Scenario, rec: Record, viewers: tuple[int, ...] | None = None) -> None:
    for viewer in viewers or sc.ids:
        for (coord, k), (lo, hi) in _brute_force(sc, rec, viewer).items():
            got = ex.interval(coord, viewer)[k]  # type: ignore[arg-type]  # coord is one of COORDINATES
            assert abs(got[0] - lo) <= AGREE * max(1.0, abs(lo)) and abs(got[1] - hi) <= AGREE * max(1.0, abs(hi)), (viewer, coord, k, got, (lo, hi))


@pytest.mark.parametrize("case", ["nsnim", "saim"])
def test_the_network_limit_is_the_definitions(case: str) -> None:
    """Node 1 hears nobody (its own limit), node 2 reads node 1's reading in the step, node 3 reads node 2's and has
    node 1's a step late (through node 2's state): three different programs, each the brute force's."""
    sc, rec = _record(case)
    assert sc.delays(1) == {1: 0} and sc.delays(2) == {1: 0, 2: 0} and sc.delays(3) == {1: 1, 2: 0, 3: 0}
    assert sc.delays(3, first=True) == {1: 2, 2: 1, 3: 0}  # step 0's data: no reading, the states alone
    ex = exact_bounds(sc, rec, network=True)
    assert ex.network and ex.label.startswith("used network") and not ex.infeasible_steps
    _agrees(ex, sc, rec)


@pytest.mark.parametrize("with_central", [False, True])
def test_the_network_limit_under_k_of_n_is_the_brute_force_over_every_hypothesis_sequence(with_central: bool) -> None:
    """One group of four on the chain, at most one faulty: a member's reading the viewer does not have yet is a sensor
    that may be healthy with any value, and the union of a step is built again as its readings come in (node 4 has
    node 1's two steps late: 4^(k+1) hypothesis sequences per horizon, brute-forced for nodes 3 and 4); the same with
    the central limit's boxes imported where a node holds their data (``central=``, as ``exact --network`` runs it)."""
    sc, rec = _record("nsnim", group=True)
    assert sc.delays(4) == {1: 2, 2: 1, 3: 0, 4: 0}
    ex = exact_bounds(sc, rec, network=True, central=exact_bounds(sc, rec) if with_central else None)
    assert ex.health is not None and ex.health.exact_ends == ex.health.ends and not ex.health.relaxed
    _agrees(ex, sc, rec, (3, 4))


def test_it_lies_between_the_central_and_the_local_limit() -> None:
    """More data for the central limit, less for a node alone: every interval of the network limit holds the central one
    and lies within the local one; where every reading reaches every node in its step, it is the central one once step
    0's data (which only the states carry) are in."""
    sc, rec = _record("saim")
    net, central = exact_bounds(sc, rec, network=True), exact_bounds(sc, rec)
    slack = 1e-7
    for i in sc.ids:
        local = exact_bounds(sc, rec, nodes=[i])
        for c in ("beta", "r", "f"):
            n, z, lo = net.interval(c, i), central.interval(c, i), local.interval(c, i)  # type: ignore[arg-type]  # c is one of COORDINATES
            assert np.all(n[:, 0] <= z[:, 0] + slack) and np.all(n[:, 1] >= z[:, 1] - slack)
            assert np.all(n[:, 0] >= lo[:, 0] - slack) and np.all(n[:, 1] <= lo[:, 1] + slack)
    everywhere = dataclasses.replace(sc, reading_scope="network")
    assert all(v == 0 for i in sc.ids for v in everywhere.delays(i).values())
    same = exact_bounds(everywhere, rec, network=True)
    whole = [i for i in sc.ids if len(everywhere.delays(i, first=True)) == len(sc.ids)]  # every node's step 0 reaches it (node 3)
    assert whole == [3]
    for i in whole:
        late = max(everywhere.delays(i, first=True).values())
        for c in ("beta", "r", "f"):
            assert np.allclose(same.interval(c, i)[late:], central.interval(c, i)[late:], rtol=0, atol=1e-8)  # type: ignore[arg-type]  # c is one of COORDINATES


def test_a_steps_union_is_built_again_as_its_readings_come_in() -> None:
    """Node 4 has node 1's reading of step 1 at horizon 3: at horizon 2 the union of step 1 counts sensor 1 as one that
    may be healthy with any value (its span the whole line), at horizon 3 its span is its reading's; from then on the
    union is kept as built."""
    sc, rec = _record("nsnim", group=True)
    prog = _Program(sc, step_data(rec), sc.fault_bounded("used"), viewer=4)
    (plan,) = _plans(prog, sc, True)
    wide = np.array([-10.0, 10.0])
    spans: dict[int, tuple] = {}
    for k in range(4):
        unions, complete = plan.unions_at(k, prog._f(3, k), (-np.inf, np.inf))
        assert complete
        spans[k] = next((u.spans for u in unions if u.step == 1), None)
        plan.learn(k, wide, wide, {4: wide})
        assert (1 in plan.pending) == (k == 1)  # complete from horizon 3 on: kept as built then
    assert spans[0] is None and spans[1] is not None and spans[1][0] == (-np.inf, np.inf)  # step 1's own horizon builds it
    assert spans[2] is not None and spans[2][0] == (-np.inf, np.inf) and all(np.isfinite(s).all() for s in spans[2][1:])
    kept = [u for u in plan.unions if u.step == 1]  # several pieces (a union), or one (rows of every later horizon)
    assert all(np.isfinite(u.spans[0]).all() for u in kept) and (kept or plan.cuts)


def _data_set(prog: _Program, k: int) -> set[tuple[int, int]]:
    """Every (node, step) whose datum the horizon-k program has, listed from its availability."""
    return {(j, s) for j in prog.ids for s in range(k + 1) if prog.available(j, s, k)}


def test_a_program_holds_another_where_it_has_every_datum_it_has() -> None:
    """_Program.holds, which decides what one node's limit may take from another's (the ledger), against the data sets
    listed one by one: on the chain (node 4 has node 1's data two steps late, step 0's three) every viewer against every
    other, every pair of horizons."""
    sc, rec = _record("nsnim", group=True)
    data, bounded = step_data(rec), sc.fault_bounded("used")
    progs = {i: _Program(sc, data, bounded, viewer=i) for i in sc.ids}
    held = 0
    for i, mine in progs.items():
        for m, other in progs.items():
            for h in range(len(data)):
                for k in range(len(data)):
                    expected = _data_set(other, h) <= _data_set(mine, k)
                    assert mine.holds(other, h, k) == expected, (i, m, h, k)
                    held += expected and i != m
    assert held > 0


def test_what_one_program_imports_from_another_leaves_every_limit_as_it_is(monkeypatch: pytest.MonkeyPatch) -> None:
    """The programs of a network limit run side by side and each takes the others' proven boxes of past states where it
    holds their data: every end the same as without any import (to the brute force's agreement), some imported."""
    import netsetest.analysis.exact as exact

    sc, rec = _record("nsnim", group=True)
    imported: list[int] = []
    proved = exact.KofNSearch._proved

    def spy(self: exact.KofNSearch, j: int, beta: np.ndarray, r: np.ndarray) -> None:
        imported.append(j)
        proved(self, j, beta, r)

    monkeypatch.setattr(exact.KofNSearch, "_proved", spy)
    with_imports = exact_bounds(sc, rec, network=True)
    own = len(imported)
    monkeypatch.setattr(exact._Program, "holds", lambda self, other, h, k: False)
    imported.clear()
    alone = exact_bounds(sc, rec, network=True)
    assert own > len(imported)  # the imports (each program's own horizons are the rest)
    for i in sc.ids:
        for c in ("beta", "r", "f"):
            a, b = with_imports.interval(c, i), alone.interval(c, i)  # type: ignore[arg-type]  # c is one of COORDINATES
            assert np.allclose(a, b, rtol=AGREE, atol=AGREE), (i, c)


def test_a_pending_steps_dead_piece_stays_dropped_as_its_union_is_built_again() -> None:
    """Node 4's union of step 1 is built again at horizon 2 (node 1's reading of step 1 is not in yet): a piece a search
    found without a trajectory (and any piece inside it) is left out of it from then on, the others kept; once every
    reading of step 1 is in, the union kept is built without it too."""
    sc, rec = _record("nsnim", group=True)
    prog = _Program(sc, step_data(rec), sc.fault_bounded("used"), viewer=4)
    (plan,) = _plans(prog, sc, True)
    wide = np.array([-10.0, 10.0])
    for k in range(2):
        plan.unions_at(k, prog._f(3, k), (-np.inf, np.inf))
        plan.learn(k, wide, wide, {4: wide})
    (before,) = [u for u in plan.unions_at(2, prog._f(3, 2), (-np.inf, np.inf))[0] if u.step == 1]
    assert 1 in plan.pending and before.pieces
    victim = before.pieces[0]
    plan.drop([(1, victim)])
    (after,) = [u for u in plan.unions_at(2, prog._f(3, 2), (-np.inf, np.inf))[0] if u.step == 1]
    assert victim not in after.pieces and set(after.pieces) == set(before.pieces) - {victim}
    plan.learn(2, wide, wide, {4: wide})  # step 1 complete from horizon 3 on
    assert 1 not in plan.pending and not any(victim == p for u in plan.unions if u.step == 1 for p in u.pieces)
