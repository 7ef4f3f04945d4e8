"""The truth of one run, step by step: the exogenous signals, the manoeuvre's steering and the plant.

One way to drive the car: the vehicle role publishes what :class:`Drive` produces, and ``netsetest
calibrate`` (analysis/calibrate.py) measures the model mismatch on exactly the same truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import numpy as np

from netsetest.models.manoeuvres import Manoeuvre
from netsetest.models.plant import make_plant
from netsetest.models.signals import ExogenousSignals, SignalKind

if TYPE_CHECKING:  # models never import config at run time (DEVELOPERS.md, import rules): the scenario is passed in
    from netsetest.config.schema import Scenario


def scheduled_speed(sc: Scenario, vx: float) -> float:
    """The Vx a plant's truth publishes for scheduling: its longitudinal speed, held inside the model's range."""
    p = sc.model.params
    return min(max(vx, p.vx_min), p.vx_max)


@dataclass(frozen=True)
class DriveStep:
    """Step k of the truth: x_k, the inputs held over [k, k+1], the sensors' v_k, γ_k, and e_k (None after
    the last step) = x_{k+1} − (Ā_k x_k + B̄_k u_k + D̄_k w_k) with the matrices of Vx_k; the car's speed v_k
    and the transition's lateral acceleration a_y,k (Plant.transition_ay) (None after the last step; models/envelope.py)."""

    k: int
    x: np.ndarray  # (NX,)
    u: float
    w: float
    vx: float
    v: np.ndarray  # (N,) per node in scenario order
    gamma: np.ndarray  # (N,)
    e: np.ndarray | None
    speed: float = 0.0  # [m/s] v at the centre of gravity
    ay: float | None = None  # [m/s²]


class Drive:
    """The seeded truth of a run; :meth:`step` is called once per step, in order from 0."""

    def __init__(self, sc: Scenario, signals: SignalKind, seed: int) -> None:
        self.sc = sc
        self.signals = ExogenousSignals(
            signals,
            seed,
            sc.steer_low,
            sc.steer_high,
            sc.W,
            [n.sensor.R for n in sc.nodes],
            [n.noise_frequency for n in sc.nodes],
            cast(list[tuple[float, float]], [n.gamma_range for n in sc.nodes]) if sc.case == "saim" else None,  # saim: every node has one
            sc.tau_s,
        )
        p = sc.model.params
        self.manoeuvre = Manoeuvre.build(sc.manoeuvre, sc.speed, sc.steer_high, p.lf + p.lr, sc.steps * sc.tau_s)
        self.plant = make_plant(sc.plant, sc.vehicle_id, sc.model, sc.x0, sc.vx(0), 0.0)

    def step(self, k: int) -> DriveStep:
        sc = self.sc
        st = self.plant.state()
        drawn, w, v, gamma = self.signals.draw(k)  # the draw order of every run: u, w, v, γ
        u = self.manoeuvre.steer(k * sc.tau_s, st, drawn)
        vx = sc.vx(k) if sc.plant == "ts" else scheduled_speed(sc, st.vx)
        e = ay = None
        if k < sc.steps and sc.plant == "ts":  # the truth is the model's own step: e_k = 0 exactly
            self.plant.advance(u, w, k * sc.tau_s, (k + 1) * sc.tau_s, sc.speed)
            e = np.zeros(2)
        elif k < sc.steps:  # the transition to k+1 (none after the last step)
            predicted = sc.model.step(st.x, u, w, vx)
            self.plant.advance(u, w, k * sc.tau_s, (k + 1) * sc.tau_s, sc.speed)
            e = self.plant.state().x - predicted
        if k < sc.steps:
            ay = self.plant.transition_ay()
        return DriveStep(k, st.x, u, w, vx, v, gamma, e, st.speed, ay)


__all__ = ["Drive", "DriveStep", "scheduled_speed"]
