"""The certificate's closed form (netsetest/estimator/certificate.py, ``diagonal_certificate``: every fact diagonal, P
3×3) against exact rational arithmetic (``fractions``), over adversarial steps (Hypothesis): every answer it gives
is a true certificate of the S-procedure condition on its own floats, including where the multipliers put the
lower block of the LMI within a few ulps of singular (on both sides) and P is badly conditioned or scaled far
from 1; and :func:`rump_definite` never calls a matrix definite that is not.  A certificate that accepts a
matrix that is not positive semidefinite would publish a set that may miss the truth: the worst bug.

A seeded short profile runs in every ``pytest``; the long run (10 000 examples each, random):
``NETSETEST_FUZZ_EXAMPLES=10000 pytest -n 0 -q --timeout 0 tests/unit/test_certificate.py``.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_polygon_exact import FUZZ

from netsetest.estimator.certificate import FactStack, _dense_certificate, certify, diagonal_certificate, rump_definite

Matrix = list[list[Fraction]]


def _exact(a: np.ndarray) -> Matrix:
    return [[Fraction(float(x)) for x in row] for row in np.atleast_2d(a)]


def _semidefinite(m: Matrix) -> bool:
    """Whether the symmetric rational matrix m is positive semidefinite (LDLᵀ with diagonal pivots, exactly: a zero
    pivot needs a zero rest of its row)."""
    a = [row[:] for row in m]
    n = len(a)
    for k in range(n):
        p = a[k][k]
        if p < 0:
            return False
        if p == 0:
            if any(a[k][j] != 0 for j in range(k + 1, n)):
                return False
            continue
        for i in range(k + 1, n):
            f = a[i][k] / p
            if f:
                for j in range(k + 1, n):
                    a[i][j] -= f * a[k][j]
    return True


def _definite(m: Matrix) -> bool:
    """Whether m is positive definite, exactly (every pivot > 0)."""
    a = [row[:] for row in m]
    n = len(a)
    for k in range(n):
        p = a[k][k]
        if p <= 0:
            return False
        for i in range(k + 1, n):
            f = a[i][k] / p
            for j in range(k + 1, n):
                a[i][j] -= f * a[k][j]
    return True


def _inverse3(p: Matrix) -> Matrix:
    (a, b, c), (d, e, f), (g, h, i) = p
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    adj = [[e * i - f * h, c * h - b * i, b * f - c * e], [f * g - d * i, a * i - c * g, c * d - a * f], [d * h - e * g, b * g - a * h, a * e - b * d]]
    return [[x / det for x in row] for row in adj]


def _holds(P: np.ndarray, pi: np.ndarray, tau: np.ndarray, facts: list[np.ndarray], rho: float) -> bool:
    """ρ e₁e₁ᵀ − Σ τ_m Q_m − Πᵀ P⁻¹ Π ⪰ 0, exactly, on these floats (and P ≻ 0): the S-procedure condition itself."""
    p = _exact(P)
    if not _definite(p):
        return False
    pinv, x = _inverse3(p), _exact(pi)
    d = len(x[0])
    q = [_exact(f) for f in facts]
    t = [Fraction(float(v)) for v in tau]
    m = [[Fraction(0)] * d for _ in range(d)]
    for i in range(d):
        for j in range(i, d):
            v = -sum((t[k] * q[k][i][j] for k in range(len(q))), Fraction(0))
            v -= sum((x[a][i] * pinv[a][b] * x[b][j] for a in range(3) for b in range(3)), Fraction(0))
            m[i][j] = m[j][i] = v
    m[0][0] += Fraction(rho)
    return _semidefinite(m)


@st.composite
def steps(draw: st.DrawFn, boundary: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
    """A step's (P, Π, τ, ball facts): P symmetric positive definite of condition up to 10¹², scaled by 10^k; Π
    (3, d), d 3–8, columns of mixed scales (some zero); ball facts 1 − Σ_slots η²/b over a random partition of the
    slots 1..d−1; τ random, or put where the lower block of the LMI is singular up to a relative 10⁻¹⁵…10⁻⁶ on
    either side (the boundary a rounding error would cross)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    d = draw(st.integers(3, 8))
    scale = 10.0 ** draw(st.integers(-8, 8))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    eig = 10.0 ** rng.uniform(-draw(st.integers(0, 12)), 0.0, size=3)
    P = scale * (q * eig) @ q.T
    P = 0.5 * (P + P.T)
    pi = rng.normal(size=(3, d)) * 10.0 ** rng.uniform(-3, 3, size=d) * np.sqrt(scale)
    pi[:, rng.random(d) < 0.15] = 0.0
    slots = list(range(1, d))
    rng.shuffle(slots)
    cuts = sorted(rng.choice(np.arange(1, d - 1), size=draw(st.integers(0, d - 2)), replace=False).tolist()) if d > 2 else []
    groups = [g for g in np.split(np.array(slots), cuts) if len(g)]
    facts = []
    for g in groups:
        f = np.zeros((d, d))
        f[0, 0] = 1.0
        f[g, g] = -1.0 / 10.0 ** rng.uniform(-4, 4)
        facts.append(f)
    how = draw(st.sampled_from(["random", "boundary"] if boundary else ["random"]))
    tau = 10.0 ** rng.uniform(-3, 3, size=len(facts))
    if how == "boundary":  # scale τ so that E − Π₂ᵀP⁻¹Π₂ is singular, then move it by a relative δ
        e = -(tau @ np.array([np.diag(f) for f in facts]))[1:]
        x = np.linalg.solve(np.linalg.cholesky(P), pi[:, 1:])
        gram = (x / np.sqrt(e)).T @ (x / np.sqrt(e))  # E^-½ Π₂ᵀP⁻¹Π₂ E^-½
        top = float(np.linalg.eigvalsh(gram)[-1])
        if top > 0:
            delta = draw(st.sampled_from([-1e-6, -1e-12, -1e-15, -4e-16, 0.0, 4e-16, 1e-15, 1e-12, 1e-6]))
            tau = tau * top * (1.0 + delta)
    tau[rng.random(len(tau)) < 0.1] = 0.0
    return P, pi, tau, facts


@FUZZ
@given(steps())
def test_every_closed_form_certificate_holds_exactly(step):
    """Whatever the closed form certifies, (ρ', τ') satisfies the S-procedure condition in exact arithmetic."""
    P, pi, tau, facts = step
    out = diagonal_certificate(P, pi, tau, FactStack.of(facts))
    if out is not None:
        rho, tau_used = out
        assert np.all(tau_used >= np.maximum(tau, 0.0))
        assert _holds(P, pi, tau_used, facts, rho)


@FUZZ
@given(steps(boundary=False))
def test_the_closed_form_is_the_dense_check_where_both_answer(step):
    """Away from the boundary (random multipliers), where the d×d check and the closed form both certify, their ρ'
    agree to one of the 10⁻⁶ widenings either may take to confirm (the closed form's margins are far below it).  At the boundary the closed form
    may pay more (its margin moves a nearly singular S) or certify nothing: never less than the truth needs."""
    P, pi, tau, facts = step
    fs = FactStack.of(facts)
    dense, closed = _dense_certificate(P, pi, tau, fs), diagonal_certificate(P, pi, tau, fs)
    if dense is not None and closed is not None:
        assert closed[0] == pytest.approx(dense[0], rel=2.1e-6, abs=1e-11)


@st.composite
def near_singular(draw: st.DrawFn) -> np.ndarray:
    """A symmetric 4×4 matrix with its smallest eigenvalue a relative 0 or ±10⁻¹⁸…10⁻¹² of its largest (rounded),
    scaled by 10^k (k −140…140)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    q, _ = np.linalg.qr(rng.normal(size=(4, 4)))
    eig = 10.0 ** rng.uniform(-6, 0, size=4)
    eig[0] = draw(st.sampled_from([0.0, 1e-18, -1e-18, 1e-16, -1e-16, 1e-14, -1e-14, 1e-12, -1e-12]))
    a = (q * eig) @ q.T * 10.0 ** draw(st.integers(-140, 140))
    return 0.5 * (a + a.T)


@FUZZ
@given(near_singular())
def test_rump_definite_never_calls_a_matrix_definite_that_is_not(a):
    if rump_definite(a.tolist()):
        assert _definite(_exact(a))


def test_rump_definite_proves_a_clearly_definite_matrix():
    assert rump_definite((np.eye(4) + 0.1).tolist())
    assert not rump_definite(np.diag([1.0, 1.0, 1.0, -1e-300]).tolist())
    assert rump_definite(np.diag([1e-200, 1.0, 1e100, 1e-17]).tolist())  # scaled by powers of two first: exact
    near = np.full((4, 4), 0.25) + 2.0**-50 * np.eye(4)  # definite, its smallest eigenvalue far below the shift: no proof
    assert _definite(_exact(near)) and not rump_definite(near.tolist())


def test_certify_takes_the_closed_form_for_ball_facts_and_the_dense_check_otherwise(monkeypatch):
    """certify() answers through the closed form where every fact is diagonal and P is 3×3 (else the d×d check),
    and both certify a plain step to the same ρ'."""
    rng = np.random.default_rng(1)
    P = np.diag([2.0, 1.0, 0.5])
    pi = rng.normal(size=(3, 5)) * 0.1
    ball = np.diag([1.0, -1.0, -1.0, -1.0, -1.0])
    sector = ball.copy()
    sector[1, 2] = sector[2, 1] = 0.1
    calls = []
    import netsetest.estimator.certificate as cert

    real = cert.diagonal_certificate
    monkeypatch.setattr(cert, "diagonal_certificate", lambda *a: calls.append(1) or real(*a))
    closed = certify(P, pi, np.array([2.0]), [ball])
    assert calls == [1]
    assert closed == pytest.approx(_dense_certificate(P, pi, np.array([2.0]), FactStack.of([ball]))[0], rel=1e-9)
    assert certify(P, pi, np.array([2.0]), [sector]) is not None
    assert calls == [1]


@st.composite
def shapes(draw: st.DrawFn) -> np.ndarray:
    """A symmetric 3×3 matrix: positive definite of eigenvalue ratio 1…10¹⁵, or with one eigenvalue 0 or negative,
    scaled by 10^k (k −100…100)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    eig = 10.0 ** rng.uniform(-draw(st.integers(0, 15)), 0.0, size=3)
    eig[0] *= draw(st.sampled_from([1.0, 1.0, 1.0, 0.0, -1.0, -1e-10]))
    a = (q * eig) @ q.T * 10.0 ** draw(st.integers(-100, 100))
    return 0.5 * (a + a.T)


@FUZZ
@given(shapes())
def test_publishable_answers_as_the_eigenvalues_do(P):
    """The minors' shortcut of publishable() accepts only what the eigenvalue test accepts (and that one's answer
    stands everywhere else)."""
    from netsetest.estimator.certificate import COND_MAX, _clearly_conditioned, publishable
    from netsetest.linalg import eigvalsh

    eig = eigvalsh(P)
    by_eigenvalues = bool(eig[0] > 0 and eig[-1] <= COND_MAX * eig[0])
    assert publishable(np.zeros(3), P) == by_eigenvalues
    if _clearly_conditioned(P.tolist()):
        assert _definite(_exact(P)) and eig[-1] <= 0.5 * COND_MAX * eig[0] * (1 + 1e-6)


def _slab_fact(a: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """(aᵀη − lo η₀)(hi η₀ − aᵀη) ≥ 0 as a symmetric Q (a dense fact: the slab cuts' and the sector facts' kind)."""
    d = len(a)
    b0 = np.zeros(d)
    b0[0] = 1.0
    return -np.outer(a, a) + 0.5 * (lo + hi) * (np.outer(a, b0) + np.outer(b0, a)) - lo * hi * np.outer(b0, b0)


@st.composite
def dense_steps(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
    """A step with a dense fact: (P, Π, τ, facts) as :func:`steps` draws them (d 3–6, P of condition up to 10¹², scaled
    by 10^k), the facts a ball over every slot but the first and one or two slab facts, τ random or put where the
    lower block of the LMI is singular up to a relative ±10⁻¹⁵…10⁻⁶ (the ball's multiplier moved)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    d = draw(st.integers(3, 6))
    scale = 10.0 ** draw(st.integers(-6, 6))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    P = scale * (q * 10.0 ** rng.uniform(-draw(st.integers(0, 12)), 0.0, size=3)) @ q.T
    P = 0.5 * (P + P.T)
    pi = rng.normal(size=(3, d)) * 10.0 ** rng.uniform(-2, 2, size=d) * np.sqrt(scale)
    ball = np.zeros((d, d))
    ball[0, 0] = 1.0
    ball[range(1, d), range(1, d)] = -1.0
    facts = [ball]
    for _ in range(draw(st.integers(1, 2))):
        a = rng.normal(size=d)
        lo = float(rng.normal())
        facts.append(_slab_fact(a, lo, lo + float(rng.uniform(0.01, 3.0))))
    tau = 10.0 ** rng.uniform(-2, 1, size=len(facts))
    # the ball's multiplier where the lower block of K is singular: −K₂₂ = τ_b I − (XᵀX + Σ_slab τ Q)₂₂
    x = np.linalg.solve(np.linalg.cholesky(P), pi)
    rest = (x.T @ x + sum(t * f for t, f in zip(tau[1:], facts[1:])))[1:, 1:]
    top = float(np.linalg.eigvalsh(rest)[-1])
    delta = draw(st.sampled_from([-1e-6, -1e-12, -1e-15, 0.0, 1e-15, 1e-12, 1e-6, 1.0]))
    tau[0] = max(top, 1e-3) * (1.0 + delta)
    return P, pi, tau, facts


@FUZZ
@given(dense_steps())
def test_every_dense_certificate_holds_exactly(step):
    """Whatever the d×d certificate certifies, (ρ', τ') satisfies the S-procedure condition in exact arithmetic."""
    P, pi, tau, facts = step
    out = _dense_certificate(P, pi, tau, FactStack.of(facts))
    if out is not None:
        rho, tau_used = out
        assert np.all(tau_used >= np.maximum(tau, 0.0))
        assert _holds(P, pi, tau_used, facts, rho)


def _threshold(P: np.ndarray, pi: np.ndarray, tau: np.ndarray, facts: list[np.ndarray]) -> Fraction | None:
    """The exact smallest ρ of the condition (k₁₁ − kᵀK₂₂⁻¹k, K = ΠᵀP⁻¹Π + Σ τ_m Q_m), None where K₂₂ is not negative
    definite."""
    p, x = _exact(P), _exact(pi)
    pinv, d = _inverse3(p), len(x[0])
    q, t = [_exact(f) for f in facts], [Fraction(float(v)) for v in tau]
    k = [
        [
            sum((x[a][i] * pinv[a][b] * x[b][j] for a in range(3) for b in range(3)), Fraction(0))
            + sum((t[m] * q[m][i][j] for m in range(len(q))), Fraction(0))
            for j in range(d)
        ]
        for i in range(d)
    ]
    neg = [[-v for v in row[1:]] for row in k[1:]]
    if not _definite(neg):
        return None
    # kᵀ(−K₂₂)⁻¹k by Gaussian elimination on [−K₂₂ | k]
    a = [row[:] + [k[i + 1][0]] for i, row in enumerate(neg)]
    n = len(a)
    for c in range(n):
        for r in range(c + 1, n):
            f = a[r][c] / a[c][c]
            for j in range(c, n + 1):
                a[r][j] -= f * a[c][j]
    sol = [Fraction(0)] * n
    for r in reversed(range(n)):
        sol[r] = (a[r][n] - sum((a[r][j] * sol[j] for j in range(r + 1, n)), Fraction(0))) / a[r][r]
    return k[0][0] + sum((k[i + 1][0] * sol[i] for i in range(n)), Fraction(0))


def _near_threshold(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, FactStack, list[float]] | None:
    """A random dense step (d = 4, a ball and a slab fact) and the floats just below its exact threshold ρ*."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    P = (q * 10.0 ** rng.uniform(-3, 0, size=3)) @ q.T
    P = 0.5 * (P + P.T)
    pi = rng.normal(size=(3, 4))
    ball = np.diag([1.0, -1.0, -1.0, -1.0])
    facts = [ball, _slab_fact(rng.normal(size=4), -1.0, 1.0)]
    x = np.linalg.solve(np.linalg.cholesky(P), pi)
    tau = np.array([0.0, float(rng.uniform(0.1, 1.0))])
    tau[0] = float(np.linalg.eigvalsh((x.T @ x + tau[1] * facts[1])[1:, 1:])[-1]) * 2.0
    star = _threshold(P, pi, tau, facts)
    if star is None:
        return None
    below = [float(star)]
    while Fraction(below[-1]) >= star:
        below.append(float(np.nextafter(below[-1], -np.inf)))
    below = below[-1:]
    for _ in range(6):
        below.append(float(np.nextafter(below[-1], -np.inf)))
    return P, pi, tau, FactStack.of(facts), below


def test_the_dense_proof_refuses_below_the_exact_threshold_and_needs_its_margins(monkeypatch):
    """lmi_proven() never proves a ρ below the exact threshold ρ* (where the condition fails); with its margins
    shrunk to nothing (N's rounding bound and Rump's shift) it does, on some of the same steps: the margins are
    what makes it sound."""
    import netsetest.estimator.certificate as cert
    from netsetest.estimator.certificate import lmi_proven

    cases = [c for c in (_near_threshold(s) for s in range(40)) if c is not None]
    assert len(cases) >= 30
    for P, pi, tau, fs, below in cases:
        assert not any(lmi_proven(P, pi, tau, fs, r) for r in below)
        rho = float(_threshold(P, pi, tau, list(fs.Q))) * (1 + 1e-9) + 1e-12  # what the certificate asks, widened
        assert lmi_proven(P, pi, tau, fs, rho)
    monkeypatch.setattr(cert, "RUMP_C", 0.0)
    monkeypatch.setattr(cert, "RUMP_FLOOR", 0.0)
    wrong = sum(any(lmi_proven(P, pi, tau, fs, r, margin=0.0) for r in below) for P, pi, tau, fs, below in cases)
    assert wrong > 0
