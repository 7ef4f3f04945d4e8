"""The truth's vehicle: the T-S model itself (``ts``) or a nonlinear CommonRoad vehicle model.

``single-track``: the single-track drift model with Pacejka tyres (``vehicle_dynamics_std``, 9 states);
``single-track-linear``: the single-track model with linear tyres of the same slope at zero slip
(``vehicle_dynamics_st``, 7 states; what the car's mismatch is without the tyres' nonlinearity);
``multi-body``: the multi-body model (``vehicle_dynamics_mb``, 29 states); both from the maintained
``commonroad-vehicle-models`` package (version 3.0.2, the ``plant`` extra), with its vehicles
``parameters_vehicle1..3``.  They are not re-implemented here: this module only

- holds the steering angle δ_k over the sampling interval (the zero-order hold the estimators assume;
  the steering-rate input is 0 and the package's steering constraints apply),
- adds the side wind as a lateral body force f_w·w at lever arm l_w (the force the T-S model's D̄ carries),
- drives the longitudinal acceleration input to follow the manoeuvre's speed reference
  (a = ṽ_ref + K_SPEED (v_ref − v)), and
- integrates between sampling instants with the adaptive Dormand–Prince Runge–Kutta 5(4) at relative
  tolerance :data:`RTOL` and absolute tolerance :data:`ATOL`: Hairer and Wanner's DOPRI5, through SciPy's
  ``ode`` (its step control runs in Fortran; ``solve_ivp``'s RK45, the same method in Python, spent more
  time choosing steps than the package's model spent in them).

The estimators' x = [β, r] is the plant's slip angle at the centre of gravity and yaw rate; the speed the
vehicle publishes for scheduling is the longitudinal speed Vx = v cos β, held inside the model's
[vx_min, vx_max] (any difference that makes is model mismatch e_k, bounded and checked like the rest).

:func:`derived_params` gives the T-S model of the same car (docs/plant.md): mass, yaw inertia and axle
distances of the parameter set, cornering stiffnesses = the Pacejka lateral force's slope at zero slip
under the static axle load.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from netsetest.extras import require
from netsetest.models.signals import SpeedProfile
from netsetest.models.vehicle import KMH, TSModel, VehicleParams

PlantKind = Literal["ts", "single-track", "single-track-linear", "multi-body"]
PLANTS: tuple[PlantKind, ...] = ("ts", "single-track", "single-track-linear", "multi-body")
VEHICLE_IDS = (1, 2, 3)  # CommonRoad parameters_vehicle1..3
VEHICLE_NAMES = {1: "Ford Escort", 2: "BMW 320i", 3: "VW Vanagon"}  # the cars of those parameter sets
RTOL = 1e-8  # DOPRI5's relative tolerance: x_{k+1} to ~1e-9 relative, far below any mismatch bound
ATOL = 1e-10
MAX_STEPS = 100_000  # DOPRI5's step budget per sampling interval (about 20 are used): a bound, not a setting
K_SPEED = 2.0  # [1/s] speed-tracking gain of the longitudinal acceleration input
GRAVITY = 9.81  # [m/s²], the package's value


def require_plant() -> None:
    """Raise :class:`~netsetest.extras.MissingExtra` unless the ``plant`` extra is installed."""
    require("vehiclemodels", "a nonlinear plant")


def vehicle_parameters(vehicle_id: int):  # the package's VehicleParameters
    """CommonRoad's parameter set ``parameters_vehicle<id>``."""
    require_plant()
    from vehiclemodels.vehicle_parameters import setup_vehicle_parameters

    return setup_vehicle_parameters(vehicle_id=vehicle_id)


def _cornering_stiffness(tire, f_z: float) -> float:
    """−dF_y/dα at α = 0 of the package's Pacejka lateral force at load f_z (central difference)."""
    from vehiclemodels.utils.tire_model import formula_lateral

    h = 1e-6
    return -(formula_lateral(h, 0.0, f_z, tire)[0] - formula_lateral(-h, 0.0, f_z, tire)[0]) / (2 * h)


def derived_params(vehicle_id: int, fw: float, lw: float, vx_min: float, vx_max: float) -> VehicleParams:
    """The bicycle-model parameters of CommonRoad vehicle ``vehicle_id`` (docs/plant.md): m, I_z, a, b of
    the set; c_f, c_r the tyre's slope at zero slip under the static axle loads m g b/(a+b), m g a/(a+b)."""
    p = vehicle_parameters(vehicle_id)
    lf, lr, m = float(p.a), float(p.b), float(p.m)
    fzf, fzr = m * GRAVITY * lr / (lf + lr), m * GRAVITY * lf / (lf + lr)
    return VehicleParams(
        m=m,
        Jz=float(p.I_z),
        lf=lf,
        lr=lr,
        cf=_cornering_stiffness(p.tire, fzf),
        cr=_cornering_stiffness(p.tire, fzr),
        fw=fw,
        lw=lw,
        vx_min=vx_min,
        vx_max=vx_max,
    )


@dataclass(frozen=True)
class PlantState:
    """What the vehicle role reads from a plant at a sampling instant."""

    x: np.ndarray  # (2,) [β, r]
    speed: float  # v at the centre of gravity [m/s]
    vx: float  # longitudinal speed v cos β [m/s]
    pose: tuple[float, float, float]  # X, Y [m], yaw ψ [rad] in the ground frame


class Plant(Protocol):
    def state(self) -> PlantState: ...

    def advance(self, u: float, w: float, t0: float, t1: float, speed: SpeedProfile) -> None:
        """Hold steering u and wind w over [t0, t1] while following the speed reference."""
        ...

    def transition_ay(self) -> float:
        """The lateral acceleration the tyres carry [m/s²] over the last :meth:`advance` (the operating
        envelope's measure, models/envelope.py): the larger in magnitude of its values at the interval's two
        ends.  The tyres' part of the body's a_y, that is without the side wind's force over the mass: e_k
        grows with the tyres' load, and a gust against a turn lowers the body's a_y, not that load."""
        ...


class TSPlant:
    """The T-S model (8) as the truth, scheduled with the reference speed (the paper's setting; e_k ≡ 0).

    The pose is integrated along (Euler at τs: only a path-following driver reads it)."""

    def __init__(self, model: TSModel, x0: np.ndarray, vx0: float) -> None:
        self.model, self.x, self.vx = model, np.asarray(x0, dtype=float).copy(), vx0
        self.pose = (0.0, 0.0, 0.0)

    def state(self) -> PlantState:
        return PlantState(self.x.copy(), self.vx / math.cos(self.x[0]), self.vx, self.pose)

    def advance(self, u: float, w: float, t0: float, t1: float, speed: SpeedProfile) -> None:
        X, Y, psi = self.pose
        tau = t1 - t0
        v = self.vx / math.cos(self.x[0])
        self.pose = (X + tau * v * math.cos(psi + self.x[0]), Y + tau * v * math.sin(psi + self.x[0]), psi + tau * self.x[1])
        x0, v0 = self.x, v
        self.x = self.model.step(self.x, u, w, self.vx)
        self.vx = speed.kmh(t1) * KMH  # as Scenario.vx: the paper's run, bit for bit
        # no instantaneous β̇ in a discrete model: the interval's mean, v̄ (Δβ/τ + r̄), less the wind's f_w w / m
        p = self.model.params
        self._ay = 0.5 * (v0 + self.vx / math.cos(self.x[0])) * ((self.x[0] - x0[0]) / tau + 0.5 * (x0[1] + self.x[1])) - p.fw * w / p.m

    def transition_ay(self) -> float:
        return self._ay


class _CommonRoadPlant:
    """A CommonRoad model integrated between sampling instants; the wind enters through ``_wind``."""

    MODEL: str  # the package's model: vehicle_dynamics_<MODEL> and init_<MODEL>
    INIT_TAKES_PARAMETERS = True  # init_<MODEL>(core, p); the linear single track's is init_st(core)

    def __init__(self, vehicle_id: int, fw: float, lw: float, x0: np.ndarray, vx0: float, delta0: float) -> None:
        """The car at x0 = [β, r], speed vx0 (longitudinal), steering δ0; the package's own initial state."""
        import importlib

        from scipy.integrate import ode

        self.p = vehicle_parameters(vehicle_id)
        self.m, self.Iz = float(self.p.m), float(self.p.I_z)
        self.fw, self.lw = fw, lw
        dynamics = importlib.import_module(f"vehiclemodels.vehicle_dynamics_{self.MODEL}")
        self._f: Callable[[list[float], list[float], object], list[float]] = getattr(dynamics, f"vehicle_dynamics_{self.MODEL}")
        beta0, r0 = float(x0[0]), float(x0[1])
        init = getattr(importlib.import_module(f"vehiclemodels.init_{self.MODEL}"), f"init_{self.MODEL}")
        core = [0.0, 0.0, delta0, vx0 / math.cos(beta0), 0.0, r0, beta0]  # X, Y, δ, v, ψ, ψ̇, β
        self.s = np.array(init(core, self.p) if self.INIT_TAKES_PARAMETERS else init(core), dtype=float)
        self._ode = ode(self._rhs).set_integrator("dopri5", rtol=RTOL, atol=ATOL, nsteps=MAX_STEPS)

    def _wind(self, f: list[float], s: np.ndarray, force: float) -> None:
        raise NotImplementedError

    def _ay(self, s: np.ndarray, f: list[float]) -> float:
        """The lateral acceleration at the centre of gravity, body frame, at state s with derivative f."""
        raise NotImplementedError

    def transition_ay(self) -> float:
        return self._ay_ends[0] if abs(self._ay_ends[0]) >= abs(self._ay_ends[1]) else self._ay_ends[1]

    def _rhs(self, t: float, s: np.ndarray, force: float, speed: SpeedProfile) -> list[float]:
        """ṡ = the package's model at s, with the speed-tracking acceleration input and the wind's force."""
        v_ref, dv_ref = speed.ms(t)
        accel = dv_ref + K_SPEED * (v_ref - s[3])  # s[3]: the speed state of both models
        f = self._f(s.tolist(), [0.0, accel], self.p)
        self._wind(f, s, force)
        return f

    def advance(self, u: float, w: float, t0: float, t1: float, speed: SpeedProfile) -> None:
        self.s[2] = u  # δ held over the interval (zero-order hold)
        # the tyres' a_y (Plant.transition_ay: the derivative without the wind's force), at t0 with the new
        # steering: its tyre force at once
        ay0 = self._ay(self.s, self._rhs(t0, self.s, 0.0, speed))
        integrator = self._ode.set_initial_value(self.s, t0).set_f_params(self.fw * w, speed)
        s1 = integrator.integrate(t1)
        if not integrator.successful():
            raise ArithmeticError(f"the plant's integration failed at t = {t0:.3f} s (DOPRI5 status {integrator.get_return_code()})")
        self.s = np.array(s1, dtype=float)
        self.s[2] = u
        self._ay_ends = (ay0, self._ay(self.s, self._rhs(t1, self.s, 0.0, speed)))


class SingleTrackPlant(_CommonRoadPlant):
    """``vehicle_dynamics_std``: states X, Y, δ, v, ψ, ψ̇, β, ω_f, ω_r."""

    MODEL = "std"

    def _wind(self, f: list[float], s: np.ndarray, force: float) -> None:
        # a lateral body force F at lever arm l_w: v̇ += F sin β / m, β̇ += F cos β / (m v), ψ̈ += l_w F / I_z
        beta, v = s[6], s[3]
        f[3] += force * math.sin(beta) / self.m
        f[6] += force * math.cos(beta) / (self.m * v)
        f[5] += self.lw * force / self.Iz

    def state(self) -> PlantState:
        s = self.s
        return PlantState(np.array([s[6], s[5]]), float(s[3]), float(s[3] * math.cos(s[6])), (float(s[0]), float(s[1]), float(s[4])))

    def _ay(self, s: np.ndarray, f: list[float]) -> float:
        # v_y = v sin β: a_y = v̇_y + r v_x = v̇ sin β + v cos β (β̇ + r)
        return float(f[3] * math.sin(s[6]) + s[3] * math.cos(s[6]) * (f[6] + s[5]))


class LinearTyrePlant(SingleTrackPlant):
    """``vehicle_dynamics_st``: states X, Y, δ, v, ψ, ψ̇, β (the first seven of the drift model's, so its wind
    and its x = [β, r] are the same). Its tyres are linear, C_S μ F_z = −p_ky1 F_z: the Pacejka tyre's slope
    at zero slip, so the derived T-S model is the same as the drift model's; load transfer under longitudinal
    acceleration is kept."""

    MODEL = "st"
    INIT_TAKES_PARAMETERS = False


class MultiBodyPlant(_CommonRoadPlant):
    """``vehicle_dynamics_mb``: 29 states; x[3] = v_x, x[10] = v_y (body frame), x[5] = ψ̇."""

    MODEL = "mb"

    def _wind(self, f: list[float], s: np.ndarray, force: float) -> None:
        # a lateral body force F at lever arm l_w: v̇_y += F / m, ψ̈ += l_w F / I_z
        f[10] += force / self.m
        f[5] += self.lw * force / self.Iz

    def _ay(self, s: np.ndarray, f: list[float]) -> float:
        return float(f[10] + s[5] * s[3])  # a_y = v̇_y + r v_x

    def state(self) -> PlantState:
        s = self.s
        return PlantState(
            np.array([math.atan2(s[10], s[3]), s[5]]),
            float(math.hypot(s[3], s[10])),
            float(s[3]),
            (float(s[0]), float(s[1]), float(s[4])),
        )


def make_plant(kind: PlantKind, vehicle_id: int, model: TSModel, x0: np.ndarray, vx0: float, delta0: float) -> Plant:
    """The plant a topology names, at the initial state x0 = [β, r], speed vx0, steering δ0."""
    if kind == "ts":
        return TSPlant(model, x0, vx0)
    p = model.params
    if kind == "multi-body":
        return MultiBodyPlant(vehicle_id, p.fw, p.lw, x0, vx0, delta0)
    cls = LinearTyrePlant if kind == "single-track-linear" else SingleTrackPlant
    return cls(vehicle_id, p.fw, p.lw, x0, vx0, delta0)


__all__ = [
    "PLANTS",
    "Plant",
    "PlantKind",
    "PlantState",
    "VEHICLE_NAMES",
    "derived_params",
    "make_plant",
    "require_plant",
    "vehicle_parameters",
]
