"""The fast path (direct Clarabel assembly, netsetest/estimator/conic/) against the LMI it replaces.

- The assembly reproduces the LMI of docs/design.md §2 entry by entry (up to its documented congruence
  scaling) at random points, and the second-order cones carry the Schur terms they stand for.
- Its reductions (one slot for the innovation noise, cones for the uncoupled groups, the LMI split
  into clique cones) leave the optimum unchanged: the clique matrices add up to the LMI, and the
  reduced and the unreduced conic problems certify the same trace.
- On the paper scenario, NSNIM and SAIM, the fast path and the cvxpy path (the reduced LMI written
  in cvxpy, the previous default) both contain the truth at every node and step where the
  assumptions hold, without fallbacks, and give the same fault-bound widths:

  * NSNIM: |w_fast / w_cvxpy − 1| ≤ 1e-3 per node-step.  Both solve the same convex program to a
    1e-8 duality gap, so their traces agree to ~1e-6 (checked on the same data below); the width
    √(ρ P₃₃) is one entry of P along a weakly curved direction of trace(P) and agrees to ~2e-4
    (measured), so 1e-3 leaves a factor 5.
  * SAIM: −2e-2 ≤ w_fast / w_cvxpy − 1 ≤ 1e-3.  The upper bound is the same argument.  The lower one
    is the cvxpy path's own error: its Clarabel stops up to ~0.9 % above the optimum of the SAIM
    problems (badly scaled φ slots); the same-data test shows that the fast path's trace is never
    above the cvxpy path's, i.e. the differences are the reference's.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from netsetest.config.schema import load_topology
from netsetest.estimator import sdp
from netsetest.estimator.certificate import FactStack, certify
from netsetest.estimator.conic.closed_form import ClosedFormSolver
from netsetest.estimator.conic.reduction import Reduction
from netsetest.estimator.conic.solver import CHORDAL_FROM, ConicSolver
from netsetest.runtime.inmemory import run_inmemory

ROOT = Path(__file__).resolve().parents[2]
PAPER6 = ROOT / "topologies" / "paper6.toml"


def _estimator(sc, i, variant="scheduled", backend="clarabel"):
    return sdp.LocalEstimator.for_node(sc, i, variant, backend=backend)


def _data(est, args):
    """The step data of a captured step (prev, inp) as the node builds it (own reading interval, sectors)."""
    prev, inp = args
    return est.context(prev, inp).data


def _sector_data(est, args):
    """The same step with the own sensor's sector fact instead of its reading interval (as for an
    assumed sector): the φ⁺ slot and the clique decomposition."""
    prev, inp = args
    return est.step_data(prev, inp, est.own_sector(prev, inp))


def _capture(sc, variant="scheduled"):
    """Run in memory with the fast path; return the result and every node-step's estimator inputs."""
    cases = []
    res = run_inmemory(sc, "paper", variant, 0, observer=lambda est, prev, inp, r, ms: cases.append((est.node_id, (prev, inp))))
    return res, cases


@pytest.fixture(scope="module")
def saim_steps():
    return _capture(load_topology(PAPER6, "saim", 12))[1]


@pytest.fixture(scope="module")
def nsnim_steps():
    return _capture(load_topology(PAPER6, "nsnim", 12))[1]


def _smat(v: np.ndarray, n: int) -> np.ndarray:
    """Inverse of Clarabel's svec: upper triangle column-wise, off-diagonals × √2."""
    m = np.zeros((n, n))
    k = 0
    for j in range(n):
        for i in range(j + 1):
            m[i, j] = m[j, i] = v[k] / (1.0 if i == j else np.sqrt(2.0))
            k += 1
    return m


@pytest.mark.parametrize("case,variant", [("saim", "scheduled"), ("saim", "per-rule"), ("nsnim", "per-rule")])
def test_conic_assembly_reproduces_the_lmi(case, variant, saim_steps, nsnim_steps):
    """b − A x = svec(D M(P, L, τ) D) at random points, M the LMI of docs/design.md §2 (negated)."""
    sc = load_topology(PAPER6, case, 12)
    steps = saim_steps if case == "saim" else nsnim_steps
    rng = np.random.default_rng(7)
    for node, args in steps[-12:]:
        est = _estimator(sc, node, variant)
        data = _data(est, args)
        rho = args[0].rho
        solver = ConicSolver(Reduction(data.lay, est.n_lmi, aggregate=False, cones=False))
        prob, inv = solver.apply(data, rho)
        tpl = inv.tpl
        A = prob.A.toarray()
        x = rng.normal(size=A.shape[1])
        s = prob.b - A @ x
        point = solver.unpack(x, inv)  # P = S P̃ Sᵀ, L = S L̃, τ = τ̂/κ
        P, Ls = point.P, point.L
        taus = [x[tpl.iT[r]] / inv.values.kappa for r in range(est.n_lmi)]  # unclipped, to test every entry
        Sinv = np.linalg.inv(inv.values.S)
        D = np.diag(np.r_[np.ones(3), inv.values.sc])
        D[:3, :3] = Sinv
        idx = [0, 1, 2] + [3 + k for k in solver.red.lmi_slots]
        d = data.lay.dim
        assert solver.red.lmi_slots == list(range(d))  # nothing left out: this is the whole LMI
        e11 = np.zeros((d, d))
        e11[0, 0] = 1.0
        for r in range(est.n_lmi):
            pi = data.pi0[r] - Ls[r] @ data.ell[None, :]
            N = rho * e11 - np.tensordot(taus[r], np.asarray(data.facts), axes=1)
            M = np.block([[P, pi], [pi.T, N]])[np.ix_(idx, idx)]
            n = tpl.lmi_n
            got = _smat(s[tpl.lmi_rows[r] : tpl.lmi_rows[r] + n * (n + 1) // 2], n)
            np.testing.assert_allclose(got, D @ M @ D.T, rtol=1e-10, atol=1e-10)


def test_second_order_cones_carry_the_schur_terms(saim_steps, nsnim_steps):
    """Scheduled: each cone's slack is (t + τ, t − τ, 2√β Π_k(L)) at random points."""
    for case, steps in (("nsnim", nsnim_steps), ("saim", saim_steps)):
        sc = load_topology(PAPER6, case, 12)
        rng = np.random.default_rng(3)
        for node, args in steps[-6:]:
            est = _estimator(sc, node)
            data = _data(est, args)
            solver = ConicSolver(Reduction(data.lay, 1))  # the node's own cones, Clarabel's problem also where NSNIM has a closed form
            prob, inv = solver.apply(data, args[0].rho)
            tpl = inv.tpl
            x = rng.normal(size=tpl.nv)
            s = prob.b - prob.A.toarray() @ x
            L = inv.values.S @ x[tpl.iL[0]]
            pi = data.pi0[0] - np.outer(L, data.ell)
            row, socs = 0, []  # the rows are laid out cone by cone, in the order of the cone list
            for cone in tpl.cones:
                name = str(cone)
                size = int(name[name.index("(") + 1 : name.index(")")])
                rows = size * (size + 1) // 2 if "PSD" in name else size
                if "SecondOrder" in name:
                    socs.append(s[row : row + rows])
                row += rows
            assert row == len(s) and len(socs) >= len(tpl.groups) > 0
            for g, v in zip(tpl.groups, socs):
                t, tau = x[tpl.iTt[tpl.groups.index(g)]], x[tpl.iT[0][g.fact]]
                np.testing.assert_allclose(v[:2], [t + tau, t - tau], atol=1e-12)
                cols = pi[:, list(g.slots)] if g.slots else -inv.values.B * L[:, None]
                beta = g.bound if g.slots else 1.0
                np.testing.assert_allclose(v[2:], (2.0 * np.sqrt(beta) * cols.T).ravel(), rtol=1e-10, atol=1e-12)


def test_clique_decomposition_sums_to_the_lmi(saim_steps):
    """SAIM, scheduled: the clique cones (plus their split variables) add up to the one LMI."""
    sc = load_topology(PAPER6, "saim", 12)
    rng = np.random.default_rng(5)
    checked = 0
    for node, args in saim_steps[::-1]:
        est = _estimator(sc, node)
        data = _sector_data(est, args)
        if data.lay.phi_new is None or checked == 6:
            continue  # decomposed only where the own sensor has a φ slot
        checked += 1
        dec, one = ConicSolver(Reduction(data.lay, 1)), ConicSolver(Reduction(data.lay, 1, decompose=False))
        cliques = dec.red.cliques
        assert cliques is not None and len(cliques) >= 2
        (pd, invd), (po, invo) = dec.apply(data, args[0].rho), one.apply(data, args[0].rho)
        td, to = invd.tpl, invo.tpl
        assert td.decomposed and not to.decomposed and td.nv > to.nv  # split variables come last
        x = rng.normal(size=td.nv)
        sd = pd.b - pd.A.toarray() @ x
        so = po.b - po.A.toarray() @ x[: to.nv]
        np.testing.assert_allclose(sd[: td.lmi_rows[0]], so[: to.lmi_rows[0]], rtol=1e-12, atol=1e-12)
        n = to.lmi_n
        total = np.zeros((n, n))
        for C, r0 in zip(cliques, td.lmi_rows):
            k = len(C)
            total[np.ix_(C, C)] += _smat(sd[r0 : r0 + k * (k + 1) // 2], k)
        np.testing.assert_allclose(total, _smat(so[to.lmi_rows[0] :], n), rtol=1e-10, atol=1e-10)
    assert checked == 6


@pytest.mark.parametrize("case", ["nsnim", "saim"])
def test_reductions_leave_the_optimum_unchanged(case, saim_steps, nsnim_steps):
    """Reduced (ξ + cones) and unreduced conic problems certify the same trace on paper data."""
    sc = load_topology(PAPER6, case, 12)
    steps = saim_steps if case == "saim" else nsnim_steps
    for node, args in steps[::5]:
        est = _estimator(sc, node)
        data = _data(est, args)
        rho = args[0].rho
        traces = []
        for solver in (ConicSolver(Reduction(data.lay, 1)), ConicSolver(Reduction(data.lay, 1, aggregate=False, cones=False, decompose=False))):
            sol = solver.solve(data, rho)
            pi = data.pi0[0] - sol.L[0] @ data.ell[None, :]
            rho_c = certify(sol.P, pi, sol.tau[0], data.facts)
            assert rho_c is not None
            traces.append(np.trace(sol.P) * rho_c / rho)
        assert traces[0] == pytest.approx(traces[1], rel=1e-5)


def test_the_solver_is_kept_below_an_lmi_of_chordal_from(saim_steps):
    """SAIM, scheduled, an LMI not split into cliques: below an LMI of CHORDAL_FROM the node keeps one Clarabel
    solver per template and updates its data in place (Clarabel's own chordal decomposition, which refuses updates,
    off); from CHORDAL_FROM on Clarabel decomposes it and a new solver solves each step.  The node-steps of 12 steps
    of paper6 replayed on each node's estimator, as the node builds it; fails where every LMI is decomposed."""
    sc = load_topology(PAPER6, "saim", 12)
    ests = {i: _estimator(sc, i) for i in sc.ids}
    for node, args in saim_steps:
        ests[node].step(*args)
    seen: dict[bool, int] = {True: 0, False: 0}
    for est in ests.values():
        for pat in est._patterns.values():
            solver = pat.solver.fallback if isinstance(pat.solver, ClosedFormSolver) else pat.solver
            for key, tpl in solver._templates.items():
                if tpl.lmi_n and not tpl.decomposed:
                    small = tpl.lmi_n < CHORDAL_FROM
                    seen[small] += 1
                    assert (key in solver._solvers) == small, (tpl.lmi_n, key)
    assert seen[True] >= 3 and seen[False] >= 1, seen


def _run(sc, backend, monkeypatch):
    """The network with every node's estimator on ``backend`` (built by for_node, as the nodes build it)."""
    build = sdp.LocalEstimator.for_node.__func__
    monkeypatch.setattr(sdp.LocalEstimator, "for_node", classmethod(lambda cls, *a, **k: build(cls, *a, **{**k, "backend": backend})))
    return run_inmemory(sc, "paper", "scheduled", 0)


@pytest.mark.parametrize("case,steps,low,high", [("nsnim", 40, -1e-3, 1e-3), ("saim", 30, -2e-2, 1e-3)])
def test_fast_and_cvxpy_paths_agree_on_the_paper_scenario(case, steps, low, high, monkeypatch):
    sc = load_topology(PAPER6, case, steps)
    fast, ref = _run(sc, "clarabel", monkeypatch), _run(sc, "cvxpy", monkeypatch)
    for res in (fast, ref):
        assert res.summary.violations_total == 0
        assert all(r.fallbacks == 0 for r in res.summary.nodes)
    for node, entries in fast.parts["nodes"].items():
        others = ref.parts["nodes"][node]
        assert [e["step"] for e in entries] == [e["step"] for e in others] == list(range(steps + 1))
        for a, b in zip(entries, others):
            for e in (a, b):
                assert e["contained"] or not e["assumptions_ok"], f"node {node} step {e['step']}: E = {e['E']}"
            if a["step"] == 0:
                continue
            assert a["status"] == b["status"] == "ok"
            w_fast, w_ref = np.sqrt(a["published"]["rho"] * a["published"]["P"][8]), np.sqrt(b["published"]["rho"] * b["published"]["P"][8])
            assert low <= w_fast / w_ref - 1.0 <= high, f"node {node} step {a['step']}: widths {w_fast} vs {w_ref}"


def test_fast_path_is_never_above_the_cvxpy_optimum_on_saim_data(saim_steps):
    """Same step data: trace of the certified fast answer ≤ the cvxpy path's (up to 1e-5)."""
    sc = load_topology(PAPER6, "saim", 12)
    for node, args in saim_steps[::3]:
        a = _estimator(sc, node).step(*args)
        b = _estimator(sc, node, backend="cvxpy").step(*args)
        assert a.figures.status == b.figures.status == "ok"
        assert np.trace(a.continued.P) <= np.trace(b.continued.P) * (1 + 1e-5)


def test_default_backend_does_not_import_cvxpy():
    """A node process must not pay cvxpy's ~120 MB and ~1 s: the default path never imports it."""
    code = (
        "import sys\n"
        "from netsetest.config.schema import load_topology\n"
        "from netsetest.bus.base import MemoryBus\n"
        "from netsetest.roles.node import Node\n"
        "import netsetest.cli.main, netsetest.runtime.processes, netsetest.bus.zenoh_bus\n"
        f"sc = load_topology({str(PAPER6)!r}, 'saim', 3)\n"
        "Node(sc, 1, MemoryBus(), 'x')\n"
        "from netsetest.runtime.inmemory import run_inmemory\n"
        "run_inmemory(sc)\n"
        "assert 'cvxpy' not in sys.modules, 'cvxpy imported'\n"
        "assert 'scipy.sparse' not in sys.modules, 'scipy.sparse imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


@pytest.mark.parametrize("case", ["nsnim", "saim"])
def test_certificate_of_stacked_facts_is_the_certificate(case, saim_steps, nsnim_steps):
    """A step stacks its facts once for its certificates (FactStack): the same ρ' bit for bit as
    from the list of facts, and still no certificate when a fact or the answer is not finite."""
    sc = load_topology(PAPER6, case, 12)
    steps = saim_steps if case == "saim" else nsnim_steps
    for node, args in steps[::5]:
        est = _estimator(sc, node)
        data = _data(est, args)
        sol = ConicSolver(Reduction(data.lay, 1)).solve(data, args[0].rho)
        pi = data.pi0[0] - sol.L[0] @ data.ell[None, :]
        stack = FactStack.of(data.facts)
        rho_c = certify(sol.P, pi, sol.tau[0], stack)
        assert rho_c is not None and rho_c == certify(sol.P, pi, sol.tau[0], data.facts)
        bad = list(data.facts)
        bad[-1] = bad[-1].copy()
        bad[-1][1, 1] = np.nan
        assert certify(sol.P, pi, sol.tau[0], FactStack.of(bad)) is None
        assert certify(np.full_like(sol.P, np.inf), pi, sol.tau[0], stack) is None


def _certified_trace(sol, data, rho):
    rho_c = certify(sol.P, data.pi0[0] - sol.L[0] @ data.ell[None, :], sol.tau[0], data.facts)
    assert rho_c is not None
    return float(np.trace(sol.P)) * rho_c / rho


@pytest.mark.parametrize("informative", [False, True])
def test_closed_form_agrees_with_clarabel(nsnim_steps, informative):
    """NSNIM, scheduled: the closed form over τ with Newton over L (estimator/sum_of_norms.py) certifies the
    same trace as Clarabel's solution of the same SOCP, never a larger one.  On the paper's data the best
    gain is L = 0 on every step (the innovations carry less than their noise bounds cost, docs/estimator.md);
    with the aggregated noise slots' ℓ scaled down (``informative``) it is not, and Newton runs."""
    sc = load_topology(PAPER6, "nsnim", 12)
    nonzero = 0
    for node, args in nsnim_steps[::3]:
        est = _estimator(sc, node)
        data = _data(est, args)
        rho = args[0].rho
        red = Reduction(data.lay, 1)
        fast, ref = ClosedFormSolver(red), ConicSolver(red)
        if informative:
            ell = data.ell.copy()
            ell[red.agg_slots] *= 1e-3
            data = dataclasses.replace(data, ell=ell)
        sol = fast.solve(data, rho)
        assert sol.status == "Solved (closed form)"
        nonzero += bool(np.any(sol.L[0] != 0.0))
        t_fast, t_ref = _certified_trace(sol, data, rho), _certified_trace(ref.solve(data, rho), data, rho)
        assert t_ref * (1 - 1e-5) <= t_fast <= t_ref * (1 + 1e-9)
    assert (nonzero > 0) == informative


@pytest.mark.parametrize("case", ["nsnim", "saim"])
def test_the_benchmark_solves_the_nodes_own_problem(case: str) -> None:
    """The benchmark re-solves every captured step with an estimator built as the node builds it: the
    answer is bit for bit the state the node published (its hand-built copy had no fault bound and solved
    another SAIM problem: 55 of 120 steps came out with an `assumed` sector where the node's had
    `fault-bound`)."""
    from netsetest_bench.solvers import capture, fast_estimators

    sc = load_topology(PAPER6, case, steps=12)
    cap = capture(sc, "scheduled")
    assert cap.parts is not None and len(cap.cases) == 6 * 12
    published = {(int(i), e["step"]): e for i, es in cap.parts["nodes"].items() for e in es}
    est = fast_estimators(sc, "scheduled")  # what the benchmark times
    bases = set()
    for n, c in enumerate(cap.cases):
        res = est[c.node].step(*c.args)
        r = res.published
        e = published[(c.node, n // 6 + 1)]
        assert r.xhat.tolist() == e["published"]["xhat"] and r.P.reshape(9).tolist() == e["published"]["P"], (c.node, n)
        assert (res.sector.basis if res.sector is not None else "none") == e["sector_basis"]
        bases.add(e["sector_basis"])
    assert case == "nsnim" or "fault-bound" in bases
