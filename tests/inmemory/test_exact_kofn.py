"""`netsetest exact` under ``[network] max_faulty``: the branch and bound over each step's pieces is the exact
limit (against brute force over every hypothesis sequence), never wider than without the assumption, holds the
truth, and no node that uses the assumption publishes an interval narrower than it."""

from __future__ import annotations

import dataclasses
import itertools
import json
from functools import cache
from pathlib import Path

import clarabel
import numpy as np
import pytest
from scipy import sparse

from netsetest.analysis.exact import COORDINATES, ExactBounds, _Program, _settings, compare_record, exact_bounds, health_line, local_limits, step_data
from netsetest.analysis.kofn import Piece, covered, step_pieces
from netsetest.cli.main import main
from netsetest.config.schema import FaultBoundsMode, HealthGroup, Scenario, load_topology
from netsetest.records.record import Record, record_from_parts
from netsetest.runtime.inmemory import run_inmemory

TOPOLOGY = "paper6_max_faulty"
ROOT = Path(__file__).resolve().parents[2]
AGREE = 1e-7  # branch and bound against brute force: both are Clarabel solves at 1e-10
STEPS_RECORD = 21  # the paper's faults of sensors 1, 2, 4 and 6 are all on from step 20


@cache
def _run(steps: int, case: str = "nsnim", estimator: str | None = None) -> tuple[Scenario, Record]:
    sc = load_topology(TOPOLOGY, case=case, steps=steps)
    if estimator is not None:
        sc = dataclasses.replace(sc, nodes=[dataclasses.replace(n, estimator=estimator) for n in sc.nodes])
    res = run_inmemory(sc, "paper", "scheduled", 0)
    assert res.parts is not None
    return sc, record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary)


@cache
def _exact(steps: int, health: bool = True, fault_bounds: FaultBoundsMode = "used") -> ExactBounds:
    sc, rec = _run(steps)
    return exact_bounds(sc, rec, fault_bounds, health=health)


def _brute_force(sc: Scenario, rec: Record, fault_bounds: FaultBoundsMode) -> dict[tuple[str, int | None, int], tuple[float, float]]:
    """Every end as the least (greatest) value over every sequence of hypotheses H_0..H_k (in every group, N − m of
    its sensors with |f| ≤ τ at each step), each one convex program on the whole horizon (no fault eliminated)."""
    prog = _Program(sc, step_data(rec), sc.fault_bounded(fault_bounds))
    position = {i: n for n, i in enumerate(sc.ids)}
    per_group = []  # per group: every set of need of its sensors in the program (positions)
    for g in sc.health_groups:
        members = [position[i] for i in g.nodes if i in position]
        per_group.append(list(itertools.combinations(members, len(members) - g.max_faulty)))
    hypotheses = [tuple(n for part in parts for n in part) for parts in itertools.product(*per_group)]
    out = {}
    for k in range(len(step_data(rec))):
        cols, A, b, cones = prog.matrices(k, eliminate=False)
        pos = {c: m for m, c in enumerate(cols)}
        best: dict[tuple[str, int | None, int], list[float]] = {}
        for seq in itertools.product(hypotheses, repeat=k + 1):
            fcols = [pos[prog._f(n, j)] for j, h in enumerate(seq) for n in h]
            rows = sparse.csc_matrix((np.tile([1.0, -1.0], len(fcols)), (np.arange(2 * len(fcols)), np.repeat(fcols, 2))), shape=(2 * len(fcols), len(cols)))
            A2, b2 = sparse.vstack([A, rows], format="csc"), np.r_[b, np.full(2 * len(fcols), sc.fault_tolerance)]
            solver = None
            for coord, node, col in prog.objectives(k):
                for side, sign in ((0, 1.0), (1, -1.0)):
                    q = np.zeros(len(cols))
                    q[pos[col]] = sign
                    if solver is None:
                        solver = clarabel.DefaultSolver(
                            sparse.csc_matrix((len(cols), len(cols))), q, A2, b2, [*cones, clarabel.NonnegativeConeT(2 * len(fcols))], _settings()
                        )
                    else:
                        solver.update(q=q)
                    sol = solver.solve()
                    if str(sol.status) in ("Solved", "AlmostSolved"):
                        v = best.setdefault((coord, node, k), [np.inf, -np.inf])
                        v[side] = min(v[side], sol.x[pos[col]]) if side == 0 else max(v[side], sol.x[pos[col]])
        out.update({key: (lo, hi) for key, (lo, hi) in best.items()})
    return out


@pytest.mark.parametrize(("fault_bounds", "tolerance"), [("used", 0.0), ("all", 0.0), ("all", 0.02)])
def test_branch_and_bound_is_brute_force_over_every_hypothesis_sequence(fault_bounds: FaultBoundsMode, tolerance: float) -> None:
    """Three sensors (1, 3, 5), at most one faulty, 4 steps: 3^(k+1) hypothesis sequences per horizon k.  With
    ``all`` every fault has declared bounds (F = δ = 0.2): with τ = 0 a healthy value always meets them (health is
    t_j in the span), with τ = 0.02 it may not (F + τ > δ: health is |f| ≤ τ, branched on per sensor)."""
    full, rec = _run(3)
    full = dataclasses.replace(full, health_groups=(HealthGroup(tuple(full.ids), 1),), fault_tolerance=tolerance)
    ex = exact_bounds(full, rec, fault_bounds, nodes=[1, 3, 5])
    assert ex.health is not None and ex.health.need == (2,) and ex.health.exact_ends == ex.health.ends and not ex.health.relaxed
    sc = dataclasses.replace(full, nodes=[n for n in full.nodes if n.id in (1, 3, 5)])
    brute = _brute_force(sc, rec, fault_bounds)
    assert not ex.infeasible_steps and len(brute) == 4 * 5
    for (coord, node, k), (lo, hi) in brute.items():
        got = ex.interval(coord, node)[k]
        assert abs(got[0] - lo) <= AGREE and abs(got[1] - hi) <= AGREE, (coord, node, k, got, (lo, hi))
    without = exact_bounds(full, rec, fault_bounds, nodes=[1, 3, 5], health=False)
    assert any(ex.fault[i][k, 1] - ex.fault[i][k, 0] < without.fault[i][k, 1] - without.fault[i][k, 0] - 1e-3 for i in sc.ids for k in ex.steps)


def test_k_of_n_bounds_lie_inside_the_bounds_without_and_hold_the_truth() -> None:
    sc, rec = _run(STEPS_RECORD)
    ex, without = _exact(STEPS_RECORD), _exact(STEPS_RECORD, health=False)
    assert ex.health is not None and ex.omitted == () and without.omitted == ("k-of-N health (max_faulty = 4)",)
    assert ex.health.exact_ends == ex.health.ends == (STEPS_RECORD + 1) * 2 * (2 + len(sc.ids)) and not ex.infeasible_steps
    narrower = 0
    for coord in COORDINATES:
        for i in sc.ids:
            a, b = ex.interval(coord, i), without.interval(coord, i)
            assert np.all(a[:, 0] >= b[:, 0] - 1e-8) and np.all(a[:, 1] <= b[:, 1] + 1e-8), (coord, i)
            narrower += int(np.sum(a[:, 1] - a[:, 0] < 0.9 * (b[:, 1] - b[:, 0])))
    assert narrower > 0  # the assumption does bite on this run
    for t in rec.truth:
        assert t["health_ok"]
        k = t["step"]
        assert ex.beta[k, 0] - 1e-8 <= t["x"][0] <= ex.beta[k, 1] + 1e-8
        assert ex.r[k, 0] - 1e-8 <= t["x"][1] <= ex.r[k, 1] + 1e-8
        for i in sc.ids:
            assert ex.fault[i][k, 0] - 1e-8 <= t["faults"][i] <= ex.fault[i][k, 1] + 1e-8, (i, k)


@pytest.mark.parametrize(("estimator", "fault_bounds"), [(None, "used"), ("zonotope", "used"), ("strip", "all")])
def test_no_node_is_narrower_than_the_k_of_n_limit(estimator: str | None, fault_bounds: FaultBoundsMode) -> None:
    """Every node uses the k-of-N interval (the SDP) and the set observers also pin their own fault: where every
    assumption held, none is narrower than the exact limit under the same assumptions (the strip observer relies on
    every declared fault bound, as ``compare`` knows, so it is measured against ``all``: against ``used`` it is
    narrower on sensors 1 and 2, by up to 0.037 on 80 steps)."""
    sc, rec = _run(STEPS_RECORD, estimator=estimator)
    ex = _exact(STEPS_RECORD, fault_bounds=fault_bounds)
    held = np.array([t["health_ok"] for t in sorted(rec.truth, key=lambda t: t["step"])])
    for i, track in rec.nodes.items():
        ok = held[track.steps] & track.assumptions_ok
        for idx, coord in enumerate(COORDINATES):
            lo, hi = track.bounds(idx)
            e = ex.interval(coord, i)[track.steps]
            bad = ok & ((lo > e[:, 0] + AGREE) | (hi < e[:, 1] - AGREE))
            assert not bad.any(), (estimator, i, coord, track.steps[bad], lo[bad], e[bad, 0], hi[bad], e[bad, 1])
    assert sum(x.narrower for n in compare_record(rec, ex).nodes for x in n.ratios.values()) == 0


def test_the_pieces_of_a_step() -> None:
    """Untied spans are counted on the line; tied ones are assumed healthy in turn (Q), and no piece lies in another."""
    assert covered([(0, 2), (1, 3), (5, 6)], 2) == [(1, 2)]
    assert covered([(0, 2), (2, 3)], 2) == [(2, 2)]  # closed intervals that touch overlap
    assert covered([(0, 1)], 0) == [(-np.inf, np.inf)]
    spans = [(0.0, 2.0), (1.0, 3.0), (5.0, 6.0), (5.5, 7.0)]
    # all untied: the points covered twice, in two disjoint pieces
    assert step_pieces(spans, [False] * 4, [True] * 4, 2, (-np.inf, np.inf)) == [Piece(1.0, 2.0, ()), Piece(5.5, 6.0, ())]
    # sensor 0 tied: either two untied agree (5.5..6) or sensor 0 is healthy with one untied (1..2)
    assert step_pieces(spans, [True, False, False, False], [True] * 4, 2, (-np.inf, np.inf)) == [Piece(5.5, 6.0, ()), Piece(1.0, 2.0, (0,))]
    # a tied sensor known to be faulty, and a window that leaves one piece
    assert step_pieces(spans, [True, False, False, False], [False, True, True, True], 2, (0.0, 4.0)) == []


def test_the_command_applies_it_and_says_how_many_ends_are_exact(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``netsetest exact`` applies max_faulty by default (``--no-health``: the outer bound of before) and writes
    the search's figures into its JSON document."""
    sc = load_topology(TOPOLOGY, case="nsnim", steps=6)
    path = tmp_path / "run.json"
    run_inmemory(sc, "paper", seed=0, record=str(path), keep=False)
    assert main(["exact", str(path), "--json", str(tmp_path / "exact.json")]) == 0
    out = capsys.readouterr().out
    assert (
        "applied: k-of-N health (max_faulty = 4: at least 2 of sensors 1, 2, 3, 4, 5, 6 healthy at every step) by branch and bound, 112 of 112 ends exact"
        in out
    )
    assert "not applied" not in out and "narrower than exact on 0 of" in out
    doc = json.loads((tmp_path / "exact.json").read_text())
    assert doc["omitted"] == [] and doc["health"]["exact_ends"] == doc["health"]["ends"] == 112 and doc["health"]["relaxed"] == []
    assert doc["health"]["declared"] == "max_faulty = 4" and doc["health"]["need"] == [2] and doc["health"]["nodes"] == [[1, 2, 3, 4, 5, 6]]
    assert main(["exact", str(path), "--no-health"]) == 0
    out = capsys.readouterr().out
    assert "not applied: k-of-N health (max_faulty = 4)" in out and "applied: k-of-N" not in out.replace("not applied: k-of-N", "")


def test_two_groups_are_brute_force_over_every_hypothesis_sequence() -> None:
    """Two k-of-N groups, sensors (1, 2) and (3, 5), at most one faulty in each, 4 steps: 2 × 2 hypotheses a step,
    4^(k+1) sequences per horizon k.  The branch and bound over both groups' unions is the brute force."""
    full, rec = _run(3)
    full = dataclasses.replace(full, health_groups=(HealthGroup((1, 2), 1), HealthGroup((3, 5), 1)))
    ex = exact_bounds(full, rec, "used", nodes=[1, 2, 3, 5])
    assert ex.health is not None and ex.health.need == (1, 1) and ex.health.exact_ends == ex.health.ends and not ex.health.relaxed
    assert ex.omitted == () and ex.health.declared == "max_faulty = 1 of nodes 1, 2; max_faulty = 1 of nodes 3, 5"
    sc = dataclasses.replace(full, nodes=[n for n in full.nodes if n.id in (1, 2, 3, 5)])
    brute = _brute_force(sc, rec, "used")
    assert not ex.infeasible_steps and len(brute) == 4 * 6
    for (coord, node, k), (lo, hi) in brute.items():
        got = ex.interval(coord, node)[k]
        assert abs(got[0] - lo) <= AGREE and abs(got[1] - hi) <= AGREE, (coord, node, k, got, (lo, hi))
    without = exact_bounds(full, rec, "used", nodes=[1, 2, 3, 5], health=False)
    assert all(ex.fault[i][k, 1] - ex.fault[i][k, 0] < 0.5 * (without.fault[i][k, 1] - without.fault[i][k, 0]) for i in sc.ids for k in ex.steps)


def test_a_group_the_nodes_leave_out_is_not_applied() -> None:
    """``exact`` over a subset of the nodes (``--local``, ``compare --alone``): a group with no node in it, or
    with no more than its m, says nothing; one with more is applied to its nodes in the subset."""
    full, rec = _run(3)
    full = dataclasses.replace(full, health_groups=(HealthGroup((1, 2), 1), HealthGroup((3, 5, 6), 1)))
    ex = exact_bounds(full, rec, "used", nodes=[3, 5])
    assert ex.health is not None and ex.health.need == (1,) and ex.health.nodes == ((3, 5),) and ex.omitted == ()
    assert "at least 1 of sensors 3, 5 healthy at every step" in health_line(ex.health)  # what was applied, not the declaration
    assert exact_bounds(full, rec, "used", nodes=[4]).health is None
    assert len(local_limits(full, rec)) == len(full.ids)


def test_the_command_applies_several_groups(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``netsetest exact`` on a record of a topology with two groups: applied, and said how."""
    text = (ROOT / "topologies" / f"{TOPOLOGY}.toml").read_text().replace('node_dir = "../nodes"', f'node_dir = "{ROOT / "nodes"}"')
    groups = "[[network.health_groups]]\nnodes = [1, 2, 3]\nmax_faulty = 2\n\n[[network.health_groups]]\nnodes = [4, 5, 6]\nmax_faulty = 2\n"
    topo = tmp_path / "groups.toml"
    topo.write_text(text.replace("max_faulty = 4\n", groups))
    sc = load_topology(topo, case="nsnim", steps=6)
    path = tmp_path / "run.json"
    run_inmemory(sc, "paper", seed=0, record=str(path), keep=False)
    assert main(["exact", str(path), "--topology", str(topo)]) == 0
    out = capsys.readouterr().out
    assert (
        "applied: k-of-N health (max_faulty = 2 of nodes 1, 2, 3; max_faulty = 2 of nodes 4, 5, 6: at least 1 of sensors 1, 2, 3 and 1 of sensors 4, 5, 6 healthy"
        in out
    )
    assert "not applied" not in out and "narrower than exact on 0 of" in out


def test_a_spent_budget_relaxes_the_end_and_says_so() -> None:
    """With too few solves the search stops at the least bound proven: the end is reported relaxed, and it is an
    outer bound of the exact one (inside the bound without the assumption)."""
    sc, rec = _run(STEPS_RECORD)
    tight = exact_bounds(sc, rec, health_budget=1)
    ex, without = _exact(STEPS_RECORD), _exact(STEPS_RECORD, health=False)
    assert tight.health is not None and tight.health.relaxed and tight.health.exact_ends + len(tight.health.relaxed) == tight.health.ends
    assert "relaxed" in tight.label and ex.label == "used with k-of-N health" and without.label == "used without k-of-N health (max_faulty = 4)"
    for key in tight.health.relaxed:
        side = 0 if key.side == "lo" else 1
        got, exact, outer = (e.interval(key.coordinate, key.node)[key.step, side] for e in (tight, ex, without))
        assert (got <= exact + 1e-9 and got >= outer - 1e-9) if side == 0 else (got >= exact - 1e-9 and got <= outer + 1e-9)


def test_a_false_declaration_is_the_exact_rows_broken_assumption(tmp_path: Path) -> None:
    """At most 3 faulty declared where the paper's four are from step 20: ``compare``'s exact row (the limit under
    the declaration) is not covered from the first step it breaks, attributed to it, never a violation; its
    reference and assumptions say the assumption was applied."""
    from netsetest.analysis.compare import compare

    text = (ROOT / "topologies" / f"{TOPOLOGY}.toml").read_text()
    topo = tmp_path / "false_kofn.toml"
    topo.write_text(text.replace('node_dir = "../nodes"', f'node_dir = "{ROOT / "nodes"}"').replace("max_faulty = 4", "max_faulty = 3"))
    row = next(r for r in compare(topo, ("exact",), steps=21).rows if r.estimator == "exact")
    assert row.violations == 0 and row.covered < row.node_steps
    assert row.misses_attributed.get("k-of-N health", 0) > 0 and "k-of-N health" in row.assumptions
    assert row.exact_reference == ["used with k-of-N health"]


def test_every_exact_end_is_reached_by_a_trajectory_with_enough_healthy_sensors() -> None:
    """Each exact end's witness, simulated with the project's model and sensors, meets every assumption: wind,
    priors, noise, and at every step at least N − m sensors with a zero fault (τ = 0) — where a fault is not tied
    to a prior or to the objective, replacing it by 0 must reproduce its reading within the noise bound."""
    sc, rec = _run(STEPS_RECORD)
    ex = exact_bounds(sc, rec, keep_witnesses=True)
    assert ex.health is not None and len(ex.witnesses) == ex.health.exact_ends == ex.health.ends
    data = step_data(rec)
    for key, wit in ex.witnesses.items():
        assert np.all(np.abs(wit.w) <= np.sqrt(sc.W) + 1e-8)
        x = wit.x0.copy()
        for j in range(key.step + 1):
            d, healthy = data[j], 0
            for n in sc.nodes:
                e = np.r_[wit.x0, wit.f[n.id][0]] - n.x0_hat
                assert e @ np.linalg.solve(n.P0, e) <= n.rho + 1e-8
                s, f = n.sensor, wit.f[n.id][j]
                assert ((d.y[n.id] - d.gamma[n.id] * s.sigma(float(s.Cbar @ np.r_[x, f]))) / s.Dv) ** 2 <= s.R + 1e-8
                tied = j == 0 or (key.coordinate == "f" and key.node == n.id and j == key.step)
                v0 = (d.y[n.id] - d.gamma[n.id] * s.sigma(float(s.Cbar @ np.r_[x, 0.0]))) / s.Dv
                healthy += abs(f) <= 1e-8 if tied else v0**2 <= s.R + 1e-8
            assert healthy >= len(sc.ids) - 4, (key, j, healthy)
            if j < key.step:
                x = sc.model.step(x, d.u, float(wit.w[j]), d.vx)
        value = wit.f[key.node][key.step] if key.coordinate == "f" else x[0 if key.coordinate == "beta" else 1]
        assert value == pytest.approx(ex.interval(key.coordinate, key.node)[key.step, 0 if key.side == "lo" else 1], abs=1e-8)


def test_worst_case_noise_leaves_every_step_feasible() -> None:
    """Worst-case signals put the two healthy sensors' noises at opposite bounds: their intervals meet in the
    truth's one point. Unwidened for rounding, the k-of-N pieces missed it by an ulp and every step from the
    faults' onset (20) was reported infeasible, though every assumption held; the truth stays inside."""
    sc = load_topology(TOPOLOGY, case="nsnim", steps=STEPS_RECORD + 2)
    res = run_inmemory(sc, "worst", "scheduled", 0)
    assert res.parts is not None
    rec = record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary)
    ex = exact_bounds(sc, rec)
    assert ex.infeasible_steps == ()
    truth = {t["step"]: t for t in res.parts["truth"]}
    for i in sc.ids:
        iv = ex.interval("f", i)
        for n, k in enumerate(ex.steps):
            f = truth[int(k)]["faults"][str(i)]
            assert iv[n, 0] - 1e-7 <= f <= iv[n, 1] + 1e-7


def test_a_spent_time_budget_relaxes_soundly_against_brute_force() -> None:
    """``budget_s = 0``: no branch is solved, every end is its relaxation where that does not meet every union.
    Each relaxed end is a superset of the exact interval (brute force over every hypothesis sequence), each end
    still called exact agrees with it, and the search says when it ran out."""
    full, rec = _run(3)
    full = dataclasses.replace(full, health_groups=(HealthGroup(tuple(full.ids), 1),))
    ex = exact_bounds(full, rec, "used", nodes=[1, 3, 5], budget_s=0.0)
    assert ex.health is not None and ex.health.relaxed and ex.health.out_of_time == 0 and ex.health.budget_s == 0.0
    assert ex.health.exact_ends + len(ex.health.relaxed) == ex.health.ends
    assert "the time budget ran out at step 0" in health_line(ex.health)
    relaxed = {(k.coordinate, k.node, k.step, k.side) for k in ex.health.relaxed}
    sc = dataclasses.replace(full, nodes=[n for n in full.nodes if n.id in (1, 3, 5)])
    wider = 0
    for (coord, node, k), (lo, hi) in _brute_force(sc, rec, "used").items():
        got = ex.interval(coord, node)[k]
        for side, (g, b) in enumerate(zip(got, (lo, hi))):
            if (coord, node if coord == "f" else None, k, ("lo", "hi")[side]) in relaxed:
                assert (g <= b + AGREE) if side == 0 else (g >= b - AGREE), (coord, node, k, side, g, b)  # never narrower
                wider += abs(g - b) > 1e-6
            else:
                assert abs(g - b) <= AGREE, (coord, node, k, side, g, b)
    assert wider > 0  # the budget did cut the search short somewhere


def test_a_minimiser_off_a_tied_union_is_mended_instead_of_branched(monkeypatch: pytest.MonkeyPatch) -> None:
    """Step 0's faults are tied by the priors, and an interior-point minimiser leaves them off zero where the end
    does not care: the search clips a piece's tied faults to τ (every row met as well as at the minimiser) instead
    of solving a branch.  The same ends, every one exact, in fewer solves than without mending (whose witnesses the
    test above simulates)."""
    from netsetest.analysis import kofn

    sc, rec = _run(STEPS_RECORD)
    mended = _exact(STEPS_RECORD)
    monkeypatch.setattr(kofn, "_repaired", lambda *args: None)
    solved = exact_bounds(sc, rec)
    assert mended.health is not None and solved.health is not None
    assert mended.health.exact_ends == solved.health.exact_ends == solved.health.ends
    assert mended.health.solves < solved.health.solves
    for coord in COORDINATES:
        for i in sc.ids:
            assert np.allclose(mended.interval(coord, i), solved.interval(coord, i), atol=AGREE, rtol=0)


def test_the_search_keeps_a_bounded_number_of_solvers() -> None:
    """What the branch and bound keeps across the ends of a program: at most ``size`` solvers, least recently used out."""
    from netsetest.analysis.kofn import Solvers

    cache = Solvers(size=2)
    a, b, c = ((0, Piece(0.0, 1.0, ())),), ((0, Piece(1.0, 2.0, ())),), ((0, Piece(2.0, 3.0, ())),)
    cache.put(a, "A")  # type: ignore[arg-type]  # any object stands for a solver here
    cache.put(b, "B")  # type: ignore[arg-type]  # as above
    assert cache.get(a) == "A"  # a is now the most recently used
    cache.put(c, "C")  # type: ignore[arg-type]  # as above
    assert len(cache) == 2 and cache.get(b) is None and cache.get(a) == "A" and cache.get(c) == "C" and cache.built == 3


def test_the_eta_grows_with_the_horizon_and_stops_at_the_budget() -> None:
    from netsetest.analysis.exact import eta_s

    assert eta_s(5.0, 0, 80, None) is None
    assert eta_s(10.0, 40, 80, None) == pytest.approx(30.0)  # a step costs its horizon: 10 s for 40 steps, 40 s for 80
    assert eta_s(10.0, 40, 80, 25.0) == pytest.approx(15.0)
    assert eta_s(30.0, 40, 80, 25.0) == pytest.approx(90.0)  # past the budget: the pace so far


@pytest.mark.parametrize("value", ["-1", "abc", "nan", "inf"])
def test_a_bad_budget_is_refused(value: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["exact", str(tmp_path / "run.json"), "--budget", value])
    assert exc.value.code == 2 and "--budget" in capsys.readouterr().err


def test_the_command_reports_a_spent_budget(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--budget 0``: the ends the relaxation does not settle are relaxed, the line says so and the JSON counts them."""
    sc = load_topology(TOPOLOGY, case="nsnim", steps=4)
    path = tmp_path / "run.json"
    run_inmemory(sc, "paper", seed=0, record=str(path), keep=False)
    assert main(["exact", str(path), "--budget", "0", "--json", str(tmp_path / "exact.json")]) == 0
    assert "the time budget ran out at step 0" in capsys.readouterr().out
    h = json.loads((tmp_path / "exact.json").read_text())["health"]
    assert h["budget_s"] == 0.0 and h["out_of_time"] == 0 and h["relaxed_ends"] == len(h["relaxed"]) > 0
    assert h["exact_ends"] + h["relaxed_ends"] == h["ends"]


def test_a_guided_solve_settles_ends_as_the_search_does(monkeypatch: pytest.MonkeyPatch) -> None:
    """kofn.guided: one solve with the previous horizon's pieces, proven by their duals over each union's hull, settles
    most ends of a SAIM run with worst-case signals past step 27 (where a gap between two pieces catches the root's
    minimiser); the ends are those of the search from the root alone, every one exact."""
    from netsetest.analysis import exact as exact_module
    from netsetest.analysis.kofn import GuidedStart, guided

    sc = load_topology(TOPOLOGY, case="saim", steps=STEPS_GUIDED)
    res = run_inmemory(sc, "worst", "scheduled", 0)
    assert res.parts is not None
    rec = record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary)
    settled = []

    def counted(*args: object) -> GuidedStart:
        start = guided(*args)  # type: ignore[arg-type]  # guided's own arguments, passed through
        settled.append(start.end is not None)
        return start

    monkeypatch.setattr(exact_module, "guided", counted)
    with_guide = exact_bounds(sc, rec)
    monkeypatch.setattr(exact_module, "guided", lambda *args: GuidedStart(None, 0))
    without = exact_bounds(sc, rec)
    assert with_guide.health is not None and without.health is not None
    assert with_guide.health.exact_ends == without.health.exact_ends == without.health.ends
    assert sum(settled) >= len(settled) // 2 > 0  # fewer solves in all on the 80 steps (docs/exact.md, measured), not yet on 36
    for coord in COORDINATES:
        for i in sc.ids:
            assert np.allclose(with_guide.interval(coord, i), without.interval(coord, i), atol=AGREE, rtol=0)


STEPS_GUIDED = 36  # paper6_max_faulty SAIM, worst-case signals: the gaps between pieces catch the roots from step 27


def test_the_duals_of_a_piece_bound_the_end_over_its_union() -> None:
    """What a piece's rows can take off the dual bound: the least of Σ y·(b − a·z) over the union's hull of t_j."""
    from netsetest.analysis.kofn import StepUnion, _certified_below

    pieces = (Piece(0.0, 1.0, ()), Piece(2.0, 3.0, ()), Piece(2.5, 2.5, ()))
    union = StepUnion(1, {2: 1.0}, ((0.0, 3.0),), (None,), 0.0, 1, pieces)
    # lo ≤ t ≤ hi with y_hi = 0, y_lo = 0.5 on [2, 3]: 0.5·(t − 2), least at the hull's lower end t = 0
    assert _certified_below(union, pieces[1], np.array([0.0, 0.5])) == pytest.approx(-1.0)
    assert _certified_below(union, pieces[1], np.array([0.25, 0.0])) == pytest.approx(0.0)  # 0.25·(3 − t), least at t = 3
    assert _certified_below(union, pieces[0], np.array([0.25, 0.0])) == pytest.approx(-0.5)  # 0.25·(1 − t), least at t = 3
    # a point piece is one equality t = 2.5 with a dual of either sign: −0.2·(2.5 − t), least at t = 0
    assert _certified_below(union, pieces[2], np.array([-0.2])) == pytest.approx(-0.5)
    unbounded = dataclasses.replace(union, pieces=(Piece(-np.inf, 1.0, ()), pieces[1]))
    assert _certified_below(unbounded, pieces[1], np.array([0.0, 0.5])) == -np.inf
    assert _certified_below(unbounded, pieces[1], np.array([0.0, 0.0])) == 0.0
