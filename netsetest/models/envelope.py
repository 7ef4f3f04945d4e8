"""The operating envelope a model-mismatch bound was calibrated for (docs/plant.md §4).

A bound on e_k is only as good as the drives it was calibrated on, and e_k grows with how far the tyres
leave their linear range, that is with the lateral acceleration, and with how far the speed is from the
ones the training held.  ``[envelope]`` declares the region those drives filled:

    |a_y,k| ≤ ay_max    and    speed_kmh[0] ≤ 3.6 v_k ≤ speed_kmh[1]

with a_y,k the lateral acceleration the tyres carry over the transition k → k+1 (models/plant.py,
``transition_ay``: the larger in magnitude of its values at the interval's two ends, the first already with
the interval's steering, so that a quick steering change shows at once in its front tyre's force) and v_k
the car's speed at step k.  The tyres' a_y is the body's less the side wind's force over the mass, f_w w/m:
e_k grows with how far the tyres leave their linear range, and a gust against a turn lowers the body's a_y
by up to f_w √W/m (1.3–1.8 m/s² on CommonRoad's cars with the worst-case wind) while the tyres carry as much as before; measured on
the body, vehicle 2's held-out double lane change left its bound on transitions the check called inside
(issue 29).
The vehicle role checks every transition against it and publishes the check with the truth
(``Truth.envelope_ok``); a miss after a transition whose e_k left its bound is then attributed to
"outside the operating envelope" where the car had left it, and to "model mismatch" where it had not
(the bound itself was too small for the envelope: recalibrate).  The guarantee rests on e_k ∈ 𝓔 alone:
a transition outside the envelope whose e_k stayed inside the bound leaves the node-step covered.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from netsetest.models.vehicle import KMH

HOLDS_RTOL = 1e-12  # the check against the envelope, with the rounding tolerance of every other bound check

# the causes of a node-step after a transition whose e_k left its bound (roles/judge.py attributes them; the
# verdict line says them in these words, with what to do)
MODEL_MISMATCH = "model mismatch"  # the car inside its envelope (or none declared): the bound is too small
OUTSIDE_ENVELOPE = "outside the operating envelope"  # the car had left the declared [envelope]
MISMATCH_CAUSES = {
    MODEL_MISMATCH: ("model mismatch exceeded its bound", "recalibrate (docs/plant.md)"),
    OUTSIDE_ENVELOPE: ("the car left its operating envelope and e_k its bound", "drive inside the envelope or calibrate a wider one (docs/plant.md)"),
}


@dataclass(frozen=True)
class OperatingEnvelope:
    """|a_y| ≤ ``ay_max`` [m/s²] and a speed within ``speed_kmh`` [km/h]."""

    ay_max: float
    speed_kmh: tuple[float, float]

    def holds(self, ay: float, speed: float) -> bool:
        """Whether a transition with lateral acceleration ``ay`` [m/s²] at speed ``speed`` [m/s] is inside."""
        if not (math.isfinite(ay) and math.isfinite(speed)):
            return False
        kmh = speed / KMH
        lo, hi = self.speed_kmh
        tol = 1 + HOLDS_RTOL
        return abs(ay) <= self.ay_max * tol and lo / tol <= kmh <= hi * tol

    @classmethod
    def covering(cls, ay: np.ndarray, speed: np.ndarray) -> OperatingEnvelope:
        """The smallest envelope holding every transition's |a_y| [m/s²] and speed [m/s] (what recorded drives covered,
        measured as the run measures it: ``calibrate --logs``)."""
        kmh = np.asarray(speed, dtype=float) / KMH
        return cls(float(np.abs(ay).max()), (float(kmh.min()), float(kmh.max())))

    def ay_margin(self, ay: float) -> float:
        """ay_max − |a_y| [m/s²]: negative where the transition is outside."""
        return self.ay_max - abs(ay)

    def speed_margin(self, speed: float) -> float:
        """The speed's distance to the nearer end of the range [km/h]: negative where outside."""
        kmh = speed / KMH
        return min(kmh - self.speed_kmh[0], self.speed_kmh[1] - kmh)

    @property
    def text(self) -> str:
        """The envelope in words, as the run's header and ``calibrate`` print it."""
        return f"|a_y| ≤ {self.ay_max:g} m/s², {self.speed_kmh[0]:g}–{self.speed_kmh[1]:g} km/h"

    def as_toml(self) -> str:
        """The ``[envelope]`` table that declares this envelope."""
        return f"[envelope]\nay_max = {self.ay_max!r}\nspeed_kmh = [{self.speed_kmh[0]!r}, {self.speed_kmh[1]!r}]\n"


__all__ = ["MISMATCH_CAUSES", "MODEL_MISMATCH", "OUTSIDE_ENVELOPE", "OperatingEnvelope"]
