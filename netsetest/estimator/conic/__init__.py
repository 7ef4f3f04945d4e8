"""Node i's SDP assembled for Clarabel directly: an exactly equivalent, smaller, well-scaled conic problem.

The LMI of :mod:`netsetest.estimator.sdp` (docs/design.md §2), written as M ⪰ 0 with

    M(P, L, τ) = [[P, Π(L)], [Π(L)ᵀ, N(τ)]],   Π(L) = Π₀ − L ℓᵀ,   N(τ) = ρ e₁e₁ᵀ − Σ_m τ_m Q_m,

τ ≥ 0, minimise trace(P), is rewritten with exact steps before it reaches the solver; the answer is
mapped back to (P, L, τ) of that LMI, which :func:`netsetest.estimator.certificate.certify` verifies as before.

1. **One scalar for the innovation noise** (``aggregate``).  A ball fact 1 − η_k²/β_k ≥ 0 on a single
   slot k that no sector fact touches and whose column of Π₀ is zero (every v_j, and the s_j of
   non-saturating neighbours) enters M only through the column −L ℓ_k and the entry τ_k in N₁₁.
   Eliminating the slot (Schur) leaves L Lᵀ ℓ_k² β_k / τ_k in the P block.  For a budget t = Σ τ_k,
   Σ_k ℓ_k² β_k / τ_k is smallest, (Σ_k |ℓ_k| √β_k)² / t, at τ_k = t |ℓ_k| √β_k / Σ|ℓ|√β
   (Cauchy–Schwarz).  So all of them together are exactly one slot ξ with column −L and the fact
   1 − ξ²/B² ≥ 0, B = Σ_k |ℓ_k| √β_k; ξ's multiplier is split back over the original facts that way.
2. **Second-order cones instead of a matrix inequality** (``cones``, variant ``scheduled``).  Where
   N(τ) is diagonal on a group of slots — a ball fact no sector fact touches, ξ, and without
   saturation the constant slot η₁ — the Schur complement splits M ⪰ 0 into
   P ⪰ P_c + Σ_k β_k Π_k Π_kᵀ / τ_k, with Π_k the columns of Π(L) of group k and P_c bounded by the
   LMI over the remaining, coupled slots.  Minimising trace(P) is then minimising trace(P_c) + Σ_k t_k
   with the rotated cones β_k ‖Π_k(L)‖² ≤ t_k τ_k.  Without saturation nothing is coupled and the SDP
   is a small SOCP; with it the sector facts keep one LMI over the slots they couple (η₁, z_i, s_j, w,
   v⁺, φ).  The P handed to certify() is the smallest one for the solver's (L, τ):
   P_c + Σ_k β_k Π_k Π_kᵀ / τ_k.  ``per-rule`` shares P between four LMIs, so it keeps them (with
   step 1 and the scaling of step 3).
3. **Scaling.**  Congruences of M that change nothing but the numbers the solver sees: the P rows by
   S⁻¹ with S Sᵀ = P_prev (the node's previous shape: P̃ = S⁻¹PS⁻ᵀ is near I, L̃ = S⁻¹L); each ball
   slot by √β_k (every ball fact then has −1 on its diagonal); each φ slot by a bound of h|r| from its
   sector fact (φ is of the size of h|r|, far smaller than the other slots); and each sector fact's
   multiplier by the size of its scaled Q (τ̂ = κτ).  Without them the SAIM problems need 30–40
   iterations and Clarabel stops up to 0.5 % above the optimum; with them 10–17 iterations and the
   optimum to about 1e-6.  Clarabel's own equilibration is then switched off (it made matters worse).
4. **Clique cones** (``decompose``, scheduled with saturation).  The remaining LMI is sparse: a sector
   fact couples its φ slot only with η₁ and the slots of its r.  It is split into one PSD cone per
   clique — {η₁, z_i, φ_i, φ⁺}, {φ⁺, w, v⁺}, {η₁, φ_j, s_j} per saturating neighbour, P's rows in
   each — whose matrices add up to the LMI (entries held by several cliques get free split
   variables).  Exact by Agler's theorem (chordal sparsity; coverage and the running-intersection
   property are checked when the node is set up).  Measured against Clarabel's own chordal
   decomposition of the same LMI: the same optimum (to 2e-6), about 10 % less time, and no
   per-step decomposition analysis.

Per step the values are filled into a sparsity pattern built once per node (per pattern key) with
numpy; the node keeps one Clarabel solver per pattern and updates its data in place
(``solver.update``), so Clarabel's set-up (KKT symbolic factorisation) is paid once, not per step.
No cvxpy, no scipy.sparse, no canonicalisation.  Where Clarabel refuses updates (``per-rule``, whose
LMIs Clarabel decomposes itself) a fresh solver is set up per step.

The package follows those seams (imports run down the list):

- :mod:`~netsetest.estimator.conic.reduction`: what steps 1–4 fix per node (:class:`Reduction`), the
  step's aggregation (step 1) and scales (step 3), and the smallest P for an answer's (L, τ) (step 2);
- :mod:`~netsetest.estimator.conic.template`: the pattern of A, b and the cones per template key and the
  value blocks that fill it per step;
- :mod:`~netsetest.estimator.conic.solver`: :class:`ConicSolver`, the Clarabel backend in cvxpy's three
  steps (``apply`` → ``ConicData`` + ``InverseData``, ``solve_via_data``, ``invert`` with a status map);
- :mod:`~netsetest.estimator.conic.closed_form`: the problem without an LMI block (NSNIM, scheduled) in
  closed form (:mod:`netsetest.estimator.sum_of_norms`), Clarabel where that fails, and
  :func:`~netsetest.estimator.conic.closed_form.clarabel_backend`, which picks one of the two for a node.
"""
