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
signals seed 3, → 1.002 (worst node 1.006)."""

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
        ("paper", "scheduled"): ("da9dd88ceeed4dfd27e60fcae971f452", "311b1a64199a2b4e3b9e76512e00e634"),
        ("paper", "per-rule"): ("5a7a4b48beff63a8924f9a1dc896d5bc", "daf7445c28042034608f373ef1bbb54e"),
        ("worst", "scheduled"): ("da9dd88ceeed4dfd27e60fcae971f452", "7510937ff827bbad69ceabd05222f676"),
        ("worst", "per-rule"): ("5a7a4b48beff63a8924f9a1dc896d5bc", "cf05f168f8aa06d1ec5fec9ab98a7f86"),
    },
    ("paper6", "saim"): {
        ("paper", "scheduled"): ("f1c7c63796f3c039d4454c82cf1bf1ef", "470d5c2a0565856f84d2c207c0c4d71e"),
        ("paper", "per-rule"): ("1fdad3257ba903d2547c62bc0f6389ea", "84f8a53e16c7bc24199c538828386d7c"),
        ("worst", "scheduled"): ("5957527439619dfb6dfafa085117b415", "21e19e83924cd738d26d79e894c1c7ae"),
        ("worst", "per-rule"): ("220fb31a0053f4158ca4810650ab614f", "b0d840d740a5f17b08ff0c51300611b6"),
    },
    ("paper6_reference", "nsnim"): {
        ("paper", "scheduled"): ("80a905b084a3bce1bedc84c1615e1d7e", "09fbba07a163a24917f0c96471470656"),
        ("paper", "per-rule"): ("617b9438bb599a9c3ee21f9942f43b25", "22c1511f5c4b6c2a6f14ec7e3ff6448b"),
        ("worst", "scheduled"): ("7a2645d84fb18ccceb9cd5376f56cc5f", "2ae574d9bb2ba3959ebf18fbb03fc17a"),
        ("worst", "per-rule"): ("f289cb58b67b559d3da93dc852f1debb", "d55824b6a0539be0b21111734d50cd4e"),
    },
    ("paper6_reference", "saim"): {
        ("paper", "scheduled"): ("39f037435c2618be7041e93ab0cd53eb", "81e9c8d40ca1b7688a0ff3dfb614393c"),
        ("paper", "per-rule"): ("c23f7b3a683b7984ce45136c49532db5", "811acef909623a7cb86986c9a9377db3"),
        ("worst", "scheduled"): ("9bb2b09ca42ec6624c531e6b0cd13f6c", "209d203570e6f11b6c9699cfd13b1062"),
        ("worst", "per-rule"): ("9835c506e0f7fea4306a61857252910b", "bb1585616432d0c92ce448ab2dbb50d3"),
    },
    ("paper6_max_faulty", "nsnim"): {
        ("paper", "scheduled"): ("73a53a38802063e660cd1bb59f21c33c", "ff1612b0cb056f5405893d368b552f06"),
        ("paper", "per-rule"): ("c64944f3779b55828855fc5302a55656", "0ca27c0ed05ac4c98a336d42da052e9c"),
        ("worst", "scheduled"): ("a65b835d538106b9c4caae8963e9991c", "0ff9c28234ca9d913a1c70950512c957"),
        ("worst", "per-rule"): ("833cd7b605221e353119e4ce79ee0fcd", "f82932dc64249c20897552bbb1462795"),
    },
    ("paper6_max_faulty", "saim"): {
        ("paper", "scheduled"): ("9340fbe3ca3499100e20e69fa850a196", "d735b190763c431dfff938f2836638ad"),
        ("paper", "per-rule"): ("19e70c6988e29a7e954d49e7127efbe8", "c1287563a5b5047de61a175f29265697"),
        ("worst", "scheduled"): ("5d2337ddd97f31adbac253a700f9f632", "e637bcd21de6584231bc577a33ace64e"),
        ("worst", "per-rule"): ("e3bad3506303634b60ff3d338b27371f", "f1e6d766097acddf371b39d565cd63e3"),
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
