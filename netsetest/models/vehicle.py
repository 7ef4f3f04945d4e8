"""Vehicle lateral dynamics: 2-DOF bicycle model and its T-S fuzzy discretisation (paper Sec. III-A).

State x = [β, r] (sideslip angle, yaw rate), input u = δf (front steering), disturbance w = side-wind
force (scalar, normalised so that w² ≤ W).  The continuous model (5) depends on 1/Vx and 1/Vx²; the
sector nonlinearity approach gives four rules, each discretised exactly with a zero-order hold at τs.
The premise values of the rules are:

    rule 1: 1/Vx = 1/Vx_max, 1/Vx² = 1/Vx_max²     rule 2: 1/Vx = 1/Vx_max, 1/Vx² = 1/Vx_min²
    rule 3: 1/Vx = 1/Vx_min, 1/Vx² = 1/Vx_max²     rule 4: 1/Vx = 1/Vx_min, 1/Vx² = 1/Vx_min²

This ordering reproduces the printed A1..A4, B1..B4, Dw,1..Dw,4 of Sec. VI (the paper's "High/Low" labels
are swapped with respect to its own matrices, see docs/design.md §1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KMH = 1.0 / 3.6  # km/h → m/s
N_RULES = 4


@dataclass(frozen=True)
class VehicleParams:
    """Table I of the paper plus the side-wind data of Sec. VI."""

    m: float = 1832.0  # mass [kg]
    Jz: float = 2488.0  # yaw moment of inertia [kg m²]
    lf: float = 1.18  # CG to front axle [m]
    lr: float = 1.77  # CG to rear axle [m]
    cf: float = 96240.0  # front cornering stiffness [N/rad]
    cr: float = 107180.0  # rear cornering stiffness [N/rad]
    fw: float = 1360.0  # wind force [N]
    lw: float = 0.5  # wind force lever arm [m]
    vx_min: float = 80.0 * KMH  # [m/s]
    vx_max: float = 120.0 * KMH  # [m/s]


def continuous_matrices(p: VehicleParams, inv_vx: float, inv_vx2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A', B', D' of (4)-(5) with 1/Vx and 1/Vx² treated as independent premise values."""
    a = np.array(
        [
            [-(p.cr + p.cf) / p.m * inv_vx, -1.0 + (p.lr * p.cr - p.lf * p.cf) / p.m * inv_vx2],
            [(p.lr * p.cr - p.lf * p.cf) / p.Jz, -(p.lr**2 * p.cr + p.lf**2 * p.cf) / p.Jz * inv_vx],
        ]
    )
    b = np.array([[p.cf / p.m * inv_vx], [p.cf * p.lf / p.Jz]])
    d = np.array([[p.fw / p.m * inv_vx], [p.lw * p.fw / p.Jz]])
    return a, b, d


def expm(m: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring of a Taylor series (small dense matrices).

    Own implementation so that a node process need not load scipy.linalg (≈ 27 MB, 0.3 s) for one 4×4
    exponential; with ‖m/2^s‖ ≤ 1/2 and 20 terms the truncation error is below 1e-19 relative.
    """
    norm = float(np.abs(m).sum(axis=1).max())
    s = max(0, int(np.ceil(np.log2(norm / 0.5)))) if norm > 0.5 else 0
    a = m / 2.0**s
    term = np.eye(m.shape[0])
    out = term.copy()
    for k in range(1, 21):
        term = term @ a / k
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


def zoh(a: np.ndarray, b: np.ndarray, d: np.ndarray, tau_s: float) -> tuple[np.ndarray, ...]:
    """Exact zero-order-hold discretisation: A = e^{A'τ}, [B D] = ∫₀^τ e^{A's} ds [B' D']."""
    n, m = a.shape[0], b.shape[1] + d.shape[1]
    big = np.zeros((n + m, n + m))
    big[:n, :n] = a
    big[:n, n:] = np.hstack([b, d])
    e = expm(big * tau_s)
    return e[:n, :n], e[:n, n : n + b.shape[1]], e[:n, n + b.shape[1] :]


@dataclass(frozen=True)
class TSModel:
    """Discrete T-S fuzzy model (8): x⁺ = Σ_ℓ α_ℓ(Vx) (A_ℓ x + B_ℓ u + Dw_ℓ w)."""

    params: VehicleParams
    tau_s: float
    A: np.ndarray  # (4, 2, 2)
    B: np.ndarray  # (4, 2, 1)
    Dw: np.ndarray  # (4, 2, 1)

    @classmethod
    def build(cls, params: VehicleParams, tau_s: float) -> TSModel:
        th1, th2 = 1.0 / params.vx_min, 1.0 / params.vx_max  # max / min of 1/Vx
        th3, th4 = th1**2, th2**2  # max / min of 1/Vx²
        premises = [(th2, th4), (th2, th3), (th1, th4), (th1, th3)]
        mats = [zoh(*continuous_matrices(params, iv, iv2), tau_s) for iv, iv2 in premises]
        return cls(
            params=params,
            tau_s=tau_s,
            A=np.array([m[0] for m in mats]),
            B=np.array([m[1] for m in mats]),
            Dw=np.array([m[2] for m in mats]),
        )

    def weights(self, vx: float) -> np.ndarray:
        """α_ℓ(Vx) = M_a(1/Vx)·Q_b(1/Vx²): products of the sector memberships; they sum to 1.

        The weight of a rule is the membership of its premise values: for rule 1 (both premises at
        the Vx_max end) it is M2·Q2 in the paper's notation.
        """
        p = self.params
        if not (p.vx_min * (1 - 1e-12) <= vx <= p.vx_max * (1 + 1e-12)):
            raise ValueError(f"speed {vx:.4f} m/s outside the model's range [{p.vx_min:.4f}, {p.vx_max:.4f}]")
        th1, th2 = 1.0 / p.vx_min, 1.0 / p.vx_max
        th3, th4 = th1**2, th2**2
        m_hi = (1.0 / vx - th2) / (th1 - th2)  # weight of the 1/Vx = ϑ1 (low-speed) end
        q_hi = (1.0 / vx**2 - th4) / (th3 - th4)
        m_hi, q_hi = min(max(m_hi, 0.0), 1.0), min(max(q_hi, 0.0), 1.0)  # np.clip costs µs per scalar call
        return np.array([(1 - m_hi) * (1 - q_hi), (1 - m_hi) * q_hi, m_hi * (1 - q_hi), m_hi * q_hi])

    def blend(self, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Σ α_ℓ (A_ℓ, B_ℓ, Dw_ℓ): the exact scheduled matrices for a known α."""
        row = alpha.reshape(1, -1)  # what np.tensordot(alpha, M, axes=1) computes, without its generic set-up (per step, per node)
        return tuple(np.dot(row, m.reshape(m.shape[0], -1)).reshape(m.shape[1:]) for m in (self.A, self.B, self.Dw))

    def step(self, x: np.ndarray, u: float, w: float, vx: float) -> np.ndarray:
        """Truth generator: the blended discrete model (8), the model the estimator assumes."""
        a, b, d = self.blend(self.weights(vx))
        return a @ x + b[:, 0] * u + d[:, 0] * w
