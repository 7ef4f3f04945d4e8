"""The clarabel backend (estimator/conic.py and the closed form of estimator/sum_of_norms.py) answers bit for
bit as it did before it was split along its seams (issue 18): digests of every backend answer (P, L_ℓ, τ_ℓ,
status, iterations) and of every published state over 30 steps, NSNIM and SAIM, paper and worst-case
signals, scheduled and per-rule, on paper6, paper6_reference (the readings' ν slots and the closed form's
warm start) and paper6_max_faulty (the closed form's vanished terms), as computed on 1e76d75.

The SAIM digests were re-recorded on 2026-11-27 (branch saim-tight) for one change by design: where a
step's sector rests on the declared fault bound, the published set is cut by |f⁺| ≤ F (estimator/slab.py;
paper6 SAIM mean fault width / exact 1.38 → 1.19).  Neighbours use the published sets, so the backend
answers of SAIM change too; NSNIM (no saturation, no cut) is unchanged bit for bit.

The paper6_max_faulty digests were re-recorded on 2026-11-27 for the SDP's health pin: where no consistent
majority of the step's readings leaves a node's sensor out, its published set is cut by |f⁺| ≤ max(τ, 1e-6)
(LocalEstimator._health_pin; paper6_max_faulty mean fault width / exact with k-of-N, seed 0, paper signals:
NSNIM 1.40 → 1.14, SAIM 1.60 → 1.21, sensors 3 and 5 ≈ 2.0 → 1.2–1.3).  The other topologies have no
max_faulty and are unchanged.

The paper6_reference SAIM published digests were re-recorded on 2026-11-27 for the fault range: a set cut
by a declared bound is published as its ellipsoid ∩ that bound (NodeState.fault_range then, ProvenSet.fault now), so the step's fault
interval, and with it the fdi label, can be narrower.  Every float of every published ellipsoid and every
backend answer is unchanged (checked against the previous commit for all 24 cases); only fdi labels moved,
on paper6_reference SAIM (more steps detected).

The paper6_reference and paper6_max_faulty digests were re-recorded on 2026-11-28 for one change by design:
the set a node continues from is cut by what the step's readings prove (LocalEstimator._carry,
the slab cut along c̄_j), so the readings reach the later steps' priors and with them every later answer.
Seed 0, worst-case signals, mean fault width / exact from step 10: paper6_max_faulty NSNIM ≤ 1.34 → ≤ 1.17,
SAIM ≤ 1.55 → ≤ 1.20; paper6_reference NSNIM ≤ 1.41 → ≤ 1.39.  paper6 (no readings) is unchanged bit for
bit, which also checks that the cut along a direction c answers as the coordinate cut did for c = e₃.
The same day, the paper6_max_faulty digests again for the pin carried too (LocalEstimator._health_pin: the set
a node continues from is cut by |f⁺| ≤ max(τ, 1e-6) where the k-of-N readings pin its fault): seed 0, mean
fault width / exact from step 10, nodes 3 and 5 (the only ones pinned): SAIM worst ≤ 1.20 → ≤ 1.16, NSNIM
worst ≤ 1.17 → ≤ 1.16; every other node unchanged.

The paper6_reference and paper6_max_faulty digests were re-recorded on 2026-11-28 (later) for the region: a node
with readings keeps a convex polygon of x = (β, r) moved through each step and cut by every reading
(netsetest/polygon.py, LocalEstimator._use_region), and its published fault interval is cut by what its own
measurement proves over it; the k-of-N prediction is narrowed by it too, so pins change.  Seed 0, mean fault
width / exact from step 10: paper6_reference NSNIM worst 1.23–1.39 → 1.000 on every node, paper6_max_faulty
SAIM worst ≤ 1.16 → ≤ 1.03.  paper6 (no readings: no region) is unchanged bit for bit, which also checks the
blended model's new arithmetic (TSModel.blend, the same dot as np.tensordot).

Every digest was re-recorded on 2026-11-28 (issue 28, after merging issue 32's exact Minkowski sum and its audit) for the region
every node now keeps and publishes (readings or not): the published set is the ellipsoid ∩ the fault range ∩ the
region, and the fault range is cut by the own measurement over the region, so the fdi labels move everywhere.
On paper6 (no readings) the ellipsoids are not reshaped by it: the backend answers of paper6 NSNIM, paper signals,
scheduled, are the parent commit's in the recording environment (checked; the WANT table before this re-record did
not match the parent commit there either).  With readings the region's cuts narrow the fault range and reshape the
ellipsoid as before, so paper6_reference and paper6_max_faulty answers change.  Mean width / exact from step 10,
seed 0, paper signals: paper6 NSNIM r 1.72 → 1.001, β 2.38 → 1.001, f 1.12 → 1.000; paper6_reference every
node r, β, f 1.000 (the reference's own fault: published [0, 0]).

The SAIM digests were re-recorded on 2026-11-28 (branch i28, issue 28) for one change by design: a measurement at the
sensor's limit (one end of its interval open) still bounds the fault from its other end over the region
(estimator/cuts.py, region_fault), where before such a step's fault range came from the ellipsoid and the size cut
alone.  On paper6 (no readings) the ellipsoids are not reshaped by it: every backend answer is unchanged (the first
digest of each SAIM pair), and only the published fault ranges, and with them the fdi labels, move.  With readings the
range's cut reshapes the published ellipsoid, so paper6_reference and paper6_max_faulty SAIM answers change too.
Every NSNIM digest is unchanged (no saturation), which also checks that the SDP step rebuilt as a pipeline
(StepContext, the declared cuts) and the cut's no-clip fast path (Polygon.cut) answer bit for bit as before.  Mean
fault width / exact from step 10, paper6 SAIM: paper signals seed 0, 1.062 → 1.003 (worst node 1.015); worst-case
signals seed 3, → 1.002 (worst node 1.006).

Every digest was re-recorded on 2026-12-07 (branch i45, issue 45) for two changes by design: the certificate of a step
whose facts are all balls is the closed form of estimator/certificate.py (its ρ' within 1.2e-14 of the d×d check's,
so every later float moves in its last bits), and objective ``bank`` no longer solves a second time (the published
ellipsoid is the one the node continues from where no cut reshapes it).  Every published interval is the same to 4
decimals of its ratio to exact on every run of ``bench --only widths`` (docs/estimator.md, *Objectives*)."""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from netsetest.config.schema import load_topology
from netsetest.estimator import sdp
from netsetest.estimator.problem import Solution
from netsetest.runtime.inmemory import run_inmemory

ROOT = Path(__file__).resolve().parents[2]
STEPS = 30
SEED = 3
PUBLISHED = ("xhat", "P", "rho")  # the floats of a published state's ellipsoid (the record's "published" set; the fault bound is xhat, P, ρ)
CERTIFIED = ("rho_cert", "sector")  # and of its certificate and sector
LABELS = ("status", "sector_basis", "fdi")

# (topology, case) → (signals, variant) → (digest of the backend's answers, digest of the published states)
WANT: dict[tuple[str, str], dict[tuple[str, str], tuple[str, str]]] = {
    ("paper6", "nsnim"): {
        ("paper", "scheduled"): ("ebf7c73b48c187555b88a7bb1e2e0ac0", "cfdc5568c085a3fcb24c7e2db4a04b58"),
        ("paper", "per-rule"): ("52e88c5ac5a63de227d03ac5c2bdfea8", "5e7f51bae32fe700281f86531536f082"),
        ("worst", "scheduled"): ("ebf7c73b48c187555b88a7bb1e2e0ac0", "55cff5a8cc701a5707f28b4f749bc56d"),
        ("worst", "per-rule"): ("52e88c5ac5a63de227d03ac5c2bdfea8", "0d1250fc5d7374d685ad20775b09b570"),
    },
    ("paper6", "saim"): {
        ("paper", "scheduled"): ("c58926faebeab5305a5646963866c66f", "8b67d69562acb208bed1cb99bebe4f31"),
        ("paper", "per-rule"): ("17767ed434c042adf2528db3832cd2f0", "afeb663b103fb24a04ac00e13185b323"),
        ("worst", "scheduled"): ("fb6a5088aa6dd9481c61a6eb471b7b82", "912f268b88e2be220178a8e3ebd87271"),
        ("worst", "per-rule"): ("2dcc4c459ac19cc210e27ffe854ea348", "275decf10e7a2fd5e4e82a45c415b041"),
    },
    ("paper6_reference", "nsnim"): {
        ("paper", "scheduled"): ("87a0078e4db56bcdb82d4f70cc8f327a", "0f563ff172dcc047867589ff3130f12c"),
        ("paper", "per-rule"): ("8e9e1be2d2da5da80853e66c6510fd36", "70647740729faca42b7a7b88b5edbbd7"),
        ("worst", "scheduled"): ("3946d13ae22899056a71c6d8fb59087d", "6735a16455f69149a312fbc20c20edcd"),
        ("worst", "per-rule"): ("a9863f17ac058aa4f93d3e7b8fea6a10", "2b10663490fb376aa37f2b996623afa3"),
    },
    ("paper6_reference", "saim"): {
        ("paper", "scheduled"): ("63beaa7bef403b0fa9a369464003dfd2", "98927880ef0d641d30f6f4550001204e"),
        ("paper", "per-rule"): ("b76ec537a9d5369e8827afed4f211500", "a747b7c04ce6b08683b5f42c9fb17b86"),
        ("worst", "scheduled"): ("48cdddce6f11411b1cf4e001cce34498", "33e02f3b578904673db74dca50d6321e"),
        ("worst", "per-rule"): ("ab0189affb1e5853904afc436c0fecb4", "093ca86e69f7bec843eb96f7cf2c4b55"),
    },
    ("paper6_max_faulty", "nsnim"): {
        ("paper", "scheduled"): ("b065b47fb6554c49afc10a6975dda46d", "937f42366c903f9ae105ad88b6026d72"),
        ("paper", "per-rule"): ("a5b15b0fcf9a64b85b9164377f6046ab", "fba2cba2bcc174511ded4b7520b30b5c"),
        ("worst", "scheduled"): ("db69268c651fd6578aa132d8bc90f622", "bb6c84cd1e92a54e2fdf81c017f3c4d9"),
        ("worst", "per-rule"): ("526e0409cf47889ec9db1303bddbf8dd", "a20577541543dbad7280ede3fffa3e83"),
    },
    ("paper6_max_faulty", "saim"): {
        ("paper", "scheduled"): ("be64f64dac1c062085b8e8e7681d9516", "18725cba402403ee8b3e2f76d90ad9df"),
        ("paper", "per-rule"): ("e11f4175c759a1e8d0210bc75f81a493", "e3aef80f3cb78225a7f1d1dfa85e7b74"),
        ("worst", "scheduled"): ("c707376cefea45e6b23d286d978f96a6", "6b09ab9614f6454ebf0403bacb0659f1"),
        ("worst", "per-rule"): ("9b13b86d5d646cfcfda71dbe7140bb64", "625a21188fff91560d8e9afd68eae5f2"),
    },
}


def _floats(h: Any, v: Any) -> None:
    h.update(b"-" if v is None else np.asarray(v, dtype=float).tobytes())


def _answers(h: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every backend answer of the run goes into ``h`` (its solver wrapped where the pattern is built)."""
    build = sdp.LocalEstimator.pattern

    def pattern(self: sdp.LocalEstimator, *args: Any, **kwargs: Any) -> Any:
        pat = build(self, *args, **kwargs)
        solver = pat.solver
        if not getattr(solver, "_digested", False):
            solve = solver.solve

            def digested(data: sdp.StepData, rho: float) -> Solution:
                sol = solve(data, rho)
                h.update(f"{self.node_id}|{sol.status}|{sol.iterations}|".encode())
                _floats(h, sol.P)
                for L, tau in zip(sol.L, sol.tau):
                    _floats(h, L)
                    _floats(h, tau)
                return sol

            solver.solve = digested  # type: ignore[method-assign]  # the test's recording wrapper
            solver._digested = True  # type: ignore[attr-defined]  # wrapped once per solver
        return pat

    monkeypatch.setattr(sdp.LocalEstimator, "pattern", pattern)


def _published(nodes: dict[str, list[dict[str, Any]]]) -> str:
    h = hashlib.blake2b(digest_size=16)
    for i in sorted(nodes, key=int):
        for e in nodes[i]:
            h.update(f"{i}|{e['step']}|".encode() + "|".join(str(e[k]) for k in LABELS).encode())
            for k in PUBLISHED:
                _floats(h, e["published"][k])
            for k in CERTIFIED:
                _floats(h, e[k])
    return h.hexdigest()


def _digests(topology: str, case: str) -> Iterator[tuple[tuple[str, str], tuple[str, str]]]:
    sc = load_topology(ROOT / "topologies" / f"{topology}.toml", case, STEPS)
    for signals in ("paper", "worst"):
        for variant in ("scheduled", "per-rule"):
            with pytest.MonkeyPatch.context() as mp:
                h = hashlib.blake2b(digest_size=16)
                _answers(h, mp)
                res = run_inmemory(sc, signals, variant, SEED)
            yield (signals, variant), (h.hexdigest(), _published(res.parts["nodes"]))


@pytest.mark.parametrize(("topology", "case"), [(t, c) for t in ("paper6", "paper6_reference", "paper6_max_faulty") for c in ("nsnim", "saim")])
def test_the_clarabel_backend_answers_bit_for_bit_as_before(topology: str, case: str) -> None:
    got = dict(_digests(topology, case))
    assert got == WANT[(topology, case)]
