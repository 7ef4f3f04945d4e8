"""The clarabel backend (estimator/conic.py and the closed form of estimator/sum_of_norms.py) answers bit for
bit as it did before it was split along its seams (issue 18): digests of every backend answer (P, L_ℓ, τ_ℓ,
status, iterations) and of every published state over 30 steps, NSNIM and SAIM, paper and worst-case
signals, scheduled and per-rule, on paper6, paper6_reference (the readings' ν slots and the closed form's
warm start) and paper6_max_faulty (the closed form's vanished terms), as computed on 1e76d75."""

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
PUBLISHED = ("xhat", "P", "rho", "rho_cert", "sector")  # the floats of a published state (the fault bound is xhat, P, ρ)
LABELS = ("status", "sector_basis", "fdi")

# (topology, case) → (signals, variant) → (digest of the backend's answers, digest of the published states)
WANT: dict[tuple[str, str], dict[tuple[str, str], tuple[str, str]]] = {
    ("paper6", "nsnim"): {
        ("paper", "scheduled"): ("126dddc9dc17bd389d8c76b416dccd88", "a9a44bbeb6f646ab2a89ebdd065670ec"),
        ("paper", "per-rule"): ("80107eeabaaf6fd479a7b7ff9c961418", "99ce0c92572b4ff68321ab7a8dd75f3e"),
        ("worst", "scheduled"): ("126dddc9dc17bd389d8c76b416dccd88", "857a04da4737f25a7057784a2ab32aaf"),
        ("worst", "per-rule"): ("80107eeabaaf6fd479a7b7ff9c961418", "b80df3d211a45f52c6c2a630b25c462b"),
    },
    ("paper6", "saim"): {
        ("paper", "scheduled"): ("ae053c9ede326da517383abbe99ee256", "5df5ac9db328908de266d7d3e259cd79"),
        ("paper", "per-rule"): ("90047ec204d0f9709e2aceab3c3b814b", "7d87718ae3dc6da835abb298945d51a5"),
        ("worst", "scheduled"): ("7de0f9a7c304c72634baeff981aa4175", "8b29bef34781367900223705457393fd"),
        ("worst", "per-rule"): ("7feca1430d6167e4214a9ddca1908b3a", "b0625962f7cc11b909a2547e4a63036e"),
    },
    ("paper6_reference", "nsnim"): {
        ("paper", "scheduled"): ("1dbd0d217e7a71d846af2982f5f7f493", "c418eaffb49d9c7b2cda8f6310e5c725"),
        ("paper", "per-rule"): ("6cf02ec75f10dfd624bc25fb13ce738e", "4af639b8357e3947b8f6c769cbbe7e1c"),
        ("worst", "scheduled"): ("2919f2a90220205b4877f255567b9efb", "8cbe8b23dd241ef4e8a1c07af3a87932"),
        ("worst", "per-rule"): ("0ff344167aa563778a4e6e46e780e48e", "387165228af4f27dca98f41586085c13"),
    },
    ("paper6_reference", "saim"): {
        ("paper", "scheduled"): ("b93d5f1f07d1e407e4339b96c08be52e", "a01e8a14d1d45363e57a0faed8f1cd86"),
        ("paper", "per-rule"): ("1398af716db894350907dd123c9317c6", "90c3ed6d3e9c829f3f7d2c77d810477c"),
        ("worst", "scheduled"): ("fbf78c53b276928fe38900fff83f2478", "055e5440d3b97006c6cf26abd66bea2c"),
        ("worst", "per-rule"): ("a6a455718755358c6f53c8156ea855b6", "6491aae8f56668a5d5ac4a5a66be1819"),
    },
    ("paper6_max_faulty", "nsnim"): {
        ("paper", "scheduled"): ("46bc7cd19e7073ae0820b351f9f3482c", "045fc083d193076256638549a3758879"),
        ("paper", "per-rule"): ("df0294fde4c24954c5270122233b5ffd", "1886c0ced42e96d1cb387e815e8b024a"),
        ("worst", "scheduled"): ("ce50a757eb601d01e4dfcff344291181", "ae031802f81219e1e273ac30e70f6365"),
        ("worst", "per-rule"): ("e124c2e26851166ea96ec54984d6b1d0", "0e505718e2124d510fecf1d730270a93"),
    },
    ("paper6_max_faulty", "saim"): {
        ("paper", "scheduled"): ("f6ac0e11bbab08ae6a1e1c7a3b0f1e6b", "e49a665812276589d025099f9c205988"),
        ("paper", "per-rule"): ("7621d72e3939f4e36a3c46e5aabbddd6", "5269ce2ec271eeca1085ee52689ff174"),
        ("worst", "scheduled"): ("1b74d2f6ce90193bd6bb7b1a30e10ede", "9cd391dac7fb9317f5b8069459b3eed5"),
        ("worst", "per-rule"): ("aede613cb532cacd06ae100c7d1d6ed4", "2e5dea32953e3077c5f4eb6dd0646c14"),
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
