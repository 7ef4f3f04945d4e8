"""The estimator interface every guaranteed estimator of a node implements.

Per node and step the input is a :class:`StepInput` (the node's own ỹ_k, γ_k and the vehicle's
u_{k−1}, Vx_{k−1}) plus the neighbours' published sets (:class:`NeighbourSet`); the output is a
guaranteed set over the node's augmented state [β, r, f_i] (a type of :mod:`netsetest.sets`, each with
``contains`` and per-coordinate ``bounds``).

Each method declares which assumptions its guarantee rests on (:data:`Assumption` names, so a checker
can attribute a miss) and whether it uses its neighbours' sets.  The ellipsoidal SDP of this project
(estimator/sdp.py, run by roles/node.py) is the one method that uses them; the methods of the other
papers (001, 003) are single-sensor observers and ignore them (documented per module).  Where the
topology declares reference sensors, an estimator may also take their readings of the same step
(``uses_readings``; :class:`ReadingSlabs`, docs/network.md).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, Union

import numpy as np

from netsetest.sets import Box, Ellipsoid, RegionSet, Slab, SumSet, Zonotope

if TYPE_CHECKING:
    from netsetest.config.schema import Scenario
    from netsetest.estimator.health import HealthAssessment, HealthModel
    from netsetest.models.sensor import Sensor

GuaranteedSet = Union[Ellipsoid, Zonotope, Box, SumSet, RegionSet]  # a runtime alias

Assumption = Literal["prior", "noise", "disturbance", "fault_bound"]
"""What a guarantee may rest on: the truth x̄_0 in the prior ellipsoid (step 0), the measurement noise
bound v² ≤ R at every step used, the wind bound w² ≤ W at every step propagated, the declared fault
bound (|f_k+1 − f_k| ≤ δ, |f_k| ≤ F) at every step used.  The truth record flags each per step."""

BASE_ASSUMPTIONS: tuple[Assumption, ...] = ("prior", "noise", "disturbance")


class EstimatorError(ValueError):
    """An estimator cannot run on this node or these data (e.g. a needed declared bound is missing)."""


@dataclass(frozen=True)
class StepInput:
    """What node i knows at step k: its own measurement and availability, and the vehicle's previous
    input and speed (None at step 0, where the prior is cut by the first measurement).

    ``y`` None: no reading at this step (a gap in a recorded drive, docs/your-log.md): a prediction-only step, the
    last set moved through the model, the disturbance and mismatch bounds and the declared fault bound alone (at
    step 0 the prior, Assumption 1), with no measurement and no reading cut."""

    step: int
    y: float | None
    gamma: float
    u_prev: float | None = None
    vx_prev: float | None = None
    readings: dict[int, tuple[float, float]] = field(default_factory=dict)  # node j → (ỹ_j, γ_j) of this step


@dataclass(frozen=True)
class ReadingSlabs:
    """How a set estimator of one node turns a step's readings into slabs over its [β, r, f_i] (built once
    per node: the references' sensors and the k-of-N model of ``[network] max_faulty``)."""

    node_id: int
    references: dict[int, Sensor]  # reference j ≠ node → its sensor
    health: HealthModel | None

    @classmethod
    def of(cls, scenario: Scenario, node_id: int) -> ReadingSlabs:
        from netsetest.estimator.health import HealthModel

        refs = {j: scenario.node(j).sensor for j in scenario.references() if j != node_id}
        return cls(node_id, refs, HealthModel.of(scenario, node_id))

    def slabs(
        self,
        own: tuple[float, float],
        readings: dict[int, tuple[float, float]],
        extent: Callable[[np.ndarray], tuple[float, float]] | None = None,
    ) -> list[Slab]:
        """Each reference's C_j x ∈ [lo, hi] (its fault is declared 0, so C̄_j x̄_j = C_j x; a side at the
        sensor's limit is open), and under ``max_faulty`` the k-of-N interval of every reading and the
        node's own (``own``: ỹ, γ), its hypotheses pruned by ``extent`` (the range of aᵀx̄ over the node's
        own set), and the own fault |f| ≤ τ where no consistent majority leaves the node's sensor out
        (estimator/health.py)."""
        return self.assessed(own, readings, extent)[0]

    def assessed(
        self,
        own: tuple[float, float],
        readings: dict[int, tuple[float, float]],
        extent: Callable[[np.ndarray], tuple[float, float]] | None = None,
    ) -> tuple[list[Slab], HealthAssessment | None]:
        """:meth:`slabs` and the step's k-of-N assessment they came from (None: no k-of-N group)."""
        out = []
        for j, (y, gamma) in sorted(readings.items()):
            sensor = self.references.get(j)
            if sensor is not None:
                lo, hi = sensor.measured_interval(y, gamma, outward=True)
                out.append(Slab(np.append(sensor.C, 0.0), float(lo), float(hi)))
        if self.health is not None:
            a = np.append(self.health.u, 0.0)
            every = {**readings, self.node_id: own}
            measured = {j: sensor.measured_interval(*every[j], outward=True) for j, sensor in self.health.sensors.items() if j in every}
            health = self.health.assess(self.node_id, measured, extent(a) if extent is not None else None, pin=True)
            if health.interval is not None:
                out.append(Slab(a, health.interval.lo, health.interval.hi))
            if health.pinned:  # no consistent majority without this sensor: |f| ≤ τ
                out.append(Slab(np.array([0.0, 0.0, 1.0]), -self.health.tolerance, self.health.tolerance))
            return out, health
        return out, None


@dataclass(frozen=True)
class NeighbourSet:
    """A neighbour's published set of step k−1 over its own [β, r, f_j]."""

    node: int
    step: int
    set: GuaranteedSet


class SetEstimator(ABC):
    """One node's guaranteed estimator; :meth:`step` is called once per step, in order from step 0."""

    name: str  # the registry name (``netsetest compare --estimators``)
    uses_neighbours: bool = False
    uses_readings: bool = False  # it intersects its set with the references' readings of the step (docs/network.md)

    @property
    @abstractmethod
    def assumptions(self) -> tuple[Assumption, ...]:
        """The assumptions this node's guarantee rests on (depends on the node: e.g. a fault bound is
        needed only where a measurement can be one-sided)."""

    @abstractmethod
    def step(self, inp: StepInput, neighbours: tuple[NeighbourSet, ...] = ()) -> GuaranteedSet:
        """The published set of step ``inp.step``."""
